//! The seam between the steppers and what they integrate.
//!
//! A stepper advances an autonomous-in-form system Ẏ = F(t, Y) over one step of signed length
//! h (h < 0 integrates backwards in time, as an adjoint pass does). It needs only
//!
//! - the vector-space operations of its stage loop on Y ([`StageVector`]): Y₀ + h Σ c_j K_j,
//!   h Σ c_j K_j, Y += a K, the fixed-weight mixes of the dense outputs, finiteness;
//! - F itself and the weighted error norm of the system ([`OdeSystem`]);
//! - for the linearly implicit method, the Jacobian J = ∂F/∂Y, F_t = ∂F/∂t and the stage
//!   solve K = hγ (I − hγ J)⁻¹ R ([`ImplicitSystem`]).
//!
//! A vector has a *primary* part (the state the guards are evaluated on: x for the forward
//! system) and *secondary* parts (sensitivities, quadratures) that a run may leave out: every
//! operation takes `all`, and with `all == false` it touches the primary part and the scalar
//! quadrature only. [`OdeSystem::all_parts`] says what a run integrates, and
//! [`OdeSystem::controls_all`] which parts enter the error norm.
//!
//! The forward augmented system (x, S, q, q_θ) is [`super::Forward`] on [`super::AugState`];
//! an adjoint (λ and its quadratures, integrated from T down to t₀) or a system with a QP in
//! its flow implements the same three traits and reuses every method unchanged.

use super::aug::{accumulate_slices, hermite_slice, mix5_slice};
use nalgebra::{allocator::Allocator, DefaultAllocator, Dim, OVector};

/// The operations a Runge–Kutta or Rosenbrock stage loop performs on the integrated vector.
///
/// Every method works part by part on contiguous slices, without allocating, so stage counts
/// known at compile time let the loops unroll. `ks` are stage derivatives; entries of `coefs`
/// that are exactly 0 are skipped (so rows of a tableau may be shorter than `ks`).
pub trait StageVector {
    /// The primary part (x for the forward system): what dense output for root finding gives.
    type Primary: PrimarySlice;

    /// `self = other`, every part.
    fn copy_from(&mut self, other: &Self);
    /// `self = base + h Σ_j c_j k_j`.
    fn combine(&mut self, base: &Self, h: f64, coefs: &[f64], ks: &[Self], all: bool)
    where
        Self: Sized;
    /// A stage argument `self = base + h Σ_j c_j k_j` over what F reads: the primary part,
    /// and the secondary parts when `reads` ([`OdeSystem::reads_secondary`]). Parts that F
    /// never reads (the forward system's quadratures) may be left as they were; by default
    /// [`StageVector::combine`] with `all = reads`.
    #[inline]
    fn combine_argument(&mut self, base: &Self, h: f64, coefs: &[f64], ks: &[Self], reads: bool)
    where
        Self: Sized,
    {
        self.combine(base, h, coefs, ks, reads);
    }
    /// `self = h Σ_j c_j k_j`.
    fn lincomb(&mut self, h: f64, coefs: &[f64], ks: &[Self], all: bool)
    where
        Self: Sized;
    /// `self += a · other`.
    fn axpy(&mut self, a: f64, other: &Self, all: bool);
    /// `self = Σ_i w_i v_i` over five vectors (the Rosenbrock dense output).
    fn mix5(&mut self, w: &[f64; 5], v: [&Self; 5], all: bool);
    /// The cubic Hermite interpolant of `step` at θ (see [`HermiteStep`]).
    fn hermite(&mut self, step: &HermiteStep<'_, Self>, theta: f64, all: bool);
    /// Whether every entry of every part is finite.
    fn is_finite(&self) -> bool;
    /// The primary part as a slice.
    fn primary(&self) -> &[f64];

    /// Σ_i (a_i − b_i)² over the primary part (Hairer's stiffness estimate).
    #[inline]
    fn primary_dist_sq(&self, other: &Self) -> f64 {
        let mut sum = 0.0;
        for (a, b) in self.primary().iter().zip(other.primary()) {
            let d = a - b;
            sum += d * d;
        }
        sum
    }

    /// `out = primary(self)`.
    #[inline]
    fn primary_into(&self, out: &mut Self::Primary) {
        out.slice_mut().copy_from_slice(self.primary());
    }
    /// `out = primary(base) + h Σ_j c_j primary(k_j)`.
    #[inline]
    fn combine_primary(out: &mut Self::Primary, base: &Self, h: f64, coefs: &[f64], ks: &[Self])
    where
        Self: Sized,
    {
        out.slice_mut().copy_from_slice(base.primary());
        accumulate_slices(out.slice_mut(), h, coefs, ks.iter().map(|k| k.primary()));
    }
    /// `out = h Σ_j c_j primary(k_j)`.
    #[inline]
    fn lincomb_primary(out: &mut Self::Primary, h: f64, coefs: &[f64], ks: &[Self])
    where
        Self: Sized,
    {
        out.slice_mut().fill(0.0);
        accumulate_slices(out.slice_mut(), h, coefs, ks.iter().map(|k| k.primary()));
    }
    /// Primary part of [`StageVector::mix5`].
    #[inline]
    fn mix5_primary(out: &mut Self::Primary, w: &[f64; 5], v: [&Self; 5]) {
        mix5_slice(out.slice_mut(), w, v.map(|u| u.primary()));
    }
    /// Primary part of [`StageVector::hermite`].
    #[inline]
    fn hermite_primary(out: &mut Self::Primary, step: &HermiteStep<'_, Self>, theta: f64) {
        hermite_slice(out.slice_mut(), step.parts(|v| v.primary()), step.h, theta);
    }
}

/// A step of signed length `h` as the cubic Hermite interpolant sees it: the values y₀, y₁
/// and the slopes f₀, f₁ at its ends, y(θ) = y₀ + c (y₁ − y₀) + h (w₀ f₀ + w₁ f₁) with
/// c = 3θ² − 2θ³, w₀ = θ − 2θ² + θ³, w₁ = θ³ − θ² (the dense output of a step whose own
/// interpolant is not formed yet, `dense.rs`).
pub struct HermiteStep<'a, V: ?Sized> {
    /// y₀.
    pub y0: &'a V,
    /// y₁.
    pub y1: &'a V,
    /// f₀ = F(t₀, y₀).
    pub f0: &'a V,
    /// f₁ = F(t₀ + h, y₁).
    pub f1: &'a V,
    /// The step's signed length.
    pub h: f64,
}

impl<'a, V: ?Sized> HermiteStep<'a, V> {
    /// One part of each of y₀, y₁, f₀, f₁, in that order.
    #[inline]
    pub fn parts<'b, T: ?Sized>(&self, part: impl Fn(&'a V) -> &'b T) -> [&'b T; 4] {
        [self.y0, self.y1, self.f0, self.f1].map(part)
    }
}

/// A primary part the stage loops write into: a contiguous slice of f64.
pub trait PrimarySlice {
    /// The entries, mutably.
    fn slice_mut(&mut self) -> &mut [f64];
}

impl<N: Dim> PrimarySlice for OVector<f64, N>
where
    DefaultAllocator: Allocator<N>,
{
    #[inline]
    fn slice_mut(&mut self) -> &mut [f64] {
        self.as_mut_slice()
    }
}

/// Which sum of the step being formed a quadrature term goes to: the step's increment ΔQ,
/// or the estimate of its local error (see [`OdeSystem::controls_quadrature`] and
/// [`OdeSystem::estimates_quadrature_error`]). The system holds both until the step is
/// closed ([`OdeSystem::quadrature_close`]) or another attempt clears them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum QuadratureSum {
    /// ΔQ over the step.
    Step,
    /// The estimate of ΔQ's local error.
    Error,
}

/// The tolerances of a run's local error control: an entry e_i of an error, with magnitude
/// y_i and weight w_i, counts as w_i e_i / (atol + rtol·w_i·|y_i|).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tol {
    /// Absolute tolerance.
    pub atol: f64,
    /// Relative tolerance.
    pub rtol: f64,
}

/// An accepted step as a global error estimate carries it: from (t₀, Y₀) over the signed
/// length h (as it stands after any truncation), with F(t₀, Y₀) = `f0` and the step's local
/// error estimate `le` (see `global_error.rs`).
#[derive(Clone, Copy, Debug)]
pub struct AcceptedStep<'a, V> {
    /// t₀.
    pub t0: f64,
    /// The signed step length h.
    pub h: f64,
    /// Y₀.
    pub y0: &'a V,
    /// F(t₀, Y₀).
    pub f0: &'a V,
    /// The local error estimate.
    pub le: &'a V,
}

/// A system Ẏ = F(t, Y) the explicit methods can integrate, in either time direction.
pub trait OdeSystem {
    /// The integrated vector Y.
    type Vector: StageVector;

    /// A zero vector of the system's shape (allocates for `Dyn` sizes; called only when an
    /// integrator is built).
    fn zeros(&self) -> Self::Vector;
    /// Whether the secondary parts are integrated (the `all` flag of every operation).
    fn all_parts(&self) -> bool;
    /// Whether F reads the secondary parts of its argument (S, for the forward system). When
    /// it does not (the adjoint's gradient quadrature is never read back), the steppers form
    /// only the primary part of a stage argument Y₀ + hΣa_ij k_j; the step's solution, error
    /// estimate and dense output still carry every integrated part.
    fn reads_secondary(&self) -> bool;
    /// Whether the secondary parts enter the error norm (never more than [`Self::all_parts`]).
    fn controls_all(&self) -> bool;
    /// `out = F(t, y)`.
    fn eval(&mut self, t: f64, y: &Self::Vector, out: &mut Self::Vector);
    /// Whether F is the same at every (t, Y) until the next restart (then Y(t + h) =
    /// Y + h·F exactly, and the integrator takes [`crate::integrate::Scheme::Exact`] steps).
    /// The default, `false`, is always safe.
    fn constant_rate(&self) -> bool {
        false
    }
    /// Evaluations of F so far (including those for difference quotients).
    fn evals(&self) -> usize;
    /// Whether the system keeps a quadrature Q̇ = G(t, Y) outside the integrated vector (F
    /// never reads Q, so Q needs no stage of its own: the integrator forms each step's share
    /// ΔQ with the scheme's weights on the step's stage values, `quadrature.rs`). The
    /// default, `false`, has none, and no quadrature method is called.
    fn has_quadrature(&self) -> bool {
        false
    }
    /// Whether Q's local error enters the step acceptance (as CVODES' `errconQB`): then every
    /// attempt forms ΔQ and its error estimate, and the attempt's norm is
    /// max(‖e_Y‖, [`OdeSystem::quadrature_error_norm`]). Otherwise ΔQ is formed once, when
    /// the accepted step is closed. The default, `false`, leaves Q out.
    fn controls_quadrature(&self) -> bool {
        false
    }
    /// Whether the system wants Q's local error estimate of each accepted step (for a
    /// global error estimate; handed over by [`OdeSystem::quadrature_close`]). The default,
    /// `false`, does not.
    fn estimates_quadrature_error(&self) -> bool {
        false
    }
    /// Sets `sum` to 0 (before a step's terms are added to it).
    fn quadrature_clear(&mut self, _sum: QuadratureSum) {}
    /// Evaluates G(t, y) once (a stage value of the step being formed) and adds `a`·G to
    /// [`QuadratureSum::Step`] and `e`·G to [`QuadratureSum::Error`] (h·bᵢ and h·(bᵢ − b̂ᵢ);
    /// a zero weight adds nothing).
    fn quadrature_add(&mut self, _t: f64, _y: &Self::Vector, _a: f64, _e: f64) {}
    /// The weighted RMS norm of [`QuadratureSum::Error`] against Q at both ends of the step,
    /// Q and Q + ΔQ (for [`OdeSystem::controls_quadrature`]).
    fn quadrature_error_norm(&self, _tol: Tol) -> f64 {
        0.0
    }
    /// Closes the step: Q += ΔQ, and with `error` the error estimate goes to the system's
    /// global error estimate.
    fn quadrature_close(&mut self, _error: bool) {}
    /// The weighted RMS norm of the local error `e` of a step from `y0` to `y1`,
    /// sqrt(1/N Σ_i (w_i e_i / (atol + rtol·w_i·max(|y0_i|, |y1_i|)))²) over the controlled
    /// entries with the system's weights w_i. Also the norm of Hairer's initial-step heuristic
    /// (with y0 = y1).
    fn error_norm(&self, e: &Self::Vector, y0: &Self::Vector, y1: &Self::Vector, tol: Tol) -> f64;
    /// Names the first integrated part of `y` holding a NaN or infinity.
    fn nonfinite_part(&self, y: &Self::Vector) -> Option<&'static str>;
    /// Names the flow being integrated (for errors: "flow of mode `m`").
    fn flow_name(&self) -> String;
    /// Names the expression that produced the non-finite stage derivative `k` (for errors).
    fn stage_source(&self, k: &Self::Vector) -> String;
}

/// What the linearly implicit (Rosenbrock) method needs beyond [`OdeSystem`]: one Jacobian
/// J = ∂F/∂Y and F_t = ∂F/∂t per step start, one factorisation of I − hγ J per attempt, and
/// the stage solves. The system owns J, its factors and its scratch; the stepper only asks.
pub trait ImplicitSystem: OdeSystem {
    /// J, F_t and the factors of W at the step start, as the stepper reads them.
    type Linear: Linearised<Self::Vector>;
    /// Evaluates J and F_t at the step start (t₀, Y₀) for steps of size about h (h may set the
    /// difference steps in t); afterwards [`Linearised::prepared`] holds until
    /// [`Linearised::invalidate`].
    fn prepare(&mut self, t0: f64, y0: &Self::Vector, h: f64);
    /// The linearisation at the step start, which the system owns: the stepper reads it,
    /// factorises W in it or forgets it.
    fn linearisation(&mut self) -> &mut Self::Linear;
    /// Solves the stage equation (I/(hγ) − J) K = R at the step start (t₀, Y₀) in place:
    /// `rk` holds R and becomes K = hγ (I − hγ J)⁻¹ R; false when the factors are missing or
    /// a solve failed.
    fn solve_stage(&mut self, t0: f64, y0: &Self::Vector, hg: f64, rk: &mut Self::Vector) -> bool;
    /// Carries the system's global error estimate, if it keeps one, over the accepted `step`.
    /// Does nothing by default.
    fn carry_global_error(&mut self, _step: AcceptedStep<'_, Self::Vector>) {}
    /// `sum` += a·(∂G/∂Y)·v at the step start t0 (the quadrature's block of J, for the
    /// Rosenbrock update of Q or its error; see `quadrature.rs`).
    fn quadrature_jac_add(&mut self, _t0: f64, _v: &Self::Vector, _a: f64, _sum: QuadratureSum) {}
    /// `sum` += a·∂G/∂t at the step start (t0, y0) (the quadrature's part of F_t).
    fn quadrature_dt_add(&mut self, _t0: f64, _y0: &Self::Vector, _a: f64, _sum: QuadratureSum) {}
    /// Evaluates the Jacobian of the primary flow at (t, y) and returns an estimate of its
    /// spectral radius (for the stiffness test of the explicit method).
    fn spectral_radius_at(&mut self, t: f64, y: &Self::Vector) -> f64;
}

/// What the stepper reads of an implicit system's linearisation at the step start (J inside
/// W, F_t, the factors of W = I − hγ J), the same for every system: `rosenbrock::Linearisation` is
/// its one implementation, and [`ImplicitSystem::linearisation`] hands it over.
pub trait Linearised<V> {
    /// J and F_t belong to the current step start (set by [`ImplicitSystem::prepare`]).
    fn prepared(&self) -> bool;
    /// F_t at the step start (valid after [`ImplicitSystem::prepare`]).
    fn time_derivative(&self) -> &V;
    /// Factorises W = I − hγ J for `hg` = hγ (any sign); false when W is singular.
    fn factorise(&mut self, hg: f64) -> bool;
    /// hγ of the current regular factorisation, if any.
    fn factorised_for(&self) -> Option<f64>;
    /// Forgets J, F_t and the factors (new step start, restart, truncation).
    fn invalidate(&mut self);
    /// The spectral-radius estimate of the last Jacobian evaluated.
    fn spectral_radius(&self) -> f64;
}
