//! Closed-form checks of the driver: the E1 ball (∫h, ∫v, ∫h², v(T), Σ v⁺², all four
//! parameters), E2 first impacts, a two-mode thermostat, a stiff relay, a Zeno ball and a
//! ceiling bounce near grazing. Closed forms are derived by hand (piecewise polynomials,
//! exponentials and logs) and differentiated exactly with dual numbers; each is also
//! checked against central finite differences of itself.
#![allow(clippy::needless_range_loop)] // index loops over params read clearer in tests

mod common;

use approx::assert_relative_eq;
use common::{ev, info, AdModel, Sc, Spec, D};
use mvad_runtime::fixtures::Ball;
use mvad_runtime::model::{Direction, ModelInfo, Switches};
use mvad_runtime::solution::{DiagnosticKind, Method, Options};
use mvad_runtime::solve::solve;
use nalgebra::DVector;

fn tight() -> Options {
    Options {
        rtol: 1e-10,
        atol: 1e-12,
        ..Options::default()
    }
}

/// Relative agreement with an absolute floor for entries that are (near) zero.
fn close(a: f64, b: f64, rel: f64, abs: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()) + abs
}

fn assert_grad(what: &str, got: &[f64], want: &[f64], rel: f64, abs: f64) {
    assert_eq!(got.len(), want.len(), "{what}");
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(
            close(*g, *w, rel, abs),
            "{what}: d/dθ{i}: got {g:.17e}, want {w:.17e}, rel err {:.2e}",
            (g - w).abs() / w.abs()
        );
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum BallCost {
    IntH,
    IntV,
    IntH2,
    FinalV,
    SumVplus2,
}

/// The E1 ball with one of several costs, as a generic formula (θ = e, g, h0, v0).
struct BallSpec {
    cost: BallCost,
    t_end: f64,
    e: f64,
}

impl Spec for BallSpec {
    fn info(&self) -> ModelInfo {
        let mut i = info(
            "Ball",
            &["h", "v"],
            &[("e", self.e), ("g", 9.81), ("h0", 2.0), ("v0", 0.0)],
            &["main"],
            vec![ev(
                "impact",
                Direction::Down,
                None,
                None,
                self.cost == BallCost::SumVplus2,
            )],
            &["height", "velocity"],
            0,
        );
        i.has_running_cost = matches!(self.cost, BallCost::IntH | BallCost::IntV | BallCost::IntH2);
        i.has_final_cost = self.cost == BallCost::FinalV;
        i
    }
    fn x0<S: Sc>(&self, p: &[S], x: &mut [S]) {
        x[0] = p[2];
        x[1] = p[3];
    }
    fn horizon<S: Sc>(&self, _p: &[S]) -> Option<S> {
        Some(S::cst(self.t_end))
    }
    fn rhs<S: Sc>(&self, _m: usize, _sw: Switches, _t: S, x: &[S], p: &[S], f: &mut [S]) {
        f[0] = x[1];
        f[1] = -p[1];
    }
    fn guard<S: Sc>(&self, _k: usize, _t: S, x: &[S], _p: &[S]) -> S {
        x[0]
    }
    fn reset<S: Sc>(&self, _k: usize, _t: S, x: &[S], p: &[S], xp: &mut [S]) {
        xp[0] = x[0];
        xp[1] = -(p[0] * x[1]);
    }
    fn observe<S: Sc>(&self, _t: S, x: &[S], _p: &[S], y: &mut [S]) {
        y[0] = x[0];
        y[1] = x[1];
    }
    fn running<S: Sc>(&self, _sw: Switches, _t: S, x: &[S], _p: &[S]) -> S {
        match self.cost {
            BallCost::IntH => x[0],
            BallCost::IntV => x[1],
            BallCost::IntH2 => x[0] * x[0],
            _ => S::cst(0.0),
        }
    }
    fn event_cost<S: Sc>(&self, _k: usize, _t: S, x: &[S], _p: &[S]) -> S {
        x[1] * x[1]
    }
    fn final_cost<S: Sc>(&self, _t: S, x: &[S], _p: &[S]) -> S {
        if self.cost == BallCost::FinalV {
            x[1]
        } else {
            S::cst(0.0)
        }
    }
}

/// Closed form of the ball on [0, T] (flights are parabolas): returns
/// [∫h, ∫v, ∫h², v(T), Σ v⁺²] and the impact times. A flight from height a with launch
/// velocity u has h(s) = a + u s − g s²/2 and lands at s = (u + √(u² + 2ga))/g, where
/// v⁻ = u − g s and v⁺ = −e v⁻; over a piece of length L:
///   ∫h = aL + uL²/2 − gL³/6,  ∫v = uL − gL²/2,
///   ∫h² = a²L + a u L² + (u² − a g) L³/3 − u g L⁴/4 + g² L⁵/20.
fn ball_closed<S: Sc>(e: S, g: S, h0: S, v0: S, t_end: f64) -> ([S; 5], Vec<f64>) {
    let (mut t0, mut a, mut u) = (S::cst(0.0), h0, v0);
    let mut out = [S::cst(0.0); 5];
    let mut impacts = Vec::new();
    loop {
        let s = (u + (u * u + g * a * 2.0).sqrt()) / g;
        let last = (t0 + s).val() >= t_end;
        let l = if last { -(t0 - t_end) } else { s };
        let (l2, l3) = (l * l, l * l * l);
        out[0] = out[0] + a * l + u * l2 / 2.0 - g * l3 / 6.0;
        out[1] = out[1] + u * l - g * l2 / 2.0;
        out[2] = out[2] + a * a * l + a * u * l2 + (u * u - a * g) * l3 / 3.0
            - u * g * l2 * l2 / 4.0
            + g * g * l3 * l2 / 20.0;
        if last {
            out[3] = u - g * l;
            return (out, impacts);
        }
        t0 = t0 + s;
        impacts.push(t0.val());
        let vplus = -(e * (u - g * s));
        out[4] = out[4] + vplus * vplus;
        a = S::cst(0.0);
        u = vplus;
    }
}

fn ball_closed_dual(p: &[f64], t_end: f64) -> ([D; 5], Vec<f64>) {
    let d = |i: usize| D::var(p[i], i);
    ball_closed(d(0), d(1), d(2), d(3), t_end)
}

#[test]
fn e1_reference_values_with_the_fixture() {
    let ball = Ball::new();
    let p = ball.default_params();
    let (cf, impacts) = ball_closed_dual(p.as_slice(), 2.0);
    // The closed form reproduces DESIGN.md's reference values.
    assert_relative_eq!(impacts[0], 0.638_550_856_814_101, max_relative = 1e-15);
    assert_relative_eq!(impacts[1], 1.660_232_227_716_662_4, max_relative = 1e-15);
    assert_relative_eq!(cf[0].v, 1.890_513_712_317_350_6, max_relative = 1e-15);
    assert_relative_eq!(cf[0].g[0], 2.831_440_814_147_005_5, max_relative = 1e-14);
    for method in [Method::Auto, Method::Tsit5, Method::Verner9] {
        let sol = solve(&ball, &p, &Options { method, ..tight() }).unwrap();
        assert_eq!(sol.events.len(), 2, "{method:?}");
        eprintln!(
            "{method:?}: t1 err {:e} t2 err {:e} steps {}",
            sol.events[0].t - impacts[0],
            sol.events[1].t - impacts[1],
            sol.stats.steps
        );
        // Verner's interpolant reproduces the parabola to ~2e-13 (its coefficients), the
        // Tsit5 one to rounding.
        let t_tol = if method == Method::Verner9 {
            1e-12
        } else {
            1e-13
        };
        assert_relative_eq!(sol.events[0].t, impacts[0], max_relative = t_tol);
        assert_relative_eq!(sol.events[1].t, impacts[1], max_relative = t_tol);
        assert_relative_eq!(sol.cost, cf[0].v, max_relative = 1e-10);
        assert_grad(
            &format!("∫h {method:?}"),
            &sol.gradient,
            &cf[0].g[..4],
            1e-9,
            1e-12,
        );
    }
}

/// The closed form itself against central differences (so the reference is not wrong).
#[test]
fn ball_closed_form_agrees_with_finite_differences() {
    let p = DVector::from_vec(vec![0.8, 9.81, 2.0, 0.3]);
    let (cf, _) = ball_closed_dual(p.as_slice(), 2.0);
    for (c, cfc) in cf.iter().enumerate() {
        for i in 0..4 {
            let f = |q: &DVector<f64>| ball_closed(q[0], q[1], q[2], q[3], 2.0).0[c];
            for h in [1e-4, 1e-5, 1e-6] {
                let fd = common::central(f, &p, i, h);
                assert!(
                    close(fd, cfc.g[i], 1e-6, 1e-8),
                    "cost {c} param {i} h {h}: fd {fd} dual {}",
                    cfc.g[i]
                );
            }
        }
    }
}

#[test]
fn e1_all_costs_all_params() {
    for cost in [
        BallCost::IntH,
        BallCost::IntV,
        BallCost::IntH2,
        BallCost::FinalV,
        BallCost::SumVplus2,
    ] {
        for p in [
            [0.8, 9.81, 2.0, 0.0],
            [0.7, 9.0, 1.5, 0.8],
            [0.9, 9.81, 1.0, -2.0],
        ] {
            let m = AdModel::new(BallSpec {
                cost,
                t_end: 2.0,
                e: 0.8,
            });
            let pv = DVector::from_column_slice(&p);
            let (cf, impacts) = ball_closed_dual(&p, 2.0);
            let c = cf[cost as usize];
            let sol = solve(&m, &pv, &tight()).unwrap();
            assert_eq!(sol.events.len(), impacts.len(), "{cost:?} {p:?}");
            for (e, t) in sol.events.iter().zip(&impacts) {
                assert_relative_eq!(e.t, *t, max_relative = 1e-13);
            }
            assert!(
                close(sol.cost, c.v, 1e-9, 1e-12),
                "{cost:?} {p:?}: cost {} want {}",
                sol.cost,
                c.v
            );
            assert_grad(
                &format!("{cost:?} {p:?}"),
                &sol.gradient,
                &c.g[..4],
                1e-9,
                1e-11,
            );
        }
    }
}

/// E2: first impact of the ball from h0 = 1 for v0 = −0.5 … −5: event time, guard slope,
/// t' (all params), the velocity atom and the zero position atom, against the closed form
/// t1 = (v0 + √(v0² + 2 g h0))/g, v⁻ = v0 − g t1, J_v = −(1 + e) v⁻, α = −J t1'.
#[test]
fn e2_first_impact_sweep() {
    let reference = [
        (-0.5, 0.403_422_815_250_207_34, 4.457_577_817_604_534),
        (-5.0, 0.171_235_510_383_883_18, 6.679_820_356_865_894),
    ];
    for i in 0..10 {
        let v0 = -0.5 * (i + 1) as f64;
        let p = [0.8, 9.81, 1.0, v0];
        let d = |i: usize| D::var(p[i], i);
        let (e, g, h0, v0d) = (d(0), d(1), d(2), d(3));
        let root = (v0d * v0d + g * h0 * 2.0).sqrt();
        let t1 = (v0d + root) / g;
        let vminus = v0d - g * t1;
        let jv = -(vminus * (e + 1.0));
        let m = AdModel::new(BallSpec {
            cost: BallCost::IntH,
            t_end: t1.v + 0.01,
            e: 0.8,
        });
        let sol = solve(&m, &DVector::from_column_slice(&p), &tight()).unwrap();
        let evr = &sol.events[0];
        assert_relative_eq!(evr.t, t1.v, max_relative = 1e-13);
        assert_relative_eq!(evr.guard_slope, vminus.v, max_relative = 1e-11);
        assert!(evr.transversal);
        if let Some(r) = reference.iter().find(|r| r.0 == v0) {
            assert_relative_eq!(evr.t, r.1, max_relative = 1e-13);
            assert_relative_eq!(evr.guard_slope.abs(), r.2, max_relative = 1e-11);
        }
        assert_grad("t'", &evr.dt, &t1.g[..4], 1e-10, 1e-13);
        assert_relative_eq!(evr.jump_states[1], jv.v, max_relative = 1e-11);
        assert_eq!(evr.jump_states[0], 0.0);
        // atoms[observable][param]: height atoms are exactly zero, velocity atoms −J_v t'.
        assert!(evr.atoms[0].iter().all(|&a| a == 0.0), "{:?}", evr.atoms[0]);
        let want: Vec<f64> = (0..4).map(|j| -jv.v * t1.g[j]).collect();
        assert_grad("velocity atom", &evr.atoms[1], &want, 1e-10, 1e-13);
    }
}

/// Two-mode thermostat with thresholds lo, hi as parameters (θ = k, lo, hi, p), ambient 10,
/// temp(0) = 19, horizon 10.
struct Thermostat {
    squared: bool,
}

impl Spec for Thermostat {
    fn info(&self) -> ModelInfo {
        let mut i = info(
            "Thermostat",
            &["temp"],
            &[("k", 0.5), ("lo", 18.0), ("hi", 22.0), ("p", 10.0)],
            &["heating", "cooling"],
            vec![
                ev("switch_off", Direction::Up, Some(0), Some(1), false),
                ev("switch_on", Direction::Down, Some(1), Some(0), false),
            ],
            &["temp"],
            0,
        );
        i.has_final_cost = false;
        i
    }
    fn x0<S: Sc>(&self, _p: &[S], x: &mut [S]) {
        x[0] = S::cst(19.0);
    }
    fn horizon<S: Sc>(&self, _p: &[S]) -> Option<S> {
        Some(S::cst(10.0))
    }
    fn rhs<S: Sc>(&self, m: usize, _sw: Switches, _t: S, x: &[S], p: &[S], f: &mut [S]) {
        f[0] = -(p[0] * (x[0] - 10.0));
        if m == 0 {
            f[0] = f[0] + p[3];
        }
    }
    fn guard<S: Sc>(&self, k: usize, _t: S, x: &[S], p: &[S]) -> S {
        if k == 0 {
            x[0] - p[2]
        } else {
            x[0] - p[1]
        }
    }
    fn observe<S: Sc>(&self, _t: S, x: &[S], _p: &[S], y: &mut [S]) {
        y[0] = x[0];
    }
    fn running<S: Sc>(&self, _sw: Switches, _t: S, x: &[S], _p: &[S]) -> S {
        if self.squared {
            (x[0] - 20.0) * (x[0] - 20.0)
        } else {
            x[0]
        }
    }
}

/// Closed form of the thermostat: on a piece with equilibrium B (heating: 10 + p/k,
/// cooling: 10) temp(s) = B + (T₀ − B) e^{−ks}; it reaches the threshold θ* at
/// s = ln((T₀ − B)/(θ* − B))/k; over a piece of length L, with c = B − 20, d = T₀ − B:
/// ∫temp = B L + d (1 − e^{−kL})/k, ∫(temp − 20)² = c² L + 2cd(1 − e^{−kL})/k + d²(1 − e^{−2kL})/(2k).
fn thermostat_closed<S: Sc>(k: S, lo: S, hi: S, p: S, t_end: f64) -> (S, S, usize) {
    let (mut t0, mut temp, mut heating) = (S::cst(0.0), S::cst(19.0), true);
    let (mut c1, mut c2, mut events) = (S::cst(0.0), S::cst(0.0), 0);
    loop {
        let b = if heating { p / k + 10.0 } else { S::cst(10.0) };
        let target = if heating { hi } else { lo };
        let s = ((temp - b) / (target - b)).ln() / k;
        let last = (t0 + s).val() >= t_end;
        let l = if last { -(t0 - t_end) } else { s };
        let (c, d) = (b - 20.0, temp - b);
        let e1 = -((-(k * l)).exp()) + 1.0;
        let e2 = -((-(k * l * 2.0)).exp()) + 1.0;
        c1 = c1 + b * l + d * e1 / k;
        c2 = c2 + c * c * l + c * d * e1 * 2.0 / k + d * d * e2 / (k * 2.0);
        if last {
            return (c1, c2, events);
        }
        t0 = t0 + s;
        temp = target;
        heating = !heating;
        events += 1;
    }
}

#[test]
fn thermostat_closed_form_all_params() {
    let p = [0.5, 18.0, 22.0, 10.0];
    let d = |i: usize| D::var(p[i], i);
    let (c1, c2, nev) = thermostat_closed(d(0), d(1), d(2), d(3), 10.0);
    // The closed form against central differences of itself.
    let pv = DVector::from_column_slice(&p);
    for i in 0..4 {
        let f = |q: &DVector<f64>| thermostat_closed(q[0], q[1], q[2], q[3], 10.0).1;
        let fd = common::central(f, &pv, i, 1e-6);
        assert!(
            close(fd, c2.g[i], 1e-6, 1e-7),
            "param {i}: fd {fd} dual {}",
            c2.g[i]
        );
    }
    for (squared, c) in [(false, c1), (true, c2)] {
        let m = AdModel::new(Thermostat { squared });
        // Exponential segments: S is put under error control too (the default controls x and
        // q only, which leaves S at ~1e-9 relative here).
        let opts = Options {
            sens_error_control: true,
            ..tight()
        };
        let sol = solve(&m, &pv, &opts).unwrap();
        assert_eq!(sol.events.len(), nev);
        assert!(
            close(sol.cost, c.v, 1e-9, 1e-12),
            "cost {} want {}",
            sol.cost,
            c.v
        );
        assert_grad(
            &format!("thermostat squared={squared}"),
            &sol.gradient,
            &c.g[..4],
            1e-9,
            1e-11,
        );
        assert_eq!(sol.mode_final, if nev % 2 == 0 { 0 } else { 1 });
    }
}

/// Stiff relay: a first-order lag u̇ = (w − u)/τ, τ = 1e-8, w = +a (mode `up`) or −a (`down`),
/// drives a slow state ẋ = u between thresholds lo < hi (θ = a, lo, hi); x(0) = 0.5, u(0) = 0.
struct Relay;

const TAU: f64 = 1e-8;

impl Spec for Relay {
    fn info(&self) -> ModelInfo {
        let mut i = info(
            "StiffRelay",
            &["u", "x"],
            &[("a", 1.0), ("lo", 0.2), ("hi", 1.0)],
            &["up", "down"],
            vec![
                ev("top", Direction::Up, Some(0), Some(1), false),
                ev("bottom", Direction::Down, Some(1), Some(0), false),
            ],
            &["x"],
            0,
        );
        i.has_final_cost = false;
        i
    }
    fn x0<S: Sc>(&self, _p: &[S], x: &mut [S]) {
        x[0] = S::cst(0.0);
        x[1] = S::cst(0.5);
    }
    fn horizon<S: Sc>(&self, _p: &[S]) -> Option<S> {
        Some(S::cst(3.0))
    }
    fn rhs<S: Sc>(&self, m: usize, _sw: Switches, _t: S, x: &[S], p: &[S], f: &mut [S]) {
        let w = if m == 0 { p[0] } else { -p[0] };
        f[0] = (w - x[0]) / TAU;
        f[1] = x[0];
    }
    fn guard<S: Sc>(&self, k: usize, _t: S, x: &[S], p: &[S]) -> S {
        if k == 0 {
            x[1] - p[2]
        } else {
            x[1] - p[1]
        }
    }
    fn observe<S: Sc>(&self, _t: S, x: &[S], _p: &[S], y: &mut [S]) {
        y[0] = x[1];
    }
    fn running<S: Sc>(&self, _sw: Switches, _t: S, x: &[S], _p: &[S]) -> S {
        x[1]
    }
}

/// Closed form of the relay: on a piece with input w from (u_s, x_s),
/// u = w + (u_s − w) e^{−s/τ}, x = x_s + w s + (u_s − w) τ (1 − e^{−s/τ}); the threshold x*
/// is reached at s = (x* − x_s − (u_s − w) τ)/w (e^{−s/τ} underflows to 0 for s ≫ τ; checked),
/// and ∫x over a piece of length L = x_s L + w L²/2 + (u_s − w) τ (L − τ (1 − e^{−L/τ})).
fn relay_closed<S: Sc>(a: S, lo: S, hi: S, t_end: f64) -> (S, usize) {
    let (mut t0, mut u, mut x, mut up) = (S::cst(0.0), S::cst(0.0), S::cst(0.5), true);
    let (mut c, mut n) = (S::cst(0.0), 0);
    loop {
        let w = if up { a } else { -a };
        let target = if up { hi } else { lo };
        let s = (target - x - (u - w) * TAU) / w;
        assert!((-s.val() / TAU).exp() == 0.0);
        let last = (t0 + s).val() >= t_end;
        let l = if last { -(t0 - t_end) } else { s };
        let decay = -((-(l / TAU)).exp()) + 1.0;
        c = c + x * l + w * l * l / 2.0 + (u - w) * TAU * (l - decay * TAU);
        if last {
            return (c, n);
        }
        t0 = t0 + s;
        x = target;
        u = w;
        up = !up;
        n += 1;
    }
}

#[test]
fn stiff_relay_auto() {
    let p = [1.0, 0.2, 1.0];
    let d = |i: usize| D::var(p[i], i);
    let (c, nev) = relay_closed(d(0), d(1), d(2), 3.0);
    let m = AdModel::new(Relay);
    let opts = Options {
        rtol: 1e-8,
        atol: 1e-10,
        ..Options::default()
    };
    let start = std::time::Instant::now();
    let sol = solve(&m, &DVector::from_column_slice(&p), &opts).unwrap();
    let wall = start.elapsed().as_secs_f64();
    eprintln!(
        "relay: {} steps, {} rejected, {:.3} s, cost {} want {}",
        sol.stats.steps, sol.stats.rejected_steps, wall, sol.cost, c.v
    );
    assert_eq!(sol.events.len(), nev);
    assert!(sol.stats.steps < 5000, "{} steps", sol.stats.steps);
    assert!(close(sol.cost, c.v, 1e-6, 0.0));
    assert_grad("relay", &sol.gradient, &c.g[..3], 1e-6, 1e-9);
}

/// A ball thrown up under a ceiling at height H (θ = e, g, h0, v0, H): event `ceiling` when
/// h ≥ H, v⁺ = −e v⁻; horizon 1 s (no floor reached). As H approaches the apex
/// h0 + v0²/(2g) the impact grazes.
struct Ceiling;

impl Spec for Ceiling {
    fn info(&self) -> ModelInfo {
        let mut i = info(
            "Ceiling",
            &["h", "v"],
            &[
                ("e", 0.8),
                ("g", 9.81),
                ("h0", 1.0),
                ("v0", 3.0),
                ("H", 1.4),
            ],
            &["main"],
            vec![ev("ceiling", Direction::Up, None, None, false)],
            &["height"],
            0,
        );
        i.has_final_cost = false;
        i
    }
    fn x0<S: Sc>(&self, p: &[S], x: &mut [S]) {
        x[0] = p[2];
        x[1] = p[3];
    }
    fn horizon<S: Sc>(&self, _p: &[S]) -> Option<S> {
        Some(S::cst(0.6))
    }
    fn rhs<S: Sc>(&self, _m: usize, _sw: Switches, _t: S, x: &[S], p: &[S], f: &mut [S]) {
        f[0] = x[1];
        f[1] = -p[1];
    }
    fn guard<S: Sc>(&self, _k: usize, _t: S, x: &[S], p: &[S]) -> S {
        x[0] - p[4]
    }
    fn reset<S: Sc>(&self, _k: usize, _t: S, x: &[S], p: &[S], xp: &mut [S]) {
        xp[0] = x[0];
        xp[1] = -(p[0] * x[1]);
    }
    fn observe<S: Sc>(&self, _t: S, x: &[S], _p: &[S], y: &mut [S]) {
        y[0] = x[0];
    }
    fn running<S: Sc>(&self, _sw: Switches, _t: S, x: &[S], _p: &[S]) -> S {
        x[0]
    }
}

/// Closed form: impact at t_c = (v0 − √(v0² − 2g(H − h0)))/g with v_c = v0 − g t_c > 0,
/// then h = H − e v_c s − g s²/2 on [t_c, T]; C = ∫h dt.
fn ceiling_closed<S: Sc>(e: S, g: S, h0: S, v0: S, hh: S, t_end: f64) -> (S, S, S) {
    let root = (v0 * v0 - g * (hh - h0) * 2.0).sqrt();
    let tc = (v0 - root) / g;
    let vc = v0 - g * tc;
    let l = -(tc - t_end);
    let u = -(e * vc);
    let c = h0 * tc + v0 * tc * tc / 2.0 - g * tc * tc * tc / 6.0 + hh * l + u * l * l / 2.0
        - g * l * l * l / 6.0;
    (c, tc, vc)
}

#[test]
fn ceiling_approaching_grazing() {
    // Apex of h0 = 1, v0 = 3: 1 + 9/(2·9.81).
    let apex = 1.0 + 9.0 / (2.0 * 9.81);
    for (gap, rel) in [(1e-1, 1e-9), (1e-3, 1e-8), (1e-5, 1e-7), (1e-7, 1e-5)] {
        let p = [0.8, 9.81, 1.0, 3.0, apex - gap];
        let d = |i: usize| D::var(p[i], i);
        let (c, tc, vc) = ceiling_closed(d(0), d(1), d(2), d(3), d(4), 0.6);
        let m = AdModel::new(Ceiling);
        let sol = solve(&m, &DVector::from_column_slice(&p), &tight()).unwrap();
        assert_eq!(sol.events.len(), 1, "gap {gap}");
        let evr = &sol.events[0];
        assert!(
            close(evr.t, tc.v, 1e-9, 0.0),
            "gap {gap}: t {} vs {}",
            evr.t,
            tc.v
        );
        assert!(
            close(evr.guard_slope, vc.v, rel, 1e-12),
            "gap {gap}: slope {} vs {}",
            evr.guard_slope,
            vc.v
        );
        let grazing = sol
            .diagnostics
            .iter()
            .any(|d| d.kind == DiagnosticKind::Grazing);
        // |∇g·f| = v_c against τ |∇g| |f| = 1e-3 √(v_c² + g²).
        assert_eq!(
            grazing,
            vc.v < 1e-3 * (vc.v * vc.v + 9.81 * 9.81).sqrt(),
            "gap {gap}"
        );
        assert_eq!(evr.transversal, !grazing);
        assert!(close(sol.cost, c.v, 1e-9, 1e-12));
        assert_grad(
            &format!("ceiling gap {gap}"),
            &sol.gradient,
            &c.g[..5],
            rel,
            1e-9,
        );
        assert_grad(
            &format!("ceiling t' gap {gap}"),
            &evr.dt,
            &tc.g[..5],
            rel,
            1e-9,
        );
    }
}

/// A kink in the flow: ẋ = −|x − c| − 1 and ℓ = x + |x − c| (θ = x0, c), x0 = 1.5, c = 0.5,
/// T = 2. With y = x − c: ẏ = −y − 1 until y = 0 at t* = ln(y0 + 1), then ẏ = y − 1:
/// y = (y0 + 1)e^{−t} − 1 before, y = 1 − e^{t − t*} after.
struct Kink;

impl Spec for Kink {
    fn info(&self) -> ModelInfo {
        let mut i = info(
            "Kink",
            &["x"],
            &[("x0", 1.5), ("c", 0.5)],
            &["main"],
            vec![],
            &["x"],
            1,
        );
        i.has_final_cost = false;
        i
    }
    fn x0<S: Sc>(&self, p: &[S], x: &mut [S]) {
        x[0] = p[0];
    }
    fn horizon<S: Sc>(&self, _p: &[S]) -> Option<S> {
        Some(S::cst(2.0))
    }
    fn switch<S: Sc>(&self, _j: usize, _t: S, x: &[S], p: &[S]) -> S {
        x[0] - p[1]
    }
    fn rhs<S: Sc>(&self, _m: usize, sw: Switches, _t: S, x: &[S], p: &[S], f: &mut [S]) {
        let y = x[0] - p[1];
        let abs = if sw & 1 != 0 { y } else { -y };
        f[0] = -abs - 1.0;
    }
    fn observe<S: Sc>(&self, _t: S, x: &[S], _p: &[S], y: &mut [S]) {
        y[0] = x[0];
    }
    fn running<S: Sc>(&self, sw: Switches, _t: S, x: &[S], p: &[S]) -> S {
        let y = x[0] - p[1];
        let abs = if sw & 1 != 0 { y } else { -y };
        x[0] + abs
    }
}

#[test]
fn switch_crossing_of_abs_in_flow_and_cost() {
    let p = [1.5, 0.5];
    let (x0, c) = (D::var(p[0], 0), D::var(p[1], 1));
    let y0 = x0 - c;
    let ts = (y0 + 1.0).ln();
    let t_end = 2.0;
    // ∫y: before (y0+1)(1 − e^{−t*}) − t*, after (T − t*) − (e^{T − t*} − 1).
    let int_before = (y0 + 1.0) * (-((-ts).exp()) + 1.0) - ts;
    let int_after = -(ts - t_end) - ((-(ts - t_end)).exp() - 1.0);
    // ∫x = cT + ∫y; ∫|y| = ∫_before y − ∫_after y.
    let want = c * t_end + int_before + int_after + int_before - int_after;
    let m = AdModel::new(Kink);
    let sol = solve(
        &m,
        &DVector::from_column_slice(&p),
        &Options {
            sens_error_control: true,
            ..tight()
        },
    )
    .unwrap();
    assert_eq!(sol.stats.switch_crossings, 1);
    assert!(sol.events.is_empty());
    assert!(
        close(sol.cost, want.v, 1e-9, 0.0),
        "{} vs {}",
        sol.cost,
        want.v
    );
    assert_grad("kink", &sol.gradient, &want.g[..2], 1e-9, 1e-11);
    let fd =
        mvad_runtime::fd::fd_full_gradient(&m, &DVector::from_column_slice(&p), &tight(), 1e-6)
            .unwrap();
    assert_grad("kink fd", &fd, &want.g[..2], 1e-6, 1e-8);
}
