//! The `mvad` binary on models with qps: the spec's `"qp"`, `"gradient_left"` and
//! `"gradient_right"` keys and the `kink` diagnostic (`grad`), the rows of a sweep that show
//! where the active set changes (`sweep`), stateless models through `check`, and the exit
//! statuses of a model error (2) and of a qp that cannot be solved (1).

mod common;

use common::{json, run_status, scratch, stderr, stdout};

#[path = "../src/cli/spec_keys.rs"]
mod spec_keys;
use spec_keys::missing_spec_keys;

const KINK: &str = "models/qp_kink.hyb";

#[test]
fn grad_json_at_the_e3_kink() {
    let v = json(&run_status(
        &["grad", KINK, "--set", "theta=0", "--json"],
        0,
    ));
    assert_eq!(missing_spec_keys(&v), Vec::<String>::new(), "{v}");
    assert_eq!(v["t_end"], 0.0);
    let q = &v["qp"]["u_star"];
    assert_eq!(q["value"]["u"], 0.0);
    assert_eq!(q["active"], serde_json::json!([0]));
    assert_eq!(q["weakly_active"], serde_json::json!([0]));
    assert_eq!(q["multipliers"], serde_json::json!([0.0]));
    let diags = v["diagnostics"].as_array().expect("diagnostics");
    assert_eq!(diags.len(), 1);
    assert_eq!(diags[0]["kind"], "kink");
    let msg = diags[0]["message"].as_str().expect("message");
    assert!(
        msg.contains("`u_star`") && msg.contains("constraint 0"),
        "{msg}"
    );
    assert_eq!(v["gradient"]["theta"], 0.0);
    assert_eq!(v["gradient_left"]["theta"], 0.0);
    assert_eq!(v["gradient_right"]["theta"], 0.0);
    // Away from the kink: no diagnostic, both sides equal θ·H(θ).
    let v = json(&run_status(
        &["grad", KINK, "--set", "theta=0.5", "--json"],
        0,
    ));
    assert_eq!(v["diagnostics"], serde_json::json!([]));
    assert_eq!(v["qp"]["u_star"]["active"], serde_json::json!([]));
    for key in ["gradient", "gradient_left", "gradient_right"] {
        assert_eq!(v[key]["theta"], 0.5, "{key}");
    }
    let o = run_status(&["grad", KINK, "--set", "theta=0"], 0);
    let text = stdout(&o);
    assert!(
        text.contains("dC/dθ (left)") && text.contains("qp u_star:"),
        "{text}"
    );
}

#[test]
fn e3_sweep_rows_carry_qp_and_diagnostics() {
    let v = json(&run_status(
        &["sweep", KINK, "--over", "theta=-1:1:101", "--json"],
        0,
    ));
    let rows = v["rows"].as_array().expect("rows");
    assert_eq!(rows.len(), 101);
    let (mut active, mut boundary, mut inactive) = (0, 0, 0);
    for r in rows {
        let q = &r["qp"]["u_star"];
        let kink = r["diagnostics"]
            .as_array()
            .expect("diagnostics")
            .iter()
            .any(|d| d["kind"] == "kink");
        match (q["active"].as_array().map(Vec::len), kink) {
            (Some(1), true) => {
                boundary += 1;
                assert_eq!(r["value"], 0.0);
            }
            (Some(1), false) => active += 1,
            (Some(0), false) => inactive += 1,
            other => panic!("{other:?} in {r}"),
        }
    }
    assert_eq!((active, boundary, inactive), (50, 1, 50));
}

#[test]
fn a_saturating_qp_in_the_flow() {
    let v = json(&run_status(
        &["grad", "models/qp_cart.hyb", "--rtol", "1e-10", "--json"],
        0,
    ));
    assert_eq!(missing_spec_keys(&v), Vec::<String>::new(), "{v}");
    assert_eq!(v["stats"]["switch_crossings"], 3);
    assert!(v["qp"]["ctl"]["value"]["u"].is_number());
    assert_eq!(
        v["qp"]["ctl"]["multipliers"].as_array().map(Vec::len),
        Some(2)
    );
    let o = run_status(&["check", "models/qp_cart.hyb"], 0);
    assert!(
        stdout(&o).contains("ctl(u) with 2 constraints, solved along the trajectory"),
        "{}",
        stdout(&o)
    );
}

/// `--mode adjoint` on qps: the cart's gradient equals forward mode's, with the qp keys; at
/// a kink (E3 with C = u*, dC/dθ = 1 from the right, 0 from the left) both one-sided
/// gradients come from the adjoint's two sweeps.
#[test]
fn qps_in_adjoint_mode() {
    let cart = |mode: &str| {
        json(&run_status(
            &[
                "grad",
                "models/qp_cart.hyb",
                "--rtol",
                "1e-12",
                "--atol",
                "1e-14",
                "--json",
                "--mode",
                mode,
            ],
            0,
        ))
    };
    let (f, a) = (cart("forward"), cart("adjoint"));
    assert_eq!(missing_spec_keys(&a), Vec::<String>::new(), "{a}");
    assert_eq!(a["stats"]["mode"], "adjoint");
    assert!(a["qp"]["ctl"]["value"]["u"].is_number());
    for (name, g) in f["gradient"].as_object().expect("gradient") {
        let (g, ga) = (
            g.as_f64().expect("f"),
            a["gradient"][name].as_f64().expect("a"),
        );
        assert!(
            (g - ga).abs() <= 1e-10 * g.abs().max(1.0),
            "{name}: {g} vs {ga}"
        );
        assert_eq!(a["gradient_right"][name], a["gradient"][name]);
    }
    let src = include_str!("../../models/qp_kink.hyb")
        .replace("cost = 0.5 * u_star.u^2;", "cost = u_star.u;");
    let (_dir, path) = scratch("kink_u.hyb", src.as_bytes());
    let v = json(&run_status(
        &[
            "grad", &path, "--set", "theta=0", "--json", "--mode", "adjoint",
        ],
        0,
    ));
    assert_eq!(v["stats"]["mode"], "adjoint");
    assert_eq!(v["diagnostics"][0]["kind"], "kink");
    assert_eq!(v["gradient_right"]["theta"], 1.0);
    assert_eq!(v["gradient_left"]["theta"], 0.0);
}

#[test]
fn stateless_models_check() {
    let o = run_status(&["check", KINK], 0);
    let text = stdout(&o);
    assert!(
        text.contains("horizon:          none (a model without states has no time)"),
        "{text}"
    );
    assert!(
        text.contains("u_star(u) with 1 constraint, static"),
        "{text}"
    );
    let v = json(&run_status(&["check", KINK, "--json"], 0));
    assert_eq!(v["qps"][0]["name"], "u_star");
    assert_eq!(v["qps"][0]["dynamic"], false);
}

#[test]
fn qp_errors_exit_with_the_spec_statuses() {
    // A model error: located, exit 2.
    let (_d, path) = scratch(
        "cubic.hyb",
        b"model Cubic { param a = 1;\n qp q(u) { minimize u^3 - a*u; } cost = q.u; }",
    );
    let o = run_status(&["grad", &path], 2);
    assert!(
        stderr(&o)
            .contains("cubic.hyb:2:21: error: the objective of qp `q` is not quadratic in `u`"),
        "{}",
        stderr(&o)
    );
    // Infeasible at these parameters: the run fails, exit 1, an "error" key under --json.
    let (_d, path) = scratch(
        "infeasible.hyb",
        b"model Bad { param a = 1;\n qp q(u) { minimize u^2; subject to u >= a; u <= 0; }\n cost = q.u; }",
    );
    let v = json(&run_status(&["grad", &path, "--json"], 1));
    let e = v["error"].as_str().expect("error");
    assert!(e.contains("qp `q`") && e.contains("infeasible"), "{e}");
    run_status(&["grad", &path, "--set", "a=-1"], 0);
    // A constraint whose coefficients vanish at t = 1/2 (probe2 c08): named as such, exit 1.
    let (_d, path) = scratch(
        "vanishing.hyb",
        b"model B { state x = 1; qp q(u) { minimize u^2 - x*u; subject to u * (t - 0.5) >= 0; }\n flow { der(x) = q.u; } cost = final(x); horizon 1; }",
    );
    let o = run_status(&["grad", &path], 1);
    assert!(
        stderr(&o).contains(
            "qp `q` at t = 0.5: qp constraint 0 no longer involves any variable: its \
             coefficients all vanish here, leaving 0 <= 0"
        ),
        "{}",
        stderr(&o)
    );
}
