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

/// The cases of section `section` of an expectation file, as (model, expected errors).
///
/// A section opens with a line `=== NAME` and runs to the next one; each case is the
/// model's lines, then one line `! LINE:COLUMN MESSAGE` per expected error, in order, then
/// a line `---`. Lines that start with `#`, blank lines before a case and everything before
/// the first section are comments.
pub fn cases(text: &str, section: &str) -> Vec<(String, Vec<Located>)> {
    let mut lines = text
        .lines()
        .skip_while(|l| l.strip_prefix("=== ") != Some(section));
    assert!(lines.next().is_some(), "no section `{section}`");
    let (mut out, mut src, mut want) = (Vec::new(), Vec::<&str>::new(), Vec::new());
    for line in lines.take_while(|l| !l.starts_with("=== ")) {
        if line == "---" {
            out.push((src.join("\n"), std::mem::take(&mut want)));
            src.clear();
        } else if let Some(e) = line.strip_prefix("! ") {
            let parsed = e.split_once(' ').and_then(|(at, msg)| {
                let (l, c) = at.split_once(':')?;
                Some((l.parse().ok()?, c.parse().ok()?, msg.to_string()))
            });
            want.push(parsed.unwrap_or_else(|| panic!("`{line}`: not `! LINE:COLUMN MESSAGE`")));
        } else {
            let comment = line.starts_with('#') || (line.is_empty() && src.is_empty());
            if !comment {
                src.push(line);
            }
        }
    }
    assert!(
        src.is_empty() && want.is_empty(),
        "section `{section}` ends without `---`"
    );
    out
}

/// Asserts that the checker gives exactly `want` for a model that parses.
#[track_caller]
pub fn expect_check(src: &str, want: &[Expected]) {
    assert_errors(src, located(src, check_errors(src)), want);
}

/// [`expect_check`] with the expected errors as [`cases`] gives them.
#[track_caller]
pub fn expect_check_located(src: &str, want: &[Located]) {
    assert_eq!(located(src, check_errors(src)), want, "{src}");
}

/// [`expect_check_located`] for each case of section `section` of an expectation file.
#[track_caller]
pub fn expect_check_section(text: &str, section: &str) {
    for (src, want) in cases(text, section) {
        expect_check_located(&src, &want);
    }
}
