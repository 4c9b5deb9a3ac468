//! Event handling beyond the closed-form matrix (`closed_forms.rs`): the measure against
//! dC/dθ and FD, exact zeros after resets, the trajectory, a parameter horizon with every
//! cost kind, a long Zeno run and its measure, primal-only runs, errors.
#![allow(clippy::needless_range_loop)] // index loops over params read clearer in tests

mod common;

use common::ball::{hops, phi, BallCost, BallSpec};
use common::check::{assert_grad, close, fd_opts, recorded, tight};
use common::{ev, info, AdModel, Sc, Spec, D};
use mvad_runtime::fixtures::Ball;
use mvad_runtime::measure::measure;
use mvad_runtime::model::{Direction, ModelInfo};
use mvad_runtime::solution::{DiagnosticKind, Options, Solution};
use mvad_runtime::solve::solve;
use nalgebra::DVector;

/// The E1 fixture ball solved at [`recorded`] options.
fn e1_recorded() -> (Ball, nalgebra::SVector<f64, 4>, Solution) {
    let ball = Ball::new();
    let p = ball.default_params();
    let sol = solve(&ball, &p, &recorded()).unwrap();
    (ball, p, sol)
}

/// d/dθ (h − h0) from the sensitivities `s` (column-major 2×4) of the fixture ball.
fn height_change(s: &[f64]) -> Vec<f64> {
    (0..4)
        .map(|j| s[2 * j] - if j == Ball::H0 { 1.0 } else { 0.0 })
        .collect()
}

/// The cumulative velocity measure μ_v([0, t]) is d/dθ ∫₀ᵗ v ds = d/dθ (h(t) − h0) =
/// S_h(t) − ∂h0/∂θ at every t (atoms included once their event has passed).
#[test]
fn cumulative_measure_of_velocity_is_the_height_sensitivity() {
    let (ball, p, sol) = e1_recorded();
    let mv = measure(&ball, &p, &sol, 1).unwrap();
    let traj = sol.trajectory.as_ref().unwrap();
    let ts = [0.0, 0.3, 0.638, 0.639, 1.2, 1.66, 1.661, 2.0];
    let cum = mv.cumulative(&ts);
    assert_eq!(cum.len(), ts.len());
    for (t, m) in ts.iter().zip(&cum) {
        let (_, s) = traj.sample(*t);
        assert_grad(&format!("t = {t}"), m, &height_change(&s), 1e-8, 1e-10);
    }
    let total = mv.pair(|_| 1.0);
    for j in 0..4 {
        assert!(close(cum[7][j], total[j], 1e-10, 1e-12));
    }
}

/// ⟨μ, 1⟩ on `height` equals dC/dθ for C = ∫h dt (E1, fixture), and the atoms are the
/// event records' atoms.
#[test]
fn measure_of_one_is_the_gradient_of_integral_h() {
    let (ball, p, sol) = e1_recorded();
    let mu = measure(&ball, &p, &sol, 0).unwrap();
    assert_eq!(mu.name, "height");
    assert_eq!(mu.atoms.len(), 2);
    let total = mu.pair(|_| 1.0);
    for j in 0..4 {
        assert!(
            close(total[j], sol.gradient[j], 1e-9, 1e-12),
            "param {j}: {} vs {}",
            total[j],
            sol.gradient[j]
        );
    }
    // Height atoms are zero (h is continuous); the density carries everything.
    assert!(mu.atoms.iter().all(|(_, a)| a.iter().all(|&v| v == 0.0)));
    // Velocity: d/dθ ∫ v dt = d/dθ (h(T) − h0), with atoms −J t'.
    let mv = measure(&ball, &p, &sol, 1).unwrap();
    let tv = mv.pair(|_| 1.0);
    let dens_only = mv.pair_density(|_| 1.0);
    let atoms: f64 = mv.atoms.iter().map(|(_, a)| a[0]).sum();
    assert!((tv[0] - dens_only[0] - atoms).abs() < 1e-12);
    // h(T) = sample of the trajectory; d h(T)/dθ = S_h(T) (horizon fixed), minus dh0/dθ.
    let traj = sol.trajectory.as_ref().unwrap();
    let (_, s) = traj.sample(2.0);
    assert_grad("⟨μ_v, 1⟩", &tv, &height_change(&s), 1e-8, 1e-10);
    assert!(measure(&ball, &p, &sol, 5).is_err());
    let unrecorded = solve(&ball, &p, &tight()).unwrap();
    assert!(measure(&ball, &p, &unrecorded, 0).is_err());
}

/// Ball with cost ∫ φ(t) h dt for a fixed test function φ: the exact gradient from the
/// run equals ⟨μ_height, φ⟩ and central differences of the cost.
#[test]
fn measure_paired_with_phi_matches_fd() {
    let m = AdModel::new(BallSpec::new(BallCost::Weighted, 2.0));
    let p = DVector::from_vec(vec![0.8, 9.81, 2.0, 0.3]);
    let opts = recorded();
    let sol = solve(&m, &p, &opts).unwrap();
    let mu = measure(&m, &p, &sol, 0).unwrap();
    let paired = mu.pair(phi);
    let fd_opts = fd_opts();
    for j in 0..4 {
        let fd = mvad_runtime::fd::fd_gradient(&m, &p, &fd_opts, j, 1e-5).unwrap();
        assert!(
            close(paired[j], sol.gradient[j], 1e-8, 1e-10),
            "param {j}: pair {} grad {}",
            paired[j],
            sol.gradient[j]
        );
        assert!(
            close(paired[j], fd, 1e-6, 1e-8),
            "param {j}: pair {} fd {fd}",
            paired[j]
        );
    }
    // Export on a grid: right-continuous density, finite everywhere.
    let grid: Vec<f64> = (0..=200).map(|i| 2.0 * i as f64 / 200.0).collect();
    let on = mu.on_grid(&grid);
    assert_eq!(on.len(), grid.len());
    assert!(on.iter().flatten().all(|v| v.is_finite()));
}

/// A ball launched from the floor at t = 0 (h0 = 0, v0 = 5), whose reset puts it *exactly*
/// on the floor (h⁺ = 0) or keeps h⁺ = h⁻.
fn floor_ball(land_on_zero: bool) -> BallSpec {
    BallSpec {
        land_on_zero,
        ..BallSpec::int_h(2.0, 0.8).defaults(&[0.8, 9.81, 0.0, 5.0])
    }
}

/// The zero guard neither re-triggers nor hides the next bounce.
#[test]
fn guard_exactly_zero_after_reset_and_at_start() {
    for exact_zero in [false, true] {
        let m = AdModel::new(floor_ball(exact_zero));
        let p = m.defaults();
        let sol = solve(&m, &p, &tight()).unwrap();
        // Launched from h = 0 with v0 = 5: hops of 2u/g with u = 5, 4, 3.2, ...
        let want = hops(0.8, 9.81, 5.0, 2.0);
        let got: Vec<f64> = sol.events.iter().map(|e| e.t).collect();
        assert_eq!(
            got.len(),
            want.len(),
            "exact_zero={exact_zero}: {got:?} vs {want:?}"
        );
        for (a, b) in got.iter().zip(&want) {
            assert!((a - b).abs() < 1e-12, "{got:?} vs {want:?}");
        }
        // Gradient against FD.
        let fd_opts = fd_opts();
        for j in [0, 1, 3] {
            let fd = mvad_runtime::fd::fd_gradient(&m, &p, &fd_opts, j, 1e-5).unwrap();
            assert!(
                close(sol.gradient[j], fd, 1e-6, 1e-8),
                "param {j}: {} vs fd {fd}",
                sol.gradient[j]
            );
        }
    }
    // A ball that starts exactly on the floor moving down bounces at t = 0.
    let m = AdModel::new(floor_ball(false));
    let p = DVector::from_vec(vec![0.8, 9.81, 0.0, -3.0]);
    let sol = solve(&m, &p, &tight()).unwrap();
    assert_eq!(sol.events[0].t, 0.0);
    assert!((sol.events[0].x_after[1] - 2.4).abs() < 1e-12);
    assert!(sol.x_final[0] >= -1e-9, "fell through: {:?}", sol.x_final);
}

/// A model that goes bad on purpose: ẋ = −1 from x = 1, and depending on `kind` a NaN in
/// the flow (√x in a second state), the guard (ln x) or the reset, or a chattering switch.
struct Sick {
    kind: u8,
}

impl Spec for Sick {
    fn info(&self) -> ModelInfo {
        let events = if self.kind == 1 || self.kind == 2 {
            vec![ev("e", Direction::Down, None, None, false)]
        } else {
            vec![]
        };
        let mut i = info(
            "Sick",
            &["x", "z"],
            &[("a", 1.0)],
            &["main"],
            events,
            &["x"],
            usize::from(self.kind == 3),
        );
        i.has_horizon = self.kind != 4;
        i
    }
    fn x0<S: Sc>(&self, p: &[S], x: &mut [S]) {
        x[0] = p[0];
        x[1] = S::cst(0.0);
    }
    fn horizon<S: Sc>(&self, _p: &[S]) -> Option<S> {
        (self.kind != 4).then(|| S::cst(2.0))
    }
    fn rhs<S: Sc>(&self, _m: usize, sw: u64, _t: S, x: &[S], _p: &[S], f: &mut [S]) {
        if self.kind == 3 {
            // ẋ = −sign(x): slides on x = 0 (chattering).
            f[0] = S::cst(if sw & 1 != 0 { -1.0 } else { 1.0 });
            f[1] = S::cst(0.0);
            return;
        }
        f[0] = S::cst(-1.0);
        f[1] = if self.kind == 0 {
            x[0].sqrt()
        } else {
            S::cst(0.0)
        };
    }
    fn guard<S: Sc>(&self, _k: usize, _t: S, x: &[S], _p: &[S]) -> S {
        if self.kind == 1 {
            x[0].ln() + 10.0
        } else {
            x[0] - 0.5
        }
    }
    fn reset<S: Sc>(&self, _k: usize, _t: S, x: &[S], _p: &[S], xp: &mut [S]) {
        xp[0] = x[0];
        xp[1] = if self.kind == 2 {
            (x[0] - 1.0).sqrt()
        } else {
            x[1]
        };
    }
    fn switch<S: Sc>(&self, _j: usize, _t: S, x: &[S], _p: &[S]) -> S {
        x[0]
    }
    fn running<S: Sc>(&self, _sw: u64, _t: S, x: &[S], _p: &[S]) -> S {
        x[0]
    }
}

#[test]
fn failures_are_errors_that_say_where() {
    use mvad_runtime::error::SolveError;
    let run = |kind: u8, opts: &Options| {
        let m = AdModel::new(Sick { kind });
        solve(&m, &m.defaults(), opts)
    };
    // √x of a negative x: the integrator shrinks the step at the NaN; either report stops
    // the run at t ≈ 1 (which one is the integrator's call).
    match run(0, &tight()) {
        Err(SolveError::NonFinite { t, what }) => assert!(
            what.contains("flow") && t > 0.9 && t <= 1.01,
            "{what} at {t}"
        ),
        Err(SolveError::StepSizeUnderflow { t, .. }) => assert!(t > 0.9 && t <= 1.01, "at {t}"),
        other => panic!("{other:?}"),
    }
    match run(1, &tight()) {
        Err(SolveError::NonFinite { t, what }) => assert!(
            what.contains("guard of event `e`") && t > 0.99,
            "{what} at {t}"
        ),
        other => panic!("{other:?}"),
    }
    match run(2, &tight()) {
        Err(e @ SolveError::NonFinite { .. }) => {
            assert!(e.to_string().contains("reset of event `e`"), "{e}");
            assert_eq!(e.diagnostic().unwrap().kind, DiagnosticKind::Nonfinite);
        }
        other => panic!("{other:?}"),
    }
    // Chattering on a switch: stopped by max_events (or by the step size), not a hang.
    match run(
        3,
        &Options {
            max_events: 1000,
            ..tight()
        },
    ) {
        Err(SolveError::MaxEvents { count, .. }) => assert_eq!(count, 1000),
        Err(SolveError::StepSizeUnderflow { .. }) => {}
        other => panic!("{other:?}"),
    }
    assert_eq!(run(4, &tight()).unwrap_err(), SolveError::NoHorizon);
    assert!(run(
        4,
        &Options {
            t_end: Some(1.5),
            ..tight()
        }
    )
    .is_ok());
    for t_end in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(matches!(
            run(
                0,
                &Options {
                    t_end: Some(t_end),
                    ..tight()
                }
            ),
            Err(SolveError::BadHorizon { .. })
        ));
    }
    assert!(matches!(
        run(
            0,
            &Options {
                rtol: 0.0,
                ..tight()
            }
        ),
        Err(SolveError::BadOption { .. })
    ));
    let m = AdModel::new(Sick { kind: 0 });
    assert!(matches!(
        solve(&m, &DVector::from_vec(vec![f64::NAN]), &tight()),
        Err(SolveError::BadParam { index: 0, .. })
    ));
    assert!(matches!(
        solve(&m, &DVector::from_vec(vec![1.0, 2.0]), &tight()),
        Err(SolveError::ParamCount {
            expected: 1,
            got: 2
        })
    ));
    // max_events on the fixture ball.
    let ball = Ball::new();
    let r = solve(
        &ball,
        &ball.default_params(),
        &Options {
            max_events: 1,
            ..tight()
        },
    );
    assert!(
        matches!(r, Err(SolveError::MaxEvents { count: 1, .. })),
        "{r:?}"
    );
}

/// The e = 0.8 ball run far past its accumulation time, and the measure of a Zeno run.
#[test]
fn zeno_ball_e08_long_horizon_and_its_measure() {
    let m = AdModel::new(BallSpec::int_h(10.0, 0.8));
    let p = m.defaults();
    let d = |i: usize| D::var(p[i], i);
    let (c, t_star) = common::ball::zeno_series(d(0), d(1), d(2), d(3));
    let opts = recorded();
    let sol = solve(&m, &p, &opts).unwrap();
    let z = sol.diagnostic(DiagnosticKind::Zeno).expect("zeno");
    assert!((z.t - t_star.v).abs() < 1e-6, "{} vs {}", z.t, t_star.v);
    assert!((sol.cost - c.v).abs() < 1e-6, "{} vs {}", sol.cost, c.v);
    for i in 0..4 {
        assert!(
            (sol.gradient[i] - c.g[i]).abs() < 1e-6,
            "θ{i}: {} vs {}",
            sol.gradient[i],
            c.g[i]
        );
    }
    // No grazing noise: the accumulation explains it.
    assert!(
        sol.diagnostic(DiagnosticKind::Grazing).is_none(),
        "{:?}",
        sol.diagnostics
    );
    // The trajectory ends with the ball at rest on the floor.
    let traj = sol.trajectory.as_ref().unwrap();
    // One segment per flight, then the rest; contiguous in time.
    assert_eq!(traj.segments.len(), sol.events.len() + 1);
    for w in traj.segments.windows(2) {
        assert_eq!(w[0].t_end, w[1].t_start);
        assert_eq!(w[0].end_step, w[1].first_step);
    }
    let (x, _) = traj.sample(9.0);
    assert!(x[0].abs() < 1e-9 && x[1].abs() < 1e-6, "{x:?}");
    let mu = measure(&m, &p, &sol, 0).unwrap();
    let total = mu.pair(|_| 1.0);
    for i in 0..4 {
        assert!(
            (total[i] - sol.gradient[i]).abs() < 1e-6,
            "θ{i}: {} vs {}",
            total[i],
            sol.gradient[i]
        );
    }
}

/// The recorded trajectory against the closed-form parabolas, right-continuous at impacts.
#[test]
fn trajectory_samples_match_closed_form() {
    let ball = Ball::new();
    let p = ball.default_params();
    let sol = solve(&ball, &p, &recorded()).unwrap();
    let traj = sol.trajectory.as_ref().unwrap();
    assert_eq!(traj.segments.len(), 3);
    assert_eq!(traj.step_times().last().copied(), Some(2.0));
    let g = 9.81;
    let t1 = (2.0f64 * 2.0 / g).sqrt();
    let u1 = 0.8 * g * t1;
    // Before the first impact: h = 2 − g t²/2, ∂h/∂h0 = 1, ∂v/∂g = −t.
    for &t in &[0.1, 0.3, 0.6] {
        let (x, s) = traj.sample(t);
        assert!((x[0] - (2.0 - g * t * t / 2.0)).abs() < 1e-10);
        assert!((s[2 * Ball::H0] - 1.0).abs() < 1e-10);
        assert!((s[2 * Ball::G + 1] + t).abs() < 1e-10);
    }
    // Exactly at the impact: the post-impact state (v = +u1).
    let te = sol.events[0].t;
    let (x, _) = traj.sample(te);
    assert!((x[1] - u1).abs() < 1e-9, "{x:?}");
    let (x, _) = traj.sample(te + 0.2);
    assert!((x[0] - (u1 * 0.2 - g * 0.04 / 2.0)).abs() < 1e-9);
}

/// A parameter-dependent horizon T = θ_T and a final cost Φ = h(T)·v(T): the terms
/// (ℓ(T) + Φ_x f(T) + Φ_t) dT/dθ, checked against central differences.
#[test]
fn parameter_dependent_horizon_and_all_cost_kinds_vs_fd() {
    let m = AdModel::new(BallSpec::param_horizon());
    let p = m.defaults();
    let sol = solve(&m, &p, &tight()).unwrap();
    assert_eq!(sol.events.len(), 2);
    assert_eq!(sol.t_end, 1.9);
    let fd_opts = fd_opts();
    let fd = mvad_runtime::fd::fd_full_gradient(&m, &p, &fd_opts, 1e-5).unwrap();
    for j in 0..4 {
        assert!(
            close(sol.gradient[j], fd[j], 1e-6, 1e-8),
            "θ{j}: {} vs fd {}",
            sol.gradient[j],
            fd[j]
        );
    }
    // The override of the horizon drops dT/dθ.
    let fixed = solve(
        &m,
        &p,
        &Options {
            t_end: Some(1.9),
            ..tight()
        },
    )
    .unwrap();
    assert!((fixed.cost - sol.cost).abs() < 1e-12);
    assert!((fixed.gradient[3]).abs() < 1e-12);
    assert!((sol.gradient[3] - fixed.gradient[3]).abs() > 1e-3);
}

/// A primal-only run of the ball: no gradient, the same events and cost. (The model
/// without parameters is a case of the closed-form matrix.)
#[test]
fn primal_only_run_of_the_ball() {
    let ball = Ball::new();
    let p = ball.default_params();
    let primal = solve(
        &ball,
        &p,
        &Options {
            sensitivities: false,
            ..tight()
        },
    )
    .unwrap();
    let full = solve(&ball, &p, &tight()).unwrap();
    assert!(primal.gradient.is_empty() && primal.events[0].dt.is_empty());
    assert_eq!(primal.events.len(), 2);
    assert!((primal.cost - full.cost).abs() < 1e-12);
}
