//! The run's view of a model's qps: a failed qp named in the error, the `kink`
//! diagnostics, the qps' states at T, and the derivative from the left at a kink.
//!
//! A weakly active constraint at (T, x(T), θ) makes the cost's dependence on θ one-sided:
//! the run's `gradient` (the qps' default side) is the derivative from the right, and a
//! second run with every qp on the left side gives `gradient_left`.

use super::Driver;
use crate::adjoint::record::Tape;
use crate::error::SolveError;
use crate::model::{At, AtOf, HybridModel, ModelAlloc, Occurrence};
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
    /// event cost's gradient by [`one_sided_cost`] (after them). A qp that fails here fails
    /// in the event's evaluations, which report it. Allocates (at such events only).
    fn one_sided_columns(&mut self, k: usize, j: usize, t: f64, kinked: &[usize], after: bool) {
        let (model, p) = (self.model, self.p);
        let (n, np) = (model.nstates(), model.nparams());
        let x = if after { &self.x_plus } else { &self.y.x };
        let (s, f) = match after {
            false => (&self.y.s, &self.f_minus),
            true => (&self.s_plus, &self.f_plus),
        };
        let dir = ParamDirections { s, f, dt: &self.dt };
        let Some(pieces) = pieces_along(model, At::new(t, x, p), &dir, kinked) else {
            return;
        };
        let occ = Occurrence::new(k, j);
        if after {
            let cost =
                |at: AtOf<'_, M>, cx: &mut _, cp: &mut _| model.event_cost_grad(occ, at, cx, cp);
            let at = At::new(t, &self.x_plus, p);
            one_sided_cost(model, at, &dir, kinked, &pieces, cost, &mut self.g_ev);
            return;
        }
        let mut rx = OMatrix::<f64, M::N, M::N>::zeros_generic(n, n);
        let mut rp = OMatrix::<f64, M::N, M::P>::zeros_generic(n, np);
        let mut rt = OVector::<f64, M::N>::zeros_generic(n, Const::<1>);
        let mut work = rt.clone();
        let mut s_col = rp.clone();
        let mut done = vec![false; np.value()];
        for col in 0..np.value() {
            if done[col] {
                continue;
            }
            pin(model, kinked, Some(&pieces[col]));
            model.reset_jac(occ, At::new(t, x, p), &mut rx, &mut rp, &mut rt);
            pin(model, kinked, None);
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

    /// At T, where the final cost reads the qps at a kink (a weakly active constraint at
    /// (T, x(T))): its gradient, added into `grad`, re-derived column by column along each
    /// parameter's own direction (dx, dθ, dt) = (S_j(T) + f(T) dT/dθ_j, e_j, dT/dθ_j), as an
    /// event's cost term is ([`one_sided_cost`]). Allocates (at such an end only).
    pub(super) fn qp_kinks_at_end(
        &self,
        x: &OVector<f64, M::N>,
        s: &OMatrix<f64, M::N, M::P>,
        f: &OVector<f64, M::N>,
        grad: &mut OVector<f64, M::P>,
    ) {
        let (model, p, t) = (self.model, self.p, self.t_end);
        if model.qps().is_empty() || !model.info().has_final_cost {
            return;
        }
        let at = At::new(t, x, p);
        // A qp that fails here fails in the final cost's evaluation, which reports it.
        let Ok(states) = model.qp_states(at) else {
            return;
        };
        let kinked: Vec<usize> = (0..states.len())
            .filter(|&q| !states[q].weakly_active().is_empty())
            .collect();
        if kinked.is_empty() {
            return;
        }
        let dir = ParamDirections {
            s,
            f,
            dt: &self.dt_end,
        };
        if let Some(pieces) = pieces_along(model, at, &dir, &kinked) {
            let cost = |at: AtOf<'_, M>, cx: &mut _, cp: &mut _| model.final_cost_grad(at, cx, cp);
            one_sided_cost(model, at, &dir, &kinked, &pieces, cost, grad);
        }
    }
}

/// Each parameter's direction through the data of a point: (dx, dθ, dt) = (S_j + f t'_j,
/// e_j, t'_j).
struct ParamDirections<'a, M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// S, the state's sensitivities.
    s: &'a OMatrix<f64, M::N, M::P>,
    /// f, the state's rate.
    f: &'a OVector<f64, M::N>,
    /// t', the time's sensitivities.
    dt: &'a OVector<f64, M::P>,
}

/// Per parameter j, the pieces of the qps `kinked` (concatenated, in order) that the data at
/// `at` select along j's direction (dx, dθ, dt) = (S_j + f t'_j, e_j, t'_j) on the qps'
/// side (`HybridModel::qp_piece`); `None` when a qp cannot tell.
fn pieces_along<M: HybridModel>(
    model: &M,
    at: AtOf<'_, M>,
    dir: &ParamDirections<'_, M>,
    kinked: &[usize],
) -> Option<Vec<Vec<bool>>>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let (s, f, dt) = (dir.s, dir.f, dir.dt);
    let sizes: Vec<usize> = kinked.iter().map(|&q| model.qps()[q].kinds.len()).collect();
    let mut active = vec![false; sizes.iter().copied().max().unwrap_or(0)];
    let mut pieces = vec![Vec::new(); model.nparams().value()];
    for (col, piece) in pieces.iter_mut().enumerate() {
        let mut dx = s.column(col).clone_owned();
        dx.axpy(dt[col], f, 1.0);
        for (&q, &m) in kinked.iter().zip(&sizes) {
            match model.qp_piece(q, at, (&dx, col, dt[col]), &mut active[..m]) {
                Some(true) => piece.extend_from_slice(&active[..m]),
                _ => return None,
            }
        }
    }
    Some(pieces)
}

/// Pins the qps `kinked` to the concatenated active sets `pieces` (`None` unpins them).
fn pin<M: HybridModel>(model: &M, kinked: &[usize], pieces: Option<&Vec<bool>>)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let mut from = 0;
    for &q in kinked {
        let m = model.qps()[q].kinds.len();
        model.pin_qp(q, pieces.map(|b| &b[from..from + m]));
        from += m;
    }
}

/// A cost term c(t, x, θ) read at a kink of the qps `kinked`, whose gradient (∂c/∂x, ∂c/∂θ,
/// ∂c/∂t from `cost_grad`) is the sum of one-sided derivatives along the data's coordinates:
/// adds to `grad[j]`, per parameter, the difference between the piece j selects (`pieces`,
/// pinned) and the unpinned one of c_x·(S_j + f t'_j) + c_θj + c_t t'_j, so that `grad[j]`
/// holds the one-sided derivative along j's own direction `dir`.
fn one_sided_cost<M: HybridModel>(
    model: &M,
    at: AtOf<'_, M>,
    dir: &ParamDirections<'_, M>,
    kinked: &[usize],
    pieces: &[Vec<bool>],
    cost_grad: impl Fn(AtOf<'_, M>, &mut OVector<f64, M::N>, &mut OVector<f64, M::P>) -> f64,
    grad: &mut OVector<f64, M::P>,
) where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let (s, f, dt) = (dir.s, dir.f, dir.dt);
    let (n, np) = (model.nstates(), model.nparams());
    let (mut cx0, mut cp0) = (
        OVector::zeros_generic(n, Const::<1>),
        OVector::zeros_generic(np, Const::<1>),
    );
    let (mut cx, mut cp) = (cx0.clone(), cp0.clone());
    let c_t0 = cost_grad(at, &mut cx0, &mut cp0);
    let mut done = vec![false; np.value()];
    for col in 0..np.value() {
        if done[col] {
            continue;
        }
        pin(model, kinked, Some(&pieces[col]));
        let c_t = cost_grad(at, &mut cx, &mut cp);
        pin(model, kinked, None);
        cx -= &cx0;
        for c in col..np.value() {
            if done[c] || pieces[c] != pieces[col] {
                continue;
            }
            let mut total = s.column(c).clone_owned();
            total.axpy(dt[c], f, 1.0);
            grad[c] += cx.dot(&total) + (cp[c] - cp0[c]) + (c_t - c_t0) * dt[c];
            done[c] = true;
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
