//! `qp NAME(VAR, ...) { minimize EXPR; subject to LHS OP RHS; ... }` → [`ast::Qp`].

use pest::iterators::Pair;

use super::{build_expr, ident, internal, next, significant, span_of, Res, Rule};
use crate::ast::{self, ConstraintOp};

/// Builds a qp declaration: its name, variables, objective and constraints in order.
pub(super) fn build_qp(pair: Pair<'_, Rule>) -> Res<ast::Qp> {
    let span = span_of(&pair);
    let mut it = significant(pair);
    let name = ident(next(&mut it, span, "qp name")?);
    let mut vars = Vec::new();
    let mut objective = None;
    let mut constraints = Vec::new();
    for p in it {
        match p.as_rule() {
            Rule::ident => vars.push(ident(p)),
            Rule::qp_objective => {
                let s = span_of(&p);
                let mut inner = significant(p);
                objective = Some(build_expr(next(&mut inner, s, "objective")?)?);
            }
            Rule::qp_constraints => {
                for c in significant(p) {
                    constraints.push(build_constraint(c)?);
                }
            }
            _ => return Err(internal(span_of(&p), "unexpected part of a qp")),
        }
    }
    Ok(ast::Qp {
        name,
        vars,
        objective: objective.ok_or_else(|| internal(span, "qp without objective"))?,
        constraints,
        span,
    })
}

fn build_constraint(pair: Pair<'_, Rule>) -> Res<ast::QpConstraint> {
    let span = span_of(&pair);
    let mut it = significant(pair);
    let lhs = build_expr(next(&mut it, span, "constraint left-hand side")?)?;
    let op_pair = next(&mut it, span, "constraint operator")?;
    let op = match op_pair.as_rule() {
        Rule::le => ConstraintOp::Le,
        Rule::ge => ConstraintOp::Ge,
        Rule::eq => ConstraintOp::Eq,
        Rule::lt => ConstraintOp::Lt,
        Rule::gt => ConstraintOp::Gt,
        _ => return Err(internal(span_of(&op_pair), "constraint operator")),
    };
    let rhs = build_expr(next(&mut it, span, "constraint right-hand side")?)?;
    Ok(ast::QpConstraint {
        lhs,
        op,
        op_span: span_of(&op_pair),
        rhs,
        span,
    })
}
