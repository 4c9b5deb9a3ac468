//! Step-size control: the PI controller and Hairer's initial step.
//!
//! A step with error norm ‖e‖ ≤ 1 is accepted and the next step is
//! h·clamp(0.9 ‖e‖^(−β₁) ‖e_prev‖^(β₂), 0.2, 10) with β₁ = 0.7/k, β₂ = 0.4/k, k = order of
//! the estimate + 1, ‖e_prev‖ ≥ 1e-4, and no growth right after a rejection; a rejected step
//! is retried with h·max(0.9 ‖e‖^(−1/k), 0.2). Step sizes here are magnitudes: the direction
//! of integration is applied by the stepper.

use super::system::{ImplicitSystem, StageVector};
use super::Integrator;

/// Memory of the PI controller.
pub(super) struct Controller {
    /// ‖e‖ of the previous accepted step (clamped below at 1e-4).
    err_prev: f64,
    /// err_prev^(β₂), cached.
    err_prev_pow: f64,
    /// Error order + 1 the two constants below were computed for.
    k: f64,
    /// 1e-4^(β₂).
    floor_pow: f64,
    /// ‖e‖ below which the step-size factor is the growth cap 10.
    full_growth_err: f64,
    /// The last attempt was rejected (no step growth on the next accepted one).
    pub last_rejected: bool,
}

impl Controller {
    /// A controller with no memory; call [`Controller::reset`] before use.
    pub fn new() -> Self {
        Controller {
            err_prev: 1e-4,
            err_prev_pow: f64::NAN,
            k: f64::NAN,
            floor_pow: f64::NAN,
            full_growth_err: 0.0,
            last_rejected: false,
        }
    }

    /// Forgets the memory (start, restart, method switch) for a method of error order k − 1.
    pub fn reset(&mut self, k: f64) {
        self.refresh(k);
        self.err_prev = 1e-4;
        self.err_prev_pow = self.floor_pow;
    }

    /// Recomputes the constants when the order changed: `floor_pow` = 1e-4^(0.4/k) (the
    /// smallest ‖e_prev‖^β₂) and `full_growth_err`, half the ‖e‖ at which
    /// 0.9 ‖e‖^(−0.7/k) · floor_pow = 10 (the growth cap).
    fn refresh(&mut self, k: f64) {
        if k != self.k {
            self.k = k;
            self.floor_pow = 1e-4f64.powf(0.4 / k);
            self.full_growth_err = 0.5 * (10.0 / (0.9 * self.floor_pow)).powf(-k / 0.7);
        }
    }

    /// The factor of the next step after accepting one with norm `err` ≤ 1; updates the memory.
    #[inline]
    pub fn accepted(&mut self, err: f64, k: f64) -> f64 {
        self.refresh(k);
        // Below `full_growth_err` the factor is clamped to 10 whatever ‖e_prev‖ is
        // (‖e_prev‖^β₂ ≥ 1e-4^β₂), so the two powers are skipped, same result.
        let mut fac = if err <= self.full_growth_err {
            10.0
        } else {
            0.9 * err.powf(-0.7 / k) * self.err_prev_pow
        };
        fac = fac.clamp(0.2, 10.0);
        if self.last_rejected {
            fac = fac.min(1.0);
        }
        self.err_prev = err.max(1e-4);
        self.err_prev_pow = if err <= 1e-4 {
            self.floor_pow
        } else {
            self.err_prev.powf(0.4 / k)
        };
        self.last_rejected = false;
        fac
    }

    /// The factor of the retry after rejecting a step with norm `err` > 1.
    #[inline]
    pub fn rejected(&mut self, err: f64, k: f64) -> f64 {
        self.last_rejected = true;
        (0.9 * err.powf(-1.0 / k)).max(0.2)
    }
}

impl<Sys: ImplicitSystem> Integrator<Sys> {
    /// Hairer's initial step heuristic (HNW I, II.4) from k[0] = F(t, y), in the direction of
    /// `span` and bounded by |span|; returns the magnitude. Its absolute fallbacks (1e-6 when
    /// y or F is negligible) assume t of order one: every guess is raised to 100 ulp-scales of
    /// t (100·ε·|t|), so a segment starting at t = 10⁹ with y = 0 does not begin below the
    /// resolution of t and report a step-size underflow.
    pub(super) fn initial_step(&mut self, span: f64) -> f64 {
        let (dir, span) = (span.signum(), span.abs());
        let all = self.sys.all_parts();
        let order = self.scheme.error_order() - 1.0;
        let d0 = self.scaled_norm(&self.y, &self.y);
        let d1 = self.scaled_norm(&self.k[0], &self.y);
        let floor = 100.0 * f64::EPSILON * self.t.abs();
        let mut h0 = if d0 < 1e-5 || d1 < 1e-5 {
            1e-6
        } else {
            0.01 * d0 / d1
        };
        h0 = h0.max(floor).min(span);
        // Explicit Euler probe: ynew = y + h0 k0, k[1] = F(t + h0, ynew).
        let h0s = dir * h0;
        self.ynew.combine(&self.y, h0s, &[1.0], &self.k[..1], all);
        self.sys.eval(self.t + h0s, &self.ynew, &mut self.k[1]);
        // tmp = k1 − k0.
        self.tmp.copy_from(&self.k[1]);
        self.tmp.axpy(-1.0, &self.k[0], true);
        let d2 = self.scaled_norm(&self.tmp, &self.y) / h0;
        let dm = d1.max(d2);
        let h1 = if !dm.is_finite() {
            h0 * 1e-3
        } else if dm <= 1e-15 {
            (h0 * 1e-3).max(1e-6)
        } else {
            (0.01 / dm).powf(1.0 / (order + 1.0))
        };
        (100.0 * h0)
            .min(h1)
            .max(floor)
            .min(span)
            .max(f64::MIN_POSITIVE)
    }

    /// Weighted RMS norm of `v` with scale atol + rtol |y|, over the controlled parts.
    pub(super) fn scaled_norm(&self, v: &Sys::Vector, y: &Sys::Vector) -> f64 {
        self.sys.error_norm(v, y, y, self.tol)
    }
}
