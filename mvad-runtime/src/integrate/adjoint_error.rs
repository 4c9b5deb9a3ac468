//! The global error estimate of an adjoint sweep: the backward sweep's local errors, and the
//! primal run's state errors it reads, carried to the gradient it returns.
//!
//! The sweep (`adjoint/sweep.rs`) integrates λ from T down to 0 with
//! λ̇ = F(t, λ) = −f_xᵀλ − w ℓ_xᵀ along the primal run's recorded x(t), accumulates the
//! quadrature ġ = G(t, λ) = −(f_θᵀλ + w ℓ_θᵀ) outside the stepper (`quadrature.rs`), and
//! returns Γ = g(0) + x₀_θᵀλ(0) (w dC/dθ plus the samples' terms: the VJP). F is affine in λ
//! and G is affine in λ and does not read g, so an error δλ the sweep makes at t reaches Γ
//! through the sweep's own homogeneous (w = 0) linear flow, and an error δg reaches it
//! unchanged. [`AdjointError`] carries that remainder r = (r_λ, r_g):
//!
//! ```text
//!   ṙ_λ = −f_xᵀ r_λ,   ṙ_g = −f_θᵀ r_λ        (from t down to 0)
//!   at a jump: the transpose with w = 0,  r_λ⁻ = R_xᵀr_λ⁺ − (c/ġ) g_xᵀ,  r_g += R_θᵀr_λ⁺ − (c/ġ) g_θ,
//!              c = (R_xᵀr_λ⁺)·f⁻ + r_λ⁺ᵀR_t − r_λ⁺·f⁺      (`adjoint/transpose.rs`)
//!   at 0:      e_Γ = r_g + x₀_θᵀ r_λ
//! ```
//!
//! (by duality e_Γ = Σ δλᵀS(t) + δg: the pairing forward mode's estimate forms, without S).
//!
//! ## The local errors of a backward step
//! - **λ**: the stepper's own estimate le_λ (λ is the integrated vector).
//! - **g**: g is the quadrature the augmented integration of (λ, g) would give (see
//!   `quadrature.rs`), so its local error is the g-block of that integration's embedded
//!   estimate. Because G never reads g, that block is the difference of the embedded weights
//!   applied to the same stage values: le_g = h Σᵢ (bᵢ − b̂ᵢ) G(tᵢ, Λᵢ) for an explicit pair
//!   (Λᵢ the λ-part of stage i's argument), and for Rodas5P (whose estimate is the last stage
//!   K₈) the Q-block of K₈, formed like the update with the weights of the unit vector e₈
//!   (`rosenbrock::quadrature_weights`). It is the same e_g the step acceptance reads
//!   ([`super::QuadratureSum::Error`], formed with Δg from one evaluation of G per stage,
//!   `adjoint_quadrature_add` on G's support: O(nnz(f_θ)), never O(p)), and is added into
//!   r_g as the integrator closes the step (`OdeSystem::quadrature_close`). A step cut short (θ < 1, forward runs only) keeps the whole step's estimate,
//!   as λ's does. The error λ's local errors cause in g is the transport's ṙ_g = −f_θᵀr_λ:
//!   the propagation of λ's error through ∫ λᵀf_θ dt.
//!
//! Per backward step, r_λ += le_λ and the transport is the forward one with J = −f_xᵀ
//! (`global_error.rs`): m explicit Euler substeps, each one product f_xᵀr_λ over f_x's
//! structural non-zeros, with r_g −= ∫ f_θᵀ r_λ by the trapezoidal rule (f_θ frozen at the
//! step start, so that is one sparse product f_θᵀ(Σ_k w_k r_λ⁽ᵏ⁾)), or one linearly implicit
//! Euler step with (I + h f_xᵀ)⁻¹. The flow-direction transport (α, β) has no counterpart:
//! the adjoint's exact solution along the flow is the invariant λᵀf, a scalar, not a
//! direction.
//!
//! ## The primal run's errors
//! The primal run's own estimate, e_x = r_x + α f, kept on the tape per step and per jump,
//! enters because the sweep reads x(t): C's error is the primal's e_C; Γ's gets
//! - on a segment, the forcing of evaluating F and G along x + e_x instead of x: per
//!   backward step h δF and h δG with δF = F(t, x + e_x, λ) − F(t, x, λ) and δG likewise at
//!   the step start, secants over the actual displacement (`Backward`'s
//!   `carry_global_error`; two `adjoint_rate` and two sparse `adjoint_quadrature_add`);
//! - at a jump, which the primal applied at (t̃, x̃⁻, x̃⁺) = (t, x⁻, x⁺) + (δt, d⁻, d⁺) with
//!   δt = −∇g·e_x⁻/ġ, d⁻ = e_x⁻ + f⁻δt, d⁺ = e_x⁺ + f⁺δt
//!   ([`super::GlobalError::jump_shift`]), the difference of the transposes at the displaced
//!   and the exact jump applied to λ⁺ (`adjoint::transpose::shift_error`), with the reset's
//!   and the event cost's products as the sweep formed them at the displaced jump: what
//!   differs is the event-time term (c/ġ)(g_x, g_θ), through f±, ℓ± and the crossing's
//!   gradient, and no reset is evaluated again (a reset with p parameters costs O(p)).
//!
//! Left out, as forward mode leaves them out: the error of locating events beyond the
//! primal's own state error, the change of the reset's and the event cost's derivatives
//! along a jump's displacement (second derivatives of R and φ), and the sweep's segments
//! changing at t̃ rather than t (a term (F⁻ − F⁺)·δt). Samples of observables add h_xᵀw to λ at x̃(t_s); their share of the primal
//! error is left out too.

use super::global_error::{sparse_product, substeps, EXPLICIT_SUBSTEPS};
use super::rosenbrock::WMatrix;
use crate::model::ModelAlloc;
use nalgebra::{Const, DefaultAllocator, Dim, OVector};

/// The λ-part and the g-part of the sweep's state, or of the estimate's remainder, borrowed
/// together.
pub type LamGrad<'a, N, P> = (&'a mut OVector<f64, N>, &'a mut OVector<f64, P>);

/// The global error estimate of an adjoint sweep (see the module doc): the remainder
/// (r_λ, r_g), carried backwards by the sweep's homogeneous linear flow. Every buffer is
/// allocated when it is built; carrying it allocates nothing and touches nothing of size p
/// but through the sparse product it is given.
#[derive(Clone, Debug)]
pub struct AdjointError<N: Dim, P: Dim>
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    /// r_λ.
    lam: OVector<f64, N>,
    /// r_g.
    g: OVector<f64, P>,
    /// Scratch: f_xᵀ r_λ, the row sums of |J| and Σ_k w_k r_λ⁽ᵏ⁾.
    vx: OVector<f64, N>,
    sums: OVector<f64, N>,
    acc: OVector<f64, N>,
}

impl<N: Dim, P: Dim> AdjointError<N, P>
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    /// A zero estimate for n states and p parameters.
    pub fn new(n: N, p: P) -> Self {
        let vn = || OVector::zeros_generic(n, Const::<1>);
        AdjointError {
            lam: vn(),
            g: OVector::zeros_generic(p, Const::<1>),
            vx: vn(),
            sums: vn(),
            acc: vn(),
        }
    }

    /// Carries the estimate over the accepted backward step of signed length h (< 0) with
    /// λ's local error estimate `le` and the primal run's forcing δF (`forcing`, per unit
    /// time; its g-part and g's own local error are added to r_g by the caller): J = −f_xᵀ at
    /// the step start in `w.jac` (`pattern` the structural non-zeros of f_x, every entry when
    /// it is empty), and `quad(v, a, r_g)` the model's sparse r_g += −a f_θᵀv at the step
    /// start.
    ///
    /// r_λ += le + h δF; then with m as for a forward step ([`substeps`]): m explicit Euler
    /// substeps r_λ ← r_λ + (h/m) J r_λ over J's non-zeros, with r_g −= ∫ f_θᵀ r_λ by the
    /// trapezoidal rule — f_θ is frozen at the step start, so that is one product
    /// f_θᵀ(Σ_k w_k r_λ⁽ᵏ⁾) with the trapezoidal weights w_k — or for a stiff step one linearly
    /// implicit Euler step r_λ ← (I + h f_xᵀ)⁻¹ r_λ (L-stable; a singular matrix leaves r_λ as
    /// it is), r_g −= h f_θᵀ r_λ.
    pub(super) fn carry(
        &mut self,
        le: &OVector<f64, N>,
        forcing: Option<&OVector<f64, N>>,
        w: &mut WMatrix<N>,
        pattern: &[(usize, usize)],
        h: f64,
        mut quad: impl FnMut(&OVector<f64, N>, f64, &mut OVector<f64, P>),
    ) {
        let AdjointError {
            lam,
            g,
            vx,
            sums,
            acc,
        } = self;
        *lam += le;
        if let Some(d) = forcing {
            lam.axpy(h, d, 1.0);
        }
        let m = substeps(&w.jac, pattern, true, h, sums);
        if m <= EXPLICIT_SUBSTEPS {
            let dt = h / m;
            acc.copy_from(lam);
            *acc *= 0.5 * dt;
            for k in 0..m as usize {
                if pattern.is_empty() {
                    vx.gemv(1.0, &w.jac, lam, 0.0);
                } else {
                    vx.fill(0.0);
                    sparse_product(&w.jac, pattern, true, lam.as_slice(), vx.as_mut_slice());
                }
                lam.axpy(dt, vx, 1.0);
                let weight = if k + 1 == m as usize { 0.5 } else { 1.0 };
                acc.axpy(weight * dt, lam, 1.0);
            }
            quad(acc, 1.0, g);
            return;
        }
        if w.factorise(h) {
            w.solve_mut(lam);
        }
        // The factors are for h, not a Rosenbrock step's hγ.
        w.invalidate();
        quad(lam, h, g);
    }

    /// The remainder (r_λ, r_g), for the jumps' transposes (which map it as they map λ and g
    /// with a zero cost cotangent) and the primal run's shares.
    pub fn remainder_mut(&mut self) -> LamGrad<'_, N, P> {
        (&mut self.lam, &mut self.g)
    }
}
