//! Helpers shared by the front end's unit tests: diagnostics as (line, column, message),
//! and the one assertion that a model gives exactly the expected errors, in order.

use crate::diag::Diagnostic;
use crate::span::line_col;

/// An expected error: (line, column, message).
pub type Expected = (usize, usize, &'static str);

/// A located error as the tests compare it: (line, column, message).
pub type Located = (usize, usize, String);

/// (line, column, message) of each diagnostic, its start located in `src`.
pub fn located(src: &str, diags: Vec<Diagnostic>) -> Vec<Located> {
    diags
        .into_iter()
        .map(|d| {
            let (l, c) = line_col(src, d.span.start);
            (l, c, d.message)
        })
        .collect()
}

/// The checker's errors of a model that parses (panics, naming it, if it does not).
pub fn check_errors(src: &str) -> Vec<Diagnostic> {
    let model = crate::parse::parse(src).unwrap_or_else(|e| panic!("{src}: {e:?}"));
    crate::check::check(&model)
}

/// Every error of `src`, parse and check ([`crate::front`]), located.
pub fn front_errors(src: &str) -> Vec<Located> {
    located(src, crate::front(src).err().unwrap_or_default())
}

/// Asserts that `got` is exactly `want`, in order (the message names `src`).
#[track_caller]
pub fn assert_errors(src: &str, got: Vec<Located>, want: &[Expected]) {
    let want: Vec<Located> = want
        .iter()
        .map(|&(l, c, m)| (l, c, m.to_string()))
        .collect();
    assert_eq!(got, want, "{src}");
}

/// Asserts that the checker gives exactly `want` for a model that parses.
#[track_caller]
pub fn expect_check(src: &str, want: &[Expected]) {
    assert_errors(src, located(src, check_errors(src)), want);
}

/// [`expect_check`] for each (model, expected errors) case of a table.
#[track_caller]
pub fn expect_check_each(cases: &[(&str, &[Expected])]) {
    for (src, want) in cases {
        expect_check(src, want);
    }
}
