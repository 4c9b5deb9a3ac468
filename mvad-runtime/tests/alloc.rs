//! The hot loop allocates nothing per step: a run's allocation count does not depend on
//! how many steps it takes, and the integrator's restart, steps, dense output and
//! truncation allocate nothing at all (counted with a global allocator wrapper, per thread
//! so that parallel tests do not interfere).

use mvad_runtime::fixtures::counting::{allocations, Counting};
use mvad_runtime::fixtures::Ball;
use mvad_runtime::integrate::{AugState, Integrator};
use mvad_runtime::solution::{Method, Options};
use mvad_runtime::solve::solve;
use mvad_runtime::HybridModel;
use nalgebra::Const;

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Options with the method and tolerances given.
fn opts(method: Method, rtol: f64, atol: f64) -> Options {
    Options {
        method,
        rtol,
        atol,
        ..Options::default()
    }
}

/// (allocations, steps, events) of a solve of the E1 ball with `opts`.
fn count(opts: &Options) -> (usize, usize, usize) {
    let ball = Ball::new();
    let p = ball.default_params();
    let before = allocations();
    let sol = solve(&ball, &p, opts).unwrap();
    let n = allocations() - before;
    (n, sol.stats.steps, sol.events.len())
}

#[test]
fn allocations_do_not_grow_with_steps() {
    for method in Method::ALL {
        // Same events (two impacts), very different step counts.
        let loose = opts(method, 1e-4, 1e-6);
        let tight = Options {
            sens_error_control: true,
            ..opts(method, 1e-12, 1e-14)
        };
        let (a_loose, s_loose, e_loose) = count(&loose);
        let (a_tight, s_tight, e_tight) = count(&tight);
        eprintln!("{method:?}: {a_loose} allocations");
        assert_eq!(e_loose, e_tight);
        assert!(s_tight > s_loose, "{s_tight} vs {s_loose} steps");
        assert_eq!(
            a_loose, a_tight,
            "{method:?}: {a_loose} allocations for {s_loose} steps, {a_tight} for {s_tight}"
        );
    }
}

#[test]
fn stepping_allocates_nothing_for_static_sizes() {
    // Restart, steps, dense output and truncation allocate nothing, with every method
    // (Rodas5P factorises W in place in buffers allocated by `Integrator::new`).
    let ball = Ball::new();
    let p = ball.default_params();
    for method in Method::ALL {
        let o = opts(method, 1e-10, 1e-10);
        let mut it = Integrator::new(&ball, &p, &o);
        let mut y0 = AugState::zeros(Const::<2>, Const::<4>);
        ball.initial_state(&p, &mut y0.x);
        ball.initial_state_jac(&p, &mut y0.s);
        let mut out = y0.clone();
        let mut xo = y0.x;
        let before = allocations();
        for _ in 0..3 {
            it.restart(0.0, &y0, 0, &mvad_runtime::Switches::default());
            while it.t() < 0.6 {
                it.step(0.6).unwrap();
                let tm = 0.5 * (it.t_prev() + it.t());
                it.dense(tm, &mut out);
                it.dense_x(tm, &mut xo);
            }
            let tc = 0.5 * (it.t_prev() + it.t());
            it.truncate(tc);
            it.step(0.6).unwrap();
        }
        let n = allocations() - before;
        if method == Method::Rosenbrock {
            assert!(it.stats().factorizations > 3, "{:?}", it.stats());
        }
        assert_eq!(n, 0, "{method:?}: {:?}", it.stats());
    }
}

#[test]
fn qp_solve_and_derivatives_allocate_nothing() {
    use mvad_runtime::qp::{ConstraintKind, QpData, QpOptions, QpSolver, Side};
    use nalgebra::{DMatrix, DVector};
    // min ½‖u − (θ, 1, −θ)‖² s.t. u₁ ≤ 0, u₃ ≥ 0, u₁ + u₂ + u₃ = 1: the first two constraints
    // are active for θ > 0, inactive for θ < 0 and weakly active (a kink) at θ = 0.
    let kinds = [ConstraintKind::Le, ConstraintKind::Le, ConstraintKind::Eq];
    let mut data = QpData {
        h: DMatrix::identity(3, 3),
        c: DVector::zeros(3),
        a: DMatrix::from_row_slice(3, 3, &[1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 1.0, 1.0, 1.0]),
        b: DVector::from_vec(vec![0.0, 0.0, 1.0]),
    };
    let mut dir = QpData::zeros(3, 3);
    dir.c[0] = -1.0;
    dir.c[2] = 1.0;
    let mut s = QpSolver::new(3, &kinds, QpOptions::default());
    let (mut du, mut dm) = ([0.0; 3], [0.0; 3]);
    let before = allocations();
    let mut kinks = 0;
    for theta in [-0.5, 0.0, 0.5, 0.0, -0.25] {
        data.c[0] = -theta;
        data.c[1] = -1.0;
        data.c[2] = theta;
        s.solve(&data).unwrap();
        kinks += usize::from(s.is_kink());
        for side in [Side::Left, Side::Right] {
            s.directional(&dir, side, &mut du, &mut dm).unwrap();
        }
    }
    assert_eq!(kinks, 2);
    assert_eq!(allocations() - before, 0);
}

#[test]
fn qp_bank_evaluations_and_switch_functions_allocate_nothing() {
    use mvad_runtime::qp::{ConstraintKind, QpBank, QpLayerInfo, QpOptions, Side};
    // The saturating controller u = argmin ½(u − kx − cv)² s.t. |u| ≤ umax of a cart with
    // state (x, v) and params (k, c, umax): data slots H, c, A (2×1), b; Jacobian columns
    // ∂/∂x, ∂/∂v, ∂/∂k, ∂/∂c, ∂/∂umax, ∂/∂t.
    let info = QpLayerInfo {
        name: "ctl".into(),
        vars: vec!["u".into()],
        kinds: vec![ConstraintKind::Le, ConstraintKind::Le],
        dynamic: true,
        switches: Some(0),
        events_before: Vec::new(),
        events_after: Vec::new(),
    };
    let mut bank = QpBank::new(vec![info], 2, 3, QpOptions::default());
    let fill = |x: &[f64], p: &[f64]| {
        let (xs, v, k, c, umax) = (x[0], x[1], p[0], p[1], p[2]);
        move |_q: usize, data: &mut [f64], jac: Option<&mut [f64]>| {
            data.copy_from_slice(&[1.0, -(k * xs + c * v), 1.0, -1.0, umax, umax]);
            if let Some(j) = jac {
                j.fill(0.0);
                // Row of slot 1 (c): ∂/∂x = −k, ∂/∂v = −c, ∂/∂k = −x, ∂/∂c = −v.
                j[6..10].copy_from_slice(&[-k, -c, -xs, -v]);
                // Slots 4 and 5 (b): ∂/∂umax = 1.
                j[4 * 6 + 4] = 1.0;
                j[5 * 6 + 4] = 1.0;
            }
        }
    };
    let p = [-2.0, -0.5, 1.0];
    let (mut gx, mut gp) = ([0.0; 2], [0.0; 3]);
    let mut sw = mvad_runtime::Switches::new(2);
    let before = allocations();
    for (i, x) in [[1.5, 0.0], [0.3, -0.2], [0.45, -0.1]].iter().enumerate() {
        assert!(bank.evaluate(0.0, x, &p, None, true, fill(x, &p)));
        sw.set(1, i == 0);
        assert!(bank.evaluate(0.0, x, &p, Some(&sw), true, fill(x, &p)));
        for j in 0..2 {
            let s = bank.switch_value(j, 0.0, x, &p, fill(x, &p));
            let (g, _) = bank.switch_grad(j, 0.0, x, &p, fill(x, &p), &mut gx, &mut gp);
            assert!(s.is_finite() && s == g);
        }
        bank.set_side(if i == 1 { Side::Left } else { Side::Right });
    }
    assert_eq!(allocations() - before, 0);
}
