//! The capability products of the model traits against their mathematics on small models
//! with known second derivatives, through both doors (`hybrid!` and the loader) and through
//! the traits' dense and finite-difference defaults ([`Defaults`]): the vector–Jacobian
//! products of a flow, a reset and x₀, ℓ_x alone, the second-order products of a flow and a
//! running cost in x and t, and frozen switch bits picking the branch of each.

use mvad::interp::InterpretedModel;
use mvad::{At, HybridModel, ModelAlloc, Occurrence, Switches};
use mvad_tests::{assert_near, Defaults};
use nalgebra::{Const, DefaultAllocator, Matrix2x1, OMatrix, OVector, Vector1, Vector2, U1, U2};

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
    adjoint_products_of(&Quad::new());
    adjoint_products_of(&Defaults(Quad::new()));
}

/// λᵀf_x, λᵀf_θ of `Quad` (its own product or the dense default).
fn adjoint_products_of(m: &impl HybridModel<N = U2, P = U1>) {
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
    // No running cost: ℓ_x = 0, whatever the buffer held.
    let mut lx = lam;
    m.running_cost_grad_x(&Switches::default(), At::new(0.0, &xv, &pv), &mut lx);
    assert_eq!(lx, Vector2::zeros());
}

#[test]
fn second_order_default_is_the_directional_derivative_of_the_sensitivity_rhs() {
    second_order_of(&Defaults(Quad::new()), 1e-9);
    second_order_of(&Quad::new(), 1e-15);
}

/// Σᵢ vᵢ ∂(f_x S + f_θ)/∂xᵢ of `Quad` to `tol` (its own product or the default).
fn second_order_of(m: &impl HybridModel<N = U2, P = U1>, tol: f64) {
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
            (out[i] - want[i]).abs() < tol,
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
    reset_products_of(&Kick::new());
    reset_products_of(&Defaults(Kick::new()));
}

/// μᵀR_x, μᵀR_θ, μᵀR_t and μᵀ∂x₀/∂θ of `Kick` (its own products or the dense defaults).
fn reset_products_of(m: &impl HybridModel<N = U2, P = U2>) {
    let (a, b, t) = (0.7, 1.3, 0.25);
    let (xv, pv) = (Vector2::new(2.0, -0.5), Vector2::new(a, b));
    let mu = Vector2::new(1.5, -2.0);
    let (mut vx, mut vp) = (Vector2::zeros(), Vector2::zeros());
    let vt = m.reset_vjp(
        Occurrence::new(0, 0),
        At::new(t, &xv, &pv),
        &mu,
        &mut vx,
        &mut vp,
    );
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

/// Declares a model once for both doors: the `hybrid!` type and its text for the loader.
macro_rules! both_doors {
    ($src:ident, $($model:tt)*) => {
        mvad::hybrid! { $($model)* }
        const $src: &str = stringify!($($model)*);
    };
}

both_doors! {
    TIMED,
    model Timed {
        param a = 0.7;
        param b = -1.3;
        state x = 0.4;
        state y = 0;
        flow { der(x) = a * x * x + b * t * x; der(y) = a * sin(x) * t; }
        cost = integral(b * x^2 * t + a * y);
    }
}

both_doors! {
    KINKED,
    model Kinked {
        param a = 0.7;
        state x = 2;
        flow { der(x) = a * abs(x - 1) * x; }
        cost = integral(a * abs(x - 1));
    }
}

/// x, θ and S (column-major) of a model at a point.
type Vecs<M> = (
    OVector<f64, <M as mvad::ModelDims>::N>,
    OVector<f64, <M as mvad::ModelDims>::P>,
    OMatrix<f64, <M as mvad::ModelDims>::N, <M as mvad::ModelDims>::P>,
);

/// Vectors of a model's sizes from slices.
fn vecs<M: HybridModel>(m: &M, x: &[f64], p: &[f64], s: &[f64]) -> Vecs<M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let (nd, pd) = (m.nstates(), m.nparams());
    (
        OVector::from_iterator_generic(nd, Const::<1>, x.iter().copied()),
        OVector::from_iterator_generic(pd, Const::<1>, p.iter().copied()),
        OMatrix::from_iterator_generic(nd, pd, s.iter().copied()),
    )
}

/// Asserts `got` (column-major n×p or a vector) equals `want` to `tol` relative.
fn close(what: &str, got: &[f64], want: &[f64], tol: f64) {
    assert_eq!(got.len(), want.len(), "{what}");
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert_near(*g, *w, tol, format_args!("{what}[{i}]"));
    }
}

/// The second-order products of `Timed` against their closed forms at (x, y) = (0.4, −1),
/// t = 0.8, to `tol`. f_x = [[2ax + bt, 0], [at cos x, 0]], f_θ = [[x², tx], [t sin x, 0]],
/// ℓ = b x² t + a y, ℓ_x = (2bxt, a), ℓ_θ = (y, x²t).
fn check_timed<M: HybridModel>(m: &M, tol: f64)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let (a, b, x, y, t) = (0.7, -1.3, 0.4, -1.0, 0.8);
    // S column-major: column a = (s00, s10), column b = (s01, s11).
    let s = [0.3, -0.8, 1.1, 0.5];
    let (xv, pv, sv) = vecs(m, &[x, y], &[a, b], &s);
    let v = OVector::<f64, M::N>::from_iterator_generic(m.nstates(), Const::<1>, [0.9, 2.0]);
    let (s0a, s0b) = (s[0], s[2]);
    let sw = Switches::default();
    let pt = mvad::Point::new(0, &sw, t, &xv, &pv);
    let mut out = sv.clone();
    // Σᵢ vᵢ ∂(f_x S + f_θ)/∂xᵢ = v₀ (∂f_x/∂x S + ∂f_θ/∂x).
    m.rhs_sens_dir_x(pt, &sv, &v, &mut out);
    let want = [
        v[0] * (2.0 * a * s0a + 2.0 * x),
        v[0] * (-a * t * x.sin() * s0a + t * x.cos()),
        v[0] * (2.0 * a * s0b + t),
        v[0] * (-a * t * x.sin() * s0b),
    ];
    close("Timed B v", out.as_slice(), &want, tol);
    // ∂ₜ(f_x S + f_θ) = ∂ₜf_x S + ∂ₜf_θ.
    m.rhs_sens_dt(pt, &sv, &mut out);
    let want = [
        b * s0a,
        a * x.cos() * s0a + x.sin(),
        b * s0b + x,
        a * x.cos() * s0b,
    ];
    close("Timed ∂ₜṠ", out.as_slice(), &want, tol);
    // Σᵢ vᵢ ∂(ℓ_x S + ℓ_θ)/∂xᵢ = v₀ (2bt S₀· + (0, 2xt)) + v₁ (1, 0).
    let mut o = OVector::<f64, M::P>::zeros_generic(m.nparams(), Const::<1>);
    m.running_cost_sens_dir_x(&sw, At::new(t, &xv, &pv), &sv, &v, &mut o);
    let want = [
        v[0] * 2.0 * b * t * s0a + v[1],
        v[0] * (2.0 * b * t * s0b + 2.0 * x * t),
    ];
    close("Timed D v", o.as_slice(), &want, tol);
    // ∂ₜ(ℓ_x S + ℓ_θ) = (2bx, 0)·S + (0, x²); ∂ₜℓ = b x².
    let lt = m.running_cost_sens_dt(&sw, At::new(t, &xv, &pv), &sv, &mut o);
    close(
        "Timed ∂ₜq̇_θ",
        o.as_slice(),
        &[2.0 * b * x * s0a, 2.0 * b * x * s0b + x * x],
        tol,
    );
    close("Timed ∂ₜℓ", &[lt], &[b * x * x], tol);
    // ℓ_x = (2bxt, a) alone.
    let mut lx = v.clone();
    m.running_cost_grad_x(&sw, At::new(t, &xv, &pv), &mut lx);
    close("Timed ℓ_x", lx.as_slice(), &[2.0 * b * x * t, a], tol);
}

#[test]
fn second_order_products_match_closed_forms_in_both_doors_and_the_defaults() {
    check_timed(&Timed::new(), 1e-15);
    check_timed(&InterpretedModel::from_source(TIMED).expect("loads"), 1e-15);
    check_timed(&Defaults(Timed::new()), 1e-8);
}

/// `Kinked` at x = 2 (σ = x − 1 > 0) with both frozen bits: f = ±a(x² − x), ℓ = ±a(x − 1),
/// so B v = ±v (2aS + 2x − 1) and D v = ±v: the bit, not the sign of σ, picks the branch.
fn check_kinked<M: HybridModel>(m: &M, tol: f64)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let (a, x, s, v) = (0.7, 2.0, 0.6, -1.5);
    assert_eq!(m.info().switches, 1);
    let (xv, pv, sv) = vecs(m, &[x], &[a], &[s]);
    let vv = OVector::<f64, M::N>::from_iterator_generic(m.nstates(), Const::<1>, [v]);
    for (bits, sign) in [(1u64, 1.0), (0, -1.0)] {
        let sw = Switches::from_bits(bits);
        let mut out = sv.clone();
        m.rhs_sens_dir_x(mvad::Point::new(0, &sw, 0.3, &xv, &pv), &sv, &vv, &mut out);
        close(
            "Kinked B v",
            out.as_slice(),
            &[sign * v * (2.0 * a * s + 2.0 * x - 1.0)],
            tol,
        );
        let mut o = OVector::<f64, M::P>::zeros_generic(m.nparams(), Const::<1>);
        m.running_cost_sens_dir_x(&sw, At::new(0.3, &xv, &pv), &sv, &vv, &mut o);
        close("Kinked D v", o.as_slice(), &[sign * v], tol);
        let mut lx = vv.clone();
        m.running_cost_grad_x(&sw, At::new(0.3, &xv, &pv), &mut lx);
        close("Kinked ℓ_x", lx.as_slice(), &[sign * a], tol);
        let (mut vx, mut vp) = (xv.clone(), pv.clone());
        m.rhs_vjp(
            mvad::Point::new(0, &sw, 0.3, &xv, &pv),
            &vv,
            &mut vx,
            &mut vp,
        );
        close(
            "Kinked λᵀf_x",
            vx.as_slice(),
            &[sign * v * a * (2.0 * x - 1.0)],
            tol,
        );
        close(
            "Kinked λᵀf_θ",
            vp.as_slice(),
            &[sign * v * (x * x - x)],
            tol,
        );
    }
}

#[test]
fn frozen_switch_bits_pick_the_branch_of_every_product() {
    check_kinked(&Kinked::new(), 1e-15);
    check_kinked(
        &InterpretedModel::from_source(KINKED).expect("loads"),
        1e-15,
    );
    check_kinked(&Defaults(Kinked::new()), 1e-8);
}
