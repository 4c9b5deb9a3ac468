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
                | Rule::kw_observe
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
        Rule::cost_decl => ast::Item::Cost(build_cost(pair)?),
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

fn build_event(pair: Pair<'_, Rule>) -> Res<ast::Event> {
    let span = span_of(&pair);
    let mut name = None;
    let mut guard = None;
    let mut target = None;
    let mut resets = None;
    for p in significant(pair) {
        match p.as_rule() {
            Rule::ident => name = Some(ident(p)),
            Rule::condition => guard = Some(build_condition(p)?.0),
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
        guard: guard.ok_or_else(|| internal(span, "event without guard"))?,
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

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::span::line_col;

    pub(crate) const BALL: &str = r#"
// Bouncing ball: the seed paper's E1.
model BouncingBall {
    param e = 0.8;            // restitution coefficient, differentiable
    param g = 9.81;
    param h0 = 2.0;
    param v0 = 0.0;
    state h = h0;             // initial values may depend on params
    state v = v0;

    flow {
        der(h) = v;
        der(v) = -g;
    }

    event impact when h <= 0 {
        v = -e * v;
    }

    observe height = h;
    observe velocity = v;

    cost = integral(h);
    horizon 2.0;
}
"#;

    pub(crate) const THERMOSTAT: &str = r#"
model Thermostat {
    param k = 0.5;  param lo = 18.0;  param hi = 22.0;  param p = 10.0;
    const ambient = 10.0;
    state temp = 19.0;
    initial mode heating;
    mode heating {
        der(temp) = -k * (temp - ambient) + p;
        event switch_off when temp >= hi -> cooling;
    }
    mode cooling {
        der(temp) = -k * (temp - ambient);
        event switch_on when temp <= lo -> heating;
    }
    cost = integral((temp - 20)^2);
    horizon 10;
}
"#;

    /// Lisp-style rendering of an expression, for precedence tests.
    fn sexpr(e: &Expr) -> String {
        match &e.kind {
            ExprKind::Number(v) => format!("{v}"),
            ExprKind::Name(id) => id.name.clone(),
            ExprKind::Time => "t".into(),
            ExprKind::Neg(x) => format!("(neg {})", sexpr(x)),
            ExprKind::Binary { op, lhs, rhs, .. } => {
                format!("({} {} {})", op.as_str(), sexpr(lhs), sexpr(rhs))
            }
            ExprKind::Call { func, args } => {
                let a: Vec<String> = args.iter().map(sexpr).collect();
                format!("({} {})", func.name, a.join(" "))
            }
            ExprKind::If { cond, then, els } => {
                let c = match &**cond {
                    ast::Condition::Compare(c) => {
                        format!("({} {} {})", c.op.as_str(), sexpr(&c.lhs), sexpr(&c.rhs))
                    }
                    ast::Condition::NotComparison(x) => format!("(not-cmp {})", sexpr(x)),
                };
                format!("(if {c} {} {})", sexpr(then), sexpr(els))
            }
        }
    }

    fn model_with_rhs(rhs: &str) -> String {
        format!("model M {{ state x = 0; flow {{ der(x) = {rhs}; }} }}")
    }

    fn rhs_of(src: &str) -> Result<Expr, Vec<Diagnostic>> {
        let m = parse(src)?;
        Ok(m.flow().expect("flow").ders[0].value.clone())
    }

    #[test]
    fn spec_examples_parse() {
        let ball = parse(BALL).expect("ball parses");
        assert_eq!(ball.name.name, "BouncingBall");
        assert_eq!(ball.params().count(), 4);
        assert_eq!(ball.states().count(), 2);
        assert_eq!(ball.flow().unwrap().ders.len(), 2);
        let ev: Vec<_> = ball.all_events();
        assert_eq!(ev.len(), 1);
        let (mode, impact) = ev[0];
        assert!(mode.is_none());
        assert_eq!(impact.name.as_ref().unwrap().name, "impact");
        let cmp = impact.comparison().expect("comparison");
        assert_eq!(cmp.op, CmpOp::Le);
        assert_eq!(&BALL[cmp.op_span.range()], "<=");
        assert_eq!(impact.resets.as_ref().unwrap().len(), 1);
        assert_eq!(
            sexpr(&impact.resets.as_ref().unwrap()[0].value),
            "(* (neg e) v)"
        );
        assert_eq!(ball.observes().count(), 2);
        let cost = ball.cost().unwrap();
        assert_eq!(cost.terms.len(), 1);
        assert!(matches!(cost.terms[0].kind, ast::CostKind::Integral(_)));
        assert_eq!(ball.horizon().unwrap().value.kind, ExprKind::Number(2.0));
        // Spans point at the right text.
        assert_eq!(&BALL[ball.name.span.range()], "BouncingBall");
        assert_eq!(
            &BALL[impact.span.range()].lines().next().unwrap(),
            &"event impact when h <= 0 {"
        );

        let th = parse(THERMOSTAT).expect("thermostat parses");
        assert_eq!(th.modes().count(), 2);
        assert_eq!(th.initial_mode().unwrap().mode.name, "heating");
        let ev = th.all_events();
        assert_eq!(ev.len(), 2);
        assert_eq!(ev[0].0.unwrap().name.name, "heating");
        assert_eq!(ev[0].1.target.as_ref().unwrap().name, "cooling");
        assert!(ev[0].1.resets.is_none());
        assert_eq!(ev[1].1.comparison().unwrap().op, CmpOp::Le);
        let ast::CostKind::Integral(e) = &th.cost().unwrap().terms[0].kind else {
            panic!("integral")
        };
        assert_eq!(sexpr(e), "(^ (- temp 20) 2)");
    }

    #[test]
    fn precedence_and_associativity() {
        let table = [
            ("-x^2", "(neg (^ x 2))"),
            ("2^3^2", "(^ 2 (^ 3 2))"),
            ("a-b-c", "(- (- a b) c)"),
            ("a/b/c", "(/ (/ a b) c)"),
            ("a*b+c/d", "(+ (* a b) (/ c d))"),
            ("a+b*c", "(+ a (* b c))"),
            ("-a*b", "(* (neg a) b)"),
            ("a - -b", "(- a (neg b))"),
            ("2^-x*3", "(* (^ 2 (neg x)) 3)"),
            ("-x^-y^2", "(neg (^ x (neg (^ y 2))))"),
            ("(a+b)*c", "(* (+ a b) c)"),
            ("- - a", "(neg (neg a))"),
            ("t * sin(t)", "(* t (sin t))"),
            ("max(a, b + 1)", "(max a (+ b 1))"),
            ("if a < b then 1 else 2 + 3", "(if (< a b) 1 (+ 2 3))"),
            ("1 + if a >= b then c else d", "(+ 1 (if (>= a b) c d))"),
            ("if a then 1 else 2", "(if (not-cmp a) 1 2)"),
            ("1e-3 + 2. + 0.5 + 1_000", "(+ (+ (+ 0.001 2) 0.5) 1000)"),
        ];
        for (src, want) in table {
            let e = rhs_of(&model_with_rhs(src)).unwrap_or_else(|d| panic!("{src}: {d:?}"));
            assert_eq!(sexpr(&e), want, "{src}");
        }
    }

    #[test]
    fn expression_spans_cover_operands() {
        let src = model_with_rhs("-(g + v) * 2");
        let e = rhs_of(&src).unwrap();
        assert_eq!(&src[e.span.range()], "-(g + v) * 2");
        let ExprKind::Binary { lhs, op_span, .. } = &e.kind else {
            panic!()
        };
        assert_eq!(&src[op_span.range()], "*");
        assert_eq!(&src[lhs.span.range()], "-(g + v)");
    }

    #[test]
    fn cost_terms_fold_factors_and_signs() {
        let src = "model M { state x = 0; flow { der(x) = 1; } event hit when x >= 1 { x = 0; }
                   cost = 0.5 * integral(x^2) - 2 * final(x) + sum(hit, x) / 4 - integral(x) * 3; }";
        let m = parse(src).unwrap();
        let f: Vec<f64> = m.cost().unwrap().terms.iter().map(|t| t.factor).collect();
        assert_eq!(f, vec![0.5, -2.0, 0.25, -3.0]);
        assert!(matches!(
            m.cost().unwrap().terms[2].kind,
            ast::CostKind::Sum { .. }
        ));
    }

    /// Parse `src`, expect a syntax error at `line:col` whose message contains `msg`.
    fn expect_error(src: &str, line: usize, col: usize, msg: &str) {
        let errs = match parse(src) {
            Ok(_) => panic!("{src:?} parsed"),
            Err(e) => e,
        };
        assert_eq!(errs.len(), 1, "{src:?}");
        let d = &errs[0];
        assert_eq!(
            line_col(src, d.span.start),
            (line, col),
            "{src:?}: {}",
            d.message
        );
        assert!(
            d.message.contains(msg),
            "{src:?}: got {:?}, want {msg:?}",
            d.message
        );
    }

    #[test]
    fn syntax_errors_are_located() {
        expect_error("", 1, 1, "unexpected end of input; expected `model`");
        expect_error("model", 1, 6, "expected an identifier");
        expect_error("model M {", 1, 10, "unexpected end of input");
        expect_error("model M { param a = 1 }", 1, 23, "unexpected `}`; expected");
        expect_error("model M { param a = 1 }", 1, 23, "`;`");
        expect_error(
            "model M {\n  state x = (1 + ;\n}",
            2,
            18,
            "expected an expression",
        );
        expect_error(
            "model M {\n  flow { der(x) = g + * v; }\n}",
            2,
            23,
            "unexpected `*`",
        );
        expect_error(
            "model M { foo x = 1; }",
            1,
            11,
            "unexpected `foo`; expected `param`",
        );
        expect_error(
            "model M { event when x == 0 { } }",
            1,
            24,
            "unexpected `==`",
        );
        expect_error("model M { param a = 1.0f64; }", 1, 21, "");
        expect_error(
            "model M { param a = 1; } trailing",
            1,
            26,
            "expected end of input",
        );
        expect_error("model M { cost = h; }", 1, 18, "expected");
        expect_error(
            "model M { param a = 1e999; }",
            1,
            21,
            "number `1e999` is out of range",
        );
        expect_error("model M { /* unterminated", 1, 11, "");
        expect_error("\u{0}\u{1}\u{ff}garbage", 1, 1, "character U+0000");
    }

    #[test]
    fn missing_semicolon_hint_points_at_the_line_end() {
        let src = "model M {\n  param g = 9.81\n  state v = 0.0;\n}";
        let d = &parse(src).unwrap_err()[0];
        assert_eq!(line_col(src, d.span.start), (3, 3));
        assert!(
            d.message.starts_with("unexpected `state`; expected `;`"),
            "{}",
            d.message
        );
        assert_eq!(d.help.as_deref(), Some("add `;` after `9.81`"));
        assert_eq!(&src[d.labels[0].0.range()], "9.81");
        // Same line, or a comment in between: no hint.
        let d = &parse("model M { param g = 9.81 state v = 0.0; }").unwrap_err()[0];
        assert!(d.help.is_none());
        let d = &parse("model M {\n param g = 9.81 // c\n state v = 0.0; }").unwrap_err()[0];
        assert!(d.help.is_none());
    }

    #[test]
    fn comments_of_both_styles() {
        let src = "/* header */ model M { // line\n state x = /* inline */ 1; flow { der(x) = x /* c */ / 2; } }";
        let e = rhs_of(src).unwrap();
        assert_eq!(sexpr(&e), "(/ x 2)");
    }

    fn assert_too_deep(src: &str) {
        let errs = parse(src).expect_err("deep input must fail");
        assert!(
            errs[0].message.contains("nested too deeply"),
            "{}",
            errs[0].message
        );
    }

    #[test]
    fn deep_nesting_is_an_error_not_a_stack_overflow() {
        let n = 100_000;
        assert_too_deep(&model_with_rhs(&format!(
            "{}x{}",
            "(".repeat(n),
            ")".repeat(n)
        )));
        assert_too_deep(&model_with_rhs(&format!("{}x", "- ".repeat(n))));
        assert_too_deep(&model_with_rhs(&format!("{}x", "-".repeat(n))));
        assert_too_deep(&model_with_rhs(&format!("x{}", "^x".repeat(n))));
        assert_too_deep(&model_with_rhs(&format!("x{}", "+x".repeat(n))));
        assert_too_deep(&model_with_rhs(&format!(
            "{}1{}",
            "if x < 1 then 0 else ".repeat(n),
            ""
        )));
        assert_too_deep(&model_with_rhs(&format!(
            "{}x{}",
            "sin(".repeat(n),
            ")".repeat(n)
        )));
        // Unbalanced opening brackets only.
        assert_too_deep(&"(".repeat(n));
    }

    #[test]
    fn nesting_just_under_the_limits_parses() {
        let k = MAX_NESTING - 8; // the model's own braces and the der's parens count too
        let src = model_with_rhs(&format!("{}x{}", "(".repeat(k), ")".repeat(k)));
        rhs_of(&src).expect("nesting under the limit");
        let src = model_with_rhs(&format!("x{}", "+x".repeat(ast::MAX_DEPTH - 2)));
        rhs_of(&src).expect("depth under the limit");
    }

    #[test]
    fn nesting_at_the_limit_fits_a_small_stack() {
        // Brackets and `if`s just under MAX_NESTING, and trees just under MAX_DEPTH,
        // parsed and checked on a 1 MiB stack (half a test thread's, an eighth of a main
        // thread's); this holds unoptimised too (`cargo test --profile dev`).
        let k = MAX_NESTING - 8;
        let parens = model_with_rhs(&format!("{}x{}", "(".repeat(k), ")".repeat(k)));
        let ifs = model_with_rhs(&format!("{}1", "if x < 1 then 0 else ".repeat(k)));
        let calls = model_with_rhs(&format!("{}x{}", "sin(".repeat(k), ")".repeat(k)));
        let d = ast::MAX_DEPTH - 2;
        let sum = model_with_rhs(&format!("x{}", "+x".repeat(d)));
        let power = model_with_rhs(&format!("x{}", "^x".repeat(d)));
        let negs = model_with_rhs(&format!("{}x", "-".repeat(d)));
        let handle = std::thread::Builder::new()
            .stack_size(1 << 20)
            .spawn(move || {
                [parens, ifs, calls, sum, power, negs]
                    .iter()
                    .map(|s| {
                        crate::front(s)
                            .map(|_| ())
                            .map_err(|d| d[0].message.clone())
                    })
                    .collect::<Vec<_>>()
            })
            .expect("spawn");
        let results = handle.join().expect("no stack overflow");
        assert_eq!(results, vec![Ok(()); 6]);
    }

    #[test]
    fn nesting_prescan_ignores_comments() {
        let src = format!(
            "// {}\nmodel M {{ state x = 0; flow {{ der(x) = 1; }} }}",
            "(".repeat(1000)
        );
        parse(&src).expect("comment parens are not nesting");
    }

    /// A random expression tree (spans are irrelevant here).
    fn arb_expr() -> impl proptest::strategy::Strategy<Value = Expr> {
        use proptest::prelude::*;
        let e = |kind| Expr {
            kind,
            span: Span::default(),
        };
        let name = |n: &str| Ident {
            name: n.to_string(),
            span: Span::default(),
        };
        let leaf = prop_oneof![
            prop::sample::select(vec![0.5, 2.0, 3.0, 1e-7, 10.0])
                .prop_map(move |v| e(ExprKind::Number(v))),
            prop::sample::select(vec!["a", "b", "x"]).prop_map(move |n| e(ExprKind::Name(name(n)))),
            Just(e(ExprKind::Time)),
        ];
        leaf.prop_recursive(6, 48, 3, move |inner| {
            let bin = prop::sample::select(vec![
                BinOp::Add,
                BinOp::Sub,
                BinOp::Mul,
                BinOp::Div,
                BinOp::Pow,
            ]);
            let cmp = prop::sample::select(vec![CmpOp::Lt, CmpOp::Le, CmpOp::Gt, CmpOp::Ge]);
            prop_oneof![
                inner
                    .clone()
                    .prop_map(move |x| e(ExprKind::Neg(Box::new(x)))),
                (bin, inner.clone(), inner.clone()).prop_map(move |(op, l, r)| e(
                    ExprKind::Binary {
                        op,
                        op_span: Span::default(),
                        lhs: Box::new(l),
                        rhs: Box::new(r),
                    }
                )),
                inner.clone().prop_map(move |x| e(ExprKind::Call {
                    func: name("sin"),
                    args: vec![x]
                })),
                (inner.clone(), inner.clone()).prop_map(move |(x, y)| e(ExprKind::Call {
                    func: name("max"),
                    args: vec![x, y],
                })),
                (cmp, inner.clone(), inner.clone(), inner.clone(), inner).prop_map(
                    move |(op, l, r, a, b)| e(ExprKind::If {
                        cond: Box::new(ast::Condition::Compare(Box::new(ast::Comparison {
                            lhs: l,
                            op,
                            op_span: Span::default(),
                            rhs: r,
                            span: Span::default(),
                        }))),
                        then: Box::new(a),
                        els: Box::new(b),
                    })
                ),
            ]
        })
    }

    /// Binding strength of the expression's top node (atoms bind tightest, `if` loosest).
    fn strength(e: &Expr) -> u8 {
        match &e.kind {
            ExprKind::If { .. } => 0,
            ExprKind::Binary {
                op: BinOp::Add | BinOp::Sub,
                ..
            } => 1,
            ExprKind::Binary {
                op: BinOp::Mul | BinOp::Div,
                ..
            } => 2,
            ExprKind::Neg(_) => 3,
            ExprKind::Binary { op: BinOp::Pow, .. } => 4,
            _ => 5,
        }
    }

    /// Prints `e` with as few parentheses as the spec's precedence allows
    /// (`full`: parenthesise every operator node instead).
    fn print(e: &Expr, full: bool) -> String {
        let wrap = |x: &Expr, need: bool| {
            let s = print(x, full);
            if need || (full && strength(x) < 5) {
                format!("({s})")
            } else {
                s
            }
        };
        match &e.kind {
            ExprKind::Number(v) => format!("{v:?}"),
            ExprKind::Name(id) => id.name.clone(),
            ExprKind::Time => "t".into(),
            ExprKind::Neg(x) => format!("-{}", wrap(x, strength(x) < 3)),
            ExprKind::Binary { op, lhs, rhs, .. } => {
                let p = strength(e);
                let (l, r) = if *op == BinOp::Pow {
                    (strength(lhs) <= p, strength(rhs) < p)
                } else {
                    (strength(lhs) < p, strength(rhs) <= p)
                };
                format!("{} {} {}", wrap(lhs, l), op.as_str(), wrap(rhs, r))
            }
            ExprKind::Call { func, args } => {
                let a: Vec<String> = args.iter().map(|x| print(x, full)).collect();
                format!("{}({})", func.name, a.join(", "))
            }
            ExprKind::If { cond, then, els } => {
                let c = cond.comparison().expect("generated conditions compare");
                format!(
                    "if {} {} {} then {} else {}",
                    print(&c.lhs, full),
                    c.op.as_str(),
                    print(&c.rhs, full),
                    print(then, full),
                    print(els, full)
                )
            }
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(400))]

        /// Printing a tree with minimal or with full parentheses and parsing it back gives
        /// the same tree: the precedence pass implements the spec's table.
        #[test]
        fn print_parse_round_trip(e in arb_expr()) {
            let want = sexpr(&e);
            for full in [false, true] {
                let text = print(&e, full);
                let got = rhs_of(&model_with_rhs(&text))
                    .map_err(|d| proptest::test_runner::TestCaseError::fail(format!("{text}: {d:?}")))?;
                proptest::prop_assert_eq!(sexpr(&got), want.clone(), "{}", text);
            }
        }
    }
}
