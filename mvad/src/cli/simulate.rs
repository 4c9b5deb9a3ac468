//! `mvad simulate MODEL.hyb [--out traj.csv]`: the trajectory as CSV and the event table.
//!
//! Rows: `t, mode, <states>, <observables>`, one at the start of every accepted step and
//! at T (or on a uniform grid with `--points N`); at an event both sides appear, the
//! pre-event row x(t_k⁻) first, then x(t_k⁺). With `--out` the CSV goes to the file and
//! the event table to stdout; without, the CSV goes to stdout and the event table to
//! stderr (so the CSV stays clean in a pipe). `--json` prints both as one object.

use std::path::PathBuf;

use clap::Args;
use mvad::runtime::solution::{Solution, Trajectory};
use mvad::runtime::solve::solve;
use mvad::{At, HybridModel, ModelAlloc};
use nalgebra::DefaultAllocator;
use serde_json::{Map, Value};

use mvad::json::trajectory_event_json;

use super::output::{
    diagnostics_json, diagnostics_text, g, json_text, more_events, num, stats_json, Table,
    MAX_EVENT_ROWS,
};
use super::{setup, solve_err, write_stderr, xvec, CliError, CmdResult, Common};

/// Arguments of `mvad simulate`.
#[derive(Args, Debug)]
pub struct SimulateArgs {
    /// Common options.
    #[command(flatten)]
    pub common: Common,
    /// Write the trajectory CSV to this file (default: stdout).
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Sample on N equispaced times instead of the integrator's steps.
    #[arg(long, value_name = "N")]
    pub points: Option<usize>,
}

/// One output row: time, mode, states, observables.
struct Row {
    t: f64,
    mode: usize,
    x: Vec<f64>,
    y: Vec<f64>,
}

/// Runs `mvad simulate`.
pub fn run<M: HybridModel>(model: &M, file: &str, args: &SimulateArgs) -> CmdResult
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let mut s = setup(model, &args.common)?;
    if let Some(n) = args.points {
        if !(2..=10_000_000).contains(&n) {
            return Err(CliError::Input(format!(
                "error: --points must be between 2 and 10000000, got {n}"
            )));
        }
    }
    s.opts.record = true;
    s.opts.sensitivities = false;
    let sol = solve(model, &s.params, &s.opts).map_err(solve_err)?;
    let rows = rows(model, &s.params, &sol, args.points);
    let info = model.info();

    if args.common.json {
        let mut m = Map::new();
        m.insert("model".into(), Value::from(info.name.clone()));
        m.insert("t_end".into(), num(sol.t_end));
        let mut cols = vec!["t".to_string(), "mode".into()];
        cols.extend(info.states.iter().cloned());
        cols.extend(info.observables.iter().cloned());
        m.insert("columns".into(), Value::from(cols));
        let data: Vec<Value> = rows
            .iter()
            .map(|r| {
                let mut v = vec![num(r.t), Value::from(info.mode_name(r.mode))];
                v.extend(r.x.iter().chain(&r.y).map(|&z| num(z)));
                Value::Array(v)
            })
            .collect();
        m.insert("rows".into(), Value::Array(data));
        let events: Vec<Value> = sol
            .events
            .iter()
            .take(args.common.event_limit())
            .map(|e| trajectory_event_json(info, e))
            .collect();
        m.insert("events".into(), Value::Array(events));
        m.insert("diagnostics".into(), diagnostics_json(&sol.diagnostics));
        m.insert("stats".into(), stats_json(&sol.stats));
        if let Some(path) = &args.out {
            write_file(path, &csv(info, &rows))?;
        }
        return Ok(json_text(&Value::Object(m)));
    }

    let table = event_table(model, file, &sol);
    match &args.out {
        Some(path) => {
            write_file(path, &csv(info, &rows))?;
            Ok(format!(
                "wrote {} rows to {}\n{table}",
                rows.len(),
                path.display()
            ))
        }
        None => {
            write_stderr(&table);
            Ok(csv(info, &rows))
        }
    }
}

fn write_file(path: &std::path::Path, text: &str) -> Result<(), CliError> {
    std::fs::write(path, text)
        .map_err(|e| CliError::Run(format!("error: cannot write `{}`: {e}", path.display())))
}

/// The mode on the segment holding step `k` (right-continuous), else the final mode.
fn mode_at_step(traj: &Trajectory, k: usize, fallback: usize) -> usize {
    traj.segments
        .iter()
        .find(|s| s.first_step <= k && k < s.end_step)
        .map(|s| s.mode)
        .unwrap_or(fallback)
}

fn rows<M: HybridModel>(
    model: &M,
    params: &nalgebra::OVector<f64, M::P>,
    sol: &Solution,
    points: Option<usize>,
) -> Vec<Row>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let info = model.info();
    let nobs = info.nobservables();
    let Some(traj) = sol.trajectory.as_ref() else {
        return Vec::new();
    };
    // The observables under the bits of recorded step k.
    let observe = |t: f64, x: &[f64], k: usize| {
        let mut y = vec![0.0; nobs];
        let sw = traj.switches_of_step(k);
        model.observe(sw, At::new(t, &xvec(model, x), params), &mut y);
        y
    };
    // The steps on either side of an event at t (the one ending there, the one starting).
    let sides = |t: f64| {
        let k = traj.step_at(t).unwrap_or(0);
        let before = if k > 0 && traj.t0[k] == t { k - 1 } else { k };
        (before, k)
    };
    let sample = |t: f64| {
        let (x, _) = traj.sample(t);
        let k = traj.step_at(t).unwrap_or(0);
        let mode = mode_at_step(traj, k, sol.mode_final);
        let y = observe(t, &x, traj.step_for(t).unwrap_or(0));
        Row { t, mode, x, y }
    };
    let mut out = Vec::new();
    let mut events = sol.events.iter().peekable();
    let mut push_events_until = |t: f64, out: &mut Vec<Row>, inclusive: bool| {
        while let Some(e) = events.peek() {
            if e.t < t || (inclusive && e.t <= t) {
                let (before, after) = sides(e.t);
                let y = observe(e.t, &e.x_before, before);
                out.push(Row {
                    t: e.t,
                    mode: e.mode_before,
                    x: e.x_before.clone(),
                    y,
                });
                let y = observe(e.t, &e.x_after, after);
                out.push(Row {
                    t: e.t,
                    mode: e.mode_after,
                    x: e.x_after.clone(),
                    y,
                });
                events.next();
            } else {
                break;
            }
        }
    };
    match points {
        Some(n) => {
            for i in 0..n {
                let t = sol.t_end * i as f64 / (n - 1) as f64;
                push_events_until(t, &mut out, false);
                out.push(sample(t));
            }
            push_events_until(f64::INFINITY, &mut out, true);
        }
        None => {
            for k in 0..traj.len() {
                let t = traj.t0[k];
                // Events at t are pushed as (pre, post) pairs; skip the duplicate post row.
                let before = out.len();
                push_events_until(t, &mut out, true);
                if out.len() == before {
                    out.push(sample(t));
                }
            }
            push_events_until(sol.t_end, &mut out, true);
            if let Some(&t1) = traj.t1.last() {
                out.push(sample(t1));
            } else {
                let x = sol.x_final.clone();
                let y = observe(sol.t_end, &x, 0);
                out.push(Row {
                    t: sol.t_end,
                    mode: sol.mode_final,
                    x,
                    y,
                });
            }
        }
    }
    out
}

fn csv(info: &mvad::ModelInfo, rows: &[Row]) -> String {
    let mut s = String::from("t,mode");
    for n in info.states.iter().chain(&info.observables) {
        s.push(',');
        s.push_str(n);
    }
    s.push('\n');
    for r in rows {
        s.push_str(&format!("{:?},{}", r.t, info.mode_name(r.mode)));
        for v in r.x.iter().chain(&r.y) {
            s.push_str(&format!(",{v:?}"));
        }
        s.push('\n');
    }
    s
}

fn event_table<M: HybridModel>(model: &M, file: &str, sol: &Solution) -> String
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let info = model.info();
    let mut s = format!(
        "model {} ({file}): {} events up to T = {}\n",
        info.name,
        sol.events.len(),
        g(sol.t_end, 10)
    );
    if !sol.events.is_empty() {
        let mut header = vec!["#".to_string(), "event".into(), "t".into(), "mode".into()];
        header.extend(info.states.iter().map(|n| format!("{n}⁻ -> {n}⁺")));
        let mut t = Table::new(&header);
        for e in sol.events.iter().take(MAX_EVENT_ROWS) {
            let mut row = vec![
                e.index.to_string(),
                info.events
                    .get(e.event)
                    .map(|x| x.name.clone())
                    .unwrap_or_default(),
                g(e.t, 12),
                if e.mode_before == e.mode_after {
                    info.mode_name(e.mode_before)
                } else {
                    format!(
                        "{} -> {}",
                        info.mode_name(e.mode_before),
                        info.mode_name(e.mode_after)
                    )
                },
            ];
            for (a, b) in e.x_before.iter().zip(&e.x_after) {
                row.push(if a == b {
                    g(*a, 8)
                } else {
                    format!("{} -> {}", g(*a, 8), g(*b, 8))
                });
            }
            t.row(row);
        }
        s.push_str(&t.render());
        s.push_str(&more_events(sol.events.len()));
    }
    s.push_str(&diagnostics_text(&sol.diagnostics));
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::test_support::{args, json, on_ball, scratch_dir};
    use approx::assert_relative_eq;
    use mvad::runtime::fixtures::Ball;

    /// Closed form of the E1 ball's height before the first impact: h0 − g t²/2.
    #[test]
    fn csv_follows_the_closed_form_and_shows_both_sides_of_events() {
        let out = on_ball(run, &["--points", "11", "--rtol", "1e-10"]).expect("runs");
        let mut lines = out.lines();
        assert_eq!(lines.next(), Some("t,mode,h,v,height,velocity"));
        let rows: Vec<Vec<String>> = lines
            .map(|l| l.split(',').map(String::from).collect())
            .collect();
        // 11 grid rows + 2 rows per impact.
        assert_eq!(rows.len(), 11 + 4);
        let num = |s: &str| s.parse::<f64>().expect("number");
        let r = &rows[2]; // t = 0.4 (before the first impact at 0.6386)
        assert_relative_eq!(num(&r[0]), 0.4, max_relative = 1e-12);
        assert_relative_eq!(num(&r[2]), 2.0 - 0.5 * 9.81 * 0.16, max_relative = 1e-8);
        assert_relative_eq!(num(&r[3]), -9.81 * 0.4, max_relative = 1e-8);
        // The first impact's two rows: v⁻ = −g t₁, v⁺ = −0.8 v⁻.
        let t1 = 0.638_550_856_814_101;
        let pre = rows
            .iter()
            .position(|r| (num(&r[0]) - t1).abs() < 1e-9)
            .expect("event row");
        assert_relative_eq!(num(&rows[pre][3]), -9.81 * t1, max_relative = 1e-8);
        assert_relative_eq!(num(&rows[pre + 1][3]), 0.8 * 9.81 * t1, max_relative = 1e-8);
        assert_eq!(rows[pre][1], "main");
    }

    #[test]
    fn step_grid_is_sorted_and_ends_at_t() {
        let out = on_ball(run, &[]).expect("runs");
        let ts: Vec<f64> = out
            .lines()
            .skip(1)
            .map(|l| l.split(',').next().expect("t").parse().expect("number"))
            .collect();
        assert!(ts.windows(2).all(|w| w[0] <= w[1]), "{ts:?}");
        assert_eq!(ts.first(), Some(&0.0));
        assert_relative_eq!(*ts.last().expect("rows"), 2.0);
    }

    #[test]
    fn out_file_and_json() {
        let dir = scratch_dir("simulate");
        let path = dir.path().join("traj.csv");
        let p = path.to_string_lossy().to_string();
        let out = on_ball(run, &["--out", &p]).expect("runs");
        assert!(out.contains("impact"), "{out}");
        let text = std::fs::read_to_string(&path).expect("written");
        assert!(text.starts_with("t,mode,h,v"));
        let out = on_ball(run, &["--json", "--points", "5"]).expect("runs");
        let v = json(&out);
        assert_eq!(v["columns"][2], "h");
        assert_eq!(v["rows"].as_array().map(Vec::len), Some(5 + 4));
        assert_eq!(v["events"][0]["name"], "impact");
        let err = on_ball(run, &["--out", "/nonexistent/dir/x.csv"]).err();
        assert_eq!(err.map(|e| e.status()), Some(1));
        assert_eq!(
            run(&Ball::new(), "b", &args(&["--points", "1"]))
                .err()
                .map(|e| e.status()),
            Some(2)
        );
    }
}
