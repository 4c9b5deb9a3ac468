//! The example models of mvad, through both doors: each is a `.hyb` file in `models/`
//! (loaded at run time by `mvad::load` and the `mvad` command line) and, compiled by
//! `mvad::hybrid!(include "…")`, a Rust type in the module of the same name, next to
//! closed-form reference solutions derived by hand.
//!
//! | module | model | what it exercises |
//! |---|---|---|
//! | [`bouncing_ball`] | the seed paper's E1 | atoms at impacts, dC/de = 2.8314408141470055 |
//! | [`e2_sweep`] | the seed paper's E2 | transversality sweep over v0, no atom in position |
//! | [`thermostat`] | two modes, parameter thresholds | mode switches, exponentials |
//! | [`stiff_relay`] | lag with τ = 1e-8 | stiffness (`--method auto`) |
//! | [`zeno_ball`] | e = 0.5 to T = 3 | Zeno accumulation, tail of the series |
//! | [`ceiling`] | near-grazing impact | t' ∝ 1/√(apex − c) |
//! | [`queue`] | the seed paper's E4, a FIFO queue | `at each` table events, 10³–10⁷ customers |
//! | [`qp_kink`] | the seed paper's E3 | a static qp, its kink at θ = 0, no states |
//! | [`generated`] | impact and chain with p parameters | adjoint cost against p (`benches/adjoint.rs`) |
//! | [`qp_cart`] | a saturating qp controller, a wall | a qp in the flow, its active-set changes as kinks |
//!
//! [`paper`] holds the numbers the seed paper printed (Tables 1 and 2), which the
//! examples `table1` and `table2` print beside ours.

/// A test's prologue: `(m, p, sol)`, the model `$model::new()` solved at its declared
/// parameters `p = $params::default()` with [`tolerances`]`(rtol, atol)`.
#[cfg(test)]
macro_rules! solved_at_defaults {
    ($model:ident, $params:ident, $rtol:expr, $atol:expr) => {{
        let m = $model::new();
        let p = $params::default();
        let opts = $crate::tolerances($rtol, $atol);
        let sol = mvad::solve::solve(&m, &p.to_vector(), &opts).expect("runs");
        (m, p, sol)
    }};
}

pub mod bouncing_ball;
pub mod ceiling;
pub mod e2_sweep;
pub mod generated;
pub mod paper;
pub mod qp_cart;
pub mod qp_kink;
pub mod queue;
pub mod stiff_relay;
pub mod thermostat;
pub mod zeno_ball;

/// The `.hyb` sources, by file name (for tests that load them at run time).
pub const SOURCES: [(&str, &str); 8] = [
    ("bouncing_ball.hyb", include_str!("../bouncing_ball.hyb")),
    ("e2_sweep.hyb", include_str!("../e2_sweep.hyb")),
    ("thermostat.hyb", include_str!("../thermostat.hyb")),
    ("stiff_relay.hyb", include_str!("../stiff_relay.hyb")),
    ("zeno_ball.hyb", include_str!("../zeno_ball.hyb")),
    ("ceiling.hyb", include_str!("../ceiling.hyb")),
    ("qp_kink.hyb", include_str!("../qp_kink.hyb")),
    ("qp_cart.hyb", include_str!("../qp_cart.hyb")),
];

/// Default options but for the tolerances (rtol, atol): the reference runs of the tests,
/// the examples and the benchmark.
pub fn tolerances(rtol: f64, atol: f64) -> mvad::solution::Options {
    mvad::solution::Options {
        rtol,
        atol,
        ..Default::default()
    }
}

/// A ball under gravity g with restitution e on a floor at h = 0, from (h0, v0): the
/// cost ∫₀ᵀ h dt and the impact times, in closed form.
///
/// Between impacts h(s) = h + v s − g s²/2, the next impact after
/// s = (v + √(v² + 2 g h)) / g with v⁻ = v − g s, v⁺ = −e v⁻; each flight contributes
/// h s + v s²/2 − g s³/6. For e < 1 the impacts accumulate at a finite time t*, after
/// which the ball rests (h = 0): the loop stops once the flights are shorter than
/// 1e-16·t (their geometric tail is below rounding).
pub fn ball_closed_form(e: f64, g: f64, h0: f64, v0: f64, t_end: f64) -> (f64, Vec<f64>) {
    let (mut t, mut h, mut v, mut cost) = (0.0f64, h0, v0, 0.0);
    let mut impacts = Vec::new();
    for _ in 0..100_000 {
        let s = (v + (v * v + 2.0 * g * h).max(0.0).sqrt()) / g;
        if t + s >= t_end {
            let s = t_end - t;
            cost += h * s + v * s * s / 2.0 - g * s * s * s / 6.0;
            return (cost, impacts);
        }
        cost += h * s + v * s * s / 2.0 - g * s * s * s / 6.0;
        t += s;
        impacts.push(t);
        v = -e * (v - g * s);
        h = 0.0;
        if s <= 1e-16 * t && impacts.len() > 2 {
            break; // accumulated: at rest from here on
        }
    }
    (cost, impacts)
}

/// Median over 15 batches of the mean time per call of `f`, in µs, each batch sized to
/// ~20 ms (for the benches and examples that print timing tables; robust on a shared machine).
pub fn median_us<R>(mut f: impl FnMut() -> R) -> f64 {
    let mut batch = 200usize;
    // Size the batch to ~20 ms.
    loop {
        let t = std::time::Instant::now();
        for _ in 0..batch {
            std::hint::black_box(f());
        }
        if t.elapsed().as_secs_f64() > 0.02 || batch > 1_000_000 {
            break;
        }
        batch *= 2;
    }
    let mut v: Vec<f64> = (0..15)
        .map(|_| {
            let t = std::time::Instant::now();
            for _ in 0..batch {
                std::hint::black_box(f());
            }
            t.elapsed().as_secs_f64() * 1e6 / batch as f64
        })
        .collect();
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Derivative of `f` at `x`: [`derivative`] with a first step of 1e-2·max(1, |x|).
pub fn central(f: impl Fn(f64) -> f64, x: f64) -> f64 {
    derivative(f, x, 1e-2 * x.abs().max(1.0))
}

/// Derivative of `f` at `x` by Ridders' extrapolation of central differences: the
/// differences D(h) = (f(x + h) − f(x − h)) / 2h for h = h0, h0/1.4, h0/1.4², … are
/// extrapolated to h → 0 in a Neville tableau (the error is even in h), keeping the
/// entry whose change from its neighbours is smallest; it stops when the error estimate
/// grows again (rounding). Typically 1e-11 relative or better for smooth `f`, provided
/// `f` is smooth on [x − h0, x + h0]. Used to differentiate the closed forms here.
pub fn derivative(f: impl Fn(f64) -> f64, x: f64, h0: f64) -> f64 {
    const SHRINK: f64 = 1.4;
    const LEVELS: usize = 12;
    let d = |h: f64| (f(x + h) - f(x - h)) / (2.0 * h);
    let mut tab = [[0.0f64; LEVELS]; LEVELS];
    let mut h = h0;
    tab[0][0] = d(h);
    let (mut best, mut err) = (tab[0][0], f64::INFINITY);
    for i in 1..LEVELS {
        h /= SHRINK;
        tab[0][i] = d(h);
        let mut fac = SHRINK * SHRINK;
        for j in 1..=i {
            tab[j][i] = (tab[j - 1][i] * fac - tab[j - 1][i - 1]) / (fac - 1.0);
            fac *= SHRINK * SHRINK;
            let e = (tab[j][i] - tab[j - 1][i])
                .abs()
                .max((tab[j][i] - tab[j - 1][i - 1]).abs());
            if e <= err {
                err = e;
                best = tab[j][i];
            }
        }
        if (tab[i][i] - tab[i - 1][i - 1]).abs() >= 2.0 * err {
            break;
        }
    }
    best
}

/// A model through both doors with the same θ: compiled by `hybrid!` (static sizes) and its
/// `.hyb` file loaded at run time (interpreted, `Dyn` sizes), as the benches time them.
pub struct BothDoors<M, const P: usize> {
    /// The compiled model.
    pub compiled: M,
    /// θ for the compiled model.
    pub p: nalgebra::SVector<f64, P>,
    /// The same model loaded from its file.
    pub loaded: mvad::interp::InterpretedModel,
    /// θ for the loaded model (the same values).
    pub pl: nalgebra::DVector<f64>,
}

impl<M, const P: usize> BothDoors<M, P> {
    /// `compiled` at θ = `p`, and `models/FILE` loaded (panics, naming the file, when it
    /// does not load: a bench cannot run without it).
    pub fn new(compiled: M, p: nalgebra::SVector<f64, P>, file: &str) -> Self {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(file);
        let loaded = mvad::load::load(&path).unwrap_or_else(|e| panic!("{file}: {e:?}"));
        BothDoors {
            compiled,
            pl: nalgebra::DVector::from_column_slice(p.as_slice()),
            p,
            loaded,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn the_closed_form_ball_gives_the_design_reference() {
        let (c, t) = ball_closed_form(0.8, 9.81, 2.0, 0.0, 2.0);
        assert_relative_eq!(c, bouncing_ball::COST, max_relative = 1e-14);
        assert_relative_eq!(t[0], bouncing_ball::IMPACT_TIMES[0], max_relative = 1e-14);
        assert_relative_eq!(t[1], bouncing_ball::IMPACT_TIMES[1], max_relative = 1e-14);
        let d = central(|e| ball_closed_form(e, 9.81, 2.0, 0.0, 2.0).0, 0.8);
        assert_relative_eq!(d, bouncing_ball::DCOST_DE, max_relative = 1e-9);
    }

    #[test]
    fn ridders_derivative_of_known_functions() {
        assert_relative_eq!(central(f64::exp, 1.0), 1f64.exp(), max_relative = 1e-12);
        assert_relative_eq!(
            central(|x| x.sin(), 0.3),
            0.3f64.cos(),
            max_relative = 1e-12
        );
        assert_relative_eq!(
            derivative(|x| (x - 1.0).sqrt(), 1.01, 1e-3),
            0.5 / 0.01f64.sqrt(),
            max_relative = 1e-9
        );
    }

    #[test]
    fn every_source_loads() {
        for (name, src) in SOURCES {
            mvad::load::load_str(name, src).unwrap_or_else(|e| panic!("{e}"));
        }
    }
}
