//! The vector–Jacobian product of a run: what a reverse-mode caller (a JAX `custom_vjp`, a
//! torch `autograd.Function`) needs.
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
//! h_x S(t_k⁺) + h_θ; the atom −J_k t_k' that the measure puts there is not part of it (y(t_k)
//! itself jumps as t_k moves with θ: it has no derivative, only one-sided ones). At T the
//! sample is x(T) after any event at T.
//!
//! In adjoint mode ([`GradientMode::Adjoint`], or `Auto` with many parameters) a sample adds
//! h_xᵀw_s to λ and h_θᵀw_s to the gradient where the backward sweep passes t_s; in forward
//! mode the recorded S is sampled. Runs the adjoint hands to forward mode (accumulations) are
//! computed forwards, as [`crate::solve::solve`] does.

use super::sweep::{sweep, Sample};
use super::{add_sweep_stats, horizon_grad, note_fallback, primal, replay_events};
use crate::error::SolveError;
use crate::model::{HybridModel, ModelAlloc};
use crate::solution::{GradientMode, Options, Solution};
use crate::solve::run_loop;
use nalgebra::{Const, DefaultAllocator, Dim, OVector};
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
    /// The run: events, diagnostics, `stats.mode` (its `gradient` is this one's).
    pub solution: Solution,
}

/// The vector–Jacobian product of C and of the observables at `cot.times` (see the module
/// doc), computed as `opts.gradient_mode` says (`opts.sensitivities` is ignored).
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
    let nobs = model.info().nobservables();
    check_cotangents(cot, nobs)?;
    let mode = opts.gradient_mode.resolve(model.nparams().value());
    let adjoint = if mode == GradientMode::Adjoint {
        primal(model, params, opts)?
    } else {
        None
    };
    let Some((mut sol, tape)) = adjoint else {
        let mut out = forward_vjp(model, params, opts, cot)?;
        if mode == GradientMode::Adjoint {
            note_fallback(&mut out.solution);
        }
        out.solution.stats.wall_seconds = start.elapsed().as_secs_f64();
        return Ok(out);
    };
    check_times(cot.times, sol.t_end)?;
    replay_events(model, params, &tape, opts, &mut sol.events);
    let samples = sorted_samples(cot, nobs);
    let mut observables = vec![0.0; cot.times.len() * nobs];
    let mut x = OVector::<f64, M::N>::zeros_generic(model.nstates(), Const::<1>);
    for (i, &t) in cot.times.iter().enumerate() {
        tape.sample(t, x.as_mut_slice());
        model.observe(t, &x, params, &mut observables[i * nobs..(i + 1) * nobs]);
    }
    let dt_end = horizon_grad(model, params, opts);
    let out = sweep(model, params, &tape, opts, &dt_end, cot.cost, &samples)?;
    sol.gradient = out.gradient.clone();
    add_sweep_stats(&mut sol.stats, &out.stats, &tape, start);
    Ok(Vjp {
        cost: sol.cost,
        observables,
        gradient: out.gradient,
        solution: sol,
    })
}

/// The same product in forward mode: dC/dθ from the run and S(t_s) from its recorded
/// trajectory (right-continuous, interpolated from the step's nodes).
fn forward_vjp<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
    cot: &Cotangents<'_>,
) -> Result<Vjp, SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let fwd = Options {
        sensitivities: true,
        record: true,
        gradient_mode: GradientMode::Forward,
        ..opts.clone()
    };
    let mut events = Vec::new();
    let (mut sol, _) = run_loop(model, params, &fwd, &mut events, false)?;
    sol.events = events;
    check_times(cot.times, sol.t_end)?;
    let traj = sol.trajectory.as_ref().ok_or(SolveError::NotRecorded)?;
    let (n, np, nobs) = (traj.n, sol.gradient.len(), model.info().nobservables());
    let mut gradient: Vec<f64> = sol.gradient.iter().map(|g| cot.cost * g).collect();
    let mut observables = vec![0.0; cot.times.len() * nobs];
    let (mut yx, mut yp) = (vec![0.0; nobs * n], vec![0.0; nobs * np]);
    let mut x = OVector::<f64, M::N>::zeros_generic(model.nstates(), Const::<1>);
    for (i, &t) in cot.times.iter().enumerate() {
        let (xs, s) = traj.sample(t);
        x.as_mut_slice().copy_from_slice(&xs);
        model.observe(t, &x, params, &mut observables[i * nobs..(i + 1) * nobs]);
        model.observe_jac(t, &x, params, &mut yx, &mut yp);
        for (o, &w) in cot.observables[i * nobs..(i + 1) * nobs].iter().enumerate() {
            if w == 0.0 {
                continue;
            }
            // w (h_x S + h_θ) for observable o; S column-major n × p.
            for (j, g) in gradient.iter_mut().enumerate() {
                let hs: f64 = (0..n).map(|r| yx[o * n + r] * s[j * n + r]).sum();
                *g += w * (hs + yp[o * np + j]);
            }
        }
    }
    Ok(Vjp {
        cost: sol.cost,
        observables,
        gradient,
        solution: sol,
    })
}

/// Finite cotangents of the right length.
fn check_cotangents(cot: &Cotangents<'_>, nobs: usize) -> Result<(), SolveError> {
    let bad = |what: String| Err(SolveError::BadOption { what });
    if !cot.cost.is_finite() {
        return bad(format!("cost cotangent {} is not finite", cot.cost));
    }
    if cot.observables.len() != cot.times.len() * nobs {
        return bad(format!(
            "{} observable cotangents for {} sample times × {nobs} observables",
            cot.observables.len(),
            cot.times.len()
        ));
    }
    if let Some(w) = cot.observables.iter().find(|w| !w.is_finite()) {
        return bad(format!("observable cotangent {w} is not finite"));
    }
    Ok(())
}

/// Every sample time in [0, T].
fn check_times(times: &[f64], t_end: f64) -> Result<(), SolveError> {
    match times.iter().find(|t| !(**t >= 0.0 && **t <= t_end)) {
        Some(t) => Err(SolveError::BadOption {
            what: format!("sample time {t} is outside [0, T] = [0, {t_end}]"),
        }),
        None => Ok(()),
    }
}

/// The samples with their cotangent rows, sorted by time.
fn sorted_samples<'a>(cot: &Cotangents<'a>, nobs: usize) -> Vec<Sample<'a>> {
    let mut s: Vec<Sample<'a>> = cot
        .times
        .iter()
        .enumerate()
        .map(|(i, &t)| Sample {
            t,
            w: &cot.observables[i * nobs..(i + 1) * nobs],
        })
        .collect();
    s.sort_by(|a, b| a.t.total_cmp(&b.t));
    s
}
