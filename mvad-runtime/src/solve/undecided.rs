//! Crossings and misses the tolerances cannot decide.
//!
//! The integrator keeps each state within about sc_i = atol + rtol·|x_i| per step, so at the
//! tolerances asked for a guard's value at a point of the trajectory is known only to
//!
//! ```text
//!   δg = Σ_i |∂g/∂x_i| (atol + rtol |x_i|).
//! ```
//!
//! Where the trajectory meets a guard at a turning point — the dip search of
//! [`crate::event`] maximises the signed guard v between samples — the maximum v* decides
//! whether the event fires. If |v*| ≤ δg at the turning point it does not decide it: a state
//! off by its tolerance would fire the event (v* < 0: a near miss) or would not (v* ≥ 0: a
//! crossing by less than the error), and C jumps between the two answers. Both are reported
//! as `grazing`. δg is taken at the turning point, where an error that only shifts the time
//! (a clock z passing through a window (z − w)² ≤ 1: ∂g/∂z = 0 at the maximum) moves v* by
//! nothing. v* and δg are values of the guard at one instant, so the verdict does not depend
//! on the unit of time (the crossing cosine |ġ|/(|∇g||f| + |∂g/∂t|) mixes the rates of states
//! of different units, and a ceiling 1e-9 below a ball's apex grazed in seconds but not in
//! milliseconds); and a near miss had no verdict at all (no event, no diagnostic, the
//! one-sided answer C would have without the event).

use super::Driver;
use crate::event::Watch;
use crate::model::{At, HybridModel, ModelAlloc};
use crate::solution::{Diagnostic, DiagnosticKind};
use nalgebra::{allocator::Allocator, DefaultAllocator, Dim, OVector};

/// δg = Σᵢ |∂g/∂xᵢ| (atol + rtol |xᵢ|): what a guard with gradient `gx` may err by at the
/// state `x` when each state is kept within its tolerance (see the module doc).
pub(super) fn guard_tolerance<N: Dim>(
    gx: &OVector<f64, N>,
    x: &OVector<f64, N>,
    (atol, rtol): (f64, f64),
) -> f64
where
    DefaultAllocator: Allocator<N>,
{
    gx.iter()
        .zip(x.iter())
        .map(|(g, xi)| g.abs() * (atol + rtol * xi.abs()))
        .sum()
}

impl<M: HybridModel> Driver<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// After a scan whose dip search evaluated a guard's maximum ([`Scanner::peaked`]): every
    /// event whose highest maximum v* on the scanned piece lies no later than `until` (the
    /// piece's end) and the earliest crossing found, with |v*| ≤ δg at the turning point, gets
    /// a `grazing` diagnostic: a near miss at once, a crossing (the event is among those
    /// found) when it is applied ([`Driver::take_undecided`]), unless its cosine grazes.
    ///
    /// [`Scanner::peaked`]: crate::event::Scanner::peaked
    #[cold]
    #[inline(never)]
    pub(super) fn judge_peaks(&mut self, until: f64) {
        let (model, p) = (self.model, self.p);
        let (atol, rtol) = (self.opts.atol, self.opts.rtol);
        let first = self.scanner.found.iter().map(|c| c.t).fold(until, f64::min);
        // x at the turning point in `xs`, the scan's scratch (the scan is over).
        for i in 0..self.scanner.watched().len() {
            let w = self.scanner.watched()[i];
            let Watch::Event(k) = self.scanner.watch(w) else {
                continue;
            };
            let Some((tm, vm)) = self.scanner.peak(w) else {
                continue;
            };
            let fires = self.scanner.found.iter().any(|c| c.w == w && c.t <= first);
            if !(fires || (vm < 0.0 && tm <= first)) {
                continue;
            }
            self.integ.dense_x(tm, &mut self.xs);
            model.guard_grad(k, At::new(tm, &self.xs, p), &mut self.gx, &mut self.gp);
            let dg = guard_tolerance(&self.gx, &self.xs, (atol, rtol));
            if vm.abs() > dg {
                continue;
            }
            let name = self.event_name(k);
            let message = if vm < 0.0 {
                format!(
                    "near miss of event `{name}`: its guard turns back {:.3e} short of zero at \
                     t = {tm}, within the {dg:.3e} the tolerances allow it to err by there \
                     (Σ|∂g/∂xᵢ|(atol + rtol|xᵢ|)): whether it fires is not decided at these \
                     tolerances, and C and dC/dθ are the values without it",
                    -vm
                )
            } else {
                format!(
                    "event `{name}` grazes: the trajectory reaches its guard only at a turning \
                     point (t = {tm}), by {vm:.3e}, within the {dg:.3e} the tolerances allow \
                     the guard to err by there (Σ|∂g/∂xᵢ|(atol + rtol|xᵢ|)): whether it fires \
                     is not decided at these tolerances; t' is ill-conditioned"
                )
            };
            let d = Diagnostic {
                kind: DiagnosticKind::Grazing,
                t: tm,
                message,
            };
            if vm < 0.0 {
                self.diagnostics.push(d);
            } else {
                self.undecided.push((k, d));
            }
        }
    }

    /// The diagnostic [`Driver::judge_peaks`] left for event k's crossing, if any (the others
    /// of the instant are dropped with it when the last is taken: they belong to this step).
    #[inline]
    pub(super) fn take_undecided(&mut self, k: usize) -> Option<Diagnostic> {
        if self.undecided.is_empty() {
            return None;
        }
        self.take_undecided_cold(k)
    }

    #[cold]
    #[inline(never)]
    fn take_undecided_cold(&mut self, k: usize) -> Option<Diagnostic> {
        let i = self.undecided.iter().position(|(e, _)| *e == k)?;
        Some(self.undecided.swap_remove(i).1)
    }
}
