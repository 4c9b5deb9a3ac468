//! A quadrature Q̇ = G(t, Y) kept outside the integrated vector (`OdeSystem::has_quadrature`:
//! the adjoint's gradient g, p long, beside λ, n long), added once per closed step with the
//! weights of the scheme that took it.
//!
//! Integrating the augmented vector (Y, Q) with the same scheme would give, because F never
//! reads Q, exactly the following update of Q; so Q comes out as the augmented integration's
//! to rounding (same order, and the same steps when Q is not under error control), while the
//! stage loop, the error norm and the dense output never touch it. For a step of signed
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
//! Every term goes through the system's `quadrature_add` (Q += a·G), which a sparse system
//! implements without forming G.
//!
//! **Local error.** When the system estimates it (`OdeSystem::estimates_quadrature_error`),
//! the same loops form the Q-block of the augmented integration's embedded error estimate
//! into [`QuadratureSum::Error`]: F never reads Q, so that block is the error weights applied
//! to the same stage values, h Σᵢ (bᵢ − b̂ᵢ) G(t₀ + cᵢh, Yᵢ) for an explicit pair, and for
//! Rodas5P (whose estimate is K₈) the update above with v = e₈. A cut step keeps the whole
//! step's error weights, as the stepper's estimate of Y is the whole step's. Without it no
//! error term is formed, and Q is bit for bit what it was.

use super::explicit::Tableau;
use super::rosenbrock::{self, NSTAGES};
use super::system::{ImplicitSystem, QuadratureSum, StageVector};
use super::{tsit5::TSIT5, verner::VERNER9, Integrator, Scheme};

impl<Sys: ImplicitSystem> Integrator<Sys> {
    /// Adds the system's quadrature over the last accepted step, from t_prev over the signed
    /// length `h_cut` (the whole step, or the part [`Integrator::truncate`] kept), and its
    /// local error estimate if the system keeps one.
    pub(super) fn add_step_quadrature(&mut self, h_cut: f64) {
        let h = self.dense_h;
        let theta = if h_cut == h { 1.0 } else { h_cut / h };
        let error = self.sys.estimates_quadrature_error();
        match self.dense_scheme {
            // F constant, so G is: the quadrature is exact.
            Scheme::Exact => {
                let y0 = &self.y_prev;
                self.sys
                    .quadrature_add(self.t_prev, y0, h_cut, QuadratureSum::Value)
            }
            Scheme::Tsit5 => self.explicit_quadrature(&TSIT5, theta, error),
            Scheme::Verner9 => self.explicit_quadrature(&VERNER9, theta, error),
            Scheme::Rodas5P => self.rosenbrock_quadrature(theta, error),
        }
    }

    /// Q += h Σᵢ bᵢ(θ) G(t₀ + cᵢh, Yᵢ) over the stages of the last explicit step, and with
    /// `error` its error h Σᵢ (bᵢ − b̂ᵢ) G(t₀ + cᵢh, Yᵢ).
    fn explicit_quadrature<const S: usize, const K: usize, const D: usize>(
        &mut self,
        tab: &Tableau<S, K, D>,
        theta: f64,
        error: bool,
    ) {
        let (t0, h) = (self.t_prev, self.dense_h);
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
        for (i, (&wi, &ei)) in w.iter().zip(&e).enumerate() {
            if wi == 0.0 && ei == 0.0 {
                continue;
            }
            let ti = t0 + tab.c[i] * h;
            if i > 0 {
                self.tmp
                    .combine(&self.y_prev, h, tab.a[i], &self.k[..i], true);
            }
            let yi = if i == 0 { &self.y_prev } else { &self.tmp };
            if wi != 0.0 {
                self.sys
                    .quadrature_add(ti, yi, h * wi, QuadratureSum::Value);
            }
            if ei != 0.0 {
                self.sys
                    .quadrature_add(ti, yi, h * ei, QuadratureSum::Error);
            }
        }
    }

    /// Q's Rosenbrock update over the last Rodas5P step, and with `error` the same update
    /// for the error estimate K₈ (see the module doc).
    fn rosenbrock_quadrature(&mut self, theta: f64, error: bool) {
        let (t0, h) = (self.t_prev, self.dense_h);
        let value = rosenbrock::quadrature_weights(theta);
        let err = if error {
            rosenbrock::quadrature_error_weights()
        } else {
            ([0.0; NSTAGES], 0.0)
        };
        for s in 0..NSTAGES {
            let (ws, es) = (value.0[s], err.0[s]);
            if ws == 0.0 && es == 0.0 {
                continue;
            }
            let (a, c) = rosenbrock::stage_row(s);
            if s > 0 {
                self.tmp.combine(&self.y_prev, 1.0, a, &self.k[1..=s], true);
            }
            let ys = if s == 0 { &self.y_prev } else { &self.tmp };
            if ws != 0.0 {
                self.sys
                    .quadrature_add(t0 + c * h, ys, h * ws, QuadratureSum::Value);
            }
            if es != 0.0 {
                self.sys
                    .quadrature_add(t0 + c * h, ys, h * es, QuadratureSum::Error);
            }
        }
        let sums: &[_] = if error {
            &[(value, QuadratureSum::Value), (err, QuadratureSum::Error)]
        } else {
            &[(value, QuadratureSum::Value)]
        };
        for &((omega, omega_t), sum) in sums {
            self.tmp.lincomb(1.0, &omega, &self.k[1..=NSTAGES], true);
            self.sys.quadrature_jac_add(t0, &self.tmp, h, sum);
            self.sys
                .quadrature_dt_add(t0, &self.y_prev, h * h * omega_t, sum);
        }
    }
}
