//! Integrator tests: empirical orders, dense output, sensitivities and quadratures against
//! closed forms, restart semantics, stiffness switching.

use approx::assert_relative_eq;
use mvad_runtime::fixtures::Ball;
use mvad_runtime::integrate::{AugState, Integrator};
use mvad_runtime::solution::{Method, Options};
use mvad_runtime::{HybridModel, ModelInfo, Switches};
use nalgebra::{Const, DVector, Dyn, OVector};

mod common;

use common::{info, AdModel, Sc, Spec};

/// The smooth test problems of this file (no events; modes `a` and `b`), as generic
/// formulas: every Jacobian by dual numbers. Closed forms beside each constructor.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Ode {
    Decay,
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
    fn dims(self) -> (usize, usize) {
        match self {
            Ode::Decay | Ode::ProtheroRobinson | Ode::Quintic => (1, 2),
            Ode::Oscillator | Ode::ZeroComponent => (2, 1),
            Ode::TwoModes | Ode::Blowup => (1, 1),
            Ode::StiffLag => (2, 2),
        }
    }
    fn model(self) -> AdModel<Ode> {
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
        i.has_running_cost = matches!(self, Ode::Decay | Ode::Oscillator);
        i.has_horizon = false;
        i
    }
    fn x0<S: Sc>(&self, _p: &[S], x: &mut [S]) {
        x.iter_mut().for_each(|v| *v = S::cst(0.0));
    }
    fn horizon<S: Sc>(&self, _p: &[S]) -> Option<S> {
        None
    }
    fn rhs<S: Sc>(&self, m: usize, _sw: Switches, t: S, x: &[S], p: &[S], f: &mut [S]) {
        match self {
            Ode::Decay => f[0] = -(p[0] * x[0]),
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
    fn running<S: Sc>(&self, _sw: Switches, _t: S, x: &[S], _p: &[S]) -> S {
        match self {
            Ode::Decay => x[0] * x[0],
            Ode::Oscillator => x[0],
            _ => S::cst(0.0),
        }
    }
}

type Model = AdModel<Ode>;

/// ẋ = −a x, θ = (a, x0), ℓ = x². Closed forms: x = x0 e^{−at}, S = (−t x, e^{−at}),
/// q = x0² (1 − e^{−2aT})/(2a).
fn decay() -> Model {
    Ode::Decay.model()
}

fn decay_start(a: f64, x0: f64) -> (DVector<f64>, AugState<Dyn, Dyn>) {
    let p = DVector::from_vec(vec![a, x0]);
    let mut y = AugState::zeros(Dyn(1), Dyn(2));
    y.x[0] = x0;
    y.s[(0, 1)] = 1.0;
    (p, y)
}

/// Closed form of the decay problem at T: (x, S_a, S_x0, q, q_a, q_x0).
fn decay_exact(a: f64, x0: f64, t: f64) -> [f64; 6] {
    let e = (-a * t).exp();
    let e2 = e * e;
    let q = x0 * x0 * (1.0 - e2) / (2.0 * a);
    let qa = x0 * x0 * (t * e2 / a - (1.0 - e2) / (2.0 * a * a));
    let qx0 = x0 * (1.0 - e2) / a;
    [x0 * e, -t * x0 * e, e, q, qa, qx0]
}

/// ẍ = −ω² x as (x, v), θ = (ω): x = cos ωt, v = −ω sin ωt,
/// ∂x/∂ω = −t sin ωt, ∂v/∂ω = −sin ωt − ωt cos ωt; ℓ = x: q = sin ωT/ω,
/// q_ω = T cos ωT/ω − sin ωT/ω².
fn oscillator() -> Model {
    Ode::Oscillator.model()
}

fn oscillator_exact(w: f64, t: f64) -> [f64; 6] {
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

fn opts(method: Method, rtol: f64, atol: f64) -> Options {
    Options {
        method,
        rtol,
        atol,
        ..Options::default()
    }
}

/// Steps `it` adaptively up to `t_end`.
fn integrate_to<M: HybridModel>(it: &mut Integrator<'_, M>, t_end: f64)
where
    nalgebra::DefaultAllocator: mvad_runtime::ModelAlloc<M::N, M::P>,
{
    while it.t() < t_end {
        it.step(t_end).unwrap();
    }
}

/// The E1 ball's initial augmented state (x0, S0 = ∂x0/∂θ).
fn ball_start(ball: &Ball, p: &OVector<f64, Const<4>>) -> AugState<Const<2>, Const<4>> {
    let mut y0 = AugState::zeros(Const::<2>, Const::<4>);
    ball.initial_state(p, &mut y0.x);
    ball.initial_state_jac(p, &mut y0.s);
    y0
}

/// The oscillator at ω = `w` from (x, v) = (1, 0): parameters and initial state.
fn oscillator_start(w: f64) -> (DVector<f64>, AugState<Dyn, Dyn>) {
    let mut y0 = AugState::zeros(Dyn(2), Dyn(1));
    y0.x[0] = 1.0;
    (DVector::from_vec(vec![w]), y0)
}

/// Integrates with fixed steps n over [0, t_end] and returns the final state.
fn fixed_steps<M: HybridModel<N = Dyn, P = Dyn>>(
    model: &M,
    p: &DVector<f64>,
    y0: &AugState<Dyn, Dyn>,
    method: Method,
    t_end: f64,
    n: usize,
) -> AugState<Dyn, Dyn> {
    let o = opts(method, 1e-6, 1e-6);
    let mut it = Integrator::new(model, p, &o);
    it.restart(0.0, y0, 0, 0);
    let h = t_end / n as f64;
    for _ in 0..n {
        it.step_fixed(h).unwrap();
    }
    assert_eq!(it.active_method(), method);
    it.y().clone()
}

/// Global error of x, S, q and q_θ of the oscillator at T = 2 with n fixed steps.
fn oscillator_errors(method: Method, n: usize) -> [f64; 6] {
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
fn observed_orders(method: Method, ns: &[usize]) -> [f64; 3] {
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

/// Per method: the fixed step counts of the convergence study and the range the observed
/// order of x, S and (q, q_θ) must fall in (Auto is Tsit5 with fixed steps).
fn order_table(method: Method) -> Option<(&'static [usize], std::ops::Range<f64>)> {
    match method {
        Method::Tsit5 => Some((&[10, 20, 40, 80], 4.7..6.0)),
        Method::Verner9 => Some((&[4, 6, 8, 12], 8.4..10.5)),
        Method::Rosenbrock => Some((&[10, 20, 40, 80], 4.6..6.2)),
        Method::Auto => None,
    }
}

#[test]
fn orders_for_state_sensitivity_and_quadrature() {
    for method in Method::ALL {
        let Some((ns, range)) = order_table(method) else {
            continue;
        };
        let o = observed_orders(method, ns);
        for (g, og) in o.iter().enumerate() {
            assert!(
                range.contains(og),
                "{method:?} group {g}: order {og} ({o:?})"
            );
        }
    }
}

/// Per method: the step sizes of one step from t = 0 and the least observed order of the
/// local error of the dense output at θ = 0.37 (a continuous extension of order k has local
/// error O(h^(k+1)): 4th order for Tsit5 and Rosenbrock, 9th for Verner).
fn dense_table(method: Method) -> Option<([f64; 3], f64)> {
    match method {
        Method::Tsit5 => Some(([0.4, 0.2, 0.1], 4.6)),
        Method::Verner9 => Some(([1.6, 0.8, 0.4], 9.3)),
        Method::Rosenbrock => Some(([0.4, 0.2, 0.1], 4.5)),
        Method::Auto => None,
    }
}

#[test]
fn dense_output_order_at_interior_points() {
    let m = oscillator();
    let w = 1.3;
    let (p, y0) = oscillator_start(w);
    for method in Method::ALL {
        let Some((hs, least)) = dense_table(method) else {
            continue;
        };
        let o = opts(method, 1e-6, 1e-6);
        let mut errs = vec![];
        for h in hs {
            let mut it = Integrator::new(&m, &p, &o);
            it.restart(0.0, &y0, 0, 0);
            it.step_fixed(h).unwrap();
            let tq = 0.37 * h;
            let mut x = DVector::zeros(2);
            it.dense_x(tq, &mut x);
            let mut full = AugState::zeros(Dyn(2), Dyn(1));
            it.dense(tq, &mut full);
            assert_relative_eq!(full.x[0], x[0], epsilon = 1e-15);
            let ex = oscillator_exact(w, tq);
            errs.push(
                (x[0] - ex[0])
                    .abs()
                    .max((full.s[(0, 0)] - ex[2]).abs())
                    .max((full.qp[0] - ex[5]).abs()),
            );
            if method == Method::Tsit5 {
                // End points reproduce the step's states exactly.
                it.dense_x(0.0, &mut x);
                assert_eq!(x[0], 1.0);
                it.dense_x(h, &mut x);
                assert_relative_eq!(x[0], it.y().x[0], epsilon = 1e-15);
            }
        }
        for i in 0..2 {
            let order = (errs[i] / errs[i + 1]).log2();
            assert!(
                order > least,
                "{method:?}: local dense order {order}: {errs:?}"
            );
        }
    }
}

/// Per method: (rtol, atol, the error-control settings for S, the relative accuracy of x,
/// S, q and q_θ on the decay problem).
fn decay_table(method: Method) -> (f64, f64, &'static [bool], f64) {
    match method {
        Method::Tsit5 | Method::Auto => (1e-10, 1e-12, &[false, true], 1e-8),
        Method::Rosenbrock => (1e-9, 1e-12, &[false, true], 1e-7),
        Method::Verner9 => (1e-13, 1e-15, &[true], 1e-12),
    }
}

#[test]
fn adaptive_decay_matches_closed_form_for_x_s_q_and_gradient() {
    let (a, x0, t_end) = (1.3, 2.0, 3.0);
    let m = decay();
    let (p, y0) = decay_start(a, x0);
    let ex = decay_exact(a, x0, t_end);
    for method in Method::ALL {
        let (rtol, atol, secs, rel) = decay_table(method);
        for &sens_ec in secs {
            let mut o = opts(method, rtol, atol);
            o.sens_error_control = sens_ec;
            let mut it = Integrator::new(&m, &p, &o);
            it.restart(0.0, &y0, 0, 0);
            let mut guard = 0;
            while it.t() < t_end {
                it.step(t_end).unwrap();
                guard += 1;
                assert!(guard < 10_000);
            }
            assert_eq!(it.t(), t_end, "{method:?} lands exactly on t_stop");
            let y = it.y();
            let got = [y.x[0], y.s[(0, 0)], y.s[(0, 1)], y.q, y.qp[0], y.qp[1]];
            for i in 0..6 {
                assert_relative_eq!(got[i], ex[i], max_relative = rel);
            }
            let st = it.stats();
            match method {
                Method::Tsit5 | Method::Auto => {
                    assert!(st.steps > 5 && st.steps < 400, "steps {}", st.steps);
                    assert!(st.rhs_evals >= 6 * st.steps);
                }
                Method::Rosenbrock => {
                    assert_eq!(st.jac_evals, st.steps, "one Jacobian per accepted step");
                    assert!(st.factorizations >= st.steps);
                }
                Method::Verner9 => {
                    assert!(st.steps < 100, "{st:?}");
                    // 15 new stages per attempt + 10 interpolation stages per accepted step,
                    // the first of which is the next step's first stage (+ F(t0, y0) and the
                    // first-step probe).
                    assert_eq!(
                        st.rhs_evals,
                        15 * (st.steps + st.rejected_steps) + 10 * st.steps + 2
                    );
                    // Tsit5 needs many more steps for the same accuracy.
                    let mut o5 = o.clone();
                    o5.method = Method::Tsit5;
                    let mut it5 = Integrator::new(&m, &p, &o5);
                    it5.restart(0.0, &y0, 0, 0);
                    integrate_to(&mut it5, t_end);
                    assert!(it5.stats().steps > 3 * st.steps);
                }
            }
        }
    }
}

#[test]
fn primal_only_leaves_sensitivities_alone() {
    let (a, x0, t_end) = (0.7, 1.5, 2.0);
    let m = decay();
    let (p, y0) = decay_start(a, x0);
    let mut o = opts(Method::Tsit5, 1e-9, 1e-12);
    o.sensitivities = false;
    let mut it = Integrator::new(&m, &p, &o);
    it.restart(0.0, &y0, 0, 0);
    integrate_to(&mut it, t_end);
    let ex = decay_exact(a, x0, t_end);
    assert_relative_eq!(it.y().x[0], ex[0], max_relative = 1e-8);
    assert_relative_eq!(it.y().q, ex[3], max_relative = 1e-8);
    // S keeps its initial value (not advanced).
    assert_eq!(it.y().s[(0, 1)], 1.0);
    assert_eq!(it.y().qp[0], 0.0);
}

#[test]
fn ball_flight_is_exact_for_tsit5() {
    // h = h0 + v0 t − g t²/2 is a quadratic: Tsit5 (order 5) integrates it exactly, and
    // S = ∂(h, v)/∂(e, g, h0, v0), q = ∫h dt, q_θ likewise.
    let ball = Ball::new();
    let p = ball.default_params();
    let o = opts(Method::Tsit5, 1e-10, 1e-10);
    let mut it = Integrator::new(&ball, &p, &o);
    let y0 = ball_start(&ball, &p);
    it.restart(0.0, &y0, 0, 0);
    let t_end = 0.6;
    integrate_to(&mut it, t_end);
    let (g, h0) = (p[1], p[2]);
    let t = t_end;
    let y = it.y();
    assert_relative_eq!(y.x[0], h0 - 0.5 * g * t * t, max_relative = 1e-13);
    assert_relative_eq!(y.x[1], -g * t, max_relative = 1e-13);
    assert_relative_eq!(y.s[(0, 1)], -0.5 * t * t, max_relative = 1e-13);
    assert_relative_eq!(y.s[(1, 1)], -t, max_relative = 1e-13);
    assert_relative_eq!(y.s[(0, 2)], 1.0, max_relative = 1e-13);
    assert_relative_eq!(y.s[(0, 3)], t, max_relative = 1e-13);
    assert_relative_eq!(y.q, h0 * t - g * t * t * t / 6.0, max_relative = 1e-13);
    assert_relative_eq!(y.qp[1], -t * t * t / 6.0, max_relative = 1e-13);
    assert_relative_eq!(y.qp[3], t * t / 2.0, max_relative = 1e-13);
    assert_eq!(y.qp[0], 0.0);
}

/// Two modes: ẋ = +1 in mode 0, ẋ = −1 in mode 1 (θ unused).
fn two_modes() -> Model {
    Ode::TwoModes.model()
}

#[test]
fn restart_discards_the_fsal_stage() {
    let m = two_modes();
    let p = DVector::from_vec(vec![0.0]);
    for method in [
        Method::Tsit5,
        Method::Verner9,
        Method::Rosenbrock,
        Method::Auto,
    ] {
        let o = opts(method, 1e-8, 1e-10);
        let mut it = Integrator::new(&m, &p, &o);
        let y0 = AugState::zeros(Dyn(1), Dyn(1));
        it.restart(0.0, &y0, 0, 0);
        it.step(1.0).unwrap();
        let (t1, x1) = (it.t(), it.y().x[0]);
        assert_relative_eq!(x1, t1, epsilon = 1e-14);
        // Same state, other mode: the next step must see ẋ = −1 from its first stage.
        let y1 = it.y().clone();
        it.restart(t1, &y1, 1, 0);
        assert_eq!(it.mode(), 1);
        it.step(10.0).unwrap();
        let (t2, x2) = (it.t(), it.y().x[0]);
        assert_relative_eq!(x2, x1 - (t2 - t1), epsilon = 1e-13);
        let mut xm = DVector::zeros(1);
        it.dense_x(0.5 * (t1 + t2), &mut xm);
        assert_relative_eq!(xm[0], x1 - 0.5 * (t2 - t1), epsilon = 1e-13);
    }
}

#[test]
fn truncate_cuts_the_step_and_the_next_step_restarts_from_the_cut() {
    let (a, x0) = (2.0, 1.0);
    let m = decay();
    let (p, y0) = decay_start(a, x0);
    let o = opts(Method::Tsit5, 1e-10, 1e-12);
    let mut it = Integrator::new(&m, &p, &o);
    it.restart(0.0, &y0, 0, 0);
    it.step(1.0).unwrap();
    it.step(1.0).unwrap();
    let (t0, t1) = (it.t_prev(), it.t());
    let tc = t0 + 0.3 * (t1 - t0);
    it.truncate(tc);
    assert_eq!(it.t(), tc);
    let ex = decay_exact(a, x0, tc);
    assert_relative_eq!(it.y().x[0], ex[0], max_relative = 1e-9);
    assert_relative_eq!(it.y().s[(0, 0)], ex[1], max_relative = 1e-8);
    // Dense output still valid inside [t_prev, t_cut].
    let mut x = DVector::zeros(1);
    it.dense_x(t0 + 0.1 * (t1 - t0), &mut x);
    assert_relative_eq!(
        x[0],
        decay_exact(a, x0, t0 + 0.1 * (t1 - t0))[0],
        max_relative = 1e-9
    );
    integrate_to(&mut it, 1.0);
    let ex = decay_exact(a, x0, 1.0);
    assert_relative_eq!(it.y().x[0], ex[0], max_relative = 1e-8);
    assert_relative_eq!(it.y().qp[0], ex[4], max_relative = 1e-8);
}

#[test]
fn blow_up_is_reported_not_hung() {
    // ẋ = x²: x = 1/(1 − t) blows up at t = 1.
    let m = Ode::Blowup.model();
    let p = DVector::from_vec(vec![0.0]);
    let o = opts(Method::Tsit5, 1e-8, 1e-10);
    let mut it = Integrator::new(&m, &p, &o);
    let mut y0 = AugState::zeros(Dyn(1), Dyn(1));
    y0.x[0] = 1.0;
    it.restart(0.0, &y0, 0, 0);
    let mut n = 0;
    let res = loop {
        match it.step(2.0) {
            Ok(()) if it.t() >= 2.0 => break Ok(()),
            Ok(()) => n += 1,
            Err(e) => break Err(e),
        }
        assert!(n < 100_000, "no progress report");
    };
    let err = res.expect_err("must fail before t = 2");
    assert!(
        it.t() < 1.0 + 1e-6 && it.t() > 0.99,
        "stopped at {}",
        it.t()
    );
    let _ = err.to_string();
}

/// Prothero–Robinson: ẏ = λ (y − sin t) + cos t, θ = (λ, y0): y = sin t + y0 e^{λt},
/// ∂y/∂λ = t y0 e^{λt}, ∂y/∂y0 = e^{λt}.
fn prothero_robinson() -> Model {
    Ode::ProtheroRobinson.model()
}

#[test]
fn prothero_robinson_stiff_with_rosenbrock_and_auto() {
    let lambda = -1e6;
    let m = prothero_robinson();
    for (y0v, method) in [
        (0.0, Method::Rosenbrock),
        (0.5, Method::Rosenbrock),
        (0.5, Method::Auto),
    ] {
        let p = DVector::from_vec(vec![lambda, y0v]);
        let mut y0 = AugState::zeros(Dyn(1), Dyn(2));
        y0.x[0] = y0v;
        y0.s[(0, 1)] = 1.0;
        let o = opts(method, 1e-8, 1e-10);
        let mut it = Integrator::new(&m, &p, &o);
        it.restart(0.0, &y0, 0, 0);
        let t_end = 10.0;
        while it.t() < t_end {
            it.step(t_end).unwrap();
            assert!(it.stats().steps < 2000, "{method:?}: too many steps");
            // Dense output tracks sin t within every step.
            let tm = 0.5 * (it.t_prev() + it.t());
            if tm > 1e-3 {
                let mut x = DVector::zeros(1);
                it.dense_x(tm, &mut x);
                // 4th-order continuous extension, steps up to ~0.1 at rtol 1e-8.
                assert_relative_eq!(x[0], tm.sin(), epsilon = 1e-5);
            }
        }
        assert_relative_eq!(it.y().x[0], t_end.sin(), epsilon = 1e-7);
        assert!(it.y().s[(0, 0)].abs() < 1e-9 && it.y().s[(0, 1)].abs() < 1e-9);
        assert_eq!(it.active_method(), Method::Rosenbrock);
    }
}

/// The stiff lag: ẏ = (u − y)/τ, u̇ = −k y, θ = (τ, k). A linear system ẋ = A x, so
/// x(t) = e^{At} x0 and ∂x/∂θ_j = X_j x0 with X_j the upper-right block of
/// exp(t [[A, ∂A/∂θ_j], [0, A]]).
fn stiff_lag() -> Model {
    Ode::StiffLag.model()
}

/// Closed form of the stiff lag from x0 = (0, 1): with λ₋ = (−1/τ − √(1/τ² − 4k/τ))/2 and
/// λ₊ = (k/τ)/λ₋ (no cancellation), eigenvectors (1, 1 + λτ) and c = 1/(τ(λ₊ − λ₋)):
/// y = c (e^{λ₊t} − e^{λ₋t}), u = c ((1 + λ₊τ) e^{λ₊t} − (1 + λ₋τ) e^{λ₋t}).
fn stiff_lag_closed(tau: f64, k: f64, t: f64) -> [f64; 2] {
    let (lm, lp) = stiff_lag_eigenvalues(tau, k);
    let c = 1.0 / (tau * (lp - lm));
    let (ep, em) = ((lp * t).exp(), (lm * t).exp());
    [
        c * (ep - em),
        c * ((1.0 + lp * tau) * ep - (1.0 + lm * tau) * em),
    ]
}

/// (λ₋, λ₊) of the stiff lag, λ₊ = (k/τ)/λ₋ without cancellation.
fn stiff_lag_eigenvalues(tau: f64, k: f64) -> (f64, f64) {
    let lm = 0.5 * (-1.0 / tau - (1.0 / (tau * tau) - 4.0 * k / tau).sqrt());
    (lm, (k / tau) / lm)
}

/// x and S = ∂x/∂(τ, k) in closed form for t ≫ τ (e^{λ₋t} = 0): λ₊ solves
/// τλ² + λ + k = 0, so λ₊' = −λ₊²/(1 + 2τλ₊) in τ and −1/(1 + 2τλ₊) in k; with
/// w = τ(λ₊ − λ₋) = √(1 − 4kτ), y = e^{λ₊t}/w, u = (1 + λ₊τ) y, and
/// ∂y = y (t ∂λ₊ + ∂w⁻¹·w), ∂_τ w⁻¹ = 2k/w³, ∂_k w⁻¹ = 2τ/w³.
fn stiff_lag_exact(tau: f64, k: f64, t: f64) -> ([f64; 2], [[f64; 2]; 2]) {
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

/// The stiff lag (τ, k) = (1e-8, 0.5) from (0, 1) over [0, 3] under `auto` at rtol 1e-8
/// with S under error control or not: asserts that `auto` switches to Rosenbrock within
/// `max_steps` steps; returns the final state and the accepted steps.
fn stiff_lag_auto(sens_error_control: bool, max_steps: usize) -> (AugState<Dyn, Dyn>, usize) {
    let m = stiff_lag();
    let p = DVector::from_vec(vec![1e-8, 0.5]);
    let mut y0 = AugState::zeros(Dyn(2), Dyn(2));
    y0.x[1] = 1.0;
    let mut o = opts(Method::Auto, 1e-8, 1e-10);
    o.sens_error_control = sens_error_control;
    let mut it = Integrator::new(&m, &p, &o);
    it.restart(0.0, &y0, 0, 0);
    while it.t() < 3.0 {
        it.step(3.0).unwrap();
        let st = it.stats();
        assert!(st.steps < max_steps, "auto did not switch: {st:?}");
    }
    assert_eq!(it.active_method(), Method::Rosenbrock);
    (it.y().clone(), it.stats().steps)
}

#[test]
fn auto_switches_to_rosenbrock_on_the_stiff_lag() {
    let (tau, k, t_end) = (1e-8, 0.5, 3.0);
    // With S under error control too (its forcing ∂f/∂τ ~ 1/τ² amplifies rounding, so the
    // explicit steps are held near τ below the stability bound: the Jacobian test switches).
    stiff_lag_auto(true, 3000);
    // With the default error control.
    let (y, steps) = stiff_lag_auto(Options::default().sens_error_control, 1000);
    assert!(steps < 500, "{steps} steps");
    // Explicit Tsit5 alone is held at h ≈ 3.5τ by stability: over [0, 1e-5] it already needs
    // hundreds of steps, i.e. ~1e8 for [0, 3].
    let m = stiff_lag();
    let p = DVector::from_vec(vec![tau, k]);
    let mut y0 = AugState::zeros(Dyn(2), Dyn(2));
    y0.x[1] = 1.0;
    let mut it5 = Integrator::new(&m, &p, &opts(Method::Tsit5, 1e-8, 1e-10));
    it5.restart(0.0, &y0, 0, 0);
    integrate_to(&mut it5, 1e-5);
    let n5 = it5.stats().steps + it5.stats().rejected_steps;
    assert!(n5 as f64 > 0.5 * 1e-5 / (3.6 * tau), "{:?}", it5.stats());
    let (x, s) = stiff_lag_exact(tau, k, t_end);
    // Sanity of the reference: to first order in τ, y = (1 + 2kτ) e^{λ₊t} with
    // λ₊ = −k(1 + kτ), so ∂y/∂τ = (2k − k²t) e^{λ₊t}.
    let lp = -k * (1.0 + k * tau);
    assert_relative_eq!(
        s[0][0],
        (2.0 * k - k * k * t_end) * (lp * t_end).exp(),
        max_relative = 1e-6
    );
    assert_relative_eq!(y.x[0], x[0], max_relative = 1e-6);
    assert_relative_eq!(y.x[1], x[1], max_relative = 1e-6);
    assert_stiff_lag_s(&y, &s, 1e-6);
}

/// S of the stiff lag against its closed form `s`, entry by entry to `rel`.
fn assert_stiff_lag_s(y: &AugState<Dyn, Dyn>, s: &[[f64; 2]; 2], rel: f64) {
    for (i, si) in s.iter().enumerate() {
        for (j, sij) in si.iter().enumerate() {
            assert_relative_eq!(y.s[(i, j)], *sij, max_relative = rel);
        }
    }
}

/// With S under error control, `auto` gets S of the stiff lag to 2e-7.
#[test]
#[ignore = "known failure since b196f90 (S columns weighted by |θ_j|): S_τ off by 4.1e-7 > 2e-7"]
fn auto_with_sensitivity_error_control_gets_s_of_the_stiff_lag_to_2e_7() {
    let (y, _) = stiff_lag_auto(true, 3000);
    let (_, s) = stiff_lag_exact(1e-8, 0.5, 3.0);
    assert_stiff_lag_s(&y, &s, 2e-7);
}

#[test]
#[ignore = "prints work counters for the report"]
fn print_ball_stats() {
    println!(
        "orders tsit5 {:?}",
        observed_orders(Method::Tsit5, &[10, 20, 40, 80])
    );
    println!(
        "orders rodas5p {:?}",
        observed_orders(Method::Rosenbrock, &[10, 20, 40, 80])
    );
    println!(
        "orders verner9 {:?}",
        observed_orders(Method::Verner9, &[4, 6, 8, 12])
    );
    let ball = Ball::new();
    let p = ball.default_params();
    for method in [Method::Tsit5, Method::Verner9, Method::Rosenbrock] {
        for sens in [false, true] {
            let mut o = opts(method, 1e-10, 1e-10);
            o.sensitivities = sens;
            let mut it = Integrator::new(&ball, &p, &o);
            let y0 = ball_start(&ball, &p);
            it.restart(0.0, &y0, 0, 0);
            let mut hs = vec![];
            while it.t() < 0.6 {
                it.step(0.6).unwrap();
                hs.push(it.t() - it.t_prev());
            }
            println!("{method:?} sens={sens}: {:?} h={hs:?}", it.stats());
        }
    }
    let m = stiff_lag();
    let p = DVector::from_vec(vec![1e-8, 0.5]);
    let mut y0 = AugState::zeros(Dyn(2), Dyn(2));
    y0.x[1] = 1.0;
    for (method, sec) in [
        (Method::Auto, false),
        (Method::Rosenbrock, false),
        (Method::Rosenbrock, true),
        (Method::Auto, true),
    ] {
        let mut o = opts(method, 1e-8, 1e-10);
        o.sens_error_control = sec;
        let mut it = Integrator::new(&m, &p, &o);
        it.restart(0.0, &y0, 0, 0);
        let mut switched = None;
        while it.t() < 3.0 {
            it.step(3.0).unwrap();
            if switched.is_none() && it.active_method() == Method::Rosenbrock {
                switched = Some((it.stats().steps, it.t()));
            }
        }
        let (x, s) = stiff_lag_exact(1e-8, 0.5, 3.0);
        let y = it.y();
        println!(
            "stiff lag {method:?} sens_error_control={sec}: switched at {switched:?}, {:?}, rel err x {:.1e} S_tau {:.1e} S_k {:.1e}",
            it.stats(),
            ((y.x[1] - x[1]) / x[1]).abs(),
            ((y.s[(0, 0)] - s[0][0]) / s[0][0]).abs(),
            ((y.s[(0, 1)] - s[0][1]) / s[0][1]).abs()
        );
    }
}

/// ẋ = −a x⁵, θ = (a, x0): x = (x0⁻⁴ + 4at)^(−1/4), ∂x/∂a = −t (x0⁻⁴ + 4at)^(−5/4),
/// ∂x/∂x0 = x0⁻⁵ (x0⁻⁴ + 4at)^(−5/4). f_x S + f_θ is cubic in x, so the Rosenbrock
/// method's directional difference for ∂_x(f_x S + f_θ) has a truncation error here.
fn quintic() -> Model {
    Ode::Quintic.model()
}

#[test]
fn nonlinear_sensitivities_all_methods() {
    let (a, x0, t_end) = (0.7, 1.5, 2.0);
    let m = quintic();
    let p = DVector::from_vec(vec![a, x0]);
    let mut y0 = AugState::zeros(Dyn(1), Dyn(2));
    y0.x[0] = x0;
    y0.s[(0, 1)] = 1.0;
    let base = x0.powi(-4) + 4.0 * a * t_end;
    let ex = [
        base.powf(-0.25),
        -t_end * base.powf(-1.25),
        x0.powi(-5) * base.powf(-1.25),
    ];
    for method in [
        Method::Tsit5,
        Method::Verner9,
        Method::Rosenbrock,
        Method::Auto,
    ] {
        let mut o = opts(method, 1e-11, 1e-13);
        o.sens_error_control = true;
        let mut it = Integrator::new(&m, &p, &o);
        it.restart(0.0, &y0, 0, 0);
        integrate_to(&mut it, t_end);
        let y = it.y();
        let got = [y.x[0], y.s[(0, 0)], y.s[(0, 1)]];
        for i in 0..3 {
            assert_relative_eq!(got[i], ex[i], max_relative = 1e-9);
        }
    }
}

/// x1 ≡ 0 with atol = 0: its error scale is 0, which must not poison the error norm.
#[test]
#[ignore = "known failure since b196f90: every method stops at t = 0 with StepSizeUnderflow (h = 2.2e-308) when atol = 0 and a component is identically zero"]
fn zero_absolute_tolerance_with_an_identically_zero_component() {
    let mut failures = vec![];
    for method in [Method::Tsit5, Method::Verner9, Method::Rosenbrock] {
        if let Err(e) = std::panic::catch_unwind(|| zero_atol(method)) {
            let msg = e.downcast_ref::<String>().cloned().unwrap_or_default();
            failures.push(format!("{method:?}: {msg}"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// [`zero_absolute_tolerance_with_an_identically_zero_component`] under `method`.
fn zero_atol(method: Method) {
    let m = Ode::ZeroComponent.model();
    let p = DVector::from_vec(vec![0.9]);
    let mut y0 = AugState::zeros(Dyn(2), Dyn(1));
    y0.x[0] = 1.0;
    let mut it = Integrator::new(&m, &p, &opts(method, 1e-9, 0.0));
    it.restart(0.0, &y0, 0, 0);
    while it.t() < 1.0 {
        it.step(1.0)
            .map_err(|e| format!("{e:?} at t = {}", it.t()))
            .unwrap();
    }
    assert_relative_eq!(it.y().x[0], (-0.9f64).exp(), max_relative = 1e-8);
    assert_relative_eq!(it.y().s[(0, 0)], -(-0.9f64).exp(), max_relative = 1e-7);
    assert_eq!(it.y().x[1], 0.0);
}

#[test]
fn seeded_step_size_is_used_and_still_controlled() {
    let ball = Ball::new();
    let p = ball.default_params();
    let y0 = ball_start(&ball, &p);
    let o = opts(Method::Tsit5, 1e-10, 1e-10);
    // The flight is a polynomial Tsit5 integrates exactly: a seed of 0.25 is accepted as is.
    let mut it = Integrator::new(&ball, &p, &o);
    it.restart(0.0, &y0, 0, 0);
    it.set_step_size(0.25);
    it.step(0.6).unwrap();
    assert_eq!(it.t(), 0.25);
    assert_eq!(it.stats().rejected_steps, 0);
    // For the decay problem a seed of 2 is far too large: rejected, then accurate anyway.
    let m = decay();
    let (pd, yd) = decay_start(1.3, 2.0);
    let mut it = Integrator::new(&m, &pd, &opts(Method::Tsit5, 1e-10, 1e-12));
    it.restart(0.0, &yd, 0, 0);
    it.set_step_size(2.0);
    it.step(3.0).unwrap();
    assert!(it.stats().rejected_steps >= 1 && it.t() < 2.0);
    integrate_to(&mut it, 3.0);
    assert_relative_eq!(
        it.y().x[0],
        decay_exact(1.3, 2.0, 3.0)[0],
        max_relative = 1e-8
    );
    // Garbage restores the heuristic.
    it.restart(0.0, &yd, 0, 0);
    it.set_step_size(f64::NAN);
    assert_eq!(it.next_step_size(), 0.0);
}

/// Lazy interpolation stages: the steps (and the FSAL chain) are identical to the eager
/// integrator's with 9 fewer evaluations per step; before `ensure_dense` the dense output is
/// the cubic Hermite interpolant (3rd order, checked against its own closed form on the
/// oscillator's exact end points), after it bit-identical to the eager 9th-order one.
#[test]
fn verner_lazy_interpolation_stages() {
    let m = oscillator();
    let w = 1.3;
    let (p, y0) = oscillator_start(w);
    let o = opts(Method::Verner9, 1e-10, 1e-12);
    let mut eager = Integrator::new(&m, &p, &o);
    let mut lazy = Integrator::new(&m, &p, &o);
    lazy.set_lazy_dense(true);
    eager.restart(0.0, &y0, 0, 0);
    lazy.restart(0.0, &y0, 0, 0);
    let t_end = 5.0;
    let mut steps = 0;
    let (mut a, mut b) = (
        AugState::zeros(Dyn(2), Dyn(1)),
        AugState::zeros(Dyn(2), Dyn(1)),
    );
    while eager.t() < t_end {
        eager.step(t_end).unwrap();
        lazy.step(t_end).unwrap();
        steps += 1;
        assert_eq!(eager.t(), lazy.t());
        assert_eq!(eager.y(), lazy.y());
        let (t0, t1) = (lazy.t_prev(), lazy.t());
        let tq = t0 + 0.37 * (t1 - t0);
        // Hermite stand-in: y0 + c (y1 − y0) + h (w0 f0 + w1 f1), f = (x₂, −w² x₁).
        lazy.dense(tq, &mut b);
        let (h, th) = (t1 - t0, 0.37f64);
        let (w0, w1, c) = (
            th - 2.0 * th * th + th.powi(3),
            th.powi(3) - th * th,
            3.0 * th * th - 2.0 * th.powi(3),
        );
        let (ya, yb) = (lazy.y_prev(), lazy.y());
        let herm = ya.x[0] + c * (yb.x[0] - ya.x[0]) + h * (w0 * ya.x[1] + w1 * yb.x[1]);
        assert_relative_eq!(b.x[0], herm, epsilon = 1e-14);
        lazy.ensure_dense();
        eager.dense(tq, &mut a);
        lazy.dense(tq, &mut b);
        assert_eq!(a, b);
        let ex = oscillator_exact(w, tq);
        assert!((b.x[0] - ex[0]).abs() < 1e-8);
    }
    let (se, sl) = (eager.stats().rhs_evals, lazy.stats().rhs_evals);
    assert_eq!(se - sl, 0, "ensure_dense on every step costs the same");
    // Without ensure_dense the lazy integrator saves 9 evaluations per accepted step.
    let mut lazy2 = Integrator::new(&m, &p, &o);
    lazy2.set_lazy_dense(true);
    lazy2.restart(0.0, &y0, 0, 0);
    integrate_to(&mut lazy2, t_end);
    assert_eq!(lazy2.y(), eager.y());
    assert_eq!(se - lazy2.stats().rhs_evals, 9 * steps);
}
