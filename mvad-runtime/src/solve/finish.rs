//! The end of a run: C and dC/dθ at T (see [`crate::reduce::final_terms`]), or at the limit
//! of an accumulation (see [`super::zeno`]), and the [`Solution`].

use super::zeno::ZENO_RATIOS;
use super::Driver;
use crate::adjoint::record::Tape;
use crate::error::SolveError;
use crate::model::{HybridModel, ModelAlloc, Point};
use crate::reduce::{final_terms, FinalWork};
use crate::solution::{Diagnostic, DiagnosticKind, Solution, Stats};
use nalgebra::{Const, DefaultAllocator, OVector};

impl<M: HybridModel> Driver<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// C = q(T) + Σφ_k + Φ and dC/dθ = q_θ(T) + Σ dφ_k/dθ + dΦ/dθ, x(T), S(T) and the work
    /// counters. The event table is the sink's business: `Solution::events` is left empty.
    /// The adjoint's tape, if kept, comes back with the solution (with its final state only
    /// when the run reached T without an accumulation).
    pub(super) fn finish(mut self) -> Result<(Solution, Option<Tape>), SolveError> {
        let (model, p, t_end, sens) = (self.model, self.p, self.t_end, self.sens);
        let mut fw = FinalWork::new(model);
        self.integ.close_step();
        let mut x_final = self.integ.y().x.clone();
        let mut s_final = self.integ.y().s.clone();
        let mut grad = OVector::<f64, M::P>::zeros_generic(model.nparams(), Const::<1>);
        let mut cost;
        let f_end;
        if let Some((t_star_geo, ratio)) = self.zeno_stop {
            // The segment up to the last event was closed when it fired.
            let acc = self.extrapolate_accumulation(
                t_star_geo,
                &mut fw,
                &mut x_final,
                &mut s_final,
                &mut grad,
            );
            cost = acc.cost;
            self.report_accumulation(acc.t_star, ratio);
            if let Some(rec) = &mut self.rec {
                rec.hold(t_end, &x_final, &s_final, self.mode, &self.sw);
            }
            // The state is at rest at T.
            f_end = OVector::<f64, M::N>::zeros_generic(model.nstates(), Const::<1>);
        } else {
            let y = self.integ.y();
            if let Some(rec) = &mut self.rec {
                rec.close_segment(t_end, self.mode, &self.sw);
                rec.finish(t_end, &y.x, self.mode, &self.sw);
            }
            cost = y.q + self.c_ev.value();
            if sens {
                grad.copy_from(&y.qp);
                grad += &self.g_ev;
            }
            model.rhs(Point::new(self.mode, &self.sw, t_end, &y.x, p), &mut fw.f);
            f_end = fw.f.clone();
        }
        cost += final_terms(
            model,
            p,
            &self.sw,
            t_end,
            &x_final,
            &s_final,
            &f_end,
            &self.dt_end,
            &mut fw,
            sens.then_some(&mut grad),
        );
        if !cost.is_finite() || (sens && !grad.iter().all(|v| v.is_finite())) {
            return Err(SolveError::NonFinite {
                t: t_end,
                what: "cost".into(),
            });
        }
        let error_estimate = self.error_at_end(cost, &grad, &x_final, &s_final, &f_end);
        let mut stats: Stats = self.integ.stats().clone();
        stats.events = self.nevents;
        stats.switch_crossings = self.switch_crossings;
        let sens_vec = |v: &[f64]| if sens { v.to_vec() } else { Vec::new() };
        let (trajectory, tape) = match self.rec {
            Some(rec) => rec.into_parts(),
            None => (None, None),
        };
        let sol = Solution {
            t_end,
            params: p.iter().copied().collect(),
            cost,
            gradient: sens_vec(grad.as_slice()),
            gradient_left: None,
            qp: Vec::new(),
            x_final: x_final.iter().copied().collect(),
            s_final: sens_vec(s_final.as_slice()),
            mode_final: self.mode,
            events: Vec::new(),
            diagnostics: self.diagnostics,
            error_estimate,
            stats,
            trajectory,
        };
        Ok((sol, tape))
    }

    /// The `zeno` diagnostic of a run that ended at an accumulation point t*.
    fn report_accumulation(&mut self, t_star: f64, ratio: f64) {
        let n = self.nevents;
        let message = if let Some(k) = self.stuck {
            format!(
                "after event `{}` at t = {t_star} the flow carries the state straight back through \
                 its guard: events accumulate there; the run ended at that time and the state \
                 is held at rest on [t, T]",
                self.event_name(k)
            )
        } else {
            format!(
                "events accumulate (dwell-time ratio {ratio:.4} over the last {ZENO_RATIOS} dwells): \
                 the run ended at the estimated accumulation time t* = {t_star} after {n} events; \
                 the tail was extrapolated (Aitken) and the state held at its limit on [t*, T]"
            )
        };
        self.diagnostics.push(Diagnostic {
            kind: DiagnosticKind::Zeno,
            t: t_star,
            message,
        });
    }
}
