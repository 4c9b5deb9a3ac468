//! The backward (adjoint) system of one segment, the second file in `integrate/` that calls
//! the model.
//!
//! On a segment [a, b] with frozen mode m and switch bits, and the primal trajectory x(t)
//! replayed from the forward record ([`Tape`]; the integrator runs in the segment's local
//! time s = t − a, see there), Y = (λ, g) with λ ∈ Rⁿ, g ∈ Rᵖ and
//!
//! ```text
//!   F(t, Y) = ( −f_xᵀ λ − w ℓ_xᵀ,   −(f_θᵀ λ + w ℓ_θᵀ) )      at (t, x(t), θ)
//! ```
//!
//! (w the cotangent of the cost), integrated from b down to a with negative steps. Then
//! d/dt(λᵀS) = λ̇ᵀS + λᵀ(f_x S + f_θ) = −w ℓ_x S + λᵀ f_θ, so
//! λ(b)ᵀS(b) + w ∫_a^b (ℓ_x S + ℓ_θ) dt = λ(a)ᵀS(a) + [g(a) − g(b)]:
//! the segment's share of dC/dθ moves into g without ever forming S. λᵀf_x and λᵀf_θ come
//! from [`crate::model::ModelAdjoint::rhs_vjp`] (sparse when the model overrides it), ℓ_x and
//! ℓ_θ from `running_cost_value_grad`, so a stage costs O(n + p) beyond the model's own work.
//!
//! ## For Rodas5P
//! J = ∂F/∂Y = [[−f_xᵀ, 0], [−f_θᵀ, 0]] is block lower triangular with a zero block for g, so
//! with W = I + hγ f_xᵀ (the `WMatrix` of J_λλ = −f_xᵀ, factorised once per attempt) a stage is
//! solved exactly: K_λ = W⁻¹ hγ R_λ, K_g = hγ (R_g − f_θᵀ K_λ), the last a vector–Jacobian
//! product at the step start. F depends on t through x(t) even for an autonomous flow, so F_t
//! is the total derivative along the trajectory, the direction (1, f₀) of (t, x) at fixed λ:
//! F_t = (−d(λᵀf_x) − w dℓ_x, −d(λᵀf_θ) − w dℓ_θ) from the model's products
//! [`crate::model::ModelAdjoint::rhs_vjp_dir`] and
//! [`crate::model::ModelAdjoint::running_cost_grad_dir`] (nothing here takes a difference
//! quotient; their trait defaults do, on the scale of the direction, so that a stiff
//! transient is differenced on its own time scale). The adjoint of a stiff flow is stiff
//! backwards in time (the eigenvalues of −f_xᵀ, stepped with h < 0, are those of f_x
//! stepped forwards), so `auto` switches to Rodas5P on it as on the forward run.

use super::aug::{axpy_slice, hermite_slice, mix5_slice, WeightedRms};
use super::global_error::AdjointError;
use super::rosenbrock::WMatrix;
use super::system::{ImplicitSystem, OdeSystem, StageVector};
use super::Integrator;
use crate::adjoint::record::{SegmentRec, Tape};
use crate::model::{HybridModel, ModelAlloc, Point, Switches};
use crate::solution::{Method, Options};
use nalgebra::{Const, DefaultAllocator, Dim, OVector};

/// The adjoint state (λ, g) of the backward sweep: λ = ∂C/∂x(t) and g, dC/dθ accumulated
/// from T down to t.
#[derive(Clone, Debug, PartialEq)]
pub struct AdjState<N: Dim, P: Dim>
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    /// λ (n).
    pub lam: OVector<f64, N>,
    /// g (p).
    pub g: OVector<f64, P>,
}

impl<N: Dim, P: Dim> AdjState<N, P>
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    /// λ = 0 and g = 0.
    pub fn zeros(n: N, p: P) -> Self {
        AdjState {
            lam: OVector::zeros_generic(n, Const::<1>),
            g: OVector::zeros_generic(p, Const::<1>),
        }
    }

    /// self += h Σ_j c_j k_j over λ, and g too when `all` (zero coefficients skipped).
    #[inline(always)]
    fn accumulate(&mut self, h: f64, coefs: &[f64], ks: &[Self], all: bool) {
        for (c, k) in coefs.iter().zip(ks) {
            if *c == 0.0 {
                continue;
            }
            axpy_slice(self.lam.as_mut_slice(), h * c, k.lam.as_slice());
            if all {
                axpy_slice(self.g.as_mut_slice(), h * c, k.g.as_slice());
            }
        }
    }
}

impl<N: Dim, P: Dim> StageVector for AdjState<N, P>
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    type Primary = OVector<f64, N>;

    #[inline]
    fn copy_from(&mut self, other: &Self) {
        self.lam.copy_from(&other.lam);
        self.g.copy_from(&other.g);
    }

    #[inline]
    fn combine(&mut self, base: &Self, h: f64, coefs: &[f64], ks: &[Self], all: bool) {
        self.lam.copy_from(&base.lam);
        if all {
            self.g.copy_from(&base.g);
        }
        self.accumulate(h, coefs, ks, all);
    }

    #[inline]
    fn lincomb(&mut self, h: f64, coefs: &[f64], ks: &[Self], all: bool) {
        self.lam.fill(0.0);
        if all {
            self.g.fill(0.0);
        }
        self.accumulate(h, coefs, ks, all);
    }

    #[inline]
    fn axpy(&mut self, a: f64, other: &Self, all: bool) {
        axpy_slice(self.lam.as_mut_slice(), a, other.lam.as_slice());
        if all {
            axpy_slice(self.g.as_mut_slice(), a, other.g.as_slice());
        }
    }

    #[inline]
    fn mix5(&mut self, w: &[f64; 5], v: [&Self; 5], all: bool) {
        Self::mix5_primary(&mut self.lam, w, v);
        if all {
            mix5_slice(self.g.as_mut_slice(), w, v.map(|u| u.g.as_slice()));
        }
    }

    #[inline]
    fn hermite(&mut self, y0: &Self, y1: &Self, f0: &Self, f1: &Self, h: f64, th: f64, all: bool) {
        Self::hermite_primary(&mut self.lam, y0, y1, f0, f1, h, th);
        if all {
            let [a, b, g0, g1] = [y0, y1, f0, f1].map(|v| v.g.as_slice());
            hermite_slice(self.g.as_mut_slice(), a, b, g0, g1, h, th);
        }
    }

    #[inline]
    fn is_finite(&self) -> bool {
        self.lam.iter().chain(self.g.iter()).all(|v| v.is_finite())
    }

    #[inline]
    fn primary(&self) -> &[f64] {
        self.lam.as_slice()
    }
}

/// `o = −o + a·v` elementwise (one pass).
#[inline]
fn negate_plus(o: &mut [f64], a: f64, v: &[f64]) {
    for (oi, vi) in o.iter_mut().zip(v) {
        *oi = a * vi - *oi;
    }
}

/// The backward system of one segment at parameters θ (see the module doc).
pub struct Backward<'a, M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    rhs: AdjRhs<'a, M>,
    hist: History<'a, M::N>,
    /// g is under error control (with λ).
    sens_err: bool,
    imp: AdjImplicit<M::N, M::P>,
    /// The sweep's global error estimate (`Options::global_error`).
    global: Option<AdjointError<M::N, M::P>>,
    /// The buffers of its primal coupling (with it).
    coupling: Option<Coupling<M::N, M::P>>,
}

/// Buffers of the primal run's share of the sweep's error (see [`Backward`]'s
/// `carry_global_error`): e_x (then its scaled direction), f, and the products.
struct Coupling<N: Dim, P: Dim>
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    ex: OVector<f64, N>,
    f: OVector<f64, N>,
    d: AdjState<N, P>,
}

/// The length, relative to max(1, ‖x‖∞), of the state direction the primal coupling's
/// directional products take with unit speed in t (see `carry_global_error`).
const DIRECTION_SCALE: f64 = 1e8;

/// Everything F needs besides x(t).
struct AdjRhs<'a, M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    model: &'a M,
    p: &'a OVector<f64, M::P>,
    mode: usize,
    sw: Switches,
    /// Absolute time of the segment's start: the integrator runs in local time s = t − t_start.
    t_start: f64,
    /// The cotangent w of the cost.
    cw: f64,
    has_rc: bool,
    lx: OVector<f64, M::N>,
    lp: OVector<f64, M::P>,
    evals: usize,
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
    /// J_λλ = −f_xᵀ and the factors of W = I − hγ J_λλ.
    w: WMatrix<N>,
    /// x and f at the step start.
    x0: OVector<f64, N>,
    f0: OVector<f64, N>,
    /// F_t at the step start.
    dt: AdjState<N, P>,
    /// λᵀf_x scratch of the stage solve, and f_θᵀK_λ.
    vx: OVector<f64, N>,
    vp: OVector<f64, P>,
    prepared: bool,
}

impl<M: HybridModel> AdjRhs<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// out = F at local time s and state x: (−f_xᵀλ − w ℓ_xᵀ, −f_θᵀλ − w ℓ_θᵀ), the model
    /// evaluated at t = t_start + s.
    #[inline]
    fn eval_at(
        &mut self,
        s: f64,
        x: &OVector<f64, M::N>,
        y: &AdjState<M::N, M::P>,
        out: &mut AdjState<M::N, M::P>,
    ) {
        self.evals += 1;
        let t = self.t_start + s;
        let pt = Point::new(self.mode, &self.sw, t, x, self.p);
        self.model.rhs_vjp(pt, &y.lam, &mut out.lam, &mut out.g);
        if self.has_rc && self.cw != 0.0 {
            let (lx, lp) = (&mut self.lx, &mut self.lp);
            self.model
                .running_cost_value_grad(&self.sw, t, x, self.p, lx, lp);
            negate_plus(out.lam.as_mut_slice(), -self.cw, lx.as_slice());
            negate_plus(out.g.as_mut_slice(), -self.cw, lp.as_slice());
        } else {
            out.lam.neg_mut();
            out.g.neg_mut();
        }
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
    /// `cw`; allocates its buffers once (the Rodas5P ones only when `opts.method` may use it).
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
        Backward {
            rhs: AdjRhs {
                model,
                p,
                mode: model.info().initial_mode,
                sw: Switches::new(model.info().switches),
                t_start: 0.0,
                cw,
                has_rc: model.info().has_running_cost,
                lx: vn(),
                lp: OVector::zeros_generic(np, Const::<1>),
                evals: 0,
            },
            hist: History {
                tape,
                seg: None,
                cursor: 0,
                x: vn(),
            },
            sens_err: opts.sens_error_control,
            imp: AdjImplicit {
                w: WMatrix::new(n, used),
                x0: vn(),
                f0: vn(),
                dt: AdjState::zeros(n, np),
                vx: vn(),
                vp: OVector::zeros_generic(np, Const::<1>),
                prepared: false,
            },
            global: opts.global_error.then(|| AdjointError::new(n, np)),
            coupling: opts.global_error.then(|| Coupling {
                ex: vn(),
                f: vn(),
                d: AdjState::zeros(n, np),
            }),
        }
    }

    fn mode_name(&self) -> String {
        match self.rhs.model.info().modes.get(self.rhs.mode) {
            Some(name) => name.clone(),
            None => self.rhs.mode.to_string(),
        }
    }
}

impl<M: HybridModel> OdeSystem for Backward<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    type Vector = AdjState<M::N, M::P>;

    fn zeros(&self) -> Self::Vector {
        AdjState::zeros(self.rhs.model.nstates(), self.rhs.model.nparams())
    }

    #[inline]
    fn all_parts(&self) -> bool {
        true
    }

    /// F depends on λ alone: g is a quadrature, never read back.
    #[inline]
    fn reads_secondary(&self) -> bool {
        false
    }

    #[inline]
    fn controls_all(&self) -> bool {
        self.sens_err
    }

    /// out = F(t, y) with x(t) from the record.
    #[inline]
    fn eval(&mut self, t: f64, y: &Self::Vector, out: &mut Self::Vector) {
        self.hist.at(t);
        self.rhs.eval_at(t, &self.hist.x, y, out);
    }

    /// A mode whose flow is a function of θ alone and no running cost: f_x = 0, so λ is
    /// constant and ġ = −f_θᵀλ too (the segment is one exact step backwards).
    #[inline]
    fn constant_rate(&self) -> bool {
        !self.rhs.has_rc && self.rhs.model.flow_is_constant(self.rhs.mode)
    }

    #[inline]
    fn evals(&self) -> usize {
        self.rhs.evals
    }

    /// [`WeightedRms`] over λ and, under sensitivity error control, g, both with weight 1.
    /// Forward mode weights S_j by |θ_j|; g is not weighted: it is a quadrature, so its
    /// errors only add up, and the weight would turn atol into an absolute tolerance of
    /// atol/|θ_j| on ∂C/∂θ_j. With |θ_j| = 1e-8 (the stiff relay's τ) that let a step skip the
    /// fast transient of λᵀf_τ (λ has none: f_x is constant there) and left 1 % in dC/dτ.
    #[inline]
    fn error_norm(
        &self,
        e: &Self::Vector,
        y0: &Self::Vector,
        y1: &Self::Vector,
        atol: f64,
        rtol: f64,
    ) -> f64 {
        let mut rms = WeightedRms::new(atol, rtol);
        rms.add(e.lam.as_slice(), y0.lam.as_slice(), y1.lam.as_slice(), 1.0);
        if self.sens_err {
            rms.add(e.g.as_slice(), y0.g.as_slice(), y1.g.as_slice(), 1.0);
        }
        rms.norm()
    }

    fn nonfinite_part(&self, y: &Self::Vector) -> Option<&'static str> {
        if !y.lam.iter().all(|v| v.is_finite()) {
            Some("adjoint state λ")
        } else if !y.g.iter().all(|v| v.is_finite()) {
            Some("adjoint gradient quadrature")
        } else {
            None
        }
    }

    /// `adjoint of the flow of mode `m``.
    fn flow_name(&self) -> String {
        format!("adjoint of the flow of mode `{}`", self.mode_name())
    }

    fn stage_source(&self, k: &Self::Vector) -> String {
        if !k.lam.iter().all(|v| v.is_finite()) {
            self.flow_name()
        } else {
            format!(
                "adjoint gradient quadrature of the flow of mode `{}`",
                self.mode_name()
            )
        }
    }
}

impl<M: HybridModel> ImplicitSystem for Backward<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// J_λλ = −f_xᵀ (and its spectral radius) and F_t at the step start.
    fn prepare(&mut self, t0: f64, y0: &Self::Vector, _h: f64) {
        let Backward { rhs, hist, imp, .. } = self;
        hist.at(t0);
        imp.x0.copy_from(&hist.x);
        let pt = Point::new(rhs.mode, &rhs.sw, rhs.t_start + t0, &imp.x0, rhs.p);
        rhs.model.rhs_jac_x(pt, &mut imp.w.jac);
        imp.w.jac.transpose_mut();
        imp.w.jac.neg_mut();
        imp.w.power_iteration();
        // F_t along the trajectory (direction (1, f₀)) at fixed λ: the model's products.
        rhs.model.rhs(pt, &mut imp.f0);
        rhs.model
            .rhs_vjp_dir(pt, &y0.lam, &imp.f0, &mut imp.dt.lam, &mut imp.dt.g);
        if rhs.has_rc && rhs.cw != 0.0 {
            let (sw, t, p) = (&rhs.sw, rhs.t_start + t0, rhs.p);
            let (lx, lp) = (&mut rhs.lx, &mut rhs.lp);
            rhs.model
                .running_cost_grad_dir(sw, t, &imp.x0, p, &imp.f0, lx, lp);
            negate_plus(imp.dt.lam.as_mut_slice(), -rhs.cw, rhs.lx.as_slice());
            negate_plus(imp.dt.g.as_mut_slice(), -rhs.cw, rhs.lp.as_slice());
        } else {
            imp.dt.lam.neg_mut();
            imp.dt.g.neg_mut();
        }
        imp.prepared = true;
    }

    fn prepared(&self) -> bool {
        self.imp.prepared
    }

    fn time_derivative(&self) -> &Self::Vector {
        &self.imp.dt
    }

    fn factorise(&mut self, hg: f64) -> bool {
        self.imp.w.factorise(hg)
    }

    fn factorised_for(&self) -> Option<f64> {
        self.imp.w.factorised_for()
    }

    /// K_λ = W⁻¹ hγ R_λ, K_g = hγ (R_g − f_θᵀ K_λ) (see the module doc).
    fn solve_stage(
        &mut self,
        t0: f64,
        _y0: &Self::Vector,
        hg: f64,
        r: &Self::Vector,
        k: &mut Self::Vector,
    ) -> bool {
        let Backward { rhs, imp, .. } = self;
        if imp.w.factorised_for().is_none() {
            return false;
        }
        k.lam.copy_from(&r.lam);
        k.lam *= hg;
        let ok = imp.w.solve_mut(&mut k.lam);
        let pt = Point::new(rhs.mode, &rhs.sw, rhs.t_start + t0, &imp.x0, rhs.p);
        rhs.model.rhs_vjp(pt, &k.lam, &mut imp.vx, &mut imp.vp);
        k.g.copy_from(&r.g);
        k.g -= &imp.vp;
        k.g *= hg;
        ok
    }

    /// [`AdjointError::carry`] with J = −f_xᵀ and the products f_xᵀv, f_θᵀv at the step
    /// start (t₀, x(t₀)), evaluated here: the step's own Rosenbrock Jacobian is gone by the
    /// time it is carried (see [`super::Forward`]'s).
    ///
    /// The primal run's state error e_x = r_x + α f at the step (from the tape) is a forcing:
    /// F is evaluated along x + e_x, so the step adds h δF with
    /// δF = −(∂ₓ(f_xᵀλ)·e_x + w ∂ₓℓ_xᵀ·e_x, ∂ₓ(f_θᵀλ)·e_x + w ∂ₓℓ_θᵀ·e_x) at the step start:
    /// the model's directional products along (1, s ê), ê = e_x/‖e_x‖∞, with s large, so
    /// that divided by s they are the derivatives along ê up to ∂ₜ/s, times ‖e_x‖∞.
    fn carry_global_error(
        &mut self,
        t0: f64,
        y0: &Self::Vector,
        _f0: &Self::Vector,
        h: f64,
        le: &Self::Vector,
    ) {
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
        let model = rhs.model;
        let pt = Point::new(rhs.mode, &rhs.sw, rhs.t_start + t0, &hist.x, rhs.p);
        let forcing = match hist.tape.state_error(hist.cursor) {
            Some((rx, alpha)) => {
                model.rhs(pt, &mut c.f);
                c.ex.as_mut_slice().copy_from_slice(rx);
                c.ex.axpy(alpha, &c.f, 1.0);
                let size = c.ex.amax();
                if size > 0.0 && size.is_finite() {
                    // Along (1, s ê) with s = DIRECTION_SCALE·max(1, ‖x‖∞): the product is
                    // s ∂ₓ·ê + ∂ₜ, so divided by s it is ∂ₓ·ê up to ∂ₜ/s (one product, not
                    // two; a difference default then steps 1e-4·max(1, ‖x‖) in x and ~1e-12
                    // in t).
                    let s = DIRECTION_SCALE * hist.x.amax().max(1.0);
                    c.ex *= s / size;
                    c.d.lam.fill(0.0);
                    c.d.g.fill(0.0);
                    if !model.flow_is_constant(rhs.mode) {
                        model.rhs_vjp_dir(pt, &y0.lam, &c.ex, &mut c.d.lam, &mut c.d.g);
                    }
                    if rhs.has_rc && rhs.cw != 0.0 {
                        let (sw, t, x, p) = (&rhs.sw, pt.t, &hist.x, rhs.p);
                        let (lx, lp) = (&mut rhs.lx, &mut rhs.lp);
                        model.running_cost_grad_dir(sw, t, x, p, &c.ex, lx, lp);
                        c.d.lam.axpy(rhs.cw, lx, 1.0);
                        c.d.g.axpy(rhs.cw, lp, 1.0);
                    }
                    c.d.lam *= -size / s;
                    c.d.g *= -size / s;
                    Some(&c.d)
                } else {
                    None
                }
            }
            None => None,
        };
        model.rhs_jac_x(pt, &mut imp.w.jac);
        imp.w.jac.transpose_mut();
        imp.w.jac.neg_mut();
        // J now holds the carried step's start, not the next step's.
        imp.prepared = false;
        let pattern = &model.info().jacobian_sparsity[rhs.mode];
        ge.carry(le, forcing, &mut imp.w, pattern, h, |v, vx, vp| {
            model.rhs_vjp(pt, v, vx, vp)
        });
    }

    fn invalidate(&mut self) {
        self.imp.prepared = false;
        self.imp.w.invalidate();
    }

    fn spectral_radius_at(&mut self, t: f64, _y: &Self::Vector) -> f64 {
        let Backward { rhs, hist, imp, .. } = self;
        hist.at(t);
        let pt = Point::new(rhs.mode, &rhs.sw, rhs.t_start + t, &hist.x, rhs.p);
        rhs.model.rhs_jac_x(pt, &mut imp.w.jac);
        imp.w.power_iteration()
    }

    fn jac_spectral_radius(&self) -> f64 {
        self.imp.w.rho
    }
}

impl<'a, M: HybridModel> Integrator<Backward<'a, M>>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// An integrator of the backward system over `tape` (see [`Backward::new`]); allocates
    /// every buffer once. Call [`Integrator::restart_segment`] before each segment.
    pub fn backward(
        model: &'a M,
        p: &'a OVector<f64, M::P>,
        tape: &'a Tape,
        opts: &Options,
        cw: f64,
    ) -> Self {
        Integrator::with_system(Backward::new(model, p, tape, opts, cw), opts)
    }

    /// Forget all history and restart at (s, y) on segment `seg` (its mode, switch bits and
    /// recorded steps), in the segment's local time s = t − t_start (see
    /// [`crate::adjoint::record`]); then `step(s_stop)` with s_stop < s integrates backwards.
    pub fn restart_segment(&mut self, seg: &'a SegmentRec, s: f64, y: &AdjState<M::N, M::P>) {
        // A pending step is carried on its own segment.
        self.carry_global_error();
        let sys = &mut self.sys;
        sys.hist.seg = Some(seg);
        sys.hist.cursor = seg.steps.end.saturating_sub(1);
        sys.rhs.mode = seg.mode;
        sys.rhs.sw.clone_from(&seg.sw);
        sys.rhs.t_start = seg.t_start;
        self.restart_at(s, y);
    }

    /// The sweep's global error estimate (`None` when `Options::global_error` is off). Carry
    /// the last step ([`Integrator::carry_global_error`]) before a jump or a new segment.
    pub fn global_error_mut(&mut self) -> Option<&mut AdjointError<M::N, M::P>> {
        self.sys.global.as_mut()
    }
}
