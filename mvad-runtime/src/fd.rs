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
//! value, and [`fd_plateau`] finds it: the estimate where neighbouring steps agree best,
//! with their difference as its uncertainty. The default relative step of a single
//! difference is [`DEFAULT_REL_STEP`] = 1e-6.

use crate::error::{SolveError, Time};
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
            what: format!(
                "finite-difference step must be finite and positive, got {}",
                Time(rel_step)
            ),
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
                "finite-difference step {} is below the resolution of parameter {i}",
                Time(rel_step)
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

/// The relative steps [`fd_plateau`] tries by default, largest first: a decade apart, from
/// where truncation (O(h²)) dominates to where the run's own error in C, divided by h,
/// does.
pub const STEP_LADDER: [f64; 7] = [1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8];

/// A central difference together with its own error.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FdEstimate {
    /// The estimate of dC/dθ_i.
    pub value: f64,
    /// The relative step it was taken with.
    pub rel_step: f64,
    /// Its uncertainty: the difference from the estimate at the neighbouring step (NaN when
    /// no neighbouring step could be run).
    pub uncertainty: f64,
}

/// A central difference of dC/dθ_i with its own error, from a sweep over `steps` (relative,
/// a decade apart): an estimate D(h) is off by its truncation error, which falls like h²,
/// plus ε_C/h, where ε_C is the run's error in C (its tolerance, and rounding), so no
/// single step is right for every parameter (a time constant of 1e-8 perturbed by 1e-6 of
/// itself moves C by less than the run's tolerance). Where the two errors balance, neighbouring
/// steps agree: the estimate whose larger difference from its two neighbours is smallest
/// lies on the plateau, and that difference is its uncertainty (two neighbours, not one:
/// two noisy estimates can agree by chance). Steps whose runs fail (a perturbation that
/// leaves the parameter's valid range) are left out; with two steps left the uncertainty is
/// their difference, with one it is NaN, with none the last failure is returned.
pub fn fd_plateau<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
    param_index: usize,
    steps: &[f64],
) -> Result<FdEstimate, SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let mut last_err = None;
    let mut points: Vec<(f64, f64)> = Vec::with_capacity(steps.len());
    for &rel_step in steps {
        match fd_gradient(model, params, opts, param_index, rel_step) {
            Ok(v) if v.is_finite() => points.push((rel_step, v)),
            Ok(_) => {}
            Err(e @ (SolveError::NoSuchParam { .. } | SolveError::BadOption { .. })) => {
                return Err(e)
            }
            Err(e) => last_err = Some(e),
        }
    }
    // The spread of the estimate at points[j]: its larger difference from its neighbours
    // (one neighbour at the ends of the sweep).
    let spread = |j: usize| {
        let left = j.checked_sub(1).map(|i| (points[i].1 - points[j].1).abs());
        let right = points.get(j + 1).map(|p| (p.1 - points[j].1).abs());
        match (left, right) {
            (Some(l), Some(r)) => l.max(r),
            (Some(d), None) | (None, Some(d)) => d,
            (None, None) => f64::NAN,
        }
    };
    // Interior points first (two neighbours vouch for them), the ends only without any.
    let interior = 1..points.len().saturating_sub(1);
    let candidates: Vec<usize> = if interior.is_empty() {
        (0..points.len()).collect()
    } else {
        interior.collect()
    };
    let best = candidates
        .into_iter()
        .map(|j| (j, spread(j)))
        .min_by(|a, b| a.1.total_cmp(&b.1));
    match best {
        Some((j, uncertainty)) => Ok(FdEstimate {
            value: points[j].1,
            rel_step: points[j].0,
            uncertainty,
        }),
        None => Err(last_err.unwrap_or(SolveError::BadOption {
            what: "no finite-difference step to try".into(),
        })),
    }
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

    /// At the default tolerance one fixed step is off by far more than the plateau: the
    /// plateau's estimate is within its stated uncertainty of the closed form, and that
    /// uncertainty is small.
    #[test]
    fn plateau_estimate_is_within_its_uncertainty() {
        let ball = Ball::new();
        let p = ball.default_params();
        let opts = Options::default();
        let exact = 2.831_440_814_147_005_5;
        let est = fd_plateau(&ball, &p, &opts, Ball::E, &STEP_LADDER).unwrap();
        assert!(
            est.uncertainty.is_finite() && est.uncertainty < 1e-5 * exact,
            "{est:?}"
        );
        assert!(
            (est.value - exact).abs() <= 2.0 * est.uncertainty + 1e-12,
            "{est:?}"
        );
        assert!(fd_plateau(&ball, &p, &opts, 9, &STEP_LADDER).is_err());
    }
}
