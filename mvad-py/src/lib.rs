//! `mvad._mvad`, the native half of the Python package `mvad` (PyO3).
//!
//! [`load`] and [`from_source`] turn `.hyb` text into a [`model::Model`]; its methods return
//! the JSON object of `mvad grad --json` as a dict (built by `mvad::json`, the builder the
//! command line prints), trajectories and measures as numpy arrays, and the batched kernels
//! the `mvad.jax` and `mvad.torch` layers call. Every solve runs with the GIL released, and
//! batches run across cores (`mvad::batch::par_map`). Errors become Python exceptions
//! ([`errors`]); a panic is caught and raised as `mvad.SolveError`, never unwound into the
//! interpreter.

mod convert;
mod errors;
mod model;

use std::path::PathBuf;

use pyo3::prelude::*;

use errors::{load_error, ModelError, SolveError};
use model::Model;

/// Loads and compiles the `.hyb` file at `path`.
///
/// Raises `mvad.ModelError` (with the located `FILE:LINE:COL: error:` text) for an invalid
/// model and `OSError` when the file cannot be read.
#[pyfunction]
fn load(py: Python<'_>, path: PathBuf) -> PyResult<Model> {
    let loaded = py.detach(|| mvad::batch::catch(|| mvad::load::load(&path)));
    Model::new(loaded.map_err(errors::panicked)?.map_err(load_error)?)
}

/// Compiles model text held in memory; `name` is the file name used in error messages.
#[pyfunction]
#[pyo3(signature = (text, name = "<string>"))]
fn from_source(py: Python<'_>, text: &str, name: &str) -> PyResult<Model> {
    let loaded = py.detach(|| mvad::batch::catch(|| mvad::load::load_str(name, text)));
    Model::new(loaded.map_err(errors::panicked)?.map_err(load_error)?)
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
