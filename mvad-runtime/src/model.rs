//! The model trait: the one seam between the `.hyb` front end and the numerics.
//!
//! A hybrid model has a state x ∈ Rⁿ, parameters θ ∈ Rᵖ, a discrete mode m and,
//! per mode, a flow ẋ = f_m(t, x, θ). Events k have a guard g_k(t, x, θ) that fires
//! when it crosses zero in its armed direction, a reset x⁺ = R_k(t, x⁻, θ) and an
//! optional target mode. Observables y = h(t, x, θ) and the cost
//! C = ∫₀ᵀ ℓ dt + Σ_k φ_k(t_k, x(t_k⁺), θ) + Φ(T, x(T), θ) complete the model.
//!
//! Both doors implement [`HybridModel`]: the `hybrid!` macro with static sizes
//! (`Const<N>`, `Const<P>`) and the run-time loader with dynamic sizes (`Dyn`), so the
//! integrators, the event code and the sensitivities are written once.
//!
//! ## Non-smooth flows and switches
//! `abs`, `min`, `max`, `sign` and `if` inside a flow or the running cost ℓ are
//! evaluated with *frozen branches*: the model exposes each such kink as a switching
//! function σ_j(t, x, θ), and the flow reads the branch from bit j of a [`Switches`]
//! word instead of from the sign of σ_j. The runtime keeps the bits constant over a
//! step, locates zero crossings of σ_j like events (identity reset, no mode change) and
//! flips the bit there, so no step straddles a kink and the saltation update
//! S⁺ = S⁻ + (f⁻ − f⁺) t' stays exact. Bit j is set iff the branch for σ_j > 0 is
//! active. Outside flows and ℓ (guards, resets, observables, event and final costs)
//! these functions are evaluated pointwise and need no bits.
//!
//! ## Conventions
//! - All evaluation methods write into caller-provided buffers and never allocate.
//! - Matrices are nalgebra matrices; for observables, whose count is not a type-level
//!   dimension, Jacobians are row-major slices (`nobs × n`, `nobs × p`).
//! - Gradient methods *overwrite* every entry of their outputs (zeros included).

use crate::qp::{QpBank, QpError, QpFlowKink, QpLayerInfo, QpState, Side};
use std::cell::RefCell;

pub mod dense;
pub mod differences;
mod point;
use nalgebra::{allocator::Allocator, DefaultAllocator, Dim, OMatrix, OVector};
pub use point::{At, Occurrence, Point, Switches};

/// Bound alias for the allocators a model's dimensions need (one line in every where-clause).
pub trait ModelAlloc<N: Dim, P: Dim>:
    Allocator<N> + Allocator<P> + Allocator<N, N> + Allocator<N, P> + Allocator<P, N>
{
}

impl<N: Dim, P: Dim, A> ModelAlloc<N, P> for A where
    A: Allocator<N> + Allocator<P> + Allocator<N, N> + Allocator<N, P> + Allocator<P, N>
{
}

/// The static description of a model (its names, events and which parts exist): plain data
/// the front end builds and both doors hand over as it is (crate `mvad-info`).
pub use mvad_info::{Direction, EventInfo, ModelInfo, Trigger};

/// The dimensions of a model: `N` the state dimension, `P` the parameter dimension
/// (`Const<_>` for models compiled by `hybrid!`, `Dyn` for models loaded at run time).
/// Its own trait so that the capability traits can name them without depending on
/// [`HybridModel`].
pub trait ModelDims {
    /// State dimension n.
    type N: Dim;
    /// Parameter dimension p.
    type P: Dim;
}

/// The flow-side evaluation point [`Point`] of a model `M` (its dimensions N, P).
pub type PointOf<'a, M> = Point<'a, <M as ModelDims>::N, <M as ModelDims>::P>;
/// The pointwise evaluation point [`At`] of a model `M` (its dimensions N, P).
pub type AtOf<'a, M> = At<'a, <M as ModelDims>::N, <M as ModelDims>::P>;

/// A hybrid model: its core — sizes, structure, and the values and first derivatives of
/// x₀, T, f, g, R, σ, h, ℓ, φ and Φ that the forward method needs — on top of the
/// capability traits ([`ModelSens`], [`ModelAdjoint`], [`ModelSecondOrder`]), whose
/// defaults are built from these methods. A model that has no better form of a capability
/// opts into its default with an empty `impl`. Integrators, the event code and the
/// reductions bound on this trait, and importing it brings every core method into scope.
///
/// ## Gradient convention
/// Every `*_grad(.., gx, gp) -> f64` method of a scalar function u(t, x, θ) *overwrites*
/// `gx` with ∇ₓu and `gp` with ∂u/∂θ and **returns ∂u/∂t**. The one method that returns
/// the value instead is named for it: [`HybridModel::running_cost_value_grad`] returns ℓ
/// (the quadrature needs ℓ with its gradient, never ∂ℓ/∂t). Vector functions have `*_jac`
/// methods that fill every block they name (∂R/∂t included). Functions of θ alone (x₀, T)
/// have no x or t part.
pub trait HybridModel: ModelDims + ModelSens + ModelAdjoint + ModelSecondOrder
where
    DefaultAllocator: ModelAlloc<Self::N, Self::P>,
{
    /// Names, defaults and structure.
    fn info(&self) -> &ModelInfo;
    /// n as a dimension value (`Const::<n>` or `Dyn(n)`).
    fn nstates(&self) -> Self::N;
    /// p as a dimension value.
    fn nparams(&self) -> Self::P;

    // ---- initial state and horizon --------------------------------------------------

    /// x₀(θ).
    fn initial_state(&self, p: &OVector<f64, Self::P>, x0: &mut OVector<f64, Self::N>);
    /// ∂x₀/∂θ (n×p).
    fn initial_state_jac(
        &self,
        p: &OVector<f64, Self::P>,
        dx0: &mut OMatrix<f64, Self::N, Self::P>,
    );
    /// T(θ), or `None` when the model declares no horizon.
    fn horizon(&self, p: &OVector<f64, Self::P>) -> Option<f64>;
    /// dT/dθ (zeros when there is no horizon or it is constant).
    fn horizon_grad(&self, p: &OVector<f64, Self::P>, dt: &mut OVector<f64, Self::P>);

    // ---- flow -------------------------------------------------------------------------

    /// f_m(t, x, θ) at `pt` = (m, sw, t, x, θ), with the frozen branches `pt.sw`.
    fn rhs(&self, pt: PointOf<'_, Self>, f: &mut OVector<f64, Self::N>);
    /// ∂f_m/∂x (n×n).
    fn rhs_jac_x(&self, pt: PointOf<'_, Self>, fx: &mut OMatrix<f64, Self::N, Self::N>);
    /// ∂f_m/∂θ (n×p).
    fn rhs_jac_p(&self, pt: PointOf<'_, Self>, fp: &mut OMatrix<f64, Self::N, Self::P>);
    /// ∂f_m/∂t (zeros for an autonomous flow).
    fn rhs_dt(&self, pt: PointOf<'_, Self>, ft: &mut OVector<f64, Self::N>);
    /// Whether f_m depends on t explicitly.
    fn rhs_depends_on_t(&self, mode: usize) -> bool;
    /// Whether f_m is a function of θ alone (it reads no state, no t, no switch bit, no qp):
    /// then x(t) = x₀ + (t − t₀) f and S(t) = S₀ + (t − t₀) f_θ along a segment, and the
    /// integrator takes the segment in one exact step. The default, `false`, is always safe.
    fn flow_is_constant(&self, mode: usize) -> bool {
        let _ = mode;
        false
    }

    // ---- events -----------------------------------------------------------------------

    /// g_k(t, x, θ) = LHS − RHS of event k's guard.
    fn guard(&self, event: usize, at: AtOf<'_, Self>) -> f64;
    /// Whether the guard of event k is affine in (x, t) (its derivatives in x and t are
    /// functions of θ alone): on a segment of a constant flow
    /// ([`HybridModel::flow_is_constant`]) it is then affine in t and the event loop samples
    /// it only at the ends of a step. The default, `false`, is always safe.
    fn guard_is_affine(&self, event: usize) -> bool {
        let _ = event;
        false
    }
    /// ∇ₓg_k into `gx`, ∂θg_k into `gp`; returns ∂ₜg_k.
    fn guard_grad(
        &self,
        event: usize,
        at: AtOf<'_, Self>,
        gx: &mut OVector<f64, Self::N>,
        gp: &mut OVector<f64, Self::P>,
    ) -> f64;
    /// x⁺ = R_k(t, x⁻, θ) (the identity for states the reset block does not assign), at
    /// occurrence j of event k (see [`Trigger`]: for `at each` the table row whose values
    /// the reset reads).
    fn reset(&self, occ: Occurrence, at: AtOf<'_, Self>, xplus: &mut OVector<f64, Self::N>);
    /// ∂R_k/∂x into `rx`, ∂R_k/∂θ into `rp`, ∂R_k/∂t into `rt`, at occurrence j.
    fn reset_jac(
        &self,
        occ: Occurrence,
        at: AtOf<'_, Self>,
        rx: &mut OMatrix<f64, Self::N, Self::N>,
        rp: &mut OMatrix<f64, Self::N, Self::P>,
        rt: &mut OVector<f64, Self::N>,
    );

    /// τ_kj(θ): the time of occurrence j of time event k (for `at each`, row j of its table;
    /// for `every`, start + j·period; for `at`, j = 0). The default, for models without time
    /// events, is NaN.
    fn event_time(&self, occ: Occurrence, p: &OVector<f64, Self::P>) -> f64 {
        let _ = (occ, p);
        f64::NAN
    }
    /// ∂τ_kj/∂θ into `dtau` (NaN by default, like [`HybridModel::event_time`]).
    fn event_time_grad(
        &self,
        occ: Occurrence,
        p: &OVector<f64, Self::P>,
        dtau: &mut OVector<f64, Self::P>,
    ) {
        let _ = (occ, p);
        dtau.fill(f64::NAN);
    }

    // ---- switching functions ----------------------------------------------------------

    /// σ_j(t, x, θ).
    fn switch_value(&self, j: usize, at: AtOf<'_, Self>) -> f64;
    /// ∇ₓσ_j into `gx`, ∂θσ_j into `gp`; returns ∂ₜσ_j.
    fn switch_grad(
        &self,
        j: usize,
        at: AtOf<'_, Self>,
        gx: &mut OVector<f64, Self::N>,
        gp: &mut OVector<f64, Self::P>,
    ) -> f64;

    // ---- observables ------------------------------------------------------------------

    /// y = h(t, x, θ), one entry per observable, with the frozen branches `sw` (an
    /// observable's kinks are switches like a flow's: the bits of the segment t lies in,
    /// and at a crossing those on the side asked for).
    fn observe(&self, sw: &Switches, at: AtOf<'_, Self>, y: &mut [f64]);
    /// ∂h/∂x (row-major nobs×n) and ∂h/∂θ (row-major nobs×p), with the frozen branches `sw`.
    fn observe_jac(&self, sw: &Switches, at: AtOf<'_, Self>, yx: &mut [f64], yp: &mut [f64]);

    // ---- cost -------------------------------------------------------------------------

    /// Running cost ℓ(t, x, θ) (sum of the `integral` terms with their factors), with the
    /// frozen branches `sw`.
    fn running_cost(&self, sw: &Switches, at: AtOf<'_, Self>) -> f64;
    /// ℓ_x into `lx`, ℓ_θ into `lp`; returns the value ℓ (not ∂ℓ/∂t, which no caller needs).
    fn running_cost_value_grad(
        &self,
        sw: &Switches,
        at: AtOf<'_, Self>,
        lx: &mut OVector<f64, Self::N>,
        lp: &mut OVector<f64, Self::P>,
    ) -> f64;
    /// φ_k(t, x⁺, θ): the `sum(EVENT, ..)` terms of event k, evaluated after its reset, at
    /// occurrence j.
    fn event_cost(&self, occ: Occurrence, at: AtOf<'_, Self>) -> f64;
    /// φ_x into `cx`, φ_θ into `cp`; returns φ_t (at occurrence j).
    fn event_cost_grad(
        &self,
        occ: Occurrence,
        at: AtOf<'_, Self>,
        cx: &mut OVector<f64, Self::N>,
        cp: &mut OVector<f64, Self::P>,
    ) -> f64;
    /// Φ(T, x(T), θ): the `final(..)` terms.
    fn final_cost(&self, at: AtOf<'_, Self>) -> f64;
    /// Φ_x into `cx`, Φ_θ into `cp`; returns Φ_t.
    fn final_cost_grad(
        &self,
        at: AtOf<'_, Self>,
        cx: &mut OVector<f64, Self::N>,
        cp: &mut OVector<f64, Self::P>,
    ) -> f64;
    // ---- optimisation layers (qp) ------------------------------------------------------
    //
    // A model's qps are solved inside its evaluation methods (see `crate::qp::QpBank`); the
    // runtime only reports on them. A model without qps keeps these defaults; a model that
    // keeps its qps in a `QpBank` hands it over (`qp_bank`), and the methods that only ask
    // the bank (side, failure, kink, persistent kinks, pins) are answered by it.

    /// The model's qp layers, in declaration order.
    fn qps(&self) -> &[QpLayerInfo] {
        &[]
    }
    /// The bank that solves the model's qps, if it keeps one (`None` by default: no qps).
    fn qp_bank(&self) -> Option<&RefCell<QpBank>> {
        None
    }
    /// Every qp solved at (t, x, θ): solutions, multipliers and constraint statuses, for
    /// reports (it may allocate); the first failure as (qp index, error).
    fn qp_states(&self, at: AtOf<'_, Self>) -> Result<Vec<QpState>, (usize, QpError)> {
        let _ = at;
        Ok(Vec::new())
    }
    /// Chooses the one-sided derivative the qps give at a kink from now on (right by
    /// default).
    fn set_qp_side(&self, side: Side) {
        if let Some(bank) = self.qp_bank() {
            bank.borrow_mut().set_side(side);
        }
    }
    /// The qp failure behind the non-finite values of the last evaluation, if any.
    fn qp_failure(&self) -> Option<(usize, QpError)> {
        let bank = self.qp_bank()?.borrow();
        bank.failure().map(|(q, e)| (q, e.clone()))
    }
    /// The first weakly active constraint of the last evaluation, as (qp, constraint): the
    /// point is a kink of the qp's solution map. Allocates nothing.
    fn qp_kink(&self) -> Option<(usize, usize)> {
        self.qp_bank()?.borrow().kink()
    }
    /// At the flow point `pt` (rate f): whether a qp of the state that the flow reads, on
    /// the active set `pt.sw` freezes, has a constraint weakly active *along* the flow — a
    /// persistent kink, where the solution's derivative is one-sided and not linear in the
    /// direction (see [`crate::qp::QpBank::flow_pieces`]; each such constraint is logged for
    /// [`HybridModel::qp_flow_kinks`]). With `s` = S, `pieces[j]` (p entries) receives the
    /// switch bits of the piece whose derivative is the one-sided one (on the side of
    /// [`HybridModel::set_qp_side`]) along column j's direction (S_j, e_j); untouched when
    /// there is no such kink. `None` when a qp failed ([`HybridModel::qp_failure`]).
    fn qp_flow_pieces(
        &self,
        pt: PointOf<'_, Self>,
        f: &OVector<f64, Self::N>,
        s: Option<&OMatrix<f64, Self::N, Self::P>>,
        pieces: &mut [Switches],
    ) -> Option<bool> {
        let _ = (pt, f, s, pieces);
        Some(false)
    }
    /// The persistent kinks [`HybridModel::qp_flow_pieces`] met since the last
    /// [`HybridModel::clear_qp_flow_kinks`] (it may allocate).
    fn qp_flow_kinks(&self) -> Vec<QpFlowKink> {
        self.qp_bank()
            .map_or_else(Vec::new, |bank| bank.borrow().flow_kinks().to_vec())
    }
    /// Forgets the persistent kinks met so far (at the start of a run).
    fn clear_qp_flow_kinks(&self) {
        if let Some(bank) = self.qp_bank() {
            bank.borrow_mut().clear_flow_kinks();
        }
    }
    /// Where qp q, solved pointwise at `at`, has a weakly active constraint: the active set
    /// of the smooth piece whose derivative is its one-sided derivative (on the side of
    /// [`HybridModel::set_qp_side`]) along the direction (dx, e_j, dt) of (x, θ, t), into
    /// `active` (one entry per constraint), and `Some(true)`; `Some(false)` away from a
    /// kink, `None` when the qp fails (see [`crate::qp::QpBank::pointwise_piece`]).
    fn qp_piece(
        &self,
        q: usize,
        at: AtOf<'_, Self>,
        direction: (&OVector<f64, Self::N>, usize, f64),
        active: &mut [bool],
    ) -> Option<bool> {
        let _ = (q, at, direction, active);
        Some(false)
    }
    /// Pins qp q's pointwise evaluations to the active set `active` (`None` unpins; see
    /// [`crate::qp::QpBank::pin`]): its solution and derivatives are then that piece's.
    fn pin_qp(&self, q: usize, active: Option<&[bool]>) {
        if let Some(bank) = self.qp_bank() {
            bank.borrow_mut().pin(q, active);
        }
    }
}

/// Capability: the forward-sensitivity right-hand side.
///
/// The default goes through the dense Jacobians of [`HybridModel`] and allocates an n×n
/// scratch matrix (on the heap for dynamic sizes); generated models override it with
/// sparse straight-line code that allocates nothing.
pub trait ModelSens: ModelDims
where
    DefaultAllocator: ModelAlloc<Self::N, Self::P>,
{
    /// f = f_m(t, x, θ) and Ṡ = f_x S + f_θ (n×p) at `pt`, with the frozen branches `pt.sw`.
    fn rhs_sens(
        &self,
        pt: PointOf<'_, Self>,
        s: &OMatrix<f64, Self::N, Self::P>,
        f: &mut OVector<f64, Self::N>,
        ds: &mut OMatrix<f64, Self::N, Self::P>,
    ) where
        Self: HybridModel,
    {
        let n = self.nstates();
        let mut fx = OMatrix::<f64, Self::N, Self::N>::zeros_generic(n, n);
        self.rhs(pt, f);
        self.rhs_jac_x(pt, &mut fx);
        self.rhs_jac_p(pt, ds);
        ds.gemm(1.0, &fx, s, 1.0);
    }
}

/// Two cotangents μ₁, μ₂ ∈ Rⁿ for one product ([`ModelAdjoint::reset_vjp_pair`]).
pub type CotangentPair<'a, N> = (&'a OVector<f64, N>, &'a OVector<f64, N>);

/// The (x, θ) outputs of a vector–Jacobian product: μᵀ∂/∂x (n) and μᵀ∂/∂θ (p).
pub type VjpOutput<'a, N, P> = (&'a mut OVector<f64, N>, &'a mut OVector<f64, P>);

/// Capability: vector–Jacobian products of the flow, for an adjoint (backward) pass.
///
/// The default forms the dense Jacobians f_x, f_θ and multiplies (it allocates both for
/// dynamic sizes); a model with a cheaper reverse-mode form overrides it.
pub trait ModelAdjoint: ModelDims
where
    DefaultAllocator: ModelAlloc<Self::N, Self::P>,
{
    /// λᵀf_x into `vx` (n) and λᵀf_θ into `vp` (p), for f = f_m(t, x, θ) at `pt`:
    /// vx_j = Σᵢ λᵢ ∂fᵢ/∂x_j, vp_k = Σᵢ λᵢ ∂fᵢ/∂θ_k. Both outputs are overwritten.
    fn rhs_vjp(
        &self,
        pt: PointOf<'_, Self>,
        lambda: &OVector<f64, Self::N>,
        vx: &mut OVector<f64, Self::N>,
        vp: &mut OVector<f64, Self::P>,
    ) where
        Self: HybridModel,
    {
        let (n, np) = (self.nstates(), self.nparams());
        let mut fx = OMatrix::<f64, Self::N, Self::N>::zeros_generic(n, n);
        let mut fp = OMatrix::<f64, Self::N, Self::P>::zeros_generic(n, np);
        self.rhs_jac_x(pt, &mut fx);
        self.rhs_jac_p(pt, &mut fp);
        fx.tr_mul_to(lambda, vx);
        fp.tr_mul_to(lambda, vp);
    }

    /// The backward sweep's rate of λ: out = −(λᵀf_x + w ℓ_x) (overwritten; ℓ not evaluated
    /// when w = 0), touching nothing of size p. The default is [`dense::adjoint_rate`].
    fn adjoint_rate(
        &self,
        pt: PointOf<'_, Self>,
        lambda: &OVector<f64, Self::N>,
        w: f64,
        out: &mut OVector<f64, Self::N>,
    ) where
        Self: HybridModel,
    {
        dense::adjoint_rate(self, pt, lambda, w, out);
    }

    /// ℓ_x alone into `lx` (n, overwritten; zeros without a running cost), with the frozen
    /// branches `sw`, touching nothing of size p: what the global error estimate of a run
    /// without sensitivities (the adjoint's primal run) needs of ℓ at every step, and what
    /// the implicit stages read (`integrate::forward`). The default is
    /// [`dense::running_cost_grad_x`].
    fn running_cost_grad_x(&self, sw: &Switches, at: AtOf<'_, Self>, lx: &mut OVector<f64, Self::N>)
    where
        Self: HybridModel,
    {
        dense::running_cost_grad_x(self, sw, at, lx);
    }

    /// The sweep's gradient quadrature, scaled and added: g += −a (λᵀf_θ + w ℓ_θ), touching
    /// only the structural non-zeros of f_θ and ℓ_θ (`integrate::quadrature`). The default
    /// is [`dense::adjoint_quadrature_add`].
    fn adjoint_quadrature_add(
        &self,
        pt: PointOf<'_, Self>,
        lambda: &OVector<f64, Self::N>,
        w: f64,
        a: f64,
        g: &mut OVector<f64, Self::P>,
    ) where
        Self: HybridModel,
    {
        dense::adjoint_quadrature_add(self, pt, lambda, w, a, g);
    }

    /// The support of the sweep's gradient quadrature G = −(λᵀf_θ + w ℓ_θ) in mode `mode`:
    /// the parameters k, ascending and without repeats, whose column of f_θ (the mode's flow)
    /// or of ℓ_θ can be non-zero. [`ModelAdjoint::adjoint_quadrature_add`] writes g nowhere
    /// else, so the sweep keeps its per-step work on g (stage values, the step's increment,
    /// its error norm) on these entries (`integrate::adjoint`). `None`, the default, stands
    /// for every parameter 0..p; both doors give the symbolic support
    /// (`ModelKernels::gradient_support`).
    fn gradient_support(&self, _mode: usize) -> Option<&[usize]> {
        None
    }

    /// μᵀR_x into `vx` (n) and μᵀR_θ into `vp` (p) for event k's reset x⁺ = R_k(t, x, θ) at
    /// occurrence j;
    /// returns μᵀ∂R_k/∂t: vx_j = Σᵢ μᵢ ∂Rᵢ/∂x_j, vp_k = Σᵢ μᵢ ∂Rᵢ/∂θ_k. Both outputs are
    /// overwritten. The transpose of the reset's linearisation, for the adjoint's jump at an
    /// event. The default forms ∂R/∂x, ∂R/∂θ and ∂R/∂t densely (it allocates them).
    fn reset_vjp(
        &self,
        occ: Occurrence,
        at: AtOf<'_, Self>,
        mu: &OVector<f64, Self::N>,
        vx: &mut OVector<f64, Self::N>,
        vp: &mut OVector<f64, Self::P>,
    ) -> f64
    where
        Self: HybridModel,
    {
        let (n, np) = (self.nstates(), self.nparams());
        let mut rx = OMatrix::<f64, Self::N, Self::N>::zeros_generic(n, n);
        let mut rp = OMatrix::<f64, Self::N, Self::P>::zeros_generic(n, np);
        let mut rt = OVector::<f64, Self::N>::zeros_generic(n, nalgebra::Const::<1>);
        self.reset_jac(occ, at, &mut rx, &mut rp, &mut rt);
        rx.tr_mul_to(mu, vx);
        rp.tr_mul_to(mu, vp);
        mu.dot(&rt)
    }

    /// [`ModelAdjoint::reset_vjp`] for two cotangents at one point: μ₁ᵀR_x, μ₁ᵀR_θ into
    /// `out1` and μ₂ᵀR_x, μ₂ᵀR_θ into `out2`, returning (μ₁ᵀ∂R/∂t, μ₂ᵀ∂R/∂t). The adjoint
    /// sweep transposes each jump for λ and, with a global error estimate, for the estimate's
    /// remainder at the same point; a model whose Jacobian evaluation dominates (a loaded
    /// model's tape, O(p) for a reset with p parameters) evaluates it once for both. The
    /// default is two calls of `reset_vjp`, the same numbers bit for bit.
    fn reset_vjp_pair(
        &self,
        occ: Occurrence,
        at: AtOf<'_, Self>,
        (mu1, mu2): CotangentPair<'_, Self::N>,
        out1: VjpOutput<'_, Self::N, Self::P>,
        out2: VjpOutput<'_, Self::N, Self::P>,
    ) -> (f64, f64)
    where
        Self: HybridModel,
    {
        let r1 = self.reset_vjp(occ, at, mu1, out1.0, out1.1);
        let r2 = self.reset_vjp(occ, at, mu2, out2.0, out2.1);
        (r1, r2)
    }

    /// The derivative of [`ModelAdjoint::rhs_vjp`] along the direction (1, v) of (t, x) at
    /// fixed λ: vx = d/dε λᵀf_x(t + ε, x + εv), vp = d/dε λᵀf_θ(t + ε, x + εv) at ε = 0. With
    /// v = f it is the time derivative of the adjoint's right-hand side along the trajectory,
    /// the F_t of its Rosenbrock stages (`integrate::adjoint`). Both outputs are overwritten.
    /// The default is a central difference of `rhs_vjp` with step ε = min(h_v, h_t) — h_v the
    /// step of the [`ModelSecondOrder`] defaults along v, h_t theirs in t — and allocates
    /// scratch; a model with symbolic second derivatives can give it exactly.
    fn rhs_vjp_dir(
        &self,
        pt: PointOf<'_, Self>,
        lambda: &OVector<f64, Self::N>,
        v: &OVector<f64, Self::N>,
        vx: &mut OVector<f64, Self::N>,
        vp: &mut OVector<f64, Self::P>,
    ) where
        Self: HybridModel,
    {
        differences::rhs_vjp_dir(self, pt, lambda, v, vx, vp);
    }

    /// The derivative of the running cost's gradient along (1, v) of (t, x), with the frozen
    /// branches `sw`: lx = d/dε ℓ_x(t + ε, x + εv), lp = d/dε ℓ_θ(t + ε, x + εv); returns
    /// dℓ/dε (zeros and 0 without a running cost). The default is the central difference of
    /// [`HybridModel::running_cost_value_grad`] with the step of
    /// [`ModelAdjoint::rhs_vjp_dir`]; it allocates scratch.
    fn running_cost_grad_dir(
        &self,
        sw: &Switches,
        at: AtOf<'_, Self>,
        v: &OVector<f64, Self::N>,
        lx: &mut OVector<f64, Self::N>,
        lp: &mut OVector<f64, Self::P>,
    ) -> f64
    where
        Self: HybridModel,
    {
        differences::running_cost_grad_dir(self, sw, at, v, lx, lp)
    }

    /// μᵀ∂x₀/∂θ into `vp` (p), overwritten: the initial state's share of an adjoint
    /// gradient. The default forms ∂x₀/∂θ densely (it allocates it).
    fn initial_state_vjp(
        &self,
        p: &OVector<f64, Self::P>,
        mu: &OVector<f64, Self::N>,
        vp: &mut OVector<f64, Self::P>,
    ) where
        Self: HybridModel,
    {
        let (n, np) = (self.nstates(), self.nparams());
        let mut dx0 = OMatrix::<f64, Self::N, Self::P>::zeros_generic(n, np);
        self.initial_state_jac(p, &mut dx0);
        dx0.tr_mul_to(mu, vp);
    }
}

/// Capability: second-derivative products, for the implicit method's Jacobian of the
/// sensitivity equations and its time derivative (see `integrate::forward`).
///
/// The defaults are central differences of the first-derivative methods ([`ModelSens::rhs_sens`],
/// [`HybridModel::running_cost_value_grad`]); they allocate scratch. Along v the step is
/// h = 1e-4·max(1, ‖x‖₂)/‖v‖₂, far larger than the usual ε^{1/3}: models with cancellation
/// inside f_θ (a lag (u − y)/τ with ∂/∂τ = −(u − y)/τ²) amplify the rounding of x ± h v by
/// 1/h, and with ε^{1/3} the sensitivity of a τ = 1e-8 lag had a 2e-6 error floor, with 1e-4
/// it is 4e-8; central differences are exact when the differenced function is at most
/// quadratic in x and perturb it by O(1e-8) relative for cubic terms. In t the step is
/// ε^{1/3}·max(1, |t|). Both doors (`hybrid!` and loaded models) override every method with
/// exact products from symbolic second derivatives.
pub trait ModelSecondOrder: ModelSens
where
    DefaultAllocator: ModelAlloc<Self::N, Self::P>,
{
    /// (∂/∂x (f_x S + f_θ)) · v into `out` (n×p): out = Σᵢ vᵢ ∂(f_x S + f_θ)/∂xᵢ, the
    /// derivative of the sensitivity right-hand side along the state direction v.
    fn rhs_sens_dir_x(
        &self,
        pt: PointOf<'_, Self>,
        s: &OMatrix<f64, Self::N, Self::P>,
        v: &OVector<f64, Self::N>,
        out: &mut OMatrix<f64, Self::N, Self::P>,
    ) where
        Self: HybridModel,
    {
        differences::rhs_sens_dir_x(self, pt, s, v, out);
    }

    /// ∂ₜ(f_x S + f_θ) into `out` (n×p): the time derivative of the sensitivity right-hand
    /// side at fixed x and S (zeros for an autonomous flow).
    fn rhs_sens_dt(
        &self,
        pt: PointOf<'_, Self>,
        s: &OMatrix<f64, Self::N, Self::P>,
        out: &mut OMatrix<f64, Self::N, Self::P>,
    ) where
        Self: HybridModel,
    {
        differences::rhs_sens_dt(self, pt, s, out);
    }

    /// (∂/∂x (ℓ_x S + ℓ_θ)) · v into `out` (p): out = Σᵢ vᵢ ∂(ℓ_x S + ℓ_θ)/∂xᵢ, the
    /// derivative of the running cost's sensitivity integrand along v (with the frozen
    /// branches `sw`; zeros without a running cost).
    fn running_cost_sens_dir_x(
        &self,
        sw: &Switches,
        at: AtOf<'_, Self>,
        s: &OMatrix<f64, Self::N, Self::P>,
        v: &OVector<f64, Self::N>,
        out: &mut OVector<f64, Self::P>,
    ) where
        Self: HybridModel,
    {
        differences::running_cost_sens_dir_x(self, sw, at, s, v, out);
    }

    /// ∂ₜ(ℓ_x S + ℓ_θ) into `out` (p), at fixed x and S, with the frozen branches `sw`;
    /// returns ∂ₜℓ (zeros and 0 without a running cost).
    fn running_cost_sens_dt(
        &self,
        sw: &Switches,
        at: AtOf<'_, Self>,
        s: &OMatrix<f64, Self::N, Self::P>,
        out: &mut OVector<f64, Self::P>,
    ) -> f64
    where
        Self: HybridModel,
    {
        differences::running_cost_sens_dt(self, sw, at, s, out)
    }
}
