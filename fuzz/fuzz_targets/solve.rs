//! Fuzz target: arbitrary text into the `.hyb` loader and, when it loads, into the solver at
//! the declared parameter values, with bounded work (few steps and events, a short horizon,
//! a loose tolerance), in forward and in adjoint mode. Every run must come back as a
//! solution or a `SolveError`; a panic, a hang or a stack overflow is a bug.
#![no_main]

use libfuzzer_sys::fuzz_target;
use mvad::{solve, GradientMode, Method, Options};

/// The horizon is capped here, so that a model declaring T = 1e300 stays cheap.
const T_CAP: f64 = 10.0;

fuzz_target!(|data: &[u8]| {
    let Ok(src) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(model) = mvad::load::load_str("fuzz.hyb", src) else {
        return;
    };
    let params = model.default_params();
    // The model's own horizon (with dT/dθ) when it is short; a longer or infinite one is
    // capped. A missing, NaN or non-positive horizon takes the solver's own error path.
    let t_end = match mvad::HybridModel::horizon(&model, &params) {
        Some(t) if t > T_CAP => Some(T_CAP),
        _ => None,
    };
    let opts = Options {
        // The input picks the method, so every scheme sees every shape of model.
        method: Method::ALL[data.len() % Method::ALL.len()],
        rtol: 1e-4,
        atol: 1e-6,
        t_end,
        max_events: 200,
        max_steps: 2_000,
        // Time events count against neither budget above; their own bound.
        max_periodic_occurrences: 2_000,
        record: data.len() % 3 == 0,
        // Every other input also runs the backward sweep (adjoint mode), so the transposed
        // event maps and the replay of the record see every shape of model too.
        gradient_mode: if data.len() % 2 == 0 {
            GradientMode::Adjoint
        } else {
            GradientMode::Forward
        },
        ..Options::default()
    };
    if let Ok(sol) = solve(&model, &params, &opts) {
        // Rendering the result is part of the run: it must not panic either.
        let _ = format!("{:?}", sol.cost);
    }
});
