//! E3 (the parametric QP min ½u² − θu s.t. u ≥ 0, J = ½u*², `models/qp_kink.hyb` compiled by
//! `hybrid!`): the cost of one point of the paper's 101-point sweep.
//!
//! - `e3_point_layer`: what a point costs the qp layer — the compiled model's `final_cost`
//!   and `final_cost_grad` (the qp's data written by generated code, the qp solved, du*/dθ
//!   from the KKT system: solved once, the second call hits the point's cache) and the kink
//!   test (`qp_kink`: is a constraint weakly active).
//! - `e3_point_solve`: a whole `mvad::solve` of the model at θ, as `mvad sweep` runs it
//!   (validation, the timeless run, C and dC/dθ, the qps' report with the kink test and, at
//!   the kink, the second run for the derivative from the left).
//!
//! The points cycle through the 101 values θ = (i − 50)/50, so the per-point cache of the
//! qp layer never answers. Target (issue 9): one point of the layer ≤ 1 µs. The medians are
//! printed after the criterion runs.

use criterion::{criterion_group, Criterion};
use models::qp_kink::QpKink;
use mvad::solution::Options;
use mvad::solve::solve;
use mvad::{At, HybridModel};
use nalgebra::SVector;
use std::hint::black_box;

use models::median_us;

/// The 101 parameter vectors of the sweep.
fn thetas() -> Vec<SVector<f64, 1>> {
    (0..=100)
        .map(|i| SVector::<f64, 1>::new((i as f64 - 50.0) / 50.0))
        .collect()
}

fn e3(c: &mut Criterion) {
    let model = QpKink::new();
    let points = thetas();
    let opts = Options::default();
    let x = SVector::<f64, 0>::zeros();

    // The layer: J, dJ/dθ and whether the point is a kink.
    let mut i = 0;
    let mut point_layer = || {
        let p = &points[i % points.len()];
        i += 1;
        let (mut cx, mut cp) = (SVector::<f64, 0>::zeros(), SVector::<f64, 1>::zeros());
        let j = model.final_cost(At::new(0.0, &x, black_box(p)));
        model.final_cost_grad(At::new(0.0, &x, p), &mut cx, &mut cp);
        let kink = model.qp_kink();
        (j, cp[0], kink)
    };
    c.bench_function("e3_point_layer", |b| b.iter(&mut point_layer));

    let mut k = 0;
    let mut point_solve = || {
        let p = &points[k % points.len()];
        k += 1;
        let sol = solve(&model, black_box(p), &opts).expect("E3 solves");
        (sol.cost, sol.gradient[0], sol.diagnostics.len())
    };
    c.bench_function("e3_point_solve", |b| b.iter(&mut point_solve));

    let layer = median_us(&mut point_layer);
    let whole = median_us(&mut point_solve);
    println!(
        "E3 medians per sweep point: qp layer {:.3} µs (target ≤ 1 µs: {}), whole solve {:.3} µs",
        layer,
        layer <= 1.0,
        whole
    );
}

criterion_group!(benches, e3);

fn main() {
    // Under `valgrind --tool=callgrind`: E3_PROFILE=layer|solve runs 10 000 points of that
    // case only (instruction counts are stable on a loaded machine; timings are not);
    // E3_POINTS=N changes the count, and the mean time per point is printed.
    if let Ok(which) = std::env::var("E3_PROFILE") {
        let model = QpKink::new();
        let points = thetas();
        let x = SVector::<f64, 0>::zeros();
        let count: usize = std::env::var("E3_POINTS")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(10_000);
        let start = std::time::Instant::now();
        let mut acc = 0.0;
        for i in 0..count {
            let p = &points[i % points.len()];
            acc += if which == "layer" {
                let (mut cx, mut cp) = (SVector::<f64, 0>::zeros(), SVector::<f64, 1>::zeros());
                model.final_cost(At::new(0.0, &x, black_box(p)))
                    + model.final_cost_grad(At::new(0.0, &x, p), &mut cx, &mut cp)
                    + cp[0]
                    + model.qp_kink().map_or(0.0, |_| 1.0)
            } else {
                solve(&model, black_box(p), &Options::default())
                    .expect("E3 solves")
                    .gradient[0]
            };
        }
        black_box(acc);
        println!(
            "{which}: {count} points, {:.3} µs per point",
            start.elapsed().as_secs_f64() * 1e6 / count as f64
        );
        return;
    }
    benches();
    criterion::Criterion::default()
        .configure_from_args()
        .final_summary();
}
