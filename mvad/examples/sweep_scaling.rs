//! Parallel sweeps against a serial loop: 10⁴ runs of the loaded bouncing ball (e swept over
//! [0.3, 0.95], gradients by forward sensitivities), once in a plain loop and once through
//! `mvad::batch::par_map` (rayon) on 1, 2, … threads. Prints the wall times (the best of
//! five repeats, so other work on the machine disturbs them less), the ratio to the serial
//! run and whether every result (cost, gradient, event times) is bit for bit the serial one.
//!
//! ```sh
//! cargo run --release -p mvad --example sweep_scaling            # 10000 points
//! cargo run --release -p mvad --example sweep_scaling -- 2000    # fewer
//! ```

use std::path::Path;
use std::time::Instant;

use mvad::batch::par_map;
use mvad::interp::InterpretedModel;
use mvad::runtime::solution::Options;
use mvad::runtime::solve::solve;
use mvad::HybridModel;
use nalgebra::DVector;

/// What one run gives: cost, gradient and event times.
type Run = Result<(f64, Vec<f64>, Vec<f64>), mvad::SolveError>;

fn run(model: &InterpretedModel, base: &DVector<f64>, e: f64) -> Run {
    let mut p = base.clone();
    p[0] = e;
    let sol = solve(model, &p, &Options::default())?;
    let times = sol.events.iter().map(|ev| ev.t).collect();
    Ok((sol.cost, sol.gradient, times))
}

/// Repeats per configuration; the fastest counts.
const REPEATS: usize = 5;

/// `f`'s result and its fastest wall time in seconds over `n` runs.
fn best_of<R>(n: usize, mut f: impl FnMut() -> R) -> (R, f64) {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..n {
        let start = Instant::now();
        let r = f();
        best = best.min(start.elapsed().as_secs_f64());
        out = Some(r);
    }
    (out.expect("n >= 1"), best)
}

fn main() {
    let count: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(10_000);
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/bouncing_ball.hyb");
    let model = match mvad::load::load(&path) {
        Ok(m) => m,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    let base = DVector::from_vec(model.info().param_defaults.clone());
    let values: Vec<f64> = (0..count)
        .map(|i| 0.3 + 0.65 * i as f64 / (count - 1).max(1) as f64)
        .collect();

    let (serial, t_serial) = best_of(REPEATS, || {
        values
            .iter()
            .map(|&e| run(&model, &base, e))
            .collect::<Vec<Run>>()
    });
    let failed = serial.iter().filter(|r| r.is_err()).count();
    println!(
        "{count} runs of the bouncing ball (e in [0.3, 0.95]), {} cores; {failed} failed",
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    println!(
        "{:<22} {:>10} {:>10} {:>10}",
        "", "wall s", "× serial", "identical"
    );
    println!(
        "{:<22} {:>10.3} {:>10.3} {:>10}",
        "serial loop", t_serial, 1.0, "-"
    );

    let max = std::thread::available_parallelism().map_or(1, |n| n.get());
    for threads in 1..=max {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("a thread pool");
        let (base, values) = (&base, &values);
        let (par, t) = best_of(REPEATS, || {
            // The model is Send, not Sync: the pool's closure takes its own copy.
            let own = model.clone();
            pool.install(move || par_map(&own, values, |m, &e| run(m, base, e), &|| {}))
        });
        let same = par.len() == serial.len()
            && par
                .iter()
                .zip(&serial)
                .all(|(p, s)| p.as_ref().is_ok_and(|p| p == s));
        println!(
            "{:<22} {:>10.3} {:>10.3} {:>10}",
            format!("par_map, {threads} thread(s)"),
            t,
            t / t_serial,
            if same { "yes" } else { "NO" }
        );
    }
}
