//! `mvad fdcheck MODEL.hyb [--step 1e-6]`: MV-AD against central finite differences,
//! as in the paper's Table 1: per parameter the MV-AD value of dC/dθ, the central
//! difference (C(θ + h e_i) − C(θ − h e_i)) / 2h with h = step · max(|θ_i|, 1) (step · |θ_i| for a smaller θ_i), their
//! absolute and relative difference; the cosine similarity of the two gradients over
//! the `--wrt` parameters; the number of events K and their times.

use clap::Args;
use mvad::runtime::fd::fd_gradient;
use mvad::runtime::solve::solve;
use mvad::{HybridModel, ModelAlloc};
use nalgebra::DefaultAllocator;
use serde_json::{Map, Value};

use super::output::{
    capped_list, cosine, diagnostics_json, diagnostics_text, g, json_text, num, Table,
};
use super::{check_step, setup, solve_err, CliError, CmdResult, Common};

/// Arguments of `mvad fdcheck`.
#[derive(Args, Debug)]
pub struct FdcheckArgs {
    /// Common options.
    #[command(flatten)]
    pub common: Common,
    /// The step of the central differences.
    #[command(flatten)]
    pub fd: FdStep,
}

/// `--step H`, the relative step of central differences (`fdcheck`, and `measure` for its
/// plot).
#[derive(Args, Clone, Copy, Debug)]
pub struct FdStep {
    /// Relative step of the central differences.
    #[arg(long, value_name = "H", default_value_t = 1e-6)]
    pub step: f64,
}

impl FdStep {
    /// The step, or a bad-input error unless 0 < h < 1.
    pub fn checked(self) -> Result<f64, CliError> {
        check_step(self.step)?;
        Ok(self.step)
    }
}

/// Runs `mvad fdcheck`.
pub fn run<M: HybridModel>(model: &M, file: &str, args: &FdcheckArgs) -> CmdResult
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let s = setup(model, &args.common)?;
    let step = args.fd.checked()?;
    let info = model.info();
    let sol = solve(model, &s.params, &s.opts).map_err(solve_err)?;
    let mut mvad = Vec::new();
    // A central difference can fail where the model does not (a perturbation that leaves
    // the parameter's valid range, e.g. a negative time constant): such a row reports
    // the failure instead of ending the check.
    let mut fd: Vec<Result<f64, String>> = Vec::new();
    for &k in &s.wrt {
        mvad.push(sol.gradient[k]);
        match fd_gradient(model, &s.params, &s.opts, k, step).map_err(solve_err) {
            Ok(v) => fd.push(Ok(v)),
            Err(CliError::Run(msg)) => fd.push(Err(msg)),
            Err(e) => return Err(e),
        }
    }
    let (ok_mvad, ok_fd): (Vec<f64>, Vec<f64>) = mvad
        .iter()
        .zip(&fd)
        .filter_map(|(a, b)| b.as_ref().ok().map(|b| (*a, *b)))
        .unzip();
    let cos = cosine(&ok_mvad, &ok_fd);
    let times: Vec<f64> = sol.events.iter().map(|e| e.t).collect();
    let rel = |a: f64, b: f64| (a - b).abs() / a.abs().max(b.abs()).max(f64::MIN_POSITIVE);

    if args.common.json {
        let rows: Vec<Value> = s
            .wrt
            .iter()
            .enumerate()
            .map(|(i, &k)| match &fd[i] {
                Ok(f) => serde_json::json!({
                    "param": info.params[k],
                    "mvad": num(mvad[i]),
                    "fd": num(*f),
                    "abs_err": num((mvad[i] - f).abs()),
                    "rel_err": num(rel(mvad[i], *f)),
                }),
                Err(msg) => serde_json::json!({
                    "param": info.params[k],
                    "mvad": num(mvad[i]),
                    "fd": Value::Null,
                    "abs_err": Value::Null,
                    "rel_err": Value::Null,
                    "fd_error": msg,
                }),
            })
            .collect();
        let mut m = Map::new();
        m.insert("model".into(), Value::from(info.name.clone()));
        m.insert("t_end".into(), num(sol.t_end));
        m.insert("cost".into(), num(sol.cost));
        m.insert("step".into(), num(step));
        m.insert("rows".into(), Value::Array(rows));
        m.insert("cosine_similarity".into(), num(cos));
        m.insert("events".into(), Value::from(sol.events.len()));
        m.insert(
            "event_times".into(),
            Value::from(times.iter().map(|&t| num(t)).collect::<Vec<_>>()),
        );
        m.insert("diagnostics".into(), diagnostics_json(&sol.diagnostics));
        return Ok(json_text(&Value::Object(m)));
    }

    let mut out = format!(
        "model {} ({file}): dC/dθ by MV-AD and by central differences (relative step {})\n\n",
        info.name,
        g(step, 3)
    );
    let mut t = Table::new(&["param", "MV-AD", "FD", "abs err", "rel err"]);
    let mut failures = String::new();
    for (i, &k) in s.wrt.iter().enumerate() {
        match &fd[i] {
            Ok(f) => t.row(vec![
                info.params[k].clone(),
                g(mvad[i], 12),
                g(*f, 12),
                g((mvad[i] - f).abs(), 3),
                g(rel(mvad[i], *f), 3),
            ]),
            Err(msg) => {
                t.row(vec![
                    info.params[k].clone(),
                    g(mvad[i], 12),
                    "failed".into(),
                    "-".into(),
                    "-".into(),
                ]);
                failures.push_str(&format!(
                    "warning: FD for `{}` failed: {}\n",
                    info.params[k],
                    msg.trim_start_matches("error: ")
                ));
            }
        }
    }
    out.push_str(&t.render());
    out.push_str(&format!("\ncosine similarity  {}\n", g(cos, 10)));
    out.push_str(&format!("events K           {}\n", times.len()));
    out.push_str(&format!(
        "event times (s)    {}\n",
        capped_list(
            &times.iter().map(|&t| g(t, 6)).collect::<Vec<_>>(),
            "; ",
            "-"
        )
    ));
    out.push_str(&failures);
    out.push_str(&diagnostics_text(&sol.diagnostics));
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::test_support::{args, json, on_ball};
    use approx::assert_relative_eq;

    #[test]
    fn e1_table_one() {
        let out = on_ball(
            run,
            &[
                "--json", "--rtol", "1e-12", "--atol", "1e-14", "--step", "1e-5",
            ],
        )
        .expect("runs");
        let v = json(&out);
        let row = &v["rows"][0];
        assert_eq!(row["param"], "e");
        assert_relative_eq!(
            row["mvad"].as_f64().expect("n"),
            2.8314408141470055,
            max_relative = 1e-9
        );
        assert_relative_eq!(
            row["fd"].as_f64().expect("n"),
            2.8314408141470055,
            max_relative = 1e-6
        );
        assert!(row["rel_err"].as_f64().expect("n") < 1e-6);
        assert_relative_eq!(
            v["cosine_similarity"].as_f64().expect("n"),
            1.0,
            max_relative = 1e-9
        );
        assert_eq!(v["events"], 2);
        assert_relative_eq!(
            v["event_times"][1].as_f64().expect("n"),
            1.6602322277166624,
            max_relative = 1e-9
        );
    }

    /// A perturbation that leaves the valid range fails for that row only: with
    /// a = 1 + 1e-7 and the step h = 1e-6·a, a − h < 1 and √(a − 1) is NaN in the
    /// perturbed run.
    #[test]
    fn a_failed_difference_is_reported_in_its_row() {
        let src = "model M { param a = 1.0000001; param b = 2; state x = 1; \
                   flow { der(x) = -sqrt(a - 1) * b * x; } cost = integral(x); horizon 1; }";
        let m = mvad::load::load_str("m.hyb", src).expect("valid model");
        let out = run(&m, "m.hyb", &args(&["--json"])).expect("the check itself runs");
        let v = json(&out);
        assert_eq!(v["rows"][0]["param"], "a");
        assert!(v["rows"][0]["fd"].is_null(), "{out}");
        assert!(
            v["rows"][0]["fd_error"]
                .as_str()
                .is_some_and(|e| e.contains("non-finite")),
            "{out}"
        );
        // b's row is unaffected: C = (1 − e^{−k})/k with k = b √(a − 1), dC/db = √(a − 1)
        // dC/dk, dC/dk = −(e^k − 1 − k)/(k² e^k).
        let root = (1.0000001f64 - 1.0).sqrt();
        let k = 2.0 * root;
        let dcdk = -(k.exp() - 1.0 - k) / (k * k * k.exp());
        assert_relative_eq!(
            v["rows"][1]["mvad"].as_f64().expect("n"),
            root * dcdk,
            max_relative = 1e-6
        );
        assert!(v["rows"][1]["rel_err"].as_f64().expect("n") < 1e-5, "{out}");
        let text = run(&m, "m.hyb", &args(&[])).expect("runs");
        assert!(text.contains("warning: FD for `a` failed"), "{text}");
    }

    #[test]
    fn text_table_and_bad_step() {
        let out = on_ball(run, &["--wrt", "e"]).expect("runs");
        assert!(out.contains("param  MV-AD"), "{out}");
        assert!(
            out.contains("event times (s)    0.638551; 1.66023"),
            "{out}"
        );
        let err = on_ball(run, &["--step", "0"]).err();
        assert_eq!(err.map(|e| e.status()), Some(2));
    }
}
