//! Hand-written models for the runtime's own tests, independent of the `.hyb` front end.
//!
//! [`Ball`] is the seed paper's E1 bouncing ball: ḣ = v, v̇ = −g, event `impact` when
//! h ≤ 0 with v⁺ = −e v⁻, C = ∫₀ᵀ h dt, T = 2. Parameters θ = (e, g, h0, v0).

pub mod counting;

use crate::model::{
    At, AtOf, Direction, EventInfo, HybridModel, ModelAdjoint, ModelDims, ModelInfo,
    ModelSecondOrder, ModelSens, Occurrence, PointOf, Switches,
};
use nalgebra::{Const, OMatrix, OVector};

type N = Const<2>;
type P = Const<4>;
type X = OVector<f64, N>;
type Th = OVector<f64, P>;

/// The E1 bouncing ball, hand-coded (the reference the generated code must match).
#[derive(Clone, Debug)]
pub struct Ball {
    info: ModelInfo,
}

impl Default for Ball {
    fn default() -> Self {
        Self::new()
    }
}

impl Ball {
    /// Parameter indices.
    pub const E: usize = 0;
    /// g.
    pub const G: usize = 1;
    /// h0.
    pub const H0: usize = 2;
    /// v0.
    pub const V0: usize = 3;

    /// The E1 ball with horizon T = 2.
    pub fn new() -> Self {
        Ball {
            info: ModelInfo {
                name: "BouncingBall".into(),
                states: vec!["h".into(), "v".into()],
                params: vec!["e".into(), "g".into(), "h0".into(), "v0".into()],
                param_defaults: vec![0.8, 9.81, 2.0, 0.0],
                modes: vec!["main".into()],
                initial_mode: 0,
                events: vec![EventInfo {
                    name: "impact".into(),
                    direction: Direction::Down,
                    mode: None,
                    target: None,
                    has_reset: true,
                    has_cost: false,
                    trigger: crate::Trigger::Guard,
                }],
                observables: vec!["height".into(), "velocity".into()],
                switches: 0,
                has_running_cost: true,
                has_final_cost: false,
                has_horizon: true,
                jacobian_sparsity: vec![vec![(0, 1)]],
            },
        }
    }

    /// Default parameter vector (e, g, h0, v0) = (0.8, 9.81, 2, 0).
    pub fn default_params(&self) -> Th {
        Th::from_column_slice(&self.info.param_defaults)
    }
}

impl ModelSens for Ball {}
impl ModelAdjoint for Ball {}
impl ModelSecondOrder for Ball {}

impl ModelDims for Ball {
    type N = N;
    type P = P;
}

impl HybridModel for Ball {
    fn info(&self) -> &ModelInfo {
        &self.info
    }
    fn nstates(&self) -> N {
        Const
    }
    fn nparams(&self) -> P {
        Const
    }
    fn initial_state(&self, p: &Th, x0: &mut X) {
        x0[0] = p[2];
        x0[1] = p[3];
    }
    fn initial_state_jac(&self, _p: &Th, dx0: &mut OMatrix<f64, N, P>) {
        dx0.fill(0.0);
        dx0[(0, 2)] = 1.0;
        dx0[(1, 3)] = 1.0;
    }
    fn horizon(&self, _p: &Th) -> Option<f64> {
        Some(2.0)
    }
    fn horizon_grad(&self, _p: &Th, dt: &mut Th) {
        dt.fill(0.0);
    }
    fn rhs(&self, pt: PointOf<'_, Self>, f: &mut X) {
        f[0] = pt.x[1];
        f[1] = -pt.p[1];
    }
    fn rhs_jac_x(&self, _pt: PointOf<'_, Self>, fx: &mut OMatrix<f64, N, N>) {
        fx.fill(0.0);
        fx[(0, 1)] = 1.0;
    }
    fn rhs_jac_p(&self, _pt: PointOf<'_, Self>, fp: &mut OMatrix<f64, N, P>) {
        fp.fill(0.0);
        fp[(1, 1)] = -1.0;
    }
    fn rhs_dt(&self, _pt: PointOf<'_, Self>, ft: &mut X) {
        ft.fill(0.0);
    }
    fn rhs_depends_on_t(&self, _mode: usize) -> bool {
        false
    }
    fn guard(&self, _k: usize, at: AtOf<'_, Self>) -> f64 {
        let At { x, .. } = at;
        x[0]
    }
    fn guard_grad(&self, _k: usize, _at: AtOf<'_, Self>, gx: &mut X, gp: &mut Th) -> f64 {
        gx.fill(0.0);
        gx[0] = 1.0;
        gp.fill(0.0);
        0.0
    }
    fn reset(&self, _occ: Occurrence, at: AtOf<'_, Self>, xplus: &mut X) {
        let At { x, p, .. } = at;
        xplus[0] = x[0];
        xplus[1] = -p[0] * x[1];
    }
    fn reset_jac(
        &self,
        _occ: Occurrence,
        at: AtOf<'_, Self>,
        rx: &mut OMatrix<f64, N, N>,
        rp: &mut OMatrix<f64, N, P>,
        rt: &mut X,
    ) {
        let At { x, p, .. } = at;
        rx.fill(0.0);
        rx[(0, 0)] = 1.0;
        rx[(1, 1)] = -p[0];
        rp.fill(0.0);
        rp[(1, 0)] = -x[1];
        rt.fill(0.0);
    }
    fn switch_value(&self, _j: usize, _at: AtOf<'_, Self>) -> f64 {
        0.0
    }
    fn switch_grad(&self, _j: usize, _at: AtOf<'_, Self>, gx: &mut X, gp: &mut Th) -> f64 {
        zero_grad(gx, gp)
    }
    fn observe(&self, _sw: &Switches, at: AtOf<'_, Self>, y: &mut [f64]) {
        let At { x, .. } = at;
        y[0] = x[0];
        y[1] = x[1];
    }
    fn observe_jac(&self, _sw: &Switches, _at: AtOf<'_, Self>, yx: &mut [f64], yp: &mut [f64]) {
        yx.fill(0.0);
        yx[0] = 1.0; // ∂height/∂h
        yx[3] = 1.0; // ∂velocity/∂v
        yp.fill(0.0);
    }
    fn running_cost(&self, _sw: &Switches, at: AtOf<'_, Self>) -> f64 {
        let At { x, .. } = at;
        x[0]
    }
    fn running_cost_value_grad(
        &self,
        _sw: &Switches,
        at: AtOf<'_, Self>,
        lx: &mut X,
        lp: &mut Th,
    ) -> f64 {
        let At { x, .. } = at;
        lx.fill(0.0);
        lx[0] = 1.0;
        lp.fill(0.0);
        x[0]
    }
    fn event_cost(&self, _occ: Occurrence, _at: AtOf<'_, Self>) -> f64 {
        0.0
    }
    fn event_cost_grad(
        &self,
        _occ: Occurrence,
        _at: AtOf<'_, Self>,
        cx: &mut X,
        cp: &mut Th,
    ) -> f64 {
        zero_grad(cx, cp)
    }
    fn final_cost(&self, _at: AtOf<'_, Self>) -> f64 {
        0.0
    }
    fn final_cost_grad(&self, _at: AtOf<'_, Self>, cx: &mut X, cp: &mut Th) -> f64 {
        zero_grad(cx, cp)
    }
}

/// The gradient of a function that is identically zero: both parts zeroed, value 0.
fn zero_grad(gx: &mut X, gp: &mut Th) -> f64 {
    gx.fill(0.0);
    gp.fill(0.0);
    0.0
}
