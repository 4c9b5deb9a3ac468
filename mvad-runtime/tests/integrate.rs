//! Integrator tests: empirical orders, dense output, sensitivities and quadratures against
//! closed forms, restart semantics, stiffness switching.

mod common;
mod odes;

use approx::assert_relative_eq;
use mvad_runtime::fixtures::Ball;
use mvad_runtime::integrate::{AugState, Integrator};
use mvad_runtime::solution::Method;
use mvad_runtime::SolveError;
use mvad_runtime::Switches;
use nalgebra::{DVector, Dyn};
use odes::*;

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
            it.restart(0.0, &y0, 0, &mvad_runtime::Switches::default());
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
            it.restart(0.0, &y0, 0, &mvad_runtime::Switches::default());
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
                    it5.restart(0.0, &y0, 0, &mvad_runtime::Switches::default());
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
    it.restart(0.0, &y0, 0, &mvad_runtime::Switches::default());
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
    it.restart(0.0, &y0, 0, &mvad_runtime::Switches::default());
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
        it.restart(0.0, &y0, 0, &mvad_runtime::Switches::default());
        it.step(1.0).unwrap();
        let (t1, x1) = (it.t(), it.y().x[0]);
        assert_relative_eq!(x1, t1, epsilon = 1e-14);
        // Same state, other mode: the next step must see ẋ = −1 from its first stage.
        let y1 = it.y().clone();
        it.restart(t1, &y1, 1, &mvad_runtime::Switches::default());
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
    it.restart(0.0, &y0, 0, &mvad_runtime::Switches::default());
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
    it.restart(0.0, &y0, 0, &mvad_runtime::Switches::default());
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
            it.restart(0.0, &y0, 0, &mvad_runtime::Switches::default());
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
        it.restart(0.0, &y0, 0, &mvad_runtime::Switches::default());
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
        it.restart(0.0, &y0, 0, &mvad_runtime::Switches::default());
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
    it.restart(0.0, &y0, 0, &mvad_runtime::Switches::default());
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
    it.restart(0.0, &y0, 0, &mvad_runtime::Switches::default());
    it.set_step_size(0.25);
    it.step(0.6).unwrap();
    assert_eq!(it.t(), 0.25);
    assert_eq!(it.stats().rejected_steps, 0);
    // For the decay problem a seed of 2 is far too large: rejected, then accurate anyway.
    let m = decay();
    let (pd, yd) = decay_start(1.3, 2.0);
    let mut it = Integrator::new(&m, &pd, &opts(Method::Tsit5, 1e-10, 1e-12));
    it.restart(0.0, &yd, 0, &mvad_runtime::Switches::default());
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
    it.restart(0.0, &yd, 0, &mvad_runtime::Switches::default());
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
    eager.restart(0.0, &y0, 0, &mvad_runtime::Switches::default());
    lazy.restart(0.0, &y0, 0, &mvad_runtime::Switches::default());
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
    lazy2.restart(0.0, &y0, 0, &mvad_runtime::Switches::default());
    integrate_to(&mut lazy2, t_end);
    assert_eq!(lazy2.y(), eager.y());
    assert_eq!(se - lazy2.stats().rhs_evals, 9 * steps);
}

/// The start x₀ of the backward-stepping test.
const BACKWARD_X0: f64 = 1.3;

/// The augmented state (x, S, q, q_θ) of a one-state, one-parameter problem.
fn one_by_one(v: [f64; 4]) -> AugState<Dyn, Dyn> {
    let mut y = AugState::zeros(Dyn(1), Dyn(1));
    (y.x[0], y.s[(0, 0)], y.q, y.qp[0]) = (v[0], v[1], v[2], v[3]);
    y
}

/// (x, S, q, q_θ) of a one-state, one-parameter state.
fn parts(y: &AugState<Dyn, Dyn>) -> [f64; 4] {
    [y.x[0], y.s[(0, 0)], y.q, y.qp[0]]
}

/// |got − want| ≤ tol·max(1, |want|), part by part.
fn assert_parts_close(got: [f64; 4], want: [f64; 4], tol: f64, what: &str) {
    for (i, (g, w)) in got.iter().zip(&want).enumerate() {
        assert!(
            (g - w).abs() <= tol * w.abs().max(1.0),
            "{what}, part {i}: {g} vs {w}"
        );
    }
}

/// Stepping backwards in time: every scheme, from T down to 0, against the closed form and
/// against the forward run.
#[test]
fn backward_steps_match_the_closed_form_and_the_forward_run() {
    let m = decay_integral();
    let a = 1.5;
    let p = DVector::from_element(1, a);
    let exact = |t: f64| decay_integral_exact(a, BACKWARD_X0, t);
    let t_end = 2.0;
    let tol = 1e-7;
    let sw = Switches::default();
    for method in Method::ALL {
        let o = opts(method, 1e-10, 1e-12);
        // Forward 0 → T, then backward T → 0 from the exact end state.
        let mut fwd = Integrator::new(&m, &p, &o);
        fwd.restart(0.0, &one_by_one(exact(0.0)), 0, &sw);
        integrate_to(&mut fwd, t_end);
        assert_parts_close(parts(fwd.y()), exact(t_end), tol, "forward end");
        let mut bwd = Integrator::new(&m, &p, &o);
        bwd.restart(t_end, &one_by_one(exact(t_end)), 0, &sw);
        let mut mid = AugState::zeros(Dyn(1), Dyn(1));
        let mut seen_mid = false;
        while bwd.t() > 0.0 {
            bwd.step(0.0).unwrap();
            assert!(bwd.t() < bwd.t_prev() && bwd.last_step_size() < 0.0);
            // Dense output between t and t_prev of a backward step.
            if bwd.t() <= 1.0 && 1.0 <= bwd.t_prev() {
                bwd.dense(1.0, &mut mid);
                assert_parts_close(parts(&mid), exact(1.0), tol, "backward dense output");
                let mut x = DVector::zeros(1);
                bwd.dense_x(1.0, &mut x);
                assert_eq!(x[0], mid.x[0]);
                seen_mid = true;
            }
        }
        assert!(seen_mid);
        assert_eq!(bwd.t(), 0.0);
        assert_parts_close(
            parts(bwd.y()),
            exact(0.0),
            tol,
            &format!("{method:?} backward end"),
        );
        // The two directions take similar effort.
        let (sf, sb) = (fwd.stats().steps as f64, bwd.stats().steps as f64);
        assert!(
            sb <= 1.5 * sf + 2.0 && sf <= 1.5 * sb + 2.0,
            "{method:?}: {sf} vs {sb} steps"
        );
        // Truncating a backward step lands on the dense output.
        bwd.restart(t_end, &one_by_one(exact(t_end)), 0, &sw);
        bwd.step(0.0).unwrap();
        let cut = 0.5 * (bwd.t() + bwd.t_prev());
        bwd.dense(cut, &mut mid);
        bwd.truncate(cut);
        assert_eq!(bwd.t(), cut);
        assert_eq!(parts(bwd.y()), parts(&mid));
        // Fixed steps: h = −T/n from T reaches 0 and the same end.
        bwd.restart(t_end, &one_by_one(exact(t_end)), 0, &sw);
        for _ in 0..400 {
            bwd.step_fixed(-t_end / 400.0).unwrap();
        }
        assert_parts_close(
            parts(bwd.y()),
            exact(0.0),
            1e-6,
            &format!("{method:?} fixed steps"),
        );
        assert!(matches!(
            bwd.step_fixed(0.0),
            Err(SolveError::StepSizeUnderflow { .. })
        ));
    }
}
