//! Adjoint mode against forward mode and closed forms.

mod common;

use common::ball::{BallCost, BallSpec};
use common::AdModel;
use mvad_runtime::solution::{GradientMode, Options};
use mvad_runtime::solve::solve;

#[test]
fn smoke_e1() {
    let m = AdModel::new(BallSpec::new(BallCost::IntH, 2.0));
    let p = m.defaults();
    let o = Options { rtol: 1e-12, atol: 1e-14, ..Options::default() };
    let f = solve(&m, &p, &o).unwrap();
    let a = solve(&m, &p, &Options { gradient_mode: GradientMode::Adjoint, ..o.clone() }).unwrap();
    println!("fwd {:?}\nadj {:?}\n{:?}", f.gradient, a.gradient, a.stats);
    println!("events {}", a.events.len());
}
