//! The adjoint sweep's gradient quadrature under error control (issue 8): models whose λ is
//! smooth through a fast transient of the primal while the gradient integrand
//! G = −(λᵀf_θ + w ℓ_θ) is a spike there (a lag u with time constant τ: λ_u is quasi-steady,
//! G_τ = −λ_u ∂f_u/∂τ ~ 1/τ over a width τ). A step-size control that sees λ alone strides
//! over the spike and prints a wrong dC/dτ (the stiff relay's was off by 6.4e6 at rtol 1e-3);
//! with g's local error in the step acceptance every entry is within 10× rtol of the closed
//! form at every decade, through both doors, as forward mode is (issue 11).

use models::stiff_relay::{cost_closed, StiffRelay, StiffRelayParams};
use mvad::interp::InterpretedModel;
use mvad::runtime::fd::fd_gradient;
use mvad::{solve, GradientMode, HybridModel, ModelAlloc, Options};
use nalgebra::{DefaultAllocator, OVector};

mvad::hybrid!(include "tests/fast_lag.hyb");

mvad::hybrid!(include "tests/pulse_pair.hyb");

/// The pulse pair's source, for the loader.
const PULSE_PAIR: &str = include_str!("pulse_pair.hyb");

/// The fast lag's source, for the loader.
const FAST_LAG: &str = include_str!("fast_lag.hyb");

/// The relay's source (`models/stiff_relay.hyb`), for the loader.
const RELAY: &str = include_str!("../../models/stiff_relay.hyb");

/// The tolerances of the check: every other decade from 1e-3 to 1e-12.
const RTOLS: [f64; 6] = [1e-3, 1e-4, 1e-6, 1e-8, 1e-10, 1e-12];

/// `[1.0e-3, ...]`.
fn sci(v: &[f64]) -> String {
    let items: Vec<String> = v.iter().map(|e| format!("{e:.1e}")).collect();
    format!("[{}]", items.join(", "))
}

/// Adjoint mode at `rtol`, the other options at their defaults (method auto, atol 1e-10).
fn adjoint(rtol: f64) -> Options {
    Options {
        rtol,
        gradient_mode: GradientMode::Adjoint,
        ..Options::default()
    }
}

/// Runs `m` at `p` in adjoint mode at every rtol of [`RTOLS`] and checks C and every entry of
/// dC/dθ against the closed form (`cost`, `grad`) to 10× rtol (relative, entry by entry).
fn within_10x_rtol<M: HybridModel>(
    m: &M,
    p: &OVector<f64, M::P>,
    (cost, grad): (f64, &[f64]),
    what: &str,
) where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    for rtol in RTOLS {
        let sol = solve(m, p, &adjoint(rtol)).unwrap_or_else(|e| panic!("{what} {rtol:e}: {e}"));
        assert_eq!(sol.stats.mode, GradientMode::Adjoint, "{what} {rtol:e}");
        let errs: Vec<f64> = (sol.gradient.iter().zip(grad))
            .map(|(a, b)| ((a - b) / b).abs())
            .collect();
        let ec = ((sol.cost - cost) / cost).abs();
        println!(
            "{what} rtol {rtol:e}: dC/dθ rel errors {}, C {ec:.1e}, {} steps \
             ({} rejected), diagnostics {:?}",
            sci(&errs),
            sol.stats.steps,
            sol.stats.rejected_steps,
            sol.diagnostics.iter().map(|d| d.kind).collect::<Vec<_>>()
        );
        assert!(
            ec <= 10.0 * rtol,
            "{what} rtol {rtol:e}: C rel err {ec:.1e}"
        );
        for (j, e) in errs.iter().enumerate() {
            assert!(
                *e <= 10.0 * rtol,
                "{what} rtol {rtol:e}: dC/dθ[{j}] = {:e}, closed form {:e}, rel err {e:.1e}",
                sol.gradient[j],
                grad[j]
            );
        }
    }
}

/// The stiff relay (τ = 1e-8, `models/stiff_relay.hyb`) in adjoint mode against its closed
/// form, compiled by `hybrid!` and loaded.
#[test]
fn stiff_relay_adjoint_is_within_10x_rtol_at_every_decade_both_doors() {
    let pp = StiffRelayParams::default();
    let (c, g) = cost_closed(pp.tau, pp.rate, pp.lo, pp.hi);
    let compiled = StiffRelay::new();
    within_10x_rtol(&compiled, &pp.to_vector(), (c, &g), "relay (compiled)");
    let loaded = InterpretedModel::from_source(RELAY).expect("the relay loads");
    let p = loaded.default_params();
    within_10x_rtol(&loaded, &p, (c, &g), "relay (loaded)");
}

/// C and dC/d(τ, a, k) of the fast lag in closed form: u = a(1 − e^{−t/τ}),
/// y(T) = k a (T − τ(1 − E)), E = e^{−T/τ}, and C = y(T)² + ∫₀ᵀ y dt with
/// ∫₀ᵀ y dt = k a (T²/2 − τT + τ²(1 − E)).
fn fast_lag_closed(tau: f64, a: f64, k: f64) -> (f64, [f64; 3]) {
    let t = 1.0;
    let e = (-t / tau).exp();
    let lag = t - tau * (1.0 - e);
    let y = k * a * lag;
    let q = k * a * (0.5 * t * t - tau * t + tau * tau * (1.0 - e));
    // d/dτ of τ(1 − E) and of the integral's bracket.
    let d_lag = (1.0 - e) - (t / tau) * e;
    let d_q = k * a * (-t + 2.0 * tau * (1.0 - e) - t * e);
    let dy = [-k * a * d_lag, k * lag, a * lag];
    let dq = [d_q, q / a, q / k];
    let grad = [0, 1, 2].map(|j| 2.0 * y * dy[j] + dq[j]);
    (y * y + q, grad)
}

/// The fast lag (`fast_lag.hyb`, τ = 1e-6) in adjoint mode against its closed form at every
/// decade, both doors. λ is constant through the transient at t = 0 (F reads no state), so
/// an error norm over λ alone lets the last backward steps grow across the spike of G_τ.
#[test]
fn fast_lag_adjoint_is_within_10x_rtol_at_every_decade_both_doors() {
    let compiled = FastLag::new();
    let p = compiled.default_params();
    let (c, g) = fast_lag_closed(p[0], p[1], p[2]);
    within_10x_rtol(&compiled, &p, (c, &g), "fast lag (compiled)");
    let loaded = InterpretedModel::from_source(FAST_LAG).expect("the fast lag loads");
    let p = loaded.default_params();
    within_10x_rtol(&loaded, &p, (c, &g), "fast lag (loaded)");
}

/// The fast lag's closed form (and so the adjoint, held to it above) against central finite
/// differences of tight primal runs at relative steps 1e-1, 1e-2 and 1e-3, entry by entry: C
/// is quadratic in a and k and, with e^{−T/τ} = 0 in doubles, in τ, so a central difference
/// has no truncation error, and what is left is the primal runs' rounding divided by the
/// step (the best within 1e-7 relative, every one within 1e-5).
#[test]
fn fast_lag_closed_form_matches_central_differences() {
    let m = FastLag::new();
    let p = m.default_params();
    let (_, g) = fast_lag_closed(p[0], p[1], p[2]);
    let tight = Options {
        rtol: 1e-12,
        atol: 1e-14,
        ..Options::default()
    };
    let adj = solve(&m, &p, &adjoint(1e-10)).expect("runs");
    for (j, &want) in g.iter().enumerate() {
        let errs: Vec<f64> = [1e-1, 1e-2, 1e-3]
            .iter()
            .map(|&h| {
                let fd = fd_gradient(&m, &p, &tight, j, h).expect("the difference runs");
                ((fd - want) / want).abs()
            })
            .collect();
        println!(
            "dC/dθ[{j}] = {want:e} (adjoint at rtol 1e-10: {:e}), FD rel errors at steps \
             1e-1, 1e-2, 1e-3: {}",
            adj.gradient[j],
            sci(&errs)
        );
        let best = errs.iter().copied().fold(f64::INFINITY, f64::min);
        assert!(best <= 1e-7, "dC/dθ[{j}]: FD errors {}", sci(&errs));
        assert!(
            errs.iter().all(|&e| e <= 1e-5),
            "dC/dθ[{j}]: {}",
            sci(&errs)
        );
        assert!(((adj.gradient[j] - want) / want).abs() <= 1e-9);
    }
}

/// The pulse pair (`pulse_pair.hyb`): x and λ constant, G a Gaussian pulse of width 0.1. With
/// λ alone in the sweep's error norm nothing limits its steps but the primal's record (a few
/// long steps over a constant x), and the quadrature of the pulse is off by percents at
/// every tolerance; with g's error in the norm it is within 10× rtol. dC/dw = 0: its
/// relative error is not defined, and it is checked absolutely against the others' scale.
/// atol is 1e-14 here: at the default 1e-10 an entry of size 0.18 is held to atol, not to
/// rtol 1e-12 (as S is in forward mode).
#[test]
fn pulse_pair_adjoint_is_within_10x_rtol_at_every_decade_both_doors() {
    let compiled = PulsePair::new();
    let p = compiled.default_params();
    let da = p[2] * std::f64::consts::PI.sqrt();
    let loaded = InterpretedModel::from_source(PULSE_PAIR).expect("the pulse pair loads");
    for rtol in RTOLS {
        let opts = Options {
            atol: 1e-14,
            ..adjoint(rtol)
        };
        for (what, sol) in [
            ("compiled", solve(&compiled, &p, &opts)),
            ("loaded", solve(&loaded, &loaded.default_params(), &opts)),
        ] {
            let sol = sol.unwrap_or_else(|e| panic!("pulse pair ({what}) {rtol:e}: {e}"));
            let g = &sol.gradient;
            let errs = [(g[0] - da) / da, (g[1] + da) / da, g[2] / da].map(f64::abs);
            println!(
                "pulse pair ({what}) rtol {rtol:e}: dC/dθ rel errors {}, {} steps ({} \
                 rejected)",
                sci(&errs),
                sol.stats.steps,
                sol.stats.rejected_steps
            );
            assert!(
                errs.iter().all(|&e| e <= 10.0 * rtol),
                "pulse pair ({what}) rtol {rtol:e}: dC/dθ = {g:?}, want ({da}, {}, 0)",
                -da
            );
        }
    }
}
