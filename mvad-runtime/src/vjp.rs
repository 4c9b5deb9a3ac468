//! The vector–Jacobian product of a run: what a reverse-mode caller (a JAX `custom_vjp`, a
//! PyTorch `autograd.Function`, the Python package's batches) asks of it. This module is the
//! one entry point: every backward pass goes through [`vjp`], which picks the method from
//! `Options::gradient_mode`.
//!
//! The forward map is θ ↦ (C(θ), y(t_1), …, y(t_m)) with y = h(t, x, θ) the observables at
//! sample times t_s. Given cotangents w_C and w_s, [`vjp`] returns
//!
//! ```text
//!   w_C dC/dθ + Σ_s w_sᵀ dy(t_s)/dθ ,    dy(t_s)/dθ = h_x S(t_s) + h_θ ,
//! ```
//!
//! with the primal values. **Sampling is right-continuous**, as the trajectory record
//! (`Trajectory::sample`, what `simulate` and the measure sample) is: at an event time t_k
//! the sample is y(t_k⁺), after every jump at t_k, and its derivative is the density
//! h_x S(t_k⁺) + h_θ of the observable's measure ([`crate::sample`](mod@crate::sample)); the atom −J_k t_k' that
//! the measure puts there is not part of it (y(t_k) itself jumps as t_k moves with θ: it has
//! no derivative, only one-sided ones). At T the sample is x(T) after any event at T.
//!
//! How it is computed (`Options::gradient_mode`, resolved by the number of parameters for
//! `Auto`):
//! - **forward**: one run carrying S = ∂x/∂θ (O(n·p) per step), recorded when there are sample
//!   times, read at them by [`crate::sample::sample`];
//! - **adjoint**: a primal run and one backward sweep ([`crate::adjoint`]); a sample adds
//!   h_xᵀw_s to λ and h_θᵀw_s to the gradient where the sweep passes t_s. A run the adjoint
//!   does not sweep (an accumulation, a stuck state, a qp at a kink; see [`crate::adjoint`])
//!   is computed forwards instead, and `solution.stats.mode` and a diagnostic say so.
//!
//! [`cost`], [`cost_gradient`], [`observe`] and [`observe_vjp`] are the shapes the Python
//! layers use: [`cost_gradient`] and [`observe_vjp`] are [`vjp`] with w_s = 0 and w_C = 0.

use crate::adjoint;
use crate::error::SolveError;
use crate::model::{HybridModel, ModelAlloc};
use crate::sample::{check_times, sample};
use crate::solution::{GradientMode, Options, Solution};
use crate::solve::solve;
use nalgebra::{DefaultAllocator, Dim, OVector};
use std::time::Instant;

/// The cotangents pulled back by [`vjp`].
#[derive(Clone, Copy, Debug)]
pub struct Cotangents<'a> {
    /// w_C, the cotangent of the cost C.
    pub cost: f64,
    /// The sample times t_s, each in [0, T], in any order (repeats allowed).
    pub times: &'a [f64],
    /// w_s for every sample, row-major: `times.len() × nobservables` (empty when there are
    /// no times).
    pub observables: &'a [f64],
}

/// What [`vjp`] returns.
#[derive(Clone, Debug, PartialEq)]
pub struct Vjp {
    /// C(θ).
    pub cost: f64,
    /// y(t_s), row-major `times.len() × nobservables`, in the order of the times given.
    pub observables: Vec<f64>,
    /// w_C dC/dθ + Σ_s w_sᵀ dy(t_s)/dθ, one entry per parameter.
    pub gradient: Vec<f64>,
    /// The run: events, diagnostics, `stats.mode`; its `gradient` is this one's, and at a qp
    /// kink at T its `gradient_left` is w_C dC/dθ from the left.
    pub solution: Solution,
}

/// The vector–Jacobian product of C and of the observables at `cot.times` (see the module
/// doc), computed as `opts.gradient_mode` says (`opts.sensitivities` and `opts.record` are
/// not looked at).
///
/// Errors: those of [`crate::solve::solve`], and `BadOption` for a non-finite cotangent, a
/// sample time outside [0, T], or a cotangent array of the wrong length.
pub fn vjp<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
    cot: &Cotangents<'_>,
) -> Result<Vjp, SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let start = Instant::now();
    check_cotangents(cot, model.info().nobservables())?;
    if let Some(t_end) = opts.t_end {
        check_times(cot.times, t_end)?;
    }
    let mode = opts.gradient_mode.resolve(model.nparams().value());
    let mut fallback = None;
    if mode == GradientMode::Adjoint {
        let mut events = Vec::new();
        match adjoint::pull_back(model, params, opts, &mut events, cot)? {
            Ok((mut solution, observables)) => {
                solution.events = events;
                return Ok(Vjp {
                    cost: solution.cost,
                    gradient: solution.gradient.clone(),
                    observables,
                    solution,
                });
            }
            Err(reason) => fallback = Some(reason),
        }
    }
    let fwd = Options {
        sensitivities: true,
        record: !cot.times.is_empty(),
        gradient_mode: GradientMode::Forward,
        ..opts.clone()
    };
    let solution = solve(model, params, &fwd)?;
    let mut out = forward_products(model, params, solution, cot)?;
    if let Some(reason) = fallback {
        adjoint::note_fallback(&mut out.solution, reason);
        out.solution.stats.wall_seconds = start.elapsed().as_secs_f64();
    }
    Ok(out)
}

/// The product from a forward-mode run `solution` (with sensitivities, recorded when there
/// are sample times): w_C dC/dθ from the run, plus w_sᵀ dy(t_s)/dθ with
/// dy(t_s)/dθ = h_x S(t_s) + h_θ read from its record ([`crate::sample::sample`]).
fn forward_products<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    mut solution: Solution,
    cot: &Cotangents<'_>,
) -> Result<Vjp, SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let mut gradient: Vec<f64> = solution.gradient.iter().map(|g| cot.cost * g).collect();
    if let Some(left) = solution.gradient_left.as_mut() {
        left.iter_mut().for_each(|g| *g *= cot.cost);
    }
    let mut observables = Vec::new();
    if !cot.times.is_empty() {
        let smp = sample(model, params, &solution, cot.times)?;
        let p = smp.nparams.max(1);
        for (row, &w) in smp.jacobian.chunks_exact(p).zip(cot.observables) {
            for (g, d) in gradient.iter_mut().zip(row) {
                *g += w * d;
            }
        }
        observables = smp.observables;
    }
    solution.gradient.clone_from(&gradient);
    Ok(Vjp {
        cost: solution.cost,
        observables,
        gradient,
        solution,
    })
}

/// C(θ) and dC/dθ (one entry per parameter), in the mode `opts.gradient_mode` says: [`vjp`]
/// with w_C = 1 and no samples.
pub fn cost_gradient<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
) -> Result<(f64, Vec<f64>), SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let cot = Cotangents {
        cost: 1.0,
        times: &[],
        observables: &[],
    };
    let out = vjp(model, params, opts, &cot)?;
    Ok((out.cost, out.gradient))
}

/// C(θ) alone, from a run without sensitivities.
pub fn cost<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
) -> Result<f64, SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let opts = Options {
        sensitivities: false,
        ..opts.clone()
    };
    Ok(solve(model, params, &opts)?.cost)
}

/// The observables at `times`, row-major (time, observable), from a run without
/// sensitivities.
pub fn observe<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
    times: &[f64],
) -> Result<Vec<f64>, SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let opts = Options {
        sensitivities: false,
        record: true,
        ..opts.clone()
    };
    let sol = solve(model, params, &opts)?;
    Ok(sample(model, params, &sol, times)?.observables)
}

/// ȳᵀ ∂y/∂θ for the observables at `times` and a cotangent ȳ laid out like [`observe`]'s
/// result (row-major (time, observable)); one entry per parameter: [`vjp`] with w_C = 0.
pub fn observe_vjp<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
    times: &[f64],
    cotangent: &[f64],
) -> Result<Vec<f64>, SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let cot = Cotangents {
        cost: 0.0,
        times,
        observables: cotangent,
    };
    Ok(vjp(model, params, opts, &cot)?.gradient)
}

/// Finite cotangents of the right length.
fn check_cotangents(cot: &Cotangents<'_>, nobs: usize) -> Result<(), SolveError> {
    let bad = |what: String| Err(SolveError::BadOption { what });
    if !cot.cost.is_finite() {
        return bad(format!("cost cotangent {} is not finite", cot.cost));
    }
    if cot.observables.len() != cot.times.len() * nobs {
        return bad(format!(
            "the cotangent has {} entries; {} sample times × {nobs} observables need {}",
            cot.observables.len(),
            cot.times.len(),
            cot.times.len() * nobs
        ));
    }
    if let Some(w) = cot.observables.iter().find(|w| !w.is_finite()) {
        return bad(format!("observable cotangent {w} is not finite"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::Ball;
    use approx::assert_relative_eq;
    use nalgebra::U4;

    fn setup() -> (Ball, OVector<f64, U4>, Options) {
        let opts = Options {
            rtol: 1e-10,
            atol: 1e-12,
            ..Options::default()
        };
        (
            Ball::new(),
            OVector::<f64, U4>::from([0.8, 9.81, 2.0, 0.0]),
            opts,
        )
    }

    /// The VJP against central differences of ȳ·y(θ) (a loss whose gradient it is), at sample
    /// times on both sides of the two impacts, in both modes.
    #[test]
    fn observe_vjp_against_central_differences() {
        let (ball, p, opts) = setup();
        let times: Vec<f64> = (0..20).map(|i| 0.1 * i as f64 + 0.05).collect();
        let cot: Vec<f64> = (0..times.len() * 2)
            .map(|k| ((k * 7) % 5) as f64 - 2.0)
            .collect();
        let loss = |q: &OVector<f64, U4>| -> f64 {
            let y = observe(&ball, q, &opts, &times).expect("runs");
            y.iter().zip(&cot).map(|(a, b)| a * b).sum()
        };
        for mode in [GradientMode::Forward, GradientMode::Adjoint] {
            let opts = Options {
                gradient_mode: mode,
                ..opts.clone()
            };
            let vjp = observe_vjp(&ball, &p, &opts, &times, &cot).expect("runs");
            for j in 0..4 {
                let h = 1e-6 * p[j].abs().max(1.0);
                let (mut up, mut down) = (p, p);
                up[j] += h;
                down[j] -= h;
                let fd = (loss(&up) - loss(&down)) / (2.0 * h);
                assert_relative_eq!(vjp[j], fd, epsilon = 1e-6, max_relative = 1e-6);
            }
        }
    }

    #[test]
    fn cost_gradient_is_the_solution_gradient_and_bad_cotangents_are_refused() {
        let (ball, p, opts) = setup();
        for mode in [GradientMode::Forward, GradientMode::Adjoint] {
            let opts = Options {
                gradient_mode: mode,
                ..opts.clone()
            };
            let (c, g) = cost_gradient(&ball, &p, &opts).expect("runs");
            assert_relative_eq!(c, 1.8905137123173506, max_relative = 1e-9);
            assert_relative_eq!(g[0], 2.8314408141470055, max_relative = 1e-8);
            let e = observe_vjp(&ball, &p, &opts, &[0.5], &[1.0]).expect_err("one short");
            assert!(matches!(e, SolveError::BadOption { .. }), "{e:?}");
        }
    }
}
