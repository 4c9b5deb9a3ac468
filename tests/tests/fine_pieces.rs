//! The pieces a step is scanned in (`solve/resolution.rs`) never crawl. Two runs that never
//! ended (found by the `solve` fuzz target): a qp whose switch value is computed with rounding
//! (the cart's objective scaled by 3, so u = k x + c v comes out of a division) and is zero at
//! t = 0, where the resolution of t is absolute; and, at rtol 1e-9, a sliver of 10⁻¹⁷ left at a
//! step's end after which every piece was twice that long. Both now finish, and agree with the
//! same controller written with `min`/`max`, whose switching functions are affine guards
//! (no piece is cut for them).

use mvad::interp::InterpretedModel;
use mvad::{At, HybridModel, Options};
use mvad_tests::{assert_near, model_source, solve_at};
use nalgebra::DVector;

/// The cart with its qp's objective weighted by `weight` instead of 0.5 (the same argmin,
/// other rounding).
fn scaled_qp(weight: &str) -> InterpretedModel {
    let to = format!("minimize {weight} *");
    let src = model_source("qp_cart.hyb").replace("minimize 0.5 *", &to);
    assert!(src.contains(&to));
    InterpretedModel::from_source(&src).expect("loads")
}

/// The cart with u = max(−umax, min(umax, k x + c v)).
fn min_max() -> InterpretedModel {
    let src = model_source("qp_cart.hyb");
    let start = src.find("    qp ctl").expect("the qp");
    let end = start + src[start..].find("    }\n").expect("its end") + 6;
    let src = format!("{}{}", &src[..start], &src[end..])
        .replace("ctl.u", "max(-umax, min(umax, k*x + c*v))");
    InterpretedModel::from_source(&src).expect("loads")
}

#[test]
fn a_qp_switch_value_zero_at_the_start_or_a_sliver_at_a_step_end_do_not_crawl() {
    let qp = scaled_qp("1.5");
    // k, c, umax, e, x0: the defaults; saturation exactly at t = 0 (k x0 = −umax); saturated
    // from the start and leaving it; saturation ending just after the start.
    let cases: [[f64; 5]; 4] = [
        [-2.0, -0.5, 1.0, 0.7, 1.5],
        [-3.0, -0.5, 1.5, 0.7, 0.5],
        [-3.003, -0.5, 1.5, 0.7, 0.5],
        [-3.0, -0.5, 1.49985, 0.7, 0.5],
    ];
    agree_with_min_max(&qp, &cases, &[(1e-6, 1e-8), (1e-9, 1e-11)]);
}

/// A qp slack far from zero whose rounding is far above 64 ε of its value: the lower bound's
/// slack u + umax = 2 of a cart saturated at u = umax comes out of terms of order k x (170 at
/// k = 64), and failed the Hermite check at every cut, so pieces of 10⁻¹³ crawled (a run
/// that never ended, found by the `solve` fuzz target); with weight 5.5 on the bundled cart
/// the crawl was a slow run. A function that keeps to one side of zero by far more than it is
/// seen to vary is resolved.
#[test]
fn a_qp_slack_far_from_zero_with_rounding_from_large_terms_does_not_crawl() {
    let tols = [(1e-6, 1e-8), (1e-9, 1e-11)];
    agree_with_min_max(&scaled_qp("1.5"), &[[64.0, -0.5, 1.0, 0.7, 1.5]], &tols);
    agree_with_min_max(&scaled_qp("5.5"), &[[-2.0, -0.5, 1.0, 0.7, 1.5]], &tols);
}

/// Saturation at t = 0 that releases at once: the switch value stands at the rounding of
/// zero (10⁻¹⁶ from terms of order 1) for 10⁻¹⁶ of time. At rtol 1e-4 a cut of 10⁻²⁹ passed
/// there, where 64 ε |v| exceeds the rates' swing, and the pieces crawled at that scale (a
/// run that did not end in a minute); with weight 13 the weakly active switch's rate was the
/// multiplier's, 26 times the slack it belongs to, and every piece failed (0.5 s).
#[test]
fn a_switch_value_standing_at_the_rounding_of_zero_does_not_crawl() {
    let tols = [(1e-4, 1e-6), (1e-6, 1e-8)];
    agree_with_min_max(
        &scaled_qp("1.5"),
        &[[-3.0, -1.0759965450898261, 1.5, 0.7, 0.5]],
        &tols,
    );
    agree_with_min_max(
        &scaled_qp("13"),
        &[[-3.0, -0.8305334154991391, 1.0, 0.7, 0.5]],
        &tols,
    );
}

/// In the band where a qp constraint is weakly active (slack and multiplier zero within the
/// tolerance) its switch value σ = s + μ is its slack s or its multiplier μ; the gradient is
/// that of the one σ is (by its sign), not of the other, whose scale differs by the
/// objective's weight (2 · 13 here). Checked against central differences of σ in x.
#[test]
fn a_weakly_active_qp_switch_has_the_gradient_of_its_value() {
    let m = scaled_qp("13");
    let (k, c, umax) = (-3.0, -0.5, 1.0);
    let p = DVector::from_vec(vec![k, c, umax, 0.7, 0.5]);
    // At u = k x = −0.6 the slacks are u − umax = −1.6 and −u − umax = −0.4.
    let x = DVector::from_vec(vec![0.2, 0.0]);
    let lower = (0..m.info().switches)
        .find(|&j| (m.switch_value(j, At::new(0.0, &x, &p)) + 0.4).abs() < 1e-12)
        .expect("the lower bound's switch");
    for delta in [-1e-11, 1e-11] {
        // k x + c v = −umax − δ: a slack of ±10⁻¹¹ on u ≥ −umax, within the tolerance.
        let x = DVector::from_vec(vec![(-umax - delta) / k, 0.0]);
        let sigma = m.switch_value(lower, At::new(0.0, &x, &p));
        let (mut gx, mut gp) = (DVector::zeros(2), DVector::zeros(5));
        m.switch_grad(lower, At::new(0.0, &x, &p), &mut gx, &mut gp);
        let h = 1e-14;
        let fd = |i: usize| {
            let (mut up, mut down) = (x.clone(), x.clone());
            up[i] += h;
            down[i] -= h;
            let sv = |y: &DVector<f64>| m.switch_value(lower, At::new(0.0, y, &p));
            (sv(&up) - sv(&down)) / (2.0 * h)
        };
        let what = format!("σ = {sigma:e} at δ = {delta:e}");
        assert!(sigma.abs() < 1e-9, "{what}: not in the band");
        assert_near(gx[0], fd(0), 1e-2, format!("∂σ/∂x, {what}"));
    }
}

/// The qp cart at each parameter set (k, c, umax, e, x0), at each (rtol, atol): under 2000
/// steps, and C and dC/dθ within 1e3·rtol of the cart with u = max(−umax, min(umax, k x + c v)).
fn agree_with_min_max(qp: &InterpretedModel, cases: &[[f64; 5]], tols: &[(f64, f64)]) {
    let reference = min_max();
    for &(rtol, atol) in tols {
        let opts = Options {
            rtol,
            atol,
            ..Options::default()
        };
        for &p in cases {
            let a = solve_at(qp, &p, &opts).expect("the qp run finishes");
            let b = solve_at(&reference, &p, &opts).expect("the min/max run finishes");
            let what = format!("{p:?} at rtol {rtol:e}");
            assert!(a.stats.steps < 2_000, "{what}: {} steps", a.stats.steps);
            assert_near(a.cost, b.cost, 1e3 * rtol, format!("C {what}"));
            for i in 0..p.len() {
                assert_near(
                    a.gradient[i],
                    b.gradient[i],
                    1e3 * rtol,
                    format!("dC/dθ{i} {what}"),
                );
            }
        }
    }
}
