//! Accumulating events: detecting a Zeno sequence, a reset that leaves the state stuck on
//! its guard, and the limit the run is continued with.
//!
//! After each user event the dwell times are checked for geometric shrinking (the last
//! [`ZENO_RATIOS`] ratios below [`ZENO_MAX_RATIO`] and within 5 % of each other). Once
//! established, the run stops when an event grazes (its crossing cosine
//! |dg/dt| / (|∇g||f⁻| + |∂g/∂t|) is below max(τ, [`ZENO_GRAZE`]),
//! independent of a user's τ = 0, since ever smaller hops would eventually be lost in
//! rounding) or the estimated remaining time t* − t_k is below 1e-9·max(1, t*).
//!
//! ## The tail as a geometric series, and its derivative
//! A quantity a_k read after event k (the event time t_k, the post-event state x_k⁺, the cost
//! accumulated so far C_k) changes by a_k − a_{k−1} = B ρ_aᵏ per event in a geometric tail
//! (for the bouncing ball with restitution e: t_k and v_k⁺ with ρ = e, C_k = Σ ∫h over bounces
//! with ρ = e³). Its limit is the sum of the series,
//!
//! ```text
//!   a_∞ = a_k + (a_k − a_{k−1}) (ρ + ρ² + …) = a_k + (a_k − a_{k−1}) ρ/(1 − ρ),
//!   ρ = (a_k − a_{k−1}) / (a_{k−1} − a_{k−2})                        (Aitken's Δ²),
//! ```
//!
//! applied three times over the last [`ZENO_SNAPS`] snapshots (the later passes remove a
//! slowly drifting ratio and the faster rates ρ², ρ³, … of a quantity that is smooth in t
//! near t*: t_k − t* ∝ ρᵏ, so ∫x dt of a state the accumulation does not constrain has
//! terms in ρᵏ and ρ²ᵏ). B and ρ both depend on θ, so the derivative of the limit is the derivative
//! of this sum, by the chain rule through it:
//!
//! ```text
//!   da_∞/dθ = Σ_i (∂a_∞/∂a_i) da_i/dθ,
//!   ∂a_∞/∂a_k = 1/(1 − ρ)²,  ∂a_∞/∂a_{k−1} = −2ρ/(1 − ρ)²,  ∂a_∞/∂a_{k−2} = ρ²/(1 − ρ)²,
//! ```
//!
//! with da_i/dθ what the run carries at event i: t_i', d x_i⁺/dθ = S⁺ + f⁺ t_i' and dC_i/dθ.
//! This is exact whenever a_k is exactly geometric; extrapolating the sequence da_k/dθ
//! instead is not, since da_k/dθ − da_∞/dθ = (B' + B k ρ'/ρ) ρᵏ has the factor k (for the
//! ball, d/de of ∫v dt came out −3e-4 instead of 0 that way).
//!
//! ## After the accumulation: the masked flow
//! The limit x* lies on the accumulating guard (x_k⁻ is on it and x_k⁺ − x_k⁻ → 0); it is
//! snapped there, and dx*/dθ onto the guard's tangent, so that no rounding of the
//! extrapolation is integrated over [t*, T]. The states the accumulation constrains (those
//! k's guard reads, those its reset writes, and those their flow reads; see
//! [`Driver::constrained_states`]) are then held at x*: the event loop runs on from t* with
//! the *masked flow*, their rows of f and of f_x S + f_θ zero (the integrator's held rows),
//! while every other state follows its flow, reading the held values, and the running cost
//! is integrated along that like anywhere else. At t*(θ) the run restarts from
//!
//! ```text
//!   x(t*) = x*,   S(t*) = dx*/dθ − f_m(t*, x*) dt*/dθᵀ,   dC/dθ −= ℓ(t*, x*) dt*/dθ,
//! ```
//!
//! f_m the masked flow: the limit's total derivative already contains a free state's own
//! motion over the θ-dependent t*, and the held rows of f_m are zero, so a held state's
//! sensitivity is its total derivative. The accumulating event is not watched while held.
//! Every other event fires as usual, its saltation read with the masked flow on both sides;
//! after an instant of events the hold goes on if they left the constrained states at the
//! limit and the flow still carries them straight back through k's guard (a sampler, an
//! event of a free state); otherwise (a kick) it is released: those rows follow their full
//! flow again (S⁺ −= f⁺ t' on them, their f⁺ in the jump having been masked) and the Zeno
//! detector starts afresh. A cost whose increments per event do not shrink (an event sum
//! whose term does not vanish at the limit) diverges: an error.

use super::Driver;
use crate::error::{SolveError, Time};
use crate::integrate::zero_rows;
use crate::model::{At, HybridModel, ModelAlloc, Occurrence, Point};
use crate::reduce::{aitken_iterated_weights, CompensatedSum};
use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector};

/// How many dwell ratios must agree before a Zeno accumulation is declared.
pub(super) const ZENO_RATIOS: usize = 6;

/// Dwell ratios at or above this count as periodic, not accumulating.
const ZENO_MAX_RATIO: f64 = 0.999;

/// Cosine below which an event of an established Zeno sequence ends the run.
const ZENO_GRAZE: f64 = 1e-3;

/// The length of the stuck-state probe, in units of the time resolution (16 ulp of t): a
/// crossing due within it could not be resolved as a new event.
const STUCK_PROBE: f64 = 1e3;

/// Post-event snapshots kept for the Zeno limit: seven, so Aitken's Δ² can be applied
/// three times (per-bounce terms of the form (a + bk)ρᵏ, as derivatives w.r.t. a
/// restitution give, need a second pass; a cost smooth in t near t* has terms ρᵏ and ρ²ᵏ:
/// ∫x dt of the sliding ball, x = vx t, came out with dC/de = 9.5e-6 for 0 after two
/// passes, 2.5e-8 after three). The detector's [`ZENO_RATIOS`] + 2 event times are at
/// least as many.
const ZENO_SNAPS: usize = 7;

/// Buffers for the snapshots of one user event, for the Zeno limit.
pub(super) struct Snapshot<M: HybridModel>
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

/// Dwell-time history and the last [`ZENO_SNAPS`] event snapshots.
pub(super) struct Zeno<M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    times: [f64; ZENO_RATIOS + 2],
    count: usize,
    snaps: [Snapshot<M>; ZENO_SNAPS],
    /// The state event whose occurrences are being recorded (the last one).
    event: usize,
    /// The accumulations whose constrained states are held at their limits now (the union of
    /// their constrained states are the run's held rows).
    holds: Vec<Hold<M>>,
    /// The events whose holds ended at the instant just applied (until the restart there).
    released: Vec<usize>,
    /// Accumulations the run has passed through (its adjoint tape is then not swept).
    passed: usize,
}

/// One accumulation held at its limit.
pub(super) struct Hold<M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// The accumulating event.
    pub(super) event: usize,
    /// It accumulated at one instant (a reset left the state stuck on its guard).
    pub(super) stuck: bool,
    /// The accumulation time and the dwell-time ratio (0 when stuck).
    pub(super) t_star: f64,
    pub(super) ratio: f64,
    /// User events applied up to t*.
    pub(super) events: usize,
    /// The states it constrains (see [`Driver::constrained_states`]).
    pub(super) constrained: Vec<bool>,
    /// The state at the limit (the constrained entries are held at theirs).
    x_limit: OVector<f64, M::N>,
}

impl<M: HybridModel> Zeno<M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// Snapshots for `model` whose derivatives are `p` wide (0 without sensitivities, which
    /// then are never recorded).
    pub(super) fn new(model: &M, p: M::P) -> Self {
        let n = model.nstates();
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
            // Written out (not `array::from_fn`, whose temporary array the optimiser may copy
            // into place: a kilobyte per run).
            snaps: [snap(), snap(), snap(), snap(), snap(), snap(), snap()],
            event: 0,
            holds: Vec::new(),
            released: Vec::new(),
            passed: 0,
        }
    }

    /// Whether some states are held at the limit of an accumulation.
    pub(super) fn holding(&self) -> bool {
        !self.holds.is_empty()
    }

    /// Whether event w's accumulation is held at its limit (then it is not watched).
    #[inline]
    pub(super) fn holds_event(&self, w: usize) -> bool {
        self.holds.iter().any(|h| h.event == w)
    }

    /// The firing value event w restarts with if its hold ended at this instant: it sits on
    /// its guard as if it had just fired from there, so it is disarmed until its guard has
    /// been below zero (the state moving off the guard), as after any firing. `None` for any
    /// other event.
    #[inline]
    pub(super) fn released_firing_value(&self, w: usize) -> Option<f64> {
        self.released.contains(&w).then_some(0.0)
    }

    /// Whether some hold ended at the instant just applied.
    #[inline]
    pub(super) fn released_any(&self) -> bool {
        !self.released.is_empty()
    }

    /// The restart after the holds released at an instant has been made.
    pub(super) fn forget_released(&mut self) {
        self.released.clear();
    }

    /// Ends the holds (at T): they are returned for their diagnostics.
    pub(super) fn take_holds(&mut self) -> Vec<Hold<M>> {
        std::mem::take(&mut self.holds)
    }

    /// Whether the run passed through an accumulation (it did not reach T by its flow and
    /// events alone: the adjoint hands such a run to forward mode).
    pub(super) fn passed(&self) -> bool {
        self.passed > 0
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
        // The newest ratio first: one that is not below ZENO_MAX_RATIO (or a dwell that is
        // not positive) decides alone, as it would at the end of the loop.
        let (d0, d1) = (t(k - 2) - t(k - 3), t(k - 1) - t(k - 2));
        if !(d0 > 0.0 && d1 > 0.0 && d1 / d0 < ZENO_MAX_RATIO) {
            return None;
        }
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

    /// The limit of a snapshot quantity and its weights w over the snapshots (oldest first):
    /// iterated Aitken Δ² over the last [`ZENO_SNAPS`] snapshots with w_i = ∂limit/∂value_i
    /// ([`aitken_iterated_weights`]), or the last snapshot itself (w = (0, …, 0, 1)) when
    /// `hold_last` (a state stuck on its guard).
    fn limit(&self, hold_last: bool, f: impl Fn(&Snapshot<M>) -> f64) -> (f64, [f64; ZENO_SNAPS]) {
        let mut w = [0.0; ZENO_SNAPS];
        if hold_last {
            w[ZENO_SNAPS - 1] = 1.0;
            return (f(self.snap(ZENO_SNAPS - 1)), w);
        }
        let seq: [f64; ZENO_SNAPS] = std::array::from_fn(|i| f(self.snap(i)));
        let (lim, wv) = aitken_iterated_weights(&seq);
        w.copy_from_slice(&wv);
        (lim, w)
    }

    /// The derivative of a limit with weights `w` ([`Zeno::limit`]): Σ_i w_i d_i, with d_i
    /// the derivative the snapshot i carries.
    fn limit_derivative(&self, w: &[f64; ZENO_SNAPS], d: impl Fn(&Snapshot<M>) -> f64) -> f64 {
        (0..ZENO_SNAPS).map(|i| w[i] * d(self.snap(i))).sum()
    }

    /// Whether the cost's increments per event do not shrink: the last two ratios
    /// |ΔC_k / ΔC_{k−1}| are at least [`ZENO_MAX_RATIO`] and the last increment is above
    /// rounding (64ε of the largest |C_i|). In a geometric tail ΔC_k = φ* + Bρᵏ, with φ* the
    /// event cost at the limit state: the sum over the infinitely many events converges iff
    /// φ* = 0, when the ratio tends to ρ < 1; otherwise (Σ 1, Σ t_k) it tends to 1 and C
    /// grows without bound. Returns the last increment then.
    fn cost_diverges(&self) -> Option<f64> {
        let c: [f64; ZENO_SNAPS] = std::array::from_fn(|i| self.snap(i).c);
        let d: [f64; ZENO_SNAPS - 1] = std::array::from_fn(|i| c[i + 1] - c[i]);
        let scale = c.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let last = d[ZENO_SNAPS - 2];
        if last.is_nan() || last.abs() <= 64.0 * f64::EPSILON * scale {
            return None;
        }
        let grows = |i: usize| (d[i + 1] / d[i]).abs() >= ZENO_MAX_RATIO;
        (grows(ZENO_SNAPS - 3) && grows(ZENO_SNAPS - 4)).then_some(last)
    }

    /// Snapshot i of the last [`ZENO_SNAPS`], oldest first.
    fn snap(&self, i: usize) -> &Snapshot<M> {
        &self.snaps[(self.count + i) % ZENO_SNAPS]
    }

    /// The time of the last snapshot.
    fn last_time(&self) -> f64 {
        self.snaps[(self.count + ZENO_SNAPS - 1) % ZENO_SNAPS].t
    }
}

impl<M: HybridModel> Driver<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// Records the post-event snapshot of state event k that fired at t (x⁺, S⁺ + f⁺t', t', C
    /// and dC/dθ so far, including ℓ⁺t' for the running cost the event moves) and decides
    /// whether the run stops accumulating here: `Some((t*, ρ))` once the dwell times shrink
    /// geometrically with ratio ρ, t* < T, and the event grazes or t* − t_k ≤ 1e-9·max(1, t*).
    pub(super) fn zeno_verdict(
        &mut self,
        k: usize,
        t: f64,
        l_plus: f64,
        grazing: bool,
        cosine: f64,
    ) -> Option<(f64, f64)> {
        let c = self.y.q + self.c_ev.value();
        self.zeno.event = k;
        let snap = self.zeno.slot();
        snap.t = t;
        snap.x.copy_from(&self.x_plus);
        snap.c = c;
        if self.sens {
            snap.dt.copy_from(&self.dt);
            snap.dx.copy_from(&self.dtot);
            snap.g.copy_from(&self.y.qp);
            snap.g += &self.g_ev;
            snap.g.axpy(l_plus, &self.dt, 1.0);
        }
        self.zeno.push(t);
        let r = self.zeno.ratio().filter(|&r| r > 0.0)?;
        let (tk, dk) = self.zeno.last_dwell();
        let t_star = tk + dk * r / (1.0 - r);
        let remaining = t_star - tk;
        let zeno_graze = grazing || cosine < ZENO_GRAZE;
        (t_star < self.t_end && (zeno_graze || remaining <= 1e-9 * t_star.abs().max(1.0)))
            .then_some((t_star, r))
    }

    /// Whether event k's reset left the state stuck on its guard: the flow approached the
    /// guard (d·ġ⁻ > 0), the reset stopped or reversed that approach to first order
    /// (d·ġ⁺ ≤ 0 at x⁺) and yet a short Heun probe (see [`Driver::flows_back_through`])
    /// lands on the firing side of the guard again. Without a crossing the event cannot fire
    /// again and the state would sink through the guard (the bouncing ball with e = 0, or a
    /// Zeno sequence too fine to resolve): events accumulate at t_k, and the run ends there
    /// with the state held at x⁺. `rate_minus` is ∇g·f⁻ + ∂g/∂t.
    pub(super) fn stuck_after_reset(
        &mut self,
        k: usize,
        t: f64,
        mode: usize,
        rate_minus: f64,
    ) -> bool {
        let (model, p) = (self.model, self.p);
        let d = model.info().events[k].direction.sign();
        if d * rate_minus <= 0.0 {
            return false;
        }
        let gt = model.guard_grad(k, At::new(t, &self.x_plus, p), &mut self.gx, &mut self.gp);
        if d * (self.gx.dot(&self.f_plus) + gt) > 0.0 {
            return false;
        }
        self.flows_back_through(k, t, mode, true)
    }

    /// The Heun probe of the state x (x⁺ when `at_plus`, under the bits `sw_next`; else
    /// `self.y.x` under `sw`) whose flow f is in `self.f_plus`: x + δ/2 (f + f(x + δ f)),
    /// δ = [`STUCK_PROBE`] times the resolution of t, lands on the firing side of event k's
    /// guard, further in than x itself: the flow would carry the state back through the guard
    /// sooner than the event loop can resolve a new crossing (a reset that leaves the ball on
    /// the floor at rest, v⁺ = 0, or at a speed within rounding of it). δ is relative to t,
    /// not to the horizon T (the verdict must be the same whether T lies just past t or 10⁶
    /// times beyond it), and short: a bounce that flies for longer than δ is simulated and
    /// left to the Zeno test (1e-6·t, as before, called a flight of 0.5 stuck at t = 10⁶).
    fn flows_back_through(&mut self, k: usize, t: f64, mode: usize, at_plus: bool) -> bool {
        let (model, p) = (self.model, self.p);
        let d = model.info().events[k].direction.sign();
        let (x, sw) = if at_plus {
            (&self.x_plus, &self.sw_next)
        } else {
            (&self.y.x, &self.sw)
        };
        let delta = STUCK_PROBE * super::time_resolution(t);
        let v_plus = d * model.guard(k, At::new(t, x, p));
        self.xs.copy_from(x);
        self.xs.axpy(delta, &self.f_plus, 1.0);
        model.rhs(Point::new(mode, sw, t + delta, &self.xs, p), &mut self.work);
        if !self.zeno.holds_event(k) {
            // Another event during a hold: the states held stay so.
            zero_rows(&mut self.work, &self.held);
        }
        self.xe.copy_from(x);
        self.xe.axpy(0.5 * delta, &self.f_plus, 1.0);
        self.xe.axpy(0.5 * delta, &self.work, 1.0);
        let v2 = d * model.guard(k, At::new(t + delta, &self.xe, p));
        v2 > 0.0 && v2 > v_plus
    }

    /// The start of the hold after an accumulation of event k's occurrences (`verdict` =
    /// (t*, ρ) from the event just applied): the run's state becomes the limit (see
    /// [`Driver::take_limit`]), the states the accumulation constrains
    /// ([`Driver::constrained_states`]) join the held rows, and S and q_θ restart at t* as
    /// the module doc says (S(t*) = dx*/dθ − f_m dt*/dθᵀ, q_θ −= ℓ dt*/dθ). Returns the time
    /// the run restarts at: t* (not beyond T).
    pub(super) fn begin_hold(&mut self, verdict: (f64, f64)) -> Result<f64, SolveError> {
        let (model, p) = (self.model, self.p);
        let (t_star_geo, ratio) = verdict;
        let stuck = self.stuck.take();
        let k = stuck.unwrap_or(self.zeno.event);
        let (t_star, dt_star) = self.take_limit(k, stuck.is_some(), t_star_geo)?;
        let constrained = self.constrained_states(k, t_star);
        if let Some(rec) = &mut self.rec {
            // The unresolved tail [t_k, t*] of the accumulation, as the limit.
            rec.bridge(t_star, &self.y.x, &self.y.s);
        }
        self.zeno.holds.push(Hold {
            event: k,
            stuck: stuck.is_some(),
            t_star,
            ratio,
            events: self.nevents,
            constrained,
            x_limit: self.y.x.clone(),
        });
        self.zeno.passed += 1;
        // The detector starts afresh: the events of the free states may accumulate in turn.
        self.zeno.count = 0;
        self.fired[k] = None;
        self.collect_held_rows();
        // The masked flow and the running cost at the limit.
        let at = Point::new(self.mode, &self.sw, t_star, &self.y.x, p);
        model.rhs(at, &mut self.work);
        zero_rows(&mut self.work, &self.held);
        self.nonfinite_x(t_star, &self.work, || {
            format!("flow of mode `{}`", model.info().modes[self.mode])
        })?;
        let l = if model.info().has_running_cost {
            model.running_cost(&self.sw, At::new(t_star, &self.y.x, p))
        } else {
            0.0
        };
        if !l.is_finite() {
            return Err(SolveError::NonFinite {
                t: t_star,
                what: "cost".into(),
            });
        }
        if self.sens {
            self.y.s.ger(-1.0, &self.work, &dt_star, 1.0);
            self.y.qp.axpy(-l, &dt_star, 1.0);
        }
        if let Some(ge) = self.integ.global_error_mut() {
            model.guard_grad(k, At::new(t_star, &self.y.x, p), &mut self.gx, &mut self.gp);
            ge.onto_guard(&self.work, l, &self.gx, self.sens);
        }
        Ok(t_star.min(self.t_end))
    }

    /// After the events at t during a hold: every accumulation whose constrained states the
    /// events moved off the limit, whose event is no longer armed in the mode, or from which
    /// the flow no longer carries the state straight back through its guard (see
    /// [`Driver::flows_back_through`]) is released (its `zeno` diagnostic reported). The
    /// rows it held follow their full flow from t on: their f⁺ in the jump was the masked
    /// flow's, zero, so S⁺ −= f⁺ t' on them (t' of the last event at t). With no hold left the
    /// Zeno detector starts afresh.
    pub(super) fn review_holds(&mut self, t: f64) {
        let (model, p, mode) = (self.model, self.p, self.mode);
        // The full flow at the state the events left (what a released state follows).
        model.rhs(
            Point::new(mode, &self.sw, t, &self.y.x, p),
            &mut self.f_plus,
        );
        let mut i = 0;
        let mut released = false;
        while i < self.zeno.holds.len() {
            let h = &self.zeno.holds[i];
            let k = h.event;
            let kept =
                (0..h.constrained.len()).all(|j| !h.constrained[j] || self.y.x[j] == h.x_limit[j]);
            let armed = model.info().events[k].armed_in(mode);
            if kept && armed && self.flows_back_through(k, t, mode, false) {
                i += 1;
                continue;
            }
            let h = self.zeno.holds.remove(i);
            self.zeno.released.push(h.event);
            self.report_accumulation(&h, Some(t));
            released = true;
        }
        if !released {
            return;
        }
        let before = std::mem::take(&mut self.held);
        self.collect_held_rows();
        if self.sens {
            for &r in before.iter().filter(|r| !self.held.contains(r)) {
                for j in 0..self.y.s.ncols() {
                    self.y.s[(r, j)] -= self.f_plus[r] * self.dt[j];
                }
            }
        }
        if !self.zeno.holding() {
            self.zeno.count = 0;
        }
    }

    /// The run's held rows: the union of the states the accumulations held now constrain.
    fn collect_held_rows(&mut self) {
        self.held.clear();
        let n = self.y.x.len();
        let holds = &self.zeno.holds;
        self.held
            .extend((0..n).filter(|&i| holds.iter().any(|h| h.constrained[i])));
    }

    /// Replaces the run's state by the limit of the accumulation of event k:
    /// `self.y.x` = x*, `y.s` = dx*/dθ, `y.q` = C(t*) (running cost and event costs, whose sums
    /// are emptied into it), `y.qp` = dC(t*)/dθ, extrapolated from the snapshots (or the last
    /// snapshot itself when `hold_last`: a state stuck on its guard). The limit lies on k's
    /// guard (x_k⁻ is on it and x_k⁺ − x_k⁻ → 0), so x* is snapped onto it by one Newton step
    /// along ∇g, x* ← x* − ∇g g/|∇g|², and S* onto the tangent of g(t*, x*, θ) = 0,
    /// S* ← S* − ∇g (∇gᵀS* + g_t dt*/dθ + g_θ)/|∇g|²: the rounding left by the extrapolation
    /// (the ball's h* ≈ −2.5e-17) would otherwise be integrated over [t*, T] and grow with T.
    /// Returns (t*, dt*/dθ); `t_star_geo` is the geometric estimate of t*, used when
    /// Aitken's extrapolation of the event times is not usable. A cost whose increments per
    /// event do not shrink (Σ 1, Σ t_k) has no finite limit: a `NonFinite` error at t* naming
    /// the sum.
    fn take_limit(
        &mut self,
        k: usize,
        hold_last: bool,
        t_star_geo: f64,
    ) -> Result<(f64, OVector<f64, M::P>), SolveError> {
        let (model, p, sens) = (self.model, self.p, self.sens);
        let z = &self.zeno;
        let mut dt_star = self.dt.clone();
        dt_star.fill(0.0);
        let (t_lim, wt) = z.limit(hold_last, |s| s.t);
        let t_star = if t_lim.is_finite() && t_lim >= z.last_time() {
            if sens {
                for j in 0..dt_star.len() {
                    dt_star[j] = z.limit_derivative(&wt, |s| s.dt[j]);
                }
            }
            t_lim
        } else {
            if sens {
                dt_star.copy_from(&z.snap(ZENO_SNAPS - 1).dt);
            }
            t_star_geo
        };
        if !hold_last {
            if let Some(last) = z.cost_diverges() {
                return Err(SolveError::NonFinite {
                    t: t_star,
                    what: format!(
                        "cost: the events of `{}` accumulate at t* = {t_star} and the cost grows \
                         by about {last} at each of them, so its sum over their infinitely many \
                         occurrences diverges",
                        self.event_name(k),
                        t_star = Time(t_star),
                    ),
                });
            }
        }
        for i in 0..self.y.x.len() {
            let (xi, wx) = z.limit(hold_last, |s| s.x[i]);
            self.y.x[i] = xi;
            if sens {
                for j in 0..self.y.s.ncols() {
                    self.y.s[(i, j)] = z.limit_derivative(&wx, |s| s.dx[(i, j)]);
                }
            }
        }
        let (cost, wc) = z.limit(hold_last, |s| s.c);
        if sens {
            for j in 0..self.y.qp.len() {
                self.y.qp[j] = z.limit_derivative(&wc, |s| s.g[j]);
            }
        }
        self.y.q = cost;
        self.c_ev = CompensatedSum::default();
        self.g_ev.fill(0.0);
        // Onto the guard g(t*, x*) = 0.
        let at = At::new(t_star, &self.y.x, p);
        let g = model.guard(k, at);
        let gt = model.guard_grad(k, at, &mut self.gx, &mut self.gp);
        let n2 = self.gx.norm_squared();
        if g.is_finite() && n2 > 0.0 && n2.is_finite() {
            self.y.x.axpy(-g / n2, &self.gx, 1.0);
            if sens {
                // r = ∇gᵀS* + g_t dt* + g_θ, S* ← S* − ∇g r / |∇g|².
                let mut r = self.gp.clone();
                r.axpy(gt, &dt_star, 1.0);
                r.gemv_tr(1.0, &self.y.s, &self.gx, 1.0);
                self.y.s.ger(-1.0 / n2, &self.gx, &r, 1.0);
            }
        }
        Ok((t_star, dt_star))
    }

    /// The states the accumulation of event k constrains: those k's guard reads (∇g ≠ 0),
    /// those its reset writes (a row of R_x or R_θ that is not the identity's) and,
    /// transitively, those the flow of a constrained state reads (f_x ≠ 0). Evaluated at the
    /// held limit `self.y.x` (the structure of the Jacobians at one point).
    fn constrained_states(&mut self, k: usize, t: f64) -> Vec<bool> {
        let (model, p) = (self.model, self.p);
        let (n, np) = (model.nstates(), model.nparams());
        let x = &self.y.x;
        model.guard_grad(k, At::new(t, x, p), &mut self.gx, &mut self.gp);
        let mut rx = OMatrix::<f64, M::N, M::N>::zeros_generic(n, n);
        let mut rp = OMatrix::<f64, M::N, M::P>::zeros_generic(n, np);
        let mut rt = OVector::<f64, M::N>::zeros_generic(n, Const::<1>);
        let occ = Occurrence::new(k, self.schedule.occurrence(k));
        model.reset_jac(occ, At::new(t, x, p), &mut rx, &mut rp, &mut rt);
        let mut constrained: Vec<bool> = (0..n.value())
            .map(|i| {
                let written = (0..n.value()).any(|j| rx[(i, j)] != if i == j { 1.0 } else { 0.0 })
                    || rp.row(i).iter().any(|&v| v != 0.0);
                self.gx[i] != 0.0 || written
            })
            .collect();
        let mut fx = OMatrix::<f64, M::N, M::N>::zeros_generic(n, n);
        model.rhs_jac_x(Point::new(self.mode, &self.sw, t, x, p), &mut fx);
        let mut grew = true;
        while grew {
            grew = false;
            for i in 0..n.value() {
                for j in 0..n.value() {
                    if constrained[i] && !constrained[j] && fx[(i, j)] != 0.0 {
                        constrained[j] = true;
                        grew = true;
                    }
                }
            }
        }
        constrained
    }
}
