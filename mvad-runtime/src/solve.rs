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
//!    `simultaneous_tol · max(T, 1)` of the earliest fire at the same time in declaration
//!    order (a `simultaneous_events` diagnostic). A switch crossing flips its bit with the
//!    identity reset. Then the integrator restarts (no stage is reused across a jump), its
//!    first step seeded with the length of the step that contained the event.
//! 4. At T the final terms (see [`crate::reduce`]).
//!
//! Zeno: after each user event the dwell times are checked for geometric shrinking (the last
//! six ratios below 0.999 and within 5 % of each other). Once established, the run stops when
//! an event grazes (|∇g·f⁻| < max(τ, 1e-3)·|∇g||f⁻|, independent of a user's τ = 0, since
//! ever smaller hops would eventually be lost in rounding) or the estimated remaining time
//! t* − t_k is below 1e-9·max(1, t*), and
//! event time, post-event state, its total derivative, accumulated cost and gradient are
//! extrapolated to the accumulation point t* by Aitken's Δ² (the geometric tail). If T > t*
//! the state is held at its limit x* on [t*, T] (the bouncing ball comes to rest), with
//! ∂x/∂θ = dx*/dθ there, and ∫_{t*}^T ℓ(t, x*, θ) dt is added with its derivative
//! (−ℓ(t*, x*) dt*/dθ + ∫ (ℓ_x dx*/dθ + ℓ_θ) dt + ℓ(T, x*) dT/dθ).

use crate::error::SolveError;
use crate::event::{Scanner, Watch};
use crate::integrate::{AugState, Forward, Integrator};
use crate::model::{HybridModel, ModelAlloc, Switches, MAX_SWITCHES};
use crate::reduce::{aitken_iterated, final_terms, FinalWork, GL8};
use crate::sens;
use crate::solution::{
    Diagnostic, DiagnosticKind, EventRecord, Options, Segment, Solution, Stats, Trajectory,
    TRAJ_NODES,
};
use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector};
use std::time::Instant;

/// Simulates `model` at `params` and returns the cost, dC/dθ and everything the measure needs.
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
    let start = Instant::now();
    validate(model, params, opts)?;
    let t_end = match opts.t_end {
        Some(t) => t,
        None => model.horizon(params).ok_or(SolveError::NoHorizon)?,
    };
    if !(t_end.is_finite() && t_end > 0.0) {
        return Err(SolveError::BadHorizon { t_end });
    }
    let mut d = Driver::new(model, params, opts, t_end);
    d.run()?;
    let mut sol = d.finish()?;
    sol.stats.wall_seconds = start.elapsed().as_secs_f64();
    Ok(sol)
}

fn validate<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
) -> Result<(), SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let info = model.info();
    let np = model.nparams().value();
    if params.len() != np || info.params.len() != np {
        return Err(SolveError::ParamCount {
            expected: np,
            got: params.len(),
        });
    }
    if let Some((index, &value)) = params.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(SolveError::BadParam { index, value });
    }
    let bad = |what: &str| Err(SolveError::BadOption { what: what.into() });
    if !(opts.rtol.is_finite() && opts.rtol > 0.0) {
        return bad("rtol must be finite and positive");
    }
    if !(opts.atol.is_finite() && opts.atol >= 0.0) {
        return bad("atol must be finite and non-negative");
    }
    if !(opts.grazing_tol.is_finite() && opts.grazing_tol >= 0.0) {
        return bad("grazing tolerance must be finite and non-negative");
    }
    if !(opts.simultaneous_tol.is_finite() && opts.simultaneous_tol >= 0.0) {
        return bad("simultaneous-event tolerance must be finite and non-negative");
    }
    if opts.max_steps == 0 {
        return bad("max_steps must be positive");
    }
    let nmodes = info.modes.len();
    let bad_model = |what: String| Err(SolveError::BadModel { what });
    if nmodes == 0 || info.initial_mode >= nmodes {
        return bad_model(format!(
            "initial mode {} of {} modes",
            info.initial_mode, nmodes
        ));
    }
    if info.switches > MAX_SWITCHES {
        return bad_model(format!(
            "{} switching functions (at most {MAX_SWITCHES})",
            info.switches
        ));
    }
    if info.states.len() != model.nstates().value() {
        return bad_model("state names and state dimension disagree".into());
    }
    for ev in &info.events {
        if ev.target.is_some_and(|m| m >= nmodes) || ev.mode.is_some_and(|m| m >= nmodes) {
            return bad_model(format!(
                "event `{}` names a mode that does not exist",
                ev.name
            ));
        }
    }
    Ok(())
}

/// Buffers for the snapshots of one user event, for the Zeno limit.
struct Snapshot<M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    t: f64,
    dt: OVector<f64, M::P>,
    x: OVector<f64, M::N>,
    dx: OMatrix<f64, M::N, M::P>,
    c: f64,
    g: OVector<f64, M::P>,
}

/// How many dwell ratios must agree before a Zeno accumulation is declared.
const ZENO_RATIOS: usize = 6;

/// Dwell ratios at or above this count as periodic, not accumulating.
const ZENO_MAX_RATIO: f64 = 0.999;

/// Cosine below which an event of an established Zeno sequence ends the run.
const ZENO_GRAZE: f64 = 1e-3;

/// Post-event snapshots kept for the Zeno limit: five, so Aitken's Δ² can be applied twice
/// (per-bounce terms of the form (a + bk)ρᵏ, as derivatives w.r.t. a restitution give,
/// need the second pass).
const ZENO_SNAPS: usize = 5;

/// Dwell-time history and the last [`ZENO_SNAPS`] event snapshots.
struct Zeno<M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    times: [f64; ZENO_RATIOS + 2],
    count: usize,
    snaps: [Snapshot<M>; ZENO_SNAPS],
}

impl<M: HybridModel> Zeno<M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    fn new(model: &M) -> Self {
        let (n, p) = (model.nstates(), model.nparams());
        let snap = || Snapshot {
            t: 0.0,
            dt: OVector::zeros_generic(p, Const::<1>),
            x: OVector::zeros_generic(n, Const::<1>),
            dx: OMatrix::zeros_generic(n, p),
            c: 0.0,
            g: OVector::zeros_generic(p, Const::<1>),
        };
        Zeno {
            times: [0.0; ZENO_RATIOS + 2],
            count: 0,
            snaps: std::array::from_fn(|_| snap()),
        }
    }

    /// The snapshot slot for the event being recorded now.
    fn slot(&mut self) -> &mut Snapshot<M> {
        &mut self.snaps[self.count % ZENO_SNAPS]
    }

    /// Registers the time of the event just recorded in `slot()`.
    fn push(&mut self, t: f64) {
        let k = self.times.len();
        self.times[self.count % k] = t;
        self.count += 1;
    }

    /// The common dwell ratio ρ if the last dwell times shrink geometrically.
    fn ratio(&self) -> Option<f64> {
        let k = self.times.len();
        if self.count < k {
            return None;
        }
        let t = |i: usize| self.times[(self.count - k + i) % k];
        let mut ratios = [0.0; ZENO_RATIOS];
        for (i, r) in ratios.iter_mut().enumerate() {
            let d0 = t(i + 1) - t(i);
            let d1 = t(i + 2) - t(i + 1);
            if !(d0 > 0.0 && d1 > 0.0) {
                return None;
            }
            *r = d1 / d0;
        }
        let (lo, hi) = ratios.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &r| {
            (lo.min(r), hi.max(r))
        });
        let mean = ratios.iter().sum::<f64>() / ZENO_RATIOS as f64;
        (hi < ZENO_MAX_RATIO && hi - lo <= 0.05 * mean).then_some(mean)
    }

    /// (t_k, t_k − t_{k−1}) of the last event.
    fn last_dwell(&self) -> (f64, f64) {
        let k = self.times.len();
        let last = self.times[(self.count - 1) % k];
        let prev = self.times[(self.count - 2) % k];
        (last, last - prev)
    }
}

/// Recording of the trajectory (only with `Options::record`).
struct Recorder {
    traj: Trajectory,
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
    sw: Switches,
    scanner: Scanner,
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
    c_ev: f64,
    g_ev: OVector<f64, M::P>,
    fired: Vec<bool>,
    events: Vec<EventRecord>,
    diagnostics: Vec<Diagnostic>,
    switch_crossings: usize,
    zeno: Zeno<M>,
    /// Set when the run stopped at a Zeno accumulation: (t*, dwell ratio).
    zeno_stop: Option<(f64, f64)>,
    /// Set when an event left the state stuck on its guard (see `stuck_after_reset`).
    stuck: Option<usize>,
    rec: Option<Recorder>,
    segment_start: f64,
    segment_first_step: usize,
}

impl<'a, M: HybridModel> Driver<'a, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    fn new(model: &'a M, p: &'a OVector<f64, M::P>, opts: &'a Options, t_end: f64) -> Self {
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
        Driver {
            model,
            p,
            opts,
            t_end,
            dt_end,
            sens: opts.sensitivities,
            integ: {
                let mut it = Integrator::new(model, p, opts);
                it.set_lazy_dense(true);
                it
            },
            y: AugState::zeros(n, np),
            aug_tmp: AugState::zeros(n, np),
            mode: info.initial_mode,
            sw: 0,
            scanner: Scanner::new(nev, info.switches),
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
            rp: OMatrix::zeros_generic(n, np),
            s_plus: OMatrix::zeros_generic(n, np),
            dtot: OMatrix::zeros_generic(n, np),
            cx: vn(),
            cp: vp(),
            obs_minus: vec![0.0; nobs],
            obs_plus: vec![0.0; nobs],
            c_ev: 0.0,
            g_ev: vp(),
            fired: vec![false; nev],
            events: Vec::new(),
            diagnostics: Vec::new(),
            switch_crossings: 0,
            zeno: Zeno::new(model),
            zeno_stop: None,
            stuck: None,
            rec: opts.record.then(|| Recorder {
                traj: Trajectory::new(n.value(), if opts.sensitivities { np.value() } else { 0 }),
            }),
            segment_start: 0.0,
            segment_first_step: 0,
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
            Err(SolveError::NonFinite { t, what: what() })
        }
    }

    /// Switch bits at (t, x) in `mode`: bit j set iff σ_j > 0; for σ_j = 0 exactly, the bit of
    /// `hint` is kept, or at the start (hint = None) the sign of σ̇_j under the other bits.
    fn switch_bits(&mut self, t: f64, x_is_plus: bool, hint: Option<Switches>) -> Switches {
        let nsw = self.model.info().switches;
        let mut bits: Switches = 0;
        let mut undecided: Switches = 0;
        for j in 0..nsw {
            let x = if x_is_plus { &self.x_plus } else { &self.y.x };
            let s = self.model.switch_value(j, t, x, self.p);
            if s > 0.0 {
                bits |= 1 << j;
            } else if s == 0.0 {
                match hint {
                    Some(h) => bits |= h & (1 << j),
                    None => undecided |= 1 << j,
                }
            }
        }
        if undecided != 0 {
            let x = if x_is_plus {
                self.x_plus.clone()
            } else {
                self.y.x.clone()
            };
            self.model
                .rhs(self.mode, bits, t, &x, self.p, &mut self.work);
            for j in 0..nsw {
                if undecided & (1 << j) != 0 {
                    let st = self
                        .model
                        .switch_grad(j, t, &x, self.p, &mut self.gx, &mut self.gp);
                    if self.gx.dot(&self.work) + st > 0.0 {
                        bits |= 1 << j;
                    }
                }
            }
        }
        bits
    }

    /// Signed watched value of function w at (t, x) under bits `sw` (see [`crate::event`]).
    fn signed(
        model: &M,
        p: &OVector<f64, M::P>,
        nev: usize,
        sw: Switches,
        w: usize,
        t: f64,
        x: &OVector<f64, M::N>,
    ) -> f64 {
        if w < nev {
            model.info().events[w].direction.sign() * model.guard(w, t, x, p)
        } else {
            let j = w - nev;
            let s = model.switch_value(j, t, x, p);
            if sw & (1 << j) != 0 {
                -s
            } else {
                s
            }
        }
    }

    /// Restarts the integrator and the scanner at (t, self.y) in the current mode and bits.
    fn restart(&mut self, t: f64) -> Result<(), SolveError> {
        let info = self.model.info();
        let nev = info.events.len();
        for w in 0..self.scanner.len() {
            let active = w >= nev || info.events[w].armed_in(self.mode);
            let v = if active {
                Self::signed(self.model, self.p, nev, self.sw, w, t, &self.y.x)
            } else {
                0.0
            };
            if v.is_nan() {
                return Err(self.guard_nonfinite(w, t));
            }
            let fired = w < nev && self.fired[w];
            self.scanner.restart_one(w, active, v, fired);
        }
        self.fired.fill(false);
        self.integ.restart(t, &self.y, self.mode, self.sw);
        self.segment_start = t;
        if let Some(rec) = &self.rec {
            self.segment_first_step = rec.traj.len();
        }
        Ok(())
    }

    fn guard_nonfinite(&self, w: usize, t: f64) -> SolveError {
        let what = match self.scanner.watch(w) {
            Watch::Event(k) => format!("guard of event `{}`", self.event_name(k)),
            Watch::Switch(j) => format!("switching function {j}"),
        };
        SolveError::NonFinite { t, what }
    }

    /// Records [t0, t1] of the current step from the dense output (before truncation).
    fn record_step(&mut self, t0: f64, t1: f64) {
        let Some(rec) = &mut self.rec else {
            return;
        };
        if t1 <= t0 {
            return;
        }
        let traj = &mut rec.traj;
        traj.t0.push(t0);
        traj.t1.push(t1);
        for i in 0..TRAJ_NODES {
            let t = t0 + (t1 - t0) * i as f64 / (TRAJ_NODES - 1) as f64;
            self.integ.dense(t, &mut self.aug_tmp);
            traj.data.extend_from_slice(self.aug_tmp.x.as_slice());
            if traj.p > 0 {
                traj.data.extend_from_slice(self.aug_tmp.s.as_slice());
            }
        }
    }

    fn close_segment(&mut self, t: f64) {
        let (mode, sw, start, first) = (
            self.mode,
            self.sw,
            self.segment_start,
            self.segment_first_step,
        );
        if let Some(rec) = &mut self.rec {
            let end_step = rec.traj.len();
            if end_step > first {
                rec.traj.segments.push(Segment {
                    t_start: start,
                    t_end: t,
                    mode,
                    switches: sw,
                    first_step: first,
                    end_step,
                });
            }
        }
    }

    fn run(&mut self) -> Result<(), SolveError> {
        let (model, p) = (self.model, self.p);
        let info = model.info();
        model.initial_state(p, &mut self.y.x);
        self.nonfinite_x(0.0, &self.y.x.clone(), || "initial state".into())?;
        if self.sens {
            model.initial_state_jac(p, &mut self.y.s);
        }
        self.sw = self.switch_bits(0.0, false, None);
        self.restart(0.0)?;
        let nev = info.events.len();
        while self.integ.t() < self.t_end {
            self.integ.step(self.t_end)?;
            // Simultaneity is judged relative to the time resolution where the events are,
            // never to the horizon: the answer must not depend on how far T lies beyond them.
            let sim_tol = self.opts.simultaneous_tol * self.integ.t().abs().max(1.0);
            // The step's full dense output is needed only to sample guards or to record.
            if self.rec.is_some() || self.scanner.active.iter().any(|&a| a) {
                self.integ.ensure_dense();
            }
            let (t0, t1) = (self.integ.t_prev(), self.integ.t());
            let sw = self.sw;
            {
                let integ = &self.integ;
                let xs = &mut self.xs;
                let xe = &mut self.xe;
                let sample = |t: f64, is_end: bool, active: &[bool], out: &mut [f64]| {
                    if is_end {
                        xs.copy_from(&integ.y().x);
                    } else {
                        integ.dense_x(t, xs);
                    }
                    for (w, o) in out.iter_mut().enumerate() {
                        if active[w] {
                            *o = Self::signed(model, p, nev, sw, w, t, xs);
                        }
                    }
                };
                let eval = |w: usize, t: f64| {
                    integ.dense_x(t, xe);
                    Self::signed(model, p, nev, sw, w, t, xe)
                };
                let res = self.scanner.scan(t0, t1, sample, eval, sim_tol);
                if let Err((w, t)) = res {
                    return Err(self.guard_nonfinite(w, t));
                }
            }
            if self.scanner.found.is_empty() {
                self.record_step(t0, t1);
                continue;
            }
            let te = self
                .scanner
                .found
                .iter()
                .map(|c| c.t)
                .fold(f64::INFINITY, f64::min);
            self.record_step(t0, te);
            self.integ.truncate(te);
            self.y.copy_from(self.integ.y());
            self.close_segment(te);
            let nfound = self.scanner.found.len();
            let mut user = 0;
            let mut stop = false;
            for i in 0..nfound {
                let c = self.scanner.found[i];
                if let Watch::Event(k) = self.scanner.watch(c.w) {
                    user += 1;
                    stop |= self.apply_event(k, te)?;
                }
            }
            if user == 0 {
                for i in 0..nfound {
                    let c = self.scanner.found[i];
                    if let Watch::Switch(j) = self.scanner.watch(c.w) {
                        self.apply_switch(j, te)?;
                    }
                }
            }
            if user > 1 {
                let names: Vec<&str> = (0..nfound)
                    .filter_map(|i| match self.scanner.watch(self.scanner.found[i].w) {
                        Watch::Event(k) => Some(self.event_name(k)),
                        Watch::Switch(_) => None,
                    })
                    .collect();
                let message = format!(
                    "events {} fired at the same time; applied in declaration order",
                    names
                        .iter()
                        .map(|n| format!("`{n}`"))
                        .collect::<Vec<_>>()
                        .join(", ")
                );
                self.diagnostics.push(Diagnostic {
                    kind: DiagnosticKind::SimultaneousEvents,
                    t: te,
                    message,
                });
            }
            let total = self.events.len() + self.switch_crossings;
            if total > self.opts.max_events {
                return Err(SolveError::MaxEvents {
                    t: te,
                    count: self.opts.max_events,
                });
            }
            if stop {
                return Ok(());
            }
            // Seed the first step after the jump with the step size in use before it (the
            // error control still shrinks a seed that is too long): Hairer's start-up
            // heuristic would otherwise spend 3–4 growing steps on every segment.
            let h_seed = self.integ.last_step_size();
            self.restart(te)?;
            self.integ.set_step_size(h_seed);
        }
        Ok(())
    }

    /// Applies user event k at time t to `self.y` (state at t⁻). Returns true when the run
    /// must stop here because a Zeno accumulation has been reached.
    fn apply_event(&mut self, k: usize, t: f64) -> Result<bool, SolveError> {
        let (model, p) = (self.model, self.p);
        let info = model.info();
        let ev = &info.events[k];
        let sens = self.sens;
        self.nonfinite_x(t, &self.y.x, || "state at event".into())?;
        model.rhs(self.mode, self.sw, t, &self.y.x, p, &mut self.f_minus);
        self.nonfinite_x(t, &self.f_minus, || {
            format!("flow of mode `{}`", info.modes[self.mode])
        })?;
        let gt = model.guard_grad(k, t, &self.y.x, p, &mut self.gx, &mut self.gp);
        if !(gt.is_finite()
            && self.gx.iter().all(|v| v.is_finite())
            && self.gp.iter().all(|v| v.is_finite())
            && model.guard(k, t, &self.y.x, p).is_finite())
        {
            return Err(SolveError::NonFinite {
                t,
                what: format!("guard of event `{}`", ev.name),
            });
        }
        let grazing = sens::is_grazing(&self.gx, &self.f_minus, gt, self.opts.grazing_tol);
        let (slope, denom) = if sens {
            sens::event_time_sensitivity(
                &self.gx,
                &self.gp,
                gt,
                &self.f_minus,
                &self.y.s,
                &mut self.dt,
            )
        } else {
            let s = self.gx.dot(&self.f_minus);
            (s, s + gt)
        };
        if sens && !self.dt.iter().all(|v| v.is_finite()) {
            return Err(SolveError::NonFinite {
                t,
                what: format!(
                    "event-time sensitivity of event `{}` (tangential crossing: ∇g·f + ∂g/∂t = {denom:e})",
                    ev.name
                ),
            });
        }
        model.reset(k, t, &self.y.x, p, &mut self.x_plus);
        self.nonfinite_x(t, &self.x_plus, || format!("reset of event `{}`", ev.name))?;
        let mode_before = self.mode;
        let sw_before = self.sw;
        let mode_after = ev.target.unwrap_or(self.mode);
        self.mode = mode_after;
        let sw_after = self.switch_bits(t, true, Some(sw_before));
        model.rhs(mode_after, sw_after, t, &self.x_plus, p, &mut self.f_plus);
        self.nonfinite_x(t, &self.f_plus, || {
            format!("flow of mode `{}`", info.modes[mode_after])
        })?;
        if sens {
            model.reset_jac(k, t, &self.y.x, p, &mut self.rx, &mut self.rp, &mut self.rt);
            sens::jump(
                &self.rx,
                &self.rp,
                &self.rt,
                &self.y.s,
                &self.f_minus,
                &self.f_plus,
                &self.dt,
                &mut self.work,
                &mut self.s_plus,
            );
            if !self.s_plus.iter().all(|v| v.is_finite()) {
                return Err(SolveError::NonFinite {
                    t,
                    what: format!("sensitivity jump of event `{}`", ev.name),
                });
            }
        }
        let mut l_plus = 0.0;
        if info.has_running_cost {
            let l_minus = model.running_cost(sw_before, t, &self.y.x, p);
            l_plus = model.running_cost(sw_after, t, &self.x_plus, p);
            if !(l_minus.is_finite() && l_plus.is_finite()) {
                return Err(SolveError::NonFinite {
                    t,
                    what: "cost".into(),
                });
            }
            if sens {
                self.y.qp.axpy(l_minus - l_plus, &self.dt, 1.0);
            }
        }
        if sens {
            sens::post_event_total(&self.s_plus, &self.f_plus, &self.dt, &mut self.dtot);
        }
        if ev.has_cost {
            let phi = model.event_cost(k, t, &self.x_plus, p);
            if !phi.is_finite() {
                return Err(SolveError::NonFinite {
                    t,
                    what: format!("cost term of event `{}`", ev.name),
                });
            }
            self.c_ev += phi;
            if sens {
                let phi_t =
                    model.event_cost_grad(k, t, &self.x_plus, p, &mut self.cx, &mut self.cp);
                // φ_x (S⁺ + f⁺ t') + φ_t t' + φ_θ
                self.g_ev.gemv_tr(1.0, &self.dtot, &self.cx, 1.0);
                self.g_ev += &self.cp;
                self.g_ev.axpy(phi_t, &self.dt, 1.0);
            }
        }
        // Jumps and atoms.
        model.observe(t, &self.y.x, p, &mut self.obs_minus);
        model.observe(t, &self.x_plus, p, &mut self.obs_plus);
        let jump_observables: Vec<f64> = self
            .obs_plus
            .iter()
            .zip(&self.obs_minus)
            .map(|(a, b)| a - b)
            .collect();
        let dt_vec: Vec<f64> = if sens {
            self.dt.iter().copied().collect()
        } else {
            Vec::new()
        };
        let atoms = jump_observables
            .iter()
            .map(|j| dt_vec.iter().map(|d| -j * d).collect())
            .collect();
        let index = self.events.len();
        // Zeno bookkeeping (before the state is replaced).
        let zeno_stop = {
            let q = self.y.q;
            let c = q + self.c_ev;
            let snap = self.zeno.slot();
            snap.t = t;
            snap.x.copy_from(&self.x_plus);
            snap.c = c;
            if sens {
                snap.dt.copy_from(&self.dt);
                snap.dx.copy_from(&self.dtot);
                snap.g.copy_from(&self.y.qp);
                snap.g += &self.g_ev;
                snap.g.axpy(l_plus, &self.dt, 1.0);
            }
            self.zeno.push(t);
            match self.zeno.ratio() {
                Some(r) if r > 0.0 => {
                    let (tk, dk) = self.zeno.last_dwell();
                    let t_star = tk + dk * r / (1.0 - r);
                    let remaining = t_star - tk;
                    let zeno_graze =
                        grazing || slope.abs() < ZENO_GRAZE * self.gx.norm() * self.f_minus.norm();
                    if t_star < self.t_end
                        && (zeno_graze || remaining <= 1e-9 * t_star.abs().max(1.0))
                    {
                        Some((t_star, r))
                    } else {
                        None
                    }
                }
                _ => None,
            }
        };
        self.events.push(EventRecord {
            index,
            event: k,
            t,
            mode_before,
            mode_after,
            guard_slope: slope,
            guard_dt: gt,
            transversal: !grazing,
            dt: dt_vec,
            x_before: self.y.x.iter().copied().collect(),
            x_after: self.x_plus.iter().copied().collect(),
            jump_states: self
                .x_plus
                .iter()
                .zip(self.y.x.iter())
                .map(|(a, b)| a - b)
                .collect(),
            jump_observables,
            atoms,
        });
        let graze_scale = self.opts.grazing_tol * self.gx.norm() * self.f_minus.norm();
        let stuck = zeno_stop.is_none()
            && ev.armed_in(mode_after)
            && t < self.t_end
            && self.stuck_after_reset(k, t, mode_after, sw_after, slope + gt, gt);
        if grazing && zeno_stop.is_none() && !stuck {
            self.diagnostics.push(Diagnostic {
                kind: DiagnosticKind::Grazing,
                t,
                message: format!(
                    "event `{}` grazes: |∇g·f| = {:.3e} < {} |∇g| |f| = {:.3e}; t' is ill-conditioned",
                    ev.name,
                    slope.abs(),
                    self.opts.grazing_tol,
                    graze_scale
                ),
            });
        }
        // The new state.
        self.y.x.copy_from(&self.x_plus);
        if sens {
            self.y.s.copy_from(&self.s_plus);
        }
        self.sw = sw_after;
        self.fired[k] = true;
        if let Some(z) = zeno_stop {
            self.zeno_stop = Some(z);
            return Ok(true);
        }
        if stuck {
            self.zeno_stop = Some((t, 0.0));
            self.stuck = Some(k);
            return Ok(true);
        }
        Ok(false)
    }

    /// Whether event k's reset left the state stuck on its guard: the flow approached the
    /// guard (d·ġ⁻ > 0), the reset stopped or reversed that approach to first order
    /// (d·ġ⁺ ≤ 0 at x⁺) and yet a short Heun probe x⁺ + δ/2 (f⁺ + f(x⁺ + δ f⁺)),
    /// δ = 1e-6·max(|t_k|, 1), lands on the firing side of the guard again. Without a crossing the
    /// event cannot fire again and the state would sink through the guard (the bouncing ball
    /// with e = 0, or a Zeno sequence too fine to resolve): events accumulate at t_k, and the
    /// run ends there with the state held at x⁺. `rate_minus` is ∇g·f⁻ + ∂g/∂t.
    fn stuck_after_reset(
        &mut self,
        k: usize,
        t: f64,
        mode: usize,
        sw: Switches,
        rate_minus: f64,
        _gt_minus: f64,
    ) -> bool {
        let (model, p) = (self.model, self.p);
        let d = model.info().events[k].direction.sign();
        if d * rate_minus <= 0.0 {
            return false;
        }
        let gt = model.guard_grad(k, t, &self.x_plus, p, &mut self.gx, &mut self.gp);
        if d * (self.gx.dot(&self.f_plus) + gt) > 0.0 {
            return false;
        }
        // Relative to the event time (the time resolution there), not to the horizon T: the
        // verdict must be the same whether T lies just past t_k or 10⁶ times beyond it.
        let delta = 1e-6 * t.abs().max(1.0);
        let v_plus = d * model.guard(k, t, &self.x_plus, p);
        self.xs.copy_from(&self.x_plus);
        self.xs.axpy(delta, &self.f_plus, 1.0);
        model.rhs(mode, sw, t + delta, &self.xs, p, &mut self.work);
        self.xe.copy_from(&self.x_plus);
        self.xe.axpy(0.5 * delta, &self.f_plus, 1.0);
        self.xe.axpy(0.5 * delta, &self.work, 1.0);
        let v2 = d * model.guard(k, t + delta, &self.xe, p);
        v2 > 0.0 && v2 > v_plus
    }

    /// Flips switch j at time t: identity reset, S⁺ = S⁻ + (f⁻ − f⁺) t', ℓ jump.
    fn apply_switch(&mut self, j: usize, t: f64) -> Result<(), SolveError> {
        let (model, p) = (self.model, self.p);
        let info = model.info();
        let sw_before = self.sw;
        let sw_after = sw_before ^ (1 << j);
        model.rhs(self.mode, sw_before, t, &self.y.x, p, &mut self.f_minus);
        model.rhs(self.mode, sw_after, t, &self.y.x, p, &mut self.f_plus);
        self.nonfinite_x(t, &self.f_plus, || {
            format!("flow of mode `{}`", info.modes[self.mode])
        })?;
        if self.sens {
            let gt = model.switch_grad(j, t, &self.y.x, p, &mut self.gx, &mut self.gp);
            sens::event_time_sensitivity(
                &self.gx,
                &self.gp,
                gt,
                &self.f_minus,
                &self.y.s,
                &mut self.dt,
            );
            if !self.dt.iter().all(|v| v.is_finite()) {
                return Err(SolveError::NonFinite {
                    t,
                    what: format!(
                        "crossing-time sensitivity of switching function {j} (tangential crossing)"
                    ),
                });
            }
            if sens::is_grazing(&self.gx, &self.f_minus, gt, self.opts.grazing_tol) {
                self.diagnostics.push(Diagnostic {
                    kind: DiagnosticKind::Grazing,
                    t,
                    message: format!("switching function {j} is crossed nearly tangentially"),
                });
            }
            sens::switch_jump(
                &mut self.y.s,
                &self.f_minus,
                &self.f_plus,
                &self.dt,
                &mut self.work,
            );
            if info.has_running_cost {
                let l_minus = model.running_cost(sw_before, t, &self.y.x, p);
                let l_plus = model.running_cost(sw_after, t, &self.y.x, p);
                self.y.qp.axpy(l_minus - l_plus, &self.dt, 1.0);
            }
        }
        self.sw = sw_after;
        self.switch_crossings += 1;
        Ok(())
    }

    fn finish(mut self) -> Result<Solution, SolveError> {
        let (model, p) = (self.model, self.p);
        let info = model.info();
        let t_end = self.t_end;
        let sens = self.sens;
        let mut fw = FinalWork::new(model);
        let (mut cost, mut grad);
        let mut x_final = self.integ.y().x.clone();
        let mut s_final = self.integ.y().s.clone();
        if let Some((t_star_geo, ratio)) = self.zeno_stop {
            // The segment up to the last event was closed when it fired.
            let z = &self.zeno;
            let c = z.count;
            let s = |i: usize| &z.snaps[(c + i) % ZENO_SNAPS];
            let last = ZENO_SNAPS - 1;
            let stuck = self.stuck.is_some();
            // Stuck on a guard: the limit is the last post-event state itself.
            let lim = |f: &dyn Fn(&Snapshot<M>) -> f64| {
                if stuck {
                    f(s(last))
                } else {
                    let seq: [f64; ZENO_SNAPS] = std::array::from_fn(|i| f(s(i)));
                    aitken_iterated(&seq)
                }
            };
            let t_star = {
                let a = lim(&|s| s.t);
                if a.is_finite() && a >= s(last).t {
                    a
                } else {
                    t_star_geo
                }
            };
            for i in 0..x_final.len() {
                x_final[i] = lim(&|s| s.x[i]);
            }
            cost = lim(&|s| s.c);
            grad = OVector::<f64, M::P>::zeros_generic(model.nparams(), Const::<1>);
            let mut dt_star = grad.clone();
            if sens {
                for j in 0..grad.len() {
                    grad[j] = lim(&|s| s.g[j]);
                    dt_star[j] = lim(&|s| s.dt[j]);
                }
                for i in 0..s_final.nrows() {
                    for j in 0..s_final.ncols() {
                        s_final[(i, j)] = lim(&|s| s.dx[(i, j)]);
                    }
                }
            }
            // Rest on [t*, T]: ∫ ℓ(t, x*) dt and its derivative.
            if info.has_running_cost && t_end > t_star {
                let l_star = model.running_cost(self.sw, t_star, &x_final, p);
                if sens {
                    grad.axpy(-l_star, &dt_star, 1.0);
                }
                let (c0, r0) = (0.5 * (t_star + t_end), 0.5 * (t_end - t_star));
                for &(xi, wi) in &GL8 {
                    let t = c0 + r0 * xi;
                    let l =
                        model.running_cost_grad(self.sw, t, &x_final, p, &mut fw.cx, &mut fw.cp);
                    cost += wi * r0 * l;
                    if sens {
                        grad.gemv_tr(wi * r0, &s_final, &fw.cx, 1.0);
                        grad.axpy(wi * r0, &fw.cp, 1.0);
                    }
                }
            }
            let zero = OVector::<f64, M::N>::zeros_generic(model.nstates(), Const::<1>);
            let phi = final_terms(
                model,
                p,
                self.sw,
                t_end,
                &x_final,
                &s_final,
                &zero,
                &self.dt_end,
                &mut fw,
                sens.then_some(&mut grad),
            );
            cost += phi;
            let n = self.events.len();
            let message = if let Some(k) = self.stuck {
                format!(
                    "after event `{}` at t = {t_star} the flow carries the state straight back through \
                     its guard: events accumulate there; the run ended at that time and the state \
                     is held at rest on [t, T]",
                    info.events[k].name
                )
            } else {
                format!(
                    "events accumulate (dwell-time ratio {ratio:.4} over the last {ZENO_RATIOS} dwells): \
                     the run ended at the estimated accumulation time t* = {t_star} after {n} events; \
                     the tail was extrapolated (Aitken) and the state held at its limit on [t*, T]"
                )
            };
            self.diagnostics.push(Diagnostic {
                kind: DiagnosticKind::Zeno,
                t: t_star,
                message,
            });
            if let Some(rec) = &mut self.rec {
                let traj = &mut rec.traj;
                let t0 = traj.t1.last().copied().unwrap_or(0.0);
                if t_end > t0 {
                    traj.t0.push(t0);
                    traj.t1.push(t_end);
                    let first = traj.len() - 1;
                    for _ in 0..TRAJ_NODES {
                        traj.data.extend_from_slice(x_final.as_slice());
                        if traj.p > 0 {
                            traj.data.extend_from_slice(s_final.as_slice());
                        }
                    }
                    traj.segments.push(Segment {
                        t_start: t0,
                        t_end,
                        mode: self.mode,
                        switches: self.sw,
                        first_step: first,
                        end_step: first + 1,
                    });
                }
            }
        } else {
            self.close_segment(t_end);
            let y = self.integ.y();
            cost = y.q + self.c_ev;
            grad = y.qp.clone() + &self.g_ev;
            model.rhs(self.mode, self.sw, t_end, &y.x, p, &mut fw.f);
            let f_end = fw.f.clone();
            let phi = final_terms(
                model,
                p,
                self.sw,
                t_end,
                &y.x,
                &y.s,
                &f_end,
                &self.dt_end,
                &mut fw,
                sens.then_some(&mut grad),
            );
            cost += phi;
        }
        if !cost.is_finite() || (sens && !grad.iter().all(|v| v.is_finite())) {
            return Err(SolveError::NonFinite {
                t: t_end,
                what: "cost".into(),
            });
        }
        let mut stats: Stats = self.integ.stats().clone();
        stats.events = self.events.len();
        stats.switch_crossings = self.switch_crossings;
        Ok(Solution {
            t_end,
            params: p.iter().copied().collect(),
            cost,
            gradient: if sens {
                grad.iter().copied().collect()
            } else {
                Vec::new()
            },
            x_final: x_final.iter().copied().collect(),
            s_final: if sens {
                s_final.iter().copied().collect()
            } else {
                Vec::new()
            },
            mode_final: self.mode,
            events: self.events,
            diagnostics: self.diagnostics,
            stats,
            trajectory: self.rec.map(|r| r.traj),
        })
    }
}
