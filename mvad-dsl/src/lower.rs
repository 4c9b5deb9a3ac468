//! AST → IR: resolve names, fold consts, inline observables, expose kinks as switches.
//!
//! Names resolve in the order state, param, const, observable; consts are folded to
//! numbers and observables used inside other expressions are inlined. Expressions of a
//! flow, of the running cost ℓ or of an observable are lowered *frozen* (an observable's
//! kinks are watched like a flow's, so the measure's steps never straddle them): each `abs`, `min`, `max`, `sign`
//! and `if` becomes a [`Node::Switch`] on bit j of the switch
//! word, with its switching function σ_j recorded (lowered pointwise, deduplicated by
//! hash-consing):
//!
//! | kink | σ | branch for σ > 0 | else |
//! |---|---|---|---|
//! | abs(u) | u | u | −u |
//! | max(a, b) | a − b | a | b |
//! | min(a, b) | a − b | b | a |
//! | sign(u) | u | 1 | −1 |
//! | if L >(=) R then A else B | L − R | A | B |
//! | if L <(=) R then A else B | L − R | B | A |
//!
//! A qp's objective and constraints become its data H, c, A, b (`lower/qp.rs`, which also
//! checks symbolically that the objective is quadratic and strictly convex and the
//! constraints affine); `NAME.VAR` becomes the leaf [`Node::QpSol`]. Static cost terms are
//! added to the final cost Φ. A model without states (but with qps) gets one mode `main`
//! with an empty flow.
//!
//! Everywhere else (guards, resets, x₀, horizon, event and final costs) the
//! same functions are lowered pointwise ([`Node::Select`] and
//! `abs`/`sign` calls), with the derivative of the side actually taken. A kink whose σ
//! is constant never switches and is lowered pointwise wherever it appears.

use std::collections::HashMap;

use crate::ast::{self, BinOp, CmpOp, CostKind, ExprKind};
use crate::diag::Diagnostic;
use crate::ir::{
    Cmp, Direction, Event, EventInfo, ExprArena, ExprId, Func, Mode, ModelNames, Node, Program,
    Schedule, Trigger,
};
use crate::span::Span;

/// Deepest nesting of expressions, observables included, that lowering accepts.
const MAX_LOWER_DEPTH: usize = 1024;

/// The most switching functions a model may have (their ids are `u32`; the runtime's
/// switch bits hold any number).
pub const MAX_SWITCHES: usize = u32::MAX as usize;

/// Lowers a checked model to a [`Program`].
///
/// The user errors found here are a model with more than [`MAX_SWITCHES`] kinks (known
/// only once the switching functions are deduplicated) and qps whose objective is not
/// quadratic and strictly convex or whose constraints are not affine (decided on the
/// lowered expressions). Everything else lowering relies on
/// (names resolve, modes and events exist, guards and `if` conditions are comparisons,
/// constant expressions are constant, depths are bounded) is [`crate::check`]'s job; a model
/// that breaks it anyway yields `internal error: ...` diagnostics, never a panic.
pub fn lower(model: &ast::Model) -> Result<Program, Vec<Diagnostic>> {
    let mut lw = Lowerer::new(model);
    let program = lw.program(model);
    if lw.diags.is_empty() {
        Ok(program)
    } else {
        Err(lw.diags)
    }
}

/// Whether kinks become frozen switches (flows, ℓ) or pointwise choices (elsewhere).
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
enum Ctx {
    Frozen,
    Pointwise,
}

/// What a name stands for.
#[derive(Clone, Copy)]
enum Sym<'a> {
    State(usize),
    Param(usize),
    Const(f64),
    Observable(&'a ast::Expr),
    /// A qp, by index into `Lowerer::qp_vars`.
    Qp(usize),
}

struct Lowerer<'a> {
    ar: ExprArena,
    names: HashMap<&'a str, Sym<'a>>,
    switches: Vec<ExprId>,
    switch_of: HashMap<ExprId, u32>,
    /// Lowered expressions, keyed by AST node address and context (observables shared).
    memo: HashMap<(*const ast::Expr, Ctx), ExprId>,
    /// Observables being inlined (cycle detection).
    inlining: Vec<*const ast::Expr>,
    /// Whether params/states/time may be read (false in const and param defaults).
    consts_only: bool,
    depth: usize,
    diags: Vec<Diagnostic>,
    /// Table name → index in declaration order.
    table_index: HashMap<&'a str, usize>,
    /// The columns read so far: (table, column), in order of first use.
    columns: Vec<(usize, String)>,
    /// Per qp: the [`Node::QpSol`] index of its first variable and its variables' names.
    qp_vars: Vec<(usize, Vec<&'a str>)>,
    /// The qp whose data are being lowered (its variables are in scope).
    qp_scope: Option<usize>,
    /// Per qp variable: whether its solution can depend on (x, t).
    qp_deps: Vec<(bool, bool)>,
    /// Per qp: whether a flow or the running cost reads its solution.
    qp_in_flow: Vec<bool>,
    /// Per qp: whether a guard reads its solution.
    qp_in_guard: Vec<bool>,
    /// A guard is being lowered.
    in_guard: bool,
}

impl<'a> Lowerer<'a> {
    fn new(model: &'a ast::Model) -> Self {
        let mut names = HashMap::new();
        for o in model.observes() {
            names.insert(o.name.name.as_str(), Sym::Observable(&o.value));
        }
        for (i, p) in model.params().enumerate() {
            names.insert(p.name.name.as_str(), Sym::Param(i));
        }
        for (i, s) in model.states().enumerate() {
            names.insert(s.name.name.as_str(), Sym::State(i));
        }
        let mut qp_vars = Vec::new();
        let mut offset = 0;
        for (i, q) in model.qps().enumerate() {
            names.insert(q.name.name.as_str(), Sym::Qp(i));
            qp_vars.push((offset, q.vars.iter().map(|v| v.name.as_str()).collect()));
            offset += q.vars.len();
        }
        Lowerer {
            ar: ExprArena::new(),
            names,
            switches: Vec::new(),
            switch_of: HashMap::new(),
            memo: HashMap::new(),
            inlining: Vec::new(),
            consts_only: false,
            depth: 0,
            diags: Vec::new(),
            table_index: {
                let mut index = HashMap::new();
                for (i, t) in model.tables().enumerate() {
                    index.entry(t.name.name.as_str()).or_insert(i);
                }
                index
            },
            columns: Vec::new(),
            qp_vars,
            qp_scope: None,
            qp_deps: Vec::new(),
            qp_in_flow: vec![false; model.qps().count()],
            qp_in_guard: vec![false; model.qps().count()],
            in_guard: false,
        }
    }

    fn error(&mut self, span: Span, msg: impl Into<String>) {
        self.diags.push(Diagnostic::new(span, msg));
    }

    fn error_with_help(&mut self, span: Span, msg: impl Into<String>, help: impl Into<String>) {
        self.diags.push(Diagnostic::new(span, msg).with_help(help));
    }

    /// A broken invariant that [`crate::check`] establishes: a bug if it is ever reported.
    fn internal(&mut self, span: Span, msg: impl Into<String>) {
        self.diags.push(Diagnostic::new(
            span,
            format!(
                "internal error: {} (the checker should have rejected this model)",
                msg.into()
            ),
        ));
    }

    /// Evaluates a constant expression (numbers and earlier consts).
    fn constant(&mut self, e: &'a ast::Expr, what: &str) -> f64 {
        self.consts_only = true;
        let id = self.expr(e, Ctx::Pointwise);
        self.consts_only = false;
        match self.ar.as_const(id) {
            Some(v) => v,
            None => {
                self.internal(e.span, format!("{what} must be a constant expression"));
                f64::NAN
            }
        }
    }

    fn program(&mut self, model: &'a ast::Model) -> Program {
        // Consts, in order (each may use earlier ones).
        for c in model.consts() {
            let v = self.constant(&c.value, &format!("the value of const `{}`", c.name.name));
            self.names.insert(c.name.name.as_str(), Sym::Const(v));
        }
        let params: Vec<String> = model.params().map(|p| p.name.name.clone()).collect();
        let param_defaults: Vec<f64> = model
            .params()
            .map(|p| self.constant(&p.value, &format!("the default of param `{}`", p.name.name)))
            .collect();
        let states: Vec<String> = model.states().map(|s| s.name.name.clone()).collect();
        let n = states.len();
        let x0: Vec<ExprId> = model
            .states()
            .map(|s| {
                let id = self.expr(&s.init, Ctx::Pointwise);
                self.no_state_or_time(
                    id,
                    s.init.span,
                    &format!("the initial value of `{}`", s.name.name),
                );
                id
            })
            .collect();

        let mut qps: Vec<crate::ir::Qp> = model
            .qps()
            .enumerate()
            .map(|(i, q)| self.qp(q, i))
            .collect();
        let deps = std::mem::take(&mut self.qp_deps);
        self.ar.set_qp_deps(deps);

        // Modes.
        let mut modes = Vec::new();
        let mut mode_index: HashMap<&str, usize> = HashMap::new();
        if let Some(flow) = model.flow() {
            let f = self.flow(&flow.ders, n, flow.span, "main");
            modes.push(Mode {
                name: "main".into(),
                flow: f,
            });
            mode_index.insert("main", 0);
        }
        for m in model.modes() {
            let f = self.flow(&m.ders, n, m.span, &m.name.name);
            mode_index.insert(m.name.name.as_str(), modes.len());
            modes.push(Mode {
                name: m.name.name.clone(),
                flow: f,
            });
        }
        if modes.is_empty() && n == 0 && !qps.is_empty() {
            // A stateless model: one mode with an empty flow, so the runtime sees a model.
            modes.push(Mode {
                name: "main".into(),
                flow: Vec::new(),
            });
        } else if modes.is_empty() {
            self.internal(
                model.name.span,
                format!("model `{}` has no `flow` and no `mode`", model.name.name),
            );
        }
        let initial_mode = match model.initial_mode() {
            Some(im) => match mode_index.get(im.mode.name.as_str()) {
                Some(&i) => i,
                None => {
                    self.internal(im.mode.span, format!("unknown mode `{}`", im.mode.name));
                    0
                }
            },
            None => 0,
        };

        // Events.
        let mut events = Vec::new();
        let all = model.all_events();
        let mut event_index: HashMap<String, usize> = HashMap::new();
        for (k, (mode, ev)) in all.iter().enumerate() {
            let name = ev
                .name
                .as_ref()
                .map_or_else(|| format!("event_{k}"), |i| i.name.clone());
            event_index.insert(name.clone(), k);
            let Some((guard, direction, schedule)) = self.trigger(ev) else {
                continue;
            };
            let mode = mode.and_then(|m| mode_index.get(m.name.name.as_str()).copied());
            let target = match &ev.target {
                Some(t) => match mode_index.get(t.name.as_str()) {
                    Some(&i) => Some(i),
                    None => {
                        self.internal(t.span, format!("unknown mode `{}`", t.name));
                        None
                    }
                },
                None => None,
            };
            let mut reset: Vec<ExprId> = (0..n).map(|i| self.ar.state(i)).collect();
            if let Some(resets) = &ev.resets {
                for a in resets {
                    match self.names.get(a.state.name.as_str()) {
                        Some(&Sym::State(i)) => reset[i] = self.expr(&a.value, Ctx::Pointwise),
                        _ => self.internal(
                            a.state.span,
                            format!("reset of `{}`, which is not a state", a.state.name),
                        ),
                    }
                }
            }
            let trigger = match schedule {
                None => Trigger::Guard,
                Some(Schedule::At(_)) => Trigger::At,
                Some(Schedule::Every { .. }) => Trigger::Every,
                Some(Schedule::Each { .. }) => Trigger::Each { rows: 0 },
            };
            events.push(Event {
                info: EventInfo {
                    name,
                    direction,
                    mode,
                    target,
                    has_reset: ev.resets.is_some(),
                    has_cost: false,
                    trigger,
                },
                guard,
                schedule,
                reset,
                cost: None,
            });
        }

        // Observables.
        let observables: Vec<(String, ExprId)> = model
            .observes()
            .map(|o| {
                self.inlining.push(&o.value as *const ast::Expr);
                let id = self.expr(&o.value, Ctx::Frozen);
                self.inlining.pop();
                (o.name.name.clone(), id)
            })
            .collect();

        // Cost.
        let mut running: Option<ExprId> = None;
        let mut fin: Option<ExprId> = None;
        let mut per_event: Vec<Option<ExprId>> = vec![None; all.len()];
        if let Some(cost) = model.cost() {
            for term in &cost.terms {
                let (target, e) = match &term.kind {
                    CostKind::Integral(e) => (&mut running, self.expr(e, Ctx::Frozen)),
                    CostKind::Final(e) | CostKind::Static(e) => {
                        (&mut fin, self.expr(e, Ctx::Pointwise))
                    }
                    CostKind::Sum { event, value } => {
                        let v = self.expr(value, Ctx::Pointwise);
                        match event_index.get(event.name.as_str()) {
                            Some(&k) => (&mut per_event[k], v),
                            None => {
                                self.internal(
                                    event.span,
                                    format!("unknown event `{}`", event.name),
                                );
                                continue;
                            }
                        }
                    }
                };
                let c = self.ar.constant(term.factor);
                let scaled = self.ar.mul(c, e);
                *target = Some(match *target {
                    Some(prev) => self.ar.add(prev, scaled),
                    None => scaled,
                });
            }
        }
        for (ev, c) in events.iter_mut().zip(per_event.iter()) {
            ev.cost = *c;
            ev.info.has_cost = c.is_some();
        }

        self.assign_qp_switches(&mut qps);
        self.no_jumping_qp_read_along_the_flow(model, &qps);

        let horizon = model.horizon().map(|h| {
            let id = self.expr(&h.value, Ctx::Pointwise);
            self.no_state_or_time(id, h.value.span, "the horizon");
            id
        });

        Program {
            arena: std::mem::take(&mut self.ar),
            names: ModelNames {
                name: model.name.name.clone(),
                states,
                params,
                tables: model
                    .tables()
                    .map(|t| (t.name.name.clone(), t.file.clone()))
                    .collect(),
                columns: std::mem::take(&mut self.columns),
                param_defaults,
            },
            x0,
            modes,
            initial_mode,
            events,
            observables,
            running_cost: running,
            final_cost: fin,
            horizon,
            switches: std::mem::take(&mut self.switches),
            qps,
        }
    }

    /// The guard g = LHS − RHS and direction of a state event, or a NaN guard and the
    /// schedule of a time event; `None` (with an internal error) for a guard that is not a
    /// comparison.
    fn trigger(&mut self, ev: &'a ast::Event) -> Option<(ExprId, Direction, Option<Schedule>)> {
        let time = |lw: &mut Self, e: &'a ast::Expr| {
            let id = lw.expr(e, Ctx::Pointwise);
            lw.no_state_or_time(id, e.span, "the time of an event");
            id
        };
        let schedule = match &ev.trigger {
            ast::Trigger::When(cond) => {
                let Some(cmp) = cond.comparison() else {
                    self.internal(cond.span(), "the guard of an event must be a comparison");
                    return None;
                };
                self.in_guard = true;
                let l = self.expr(&cmp.lhs, Ctx::Pointwise);
                let r = self.expr(&cmp.rhs, Ctx::Pointwise);
                self.in_guard = false;
                let direction = match cmp.op {
                    CmpOp::Le | CmpOp::Lt => Direction::Down,
                    CmpOp::Ge | CmpOp::Gt => Direction::Up,
                };
                let g = self.ar.sub(l, r);
                let Some(g) = guard::continuous(&mut self.ar, g, direction) else {
                    self.error(
                        cond.span(),
                        format!(
                            "more than {} jumps (`if` or `sign` of a value that moves along the flow) in one guard",
                            guard::MAX_JUMPS
                        ),
                    );
                    return None;
                };
                return Some((g, direction, None));
            }
            ast::Trigger::At(e) => Schedule::At(time(self, e)),
            ast::Trigger::Every { period, start } => {
                let period = time(self, period);
                let start = match start {
                    Some(s) => time(self, s),
                    None => self.ar.constant(0.0),
                };
                Schedule::Every { period, start }
            }
            ast::Trigger::Each(e) => {
                let mut table = None;
                crate::check::walk_expr(e, &mut |x| {
                    if let (None, ExprKind::Column { table: t, .. }) = (table, &x.kind) {
                        table = Some(t);
                    }
                });
                let Some(&t) = table.and_then(|t| self.table_index.get(t.name.as_str())) else {
                    self.internal(e.span, "the times of an `at each` event read no table");
                    return None;
                };
                Schedule::Each {
                    table: t,
                    time: time(self, e),
                }
            }
        };
        let nan = self.ar.constant(f64::NAN);
        Some((nan, Direction::Up, Some(schedule)))
    }

    /// The node of column `column` of table `table` (numbered on first use).
    fn column(&mut self, table: &ast::Ident, column: &ast::Ident) -> ExprId {
        let Some(&t) = self.table_index.get(table.name.as_str()) else {
            self.internal(table.span, format!("unknown table `{}`", table.name));
            return self.ar.constant(f64::NAN);
        };
        let c = match self
            .columns
            .iter()
            .position(|(ti, name)| *ti == t && *name == column.name)
        {
            Some(c) => c,
            None => {
                self.columns.push((t, column.name.clone()));
                self.columns.len() - 1
            }
        };
        self.ar.intern(Node::Column(c as u32))
    }

    fn no_state_or_time(&mut self, id: ExprId, span: Span, what: &str) {
        if self
            .ar
            .depends_on(id, |n| matches!(n, Node::State(_) | Node::Time))
        {
            self.internal(span, format!("{what} may use only params and consts"));
        }
    }

    fn flow(&mut self, ders: &'a [ast::Der], n: usize, span: Span, mode: &str) -> Vec<ExprId> {
        let mut f: Vec<Option<ExprId>> = vec![None; n];
        for d in ders {
            match self.names.get(d.state.name.as_str()) {
                Some(&Sym::State(i)) => f[i] = Some(self.expr(&d.value, Ctx::Frozen)),
                _ => self.internal(
                    d.state.span,
                    format!("`der` of `{}`, which is not a state", d.state.name),
                ),
            }
        }
        f.into_iter()
            .enumerate()
            .map(|(i, e)| {
                e.unwrap_or_else(|| {
                    self.internal(
                        span,
                        format!("state number {} has no `der` in mode `{mode}`", i + 1),
                    );
                    self.ar.constant(0.0)
                })
            })
            .collect()
    }

    /// Lowers one expression (memoised per AST node and context).
    fn expr(&mut self, e: &'a ast::Expr, ctx: Ctx) -> ExprId {
        let key = (e as *const ast::Expr, ctx);
        if let Some(&id) = self.memo.get(&key) {
            return id;
        }
        if self.depth >= MAX_LOWER_DEPTH {
            self.internal(e.span, "expression nested too deeply");
            return self.ar.constant(f64::NAN);
        }
        self.depth += 1;
        let id = self.expr_inner(e, ctx);
        self.depth -= 1;
        if !self.consts_only {
            self.memo.insert(key, id);
        }
        id
    }

    fn expr_inner(&mut self, e: &'a ast::Expr, ctx: Ctx) -> ExprId {
        match &e.kind {
            ExprKind::Number(v) => self.ar.constant(*v),
            ExprKind::Time => {
                if self.consts_only {
                    self.internal(e.span, "`t` cannot be used in a constant expression");
                }
                self.ar.time()
            }
            ExprKind::Name(id) => self.name(id, ctx),
            ExprKind::Column { table, column }
                if self.table_index.contains_key(table.name.as_str()) =>
            {
                if self.consts_only {
                    self.internal(
                        e.span,
                        "a table column cannot be used in a constant expression",
                    );
                }
                self.column(table, column)
            }
            ExprKind::Column { table, column } => self.qp_solution(table, column, ctx),
            ExprKind::Neg(a) => {
                let a = self.expr(a, ctx);
                self.ar.neg(a)
            }
            ExprKind::Binary { op, lhs, rhs, .. } => {
                let a = self.expr(lhs, ctx);
                let b = self.expr(rhs, ctx);
                match op {
                    BinOp::Add => self.ar.add(a, b),
                    BinOp::Sub => self.ar.sub(a, b),
                    BinOp::Mul => self.ar.mul(a, b),
                    BinOp::Div => self.ar.div(a, b),
                    BinOp::Pow => self.ar.pow(a, b),
                }
            }
            ExprKind::Call { func, args } => self.call(e, func, args, ctx),
            ExprKind::If { cond, then, els } => {
                let Some(cmp) = cond.comparison() else {
                    self.internal(cond.span(), "the condition of `if` must be a comparison");
                    return self.ar.constant(f64::NAN);
                };
                let a = self.expr(then, ctx);
                let b = self.expr(els, ctx);
                let op = match cmp.op {
                    CmpOp::Gt => Cmp::Gt,
                    CmpOp::Ge => Cmp::Ge,
                    CmpOp::Lt => Cmp::Lt,
                    CmpOp::Le => Cmp::Le,
                };
                let (l, r) = (
                    self.expr(&cmp.lhs, Ctx::Pointwise),
                    self.expr(&cmp.rhs, Ctx::Pointwise),
                );
                let sigma = self.ar.sub(l, r);
                if ctx == Ctx::Pointwise || self.ar.as_const(sigma).is_some() {
                    // Pointwise (a constant σ never switches).
                    self.ar.select(op, sigma, a, b)
                } else {
                    let (pos, neg) = match cmp.op {
                        CmpOp::Gt | CmpOp::Ge => (a, b),
                        CmpOp::Lt | CmpOp::Le => (b, a),
                    };
                    self.kink(sigma, pos, neg, e.span)
                }
            }
        }
    }

    fn name(&mut self, id: &'a ast::Ident, ctx: Ctx) -> ExprId {
        if let Some(k) = self.qp_variable(&id.name) {
            return self.ar.intern(Node::QpSol(k as u32));
        }
        let sym = self.names.get(id.name.as_str()).copied();
        match sym {
            Some(Sym::Const(v)) => self.ar.constant(v),
            Some(_) if self.consts_only => {
                self.internal(id.span, format!("`{}` is not a const; a constant expression may use only numbers and consts", id.name));
                self.ar.constant(f64::NAN)
            }
            Some(Sym::State(i)) => self.ar.state(i),
            Some(Sym::Param(i)) => self.ar.param(i),
            Some(Sym::Observable(e)) => {
                let key = e as *const ast::Expr;
                if self.inlining.contains(&key) {
                    self.internal(
                        id.span,
                        format!("observable `{}` refers to itself", id.name),
                    );
                    return self.ar.constant(f64::NAN);
                }
                self.inlining.push(key);
                let r = self.expr(e, ctx);
                self.inlining.pop();
                r
            }
            Some(Sym::Qp(_)) => {
                self.internal(id.span, format!("qp `{}` used as a value", id.name));
                self.ar.constant(f64::NAN)
            }
            None => {
                self.internal(id.span, format!("undefined name `{}`", id.name));
                self.ar.constant(f64::NAN)
            }
        }
    }

    fn call(
        &mut self,
        e: &'a ast::Expr,
        func: &'a ast::Ident,
        args: &'a [ast::Expr],
        ctx: Ctx,
    ) -> ExprId {
        let name = func.name.as_str();
        let want = match name {
            "min" | "max" | "pow" => 2,
            _ => 1,
        };
        if Func::from_name(name).is_none() && want == 1 {
            self.internal(func.span, format!("unknown function `{name}`"));
            return self.ar.constant(f64::NAN);
        }
        if args.len() != want {
            self.internal(
                func.span,
                format!(
                    "`{name}` takes {want} argument{}, found {}",
                    if want == 1 { "" } else { "s" },
                    args.len()
                ),
            );
            return self.ar.constant(f64::NAN);
        }
        let a = self.expr(&args[0], ctx);
        let b = if want == 2 {
            Some(self.expr(&args[1], ctx))
        } else {
            None
        };
        let b = b.unwrap_or(a);
        // In a flow or ℓ, the kink's switching function σ (lowered pointwise).
        let sigma = match (name, ctx) {
            ("min" | "max", Ctx::Frozen) => {
                let ap = self.expr(&args[0], Ctx::Pointwise);
                let bp = self.expr(&args[1], Ctx::Pointwise);
                Some(self.ar.sub(ap, bp))
            }
            ("abs" | "sign", Ctx::Frozen) => Some(self.expr(&args[0], Ctx::Pointwise)),
            _ => None,
        };
        // A constant σ never switches: evaluate the kink pointwise (exact at σ = 0).
        let sigma = sigma.filter(|&s| self.ar.as_const(s).is_none());
        match (name, sigma) {
            ("pow", _) => self.ar.pow(a, b),
            ("max", None) => {
                let c = self.ar.sub(a, b);
                self.ar.select(Cmp::Gt, c, a, b)
            }
            ("min", None) => {
                let c = self.ar.sub(a, b);
                self.ar.select(Cmp::Gt, c, b, a)
            }
            ("max", Some(sigma)) => self.kink(sigma, a, b, e.span),
            ("min", Some(sigma)) => self.kink(sigma, b, a, e.span),
            ("abs", Some(sigma)) => {
                let na = self.ar.neg(a);
                self.kink(sigma, a, na, e.span)
            }
            ("sign", Some(sigma)) => {
                let (one, minus) = (self.ar.constant(1.0), self.ar.constant(-1.0));
                self.kink(sigma, one, minus, e.span)
            }
            _ => match Func::from_name(name) {
                Some(f) => self.ar.call(f, a),
                None => self.ar.constant(f64::NAN),
            },
        }
    }

    /// A frozen kink with switching function σ: `Switch(j, pos, neg)`.
    fn kink(&mut self, sigma: ExprId, pos: ExprId, neg: ExprId, span: Span) -> ExprId {
        if pos == neg {
            return pos;
        }
        let j = match self.switch_of.get(&sigma) {
            Some(&j) => j,
            None => {
                let j = self.switches.len() as u32;
                if self.switches.len() == MAX_SWITCHES {
                    self.error(span, format!("more than {MAX_SWITCHES} kinks (abs, min, max, sign, if) in flows and running cost"));
                }
                self.switches.push(sigma);
                self.switch_of.insert(sigma, j);
                j
            }
        };
        self.ar.switch(j, pos, neg)
    }
}

mod guard;
mod qp;

#[cfg(test)]
mod tests;
