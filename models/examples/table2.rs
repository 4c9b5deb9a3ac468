//! The seed paper's Table 2 (E2, first impact of the ball dropped from h0 = 1 with
//! initial velocity v0; observable: position) from our runs, beside the paper's numbers.
//!
//! `cargo run --release -p models --example table2`

use models::e2_sweep::{first_impact, E2Sweep, E2SweepParams};
use models::paper::TABLE2;
use mvad::solve::solve;

fn main() {
    let model = E2Sweep::new();
    let opts = models::tolerances(1e-10, 1e-12);
    println!(
        "Table 2. E2 transversality sweep: first impact, observable position (J = 0: no atom)\n"
    );
    println!(
        "{:>6} | {:>18} {:>8} {:>10} {:>18} | {:>8} {:>8} {:>6} {:>8} | {:>9}",
        "v0",
        "|∇g·f| ours",
        "transv.",
        "atom |α|",
        "t₁ ours",
        "|∇g·f|",
        "transv.",
        "atom",
        "t₁",
        "exact t₁ − ours"
    );
    println!("{:>6} | {:^58} | {:^35} |", "", "ours", "paper");
    for &(v0, slope_p, transv_p, atom_p, t_p) in &TABLE2 {
        let theta = E2SweepParams {
            v0,
            ..E2SweepParams::default()
        }
        .to_vector();
        let sol = match solve(&model, &theta, &opts) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("error at v0 = {v0}: {e}");
                std::process::exit(1);
            }
        };
        let Some(ev) = sol.events.first() else {
            eprintln!("error at v0 = {v0}: no impact before T");
            std::process::exit(1);
        };
        // Atom magnitude of the position observable (index 0) over all parameters.
        let atom = ev.atoms[0].iter().map(|a| a * a).sum::<f64>().sqrt();
        let (t_exact, _) = first_impact(v0, 9.81, 1.0);
        println!(
            "{:>6.1} | {:>18.15} {:>8} {:>10.1e} {:>18.15} | {:>8.4} {:>8} {:>6.1} {:>8.4} | {:>9.1e}",
            v0,
            ev.guard_slope.abs(),
            if ev.transversal { "True" } else { "False" },
            atom,
            ev.t,
            slope_p,
            if transv_p { "True" } else { "False" },
            atom_p,
            t_p,
            t_exact - ev.t
        );
    }
}
