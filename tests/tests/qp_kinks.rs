//! Kinks of the cost in θ that qps make: a constraint weakly active *along* a flow (its
//! one-sided derivative follows, column by column of S, the piece the direction selects), a
//! qp read by an event where it is weakly active, and one read by the final cost at T. Both doors, forward and
//! adjoint modes, against closed forms.

use mvad::interp::InterpretedModel;
use mvad::{DiagnosticKind, GradientMode, HybridModel, ModelAlloc, Options, Solution};
use mvad_tests::{assert_near, loaded_test_model, solve_at, tight};
use nalgebra::DefaultAllocator;

mvad::hybrid!(include "tests/qp_weak_flow.hyb");
mvad::hybrid!(include "tests/qp_weak_interval.hyb");

const E: f64 = std::f64::consts::E;

fn adjoint() -> Options {
    Options {
        gradient_mode: GradientMode::Adjoint,
        ..tight()
    }
}

/// Solves and checks `gradient` (right) and `gradient_left` (the same away from a kink,
/// where the solution leaves it out) against closed forms, to `tol`.
#[track_caller]
fn check<M: HybridModel>(
    m: &M,
    p: &[f64],
    opts: &Options,
    right: &[f64],
    left: &[f64],
    tol: f64,
) -> Solution
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let sol = solve_at(m, p, opts).expect("solves");
    let gl = (sol.gradient_left.clone()).unwrap_or_else(|| sol.gradient.clone());
    for i in 0..right.len() {
        assert_near(
            sol.gradient[i],
            right[i],
            tol,
            format_args!("right, param {i}"),
        );
        assert_near(gl[i], left[i], tol, format_args!("left, param {i}"));
        eprintln!(
            "param {i}: right {:.15e} (err {:.1e}), left {:.15e} (err {:.1e})",
            sol.gradient[i],
            (sol.gradient[i] - right[i]).abs(),
            gl[i],
            (gl[i] - left[i]).abs()
        );
    }
    sol
}

/// Both doors (the loaded model, then the compiled one) in both modes, forward then adjoint,
/// at θ = `p`, each checked by [`check`]: the four (options, solution) pairs.
#[track_caller]
fn both_doors<A: HybridModel, B: HybridModel>(
    loaded: &A,
    compiled: &B,
    p: &[f64],
    right: &[f64],
    left: &[f64],
    tol: f64,
) -> Vec<(Options, Solution)>
where
    DefaultAllocator: ModelAlloc<A::N, A::P> + ModelAlloc<B::N, B::P>,
{
    let mut out = Vec::with_capacity(4);
    for opts in [tight(), adjoint()] {
        let a = check(loaded, p, &opts, right, left, tol);
        let b = check(compiled, p, &opts, right, left, tol);
        out.extend([(opts.clone(), a), (opts, b)]);
    }
    out
}

/// Whether the run reported a `kink` diagnostic.
fn has_kink(sol: &Solution) -> bool {
    sol.diagnostics
        .iter()
        .any(|d| d.kind == DiagnosticKind::Kink)
}

/// A smooth run: no `kink` diagnostic, and the gradient mode asked for kept.
#[track_caller]
fn assert_smooth(sol: &Solution, opts: &Options) {
    assert!(!has_kink(sol));
    assert_eq!(sol.stats.mode, opts.gradient_mode);
}

/// The `kink` diagnostic of a qp kink along the flow, with the constraint and the time.
fn flow_kink(sol: &Solution) -> &mvad::Diagnostic {
    sol.diagnostics
        .iter()
        .find(|d| d.kind == DiagnosticKind::Kink && d.message.contains("along the flow"))
        .expect("a kink along the flow is reported")
}

#[test]
fn a_constraint_weakly_active_along_the_whole_run_has_both_one_sided_gradients() {
    // x0 then k: dC/dx0 = e − 1 both sides, dC/dk 0 from the right, e − 2 from the left.
    let (right, left) = ([E - 1.0, 0.0], [E - 1.0, E - 2.0]);
    let loaded = loaded_test_model("qp_weak_flow.hyb");
    let compiled = QpWeakFlow::new();
    let runs = both_doors(&loaded, &compiled, &[2.0, 0.0], &right, &left, 1e-9);
    for (i, (opts, sol)) in runs.iter().enumerate() {
        if i % 2 == 0 {
            assert!(
                sol.gradient_left.is_some(),
                "the loaded door's left gradient"
            );
        }
        let d = flow_kink(sol);
        assert!(d.message.contains("qp `q`, constraint 0"), "{}", d.message);
        assert_eq!(d.t, 0.0);
        // The adjoint cannot sweep a persistent kink: forward mode computed it, and says so.
        assert_eq!(sol.stats.mode, GradientMode::Forward);
        if opts.gradient_mode == GradientMode::Adjoint {
            assert!(d.message.contains("forward mode"), "{}", d.message);
        }
    }
}

#[test]
fn off_the_kink_the_run_is_smooth_and_agrees_with_the_one_sided_limits() {
    // k = ∓1e-7: strictly active / inactive along the run, no kink; the gradients are the
    // left / right values at k = 0 up to O(k).
    let m = loaded_test_model("qp_weak_flow.hyb");
    for (k, want) in [(-1e-7, E - 2.0), (1e-7, 0.0)] {
        let sol = solve_at(&m, &[2.0, k], &tight()).expect("solves");
        assert!(!sol
            .diagnostics
            .iter()
            .any(|d| d.message.contains("along the flow")));
        assert_near(
            sol.gradient[1],
            want,
            1e-6,
            format_args!("dC/dk at k = {k}"),
        );
    }
}

#[test]
fn a_kink_on_part_of_the_run_ending_at_a_crossing_or_not() {
    let loaded = loaded_test_model("qp_weak_interval.hyb");
    let compiled = QpWeakInterval::new();
    let h = 0.5f64.exp();
    // a = 1: the constraint turns active at t = 1/2, a switch crossing.
    let da = -(h - 13.0 / 8.0);
    let right = [E - 1.0, h - 1.5, da];
    let left = [E - 1.0, E - 2.0, da];
    // a = −1: it turns inactive at t = 1/2.
    let right2 = [E - 1.0, 0.0, 0.0];
    let left2 = [E - 1.0, h - 1.5 + (h - 1.0).powi(2), 0.0];
    for (a, r, l) in [(1.0, &right, &left), (-1.0, &right2, &left2)] {
        for (_, sol) in both_doors(&loaded, &compiled, &[2.0, 0.0, a], r, l, 1e-9) {
            assert_eq!(flow_kink(&sol).t, 0.0);
            assert_eq!(sol.stats.switch_crossings, if a > 0.0 { 2 } else { 1 });
        }
    }
}

#[test]
fn a_transversal_qp_crossing_is_not_a_kink() {
    // The cart's qp changes its active set three times, each a transversal crossing: no
    // kink along the flow, and the adjoint keeps the run.
    let m = InterpretedModel::from_source(&mvad_tests::model_source("qp_cart.hyb")).expect("loads");
    for opts in [tight(), adjoint()] {
        let sol = solve_at(&m, &m.info().param_defaults, &opts).expect("solves");
        assert_eq!(sol.stats.switch_crossings, 3);
        assert_smooth(&sol, &opts);
    }
}

mvad::hybrid!(include "tests/qp_reset_kink.hyb");
mvad::hybrid!(include "tests/qp_event_kink.hyb");

/// The `kink` diagnostic of a qp read by an event.
fn event_kink<'a>(sol: &'a Solution, event: &str) -> &'a mvad::Diagnostic {
    sol.diagnostics
        .iter()
        .find(|d| d.kind == DiagnosticKind::Kink && d.message.contains(&format!("event `{event}`")))
        .expect("a kink where the event reads the qp is reported")
}

#[test]
fn a_qp_read_by_a_reset_at_its_kink_mid_run() {
    // probe2 q15: C = (5 − c − d)·max(c + d − e, 0) at c + d = e = 3/2.
    let (right, left) = ([3.5, 3.5, 0.0], [0.0, 0.0, -3.5]);
    let loaded = loaded_test_model("qp_reset_kink.hyb");
    let compiled = QpResetKink::new();
    for (_, sol) in both_doors(&loaded, &compiled, &[1.0, 0.5, 1.5], &right, &left, 1e-12) {
        let d = event_kink(&sol, "hit");
        assert!(d.message.contains("qp `q2`, constraint 0"), "{}", d.message);
        assert_near(d.t, 1.5, 1e-14, "the kink's time");
        assert_eq!(sol.stats.mode, GradientMode::Forward);
    }
}

#[test]
fn each_parameter_crosses_an_event_kink_on_its_own_side() {
    // C = 3·max(v·tau − e, 0) at v·tau = e: tau moves x⁻ backwards (f⁻ t' = v < 0), so its
    // right derivative is 0 and its left one −3, unlike v's.
    let (right, left) = ([4.5, 0.0, 0.0], [0.0, -3.0, -3.0]);
    let loaded = loaded_test_model("qp_event_kink.hyb");
    let compiled = QpEventKink::new();
    for (opts, sol) in both_doors(&loaded, &compiled, &[-1.0, 1.5, -1.5], &right, &left, 1e-12) {
        assert_eq!(event_kink(&sol, "hit").t, 1.5);
        assert_eq!(sol.stats.mode, GradientMode::Forward);
        if opts.gradient_mode == GradientMode::Adjoint {
            let d = event_kink(&sol, "hit");
            assert!(d.message.contains("forward mode"), "{}", d.message);
        }
    }
    // Off the kink (e = −1.6: the argument is 0.1): ∇C = 3·(tau, v, −1).
    smooth_in_both_modes(&loaded, &[-1.0, 1.5, -1.6], &[4.5, -3.0, -3.0]);
}

/// Off a kink the run is smooth in both modes: no `kink` diagnostic, the mode asked for, and
/// ∇C = `grad` to 1e-12.
#[track_caller]
fn smooth_in_both_modes(m: &InterpretedModel, p: &[f64], grad: &[f64]) {
    for opts in [tight(), adjoint()] {
        let sol = check(m, p, &opts, grad, grad, 1e-12);
        assert_smooth(&sol, &opts);
    }
}

mvad::hybrid!(include "tests/qp_final_kink.hyb");

#[test]
fn a_final_cost_kink_at_t_follows_each_parameters_side() {
    // C = 3·max(v·T − e, 0) at v·T = e: T moves x(T) backwards (f dT = v < 0), so its right
    // derivative is 0 and its left one −3, like e's and unlike v's. Adjoint mode hands the
    // run over to forward mode (each parameter's side is not linear in a cotangent).
    let (right, left) = ([4.5, 0.0, 0.0], [0.0, -3.0, -3.0]);
    let loaded = loaded_test_model("qp_final_kink.hyb");
    let compiled = TKink::new();
    for (_, sol) in both_doors(&loaded, &compiled, &[-1.0, 1.5, -1.5], &right, &left, 1e-12) {
        assert_eq!(sol.stats.mode, GradientMode::Forward);
        assert!(has_kink(&sol));
    }
    // Off the kink (e = −1.6: the argument is 0.1): ∇C = 3·(T, v, −1).
    smooth_in_both_modes(&loaded, &[-1.0, 1.5, -1.6], &[4.5, -3.0, -3.0]);
}
