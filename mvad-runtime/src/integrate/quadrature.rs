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

use super::explicit::Tableau;
use super::rosenbrock::{self, NSTAGES};
use super::system::{ImplicitSystem, StageVector};
use super::{tsit5::TSIT5, verner::VERNER9, Integrator, Scheme};

impl<Sys: ImplicitSystem> Integrator<Sys> {
    /// Adds the system's quadrature over the last accepted step, from t_prev over the signed
    /// length `h_cut` (the whole step, or the part [`Integrator::truncate`] kept).
    pub(super) fn add_step_quadrature(&mut self, h_cut: f64) {
        let h = self.dense_h;
        let theta = if h_cut == h { 1.0 } else { h_cut / h };
        match self.dense_scheme {
            Scheme::Exact => self.sys.quadrature_add(self.t_prev, &self.y_prev, h_cut),
            Scheme::Tsit5 => self.explicit_quadrature(&TSIT5, theta),
            Scheme::Verner9 => self.explicit_quadrature(&VERNER9, theta),
            Scheme::Rodas5P => self.rosenbrock_quadrature(theta),
        }
    }

    /// Q += h Σᵢ bᵢ(θ) G(t₀ + cᵢh, Yᵢ) over the stages of the last explicit step.
    fn explicit_quadrature<const S: usize, const K: usize, const D: usize>(
        &mut self,
        tab: &Tableau<S, K, D>,
        theta: f64,
    ) {
        let (t0, h) = (self.t_prev, self.dense_h);
        let mut w = [0.0; K];
        if theta == 1.0 {
            w[..S].copy_from_slice(&tab.b);
        } else {
            self.ensure_dense();
            w = tab.weights(theta);
        }
        for (i, &wi) in w.iter().enumerate() {
            if wi == 0.0 {
                continue;
            }
            let ti = t0 + tab.c[i] * h;
            if i == 0 {
                self.sys.quadrature_add(t0, &self.y_prev, h * wi);
            } else {
                self.tmp
                    .combine(&self.y_prev, h, tab.a[i], &self.k[..i], true);
                self.sys.quadrature_add(ti, &self.tmp, h * wi);
            }
        }
    }

    /// Q's Rosenbrock update over the last Rodas5P step (see the module doc).
    fn rosenbrock_quadrature(&mut self, theta: f64) {
        let (t0, h) = (self.t_prev, self.dense_h);
        let (omega, omega_t) = rosenbrock::quadrature_weights(theta);
        for (s, &ws) in omega.iter().enumerate() {
            if ws == 0.0 {
                continue;
            }
            if s == 0 {
                self.sys.quadrature_add(t0, &self.y_prev, h * ws);
            } else {
                let (a, c) = rosenbrock::stage_row(s);
                self.tmp.combine(&self.y_prev, 1.0, a, &self.k[1..=s], true);
                self.sys.quadrature_add(t0 + c * h, &self.tmp, h * ws);
            }
        }
        self.tmp.lincomb(1.0, &omega, &self.k[1..=NSTAGES], true);
        self.sys.quadrature_jac_add(t0, &self.tmp, h);
        self.sys
            .quadrature_dt_add(t0, &self.y_prev, h * h * omega_t);
    }
}
