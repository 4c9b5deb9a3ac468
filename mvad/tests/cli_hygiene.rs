//! The `mvad` binary on a model with many events: the human-readable tables of `grad`,
//! `simulate` and `measure` stop at 20 event rows and `fdcheck` lists 5 event times, each
//! followed by "… and N more"; `--json` still carries every event. Also: the hints naming
//! command-line flags come from the CLI, not the runtime.

mod common;

use common::{run_status, scratch, stderr, stdout};
use serde_json::Value;

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

/// `saw.hyb` in a temporary directory (removed when dropped), its path, and the number of
/// events of its full run.
struct Saw {
    dir: tempfile::TempDir,
    path: String,
    events: usize,
}

/// Writes the sawtooth and counts its events with `grad --json`.
fn saw() -> Saw {
    let (dir, path) = scratch("saw.hyb", SAW.as_bytes());
    let events = json(&["grad", &path, "--json"])["events"]
        .as_array()
        .expect("events")
        .len();
    assert!((999..=1000).contains(&events), "{events} events");
    Saw { dir, path, events }
}

/// Standard output of a successful run.
fn ok(args: &[&str]) -> String {
    stdout(&run_status(args, 0))
}

/// Standard output of a successful run, parsed as JSON.
fn json(args: &[&str]) -> Value {
    common::json(&run_status(args, 0))
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
    let saw = saw();
    let (model, n) = (saw.path.as_str(), saw.events);
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
    let saw = saw();
    let (model, n) = (saw.path.as_str(), saw.events);
    let csv = saw.dir.path().join("traj.csv");
    let out = ok(&[
        "simulate",
        model,
        "--out",
        csv.to_str().expect("a UTF-8 path"),
    ]);
    assert!(out.contains(&format!("{n} events up to T")), "{out}");
    assert_eq!(event_rows(&out), ROWS, "{out}");
    assert!(
        out.contains(&format!("… and {} more events", n - ROWS)),
        "{out}"
    );
    // The CSV keeps both sides of every event.
    let rows = std::fs::read_to_string(&csv)
        .expect("the CSV")
        .lines()
        .count();
    assert!(rows > 2 * n, "{rows} CSV lines for {n} events");
    let v = json(&["simulate", model, "--json"]);
    assert_eq!(v["events"].as_array().map(Vec::len), Some(n));
}

#[test]
fn measure_atom_table_is_capped_and_json_is_complete() {
    let saw = saw();
    let (model, n) = (saw.path.as_str(), saw.events);
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
    let saw = saw();
    let (model, n) = (saw.path.as_str(), saw.events);
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
    // Models without a horizon need `--t-end`, and the CLI says so.
    for (name, src) in [
        (
            "nohorizon.hyb",
            "model M {\n  state x = 1;\n  flow { der(x) = -x; }\n}\n",
        ),
        (
            "endless.hyb",
            "model Endless { state x = 0; flow { der(x) = 1; } cost = integral(x); }",
        ),
    ] {
        let (_dir, path) = scratch(name, src.as_bytes());
        let o = run_status(&["grad", &path], 2);
        let err = stderr(&o);
        assert!(err.contains("no horizon"), "{name}: {err}");
        assert!(err.contains("--t-end"), "{name}: {err}");
        run_status(&["grad", &path, "--t-end", "1"], 0);
    }
    // The runtime's own message names no flag.
    let e = mvad::SolveError::NoHorizon.to_string();
    assert!(!e.contains("--"), "{e}");
    let e = mvad::SolveError::MaxSteps {
        t: 0.0,
        steps: 1,
        h: 1e-3,
        not_stiff: false,
        largest: 1.0,
    }
    .to_string();
    assert!(!e.contains("--") && e.contains("rosenbrock"), "{e}");
}
