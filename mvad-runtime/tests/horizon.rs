//! No decision of the event loop may depend on how far the horizon T lies beyond the
//! dynamics. A ball that comes to rest (Zeno accumulation at t*, or stuck at once for e = 0)
//! must give the same events, cost and gradient whether T lies just past t* or 10⁶ times
//! the event spacing beyond it. Before the fix the "stuck after reset" probe and the
//! simultaneity window were scaled by T: at T = 10⁶ any flight shorter than 1 s counted as
//! stuck, and the run ended after the second bounce with a wrong gradient and a `zeno`
//! diagnostic at the wrong time.

use mvad_runtime::fixtures::Ball;
use mvad_runtime::solution::Options;
use mvad_runtime::solve::solve;

/// t* = t₁ + (2 v₁ / g) e / (1 − e): the accumulation time of the ball dropped from h0 at rest.
fn t_star(e: f64, g: f64, h0: f64) -> f64 {
    let t1 = (2.0 * h0 / g).sqrt();
    let v1 = (2.0 * g * h0).sqrt();
    t1 + 2.0 * v1 / g * e / (1.0 - e)
}

#[test]
fn horizon_far_beyond_the_accumulation_point_changes_nothing() {
    let ball = Ball::new();
    for e in [0.0, 0.3, 0.8] {
        let mut p = ball.default_params();
        p[Ball::E] = e;
        let ts = t_star(e, p[Ball::G], p[Ball::H0]);
        let run = |t_end: f64| {
            let opts = Options {
                rtol: 1e-10,
                atol: 1e-12,
                t_end: Some(t_end),
                ..Options::default()
            };
            solve(&ball, &p, &opts).unwrap()
        };
        let near = run(ts + 0.25);
        for t_end in [1e3, 1e6] {
            let far = run(t_end);
            assert_eq!(
                near.events.len(),
                far.events.len(),
                "e = {e}, T = {t_end}: event count"
            );
            for (a, b) in near.events.iter().zip(&far.events) {
                assert!(
                    (a.t - b.t).abs() <= 1e-12 * a.t.max(1.0),
                    "e = {e}: {a:?} vs {b:?}"
                );
            }
            let rel = |a: f64, b: f64| (a - b).abs() / a.abs().max(1e-300);
            // Past t* the state is held at rest, so C grows by ∫h = h_rest·(T_far − T_near), where
            // h_rest is the held height (zero up to the rounding of the located root, ≲ 1e-13);
            // everything else must be identical.
            let held = far.x_final[0] * (t_end - near.t_end);
            assert!(
                rel(near.cost + held, far.cost) <= 1e-12,
                "e = {e}, T = {t_end}: C {} + {held:e} vs {}",
                near.cost,
                far.cost
            );
            assert!(
                far.x_final[0].abs() <= 1e-12,
                "e = {e}: rest height {}",
                far.x_final[0]
            );
            for (j, (a, b)) in near.gradient.iter().zip(&far.gradient).enumerate() {
                assert!(
                    (a - b).abs() <= 1e-9 * a.abs().max(1.0),
                    "e = {e}, T = {t_end}: dC/dθ[{j}] {a} vs {b}"
                );
            }
            let kinds = |s: &mvad_runtime::solution::Solution| {
                s.diagnostics
                    .iter()
                    .map(|d| (d.kind, d.t.to_bits()))
                    .collect::<Vec<_>>()
            };
            assert_eq!(
                kinds(&near).len(),
                kinds(&far).len(),
                "e = {e}, T = {t_end}: diagnostics"
            );
        }
    }
}
