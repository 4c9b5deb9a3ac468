//! What a differentiable layer (a JAX `custom_vjp`, a PyTorch `autograd.Function`) asks of a
//! run: the value on the way forward, the vector–Jacobian product on the way back.
//!
//! - the cost: C(θ) alone ([`cost`]), or with dC/dθ ([`cost_gradient`]); the layer's
//!   backward pass is θ̄ = c̄ · dC/dθ;
//! - observables at sample times tᵢ: yᵢₒ = hₒ(tᵢ, x(tᵢ), θ) ([`observe`], a run without
//!   sensitivities) and, for a cotangent ȳ of the same shape, ([`observe_vjp`])
//!
//! ```text
//!   θ̄_j = Σᵢ Σₒ ȳᵢₒ (h_x S(tᵢ) + h_θ)ₒⱼ ,
//! ```
//!
//!   the density of each observable's measure at tᵢ contracted with ȳ ([`crate::sample`]).
//!
//! This module is the one place that decides how the backward passes are computed. Today they
//! carry the forward sensitivities S = ∂x/∂θ along the run (cost ∝ number of params); an
//! adjoint pass (one backward sweep whose cost does not grow with the number of params)
//! replaces the bodies of [`cost_gradient`] and [`observe_vjp`] and no caller changes.

use crate::error::SolveError;
use crate::model::{HybridModel, ModelAlloc};
use crate::sample::{check_times, sample};
use crate::solution::Options;
use crate::solve::solve;
use nalgebra::{DefaultAllocator, OVector};

/// C(θ) and dC/dθ (one entry per parameter).
pub fn cost_gradient<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
) -> Result<(f64, Vec<f64>), SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let opts = Options {
        sensitivities: true,
        ..opts.clone()
    };
    let sol = solve(model, params, &opts)?;
    Ok((sol.cost, sol.gradient))
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
/// result (row-major (time, observable)); one entry per parameter.
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
    let m = model.info().nobservables();
    if cotangent.len() != times.len() * m {
        return Err(SolveError::BadOption {
            what: format!(
                "the cotangent has {} entries; {} sample times × {m} observables need {}",
                cotangent.len(),
                times.len(),
                times.len() * m
            ),
        });
    }
    if let Some(t_end) = opts.t_end {
        check_times(times, t_end)?;
    }
    let opts = Options {
        sensitivities: true,
        record: true,
        ..opts.clone()
    };
    let sol = solve(model, params, &opts)?;
    let smp = sample(model, params, &sol, times)?;
    let p = smp.nparams;
    let mut vjp = vec![0.0; p];
    for (row, &w) in smp.jacobian.chunks_exact(p.max(1)).zip(cotangent) {
        for (v, d) in vjp.iter_mut().zip(row) {
            *v += w * d;
        }
    }
    Ok(vjp)
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
    /// times on both sides of the two impacts.
    #[test]
    fn observe_vjp_against_central_differences() {
        let (ball, p, opts) = setup();
        let times: Vec<f64> = (0..20).map(|i| 0.1 * i as f64 + 0.05).collect();
        let cot: Vec<f64> = (0..times.len() * 2)
            .map(|k| ((k * 7) % 5) as f64 - 2.0)
            .collect();
        let vjp = observe_vjp(&ball, &p, &opts, &times, &cot).expect("runs");
        let loss = |q: &OVector<f64, U4>| -> f64 {
            let y = observe(&ball, q, &opts, &times).expect("runs");
            y.iter().zip(&cot).map(|(a, b)| a * b).sum()
        };
        for j in 0..4 {
            let h = 1e-6 * p[j].abs().max(1.0);
            let (mut up, mut down) = (p, p);
            up[j] += h;
            down[j] -= h;
            let fd = (loss(&up) - loss(&down)) / (2.0 * h);
            assert_relative_eq!(vjp[j], fd, epsilon = 1e-6, max_relative = 1e-6);
        }
    }

    #[test]
    fn cost_gradient_is_the_solution_gradient_and_bad_cotangents_are_refused() {
        let (ball, p, opts) = setup();
        let (c, g) = cost_gradient(&ball, &p, &opts).expect("runs");
        assert_relative_eq!(c, 1.8905137123173506, max_relative = 1e-9);
        assert_relative_eq!(g[0], 2.8314408141470055, max_relative = 1e-8);
        let e = observe_vjp(&ball, &p, &opts, &[0.5], &[1.0]).expect_err("one short");
        assert!(matches!(e, SolveError::BadOption { .. }), "{e:?}");
    }
}
