//! Steps short enough for the watched functions, not only for the states.
//!
//! The error control sizes a step by the states' local error; the scanner then samples each
//! watched function at a few points of the step. A guard that varies much faster than the
//! states — an explicit carrier sin(ωt) of a PWM, sin(ωx) of a shaft angle, any guard on a
//! segment of a constant flow, where one exact step spans the whole segment — can cross zero
//! and come back between two samples, and aliasing makes the samples look smooth. Such a
//! step is cut until every watched function that is not an affine guard (an affine guard
//! moves with the states, whose error is controlled; near-tangential dips are the scanner's
//! job) is resolved on it: with v and v̇ = d·(∇g·f + ∂g/∂t) at the step's ends, the cubic
//! Hermite interpolant H must reproduce v at the interior quarter points,
//!
//! ```text
//!   max_i |v(t_i) − H(t_i)| ≤ RESOLUTION · (max v − min v) + 64 ε max |v|
//! ```
//!
//! (max and min over the ends and the interior points), unless, on the piece first asked
//! about, it keeps to one side of zero by more than [`FAR`] times its range, defect and rates'
//! swing together ([`keeps_off_zero`]: its defect is then rounding, which for a qp's slack
//! computed from large terms is far above 64 ε |v|). For a smooth v the defect is O(h⁴ v⁗), far
//! below the range of its values over the step; for a v that oscillates within the step the
//! end slopes, which are of the order of h⁻¹ times the range for each oscillation, drive H far
//! outside the range of the samples (aliasing can make the samples look smooth, the slopes
//! cannot). A piece of the step that fails is cut to a quarter until it passes, until a failing
//! function stands still on the cut (every sample the same double: [`Check::Still`]) or until
//! the cut reaches the resolution of t. A piece no cut resolves is rounding or a kink, not an
//! oscillation, and is scanned whole. The step is scanned piece by piece on its dense output
//! (nothing is integrated again, and the state is cut from the dense output only at a crossing,
//! as always); each piece starts at twice the length of the last one taken (not of a sliver a
//! step's end cut short).

use super::{time_resolution, Driver};
use crate::integrate::zero_rows;
use crate::model::{At, HybridModel, ModelAlloc, Point};
use nalgebra::DefaultAllocator;

/// The largest Hermite defect, relative to the range of the values over the step, a resolved
/// watched function may show.
const RESOLUTION: f64 = 0.1;

/// How far from zero, in multiples of all it varies by on a piece, a watched function is
/// resolved whatever its Hermite defect ([`keeps_off_zero`]).
const FAR: f64 = 1024.0;

/// Cuts a piece may take before it is scanned as it is (each cuts it to a quarter).
const MAX_CUTS: usize = 40;

/// A passing piece ended by its step's end and shorter than this many resolutions of t
/// (2²⁰ · 16 ulp) is a sliver: it leaves the next piece's length as it was.
const SLIVER: f64 = 1_048_576.0;

/// Interior points of the check (at the quarters of the step).
const POINTS: usize = 3;

/// Per-run state of the check: the length of the next piece to try and scratch per watched
/// function.
#[derive(Clone, Debug)]
pub(super) struct Resolution {
    /// Twice the last piece taken (∞ until one was cut).
    next: f64,
    /// v and v̇ of each function at the start of the piece being checked.
    v0: Vec<f64>,
    s0: Vec<f64>,
    /// v and v̇ at the end of the last piece checked, which the next piece starts from.
    v1: Vec<f64>,
    s1: Vec<f64>,
    /// The time of `v1`, `s1` when they hold for every function and the state has not jumped
    /// since (NaN otherwise: see [`Resolution::forget`]).
    end: f64,
}

impl Resolution {
    /// Scratch for the longest list of functions to resolve in any mode of `watch` (nothing
    /// allocated when there is none: every watched function an affine guard).
    pub(super) fn new(watch: &[super::ModeWatch]) -> Self {
        let n = watch.iter().map(|m| m.unresolved.len()).max().unwrap_or(0);
        Resolution {
            next: f64::INFINITY,
            v0: vec![0.0; n],
            s0: vec![0.0; n],
            v1: vec![0.0; n],
            s1: vec![0.0; n],
            end: f64::NAN,
        }
    }

    /// Sets the next piece's length to twice that of [t0, t1], the piece just taken, unless
    /// it is a sliver: a piece the step's end (`t_step`) cut short to under [`SLIVER`]
    /// resolutions of t (10⁻¹⁷ left of a step) does not shorten the next piece, whose
    /// successors would crawl on at twice that, pieces of a few ulps of t that pass or fail
    /// by the rounding of t (a run that never ended).
    fn grow(&mut self, t0: f64, t1: f64, t_step: f64) {
        let grown = 2.0 * (t1 - t0);
        let sliver = t1 == t_step && t1 - t0 < SLIVER * time_resolution(t1);
        self.next = if sliver { grown.max(self.next) } else { grown };
    }

    /// Forgets the values at the end of the last piece (the state, mode or bits changed).
    pub(super) fn forget(&mut self) {
        self.end = f64::NAN;
    }
}

/// Whether a function whose samples on the `whole` piece the check is first asked about
/// (not one of its cuts) lie in [lo, hi], with Hermite `defect` and end rates that swing it
/// by `swing` = h (|v̇₀| + |v̇₁|) over the piece, keeps to one side of zero by more than
/// [`FAR`] times all of these together. Such a function crosses nothing on the piece (a
/// crossing would need a swing that neither the values nor the rates show), and what fails
/// the check there is its rounding, which comes from the terms it is computed from and can be
/// far above 64 ε |v| (a qp's slack of 2 computed from terms of order k x = 170): cutting
/// would only crawl. Not on a cut: there a value at the rounding of zero (10⁻¹⁶) is far from
/// zero by the measure of a piece of 10⁻²⁰.
fn keeps_off_zero(lo: f64, hi: f64, defect: f64, swing: f64, whole: bool) -> bool {
    let gap = if lo > 0.0 {
        lo
    } else if hi < 0.0 {
        -hi
    } else {
        return false;
    };
    whole && gap > FAR * ((hi - lo) + defect + swing)
}

/// What the check of one piece found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Check {
    /// Every function resolved.
    Resolved,
    /// Some function is not: cut the piece.
    Unresolved,
    /// Some function is not, and stands still on the piece (every sample the same double)
    /// while its rates move it: the piece is below the rounding of its values, and no shorter
    /// cut can resolve it either.
    Still,
}

/// The cubic Hermite interpolant with values v₀, v₁ and slopes s₀, s₁ on a step of length h,
/// at the fraction θ of the step.
fn hermite(v0: f64, s0: f64, v1: f64, s1: f64, h: f64, theta: f64) -> f64 {
    let (t2, t3) = (theta * theta, theta * theta * theta);
    (2.0 * t3 - 3.0 * t2 + 1.0) * v0
        + (t3 - 2.0 * t2 + theta) * h * s0
        + (3.0 * t2 - 2.0 * t3) * v1
        + (t3 - t2) * h * s1
}

impl<M: HybridModel> Driver<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// The end t₁ ≤ `t_step` of the next piece, from t₀, of the step that ends at `t_step`
    /// on which every watched function of the current mode that is not an affine guard is
    /// resolved (see the module doc).
    #[inline]
    pub(super) fn resolved_end(&mut self, t0: f64, t_step: f64) -> f64 {
        if self.watch[self.mode].unresolved.is_empty() {
            return t_step;
        }
        self.resolved_piece(t0, t_step)
    }

    /// [`Driver::resolved_end`] where some watched function is not an affine guard.
    fn resolved_piece(&mut self, t0: f64, t_step: f64) -> f64 {
        let mode = self.mode;
        let n = self.watch[mode].unresolved.len();
        let r = &mut self.resolution;
        if t0 == r.end {
            // The last piece (of this step or the last) ended here and passed: its end values
            // are this piece's start values.
            std::mem::swap(&mut r.v0, &mut r.v1);
            std::mem::swap(&mut r.s0, &mut r.s1);
        } else {
            if t0 == self.integ.t_prev() {
                self.xs.copy_from(&self.integ.y_prev().x);
            } else {
                self.integ.dense_x(t0, &mut self.xs);
            }
            for i in 0..n {
                let w = self.watch[mode].unresolved[i];
                let (v, s) = self.value_and_rate(w, t0, i == 0);
                self.resolution.v0[i] = v;
                self.resolution.s0[i] = s;
            }
        }
        let whole = t_step.min(t0 + self.resolution.next);
        let mut t1 = whole;
        self.resolution.end = f64::NAN;
        for cut in 0..MAX_CUTS {
            match self.resolved_on(t0, t1, t_step, cut == 0) {
                Check::Resolved => {
                    self.resolution.end = t1;
                    self.resolution.grow(t0, t1, t_step);
                    return t1;
                }
                Check::Still => break,
                Check::Unresolved => {}
            }
            let cut = t0 + 0.25 * (t1 - t0);
            if cut - t0 <= 4.0 * time_resolution(t0) {
                break;
            }
            t1 = cut;
        }
        // No cut resolved it: what still fails on a piece too short for its values to move
        // (a value at the rounding of zero, 10⁻¹⁶ from terms of order 1), a 4⁻⁴⁰ part of the
        // piece or one at the resolution of t is the rounding of v or a kink of v, not an
        // oscillation between the samples. The piece is scanned whole and the next grows from
        // it as from one that passed. Carrying the cut on would crawl, each piece 4⁻⁴⁰ of the
        // last or, from t = 0, at the resolution of t, which is absolute there; a cut that
        // passes only at 10⁻²⁹, where 64 ε |v| of such a value exceeds its rates' swing,
        // would set pieces that crawl at that scale (a run of minutes); and keeping the next
        // piece's length would crawl at it for as long as the rounding lasts.
        self.resolution.grow(t0, whole, t_step);
        whole
    }

    /// Whether every unresolved-class watched function passes the Hermite check on [t0, t1]
    /// (its values and rates at t0 in `v0`, `s0`; those at t1 are left in `v1`, `s1`) or, on
    /// the `whole` piece (not one of its cuts), [`keeps_off_zero`]; and, if one does not,
    /// whether it stands still there ([`Check::Still`]).
    fn resolved_on(&mut self, t0: f64, t1: f64, t_step: f64, whole: bool) -> Check {
        let mode = self.mode;
        let h = t1 - t0;
        if t1 == t_step {
            self.xs.copy_from(&self.integ.y().x);
        } else {
            self.integ.dense_x(t1, &mut self.xs);
        }
        let n = self.watch[mode].unresolved.len();
        let mut eval_f = true;
        for i in 0..n {
            let w = self.watch[mode].unresolved[i];
            if self.zeno.holds_event(w) {
                // Not watched while its accumulation is held.
                continue;
            }
            // The rates at t1 need f there once; `value_and_rate` evaluates it on the first.
            let (v1, s1) = self.value_and_rate(w, t1, eval_f);
            eval_f = false;
            (self.resolution.v1[i], self.resolution.s1[i]) = (v1, s1);
            let (v0, s0) = (self.resolution.v0[i], self.resolution.s0[i]);
            let mut defect: f64 = 0.0;
            let (mut lo, mut hi) = (v0.min(v1), v0.max(v1));
            for q in 1..=POINTS {
                let theta = q as f64 / (POINTS + 1) as f64;
                let t = t0 + theta * h;
                self.integ.dense_x(t, &mut self.xe);
                let nev = self.scanner.nevents;
                let v = Self::signed(self.model, self.p, nev, &self.sw, w, t, &self.xe);
                defect = defect.max((v - hermite(v0, s0, v1, s1, h, theta)).abs());
                (lo, hi) = (lo.min(v), hi.max(v));
            }
            // The rounding of v is no defect. NaN is the scanner's to report.
            let floor = 64.0 * f64::EPSILON * lo.abs().max(hi.abs());
            if defect > RESOLUTION * (hi - lo) + floor
                && !keeps_off_zero(lo, hi, defect, h * (s0.abs() + s1.abs()), whole)
            {
                return if lo == hi {
                    Check::Still
                } else {
                    Check::Unresolved
                };
            }
        }
        Check::Resolved
    }

    /// The signed watched value v of function w at (t, `self.xs`) and its rate
    /// v̇ = ±(∇g·f + ∂g/∂t), with f = f(t, `self.xs`) (the masked flow during a hold)
    /// evaluated into `self.work` when `eval_f` (else the f already there).
    fn value_and_rate(&mut self, w: usize, t: f64, eval_f: bool) -> (f64, f64) {
        let (model, p) = (self.model, self.p);
        let nev = self.scanner.nevents;
        if eval_f {
            model.rhs(
                Point::new(self.mode, &self.sw, t, &self.xs, p),
                &mut self.work,
            );
            zero_rows(&mut self.work, &self.held);
        }
        let v = Self::signed(model, p, nev, &self.sw, w, t, &self.xs);
        let rate = if w < nev {
            let gt = model.guard_grad(w, At::new(t, &self.xs, p), &mut self.gx, &mut self.gp);
            model.info().events[w].direction.sign() * (self.gx.dot(&self.work) + gt)
        } else {
            let j = w - nev;
            let st = model.switch_grad(j, At::new(t, &self.xs, p), &mut self.gx, &mut self.gp);
            let s = self.gx.dot(&self.work) + st;
            if self.sw.get(j) {
                -s
            } else {
                s
            }
        };
        (v, rate)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hermite_reproduces_cubics() {
        // v(t) = 1 − 2t + 3t² − t³ on [0, 2]: v₀ = 1, v₁ = 1, v̇₀ = −2, v̇₁ = −2 + 12 − 12 = −2.
        let v = |t: f64| 1.0 - 2.0 * t + 3.0 * t * t - t * t * t;
        for theta in [0.25, 0.5, 0.75] {
            let h = hermite(1.0, -2.0, v(2.0), -2.0, 2.0, theta);
            assert!((h - v(2.0 * theta)).abs() < 1e-14);
        }
    }
}
