use crate::ast::MAX_DEPTH;
use crate::testing::{cases, check_errors, expect_check_located};

/// The cases of `one_error_per_rule` (the format: [`cases`]).
const ERRORS: &str = include_str!("errors.txt");

#[test]
fn spec_models_are_clean() {
    assert!(check_errors(crate::parse::tests::BALL).is_empty());
    assert!(check_errors(crate::parse::tests::THERMOSTAT).is_empty());
}

#[test]
fn one_error_per_rule() {
    let mut bad = Vec::new();
    for (src, want) in cases(ERRORS, "one_error_per_rule") {
        if std::panic::catch_unwind(|| expect_check_located(&src, &want)).is_err() {
            bad.push(src);
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
