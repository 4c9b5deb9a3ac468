//! The qp part of `grad` and `sweep`: each qp's solution, active and weakly active
//! constraints and multipliers at the end of the run, and the one-sided gradients at a
//! kink (the spec's `"qp"`, `"gradient_left"` and `"gradient_right"`).

use mvad::qp::{QpLayerInfo, QpState};
use mvad::runtime::solution::Solution;
use serde_json::{Map, Value};

use super::output::{by_name, g, join_or, num, Table};

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

/// The readable form: one table row per qp variable, then the constraints.
pub fn qp_text(qps: &[QpLayerInfo], states: &[QpState]) -> String {
    let mut s = String::new();
    for (info, st) in qps.iter().zip(states) {
        let mut t = Table::new(&["variable", "value"]);
        for (v, &u) in info.vars.iter().zip(&st.u) {
            t.row(vec![format!("{}.{v}", info.name), g(u, 15)]);
        }
        s.push_str(&format!("\nqp {}:\n", info.name));
        s.push_str(&t.render());
        let ids = |v: Vec<usize>| v.iter().map(|i| i.to_string()).collect::<Vec<_>>();
        s.push_str(&format!(
            "  active constraints: {}; weakly active (kinks): {}\n  multipliers: {}\n",
            join_or(&ids(st.active()), ", ", "none"),
            join_or(&ids(st.weakly_active()), ", ", "none"),
            join_or(
                &st.multipliers.iter().map(|&x| g(x, 10)).collect::<Vec<_>>(),
                ", ",
                "none"
            ),
        ));
    }
    s
}
