//! The smooth test problems of the integrator tests (`integrate.rs`, `stiff.rs`) with
//! their closed forms, and the helpers that drive an [`Integrator`] directly.
#![allow(dead_code)]

use crate::common::{info, AdModel, Sc, Spec};
use mvad_runtime::fixtures::Ball;
use mvad_runtime::integrate::{AugState, Forward, Integrator};
use mvad_runtime::solution::{Method, Options};
use mvad_runtime::{HybridModel, ModelInfo};
use nalgebra::{Const, DVector, Dyn, OVector};

/// The smooth test problems of the integrator tests (no events; modes `a` and `b`), as generic
/// formulas: every Jacobian by dual numbers. Closed forms beside each constructor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Ode {
    Decay,
    DecayIntegral,
    Oscillator,
    TwoModes,
    Blowup,
    ProtheroRobinson,
    StiffLag,
    Quintic,
    ZeroComponent,
}

impl Ode {
    /// (states, parameters).
    pub fn dims(self) -> (usize, usize) {
        match self {
            Ode::Decay | Ode::ProtheroRobinson | Ode::Quintic => (1, 2),
            Ode::Oscillator | Ode::ZeroComponent => (2, 1),
            Ode::TwoModes | Ode::Blowup | Ode::DecayIntegral => (1, 1),
            Ode::StiffLag => (2, 2),
        }
    }
    pub fn model(self) -> AdModel<Ode> {
        AdModel::new(self)
    }
}

impl Spec for Ode {
    fn info(&self) -> ModelInfo {
        let (n, np) = self.dims();
        let states: Vec<String> = (0..n).map(|i| format!("x{i}")).collect();
        let params: Vec<String> = (0..np).map(|i| format!("p{i}")).collect();
        let states: Vec<&str> = states.iter().map(String::as_str).collect();
        let params: Vec<(&str, f64)> = params.iter().map(|p| (p.as_str(), 0.0)).collect();
        let mut i = info("ode", &states, &params, &["a", "b"], vec![], &[], 0);
        i.has_running_cost = matches!(self, Ode::Decay | Ode::DecayIntegral | Ode::Oscillator);
        i.has_horizon = false;
        i
    }
    fn x0<S: Sc>(&self, _p: &[S], x: &mut [S]) {
        x.iter_mut().for_each(|v| *v = S::cst(0.0));
    }
    fn horizon<S: Sc>(&self, _p: &[S]) -> Option<S> {
        None
    }
    fn rhs<S: Sc>(&self, m: usize, _sw: u64, t: S, x: &[S], p: &[S], f: &mut [S]) {
        match self {
            Ode::Decay | Ode::DecayIntegral => f[0] = -(p[0] * x[0]),
            Ode::Oscillator => {
                f[0] = x[1];
                f[1] = -(p[0] * p[0] * x[0]);
            }
            Ode::TwoModes => f[0] = S::cst(if m == 0 { 1.0 } else { -1.0 }),
            Ode::Blowup => f[0] = x[0] * x[0],
            Ode::ProtheroRobinson => f[0] = p[0] * (x[0] - t.sin()) + t.cos(),
            Ode::StiffLag => {
                f[0] = (x[1] - x[0]) / p[0];
                f[1] = -(p[1] * x[0]);
            }
            Ode::Quintic => f[0] = -(p[0] * x[0].powi(5)),
            Ode::ZeroComponent => {
                f[0] = -(p[0] * x[0]);
                f[1] = S::cst(0.0);
            }
        }
    }
    fn running<S: Sc>(&self, _sw: u64, _t: S, x: &[S], _p: &[S]) -> S {
        match self {
            Ode::Decay => x[0] * x[0],
            Ode::Oscillator | Ode::DecayIntegral => x[0],
            _ => S::cst(0.0),
        }
    }
}

pub type Model = AdModel<Ode>;

/// ẋ = −a x, θ = (a, x0), ℓ = x². Closed forms: x = x0 e^{−at}, S = (−t x, e^{−at}),
/// q = x0² (1 − e^{−2aT})/(2a).
pub fn decay() -> Model {
    Ode::Decay.model()
}

pub fn decay_start(a: f64, x0: f64) -> (DVector<f64>, AugState<Dyn, Dyn>) {
    let p = DVector::from_vec(vec![a, x0]);
    let mut y = AugState::zeros(Dyn(1), Dyn(2));
    y.x[0] = x0;
    y.s[(0, 1)] = 1.0;
    (p, y)
}

/// Closed form of the decay problem at T: (x, S_a, S_x0, q, q_a, q_x0).
pub fn decay_exact(a: f64, x0: f64, t: f64) -> [f64; 6] {
    let e = (-a * t).exp();
    let e2 = e * e;
    let q = x0 * x0 * (1.0 - e2) / (2.0 * a);
    let qa = x0 * x0 * (t * e2 / a - (1.0 - e2) / (2.0 * a * a));
    let qx0 = x0 * (1.0 - e2) / a;
    [x0 * e, -t * x0 * e, e, q, qa, qx0]
}

/// ẋ = −a x, θ = (a), ℓ = x (the start is set by the caller).
pub fn decay_integral() -> Model {
    Ode::DecayIntegral.model()
}

/// Closed form of [`decay_integral`] from x(0) = x0: (x, S, q, q_θ) =
/// (x0 e^{−at}, −t x, x0 (1 − e^{−at})/a, x0 (t e^{−at}/a − (1 − e^{−at})/a²)).
pub fn decay_integral_exact(a: f64, x0: f64, t: f64) -> [f64; 4] {
    let e = (-a * t).exp();
    let x = x0 * e;
    [
        x,
        -t * x,
        x0 * (1.0 - e) / a,
        x0 * (t * e / a - (1.0 - e) / (a * a)),
    ]
}

/// ẍ = −ω² x as (x, v), θ = (ω): x = cos ωt, v = −ω sin ωt,
/// ∂x/∂ω = −t sin ωt, ∂v/∂ω = −sin ωt − ωt cos ωt; ℓ = x: q = sin ωT/ω,
/// q_ω = T cos ωT/ω − sin ωT/ω².
pub fn oscillator() -> Model {
    Ode::Oscillator.model()
}

pub fn oscillator_exact(w: f64, t: f64) -> [f64; 6] {
    let (s, c) = (w * t).sin_cos();
    [
        c,
        -w * s,
        -t * s,
        -s - w * t * c,
        s / w,
        t * c / w - s / (w * w),
    ]
}

pub fn opts(method: Method, rtol: f64, atol: f64) -> Options {
    Options {
        method,
        rtol,
        atol,
        ..Options::default()
    }
}

/// Steps `it` adaptively up to `t_end`.
pub fn integrate_to<M: HybridModel>(it: &mut Integrator<Forward<'_, M>>, t_end: f64)
where
    nalgebra::DefaultAllocator: mvad_runtime::ModelAlloc<M::N, M::P>,
{
    while it.t() < t_end {
        it.step(t_end).unwrap();
    }
}

/// The E1 ball's initial augmented state (x0, S0 = ∂x0/∂θ).
pub fn ball_start(ball: &Ball, p: &OVector<f64, Const<4>>) -> AugState<Const<2>, Const<4>> {
    let mut y0 = AugState::zeros(Const::<2>, Const::<4>);
    ball.initial_state(p, &mut y0.x);
    ball.initial_state_jac(p, &mut y0.s);
    y0
}

/// The oscillator at ω = `w` from (x, v) = (1, 0): parameters and initial state.
pub fn oscillator_start(w: f64) -> (DVector<f64>, AugState<Dyn, Dyn>) {
    let mut y0 = AugState::zeros(Dyn(2), Dyn(1));
    y0.x[0] = 1.0;
    (DVector::from_vec(vec![w]), y0)
}

/// Integrates with fixed steps n over [0, t_end] and returns the final state.
pub fn fixed_steps<M: HybridModel<N = Dyn, P = Dyn>>(
    model: &M,
    p: &DVector<f64>,
    y0: &AugState<Dyn, Dyn>,
    method: Method,
    t_end: f64,
    n: usize,
) -> AugState<Dyn, Dyn> {
    let o = opts(method, 1e-6, 1e-6);
    let mut it = Integrator::new(model, p, &o);
    it.restart(0.0, y0, 0, &mvad_runtime::Switches::default());
    let h = t_end / n as f64;
    for _ in 0..n {
        it.step_fixed(h).unwrap();
    }
    assert_eq!(it.active_method(), method);
    it.y().clone()
}

/// Global error of x, S, q and q_θ of the oscillator at T = 2 with n fixed steps.
pub fn oscillator_errors(method: Method, n: usize) -> [f64; 6] {
    let m = oscillator();
    let w = 1.7;
    let (p, y0) = oscillator_start(w);
    let y = fixed_steps(&m, &p, &y0, method, 2.0, n);
    let ex = oscillator_exact(w, 2.0);
    let got = [y.x[0], y.x[1], y.s[(0, 0)], y.s[(1, 0)], y.q, y.qp[0]];
    let mut err = [0.0; 6];
    for i in 0..6 {
        err[i] = (got[i] - ex[i]).abs();
    }
    err
}

/// Least-squares slope of log(error) against log(h) over the step counts `ns`, for the
/// groups (x, v), S and (q, q_θ) (group norms: single components can cross zero).
pub fn observed_orders(method: Method, ns: &[usize]) -> [f64; 3] {
    let errs: Vec<[f64; 3]> = ns
        .iter()
        .map(|&n| {
            let e = oscillator_errors(method, n);
            [e[0].hypot(e[1]), e[2].hypot(e[3]), e[4].hypot(e[5])]
        })
        .collect();
    let lh: Vec<f64> = ns.iter().map(|&n| (1.0 / n as f64).ln()).collect();
    let mh = lh.iter().sum::<f64>() / lh.len() as f64;
    let mut o = [0.0; 3];
    for g in 0..3 {
        let le: Vec<f64> = errs.iter().map(|e| e[g].ln()).collect();
        let me = le.iter().sum::<f64>() / le.len() as f64;
        let num: f64 = lh.iter().zip(&le).map(|(a, b)| (a - mh) * (b - me)).sum();
        let den: f64 = lh.iter().map(|a| (a - mh) * (a - mh)).sum();
        o[g] = num / den;
    }
    o
}

/// Two modes: ẋ = +1 in mode 0, ẋ = −1 in mode 1 (θ unused).
pub fn two_modes() -> Model {
    Ode::TwoModes.model()
}

/// Prothero–Robinson: ẏ = λ (y − sin t) + cos t, θ = (λ, y0): y = sin t + y0 e^{λt},
/// ∂y/∂λ = t y0 e^{λt}, ∂y/∂y0 = e^{λt}.
pub fn prothero_robinson() -> Model {
    Ode::ProtheroRobinson.model()
}

/// The stiff lag: ẏ = (u − y)/τ, u̇ = −k y, θ = (τ, k). A linear system ẋ = A x, so
/// x(t) = e^{At} x0 and ∂x/∂θ_j = X_j x0 with X_j the upper-right block of
/// exp(t [[A, ∂A/∂θ_j], [0, A]]).
pub fn stiff_lag() -> Model {
    Ode::StiffLag.model()
}

/// Closed form of the stiff lag from x0 = (0, 1): with λ₋ = (−1/τ − √(1/τ² − 4k/τ))/2 and
/// λ₊ = (k/τ)/λ₋ (no cancellation), eigenvectors (1, 1 + λτ) and c = 1/(τ(λ₊ − λ₋)):
/// y = c (e^{λ₊t} − e^{λ₋t}), u = c ((1 + λ₊τ) e^{λ₊t} − (1 + λ₋τ) e^{λ₋t}).
pub fn stiff_lag_closed(tau: f64, k: f64, t: f64) -> [f64; 2] {
    let (lm, lp) = stiff_lag_eigenvalues(tau, k);
    let c = 1.0 / (tau * (lp - lm));
    let (ep, em) = ((lp * t).exp(), (lm * t).exp());
    [
        c * (ep - em),
        c * ((1.0 + lp * tau) * ep - (1.0 + lm * tau) * em),
    ]
}

/// (λ₋, λ₊) of the stiff lag, λ₊ = (k/τ)/λ₋ without cancellation.
pub fn stiff_lag_eigenvalues(tau: f64, k: f64) -> (f64, f64) {
    let lm = 0.5 * (-1.0 / tau - (1.0 / (tau * tau) - 4.0 * k / tau).sqrt());
    (lm, (k / tau) / lm)
}

/// x and S = ∂x/∂(τ, k) in closed form for t ≫ τ (e^{λ₋t} = 0): λ₊ solves
/// τλ² + λ + k = 0, so λ₊' = −λ₊²/(1 + 2τλ₊) in τ and −1/(1 + 2τλ₊) in k; with
/// w = τ(λ₊ − λ₋) = √(1 − 4kτ), y = e^{λ₊t}/w, u = (1 + λ₊τ) y, and
/// ∂y = y (t ∂λ₊ + ∂w⁻¹·w), ∂_τ w⁻¹ = 2k/w³, ∂_k w⁻¹ = 2τ/w³.
pub fn stiff_lag_exact(tau: f64, k: f64, t: f64) -> ([f64; 2], [[f64; 2]; 2]) {
    let x = stiff_lag_closed(tau, k, t);
    let (_, lp) = stiff_lag_eigenvalues(tau, k);
    let w = (1.0 - 4.0 * k * tau).sqrt();
    let y = x[0];
    let dl_tau = -lp * lp / (1.0 + 2.0 * tau * lp);
    let dl_k = -1.0 / (1.0 + 2.0 * tau * lp);
    let dy_tau = y * (t * dl_tau + 2.0 * k / (w * w));
    let dy_k = y * (t * dl_k + 2.0 * tau / (w * w));
    let du_tau = (lp + tau * dl_tau) * y + (1.0 + lp * tau) * dy_tau;
    let du_k = tau * dl_k * y + (1.0 + lp * tau) * dy_k;
    (x, [[dy_tau, dy_k], [du_tau, du_k]])
}

/// ẋ = −a x⁵, θ = (a, x0): x = (x0⁻⁴ + 4at)^(−1/4), ∂x/∂a = −t (x0⁻⁴ + 4at)^(−5/4),
/// ∂x/∂x0 = x0⁻⁵ (x0⁻⁴ + 4at)^(−5/4). f_x S + f_θ is cubic in x, so the Rosenbrock
/// method's directional difference for ∂_x(f_x S + f_θ) has a truncation error here.
pub fn quintic() -> Model {
    Ode::Quintic.model()
}
