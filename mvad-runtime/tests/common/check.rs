//! Assertion helpers shared by the test files: options, closeness, gradients, and a
//! [`Report`] that collects every failure of a case instead of stopping at the first.

use mvad_runtime::solution::{DiagnosticKind, Options, Solution};

/// rtol 1e-10, atol 1e-12: the tolerances the closed-form tests run at.
pub fn tight() -> Options {
    Options {
        rtol: 1e-10,
        atol: 1e-12,
        ..Options::default()
    }
}

/// [`tight`], recording the trajectory.
pub fn recorded() -> Options {
    Options {
        record: true,
        ..tight()
    }
}

/// rtol 1e-12, atol 1e-14: the runs finite differences are taken of.
pub fn fd_opts() -> Options {
    Options {
        rtol: 1e-12,
        atol: 1e-14,
        ..Options::default()
    }
}

/// Relative agreement with an absolute floor for entries that are (near) zero.
pub fn close(a: f64, b: f64, rel: f64, abs: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()) + abs
}

/// Whether `sol` has a diagnostic of kind `kind`.
pub fn has(sol: &Solution, kind: DiagnosticKind) -> bool {
    sol.diagnostic(kind).is_some()
}

/// The failures found so far, one line each.
#[derive(Debug, Default)]
pub struct Report(pub Vec<String>);

impl Report {
    /// Records `what` unless `ok`.
    pub fn check(&mut self, ok: bool, what: impl FnOnce() -> String) {
        if !ok {
            self.0.push(what());
        }
    }
    /// `got` equals `want`.
    pub fn eq<T: PartialEq + std::fmt::Debug>(&mut self, what: &str, got: T, want: T) {
        self.check(got == want, || {
            format!("{what}: got {got:?}, want {want:?}")
        });
    }
    /// [`close`]`(got, want, rel, abs)`.
    pub fn close(&mut self, what: &str, got: f64, want: f64, rel: f64, abs: f64) {
        self.check(close(got, want, rel, abs), || {
            format!(
                "{what}: got {got:.17e}, want {want:.17e}, rel err {:.2e} (rel {rel:e}, abs {abs:e})",
                (got - want).abs() / want.abs()
            )
        });
    }
    /// Every entry of `got` [`close`] to `want`'s.
    pub fn all_close(&mut self, what: &str, got: &[f64], want: &[f64], rel: f64, abs: f64) {
        self.eq(&format!("{what}: length"), got.len(), want.len());
        for (i, (g, w)) in got.iter().zip(want).enumerate() {
            self.close(&format!("{what}: d/dθ{i}"), *g, *w, rel, abs);
        }
    }
    /// Panics with every failure recorded, if any.
    pub fn assert_ok(self) {
        assert!(
            self.0.is_empty(),
            "{} failures:\n{}",
            self.0.len(),
            self.0.join("\n")
        );
    }
}

/// Asserts every entry of `got` [`close`] to `want`'s (named `what` in the message).
pub fn assert_grad(what: &str, got: &[f64], want: &[f64], rel: f64, abs: f64) {
    let mut r = Report::default();
    r.all_close(what, got, want, rel, abs);
    r.assert_ok();
}

/// Asserts [`close`]`(got, want, rel, abs)`.
pub fn assert_close(what: &str, got: f64, want: f64, rel: f64, abs: f64) {
    let mut r = Report::default();
    r.close(what, got, want, rel, abs);
    r.assert_ok();
}

/// Asserts C of `sol` [`close`] to `cost` (relative `cost_rel`) and the first `grad.len()`
/// entries of dC/dθ to `grad` (`grad_rel`, `grad_abs`), named `what` in the messages.
pub fn assert_cost_grad(
    what: &str,
    sol: &Solution,
    cost: f64,
    grad: &[f64],
    cost_rel: f64,
    grad_rel: f64,
    grad_abs: f64,
) {
    assert_close(&format!("{what}: cost"), sol.cost, cost, cost_rel, 0.0);
    assert_grad(what, &sol.gradient[..grad.len()], grad, grad_rel, grad_abs);
}
