//! The stiff relay (`models/stiff_relay.hyb`, τ = 1e-8, θ = (tau, rate, lo, hi), T = 3, three
//! switches) under `auto` (which runs Rodas5P: one factorisation of W = I − hγ f_x per
//! attempt) at rtol 1e-8, with the default atol:
//! - `relay_compiled_gradient`: the `hybrid!` model (static sizes), C and dC/dθ;
//! - `relay_loaded_gradient`: the same file loaded at run time (interpreted, `Dyn` sizes).
//!
//! For instruction counts (stable on a shared machine) run the bench binary under
//! `valgrind --tool=callgrind` with `RELAY_PROFILE=compiled|loaded`: it then runs 200
//! evaluations of that case only, without criterion, and prints the work counters.

use criterion::{criterion_group, Criterion};
use models::stiff_relay::{StiffRelay, StiffRelayParams};
use models::BothDoors;
use mvad::solution::Options;
use mvad::solve::solve;
use std::hint::black_box;

/// The relay through both doors (compiled and loaded, the same θ) and the options.
struct Relay {
    doors: BothDoors<StiffRelay, 4>,
    opts: Options,
}

fn setup() -> Relay {
    let p = StiffRelayParams::default().to_vector();
    Relay {
        doors: BothDoors::new(StiffRelay::new(), p, "stiff_relay.hyb"),
        opts: Options {
            rtol: 1e-8,
            ..Options::default()
        },
    }
}

fn relay(c: &mut Criterion) {
    let r = setup();
    c.bench_function("relay_compiled_gradient", |b| {
        b.iter(|| {
            solve(&r.doors.compiled, black_box(&r.doors.p), &r.opts)
                .unwrap()
                .gradient[0]
        })
    });
    c.bench_function("relay_loaded_gradient", |b| {
        b.iter(|| {
            solve(&r.doors.loaded, black_box(&r.doors.pl), &r.opts)
                .unwrap()
                .gradient[0]
        })
    });
}

criterion_group!(benches, relay);

fn main() {
    if let Ok(which) = std::env::var("RELAY_PROFILE") {
        let r = setup();
        let mut acc = 0.0;
        for i in 0..200 {
            let sol = if which == "compiled" {
                solve(&r.doors.compiled, black_box(&r.doors.p), &r.opts)
            } else {
                solve(&r.doors.loaded, black_box(&r.doors.pl), &r.opts)
            }
            .unwrap();
            if i == 0 {
                let s = &sol.stats;
                println!(
                    "{which}: steps {} rejected {} jac_evals {} factorizations {} cost {} gradient {:?}",
                    s.steps, s.rejected_steps, s.jac_evals, s.factorizations, sol.cost, sol.gradient
                );
            }
            acc += sol.cost;
        }
        black_box(acc);
        return;
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
