use super::*;
use crate::span::line_col;

/// The spec's first model, E1's bouncing ball, as the bundled model file.
pub(crate) const BALL: &str = include_str!("../../../models/bouncing_ball.hyb");

/// The spec's multi-mode example, as the bundled model file.
pub(crate) const THERMOSTAT: &str = include_str!("../../../models/thermostat.hyb");

/// Lisp-style rendering of an expression, for precedence tests.
fn sexpr(e: &Expr) -> String {
    match &e.kind {
        ExprKind::Number(v) => format!("{v}"),
        ExprKind::Name(id) => id.name.clone(),
        ExprKind::Time => "t".into(),
        ExprKind::Column { table, column } => format!("{}.{}", table.name, column.name),
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
    // (source, line, column, a part of the one error's message)
    let cases: &[(&str, usize, usize, &str)] = &[
        ("", 1, 1, "unexpected end of input; expected `model`"),
        ("model", 1, 6, "expected an identifier"),
        ("model M {", 1, 10, "unexpected end of input"),
        ("model M { param a = 1 }", 1, 23, "unexpected `}`; expected"),
        ("model M { param a = 1 }", 1, 23, "`;`"),
        (
            "model M {\n  state x = (1 + ;\n}",
            2,
            18,
            "expected an expression",
        ),
        (
            "model M {\n  flow { der(x) = g + * v; }\n}",
            2,
            23,
            "unexpected `*`",
        ),
        (
            "model M { foo x = 1; }",
            1,
            11,
            "unexpected `foo`; expected `param`",
        ),
        (
            "model M { event when x == 0 { } }",
            1,
            24,
            "unexpected `==`",
        ),
        ("model M { param a = 1.0f64; }", 1, 21, ""),
        (
            "model M { param a = 1; } trailing",
            1,
            26,
            "expected end of input",
        ),
        // A bare expression is a static cost term (the `qp` extension of the spec), so
        // `cost = h;` parses and is refused by the checker at the same place (see
        // `check::tests::static_cost_terms_read_only_params_and_static_qps`); an empty cost and
        // a bare sum still are syntax errors.
        ("model M { cost = ; }", 1, 18, "expected"),
        ("model M { cost = h + ; }", 1, 22, "expected"),
        (
            "model M { param a = 1e999; }",
            1,
            21,
            "number `1e999` is out of range",
        ),
        ("model M { /* unterminated", 1, 11, ""),
        ("\u{0}\u{1}\u{ff}garbage", 1, 1, "character U+0000"),
    ];
    for &(src, line, col, msg) in cases {
        expect_error(src, line, col, msg);
    }
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
            (bin, inner.clone(), inner.clone()).prop_map(move |(op, l, r)| e(ExprKind::Binary {
                op,
                op_span: Span::default(),
                lhs: Box::new(l),
                rhs: Box::new(r),
            })),
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
        ExprKind::Column { table, column } => format!("{}.{}", table.name, column.name),
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
