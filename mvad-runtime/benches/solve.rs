//! The E1 bouncing ball (fixtures::Ball, compiled sizes) at rtol 1e-10: the full gradient
//! w.r.t. its four parameters and the primal simulation alone. Targets: ≤ 10 µs per
//! gradient and ≤ 3× the primal.

use criterion::{criterion_group, criterion_main, Criterion};
use mvad_runtime::fixtures::Ball;
use mvad_runtime::solution::Options;
use mvad_runtime::solve::solve;
use std::hint::black_box;

fn e1(c: &mut Criterion) {
    let ball = Ball::new();
    let p = ball.default_params();
    let grad = Options {
        rtol: 1e-10,
        atol: 1e-12,
        ..Options::default()
    };
    let primal = Options {
        sensitivities: false,
        ..grad.clone()
    };
    c.bench_function("e1_gradient_rtol1e-10", |b| {
        b.iter(|| {
            solve(black_box(&ball), black_box(&p), &grad)
                .unwrap()
                .gradient[0]
        })
    });
    c.bench_function("e1_primal_rtol1e-10", |b| {
        b.iter(|| {
            solve(black_box(&ball), black_box(&p), &primal)
                .unwrap()
                .cost
        })
    });
}

criterion_group!(benches, e1);
criterion_main!(benches);
