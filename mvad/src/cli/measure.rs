//! `mvad measure MODEL.hyb --observable NAME`: the derivative of one observable's
//! trajectory as a measure,
//!
//! ```text
//!   μ_y = (h_x S + h_θ) dt + Σ_k α_k δ(t − t_k),   α_k = −J_k t_k',
//! ```
//!
//! a density sampled on a grid plus the atoms, one of each per parameter in `--wrt`. The
//! pairing ⟨μ_y, 1⟩ = d/dθ ∫₀ᵀ y dt is printed with it (split into its density part and
//! its atoms). `--plot FILE.svg|png` draws the paper's Figure 1 for the first `--wrt`
//! parameter: y(t) with the events, the density with the atoms as stems, and
//! d/dθ ∫₀ᵗ y ds from MV-AD (density integral plus the atoms so far) against central
//! finite differences of the same integral.

use mvad_runtime::reduce::integrate_adaptive;
use std::path::PathBuf;

use clap::Args;
use mvad::runtime::measure::{measure, AtomOrigin, Measure};
use mvad::runtime::solution::{Options, Solution};
use mvad::runtime::solve::solve;
use mvad::{At, HybridModel, ModelAlloc};
use nalgebra::{DefaultAllocator, OVector};
use serde_json::{Map, Value};

use super::fdcheck::FdStep;
use super::output::{
    diagnostics_json, diagnostics_text, g, json_text, more_events, num, param_header, Table,
    MAX_EVENT_ROWS,
};
use super::plot::{figure1, format_of, Figure1};
use super::{observable_index, setup, solve_err, xvec, CliError, CmdResult, Common};

/// Arguments of `mvad measure`.
#[derive(Args, Debug)]
pub struct MeasureArgs {
    /// Common options.
    #[command(flatten)]
    pub common: Common,
    /// The observable y whose derivative is shown.
    #[arg(long, value_name = "NAME")]
    pub observable: String,
    /// Draw the paper's Figure 1 into FILE (.svg or .png).
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    /// Number of grid points for the density.
    #[arg(long, value_name = "N", default_value_t = 201)]
    pub points: usize,
    /// The step of the central differences in the plot.
    #[command(flatten)]
    pub fd: FdStep,
}

/// Runs `mvad measure`.
pub fn run<M: HybridModel>(model: &M, file: &str, args: &MeasureArgs) -> CmdResult
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let mut s = setup(model, &args.common)?;
    let info = model.info();
    let obs = observable_index(info, &args.observable)?;
    if !(2..=1_000_000).contains(&args.points) {
        return Err(CliError::Input(format!(
            "error: --points must be between 2 and 1000000, got {}",
            args.points
        )));
    }
    let step = args.fd.checked()?;
    if let Some(p) = &args.plot {
        format_of(p)?;
        if s.wrt.is_empty() {
            return Err(CliError::Input(
                "error: --plot needs a parameter to differentiate by, and the model has none"
                    .into(),
            ));
        }
    }
    s.opts.record = true;
    let sol = solve(model, &s.params, &s.opts).map_err(solve_err)?;
    let mu = measure(model, &s.params, &sol, obs).map_err(solve_err)?;
    let t_end = sol.t_end;
    let grid: Vec<f64> = (0..args.points)
        .map(|i| t_end * i as f64 / (args.points - 1) as f64)
        .collect();
    let dens = mu.on_grid(&grid);
    let total = mu.pair(|_| 1.0);
    let density_part = mu.pair_density(|_| 1.0);
    let wrt = &s.wrt;

    let mut plot_note = None;
    if let Some(path) = &args.plot {
        let fig = figure_data(model, &s.params, &s.opts, &sol, &mu, obs, wrt[0], step)?;
        plot_note = Some(fig.note.clone());
        figure1(path, &fig)?;
    }

    if args.common.json {
        let mut m = Map::new();
        m.insert("model".into(), Value::from(info.name.clone()));
        m.insert(
            "observable".into(),
            Value::from(info.observables[obs].clone()),
        );
        m.insert("t_end".into(), num(t_end));
        m.insert(
            "wrt".into(),
            Value::from(
                wrt.iter()
                    .map(|&k| info.params[k].clone())
                    .collect::<Vec<_>>(),
            ),
        );
        m.insert(
            "grid".into(),
            Value::from(grid.iter().map(|&t| num(t)).collect::<Vec<_>>()),
        );
        let mut d = Map::new();
        for &k in wrt {
            d.insert(
                info.params[k].clone(),
                Value::from(dens.iter().map(|row| num(row[k])).collect::<Vec<_>>()),
            );
        }
        m.insert("density".into(), Value::Object(d));
        let atoms: Vec<Value> = mu
            .atoms
            .iter()
            .zip(&mu.origins)
            .map(|((t, a), origin)| {
                let mut vals = Map::new();
                for &k in wrt {
                    vals.insert(info.params[k].clone(), num(a[k]));
                }
                let (kind, index, name, switch, jump) = atom_origin(&sol, info, origin);
                serde_json::json!({
                    "origin": kind,
                    "index": index,
                    "name": name,
                    "switch": switch,
                    "t": num(*t),
                    "jump": num(jump),
                    "values": Value::Object(vals),
                })
            })
            .collect();
        m.insert("atoms".into(), Value::Array(atoms));
        let mut pairing = Map::new();
        for &k in wrt {
            pairing.insert(
                info.params[k].clone(),
                serde_json::json!({
                    "total": num(total[k]),
                    "density": num(density_part[k]),
                    "atoms": num(total[k] - density_part[k]),
                }),
            );
        }
        m.insert("integral_derivative".into(), Value::Object(pairing));
        m.insert("diagnostics".into(), diagnostics_json(&sol.diagnostics));
        if let Some(note) = plot_note {
            m.insert("plot".into(), serde_json::json!({"file": args.plot.as_ref().map(|p| p.display().to_string()), "comparison": note}));
        }
        return Ok(json_text(&Value::Object(m)));
    }

    let mut out = format!(
        "model {} ({file}): the derivative of `{}` as a measure on [0, {}]\n",
        info.name,
        info.observables[obs],
        g(t_end, 10)
    );
    out.push_str("density (h_x S + h_θ) dt plus atoms α_k δ(t − t_k), α_k = −J_k t_k'\n\n");
    let mut t = Table::new(&["param", "d/dθ ∫y dt", "density part", "atoms part"]);
    for &k in wrt {
        t.row(vec![
            info.params[k].clone(),
            g(total[k], 12),
            g(density_part[k], 12),
            g(total[k] - density_part[k], 12),
        ]);
    }
    out.push_str(&t.render());
    out.push_str(&format!("\natoms ({}):\n", mu.atoms.len()));
    if !mu.atoms.is_empty() {
        let header = param_header(&["#", "t", "jump J"], "α d/d", &info.params, wrt);
        let mut t = Table::new(&header);
        for ((tk, a), origin) in mu.atoms.iter().zip(&mu.origins).take(MAX_EVENT_ROWS) {
            let (kind, index, _, switch, jump) = atom_origin(&sol, info, origin);
            let label = match (index, switch) {
                (Some(i), _) => i.to_string(),
                (None, Some(j)) => format!("switch {j}"),
                (None, None) => kind.replace('_', " "),
            };
            let mut row = vec![label, g(*tk, 10), g(jump, 8)];
            row.extend(wrt.iter().map(|&k| g(a[k], 8)));
            t.row(row);
        }
        out.push_str(&t.render());
        out.push_str(&more_events(mu.atoms.len()));
    }
    out.push_str("\ndensity on the grid:\n");
    let mut t = Table::new(&param_header(&["t"], "d/d", &info.params, wrt));
    let stride = (grid.len() / 20).max(1);
    for (i, (ti, row)) in grid.iter().zip(&dens).enumerate() {
        if i % stride == 0 || i + 1 == grid.len() {
            let mut r = vec![g(*ti, 6)];
            r.extend(wrt.iter().map(|&k| g(row[k], 8)));
            t.row(r);
        }
    }
    out.push_str(&t.render());
    if stride > 1 {
        out.push_str(&format!(
            "(every {stride}th of {} points; --json prints all)\n",
            grid.len()
        ));
    }
    if let (Some(p), Some(note)) = (&args.plot, plot_note) {
        out.push_str(&format!("\nwrote {}: {note}\n", p.display()));
    }
    out.push_str(&diagnostics_text(&sol.diagnostics));
    Ok(out)
}

/// What placed an atom: (its kind — `event`, `switch`, `zeno_tail` or `horizon` —, the
/// event's index in the run's table and its name, or the kink's switching function, and the
/// jump J of the observable; NaN for a Zeno tail).
fn atom_origin(
    sol: &Solution,
    info: &mvad::ModelInfo,
    origin: &AtomOrigin,
) -> (
    &'static str,
    Option<usize>,
    Option<String>,
    Option<usize>,
    f64,
) {
    match *origin {
        AtomOrigin::Event { index, jump } => {
            let e = &sol.events[index];
            let name = info.events.get(e.event).map(|x| x.name.clone());
            ("event", Some(e.index), name, None, jump)
        }
        AtomOrigin::Switch { switch, jump } => ("switch", None, None, Some(switch), jump),
        AtomOrigin::ZenoTail => ("zeno_tail", None, None, None, f64::NAN),
        AtomOrigin::Horizon { jump } => ("horizon", None, None, None, jump),
    }
}

/// y(t) along a recorded solution, under the bits of the step the sample reads
/// (right-continuous at events, the left limit at a switch crossing; NaN without a record).
fn observable_along<'a, M: HybridModel>(
    model: &'a M,
    params: &'a OVector<f64, M::P>,
    sol: &'a Solution,
    obs: usize,
) -> impl Fn(f64) -> f64 + 'a
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let nobs = model.info().nobservables();
    move |t| match sol.trajectory.as_ref() {
        Some(traj) => {
            let mut y = vec![0.0; nobs];
            let sw = traj.switches_of_step(traj.step_for(t).unwrap_or(0));
            let x = xvec(model, &traj.sample(t).0);
            model.observe(sw, At::new(t, &x, params), &mut y);
            y[obs]
        }
        None => f64::NAN,
    }
}

/// ∫₀ᵗ y ds at `ts` (ascending) from a recorded solution: adaptive Gauss–Legendre on every
/// piece between consecutive accepted-step times, event times and grid times, so neither a
/// jump nor a boundary layer inside a step (a stiff lag's 1e-8 transient) is straddled by a
/// fixed rule — finite differences of two such integrals then stay accurate.
fn observable_integral<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    sol: &Solution,
    obs: usize,
    ts: &[f64],
) -> Vec<f64>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let Some(traj) = sol.trajectory.as_ref() else {
        return vec![f64::NAN; ts.len()];
    };
    let y = observable_along(model, params, sol, obs);
    let mut knots: Vec<f64> = traj.step_times().to_vec();
    knots.extend(sol.events.iter().map(|e| e.t));
    knots.extend_from_slice(ts);
    knots.retain(|t| t.is_finite());
    knots.sort_by(f64::total_cmp);
    knots.dedup();
    let mut out = Vec::with_capacity(ts.len());
    let mut acc = [0.0];
    let mut tmp = [0.0; 3];
    let mut next = 0;
    let mut prev: Option<f64> = None;
    for &b in &knots {
        if let Some(a) = prev {
            let mut f = |s: f64, o: &mut [f64]| o[0] = y(s);
            integrate_adaptive(&mut f, a, b, 1e-12, 1e-300, &mut acc, &mut tmp);
        }
        prev = Some(b);
        while next < ts.len() && ts[next] <= b {
            out.push(acc[0]);
            next += 1;
        }
    }
    out.resize(ts.len(), acc[0]);
    out
}

/// The data of Figure 1 for observable `obs` and parameter `k`.
#[allow(clippy::too_many_arguments)]
fn figure_data<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
    sol: &Solution,
    mu: &Measure,
    obs: usize,
    k: usize,
    rel_step: f64,
) -> Result<Figure1, CliError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let info = model.info();
    let t_end = sol.t_end;
    let n = 2001;
    let ts: Vec<f64> = (0..n).map(|i| t_end * i as f64 / (n - 1) as f64).collect();
    let y_of = observable_along(model, params, sol, obs);
    let y: Vec<f64> = ts.iter().map(|&t| y_of(t)).collect();
    let dens: Vec<f64> = ts.iter().map(|&t| mu.density(t)[k]).collect();
    // MV-AD: μ([0, t]) = ∫₀ᵗ density + Σ_{t_k ≤ t} α_k, with the density integrated
    // adaptively inside every step.
    let cum: Vec<f64> = mu.cumulative(&ts).into_iter().map(|m| m[k]).collect();
    // Central differences of ∫₀ᵗ y ds from two recorded primal runs.
    let h = mvad_runtime::fd::fd_step(params[k], rel_step);
    let run_at = |delta: f64| -> Result<(Vec<f64>, f64), CliError> {
        let mut p = params.clone();
        p[k] += delta;
        let o = Options {
            record: true,
            sensitivities: false,
            // A fixed horizon: the picture compares integrals over the same [0, t].
            t_end: Some(t_end),
            ..opts.clone()
        };
        let s = solve(model, &p, &o).map_err(solve_err)?;
        Ok((observable_integral(model, &p, &s, obs, &ts), p[k]))
    };
    let (plus, vp) = run_at(h)?;
    let (minus, vm) = run_at(-h)?;
    let mut fd: Vec<f64> = plus
        .iter()
        .zip(&minus)
        .map(|(a, b)| (a - b) / (vp - vm))
        .collect();
    if sol.dt_end[k] != 0.0 {
        // The horizon moves with θ_k: μ([0, T]) holds the atom y(T⁻) T' at T, and its
        // difference quotient is that of ∫₀^T(θ) y over each run's own horizon.
        let whole = |delta: f64| -> Result<f64, CliError> {
            let mut p = params.clone();
            p[k] += delta;
            let o = Options {
                record: true,
                sensitivities: false,
                ..opts.clone()
            };
            let s = solve(model, &p, &o).map_err(solve_err)?;
            let last = observable_integral(model, &p, &s, obs, &[s.t_end]);
            Ok(last.last().copied().unwrap_or(f64::NAN))
        };
        if let Some(end) = fd.last_mut() {
            *end = (whole(h)? - whole(-h)?) / (vp - vm);
        }
    }
    let mvad_total = mu.pair(|_| 1.0)[k];
    let fd_total = fd.last().copied().unwrap_or(f64::NAN);
    let abs = (mvad_total - fd_total).abs();
    let rel = abs / mvad_total.abs().max(f64::MIN_POSITIVE);
    let note = format!(
        "MV-AD {} vs FD {}: abs err {}, rel err {}",
        g(mvad_total, 8),
        g(fd_total, 8),
        g(abs, 3),
        g(rel, 3)
    );
    Ok(Figure1 {
        title: format!(
            "{}: d{}/d{} as a measure",
            info.name, info.observables[obs], info.params[k]
        ),
        observable: info.observables[obs].clone(),
        param: info.params[k].clone(),
        trajectory: ts.iter().copied().zip(y).collect(),
        events: mu.atoms.iter().map(|a| a.0).collect(),
        density: ts.iter().copied().zip(dens).collect(),
        atoms: mu.atoms.iter().map(|(t, a)| (*t, a[k])).collect(),
        cumulative_mvad: ts.iter().copied().zip(cum).collect(),
        cumulative_fd: ts.iter().copied().zip(fd).collect(),
        note,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::test_support::{args, json, on_ball, scratch_dir, tight};
    use approx::assert_relative_eq;
    use mvad::runtime::fixtures::Ball;

    #[test]
    fn json_density_atoms_and_the_pairing_with_one() {
        let out = on_ball(
            run,
            &tight(&["--observable", "height", "--wrt", "e", "--json"]),
        )
        .expect("runs");
        let v = json(&out);
        assert_eq!(v["observable"], "height");
        assert_eq!(v["grid"].as_array().map(Vec::len), Some(201));
        assert_eq!(v["density"]["e"].as_array().map(Vec::len), Some(201));
        // Before the first impact nothing depends on e.
        assert_eq!(v["density"]["e"][10], 0.0);
        // Height is continuous: its atoms vanish.
        assert_eq!(v["atoms"].as_array().map(Vec::len), Some(2));
        assert_eq!(v["atoms"][0]["origin"], "event");
        assert_eq!(
            v["atoms"][1]["values"]["e"].as_f64().map(f64::abs),
            Some(0.0)
        );
        // ⟨μ_height, 1⟩ = d/de ∫h dt = dC/de of the E1 reference.
        let total = v["integral_derivative"]["e"]["total"]
            .as_f64()
            .expect("number");
        assert_relative_eq!(total, 2.8314408141470055, max_relative = 1e-7);
    }

    #[test]
    fn velocity_has_atoms_and_the_plot_compares_with_fd() {
        let dir = scratch_dir("measure");
        let svg = dir.path().join("fig.svg").to_string_lossy().to_string();
        let out = on_ball(
            run,
            &[
                "--observable",
                "velocity",
                "--wrt",
                "e",
                "--plot",
                &svg,
                "--json",
            ],
        )
        .expect("runs");
        let v = json(&out);
        // Second impact: α = −J t' with J = (1 + e) |v⁻|, t' = dt₂/de = 2 v₁/g.
        let a = v["atoms"][1]["values"]["e"].as_f64().expect("atom");
        assert!(a < -1.0, "{a}");
        let text = std::fs::read_to_string(&svg).expect("plot written");
        assert!(text.contains("MV-AD"));
        assert!(v["plot"]["comparison"]
            .as_str()
            .expect("note")
            .contains("FD"));
    }

    #[test]
    fn bad_observable_lists_the_known_ones() {
        let err = run(&Ball::new(), "b", &args(&["--observable", "x"]))
            .map(|_| ())
            .expect_err("error");
        assert_eq!(err.status(), 2);
        assert!(
            err.message()
                .contains("known observables: height, velocity"),
            "{err:?}"
        );
        let err = run(
            &Ball::new(),
            "b",
            &args(&["--observable", "height", "--plot", "a.pdf"]),
        )
        .err();
        assert_eq!(err.map(|e| e.status()), Some(2));
    }
}
