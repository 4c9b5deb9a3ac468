//! `auto`'s switching between Tsit5 and Rodas5P (see the module doc of `integrate`): Hairer's
//! test h·‖k₇ − k₆‖/‖y₇ − y₆‖ against Tsit5's real stability boundary after every Tsit5 step,
//! every [`JAC_CHECK_EVERY`] steps h·ρ(f_x) from a power iteration, and back to Tsit5 when
//! Rodas5P's steps would be stable for it.
//!
//! The Jacobian check also catches the stiffness that tight tolerances hide. There the step
//! Tsit5's accuracy allows is itself close to the stability bound (h·ρ ≈ 1, below both
//! thresholds above), although the solution varies far more slowly than its fast modes: a
//! stiff lag tracking cos t with λ = 10⁴ at rtol 1e-10 took 36× the steps of Rodas5P. So a
//! check also counts as stiff when h·ρ > [`JAC_SLOW_HRHO`] and ρ exceeds the solution's own
//! rate max_i |f_i|/max(|x_i|, atol/rtol) by [`SLOW_SOLUTION_FACTOR`]: the fast modes have
//! decayed and it is they, not the solution, that hold the step (an oscillation or a fast
//! transient has a rate near ρ and stays with Tsit5).

use super::{ImplicitSystem, Integrator, Linearised, Scheme, StageVector};
use crate::solution::Method;

/// Real-axis stability boundary of Tsit5 used by the stiffness test (|hλ| beyond it is
/// unstable; the test fires slightly inside it).
const TSIT5_STIFF_BOUND: f64 = 3.25;
/// Accepted stiff-looking Tsit5 steps (with fewer than 6 non-stiff ones in between) before
/// `auto` switches to Rodas5P.
const STIFF_STEPS_TO_SWITCH: usize = 15;
/// Accepted Tsit5 steps between two Jacobian-based stiffness checks under `auto`.
const JAC_CHECK_EVERY: usize = 20;
/// |h|·ρ(f_x) above which a Tsit5 step counts as stiff in the Jacobian check (three checks in
/// a row switch to Rodas5P).
const JAC_STIFF_HRHO: f64 = 0.8;
/// |h|·ρ(f_x) above which a Tsit5 step on a slowly varying solution counts as stiff in the
/// Jacobian check (see the module doc).
const JAC_SLOW_HRHO: f64 = 0.1;
/// ρ(f_x) over the solution's own rate beyond which the solution is slow (see the module doc).
const SLOW_SOLUTION_FACTOR: f64 = 100.0;
/// |h|·ρ(f_x) below which a Rodas5P step counts as non-stiff.
const JAC_NONSTIFF_HRHO: f64 = 0.4;
/// Consecutive non-stiff Rodas5P steps before `auto` switches back to Tsit5.
const NONSTIFF_STEPS_TO_SWITCH: usize = 20;

impl<Sys: ImplicitSystem> Integrator<Sys> {
    /// Auto switching between Tsit5 and Rodas5P after an accepted step.
    pub(super) fn update_stiffness(&mut self) {
        if self.requested != Method::Auto || self.scheme == Scheme::Exact {
            return;
        }
        match self.scheme {
            Scheme::Tsit5 => {
                if self.stiff_ratio > TSIT5_STIFF_BOUND {
                    self.stiff_count += 1;
                    self.nonstiff_count = 0;
                } else {
                    self.nonstiff_count += 1;
                    if self.nonstiff_count >= 6 {
                        self.stiff_count = 0;
                    }
                }
                // Second test (for steps held small by something other than the stability
                // bound, where Hairer's ratio stays low): every JAC_CHECK_EVERY steps compare
                // h with the spectral radius of the Jacobian.
                self.jac_check_count += 1;
                if self.jac_check_count >= JAC_CHECK_EVERY {
                    self.jac_check_count = 0;
                    let rho = self.sys.spectral_radius_at(self.t, &self.y);
                    self.stats.jac_evals += 1;
                    let hrho = self.dense_h.abs() * rho;
                    if hrho > JAC_STIFF_HRHO
                        || (hrho > JAC_SLOW_HRHO
                            && rho > SLOW_SOLUTION_FACTOR * self.solution_rate())
                    {
                        self.jac_stiff_count += 1;
                    } else {
                        self.jac_stiff_count = 0;
                    }
                }
                if self.stiff_count >= STIFF_STEPS_TO_SWITCH || self.jac_stiff_count >= 3 {
                    self.jac_stiff_count = 0;
                    self.jac_check_count = 0;
                    self.scheme = Scheme::Rodas5P;
                    self.stiff_count = 0;
                    self.nonstiff_count = 0;
                    // The FSAL stage is F(t, y) and stays valid for Rodas5P's first stage.
                    self.ctrl.reset(self.scheme.error_order());
                }
            }
            Scheme::Rodas5P => {
                // Back to explicit when the step Rodas5P proposes is well inside Tsit5's
                // stability region (hysteresis against the forward tests).
                let rho = self.sys.linearisation().spectral_radius();
                if self.h * rho < JAC_NONSTIFF_HRHO {
                    self.nonstiff_count += 1;
                } else {
                    self.nonstiff_count = 0;
                }
                if self.nonstiff_count >= NONSTIFF_STEPS_TO_SWITCH {
                    self.scheme = Scheme::Tsit5;
                    self.nonstiff_count = 0;
                    self.stiff_count = 0;
                    self.ctrl.reset(self.scheme.error_order());
                }
            }
            Scheme::Verner9 | Scheme::Exact => {}
        }
    }

    /// The rate at which the solution itself varies, max_i |f_i(t, y)|/max(|y_i|, atol/rtol)
    /// over the primary part (a component below atol/rtol is measured against that floor),
    /// from the FSAL stage the last accepted step left; +∞ when there is none (never stiff by
    /// this test).
    fn solution_rate(&self) -> f64 {
        let Some(slot) = self.fsal_slot else {
            return f64::INFINITY;
        };
        let floor = (self.tol.atol / self.tol.rtol).max(f64::MIN_POSITIVE);
        self.k[slot]
            .primary()
            .iter()
            .zip(self.y.primary())
            .map(|(f, y)| f.abs() / y.abs().max(floor))
            .fold(0.0, f64::max)
    }
}
