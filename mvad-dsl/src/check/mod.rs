//! Semantic checks on a parsed [`Model`]: one `check_*` function per rule, each returning
//! every error it finds, so a model with several mistakes reports them all at once.
//!
//! Name scopes (what an expression may read) depend on where it is written:
//!
//! | where | may use |
//! |---|---|
//! | `const` value | numbers and earlier consts |
//! | `param` default | numbers and consts |
//! | `state` initial value, `horizon` | numbers, consts, params |
//! | flows, guards, resets, observables, cost terms | consts, params, states, observables, `t`, qp solutions `NAME.VAR` |
//! | the objective and constraints of a qp | its own variables, consts, params, states, `t` |
//! | a static cost term | consts, params, solutions of static qps |
//!
//! After [`check`] returns no error the model satisfies everything [`crate::lower`]
//! relies on: names resolve, calls are known with the right arity, guards and `if`
//! conditions are comparisons, each state has exactly one `der` per mode, observables do
//! not depend on themselves and stay within [`crate::ast::MAX_DEPTH`] once substituted.

use std::collections::hash_map::Entry;
use std::collections::{HashMap, HashSet};

use crate::ast::{Condition, CostKind, Event, Expr, ExprKind, Ident, Item, Model, Trigger};
use crate::diag::Diagnostic;
use crate::span::Span;

/// The functions of the language with their number of arguments.
pub const FUNCTIONS: &[(&str, usize)] = &[
    ("sin", 1),
    ("cos", 1),
    ("tan", 1),
    ("asin", 1),
    ("acos", 1),
    ("atan", 1),
    ("exp", 1),
    ("log", 1),
    ("sqrt", 1),
    ("sinh", 1),
    ("cosh", 1),
    ("tanh", 1),
    ("abs", 1),
    ("sign", 1),
    ("min", 2),
    ("max", 2),
    ("pow", 2),
];

/// The keywords of the language (reserved, together with [`FUNCTIONS`] and `t`).
pub const KEYWORDS: &[&str] = &[
    "model", "param", "const", "state", "flow", "mode", "initial", "event", "when", "observe",
    "cost", "horizon", "der", "integral", "sum", "final", "if", "then", "else", "t", "qp",
    "minimize", "subject",
];

/// Rust keywords: names become Rust identifiers in `hybrid!`'s output, so they are
/// reserved in both doors to keep the language one.
pub const RUST_KEYWORDS: &[&str] = &[
    "as", "async", "await", "break", "const", "continue", "crate", "dyn", "else", "enum", "extern",
    "false", "fn", "for", "gen", "if", "impl", "in", "let", "loop", "match", "mod", "move", "mut",
    "pub", "ref", "return", "self", "Self", "static", "struct", "super", "trait", "true", "type",
    "unsafe", "use", "where", "while", "abstract", "become", "box", "do", "final", "macro",
    "override", "priv", "try", "typeof", "unsized", "virtual", "yield",
];

/// The number of arguments of function `name`, or `None` if it is not a function.
pub fn function_arity(name: &str) -> Option<usize> {
    FUNCTIONS.iter().find(|(f, _)| *f == name).map(|(_, n)| *n)
}

/// Whether `name` may not be declared (a keyword, a function name, `t`, a Rust keyword).
pub fn is_reserved(name: &str) -> bool {
    KEYWORDS.contains(&name) || function_arity(name).is_some() || RUST_KEYWORDS.contains(&name)
}

/// Runs every check; the errors come back sorted by position.
pub fn check(model: &Model) -> Vec<Diagnostic> {
    let mut out = Vec::new();
    out.extend(check_has_states(model));
    out.extend(check_stateless(model));
    out.extend(check_qps(model));
    out.extend(check_reserved_names(model));
    out.extend(check_duplicates(model));
    out.extend(check_flow_or_modes(model));
    out.extend(check_ders(model));
    out.extend(check_resets(model));
    out.extend(check_modes(model));
    out.extend(check_sum_events(model));
    out.extend(check_calls(model));
    out.extend(check_conditions(model));
    out.extend(check_names(model));
    out.extend(check_observables(model));
    out.extend(check_time_events(model));
    out.sort_by_key(|d| (d.span.start, d.span.end));
    out.dedup();
    out
}

// ------------------------------------------------------------------ helpers

/// What a declared name is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Param,
    /// A const with its declaration order among consts.
    Const(usize),
    State,
    Observable,
    Qp,
}

impl Kind {
    fn noun(self) -> &'static str {
        match self {
            Kind::Param => "param",
            Kind::Const(_) => "const",
            Kind::State => "state",
            Kind::Observable => "observable",
            Kind::Qp => "qp",
        }
    }
}

/// The first declaration of every param, const, state and observable.
fn symbols(model: &Model) -> HashMap<&str, (Kind, Span)> {
    let mut map = HashMap::new();
    let mut nconst = 0;
    for item in &model.items {
        let (kind, id) = match item {
            Item::Param(p) => (Kind::Param, &p.name),
            Item::Const(c) => {
                nconst += 1;
                (Kind::Const(nconst - 1), &c.name)
            }
            Item::State(s) => (Kind::State, &s.name),
            Item::Observe(o) => (Kind::Observable, &o.name),
            Item::Qp(q) => (Kind::Qp, &q.name),
            _ => continue,
        };
        map.entry(id.name.as_str()).or_insert((kind, id.span));
    }
    map
}

/// Where an expression is written, which decides the names it may read.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Site<'a> {
    /// The value of the const with this declaration order and name.
    ConstValue(usize, &'a Ident),
    /// The default value of a param.
    ParamDefault(&'a Ident),
    /// The initial value of a state.
    StateInit(&'a Ident),
    /// The horizon.
    Horizon,
    /// The time, times or period of a time event (`at`, `at each`, `every`), with its name.
    EventTime(Option<&'a Ident>),
    /// Flows, guards, resets, observables, cost terms.
    Dynamic,
    /// The objective or a constraint of a qp.
    Qp(&'a crate::ast::Qp),
    /// A static cost term (written bare in `cost = ...;`).
    StaticTerm,
}

/// Every top-level expression of the model with its site, in source order.
fn sites(model: &Model) -> Vec<(Site<'_>, &Expr)> {
    let mut out = Vec::new();
    let mut nconst = 0;
    fn event_exprs<'a>(out: &mut Vec<(Site<'a>, &'a Expr)>, e: &'a Event) {
        let time = Site::EventTime(e.name.as_ref());
        match &e.trigger {
            Trigger::When(Condition::Compare(c)) => {
                out.push((Site::Dynamic, &c.lhs));
                out.push((Site::Dynamic, &c.rhs));
            }
            Trigger::When(Condition::NotComparison(x)) => out.push((Site::Dynamic, x)),
            Trigger::At(x) | Trigger::Each(x) => out.push((time, x)),
            Trigger::Every { period, start } => {
                out.push((time, period));
                out.extend(start.iter().map(|s| (time, s)));
            }
        }
        for r in e.resets.iter().flatten() {
            out.push((Site::Dynamic, &r.value));
        }
    }
    for item in &model.items {
        match item {
            Item::Param(p) => out.push((Site::ParamDefault(&p.name), &p.value)),
            Item::Const(c) => {
                out.push((Site::ConstValue(nconst, &c.name), &c.value));
                nconst += 1;
            }
            Item::State(s) => out.push((Site::StateInit(&s.name), &s.init)),
            Item::Flow(f) => out.extend(f.ders.iter().map(|d| (Site::Dynamic, &d.value))),
            Item::Mode(m) => {
                out.extend(m.ders.iter().map(|d| (Site::Dynamic, &d.value)));
                for e in &m.events {
                    event_exprs(&mut out, e);
                }
            }
            Item::InitialMode(_) | Item::Table(_) => {}
            Item::Event(e) => event_exprs(&mut out, e),
            Item::Observe(o) => out.push((Site::Dynamic, &o.value)),
            Item::Cost(c) => {
                for t in &c.terms {
                    let (site, e) = match &t.kind {
                        CostKind::Integral(e) | CostKind::Final(e) => (Site::Dynamic, e),
                        CostKind::Sum { value, .. } => (Site::Dynamic, value),
                        CostKind::Static(e) => (Site::StaticTerm, e),
                    };
                    out.push((site, e));
                }
            }
            Item::Horizon(h) => out.push((Site::Horizon, &h.value)),
            Item::Qp(q) => {
                out.push((Site::Qp(q), &q.objective));
                for c in &q.constraints {
                    out.push((Site::Qp(q), &c.lhs));
                    out.push((Site::Qp(q), &c.rhs));
                }
            }
        }
    }
    out
}

/// Calls `f` on `e` and every subexpression (conditions of `if` included), parents first.
/// Recursion depth is bounded by [`crate::ast::MAX_DEPTH`] (a parser invariant).
pub fn walk_expr<'a>(e: &'a Expr, f: &mut dyn FnMut(&'a Expr)) {
    f(e);
    match &e.kind {
        ExprKind::Number(_) | ExprKind::Name(_) | ExprKind::Time | ExprKind::Column { .. } => {}
        ExprKind::Neg(x) => walk_expr(x, f),
        ExprKind::Binary { lhs, rhs, .. } => {
            walk_expr(lhs, f);
            walk_expr(rhs, f);
        }
        ExprKind::Call { args, .. } => args.iter().for_each(|a| walk_expr(a, f)),
        ExprKind::If { cond, then, els } => {
            match &**cond {
                Condition::Compare(c) => {
                    walk_expr(&c.lhs, f);
                    walk_expr(&c.rhs, f);
                }
                Condition::NotComparison(x) => walk_expr(x, f),
            }
            walk_expr(then, f);
            walk_expr(els, f);
        }
    }
}

/// Every subexpression of every site, with the site.
fn all_exprs(model: &Model) -> Vec<(Site<'_>, &Expr)> {
    let mut out = Vec::new();
    for (site, e) in sites(model) {
        walk_expr(e, &mut |x| out.push((site, x)));
    }
    out
}

/// Levenshtein distance, for "did you mean" hints.
fn distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    let mut cur = vec![0; b.len() + 1];
    for (i, ca) in a.chars().enumerate() {
        cur[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let sub = prev[j] + usize::from(ca != cb);
            cur[j + 1] = sub.min(prev[j + 1] + 1).min(cur[j] + 1);
        }
        std::mem::swap(&mut prev, &mut cur);
    }
    prev[b.len()]
}

/// The closest candidate to `name` if it is close enough to be a likely typo.
fn suggest<'a>(name: &str, candidates: impl IntoIterator<Item = &'a str>) -> Option<&'a str> {
    let limit = if name.chars().count() <= 3 { 1 } else { 2 };
    candidates
        .into_iter()
        .map(|c| (distance(name, c), c))
        .filter(|&(d, _)| d <= limit)
        .min_by_key(|&(d, c)| (d, c))
        .map(|(_, c)| c)
}

/// A span covering the first `len` bytes of `span` (a keyword at the start of a block).
fn head(span: Span, len: usize) -> Span {
    Span::new(span.start, (span.start + len).min(span.end))
}

/// The name used in messages for an event.
fn event_label(e: &Event) -> String {
    match &e.name {
        Some(n) => format!("event `{}`", n.name),
        None => "event".to_string(),
    }
}

// ------------------------------------------------------------------ checks

/// A model must declare at least one state, unless it declares a qp (a stateless model,
/// see [`check_stateless`]).
pub fn check_has_states(model: &Model) -> Vec<Diagnostic> {
    if model.states().next().is_some() || model.qps().next().is_some() {
        return Vec::new();
    }
    vec![Diagnostic::new(
        model.name.span,
        format!("model `{}` has no states", model.name.name),
    )
    .with_help("declare one with `state NAME = VALUE;`")]
}

/// No declared name may be reserved (a keyword, a function, `t`, a Rust keyword).
pub fn check_reserved_names(model: &Model) -> Vec<Diagnostic> {
    let mut names: Vec<&Ident> = vec![&model.name];
    for item in &model.items {
        match item {
            Item::Param(p) => names.push(&p.name),
            Item::Const(c) => names.push(&c.name),
            Item::State(s) => names.push(&s.name),
            Item::Observe(o) => names.push(&o.name),
            Item::Mode(m) => names.push(&m.name),
            Item::Table(t) => names.push(&t.name),
            Item::Qp(q) => {
                names.push(&q.name);
                names.extend(&q.vars);
            }
            _ => {}
        }
    }
    for (_, e) in model.all_events() {
        names.extend(e.name.as_ref());
    }
    names
        .into_iter()
        .filter(|id| is_reserved(&id.name))
        .map(|id| {
            let what = if KEYWORDS.contains(&id.name.as_str()) {
                "a keyword"
            } else if function_arity(&id.name).is_some() {
                "a function name"
            } else {
                "a Rust keyword"
            };
            Diagnostic::new(
                id.span,
                format!("reserved name `{}` used as an identifier", id.name),
            )
            .with_help(format!("`{}` is {what}; choose another name", id.name))
        })
        .collect()
}

/// Params, consts, states and observables share one namespace; modes and events have
/// their own; `flow`, `initial mode`, `cost` and `horizon` may appear at most once.
pub fn check_duplicates(model: &Model) -> Vec<Diagnostic> {
    let mut out = Vec::new();
    let mut dup = |seen: &mut HashMap<String, Span>, id: &Ident, what: &str| {
        if let Some(&first) = seen.get(&id.name) {
            out.push(
                Diagnostic::new(id.span, format!("duplicate {what} `{}`", id.name))
                    .with_label(first, "first declared here"),
            );
        } else {
            seen.insert(id.name.clone(), id.span);
        }
    };
    let mut values = HashMap::new();
    let mut modes = HashMap::new();
    let mut events = HashMap::new();
    let mut tables = HashMap::new();
    for item in &model.items {
        match item {
            Item::Param(p) => dup(&mut values, &p.name, "declaration of"),
            Item::Const(c) => dup(&mut values, &c.name, "declaration of"),
            Item::State(s) => dup(&mut values, &s.name, "declaration of"),
            Item::Observe(o) => dup(&mut values, &o.name, "declaration of"),
            Item::Qp(q) => dup(&mut values, &q.name, "declaration of"),
            Item::Mode(m) => dup(&mut modes, &m.name, "mode"),
            Item::Table(t) => dup(&mut tables, &t.name, "table"),
            _ => {}
        }
    }
    for (_, e) in model.all_events() {
        if let Some(n) = &e.name {
            dup(&mut events, n, "event");
        }
    }
    let mut singles: HashMap<&str, Span> = HashMap::new();
    for item in &model.items {
        let (what, len) = match item {
            Item::Flow(_) => ("flow", 4),
            Item::InitialMode(_) => ("initial mode", 7),
            Item::Cost(_) => ("cost", 4),
            Item::Horizon(_) => ("horizon", 7),
            _ => continue,
        };
        let span = head(item.span(), len);
        if let Some(&first) = singles.get(what) {
            out.push(
                Diagnostic::new(span, format!("duplicate `{what}` declaration"))
                    .with_label(first, "first declared here"),
            );
        } else {
            singles.insert(what, span);
        }
    }
    out
}

/// A model has either one `flow` block or one or more `mode` blocks, not both, not neither.
pub fn check_flow_or_modes(model: &Model) -> Vec<Diagnostic> {
    let flow = model.flow();
    let first_mode = model.modes().next();
    match (flow, first_mode) {
        (Some(f), Some(m)) => {
            let later = if m.span.start > f.span.start {
                m.name.span
            } else {
                head(f.span, 4)
            };
            vec![Diagnostic::new(
                later,
                "a model cannot have both a `flow` block and `mode` blocks",
            )
            .with_help("put the equations of `flow` into each mode, or drop the modes")]
        }
        (None, None) if is_stateless(model) => Vec::new(),
        (None, None) => vec![Diagnostic::new(
            model.name.span,
            format!(
                "model `{}` has no `flow` block and no `mode`",
                model.name.name
            ),
        )
        .with_help("add `flow { der(X) = ...; }`")],
        _ => Vec::new(),
    }
}

/// In the flow and in each mode: `der` only of states, at most once per state, and every
/// state given one.
pub fn check_ders(model: &Model) -> Vec<Diagnostic> {
    let syms = symbols(model);
    let states: Vec<&Ident> = model.states().map(|s| &s.name).collect();
    let mut out = Vec::new();
    let mut blocks: Vec<(&[crate::ast::Der], Span, String)> = Vec::new();
    for item in &model.items {
        match item {
            Item::Flow(f) => blocks.push((&f.ders, head(f.span, 4), "`flow`".to_string())),
            Item::Mode(m) => blocks.push((&m.ders, m.name.span, format!("mode `{}`", m.name.name))),
            _ => {}
        }
    }
    for (ders, anchor, where_) in blocks {
        let mut given: HashMap<&str, Span> = HashMap::new();
        for d in ders {
            let name = d.state.name.as_str();
            match assign_state(&syms, &d.state, "`der`", &mut given) {
                Ok(()) => {}
                Err(Misassigned::NotAState(diag)) => out.push(diag),
                Err(Misassigned::Undeclared(diag)) => out.push(
                    match suggest(name, states.iter().map(|s| s.name.as_str())) {
                        Some(s) => diag.with_help(format!("did you mean `{s}`?")),
                        None => diag,
                    },
                ),
                Err(Misassigned::Again(first)) => out.push(
                    Diagnostic::new(
                        d.state.span,
                        format!("`der({name})` is given twice in {where_}"),
                    )
                    .with_label(first, "first given here"),
                ),
            }
        }
        let mut seen = HashSet::new();
        for s in &states {
            if !given.contains_key(s.name.as_str()) && seen.insert(s.name.as_str()) {
                out.push(
                    Diagnostic::new(
                        anchor,
                        format!("state `{}` has no `der` in {where_}", s.name),
                    )
                    .with_label(s.span, "declared here")
                    .with_help(format!("add `der({}) = ...;`", s.name)),
                );
            }
        }
    }
    out
}

/// Why a `der` or a reset may not assign the name it targets.
enum Misassigned {
    /// The name is declared, but not as a state: "WHAT of KIND `x`, which is not a state",
    /// labelled at the declaration.
    NotAState(Diagnostic),
    /// The name is not declared: "WHAT of `x`, which is not a declared state".
    Undeclared(Diagnostic),
    /// The state was assigned before in the same block or event, at this span.
    Again(Span),
}

/// Checks that `target`, assigned by `what` (`der` or a reset), is a state not yet in
/// `assigned` (a block's or an event's assignments so far), and records it there.
fn assign_state<'m>(
    syms: &HashMap<&str, (Kind, Span)>,
    target: &'m Ident,
    what: &str,
    assigned: &mut HashMap<&'m str, Span>,
) -> Result<(), Misassigned> {
    let name = target.name.as_str();
    match syms.get(name) {
        Some((Kind::State, _)) => {}
        Some((k, decl)) => {
            let msg = format!("{what} of {} `{name}`, which is not a state", k.noun());
            let diag = Diagnostic::new(target.span, msg).with_label(*decl, "declared here");
            return Err(Misassigned::NotAState(diag));
        }
        None => {
            let msg = format!("{what} of `{name}`, which is not a declared state");
            return Err(Misassigned::Undeclared(Diagnostic::new(target.span, msg)));
        }
    }
    match assigned.entry(name) {
        Entry::Occupied(first) => Err(Misassigned::Again(*first.get())),
        Entry::Vacant(slot) => {
            slot.insert(target.span);
            Ok(())
        }
    }
}

/// Resets assign only states, each at most once per event.
pub fn check_resets(model: &Model) -> Vec<Diagnostic> {
    let syms = symbols(model);
    let mut out = Vec::new();
    for (_, e) in model.all_events() {
        let mut assigned: HashMap<&str, Span> = HashMap::new();
        for r in e.resets.iter().flatten() {
            let name = r.state.name.as_str();
            match assign_state(&syms, &r.state, "reset", &mut assigned) {
                Ok(()) => {}
                Err(Misassigned::NotAState(diag)) => {
                    out.push(diag.with_help("a reset block may assign only states"))
                }
                Err(Misassigned::Undeclared(diag)) => out.push(diag),
                Err(Misassigned::Again(first)) => out.push(
                    Diagnostic::new(
                        r.state.span,
                        format!("state `{name}` is reset twice in {}", event_label(e)),
                    )
                    .with_label(first, "first assigned here"),
                ),
            }
        }
    }
    out
}

/// `initial mode` and `-> MODE` name declared modes (a single-mode model has none).
pub fn check_modes(model: &Model) -> Vec<Diagnostic> {
    let modes: Vec<&str> = model.modes().map(|m| m.name.name.as_str()).collect();
    let mut refs: Vec<&Ident> = Vec::new();
    for item in &model.items {
        if let Item::InitialMode(i) = item {
            refs.push(&i.mode);
        }
    }
    for (_, e) in model.all_events() {
        refs.extend(e.target.as_ref());
    }
    refs.into_iter()
        .filter(|id| !modes.contains(&id.name.as_str()))
        .map(|id| {
            let d = Diagnostic::new(id.span, format!("unknown mode `{}`", id.name));
            if modes.is_empty() {
                d.with_help("this model declares no `mode` blocks")
            } else if let Some(s) = suggest(&id.name, modes.iter().copied()) {
                d.with_help(format!("did you mean `{s}`?"))
            } else {
                d.with_help(format!("the modes are {}", quoted_list(&modes)))
            }
        })
        .collect()
}

fn quoted_list(names: &[&str]) -> String {
    names
        .iter()
        .map(|n| format!("`{n}`"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// `sum(EVENT, ...)` names a declared (named) event.
pub fn check_sum_events(model: &Model) -> Vec<Diagnostic> {
    let events: Vec<&str> = model
        .all_events()
        .into_iter()
        .filter_map(|(_, e)| e.name.as_ref().map(|n| n.name.as_str()))
        .collect();
    let Some(cost) = model.cost() else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for term in &cost.terms {
        if let CostKind::Sum { event, .. } = &term.kind {
            if !events.contains(&event.name.as_str()) {
                let mut d = Diagnostic::new(
                    event.span,
                    format!("unknown event `{}` in `sum`", event.name),
                );
                d = match suggest(&event.name, events.iter().copied()) {
                    Some(s) => d.with_help(format!("did you mean `{s}`?")),
                    None if events.is_empty() => {
                        d.with_help("only named events can be summed: `event NAME when ...`")
                    }
                    None => d.with_help(format!("the events are {}", quoted_list(&events))),
                };
                out.push(d);
            }
        }
    }
    out
}

/// Calls name a known function and pass it the right number of arguments.
pub fn check_calls(model: &Model) -> Vec<Diagnostic> {
    let syms = symbols(model);
    let mut out = Vec::new();
    for (_, e) in all_exprs(model) {
        let ExprKind::Call { func, args } = &e.kind else {
            continue;
        };
        let name = func.name.as_str();
        match function_arity(name) {
            Some(n) if n != args.len() => out.push(Diagnostic::new(
                e.span,
                format!(
                    "function `{name}` takes {n} argument{}, but {} {} given",
                    if n == 1 { "" } else { "s" },
                    args.len(),
                    if args.len() == 1 { "was" } else { "were" }
                ),
            )),
            Some(_) => {}
            None => {
                let mut d = if let Some((k, _)) = syms.get(name) {
                    Diagnostic::new(
                        func.span,
                        format!("{} `{name}` is not a function", k.noun()),
                    )
                } else {
                    Diagnostic::new(func.span, format!("unknown function `{name}`"))
                };
                if name == "der" {
                    d = d.with_help("`der(X) = ...;` may appear only in `flow` and `mode` blocks");
                } else if matches!(name, "integral" | "sum" | "final") {
                    d = d.with_help(format!("`{name}(...)` may appear only in `cost = ...;`"));
                } else if let Some(s) = suggest(name, FUNCTIONS.iter().map(|(f, _)| *f)) {
                    d = d.with_help(format!("did you mean `{s}`?"));
                }
                out.push(d);
            }
        }
    }
    out
}

/// Guards and `if` conditions are comparisons `LHS OP RHS`.
pub fn check_conditions(model: &Model) -> Vec<Diagnostic> {
    const HELP: &str = "write a comparison: `LHS <= RHS`, `LHS < RHS`, `LHS >= RHS` or `LHS > RHS`";
    let mut out = Vec::new();
    for (_, e) in model.all_events() {
        if let Trigger::When(Condition::NotComparison(x)) = &e.trigger {
            out.push(
                Diagnostic::new(
                    x.span,
                    format!("guard of {} is not a comparison", event_label(e)),
                )
                .with_help(HELP),
            );
        }
    }
    for (_, e) in all_exprs(model) {
        if let ExprKind::If { cond, .. } = &e.kind {
            if let Condition::NotComparison(x) = &**cond {
                out.push(
                    Diagnostic::new(x.span, "condition of `if` is not a comparison")
                        .with_help(HELP),
                );
            }
        }
    }
    out
}

mod names;
mod qp;
mod time_events;
pub use names::{check_names, check_observables};
pub use qp::{check_qps, check_stateless, is_stateless};
pub use time_events::check_time_events;

#[cfg(test)]
mod tests;
