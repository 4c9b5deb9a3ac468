//! `mvad._mvad`, the native half of the Python package `mvad` (PyO3).
//!
//! `load` and `from_source` turn `.hyb` text into a `model::Model`; its methods return
//! the JSON object of `mvad grad --json` as a dict (built by `mvad::json`, the builder the
//! command line prints), trajectories and measures as numpy arrays, and the batched kernels
//! the `mvad.jax` and `mvad.torch` layers call. Every solve runs with the GIL released, and
//! batches run across cores (`mvad::batch::par_map`). Errors become Python exceptions
//! (`errors`); a panic is caught and raised as `mvad.SolveError`, never unwound into the
//! interpreter.

mod convert;
mod errors;
mod model;

use std::path::PathBuf;

use pyo3::prelude::*;

use errors::{load_error, ModelError, SolveError};
use model::Model;

/// Loads and compiles the `.hyb` file at `path` and reads the data tables it declares (files
/// relative to the model), or takes them from `tables` (`{"NAME": "FILE.csv"}` or
/// `{"NAME": {"COL": array}}`, as every run method also accepts).
///
/// Raises `mvad.ModelError` (with the located `FILE:LINE:COL: error:` text) for an invalid
/// model or table and `OSError` when the model file cannot be read.
#[pyfunction]
#[pyo3(signature = (path, tables = None))]
fn load(py: Python<'_>, path: PathBuf, tables: Option<Bound<'_, PyAny>>) -> PyResult<Model> {
    let tables = match tables {
        Some(t) if !t.is_none() => convert::tables(&t)?,
        _ => Vec::new(),
    };
    let loaded = py.detach(|| mvad::batch::catch(|| mvad::load::load_with_tables(&path, &tables)));
    let dir = path.parent().map(PathBuf::from).unwrap_or_default();
    Model::new(loaded.map_err(errors::panicked)?.map_err(load_error)?, dir)
}

/// Compiles model text held in memory; `name` is the file name used in error messages. Its
/// data tables are not read: pass them to the run methods (`tables=`), files relative to the
/// working directory.
#[pyfunction]
#[pyo3(signature = (text, name = "<string>"))]
fn from_source(py: Python<'_>, text: &str, name: &str) -> PyResult<Model> {
    let loaded = py.detach(|| mvad::batch::catch(|| mvad::load::load_str(name, text)));
    Model::new(
        loaded.map_err(errors::panicked)?.map_err(load_error)?,
        PathBuf::new(),
    )
}

/// The native module.
#[pymodule]
fn _mvad(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(load, m)?)?;
    m.add_function(wrap_pyfunction!(from_source, m)?)?;
    m.add_class::<Model>()?;
    m.add("ModelError", m.py().get_type::<ModelError>())?;
    m.add("SolveError", m.py().get_type::<SolveError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
