//! Rust failures as Python exceptions, one mapping for the whole module:
//!
//! | failure | exception |
//! |---|---|
//! | a model that does not compile (`LoadError::Model`), a bad data table (`LoadError::Table`) | `mvad.ModelError` (a `ValueError`), the located `FILE:LINE:COL: error:` text |
//! | a table name the model does not declare | `ValueError` |
//! | a file that cannot be read | `FileNotFoundError` / `OSError` |
//! | a bad request (unknown parameter, tolerance out of range, no horizon, bad sample times) | `ValueError` |
//! | a run that started and failed (non-finite values, step-size underflow, too many events or steps) | `mvad.SolveError` (a `RuntimeError`) |
//! | a panic inside the library | `mvad.SolveError` saying it is an internal error |

use mvad::batch::Panicked;
use mvad::load::LoadError;
use mvad::setup::{SetupError, Spelling};
use pyo3::create_exception;
use pyo3::exceptions::{PyFileNotFoundError, PyOSError, PyRuntimeError, PyValueError};
use pyo3::PyErr;

create_exception!(
    mvad,
    ModelError,
    PyValueError,
    "A .hyb model that does not compile; the message holds `FILE:LINE:COL: error: ...` for each error."
);
create_exception!(
    mvad,
    SolveError,
    PyRuntimeError,
    "A run that started and failed (non-finite values, step-size underflow, too many events or steps)."
);

/// How Python spells the options of a request: keyword arguments (`rtol`, `t_end=T`); the
/// parameter overrides are the `params` dict.
pub struct Keywords;

impl Spelling for Keywords {
    fn option(&self, name: &str) -> String {
        match name {
            "set" => "params".to_string(),
            other => other.to_string(),
        }
    }
    fn assign(&self, name: &str, value: &str) -> String {
        format!("{}={value}", self.option(name))
    }
}

/// A model that could not be loaded.
pub fn load_error(e: LoadError) -> PyErr {
    match &e {
        LoadError::Io { path, .. } if !std::path::Path::new(path).exists() => {
            PyFileNotFoundError::new_err(e.to_string())
        }
        LoadError::Io { .. } => PyOSError::new_err(e.to_string()),
        LoadError::Model { .. } | LoadError::Table(_) => ModelError::new_err(e.to_string()),
        LoadError::UnknownTable { .. } => PyValueError::new_err(e.to_string()),
    }
}

/// A request that cannot run.
pub fn setup_error(e: SetupError) -> PyErr {
    PyValueError::new_err(e.message(&Keywords))
}

/// A run that failed, or was asked for with bad input.
pub fn solve_error(e: mvad::SolveError) -> PyErr {
    if e.is_bad_input() {
        PyValueError::new_err(e.to_string())
    } else {
        SolveError::new_err(format!("the run failed: {e}"))
    }
}

/// A panic caught at the boundary.
pub fn panicked(e: Panicked) -> PyErr {
    SolveError::new_err(e.to_string())
}

/// A bad argument of the Python API itself (a shape, a name).
pub fn value_error(msg: impl Into<String>) -> PyErr {
    PyValueError::new_err(msg.into())
}
