//! Closed-form checks of the driver under every method (the matrix of
//! [`common::cases`]): the E1 ball (∫h, ∫v, ∫h², v(T), Σ v⁺², all four parameters), E2
//! first impacts, a two-mode thermostat, a stiff relay, a ceiling bounce near grazing, a
//! kink in the flow, Zeno balls, simultaneous and double crossings. Closed forms are derived
//! by hand (piecewise polynomials, exponentials and logs) and differentiated exactly with
//! dual numbers; the references are also checked against central finite differences.

mod common;

use approx::assert_relative_eq;
use common::ball::flights;
use common::cases::{cases, flights_dual, run_matrix};
use common::check::close;
use common::models::thermostat_closed;
use common::D;
use mvad_runtime::fixtures::Ball;
use mvad_runtime::solution::Method;
use nalgebra::DVector;

/// Every case under every method it applies to, except the [`KNOWN_FAILURES`]; all
/// failures are reported at once.
#[test]
fn closed_forms_under_every_method() {
    run_matrix(cases(), 40 * 4);
}

/// The closed form reproduces DESIGN.md's reference values of E1 (at the fixture's θ).
#[test]
fn e1_reference_values() {
    let ball = Ball::new();
    let p = ball.default_params();
    let (cf, impacts) = flights_dual(p.as_slice(), 2.0);
    assert_relative_eq!(impacts[0], 0.638_550_856_814_101, max_relative = 1e-15);
    assert_relative_eq!(impacts[1], 1.660_232_227_716_662_4, max_relative = 1e-15);
    assert_relative_eq!(cf[0].v, 1.890_513_712_317_350_6, max_relative = 1e-15);
    assert_relative_eq!(cf[0].g[0], 2.831_440_814_147_005_5, max_relative = 1e-14);
}

/// Asserts that central differences of `f` at `p` with steps `hs` match `grad` (each
/// coordinate, [`close`] with `rel`, `abs`).
fn assert_fd(
    what: &str,
    f: impl Fn(&DVector<f64>) -> f64,
    p: &DVector<f64>,
    grad: &[f64],
    hs: &[f64],
    rel: f64,
    abs: f64,
) {
    for (i, gi) in grad.iter().enumerate() {
        for &h in hs {
            let fd = common::central(&f, p, i, h);
            assert!(
                close(fd, *gi, rel, abs),
                "{what} param {i} h {h}: fd {fd} dual {gi}"
            );
        }
    }
}

/// The ball's closed form itself against central differences (so the reference is not wrong).
#[test]
fn ball_closed_form_agrees_with_finite_differences() {
    let p = DVector::from_vec(vec![0.8, 9.81, 2.0, 0.3]);
    let (cf, _) = flights_dual(p.as_slice(), 2.0);
    for (c, cfc) in cf.iter().enumerate() {
        let f = |q: &DVector<f64>| flights(q[0], q[1], q[2], q[3], 2.0).0[c];
        assert_fd(
            &format!("cost {c}"),
            f,
            &p,
            &cfc.g[..4],
            &[1e-4, 1e-5, 1e-6],
            1e-6,
            1e-8,
        );
    }
}

/// The thermostat's closed form against central differences of itself.
#[test]
fn thermostat_closed_form_agrees_with_finite_differences() {
    let p = [0.5, 18.0, 22.0, 10.0];
    let d = |i: usize| D::var(p[i], i);
    let (_, c2, _) = thermostat_closed(d(0), d(1), d(2), d(3), 10.0);
    let f = |q: &DVector<f64>| thermostat_closed(q[0], q[1], q[2], q[3], 10.0).1;
    let pv = DVector::from_column_slice(&p);
    assert_fd("∫(temp − 20)²", f, &pv, &c2.g[..4], &[1e-6], 1e-6, 1e-7);
}

/// The matrix covers every method.
#[test]
fn every_method_is_in_the_matrix() {
    let all = cases();
    for method in Method::ALL {
        assert!(all.iter().filter(|c| c.methods.contains(&method)).count() >= 40);
    }
}

/// The matrix can fail: a solution whose cost, gradient or event time is off by more than
/// the tolerances is reported by its case's check.
#[test]
fn the_checks_catch_a_perturbed_solution() {
    let all = cases();
    let case = all.iter().find(|c| c.name == "E1 fixture").expect("E1");
    let tol = common::cases::tol(Method::Auto);
    let sol = (case.run)(&case.opts).expect("E1 solves");
    let check = |sol: &mvad_runtime::solution::Solution| {
        let mut r = common::check::Report::default();
        (case.check)(sol, tol, 0.0, &mut r);
        r.0
    };
    assert!(check(&sol).is_empty(), "{:?}", check(&sol));
    let mut off = sol.clone();
    off.cost *= 1.0 + 1e-8;
    assert_eq!(check(&off).len(), 1);
    let mut off = sol.clone();
    off.gradient[0] *= 1.0 + 1e-7;
    assert_eq!(check(&off).len(), 1);
    let mut off = sol;
    off.events[1].t += 1e-9;
    assert_eq!(check(&off).len(), 1);
}
