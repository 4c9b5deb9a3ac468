//! The pieces a step is scanned in (`solve/resolution.rs`) never crawl. Two runs that never
//! ended (found by the `solve` fuzz target): a qp whose switch value is computed with rounding
//! (the cart's objective scaled by 3, so u = k x + c v comes out of a division) and is zero at
//! t = 0, where the resolution of t is absolute; and, at rtol 1e-9, a sliver of 10⁻¹⁷ left at a
//! step's end after which every piece was twice that long. Both now finish, and agree with the
//! same controller written with `min`/`max`, whose switching functions are affine guards
//! (no piece is cut for them).

use mvad::interp::InterpretedModel;
use mvad::Options;
use mvad_tests::{assert_near, model_source, solve_at};

/// The cart with its qp's objective scaled by 3 (the same argmin, other rounding).
fn scaled_qp() -> InterpretedModel {
    let src = model_source("qp_cart.hyb").replace("minimize 0.5 *", "minimize 1.5 *");
    assert!(src.contains("minimize 1.5 *"));
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
    let (qp, reference) = (scaled_qp(), min_max());
    // k, c, umax, e, x0: the defaults; saturation exactly at t = 0 (k x0 = −umax); saturated
    // from the start and leaving it; saturation ending just after the start.
    let cases: [[f64; 5]; 4] = [
        [-2.0, -0.5, 1.0, 0.7, 1.5],
        [-3.0, -0.5, 1.5, 0.7, 0.5],
        [-3.003, -0.5, 1.5, 0.7, 0.5],
        [-3.0, -0.5, 1.49985, 0.7, 0.5],
    ];
    for (rtol, atol) in [(1e-6, 1e-8), (1e-9, 1e-11)] {
        let opts = Options {
            rtol,
            atol,
            ..Options::default()
        };
        for p in cases {
            let a = solve_at(&qp, &p, &opts).expect("the qp run finishes");
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
