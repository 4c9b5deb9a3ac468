//! The time events' source: for every event, its occurrence index j and, for a time event,
//! the time τ_kj(θ) of its next occurrence (see [`crate::model::Trigger`]).
//!
//! The event loop steps exactly onto the earliest τ of the time events armed in the current
//! mode (the stepper's `step(t_stop)`), so a time event needs no root finding; its
//! event-time sensitivity t' = ∂τ/∂θ comes from [`HybridModel::event_time_grad`] through the
//! same formula as a guard's (g = t − τ: g_x = 0, g_t = 1, g_θ = −∂τ/∂θ). Occurrences before
//! t = 0, and occurrences that pass while their event is not armed, are skipped. A state
//! event's j counts its earlier firings.

use crate::error::{SolveError, Time};
use crate::model::{HybridModel, ModelAlloc, Occurrence, Trigger};
use nalgebra::{DefaultAllocator, OVector};

/// Occurrence indices and next times of a run's events (allocated once).
#[derive(Clone, Debug)]
pub(super) struct Schedule {
    /// j of the next occurrence of event k.
    next: Vec<usize>,
    /// τ of that occurrence (time events; ∞ when none is left, and for state events).
    time: Vec<f64>,
    /// Per mode: the time events armed there, in declaration order.
    armed: Vec<Vec<usize>>,
    /// Per mode: the time events not armed there.
    unarmed: Vec<Vec<usize>>,
    /// Per mode: the time events armed there but not in every mode (those a mode switch into
    /// it can find behind; see [`Schedule::enter_mode`]).
    partial: Vec<Vec<usize>>,
    /// (mode, the earliest time of the events armed there), as last computed; cleared
    /// whenever a time changes.
    earliest: Option<(usize, f64)>,
    /// Each event's trigger (a copy of `EventInfo::trigger`, read on every occurrence).
    trigger: Vec<Trigger>,
}

impl Schedule {
    /// The schedule of the events of `model`, before [`Schedule::start`] (which time events
    /// each mode arms is decided here, once per run).
    pub(super) fn new<M: HybridModel>(model: &M) -> Self
    where
        DefaultAllocator: ModelAlloc<M::N, M::P>,
    {
        let info = model.info();
        let nevents = info.events.len();
        let timed = |mode: usize, armed: bool| -> Vec<usize> {
            (0..nevents)
                .filter(|&k| {
                    let ev = &info.events[k];
                    ev.is_time_event() && ev.armed_in(mode) == armed
                })
                .collect()
        };
        Schedule {
            next: vec![0; nevents],
            time: vec![f64::INFINITY; nevents],
            armed: (0..info.modes.len()).map(|m| timed(m, true)).collect(),
            unarmed: (0..info.modes.len()).map(|m| timed(m, false)).collect(),
            partial: (0..info.modes.len())
                .map(|m| {
                    let everywhere =
                        |k: &usize| (0..info.modes.len()).all(|o| info.events[*k].armed_in(o));
                    timed(m, true)
                        .into_iter()
                        .filter(|k| !everywhere(k))
                        .collect()
                })
                .collect(),
            earliest: None,
            trigger: info.events.iter().map(|ev| ev.trigger).collect(),
        }
    }

    /// The time events armed in `mode`, in declaration order.
    pub(super) fn armed_in(&self, mode: usize) -> &[usize] {
        &self.armed[mode]
    }

    /// Whether the model has time events (each is armed or not armed in mode 0).
    #[inline]
    pub(super) fn has_time_events(&self) -> bool {
        !(self.armed[0].is_empty() && self.unarmed[0].is_empty())
    }

    /// Occurrence index of the next firing of event k.
    pub(super) fn occurrence(&self, k: usize) -> usize {
        self.next[k]
    }

    /// τ of the next occurrence of event k (∞ for state events and exhausted schedules).
    pub(super) fn time(&self, k: usize) -> f64 {
        self.time[k]
    }

    /// First occurrences of every time event at or after t = 0; checks that periods are
    /// positive, times finite, and that no `every` event fires more than `limit` times before
    /// `t_end` (`Options::max_periodic_occurrences`: scheduled occurrences count against
    /// neither the event nor the step budget, so this bounds the run).
    pub(super) fn start<M: HybridModel>(
        &mut self,
        model: &M,
        p: &OVector<f64, M::P>,
        (t_end, limit): (f64, usize),
    ) -> Result<(), SolveError>
    where
        DefaultAllocator: ModelAlloc<M::N, M::P>,
    {
        let info = model.info();
        self.earliest = None;
        for (k, ev) in info.events.iter().enumerate() {
            self.next[k] = 0;
            self.time[k] = f64::INFINITY;
            if !ev.is_time_event() {
                continue;
            }
            if ev.trigger == Trigger::Every {
                let (t0, period) = first_and_period(model, p, k);
                if !(t0.is_finite() && period.is_finite() && period > 0.0) {
                    return Err(SolveError::BadSchedule {
                        event: ev.name.clone(),
                        what: bad_period(t0, period),
                    });
                }
                let count = ((t_end - t0.max(0.0)) / period).floor() + 1.0;
                if count > limit as f64 {
                    return Err(SolveError::BadSchedule {
                        event: ev.name.clone(),
                        what: format!(
                            "with period {period:e} it would fire {count:.3e} times before the \
                             horizon {t_end}, more than {limit} (max_periodic_occurrences)",
                            t_end = Time(t_end),
                        ),
                    });
                }
            }
            self.time[k] = self.time_of(model, p, k, 0)?;
            self.skip_before(model, p, k, 0.0)?;
        }
        self.earliest = None;
        Ok(())
    }

    /// τ_kj, ∞ past the end of the schedule.
    #[inline]
    fn time_of<M: HybridModel>(
        &self,
        model: &M,
        p: &OVector<f64, M::P>,
        k: usize,
        j: usize,
    ) -> Result<f64, SolveError>
    where
        DefaultAllocator: ModelAlloc<M::N, M::P>,
    {
        let exists = match self.trigger[k] {
            Trigger::Guard => false,
            Trigger::At => j == 0,
            Trigger::Every => true,
            Trigger::Each { rows } => j < rows,
        };
        if !exists {
            return Ok(f64::INFINITY);
        }
        let tau = model.event_time(Occurrence::new(k, j), p);
        if tau.is_finite() {
            Ok(tau)
        } else {
            Err(nonfinite_time(tau, j, &model.info().events[k].name))
        }
    }

    /// Moves event k on to its next occurrence (after it fired or was skipped); the times of a
    /// schedule must not decrease.
    #[inline]
    pub(super) fn advance<M: HybridModel>(
        &mut self,
        model: &M,
        p: &OVector<f64, M::P>,
        k: usize,
    ) -> Result<(), SolveError>
    where
        DefaultAllocator: ModelAlloc<M::N, M::P>,
    {
        let j = self.next[k] + 1;
        self.next[k] = j;
        if self.trigger[k] == Trigger::Guard {
            return Ok(());
        }
        self.earliest = None;
        let tau = self.time_of(model, p, k, j)?;
        if tau < self.time[k] {
            return Err(decreasing_times(
                &model.info().events[k].name,
                j,
                self.time[k],
                tau,
            ));
        }
        self.time[k] = tau;
        Ok(())
    }

    /// On entering mode `to` from mode `from` at the instant t (an event switched it): every
    /// time event armed in `to` but not in `from` skips its occurrences up to and including t
    /// (within [`super::time_resolution`]). They fell while it was not armed: the instant's
    /// events were decided in `from`, at t⁻, so a row that `from`'s event handled at t is not
    /// handled again by `to`'s. (Its occurrences before t would otherwise be due at once and
    /// fire late, at t, with t' = 0: probe3 A1.) Events armed in both modes are left alone:
    /// their occurrence at t, if any, is among the instant's.
    pub(super) fn enter_mode<M: HybridModel>(
        &mut self,
        model: &M,
        p: &OVector<f64, M::P>,
        (from, to): (usize, usize),
        t: f64,
    ) -> Result<(), SolveError>
    where
        DefaultAllocator: ModelAlloc<M::N, M::P>,
    {
        if self.partial[to].is_empty() {
            return Ok(());
        }
        let after = (t + super::time_resolution(t)).next_up();
        for i in 0..self.partial[to].len() {
            let k = self.partial[to][i];
            if !model.info().events[k].armed_in(from) {
                self.skip_before(model, p, k, after)?;
            }
        }
        Ok(())
    }

    /// Skips the occurrences of time event k before t.
    pub(super) fn skip_before<M: HybridModel>(
        &mut self,
        model: &M,
        p: &OVector<f64, M::P>,
        k: usize,
        t: f64,
    ) -> Result<(), SolveError>
    where
        DefaultAllocator: ModelAlloc<M::N, M::P>,
    {
        if self.time[k] >= t {
            return Ok(());
        }
        if model.info().events[k].trigger == Trigger::Every {
            // Jump to just before t (a short period would otherwise take many steps), then walk.
            let (t0, period) = first_and_period(model, p, k);
            let target = ((t - t0) / period).floor();
            if target.is_finite() && target > self.next[k] as f64 + 1.0 && target < 1e15 {
                let j = target as usize - 1;
                self.next[k] = j;
                self.earliest = None;
                self.time[k] = self.time_of(model, p, k, j)?;
            }
        }
        while self.time[k] < t {
            self.advance(model, p, k)?;
        }
        Ok(())
    }

    /// The earliest next time of the time events armed in `mode` (∞ if none), after skipping
    /// the occurrences before `t` of every time event that is not armed there. O(1) when
    /// every time event is armed in `mode` and no time has changed since the last call.
    #[inline(always)]
    pub(super) fn next_in_mode<M: HybridModel>(
        &mut self,
        model: &M,
        p: &OVector<f64, M::P>,
        mode: usize,
        t: f64,
    ) -> Result<f64, SolveError>
    where
        DefaultAllocator: ModelAlloc<M::N, M::P>,
    {
        for i in 0..self.unarmed[mode].len() {
            let k = self.unarmed[mode][i];
            self.skip_before(model, p, k, t)?;
        }
        if let Some((m, next)) = self.earliest {
            if m == mode {
                return Ok(next);
            }
        }
        let next = self.armed[mode]
            .iter()
            .fold(f64::INFINITY, |next, &k| next.min(self.time[k]));
        self.earliest = Some((mode, next));
        Ok(next)
    }
}

/// The error of a time that is not finite: τ of occurrence j of the event `name`.
#[cold]
#[inline(never)]
fn nonfinite_time(tau: f64, j: usize, name: &str) -> SolveError {
    SolveError::NonFinite {
        t: tau,
        what: format!("time of occurrence {j} of event `{name}`"),
    }
}

/// The error of a schedule whose occurrence j comes before occurrence j − 1.
#[cold]
#[inline(never)]
fn decreasing_times(name: &str, j: usize, before: f64, tau: f64) -> SolveError {
    SolveError::BadSchedule {
        event: name.to_string(),
        what: format!(
            "its times decrease at occurrence {j} (row {j} of its table for `at each`): \
             {before} then {tau}",
            before = Time(before),
            tau = Time(tau),
        ),
    }
}

/// Why `every` times with first time t0 and period τ₁ − τ₀ = `period` are unusable. The period
/// is read as the difference of the first two times, so a period below the resolution of t0
/// (`every 1 from -1e20`: ulp 1.6e4) comes out 0 although the model's is not.
fn bad_period(t0: f64, period: f64) -> String {
    if t0.is_finite() && period == 0.0 && t0 != 0.0 {
        return format!(
            "its first time {} and the next coincide in floating point: the period is below the \
             resolution of times that large (about {:.1e}), so its occurrences cannot be told \
             apart",
            Time(t0),
            f64::EPSILON * t0.abs()
        );
    }
    format!(
        "its period is {} and its first time {}; the period must be positive and both finite",
        Time(period),
        Time(t0)
    )
}

/// The first time and the period of `every` event k: τ_k0 and τ_k1 − τ_k0.
fn first_and_period<M: HybridModel>(model: &M, p: &OVector<f64, M::P>, k: usize) -> (f64, f64)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let t0 = model.event_time(Occurrence::new(k, 0), p);
    (t0, model.event_time(Occurrence::new(k, 1), p) - t0)
}

#[cfg(test)]
mod tests {
    use super::bad_period;

    /// `every 1 from -1e20` has τ₁ − τ₀ = 0 in floating point: the message says why, not that
    /// the period is 0; a period that really is not positive is named as such.
    #[test]
    fn a_period_lost_in_the_first_times_rounding_is_named() {
        let t0 = -1e20;
        let msg = bad_period(t0, (t0 + 1.0) - t0);
        assert!(
            msg.contains("first time -1e20 and the next coincide"),
            "{msg}"
        );
        assert!(msg.contains("about 2.2e4"), "{msg}");
        let msg = bad_period(0.0, -1.0);
        assert_eq!(
            msg,
            "its period is -1 and its first time 0; the period must be positive and both finite"
        );
        assert!(bad_period(f64::NAN, 1.0).contains("first time NaN"));
    }
}
