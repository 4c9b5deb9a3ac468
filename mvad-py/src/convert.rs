//! Python values in and out: keyword options into a `mvad::setup::Request`, parameter
//! batches into parameter vectors, `serde_json` values into Python objects, flat vectors into
//! numpy arrays.

use std::collections::BTreeMap;

use std::path::PathBuf;

use mvad::runtime::solution::Method;
use mvad::setup::{check_mode, Request};
use mvad::table::{Table, TableSource};
use numpy::{PyArray1, PyArrayDyn, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use serde_json::Value;

use crate::errors::{setup_error, value_error};

/// The keyword options every run takes.
pub const OPTION_NAMES: [&str; 7] = [
    "rtol",
    "atol",
    "method",
    "t_end",
    "grazing_tol",
    "mode",
    "tables",
];

/// A request from `params` (overrides by name), `wrt` and the keyword `options`
/// (`rtol`, `atol`, `method`, `t_end`, `grazing_tol`, `mode`, `tables`; `None` values keep
/// the defaults). `mode` (`forward`, `adjoint` or `auto`) says how derivatives are computed;
/// `tables` replaces data tables (see [`tables`]).
pub fn request(
    params: Option<BTreeMap<String, f64>>,
    wrt: Option<Vec<String>>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<Request> {
    let mut req = Request {
        set: params.unwrap_or_default().into_iter().collect(),
        wrt,
        ..Request::default()
    };
    let Some(options) = options else {
        return Ok(req);
    };
    for (key, value) in options.iter() {
        let key: String = key.extract()?;
        if value.is_none() {
            continue;
        }
        let number = || -> PyResult<Option<f64>> { Ok(Some(value.extract::<f64>()?)) };
        match key.as_str() {
            "rtol" => req.rtol = number()?,
            "atol" => req.atol = number()?,
            "t_end" => req.t_end = number()?,
            "grazing_tol" => req.grazing_tol = number()?,
            "tables" => req.tables = tables(&value)?,
            "mode" => req.mode = check_mode(&value.extract::<String>()?).map_err(setup_error)?,
            "method" => {
                let name: String = value.extract()?;
                req.method = Method::from_name(&name).ok_or_else(|| {
                    let known: Vec<&str> = Method::ALL.iter().map(|m| m.name()).collect();
                    value_error(format!(
                        "unknown method `{name}`; use one of {}",
                        known.join(", ")
                    ))
                })?;
            }
            other => {
                return Err(PyTypeError::new_err(format!(
                    "unexpected keyword argument `{other}`; the run options are {}",
                    OPTION_NAMES.join(", ")
                )))
            }
        }
    }
    Ok(req)
}

/// `tables={"NAME": source}` as replacement tables: a source is a file name (a `str` or an
/// `os.PathLike`, read as CSV) or a dict of columns (`{"t": array, "s": array}`, 1-D arrays or
/// sequences of numbers, of equal length and finite, as a CSV file's columns must be).
pub fn tables(value: &Bound<'_, PyAny>) -> PyResult<Vec<(String, TableSource)>> {
    let dict = value.cast::<PyDict>().map_err(|_| {
        PyTypeError::new_err("tables must be a dict: {\"NAME\": \"FILE.csv\" or {\"COL\": array}}")
    })?;
    let mut out = Vec::with_capacity(dict.len());
    for (name, source) in dict.iter() {
        let name: String = name.extract()?;
        if let Ok(columns) = source.cast::<PyDict>() {
            let mut cols = Vec::with_capacity(columns.len());
            for (col, values) in columns.iter() {
                let col: String = col.extract()?;
                let what = format!("tables[\"{name}\"][\"{col}\"]");
                cols.push((col, float_array(&values, &what, 1)?.data));
            }
            let table = Table::from_columns(&name, cols).map_err(|e| value_error(e.to_string()))?;
            out.push((name, TableSource::Data(table)));
        } else {
            let path: PathBuf = source.extract().map_err(|_| {
                value_error(format!(
                    "tables[\"{name}\"] must be a file name or a dict of columns"
                ))
            })?;
            out.push((name, TableSource::File(path)));
        }
    }
    Ok(out)
}

/// A JSON value as the Python object `json.loads` would make of it (`null` → `None`).
pub fn json_to_py<'py>(py: Python<'py>, value: &Value) -> PyResult<Bound<'py, PyAny>> {
    Ok(match value {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => b.into_pyobject(py)?.to_owned().into_any(),
        Value::Number(n) => match (n.as_u64(), n.as_i64(), n.as_f64()) {
            (Some(u), _, _) => u.into_pyobject(py)?.into_any(),
            (_, Some(i), _) => i.into_pyobject(py)?.into_any(),
            (_, _, f) => f.unwrap_or(f64::NAN).into_pyobject(py)?.into_any(),
        },
        Value::String(s) => s.into_pyobject(py)?.into_any(),
        Value::Array(items) => {
            let list = pyo3::types::PyList::empty(py);
            for item in items {
                list.append(json_to_py(py, item)?)?;
            }
            list.into_any()
        }
        Value::Object(map) => {
            let dict = PyDict::new(py);
            for (k, v) in map {
                dict.set_item(k, json_to_py(py, v)?)?;
            }
            dict.into_any()
        }
    })
}

/// A flat row-major vector as a numpy array of the given shape.
pub fn array<'py>(py: Python<'py>, data: Vec<f64>, shape: &[usize]) -> PyResult<Bound<'py, PyAny>> {
    let flat = PyArray1::from_vec(py, data);
    Ok(match shape {
        [_] => flat.into_any(),
        [a, b] => flat.reshape([*a, *b])?.into_any(),
        [a, b, c] => flat.reshape([*a, *b, *c])?.into_any(),
        _ => return Err(value_error(format!("unsupported array shape {shape:?}"))),
    })
}

/// Column `col` of a row-major table with `ncols` columns.
pub fn column(data: &[f64], ncols: usize, col: usize) -> Vec<f64> {
    data.iter()
        .skip(col)
        .step_by(ncols.max(1))
        .copied()
        .collect()
}

/// An array argument read as float64: its values in row-major order and its shape.
pub struct FloatArray {
    /// Row-major values.
    pub data: Vec<f64>,
    /// The shape, `ndim` long.
    pub shape: Vec<usize>,
}

/// The array-like argument `name` (a numpy array of any real dtype, a list, a tuple, nested
/// lists) as `numpy.asarray(value, dtype=numpy.float64)` would make it, copied out of Python;
/// a `ValueError` when it is not numbers or not `ndim`-dimensional.
pub fn float_array(value: &Bound<'_, PyAny>, name: &str, ndim: usize) -> PyResult<FloatArray> {
    let numpy = value.py().import("numpy")?;
    let converted = numpy
        .call_method1("asarray", (value, numpy.getattr("float64")?))
        .map_err(|e| value_error(format!("{name} must be an array of numbers: {e}")))?;
    let array = converted
        .cast_into::<PyArrayDyn<f64>>()
        .map_err(|_| value_error(format!("{name} must be an array of numbers")))?;
    let array = array.readonly();
    if array.ndim() != ndim {
        return Err(value_error(format!(
            "{name} must be a {ndim}-D array, got shape {:?}",
            array.shape()
        )));
    }
    Ok(FloatArray {
        data: array.as_array().iter().copied().collect(),
        shape: array.shape().to_vec(),
    })
}
