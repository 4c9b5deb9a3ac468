//! Forward sensitivities through an event: the event-time sensitivity and the jump
//! (saltation) update of S = ∂x/∂θ.
//!
//! On a smooth segment S obeys Ṡ = f_x S + f_θ (the integrator carries it). At an event
//! whose guard g(t, x, θ) reaches zero at t_k, the implicit function theorem applied to
//! g(t_k(θ), x(t_k(θ); θ), θ) = 0 gives the event-time sensitivity (a row vector, one entry
//! per parameter)
//!
//! ```text
//!   t_k' = −(g_x S⁻ + g_θ) / (g_x f⁻ + g_t)
//! ```
//!
//! which exists iff the crossing is transversal (denominator ≠ 0). Differentiating
//! x⁺ = R(t_k, x⁻(t_k), θ) and x(t) = x⁺ + f⁺ (t − t_k) + … on the right gives the jump
//!
//! ```text
//!   S⁺ = R_x S⁻ + R_θ + (R_x f⁻ + R_t − f⁺) t_k'
//! ```
//!
//! with f⁻ the old mode's flow at (t_k, x⁻) and f⁺ the new mode's flow at (t_k, x⁺) (switch
//! bits re-evaluated at x⁺). A zero crossing of a switching function is the special case
//! R = identity: S⁺ = S⁻ + (f⁻ − f⁺) t'. The total derivative of the post-event state is
//! d x(t_k⁺)/dθ = S⁺ + f⁺ t_k' (used by event costs and the Zeno limit).
//!
//! All functions write into caller-provided buffers and allocate nothing.

use crate::model::{At, HybridModel, ModelAlloc, Occurrence};
use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

/// The gradient of what event k crosses at its occurrence j, at (t, x): ∇ₓg into `gx`, ∂θg
/// into `gp`, and ∂g/∂t returned. For a state event g is its guard; for a time event it is
/// g = t − τ_kj(θ), so ∇ₓg = 0, ∂θg = −∂τ_kj/∂θ and ∂g/∂t = 1, and the formulas below give
/// t' = ∂τ/∂θ unchanged. The forward jump and the adjoint's transpose both take it from here.
#[allow(clippy::too_many_arguments)]
pub fn event_guard_grad<M: HybridModel>(
    model: &M,
    k: usize,
    j: usize,
    t: f64,
    x: &OVector<f64, M::N>,
    p: &OVector<f64, M::P>,
    gx: &mut OVector<f64, M::N>,
    gp: &mut OVector<f64, M::P>,
) -> f64
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    if model.info().events[k].is_time_event() {
        gx.fill(0.0);
        model.event_time_grad(Occurrence::new(k, j), p, gp);
        gp.neg_mut();
        1.0
    } else {
        model.guard_grad(k, At::new(t, x, p), gx, gp)
    }
}

/// Event-time sensitivity: writes t' = −(g_x S⁻ + g_θ)/(g_x f⁻ + g_t) into `dt` (one entry per
/// parameter) and returns the pair (g_x f⁻, g_x f⁻ + g_t): the guard slope along the flow and
/// the full denominator. When the denominator is exactly zero `dt` is filled with the signed
/// infinities (or NaN) the division gives; callers check transversality first.
pub fn event_time_sensitivity<N: Dim, P: Dim>(
    gx: &OVector<f64, N>,
    gp: &OVector<f64, P>,
    gt: f64,
    f_minus: &OVector<f64, N>,
    s_minus: &OMatrix<f64, N, P>,
    dt: &mut OVector<f64, P>,
) -> (f64, f64)
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    let slope = gx.dot(f_minus);
    let denom = slope + gt;
    // dt = S⁻ᵀ g_x + g_θ, then scaled by −1/denom.
    dt.copy_from(gp);
    dt.gemv_tr(1.0, s_minus, gx, 1.0);
    let scale = -1.0 / denom;
    dt.scale_mut(scale);
    (slope, denom)
}

/// The cosine of a crossing: |dg/dt| / (|g_x| |f⁻| + |g_t|), where dg/dt = g_x f⁻ + g_t is the
/// total rate of the guard along the trajectory at t_k⁻ (the quantity t' divides by, and the
/// `guard_slope` of an event). It is 0 for a tangential crossing and at most 1; for a guard
/// without t it is the cosine between the guard's normal and the flow, and a pure time guard
/// `t ≥ p` has rate 1 and cosine 1. A crossing with vanishing g_x, f⁻ and g_t has cosine 0.
pub fn crossing_cosine<N: Dim>(gx: &OVector<f64, N>, f_minus: &OVector<f64, N>, gt: f64) -> f64
where
    DefaultAllocator: nalgebra::allocator::Allocator<N>,
{
    cosine_of(gx.dot(f_minus) + gt, gx.norm() * f_minus.norm() + gt.abs())
}

/// The [`crossing_cosine`] of a crossing with total rate `rate` = g_x f⁻ + g_t and scale
/// |g_x| |f⁻| + |g_t|: |rate| / scale, and 0 for a vanishing rate.
#[inline]
pub fn cosine_of(rate: f64, scale: f64) -> f64 {
    if rate == 0.0 {
        return 0.0;
    }
    rate.abs() / scale
}

/// Whether a crossing of [`crossing_cosine`] `cosine` grazes at tolerance τ (see
/// [`is_grazing`]).
#[inline]
pub fn is_grazing_cosine(cosine: f64, tau: f64) -> bool {
    cosine == 0.0 || cosine < tau
}

/// Whether a crossing is grazing: its [`crossing_cosine`] is below τ, i.e.
/// |g_x f⁻ + g_t| < τ (|g_x| |f⁻| + |g_t|). Also true when the rate vanishes entirely
/// (the denominator of t' is zero).
pub fn is_grazing<N: Dim>(
    gx: &OVector<f64, N>,
    f_minus: &OVector<f64, N>,
    gt: f64,
    tau: f64,
) -> bool
where
    DefaultAllocator: nalgebra::allocator::Allocator<N>,
{
    is_grazing_cosine(crossing_cosine(gx, f_minus, gt), tau)
}

/// Saltation update at an event with reset R:
/// S⁺ = R_x S⁻ + R_θ + (R_x f⁻ + R_t − f⁺) t'. `work` is an n-vector of scratch.
#[allow(clippy::too_many_arguments)]
pub fn jump<N: Dim, P: Dim>(
    rx: &OMatrix<f64, N, N>,
    rp: &OMatrix<f64, N, P>,
    rt: &OVector<f64, N>,
    s_minus: &OMatrix<f64, N, P>,
    f_minus: &OVector<f64, N>,
    f_plus: &OVector<f64, N>,
    dt: &OVector<f64, P>,
    work: &mut OVector<f64, N>,
    s_plus: &mut OMatrix<f64, N, P>,
) where
    DefaultAllocator: ModelAlloc<N, P>,
{
    // s_plus = R_x S⁻ + R_θ
    s_plus.copy_from(rp);
    s_plus.gemm(1.0, rx, s_minus, 1.0);
    if dt.iter().all(|&d| d == 0.0) {
        // t' = 0 (a time event whose times do not depend on θ): no time term.
        return;
    }
    // work = R_x f⁻ + R_t − f⁺
    work.copy_from(rt);
    work.gemv(1.0, rx, f_minus, 1.0);
    *work -= f_plus;
    // s_plus += work · t'ᵀ
    s_plus.ger(1.0, work, dt, 1.0);
}

/// Saltation update at a switch crossing (identity reset), in place:
/// S ← S + (f⁻ − f⁺) t'. `work` is an n-vector of scratch.
pub fn switch_jump<N: Dim, P: Dim>(
    s: &mut OMatrix<f64, N, P>,
    f_minus: &OVector<f64, N>,
    f_plus: &OVector<f64, N>,
    dt: &OVector<f64, P>,
    work: &mut OVector<f64, N>,
) where
    DefaultAllocator: ModelAlloc<N, P>,
{
    work.copy_from(f_minus);
    *work -= f_plus;
    s.ger(1.0, work, dt, 1.0);
}

/// Total derivative of the post-event state, d x(t_k⁺)/dθ = S⁺ + f⁺ t'ᵀ, into `out`.
pub fn post_event_total<N: Dim, P: Dim>(
    s_plus: &OMatrix<f64, N, P>,
    f_plus: &OVector<f64, N>,
    dt: &OVector<f64, P>,
    out: &mut OMatrix<f64, N, P>,
) where
    DefaultAllocator: ModelAlloc<N, P>,
{
    out.copy_from(s_plus);
    if dt.iter().any(|&d| d != 0.0) {
        out.ger(1.0, f_plus, dt, 1.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use nalgebra::{Matrix2, Matrix2x1, Vector1, Vector2};

    /// Ball from h0 with v0 = 0, one parameter θ = h0: first impact at t = sqrt(2 h0 / g).
    /// S⁻ = (1, 0)ᵀ (∂h/∂h0 = 1, ∂v/∂h0 = 0 before the impact), f⁻ = (v⁻, −g), g = h.
    /// t' = −1/v⁻ = 1/sqrt(2 g h0) = dt_k/dh0 (closed form: d sqrt(2h0/g)/dh0).
    #[test]
    fn a_pure_time_guard_has_rate_one_and_is_not_grazing() {
        // g = t − p: ∇ₓg = 0, ∂g/∂t = 1, whatever the flow: cosine 1.
        let (gx, f) = (Vector2::zeros(), Vector2::new(3.0, -4.0));
        assert_eq!(crossing_cosine(&gx, &f, 1.0), 1.0);
        assert!(!is_grazing(&gx, &f, 1.0, 1e-3));
        // A state guard: the cosine between ∇g and f; tangential ⇒ 0 and grazing.
        let gx = Vector2::new(1.0, 0.0);
        assert_relative_eq!(crossing_cosine(&gx, &f, 0.0), 0.6);
        assert!(is_grazing(&gx, &Vector2::new(0.0, 1.0), 0.0, 1e-3));
        // A moving guard g = x − t crossed with ẋ = 1 + 1e-6: rate 1e-6 of scale 2.
        let f = Vector2::new(1.0 + 1e-6, 0.0);
        assert_relative_eq!(crossing_cosine(&gx, &f, -1.0), 0.5e-6, max_relative = 1e-6);
        assert!(is_grazing(&gx, &f, -1.0, 1e-3));
    }

    #[test]
    fn event_time_matches_closed_form() {
        let (g, h0, e): (f64, f64, f64) = (9.81, 2.0, 0.8);
        let tk = (2.0 * h0 / g).sqrt();
        let vm = -g * tk;
        let gx = Vector2::new(1.0, 0.0);
        let gp = Vector1::new(0.0);
        let f_minus = Vector2::new(vm, -g);
        let s_minus = Matrix2x1::new(1.0, 0.0);
        let mut dt = Vector1::zeros();
        let (slope, denom) = event_time_sensitivity(&gx, &gp, 0.0, &f_minus, &s_minus, &mut dt);
        assert_relative_eq!(slope, vm);
        assert_relative_eq!(denom, vm);
        let dtk_dh0 = 1.0 / (2.0 * g * h0).sqrt();
        assert_relative_eq!(dt[0], dtk_dh0, max_relative = 1e-14);

        // Jump: R = (h, −e v); R_x = diag(1, −e), R_θ = 0 (θ = h0), R_t = 0.
        let rx = Matrix2::new(1.0, 0.0, 0.0, -e);
        let rp = Matrix2x1::zeros();
        let rt = Vector2::zeros();
        let f_plus = Vector2::new(-e * vm, -g);
        let mut work = Vector2::zeros();
        let mut s_plus = Matrix2x1::zeros();
        jump(
            &rx,
            &rp,
            &rt,
            &s_minus,
            &f_minus,
            &f_plus,
            &dt,
            &mut work,
            &mut s_plus,
        );
        // Closed form after the impact: h(t) = u (t − t_k) − g (t − t_k)²/2 with u = e g t_k,
        // t_k = sqrt(2 h0/g). ∂h/∂h0 at fixed t just after t_k: −u t_k' (h(t_k⁺) = 0 always
        // and ḣ(t_k⁺) = u); ∂v/∂h0 = d u/dh0 + g t_k' = e g t_k' + g t_k'.
        let u = e * g * tk;
        assert_relative_eq!(s_plus[(0, 0)], -u * dtk_dh0, max_relative = 1e-14);
        assert_relative_eq!(
            s_plus[(1, 0)],
            (e + 1.0) * g * dtk_dh0,
            max_relative = 1e-14
        );

        // Total derivative of x⁺ = (0, u): (0, du/dh0) = (0, e g t_k').
        let mut tot = Matrix2x1::zeros();
        post_event_total(&s_plus, &f_plus, &dt, &mut tot);
        assert!(tot[(0, 0)].abs() < 1e-15);
        assert_relative_eq!(tot[(1, 0)], e * g * dtk_dh0, max_relative = 1e-14);
    }

    /// A kink: σ = x − c, flow f = −1 for σ > 0 and f = −2 below; θ = (x0, c), x(0) = x0.
    /// The crossing is at t* = x0 − c (t*' = (1, −1)); after it x(t) = c − 2 (t − t*)
    /// = 2 x0 − c − 2t, so ∂x/∂x0 = 2 and ∂x/∂c = −1.
    #[test]
    fn switch_saltation_matches_closed_form() {
        let s_minus = nalgebra::Matrix1x2::new(1.0, 0.0); // x = x0 − t before: ∂/∂x0 = 1
        let gx = Vector1::new(1.0);
        let gp = Vector2::new(0.0, -1.0);
        let f_minus = Vector1::new(-1.0);
        let f_plus = Vector1::new(-2.0);
        let mut dt = Vector2::zeros();
        event_time_sensitivity(&gx, &gp, 0.0, &f_minus, &s_minus, &mut dt);
        assert_relative_eq!(dt[0], 1.0); // t* = x0 − c
        assert_relative_eq!(dt[1], -1.0);
        let mut s = s_minus;
        let mut work = Vector1::zeros();
        switch_jump(&mut s, &f_minus, &f_plus, &dt, &mut work);
        assert_relative_eq!(s[(0, 0)], 2.0);
        assert_relative_eq!(s[(0, 1)], -1.0);
    }

    #[test]
    fn grazing_test() {
        let gx = Vector2::new(1.0, 0.0);
        assert!(is_grazing(&gx, &Vector2::new(1e-4, -9.81), 0.0, 1e-3));
        assert!(!is_grazing(&gx, &Vector2::new(-1.0, -9.81), 0.0, 1e-3));
        assert!(is_grazing(&gx, &Vector2::new(0.0, 0.0), 0.0, 1e-3));
    }
}
