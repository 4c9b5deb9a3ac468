//! The integrator on stiff problems: Rosenbrock and `auto` on Prothero–Robinson, `auto`
//! switching to Rosenbrock on the stiff lag, with S against the closed forms.

mod common;
mod odes;

use approx::assert_relative_eq;
use mvad_runtime::integrate::{AugState, Integrator};
use mvad_runtime::solution::Method;
use nalgebra::{DVector, Dyn};
use odes::*;

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
        it.restart(0.0, &y0, 0, &mvad_runtime::Switches::default());
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

/// Tight tolerances hide stiffness from the stability tests: Tsit5's accuracy alone holds
/// its step near the stability bound (h·ρ ≈ 0.2–1), where Hairer's test and h·ρ > 0.8 stay
/// quiet, although y = sin t varies 10⁴ times more slowly than its fast mode. `auto` must still
/// switch (the slow-solution test in `stiffness.rs`) and take about Rosenbrock's steps, not
/// Tsit5's (before the test: 36× Rosenbrock's at rtol 1e-10 on a stiff tracking problem).
#[test]
fn auto_finds_stiffness_that_tight_tolerances_hide() {
    let m = prothero_robinson();
    let p = DVector::from_vec(vec![-1e4, 0.0]);
    let t_end = 10.0;
    for rtol in [1e-8, 1e-10, 1e-12] {
        let steps = |method: Method| {
            let o = opts(method, rtol, rtol * 1e-2);
            let mut it = Integrator::new(&m, &p, &o);
            let mut y0 = AugState::zeros(Dyn(1), Dyn(2));
            y0.s[(0, 1)] = 1.0;
            it.restart(0.0, &y0, 0, &mvad_runtime::Switches::default());
            integrate_to(&mut it, t_end);
            assert_relative_eq!(it.y().x[0], t_end.sin(), max_relative = 1e3 * rtol);
            it.stats().steps
        };
        let (auto, rosenbrock) = (steps(Method::Auto), steps(Method::Rosenbrock));
        assert!(
            auto <= 2 * rosenbrock,
            "rtol {rtol}: auto took {auto} steps, Rosenbrock {rosenbrock}"
        );
    }
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
    it.restart(0.0, &y0, 0, &mvad_runtime::Switches::default());
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
    // With error control on x alone.
    let (y, steps) = stiff_lag_auto(false, 1000);
    assert!(steps < 500, "{steps} steps");
    // Explicit Tsit5 alone is held at h ≈ 3.5τ by stability: over [0, 1e-5] it already needs
    // hundreds of steps, i.e. ~1e8 for [0, 3].
    let m = stiff_lag();
    let p = DVector::from_vec(vec![tau, k]);
    let mut y0 = AugState::zeros(Dyn(2), Dyn(2));
    y0.x[1] = 1.0;
    let mut it5 = Integrator::new(&m, &p, &opts(Method::Tsit5, 1e-8, 1e-10));
    it5.restart(0.0, &y0, 0, &mvad_runtime::Switches::default());
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

/// With S under error control, `auto` gets S of the stiff lag to 2e-6. Column j of S is
/// controlled as θ_j·S_j (CVODES's parameter scaling), so S_τ, of size 1 here, is held to
/// ~atol/τ absolute rather than atol: ∂y/∂τ comes out 1.55e-6 relative (5.0e-7 before steps
/// were put on the time grid, (t + h) − t, which at τ-sized steps near t = 1 changes h by up
/// to 1e-8 relative and so the step sequence; 2e-7 with unscaled control, which in turn
/// cannot run the stiff relay, whose S_τ reaches 1/τ). Both are far inside what the scaled
/// control promises (atol/τ = 1e-2 absolute).
#[test]
fn auto_with_sensitivity_error_control_gets_s_of_the_stiff_lag_to_2e_6() {
    let (y, _) = stiff_lag_auto(true, 3000);
    let (_, s) = stiff_lag_exact(1e-8, 0.5, 3.0);
    assert_stiff_lag_s(&y, &s, 2e-6);
}
