//! Robustness of the driver: a step budget instead of a hang (explicit method on a stiff
//! model), and NaN/∞ from a flow reported as `NonFinite` naming the flow and the time.

mod common;

use common::{info, AdModel, Sc, Spec};
use mvad_runtime::error::SolveError;
use mvad_runtime::model::ModelInfo;
use mvad_runtime::solution::{DiagnosticKind, Method, Options};
use mvad_runtime::solve::solve;

/// A stiff lag coupled to a slow state: ẏ = (u − y)/τ, u̇ = −u, τ = 1e-8, u(0) = 1, y(0) = 0,
/// C = ∫ y dt over [0, 1]. Tsit5's stability bound forces h ≈ 3.3 τ, i.e. ~3e8 steps.
struct Lag;

impl Spec for Lag {
    fn info(&self) -> ModelInfo {
        info(
            "Lag",
            &["y", "u"],
            &[("tau", 1e-8)],
            &["lag"],
            vec![],
            &[],
            0,
        )
    }
    const X0: &'static [f64] = &[0.0, 1.0];
    const T_END: Option<f64> = Some(1.0);
    fn rhs<S: Sc>(&self, _m: usize, _sw: u64, _t: S, x: &[S], p: &[S], f: &mut [S]) {
        f[0] = (x[1] - x[0]) / p[0];
        f[1] = -x[1];
    }
    fn running<S: Sc>(&self, _sw: u64, _t: S, x: &[S], _p: &[S]) -> S {
        x[0]
    }
}

#[test]
fn explicit_method_on_a_stiff_model_stops_at_max_steps() {
    let m = AdModel::new(Lag);
    let p = m.defaults();
    let opts = Options {
        method: Method::Tsit5,
        max_steps: 20_000,
        ..Options::default()
    };
    let err = solve(&m, &p, &opts).unwrap_err();
    match &err {
        SolveError::MaxSteps { t, steps, .. } => {
            assert_eq!(*steps, 20_000);
            // ~3.3e-8 per step: far from the horizon.
            assert!(*t > 0.0 && *t < 1e-2, "t = {t}");
        }
        other => panic!("expected MaxSteps, got {other:?}"),
    }
    let msg = err.to_string();
    // It suggests the implicit methods but names no command-line flag (the CLI adds those).
    assert!(
        msg.contains("auto") && msg.contains("rosenbrock") && !msg.contains("--"),
        "{msg}"
    );
    let d = err.diagnostic().expect("a numerical failure");
    assert_eq!(d.kind, DiagnosticKind::MaxSteps);
    assert_eq!(d.kind.name(), "max_steps");
    // The same model under `auto` (stiffness detection → Rodas5P) stays far inside the
    // default budget and gets C = ∫₀¹ y dt with y ≈ e^{−t} (1 + O(τ)).
    let sol = solve(&m, &p, &Options::default()).expect("auto handles the stiff lag");
    let used = sol.stats.steps + sol.stats.rejected_steps;
    assert!(used < 5_000, "{used} steps");
    approx::assert_relative_eq!(sol.cost, 1.0 - (-1.0f64).exp(), max_relative = 1e-6);
}

#[test]
fn a_zero_step_budget_is_an_error_not_a_panic() {
    let m = AdModel::new(Lag);
    let opts = Options {
        max_steps: 0,
        ..Options::default()
    };
    assert!(solve(&m, &m.defaults(), &opts).is_err());
}

/// x(0) = 0, c = 0.7, horizon 1, C = ∫ x dt, with d = c − t and
/// - kind 0: ẋ = √d (NaN for t > c);
/// - kind 1: ẋ = d / max(d, 0) with max(d, 0) = (d + √(d²))/2 exactly: ẋ = 1 for t < c,
///   0/0 at c and d/0 = −∞ beyond (a division by zero from a known time on);
/// - kind 2: ẋ = 1/d: the flow stays finite but x = −ln(1 − t/c) blows up at c (a genuine
///   singularity of the solution, not a NaN: the step size underflows).
struct Undefined {
    kind: u8,
}

impl Spec for Undefined {
    fn info(&self) -> ModelInfo {
        info(
            "Undefined",
            &["x"],
            &[("c", 0.7)],
            &["rising"],
            vec![],
            &[],
            0,
        )
    }
    const X0: &'static [f64] = &[0.0];
    const T_END: Option<f64> = Some(1.0);
    fn rhs<S: Sc>(&self, _m: usize, _sw: u64, t: S, _x: &[S], p: &[S], f: &mut [S]) {
        let d = p[0] - t;
        f[0] = match self.kind {
            0 => d.sqrt(),
            1 => d / ((d + (d * d).sqrt()) * 0.5),
            _ => S::cst(1.0) / d,
        };
    }
    fn running<S: Sc>(&self, _sw: u64, _t: S, x: &[S], _p: &[S]) -> S {
        x[0]
    }
}

#[test]
fn nan_in_a_flow_is_nonfinite_at_the_right_time_naming_the_flow() {
    for sens in [true, false] {
        for kind in [0u8, 1] {
            nonfinite_flow(kind, sens);
        }
    }
}

/// A flow that turns NaN (kind 0) or ±∞ (kind 1) at t = 0.7 is reported as `NonFinite`
/// there, naming the mode and the flow.
fn nonfinite_flow(kind: u8, sens: bool) {
    let m = AdModel::new(Undefined { kind });
    let opts = Options {
        rtol: 1e-10,
        atol: 1e-12,
        sensitivities: sens,
        ..Options::default()
    };
    let err = solve(&m, &m.defaults(), &opts).unwrap_err();
    match &err {
        SolveError::NonFinite { t, what } => {
            assert!(what.contains("mode `rising`"), "kind {kind}: {what}");
            assert!(what.contains("flow"), "kind {kind}: {what}");
            assert!((t - 0.7).abs() < 1e-9, "kind {kind} sens {sens}: t = {t}");
        }
        other => panic!("kind {kind} sens {sens}: expected NonFinite, got {other:?}"),
    }
    let d = err.diagnostic().unwrap();
    assert_eq!(d.kind, DiagnosticKind::Nonfinite);
    assert!(err.to_string().contains("non-finite"), "{err}");
}

#[test]
fn a_singular_solution_is_a_step_size_underflow_at_the_singularity() {
    let m = AdModel::new(Undefined { kind: 2 });
    let opts = Options {
        rtol: 1e-10,
        atol: 1e-12,
        ..Options::default()
    };
    match solve(&m, &m.defaults(), &opts).unwrap_err() {
        SolveError::StepSizeUnderflow { t, .. } => assert!((t - 0.7).abs() < 1e-6, "t = {t}"),
        other => panic!("expected StepSizeUnderflow, got {other:?}"),
    }
}

/// ẋ = −a x, x(0) = 1, C = ∫₀¹ x dt = (1 − e^{−a})/a, no events.
struct Decay;

impl Spec for Decay {
    fn info(&self) -> ModelInfo {
        info("Decay", &["x"], &[("a", 1.3)], &["main"], vec![], &[], 0)
    }
    const X0: &'static [f64] = &[1.0];
    const T_END: Option<f64> = Some(1.0);
    fn rhs<S: Sc>(&self, _m: usize, _sw: u64, _t: S, x: &[S], p: &[S], f: &mut [S]) {
        f[0] = -p[0] * x[0];
    }
    fn running<S: Sc>(&self, _sw: u64, _t: S, x: &[S], _p: &[S]) -> S {
        x[0]
    }
}

/// Without events or recording the driver never evaluates Verner's nine extra interpolation
/// stages: same steps, bit-identical cost and gradient, 9 fewer evaluations per step than a
/// recorded run (which needs the 9th-order dense output), and both match the closed form.
#[test]
fn verner_skips_interpolation_stages_when_nothing_samples_them() {
    let m = AdModel::new(Decay);
    let p = m.defaults();
    let opts = Options {
        method: Method::Verner9,
        rtol: 1e-12,
        atol: 1e-14,
        ..Options::default()
    };
    let plain = solve(&m, &p, &opts).unwrap();
    let rec = solve(
        &m,
        &p,
        &Options {
            record: true,
            ..opts.clone()
        },
    )
    .unwrap();
    assert_eq!(plain.stats.steps, rec.stats.steps);
    assert_eq!(plain.cost, rec.cost);
    assert_eq!(plain.gradient, rec.gradient);
    assert_eq!(
        rec.stats.rhs_evals - plain.stats.rhs_evals,
        9 * plain.stats.steps
    );
    let a = p[0];
    let c = (1.0 - (-a).exp()) / a;
    let dc = (-a).exp() / a - (1.0 - (-a).exp()) / (a * a);
    approx::assert_relative_eq!(plain.cost, c, max_relative = 1e-11);
    approx::assert_relative_eq!(plain.gradient[0], dc, max_relative = 1e-10);
}

/// ẋ = x², x(0) = 1: x = 1/(1 − t) blows up at t* = 1, inside the horizon 2.
struct BlowUp;

impl Spec for BlowUp {
    fn info(&self) -> ModelInfo {
        info("BlowUp", &["x"], &[("a", 1.0)], &["main"], vec![], &[], 0)
    }
    const T_END: Option<f64> = Some(2.0);
    fn x0<S: Sc>(&self, p: &[S], x: &mut [S]) {
        x[0] = p[0];
    }
    fn rhs<S: Sc>(&self, _m: usize, _sw: u64, _t: S, x: &[S], _p: &[S], f: &mut [S]) {
        f[0] = x[0] * x[0];
    }
    fn running<S: Sc>(&self, _sw: u64, _t: S, x: &[S], _p: &[S]) -> S {
        x[0]
    }
}

/// A run that uses up its step budget while the solution blows up blames stiffness only when
/// stiffness is possible: with the implicit method, or with `auto` (whose stiffness test did
/// not switch), the failure says the steps shrank for another reason and shows the state's
/// size; an explicitly requested explicit method still gets the hint towards `auto`. Without
/// a budget the run stops at the singularity with the state's size in the message.
#[test]
fn a_blow_up_is_not_called_stiffness() {
    let m = AdModel::new(BlowUp);
    for method in Method::ALL {
        let opts = Options {
            method,
            max_steps: 40,
            ..Options::default()
        };
        let err = solve(&m, &m.defaults(), &opts).unwrap_err();
        let SolveError::MaxSteps {
            t,
            not_stiff,
            largest,
            h,
            ..
        } = &err
        else {
            panic!("{method:?}: expected MaxSteps, got {err:?}");
        };
        // x = 1/(1 − t) where the budget ran out, and steps shorter than the way to t*.
        assert!(*t < 1.0, "{method:?}: t = {t}");
        approx::assert_relative_eq!(*largest, 1.0 / (1.0 - t), max_relative = 1e-3);
        assert!(*h < 1.0 - t, "{method:?}: h = {h}, t = {t}");
        let explicit = matches!(method, Method::Tsit5 | Method::Verner9);
        assert_eq!(*not_stiff, !explicit, "{method:?}");
        let msg = err.to_string();
        assert_eq!(
            msg.contains("probably stiff"),
            explicit,
            "{method:?}: {msg}"
        );
        assert!(msg.contains("largest |state|"), "{msg}");
        if !explicit {
            assert!(msg.contains("blow up"), "{method:?}: {msg}");
        }
    }
    let err = solve(&m, &m.defaults(), &Options::default()).unwrap_err();
    match &err {
        SolveError::StepSizeUnderflow { t, largest, .. } => {
            assert!((t - 1.0).abs() < 1e-6, "t = {t}");
            assert!(*largest > 1e6, "largest = {largest}");
        }
        other => panic!("expected StepSizeUnderflow, got {other:?}"),
    }
}
