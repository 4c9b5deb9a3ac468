//! The run's view of a model's qps: a failed qp named in the error, the `kink`
//! diagnostics, the qps' states at T, and the derivative from the left at a kink.
//!
//! A weakly active constraint at (T, x(T), θ) makes the cost's dependence on θ one-sided:
//! the run's `gradient` (the qps' default side) is the derivative from the right, and a
//! second run with every qp on the left side gives `gradient_left`.

use super::Driver;
use crate::adjoint::record::Tape;
use crate::error::SolveError;
use crate::model::{At, HybridModel, ModelAlloc, Occurrence};
use crate::qp::{QpLayerInfo, Side};
use crate::sens;
use crate::sink::EventSink;
use crate::solution::{Diagnostic, DiagnosticKind, Options, Solution};
use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector};

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
    /// Between the reset and the cost terms of user event k (occurrence j) at time t (x⁻ in
    /// `self.y.x`, S⁺ in `self.s_plus`): the kinks of the qps its guard or reset reads (at
    /// x⁻), and with sensitivities each column of S⁺ re-derived on its own side of them
    /// (see [`Driver::one_sided_columns`]).
    #[inline]
    pub(super) fn qp_kinks_before_costs(&mut self, k: usize, j: usize, t: f64) {
        if self.model.qps().is_empty() {
            return;
        }
        let kinked = self.qp_kinks_at_event(k, t, false);
        if self.sens && !kinked.is_empty() {
            self.one_sided_columns(k, j, t, &kinked, false);
        }
    }

    /// After the cost terms of user event k: the kinks of the qps its cost term reads (at
    /// x⁺), and with sensitivities the cost's gradient re-derived column by column.
    #[inline]
    pub(super) fn qp_kinks_after_costs(&mut self, k: usize, j: usize, t: f64) {
        if self.model.qps().is_empty() {
            return;
        }
        let kinked = self.qp_kinks_at_event(k, t, true);
        if self.sens && !kinked.is_empty() && self.model.info().events[k].has_cost {
            self.one_sided_columns(k, j, t, &kinked, true);
        }
    }

    /// A `kink` diagnostic per weakly active constraint of a qp that event k reads: its
    /// guard or reset (solved at x⁻) or, `after`, its cost term (at x⁺). There C is not
    /// differentiable in θ: the perturbed runs read the qp on one side of its kink or the
    /// other. Returns the qps at a kink.
    fn qp_kinks_at_event(&mut self, k: usize, t: f64, after: bool) -> Vec<usize> {
        let (model, p) = (self.model, self.p);
        let qps = model.qps();
        let reads = |q: &QpLayerInfo| match after {
            false => q.events_before.contains(&k),
            true => q.events_after.contains(&k),
        };
        if !qps.iter().any(reads) {
            return Vec::new();
        }
        let x = if after { &self.x_plus } else { &self.y.x };
        // A qp that fails here fails in the event's own evaluations, which report it.
        let Ok(states) = model.qp_states(At::new(t, x, p)) else {
            return Vec::new();
        };
        let event = &model.info().events[k].name;
        let mut kinked = Vec::new();
        for (q, (info, state)) in qps.iter().zip(&states).enumerate() {
            let weak = state.weakly_active();
            if !reads(info) || weak.is_empty() {
                continue;
            }
            kinked.push(q);
            self.qp_event_kink = true;
            for i in weak {
                let message = format!(
                    "qp `{}`, constraint {i}: weakly active (slack and multiplier both zero) \
                     {EVENT_KINK}{event}` reads it, so the cost is a kink of the parameters; \
                     `gradient` is the derivative from the right, `gradient_left` the one \
                     from the left",
                    info.name
                );
                // Read before and after the jump at the same kink: one diagnostic.
                let known = |d: &Diagnostic| d.t == t && d.message == message;
                if !self
                    .diagnostics
                    .iter()
                    .rev()
                    .take_while(|d| d.t == t)
                    .any(known)
                {
                    self.diagnostics.push(Diagnostic {
                        kind: DiagnosticKind::Kink,
                        t,
                        message,
                    });
                }
            }
        }
        kinked
    }

    /// At event k, where the qps `kinked` are read at a kink: column j of the jump moves
    /// the qps' data along its own direction — (dx, dθ, dt) = (S⁻_j + f⁻t'_j, e_j, t'_j) for
    /// the reset at x⁻, (S⁺_j + f⁺t'_j, e_j, t'_j) for the cost at x⁺ — and the one-sided
    /// derivative along it is that of one smooth piece of each qp (`HybridModel::qp_piece`),
    /// not a sum of one-sided derivatives along the data's coordinates. So each column is
    /// derived again with the qps pinned to its pieces (`HybridModel::pin_qp`): S⁺_j by
    /// the saltation update with that piece's R_x, R_θ, R_t (before the costs), or the
    /// event cost's gradient g_j by the difference between that piece's
    /// φ_x(S⁺_j + f⁺t'_j) + φ_θⱼ + φ_t t'_j and the unpinned one (after them). A qp that
    /// fails here fails in the event's evaluations, which report it. Allocates (at such
    /// events only).
    fn one_sided_columns(&mut self, k: usize, j: usize, t: f64, kinked: &[usize], after: bool) {
        let (model, p) = (self.model, self.p);
        let (n, np) = (model.nstates(), model.nparams());
        let sizes: Vec<usize> = kinked.iter().map(|&q| model.qps()[q].kinds.len()).collect();
        let x = if after { &self.x_plus } else { &self.y.x };
        let (s, f) = match after {
            false => (&self.y.s, &self.f_minus),
            true => (&self.s_plus, &self.f_plus),
        };
        // Per column, the pieces of the kinked qps, concatenated.
        let mut pieces = vec![Vec::new(); np.value()];
        let mut active = vec![false; sizes.iter().copied().max().unwrap_or(0)];
        for (col, piece) in pieces.iter_mut().enumerate() {
            let mut dx = s.column(col).clone_owned();
            dx.axpy(self.dt[col], f, 1.0);
            for (&q, &m) in kinked.iter().zip(&sizes) {
                let dir = (&dx, col, self.dt[col]);
                match model.qp_piece(q, At::new(t, x, p), dir, &mut active[..m]) {
                    Some(true) => piece.extend_from_slice(&active[..m]),
                    _ => return,
                }
            }
        }
        let occ = Occurrence::new(k, j);
        let pin = |piece: Option<&Vec<bool>>| {
            let mut at = 0;
            for (&q, &m) in kinked.iter().zip(&sizes) {
                model.pin_qp(q, piece.map(|b| &b[at..at + m]));
                at += m;
            }
        };
        let mut done = vec![false; np.value()];
        if after {
            let (mut cx0, mut cp0) = (
                OVector::zeros_generic(n, Const::<1>),
                OVector::zeros_generic(np, Const::<1>),
            );
            let (mut cx, mut cp) = (cx0.clone(), cp0.clone());
            let phi_t0 = model.event_cost_grad(occ, At::new(t, x, p), &mut cx0, &mut cp0);
            for col in 0..np.value() {
                if done[col] {
                    continue;
                }
                pin(Some(&pieces[col]));
                let phi_t = model.event_cost_grad(occ, At::new(t, x, p), &mut cx, &mut cp);
                pin(None);
                cx -= &cx0;
                for c in col..np.value() {
                    if done[c] || pieces[c] != pieces[col] {
                        continue;
                    }
                    let mut total = self.s_plus.column(c).clone_owned();
                    total.axpy(self.dt[c], &self.f_plus, 1.0);
                    self.g_ev[c] +=
                        cx.dot(&total) + (cp[c] - cp0[c]) + (phi_t - phi_t0) * self.dt[c];
                    done[c] = true;
                }
            }
            return;
        }
        let mut rx = OMatrix::<f64, M::N, M::N>::zeros_generic(n, n);
        let mut rp = OMatrix::<f64, M::N, M::P>::zeros_generic(n, np);
        let mut rt = OVector::<f64, M::N>::zeros_generic(n, Const::<1>);
        let mut work = rt.clone();
        let mut s_col = rp.clone();
        for col in 0..np.value() {
            if done[col] {
                continue;
            }
            pin(Some(&pieces[col]));
            model.reset_jac(occ, At::new(t, x, p), &mut rx, &mut rp, &mut rt);
            pin(None);
            let (s, fm, fp) = (&self.y.s, &self.f_minus, &self.f_plus);
            sens::jump(&rx, &rp, &rt, s, fm, fp, &self.dt, &mut work, &mut s_col);
            for c in col..np.value() {
                if done[c] || pieces[c] != pieces[col] {
                    continue;
                }
                self.s_plus.column_mut(c).copy_from(&s_col.column(c));
                done[c] = true;
            }
        }
    }
}

/// Whether `d` is the `kink` diagnostic of a qp read by an event at a kink (see
/// `Driver::qp_kinks_at_event`, the only place that writes it).
pub(crate) fn is_event_kink(d: &Diagnostic) -> bool {
    d.kind == DiagnosticKind::Kink && d.message.contains(EVENT_KINK)
}

/// What the message of an event's qp kink says, and [`is_event_kink`] looks for.
const EVENT_KINK: &str = "where event `";

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
