//! The run's global error estimate: the accepted steps' local error estimates, carried to T by
//! the linearised flow.
//!
//! Local error control bounds the error each step makes, not the error at T. Where the
//! variational flow amplifies perturbations (an unstable flow, the passage of a fold), or where
//! the steps commit their errors at a scale much larger than the solution's at T (S ≈ f·t' is
//! 10⁶ times its final size while Van der Pol jumps, and only part of the error made there is
//! damped on landing), the error at T can exceed the tolerance by orders of magnitude. This
//! estimate integrates, alongside the run, the linearised error equation
//!
//! ```text
//!   ė_x = f_x e_x + δ_x,   ė_S = f_x e_S + δ_S,   ė_q = ℓ_x e_x + δ_q,   ė_qθ = e_Sᵀ ℓ_x + δ_qθ
//! ```
//!
//! with δ the local error estimates of the steps (per unit time). Per accepted step [t₀, t₀ + h]
//! with local error estimate le: r ← r + le, then up to 8 explicit Euler substeps of h/m with
//! |h/m|‖f_x‖∞ ≤ 1/2 (stable and first-order accurate there, at the cost of products over
//! f_x's structural non-zeros, like the capability products; the quadratures by the
//! trapezoidal rule), or, for a stiff step, one linearly implicit Euler step (L-stable: it damps
//! stiff modes as the flow does, at one factorisation of W = I − h f_x(t₀, x₀), as a Rosenbrock
//! step does):
//!
//! ```text
//!   r_x ← M r_x,   r_S ← M r_S,   r_q ← r_q + h ℓ_x·r_x,   r_qθ ← r_qθ + h r_Sᵀ ℓ_x
//! ```
//!
//! with M = I + (h/m) f_x per substep, or W⁻¹. f_x and ℓ_x are taken at (t₀, x₀).
//!
//! The direction of the flow is carried exactly: for an autonomous flow the variational flow
//! maps f(t₀) to f(t₁), so a time shift α (e_x = α f, e_q = α ℓ) and an error β_j of t'
//! (e_S = f βᵀ, e_qθ = β ℓ) are transported without any discretisation error. Before each
//! implicit step the component of r_x, and of each column of r_S, along f(t₀) (in the norm of
//! the error weights 1/(atol + rtol |x₀ᵢ|)) moves into α, β. Without it the implicit steps lose
//! the cancellation by which a time shift made at the peak of a fast jump (|f| ~ 10⁶) shrinks
//! back with |f| on landing, and overestimate e_x there by 10⁵ (Van der Pol, μ = 10⁶); and
//! they compound (1 − h a)⁻¹ > e^{h a} over long steps of a growing solution (x' = a x), which
//! would raise a false alarm.
//!
//! At an event the estimate jumps by the linearisation of the run's own jump: with the
//! saltation matrix Σ = R_x − w ∇gᵀ/ġ, w = R_x f⁻ + R_t − f⁺, ġ = ∇g·f⁻ + ∂g/∂t (the map S⁻ ↦ S⁺
//! of `sens::jump` is affine in S⁻ with linear part Σ),
//!
//! ```text
//!   δt = −∇g·e_x⁻/ġ,   δt' = −e_S⁻ᵀ∇g/ġ,   e_x⁺ = Σ e_x⁻,   e_S⁺ = Σ e_S⁻,
//!   e_q⁺ = e_q⁻ + (ℓ⁻ − ℓ⁺) δt,   e_qθ⁺ = e_qθ⁻ + (ℓ⁻ − ℓ⁺) δt',
//! ```
//!
//! and an event cost φ(t, x⁺) contributes φ_x·(e_x⁺ + f⁺ δt) + φ_t δt to the error of C and
//! (e_S⁺ + f⁺ δt'ᵀ)ᵀ φ_x + φ_t δt' to that of dC/dθ. At T, e_C = e_q + Σ δφ + Φ_x·e_x and
//! e_{dC/dθ} = e_qθ + Σ δ(dφ/dθ) + e_Sᵀ Φ_x.
//!
//! ## Rounding
//! The estimate also carries the run's rounding, added where it is made and transported by
//! the same mechanism as the steps' errors (see `rounding.rs`, `GlobalError::event_rounding`
//! for the terms and the cases they bound).
//!
//! What the estimate leaves out: the second-order coupling of state errors into the
//! sensitivities (∂(f_x S)/∂x · e_x along the flow, the derivative of the jump map in x⁻)
//! beyond the time shift at T, so e_S is driven by the sensitivities' own local errors and
//! rounding; and the error of locating events beyond rounding. The
//! embedded pairs' estimates bound the error of their lower-order solution, so the estimate is
//! usually larger than the true error where the steps' errors dominate (1 to 100× on the
//! suite); the rounding terms are bounds taken with one sign, 2 to 30× the errors measured
//! on the cases above; it is a criterion, not a correction. With sensitivity error control
//! off, no local error of S is estimated, and only C is judged.

use super::aug::AugState;
use super::rosenbrock::WMatrix;
use crate::model::ModelAlloc;
use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector};

/// The largest |γ|‖f_x‖∞ at which a component γ f of the state's error along the flow is read
/// as a time shift γ: after a long step ([`GlobalError::carry`]) and at T
/// ([`GlobalError::at_end`]).
const PHASE_LINEAR: f64 = 1e-3;

mod rounding;
pub use rounding::{EventRounding, JumpOf, PhaseRates};

/// Explicit Euler substeps a step may take before the estimate is carried by one implicit
/// step instead (|h|‖f_x‖∞ > 4: a stiff step).
pub const EXPLICIT_SUBSTEPS: f64 = 8.0;

/// Calls `f(i, j)` for every structurally non-zero entry (i, j) of an n × n Jacobian listed
/// in `pattern`, or for every entry when `pattern` is empty (a model that does not give it).
#[inline]
fn for_each_entry(n: usize, pattern: &[(usize, usize)], mut f: impl FnMut(usize, usize)) {
    if pattern.is_empty() {
        for j in 0..n {
            for i in 0..n {
                f(i, j);
            }
        }
    } else {
        for &(i, j) in pattern {
            f(i, j);
        }
    }
}

/// m = ⌈2|h|‖J‖∞⌉ (at least 1): the explicit Euler substeps that carry a step of length h
/// stably (|h/m|‖J‖∞ ≤ 1/2). ‖J‖∞ from the row sums of |J_ij| over the structural non-zeros
/// `pattern` of f_x (every entry when it is empty); with `transposed` the matrix holds −f_xᵀ
/// (the adjoint's J), whose non-zeros are the pattern's (j, i). `sums` is n-long scratch.
pub(super) fn substeps<N: Dim>(
    jac: &OMatrix<f64, N, N>,
    pattern: &[(usize, usize)],
    transposed: bool,
    h: f64,
    sums: &mut OVector<f64, N>,
) -> f64
where
    DefaultAllocator: nalgebra::allocator::Allocator<N, N> + nalgebra::allocator::Allocator<N>,
{
    let (n, entries) = (jac.nrows(), jac.as_slice());
    sums.fill(0.0);
    for_each_entry(n, pattern, |i, j| {
        let (i, j) = if transposed { (j, i) } else { (i, j) };
        sums[i] += entries[i + j * n].abs();
    });
    (2.0 * h.abs() * sums.amax()).ceil().max(1.0)
}

/// out += J v over the entries (i, j) of `pattern`, or with `transposed` over their mirror
/// images (j, i) (J = −f_xᵀ stored, `pattern` f_x's).
#[inline]
pub(super) fn sparse_product<N: Dim>(
    jac: &OMatrix<f64, N, N>,
    pattern: &[(usize, usize)],
    transposed: bool,
    v: &[f64],
    out: &mut [f64],
) where
    DefaultAllocator: nalgebra::allocator::Allocator<N, N>,
{
    let n = jac.nrows();
    let j_entries = jac.as_slice();
    for &(i, j) in pattern {
        let (i, j) = if transposed { (j, i) } else { (i, j) };
        out[i] += j_entries[i + j * n] * v[j];
    }
}

/// The global error estimate of a forward run (see the module doc): e_x = α f + r_x,
/// e_q = α ℓ + r_q, e_S = f βᵀ + r_S, e_qθ = β ℓ + r_qθ; plus the errors of the event costs
/// so far.
/// Every buffer is allocated when it is built; carrying it allocates nothing.
#[derive(Clone, Debug)]
pub struct GlobalError<N: Dim, P: Dim>
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    /// The remainder r (x, S, q, q_θ).
    r: AugState<N, P>,
    /// The time shift α carried along f.
    alpha: f64,
    /// The error β_j of t' carried along f in column j of S.
    beta: OVector<f64, P>,
    /// The error of Σφ_k so far.
    events_cost: f64,
    /// The error of Σ dφ_k/dθ so far.
    events_grad: OVector<f64, P>,
    /// Nothing has been carried yet: every part is exactly zero, and so is its image under
    /// any jump (a run whose steps are all exact, which make no error, never leaves it but
    /// through its events' rounding, see `pending`).
    zero: bool,
    /// While the estimate is zero, the events' rounding so far, not transported (see
    /// [`GlobalError::event_rounding`]): it starts the estimate when the first step is
    /// carried or when it reaches the tolerance, and is added at T otherwise.
    pending: AugState<N, P>,
    /// The largest ‖x⁺‖∞ and ‖S⁺‖∞ at the events that added to `pending`: the scale of its
    /// tolerance.
    pending_scale: (f64, f64),
    /// The last jump's displacement: the recorded jump (t̃, x̃⁻, x̃⁺) is the exact one moved
    /// by (δt, d⁻, d⁺), d⁻ = e_x⁻ + f⁻ δt, d⁺ = e_x⁺ + f⁺ δt (see [`GlobalError::jump_shift`]).
    d_minus: OVector<f64, N>,
    d_plus: OVector<f64, N>,
    shift_dt: f64,
    /// Row sums Σ_j |∂f_i/∂x_j| of the last carried step's f_x (zeros before the first): with
    /// ‖x‖∞ the scale of the rounding of evaluating f at an event ([`EventRounding`]).
    jac_rows: OVector<f64, N>,
    /// Scratch: two n-vectors, n×p and p.
    xs: OVector<f64, N>,
    w: OVector<f64, N>,
    ss: OMatrix<f64, N, P>,
    dts: OVector<f64, P>,
}

/// What an event's linearised jump needs (see the module doc); `rx`/`rt` `None` is the
/// identity reset of a switch crossing.
pub struct Saltation<'a, N: Dim>
where
    DefaultAllocator: nalgebra::allocator::Allocator<N> + nalgebra::allocator::Allocator<N, N>,
{
    /// R_x, or `None` for the identity.
    pub rx: Option<&'a OMatrix<f64, N, N>>,
    /// R_t, or `None` for zero.
    pub rt: Option<&'a OVector<f64, N>>,
    /// f⁻ (the old mode's flow at x⁻).
    pub f_minus: &'a OVector<f64, N>,
    /// f⁺ (the new mode's flow at x⁺).
    pub f_plus: &'a OVector<f64, N>,
    /// ∇g at x⁻.
    pub gx: &'a OVector<f64, N>,
    /// ġ = ∇g·f⁻ + ∂g/∂t.
    pub rate: f64,
    /// ℓ⁻ and ℓ⁺ (zeros without a running cost).
    pub l_minus: f64,
    /// See `l_minus`.
    pub l_plus: f64,
    /// The event cost's (φ_x, φ_t) at (t, x⁺), if the event has a cost.
    pub cost: Option<(&'a OVector<f64, N>, f64)>,
    /// Without sensitivities, the reset's displacement by a secant instead of `rx`/`rt`:
    /// `secant(d⁻, δt, scratch, out)` writes R(t + δt, x⁻ + d⁻) − x⁺ into `out` (see
    /// [`GlobalError::jump`]); `None` uses the matrices.
    pub secant: Option<&'a ResetSecant<'a, N>>,
}

/// The secant of an event's reset along a displacement (d⁻, δt) of its point:
/// `(d⁻, δt, scratch, out)` ↦ out = R(t + δt, x⁻ + d⁻) − x⁺ (x⁺ = R(t, x⁻)), scratch an
/// n-vector it may overwrite.
pub type ResetSecant<'a, N> =
    dyn Fn(&OVector<f64, N>, f64, &mut OVector<f64, N>, &mut OVector<f64, N>) + 'a;

impl<N: Dim, P: Dim> GlobalError<N, P>
where
    DefaultAllocator: ModelAlloc<N, P>,
{
    /// A zero estimate for n states and p parameters.
    pub fn new(n: N, p: P) -> Self {
        GlobalError {
            r: AugState::zeros(n, p),
            pending: AugState::zeros(n, p),
            pending_scale: (0.0, 0.0),
            alpha: 0.0,
            beta: OVector::zeros_generic(p, Const::<1>),
            events_cost: 0.0,
            events_grad: OVector::zeros_generic(p, Const::<1>),
            zero: true,
            d_minus: OVector::zeros_generic(n, Const::<1>),
            d_plus: OVector::zeros_generic(n, Const::<1>),
            shift_dt: 0.0,
            jac_rows: OVector::zeros_generic(n, Const::<1>),
            xs: OVector::zeros_generic(n, Const::<1>),
            w: OVector::zeros_generic(n, Const::<1>),
            ss: OMatrix::zeros_generic(n, p),
            dts: OVector::zeros_generic(p, Const::<1>),
        }
    }

    /// Whether the estimate is exactly zero because nothing has been carried yet (the steps so
    /// far were exact): its jump at an event is then zero too, and needs no inputs; only the
    /// event's rounding is added, to the pending part ([`GlobalError::event_rounding`]).
    pub fn is_zero(&self) -> bool {
        self.zero
    }

    /// Carries the estimate over the accepted step from (t₀, Y₀) of signed length h with local
    /// error estimate `le`, F(t₀, Y₀) = `f0`, J = f_x(t₀, x₀) in `w.jac` (structurally
    /// non-zero at `pattern`, every entry when it is empty) and ℓ_x(t₀) in `lx`; with `sens`
    /// the sensitivity parts too (their local errors are then estimated).
    ///
    /// r += le; then, with m = ⌈2|h|‖J‖∞⌉: where m ≤ [`EXPLICIT_SUBSTEPS`], m explicit Euler
    /// substeps of h/m, each r_x, r_S ← (I + (h/m)J) r_x, r_S (stable and first-order accurate
    /// at |h/m|‖J‖∞ ≤ 1/2, at the cost of products over J's non-zeros) with r_q, r_qθ by the
    /// trapezoidal rule over each substep; elsewhere (a stiff step) linearly implicit Euler,
    /// r_x, r_S ← (I − hJ)⁻¹ r_x, r_S (L-stable; one factorisation; a singular I − hJ leaves
    /// them as they are) with r_q += h ℓ_x·r_x, r_qθ += h r_Sᵀ ℓ_x. Before an implicit step of a
    /// flow that does not depend on t (`autonomous`), the components of r_x and of r_S's
    /// columns along f₀ move into α and β, which the step carries exactly: an implicit step of
    /// a stiff transient is where a first-order transport of the flow direction goes wrong.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn carry(
        &mut self,
        le: &AugState<N, P>,
        f0: &AugState<N, P>,
        y0: &AugState<N, P>,
        (atol, rtol): (f64, f64),
        w: &mut WMatrix<N>,
        pattern: &[(usize, usize)],
        lx: &OVector<f64, N>,
        h: f64,
        sens: bool,
        autonomous: bool,
    ) {
        if self.zero {
            self.start_from_pending();
        }
        let r = &mut self.r;
        r.x += &le.x;
        r.q += le.q;
        if sens {
            r.s += &le.s;
            r.qp += &le.qp;
        }
        self.step_rounding(y0, f0, h);
        let m = substeps(&w.jac, pattern, false, h, &mut self.w);
        self.jac_rows.copy_from(&self.w);
        if m <= EXPLICIT_SUBSTEPS {
            let dt = h / m;
            // The quadratures by the trapezoidal rule (r_x is linear across a substep).
            for _ in 0..m as usize {
                self.quadrature(lx, 0.5 * dt, sens);
                self.explicit_euler(&w.jac, pattern, dt, sens);
                self.quadrature(lx, 0.5 * dt, sens);
            }
            return;
        }
        if autonomous {
            self.move_along_flow(f0, y0, (atol, rtol), sens);
        }
        let r = &mut self.r;
        if w.factorise(h) {
            w.solve_mut(&mut r.x);
            if sens {
                w.solve_mut(&mut r.s);
            }
        }
        // The factors are for h, not a Rosenbrock step's hγ.
        w.invalidate();
        self.quadrature(lx, h, sens);
    }

    /// r_x += dt J r_x and r_S += dt J r_S, over J's non-zeros (`pattern`; every entry, by
    /// nalgebra's products, when it is empty).
    fn explicit_euler(
        &mut self,
        jac: &OMatrix<f64, N, N>,
        pattern: &[(usize, usize)],
        dt: f64,
        sens: bool,
    ) {
        if pattern.is_empty() {
            self.xs.gemv(1.0, jac, &self.r.x, 0.0);
            if sens {
                self.ss.gemm(1.0, jac, &self.r.s, 0.0);
            }
        } else {
            let n = self.r.x.len();
            self.xs.fill(0.0);
            sparse_product(
                jac,
                pattern,
                false,
                self.r.x.as_slice(),
                self.xs.as_mut_slice(),
            );
            if sens {
                self.ss.fill(0.0);
                let src = self.r.s.as_slice().chunks_exact(n);
                let dst = self.ss.as_mut_slice().chunks_exact_mut(n);
                for (v, out) in src.zip(dst) {
                    sparse_product(jac, pattern, false, v, out);
                }
            }
        }
        self.r.x.axpy(dt, &self.xs, 1.0);
        if sens {
            super::aug::axpy_slice(self.r.s.as_mut_slice(), dt, self.ss.as_slice());
        }
    }

    /// r_q += dt ℓ_x·r_x and r_qθ += dt r_Sᵀ ℓ_x.
    fn quadrature(&mut self, lx: &OVector<f64, N>, dt: f64, sens: bool) {
        self.r.q += dt * lx.dot(&self.r.x);
        if sens {
            self.r.qp.gemv_tr(dt, &self.r.s, lx, 1.0);
        }
    }

    /// Moves the components of r_x and of each column of r_S along f₀ = F(t₀, Y₀).x into α
    /// and β (weights 1/(atol + rtol|x₀ᵢ|)), with their shares of r_q and r_qθ (γ ℓ₀).
    fn move_along_flow(
        &mut self,
        f0: &AugState<N, P>,
        y0: &AugState<N, P>,
        (atol, rtol): (f64, f64),
        sens: bool,
    ) {
        let n = self.r.x.len();
        let (fx, x0) = (f0.x.as_slice(), y0.x.as_slice());
        // xs = weights² ⊙ f₀, ff = f₀ᵀ xs.
        let mut ff = 0.0;
        for (i, wi) in self.xs.as_mut_slice().iter_mut().enumerate() {
            let w = 1.0 / (atol + rtol * x0[i].abs());
            *wi = w * w * fx[i];
            ff += *wi * fx[i];
        }
        if !(ff > 0.0 && ff.is_finite()) {
            return;
        }
        let inv_ff = 1.0 / ff;
        let gamma = self.xs.dot(&self.r.x) * inv_ff;
        // A shift is a first-order reading of the error only while |α|‖f_x‖∞ is small: near
        // an equilibrium (f ≈ 0; a decay's tail, where an error of atol is 10⁸ times x) the
        // component along f is no shift, and its shift materialised under a later f (after a
        // kick) was an error 10¹⁷ times the tolerance on an exact answer (probe3 b2). The
        // error then stays in r_x, transported by the linearised flow.
        if !(gamma.is_finite() && (self.alpha + gamma).abs() * self.jac_rows.amax() <= PHASE_LINEAR)
        {
            return;
        }
        self.alpha += gamma;
        self.r.x.axpy(-gamma, &f0.x, 1.0);
        self.r.q -= gamma * f0.q;
        if !sens {
            return;
        }
        let w = self.xs.as_slice();
        let cols = self.r.s.as_mut_slice().chunks_exact_mut(n);
        for ((col, q), b) in cols
            .zip(self.r.qp.as_mut_slice())
            .zip(self.beta.as_mut_slice())
        {
            let g = col.iter().zip(w).map(|(c, wi)| c * wi).sum::<f64>() * inv_ff;
            *b += g;
            for (c, f) in col.iter_mut().zip(fx) {
                *c -= g * f;
            }
            *q -= g * f0.q;
        }
    }

    /// Turns the time shifts into the errors they are at a point with flow f and running cost
    /// ℓ: r_x += α f, r_q += α ℓ, r_S += f βᵀ, r_qθ += β ℓ; α, β = 0.
    fn materialise(&mut self, f: &OVector<f64, N>, l: f64, sens: bool) {
        self.r.x.axpy(self.alpha, f, 1.0);
        self.r.q += self.alpha * l;
        self.alpha = 0.0;
        if sens {
            self.r.s.ger(1.0, f, &self.beta, 1.0);
            self.r.qp.axpy(l, &self.beta, 1.0);
        }
        self.beta.fill(0.0);
    }

    /// At the limit of an accumulation, which the driver snaps onto the accumulating guard
    /// (x* ← x* − ∇g g/|∇g|², S* onto the guard's tangent): the time shifts become the errors
    /// they are at the limit, under the flow f the hold follows there (its held rows zero) and
    /// running cost ℓ, and the errors of x and of S's columns lose their components along ∇g,
    /// which the snap makes exact (the resting ball's h* = 0: a held h with an estimated error
    /// would otherwise grow the estimate of ∫h by that error times T − t*).
    pub fn onto_guard(&mut self, f: &OVector<f64, N>, l: f64, gx: &OVector<f64, N>, sens: bool) {
        if self.zero {
            return;
        }
        self.materialise(f, l, sens);
        let n2 = gx.norm_squared();
        if !(n2 > 0.0 && n2.is_finite()) {
            return;
        }
        let along = gx.dot(&self.r.x) / n2;
        self.r.x.axpy(-along, gx, 1.0);
        if sens {
            self.dts.gemv_tr(1.0 / n2, &self.r.s, gx, 0.0);
            self.r.s.ger(-1.0, gx, &self.dts, 1.0);
        }
    }

    /// The linearised jump at an event (see the module doc); the time shifts are turned into
    /// the errors they are at t⁻ first (the linearised jump maps them exactly).
    pub fn jump(&mut self, s: &Saltation<'_, N>, sens: bool) {
        if self.zero {
            // The jump is linear in the estimate: zero stays zero.
            return;
        }
        self.materialise(s.f_minus, s.l_minus, sens);
        if let (false, Some(secant)) = (sens, s.secant) {
            self.jump_by_secant(s, secant);
            return;
        }
        // w = R_x f⁻ + R_t − f⁺.
        match s.rx {
            Some(rx) => self.w.gemv(1.0, rx, s.f_minus, 0.0),
            None => self.w.copy_from(s.f_minus),
        }
        if let Some(rt) = s.rt {
            self.w += rt;
        }
        self.w -= s.f_plus;
        let inv_rate = if s.rate != 0.0 && s.rate.is_finite() {
            -1.0 / s.rate
        } else {
            0.0
        };
        let dl = s.l_minus - s.l_plus;
        // x: δt = −∇g·e_x/ġ, e_x⁺ = R_x e_x + w δt.
        let dt = inv_rate * s.gx.dot(&self.r.x);
        self.d_minus.copy_from(&self.r.x);
        self.d_minus.axpy(dt, s.f_minus, 1.0);
        match s.rx {
            Some(rx) => self.xs.gemv(1.0, rx, &self.r.x, 0.0),
            None => self.xs.copy_from(&self.r.x),
        }
        self.xs.axpy(dt, &self.w, 1.0);
        self.r.x.copy_from(&self.xs);
        self.d_plus.copy_from(&self.r.x);
        self.d_plus.axpy(dt, s.f_plus, 1.0);
        self.shift_dt = dt;
        self.r.q += dl * dt;
        if let Some((phi_x, phi_t)) = s.cost {
            self.events_cost += phi_x.dot(&self.r.x) + (phi_x.dot(s.f_plus) + phi_t) * dt;
        }
        if !sens {
            return;
        }
        // S: δt' = −e_Sᵀ∇g/ġ, e_S⁺ = R_x e_S + w δt'ᵀ.
        self.dts.gemv_tr(inv_rate, &self.r.s, s.gx, 0.0);
        match s.rx {
            Some(rx) => self.ss.gemm(1.0, rx, &self.r.s, 0.0),
            None => self.ss.copy_from(&self.r.s),
        }
        self.ss.ger(1.0, &self.w, &self.dts, 1.0);
        self.r.s.copy_from(&self.ss);
        self.r.qp.axpy(dl, &self.dts, 1.0);
        if let Some((phi_x, phi_t)) = s.cost {
            self.events_grad.gemv_tr(1.0, &self.r.s, phi_x, 1.0);
            self.events_grad
                .axpy(phi_x.dot(s.f_plus) + phi_t, &self.dts, 1.0);
        }
    }

    /// The jump of the state's estimate without sensitivities, where only the reset's
    /// directional derivative along the displacement is needed: with δt = −∇g·e_x⁻/ġ and
    /// d⁻ = e_x⁻ + f⁻ δt, the linearised jump is d⁺ = R_x d⁻ + R_t δt and e_x⁺ = d⁺ − f⁺ δt
    /// (the same as R_x e_x⁻ + w δt). d⁺ is taken as the secant R(t + δt, x⁻ + d⁻) − x⁺, one
    /// evaluation of the reset instead of its Jacobians (whose ∂R/∂θ is p long), exact to
    /// first order in the displacement, to rounding ε|x⁺| below it.
    fn jump_by_secant(&mut self, s: &Saltation<'_, N>, secant: &ResetSecant<'_, N>) {
        let inv_rate = if s.rate != 0.0 && s.rate.is_finite() {
            -1.0 / s.rate
        } else {
            0.0
        };
        let dt = inv_rate * s.gx.dot(&self.r.x);
        self.d_minus.copy_from(&self.r.x);
        self.d_minus.axpy(dt, s.f_minus, 1.0);
        secant(&self.d_minus, dt, &mut self.xs, &mut self.d_plus);
        self.r.x.copy_from(&self.d_plus);
        self.r.x.axpy(-dt, s.f_plus, 1.0);
        self.shift_dt = dt;
        self.r.q += (s.l_minus - s.l_plus) * dt;
        if let Some((phi_x, phi_t)) = s.cost {
            self.events_cost += phi_x.dot(&self.r.x) + (phi_x.dot(s.f_plus) + phi_t) * dt;
        }
    }

    /// The estimated error of x now: (r_x, α), e_x = r_x + α f(t, x).
    pub fn state_error(&self) -> (&OVector<f64, N>, f64) {
        (&self.r.x, self.alpha)
    }

    /// The last jump's displacement (d⁻, d⁺, δt): the jump the run applied, at t̃ = t + δt
    /// from x̃⁻ = x⁻ + d⁻ to x̃⁺ = x⁺ + d⁺, is the exact one (t, x⁻, x⁺) moved by the state
    /// error e_x⁻ it arrived with: δt = −∇g·e_x⁻/ġ, d⁻ = e_x⁻ + f⁻ δt and d⁺ = e_x⁺ + f⁺ δt =
    /// R_x d⁻ + R_t δt (the adjoint sweep's transposes are evaluated there).
    pub fn jump_shift(&self) -> (&OVector<f64, N>, &OVector<f64, N>, f64) {
        (&self.d_minus, &self.d_plus, self.shift_dt)
    }

    /// The estimated errors at T, given f(T), ℓ(T) and, with a final cost, Φ_x(T): returns the
    /// error of C and writes that of dC/dθ into `grad` (with `sens`). With `phase` =
    /// (x(T), (atol, rtol), Ṡ(T), q̇_θ(T) − q_θ(T)/T), the component γ of e_x along f(T)
    /// (weights 1/(atol + rtol|xᵢ|), as `GlobalError::carry` moves it into α), when
    /// |γ|‖f_x‖∞ ≤ 10⁻³, is read as the time shift it is to first order: the
    /// sensitivities computed along x(t + γ) are S(t + γ), so e_S += γṠ(T) and
    /// e_qθ += γ(q̇_θ(T) − q̄_θ) (see the module doc).
    #[allow(clippy::too_many_arguments)]
    pub fn at_end(
        &mut self,
        f: &OVector<f64, N>,
        l: f64,
        phi_x: Option<&OVector<f64, N>>,
        sens: bool,
        phase: Option<PhaseRates<'_, N, P>>,
        grad: &mut OVector<f64, P>,
    ) -> f64 {
        if self.zero {
            self.start_from_pending();
        }
        self.materialise(f, l, sens);
        if let (true, Some(phase)) = (sens, phase) {
            self.phase_at_end(f, phase);
        }
        let mut cost = self.r.q + self.events_cost;
        if let Some(phi_x) = phi_x {
            cost += phi_x.dot(&self.r.x);
        }
        if sens {
            grad.copy_from(&self.r.qp);
            *grad += &self.events_grad;
            if let Some(phi_x) = phi_x {
                grad.gemv_tr(1.0, &self.r.s, phi_x, 1.0);
            }
        }
        cost
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use nalgebra::{Matrix2, Vector2};

    /// An event's jump without running or event costs: R_x, R_t (`None`: zero), f±, ∇g and
    /// the rate ∇g·f⁻, and optionally the reset's secant.
    fn impact<'a>(
        (rx, rt): (&'a Matrix2<f64>, Option<&'a Vector2<f64>>),
        (f_minus, f_plus): (&'a Vector2<f64>, &'a Vector2<f64>),
        gx: &'a Vector2<f64>,
        secant: Option<&'a ResetSecant<'a, Const<2>>>,
    ) -> Saltation<'a, Const<2>> {
        Saltation {
            rx: Some(rx),
            rt,
            f_minus,
            f_plus,
            gx,
            rate: gx.dot(f_minus),
            l_minus: 0.0,
            l_plus: 0.0,
            cost: None,
            secant,
        }
    }

    /// A time shift passes an event exactly: with the ball's impact (R = (h, −e v), g = h),
    /// e_x⁻ = α f⁻ becomes α f⁺ + (the shift's own effect on nothing else), i.e. Σ f⁻ = f⁺.
    #[test]
    fn the_saltation_matrix_maps_a_time_shift_to_a_time_shift() {
        let (e, g, v) = (0.8, 9.81, -3.0);
        let mut ge = GlobalError::new(Const::<2>, Const::<1>);
        ge.alpha = 1e-3;
        ge.zero = false;
        let f_minus = Vector2::new(v, -g);
        let f_plus = Vector2::new(-e * v, -g);
        let rx = Matrix2::new(1.0, 0.0, 0.0, -e);
        let gx = Vector2::new(1.0, 0.0);
        let s = impact((&rx, None), (&f_minus, &f_plus), &gx, None);
        ge.jump(&s, false);
        assert_relative_eq!(ge.r.x[0], 1e-3 * f_plus[0], max_relative = 1e-14);
        assert_relative_eq!(ge.r.x[1], 1e-3 * f_plus[1], max_relative = 1e-14);
    }

    /// Without sensitivities the jump by the reset's secant agrees with the Jacobian path to
    /// first order in the displacement: a nonlinear, time-dependent reset R(t, h, v) =
    /// (h, −e v − c v³ + k t) at an impact with a state error that is not a time shift, so
    /// every term (R_x d⁻, R_t δt, −f⁺ δt) is exercised; the two agree to O(|d|²).
    #[test]
    fn the_secant_jump_agrees_with_the_jacobian_jump() {
        let (e, c, k, g, t) = (0.8, 0.3, 0.7, 9.81, 1.2);
        let x_minus = Vector2::new(0.0, -3.0);
        let reset =
            |t: f64, x: &Vector2<f64>| Vector2::new(x[0], -e * x[1] - c * x[1].powi(3) + k * t);
        let x_plus = reset(t, &x_minus);
        let f_minus = Vector2::new(x_minus[1], -g);
        let f_plus = Vector2::new(x_plus[1], -g);
        let rx = Matrix2::new(1.0, 0.0, 0.0, -e - 3.0 * c * x_minus[1].powi(2));
        let rt = Vector2::new(0.0, k);
        let gx = Vector2::new(1.0, 0.0);
        let secant = |d: &Vector2<f64>, dt: f64, xs: &mut Vector2<f64>, out: &mut Vector2<f64>| {
            *xs = x_minus + d;
            *out = reset(t + dt, xs) - x_plus;
        };
        for scale in [1e-4, 1e-6, 1e-8] {
            let run = |secant: Option<&ResetSecant<'_, Const<2>>>| {
                let mut ge = GlobalError::new(Const::<2>, Const::<1>);
                ge.r.x = Vector2::new(2.0 * scale, -1.5 * scale);
                ge.zero = false;
                let s = impact((&rx, Some(&rt)), (&f_minus, &f_plus), &gx, secant);
                ge.jump(&s, false);
                let (dm, dp, dt) = ge.jump_shift();
                (ge.r.x, *dm, *dp, dt)
            };
            let (ex, dm, dp, dt) = run(None);
            let (sx, sm, sp, st) = run(Some(&secant));
            assert_eq!((dm, dt), (sm, st), "the displacement d⁻, δt does not use R");
            // The secant's second-order term: 3c|v|·d_v² = 2.7 d_v² (and c·d_v³).
            let bound = 3.0 * dm.norm_squared() + 1e-15;
            for (a, b) in [(ex, sx), (dp, sp)] {
                assert!((a - b).norm() <= bound, "{scale}: {a} vs {b}");
                assert!(
                    (a - b).norm() > 0.0 || scale < 1e-7,
                    "{scale}: a nonlinear reset"
                );
            }
            assert!(ex.norm() > 0.5 * scale, "the estimate moved: {ex}");
        }
    }

    /// Moving r_x's component along f into α leaves r_x orthogonal to f in the weighted norm
    /// and α f + r_x unchanged.
    #[test]
    fn the_flow_component_moves_into_the_time_shift() {
        let mut ge = GlobalError::new(Const::<2>, Const::<1>);
        ge.r.x = Vector2::new(2e-6, 1e-6);
        let mut f0 = AugState::zeros(Const::<2>, Const::<1>);
        f0.x = Vector2::new(1.0, 3.0);
        let y0 = AugState::zeros(Const::<2>, Const::<1>);
        ge.move_along_flow(&f0, &y0, (1.0, 0.0), false);
        assert_relative_eq!(ge.r.x.dot(&f0.x), 0.0, epsilon = 1e-20);
        let e = ge.r.x + f0.x * ge.alpha;
        assert_relative_eq!(e[0], 2e-6, max_relative = 1e-14);
        assert_relative_eq!(e[1], 1e-6, max_relative = 1e-14);
    }
}
