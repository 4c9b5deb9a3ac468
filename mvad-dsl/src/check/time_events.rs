//! Rules of time events and data tables.
//!
//! - A table names a file (a path that is not blank).
//! - A `TABLE.COL` whose TABLE is declared reads a column (its columns are known only once the
//!   CSV file is read, so the loader checks them, located in the file). What a dotted name
//!   resolves to (a table, a qp, neither) is a name rule ([`super::names`]); the rules below
//!   concern the names that resolve to tables.
//! - `at each EXPR` reads columns of exactly one table: the event runs over that table's rows.
//! - A column is read only where a row is current: in the times, the reset block and the
//!   `sum(EVENT, ..)` cost terms of an `at each` event over the column's table.
//!
//! (That `at`, `every` and `at each` times use only params, consts and numbers is a scope rule
//! of [`super::names`]: their site is [`super::Site::EventTime`].)

use std::collections::{HashMap, HashSet};

use super::{all_exprs, walk_expr};
use crate::ast::{CostKind, Event, Expr, ExprKind, Model, Trigger};
use crate::diag::Diagnostic;
use crate::span::Span;

/// Checks the table and time-event rules above.
pub fn check_time_events(model: &Model) -> Vec<Diagnostic> {
    let mut tables: HashMap<&str, Span> = HashMap::new();
    let mut out = Vec::new();
    for t in model.tables() {
        tables.entry(t.name.name.as_str()).or_insert(t.name.span);
        if t.file.trim().is_empty() {
            out.push(
                Diagnostic::new(
                    t.file_span,
                    format!("table `{}` names no file", t.name.name),
                )
                .with_help("write the CSV file's path, relative to the model file"),
            );
        }
    }
    let mut allowed: HashSet<*const Expr> = HashSet::new();
    for (_, ev) in model.all_events() {
        let Trigger::Each(times) = &ev.trigger else {
            continue;
        };
        let read = tables_read(model, times);
        // Columns of an event whose times are wrong get no errors of their own.
        let excuse = |allowed: &mut HashSet<*const Expr>| {
            for x in event_row_exprs(model, ev, times) {
                walk_expr(x, &mut |c| {
                    if matches!(c.kind, ExprKind::Column { .. }) {
                        allowed.insert(c as *const Expr);
                    }
                });
            }
        };
        let Some(&(first, _)) = read.first() else {
            excuse(&mut allowed);
            out.push(
                Diagnostic::new(
                    times.span,
                    format!("the times of {} read no table column", event_label(ev)),
                )
                .with_help("`at each` runs over the rows of a table: write `at each TABLE.COL`"),
            );
            continue;
        };
        if let Some(&(other, span)) = read.iter().find(|(t, _)| *t != first) {
            out.push(
                Diagnostic::new(
                    span,
                    format!(
                        "the times of {} read two tables, `{first}` and `{other}`",
                        event_label(ev)
                    ),
                )
                .with_help("`at each` runs over the rows of one table"),
            );
            excuse(&mut allowed);
            continue;
        }
        for x in event_row_exprs(model, ev, times) {
            walk_expr(x, &mut |c| {
                if let ExprKind::Column { table, .. } = &c.kind {
                    if table.name == first {
                        allowed.insert(c as *const Expr);
                    } else if tables.contains_key(table.name.as_str()) {
                        out.push(Diagnostic::new(
                            c.span,
                            format!(
                                "`{}` is a column of table `{}`, but {} runs over the rows of table `{first}`",
                                column_text(c),
                                table.name,
                                event_label(ev)
                            ),
                        ));
                        allowed.insert(c as *const Expr);
                    }
                }
            });
        }
    }
    let mut reported = HashSet::new();
    for (_, e) in all_exprs(model) {
        if let ExprKind::Column { table, .. } = &e.kind {
            let known = tables.contains_key(table.name.as_str());
            if known && !allowed.contains(&(e as *const Expr)) && reported.insert(e.span) {
                out.push(
                    Diagnostic::new(
                        e.span,
                        format!(
                            "table column `{}` is read where no row is current",
                            column_text(e)
                        ),
                    )
                    .with_help(
                        "a row value may be read only in the times, the reset block and the \
                         `sum` terms of an `at each` event over its table",
                    ),
                );
            }
        }
    }
    out
}

/// The tables a time expression reads (its dotted names that are not only qps: an unknown or
/// ambiguous one is reported by [`super::names`] and counts as a table here, so that it has no
/// follow-on error), in order of first use, with the span of that use.
fn tables_read<'a>(model: &Model, e: &'a Expr) -> Vec<(&'a str, Span)> {
    let mut out: Vec<(&str, Span)> = Vec::new();
    walk_expr(e, &mut |x| {
        if let ExprKind::Column { table, .. } = &x.kind {
            let qp = model.qps().any(|q| q.name.name == table.name)
                && !model.tables().any(|t| t.name.name == table.name);
            if !qp && !out.iter().any(|(t, _)| *t == table.name) {
                out.push((table.name.as_str(), x.span));
            }
        }
    });
    out
}

/// The expressions of an `at each` event in which its row is current: its times, its resets
/// and the `sum` terms that name it.
fn event_row_exprs<'a>(model: &'a Model, ev: &'a Event, times: &'a Expr) -> Vec<&'a Expr> {
    let mut out = vec![times];
    out.extend(ev.resets.iter().flatten().map(|r| &r.value));
    if let (Some(name), Some(cost)) = (&ev.name, model.cost()) {
        for term in &cost.terms {
            if let CostKind::Sum { event, value } = &term.kind {
                if event.name == name.name {
                    out.push(value);
                }
            }
        }
    }
    out
}

fn column_text(e: &Expr) -> String {
    match &e.kind {
        ExprKind::Column { table, column } => format!("{}.{}", table.name, column.name),
        _ => String::new(),
    }
}

fn event_label(e: &Event) -> String {
    match &e.name {
        Some(n) => format!("event `{}`", n.name),
        None => "the event".to_string(),
    }
}

#[cfg(test)]
mod tests;
