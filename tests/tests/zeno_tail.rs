//! What follows a Zeno accumulation, against closed forms through both doors: the state is
//! held at its limit (on the accumulating guard) and the answer does not depend on how far
//! T lies beyond t*; a time event after t* fires from the held state and the run goes on
//! (a kick), or the hold goes on (a sampler that reads the resting ball); an event sum
//! whose terms do not vanish at the limit diverges and is an error, not a number.
//!
//! The reference is the exact ball: flight by flight from the closed-form parabola, the
//! flights that remain once they all fit before T summed as a geometric series
//! (∫ over a flight launched from the floor at speed w is (2/3) w³/g²). Its gradient is
//! the central difference of that closed form, Richardson-extrapolated over two steps.

use mvad::interp::InterpretedModel;
use mvad::runtime::error::SolveError;
use mvad::runtime::solution::{GradientMode, Options, Solution};
use mvad::{DiagnosticKind, HybridModel, ModelAlloc};
use mvad_tests::{assert_near, precise, solve_at};
use nalgebra::DefaultAllocator;

mvad::hybrid!(include "tests/zeno_kick.hyb");
mvad::hybrid!(include "tests/zeno_sampled.hyb");

/// ∫_{t0}^{t1} h dt of a ball at (h, v) at t0 (restitution e, gravity g), and (h, v) at t1.
fn ball(mut h: f64, mut v: f64, t0: f64, t1: f64, g: f64, e: f64) -> (f64, f64, f64) {
    let (mut c, mut t) = (0.0, t0);
    loop {
        if h == 0.0 && v > 0.0 && t + 2.0 * v / (g * (1.0 - e)) <= t1 {
            // Every remaining flight (launch speeds v eᵏ) ends before t1: the ball rests.
            return (
                c + 2.0 * v.powi(3) / (3.0 * g * g * (1.0 - e.powi(3))),
                0.0,
                0.0,
            );
        }
        let s = (v + (v * v + 2.0 * g * h).sqrt()) / g;
        let d = (t + s).min(t1) - t;
        c += h * d + v * d * d / 2.0 - g * d.powi(3) / 6.0;
        if t + s >= t1 {
            return (c, h + v * d - g * d * d / 2.0, v - g * d);
        }
        t += s;
        v = e * (g * s - v);
        h = 0.0;
    }
}

/// The accumulation time of a ball dropped from h0 at rest.
fn t_star(e: f64, g: f64, h0: f64) -> f64 {
    (2.0 * h0 / g).sqrt() * (1.0 + 2.0 * e / (1.0 - e))
}

/// The central difference of `f` in each parameter, Richardson-extrapolated from the steps
/// δ and δ/2 (δ = rel·max(|θ|, 1)): error O(δ⁴) on a smooth closed form.
fn fd(f: impl Fn(&[f64]) -> f64, p: &[f64], rel: f64) -> Vec<f64> {
    (0..p.len())
        .map(|i| {
            let cd = |d: f64| {
                let mut a = p.to_vec();
                let mut b = p.to_vec();
                a[i] += d;
                b[i] -= d;
                (f(&a) - f(&b)) / (2.0 * d)
            };
            let d = rel * p[i].abs().max(1.0);
            (4.0 * cd(d / 2.0) - cd(d)) / 3.0
        })
        .collect()
}

fn run<M: HybridModel>(m: &M, p: &[f64], opts: &Options) -> Result<Solution, SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    solve_at(m, p, opts)
}

fn loaded(file: &str) -> InterpretedModel {
    let src = std::fs::read_to_string(format!("{}/tests/{file}", env!("CARGO_MANIFEST_DIR")))
        .expect(file);
    InterpretedModel::from_source(&src).unwrap_or_else(|e| panic!("{file}: {e:?}"))
}

/// C = ∫₀ᵀ h dt + h(T) + v(T) of the ball kicked by u at τ after coming to rest.
fn kick_cost(p: &[f64]) -> f64 {
    let [e, g, h0, u, tau] = [p[0], p[1], p[2], p[3], p[4]];
    let (c0, h, v) = ball(h0, 0.0, 0.0, tau, g, e);
    assert_eq!((h, v), (0.0, 0.0), "at rest before the kick");
    let (c1, h, v) = ball(0.0, u, tau, 10.0, g, e);
    c0 + c1 + h + v
}

fn assert_solution(sol: &Solution, c: f64, grad: &[f64], rel: f64, what: &str) {
    assert_near(sol.cost, c, rel, format_args!("{what}: C"));
    for (j, (&a, &b)) in sol.gradient.iter().zip(grad).enumerate() {
        assert_near(a, b, rel, format_args!("{what}: dC/dθ{j}"));
    }
}

#[test]
fn a_time_event_after_the_accumulation_fires_and_the_run_goes_on() {
    let interp = loaded("zeno_kick.hyb");
    // The second set comes to rest again before T (a second accumulation, where the
    // kick's time no longer matters: dC/dτ = 0).
    for (p, accumulations) in [
        ([0.8, 9.81, 2.0, 3.0, 8.0], 1),
        ([0.7, 9.81, 1.5, 2.0, 7.0], 2),
    ] {
        assert!(t_star(p[0], p[1], p[2]) < p[4]);
        let (c, grad) = (kick_cost(&p), fd(kick_cost, &p, 1e-3));
        // The kick matters: without it C would not move with u.
        assert!(grad[3].abs() > 0.1, "{grad:?}");
        for mode in [GradientMode::Forward, GradientMode::Adjoint] {
            let o = precise(mode);
            for (door, sol) in [
                ("macro", run(&ZenoKick::new(), &p, &o)),
                ("loaded", run(&interp, &p, &o)),
            ] {
                let sol = sol.expect("runs");
                assert_solution(&sol, c, &grad, 1e-8, &format!("{door} {mode:?} {p:?}"));
                // The accumulation is run in forward mode, which the diagnostic says.
                assert_eq!(sol.stats.mode, GradientMode::Forward);
                let z = sol.diagnostic(DiagnosticKind::Zeno).expect("zeno");
                assert_near(z.t, t_star(p[0], p[1], p[2]), 1e-9, "t*");
                assert!(
                    z.message.contains(&format!("[t*, {}]", p[4])),
                    "{}",
                    z.message
                );
                let n = sol
                    .diagnostics
                    .iter()
                    .filter(|d| d.kind == DiagnosticKind::Zeno)
                    .count();
                assert_eq!(n, accumulations, "{:?}", sol.diagnostics);
                if accumulations == 1 {
                    assert!(
                        sol.x_final[0] > 0.0,
                        "the ball flies again: {:?}",
                        sol.x_final
                    );
                }
            }
        }
    }
}

#[test]
fn a_kick_far_in_time_gives_the_answer_of_a_kick_at_eight() {
    // With T = τ + 2 the answer does not depend on τ (the ball rests from t* to τ, and what
    // follows the kick only on T − τ): the reference is the closed form at τ = 8, T = 10.
    // At τ = 10⁶ event times are quantised to ulp(10⁶) = 1.2e-10, which leaves ~1e-8 in C.
    let interp = loaded("zeno_kick.hyb");
    let p8 = [0.8, 9.81, 2.0, 3.0, 8.0];
    let (c, grad) = (kick_cost(&p8), fd(kick_cost, &p8, 1e-3));
    for (tau, rel) in [(1e3, 1e-8), (1e6, 1e-7)] {
        let p = [0.8, 9.81, 2.0, 3.0, tau];
        let o = Options {
            t_end: Some(tau + 2.0),
            ..precise(GradientMode::Forward)
        };
        for (door, sol) in [
            ("macro", run(&ZenoKick::new(), &p, &o)),
            ("loaded", run(&interp, &p, &o)),
        ] {
            let sol = sol.expect("runs");
            assert_solution(&sol, c, &grad, rel, &format!("{door} τ = {tau}"));
        }
    }
}

#[test]
fn the_held_limit_does_not_depend_on_how_far_the_horizon_lies() {
    let interp = loaded("zeno_kick.hyb");
    // Without a kick before T: C = ∫₀^{t*} h dt + 0 whatever T > t*.
    let cost = |p: &[f64]| ball(p[2], 0.0, 0.0, 20.0, p[1], p[0]).0;
    // The kick lies beyond every T (occurrences after T never fire).
    let p = [0.8, 9.81, 2.0, 3.0, 1e305];
    let pe = [p[0], p[1], p[2]];
    let (c, g3) = (cost(&pe), fd(cost, &pe, 1e-3));
    assert_near(c, 2.6379478019205, 1e-12, "the probe's reference");
    let grad = [g3[0], g3[1], g3[2], 0.0, 0.0];
    for t_end in [10.0, 1e6, 1e12, 1e20, 1e300] {
        let o = Options {
            t_end: Some(t_end),
            ..precise(GradientMode::Forward)
        };
        for (door, sol) in [
            ("macro", run(&ZenoKick::new(), &p, &o)),
            ("loaded", run(&interp, &p, &o)),
        ] {
            let sol = sol.expect("runs");
            assert_solution(&sol, c, &grad, 1e-8, &format!("{door} T = {t_end}"));
            // Held on the guard exactly: h(T) = 0, dh(T)/dθ = 0.
            assert_eq!(sol.x_final[0], 0.0, "{door} T = {t_end}");
            for j in 0..p.len() {
                assert_eq!(sol.s_final[2 * j], 0.0, "{door} T = {t_end}: S_h,{j}");
            }
        }
    }
}

/// C = ∫₀ᵀ (h + s) dt, s the height sampled every P (zero-order hold).
fn sampled_cost(p: &[f64]) -> f64 {
    let [e, g, h0, period] = [p[0], p[1], p[2], p[3]];
    let t_end = 10.0;
    let mut c = ball(h0, 0.0, 0.0, t_end, g, e).0;
    let mut j = 0.0;
    while j * period <= t_end {
        let t = j * period;
        let h = if t == 0.0 {
            h0
        } else {
            ball(h0, 0.0, 0.0, t, g, e).1
        };
        c += h * (((j + 1.0) * period).min(t_end) - t);
        j += 1.0;
    }
    c
}

#[test]
fn a_time_event_that_leaves_the_ball_at_rest_keeps_it_held() {
    let interp = loaded("zeno_sampled.hyb");
    // P = 0.5: no sample lies within a few bounces of t* (the height there swings with e
    // within a flight of 0.01 s, which a difference step must not cross).
    let p = [0.8, 9.81, 2.0, 0.5];
    let (c, grad) = (sampled_cost(&p), fd(sampled_cost, &p, 1e-5));
    let o = precise(GradientMode::Forward);
    for (door, sol) in [
        ("macro", run(&ZenoSampled::new(), &p, &o)),
        ("loaded", run(&interp, &p, &o)),
    ] {
        let sol = sol.expect("runs");
        assert_solution(&sol, c, &grad, 1e-7, door);
        // One accumulation, held to T through the 9 samples after t*.
        let zeno: Vec<_> = sol
            .diagnostics
            .iter()
            .filter(|d| d.kind == DiagnosticKind::Zeno)
            .collect();
        assert_eq!(zeno.len(), 1, "{zeno:?}");
        assert!(zeno[0].message.contains("[t*, T]"), "{}", zeno[0].message);
        assert_eq!(sol.x_final[0], 0.0);
        assert_eq!(sol.x_final[2], 0.0, "the last sample read the resting ball");
    }
}

const DIVERGENT: [(&str, &str); 2] = [("sum(impact, 1)", "1"), ("sum(impact, t)", "5.7")];

#[test]
fn an_event_sum_that_diverges_at_the_accumulation_is_an_error() {
    for (term, grows) in DIVERGENT {
        let src = format!(
            "model Divergent {{
                param e = 0.8;   param g = 9.81;   param h0 = 2.0;
                state h = h0;    state v = 0;
                flow {{ der(h) = v; der(v) = -g; }}
                event impact when h <= 0 {{ v = -e * v; }}
                cost = integral(h) + {term};
                horizon 10;
            }}"
        );
        let m = InterpretedModel::from_source(&src).expect("loads");
        for mode in [GradientMode::Forward, GradientMode::Adjoint] {
            match run(&m, &[0.8, 9.81, 2.0], &precise(mode)) {
                Err(SolveError::NonFinite { t, what }) => {
                    assert_near(t, t_star(0.8, 9.81, 2.0), 1e-9, "t*");
                    assert!(
                        what.contains("`impact`") && what.contains("diverges"),
                        "{what}"
                    );
                    assert!(what.contains(&format!("by about {grows}")), "{what}");
                }
                other => panic!("{term} {mode:?}: {:?}", other.map(|s| s.cost)),
            }
        }
    }
}

#[test]
fn a_convergent_event_sum_over_the_accumulation_is_summed() {
    // Σ_k (eᵏ v1)² = 2 g h0 e²/(1 − e²) over the impacts (all before t* < T).
    let src = "model Convergent {
        param e = 0.8;   param g = 9.81;   param h0 = 2.0;
        state h = h0;    state v = 0;
        flow { der(h) = v; der(v) = -g; }
        event impact when h <= 0 { v = -e * v; }
        cost = sum(impact, v^2);
        horizon 10;
    }";
    let m = InterpretedModel::from_source(src).expect("loads");
    let (e, g, h0): (f64, f64, f64) = (0.8, 9.81, 2.0);
    let c = 2.0 * g * h0 * e * e / (1.0 - e * e);
    let grad = [
        2.0 * g * h0 * 2.0 * e / (1.0 - e * e).powi(2),
        c / g,
        c / h0,
    ];
    let sol = run(&m, &[e, g, h0], &precise(GradientMode::Forward)).expect("runs");
    assert_solution(&sol, c, &grad, 1e-8, "Σ v²");
}

/// An accumulation whose limit lies within rounding of T (e = 1/2, g = 9, h0 = 2: t* = 2 = T):
/// the hold's last step to T is a few ulp long and is taken (it was a "step size underflow"
/// in a primal run), and C = ∫h = 8/7 with or without sensitivities.
#[test]
fn an_accumulation_within_rounding_of_the_horizon_ends_the_run() {
    let m = mvad_tests::loaded_test_model("../../models/bouncing_ball.hyb");
    for sensitivities in [false, true] {
        let opts = Options {
            rtol: 1e-10,
            atol: 1e-12,
            sensitivities,
            ..Options::default()
        };
        let sol = solve_at(&m, &[0.5, 9.0, 2.0, 0.0], &opts).expect("runs");
        assert_near(sol.cost, 8.0 / 7.0, 1e-12, format!("sens {sensitivities}"));
    }
}
