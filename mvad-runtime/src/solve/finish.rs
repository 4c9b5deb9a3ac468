//! The end of a run: C and dC/dθ at T (see [`crate::reduce::final_terms`]), or at the limit
//! of an accumulation (see [`super::zeno`]), and the [`Solution`].

use super::zeno::{Hold, ZENO_RATIOS};
use super::Driver;
use crate::adjoint::record::Tape;
use crate::error::{SolveError, Time};
use crate::integrate::zero_rows;
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
        self.y.copy_from(self.integ.y());
        if let Some(rec) = &mut self.rec {
            rec.close_segment(t_end, self.mode, &self.sw);
            rec.finish(t_end, &self.y.x, self.mode, &self.sw);
        }
        for h in self.zeno.take_holds() {
            self.report_accumulation(&h, None);
        }
        let x_final = self.y.x.clone();
        let s_final = self.y.s.clone();
        let mut cost = self.y.q + self.c_ev.value();
        let mut grad = OVector::<f64, M::P>::zeros_generic(model.nparams(), Const::<1>);
        if sens {
            grad.copy_from(&self.y.qp);
            grad += &self.g_ev;
        }
        // f(T): the masked flow if states are held at the limit of an accumulation.
        model.rhs(
            Point::new(self.mode, &self.sw, t_end, &x_final, p),
            &mut fw.f,
        );
        zero_rows(&mut fw.f, &self.held);
        let f_end = fw.f.clone();
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
        if sens {
            self.qp_kinks_at_end(&x_final, &s_final, &f_end, &mut grad);
        }
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
        // A run that passed through an accumulation is not swept back (its tape holds a jump
        // to the limit that no event made).
        let tape = tape.filter(|_| !self.zeno.passed());
        let sol = Solution {
            t_end,
            dt_end: self.dt_end.iter().copied().collect(),
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

    /// The `zeno` diagnostic of the accumulation `h` (of event k's occurrences at t*, or at
    /// a single instant when stuck on the guard): the states it constrains held at the limit
    /// on [t*, T] or, when `released_at` is τ, until events at τ moved them off (the run went
    /// on from there); the others followed their flow.
    pub(super) fn report_accumulation(&mut self, h: &Hold<M>, released_at: Option<f64>) {
        let info = self.model.info();
        let name = self.event_name(h.event);
        let (t_star, ratio, n) = (Time(h.t_star), h.ratio, h.events);
        let span = match released_at {
            None => "[t*, T]".to_string(),
            Some(tau) => format!(
                "[t*, {}], where an event moved them off and the run went on",
                Time(tau)
            ),
        };
        let held: Vec<String> = (0..h.constrained.len())
            .filter(|&i| h.constrained[i])
            .map(|i| format!("`{}`", info.states[i]))
            .collect();
        let free = if held.len() == h.constrained.len() {
            String::new()
        } else {
            "; the other states follow their flow".to_string()
        };
        let held = held.join(", ");
        let message = if h.stuck {
            format!(
                "after event `{name}` at t* = {t_star} the flow carries the state straight back \
                 through its guard: events accumulate there; states {held} are held at rest on \
                 {span}{free}"
            )
        } else {
            format!(
                "events of `{name}` accumulate (dwell-time ratio {ratio:.4} over the last \
                 {ZENO_RATIOS} dwells) at the estimated accumulation time t* = {t_star} after {n} \
                 events; the tail was extrapolated (Aitken) and states {held} are held at its \
                 limit on {span}{free}"
            )
        };
        self.diagnostics.push(Diagnostic {
            kind: DiagnosticKind::Zeno,
            t: t_star.0,
            message,
        });
    }
}
