//! Adjoint mode: dC/dθ (and vector–Jacobian products of observables) from one primal run and
//! one backward sweep, at a cost that does not grow with the number of parameters beyond the
//! model's own products λᵀf_θ.
//!
//! Forward mode carries S = ∂x/∂θ (n × p) along the run: O(n·p) work per step. The adjoint
//! instead
//!
//! 1. runs the event loop without sensitivities (x and q only, O(n) per step) and keeps the
//!    forward record ([`record::Tape`]: every step's dense output, every jump with its states,
//!    modes and switch bits; the memory is stated there);
//! 2. sweeps backwards from T to 0 (`sweep`): λ̇ = −f_xᵀλ − ℓ_xᵀ on each segment with
//!    ∫ (λᵀf_θ + ℓ_θ) dt accumulated, the transpose of every jump (`transpose`), and at the
//!    ends the final and initial terms.
//!
//! Both converge to the same exact dC/dθ; they differ by the integrators' errors (the primal
//! run takes steps chosen for x alone, the sweep for λ and its quadrature).
//!
//! ## What the adjoint leaves out, and when it hands over to forward mode
//! Its events carry t, the modes, the guard slope, transversality and the jumps, but no t'
//! (so no atoms); it returns no S(T), and a trajectory it records has x only. A run that
//! forward mode ends specially — at a Zeno accumulation, whose tail it extrapolates, or with
//! a state stuck on its guard — is not swept: it is solved again in forward mode, which says
//! so in its `zeno` diagnostic and in `Stats::mode`. Errors (a tangential crossing, too many
//! events) are those of forward mode.
//!
//! ## Global error estimate
//! With `Options::global_error` the primal run carries forward mode's estimate of x and C
//! (and keeps its state errors on the tape), the sweep carries the estimate of the VJP
//! (`integrate/adjoint_error.rs`), and `pull_back` judges both at the
//! tolerances asked for by forward mode's rule (`ill_conditioned`, `Solution::error_estimate`).
//!
//! [`crate::vjp::vjp`] is the entry point for reverse-mode callers (a JAX `custom_vjp`, a
//! torch `autograd.Function`): cotangents of C and of observables at sample times in, dθ out;
//! in adjoint mode it calls `pull_back`.
//!
//! ## qp layers
//! A qp read by a flow is solved on the active set its switch bits freeze, so on a segment the
//! flow is smooth and its products λᵀf_x, λᵀf_θ carry the qp's KKT derivative; the switch
//! flips are transposed like any other. At a qp kink at T (a weakly active constraint, a
//! `kink` diagnostic) of a model without states or without a final cost, `gradient` is the
//! derivative from the right and `gradient_left` comes from a second sweep over the same
//! record with every qp on its left side (each the sum of one-sided derivatives along the
//! data's coordinates). A constraint weakly active *along* a flow (a persistent kink,
//! `crate::qp::FlowPieces`), where an event reads its qp, or at T under the final cost of a
//! model with states makes each parameter's derivative follow the piece its own
//! perturbation selects: not linear in the cotangent, so the run is handed over to forward
//! mode (`Handover::QpKink`, said in the `kink` diagnostic).

pub mod record;
mod sweep;
mod transpose;

use crate::error::SolveError;
use crate::model::{At, HybridModel, ModelAlloc};
use crate::qp::Side;
use crate::sample::check_times;
use crate::sink::{EventSink, EventView};
use crate::solution::{Diagnostic, DiagnosticKind, GradientMode, Options, Solution, Stats};
use crate::solve::{is_event_kink, judge, run_loop};
use crate::vjp::Cotangents;
use nalgebra::{Const, DefaultAllocator, OVector};
use record::{Item, JumpKind, Tape};
use std::time::Instant;
use sweep::{sweep, Sample};
use transpose::JumpWork;

/// Why the adjoint hands a run over to forward mode.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Handover {
    /// The primal run ended at a Zeno accumulation (whose tail forward mode extrapolates) or
    /// with a state stuck on its guard: reported in the `zeno` diagnostic.
    Accumulation,
    /// A qp was read at a kink — weakly active along a flow (a persistent kink), where an
    /// event reads it, or at T under a final cost — reported in a `kink` diagnostic: each
    /// parameter's
    /// one-sided derivative follows the piece its own perturbation selects, which is not
    /// linear in a cotangent, so no sweep gives it.
    QpKink,
    /// The record passed [`Options::max_record_bytes`] at time t: reported in a
    /// `record_budget` diagnostic.
    RecordBudget { t: f64, budget: usize },
}

impl Handover {
    /// The diagnostic that carries the note, and the note.
    fn note(self) -> (DiagnosticKind, String) {
        match self {
            Handover::Accumulation => (
                DiagnosticKind::Zeno,
                "adjoint mode does not sweep back through an accumulation: \
                 the gradient was computed in forward mode"
                    .into(),
            ),
            Handover::RecordBudget { t, budget } => (
                DiagnosticKind::RecordBudget,
                format!(
                    "adjoint mode's record of the run passed its budget of {budget} bytes at \
                     t = {}: the gradient was computed in forward mode, whose memory does not \
                     grow with the number of events",
                    crate::error::Time(t)
                ),
            ),
            Handover::QpKink => (
                DiagnosticKind::Kink,
                "adjoint mode cannot sweep back through a qp kink inside the run or under the \
                 final cost at T (each \
                 parameter's one-sided derivative follows its own side of it, which is not \
                 linear in a cotangent): the gradients were computed in forward mode"
                    .into(),
            ),
        }
    }
}

/// The primal run with the tape, its user events to `sink` (without t'), the observables at
/// `cot.times` read from the tape, and the backward sweep with the cotangents: the solution
/// (its `gradient` is w_C dC/dθ + Σ_s w_sᵀ dy(t_s)/dθ, its `gradient_left` at a qp kink
/// w_C dC/dθ from the left) and y(t_s) row-major. `Err(handover)` when the adjoint does not
/// apply and forward mode has to take over.
#[allow(clippy::type_complexity)]
pub(crate) fn pull_back<M: HybridModel, K: EventSink>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
    sink: &mut K,
    cot: &Cotangents<'_>,
) -> Result<Result<(Solution, Vec<f64>), Handover>, SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let start = Instant::now();
    let (mut sol, tape) = match primal(model, params, opts)? {
        Ok(run) => run,
        Err(handover) => return Ok(Err(handover)),
    };
    check_times(cot.times, sol.t_end)?;
    replay_events(model, params, &tape, opts, sink);
    let nobs = model.info().nobservables();
    let mut observables = vec![0.0; cot.times.len() * nobs];
    let mut x = OVector::<f64, M::N>::zeros_generic(model.nstates(), Const::<1>);
    for (i, &t) in cot.times.iter().enumerate() {
        tape.sample(t, x.as_mut_slice());
        let bits = tape.sample_switches(t).ok_or(SolveError::NotRecorded)?;
        model.observe(
            bits,
            At::new(t, &x, params),
            &mut observables[i * nobs..(i + 1) * nobs],
        );
    }
    let samples = sorted_samples(cot, nobs);
    let dt_end = horizon_grad(model, params, opts);
    let out = sweep(model, params, &tape, opts, &dt_end, cot.cost, &samples)?;
    sol.gradient = out.gradient;
    judge_estimate(&mut sol, out.error.as_deref(), params.as_slice(), opts);
    add_sweep_stats(&mut sol.stats, &out.stats);
    if sol
        .diagnostics
        .iter()
        .any(|d| d.kind == DiagnosticKind::Kink)
    {
        model.set_qp_side(Side::Left);
        let left = sweep(model, params, &tape, opts, &dt_end, cot.cost, &[]);
        model.set_qp_side(Side::Right);
        let left = left?;
        sol.gradient_left = Some(left.gradient);
        add_sweep_stats(&mut sol.stats, &left.stats);
    }
    sol.stats.record_bytes = tape.bytes();
    sol.stats.mode = GradientMode::Adjoint;
    sol.stats.wall_seconds = start.elapsed().as_secs_f64();
    Ok(Ok((sol, observables)))
}

/// The global error estimate of an adjoint result, judged at the tolerances asked for (the
/// primal run's own judgement, at [`PRIMAL_TOL_FACTOR`] of them, is not made): the error of C
/// is the primal run's estimate, that of the gradient the sweep's `e_grad` (see
/// `integrate/adjoint_error.rs`). The same `ill_conditioned` rule as forward mode
/// ([`crate::solve::judge`]).
fn judge_estimate(sol: &mut Solution, e_grad: Option<&[f64]>, p: &[f64], opts: &Options) {
    let Some(primal) = sol.error_estimate.take() else {
        return;
    };
    let grad = e_grad.map(|e| (e, sol.gradient.as_slice()));
    let (estimate, diagnostic) = judge(
        (primal.cost, sol.cost),
        grad,
        p,
        (opts.atol, opts.rtol),
        sol.t_end,
    );
    sol.error_estimate = Some(estimate);
    sol.diagnostics.extend(diagnostic);
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

/// The primal run's tolerances relative to the requested ones. Forward mode's error norm
/// covers S (column j weighted by |θ_j|), which holds its steps to the accuracy the gradient
/// needs; the primal run carries no S, and at the requested tolerances its x (the event times,
/// the trajectory λ is integrated along) is the adjoint's largest error: on the thermostat
/// (∫temp, closed form) it left 2.4e-7 relative in dC/dθ at rtol 1e-8 where forward mode
/// leaves 2.2e-9. At 1/100 of them the adjoint is as accurate as forward mode (Tsit5, rtol
/// 1e-8 / 1e-10 / 1e-12: 2.0e-10 / 3.5e-12 / 1.2e-12 against forward's 2.2e-9 / 1.1e-11 /
/// 3.3e-13; Rodas5P 2.6e-9 / 7.1e-12 / 2.6e-12 against 2.7e-9 / 1.4e-11 / 1.9e-12), for
/// about 2.5× the primal steps of a 5th-order method, each O(n). At 1/10 (with the
/// quadrature outside the stepper, `integrate::adjoint`) the thermostat under `auto` leaves
/// 3.5e-9 / 4.2e-10 / 5.8e-12 at rtol 1e-8 / 1e-10 / 1e-12 (forward: 2.2e-9 / 1.1e-11 /
/// 6.4e-13), more than 5× forward mode's error or 5× rtol at 1e-12: this factor, not the
/// sweep, is what keeps the adjoint slower than forward mode on a model whose flow has the p
/// terms (`benches/adjoint.rs`, chain: 1222 primal steps against forward mode's 249–398).
///
/// The primal's absolute tolerance is this factor times min(atol, rtol): with atol > rtol
/// (rtol 1e-12 at the default atol 1e-10) an O(1) state would be held to atol alone, looser
/// than the relative accuracy asked of the gradient, which reads x through G's sensitivity
/// to it: the stiff relay's G_τ = −λ_u(−1 − u)/τ² amplifies an error of u in its transient
/// ~90× into dC/dτ (rel. 6.2e-11 at rtol 1e-12 with the primal at atol 1e-12; 1.3e-12 at
/// 1e-14, for 2× the primal steps; forward mode holds S_τ relative to itself instead).
pub const PRIMAL_TOL_FACTOR: f64 = 0.01;

/// The primal run with the tape; a [`Handover`] when it did not reach T normally (an
/// accumulation or a stuck state ended it) or met a qp kink that persists along a flow, so
/// forward mode has to take over.
fn primal<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
) -> Result<Result<(Solution, Tape), Handover>, SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let primal = Options {
        sensitivities: false,
        rtol: opts.rtol * PRIMAL_TOL_FACTOR,
        atol: opts.atol.min(opts.rtol) * PRIMAL_TOL_FACTOR,
        ..opts.clone()
    };
    let (sol, tape) = run_loop(model, params, &primal, &mut (), true)?;
    if let Some(t) = tape.as_ref().and_then(Tape::overflowed_at) {
        let budget = opts.max_record_bytes;
        return Ok(Err(Handover::RecordBudget { t, budget }));
    }
    // A final cost read at a qp kink at T: each parameter's side, as for an event's cost
    // (without states θⱼ moves the data along e_j alone, whose side the second sweep takes).
    let final_kink = model.info().has_final_cost
        && nalgebra::Dim::value(&model.nstates()) > 0
        && sol.qp.iter().any(|q| !q.weakly_active().is_empty());
    if !model.qp_flow_kinks().is_empty() || sol.diagnostics.iter().any(is_event_kink) || final_kink
    {
        return Ok(Err(Handover::QpKink));
    }
    Ok(match tape.filter(|t| t.final_state().is_some()) {
        Some(tape) => Ok((sol, tape)),
        None => Err(Handover::Accumulation),
    })
}

/// dT/dθ: the horizon's gradient, or zero when `Options::t_end` overrides it.
fn horizon_grad<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
) -> OVector<f64, M::P>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let mut dt = OVector::<f64, M::P>::zeros_generic(model.nparams(), Const::<1>);
    if opts.t_end.is_none() {
        model.horizon_grad(params, &mut dt);
    }
    dt
}

/// Adds the sweep's counters to the primal run's.
fn add_sweep_stats(stats: &mut Stats, sweep: &Stats) {
    stats.steps += sweep.steps;
    stats.rejected_steps += sweep.rejected_steps;
    stats.rhs_evals += sweep.rhs_evals;
    stats.jac_evals += sweep.jac_evals;
    stats.factorizations += sweep.factorizations;
}

/// Marks a forward solution that stands in for an adjoint one: `Stats::mode` is forward and
/// the diagnostic of the [`Handover`]'s kind (the last one, or a new one at T) carries its
/// note.
pub(crate) fn note_fallback(sol: &mut Solution, handover: Handover) {
    let (kind, note) = handover.note();
    sol.stats.mode = GradientMode::Forward;
    match sol.diagnostics.iter_mut().rfind(|d| d.kind == kind) {
        Some(d) => {
            d.message.push_str("; ");
            d.message.push_str(&note);
        }
        None => sol.diagnostics.push(Diagnostic {
            kind,
            // Where the record passed its budget; T for the others.
            t: match handover {
                Handover::RecordBudget { t, .. } => t,
                _ => sol.t_end,
            },
            message: note,
        }),
    }
}

/// Hands the primal run's user events to `sink`, in time order, as the event loop would
/// have: the guard slope ∇g·f⁻, ∂g/∂t and transversality recomputed from the tape's x⁻ (the
/// same inputs, so the same numbers), the observables on both sides, and no t'.
fn replay_events<M: HybridModel, K: EventSink>(
    model: &M,
    p: &OVector<f64, M::P>,
    tape: &Tape,
    opts: &Options,
    sink: &mut K,
) where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let nobs = model.info().nobservables();
    let (mut obs_minus, mut obs_plus) = (vec![0.0; nobs], vec![0.0; nobs]);
    let mut work = JumpWork::new(model);
    let mut index = 0;
    for item in tape.items() {
        let Item::Jump(j) = item else { continue };
        let JumpKind::Event(k, _) = j.kind else {
            continue;
        };
        let (x_before, x_after) = tape.jump_states(j);
        work.approach(model, p, j, x_before, x_after);
        let gt = work.crossing_grad(model, p, j);
        let (slope, grazing) = work.slope_and_grazing(gt, opts.grazing_tol);
        model.observe(
            &j.sw_before,
            At::new(j.t, work.x_minus(), p),
            &mut obs_minus,
        );
        model.observe(&j.sw_after, At::new(j.t, work.x_plus(), p), &mut obs_plus);
        sink.event(&EventView {
            index,
            event: k,
            t: j.t,
            mode_before: j.mode_before,
            mode_after: j.mode_after,
            guard_slope: slope,
            guard_dt: gt,
            transversal: !grazing,
            dt: &[],
            x_before,
            x_after,
            observables_before: &obs_minus,
            observables_after: &obs_plus,
        });
        index += 1;
    }
}
