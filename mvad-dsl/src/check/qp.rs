//! The rules of `qp` blocks, of `NAME.VAR` references to their solutions, and of stateless
//! models.
//!
//! - A qp's variables are distinct and not reserved; they are visible only inside their
//!   qp, where they shadow any model name they share (`observe u = u_star.u;` beside
//!   `qp u_star(u)` is fine). Constraints use `<=`, `>=` or `==`: the feasible set must be
//!   closed.
//! - `NAME.VAR` names a declared qp and one of its variables. It may be read wherever a
//!   state may, and in static cost terms when the qp is static; never inside a qp (the data of
//!   a qp do not depend on another qp's solution), a const, a param default, an initial
//!   value or the horizon.
//! - A qp is *static* when its data read no state and not `t`; otherwise it is solved along
//!   the trajectory.
//! - A model without states is valid when it declares a qp: it has no time, so no `flow`,
//!   `mode`, event, `horizon`, `t`, or `integral`/`sum`/`final` cost term; its cost is a sum
//!   of static terms.
//!
//! That objectives are quadratic and strictly convex and constraints affine is checked
//! symbolically on the lowered expressions (`lower::qp`), where derivatives exist.

use std::collections::{HashMap, HashSet};

use super::names::static_site;
use super::{head, suggest, walk_expr, Kind, Site};
use crate::ast::{ConstraintOp, CostKind, Expr, ExprKind, Ident, Item, Model, Qp};
use crate::diag::Diagnostic;
use crate::span::Span;

/// Whether the model is stateless: no state, at least one qp.
pub fn is_stateless(model: &Model) -> bool {
    model.states().next().is_none() && model.qps().next().is_some()
}

/// Whether the data of `q` read a state or `t` (then it is solved along the trajectory).
pub(super) fn is_dynamic(q: &Qp, syms: &HashMap<&str, (Kind, Span)>) -> bool {
    let mut dynamic = false;
    let mut visit = |e: &Expr| match &e.kind {
        ExprKind::Time => dynamic = true,
        ExprKind::Name(id) => {
            let own = q.vars.iter().any(|v| v.name == id.name);
            if !own && matches!(syms.get(id.name.as_str()), Some((Kind::State, _))) {
                dynamic = true;
            }
        }
        _ => {}
    };
    walk_expr(&q.objective, &mut visit);
    for c in &q.constraints {
        walk_expr(&c.lhs, &mut visit);
        walk_expr(&c.rhs, &mut visit);
    }
    dynamic
}

/// Variables distinct; closed constraints.
pub fn check_qps(model: &Model) -> Vec<Diagnostic> {
    let mut out = Vec::new();
    for q in model.qps() {
        let mut seen: HashMap<&str, Span> = HashMap::new();
        for v in &q.vars {
            if let Some(&first) = seen.get(v.name.as_str()) {
                out.push(
                    Diagnostic::new(
                        v.span,
                        format!(
                            "variable `{}` is declared twice in qp `{}`",
                            v.name, q.name.name
                        ),
                    )
                    .with_label(first, "first declared here"),
                );
                continue;
            }
            seen.insert(&v.name, v.span);
        }
        for c in &q.constraints {
            if matches!(c.op, ConstraintOp::Lt | ConstraintOp::Gt) {
                let closed = if c.op == ConstraintOp::Lt { "<=" } else { ">=" };
                out.push(
                    Diagnostic::new(
                        c.op_span,
                        format!(
                            "strict inequality `{}` in a constraint of qp `{}`",
                            c.op.as_str(),
                            q.name.name
                        ),
                    )
                    .with_help(format!(
                        "a qp's feasible set must be closed: write `{closed}`"
                    )),
                );
            }
        }
    }
    out
}

/// A stateless model has no time: no flow, modes, events, horizon, `t`, or
/// `integral`/`sum`/`final` terms.
pub fn check_stateless(model: &Model) -> Vec<Diagnostic> {
    if !is_stateless(model) {
        return Vec::new();
    }
    const HELP: &str = "a model without states has no time; declare a state to simulate one";
    let mut out = Vec::new();
    let no = |span: Span, what: &str| {
        Diagnostic::new(span, format!("a model without states cannot have {what}")).with_help(HELP)
    };
    for item in &model.items {
        match item {
            Item::Flow(f) => out.push(no(head(f.span, 4), "a `flow` block")),
            Item::Mode(m) => out.push(no(m.name.span, "modes")),
            Item::Event(e) => out.push(no(head(e.span, 5), "events")),
            Item::Horizon(h) => out.push(no(head(h.span, 7), "a `horizon`")),
            Item::Cost(c) => {
                for t in &c.terms {
                    let kind = match t.kind {
                        CostKind::Integral(_) => "`integral`",
                        CostKind::Sum { .. } => "`sum`",
                        CostKind::Final(_) => "`final`",
                        CostKind::Static(_) => continue,
                    };
                    out.push(
                        Diagnostic::new(
                            t.span,
                            format!("a model without states cannot have {kind} cost terms"),
                        )
                        .with_help("write its cost as static terms: `cost = 0.5 * NAME.VAR^2;`"),
                    );
                }
            }
            _ => {}
        }
    }
    for (_, e) in super::all_exprs(model) {
        if matches!(e.kind, ExprKind::Time) {
            out.push(
                Diagnostic::new(e.span, "a model without states has no time `t`").with_help(HELP),
            );
        }
    }
    out
}

/// The checks of one `NAME.VAR` at `site` once NAME resolved to qp `q` (see
/// [`super::names`]): VAR is one of its variables, and the site may read its solution.
pub(super) fn check_column(
    q: &Qp,
    syms: &HashMap<&str, (Kind, Span)>,
    site: Site<'_>,
    e: &Expr,
    column: &Ident,
) -> Option<Diagnostic> {
    let name = q.name.name.as_str();
    if !q.vars.iter().any(|v| v.name == column.name) {
        let vars: Vec<&str> = q.vars.iter().map(|v| v.name.as_str()).collect();
        let d = Diagnostic::new(
            column.span,
            format!("qp `{name}` has no variable `{}`", column.name),
        )
        .with_label(q.name.span, "declared here");
        return Some(match suggest(&column.name, vars.iter().copied()) {
            Some(s) => d.with_help(format!("did you mean `{s}`?")),
            None => d.with_help(format!(
                "its variables are {}",
                vars.iter()
                    .map(|v| format!("`{v}`"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )),
        });
    }
    let msg = match site {
        Site::Dynamic => return None,
        Site::Qp(own) => format!(
            "the data of qp `{}` cannot use the solution of qp `{name}`",
            own.name.name
        ),
        Site::StaticTerm if !is_dynamic(q, syms) => return None,
        Site::StaticTerm => {
            return Some(
                Diagnostic::new(
                    e.span,
                    format!(
                        "a static cost term cannot use the solution of qp `{name}`, which depends on states or `t`"
                    ),
                )
                .with_label(q.name.span, "declared here")
                .with_help("wrap the term in `final(..)` or `integral(..)`"),
            )
        }
        _ => format!(
            "{} cannot depend on the solution of qp `{name}`",
            static_site(site).unwrap_or_default()
        ),
    };
    Some(Diagnostic::new(e.span, msg).with_label(q.name.span, "declared here"))
}

/// The qps whose variables are called `name` (for "write `NAME.VAR`" hints).
pub(super) fn qps_with_var<'a>(model: &'a Model, name: &str) -> Vec<&'a str> {
    let mut out: Vec<&str> = model
        .qps()
        .filter(|q| q.vars.iter().any(|v| v.name == name))
        .map(|q| q.name.name.as_str())
        .collect();
    let mut seen = HashSet::new();
    out.retain(|q| seen.insert(*q));
    out
}

#[cfg(test)]
mod tests;
