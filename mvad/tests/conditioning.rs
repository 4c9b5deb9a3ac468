//! The global error estimate and its `ill_conditioned` diagnostic (issue 11): a run whose
//! error at T local error control does not bound says so; a run whose error it bounds stays
//! silent. Checked against closed forms (`suite/unstable_tracking.hyb`,
//! `suite/exponential_growth.hyb`, the E1 ball) at every method and several tolerances.

use std::path::Path;

use mvad::runtime::solution::{DiagnosticKind, GradientMode, Method, Options, Solution};
use mvad::runtime::solve::solve;
use mvad::HybridModel;
use nalgebra::DVector;

fn load(file: &str) -> mvad::interp::InterpretedModel {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(file);
    mvad::load::load(&path).expect("the model loads")
}

fn run_in(
    m: &mvad::interp::InterpretedModel,
    p: &[f64],
    method: Method,
    rtol: f64,
    gradient_mode: GradientMode,
) -> Solution {
    try_run(m, p, method, rtol, gradient_mode).expect("the run succeeds")
}

fn try_run(
    m: &mvad::interp::InterpretedModel,
    p: &[f64],
    method: Method,
    rtol: f64,
    gradient_mode: GradientMode,
) -> Result<Solution, mvad::runtime::error::SolveError> {
    let opts = Options {
        method,
        rtol,
        atol: rtol * 1e-2,
        gradient_mode,
        ..Options::default()
    };
    let sol = solve(m, &DVector::from_column_slice(p), &opts)?;
    assert_eq!(sol.stats.mode, gradient_mode, "ran in the mode asked for");
    Ok(sol)
}

fn ill_conditioned(sol: &Solution) -> bool {
    sol.diagnostic(DiagnosticKind::IllConditioned).is_some()
}

/// max_i |a_i − r_i| / max_i |r_i|, the suite's error of a gradient.
fn grad_error(a: &[f64], r: &[f64]) -> f64 {
    let d = a
        .iter()
        .zip(r)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    d / r.iter().map(|y| y.abs()).fold(0.0, f64::max)
}

/// x' = a (x − b sin t) + b cos t, x(0) = 0: x = b sin t for every a, but perturbations grow
/// like e^{a t}. C = b (1 − cos T), dC/da = 0, dC/db = 1 − cos T (T = 10). With a = 2, 3
/// (amplification e^{20}, e^{30}) the gradient's error exceeds 10³ × rtol in almost every run;
/// wherever it does, the run raises `ill_conditioned`, at every method; the estimate is within
/// a factor 20 below and (at rtol ≤ 1e-8) 100 above the true error.
#[test]
fn an_unstable_flow_is_reported_at_every_method_and_tolerance() {
    // Measured: est/err from 0.07 (Rosenbrock, rtol 1e-6, a = 3) to 30 at rtol ≤ 1e-8; with
    // long steps on the unstable flow (Verner 9 at rtol 1e-6) the first-order transport
    // overestimates by up to 10⁸, in the safe direction.
    unstable_flow_is_reported(GradientMode::Forward, 100.0, 0);
}

/// The runs of the unstable tracking flow (a = 2, 3) in `mode` at every method and rtol 1e-6,
/// 1e-8, 1e-10: wherever the gradient's error exceeds 10³ × rtol, `ill_conditioned` is raised
/// (in at least 20 of the 24 runs it does); the estimate is above 0.05 × the error, and at
/// rtol ≤ 1e-8 below `above` × the error. At most `failures` runs may end in an error (which
/// is reported, not silent).
fn unstable_flow_is_reported(mode: GradientMode, above: f64, failures: usize) {
    let m = load("suite/unstable_tracking.hyb");
    let exact = [0.0, 1.0 - 10f64.cos()];
    let (mut wrong, mut errors) = (0, 0);
    for a in [2.0, 3.0] {
        for method in Method::ALL {
            for rtol in [1e-6, 1e-8, 1e-10] {
                let sol = match try_run(&m, &[a, 1.0], method, rtol, mode) {
                    Ok(sol) => sol,
                    Err(e) => {
                        eprintln!("a = {a}, {mode:?}, {method:?}, rtol {rtol:e}: {e}");
                        errors += 1;
                        continue;
                    }
                };
                let err = grad_error(&sol.gradient, &exact);
                let est = sol.error_estimate.as_ref().expect("an estimate");
                let est_rel = est.gradient.iter().map(|e| e.abs()).fold(0.0, f64::max) / exact[1];
                let what = format!(
                    "a = {a}, {mode:?}, {method:?}, rtol {rtol:e}: error {err:.1e}, estimate {est_rel:.1e}"
                );
                eprintln!("{what}");
                if err > 1e3 * rtol {
                    assert!(ill_conditioned(&sol), "silently wrong: {what}");
                    wrong += 1;
                }
                assert!(est_rel > 0.05 * err, "estimate below the error: {what}");
                if rtol <= 1e-8 {
                    assert!(
                        est_rel < above * err,
                        "estimate far above the error: {what}"
                    );
                }
            }
        }
    }
    assert!(errors <= failures, "{errors} runs failed");
    assert!(
        wrong >= 20,
        "only {wrong} of 24 runs are off by more than 1e3 x rtol"
    );
}

/// The same flow with a = 0.5 (amplification e^5 ≈ 150) and exponential growth x' = a x
/// (the solution grows with its perturbations, so relative errors do not): local error control
/// bounds the error, the runs meet 10³ × rtol and stay silent, at every method.
#[test]
fn a_bounded_error_raises_nothing() {
    bounded_cases_raise_nothing(GradientMode::Forward, |_, _| false);
}

/// The runs of the bounded cases in `mode` meet 10³ × rtol and raise nothing, but where
/// `allowed(method, rtol)` says an alarm is known.
fn bounded_cases_raise_nothing(mode: GradientMode, allowed: impl Fn(Method, f64) -> bool) {
    let tracking = load("suite/unstable_tracking.hyb");
    let growth = load("suite/exponential_growth.hyb");
    let e = (2.0f64 * 10.0).exp();
    let growth_exact = [10.0 * e / 2.0 - (e - 1.0) / 4.0, (e - 1.0) / 2.0];
    let cases: [(&mvad::interp::InterpretedModel, [f64; 2], [f64; 2]); 2] = [
        (&tracking, [0.5, 1.0], [0.0, 1.0 - 10f64.cos()]),
        (&growth, [2.0, 1.0], growth_exact),
    ];
    for (m, p, exact) in cases {
        for method in Method::ALL {
            for rtol in [1e-6, 1e-8, 1e-10] {
                let sol = run_in(m, &p, method, rtol, mode);
                let err = grad_error(&sol.gradient, &exact);
                let what = format!(
                    "{}, {mode:?}, {method:?}, rtol {rtol:e}: error {err:.1e}",
                    m.info().name
                );
                assert!(err < 1e3 * rtol, "{what}");
                assert!(
                    allowed(method, rtol) || !ill_conditioned(&sol),
                    "false alarm: {what}: {:?}",
                    sol.diagnostics
                );
            }
        }
    }
}

/// Van der Pol at μ = 10⁶ through its fold (suite case `van der pol mu=1e6`): its gradient at
/// rtol 1e-8 is off by 3.1e-4 relative (3·10⁴ × rtol; reference: Rodas5P at rtol 1e-12 by
/// central differences, confirmed by Tsit5 and Verner 9 at rtol 1e-12/1e-13 to 2e-6). The run
/// says so, at the default options.
#[test]
fn the_fold_of_van_der_pol_is_reported() {
    the_fold_is_reported(&Options::default());
}

/// Van der Pol at μ = 10⁶ with `opts`: the run raises `ill_conditioned` for dC/dθ, its
/// estimate above 10⁴ × the tolerance. Returns the model and θ.
fn the_fold_is_reported(opts: &Options) -> (mvad::interp::InterpretedModel, DVector<f64>) {
    let m = load("suite/van_der_pol.hyb");
    let mut p = DVector::from_column_slice(&m.info().param_defaults);
    p[0] = 1e6;
    let sol = solve(&m, &p, opts).expect("the run succeeds");
    assert_eq!(sol.stats.mode, opts.gradient_mode);
    let d = sol
        .diagnostic(DiagnosticKind::IllConditioned)
        .expect("ill_conditioned raised");
    assert!(d.message.contains("dC/dθ"), "{}", d.message);
    let est = sol.error_estimate.expect("an estimate");
    assert!(est.gradient_ratio > 1e4, "{est:?}");
    (m, p)
}

/// Off, nothing is carried and nothing is said; the numbers are the same bit for bit.
#[test]
fn the_estimate_can_be_switched_off() {
    let m = load("suite/unstable_tracking.hyb");
    let p = DVector::from_column_slice(&[2.0, 1.0]);
    let on = solve(&m, &p, &Options::default()).expect("runs");
    let off = solve(
        &m,
        &p,
        &Options {
            global_error: false,
            ..Options::default()
        },
    )
    .expect("runs");
    assert!(ill_conditioned(&on));
    assert!(off.error_estimate.is_none() && off.diagnostics.is_empty());
    assert_eq!(on.cost.to_bits(), off.cost.to_bits());
    assert_eq!(on.gradient, off.gradient);
}

/// Adjoint mode (issue 8): the sweep's estimate on the unstable flow. Measured after the
/// gradient quadrature left the stepper and before it came under error control (its local
/// error is the embedded weights' difference, the lower-order quadrature's error): est/err from 1.2
/// to 4.6e3 (Tsit5 2e3 to 5e3, Verner 9 600 to 1.5e3, Rodas5P 1.2 to 40); without the
/// quadrature's own error it was 100 to 1e3, and the stiff relay's dC/dτ at rtol 1e-3 was
/// wrong by 6e6 with no diagnostic. Verner 9 at rtol 1e-10 for a = 3 may run out of steps in
/// the primal run (at rtol 1e-12).
#[test]
fn an_unstable_flow_is_reported_in_adjoint_mode() {
    unstable_flow_is_reported(GradientMode::Adjoint, 1e4, 1);
}

/// Adjoint mode on the bounded cases of `a_bounded_error_raises_nothing`: the adjoint meets
/// 10³ × rtol and its estimate stays silent, at every method — except on the tracking flow
/// (whose dC/db = 1.84 is the sum of an integrand of size ~150, λ ~ e^{a(T−t)}): Rodas5P at
/// every rtol (errors 46, 67 and 73 × rtol) and Tsit5 at rtol 1e-10 (error 1.1 × rtol,
/// estimate 1.5e3 × rtol; measured before the gradient quadrature came under error
/// control). Its estimated local error is the embedded (lower-order) quadrature's, which the
/// cancellation amplifies 80×: alarms there are known and allowed, not required.
#[test]
fn a_bounded_error_raises_nothing_in_adjoint_mode() {
    bounded_cases_raise_nothing(GradientMode::Adjoint, |method, rtol| {
        method == Method::Rosenbrock
            || (rtol == 1e-10 && matches!(method, Method::Auto | Method::Tsit5))
    });
}

/// Van der Pol at μ = 10⁶ (`the_fold_of_van_der_pol_is_reported`) in adjoint mode: the
/// gradient at rtol 1e-8 is off by 6.9e-3 relative (7·10⁵ × rtol; it was printed with no
/// diagnostic before the sweep carried an estimate). `solve` and the VJP entry point say so.
#[test]
fn the_fold_of_van_der_pol_is_reported_in_adjoint_mode() {
    let opts = Options {
        gradient_mode: GradientMode::Adjoint,
        ..Options::default()
    };
    let (m, p) = the_fold_is_reported(&opts);
    // The same through `vjp`, with a cotangent on an observable-free cost.
    let cot = mvad::runtime::vjp::Cotangents {
        cost: 2.0,
        times: &[],
        observables: &[],
    };
    let out = mvad::runtime::vjp::vjp(&m, &p, &opts, &cot).expect("the vjp runs");
    assert!(
        ill_conditioned(&out.solution),
        "{:?}",
        out.solution.diagnostics
    );
}

/// Off in adjoint mode, nothing is carried (no tape entries either) and nothing is said; the
/// numbers are the same bit for bit.
#[test]
fn the_estimate_can_be_switched_off_in_adjoint_mode() {
    let m = load("suite/unstable_tracking.hyb");
    let p = DVector::from_column_slice(&[2.0, 1.0]);
    let on = Options {
        gradient_mode: GradientMode::Adjoint,
        ..Options::default()
    };
    let off = Options {
        global_error: false,
        ..on.clone()
    };
    let on = solve(&m, &p, &on).expect("runs");
    let off = solve(&m, &p, &off).expect("runs");
    assert!(ill_conditioned(&on));
    assert!(off.error_estimate.is_none() && off.diagnostics.is_empty());
    assert_eq!(on.cost.to_bits(), off.cost.to_bits());
    assert_eq!(on.gradient, off.gradient);
    assert!(on.stats.record_bytes > off.stats.record_bytes);
}

/// No false alarm at the default tolerances on the bundled models, in either mode; and on
/// E1 (the ball's closed forms, `suite/manifest.json`'s reference) at rtol 1e-4 … 1e-12 in
/// adjoint mode, where the gradient meets 10 × rtol.
#[test]
fn the_bundled_models_and_e1_raise_nothing_in_adjoint_mode() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .expect("models/")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "hyb"))
        .collect();
    files.sort();
    assert!(files.len() >= 8, "{files:?}");
    for file in &files {
        let m = mvad::load::load(file).expect("loads");
        let p = DVector::from_column_slice(&m.info().param_defaults);
        for gradient_mode in [GradientMode::Forward, GradientMode::Adjoint] {
            let opts = Options {
                gradient_mode,
                ..Options::default()
            };
            let sol = solve(&m, &p, &opts).expect("runs");
            assert!(
                !ill_conditioned(&sol),
                "{}, {gradient_mode:?}: {:?}",
                file.display(),
                sol.diagnostics
            );
        }
    }
    let ball = load("suite/ball.hyb");
    // dC/d(e, g, h0, v0) at the defaults: closed form (suite/references.py).
    let exact = [
        2.8314408141470055,
        -0.015223766515235087,
        1.0199294309159035,
        0.12274090656022231,
    ];
    let p = ball.info().param_defaults.clone();
    for rtol in [1e-4, 1e-6, 1e-8, 1e-10, 1e-12] {
        for method in Method::ALL {
            let sol = run_in(&ball, &p, method, rtol, GradientMode::Adjoint);
            let err = grad_error(&sol.gradient, &exact);
            let what = format!("E1, {method:?}, rtol {rtol:e}: error {err:.1e}");
            assert!(err < 10.0 * rtol, "{what}");
            assert!(!ill_conditioned(&sol), "false alarm: {what}");
        }
    }
}

/// A decay kicked every P, far past its equilibrium between kicks: in the tail an error of
/// atol is 10⁸ times x, and read as a time shift along f ≈ 0 it became a shift of 10⁸ time
/// units, materialised under the kick's f as an error 10¹⁷ times the tolerance on an answer
/// exact to 1e-15 (probe3 b2). A shift is read only while |γ|‖f_x‖∞ ≤ 10⁻³. C = 4/a + 4 and
/// dC/da = −4/a² (kicks at 0, 1000, 2000 over [0, 2500]).
#[test]
fn a_decayed_tail_is_no_time_shift() {
    let src = "model DecayKicked {
        param a = 0.8; param P = 1000;
        state x = 1;
        flow { der(x) = -a * x; }
        event kick every P { x = x + 1; }
        cost = integral(x) + sum(kick, x);
        horizon 2500;
    }";
    let m = mvad::load::load_str("decay_kicked.hyb", src).expect("valid model");
    let a = 0.8;
    for method in [Method::Rosenbrock, Method::Auto, Method::Tsit5] {
        for mode in [GradientMode::Forward, GradientMode::Adjoint] {
            let sol = run_in(&m, &[a, 1000.0], method, 1e-8, mode);
            let what = format!("{method:?} {mode:?}");
            assert!(
                ((sol.cost - (4.0 / a + 4.0)) / 9.0).abs() < 1e-8,
                "{what}: C = {}",
                sol.cost
            );
            assert!(
                (sol.gradient[0] + 4.0 / (a * a)).abs() < 1e-7 * 6.25,
                "{what}: dC/da = {}",
                sol.gradient[0]
            );
            assert!(!ill_conditioned(&sol), "{what}: {:?}", sol.diagnostics);
        }
    }
}
