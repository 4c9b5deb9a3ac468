//! Text -> [`ast::Model`]: a nesting pre-scan, the pest grammar (`grammar.pest`), then a
//! walk over pest's pairs with an operator-precedence (Pratt) pass for expressions.
//!
//! Precedence, tightest first: `^` (right associative), unary `-`, `* /`, `+ -` (left
//! associative), so `-x^2` is `-(x^2)` and `2^-x*3` is `(2^(-x))*3`.
//!
//! **Invariant:** nothing here recurses deeper than the input's nesting, and the pre-scan
//! ([`check_nesting`]) rejects more than [`MAX_NESTING`] nested brackets or `if`s before
//! pest (which recurses) sees the text; the Pratt pass is iterative and rejects trees
//! deeper than [`ast::MAX_DEPTH`]. No input can overflow the stack.

use pest::iterators::Pair;
use pest::Parser;

use crate::ast::{self, BinOp, CmpOp, Expr, ExprKind, Ident};
use crate::diag::{self, Diagnostic};
use crate::span::Span;

mod generated {
    #![allow(missing_docs)]
    /// The pest parser generated from `grammar.pest`; its `Rule` enum names the rules.
    #[derive(pest_derive::Parser)]
    #[grammar = "grammar.pest"]
    pub struct HybParser;
}

pub use generated::{HybParser, Rule};

/// The deepest nesting of brackets and `if` expressions the parser accepts.
pub const MAX_NESTING: usize = 64;

/// Parses one model. Syntax errors come back as located [`Diagnostic`]s (pest stops at the
/// first syntax error, so that vector has one entry).
pub fn parse(src: &str) -> Result<ast::Model, Vec<Diagnostic>> {
    check_nesting(src).map_err(|d| vec![d])?;
    let mut pairs =
        HybParser::parse(Rule::file, src).map_err(|e| vec![diag::from_pest(&e, src)])?;
    let file = pairs
        .next()
        .ok_or_else(|| vec![Diagnostic::new(Span::point(0), "empty input")])?;
    let model = file
        .into_inner()
        .find(|p| p.as_rule() == Rule::model)
        .ok_or_else(|| vec![Diagnostic::new(Span::point(0), "expected a model")])?;
    build_model(model).map_err(|d| vec![d])
}

/// Rejects input whose brackets or `if` expressions nest more than [`MAX_NESTING`] deep,
/// before pest's recursive descent sees it.
///
/// Depth counts open `(`, `[`, `{` plus the `if` keywords since the last `;`, `{` or `}`
/// (an `if` ends at the end of its statement at the latest). Comments are skipped.
pub fn check_nesting(src: &str) -> Result<(), Diagnostic> {
    let bytes = src.as_bytes();
    let mut brackets = 0usize;
    let mut ifs = 0usize;
    let mut i = 0;
    while i < bytes.len() {
        let b = bytes[i];
        match b {
            b'/' if bytes.get(i + 1) == Some(&b'/') => {
                while i < bytes.len() && bytes[i] != b'\n' {
                    i += 1;
                }
                continue;
            }
            b'/' if bytes.get(i + 1) == Some(&b'*') => {
                i += 2;
                while i < bytes.len() && !(bytes[i] == b'*' && bytes.get(i + 1) == Some(&b'/')) {
                    i += 1;
                }
                i += 2;
                continue;
            }
            b'(' | b'[' | b'{' => {
                brackets += 1;
                if b == b'{' {
                    ifs = 0;
                }
            }
            b')' | b']' | b'}' => {
                brackets = brackets.saturating_sub(1);
                if b == b'}' {
                    ifs = 0;
                }
            }
            b';' => ifs = 0,
            b'i' if bytes.get(i + 1) == Some(&b'f')
                && (i == 0 || !is_ident_byte(bytes[i - 1]))
                && !bytes.get(i + 2).copied().is_some_and(is_ident_byte) =>
            {
                ifs += 1;
            }
            _ => {}
        }
        if brackets + ifs > MAX_NESTING {
            return Err(Diagnostic::new(
                Span::new(i, i + 1),
                format!("expression nested too deeply (more than {MAX_NESTING} levels)"),
            ));
        }
        i += 1;
    }
    Ok(())
}

fn is_ident_byte(b: u8) -> bool {
    b.is_ascii_alphanumeric() || b == b'_'
}

type Res<T> = Result<T, Diagnostic>;

fn span_of(pair: &Pair<'_, Rule>) -> Span {
    pair.as_span().into()
}

fn ident(pair: Pair<'_, Rule>) -> Ident {
    Ident {
        name: pair.as_str().to_string(),
        span: span_of(&pair),
    }
}

/// The children of `pair`, keywords and punctuation dropped (they carry no data).
fn significant(pair: Pair<'_, Rule>) -> impl Iterator<Item = Pair<'_, Rule>> {
    pair.into_inner().filter(|p| {
        !matches!(
            p.as_rule(),
            Rule::kw_model
                | Rule::kw_param
                | Rule::kw_const
                | Rule::kw_state
                | Rule::kw_flow
                | Rule::kw_mode
                | Rule::kw_initial
                | Rule::kw_event
                | Rule::kw_when
                | Rule::kw_table
                | Rule::kw_at
                | Rule::kw_each
                | Rule::kw_every
                | Rule::kw_from
                | Rule::dot
                | Rule::kw_observe
                | Rule::kw_qp
                | Rule::kw_minimize
                | Rule::kw_subject
                | Rule::kw_to
                | Rule::kw_cost
                | Rule::kw_horizon
                | Rule::kw_der
                | Rule::kw_integral
                | Rule::kw_sum
                | Rule::kw_final
                | Rule::kw_if
                | Rule::kw_then
                | Rule::kw_else
                | Rule::semicolon
                | Rule::comma
                | Rule::lbrace
                | Rule::rbrace
                | Rule::lparen
                | Rule::rparen
                | Rule::assign
                | Rule::arrow
                | Rule::EOI
        )
    })
}

/// A structural mismatch between the grammar and this walker (a bug, reported, not a panic).
fn internal(span: Span, what: &str) -> Diagnostic {
    Diagnostic::new(span, format!("internal parser error: {what}"))
}

fn next<'a>(
    it: &mut impl Iterator<Item = Pair<'a, Rule>>,
    span: Span,
    what: &str,
) -> Res<Pair<'a, Rule>> {
    it.next().ok_or_else(|| internal(span, what))
}

fn build_model(pair: Pair<'_, Rule>) -> Res<ast::Model> {
    let span = span_of(&pair);
    let mut it = significant(pair);
    let name = ident(next(&mut it, span, "model name")?);
    let mut items = Vec::new();
    for p in it {
        items.push(build_item(p)?);
    }
    Ok(ast::Model { name, items, span })
}

fn build_item(pair: Pair<'_, Rule>) -> Res<ast::Item> {
    let span = span_of(&pair);
    let rule = pair.as_rule();
    Ok(match rule {
        Rule::param_decl | Rule::const_decl | Rule::state_decl | Rule::observe_decl => {
            let mut it = significant(pair);
            let name = ident(next(&mut it, span, "declared name")?);
            let value = build_expr(next(&mut it, span, "declared value")?)?;
            match rule {
                Rule::param_decl => ast::Item::Param(ast::Param { name, value, span }),
                Rule::const_decl => ast::Item::Const(ast::Const { name, value, span }),
                Rule::state_decl => ast::Item::State(ast::State {
                    name,
                    init: value,
                    span,
                }),
                _ => ast::Item::Observe(ast::Observe { name, value, span }),
            }
        }
        Rule::flow_block => ast::Item::Flow(ast::Flow {
            ders: significant(pair).map(build_der).collect::<Res<_>>()?,
            span,
        }),
        Rule::mode_block => {
            let mut it = significant(pair);
            let name = ident(next(&mut it, span, "mode name")?);
            let mut ders = Vec::new();
            let mut events = Vec::new();
            for p in it {
                match p.as_rule() {
                    Rule::der_eq => ders.push(build_der(p)?),
                    _ => events.push(build_event(p)?),
                }
            }
            ast::Item::Mode(ast::Mode {
                name,
                ders,
                events,
                span,
            })
        }
        Rule::initial_decl => {
            let mut it = significant(pair);
            ast::Item::InitialMode(ast::InitialMode {
                mode: ident(next(&mut it, span, "initial mode")?),
                span,
            })
        }
        Rule::event_decl => ast::Item::Event(build_event(pair)?),
        Rule::table_decl => {
            let mut it = significant(pair);
            let name = ident(next(&mut it, span, "table name")?);
            let lit = next(&mut it, span, "table file")?;
            ast::Item::Table(ast::Table {
                name,
                file: unescape(lit.as_str()),
                file_span: span_of(&lit),
                span,
            })
        }
        Rule::cost_decl => ast::Item::Cost(build_cost(pair)?),
        Rule::qp_decl => ast::Item::Qp(qp::build_qp(pair)?),
        Rule::horizon_decl => {
            let mut it = significant(pair);
            ast::Item::Horizon(ast::Horizon {
                value: build_expr(next(&mut it, span, "horizon")?)?,
                span,
            })
        }
        _ => return Err(internal(span, "unexpected declaration")),
    })
}

fn build_der(pair: Pair<'_, Rule>) -> Res<ast::Der> {
    let span = span_of(&pair);
    let mut it = significant(pair);
    let state = ident(next(&mut it, span, "der state")?);
    let value = build_expr(next(&mut it, span, "der value")?)?;
    Ok(ast::Der { state, value, span })
}

/// The text of a string literal `"..."` without its quotes, `\x` read as `x`.
fn unescape(lit: &str) -> String {
    let inner = lit
        .strip_prefix('"')
        .and_then(|s| s.strip_suffix('"'))
        .unwrap_or(lit);
    let mut out = String::with_capacity(inner.len());
    let mut chars = inner.chars();
    while let Some(c) = chars.next() {
        if c == '\\' {
            out.extend(chars.next());
        } else {
            out.push(c);
        }
    }
    out
}

fn build_trigger(pair: Pair<'_, Rule>) -> Res<ast::Trigger> {
    let span = span_of(&pair);
    let rule = pair.as_rule();
    let mut it = significant(pair);
    Ok(match rule {
        Rule::when_trigger => ast::Trigger::When(build_condition(next(&mut it, span, "guard")?)?.0),
        Rule::at_trigger => ast::Trigger::At(build_expr(next(&mut it, span, "event time")?)?),
        Rule::each_trigger => ast::Trigger::Each(build_expr(next(&mut it, span, "event times")?)?),
        Rule::every_trigger => {
            let period = build_expr(next(&mut it, span, "event period")?)?;
            let start = it.next().map(build_expr).transpose()?;
            ast::Trigger::Every { period, start }
        }
        _ => return Err(internal(span, "unexpected trigger")),
    })
}

fn build_event(pair: Pair<'_, Rule>) -> Res<ast::Event> {
    let span = span_of(&pair);
    let mut name = None;
    let mut guard = None;
    let mut target = None;
    let mut resets = None;
    for p in significant(pair) {
        match p.as_rule() {
            Rule::ident => name = Some(ident(p)),
            Rule::when_trigger | Rule::at_trigger | Rule::each_trigger | Rule::every_trigger => {
                guard = Some(build_trigger(p)?)
            }
            Rule::target => {
                let s = span_of(&p);
                let mut it = significant(p);
                target = Some(ident(next(&mut it, s, "target mode")?));
            }
            Rule::reset_block => {
                let mut list = Vec::new();
                for r in significant(p) {
                    let rs = span_of(&r);
                    let mut it = significant(r);
                    let state = ident(next(&mut it, rs, "reset state")?);
                    let value = build_expr(next(&mut it, rs, "reset value")?)?;
                    list.push(ast::Reset {
                        state,
                        value,
                        span: rs,
                    });
                }
                resets = Some(list);
            }
            _ => return Err(internal(span_of(&p), "unexpected part of an event")),
        }
    }
    Ok(ast::Event {
        name,
        trigger: guard.ok_or_else(|| internal(span, "event without trigger"))?,
        target,
        resets,
        span,
    })
}

fn parse_number(pair: &Pair<'_, Rule>) -> Res<f64> {
    let text: String = pair.as_str().chars().filter(|&c| c != '_').collect();
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(Diagnostic::new(
            span_of(pair),
            format!("number `{}` is out of range", pair.as_str()),
        )),
    }
}

fn build_cost(pair: Pair<'_, Rule>) -> Res<ast::Cost> {
    let span = span_of(&pair);
    let mut terms = Vec::new();
    let mut sign = 1.0;
    for p in significant(pair) {
        match p.as_rule() {
            Rule::add => sign = 1.0,
            Rule::sub => sign = -1.0,
            Rule::cost_term => {
                let mut t = build_cost_term(p)?;
                t.factor *= sign;
                terms.push(t);
            }
            _ => return Err(internal(span_of(&p), "unexpected part of a cost")),
        }
    }
    Ok(ast::Cost { terms, span })
}

fn build_cost_term(pair: Pair<'_, Rule>) -> Res<ast::CostTerm> {
    let span = span_of(&pair);
    let mut factor = 1.0;
    let mut kind = None;
    let mut divide = false;
    for p in significant(pair) {
        match p.as_rule() {
            Rule::neg => factor = -factor,
            Rule::mul => {}
            Rule::div => divide = true,
            Rule::number => {
                let v = parse_number(&p)?;
                if divide {
                    if v == 0.0 {
                        return Err(Diagnostic::new(span_of(&p), "cost factor divides by zero"));
                    }
                    factor /= v;
                } else {
                    factor *= v;
                }
            }
            Rule::integral_term | Rule::final_term => {
                let s = span_of(&p);
                let is_integral = p.as_rule() == Rule::integral_term;
                let mut it = significant(p);
                let e = build_expr(next(&mut it, s, "cost term argument")?)?;
                kind = Some(if is_integral {
                    ast::CostKind::Integral(e)
                } else {
                    ast::CostKind::Final(e)
                });
            }
            Rule::sum_term => {
                let s = span_of(&p);
                let mut it = significant(p);
                let event = ident(next(&mut it, s, "sum event")?);
                let value = build_expr(next(&mut it, s, "sum argument")?)?;
                kind = Some(ast::CostKind::Sum { event, value });
            }
            Rule::static_term => kind = Some(ast::CostKind::Static(build_expr(p)?)),
            _ => return Err(internal(span_of(&p), "unexpected part of a cost term")),
        }
    }
    if !factor.is_finite() {
        return Err(Diagnostic::new(span, "cost factor is out of range"));
    }
    Ok(ast::CostTerm {
        factor,
        kind: kind.ok_or_else(|| internal(span, "cost term without kind"))?,
        span,
    })
}

/// Returns the condition and its tree depth.
fn build_condition(pair: Pair<'_, Rule>) -> Res<(ast::Condition, usize)> {
    let span = span_of(&pair);
    let mut it = pair.into_inner();
    let (lhs, dl) = expr_with_depth(next(&mut it, span, "condition")?)?;
    let Some(op_pair) = it.next() else {
        return Ok((ast::Condition::NotComparison(Box::new(lhs)), dl));
    };
    let op = match op_pair.as_rule() {
        Rule::le => CmpOp::Le,
        Rule::lt => CmpOp::Lt,
        Rule::ge => CmpOp::Ge,
        Rule::gt => CmpOp::Gt,
        _ => return Err(internal(span_of(&op_pair), "comparison operator")),
    };
    let (rhs, dr) = expr_with_depth(next(&mut it, span, "comparison right-hand side")?)?;
    let depth = 1 + dl.max(dr);
    Ok((
        ast::Condition::Compare(Box::new(ast::Comparison {
            lhs,
            op,
            op_span: span_of(&op_pair),
            rhs,
            span,
        })),
        depth,
    ))
}

fn build_expr(pair: Pair<'_, Rule>) -> Res<Expr> {
    expr_with_depth(pair).map(|(e, _)| e)
}

/// A pending operator of the precedence pass.
enum Op {
    Neg(Span),
    Bin(BinOp, Span),
}

/// Binding power: `+ -` 1, `* /` 2, unary `-` 3, `^` 4.
fn power(op: &Op) -> u8 {
    match op {
        Op::Neg(_) => 3,
        Op::Bin(BinOp::Add | BinOp::Sub, _) => 1,
        Op::Bin(BinOp::Mul | BinOp::Div, _) => 2,
        Op::Bin(BinOp::Pow, _) => 4,
    }
}

fn too_deep(span: Span) -> Diagnostic {
    Diagnostic::new(
        span,
        format!(
            "expression nested too deeply (more than {} levels)",
            ast::MAX_DEPTH
        ),
    )
}

/// Pops one operator and applies it to the operand stack.
fn reduce(operands: &mut Vec<(Expr, usize)>, op: Op) -> Res<()> {
    let malformed = || internal(Span::default(), "operator without operand");
    let (expr, depth) = match op {
        Op::Neg(s) => {
            let (e, d) = operands.pop().ok_or_else(malformed)?;
            let span = s.to(e.span);
            (
                Expr {
                    kind: ExprKind::Neg(Box::new(e)),
                    span,
                },
                d + 1,
            )
        }
        Op::Bin(op, op_span) => {
            let (r, dr) = operands.pop().ok_or_else(malformed)?;
            let (l, dl) = operands.pop().ok_or_else(malformed)?;
            let span = l.span.to(r.span);
            (
                Expr {
                    kind: ExprKind::Binary {
                        op,
                        op_span,
                        lhs: Box::new(l),
                        rhs: Box::new(r),
                    },
                    span,
                },
                dl.max(dr) + 1,
            )
        }
    };
    if depth > ast::MAX_DEPTH {
        return Err(too_deep(expr.span));
    }
    operands.push((expr, depth));
    Ok(())
}

/// Builds an expression from its flat pest sequence with operator precedence, iteratively
/// (shunting-yard), and returns it with its tree depth.
fn expr_with_depth(pair: Pair<'_, Rule>) -> Res<(Expr, usize)> {
    let mut operands: Vec<(Expr, usize)> = Vec::new();
    let mut ops: Vec<Op> = Vec::new();
    for p in pair.into_inner() {
        let binop = match p.as_rule() {
            Rule::neg => {
                ops.push(Op::Neg(span_of(&p)));
                continue;
            }
            Rule::add => BinOp::Add,
            Rule::sub => BinOp::Sub,
            Rule::mul => BinOp::Mul,
            Rule::div => BinOp::Div,
            Rule::pow => BinOp::Pow,
            _ => {
                operands.push(build_primary(p)?);
                continue;
            }
        };
        let new = Op::Bin(binop, span_of(&p));
        let (pw, right_assoc) = (power(&new), binop == BinOp::Pow);
        while let Some(top) = ops.last() {
            let tp = power(top);
            if tp > pw || (tp == pw && !right_assoc) {
                let top = ops
                    .pop()
                    .ok_or_else(|| internal(span_of(&p), "operator stack"))?;
                reduce(&mut operands, top)?;
            } else {
                break;
            }
        }
        ops.push(new);
    }
    while let Some(top) = ops.pop() {
        reduce(&mut operands, top)?;
    }
    match (operands.pop(), operands.is_empty()) {
        (Some(e), true) => Ok(e),
        _ => Err(internal(Span::default(), "unbalanced expression")),
    }
}

fn build_primary(pair: Pair<'_, Rule>) -> Res<(Expr, usize)> {
    let span = span_of(&pair);
    match pair.as_rule() {
        Rule::number => Ok((
            Expr {
                kind: ExprKind::Number(parse_number(&pair)?),
                span,
            },
            1,
        )),
        Rule::ident => {
            let kind = if pair.as_str() == "t" {
                ExprKind::Time
            } else {
                ExprKind::Name(ident(pair))
            };
            Ok((Expr { kind, span }, 1))
        }
        Rule::column => {
            let mut it = significant(pair);
            let table = ident(next(&mut it, span, "table or qp name")?);
            let column = ident(next(&mut it, span, "column or qp variable")?);
            Ok((
                Expr {
                    kind: ExprKind::Column { table, column },
                    span,
                },
                1,
            ))
        }
        Rule::paren => {
            // The parentheses belong to the expression's span, so `-(g + v)` covers `)`.
            let mut it = significant(pair);
            let (mut e, d) = expr_with_depth(next(&mut it, span, "parenthesised expression")?)?;
            e.span = span;
            Ok((e, d))
        }
        Rule::call => {
            let mut it = significant(pair);
            let func = ident(next(&mut it, span, "function name")?);
            let mut args = Vec::new();
            let mut depth = 0;
            for a in it {
                let (e, d) = expr_with_depth(a)?;
                depth = depth.max(d);
                args.push(e);
            }
            if depth + 1 > ast::MAX_DEPTH {
                return Err(too_deep(span));
            }
            Ok((
                Expr {
                    kind: ExprKind::Call { func, args },
                    span,
                },
                depth + 1,
            ))
        }
        Rule::if_expr => {
            let mut it = significant(pair);
            let (cond, dc) = build_condition(next(&mut it, span, "if condition")?)?;
            let (then, dt) = expr_with_depth(next(&mut it, span, "then branch")?)?;
            let (els, de) = expr_with_depth(next(&mut it, span, "else branch")?)?;
            let depth = 1 + dc.max(dt).max(de);
            if depth > ast::MAX_DEPTH {
                return Err(too_deep(span));
            }
            Ok((
                Expr {
                    kind: ExprKind::If {
                        cond: Box::new(cond),
                        then: Box::new(then),
                        els: Box::new(els),
                    },
                    span,
                },
                depth,
            ))
        }
        _ => Err(internal(span, "unexpected operand")),
    }
}

mod qp;

#[cfg(test)]
pub(crate) mod tests;
