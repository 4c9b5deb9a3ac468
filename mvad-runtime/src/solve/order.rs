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
//! The check, in both directions, at the instants the loop applies (`fire_at`):
//!
//! - (a) a time event fires at τ (no crossing scanned there) while an armed state event's
//!   signed guard v = d·g at τ⁻ has not triggered but is rising and −v ≤ δg at x(τ⁻): its
//!   crossing, found after τ on the numerical trajectory, may lie before τ on the true one.
//!   v(τ) ≈ −ġ·(t_s − τ), so this is also the state event located just after the time
//!   event, (t_s − τ)|ġ| ≤ δg, caught before the state event is located. A guard falling at
//!   τ is left out: had it come within δg of zero before τ it turned back there, a near miss
//!   the dip search judges (`grazing`);
//! - (b) a state event fires at t_s (a crossing located on a stepped segment): with ġ and δg
//!   at x(t_s⁻), every time event due in (t_s, t_s + δg/|ġ|] fires after it only by the
//!   numerics. The time events armed in the mode before the event are compared at once (one
//!   that the event's mode switch disarms would have fired in the other order); the window is
//!   kept, and a time event applied within it at a later instant (armed in the new mode) is
//!   reported there.
//!
//! Both are reported as `simultaneous_events`, naming the events and the margins. An exact
//! segment (`Scheme::Exact`) has no location error beyond rounding, which the loop's own
//! joining of events within 16 ulp covers: it is never checked, and a run without time
//! events never gets past one comparison, so neither the queue's nor E1's event loop pays
//! for it.

use super::{time_resolution, Driver};
use crate::integrate::{zero_rows, Scheme};
use crate::model::{At, HybridModel, ModelAlloc, Point};
use crate::solution::{Diagnostic, DiagnosticKind};
use nalgebra::DefaultAllocator;

/// What the order check keeps between instants (no allocation after `new`).
#[derive(Clone, Copy, Debug)]
pub(super) struct Order {
    /// The model has time events (otherwise nothing is ever checked).
    timed: bool,
    /// After a state event located on a stepped segment, its window (check (b)): a time event
    /// applied at a later instant within it is reported there.
    window: Option<Window>,
}

/// The window (t_s, t_s + δg/|ġ|] of state event `state` located at t_s.
#[derive(Clone, Copy, Debug)]
struct Window {
    t_s: f64,
    end: f64,
    state: usize,
    /// |ġ| at t_s⁻.
    rate: f64,
    /// δg at t_s⁻.
    dg: f64,
}

impl Order {
    /// The check for a model whose events `time_events` says whether any is a time event.
    pub(super) fn new(time_events: bool) -> Self {
        Order {
            timed: time_events,
            window: None,
        }
    }
}

/// The signed margin of a guard within its location error of the time event (see the module
/// doc): `v` the signed guard (or ġ·(τ − t_s)), `dg` its uncertainty δg.
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
    /// The order check at an instant t about to be applied (`scanner.found` holds what fires
    /// there, `self.y` x(t⁻), the scanner's tracks the values at the end of the last step;
    /// `scanned`: a crossing was located there). See the module doc. O(1) unless the run has
    /// time events and the segment just ended was stepped, or a window is open.
    #[inline]
    pub(super) fn check_order(&mut self, t: f64, scanned: bool) {
        if !self.order.timed || self.order.window.is_none() && self.integ.scheme() == Scheme::Exact
        {
            return;
        }
        self.check_order_cold(t, scanned);
    }

    #[cold]
    #[inline(never)]
    fn check_order_cold(&mut self, t: f64, scanned: bool) {
        let info = self.model.info();
        let nev = self.scanner.nevents;
        let timed_here = self
            .scanner
            .found
            .iter()
            .find(|c| c.w < nev && info.events[c.w].is_time_event())
            .map(|c| c.w);
        // (b), a later instant: a time event within the window of the last located crossing.
        if let Some(win) = self.order.window {
            if t > win.end {
                self.order.window = None;
            } else if let Some(kt) = timed_here.filter(|_| t > win.t_s) {
                self.order.window = None;
                let margin = Margin {
                    state: win.state,
                    timed: kt,
                    v: win.rate * (t - win.t_s),
                    dg: win.dg,
                };
                self.report_order(t, margin, false);
            }
        }
        if self.integ.scheme() == Scheme::Exact || self.zeno.holding() {
            return;
        }
        if scanned {
            self.open_windows(t);
        } else if let Some(kt) = timed_here {
            self.guards_short_of_zero(t, kt);
        }
    }

    /// δg = Σᵢ |∂g/∂xᵢ| (atol + rtol |xᵢ|) of state event k at (t, x(t⁻) = `self.y.x`), with
    /// ∇g in `self.gx`; returns (δg, ∂g/∂t).
    fn guard_uncertainty(&mut self, k: usize, t: f64) -> (f64, f64) {
        let (atol, rtol) = (self.opts.atol, self.opts.rtol);
        let at = At::new(t, &self.y.x, self.p);
        let gt = self.model.guard_grad(k, at, &mut self.gx, &mut self.gp);
        let dg = self
            .gx
            .iter()
            .zip(self.y.x.iter())
            .map(|(g, x)| g.abs() * (atol + rtol * x.abs()))
            .sum();
        (dg, gt)
    }

    /// Check (a): at a time event's instant τ = t, every armed state event not firing there
    /// whose signed guard v at τ⁻ is below zero, rising, and within δg of it.
    fn guards_short_of_zero(&mut self, t: f64, kt: usize) {
        let info = self.model.info();
        let nev = self.scanner.nevents;
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
            if self.scanner.found.iter().any(|c| c.w == w) {
                continue;
            }
            let (dg, _) = self.guard_uncertainty(w, t);
            if -v <= dg {
                self.report_order(
                    t,
                    Margin {
                        state: w,
                        timed: kt,
                        v,
                        dg,
                    },
                    true,
                );
            }
        }
    }

    /// Check (b) at a located crossing t = t_s: for each state event firing there, the window
    /// (t_s, t_s + δg/|ġ|] with ġ = ∇g·f⁻ + ∂g/∂t at x(t_s⁻); a time event armed in the mode
    /// in force due within it (after the 16 ulp in which it joins this instant) is reported
    /// now, otherwise the widest window is kept for the instants that follow.
    fn open_windows(&mut self, t: f64) {
        let info = self.model.info();
        let nev = self.scanner.nevents;
        let due = t + time_resolution(t);
        let mut flowed = false;
        self.order.window = None;
        for i in 0..self.scanner.found.len() {
            let w = self.scanner.found[i].w;
            if w >= nev || info.events[w].is_time_event() {
                continue;
            }
            let (dg, gt) = self.guard_uncertainty(w, t);
            if !flowed {
                let pt = Point::new(self.mode, &self.sw, t, &self.y.x, self.p);
                self.model.rhs(pt, &mut self.work);
                zero_rows(&mut self.work, &self.held);
                flowed = true;
            }
            let rate = (self.gx.dot(&self.work) + gt).abs();
            let width = dg / rate;
            // (A tangential crossing, ġ = 0, is located to no time at all: its window is
            // unbounded, and `grazing` reports the crossing itself.)
            if width.is_nan() {
                continue;
            }
            let end = t + width;
            let first = self
                .schedule
                .armed_in(self.mode)
                .iter()
                .copied()
                .filter(|&k| {
                    let tau = self.schedule.time(k);
                    tau > due && tau <= end
                })
                .min_by(|&a, &b| self.schedule.time(a).total_cmp(&self.schedule.time(b)));
            if let Some(kt) = first {
                let tau = self.schedule.time(kt);
                let margin = Margin {
                    state: w,
                    timed: kt,
                    v: rate * (tau - t),
                    dg,
                };
                self.report_order(t, margin, false);
                self.order.window = None;
                return;
            }
            if self.order.window.is_none_or(|win| end > win.end) {
                self.order.window = Some(Window {
                    t_s: t,
                    end,
                    state: w,
                    rate,
                    dg,
                });
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
                "state event `{s}` was located {:.3e} (in guard units, |dg/dt|·Δt) before time \
                 event `{k}`",
                m.v
            )
        };
        let message = format!(
            "events `{k}` and `{s}`: {how}, within the {:.3e} its guard may err by at these \
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
