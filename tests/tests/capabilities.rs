//! The capability defaults of the model traits against their mathematics on a small model with
//! known second derivatives: f = (a x², a sin x), θ = (a).

use mvad::{ModelAdjoint, ModelSecondOrder, Switches};
use nalgebra::{Matrix2x1, Vector1, Vector2};

mvad::hybrid! {
    model Quad {
        param a = 0.7;
        state x = 0.4;
        state y = 0;
        flow { der(x) = a * x * x; der(y) = a * sin(x); }
    }
}

/// The point both `Quad` tests evaluate at: a = 0.7, (x, y) = (0.4, −1), as
/// (a, x, state vector, parameter vector).
fn quad_point() -> (f64, f64, Vector2<f64>, Vector1<f64>) {
    let (a, x) = (0.7, 0.4);
    (a, x, Vector2::new(x, -1.0), Vector1::new(a))
}

#[test]
fn adjoint_products_are_lambda_times_the_jacobians() {
    let m = Quad::new();
    let (a, x, xv, pv) = quad_point();
    let lam = Vector2::new(1.5, -2.0);
    let (mut vx, mut vp) = (Vector2::zeros(), Vector1::zeros());
    m.rhs_vjp(
        mvad::Point::new(0, &Switches::default(), 0.0, &xv, &pv),
        &lam,
        &mut vx,
        &mut vp,
    );
    // f_x = [[2ax, 0], [a cos x, 0]], f_θ = [x², sin x].
    let want_x = [lam[0] * 2.0 * a * x + lam[1] * a * x.cos(), 0.0];
    let want_p = lam[0] * x * x + lam[1] * x.sin();
    assert!(
        (vx[0] - want_x[0]).abs() < 1e-15 && vx[1] == want_x[1],
        "{vx:?}"
    );
    assert!((vp[0] - want_p).abs() < 1e-15, "{vp:?}");
}

#[test]
fn second_order_default_is_the_directional_derivative_of_the_sensitivity_rhs() {
    let m = Quad::new();
    let (a, x, xv, pv) = quad_point();
    let s = Matrix2x1::new(0.3, -0.8);
    let v = Vector2::new(0.9, 2.0);
    let mut out = Matrix2x1::zeros();
    m.rhs_sens_dir_x(
        mvad::Point::new(0, &Switches::default(), 0.0, &xv, &pv),
        &s,
        &v,
        &mut out,
    );
    // Σᵢ vᵢ ∂(f_x S + f_θ)/∂xᵢ: only x enters, so v₀ (∂f_x/∂x S + ∂f_θ/∂x).
    let want = [
        v[0] * (2.0 * a * s[0] + 2.0 * x),
        v[0] * (-a * x.sin() * s[0] + x.cos()),
    ];
    for i in 0..2 {
        assert!(
            (out[i] - want[i]).abs() < 1e-9,
            "{i}: {} vs {}",
            out[i],
            want[i]
        );
    }
}

mvad::hybrid! {
    model Kick {
        param a = 0.7;
        param b = 1.3;
        state x = a * b;
        state y = b;
        flow { der(x) = 1; der(y) = 0; }
        event kick when x >= 2 { x = a * x * y + t; y = b * t; }
    }
}

#[test]
fn reset_and_initial_state_vjps_are_mu_times_the_jacobians() {
    let m = Kick::new();
    let (a, b, t) = (0.7, 1.3, 0.25);
    let (xv, pv) = (Vector2::new(2.0, -0.5), Vector2::new(a, b));
    let mu = Vector2::new(1.5, -2.0);
    let (mut vx, mut vp) = (Vector2::zeros(), Vector2::zeros());
    let vt = m.reset_vjp(0, 0, t, &xv, &pv, &mu, &mut vx, &mut vp);
    // R = (a x y + t, b t): R_x = [[a y, a x], [0, 0]], R_θ = [[x y, 0], [0, t]], R_t = (1, b).
    let (x, y) = (xv[0], xv[1]);
    let want_x = [mu[0] * a * y, mu[0] * a * x];
    let want_p = [mu[0] * x * y, mu[1] * t];
    let want_t = mu[0] + mu[1] * b;
    for i in 0..2 {
        assert!((vx[i] - want_x[i]).abs() < 1e-15, "{vx:?}");
        assert!((vp[i] - want_p[i]).abs() < 1e-15, "{vp:?}");
    }
    assert!((vt - want_t).abs() < 1e-15, "{vt}");
    // x₀ = (a b, b): ∂x₀/∂θ = [[b, a], [0, 1]].
    let mut v0 = Vector2::zeros();
    m.initial_state_vjp(&pv, &mu, &mut v0);
    assert!((v0[0] - mu[0] * b).abs() < 1e-15 && (v0[1] - (mu[0] * a + mu[1])).abs() < 1e-15);
}
