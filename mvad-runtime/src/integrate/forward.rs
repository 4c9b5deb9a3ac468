//! The forward augmented system of one mode, the only place in `integrate/` that calls the
//! model.
//!
//! With frozen mode m and switch bits, Y = (x, S, q, q_θ) and
//!
//! ```text
//!   F(t, Y) = ( f(t, x, θ),  f_x S + f_θ,  ℓ(t, x, θ),  ℓ_x S + ℓ_θ )
//! ```
//!
//! f and f_x S + f_θ come from [`HybridModel::rhs_sens`] (or f alone from
//! [`HybridModel::rhs`] without sensitivities), ℓ, ℓ_x, ℓ_θ from
//! [`HybridModel::running_cost_value_grad`] (only when the model has a running cost; otherwise q ≡ 0);
//! the implicit stages and the global error estimate read ℓ_x alone
//! ([`crate::model::ModelAdjoint::running_cost_grad_x`], nothing of size p).
//!
//! ## The augmented Jacobian, factorised once (for Rodas5P)
//! J = ∂F/∂Y is block lower triangular:
//!
//! ```text
//!        x            S           q   q_θ
//!   x  [ f_x          0           0   0 ]
//!   S  [ B            I_p ⊗ f_x   0   0 ]     B v = ∂_x(f_x S₀ + f_θ) v
//!   q  [ ℓ_x          0           0   0 ]
//!   q_θ[ D            ℓ_xᵀ (·)    0   0 ]     D v = ∂_x(ℓ_x S₀ + ℓ_θ) v
//! ```
//!
//! so with W = I − hγ f_x, factorised by [`WMatrix`] ONCE per attempt, every stage is solved
//! exactly by block forward substitution:
//! K_x = W⁻¹ hγ R_x, K_S = W⁻¹ hγ (R_S + B K_x) (all p columns against one factorisation),
//! K_q = hγ (R_q + ℓ_x K_x), K_{q_θ} = hγ (R_{q_θ} + D K_x + K_Sᵀ ℓ_x).
//! f_x is the model's [`HybridModel::rhs_jac_x`]; the second-derivative actions B K_x and
//! D K_x are the model's [`ModelSecondOrder::rhs_sens_dir_x`] and
//! [`ModelSecondOrder::running_cost_sens_dir_x`] along K_x at (t₀, x₀, S₀), and
//! F_t = (∂ₜf, ∂ₜ(f_x S + f_θ), ∂ₜℓ, ∂ₜ(ℓ_x S + ℓ_θ)) at (t₀, Y₀) comes from
//! [`HybridModel::rhs_dt`], [`ModelSecondOrder::rhs_sens_dt`] (only when f depends on t) and
//! [`ModelSecondOrder::running_cost_sens_dt`] (only with a running cost). Both doors emit
//! these products exactly, from symbolic second derivatives, so J and F_t are exact and
//! nothing here takes a difference quotient (a hand-written model without them gets the
//! trait's central-difference defaults).
//! The S and q_θ orders are verified empirically in the tests.
//!
//! ## Held rows
//! After a Zeno accumulation the states the accumulation constrains are held at its limit
//! (see `solve/zeno.rs`): the system then integrates the *masked* flow, the rows `held` of f
//! and of f_x S + f_θ set to zero after the model's evaluation (and the same rows of f_x,
//! ∂ₜf, ∂ₜ(f_x S + f_θ) and B K_x in the Rosenbrock stages and the global error estimate),
//! so the held states keep their values exactly while the others follow their flow, reading
//! the held values, and q, q_θ integrate ℓ along that. With every row held and no running
//! cost F = 0: a constant rate, one exact step.

use super::aug::{weighted_rms, AugState};
use super::global_error::GlobalError;
use super::rosenbrock::{Linearisation, WMatrix};
use super::system::{AcceptedStep, ImplicitSystem, OdeSystem, Tol};
use super::{Integrator, Scheme};
#[cfg(doc)]
use crate::model::ModelSecondOrder;
use crate::model::{At, HybridModel, ModelAlloc, Point, Switches};
use crate::qp::FlowPieces;
use crate::solution::{Method, Options};
use nalgebra::{Const, DefaultAllocator, Dim, Matrix, OMatrix, OVector, StorageMut};

/// The forward augmented system (x, S, q, q_θ) of `model` at parameters θ in one mode with
/// frozen switch bits (see the module doc).
pub struct Forward<'a, M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    rhs: Rhs<'a, M>,
    /// S and q_θ are under error control.
    sens_err: bool,
    /// Columns of S and length of q_θ: p, or 0 in a primal run of a model whose parameter
    /// dimension is dynamic (so no stage operation or copy touches n·p unused entries).
    sp: M::P,
    imp: ImplicitWork<M::N, M::P>,
    /// The run's global error estimate (`Options::global_error`), with the tolerances that
    /// weigh its split along the flow.
    global: Option<GlobalError<M::N, M::P>>,
    tol: Tol,
    /// Per mode: the constant F of a constant-rate mode ([`OdeSystem::constant_rate`]) once
    /// evaluated, `None` for the other modes (see [`Integrator::restart`]).
    rates: Vec<Option<ConstantRate<M::N, M::P>>>,
}

/// The F of a constant-rate mode, a function of θ, the mode and the switch bits alone
/// (F = (f(θ), f_θ(θ), 0, 0)): evaluated at the first restart into the mode under given
/// bits, reused at every later one under the same bits (buffers allocated once per run).
struct ConstantRate<N: Dim, P: Dim>
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    /// `f` holds F under the bits `sw`.
    valid: bool,
    sw: Switches,
    f: AugState<N, P>,
}

/// One mode's flow of `model` at θ with frozen switch bits, as both systems evaluate it (the
/// forward [`Rhs`] and the adjoint's), and the count of their evaluations.
pub(super) struct ModeFlow<'a, M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    pub(super) model: &'a M,
    pub(super) p: &'a OVector<f64, M::P>,
    pub(super) mode: usize,
    pub(super) sw: Switches,
    /// The model has a running cost ℓ.
    pub(super) has_rc: bool,
    /// Evaluations of F (and of the adjoint's quadrature G).
    pub(super) evals: usize,
}

impl<'a, M: HybridModel> ModeFlow<'a, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// `model` at `p` in its initial mode with its initial switch bits.
    pub(super) fn new(model: &'a M, p: &'a OVector<f64, M::P>) -> Self {
        let info = model.info();
        ModeFlow {
            model,
            p,
            mode: info.initial_mode,
            sw: Switches::new(info.switches),
            has_rc: info.has_running_cost,
            evals: 0,
        }
    }

    /// The model's point (m, sw, t, x, θ).
    #[inline]
    pub(super) fn point<'b>(&'b self, t: f64, x: &'b OVector<f64, M::N>) -> Point<'b, M::N, M::P> {
        Point::new(self.mode, &self.sw, t, x, self.p)
    }

    /// Name of the current mode (or its index if the model names fewer modes).
    pub(super) fn mode_name(&self) -> String {
        self.model.info().mode_name(self.mode)
    }
}

/// Everything F needs, apart from the Rosenbrock buffers so both can be borrowed at once.
struct Rhs<'a, M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    flow: ModeFlow<'a, M>,
    /// S and q_θ are integrated.
    sens: bool,
    /// The rows of f (and of f_x S + f_θ) held at zero, ascending (see the module doc):
    /// empty but during the hold after an accumulation.
    held: Vec<usize>,
    /// ℓ_x scratch.
    lx: OVector<f64, M::N>,
    /// ℓ_θ scratch.
    lp: OVector<f64, M::P>,
    /// The columns of S that follow another qp piece at a persistent qp kink (`None` when
    /// no flow reads a qp; see `crate::qp::FlowPieces`).
    pieces: Option<FlowPieces<M>>,
}

/// The Rodas5P buffers of the forward system (allocated once; empty for `Dyn` sizes when the
/// method is never used).
struct ImplicitWork<N: Dim, P: Dim>
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    /// f_x and the factors of W, and F_t at the step start.
    lin: Linearisation<N, AugState<N, P>>,
    /// ℓ_x at the step start (zeros without running cost).
    lx0: OVector<f64, N>,
    /// A zero S and its q̇_θ_t, full width, for ∂ₜℓ in a narrow primal run (else empty).
    s0: OMatrix<f64, N, P>,
    qp0: OVector<f64, P>,
    /// B K_x and D K_x of a stage solve (its S and q_θ parts).
    bk: AugState<N, P>,
}

impl<'a, M: HybridModel> Forward<'a, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// The forward system of `model` at `p` in its initial mode; allocates its buffers once
    /// (the Rodas5P ones only when `opts.method` may use it).
    pub fn new(model: &'a M, p: &'a OVector<f64, M::P>, opts: &Options) -> Self {
        Self::sized(model, p, opts, false)
    }

    /// [`Forward::new`]; with `narrow`, a primal run (`opts.sensitivities == false`) of a
    /// model with a dynamic parameter dimension gets S of width 0 and q_θ of length 0, so
    /// its vectors (see [`OdeSystem::zeros`]) carry nothing of size n·p. (Rodas5P's F_t needs
    /// ∂ₜℓ, which only `running_cost_sens_dt` gives, and that takes a full S: such a run keeps
    /// one zero S for that call.)
    fn sized(model: &'a M, p: &'a OVector<f64, M::P>, opts: &Options, narrow: bool) -> Self {
        let n = model.nstates();
        let np = model.nparams();
        // The global error estimate factorises I − h f_x on stiff steps, whatever the method.
        let used = matches!(opts.method, Method::Auto | Method::Rosenbrock) || opts.global_error;
        let narrow = narrow && !opts.sensitivities && M::P::try_to_usize().is_none();
        let sp = if narrow { M::P::from_usize(0) } else { np };
        let zero_s = narrow && used && model.info().has_running_cost;
        let s0p = if zero_s || M::P::try_to_usize().is_some() {
            np
        } else {
            M::P::from_usize(0)
        };
        // Unused Rodas5P buffers: empty for Dyn sizes (no allocation).
        let rn = if used || M::N::try_to_usize().is_some() {
            n
        } else {
            M::N::from_usize(0)
        };
        let rp = if used || M::P::try_to_usize().is_some() {
            np
        } else {
            M::P::from_usize(0)
        };
        let rsp = if used { sp } else { rp };
        Forward {
            rhs: Rhs {
                flow: ModeFlow::new(model, p),
                sens: opts.sensitivities,
                held: Vec::new(),
                lx: OVector::zeros_generic(n, Const::<1>),
                lp: OVector::zeros_generic(np, Const::<1>),
                pieces: FlowPieces::new(model),
            },
            sens_err: opts.sens_error_control && opts.sensitivities,
            sp,
            imp: ImplicitWork {
                lin: Linearisation::new(WMatrix::new(n, used), AugState::zeros(rn, rsp)),
                lx0: OVector::zeros_generic(rn, Const::<1>),
                s0: OMatrix::zeros_generic(n, s0p),
                qp0: OVector::zeros_generic(s0p, Const::<1>),
                bk: AugState::zeros(rn, rsp),
            },
            global: opts.global_error.then(|| GlobalError::new(n, sp)),
            tol: Tol {
                atol: opts.atol,
                rtol: opts.rtol,
            },
            rates: (0..model.info().modes.len())
                .map(|mode| {
                    (!model.info().has_running_cost && model.flow_is_constant(mode)).then(|| {
                        ConstantRate {
                            valid: false,
                            sw: Switches::new(model.info().switches),
                            f: AugState::zeros(n, sp),
                        }
                    })
                })
                .collect(),
        }
    }
}

/// Sets the rows `rows` of `m` (a flow vector, a Jacobian or a matrix of sensitivity rates)
/// to zero: the masked flow of held states (see the module doc).
#[inline]
pub(crate) fn zero_rows<R: Dim, C: Dim, S>(m: &mut Matrix<f64, R, C, S>, rows: &[usize])
where
    S: StorageMut<f64, R, C>,
{
    for &i in rows {
        m.row_mut(i).fill(0.0);
    }
}

impl<M: HybridModel> Rhs<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// f_x at `pt` into `jac`, its held rows zero.
    #[inline]
    fn jac_x(&self, pt: Point<'_, M::N, M::P>, jac: &mut OMatrix<f64, M::N, M::N>) {
        self.flow.model.rhs_jac_x(pt, jac);
        zero_rows(jac, &self.held);
    }

    /// Whether F is constant until the next restart: a constant-rate mode (its masked flow
    /// is as constant), or every row held and no running cost (F = 0).
    fn constant(&self, has_slot: bool) -> bool {
        has_slot
            || (!self.flow.has_rc
                && !self.held.is_empty()
                && self.held.len() == self.flow.model.nstates().value())
    }

    /// out = F(t, y): (f, f_x S + f_θ, ℓ, ℓ_x S + ℓ_θ).
    #[inline]
    fn eval(&mut self, t: f64, y: &AugState<M::N, M::P>, out: &mut AugState<M::N, M::P>) {
        self.flow.evals += 1;
        if self.sens {
            self.flow
                .model
                .rhs_sens(self.flow.point(t, &y.x), &y.s, &mut out.x, &mut out.s);
        } else {
            self.flow.model.rhs(self.flow.point(t, &y.x), &mut out.x);
        }
        if !self.held.is_empty() {
            zero_rows(&mut out.x, &self.held);
            if self.sens {
                zero_rows(&mut out.s, &self.held);
            }
        }
        if !self.flow.has_rc {
            out.q = 0.0;
            if self.sens {
                out.qp.fill(0.0);
            }
        } else if self.sens {
            out.q = self.flow.model.running_cost_value_grad(
                &self.flow.sw,
                At::new(t, &y.x, self.flow.p),
                &mut self.lx,
                &mut self.lp,
            );
            out.qp.copy_from(&self.lp);
            out.qp.gemv_tr(1.0, &y.s, &self.lx, 1.0);
        } else {
            out.q = self
                .flow
                .model
                .running_cost(&self.flow.sw, At::new(t, &y.x, self.flow.p));
        }
        if let Some(pieces) = &mut self.pieces {
            let dq = (self.sens && self.flow.has_rc).then_some(&mut out.qp);
            let pt = self.flow.point(t, &y.x);
            let s = self.sens.then_some(&y.s);
            pieces.correct(self.flow.model, pt, s, &mut out.x, &mut out.s, dq);
            zero_rows(&mut out.s, &self.held);
        }
    }
}

impl<M: HybridModel> OdeSystem for Forward<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    type Vector = AugState<M::N, M::P>;

    /// (x, S, q, q_θ) with S n×p, or n×0 in a primal run of a `Dyn`-parameter model.
    fn zeros(&self) -> Self::Vector {
        AugState::zeros(self.rhs.flow.model.nstates(), self.sp)
    }

    #[inline]
    fn all_parts(&self) -> bool {
        self.rhs.sens
    }

    /// F reads S (f_x S + f_θ) whenever it is integrated.
    #[inline]
    fn reads_secondary(&self) -> bool {
        self.rhs.sens
    }

    #[inline]
    fn controls_all(&self) -> bool {
        self.sens_err
    }

    /// out = F(t, y): (f, f_x S + f_θ, ℓ, ℓ_x S + ℓ_θ).
    #[inline]
    fn eval(&mut self, t: f64, y: &Self::Vector, out: &mut Self::Vector) {
        self.rhs.eval(t, y, out);
    }

    /// A mode whose flow is a function of θ alone ([`HybridModel::flow_is_constant`]) and no
    /// running cost: F = (f(θ), f_θ(θ), 0, 0) (its held rows zero); or every row held and no
    /// running cost: F = 0.
    #[inline]
    fn constant_rate(&self) -> bool {
        // `rates` holds a slot exactly for the modes with !has_rc && flow_is_constant.
        let slot = matches!(self.rates.get(self.rhs.flow.mode), Some(Some(_)));
        self.rhs.constant(slot)
    }

    #[inline]
    fn evals(&self) -> usize {
        self.rhs.flow.evals
    }

    /// `weighted_rms`: x, q (with a running cost) and, under sensitivity error control, S and
    /// q_θ with column j weighted by |θ_j|.
    #[inline]
    fn error_norm(&self, e: &Self::Vector, y0: &Self::Vector, y1: &Self::Vector, tol: Tol) -> f64 {
        let flow = &self.rhs.flow;
        weighted_rms(e, y0, y1, tol, flow.has_rc, self.sens_err, flow.p)
    }

    fn nonfinite_part(&self, y: &Self::Vector) -> Option<&'static str> {
        y.nonfinite_part(self.rhs.sens)
    }

    /// `flow of mode `m``.
    fn flow_name(&self) -> String {
        format!("flow of mode `{}`", self.rhs.flow.mode_name())
    }

    /// `flow of mode `m``, its sensitivity equation, the running cost or its gradient.
    fn stage_source(&self, k: &Self::Vector) -> String {
        let mode = self.rhs.flow.mode_name();
        if !k.x.iter().all(|v| v.is_finite()) {
            format!("flow of mode `{mode}`")
        } else if !k.q.is_finite() {
            "running cost".into()
        } else if !k.s.iter().all(|v| v.is_finite()) {
            format!("sensitivity equation of the flow of mode `{mode}`")
        } else {
            "running-cost gradient".into()
        }
    }
}

impl<M: HybridModel> ImplicitSystem for Forward<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    type Linear = Linearisation<M::N, AugState<M::N, M::P>>;

    /// f_x (and its spectral radius), ℓ_x and F_t at the step start (t0, y0), all exact.
    fn prepare(&mut self, t0: f64, y0: &Self::Vector, _h: f64) {
        let Forward { rhs, imp: w, .. } = self;
        let (model, p, mode) = (rhs.flow.model, rhs.flow.p, rhs.flow.mode);
        let pt = rhs.flow.point(t0, &y0.x);
        let lin = &mut w.lin;
        rhs.jac_x(pt, &mut lin.w.jac);
        lin.w.power_iteration();
        model.rhs_dt(pt, &mut lin.dt.x);
        zero_rows(&mut lin.dt.x, &rhs.held);
        if rhs.sens && model.rhs_depends_on_t(mode) {
            model.rhs_sens_dt(pt, &y0.s, &mut lin.dt.s);
            zero_rows(&mut lin.dt.s, &rhs.held);
        } else {
            lin.dt.s.fill(0.0);
        }
        if rhs.flow.has_rc {
            model.running_cost_grad_x(&rhs.flow.sw, At::new(t0, &y0.x, p), &mut w.lx0);
            lin.dt.q = if y0.s.ncols() == p.len() {
                model.running_cost_sens_dt(
                    &rhs.flow.sw,
                    At::new(t0, &y0.x, p),
                    &y0.s,
                    &mut lin.dt.qp,
                )
            } else {
                // A narrow primal run: ∂ₜℓ alone, from the full-width zero S.
                model.running_cost_sens_dt(&rhs.flow.sw, At::new(t0, &y0.x, p), &w.s0, &mut w.qp0)
            };
        } else {
            w.lx0.fill(0.0);
            lin.dt.q = 0.0;
            lin.dt.qp.fill(0.0);
        }
        lin.prepared = true;
    }

    fn linearisation(&mut self) -> &mut Self::Linear {
        &mut self.imp.lin
    }

    /// K = hγ (I − hγ J)⁻¹ R by block forward substitution (see the module doc).
    fn solve_stage(&mut self, t0: f64, y0: &Self::Vector, hg: f64, k: &mut Self::Vector) -> bool {
        let Forward { rhs, imp: w, .. } = self;
        if w.lin.w.factorised_for().is_none() {
            return false;
        }
        let ok_x = w.lin.w.solve_scaled(hg, &mut k.x);
        let lxk = w.lx0.dot(&k.x);
        k.q = hg * (k.q + lxk);
        if !rhs.sens {
            return ok_x;
        }
        // K_S = W⁻¹ hγ (R_S + B K_x), B K_x at (t0, x0, S0); D K_x likewise.
        let pt = rhs.flow.point(t0, &y0.x);
        rhs.flow.model.rhs_sens_dir_x(pt, &y0.s, &k.x, &mut w.bk.s);
        zero_rows(&mut w.bk.s, &rhs.held);
        k.s += &w.bk.s;
        if rhs.flow.has_rc {
            rhs.flow.model.running_cost_sens_dir_x(
                &rhs.flow.sw,
                At::new(t0, &y0.x, rhs.flow.p),
                &y0.s,
                &k.x,
                &mut w.bk.qp,
            );
            k.qp += &w.bk.qp;
        }
        k.s *= hg;
        let ok_s = w.lin.w.solve_mut(&mut k.s);
        if rhs.flow.has_rc {
            k.qp.gemv_tr(hg, &k.s, &w.lx0, hg);
        } else {
            k.qp.fill(0.0);
        }
        ok_x && ok_s
    }

    /// `GlobalError::carry` with f_x and ℓ_x at (t₀, x₀). The step's own
    /// Rosenbrock Jacobian is gone by the time a step is carried (the step is carried once it
    /// is known where it ends: at the next step, at a truncation, or at the end of the run), so
    /// f_x and ℓ_x are evaluated here.
    fn carry_global_error(&mut self, step: AcceptedStep<'_, Self::Vector>) {
        let AcceptedStep { t0, h, y0, f0, le } = step;
        let Forward {
            rhs,
            imp,
            global,
            sens_err,
            ..
        } = self;
        let Some(ge) = global else {
            return;
        };
        let (model, p) = (rhs.flow.model, rhs.flow.p);
        let pt = rhs.flow.point(t0, &y0.x);
        rhs.jac_x(pt, &mut imp.lin.w.jac);
        if rhs.flow.has_rc {
            model.running_cost_grad_x(&rhs.flow.sw, At::new(t0, &y0.x, p), &mut imp.lx0);
        }
        // f_x and ℓ_x now hold the carried step's start, not the next step's.
        imp.lin.prepared = false;
        let tols = (self.tol.atol, self.tol.rtol);
        let autonomous = !model.rhs_depends_on_t(rhs.flow.mode);
        let pattern = &model.info().jacobian_sparsity[rhs.flow.mode];
        ge.carry(
            le,
            f0,
            y0,
            tols,
            &mut imp.lin.w,
            pattern,
            &imp.lx0,
            h,
            *sens_err,
            autonomous,
        );
    }

    fn spectral_radius_at(&mut self, t: f64, y: &Self::Vector) -> f64 {
        let rhs = &self.rhs;
        let w = &mut self.imp.lin.w;
        rhs.jac_x(rhs.flow.point(t, &y.x), &mut w.jac);
        w.power_iteration()
    }
}

impl<'a, M: HybridModel> Integrator<Forward<'a, M>>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// A new integrator of the forward augmented flow of `model` at parameters `p`; allocates
    /// every buffer once. Call [`Integrator::restart`] before the first [`Integrator::step`].
    pub fn new(model: &'a M, p: &'a OVector<f64, M::P>, opts: &Options) -> Self {
        Integrator::with_system(Forward::new(model, p, opts), opts)
    }

    /// [`Integrator::new`] for the event loop: in a primal run of a model with a dynamic
    /// parameter dimension S and q_θ have zero width (the states it restarts from must come
    /// from `system().zeros()`), so a primal run's cost does not grow with p.
    pub(crate) fn new_narrow(model: &'a M, p: &'a OVector<f64, M::P>, opts: &Options) -> Self {
        Integrator::with_system(Forward::sized(model, p, opts, true), opts)
    }

    /// Forget all history (no FSAL reuse, no old Jacobian, no step-size memory) and restart at
    /// (t, y) in `mode` with frozen switch bits `sw`, no row held.
    ///
    /// Must be called at the start and after every event, mode switch or switch flip. Under
    /// `auto` the method in use (explicit or implicit) is kept: stiffness is a property of the
    /// model that usually survives an event, and the switch-back test runs on every step.
    ///
    /// In a constant-rate mode the first step's k₀ = F is the mode's F as first evaluated
    /// under the same switch bits (F does not depend on t or Y there), not a new evaluation.
    pub fn restart(&mut self, t: f64, y: &AugState<M::N, M::P>, mode: usize, sw: &Switches) {
        self.restart_holding(t, y, mode, sw, &[]);
    }

    /// [`Integrator::restart`] with the rows `held` (ascending state indices) of the flow and
    /// of its sensitivity rate held at zero until the next restart (the masked flow after an
    /// accumulation, see the module doc of `forward.rs`).
    pub fn restart_holding(
        &mut self,
        t: f64,
        y: &AugState<M::N, M::P>,
        mode: usize,
        sw: &Switches,
        held: &[usize],
    ) {
        // Still in the same constant-rate mode under the same bits and held rows (a time
        // event that changed none of them): k₀ = F stays where the last exact step left it.
        let rhs = &self.sys.rhs;
        let same_held = held.is_empty() && rhs.held.is_empty() || held == rhs.held.as_slice();
        if self.scheme == Scheme::Exact
            && self.dense_scheme == Scheme::Exact
            && mode == rhs.flow.mode
            && *sw == rhs.flow.sw
            && same_held
        {
            self.restart_exact_keeping_rate(t, y);
            return;
        }
        let rhs = &mut self.sys.rhs;
        rhs.flow.mode = mode;
        rhs.flow.sw.clone_from(sw);
        if !same_held {
            rhs.held.clear();
            rhs.held.extend_from_slice(held);
        }
        self.restart_at(t, y);
        if self.scheme == Scheme::Exact && held.is_empty() {
            self.reuse_constant_rate();
        }
    }

    /// k₀ = the mode's constant F, evaluated here on the first restart into the mode under
    /// these bits (with no row held: a masked F is evaluated by the first step, not cached).
    /// A non-finite F is not kept: the first step evaluates it again and reports it.
    fn reuse_constant_rate(&mut self) {
        let sys = &mut self.sys;
        let Some(Some(c)) = sys.rates.get_mut(sys.rhs.flow.mode) else {
            return;
        };
        if !c.valid || c.sw != sys.rhs.flow.sw {
            sys.rhs.eval(self.t, &self.y, &mut c.f);
            if c.f.nonfinite_part(sys.rhs.sens).is_some() {
                c.valid = false;
                return;
            }
            c.sw.clone_from(&sys.rhs.flow.sw);
            c.valid = true;
        }
        self.k[0].copy_from(&c.f);
        self.k0_valid = true;
    }

    /// Current mode.
    pub fn mode(&self) -> usize {
        self.sys.rhs.flow.mode
    }
    /// Current frozen switch bits.
    pub fn switches(&self) -> &Switches {
        &self.sys.rhs.flow.sw
    }
    /// The rows of the flow held at zero since the last restart (empty but after an
    /// accumulation).
    pub fn held(&self) -> &[usize] {
        &self.sys.rhs.held
    }
    /// The run's global error estimate (`None` when `Options::global_error` is off); the
    /// last accepted step may still be pending ([`Integrator::close_step`]).
    pub fn global_error(&self) -> Option<&GlobalError<M::N, M::P>> {
        self.sys.global.as_ref()
    }

    /// The run's global error estimate (`None` when `Options::global_error` is off).
    pub fn global_error_mut(&mut self) -> Option<&mut GlobalError<M::N, M::P>> {
        self.sys.global.as_mut()
    }
}
