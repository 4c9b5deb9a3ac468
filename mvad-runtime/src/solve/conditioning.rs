//! The driver's part of the global error estimate (the integrator carries it over the steps, see
//! `integrate/global_error.rs`): its jump at every user event and switch crossing, and at T the
//! estimated errors of C and dC/dθ, with an `ill_conditioned` diagnostic when either exceeds
//! [`ILL_CONDITIONED_FACTOR`] times the tolerance atol + rtol·|value|.
//!
//! The gradient's error is measured two ways, and the larger ratio is judged: with the
//! parameters weighed as the sensitivities' error control weighs them (column j by
//! w_j = |θ_j|, 1 for θ_j = 0), as the change of C it predicts for relative changes of θ
//! (max_j w_j |e_j| against max_j w_j |dC/dθ_j|), and unweighted, as the suite measures a
//! gradient's error (max_j |e_j| against max_j |dC/dθ_j|). The second catches an entry for a
//! tiny parameter that is wrong by orders of magnitude (dC/dτ of the stiff relay, τ = 1e-8,
//! from a sweep at rtol 1e-3), which the first scales away; forward mode's error control
//! weighs S by |θ_j|, adjoint mode's quadrature g is controlled unweighted.

use super::Driver;
use crate::integrate::{sens_weight, EventRounding, JumpOf, ResetSecant, Saltation};
use crate::model::{At, HybridModel, ModelAlloc, Occurrence, Point};
use crate::solution::{Diagnostic, DiagnosticKind, ErrorEstimate, ILL_CONDITIONED_FACTOR};
use nalgebra::{Const, DefaultAllocator, OMatrix, OVector};

/// How an estimate's jump takes the reset (see [`Saltation`]).
enum Reset {
    /// The identity (a switch crossing).
    Identity,
    /// R_x and R_t as the sensitivities' jump computed them.
    Jacobians,
    /// Without sensitivities: the secant of occurrence `.0`'s reset at time `.1`.
    Secant(Occurrence, f64),
}

impl<M: HybridModel> Driver<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// Carries the estimate through occurrence j of user event k at t. Expects what `apply_event` has computed
    /// up to the event's costs: x⁻ in `y.x`, x⁺ in `x_plus`, f⁻, f⁺, ∇g at x⁻ in `gx`, the old
    /// bits in `sw` and the new in `sw_next`; `rate` = ∇g·f⁻ + ∂g/∂t and ℓ⁺ = `l_plus`;
    /// `phi_t` = φ_t with φ_x in `cx` when `event_costs` evaluated them.
    pub(super) fn error_through_event(
        &mut self,
        k: usize,
        j: usize,
        t: f64,
        rate: f64,
        l_plus: f64,
        phi_t: Option<f64>,
    ) {
        let Some(zero) = self.estimate_at_jump() else {
            return;
        };
        let (model, p) = (self.model, self.p);
        let occ = Occurrence::new(k, j);
        let l_minus = self.running_cost_minus(t);
        if zero {
            // A zero estimate (only exact steps so far) jumps to zero: only the rounding, which
            // it takes with sensitivities only ([`Self::estimate_at_jump`]).
            let kind = self.jump_of(k);
            self.error_jump(Reset::Jacobians, None, (l_minus, l_plus), None, (t, kind));
            return;
        }
        // φ_t and φ_x as `event_costs` left them (with sensitivities and no qp, whose kinks
        // may take the cost's columns again), else evaluated here.
        let phi_t = match phi_t {
            Some(phi_t) if model.qps().is_empty() => Some(phi_t),
            _ => model.info().events[k].has_cost.then(|| {
                model.event_cost_grad(occ, At::new(t, &self.x_plus, p), &mut self.cx, &mut self.cp)
            }),
        };
        let reset = if self.sens {
            // R_x and R_t as `event_reset` computed them for the sensitivities.
            Reset::Jacobians
        } else {
            // Without sensitivities the estimate needs R only along its displacement: a
            // secant of the reset (one evaluation, never the p-long ∂R/∂θ of `reset_jac`).
            Reset::Secant(occ, t)
        };
        self.error_jump(
            reset,
            Some(rate),
            (l_minus, l_plus),
            phi_t,
            (t, self.jump_of(k)),
        );
    }

    /// Whether the estimate has anything to do at the jump being applied: `None` without an
    /// estimate, or when it is zero and the jump adds no rounding to it (t' = 0, or no
    /// sensitivities: `GlobalError::takes_event_rounding`); else whether it is zero.
    fn estimate_at_jump(&self) -> Option<bool> {
        let ge = self.integ.global_error()?;
        let dt = self.sens.then_some(&self.dt);
        ge.takes_event_rounding(dt).then(|| ge.is_zero())
    }

    /// How user event k's time was found ([`JumpOf`]).
    fn jump_of(&self, k: usize) -> JumpOf {
        match self.model.info().events[k].is_time_event() {
            true => JumpOf::TimeEvent,
            false => JumpOf::StateEvent,
        }
    }

    /// Carries the estimate through the crossing of switching function j at t (identity
    /// reset): x in `y.x`, f⁻ and f⁺ computed, the old bits in `sw` and the new in `sw_next`.
    pub(super) fn error_through_switch(&mut self, j: usize, t: f64) {
        let Some(zero) = self.estimate_at_jump() else {
            return;
        };
        let (model, p) = (self.model, self.p);
        let l_minus = self.running_cost_minus(t);
        let l_plus = if model.info().has_running_cost {
            model.running_cost(&self.sw_next, At::new(t, &self.y.x, p))
        } else {
            0.0
        };
        // `apply_switch` leaves ∇σ_j in `gx` only with sensitivities; a zero estimate needs
        // only the rounding, not the rate.
        let rate = (!zero).then(|| {
            let gt = model.switch_grad(j, At::new(t, &self.y.x, p), &mut self.gx, &mut self.gp);
            self.gx.dot(&self.f_minus) + gt
        });
        self.error_jump(
            Reset::Identity,
            rate,
            (l_minus, l_plus),
            None,
            (t, JumpOf::Switch),
        );
    }

    /// The estimate's jump with f⁻, f⁺ and ∇g from the driver's buffers, the reset as
    /// `reset` says (R_x, R_t from the driver's buffers, or the secant of R at x⁻ in `y.x`
    /// with x⁺ in `x_plus`), ġ = `rate`, (ℓ⁻, ℓ⁺) and, for an event cost, φ_t with φ_x in
    /// `cx`; then the jump's rounding at event time t (`kind`; a user event has x⁺ in
    /// `x_plus`, S⁺ in `s_plus`, R_θ in `rp`, a switch crossing S⁺ in `y.s`). Without
    /// `rate` (a zero estimate, whose linearised jump is zero) only the rounding.
    fn error_jump(
        &mut self,
        reset: Reset,
        rate: Option<f64>,
        (l_minus, l_plus): (f64, f64),
        phi_t: Option<f64>,
        (t, kind): (f64, JumpOf),
    ) {
        let event = kind != JumpOf::Switch;
        let (model, p) = (self.model, self.p);
        let (x_minus, x_plus) = (&self.y.x, &self.x_plus);
        let secant_at = |occ: Occurrence, t: f64| {
            move |d: &OVector<f64, M::N>,
                  dt: f64,
                  xs: &mut OVector<f64, M::N>,
                  out: &mut OVector<f64, M::N>| {
                xs.copy_from(x_minus);
                *xs += d;
                model.reset(occ, At::new(t + dt, xs, p), out);
                *out -= x_plus;
            }
        };
        let secant = match reset {
            Reset::Secant(occ, t) => Some(secant_at(occ, t)),
            _ => None,
        };
        let jacobians = matches!(reset, Reset::Jacobians);
        let s = Saltation {
            rx: jacobians.then_some(&self.rx),
            rt: jacobians.then_some(&self.rt),
            f_minus: &self.f_minus,
            f_plus: &self.f_plus,
            gx: &self.gx,
            rate: rate.unwrap_or(0.0),
            l_minus,
            l_plus,
            cost: phi_t.map(|phi_t| (&self.cx, phi_t)),
            secant: secant.as_ref().map(|f| f as &ResetSecant<'_, M::N>),
        };
        let rounding = EventRounding {
            t,
            kind,
            tols: (self.opts.atol, self.opts.rtol),
            x_minus: &self.y.x,
            x_plus: if event { &self.x_plus } else { &self.y.x },
            sens: self.sens.then_some(match event {
                true => (&self.dt, &self.s_plus, Some(&self.rp)),
                false => (&self.dt, &self.y.s, None),
            }),
        };
        if let Some(ge) = self.integ.global_error_mut() {
            if rate.is_some() {
                ge.jump(&s, self.sens);
            }
            ge.event_rounding(&s, &rounding);
        }
    }

    /// ℓ at (t, x⁻) under the old bits (0 without a running cost).
    fn running_cost_minus(&self, t: f64) -> f64 {
        if self.model.info().has_running_cost {
            self.model
                .running_cost(&self.sw, At::new(t, &self.y.x, self.p))
        } else {
            0.0
        }
    }

    /// The estimated errors at T of the run's C and dC/dθ (`grad`, meaningful with
    /// sensitivities), with x(T), S(T) and f(T); pushes the `ill_conditioned` diagnostic when they
    /// exceed what the tolerances ask for ([`judge`]), except in the adjoint's primal run.
    /// `None` when no estimate was carried.
    pub(super) fn error_at_end(
        &mut self,
        cost: f64,
        grad: &OVector<f64, M::P>,
        x_final: &OVector<f64, M::N>,
        s_final: &OMatrix<f64, M::N, M::P>,
        f_end: &OVector<f64, M::N>,
    ) -> Option<ErrorEstimate> {
        let (model, p, t_end, sens) = (self.model, self.p, self.t_end, self.sens);
        let info = model.info();
        let l_end = if info.has_running_cost {
            model.running_cost(&self.sw, At::new(t_end, x_final, p))
        } else {
            0.0
        };
        let phi_x = if info.has_final_cost {
            model.final_cost_grad(At::new(t_end, x_final, p), &mut self.cx, &mut self.cp);
            Some(&self.cx)
        } else {
            None
        };
        let mut e_grad = OVector::<f64, M::P>::zeros_generic(model.nparams(), Const::<1>);
        // Ṡ(T) = f_x S + f_θ and q̇_θ(T) = ℓ_x S + ℓ_θ less its mean q_θ(T)/T, for the time
        // shift of S at T (one evaluation per run; `s_plus` and `dt` are free after the last
        // event).
        if sens {
            let pt = Point::new(self.mode, &self.sw, t_end, x_final, p);
            model.rhs_sens(pt, s_final, &mut self.xs, &mut self.s_plus);
            self.dt.fill(0.0);
            if info.has_running_cost {
                let at = At::new(t_end, x_final, p);
                model.running_cost_value_grad(&self.sw, at, &mut self.gx, &mut self.dt);
                self.dt.gemv_tr(1.0, s_final, &self.gx, 1.0);
                if t_end > 0.0 {
                    self.dt.axpy(-1.0 / t_end, &self.integ.y().qp, 1.0);
                }
            }
        }
        let phase = sens.then_some((
            x_final,
            (self.opts.atol, self.opts.rtol),
            &self.s_plus,
            &self.dt,
        ));
        let e_cost =
            self.integ
                .global_error_mut()?
                .at_end(f_end, l_end, phi_x, sens, phase, &mut e_grad);
        let e_grad = sens.then(|| (e_grad.as_slice(), grad.as_slice()));
        let (estimate, diagnostic) = judge(
            (e_cost, cost),
            e_grad,
            p.as_slice(),
            (self.opts.atol, self.opts.rtol),
            t_end,
        );
        // The adjoint's primal run (at a fraction of the tolerances) is judged by the
        // adjoint, with the sweep's estimate, at the tolerances asked for.
        if !self.tape {
            self.diagnostics.extend(diagnostic);
        }
        Some(estimate)
    }
}

/// The estimate of a result and its judgement: `(e_cost, cost)` the estimated error of C and
/// C, `grad` (the estimated error of the gradient and the gradient, `None` when only C was
/// judged), θ and the tolerances asked for; the `ill_conditioned` diagnostic (at `t_end`) when
/// either error exceeds [`ILL_CONDITIONED_FACTOR`] times atol + rtol·|value| (the gradient's
/// weighed by |θ_j|, see the module doc). Forward mode and adjoint mode both judge here.
pub(crate) fn judge(
    (e_cost, cost): (f64, f64),
    grad: Option<(&[f64], &[f64])>,
    p: &[f64],
    (atol, rtol): (f64, f64),
    t_end: f64,
) -> (ErrorEstimate, Option<Diagnostic>) {
    let cost_ratio = e_cost.abs() / (atol + rtol * cost.abs());
    let weighted_max = |v: &[f64], weighted: bool| {
        v.iter()
            .zip(p)
            .map(|(g, th)| (g * if weighted { sens_weight(*th) } else { 1.0 }).abs())
            .fold(0.0, f64::max)
    };
    // (error, size, ratio) of the gradient, weighted and not; the larger ratio is judged.
    let measure = |weighted: bool| match grad {
        Some((e, g)) => {
            let (err, size) = (weighted_max(e, weighted), weighted_max(g, weighted));
            (err, size, err / (atol + rtol * size))
        }
        None => (0.0, 0.0, 0.0),
    };
    let (weighted, plain) = (measure(true), measure(false));
    let (g_err, g_size, gradient_ratio) = if plain.2 > weighted.2 {
        plain
    } else {
        weighted
    };
    let mut parts = Vec::new();
    if cost_ratio > ILL_CONDITIONED_FACTOR {
        parts.push(describe("C", e_cost.abs(), cost.abs(), cost_ratio));
    }
    if gradient_ratio > ILL_CONDITIONED_FACTOR {
        parts.push(describe("dC/dθ", g_err, g_size, gradient_ratio));
    }
    let diagnostic = (!parts.is_empty()).then(|| Diagnostic {
        kind: DiagnosticKind::IllConditioned,
        t: t_end,
        message: format!(
            "global error estimate of {} (rtol {rtol:e}, atol {atol:e}): the steps' \
             local errors reach T amplified, or not damped, by the flow, so local error \
             control does not bound the result; tighten rtol and compare",
            parts.join(" and of ")
        ),
    });
    let estimate = ErrorEstimate {
        cost: e_cost,
        gradient: grad.map(|(e, _)| e.to_vec()).unwrap_or_default(),
        cost_ratio,
        gradient_ratio,
    };
    (estimate, diagnostic)
}

/// "dC/dθ: 3.9e-3 relative, 2.6e5 × the tolerance".
fn describe(what: &str, err: f64, size: f64, ratio: f64) -> String {
    if size > 0.0 {
        format!(
            "{what}: {:.1e} relative, {ratio:.1e} × the tolerance",
            err / size
        )
    } else {
        format!("{what}: {err:.1e} absolute, {ratio:.1e} × the tolerance")
    }
}
