//! The checks before a run: θ has the model's length and is finite, the options are in
//! range, and the model's description is consistent (its initial mode and every event's
//! modes exist, its state names match its dimension). A failed check is bad input
//! ([`SolveError::ParamCount`], [`SolveError::BadParam`], [`SolveError::BadOption`]) or a
//! model that contradicts itself ([`SolveError::BadModel`]); nothing has run yet.

use crate::error::SolveError;
use crate::model::{HybridModel, ModelAlloc};
use crate::solution::Options;
use nalgebra::{DefaultAllocator, Dim, OVector};

/// Checks `params`, `opts` and `model` as the module doc says.
pub(super) fn validate<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    opts: &Options,
) -> Result<(), SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let info = model.info();
    let np = model.nparams().value();
    if params.len() != np || info.params.len() != np {
        return Err(SolveError::ParamCount {
            expected: np,
            got: params.len(),
        });
    }
    if let Some((index, &value)) = params.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(SolveError::BadParam { index, value });
    }
    let bad = |what: &str| Err(SolveError::BadOption { what: what.into() });
    if !(opts.rtol.is_finite() && opts.rtol > 0.0) {
        return bad("rtol must be finite and positive");
    }
    if !(opts.atol.is_finite() && opts.atol >= 0.0) {
        return bad("atol must be finite and non-negative");
    }
    if !(opts.grazing_tol.is_finite() && opts.grazing_tol >= 0.0) {
        return bad("grazing tolerance must be finite and non-negative");
    }
    if !(opts.simultaneous_tol.is_finite() && opts.simultaneous_tol >= 0.0) {
        return bad("simultaneous-event tolerance must be finite and non-negative");
    }
    if opts.max_steps == 0 {
        return bad("max_steps must be positive");
    }
    let nmodes = info.modes.len();
    let bad_model = |what: String| Err(SolveError::BadModel { what });
    if nmodes == 0 || info.initial_mode >= nmodes {
        return bad_model(format!(
            "initial mode {} of {} modes",
            info.initial_mode, nmodes
        ));
    }
    if info.states.len() != model.nstates().value() {
        return bad_model("state names and state dimension disagree".into());
    }
    for ev in &info.events {
        if ev.target.is_some_and(|m| m >= nmodes) || ev.mode.is_some_and(|m| m >= nmodes) {
            return bad_model(format!(
                "event `{}` names a mode that does not exist",
                ev.name
            ));
        }
    }
    Ok(())
}
