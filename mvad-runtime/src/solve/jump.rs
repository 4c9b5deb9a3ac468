//! What happens at an event time: a user event (t', reset, new mode and bits, S⁺, the cost
//! terms it moves, the Zeno and stuck-state checks, the event handed to the sink) and a
//! switch crossing of a kink (identity reset, S⁺ = S⁻ + (f⁻ − f⁺) t', ℓ jump).

use super::{time_resolution, Driver};
use crate::adjoint::record::JumpKind;
use crate::error::{SolveError, Time};
use crate::integrate::zero_rows;
use crate::model::{At, HybridModel, ModelAlloc, Occurrence, Point};
use crate::sens;
use crate::sink::{EventSink, EventView};
use crate::solution::{Diagnostic, DiagnosticKind};
use nalgebra::{DefaultAllocator, OMatrix};

/// Step attempts each scheduled occurrence (a table row, a sample of an `every` event, an `at`
/// event) adds to `Options::max_steps`, which is there to stop an explicit method crawling
/// through a stiff segment, not a run over a long schedule.
const STEPS_PER_SCHEDULED_EVENT: usize = 100;

/// A switching function crossed with a cosine |σ̇| / (|∇σ||f⁻| + |∂σ/∂t|) at most this (64 ε)
/// has a rate that is zero within the rounding of its terms: it does not cross zero but stays
/// on it along the flow (σ = x − z/3 with z = 3x, or a qp's data that cancel only to rounding),
/// and its sign changes, one every few steps, are noise. The crossing time is undefined there
/// and t' = −(∇σ·S + ∂σ/∂θ)/σ̇ is rounding divided by rounding: the run stops with an error
/// in either gradient mode (before, forward mode stopped only at σ̇ = 0 exactly, and a run
/// without sensitivities flipped the bit at every sign change until `max_events`, for
/// minutes).
const TANGENT_WITHIN_ROUNDING: f64 = 64.0 * f64::EPSILON;

/// How the trajectory met the guard of the event being applied.
#[derive(Clone, Copy, Debug)]
struct Approach {
    /// The total rate dg/dt = ∇g·f⁻ + ∂g/∂t at t⁻ (the event's `guard_slope`).
    rate: f64,
    /// ∂g/∂t.
    gt: f64,
    /// The crossing's cosine |dg/dt| / (|∇g||f⁻| + |∂g/∂t|) (see [`sens::crossing_cosine`]).
    cosine: f64,
    /// Its scale |∇g||f⁻| + |∂g/∂t|.
    scale: f64,
    /// The cosine is below the grazing tolerance.
    grazing: bool,
    /// The signed guard d·g at the state the event fires from (after the snap onto the
    /// guard; 0 for a time event): below zero when it fired within the simultaneity window
    /// of an earlier crossing (see [`crate::event`] on re-arming).
    signed_guard: f64,
    /// f⁻ (and, by the reset, f⁺) were evaluated. A time event whose time does not move
    /// with θ (t' = 0) skips both when nothing else reads them (no global error estimate
    /// to carry): every term they enter is multiplied by t' = 0. Nothing reads them then:
    /// the saltation's time term and the total derivative S⁺ + f⁺t' are left out of a still
    /// event, and the estimate takes no jump (it is absent or zero, and a still event, or
    /// one without sensitivities, adds no rounding to a zero estimate:
    /// `GlobalError::takes_event_rounding`), so f⁻, f⁺, ∇g = 0 and ∂g/∂θ are not written.
    flows: bool,
    /// With sensitivities, t' = 0 exactly (a time event whose time does not move with θ):
    /// every term multiplied by t' is left out (S⁺ = R_x S⁻ + R_θ, dx⁺/dθ = S⁺).
    still: bool,
}

impl<M: HybridModel> Driver<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// Applies user event k at time t to `self.y` (the state at t⁻) and hands it to `sink`.
    /// Sets `self.zeno_stop` when the run must restart from a limit: a Zeno accumulation has
    /// been reached or the reset left the state stuck on its guard.
    pub(super) fn apply_event(
        &mut self,
        k: usize,
        t: f64,
        sink: &mut impl EventSink,
    ) -> Result<(), SolveError> {
        let info = self.model.info();
        let timed = info.events[k].is_time_event();
        let j = self.schedule.occurrence(k);
        let approach = self.event_approach(k, j, t)?;
        // (τ' is computed in a primal run too: adjoint mode reports it as forward mode does.)
        // At T means within the resolution of t: `every 0.3 from 0.3` with T = 3 has its last
        // occurrence at 2.9999999999999996, which any larger period moves past T.
        let at_an_end = t == 0.0 || self.t_end - t <= time_resolution(self.t_end);
        if timed && at_an_end && self.moves_off_an_end(t) {
            self.report_time_event_at_an_end(k, t);
        }
        if !timed && t == 0.0 && self.guard_moves_at_start() {
            self.report_state_event_at_start(k);
        }
        let mode_before = self.mode;
        self.event_reset(k, j, t, approach.flows)?;
        self.qp_kinks_before_costs(k, j, t);
        let (l_plus, phi_t) = self.event_costs(k, j, t, approach.still)?;
        self.qp_kinks_after_costs(k, j, t);
        self.error_through_event(k, j, t, approach.rate, l_plus, phi_t);
        // Time events neither accumulate nor get stuck: their times are given.
        let zeno_stop = if timed {
            None
        } else {
            self.zeno_verdict(k, t, l_plus, approach.grazing, approach.cosine)
        };
        self.emit_event(k, t, mode_before, approach, sink);
        if timed {
            self.scheduled_events += 1;
            self.integ.extend_step_budget(STEPS_PER_SCHEDULED_EVENT);
        }
        self.schedule.advance(self.model, self.p, k)?;
        let mode_after = self.mode;
        if mode_after != mode_before {
            let modes = (mode_before, mode_after);
            self.schedule.enter_mode(self.model, self.p, modes, t)?;
        }
        let stuck = zeno_stop.is_none()
            && !timed
            && info.events[k].armed_in(mode_after)
            && t < self.t_end
            && self.stuck_after_reset(k, t, mode_after, approach.rate);
        let undecided = self.take_undecided(k);
        if zeno_stop.is_none() && !stuck {
            if approach.grazing {
                self.report_grazing(k, t, approach);
            } else if let Some(d) = undecided {
                self.diagnostics.push(d);
            }
        }
        if let Some(rec) = &mut self.rec {
            let modes = (mode_before, mode_after);
            let (x, xp) = (&self.y.x, &self.x_plus);
            rec.jump(
                JumpKind::Event(k, j),
                t,
                x,
                xp,
                modes,
                &self.sw,
                &self.sw_next,
                self.integ.global_error(),
            );
        }
        // The new state.
        self.y
            .x
            .as_mut_slice()
            .copy_from_slice(self.x_plus.as_slice());
        if self.sens {
            self.y
                .s
                .as_mut_slice()
                .copy_from_slice(self.s_plus.as_slice());
        }
        std::mem::swap(&mut self.sw, &mut self.sw_next);
        self.fired[k] = Some(approach.signed_guard);
        if zeno_stop.is_some() {
            self.zeno_stop = zeno_stop;
        } else if stuck {
            self.zeno_stop = Some((t, 0.0));
            self.stuck = Some(k);
        }
        Ok(())
    }

    /// Whether the time event just approached at t = 0 or t = T (its t' in `self.dt`) moves
    /// relative to that end: t' ≠ 0 at the start, t' ≠ dT/dθ at the horizon (an event at a
    /// horizon that moves with it stays on it).
    fn moves_off_an_end(&self, t: f64) -> bool {
        if t == 0.0 {
            self.dt.iter().any(|&v| v != 0.0)
        } else {
            self.dt.iter().zip(self.dt_end.iter()).any(|(a, b)| a != b)
        }
    }

    /// Whether the guard value g(0, x₀(θ), θ) of the state event just approached at t = 0
    /// (its ∇g and ∂g/∂θ in `gx`, `gp`) moves with θ: ∇g·∂x₀/∂θ + ∂g/∂θ ≠ 0. Only an event
    /// whose guard is exactly on zero at t = 0 fires there (see [`crate::event`]), so this runs
    /// at most once per event and run, and may allocate.
    #[cold]
    #[inline(never)]
    fn guard_moves_at_start(&self) -> bool {
        let (model, p) = (self.model, self.p);
        let mut dx0 = OMatrix::<f64, M::N, M::P>::zeros_generic(model.nstates(), model.nparams());
        model.initial_state_jac(p, &mut dx0);
        let rate = dx0.tr_mul(&self.gx) + &self.gp;
        rate.iter().any(|&v| v != 0.0)
    }

    /// The `kink` diagnostic for state event k firing at t = 0 from a guard exactly on zero
    /// whose value there moves with θ: on one side the run starts past the guard and the event
    /// never fires (a guard is crossed, not found satisfied), so C jumps there and dC/dθ is
    /// its one-sided value (the side on which the event fires).
    #[cold]
    #[inline(never)]
    fn report_state_event_at_start(&mut self, k: usize) {
        self.diagnostics.push(Diagnostic {
            kind: DiagnosticKind::Kink,
            t: 0.0,
            message: format!(
                "event `{}` fires at t = 0 from a guard exactly on zero, and the guard's value \
                 there moves with the params: on one side the run starts past the guard and the \
                 event does not fire, so C is not differentiable here and the gradient is the \
                 one-sided value with the event",
                self.event_name(k),
            ),
        });
    }

    /// The `kink` diagnostic for time event k firing at an end of the run (t = 0 or t = T)
    /// with a time that moves with θ (τ' ≠ 0): on one side of θ it fires at the end, on the
    /// other outside the run (never), so C jumps or kinks there and dC/dθ is its one-sided
    /// value (the side on which the event fires). At T only an event that changes something
    /// (a reset, a cost, a mode) is reported: one that does nothing leaves C as it is.
    #[cold]
    #[inline(never)]
    fn report_time_event_at_an_end(&mut self, k: usize, t: f64) {
        let ev = &self.model.info().events[k];
        let (side, changes) = if t == 0.0 {
            ("before the run", true)
        } else {
            (
                "after the horizon",
                ev.has_reset || ev.has_cost || ev.target.is_some(),
            )
        };
        if !changes {
            return;
        }
        self.diagnostics.push(Diagnostic {
            kind: DiagnosticKind::Kink,
            t,
            message: format!(
                "time event `{}` fires at t = {t}, an end of the run, and its time moves with the \
                 params: on one side it falls {side} and does not fire, so C is not \
                 differentiable here and the gradient is the one-sided value with the event",
                self.event_name(k),
                t = Time(t),
            ),
        });
    }

    /// f⁻, ∇g and ∂g/∂t at (t, x⁻), whether the crossing grazes and, with sensitivities, the
    /// event-time sensitivity t' = −(∇g·S⁻ + ∂g/∂θ)/(∇g·f⁻ + ∂g/∂t) into `self.dt`. A time
    /// event (occurrence j) has g = t − τ_kj(θ): ∇g = 0, ∂g/∂θ = −∂τ/∂θ, ∂g/∂t = 1, so
    /// t' = ∂τ/∂θ by the same formula.
    fn event_approach(&mut self, k: usize, j: usize, t: f64) -> Result<Approach, SolveError> {
        let (model, p) = (self.model, self.p);
        let info = model.info();
        let name = &info.events[k].name;
        self.nonfinite_x(t, &self.y.x, || "state at event".into())?;
        if info.events[k].is_time_event() {
            return self.time_event_approach(k, j, t);
        }
        let gt = model.guard_grad(k, At::new(t, &self.y.x, p), &mut self.gx, &mut self.gp);
        self.flow_before(t)?;
        let g = model.guard(k, At::new(t, &self.y.x, p));
        if !(gt.is_finite()
            && g.is_finite()
            && self.gx.iter().all(|v| v.is_finite())
            && self.gp.iter().all(|v| v.is_finite()))
        {
            return Err(SolveError::NonFinite {
                t,
                what: format!("guard of event `{name}`"),
            });
        }
        let rate = self.gx.dot(&self.f_minus) + gt;
        let scale = self.gx.norm() * self.f_minus.norm() + gt.abs();
        let cosine = sens::cosine_of(rate, scale);
        let grazing = sens::is_grazing_cosine(cosine, self.opts.grazing_tol);
        let g = if grazing {
            g
        } else {
            self.snap_onto_guard(k, t, g, rate)
        };
        let approach = Approach {
            rate,
            gt,
            cosine,
            scale,
            grazing,
            signed_guard: info.events[k].direction.sign() * g,
            flows: true,
            still: false,
        };
        if !self.sens {
            return Ok(approach);
        }
        let (_, denom) = self.crossing_time_sensitivity(gt);
        if !self.dt.iter().all(|v| v.is_finite()) {
            return Err(SolveError::NonFinite {
                t,
                what: format!(
                    "event-time sensitivity of event `{name}` (tangential crossing: ∇g·f + ∂g/∂t = {denom:e})"
                ),
            });
        }
        Ok(approach)
    }

    /// f⁻ = f(t, x⁻) in the current mode and bits into `self.f_minus`, checked finite: the
    /// masked flow during a hold (the held rows zero; see `zeno`).
    pub(super) fn flow_before(&mut self, t: f64) -> Result<(), SolveError> {
        let info = self.model.info();
        self.model.rhs(
            Point::new(self.mode, &self.sw, t, &self.y.x, self.p),
            &mut self.f_minus,
        );
        zero_rows(&mut self.f_minus, &self.held);
        self.nonfinite_x(t, &self.f_minus, || {
            format!("flow of mode `{}`", info.modes[self.mode])
        })
    }

    /// The approach of time event k (occurrence j) at its time t: g = t − τ_kj(θ), so ∇g = 0,
    /// ∂g/∂θ = −∂τ/∂θ, ∂g/∂t = 1, the rate and the cosine are 1 (never grazing unless the
    /// tolerance exceeds 1), g = 0 at the state it fires from, and t' = −(∇g·S⁻ + ∂g/∂θ)/1 =
    /// ∂τ/∂θ, written straight into `self.dt` (`gp` = −t', `gx` = 0 as the error estimate
    /// reads them). f⁻ is evaluated only when something reads it (see
    /// [`Approach::flows`]); when t' = 0 the event is `still`. Without `flows` nothing reads
    /// ∇g, ∂g/∂θ, f⁻ or f⁺ of this event (see [`Approach::flows`]), and none is written.
    fn time_event_approach(&mut self, k: usize, j: usize, t: f64) -> Result<Approach, SolveError> {
        let (model, p) = (self.model, self.p);
        let info = model.info();
        model.event_time_grad(Occurrence::new(k, j), p, &mut self.dt);
        if !self.dt.iter().all(|v| v.is_finite()) {
            return Err(SolveError::NonFinite {
                t,
                what: format!("guard of event `{}`", info.events[k].name),
            });
        }
        let still = !self.dt.iter().any(|&v| v != 0.0);
        let flows = (self.sens && !still)
            || self
                .integ
                .global_error_mut()
                .is_some_and(|ge| !ge.is_zero());
        if flows {
            self.gx.fill(0.0);
            self.gp.copy_from(&self.dt);
            self.gp.neg_mut();
            self.flow_before(t)?;
        }
        let cosine = sens::cosine_of(1.0, 1.0);
        Ok(Approach {
            rate: 1.0,
            gt: 1.0,
            cosine,
            scale: 1.0,
            grazing: sens::is_grazing_cosine(cosine, self.opts.grazing_tol),
            signed_guard: 0.0,
            flows,
            still: self.sens && still,
        })
    }

    /// Moves x⁻ along the flow onto the guard of event k: x⁻ ← x⁻ − f⁻·g/(∇g·f⁻ + ∂g/∂t), one
    /// Newton step of the crossing time applied to the state. The root is located to the
    /// resolution of t (a few ulp of t), so the state there misses the guard by up to
    /// |ġ|·ulp(t), which at t ~ 10⁶ dwarfs ulp(x); the step removes that miss to first order (a
    /// queue that drains ends with w = 0 exactly, as w − (−1)·(w/(−1)) = 0). It is taken only
    /// when it is that small (|g/ġ| ≤ [`super::time_resolution`]), i.e. it never moves the state by more than
    /// the time resolution does, and only when it leaves the state on or past the guard.
    /// `g` is the guard at x⁻ and `rate` = ∇g·f⁻ + ∂g/∂t; returns the guard at x⁻ as left.
    fn snap_onto_guard(&mut self, k: usize, t: f64, g: f64, rate: f64) -> f64 {
        let (model, p) = (self.model, self.p);
        let shift = g / rate;
        if shift == 0.0 || shift.abs() > super::time_resolution(t) {
            return g;
        }
        // Keep the root finder's promise: the state handed to the reset is on or past the
        // guard, never short of it.
        self.xs.copy_from(&self.y.x);
        self.xs.axpy(-shift, &self.f_minus, 1.0);
        let d = model.info().events[k].direction.sign();
        let g_snapped = model.guard(k, At::new(t, &self.xs, p));
        if d * g_snapped >= 0.0 {
            self.y.x.copy_from(&self.xs);
            return g_snapped;
        }
        g
    }

    /// t' = −(∇g·S⁻ + ∂g/∂θ)/(∇g·f⁻ + ∂g/∂t) into `self.dt`, from ∇g and ∂g/∂θ in
    /// `self.gx`, `self.gp`, f⁻ in `self.f_minus` and `gt` = ∂g/∂t (g a guard or a switching
    /// function); returns (∇g·f⁻, ∇g·f⁻ + ∂g/∂t).
    fn crossing_time_sensitivity(&mut self, gt: f64) -> (f64, f64) {
        sens::event_time_sensitivity(
            &self.gx,
            &self.gp,
            gt,
            &self.f_minus,
            &self.y.s,
            &mut self.dt,
        )
    }

    /// x⁺ = R_k(t, x⁻) into `self.x_plus`, the new mode (set) and switch bits (into
    /// `self.sw_next`, bits with σ_j = 0 keep their old value), f⁺ (masked during a hold; not written unless `flows`, see
    /// [`Approach::flows`]) and, with sensitivities, S⁺ by the saltation jump (see
    /// [`sens::jump`]) into `self.s_plus`.
    fn event_reset(&mut self, k: usize, j: usize, t: f64, flows: bool) -> Result<(), SolveError> {
        let (model, p) = (self.model, self.p);
        let info = model.info();
        let ev = &info.events[k];
        model.reset(
            Occurrence::new(k, j),
            At::new(t, &self.y.x, p),
            &mut self.x_plus,
        );
        self.nonfinite_x(t, &self.x_plus, || format!("reset of event `{}`", ev.name))?;
        let mode_after = ev.target.unwrap_or(self.mode);
        self.mode = mode_after;
        self.switch_bits(t, true, true);
        if flows {
            model.rhs(
                Point::new(mode_after, &self.sw_next, t, &self.x_plus, p),
                &mut self.f_plus,
            );
            // During a hold the masked flow (released rows are corrected in `review_holds`).
            zero_rows(&mut self.f_plus, &self.held);
            self.nonfinite_x(t, &self.f_plus, || {
                format!("flow of mode `{}`", info.modes[mode_after])
            })?;
        }
        if self.sens {
            model.reset_jac(
                Occurrence::new(k, j),
                At::new(t, &self.y.x, p),
                &mut self.rx,
                &mut self.rp,
                &mut self.rt,
            );
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
        Ok(())
    }

    /// The cost terms event k moves: the running-cost jump (ℓ⁻ − ℓ⁺)·t' into q_θ, the total
    /// derivative S⁺ + f⁺t' of the post-event state into `self.dtot`, and the event cost φ_k
    /// with dφ_k/dθ = φ_x (S⁺ + f⁺t') + φ_t t' + φ_θ; when the event is `still` (t' = 0,
    /// [`Approach::still`]) that is φ_x S⁺ + φ_θ and `self.dtot` is not written. Returns ℓ⁺
    /// (0 without a running cost) and, when φ_x, φ_θ and φ_t were evaluated (an event cost,
    /// with sensitivities), φ_t, with φ_x left in `self.cx` for the error estimate.
    fn event_costs(
        &mut self,
        k: usize,
        j: usize,
        t: f64,
        still: bool,
    ) -> Result<(f64, Option<f64>), SolveError> {
        let (model, p, sens) = (self.model, self.p, self.sens);
        let info = model.info();
        let mut l_plus = 0.0;
        if info.has_running_cost {
            let l_minus = model.running_cost(&self.sw, At::new(t, &self.y.x, p));
            l_plus = model.running_cost(&self.sw_next, At::new(t, &self.x_plus, p));
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
        if sens && !still {
            sens::post_event_total(&self.s_plus, &self.f_plus, &self.dt, &mut self.dtot);
        }
        let ev = &info.events[k];
        let mut phi_t_out = None;
        if ev.has_cost {
            let phi = model.event_cost(Occurrence::new(k, j), At::new(t, &self.x_plus, p));
            if !phi.is_finite() {
                return Err(SolveError::NonFinite {
                    t,
                    what: format!("cost term of event `{}`", ev.name),
                });
            }
            self.c_ev.add(phi);
            if sens {
                let phi_t = model.event_cost_grad(
                    Occurrence::new(k, j),
                    At::new(t, &self.x_plus, p),
                    &mut self.cx,
                    &mut self.cp,
                );
                // dx⁺/dθ is S⁺ + f⁺t', or S⁺ itself for a still event (t' = 0).
                let total = if still { &self.s_plus } else { &self.dtot };
                self.g_ev.gemv_tr(1.0, total, &self.cx, 1.0);
                self.g_ev += &self.cp;
                if !still {
                    self.g_ev.axpy(phi_t, &self.dt, 1.0);
                }
                phi_t_out = Some(phi_t);
            }
        }
        Ok((l_plus, phi_t_out))
    }

    /// Hands the event to the sink, with the observables on both sides of the jump (nothing is
    /// built for a sink that does not want it).
    fn emit_event(
        &mut self,
        k: usize,
        t: f64,
        mode_before: usize,
        a: Approach,
        sink: &mut impl EventSink,
    ) {
        let (model, p) = (self.model, self.p);
        if !sink.wants_events() {
            self.nevents += 1;
            return;
        }
        model.observe(&self.sw, At::new(t, &self.y.x, p), &mut self.obs_minus);
        model.observe(
            &self.sw_next,
            At::new(t, &self.x_plus, p),
            &mut self.obs_plus,
        );
        sink.event(&EventView {
            index: self.nevents,
            event: k,
            t,
            mode_before,
            mode_after: self.mode,
            guard_slope: a.rate,
            guard_dt: a.gt,
            transversal: !a.grazing,
            dt: if self.sens { self.dt.as_slice() } else { &[] },
            x_before: self.y.x.as_slice(),
            x_after: self.x_plus.as_slice(),
            observables_before: &self.obs_minus,
            observables_after: &self.obs_plus,
        });
        self.nevents += 1;
    }

    fn report_grazing(&mut self, k: usize, t: f64, a: Approach) {
        let message = format!(
            "event `{}` grazes: |dg/dt| = |∇g·f + ∂g/∂t| = {:.3e} < {} (|∇g| |f| + |∂g/∂t|) = {:.3e}; t' is ill-conditioned",
            self.event_name(k),
            a.rate.abs(),
            self.opts.grazing_tol,
            self.opts.grazing_tol * a.scale
        );
        self.diagnostics.push(Diagnostic {
            kind: DiagnosticKind::Grazing,
            t,
            message,
        });
    }

    /// The error for switching function j "crossed" at t with a rate σ̇ = ∇σ·f⁻ + ∂σ/∂t
    /// that is zero within rounding (see [`TANGENT_WITHIN_ROUNDING`]).
    #[cold]
    #[inline(never)]
    fn switch_on_zero(&self, j: usize, t: f64, rate: f64, scale: f64) -> SolveError {
        SolveError::NonFinite {
            t,
            what: format!(
                "crossing-time sensitivity of switching function {j} (a kink of abs/min/max/sign/if \
                 or a qp constraint): its rate ∇σ·f + ∂σ/∂t = {rate:e} is zero within rounding \
                 against its scale {scale:e}, so σ stays on zero along the flow up to rounding and \
                 its sign changes are rounding noise, not crossings (data that cancel only to \
                 rounding; where they cancel exactly the kink is held on zero and reported)"
            ),
        }
    }

    /// Flips switch j at time t: identity reset, S⁺ = S⁻ + (f⁻ − f⁺) t' (the masked flows
    /// during a hold), ℓ jump.
    pub(super) fn apply_switch(&mut self, j: usize, t: f64) -> Result<(), SolveError> {
        let (model, p) = (self.model, self.p);
        let info = model.info();
        self.sw_next.clone_from(&self.sw);
        self.sw_next.flip(j);
        model.rhs(
            Point::new(self.mode, &self.sw, t, &self.y.x, p),
            &mut self.f_minus,
        );
        model.rhs(
            Point::new(self.mode, &self.sw_next, t, &self.y.x, p),
            &mut self.f_plus,
        );
        zero_rows(&mut self.f_minus, &self.held);
        zero_rows(&mut self.f_plus, &self.held);
        self.nonfinite_x(t, &self.f_plus, || {
            format!("flow of mode `{}`", info.modes[self.mode])
        })?;
        let gt = model.switch_grad(j, At::new(t, &self.y.x, p), &mut self.gx, &mut self.gp);
        let rate = self.gx.dot(&self.f_minus) + gt;
        let scale = self.gx.norm() * self.f_minus.norm() + gt.abs();
        let cosine = sens::cosine_of(rate, scale);
        if cosine <= TANGENT_WITHIN_ROUNDING {
            return Err(self.switch_on_zero(j, t, rate, scale));
        }
        if self.sens {
            self.crossing_time_sensitivity(gt);
            if !self.dt.iter().all(|v| v.is_finite()) {
                return Err(SolveError::NonFinite {
                    t,
                    what: format!(
                        "crossing-time sensitivity of switching function {j} (tangential crossing)"
                    ),
                });
            }
            if sens::is_grazing_cosine(cosine, self.opts.grazing_tol) {
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
                let l_minus = model.running_cost(&self.sw, At::new(t, &self.y.x, p));
                let l_plus = model.running_cost(&self.sw_next, At::new(t, &self.y.x, p));
                self.y.qp.axpy(l_minus - l_plus, &self.dt, 1.0);
            }
        }
        self.error_through_switch(j, t);
        if let Some(rec) = &mut self.rec {
            let (x, modes) = (&self.y.x, (self.mode, self.mode));
            let ge = self.integ.global_error();
            rec.jump(
                JumpKind::Switch(j),
                t,
                x,
                x,
                modes,
                &self.sw,
                &self.sw_next,
                ge,
            );
            let dt = if self.sens { self.dt.as_slice() } else { &[] };
            rec.crossing(j, t, x, dt, (&self.sw, &self.sw_next));
        }
        std::mem::swap(&mut self.sw, &mut self.sw_next);
        self.switch_crossings += 1;
        Ok(())
    }
}
