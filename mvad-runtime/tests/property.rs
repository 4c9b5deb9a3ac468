//! Property test: randomly drawn smooth models with events (a forced, damped oscillator
//! hitting a wall) — the driver's gradient against central finite differences.
#![allow(clippy::needless_range_loop)] // index loops over params read clearer in tests

mod common;

use common::{ev, info, AdModel, Sc, Spec};
use mvad_runtime::fd::fd_full_gradient;
use mvad_runtime::model::{Direction, ModelInfo};
use mvad_runtime::solution::{DiagnosticKind, Options};
use mvad_runtime::solve::solve;
use nalgebra::DVector;
use proptest::prelude::*;

/// ẋ0 = x1, ẋ1 = −k x0 − d x1 + u sin(ω t); event `hit` when x0 ≥ c: x1 ← −r x1 (Up);
/// C = ∫ (x0² + q x1) dt + Σ_hit x1² + x0(T). θ = (k, d, u, c, r); ω, q, v0, T fixed per case.
struct Wall {
    /// Moving wall: guard x0 − c − 0.2 sin(t) and reset x1 ← −r x1 + 0.3 r cos(t) (g_t, R_t ≠ 0).
    moving: bool,
    omega: f64,
    q: f64,
    v0: f64,
    t_end: f64,
    defaults: [f64; 5],
}

impl Spec for Wall {
    fn info(&self) -> ModelInfo {
        let names = ["k", "d", "u", "c", "r"];
        let params: Vec<(&str, f64)> = names.iter().copied().zip(self.defaults).collect();
        let mut i = info(
            "Wall",
            &["x0", "x1"],
            &params,
            &["main"],
            vec![ev("hit", Direction::Up, None, None, true)],
            &["x0"],
            0,
        );
        i.has_final_cost = true;
        i
    }
    fn x0<S: Sc>(&self, _p: &[S], x: &mut [S]) {
        x[0] = S::cst(0.0);
        x[1] = S::cst(self.v0);
    }
    fn horizon<S: Sc>(&self, _p: &[S]) -> Option<S> {
        Some(S::cst(self.t_end))
    }
    fn rhs<S: Sc>(&self, _m: usize, _sw: u64, t: S, x: &[S], p: &[S], f: &mut [S]) {
        f[0] = x[1];
        f[1] = -(p[0] * x[0]) - p[1] * x[1] + p[2] * (t * self.omega).sin();
    }
    fn guard<S: Sc>(&self, _k: usize, t: S, x: &[S], p: &[S]) -> S {
        if self.moving {
            x[0] - p[3] - t.sin() * 0.2
        } else {
            x[0] - p[3]
        }
    }
    fn reset<S: Sc>(&self, _k: usize, t: S, x: &[S], p: &[S], xp: &mut [S]) {
        xp[0] = x[0];
        xp[1] = -(p[4] * x[1]);
        if self.moving {
            xp[1] = xp[1] + p[4] * t.cos() * 0.3;
        }
    }
    fn observe<S: Sc>(&self, _t: S, x: &[S], _p: &[S], y: &mut [S]) {
        y[0] = x[0];
    }
    fn running<S: Sc>(&self, _sw: u64, _t: S, x: &[S], _p: &[S]) -> S {
        x[0] * x[0] + x[1] * self.q
    }
    fn event_cost<S: Sc>(&self, _k: usize, _t: S, x: &[S], _p: &[S]) -> S {
        x[1] * x[1]
    }
    fn final_cost<S: Sc>(&self, _t: S, x: &[S], _p: &[S]) -> S {
        x[0]
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, .. ProptestConfig::default() })]
    #[test]
    fn random_wall_models_match_fd(
        k in 1.0..4.0f64, d in 0.0..0.5f64, u in 0.0..1.0f64, c in 0.2..0.6f64, r in 0.3..0.9f64,
        omega in 0.5..3.0f64, q in -1.0..1.0f64, v0 in 1.5..2.5f64, t_end in 2.0..5.0f64,
        moving in proptest::bool::ANY,
    ) {
        let spec = Wall { moving, omega, q, v0, t_end, defaults: [k, d, u, c, r] };
        let m = AdModel::new(spec);
        let p = m.defaults();
        let opts = Options { rtol: 1e-11, atol: 1e-13, ..Options::default() };
        let sol = solve(&m, &p, &opts).unwrap();
        // Skip draws where FD is not meaningful: grazing impacts or an event within reach
        // of the horizon (the FD perturbation would add or remove it).
        prop_assume!(sol.diagnostic(DiagnosticKind::Grazing).is_none());
        prop_assume!(sol.events.iter().all(|e| (e.t - t_end).abs() > 1e-3 && e.guard_slope.abs() > 1e-2));
        // Central differences at three relative steps: near a steep but transversal impact
        // (guard slope 0.017) the truncation error of FD at 1e-6 alone is 3e-5 relative
        // (dC/dc 204.65886 against FD 50.7, 201.8, 205.37, 204.66589, 204.658924 at steps
        // 1e-3 … 1e-7), so the gradient must agree with FD at one of the steps.
        let fds: Vec<Vec<f64>> = [1e-5, 1e-6, 1e-7]
            .iter()
            .map(|&h| fd_full_gradient(&m, &p, &opts, h).unwrap())
            .collect();
        for j in 0..5 {
            let a = sol.gradient[j];
            let agrees = |b: f64| (a - b).abs() <= 1e-5 * a.abs().max(b.abs()) + 1e-6;
            prop_assert!(fds.iter().any(|fd| agrees(fd[j])),
                "param {}: mvad {} fd {:?} ({} events)", j, a,
                fds.iter().map(|fd| fd[j]).collect::<Vec<_>>(), sol.events.len());
        }
    }
}

#[test]
fn wall_model_has_events() {
    // The property above is not vacuous: the default draw hits the wall.
    let m = AdModel::new(Wall {
        moving: true,
        omega: 1.0,
        q: 0.5,
        v0: 2.0,
        t_end: 4.0,
        defaults: [2.0, 0.1, 0.5, 0.4, 0.7],
    });
    let sol = solve(&m, &m.defaults(), &Options::default()).unwrap();
    assert!(sol.events.len() >= 2, "{}", sol.events.len());
    let _ = DVector::<f64>::zeros(1);
}
