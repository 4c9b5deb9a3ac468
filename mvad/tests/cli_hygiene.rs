//! The `mvad` binary on a model with many events: the human-readable tables of `grad`,
//! `simulate` and `measure` stop at 20 event rows and `fdcheck` lists 5 event times, each
//! followed by "… and N more"; `--json` still carries every event. Also: the hints naming
//! command-line flags come from the CLI, not the runtime.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;
use tempfile::TempDir;

/// A sawtooth: x climbs at rate r and is reset to 0 at x = 0.01, so 1 000 events up to T = 10
/// (999 or 1 000, depending on the rounding of the last one).
const SAW: &str = "model Saw {
    param r = 1;
    state x = 0;
    flow { der(x) = r; }
    event drop when x >= 0.01 { x = 0; }
    observe y = x;
    cost = integral(x);
    horizon 10;
}
";

/// Rows shown by the human event tables.
const ROWS: usize = 20;
/// Event times listed by `fdcheck`.
const TIMES: usize = 5;

/// A temporary directory holding `saw.hyb` (removed when the guard drops).
fn saw() -> (TempDir, PathBuf) {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let path = dir.path().join("saw.hyb");
    fs::write(&path, SAW).expect("write the model");
    (dir, path)
}

fn mvad(args: &[&str]) -> Output {
    let o = Command::new(env!("CARGO_BIN_EXE_mvad"))
        .args(args)
        .output()
        .expect("the binary runs");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!err.contains("panicked"), "panic for {args:?}: {err}");
    o
}

fn ok(args: &[&str]) -> String {
    let o = mvad(args);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn json(args: &[&str]) -> Value {
    let out = ok(args);
    serde_json::from_str(&out).unwrap_or_else(|e| panic!("not JSON ({e}): {out}"))
}

fn path_str(p: &Path) -> &str {
    p.to_str().expect("a UTF-8 path")
}

/// The number of events of the full run, from `grad --json`.
fn event_count(model: &str) -> usize {
    let v = json(&["grad", model, "--json"]);
    let n = v["events"].as_array().expect("events").len();
    assert!((999..=1000).contains(&n), "{n} events");
    n
}

/// Lines of `text` that are rows of an event table: they start with an event index and
/// name the event `drop`.
fn event_rows(text: &str) -> usize {
    text.lines()
        .filter(|l| {
            let mut w = l.split_whitespace();
            w.next().is_some_and(|i| i.parse::<usize>().is_ok()) && w.next() == Some("drop")
        })
        .count()
}

#[test]
fn grad_prints_twenty_events_and_json_all_of_them() {
    let (_dir, model) = saw();
    let model = path_str(&model);
    let n = event_count(model);
    let out = ok(&["grad", model]);
    assert!(out.contains(&format!("events ({n}):")), "{out}");
    assert_eq!(event_rows(&out), ROWS, "{out}");
    let more = format!("… and {} more events", n - ROWS);
    // Once under the event table, once under the atom table.
    assert_eq!(out.matches(&more).count(), 2, "{out}");
    assert!(out.lines().count() < 120, "{} lines", out.lines().count());
}

#[test]
fn simulate_event_table_is_capped_and_json_is_complete() {
    let (dir, model) = saw();
    let model = path_str(&model);
    let n = event_count(model);
    let csv = dir.path().join("traj.csv");
    let out = ok(&["simulate", model, "--out", path_str(&csv)]);
    assert!(out.contains(&format!("{n} events up to T")), "{out}");
    assert_eq!(event_rows(&out), ROWS, "{out}");
    assert!(
        out.contains(&format!("… and {} more events", n - ROWS)),
        "{out}"
    );
    // The CSV keeps both sides of every event.
    let rows = fs::read_to_string(&csv).expect("the CSV").lines().count();
    assert!(rows > 2 * n, "{rows} CSV lines for {n} events");
    let v = json(&["simulate", model, "--json"]);
    assert_eq!(v["events"].as_array().map(Vec::len), Some(n));
}

#[test]
fn measure_atom_table_is_capped_and_json_is_complete() {
    let (_dir, model) = saw();
    let model = path_str(&model);
    let n = event_count(model);
    let out = ok(&["measure", model, "--observable", "y"]);
    assert!(out.contains(&format!("atoms ({n}):")), "{out}");
    assert!(
        out.contains(&format!("… and {} more events", n - ROWS)),
        "{out}"
    );
    let v = json(&["measure", model, "--observable", "y", "--json"]);
    assert_eq!(v["atoms"].as_array().map(Vec::len), Some(n));
}

#[test]
fn fdcheck_lists_five_event_times() {
    let (_dir, model) = saw();
    let model = path_str(&model);
    let n = event_count(model);
    let out = ok(&["fdcheck", model]);
    let line = out
        .lines()
        .find(|l| l.starts_with("event times"))
        .unwrap_or_else(|| panic!("no event times line: {out}"));
    assert_eq!(line.matches("; ").count(), TIMES, "{line}");
    assert!(
        line.ends_with(&format!("… and {} more", n - TIMES)),
        "{line}"
    );
    assert!(line.len() < 120, "{line}");
    let v = json(&["fdcheck", model, "--json"]);
    assert_eq!(v["event_times"].as_array().map(Vec::len), Some(n));
}

#[test]
fn runtime_errors_get_their_flag_hints_from_the_cli() {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let path = dir.path().join("endless.hyb");
    fs::write(
        &path,
        "model Endless { state x = 0; flow { der(x) = 1; } cost = integral(x); }",
    )
    .expect("write the model");
    let o = mvad(&["grad", path_str(&path)]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("no horizon"), "{err}");
    assert!(err.contains("--t-end"), "{err}");
    // The runtime's own message names no flag.
    let e = mvad::SolveError::NoHorizon.to_string();
    assert!(!e.contains("--"), "{e}");
    let e = mvad::SolveError::MaxSteps { t: 0.0, steps: 1 }.to_string();
    assert!(!e.contains("--") && e.contains("rosenbrock"), "{e}");
}
