//! The seed paper's Table 3 (E3): 101 points θ ∈ [−1, 1] of the parametric QP
//! min ½u² − θu s.t. u ≥ 0 with J = ½u*², compiled (`models/qp_kink.hyb` through
//! `hybrid!`): the constraint's status at each point (active, boundary = weakly active,
//! inactive), dJ/dθ against θ·H(θ), and at the kink θ = 0 the two one-sided derivatives.
//!
//! `cargo run --release -p models --example table3` (`--all` prints every row).

use models::paper::TABLE3;
use models::qp_kink::{self, QpKink, QpKinkParams};
use mvad::qp::{ConstraintKind, ConstraintStatus, QpData, QpOptions, QpSolver, Side};
use mvad::solution::{DiagnosticKind, Options};
use mvad::solve::solve;
use nalgebra::{DMatrix, DVector};

fn main() {
    let all = std::env::args().any(|a| a == "--all");
    let model = QpKink::new();
    let (mut active, mut boundary, mut inactive) = (0, 0, 0);
    let (mut err_sum, mut err_max) = (0.0f64, 0.0f64);
    println!("Table 3. E3 parametric QP: dJ/dθ across the kink (no atom)\n");
    println!(
        "{:>6} {:>6} {:>10} {:>12} {:>12} {:>9}  diagnostics",
        "θ", "u*", "status", "dJ/dθ ours", "θ·H(θ)", "|error|"
    );
    for i in 0..=100 {
        let theta = (i as f64 - 50.0) / 50.0;
        let p = QpKinkParams { theta }.to_vector();
        let sol = match solve(&model, &p, &Options::default()) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("error at θ = {theta}: {e}");
                std::process::exit(1);
            }
        };
        let status = sol.qp[0].status[0];
        let label = match status {
            ConstraintStatus::Active => {
                active += 1;
                "active"
            }
            ConstraintStatus::WeaklyActive => {
                boundary += 1;
                "boundary"
            }
            ConstraintStatus::Inactive => {
                inactive += 1;
                "inactive"
            }
        };
        let exact = qp_kink::gradient(theta);
        let err = (sol.gradient[0] - exact).abs();
        err_sum += err;
        err_max = err_max.max(err);
        let kinks: Vec<&str> = sol
            .diagnostics
            .iter()
            .filter(|d| d.kind == DiagnosticKind::Kink)
            .map(|d| d.kind.name())
            .collect();
        if all || i % 10 == 0 || status == ConstraintStatus::WeaklyActive {
            println!(
                "{:>6.2} {:>6.2} {:>10} {:>12.6} {:>12.6} {:>9.1e}  {}",
                theta,
                sol.qp[0].u[0],
                label,
                sol.gradient[0],
                exact,
                err,
                kinks.join(", ")
            );
        }
    }
    println!(
        "\n{:<28} {:>8} {:>8} {:>8} {:>14}",
        "", "active", "boundary", "inactive", "mean |error|"
    );
    println!(
        "{:<28} {:>8} {:>8} {:>8} {:>14.2e}   (max {:.1e})",
        "ours (compiled)",
        active,
        boundary,
        inactive,
        err_sum / 101.0,
        err_max
    );
    println!(
        "{:<28} {:>8} {:>8} {:>8} {:>14.2e}",
        "paper", TABLE3.active, TABLE3.boundary, TABLE3.inactive, TABLE3.mean_abs_err
    );

    // du*/dθ at the kink, from the solver directly: 0 from the left, 1 from the right.
    let data = QpData {
        h: DMatrix::from_element(1, 1, 1.0),
        c: DVector::zeros(1),
        a: DMatrix::from_element(1, 1, -1.0),
        b: DVector::zeros(1),
    };
    let mut dir = QpData::zeros(1, 1);
    dir.c[0] = -1.0;
    let mut s = QpSolver::new(1, &[ConstraintKind::Le], QpOptions::default());
    s.solve(&data).expect("E3 at θ = 0 solves");
    let mut one_sided = |side| {
        let (mut du, mut dm) = ([0.0], [0.0]);
        s.directional(&dir, side, &mut du, &mut dm)
            .expect("derivative");
        du[0]
    };
    let (left, right) = (one_sided(Side::Left), one_sided(Side::Right));
    println!("\nat θ = 0 the constraint is weakly active: du*/dθ = {left} from the left, {right} from the right");
}
