//! `mvad.Model`: a loaded `.hyb` model and what Python asks of it.
//!
//! Every method takes `params` (a dict of overrides by name) and the keyword run options
//! `rtol`, `atol`, `method`, `t_end`, `grazing_tol`, `mode`, resolved by `mvad::setup::resolve`
//! exactly as the command line resolves its flags. Derivatives (`grad`, `cost_batch`,
//! `observe_vjp_batch`) are computed in the mode `mode` names (`forward`, `adjoint`, `auto`):
//! `grad` through `mvad::runtime::solve`, the batches through `mvad::runtime::vjp`, the one
//! VJP entry point. Solves run with the GIL released; the
//! batch methods (`cost_batch`, `observe_batch`, `observe_vjp_batch`: one row of `thetas`
//! per run, θ ordered as `wrt`) run across cores with `mvad::batch::par_map`, results in
//! row order.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Mutex;

use mvad::batch::{catch, par_map, Panicked};
use mvad::interp::InterpretedModel;
use mvad::json::{
    diagnostics_json, grad_json, solve_listing, trajectory_event_json, MAX_JSON_EVENTS,
};
use mvad::load::{bind_tables, LoadError};
use mvad::runtime::{measure, sample, solve, vjp};
use mvad::setup::{check_mode, resolve, Request, Setup, SetupError};
use mvad::{HybridModel, ModelInfo};
use nalgebra::DVector;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{array, column, float_array, json_to_py, request, FloatArray};
use crate::errors::{load_error, panicked, setup_error, solve_error, value_error};

/// Why a call failed, carried out of the GIL-free section and raised after it.
enum Failure {
    Load(LoadError),
    Setup(SetupError),
    Solve(mvad::SolveError),
    Panic(Panicked),
}

impl From<SetupError> for Failure {
    fn from(e: SetupError) -> Self {
        Failure::Setup(e)
    }
}

impl From<mvad::SolveError> for Failure {
    fn from(e: mvad::SolveError) -> Self {
        Failure::Solve(e)
    }
}

impl From<Failure> for PyErr {
    fn from(f: Failure) -> Self {
        match f {
            Failure::Load(e) => load_error(e),
            Failure::Setup(e) => setup_error(e),
            Failure::Solve(e) => solve_error(e),
            Failure::Panic(e) => panicked(e),
        }
    }
}

type Resolved = Setup<InterpretedModel>;

/// A model loaded from `.hyb` text (`mvad.load(path)`).
#[pyclass(module = "mvad", frozen)]
pub struct Model {
    /// The model; its evaluator keeps scratch space, so one caller at a time.
    inner: Mutex<InterpretedModel>,
    /// Names and defaults, readable without the lock.
    info: ModelInfo,
    /// The directory the files of the model's `table` declarations are relative to.
    dir: PathBuf,
}

impl Model {
    /// Wraps a loaded model whose table files are relative to `dir`.
    pub fn new(model: InterpretedModel, dir: PathBuf) -> PyResult<Model> {
        Ok(Model {
            info: model.info().clone(),
            inner: Mutex::new(model),
            dir,
        })
    }

    /// Resolves `req` and runs `f` on the model (on a copy bound to `req.tables` when the
    /// request replaces tables), panics caught. Called without the GIL.
    fn run<R>(
        &self,
        req: &Request,
        f: impl FnOnce(&InterpretedModel, &Resolved) -> Result<R, Failure>,
    ) -> Result<R, Failure> {
        let model = match self.inner.lock() {
            Ok(m) => m,
            Err(poisoned) => poisoned.into_inner(),
        };
        catch(|| {
            let rebound;
            let m: &InterpretedModel = if req.tables.is_empty() {
                &model
            } else {
                let mut copy = model.clone();
                bind_tables(&mut copy, &self.dir, &req.tables).map_err(Failure::Load)?;
                rebound = copy;
                &rebound
            };
            let s = resolve(m, req)?;
            f(m, &s)
        })
        .map_err(Failure::Panic)?
    }

    /// `f(row index, model, θ, setup)` on every row of `thetas` (θ ordered as `wrt`), across
    /// cores, results in row order, with w (the number of `wrt` parameters once duplicates are
    /// dropped); the first failure in row order is raised.
    fn batch<R: Send>(
        &self,
        py: Python<'_>,
        req: &Request,
        thetas: &Rows,
        f: impl Fn(usize, &InterpretedModel, &DVector<f64>, &Resolved) -> Result<R, mvad::SolveError>
            + Sync,
    ) -> PyResult<(Vec<R>, usize)> {
        let out = py.detach(|| {
            self.run(req, |model, s| {
                let w = s.wrt.len();
                if thetas.cols != w {
                    return Err(Failure::Solve(mvad::SolveError::BadOption {
                        what: format!(
                            "thetas has {} columns; it needs {w}, one per wrt parameter",
                            thetas.cols
                        ),
                    }));
                }
                let rows: Vec<(usize, &[f64])> =
                    thetas.data.chunks_exact(w.max(1)).enumerate().collect();
                let results = par_map(
                    model,
                    &rows,
                    |m, &(i, row)| {
                        let mut p = s.params.clone();
                        for (&k, &v) in s.wrt.iter().zip(row) {
                            p[k] = v;
                        }
                        f(i, m, &p, s)
                    },
                    &|| {},
                );
                let out: Result<Vec<R>, Failure> = results
                    .into_iter()
                    .map(|r| r.map_err(Failure::Panic)?.map_err(Failure::Solve))
                    .collect();
                Ok((out?, w))
            })
        })?;
        Ok(out)
    }
}

/// A (B, w) array of parameter rows, copied out of Python before the GIL is released.
struct Rows {
    /// Row-major values.
    data: Vec<f64>,
    /// w.
    cols: usize,
    /// B.
    count: usize,
}

/// The (B, w) array `thetas`.
fn rows(thetas: &Bound<'_, PyAny>) -> PyResult<Rows> {
    let FloatArray { data, shape } = float_array(thetas, "thetas", 2)?;
    Ok(Rows {
        data,
        cols: shape[1],
        count: shape[0],
    })
}

/// The `wrt` list given, or every parameter (a name given twice counts once, as everywhere:
/// `thetas` has one column per distinct name).
fn wrt_or_all(info: &ModelInfo, wrt: Option<Vec<String>>) -> Vec<String> {
    wrt.unwrap_or_else(|| info.params.clone())
}

/// The request of a batch of observables (derivatives in `wrt`, every parameter by
/// default) and its sample times.
fn observe_request(
    info: &ModelInfo,
    times: &Bound<'_, PyAny>,
    wrt: Option<Vec<String>>,
    params: Option<BTreeMap<String, f64>>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<(Request, Vec<f64>)> {
    let req = request(params, Some(wrt_or_all(info, wrt)), options)?;
    Ok((req, float_array(times, "times", 1)?.data))
}

#[pymethods]
impl Model {
    /// The model's name.
    #[getter]
    fn name(&self) -> String {
        self.info.name.clone()
    }

    /// Parameter names, in declaration order (the order of θ).
    #[getter]
    fn params(&self) -> Vec<String> {
        self.info.params.clone()
    }

    /// The declared parameter values by name.
    #[getter]
    fn param_defaults(&self) -> BTreeMap<String, f64> {
        self.info
            .params
            .iter()
            .cloned()
            .zip(self.info.param_defaults.iter().copied())
            .collect()
    }

    /// State names, in declaration order.
    #[getter]
    fn states(&self) -> Vec<String> {
        self.info.states.clone()
    }

    /// Observable names, in declaration order.
    #[getter]
    fn observables(&self) -> Vec<String> {
        self.info.observables.clone()
    }

    /// Mode names (`["main"]` for a single-mode model).
    #[getter]
    fn modes(&self) -> Vec<String> {
        self.info.modes.clone()
    }

    /// Event names, in declaration order.
    #[getter]
    fn events(&self) -> Vec<String> {
        self.info.events.iter().map(|e| e.name.clone()).collect()
    }

    fn __repr__(&self) -> String {
        format!(
            "<mvad.Model {} states={:?} params={:?}>",
            self.info.name, self.info.states, self.info.params
        )
    }

    /// The cost C, dC/dθ for `wrt` (default all) and the event table: the JSON object of
    /// `mvad grad --json --mode MODE` as a dict (`forward`, `adjoint` or `auto`; its first 1000
    /// events, or all with `all_events=True`, as `--all-events`; `stats.events` counts all).
    #[pyo3(signature = (params=None, wrt=None, mode="forward", all_events=false, **options))]
    fn grad<'py>(
        &self,
        py: Python<'py>,
        params: Option<BTreeMap<String, f64>>,
        wrt: Option<Vec<String>>,
        mode: &str,
        all_events: bool,
        options: Option<&Bound<'py, PyDict>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let mut req = request(params, wrt, options)?;
        req.mode = check_mode(mode).map_err(setup_error)?;
        let info = &self.info;
        let limit = if all_events {
            usize::MAX
        } else {
            MAX_JSON_EVENTS
        };
        let value = py.detach(|| {
            self.run(&req, |m, s| {
                let sol = solve_listing(m, &s.params, &s.opts, limit)?;
                Ok(grad_json(info, m.qps(), &sol, &s.wrt))
            })
        })?;
        json_to_py(py, &value)
    }

    /// States and observables at `times` (within [0, T]; right-continuous at events):
    /// `{"t": array, "states": {name: array}, "observables": {name: array}, "events": [..],
    /// "diagnostics": [..]}`, the events as in `mvad simulate --json`.
    #[pyo3(signature = (times, params=None, **options))]
    fn simulate<'py>(
        &self,
        py: Python<'py>,
        times: &Bound<'py, PyAny>,
        params: Option<BTreeMap<String, f64>>,
        options: Option<&Bound<'py, PyDict>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let req = request(params, None, options)?;
        let ts = float_array(times, "times", 1)?.data;
        let info = &self.info;
        let (smp, events, diags) = py.detach(|| {
            self.run(&req, |m, s| {
                let mut opts = s.opts.clone();
                opts.record = true;
                opts.sensitivities = false;
                let sol = solve(m, &s.params, &opts)?;
                let smp = sample(m, &s.params, &sol, &ts)?;
                let events: Vec<_> = sol
                    .events
                    .iter()
                    .map(|e| trajectory_event_json(info, e))
                    .collect();
                Ok((smp, events, diagnostics_json(&sol.diagnostics)))
            })
        })?;
        let out = PyDict::new(py);
        out.set_item("t", array(py, ts.clone(), &[ts.len()])?)?;
        let states = PyDict::new(py);
        for (r, name) in self.info.states.iter().enumerate() {
            let col = column(&smp.states, smp.nstates, r);
            states.set_item(name, array(py, col, &[ts.len()])?)?;
        }
        out.set_item("states", states)?;
        let obs = PyDict::new(py);
        for (o, name) in self.info.observables.iter().enumerate() {
            let col = column(&smp.observables, smp.nobservables, o);
            obs.set_item(name, array(py, col, &[ts.len()])?)?;
        }
        out.set_item("observables", obs)?;
        out.set_item("events", json_to_py(py, &serde_json::Value::from(events))?)?;
        out.set_item("diagnostics", json_to_py(py, &diags)?)?;
        Ok(out.into_any())
    }

    /// The derivative of `observable` as a measure, one column per `wrt` parameter: the
    /// density h_x S + h_θ on `grid` (default: `points` equispaced times on [0, T]) and the
    /// atoms α_k = −J_k t_k' at the event times, with ⟨μ, 1⟩ = d/dθ ∫₀ᵀ y dt.
    #[pyo3(signature = (observable, params=None, wrt=None, grid=None, points=201, **options))]
    #[allow(clippy::too_many_arguments)]
    fn measure<'py>(
        &self,
        py: Python<'py>,
        observable: &str,
        params: Option<BTreeMap<String, f64>>,
        wrt: Option<Vec<String>>,
        grid: Option<&Bound<'py, PyAny>>,
        points: i64,
        options: Option<&Bound<'py, PyDict>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let obs = self.info.observable_index(observable).ok_or_else(|| {
            value_error(format!(
                "unknown observable `{observable}`; known observables: {}",
                self.info.observables.join(", ")
            ))
        })?;
        if grid.is_none() && !(2..=1_000_000).contains(&points) {
            return Err(value_error(format!(
                "points must be between 2 and 1000000, got {points}"
            )));
        }
        let req = request(params, wrt, options)?;
        let given: Option<Vec<f64>> = match grid {
            Some(g) => Some(float_array(g, "grid", 1)?.data),
            None => None,
        };
        let points = points as usize; // in 2..=10⁶ when no grid is given
        let (grid, wrt, dens, atoms_t, atoms, total) = py.detach(|| {
            self.run(&req, |m, s| {
                let mut opts = s.opts.clone();
                opts.record = true;
                let sol = solve(m, &s.params, &opts)?;
                let mu = measure(m, &s.params, &sol, obs)?;
                let grid = given.clone().unwrap_or_else(|| {
                    (0..points)
                        .map(|i| sol.t_end * i as f64 / (points - 1) as f64)
                        .collect()
                });
                mvad::runtime::sample::check_times(&grid, sol.t_end)?;
                let pick = |v: &[f64]| s.wrt.iter().map(|&k| v[k]).collect::<Vec<f64>>();
                let dens: Vec<f64> = grid.iter().flat_map(|&t| pick(&mu.density(t))).collect();
                let atoms_t: Vec<f64> = mu.atoms.iter().map(|a| a.0).collect();
                let atoms: Vec<f64> = mu.atoms.iter().flat_map(|a| pick(&a.1)).collect();
                let total = pick(&mu.pair(|_| 1.0));
                Ok((grid, s.wrt.clone(), dens, atoms_t, atoms, total))
            })
        })?;
        let w = wrt.len();
        let out = PyDict::new(py);
        out.set_item("observable", observable)?;
        let names: Vec<String> = wrt.iter().map(|&k| self.info.params[k].clone()).collect();
        out.set_item("wrt", names)?;
        out.set_item("grid", array(py, grid.clone(), &[grid.len()])?)?;
        out.set_item("density", array(py, dens, &[grid.len(), w])?)?;
        let atom_dict = PyDict::new(py);
        atom_dict.set_item("t", array(py, atoms_t.clone(), &[atoms_t.len()])?)?;
        atom_dict.set_item("values", array(py, atoms, &[atoms_t.len(), w])?)?;
        out.set_item("atoms", atom_dict)?;
        out.set_item("integral_derivative", array(py, total, &[w])?)?;
        Ok(out.into_any())
    }

    /// C(θ) for each row of `thetas` (shape (B, len(wrt)), θ ordered as `wrt`), and with
    /// `gradient=True` dC/dθ for the `wrt` parameters: `(costs (B,), gradients (B, w))`.
    /// Runs across cores.
    #[pyo3(signature = (thetas, wrt=None, params=None, gradient=true, **options))]
    fn cost_batch<'py>(
        &self,
        py: Python<'py>,
        thetas: &Bound<'py, PyAny>,
        wrt: Option<Vec<String>>,
        params: Option<BTreeMap<String, f64>>,
        gradient: bool,
        options: Option<&Bound<'py, PyDict>>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let req = request(params, Some(wrt_or_all(&self.info, wrt)), options)?;
        let flat = rows(thetas)?;
        let (results, w) = self.batch(py, &req, &flat, |_, m, p, s| {
            if gradient {
                let (c, g) = vjp::cost_gradient(m, p, &s.opts)?;
                Ok((c, s.wrt.iter().map(|&k| g[k]).collect::<Vec<_>>()))
            } else {
                Ok((vjp::cost(m, p, &s.opts)?, Vec::new()))
            }
        })?;
        let b = results.len();
        let costs: Vec<f64> = results.iter().map(|r| r.0).collect();
        let grads: Vec<f64> = results.into_iter().flat_map(|r| r.1).collect();
        let gshape = if gradient { [b, w] } else { [b, 0] };
        Ok((array(py, costs, &[b])?, array(py, grads, &gshape)?))
    }

    /// The observables at `times` for each row of `thetas`: shape (B, len(times), m).
    #[pyo3(signature = (thetas, times, wrt=None, params=None, **options))]
    fn observe_batch<'py>(
        &self,
        py: Python<'py>,
        thetas: &Bound<'py, PyAny>,
        times: &Bound<'py, PyAny>,
        wrt: Option<Vec<String>>,
        params: Option<BTreeMap<String, f64>>,
        options: Option<&Bound<'py, PyDict>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (req, ts) = observe_request(&self.info, times, wrt, params, options)?;
        let flat = rows(thetas)?;
        let (results, _) = self.batch(py, &req, &flat, |_, m, p, s| {
            vjp::observe(m, p, &s.opts, &ts)
        })?;
        let b = results.len();
        let m = self.info.nobservables();
        let data: Vec<f64> = results.into_iter().flatten().collect();
        array(py, data, &[b, ts.len(), m])
    }

    /// ȳᵀ ∂y/∂θ for each row of `thetas` and of `cotangents` (shape (B, len(times), m)),
    /// for the `wrt` parameters: shape (B, w). The backward pass of `mvad.jax.observe` and
    /// `mvad.torch.observe` (`mvad::runtime::vjp::observe_vjp`).
    #[pyo3(signature = (thetas, times, cotangents, wrt=None, params=None, **options))]
    #[allow(clippy::too_many_arguments)]
    fn observe_vjp_batch<'py>(
        &self,
        py: Python<'py>,
        thetas: &Bound<'py, PyAny>,
        times: &Bound<'py, PyAny>,
        cotangents: &Bound<'py, PyAny>,
        wrt: Option<Vec<String>>,
        params: Option<BTreeMap<String, f64>>,
        options: Option<&Bound<'py, PyDict>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (req, ts) = observe_request(&self.info, times, wrt, params, options)?;
        let m = self.info.nobservables();
        let thetas = rows(thetas)?;
        let b = thetas.count;
        let cotangents = float_array(cotangents, "cotangents", 3)?;
        if cotangents.shape != [b, ts.len(), m] {
            return Err(value_error(format!(
                "cotangents must have shape ({b}, {}, {m}), got {:?}",
                ts.len(),
                cotangents.shape
            )));
        }
        let cot = cotangents.data;
        let per_row = ts.len() * m;
        let (results, w) = self.batch(py, &req, &thetas, |i, model, p, s| {
            let ybar = &cot[i * per_row..(i + 1) * per_row];
            let v = vjp::observe_vjp(model, p, &s.opts, &ts, ybar)?;
            Ok(s.wrt.iter().map(|&k| v[k]).collect::<Vec<_>>())
        })?;
        let data: Vec<f64> = results.into_iter().flatten().collect();
        array(py, data, &[b, w])
    }
}
