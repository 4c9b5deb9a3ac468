//! A switching function that stays on zero up to rounding (`switch_noise.hyb`: σ = x − z/3
//! with z = 3x) changes sign every few steps by rounding alone. Its "crossings" have a rate
//! that is zero within rounding, so no crossing time and no t' exist there. Before, forward
//! mode stopped only where the rate was exactly 0 (an error naming a tangential crossing),
//! and a run without sensitivities (adjoint mode's primal pass) flipped the bit at every
//! sign change until `max_events`: minutes. Now every method stops at the first such
//! crossing in both modes, with an error that says what happened. (With z = x, σ cancels
//! exactly, never changes sign, and the run goes on with a `kink` diagnostic.)

use mvad::runtime::solution::{GradientMode, Method, Options};

mvad::hybrid!(include "tests/switch_noise.hyb");

#[test]
fn a_switching_function_on_zero_up_to_rounding_stops_the_run_at_once_with_a_clear_error() {
    let loaded = mvad_tests::loaded_test_model("switch_noise.hyb");
    for method in [Method::Auto, Method::Tsit5, Method::Verner9] {
        for mode in [GradientMode::Forward, GradientMode::Adjoint] {
            let opts = Options {
                method,
                gradient_mode: mode,
                ..Options::default()
            };
            for (door, res) in [
                (
                    "compiled",
                    mvad_tests::solve_at(&SwitchNoise::new(), &[1.0, 0.0], &opts),
                ),
                ("loaded", mvad_tests::solve_at(&loaded, &[1.0, 0.0], &opts)),
            ] {
                let what = format!("{door}, {method:?}, {mode:?}");
                let err = match res {
                    Ok(sol) => panic!("{what}: ran, C = {}", sol.cost),
                    Err(e) => e.to_string(),
                };
                assert!(err.contains("is zero within rounding"), "{what}: {err}");
                assert!(err.contains("switching function 0"), "{what}: {err}");
            }
        }
    }
}
