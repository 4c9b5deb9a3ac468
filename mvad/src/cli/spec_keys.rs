//! The keys the language spec requires in the object `mvad grad --json` prints. Shared
//! by the unit tests and the end-to-end tests (`tests/cli.rs` includes this file by path),
//! so the list is written once.

use serde_json::Value;

/// Top-level keys.
pub const GRAD_KEYS: [&str; 8] = [
    "model",
    "t_end",
    "params",
    "cost",
    "gradient",
    "events",
    "diagnostics",
    "stats",
];

/// Keys of every event object.
pub const EVENT_KEYS: [&str; 10] = [
    "index",
    "name",
    "t",
    "mode_before",
    "mode_after",
    "guard_slope",
    "transversal",
    "dt",
    "jump",
    "atoms",
];

/// Event keys an adjoint run (`stats.mode` = `adjoint`) may leave out: forward quantities.
pub const ADJOINT_OPTIONAL_EVENT_KEYS: [&str; 2] = ["dt", "atoms"];

/// Keys of every diagnostic object.
pub const DIAGNOSTIC_KEYS: [&str; 3] = ["kind", "t", "message"];

/// Keys of the stats object.
pub const STATS_KEYS: [&str; 4] = ["steps", "rejected_steps", "events", "wall_seconds"];

/// The spec's keys that `v` lacks, each named by its path (`events[1].dt`); empty if none.
/// The events of an adjoint run need not have [`ADJOINT_OPTIONAL_EVENT_KEYS`].
pub fn missing_spec_keys(v: &Value) -> Vec<String> {
    let adjoint = v["stats"]["mode"] == "adjoint";
    let optional = |list: &str, k: &str| {
        adjoint && list == "events" && ADJOINT_OPTIONAL_EVENT_KEYS.contains(&k)
    };
    let mut missing: Vec<String> = GRAD_KEYS
        .iter()
        .filter(|k| v.get(**k).is_none())
        .map(|k| k.to_string())
        .collect();
    for (list, keys) in [
        ("events", &EVENT_KEYS[..]),
        ("diagnostics", &DIAGNOSTIC_KEYS),
    ] {
        for (i, item) in v[list].as_array().into_iter().flatten().enumerate() {
            missing.extend(
                keys.iter()
                    .filter(|k| item.get(**k).is_none() && !optional(list, k))
                    .map(|k| format!("{list}[{i}].{k}")),
            );
        }
    }
    missing.extend(
        STATS_KEYS
            .iter()
            .filter(|k| v["stats"].get(**k).is_none())
            .map(|k| format!("stats.{k}")),
    );
    missing
}
