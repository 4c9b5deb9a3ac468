//! Two state events whose guards lie closer together than the run's tolerances (b − a from 0
//! to 10⁻⁹, rtol from 10⁻⁶ to 10⁻¹³): each fires exactly once, in both gradient modes, under
//! every method, through both doors, on a curved clock (adaptive steps, the scanner samples
//! the dense output) and on a constant one (exact segments, the scanner's linear path). An
//! event that fires within the simultaneity window of an earlier crossing, before its own
//! guard has triggered, must not fire a second time when that guard does cross a moment
//! later (`suite/two_guards.hyb` at rtol 10⁻¹² once gave C = 1.109 for 1, silently).

use mvad::interp::InterpretedModel;
use mvad::runtime::solution::{DiagnosticKind, GradientMode, Method, Options, Solution};
use mvad::runtime::solve::solve;
use mvad::{HybridModel, ModelAlloc};
use nalgebra::{Const, DefaultAllocator, OVector};

mvad::hybrid!(include "tests/near_guards.hyb");
mvad::hybrid!(include "tests/near_guards_exact.hyb");

/// b − a, all below 10⁻⁹ (0: the same guard value).
const GAPS: [f64; 9] = [0.0, 1e-16, 1e-15, 1e-13, 5e-13, 1e-12, 2e-12, 1e-11, 1e-9];
/// Relative tolerances of the runs.
const RTOLS: [f64; 5] = [1e-6, 1e-9, 1e-10, 1e-12, 1e-13];
const A: f64 = 0.5;
const U: f64 = 0.7;
const V: f64 = 2.0;
const T: f64 = 1.0;

/// `NearGuards` (y₀ = 1, ẋ = 1 + kx): t_c = ln(1 + kc)/k,
/// C = t_a + (1 + u)(t_b − t_a) + (1 + u)v(T − t_b) and its gradient in (a, b, u, v, k).
fn curved_closed_form(p: [f64; 5]) -> (f64, [f64; 5]) {
    let [a, b, u, v, k] = p;
    let t = |c: f64| (1.0 + k * c).ln() / k;
    let t_c = |c: f64| 1.0 / (1.0 + k * c);
    let t_k = |c: f64| c / (k * (1.0 + k * c)) - (1.0 + k * c).ln() / (k * k);
    let (ta, tb) = (t(a), t(b));
    let (y1, y2) = (1.0 + u, (1.0 + u) * v);
    let cost = ta + y1 * (tb - ta) + y2 * (T - tb);
    let grad = [
        (1.0 - y1) * t_c(a),
        (y1 - y2) * t_c(b),
        (tb - ta) + v * (T - tb),
        y1 * (T - tb),
        (1.0 - y1) * t_k(a) + (y1 - y2) * t_k(b),
    ];
    (cost, grad)
}

/// `NearGuardsExact` (ẋ = c): C = a/c + 2b/c + (1 + u)v and its gradient in (a, b, u, v, c).
fn exact_closed_form(p: [f64; 5]) -> (f64, [f64; 5]) {
    let [a, b, u, v, c] = p;
    let cost = a / c + 2.0 * b / c + (1.0 + u) * v;
    (
        cost,
        [1.0 / c, 2.0 / c, v, 1.0 + u, -(a + 2.0 * b) / (c * c)],
    )
}

/// The closed forms' gradients against central differences (steps 10⁻³ … 10⁻⁵), so that
/// the references the runs are held to are themselves checked.
#[test]
fn the_closed_forms_agree_with_central_differences() {
    for form in [curved_closed_form, exact_closed_form] {
        let p = [A, A + 1e-3, U, V, 0.5];
        let (_, g) = form(p);
        for i in 0..5 {
            for h in [1e-3, 1e-4, 1e-5] {
                let (mut hi, mut lo) = (p, p);
                hi[i] += h;
                lo[i] -= h;
                let fd = (form(hi).0 - form(lo).0) / (2.0 * h);
                // The differences' own error is O(h²).
                let tol = (1e-8 + 10.0 * h * h) * g[i].abs().max(1.0);
                assert!((fd - g[i]).abs() <= tol, "{i} {h}: {fd} vs {}", g[i]);
            }
        }
    }
}

/// Runs `model` at every gap, tolerance, method and gradient mode; every run must fire
/// `first` then `second`, once each, and match `closed_form` (a simultaneous firing
/// within the window moves C by at most the gap, and says so with a diagnostic).
fn check_every_gap<M: HybridModel>(
    model: &M,
    name: &str,
    k: f64,
    closed_form: fn([f64; 5]) -> (f64, [f64; 5]),
) -> usize
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let mut failures = Vec::new();
    let mut runs = 0;
    for gap in GAPS {
        let p = [A, A + gap, U, V, k];
        let theta = OVector::<f64, M::P>::from_iterator_generic(model.nparams(), Const::<1>, p);
        let (want_c, want_g) = closed_form(p);
        for rtol in RTOLS {
            for method in Method::ALL {
                for mode in [GradientMode::Forward, GradientMode::Adjoint] {
                    let opts = Options {
                        rtol,
                        atol: rtol * 1e-2,
                        method,
                        gradient_mode: mode,
                        ..Options::default()
                    };
                    let case = format!("{name} gap {gap:e} rtol {rtol:e} {method:?} {mode:?}");
                    runs += 1;
                    let sol = match solve(model, &theta, &opts) {
                        Ok(sol) => sol,
                        Err(e) => {
                            failures.push(format!("{case}: {e}"));
                            continue;
                        }
                    };
                    if let Some(why) = verdict(&sol, rtol, want_c, &want_g) {
                        failures.push(format!("{case}: {why}"));
                    }
                }
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    runs
}

/// What is wrong with `sol`, if anything: its events (exactly `first`, `second`), a
/// shared instant without its diagnostic, C or dC/dθ off the closed form by more than
/// max(10⁻¹⁰, 10³·rtol) relative to their scale.
fn verdict(sol: &Solution, rtol: f64, want_c: f64, want_g: &[f64; 5]) -> Option<String> {
    let fired: Vec<usize> = sol.events.iter().map(|e| e.event).collect();
    if fired != [0, 1] {
        let times: Vec<f64> = sol.events.iter().map(|e| e.t).collect();
        return Some(format!("events {fired:?} at {times:?}, C = {}", sol.cost));
    }
    let together = sol.events[0].t == sol.events[1].t;
    let reported = sol
        .diagnostics
        .iter()
        .any(|d| d.kind == DiagnosticKind::SimultaneousEvents);
    if together != reported {
        return Some(format!(
            "fired together: {together}, diagnostics {:?}",
            sol.diagnostics
        ));
    }
    let tol = (1e3 * rtol).max(1e-10);
    if (sol.cost - want_c).abs() > tol * want_c.abs().max(1.0) {
        return Some(format!("C = {} vs {want_c}", sol.cost));
    }
    let scale = want_g.iter().fold(1.0f64, |m, g| m.max(g.abs()));
    let worst = sol
        .gradient
        .iter()
        .zip(want_g)
        .map(|(g, w)| (g - w).abs())
        .fold(0.0, f64::max);
    if worst > tol * scale {
        return Some(format!("dC/dθ = {:?} vs {want_g:?}", sol.gradient));
    }
    None
}

#[test]
fn near_guards_on_a_curved_clock_fire_once_each() {
    let src = include_str!("near_guards.hyb");
    let loaded = InterpretedModel::from_source(src).expect("loads");
    let runs = check_every_gap(&NearGuards::new(), "compiled", 0.5, curved_closed_form);
    check_every_gap(&loaded, "loaded", 0.5, curved_closed_form);
    assert_eq!(runs, GAPS.len() * RTOLS.len() * Method::ALL.len() * 2);
}

#[test]
fn near_guards_on_exact_segments_fire_once_each() {
    let compiled = NearGuardsExact::new();
    assert!(
        compiled.flow_is_constant(0) && compiled.guard_is_affine(0) && compiled.guard_is_affine(1)
    );
    let src = include_str!("near_guards_exact.hyb");
    let loaded = InterpretedModel::from_source(src).expect("loads");
    check_every_gap(&compiled, "compiled", 1.0, exact_closed_form);
    check_every_gap(&loaded, "loaded", 1.0, exact_closed_form);
}
