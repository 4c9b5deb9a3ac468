//! Rodas5P: a stiffly accurate Rosenbrock method of order 5(4) with a 4th-order dense output
//! (G. Steinebach, "Improvement of Rosenbrock–Wanner method RODASP", 2023; coefficients as
//! tabulated in OrdinaryDiffEq.jl).
//!
//! ## The scheme
//! With Y the integrated vector, F its right-hand side, J = ∂F/∂Y at (t₀, Y₀) and
//! F_t = ∂F/∂t there, stage i (i = 1..8) solves
//!
//! ```text
//!   (I/(hγ) − J) K_i = F(t₀ + c_i h, Y₀ + Σ_{j<i} a_ij K_j) + Σ_{j<i} (C_ij/h) K_j + h d_i F_t
//! ```
//!
//! and Y₁ = Y₀ + Σ_{j<6} a_6j K_j + K₆ + K₇ + K₈ (stiffly accurate: the last two stages are
//! evaluated at t₀ + h); K₈ is the local error estimate. The dense output is
//! Y(θ) = (1−θ) Y₀ + θ (Y₁ + (1−θ)(D₁ + θ (D₂ + θ D₃))), D_j = Σ_i H_ji K_i.
//! h is signed (a backward step has h < 0 and factorises I − hγ J with hγ < 0).
//!
//! Every stage goes through the same routine: build R, then [`ImplicitSystem::solve_stage`];
//! how a system solves its (block-triangular) stage equation with one factorisation of the
//! n × n matrix W = I − hγ f_x is the system's business (for the forward augmented state see
//! [`super::forward`]). [`WMatrix`] is that factorisation, shared by every system.

use super::system::{ImplicitSystem, Linearised, StageVector};
use super::Integrator;
use nalgebra::allocator::Allocator;
use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector};

/// Rodas5P stages.
pub(super) const NSTAGES: usize = 8;
/// Slots in the stage vector: k[0] = F(t₀, Y₀), k[1..=8] the stages, k[9..=11] the dense
/// coefficients D₁, D₂, D₃.
pub(super) const STAGES: usize = 1 + NSTAGES + 3;

/// γ.
const GAMMA: f64 = 0.211_937_563_194_290_14;

/// a_ij (row i = stage i, 0-based); rows 7 and 8 take the previous argument plus K₆, K₇, and
/// the last row is the solution: the 8th argument plus K₈.
#[rustfmt::skip]
const A: [[f64; NSTAGES]; NSTAGES + 1] = [
    [0.0; NSTAGES],
    [3.0, 0.0, 0.0, 0.0,
     0.0, 0.0, 0.0, 0.0],
    [2.849394379747939, 0.45842242204463923, 0.0, 0.0,
     0.0, 0.0, 0.0, 0.0],
    [-6.954028509809101, 2.489845061869568, -10.358996098473584, 0.0,
     0.0, 0.0, 0.0, 0.0],
    [2.8029986275628964, 0.5072464736228206, -0.3988312541770524, -0.04721187230404641,
     0.0, 0.0, 0.0, 0.0],
    [-7.502846399306121, 2.561846144803919, -11.627539656261098, -0.18268767659942256,
     0.030198172008377946, 0.0, 0.0, 0.0],
    [-7.502846399306121, 2.561846144803919, -11.627539656261098, -0.18268767659942256,
     0.030198172008377946, 1.0, 0.0, 0.0],
    [-7.502846399306121, 2.561846144803919, -11.627539656261098, -0.18268767659942256,
     0.030198172008377946, 1.0, 1.0, 0.0],
    [-7.502846399306121, 2.561846144803919, -11.627539656261098, -0.18268767659942256,
     0.030198172008377946, 1.0, 1.0, 1.0],
];

/// C_ij (row i = stage i, 0-based).
#[rustfmt::skip]
const CC: [[f64; NSTAGES]; NSTAGES] = [
    [0.0; NSTAGES],
    [-14.155112264123755, 0.0, 0.0, 0.0,
     0.0, 0.0, 0.0, 0.0],
    [-17.97296035885952, -2.859693295451294, 0.0, 0.0,
     0.0, 0.0, 0.0, 0.0],
    [147.12150275711716, -1.41221402718213, 71.68940251302358, 0.0,
     0.0, 0.0, 0.0, 0.0],
    [165.43517024871676, -0.4592823456491126, 42.90938336958603, -5.961986721573306,
     0.0, 0.0, 0.0, 0.0],
    [24.854864614690072, -3.0009227002832186, 47.4931110020768, 5.5814197821558125,
     -0.6610691825249471, 0.0, 0.0, 0.0],
    [30.91273214028599, -3.1208243349937974, 77.79954646070892, 34.28646028294783,
     -19.097331116725623, -28.087943162872662, 0.0, 0.0],
    [37.80277123390563, -3.2571969029072276, 112.26918849496327, 66.9347231244047,
     -40.06618937091002, -54.66780262877968, -9.48861652309627, 0.0],
];

/// Nodes c_i.
#[rustfmt::skip]
const C: [f64; NSTAGES] = [
    0.0, 0.6358126895828704, 0.4095798393397535, 0.9769306725060716,
    0.4288403609558664, 1.0, 1.0, 1.0,
];

/// d_i (weights of h F_t).
#[rustfmt::skip]
const D: [f64; NSTAGES] = [
    0.21193756319429014, -0.42387512638858027, -0.3384627126235924, 1.8046452872882734,
    2.325825639765069, 0.0, 0.0, 0.0,
];

/// Dense-output weights H_ji.
#[rustfmt::skip]
const H: [[f64; NSTAGES]; 3] = [
    [25.948786856663858, -2.5579724845846235, 10.433815404888879, -2.3679251022685204,
     0.524948541321073, 1.1241088310450404, 0.4272876194431874, -0.17202221070155493],
    [-9.91568850695171, -0.9689944594115154, 3.0438037242978453, -24.495224566215796,
     20.176138334709044, 15.98066361424651, -6.789040303419874, -6.710236069923372],
    [11.419903575922262, 2.8879645146136994, 72.92137995996029, 80.12511834622643,
     -52.072871366152654, -59.78993625266729, -0.15582684282751913, 4.883087185713722],
];

/// The n × n matrix f_x of a step start and the in-place LU factors of W = I − hγ f_x
/// (allocated once; zero-sized for `Dyn` when the method is never used).
pub struct WMatrix<N: Dim>
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    /// f_x at the step start.
    pub jac: OMatrix<f64, N, N>,
    /// LU factors of W for the current attempt, in place (unit lower triangle below the
    /// diagonal, U on and above it), valid when `lu_ok`.
    wlu: OMatrix<f64, N, N>,
    /// Row interchanges of the partial pivoting: row i was swapped with row piv[i] ≥ i.
    piv: OVector<usize, N>,
    /// `wlu`/`piv` hold a regular factorisation for `lu_hg`.
    lu_ok: bool,
    /// hγ that `wlu` was factorised for.
    lu_hg: f64,
    /// Spectral-radius estimate of `jac` (for `auto`).
    pub rho: f64,
    /// Power-iteration scratch.
    pv: OVector<f64, N>,
    pw: OVector<f64, N>,
}

impl<N: Dim> WMatrix<N>
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    /// Buffers for n states when `used`; empty for `Dyn` sizes otherwise.
    pub fn new(n: N, used: bool) -> Self {
        let n = if used || N::try_to_usize().is_some() {
            n
        } else {
            N::from_usize(0)
        };
        WMatrix {
            jac: OMatrix::zeros_generic(n, n),
            wlu: OMatrix::zeros_generic(n, n),
            piv: OVector::from_element_generic(n, Const::<1>, 0),
            lu_ok: false,
            lu_hg: 0.0,
            rho: 0.0,
            pv: OVector::zeros_generic(n, Const::<1>),
            pw: OVector::zeros_generic(n, Const::<1>),
        }
    }

    /// Forgets the factors.
    pub fn invalidate(&mut self) {
        self.lu_ok = false;
    }

    /// hγ of the current regular factorisation.
    pub fn factorised_for(&self) -> Option<f64> {
        self.lu_ok.then_some(self.lu_hg)
    }

    /// Factorises W = I − hγ f_x in place by Gaussian elimination with partial pivoting
    /// (PW = LU, the algorithm of nalgebra's `LU::new`), on the buffers of this struct so that
    /// no factorisation allocates (`LU::new` takes its matrix by value and allocates its
    /// permutation for `Dyn` sizes). Built from nalgebra's public operations only: `icamax`
    /// picks the pivot, `swap_rows` interchanges rows, and step i scales the column below the
    /// pivot, l = W[i+1.., i]/W[i, i], then updates the trailing block column by column,
    /// W[i+1.., k] −= W[i, k]·l (`axpy`). Returns false for a singular W.
    pub fn factorise(&mut self, hg: f64) -> bool {
        let n = self.wlu.nrows();
        self.wlu.copy_from(&self.jac);
        self.wlu *= -hg;
        for i in 0..n {
            self.wlu[(i, i)] += 1.0;
        }
        self.lu_hg = hg;
        self.lu_ok = false;
        for i in 0..n {
            let piv = self.wlu.view_range(i.., i).icamax() + i;
            let diag = self.wlu[(piv, i)];
            if diag == 0.0 || !diag.is_finite() {
                return false;
            }
            self.piv[i] = piv;
            if piv != i {
                self.wlu.swap_rows(i, piv);
            }
            let mut block = self.wlu.view_range_mut(i.., i..);
            let (mut col, mut rest) = block.columns_range_pair_mut(0, 1..);
            let mut l = col.rows_range_mut(1..);
            l *= 1.0 / diag;
            let (urow, mut down) = rest.rows_range_pair_mut(0, 1..);
            for k in 0..urow.ncols() {
                down.column_mut(k).axpy(-urow[k], &l, 1.0);
            }
        }
        self.lu_ok = true;
        true
    }

    /// b := W⁻¹ b with the factors of [`WMatrix::factorise`] (row interchanges, then
    /// nalgebra's unit-lower and upper triangular solves, as `LU::solve_mut`).
    pub fn solve_mut<C: Dim>(&self, b: &mut OMatrix<f64, N, C>) -> bool
    where
        DefaultAllocator: Allocator<N, C>,
    {
        if !self.lu_ok {
            return false;
        }
        for (i, &p) in self.piv.iter().enumerate() {
            if p != i {
                b.swap_rows(i, p);
            }
        }
        let _ = self.wlu.solve_lower_triangular_with_diag_mut(b, 1.0);
        self.wlu.solve_upper_triangular_mut(b)
    }

    /// rk := hγ W⁻¹ rk in place (R in, K out), the stage solve of a block that W alone
    /// governs; false (rk untouched) without factors.
    pub fn solve_scaled(&self, hg: f64, rk: &mut OVector<f64, N>) -> bool {
        if !self.lu_ok {
            return false;
        }
        *rk *= hg;
        self.solve_mut(rk)
    }

    /// ρ(f_x) ≈ (‖J⁸v‖/‖v‖)^(1/8) from a fixed start vector (geometric mean of the growth
    /// factors of 8 power steps; within a small factor of ρ also for complex pairs, and 0 for
    /// nilpotent Jacobians such as the ball's); stored in `rho` and returned.
    pub fn power_iteration(&mut self) -> f64 {
        self.rho = self.power_iteration_inner();
        self.rho
    }

    fn power_iteration_inner(&mut self) -> f64 {
        let n = self.pv.len();
        if n == 0 {
            return 0.0;
        }
        for (i, v) in self.pv.iter_mut().enumerate() {
            // Deterministic, with no special structure (not orthogonal to coordinate axes).
            *v = 1.0 + 0.618_033_988_749_895 * ((i * 7 + 3) % 11) as f64;
        }
        let nv = self.pv.norm();
        self.pv /= nv;
        let mut log_growth = 0.0;
        const ITERS: usize = 8;
        for _ in 0..ITERS {
            self.pw.gemv(1.0, &self.jac, &self.pv, 0.0);
            let g = self.pw.norm();
            // Nilpotent (g = 0) or broken (non-finite) Jacobian: no stiffness evidence.
            if g.is_nan() || g <= 0.0 || g.is_infinite() {
                return 0.0;
            }
            log_growth += g.ln();
            self.pv.copy_from(&self.pw);
            self.pv /= g;
        }
        (log_growth / ITERS as f64).exp()
    }
}

/// J of the step start (in `w`, with the factors of W = I − hγ J), F_t there (`dt`, a vector
/// of the system's shape) and whether both belong to the current step start. A system fills
/// `w.jac` and `dt` in its [`ImplicitSystem::prepare`] and sets `prepared`.
pub struct Linearisation<N: Dim, V>
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    /// J (or, for the forward system, its f_x block) and the factors of W.
    pub w: WMatrix<N>,
    /// F_t at the step start.
    pub dt: V,
    /// `w.jac` and `dt` belong to the current step start.
    pub prepared: bool,
}

impl<N: Dim, V> Linearisation<N, V>
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    /// Not prepared, with the buffers `w` and `dt`.
    pub fn new(w: WMatrix<N>, dt: V) -> Self {
        Linearisation {
            w,
            dt,
            prepared: false,
        }
    }
}

impl<N: Dim, V> Linearised<V> for Linearisation<N, V>
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    #[inline]
    fn prepared(&self) -> bool {
        self.prepared
    }

    #[inline]
    fn time_derivative(&self) -> &V {
        &self.dt
    }

    #[inline]
    fn factorise(&mut self, hg: f64) -> bool {
        self.w.factorise(hg)
    }

    #[inline]
    fn factorised_for(&self) -> Option<f64> {
        self.w.factorised_for()
    }

    #[inline]
    fn invalidate(&mut self) {
        self.prepared = false;
        self.w.invalidate();
    }

    #[inline]
    fn spectral_radius(&self) -> f64 {
        self.w.rho
    }
}

/// Stage s's row of a (its argument Y₀ + Σ_{j<s} a_sj K_j) and its node c_s.
pub(super) fn stage_row(s: usize) -> (&'static [f64], f64) {
    (&A[s][..s], C[s])
}

/// The weights (ω, ω_t) of a quadrature's Rosenbrock update over a step cut at θ (θ = 1: the
/// whole step): ΔQ = Σ_s ω_s h (G_s + J_QY K_s) + ω_t h² G_t (see `quadrature.rs`). The stage
/// weights of the update are v_s = a_{8s} for the solution and
/// v_s = θ a_{8s} + θ(1−θ)(H_1s + θ H_2s + θ² H_3s) for the dense output; then
/// (I − γC)ᵀ z = v by back substitution, ω = γz, ω_t = Σ_s ω_s d_s.
pub(super) fn quadrature_weights(theta: f64) -> ([f64; NSTAGES], f64) {
    let mut z = A[NSTAGES];
    if theta != 1.0 {
        let t1 = theta * (1.0 - theta);
        for (s, zs) in z.iter_mut().enumerate() {
            *zs = theta * *zs + t1 * (H[0][s] + theta * (H[1][s] + theta * H[2][s]));
        }
    }
    update_weights(z)
}

/// The weights (ω, ω_t) of the Rosenbrock error estimate K₈ of a quadrature (its Q-block;
/// see `quadrature.rs`): the update's with v = e₈.
pub(super) fn quadrature_error_weights() -> ([f64; NSTAGES], f64) {
    let mut v = [0.0; NSTAGES];
    v[NSTAGES - 1] = 1.0;
    update_weights(v)
}

/// (ω, ω_t) for the stage weights v of an update vᵀK_Q: (I − γC)ᵀ z = v by back
/// substitution, ω = γz, ω_t = Σ_s ω_s d_s.
fn update_weights(mut z: [f64; NSTAGES]) -> ([f64; NSTAGES], f64) {
    for s in (0..NSTAGES).rev() {
        for j in s + 1..NSTAGES {
            z[s] += GAMMA * CC[j][s] * z[j];
        }
    }
    let omega = z.map(|zs| GAMMA * zs);
    let omega_t = omega.iter().zip(&D).map(|(w, d)| w * d).sum();
    (omega, omega_t)
}

/// Degree in θ of the dense output: θ³(1 − θ) D₃ is its highest term.
pub(super) const DENSE_DEGREE: usize = 4;

/// Weights of (Y₀, Y₁, D₁, D₂, D₃) in the dense output at θ.
#[inline]
fn weights(theta: f64) -> [f64; 5] {
    let t1 = 1.0 - theta;
    [
        t1,
        theta,
        theta * t1,
        theta * theta * t1,
        theta * theta * theta * t1,
    ]
}

/// (1−θ) Y₀ + θ (Y₁ + (1−θ)(D₁ + θ (D₂ + θ D₃))) for every integrated part.
pub(super) fn dense<V: StageVector>(k: &[V], y0: &V, y1: &V, theta: f64, all: bool, out: &mut V) {
    let dk = &k[1 + NSTAGES..STAGES];
    out.mix5(&weights(theta), [y0, y1, &dk[0], &dk[1], &dk[2]], all);
}

/// The primary part of [`dense`].
pub(super) fn dense_primary<V: StageVector>(
    k: &[V],
    y0: &V,
    y1: &V,
    theta: f64,
    out: &mut V::Primary,
) {
    let dk = &k[1 + NSTAGES..STAGES];
    V::mix5_primary(out, &weights(theta), [y0, y1, &dk[0], &dk[1], &dk[2]]);
}

/// [`dense_primary`] as a polynomial in θ, Σ_{m=0..4} θᵐ c_m, into `coefs[0..=4]`:
/// c₀ = Y₀, c₁ = Y₁ − Y₀ + D₁, c₂ = D₂ − D₁, c₃ = D₃ − D₂, c₄ = −D₃.
pub(super) fn poly_primary<V: StageVector>(k: &[V], y0: &V, y1: &V, coefs: &mut [V::Primary]) {
    let dk = &k[1 + NSTAGES..STAGES];
    let v = [y0, y1, &dk[0], &dk[1], &dk[2]];
    y0.primary_into(&mut coefs[0]);
    let rows: [[f64; 5]; DENSE_DEGREE] = [
        [-1.0, 1.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, -1.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, -1.0, 1.0],
        [0.0, 0.0, 0.0, 0.0, -1.0],
    ];
    for (c, w) in coefs[1..=DENSE_DEGREE].iter_mut().zip(&rows) {
        V::mix5_primary(c, w, v);
    }
}

impl<Sys: ImplicitSystem> Integrator<Sys> {
    /// One Rodas5P attempt from (t, y) with k[0] = F(t, y): stages into k[1..=8], dense
    /// coefficients into k[9..=11], the candidate into `ynew`, K₈ into `yerr`; returns ‖K₈‖.
    pub(super) fn rosenbrock_attempt(&mut self, h: f64) -> f64 {
        let all = self.sys.all_parts();
        let t0 = self.t;
        if !self.sys.linearisation().prepared() {
            self.sys.prepare(t0, &self.y, h);
            self.stats.jac_evals += 1;
        }
        let hg = h * GAMMA;
        if self.sys.linearisation().factorised_for() != Some(hg) {
            self.stats.factorizations += 1;
            if !self.sys.linearisation().factorise(hg) {
                return f64::NAN;
            }
        }
        for s in 0..NSTAGES {
            if !self.rosenbrock_stage(s, h, hg, all) {
                return f64::NAN;
            }
        }
        self.ynew
            .combine(&self.y, 1.0, &A[NSTAGES], &self.k[1..=NSTAGES], all);
        self.yerr.copy_from(&self.k[NSTAGES]);
        // Dense coefficients D_j = Σ_i H_ji K_i.
        for (j, hj) in H.iter().enumerate() {
            let (stages, dense) = self.k.split_at_mut(1 + NSTAGES);
            dense[j].lincomb(1.0, hj, &stages[1..], all);
        }
        self.error_norm()
    }

    /// Stage s (0-based) into k[1 + s]: R = F(t₀ + c_s h, Y₀ + Σ a_sj K_j) + Σ (C_sj/h) K_j
    /// + h d_s F_t, then K_s = hγ (I − hγ J)⁻¹ R.
    fn rosenbrock_stage(&mut self, s: usize, h: f64, hg: f64, all: bool) -> bool {
        let t0 = self.t;
        // R is formed in k[1 + s] and solved for K_s in place.
        let (done, tail) = self.k.split_at_mut(1 + s);
        let rk = &mut tail[0];
        if s == 0 {
            rk.copy_from(&done[0]);
        } else {
            let reads = self.sys.reads_secondary();
            self.tmp
                .combine_argument(&self.y, 1.0, &A[s][..s], &done[1..=s], reads);
            self.sys.eval(t0 + C[s] * h, &self.tmp, rk);
            for (c, kj) in CC[s][..s].iter().zip(&done[1..=s]) {
                rk.axpy(c / h, kj, all);
            }
        }
        if D[s] != 0.0 {
            rk.axpy(h * D[s], self.sys.linearisation().time_derivative(), all);
        }
        self.sys.solve_stage(t0, &self.y, hg, rk)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn tableau_consistency() {
        // Stiffly accurate: the last stage argument plus K₈ is the solution; c = 1 there.
        assert!(C[5..].iter().all(|c| *c == 1.0));
        // The dense output reproduces y1 at θ = 1 and y0 at θ = 0.
        assert_eq!(weights(0.0), [1.0, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(weights(1.0), [0.0, 1.0, 0.0, 0.0, 0.0]);
        assert_relative_eq!(D[0], GAMMA);
    }
}
