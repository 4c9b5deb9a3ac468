//! `mvad workprec MODEL.hyb`: error against wall time over tolerances 1e-3 … 1e-12.
//!
//! For each rtol (atol = rtol · `--atol-ratio`), two ways to get C and dC/dθ:
//! - MV-AD: one run with sensitivities;
//! - central FD: one primal run for C and two primal runs per `--wrt` parameter, with
//!   relative step `--step` (default 1e-6, the paper's: the differenced runs take
//!   nearly the same steps, so their tolerance-level errors largely cancel and a small
//!   step beats the textbook rtol^(1/3), which is far too coarse for models whose cost
//!   has large higher derivatives, such as the thermostat's twelve compounding switches).
//!
//! Errors are relative to a reference: `--reference C=VALUE` for the cost and
//! `--reference NAME=VALUE` for dC/dNAME, or else an MV-AD run at rtol 1e-13. The error
//! of dC/dθ is max_i |Δ_i| / max_i |ref_i| over the `--wrt` parameters. Wall times are
//! means over repeated runs (at least 20 ms of work, at most 200 repetitions).
//! `--plot FILE.svg|png` draws both errors against wall time, log-log.

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use mvad::runtime::error::SolveError;
use mvad::runtime::solution::{Options, Solution};
use mvad::runtime::solve::solve;
use mvad::suite::{grad_error, rel_error};
use mvad::{fd_gradient, HybridModel, ModelAlloc};
use nalgebra::{DefaultAllocator, OVector};
use serde_json::Value;

use super::output::{g, json_text, num, Table};
use super::plot::{format_of, workprec as plot_workprec, Curve};
use super::progress::Progress;
use super::{check_step, param_index, parse_number, setup, solve_err, CliError, CmdResult, Common};

/// Arguments of `mvad workprec`.
#[derive(Args, Debug)]
pub struct WorkprecArgs {
    /// Common options.
    #[command(flatten)]
    pub common: Common,
    /// Reference values: `C=VALUE` for the cost, `NAME=VALUE` for dC/dNAME (repeatable).
    #[arg(long, value_name = "NAME=VALUE")]
    pub reference: Vec<String>,
    /// Relative step of the central differences.
    #[arg(long, value_name = "H", default_value_t = 1e-6)]
    pub step: f64,
    /// atol = rtol · RATIO.
    #[arg(long = "atol-ratio", value_name = "RATIO", default_value_t = 1e-2)]
    pub atol_ratio: f64,
    /// Draw the error against wall time into FILE (.svg or .png), log-log.
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
}

/// The tolerances of the diagram.
pub const TOLERANCES: [f64; 10] = [
    1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12,
];

/// One row: tolerance, and for MV-AD and FD the wall time, C and its error, dC/dθ and its error.
#[derive(Clone, Debug)]
struct Row {
    rtol: f64,
    atol: f64,
    mvad: Point,
    fd: Point,
}

/// One point of the diagram: wall time, C, dC/dθ and their errors against the reference.
#[derive(Clone, Debug)]
pub(super) struct Point {
    pub(super) seconds: f64,
    cost: f64,
    pub(super) cost_err: f64,
    grad: Vec<f64>,
    pub(super) grad_err: f64,
    step: f64,
}

/// The reference values the errors are measured against: C and dC/dθ over `--wrt`.
pub(super) struct Reference {
    pub(super) cost: f64,
    pub(super) grad: Vec<f64>,
}

impl Point {
    /// A point with its errors against `r`.
    fn scored(seconds: f64, cost: f64, grad: Vec<f64>, step: f64, r: &Reference) -> Point {
        Point {
            seconds,
            cost,
            cost_err: rel_error(cost, r.cost),
            grad_err: grad_error(&grad, &r.grad),
            grad,
            step,
        }
    }
}

/// Mean wall time of `f` over enough repetitions, and its last result.
pub(super) fn timed<T>(
    mut f: impl FnMut() -> Result<T, SolveError>,
) -> Result<(f64, T), SolveError> {
    let start = Instant::now();
    let mut out = f()?;
    let mut reps = 1u32;
    while start.elapsed().as_secs_f64() < 0.02 && reps < 200 {
        out = f()?;
        reps += 1;
    }
    Ok((start.elapsed().as_secs_f64() / f64::from(reps), out))
}

/// Runs `mvad workprec`.
pub fn run<M: HybridModel>(model: &M, file: &str, args: &WorkprecArgs) -> CmdResult
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let s = setup(model, &args.common)?;
    let info = model.info();
    if let Some(p) = &args.plot {
        format_of(p)?;
    }
    check_step(args.step)?;
    if !(args.atol_ratio.is_finite() && args.atol_ratio > 0.0) {
        return Err(CliError::Input(format!(
            "error: --atol-ratio must be positive, got {}",
            args.atol_ratio
        )));
    }
    let wrt = &s.wrt;

    // Reference values: given, or a tight MV-AD run.
    let mut ref_cost = None;
    let mut ref_grad: Vec<Option<f64>> = vec![None; info.params.len()];
    for item in &args.reference {
        let (name, value) = item.split_once('=').ok_or_else(|| {
            CliError::Input(format!(
                "error: --reference expects NAME=VALUE, got `{item}`"
            ))
        })?;
        let value = parse_number(value, &format!("error: --reference {}", name.trim()))?;
        match name.trim() {
            "C" | "cost" => ref_cost = Some(value),
            other => {
                let k = param_index(
                    &info.params,
                    other,
                    "--reference (use C=VALUE for the cost)",
                )?;
                ref_grad[k] = Some(value);
            }
        }
    }
    let need_run = ref_cost.is_none() || wrt.iter().any(|&k| ref_grad[k].is_none());
    let mut source = "given".to_string();
    if need_run {
        // The tightest reference the model allows: rtol 1e-13, loosened a decade at a time
        // (to 1e-11) when rounding makes the tighter run fail (a stiff model's sensitivity
        // equation can); the table says which rtol the reference used.
        let attempt = |rtol: f64| {
            let o = Options {
                rtol,
                atol: 1e-2 * rtol,
                ..s.opts.clone()
            };
            solve(model, &s.params, &o).map(|sol| (rtol, sol))
        };
        let (rtol, sol) = attempt(1e-13)
            .or_else(|_| attempt(1e-12))
            .or_else(|_| attempt(1e-11))
            .map_err(solve_err)?;
        ref_cost.get_or_insert(sol.cost);
        for &k in wrt {
            ref_grad[k].get_or_insert(sol.gradient[k]);
        }
        source = if args.reference.is_empty() {
            format!("MV-AD at rtol {rtol:e}")
        } else {
            format!("given, the rest MV-AD at rtol {rtol:e}")
        };
    }
    let reference = Reference {
        cost: ref_cost.unwrap_or(f64::NAN),
        grad: wrt
            .iter()
            .map(|&k| ref_grad[k].unwrap_or(f64::NAN))
            .collect(),
    };

    let progress = Progress::new(TOLERANCES.len(), "workprec");
    let mut rows = Vec::new();
    for &rtol in &TOLERANCES {
        let atol = rtol * args.atol_ratio;
        let o = Options {
            rtol,
            atol,
            ..s.opts.clone()
        };
        let mv = mvad_point(model, &s.params, &o, wrt, &reference).map_err(solve_err)?;
        let fd = fd_point(model, &s.params, &o, wrt, args.step, &reference).map_err(solve_err)?;
        rows.push(Row {
            rtol,
            atol,
            mvad: mv,
            fd,
        });
        progress.inc();
    }
    progress.finish();

    if let Some(path) = &args.plot {
        let curve = |label: &str, f: &dyn Fn(&Row) -> (f64, f64)| Curve {
            label: label.to_string(),
            points: rows.iter().map(f).collect(),
        };
        let panels = vec![
            (
                "relative error of C".to_string(),
                vec![
                    curve("MV-AD", &|r| (r.mvad.seconds, r.mvad.cost_err)),
                    curve("central FD (primal run)", &|r| {
                        (r.fd.seconds, r.fd.cost_err)
                    }),
                ],
            ),
            (
                "relative error of dC/dθ".to_string(),
                vec![
                    curve("MV-AD", &|r| (r.mvad.seconds, r.mvad.grad_err)),
                    curve("central FD", &|r| (r.fd.seconds, r.fd.grad_err)),
                ],
            ),
        ];
        plot_workprec(
            path,
            &format!("{}: error against wall time", info.name),
            &panels,
        )?;
    }

    let names: Vec<String> = wrt.iter().map(|&k| info.params[k].clone()).collect();
    if args.common.json {
        // {NAME: value} over the `--wrt` parameters.
        let named = |values: &[f64]| -> Value {
            let pairs = names.iter().zip(values);
            Value::Object(pairs.map(|(n, v)| (n.clone(), num(*v))).collect())
        };
        let point = |p: &Point| {
            serde_json::json!({
                "wall_seconds": num(p.seconds),
                "cost": num(p.cost),
                "cost_error": num(p.cost_err),
                "gradient": named(&p.grad),
                "gradient_error": num(p.grad_err),
            })
        };
        let rows_json: Vec<Value> = rows
            .iter()
            .map(|r| {
                let mut fd = point(&r.fd);
                if let Value::Object(m) = &mut fd {
                    m.insert("step".into(), num(r.fd.step));
                }
                serde_json::json!({
                    "rtol": num(r.rtol), "atol": num(r.atol),
                    "mvad": point(&r.mvad), "fd": fd,
                })
            })
            .collect();
        let v = serde_json::json!({
            "model": info.name, "wrt": names,
            "reference": {"cost": num(reference.cost), "gradient": named(&reference.grad), "source": source},
            "rows": rows_json,
        });
        return Ok(json_text(&v));
    }

    let mut out = format!(
        "model {} ({file}): error against wall time, w.r.t. {}\nreference ({source}): C = {}, dC/dθ = [{}]\n\
         errors are relative; dC/dθ error = max |Δ| / max |ref| over the parameters\n\n",
        info.name,
        names.join(", "),
        g(reference.cost, 15),
        reference.grad.iter().map(|&v| g(v, 15)).collect::<Vec<_>>().join(", ")
    );
    let mut t = Table::new(&[
        "rtol",
        "MV-AD time",
        "MV-AD err C",
        "MV-AD err dC",
        "FD time",
        "FD err C",
        "FD err dC",
        "FD step",
    ]);
    for r in &rows {
        t.row(vec![
            format!("{:.0e}", r.rtol),
            format!("{} s", g(r.mvad.seconds, 3)),
            g(r.mvad.cost_err, 2),
            g(r.mvad.grad_err, 2),
            format!("{} s", g(r.fd.seconds, 3)),
            g(r.fd.cost_err, 2),
            g(r.fd.grad_err, 2),
            g(r.fd.step, 2),
        ]);
    }
    out.push_str(&t.render());
    if let Some(p) = &args.plot {
        out.push_str(&format!("\nwrote {}\n", p.display()));
    }
    Ok(out)
}

fn mvad_point<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
    wrt: &[usize],
    reference: &Reference,
) -> Result<Point, SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let (seconds, sol): (f64, Solution) = timed(|| solve(model, params, opts))?;
    let grad: Vec<f64> = wrt.iter().map(|&k| sol.gradient[k]).collect();
    Ok(Point::scored(seconds, sol.cost, grad, 0.0, reference))
}

/// Central differences of primal runs (relative step `rel_step`) over `wrt`, timed.
pub(super) fn fd_point<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
    wrt: &[usize],
    rel_step: f64,
    reference: &Reference,
) -> Result<Point, SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let primal = Options {
        sensitivities: false,
        record: false,
        ..opts.clone()
    };
    let (seconds, (cost, grad)) = timed(|| {
        let cost = solve(model, params, &primal)?.cost;
        let grad = wrt
            .iter()
            .map(|&k| fd_gradient(model, params, opts, k, rel_step))
            .collect::<Result<Vec<f64>, SolveError>>()?;
        Ok((cost, grad))
    })?;
    Ok(Point::scored(seconds, cost, grad, rel_step, reference))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::test_support::{json, lines_with, on_ball};

    #[test]
    fn errors_fall_with_the_tolerance_against_the_closed_form() {
        let out = on_ball(
            run,
            &[
                "--json",
                "--wrt",
                "e",
                "--reference",
                "C=1.8905137123173506",
                "--reference",
                "e=2.8314408141470055",
            ],
        )
        .expect("runs");
        let v = json(&out);
        assert_eq!(v["reference"]["source"], "given");
        let rows = v["rows"].as_array().expect("rows");
        assert_eq!(rows.len(), TOLERANCES.len());
        let err = |i: usize, k: &str, q: &str| rows[i][k][q].as_f64().expect("number");
        // The tightest MV-AD run is accurate to ~1e-9 and better than the loosest.
        assert!(err(9, "mvad", "gradient_error") < 1e-8, "{out}");
        assert!(err(9, "mvad", "cost_error") < 1e-8, "{out}");
        assert!(err(9, "mvad", "gradient_error") < err(0, "mvad", "gradient_error").max(1e-14));
        // MV-AD beats FD at the same tolerance from 1e-6 on.
        assert!(
            err(5, "mvad", "gradient_error") < err(5, "fd", "gradient_error"),
            "{out}"
        );
        assert!(rows[0]["mvad"]["wall_seconds"].as_f64().expect("t") > 0.0);
    }

    #[test]
    fn text_and_bad_references() {
        let out = on_ball(run, &["--wrt", "e"]).expect("runs");
        assert!(out.contains("MV-AD at rtol 1e-13"), "{out}");
        assert_eq!(lines_with(&out, " s "), TOLERANCES.len(), "{out}");
        for bad in [
            &["--reference", "x=1"][..],
            &["--reference", "C"],
            &["--reference", "C=q"],
            &["--step", "2"],
        ] {
            let err = on_ball(run, bad).err();
            assert_eq!(err.map(|e| e.status()), Some(2), "{bad:?}");
        }
    }
}
