//! Time events and data tables through both doors: a single dose (`at`) and a periodic
//! sampled controller (`every`) against closed forms, and the queue (`at each` over a table)
//! against the exact Lindley recursion (rational arithmetic on the same data) and finite
//! differences.

use approx::assert_relative_eq;
use models::queue::{self, Arrivals};
use mvad::interp::InterpretedModel;
use mvad::runtime::solution::{GradientMode, Options, Solution};
use mvad::runtime::solve::{solve, solve_with};
use mvad::table::Table;
use mvad::{fd_gradient, HybridModel, ModelAlloc, Trigger};
use mvad_tests::{assert_near, solve_at};
use nalgebra::DefaultAllocator;

mvad::hybrid!(include "tests/dose.hyb");
mvad::hybrid!(include "tests/sampled.hyb");
mvad::hybrid!(include "tests/late_dose.hyb");

fn tight() -> Options {
    Options {
        rtol: 1e-12,
        atol: 1e-14,
        ..Options::default()
    }
}

fn loaded(file: &str) -> InterpretedModel {
    mvad_tests::loaded_test_model(file)
}

fn run<M: HybridModel>(m: &M, p: &[f64], opts: &Options) -> Solution
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    solve_at(m, p, opts).expect("runs")
}

/// C = A (1 − e^{−k(T − t_d)})/k with t_d = 2·tdose, and its gradient in (k, A, tdose).
fn dose_closed_form(k: f64, a: f64, tdose: f64) -> (f64, [f64; 3]) {
    let (t_end, td) = (3.0, 2.0 * tdose);
    let s = t_end - td;
    let e = (-k * s).exp();
    let c = a * (1.0 - e) / k;
    let dk = a * (s * e * k - (1.0 - e)) / (k * k);
    (c, [dk, (1.0 - e) / k, -2.0 * a * e])
}

#[test]
fn a_single_dose_matches_its_closed_form_through_both_doors() {
    let p = [0.7, 2.0, 0.4];
    let (c, g) = dose_closed_form(p[0], p[1], p[2]);
    let interp = loaded("dose.hyb");
    for sol in [run(&Dose::new(), &p, &tight()), run(&interp, &p, &tight())] {
        assert_relative_eq!(sol.cost, c, max_relative = 1e-11);
        for (got, want) in sol.gradient.iter().zip(g) {
            assert_relative_eq!(*got, want, max_relative = 1e-10);
        }
        assert_eq!(sol.events.len(), 1);
        assert_eq!(sol.events[0].t, 0.8);
        // t' = ∂τ/∂θ = (0, 0, 2) for τ = 2·tdose; no root finding, no grazing.
        assert_eq!(sol.events[0].dt, vec![0.0, 0.0, 2.0]);
        assert!(sol.events[0].transversal);
    }
    assert_eq!(interp.info().events[0].trigger, Trigger::At);
    // A dose after the horizon never fires; one before t = 0 neither.
    for tdose in [1.6, -0.1] {
        let sol = run(&interp, &[0.7, 2.0, tdose], &tight());
        assert!(sol.events.is_empty());
        assert_eq!(sol.cost, 0.0);
    }
}

/// The sampled loop in closed form: x_j = x0 (1 − K h)^j at t = j h (j = 0..N, N h ≤ T),
/// Step sizes are not tied to t = 0: a segment starting at t = 10⁹ with a zero state (the
/// flow before the dose, and the backward sweep's λ = 0 at T) is integrated like one at
/// t = 0. T − t_d = 3 for every tdose, so C is the dose's closed form over 3 time units and
/// dC/dtdose = 0, in both modes and through both doors.
#[test]
fn a_dose_at_t_1e9_matches_its_closed_form_in_both_modes() {
    let p = [0.7, 2.0, 5e8];
    let (c, g) = dose_closed_form(p[0], p[1], 0.0);
    let interp = loaded("late_dose.hyb");
    for mode in [GradientMode::Forward, GradientMode::Adjoint] {
        let opts = Options {
            gradient_mode: mode,
            ..tight()
        };
        for sol in [run(&LateDose::new(), &p, &opts), run(&interp, &p, &opts)] {
            assert_relative_eq!(sol.cost, c, max_relative = 1e-10);
            assert_relative_eq!(sol.gradient[0], g[0], max_relative = 1e-9);
            assert_relative_eq!(sol.gradient[1], g[1], max_relative = 1e-9);
            assert!(
                sol.gradient[2].abs() <= 1e-9,
                "{mode:?}: dC/dtdose {}",
                sol.gradient[2]
            );
        }
    }
}

/// u_j = −K x_j held until the next sample; C = x(T) + ∫₀ᵀ x dt.
fn sampled_closed_form(gain: f64, h: f64, x0: f64) -> f64 {
    let t_end = 1.05;
    let n = (t_end / h).floor() as i32;
    let r = 1.0 - gain * h;
    let xj = |j: i32| x0 * r.powi(j);
    let tail = t_end - f64::from(n) * h;
    let integral: f64 = (0..n)
        .map(|j| h * xj(j) * (1.0 - gain * h / 2.0))
        .sum::<f64>()
        + tail * xj(n) * (1.0 - gain * tail / 2.0);
    xj(n) * (1.0 - gain * tail) + integral
}

#[test]
fn a_sampled_controller_matches_its_closed_form_through_both_doors() {
    let p = [2.0, 0.1, 1.5];
    let c = sampled_closed_form(p[0], p[1], p[2]);
    // Ridders' extrapolation of the closed form, with steps that keep N = 10 samples.
    let g = [
        models::derivative(|v| sampled_closed_form(v, p[1], p[2]), p[0], 1e-2),
        models::derivative(|v| sampled_closed_form(p[0], v, p[2]), p[1], 1e-3),
        models::derivative(|v| sampled_closed_form(p[0], p[1], v), p[2], 1e-2),
    ];
    let interp = loaded("sampled.hyb");
    for sol in [
        run(&Sampled::new(), &p, &tight()),
        run(&interp, &p, &tight()),
    ] {
        assert_relative_eq!(sol.cost, c, max_relative = 1e-12);
        for (got, want) in sol.gradient.iter().zip(g) {
            assert_relative_eq!(*got, want, max_relative = 1e-9);
        }
        // Samples at j·period for j = 0..10, each moving with dt/dperiod = j.
        assert_eq!(sol.events.len(), 11);
        for (j, e) in sol.events.iter().enumerate() {
            assert_relative_eq!(e.t, j as f64 * 0.1, max_relative = 1e-15);
            assert_eq!(e.dt[1], j as f64);
        }
    }
    // A period that is not positive is bad input, not a hang.
    let pv = nalgebra::DVector::from_vec(vec![2.0, 0.0, 1.5]);
    let err = solve(&interp, &pv, &tight()).unwrap_err();
    assert!(err.to_string().contains("period"), "{err}");
}

fn compiled_queue(a: &Arrivals) -> queue::Queue {
    queue::Queue::new(queue::QueueTables {
        arrivals: a.table().expect("table"),
    })
    .expect("binds")
}

fn loaded_queue(file: &str, a: &Arrivals) -> InterpretedModel {
    let mut m = InterpretedModel::from_source(&mvad_tests::model_source(file)).expect(file);
    m.bind_tables(&[&a.table().expect("table")]).expect("binds");
    m
}

/// Relative error, for messages.
fn rel(x: f64, y: f64) -> f64 {
    ((x - y) / y).abs()
}

/// `n` customers (generated from `seed`) served at μ = 1.25, and the exact C and dC/dμ of
/// the Lindley recursion.
fn lindley_queue(n: usize, seed: u64) -> (Arrivals, f64, f64, f64) {
    let a = Arrivals::generate(n, seed);
    let mu = 1.25;
    let (c, dmu, _) = queue::exact(&a.t, &a.s, mu, 1.0);
    (a, mu, c, dmu)
}

/// A run's C and dC/dμ against the exact ones, to 1e-12 relative.
#[track_caller]
fn assert_exact(door: &str, sol: &Solution, c: f64, dmu: f64) {
    assert!(rel(sol.cost, c) < 1e-12, "{door}: C = {} vs {c}", sol.cost);
    assert!(
        rel(sol.gradient[0], dmu) < 1e-12,
        "{door}: {} vs {dmu}",
        sol.gradient[0]
    );
}

#[test]
fn the_queue_matches_the_exact_lindley_recursion_through_both_doors() {
    let (a, mu, c, dmu) = lindley_queue(1000, 11);
    let opts = Options::default();
    let p = [mu];
    for (door, sol) in [
        ("compiled", run(&compiled_queue(&a), &p, &opts)),
        ("loaded", run(&loaded_queue("queue.hyb", &a), &p, &opts)),
    ] {
        assert_exact(door, &sol, c, dmu);
        let arrivals = sol.events.iter().filter(|e| e.event == 1).count();
        assert_eq!(arrivals, 1000, "{door}");
    }
}

#[test]
fn the_queue_at_1e6_customers_streams_and_matches_the_exact_recursion_through_both_doors() {
    // No event table (the `()` sink); about 4 s in the test profile. 10⁷ customers and the
    // command line are run by the release example `queue_scale`, which checks the same bound.
    let (a, mu, c, dmu) = lindley_queue(1_000_000, 3);
    let opts = Options::default();
    let compiled = solve_with(
        &compiled_queue(&a),
        &nalgebra::SVector::<f64, 1>::new(mu),
        &opts,
        &mut (),
    )
    .expect("runs");
    let loaded = solve_with(
        &loaded_queue("queue.hyb", &a),
        &nalgebra::DVector::from_vec(vec![mu]),
        &opts,
        &mut (),
    )
    .expect("runs");
    for (door, sol) in [("compiled", compiled), ("loaded", loaded)] {
        assert!(sol.events.is_empty(), "{door}");
        assert!(sol.stats.events > 1_000_000, "{door}");
        assert_exact(door, &sol, c, dmu);
    }
}

#[test]
fn the_stretched_queue_matches_the_exact_ipa_derivative_and_finite_differences() {
    let a = Arrivals::generate(1000, 5);
    let (mu, scale) = (1.25, 0.9);
    let (c, dmu, dsc) = queue::exact(&a.t, &a.s, mu, scale);
    let opts = Options::default();
    let p = [mu, scale];
    let compiled = queue::stretched::StretchedQueue::new(queue::stretched::StretchedQueueTables {
        arrivals: a.table().expect("table"),
    })
    .expect("binds");
    let interp = loaded_queue("queue_stretched.hyb", &a);
    for (door, sol) in [
        ("compiled", run(&compiled, &p, &opts)),
        ("loaded", run(&interp, &p, &opts)),
    ] {
        assert_exact(door, &sol, c, dmu);
        assert!(
            rel(sol.gradient[1], dsc) < 1e-12,
            "{door}: {} vs {dsc}",
            sol.gradient[1]
        );
    }
    // Central differences at several steps agree with the exact derivative to their own
    // truncation error (C is piecewise smooth in θ: kinks where a customer finds the server
    // just drained, so the steps stay small).
    let pv = nalgebra::DVector::from_vec(p.to_vec());
    for (i, want) in [(0, dmu), (1, dsc)] {
        for step in [1e-7, 1e-8] {
            let fd = fd_gradient(&interp, &pv, &opts, i, step).expect("fd");
            assert!(
                rel(fd, want) < 1e-5,
                "param {i}, step {step}: FD {fd} vs exact {want}"
            );
        }
    }
}

#[test]
fn table_events_stream_and_never_trip_the_event_budget() {
    // 3000 customers, about 3600 events, against a budget of 100 for state events: the
    // table's events do not count, nor one drain per arrival.
    let a = Arrivals::generate(3000, 2);
    let m = compiled_queue(&a);
    let opts = Options {
        max_events: 100,
        ..Options::default()
    };
    let p = nalgebra::SVector::<f64, 1>::new(1.25);
    let sol = solve_with(&m, &p, &opts, &mut ()).expect("runs within the budget");
    assert!(sol.events.is_empty());
    assert!(sol.stats.events > 3000, "{}", sol.stats.events);
    let (c, dmu, _) = queue::exact(&a.t, &a.s, 1.25, 1.0);
    assert!(rel(sol.cost, c) < 1e-12 && rel(sol.gradient[0], dmu) < 1e-12);
}

#[test]
fn scheduled_events_never_trip_the_event_or_step_budget() {
    // A sampled controller at 1 kHz: 1051 samples against a budget of 100 events and 500
    // step attempts. Like a table's rows, an `every` event's occurrences are given by the
    // model (T/period of them), not a flood: they count against neither budget.
    let p = [2.0, 1e-3, 1.5];
    let c = sampled_closed_form(p[0], p[1], p[2]);
    let dgain = models::derivative(|v| sampled_closed_form(v, p[1], p[2]), p[0], 1e-2);
    let opts = Options {
        max_events: 100,
        max_steps: 500,
        ..tight()
    };
    let interp = loaded("sampled.hyb");
    for sol in [run(&Sampled::new(), &p, &opts), run(&interp, &p, &opts)] {
        assert_eq!(sol.stats.events, 1051);
        assert_relative_eq!(sol.cost, c, max_relative = 1e-12);
        assert_relative_eq!(sol.gradient[0], dgain, max_relative = 1e-9);
    }
    // What bounds such a run instead: a period so short that the event would fire more than
    // 10⁹ times before T is bad input, not a run that never ends.
    let pv = nalgebra::DVector::from_vec(vec![2.0, 1e-12, 1.5]);
    let err = solve(&interp, &pv, &opts).unwrap_err();
    assert!(err.is_bad_input(), "{err}");
    assert!(err.to_string().contains("1.050e12 times"), "{err}");
}

#[test]
fn bad_tables_are_located_errors() {
    let t = Table::parse_csv("q.csv", "t,s\n1,2\n0.5,1\n".to_string()).expect("parses");
    let err = queue::Queue::new(queue::QueueTables {
        arrivals: t.clone(),
    })
    .unwrap_err();
    assert!(
        err.to_string()
            .starts_with("q.csv:3:1: error: column `t` of table `arrivals` decreases"),
        "{err}"
    );
    // Stretched times are checked as they are scheduled: with scale < 0 they decrease.
    let mut m = InterpretedModel::from_source(&mvad_tests::model_source("queue_stretched.hyb"))
        .expect("model");
    let ok = Table::parse_csv("q.csv", "t,s\n1,2\n3,1\n".to_string()).expect("parses");
    m.bind_tables(&[&ok]).expect("binds");
    let err = solve(
        &m,
        &nalgebra::DVector::from_vec(vec![1.25, -1.0]),
        &Options::default(),
    )
    .unwrap_err();
    assert!(err.to_string().contains("decrease"), "{err}");
    let missing = Table::parse_csv("q.csv", "t,x\n1,2\n".to_string()).expect("parses");
    let err = queue::Queue::new(queue::QueueTables { arrivals: missing }).unwrap_err();
    assert!(
        err.to_string()
            .starts_with("q.csv:1:1: error: table `arrivals` has no column `s`"),
        "{err}"
    );
}

#[test]
fn occurrences_before_zero_or_outside_their_mode_are_skipped() {
    // Ticks at −0.25 + 0.1·j count in mode `a` only; `switch` leaves `a` at t = 0.35 and
    // `back` returns at 0.62: ticks at 0.05, 0.15, 0.25, 0.35 (with `switch`, applied after the
    // tick in declaration order), then 0.65, 0.75, 0.85, 0.95.
    let src = "model Ticks {
        param start = -0.25;
        state n = 0;
        initial mode a;
        mode a { der(n) = 0; event tick every 0.1 from start { n = n + 1; } }
        mode b { der(n) = 0; }
        event switch at 0.35 -> b;
        event back at 0.62 -> a;
        cost = final(n);
        horizon 1;
    }";
    let m = InterpretedModel::from_source(src).expect("model");
    let sol = solve(&m, &nalgebra::DVector::from_vec(vec![-0.25]), &tight()).expect("runs");
    let ticks: Vec<f64> = sol
        .events
        .iter()
        .filter(|e| e.event == 0)
        .map(|e| e.t)
        .collect();
    let want = [0.05, 0.15, 0.25, 0.35, 0.65, 0.75, 0.85, 0.95];
    assert_eq!(ticks.len(), want.len(), "{ticks:?}");
    for (t, w) in ticks.iter().zip(want) {
        assert_relative_eq!(*t, w, max_relative = 1e-14);
    }
    assert_eq!(sol.cost, 8.0);
    assert!(sol
        .diagnostics
        .iter()
        .any(|d| d.kind == mvad::DiagnosticKind::SimultaneousEvents && (d.t - 0.35).abs() < 1e-12));
    // The tick times move with `start`: t' = 1 for each.
    assert!(sol
        .events
        .iter()
        .filter(|e| e.event == 0)
        .all(|e| e.dt == vec![1.0]));
}

/// Adjoint mode on time events: the dose, the sampled controller, the queue and the stretched
/// queue, through both doors, against forward mode and the exact recursion.
#[test]
fn time_events_in_adjoint_mode_match_forward_mode_through_both_doors() {
    use mvad::GradientMode;
    let mode = |m: GradientMode| Options {
        gradient_mode: m,
        ..tight()
    };
    let check = |what: &str, f: Solution, a: Solution| {
        assert_eq!(a.stats.mode, GradientMode::Adjoint, "{what}");
        assert_relative_eq!(a.cost, f.cost, max_relative = 1e-11);
        for (x, y) in a.gradient.iter().zip(&f.gradient) {
            assert_near(
                *x,
                *y,
                1e-9,
                format_args!("{what}: adjoint vs forward gradient"),
            );
        }
    };
    let dose = [0.7, 2.0, 0.4];
    let sampled = [2.0, 0.1, 1.5];
    for (what, p, interp) in [
        ("dose", &dose[..], loaded("dose.hyb")),
        ("sampled", &sampled[..], loaded("sampled.hyb")),
    ] {
        let f = run(&interp, p, &mode(GradientMode::Forward));
        let a = run(&interp, p, &mode(GradientMode::Adjoint));
        check(&format!("{what} loaded"), f, a);
    }
    let f = run(&Dose::new(), &dose, &mode(GradientMode::Forward));
    let a = run(&Dose::new(), &dose, &mode(GradientMode::Adjoint));
    check("dose compiled", f, a);
    let f = run(&Sampled::new(), &sampled, &mode(GradientMode::Forward));
    let a = run(&Sampled::new(), &sampled, &mode(GradientMode::Adjoint));
    check("sampled compiled", f, a);
    // The queues: every arrival an `at each` event with a row value in its reset and cost.
    let a = Arrivals::generate(1000, 6);
    let (mu, scale) = (1.25, 0.9);
    let (c, dmu, _) = queue::exact(&a.t, &a.s, mu, 1.0);
    let (cs, dmus, dscs) = queue::exact(&a.t, &a.s, mu, scale);
    let opts = Options {
        gradient_mode: GradientMode::Adjoint,
        ..Options::default()
    };
    let plain = [
        run(&compiled_queue(&a), &[mu], &opts),
        run(&loaded_queue("queue.hyb", &a), &[mu], &opts),
    ];
    for sol in plain {
        assert_eq!(sol.stats.mode, GradientMode::Adjoint);
        assert!(
            rel(sol.cost, c) < 1e-12 && rel(sol.gradient[0], dmu) < 1e-12,
            "{sol:?}"
        );
    }
    let stretched = queue::stretched::StretchedQueue::new(queue::stretched::StretchedQueueTables {
        arrivals: a.table().expect("table"),
    })
    .expect("binds");
    for sol in [
        run(&stretched, &[mu, scale], &opts),
        run(
            &loaded_queue("queue_stretched.hyb", &a),
            &[mu, scale],
            &opts,
        ),
    ] {
        assert!(rel(sol.cost, cs) < 1e-12, "{}", sol.cost);
        assert!(rel(sol.gradient[0], dmus) < 1e-12, "{:?}", sol.gradient);
        assert!(rel(sol.gradient[1], dscs) < 1e-12, "{:?}", sol.gradient);
    }
}

/// A time event exactly at an end of the run whose time moves with θ makes C jump there (on one
/// side it falls outside [0, T] and does not fire): a `kink` diagnostic at t = 0 and at t = T,
/// the gradient the one-sided value with the event. At a horizon that moves with the event
/// (`horizon tau`) it stays on the end: no kink.
#[test]
fn a_time_event_at_an_end_of_the_run_moving_with_the_params_is_a_kink() {
    let model = |at: &str, horizon: &str| {
        InterpretedModel::from_source(&format!(
            "model EndEvent {{
                param tau = {at}; param b = 1; param x0 = 1;
                state x = x0;
                flow {{ der(x) = 0; }}
                event kick at tau {{ x = x + b; }}
                cost = final(x) + integral(x);
                horizon {horizon};
            }}"
        ))
        .expect("valid")
    };
    // Adjoint mode reports it too (its primal run computes τ'), with the same one-sided value.
    let adjoint = |m: &InterpretedModel| {
        let opts = Options {
            gradient_mode: GradientMode::Adjoint,
            ..Options::default()
        };
        let sol = mvad_tests::solve_at_defaults(m, &opts);
        assert_eq!(sol.stats.mode, GradientMode::Adjoint);
        sol
    };
    let kinks = |m: &InterpretedModel| {
        let sol = mvad_tests::solve_at_defaults(m, &Options::default());
        let adj = adjoint(m);
        assert_eq!(adj.diagnostics.len(), sol.diagnostics.len(), "{adj:?}");
        for (a, f) in adj.gradient.iter().zip(&sol.gradient) {
            assert_near(*a, *f, 1e-9, "adjoint gradient");
        }
        (kink_times(&sol), sol)
    };
    // At T = 2: C = (x0 + b) + x0 τ + (x0 + b)(T − τ) for τ ≤ T: 4 at τ = T, dC/dτ = −b from
    // the side where it fires (x0 + b + x0 T = 3 for τ > T).
    let (ts, sol) = kinks(&model("2", "2"));
    assert_eq!(ts, vec![2.0]);
    assert_near(sol.cost, 4.0, 1e-12, "C at T");
    assert_near(sol.gradient[0], -1.0, 1e-12, "dC/dtau at T");
    // At t = 0: the kick fires at the start, x = x0 + b on [0, 2]: C = 2 (x0 + b) + (x0 + b).
    let (ts, sol) = kinks(&model("0", "2"));
    assert_eq!(ts, vec![0.0]);
    assert_near(sol.cost, 6.0, 1e-12, "C at 0");
    // The horizon moves with the event: no kink.
    let (ts, _) = kinks(&model("2", "tau"));
    assert!(ts.is_empty(), "{ts:?}");
}

/// `every 0.3 from 0.3` with T = 3: its tenth occurrence is 0.3 + 9·0.3 = 2.9999999999999996,
/// one ulp before T (probe4 1, 2). The step that lands on it leaves a sliver of 4.4e-16 to T.
/// Adjoint mode's sweep starts on that sliver, and it used to seed the next segment's first
/// step with it: a step-size underflow. The seed is now ignored, so both modes give
/// C = e^{−aT} k^{10} (for cost = final(x), and its integral for ∫x). The occurrence is at T
/// within the resolution of t, so a larger period moves it past T: it is the `kink` of a time
/// event at an end of the run, in both modes.
#[test]
fn a_sample_one_ulp_before_the_horizon_is_at_the_end() {
    let (a, k, t_end) = (0.7_f64, 0.8_f64, 3.0_f64);
    for (cost, want) in [
        ("final(x)", (-a * t_end).exp() * k.powi(10)),
        // ∫₀ᵀ x: on [0.3 j, 0.3 (j+1)) x = k^j e^{−a t}; the last piece, after the tenth
        // sample, is one ulp long.
        ("integral(x)", {
            let mut sum = 0.0;
            for j in 0..10 {
                let (t0, t1) = (0.3 * j as f64, 0.3 * (j + 1) as f64);
                sum += k.powi(j) * ((-a * t0).exp() - (-a * t1).exp()) / a;
            }
            sum
        }),
    ] {
        let m = InterpretedModel::from_source(&format!(
            "model Sliver {{
                param a = {a}; param P = 0.3; param off = 0.3; param k = {k};
                state x = 1.0;
                flow {{ der(x) = -a*x; }}
                event samp every P from off {{ x = k*x; }}
                cost = {cost};
                horizon {t_end};
            }}"
        ))
        .expect("valid");
        for mode in [GradientMode::Forward, GradientMode::Adjoint] {
            let opts = Options {
                gradient_mode: mode,
                ..tight()
            };
            let sol = solve_at(&m, &m.info().param_defaults, &opts).expect("runs");
            assert_eq!(sol.stats.mode, mode);
            assert_near(sol.cost, want, 1e-9, format!("C of {cost}, {mode:?}"));
            assert_eq!(
                kink_times(&sol),
                vec![0.3 + 9.0 * 0.3],
                "{cost}, {mode:?}: {:?}",
                sol.diagnostics
            );
        }
    }
}

/// The times of a run's `kink` diagnostics.
fn kink_times(sol: &Solution) -> Vec<f64> {
    sol.diagnostics
        .iter()
        .filter(|d| d.kind == mvad::runtime::solution::DiagnosticKind::Kink)
        .map(|d| d.t)
        .collect()
}
