//! The transposes of the forward event map: how λ and dC/dθ cross a jump backwards.
//!
//! ## A user event
//! Forwards (DESIGN.md, `solve/jump.rs`), with ġ = g_x f⁻ + g_t:
//!
//! ```text
//!   t'  = −(g_x S⁻ + g_θ) / ġ
//!   S⁺  = R_x S⁻ + R_θ + (R_x f⁻ + R_t − f⁺) t'
//!   dC += w [(ℓ⁻ − ℓ⁺) t' + φ_x (S⁺ + f⁺ t') + φ_t t' + φ_θ]
//! ```
//!
//! (w the cost's cotangent). What comes after the event contributes λ⁺ᵀS⁺ (λ⁺ the adjoint just
//! after it), so the event and everything after it contribute, with λ̃ = λ⁺ + w φ_xᵀ,
//!
//! ```text
//!   λ̃ᵀS⁺ + w(φ_x f⁺ + φ_t + ℓ⁻ − ℓ⁺) t' + w φ_θ
//!   = λ̃ᵀR_x S⁻ + λ̃ᵀR_θ + c t' + w φ_θ,
//!   c = λ̃ᵀ(R_x f⁻ + R_t − f⁺) + w(φ_x f⁺ + φ_t + ℓ⁻ − ℓ⁺)
//!     = (R_xᵀλ̃)·f⁻ + λ̃ᵀR_t − λ⁺·f⁺ + w(φ_t + ℓ⁻ − ℓ⁺),
//! ```
//!
//! and substituting t' leaves a term linear in S⁻ and one in θ alone:
//!
//! ```text
//!   λ⁻     = R_xᵀλ̃ − (c/ġ) g_xᵀ
//!   dC/dθ += R_θᵀλ̃ − (c/ġ) g_θ + w φ_θ .
//! ```
//!
//! R_xᵀλ̃, R_θᵀλ̃ and λ̃ᵀR_t are one [`crate::model::ModelAdjoint::reset_vjp`]; g_x, g_θ, φ_x,
//! φ_θ are gradients: nothing of size n×p is formed, so the work per event is O(n + p)
//! beyond the model's own. ġ = 0 (a tangential crossing) is the same error forward mode
//! reports.
//!
//! ## A switch flip
//! The identity reset in the same mode, bits b⁻ → b⁺ (f⁻, ℓ⁻ under b⁻; f⁺, ℓ⁺ under b⁺):
//! S⁺ = S⁻ + (f⁻ − f⁺) t', dC += w (ℓ⁻ − ℓ⁺) t', t' = −(σ_x S⁻ + σ_θ)/σ̇, σ̇ = σ_x f⁻ + σ_t, so
//!
//! ```text
//!   c = λ⁺·(f⁻ − f⁺) + w(ℓ⁻ − ℓ⁺),   λ⁻ = λ⁺ − (c/σ̇) σ_xᵀ,   dC/dθ −= (c/σ̇) σ_θ .
//! ```
//!
//! Simultaneous jumps are undone in the reverse of the order they were applied in.

use super::record::{Jump, JumpKind};
use crate::error::SolveError;
use crate::integrate::{AdjointError, LamGrad};
use crate::model::{At, HybridModel, ModelAlloc, Occurrence, Point, VjpOutput};
use nalgebra::{Const, DefaultAllocator, Dim, OVector};

/// Scratch for the transposes (allocated once per sweep).
pub(super) struct JumpWork<M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    xm: OVector<f64, M::N>,
    xp: OVector<f64, M::N>,
    f_minus: OVector<f64, M::N>,
    f_plus: OVector<f64, M::N>,
    gx: OVector<f64, M::N>,
    gp: OVector<f64, M::P>,
    mu: OVector<f64, M::N>,
    vx: OVector<f64, M::N>,
    vp: OVector<f64, M::P>,
    /// The estimate remainder's products (see [`transpose_jump_and_remainder`]).
    vx_rem: OVector<f64, M::N>,
    vp_rem: OVector<f64, M::P>,
    cx: OVector<f64, M::N>,
    cp: OVector<f64, M::P>,
    /// What the last [`transpose_jump_and_remainder`] applied, for [`shift_error`]: the
    /// event-time coefficient c/ġ and c's part that does not read f± or ℓ±, λ̃ᵀR_t + wφ_t
    /// (0 for a switch flip). `vx` still holds R_xᵀλ̃ (λ⁺ for a switch flip), `gx`, `gp`
    /// the crossing's gradient.
    ratio: f64,
    c_fixed: f64,
}

impl<M: HybridModel> JumpWork<M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// Buffers for `model`.
    pub(super) fn new(model: &M) -> Self {
        let (n, p) = (model.nstates(), model.nparams());
        let vn = || OVector::<f64, M::N>::zeros_generic(n, Const::<1>);
        let vp = || OVector::<f64, M::P>::zeros_generic(p, Const::<1>);
        JumpWork {
            xm: vn(),
            xp: vn(),
            f_minus: vn(),
            f_plus: vn(),
            gx: vn(),
            gp: vp(),
            mu: vn(),
            vx: vn(),
            vp: vp(),
            vx_rem: vn(),
            vp_rem: vp(),
            cx: vn(),
            cp: vp(),
            ratio: 0.0,
            c_fixed: 0.0,
        }
    }

    /// After [`JumpWork::approach`] and [`JumpWork::crossing_grad`] (which returned `gt`):
    /// the guard slope ∇g·f⁻ and whether the crossing grazes at tolerance `tau`, exactly as
    /// the event loop judged it.
    pub(super) fn slope_and_grazing(&self, gt: f64, tau: f64) -> (f64, bool) {
        let grazing = crate::sens::is_grazing(&self.gx, &self.f_minus, gt, tau);
        (self.gx.dot(&self.f_minus), grazing)
    }

    /// x⁻ as loaded by [`JumpWork::approach`].
    pub(super) fn x_minus(&self) -> &OVector<f64, M::N> {
        &self.xm
    }

    /// x⁺ as loaded by [`JumpWork::approach`].
    pub(super) fn x_plus(&self) -> &OVector<f64, M::N> {
        &self.xp
    }

    /// Loads x⁻, x⁺ and evaluates f⁻ = f_{m⁻}(t, x⁻) under b⁻ and f⁺ = f_{m⁺}(t, x⁺) under b⁺.
    pub(super) fn approach(
        &mut self,
        model: &M,
        p: &OVector<f64, M::P>,
        jump: &Jump,
        x_minus: &[f64],
        x_plus: &[f64],
    ) {
        self.xm.as_mut_slice().copy_from_slice(x_minus);
        self.xp.as_mut_slice().copy_from_slice(x_plus);
        let (t, sw0, sw1) = (jump.t, &jump.sw_before, &jump.sw_after);
        let before = Point::new(jump.mode_before, sw0, t, &self.xm, p);
        model.rhs(before, &mut self.f_minus);
        let after = Point::new(jump.mode_after, sw1, t, &self.xp, p);
        model.rhs(after, &mut self.f_plus);
    }

    /// ∂g/∂t of the guard (g = t − τ for a time event) or switching function that fired, with
    /// ∇ₓ into `gx` and ∂θ into `gp`, at (t, x⁻).
    pub(super) fn crossing_grad(&mut self, model: &M, p: &OVector<f64, M::P>, jump: &Jump) -> f64 {
        crossing_grad(model, p, jump, &self.xm, (&mut self.gx, &mut self.gp))
    }
}

/// ∂g/∂t of the guard or switching function that fired at `jump` (at its time t), with ∇ₓ
/// into `gx` and ∂θ into `gp`, at (t, x⁻ = `x`).
fn crossing_grad<M: HybridModel>(
    model: &M,
    p: &OVector<f64, M::P>,
    jump: &Jump,
    x: &OVector<f64, M::N>,
    (gx, gp): VjpOutput<'_, M::N, M::P>,
) -> f64
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    match jump.kind {
        JumpKind::Event(k, occ) => {
            crate::sens::event_guard_grad(model, k, occ, jump.t, x, p, gx, gp)
        }
        JumpKind::Switch(j) => model.switch_grad(j, At::new(jump.t, x, p), gx, gp),
    }
}

/// The jump being transposed, with what every transpose of it reads: the model, θ and the
/// cost cotangent w.
pub(super) struct JumpSite<'a, M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// The model.
    pub model: &'a M,
    /// θ.
    pub p: &'a OVector<f64, M::P>,
    /// The cost cotangent w.
    pub cw: f64,
    /// The recorded jump.
    pub jump: &'a Jump,
}

impl<M: HybridModel> Clone for JumpSite<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    fn clone(&self) -> Self {
        *self
    }
}

impl<M: HybridModel> Copy for JumpSite<'_, M> where DefaultAllocator: ModelAlloc<M::N, M::P> {}

/// Undoes one jump: λ⁺ → λ⁻ in place and its share of dC/dθ added to `grad` (see the module
/// doc), with cost cotangent `cw`. x⁻ and x⁺ come from the tape.
pub(super) fn transpose_jump<M: HybridModel>(
    site: JumpSite<'_, M>,
    states: (&[f64], &[f64]),
    lam: &mut OVector<f64, M::N>,
    grad: &mut OVector<f64, M::P>,
    w: &mut JumpWork<M>,
) -> Result<(), SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    transpose_jump_and_remainder(site, states, (lam, grad), None, w)
}

/// [`transpose_jump`] for (λ, g) and, when `remainder` is given, the jump's homogeneous
/// part (w = 0: no cost terms) for the global error estimate's remainder (r_λ, r_g) at the
/// same point: f±, the crossing's gradient and one [`crate::model::ModelAdjoint::reset_vjp_pair`]
/// serve both, so a reset whose Jacobian costs O(p) is evaluated once. A failure is the main
/// transpose's; the remainder's own (a non-finite ratio from a non-finite remainder) leaves
/// it without its t' term, as the estimate is then already non-finite.
fn transpose_jump_and_remainder<M: HybridModel>(
    site: JumpSite<'_, M>,
    (x_minus, x_plus): (&[f64], &[f64]),
    (lam, grad): LamGrad<'_, M::N, M::P>,
    mut remainder: Option<LamGrad<'_, M::N, M::P>>,
    w: &mut JumpWork<M>,
) -> Result<(), SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let JumpSite { model, p, cw, jump } = site;
    let info = model.info();
    let t = jump.t;
    w.approach(model, p, jump, x_minus, x_plus);
    let gt = w.crossing_grad(model, p, jump);
    let gdot = w.gx.dot(&w.f_minus) + gt;
    // w(ℓ⁻ − ℓ⁺): both sides of the jump, each under its own bits.
    let mut c = 0.0;
    let mut c_rem = 0.0;
    w.c_fixed = 0.0;
    if info.has_running_cost && cw != 0.0 {
        let l_minus = model.running_cost(&jump.sw_before, At::new(t, &w.xm, p));
        let l_plus = model.running_cost(&jump.sw_after, At::new(t, &w.xp, p));
        c += cw * (l_minus - l_plus);
    }
    match jump.kind {
        JumpKind::Event(k, occ) => {
            // λ̃ = λ⁺ + w φ_xᵀ, and w φ_θ into grad.
            w.mu.copy_from(lam);
            if info.events[k].has_cost && cw != 0.0 {
                let phi_t = model.event_cost_grad(
                    Occurrence::new(k, occ),
                    At::new(t, &w.xp, p),
                    &mut w.cx,
                    &mut w.cp,
                );
                w.mu.axpy(cw, &w.cx, 1.0);
                grad.axpy(cw, &w.cp, 1.0);
                c += cw * phi_t;
                w.c_fixed = cw * phi_t;
            }
            let occ = Occurrence::new(k, occ);
            let at = At::new(t, &w.xm, p);
            let mu_rt = match remainder.as_mut() {
                None => model.reset_vjp(occ, at, &w.mu, &mut w.vx, &mut w.vp),
                Some((r_lam, r_g)) => {
                    let (mu_rt, rem_rt) = model.reset_vjp_pair(
                        occ,
                        at,
                        (&w.mu, r_lam),
                        (&mut w.vx, &mut w.vp),
                        (&mut w.vx_rem, &mut w.vp_rem),
                    );
                    c_rem += w.vx_rem.dot(&w.f_minus) + rem_rt - r_lam.dot(&w.f_plus);
                    r_lam.copy_from(&w.vx_rem);
                    **r_g += &w.vp_rem;
                    mu_rt
                }
            };
            c += w.vx.dot(&w.f_minus) + mu_rt - lam.dot(&w.f_plus);
            w.c_fixed += mu_rt;
            lam.copy_from(&w.vx);
            *grad += &w.vp;
        }
        JumpKind::Switch(_) => {
            c += lam.dot(&w.f_minus) - lam.dot(&w.f_plus);
            w.vx.copy_from(lam);
            if let Some((r_lam, _)) = remainder.as_ref() {
                c_rem += r_lam.dot(&w.f_minus) - r_lam.dot(&w.f_plus);
            }
        }
    }
    let ratio = c / gdot;
    if !(ratio.is_finite() && gdot != 0.0) {
        let what = match jump.kind {
            JumpKind::Event(k, _) => format!(
                "event-time sensitivity of event `{}` (tangential crossing: ∇g·f + ∂g/∂t = {gdot:e})",
                info.events[k].name
            ),
            JumpKind::Switch(j) => format!(
                "crossing-time sensitivity of switching function {j} (tangential crossing)"
            ),
        };
        return Err(SolveError::NonFinite { t, what });
    }
    lam.axpy(-ratio, &w.gx, 1.0);
    grad.axpy(-ratio, &w.gp, 1.0);
    w.ratio = ratio;
    if let Some((r_lam, r_g)) = remainder {
        let ratio_rem = c_rem / gdot;
        if ratio_rem.is_finite() {
            r_lam.axpy(-ratio_rem, &w.gx, 1.0);
            r_g.axpy(-ratio_rem, &w.gp, 1.0);
        }
    }
    if !(lam.iter().all(|v| v.is_finite()) && grad.iter().all(|v| v.is_finite())) {
        let what = match jump.kind {
            JumpKind::Event(k, _) => format!("adjoint jump of event `{}`", info.events[k].name),
            JumpKind::Switch(j) => format!("adjoint jump of switching function {j}"),
        };
        return Err(SolveError::NonFinite { t, what });
    }
    Ok(())
}

/// Scratch for the estimate's share of a jump (allocated once per sweep, with the estimate).
pub(super) struct JumpErrorWork<M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// The exact jump (the recorded one moved back by its displacement) and its states.
    jump: Option<Jump>,
    xm: Vec<f64>,
    xp: Vec<f64>,
    /// λ⁺, kept before the sweep's transpose overwrites it.
    lam_plus: OVector<f64, M::N>,
    /// The crossing's gradient at the exact jump.
    gx: OVector<f64, M::N>,
    gp: OVector<f64, M::P>,
}

impl<M: HybridModel> JumpErrorWork<M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// Buffers for `model`.
    pub(super) fn new(model: &M) -> Self {
        let (n, p) = (model.nstates(), model.nparams());
        let vn = || OVector::zeros_generic(n, Const::<1>);
        JumpErrorWork {
            jump: None,
            xm: vec![0.0; n.value()],
            xp: vec![0.0; n.value()],
            lam_plus: vn(),
            gx: vn(),
            gp: OVector::zeros_generic(p, Const::<1>),
        }
    }
}

/// The sweep's transpose of jump `jump` ([`transpose_jump`], λ and g in place) with its share
/// of the global error estimate `ge`: the jump's homogeneous part (w = 0) maps the remainder
/// (r_λ, r_g) as the transpose maps (λ, g), and the primal run's displacement `shift` of the
/// jump, if it was recorded, adds [`shift_error`]. O(n + p) per jump beyond the model's own
/// products (one reset product for both cotangents; the shift evaluates no reset).
pub(super) fn transpose_jump_with_error<M: HybridModel>(
    site: JumpSite<'_, M>,
    states: (&[f64], &[f64]),
    shift: Option<(&[f64], &[f64], f64)>,
    (lam, g): LamGrad<'_, M::N, M::P>,
    ge: &mut AdjointError<M::N, M::P>,
    w: &mut JumpWork<M>,
    s: &mut JumpErrorWork<M>,
) -> Result<(), SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    s.lam_plus.copy_from(lam);
    let (r_lam, r_g) = ge.remainder_mut();
    transpose_jump_and_remainder(site, states, (lam, g), Some((r_lam, r_g)), w)?;
    if let Some(shift) = shift {
        shift_error(site, shift, ge.remainder_mut(), w, s);
    }
    Ok(())
}

/// The primal run's share of the sweep's error at a jump. The run applied the jump at
/// (t̃, x̃⁻, x̃⁺), the exact one (t, x⁻, x⁺) moved by its state error:
/// (δt, d⁻, d⁺) = `shift` (see [`crate::integrate::GlobalError::jump_shift`]). The sweep
/// transposes the jump there, so it maps (λ⁺, g) by T̃ where the exact jump's transpose is T:
/// the remainder r = (r_λ, r_g) gains T̃(λ⁺) − T(λ⁺). Nothing is added when the jump was not
/// displaced.
///
/// T is taken with the products of the reset and of the event cost as the sweep formed them
/// at the recorded jump (R_xᵀλ̃, R_θᵀλ̃, λ̃ᵀR_t, φ_x, φ_θ, φ_t): those terms cancel in
/// T̃ − T, and what remains is the event-time term, evaluated at both jumps,
///
/// ```text
///   T̃(λ⁺) − T(λ⁺) = (c/ġ)(g_x, g_θ) − (c̃/ġ̃)(g̃_x, g̃_θ),
///   c = (R_xᵀλ̃)·f⁻ − λ⁺·f⁺ + λ̃ᵀR_t + w(φ_t + ℓ⁻ − ℓ⁺),   ġ = g_x·f⁻ + g_t,
/// ```
///
/// with f±, ℓ± and the crossing's gradient at the exact jump (c̃/ġ̃ is what the sweep
/// applied: a secant over the actual displacement, whose rounding, ε|c/ġ|, is far below
/// any tolerance). A switch flip has λ̃ = λ⁺ and no reset or cost. So no reset is evaluated
/// here, and nothing of size p beyond the crossing's ∂θ. Left out: the change of the reset's
/// and the event cost's derivatives along the displacement (second derivatives of R and φ,
/// as forward mode's estimate leaves out the jump map's derivative in x⁻), and the sweep's
/// segments changing at t̃ instead of t, which moves (F⁻ − F⁺)·δt of the adjoint's
/// right-hand side across the jump.
fn shift_error<M: HybridModel>(
    site: JumpSite<'_, M>,
    (d_minus, d_plus, dt): (&[f64], &[f64], f64),
    (r_lam, r_g): LamGrad<'_, M::N, M::P>,
    w: &mut JumpWork<M>,
    s: &mut JumpErrorWork<M>,
) where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let JumpSite { model, p, cw, jump } = site;
    if dt == 0.0 && d_minus.iter().chain(d_plus).all(|&d| d == 0.0) {
        return;
    }
    let exact = match &mut s.jump {
        Some(exact) => {
            exact.clone_from(jump);
            exact
        }
        None => s.jump.insert(jump.clone()),
    };
    exact.t = jump.t - dt;
    for (e, (x, d)) in s.xm.iter_mut().zip(w.xm.iter().zip(d_minus)) {
        *e = x - d;
    }
    for (e, (x, d)) in s.xp.iter_mut().zip(w.xp.iter().zip(d_plus)) {
        *e = x - d;
    }
    // f± at the exact jump (x± and f± of the recorded one are no longer needed).
    w.approach(model, p, exact, &s.xm, &s.xp);
    let gt = crossing_grad(model, p, exact, &w.xm, (&mut s.gx, &mut s.gp));
    let gdot = s.gx.dot(&w.f_minus) + gt;
    let mut c = 0.0;
    if model.info().has_running_cost && cw != 0.0 {
        let l_minus = model.running_cost(&exact.sw_before, At::new(exact.t, &w.xm, p));
        let l_plus = model.running_cost(&exact.sw_after, At::new(exact.t, &w.xp, p));
        c += cw * (l_minus - l_plus);
    }
    c += w.c_fixed + w.vx.dot(&w.f_minus) - s.lam_plus.dot(&w.f_plus);
    let ratio = c / gdot;
    if !(ratio.is_finite() && gdot != 0.0) {
        return;
    }
    r_lam.axpy(ratio, &s.gx, 1.0);
    r_lam.axpy(-w.ratio, &w.gx, 1.0);
    r_g.axpy(ratio, &s.gp, 1.0);
    r_g.axpy(-w.ratio, &w.gp, 1.0);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::adjoint::record::{Item, Tape};
    use crate::fixtures::Ball;
    use crate::model::Switches;

    /// The shift's share of the remainder is the secant of the full transposes at the
    /// displaced and at the exact jump, T̃(λ⁺) − T(λ⁺), less the change of the reset's
    /// derivatives it leaves out. For the ball, x⁺ = (h, −e v): R_x and R_t do not depend on
    /// the state, R_θ does through ∂v⁺/∂e = −v⁻, so that entry of the secant has the extra
    /// −λ⁺_v d_v and every other entry agrees to rounding (a displacement of v moves ġ = v⁻
    /// and f±; one of h alone moves nothing, as ℓ⁻ − ℓ⁺ = h⁻ − h⁺ = 0).
    #[test]
    fn the_shift_is_the_secant_of_the_transposes_but_for_the_resets_derivatives() {
        let model = Ball::new();
        let p = model.default_params();
        let e = p[Ball::E];
        let sw = Switches::default();
        let (t, xm, lam_plus) = (0.6, [0.0, -5.9], [0.7, -1.3]);
        let xp = [xm[0], -e * xm[1]];
        for (dm, dt) in [
            ([0.0, 3e-3], 2e-4),
            ([-1e-3, 1e-3], 0.0),
            ([2e-4, -5e-4], -1e-4),
        ] {
            let dp = [dm[0], -e * dm[1]];
            let (xm_rec, xp_rec) = (
                [xm[0] + dm[0], xm[1] + dm[1]],
                [xp[0] + dp[0], xp[1] + dp[1]],
            );
            let mut tape = Tape::new(2);
            let kind = JumpKind::Event(0, 0);
            let shift = Some((&dm[..], &dp[..], dt));
            tape.jump(kind, t + dt, &xm_rec, &xp_rec, (0, 0), &sw, &sw, shift);
            let Item::Jump(recorded) = &tape.items()[0] else {
                panic!("a jump was recorded");
            };
            let mut exact = recorded.clone();
            exact.t = t;
            let mut w = JumpWork::new(&model);
            // The secant of the full transposes.
            let transposed = |jump: &Jump, states, w: &mut JumpWork<Ball>| {
                let mut lam = OVector::<f64, Const<2>>::from_column_slice(&lam_plus);
                let mut g = OVector::<f64, Const<4>>::zeros();
                let site = JumpSite {
                    model: &model,
                    p: &p,
                    cw: 1.0,
                    jump,
                };
                transpose_jump(site, states, &mut lam, &mut g, w).expect("transversal");
                (lam, g)
            };
            let (lam_rec, g_rec) = transposed(recorded, (&xm_rec[..], &xp_rec[..]), &mut w);
            let (lam_ex, g_ex) = transposed(&exact, (&xm[..], &xp[..]), &mut w);
            let (want_lam, mut want_g) = (lam_rec - lam_ex, g_rec - g_ex);
            want_g[Ball::E] += lam_plus[1] * dm[1];
            // The sweep's transpose with the estimate, from a zero remainder.
            let mut ge = AdjointError::new(Const::<2>, Const::<4>);
            let mut s = JumpErrorWork::new(&model);
            let mut lam = OVector::<f64, Const<2>>::from_column_slice(&lam_plus);
            let mut g = OVector::<f64, Const<4>>::zeros();
            let states = tape.jump_states(recorded);
            let shift = tape.jump_shift(recorded);
            let site = JumpSite {
                model: &model,
                p: &p,
                cw: 1.0,
                jump: recorded,
            };
            transpose_jump_with_error(
                site,
                states,
                shift,
                (&mut lam, &mut g),
                &mut ge,
                &mut w,
                &mut s,
            )
            .expect("transversal");
            assert_eq!(
                (lam, g),
                (lam_rec, g_rec),
                "the sweep's own transpose is untouched"
            );
            let (r_lam, r_g) = ge.remainder_mut();
            let moved = want_lam.amax().max(want_g.amax());
            assert!(
                moved > 1e-4,
                "the displacement moves the transpose: {moved:e}"
            );
            // The secant's rounding: ε times the transposes' size.
            let scale = lam_rec.amax().max(g_rec.amax());
            for (got, want) in r_lam
                .iter()
                .chain(r_g.iter())
                .zip(want_lam.iter().chain(want_g.iter()))
            {
                assert!(
                    (got - want).abs() <= 1e-14 * scale,
                    "{r_lam:?} {r_g:?} against {want_lam:?} {want_g:?}"
                );
            }
        }
    }
}
