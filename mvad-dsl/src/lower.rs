//! AST → IR: resolve names, fold consts, inline observables, expose kinks as switches.
//!
//! Names resolve in the order state, param, const, observable; consts are folded to
//! numbers and observables used inside other expressions are inlined. Expressions of a
//! flow or of the running cost ℓ are lowered *frozen*: each `abs`, `min`, `max`, `sign`
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
//! Everywhere else (guards, resets, observables, x₀, horizon, event and final costs) the
//! same functions are lowered pointwise ([`Node::Select`] and
//! `abs`/`sign` calls), with the derivative of the side actually taken. A kink whose σ
//! is constant never switches and is lowered pointwise wherever it appears.

use std::collections::HashMap;

use crate::ast::{self, BinOp, CmpOp, CostKind, ExprKind};
use crate::diag::Diagnostic;
use crate::ir::{Cmp, Direction, Event, ExprArena, ExprId, Func, Mode, Node, Program, Schedule};
use crate::span::Span;

/// Deepest nesting of expressions, observables included, that lowering accepts.
const MAX_LOWER_DEPTH: usize = 1024;

/// The most switching functions a model may have (their ids are `u32`; the runtime's
/// switch bits hold any number).
pub const MAX_SWITCHES: usize = u32::MAX as usize;

/// Lowers a checked model to a [`Program`].
///
/// The one user error found here is a model with more than [`MAX_SWITCHES`] kinks (known
/// only once the switching functions are deduplicated). Everything else lowering relies on
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
        }
    }

    fn error(&mut self, span: Span, msg: impl Into<String>) {
        self.diags.push(Diagnostic::new(span, msg));
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
        if modes.is_empty() {
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
            events.push(Event {
                name,
                direction,
                mode,
                target,
                guard,
                schedule,
                reset,
                has_reset: ev.resets.is_some(),
                cost: None,
            });
        }

        // Observables.
        let observables: Vec<(String, ExprId)> = model
            .observes()
            .map(|o| {
                self.inlining.push(&o.value as *const ast::Expr);
                let id = self.expr(&o.value, Ctx::Pointwise);
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
                    CostKind::Final(e) => (&mut fin, self.expr(e, Ctx::Pointwise)),
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
        }

        let horizon = model.horizon().map(|h| {
            let id = self.expr(&h.value, Ctx::Pointwise);
            self.no_state_or_time(id, h.value.span, "the horizon");
            id
        });

        Program {
            arena: std::mem::take(&mut self.ar),
            name: model.name.name.clone(),
            states,
            params,
            tables: model
                .tables()
                .map(|t| (t.name.name.clone(), t.file.clone()))
                .collect(),
            columns: std::mem::take(&mut self.columns),
            param_defaults,
            x0,
            modes,
            initial_mode,
            events,
            observables,
            running_cost: running,
            final_cost: fin,
            horizon,
            switches: std::mem::take(&mut self.switches),
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
                let l = self.expr(&cmp.lhs, Ctx::Pointwise);
                let r = self.expr(&cmp.rhs, Ctx::Pointwise);
                let direction = match cmp.op {
                    CmpOp::Le | CmpOp::Lt => Direction::Down,
                    CmpOp::Ge | CmpOp::Gt => Direction::Up,
                };
                return Some((self.ar.sub(l, r), direction, None));
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
            ExprKind::Column { table, column } => {
                if self.consts_only {
                    self.internal(
                        e.span,
                        "a table column cannot be used in a constant expression",
                    );
                }
                self.column(table, column)
            }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ir::Point;

    fn program(src: &str) -> Program {
        let model = crate::front(src).unwrap_or_else(|e| panic!("front: {e:?}"));
        lower(&model).unwrap_or_else(|e| panic!("lower: {e:?}"))
    }

    fn errors(src: &str) -> Vec<String> {
        match crate::front(src).and_then(|m| lower(&m)) {
            Ok(_) => Vec::new(),
            Err(e) => e.into_iter().map(|d| d.message).collect(),
        }
    }

    #[test]
    fn events_directions_names_and_resets() {
        let p = program(
            "model M { param e = 0.8; state h = 1; state v = 0;
               flow { der(h) = v; der(v) = -9.81; }
               event impact when h <= 0 { v = -e * v; }
               event when v > 2;
               event when 1 >= h - v { h = v; v = h; } }",
        );
        assert_eq!(p.modes.len(), 1);
        assert_eq!(p.modes[0].name, "main");
        let names: Vec<&str> = p.events.iter().map(|e| e.name.as_str()).collect();
        assert_eq!(names, ["impact", "event_1", "event_2"]);
        let dirs: Vec<Direction> = p.events.iter().map(|e| e.direction).collect();
        assert_eq!(dirs, [Direction::Down, Direction::Up, Direction::Up]);
        assert!(!p.events[1].has_reset);
        // Identity for unassigned states; right-hand sides read the pre-event state.
        assert_eq!(p.events[0].reset[0], p.arena.clone().state(0));
        let x = [0.3, 1.7];
        let at = Point {
            t: 0.0,
            x: &x,
            p: &[0.8],
            sw: 0,
        };
        assert_eq!(p.arena.eval(&p.events[2].reset, &at), vec![1.7, 0.3]);
        // g = LHS − RHS.
        assert_eq!(
            p.arena.eval(&[p.events[2].guard], &at),
            vec![1.0 - (0.3 - 1.7)]
        );
    }

    #[test]
    fn kinks_become_deduplicated_switches_only_in_flows_and_running_cost() {
        let p = program(
            "model M { param a = 1; state x = 1; state y = 2;
               flow { der(x) = abs(x - y) + sign(x - y); der(y) = min(x, y) + max(y, a); }
               observe o = abs(x - y);
               event when abs(x) <= 1;
               cost = integral(max(y, a)) + final(abs(x)); }",
        );
        // abs(x−y), sign(x−y), min(x, y) share σ = x − y; max(y, a) has σ = y − a.
        assert_eq!(p.switches.len(), 2);
        let x = [0.5, 2.0];
        let th = [1.0];
        let at = |sw| Point {
            t: 0.0,
            x: &x,
            p: &th,
            sw,
        };
        // Frozen branches follow the bits, not the point: bit 0 set means x − y > 0.
        let f_pos = p.arena.eval(&p.modes[0].flow, &at(0b11));
        let f_neg = p.arena.eval(&p.modes[0].flow, &at(0b00));
        assert_eq!(f_pos, vec![(0.5 - 2.0) + 1.0, 2.0 + 2.0]);
        assert_eq!(f_neg, vec![(2.0 - 0.5) - 1.0, 0.5 + 1.0]);
        // Observables are pointwise whatever the bits.
        assert_eq!(p.arena.eval(&[p.observables[0].1], &at(0b11)), vec![1.5]);
    }

    #[test]
    fn if_branches_follow_the_comparison() {
        let p = program(
            "model M { state x = 1;
               flow { der(x) = (if x < 2 then 10 else 20) + (if x >= 3 then 100 else 200); }
               observe o = if x < 2 then 10 else 20; }",
        );
        assert_eq!(p.switches.len(), 2);
        let x = [1.0];
        let at = |sw| Point {
            t: 0.0,
            x: &x,
            p: &[],
            sw,
        };
        // σ₀ = x − 2 > 0 selects the else branch of `<`; σ₁ = x − 3 > 0 the then branch of `>=`.
        assert_eq!(
            p.arena.eval(&p.modes[0].flow, &at(0b01)),
            vec![20.0 + 200.0]
        );
        assert_eq!(
            p.arena.eval(&p.modes[0].flow, &at(0b10)),
            vec![10.0 + 100.0]
        );
        assert_eq!(p.arena.eval(&[p.observables[0].1], &at(0)), vec![10.0]);
    }

    #[test]
    fn constant_kinks_are_exact_and_not_switches() {
        let p = program(
            "model M { const c = 1; state x = 1;
               flow { der(x) = (if c >= 1 then 5 else 7) + sign(c - 1) + max(c, 1) + abs(0 - c); } }",
        );
        assert!(p.switches.is_empty());
        assert_eq!(
            p.arena.as_const(p.modes[0].flow[0]),
            Some(5.0 + 0.0 + 1.0 + 1.0)
        );
    }

    #[test]
    fn observables_are_inlined_and_consts_folded() {
        let p = program(
            "model M { const c = 2 * 3; param a = c + 1; state x = a;
               flow { der(x) = o1 * c; }
               observe o1 = x + a; }",
        );
        assert_eq!(p.param_defaults, vec![7.0]);
        let mut ar = p.arena.clone();
        let (x, a) = (ar.state(0), ar.param(0));
        let s = ar.add(x, a);
        let six = ar.constant(6.0);
        assert_eq!(p.modes[0].flow[0], ar.mul(s, six));
        assert_eq!(p.observables[0].1, s);
    }

    #[test]
    fn bad_models_are_errors_not_panics() {
        let cyc = "model M { state x = 1; flow { der(x) = a; } observe a = b; observe b = a; }";
        assert!(!errors(cyc).is_empty());
        let hz = "model M { state x = 1; flow { der(x) = 1; } horizon x; }";
        assert!(!errors(hz).is_empty());
        let mut many = String::from("model M { state x = 1; flow { der(x) = 0");
        for i in 0..70 {
            many.push_str(&format!(" + abs(x - {i})"));
        }
        many.push_str("; } }");
        // More than 64 kinks are fine: the switch bits are not limited to one word.
        let e = errors(&many);
        assert!(e.is_empty(), "{e:?}");
    }

    /// Models the checker rejects, lowered without it: every broken invariant comes back
    /// as an `internal error: ...` diagnostic, never a panic or a user-facing duplicate.
    #[test]
    fn unchecked_models_give_internal_errors_not_panics() {
        let bad = [
            // undefined name, unknown function, wrong argument counts
            "model M { state x = 1; flow { der(x) = y; } }",
            "model M { state x = 1; flow { der(x) = foo(x); } }",
            "model M { state x = 1; flow { der(x) = min(x) + max(x, x, x) + pow(x); } }",
            "model M { state x = 1; flow { der(x) = sin(); } }",
            // `der` of a non-state, a missing `der`, no flow at all
            "model M { param p = 1; state x = 1; flow { der(p) = 1; } }",
            "model M { state x = 1; state z = 2; flow { der(x) = 1; } }",
            "model M { state x = 1; }",
            // unknown modes, unknown event in `sum`, reset of a non-state
            "model M { state x = 1; mode a { der(x) = 1; } initial mode b; }",
            "model M { state x = 1; mode a { der(x) = 1; } event when x >= 2 -> b; }",
            "model M { state x = 1; flow { der(x) = 1; } cost = sum(nope, x); }",
            "model M { param p = 1; state x = 1; flow { der(x) = 1; } event when x >= 2 { p = 0; } }",
            // non-constant consts and defaults, state or time where only params may appear
            "model M { state x = 1; const c = x; param p = t; flow { der(x) = c + p; } }",
            "model M { param p = 1; state x = 1; state y = x + t; flow { der(x) = 1; der(y) = 1; } horizon x; }",
            // self-referential observables
            "model M { state x = 1; flow { der(x) = a; } observe a = b; observe b = a; }",
        ];
        for src in bad {
            let model = crate::parse::parse(src).unwrap_or_else(|e| panic!("parse {src}: {e:?}"));
            assert!(
                !crate::check::check(&model).is_empty(),
                "the checker accepts {src}"
            );
            let diags = match std::panic::catch_unwind(|| lower(&model)) {
                Ok(Err(d)) => d,
                Ok(Ok(_)) => panic!("lowered without an error: {src}"),
                Err(_) => panic!("lower panicked on {src}"),
            };
            assert!(
                diags
                    .iter()
                    .all(|d| d.message.starts_with("internal error: ")),
                "{src}: {diags:?}"
            );
        }
    }
}

#[cfg(test)]
mod depth_tests {
    /// Observables chained through each other nest deeper than any one expression: the
    /// lowering depth bound turns that into an error instead of a stack overflow.
    #[test]
    fn deep_observable_chains_are_errors() {
        let mut src = String::from("model M { state x = 1; flow { der(x) = o39; } observe o0 = x;");
        for i in 1..40 {
            let inner = format!("{}o{}{}", "sin(".repeat(100), i - 1, ")".repeat(100));
            src.push_str(&format!(" observe o{i} = {inner};"));
        }
        src.push('}');
        let r = std::thread::Builder::new()
            .stack_size(2 << 20)
            .spawn(move || {
                crate::compile(&src)
                    .map(|_| ())
                    .map_err(|e| e.into_iter().map(|d| d.message).collect::<Vec<_>>())
            })
            .expect("thread")
            .join()
            .expect("no stack overflow");
        let errs = r.expect_err("too deep");
        assert!(
            errs.iter().any(|m| m.contains("nested too deeply")),
            "{errs:?}"
        );
    }
}
