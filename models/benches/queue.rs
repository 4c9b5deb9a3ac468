//! E4 at 10⁶ customers (data in memory, seed 1, μ = 1.25): C and dC/dμ of the compiled queue
//! (`models/queue.hyb` through `hybrid!`, streaming: the `()` sink keeps no event) against the
//! hand-written Lindley-IPA loop, in the same criterion run.
//!
//! Targets (issue 10): the compiled model at most 5× the Lindley loop (aim 3×) and under
//! 17 ms. After criterion, the ratio is printed from a separate timing loop (median of 5).
//! `QUEUE_N` overrides the number of customers.
//!
//! For instruction counts (stable on a shared machine) run the bench binary under
//! `valgrind --tool=callgrind` with `QUEUE_PROFILE=compiled|loaded|lindley`: it then runs that
//! case once at `QUEUE_N` customers, without criterion, and prints C and dC/dμ.

use criterion::{criterion_group, Criterion};
use models::queue::{self, Arrivals};
use mvad::solution::Options;
use mvad::solve::solve_with;
use std::hint::black_box;
use std::time::Instant;

fn customers() -> usize {
    std::env::var("QUEUE_N")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1_000_000)
}

struct Setup {
    arrivals: Arrivals,
    model: queue::Queue,
    p: nalgebra::SVector<f64, 1>,
    opts: Options,
}

fn setup() -> Setup {
    let arrivals = Arrivals::generate(customers(), 1);
    let model = queue::Queue::new(queue::QueueTables {
        arrivals: arrivals.table().expect("table"),
    })
    .expect("binds");
    Setup {
        arrivals,
        model,
        p: nalgebra::SVector::<f64, 1>::new(1.25),
        opts: Options::default(),
    }
}

fn compiled(s: &Setup) -> (f64, f64) {
    let sol = solve_with(&s.model, &s.p, &s.opts, &mut ()).expect("runs");
    (sol.cost, sol.gradient[0])
}

fn lindley(s: &Setup) -> (f64, f64) {
    let (c, g, _) = queue::lindley_ipa(&s.arrivals.t, &s.arrivals.s, 1.25, 1.0);
    (c, g)
}

fn median_s(mut f: impl FnMut()) -> f64 {
    let mut v: Vec<f64> = (0..5)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .collect();
    v.sort_by(f64::total_cmp);
    v[2]
}

fn bench(c: &mut Criterion) {
    let s = setup();
    let mut g = c.benchmark_group("queue");
    g.sample_size(10);
    g.bench_function("lindley_ipa", |b| b.iter(|| black_box(lindley(&s))));
    g.bench_function("compiled_grad", |b| b.iter(|| black_box(compiled(&s))));
    g.finish();
}

criterion_group!(benches, bench);

/// One run of the case `which` (`compiled`, `loaded` or `lindley`), for callgrind.
fn profile(which: &str) {
    let s = setup();
    let (c, g) = match which {
        "compiled" => compiled(&s),
        "lindley" => lindley(&s),
        _ => {
            let mut loaded =
                mvad::interp::InterpretedModel::from_source(include_str!("../queue.hyb"))
                    .expect("model");
            loaded
                .bind_tables(&[&s.arrivals.table().expect("table")])
                .expect("binds");
            let p = nalgebra::DVector::from_vec(vec![1.25]);
            let sol = solve_with(&loaded, black_box(&p), &s.opts, &mut ()).expect("runs");
            (sol.cost, sol.gradient[0])
        }
    };
    println!("{which}, {} customers: C {c}, dC/dμ {g}", customers());
}

fn main() {
    if let Ok(which) = std::env::var("QUEUE_PROFILE") {
        profile(&which);
        return;
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
    let s = setup();
    let (c, g) = compiled(&s);
    let (cl, gl) = lindley(&s);
    let tl = median_s(|| {
        black_box(lindley(&s));
    });
    let tc = median_s(|| {
        black_box(compiled(&s));
    });
    println!(
        "queue, {} customers: Lindley-IPA {:.2} ms, compiled model {:.1} ms = {:.0}× (target ≤ 5×, < 17 ms); \
         C {c} vs {cl}, dC/dμ {g} vs {gl}",
        customers(),
        tl * 1e3,
        tc * 1e3,
        tc / tl
    );
}
