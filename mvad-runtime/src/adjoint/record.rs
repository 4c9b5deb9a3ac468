//! The forward record a backward sweep replays: the primal run's trajectory on every smooth
//! segment and what happened at every jump between them.
//!
//! The primal run (x and q only, no sensitivities) hands the record, through the event
//! loop's `Recorder`, three things:
//!
//! - **Steps.** Each accepted step from t₀ with signed length h (the part of it before an
//!   event, where one falls inside) keeps the integrator's dense output, a polynomial of
//!   degree D in θ = (t − t₀)/h (D = 4 for Tsit5 and Rodas5P, 9 for Verner), as its monomial
//!   coefficients c₀ = x(t₀), c₁, …, c_D ([`crate::integrate::Integrator::dense_poly`]), and
//!   evaluates x(t) = c₀ + θ(c₁ + θ(c₂ + …)) by Horner's scheme: what the forward run's own
//!   dense output gives, at the order of the method. A component the step left unchanged
//!   comes back exactly: a stiff state sitting at its equilibrium u = w stays w − u = 0, which
//!   matters where the flow divides by a small parameter (a lag (w − u)/τ has
//!   ∂/∂τ = −(w − u)/τ², so a rounding error of u in the record, 1e-16, would be an error of
//!   1 in f_τ at τ = 1e-8).
//!
//! Times on a segment are **local**: s, the sum of the step lengths h taken since the
//! segment's start, which the record stores and [`Tape::state_at`] takes (s ≈ t − t_start).
//! Near t ≈ 2.5 absolute time is resolved to 4.4e-16, and across a transient of width 1e-8
//! (the stiff relay's lag) that is an error of 1e-7 in x(t); the primal run's own times are
//! rounded that way too (t += h), while its states advance by exactly h. The forward run
//! never looks its states up by time, so it does not see it; in s, which is resolved to
//! 1e-24 where the transient is and advances by the h the states did, neither error arises.
//! - **Segments.** A smooth piece between two jumps: its mode, its frozen switch bits and the
//!   range of its steps (segments of length zero, between simultaneous events, are dropped).
//! - **Jumps.** A user event k or a switch flip j at t: x⁻, x⁺ (equal for a flip), the modes
//!   and the switch bits on both sides; everything else the transpose needs (f⁻, f⁺, ∇g, ℓ⁻,
//!   ℓ⁺, the costs) is recomputed from these.
//!
//! - **State errors** (with `Options::global_error`): the primal run's global error estimate
//!   of x at each step's start, (r_x, α) with e_x = r_x + α f, and at each jump the
//!   displacement (d⁻, d⁺, δt) of the jump it applied from the exact one
//!   ([`crate::integrate::GlobalError::jump_shift`]); the sweep's estimate reads them
//!   (`integrate/adjoint_error.rs`).
//!
//! Memory: 8·(D + 1)·n bytes of nodes plus 32 bytes per step (40n + 32 for Tsit5 and
//! Rodas5P, 80n + 32 for Verner 9(8)); per jump 16n bytes of states plus about 100 bytes
//! (switch bits beyond 64 add 8 bytes per 64 on each side); with the global error estimate
//! 8(n + 1) bytes more per step and 8(2n + 1) per jump. [`Tape::bytes`] counts it.

use crate::model::Switches;
use std::ops::Range;

/// Most coefficients a step keeps (Verner's degree-9 dense output).
pub(crate) const MAX_COEFS: usize = 10;

/// What fired at a jump.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JumpKind {
    /// User event k at its occurrence j (its reset, mode switch and costs; j is the table row
    /// of an `at each` event, see [`crate::model::Trigger`]).
    Event(usize, usize),
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
    /// Its local length: the local time s of its end (≈ t_end − t_start).
    pub s_end: f64,
    /// Its steps (indices into the tape's steps).
    pub steps: Range<usize>,
}

impl SegmentRec {
    /// The local time s ≈ t − t_start of an absolute time t on this segment (exactly s_end
    /// at t_end).
    pub fn local(&self, t: f64) -> f64 {
        if t >= self.t_end {
            self.s_end + (t - self.t_end)
        } else {
            t - self.t_start
        }
    }
}

/// A piece of the primal run, in time order.
#[derive(Clone, Debug, PartialEq)]
pub enum Item {
    /// A smooth segment.
    Segment(SegmentRec),
    /// A jump (user event or switch flip).
    Jump(Jump),
}

/// The dense output of one step from local time `t0` with signed length `h`, recorded on
/// [lo, hi] (lo = t0; hi < t0 + h when an event cut the step): degree `deg` in
/// θ = (s − t0)/h, its `deg + 1` coefficient vectors at `at`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct StepPoly {
    lo: f64,
    hi: f64,
    t0: f64,
    h: f64,
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
    /// (r_x, α) at each step's start (n + 1 per step), or empty.
    state_errors: Vec<f64>,
    /// (d⁻, d⁺, δt) of each jump (2n + 1 per jump), or empty.
    jump_shifts: Vec<f64>,
    items: Vec<Item>,
    open_start: f64,
    open_first: usize,
    /// The local time reached on the open segment.
    clock: f64,
    fin: Option<FinalState>,
    /// The most bytes the record may hold ([`crate::solution::Options::max_record_bytes`]).
    budget: usize,
    /// The record passed `budget` at this time: it was dropped, and records nothing more.
    overflowed_at: Option<f64>,
}

impl Tape {
    /// An empty record for n states, without a memory budget.
    #[cfg(test)]
    pub(crate) fn new(n: usize) -> Self {
        Self::with_budget(n, usize::MAX)
    }

    /// An empty record for n states that holds at most `budget` bytes: past it, it drops what
    /// it holds and records nothing more ([`Tape::overflowed_at`]).
    pub(crate) fn with_budget(n: usize, budget: usize) -> Self {
        Tape {
            n,
            steps: Vec::new(),
            nodes: Vec::new(),
            jump_x: Vec::new(),
            state_errors: Vec::new(),
            jump_shifts: Vec::new(),
            items: Vec::new(),
            open_start: 0.0,
            open_first: 0,
            clock: 0.0,
            fin: None,
            budget,
            overflowed_at: None,
        }
    }

    /// When the record passed its budget (it then holds nothing), if it did.
    pub fn overflowed_at(&self) -> Option<f64> {
        self.overflowed_at
    }

    /// The bytes the record's buffers hold, counted as [`Tape::bytes`] counts them but
    /// without the switch words beyond 64 (O(1): checked at every step and jump).
    fn bytes_held(&self) -> usize {
        let f = std::mem::size_of::<f64>();
        self.steps.len() * std::mem::size_of::<StepPoly>()
            + (self.nodes.len() + self.jump_x.len()) * f
            + (self.state_errors.len() + self.jump_shifts.len()) * f
            + self.items.len() * std::mem::size_of::<Item>()
    }

    /// Past the budget: drops every buffer (their memory is freed) and records no more.
    fn check_budget(&mut self, t: f64) {
        if self.bytes_held() > self.budget {
            let (n, budget) = (self.n, self.budget);
            *self = Self::with_budget(n, budget);
            self.overflowed_at = Some(t);
        }
    }

    /// Opens a segment at t (after a restart).
    pub(crate) fn open_segment(&mut self, t: f64) {
        self.open_start = t;
        self.open_first = self.steps.len();
        self.clock = 0.0;
    }

    /// Records a step from `t0` (absolute) of signed length `h`, or its part up to `cut` (an
    /// event time inside it), whose dense output has degree `deg` ≤ 9: `coefs(m, out)`
    /// writes c_m (length n) into `out`, m = 0..=deg. In local time the step starts where
    /// the last one ended and lasts h (the states advanced by exactly h), or cut − t0.
    /// `err` is the primal run's state error (r_x, α) at the step's start, if it keeps one.
    pub(crate) fn record_step(
        &mut self,
        (t0, h): (f64, f64),
        cut: Option<f64>,
        deg: usize,
        mut coefs: impl FnMut(usize, &mut [f64]),
        err: Option<(&[f64], f64)>,
    ) {
        let len = match cut {
            Some(te) => te - t0,
            None => h,
        };
        if len.is_nan() || len <= 0.0 || h == 0.0 || self.overflowed_at.is_some() {
            return;
        }
        let start = self.clock;
        self.clock = start + len;
        let step = StepPoly {
            lo: start,
            hi: self.clock,
            t0: start,
            h,
            at: self.nodes.len(),
            deg: deg.min(MAX_COEFS - 1),
        };
        let n = self.n;
        for m in 0..=step.deg {
            let start = self.nodes.len();
            self.nodes.resize(start + n, 0.0);
            coefs(m, &mut self.nodes[start..]);
        }
        self.steps.push(step);
        if let Some((rx, alpha)) = err {
            self.state_errors.extend_from_slice(rx);
            self.state_errors.push(alpha);
        }
        self.check_budget(t0 + len);
    }

    /// Closes the open segment at t in `mode` with bits `sw` (dropped if it has no steps).
    pub(crate) fn close_segment(&mut self, t: f64, mode: usize, sw: &Switches) {
        if self.overflowed_at.is_some() {
            return;
        }
        let end = self.steps.len();
        if end > self.open_first {
            self.items.push(Item::Segment(SegmentRec {
                t_start: self.open_start,
                t_end: t,
                mode,
                sw: sw.clone(),
                s_end: self.clock,
                steps: self.open_first..end,
            }));
        }
        self.open_first = end;
    }

    /// Records a jump: what fired at t, x⁻ and x⁺, the modes and bits on both sides, and
    /// the displacement (d⁻, d⁺, δt) from the exact jump, if the run estimates it.
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
        shift: Option<(&[f64], &[f64], f64)>,
    ) {
        if self.overflowed_at.is_some() {
            return;
        }
        if let Some((d_minus, d_plus, dt)) = shift {
            self.jump_shifts.extend_from_slice(d_minus);
            self.jump_shifts.extend_from_slice(d_plus);
            self.jump_shifts.push(dt);
        }
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
        self.check_budget(t);
    }

    /// Records the state at T.
    pub(crate) fn finish(&mut self, t: f64, x: &[f64], mode: usize, sw: &Switches) {
        if self.overflowed_at.is_some() {
            return;
        }
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

    /// The primal run's state error (r_x, α) at the start of step k (an index
    /// [`Tape::state_at`] leaves in its cursor), if it was recorded.
    pub fn state_error(&self, k: usize) -> Option<(&[f64], f64)> {
        let n = self.n;
        let e = self.state_errors.get(k * (n + 1)..(k + 1) * (n + 1))?;
        Some((&e[..n], e[n]))
    }

    /// The displacement (d⁻, d⁺, δt) of jump `j` from the exact jump, if it was recorded.
    pub fn jump_shift(&self, j: &Jump) -> Option<(&[f64], &[f64], f64)> {
        let n = self.n;
        let k = j.at.checked_div(2 * n)?;
        let e = self
            .jump_shifts
            .get(k * (2 * n + 1)..(k + 1) * (2 * n + 1))?;
        Some((&e[..n], &e[n..2 * n], e[2 * n]))
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
            + (self.state_errors.len() + self.jump_shifts.len()) * f
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

    /// x at local time s (= t − t_start, see the module doc) on `seg` into `out` (length n)
    /// from the polynomial of the step holding s; `cursor` (a step index, kept between calls)
    /// makes a monotone sweep O(1) per call. Times outside the segment use its first or last
    /// step.
    pub fn state_at(&self, seg: &SegmentRec, t: f64, cursor: &mut usize, out: &mut [f64]) {
        let (first, last) = (seg.steps.start, seg.steps.end - 1);
        let mut k = (*cursor).clamp(first, last);
        while k > first && t < self.steps[k].lo {
            k -= 1;
        }
        while k < last && t > self.steps[k].hi {
            k += 1;
        }
        *cursor = k;
        self.eval_step(k, t, out);
    }

    /// How far below s (local time, on `seg`) a backward step may reach when it must not
    /// be longer than `m` times the shortest recorded step it overlaps: the furthest e with
    /// s − e ≤ m·min{length of the recorded steps meeting (e, s)}, looking no further than
    /// s − `h` (the step about to be tried; 0 for no limit), or −∞ when the segment's start
    /// is within reach. `cursor` as in [`Tape::state_at`]. See `adjoint::sweep`.
    pub fn backward_reach(
        &self,
        seg: &SegmentRec,
        s: f64,
        m: f64,
        h: f64,
        cursor: &mut usize,
    ) -> f64 {
        let (first, last) = (seg.steps.start, seg.steps.end - 1);
        let mut k = (*cursor).clamp(first, last);
        while k > first && s <= self.steps[k].lo {
            k -= 1;
        }
        while k < last && s > self.steps[k].hi {
            k += 1;
        }
        *cursor = k;
        let mut shortest = f64::INFINITY;
        for step in self.steps[first..=k].iter().rev() {
            shortest = shortest.min(step.hi - step.lo);
            let reach = m * shortest;
            if s - step.lo >= reach || (h > 0.0 && s - step.lo >= h) {
                return s - reach;
            }
        }
        f64::NEG_INFINITY
    }

    /// Step k's polynomial at t, by Horner's scheme in θ = (t − t0)/h.
    fn eval_step(&self, k: usize, t: f64, out: &mut [f64]) {
        let s = self.steps[k];
        let n = self.n;
        let theta = (t - s.t0) / s.h;
        let coef = |m: usize| &self.nodes[s.at + m * n..s.at + (m + 1) * n];
        out.copy_from_slice(coef(s.deg));
        for m in (0..s.deg).rev() {
            for (o, c) in out.iter_mut().zip(coef(m)) {
                *o = *o * theta + c;
            }
        }
    }

    /// Whether item i is a segment that starts at a switch crossing of a kink (item i − 1
    /// is a switch flip at its start): a sample at its start belongs to the segment before
    /// it (the left limit, see [`Tape::sample_switches`]).
    pub fn starts_at_switch(&self, i: usize) -> bool {
        match (i.checked_sub(1).map(|h| &self.items[h]), &self.items[i]) {
            (Some(Item::Jump(j)), Item::Segment(s)) => {
                matches!(j.kind, JumpKind::Switch(_)) && j.t == s.t_start
            }
            _ => false,
        }
    }

    /// The switch bits an observable sampled at t is evaluated with: those of the segment
    /// [`Tape::sample`] reads, except at a switch crossing of a kink, where the bits before
    /// the flip (the value at t⁻; x is continuous there); at T those at T.
    pub fn sample_switches(&self, t: f64) -> Option<&Switches> {
        let fin = self.fin.as_ref()?;
        if t == fin.t {
            return Some(&fin.sw);
        }
        let i = self
            .items
            .iter()
            .position(|it| matches!(it, Item::Segment(s) if s.t_start <= t && t < s.t_end))?;
        match (&self.items[i], i.checked_sub(1).map(|h| &self.items[h])) {
            (Item::Segment(s), Some(Item::Jump(j)))
                if s.t_start == t && self.starts_at_switch(i) =>
            {
                Some(&j.sw_before)
            }
            (Item::Segment(s), _) => Some(&s.sw),
            _ => None,
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
        let s = seg.local(t);
        let mut cursor =
            seg.steps.start + self.steps[seg.steps.clone()].partition_point(|st| st.hi < s);
        self.state_at(seg, s, &mut cursor, out);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The record evaluates each step's polynomial, picks the step that holds t, and samples
    /// right-continuously.
    #[test]
    fn steps_evaluate_their_polynomials() {
        // x(t) = (1 + 2θ − θ⁴, 3θ⁹) on the step from 0.3 of length 0.4 (θ = (t − 0.3)/0.4),
        // recorded on [0.3, 0.6] (cut by an event), then a constant step on [0.6, 0.9].
        let p = |t: f64| {
            let th = (t - 0.3) / 0.4;
            [1.0 + 2.0 * th - th.powi(4), 3.0 * th.powi(9)]
        };
        let mut c = [[0.0; 2]; 10];
        c[0][0] = 1.0;
        c[1][0] = 2.0;
        c[4][0] = -1.0;
        c[9][1] = 3.0;
        let mut tape = Tape::new(2);
        tape.open_segment(0.3);
        tape.record_step(
            (0.3, 0.4),
            Some(0.6),
            9,
            |m, out| out.copy_from_slice(&c[m]),
            None,
        );
        tape.record_step(
            (0.6, 0.3),
            None,
            0,
            |_, out| out.copy_from_slice(&[5.0, 6.0]),
            None,
        );
        tape.close_segment(0.9, 0, &Switches::default());
        tape.finish(0.9, &[5.0, 6.0], 0, &Switches::default());
        let Item::Segment(seg) = &tape.items()[0] else {
            panic!("no segment");
        };
        let mut out = [0.0; 2];
        let mut cursor = 0;
        for i in 0..=30 {
            let t = 0.3 + 0.3 * i as f64 / 30.0;
            tape.state_at(seg, seg.local(t), &mut cursor, &mut out);
            let want = p(t);
            for c in 0..2 {
                assert!(
                    (out[c] - want[c]).abs() < 1e-14,
                    "t {t}: {out:?} vs {want:?}"
                );
            }
        }
        tape.state_at(seg, seg.local(0.75), &mut cursor, &mut out);
        assert_eq!(out, [5.0, 6.0]);
        // Right-continuous sampling, x(T) at T, nothing outside [0, T].
        assert!(tape.sample(0.75, &mut out));
        assert_eq!(out, [5.0, 6.0]);
        assert!(tape.sample(0.45, &mut out));
        assert!((out[0] - p(0.45)[0]).abs() < 1e-14);
        assert!(tape.sample(0.9, &mut out));
        assert!(!tape.sample(0.1, &mut out));
        assert!(!tape.sample(1.0, &mut out));
    }
}
