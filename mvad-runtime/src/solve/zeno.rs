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
//! applied twice over the last [`ZENO_SNAPS`] snapshots (the second pass removes a slowly
//! drifting ratio). B and ρ both depend on θ, so the derivative of the limit is the derivative
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
//! ## After the accumulation
//! The limit x* lies on the accumulating guard (x_k⁻ is on it and x_k⁺ − x_k⁻ → 0); it is
//! snapped there, and dx*/dθ onto the guard's tangent, so that no rounding of the
//! extrapolation is integrated over [t*, T]. The state is then held at x* (∂x/∂θ = dx*/dθ,
//! flow zero) and ∫ ℓ(t, x*, θ) dt added with its derivative −ℓ(t*, x*) dt*/dθ +
//! ∫ (ℓ_x dx*/dθ + ℓ_θ) dt, up to T or to the next time event τ ≤ T. That event fires from the
//! held state (f⁻ = 0); if the state it leaves flows straight back through the guard the hold
//! goes on, otherwise the event loop resumes at τ. A cost whose increments per event do not
//! shrink (an event sum whose term does not vanish at the limit) diverges: an error.

use super::Driver;
use crate::error::SolveError;
use crate::model::{At, HybridModel, ModelAlloc, Occurrence, Point};
use crate::reduce::{aitken_iterated_weights, CompensatedSum, GL8};
use crate::sink::EventSink;
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

/// Post-event snapshots kept for the Zeno limit: five, so Aitken's Δ² can be applied twice
/// (per-bounce terms of the form (a + bk)ρᵏ, as derivatives w.r.t. a restitution give,
/// need the second pass).
const ZENO_SNAPS: usize = 5;

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
    /// The run's state is held at the limit of an accumulation (in `Driver::y`): a time
    /// event fired from it sees the held state's flow, zero (f⁻ = 0).
    holding: bool,
    /// Accumulations the run has passed through (its adjoint tape is then not swept).
    passed: usize,
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
            snaps: std::array::from_fn(|_| snap()),
            event: 0,
            holding: false,
            passed: 0,
        }
    }

    /// Whether the state is held at the limit of an accumulation (its flow is zero).
    pub(super) fn holding(&self) -> bool {
        self.holding
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
        self.xe.copy_from(x);
        self.xe.axpy(0.5 * delta, &self.f_plus, 1.0);
        self.xe.axpy(0.5 * delta, &self.work, 1.0);
        let v2 = d * model.guard(k, At::new(t + delta, &self.xe, p));
        v2 > 0.0 && v2 > v_plus
    }

    /// What follows an accumulation of event k's occurrences (`self.zeno_stop` set by the
    /// event just applied): the run's state becomes the limit (see [`Driver::take_limit`]) and
    /// is held there (flow zero, running cost ℓ(t, x*) integrated) until T or the next time
    /// event armed in the mode, whichever comes first. A time event due by T fires from the
    /// held state (f⁻ = 0: S⁺ = R_x S* + R_θ − f⁺t'); if its reset leaves the states the
    /// accumulation constrains ([`Driver::constrained_states`]) as they were and the flow
    /// carries them straight back through k's guard (a sampler that only reads the state)
    /// the hold goes on, S being the total derivative dx⁺/dθ = S⁺ + f⁺t'; otherwise (a kick)
    /// the run resumes from there with the event loop, the Zeno detector starting afresh.
    /// Returns true when the run ends (held to T), false when it resumes at a time event's
    /// time (the integrator restarted there).
    pub(super) fn after_accumulation(
        &mut self,
        sink: &mut impl EventSink,
    ) -> Result<bool, SolveError> {
        let (model, p, t_end) = (self.model, self.p, self.t_end);
        let Some((t_star_geo, ratio)) = self.zeno_stop.take() else {
            return Ok(true);
        };
        let stuck = self.stuck.take();
        let k = stuck.unwrap_or(self.zeno.event);
        let (t_star, dt_star) = self.take_limit(k, stuck.is_some(), t_star_geo)?;
        let constrained = self.constrained_states(k, t_star);
        let frozen = self.frozen_free_states(&constrained, t_star);
        let mut x_held = self.y.x.clone();
        self.zeno.holding = true;
        self.zeno.passed += 1;
        let mut from = t_star;
        let mut d_from = Some(dt_star);
        loop {
            let tau = self.schedule.next_in_mode(model, p, self.mode, from)?;
            let until = tau.min(t_end);
            if until > from {
                self.hold_cost(from, until, d_from.take().as_ref());
            }
            if let Some(rec) = &mut self.rec {
                rec.hold(until, &self.y.x, &self.y.s, self.mode, &self.sw);
            }
            if tau > t_end {
                self.report_accumulation(k, stuck.is_some(), t_star, ratio, None, &frozen);
                return Ok(true);
            }
            // The time events due at τ fire from the held state; fire_at restarts there.
            self.scanner.found.clear();
            if self.fire_at(tau, sink)? {
                return Ok(true);
            }
            let mode = self.mode;
            let armed = model.info().events[k].armed_in(mode);
            // f⁺ (the event may have left it unevaluated when t' = 0).
            model.rhs(
                Point::new(mode, &self.sw, tau, &self.y.x, p),
                &mut self.f_plus,
            );
            // Held on only if the event left the states the accumulation constrains as they
            // were (its limit is theirs) and the flow still carries them through k's guard.
            let kept = (0..constrained.len()).all(|i| !constrained[i] || self.y.x[i] == x_held[i]);
            if !(kept && armed && self.flows_back_through(k, tau, mode, false)) {
                self.report_accumulation(k, stuck.is_some(), t_star, ratio, Some(tau), &frozen);
                self.zeno.holding = false;
                self.zeno.count = 0;
                return Ok(false);
            }
            if self.sens && self.dt.iter().any(|&v| v != 0.0) {
                // Held: x no longer moves with the flow, so its sensitivity is dx⁺/dθ.
                self.y.s.ger(1.0, &self.f_plus, &self.dt, 1.0);
            }
            x_held.copy_from(&self.y.x);
            from = from.max(tau);
        }
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
                        self.event_name(k)
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

    /// Adds the running cost of the held state x_h = `self.y.x` (∂x_h/∂θ = `self.y.s`) on
    /// [a, b] to `self.y.q`, ∫ ℓ(t, x_h, θ) dt by 8-point Gauss–Legendre (exact for ℓ
    /// polynomial in t up to degree 15, and for ℓ independent of t whatever b − a), and its
    /// derivative ∫ (ℓ_x ∂x_h/∂θ + ℓ_θ) dt − ℓ(a, x_h) da/dθ to `self.y.qp` (`da` only for the
    /// accumulation time: where a hold starts at a time event, that event's running-cost
    /// jump (ℓ⁻ − ℓ⁺)t' already carries it).
    fn hold_cost(&mut self, a: f64, b: f64, da: Option<&OVector<f64, M::P>>) {
        let (model, p, sens) = (self.model, self.p, self.sens);
        if !model.info().has_running_cost {
            return;
        }
        if let (true, Some(da)) = (sens, da) {
            let l_a = model.running_cost(&self.sw, At::new(a, &self.y.x, p));
            self.y.qp.axpy(-l_a, da, 1.0);
        }
        let (c0, r0) = (0.5 * (a + b), 0.5 * (b - a));
        let mut sum = CompensatedSum::default();
        for &(xi, wi) in &GL8 {
            let t = c0 + r0 * xi;
            let l = model.running_cost_value_grad(
                &self.sw,
                At::new(t, &self.y.x, p),
                &mut self.cx,
                &mut self.cp,
            );
            sum.add(wi * r0 * l);
            if sens {
                self.y.qp.gemv_tr(wi * r0, &self.y.s, &self.cx, 1.0);
                self.y.qp.axpy(wi * r0, &self.cp, 1.0);
            }
        }
        self.y.q += sum.value();
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

    /// The names of the states outside `constrained` whose flow at (t, `self.y.x`) is not
    /// zero: held with the rest although the accumulation does not hold them, so their values
    /// after t* are those of a frozen state, not of their flow.
    fn frozen_free_states(&mut self, constrained: &[bool], t: f64) -> Vec<String> {
        let (model, p) = (self.model, self.p);
        let info = model.info();
        model.rhs(
            Point::new(self.mode, &self.sw, t, &self.y.x, p),
            &mut self.work,
        );
        (0..constrained.len())
            .filter(|&i| !constrained[i] && self.work[i] != 0.0)
            .map(|i| format!("`{}`", info.states[i]))
            .collect()
    }
}
