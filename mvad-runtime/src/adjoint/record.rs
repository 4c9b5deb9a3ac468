//! The forward record a backward sweep replays: the primal run's trajectory on every smooth
//! segment and what happened at every jump between them.
//!
//! The primal run (x and q only, no sensitivities) hands the record, through the event
//! loop's `Recorder`, three things:
//!
//! - **Steps.** Each accepted step [t₀, t₁] (cut at an event where one falls inside) keeps the
//!   integrator's dense output, a polynomial of degree D in θ = (t − t₀)/(t₁ − t₀) (D = 4 for
//!   Tsit5 and Rodas5P, 9 for Verner), as its values at the D + 1 Chebyshev points
//!   τ_j = t₀ + (t₁ − t₀)(1 − cos(jπ/D))/2. The barycentric formula
//!   x(t) = Σ_j (w_j/(t − τ_j)) x_j / Σ_j w_j/(t − τ_j), w_j = (−1)ʲ (halved at j = 0, D),
//!   reproduces that polynomial exactly up to rounding (the Lebesgue constant of these
//!   points is below 3 for D ≤ 9), so x(t) anywhere on a step is what the forward run's own
//!   dense output gives, at the order of the method.
//! - **Segments.** A smooth piece between two jumps: its mode, its frozen switch bits and the
//!   range of its steps (segments of length zero, between simultaneous events, are dropped).
//! - **Jumps.** A user event k or a switch flip j at t: x⁻, x⁺ (equal for a flip), the modes
//!   and the switch bits on both sides; everything else the transpose needs (f⁻, f⁺, ∇g, ℓ⁻,
//!   ℓ⁺, the costs) is recomputed from these.
//!
//! Memory: 8·(D + 1)·n bytes of nodes plus 32 bytes per step (40n + 32 for Tsit5 and
//! Rodas5P, 80n + 32 for Verner 9(8)); per jump 16n bytes of states plus about 100 bytes
//! (switch bits beyond 64 add 8 bytes per 64 on each side). [`Tape::bytes`] counts it.

use crate::model::Switches;
use std::ops::Range;
use std::sync::OnceLock;

/// Most nodes a step keeps (Verner's degree-9 dense output).
const MAX_NODES: usize = 10;

/// What fired at a jump.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JumpKind {
    /// User event k (its reset, mode switch and costs).
    Event(usize),
    /// Switching function σ_j crossed zero: bit j flips, the reset is the identity.
    Switch(usize),
}

/// One jump of the primal run, in the order it was applied.
#[derive(Clone, Debug, PartialEq)]
pub struct Jump {
    /// What fired.
    pub kind: JumpKind,
    /// t_k.
    pub t: f64,
    /// The mode before it.
    pub mode_before: usize,
    /// The mode after it.
    pub mode_after: usize,
    /// The switch bits before it (those f⁻ and ℓ⁻ are evaluated with).
    pub sw_before: Switches,
    /// The switch bits after it (those f⁺ and ℓ⁺ are evaluated with).
    pub sw_after: Switches,
    /// Offset of x⁻ (then x⁺) in `Tape::jump_x`.
    at: usize,
}

/// One smooth segment of the primal run.
#[derive(Clone, Debug, PartialEq)]
pub struct SegmentRec {
    /// Start time (0 or a jump time).
    pub t_start: f64,
    /// End time (a jump time or T).
    pub t_end: f64,
    /// Its mode.
    pub mode: usize,
    /// Its frozen switch bits.
    pub sw: Switches,
    /// Its steps (indices into the tape's steps).
    pub steps: Range<usize>,
}

/// A piece of the primal run, in time order.
#[derive(Clone, Debug, PartialEq)]
pub enum Item {
    /// A smooth segment.
    Segment(SegmentRec),
    /// A jump (user event or switch flip).
    Jump(Jump),
}

/// The dense output of one step: degree `deg` in θ, its `deg + 1` node values at `at`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct StepPoly {
    t0: f64,
    t1: f64,
    at: usize,
    deg: usize,
}

/// The state at the end of the run: t = T, x(T) (after any jump at T), the mode and bits.
#[derive(Clone, Debug, PartialEq)]
pub struct FinalState {
    /// T.
    pub t: f64,
    /// x(T).
    pub x: Vec<f64>,
    /// The mode at T.
    pub mode: usize,
    /// The switch bits at T.
    pub sw: Switches,
}

/// The record of a primal run (see the module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct Tape {
    n: usize,
    steps: Vec<StepPoly>,
    nodes: Vec<f64>,
    jump_x: Vec<f64>,
    items: Vec<Item>,
    open_start: f64,
    open_first: usize,
    fin: Option<FinalState>,
}

/// (1 − cos(jπ/D))/2 for D = 1..9, j = 0..=D: the Chebyshev points on [0, 1].
fn unit_nodes(deg: usize) -> &'static [f64] {
    static TABLE: OnceLock<[[f64; MAX_NODES]; MAX_NODES]> = OnceLock::new();
    let table = TABLE.get_or_init(|| {
        let mut t = [[0.0; MAX_NODES]; MAX_NODES];
        for (d, row) in t.iter_mut().enumerate().skip(1) {
            for (j, v) in row.iter_mut().enumerate().take(d + 1) {
                *v = 0.5 * (1.0 - (j as f64 * std::f64::consts::PI / d as f64).cos());
            }
            row[d] = 1.0;
        }
        t
    });
    &table[deg][..=deg]
}

impl StepPoly {
    /// Node j's time (τ₀ = t₀ and τ_D = t₁ exactly).
    #[inline]
    fn node(&self, j: usize) -> f64 {
        if j == self.deg {
            self.t1
        } else {
            self.t0 + (self.t1 - self.t0) * unit_nodes(self.deg)[j]
        }
    }
}

impl Tape {
    /// An empty record for n states.
    pub(crate) fn new(n: usize) -> Self {
        Tape {
            n,
            steps: Vec::new(),
            nodes: Vec::new(),
            jump_x: Vec::new(),
            items: Vec::new(),
            open_start: 0.0,
            open_first: 0,
            fin: None,
        }
    }

    /// Opens a segment at t (after a restart).
    pub(crate) fn open_segment(&mut self, t: f64) {
        self.open_start = t;
        self.open_first = self.steps.len();
    }

    /// Records [t0, t1] of a step whose dense output has degree `deg` (clamped to 1..=9):
    /// `dense(τ, out)` writes x(τ) into `out` (length n).
    pub(crate) fn record_step(
        &mut self,
        t0: f64,
        t1: f64,
        deg: usize,
        mut dense: impl FnMut(f64, &mut [f64]),
    ) {
        if t1 <= t0 {
            return;
        }
        let step = StepPoly {
            t0,
            t1,
            at: self.nodes.len(),
            deg: deg.clamp(1, MAX_NODES - 1),
        };
        let n = self.n;
        for j in 0..=step.deg {
            let start = self.nodes.len();
            self.nodes.resize(start + n, 0.0);
            dense(step.node(j), &mut self.nodes[start..]);
        }
        self.steps.push(step);
    }

    /// Closes the open segment at t in `mode` with bits `sw` (dropped if it has no steps).
    pub(crate) fn close_segment(&mut self, t: f64, mode: usize, sw: &Switches) {
        let end = self.steps.len();
        if end > self.open_first {
            self.items.push(Item::Segment(SegmentRec {
                t_start: self.open_start,
                t_end: t,
                mode,
                sw: sw.clone(),
                steps: self.open_first..end,
            }));
        }
        self.open_first = end;
    }

    /// Records a jump: what fired at t, x⁻ and x⁺, the modes and bits on both sides.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn jump(
        &mut self,
        kind: JumpKind,
        t: f64,
        x_before: &[f64],
        x_after: &[f64],
        modes: (usize, usize),
        sw_before: &Switches,
        sw_after: &Switches,
    ) {
        let at = self.jump_x.len();
        self.jump_x.extend_from_slice(x_before);
        self.jump_x.extend_from_slice(x_after);
        self.items.push(Item::Jump(Jump {
            kind,
            t,
            mode_before: modes.0,
            mode_after: modes.1,
            sw_before: sw_before.clone(),
            sw_after: sw_after.clone(),
            at,
        }));
    }

    /// Records the state at T.
    pub(crate) fn finish(&mut self, t: f64, x: &[f64], mode: usize, sw: &Switches) {
        self.fin = Some(FinalState {
            t,
            x: x.to_vec(),
            mode,
            sw: sw.clone(),
        });
    }

    /// Number of states n.
    pub fn nstates(&self) -> usize {
        self.n
    }

    /// The segments and jumps in time order.
    pub fn items(&self) -> &[Item] {
        &self.items
    }

    /// The state at T (None if the run did not reach T normally).
    pub fn final_state(&self) -> Option<&FinalState> {
        self.fin.as_ref()
    }

    /// (x⁻, x⁺) of a jump.
    pub fn jump_states(&self, j: &Jump) -> (&[f64], &[f64]) {
        let n = self.n;
        (
            &self.jump_x[j.at..j.at + n],
            &self.jump_x[j.at + n..j.at + 2 * n],
        )
    }

    /// Recorded steps.
    pub fn nsteps(&self) -> usize {
        self.steps.len()
    }

    /// Bytes held by the record (steps, nodes, jumps; the switch words beyond 64 included).
    pub fn bytes(&self) -> usize {
        let f = std::mem::size_of::<f64>();
        let sw_bytes = |s: &Switches| std::mem::size_of_val(s.high_words());
        self.steps.len() * std::mem::size_of::<StepPoly>()
            + (self.nodes.len() + self.jump_x.len()) * f
            + self.items.len() * std::mem::size_of::<Item>()
            + self
                .items
                .iter()
                .map(|i| match i {
                    Item::Segment(s) => sw_bytes(&s.sw),
                    Item::Jump(j) => sw_bytes(&j.sw_before) + sw_bytes(&j.sw_after),
                })
                .sum::<usize>()
    }

    /// x(t) on `seg` into `out` (length n) by the barycentric formula on the step holding t;
    /// `cursor` (a step index, kept between calls) makes a monotone sweep O(1) per call.
    /// Times outside the segment use its first or last step.
    pub fn state_at(&self, seg: &SegmentRec, t: f64, cursor: &mut usize, out: &mut [f64]) {
        let (first, last) = (seg.steps.start, seg.steps.end - 1);
        let mut k = (*cursor).clamp(first, last);
        while k > first && t < self.steps[k].t0 {
            k -= 1;
        }
        while k < last && t > self.steps[k].t1 {
            k += 1;
        }
        *cursor = k;
        self.eval_step(k, t, out);
    }

    /// The barycentric interpolant of step k at t.
    fn eval_step(&self, k: usize, t: f64, out: &mut [f64]) {
        let s = self.steps[k];
        let n = self.n;
        let node = |j: usize| &self.nodes[s.at + j * n..s.at + (j + 1) * n];
        for j in 0..=s.deg {
            if t == s.node(j) {
                out.copy_from_slice(node(j));
                return;
            }
        }
        out.fill(0.0);
        let mut den = 0.0;
        for j in 0..=s.deg {
            let mut w = if j % 2 == 0 { 1.0 } else { -1.0 };
            if j == 0 || j == s.deg {
                w *= 0.5;
            }
            let c = w / (t - s.node(j));
            den += c;
            for (o, v) in out.iter_mut().zip(node(j)) {
                *o += c * v;
            }
        }
        for o in out.iter_mut() {
            *o /= den;
        }
    }

    /// x(t) at a sample time into `out`, right-continuous: on the segment with
    /// t_start ≤ t < t_end, or x(T) (after any jump at T) for t = T. False (and `out`
    /// untouched) for a time outside [0, T] or a run that did not reach T.
    pub fn sample(&self, t: f64, out: &mut [f64]) -> bool {
        let Some(fin) = self.fin.as_ref() else {
            return false;
        };
        if t == fin.t {
            out.copy_from_slice(&fin.x);
            return true;
        }
        let seg = self.items.iter().find_map(|it| match it {
            Item::Segment(s) if s.t_start <= t && t < s.t_end => Some(s),
            _ => None,
        });
        let Some(seg) = seg else {
            return false;
        };
        let mut cursor =
            seg.steps.start + self.steps[seg.steps.clone()].partition_point(|s| s.t1 < t);
        self.state_at(seg, t, &mut cursor, out);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A polynomial of the recorded degree is reproduced to rounding anywhere on its step.
    #[test]
    fn nodes_reproduce_polynomials_of_their_degree() {
        let p = |t: f64| {
            [
                1.0 + t - 3.0 * t.powi(4) + 0.5 * t.powi(9),
                (2.0 * t).powi(4),
            ]
        };
        let mut tape = Tape::new(2);
        tape.open_segment(0.3);
        tape.record_step(0.3, 0.9, 9, |t, out| out.copy_from_slice(&p(t)));
        tape.close_segment(0.9, 0, &Switches::default());
        tape.finish(0.9, &p(0.9), 0, &Switches::default());
        let Item::Segment(seg) = &tape.items()[0] else {
            panic!("no segment");
        };
        let mut out = [0.0; 2];
        let mut cursor = 0;
        for i in 0..=50 {
            let t = 0.3 + 0.6 * i as f64 / 50.0;
            tape.state_at(seg, t, &mut cursor, &mut out);
            let want = p(t);
            for c in 0..2 {
                assert!(
                    (out[c] - want[c]).abs() < 1e-14,
                    "t {t}: {out:?} vs {want:?}"
                );
            }
        }
        // Right-continuous sampling, and x(T) at T.
        assert!(tape.sample(0.9, &mut out));
        assert_eq!(out, p(0.9));
        assert!(tape.sample(0.5, &mut out));
        assert!((out[1] - p(0.5)[1]).abs() < 1e-14);
        assert!(!tape.sample(0.1, &mut out));
        assert!(!tape.sample(1.0, &mut out));
    }
}
