use crate::ast::MAX_DEPTH;
use crate::testing::{check_errors, expect_check, Expected};

#[test]
fn spec_models_are_clean() {
    assert!(check_errors(crate::parse::tests::BALL).is_empty());
    assert!(check_errors(crate::parse::tests::THERMOSTAT).is_empty());
}

#[test]
fn one_error_per_rule() {
    let cases: &[(&str, &[Expected])] = &[
        (
            "model M { state h = 0;\n flow { der(h) = vv; } }",
            &[(2, 18, "undefined name `vv`")],
        ),
        (
            "model M { param a = 1;\n param a = 2; state h = 0; flow { der(h) = a; } }",
            &[(2, 8, "duplicate declaration of `a`")],
        ),
        (
            "model M { param a = 1; state h = 0;\n observe a = h; flow { der(h) = a; } }",
            &[(2, 10, "duplicate declaration of `a`")],
        ),
        (
            "model M { state h = 0; state v = 0;\n flow { der(h) = v; } }",
            &[(2, 2, "state `v` has no `der` in `flow`")],
        ),
        (
            "model M { state h = 0; state v = 0;\n mode a { der(h) = v; der(v) = 1; }\n mode b { der(v) = 1; } }",
            &[(3, 7, "state `h` has no `der` in mode `b`")],
        ),
        (
            "model M { param g = 1; state h = 0; flow { der(h) = 1;\n der(g) = 2; } }",
            &[(2, 6, "`der` of param `g`, which is not a state")],
        ),
        (
            "model M { state h = 0; flow { der(h) = 1;\n der(q) = 2; } }",
            &[(2, 6, "`der` of `q`, which is not a declared state")],
        ),
        (
            "model M { state h = 0; flow { der(h) = 1;\n der(h) = 2; } }",
            &[(2, 6, "`der(h)` is given twice in `flow`")],
        ),
        (
            "model M { param e = 1; state h = 0; flow { der(h) = 1; }\n event hit when h <= 0 { e = 2; } }",
            &[(2, 26, "reset of param `e`, which is not a state")],
        ),
        (
            "model M { state h = 0; flow { der(h) = 1; }\n event hit when h <= 0 { h = 2; h = 3; } }",
            &[(2, 33, "state `h` is reset twice in event `hit`")],
        ),
        (
            "model M { state h = 0;\n initial mode up; mode a { der(h) = 1; } }",
            &[(2, 15, "unknown mode `up`")],
        ),
        (
            "model M { state h = 0; mode a { der(h) = 1;\n event s when h >= 1 -> b; } }",
            &[(2, 25, "unknown mode `b`")],
        ),
        (
            "model M { state h = 0; flow { der(h) = 1; }\n event s when h >= 1 -> main; }",
            &[(2, 25, "unknown mode `main`")],
        ),
        (
            "model M { state h = 0; flow { der(h) = 1; } event hit when h <= 0;\n cost = sum(hot, h); }",
            &[(2, 13, "unknown event `hot` in `sum`")],
        ),
        (
            "model M { state h = 0; flow { der(h) = 1; } event when h <= 0;\n cost = sum(event_0, h); }",
            &[(2, 13, "unknown event `event_0` in `sum`")],
        ),
        (
            "model M { state h = 0;\n flow { der(h) = sine(h); } }",
            &[(2, 18, "unknown function `sine`")],
        ),
        (
            "model M { state h = 0;\n flow { der(h) = h(2); } }",
            &[(2, 18, "state `h` is not a function")],
        ),
        (
            "model M { state h = 0;\n flow { der(h) = max(h) + pow(h, 2, 3) + sin(); } }",
            &[
                (2, 18, "function `max` takes 2 arguments, but 1 was given"),
                (2, 27, "function `pow` takes 2 arguments, but 3 were given"),
                (2, 42, "function `sin` takes 1 argument, but 0 were given"),
            ],
        ),
        (
            "model M { state h = 0; flow { der(h) = 1; }\n event hit when h { h = 1; } }",
            &[(2, 17, "guard of event `hit` is not a comparison")],
        ),
        (
            "model M { state h = 0;\n flow { der(h) = if h + 1 then 1 else 2; } }",
            &[(2, 21, "condition of `if` is not a comparison")],
        ),
        (
            "model M { param p = 1;\n const c = 2 * p; state h = 0; flow { der(h) = c; } }",
            &[(2, 16, "const `c` cannot depend on param `p`")],
        ),
        (
            "model M { state h = 0;\n const c = h; flow { der(h) = c; } }",
            &[(2, 12, "const `c` cannot depend on state `h`")],
        ),
        (
            "model M {\n const a = b; const b = 1; state h = 0; flow { der(h) = a; } }",
            &[(2, 12, "const `a` uses const `b` before its declaration")],
        ),
        (
            "model M { param p = 1; }",
            &[
                (1, 7, "model `M` has no states"),
                (1, 7, "model `M` has no `flow` block and no `mode`"),
            ],
        ),
        (
            "model M {\n param sin = 1; state t = 0; flow { der(t) = 1; } }",
            &[
                (2, 8, "reserved name `sin` used as an identifier"),
                (2, 23, "reserved name `t` used as an identifier"),
            ],
        ),
        (
            "model M { state h = 0; flow { der(h) = 1; }\n mode a { der(h) = 2; } }",
            &[(2, 7, "a model cannot have both a `flow` block and `mode` blocks")],
        ),
        (
            "model M { state h = 0; }",
            &[(1, 7, "model `M` has no `flow` block and no `mode`")],
        ),
        (
            "model M { state h = 0; param q = 1;\n param p = q; flow { der(h) = 1; } }",
            &[(2, 12, "the default value of param `p` cannot depend on param `q`")],
        ),
        (
            "model M { state h = 0; flow { der(h) = 1; }\n horizon h; }",
            &[(2, 10, "the horizon cannot depend on state `h`")],
        ),
        (
            "model M { state h = 0; state v = h;\n flow { der(h) = 1; der(v) = 1; } }",
            &[(1, 34, "the initial value of state `v` cannot depend on state `h`")],
        ),
        (
            "model M { state h = t;\n flow { der(h) = 1; } }",
            &[(1, 21, "the initial value of state `h` cannot depend on the time `t`")],
        ),
        (
            "model M { state h = 0; flow { der(h) = 1; }\n observe a = b; observe b = a + 1; }",
            &[
                (2, 10, "observable `a` depends on itself"),
                (2, 25, "observable `b` depends on itself"),
            ],
        ),
        (
            "model M { state h = 0; flow { der(h) = 1; }\n cost = integral(h); cost = final(h); horizon 1; horizon 2; }",
            &[
                (2, 22, "duplicate `cost` declaration"),
                (2, 50, "duplicate `horizon` declaration"),
            ],
        ),
        (
            "model M { state h = 0;\n mode a { der(h) = 1; event s when h > 1 -> a; }\n mode a { der(h) = 1; event s when h < 0 -> a; } }",
            &[
                (3, 7, "duplicate mode `a`"),
                (3, 29, "duplicate event `s`"),
            ],
        ),
    ];
    let mut bad = Vec::new();
    for (src, want) in cases {
        if std::panic::catch_unwind(|| expect_check(src, want)).is_err() {
            bad.push(*src);
        }
    }
    assert!(bad.is_empty(), "{} cases failed", bad.len());
}

#[test]
fn reports_every_error_sorted_by_position() {
    let src = "model M { state h = 0; state v = 0;\n flow { der(h) = vv; der(q) = 1; }\n event when h <= 0 -> nowhere; }";
    let got: Vec<String> = check_errors(src).into_iter().map(|d| d.message).collect();
    assert_eq!(
        got,
        vec![
            "state `v` has no `der` in `flow`",
            "undefined name `vv`",
            "`der` of `q`, which is not a declared state",
            "unknown mode `nowhere`",
        ]
    );
}

#[test]
fn names_in_scope_are_accepted() {
    // Observables used by name (in any order), consts in params, params in inits and
    // the horizon, `t` in flows: all allowed.
    let src = "model M { const c0 = 2; const c1 = c0 * 3; param p = c1 - 1; state h = p * c0;
               flow { der(h) = y2 + t * p; } observe y2 = 2 * y1; observe y1 = h + c1;
               event e when y1 >= p { h = y2; } cost = integral(y2) + sum(e, h) + final(t); horizon p + c0; }";
    assert_eq!(check_errors(src), vec![]);
}

#[test]
fn hints() {
    let d = &check_errors("model M { state speed = 0; flow { der(speed) = sped; } }")[0];
    assert_eq!(d.help.as_deref(), Some("did you mean `speed`?"));
    let d = &check_errors("model M { state h = 0; flow { der(h) = sin; } }")[0];
    assert_eq!(
        d.help.as_deref(),
        Some("`sin` is a function: call it as `sin(...)`")
    );
    let d =
        &check_errors("model M { param a = 1; param a = 2; state h = 0; flow { der(h) = a; } }")[0];
    assert_eq!(d.labels.len(), 1);
    assert_eq!(d.labels[0].1, "first declared here");
}

#[test]
fn observable_substitution_depth_is_bounded() {
    // A chain of observables, each adding a level: fine when short, an error when the
    // substituted depth passes MAX_DEPTH (never a stack overflow in `lower`).
    let chain = |n: usize| {
        let mut s = String::from("model M { state h = 0; flow { der(h) = o0; } observe o0 = h");
        for i in 1..n {
            s.push_str(&format!("; observe o{i} = o{} + 1", i - 1));
        }
        s.push_str(&format!("; observe z = o{}; }}", n - 1));
        s
    };
    assert!(check_errors(&chain(10)).is_empty());
    let errs = check_errors(&chain(MAX_DEPTH + 10));
    assert!(!errs.is_empty());
    assert!(
        errs.iter().all(|d| d.message.contains("nested too deeply")),
        "{errs:?}"
    );
}
