//! Rodas5P: a stiffly accurate Rosenbrock method of order 5(4) with a 4th-order dense output
//! (G. Steinebach, "Improvement of Rosenbrock–Wanner method RODASP", 2023; coefficients as
//! tabulated in OrdinaryDiffEq.jl).
//!
//! ## The scheme
//! With Y the augmented state, F its right-hand side, J = ∂F/∂Y at (t₀, Y₀) and
//! F_t = ∂F/∂t there, stage i (i = 1..8) solves
//!
//! ```text
//!   (I/(hγ) − J) K_i = F(t₀ + c_i h, Y₀ + Σ_{j<i} a_ij K_j) + Σ_{j<i} (C_ij/h) K_j + h d_i F_t
//! ```
//!
//! and Y₁ = Y₀ + Σ_{j<6} a_6j K_j + K₆ + K₇ + K₈ (stiffly accurate: the last two stages are
//! evaluated at t₀ + h); K₈ is the local error estimate. The dense output is
//! Y(θ) = (1−θ) Y₀ + θ (Y₁ + (1−θ)(D₁ + θ (D₂ + θ D₃))), D_j = Σ_i H_ji K_i.
//!
//! ## The augmented Jacobian, factorised once
//! For Y = (x, S, q, q_θ), J is block lower triangular:
//!
//! ```text
//!        x            S           q   q_θ
//!   x  [ f_x          0           0   0 ]
//!   S  [ B            I_p ⊗ f_x   0   0 ]     B v = ∂_x(f_x S₀ + f_θ) v
//!   q  [ ℓ_x          0           0   0 ]
//!   q_θ[ D            ℓ_xᵀ (·)    0   0 ]     D v = ∂_x(ℓ_x S₀ + ℓ_θ) v
//! ```
//!
//! so with W = I − hγ f_x, factorised by nalgebra's LU ONCE per attempt, every stage is solved
//! exactly by block forward substitution:
//! K_x = W⁻¹ hγ R_x, K_S = W⁻¹ hγ (R_S + B K_x) (all p columns against one factorisation),
//! K_q = hγ (R_q + ℓ_x K_x), K_{q_θ} = hγ (R_{q_θ} + D K_x + K_Sᵀ ℓ_x).
//! f_x is the model's symbolic Jacobian; the second-derivative actions B K_x and D K_x (the
//! model has no second derivatives) are central directional differences of `rhs_sens` /
//! `running_cost_grad` along K_x at (t₀, x₀, S₀), with perturbation ‖εK_x‖ = 1e-4·max(1, ‖x₀‖).
//! Central differences are exact when f_x S + f_θ is at most quadratic in x, and perturb J by
//! O(1e-8) relative for cubic terms; the step is far larger than the usual ε^(1/3) because
//! models with cancellation inside f_θ (a lag (u − y)/τ with ∂/∂τ = −(u − y)/τ²) amplify the
//! rounding of x ± εK_x by 1/ε: with ε^(1/3) the sensitivity of the τ = 1e-8 lag had a 2e-6
//! error floor, with 1e-4 it is 4e-8. F_t: ∂f/∂t is the model's `rhs_dt`; the S and q parts of
//! F_t are central differences in t (only when f depends on t, resp. when there is a running
//! cost), with step ε^(1/3)·max(|t₀|, h).
//! The S and q_θ orders are verified empirically in the tests.

use super::{combine, AugState, Integrator, Rhs};
use crate::model::{HybridModel, ModelAlloc};
use nalgebra::linalg::{gauss_step, gauss_step_swap};
use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

/// Rodas5P stages.
const NSTAGES: usize = 8;
/// Slots in the stage vector: k[0] = F(t₀, Y₀), k[1..=8] the stages, k[9..=11] the dense
/// coefficients D₁, D₂, D₃.
pub(super) const STAGES: usize = 1 + NSTAGES + 3;

/// γ.
const GAMMA: f64 = 0.211_937_563_194_290_14;

/// a_ij (row i = stage i, 0-based); rows 7 and 8 take the previous argument plus K₆, K₇.
const A: [[f64; NSTAGES]; NSTAGES + 1] = [
    [0.0; NSTAGES],
    [3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [
        2.849_394_379_747_939,
        0.458_422_422_044_639_23,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
    ],
    [
        -6.954_028_509_809_101,
        2.489_845_061_869_568,
        -10.358_996_098_473_584,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
    ],
    [
        2.802_998_627_562_896_4,
        0.507_246_473_622_820_6,
        -0.398_831_254_177_052_4,
        -0.047_211_872_304_046_41,
        0.0,
        0.0,
        0.0,
        0.0,
    ],
    [
        -7.502_846_399_306_121,
        2.561_846_144_803_919,
        -11.627_539_656_261_098,
        -0.182_687_676_599_422_56,
        0.030_198_172_008_377_946,
        0.0,
        0.0,
        0.0,
    ],
    [
        -7.502_846_399_306_121,
        2.561_846_144_803_919,
        -11.627_539_656_261_098,
        -0.182_687_676_599_422_56,
        0.030_198_172_008_377_946,
        1.0,
        0.0,
        0.0,
    ],
    [
        -7.502_846_399_306_121,
        2.561_846_144_803_919,
        -11.627_539_656_261_098,
        -0.182_687_676_599_422_56,
        0.030_198_172_008_377_946,
        1.0,
        1.0,
        0.0,
    ],
    // The solution: the 8th argument plus K₈.
    [
        -7.502_846_399_306_121,
        2.561_846_144_803_919,
        -11.627_539_656_261_098,
        -0.182_687_676_599_422_56,
        0.030_198_172_008_377_946,
        1.0,
        1.0,
        1.0,
    ],
];

/// C_ij (row i = stage i, 0-based).
const CC: [[f64; NSTAGES]; NSTAGES] = [
    [0.0; NSTAGES],
    [-14.155_112_264_123_755, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [
        -17.972_960_358_859_52,
        -2.859_693_295_451_294,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
    ],
    [
        147.121_502_757_117_16,
        -1.412_214_027_182_13,
        71.689_402_513_023_58,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
    ],
    [
        165.435_170_248_716_76,
        -0.459_282_345_649_112_6,
        42.909_383_369_586_03,
        -5.961_986_721_573_306,
        0.0,
        0.0,
        0.0,
        0.0,
    ],
    [
        24.854_864_614_690_072,
        -3.000_922_700_283_218_6,
        47.493_111_002_076_8,
        5.581_419_782_155_812_5,
        -0.661_069_182_524_947_1,
        0.0,
        0.0,
        0.0,
    ],
    [
        30.912_732_140_285_99,
        -3.120_824_334_993_797_4,
        77.799_546_460_708_92,
        34.286_460_282_947_83,
        -19.097_331_116_725_623,
        -28.087_943_162_872_662,
        0.0,
        0.0,
    ],
    [
        37.802_771_233_905_63,
        -3.257_196_902_907_227_6,
        112.269_188_494_963_27,
        66.934_723_124_404_7,
        -40.066_189_370_910_02,
        -54.667_802_628_779_68,
        -9.488_616_523_096_27,
        0.0,
    ],
];

/// Nodes c_i.
const C: [f64; NSTAGES] = [
    0.0,
    0.635_812_689_582_870_4,
    0.409_579_839_339_753_5,
    0.976_930_672_506_071_6,
    0.428_840_360_955_866_4,
    1.0,
    1.0,
    1.0,
];

/// d_i (weights of h F_t).
const D: [f64; NSTAGES] = [
    0.211_937_563_194_290_14,
    -0.423_875_126_388_580_27,
    -0.338_462_712_623_592_4,
    1.804_645_287_288_273_4,
    2.325_825_639_765_069,
    0.0,
    0.0,
    0.0,
];

/// Dense-output weights H_ji.
const H: [[f64; NSTAGES]; 3] = [
    [
        25.948_786_856_663_858,
        -2.557_972_484_584_623_5,
        10.433_815_404_888_879,
        -2.367_925_102_268_520_4,
        0.524_948_541_321_073,
        1.124_108_831_045_040_4,
        0.427_287_619_443_187_4,
        -0.172_022_210_701_554_93,
    ],
    [
        -9.915_688_506_951_71,
        -0.968_994_459_411_515_4,
        3.043_803_724_297_845_3,
        -24.495_224_566_215_796,
        20.176_138_334_709_044,
        15.980_663_614_246_51,
        -6.789_040_303_419_874,
        -6.710_236_069_923_372,
    ],
    [
        11.419_903_575_922_262,
        2.887_964_514_613_699_4,
        72.921_379_959_960_29,
        80.125_118_346_226_43,
        -52.072_871_366_152_654,
        -59.789_936_252_667_29,
        -0.155_826_842_827_519_13,
        4.883_087_185_713_722,
    ],
];

/// Buffers of the Rosenbrock method (allocated in `Integrator::new` when the method can be
/// used; zero-sized otherwise).
pub struct RosenbrockWork<N: Dim, P: Dim>
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    /// f_x at the step start.
    jac: OMatrix<f64, N, N>,
    /// LU factors of W = I − hγ f_x for the current attempt, in place (unit lower triangle
    /// below the diagonal, U on and above it), valid when `lu_ok`.
    wlu: OMatrix<f64, N, N>,
    /// Row interchanges of the partial pivoting: row i was swapped with row piv[i] ≥ i.
    piv: OVector<usize, N>,
    /// `wlu`/`piv` hold a regular factorisation for `lu_hg`.
    lu_ok: bool,
    /// hγ that `wlu` was factorised for.
    lu_hg: f64,
    /// ℓ_x at the step start (zeros without running cost).
    lx0: OVector<f64, N>,
    /// ℓ_θ scratch.
    lp0: OVector<f64, P>,
    /// F_t at the step start.
    dt: AugState<N, P>,
    /// Stage right-hand side R.
    r: AugState<N, P>,
    /// Perturbed argument for the difference quotients.
    ypert: AugState<N, P>,
    fplus: AugState<N, P>,
    fminus: AugState<N, P>,
    /// (jac, lx0, dt) belong to the current step start.
    base_valid: bool,
    /// Spectral-radius estimate of the last Jacobian (for `auto`).
    jac_rho: f64,
    /// Power-iteration scratch.
    pv: OVector<f64, N>,
    pw: OVector<f64, N>,
}

impl<N: Dim, P: Dim> RosenbrockWork<N, P>
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    pub(super) fn new(n: N, p: P, used: bool) -> Self {
        // Unused: empty buffers (no allocation for Dyn sizes).
        let n = if used || N::try_to_usize().is_some() {
            n
        } else {
            N::from_usize(0)
        };
        let p = if used || P::try_to_usize().is_some() {
            p
        } else {
            P::from_usize(0)
        };
        let z = || AugState::zeros(n, p);
        RosenbrockWork {
            jac: OMatrix::zeros_generic(n, n),
            wlu: OMatrix::zeros_generic(n, n),
            piv: OVector::from_element_generic(n, nalgebra::Const::<1>, 0),
            lu_ok: false,
            lu_hg: 0.0,
            lx0: OVector::zeros_generic(n, nalgebra::Const::<1>),
            lp0: OVector::zeros_generic(p, nalgebra::Const::<1>),
            dt: z(),
            r: z(),
            ypert: z(),
            fplus: z(),
            fminus: z(),
            base_valid: false,
            jac_rho: 0.0,
            pv: OVector::zeros_generic(n, nalgebra::Const::<1>),
            pw: OVector::zeros_generic(n, nalgebra::Const::<1>),
        }
    }

    /// Forget the Jacobian and F_t (new step start).
    pub(super) fn invalidate(&mut self) {
        self.base_valid = false;
        self.lu_ok = false;
    }

    /// Factorises W = I − hγ f_x in place with partial pivoting: the elimination steps are
    /// nalgebra's (`gauss_step`/`gauss_step_swap`, exactly what `LU::new` runs), but on the
    /// buffers of this struct, so no factorisation allocates (`LU::new` takes its matrix by
    /// value). Returns false for a singular W.
    fn factorise(&mut self, hg: f64) -> bool {
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
                self.wlu.columns_range_mut(..i).swap_rows(i, piv);
                gauss_step_swap(&mut self.wlu, diag, i, piv);
            } else {
                gauss_step(&mut self.wlu, diag, i);
            }
        }
        self.lu_ok = true;
        true
    }

    /// b := W⁻¹ b with the factors of [`RosenbrockWork::factorise`] (row interchanges, then
    /// nalgebra's unit-lower and upper triangular solves, as `LU::solve_mut`).
    fn solve_mut<C: Dim>(&self, b: &mut OMatrix<f64, N, C>) -> bool
    where
        DefaultAllocator: nalgebra::allocator::Allocator<N, C>,
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

    /// Spectral-radius estimate of f_x at the start of the last Rodas5P step.
    pub(super) fn jac_spectral_radius(&self) -> f64 {
        self.jac_rho
    }

    /// Evaluates f_x at (t, x) and returns its spectral-radius estimate (for the stiffness
    /// check of the explicit method; counts as a Jacobian evaluation).
    pub(super) fn spectral_radius_at<M: HybridModel<N = N, P = P>>(
        &mut self,
        rhs: &Rhs<'_, M>,
        t: f64,
        x: &OVector<f64, N>,
    ) -> f64 {
        rhs.model
            .rhs_jac_x(rhs.mode, rhs.sw, t, x, rhs.p, &mut self.jac);
        self.jac_rho = self.power_iteration();
        self.jac_rho
    }

    /// ρ(f_x) ≈ (‖J⁸v‖/‖v‖)^(1/8) from a fixed start vector (geometric mean of the growth
    /// factors of 8 power steps; within a small factor of ρ also for complex pairs, and 0 for
    /// nilpotent Jacobians such as the ball's).
    fn power_iteration(&mut self) -> f64 {
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

/// (1−θ) y0 + θ (y1 + (1−θ)(D₁ + θ (D₂ + θ D₃))) for the whole augmented state.
pub(super) fn dense<N: Dim, P: Dim>(
    k: &[AugState<N, P>],
    y0: &AugState<N, P>,
    y1: &AugState<N, P>,
    theta: f64,
    sens: bool,
    out: &mut AugState<N, P>,
) where
    DefaultAllocator: ModelAlloc<N, P>,
{
    let w = weights(theta);
    let dk = &k[1 + NSTAGES..STAGES];
    let mix = |o: &mut [f64], a: &[f64], b: &[f64], d: [&[f64]; 3]| {
        for i in 0..o.len() {
            o[i] = w[0] * a[i] + w[1] * b[i] + w[2] * d[0][i] + w[3] * d[1][i] + w[4] * d[2][i];
        }
    };
    mix(
        out.x.as_mut_slice(),
        y0.x.as_slice(),
        y1.x.as_slice(),
        [dk[0].x.as_slice(), dk[1].x.as_slice(), dk[2].x.as_slice()],
    );
    out.q = w[0] * y0.q + w[1] * y1.q + w[2] * dk[0].q + w[3] * dk[1].q + w[4] * dk[2].q;
    if sens {
        mix(
            out.s.as_mut_slice(),
            y0.s.as_slice(),
            y1.s.as_slice(),
            [dk[0].s.as_slice(), dk[1].s.as_slice(), dk[2].s.as_slice()],
        );
        mix(
            out.qp.as_mut_slice(),
            y0.qp.as_slice(),
            y1.qp.as_slice(),
            [
                dk[0].qp.as_slice(),
                dk[1].qp.as_slice(),
                dk[2].qp.as_slice(),
            ],
        );
    }
}

/// Weights of (y0, y1, D₁, D₂, D₃) in the dense output at θ.
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

/// x part of [`dense`].
pub(super) fn dense_x<N: Dim, P: Dim>(
    k: &[AugState<N, P>],
    y0: &AugState<N, P>,
    y1: &AugState<N, P>,
    theta: f64,
    out: &mut OVector<f64, N>,
) where
    DefaultAllocator: ModelAlloc<N, P>,
{
    let w = weights(theta);
    let dk = &k[1 + NSTAGES..STAGES];
    let o = out.as_mut_slice();
    let (a, b) = (y0.x.as_slice(), y1.x.as_slice());
    let (d0, d1, d2) = (dk[0].x.as_slice(), dk[1].x.as_slice(), dk[2].x.as_slice());
    for i in 0..o.len() {
        o[i] = w[0] * a[i] + w[1] * b[i] + w[2] * d0[i] + w[3] * d1[i] + w[4] * d2[i];
    }
}

/// Relative size of the perturbation of x in the directional differences (see module doc).
const FD_REL: f64 = 1e-4;
/// Relative step of the central differences in t (ε^(1/3)).
const FD_REL_T: f64 = 6.055_454_452_393_343e-6;

/// Computes f_x, ℓ_x and F_t at the step start (t0, y0).
fn prepare_base<M: HybridModel>(
    rhs: &mut Rhs<'_, M>,
    w: &mut RosenbrockWork<M::N, M::P>,
    t0: f64,
    y0: &AugState<M::N, M::P>,
    h: f64,
) where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let (model, p, mode, sw) = (rhs.model, rhs.p, rhs.mode, rhs.sw);
    model.rhs_jac_x(mode, sw, t0, &y0.x, p, &mut w.jac);
    w.jac_rho = w.power_iteration();
    if rhs.has_rc {
        model.running_cost_grad(sw, t0, &y0.x, p, &mut w.lx0, &mut w.lp0);
    } else {
        w.lx0.fill(0.0);
    }
    // F_t: exact for x; central differences in t for the S and q parts.
    let dep_t = model.rhs_depends_on_t(mode);
    if (dep_t && rhs.sens) || rhs.has_rc {
        let dt = FD_REL_T * t0.abs().max(h).max(f64::MIN_POSITIVE);
        rhs.eval(t0 + dt, y0, &mut w.fplus);
        rhs.eval(t0 - dt, y0, &mut w.fminus);
        let s = 0.5 / dt;
        w.dt.q = (w.fplus.q - w.fminus.q) * s;
        if rhs.sens {
            w.dt.s.fill(0.0);
            super::axpy_slice(w.dt.s.as_mut_slice(), s, w.fplus.s.as_slice());
            super::axpy_slice(w.dt.s.as_mut_slice(), -s, w.fminus.s.as_slice());
            w.dt.qp.fill(0.0);
            super::axpy_slice(w.dt.qp.as_mut_slice(), s, w.fplus.qp.as_slice());
            super::axpy_slice(w.dt.qp.as_mut_slice(), -s, w.fminus.qp.as_slice());
        }
    } else {
        w.dt.q = 0.0;
        w.dt.s.fill(0.0);
        w.dt.qp.fill(0.0);
    }
    if !dep_t {
        w.dt.s.fill(0.0);
    }
    if !rhs.has_rc {
        w.dt.q = 0.0;
        w.dt.qp.fill(0.0);
    }
    model.rhs_dt(mode, sw, t0, &y0.x, p, &mut w.dt.x);
    if rhs.sens {
        w.ypert.s.copy_from(&y0.s);
    }
    w.base_valid = true;
}

/// K = hγ (I − hγ J)⁻¹ R by block forward substitution (see the module doc); R in `w.r`.
fn solve_stage<M: HybridModel>(
    rhs: &mut Rhs<'_, M>,
    w: &mut RosenbrockWork<M::N, M::P>,
    t0: f64,
    y0: &AugState<M::N, M::P>,
    hg: f64,
    k: &mut AugState<M::N, M::P>,
) -> bool
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    if !w.lu_ok {
        return false;
    }
    k.x.copy_from(&w.r.x);
    k.x *= hg;
    let ok_x = w.solve_mut(&mut k.x);
    let lxk = w.lx0.dot(&k.x);
    k.q = hg * (w.r.q + lxk);
    if !rhs.sens {
        return ok_x;
    }
    // B K_x and D K_x by central differences along K_x at (t0, x0, S0).
    let nv = k.x.norm();
    k.s.copy_from(&w.r.s);
    k.qp.copy_from(&w.r.qp);
    if nv > 0.0 && nv.is_finite() {
        let eps = FD_REL * y0.x.norm().max(1.0) / nv;
        w.ypert.x.copy_from(&y0.x);
        w.ypert.x.axpy(eps, &k.x, 1.0);
        rhs.eval(t0, &w.ypert, &mut w.fplus);
        w.ypert.x.copy_from(&y0.x);
        w.ypert.x.axpy(-eps, &k.x, 1.0);
        rhs.eval(t0, &w.ypert, &mut w.fminus);
        let s = 0.5 / eps;
        super::axpy_slice(k.s.as_mut_slice(), s, w.fplus.s.as_slice());
        super::axpy_slice(k.s.as_mut_slice(), -s, w.fminus.s.as_slice());
        if rhs.has_rc {
            super::axpy_slice(k.qp.as_mut_slice(), s, w.fplus.qp.as_slice());
            super::axpy_slice(k.qp.as_mut_slice(), -s, w.fminus.qp.as_slice());
        }
    }
    k.s *= hg;
    let ok_s = w.solve_mut(&mut k.s);
    if rhs.has_rc {
        k.qp.gemv_tr(hg, &k.s, &w.lx0, hg);
    } else {
        k.qp.fill(0.0);
    }
    ok_x && ok_s
}

impl<M: HybridModel> Integrator<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// One Rodas5P attempt from (t, y) with k[0] = F(t, y): stages into k[1..=8], dense
    /// coefficients into k[9..=11], the candidate into `ynew`, K₈ into `yerr`; returns ‖K₈‖.
    pub(super) fn rosenbrock_attempt(&mut self, h: f64) -> f64 {
        let sens = self.rhs.sens;
        let t0 = self.t;
        if !self.ros.base_valid {
            prepare_base(&mut self.rhs, &mut self.ros, t0, &self.y, h);
            self.stats.jac_evals += 1;
        }
        let hg = h * GAMMA;
        if !self.ros.lu_ok || self.ros.lu_hg != hg {
            self.stats.factorizations += 1;
            if !self.ros.factorise(hg) {
                return f64::NAN;
            }
        }
        for s in 0..NSTAGES {
            // R = F(t0 + c_s h, Y0 + Σ a_sj K_j) + Σ (C_sj/h) K_j + h d_s F_t.
            if s == 0 {
                self.ros.r.copy_from(&self.k[0]);
            } else {
                combine(
                    &mut self.tmp,
                    &self.y,
                    1.0,
                    &A[s][..s],
                    &self.k[1..=s],
                    sens,
                );
                self.rhs.eval(t0 + C[s] * h, &self.tmp, &mut self.ros.r);
                for (c, kj) in CC[s][..s].iter().zip(&self.k[1..=s]) {
                    self.ros.r.axpy_parts(c / h, kj, sens);
                }
            }
            if D[s] != 0.0 {
                let RosenbrockWork { r, dt, .. } = &mut self.ros;
                r.axpy_parts(h * D[s], dt, sens);
            }
            let tail = &mut self.k[1 + s..];
            if !solve_stage(&mut self.rhs, &mut self.ros, t0, &self.y, hg, &mut tail[0]) {
                return f64::NAN;
            }
        }
        combine(
            &mut self.ynew,
            &self.y,
            1.0,
            &A[NSTAGES],
            &self.k[1..=NSTAGES],
            sens,
        );
        self.yerr.copy_from(&self.k[NSTAGES]);
        // Dense coefficients D_j = Σ_i H_ji K_i.
        for j in 0..3 {
            let (stages, dense) = self.k.split_at_mut(1 + NSTAGES);
            super::lincomb(&mut dense[j], 1.0, &H[j], &stages[1..], sens);
        }
        self.error_norm()
    }
}

impl<N: Dim, P: Dim> AugState<N, P>
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    /// `self += a · other` on x and q, and on S and q_θ when `sens`.
    fn axpy_parts(&mut self, a: f64, other: &Self, sens: bool) {
        super::axpy_slice(self.x.as_mut_slice(), a, other.x.as_slice());
        self.q += a * other.q;
        if sens {
            super::axpy_slice(self.s.as_mut_slice(), a, other.s.as_slice());
            super::axpy_slice(self.qp.as_mut_slice(), a, other.qp.as_slice());
        }
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
