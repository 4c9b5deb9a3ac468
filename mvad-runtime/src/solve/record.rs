//! The forward record of a run, kept by the event loop when asked: the trajectory
//! (`Options::record`: x and S at [`TRAJ_NODES`] equispaced nodes of every accepted step,
//! filled from the integrator's dense output, and the smooth segments between events) and,
//! for an adjoint sweep, the [`Tape`] (every step's dense output at its own degree, and the
//! jumps with the states, modes and switch bits on both sides; see [`crate::adjoint::record`]).

use crate::adjoint::record::{JumpKind, Tape};
use crate::integrate::{AugState, Forward, GlobalError, Integrator};
use crate::model::{HybridModel, ModelAlloc, Switches};
use crate::solution::{Segment, SwitchCrossing, Trajectory, TRAJ_NODES};
use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

/// The records being kept and the segment currently open.
pub(super) struct Recorder {
    traj: Option<Trajectory>,
    tape: Option<Tape>,
    segment_start: f64,
    segment_first_step: usize,
    /// A constant step over the unresolved tail of an accumulation (see
    /// [`Recorder::bridge`]), which the next segment opens with: (its start, its index).
    bridge: Option<(f64, usize)>,
}

impl Recorder {
    /// Empty records for n states and p parameters (p = 0: no sensitivities): the trajectory
    /// when `traj`, the adjoint's tape when `tape` (of at most that many bytes, see
    /// [`Tape::with_budget`]).
    pub(super) fn new(n: usize, p: usize, traj: bool, tape: Option<usize>) -> Self {
        Recorder {
            traj: traj.then(|| Trajectory::new(n, p)),
            tape: tape.map(|budget| Tape::with_budget(n, budget)),
            segment_start: 0.0,
            segment_first_step: 0,
            bridge: None,
        }
    }

    /// The adjoint's tape passed its memory budget: the run it records is handed over to
    /// forward mode, so it need not go on.
    pub(super) fn tape_overflowed(&self) -> bool {
        self.tape
            .as_ref()
            .is_some_and(|tape| tape.overflowed_at().is_some())
    }

    /// The records: (trajectory, tape).
    pub(super) fn into_parts(self) -> (Option<Trajectory>, Option<Tape>) {
        (self.traj, self.tape)
    }

    /// Opens a segment at t (after a restart), or at the start of a pending bridge step.
    pub(super) fn open_segment(&mut self, t: f64) {
        self.segment_start = t;
        if let Some(traj) = &self.traj {
            self.segment_first_step = traj.len();
        }
        if let Some((t0, first)) = self.bridge.take() {
            (self.segment_start, self.segment_first_step) = (t0, first);
        }
        if let Some(tape) = &mut self.tape {
            tape.open_segment(t);
        }
    }

    /// Records [t0, t1] of the integrator's current step from its dense output (before the
    /// step is truncated at an event). `tmp` is scratch space for one dense evaluation,
    /// `poly` for the coefficients of one dense polynomial (the tape's; `MAX_COEFS` vectors).
    pub(super) fn record_step<M: HybridModel>(
        &mut self,
        integ: &Integrator<Forward<'_, M>>,
        tmp: &mut AugState<M::N, M::P>,
        poly: &mut [OVector<f64, M::N>],
        t0: f64,
        t1: f64,
    ) where
        DefaultAllocator: ModelAlloc<M::N, M::P>,
    {
        if t1 <= t0 {
            return;
        }
        if let Some(tape) = &mut self.tape {
            let deg = integ.dense_poly(poly);
            let step = (integ.t_prev(), integ.last_step_size());
            let cut = (t1 != integ.t()).then_some(t1);
            let err = integ
                .global_error()
                .map(|ge| (ge.state_error().0.as_slice(), ge.state_error().1));
            tape.record_step(
                step,
                cut,
                deg,
                |m, out| out.copy_from_slice(poly[m].as_slice()),
                err,
            );
        }
        let Some(traj) = &mut self.traj else {
            return;
        };
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
        if let Some(tape) = &mut self.tape {
            tape.close_segment(t, mode, sw);
        }
        let Some(traj) = &mut self.traj else {
            return;
        };
        let end_step = traj.len();
        if end_step > self.segment_first_step {
            traj.segments.push(Segment {
                t_start: self.segment_start,
                t_end: t,
                mode,
                switches: sw.clone(),
                first_step: self.segment_first_step,
                end_step,
            });
        }
    }

    /// A jump the event loop applied at t: what fired, x⁻ and x⁺, the modes (before, after)
    /// and the switch bits on both sides (for the tape; the trajectory has its event table);
    /// `ge` the run's global error estimate, which has just been carried through the jump
    /// (its displacement goes on the tape).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn jump<N: Dim, P: Dim>(
        &mut self,
        kind: JumpKind,
        t: f64,
        x_before: &OVector<f64, N>,
        x_after: &OVector<f64, N>,
        modes: (usize, usize),
        sw_before: &Switches,
        sw_after: &Switches,
        ge: Option<&GlobalError<N, P>>,
    ) where
        DefaultAllocator: ModelAlloc<N, P>,
    {
        if let Some(tape) = &mut self.tape {
            let (a, b) = (x_before.as_slice(), x_after.as_slice());
            let shift = ge.map(|ge| {
                let (dm, dp, dt) = ge.jump_shift();
                (dm.as_slice(), dp.as_slice(), dt)
            });
            tape.jump(kind, t, a, b, modes, sw_before, sw_after, shift);
        }
    }

    /// A switch crossing of kink j at t (for the trajectory: the measure's atoms of the
    /// observables that jump there); `dt` is t' (empty without sensitivities).
    pub(super) fn crossing<N: Dim>(
        &mut self,
        j: usize,
        t: f64,
        x: &OVector<f64, N>,
        dt: &[f64],
        sw: (&Switches, &Switches),
    ) where
        DefaultAllocator: nalgebra::allocator::Allocator<N>,
    {
        if let Some(traj) = &mut self.traj {
            traj.crossings.push(SwitchCrossing {
                t,
                switch: j,
                x: x.as_slice().to_vec(),
                dt: dt.to_vec(),
                before: sw.0.clone(),
                after: sw.1.clone(),
            });
        }
    }

    /// The run reached T with state x in `mode` under bits `sw` (for the tape).
    pub(super) fn finish<N: Dim>(&mut self, t: f64, x: &OVector<f64, N>, mode: usize, sw: &Switches)
    where
        DefaultAllocator: nalgebra::allocator::Allocator<N>,
    {
        if let Some(tape) = &mut self.tape {
            tape.finish(t, x.as_slice(), mode, sw);
        }
    }

    /// Appends one step holding x and S constant from the last recorded time to `t_end`:
    /// the unresolved tail [t_k, t*] of an accumulation, as its limit (x*, dx*/dθ). It opens
    /// the segment of the hold that follows (see [`Recorder::open_segment`]), so the
    /// segments stay contiguous.
    pub(super) fn bridge<N: Dim, P: Dim>(
        &mut self,
        t_end: f64,
        x: &OVector<f64, N>,
        s: &OMatrix<f64, N, P>,
    ) where
        DefaultAllocator: ModelAlloc<N, P>,
    {
        let Some(traj) = &mut self.traj else {
            return;
        };
        let t0 = traj.t1.last().copied().unwrap_or(0.0);
        if t_end <= t0 {
            return;
        }
        self.bridge = Some((t0, traj.len()));
        traj.t0.push(t0);
        traj.t1.push(t_end);
        for _ in 0..TRAJ_NODES {
            traj.data.extend_from_slice(x.as_slice());
            if traj.p > 0 {
                traj.data.extend_from_slice(s.as_slice());
            }
        }
    }
}
