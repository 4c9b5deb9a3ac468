//! Qp layers through both doors: the paper's E3 (`models/qp_kink.hyb`) swept over 101
//! points of θ ∈ [−1, 1] against its closed form (counts of active, boundary and inactive
//! points, mean error of dJ/dθ, the kink at θ = 0 with both one-sided derivatives), and the
//! compiled and loaded models agreeing.

use models::qp_kink::{self, QpKink};
use mvad::interp::InterpretedModel;
use mvad::qp::ConstraintStatus;
use mvad::{solve, DiagnosticKind, HybridModel, ModelAlloc, Options};
use mvad_tests::{assert_near, model_source, tight};
use nalgebra::{DefaultAllocator, OVector};

/// θ_i = (i − 50)/50, i = 0..=100: θ = 0 exactly at i = 50.
fn thetas() -> impl Iterator<Item = f64> {
    (0..=100).map(|i| (i as f64 - 50.0) / 50.0)
}

/// (active, boundary, inactive) counts and the mean |dJ/dθ − θH(θ)| of the E3 sweep.
fn e3_sweep<M: HybridModel>(m: &M) -> ((usize, usize, usize), f64)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let (mut counts, mut err) = ((0, 0, 0), 0.0);
    for theta in thetas() {
        let p =
            OVector::<f64, M::P>::from_element_generic(m.nparams(), nalgebra::Const::<1>, theta);
        let sol = solve(m, &p, &Options::default()).expect("E3 solves");
        assert_eq!(sol.qp.len(), 1);
        let u = sol.qp[0].u[0];
        assert_eq!(u, qp_kink::solution(theta));
        assert_eq!(sol.cost, 0.5 * u * u);
        err += (sol.gradient[0] - qp_kink::gradient(theta)).abs();
        let kink = sol.diagnostic(DiagnosticKind::Kink).is_some();
        match sol.qp[0].status[0] {
            ConstraintStatus::Active => counts.0 += 1,
            ConstraintStatus::WeaklyActive => {
                counts.1 += 1;
                assert_eq!(theta, 0.0);
                assert!(kink);
                // dJ/dθ = u du/dθ = 0 on both sides at u = 0.
                assert_eq!(sol.gradient_left.as_deref(), Some(&[0.0][..]));
            }
            ConstraintStatus::Inactive => counts.2 += 1,
        }
        if sol.qp[0].status[0] != ConstraintStatus::WeaklyActive {
            assert!(!kink && sol.gradient_left.is_none());
        }
    }
    (counts, err / 101.0)
}

#[test]
fn e3_sweep_compiled_and_loaded() {
    let loaded = InterpretedModel::from_source(&model_source("qp_kink.hyb")).expect("loads");
    for (counts, mean) in [e3_sweep(&QpKink::new()), e3_sweep(&loaded)] {
        eprintln!("E3 sweep: counts {counts:?}, mean |dJ/dθ − θH(θ)| = {mean:e}");
        assert_eq!(counts, (50, 1, 50));
        assert!(mean <= 1e-15, "mean error {mean}");
    }
}

/// J = u*(θ) itself: du/dθ at the kink θ = 0 is 0 from the left and 1 from the right.
mod linear_cost {
    mvad::hybrid! {
        model QpLinear {
            param theta = 0.0;
            qp u_star(u) { minimize 0.5 * u^2 - theta * u; subject to u >= 0; }
            cost = u_star.u;
        }
    }
}

const LINEAR: &str = "model QpLinear { param theta = 0.0;
    qp u_star(u) { minimize 0.5 * u^2 - theta * u; subject to u >= 0; }
    cost = u_star.u; }";

fn one_sided_at_zero<M: HybridModel>(m: &M) -> (f64, Option<f64>)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let p = OVector::<f64, M::P>::zeros_generic(m.nparams(), nalgebra::Const::<1>);
    let sol = solve(m, &p, &Options::default()).expect("solves");
    assert!(sol
        .diagnostics
        .iter()
        .any(|d| d.kind == DiagnosticKind::Kink
            && d.message.contains("`u_star`")
            && d.message.contains("constraint 0")));
    (sol.gradient[0], sol.gradient_left.map(|g| g[0]))
}

#[test]
fn e3_du_dtheta_at_the_kink_is_one_sided() {
    let loaded = InterpretedModel::from_source(LINEAR).expect("loads");
    assert_eq!(
        one_sided_at_zero(&linear_cost::QpLinear::new()),
        (1.0, Some(0.0))
    );
    assert_eq!(one_sided_at_zero(&loaded), (1.0, Some(0.0)));
}

/// A qp of the state read pointwise: in a guard, a reset, an observable and the final cost
/// (`tests/projected.hyb`).
mod projected {
    mvad::hybrid!(include "tests/projected.hyb");
}

const PROJECTED: &str = include_str!("projected.hyb");

#[test]
fn pointwise_qps_of_the_state_against_finite_differences() {
    let compiled = projected::Projected::new();
    let loaded = InterpretedModel::from_source(PROJECTED).expect("loads");
    let pc = compiled.default_params();
    let pl = loaded.default_params();
    let sc = solve(&compiled, &pc, &tight()).expect("compiled solves");
    let sl = solve(&loaded, &pl, &tight()).expect("loaded solves");
    // The event fires, no qp is at a kink at T, and the doors agree.
    assert_eq!(sc.events.len(), 1, "{:?}", sc.events);
    assert!(sc
        .diagnostics
        .iter()
        .all(|d| d.kind != DiagnosticKind::Kink));
    assert!((sc.cost - sl.cost).abs() <= 1e-13 * sc.cost.abs());
    for (a, b) in sc.gradient.iter().zip(&sl.gradient) {
        assert_near(*b, *a, 1e-12, "loaded vs compiled gradient");
    }
    assert_eq!(sc.qp[0].status, sl.qp[0].status);
    // Central differences at three steps: the best agrees to 1e-7.
    for i in 0..4 {
        let best = [1e-4, 1e-5, 1e-6]
            .iter()
            .map(|&h| {
                let fd = mvad::fd_gradient(&compiled, &pc, &tight(), i, h).expect("fd");
                (fd - sc.gradient[i]).abs() / sc.gradient[i].abs().max(1.0)
            })
            .fold(f64::INFINITY, f64::min);
        eprintln!("projected param {i}: FD rel err {best:.1e}");
        assert!(best <= 1e-7, "param {i}: {best:e}");
    }
}

#[test]
fn an_infeasible_qp_is_a_located_run_error() {
    let src = "model Bad { param a = 1;
        qp q(u) { minimize u^2; subject to u >= a; u <= 0; }
        cost = q.u; }";
    let m = InterpretedModel::from_source(src).expect("loads");
    let e = solve(&m, &m.default_params(), &Options::default()).expect_err("infeasible");
    assert_eq!(
        e.to_string(),
        "qp `q` at t = 0: qp is infeasible: constraint 1 cannot be satisfied"
    );
    // Feasible again at a ≤ 0.
    let p = OVector::<f64, nalgebra::Dyn>::from_element(1, -0.5);
    assert_eq!(
        solve(&m, &p, &Options::default()).expect("feasible").cost,
        0.0
    );
}
