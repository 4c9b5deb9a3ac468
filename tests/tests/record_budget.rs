//! The adjoint's record grows with the number of events (a jump per event); a run whose
//! record would pass `Options::max_record_bytes` is computed in forward mode instead, with a
//! `record_budget` diagnostic: never an allocation the machine cannot hold (probe2 C2: `every
//! 1e-9` on [0, 1] asked for a 360 GB record).

use mvad::runtime::solution::{DiagnosticKind, GradientMode, Options};
use mvad::runtime::vjp::{vjp, Cotangents};
use nalgebra::DVector;

fn opts(mode: GradientMode, budget: usize) -> Options {
    Options {
        rtol: 1e-10,
        atol: 1e-12,
        gradient_mode: mode,
        max_record_bytes: budget,
        t_end: Some(10.0),
        ..Options::default()
    }
}

#[test]
fn an_adjoint_record_past_its_budget_hands_over_to_forward_mode() {
    // 100 samples of the sampled loop (period 0.1 over [0, 10]).
    let m = mvad_tests::loaded_test_model("sampled.hyb");
    let p = DVector::from_vec(vec![2.0, 0.1, 1.5]);
    let forward = mvad::solve(&m, &p, &opts(GradientMode::Forward, 2 << 30)).unwrap();
    let adjoint = mvad::solve(&m, &p, &opts(GradientMode::Adjoint, 2 << 30)).unwrap();
    assert_eq!(adjoint.stats.mode, GradientMode::Adjoint);
    assert!(adjoint.stats.record_bytes > 20_000, "{:?}", adjoint.stats);
    assert!(!adjoint
        .diagnostics
        .iter()
        .any(|d| d.kind == DiagnosticKind::RecordBudget));
    for (a, f) in adjoint.gradient.iter().zip(&forward.gradient) {
        assert!((a - f).abs() <= 1e-7 * f.abs().max(1.0), "{a} vs {f}");
    }

    // A budget of a fifth of that record: forward mode, the same numbers as a forward run.
    let budget = adjoint.stats.record_bytes / 5;
    let over = mvad::solve(&m, &p, &opts(GradientMode::Adjoint, budget)).unwrap();
    assert_eq!(over.stats.mode, GradientMode::Forward);
    assert_eq!(over.stats.record_bytes, 0);
    assert_eq!(over.cost, forward.cost);
    assert_eq!(over.gradient, forward.gradient);
    let d = over
        .diagnostics
        .iter()
        .find(|d| d.kind == DiagnosticKind::RecordBudget)
        .expect("a record_budget diagnostic");
    assert!(
        d.message.contains(&format!("{budget} bytes")) && d.message.contains("forward mode"),
        "{}",
        d.message
    );
    assert_eq!(d.kind.name(), "record_budget");
    // `t` is where the record passed the budget (the primal run stopped there).
    assert!(d.t > 0.0 && d.t < 10.0, "{}", d.t);

    // The vector–Jacobian product takes the same way (samples of x at t = 5 and T).
    let times = [5.0, 10.0];
    let nobs = mvad::HybridModel::info(&m).nobservables();
    let w: Vec<f64> = (0..times.len() * nobs)
        .map(|i| 1.0 / (1 + i) as f64)
        .collect();
    let cot = Cotangents {
        cost: 1.0,
        times: &times,
        observables: &w,
    };
    let fwd = vjp(&m, &p, &opts(GradientMode::Forward, budget), &cot).unwrap();
    let pulled = vjp(&m, &p, &opts(GradientMode::Adjoint, budget), &cot).unwrap();
    assert_eq!(pulled.solution.stats.mode, GradientMode::Forward);
    assert_eq!(pulled.solution.gradient, fwd.solution.gradient);
}
