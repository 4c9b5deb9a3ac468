//! The global error estimate against the actual error, forward and adjoint mode, on the
//! stiff and extreme suite (`suite/`): one markdown row per case and mode with the errors of
//! C and dC/dθ against the case's reference, the estimates (relative in the same measure),
//! the ratio estimate/actual of the gradient, the diagnostics and the case's verdict.
//!
//! `cargo run --release -p mvad --example error_estimates [NAME-SUBSTRING ...]`
//! (every case without arguments; the slow ones take a few seconds each).

use std::path::Path;

use mvad::runtime::solution::GradientMode;
use mvad::suite::Suite;

fn main() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../suite");
    let suite = Suite::load(&dir).expect("the suite loads");
    let filters: Vec<String> = std::env::args().skip(1).collect();
    println!(
        "| case | mode | err C | est C | err dC/dθ | est dC/dθ | est/err dC | diagnostics | verdict |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let (mut runs, mut passed) = (0, 0);
    for case in &suite.cases {
        if !filters.is_empty() && !filters.iter().any(|f| case.name.contains(f.as_str())) {
            continue;
        }
        for mode in [GradientMode::Forward, GradientMode::Adjoint] {
            let (_, o, v) = case.check_in_mode(&dir, mode).expect("the case runs");
            let (est_c, est_g) = o.estimate.unwrap_or((f64::NAN, f64::NAN));
            println!(
                "| {} | {mode:?} | {:.1e} | {est_c:.1e} | {:.1e} | {est_g:.1e} | {:.1e} | {} | {} |",
                case.name,
                o.cost_err,
                o.grad_err,
                est_g / o.grad_err,
                if o.diagnostics.is_empty() {
                    "–".to_string()
                } else {
                    o.diagnostics.join(", ")
                },
                if v.pass { "pass" } else { "FAIL" },
            );
            runs += 1;
            passed += usize::from(v.pass);
        }
    }
    println!("\n{passed} of {runs} runs passed.");
}
