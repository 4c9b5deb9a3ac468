//! The order of a time event and a state event whose crossing lies within its location error
//! of the time event.
//!
//! A state event of a stepped segment is located on the numerical trajectory, which the
//! integrator keeps within about atol + rtol·|xᵢ| of the true one per state, so the guard's
//! value at an instant of the trajectory is known only to
//!
//! ```text
//!   δg = Σᵢ |∂g/∂xᵢ| (atol + rtol |xᵢ|)
//! ```
//!
//! (the spec's δg, the one `undecided` judges turning points by), and the crossing time t_s
//! only to δt = δg/|ġ|, ġ = ∇g·f + ∂g/∂t. A time event fires at its own τ, exactly. When
//! |τ − t_s| ≤ δt the tolerances do not decide which of the two comes first, and C jumps
//! between the two orders by O(1) when their resets do not commute (probe4 finding 4: a
//! doubling and a `+1` 2.7e-13 apart at rtol 1e-10, C = 9.92 for the true 7.61, silently).
//! The check, in both directions, just before the loop applies an instant reached by a step
//! (`Driver::run`):
//!
//! - (a) a time event fires at τ (no crossing scanned there) while an armed state event's
//!   signed guard v = d·g at τ⁻ has not triggered but is rising and −v ≤ δg at x(τ⁻): its
//!   crossing, found after τ on the numerical trajectory, may lie before τ on the true one.
//!   v(τ) ≈ −ġ·(t_s − τ), so this is also the state event located just after the time event,
//!   (t_s − τ)|ġ| ≤ δg, caught before the state event is located. A guard falling at τ is
//!   left out: had it come within δg of zero before τ it turned back there, a near miss the
//!   dip search judges (`grazing`). A guard that joins the instant (within 16 ulp of zero,
//!   `Scanner::join_events_due`) is already `simultaneous_events`;
//! - (b) a state event fires at t_s (a crossing located on a stepped segment): with ġ and δg
//!   at x(t_s⁻), a time event due in (t_s, t_s + δg/|ġ|] fires after it only by the numerics
//!   (one due by t_s + 16 ulp joins the instant and is reported as simultaneous already). The
//!   candidates are the time events armed in the mode before the event (they would have
//!   fired first in the other order) and in its target mode (they fire after it here, and
//!   in the other order their occurrence passes in a mode that does not arm them).
//!
//! Both are reported as `simultaneous_events`, naming the events and the margins. An exact
//! segment (`Scheme::Exact`) has no location error beyond rounding, which the loop's own
//! joining of events within 16 ulp covers: it is never checked, nor is an instant applied
//! by a segment of lines (`line`, exact by definition); a run without time events never
//! gets past one comparison, so neither the queue's nor E1's event loop pays for it.

use super::undecided::guard_tolerance;
use super::{time_resolution, Driver};
use crate::integrate::Scheme;
use crate::model::{At, HybridModel, ModelAlloc};
use crate::solution::{Diagnostic, DiagnosticKind};
use nalgebra::DefaultAllocator;

/// A time event and a state event within the latter's location error (see the module doc):
/// `v` the signed guard at the time event (a), or ġ·(τ − t_s) (b); `dg` its uncertainty δg.
#[derive(Clone, Copy, Debug)]
struct Margin {
    state: usize,
    timed: usize,
    v: f64,
    dg: f64,
}

impl<M: HybridModel> Driver<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// The order check at an instant t reached by a step and about to be applied: `scanned`,
    /// the crossings located there are in `scanner.found`; otherwise a time event is due at t
    /// (`scanner.found` empty). `self.y` holds x(t⁻) and the scanner's tracks the watched
    /// values at the end of the step. See the module doc. A few comparisons unless the run
    /// has time events and the segment just ended was stepped.
    #[inline]
    pub(super) fn check_order(&mut self, t: f64, scanned: bool) {
        if !self.schedule.has_time_events()
            || self.integ.scheme() == Scheme::Exact
            || self.zeno.holding()
        {
            return;
        }
        if scanned {
            self.time_events_after_crossings(t);
        } else {
            self.guards_short_of_zero(t);
        }
    }

    /// δg = Σᵢ |∂g/∂xᵢ| (atol + rtol |xᵢ|) of state event k at (t, x(t⁻) = `self.y.x`), with
    /// ∇g in `self.gx`; returns (δg, ∂g/∂t).
    fn guard_uncertainty(&mut self, k: usize, t: f64) -> (f64, f64) {
        let at = At::new(t, &self.y.x, self.p);
        let gt = self.model.guard_grad(k, at, &mut self.gx, &mut self.gp);
        let tols = (self.opts.atol, self.opts.rtol);
        (guard_tolerance(&self.gx, &self.y.x, tols), gt)
    }

    /// Check (a): at a time event's instant τ = t, every armed state event whose signed guard
    /// v at τ⁻ is below zero, rising, not joining the instant, and within δg of zero.
    #[cold]
    #[inline(never)]
    fn guards_short_of_zero(&mut self, t: f64) {
        let model = self.model;
        let info = model.info();
        let nev = self.scanner.nevents;
        let due = t + time_resolution(t);
        let Some(&kt) = self
            .schedule
            .armed_in(self.mode)
            .iter()
            .find(|&&k| self.schedule.time(k) <= due)
        else {
            return;
        };
        for i in 0..self.scanner.watched().len() {
            let w = self.scanner.watched()[i];
            if w >= nev || info.events[w].is_time_event() {
                continue;
            }
            let tr = &self.scanner.tracks[w];
            let v = tr.start_val;
            if !(tr.armed && v < 0.0 && tr.last_rise > 0.0) {
                continue;
            }
            // Joins the instant (the test of `Scanner::join_events_due`, v + v̇·16 ulp ≥ 0):
            // reported as simultaneous when it is applied.
            if v * tr.last_span + tr.last_rise * time_resolution(t) >= 0.0 {
                continue;
            }
            let (dg, _) = self.guard_uncertainty(w, t);
            if -v <= dg {
                let margin = Margin {
                    state: w,
                    timed: kt,
                    v,
                    dg,
                };
                self.report_order(t, margin, true);
            }
        }
    }

    /// Check (b) at a located crossing t = t_s: for each state event firing there, the window
    /// (t_s + 16 ulp, t_s + δg/|ġ|] with ġ = ∇g·f⁻ + ∂g/∂t at x(t_s⁻); the earliest time
    /// event armed in the mode in force or in the event's target mode due within it is
    /// reported.
    #[cold]
    #[inline(never)]
    fn time_events_after_crossings(&mut self, t: f64) {
        let model = self.model;
        let info = model.info();
        let nev = self.scanner.nevents;
        let due = t + time_resolution(t);
        let mut flowed = false;
        for i in 0..self.scanner.found.len() {
            let w = self.scanner.found[i].w;
            if w >= nev || info.events[w].is_time_event() {
                continue;
            }
            let (dg, gt) = self.guard_uncertainty(w, t);
            if !flowed {
                // f⁻ into `self.f_minus` (applying the event evaluates it again there; a
                // non-finite f⁻ is reported by that evaluation).
                if self.flow_before(t).is_err() {
                    return;
                }
                flowed = true;
            }
            // A tangential crossing (ġ = 0) is located to no time at all: its window is
            // unbounded (and `grazing` reports the crossing itself).
            let rate = (self.gx.dot(&self.f_minus) + gt).abs();
            let end = t + dg / rate;
            let schedule = &self.schedule;
            let target = info.events[w]
                .target
                .map_or(&[][..], |m| schedule.armed_in(m));
            let first = schedule
                .armed_in(self.mode)
                .iter()
                .chain(target)
                .map(|&k| (k, schedule.time(k)))
                .filter(|&(_, tau)| tau > due && tau <= end)
                .min_by(|a, b| a.1.total_cmp(&b.1));
            if let Some((kt, tau)) = first {
                let margin = Margin {
                    state: w,
                    timed: kt,
                    v: rate * (tau - t),
                    dg,
                };
                self.report_order(t, margin, false);
            }
        }
    }

    /// The `simultaneous_events` diagnostic of a time event and a state event whose order is
    /// within the state event's location error (`short`: check (a), the guard is −v short of
    /// zero at the time event; otherwise (b), the crossing was located ġ·(τ − t_s) = v in
    /// guard units before it).
    #[cold]
    #[inline(never)]
    fn report_order(&mut self, t: f64, m: Margin, short: bool) {
        let (s, k) = (self.event_name(m.state), self.event_name(m.timed));
        let how = if short {
            format!(
                "time event `{k}` fires at t = {t} while the guard of state event `{s}` is {:.3e} \
                 short of zero",
                -m.v
            )
        } else {
            format!(
                "state event `{s}` was located at t = {t}, {:.3e} in guard units (|dg/dt|·Δt) \
                 before time event `{k}` is due",
                m.v
            )
        };
        let message = format!(
            "events `{k}` and `{s}`: {how}, within the {:.3e} the guard may err by at these \
             tolerances (Σ|∂g/∂xᵢ|(atol + rtol|xᵢ|)): their order is within the state event's \
             location error and was decided by the numerics; C may jump between the two orders",
            m.dg
        );
        self.diagnostics.push(Diagnostic {
            kind: DiagnosticKind::SimultaneousEvents,
            t,
            message,
        });
    }
}
