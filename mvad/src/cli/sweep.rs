//! `mvad sweep MODEL.hyb --over NAME=START:STOP:COUNT`: one run per value of parameter
//! NAME (COUNT values from START to STOP inclusive), as in the paper's Table 2: the value,
//! the guard slope |∇ₓg·f| of the first event, whether it is transversal, the atom
//! magnitude ‖α‖ (over the `--wrt` parameters) of `--observable` (default: the first
//! observable) and the event time; plus dt/dNAME, C and dC/dNAME. `--json` gives every
//! event of every run. The runs go across cores (`mvad::batch::par_map`), in input order,
//! identical to a serial loop; a progress bar is drawn only on a terminal.

use clap::Args;
use mvad::batch::par_map;
use mvad::runtime::solve::solve;
use mvad::{HybridModel, ModelAlloc};
use nalgebra::{Const, DefaultAllocator, OVector};
use serde_json::{Map, Value};

use super::output::{diagnostics_json, g, json_text, num, Table};
use super::progress::Progress;
use super::{
    observable_index, param_index, parse_number, setup, solve_err, CliError, CmdResult, Common,
};
use mvad::json::grad_json;
use mvad::json::qp_json;

/// Arguments of `mvad sweep`.
#[derive(Args, Debug)]
pub struct SweepArgs {
    /// Common options.
    #[command(flatten)]
    pub common: Common,
    /// The parameter and its values: NAME=START:STOP:COUNT (COUNT ≥ 1 values, STOP included).
    #[arg(long, value_name = "NAME=START:STOP:COUNT", allow_hyphen_values = true)]
    pub over: String,
    /// The observable whose atoms are shown (default: the first one).
    #[arg(long, value_name = "NAME")]
    pub observable: Option<String>,
}

/// The parsed `--over` value.
#[derive(Clone, Debug, PartialEq)]
pub struct Over {
    /// The parameter's index.
    pub param: usize,
    /// The values.
    pub values: Vec<f64>,
}

/// Parses `NAME=START:STOP:COUNT` against the parameter names.
pub fn parse_over(names: &[String], text: &str) -> Result<Over, CliError> {
    let bad = || {
        CliError::Input(format!(
            "error: --over expects NAME=START:STOP:COUNT (e.g. v0=-0.5:-5:10), got `{text}`"
        ))
    };
    let (name, range) = text.split_once('=').ok_or_else(bad)?;
    let param = param_index(names, name.trim(), "--over")?;
    let parts: Vec<&str> = range.split(':').collect();
    let [a, b, c] = parts[..] else {
        return Err(bad());
    };
    let start = parse_number(a, "error: --over START")?;
    let stop = parse_number(b, "error: --over STOP")?;
    let count: usize = c.trim().parse().map_err(|_| bad())?;
    if count == 0 || count > 100_000 {
        return Err(CliError::Input(format!(
            "error: --over COUNT must be between 1 and 100000, got {count}"
        )));
    }
    let values = if count == 1 {
        vec![start]
    } else {
        (0..count)
            .map(|i| start + (stop - start) * i as f64 / (count - 1) as f64)
            .collect()
    };
    Ok(Over { param, values })
}

/// Runs `mvad sweep`.
pub fn run<M: HybridModel + Clone + Send>(model: &M, file: &str, args: &SweepArgs) -> CmdResult
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let s = setup(model, &args.common)?;
    let info = model.info();
    let over = parse_over(&info.params, &args.over)?;
    let obs = match &args.observable {
        None => 0,
        Some(name) => observable_index(info, name)?,
    };
    let k = over.param;
    let pname = &info.params[k];
    let progress = Progress::new(over.values.len(), &format!("sweep {pname}"));
    // One run per value across cores; the first failure in input order is reported, as a
    // serial loop would.
    let base: Vec<f64> = s.params.iter().copied().collect();
    let opts = &s.opts;
    let results = par_map(
        model,
        &over.values,
        |m, &value| {
            let mut p = OVector::<f64, M::P>::from_iterator_generic(
                m.nparams(),
                Const::<1>,
                base.iter().copied(),
            );
            p[k] = value;
            solve(m, &p, opts)
        },
        &|| progress.inc(),
    );
    progress.finish();
    let mut runs = Vec::with_capacity(over.values.len());
    for (&value, result) in over.values.iter().zip(results) {
        let at = |m: &str| format!("{m} (at {pname} = {})", g(value, 10));
        let sol = result
            .map_err(|e| CliError::Run(format!("error: {}", at(&e.to_string()))))?
            .map_err(|e| solve_err(e).map_message(at))?;
        runs.push((value, sol));
    }

    let atom_norm = |atoms: &[Vec<f64>]| -> f64 {
        atoms
            .get(obs)
            .map(|a| s.wrt.iter().map(|&j| a[j] * a[j]).sum::<f64>().sqrt())
            .unwrap_or(0.0)
    };

    if args.common.json {
        let rows: Vec<Value> = runs
            .iter()
            .map(|(value, sol)| {
                let mut m = Map::new();
                m.insert("value".into(), num(*value));
                let first = sol.events.first();
                m.insert(
                    "guard_slope".into(),
                    first
                        .map(|e| num(e.guard_slope.abs()))
                        .unwrap_or(Value::Null),
                );
                m.insert(
                    "transversal".into(),
                    first
                        .map(|e| Value::from(e.transversal))
                        .unwrap_or(Value::Null),
                );
                m.insert(
                    "atom_magnitude".into(),
                    first
                        .map(|e| num(atom_norm(&e.atoms)))
                        .unwrap_or(Value::Null),
                );
                m.insert(
                    "event_time".into(),
                    first.map(|e| num(e.t)).unwrap_or(Value::Null),
                );
                if !model.qps().is_empty() {
                    m.insert("qp".into(), qp_json(model.qps(), &sol.qp));
                }
                m.insert("diagnostics".into(), diagnostics_json(&sol.diagnostics));
                m.insert("run".into(), grad_json(info, model.qps(), sol, &s.wrt));
                Value::Object(m)
            })
            .collect();
        let v = serde_json::json!({
            "model": info.name, "param": pname, "observable": info.observables.get(obs),
            "rows": rows,
        });
        return Ok(json_text(&v));
    }

    let obs_name = info
        .observables
        .get(obs)
        .cloned()
        .unwrap_or_else(|| "-".into());
    let mut out = format!(
        "model {} ({file}): sweep of {pname} over {} values; first event of each run, atoms of `{obs_name}`\n\n",
        info.name,
        runs.len()
    );
    let mut t = Table::new(&[
        pname.clone(),
        "K".into(),
        "guard slope |∇g·f|".into(),
        "transversal".into(),
        "atom |α|".into(),
        "event time".into(),
        format!("dt/d{pname}"),
        "C".into(),
        format!("dC/d{pname}"),
    ]);
    let mut warnings = String::new();
    for (value, sol) in &runs {
        let mut row = vec![g(*value, 8), sol.events.len().to_string()];
        match sol.events.first() {
            Some(e) => row.extend([
                g(e.guard_slope.abs(), 6),
                if e.transversal { "True" } else { "False" }.to_string(),
                g(atom_norm(&e.atoms), 6),
                g(e.t, 6),
                g(e.dt[k], 6),
            ]),
            None => row.extend(["-", "-", "-", "-", "-"].map(String::from)),
        }
        row.push(g(sol.cost, 10));
        row.push(g(sol.gradient[k], 10));
        t.row(row);
        for d in &sol.diagnostics {
            warnings.push_str(&format!(
                "warning: at {pname} = {}: {} at t = {}: {}\n",
                g(*value, 8),
                d.kind.name(),
                g(d.t, 8),
                d.message
            ));
        }
    }
    out.push_str(&t.render());
    out.push_str(&warnings);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::test_support::{json, lines_with, on_ball, tight};
    use approx::assert_relative_eq;

    #[test]
    fn parses_ranges() {
        let names: Vec<String> = ["a", "v0"].map(String::from).to_vec();
        let o = parse_over(&names, "v0=-0.5:-5:10").expect("ok");
        assert_eq!(o.param, 1);
        assert_eq!(o.values.len(), 10);
        assert_relative_eq!(o.values[0], -0.5);
        assert_relative_eq!(o.values[9], -5.0);
        assert_relative_eq!(o.values[1], -1.0);
        assert_eq!(parse_over(&names, "a=1:2:1").expect("ok").values, vec![1.0]);
        for bad in [
            "v0",
            "v0=1:2",
            "v0=1:2:x",
            "v0=1:2:0",
            "q=1:2:3",
            "v0=a:2:3",
            "v0=1:2:3:4",
        ] {
            assert_eq!(
                parse_over(&names, bad).err().map(|e| e.status()),
                Some(2),
                "{bad}"
            );
        }
    }

    /// E2 (h0 = 1): the first impact of the ball thrown down at v0 has
    /// t = (v0 + sqrt(v0² + 2 g h0)) / g and |∇g·f| = sqrt(v0² + 2 g h0).
    #[test]
    fn e2_table_two_against_the_closed_form() {
        let out = on_ball(
            run,
            &tight(&[
                "--over=v0=-0.5:-5:10",
                "--set=h0=1",
                "--observable=height",
                "--json",
            ]),
        )
        .expect("runs");
        let v = json(&out);
        let rows = v["rows"].as_array().expect("rows");
        assert_eq!(rows.len(), 10);
        for r in rows {
            let v0 = r["value"].as_f64().expect("v0");
            let speed = (v0 * v0 + 2.0 * 9.81).sqrt();
            assert_relative_eq!(
                r["guard_slope"].as_f64().expect("n"),
                speed,
                max_relative = 1e-8
            );
            assert_relative_eq!(
                r["event_time"].as_f64().expect("n"),
                (v0 + speed) / 9.81,
                max_relative = 1e-8
            );
            assert_eq!(r["transversal"], true);
            assert!(r["atom_magnitude"].as_f64().expect("n") < 1e-12);
        }
    }

    #[test]
    fn text_table() {
        let out = on_ball(run, &["--over", "e=0.5:0.9:3"]).expect("runs");
        assert!(out.contains("guard slope |∇g·f|"), "{out}");
        assert_eq!(lines_with(&out, "True"), 3, "{out}");
    }
}
