//! The queue (E4) from 10³ to 10⁷ customers: C and dC/dμ of the compiled and the loaded model
//! (streaming: no event table) against the exact Lindley recursion (integer arithmetic on the
//! same data), with the wall time of each and of the hand-written Lindley-IPA loop, the
//! compiled model's time per event and its ratio to the Lindley loop, and how much the peak
//! resident memory of the process grew during the two runs (`VmHWM` of /proc/self/status:
//! 0 when the runs stream); with `--cli`, also `mvad grad --table` as a whole process (the
//! release binary must be built).
//!
//! ```text
//! cargo run --release -p models --example queue_scale -- [N ...] [--cli]
//! ```
//! Default N: 1000 10000 100000 1000000. Exits non-zero if any relative error exceeds 1e-12.

use std::time::Instant;

use models::queue::{self, Arrivals};
use mvad::interp::InterpretedModel;
use mvad::runtime::solution::Options;
use mvad::runtime::solve::solve_with;

fn rel(x: f64, y: f64) -> f64 {
    ((x - y) / y).abs()
}

fn main() -> std::process::ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let cli = args.iter().any(|a| a == "--cli");
    let mut sizes: Vec<usize> = args
        .iter()
        .filter_map(|a| a.replace('_', "").parse().ok())
        .collect();
    if sizes.is_empty() {
        sizes = vec![1_000, 10_000, 100_000, 1_000_000];
    }
    let mu = 1.25;
    let opts = Options::default();
    let src = include_str!("../queue.hyb");
    let mut worst: f64 = 0.0;
    println!(
        "{:>9} {:>11} {:>9} {:>9} {:>9} | {:>9} {:>8} {:>7} {:>9} {:>9} | {:>9} {:>9} {:>9} | {:>8}",
        "N",
        "events",
        "lindley",
        "err C",
        "exact",
        "compiled",
        "ns/event",
        "×lindl",
        "err C",
        "err dC",
        "loaded",
        "err C",
        "err dC",
        "ΔHWM KB"
    );
    for &n in &sizes {
        let a = Arrivals::generate(n, 1);
        let t0 = Instant::now();
        let (c_l, g_l, _) = queue::lindley_ipa(&a.t, &a.s, mu, 1.0);
        let t_lindley = t0.elapsed().as_secs_f64();
        std::hint::black_box(g_l);
        let t0 = Instant::now();
        let (c, g, _) = queue::exact(&a.t, &a.s, mu, 1.0);
        let t_exact = t0.elapsed().as_secs_f64();

        let table = a.table().expect("table");
        let compiled = queue::Queue::new(queue::QueueTables {
            arrivals: table.clone(),
        })
        .expect("binds");
        let p = nalgebra::SVector::<f64, 1>::new(mu);
        let t0 = Instant::now();
        let sol = solve_with(&compiled, &p, &opts, &mut ()).expect("runs");
        let t_compiled = t0.elapsed().as_secs_f64();

        let mut loaded = InterpretedModel::from_source(src).expect("model");
        loaded.bind_tables(&[&table]).expect("binds");
        let pl = nalgebra::DVector::from_vec(vec![mu]);
        let hwm_before = peak_rss_kb();
        let t0 = Instant::now();
        let sol_l = solve_with(&loaded, &pl, &opts, &mut ()).expect("runs");
        let t_loaded = t0.elapsed().as_secs_f64();
        let hwm_growth = peak_rss_kb().zip(hwm_before).map(|(a, b)| a - b);

        let errs = [
            rel(sol.cost, c),
            rel(sol.gradient[0], g),
            rel(sol_l.cost, c),
            rel(sol_l.gradient[0], g),
        ];
        worst = errs.iter().copied().fold(worst, f64::max);
        let events = sol.stats.events;
        println!(
            "{n:>9} {events:>11} {:>8.4}s {:>9.1e} {:>8.3}s | {:>8.4}s {:>8.1} {:>7.1} {:>9.1e} {:>9.1e} | {:>8.4}s {:>9.1e} {:>9.1e} | {:>8}",
            t_lindley,
            rel(c_l, c),
            t_exact,
            t_compiled,
            t_compiled * 1e9 / events as f64,
            t_compiled / t_lindley,
            errs[0],
            errs[1],
            t_loaded,
            errs[2],
            errs[3],
            hwm_growth.map_or("?".to_string(), |g| g.to_string())
        );
        if cli {
            worst = worst.max(run_cli(&a, c, g));
        }
    }
    println!("worst relative error against the exact recursion: {worst:.1e}");
    if worst <= 1e-12 {
        std::process::ExitCode::SUCCESS
    } else {
        std::process::ExitCode::from(1)
    }
}

/// The peak resident set size of this process so far (`VmHWM`, KB), where /proc has it.
fn peak_rss_kb() -> Option<i64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// `mvad grad models/queue.hyb --table arrivals=FILE --json` as a whole process; returns the
/// worst relative error of its C and dC/dμ.
fn run_cli(a: &Arrivals, c: f64, g: f64) -> f64 {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let bin = root.join("target/release/mvad");
    let dir = std::env::temp_dir().join(format!("mvad-queue-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let csv = dir.join("arrivals.csv");
    std::fs::write(&csv, a.to_csv()).expect("write");
    let t0 = Instant::now();
    let out = std::process::Command::new(&bin)
        .current_dir(&root)
        .args(["grad", "models/queue.hyb", "--json", "--table"])
        .arg(format!("arrivals={}", csv.display()))
        .output();
    let wall = t0.elapsed().as_secs_f64();
    let _ = std::fs::remove_dir_all(&dir);
    let Ok(out) = out else {
        println!(
            "  mvad grad: {} not found (cargo build --release -p mvad)",
            bin.display()
        );
        return 0.0;
    };
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap_or_default();
    let (cc, gc) = (
        v["cost"].as_f64().unwrap_or(f64::NAN),
        v["gradient"]["mu"].as_f64().unwrap_or(f64::NAN),
    );
    let err = rel(cc, c).max(rel(gc, g));
    println!(
        "  mvad grad --table ({} rows): {wall:.3} s as a whole process, err C {:.1e}, err dC {:.1e}",
        a.t.len(),
        rel(cc, c),
        rel(gc, g)
    );
    if err.is_nan() {
        f64::INFINITY
    } else {
        err
    }
}
