//! Recording the trajectory (only with `Options::record`): x and S at [`TRAJ_NODES`]
//! equispaced nodes of every accepted step, filled from the integrator's dense output, and
//! the smooth segments (mode and switch bits) between events. Together with the event table
//! (x⁻, x⁺, t_k, dt_k/dθ per event) this is the forward record a backward pass replays.

use crate::integrate::{AugState, Forward, Integrator};
use crate::model::{HybridModel, ModelAlloc, Switches};
use crate::solution::{Segment, Trajectory, TRAJ_NODES};
use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

/// The trajectory being recorded and the segment currently open.
pub(super) struct Recorder {
    pub(super) traj: Trajectory,
    segment_start: f64,
    segment_first_step: usize,
}

impl Recorder {
    /// An empty record for n states and p parameters (p = 0: no sensitivities).
    pub(super) fn new(n: usize, p: usize) -> Self {
        Recorder {
            traj: Trajectory::new(n, p),
            segment_start: 0.0,
            segment_first_step: 0,
        }
    }

    /// Opens a segment at t (after a restart).
    pub(super) fn open_segment(&mut self, t: f64) {
        self.segment_start = t;
        self.segment_first_step = self.traj.len();
    }

    /// Records [t0, t1] of the integrator's current step from its dense output (before the
    /// step is truncated at an event). `tmp` is scratch space for one dense evaluation.
    pub(super) fn record_step<M: HybridModel>(
        &mut self,
        integ: &Integrator<Forward<'_, M>>,
        tmp: &mut AugState<M::N, M::P>,
        t0: f64,
        t1: f64,
    ) where
        DefaultAllocator: ModelAlloc<M::N, M::P>,
    {
        if t1 <= t0 {
            return;
        }
        let traj = &mut self.traj;
        traj.t0.push(t0);
        traj.t1.push(t1);
        for i in 0..TRAJ_NODES {
            let t = t0 + (t1 - t0) * i as f64 / (TRAJ_NODES - 1) as f64;
            integ.dense(t, tmp);
            traj.data.extend_from_slice(tmp.x.as_slice());
            if traj.p > 0 {
                traj.data.extend_from_slice(tmp.s.as_slice());
            }
        }
    }

    /// Closes the open segment at t, in `mode` with switch bits `sw` (empty segments, as
    /// between simultaneous events, are dropped).
    pub(super) fn close_segment(&mut self, t: f64, mode: usize, sw: &Switches) {
        let end_step = self.traj.len();
        if end_step > self.segment_first_step {
            self.traj.segments.push(Segment {
                t_start: self.segment_start,
                t_end: t,
                mode,
                switches: sw.clone(),
                first_step: self.segment_first_step,
                end_step,
            });
        }
    }

    /// Appends one step holding x and S constant from the last recorded time to `t_end`
    /// (the state at rest after an accumulation), as its own segment.
    pub(super) fn hold<N: Dim, P: Dim>(
        &mut self,
        t_end: f64,
        x: &OVector<f64, N>,
        s: &OMatrix<f64, N, P>,
        mode: usize,
        sw: &Switches,
    ) where
        DefaultAllocator: ModelAlloc<N, P>,
    {
        let traj = &mut self.traj;
        let t0 = traj.t1.last().copied().unwrap_or(0.0);
        if t_end <= t0 {
            return;
        }
        traj.t0.push(t0);
        traj.t1.push(t_end);
        let first = traj.len() - 1;
        for _ in 0..TRAJ_NODES {
            traj.data.extend_from_slice(x.as_slice());
            if traj.p > 0 {
                traj.data.extend_from_slice(s.as_slice());
            }
        }
        traj.segments.push(Segment {
            t_start: t0,
            t_end,
            mode,
            switches: sw.clone(),
            first_step: first,
            end_step: first + 1,
        });
    }
}
