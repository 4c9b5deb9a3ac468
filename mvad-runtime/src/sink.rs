//! Where the events of a run go: the event loop hands every user event, as a borrowed
//! [`EventView`], to an [`EventSink`] the caller chooses.
//!
//! - `()` keeps nothing: a run that wants only C and dC/dθ allocates nothing per event
//!   (the count is still in [`crate::Stats::events`]).
//! - [`EventCounts`] counts the firings of each declared event.
//! - [`FirstEvents`] keeps the table of the first N events only.
//! - `Vec<EventRecord>` keeps the full table, with the jumps and atoms of the measure;
//!   [`crate::solve::solve`] uses it and returns it as [`crate::Solution::events`].
//! - [`Stream`] calls a closure per event: a streaming reduction (a running sum of event
//!   times, a histogram, a check) over a run too long to keep.

use crate::solution::EventRecord;

/// One user event as the event loop sees it when the event fires: the scalar fields of
/// [`EventRecord`] (same names, same meaning) and borrowed slices of the loop's buffers,
/// valid only for the call; the jumps and atoms follow from them ([`EventView::to_record`]).
#[derive(Clone, Copy, Debug)]
#[allow(missing_docs)]
pub struct EventView<'a> {
    pub index: usize,
    pub event: usize,
    pub t: f64,
    pub mode_before: usize,
    pub mode_after: usize,
    pub guard_slope: f64,
    pub guard_dt: f64,
    pub transversal: bool,
    pub dt: &'a [f64],
    pub x_before: &'a [f64],
    pub x_after: &'a [f64],
    /// The observables at (t_k, x⁻).
    pub observables_before: &'a [f64],
    /// The observables at (t_k, x⁺).
    pub observables_after: &'a [f64],
}

impl EventView<'_> {
    /// The event table's entry: the jumps J = y⁺ − y⁻ of every state and observable and the
    /// atoms α = −J·dt_k/dθ the measure places at t_k, one row per observable.
    pub fn to_record(&self) -> EventRecord {
        let diff =
            |a: &[f64], b: &[f64]| -> Vec<f64> { a.iter().zip(b).map(|(a, b)| a - b).collect() };
        let jump_observables = diff(self.observables_after, self.observables_before);
        let atoms = jump_observables
            .iter()
            .map(|j| self.dt.iter().map(|d| -j * d).collect())
            .collect();
        EventRecord {
            index: self.index,
            event: self.event,
            t: self.t,
            mode_before: self.mode_before,
            mode_after: self.mode_after,
            guard_slope: self.guard_slope,
            guard_dt: self.guard_dt,
            transversal: self.transversal,
            dt: self.dt.to_vec(),
            x_before: self.x_before.to_vec(),
            x_after: self.x_after.to_vec(),
            jump_states: diff(self.x_after, self.x_before),
            jump_observables,
            atoms,
        }
    }
}

/// Receives the user events of a run, in time order (simultaneous events in declaration
/// order). Switch crossings of kinks are not events and are not passed on.
pub trait EventSink {
    /// Called once per user event, after its reset and sensitivity jump are known.
    fn event(&mut self, ev: &EventView<'_>);
    /// Whether the sink looks at the next event at all: when it does not, the loop neither
    /// builds the view (the observables on both sides) nor calls [`EventSink::event`].
    fn wants_events(&self) -> bool {
        true
    }
}

/// Keeps nothing.
impl EventSink for () {
    #[inline]
    fn event(&mut self, _ev: &EventView<'_>) {}
    #[inline]
    fn wants_events(&self) -> bool {
        false
    }
}

/// Keeps the full event table.
impl EventSink for Vec<EventRecord> {
    fn event(&mut self, ev: &EventView<'_>) {
        self.push(ev.to_record());
    }
}

/// Keeps the table of the first `limit` events only (a large run's JSON lists the first
/// 1000); the count of all of them is in [`crate::Stats::events`]. Allocates nothing once
/// the limit is reached.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FirstEvents {
    /// How many records to keep.
    pub limit: usize,
    /// The records of the first `limit` events.
    pub records: Vec<EventRecord>,
}

impl FirstEvents {
    /// Keeps at most `limit` records.
    pub fn new(limit: usize) -> Self {
        FirstEvents {
            limit,
            records: Vec::new(),
        }
    }
}

impl EventSink for FirstEvents {
    fn event(&mut self, ev: &EventView<'_>) {
        if self.records.len() < self.limit {
            self.records.push(ev.to_record());
        }
    }
    fn wants_events(&self) -> bool {
        self.records.len() < self.limit
    }
}

/// Firings per declared event, indexed like `ModelInfo::events`.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct EventCounts {
    /// `per_event[k]` = how often event k fired.
    pub per_event: Vec<usize>,
}

impl EventCounts {
    /// Counters for a model with `nevents` declared events (allocated here, once).
    pub fn new(nevents: usize) -> Self {
        EventCounts {
            per_event: vec![0; nevents],
        }
    }
}

impl EventSink for EventCounts {
    fn event(&mut self, ev: &EventView<'_>) {
        if ev.event >= self.per_event.len() {
            self.per_event.resize(ev.event + 1, 0);
        }
        self.per_event[ev.event] += 1;
    }
}

/// A streaming reduction: the closure sees every event and keeps what it wants.
pub struct Stream<F>(pub F);

impl<F: FnMut(&EventView<'_>)> EventSink for Stream<F> {
    fn event(&mut self, ev: &EventView<'_>) {
        (self.0)(ev)
    }
}

impl<S: EventSink + ?Sized> EventSink for &mut S {
    fn event(&mut self, ev: &EventView<'_>) {
        (**self).event(ev)
    }
    fn wants_events(&self) -> bool {
        (**self).wants_events()
    }
}
