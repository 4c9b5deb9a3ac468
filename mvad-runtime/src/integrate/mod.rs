//! One-step integrators, generic over the system they integrate, in either time direction.
//!
//! A stepper advances Ẏ = F(t, Y) for any system behind the seam of [`system`]:
//! [`StageVector`] (the vector-space operations of a stage loop), [`OdeSystem`] (F and the
//! error norm) and [`ImplicitSystem`] (Jacobian, factorisation, stage solves). Step sizes are
//! signed: `step(t_stop)` with t_stop < t integrates backwards (an adjoint pass from T to t₀).
//!
//! The forward run integrates, in a fixed mode m with frozen switch bits, the augmented system
//!
//! ```text
//!   ẋ   = f(t, x, θ)                  (n)
//!   Ṡ   = f_x S + f_θ                 (n × p, S = ∂x/∂θ)
//!   q̇   = ℓ(t, x, θ)                  (running cost)
//!   q̇_θ = ℓ_x S + ℓ_θ                 (p, its parameter gradient)
//! ```
//!
//! as one state [`AugState`] `(x, S, q, q_θ)` through [`Forward`] (`forward.rs`, the only file
//! here that calls the model). With `Options::sensitivities == false` only x and q are
//! advanced (S and q_θ stay untouched).
//!
//! ## Schemes
//! The requested [`Method`] is mapped to the [`Scheme`] taking the steps:
//! - [`Scheme::Tsit5`]: Tsitouras' 5(4) pair, FSAL, with its 4th-order continuous extension
//!   (`tsit5.rs`, a table for the stage loop of `explicit.rs`).
//! - [`Scheme::Verner9`]: Verner's "most efficient" 9(8) pair with its 9th-order interpolant
//!   (`verner.rs`, a table for the same loop).
//! - [`Scheme::Rodas5P`]: a stiffly accurate linearly implicit method of order 5(4) with a
//!   4th-order dense output that uses the system's Jacobian (`rosenbrock.rs`).
//! - [`Scheme::Exact`]: for a segment on which F is constant ([`OdeSystem::constant_rate`]: a
//!   mode whose flow is a function of θ alone, no running cost), Y(t + h) = Y + h·F is the
//!   exact solution (x and S are linear in t); one step reaches the stop time, with no error
//!   estimate and no step-size control, and the dense output is the same line. Whatever the
//!   method, the integrator uses it from every restart in such a mode.
//! - [`Method::Auto`] (default) starts with Tsit5 and runs Hairer's stiffness test
//!   (h·‖k₇ − k₆‖/‖y₇ − y₆‖ against the real stability boundary of Tsit5) and, every 20 steps,
//!   h·ρ(f_x) from a power iteration on the Jacobian (this catches steps held near 1/ρ by
//!   something other than stability, e.g. sensitivity error control); after repeated stiff
//!   steps it switches to Rodas5P, and back when h·ρ(f_x) < 0.4 shows the explicit method
//!   would be stable again (`stiffness.rs`).
//!
//! ## Error control and step size
//! The local error estimate e of the embedded pair is measured in the system's weighted RMS
//! norm ([`OdeSystem::error_norm`]); for the forward system
//! ‖e‖ = sqrt(1/N Σ (w_i e_i / (atol + rtol·w_i·max(|y0_i|, |y1_i|)))²) over x and q (the
//! latter only with a running cost), and `Options::sens_error_control` (on by default) adds S
//! and q_θ, column j weighted by w = |θ_j| so that it is controlled as the change θ_j·S_j it
//! predicts (the parameter scaling of CVODES). A step is accepted when ‖e‖ ≤ 1; the PI
//! controller of `control.rs` proposes the next one. The first step after every restart comes
//! from Hairer's heuristic (Hairer, Nørsett, Wanner I, II.4).
//!
//! ## Restarts
//! [`Integrator::restart`] forgets everything derived from the previous state: the FSAL stage,
//! the Jacobian, the step-size history. The driver calls it at the start and after every event,
//! mode switch or switch flip, so the first stage after a jump is always F at the new state.

mod adjoint;
mod adjoint_error;
mod aug;
mod control;
mod dense;
mod explicit;
mod forward;
mod global_error;
mod quadrature;
mod rosenbrock;
mod scheme;
mod stiffness;
pub mod system;
mod tsit5;
mod verner;

pub use adjoint::Backward;
pub use adjoint_error::{AdjointError, LamGrad};
pub(crate) use aug::sens_weight;
pub use aug::AugState;
pub(crate) use forward::zero_rows;
pub use forward::Forward;
pub use global_error::{EventRounding, GlobalError, JumpOf, ResetSecant, Saltation};
pub use scheme::Scheme;
pub use system::{
    AcceptedStep, ImplicitSystem, Linearised, OdeSystem, QuadratureSum, StageVector, Tol,
};

use crate::error::SolveError;
use crate::solution::{Method, Options, Stats};
use control::Controller;
use tsit5::TSIT5;
use verner::VERNER9;

/// The rate after a restart, against the rate before it, beyond which a seeded step gives
/// way to Hairer's heuristic ([`Integrator::set_step_size`]); within it (the controller's own
/// growth limit) the seed stands.
const SEED_RATE_JUMP: f64 = 10.0;

/// A seed of at most this many ulps of t is no seed ([`Integrator::set_step_size`]): 100, ten
/// times the shortest step the controller takes before it reports an underflow.
const SEED_FLOOR_ULPS: f64 = 100.0;

/// An adaptive one-step integrator of the system `Sys` (see the module doc); for the forward
/// augmented flow of a model, `Integrator<Forward<'_, M>>` built by [`Integrator::new`].
///
/// All buffers are allocated when it is built; stepping allocates nothing, for static and
/// `Dyn` sizes alike (the Rosenbrock method factorises in place in the system's buffers).
/// Times and step lengths are signed; t_prev → t is the last accepted step in either direction.
pub struct Integrator<Sys: OdeSystem> {
    sys: Sys,
    tol: Tol,
    /// Budget of step attempts (accepted + rejected) over the integrator's life.
    max_steps: usize,
    requested: Method,
    scheme: Scheme,
    /// The adaptive scheme to return to when a restart leaves a segment of exact steps.
    adaptive: Scheme,
    /// Scheme that produced the last accepted step (the one `dense` uses).
    dense_scheme: Scheme,
    t: f64,
    t_prev: f64,
    /// Signed length of the last accepted step (dense output lives between t_prev and
    /// t_prev + dense_h).
    dense_h: f64,
    /// Magnitude of the proposed next step; 0 ⇒ choose it by Hairer's heuristic.
    h: f64,
    y: Sys::Vector,
    y_prev: Sys::Vector,
    /// The end state of the last accepted step once [`Integrator::truncate`] has overwritten y.
    y_end: Sys::Vector,
    /// y was cut by `truncate` (the step's end state is in y_end).
    truncated: bool,
    /// Candidate state of the step being attempted.
    ynew: Sys::Vector,
    /// Stage argument scratch.
    tmp: Sys::Vector,
    /// Local error estimate.
    yerr: Sys::Vector,
    /// Stage derivatives k_i (and for Verner, the interpolation stages).
    k: Vec<Sys::Vector>,
    /// Signed length of the last accepted step while it is not closed: the system's global
    /// error estimate not carried over it, its quadrature not added (see
    /// [`Integrator::close_step`]).
    carry_pending: Option<f64>,
    /// The system's quadrature sums hold the last attempt's whole-step ΔQ and its error
    /// (formed in [`Integrator::attempt`] under [`OdeSystem::controls_quadrature`]); once
    /// that attempt is accepted they wait for [`Integrator::close_step`].
    quadrature_formed: bool,
    /// The proposed step `h` is a seed ([`Integrator::set_step_size`]): the scaled rate at
    /// the start of the last step before it, until the first step after it compares it with
    /// its own.
    seed_rate: Option<f64>,
    /// k[0] = F(t, y) holds (computed or taken over from the FSAL stage).
    k0_valid: bool,
    /// The last accepted step left F(t, y) in this stage slot (Tsit5: k₇; Verner: the first
    /// interpolation stage), to become the next step's k[0] unless a restart intervenes.
    fsal_slot: Option<usize>,
    ctrl: Controller,
    /// Verner: evaluate the nine interpolation stages after the FSAL one only on demand
    /// ([`Integrator::ensure_dense`]); see [`Integrator::set_lazy_dense`].
    lazy_dense: bool,
    /// The last accepted Verner step's interpolation stages 18..26 are not evaluated yet.
    dense_pending: bool,
    /// Hairer's stiffness estimate |h|·‖k₇ − k₆‖/‖y₇ − y₆‖ of the last Tsit5 attempt.
    stiff_ratio: f64,
    stiff_count: usize,
    nonstiff_count: usize,
    /// Accepted Tsit5 steps since the last Jacobian check, and consecutive stiff checks.
    jac_check_count: usize,
    jac_stiff_count: usize,
    stats: Stats,
}

impl<Sys: ImplicitSystem> Integrator<Sys> {
    /// An integrator of `sys` with the stage buffers of every scheme `opts.method` may use;
    /// allocates every buffer once. Call [`Integrator::restart_at`] (or the system's own
    /// restart) before the first step.
    pub fn with_system(sys: Sys, opts: &Options) -> Self {
        let slots = Scheme::slots(opts.method);
        let scheme = Scheme::initial(opts.method);
        let zero = || sys.zeros();
        let mut it = Integrator {
            tol: Tol {
                atol: opts.atol,
                rtol: opts.rtol,
            },
            max_steps: opts.max_steps,
            requested: opts.method,
            scheme,
            adaptive: scheme,
            dense_scheme: scheme,
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
            k: (0..slots).map(|_| zero()).collect(),
            k0_valid: false,
            seed_rate: None,
            quadrature_formed: false,
            carry_pending: None,
            fsal_slot: None,
            ctrl: Controller::new(),
            lazy_dense: false,
            dense_pending: false,
            stiff_ratio: 0.0,
            stiff_count: 0,
            nonstiff_count: 0,
            jac_check_count: 0,
            jac_stiff_count: 0,
            stats: Stats::default(),
            sys,
        };
        it.ctrl.reset(scheme.error_order());
        it
    }

    /// Forget all history (no FSAL reuse, no old Jacobian, no step-size memory) and restart at
    /// (t, y). The adaptive scheme in use is kept; [`Scheme::Exact`] replaces it while the
    /// system's F is constant.
    pub fn restart_at(&mut self, t: f64, y: &Sys::Vector) {
        self.close_step();
        if self.scheme != Scheme::Exact {
            self.adaptive = self.scheme;
        }
        self.scheme = if self.sys.constant_rate() {
            Scheme::Exact
        } else {
            self.adaptive
        };
        self.restart_clock_and_state(t, y);
        self.k0_valid = false;
        self.ctrl.reset(self.scheme.error_order());
        self.ctrl.last_rejected = false;
        self.dense_scheme = self.scheme;
    }

    /// What every restart forgets: the clock and state restart at (t, y) with no step behind
    /// them (no dense output, no step-size proposal or seed, no FSAL stage, no Jacobian).
    fn restart_clock_and_state(&mut self, t: f64, y: &Sys::Vector) {
        self.t = t;
        self.t_prev = t;
        self.dense_h = 0.0;
        self.truncated = false;
        self.h = 0.0;
        self.seed_rate = None;
        self.y.copy_from(y);
        self.y_prev.copy_from(y);
        self.fsal_slot = None;
        self.dense_pending = false;
        self.sys.linearisation().invalidate();
    }

    /// The restart after a jump inside a segment of exact steps that leaves F as it was (the
    /// caller knows F is the same: a constant-rate system under the same mode and bits, F a
    /// function of θ, the mode and the bits alone): closes the last step and restarts at
    /// (t, y) like [`Integrator::restart_at`], keeping `k[0]` = F (an exact step and a
    /// truncation of one leave it in place) instead of taking it again.
    pub fn restart_exact_keeping_rate(&mut self, t: f64, y: &Sys::Vector) {
        debug_assert!(self.scheme == Scheme::Exact && self.dense_scheme == Scheme::Exact);
        self.close_step();
        self.restart_clock_and_state(t, y);
        self.k0_valid = true;
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

    /// End of the last accepted step.
    pub fn t(&self) -> f64 {
        self.t
    }
    /// Start of the last accepted step.
    pub fn t_prev(&self) -> f64 {
        self.t_prev
    }
    /// State at [`Integrator::t`].
    pub fn y(&self) -> &Sys::Vector {
        &self.y
    }
    /// State at [`Integrator::t_prev`].
    pub fn y_prev(&self) -> &Sys::Vector {
        &self.y_prev
    }
    /// The system being integrated.
    pub fn system(&self) -> &Sys {
        &self.sys
    }
    /// Work counters (steps, rejected_steps, rhs_evals, jac_evals, factorizations; the event
    /// fields stay zero).
    pub fn stats(&self) -> &Stats {
        &self.stats
    }
    /// The method taking the steps now (what `auto` is using).
    pub fn active_method(&self) -> Method {
        self.scheme.method()
    }
    /// The scheme taking the steps now.
    pub fn scheme(&self) -> Scheme {
        self.scheme
    }
    /// Signed length of the last accepted step before any truncation (0 right after a
    /// restart).
    pub fn last_step_size(&self) -> f64 {
        self.dense_h
    }
    /// The magnitude of the step the controller proposes next (0 before the first step after
    /// a restart).
    pub fn next_step_size(&self) -> f64 {
        self.h
    }

    /// F of the segment of exact steps in progress ([`Scheme::Exact`]: constant along it,
    /// `k[0]` from the restart that began it, where every exact step leaves it), or `None`
    /// when the scheme is adaptive or F is not known yet (a masked or non-finite F is
    /// evaluated by the first step).
    pub fn exact_rate(&self) -> Option<&Sys::Vector> {
        let known = self.k0_valid || self.fsal_slot == Some(0);
        (self.scheme == Scheme::Exact && known).then(|| &self.k[0])
    }

    /// Raises the budget of step attempts by `extra` (the driver grants each row of a data
    /// table its own allowance: a long table needs at least one step per row).
    pub fn extend_step_budget(&mut self, extra: usize) {
        self.max_steps = self.max_steps.saturating_add(extra);
    }

    /// Seeds the magnitude of the next step attempt, e.g. with the step size in use before an
    /// event (call it after a restart, which otherwise starts from Hairer's heuristic; the
    /// error control still rejects and shrinks a seed that is too large). A value that is not
    /// finite and positive restores the heuristic, and so does one too short to be a step
    /// here (at most `SEED_FLOOR_ULPS` ulps of t): the step before the jump was then a landing
    /// cut short by its stop (a time event one ulp before an end, the adjoint's sweep starting
    /// on the sliver between such an event and T), which says nothing of the flow's time scale
    /// and would be refused as a step-size underflow.
    ///
    /// The seed belongs to the rate before the restart: when the rate after it, ‖F(t, y)‖ in
    /// the error norm's scaling, is more than `SEED_RATE_JUMP` times the rate at the start
    /// of the last step before it (`k[0]`, still in its slot), the state's time scale has
    /// shrunk by as much and the seed says nothing about it: the first step comes from
    /// Hairer's heuristic, as at t₀. The error estimate cannot refuse a seed on its own when
    /// an L-stable step strides over a fast transient the jump started (a stiff lag's new set
    /// point): the step lands right at the transient's end, and only its dense output, which
    /// the adjoint's sweep reads, misses the transient (the stiff relay's dC/dτ was off by
    /// 6e6 at rtol 1e-3 in adjoint mode). Without a step before it (a rate below 1e-5) the
    /// seed stands.
    pub fn set_step_size(&mut self, h: f64) {
        let floor = SEED_FLOOR_ULPS * f64::EPSILON * self.t.abs();
        self.h = if h.is_finite() && h > 0.0 && h > floor {
            h
        } else {
            0.0
        };
        // An exact segment takes no seed (and its k[0] is already the new F).
        let adaptive = self.h > 0.0 && self.scheme != Scheme::Exact;
        self.seed_rate = adaptive.then(|| self.scaled_norm(&self.k[0], &self.y));
    }

    /// Take ONE accepted step towards `t_stop`, never beyond it; lands exactly on `t_stop`
    /// when it is reached. `t_stop < t()` integrates backwards; `t_stop == t()` does nothing.
    pub fn step(&mut self, t_stop: f64) -> Result<(), SolveError> {
        if t_stop.is_nan() {
            return Err(SolveError::NonFinite {
                t: self.t,
                what: "stop time".into(),
            });
        }
        if t_stop == self.t {
            return Ok(());
        }
        let dir = if t_stop > self.t { 1.0 } else { -1.0 };
        self.close_step();
        self.ensure_k0()?;
        let seed_rate = self.seed_rate.take();
        if self.scheme == Scheme::Exact {
            return self.exact_step(t_stop);
        }
        if let Some(before) = seed_rate {
            let after = self.scaled_norm(&self.k[0], &self.y);
            if before >= 1e-5 && after > SEED_RATE_JUMP * before {
                self.h = 0.0;
            }
        }
        if self.h == 0.0 {
            self.h = self.initial_step(t_stop - self.t);
        }
        // Where the last non-finite attempt of this step came from (see `nonfinite_source`).
        let mut nonfinite: Option<String> = None;
        let mut nonfinite_tries = 0usize;
        loop {
            let span = (t_stop - self.t).abs();
            let mut h = self.h;
            let landing = h * 1.01 >= span;
            if landing {
                h = span;
            } else {
                // The step the time grid takes: t + h is rounded to a double, so the step is
                // (t + h) − t (exact by Sterbenz). Far from t = 0 (t = 10⁹: ulp 1.2e-7) the
                // requested h and the grid's differ, and stepping the state by one while the
                // clock moves by the other loses accuracy in every step.
                h = ((self.t + dir * h) - self.t).abs();
            }
            // A landing step onto t_stop is taken however short: the interval left is real
            // (an accumulation whose limit t* lies 2 ulp before T, an event 1e-301 after
            // t = 0), and a step that short changes the state by f·h, below its rounding.
            // Only a step the controller has shrunk to the resolution of t is an underflow.
            let too_short = h <= 10.0 * f64::EPSILON * self.t.abs() || h < 1e-300;
            if h.is_nan() || (too_short && !(landing && h > 0.0)) {
                // Shrinking towards a point where the flow stops being defined (√ of a
                // negative, 1/0, ...) ends here: report the NaN, not the step size.
                return Err(match nonfinite.or_else(|| self.undefined_just_ahead(dir)) {
                    Some(what) => SolveError::NonFinite { t: self.t, what },
                    None => SolveError::StepSizeUnderflow {
                        t: self.t,
                        h,
                        largest: self.largest_entry(),
                    },
                });
            }
            let used = self.stats.steps + self.stats.rejected_steps;
            if used >= self.max_steps {
                return Err(self.out_of_steps(h));
            }
            let err = self.attempt(dir * h);
            if !err.is_finite() || !self.ynew.is_finite() {
                // NaN or overflow inside the step: retry much shorter, give up after many
                // tries (or at the step-size floor above).
                nonfinite_tries += 1;
                self.stats.rejected_steps += 1;
                self.ctrl.last_rejected = true;
                let what = self.nonfinite_source();
                if nonfinite_tries > 60 {
                    return Err(SolveError::NonFinite { t: self.t, what });
                }
                nonfinite = Some(what);
                self.h = h * 0.25;
                continue;
            }
            let k = self.scheme.error_order();
            if err <= 1.0 {
                let fac = self.ctrl.accepted(err, k);
                self.accept(dir * h, landing, t_stop);
                self.carry_pending = Some(dir * h);
                self.h = h * fac;
                self.update_stiffness();
                return Ok(());
            }
            self.stats.rejected_steps += 1;
            self.h = h * self.ctrl.rejected(err, k);
        }
    }

    /// The largest |entry| of the primary part of the integrated state (x, or the adjoint's
    /// λ): what a failure reports, so that a solution blowing up is told from a stiff one.
    fn largest_entry(&self) -> f64 {
        self.y.primary().iter().fold(0.0, |m, v| m.max(v.abs()))
    }

    /// The failure when the step budget is used up, with the step size `h` reached, whether
    /// stiffness is ruled out (the implicit scheme in use, or `auto`, whose stiffness test
    /// would have switched to it), and the largest state entry.
    fn out_of_steps(&self, h: f64) -> SolveError {
        SolveError::MaxSteps {
            t: self.t,
            steps: self.max_steps,
            h,
            not_stiff: self.scheme == Scheme::Rodas5P || self.requested == Method::Auto,
            largest: self.largest_entry(),
        }
    }

    /// The one step of a [`Scheme::Exact`] segment: Y(t_stop) = Y + (t_stop − t)·F, landing on
    /// t_stop, with no error estimate, no step-size control and nothing to carry for the global
    /// error estimate (the step makes no error, and its flow, a function of θ alone, moves
    /// none). Fails as an adaptive step would: a step below the resolution of t, the step
    /// budget, or a state that overflows.
    fn exact_step(&mut self, t_stop: f64) -> Result<(), SolveError> {
        let h = t_stop - self.t;
        if h.abs() <= 10.0 * f64::EPSILON * self.t.abs() || h.abs() < 1e-300 {
            return Err(SolveError::StepSizeUnderflow {
                t: self.t,
                h: h.abs(),
                largest: self.largest_entry(),
            });
        }
        if self.stats.steps + self.stats.rejected_steps >= self.max_steps {
            return Err(self.out_of_steps(h.abs()));
        }
        // In place (no candidate state to swap in): y_prev ← Y, Y ← Y + h·F.
        self.quadrature_formed = false;
        self.y_prev.copy_from(&self.y);
        let all = self.sys.all_parts();
        self.y.axpy(h, &self.k[0], all);
        if !self.y.is_finite() {
            std::mem::swap(&mut self.y, &mut self.ynew);
            self.y.copy_from(&self.y_prev);
            self.stats.rejected_steps += 1;
            let what = self.nonfinite_source();
            return Err(SolveError::NonFinite { t: self.t, what });
        }
        self.t_prev = self.t;
        self.t = t_stop;
        self.dense_h = h;
        self.truncated = false;
        self.dense_scheme = Scheme::Exact;
        self.stats.steps += 1;
        // F is constant: k[0] stays the next step's first stage.
        self.k0_valid = false;
        self.fsal_slot = Some(0);
        self.sys.linearisation().invalidate();
        self.dense_pending = false;
        self.stats.rhs_evals = self.sys.evals();
        // Pending like any accepted step when the system keeps a quadrature outside its
        // vector: `close_step` carries no global error over an exact step but adds that
        // quadrature (the adjoint's g += −h λᵀf_θ). Without one there is nothing to close.
        if self.sys.has_quadrature() {
            self.carry_pending = Some(h);
        }
        Ok(())
    }

    /// Takes one step of exactly `h` (either sign) with the active scheme and no error control
    /// (always accepted); returns the weighted norm of its local error estimate. For verifying
    /// convergence orders; the driver uses [`Integrator::step`].
    pub fn step_fixed(&mut self, h: f64) -> Result<f64, SolveError> {
        if h.is_nan() || h == 0.0 || !h.is_finite() {
            return Err(SolveError::StepSizeUnderflow {
                t: self.t,
                h,
                largest: self.largest_entry(),
            });
        }
        self.ensure_k0()?;
        let err = self.attempt(h);
        if let Some(what) = self.sys.nonfinite_part(&self.ynew) {
            return Err(SolveError::NonFinite {
                t: self.t,
                what: what.into(),
            });
        }
        let t_end = self.t + h;
        self.accept(h, true, t_end);
        Ok(err)
    }

    /// Closes the last accepted step, if that is still pending: carries the system's global
    /// error estimate over it and adds its quadrature ([`OdeSystem::has_quadrature`]; ΔQ as
    /// the accepted attempt formed it, re-formed with the weights bᵢ(θ) when the step was
    /// cut, or formed now when the attempt did not, `quadrature.rs`). A step is closed once
    /// it is known where it ends: when the next step starts, when [`Integrator::truncate`]
    /// cuts it (over the cut length), at a restart, or when the caller asks before reading
    /// the estimate or the quadrature (at the end of a run or a segment). Until then t_prev,
    /// y_prev, the stages k (`k[0]` = F(t_prev, y_prev)) and the local error estimate are the
    /// step's. An exact step makes no error, and its flow (a function of θ alone) moves none:
    /// it carries nothing, but adds its quadrature.
    #[inline]
    pub fn close_step(&mut self) {
        if self.carry_pending.is_some() {
            self.close_pending_step();
        }
    }

    /// [`Integrator::close_step`] of a step that is pending.
    fn close_pending_step(&mut self) {
        if let Some(h) = self.carry_pending.take() {
            let exact = self.dense_scheme == Scheme::Exact;
            if !exact {
                self.sys.carry_global_error(AcceptedStep {
                    t0: self.t_prev,
                    h,
                    y0: &self.y_prev,
                    f0: &self.k[0],
                    le: &self.yerr,
                });
            }
            if self.sys.has_quadrature() {
                let error = self.sys.estimates_quadrature_error() && !exact;
                let of = quadrature::QuadratureOf::Accepted(h / self.dense_h);
                if !self.quadrature_formed {
                    self.form_quadrature(of, error);
                } else if h != self.dense_h {
                    self.form_quadrature(of, false);
                }
                self.sys.quadrature_close(error);
            }
            self.quadrature_formed = false;
        }
    }

    /// Makes k[0] = F(t, y): from the FSAL stage of the last explicit step, or by evaluating.
    fn ensure_k0(&mut self) -> Result<(), SolveError> {
        if self.k0_valid {
            return Ok(());
        }
        if let Some(slot) = self.fsal_slot.take() {
            self.k.swap(0, slot);
        } else {
            self.sys.eval(self.t, &self.y, &mut self.k[0]);
        }
        if self.sys.nonfinite_part(&self.k[0]).is_some() {
            let what = if self.sys.nonfinite_part(&self.y).is_some() {
                format!("{} (the state itself)", self.sys.stage_source(&self.k[0]))
            } else {
                self.sys.stage_source(&self.k[0])
            };
            return Err(SolveError::NonFinite { t: self.t, what });
        }
        self.k0_valid = true;
        Ok(())
    }

    /// When the step size has shrunk to the resolution of t without a non-finite attempt
    /// (the sensitivities' derivative can blow up before the flow does, as ∂√(c − t)/∂c at
    /// t → c, and hold the step short of c), probes F at t + dir·2ᵏ·10ε|t|, k = 0..4, with
    /// the state held: the name of the expression that is non-finite there, if any, so the
    /// run reports where the flow stops being defined rather than a bare step-size underflow.
    fn undefined_just_ahead(&mut self, dir: f64) -> Option<String> {
        let dt = 10.0 * f64::EPSILON * self.t.abs().max(f64::MIN_POSITIVE);
        for k in 0..5 {
            let t = self.t + dir * dt * f64::from(1u32 << k);
            self.sys.eval(t, &self.y, &mut self.k[1]);
            if self.sys.nonfinite_part(&self.k[1]).is_some() {
                return Some(self.sys.stage_source(&self.k[1]));
            }
        }
        None
    }

    /// Names the expression behind a non-finite attempt: the first evaluated stage with a
    /// NaN/∞ decides (the system's [`OdeSystem::stage_source`]); if all stages are finite, the
    /// combination overflowed (`state x ...`).
    fn nonfinite_source(&self) -> String {
        let stages = self.scheme.info().2.min(self.k.len());
        for k in &self.k[..stages] {
            if self.sys.nonfinite_part(k).is_some() {
                return self.sys.stage_source(k);
            }
        }
        if self.quadrature_formed && self.ynew.is_finite() {
            return format!("quadrature of the {}", self.sys.flow_name());
        }
        let part = self
            .sys
            .nonfinite_part(&self.ynew)
            .unwrap_or("local error estimate");
        format!("{part} (overflow in the {})", self.sys.flow_name())
    }

    /// One attempt of the active scheme with signed step h from (t, y): fills `ynew`, the
    /// stages and `yerr`, and returns the error norm (NaN when something overflowed). Under
    /// [`OdeSystem::controls_quadrature`] an attempt that Y's norm accepts also forms the
    /// quadrature's ΔQ and its error, and the norm is max(‖e_Y‖, ‖e_Q‖).
    #[inline]
    fn attempt(&mut self, h: f64) -> f64 {
        let err = match self.scheme {
            Scheme::Tsit5 => self.explicit_attempt(&TSIT5, h),
            Scheme::Verner9 => self.explicit_attempt(&VERNER9, h),
            Scheme::Rodas5P => self.rosenbrock_attempt(h),
            Scheme::Exact => self.exact_attempt(h),
        };
        self.quadrature_formed = false;
        let controlled = self.scheme != Scheme::Exact
            && self.sys.has_quadrature()
            && self.sys.controls_quadrature();
        if !controlled || err.is_nan() || err > 1.0 {
            return err;
        }
        self.form_quadrature(quadrature::QuadratureOf::Attempt(h), true);
        self.quadrature_formed = true;
        let eq = self.sys.quadrature_error_norm(self.tol);
        // A non-finite ΔQ or error makes the attempt non-finite (`f64::max` would drop it).
        if eq.is_nan() {
            f64::NAN
        } else {
            err.max(eq)
        }
    }

    /// Y₁ = Y₀ + h·F₀ for a constant F (exact); the error estimate is zero.
    fn exact_attempt(&mut self, h: f64) -> f64 {
        let all = self.sys.all_parts();
        self.ynew.copy_from(&self.y);
        self.ynew.axpy(h, &self.k[0], all);
        0.0
    }

    /// Commits the attempted step of signed length h.
    fn accept(&mut self, h: f64, landing: bool, t_stop: f64) {
        std::mem::swap(&mut self.y_prev, &mut self.y);
        std::mem::swap(&mut self.y, &mut self.ynew);
        self.t_prev = self.t;
        self.t = if landing { t_stop } else { self.t + h };
        self.dense_h = h;
        self.truncated = false;
        self.dense_scheme = self.scheme;
        self.stats.steps += 1;
        self.k0_valid = false;
        self.fsal_slot = self.scheme.info().3;
        self.sys.linearisation().invalidate();
        self.dense_pending = false;
        if self.scheme == Scheme::Verner9 {
            self.accepted_interp_stages(&VERNER9, h);
        }
        self.stats.rhs_evals = self.sys.evals();
    }

    /// The system's weighted RMS norm of `yerr` relative to y (start) and ynew (end).
    #[inline]
    fn error_norm(&self) -> f64 {
        self.sys
            .error_norm(&self.yerr, &self.y, &self.ynew, self.tol)
    }
}

#[cfg(test)]
mod tests;
