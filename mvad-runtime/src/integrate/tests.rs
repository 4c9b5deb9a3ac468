//! A non-finite stage is an error that names the flow (the schemes against closed forms,
//! forward and backward in time, are in `mvad-runtime/tests/integrate.rs`).

use super::{AugState, Integrator};
use crate::error::SolveError;
use crate::fixtures::Ball;
use crate::model::Switches;
use crate::solution::Options;
use nalgebra::Const;

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
        Err(SolveError::NonFinite { what, .. }) => {
            assert!(what.contains("flow of mode"), "{what}")
        }
        other => panic!("expected NonFinite, got {other:?}"),
    }
}
