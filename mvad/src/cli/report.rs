//! `mvad report SUITE_DIR --out DIR`: every case of a suite (see [`mvad::suite`]) checked
//! against its reference, and swept across the methods (auto, tsit5, verner9, rosenbrock)
//! and the case's tolerances (atol = rtol · 1e-2), MV-AD against central FD.
//!
//! Writes `DIR/README.md` (a summary table with every case's check: errors, bound, steps,
//! events, diagnostics, verdict; then per case the sweep: time, errors, steps and diagnostics
//! of MV-AD and FD per method and tolerance) and per case a work-precision diagram
//! `DIR/CASE.svg` and `.png` (error of C and of dC/dθ against wall time). The points are
//! those of `mvad workprec` (its timing and its central differences: one mechanism).
//! A method that fails with `max_steps` at one tolerance is not run at the tighter ones
//! (they would fail the same way); the table says so. The exit status is 1 when a case
//! fails its check (the report is written first), so a silently wrong number is an error.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use clap::Args;
use mvad::interp::InterpretedModel;
use mvad::runtime::solution::Method;
use mvad::runtime::solve::solve;
use mvad::suite::{Case, Outcome, Reference, RunSpec, Suite, Verdict};
use nalgebra::DVector;

use super::output::g;
use super::plot::{workprec as plot_workprec, Curve};
use super::progress::Progress;
use super::workprec::{fd_point, timed, Point, Reference as WpReference};
use super::{check_step, CliError, CmdResult};

/// Arguments of `mvad report`.
#[derive(Args, Debug)]
pub struct ReportArgs {
    /// The suite directory (holding `manifest.json` and the models it names).
    pub suite: PathBuf,
    /// Where to write README.md and the diagrams (created if missing).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Only the cases whose name contains this text.
    #[arg(long, value_name = "TEXT")]
    pub only: Option<String>,
    /// Relative step of the central differences.
    #[arg(long, value_name = "H", default_value_t = 1e-6)]
    pub step: f64,
}

/// One point of a sweep: a method at a tolerance, MV-AD and FD.
struct SweepRow {
    method: Method,
    rtol: f64,
    mvad: Outcome,
    /// `None` when FD was not run (MV-AD failed: the primal runs would too).
    fd: Option<Result<Point, String>>,
    /// Not run: an earlier tolerance of this method hit `max_steps`.
    skipped: bool,
}

/// Everything the report says about one case.
struct CaseReport {
    case: Case,
    reference: Result<Reference, String>,
    check: Option<(Outcome, Verdict)>,
    sweep: Vec<SweepRow>,
}

/// Runs `mvad report`.
pub fn run(args: &ReportArgs) -> CmdResult {
    check_step(args.step)?;
    let suite = Suite::load(&args.suite).map_err(|e| CliError::Input(format!("error: {e}")))?;
    let cases: Vec<&Case> = suite
        .cases
        .iter()
        .filter(|c| {
            args.only
                .as_ref()
                .is_none_or(|s| c.name.contains(s.as_str()))
        })
        .collect();
    if cases.is_empty() {
        return Err(CliError::Input(format!(
            "error: no case of {} matches",
            args.suite.display()
        )));
    }
    std::fs::create_dir_all(&args.out)
        .map_err(|e| CliError::Input(format!("error: --out {}: {e}", args.out.display())))?;
    let points: usize = cases
        .iter()
        .map(|c| 1 + Method::ALL.len() * c.sweep.len())
        .sum();
    let progress = Progress::new(points, "report");
    let mut reports = Vec::with_capacity(cases.len());
    for case in cases {
        reports.push(report_case(&suite.dir, case, args.step, &progress)?);
    }
    progress.finish();
    for r in &reports {
        if !r.sweep.is_empty() {
            draw(&args.out, r)?;
        }
    }
    let md = markdown(&args.suite, &reports);
    let path = args.out.join("README.md");
    std::fs::write(&path, &md)
        .map_err(|e| CliError::Run(format!("error: {}: {e}", path.display())))?;
    let failed: Vec<&str> = reports
        .iter()
        .filter(|r| !passed(r))
        .map(|r| r.case.name.as_str())
        .collect();
    let summary = format!(
        "{} cases, {} passed, {} failed; wrote {}\n",
        reports.len(),
        reports.len() - failed.len(),
        failed.len(),
        path.display()
    );
    if failed.is_empty() {
        Ok(summary)
    } else {
        Err(CliError::Run(format!(
            "{summary}error: cases failed their check: {}",
            failed.join("; ")
        )))
    }
}

fn passed(r: &CaseReport) -> bool {
    r.check.as_ref().is_some_and(|(_, v)| v.pass)
}

/// The check and the sweep of one case.
fn report_case(
    dir: &Path,
    case: &Case,
    step: f64,
    progress: &Progress,
) -> Result<CaseReport, CliError> {
    let input = |e: String| CliError::Input(format!("error: {e}"));
    let model = case.load_model(dir).map_err(input)?;
    let params = case.params(&model).map_err(input)?;
    let reference = case.reference(&model, &params);
    let Ok(r) = &reference else {
        progress.inc_by(1 + Method::ALL.len() * case.sweep.len());
        return Ok(CaseReport {
            case: case.clone(),
            reference,
            check: None,
            sweep: Vec::new(),
        });
    };
    let check = run_point(case, &model, &params, case.check, r);
    let verdict = case.verdict(&check);
    progress.inc();
    let mut sweep = Vec::new();
    for method in Method::ALL {
        let mut gave_up = false;
        for &rtol in &case.sweep {
            if gave_up {
                sweep.push(skipped_row(method, rtol, r));
                progress.inc();
                continue;
            }
            let spec = RunSpec {
                method,
                rtol,
                atol: rtol * 1e-2,
            };
            let mvad = run_point(case, &model, &params, spec, r);
            let fd = mvad.error.is_none().then(|| {
                let wp = WpReference {
                    cost: r.cost,
                    grad: r.gradient.clone(),
                };
                fd_point(&model, &params, &case.options(spec), &r.wrt, step, &wp)
                    .map_err(|e| e.to_string())
            });
            gave_up = mvad.diagnostics.iter().any(|d| d == "max_steps");
            sweep.push(SweepRow {
                method,
                rtol,
                mvad,
                fd,
                skipped: false,
            });
            progress.inc();
        }
    }
    Ok(CaseReport {
        case: case.clone(),
        reference,
        check: Some((check, verdict)),
        sweep,
    })
}

/// One timed MV-AD run of the case with `spec`, against the reference.
fn run_point(
    case: &Case,
    model: &InterpretedModel,
    params: &DVector<f64>,
    spec: RunSpec,
    r: &Reference,
) -> Outcome {
    let opts = case.options(spec);
    match timed(|| solve(model, params, &opts)) {
        Ok((seconds, sol)) => case.outcome(Ok(sol), seconds, r),
        Err(e) => case.outcome(Err(e), f64::NAN, r),
    }
}

fn skipped_row(method: Method, rtol: f64, r: &Reference) -> SweepRow {
    SweepRow {
        method,
        rtol,
        mvad: Outcome {
            cost: f64::NAN,
            gradient: vec![f64::NAN; r.wrt.len()],
            cost_err: f64::NAN,
            grad_err: f64::NAN,
            steps: 0,
            events: 0,
            diagnostics: Vec::new(),
            error: None,
            seconds: f64::NAN,
            estimate: None,
        },
        fd: None,
        skipped: true,
    }
}

/// The file stem of a case's diagram: its name in lowercase letters, digits and dashes.
fn slug(name: &str) -> String {
    let mut s = String::new();
    for ch in name.chars() {
        if ch.is_ascii_alphanumeric() {
            s.push(ch.to_ascii_lowercase());
        } else if !s.ends_with('-') {
            s.push('-');
        }
    }
    s.trim_matches('-').to_string()
}

/// The work-precision diagram of one case, as SVG and PNG: C and dC/dθ errors against wall
/// time, one curve per method for MV-AD and one for FD.
fn draw(out: &Path, r: &CaseReport) -> Result<(), CliError> {
    let curves = |err: &dyn Fn(&Outcome) -> f64, fd_err: &dyn Fn(&Point) -> f64| {
        let mut v = Vec::new();
        for method in Method::ALL {
            let rows = || {
                r.sweep
                    .iter()
                    .filter(move |s| s.method == method && !s.skipped)
            };
            v.push(Curve {
                label: format!("MV-AD {}", method.name()),
                points: rows().map(|s| (s.mvad.seconds, err(&s.mvad))).collect(),
            });
            v.push(Curve {
                label: format!("FD {}", method.name()),
                points: rows()
                    .filter_map(|s| match &s.fd {
                        Some(Ok(p)) => Some((p.seconds, fd_err(p))),
                        _ => None,
                    })
                    .collect(),
            });
        }
        v
    };
    let panels = vec![
        (
            "relative error of C".to_string(),
            curves(&|o| o.cost_err, &|p| p.cost_err),
        ),
        (
            "relative error of dC/dθ".to_string(),
            curves(&|o| o.grad_err, &|p| p.grad_err),
        ),
    ];
    let title = format!("{}: error against wall time", r.case.name);
    for ext in ["svg", "png"] {
        let path = out.join(format!("{}.{ext}", slug(&r.case.name)));
        plot_workprec(&path, &title, &panels)?;
    }
    Ok(())
}

fn e(x: f64) -> String {
    if x.is_nan() {
        "–".into()
    } else {
        format!("{x:.1e}")
    }
}

fn secs(x: f64) -> String {
    if x.is_nan() {
        "–".into()
    } else {
        format!("{} s", g(x, 3))
    }
}

fn diags(o: &Outcome) -> String {
    if o.diagnostics.is_empty() {
        "–".into()
    } else {
        o.diagnostics.join(", ")
    }
}

/// The report as markdown (produced here, never by hand).
fn markdown(suite: &Path, reports: &[CaseReport]) -> String {
    let mut s = String::new();
    let failed = reports.iter().filter(|r| !passed(r)).count();
    let _ = writeln!(s, "# Stiff and extreme cases: accuracy against work\n");
    let _ = writeln!(
        s,
        "Generated by `mvad report {} --out DIR` (do not edit by hand). Each case is checked \
         with its own method and tolerances against its reference (a closed form, or an \
         independent tight run): it passes when the relative errors of C and of dC/dθ \
         (max |Δ| / max |ref|) are within its bounds, or when a diagnostic that excuses the \
         miss was raised, and every diagnostic it requires was raised. A missed bound with no \
         diagnostic is a silently wrong number and fails.\n",
        suite.display()
    );
    let _ = writeln!(
        s,
        "**{} cases, {} passed, {} failed.** Times are wall-clock means on a shared 2-core \
         machine.\n",
        reports.len(),
        reports.len() - failed,
        failed
    );
    s.push_str("| case | check | reference | err C | err dC/dθ | bounds (C, dC) | steps | events | diagnostics | verdict |\n");
    s.push_str("|---|---|---|---|---|---|---|---|---|---|\n");
    for r in reports {
        let c = &r.case;
        let check = format!(
            "{} rtol {:.0e} atol {:.0e}",
            c.check.method.name(),
            c.check.rtol,
            c.check.atol
        );
        let verdict = match (&r.reference, &r.check) {
            (Err(err), _) => format!("FAIL: {err}"),
            (_, Some((_, v))) => format!("{}: {}", if v.pass { "pass" } else { "FAIL" }, v.reason),
            _ => "FAIL".into(),
        };
        let (ec, eg, steps, events, d) = match &r.check {
            Some((o, _)) => (
                e(o.cost_err),
                e(o.grad_err),
                o.steps.to_string(),
                o.events.to_string(),
                diags(o),
            ),
            None => ("–".into(), "–".into(), "–".into(), "–".into(), "–".into()),
        };
        let _ = writeln!(
            s,
            "| {} | {check} | {} | {ec} | {eg} | {:.0e}, {:.0e} | {steps} | {events} | {d} | {verdict} |",
            c.name, c.source, c.bound_cost, c.bound_gradient
        );
    }
    for r in reports.iter().filter(|r| !r.sweep.is_empty()) {
        let stem = slug(&r.case.name);
        let _ = writeln!(s, "\n## {}\n", r.case.name);
        let _ = writeln!(
            s,
            "Model `{}`{}; reference: {}.\n\n![{}]({stem}.svg)\n",
            r.case.model,
            if r.case.set.is_empty() {
                String::new()
            } else {
                let set: Vec<String> = r
                    .case
                    .set
                    .iter()
                    .map(|(k, v)| format!("{k} = {v:e}"))
                    .collect();
                format!(" with {}", set.join(", "))
            },
            r.case.source,
            r.case.name
        );
        s.push_str("| method | rtol | MV-AD time | err C | err dC/dθ | steps | events | diagnostics | FD time | FD err dC/dθ |\n");
        s.push_str("|---|---|---|---|---|---|---|---|---|---|\n");
        for row in &r.sweep {
            let o = &row.mvad;
            let (fdt, fde) = match &row.fd {
                Some(Ok(p)) => (secs(p.seconds), e(p.grad_err)),
                Some(Err(err)) => ("–".into(), format!("failed: {err}")),
                None => ("–".into(), "–".into()),
            };
            let d = if row.skipped {
                "not run (max_steps at a looser rtol)".to_string()
            } else if let Some(err) = &o.error {
                format!("{}: {err}", diags(o))
            } else {
                diags(o)
            };
            let _ = writeln!(
                s,
                "| {} | {:.0e} | {} | {} | {} | {} | {} | {d} | {fdt} | {fde} |",
                row.method.name(),
                row.rtol,
                secs(o.seconds),
                e(o.cost_err),
                e(o.grad_err),
                o.steps,
                o.events
            );
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slugs_are_file_names() {
        assert_eq!(slug("zeno e=0.5, C = int v"), "zeno-e-0-5-c-int-v");
        assert_eq!(slug("stiff relay rtol 1e-03"), "stiff-relay-rtol-1e-03");
    }

    #[test]
    fn a_small_suite_is_reported_with_diagrams_and_a_table() {
        let dir = crate::cli::test_support::scratch_dir("report");
        let suite = dir.path().join("suite");
        std::fs::create_dir_all(&suite).expect("mkdir");
        std::fs::write(
            suite.join("ball.hyb"),
            include_str!("../../../models/bouncing_ball.hyb"),
        )
        .expect("write");
        std::fs::write(
            suite.join("manifest.json"),
            r#"{"cases": [
              {"name": "ball", "model": "ball.hyb", "check": {"rtol": 1e-10, "atol": 1e-12},
               "reference": {"cost": 1.8905137123173506, "gradient": {"e": 2.8314408141470055},
                             "source": "closed form"},
               "bound": {"cost": 1e-9, "gradient": 1e-9}, "sweep": [1e-6, 1e-10]},
              {"name": "wrong reference", "model": "ball.hyb",
               "reference": {"cost": 1.9}, "bound": {"cost": 1e-9}, "sweep": []}
            ]}"#,
        )
        .expect("write");
        let out = dir.path().join("out");
        let args = ReportArgs {
            suite: suite.clone(),
            out: out.clone(),
            only: None,
            step: 1e-6,
        };
        let err = run(&args).expect_err("the wrong reference fails its check");
        assert_eq!(err.status(), 1);
        assert!(
            err.message().contains("wrong reference"),
            "{}",
            err.message()
        );
        let md = std::fs::read_to_string(out.join("README.md")).expect("README.md");
        assert!(md.contains("2 cases, 1 passed, 1 failed"), "{md}");
        assert!(md.contains("WRONG WITH NO DIAGNOSTIC"), "{md}");
        assert!(md.contains("![ball](ball.svg)"), "{md}");
        // Four methods × two tolerances in the sweep table of the case with a sweep.
        assert_eq!(md.matches("| rosenbrock | ").count(), 2, "{md}");
        for ext in ["svg", "png"] {
            assert!(out.join(format!("ball.{ext}")).is_file());
        }
        assert!(!out.join("wrong-reference.svg").exists());
        let only = ReportArgs {
            only: Some("ball".into()),
            ..args
        };
        assert!(run(&only)
            .expect("passes")
            .contains("1 cases, 1 passed, 0 failed"));
    }
}
