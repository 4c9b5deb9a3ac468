//! Writes a seeded arrival table for the queue models (`models/queue.hyb`): exponential
//! interarrival times and service requirements of mean 1, as CSV with columns `t,s`; or, with
//! `--exact`, the exact C and dC/dμ of a table (the Lindley recursion in integer arithmetic,
//! `models::queue::exact`) as JSON.
//!
//! ```text
//! cargo run --release -p models --example queue_table -- N [SEED] > arrivals.csv
//! mvad grad models/queue.hyb --table arrivals=arrivals.csv
//! cargo run --release -p models --example queue_table -- --exact arrivals.csv [MU]
//! ```
//! (`models/queue.csv` is `N = 1000, SEED = 1`; `models/queue_exact.json` is its `--exact` at
//! the model's μ = 1.25, which the command-line tests compare against.)

use std::io::Write;

fn main() -> std::process::ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("--exact") {
        return exact(&args[1..]);
    }
    let parse = |i: usize, default: u64| -> Option<u64> {
        args.get(i)
            .map_or(Some(default), |a| a.replace('_', "").parse().ok())
    };
    let (Some(n), Some(seed)) = (parse(0, 1000), parse(1, 1)) else {
        eprintln!("usage: queue_table N [SEED]  (N customers, a u64 seed)");
        return std::process::ExitCode::from(2);
    };
    let arrivals = models::queue::Arrivals::generate(n as usize, seed);
    let mut out = std::io::stdout().lock();
    if out.write_all(arrivals.to_csv().as_bytes()).is_err() {
        return std::process::ExitCode::from(1);
    }
    std::process::ExitCode::SUCCESS
}

/// `--exact FILE.csv [MU]`: the exact reference of a table as JSON.
fn exact(args: &[String]) -> std::process::ExitCode {
    let (Some(file), Some(mu)) = (
        args.first(),
        args.get(1).map_or(Some(1.25), |m| m.parse::<f64>().ok()),
    ) else {
        eprintln!("usage: queue_table --exact FILE.csv [MU]");
        return std::process::ExitCode::from(2);
    };
    let table = match mvad::table::Table::read_csv(std::path::Path::new(file)) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("{e}");
            return std::process::ExitCode::from(2);
        }
    };
    let (Some(t), Some(s)) = (table.column("t"), table.column("s")) else {
        eprintln!("{file}: the table needs columns t and s");
        return std::process::ExitCode::from(2);
    };
    println!("{}", models::queue::exact_json(t, s, mu));
    std::process::ExitCode::SUCCESS
}
