//! Integrator benchmarks: Tsit5 over the first flight of the E1 ball, [0, 0.6], at
//! rtol = atol = 1e-10, primal alone and with the 2×4 sensitivities and the ∫h quadrature.

use criterion::{criterion_group, criterion_main, Criterion};
use mvad_runtime::fixtures::Ball;
use mvad_runtime::integrate::{AugState, Integrator};
use mvad_runtime::solution::{Method, Options};
use mvad_runtime::HybridModel;
use nalgebra::Const;
use std::hint::black_box;

fn flight(ball: &Ball, sensitivities: bool, method: Method) -> f64 {
    let p = ball.default_params();
    let opts = Options {
        method,
        rtol: 1e-10,
        atol: 1e-10,
        sensitivities,
        ..Options::default()
    };
    let mut y0 = AugState::zeros(Const::<2>, Const::<4>);
    ball.initial_state(&p, &mut y0.x);
    ball.initial_state_jac(&p, &mut y0.s);
    let mut it = Integrator::new(ball, &p, &opts);
    it.restart(0.0, &y0, 0, &mvad_runtime::Switches::default());
    while it.t() < 0.6 {
        it.step(0.6).expect("ball flight");
    }
    it.y().x[0] + it.y().s[(0, 1)] + it.y().q
}

fn bench(c: &mut Criterion) {
    let ball = Ball::new();
    c.bench_function("tsit5_ball_flight_primal", |b| {
        b.iter(|| flight(black_box(&ball), false, Method::Tsit5))
    });
    c.bench_function("tsit5_ball_flight_sens", |b| {
        b.iter(|| flight(black_box(&ball), true, Method::Tsit5))
    });
    c.bench_function("verner9_ball_flight_sens", |b| {
        b.iter(|| flight(black_box(&ball), true, Method::Verner9))
    });
    c.bench_function("rodas5p_ball_flight_sens", |b| {
        b.iter(|| flight(black_box(&ball), true, Method::Rosenbrock))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
