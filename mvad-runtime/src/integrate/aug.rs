//! The forward augmented state (x, S, q, q_θ) and its vector-space operations.

use super::system::{HermiteStep, StageVector, Tol};
use crate::model::ModelAlloc;
use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector};
use std::slice;

/// The augmented state `(x, S, q, q_θ)` integrated over a smooth segment (see the module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct AugState<N: Dim, P: Dim>
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    /// The state x.
    pub x: OVector<f64, N>,
    /// The sensitivity S = ∂x/∂θ (n × p).
    pub s: OMatrix<f64, N, P>,
    /// The running-cost quadrature q = ∫ ℓ dt.
    pub q: f64,
    /// Its parameter gradient q_θ = ∫ (ℓ_x S + ℓ_θ) dt.
    pub qp: OVector<f64, P>,
}

impl<N: Dim, P: Dim> AugState<N, P>
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    /// self = start + h Σ_j c_j k_j over x, S when `sens`, q when `quad` and q_θ when both
    /// (zero coefficients skipped), with start = `base` ([`StageVector::combine`]) or 0
    /// ([`StageVector::lincomb`]). The first term writes start + a k (no separate copy or
    /// fill pass); every operation is the one of copy-then-axpy, in the same order.
    #[inline(always)]
    fn accumulate(
        &mut self,
        base: Option<&Self>,
        h: f64,
        (coefs, ks): (&[f64], &[Self]),
        sens: bool,
        quad: bool,
    ) {
        let mut terms = coefs.iter().zip(ks).filter(|(c, _)| **c != 0.0);
        let Some((c, k)) = terms.next() else {
            // No term: start itself.
            match base {
                Some(b) => self.copy_parts_from(b, sens, quad),
                None => self.fill_parts(0.0, sens, quad),
            }
            return;
        };
        let a = h * c;
        axpy_into(
            self.x.as_mut_slice(),
            base.map(|b| b.x.as_slice()),
            a,
            k.x.as_slice(),
        );
        if quad {
            self.q = base.map_or(0.0, |b| b.q) + a * k.q;
        }
        if sens {
            let s0 = base.map(|b| b.s.as_slice());
            axpy_into(self.s.as_mut_slice(), s0, a, k.s.as_slice());
            if quad {
                let qp0 = base.map(|b| b.qp.as_slice());
                axpy_into(self.qp.as_mut_slice(), qp0, a, k.qp.as_slice());
            }
        }
        for (c, k) in terms {
            let a = h * c;
            axpy_slice(self.x.as_mut_slice(), a, k.x.as_slice());
            if quad {
                self.q += a * k.q;
            }
            if sens {
                axpy_slice(self.s.as_mut_slice(), a, k.s.as_slice());
                if quad {
                    axpy_slice(self.qp.as_mut_slice(), a, k.qp.as_slice());
                }
            }
        }
    }

    /// Copies x, S when `sens`, q when `quad` and q_θ when both from `other`.
    #[inline]
    fn copy_parts_from(&mut self, other: &Self, sens: bool, quad: bool) {
        self.x.as_mut_slice().copy_from_slice(other.x.as_slice());
        if quad {
            self.q = other.q;
        }
        if sens {
            self.s.as_mut_slice().copy_from_slice(other.s.as_slice());
            if quad {
                self.qp.as_mut_slice().copy_from_slice(other.qp.as_slice());
            }
        }
    }

    /// Sets x, S when `sens`, q when `quad` and q_θ when both to `v`.
    #[inline]
    fn fill_parts(&mut self, v: f64, sens: bool, quad: bool) {
        self.x.fill(v);
        if quad {
            self.q = v;
        }
        if sens {
            self.s.fill(v);
            if quad {
                self.qp.fill(v);
            }
        }
    }

    /// All parts zero (x ∈ Rⁿ, S ∈ Rⁿˣᵖ, q, q_θ ∈ Rᵖ).
    #[inline]
    pub fn zeros(n: N, p: P) -> Self {
        AugState {
            x: OVector::zeros_generic(n, Const::<1>),
            s: OMatrix::zeros_generic(n, p),
            q: 0.0,
            qp: OVector::zeros_generic(p, Const::<1>),
        }
    }

    /// Copies every part of `other` into `self` (no allocation; slice copies, which for
    /// dynamic sizes are a memcpy rather than nalgebra's checked element loop).
    #[inline]
    pub fn copy_from(&mut self, other: &Self) {
        self.x.as_mut_slice().copy_from_slice(other.x.as_slice());
        self.s.as_mut_slice().copy_from_slice(other.s.as_slice());
        self.q = other.q;
        self.qp.as_mut_slice().copy_from_slice(other.qp.as_slice());
    }

    /// `self += a · other`, every part.
    pub fn axpy(&mut self, a: f64, other: &Self) {
        StageVector::axpy(self, a, other, true);
    }

    /// Whether every entry of every part is finite.
    pub fn is_finite(&self) -> bool {
        self.x.iter().all(|v| v.is_finite())
            && self.s.iter().all(|v| v.is_finite())
            && self.q.is_finite()
            && self.qp.iter().all(|v| v.is_finite())
    }

    /// Names the first part holding a NaN or infinity, for diagnostics (S and q_θ only when
    /// `sens`).
    pub(super) fn nonfinite_part(&self, sens: bool) -> Option<&'static str> {
        if !self.x.iter().all(|v| v.is_finite()) {
            Some("state x")
        } else if !self.q.is_finite() {
            Some("running cost")
        } else if sens && !self.s.iter().all(|v| v.is_finite()) {
            Some("sensitivity S")
        } else if sens && !self.qp.iter().all(|v| v.is_finite()) {
            Some("running-cost gradient")
        } else {
            None
        }
    }
}

/// `y += a x` on raw slices, four entries per iteration (so pairs of them vectorise) with
/// no bounds checks.
#[inline]
pub(super) fn axpy_slice(y: &mut [f64], a: f64, x: &[f64]) {
    let len = y.len().min(x.len());
    let (y, x) = (&mut y[..len], &x[..len]);
    let mut yc = y.chunks_exact_mut(4);
    let mut xc = x.chunks_exact(4);
    for (yy, xx) in (&mut yc).zip(&mut xc) {
        yy[0] += a * xx[0];
        yy[1] += a * xx[1];
        yy[2] += a * xx[2];
        yy[3] += a * xx[3];
    }
    for (yi, xi) in yc.into_remainder().iter_mut().zip(xc.remainder()) {
        *yi += a * xi;
    }
}

/// `y = b + a x` with b = `base` or 0 (bit-identical to copying b, or filling 0, and then
/// [`axpy_slice`]), four entries per iteration.
#[inline]
fn axpy_into(y: &mut [f64], base: Option<&[f64]>, a: f64, x: &[f64]) {
    let Some(b) = base else {
        let len = y.len().min(x.len());
        let (y, x) = (&mut y[..len], &x[..len]);
        for (yi, xi) in y.iter_mut().zip(x) {
            *yi = 0.0 + a * xi;
        }
        return;
    };
    let len = y.len().min(x.len()).min(b.len());
    let (y, x, b) = (&mut y[..len], &x[..len], &b[..len]);
    let mut yc = y.chunks_exact_mut(4);
    let mut xc = x.chunks_exact(4);
    let mut bc = b.chunks_exact(4);
    for ((yy, xx), bb) in (&mut yc).zip(&mut xc).zip(&mut bc) {
        yy[0] = bb[0] + a * xx[0];
        yy[1] = bb[1] + a * xx[1];
        yy[2] = bb[2] + a * xx[2];
        yy[3] = bb[3] + a * xx[3];
    }
    let rest = yc.into_remainder().iter_mut().zip(xc.remainder());
    for ((yi, xi), bi) in rest.zip(bc.remainder()) {
        *yi = bi + a * xi;
    }
}

/// `out += h Σ_j c_j k_j` over slices, zero coefficients skipped (the primary parts of
/// [`StageVector::combine_primary`] and [`StageVector::lincomb_primary`]).
#[inline]
pub(super) fn accumulate_slices<'a>(
    out: &mut [f64],
    h: f64,
    coefs: &[f64],
    ks: impl Iterator<Item = &'a [f64]>,
) {
    for (c, k) in coefs.iter().zip(ks) {
        if *c != 0.0 {
            axpy_slice(out, h * c, k);
        }
    }
}

/// `o = Σ_i w_i v_i` elementwise over five slices, summed left to right.
#[inline]
pub(super) fn mix5_slice(o: &mut [f64], w: &[f64; 5], v: [&[f64]; 5]) {
    for i in 0..o.len() {
        o[i] = w[0] * v[0][i] + w[1] * v[1][i] + w[2] * v[2][i] + w[3] * v[3][i] + w[4] * v[4][i];
    }
}

/// Cubic Hermite weights (w₀, w₁, c) with y(θ) = y₀ + c (y₁ − y₀) + h (w₀ f₀ + w₁ f₁):
/// c = 3θ² − 2θ³, w₀ = θ − 2θ² + θ³, w₁ = θ³ − θ².
#[inline]
fn hermite_weights(theta: f64) -> (f64, f64, f64) {
    let t2 = theta * theta;
    let t3 = t2 * theta;
    (theta - 2.0 * t2 + t3, t3 - t2, 3.0 * t2 - 2.0 * t3)
}

/// d = a + c (b − a) + h (w₀ f₀ + w₁ f₁), elementwise, from `[a, b, f₀, f₁]`.
#[inline]
pub(super) fn hermite_slice(d: &mut [f64], [a, b, f0, f1]: [&[f64]; 4], h: f64, th: f64) {
    let (w0, w1, c) = hermite_weights(th);
    for ((((di, ai), bi), g0), g1) in d.iter_mut().zip(a).zip(b).zip(f0).zip(f1) {
        *di = ai + c * (bi - ai) + h * (w0 * g0 + w1 * g1);
    }
}

impl<N: Dim, P: Dim> StageVector for AugState<N, P>
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    type Primary = OVector<f64, N>;

    #[inline]
    fn copy_from(&mut self, other: &Self) {
        AugState::copy_from(self, other);
    }

    #[inline]
    fn combine(&mut self, base: &Self, h: f64, coefs: &[f64], ks: &[Self], all: bool) {
        self.accumulate(Some(base), h, (coefs, ks), all, true);
    }

    #[inline]
    fn lincomb(&mut self, h: f64, coefs: &[f64], ks: &[Self], all: bool) {
        self.accumulate(None, h, (coefs, ks), all, true);
    }

    /// x and, when `reads`, S: F never reads the quadratures q and q_θ of its argument, so
    /// a stage argument leaves them as they were.
    #[inline]
    fn combine_argument(&mut self, base: &Self, h: f64, coefs: &[f64], ks: &[Self], reads: bool) {
        self.accumulate(Some(base), h, (coefs, ks), reads, false);
    }

    #[inline]
    fn axpy(&mut self, a: f64, other: &Self, all: bool) {
        axpy_slice(self.x.as_mut_slice(), a, other.x.as_slice());
        self.q += a * other.q;
        if all {
            axpy_slice(self.s.as_mut_slice(), a, other.s.as_slice());
            axpy_slice(self.qp.as_mut_slice(), a, other.qp.as_slice());
        }
    }

    #[inline]
    fn mix5(&mut self, w: &[f64; 5], v: [&Self; 5], all: bool) {
        Self::mix5_primary(&mut self.x, w, v);
        self.q = w[0] * v[0].q + w[1] * v[1].q + w[2] * v[2].q + w[3] * v[3].q + w[4] * v[4].q;
        if all {
            mix5_slice(self.s.as_mut_slice(), w, v.map(|u| u.s.as_slice()));
            mix5_slice(self.qp.as_mut_slice(), w, v.map(|u| u.qp.as_slice()));
        }
    }

    #[inline]
    fn hermite(&mut self, step: &HermiteStep<'_, Self>, th: f64, all: bool) {
        Self::hermite_primary(&mut self.x, step, th);
        let mut q = [0.0];
        hermite_slice(&mut q, step.parts(|v| slice::from_ref(&v.q)), step.h, th);
        self.q = q[0];
        if all {
            let s = step.parts(|v| v.s.as_slice());
            hermite_slice(self.s.as_mut_slice(), s, step.h, th);
            let qp = step.parts(|v| v.qp.as_slice());
            hermite_slice(self.qp.as_mut_slice(), qp, step.h, th);
        }
    }

    #[inline]
    fn is_finite(&self) -> bool {
        AugState::is_finite(self)
    }

    #[inline]
    fn primary(&self) -> &[f64] {
        self.x.as_slice()
    }
}

/// The weighted RMS norm sqrt(1/N Σ_i (w_i e_i / (atol + rtol·w_i·max(|y0_i|, |y1_i|)))²),
/// accumulated part by part (each part with its own weight w), so every system measures its
/// local error the same way. Entries whose scale is 0 are not counted in N.
pub(super) struct WeightedRms {
    tol: Tol,
    sum: f64,
    count: usize,
}

impl WeightedRms {
    /// An empty sum for the tolerances `tol`.
    #[inline]
    pub(super) fn new(tol: Tol) -> Self {
        WeightedRms {
            tol,
            sum: 0.0,
            count: 0,
        }
    }

    /// Adds the entries of one part: its error `e`, its values `y0`, `y1` at the two ends of
    /// the step, and its weight `w`.
    #[inline]
    pub(super) fn add(&mut self, e: &[f64], y0: &[f64], y1: &[f64], w: f64) {
        let rw = self.tol.rtol * w;
        for ((ei, a), b) in e.iter().zip(y0).zip(y1) {
            self.add_one(*ei, magnitude(*a, *b), w, rw);
        }
    }

    /// Adds one entry: its error `e`, its values `y0`, `y1` at the two ends of the step, and
    /// its weight `w`.
    #[inline]
    pub(super) fn add_entry(&mut self, e: f64, y0: f64, y1: f64, w: f64) {
        self.add_one(e, magnitude(y0, y1), w, self.tol.rtol * w);
    }

    /// Adds one entry: error `e`, magnitude `m` = max(|y0|, |y1|), weight `w`, `rw` = rtol·w.
    #[inline(always)]
    fn add_one(&mut self, e: f64, m: f64, w: f64, rw: f64) {
        let scale = self.tol.atol + rw * m;
        // A component with scale 0 (atol = 0 and y = 0 at both ends, as S at t = 0 when
        // x₀ does not depend on θ) has no relative accuracy to hold: it is left out, rather
        // than making the norm infinite and the (first) step zero.
        if scale != 0.0 {
            if e != 0.0 {
                let r = w * e / scale;
                self.sum += r * r;
            }
            self.count += 1;
        }
    }

    /// The norm (0 when nothing was counted).
    #[inline]
    pub(super) fn norm(&self) -> f64 {
        if self.count == 0 {
            return 0.0;
        }
        (self.sum / self.count as f64).sqrt()
    }
}

/// max(|a|, |b|) for the scale of an error entry, as one compare (no NaN-aware `f64::max`:
/// the end state `b` of a step is NaN only in an attempt that the stepper rejects for it
/// anyway, whatever its norm; the start state `a` of a step is always finite).
#[inline(always)]
fn magnitude(a: f64, b: f64) -> f64 {
    let (a, b) = (a.abs(), b.abs());
    if a > b {
        a
    } else {
        b
    }
}

/// [`WeightedRms`] over x, q (with a running cost) and, under sensitivity error control
/// (`sens_err`), S and q_θ. The weight is 1 on x and q and [`sens_weight`]`(θ_j)` on column j
/// of S and on q_θ[j], so both are measured as the change θ_j·S_j they predict for a relative
/// change of θ_j.
pub(super) fn weighted_rms<N: Dim, P: Dim>(
    e: &AugState<N, P>,
    y0: &AugState<N, P>,
    y1: &AugState<N, P>,
    tol: Tol,
    has_rc: bool,
    sens_err: bool,
    theta: &OVector<f64, P>,
) -> f64
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    let mut rms = WeightedRms::new(tol);
    rms.add(e.x.as_slice(), y0.x.as_slice(), y1.x.as_slice(), 1.0);
    if has_rc {
        rms.add_one(e.q, magnitude(y0.q, y1.q), 1.0, tol.rtol);
    }
    if sens_err {
        // Column j of S, then q_θ[j], in one pass over the columns.
        let n = e.x.len();
        let [es, as_, bs] = [e, y0, y1].map(|v| v.s.as_slice());
        for (j, th) in theta.iter().enumerate() {
            let w = sens_weight(*th);
            let col = j * n..(j + 1) * n;
            rms.add(&es[col.clone()], &as_[col.clone()], &bs[col], w);
            if has_rc {
                rms.add_one(e.qp[j], magnitude(y0.qp[j], y1.qp[j]), w, tol.rtol * w);
            }
        }
    }
    rms.norm()
}

/// The weight of parameter θ_j's sensitivities in the error norm: |θ_j|, or 1 when θ_j = 0
/// (the parameter scaling `pbar` of CVODES). Unweighted, a parameter of size 1e-8 has
/// sensitivities of size 1e8 whose rounding floor (ε·1e8) lies above any absolute
/// tolerance, and one of size 1e8 has sensitivities too small to be controlled at all;
/// weighted, every column is held to the accuracy the state itself is held to.
pub(crate) fn sens_weight(theta: f64) -> f64 {
    if theta != 0.0 && theta.is_finite() {
        theta.abs()
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn aug_state_axpy_and_combine() {
        let n = Const::<2>;
        let p = Const::<4>;
        let mut a = AugState::zeros(n, p);
        let mut b = AugState::zeros(n, p);
        b.x[0] = 1.0;
        b.s[(1, 3)] = 2.0;
        b.q = 3.0;
        b.qp[2] = 4.0;
        a.axpy(2.0, &b);
        assert_relative_eq!(a.x[0], 2.0);
        assert_relative_eq!(a.s[(1, 3)], 4.0);
        assert_relative_eq!(a.q, 6.0);
        assert_relative_eq!(a.qp[2], 8.0);
        let mut d = AugState::zeros(n, p);
        d.combine(&a, 0.5, &[1.0, 0.0], &[b.clone(), a.clone()], false);
        assert_relative_eq!(d.x[0], 2.5);
        assert_relative_eq!(d.q, 7.5);
        // all == false leaves S and q_θ of dst alone.
        assert_relative_eq!(d.s[(1, 3)], 0.0);
        d.combine(&a, 0.5, &[1.0], &[b], true);
        assert_relative_eq!(d.s[(1, 3)], 5.0);
        assert_relative_eq!(d.qp[2], 10.0);
    }
}
