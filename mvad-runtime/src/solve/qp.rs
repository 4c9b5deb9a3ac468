//! The run's view of a model's qps: a failed qp named in the error, the `kink`
//! diagnostics, the qps' states at T, and the derivative from the left at a kink.
//!
//! A weakly active constraint at (T, x(T), θ) makes the cost's dependence on θ one-sided:
//! the run's `gradient` (the qps' default side) is the derivative from the right, and a
//! second run with every qp on the left side gives `gradient_left`.

use super::Driver;
use crate::adjoint::record::Tape;
use crate::error::SolveError;
use crate::model::{At, HybridModel, ModelAlloc};
use crate::qp::{QpLayerInfo, Side};
use crate::sink::EventSink;
use crate::solution::{Diagnostic, DiagnosticKind, Options, Solution};
use nalgebra::{Const, DefaultAllocator, OVector};

/// One run from t = 0 to `t_end`: the driver's loop and its end (with the adjoint's record
/// when `tape`, see [`super::run_loop`]), and whether an event read a qp at a kink.
pub(super) fn run<M: HybridModel, K: EventSink>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
    t_end: f64,
    sink: &mut K,
    tape: bool,
) -> Result<(Solution, Option<Tape>, bool), SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    model.clear_qp_flow_kinks();
    let mut d = Driver::new(model, params, opts, t_end, tape);
    d.run(sink).map_err(|e| explain(model, e))?;
    let event_kink = d.qp_event_kink;
    let (sol, tape) = d.finish().map_err(|e| explain(model, e))?;
    Ok((sol, tape, event_kink))
}

impl<M: HybridModel> Driver<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// At user event k at time t (x⁻ in `self.y.x`, x⁺ in `self.x_plus`): a `kink`
    /// diagnostic per weakly active constraint of a qp that the event's guard or reset reads
    /// (solved at x⁻) or its cost term reads (at x⁺). There C is not differentiable in θ:
    /// the perturbed runs read the qp on one side of its kink or the other.
    pub(super) fn report_qp_kinks_at_event(&mut self, k: usize, t: f64) {
        let (model, p) = (self.model, self.p);
        let qps = model.qps();
        for after in [false, true] {
            let reads = |q: &QpLayerInfo| match after {
                false => q.events_before.contains(&k),
                true => q.events_after.contains(&k),
            };
            if !qps.iter().any(reads) {
                continue;
            }
            let x = if after { &self.x_plus } else { &self.y.x };
            // A qp that fails here fails in the event's own evaluations, which report it.
            let Ok(states) = model.qp_states(At::new(t, x, p)) else {
                continue;
            };
            let event = &model.info().events[k].name;
            for (info, state) in qps.iter().zip(&states).filter(|(q, _)| reads(q)) {
                for i in state.weakly_active() {
                    self.qp_event_kink = true;
                    self.diagnostics.push(Diagnostic {
                        kind: DiagnosticKind::Kink,
                        t,
                        message: format!(
                            "qp `{}`, constraint {i}: weakly active (slack and multiplier \
                             both zero) where event `{event}` reads it, so the cost is a kink \
                             of the parameters; `gradient` is the derivative from the right, \
                             `gradient_left` the one from the left",
                            info.name
                        ),
                    });
                }
            }
        }
    }
}

/// A non-finite value that a failed qp produced becomes that qp's error.
fn explain<M: HybridModel>(model: &M, e: SolveError) -> SolveError
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    match (e, model.qp_failure()) {
        (SolveError::NonFinite { t, .. }, Some((q, error))) => SolveError::Qp {
            t,
            qp: model.qps()[q].name.clone(),
            error,
        },
        (e, _) => e,
    }
}

/// The qps' states at T into `sol.qp`, a `kink` diagnostic per weakly active constraint,
/// and at a kink the derivative from the left (a second run).
pub(super) fn report<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
    sol: &mut Solution,
    event_kink: bool,
) -> Result<(), SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    if model.qps().is_empty() {
        return Ok(());
    }
    let t = sol.t_end;
    let x = OVector::<f64, M::N>::from_iterator_generic(
        model.nstates(),
        Const::<1>,
        sol.x_final.iter().copied(),
    );
    let states = model
        .qp_states(At::new(t, &x, params))
        .map_err(|(q, error)| SolveError::Qp {
            t,
            qp: model.qps()[q].name.clone(),
            error,
        })?;
    let mut kink = event_kink;
    for (info, state) in model.qps().iter().zip(&states) {
        for i in state.weakly_active() {
            kink = true;
            sol.diagnostics.push(Diagnostic {
                kind: DiagnosticKind::Kink,
                t,
                message: format!(
                    "qp `{}`, constraint {i}: weakly active (slack and multiplier both zero), \
                     so the solution is a kink of the parameters; `gradient` is the derivative \
                     from the right, `gradient_left` the one from the left",
                    info.name
                ),
            });
        }
    }
    for k in model.qp_flow_kinks() {
        kink = true;
        sol.diagnostics.push(Diagnostic {
            kind: DiagnosticKind::Kink,
            t: k.first,
            message: format!(
                "qp `{}`, constraint {}: weakly active along the flow from t = {} (slack and \
                 multiplier stay zero), so the cost is a kink of the parameters; `gradient` \
                 is the derivative from the right, `gradient_left` the one from the left",
                model.qps()[k.qp].name,
                k.constraint,
                k.first,
            ),
        });
    }
    sol.qp = states;
    if kink && opts.sensitivities {
        model.set_qp_side(Side::Left);
        let left = run(model, params, opts, t, &mut (), false);
        model.set_qp_side(Side::Right);
        sol.gradient_left = Some(left?.0.gradient);
    }
    Ok(())
}
