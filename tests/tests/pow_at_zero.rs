//! ∂(a^b)/∂b = a^b ln a where a^b = 0 (a = 0, b > 0) is 0, the limit, not 0·(−∞): y' = t^p
//! and z' = x^p with x = t = 0 at the start. Before, the run failed with "non-finite value in
//! sensitivity equation at t = 0" though C = 2/(p + 1) and dC/dp = −2/(p + 1)² exist.
//! Both doors, both modes, against the closed form.

use mvad::runtime::solution::{GradientMode, Options};

mvad::hybrid!(include "tests/pow_at_zero.hyb");

#[test]
fn a_parameter_exponent_on_a_base_starting_at_zero_has_its_derivative() {
    let loaded = mvad_tests::loaded_test_model("pow_at_zero.hyb");
    // p ≥ 1 keeps ∂(x^p)/∂x = p x^(p−1) finite at x = 0 (below 1 it is infinite there, and the
    // sensitivity equation reads ∞·0).
    for p in [1.0, 2.0, 3.7] {
        for mode in [GradientMode::Forward, GradientMode::Adjoint] {
            let opts = Options {
                gradient_mode: mode,
                ..Options::default()
            };
            for (door, sol) in [
                (
                    "compiled",
                    mvad_tests::solve_at(&PowAtZero::new(), &[p], &opts),
                ),
                ("loaded", mvad_tests::solve_at(&loaded, &[p], &opts)),
            ] {
                let what = format!("{door}, p = {p}, {mode:?}");
                let sol = sol.unwrap_or_else(|e| panic!("{what}: {e}"));
                mvad_tests::assert_near(sol.cost, 2.0 / (p + 1.0), 1e-9, &what);
                let want = -2.0 / ((p + 1.0) * (p + 1.0));
                mvad_tests::assert_near(sol.gradient[0], want, 1e-8, &what);
            }
        }
    }
}
