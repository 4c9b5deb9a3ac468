//! The dense defaults of the adjoint sweep's products ([`super::ModelAdjoint::adjoint_rate`],
//! [`super::ModelAdjoint::adjoint_quadrature_add`], [`super::ModelAdjoint::running_cost_grad_x`]), built on `rhs_vjp` and
//! `running_cost_value_grad`, for hand-written models. They allocate p-long scratch and cost
//! O(p) per call; both doors override the products with sparse kernels that do neither.

use super::{At, HybridModel, ModelAlloc, Point, Switches};
use nalgebra::{Const, DefaultAllocator, OVector};

/// out = −(λᵀf_x + w ℓ_x) at `pt` (ℓ not evaluated when w = 0 or the model has none).
pub fn adjoint_rate<M: HybridModel + ?Sized>(
    m: &M,
    pt: Point<'_, M::N, M::P>,
    lambda: &OVector<f64, M::N>,
    w: f64,
    out: &mut OVector<f64, M::N>,
) where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let (n, np) = (m.nstates(), m.nparams());
    let mut vp = OVector::<f64, M::P>::zeros_generic(np, Const::<1>);
    m.rhs_vjp(pt, lambda, out, &mut vp);
    if w != 0.0 && m.info().has_running_cost {
        let mut lx = OVector::<f64, M::N>::zeros_generic(n, Const::<1>);
        m.running_cost_value_grad(pt.sw, pt.at(), &mut lx, &mut vp);
        out.axpy(w, &lx, 1.0);
    }
    out.neg_mut();
}

/// g += −a (λᵀf_θ + w ℓ_θ) at `pt` (ℓ not evaluated when w = 0 or the model has none).
pub fn adjoint_quadrature_add<M: HybridModel + ?Sized>(
    m: &M,
    pt: Point<'_, M::N, M::P>,
    lambda: &OVector<f64, M::N>,
    w: f64,
    a: f64,
    g: &mut OVector<f64, M::P>,
) where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let (n, np) = (m.nstates(), m.nparams());
    let mut vx = OVector::<f64, M::N>::zeros_generic(n, Const::<1>);
    let mut vp = OVector::<f64, M::P>::zeros_generic(np, Const::<1>);
    m.rhs_vjp(pt, lambda, &mut vx, &mut vp);
    g.axpy(-a, &vp, 1.0);
    if w != 0.0 && m.info().has_running_cost {
        m.running_cost_value_grad(pt.sw, pt.at(), &mut vx, &mut vp);
        g.axpy(-a * w, &vp, 1.0);
    }
}

/// lx = ℓ_x at `at` under the bits `sw` (zeros without a running cost), through the full
/// gradient with a p-long scratch ℓ_θ.
pub fn running_cost_grad_x<M: HybridModel + ?Sized>(
    m: &M,
    sw: &Switches,
    at: At<'_, M::N, M::P>,
    lx: &mut OVector<f64, M::N>,
) where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    if !m.info().has_running_cost {
        lx.fill(0.0);
        return;
    }
    let mut lp = OVector::<f64, M::P>::zeros_generic(m.nparams(), Const::<1>);
    m.running_cost_value_grad(sw, at, lx, &mut lp);
}
