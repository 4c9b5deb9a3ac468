//! The seed paper's Table 1 (E1, dC/de of C = ∫₀² h dt for the bouncing ball) from our
//! run, beside the paper's numbers and the closed form.
//!
//! `cargo run --release -p models --example table1`

use models::bouncing_ball::{BouncingBall, BouncingBallParams, DCOST_DE};
use models::paper::TABLE1;
use mvad::fd::fd_gradient;
use mvad::solve::solve;

fn main() {
    let model = BouncingBall::new();
    let theta = BouncingBallParams::default().to_vector();
    let opts = models::tolerances(1e-10, 1e-12);
    let sol = match solve(&model, &theta, &opts) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    };
    // The paper's FD: central differences with relative step 1e-6.
    let fd = match fd_gradient(&model, &theta, &opts, 0, 1e-6) {
        Ok(v) => v,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    };
    let mvad = sol.gradient[0];
    let abs = (mvad - fd).abs();
    let rel = abs / mvad.abs();
    // One parameter: the cosine similarity of two non-zero scalars of equal sign is 1.
    let cos = (mvad * fd) / (mvad.abs() * fd.abs());
    let times: Vec<String> = sol.events.iter().map(|e| format!("{:.4}", e.t)).collect();
    let paper_times: Vec<String> = TABLE1
        .event_times
        .iter()
        .map(|t| format!("{t:.4}"))
        .collect();

    println!(
        "Table 1. E1 bouncing ball: dC/de, C = ∫₀² h dt (e = 0.8, g = 9.81, h0 = 2, v0 = 0)\n"
    );
    println!(
        "{:<7} {:>19} {:>19} {:>10} {:>10} {:>10} {:>3}  event times (s)",
        "", "MV-AD ∇", "FD ∇", "abs err", "rel err", "cos sim", "K"
    );
    println!(
        "{:<7} {:>19.15} {:>19.15} {:>10.2e} {:>10.2e} {:>10.3} {:>3}  {}",
        "ours",
        mvad,
        fd,
        abs,
        rel,
        cos,
        sol.events.len(),
        times.join("; ")
    );
    println!(
        "{:<7} {:>19} {:>19} {:>10.2e} {:>10.2e} {:>10.3} {:>3}  {}",
        "paper",
        TABLE1.mvad,
        TABLE1.fd,
        TABLE1.abs_err,
        TABLE1.rel_err,
        TABLE1.cosine,
        TABLE1.events,
        paper_times.join("; ")
    );
    println!("\nexact (closed form): dC/de = {DCOST_DE:.16}");
    println!(
        "error against the closed form: ours MV-AD {:.1e}, ours FD {:.1e}; paper MV-AD {:.1e}, paper FD {:.1e} (relative)",
        (mvad - DCOST_DE).abs() / DCOST_DE,
        (fd - DCOST_DE).abs() / DCOST_DE,
        (TABLE1.mvad - DCOST_DE).abs() / DCOST_DE,
        (TABLE1.fd - DCOST_DE).abs() / DCOST_DE
    );
}
