//! Stepping backwards in time: every scheme, from T down to 0, against the closed form and
//! against the forward run.

use super::{AugState, Integrator, StepError};
use crate::fixtures::Ball;
use crate::model::{
    HybridModel, ModelAdjoint, ModelDims, ModelInfo, ModelSecondOrder, ModelSens, Point, Switches,
};
use crate::solution::{Method, Options};
use nalgebra::{Const, OMatrix, OVector};

type N = Const<1>;
type P = Const<1>;
type X = OVector<f64, N>;
type Th = OVector<f64, P>;

/// ẋ = −a x, ℓ = x, θ = (a): x = x₀e^(−at), S = −t x, q = x₀(1 − e^(−at))/a,
/// q_θ = x₀(t e^(−at)/a − (1 − e^(−at))/a²).
struct Decay {
    info: ModelInfo,
}

const X0: f64 = 1.3;

fn exact(a: f64, t: f64) -> [f64; 4] {
    let e = (-a * t).exp();
    let x = X0 * e;
    [
        x,
        -t * x,
        X0 * (1.0 - e) / a,
        X0 * (t * e / a - (1.0 - e) / (a * a)),
    ]
}

fn state(v: [f64; 4]) -> AugState<N, P> {
    let mut y = AugState::zeros(Const::<1>, Const::<1>);
    (y.x[0], y.s[(0, 0)], y.q, y.qp[0]) = (v[0], v[1], v[2], v[3]);
    y
}

fn parts(y: &AugState<N, P>) -> [f64; 4] {
    [y.x[0], y.s[(0, 0)], y.q, y.qp[0]]
}

impl ModelSens for Decay {}
impl ModelAdjoint for Decay {}
impl ModelSecondOrder for Decay {}

impl ModelDims for Decay {
    type N = N;
    type P = P;
}

impl HybridModel for Decay {
    fn info(&self) -> &ModelInfo {
        &self.info
    }
    fn nstates(&self) -> N {
        Const
    }
    fn nparams(&self) -> P {
        Const
    }
    fn initial_state(&self, _p: &Th, x0: &mut X) {
        x0[0] = X0;
    }
    fn initial_state_jac(&self, _p: &Th, dx0: &mut OMatrix<f64, N, P>) {
        dx0.fill(0.0);
    }
    fn horizon(&self, _p: &Th) -> Option<f64> {
        Some(2.0)
    }
    fn horizon_grad(&self, _p: &Th, dt: &mut Th) {
        dt.fill(0.0);
    }
    fn rhs(&self, pt: Point<'_, Self::N, Self::P>, f: &mut X) {
        let Point {
            mode: _m,
            sw: _sw,
            t: _t,
            x,
            p,
        } = pt;
        f[0] = -p[0] * x[0];
    }
    fn rhs_jac_x(&self, pt: Point<'_, Self::N, Self::P>, fx: &mut OMatrix<f64, N, N>) {
        let Point {
            mode: _m,
            sw: _sw,
            t: _t,
            x: _x,
            p,
        } = pt;
        fx[(0, 0)] = -p[0];
    }
    fn rhs_jac_p(&self, pt: Point<'_, Self::N, Self::P>, fp: &mut OMatrix<f64, N, P>) {
        let Point {
            mode: _m,
            sw: _sw,
            t: _t,
            x,
            p: _p,
        } = pt;
        fp[(0, 0)] = -x[0];
    }
    fn rhs_dt(&self, pt: Point<'_, Self::N, Self::P>, ft: &mut X) {
        let Point {
            mode: _m,
            sw: _sw,
            t: _t,
            x: _x,
            p: _p,
        } = pt;
        ft.fill(0.0);
    }
    fn rhs_depends_on_t(&self, _mode: usize) -> bool {
        false
    }
    fn guard(&self, _k: usize, _t: f64, _x: &X, _p: &Th) -> f64 {
        1.0
    }
    fn guard_grad(&self, _k: usize, _t: f64, _x: &X, _p: &Th, gx: &mut X, gp: &mut Th) -> f64 {
        gx.fill(0.0);
        gp.fill(0.0);
        0.0
    }
    fn reset(&self, _k: usize, _j: usize, _t: f64, x: &X, _p: &Th, xplus: &mut X) {
        xplus.copy_from(x);
    }
    fn reset_jac(
        &self,
        _k: usize,
        _j: usize,
        _t: f64,
        _x: &X,
        _p: &Th,
        rx: &mut OMatrix<f64, N, N>,
        rp: &mut OMatrix<f64, N, P>,
        rt: &mut X,
    ) {
        rx.fill(1.0);
        rp.fill(0.0);
        rt.fill(0.0);
    }
    fn switch_value(&self, _j: usize, _t: f64, _x: &X, _p: &Th) -> f64 {
        0.0
    }
    fn switch_grad(&self, _j: usize, _t: f64, _x: &X, _p: &Th, gx: &mut X, gp: &mut Th) -> f64 {
        gx.fill(0.0);
        gp.fill(0.0);
        0.0
    }
    fn observe(&self, _t: f64, _x: &X, _p: &Th, _y: &mut [f64]) {}
    fn observe_jac(&self, _t: f64, _x: &X, _p: &Th, _yx: &mut [f64], _yp: &mut [f64]) {}
    fn running_cost(&self, _sw: &Switches, _t: f64, x: &X, _p: &Th) -> f64 {
        x[0]
    }
    fn running_cost_value_grad(
        &self,
        _sw: &Switches,
        _t: f64,
        x: &X,
        _p: &Th,
        lx: &mut X,
        lp: &mut Th,
    ) -> f64 {
        lx[0] = 1.0;
        lp.fill(0.0);
        x[0]
    }
    fn event_cost(&self, _k: usize, _j: usize, _t: f64, _x: &X, _p: &Th) -> f64 {
        0.0
    }
    fn event_cost_grad(
        &self,
        _k: usize,
        _j: usize,
        _t: f64,
        _x: &X,
        _p: &Th,
        cx: &mut X,
        cp: &mut Th,
    ) -> f64 {
        cx.fill(0.0);
        cp.fill(0.0);
        0.0
    }
    fn final_cost(&self, _t: f64, _x: &X, _p: &Th) -> f64 {
        0.0
    }
    fn final_cost_grad(&self, _t: f64, _x: &X, _p: &Th, cx: &mut X, cp: &mut Th) -> f64 {
        cx.fill(0.0);
        cp.fill(0.0);
        0.0
    }
}

fn decay() -> Decay {
    Decay {
        info: ModelInfo {
            name: "Decay".into(),
            states: vec!["x".into()],
            params: vec!["a".into()],
            param_defaults: vec![1.5],
            modes: vec!["main".into()],
            initial_mode: 0,
            events: vec![],
            observables: vec![],
            switches: 0,
            has_running_cost: true,
            has_final_cost: false,
            has_horizon: true,
            jacobian_sparsity: vec![vec![(0, 0)]],
        },
    }
}

/// |got − want| ≤ tol·max(1, |want|), part by part.
fn assert_close(got: [f64; 4], want: [f64; 4], tol: f64, what: &str) {
    for (i, (g, w)) in got.iter().zip(&want).enumerate() {
        assert!(
            (g - w).abs() <= tol * w.abs().max(1.0),
            "{what}, part {i}: {g} vs {w}"
        );
    }
}

#[test]
fn backward_steps_match_the_closed_form_and_the_forward_run() {
    let m = decay();
    let a = 1.5;
    let p = Th::from_element(a);
    let t_end = 2.0;
    let tol = 1e-7;
    for method in Method::ALL {
        let opts = Options {
            method,
            rtol: 1e-10,
            atol: 1e-12,
            ..Options::default()
        };
        // Forward 0 → T, then backward T → 0 from the exact end state.
        let mut fwd = Integrator::new(&m, &p, &opts);
        fwd.restart(0.0, &state(exact(a, 0.0)), 0, &Switches::default());
        while fwd.t() < t_end {
            fwd.step(t_end).unwrap();
        }
        assert_close(parts(fwd.y()), exact(a, t_end), tol, "forward end");
        let mut bwd = Integrator::new(&m, &p, &opts);
        bwd.restart(t_end, &state(exact(a, t_end)), 0, &Switches::default());
        let mut mid = AugState::zeros(Const::<1>, Const::<1>);
        let mut seen_mid = false;
        while bwd.t() > 0.0 {
            bwd.step(0.0).unwrap();
            assert!(bwd.t() < bwd.t_prev() && bwd.last_step_size() < 0.0);
            // Dense output between t and t_prev of a backward step.
            if bwd.t() <= 1.0 && 1.0 <= bwd.t_prev() {
                bwd.dense(1.0, &mut mid);
                assert_close(parts(&mid), exact(a, 1.0), tol, "backward dense output");
                let mut x = X::zeros();
                bwd.dense_x(1.0, &mut x);
                assert_eq!(x[0], mid.x[0]);
                seen_mid = true;
            }
        }
        assert!(seen_mid);
        assert_eq!(bwd.t(), 0.0);
        assert_close(
            parts(bwd.y()),
            exact(a, 0.0),
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
        bwd.restart(t_end, &state(exact(a, t_end)), 0, &Switches::default());
        bwd.step(0.0).unwrap();
        let cut = 0.5 * (bwd.t() + bwd.t_prev());
        bwd.dense(cut, &mut mid);
        bwd.truncate(cut);
        assert_eq!(bwd.t(), cut);
        assert_eq!(parts(bwd.y()), parts(&mid));
        // Fixed steps: h = −T/n from T reaches 0 and the same end.
        bwd.restart(t_end, &state(exact(a, t_end)), 0, &Switches::default());
        for _ in 0..400 {
            bwd.step_fixed(-t_end / 400.0).unwrap();
        }
        assert_close(
            parts(bwd.y()),
            exact(a, 0.0),
            1e-6,
            &format!("{method:?} fixed steps"),
        );
        assert!(matches!(
            bwd.step_fixed(0.0),
            Err(StepError::StepSizeUnderflow { .. })
        ));
    }
}

#[test]
fn nonfinite_start_is_an_error() {
    let ball = Ball::new();
    let mut p = ball.default_params();
    p[1] = f64::NAN;
    let opts = Options::default();
    let mut it = Integrator::new(&ball, &p, &opts);
    let mut y = AugState::zeros(Const::<2>, Const::<4>);
    y.x[0] = 2.0;
    it.restart(0.0, &y, 0, &Switches::default());
    match it.step(1.0) {
        Err(StepError::NonFinite { what, .. }) => {
            assert!(what.contains("flow of mode"), "{what}")
        }
        other => panic!("expected NonFinite, got {other:?}"),
    }
}
