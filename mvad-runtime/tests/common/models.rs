//! The test models other than the ball, as generic formulas, with their closed forms:
//! a thermostat, a stiff relay, a kink in the flow, a dip (double crossing), twin events
//! on one guard and a decay without parameters.

use super::{ev, info, Sc, Spec};
use mvad_runtime::model::{Direction, EventInfo, ModelInfo};

/// The two events of a relay with hysteresis between modes 0 and 1: `up` fires when the
/// watched value rises through the upper threshold in mode 0 (→ mode 1), `down` when it
/// falls through the lower one in mode 1 (→ mode 0).
fn hysteresis_events(up: &str, down: &str) -> Vec<EventInfo> {
    vec![
        ev(up, Direction::Up, Some(0), Some(1), false),
        ev(down, Direction::Down, Some(1), Some(0), false),
    ]
}

/// The guards of [`hysteresis_events`] on the watched value v: g₀ = v − hi, g₁ = v − lo.
fn hysteresis_guard<S: Sc>(k: usize, v: S, lo: S, hi: S) -> S {
    if k == 0 {
        v - hi
    } else {
        v - lo
    }
}

/// Two-mode thermostat with thresholds lo, hi as parameters (θ = k, lo, hi, p), ambient 10,
/// temp(0) = 19, horizon 10.
#[derive(Clone)]
pub struct Thermostat {
    /// Cost ∫(temp − 20)² dt instead of ∫temp dt.
    pub squared: bool,
}

impl Spec for Thermostat {
    fn info(&self) -> ModelInfo {
        info(
            "Thermostat",
            &["temp"],
            &[("k", 0.5), ("lo", 18.0), ("hi", 22.0), ("p", 10.0)],
            &["heating", "cooling"],
            hysteresis_events("switch_off", "switch_on"),
            &["temp"],
            0,
        )
    }
    const X0: &'static [f64] = &[19.0];
    const T_END: Option<f64> = Some(10.0);
    fn rhs<S: Sc>(&self, m: usize, _sw: u64, _t: S, x: &[S], p: &[S], f: &mut [S]) {
        f[0] = -(p[0] * (x[0] - 10.0));
        if m == 0 {
            f[0] = f[0] + p[3];
        }
    }
    fn guard<S: Sc>(&self, k: usize, _t: S, x: &[S], p: &[S]) -> S {
        hysteresis_guard(k, x[0], p[1], p[2])
    }
    fn observe<S: Sc>(&self, _t: S, x: &[S], _p: &[S], y: &mut [S]) {
        y[0] = x[0];
    }
    fn running<S: Sc>(&self, _sw: u64, _t: S, x: &[S], _p: &[S]) -> S {
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
pub fn thermostat_closed<S: Sc>(k: S, lo: S, hi: S, p: S, t_end: f64) -> (S, S, usize) {
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

/// Stiff relay: a first-order lag u̇ = (w − u)/τ, τ = 1e-8, w = +a (mode `up`) or −a (`down`),
/// drives a slow state ẋ = u between thresholds lo < hi (θ = a, lo, hi); x(0) = 0.5, u(0) = 0.
#[derive(Clone)]
pub struct Relay;

pub const TAU: f64 = 1e-8;

impl Spec for Relay {
    fn info(&self) -> ModelInfo {
        info(
            "StiffRelay",
            &["u", "x"],
            &[("a", 1.0), ("lo", 0.2), ("hi", 1.0)],
            &["up", "down"],
            hysteresis_events("top", "bottom"),
            &["x"],
            0,
        )
    }
    const X0: &'static [f64] = &[0.0, 0.5];
    const T_END: Option<f64> = Some(3.0);
    fn rhs<S: Sc>(&self, m: usize, _sw: u64, _t: S, x: &[S], p: &[S], f: &mut [S]) {
        let w = if m == 0 { p[0] } else { -p[0] };
        f[0] = (w - x[0]) / TAU;
        f[1] = x[0];
    }
    fn guard<S: Sc>(&self, k: usize, _t: S, x: &[S], p: &[S]) -> S {
        hysteresis_guard(k, x[1], p[1], p[2])
    }
    fn observe<S: Sc>(&self, _t: S, x: &[S], _p: &[S], y: &mut [S]) {
        y[0] = x[1];
    }
    fn running<S: Sc>(&self, _sw: u64, _t: S, x: &[S], _p: &[S]) -> S {
        x[1]
    }
}

/// Closed form of the relay: on a piece with input w from (u_s, x_s),
/// u = w + (u_s − w) e^{−s/τ}, x = x_s + w s + (u_s − w) τ (1 − e^{−s/τ}); the threshold x*
/// is reached at s = (x* − x_s − (u_s − w) τ)/w (e^{−s/τ} underflows to 0 for s ≫ τ; checked),
/// and ∫x over a piece of length L = x_s L + w L²/2 + (u_s − w) τ (L − τ (1 − e^{−L/τ})).
pub fn relay_closed<S: Sc>(a: S, lo: S, hi: S, t_end: f64) -> (S, usize) {
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

/// A kink in the flow: ẋ = −|x − c| − 1 and ℓ = x + |x − c| (θ = x0, c), x0 = 1.5, c = 0.5,
/// T = 2. With y = x − c: ẏ = −y − 1 until y = 0 at t* = ln(y0 + 1), then ẏ = y − 1:
/// y = (y0 + 1)e^{−t} − 1 before, y = 1 − e^{t − t*} after.
#[derive(Clone)]
pub struct Kink;

impl Spec for Kink {
    fn info(&self) -> ModelInfo {
        info(
            "Kink",
            &["x"],
            &[("x0", 1.5), ("c", 0.5)],
            &["main"],
            vec![],
            &["x"],
            1,
        )
    }
    const T_END: Option<f64> = Some(2.0);
    fn x0<S: Sc>(&self, p: &[S], x: &mut [S]) {
        x[0] = p[0];
    }
    fn switch<S: Sc>(&self, _j: usize, _t: S, x: &[S], p: &[S]) -> S {
        x[0] - p[1]
    }
    fn rhs<S: Sc>(&self, _m: usize, sw: u64, _t: S, x: &[S], p: &[S], f: &mut [S]) {
        let y = x[0] - p[1];
        let abs = if sw & 1 != 0 { y } else { -y };
        f[0] = -abs - 1.0;
    }
    fn observe<S: Sc>(&self, _t: S, x: &[S], _p: &[S], y: &mut [S]) {
        y[0] = x[0];
    }
    fn running<S: Sc>(&self, sw: u64, _t: S, x: &[S], p: &[S]) -> S {
        let y = x[0] - p[1];
        let abs = if sw & 1 != 0 { y } else { -y };
        x[0] + abs
    }
}

/// ẋ = 1; events `enter` when (x − c)² − w² ≤ 0 and `leave` when ≥ 0: a dip of width 2w
/// that a coarse step straddles without any sign change at its samples.
#[derive(Clone)]
pub struct Dip;

impl Spec for Dip {
    fn info(&self) -> ModelInfo {
        info(
            "Dip",
            &["x"],
            &[("c", 0.5), ("w", 1e-3)],
            &["main"],
            vec![
                ev("enter", Direction::Down, None, None, false),
                ev("leave", Direction::Up, None, None, false),
            ],
            &["x"],
            0,
        )
    }
    const X0: &'static [f64] = &[0.0];
    const T_END: Option<f64> = Some(1.0);
    fn rhs<S: Sc>(&self, _m: usize, _sw: u64, _t: S, _x: &[S], _p: &[S], f: &mut [S]) {
        f[0] = S::cst(1.0);
    }
    fn guard<S: Sc>(&self, _k: usize, _t: S, x: &[S], p: &[S]) -> S {
        (x[0] - p[0]) * (x[0] - p[0]) - p[1] * p[1]
    }
    fn running<S: Sc>(&self, _sw: u64, _t: S, x: &[S], _p: &[S]) -> S {
        x[0]
    }
}

/// Two events on one guard at the same instant, fired in declaration order (a: y += u, then
/// b: y ×= v) and reported: x = t, y(0) = y0, C = ∫₀¹ y dt + y(1)², so y = y0 before c and
/// (y0 + u) v after, C = y0 c + (y0 + u) v (1 − c) + ((y0 + u) v)².
#[derive(Clone)]
pub struct Twin;

impl Spec for Twin {
    fn info(&self) -> ModelInfo {
        let mut i = info(
            "Twin",
            &["x", "y"],
            &[("c", 0.4), ("y0", 1.5), ("u", 0.7), ("v", 2.0)],
            &["main"],
            vec![
                ev("a", Direction::Up, None, None, false),
                ev("b", Direction::Up, None, None, false),
            ],
            &["y"],
            0,
        );
        i.has_final_cost = true;
        i
    }
    const T_END: Option<f64> = Some(1.0);
    fn x0<S: Sc>(&self, p: &[S], x: &mut [S]) {
        x[0] = S::cst(0.0);
        x[1] = p[1];
    }
    fn rhs<S: Sc>(&self, _m: usize, _sw: u64, _t: S, _x: &[S], _p: &[S], f: &mut [S]) {
        f[0] = S::cst(1.0);
        f[1] = S::cst(0.0);
    }
    fn guard<S: Sc>(&self, _k: usize, _t: S, x: &[S], p: &[S]) -> S {
        x[0] - p[0]
    }
    fn reset<S: Sc>(&self, k: usize, _t: S, x: &[S], p: &[S], xp: &mut [S]) {
        xp[0] = x[0];
        xp[1] = if k == 0 { x[1] + p[2] } else { x[1] * p[3] };
    }
    fn observe<S: Sc>(&self, _t: S, x: &[S], _p: &[S], y: &mut [S]) {
        y[0] = x[1];
    }
    fn running<S: Sc>(&self, _sw: u64, _t: S, x: &[S], _p: &[S]) -> S {
        x[1]
    }
    fn final_cost<S: Sc>(&self, _t: S, x: &[S], _p: &[S]) -> S {
        x[1] * x[1]
    }
}

/// A model without parameters: ẋ = −x from 1, event `half` at x = 1/2 halves x; C = ∫x dt.
#[derive(Clone)]
pub struct Decay;

impl Spec for Decay {
    fn info(&self) -> ModelInfo {
        info(
            "Decay",
            &["x"],
            &[],
            &["main"],
            vec![ev("half", Direction::Down, None, None, false)],
            &["x"],
            0,
        )
    }
    const X0: &'static [f64] = &[1.0];
    const T_END: Option<f64> = Some(2.0);
    fn rhs<S: Sc>(&self, _m: usize, _sw: u64, _t: S, x: &[S], _p: &[S], f: &mut [S]) {
        f[0] = -x[0];
    }
    fn guard<S: Sc>(&self, _k: usize, _t: S, x: &[S], _p: &[S]) -> S {
        x[0] - 0.5
    }
    fn reset<S: Sc>(&self, _k: usize, _t: S, x: &[S], _p: &[S], xp: &mut [S]) {
        xp[0] = x[0] * 0.5;
    }
    fn running<S: Sc>(&self, _sw: u64, _t: S, x: &[S], _p: &[S]) -> S {
        x[0]
    }
}
