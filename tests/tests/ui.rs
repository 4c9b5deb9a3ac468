//! The `hybrid!` macro's compile errors: one case per mistake in `tests/ui/*.rs`, each
//! with its `.stderr` snapshot (regenerate with `TRYBUILD=overwrite`, then read each one
//! to check that the caret sits under the token at fault), and models that must compile
//! in `tests/ui/pass/`.

#[test]
fn ui() {
    let t = trybuild::TestCases::new();
    t.compile_fail("ui/*.rs");
    t.pass("ui/pass/*.rs");
}
