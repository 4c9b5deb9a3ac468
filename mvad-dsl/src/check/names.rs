//! Name rules: every name resolves to a declaration that its site may read (the scope table
//! of the parent module), and observables neither depend on themselves nor exceed
//! [`MAX_DEPTH`] once substituted.

use std::collections::{HashMap, HashSet};

use super::qp::{check_column, qps_with_var};
use super::{all_exprs, function_arity, sites, suggest, symbols, walk_expr, Kind, Site};
use crate::ast::{Condition, Expr, ExprKind, Ident, Model, MAX_DEPTH};
use crate::diag::Diagnostic;
use crate::span::Span;

/// Every name is declared and allowed where it is used (see the module table).
pub fn check_names(model: &Model) -> Vec<Diagnostic> {
    let syms = symbols(model);
    let mut out = Vec::new();
    // A scope error is reported once per (site, name), not at every use.
    let mut reported: HashSet<String> = HashSet::new();
    for (site, e) in all_exprs(model) {
        match &e.kind {
            ExprKind::Time => {
                if let Some(what) = static_site(site) {
                    out.push(Diagnostic::new(
                        e.span,
                        format!("{what} cannot depend on the time `t`"),
                    ));
                }
            }
            ExprKind::Column { table, column } => {
                if let Some(d) = check_dotted(model, &syms, site, e, table, column) {
                    if reported.insert(format!("{}@{}", d.message, d.span.start)) {
                        out.push(d);
                    }
                }
            }
            ExprKind::Name(id) => {
                let name = id.name.as_str();
                if let Site::Qp(q) = site {
                    if q.vars.iter().any(|v| v.name == id.name) {
                        continue;
                    }
                }
                match syms.get(name) {
                    None => out.push(undefined(id, &syms, &qps_with_var(model, name))),
                    Some(&(kind, decl)) => {
                        if let Some(d) = scope_error(site, id, kind, decl) {
                            if reported.insert(d.message.clone()) {
                                out.push(d);
                            }
                        }
                    }
                }
            }
            _ => {}
        }
    }
    out
}

/// How a non-dynamic site is named in messages (`None` for dynamic sites).
pub(super) fn static_site(site: Site<'_>) -> Option<String> {
    match site {
        Site::ConstValue(_, c) => Some(format!("const `{}`", c.name)),
        Site::ParamDefault(p) => Some(format!("the default value of param `{}`", p.name)),
        Site::StateInit(s) => Some(format!("the initial value of state `{}`", s.name)),
        Site::Horizon => Some("the horizon".to_string()),
        Site::EventTime(Some(e)) => Some(format!("the time of event `{}`", e.name)),
        Site::EventTime(None) => Some("the time of an event".to_string()),
        Site::StaticTerm => Some("a static cost term".to_string()),
        Site::Dynamic | Site::Qp(_) => None,
    }
}

/// Resolves a dotted name `NAME.VAR`: NAME is a table (VAR a column, which only the table's
/// file can confirm; where a row is current is checked by [`super::time_events`]) or a qp
/// (then [`check_column`]). A located error when NAME is neither, or both.
fn check_dotted(
    model: &Model,
    syms: &HashMap<&str, (Kind, Span)>,
    site: Site<'_>,
    e: &Expr,
    table: &Ident,
    column: &Ident,
) -> Option<Diagnostic> {
    let name = table.name.as_str();
    let declared = model.tables().find(|t| t.name.name == name);
    let qp = model.qps().find(|q| q.name.name == name);
    let (has_tables, has_qps) = (
        model.tables().next().is_some(),
        model.qps().next().is_some(),
    );
    let noun = match (has_tables, has_qps) {
        (true, false) => "table",
        (false, true) => "qp",
        _ => "table or qp",
    };
    match (declared, qp) {
        (Some(t), Some(q)) => Some(
            Diagnostic::new(
                table.span,
                format!(
                    "`{name}.{}` is ambiguous: `{name}` is a table and a qp",
                    column.name
                ),
            )
            .with_label(t.name.span, "the table")
            .with_label(q.name.span, "the qp")
            .with_help("rename the table or the qp"),
        ),
        (Some(_), None) => None,
        (None, Some(q)) => check_column(q, syms, site, e, column),
        (None, None) => Some(match syms.get(name) {
            Some(&(kind, decl)) => Diagnostic::new(
                table.span,
                format!(
                    "{} `{name}` is not a {noun}: `{name}.{}` names nothing",
                    kind.noun(),
                    column.name
                ),
            )
            .with_label(decl, "declared here"),
            None => {
                let d = Diagnostic::new(table.span, format!("unknown {noun} `{name}`"));
                let known = (model.tables().map(|t| t.name.name.as_str()))
                    .chain(model.qps().map(|q| q.name.name.as_str()));
                match suggest(name, known) {
                    Some(s) => d.with_help(format!("did you mean `{s}`?")),
                    None if has_tables || has_qps => d,
                    None => d.with_help(
                        "declare a table with `table NAME = \"FILE.csv\";` or a qp with \
                         `qp NAME(VAR, ...) { ... }`",
                    ),
                }
            }
        }),
    }
}

fn undefined(id: &Ident, syms: &HashMap<&str, (Kind, Span)>, qps: &[&str]) -> Diagnostic {
    let name = id.name.as_str();
    let d = Diagnostic::new(id.span, format!("undefined name `{name}`"));
    if function_arity(name).is_some() {
        return d.with_help(format!("`{name}` is a function: call it as `{name}(...)`"));
    }
    if let Some(q) = qps.first() {
        return d.with_help(format!(
            "`{name}` is a variable of qp `{q}`: write `{q}.{name}` for its solution"
        ));
    }
    match suggest(name, syms.keys().copied()) {
        Some(s) => d.with_help(format!("did you mean `{s}`?")),
        None => d,
    }
}

fn scope_error(site: Site<'_>, id: &Ident, kind: Kind, decl: Span) -> Option<Diagnostic> {
    let name = id.name.as_str();
    let noun = kind.noun();
    if kind == Kind::Qp {
        return Some(
            Diagnostic::new(id.span, format!("qp `{name}` is not a value"))
                .with_label(decl, "declared here")
                .with_help(format!("write `{name}.VAR` for a variable of its solution")),
        );
    }
    let (ok, help) = match site {
        Site::Dynamic => (true, ""),
        Site::Qp(q) => {
            if matches!(kind, Kind::Param | Kind::Const(_) | Kind::State) {
                return None;
            }
            return Some(
                Diagnostic::new(
                    id.span,
                    format!("the data of qp `{}` cannot depend on {noun} `{name}`", q.name.name),
                )
                .with_label(decl, "declared here")
                .with_help("a qp's objective and constraints may use its variables, consts, params, states and `t`"),
            );
        }
        Site::StaticTerm => (
            matches!(kind, Kind::Const(_) | Kind::Param),
            "a static term may use only numbers, consts, params and static qp solutions; wrap it in `final(..)` or `integral(..)`",
        ),
        Site::ConstValue(order, c) => match kind {
            Kind::Const(k) if k < order => (true, ""),
            Kind::Const(_) => {
                let msg = if c.name == name {
                    format!("const `{name}` is defined in terms of itself")
                } else {
                    format!(
                        "const `{}` uses const `{name}` before its declaration",
                        c.name
                    )
                };
                return Some(Diagnostic::new(id.span, msg).with_label(decl, "declared here"));
            }
            _ => (
                false,
                "a const may use only numbers and earlier consts; make it a param",
            ),
        },
        Site::ParamDefault(_) => (
            matches!(kind, Kind::Const(_)),
            "a param's default value may use only numbers and consts",
        ),
        Site::StateInit(_) | Site::Horizon | Site::EventTime(_) => (
            matches!(kind, Kind::Const(_) | Kind::Param),
            "it may use only numbers, consts and params",
        ),
    };
    if ok {
        return None;
    }
    let what = static_site(site).unwrap_or_default();
    Some(
        Diagnostic::new(id.span, format!("{what} cannot depend on {noun} `{name}`"))
            .with_label(decl, "declared here")
            .with_help(help),
    )
}

/// Observables used by name do not form a cycle, and every dynamic expression stays within
/// [`MAX_DEPTH`] once observables are substituted (as `lower` does).
pub fn check_observables(model: &Model) -> Vec<Diagnostic> {
    let obs: Vec<&crate::ast::Observe> = model.observes().collect();
    let index: HashMap<&str, usize> = obs
        .iter()
        .enumerate()
        .rev() // the first declaration wins, as in `symbols`
        .map(|(i, o)| (o.name.name.as_str(), i))
        .collect();
    // Edges o -> observables it reads.
    let deps: Vec<Vec<usize>> = obs
        .iter()
        .map(|o| {
            let mut d = Vec::new();
            walk_expr(&o.value, &mut |e| {
                if let ExprKind::Name(id) = &e.kind {
                    if let Some(&j) = index.get(id.name.as_str()) {
                        d.push(j);
                    }
                }
            });
            d
        })
        .collect();
    // Kahn's algorithm on the reversed edges: an observable is ready when all it reads are.
    let mut waiting: Vec<usize> = deps.iter().map(Vec::len).collect();
    let mut readers: Vec<Vec<usize>> = vec![Vec::new(); obs.len()];
    for (i, d) in deps.iter().enumerate() {
        for &j in d {
            readers[j].push(i);
        }
    }
    let mut ready: Vec<usize> = (0..obs.len()).filter(|&i| waiting[i] == 0).collect();
    let mut depth: HashMap<&str, usize> = HashMap::new();
    let mut out = Vec::new();
    while let Some(i) = ready.pop() {
        let d = substituted_depth(&obs[i].value, &depth);
        depth.insert(obs[i].name.name.as_str(), d);
        for &r in &readers[i] {
            waiting[r] -= 1;
            if waiting[r] == 0 {
                ready.push(r);
            }
        }
    }
    for (i, o) in obs.iter().enumerate() {
        if waiting[i] > 0 && index.get(o.name.name.as_str()) == Some(&i) {
            out.push(Diagnostic::new(
                o.name.span,
                format!("observable `{}` depends on itself", o.name.name),
            ));
        }
    }
    if !out.is_empty() {
        return out;
    }
    for (site, e) in sites(model) {
        if site == Site::Dynamic && substituted_depth(e, &depth) > MAX_DEPTH {
            out.push(Diagnostic::new(
                e.span,
                format!(
                    "expression nested too deeply once observables are substituted (more than {MAX_DEPTH} levels)"
                ),
            ));
        }
    }
    out
}

/// Tree depth of `e` with each observable replaced by its definition (depths in `obs`).
fn substituted_depth(e: &Expr, obs: &HashMap<&str, usize>) -> usize {
    let sub = |x: &Expr| substituted_depth(x, obs);
    match &e.kind {
        ExprKind::Number(_) | ExprKind::Time | ExprKind::Column { .. } => 1,
        ExprKind::Name(id) => obs.get(id.name.as_str()).copied().unwrap_or(1),
        ExprKind::Neg(x) => 1 + sub(x),
        ExprKind::Binary { lhs, rhs, .. } => 1 + sub(lhs).max(sub(rhs)),
        ExprKind::Call { args, .. } => 1 + args.iter().map(sub).max().unwrap_or(0),
        ExprKind::If { cond, then, els } => {
            let c = match &**cond {
                Condition::Compare(c) => sub(&c.lhs).max(sub(&c.rhs)),
                Condition::NotComparison(x) => sub(x),
            };
            1 + c.max(sub(then)).max(sub(els))
        }
    }
}
