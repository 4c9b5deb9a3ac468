//! A suite of cases kept as data: a directory holding `manifest.json` and the `.hyb` files it
//! names. Each case is a model with parameter overrides, the options of its check, a
//! reference (a closed form, or an independent tight run of another method whose gradient
//! is taken by central differences) and what it must satisfy:
//!
//! - `bound`: relative errors of C and of dC/dθ (max_i |Δ_i| / max_i |ref_i| over the
//!   referenced parameters; absolute when the reference is 0) that the check must meet;
//! - `require`: diagnostic kinds that must be raised (`zeno` for an accumulation);
//! - `excuse`: diagnostic kinds that, when raised, excuse a missed bound: the tool said the
//!   number is unreliable (`grazing` near a tangency). A run that fails with an error counts
//!   as raising that error's kind (`max_steps`, `step_size_underflow`, ...).
//!
//! A case passes when every required kind is present and either the bound is met or an
//! excusing kind is present; a missed bound with no excuse is a silently wrong number, the
//! defect the suite exists to catch. `fast` cases run under `cargo test`; `mvad report` runs
//! them all across methods and tolerances.
//!
//! ```json
//! { "cases": [ {
//!     "name": "zeno e=0.5", "model": "zeno_ball.hyb", "set": {"e": 0.5},
//!     "check": {"method": "auto", "rtol": 1e-10, "atol": 1e-12},
//!     "reference": {"cost": 1.0946, "gradient": {"e": 1.668}, "source": "geometric series"},
//!     "bound": {"cost": 1e-10, "gradient": 1e-10}, "require": ["zeno"], "fast": true } ] }
//! ```
//!
//! A run reference is `"reference": {"run": {"method": "rosenbrock", "rtol": 1e-12,
//! "atol": 1e-14}, "fd_step": 1e-5, "source": "..."}`: C of that run, and dC/dθ by central
//! differences of its primal runs with relative step `fd_step` (an independent mechanism),
//! or without `fd_step` the tight run's own dC/dθ.

use std::path::{Path, PathBuf};
use std::time::Instant;

use nalgebra::DVector;
use serde_json::Value;

use crate::interp::InterpretedModel;
use crate::runtime::error::SolveError;
use crate::runtime::fd::fd_gradient;
use crate::runtime::solution::{GradientMode, Method, Options, Solution};
use crate::runtime::solve::solve;
use crate::HybridModel;

/// The suite: its directory and its cases, in manifest order.
#[derive(Clone, Debug)]
pub struct Suite {
    /// The directory holding `manifest.json` and the models.
    pub dir: PathBuf,
    /// The cases.
    pub cases: Vec<Case>,
}

/// Method and tolerances of one run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RunSpec {
    /// Integration method.
    pub method: Method,
    /// Relative tolerance.
    pub rtol: f64,
    /// Absolute tolerance.
    pub atol: f64,
}

/// Where a case's reference values come from.
#[derive(Clone, Debug)]
pub enum ReferenceSpec {
    /// Values given in the manifest (closed forms), C and dC/dθ by parameter name.
    Given {
        /// C, if referenced.
        cost: Option<f64>,
        /// dC/dθ by parameter name.
        gradient: Vec<(String, f64)>,
    },
    /// An independent tight run: C from it, dC/dθ over `wrt` (every parameter when empty) by
    /// central differences of its primal runs with relative step `fd_step`, or, without a
    /// step, from the tight run's own sensitivities (when differences cannot resolve a
    /// parameter, such as a time constant of 1e-6 whose step would be 1e-11).
    Run {
        /// The run.
        run: RunSpec,
        /// Relative step of the central differences (`None`: the run's sensitivities).
        fd_step: Option<f64>,
        /// Parameters whose derivatives are referenced.
        wrt: Vec<String>,
    },
}

/// One case of the suite.
#[derive(Clone, Debug)]
pub struct Case {
    /// Unique name.
    pub name: String,
    /// The model file, relative to the suite directory.
    pub model: String,
    /// Parameter overrides.
    pub set: Vec<(String, f64)>,
    /// Horizon override.
    pub t_end: Option<f64>,
    /// Grazing tolerance override.
    pub grazing_tol: Option<f64>,
    /// The run that is checked.
    pub check: RunSpec,
    /// The reference.
    pub reference: ReferenceSpec,
    /// Where the reference comes from, in words.
    pub source: String,
    /// Relative error bounds of C and dC/dθ (∞ when not checked).
    pub bound_cost: f64,
    /// See [`Case::bound_cost`].
    pub bound_gradient: f64,
    /// Diagnostic kinds that must be present.
    pub require: Vec<String>,
    /// Diagnostic kinds that excuse a missed bound.
    pub excuse: Vec<String>,
    /// Runs under `cargo test`.
    pub fast: bool,
    /// Tolerances of the report's sweep (empty: the check only).
    pub sweep: Vec<f64>,
}

/// The reference values of a case, resolved: C and dC/dθ over the referenced parameters.
#[derive(Clone, Debug)]
pub struct Reference {
    /// C (NaN when not referenced).
    pub cost: f64,
    /// Indices of the referenced parameters.
    pub wrt: Vec<usize>,
    /// dC/dθ over `wrt`.
    pub gradient: Vec<f64>,
}

/// What one checked run gave.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// C (NaN when the run failed).
    pub cost: f64,
    /// dC/dθ over the reference's parameters.
    pub gradient: Vec<f64>,
    /// Relative error of C.
    pub cost_err: f64,
    /// Relative error of dC/dθ (max |Δ| / max |ref|).
    pub grad_err: f64,
    /// Accepted steps.
    pub steps: usize,
    /// Events.
    pub events: usize,
    /// Diagnostic kinds raised (a failed run's error kind included), without repeats.
    pub diagnostics: Vec<String>,
    /// The error of a failed run.
    pub error: Option<String>,
    /// Wall time of the run.
    pub seconds: f64,
    /// The run's global error estimate of C and of dC/dθ, relative as `cost_err` and
    /// `grad_err` are (the gradient's: max |e| / max |ref| over the reference's parameters),
    /// when it carried one.
    pub estimate: Option<(f64, f64)>,
}

/// Whether a case passed, and why.
#[derive(Clone, Debug)]
pub struct Verdict {
    /// Passed.
    pub pass: bool,
    /// One line: what was met, missed, excused or missing.
    pub reason: String,
}

/// The relative error |a − r|/|r| (absolute when r = 0).
pub fn rel_error(a: f64, r: f64) -> f64 {
    if r != 0.0 {
        (a - r).abs() / r.abs()
    } else {
        (a - r).abs()
    }
}

/// The error measure of a gradient: max_i |a_i − r_i| / max_i |r_i| (absolute when r = 0).
pub fn grad_error(a: &[f64], r: &[f64]) -> f64 {
    let diff = a
        .iter()
        .zip(r)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    let scale = r.iter().map(|y| y.abs()).fold(0.0, f64::max);
    if scale > 0.0 {
        diff / scale
    } else {
        diff
    }
}

/// Tolerances of the report's sweep when a case names none.
pub const DEFAULT_SWEEP: [f64; 5] = [1e-4, 1e-6, 1e-8, 1e-10, 1e-12];

impl Suite {
    /// Reads `DIR/manifest.json`; every error names the case and the key.
    pub fn load(dir: &Path) -> Result<Suite, String> {
        let path = dir.join("manifest.json");
        let text = std::fs::read_to_string(&path)
            .map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
        let v: Value = serde_json::from_str(&text)
            .map_err(|e| format!("{}: not JSON: {e}", path.display()))?;
        let list = v["cases"]
            .as_array()
            .ok_or_else(|| format!("{}: no `cases` array", path.display()))?;
        let mut cases = Vec::with_capacity(list.len());
        for (i, c) in list.iter().enumerate() {
            let case = Case::parse(c).map_err(|e| format!("{}: case {i}: {e}", path.display()))?;
            if cases.iter().any(|k: &Case| k.name == case.name) {
                return Err(format!(
                    "{}: duplicate case `{}`",
                    path.display(),
                    case.name
                ));
            }
            cases.push(case);
        }
        Ok(Suite {
            dir: dir.to_path_buf(),
            cases,
        })
    }
}

fn number(v: &Value, key: &str) -> Result<Option<f64>, String> {
    match &v[key] {
        Value::Null => Ok(None),
        x => x
            .as_f64()
            .filter(|f| f.is_finite())
            .map(Some)
            .ok_or_else(|| format!("`{key}` must be a finite number")),
    }
}

fn strings(v: &Value, key: &str) -> Result<Vec<String>, String> {
    match &v[key] {
        Value::Null => Ok(Vec::new()),
        Value::Array(a) => a
            .iter()
            .map(|s| s.as_str().map(str::to_string))
            .collect::<Option<Vec<_>>>()
            .ok_or_else(|| format!("`{key}` must be a list of strings")),
        _ => Err(format!("`{key}` must be a list of strings")),
    }
}

fn named_numbers(v: &Value, key: &str) -> Result<Vec<(String, f64)>, String> {
    match &v[key] {
        Value::Null => Ok(Vec::new()),
        Value::Object(m) => m
            .iter()
            .map(|(k, x)| {
                x.as_f64()
                    .filter(|f| f.is_finite())
                    .map(|f| (k.clone(), f))
                    .ok_or_else(|| format!("`{key}.{k}` must be a finite number"))
            })
            .collect(),
        _ => Err(format!("`{key}` must be an object of numbers")),
    }
}

fn run_spec(v: &Value, what: &str) -> Result<RunSpec, String> {
    let method = match v["method"].as_str() {
        None => Method::Auto,
        Some(m) => Method::from_name(m).ok_or_else(|| format!("{what}: unknown method `{m}`"))?,
    };
    let defaults = Options::default();
    Ok(RunSpec {
        method,
        rtol: number(v, "rtol")?.unwrap_or(defaults.rtol),
        atol: number(v, "atol")?.unwrap_or(defaults.atol),
    })
}

impl Case {
    fn parse(c: &Value) -> Result<Case, String> {
        let name = c["name"].as_str().ok_or("no `name`")?.to_string();
        let err = |e: String| format!("`{name}`: {e}");
        let model = c["model"]
            .as_str()
            .ok_or_else(|| err("no `model`".into()))?
            .to_string();
        let r = &c["reference"];
        let reference = if r["run"].is_object() {
            ReferenceSpec::Run {
                run: run_spec(&r["run"], "reference.run").map_err(err)?,
                fd_step: number(r, "fd_step").map_err(err)?,
                wrt: strings(r, "wrt").map_err(err)?,
            }
        } else {
            ReferenceSpec::Given {
                cost: number(r, "cost").map_err(err)?,
                gradient: named_numbers(r, "gradient").map_err(err)?,
            }
        };
        let b = &c["bound"];
        let sweep = match &c["sweep"] {
            Value::Null => DEFAULT_SWEEP.to_vec(),
            _ => {
                let s: Option<Vec<f64>> = c["sweep"]
                    .as_array()
                    .map(|a| a.iter().filter_map(Value::as_f64).collect());
                s.ok_or_else(|| err("`sweep` must be a list of tolerances".into()))?
            }
        };
        Ok(Case {
            model,
            set: named_numbers(c, "set").map_err(err)?,
            t_end: number(c, "t_end").map_err(err)?,
            grazing_tol: number(c, "grazing_tol").map_err(err)?,
            check: run_spec(&c["check"], "check").map_err(err)?,
            reference,
            source: r["source"].as_str().unwrap_or("").to_string(),
            bound_cost: number(b, "cost").map_err(err)?.unwrap_or(f64::INFINITY),
            bound_gradient: number(b, "gradient").map_err(err)?.unwrap_or(f64::INFINITY),
            require: strings(c, "require").map_err(err)?,
            excuse: strings(c, "excuse").map_err(err)?,
            fast: c["fast"].as_bool().unwrap_or(false),
            sweep,
            name,
        })
    }

    /// Loads the case's model from the suite directory.
    pub fn load_model(&self, dir: &Path) -> Result<InterpretedModel, String> {
        crate::load::load(&dir.join(&self.model)).map_err(|e| e.to_string())
    }

    /// θ: the model's defaults with the case's overrides.
    pub fn params(&self, model: &InterpretedModel) -> Result<DVector<f64>, String> {
        let info = model.info();
        let mut p = DVector::from_column_slice(&info.param_defaults);
        for (name, v) in &self.set {
            let k = self.param(model, name)?;
            p[k] = *v;
        }
        Ok(p)
    }

    fn param(&self, model: &InterpretedModel, name: &str) -> Result<usize, String> {
        model
            .info()
            .params
            .iter()
            .position(|q| q == name)
            .ok_or_else(|| format!("`{}`: no parameter `{name}` in {}", self.name, self.model))
    }

    /// The options of a run of this case with `run`'s method and tolerances.
    pub fn options(&self, run: RunSpec) -> Options {
        let d = Options::default();
        Options {
            method: run.method,
            rtol: run.rtol,
            atol: run.atol,
            t_end: self.t_end,
            grazing_tol: self.grazing_tol.unwrap_or(d.grazing_tol),
            ..d
        }
    }

    /// The reference values: given, or from the independent tight run (C) and central
    /// differences of its primal runs (dC/dθ).
    pub fn reference(
        &self,
        model: &InterpretedModel,
        params: &DVector<f64>,
    ) -> Result<Reference, String> {
        match &self.reference {
            ReferenceSpec::Given { cost, gradient } => {
                let mut wrt = Vec::new();
                let mut values = Vec::new();
                for (name, v) in gradient {
                    wrt.push(self.param(model, name)?);
                    values.push(*v);
                }
                Ok(Reference {
                    cost: cost.unwrap_or(f64::NAN),
                    wrt,
                    gradient: values,
                })
            }
            ReferenceSpec::Run {
                run,
                fd_step: rel,
                wrt,
            } => {
                let fail =
                    |e: SolveError| format!("`{}`: the reference run failed: {e}", self.name);
                let wrt: Vec<usize> = if wrt.is_empty() {
                    (0..params.len()).collect()
                } else {
                    wrt.iter()
                        .map(|n| self.param(model, n))
                        .collect::<Result<_, _>>()?
                };
                let Some(rel) = rel else {
                    let sol = solve(model, params, &self.options(*run)).map_err(fail)?;
                    return Ok(Reference {
                        cost: sol.cost,
                        gradient: wrt.iter().map(|&k| sol.gradient[k]).collect(),
                        wrt,
                    });
                };
                let primal = Options {
                    sensitivities: false,
                    ..self.options(*run)
                };
                let cost = solve(model, params, &primal).map_err(fail)?.cost;
                let gradient = wrt
                    .iter()
                    .map(|&k| fd_gradient(model, params, &primal, k, *rel))
                    .collect::<Result<Vec<f64>, SolveError>>()
                    .map_err(fail)?;
                Ok(Reference {
                    cost,
                    wrt,
                    gradient,
                })
            }
        }
    }

    /// The outcome of one run (already timed) against the reference.
    pub fn outcome(
        &self,
        result: Result<Solution, SolveError>,
        seconds: f64,
        reference: &Reference,
    ) -> Outcome {
        match result {
            Ok(sol) => {
                let gradient: Vec<f64> = reference.wrt.iter().map(|&k| sol.gradient[k]).collect();
                // Measured as the errors are: the reference moved by the estimate.
                let estimate = sol.error_estimate.as_ref().map(|e| {
                    let r = &reference.gradient;
                    let moved: Vec<f64> = match e.gradient.is_empty() {
                        true => r.clone(),
                        false => reference
                            .wrt
                            .iter()
                            .zip(r)
                            .map(|(&k, v)| v + e.gradient[k])
                            .collect(),
                    };
                    let cost = match reference.cost.is_nan() {
                        true => 0.0,
                        false => rel_error(reference.cost + e.cost, reference.cost),
                    };
                    (cost, grad_error(&moved, r))
                });
                let mut diagnostics: Vec<String> = Vec::new();
                for d in &sol.diagnostics {
                    let k = d.kind.name().to_string();
                    if !diagnostics.contains(&k) {
                        diagnostics.push(k);
                    }
                }
                Outcome {
                    cost_err: if reference.cost.is_nan() {
                        0.0
                    } else {
                        rel_error(sol.cost, reference.cost)
                    },
                    grad_err: grad_error(&gradient, &reference.gradient),
                    cost: sol.cost,
                    gradient,
                    steps: sol.stats.steps,
                    events: sol.events.len(),
                    diagnostics,
                    error: None,
                    seconds,
                    estimate,
                }
            }
            Err(e) => Outcome {
                cost: f64::NAN,
                gradient: vec![f64::NAN; reference.wrt.len()],
                cost_err: f64::NAN,
                grad_err: f64::NAN,
                steps: 0,
                events: 0,
                diagnostics: e
                    .diagnostic()
                    .map(|d| vec![d.kind.name().to_string()])
                    .unwrap_or_else(|| vec!["error".to_string()]),
                error: Some(e.to_string()),
                seconds,
                estimate: None,
            },
        }
    }

    /// The verdict on an outcome of the checked run (see the module doc).
    pub fn verdict(&self, o: &Outcome) -> Verdict {
        let missing: Vec<&String> = self
            .require
            .iter()
            .filter(|k| !o.diagnostics.contains(k))
            .collect();
        let within = o.cost_err <= self.bound_cost && o.grad_err <= self.bound_gradient;
        let excuse = self.excuse.iter().find(|k| o.diagnostics.contains(k));
        let errors = format!(
            "err C {:.1e} (bound {:.0e}), err dC {:.1e} (bound {:.0e})",
            o.cost_err, self.bound_cost, o.grad_err, self.bound_gradient
        );
        if !missing.is_empty() {
            let names: Vec<&str> = missing.iter().map(|s| s.as_str()).collect();
            return Verdict {
                pass: false,
                reason: format!(
                    "required diagnostic missing: {}; {errors}",
                    names.join(", ")
                ),
            };
        }
        match (within, excuse) {
            (true, _) => Verdict {
                pass: true,
                reason: format!("within bounds: {errors}"),
            },
            (false, Some(k)) => Verdict {
                pass: true,
                reason: format!("bound missed, `{k}` raised: {errors}"),
            },
            (false, None) => Verdict {
                pass: false,
                reason: match &o.error {
                    Some(e) => format!("the run failed: {e}"),
                    None => format!("WRONG WITH NO DIAGNOSTIC: {errors}"),
                },
            },
        }
    }

    /// Runs the checked configuration once and judges it: (reference, outcome, verdict).
    pub fn check_in(&self, dir: &Path) -> Result<(Reference, Outcome, Verdict), String> {
        self.check_in_mode(dir, GradientMode::Forward)
    }

    /// [`Case::check_in`] with the gradient computed in `mode` (the case's bounds and
    /// diagnostics are the same in every mode).
    pub fn check_in_mode(
        &self,
        dir: &Path,
        mode: GradientMode,
    ) -> Result<(Reference, Outcome, Verdict), String> {
        let model = self.load_model(dir)?;
        let params = self.params(&model)?;
        let reference = self.reference(&model, &params)?;
        let opts = Options {
            gradient_mode: mode,
            ..self.options(self.check)
        };
        let start = Instant::now();
        let result = solve(&model, &params, &opts);
        let outcome = self.outcome(result, start.elapsed().as_secs_f64(), &reference);
        let verdict = self.verdict(&outcome);
        Ok((reference, outcome, verdict))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn case(json: &str) -> Case {
        Case::parse(&serde_json::from_str(json).expect("json")).expect("case")
    }

    fn outcome(cost_err: f64, grad_err: f64, diagnostics: &[&str]) -> Outcome {
        Outcome {
            cost: 0.0,
            gradient: vec![],
            cost_err,
            grad_err,
            steps: 1,
            events: 0,
            diagnostics: diagnostics.iter().map(|s| s.to_string()).collect(),
            error: None,
            seconds: 0.0,
            estimate: None,
        }
    }

    #[test]
    fn a_wrong_number_without_a_diagnostic_fails() {
        let c = case(
            r#"{"name": "a", "model": "m.hyb", "bound": {"cost": 1e-6, "gradient": 1e-6},
                "excuse": ["grazing"], "require": ["zeno"]}"#,
        );
        assert!(c.verdict(&outcome(1e-7, 1e-7, &["zeno"])).pass);
        let silent = c.verdict(&outcome(1e-7, 1e-3, &["zeno"]));
        assert!(
            !silent.pass && silent.reason.contains("NO DIAGNOSTIC"),
            "{silent:?}"
        );
        assert!(c.verdict(&outcome(1e-7, 1e-3, &["zeno", "grazing"])).pass);
        let missing = c.verdict(&outcome(0.0, 0.0, &[]));
        assert!(
            !missing.pass && missing.reason.contains("zeno"),
            "{missing:?}"
        );
        // NaN errors (a failed run) never meet a bound.
        assert!(!c.verdict(&outcome(f64::NAN, f64::NAN, &["zeno"])).pass);
    }

    #[test]
    fn manifest_errors_name_the_case_and_key() {
        let bad = serde_json::from_str(r#"{"name": "b", "model": "m.hyb", "set": {"e": "x"}}"#)
            .expect("json");
        let e = Case::parse(&bad).expect_err("bad set");
        assert!(e.contains("`b`") && e.contains("set.e"), "{e}");
        let bad =
            serde_json::from_str(r#"{"name": "c", "model": "m", "check": {"method": "rk4"}}"#)
                .expect("json");
        assert!(Case::parse(&bad).expect_err("method").contains("rk4"));
        assert_eq!(grad_error(&[1.0, 2.0], &[1.0, 4.0]), 0.5);
        assert_eq!(rel_error(1.0, 0.0), 1.0);
    }
}
