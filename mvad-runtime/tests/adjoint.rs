//! Adjoint mode (`GradientMode::Adjoint`): against closed forms (the case matrix of
//! `common::cases` under every method), against forward mode at rtol 1e-12 on every test
//! model and on random models (proptest), through simultaneous events and a stiff relay, its
//! fallback to forward mode at accumulations, and the VJP entry point against central finite
//! differences for observables sampled before, between, at and after events.
#![allow(clippy::needless_range_loop)] // index loops over params read clearer in tests

mod common;

use common::ball::{BallCost, BallSpec};
use common::cases::{cases, run_matrix};
use common::check::{assert_close, assert_cost_grad, close};
use common::models::{relay_closed, Dip, Kink, Relay, Thermostat, Twin};
use common::{ev, info, AdModel, Sc, Spec, D};
use mvad_runtime::model::{Direction, ModelInfo};
use mvad_runtime::solution::{DiagnosticKind, GradientMode, Method, Options, Solution};
use mvad_runtime::solve::solve;
use mvad_runtime::{vjp, Cotangents};
use nalgebra::DVector;
use proptest::prelude::*;

/// rtol 1e-12, atol 1e-14: where forward and adjoint must agree to 1e-10.
fn fine(mode: GradientMode) -> Options {
    Options {
        rtol: 1e-12,
        atol: 1e-14,
        gradient_mode: mode,
        ..Options::default()
    }
}

/// The largest |a_j − f_j| / max(max_j |f_j|, floor): agreement relative to the gradient's
/// scale (an entry that is exactly zero forwards is held to the same absolute accuracy).
fn rel_diff(a: &[f64], f: &[f64], floor: f64) -> f64 {
    assert_eq!(a.len(), f.len());
    let scale = f.iter().fold(floor, |m, v| m.max(v.abs()));
    a.iter()
        .zip(f)
        .map(|(x, y)| (x - y).abs() / scale)
        .fold(0.0, f64::max)
}

/// Solves in forward and adjoint mode under `method`; returns both.
fn both<T: Spec>(spec: T, p: &[f64], o: &Options) -> (Solution, Solution) {
    let m = AdModel::new(spec);
    let p = DVector::from_column_slice(p);
    let fwd = Options {
        gradient_mode: GradientMode::Forward,
        ..o.clone()
    };
    let adj = Options {
        gradient_mode: GradientMode::Adjoint,
        ..o.clone()
    };
    let f = solve(&m, &p, &fwd).expect("forward");
    let a = solve(&m, &p, &adj).expect("adjoint");
    (f, a)
}

/// Cases whose checks read forward-only quantities (t', atoms): E2's first impacts, the
/// ceilings near grazing and the dips; their gradients are compared with forward mode in
/// [`adjoint_matches_forward`] instead.
fn reads_forward_quantities(name: &str) -> bool {
    ["E2 ", "ceiling", "dip"]
        .iter()
        .any(|p| name.starts_with(p))
}

/// The closed-form matrix in adjoint mode, under every method each case applies to: E1's
/// five costs at three parameter points and the fixture, the thermostat (∫temp, ∫(temp −
/// 20)²), the stiff relay, the kink, twin events at one instant, a model without parameters;
/// the Zeno and inelastic balls fall back to forward mode and still meet their checks.
#[test]
fn closed_forms_in_adjoint_mode() {
    let adjoint = cases()
        .into_iter()
        .filter(|case| !reads_forward_quantities(&case.name))
        .map(|mut case| {
            case.opts.gradient_mode = GradientMode::Adjoint;
            case
        });
    run_matrix(adjoint, 25 * 4);
}

/// Forward and adjoint agree to 1e-10 of the gradient's scale at rtol 1e-12 on every test
/// model, under every method (the stiff relay under the implicit ones).
#[test]
fn adjoint_matches_forward() {
    let apex = 1.0 + 9.0 / (2.0 * 9.81);
    let mut worst = 0.0f64;
    let mut report = vec![];
    let mut check = |name: &str, (f, a): (Solution, Solution)| {
        assert_eq!(a.stats.mode, GradientMode::Adjoint, "{name}");
        assert_eq!(f.stats.mode, GradientMode::Forward, "{name}");
        assert_eq!(a.events.len(), f.events.len(), "{name}: event count");
        assert!(close(a.cost, f.cost, 1e-11, 1e-14), "{name}: cost");
        let d = rel_diff(&a.gradient, &f.gradient, 1e-8);
        worst = worst.max(d);
        report.push(format!("{name}: {d:.1e}"));
        assert!(
            d <= 1e-10,
            "{name}: adjoint {:?} forward {:?} ({d:e})",
            a.gradient,
            f.gradient
        );
    };
    for method in Method::ALL {
        let o = Options {
            method,
            ..fine(GradientMode::Forward)
        };
        for cost in BallCost::CLOSED_FORM
            .into_iter()
            .chain([BallCost::Weighted])
        {
            let spec = BallSpec::new(cost, 2.0);
            let p = spec.defaults.clone();
            check(&format!("ball {cost:?} {method:?}"), both(spec, &p, &o));
        }
        let spec = BallSpec::param_horizon();
        let p = spec.defaults.clone();
        check(&format!("ball mixed, T = θ {method:?}"), both(spec, &p, &o));
        for gap in [1e-1, 1e-3] {
            let p = [0.8, 9.81, 1.0, 3.0, apex - gap];
            let name = format!("ceiling gap {gap:e} {method:?}");
            check(&name, both(BallSpec::ceiling(), &p, &o));
        }
        for squared in [false, true] {
            let name = format!("thermostat squared={squared} {method:?}");
            check(
                &name,
                both(Thermostat { squared }, &[0.5, 18.0, 22.0, 10.0], &o),
            );
        }
        check(&format!("kink {method:?}"), both(Kink, &[1.5, 0.5], &o));
        check(&format!("dip {method:?}"), both(Dip, &[0.5, 1e-3], &o));
        check(
            &format!("twin {method:?}"),
            both(Twin, &[0.4, 1.0, 1.0, 2.0], &o),
        );
        let wall = Wild::default();
        let p = wall.defaults.to_vec();
        check(&format!("every construct {method:?}"), both(wall, &p, &o));
        if matches!(method, Method::Auto | Method::Rosenbrock) {
            check(
                &format!("stiff relay {method:?}"),
                both(Relay, &[1.0, 0.2, 1.0], &o),
            );
        }
    }
    println!("forward vs adjoint at rtol 1e-12 (max |Δ| / max |dC/dθ|):");
    for r in &report {
        println!("  {r}");
    }
    println!("worst {worst:.2e}");
}

/// The stiff relay (τ = 1e-8) in adjoint mode at rtol 1e-9: cost and gradient within 1e-6
/// of the closed form, under `auto` (which must switch to Rodas5P backwards too) and Rodas5P.
#[test]
fn stiff_relay_adjoint_at_rtol_1e9() {
    let p = [1.0, 0.2, 1.0];
    let (c, nev) = relay_closed(D::var(p[0], 0), D::var(p[1], 1), D::var(p[2], 2), 3.0);
    for method in [Method::Auto, Method::Rosenbrock] {
        let o = Options {
            method,
            rtol: 1e-9,
            atol: 1e-11,
            gradient_mode: GradientMode::Adjoint,
            ..Options::default()
        };
        let sol = solve(&AdModel::new(Relay), &DVector::from_column_slice(&p), &o).unwrap();
        assert_eq!(sol.stats.mode, GradientMode::Adjoint);
        assert_eq!(sol.events.len(), nev);
        assert_cost_grad(
            &format!("{method:?}"),
            &sol,
            c.v,
            &c.g[..3],
            1e-6,
            1e-6,
            1e-9,
        );
        // A stiff sweep in few steps: the implicit method took over backwards as well.
        assert!(
            sol.stats.steps < 10_000,
            "{method:?}: {} steps",
            sol.stats.steps
        );
        assert!(sol.stats.factorizations > 0, "{method:?}");
    }
}

/// [`Twin`]'s two events at one instant, undone in reverse order by the sweep, against the
/// closed form by dual numbers.
#[test]
fn simultaneous_events_undone_in_reverse_order() {
    let p = [0.4, 1.5, 0.7, 2.0];
    let d = |i: usize| D::var(p[i], i);
    let (c, y0, u, v) = (d(0), d(1), d(2), d(3));
    let after = (y0 + u) * v;
    let want = y0 * c + after * (-c + 1.0) + after * after;
    for method in Method::ALL {
        let o = Options {
            method,
            ..fine(GradientMode::Adjoint)
        };
        let sol = solve(&AdModel::new(Twin), &DVector::from_column_slice(&p), &o).unwrap();
        assert!(sol.diagnostic(DiagnosticKind::SimultaneousEvents).is_some());
        assert_eq!(sol.events.len(), 2);
        assert_cost_grad(
            &format!("{method:?}"),
            &sol,
            want.v,
            &want.g[..4],
            1e-13,
            1e-12,
            1e-13,
        );
    }
}

/// An accumulation: the adjoint hands over to forward mode and says so.
#[test]
fn zeno_falls_back_to_forward_mode() {
    let spec = BallSpec::int_h(3.0, 0.5);
    let p = spec.defaults.clone();
    let (f, a) = both(spec, &p, &fine(GradientMode::Forward));
    assert_eq!(a.stats.mode, GradientMode::Forward);
    let z = a.diagnostic(DiagnosticKind::Zeno).expect("zeno diagnostic");
    assert!(z.message.contains("forward mode"), "{}", z.message);
    assert_eq!(a.gradient, f.gradient);
}

/// `auto` picks the adjoint from `AUTO_ADJOINT_MIN_PARAMS` parameters on.
#[test]
fn auto_mode_resolves_by_parameter_count() {
    let k = GradientMode::AUTO_ADJOINT_MIN_PARAMS;
    assert_eq!(GradientMode::Auto.resolve(k - 1), GradientMode::Forward);
    assert_eq!(GradientMode::Auto.resolve(k), GradientMode::Adjoint);
    assert_eq!(GradientMode::Adjoint.resolve(1), GradientMode::Adjoint);
    let spec = BallSpec::new(BallCost::IntH, 2.0);
    let (f, a) = both(spec, &[0.8, 9.81, 2.0, 0.0], &fine(GradientMode::Auto));
    assert_eq!(
        (f.stats.mode, a.stats.mode),
        (GradientMode::Forward, GradientMode::Adjoint)
    );
}

/// Every construct at once (two modes, parameter-dependent guards, resets, initial state
/// and horizon, a time-dependent guard and reset, kinks in the flow and in ℓ, running,
/// event and final costs): x = (x0, x1), θ = (k, d, u, c, r, a).
///
/// mode `free`:   ẋ0 = x1, ẋ1 = −k x0 − d x1 + u sin(ω t) + a |x0 − 0.1|;
///   event `hit` when x0 ≥ c + 0.2 sin t → `stuck`: x1 ← −r x1 + 0.3 r cos t;
/// mode `stuck`:  ẋ0 = x1, ẋ1 = −k x0 − 2d x1 − a x0;
///   event `back` when x0 ≤ −c/2 → `free` (identity reset);
/// ℓ = x0² + q x1 + |x1 − 0.2|, φ_hit = x1² (after the reset), Φ = a x0(T),
/// x(0) = (0.1 u, v0), T = t_end (1 + 0.1 d).
#[derive(Clone, Copy, Debug)]
struct Wild {
    omega: f64,
    q: f64,
    v0: f64,
    t_end: f64,
    defaults: [f64; 6],
}

impl Default for Wild {
    fn default() -> Self {
        Wild {
            omega: 1.3,
            q: 0.4,
            v0: 2.0,
            t_end: 4.0,
            defaults: [2.0, 0.1, 0.5, 0.4, 0.7, 0.3],
        }
    }
}

impl Spec for Wild {
    fn info(&self) -> ModelInfo {
        let names = ["k", "d", "u", "c", "r", "a"];
        let params: Vec<(&str, f64)> = names.iter().copied().zip(self.defaults).collect();
        let mut i = info(
            "Wild",
            &["x0", "x1"],
            &params,
            &["free", "stuck"],
            vec![
                ev("hit", Direction::Up, Some(0), Some(1), true),
                ev("back", Direction::Down, Some(1), Some(0), false),
            ],
            &["x0", "x1"],
            2,
        );
        i.has_final_cost = true;
        i
    }
    fn x0<S: Sc>(&self, p: &[S], x: &mut [S]) {
        x[0] = p[2] * 0.1;
        x[1] = S::cst(self.v0);
    }
    fn horizon<S: Sc>(&self, p: &[S]) -> Option<S> {
        Some((p[1] * 0.1 + 1.0) * self.t_end)
    }
    fn switch<S: Sc>(&self, j: usize, _t: S, x: &[S], _p: &[S]) -> S {
        if j == 0 {
            x[0] - 0.1
        } else {
            x[1] - 0.2
        }
    }
    fn rhs<S: Sc>(&self, m: usize, sw: u64, t: S, x: &[S], p: &[S], f: &mut [S]) {
        f[0] = x[1];
        if m == 0 {
            let s = x[0] - 0.1;
            let abs = if sw & 1 != 0 { s } else { -s };
            f[1] = -(p[0] * x[0]) - p[1] * x[1] + p[2] * (t * self.omega).sin() + p[5] * abs;
        } else {
            f[1] = -(p[0] * x[0]) - p[1] * x[1] * 2.0 - p[5] * x[0];
        }
    }
    fn guard<S: Sc>(&self, k: usize, t: S, x: &[S], p: &[S]) -> S {
        if k == 0 {
            x[0] - p[3] - t.sin() * 0.2
        } else {
            x[0] + p[3] * 0.5
        }
    }
    fn reset<S: Sc>(&self, k: usize, t: S, x: &[S], p: &[S], xp: &mut [S]) {
        xp[0] = x[0];
        xp[1] = if k == 0 {
            -(p[4] * x[1]) + p[4] * t.cos() * 0.3
        } else {
            x[1]
        };
    }
    fn observe<S: Sc>(&self, _t: S, x: &[S], _p: &[S], y: &mut [S]) {
        y[0] = x[0];
        y[1] = x[1];
    }
    fn running<S: Sc>(&self, sw: u64, _t: S, x: &[S], _p: &[S]) -> S {
        let s = x[1] - 0.2;
        let abs = if sw & 2 != 0 { s } else { -s };
        x[0] * x[0] + x[1] * self.q + abs
    }
    fn event_cost<S: Sc>(&self, k: usize, _t: S, x: &[S], _p: &[S]) -> S {
        if k == 0 {
            x[1] * x[1]
        } else {
            S::cst(0.0)
        }
    }
    fn final_cost<S: Sc>(&self, _t: S, x: &[S], p: &[S]) -> S {
        p[5] * x[0]
    }
}

#[test]
fn every_construct_model_has_events_flips_and_mode_switches() {
    // The comparisons above and below are not vacuous: the default draw crosses both kinks,
    // fires both events and switches modes.
    let wild = Wild::default();
    let p = wild.defaults;
    let (f, _) = both(wild, &p, &fine(GradientMode::Forward));
    let names: Vec<usize> = f.events.iter().map(|e| e.event).collect();
    assert!(names.contains(&0) && names.contains(&1), "{names:?}");
    assert!(
        f.stats.switch_crossings >= 2,
        "{}",
        f.stats.switch_crossings
    );
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, .. ProptestConfig::default() })]
    /// Random draws of the every-construct model: forward and adjoint agree to 1e-10 of the
    /// gradient's scale at rtol 1e-12 (grazing draws included: both modes divide by the
    /// same ġ).
    #[test]
    fn random_models_adjoint_matches_forward(
        k in 1.0..4.0f64, d in 0.0..0.5f64, u in 0.0..1.0f64, c in 0.2..0.6f64,
        r in 0.3..0.9f64, a in -0.5..0.5f64, omega in 0.5..3.0f64, q in -1.0..1.0f64,
        v0 in 1.5..2.5f64, t_end in 2.0..5.0f64,
    ) {
        let wild = Wild { omega, q, v0, t_end, defaults: [k, d, u, c, r, a] };
        let p = wild.defaults;
        let (f, a) = both(wild, &p, &fine(GradientMode::Forward));
        prop_assert_eq!(a.events.len(), f.events.len());
        let diff = rel_diff(&a.gradient, &f.gradient, 1e-8);
        prop_assert!(diff <= 1e-10, "adjoint {:?} forward {:?} ({:e}, {} events, {} flips)",
            a.gradient, f.gradient, diff, f.events.len(), f.stats.switch_crossings);
    }
}

/// The cotangents w_C of C and w of the observables at `times`.
fn cotangents<'a>(times: &'a [f64], wc: f64, w: &'a [f64]) -> Cotangents<'a> {
    Cotangents {
        cost: wc,
        times,
        observables: w,
    }
}

/// w_C C + Σ_s w_sᵀ y(t_s) from the primal outputs of a VJP `v` (see [`pullback`]).
fn pairing(v: &mvad_runtime::Vjp, cot: &Cotangents<'_>) -> f64 {
    let w = cot.observables;
    cot.cost * v.cost + v.observables.iter().zip(w).map(|(y, w)| y * w).sum::<f64>()
}

/// The VJP at θ in the given mode.
fn pullback<T: Spec + Clone>(
    spec: &T,
    p: &[f64],
    o: &Options,
    cot: &Cotangents<'_>,
) -> mvad_runtime::Vjp {
    let m = AdModel::new(spec.clone());
    vjp(&m, &DVector::from_column_slice(p), o, cot).expect("vjp")
}

/// Central differences of [`pairing`] (of the VJP at each point) in each parameter with
/// relative steps 1e-4, 1e-5, 1e-6: each must be within `rel` (of the gradient's scale) of
/// `grad`. Returns the largest such error.
fn assert_central_fd<T: Spec + Clone>(
    what: &str,
    spec: &T,
    p: &[f64],
    o: &Options,
    cot: &Cotangents<'_>,
    grad: &[f64],
    rel: f64,
) -> f64 {
    let scale = grad.iter().fold(1e-3f64, |m, g| m.max(g.abs()));
    let mut worst = 0.0f64;
    for j in 0..p.len() {
        for step in [1e-4, 1e-5, 1e-6] {
            let h = step * p[j].abs().max(1.0);
            let (mut a, mut b) = (p.to_vec(), p.to_vec());
            a[j] += h;
            b[j] -= h;
            let fa = pairing(&pullback(spec, &a, o, cot), cot);
            let fb = pairing(&pullback(spec, &b, o, cot), cot);
            let fd = (fa - fb) / (2.0 * h);
            let e = (fd - grad[j]).abs() / scale;
            worst = worst.max(e);
            assert!(
                e <= rel,
                "{what} param {j} step {step:e}: fd {fd} vjp {}",
                grad[j]
            );
        }
    }
    println!("{what}: VJP against central differences, worst {worst:.1e} of the gradient's scale");
    worst
}

/// The ball's height and velocity sampled before the first impact (0.3), between the
/// impacts (1.0), after the second (1.8) and at T, with a cost cotangent: the VJP in adjoint
/// mode against central differences (every method), and equal to forward mode's.
#[test]
fn vjp_matches_finite_differences_around_events() {
    let spec = BallSpec::new(BallCost::IntH, 2.0);
    let p = [0.8, 9.81, 2.0, 0.3];
    let times = [0.3, 1.0, 1.8, 2.0];
    let w = [0.3, -1.2, 1.1, 0.4, -0.5, 0.9, 0.2, 0.6];
    let cot = cotangents(&times, 0.7, &w);
    for method in Method::ALL {
        let o = Options {
            method,
            ..fine(GradientMode::Adjoint)
        };
        let adj = pullback(&spec, &p, &o, &cot);
        assert_eq!(adj.solution.stats.mode, GradientMode::Adjoint);
        assert_eq!(adj.solution.events.len(), 2);
        let fo = Options {
            gradient_mode: GradientMode::Forward,
            ..o.clone()
        };
        let fwd = pullback(&spec, &p, &fo, &cot);
        let d = rel_diff(&adj.gradient, &fwd.gradient, 1e-8);
        assert!(
            d <= 1e-9,
            "{method:?}: adjoint {:?} forward {:?}",
            adj.gradient,
            fwd.gradient
        );
        for (a, f) in adj.observables.iter().zip(&fwd.observables) {
            assert!(close(*a, *f, 1e-10, 1e-12), "{method:?}: y {a} vs {f}");
        }
        let what = format!("ball {method:?}");
        assert_central_fd(&what, &spec, &p, &o, &cot, &adj.gradient, 1e-6);
    }
    // The thermostat's temperature between its switchings, no cost cotangent.
    let th = Thermostat { squared: true };
    let p = [0.5, 18.0, 22.0, 10.0];
    let o = fine(GradientMode::Adjoint);
    let times = [0.5, 2.7, 6.1, 9.9];
    let w = [1.0, -0.4, 0.8, 0.25];
    let cot = cotangents(&times, 0.0, &w);
    let adj = pullback(&th, &p, &o, &cot);
    assert_central_fd("thermostat", &th, &p, &o, &cot, &adj.gradient, 1e-6);
}

/// A sample exactly at an event time takes the post-event value y(t_k⁺) and its derivative
/// h_x S(t_k⁺) + h_θ: forward mode's recorded S there, and the one-sided difference from the
/// side where the event has already happened at t_k (second order: θ, θ + h, θ + 2h with
/// h·t_k' < 0); for e, which does not move t_k, the central one.
#[test]
fn vjp_at_an_event_time_is_right_continuous() {
    let spec = BallSpec::new(BallCost::IntH, 2.0);
    let p = [0.8, 9.81, 2.0, 0.3];
    let o = fine(GradientMode::Adjoint);
    // The event time as the adjoint's primal run locates it (forward mode's differs in the
    // last bits, and a sample a bit before the event is a pre-event sample); t' from forward
    // mode picks the side of the one-sided difference.
    let ev = pullback(&spec, &p, &o, &cotangents(&[], 1.0, &[]))
        .solution
        .events[0]
        .clone();
    let fwd = solve(
        &AdModel::new(spec.clone()),
        &DVector::from_column_slice(&p),
        &fine(GradientMode::Forward),
    )
    .unwrap();
    let dt = &fwd.events[0].dt;
    let times = [ev.t];
    let w = [0.0, 1.0];
    let cot = cotangents(&times, 0.0, &w);
    let adj = pullback(&spec, &p, &o, &cot);
    // y = v(t_k⁺) = −e v⁻.
    assert!(
        close(adj.observables[1], ev.x_after[1], 1e-12, 0.0),
        "{:?}",
        adj.observables
    );
    let f = |q: &[f64]| pairing(&pullback(&spec, q, &o, &cot), &cot);
    // Forward mode samples S a hair after the event (its own t_k differs in the last bits).
    let fo = Options {
        gradient_mode: GradientMode::Forward,
        ..o.clone()
    };
    let by_fwd = pullback(&spec, &p, &fo, &cotangents(&[ev.t + 1e-12], 0.0, &w));
    for j in 0..4 {
        let h = 1e-5 * p[j].abs().max(1.0);
        let fd = if dt[j] == 0.0 {
            let (mut a, mut b) = (p.to_vec(), p.to_vec());
            a[j] += h;
            b[j] -= h;
            (f(&a) - f(&b)) / (2.0 * h)
        } else {
            let h = -h * dt[j].signum();
            let (mut a, mut b) = (p.to_vec(), p.to_vec());
            a[j] += h;
            b[j] += 2.0 * h;
            (-3.0 * f(&p) + 4.0 * f(&a) - f(&b)) / (2.0 * h)
        };
        assert!(
            close(adj.gradient[j], fd, 1e-5, 1e-8),
            "param {j}: vjp {} fd {fd}",
            adj.gradient[j]
        );
        let what = format!("param {j}: adjoint vs forward");
        assert_close(&what, adj.gradient[j], by_fwd.gradient[j], 1e-9, 1e-10);
    }
}

/// Bad cotangents are errors, never a panic or a silent answer.
#[test]
fn vjp_rejects_bad_cotangents() {
    let m = AdModel::new(BallSpec::new(BallCost::IntH, 2.0));
    let p = m.defaults();
    let o = fine(GradientMode::Adjoint);
    let bad = [
        (1.0, vec![0.5], vec![1.0]),       // one entry per observable needed (2)
        (1.0, vec![2.5], vec![1.0, 0.0]),  // after T
        (1.0, vec![-0.1], vec![1.0, 0.0]), // before 0
        (f64::NAN, vec![0.5], vec![1.0, 0.0]), // non-finite cost cotangent
        (1.0, vec![0.5], vec![f64::INFINITY, 0.0]),
    ];
    for (wc, times, w) in bad {
        let cot = Cotangents {
            cost: wc,
            times: &times,
            observables: &w,
        };
        let e = vjp(&m, &p, &o, &cot).expect_err("bad cotangent");
        assert!(
            matches!(e, mvad_runtime::SolveError::BadOption { .. }),
            "{e:?}"
        );
    }
}

/// Against the thermostat's closed form (∫temp, all four parameters) at rtol 1e-8, 1e-10 and
/// 1e-12 under every method, the adjoint's largest relative error is at most 5× forward
/// mode's or 5× rtol, whichever is larger: the primal run at 1/100 of the tolerances
/// (`PRIMAL_TOL_FACTOR`) makes up for the sensitivities that hold forward mode's steps short.
#[test]
fn adjoint_as_accurate_as_forward_against_a_closed_form() {
    use common::models::thermostat_closed;
    let p = [0.5, 18.0, 22.0, 10.0];
    let d = |i: usize| D::var(p[i], i);
    let (c1, _, _) = thermostat_closed(d(0), d(1), d(2), d(3), 10.0);
    let err = |g: &[f64]| (0..4).fold(0.0f64, |m, j| m.max(((g[j] - c1.g[j]) / c1.g[j]).abs()));
    println!("thermostat ∫temp, max relative error of dC/dθ (steps):");
    for method in Method::ALL {
        for rtol in [1e-8, 1e-10, 1e-12] {
            let o = Options {
                method,
                rtol,
                atol: rtol * 1e-2,
                ..Options::default()
            };
            let (f, a) = both(Thermostat { squared: false }, &p, &o);
            let (ef, ea) = (err(&f.gradient), err(&a.gradient));
            println!(
                "  {method:?} rtol {rtol:e}: forward {ef:.1e} ({}), adjoint {ea:.1e} ({})",
                f.stats.steps, a.stats.steps
            );
            assert!(
                ea <= 5.0 * ef.max(rtol),
                "{method:?} rtol {rtol:e}: {ea:e} vs {ef:e}"
            );
        }
    }
}
