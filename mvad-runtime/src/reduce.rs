//! Reduction of a run to C(θ) and dC/dθ, and the limits used when events accumulate (Zeno).
//!
//! For C = ∫₀ᵀ ℓ dt + Σ_k φ_k(t_k, x(t_k⁺), θ) + Φ(T, x(T), θ) the total derivative is
//!
//! ```text
//!   dC/dθ = Σ_seg ∫ (ℓ_x S + ℓ_θ) dt + Σ_k (ℓ(t_k⁻) − ℓ(t_k⁺)) t_k'
//!         + Σ_k [φ_x (S⁺ + f⁺ t_k') + φ_t t_k' + φ_θ]
//!         + Φ_x S(T) + Φ_θ + (ℓ(T) + Φ_x f(T) + Φ_t) dT/dθ .
//! ```
//!
//! The integral part is the integrator's quadrature state q_θ; the event parts are added by
//! the driver at each event; [`final_terms`] adds the terms at T.
//!
//! Zeno: when dwell times shrink geometrically, a quantity a_k sampled at the k-th event
//! (event time, post-event state, its total derivative, accumulated cost and gradient)
//! converges like a_k ≈ a_∞ + B ρᵏ. [`aitken`] estimates a_∞ from three consecutive values
//! (Aitken's Δ²: a_∞ = a₂ − (a₂ − a₁)² / ((a₂ − a₁) − (a₁ − a₀))), the sum of the geometric
//! tail. The derivative of a limit is not extrapolated from the derivative sequence (whose
//! error (B' + B k ρ'/ρ) ρᵏ is not geometric): it is the derivative of the sum of the series,
//! Σ_i ∂a_∞/∂a_i · da_i/dθ ([`aitken_weights`]), exact when a_k is exactly geometric.

use crate::model::{At, HybridModel, ModelAlloc, Switches};
use nalgebra::{DefaultAllocator, OMatrix, OVector};

/// Aitken's Δ² applied repeatedly: each pass maps every three consecutive values to their
/// [`aitken`] limit, until fewer than three remain; returns the last. Five values give two
/// passes, which remove error terms of the form (a + bk)ρᵏ that one pass leaves.
pub fn aitken_iterated(seq: &[f64]) -> f64 {
    aitken_iterated_weights(seq).0
}

/// [`aitken_iterated`] with its sensitivities to the inputs: (a_∞, w) with w_i = ∂a_∞/∂a_i,
/// so that for a sequence a_k(θ) whose derivatives da_k/dθ are known the limit's derivative
/// is da_∞/dθ = Σ_i w_i da_i/dθ (the chain rule through the extrapolation). The weights sum
/// to 1 (a shift of every a_i shifts the limit).
pub fn aitken_iterated_weights(seq: &[f64]) -> (f64, Vec<f64>) {
    let n = seq.len();
    let unit = |i: usize| {
        (0..n)
            .map(|m| if m == i { 1.0 } else { 0.0 })
            .collect::<Vec<_>>()
    };
    let mut cur: Vec<(f64, Vec<f64>)> =
        seq.iter().enumerate().map(|(i, &a)| (a, unit(i))).collect();
    while cur.len() >= 3 {
        cur = cur
            .windows(3)
            .map(|w| {
                let (lim, c) = aitken_weights(w[0].0, w[1].0, w[2].0);
                let wts = (0..n)
                    .map(|i| c[0] * w[0].1[i] + c[1] * w[1].1[i] + c[2] * w[2].1[i])
                    .collect();
                (lim, wts)
            })
            .collect();
    }
    cur.pop().unwrap_or((f64::NAN, vec![0.0; n]))
}

/// Aitken's Δ² limit of a sequence from its last three values a0, a1, a2.
///
/// Falls back to a2 when the differences do not look geometric (ratio outside (−0.999, 0.999),
/// zero or non-finite denominators) or are at the level of rounding (the sequence has
/// converged: both differences within 64ε of the largest value).
pub fn aitken(a0: f64, a1: f64, a2: f64) -> f64 {
    aitken_weights(a0, a1, a2).0
}

/// [`aitken`] and its partial derivatives w = (∂/∂a0, ∂/∂a1, ∂/∂a2).
///
/// With d1 = a1 − a0, d2 = a2 − a1, r = d2/d1 and D = d1 − d2, the limit is the sum of the
/// geometric series a2 + d2 (r + r² + …) = a2 + d2²/D, whose derivatives are
///
/// ```text
///   ∂/∂a2 = 1/(1 − r)² = d1²/D²,   ∂/∂a1 = −2 d1 d2 / D²,   ∂/∂a0 = d2²/D².
/// ```
///
/// If a_k = a_∞ + B ρᵏ exactly with a_∞, B and ρ all functions of θ, the limit is a_∞ for
/// every θ, so Σ w_i da_i/dθ is da_∞/dθ exactly; Aitken applied to the sequence da_k/dθ
/// itself would not be, since it has the non-geometric term B k ρᵏ⁻¹ dρ/dθ. On a fallback the
/// weights are (0, 0, 1).
pub fn aitken_weights(a0: f64, a1: f64, a2: f64) -> (f64, [f64; 3]) {
    const LAST: [f64; 3] = [0.0, 0.0, 1.0];
    let d1 = a1 - a0;
    let d2 = a2 - a1;
    let scale = a0.abs().max(a1.abs()).max(a2.abs());
    let converged = d1.abs().max(d2.abs()) <= 64.0 * f64::EPSILON * scale;
    if d2 == 0.0 || d1 == 0.0 || converged {
        return (a2, LAST);
    }
    let r = d2 / d1;
    if !r.is_finite() || r.abs() >= 0.999 {
        return (a2, LAST);
    }
    // a2 + d2 (r + r² + …) = a2 + d2 r/(1 − r)
    let lim = a2 + d2 * r / (1.0 - r);
    if !lim.is_finite() {
        return (a2, LAST);
    }
    let q = 1.0 / (1.0 - r);
    // d1²/D² = q², −2 d1 d2/D² = −2 r q², d2²/D² = r² q².
    (lim, [r * r * q * q, -2.0 * r * q * q, q * q])
}

/// Gauss–Legendre nodes and weights on [−1, 1], 8 points (exact for degree 15).
pub const GL8: [(f64, f64); 8] = [
    (-0.960_289_856_497_536_2, 0.101_228_536_290_376_26),
    (-0.796_666_477_413_626_7, 0.222_381_034_453_374_47),
    (-0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (-0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (0.796_666_477_413_626_7, 0.222_381_034_453_374_47),
    (0.960_289_856_497_536_2, 0.101_228_536_290_376_26),
];

/// Adaptive Gauss–Legendre quadrature of a vector-valued integrand on [a, b]: `f(t, out)`
/// writes the integrand into `out`; the integral is *added* to `acc`. An interval is accepted
/// when the 8-point rule on it and the sum of the rules on its halves agree to `rtol`
/// (relative to the larger entry, absolute floor `atol`), else it is split (depth ≤ 30).
/// At most [`MAX_QUADRATURE_SPLITS`] splits are made per call, so an integrand with a
/// discontinuity or noise below `rtol` costs bounded work instead of 2³⁰ pieces; past the
/// budget each remaining piece is accepted as it stands. `tmp` needs 3·len scratch entries.
pub fn integrate_adaptive<F: FnMut(f64, &mut [f64])>(
    f: &mut F,
    a: f64,
    b: f64,
    rtol: f64,
    atol: f64,
    acc: &mut [f64],
    tmp: &mut [f64],
) {
    let len = acc.len();
    let (whole, rest) = tmp.split_at_mut(len);
    let (halves, val) = rest.split_at_mut(len);
    gl8(f, a, b, whole, &mut val[..len]);
    let mut budget = MAX_QUADRATURE_SPLITS;
    adapt(
        f,
        (a, b),
        (rtol, atol),
        acc,
        whole,
        halves,
        &mut val[..len],
        0,
        &mut budget,
    );
}

/// The most interval splits one call of [`integrate_adaptive`] makes (each costs 16
/// integrand evaluations).
pub const MAX_QUADRATURE_SPLITS: usize = 256;

/// One 8-point rule on [a, b] into `out`; `val` is scratch of the same length.
fn gl8<F: FnMut(f64, &mut [f64])>(f: &mut F, a: f64, b: f64, out: &mut [f64], val: &mut [f64]) {
    out.fill(0.0);
    let (c, r) = (0.5 * (a + b), 0.5 * (b - a));
    for &(x, w) in &GL8 {
        f(c + r * x, val);
        for (o, v) in out.iter_mut().zip(val.iter()) {
            *o += w * r * v;
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn adapt<F: FnMut(f64, &mut [f64])>(
    f: &mut F,
    (a, b): (f64, f64),
    (rtol, atol): (f64, f64),
    acc: &mut [f64],
    whole: &[f64],
    halves: &mut [f64],
    val: &mut [f64],
    depth: usize,
    budget: &mut usize,
) {
    let len = acc.len();
    let m = 0.5 * (a + b);
    let mut left = vec![0.0; len];
    let mut right = vec![0.0; len];
    gl8(f, a, m, &mut left, val);
    gl8(f, m, b, &mut right, val);
    let mut ok = true;
    for i in 0..len {
        halves[i] = left[i] + right[i];
        let scale = halves[i].abs().max(whole[i].abs());
        if (halves[i] - whole[i]).abs() > rtol * scale + atol {
            ok = false;
        }
    }
    if ok || depth >= 30 || *budget == 0 || !(m > a && m < b) {
        for i in 0..len {
            acc[i] += halves[i];
        }
        return;
    }
    *budget -= 1;
    let tols = (rtol, 0.5 * atol);
    adapt(f, (a, m), tols, acc, &left, halves, val, depth + 1, budget);
    adapt(f, (m, b), tols, acc, &right, halves, val, depth + 1, budget);
}

/// Scratch for [`final_terms`].
pub struct FinalWork<M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// Φ_x / ℓ_x scratch.
    pub cx: OVector<f64, M::N>,
    /// Φ_θ / ℓ_θ scratch.
    pub cp: OVector<f64, M::P>,
    /// f(T).
    pub f: OVector<f64, M::N>,
}

impl<M: HybridModel> FinalWork<M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// Buffers for `model`.
    pub fn new(model: &M) -> Self {
        let (n, p) = (model.nstates(), model.nparams());
        FinalWork {
            cx: OVector::zeros_generic(n, nalgebra::Const::<1>),
            cp: OVector::zeros_generic(p, nalgebra::Const::<1>),
            f: OVector::zeros_generic(n, nalgebra::Const::<1>),
        }
    }
}

/// The terms at T: returns Φ(T, x(T)) and, when `grad` is given, adds
/// Φ_x S(T) + Φ_θ + (ℓ(T) + Φ_x ẋ(T) + Φ_t) dT/dθ to it. `xdot` is ẋ(T) (f(T), or zero for a
/// state held at rest after a Zeno accumulation).
#[allow(clippy::too_many_arguments)]
pub fn final_terms<M: HybridModel>(
    model: &M,
    p: &OVector<f64, M::P>,
    sw: &Switches,
    t: f64,
    x: &OVector<f64, M::N>,
    s: &OMatrix<f64, M::N, M::P>,
    xdot: &OVector<f64, M::N>,
    dt_end: &OVector<f64, M::P>,
    work: &mut FinalWork<M>,
    grad: Option<&mut OVector<f64, M::P>>,
) -> f64
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let info = model.info();
    let phi = if info.has_final_cost {
        model.final_cost(At::new(t, x, p))
    } else {
        0.0
    };
    if let Some(grad) = grad {
        let mut rate = 0.0;
        if info.has_final_cost {
            let phi_t = model.final_cost_grad(At::new(t, x, p), &mut work.cx, &mut work.cp);
            // Φ_x S + Φ_θ
            grad.gemv_tr(1.0, s, &work.cx, 1.0);
            *grad += &work.cp;
            rate += work.cx.dot(xdot) + phi_t;
        }
        if info.has_running_cost {
            rate += model.running_cost(sw, At::new(t, x, p));
        }
        if rate != 0.0 {
            grad.axpy(rate, dt_end, 1.0);
        }
    }
    phi
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn aitken_is_exact_on_geometric_sequences() {
        let a = |k: i32| 3.0 + 2.0 * 0.6f64.powi(k);
        assert_relative_eq!(aitken(a(4), a(5), a(6)), 3.0, max_relative = 1e-13);
        // Constant and non-geometric fall back to the last value.
        assert_eq!(aitken(1.0, 1.0, 1.0), 1.0);
        assert_eq!(aitken(0.0, 1.0, 2.0), 2.0);
        // Arithmetico-geometric: error O(ρᵏ/k) of the tail, far below the tail itself.
        let b = |k: i32| 1.0 + (k as f64) * 0.5f64.powi(k);
        let tail = b(20) - 1.0;
        assert!((aitken(b(18), b(19), b(20)) - 1.0).abs() < 0.1 * tail);
    }

    #[test]
    fn the_limit_of_a_geometric_sequence_is_differentiated_exactly() {
        // a_k(θ) = a∞(θ) + B(θ) ρ(θ)ᵏ with a∞ = θ², B = 1 + θ, ρ = θ/2 at θ = 0.9: the chain
        // rule through the (iterated) extrapolation gives da∞/dθ = 2θ exactly, while Aitken
        // on the derivative sequence (which carries B k ρᵏ⁻¹ ρ') does not.
        let th: f64 = 0.9;
        let (rho, b, drho, db) = (th / 2.0, 1.0 + th, 0.5, 1.0);
        let a = |k: i32| th * th + b * rho.powi(k);
        let da = |k: i32| 2.0 * th + db * rho.powi(k) + b * f64::from(k) * rho.powi(k - 1) * drho;
        let seq: Vec<f64> = (6..11).map(a).collect();
        let dseq: Vec<f64> = (6..11).map(da).collect();
        let (lim, w) = aitken_iterated_weights(&seq);
        assert_relative_eq!(lim, th * th, max_relative = 1e-13);
        assert_relative_eq!(w.iter().sum::<f64>(), 1.0, max_relative = 1e-12);
        let d: f64 = w.iter().zip(&dseq).map(|(w, d)| w * d).sum();
        assert!((d - 2.0 * th).abs() < 1e-12, "{d}");
        assert!((aitken_iterated(&dseq) - 2.0 * th).abs() > 1e-6);
        // One pass: the weights are the partial derivatives of the limit (central differences).
        let (a0, a1, a2) = (a(3), a(4), a(5));
        let (_, w3) = aitken_weights(a0, a1, a2);
        let h = 1e-7;
        let fd = [
            (aitken(a0 + h, a1, a2) - aitken(a0 - h, a1, a2)) / (2.0 * h),
            (aitken(a0, a1 + h, a2) - aitken(a0, a1 - h, a2)) / (2.0 * h),
            (aitken(a0, a1, a2 + h) - aitken(a0, a1, a2 - h)) / (2.0 * h),
        ];
        for (x, y) in w3.iter().zip(fd) {
            assert_relative_eq!(*x, y, max_relative = 1e-6);
        }
        // A converged sequence (differences at rounding level) is its last value.
        assert_eq!(
            aitken_weights(-2.0, -2.0 + 4e-16, -2.0),
            (-2.0, [0.0, 0.0, 1.0])
        );
    }

    #[test]
    fn adaptive_quadrature_of_smooth_and_peaked_integrands() {
        let mut tmp = vec![0.0; 6];
        let mut acc = [0.0, 0.0];
        let mut f = |t: f64, out: &mut [f64]| {
            out[0] = t.sin();
            out[1] = 1.0 / (1e-4 + (t - 0.3) * (t - 0.3));
        };
        integrate_adaptive(&mut f, 0.0, 1.0, 1e-13, 0.0, &mut acc, &mut tmp);
        assert_relative_eq!(acc[0], 1.0 - 1f64.cos(), max_relative = 1e-13);
        let exact = 100.0 * ((0.7f64 / 0.01).atan() + (0.3f64 / 0.01).atan());
        assert_relative_eq!(acc[1], exact, max_relative = 1e-11);
    }
}

/// A running sum with Neumaier's compensation: the rounding error of every addition is kept
/// in `lo`, so Σ φ_k over millions of events (a queue's sojourn times) is accurate to about
/// one rounding of the total instead of n of them.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CompensatedSum {
    hi: f64,
    lo: f64,
}

impl CompensatedSum {
    /// Adds `x`.
    #[inline]
    pub fn add(&mut self, x: f64) {
        let t = self.hi + x;
        self.lo += if self.hi.abs() >= x.abs() {
            (self.hi - t) + x
        } else {
            (x - t) + self.hi
        };
        self.hi = t;
    }

    /// The sum.
    #[inline]
    pub fn value(&self) -> f64 {
        self.hi + self.lo
    }
}

#[cfg(test)]
mod compensated_tests {
    use super::CompensatedSum;

    #[test]
    fn compensation_keeps_what_plain_summation_loses() {
        let mut s = CompensatedSum::default();
        let mut plain = 0.0;
        for x in [1e16, 1.0, 1.0, -1e16] {
            s.add(x);
            plain += x;
        }
        assert_eq!(s.value(), 2.0);
        assert_eq!(plain, 0.0);
    }
}
