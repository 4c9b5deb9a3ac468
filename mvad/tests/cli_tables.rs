//! The command line on models with data tables: `--table NAME=FILE`, errors located in the
//! CSV file (exit 2), `--all-events` and the 1000-event cap of the JSON `events`.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn mvad(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mvad"))
        .args(args)
        .current_dir(root())
        .output()
        .expect("the binary runs")
}

/// Runs, checks the exit status and that nothing panicked; returns (stdout, stderr).
fn run(args: &[&str], status: i32) -> (String, String) {
    let o = mvad(args);
    let (out, err) = (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    );
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    assert_eq!(o.status.code(), Some(status), "{args:?}\n{out}\n{err}");
    (out, err)
}

fn json(args: &[&str]) -> Value {
    let (out, _) = run(args, 0);
    serde_json::from_str(&out).unwrap_or_else(|e| panic!("not JSON ({e}): {out}"))
}

/// A CSV file `name` with `text` in a fresh directory (removed when dropped).
fn csv(name: &str, text: &str) -> (tempfile::TempDir, String) {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join(name);
    std::fs::write(&path, text).expect("write");
    (dir, path.to_string_lossy().into_owned())
}

const QUEUE: &str = "models/queue.hyb";

#[test]
fn table_replaces_the_data_and_the_answer_is_the_lindley_recursion() {
    // Arrivals at 1, 2, 10 with s = 2, 2, 1 at μ = 1: workloads 2, 3, 1 after the arrivals,
    // C = 6; du/dμ = −2, −4, −1, so dC/dμ = −7 (the third finds the server idle).
    let (_dir, path) = csv("three.csv", "t,s\n1,2\n2,2\n10,1\n");
    let table = format!("arrivals={path}");
    let v = json(&["grad", QUEUE, "--table", &table, "--set", "mu=1", "--json"]);
    let c = v["cost"].as_f64().expect("cost");
    let g = v["gradient"]["mu"].as_f64().expect("gradient");
    assert!((c - 6.0).abs() < 1e-12 && (g + 7.0).abs() < 1e-12, "{v}");
    // Three arrivals and two drains.
    assert_eq!(v["stats"]["events"], 5, "{v}");
    let (out, _) = run(&["grad", QUEUE, "--table", &table, "--set", "mu=1"], 0);
    assert!(out.contains("cost C = 6\n"), "{out}");
}

#[test]
fn grad_with_a_table_matches_the_exact_lindley_recursion() {
    // models/queue_exact.json: C and dC/dμ of models/queue.csv (1000 customers) by the
    // recursion in integer arithmetic (`queue_table --exact`, checked by the models crate).
    let text = std::fs::read_to_string(root().join("models/queue_exact.json")).expect("stored");
    let exact: Value = serde_json::from_str(&text).expect("JSON");
    let v = json(&[
        "grad",
        QUEUE,
        "--table",
        "arrivals=models/queue.csv",
        "--json",
    ]);
    let rel = |key: &str, got: &Value, want: &Value| {
        let (g, w) = (got.as_f64().expect(key), want.as_f64().expect(key));
        assert!(((g - w) / w).abs() < 1e-12, "{key}: {g} vs exact {w}");
    };
    rel("cost", &v["cost"], &exact["cost"]);
    rel("dC/dmu", &v["gradient"]["mu"], &exact["gradient"]["mu"]);
}

#[test]
fn json_lists_1000_events_unless_all_events_is_given() {
    let v = json(&["grad", QUEUE, "--json"]);
    let total = v["stats"]["events"].as_u64().expect("count");
    assert!(total > 1000, "{total}");
    assert_eq!(v["events"].as_array().map(Vec::len), Some(1000));
    let v = json(&["grad", QUEUE, "--json", "--all-events"]);
    assert_eq!(v["events"].as_array().map(Vec::len), Some(total as usize));
    let (out, _) = run(&["grad", QUEUE], 0);
    assert!(out.contains(&format!("events ({total}):")), "{out}");
    assert!(
        out.contains("more events (--json lists 1000, --all-events all)"),
        "{out}"
    );
}

#[test]
fn table_errors_are_located_in_the_csv_file_with_exit_status_2() {
    let cases: &[(&str, &str, &str)] = &[
        (
            "t,s\n1,2\n2,x2\n",
            ":3:3: error: `x2` in column `s` is not a finite number",
            "x2",
        ),
        (
            "t,z\n1,2\n",
            ":1:1: error: table `arrivals` has no column `s`; its columns are t, z",
            "t,z",
        ),
        (
            "t,s\n1,2\n0.5,1\n",
            ":3:1: error: column `t` of table `arrivals` decreases here (0.5 after 1)",
            "0.5,1",
        ),
        (
            "t,s\n1,2\n3\n",
            ":3:2: error: this row has 1 fields, the header 2",
            "3",
        ),
    ];
    for (text, message, quoted) in cases {
        let (_dir, path) = csv("bad.csv", text);
        let (_, err) = run(&["grad", QUEUE, "--table", &format!("arrivals={path}")], 2);
        assert!(err.starts_with(&format!("{path}{message}")), "{err}");
        assert!(err.contains(quoted) && err.contains('^'), "{err}");
        let (out, _) = run(
            &[
                "grad",
                QUEUE,
                "--json",
                "--table",
                &format!("arrivals={path}"),
            ],
            2,
        );
        let v: Value = serde_json::from_str(&out).expect("an error object");
        assert_eq!(v["kind"], "input", "{v}");
    }
    let (_, err) = run(
        &["grad", QUEUE, "--table", "arrivals=/nonexistent/q.csv"],
        2,
    );
    assert!(
        err.starts_with("/nonexistent/q.csv:1:1: error: cannot read the table"),
        "{err}"
    );
    let (_, err) = run(&["grad", QUEUE, "--table", "nope=models/queue.csv"], 2);
    assert!(
        err.contains("no table `nope`; its tables are arrivals"),
        "{err}"
    );
    let (_, err) = run(&["grad", QUEUE, "--table", "arrivals"], 2);
    assert!(err.contains("--table expects NAME=FILE"), "{err}");
    let (_, err) = run(
        &[
            "grad",
            QUEUE,
            "--table",
            "arrivals=models/queue.csv",
            "--table",
            "arrivals=models/queue.csv",
        ],
        2,
    );
    assert!(
        err.contains("--table names table `arrivals` twice"),
        "{err}"
    );
}

#[test]
fn stretched_times_that_decrease_are_bad_input() {
    let (_, err) = run(
        &["grad", "models/queue_stretched.hyb", "--set", "scale=-1"],
        2,
    );
    assert!(
        err.contains("the times of event `arrive` are unusable"),
        "{err}"
    );
}
