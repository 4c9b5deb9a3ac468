//! Qps inside the dynamics: a change of the active set along the trajectory is a kink of
//! the flow, located by the qp's switching functions (σᵢ = slack + multiplier) and crossed
//! with the saltation update, so the gradient stays exact across it.
//!
//! The brief's test: a cart driven by u = argmin ½(u − kx − cv)² s.t. |u| ≤ u_max, with a
//! wall impact event, against the same model written with `min`/`max` (to 1e-10) and
//! against central finite differences; a two-variable controller with a coupled
//! constraint and an equality against finite differences; compiled and loaded alike.

use models::qp_cart::{QpCart, MINMAX_SOURCE};
use mvad::interp::InterpretedModel;
use mvad::{fd_gradient, solve, HybridModel, ModelAlloc, Options, Solution};
use mvad_tests::{assert_near, model_source, tight};
use nalgebra::DefaultAllocator;

/// Two controls sharing a budget, one pinned by an equality: u₁ + u₂ ≤ b, u₁ − u₂ = d·x.
const TWO_CONTROLS: &str = include_str!("two_controls.hyb");

fn run<M: HybridModel>(m: &M, p: &nalgebra::OVector<f64, M::P>) -> Solution
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    solve(m, p, &tight()).expect("solves")
}

/// The smallest relative error of `grad[i]` against central differences at three steps.
fn fd_error<M: HybridModel>(m: &M, p: &nalgebra::OVector<f64, M::P>, grad: &[f64], i: usize) -> f64
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    [1e-4, 1e-5, 1e-6]
        .iter()
        .map(|&h| {
            let fd = fd_gradient(m, p, &tight(), i, h).expect("fd");
            (fd - grad[i]).abs() / grad[i].abs().max(1.0)
        })
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn cart_with_a_saturating_qp_matches_min_max_and_fd() {
    let qp = InterpretedModel::from_source(&model_source("qp_cart.hyb")).expect("loads");
    let mm = InterpretedModel::from_source(MINMAX_SOURCE).expect("loads");
    let cc = QpCart::new();
    let p = qp.default_params();
    let (sq, sm) = (run(&qp, &p), run(&mm, &p));
    let sc = run(&cc, &cc.default_params());
    // Saturated at the start, released, saturated again after the impact: three
    // active-set changes, each a located switch crossing (as min/max's kinks are).
    assert_eq!(sq.stats.switch_crossings, 3);
    assert_eq!(sm.stats.switch_crossings, 3);
    assert_eq!(sq.events.len(), 1);
    assert!((sq.cost - sm.cost).abs() <= 1e-10 * sm.cost.abs());
    assert!((sc.cost - sq.cost).abs() <= 1e-13 * sq.cost.abs());
    for i in 0..p.len() {
        let (a, b, c) = (sq.gradient[i], sm.gradient[i], sc.gradient[i]);
        assert_near(a, b, 1e-10, format_args!("param {i}: qp vs min/max"));
        assert_near(c, a, 1e-12, format_args!("param {i}: compiled vs loaded"));
        let err = fd_error(&qp, &p, &sq.gradient, i);
        eprintln!(
            "cart param {i}: qp {a:.15e}, |qp − min/max| {:.1e}, |compiled − loaded| {:.1e}, FD rel err {err:.1e}",
            (a - b).abs(),
            (c - a).abs()
        );
        assert!(err <= 1e-6, "param {i}: FD error {err:e}");
    }
}

#[test]
fn cart_under_the_implicit_method_matches_min_max() {
    // Rodas5P uses the second-order products: the qp model's are difference quotients
    // (its flow reads a qp of the state), min/max's are symbolic; both converge together.
    let qp = InterpretedModel::from_source(&model_source("qp_cart.hyb")).expect("loads");
    let mm = InterpretedModel::from_source(MINMAX_SOURCE).expect("loads");
    let cc = QpCart::new();
    let opts = Options {
        method: mvad::Method::Rosenbrock,
        ..tight()
    };
    let p = qp.default_params();
    let sq = solve(&qp, &p, &opts).expect("solves");
    let sm = solve(&mm, &p, &opts).expect("solves");
    let sc = solve(&cc, &cc.default_params(), &opts).expect("solves");
    assert_eq!(sq.stats.switch_crossings, 3);
    for i in 0..p.len() {
        let (a, b, c) = (sq.gradient[i], sm.gradient[i], sc.gradient[i]);
        eprintln!(
            "rosenbrock cart param {i}: |qp − min/max| {:.1e}, |compiled − loaded| {:.1e}",
            (a - b).abs(),
            (c - a).abs()
        );
        assert_near(a, b, 1e-8, format_args!("param {i}: qp vs min/max"));
        assert_near(c, a, 1e-10, format_args!("param {i}: compiled vs loaded"));
    }
}

#[test]
fn two_controls_with_a_coupled_constraint_against_fd() {
    let m = InterpretedModel::from_source(TWO_CONTROLS).expect("loads");
    let p = m.default_params();
    let sol = run(&m, &p);
    assert!(sol.stats.switch_crossings >= 1, "{:?}", sol.stats);
    for i in 0..p.len() {
        let err = fd_error(&m, &p, &sol.gradient, i);
        eprintln!("two controls param {i}: FD rel err {err:.1e}");
        assert!(err <= 1e-6, "param {i}: FD error {err:e}");
    }
}
