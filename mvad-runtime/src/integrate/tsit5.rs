//! Tsitouras' 5(4) pair (Ch. Tsitouras, "Runge–Kutta pairs of order 5(4) satisfying only the
//! first column simplifying assumption", Comput. Math. Appl. 62 (2011) 770–775).
//!
//! Seven stages, FSAL: b = a₇,· and c₆ = c₇ = 1, so k₇ = F(t + h, y₁) is the next step's k₁
//! (reused only between accepted steps of the same segment — a restart discards it). The
//! error estimate is h Σ b̃_i k_i with b̃ = b − b̂ (4th order); the continuous extension is
//! y(t₀ + θh) = y₀ + h Σ b_i(θ) k_i with the quartic polynomials b_i(θ) of the paper, which
//! reproduce b_i at θ = 1 (4th-order dense output).

use super::{combine, combine_x, AugState, Integrator};
use crate::model::{HybridModel, ModelAlloc};
use nalgebra::{DefaultAllocator, Dim, OVector};

/// Number of stages.
pub(super) const STAGES: usize = 7;

/// Nodes c_i.
const C: [f64; STAGES] = [0.0, 0.161, 0.327, 0.9, 0.980_025_540_904_509_7, 1.0, 1.0];

/// Coupling coefficients a_ij (row i = stage i, 0-based; the last row is b).
const A: [[f64; 6]; STAGES] = [
    [0.0; 6],
    [0.161, 0.0, 0.0, 0.0, 0.0, 0.0],
    [
        -0.008_480_655_492_356_989,
        0.335_480_655_492_357,
        0.0,
        0.0,
        0.0,
        0.0,
    ],
    [
        2.897_153_057_105_493_5,
        -6.359_448_489_975_075,
        4.362_295_432_869_581_5,
        0.0,
        0.0,
        0.0,
    ],
    [
        5.325_864_828_439_257,
        -11.748_883_564_062_828,
        7.495_539_342_889_836_5,
        -0.092_495_066_361_755_25,
        0.0,
        0.0,
    ],
    [
        5.861_455_442_946_42,
        -12.920_969_317_847_11,
        8.159_367_898_576_159,
        -0.071_584_973_281_401,
        -0.028_269_050_394_068_383,
        0.0,
    ],
    [
        0.096_460_766_818_065_23,
        0.01,
        0.479_889_650_414_499_6,
        1.379_008_574_103_742,
        -3.290_069_515_436_081,
        2.324_710_524_099_774,
    ],
];

/// b − b̂ (the error weights).
const BTILDE: [f64; STAGES] = [
    -0.001_780_011_052_225_777,
    -0.000_816_434_459_656_746_9,
    0.007_880_878_010_261_995,
    -0.144_711_007_173_262_9,
    0.582_357_165_452_555_2,
    -0.458_082_105_929_186_97,
    0.015_151_515_151_515_152,
];

/// Dense-output polynomials b_i(θ) = r_i1 θ + r_i2 θ² + r_i3 θ³ + r_i4 θ⁴, rows (r_i1..r_i4).
const R: [[f64; 4]; STAGES] = [
    [
        1.0,
        -2.763_706_197_274_826,
        2.913_255_461_821_912_6,
        -1.053_088_497_729_021_6,
    ],
    [0.0, 0.131_7, -0.223_4, 0.101_7],
    [
        0.0,
        3.930_296_236_894_751_6,
        -5.941_033_872_131_505,
        2.490_627_285_651_253,
    ],
    [
        0.0,
        -12.411_077_166_933_676,
        30.338_188_630_282_32,
        -16.548_102_889_244_902,
    ],
    [
        0.0,
        37.509_313_416_511_04,
        -88.178_904_894_766_4,
        47.379_521_962_819_28,
    ],
    [
        0.0,
        -27.896_526_289_197_286,
        65.091_894_674_793_66,
        -34.870_657_861_496_61,
    ],
    [0.0, 1.5, -4.0, 2.5],
];

/// The weights b_i(θ) of the continuous extension.
fn weights(theta: f64) -> [f64; STAGES] {
    let mut b = [0.0; STAGES];
    for (bi, r) in b.iter_mut().zip(&R) {
        *bi = theta * (r[0] + theta * (r[1] + theta * (r[2] + theta * r[3])));
    }
    b
}

/// y(t₀ + θh) for the whole augmented state.
pub(super) fn dense<N: Dim, P: Dim>(
    k: &[AugState<N, P>],
    y0: &AugState<N, P>,
    h: f64,
    theta: f64,
    sens: bool,
    out: &mut AugState<N, P>,
) where
    DefaultAllocator: ModelAlloc<N, P>,
{
    combine(out, y0, h, &weights(theta), &k[..STAGES], sens);
}

/// x(t₀ + θh) only.
pub(super) fn dense_x<N: Dim, P: Dim>(
    k: &[AugState<N, P>],
    y0: &AugState<N, P>,
    h: f64,
    theta: f64,
    out: &mut OVector<f64, N>,
) where
    DefaultAllocator: ModelAlloc<N, P>,
{
    combine_x(out, &y0.x, h, &weights(theta), &k[..STAGES]);
}

impl<M: HybridModel> Integrator<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// One Tsit5 attempt from (t, y) with k[0] = F(t, y): stages into k[1..7], the candidate
    /// into `ynew`, the error into `yerr`; returns ‖yerr‖ and records Hairer's stiffness ratio.
    pub(super) fn tsit5_attempt(&mut self, h: f64) -> f64 {
        let sens = self.rhs.sens;
        let t = self.t;
        for i in 1..STAGES - 1 {
            combine(&mut self.tmp, &self.y, h, &A[i][..i], &self.k[..i], sens);
            self.rhs.eval(t + C[i] * h, &self.tmp, &mut self.k[i]);
        }
        // tmp now holds the 6th stage argument (c₆ = 1).
        combine(&mut self.ynew, &self.y, h, &A[6], &self.k[..6], sens);
        self.rhs.eval(t + h, &self.ynew, &mut self.k[6]);
        // Only the parts under error control are needed.
        super::lincomb(&mut self.yerr, h, &BTILDE, &self.k[..STAGES], self.sens_err);
        // Hairer's stiffness estimate: both k₆ and k₇ are f at t + h, at y₆ and y₇ = y₁.
        let mut num = 0.0;
        let mut den = 0.0;
        for i in 0..self.ynew.x.len() {
            let dk = self.k[6].x[i] - self.k[5].x[i];
            let dy = self.ynew.x[i] - self.tmp.x[i];
            num += dk * dk;
            den += dy * dy;
        }
        self.stiff_ratio = if den > 0.0 {
            h * (num / den).sqrt()
        } else {
            0.0
        };
        self.error_norm()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn tableau_consistency() {
        // Row sums equal the nodes; b̃ sums to 0; b_i(1) = b_i = a_7i; b_i(0) = 0.
        for i in 0..STAGES {
            let s: f64 = A[i].iter().sum();
            assert_relative_eq!(s, C[i], epsilon = 1e-14);
        }
        assert_relative_eq!(BTILDE.iter().sum::<f64>(), 0.0, epsilon = 1e-14);
        let b1 = weights(1.0);
        for j in 0..6 {
            assert_relative_eq!(b1[j], A[6][j], epsilon = 1e-13);
        }
        assert_relative_eq!(b1[6], 0.0, epsilon = 1e-14);
        assert!(weights(0.0).iter().all(|b| *b == 0.0));
        // Quadrature orders of b: Σ b_i c_i^(q−1) = 1/q for q = 1..5.
        for q in 1..=5 {
            let s: f64 = (0..6).map(|j| A[6][j] * C[j].powi(q - 1)).sum();
            assert_relative_eq!(s, 1.0 / q as f64, epsilon = 1e-13);
        }
    }
}
