//! The driver: simulate a hybrid model, locate its events, carry S = ∂x/∂θ through every
//! jump and reduce to C(θ) and dC/dθ.
//!
//! One run of [`solve`]:
//! 1. T from `Options::t_end` (then dT/dθ = 0) or the model's horizon; x(0) = x₀(θ),
//!    S(0) = ∂x₀/∂θ; switch bits from the signs of σ_j at t = 0.
//! 2. Accepted steps of the integrator (x, S, q = ∫ℓ, q_θ = ∫(ℓ_x S + ℓ_θ)); after each step the
//!    [`Scanner`] looks for guard and switch crossings on the dense output (see [`crate::event`]).
//! 3. At the earliest crossing the step is truncated there and the event applied: t_k', the
//!    reset, the new mode, the switch bits re-evaluated at x⁺, S⁺ (see [`crate::sens`]), the
//!    running-cost jump (ℓ⁻ − ℓ⁺) t_k', the event cost and its total derivative, the jumps of
//!    every state and observable and the atoms α_k = −J_k t_k'. Events within
//!    `simultaneous_tol · max(|t_k|, 1)` of the earliest fire at the same time in declaration
//!    order (a `simultaneous_events` diagnostic). A switch crossing flips its bit with the
//!    identity reset. Then the integrator restarts (no stage is reused across a jump), its
//!    first step seeded with the length of the step that contained the event.
//! 4. At T the final terms (see [`crate::reduce`]).
//!
//! At a Zeno accumulation, or a reset that leaves the state on its guard, the run restarts
//! from the limit with the states the accumulation constrains held there and the others
//! following their flow (see `zeno`).
//!
//! The work is split by job: this module holds the loop (step, scan, truncate at the
//! earliest crossing, apply, restart); `jump` what happens at an event or switch crossing;
//! `zeno` accumulations; `undecided` crossings and near misses the tolerances cannot decide;
//! `order` a time event and a state event whose order the state event's location error
//! leaves undecided;
//! `record` the trajectory record; `finish` the end of the run; `validate` the checks of
//! the parameters, options and model before a run; `watch` what each mode
//! watches; `line` the exact segments whose watched guards are lines, taken to their first
//! root in closed form instead of being stepped and scanned.
//! Events leave the loop through an [`EventSink`] the caller chooses.

mod conditioning;
mod finish;
mod jump;
mod line;
mod order;
mod qp;
pub(crate) use qp::is_event_kink;
mod record;
mod resolution;
mod schedule;
mod undecided;
mod validate;
mod watch;
mod zeno;

pub(crate) use conditioning::judge;

use crate::adjoint::record::{Tape, MAX_COEFS};
use crate::error::{SolveError, Time};
use crate::event::{Crossing, Scanner, Watch};
use crate::integrate::{zero_rows, AugState, Forward, Integrator, OdeSystem, Scheme};
use crate::model::{At, HybridModel, ModelAlloc, Point, Switches};
use crate::reduce::CompensatedSum;
use crate::sink::EventSink;
use crate::solution::{Diagnostic, DiagnosticKind, EventRecord, GradientMode, Options, Solution};
use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector};
use record::Recorder;
use schedule::Schedule;
use std::time::Instant;
use validate::validate;
use watch::ModeWatch;
use zeno::Zeno;

/// Simulates `model` at `params` and returns the cost, dC/dθ, the full event table and
/// everything the measure needs.
///
/// Errors: bad input (wrong parameter count, non-finite parameters, bad options, no or a
/// non-positive horizon) and numerical failures (`NonFinite` naming the expression,
/// `StepSizeUnderflow`, `MaxEvents`); see [`SolveError`].
pub fn solve<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
) -> Result<Solution, SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let mut table: Vec<EventRecord> = Vec::new();
    let mut sol = solve_with(model, params, opts, &mut table)?;
    sol.events = table;
    Ok(sol)
}

/// Like [`solve`], but every user event goes to `sink` instead of into
/// `Solution::events` (which stays empty): with `&mut ()` a run that wants only C and dC/dθ
/// allocates nothing per event; see [`crate::sink`].
///
/// With sensitivities and `Options::gradient_mode` resolving to
/// [`GradientMode::Adjoint`], dC/dθ comes from a primal run and a backward sweep
/// ([`crate::adjoint`]); the sink then sees the primal run's events (without t').
pub fn solve_with<M: HybridModel, K: EventSink>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
    sink: &mut K,
) -> Result<Solution, SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let adjoint = opts.gradient_mode.resolve(model.nparams().value()) == GradientMode::Adjoint;
    if !(opts.sensitivities && adjoint) {
        return Ok(run_loop(model, params, opts, sink, false)?.0);
    }
    // Adjoint mode: the pull-back of w_C = 1 with no samples, or forward mode where the
    // adjoint does not apply (see `crate::adjoint`).
    let start = std::time::Instant::now();
    let cost_only = crate::vjp::Cotangents {
        cost: 1.0,
        times: &[],
        observables: &[],
    };
    match crate::adjoint::pull_back(model, params, opts, sink, &cost_only)? {
        Ok((sol, _)) => Ok(sol),
        Err(handover) => {
            let fwd = Options {
                gradient_mode: GradientMode::Forward,
                ..opts.clone()
            };
            let (mut sol, _) = run_loop(model, params, &fwd, sink, false)?;
            crate::adjoint::note_fallback(&mut sol, handover);
            sol.stats.wall_seconds = start.elapsed().as_secs_f64();
            Ok(sol)
        }
    }
}

/// One run of the event loop, with forward sensitivities or primal only as
/// `opts.sensitivities` says (`opts.gradient_mode` is not looked at), keeping the adjoint's
/// record of the run when `tape` (returned only if the run reached T without a Zeno or
/// stuck-state stop, which end it differently).
pub(crate) fn run_loop<M: HybridModel, K: EventSink>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
    sink: &mut K,
    tape: bool,
) -> Result<(Solution, Option<Tape>), SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let start = Instant::now();
    validate(model, params, opts)?;
    // A model without states has no time: its cost is a function of θ, taken at t = 0.
    let timeless = model.nstates().value() == 0;
    let t_end = match opts.t_end {
        Some(t) => t,
        None => match model.horizon(params) {
            Some(t) => t,
            None if timeless => 0.0,
            None => return Err(SolveError::NoHorizon),
        },
    };
    if !(t_end.is_finite() && (t_end > 0.0 || timeless && t_end == 0.0)) {
        return Err(SolveError::BadHorizon { t_end });
    }
    let (mut sol, tape, qp_event_kink) = qp::run(model, params, opts, t_end, sink, tape)?;
    qp::report(model, params, opts, &mut sol, qp_event_kink)?;
    sol.stats.wall_seconds = start.elapsed().as_secs_f64();
    Ok((sol, tape))
}

/// The `NonFinite` error at t; its text is built only when it happens (off the hot path).
#[cold]
#[inline(never)]
fn nonfinite(t: f64, what: impl FnOnce() -> String) -> SolveError {
    SolveError::NonFinite { t, what: what() }
}

/// The resolution of the time t in the event loop, 16 ulp: a located crossing is that close
/// to the true one, a state event's state is snapped onto its guard only that far, and a time
/// event due that soon after an instant joins it (no step that short can be taken).
pub(super) fn time_resolution(t: f64) -> f64 {
    16.0 * f64::EPSILON * t.abs() + f64::MIN_POSITIVE
}

/// All state and buffers of one run (allocated once in `new`).
struct Driver<'a, M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    model: &'a M,
    p: &'a OVector<f64, M::P>,
    opts: &'a Options,
    t_end: f64,
    dt_end: OVector<f64, M::P>,
    sens: bool,
    integ: Integrator<Forward<'a, M>>,
    y: AugState<M::N, M::P>,
    aug_tmp: AugState<M::N, M::P>,
    mode: usize,
    /// The frozen switch bits in force.
    sw: Switches,
    /// The bits after a pending event or flip (swapped into `sw` when it is applied).
    sw_next: Switches,
    /// Scratch: switching functions at exactly zero when the bits are first decided.
    sw_undecided: Switches,
    scanner: Scanner,
    /// The length of the pieces the watched functions allow (see `resolution`).
    resolution: resolution::Resolution,
    /// What each mode watches, decided once per run (see [`ModeWatch`]).
    watch: Vec<ModeWatch>,
    /// Every watched function active since the last restart is an affine guard (see
    /// [`HybridModel::guard_is_affine`]): on an exact step the scanner needs only its ends.
    affine_watch: bool,
    /// The watched lines of exact segments (see `line`).
    lines: line::Lines,
    /// The mode whose whole watch list the scanner holds from the last restart (`None` before
    /// the first and after a restart during a hold, which leaves held events out): a restart
    /// in the same mode outside a hold restarts the same functions in place.
    watching: Option<usize>,
    xs: OVector<f64, M::N>,
    xe: OVector<f64, M::N>,
    x_plus: OVector<f64, M::N>,
    f_minus: OVector<f64, M::N>,
    f_plus: OVector<f64, M::N>,
    work: OVector<f64, M::N>,
    rt: OVector<f64, M::N>,
    gx: OVector<f64, M::N>,
    gp: OVector<f64, M::P>,
    dt: OVector<f64, M::P>,
    rx: OMatrix<f64, M::N, M::N>,
    rp: OMatrix<f64, M::N, M::P>,
    s_plus: OMatrix<f64, M::N, M::P>,
    dtot: OMatrix<f64, M::N, M::P>,
    cx: OVector<f64, M::N>,
    cp: OVector<f64, M::P>,
    obs_minus: Vec<f64>,
    obs_plus: Vec<f64>,
    /// Accumulated event costs Σ φ_k and their total derivatives.
    c_ev: CompensatedSum,
    g_ev: OVector<f64, M::P>,
    /// The events applied at the last instant, each with its signed guard at the state it
    /// fired from (see [`Scanner::restart_one`]).
    fired: Vec<Option<f64>>,
    /// Occurrence indices and next times of the events (the time events' source).
    schedule: Schedule,
    /// User events applied so far.
    nevents: usize,
    /// Of those, the time events (`at`, `every`, `at each`), which never count towards
    /// `max_events`: their number is the model's, T/period or a table's rows.
    scheduled_events: usize,
    diagnostics: Vec<Diagnostic>,
    /// An event read a qp where it was weakly active (a `kink` diagnostic; see `qp.rs`).
    qp_event_kink: bool,
    /// The `grazing` diagnostics of crossings found at a turning point within the guard's
    /// uncertainty on the step just scanned, by event (see `undecided`): reported when the
    /// event is applied, unless its crossing cosine already grazes.
    undecided: Vec<(usize, Diagnostic)>,
    /// The time at which the count of events towards `Options::max_events` passed half its
    /// limit (see [`SolveError::MaxEvents`]).
    flood_half: Option<f64>,
    switch_crossings: usize,
    zeno: Zeno<M>,
    /// The states held at the limit of an accumulation (ascending; empty but during a hold,
    /// see `zeno`): the rows of the flow the integrator and every jump hold at zero.
    held: Vec<usize>,
    /// Set when the run stopped at a Zeno accumulation: (t*, dwell ratio).
    zeno_stop: Option<(f64, f64)>,
    /// Set when an event left the state stuck on its guard (see `stuck_after_reset`).
    stuck: Option<usize>,
    rec: Option<Recorder>,
    /// The run keeps the adjoint's tape: it is the adjoint's primal run.
    tape: bool,
    /// The coefficients of one step's dense polynomial, for the adjoint's tape (empty
    /// without it).
    poly: Vec<OVector<f64, M::N>>,
}

impl<'a, M: HybridModel> Driver<'a, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    fn new(
        model: &'a M,
        p: &'a OVector<f64, M::P>,
        opts: &'a Options,
        t_end: f64,
        tape: bool,
    ) -> Self {
        let (n, np) = (model.nstates(), model.nparams());
        let info = model.info();
        let vn = || OVector::<f64, M::N>::zeros_generic(n, Const::<1>);
        let vp = || OVector::<f64, M::P>::zeros_generic(np, Const::<1>);
        let mut dt_end = vp();
        if opts.t_end.is_none() {
            model.horizon_grad(p, &mut dt_end);
        }
        let nobs = info.nobservables();
        let nev = info.events.len();
        let mut integ = Integrator::new_narrow(model, p, opts);
        integ.set_lazy_dense(true);
        // S and q_θ as wide as the integrator's (zero width in a primal run of a Dyn model).
        let watch = ModeWatch::of_modes(model);
        let y = integ.system().zeros();
        let aug_tmp = integ.system().zeros();
        let sp = if opts.sensitivities { np.value() } else { 0 };
        // The sensitivities' buffers as wide as S (zero width in a primal run of a Dyn model).
        let sw_p = y.s.shape_generic().1;
        Driver {
            model,
            p,
            opts,
            t_end,
            dt_end,
            sens: opts.sensitivities,
            integ,
            y,
            aug_tmp,
            mode: info.initial_mode,
            sw: Switches::new(info.switches),
            sw_next: Switches::new(info.switches),
            sw_undecided: Switches::new(info.switches),
            scanner: Scanner::new(nev, info.switches),
            resolution: resolution::Resolution::new(&watch),
            watch,
            affine_watch: false,
            lines: line::Lines::new(),
            watching: None,
            xs: vn(),
            xe: vn(),
            x_plus: vn(),
            f_minus: vn(),
            f_plus: vn(),
            work: vn(),
            rt: vn(),
            gx: vn(),
            gp: vp(),
            dt: vp(),
            rx: OMatrix::zeros_generic(n, n),
            rp: OMatrix::zeros_generic(n, sw_p),
            s_plus: OMatrix::zeros_generic(n, sw_p),
            dtot: OMatrix::zeros_generic(n, sw_p),
            cx: vn(),
            cp: vp(),
            obs_minus: vec![0.0; nobs],
            obs_plus: vec![0.0; nobs],
            c_ev: CompensatedSum::default(),
            g_ev: OVector::zeros_generic(sw_p, Const::<1>),
            fired: vec![None; nev],
            schedule: Schedule::new(model),
            nevents: 0,
            scheduled_events: 0,
            diagnostics: Vec::new(),
            qp_event_kink: false,
            undecided: Vec::new(),
            flood_half: None,
            switch_crossings: 0,
            zeno: Zeno::new(model, sw_p),
            held: Vec::new(),
            zeno_stop: None,
            stuck: None,
            rec: (opts.record || tape).then(|| {
                Recorder::new(
                    n.value(),
                    sp,
                    opts.record,
                    tape.then_some(opts.max_record_bytes),
                )
            }),
            tape,
            poly: if tape {
                (0..MAX_COEFS).map(|_| vn()).collect()
            } else {
                Vec::new()
            },
        }
    }

    fn event_name(&self, k: usize) -> &str {
        &self.model.info().events[k].name
    }

    fn nonfinite_x(
        &self,
        t: f64,
        x: &OVector<f64, M::N>,
        what: impl FnOnce() -> String,
    ) -> Result<(), SolveError> {
        if x.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(nonfinite(t, what))
        }
    }

    /// Switch bits at (t, x) in `mode` into `self.sw_next`: bit j set iff σ_j > 0; for σ_j = 0
    /// exactly, the bit of `self.sw` is kept (`keep`), or at the start (`keep` false) the sign
    /// of σ̇_j under the other bits decides.
    fn switch_bits(&mut self, t: f64, x_is_plus: bool, keep: bool) {
        let nsw = self.model.info().switches;
        self.sw_next.clear();
        if nsw == 0 {
            return;
        }
        self.sw_undecided.clear();
        let mut undecided = false;
        for j in 0..nsw {
            let x = if x_is_plus { &self.x_plus } else { &self.y.x };
            let s = self.model.switch_value(j, At::new(t, x, self.p));
            if s > 0.0 {
                self.sw_next.set(j, true);
            } else if s == 0.0 {
                if keep {
                    self.sw_next.set(j, self.sw.get(j));
                } else {
                    self.sw_undecided.set(j, true);
                    undecided = true;
                }
            }
        }
        if undecided {
            let x = if x_is_plus {
                self.x_plus.clone()
            } else {
                self.y.x.clone()
            };
            self.model.rhs(
                Point::new(self.mode, &self.sw_next, t, &x, self.p),
                &mut self.work,
            );
            zero_rows(&mut self.work, &self.held);
            for j in 0..nsw {
                if self.sw_undecided.get(j) {
                    let st = self.model.switch_grad(
                        j,
                        At::new(t, &x, self.p),
                        &mut self.gx,
                        &mut self.gp,
                    );
                    if self.gx.dot(&self.work) + st > 0.0 {
                        self.sw_next.set(j, true);
                    }
                    if self.gp.iter().any(|&v| v != 0.0) {
                        self.report_kink_at_start(j, t);
                    }
                }
            }
        }
    }

    /// Signed watched value of function w at (t, x) under bits `sw` (see [`crate::event`]).
    fn signed(
        model: &M,
        p: &OVector<f64, M::P>,
        nev: usize,
        sw: &Switches,
        w: usize,
        t: f64,
        x: &OVector<f64, M::N>,
    ) -> f64 {
        if w < nev {
            model.info().events[w].direction.sign() * model.guard(w, At::new(t, x, p))
        } else {
            let j = w - nev;
            let s = model.switch_value(j, At::new(t, x, p));
            if sw.get(j) {
                -s
            } else {
                s
            }
        }
    }

    /// Restarts the integrator and the scanner at (t, self.y) in the current mode and bits.
    fn restart(&mut self, t: f64) -> Result<(), SolveError> {
        let nev = self.scanner.nevents;
        let watch = &self.watch[self.mode];
        self.affine_watch = watch.affine;
        // (Asked once: the loop below runs at every restart.)
        let (holding, released) = (self.zeno.holding(), self.zeno.released_any());
        // The same mode as at the last restart, outside a hold: the same functions are
        // watched and the segment is again one of lines iff it was (see `begin_lines`).
        let same = self.watching == Some(self.mode) && !holding;
        if !same {
            self.scanner.begin_restart();
        }
        self.watching = (!holding).then_some(self.mode);
        for &w in &watch.list {
            // An event whose accumulation is held at its limit is not watched: its guard
            // stays on zero, where it could only fire again.
            if holding && self.zeno.holds_event(w) {
                continue;
            }
            let v = Self::signed(self.model, self.p, nev, &self.sw, w, t, &self.y.x);
            if v.is_nan() {
                return Err(self.guard_nonfinite(w, t));
            }
            let fired = match (w < nev, released) {
                (false, _) => None,
                (true, false) => self.fired[w],
                (true, true) => self.fired[w].or(self.zeno.released_firing_value(w)),
            };
            self.scanner.restart_one(w, v, fired);
        }
        // Only the events applied at this instant (in `scanner.found`) and those whose
        // holds it released have a firing value.
        for c in &self.scanner.found {
            if c.w < nev {
                self.fired[c.w] = None;
            }
        }
        if released {
            self.zeno.forget_released();
        }
        self.resolution.forget();
        self.undecided.clear();
        self.integ
            .restart_holding(t, &self.y, self.mode, &self.sw, &self.held);
        if let Some(rec) = &mut self.rec {
            rec.open_segment(t);
        }
        if !(same && self.lines.on) {
            self.begin_lines(t);
        }
        Ok(())
    }

    #[cold]
    #[inline(never)]
    fn guard_nonfinite(&self, w: usize, t: f64) -> SolveError {
        let what = match self.scanner.watch(w) {
            Watch::Event(k) => format!("guard of event `{}`", self.event_name(k)),
            Watch::Switch(j) => format!("switching function {j}"),
        };
        SolveError::NonFinite { t, what }
    }

    /// The event loop: step towards T or the next time of a time event, scan the step's
    /// dense output for crossings, truncate at the earliest, apply what fires there (see
    /// [`Driver::fire_at`]; a time event and a state event whose order lies within the state
    /// event's location error are reported first, see `order`), restart, until T or a stop at
    /// an accumulation.
    fn run(&mut self, sink: &mut impl EventSink) -> Result<(), SolveError> {
        let (model, p) = (self.model, self.p);
        model.initial_state(p, &mut self.y.x);
        self.nonfinite_x(0.0, &self.y.x.clone(), || "initial state".into())?;
        if self.sens {
            model.initial_state_jac(p, &mut self.y.s);
        }
        self.switch_bits(0.0, false, false);
        std::mem::swap(&mut self.sw, &mut self.sw_next);
        self.schedule
            .start(model, p, (self.t_end, self.opts.max_periodic_occurrences))?;
        self.restart(0.0)?;
        loop {
            if self.rec.as_ref().is_some_and(Recorder::tape_overflowed) {
                // Adjoint mode hands this run over to forward mode (`Handover::RecordBudget`):
                // its end is never read.
                return Ok(());
            }
            let t = self.integ.t();
            let t_next = self.schedule.next_in_mode(model, p, self.mode, t)?;
            if t_next <= t + time_resolution(t) {
                // The last step landed on a time event (or one is due at the start).
                self.y.copy_from(self.integ.y());
                if let Some(rec) = &mut self.rec {
                    rec.close_segment(t, self.mode, &self.sw);
                }
                self.scanner.found.clear();
                self.check_order(t, false);
                self.fire_at(t, sink)?;
                continue;
            }
            if t >= self.t_end {
                return Ok(());
            }
            let t_stop = self.t_end.min(t_next);
            if self.lines.on && self.line_segment(t_stop, t_next, sink)? {
                continue;
            }
            self.integ.step(t_stop)?;
            // The step's full dense output is needed only to sample guards or to record.
            if self.rec.is_some() || self.watch[self.mode].any {
                self.integ.ensure_dense();
            }
            let (t_first, t_step) = (self.integ.t_prev(), self.integ.t());
            // The step is scanned in pieces short enough for the watched functions (one piece
            // unless a watched function varies faster than the states; see `resolution`).
            let mut t0 = t_first;
            loop {
                let t1 = self.resolved_end(t0, t_step);
                self.scan_piece(t0, t1, t_step)?;
                if self.scanner.found.is_empty() && t1 < t_step {
                    t0 = t1;
                    continue;
                }
                break;
            }
            if self.scanner.found.is_empty() {
                self.record_step(t_first, t_step);
                continue;
            }
            let te = self
                .scanner
                .found
                .iter()
                .map(|c| c.t)
                .fold(f64::INFINITY, f64::min);
            self.record_step(t_first, te);
            self.integ.truncate(te);
            self.y.copy_from(self.integ.y());
            if let Some(rec) = &mut self.rec {
                rec.close_segment(te, self.mode, &self.sw);
            }
            self.check_order(te, true);
            self.fire_at(te, sink)?;
        }
    }

    /// Scans [t0, t1] of the last step (which ends at `t_step`) for crossings into
    /// `scanner.found`: the watched values at the piece's ends and samples from the step's
    /// dense output (its exact end state at `t_step`).
    #[inline]
    fn scan_piece(&mut self, t0: f64, t1: f64, t_step: f64) -> Result<(), SolveError> {
        let (model, p) = (self.model, self.p);
        let nev = self.scanner.nevents;
        let sim_tol = self.simultaneity(t1);
        let linear = self.affine_watch && self.integ.scheme() == Scheme::Exact;
        let sw = &self.sw;
        let integ = &self.integ;
        let xs = &mut self.xs;
        let xe = &mut self.xe;
        let sample = |t: f64, is_end: bool, watched: &[usize], out: &mut [f64]| {
            let x = if is_end && t == t_step {
                &integ.y().x
            } else {
                integ.dense_x(t, xs);
                &*xs
            };
            for &w in watched {
                out[w] = Self::signed(model, p, nev, sw, w, t, x);
            }
        };
        let eval = |w: usize, t: f64| {
            integ.dense_x(t, xe);
            Self::signed(model, p, nev, sw, w, t, xe)
        };
        let res = self.scanner.scan(t0, t1, linear, sample, eval, sim_tol);
        res.map_err(|(w, t)| self.guard_nonfinite(w, t))?;
        if self.scanner.peaked() {
            self.judge_peaks(t1);
        }
        Ok(())
    }

    /// The window within which events at t count as simultaneous: relative to the time
    /// resolution where the events are, never to the horizon (the answer must not depend on
    /// how far T lies beyond them).
    fn simultaneity(&self, t: f64) -> f64 {
        self.opts.simultaneous_tol * t.abs().max(1.0)
    }

    /// Applies everything that fires at t, `self.y` holding x(t⁻): the crossings in
    /// `scanner.found` and the time events armed in the current mode that are due by
    /// t + [`time_resolution`]; user events in declaration order, switch flips only when
    /// no user event fires. Then checks the event budget and restarts: at t, or at t* when
    /// the events accumulate (the hold begins, see `zeno`).
    fn fire_at(&mut self, t: f64, sink: &mut impl EventSink) -> Result<(), SolveError> {
        // A time event joins this instant only if it is due within the resolution of t (a
        // step to it would be too short to take); one a little later fires at its own time.
        let due = t + time_resolution(t);
        let scanned = !self.scanner.found.is_empty();
        let schedule = &self.schedule;
        for &k in schedule.armed_in(self.mode) {
            if schedule.time(k) <= due {
                self.scanner.found.push(Crossing { w: k, t });
            }
        }
        if !scanned && !self.scanner.found.is_empty() {
            self.join_state_events_due(t);
        }
        if self.scanner.found.len() > 1 {
            self.scanner.found.sort_unstable_by_key(|c| c.w);
        }
        let nfound = self.scanner.found.len();
        let (mut user, mut timed) = (0, 0);
        for i in 0..nfound {
            let c = self.scanner.found[i];
            if let Watch::Event(k) = self.scanner.watch(c.w) {
                user += 1;
                timed += usize::from(self.model.info().events[k].is_time_event());
                self.apply_event(k, t, sink)?;
            }
        }
        if user == 0 {
            for i in 0..nfound {
                let c = self.scanner.found[i];
                if let Watch::Switch(j) = self.scanner.watch(c.w) {
                    self.apply_switch(j, t)?;
                }
            }
        }
        if user > 1 {
            self.report_simultaneous(t);
        }
        // Time events never count: their number is the schedule's (a table's rows, T/period),
        // not a flood. Nor does one state event (or switch crossing) per scheduled occurrence:
        // a queue drains once per arrival at most. A flood is many more than that. An instant
        // of time events alone leaves the count as it was and raises the limit, so neither
        // check can newly hold there.
        if user > timed || user == 0 {
            self.check_event_budget(t)?;
        }
        if let Some(verdict) = self.zeno_stop.take() {
            // The constrained states are held at the accumulation's limit from t* on; the
            // others follow their flow.
            let t_star = self.begin_hold(verdict)?;
            return self.restart(t_star);
        }
        if self.zeno.holding() {
            // Whether the events at t left the held states at their limit.
            self.review_holds(t);
        }
        // Seed the first step after the jump with the step size in use before it (the
        // error control still shrinks a seed that is too long): Hairer's start-up
        // heuristic would otherwise spend 3–4 growing steps on every segment.
        let h_seed = self.integ.last_step_size();
        self.restart(t)?;
        // An exact segment takes no seed (one step reaches its stop).
        if self.integ.scheme() != Scheme::Exact {
            self.integ.set_step_size(h_seed);
        }
        Ok(())
    }

    /// The event budget (`Options::max_events`) after an instant at t: the state events and
    /// switch crossings so far against the limit raised by one per scheduled occurrence;
    /// the time at which the count passed half the limit is kept for the error.
    fn check_event_budget(&mut self, t: f64) -> Result<(), SolveError> {
        let total = self.nevents - self.scheduled_events + self.switch_crossings;
        let limit = self.opts.max_events.saturating_add(self.scheduled_events);
        if total > limit / 2 && self.flood_half.is_none() {
            self.flood_half = Some(t);
        }
        if total > limit {
            return Err(SolveError::MaxEvents {
                t,
                count: self.opts.max_events,
                span: t - self.flood_half.unwrap_or(t),
            });
        }
        Ok(())
    }

    /// At an instant of time events only (no crossing scanned), the armed state events whose
    /// guards reach zero within the resolution of t join it, as a time event due that soon
    /// does: a guard x ≥ c with x = t on a step that landed on a time event at t = c ends the
    /// step at v = −1 ulp (the stepper's rounding), and would otherwise fire 2 ulp later as an
    /// instant of its own, not reported as simultaneous and applied after the time event
    /// whatever the declaration order. v and dv/dt are the guard's at the end of the last
    /// step (`Track::start_val`, `Track::slope`).
    fn join_state_events_due(&mut self, t: f64) {
        self.scanner.join_events_due(t, time_resolution(t));
    }

    /// The `kink` diagnostic for switching function j, exactly zero at the start t and moving
    /// with θ (∂σ_j/∂θ ≠ 0): a tie of `min`/`max`, `abs` at zero. C is not differentiable in
    /// θ there: on one side of θ the kink is crossed after t (a jump of S), on the other
    /// before the run; dC/dθ is the one-sided value of the bit σ̇ chose.
    #[cold]
    #[inline(never)]
    fn report_kink_at_start(&mut self, j: usize, t: f64) {
        self.diagnostics.push(Diagnostic {
            kind: DiagnosticKind::Kink,
            t,
            message: format!(
                "switching function {j} (a kink of abs/min/max/sign/if) is exactly zero at t = {t} and \
                 moves with the params: C is not differentiable here, and the gradient is one of its \
                 one-sided values",
                t = Time(t),
            ),
        });
    }

    /// The `simultaneous_events` diagnostic for the user events among the crossings found
    /// at t (applied in declaration order).
    #[cold]
    #[inline(never)]
    fn report_simultaneous(&mut self, t: f64) {
        let names: Vec<String> = self
            .scanner
            .found
            .iter()
            .filter_map(|c| match self.scanner.watch(c.w) {
                Watch::Event(k) => Some(format!("`{}`", self.event_name(k))),
                Watch::Switch(_) => None,
            })
            .collect();
        self.diagnostics.push(Diagnostic {
            kind: DiagnosticKind::SimultaneousEvents,
            t,
            message: format!(
                "events {} fired at the same time; applied in declaration order",
                names.join(", ")
            ),
        });
    }

    /// Records [t0, t1] of the current step when recording.
    fn record_step(&mut self, t0: f64, t1: f64) {
        if let Some(rec) = &mut self.rec {
            rec.record_step(&self.integ, &mut self.aug_tmp, &mut self.poly, t0, t1);
        }
    }
}
