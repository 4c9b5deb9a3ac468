//! Writes a seeded arrival table for the queue models (`models/queue.hyb`): exponential
//! interarrival times and service requirements of mean 1, as CSV with columns `t,s`.
//!
//! ```text
//! cargo run --release -p models --example queue_table -- N [SEED] > arrivals.csv
//! mvad grad models/queue.hyb --table arrivals=arrivals.csv
//! ```
//! (`models/queue.csv` is `N = 1000, SEED = 1`.)

use std::io::Write;

fn main() -> std::process::ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
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
