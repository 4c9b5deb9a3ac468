//! `mvad check MODEL.hyb`: the model parsed and validated (errors never get this far:
//! they are located and rendered by the loader), and what it declares: states, params,
//! modes, events, observables, cost terms, horizon and the sparsity of ∂f/∂x per mode.

use clap::Args;
use mvad::{Direction, HybridModel, ModelAlloc};
use nalgebra::DefaultAllocator;
use serde_json::{Map, Value};

use super::output::{g, join_or, json_text, num};
use super::{setup_params_only, CmdResult, Common};

/// Arguments of `mvad check`.
#[derive(Args, Debug)]
pub struct CheckArgs {
    /// Common options.
    #[command(flatten)]
    pub common: Common,
}

/// Runs `mvad check`.
pub fn run<M: HybridModel>(model: &M, file: &str, args: &CheckArgs) -> CmdResult
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let params = setup_params_only(model, &args.common)?;
    let info = model.info();
    let horizon = match args.common.t_end {
        Some(t) => Some(t),
        None => model.horizon(&params),
    };
    let mode_name = |m: usize| info.modes.get(m).cloned().unwrap_or_default();
    let dir = |d: Direction| match d {
        Direction::Down => "down",
        Direction::Up => "up",
    };
    if args.common.json {
        let mut m = Map::new();
        m.insert("model".into(), Value::from(info.name.clone()));
        m.insert("file".into(), Value::from(file));
        m.insert("states".into(), Value::from(info.states.clone()));
        let mut p = Map::new();
        for (k, name) in info.params.iter().enumerate() {
            p.insert(name.clone(), num(params[k]));
        }
        m.insert("params".into(), Value::Object(p));
        m.insert("modes".into(), Value::from(info.modes.clone()));
        m.insert(
            "initial_mode".into(),
            Value::from(mode_name(info.initial_mode)),
        );
        let events: Vec<Value> = info
            .events
            .iter()
            .map(|e| {
                serde_json::json!({
                    "name": e.name,
                    "direction": dir(e.direction),
                    "mode": e.mode.map(mode_name),
                    "target": e.target.map(mode_name),
                    "has_reset": e.has_reset,
                    "has_cost": e.has_cost,
                })
            })
            .collect();
        m.insert("events".into(), Value::Array(events));
        m.insert("observables".into(), Value::from(info.observables.clone()));
        m.insert("switches".into(), Value::from(info.switches));
        m.insert(
            "cost".into(),
            serde_json::json!({
                "integral": info.has_running_cost,
                "sum": info.events.iter().filter(|e| e.has_cost).map(|e| e.name.clone()).collect::<Vec<_>>(),
                "final": info.has_final_cost,
            }),
        );
        m.insert("horizon".into(), horizon.map(num).unwrap_or(Value::Null));
        let qps: Vec<Value> = model
            .qps()
            .iter()
            .map(|q| {
                serde_json::json!({
                    "name": q.name,
                    "variables": q.vars,
                    "constraints": q.kinds.len(),
                    "dynamic": q.dynamic,
                })
            })
            .collect();
        m.insert("qps".into(), Value::Array(qps));
        let mut sp = Map::new();
        for (mi, entries) in info.jacobian_sparsity.iter().enumerate() {
            let pairs: Vec<Value> = entries
                .iter()
                .map(|&(r, c)| serde_json::json!([info.states.get(r), info.states.get(c)]))
                .collect();
            sp.insert(mode_name(mi), Value::Array(pairs));
        }
        m.insert("jacobian_sparsity".into(), Value::Object(sp));
        return Ok(json_text(&Value::Object(m)));
    }

    let mut s = String::new();
    s.push_str(&format!("{file}: model `{}` is valid\n", info.name));
    s.push_str(&format!(
        "states ({}):       {}\n",
        info.states.len(),
        info.states.join(", ")
    ));
    let plist: Vec<String> = info
        .params
        .iter()
        .enumerate()
        .map(|(k, n)| format!("{n} = {}", g(params[k], 10)))
        .collect();
    s.push_str(&format!(
        "params ({}):       {}\n",
        info.params.len(),
        join_or(&plist, ", ", "-")
    ));
    s.push_str(&format!(
        "modes ({}):        {} (initial: {})\n",
        info.modes.len(),
        info.modes.join(", "),
        mode_name(info.initial_mode)
    ));
    s.push_str(&format!("events ({}):\n", info.events.len()));
    for e in &info.events {
        s.push_str(&format!(
            "  {:<16} fires {:<4} armed in {:<12} {}{}\n",
            e.name,
            dir(e.direction),
            e.mode.map(mode_name).unwrap_or_else(|| "every mode".into()),
            e.target
                .map(|t| format!("-> {}", mode_name(t)))
                .unwrap_or_else(|| "-> (same mode)".into()),
            if e.has_reset { ", with reset" } else { "" }
        ));
    }
    s.push_str(&format!(
        "observables ({}):  {}\n",
        info.observables.len(),
        join_or(&info.observables, ", ", "-")
    ));
    let mut cost = Vec::new();
    if info.has_running_cost {
        cost.push("integral".to_string());
    }
    for e in info.events.iter().filter(|e| e.has_cost) {
        cost.push(format!("sum({})", e.name));
    }
    if info.has_final_cost {
        cost.push("final / static".to_string());
    }
    s.push_str(&format!(
        "cost:             {}\n",
        join_or(&cost, " + ", "none (C = 0)")
    ));
    s.push_str(&format!(
        "horizon:          {}\n",
        match horizon {
            Some(t) => g(t, 10),
            None if info.states.is_empty() => "none (a model without states has no time)".into(),
            None => "none (pass --t-end T to run)".to_string(),
        }
    ));
    let qps: Vec<String> = model
        .qps()
        .iter()
        .map(|q| {
            format!(
                "{}({}) with {} constraint{}, {}",
                q.name,
                q.vars.join(", "),
                q.kinds.len(),
                if q.kinds.len() == 1 { "" } else { "s" },
                if q.dynamic {
                    "solved along the trajectory"
                } else {
                    "static"
                }
            )
        })
        .collect();
    s.push_str(&format!(
        "qps ({}):          {}\n",
        qps.len(),
        join_or(&qps, "; ", "-")
    ));
    s.push_str(&format!(
        "switches:         {} (kinks of abs/min/max/sign/if in flows)\n",
        info.switches
    ));
    let n = info.states.len();
    s.push_str("sparsity of df/dx:\n");
    for (mi, entries) in info.jacobian_sparsity.iter().enumerate() {
        let list: Vec<String> = entries
            .iter()
            .map(|&(r, c)| {
                format!(
                    "d{}/d{}",
                    info.states.get(r).map(String::as_str).unwrap_or("?"),
                    info.states.get(c).map(String::as_str).unwrap_or("?")
                )
            })
            .collect();
        s.push_str(&format!(
            "  {}: {} of {} non-zero{}{}\n",
            mode_name(mi),
            entries.len(),
            n * n,
            if list.is_empty() { "" } else { ": " },
            list.join(", ")
        ));
    }
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::test_support::{assert_contains_all, json, on_ball};

    #[test]
    fn text_lists_the_declarations() {
        let out = on_ball(run, &[]).expect("ok");
        assert!(
            out.starts_with("ball.hyb: model `BouncingBall` is valid\n"),
            "{out}"
        );
        assert_contains_all(
            &out,
            &[
                "states (2):       h, v",
                "e = 0.8, g = 9.81, h0 = 2, v0 = 0",
                "impact",
                "main: 1 of 4 non-zero: dh/dv",
                "horizon:          2\n",
            ],
        );
    }

    #[test]
    fn json_has_the_structure() {
        let out = on_ball(run, &["--json", "--set", "e=0.5"]).expect("ok");
        let v = json(&out);
        assert_eq!(v["model"], "BouncingBall");
        assert_eq!(v["params"]["e"], 0.5);
        assert_eq!(v["events"][0]["name"], "impact");
        assert_eq!(v["events"][0]["direction"], "down");
        assert_eq!(v["jacobian_sparsity"]["main"][0][0], "h");
        assert_eq!(v["horizon"], 2.0);
    }
}
