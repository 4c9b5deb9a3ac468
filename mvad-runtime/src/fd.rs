//! Finite-difference checks of dC/dθ: central differences and a step sweep.
//!
//! For parameter i the absolute step is h = rel_step · max(|θ_i|, 1), or rel_step · |θ_i|
//! for a parameter smaller than that ([`fd_step`]), so a time constant of 1e-8 is perturbed
//! relative to its own size and never changes sign, and
//!
//! ```text
//!   dC/dθ_i ≈ (C(θ + h e_i) − C(θ − h e_i)) / (θ_i⁺ − θ_i⁻)
//! ```
//!
//! with the denominator taken from the perturbed values actually represented in floating
//! point. Each evaluation is a primal run (`sensitivities` and `record` off). The truncation
//! error is O(h²) while the rounding error grows like ε_C/h, where ε_C is the run's
//! tolerance-level error in C, hence the sweep: the plateau of a sweep is the trustworthy
//! value. The default relative step is [`DEFAULT_REL_STEP`] = 1e-6.

use crate::error::SolveError;
use crate::model::{HybridModel, ModelAlloc};
use crate::solution::Options;
use crate::solve::solve_with;
use nalgebra::{DefaultAllocator, OVector};

/// The absolute central-difference step for a parameter of value `theta`:
/// h = rel_step · max(|θ|, 1), except that a parameter smaller than that step (a time
/// constant of 1e-8, say) gets the purely relative h = rel_step · |θ|, so θ ± h never
/// changes sign.
pub fn fd_step(theta: f64, rel_step: f64) -> f64 {
    let h = rel_step * theta.abs().max(1.0);
    if theta != 0.0 && h >= theta.abs() {
        rel_step * theta.abs()
    } else {
        h
    }
}

/// Default relative step of the central differences.
pub const DEFAULT_REL_STEP: f64 = 1e-6;

/// One point of a step sweep.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FdPoint {
    /// The relative step.
    pub rel_step: f64,
    /// The absolute step h actually used.
    pub step: f64,
    /// The central-difference estimate of dC/dθ_i.
    pub value: f64,
}

/// Central-difference estimate of dC/dθ_i with relative step `rel_step` (see the module doc).
pub fn fd_gradient<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
    param_index: usize,
    rel_step: f64,
) -> Result<f64, SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let i = param_index;
    if i >= params.len() {
        return Err(SolveError::NoSuchParam {
            index: i,
            count: params.len(),
        });
    }
    if !(rel_step.is_finite() && rel_step > 0.0) {
        return Err(SolveError::BadOption {
            what: format!("finite-difference step must be finite and positive, got {rel_step}"),
        });
    }
    let h = fd_step(params[i], rel_step);
    let mut plus = params.clone();
    let mut minus = params.clone();
    plus[i] += h;
    minus[i] -= h;
    let denom = plus[i] - minus[i];
    if denom == 0.0 {
        return Err(SolveError::BadOption {
            what: format!(
                "finite-difference step {rel_step} is below the resolution of parameter {i}"
            ),
        });
    }
    // Primal runs only, without the global error estimate (a difference needs C alone).
    let opts = Options {
        sensitivities: false,
        record: false,
        global_error: false,
        ..opts.clone()
    };
    let cp = solve_with(model, &plus, &opts, &mut ())?.cost;
    let cm = solve_with(model, &minus, &opts, &mut ())?.cost;
    Ok((cp - cm) / denom)
}

/// Central differences for every parameter (2p primal runs).
pub fn fd_full_gradient<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
    rel_step: f64,
) -> Result<Vec<f64>, SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    (0..params.len())
        .map(|i| fd_gradient(model, params, opts, i, rel_step))
        .collect()
}

/// Central differences of dC/dθ_i for each relative step in `steps` (for tests and
/// `mvad fdcheck`).
pub fn fd_sweep<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
    param_index: usize,
    steps: &[f64],
) -> Result<Vec<FdPoint>, SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    steps
        .iter()
        .map(|&rel_step| {
            Ok(FdPoint {
                rel_step,
                value: fd_gradient(model, params, opts, param_index, rel_step)?,
                step: fd_step(params[param_index], rel_step),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::Ball;
    use approx::assert_relative_eq;

    #[test]
    fn fd_matches_e1_reference_and_sweep_has_a_plateau() {
        let ball = Ball::new();
        let p = ball.default_params();
        let opts = Options {
            rtol: 1e-12,
            atol: 1e-14,
            method: crate::solution::Method::Tsit5,
            ..Options::default()
        };
        let d = fd_gradient(&ball, &p, &opts, Ball::E, 1e-5).unwrap();
        assert_relative_eq!(d, 2.831_440_814_147_005_5, max_relative = 1e-6);
        let sweep = fd_sweep(&ball, &p, &opts, Ball::E, &[1e-3, 1e-4, 1e-5]).unwrap();
        assert_eq!(sweep.len(), 3);
        // O(h²) truncation: the 1e-3 estimate is worse than the 1e-4 one.
        let err = |v: f64| (v - 2.831_440_814_147_005_5).abs();
        assert!(err(sweep[1].value) < err(sweep[0].value));
        assert!(fd_gradient(&ball, &p, &opts, 9, 1e-6).is_err());
        assert!(fd_gradient(&ball, &p, &opts, 0, -1.0).is_err());
    }
}
