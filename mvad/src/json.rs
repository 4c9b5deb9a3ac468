//! The JSON objects of the spec, built once for every front end: `mvad grad --json`
//! prints [`grad_json`], and the Python package returns the same object as a dict.
//! Non-finite numbers become `null` (JSON has no NaN or ∞).

use mvad_runtime::qp::{QpLayerInfo, QpState};
use mvad_runtime::solution::{Diagnostic, EventRecord, Options, Solution, Stats};
use mvad_runtime::solve::solve_with;
use mvad_runtime::{FirstEvents, HybridModel, ModelAlloc, ModelInfo, SolveError};
use nalgebra::{DefaultAllocator, OVector};
use serde_json::{Map, Value};

/// The most events a JSON object lists unless every one is asked for (`--all-events`,
/// `all_events=True`); `stats.events` always counts all of them.
pub const MAX_JSON_EVENTS: usize = 1000;

/// Solves keeping the records of the first `limit` events only (a long run streams the
/// rest: no table of them is built), as [`grad_json`] lists them.
pub fn solve_listing<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
    limit: usize,
) -> Result<Solution, SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let mut first = FirstEvents::new(limit);
    let mut sol = solve_with(model, params, opts, &mut first)?;
    sol.events = first.records;
    Ok(sol)
}

/// The spec's JSON object for a solution, derivatives restricted to `wrt` (with the qp keys
/// when the model has qps); the top-level `mode` is the gradient mode that ran
/// (`stats.mode`).
pub fn grad_json(info: &ModelInfo, qps: &[QpLayerInfo], sol: &Solution, wrt: &[usize]) -> Value {
    let all: Vec<usize> = (0..info.params.len()).collect();
    let mut m = Map::new();
    m.insert("model".into(), Value::from(info.name.clone()));
    m.insert("t_end".into(), num(sol.t_end));
    m.insert("params".into(), by_name(&info.params, &all, &sol.params));
    m.insert("cost".into(), num(sol.cost));
    m.insert("gradient".into(), by_name(&info.params, wrt, &sol.gradient));
    m.insert(
        "events".into(),
        Value::Array(
            sol.events
                .iter()
                .map(|e| event_json(info, e, wrt))
                .collect(),
        ),
    );
    m.insert("diagnostics".into(), diagnostics_json(&sol.diagnostics));
    m.insert("stats".into(), stats_json(&sol.stats));
    m.insert("mode".into(), Value::from(sol.stats.mode.name()));
    add_qp_keys(&mut m, qps, &info.params, sol, wrt);
    Value::Object(m)
}

/// A JSON number, or `null` for NaN/∞ (JSON has no such numbers).
pub fn num(x: f64) -> Value {
    serde_json::Number::from_f64(x)
        .map(Value::Number)
        .unwrap_or(Value::Null)
}

/// `{name: value}` over the selected indices, in the given order.
pub fn by_name(names: &[String], idx: &[usize], values: &[f64]) -> Value {
    let mut m = Map::new();
    for &k in idx {
        if let (Some(n), Some(&v)) = (names.get(k), values.get(k)) {
            m.insert(n.clone(), num(v));
        }
    }
    Value::Object(m)
}

/// One event as the spec's JSON object: index, name, t, modes, guard slope,
/// transversality, t_k' per param, the jump per state and observable, and the atoms
/// α_k = −J_k t_k' per observable and param (params restricted to `wrt`). An event without
/// t' (adjoint mode) leaves out `dt` and `atoms`, as the spec allows.
pub fn event_json(info: &ModelInfo, ev: &EventRecord, wrt: &[usize]) -> Value {
    let name = info
        .events
        .get(ev.event)
        .map(|e| e.name.clone())
        .unwrap_or_else(|| format!("event_{}", ev.event));
    let mut jump = Map::new();
    for (i, s) in info.states.iter().enumerate() {
        jump.insert(
            s.clone(),
            num(ev.jump_states.get(i).copied().unwrap_or(f64::NAN)),
        );
    }
    for (i, o) in info.observables.iter().enumerate() {
        jump.insert(
            o.clone(),
            num(ev.jump_observables.get(i).copied().unwrap_or(f64::NAN)),
        );
    }
    let mut atoms = Map::new();
    for (i, o) in info.observables.iter().enumerate() {
        let row = ev.atoms.get(i).map(Vec::as_slice).unwrap_or(&[]);
        atoms.insert(o.clone(), by_name(&info.params, wrt, row));
    }
    let mut m = Map::new();
    m.insert("index".into(), Value::from(ev.index));
    m.insert("name".into(), Value::from(name));
    m.insert("t".into(), num(ev.t));
    m.insert(
        "mode_before".into(),
        Value::from(info.mode_name(ev.mode_before)),
    );
    m.insert(
        "mode_after".into(),
        Value::from(info.mode_name(ev.mode_after)),
    );
    m.insert("guard_slope".into(), num(ev.guard_slope));
    m.insert("transversal".into(), Value::from(ev.transversal));
    let forward = !ev.dt.is_empty() || info.params.is_empty();
    if forward {
        m.insert("dt".into(), by_name(&info.params, wrt, &ev.dt));
    }
    m.insert("jump".into(), Value::Object(jump));
    if forward {
        m.insert("atoms".into(), Value::Object(atoms));
    }
    Value::Object(m)
}

/// One event of a trajectory (`mvad simulate --json`, `Model.simulate`): index, name, t, the
/// modes and the state on both sides, x(t_k⁻) and x(t_k⁺).
pub fn trajectory_event_json(info: &ModelInfo, ev: &EventRecord) -> Value {
    serde_json::json!({
        "index": ev.index,
        "name": info.events.get(ev.event).map(|x| x.name.clone()),
        "t": num(ev.t),
        "mode_before": info.mode_name(ev.mode_before),
        "mode_after": info.mode_name(ev.mode_after),
        "x_before": ev.x_before.iter().map(|&z| num(z)).collect::<Vec<_>>(),
        "x_after": ev.x_after.iter().map(|&z| num(z)).collect::<Vec<_>>(),
    })
}

/// Diagnostics as `[{kind, t, message}]`.
pub fn diagnostics_json(diags: &[Diagnostic]) -> Value {
    Value::Array(
        diags
            .iter()
            .map(|d| {
                let mut m = Map::new();
                m.insert("kind".into(), Value::from(d.kind.name()));
                m.insert("t".into(), num(d.t));
                m.insert("message".into(), Value::from(d.message.clone()));
                Value::Object(m)
            })
            .collect(),
    )
}

/// Stats as `{steps, rejected_steps, events, wall_seconds}` plus the other counters, the
/// gradient mode that ran and the bytes of an adjoint run's forward record.
pub fn stats_json(s: &Stats) -> Value {
    let mut m = Map::new();
    m.insert("steps".into(), Value::from(s.steps));
    m.insert("rejected_steps".into(), Value::from(s.rejected_steps));
    m.insert("events".into(), Value::from(s.events));
    m.insert("wall_seconds".into(), num(s.wall_seconds));
    m.insert("switch_crossings".into(), Value::from(s.switch_crossings));
    m.insert("rhs_evals".into(), Value::from(s.rhs_evals));
    m.insert("jac_evals".into(), Value::from(s.jac_evals));
    m.insert("factorizations".into(), Value::from(s.factorizations));
    m.insert("mode".into(), Value::from(s.mode.name()));
    m.insert("record_bytes".into(), Value::from(s.record_bytes));
    Value::Object(m)
}

/// `{NAME: {"value": {VAR: ..}, "active": [i, ..], "weakly_active": [i, ..],
/// "multipliers": [..]}}`, constraints numbered from 0 in declaration order.
pub fn qp_json(qps: &[QpLayerInfo], states: &[QpState]) -> Value {
    let mut m = Map::new();
    for (info, st) in qps.iter().zip(states) {
        let all: Vec<usize> = (0..info.vars.len()).collect();
        let mut q = Map::new();
        q.insert("value".into(), by_name(&info.vars, &all, &st.u));
        let list = |v: Vec<usize>| Value::Array(v.into_iter().map(Value::from).collect());
        q.insert("active".into(), list(st.active()));
        q.insert("weakly_active".into(), list(st.weakly_active()));
        q.insert(
            "multipliers".into(),
            Value::Array(st.multipliers.iter().map(|&x| num(x)).collect()),
        );
        m.insert(info.name.clone(), Value::Object(q));
    }
    Value::Object(m)
}

/// Adds `"qp"`, `"gradient_left"` and `"gradient_right"` to a `grad` object when the model
/// has qps: `gradient` stays the derivative from the right, the left one differs only at a
/// kink.
pub fn add_qp_keys(
    m: &mut Map<String, Value>,
    qps: &[QpLayerInfo],
    params: &[String],
    sol: &Solution,
    wrt: &[usize],
) {
    if qps.is_empty() {
        return;
    }
    m.insert("qp".into(), qp_json(qps, &sol.qp));
    let left = sol.gradient_left.as_deref().unwrap_or(&sol.gradient);
    m.insert("gradient_left".into(), by_name(params, wrt, left));
    m.insert("gradient_right".into(), by_name(params, wrt, &sol.gradient));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nonfinite_numbers_are_null() {
        assert_eq!(num(f64::NAN), Value::Null);
        assert_eq!(num(f64::INFINITY), Value::Null);
        assert_eq!(num(1.5), serde_json::json!(1.5));
    }
}
