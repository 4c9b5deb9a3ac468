//! Roots → live nodes → ordered temporaries: one [`Kernel`] per model function.
//!
//! [`kernels`] differentiates a [`Program`] (all partials land in its arena, so f and
//! its derivatives share subexpressions) and cuts it into straight-line kernels, one per
//! method of the runtime's model trait. A kernel lists its live nodes in topological
//! order and only its *structurally non-zero* outputs, each with a slot in a dense output
//! layout documented on the field that holds it. Matrices are row-major in slots:
//! entry (r, c) of an r×c block is slot r·cols + c. Both back ends (codegen, tape) read
//! the same kernels.
//!
//! Besides the first derivatives, each flow and the running cost get the kernels of the
//! capability products ([`SecondOrderKernels`]): the non-zero entries of G_x and G_θ (for
//! the adjoint's λᵀG_x, λᵀG_θ) and their non-zero derivatives in x and t (for the implicit
//! method's ∂ₓ(G_x S + G_θ)·v and ∂ₜ(G_x S + G_θ)), all taken in the same arena.

use crate::diff::{diff, Var};
use crate::ir::{
    EventInfo, ExprArena, ExprId, ModelInfo, ModelNames, Node, Program, QpLayerInfo, Schedule, Wrt,
};

/// A straight-line function: live nodes in topological order and its non-zero outputs.
#[derive(Clone, Debug, PartialEq)]
pub struct Kernel {
    /// Every node the outputs need (leaves included), in topological order.
    pub nodes: Vec<ExprId>,
    /// Length of the dense output.
    pub len: usize,
    /// The structurally non-zero outputs as (slot, expression), slots ascending.
    pub outputs: Vec<(usize, ExprId)>,
}

impl Kernel {
    /// The kernel computing `exprs` (slot i ← exprs\[i\]), zeros dropped.
    pub fn new(ar: &ExprArena, exprs: &[ExprId]) -> Kernel {
        let outputs: Vec<(usize, ExprId)> = exprs
            .iter()
            .copied()
            .enumerate()
            .filter(|&(_, e)| !ar.is_zero(e))
            .collect();
        let roots: Vec<ExprId> = outputs.iter().map(|&(_, e)| e).collect();
        let live = ar.live(&roots);
        let nodes = (0..live.len())
            .filter(|&i| live[i])
            .map(|i| ExprId(i as u32))
            .collect();
        Kernel {
            nodes,
            len: exprs.len(),
            outputs,
        }
    }

    /// Whether every slot has a (non-zero) output, so no zero fill is needed.
    pub fn is_dense(&self) -> bool {
        self.outputs.len() == self.len
    }

    /// Whether the kernel computes nothing (all outputs zero).
    pub fn is_zero(&self) -> bool {
        self.outputs.is_empty()
    }

    /// Whether any live node satisfies `pred` (reads t, x, θ or a switch bit).
    pub fn uses(&self, ar: &ExprArena, pred: impl Fn(&Node) -> bool) -> bool {
        self.nodes.iter().any(|&id| pred(&ar.node(id)))
    }
}

/// A scalar function and its gradient.
#[derive(Clone, Debug, PartialEq)]
pub struct GradKernels {
    /// The value (1 slot).
    pub value: Kernel,
    /// Slots `[0, n)` ∂/∂x, `[n, n+p)` ∂/∂θ, `n+p` either ∂/∂t (guards, switches, event
    /// and final costs) or the value itself (running cost, whose grad method returns ℓ).
    pub grad: Kernel,
}

/// The kernels of one mode's flow.
#[derive(Clone, Debug, PartialEq)]
pub struct ModeKernels {
    /// f (n slots).
    pub rhs: Kernel,
    /// ∂f/∂x (n×n, row-major).
    pub jac_x: Kernel,
    /// ∂f/∂θ (n×p, row-major).
    pub jac_p: Kernel,
    /// ∂f/∂t (n slots).
    pub dt: Kernel,
    /// Whether f depends on t explicitly.
    pub depends_on_t: bool,
    /// Whether f is a function of θ alone (it reads no state, no t, no switch bit and no qp
    /// solution): along a segment x and S are then linear in t.
    pub constant: bool,
    /// Structurally non-zero entries (row, col) of ∂f/∂x.
    pub sparsity: Vec<(usize, usize)>,
    /// Fused sensitivity kernel: slots `[0, n)` f, then one slot per entry of
    /// `sparsity` (∂f/∂x values, same order), then ∂f/∂θ (n×p row-major). Ṡ = f_x S + f_θ is
    /// formed from these by the back ends with only the non-zero f_x entries.
    pub sens: Kernel,
    /// The non-zero entries of f_x and f_θ, for λᵀf_x and λᵀf_θ: slot e < |x_entries| is
    /// f_x entry e, slot |x_entries| + e is f_θ entry e (entries as in `second`).
    pub jac: Kernel,
    /// The second-order kernels of f (its `x_entries` are `sparsity`).
    pub second: SecondOrderKernels,
}

/// The sparse first derivatives (G_x, G_θ) of a vector function G(t, x, θ) — a mode's flow f,
/// or the running cost ℓ as one row — and their derivatives in x and in t: what the products
///
/// ```text
///   ∂ₓ(G_x S + G_θ)·v = (Σᵢ vᵢ ∂G_x/∂xᵢ) S + Σᵢ vᵢ ∂G_θ/∂xᵢ,
///   ∂ₜ(G_x S + G_θ)   = (∂ₜG_x) S + ∂ₜG_θ
/// ```
///
/// need. "Entry e" numbers the non-zero first derivatives: e < |x_entries| is the G_x entry
/// `x_entries[e]`, e ≥ |x_entries| the G_θ entry `p_entries[e − |x_entries|]`. Only entries
/// that are structurally non-zero are ever formed, so a product costs the number of non-zero
/// second derivatives plus one pass over the non-zero G_x entries per column of S.
#[derive(Clone, Debug, PartialEq)]
pub struct SecondOrderKernels {
    /// Number of rows of G (n for a flow, 1 for ℓ).
    pub rows: usize,
    /// (row, state) of the non-zero entries of G_x, row-major order.
    pub x_entries: Vec<(usize, usize)>,
    /// (row, param) of the non-zero entries of G_θ, row-major order.
    pub p_entries: Vec<(usize, usize)>,
    /// The non-zero ∂(entry e)/∂xᵢ: slot j is the derivative named by `dx_terms[j]`.
    pub dx: Kernel,
    /// (entry e, state i) of each slot of `dx`, e ascending, then i ascending.
    pub dx_terms: Vec<(usize, usize)>,
    /// ∂ₜ of the entries: slot e is ∂ₜ(entry e); for ℓ, slot |entries| + r is ∂ₜG_r (∂ₜℓ).
    /// Zeros dropped.
    pub dt: Kernel,
}

impl SecondOrderKernels {
    /// Number of entries (non-zero first derivatives).
    pub fn nentries(&self) -> usize {
        self.x_entries.len() + self.p_entries.len()
    }
}

/// The kernels of one event.
#[derive(Clone, Debug, PartialEq)]
pub struct EventKernels {
    /// g and (∇ₓg, ∂θg, ∂ₜg).
    pub guard: GradKernels,
    /// x⁺ = R(t, x⁻, θ) (n slots).
    pub reset: Kernel,
    /// Slots `[0, n²)` ∂R/∂x (row-major), `[n², n²+np)` ∂R/∂θ (row-major), then n of ∂R/∂t.
    pub reset_jac: Kernel,
    /// φ_k and (φ_x, φ_θ, φ_t), if the cost has `sum` terms for this event.
    pub cost: Option<GradKernels>,
    /// The times of a time event.
    pub time: Option<TimeKernels>,
}

/// The times of a time event: τ(θ) (or τ(θ, row) for `at each`, or the start of `every`) and
/// ∂τ/∂θ; for `every` also the period and its gradient. Time j of `every` is start + j·period.
#[derive(Clone, Debug, PartialEq)]
pub struct TimeKernels {
    /// τ, or the start of `every` (1 slot).
    pub time: Kernel,
    /// ∂τ/∂θ (p slots).
    pub time_grad: Kernel,
    /// `every`: the period (1 slot) and its gradient (p slots).
    pub period: Option<(Kernel, Kernel)>,
}

/// An event as the back ends see it: its static description and what the kernels add.
#[derive(Clone, Debug, PartialEq)]
pub struct EventMeta {
    /// As lowered ([`crate::ir::Event::info`]); `Trigger::Each { rows: 0 }` until the table
    /// is bound.
    pub info: EventInfo,
    /// The table whose rows an `at each` event runs over (index into `ModelNames::tables`).
    pub table: Option<usize>,
    /// Whether the guard is affine in (x, t) (its derivatives in x and t are functions of θ
    /// alone): along a segment of a constant flow it is then affine in t.
    pub affine_guard: bool,
}

/// Whether a leaf can change along a segment at fixed θ (a state, t, a switch bit, a qp
/// solution or its derivative, a table row).
pub(crate) fn varies_in_time(nd: &Node) -> bool {
    matches!(
        nd,
        Node::State(_)
            | Node::Time
            | Node::Switch(..)
            | Node::QpSol(_)
            | Node::QpDeriv(..)
            | Node::Column(_)
    )
}

/// Whether `e` is affine in (x, t): its derivatives in every state and in t are functions of
/// θ alone ([`varies_in_time`] reads none of them). A guard is continuous (lowering rewrites
/// one that jumps, `lower::guard`), so constant derivatives on both sides of a choice make it
/// affine: a jump cannot hide behind equal slopes.
fn affine_in_state_and_time(ar: &mut ExprArena, e: ExprId, n: usize) -> bool {
    if ar.depends_on(e, |nd| matches!(nd, Node::Switch(..) | Node::Column(_))) {
        return false;
    }
    (0..n).map(Var::State).chain([Var::Time]).all(|v| {
        let d = diff(ar, e, v);
        !ar.depends_on(d, varies_in_time)
    })
}

/// The kernels of one qp: its data and their derivatives, which the back ends hand to the
/// runtime's qp solver.
#[derive(Clone, Debug, PartialEq)]
pub struct QpKernels {
    /// Its static description, as the runtime's qp bank takes it.
    pub info: QpLayerInfo,
    /// The [`Node::QpSol`] index of its first variable.
    pub offset: usize,
    /// Whether a flow or ℓ reads its solution.
    pub in_flow: bool,
    /// The data: slots `[0, v²)` H (row-major), then c (v), A (m×v, row-major), b (m).
    pub data: Kernel,
    /// ∂data/∂(x, θ, t): slot d·(n + p + 1) + w for data slot d and column w
    /// ([`Wrt::column`]).
    pub data_jac: Kernel,
}

/// Everything the back ends need: the arena, names and one kernel per model function.
#[derive(Clone, Debug)]
pub struct ModelKernels {
    /// The arena holding every expression and derivative.
    pub arena: ExprArena,
    /// The program's names, as they were.
    pub names: ModelNames,
    /// Mode names.
    pub mode_names: Vec<String>,
    /// Initial mode.
    pub initial_mode: usize,
    /// Event descriptions.
    pub event_meta: Vec<EventMeta>,
    /// Observable names.
    pub observables: Vec<String>,
    /// x₀(θ) (n slots).
    pub x0: Kernel,
    /// ∂x₀/∂θ (n×p, row-major).
    pub x0_jac: Kernel,
    /// T(θ) (1 slot) and dT/dθ (p slots), if a horizon is declared.
    pub horizon: Option<(Kernel, Kernel)>,
    /// Per mode.
    pub modes: Vec<ModeKernels>,
    /// Per event.
    pub events: Vec<EventKernels>,
    /// Per switching function σ_j: σ_j and (∇ₓσ_j, ∂θσ_j, ∂ₜσ_j).
    pub switches: Vec<GradKernels>,
    /// y = h (nobs slots).
    pub observe: Kernel,
    /// Slots `[0, nobs·n)` ∂h/∂x, then `[nobs·n, nobs·(n+p))` ∂h/∂θ, both row-major.
    pub observe_jac: Kernel,
    /// ℓ and (ℓ_x, ℓ_θ, ℓ), if the cost has `integral` terms.
    pub running_cost: Option<GradKernels>,
    /// Φ and (Φ_x, Φ_θ, Φ_t), if the cost has `final` or static terms.
    pub final_cost: Option<GradKernels>,
    /// The second-order kernels of ℓ as one row (with ∂ₜℓ), if the cost has `integral` terms.
    pub running_cost_second: Option<SecondOrderKernels>,
    /// Per qp, in declaration order.
    pub qps: Vec<QpKernels>,
}

impl ModelKernels {
    /// Number of states n.
    pub fn nstates(&self) -> usize {
        self.names.nstates()
    }
    /// Number of parameters p.
    pub fn nparams(&self) -> usize {
        self.names.nparams()
    }
    /// The model's static description, the one value both back ends give the runtime: the
    /// names, modes, events and observables as lowered, the switch bits
    /// ([`ModelKernels::nswitches`]), which costs and horizon exist, and per mode the
    /// non-zero entries of ∂f/∂x. An `at each` event's `rows` is 0 until its table is bound.
    pub fn info(&self) -> ModelInfo {
        ModelInfo {
            name: self.names.name.clone(),
            states: self.names.states.clone(),
            params: self.names.params.clone(),
            param_defaults: self.names.param_defaults.clone(),
            modes: self.mode_names.clone(),
            initial_mode: self.initial_mode,
            events: self.event_meta.iter().map(|e| e.info.clone()).collect(),
            observables: self.observables.clone(),
            switches: self.nswitches(),
            has_running_cost: self.running_cost.is_some(),
            has_final_cost: self.final_cost.is_some(),
            has_horizon: self.horizon.is_some(),
            jacobian_sparsity: self.modes.iter().map(|m| m.sparsity.clone()).collect(),
        }
    }

    /// The `at each` events whose times are a bare column `TABLE.COL` (so the column itself
    /// must not decrease, which can be checked where the table is read): (column, event).
    pub fn bare_time_columns(&self) -> Vec<(usize, usize)> {
        let mut out = Vec::new();
        for (e, (ev, meta)) in self.events.iter().zip(&self.event_meta).enumerate() {
            let (Some(tk), Some(_)) = (&ev.time, meta.table) else {
                continue;
            };
            if let [(_, id)] = tk.time.outputs[..] {
                if let Node::Column(c) = self.arena.node(id) {
                    out.push((c as usize, e));
                }
            }
        }
        out
    }

    /// Every kernel, for the back ends' scratch sizing and tests.
    pub fn all_kernels(&self) -> Vec<&Kernel> {
        let mut v = vec![&self.x0, &self.x0_jac, &self.observe, &self.observe_jac];
        if let Some((a, b)) = &self.horizon {
            v.push(a);
            v.push(b);
        }
        for m in &self.modes {
            v.extend([&m.rhs, &m.jac_x, &m.jac_p, &m.dt, &m.sens, &m.jac]);
            v.extend([&m.second.dx, &m.second.dt]);
        }
        for e in &self.events {
            v.extend([&e.guard.value, &e.guard.grad]);
            v.extend([&e.reset, &e.reset_jac]);
            if let Some(c) = &e.cost {
                v.extend([&c.value, &c.grad]);
            }
            if let Some(tk) = &e.time {
                v.extend([&tk.time, &tk.time_grad]);
                if let Some((a, b)) = &tk.period {
                    v.extend([a, b]);
                }
            }
        }
        for s in &self.switches {
            v.extend([&s.value, &s.grad]);
        }
        for c in [&self.running_cost, &self.final_cost].into_iter().flatten() {
            v.extend([&c.value, &c.grad]);
        }
        if let Some(c) = &self.running_cost_second {
            v.extend([&c.dx, &c.dt]);
        }
        for q in &self.qps {
            v.extend([&q.data, &q.data_jac]);
        }
        v
    }

    /// Number of switch bits: the kinks' switching functions, then the qps' constraints.
    pub fn nswitches(&self) -> usize {
        self.switches.len()
            + crate::ir::qp_switch_bits(self.qps.iter().map(|q| (q.info.switches, &q.info.kinds)))
    }

    /// Whether the second-order products must be difference quotients: a flow or ℓ reads
    /// the solution of a qp of the state, whose second derivatives the kernels do not have
    /// (the `QpDeriv` leaves are first derivatives; see `ir::Node::QpDeriv`).
    pub fn second_order_by_differences(&self) -> bool {
        self.qps.iter().any(|q| q.info.dynamic && q.in_flow)
    }

    /// The support of the adjoint's gradient quadrature G = −(λᵀf_θ + w ℓ_θ) in `mode`: the
    /// parameters whose column of f_θ (its structural non-zeros, `second.p_entries`, the
    /// entries of `jac_p`) or of ℓ_θ (the θ slots of ℓ's gradient kernel) can be non-zero,
    /// ascending. Both back ends emit it as `ModelAdjoint::gradient_support`.
    pub fn gradient_support(&self, mode: usize) -> Vec<usize> {
        let (n, p) = (self.nstates(), self.nparams());
        let mut on = vec![false; p];
        for &(_, k) in &self.modes[mode].second.p_entries {
            on[k] = true;
        }
        if let Some(rc) = &self.running_cost {
            for &(s, _) in &rc.grad.outputs {
                if (n..n + p).contains(&s) {
                    on[s - n] = true;
                }
            }
        }
        (0..p).filter(|&k| on[k]).collect()
    }

    /// Number of qp solution variables (all qps).
    pub fn nqp_vars(&self) -> usize {
        self.qps.iter().map(|q| q.info.vars.len()).sum()
    }
}

/// ∂e/∂x (n), ∂e/∂θ (p) and a last entry.
fn grad_exprs(
    ar: &mut ExprArena,
    e: ExprId,
    n: usize,
    p: usize,
    last_is_value: bool,
) -> Vec<ExprId> {
    let mut v: Vec<ExprId> = (0..n).map(|i| diff(ar, e, Var::State(i))).collect();
    v.extend((0..p).map(|i| diff(ar, e, Var::Param(i))));
    v.push(if last_is_value {
        e
    } else {
        diff(ar, e, Var::Time)
    });
    v
}

/// The value and gradient kernels of a scalar `e`.
fn grad_kernels(
    ar: &mut ExprArena,
    e: ExprId,
    n: usize,
    p: usize,
    last_is_value: bool,
) -> GradKernels {
    let g = grad_exprs(ar, e, n, p, last_is_value);
    GradKernels {
        value: Kernel::new(ar, &[e]),
        grad: Kernel::new(ar, &g),
    }
}

/// Row-major Jacobian of `exprs` with respect to `vars`.
fn jacobian(
    ar: &mut ExprArena,
    exprs: &[ExprId],
    vars: impl Fn(usize) -> Var,
    ncols: usize,
) -> Vec<ExprId> {
    let mut out = Vec::with_capacity(exprs.len() * ncols);
    for &e in exprs {
        for c in 0..ncols {
            out.push(diff(ar, e, vars(c)));
        }
    }
    out
}

/// The states an expression reads, ascending.
fn states_read(ar: &ExprArena, e: ExprId) -> Vec<usize> {
    let live = ar.live(&[e]);
    let mut v: Vec<usize> = live
        .iter()
        .zip(ar.nodes())
        .filter_map(|(&l, nd)| match nd {
            Node::State(i) if l => Some(*i as usize),
            _ => None,
        })
        .collect();
    v.sort_unstable();
    v
}

/// The second-order kernels of G (`rows` expressions) from its Jacobians `gx` (rows×n) and
/// `gp` (rows×p), row-major; with `time_rows`, `dt` also holds ∂ₜG_r.
fn second_order(
    ar: &mut ExprArena,
    rows: &[ExprId],
    gx: &[ExprId],
    gp: &[ExprId],
    n: usize,
    p: usize,
    time_rows: bool,
) -> SecondOrderKernels {
    let nonzero = |ar: &ExprArena, m: &[ExprId], cols: usize| -> Vec<(usize, usize, ExprId)> {
        m.iter()
            .enumerate()
            .filter(|&(_, &e)| !ar.is_zero(e))
            .map(|(k, &e)| (k / cols.max(1), k % cols.max(1), e))
            .collect()
    };
    let xs = nonzero(ar, gx, n);
    let ps = nonzero(ar, gp, p);
    let entries: Vec<ExprId> = xs.iter().chain(&ps).map(|&(_, _, e)| e).collect();
    let (mut dx, mut dx_terms) = (Vec::new(), Vec::new());
    for (e, &g) in entries.iter().enumerate() {
        for i in states_read(ar, g) {
            let d = diff(ar, g, Var::State(i));
            if !ar.is_zero(d) {
                dx.push(d);
                dx_terms.push((e, i));
            }
        }
    }
    let mut dt: Vec<ExprId> = entries.iter().map(|&g| diff(ar, g, Var::Time)).collect();
    if time_rows {
        dt.extend(rows.iter().map(|&g| diff(ar, g, Var::Time)));
    }
    SecondOrderKernels {
        rows: rows.len(),
        x_entries: xs.iter().map(|&(r, c, _)| (r, c)).collect(),
        p_entries: ps.iter().map(|&(r, c, _)| (r, c)).collect(),
        dx: Kernel::new(ar, &dx),
        dx_terms,
        dt: Kernel::new(ar, &dt),
    }
}

/// Differentiates the program and cuts it into kernels.
pub fn kernels(program: &Program) -> ModelKernels {
    let mut ar = program.arena.clone();
    let n = program.nstates();
    let p = program.nparams();

    let x0 = Kernel::new(&ar, &program.x0);
    let dx0 = jacobian(&mut ar, &program.x0, Var::Param, p);
    let x0_jac = Kernel::new(&ar, &dx0);

    let horizon = program.horizon.map(|h| {
        let g: Vec<ExprId> = (0..p).map(|i| diff(&mut ar, h, Var::Param(i))).collect();
        (Kernel::new(&ar, &[h]), Kernel::new(&ar, &g))
    });

    let modes = program
        .modes
        .iter()
        .map(|m| {
            let fx = jacobian(&mut ar, &m.flow, Var::State, n);
            let fp = jacobian(&mut ar, &m.flow, Var::Param, p);
            let ft: Vec<ExprId> = m
                .flow
                .iter()
                .map(|&e| diff(&mut ar, e, Var::Time))
                .collect();
            let sparsity: Vec<(usize, usize)> = (0..n * n)
                .filter(|&k| !ar.is_zero(fx[k]))
                .map(|k| (k / n.max(1), k % n.max(1)))
                .collect();
            let mut sens: Vec<ExprId> = m.flow.clone();
            sens.extend(sparsity.iter().map(|&(r, c)| fx[r * n + c]));
            sens.extend(fp.iter().copied());
            let second = second_order(&mut ar, &m.flow, &fx, &fp, n, p, false);
            let jac: Vec<ExprId> = (second.x_entries.iter().map(|&(r, c)| fx[r * n + c]))
                .chain(second.p_entries.iter().map(|&(r, c)| fp[r * p + c]))
                .collect();
            let depends_on_t = m
                .flow
                .iter()
                .any(|&e| ar.depends_on(e, |nd| matches!(nd, Node::Time)))
                || ft
                    .iter()
                    .any(|&e| ar.depends_on(e, |nd| matches!(nd, Node::QpDeriv(_, Wrt::Time))));
            let constant = !m.flow.iter().any(|&e| ar.depends_on(e, varies_in_time));
            ModeKernels {
                rhs: Kernel::new(&ar, &m.flow),
                jac_x: Kernel::new(&ar, &fx),
                jac_p: Kernel::new(&ar, &fp),
                dt: Kernel::new(&ar, &ft),
                depends_on_t,
                constant,
                sparsity,
                sens: Kernel::new(&ar, &sens),
                jac: Kernel::new(&ar, &jac),
                second,
            }
        })
        .collect();

    let affine_guards: Vec<bool> = (program.events.iter())
        .map(|ev| ev.schedule.is_none() && affine_in_state_and_time(&mut ar, ev.guard, n))
        .collect();
    let events = program
        .events
        .iter()
        .map(|ev| {
            let guard = grad_kernels(&mut ar, ev.guard, n, p, false);
            let mut rj = jacobian(&mut ar, &ev.reset, Var::State, n);
            rj.extend(jacobian(&mut ar, &ev.reset, Var::Param, p));
            rj.extend(jacobian(&mut ar, &ev.reset, |_| Var::Time, 1));
            let mut theta_kernels = |e: ExprId| {
                let g: Vec<ExprId> = (0..p).map(|i| diff(&mut ar, e, Var::Param(i))).collect();
                (Kernel::new(&ar, &[e]), Kernel::new(&ar, &g))
            };
            let time = ev.schedule.map(|s| {
                let (first, period) = match s {
                    Schedule::At(tau) | Schedule::Each { time: tau, .. } => (tau, None),
                    Schedule::Every { period, start } => (start, Some(period)),
                };
                let (time, time_grad) = theta_kernels(first);
                TimeKernels {
                    time,
                    time_grad,
                    period: period.map(&mut theta_kernels),
                }
            });
            EventKernels {
                guard,
                reset: Kernel::new(&ar, &ev.reset),
                reset_jac: Kernel::new(&ar, &rj),
                cost: ev.cost.map(|c| grad_kernels(&mut ar, c, n, p, false)),
                time,
            }
        })
        .collect();

    let switches = program
        .switches
        .iter()
        .map(|&s| grad_kernels(&mut ar, s, n, p, false))
        .collect();

    let obs: Vec<ExprId> = program.observables.iter().map(|&(_, e)| e).collect();
    let mut oj = jacobian(&mut ar, &obs, Var::State, n);
    oj.extend(jacobian(&mut ar, &obs, Var::Param, p));

    let running_cost = program
        .running_cost
        .map(|c| grad_kernels(&mut ar, c, n, p, true));
    let final_cost = program
        .final_cost
        .map(|c| grad_kernels(&mut ar, c, n, p, false));
    let running_cost_second = program.running_cost.map(|c| {
        let gx: Vec<ExprId> = (0..n).map(|i| diff(&mut ar, c, Var::State(i))).collect();
        let gp: Vec<ExprId> = (0..p).map(|i| diff(&mut ar, c, Var::Param(i))).collect();
        second_order(&mut ar, &[c], &gx, &gp, n, p, true)
    });

    let qps = program
        .qps
        .iter()
        .map(|q| {
            let data = q.data();
            let jac = jacobian(&mut ar, &data, Var::State, n);
            let dp = jacobian(&mut ar, &data, Var::Param, p);
            let dt = jacobian(&mut ar, &data, |_| Var::Time, 1);
            // Interleave to slot d·(n + p + 1) + w.
            let w = n + p + 1;
            let mut dj = Vec::with_capacity(data.len() * w);
            for d in 0..data.len() {
                dj.extend_from_slice(&jac[d * n..(d + 1) * n]);
                dj.extend_from_slice(&dp[d * p..(d + 1) * p]);
                dj.push(dt[d]);
            }
            let vars = q.offset..q.offset + q.vars.len();
            let reads = |e: ExprId| {
                ar.depends_on(
                    e,
                    |nd| matches!(nd, Node::QpSol(k) if vars.contains(&(*k as usize))),
                )
            };
            let events_before = (program.events.iter().enumerate())
                .filter(|(_, ev)| {
                    ev.schedule.is_none() && reads(ev.guard) || ev.reset.iter().any(|&e| reads(e))
                })
                .map(|(k, _)| k)
                .collect();
            let events_after = (program.events.iter().enumerate())
                .filter(|(_, ev)| ev.cost.is_some_and(reads))
                .map(|(k, _)| k)
                .collect();
            QpKernels {
                info: QpLayerInfo {
                    name: q.name.clone(),
                    vars: q.vars.clone(),
                    kinds: q.kinds.clone(),
                    dynamic: q.dynamic,
                    switches: q.switches,
                    events_before,
                    events_after,
                },
                offset: q.offset,
                in_flow: q.in_flow,
                data: Kernel::new(&ar, &data),
                data_jac: Kernel::new(&ar, &dj),
            }
        })
        .collect();

    ModelKernels {
        names: program.names.clone(),
        mode_names: program.modes.iter().map(|m| m.name.clone()).collect(),
        initial_mode: program.initial_mode,
        event_meta: (program.events.iter().zip(affine_guards))
            .map(|(e, affine_guard)| EventMeta {
                info: e.info.clone(),
                table: match e.schedule {
                    Some(Schedule::Each { table, .. }) => Some(table),
                    _ => None,
                },
                affine_guard,
            })
            .collect(),
        observables: program.observables.iter().map(|(n, _)| n.clone()).collect(),
        x0,
        x0_jac,
        horizon,
        modes,
        events,
        switches,
        observe: Kernel::new(&ar, &obs),
        observe_jac: Kernel::new(&ar, &oj),
        running_cost,
        final_cost,
        running_cost_second,
        qps,
        arena: ar,
    }
}

#[cfg(test)]
mod tests {
    /// A 40-state, 20-param chain: scheduling stays fast and the Jacobian sparse.
    #[test]
    fn large_model_schedules_quickly() {
        let (n, p) = (40, 20);
        let mut src = String::from("model Big {");
        for j in 0..p {
            src.push_str(&format!(" param k{j} = {}.5;", j + 1));
        }
        for i in 0..n {
            src.push_str(&format!(" state x{i} = k{};", i % p));
        }
        src.push_str(" flow {");
        for i in 0..n {
            let prev = (i + n - 1) % n;
            src.push_str(&format!(
                " der(x{i}) = -k{} * x{i} + sin(x{prev}) * k{} + abs(x{i} - x{prev});",
                i % p,
                (i + 1) % p
            ));
        }
        src.push_str(" } event hit when x0 <= 0 { x0 = -x0; } cost = integral(x1^2); horizon 1; }");
        let k = crate::compile(&src).expect("compiles");
        assert_eq!(k.modes[0].sparsity.len(), 2 * n);
        assert_eq!(k.switches.len(), n);
        let code = crate::codegen::generate(&k).to_string();
        assert!(!code.is_empty());
    }
}
