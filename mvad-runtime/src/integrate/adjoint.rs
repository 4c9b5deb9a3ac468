//! The backward (adjoint) system of one segment, the second file in `integrate/` that calls
//! the model.
//!
//! On a segment [a, b] with frozen mode m and switch bits, and the primal trajectory x(t)
//! replayed from the forward record ([`Tape`]; the integrator runs in the segment's local
//! time s = t − a, see there), the integrated vector is λ ∈ Rⁿ alone,
//!
//! ```text
//!   λ̇ = −f_xᵀ λ − w ℓ_xᵀ                    at (t, x(t), θ)   (the stepper's F)
//!   ġ = G(t, λ) = −(f_θᵀ λ + w ℓ_θᵀ)                           (a quadrature, g ∈ Rᵖ)
//! ```
//!
//! (w the cotangent of the cost), integrated from b down to a with negative steps. Then
//! d/dt(λᵀS) = λ̇ᵀS + λᵀ(f_x S + f_θ) = −w ℓ_x S + λᵀ f_θ, so
//! λ(b)ᵀS(b) + w ∫_a^b (ℓ_x S + ℓ_θ) dt = λ(a)ᵀS(a) + [g(a) − g(b)]:
//! the segment's share of dC/dθ moves into g without ever forming S.
//!
//! ## The quadrature outside the stepper, under error control
//! G never feeds back into λ̇, so g is not part of the integrated vector: the stepper's
//! stages, dense output and finiteness checks are all n long, and g (p long) is kept here.
//! Each step's increment Δg is formed by the scheme's own weights on the step's stage values
//! (`integrate/quadrature.rs`): for the augmented system (λ, g) the Runge–Kutta update of g
//! is exactly g₁ = g₀ + h Σᵢ bᵢ G(tᵢ, Λᵢ) with Λᵢ the λ-part of stage i's argument, and its
//! embedded error estimate e_g = h Σᵢ (bᵢ − b̂ᵢ) G(tᵢ, Λᵢ) comes from the same stage values.
//!
//! g is under error control (CVODES' `errconQB = true`; `Options::sens_error_control`, on by
//! default, as S is in forward mode): every attempt forms Δg and e_g, one evaluation of G per
//! stage, and is accepted when max(‖e_λ‖, ‖e_g‖) ≤ 1, with
//! ‖e_g‖ = sqrt(1/|P| Σ_{j∈P} (w_j e_j / (atol + rtol·w_j·max(|g_j|, |g_j + Δg_j|)))²) over
//! the support P and w_j = max(1, |θ_j|) (`gradient_weight`). Without it, λ's norm alone
//! strides over the places where G is sharp and λ is not: behind a stiff lag's transient
//! (u relaxing in τ after a relay switch) λ_u is quasi-steady while G_τ = −λ_u(1 − u)/τ² is a
//! spike of height ~1/τ and width τ carrying an O(1) share of dC/dτ. Δg waits until the
//! accepted step is closed (`Integrator::close_step`), so a rejected attempt leaves nothing
//! in g; the result is the augmented integration's to rounding, the same order and the same
//! steps.
//!
//! Flat in p: every term is the model's sparse product
//! [`crate::model::ModelAdjoint::adjoint_quadrature_add`], which touches only the structural
//! non-zeros of f_θ and ℓ_θ, and every loop over g (the stage value's scratch, the sums, the
//! norm, the close) runs over the mode's support
//! [`crate::model::ModelAdjoint::gradient_support`], the parameters f_θ and ℓ_θ can reach;
//! the stages use [`crate::model::ModelAdjoint::adjoint_rate`], which touches nothing of size
//! p. So a backward step costs O(n + nnz(f_θ) + |P|) beyond the model's own work, never O(p).
//!
//! ## For Rodas5P
//! J_λλ = −f_xᵀ, and with W = I + hγ f_xᵀ (the `WMatrix` of J_λλ, factorised once per
//! attempt) a stage is K_λ = W⁻¹ hγ R_λ. For the augmented system J = [[−f_xᵀ, 0],
//! [−f_θᵀ, 0]], and the g block of a Rosenbrock step is linear in the stage values G_i, in
//! J_gλ K_λ,i and in G_t, so its update is formed from them after the step (see
//! `quadrature.rs`). F depends on t through x(t) even for an autonomous flow, so F_t is the
//! total derivative along the trajectory, the direction (1, f₀) of (t, x) at fixed λ:
//! F_t = −d(λᵀf_x) − w dℓ_x and G_t = −d(λᵀf_θ) − w dℓ_θ from the model's products
//! [`crate::model::ModelAdjoint::rhs_vjp_dir`] and
//! [`crate::model::ModelAdjoint::running_cost_grad_dir`] (nothing here takes a difference
//! quotient; their trait defaults do, on the scale of the direction, so that a stiff
//! transient is differenced on its own time scale). G_t is p long as the model's product
//! writes it (its work, once per step start); it enters the sums on the support. The adjoint of a stiff flow is stiff backwards in time (the
//! eigenvalues of −f_xᵀ, stepped with h < 0, are those of f_x stepped forwards), so `auto`
//! switches to Rodas5P on it as on the forward run.

use super::adjoint_error::AdjointError;
use super::aug::{axpy_slice, WeightedRms};
use super::forward::ModeFlow;
use super::rosenbrock::{Linearisation, WMatrix};
use super::system::{AcceptedStep, HermiteStep, ImplicitSystem, OdeSystem, QuadratureSum};
use super::system::{StageVector, Tol};
use super::Integrator;
use crate::adjoint::record::{SegmentRec, Tape};
use crate::model::{At, HybridModel, ModelAlloc, Point};
use crate::solution::{Method, Options};
use nalgebra::{allocator::Allocator, Const, DefaultAllocator, Dim, OVector};

/// A plain vector as the integrated vector of a system with no secondary parts (the
/// adjoint's λ): it is its own primary part, so every operation is the primary one and `all`
/// changes nothing.
impl<N: Dim> StageVector for OVector<f64, N>
where
    DefaultAllocator: Allocator<N>,
{
    type Primary = OVector<f64, N>;

    #[inline]
    fn copy_from(&mut self, other: &Self) {
        other.primary_into(self);
    }

    #[inline]
    fn combine(&mut self, base: &Self, h: f64, coefs: &[f64], ks: &[Self], _all: bool) {
        Self::combine_primary(self, base, h, coefs, ks);
    }

    #[inline]
    fn lincomb(&mut self, h: f64, coefs: &[f64], ks: &[Self], _all: bool) {
        Self::lincomb_primary(self, h, coefs, ks);
    }

    #[inline]
    fn axpy(&mut self, a: f64, other: &Self, _all: bool) {
        axpy_slice(self.as_mut_slice(), a, other.as_slice());
    }

    #[inline]
    fn mix5(&mut self, w: &[f64; 5], v: [&Self; 5], _all: bool) {
        Self::mix5_primary(self, w, v);
    }

    #[inline]
    fn hermite(&mut self, step: &HermiteStep<'_, Self>, th: f64, _all: bool) {
        Self::hermite_primary(self, step, th);
    }

    #[inline]
    fn is_finite(&self) -> bool {
        self.iter().all(|v| v.is_finite())
    }

    #[inline]
    fn primary(&self) -> &[f64] {
        self.as_slice()
    }
}

/// The backward system of one segment at parameters θ (see the module doc).
pub struct Backward<'a, M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    rhs: AdjRhs<'a, M>,
    hist: History<'a, M::N>,
    imp: AdjImplicit<M::N, M::P>,
    /// g: the gradient quadrature, with whatever the sweep adds to it (jumps, samples, the
    /// terminal and initial terms).
    g: OVector<f64, M::P>,
    /// The step being formed: its Δg, its error, G's support (see [`StepQuadrature`]).
    quad: StepQuadrature<M::P>,
    /// The sweep's global error estimate (`Options::global_error`).
    global: Option<AdjointError<M::N, M::P>>,
    /// The buffers of its primal coupling (with it).
    coupling: Option<Coupling<M::N>>,
}

/// g and the sweep's global error estimate, borrowed together
/// ([`Integrator::gradient_and_error_mut`]).
pub type GradientAndError<'a, N, P> = (&'a mut OVector<f64, P>, Option<&'a mut AdjointError<N, P>>);

/// Buffers of the primal run's share of the sweep's error (see [`Backward`]'s
/// `carry_global_error`): e_x, x + e_x, f, and δF.
struct Coupling<N: Dim>
where
    DefaultAllocator: nalgebra::allocator::Allocator<N>,
{
    ex: OVector<f64, N>,
    xe: OVector<f64, N>,
    f: OVector<f64, N>,
    d: OVector<f64, N>,
}

/// The gradient quadrature of the step being formed (`quadrature.rs`), on the support of G
/// in the segment's mode ([`crate::model::ModelAdjoint::gradient_support`]): every loop
/// below runs over `support`, never over 0..p, and entries outside it are never read.
struct StepQuadrature<P: Dim>
where
    DefaultAllocator: nalgebra::allocator::Allocator<P>,
{
    /// The parameters G can reach in the current mode, ascending (capacity p, filled per
    /// segment without allocating).
    support: Vec<usize>,
    /// One stage value G(tᵢ, Λᵢ), when it goes to both sums.
    stage: OVector<f64, P>,
    /// Δg of the step.
    step: OVector<f64, P>,
    /// Its local error estimate.
    err: OVector<f64, P>,
    /// g's local error enters the step acceptance (`Options::sens_error_control`).
    controlled: bool,
}

impl<P: Dim> StepQuadrature<P>
where
    DefaultAllocator: nalgebra::allocator::Allocator<P>,
{
    /// The sum `sum` of the step.
    #[inline]
    fn sum_mut(&mut self, sum: QuadratureSum) -> &mut OVector<f64, P> {
        match sum {
            QuadratureSum::Step => &mut self.step,
            QuadratureSum::Error => &mut self.err,
        }
    }
}

/// The weight of g_j in the sweep's error norm: max(1, |θ_j|). Forward mode weighs S's
/// column j by |θ_j| ([`super::sens_weight`]), which makes its absolute tolerance atol/|θ_j|;
/// for g that floor would be far above g_j itself when θ_j is small (a lag τ = 1e-8 with
/// dC/dτ ~ 1 would be held to 1e-2 at atol 1e-10), so g_j is held to the stricter of atol and
/// atol/|θ_j| besides rtol·|g_j|.
#[inline]
fn gradient_weight(theta: f64) -> f64 {
    super::sens_weight(theta).max(1.0)
}

/// Everything F needs besides x(t).
struct AdjRhs<'a, M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    flow: ModeFlow<'a, M>,
    /// Absolute time of the segment's start: the integrator runs in local time s = t − t_start.
    t_start: f64,
    /// The cotangent w of the cost (0 when the model has no running cost: ℓ is never
    /// evaluated then).
    w: f64,
}

/// x(t) from the record, on the segment being swept.
struct History<'a, N: Dim>
where
    DefaultAllocator: nalgebra::allocator::Allocator<N>,
{
    tape: &'a Tape,
    seg: Option<&'a SegmentRec>,
    cursor: usize,
    x: OVector<f64, N>,
}

/// The Rodas5P buffers (allocated once).
struct AdjImplicit<N: Dim, P: Dim>
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    /// J_λλ = −f_xᵀ and the factors of W = I − hγ J_λλ, and F_t at the step start.
    lin: Linearisation<N, OVector<f64, N>>,
    /// x and f at the step start.
    x0: OVector<f64, N>,
    f0: OVector<f64, N>,
    /// G_t at the step start `dt_at` (local time), and ℓ's directional-derivative scratch.
    dt_g: OVector<f64, P>,
    dt_at: Option<f64>,
    lx: OVector<f64, N>,
    lp: OVector<f64, P>,
}

impl<M: HybridModel> AdjRhs<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// The model's point at local time s and state x.
    #[inline]
    fn point<'b>(&'b self, s: f64, x: &'b OVector<f64, M::N>) -> Point<'b, M::N, M::P> {
        self.flow.point(self.t_start + s, x)
    }
}

impl<N: Dim> History<'_, N>
where
    DefaultAllocator: nalgebra::allocator::Allocator<N>,
{
    /// x(t) into `self.x` (NaN before a segment is set).
    #[inline]
    fn at(&mut self, t: f64) {
        match self.seg {
            Some(seg) => self
                .tape
                .state_at(seg, t, &mut self.cursor, self.x.as_mut_slice()),
            None => self.x.fill(f64::NAN),
        }
    }
}

impl<'a, M: HybridModel> Backward<'a, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// The backward system of `model` at `p` over the record `tape`, with cost cotangent
    /// `cw` and g = 0; allocates its buffers once (the Rodas5P ones only when `opts.method`
    /// may use it). Its integrator is `Integrator::with_system(Backward::new(..), opts)`;
    /// call [`Integrator::restart_segment`] before each segment.
    pub fn new(
        model: &'a M,
        p: &'a OVector<f64, M::P>,
        tape: &'a Tape,
        opts: &Options,
        cw: f64,
    ) -> Self {
        let (n, np) = (model.nstates(), model.nparams());
        let used = matches!(opts.method, Method::Auto | Method::Rosenbrock) || opts.global_error;
        let vn = || OVector::<f64, M::N>::zeros_generic(n, Const::<1>);
        // G_t's buffers, like the WMatrix: empty for `Dyn` sizes unless Rodas5P may run.
        let stiff_np = if used || M::P::try_to_usize().is_some() {
            np
        } else {
            M::P::from_usize(0)
        };
        Backward {
            rhs: AdjRhs {
                flow: ModeFlow::new(model, p),
                t_start: 0.0,
                w: if model.info().has_running_cost {
                    cw
                } else {
                    0.0
                },
            },
            hist: History {
                tape,
                seg: None,
                cursor: 0,
                x: vn(),
            },
            imp: AdjImplicit {
                lin: Linearisation::new(WMatrix::new(n, used), vn()),
                x0: vn(),
                f0: vn(),
                dt_g: OVector::zeros_generic(stiff_np, Const::<1>),
                dt_at: None,
                lx: vn(),
                lp: OVector::zeros_generic(stiff_np, Const::<1>),
            },
            g: OVector::zeros_generic(np, Const::<1>),
            quad: StepQuadrature {
                support: Vec::with_capacity(np.value()),
                stage: OVector::zeros_generic(np, Const::<1>),
                step: OVector::zeros_generic(np, Const::<1>),
                err: OVector::zeros_generic(np, Const::<1>),
                controlled: opts.sens_error_control,
            },
            global: opts.global_error.then(|| AdjointError::new(n, np)),
            coupling: opts.global_error.then(|| Coupling {
                ex: vn(),
                xe: vn(),
                f: vn(),
                d: vn(),
            }),
        }
    }

    /// x₀ = x(t0), f₀ = f(t₀, x₀), F_t = −d(λᵀf_x) − w dℓ_x and G_t = −d(λᵀf_θ) − w dℓ_θ
    /// along (1, f₀) at fixed λ = y0 (local time t0).
    fn time_derivatives(&mut self, t0: f64, y0: &OVector<f64, M::N>) {
        let Backward { rhs, hist, imp, .. } = self;
        hist.at(t0);
        imp.x0.copy_from(&hist.x);
        let pt = rhs.point(t0, &imp.x0);
        rhs.flow.model.rhs(pt, &mut imp.f0);
        rhs.flow
            .model
            .rhs_vjp_dir(pt, y0, &imp.f0, &mut imp.lin.dt, &mut imp.dt_g);
        if rhs.w != 0.0 {
            let (sw, t, p) = (&rhs.flow.sw, rhs.t_start + t0, rhs.flow.p);
            let (lx, lp) = (&mut imp.lx, &mut imp.lp);
            rhs.flow
                .model
                .running_cost_grad_dir(sw, At::new(t, &imp.x0, p), &imp.f0, lx, lp);
            imp.lin.dt.axpy(rhs.w, &imp.lx, 1.0);
            imp.dt_g.axpy(rhs.w, &imp.lp, 1.0);
        }
        imp.lin.dt.neg_mut();
        imp.dt_g.neg_mut();
        imp.dt_at = Some(t0);
    }
}

impl<M: HybridModel> OdeSystem for Backward<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    type Vector = OVector<f64, M::N>;

    fn zeros(&self) -> Self::Vector {
        OVector::zeros_generic(self.rhs.flow.model.nstates(), Const::<1>)
    }

    #[inline]
    fn all_parts(&self) -> bool {
        true
    }

    #[inline]
    fn reads_secondary(&self) -> bool {
        true
    }

    #[inline]
    fn controls_all(&self) -> bool {
        true
    }

    /// out = −f_xᵀλ − w ℓ_xᵀ with x(t) from the record.
    #[inline]
    fn eval(&mut self, t: f64, y: &Self::Vector, out: &mut Self::Vector) {
        self.hist.at(t);
        let rhs = &mut self.rhs;
        rhs.flow.evals += 1;
        let pt = rhs.point(t, &self.hist.x);
        rhs.flow.model.adjoint_rate(pt, y, rhs.w, out);
    }

    /// A mode whose flow is a function of θ alone and no running cost: f_x = 0, so λ is
    /// constant and ġ = −f_θᵀλ too (the segment is one exact step backwards).
    #[inline]
    fn constant_rate(&self) -> bool {
        !self.rhs.flow.has_rc && self.rhs.flow.model.flow_is_constant(self.rhs.flow.mode)
    }

    #[inline]
    fn evals(&self) -> usize {
        self.rhs.flow.evals
    }

    /// `WeightedRms` over λ with weight 1 (g is a quadrature outside the vector; see the
    /// module doc).
    #[inline]
    fn error_norm(&self, e: &Self::Vector, y0: &Self::Vector, y1: &Self::Vector, tol: Tol) -> f64 {
        let mut rms = WeightedRms::new(tol);
        rms.add(e.as_slice(), y0.as_slice(), y1.as_slice(), 1.0);
        rms.norm()
    }

    fn nonfinite_part(&self, y: &Self::Vector) -> Option<&'static str> {
        (!y.iter().all(|v| v.is_finite())).then_some("adjoint state λ")
    }

    /// `adjoint of the flow of mode `m``.
    fn flow_name(&self) -> String {
        format!(
            "adjoint of the flow of mode `{}`",
            self.rhs.flow.mode_name()
        )
    }

    fn stage_source(&self, _k: &Self::Vector) -> String {
        self.flow_name()
    }

    #[inline]
    fn has_quadrature(&self) -> bool {
        true
    }

    /// g's local error enters the step acceptance, as S's does in forward mode
    /// (`Options::sens_error_control`): λ is smooth through the primal's fast transients
    /// (the adjoint of a stiff lag is quasi-steady), while G = −(λᵀf_θ + w ℓ_θ) is not
    /// (−λ_u(1 − u)/τ² spikes to ~1/τ there): an error norm over λ alone strides over it.
    #[inline]
    fn controls_quadrature(&self) -> bool {
        self.quad.controlled
    }

    /// The quadrature's local error goes into the sweep's estimate, when it keeps one.
    #[inline]
    fn estimates_quadrature_error(&self) -> bool {
        self.global.is_some()
    }

    #[inline]
    fn quadrature_clear(&mut self, sum: QuadratureSum) {
        let q = &mut self.quad;
        let v = match sum {
            QuadratureSum::Step => &mut q.step,
            QuadratureSum::Error => &mut q.err,
        };
        for &k in &q.support {
            v[k] = 0.0;
        }
    }

    /// G(t, λ) = −(λᵀf_θ + w ℓ_θ) at x(t), the model's sparse product, once: straight into
    /// the one sum with a non-zero weight, or into a scratch (zeroed on the support) and
    /// from there into both.
    #[inline]
    fn quadrature_add(&mut self, t: f64, y: &Self::Vector, a: f64, e: f64) {
        self.hist.at(t);
        let rhs = &mut self.rhs;
        rhs.flow.evals += 1;
        let pt = rhs.point(t, &self.hist.x);
        let q = &mut self.quad;
        match (a != 0.0, e != 0.0) {
            (true, false) => rhs
                .flow
                .model
                .adjoint_quadrature_add(pt, y, rhs.w, a, &mut q.step),
            (false, true) => rhs
                .flow
                .model
                .adjoint_quadrature_add(pt, y, rhs.w, e, &mut q.err),
            (true, true) => {
                for &k in &q.support {
                    q.stage[k] = 0.0;
                }
                rhs.flow
                    .model
                    .adjoint_quadrature_add(pt, y, rhs.w, 1.0, &mut q.stage);
                for &k in &q.support {
                    let gk = q.stage[k];
                    q.step[k] += a * gk;
                    q.err[k] += e * gk;
                }
            }
            (false, false) => {}
        }
    }

    /// `WeightedRms` over the support of the error of Δg against g and g + Δg, entry j
    /// weighted by `gradient_weight``(θ_j)`: g is a running sum, held relative to its own
    /// size as forward mode holds S.
    fn quadrature_error_norm(&self, tol: Tol) -> f64 {
        let q = &self.quad;
        let mut rms = WeightedRms::new(tol);
        for &k in &q.support {
            let g0 = self.g[k];
            let w = gradient_weight(self.rhs.flow.p[k]);
            rms.add_entry(q.err[k], g0, g0 + q.step[k], w);
        }
        rms.norm()
    }

    /// g += Δg, and with `error` the estimate's r_g += the step's error (on the support).
    fn quadrature_close(&mut self, error: bool) {
        let q = &self.quad;
        for &k in &q.support {
            self.g[k] += q.step[k];
        }
        if let (true, Some(ge)) = (error, self.global.as_mut()) {
            let (_, r_g) = ge.remainder_mut();
            for &k in &q.support {
                r_g[k] += q.err[k];
            }
        }
    }
}

impl<M: HybridModel> ImplicitSystem for Backward<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    type Linear = Linearisation<M::N, OVector<f64, M::N>>;

    /// J_λλ = −f_xᵀ (and its spectral radius), F_t and G_t at the step start.
    fn prepare(&mut self, t0: f64, y0: &Self::Vector, _h: f64) {
        self.time_derivatives(t0, y0);
        let Backward { rhs, imp, .. } = self;
        let w = &mut imp.lin.w;
        adjoint_jacobian(rhs.flow.model, rhs.point(t0, &imp.x0), w);
        w.power_iteration();
        imp.lin.prepared = true;
    }

    fn linearisation(&mut self) -> &mut Self::Linear {
        &mut self.imp.lin
    }

    /// K_λ = W⁻¹ hγ R_λ (see the module doc).
    fn solve_stage(
        &mut self,
        _t0: f64,
        _y0: &Self::Vector,
        hg: f64,
        rk: &mut Self::Vector,
    ) -> bool {
        self.imp.lin.w.solve_scaled(hg, rk)
    }

    /// `sum` += a·J_gλ v = −a·f_θᵀv at the step start (x(t0)).
    fn quadrature_jac_add(&mut self, t0: f64, v: &Self::Vector, a: f64, sum: QuadratureSum) {
        self.hist.at(t0);
        let rhs = &mut self.rhs;
        let pt = rhs.point(t0, &self.hist.x);
        let target = self.quad.sum_mut(sum);
        rhs.flow.model.adjoint_quadrature_add(pt, v, 0.0, a, target);
    }

    /// `sum` += a·G_t at the step start (from `prepare`, recomputed if it was for another
    /// one), on the support (G_t vanishes off it).
    fn quadrature_dt_add(&mut self, t0: f64, y0: &Self::Vector, a: f64, sum: QuadratureSum) {
        if self.imp.dt_at != Some(t0) {
            self.time_derivatives(t0, y0);
            self.imp.lin.prepared = false;
        }
        let dt_g = &self.imp.dt_g;
        let q = &mut self.quad;
        let target = match sum {
            QuadratureSum::Step => &mut q.step,
            QuadratureSum::Error => &mut q.err,
        };
        for &k in &q.support {
            target[k] += a * dt_g[k];
        }
    }

    /// `AdjointError::carry` with J = −f_xᵀ and the sparse product f_θᵀv at the step start
    /// (t₀, x(t₀)), evaluated here: the step's own Rosenbrock Jacobian is gone by the time it
    /// is carried (see [`super::Forward`]'s). g's own local error is added by the quadrature
    /// (`QuadratureSum::Error`).
    ///
    /// The primal run's state error e_x = r_x + α f at the step (from the tape) is a forcing:
    /// F and G are evaluated along x + e_x, so the step adds h δF to r_λ and h δG to r_g with
    /// δF = F(t₀, x + e_x, λ₀) − F(t₀, x, λ₀) and δG likewise: secants over the actual
    /// displacement (`adjoint_rate` twice, and the sparse `adjoint_quadrature_add` with ±h,
    /// never a p-long vector). A displacement at which F is not finite adds nothing.
    fn carry_global_error(&mut self, step: AcceptedStep<'_, Self::Vector>) {
        let AcceptedStep { t0, h, y0, le, .. } = step;
        let Backward {
            rhs,
            hist,
            imp,
            global,
            coupling,
            ..
        } = self;
        let (Some(ge), Some(c)) = (global, coupling) else {
            return;
        };
        hist.at(t0);
        let model = rhs.flow.model;
        let pt = rhs.point(t0, &hist.x);
        let (_, r_g) = ge.remainder_mut();
        let mut forcing = None;
        if let Some((rx, alpha)) = hist.tape.state_error(hist.cursor) {
            c.ex.as_mut_slice().copy_from_slice(rx);
            if alpha != 0.0 {
                model.rhs(pt, &mut c.f);
                c.ex.axpy(alpha, &c.f, 1.0);
            }
            if c.ex.iter().any(|&e| e != 0.0) {
                c.xe.copy_from(&hist.x);
                c.xe += &c.ex;
                let pe = rhs.point(t0, &c.xe);
                model.adjoint_rate(pe, y0, rhs.w, &mut c.d);
                model.adjoint_rate(pt, y0, rhs.w, &mut c.f);
                c.d -= &c.f;
                if c.d.iter().all(|v| v.is_finite()) {
                    model.adjoint_quadrature_add(pe, y0, rhs.w, h, r_g);
                    model.adjoint_quadrature_add(pt, y0, rhs.w, -h, r_g);
                    forcing = Some(&c.d);
                }
            }
        }
        adjoint_jacobian(model, pt, &mut imp.lin.w);
        // J now holds the carried step's start, not the next step's.
        imp.lin.prepared = false;
        let pattern = &model.info().jacobian_sparsity[rhs.flow.mode];
        ge.carry(le, forcing, &mut imp.lin.w, pattern, h, |v, a, g| {
            model.adjoint_quadrature_add(pt, v, 0.0, a, g)
        });
    }

    fn spectral_radius_at(&mut self, t: f64, _y: &Self::Vector) -> f64 {
        let Backward { rhs, hist, imp, .. } = self;
        hist.at(t);
        let w = &mut imp.lin.w;
        rhs.flow.model.rhs_jac_x(rhs.point(t, &hist.x), &mut w.jac);
        w.power_iteration()
    }
}

/// J_λλ = −f_xᵀ at `pt` into `w.jac`.
fn adjoint_jacobian<M: HybridModel>(model: &M, pt: Point<'_, M::N, M::P>, w: &mut WMatrix<M::N>)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    model.rhs_jac_x(pt, &mut w.jac);
    w.jac.transpose_mut();
    w.jac.neg_mut();
}

impl<'a, M: HybridModel> Integrator<Backward<'a, M>>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// Forget all history and restart at (s, λ) on segment `seg` (its mode, switch bits and
    /// recorded steps), in the segment's local time s = t − t_start (see
    /// [`crate::adjoint::record`]); then `step(s_stop)` with s_stop < s integrates backwards.
    pub fn restart_segment(&mut self, seg: &'a SegmentRec, s: f64, lambda: &OVector<f64, M::N>) {
        // The last step of the previous segment is closed on that segment.
        self.close_step();
        let sys = &mut self.sys;
        sys.hist.seg = Some(seg);
        sys.hist.cursor = seg.steps.end.saturating_sub(1);
        sys.rhs.flow.mode = seg.mode;
        sys.rhs.flow.sw.clone_from(&seg.sw);
        sys.rhs.t_start = seg.t_start;
        let q = &mut sys.quad;
        q.support.clear();
        match sys.rhs.flow.model.gradient_support(seg.mode) {
            Some(support) => q.support.extend_from_slice(support),
            None => q.support.extend(0..sys.g.len()),
        }
        self.restart_at(s, lambda);
    }

    /// g, the gradient accumulated so far, with the last accepted step's quadrature added
    /// (the sweep adds the jumps', samples' and end terms to it).
    pub fn gradient_mut(&mut self) -> &mut OVector<f64, M::P> {
        self.close_step();
        &mut self.sys.g
    }

    /// g and the sweep's global error estimate (`None` when `Options::global_error` is off),
    /// with the last accepted step closed (its quadrature and its error added).
    pub fn gradient_and_error_mut(&mut self) -> GradientAndError<'_, M::N, M::P> {
        self.close_step();
        (&mut self.sys.g, self.sys.global.as_mut())
    }
}
