//! The run's rounding in the global error estimate: further local errors, added where they are
//! made and transported by the same mechanism as the steps' errors (so a rounding error the
//! flow damps, or a saltation zeroes, is forgotten as a step's error is).
//!
//! Each source is taken as u = 2⁻⁵³ times the magnitudes of the operands it is formed from, with a fixed sign (in steady state the
//! same operands round the same way each time, so the errors add up rather than cancel):
//!
//! - each accepted step (`GlobalError::step_rounding`): Y₁ = Y₀ + h Σ bᵢkᵢ rounds each entry of
//!   x and q to u(|Y₀| + |h F₀|) (S and q_θ alike, left out: see there);
//! - each event (`GlobalError::event_rounding`), after its linearised jump: x⁺ to u|x⁺|; the
//!   event time is off by u|t| (a crossing located to the resolution of t, then the state
//!   snapped onto the guard: x⁺ off by f⁺·u|t|, a time shift; a time event's computed time or
//!   a switch crossing: by w·u|t|), and q by (ℓ⁻ − ℓ⁺)·u|t|; S⁺ = R_x S⁻ + R_θ + w t'ᵀ rounds to u(|S⁺| + |R_θ| + ρ_w|t'|ᵀ), where
//!   ρ_w = |R_x|ρ⁻ + |R_t| + ρ⁺ is the scale of w = R_x f⁻ + R_t − f⁺ as its operands are
//!   rounded, ρ± = |f±| + J̄‖x±‖∞ that of evaluating f± (J̄ the row sums of |f_x| at the last
//!   step: f's terms can cancel, so |f| alone does not measure its rounding); and
//!   q_θ's jump (ℓ⁻ − ℓ⁺)t' to u(|ℓ⁻| + |ℓ⁺|)|t'|.
//!
//! The event term is what bounds a gradient whose events move with θ at a rate that grows along
//! the run: with θ the period of an `every` event the j-th sample has t' = j, and in the
//! steady state of a sampled loop f⁻ ≈ f⁺ ≈ 0 is a cancellation whose rounding u·ρ_w·j sums to
//! u ρ_w N²/2 over N samples (x' = −x + u + 1, u = −2x every 0.01, dC/dperiod: error 2.9e-7 at
//! T = 900 at every rtol, estimated 7.1e-7).
//!
//! At T the component γ of e_x along f(T) (weights 1/(atol + rtol|xᵢ|)) is a time shift of the
//! run to first order; the sensitivities computed along x(t + γ) are S(t + γ), so it moves S
//! by γṠ(T) and q_θ by γ(q̇_θ(T) − q̄_θ), q̄_θ = q_θ(T)/T the mean rate (a shift made at t₀ moves
//! q_θ by γ(q̇_θ(T) − q̇_θ(t₀)); the mean stands for q̇_θ at the times the shifts were made). It is
//! taken only while |γ|‖f_x‖∞ ≤ 10⁻³ (near an equilibrium, f(T) ≈ 0, the component along f is
//! no shift). This is what bounds 10⁴ bounces of a ball: each impact is located to u|t|, the
//! phase errors add up (the flow neither damps nor amplifies a phase), and dC/de, whose S grows
//! like the bounce index, is read at a phase off by their sum (error 5.7e-2 of 1.0e6 at
//! T = 20000, estimated 0.20).
//!
//! A run whose steps are all exact carries no estimate (it is zero, and its events skip the
//! linearised jump): its events' rounding is kept pending, untransported (the exact steps'
//! flow is a function of θ alone, f_x = 0, so the errors stay as they are between events;
//! the jumps are taken as the identity), and only from events that move with θ (t' ≠ 0),
//! whose rounding can grow along the run; it starts the estimate at the first carried step or
//! once it exceeds the tolerance (from then on it is transported, and reaches the event and
//! running costs), or is added at T.

use super::{AugState, GlobalError, Saltation, PHASE_LINEAR};
use crate::model::ModelAlloc;
use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

/// The unit roundoff u = 2⁻⁵³ (ε in the formulas): an operation whose exact result is a
/// rounds to a(1 + δ), |δ| ≤ u.
const EPS: f64 = 0.5 * f64::EPSILON;

/// r += ε(|y| + |h f|) entrywise: the rounding of the update y + h·(…) with rate f.
fn add_rounding(r: &mut [f64], y: &[f64], f: &[f64], h: f64) {
    // Equal lengths up front, so the loop indexes without bounds checks.
    let (y, f) = (&y[..r.len()], &f[..r.len()]);
    for (i, r) in r.iter_mut().enumerate() {
        *r += EPS * (y[i].abs() + (h * f[i]).abs());
    }
}

/// (x(T), (atol, rtol), Ṡ(T), q̇_θ(T) − q_θ(T)/T) for the time shift of the sensitivities at T
/// ([`GlobalError::at_end`]).
pub type PhaseRates<'a, N, P> = (
    &'a OVector<f64, N>,
    (f64, f64),
    &'a OMatrix<f64, N, P>,
    &'a OVector<f64, P>,
);

/// What jumps at an event, and how the error u|t| of its time moves x⁺.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JumpOf {
    /// A state event: the crossing is located to u|t| and the state snapped onto the guard,
    /// so the jump is the exact one at a time off by δt, and x⁺ is off by −f⁺δt (a time
    /// shift).
    StateEvent,
    /// A time event, whose time is computed to u|t| and the state integrated to it: x⁺ is off
    /// by wδt, w = R_x f⁻ + R_t − f⁺.
    TimeEvent,
    /// A switch crossing (identity reset), located to u|t|: x⁺ is off by (f⁻ − f⁺)δt.
    Switch,
}

/// t', S⁺ and R_θ (`None`: zero) of an event's sensitivity jump ([`EventRounding`]).
pub type SensJump<'a, N, P> = (
    &'a OVector<f64, P>,
    &'a OMatrix<f64, N, P>,
    Option<&'a OMatrix<f64, N, P>>,
);

/// What the rounding of an event's jump is measured by ([`GlobalError::event_rounding`]),
/// beside its [`Saltation`].
pub struct EventRounding<'a, N: Dim, P: Dim>
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    /// The event time t (located to about ε|t|).
    pub t: f64,
    /// What jumps and how its time was found.
    pub kind: JumpOf,
    /// (atol, rtol): the tolerance the rounding pending in a zero estimate is measured by.
    pub tols: (f64, f64),
    /// x⁻ and x⁺.
    pub x_minus: &'a OVector<f64, N>,
    /// See `x_minus`.
    pub x_plus: &'a OVector<f64, N>,
    /// With sensitivities: t', S⁺ and R_θ (`None` for a switch crossing, whose R_θ = 0).
    pub sens: Option<SensJump<'a, N, P>>,
}

impl<N: Dim, P: Dim> GlobalError<N, P>
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    /// The rounding of the step from Y₀ with F₀ = F(t₀, Y₀): the update Y₁ = Y₀ + h Σ bᵢ kᵢ
    /// rounds each entry of x and q to about u(|Y₀| + |h F₀|), added to r. S and q_θ round
    /// alike, but are left out: u per step relative, which the flow amplifies as it does x's
    /// (whose share is carried), and on both cases of the module doc their share moves the
    /// estimate by less than 0.1% at 2–6% of E1's instructions.
    pub(super) fn step_rounding(&mut self, y0: &AugState<N, P>, f0: &AugState<N, P>, h: f64) {
        add_rounding(self.r.x.as_mut_slice(), y0.x.as_slice(), f0.x.as_slice(), h);
        self.r.q += EPS * (y0.q.abs() + (h * f0.q).abs());
    }

    /// The rounding of an event's jump (see the module doc), added to the estimate after its
    /// linearised jump [`GlobalError::jump`] with the same `s`: with ρ± = |f±| + J̄‖x±‖∞ the
    /// scale of the rounding of evaluating f± (J̄ the row sums of |f_x| of the last step) and
    /// ρ_w = |R_x|ρ⁻ + |R_t| + ρ⁺ that of w = R_x f⁻ + R_t − f⁺ (|R_x| = I for a switch and
    /// without sensitivities), and the event time off by δt = u|t| ([`JumpOf`]),
    ///
    /// ```text
    ///   r_x += u(|x⁺| + |t||v|),   v = f⁺ (state event), w (time event, switch),
    ///   r_q += u|t||ℓ⁻ − ℓ⁺|,   r_S += u(|S⁺| + |R_θ| + ρ_w |t'|ᵀ),   r_qθ += u(|ℓ⁻| + |ℓ⁺|)|t'|
    /// ```
    ///
    /// (|w| bounded by |f⁻| + |R_t| + |f⁺| for a reset whose R_x is not formed, without
    /// sensitivities).
    ///
    /// While the estimate is zero (only exact steps so far, whose flow is a function of θ
    /// alone: f_x = 0, so errors are carried unchanged between events) the rounding goes into
    /// a pending part, which is not transported through the jumps (taken as the identity
    /// there) and starts the estimate when the first step is carried or once it exceeds the
    /// tolerance atol + rtol·max‖x⁺‖∞ of x (or of S, with max‖S⁺‖∞), or is added at T: below
    /// the tolerance it cannot reach the `ill_conditioned` threshold (10³ times it) unless a
    /// jump amplifies it 10³-fold, and a run of exact steps and 10⁶ events (the queue) is not
    /// slowed by carrying it through every jump. There only events that move with θ add to it
    /// (with sensitivities, t' ≠ 0): the others add u|x⁺|, u|S⁺|, which over 10⁶ events stay
    /// 10⁻¹⁰ of x and S, below any alarm. While pending, its share in the event costs and the
    /// running cost is left out.
    pub fn event_rounding(&mut self, s: &Saltation<'_, N>, e: &EventRounding<'_, N, P>) {
        if !self.takes_event_rounding(e.sens.map(|(dt, _, _)| dt)) {
            return;
        }
        let GlobalError {
            r,
            pending,
            zero,
            jac_rows: rows,
            xs,
            w,
            ..
        } = self;
        let target = if *zero { pending } else { r };
        let (fm, fp) = (s.f_minus.as_slice(), s.f_plus.as_slice());
        let rt = |i: usize| s.rt.map_or(0.0, |rt| rt[i]);
        // xs = |v|: the time error δt moves x⁺ by v δt.
        match (e.kind, s.rx) {
            (JumpOf::StateEvent, _) => xs.copy_from(s.f_plus),
            (JumpOf::Switch, _) => xs.zip_zip_apply(s.f_minus, s.f_plus, |v, a, b| *v = a - b),
            (JumpOf::TimeEvent, Some(rx)) => {
                xs.gemv(1.0, rx, s.f_minus, 0.0);
                for (i, v) in xs.as_mut_slice().iter_mut().enumerate() {
                    *v += rt(i) - fp[i];
                }
            }
            (JumpOf::TimeEvent, None) => {
                for (i, v) in xs.as_mut_slice().iter_mut().enumerate() {
                    *v = fm[i].abs() + rt(i).abs() + fp[i].abs();
                }
            }
        }
        let t = e.t.abs();
        let tx = target.x.as_mut_slice();
        for ((r, x), v) in tx.iter_mut().zip(e.x_plus.iter()).zip(xs.iter()) {
            *r += EPS * (x.abs() + t * v.abs());
        }
        target.q += EPS * t * (s.l_minus - s.l_plus).abs();
        let Some((dt, s_plus, rp)) = e.sens else {
            return;
        };
        if *zero {
            let scale = &mut self.pending_scale;
            *scale = (scale.0.max(e.x_plus.amax()), scale.1.max(s_plus.amax()));
        }
        // xs = ρ⁻, w = ρ_w.
        let (xm, xp) = (e.x_minus.amax(), e.x_plus.amax());
        for (i, rho) in xs.as_mut_slice().iter_mut().enumerate() {
            *rho = fm[i].abs() + rows[i] * xm;
        }
        match s.rx {
            Some(rx) => {
                w.fill(0.0);
                for (j, col) in rx.column_iter().enumerate() {
                    for (wi, rij) in w.iter_mut().zip(col.iter()) {
                        *wi += rij.abs() * xs[j];
                    }
                }
            }
            None => w.copy_from(xs),
        }
        for (i, wi) in w.as_mut_slice().iter_mut().enumerate() {
            *wi += fp[i].abs() + rows[i] * xp + rt(i).abs();
        }
        let n = w.len();
        let l = s.l_minus.abs() + s.l_plus.abs();
        let cols = target.s.as_mut_slice().chunks_exact_mut(n);
        for (j, (col, sp)) in cols.zip(s_plus.as_slice().chunks_exact(n)).enumerate() {
            let d = dt[j].abs();
            for (i, (r, v)) in col.iter_mut().zip(sp).enumerate() {
                let r_theta = rp.map_or(0.0, |rp| rp[(i, j)].abs());
                *r += EPS * (v.abs() + r_theta + w[i] * d);
            }
            target.qp[j] += EPS * l * d;
        }
        let (atol, rtol) = e.tols;
        let (x_scale, s_scale) = self.pending_scale;
        if self.zero
            && (self.pending.x.amax() > atol + rtol * x_scale
                || self.pending.s.amax() > atol + rtol * s_scale)
        {
            self.start_from_pending();
        }
    }

    /// Whether an event whose time moves with θ at t' (`None` without sensitivities) adds its
    /// rounding ([`GlobalError::event_rounding`]): always, but to a zero estimate only with
    /// t' ≠ 0.
    pub fn takes_event_rounding(&self, dt: Option<&OVector<f64, P>>) -> bool {
        !self.zero || dt.is_some_and(|dt| dt.iter().any(|&d| d != 0.0))
    }

    /// Moves the pending rounding into the estimate, which it starts (no longer zero).
    pub(super) fn start_from_pending(&mut self) {
        self.r.x += &self.pending.x;
        self.r.q += self.pending.q;
        self.r.s += &self.pending.s;
        self.r.qp += &self.pending.qp;
        self.pending.x.fill(0.0);
        self.pending.q = 0.0;
        self.pending.s.fill(0.0);
        self.pending.qp.fill(0.0);
        self.pending_scale = (0.0, 0.0);
        self.zero = false;
    }

    /// The time shift at T (see the module doc): γ, the component of e_x = r_x (α already
    /// materialised) along f = f(T) in the weights 1/(atol + rtol|xᵢ|), moves S by γṠ(T) and
    /// q_θ by γ(q̇_θ(T) − q̄_θ), when |γ|‖f_x‖∞ ≤ `PHASE_LINEAR`.
    pub(super) fn phase_at_end(&mut self, f: &OVector<f64, N>, phase: PhaseRates<'_, N, P>) {
        let (x, (atol, rtol), s_dot, qp_dot) = phase;
        let (mut fw, mut ff) = (0.0, 0.0);
        for ((fi, ri), xi) in f.iter().zip(self.r.x.iter()).zip(x.iter()) {
            let w = 1.0 / (atol + rtol * xi.abs());
            fw += w * w * fi * ri;
            ff += w * w * fi * fi;
        }
        let gamma = if ff > 0.0 && ff.is_finite() {
            fw / ff
        } else {
            0.0
        };
        // A time shift only while it is short against the flow's time scale 1/‖f_x‖∞, so
        // that S(T + γ) − S(T) = γṠ(T) to first order (near an equilibrium, where
        // f(T) ≈ 0, the component along f is no shift).
        if gamma.is_finite() && gamma.abs() * self.jac_rows.amax() <= PHASE_LINEAR {
            crate::integrate::aug::axpy_slice(self.r.s.as_mut_slice(), gamma, s_dot.as_slice());
            self.r.qp.axpy(gamma, qp_dot, 1.0);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Const, Matrix1, Vector1, Vector2};

    /// A zero estimate (no step carried) keeps an event's rounding pending: nothing from an
    /// event with t' = 0, u(|S⁺| + ρ_w|t'|) from one with t' ≠ 0 (ρ_w = |R_x||f⁻| + |f⁺| = 2
    /// here, J̄ = 0), until the pending S exceeds atol + rtol·max|S⁺|; then it starts the
    /// estimate with exactly what was pending.
    #[test]
    fn a_zero_estimate_keeps_its_events_rounding_pending_until_the_tolerance() {
        let mut ge = GlobalError::new(Const::<1>, Const::<1>);
        let (f, rx, gx) = (Vector1::new(1.0), Matrix1::new(1.0), Vector1::new(0.0));
        let (x, s_plus) = (Vector1::new(1.0), Matrix1::new(1.0));
        let s = Saltation {
            rx: Some(&rx),
            rt: None,
            f_minus: &f,
            f_plus: &f,
            gx: &gx,
            rate: 1.0,
            l_minus: 0.0,
            l_plus: 0.0,
            cost: None,
            secant: None,
        };
        let tols = (1e-10, 1e-8);
        let event = |dt| EventRounding {
            t: 1.0,
            kind: JumpOf::TimeEvent,
            tols,
            x_minus: &x,
            x_plus: &x,
            sens: Some((dt, &s_plus, None)),
        };
        let still = Vector1::new(0.0);
        assert!(!ge.takes_event_rounding(Some(&still)));
        ge.event_rounding(&s, &event(&still));
        assert!(ge.is_zero());
        assert_eq!(ge.pending.s[0], 0.0);
        let moving = Vector1::new(1e6);
        let per_event = EPS * (1.0 + 2.0 * 1e6);
        let tol = tols.0 + tols.1 * 1.0;
        let mut events = 0;
        while ge.is_zero() {
            ge.event_rounding(&s, &event(&moving));
            events += 1;
            assert!(events < 10_000, "never started");
        }
        assert_eq!(events, (tol / per_event).floor() as usize + 1);
        let started = ge.r.s[0];
        assert!((started - events as f64 * per_event).abs() < 1e-12 * started);
        assert_eq!(ge.pending.s[0], 0.0);
    }

    /// At T the component γ of e_x along f moves q_θ by γ(q̇_θ(T) − q̄_θ) and S by γṠ(T), while
    /// |γ|‖f_x‖∞ ≤ 10⁻³; a larger γ (f ≈ 0, an equilibrium) is no time shift and moves nothing.
    #[test]
    fn the_phase_at_the_end_moves_the_sensitivities_by_the_same_shift() {
        let f = Vector2::new(3.0, -1.0);
        let x = Vector2::new(1.0, 2.0);
        let s_dot = nalgebra::Matrix2x1::new(5.0, 7.0);
        let qp_dot = Vector1::new(11.0);
        for (gamma, moved) in [(2e-4, true), (2e-2, false)] {
            let mut ge = GlobalError::new(Const::<2>, Const::<1>);
            ge.zero = false;
            ge.jac_rows = Vector2::new(1.0, 0.5);
            // e_x = γ f plus a part orthogonal to f in the weights (equal here: rtol = 0).
            ge.r.x = f * gamma + Vector2::new(1.0, 3.0) * 1e-9;
            ge.phase_at_end(&f, (&x, (1.0, 0.0), &s_dot, &qp_dot));
            let want = if moved { gamma } else { 0.0 };
            assert!(
                (ge.r.qp[0] - want * 11.0).abs() < 1e-15,
                "{gamma}: {}",
                ge.r.qp[0]
            );
            assert!(
                (ge.r.s[1] - want * 7.0).abs() < 1e-15,
                "{gamma}: {}",
                ge.r.s[1]
            );
        }
    }
}
