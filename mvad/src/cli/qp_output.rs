//! The readable qp part of `grad`: each qp's solution, active and weakly active constraints
//! and multipliers at the end of the run (the JSON keys come from [`mvad::json::qp_json`]).

use mvad::qp::{QpLayerInfo, QpState};

use super::output::{g, join_or, Table};

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
