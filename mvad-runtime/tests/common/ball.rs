//! THE test ball, once: ḣ = v, v̇ = −g, an impact when h reaches the floor (h ≤ 0) or a
//! ceiling (h ≥ H), v⁺ = −e v⁻, with the costs the tests use; and its closed forms
//! (parabolic flights, the Zeno series, a ceiling bounce). θ = (e, g, h0, v0), plus H for a
//! ceiling; with a parameter horizon θ3 is T instead of v0 (and v0 = 0).

use super::{ev, info, Sc, Spec};
use mvad_runtime::model::{Direction, ModelInfo};

/// The cost of a [`BallSpec`] run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BallCost {
    /// ∫h dt.
    IntH,
    /// ∫v dt.
    IntV,
    /// ∫h² dt.
    IntH2,
    /// v(T).
    FinalV,
    /// Σ v⁺² over the impacts.
    SumVplus2,
    /// ∫φ(t) h dt with the test function [`phi`].
    Weighted,
    /// Every kind at once: ∫(h² + t v) dt + Σ v⁺ t e + h(T) v(T) + T².
    Mixed,
}

impl BallCost {
    /// The five costs that E1's closed form gives ([`flights`], indexed by the
    /// discriminant).
    pub const CLOSED_FORM: [BallCost; 5] = [
        BallCost::IntH,
        BallCost::IntV,
        BallCost::IntH2,
        BallCost::FinalV,
        BallCost::SumVplus2,
    ];
}

/// Which surface the ball bounces off.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Wall {
    /// The floor h = 0, hit going down.
    Floor,
    /// A ceiling h = θ4, hit going up.
    Ceiling,
}

/// The ball as a generic formula (see the module docs).
#[derive(Clone, Debug)]
pub struct BallSpec {
    /// The cost.
    pub cost: BallCost,
    /// The horizon; `None`: T = θ3 (and v0 = 0).
    pub t_end: Option<f64>,
    /// Default parameters.
    pub defaults: Vec<f64>,
    /// Floor or ceiling.
    pub wall: Wall,
    /// The reset puts the ball exactly on the floor (h⁺ = 0) instead of h⁺ = h⁻.
    pub land_on_zero: bool,
}

impl BallSpec {
    /// The E1 ball (e, g, h0, v0) = (0.8, 9.81, 2, 0) with cost `cost` and horizon `t_end`.
    pub fn new(cost: BallCost, t_end: f64) -> Self {
        BallSpec {
            cost,
            t_end: Some(t_end),
            defaults: vec![0.8, 9.81, 2.0, 0.0],
            wall: Wall::Floor,
            land_on_zero: false,
        }
    }
    /// ∫h dt over [0, T] with restitution `e`.
    pub fn int_h(t_end: f64, e: f64) -> Self {
        Self::new(BallCost::IntH, t_end).defaults(&[e, 9.81, 2.0, 0.0])
    }
    /// With other default parameters.
    pub fn defaults(mut self, p: &[f64]) -> Self {
        self.defaults = p.to_vec();
        self
    }
    /// Thrown up from h0 = 1 at v0 = 3 under a ceiling at H = 1.4 (θ4), T = 0.6, ∫h dt:
    /// one impact; as H approaches the apex h0 + v0²/(2g) the impact grazes.
    pub fn ceiling() -> Self {
        BallSpec {
            cost: BallCost::IntH,
            t_end: Some(0.6),
            defaults: vec![0.8, 9.81, 1.0, 3.0, 1.4],
            wall: Wall::Ceiling,
            land_on_zero: false,
        }
    }
    /// T = θ3 = 1.9 and every kind of cost ([`BallCost::Mixed`]), dropped at rest.
    pub fn param_horizon() -> Self {
        BallSpec {
            cost: BallCost::Mixed,
            t_end: None,
            defaults: vec![0.8, 9.81, 2.0, 1.9],
            wall: Wall::Floor,
            land_on_zero: false,
        }
    }
}

/// The weight of [`BallCost::Weighted`]: φ(t) = sin 3t + t²/2 − 0.2.
pub fn phi(t: f64) -> f64 {
    (3.0 * t).sin() + 0.5 * t * t - 0.2
}

impl Spec for BallSpec {
    fn info(&self) -> ModelInfo {
        let last = if self.t_end.is_some() { "v0" } else { "T" };
        let names = ["e", "g", "h0", last, "H"];
        let params: Vec<(&str, f64)> = names.iter().copied().zip(self.defaults.clone()).collect();
        let (event, dir) = match self.wall {
            Wall::Floor => ("impact", Direction::Down),
            Wall::Ceiling => ("ceiling", Direction::Up),
        };
        let event_cost = matches!(self.cost, BallCost::SumVplus2 | BallCost::Mixed);
        let mut i = info(
            "Ball",
            &["h", "v"],
            &params,
            &["main"],
            vec![ev(event, dir, None, None, event_cost)],
            &["height", "velocity"],
            0,
        );
        i.has_running_cost = !matches!(self.cost, BallCost::FinalV | BallCost::SumVplus2);
        i.has_final_cost = matches!(self.cost, BallCost::FinalV | BallCost::Mixed);
        i
    }
    fn x0<S: Sc>(&self, p: &[S], x: &mut [S]) {
        x[0] = p[2];
        x[1] = if self.t_end.is_some() {
            p[3]
        } else {
            S::cst(0.0)
        };
    }
    fn horizon<S: Sc>(&self, p: &[S]) -> Option<S> {
        Some(self.t_end.map_or(p[3], S::cst))
    }
    fn rhs<S: Sc>(&self, _m: usize, _sw: u64, _t: S, x: &[S], p: &[S], f: &mut [S]) {
        f[0] = x[1];
        f[1] = -p[1];
    }
    fn guard<S: Sc>(&self, _k: usize, _t: S, x: &[S], p: &[S]) -> S {
        match self.wall {
            Wall::Floor => x[0],
            Wall::Ceiling => x[0] - p[4],
        }
    }
    fn reset<S: Sc>(&self, _k: usize, _t: S, x: &[S], p: &[S], xp: &mut [S]) {
        xp[0] = if self.land_on_zero { S::cst(0.0) } else { x[0] };
        xp[1] = -(p[0] * x[1]);
    }
    fn observe<S: Sc>(&self, _t: S, x: &[S], _p: &[S], y: &mut [S]) {
        y[0] = x[0];
        y[1] = x[1];
    }
    fn running<S: Sc>(&self, _sw: u64, t: S, x: &[S], _p: &[S]) -> S {
        match self.cost {
            BallCost::IntH => x[0],
            BallCost::IntV => x[1],
            BallCost::IntH2 => x[0] * x[0],
            BallCost::Weighted => ((t * 3.0).sin() + t * t * 0.5 - 0.2) * x[0],
            BallCost::Mixed => x[0] * x[0] + t * x[1],
            BallCost::FinalV | BallCost::SumVplus2 => S::cst(0.0),
        }
    }
    fn event_cost<S: Sc>(&self, _k: usize, t: S, x: &[S], p: &[S]) -> S {
        match self.cost {
            BallCost::SumVplus2 => x[1] * x[1],
            BallCost::Mixed => x[1] * t * p[0],
            _ => S::cst(0.0),
        }
    }
    fn final_cost<S: Sc>(&self, t: S, x: &[S], _p: &[S]) -> S {
        match self.cost {
            BallCost::FinalV => x[1],
            BallCost::Mixed => x[0] * x[1] + t * t,
            _ => S::cst(0.0),
        }
    }
}

/// Closed form of the floor ball on [0, T] (flights are parabolas): returns
/// [∫h, ∫v, ∫h², v(T), Σ v⁺²] (indexed by [`BallCost`] up to `SumVplus2`) and the impact
/// times. A flight from height a with launch velocity u has h(s) = a + u s − g s²/2 and
/// lands at s = (u + √(u² + 2ga))/g, where v⁻ = u − g s and v⁺ = −e v⁻; over a piece of
/// length L: ∫h = aL + uL²/2 − gL³/6,  ∫v = uL − gL²/2,
///   ∫h² = a²L + a u L² + (u² − a g) L³/3 − u g L⁴/4 + g² L⁵/20.
pub fn flights<S: Sc>(e: S, g: S, h0: S, v0: S, t_end: f64) -> ([S; 5], Vec<f64>) {
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

/// Exact series for ∫h dt when T is past the accumulation time t*: first fall
/// h0 t1 + v0 t1²/2 − g t1³/6 (t1 = (v0 + V)/g, V = √(v0² + 2 g h0)), then hops with launch
/// speeds eᵏV, each contributing (2/3) u³/g², summed: (2/3) V³ e³ /(g² (1 − e³));
/// t* = t1 + 2 e V /(g (1 − e)). Returns (C, t*).
pub fn zeno_series<S: Sc>(e: S, g: S, h0: S, v0: S) -> (S, S) {
    let v = (v0 * v0 + g * h0 * 2.0).sqrt();
    let t1 = (v0 + v) / g;
    let e3 = e * e * e;
    let c = h0 * t1 + v0 * t1 * t1 / 2.0 - g * t1 * t1 * t1 / 6.0
        + v * v * v * e3 * (2.0 / 3.0) / (g * g * (-e3 + 1.0));
    let t_star = t1 + e * v * 2.0 / (g * (-e + 1.0));
    (c, t_star)
}

/// The ceiling ball: impact at t_c = (v0 − √(v0² − 2g(H − h0)))/g with v_c = v0 − g t_c > 0,
/// then h = H − e v_c s − g s²/2 on [t_c, T]; returns (C = ∫h dt, t_c, v_c).
pub fn ceiling_closed<S: Sc>(e: S, g: S, h0: S, v0: S, hh: S, t_end: f64) -> (S, S, S) {
    let root = (v0 * v0 - g * (hh - h0) * 2.0).sqrt();
    let tc = (v0 - root) / g;
    let vc = v0 - g * tc;
    let l = -(tc - t_end);
    let u = -(e * vc);
    let c = h0 * tc + v0 * tc * tc / 2.0 - g * tc * tc * tc / 6.0 + hh * l + u * l * l / 2.0
        - g * l * l * l / 6.0;
    (c, tc, vc)
}

/// The launch from the floor at v0 (h0 = 0): impact times of hops 2u/g, u ← e u, before T.
pub fn hops(e: f64, g: f64, v0: f64, t_end: f64) -> Vec<f64> {
    let (mut t, mut u, mut out) = (0.0, v0, Vec::new());
    loop {
        t += 2.0 * u / g;
        if t >= t_end {
            return out;
        }
        out.push(t);
        u *= e;
    }
}
