//! One-step integrators for the augmented flow of a single mode.
//!
//! In a fixed mode m with frozen switch bits, the runtime integrates the augmented system
//!
//! ```text
//!   ẋ   = f(t, x, θ)                  (n)
//!   Ṡ   = f_x S + f_θ                 (n × p, S = ∂x/∂θ)
//!   q̇   = ℓ(t, x, θ)                  (running cost)
//!   q̇_θ = ℓ_x S + ℓ_θ                 (p, its parameter gradient)
//! ```
//!
//! as one state [`AugState`] `(x, S, q, q_θ)`. With `Options::sensitivities == false` only x
//! and q are advanced (S and q_θ stay untouched). f and Ṡ come from
//! [`HybridModel::rhs_sens`], ℓ, ℓ_x, ℓ_θ from [`HybridModel::running_cost_grad`] (only when the
//! model has a running cost; otherwise q ≡ 0).
//!
//! ## Methods
//! - [`Method::Tsit5`]: Tsitouras' 5(4) pair, FSAL, with its 4th-order continuous extension
//!   (`tsit5.rs`).
//! - [`Method::Verner9`]: Verner's "most efficient" 9(8) pair with its 9th-order interpolant
//!   (`verner.rs`).
//! - [`Method::Rosenbrock`]: Rodas5P, a stiffly accurate linearly implicit method of order 5(4)
//!   with a 4th-order dense output that uses the model's symbolic Jacobian (`rosenbrock.rs`).
//! - [`Method::Auto`] (default): Tsit5 with Hairer's stiffness test (h·‖k₇ − k₆‖/‖y₇ − y₆‖
//!   against the real stability boundary of Tsit5) and, every 20 steps, h·ρ(f_x) from a power
//!   iteration on the symbolic Jacobian (this catches steps held near 1/ρ by something other
//!   than stability, e.g. sensitivity error control); after repeated stiff steps it switches to
//!   Rodas5P, and back when h·ρ(f_x) < 0.4 shows the explicit method would be stable again.
//!
//! ## Error control and step size
//! The local error estimate e of the embedded pair is measured in the weighted RMS norm
//! ‖e‖ = sqrt(1/N Σ (e_i / (atol + rtol·max(|y0_i|, |y1_i|)))²) over x and q (the latter only
//! with a running cost); `Options::sens_error_control` (on by default) adds S and q_θ, column j
//! weighted by |θ_j| so that it is controlled as the change θ_j·S_j it predicts (the parameter
//! scaling of CVODES; see [`sens_weight`]). A step is accepted when
//! ‖e‖ ≤ 1, and the next step is h·clamp(0.9 ‖e‖^(−β₁) ‖e_prev‖^(β₂), 0.2, 10) (a PI controller
//! with β₁ = 0.7/k, β₂ = 0.4/k, k = order of the estimate + 1; no growth right after a
//! rejection). The first step after every [`Integrator::restart`] comes from Hairer's heuristic
//! (Hairer, Nørsett, Wanner I, II.4).
//!
//! ## Restarts
//! [`Integrator::restart`] forgets everything derived from the previous state: the FSAL stage,
//! the Jacobian, the step-size history. The driver calls it at the start and after every event,
//! mode switch or switch flip, so the first stage after a jump is always f at the new state.

mod rosenbrock;
mod tsit5;
mod verner;

use crate::model::{HybridModel, ModelAlloc, Switches};
use crate::solution::{Method, Options, Stats};
use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector};
use std::fmt;

use rosenbrock::RosenbrockWork;

/// The augmented state `(x, S, q, q_θ)` integrated over a smooth segment (see the module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct AugState<N: Dim, P: Dim>
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    /// The state x.
    pub x: OVector<f64, N>,
    /// The sensitivity S = ∂x/∂θ (n × p).
    pub s: OMatrix<f64, N, P>,
    /// The running-cost quadrature q = ∫ ℓ dt.
    pub q: f64,
    /// Its parameter gradient q_θ = ∫ (ℓ_x S + ℓ_θ) dt.
    pub qp: OVector<f64, P>,
}

impl<N: Dim, P: Dim> AugState<N, P>
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    /// All parts zero (x ∈ Rⁿ, S ∈ Rⁿˣᵖ, q, q_θ ∈ Rᵖ).
    pub fn zeros(n: N, p: P) -> Self {
        AugState {
            x: OVector::zeros_generic(n, Const::<1>),
            s: OMatrix::zeros_generic(n, p),
            q: 0.0,
            qp: OVector::zeros_generic(p, Const::<1>),
        }
    }

    /// Copies every part of `other` into `self` (no allocation).
    pub fn copy_from(&mut self, other: &Self) {
        self.x.copy_from(&other.x);
        self.s.copy_from(&other.s);
        self.q = other.q;
        self.qp.copy_from(&other.qp);
    }

    /// `self += a · other`, every part.
    pub fn axpy(&mut self, a: f64, other: &Self) {
        axpy_slice(self.x.as_mut_slice(), a, other.x.as_slice());
        axpy_slice(self.s.as_mut_slice(), a, other.s.as_slice());
        self.q += a * other.q;
        axpy_slice(self.qp.as_mut_slice(), a, other.qp.as_slice());
    }

    /// Sets every part to zero.
    pub fn fill_zero(&mut self) {
        self.x.fill(0.0);
        self.s.fill(0.0);
        self.q = 0.0;
        self.qp.fill(0.0);
    }

    /// Whether every entry of every part is finite.
    pub fn is_finite(&self) -> bool {
        self.x.iter().all(|v| v.is_finite())
            && self.s.iter().all(|v| v.is_finite())
            && self.q.is_finite()
            && self.qp.iter().all(|v| v.is_finite())
    }

    /// Names the first part holding a NaN or infinity, for diagnostics.
    fn nonfinite_part(&self, sens: bool) -> Option<&'static str> {
        if !self.x.iter().all(|v| v.is_finite()) {
            Some("state x")
        } else if !self.q.is_finite() {
            Some("running cost")
        } else if sens && !self.s.iter().all(|v| v.is_finite()) {
            Some("sensitivity S")
        } else if sens && !self.qp.iter().all(|v| v.is_finite()) {
            Some("running-cost gradient")
        } else {
            None
        }
    }
}

/// `y += a x` on raw slices.
#[inline]
fn axpy_slice(y: &mut [f64], a: f64, x: &[f64]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += a * xi;
    }
}

/// `dst = base + h Σ_j c_j k_j` (terms with c_j = 0 skipped); S and q_θ only when `sens`.
fn combine<N: Dim, P: Dim>(
    dst: &mut AugState<N, P>,
    base: &AugState<N, P>,
    h: f64,
    coefs: &[f64],
    ks: &[AugState<N, P>],
    sens: bool,
) where
    DefaultAllocator: ModelAlloc<N, P>,
{
    dst.x.copy_from(&base.x);
    dst.q = base.q;
    if sens {
        dst.s.copy_from(&base.s);
        dst.qp.copy_from(&base.qp);
    }
    for (c, k) in coefs.iter().zip(ks) {
        if *c == 0.0 {
            continue;
        }
        let a = h * c;
        axpy_slice(dst.x.as_mut_slice(), a, k.x.as_slice());
        dst.q += a * k.q;
        if sens {
            axpy_slice(dst.s.as_mut_slice(), a, k.s.as_slice());
            axpy_slice(dst.qp.as_mut_slice(), a, k.qp.as_slice());
        }
    }
}

/// `dst = h Σ_j c_j k_j`; S and q_θ only when `sens`.
fn lincomb<N: Dim, P: Dim>(
    dst: &mut AugState<N, P>,
    h: f64,
    coefs: &[f64],
    ks: &[AugState<N, P>],
    sens: bool,
) where
    DefaultAllocator: ModelAlloc<N, P>,
{
    dst.x.fill(0.0);
    dst.q = 0.0;
    if sens {
        dst.s.fill(0.0);
        dst.qp.fill(0.0);
    }
    for (c, k) in coefs.iter().zip(ks) {
        if *c == 0.0 {
            continue;
        }
        let a = h * c;
        axpy_slice(dst.x.as_mut_slice(), a, k.x.as_slice());
        dst.q += a * k.q;
        if sens {
            axpy_slice(dst.s.as_mut_slice(), a, k.s.as_slice());
            axpy_slice(dst.qp.as_mut_slice(), a, k.qp.as_slice());
        }
    }
}

/// `dst = base + h Σ_j c_j k_j` for the x part only.
fn combine_x<N: Dim, P: Dim>(
    dst: &mut OVector<f64, N>,
    base: &OVector<f64, N>,
    h: f64,
    coefs: &[f64],
    ks: &[AugState<N, P>],
) where
    DefaultAllocator: ModelAlloc<N, P>,
{
    dst.copy_from(base);
    for (c, k) in coefs.iter().zip(ks) {
        if *c != 0.0 {
            axpy_slice(dst.as_mut_slice(), h * c, k.x.as_slice());
        }
    }
}

/// Why a step could not be taken.
#[derive(Clone, Debug, PartialEq)]
pub enum StepError {
    /// The step size fell below what the floating-point resolution of t allows.
    StepSizeUnderflow {
        /// Time at which the integrator is stuck.
        t: f64,
        /// The step size it would need.
        h: f64,
    },
    /// A NaN or infinity appeared and shrinking the step did not remove it.
    NonFinite {
        /// Time of the step start (for a flow that is undefined beyond some t*, the last
        /// step creeps up to t* before giving up, so this is t* to rounding).
        t: f64,
        /// The expression it came from: `flow of mode `m``, `sensitivity equation of the
        /// flow of mode `m``, `running cost`, `running-cost gradient`, or `state x` when
        /// every evaluated stage was finite but their combination overflowed.
        what: String,
    },
    /// `Options::max_steps` step attempts (accepted + rejected) were used up.
    MaxSteps {
        /// Time reached.
        t: f64,
        /// The limit that was hit.
        steps: usize,
    },
}

impl fmt::Display for StepError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StepError::StepSizeUnderflow { t, h } => {
                write!(f, "step size underflow at t = {t:e} (h = {h:e})")
            }
            StepError::NonFinite { t, what } => write!(f, "non-finite {what} at t = {t:e}"),
            StepError::MaxSteps { t, steps } => {
                write!(f, "gave up after {steps} steps at t = {t:e} (max_steps)")
            }
        }
    }
}

impl std::error::Error for StepError {}

/// Everything the right-hand side evaluation needs, split from the buffers so stage
/// evaluations can borrow both at once.
struct Rhs<'a, M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    model: &'a M,
    p: &'a OVector<f64, M::P>,
    mode: usize,
    sw: Switches,
    sens: bool,
    has_rc: bool,
    /// ℓ_x scratch.
    lx: OVector<f64, M::N>,
    /// ℓ_θ scratch.
    lp: OVector<f64, M::P>,
    /// Evaluations of the augmented right-hand side.
    evals: usize,
}

impl<M: HybridModel> Rhs<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// out = F(t, y): (f, f_x S + f_θ, ℓ, ℓ_x S + ℓ_θ).
    fn eval(&mut self, t: f64, y: &AugState<M::N, M::P>, out: &mut AugState<M::N, M::P>) {
        self.evals += 1;
        if self.sens {
            self.model.rhs_sens(
                self.mode, self.sw, t, &y.x, self.p, &y.s, &mut out.x, &mut out.s,
            );
        } else {
            self.model
                .rhs(self.mode, self.sw, t, &y.x, self.p, &mut out.x);
        }
        if !self.has_rc {
            out.q = 0.0;
            if self.sens {
                out.qp.fill(0.0);
            }
        } else if self.sens {
            out.q =
                self.model
                    .running_cost_grad(self.sw, t, &y.x, self.p, &mut self.lx, &mut self.lp);
            out.qp.copy_from(&self.lp);
            out.qp.gemv_tr(1.0, &y.s, &self.lx, 1.0);
        } else {
            out.q = self.model.running_cost(self.sw, t, &y.x, self.p);
        }
    }
}

/// Outcome of one attempted step of a method: the error norm (NaN when something overflowed).
type Attempt = f64;

/// Real-axis stability boundary of Tsit5 used by the stiffness test (|hλ| beyond it is
/// unstable; the test fires slightly inside it).
const TSIT5_STIFF_BOUND: f64 = 3.25;
/// Accepted stiff-looking Tsit5 steps (with fewer than 6 non-stiff ones in between) before
/// `auto` switches to Rodas5P.
const STIFF_STEPS_TO_SWITCH: usize = 15;
/// Accepted Tsit5 steps between two Jacobian-based stiffness checks under `auto`.
const JAC_CHECK_EVERY: usize = 20;
/// h·ρ(f_x) above which a Tsit5 step counts as stiff in the Jacobian check (three checks in
/// a row switch to Rodas5P).
const JAC_STIFF_HRHO: f64 = 0.8;
/// h·ρ(f_x) below which a Rodas5P step counts as non-stiff.
const JAC_NONSTIFF_HRHO: f64 = 0.4;
/// Consecutive non-stiff Rodas5P steps before `auto` switches back to Tsit5.
const NONSTIFF_STEPS_TO_SWITCH: usize = 20;

/// An adaptive one-step integrator of the augmented flow in one mode (see the module doc).
///
/// All buffers are allocated in [`Integrator::new`]; stepping allocates nothing, for static
/// and `Dyn` sizes alike (the Rosenbrock method factorises in place in its own buffers).
pub struct Integrator<'a, M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    rhs: Rhs<'a, M>,
    rtol: f64,
    atol: f64,
    sens_err: bool,
    /// Budget of step attempts (accepted + rejected) over the integrator's life.
    max_steps: usize,
    requested: Method,
    active: Method,
    /// Method that produced the last accepted step (the one `dense` uses).
    dense_method: Method,
    t: f64,
    t_prev: f64,
    /// Length of the last accepted step (dense output lives on [t_prev, t_prev + dense_h]).
    dense_h: f64,
    /// Proposed next step size; 0 ⇒ choose it by Hairer's heuristic.
    h: f64,
    y: AugState<M::N, M::P>,
    y_prev: AugState<M::N, M::P>,
    /// The end state of the last accepted step once [`Integrator::truncate`] has overwritten y.
    y_end: AugState<M::N, M::P>,
    /// y was cut by `truncate` (the step's end state is in y_end).
    truncated: bool,
    /// Candidate state of the step being attempted.
    ynew: AugState<M::N, M::P>,
    /// Stage argument scratch.
    tmp: AugState<M::N, M::P>,
    /// Local error estimate.
    yerr: AugState<M::N, M::P>,
    /// Stage derivatives k_i (and for Verner, the interpolation stages).
    k: Vec<AugState<M::N, M::P>>,
    /// k[0] = F(t, y) holds (computed or taken over from the FSAL stage).
    k0_valid: bool,
    /// The last accepted step left F(t, y) in this stage slot (Tsit5: k₇; Verner: the first
    /// interpolation stage), to become the next step's k[0] unless a restart intervenes.
    fsal_slot: Option<usize>,
    /// ‖e‖ of the previous accepted step (PI controller memory).
    err_prev: f64,
    /// err_prev^(β₂), cached.
    err_prev_pow: f64,
    /// Error order the two constants below were computed for (see
    /// `refresh_controller_consts`).
    controller_k: f64,
    /// 1e-4^(β₂).
    floor_pow: f64,
    /// ‖e‖ below which the step-size factor is the growth cap 10.
    full_growth_err: f64,
    /// The last attempt was rejected (no step growth on the next accepted one).
    last_rejected: bool,
    /// Verner: evaluate the nine interpolation stages after the FSAL one only on demand
    /// ([`Integrator::ensure_dense`]); see [`Integrator::set_lazy_dense`].
    lazy_dense: bool,
    /// The last accepted Verner step's interpolation stages 18..26 are not evaluated yet.
    dense_pending: bool,
    /// Hairer's stiffness estimate h·‖k₇ − k₆‖/‖y₇ − y₆‖ of the last Tsit5 attempt.
    stiff_ratio: f64,
    stiff_count: usize,
    nonstiff_count: usize,
    /// Accepted Tsit5 steps since the last Jacobian check, and consecutive stiff checks.
    jac_check_count: usize,
    jac_stiff_count: usize,
    stats: Stats,
    ros: RosenbrockWork<M::N, M::P>,
}

impl<'a, M: HybridModel> Integrator<'a, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// A new integrator for `model` at parameters `p`; allocates every buffer once.
    /// Call [`Integrator::restart`] before the first [`Integrator::step`].
    pub fn new(model: &'a M, p: &'a OVector<f64, M::P>, opts: &Options) -> Self {
        let n = model.nstates();
        let np = model.nparams();
        let nstages = match opts.method {
            Method::Tsit5 => tsit5::STAGES,
            Method::Verner9 => verner::STAGES_WITH_DENSE,
            Method::Rosenbrock => rosenbrock::STAGES,
            Method::Auto => tsit5::STAGES.max(rosenbrock::STAGES),
        };
        let zero = || AugState::zeros(n, np);
        let active = match opts.method {
            Method::Auto => Method::Tsit5,
            m => m,
        };
        let mut it = Integrator {
            rhs: Rhs {
                model,
                p,
                mode: model.info().initial_mode,
                sw: 0,
                sens: opts.sensitivities,
                has_rc: model.info().has_running_cost,
                lx: OVector::zeros_generic(n, Const::<1>),
                lp: OVector::zeros_generic(np, Const::<1>),
                evals: 0,
            },
            rtol: opts.rtol,
            atol: opts.atol,
            sens_err: opts.sens_error_control && opts.sensitivities,
            max_steps: opts.max_steps,
            requested: opts.method,
            active,
            dense_method: active,
            t: 0.0,
            t_prev: 0.0,
            dense_h: 0.0,
            h: 0.0,
            y: zero(),
            y_prev: zero(),
            y_end: zero(),
            truncated: false,
            ynew: zero(),
            tmp: zero(),
            yerr: zero(),
            k: (0..nstages).map(|_| zero()).collect(),
            k0_valid: false,
            fsal_slot: None,
            err_prev: 1e-4,
            err_prev_pow: f64::NAN,
            controller_k: f64::NAN,
            floor_pow: f64::NAN,
            full_growth_err: 0.0,
            last_rejected: false,
            lazy_dense: false,
            dense_pending: false,
            stiff_ratio: 0.0,
            stiff_count: 0,
            nonstiff_count: 0,
            jac_check_count: 0,
            jac_stiff_count: 0,
            stats: Stats::default(),
            ros: RosenbrockWork::new(
                n,
                np,
                matches!(opts.method, Method::Auto | Method::Rosenbrock),
            ),
        };
        it.reset_controller();
        it
    }

    /// Forget all history (no FSAL reuse, no old Jacobian, no step-size memory) and restart at
    /// (t, y) in `mode` with frozen switch bits `sw`.
    ///
    /// Must be called at the start and after every event, mode switch or switch flip. Under
    /// `auto` the method in use (explicit or implicit) is kept: stiffness is a property of the
    /// model that usually survives an event, and the switch-back test runs on every step.
    pub fn restart(&mut self, t: f64, y: &AugState<M::N, M::P>, mode: usize, sw: Switches) {
        self.t = t;
        self.t_prev = t;
        self.dense_h = 0.0;
        self.truncated = false;
        self.h = 0.0;
        self.y.copy_from(y);
        self.y_prev.copy_from(y);
        self.rhs.mode = mode;
        self.rhs.sw = sw;
        self.k0_valid = false;
        self.fsal_slot = None;
        self.reset_controller();
        self.last_rejected = false;
        self.dense_method = self.active;
        self.dense_pending = false;
        self.ros.invalidate();
    }

    /// Verner 9(8) only: with `on`, the nine interpolation stages of an accepted step beyond
    /// the FSAL one (a third of the step's work) are evaluated only when
    /// [`Integrator::ensure_dense`] asks for them (the driver does so when it samples guards
    /// or records the trajectory); until then `dense`/`dense_x` fall back to the cubic
    /// Hermite interpolant of the step's end points and slopes (3rd order, never garbage).
    /// [`Integrator::truncate`] completes the stages itself. Off by default.
    pub fn set_lazy_dense(&mut self, on: bool) {
        self.lazy_dense = on;
    }

    /// Makes the full-order dense output of the last accepted step available (evaluates
    /// Verner's pending interpolation stages; nothing for the other methods).
    pub fn ensure_dense(&mut self) {
        if self.dense_pending {
            let h = self.dense_h;
            self.verner_dense_stages_rest(h);
            self.dense_pending = false;
            self.stats.rhs_evals = self.rhs.evals;
        }
    }

    /// End of the last accepted step.
    pub fn t(&self) -> f64 {
        self.t
    }
    /// Start of the last accepted step.
    pub fn t_prev(&self) -> f64 {
        self.t_prev
    }
    /// State at [`Integrator::t`].
    pub fn y(&self) -> &AugState<M::N, M::P> {
        &self.y
    }
    /// State at [`Integrator::t_prev`].
    pub fn y_prev(&self) -> &AugState<M::N, M::P> {
        &self.y_prev
    }
    /// Work counters (steps, rejected_steps, rhs_evals, jac_evals, factorizations; the event
    /// fields stay zero).
    pub fn stats(&self) -> &Stats {
        &self.stats
    }
    /// The method taking the steps now (what `auto` is using).
    pub fn active_method(&self) -> Method {
        self.active
    }
    /// Current mode.
    pub fn mode(&self) -> usize {
        self.rhs.mode
    }
    /// Current frozen switch bits.
    pub fn switches(&self) -> Switches {
        self.rhs.sw
    }
    /// Length of the last accepted step before any truncation (0 right after a restart).
    pub fn last_step_size(&self) -> f64 {
        self.dense_h
    }
    /// The step size the controller proposes next (0 before the first step after a restart).
    pub fn next_step_size(&self) -> f64 {
        self.h
    }

    /// Seeds the size of the next step attempt, e.g. with the step size in use before an event
    /// (call it after [`Integrator::restart`], which otherwise starts from Hairer's heuristic;
    /// the error control still rejects and shrinks a seed that is too large). A value that is
    /// not finite and positive restores the heuristic.
    pub fn set_step_size(&mut self, h: f64) {
        self.h = if h.is_finite() && h > 0.0 { h } else { 0.0 };
    }

    /// Take ONE accepted step, never beyond `t_stop`; lands exactly on `t_stop` when it is
    /// reached. Integration runs forward only: when `t_stop <= t()` nothing happens.
    pub fn step(&mut self, t_stop: f64) -> Result<(), StepError> {
        if t_stop.is_nan() {
            return Err(StepError::NonFinite {
                t: self.t,
                what: "stop time".into(),
            });
        }
        if t_stop <= self.t {
            return Ok(());
        }
        self.ensure_k0()?;
        if self.h == 0.0 {
            self.h = self.initial_step(t_stop - self.t);
        }
        // Where the last non-finite attempt of this step came from (see `nonfinite_source`).
        let mut nonfinite: Option<String> = None;
        let mut nonfinite_tries = 0usize;
        loop {
            let span = t_stop - self.t;
            let mut h = self.h;
            let landing = h * 1.01 >= span;
            if landing {
                h = span;
            }
            if h.is_nan() || h <= 10.0 * f64::EPSILON * self.t.abs() || h < 1e-300 {
                // Shrinking towards a point where the flow stops being defined (√ of a
                // negative, 1/0, ...) ends here: report the NaN, not the step size.
                return Err(match nonfinite.or_else(|| self.undefined_just_ahead()) {
                    Some(what) => StepError::NonFinite { t: self.t, what },
                    None => StepError::StepSizeUnderflow { t: self.t, h },
                });
            }
            let used = self.stats.steps + self.stats.rejected_steps;
            if used >= self.max_steps {
                return Err(StepError::MaxSteps {
                    t: self.t,
                    steps: self.max_steps,
                });
            }
            let err = self.attempt(h);
            if !err.is_finite() || !self.ynew.is_finite() {
                // NaN or overflow inside the step: retry much shorter, give up after many
                // tries (or at the step-size floor above).
                nonfinite_tries += 1;
                self.stats.rejected_steps += 1;
                self.last_rejected = true;
                let what = self.nonfinite_source();
                if nonfinite_tries > 60 {
                    return Err(StepError::NonFinite { t: self.t, what });
                }
                nonfinite = Some(what);
                self.h = h * 0.25;
                continue;
            }
            let k = self.error_order();
            if err <= 1.0 {
                self.refresh_controller_consts();
                // Below `full_growth_err` the factor is clamped to 10 whatever ‖e_prev‖ is
                // (‖e_prev‖^β₂ ≥ 1e-4^β₂), so the two powers are skipped, same result.
                let mut fac = if err <= self.full_growth_err {
                    10.0
                } else {
                    0.9 * err.powf(-0.7 / k) * self.err_prev_pow
                };
                fac = fac.clamp(0.2, 10.0);
                if self.last_rejected {
                    fac = fac.min(1.0);
                }
                self.err_prev = err.max(1e-4);
                self.err_prev_pow = if err <= 1e-4 {
                    self.floor_pow
                } else {
                    self.err_prev.powf(0.4 / k)
                };
                self.last_rejected = false;
                self.accept(h, landing, t_stop);
                self.h = h * fac;
                self.update_stiffness();
                return Ok(());
            }
            self.stats.rejected_steps += 1;
            self.last_rejected = true;
            self.h = h * (0.9 * err.powf(-1.0 / k)).max(0.2);
        }
    }

    /// Takes one step of exactly `h` with the active method and no error control (always
    /// accepted); returns the weighted norm of its local error estimate. For verifying
    /// convergence orders; the driver uses [`Integrator::step`].
    pub fn step_fixed(&mut self, h: f64) -> Result<f64, StepError> {
        if h.is_nan() || h <= 0.0 || !h.is_finite() {
            return Err(StepError::StepSizeUnderflow { t: self.t, h });
        }
        self.ensure_k0()?;
        let err = self.attempt(h);
        if let Some(what) = self.ynew.nonfinite_part(self.rhs.sens) {
            return Err(StepError::NonFinite {
                t: self.t,
                what: what.into(),
            });
        }
        let t_end = self.t + h;
        self.accept(h, true, t_end);
        Ok(err)
    }

    /// Makes k[0] = F(t, y): from the FSAL stage of the last Tsit5 step, or by evaluating.
    fn ensure_k0(&mut self) -> Result<(), StepError> {
        if self.k0_valid {
            return Ok(());
        }
        if let Some(slot) = self.fsal_slot.take() {
            self.k.swap(0, slot);
        } else {
            self.rhs.eval(self.t, &self.y, &mut self.k[0]);
        }
        if self.k[0].nonfinite_part(self.rhs.sens).is_some() {
            let what = if self.y.nonfinite_part(self.rhs.sens).is_some() {
                format!("{} (the state itself)", self.stage_source(0))
            } else {
                self.stage_source(0)
            };
            return Err(StepError::NonFinite { t: self.t, what });
        }
        self.k0_valid = true;
        Ok(())
    }

    /// Names the expression behind a non-finite attempt: the first evaluated stage with a
    /// NaN/∞ decides (`flow of mode `m``, its sensitivity equation, the running cost or its
    /// gradient); if all stages are finite, the combination overflowed (`state x ...`).
    fn nonfinite_source(&self) -> String {
        let stages = match self.active {
            Method::Tsit5 | Method::Auto => tsit5::STAGES,
            Method::Verner9 => verner::FSAL_SLOT,
            Method::Rosenbrock => rosenbrock::STAGES,
        }
        .min(self.k.len());
        for i in 0..stages {
            if self.k[i].nonfinite_part(self.rhs.sens).is_some() {
                return self.stage_source(i);
            }
        }
        let part = self
            .ynew
            .nonfinite_part(self.rhs.sens)
            .unwrap_or("local error estimate");
        format!(
            "{part} (overflow in the flow of mode `{}`)",
            self.mode_name()
        )
    }

    /// When the step size has shrunk to the resolution of t without a non-finite attempt
    /// (the sensitivities' derivative can blow up before the flow does, as ∂√(c − t)/∂c at
    /// t → c, and hold the step short of c), probes F at t + 2ᵏ·10ε|t|, k = 0..4, with the
    /// state held: the name of the expression that is non-finite there, if any, so the run
    /// reports where the flow stops being defined rather than a bare step-size underflow.
    fn undefined_just_ahead(&mut self) -> Option<String> {
        let dt = 10.0 * f64::EPSILON * self.t.abs().max(f64::MIN_POSITIVE);
        for k in 0..5 {
            let t = self.t + dt * f64::from(1u32 << k);
            self.rhs.eval(t, &self.y, &mut self.k[1]);
            if self.k[1].nonfinite_part(self.rhs.sens).is_some() {
                return Some(self.stage_source(1));
            }
        }
        None
    }

    /// The expression that produced the non-finite part of stage `i` (which must have one).
    fn stage_source(&self, i: usize) -> String {
        let k = &self.k[i];
        let mode = self.mode_name();
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

    /// Name of the current mode (or its index if the model names fewer modes).
    fn mode_name(&self) -> String {
        match self.rhs.model.info().modes.get(self.rhs.mode) {
            Some(name) => name.clone(),
            None => self.rhs.mode.to_string(),
        }
    }

    /// One attempt of the active method with step h from (t, y): fills `ynew`, the stages and
    /// returns the error norm.
    fn attempt(&mut self, h: f64) -> Attempt {
        match self.active {
            Method::Tsit5 | Method::Auto => self.tsit5_attempt(h),
            Method::Verner9 => self.verner_attempt(h),
            Method::Rosenbrock => self.rosenbrock_attempt(h),
        }
    }

    /// Forgets the PI controller's memory (start, restart, method switch).
    fn reset_controller(&mut self) {
        self.refresh_controller_consts();
        self.err_prev = 1e-4;
        self.err_prev_pow = self.floor_pow;
    }

    /// Recomputes the controller constants when the order of the active method changed:
    /// `floor_pow` = 1e-4^(0.4/k) (the smallest ‖e_prev‖^β₂) and `full_growth_err`, half
    /// the ‖e‖ at which 0.9 ‖e‖^(−0.7/k) · floor_pow = 10 (the growth cap).
    fn refresh_controller_consts(&mut self) {
        let k = self.error_order();
        if k != self.controller_k {
            self.controller_k = k;
            self.floor_pow = 1e-4f64.powf(0.4 / k);
            self.full_growth_err = 0.5 * (10.0 / (0.9 * self.floor_pow)).powf(-k / 0.7);
        }
    }

    /// Order of the error estimate + 1 (the exponent base of the controller).
    fn error_order(&self) -> f64 {
        match self.active {
            Method::Tsit5 | Method::Auto => 5.0,
            Method::Verner9 => 9.0,
            Method::Rosenbrock => 5.0,
        }
    }

    /// Commits the attempted step.
    fn accept(&mut self, h: f64, landing: bool, t_stop: f64) {
        std::mem::swap(&mut self.y_prev, &mut self.y);
        std::mem::swap(&mut self.y, &mut self.ynew);
        self.t_prev = self.t;
        self.t = if landing { t_stop } else { self.t + h };
        self.dense_h = h;
        self.truncated = false;
        self.dense_method = self.active;
        self.stats.steps += 1;
        self.k0_valid = false;
        self.fsal_slot = match self.active {
            Method::Tsit5 => Some(tsit5::STAGES - 1),
            Method::Verner9 => Some(verner::FSAL_SLOT),
            _ => None,
        };
        self.ros.invalidate();
        self.dense_pending = false;
        if self.active == Method::Verner9 {
            if self.lazy_dense {
                self.verner_fsal_stage(h);
                self.dense_pending = true;
            } else {
                self.verner_dense_stages(h);
            }
        }
        self.stats.rhs_evals = self.rhs.evals;
    }

    /// Auto switching between Tsit5 and Rodas5P after an accepted step.
    fn update_stiffness(&mut self) {
        if self.requested != Method::Auto {
            return;
        }
        match self.active {
            Method::Tsit5 => {
                if self.stiff_ratio > TSIT5_STIFF_BOUND {
                    self.stiff_count += 1;
                    self.nonstiff_count = 0;
                } else {
                    self.nonstiff_count += 1;
                    if self.nonstiff_count >= 6 {
                        self.stiff_count = 0;
                    }
                }
                // Second test (for steps held small by something other than the stability
                // bound, where Hairer's ratio stays low): every JAC_CHECK_EVERY steps compare
                // h with the spectral radius of the symbolic Jacobian.
                self.jac_check_count += 1;
                if self.jac_check_count >= JAC_CHECK_EVERY {
                    self.jac_check_count = 0;
                    let rho = self.ros.spectral_radius_at(&self.rhs, self.t, &self.y.x);
                    self.stats.jac_evals += 1;
                    if self.dense_h * rho > JAC_STIFF_HRHO {
                        self.jac_stiff_count += 1;
                    } else {
                        self.jac_stiff_count = 0;
                    }
                }
                if self.stiff_count >= STIFF_STEPS_TO_SWITCH || self.jac_stiff_count >= 3 {
                    self.jac_stiff_count = 0;
                    self.jac_check_count = 0;
                    self.active = Method::Rosenbrock;
                    self.stiff_count = 0;
                    self.nonstiff_count = 0;
                    // The FSAL stage is F(t, y) and stays valid for Rodas5P's first stage.
                    self.reset_controller();
                }
            }
            Method::Rosenbrock => {
                // Back to explicit when the step Rodas5P proposes is well inside Tsit5's
                // stability region (hysteresis against the forward tests).
                let rho = self.ros.jac_spectral_radius();
                if self.h * rho < JAC_NONSTIFF_HRHO {
                    self.nonstiff_count += 1;
                } else {
                    self.nonstiff_count = 0;
                }
                if self.nonstiff_count >= NONSTIFF_STEPS_TO_SWITCH {
                    self.active = Method::Tsit5;
                    self.nonstiff_count = 0;
                    self.stiff_count = 0;
                    self.reset_controller();
                }
            }
            _ => {}
        }
    }

    /// Weighted RMS norm of `self.yerr` relative to y (start) and ynew (end).
    fn error_norm(&self) -> f64 {
        self.weighted_rms(&self.yerr, &self.y, &self.ynew, false)
    }

    /// Weighted RMS norm of `v` with scale atol + rtol |y|, over the controlled parts, for the
    /// initial-step heuristic. Components whose scale is zero (atol = 0 and y = 0, as S at
    /// t = 0 when x₀ does not depend on θ) say nothing about the solution's scale and are
    /// left out, instead of making the norm infinite and the first step zero.
    fn scaled_norm(&self, v: &AugState<M::N, M::P>, y: &AugState<M::N, M::P>) -> f64 {
        self.weighted_rms(v, y, y, true)
    }

    /// sqrt(1/N Σ_i (w_i e_i / (atol + rtol·w_i·max(|y0_i|, |y1_i|)))²) over x, q and, under
    /// sensitivity error control, S and q_θ. The weight is 1 on x and q and
    /// [`sens_weight`]`(θ_j)` on column j of S and on q_θ[j], so both are measured as the
    /// change θ_j·S_j they predict for a relative change of θ_j.
    fn weighted_rms(
        &self,
        e: &AugState<M::N, M::P>,
        y0: &AugState<M::N, M::P>,
        y1: &AugState<M::N, M::P>,
        skip_unscaled: bool,
    ) -> f64 {
        let (atol, rtol) = (self.atol, self.rtol);
        let mut sum = 0.0;
        let mut count = 0usize;
        let mut add = |e: &[f64], y0: &[f64], y1: &[f64], w: f64| {
            for ((ei, a), b) in e.iter().zip(y0).zip(y1) {
                let scale = atol + rtol * w * a.abs().max(b.abs());
                if skip_unscaled && scale == 0.0 {
                    continue;
                }
                // An exact zero counts as zero even where the scale is 0 (atol = 0, y = 0).
                if *ei != 0.0 {
                    let r = w * ei / scale;
                    sum += r * r;
                }
                count += 1;
            }
        };
        add(e.x.as_slice(), y0.x.as_slice(), y1.x.as_slice(), 1.0);
        if self.rhs.has_rc {
            add(&[e.q], &[y0.q], &[y1.q], 1.0);
        }
        if self.sens_err {
            let n = e.x.len();
            for (j, theta) in self.rhs.p.iter().enumerate() {
                let w = sens_weight(*theta);
                let col = j * n..(j + 1) * n;
                add(
                    &e.s.as_slice()[col.clone()],
                    &y0.s.as_slice()[col.clone()],
                    &y1.s.as_slice()[col],
                    w,
                );
                if self.rhs.has_rc {
                    add(&[e.qp[j]], &[y0.qp[j]], &[y1.qp[j]], w);
                }
            }
        }
        if count == 0 {
            return 0.0;
        }
        (sum / count as f64).sqrt()
    }

    /// Hairer's initial step heuristic (HNW I, II.4) from k[0] = F(t, y), bounded by `span`.
    fn initial_step(&mut self, span: f64) -> f64 {
        let order = self.error_order() - 1.0;
        let d0 = self.scaled_norm(&self.y, &self.y);
        let d1 = self.scaled_norm(&self.k[0], &self.y);
        let mut h0 = if d0 < 1e-5 || d1 < 1e-5 {
            1e-6
        } else {
            0.01 * d0 / d1
        };
        h0 = h0.min(span);
        // Explicit Euler probe: ynew = y + h0 k0, k[1] = F(t + h0, ynew).
        combine(
            &mut self.ynew,
            &self.y,
            h0,
            &[1.0],
            &self.k[..1],
            self.rhs.sens,
        );
        self.rhs.eval(self.t + h0, &self.ynew, &mut self.k[1]);
        // tmp = k1 − k0.
        self.tmp.copy_from(&self.k[1]);
        self.tmp.axpy(-1.0, &self.k[0]);
        let d2 = self.scaled_norm(&self.tmp, &self.y) / h0;
        let dm = d1.max(d2);
        let h1 = if !dm.is_finite() {
            h0 * 1e-3
        } else if dm <= 1e-15 {
            (h0 * 1e-3).max(1e-6)
        } else {
            (0.01 / dm).powf(1.0 / (order + 1.0))
        };
        (100.0 * h0).min(h1).min(span).max(f64::MIN_POSITIVE)
    }

    /// Dense output of x on [t_prev, t] (the continuous extension of the method that took the
    /// last step: 4th order for Tsit5 and Rodas5P, 9th for Verner). Cheap; for root finding.
    pub fn dense_x(&self, t: f64, out: &mut OVector<f64, M::N>) {
        if self.dense_h == 0.0 {
            out.copy_from(&self.y.x);
            return;
        }
        let theta = (t - self.t_prev) / self.dense_h;
        let (k, y0, y1, h) = (&self.k[..], &self.y_prev, self.end_state(), self.dense_h);
        if self.dense_pending {
            verner::hermite_x(k, y0, y1, h, theta, out);
            return;
        }
        match self.dense_method {
            Method::Tsit5 | Method::Auto => tsit5::dense_x(k, y0, h, theta, out),
            Method::Verner9 => verner::dense_x(k, y0, h, theta, out),
            Method::Rosenbrock => rosenbrock::dense_x(k, y0, y1, theta, out),
        }
    }

    /// Dense output of the full augmented state (x, S, q, q_θ) on [t_prev, t].
    pub fn dense(&self, t: f64, out: &mut AugState<M::N, M::P>) {
        if self.dense_h == 0.0 {
            out.copy_from(&self.y);
            return;
        }
        let theta = (t - self.t_prev) / self.dense_h;
        if self.dense_pending {
            let sens = self.rhs.sens;
            verner::hermite(
                &self.k,
                &self.y_prev,
                self.end_state(),
                self.dense_h,
                theta,
                sens,
                out,
            );
            return;
        }
        dense_into(
            self.dense_method,
            &self.k,
            &self.y_prev,
            self.end_state(),
            self.dense_h,
            theta,
            self.rhs.sens,
            out,
        );
    }

    /// The state at the end of the last accepted step (before any truncation).
    fn end_state(&self) -> &AugState<M::N, M::P> {
        if self.truncated {
            &self.y_end
        } else {
            &self.y
        }
    }

    /// Cuts the last step at `t_cut` ∈ [t_prev, t]: t() := t_cut, y() := dense(t_cut). The
    /// dense output stays valid on [t_prev, t_cut]; the next step re-evaluates F at the cut.
    pub fn truncate(&mut self, t_cut: f64) {
        let t_cut = t_cut.clamp(self.t_prev, self.t);
        if t_cut == self.t {
            return;
        }
        self.ensure_dense();
        if !self.truncated {
            self.y_end.copy_from(&self.y);
            self.truncated = true;
        }
        let theta = (t_cut - self.t_prev) / self.dense_h;
        dense_into(
            self.dense_method,
            &self.k,
            &self.y_prev,
            &self.y_end,
            self.dense_h,
            theta,
            self.rhs.sens,
            &mut self.y,
        );
        self.t = t_cut;
        self.k0_valid = false;
        self.fsal_slot = None;
        self.ros.invalidate();
    }
}

/// Dense output of `method` at θ ∈ [0, 1] of a step of length h from y0 to y1 with stages `k`.
#[allow(clippy::too_many_arguments)]
fn dense_into<N: Dim, P: Dim>(
    method: Method,
    k: &[AugState<N, P>],
    y0: &AugState<N, P>,
    y1: &AugState<N, P>,
    h: f64,
    theta: f64,
    sens: bool,
    out: &mut AugState<N, P>,
) where
    DefaultAllocator: ModelAlloc<N, P>,
{
    match method {
        Method::Tsit5 | Method::Auto => tsit5::dense(k, y0, h, theta, sens, out),
        Method::Verner9 => verner::dense(k, y0, h, theta, sens, out),
        Method::Rosenbrock => rosenbrock::dense(k, y0, y1, theta, sens, out),
    }
}

/// The weight of parameter θ_j's sensitivities in the error norm: |θ_j|, or 1 when θ_j = 0
/// (the parameter scaling `pbar` of CVODES). Unweighted, a parameter of size 1e-8 has
/// sensitivities of size 1e8 whose rounding floor (ε·1e8) lies above any absolute
/// tolerance, and one of size 1e8 has sensitivities too small to be controlled at all;
/// weighted, every column is held to the accuracy the state itself is held to.
fn sens_weight(theta: f64) -> f64 {
    if theta != 0.0 && theta.is_finite() {
        theta.abs()
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::Ball;
    use approx::assert_relative_eq;

    #[test]
    fn aug_state_axpy_and_combine() {
        let n = Const::<2>;
        let p = Const::<4>;
        let mut a = AugState::zeros(n, p);
        let mut b = AugState::zeros(n, p);
        b.x[0] = 1.0;
        b.s[(1, 3)] = 2.0;
        b.q = 3.0;
        b.qp[2] = 4.0;
        a.axpy(2.0, &b);
        assert_relative_eq!(a.x[0], 2.0);
        assert_relative_eq!(a.s[(1, 3)], 4.0);
        assert_relative_eq!(a.q, 6.0);
        assert_relative_eq!(a.qp[2], 8.0);
        let mut d = AugState::zeros(n, p);
        combine(&mut d, &a, 0.5, &[1.0, 0.0], &[b.clone(), a.clone()], false);
        assert_relative_eq!(d.x[0], 2.5);
        assert_relative_eq!(d.q, 7.5);
        // sens == false leaves S and q_θ of dst alone.
        assert_relative_eq!(d.s[(1, 3)], 0.0);
        combine(&mut d, &a, 0.5, &[1.0], &[b], true);
        assert_relative_eq!(d.s[(1, 3)], 5.0);
        assert_relative_eq!(d.qp[2], 10.0);
    }

    #[test]
    fn nonfinite_start_is_an_error() {
        let ball = Ball::new();
        let mut p = ball.default_params();
        p[1] = f64::NAN;
        let opts = Options::default();
        let mut it = Integrator::new(&ball, &p, &opts);
        let mut y = AugState::zeros(Const::<2>, Const::<4>);
        y.x[0] = 2.0;
        it.restart(0.0, &y, 0, 0);
        match it.step(1.0) {
            Err(StepError::NonFinite { what, .. }) => {
                assert!(what.contains("flow of mode"), "{what}")
            }
            other => panic!("expected NonFinite, got {other:?}"),
        }
    }
}
