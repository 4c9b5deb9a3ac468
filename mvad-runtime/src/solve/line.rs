//! Exact segments whose watched functions are lines: not stepped towards a guess and scanned,
//! but taken straight to their first root.
//!
//! In a mode whose segment is exact (`Scheme::Exact`: F constant, x(t) = x₀ + (t − t₀)F) and
//! whose watched functions are all affine guards (`ModeWatch::affine`: ∇g and ∂g/∂t are
//! functions of θ alone), each watched value is exactly the line
//!
//! ```text
//!   v_w(t) = v_w(t₀) + v̇_w (t − t₀),   v̇_w = d_w (∇g_w·F + ∂g_w/∂t),
//! ```
//!
//! with v̇_w a function of θ and the mode alone (a mode whose watch is affine watches no
//! switching function, and F of a constant-rate mode reads no state, time or bit), computed
//! once per mode and run. The loop then steps once, to the earlier of its stop (T or the next
//! time event) and the first root t₀ − v_w(t₀)/v̇_w of an armed line rising towards zero
//! (`Scanner::first_line_root`), and evaluates the guards only at the state it lands on
//! (`Scanner::close_lines`): no dense output, no samples, no bracket, no root finding.
//!
//! The scanner's semantics are kept: the root, as rounded, is accepted only if the guard
//! evaluated at the state there, x₀ + (t − t₀)F as the step computes it, has triggered (so
//! the state handed to the reset is on or past the guard, as the root finder promises);
//! otherwise the next few doubles are tried. Whatever the closed form does not decide alone —
//! a root that no double within a few ulp triggers, a root within the resolution of t₀, a
//! line on zero at t₀, two lines reaching zero within the simultaneity window — is scanned as
//! before, so the answer is the scanner's in every case. A line has no turning point: the dip
//! search, its near misses and the undecided verdicts have nothing to look at. Not taken
//! while recording (the recorder keeps the step as the scan sees it), during a Zeno hold (a
//! masked F), or when a slope is not finite.

use super::{time_resolution, Driver};
use crate::error::SolveError;
use crate::event::LineRoot;
use crate::model::{HybridModel, ModelAlloc};
use crate::sink::EventSink;
use nalgebra::DefaultAllocator;

/// Doubles after the rounded root tried before the segment is scanned instead.
const NUDGES: usize = 4;

/// The rates of the watched lines, per mode, and whether the segment in progress is one of
/// lines.
pub(super) struct Lines {
    /// Per mode: v̇_w of every function w watched there (indexed by w; other entries 0), once
    /// computed; `None` until then.
    slopes: Vec<Option<Vec<f64>>>,
    /// The segment begun at the last restart is exact with affine watched guards, and no
    /// recorder or hold is in the way: [`Driver::line_segment`] takes it.
    pub(super) on: bool,
}

impl Lines {
    /// Nothing computed (and nothing allocated) yet: the slopes are made on the first
    /// segment of lines of the run.
    pub(super) fn new() -> Self {
        Lines {
            slopes: Vec::new(),
            on: false,
        }
    }
}

impl<M: HybridModel> Driver<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// After a restart at t: whether the new segment is one of lines ([`Lines::on`]), with the
    /// mode's slopes computed on its first such segment.
    pub(super) fn begin_lines(&mut self, t: f64) {
        self.lines.on = false;
        let mode = self.mode;
        if !self.watch[mode].affine
            || self.rec.is_some()
            || !self.held.is_empty()
            || self.zeno.holding()
        {
            return;
        }
        let Some(rate) = self.integ.exact_rate() else {
            return;
        };
        if self.lines.slopes.is_empty() {
            self.lines.slopes.resize(self.watch.len(), None);
        }
        if self.lines.slopes[mode].is_none() {
            let (model, p) = (self.model, self.p);
            let info = model.info();
            let mut slope = vec![0.0; self.scanner.len()];
            for &w in &self.watch[mode].list {
                let gt = model.guard_grad(
                    w,
                    crate::model::At::new(t, &self.y.x, p),
                    &mut self.gx,
                    &mut self.gp,
                );
                slope[w] = info.events[w].direction.sign() * (self.gx.dot(&rate.x) + gt);
            }
            if !slope.iter().all(|v| v.is_finite()) {
                return;
            }
            self.lines.slopes[mode] = Some(slope);
        }
        self.lines.on = true;
    }

    /// Takes the segment of lines from the integrator's t to `t_stop` (see the module doc):
    /// one exact step to the first root or to `t_stop`, the guards at its end, and the events
    /// there applied. `t_next` is the time of the next time event armed in the mode: a step
    /// that lands on it with no crossing applies it at once (what the loop's next round would
    /// do: the schedule's next time at the stop is `t_next` again, and nothing else is read in
    /// between). Returns false, having changed nothing, when the segment must be scanned.
    pub(super) fn line_segment(
        &mut self,
        t_stop: f64,
        t_next: f64,
        sink: &mut impl EventSink,
    ) -> Result<bool, SolveError> {
        let t0 = self.integ.t();
        let Some(slope) = &self.lines.slopes[self.mode] else {
            return Ok(false);
        };
        let sim_tol = self.simultaneity(t_stop);
        let t1 = match self.scanner.first_line_root(t0, t_stop, slope, sim_tol) {
            LineRoot::Scan => return Ok(false),
            LineRoot::Beyond => t_stop,
            LineRoot::At(w, t) => match self.triggered_root(w, t0, t, t_stop) {
                Some(t1) => t1,
                None => return Ok(false),
            },
        };
        self.integ.step(t1)?;
        let (model, p, nev) = (self.model, self.p, self.scanner.nevents);
        let (sw, x) = (&self.sw, &self.integ.y().x);
        let sample = |t: f64, _: bool, watched: &[usize], out: &mut [f64]| {
            for &w in watched {
                out[w] = Self::signed(model, p, nev, sw, w, t, x);
            }
        };
        let closed = self.scanner.close_lines(t0, t1, sample);
        closed.map_err(|(w, t)| self.guard_nonfinite(w, t))?;
        if !self.scanner.found.is_empty() || t1 == t_stop && t_next <= t1 + time_resolution(t1) {
            self.y.copy_from(self.integ.y());
            self.fire_at(t1, sink)?;
        }
        Ok(true)
    }

    /// The first of the rounded root `t` of line w and the next [`NUDGES`] doubles at which
    /// the guard, at the state the exact step from t₀ computes there, has triggered (`t_stop`
    /// if they reach it: the guards at the stop decide); `None` when none has, or the step
    /// would be below the resolution of t₀.
    fn triggered_root(&mut self, w: usize, t0: f64, mut t: f64, t_stop: f64) -> Option<f64> {
        let (model, p, nev) = (self.model, self.p, self.scanner.nevents);
        let rate = &self.integ.exact_rate()?.x;
        let x0 = &self.integ.y().x;
        for _ in 0..=NUDGES {
            if t >= t_stop {
                return Some(t_stop);
            }
            if t - t0 <= time_resolution(t0) {
                return None;
            }
            // x₀ + h·F entry by entry, as the exact step computes it.
            let h = t - t0;
            for ((xs, &x), &f) in self.xs.iter_mut().zip(x0.iter()).zip(rate.iter()) {
                *xs = x + h * f;
            }
            let v = Self::signed(model, p, nev, &self.sw, w, t, &self.xs);
            if v > 0.0 || v == 0.0 && !self.scanner.strict(w) {
                return Some(t);
            }
            if v.is_nan() {
                return None;
            }
            t = t.next_up();
        }
        None
    }
}
