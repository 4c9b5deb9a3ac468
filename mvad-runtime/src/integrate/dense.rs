//! Dense output of the last accepted step, and cutting a step short.
//!
//! After a step from (t_prev, Y₀) to (t, Y₁) of signed length h = t − t_prev, Y(t_prev + θh)
//! for θ ∈ [0, 1] is the continuous extension of the scheme that took the step: 4th order for
//! Tsit5 and Rodas5P, the line Y₀ + θh·F₀ (exact) for an exact step, 9th for Verner (or, while Verner's interpolation stages are pending,
//! the cubic Hermite interpolant of (Y₀, F₀, Y₁, F₁)). Works for either direction of time.

use super::explicit::Tableau;
use super::system::{HermiteStep, ImplicitSystem, Linearised, StageVector};
use super::{rosenbrock, tsit5::TSIT5, verner, verner::VERNER9, Integrator, Scheme};

impl<Sys: ImplicitSystem> Integrator<Sys> {
    /// The step from t_prev as a cubic Hermite interpolant: y_prev, the end state, and the
    /// slopes k[0] and the FSAL slot at its ends.
    fn hermite_step(&self) -> HermiteStep<'_, Sys::Vector> {
        HermiteStep {
            y0: &self.y_prev,
            y1: self.end_state(),
            f0: &self.k[0],
            f1: &self.k[VERNER9.fsal_slot()],
            h: self.dense_h,
        }
    }

    /// Dense output of the primary part (x) between t_prev and t (cheap; for root finding).
    pub fn dense_x(&self, t: f64, out: &mut <Sys::Vector as StageVector>::Primary) {
        if self.dense_h == 0.0 {
            self.y.primary_into(out);
            return;
        }
        let theta = (t - self.t_prev) / self.dense_h;
        let (k, y0, y1, h) = (&self.k[..], &self.y_prev, self.end_state(), self.dense_h);
        if self.dense_pending {
            Sys::Vector::hermite_primary(out, &self.hermite_step(), theta);
            return;
        }
        match self.dense_scheme {
            Scheme::Tsit5 => TSIT5.dense_primary(k, y0, h, theta, out),
            Scheme::Verner9 => VERNER9.dense_primary(k, y0, h, theta, out),
            Scheme::Rodas5P => rosenbrock::dense_primary(k, y0, y1, theta, out),
            Scheme::Exact => Sys::Vector::combine_primary(out, y0, h, &[theta], &k[..1]),
        }
    }

    /// Dense output of every integrated part between t_prev and t.
    pub fn dense(&self, t: f64, out: &mut Sys::Vector) {
        if self.dense_h == 0.0 {
            out.copy_from(&self.y);
            return;
        }
        let theta = (t - self.t_prev) / self.dense_h;
        if self.dense_pending {
            out.hermite(&self.hermite_step(), theta, self.sys.all_parts());
            return;
        }
        let all = self.sys.all_parts();
        let (k, y0, y1) = (&self.k[..], &self.y_prev, self.end_state());
        dense_into(self.dense_scheme, k, y0, y1, self.dense_h, theta, all, out);
    }

    /// The degree in θ of the dense output [`Integrator::dense_x`] gives now: 4 for Tsit5 and
    /// Rodas5P, 1 for an exact step, 9 for Verner (3 while its interpolation stages are pending), 0 right after a
    /// restart (see [`Integrator::dense_poly`]).
    pub fn dense_degree(&self) -> usize {
        if self.dense_h == 0.0 {
            0
        } else if self.dense_pending {
            3
        } else {
            match self.dense_scheme {
                Scheme::Tsit5 => TSIT5.degree(),
                Scheme::Verner9 => VERNER9.degree(),
                Scheme::Rodas5P => rosenbrock::DENSE_DEGREE,
                Scheme::Exact => 1,
            }
        }
    }

    /// The primary part of the dense output of the last accepted step as a polynomial in
    /// θ = (t − t_prev)/h: Σ_{m=0..D} θᵐ c_m with c₀ = Y₀, c_m into `coefs[m]` (at least
    /// [`Integrator::dense_degree`] + 1 of them); returns D. The same polynomial
    /// [`Integrator::dense_x`] evaluates, in the monomial basis about the step start, so a
    /// component the step left unchanged (all its stages exactly zero, as a stiff state at its
    /// equilibrium) is reproduced exactly, not to the rounding of a mix of Y₀ and Y₁.
    pub fn dense_poly(&self, coefs: &mut [<Sys::Vector as StageVector>::Primary]) -> usize {
        let deg = self.dense_degree();
        if deg == 0 {
            self.y.primary_into(&mut coefs[0]);
            return 0;
        }
        let (k, y0, y1, h) = (&self.k[..], &self.y_prev, self.end_state(), self.dense_h);
        if self.dense_pending {
            // Y₀ + θ h f₀ + θ² (3ΔY − 2h f₀ − h f₁) + θ³ (−2ΔY + h f₀ + h f₁), ΔY = Y₁ − Y₀.
            let f1 = &k[VERNER9.fsal_slot()];
            let v = [y0, y1, &k[0], f1, f1];
            y0.primary_into(&mut coefs[0]);
            Sys::Vector::mix5_primary(&mut coefs[1], &[0.0, 0.0, h, 0.0, 0.0], v);
            Sys::Vector::mix5_primary(&mut coefs[2], &[-3.0, 3.0, -2.0 * h, -h, 0.0], v);
            Sys::Vector::mix5_primary(&mut coefs[3], &[2.0, -2.0, h, h, 0.0], v);
            return deg;
        }
        match self.dense_scheme {
            Scheme::Tsit5 => TSIT5.poly_primary(k, y0, h, coefs),
            Scheme::Verner9 => VERNER9.poly_primary(k, y0, h, coefs),
            Scheme::Rodas5P => rosenbrock::poly_primary(k, y0, y1, coefs),
            Scheme::Exact => {
                // Y₀ + θ h F₀.
                y0.primary_into(&mut coefs[0]);
                let f0 = &k[0];
                Sys::Vector::mix5_primary(&mut coefs[1], &[h, 0.0, 0.0, 0.0, 0.0], [f0; 5]);
            }
        }
        deg
    }

    /// The state at the end of the last accepted step (before any truncation).
    fn end_state(&self) -> &Sys::Vector {
        if self.truncated {
            &self.y_end
        } else {
            &self.y
        }
    }

    /// Cuts the last step at `t_cut` between t_prev and t: t() := t_cut, y() := dense(t_cut).
    /// The dense output stays valid between t_prev and t_cut; the next step re-evaluates F at
    /// the cut.
    pub fn truncate(&mut self, t_cut: f64) {
        let t_cut = t_cut.clamp(self.t_prev.min(self.t), self.t_prev.max(self.t));
        // The step ends at t_cut: the global error estimate is carried that far.
        if self.carry_pending.is_some() {
            self.carry_pending = Some(t_cut - self.t_prev);
            self.close_step();
        }
        if t_cut == self.t {
            return;
        }
        self.ensure_dense();
        if !self.truncated {
            self.y_end.copy_from(&self.y);
            self.truncated = true;
        }
        let theta = (t_cut - self.t_prev) / self.dense_h;
        let all = self.sys.all_parts();
        let (k, y0, y1) = (&self.k[..], &self.y_prev, &self.y_end);
        dense_into(
            self.dense_scheme,
            k,
            y0,
            y1,
            self.dense_h,
            theta,
            all,
            &mut self.y,
        );
        self.t = t_cut;
        self.k0_valid = false;
        self.fsal_slot = None;
        self.sys.linearisation().invalidate();
    }

    /// Makes the full-order dense output of the last accepted step available (evaluates
    /// Verner's pending interpolation stages; nothing for the other methods).
    pub fn ensure_dense(&mut self) {
        if self.dense_pending {
            let h = self.dense_h;
            self.explicit_interp_stages(
                &VERNER9,
                VERNER9.fsal_slot() + 1..verner::STAGES_WITH_DENSE,
                h,
            );
            self.dense_pending = false;
            self.stats.rhs_evals = self.sys.evals();
        }
    }

    /// The interpolation stages of an accepted explicit step: all of them, or with
    /// `lazy_dense` only the FSAL one (the rest wait for [`Integrator::ensure_dense`]).
    pub(super) fn accepted_interp_stages<const S: usize, const K: usize, const D: usize>(
        &mut self,
        tab: &Tableau<S, K, D>,
        h: f64,
    ) {
        if K == S {
            return;
        }
        if self.lazy_dense {
            let fsal = tab.fsal_slot();
            self.explicit_interp_stages(tab, fsal..fsal + 1, h);
            self.dense_pending = true;
        } else {
            self.explicit_interp_stages(tab, S..K, h);
        }
    }
}

/// Dense output of `scheme` at θ of a step of signed length h from y0 to y1 with stages `k`.
#[allow(clippy::too_many_arguments)]
#[inline]
fn dense_into<V: StageVector>(
    scheme: Scheme,
    k: &[V],
    y0: &V,
    y1: &V,
    h: f64,
    theta: f64,
    all: bool,
    out: &mut V,
) {
    match scheme {
        Scheme::Tsit5 => TSIT5.dense(k, y0, h, theta, all, out),
        Scheme::Verner9 => VERNER9.dense(k, y0, h, theta, all, out),
        Scheme::Rodas5P => rosenbrock::dense(k, y0, y1, theta, all, out),
        Scheme::Exact => out.combine(y0, h, &[theta], &k[..1], all),
    }
}
