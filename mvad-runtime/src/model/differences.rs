//! The difference quotients behind the [`super::ModelSecondOrder`] defaults (their steps are
//! explained on that trait) and the [`super::ModelAdjoint`] defaults `rhs_vjp_dir` and
//! `running_cost_grad_dir`. Public so that a model whose second derivatives are not
//! symbolic — one whose flow reads a qp of the state, whose solution has first derivatives
//! from the KKT system but no second — can use them from its own implementation. They
//! allocate scratch.

use super::{At, HybridModel, ModelAlloc, Point, Switches};
use nalgebra::{allocator::Allocator, DefaultAllocator, Dim, OMatrix, OVector};

/// Relative size of the perturbation of x in the directional differences of the
/// [`super::ModelSecondOrder`] defaults: h = `DIR_STEP`·max(1, ‖x‖₂)/‖v‖₂ (why 1e-4: see the trait).
const DIR_STEP: f64 = 1e-4;

/// The step h of the directional differences along v at x (see [`DIR_STEP`]) and the points
/// x ± h v; `None` when v = 0 (the product is zero), h = NaN when v is not finite.
#[allow(clippy::type_complexity)]
fn dir_points<N: Dim>(
    x: &OVector<f64, N>,
    v: &OVector<f64, N>,
) -> Option<(f64, OVector<f64, N>, OVector<f64, N>)>
where
    DefaultAllocator: Allocator<N>,
{
    let nv = v.norm();
    if nv == 0.0 {
        return None;
    }
    let h = if nv.is_finite() {
        DIR_STEP * x.norm().max(1.0) / nv
    } else {
        f64::NAN
    };
    let (mut up, mut dn) = (x.clone_owned(), x.clone_owned());
    up.axpy(h, v, 1.0);
    dn.axpy(-h, v, 1.0);
    Some((h, up, dn))
}

/// The step of the central differences in t of the [`super::ModelSecondOrder`] defaults:
/// ε^{1/3}·max(1, |t|) (truncation and rounding errors balance at O(ε^{2/3})).
fn time_step(t: f64) -> f64 {
    f64::EPSILON.cbrt() * t.abs().max(1.0)
}

/// The step ε of the [`super::ModelAdjoint`] defaults along the direction (1, v) of (t, x)
/// and the points x ± ε v: the smaller of the steps along v ([`DIR_STEP`]) and in t
/// ([`time_step`]), so that a fast transient (‖v‖ large) is differenced on its own scale.
fn flow_points<N: Dim>(
    t: f64,
    x: &OVector<f64, N>,
    v: &OVector<f64, N>,
) -> (f64, OVector<f64, N>, OVector<f64, N>)
where
    DefaultAllocator: Allocator<N>,
{
    let ht = time_step(t);
    let nv = v.norm();
    let hv = if nv > 0.0 && nv.is_finite() {
        DIR_STEP * x.norm().max(1.0) / nv
    } else {
        ht
    };
    let h = hv.min(ht);
    let (mut up, mut dn) = (x.clone_owned(), x.clone_owned());
    up.axpy(h, v, 1.0);
    dn.axpy(-h, v, 1.0);
    (h, up, dn)
}

/// d/dε (λᵀf_x, λᵀf_θ)(t + ε, x + εv) at ε = 0 by a central difference with the step of
/// `flow_points` (the default of [`super::ModelAdjoint::rhs_vjp_dir`]).
pub fn rhs_vjp_dir<M: HybridModel + ?Sized>(
    m: &M,
    pt: Point<'_, M::N, M::P>,
    lambda: &OVector<f64, M::N>,
    v: &OVector<f64, M::N>,
    vx: &mut OVector<f64, M::N>,
    vp: &mut OVector<f64, M::P>,
) where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let (eps, xu, xd) = flow_points(pt.t, pt.x, v);
    let (mut vx_dn, mut vp_dn) = (vx.clone_owned(), vp.clone_owned());
    let up = Point {
        t: pt.t + eps,
        x: &xu,
        ..pt
    };
    let dn = Point {
        t: pt.t - eps,
        x: &xd,
        ..pt
    };
    m.rhs_vjp(up, lambda, vx, vp);
    m.rhs_vjp(dn, lambda, &mut vx_dn, &mut vp_dn);
    *vx -= &vx_dn;
    *vp -= &vp_dn;
    *vx /= 2.0 * eps;
    *vp /= 2.0 * eps;
}

/// d/dε (ℓ_x, ℓ_θ)(t + ε, x + εv) at ε = 0 into `lx`, `lp`, returning dℓ/dε, by central
/// differences with the step of `flow_points` (the default of
/// [`super::ModelAdjoint::running_cost_grad_dir`]).
pub fn running_cost_grad_dir<M: HybridModel + ?Sized>(
    m: &M,
    sw: &Switches,
    at: At<'_, M::N, M::P>,
    v: &OVector<f64, M::N>,
    lx: &mut OVector<f64, M::N>,
    lp: &mut OVector<f64, M::P>,
) -> f64
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let (eps, xu, xd) = flow_points(at.t, at.x, v);
    let (mut lx_dn, mut lp_dn) = (lx.clone_owned(), lp.clone_owned());
    let up = m.running_cost_value_grad(sw, At::new(at.t + eps, &xu, at.p), lx, lp);
    let dn = m.running_cost_value_grad(sw, At::new(at.t - eps, &xd, at.p), &mut lx_dn, &mut lp_dn);
    *lx -= &lx_dn;
    *lp -= &lp_dn;
    *lx /= 2.0 * eps;
    *lp /= 2.0 * eps;
    (up - dn) / (2.0 * eps)
}

/// (∂/∂x (f_x S + f_θ))·v by a central difference along v (the default of
/// [`super::ModelSecondOrder::rhs_sens_dir_x`]).
pub fn rhs_sens_dir_x<M: HybridModel + ?Sized>(
    m: &M,
    pt: Point<'_, M::N, M::P>,
    s: &OMatrix<f64, M::N, M::P>,
    v: &OVector<f64, M::N>,
    out: &mut OMatrix<f64, M::N, M::P>,
) where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let Some((h, xu, xd)) = dir_points(pt.x, v) else {
        out.fill(0.0);
        return;
    };
    rhs_sens_difference(
        m,
        Point { x: &xu, ..pt },
        Point { x: &xd, ..pt },
        s,
        2.0 * h,
        out,
    );
}

/// ∂ₜ(f_x S + f_θ) by a central difference in t (the default of
/// [`super::ModelSecondOrder::rhs_sens_dt`]).
pub fn rhs_sens_dt<M: HybridModel + ?Sized>(
    m: &M,
    pt: Point<'_, M::N, M::P>,
    s: &OMatrix<f64, M::N, M::P>,
    out: &mut OMatrix<f64, M::N, M::P>,
) where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let h = time_step(pt.t);
    let (up, dn) = (Point { t: pt.t + h, ..pt }, Point { t: pt.t - h, ..pt });
    rhs_sens_difference(m, up, dn, s, 2.0 * h, out);
}

/// (∂/∂x (ℓ_x S + ℓ_θ))·v by a central difference along v (the default of
/// [`super::ModelSecondOrder::running_cost_sens_dir_x`]).
pub fn running_cost_sens_dir_x<M: HybridModel + ?Sized>(
    m: &M,
    sw: &Switches,
    at: At<'_, M::N, M::P>,
    s: &OMatrix<f64, M::N, M::P>,
    v: &OVector<f64, M::N>,
    out: &mut OVector<f64, M::P>,
) where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let Some((h, xu, xd)) = dir_points(at.x, v) else {
        out.fill(0.0);
        return;
    };
    let (up, dn) = (At { x: &xu, ..at }, At { x: &xd, ..at });
    running_cost_sens_difference(m, sw, up, dn, s, 2.0 * h, out);
}

/// ∂ₜ(ℓ_x S + ℓ_θ) by a central difference in t; returns ∂ₜℓ (the default of
/// [`super::ModelSecondOrder::running_cost_sens_dt`]).
pub fn running_cost_sens_dt<M: HybridModel + ?Sized>(
    m: &M,
    sw: &Switches,
    at: At<'_, M::N, M::P>,
    s: &OMatrix<f64, M::N, M::P>,
    out: &mut OVector<f64, M::P>,
) -> f64
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let h = time_step(at.t);
    let (up, dn) = (At { t: at.t + h, ..at }, At { t: at.t - h, ..at });
    running_cost_sens_difference(m, sw, up, dn, s, 2.0 * h, out)
}

/// out = (Ṡ(up) − Ṡ(dn))/h2 for Ṡ = f_x S + f_θ (the difference quotient of the defaults).
fn rhs_sens_difference<M: HybridModel + ?Sized>(
    m: &M,
    up: Point<'_, M::N, M::P>,
    dn: Point<'_, M::N, M::P>,
    s: &OMatrix<f64, M::N, M::P>,
    h2: f64,
    out: &mut OMatrix<f64, M::N, M::P>,
) where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let mut f = up.x.clone_owned();
    let mut minus = out.clone_owned();
    m.rhs_sens(up, s, &mut f, out);
    m.rhs_sens(dn, s, &mut f, &mut minus);
    *out -= &minus;
    *out /= h2;
}

/// out = (q̇_θ(up) − q̇_θ(dn))/h2 for q̇_θ = ℓ_x S + ℓ_θ with the frozen branches `sw`;
/// returns (ℓ(up) − ℓ(dn))/h2 (the difference quotients of the defaults).
fn running_cost_sens_difference<M: HybridModel + ?Sized>(
    m: &M,
    sw: &Switches,
    up: At<'_, M::N, M::P>,
    dn: At<'_, M::N, M::P>,
    s: &OMatrix<f64, M::N, M::P>,
    h2: f64,
    out: &mut OVector<f64, M::P>,
) -> f64
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let (mut lx, mut lx_dn, mut lp_dn) =
        (up.x.clone_owned(), up.x.clone_owned(), out.clone_owned());
    let l_up = m.running_cost_value_grad(sw, up, &mut lx, out);
    let l_dn = m.running_cost_value_grad(sw, dn, &mut lx_dn, &mut lp_dn);
    lx -= &lx_dn;
    *out -= &lp_dn;
    out.gemv_tr(1.0, s, &lx, 1.0);
    *out /= h2;
    (l_up - l_dn) / h2
}
