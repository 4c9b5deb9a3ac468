//! A quadrature Q̇ = G(t, Y) kept outside the integrated vector (`OdeSystem::has_quadrature`:
//! the adjoint's gradient g, p long, beside λ, n long): each step's increment ΔQ is formed
//! from the step's stage values with the weights of the scheme that took it, and added to Q
//! when the step is closed.
//!
//! Integrating the augmented vector (Y, Q) with the same scheme would give, because F never
//! reads Q, exactly the following update of Q; so Q comes out as the augmented integration's
//! to rounding (the same order, and the same steps: under `OdeSystem::controls_quadrature`
//! the acceptance test is the augmented one, max(‖e_Y‖, ‖e_Q‖)), while the stage loop, the
//! dense output and the finiteness checks never touch it. For a step of signed
//! length h from (t₀, Y₀), cut at θ ∈ (0, 1] (θ = 1 for a whole step):
//!
//! - **Explicit Runge–Kutta** (Tsit5, Verner): Q(t₀ + θh) − Q₀ = h Σᵢ bᵢ(θ) G(t₀ + cᵢh, Yᵢ)
//!   with Yᵢ = Y₀ + h Σ_j a_ij k_j the stage arguments (rebuilt from the stages, bit for bit
//!   those of the attempt) and bᵢ(1) = bᵢ; a cut step uses the continuous extension's
//!   weights bᵢ(θ) (and so Verner's interpolation stages).
//! - **Exact** (F constant, so G constant): θh·G(t₀, Y₀).
//! - **Rodas5P**: with J = [[J_YY, 0], [J_QY, 0]] the Q block of stage s is
//!   K_Q,s = γ(h Gₛ + h J_QY K_Y,s) + γ Σ_{j<s} C_sj K_Q,j + γ d_s h² G_t, Gₛ = G at stage s's
//!   argument. In vector form K_Q = γ(I − γC)⁻¹(u + d τ), u_s = h(Gₛ + J_QY K_Y,s),
//!   τ = h² G_t, and Q's update vᵀK_Q (v the stage weights of the solution, Σ_s a_{8s}, or of
//!   the dense output at θ) is Σ_s ω_s u_s + ω_t τ with ω = γz, (I − γC)ᵀ z = v (a back
//!   substitution over 8 stages) and ω_t = ωᵀd. So: eight stage values, one product J_QY·
//!   Σ_s ω_s K_Y,s at the step start, and G_t.
//!
//! Every stage value goes through the system's `quadrature_add`, which evaluates G once and
//! adds it with the step's weight to ΔQ ([`QuadratureSum::Step`]) and with the error weight to
//! the error estimate ([`QuadratureSum::Error`]); a sparse system does so on G's support only.
//!
//! **Local error.** The same loops form the Q-block of the augmented integration's embedded
//! error estimate: F never reads Q, so that block is the error weights applied to the same
//! stage values, h Σᵢ (bᵢ − b̂ᵢ) G(t₀ + cᵢh, Yᵢ) for an explicit pair, and for Rodas5P (whose
//! estimate is K₈) the update above with v = e₈. A cut step keeps the whole step's error
//! weights, as the stepper's estimate of Y is the whole step's.
//!
//! **When.** Under `OdeSystem::controls_quadrature` every attempt forms ΔQ and its error
//! (`Integrator::attempt`), so the acceptance sees ‖e_Q‖ and each stage's G is evaluated once
//! per attempt; a rejected attempt's sums are cleared by the next one and never reach Q. The
//! accepted step's sums wait for `Integrator::close_step`, which adds ΔQ to Q (re-forming
//! only ΔQ, with the weights bᵢ(θ), for a step cut at θ < 1). Otherwise nothing is formed
//! until the step is closed, with the error only when the system estimates it
//! (`OdeSystem::estimates_quadrature_error`).

use super::explicit::Tableau;
use super::rosenbrock::{self, NSTAGES};
use super::system::{ImplicitSystem, QuadratureSum, StageVector};
use super::{tsit5::TSIT5, verner::VERNER9, Integrator, Scheme};

/// The step whose quadrature is formed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum QuadratureOf {
    /// The attempt from (t, y) of signed length h with the active scheme (its stages in k).
    Attempt(f64),
    /// The last accepted step, from (t_prev, y_prev) over dense_h, cut at θ ∈ (0, 1].
    Accepted(f64),
}

impl QuadratureOf {
    fn is_attempt(self) -> bool {
        matches!(self, QuadratureOf::Attempt(_))
    }
}

impl<Sys: ImplicitSystem> Integrator<Sys> {
    /// Forms ΔQ of `step` into [`QuadratureSum::Step`], and with `error` its local error
    /// estimate (the whole step's) into [`QuadratureSum::Error`], each cleared first.
    pub(super) fn form_quadrature(&mut self, step: QuadratureOf, error: bool) {
        let (theta, scheme) = match step {
            QuadratureOf::Attempt(_) => (1.0, self.scheme),
            QuadratureOf::Accepted(theta) => (theta, self.dense_scheme),
        };
        self.sys.quadrature_clear(QuadratureSum::Step);
        if error {
            self.sys.quadrature_clear(QuadratureSum::Error);
        }
        match scheme {
            // F constant, so G is: the quadrature is exact (and makes no error).
            Scheme::Exact => {
                let (t0, h) = self.quadrature_span(step);
                let y0 = if step.is_attempt() {
                    &self.y
                } else {
                    &self.y_prev
                };
                self.sys.quadrature_add(t0, y0, theta * h, 0.0)
            }
            Scheme::Tsit5 => self.explicit_quadrature(&TSIT5, step, theta, error),
            Scheme::Verner9 => self.explicit_quadrature(&VERNER9, step, theta, error),
            Scheme::Rodas5P => self.rosenbrock_quadrature(step, theta, error),
        }
    }

    /// (t₀, h) of `step` (its start state is y for an attempt, y_prev for the accepted step).
    fn quadrature_span(&self, step: QuadratureOf) -> (f64, f64) {
        match step {
            QuadratureOf::Attempt(h) => (self.t, h),
            QuadratureOf::Accepted(_) => (self.t_prev, self.dense_h),
        }
    }

    /// ΔQ = h Σᵢ bᵢ(θ) G(t₀ + cᵢh, Yᵢ) over the stages of an explicit step, and with `error`
    /// its error h Σᵢ (bᵢ − b̂ᵢ) G(t₀ + cᵢh, Yᵢ), one evaluation of G per stage.
    fn explicit_quadrature<const S: usize, const K: usize, const D: usize>(
        &mut self,
        tab: &Tableau<S, K, D>,
        step: QuadratureOf,
        theta: f64,
        error: bool,
    ) {
        let mut w = [0.0; K];
        if theta == 1.0 {
            w[..S].copy_from_slice(&tab.b);
        } else {
            self.ensure_dense();
            w = tab.weights(theta);
        }
        let mut e = [0.0; K];
        if error {
            e[..S].copy_from_slice(&tab.btilde);
        }
        let (t0, h) = self.quadrature_span(step);
        let y0 = if step.is_attempt() {
            &self.y
        } else {
            &self.y_prev
        };
        for (i, (&wi, &ei)) in w.iter().zip(&e).enumerate() {
            if wi == 0.0 && ei == 0.0 {
                continue;
            }
            if i > 0 {
                self.tmp.combine(y0, h, tab.a[i], &self.k[..i], true);
            }
            let yi = if i == 0 { y0 } else { &self.tmp };
            self.sys
                .quadrature_add(t0 + tab.c[i] * h, yi, h * wi, h * ei);
        }
    }

    /// ΔQ's Rosenbrock update over a Rodas5P step, and with `error` the same update for the
    /// error estimate K₈ (see the module doc): one evaluation of G per stage.
    fn rosenbrock_quadrature(&mut self, step: QuadratureOf, theta: f64, error: bool) {
        let value = rosenbrock::quadrature_weights(theta);
        let err = if error {
            rosenbrock::quadrature_error_weights()
        } else {
            ([0.0; NSTAGES], 0.0)
        };
        let (t0, h) = self.quadrature_span(step);
        let y0 = if step.is_attempt() {
            &self.y
        } else {
            &self.y_prev
        };
        for s in 0..NSTAGES {
            let (ws, es) = (value.0[s], err.0[s]);
            if ws == 0.0 && es == 0.0 {
                continue;
            }
            let (a, c) = rosenbrock::stage_row(s);
            if s > 0 {
                self.tmp.combine(y0, 1.0, a, &self.k[1..=s], true);
            }
            let ys = if s == 0 { y0 } else { &self.tmp };
            self.sys.quadrature_add(t0 + c * h, ys, h * ws, h * es);
        }
        let sums: &[_] = if error {
            &[(value, QuadratureSum::Step), (err, QuadratureSum::Error)]
        } else {
            &[(value, QuadratureSum::Step)]
        };
        for &((omega, omega_t), sum) in sums {
            self.tmp.lincomb(1.0, &omega, &self.k[1..=NSTAGES], true);
            self.sys.quadrature_jac_add(t0, &self.tmp, h, sum);
            self.sys.quadrature_dt_add(t0, y0, h * h * omega_t, sum);
        }
    }
}
