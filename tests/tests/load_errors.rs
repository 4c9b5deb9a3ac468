//! The loader's located errors, through the library (`mvad::load`): every semantic error
//! class, syntax errors, empty files, bytes that are not UTF-8, binary data and deep
//! nesting come back as `LoadError::Model` whose text starts with
//! `FILE:LINE:COL: error: MESSAGE`, quotes the line and puts a caret under the offending
//! text; several errors in one file are all reported. (The same inputs through the
//! binary, with exit statuses, are in `mvad/tests/cli.rs`.)

use mvad::load::{load_bytes, load_str, LoadError};

/// Loads `src` expecting an error; returns its rendered text.
fn error_text(name: &str, src: &[u8]) -> String {
    match load_bytes(name, src) {
        Ok(_) => panic!("{name}: loaded, expected an error"),
        Err(e @ LoadError::Model { .. }) => {
            assert!(!e.diagnostics().is_empty(), "{name}: no diagnostics");
            e.to_string()
        }
        Err(e) => panic!("{name}: not a model error: {e}"),
    }
}

/// Asserts the first error is at `line:col` with `fragment` in its message, that the
/// quoted line is shown and that the caret sits under `token`.
fn assert_at(name: &str, src: &str, line: usize, col: usize, fragment: &str, token: &str) {
    let text = error_text(name, src.as_bytes());
    let first = text.lines().next().unwrap_or_default();
    let prefix = format!("{name}:{line}:{col}: error: ");
    assert!(
        first.starts_with(&prefix),
        "{name}: expected {prefix}…, got:\n{text}"
    );
    assert!(
        first.contains(fragment),
        "{name}: `{fragment}` not in {first}"
    );
    let quoted = text
        .lines()
        .find(|l| l.trim_start().starts_with(&format!("{line} |")))
        .unwrap_or_else(|| panic!("{name}: line {line} not quoted:\n{text}"));
    let caret = text
        .lines()
        .find(|l| l.trim_start().starts_with('|') && l.contains('^'))
        .unwrap_or_else(|| panic!("{name}: no caret:\n{text}"));
    // The gutter has the same width on both lines, so the caret's byte offset in its line
    // is the offending token's offset in the quoted line.
    let at = caret.find('^').unwrap_or(0);
    assert!(
        quoted.get(at..).is_some_and(|rest| rest.starts_with(token)),
        "{name}: caret not under `{token}`:\n{text}"
    );
}

#[test]
fn every_semantic_error_class_is_located_at_its_token() {
    let cases: &[(&str, &str, usize, usize, &str, &str)] = &[
        ("undefined.hyb", "model M {\n    state x = 1;\n    flow { der(x) = -k * x; }\n}\n", 3, 22, "undefined name `k`", "k"),
        ("duplicate.hyb", "model M {\n    param a = 1;\n    param a = 2;\n    state x = 1;\n    flow { der(x) = -a * x; }\n}\n", 3, 11, "duplicate declaration of `a`", "a"),
        ("der-of-param.hyb", "model M {\n    param a = 1;\n    state x = 1;\n    flow { der(x) = -x; der(a) = 1; }\n}\n", 4, 29, "not a state", "a"),
        ("der-twice.hyb", "model M {\n    state x = 1;\n    flow { der(x) = -x; der(x) = 1; }\n}\n", 3, 29, "twice", "x"),
        ("reset-non-state.hyb", "model M {\n    param a = 1;\n    state x = 1;\n    flow { der(x) = -x; }\n    event hit when x <= 0 { a = 2; }\n}\n", 5, 29, "not a state", "a"),
        ("unknown-mode.hyb", "model M {\n    state x = 1;\n    mode up { der(x) = 1; event e when x >= 2 -> down; }\n}\n", 3, 50, "unknown mode `down`", "down"),
        ("unknown-event.hyb", "model M {\n    state x = 1;\n    flow { der(x) = -x; }\n    event hit when x <= 0.5 { x = 1; }\n    cost = sum(miss, x);\n    horizon 1;\n}\n", 5, 16, "unknown event `miss`", "miss"),
        ("unknown-function.hyb", "model M {\n    state x = 1;\n    flow { der(x) = foo(x); }\n}\n", 3, 21, "unknown function `foo`", "foo"),
        ("wrong-arity.hyb", "model M {\n    state x = 1;\n    flow { der(x) = sin(x, 2); }\n}\n", 3, 21, "takes 1 argument", "sin"),
        ("guard.hyb", "model M {\n    state x = 1;\n    flow { der(x) = -x; }\n    event hit when x + 1 { x = 1; }\n}\n", 4, 20, "not a comparison", "x + 1"),
        ("const-uses-param.hyb", "model M {\n    param a = 1;\n    const c = 2 * a;\n    state x = 1;\n    flow { der(x) = -c * x; }\n}\n", 3, 19, "param `a`", "a"),
        ("no-states.hyb", "model M {\n    param a = 1;\n    horizon 1;\n}\n", 1, 7, "no states", "M"),
        ("reserved.hyb", "model M {\n    param sin = 1;\n    state x = 1;\n    flow { der(x) = -x; }\n}\n", 2, 11, "reserved name `sin`", "sin"),
        ("syntax.hyb", "model M {\n    state x = 1\n    flow { der(x) = -x; }\n}\n", 3, 5, "expected `;`", "flow"),
        ("guard-jumps.hyb", "model M {\n    state x = 0;\n    flow { der(x) = 1; }\n    event e when sign(x-1)+sign(x-2)+sign(x-3)+sign(x-4)+sign(x-5)+sign(x-6)+sign(x-7) >= 0 { x = 0; }\n}\n", 4, 18, "more than 6 jumps", "sign(x-1)"),
    ];
    for &(name, src, line, col, fragment, token) in cases {
        assert_at(name, src, line, col, fragment, token);
    }
}

#[test]
fn every_error_in_a_file_is_reported() {
    let src = "model M {\n    state x = 1;\n    flow { der(x) = -k * x + foo(x); }\n    observe y = zz;\n}\n";
    let text = error_text("many.hyb", src.as_bytes());
    let firsts: Vec<&str> = text
        .lines()
        .filter(|l| l.starts_with("many.hyb:"))
        .collect();
    assert!(firsts.len() >= 3, "expected three errors:\n{text}");
    assert!(
        text.contains("`k`") && text.contains("`foo`") && text.contains("`zz`"),
        "{text}"
    );
}

#[test]
fn below_the_grammar_errors_are_located_too() {
    let text = error_text("empty.hyb", b"");
    assert!(
        text.starts_with("empty.hyb:1:1: error: empty model file"),
        "{text}"
    );
    let text = error_text("bad-utf8.hyb", b"model M {\n  state x = 1; // \xc3\x28\n}");
    assert!(
        text.starts_with("bad-utf8.hyb:2:19: error: the file is not valid UTF-8"),
        "{text}"
    );
    let text = error_text("binary.hyb", b"\x7fELF\x02\x01\x01\x00\x00\x00\x00\x00");
    assert!(
        text.starts_with("binary.hyb:1:1: error: unexpected character U+007F"),
        "{text}"
    );
    // A long binary line is quoted only up to a little past the error.
    let mut long = b"model M { state x = 1; ".to_vec();
    long.extend(std::iter::repeat_n(0u8, 10_000));
    let text = error_text("long.hyb", &long);
    assert!(text.len() < 500, "{} bytes", text.len());
}

#[test]
fn deep_nesting_is_an_error_not_a_stack_overflow() {
    for depth in [1_000usize, 100_000] {
        let src = format!(
            "model M {{\n  state x = {}1{};\n  flow {{ der(x) = 1; }}\n}}\n",
            "(".repeat(depth),
            ")".repeat(depth)
        );
        let text = error_text("deep.hyb", src.as_bytes());
        assert!(
            text.starts_with("deep.hyb:2:"),
            "{}",
            &text[..200.min(text.len())]
        );
        assert!(text.contains("nested too deeply"));
        let src = format!(
            "model M {{ state x = 1; flow {{ der(x) = {}x; }} }}",
            "-".repeat(depth)
        );
        error_text("deep-neg.hyb", src.as_bytes());
        let src = format!(
            "model M {{ state x = 1; flow {{ der(x) = x{}; }} }}",
            "^x".repeat(depth)
        );
        error_text("deep-pow.hyb", src.as_bytes());
    }
}

#[test]
fn valid_models_load() {
    for (name, src) in models::SOURCES {
        load_str(name, src).unwrap_or_else(|e| panic!("{e}"));
    }
}

/// A qp whose data jump along the flow (`if`/`sign` of a state or t) is refused where a flow,
/// ℓ, an observable or a guard reads it (the jump would be a jump of the flow or guard that no
/// switching function marks); read only by a reset or a cost it is evaluated there, like
/// their own choices, and a continuous kink (`max`) in its data is fine anywhere.
#[test]
fn a_qp_whose_data_jump_is_refused_where_the_jump_would_go_unmarked() {
    let model = |data: &str, reader: &str| {
        format!(
            "model M {{\n    param c = 0.5;\n    state x = 0;\n    state y = 0;\n    qp q(u) {{\n        minimize 0.5 * u^2 - ({data}) * u;\n    }}\n    flow {{ der(x) = 1; der(y) = {flow}; }}\n    event e when {guard} >= 2 {{ y = y + {reset}; }}\n    cost = final(y);\n    horizon 1;\n}}\n",
            flow = if reader == "flow" { "q.u" } else { "0" },
            guard = if reader == "guard" { "q.u + x" } else { "x" },
            reset = if reader == "reset" { "q.u" } else { "1" },
        )
    };
    let jump = "if x >= c then 2 else 1";
    for reader in ["flow", "guard"] {
        let text = error_text("qp-jump.hyb", model(jump, reader).as_bytes());
        assert!(
            text.starts_with("qp-jump.hyb:5:8: error: the data of qp `q` jump along the flow"),
            "{reader}: {text}"
        );
    }
    for (data, reader) in [
        (jump, "reset"),
        ("max(x, c)", "flow"),
        ("max(x, c)", "guard"),
    ] {
        if let Err(e) = load_str("qp-ok.hyb", &model(data, reader)) {
            panic!("{data} read by a {reader}: {e}");
        }
    }
}
