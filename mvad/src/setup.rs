//! From what a caller asks for to what a run needs, checked once for every front end.
//!
//! A [`Request`] names parameter overrides, the parameters to differentiate by, tolerances,
//! the method, the horizon and replacement data tables; [`resolve`] turns it into θ, [`Options`] and the `wrt` indices
//! ([`Setup`]), or a [`SetupError`]. The command line (`--rtol`) and the Python package
//! (`rtol=`) spell the options differently, so an error is rendered through a [`Spelling`].

use std::fmt;

use crate::table::TableSource;
use mvad_runtime::error::Time;
use mvad_runtime::solution::{GradientMode, Method, Options};
use mvad_runtime::{HybridModel, ModelAlloc};
use nalgebra::{Const, DefaultAllocator, OVector};

/// What a caller asks for; `None` keeps the model's or the runtime's default.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Request {
    /// Parameter overrides by name, applied in order.
    pub set: Vec<(String, f64)>,
    /// The parameters to differentiate by, in the order given (duplicates dropped); `None`:
    /// all, in declaration order.
    pub wrt: Option<Vec<String>>,
    /// Final time T overriding the model's horizon.
    pub t_end: Option<f64>,
    /// Relative tolerance, in (0, 1).
    pub rtol: Option<f64>,
    /// Absolute tolerance, positive.
    pub atol: Option<f64>,
    /// Integration method.
    pub method: Method,
    /// τ of the grazing test, in [0, 1).
    pub grazing_tol: Option<f64>,
    /// Data tables replacing the files the model's `table` declarations name, by table name.
    /// They are bound where the model is built ([`crate::load::load_with_tables`],
    /// [`crate::load::bind_tables`]; a compiled model takes its tables in `new`), not by
    /// [`resolve`].
    pub tables: Vec<(String, TableSource)>,
    /// How dC/dθ and vector–Jacobian products are computed (see [`check_mode`]).
    pub mode: GradientMode,
}

/// Everything a run needs: θ (declared values with the overrides applied), the solver
/// options and the indices of the parameters to report derivatives for.
pub struct Setup<M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// θ.
    pub params: OVector<f64, M::P>,
    /// Solver options (tolerances, method, horizon override, grazing τ).
    pub opts: Options,
    /// Indices of the parameters to differentiate by.
    pub wrt: Vec<usize>,
}

/// How a front end writes an option: `option("t_end")` is `--t-end` on the command line and
/// `t_end` in Python; `assign("t_end", "T")` is `--t-end T` and `t_end=T`.
pub trait Spelling {
    /// The option called `name` (the [`Request`] field name).
    fn option(&self, name: &str) -> String;
    /// The option given a value.
    fn assign(&self, name: &str, value: &str) -> String;
}

/// A request that cannot run; [`SetupError::message`] renders it in a front end's words.
#[derive(Clone, Debug, PartialEq)]
pub enum SetupError {
    /// A parameter name the model does not declare.
    UnknownParam {
        /// The name given.
        name: String,
        /// The option (field of [`Request`], or a front end's own) it was given in.
        option: &'static str,
        /// The model's parameter names.
        known: Vec<String>,
    },
    /// A parameter override that is NaN or infinite.
    NotFinite {
        /// The parameter.
        name: String,
        /// Its value.
        value: f64,
    },
    /// A tolerance or horizon outside its range.
    OutOfRange {
        /// The option.
        option: &'static str,
        /// What it must be (`must be in (0, 1)`).
        requirement: &'static str,
        /// The value given.
        got: f64,
    },
    /// `wrt` names no parameter.
    EmptyWrt {
        /// The model's parameter names.
        known: Vec<String>,
    },
    /// The model declares no horizon and none was given.
    NoHorizon {
        /// The model's name.
        model: String,
    },
    /// A gradient mode that is not known.
    Mode {
        /// The mode asked for.
        mode: String,
    },
    /// The model's horizon is not positive and finite at these parameters.
    BadHorizon {
        /// The model's name.
        model: String,
        /// Its value.
        t: f64,
    },
}

/// `known parameters: a, b` (or that there are none), for error messages.
pub fn known_params(names: &[String]) -> String {
    if names.is_empty() {
        "the model has no parameters".to_string()
    } else {
        format!("known parameters: {}", names.join(", "))
    }
}

impl SetupError {
    /// The message, options spelled as the front end writes them.
    pub fn message(&self, spell: &dyn Spelling) -> String {
        match self {
            SetupError::UnknownParam {
                name,
                option,
                known,
            } => format!(
                "unknown parameter `{name}` in {}; {}",
                spell.option(option),
                known_params(known)
            ),
            SetupError::NotFinite { name, value } => format!(
                "{}: parameter `{name}` = {} is not a finite number",
                spell.option("set"),
                Time(*value)
            ),
            SetupError::OutOfRange {
                option,
                requirement,
                got,
            } => format!("{} {requirement}, got {}", spell.option(option), Time(*got)),
            SetupError::EmptyWrt { known } => format!(
                "{} names no parameter; {}",
                spell.option("wrt"),
                known_params(known)
            ),
            SetupError::NoHorizon { model } => format!(
                "model `{model}` declares no horizon; give one with {}",
                spell.assign("t_end", "T")
            ),
            SetupError::Mode { mode } => format!(
                "unknown {} `{mode}`; use forward, adjoint or auto",
                spell.option("mode")
            ),
            SetupError::BadHorizon { model, t } => format!(
                "the horizon of model `{model}` evaluates to {} at these parameters; \
                 it must be positive and finite (or pass {})",
                Time(*t),
                spell.assign("t_end", "T")
            ),
        }
    }
}

/// Field names as they are: the spelling of library callers.
impl Spelling for () {
    fn option(&self, name: &str) -> String {
        name.to_string()
    }
    fn assign(&self, name: &str, value: &str) -> String {
        format!("{name} = {value}")
    }
}

impl fmt::Display for SetupError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message(&()))
    }
}

impl std::error::Error for SetupError {}

/// Index of parameter `name` in `names`; `option` says where it was given.
pub fn param_index(
    names: &[String],
    name: &str,
    option: &'static str,
) -> Result<usize, SetupError> {
    names
        .iter()
        .position(|p| p == name)
        .ok_or_else(|| SetupError::UnknownParam {
            name: name.to_string(),
            option,
            known: names.to_vec(),
        })
}

/// The indices of the parameters `wrt` names, duplicates dropped, in the order given; all
/// parameters in declaration order for `None`.
pub fn wrt_indices(names: &[String], wrt: Option<&[String]>) -> Result<Vec<usize>, SetupError> {
    let Some(list) = wrt else {
        return Ok((0..names.len()).collect());
    };
    let mut out = Vec::new();
    for name in list.iter().map(|s| s.trim()).filter(|s| !s.is_empty()) {
        let k = param_index(names, name, "wrt")?;
        if !out.contains(&k) {
            out.push(k);
        }
    }
    if out.is_empty() {
        return Err(SetupError::EmptyWrt {
            known: names.to_vec(),
        });
    }
    Ok(out)
}

/// The gradient mode a front end names: `forward` (sensitivities carried along the run),
/// `adjoint` (a primal run and one backward sweep) or `auto` (adjoint from
/// [`GradientMode::AUTO_ADJOINT_MIN_PARAMS`] params on).
pub fn check_mode(mode: &str) -> Result<GradientMode, SetupError> {
    GradientMode::from_name(mode).ok_or_else(|| SetupError::Mode {
        mode: mode.to_string(),
    })
}

/// θ: the declared values with `set` applied.
pub fn params_with<M: HybridModel>(
    model: &M,
    set: &[(String, f64)],
) -> Result<OVector<f64, M::P>, SetupError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let info = model.info();
    let mut values = info.param_defaults.clone();
    for (name, value) in set {
        let k = param_index(&info.params, name.trim(), "set")?;
        if !value.is_finite() {
            return Err(SetupError::NotFinite {
                name: info.params[k].clone(),
                value: *value,
            });
        }
        values[k] = *value;
    }
    Ok(OVector::<f64, M::P>::from_iterator_generic(
        model.nparams(),
        Const::<1>,
        values,
    ))
}

/// Checks `value` against `ok`, or says what it must be.
fn checked(
    value: Option<f64>,
    option: &'static str,
    requirement: &'static str,
    ok: impl Fn(f64) -> bool,
) -> Result<Option<f64>, SetupError> {
    match value {
        Some(v) if !(v.is_finite() && ok(v)) => Err(SetupError::OutOfRange {
            option,
            requirement,
            got: v,
        }),
        v => Ok(v),
    }
}

/// Resolves a request against a model: θ, options and `wrt`, every value checked, and the
/// horizon (given, or the model's at θ) positive and finite.
pub fn resolve<M: HybridModel>(model: &M, req: &Request) -> Result<Setup<M>, SetupError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let info = model.info();
    let params = params_with(model, &req.set)?;
    let wrt = wrt_indices(&info.params, req.wrt.as_deref())?;
    let mut opts = Options {
        method: req.method,
        gradient_mode: req.mode,
        ..Options::default()
    };
    if let Some(r) = checked(req.rtol, "rtol", "must be in (0, 1)", |r| {
        r > 0.0 && r < 1.0
    })? {
        opts.rtol = r;
    }
    if let Some(a) = checked(req.atol, "atol", "must be positive and finite", |a| a > 0.0)? {
        opts.atol = a;
    }
    if let Some(tau) = checked(req.grazing_tol, "grazing_tol", "must be in [0, 1)", |t| {
        (0.0..1.0).contains(&t)
    })? {
        opts.grazing_tol = tau;
    }
    opts.t_end = checked(req.t_end, "t_end", "must be positive and finite", |t| {
        t > 0.0
    })?;
    if opts.t_end.is_none() {
        match model.horizon(&params) {
            // A model without states has no time (its cost is static).
            None if info.states.is_empty() => {}
            None => {
                return Err(SetupError::NoHorizon {
                    model: info.name.clone(),
                })
            }
            Some(t) if !(t.is_finite() && t > 0.0) => {
                return Err(SetupError::BadHorizon {
                    model: info.name.clone(),
                    t,
                })
            }
            Some(_) => {}
        }
    }
    Ok(Setup { params, opts, wrt })
}

#[cfg(test)]
mod tests {
    use super::*;
    use mvad_runtime::fixtures::Ball;

    struct Cli;
    impl Spelling for Cli {
        fn option(&self, name: &str) -> String {
            format!("--{}", name.replace('_', "-"))
        }
        fn assign(&self, name: &str, value: &str) -> String {
            format!("{} {value}", self.option(name))
        }
    }

    fn req() -> Request {
        Request::default()
    }

    #[test]
    fn overrides_wrt_and_tolerances() {
        let ball = Ball::new();
        let s = resolve(
            &ball,
            &Request {
                set: vec![("e".into(), 0.5), ("h0".into(), 3.0)],
                wrt: Some(vec!["v0".into(), "e".into(), "v0".into()]),
                rtol: Some(1e-6),
                t_end: Some(3.5),
                method: Method::Verner9,
                ..req()
            },
        )
        .map_err(|e| e.to_string())
        .expect("resolves");
        assert_eq!(s.params.as_slice(), &[0.5, 9.81, 3.0, 0.0]);
        assert_eq!(s.wrt, vec![3, 0]);
        assert_eq!(s.opts.rtol, 1e-6);
        assert_eq!(s.opts.t_end, Some(3.5));
        assert_eq!(s.opts.method, Method::Verner9);
    }

    #[test]
    fn every_bad_request_is_an_error_in_the_front_ends_words() {
        let ball = Ball::new();
        let cases: Vec<(Request, &str)> = vec![
            (
                Request {
                    set: vec![("q".into(), 1.0)],
                    ..req()
                },
                "unknown parameter `q` in --set; known parameters: e, g, h0, v0",
            ),
            (
                Request {
                    set: vec![("e".into(), f64::NAN)],
                    ..req()
                },
                "--set: parameter `e` = NaN is not a finite number",
            ),
            (
                Request {
                    wrt: Some(vec![" ".into()]),
                    ..req()
                },
                "--wrt names no parameter; known parameters: e, g, h0, v0",
            ),
            (
                Request {
                    rtol: Some(0.0),
                    ..req()
                },
                "--rtol must be in (0, 1), got 0",
            ),
            (
                Request {
                    atol: Some(f64::INFINITY),
                    ..req()
                },
                "--atol must be positive and finite, got inf",
            ),
            (
                Request {
                    grazing_tol: Some(2.0),
                    ..req()
                },
                "--grazing-tol must be in [0, 1), got 2",
            ),
            (
                Request {
                    t_end: Some(-2.0),
                    ..req()
                },
                "--t-end must be positive and finite, got -2",
            ),
        ];
        for (r, want) in cases {
            let e = resolve(&ball, &r).err().expect("an error");
            assert_eq!(e.message(&Cli), want);
        }
        let e = resolve(
            &ball,
            &Request {
                rtol: Some(2.0),
                ..req()
            },
        )
        .err()
        .expect("an error");
        assert_eq!(e.to_string(), "rtol must be in (0, 1), got 2");
    }
}
