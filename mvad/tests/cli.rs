//! End-to-end tests of the `mvad` binary: every command, the JSON keys of the spec, the
//! tables, the exit statuses (0 ok, 1 the run failed, 2 bad input), and located errors
//! for malformed models (empty, binary, deeply nested, every semantic error class),
//! none of which may panic.

mod common;

use approx::assert_relative_eq;
use common::{json, run_status, scratch, stderr, stdout};
use serde_json::Value;

#[path = "../src/cli/spec_keys.rs"]
mod spec_keys;
use spec_keys::missing_spec_keys;

/// How many lines of `text` satisfy `pred`.
fn count_lines(text: &str, pred: impl Fn(&str) -> bool) -> usize {
    text.lines().filter(|l| pred(l)).count()
}

const BALL: &str = "models/bouncing_ball.hyb";
/// Every model shipped in `models/`.
const MODELS: [&str; 6] = [
    "bouncing_ball",
    "e2_sweep",
    "thermostat",
    "stiff_relay",
    "zeno_ball",
    "ceiling",
];
/// Tolerances at which E1 is accurate to about 1e-10.
const TIGHT: [&str; 4] = ["--rtol", "1e-10", "--atol", "1e-12"];

/// `args` followed by [`TIGHT`].
fn tight<'a>(args: &[&'a str]) -> Vec<&'a str> {
    args.iter().copied().chain(TIGHT).collect()
}

const E1_COST: f64 = 1.8905137123173506;
const E1_DCDE: f64 = 2.8314408141470055;
const E1_T1: f64 = 0.638_550_856_814_101;
const E1_T2: f64 = 1.6602322277166624;

/// The first diagnostic of `kind` in a `grad --json` object.
fn diagnostic<'a>(v: &'a Value, kind: &str) -> &'a Value {
    v["diagnostics"]
        .as_array()
        .expect("array")
        .iter()
        .find(|d| d["kind"] == kind)
        .unwrap_or_else(|| panic!("no {kind} diagnostic in {v}"))
}

/// C and dC/de of E1 to 1e-9 and its two events; returns the events.
fn assert_e1_values(v: &Value) -> &Vec<Value> {
    assert_relative_eq!(
        v["cost"].as_f64().expect("cost"),
        E1_COST,
        max_relative = 1e-9
    );
    assert_relative_eq!(
        v["gradient"]["e"].as_f64().expect("dC/de"),
        E1_DCDE,
        max_relative = 1e-9
    );
    let events = v["events"].as_array().expect("events");
    assert_eq!(events.len(), 2);
    events
}

#[test]
fn grad_json_has_the_spec_keys_and_the_e1_values() {
    let v = json(&run_status(&tight(&["grad", BALL, "--json"]), 0));
    assert_eq!(missing_spec_keys(&v), Vec::<String>::new(), "{v}");
    assert_eq!(v["model"], "BouncingBall");
    assert_eq!(v["t_end"], 2.0);
    assert_eq!(v["params"]["e"], 0.8);
    assert_eq!(v["params"]["g"], 9.81);
    let events = assert_e1_values(&v);
    for (k, (ev, t)) in events.iter().zip([E1_T1, E1_T2]).enumerate() {
        assert_eq!(ev["index"], k);
        assert_eq!(ev["name"], "impact");
        assert_eq!(ev["mode_before"], "main");
        assert_eq!(ev["mode_after"], "main");
        assert_eq!(ev["transversal"], true);
        assert_relative_eq!(ev["t"].as_f64().expect("t"), t, max_relative = 1e-10);
        for key in ["h", "v", "height", "velocity"] {
            assert!(ev["jump"][key].is_number(), "jump lacks {key}");
        }
        for obs in ["height", "velocity"] {
            for p in ["e", "g", "h0", "v0"] {
                assert!(ev["atoms"][obs][p].is_number(), "atoms lack {obs}/{p}");
            }
        }
    }
    // First impact: v⁻ = −g t₁, slope ∇g·f = v⁻, J_v = (1 + e) g t₁, t₁' w.r.t. h0 = 1/(g t₁).
    let ev = &events[0];
    assert_relative_eq!(
        ev["guard_slope"].as_f64().expect("n"),
        -9.81 * E1_T1,
        max_relative = 1e-9
    );
    assert_relative_eq!(
        ev["jump"]["v"].as_f64().expect("n"),
        1.8 * 9.81 * E1_T1,
        max_relative = 1e-9
    );
    assert_relative_eq!(
        ev["dt"]["h0"].as_f64().expect("n"),
        1.0 / (9.81 * E1_T1),
        max_relative = 1e-8
    );
    // α = −J t' for velocity and h0: −(1.8 g t₁)(1/(g t₁)) = −1.8.
    assert_relative_eq!(
        ev["atoms"]["velocity"]["h0"].as_f64().expect("n"),
        -1.8,
        max_relative = 1e-8
    );
    assert_eq!(ev["jump"]["height"].as_f64().map(f64::abs), Some(0.0));
    for key in spec_keys::STATS_KEYS {
        assert!(v["stats"][key].is_number(), "stats lack {key}");
    }
    assert_eq!(v["stats"]["events"], 2);
    assert!(v["diagnostics"].as_array().expect("array").is_empty());
}

#[test]
fn grad_wrt_set_and_t_end() {
    let o = run_status(
        &[
            "grad", BALL, "--json", "--wrt", "e", "--set", "e=0.5", "--t-end", "1",
        ],
        0,
    );
    let v = json(&o);
    assert_eq!(v["params"]["e"], 0.5);
    assert_eq!(v["t_end"], 1.0);
    assert_eq!(v["gradient"].as_object().map(|g| g.len()), Some(1));
    assert_eq!(v["events"][0]["dt"].as_object().map(|g| g.len()), Some(1));
    assert_eq!(
        v["events"][0]["atoms"]["velocity"]
            .as_object()
            .map(|g| g.len()),
        Some(1)
    );
    assert_eq!(v["events"].as_array().map(Vec::len), Some(1));
}

#[test]
fn grad_text_table() {
    let o = run_status(&["grad", BALL], 0);
    let out = stdout(&o);
    assert!(out.contains("cost C = 1.89051371"), "{out}");
    assert!(
        out.lines()
            .any(|l| l.starts_with("e ") && l.contains("2.83144081")),
        "{out}"
    );
    assert!(out.contains("events (2):"), "{out}");
    assert!(out.contains("guard slope"), "{out}");
}

#[test]
fn grad_adjoint_gives_e1_and_leaves_out_forward_quantities() {
    let v = json(&run_status(
        &tight(&["grad", BALL, "--json", "--mode", "adjoint"]),
        0,
    ));
    assert_eq!(missing_spec_keys(&v), Vec::<String>::new(), "{v}");
    assert_eq!(v["stats"]["mode"], "adjoint");
    assert_eq!(v["mode"], "adjoint");
    assert!(
        v["stats"]["record_bytes"].as_u64().is_some_and(|b| b > 0),
        "{v}"
    );
    let events = assert_e1_values(&v);
    for (ev, t) in events.iter().zip([E1_T1, E1_T2]) {
        assert_eq!(ev["name"], "impact");
        assert_relative_eq!(ev["t"].as_f64().expect("t"), t, max_relative = 1e-10);
        assert!(ev["guard_slope"].is_number() && ev["transversal"] == true);
        assert!(ev["jump"]["velocity"].is_number());
        assert!(ev.get("dt").is_none() && ev.get("atoms").is_none(), "{ev}");
    }
    // The text form says which mode ran and has no t' columns.
    let out = stdout(&run_status(&["grad", BALL, "--mode", "adjoint"], 0));
    assert!(out.contains("gradient by adjoint mode"), "{out}");
    assert!(!out.contains("dt/d"), "{out}");
    // auto: 4 params take forward mode.
    let v = json(&run_status(&["grad", BALL, "--json", "--mode", "auto"], 0));
    assert_eq!(v["stats"]["mode"], "forward");
    run_status(&["grad", BALL, "--mode", "backward"], 2);
}

#[test]
fn grad_adjoint_of_an_accumulation_falls_back_to_forward() {
    let o = run_status(
        &[
            "grad",
            "models/zeno_ball.hyb",
            "--json",
            "--mode",
            "adjoint",
        ],
        0,
    );
    let v = json(&o);
    assert_eq!(v["stats"]["mode"], "forward");
    assert_eq!(missing_spec_keys(&v), Vec::<String>::new(), "{v}");
    let zeno = diagnostic(&v, "zeno");
    let message = zeno["message"].as_str().expect("message");
    assert!(message.contains("forward mode"), "{message}");
}

#[test]
fn zeno_ball_reports_a_zeno_diagnostic_and_finishes() {
    let o = run_status(&["grad", "models/zeno_ball.hyb", "--json"], 0);
    let v = json(&o);
    let kinds: Vec<&str> = v["diagnostics"]
        .as_array()
        .expect("array")
        .iter()
        .filter_map(|d| d["kind"].as_str())
        .collect();
    assert!(kinds.contains(&"zeno"), "{kinds:?}");
    assert_eq!(missing_spec_keys(&v), Vec::<String>::new(), "{v}");
    // e = 0.5, h0 = 2: the bounces accumulate at t* = t₁ (1 + 2e/(1 − e)) = 3 t₁.
    let zeno = diagnostic(&v, "zeno");
    assert_relative_eq!(
        zeno["t"].as_f64().expect("t"),
        3.0 * E1_T1,
        max_relative = 1e-6
    );
}

#[test]
fn every_bundled_model_checks_and_runs_grad() {
    for name in MODELS {
        let path = format!("models/{name}.hyb");
        let o = run_status(&["check", &path], 0);
        assert!(stdout(&o).contains("is valid"), "{}", stdout(&o));
        let v = json(&run_status(&["check", &path, "--json"], 0));
        assert!(v["states"].as_array().is_some_and(|s| !s.is_empty()));
        let v = json(&run_status(&["grad", &path, "--json"], 0));
        assert_eq!(missing_spec_keys(&v), Vec::<String>::new(), "{name}");
        assert!(v["cost"].is_number(), "{name}");
        let gradient = v["gradient"].as_object().expect("gradient");
        assert!(
            gradient.values().all(Value::is_number),
            "{name}: {gradient:?}"
        );
        // Adjoint mode: the spec's keys and the same gradient (at the default tolerances).
        let a = json(&run_status(
            &["grad", &path, "--json", "--mode", "adjoint"],
            0,
        ));
        assert_eq!(missing_spec_keys(&a), Vec::<String>::new(), "{name}");
        for (k, g) in gradient {
            let (f, b) = (
                g.as_f64().expect("f"),
                a["gradient"][k].as_f64().expect("a"),
            );
            assert!(
                (f - b).abs() <= 1e-5 * f.abs().max(1e-3),
                "{name} d/d{k}: forward {f} adjoint {b}"
            );
        }
    }
    let v = json(&run_status(
        &["check", "models/thermostat.hyb", "--json"],
        0,
    ));
    assert_eq!(v["modes"], serde_json::json!(["heating", "cooling"]));
    assert_eq!(v["events"][0]["target"], "cooling");
}

#[test]
fn simulate_csv_to_stdout_and_file() {
    let o = run_status(&["simulate", BALL, "--points", "21"], 0);
    let out = stdout(&o);
    assert!(out.starts_with("t,mode,h,v,height,velocity\n"), "{out}");
    assert_eq!(out.lines().count(), 1 + 21 + 4);
    assert!(
        stderr(&o).contains("impact"),
        "event table on stderr: {}",
        stderr(&o)
    );
    let (_dir, p) = scratch("traj.csv", b"");
    let o = run_status(&["simulate", BALL, "--out", &p], 0);
    assert!(stdout(&o).contains("impact"), "{}", stdout(&o));
    let csv = std::fs::read_to_string(&p).expect("csv written");
    let last = csv.lines().last().expect("rows");
    assert!(last.starts_with("2.0,main,"), "{last}");
    let v = json(&run_status(
        &["simulate", BALL, "--json", "--points", "3"],
        0,
    ));
    assert_eq!(v["columns"][0], "t");
    assert_eq!(v["rows"].as_array().map(Vec::len), Some(3 + 4));
}

#[test]
fn measure_json_and_plots() {
    let v = json(&run_status(
        &tight(&["measure", BALL, "--observable=height", "--wrt=e", "--json"]),
        0,
    ));
    for key in [
        "observable",
        "grid",
        "density",
        "atoms",
        "integral_derivative",
    ] {
        assert!(v.get(key).is_some(), "missing {key}");
    }
    assert_relative_eq!(
        v["integral_derivative"]["e"]["total"].as_f64().expect("n"),
        E1_DCDE,
        max_relative = 1e-8
    );
    for ext in ["svg", "png"] {
        let (_dir, p) = scratch(&format!("fig1.{ext}"), b"");
        let o = run_status(
            &[
                "measure",
                BALL,
                "--observable",
                "velocity",
                "--wrt",
                "e",
                "--plot",
                &p,
            ],
            0,
        );
        assert!(stdout(&o).contains("wrote"), "{}", stdout(&o));
        let bytes = std::fs::read(&p).expect("picture");
        assert!(bytes.len() > 1000, "{ext}: {} bytes", bytes.len());
        if ext == "png" {
            assert_eq!(&bytes[..4], b"\x89PNG");
        } else {
            assert!(bytes.starts_with(b"<svg"));
        }
    }
    let o = run_status(&["measure", BALL, "--observable", "nope"], 2);
    assert!(
        stderr(&o).contains("known observables: height, velocity"),
        "{}",
        stderr(&o)
    );
    run_status(&["measure", BALL], 2); // --observable is required
}

#[test]
fn fdcheck_table_one() {
    let o = run_status(&["fdcheck", BALL, "--wrt", "e"], 0);
    let out = stdout(&o);
    for word in [
        "MV-AD",
        "FD",
        "abs err",
        "rel err",
        "cosine similarity",
        "0.638551; 1.66023",
    ] {
        assert!(out.contains(word), "{word}: {out}");
    }
    let v = json(&run_status(
        &[
            "fdcheck", BALL, "--json", "--step", "1e-5", "--rtol", "1e-12", "--atol", "1e-14",
        ],
        0,
    ));
    let row = &v["rows"][0];
    for key in ["param", "mvad", "fd", "abs_err", "rel_err"] {
        assert!(row.get(key).is_some(), "row lacks {key}");
    }
    assert!(row["rel_err"].as_f64().expect("n") < 1e-6, "{row}");
    assert_relative_eq!(
        v["cosine_similarity"].as_f64().expect("n"),
        1.0,
        max_relative = 1e-9
    );
    assert_eq!(v["events"], 2);
}

#[test]
fn sweep_table_two_on_e2() {
    let o = run_status(
        &["sweep", "models/e2_sweep.hyb", "--over", "v0=-0.5:-5:10"],
        0,
    );
    let out = stdout(&o);
    assert!(out.contains("guard slope"), "{out}");
    assert_eq!(count_lines(&out, |l| l.contains("True")), 10, "{out}");
    let over = "--over=v0=-0.5:-5:10";
    let v = json(&run_status(
        &tight(&["sweep", "models/e2_sweep.hyb", over, "--json"]),
        0,
    ));
    let rows = v["rows"].as_array().expect("rows");
    assert_eq!(rows.len(), 10);
    // h0 = 1, g = 9.81: the impact speed |∇g·f| = √(v0² + 2 g h0) and the time
    // (v0 + √(v0² + 2 g h0)) / g, at both ends of the sweep (the paper's Table 2).
    for (row, v0) in [(&rows[0], -0.5f64), (&rows[9], -5.0)] {
        let speed = (v0 * v0 + 2.0 * 9.81).sqrt();
        let slope = row["guard_slope"].as_f64().expect("n");
        assert_relative_eq!(slope, speed, max_relative = 1e-9);
        let t = row["event_time"].as_f64().expect("n");
        assert_relative_eq!(t, (v0 + speed) / 9.81, max_relative = 1e-9);
    }
    for r in rows {
        assert_eq!(r["atom_magnitude"], 0.0, "position is continuous: no atom");
        assert_eq!(r["transversal"], true);
    }
    run_status(&["sweep", "models/e2_sweep.hyb", "--over", "v0=1:2"], 2);
    run_status(&["sweep", "models/e2_sweep.hyb", "--over", "zz=1:2:3"], 2);
}

#[test]
fn workprec_table_and_plot() {
    let (_dir, p) = scratch("wp.svg", b"");
    let o = run_status(
        &[
            "workprec",
            BALL,
            "--wrt",
            "e",
            &format!("--reference=C={E1_COST}"),
            &format!("--reference=e={E1_DCDE}"),
            "--plot",
            &p,
        ],
        0,
    );
    let out = stdout(&o);
    assert!(out.contains("MV-AD err dC"), "{out}");
    assert_eq!(count_lines(&out, |l| l.starts_with("1e-")), 10, "{out}");
    assert!(std::fs::read_to_string(&p).expect("plot").contains("MV-AD"));
}

#[test]
fn unknown_set_lists_the_known_params() {
    for cmd in ["check", "simulate", "grad", "fdcheck", "workprec"] {
        let o = run_status(&[cmd, BALL, "--set", "q=1"], 2);
        assert!(
            stderr(&o).contains("known parameters: e, g, h0, v0"),
            "{cmd}: {}",
            stderr(&o)
        );
    }
    run_status(&["grad", BALL, "--wrt", "nope"], 2);
    run_status(&["grad", BALL, "--set", "e=abc"], 2);
}

#[test]
fn bad_options_and_usage_errors_exit_2() {
    run_status(&["grad", BALL, "--bogus"], 2);
    run_status(&["frobnicate", BALL], 2);
    run_status(&[], 2);
    run_status(&["grad"], 2);
    run_status(&["grad", BALL, "--method", "euler"], 2);
    run_status(&["grad", BALL, "--rtol", "-1"], 2);
    run_status(&["grad", BALL, "--rtol", "x"], 2);
    run_status(&["grad", BALL, "--t-end", "0"], 2);
    run_status(&["grad", BALL, "--grazing-tol", "nan"], 2);
    run_status(&["grad", "/nonexistent/model.hyb"], 2);
    run_status(
        &["measure", BALL, "--observable", "height", "--plot", "x.pdf"],
        2,
    );
    let o = run_status(&["--help"], 0);
    assert!(stdout(&o).contains("workprec"));
    run_status(&["grad", "--help"], 0);
    run_status(&["--version"], 0);
    // Every method parses and runs.
    for m in ["auto", "tsit5", "verner9", "rosenbrock"] {
        run_status(&["grad", BALL, "--method", m], 0);
    }
}

#[test]
fn a_failed_run_exits_1_with_an_error_object() {
    let (_dir, p) = scratch(
        "nan.hyb",
        b"model M {\n  state x = -1;\n  flow { der(x) = log(x); }\n  cost = integral(x);\n  horizon 1;\n}\n",
    );
    let o = run_status(&["grad", &p, "--json"], 1);
    let v = json(&o);
    assert!(
        v["error"]
            .as_str()
            .is_some_and(|m| m.contains("non-finite")),
        "{v}"
    );
    assert!(stderr(&o).contains("non-finite"), "{}", stderr(&o));
    let o = run_status(&["grad", &p], 1);
    assert!(stdout(&o).is_empty());
    // A solution that blows up in finite time.
    let (_dir, p) = scratch(
        "blowup.hyb",
        b"model M {\n  state x = 1;\n  flow { der(x) = x^2; }\n  cost = integral(x);\n  horizon 2;\n}\n",
    );
    let v = json(&run_status(&["grad", &p, "--json"], 1));
    assert!(v["error"].is_string());
}

/// Asserts a located error: exit 2, first stderr line `FILE:LINE:COL: error: ...` with the
/// expected line and a message containing `fragment`, the line quoted, a caret.
fn assert_located(name: &str, contents: &[u8], line: usize, fragment: &str) {
    let (_dir, p) = scratch(name, contents);
    for cmd in ["check", "grad"] {
        let o = run_status(&[cmd, &p], 2);
        let err = stderr(&o);
        let first = err.lines().next().unwrap_or_default();
        let prefix = format!("{p}:{line}:");
        assert!(
            first.starts_with(&prefix),
            "{name}: expected {prefix}…, got: {err}"
        );
        let rest = &first[prefix.len()..];
        let (col, msg) = rest
            .split_once(": error: ")
            .unwrap_or_else(|| panic!("{name}: {first}"));
        assert!(
            col.parse::<usize>().is_ok_and(|c| c >= 1),
            "{name}: column in {first}"
        );
        assert!(
            msg.contains(fragment),
            "{name}: `{fragment}` not in {first}"
        );
        assert!(
            err.lines()
                .any(|l| l.trim_start().starts_with(&format!("{line} |"))),
            "{name}: no quoted line: {err}"
        );
        assert!(
            err.lines()
                .any(|l| l.trim_start().starts_with('|') && l.contains('^')),
            "{name}: no caret: {err}"
        );
        assert!(stdout(&o).is_empty(), "{name}: stdout not empty");
    }
    // Under --json the failure is also an object with an "error" key.
    let v = json(&run_status(&["grad", &p, "--json"], 2));
    assert!(v["error"].is_string());
}

#[test]
fn empty_blank_and_binary_files_are_located_errors() {
    assert_located("empty.hyb", b"", 1, "empty model file");
    assert_located("blank.hyb", b"  \n\n \t\n", 1, "empty model file");
    assert_located(
        "nul.hyb",
        b"model M {\n  state \x00\x01 x = 1;\n}",
        2,
        "U+0000",
    );
    assert_located(
        "latin1.hyb",
        b"model M {\n  // caf\xe9\n}",
        2,
        "not valid UTF-8",
    );
    // Pseudo-random bytes (a fixed xorshift stream) in several sizes.
    let mut s = 0x2545_f491_4f6c_dd1du64;
    for size in [1usize, 7, 100, 4096] {
        let bytes: Vec<u8> = (0..size)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                (s >> 24) as u8
            })
            .collect();
        let (_dir, p) = scratch(&format!("garbage{size}.hyb"), &bytes);
        let o = run_status(&["grad", &p], 2);
        assert!(stderr(&o).starts_with(&format!("{p}:")), "{}", stderr(&o));
    }
}

/// A one-state model with the initial value `init` and the flow `der(x) = rhs`.
fn one_state_model(init: &str, rhs: &str) -> Vec<u8> {
    format!("model M {{\n  state x = {init};\n  flow {{ der(x) = {rhs}; }}\n}}\n").into_bytes()
}

#[test]
fn deep_nesting_is_an_error_not_a_crash() {
    let depth = 100_000;
    let parens = format!("{}1{}", "(".repeat(depth), ")".repeat(depth));
    assert_located(
        "deep.hyb",
        &one_state_model(&parens, "1"),
        2,
        "nested too deeply",
    );
    let negations = format!("{}x", "-".repeat(depth));
    let powers = format!("x{}", "^x".repeat(depth));
    for (name, rhs) in [("deepneg", negations), ("deeppow", powers)] {
        let (_dir, p) = scratch(&format!("{name}.hyb"), &one_state_model("1", &rhs));
        run_status(&["check", &p], 2);
    }
}

#[test]
fn every_semantic_error_class_is_located() {
    let cases: &[(&str, &str, usize, &str)] = &[
        ("undefined", "model M {\n    state x = 1;\n    flow { der(x) = -k * x; }\n}\n", 3, "undefined name `k`"),
        ("duplicate", "model M {\n    param a = 1;\n    param a = 2;\n    state x = 1;\n    flow { der(x) = -a * x; }\n}\n", 3, "duplicate"),
        ("missing-der", "model M {\n    state x = 1;\n    state y = 2;\n    flow { der(x) = -x; }\n}\n", 4, "`y`"),
        ("der-of-param", "model M {\n    param a = 1;\n    state x = 1;\n    flow { der(x) = -x; der(a) = 1; }\n}\n", 4, "not a state"),
        ("der-twice", "model M {\n    state x = 1;\n    flow { der(x) = -x; der(x) = 1; }\n}\n", 3, "twice"),
        ("reset-non-state", "model M {\n    param a = 1;\n    state x = 1;\n    flow { der(x) = -x; }\n    event hit when x <= 0 { a = 2; }\n}\n", 5, "not a state"),
        ("unknown-mode", "model M {\n    state x = 1;\n    mode up { der(x) = 1; event e when x >= 2 -> down; }\n}\n", 3, "unknown mode `down`"),
        ("unknown-initial", "model M {\n    state x = 1;\n    initial mode nowhere;\n    mode up { der(x) = 1; }\n}\n", 3, "unknown mode"),
        ("unknown-event", "model M {\n    state x = 1;\n    flow { der(x) = -x; }\n    event hit when x <= 0.5 { x = 1; }\n    cost = sum(miss, x);\n    horizon 1;\n}\n", 5, "unknown event `miss`"),
        ("unknown-function", "model M {\n    state x = 1;\n    flow { der(x) = foo(x); }\n}\n", 3, "unknown function `foo`"),
        ("wrong-arity", "model M {\n    state x = 1;\n    flow { der(x) = sin(x, 2); }\n}\n", 3, "argument"),
        ("guard-not-comparison", "model M {\n    state x = 1;\n    flow { der(x) = -x; }\n    event hit when x + 1 { x = 1; }\n}\n", 4, "not a comparison"),
        ("const-uses-param", "model M {\n    param a = 1;\n    const c = 2 * a;\n    state x = 1;\n    flow { der(x) = -c * x; }\n}\n", 3, "param `a`"),
        ("no-states", "model M {\n    param a = 1;\n    horizon 1;\n}\n", 1, "no states"),
        ("reserved-name", "model M {\n    param sin = 1;\n    state x = 1;\n    flow { der(x) = -x; }\n}\n", 2, "reserved"),
        ("flow-and-modes", "model M {\n    state x = 1;\n    flow { der(x) = -x; }\n    mode up { der(x) = 1; }\n}\n", 4, "both"),
        ("no-flow", "model M {\n    state x = 1;\n    horizon 1;\n}\n", 1, "no `flow`"),
        ("param-not-constant", "model M {\n    param a = sin(t);\n    state x = 1;\n    flow { der(x) = -a * x; }\n}\n", 2, "param `a`"),
        ("param-uses-state", "model M {\n    param a = x;\n    state x = 1;\n    flow { der(x) = -a * x; }\n}\n", 2, "state `x`"),
        ("syntax-missing-semicolon", "model M {\n    state x = 1\n    flow { der(x) = -x; }\n}\n", 3, "expected"),
        ("syntax-unclosed", "model M {\n    state x = 1;\n    flow { der(x) = -x; }\n", 4, "end of input"),
        ("syntax-bad-operator", "model M {\n    state x = 1;\n    flow { der(x) = (x + * x); }\n}\n", 3, "unexpected"),
    ];
    for (name, src, line, fragment) in cases {
        assert_located(&format!("{name}.hyb"), src.as_bytes(), *line, fragment);
    }
}

#[test]
fn guard_slope_is_the_total_rate_so_a_pure_time_guard_has_slope_one() {
    // dg/dt = ∇ₓg·f + ∂g/∂t at t_k⁻: `t >= tdose` has ∇ₓg = 0 and ∂g/∂t = 1; a guard on a
    // state x with ẋ = 2 moving as t (x − t >= 0.5, crossed where 2t − t = 0.5) has 2 − 1 = 1.
    let (_dir, p) = scratch(
        "dose.hyb",
        b"model Dose {
            param tdose = 0.5; param c = 0.5;
            state x = 0;
            flow { der(x) = 2; }
            event dose when t >= tdose { x = x + 1; }
            event moving when x - t >= c + 1 { x = x - 10; }
            cost = integral(x);
            horizon 2;
        }",
    );
    let v = json(&run_status(&["grad", &p, "--json"], 0));
    let events = v["events"].as_array().expect("events");
    assert_eq!(events.len(), 2, "{v}");
    for ev in events {
        assert_relative_eq!(
            ev["guard_slope"].as_f64().expect("n"),
            1.0,
            max_relative = 1e-12
        );
        assert_eq!(ev["transversal"], true);
    }
    // t' of the dose: dt/dtdose = 1 (C = ∫x moves by −1 per unit of tdose before the
    // second event, which the dose brings forward by 1/(2 − 1) = 1 per unit).
    assert_relative_eq!(
        events[0]["dt"]["tdose"].as_f64().expect("n"),
        1.0,
        max_relative = 1e-12
    );
}

#[test]
fn report_runs_a_suite_and_refuses_a_missing_one() {
    let (dir, _) = scratch("x", b"");
    let out = dir.path().join("report");
    let o = run_status(
        &[
            "report",
            "suite",
            "--out",
            out.to_str().expect("utf-8"),
            "--only",
            "zeno e=0.5",
        ],
        0,
    );
    assert!(
        stdout(&o).contains("2 cases, 2 passed, 0 failed"),
        "{}",
        stdout(&o)
    );
    let md = std::fs::read_to_string(out.join("README.md")).expect("README.md");
    assert!(md.contains("| zeno e=0.5 |"), "{md}");
    assert!(out.join("zeno-e-0-5.png").is_file());
    run_status(&["report", "/nonexistent/suite", "--out", "/tmp/x"], 2);
    run_status(
        &[
            "report",
            "suite",
            "--out",
            "/tmp/x",
            "--only",
            "no such case",
        ],
        2,
    );
}
