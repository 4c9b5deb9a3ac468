//! A guard that jumps across zero (an `if` or `sign` of a value that moves along the flow)
//! fires where it jumps, with the event-time sensitivity of the jump's condition: the
//! lowering rewrites it as a continuous guard with the same firing set (`lower/guard.rs`).
//! Before, the `if` guard of an exact segment was taken for a line (its derivative is 1 on
//! both sides) and fired at x = 1, not x = c: C 2.0 and dC/dc 0 where the truth is 1.5
//! and 1; a stepped run fired at the jump but took t' from the guard's side (dC/dc 0).
//!
//! Closed forms: the `if` guard fires at t₁ = c/a, the `sign` guard where
//! y = 2(1 − e^{−bt}) reaches d, t₂ = ln(2/(2 − d))/b; C = t₁ + t₂.

use mvad::runtime::solution::{GradientMode, Method, Options};

mvad::hybrid!(include "tests/guard_jump.hyb");

#[test]
fn a_guard_jumping_across_zero_fires_at_its_jump_with_the_jumps_sensitivity() {
    let loaded = mvad_tests::loaded_test_model("guard_jump.hyb");
    for [a, c, b, d] in [[1.0f64, 0.5, 1.0, 1.0], [2.0, 0.3, 0.7, 1.5]] {
        let t2 = (2.0 / (2.0 - d)).ln() / b;
        let cost = c / a + t2;
        // ∂/∂(a, c, b, d).
        let want = [-c / (a * a), 1.0 / a, -t2 / b, 1.0 / (b * (2.0 - d))];
        for method in [Method::Tsit5, Method::Verner9, Method::Rosenbrock] {
            for mode in [GradientMode::Forward, GradientMode::Adjoint] {
                let opts = Options {
                    method,
                    ..mvad_tests::precise(mode)
                };
                for (door, sol) in [
                    (
                        "compiled",
                        mvad_tests::solve_at(&GuardJump::new(), &[a, c, b, d], &opts),
                    ),
                    (
                        "loaded",
                        mvad_tests::solve_at(&loaded, &[a, c, b, d], &opts),
                    ),
                ] {
                    let what = format!("{door}, θ = {:?}, {method:?}, {mode:?}", [a, c, b, d]);
                    let sol = sol.unwrap_or_else(|e| panic!("{what}: {e}"));
                    assert_eq!(sol.events.len(), 2, "{what}: events");
                    mvad_tests::assert_near(sol.cost, cost, 1e-8, &what);
                    for (i, (&g, &w)) in sol.gradient.iter().zip(&want).enumerate() {
                        mvad_tests::assert_near(g, w, 1e-7, format!("{what}: dC/dθ{i}"));
                    }
                }
            }
        }
    }
}
