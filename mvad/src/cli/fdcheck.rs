//! `mvad fdcheck MODEL.hyb [--step H]`: MV-AD against central finite differences,
//! as in the paper's Table 1: per parameter the MV-AD value of dC/dθ, the central
//! difference (C(θ + h e_i) − C(θ − h e_i)) / 2h with h = step · max(|θ_i|, 1) (step · |θ_i|
//! for a smaller θ_i) and the difference's own uncertainty, their absolute and relative
//! difference and whether they agree within that uncertainty; the cosine similarity of the
//! two gradients over the `--wrt` parameters; the number of events K and their times.
//!
//! Without `--step` each parameter's step is found on a ladder of relative steps 1e-2 …
//! 1e-8 ([`fd_plateau`]: where neighbouring steps agree best, their difference being the
//! uncertainty); with `--step H` the difference is taken at H and its uncertainty is the
//! difference from the one at H/10. The differences' runs are at 1/1000 of the tolerances
//! (see [`reference_options`]), so they are a reference for MV-AD at the tolerances asked for. One fixed step is not right for every parameter: at the
//! default tolerance a time constant of 1e-8 perturbed by 1e-6 of itself moves C by less
//! than the run's error, and the difference is off by 1 %.

use clap::Args;
use mvad::runtime::error::SolveError;
use mvad::runtime::fd::{fd_gradient, fd_plateau, FdEstimate, STEP_LADDER};
use mvad::runtime::solution::{Options, Solution};
use mvad::runtime::solve::solve;
use mvad::setup::Setup;
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
    /// Relative step of the central differences (default: found per parameter on a ladder
    /// of steps 1e-2 … 1e-8, where neighbouring steps agree best).
    #[arg(long, value_name = "H")]
    pub step: Option<f64>,
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
    if let Some(h) = args.step {
        check_step(h)?;
    }
    let info = model.info();
    let sol = solve(model, &s.params, &s.opts).map_err(solve_err)?;
    let mut mvad = Vec::new();
    let mut own = Vec::new();
    // A central difference can fail where the model does not (a perturbation that leaves
    // the parameter's valid range, e.g. a negative time constant): such a row reports
    // the failure instead of ending the check.
    let mut fd: Vec<Result<FdEstimate, String>> = Vec::new();
    for &k in &s.wrt {
        mvad.push(sol.gradient[k]);
        own.push(own_error(&sol, &s.opts, k, sol.gradient[k]));
        match difference(model, &s, k, args.step).map_err(solve_err) {
            Ok(v) => fd.push(Ok(v)),
            Err(CliError::Run(msg)) => fd.push(Err(msg)),
            Err(e) => return Err(e),
        }
    }
    let (ok_mvad, ok_fd): (Vec<f64>, Vec<f64>) = mvad
        .iter()
        .zip(&fd)
        .filter_map(|(a, b)| b.as_ref().ok().map(|b| (*a, b.value)))
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
                    "fd": num(f.value),
                    "fd_step": num(f.rel_step),
                    "fd_uncertainty": num(f.uncertainty),
                    "abs_err": num((mvad[i] - f.value).abs()),
                    "rel_err": num(rel(mvad[i], f.value)),
                    "consistent": consistent(mvad[i], f, own[i]).map_or(Value::Null, Value::from),
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
        m.insert("step".into(), args.step.map_or(Value::Null, num));
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

    let steps = match args.step {
        Some(h) => format!("relative step {}, uncertainty from the step h/10", g(h, 3)),
        None => "relative step per parameter where steps 1e-2 … 1e-8 agree best".into(),
    };
    let mut out = format!(
        "model {} ({file}): dC/dθ by MV-AD and by central differences ({steps})\n\n",
        info.name,
    );
    let mut t = Table::new(&[
        "param", "MV-AD", "FD", "FD ±", "step", "abs err", "rel err", "agree",
    ]);
    let mut disagree = Vec::new();
    let mut undecided = Vec::new();
    let mut failures = String::new();
    for (i, &k) in s.wrt.iter().enumerate() {
        match &fd[i] {
            Ok(f) => {
                let agree = consistent(mvad[i], f, own[i]);
                match agree {
                    Some(false) => disagree.push(format!("`{}`", info.params[k])),
                    None => undecided.push(format!("`{}`", info.params[k])),
                    Some(true) => {}
                }
                t.row(vec![
                    info.params[k].clone(),
                    g(mvad[i], 12),
                    g(f.value, 12),
                    g(f.uncertainty, 2),
                    g(f.rel_step, 1),
                    g((mvad[i] - f.value).abs(), 3),
                    g(rel(mvad[i], f.value), 3),
                    agree.map_or("?", |a| if a { "yes" } else { "NO" }).into(),
                ])
            }
            Err(msg) => {
                t.row(vec![
                    info.params[k].clone(),
                    g(mvad[i], 12),
                    "failed".into(),
                    "-".into(),
                    "-".into(),
                    "-".into(),
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
    if !disagree.is_empty() {
        out.push_str(&format!(
            "\nMV-AD and FD differ by more than twice the FD's uncertainty plus MV-AD's own \
             error at this tolerance for {}\n",
            disagree.join(", ")
        ));
    }
    if !undecided.is_empty() {
        out.push_str(&format!(
            "\nthe differences decide nothing for {}: their uncertainty is unknown or larger \
             than the derivative (C may have a kink or a jump in the parameter there)\n",
            undecided.join(", ")
        ));
    }
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

/// The options of the differences' runs: the check's at 1/1000 of its tolerances (not below
/// rtol 1e-12, atol 1e-14). A difference of C computed at the check's own tolerance measures
/// the derivative of C's error too, which is smooth in θ where the steps are (so no step
/// sweep reveals it) and of the order of the tolerance over θ's scale: at rtol 1e-8 the
/// cart's dC/dk came out 8e-7 off that way while MV-AD was right to 2e-9.
fn reference_options(opts: &Options) -> Options {
    Options {
        rtol: (opts.rtol * 1e-3).max(1e-12).min(opts.rtol),
        atol: (opts.atol * 1e-3).max(1e-14).min(opts.atol),
        ..opts.clone()
    }
}

/// The central difference for parameter k: at `step` with the uncertainty from the
/// difference at step/10, or on the default ladder ([`fd_plateau`]).
fn difference<M: HybridModel>(
    model: &M,
    s: &Setup<M>,
    k: usize,
    step: Option<f64>,
) -> Result<FdEstimate, SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let opts = reference_options(&s.opts);
    let Some(h) = step else {
        return fd_plateau(model, &s.params, &opts, k, &STEP_LADDER);
    };
    let value = fd_gradient(model, &s.params, &opts, k, h)?;
    let finer = fd_gradient(model, &s.params, &opts, k, h / 10.0);
    Ok(FdEstimate {
        value,
        rel_step: h,
        uncertainty: finer.map_or(f64::NAN, |v| (v - value).abs()),
    })
}

/// Whether the MV-AD value `a` agrees with the difference `f`: within twice the difference's
/// uncertainty plus `a`'s own, `own` (see [`own_error`]). None when the comparison decides
/// nothing: the difference's uncertainty is unknown, or twice it exceeds both values and
/// `own` (the steps of the ladder disagree by more than the derivative itself, as they do
/// where C has a kink or a jump in θ: any value would pass).
fn consistent(a: f64, f: &FdEstimate, own: f64) -> Option<bool> {
    let u = f.uncertainty;
    let decides = u.is_finite() && 2.0 * u <= a.abs().max(f.value.abs()).max(own);
    decides.then(|| (a - f.value).abs() <= 2.0 * u + own)
}

/// The error MV-AD's value `a` of dC/dθ_k may have at the run's tolerances: ten times
/// atol + rtol·|a|, plus the global error estimate of the entry where the run has one.
fn own_error(sol: &Solution, opts: &Options, k: usize, a: f64) -> f64 {
    let estimate = sol
        .error_estimate
        .as_ref()
        .and_then(|e| e.gradient.get(k).copied())
        .filter(|e| e.is_finite())
        .unwrap_or(0.0);
    10.0 * (opts.atol + opts.rtol * a.abs()) + estimate
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
        let out =
            run(&m, "m.hyb", &args(&["--json", "--step", "1e-6"])).expect("the check itself runs");
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
        let text = run(&m, "m.hyb", &args(&["--step", "1e-6"])).expect("runs");
        assert!(text.contains("warning: FD for `a` failed"), "{text}");
    }

    /// One fixed step is not right for every parameter: dC/dτ of the stiff relay (τ = 1e-8,
    /// dC/dτ = 1.5) by the old default, a step of 1e-6 of τ at the check's own rtol 1e-8,
    /// came out 1.5127 (0.8 % off). On the ladder, at 1/1000 of the tolerance, the difference
    /// is within 1e-4 of it and states an uncertainty that covers its error (its floor is C's
    /// own run-to-run error, ~1e-15 against a δC of 3e-11 at the chosen step: 3e-5; it read
    /// 1.2e-7 or 1.7e-5 off depending on where `auto` switched to Rosenbrock), and every
    /// parameter of the relay and of the saturated cart (where a difference at the check's
    /// own tolerance was off by 8e-7 of dC/dk) agrees with MV-AD.
    #[test]
    fn ladder_differences_are_references_for_every_parameter() {
        for (file, src) in [
            (
                "stiff_relay.hyb",
                include_str!("../../../models/stiff_relay.hyb"),
            ),
            ("qp_cart.hyb", include_str!("../../../models/qp_cart.hyb")),
        ] {
            let m = mvad::load::load_str(file, src).expect("valid model");
            let v = json(&run(&m, file, &args(&["--json"])).expect("runs"));
            assert!(v["step"].is_null());
            for row in v["rows"].as_array().expect("rows") {
                assert_eq!(row["consistent"], true, "{file}: {row}");
                let unc = row["fd_uncertainty"].as_f64().expect("n");
                assert!(unc.is_finite() && unc >= 0.0, "{row}");
            }
            if file == "stiff_relay.hyb" {
                let tau = &v["rows"][0];
                assert_eq!(tau["param"], "tau");
                let fd = tau["fd"].as_f64().expect("n");
                let unc = tau["fd_uncertainty"].as_f64().expect("n");
                assert!((fd - 1.5).abs() < 1e-4, "{tau}");
                assert!((fd - 1.5).abs() <= 2.0 * unc, "{tau}");
            }
        }
    }

    /// Where C jumps in a parameter (a sample at t = 0 that a smaller `offset` moves before
    /// the run) the ladder's steps disagree by more than the derivative: the row decides
    /// nothing (null, `?`), not `yes`, and the run itself reports the kink.
    #[test]
    fn a_jump_in_the_parameter_decides_nothing() {
        let src = "model Sampled {
            param period = 0.25; param offset = 0; param k = 0.5;
            state y = 1; state u = 0;
            flow { der(y) = u - y; der(u) = 0; }
            event sample every period from offset { u = -k * y; }
            cost = integral(y^2);
            horizon 1;
        }";
        let m = mvad::load::load_str("s.hyb", src).expect("valid model");
        let v = json(&run(&m, "s.hyb", &args(&["--json"])).expect("runs"));
        let rows = v["rows"].as_array().expect("rows");
        let row = |name: &str| rows.iter().find(|r| r["param"] == name).expect("row");
        let offset = row("offset");
        assert!(offset["consistent"].is_null(), "{offset}");
        assert!(
            offset["fd_uncertainty"].as_f64().expect("n") > 1.0,
            "{offset}"
        );
        assert_eq!(row("k")["consistent"], true, "{}", row("k"));
        assert_eq!(row("period")["consistent"], true, "{}", row("period"));
        let text = run(&m, "s.hyb", &args(&[])).expect("runs");
        assert!(text.contains("decide nothing for `offset`"), "{text}");
        assert!(text.contains("warning: kink at t = 0"), "{text}");
        assert!(
            text.contains("time event `sample` fires at t = 0"),
            "{text}"
        );
    }

    /// With `--step H` the difference is the one at H and its uncertainty the difference
    /// from the one at H/10.
    #[test]
    fn an_explicit_step_is_kept() {
        let out = on_ball(run, &["--json", "--wrt", "e", "--step", "1e-4"]).expect("runs");
        let v = json(&out);
        assert_eq!(v["step"].as_f64(), Some(1e-4));
        let row = &v["rows"][0];
        assert_eq!(row["fd_step"].as_f64(), Some(1e-4));
        assert!(row["fd_uncertainty"].as_f64().expect("n") < 1e-6, "{row}");
        assert_eq!(row["consistent"], true, "{row}");
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
