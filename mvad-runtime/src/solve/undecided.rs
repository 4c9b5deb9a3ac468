//! Crossings and misses the tolerances cannot decide.
//!
//! The integrator keeps each state within about sc_i = atol + rtol·|x_i| per step, so at the
//! tolerances asked for a guard is known only to
//!
//! ```text
//!   δg = Σ_i |∂g/∂x_i| (atol + rtol |x_i|).
//! ```
//!
//! Where the trajectory meets a guard at a turning point — the dip search of
//! [`crate::event`] maximises the signed guard v between samples — the maximum v* decides
//! whether the event fires. If |v*| ≤ δg it does not decide it: a state off by its
//! tolerance would fire the event (v* < 0: a near miss) or would not (v* ≥ 0: a crossing by
//! less than the error), and C jumps between the two answers. Both are reported as
//! `grazing`. v* and δg are values of the guard at one instant, so the verdict does not
//! depend on the unit of time (the crossing cosine |ġ|/(|∇g||f| + |∂g/∂t|) mixes the rates of
//! states of different units, and a ceiling 1e-9 below a ball's apex grazed in seconds but
//! not in milliseconds); and a near miss had no verdict at all (no event, no diagnostic, the
//! one-sided answer C would have without the event).

use super::Driver;
use crate::event::Watch;
use crate::model::{At, HybridModel, ModelAlloc};
use crate::solution::{Diagnostic, DiagnosticKind};
use nalgebra::{DefaultAllocator, OVector};

impl<M: HybridModel> Driver<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// δg of event k's guard at (t, x): Σ_i |∂g/∂x_i| (atol + rtol |x_i|) (see the module
    /// doc). Leaves ∇g in `self.gx`.
    fn guard_uncertainty(&mut self, k: usize, t: f64, x: &OVector<f64, M::N>) -> f64 {
        let (atol, rtol) = (self.opts.atol, self.opts.rtol);
        self.model
            .guard_grad(k, At::new(t, x, self.p), &mut self.gx, &mut self.gp);
        self.gx
            .iter()
            .zip(x.iter())
            .map(|(g, xi)| g.abs() * (atol + rtol * xi.abs()))
            .sum()
    }

    /// After a scan whose dip search turned back short of a guard ([`Scanner::missed`]):
    /// every event whose highest maximum v* < 0 on the scanned piece lies before `until` (the
    /// earliest crossing found, or the piece's end) and within its guard's uncertainty,
    /// −v* ≤ δg, gets a `grazing` diagnostic (a near miss).
    ///
    /// [`Scanner::missed`]: crate::event::Scanner::missed
    #[cold]
    #[inline(never)]
    pub(super) fn report_near_misses(&mut self, until: f64) {
        let until = self.scanner.found.iter().map(|c| c.t).fold(until, f64::min);
        let mut x = self.xs.clone();
        for i in 0..self.scanner.watched().len() {
            let w = self.scanner.watched()[i];
            let Watch::Event(k) = self.scanner.watch(w) else {
                continue;
            };
            let Some((tm, vm)) = self.scanner.peak(w) else {
                continue;
            };
            if vm >= 0.0 || tm > until {
                continue;
            }
            self.integ.dense_x(tm, &mut x);
            let dg = self.guard_uncertainty(k, tm, &x);
            if -vm <= dg {
                let message = format!(
                    "near miss of event `{}`: its guard turns back {:.3e} short of zero at t = {tm}, \
                     within the {dg:.3e} the tolerances allow it to err by (Σ|∂g/∂xᵢ|(atol + \
                     rtol|xᵢ|)): whether it fires is not decided at these tolerances, and C and \
                     dC/dθ are the values without it",
                    self.event_name(k),
                    -vm
                );
                self.diagnostics.push(Diagnostic {
                    kind: DiagnosticKind::Grazing,
                    t: tm,
                    message,
                });
            }
        }
    }

    /// Whether state event k, firing at t from x⁻ = `self.y.x`, was reached only at the top of
    /// a dip by v* ≥ 0 within its guard's uncertainty δg: Some((v*, δg)) then (see the module
    /// doc), reported by [`Driver::report_undecided_crossing`].
    pub(super) fn undecided_crossing(&mut self, k: usize, t: f64) -> Option<(f64, f64)> {
        let (_, vm) = self.scanner.peak(k).filter(|&(_, v)| v >= 0.0)?;
        let x = self.y.x.clone();
        let dg = self.guard_uncertainty(k, t, &x);
        (vm <= dg).then_some((vm, dg))
    }

    /// The `grazing` diagnostic of an undecided crossing of event k at t (see
    /// [`Driver::undecided_crossing`]).
    #[cold]
    #[inline(never)]
    pub(super) fn report_undecided_crossing(&mut self, k: usize, t: f64, vm: f64, dg: f64) {
        let message = format!(
            "event `{}` grazes: the trajectory reaches its guard only at a turning point, by \
             {vm:.3e}, within the {dg:.3e} the tolerances allow the guard to err by \
             (Σ|∂g/∂xᵢ|(atol + rtol|xᵢ|)): whether it fires is not decided at these tolerances; \
             t' is ill-conditioned",
            self.event_name(k)
        );
        self.diagnostics.push(Diagnostic {
            kind: DiagnosticKind::Grazing,
            t,
            message,
        });
    }
}
