//! One generated model of the adjoint benchmark (`benches/adjoint.rs`), solved `runs` times
//! in one gradient mode at the default options: for instruction counts under a profiler
//! (`valgrind --tool=callgrind`), where criterion's repetitions would drown the run.
//!
//! ```text
//! cargo run --release -p models --example adjoint_profile -- impact 1000 adjoint [runs]
//! ```
//!
//! Arguments: the family (`impact` or `chain`), p, the mode (`forward` or `adjoint`), the
//! number of runs (default 1) and optionally `no-global-error` (`Options::global_error` off,
//! to see what the global error estimate costs). Prints the gradient's first entry, the steps of the run (for
//! the adjoint: the primal run's and the sweep's, apart) and the record's bytes.

use models::generated::{chain, impact};
use mvad::interp::InterpretedModel;
use mvad::solution::{GradientMode, Options};
use mvad::solve::solve;
use std::process::ExitCode;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: adjoint_profile impact|chain P forward|adjoint [RUNS [no-global-error]]";
    let (Some(family), Some(p), Some(mode)) = (args.first(), args.get(1), args.get(2)) else {
        eprintln!("{usage}");
        return ExitCode::from(2);
    };
    let text = match family.as_str() {
        "impact" => impact,
        "chain" => chain,
        _ => {
            eprintln!("{usage}");
            return ExitCode::from(2);
        }
    };
    let (Ok(p), Some(mode)) = (p.parse::<usize>(), GradientMode::from_name(mode)) else {
        eprintln!("{usage}");
        return ExitCode::from(2);
    };
    let runs: usize = args.get(3).and_then(|r| r.parse().ok()).unwrap_or(1);
    if p == 0 {
        eprintln!("p must be at least 1");
        return ExitCode::from(2);
    }
    let model = match InterpretedModel::from_source(&text(p)) {
        Ok(m) => m,
        Err(diags) => {
            for d in diags {
                eprintln!("{}", d.message);
            }
            return ExitCode::from(1);
        }
    };
    let theta = model.default_params();
    let opts = Options {
        gradient_mode: mode,
        global_error: args.get(4).map(String::as_str) != Some("no-global-error"),
        ..Options::default()
    };
    let mut last = None;
    for _ in 0..runs {
        match solve(&model, &theta, &opts) {
            Ok(sol) => last = Some(sol),
            Err(e) => {
                eprintln!("{e}");
                return ExitCode::from(1);
            }
        }
    }
    let Some(sol) = last else {
        return ExitCode::SUCCESS;
    };
    print!(
        "{family} p = {p} {}: dC/dθ₀ = {:.15e}, {} steps",
        mode.name(),
        sol.gradient[0],
        sol.stats.steps
    );
    if mode == GradientMode::Adjoint {
        let primal = Options {
            sensitivities: false,
            rtol: opts.rtol * mvad::adjoint::PRIMAL_TOL_FACTOR,
            atol: opts.atol * mvad::adjoint::PRIMAL_TOL_FACTOR,
            ..opts.clone()
        };
        if let Ok(run) = solve(&model, &theta, &primal) {
            print!(
                " (primal {}, sweep {})",
                run.stats.steps,
                sol.stats.steps - run.stats.steps
            );
        }
        print!(", record {} B", sol.stats.record_bytes);
    }
    println!();
    ExitCode::SUCCESS
}
