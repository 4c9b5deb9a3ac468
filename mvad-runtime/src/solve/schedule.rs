//! The time events' source: for every event, its occurrence index j and, for a time event,
//! the time τ_kj(θ) of its next occurrence (see [`crate::model::Trigger`]).
//!
//! The event loop steps exactly onto the earliest τ of the time events armed in the current
//! mode (the stepper's `step(t_stop)`), so a time event needs no root finding; its
//! event-time sensitivity t' = ∂τ/∂θ comes from [`HybridModel::event_time_grad`] through the
//! same formula as a guard's (g = t − τ: g_x = 0, g_t = 1, g_θ = −∂τ/∂θ). Occurrences before
//! t = 0, and occurrences that pass while their event is not armed, are skipped. A state
//! event's j counts its earlier firings.

use crate::error::SolveError;
use crate::model::{HybridModel, ModelAlloc, Occurrence, Trigger};
use nalgebra::{DefaultAllocator, OVector};

/// Occurrence indices and next times of a run's events (allocated once).
#[derive(Clone, Debug)]
pub(super) struct Schedule {
    /// j of the next occurrence of event k.
    next: Vec<usize>,
    /// τ of that occurrence (time events; ∞ when none is left, and for state events).
    time: Vec<f64>,
}

impl Schedule {
    /// The schedule of `nevents` events, before [`Schedule::start`].
    pub(super) fn new(nevents: usize) -> Self {
        Schedule {
            next: vec![0; nevents],
            time: vec![f64::INFINITY; nevents],
        }
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
    /// positive and times finite.
    pub(super) fn start<M: HybridModel>(
        &mut self,
        model: &M,
        p: &OVector<f64, M::P>,
    ) -> Result<(), SolveError>
    where
        DefaultAllocator: ModelAlloc<M::N, M::P>,
    {
        let info = model.info();
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
                        what: format!(
                            "its period is {period} and its first time {t0}; the period must be \
                             positive and both finite"
                        ),
                    });
                }
            }
            self.time[k] = self.time_of(model, p, k, 0)?;
            self.skip_before(model, p, k, 0.0)?;
        }
        Ok(())
    }

    /// τ_kj, ∞ past the end of the schedule.
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
        let ev = &model.info().events[k];
        let exists = match ev.trigger {
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
            Err(SolveError::NonFinite {
                t: tau,
                what: format!("time of occurrence {j} of event `{}`", ev.name),
            })
        }
    }

    /// Moves event k on to its next occurrence (after it fired or was skipped); the times of a
    /// schedule must not decrease.
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
        if !model.info().events[k].is_time_event() {
            return Ok(());
        }
        let tau = self.time_of(model, p, k, j)?;
        if tau < self.time[k] {
            let ev = &model.info().events[k];
            return Err(SolveError::BadSchedule {
                event: ev.name.clone(),
                what: format!(
                    "its times decrease at occurrence {j} (row {j} of its table for `at each`): \
                     {} then {tau}",
                    self.time[k]
                ),
            });
        }
        self.time[k] = tau;
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
                self.time[k] = self.time_of(model, p, k, j)?;
            }
        }
        while self.time[k] < t {
            self.advance(model, p, k)?;
        }
        Ok(())
    }

    /// The earliest next time of the time events armed in `mode` (∞ if none), after skipping
    /// the occurrences before `t` of every time event that is not armed there.
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
        let mut next = f64::INFINITY;
        for (k, ev) in model.info().events.iter().enumerate() {
            if !ev.is_time_event() {
                continue;
            }
            if ev.armed_in(mode) {
                next = next.min(self.time[k]);
            } else {
                self.skip_before(model, p, k, t)?;
            }
        }
        Ok(next)
    }
}

/// The first time and the period of `every` event k: τ_k0 and τ_k1 − τ_k0.
fn first_and_period<M: HybridModel>(model: &M, p: &OVector<f64, M::P>, k: usize) -> (f64, f64)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let t0 = model.event_time(Occurrence::new(k, 0), p);
    (t0, model.event_time(Occurrence::new(k, 1), p) - t0)
}
