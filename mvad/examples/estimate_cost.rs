//! What the global error estimate costs: runs a model N times at its defaults in one gradient
//! mode with `Options::global_error` on or off and prints the mean wall time per run (for
//! deterministic counts run it under `valgrind --tool=callgrind` and compare the totals).
//!
//! `cargo run --release -p mvad --example estimate_cost -- MODEL.hyb N forward|adjoint on|off`

use std::path::Path;
use std::time::Instant;

use mvad::runtime::solution::{GradientMode, Options};
use mvad::runtime::solve::solve;
use mvad::HybridModel;
use nalgebra::DVector;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [file, n, mode, estimate] = args.as_slice() else {
        eprintln!("usage: estimate_cost MODEL.hyb N forward|adjoint on|off");
        std::process::exit(2);
    };
    let model = mvad::load::load(Path::new(file)).expect("the model loads");
    let p = DVector::from_column_slice(&model.info().param_defaults);
    let n: usize = n.parse().expect("N");
    let opts = Options {
        gradient_mode: match mode.as_str() {
            "adjoint" => GradientMode::Adjoint,
            _ => GradientMode::Forward,
        },
        global_error: estimate == "on",
        ..Options::default()
    };
    let start = Instant::now();
    let mut sol = None;
    for _ in 0..n {
        sol = Some(std::hint::black_box(
            solve(&model, &p, &opts).expect("runs"),
        ));
    }
    let sol = sol.expect("N > 0");
    println!(
        "{file} p = {} {mode} estimate {estimate}: {:.3} ms per run, {} steps, {} record bytes, gradient[0] {:e}",
        p.len(),
        start.elapsed().as_secs_f64() * 1e3 / n as f64,
        sol.stats.steps,
        sol.stats.record_bytes,
        sol.gradient.first().copied().unwrap_or(f64::NAN)
    );
}
