//! The stiff relay (`models/stiff_relay.hyb`, τ = 1e-8) against its closed form
//! ([`models::stiff_relay::cost_closed`]): the relative error of each entry of dC/dθ,
//! θ = (tau, rate, lo, hi), per method, atol and rtol, with the steps taken, or the error
//! the run stopped with (a non-finite value, a step-size underflow, ...).
//!
//! `cargo run --release -p models --example stiff_relay_errors`

use models::stiff_relay::{cost_closed, StiffRelay, StiffRelayParams};
use mvad::solution::{Method, Options};
use mvad::solve::solve;

fn main() {
    let m = StiffRelay::new();
    let pp = StiffRelayParams::default();
    let p = pp.to_vector();
    let (c_exact, g_exact) = cost_closed(pp.tau, pp.rate, pp.lo, pp.hi);
    println!("closed form: C = {c_exact:.17e}, dC/dθ = {g_exact:?}\n");
    println!(
        "{:>10} {:>6} {:>6} | {:>9} {:>9} {:>9} {:>9} | {:>9} | {:>6} {:>6}",
        "method", "atol", "rtol", "tau", "rate", "lo", "hi", "C", "steps", "rej."
    );
    for method in [Method::Rosenbrock, Method::Auto] {
        for atol in [1e-10, 1e-15] {
            for rtol in [1e-3, 1e-4, 1e-6, 1e-8, 1e-10, 1e-12] {
                let opts = Options {
                    method,
                    rtol,
                    atol,
                    ..Options::default()
                };
                let head = format!("{:>10} {atol:>6.0e} {rtol:>6.0e}", format!("{method:?}"));
                match solve(&m, &p, &opts) {
                    Ok(sol) => {
                        let errs: Vec<String> = sol
                            .gradient
                            .iter()
                            .zip(g_exact)
                            .map(|(a, b)| format!("{:>9.1e}", ((a - b) / b).abs()))
                            .collect();
                        let ec = ((sol.cost - c_exact) / c_exact).abs();
                        println!(
                            "{head} | {} | {ec:>9.1e} | {:>6} {:>6}{}",
                            errs.join(" "),
                            sol.stats.steps,
                            sol.stats.rejected_steps,
                            if sol.diagnostics.is_empty() {
                                String::new()
                            } else {
                                format!("  diagnostics: {:?}", sol.diagnostics)
                            }
                        );
                    }
                    Err(e) => println!("{head} | error: {e}"),
                }
            }
        }
    }
}
