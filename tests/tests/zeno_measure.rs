//! The measure of a Zeno run: the events the run did not simulate (infinitely many before
//! the accumulation time t*) are lumped into one effective atom at t*, so the pairing
//! ⟨μ_v, 1⟩ = d/dθ ∫₀ᵀ v dt = d/dθ (h(T) − h0) still holds. The ball rests at h = 0 after
//! t* < T, so the exact value is (0, 0, −1, 0) for (e, g, h0, v0).

use std::path::Path;

use mvad::load::load;
use mvad::{measure, solve, DiagnosticKind, HybridModel, Options};
use mvad_tests::assert_near;

#[test]
fn zeno_velocity_measure_pairs_to_the_height_change() {
    let path = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../models/zeno_ball.hyb"
    ));
    let model = load(path).expect("zeno_ball.hyb loads");
    let p = model.default_params();
    let opts = Options {
        record: true,
        rtol: 1e-10,
        atol: 1e-12,
        ..Options::default()
    };
    let sol = solve(&model, &p, &opts).expect("the run succeeds");
    assert!(sol.diagnostic(DiagnosticKind::Zeno).is_some());
    let info = model.info();
    let height = measure(&model, &p, &sol, info.observable_index("height").unwrap()).unwrap();
    let velocity = measure(&model, &p, &sol, info.observable_index("velocity").unwrap()).unwrap();

    // ⟨μ_h, 1⟩ is the cost gradient (C = ∫h dt), tail included.
    let h_total = height.pair(|_| 1.0);
    for (j, (&a, &b)) in h_total.iter().zip(&sol.gradient).enumerate() {
        assert_near(a, b, 1e-7, format_args!("height θ{j}"));
    }

    // ⟨μ_v, 1⟩ = d/dθ (h(T) − h0). The tail of S extrapolated from the last five bounces
    // (Aitken twice) leaves about 3e-4 for the restitution e (terms k·eᵏ converge slowly);
    // the others are exact to 1e-7.
    let v_total = velocity.pair(|_| 1.0);
    let want = [0.0, 0.0, -1.0, 0.0];
    let tol = [1e-3, 1e-7, 1e-7, 1e-7];
    for j in 0..4 {
        assert!(
            (v_total[j] - want[j]).abs() <= tol[j],
            "velocity θ{j}: {} vs {}",
            v_total[j],
            want[j]
        );
    }
    // Without the effective atom at t*, d/de would be off by about 2e-2: the atom matters.
    let t_star = sol.diagnostic(DiagnosticKind::Zeno).unwrap().t;
    let tail = velocity
        .atoms
        .iter()
        .find(|(t, _)| *t == t_star)
        .expect("an effective atom at t*");
    assert!(tail.1[0].abs() > 1e-3, "{:?}", tail.1);
}
