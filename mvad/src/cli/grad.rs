//! `mvad grad MODEL.hyb`: the cost C(θ) and dC/dθ, with the event table: for every event
//! t_k, the guard slope ∇ₓg·f⁻, transversality, t_k' per param, the jump J_k of every
//! state and observable, and the atoms α_k = −J_k t_k'. `--json` prints the spec's object.
//!
//! `--mode adjoint` computes dC/dθ by a backward sweep (`mvad::adjoint`); its events have no
//! t' and no atoms (forward quantities), which the JSON leaves out. `--mode auto` takes the
//! adjoint from `GradientMode::AUTO_ADJOINT_MIN_PARAMS` params on; `stats.mode` (and the
//! top-level `mode`) say which mode ran.

use clap::Args;
use mvad::json::grad_json;
use mvad::qp::QpLayerInfo;
use mvad::runtime::solution::Solution;
use mvad::setup::check_mode;
use mvad::{HybridModel, ModelAlloc, ModelInfo};
use nalgebra::DefaultAllocator;

use super::output::{
    diagnostics_text, g, json_text, more_events, param_header, Table, MAX_EVENT_ROWS,
};
use super::qp_output::qp_text;
use super::{setup, setup_err, solve_listing, CmdResult, Common};

/// Arguments of `mvad grad`.
#[derive(Args, Debug)]
pub struct GradArgs {
    /// Common options.
    #[command(flatten)]
    pub common: Common,
    /// Sensitivity mode: `forward` (sensitivities carried along the run), `adjoint` (a primal
    /// run, then one backward sweep: cost flat in the number of params; events without t'
    /// and atoms) or `auto` (adjoint from 50 params on).
    #[arg(long, default_value = "forward", value_parser = ["forward", "adjoint", "auto"])]
    pub mode: String,
}

/// Runs `mvad grad`.
pub fn run<M: HybridModel>(model: &M, file: &str, args: &GradArgs) -> CmdResult
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let mut s = setup(model, &args.common)?;
    s.opts.gradient_mode = check_mode(&args.mode).map_err(setup_err)?;
    let sol = solve_listing(model, &s, &args.common)?;
    let info = model.info();
    if args.common.json {
        Ok(json_text(&grad_json(info, model.qps(), &sol, &s.wrt)))
    } else {
        Ok(grad_text(info, model.qps(), file, &sol, &s.wrt))
    }
}

/// The readable form: cost, gradient table, event table, atom table, warnings, stats.
pub fn grad_text(
    info: &ModelInfo,
    qps: &[QpLayerInfo],
    file: &str,
    sol: &Solution,
    wrt: &[usize],
) -> String {
    let mut s = String::new();
    s.push_str(&format!(
        "model {} ({file}), T = {}\n",
        info.name,
        g(sol.t_end, 10)
    ));
    s.push_str(&format!("cost C = {}\n", g(sol.cost, 15)));
    s.push_str(&format!("gradient by {} mode\n\n", sol.stats.mode.name()));

    let left = sol.gradient_left.as_deref();
    let header: &[&str] = if left.is_some() {
        &["param", "value", "dC/dθ (right)", "dC/dθ (left)"]
    } else {
        &["param", "value", "dC/dθ"]
    };
    let mut t = Table::new(header);
    for &k in wrt {
        let mut row = vec![
            info.params[k].clone(),
            g(sol.params.get(k).copied().unwrap_or(f64::NAN), 10),
            g(sol.gradient.get(k).copied().unwrap_or(f64::NAN), 15),
        ];
        if let Some(l) = left {
            row.push(g(l.get(k).copied().unwrap_or(f64::NAN), 15));
        }
        t.row(row);
    }
    s.push_str(&t.render());
    s.push_str(&qp_text(qps, &sol.qp));

    s.push_str(&format!("\nevents ({}):\n", sol.stats.events));
    if !sol.events.is_empty() {
        // t' and the atoms are forward quantities: an adjoint run's events have neither.
        let with_dt = sol.events.iter().all(|e| !e.dt.is_empty());
        let cols: &[usize] = if with_dt { wrt } else { &[] };
        let mode = |m: usize| info.modes.get(m).cloned().unwrap_or_default();
        let mut t = Table::new(&param_header(
            &["#", "event", "t", "mode", "guard slope", "transversal"],
            "dt/d",
            &info.params,
            cols,
        ));
        for e in sol.events.iter().take(MAX_EVENT_ROWS) {
            let name = info
                .events
                .get(e.event)
                .map(|x| x.name.clone())
                .unwrap_or_default();
            let modes = if e.mode_before == e.mode_after {
                mode(e.mode_before)
            } else {
                format!("{} -> {}", mode(e.mode_before), mode(e.mode_after))
            };
            let mut row = vec![
                e.index.to_string(),
                name,
                g(e.t, 12),
                modes,
                g(e.guard_slope, 8),
                if e.transversal { "yes" } else { "NO (grazing)" }.to_string(),
            ];
            row.extend(
                cols.iter()
                    .map(|&k| g(e.dt.get(k).copied().unwrap_or(f64::NAN), 8)),
            );
            t.row(row);
        }
        s.push_str(&t.render());
        s.push_str(&more_events(sol.stats.events));

        // Jumps and atoms of the observables that jump.
        let mut t = Table::new(&param_header(
            &["#", "t", "observable", "jump J"],
            "atom d/d",
            &info.params,
            cols,
        ));
        for e in sol.events.iter().take(MAX_EVENT_ROWS) {
            for (i, o) in info.observables.iter().enumerate() {
                let jump = e.jump_observables.get(i).copied().unwrap_or(0.0);
                if jump == 0.0 {
                    continue;
                }
                let mut row = vec![e.index.to_string(), g(e.t, 8), o.clone(), g(jump, 8)];
                let atoms = e.atoms.get(i).map(Vec::as_slice).unwrap_or(&[]);
                row.extend(
                    cols.iter()
                        .map(|&k| g(atoms.get(k).copied().unwrap_or(f64::NAN), 8)),
                );
                t.row(row);
            }
        }
        if t.is_empty() {
            s.push_str("\nno observable jumps at the events: the measures have no atoms\n");
        } else if !with_dt {
            s.push_str(
                "\njumps J of the observables (the atoms α = −J t' need t', a forward \
                 quantity: --mode forward):\n",
            );
            s.push_str(&t.render());
            s.push_str(&more_events(sol.events.len()));
        } else {
            s.push_str("\natoms α = −J t' of the observables that jump:\n");
            s.push_str(&t.render());
            s.push_str(&more_events(sol.stats.events));
        }
    }
    let diags = diagnostics_text(&sol.diagnostics);
    if !diags.is_empty() {
        s.push('\n');
        s.push_str(&diags);
    }
    s.push_str(&format!(
        "\n{} steps ({} rejected), {} events, {} s\n",
        sol.stats.steps,
        sol.stats.rejected_steps,
        sol.stats.events,
        g(sol.stats.wall_seconds, 3)
    ));
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::spec_keys::missing_spec_keys;
    use crate::cli::test_support::{assert_contains_all, json, on_ball, tight};
    use approx::assert_relative_eq;
    use serde_json::Value;

    #[test]
    fn json_has_every_key_of_the_spec_and_the_e1_values() {
        let out = on_ball(run, &tight(&["--json"])).expect("runs");
        let v = json(&out);
        assert_eq!(missing_spec_keys(&v), Vec::<String>::new(), "{out}");
        assert_eq!(v["model"], "BouncingBall");
        assert_eq!(v["t_end"], 2.0);
        assert_eq!(v["params"]["e"], 0.8);
        let cost = v["cost"].as_f64().expect("number");
        assert_relative_eq!(cost, 1.8905137123173506, max_relative = 1e-8);
        let de = v["gradient"]["e"].as_f64().expect("number");
        assert_relative_eq!(de, 2.8314408141470055, max_relative = 1e-7);
        let ev = &v["events"][0];
        assert_eq!(ev["name"], "impact");
        assert_eq!(ev["mode_before"], "main");
        // v⁻ = −g t₁ = −6.264 and v⁺ = −e v⁻: the velocity jumps by (1 + e) g t₁.
        let t1 = 0.638_550_856_814_101;
        assert_relative_eq!(ev["t"].as_f64().expect("t"), t1, max_relative = 1e-9);
        let slope = ev["guard_slope"].as_f64().expect("slope");
        assert_relative_eq!(slope, -9.81 * t1, max_relative = 1e-8);
        let jump = ev["jump"]["velocity"].as_f64().expect("J");
        assert_relative_eq!(jump, 1.8 * 9.81 * t1, max_relative = 1e-8);
        assert_eq!(ev["jump"]["height"], 0.0);
        assert!(ev["atoms"]["velocity"]["g"].is_number());
        assert_eq!(v["events"].as_array().map(Vec::len), Some(2));
        // Removing a key is caught.
        let mut broken = v.clone();
        if let Some(ev) = broken["events"][1].as_object_mut() {
            ev.remove("dt");
        }
        assert_eq!(missing_spec_keys(&broken), ["events[1].dt"]);
    }

    #[test]
    fn wrt_restricts_gradient_dt_and_atoms() {
        let out = on_ball(run, &["--json", "--wrt", "e,v0"]).expect("runs");
        let v = json(&out);
        let keys = |x: &Value| -> Vec<String> {
            x.as_object()
                .into_iter()
                .flat_map(|o| o.keys().cloned())
                .collect()
        };
        assert_eq!(keys(&v["gradient"]), ["e", "v0"]);
        assert_eq!(keys(&v["events"][0]["dt"]), ["e", "v0"]);
        assert_eq!(keys(&v["events"][0]["atoms"]["velocity"]), ["e", "v0"]);
        // params stay complete
        assert_eq!(v["params"].as_object().map(|o| o.len()), Some(4));
    }

    #[test]
    fn text_table() {
        let out = on_ball(run, &[]).expect("runs");
        assert_contains_all(
            &out,
            &[
                "cost C = 1.89051371",
                "gradient by forward mode",
                "events (2):",
                "impact",
                "velocity",
            ],
        );
    }

    #[test]
    fn adjoint_json_has_the_spec_keys_and_the_e1_values() {
        let out = on_ball(run, &tight(&["--json", "--mode", "adjoint"])).expect("runs");
        let v = json(&out);
        assert_eq!(missing_spec_keys(&v), Vec::<String>::new(), "{out}");
        assert_eq!(v["stats"]["mode"], "adjoint");
        let de = v["gradient"]["e"].as_f64().expect("number");
        assert_relative_eq!(de, 2.8314408141470055, max_relative = 1e-8);
        assert!(v["events"][0].get("dt").is_none(), "{out}");
        // Dropping a key an adjoint run must have is still caught.
        let mut broken = v.clone();
        if let Some(ev) = broken["events"][0].as_object_mut() {
            ev.remove("jump");
        }
        assert_eq!(missing_spec_keys(&broken), ["events[0].jump"]);
        let text = on_ball(run, &["--mode", "adjoint"]).expect("runs");
        assert!(text.contains("gradient by adjoint mode"), "{text}");
        assert!(text.contains("jumps J of the observables"), "{text}");
    }
}
