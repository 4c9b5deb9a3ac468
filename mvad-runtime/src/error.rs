//! Why a run failed: [`SolveError`], with the data in its variants.
//!
//! A run that *finishes* may still carry warnings (grazing, Zeno, simultaneous events) in
//! `Solution::diagnostics`; a `SolveError` means there is no trustworthy cost or gradient.
//! [`SolveError::diagnostic`] turns the numerical failures into the spec's diagnostic kinds
//! (`max_events`, `max_steps`, `step_size_underflow`, `nonfinite`) for callers that print both alike.
//!
//! The messages name no command-line flags: the runtime knows no front end. The `mvad`
//! binary adds its hints (`--t-end`, `--method`) when it reports an error (`cli::solve_err`).

use crate::qp::QpError;
use crate::solution::{Diagnostic, DiagnosticKind};
use std::fmt;

/// Events that pass [`SolveError::MaxEvents`]'s limit within this fraction of max(|t|, 1) for
/// their second half chatter (a sliding mode): 10⁻⁶, a million times the resolution of t.
pub const CHATTER_SPAN: f64 = 1e-6;

/// A number as a message prints it (a time mostly; also a horizon, a step or a parameter value):
/// the shortest decimal that reads back as t, in exponent form when that decimal would be long
/// (|t| < 10⁻⁴ or ≥ 10¹⁶; `{}` of 2.3e-310 is 310 digits).
pub struct Time(pub f64);

impl fmt::Display for Time {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let t = self.0;
        if t != 0.0 && t.is_finite() && !(1e-4..1e16).contains(&t.abs()) {
            write!(f, "{t:e}")
        } else {
            write!(f, "{t}")
        }
    }
}

/// A run that could not produce a cost and a gradient.
#[derive(Clone, Debug, PartialEq)]
pub enum SolveError {
    /// The model declares no horizon and `Options::t_end` is not set.
    NoHorizon,
    /// The horizon is not a finite positive number.
    BadHorizon {
        /// The offending value of T.
        t_end: f64,
    },
    /// The parameter vector has the wrong length.
    ParamCount {
        /// Number of parameters the model declares.
        expected: usize,
        /// Number given.
        got: usize,
    },
    /// A parameter value is NaN or infinite.
    BadParam {
        /// Index of the parameter.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// An option is out of range (non-positive tolerance, ...).
    BadOption {
        /// Which option and why.
        what: String,
    },
    /// A NaN or infinity appeared; the run stopped.
    NonFinite {
        /// Time at which it appeared.
        t: f64,
        /// The expression it came from (`flow`, `guard of event `impact``, `reset of ...`, `cost`).
        what: String,
    },
    /// The step size fell below the resolution of t.
    StepSizeUnderflow {
        /// Time at which the integrator got stuck.
        t: f64,
        /// The step size it would need.
        h: f64,
        /// The largest |entry| of the integrated state there (a solution blowing up at a
        /// finite time t* shows as 1/(t* − t)).
        largest: f64,
    },
    /// `Options::max_steps` step attempts were used up: an explicit method on a stiff model,
    /// or steps shrinking towards a blow-up or a discontinuity.
    MaxSteps {
        /// Time reached.
        t: f64,
        /// The limit that was hit.
        steps: usize,
        /// The step size the integrator had come down to.
        h: f64,
        /// Whether stiffness is ruled out as the cause (the implicit method was in use, or
        /// `auto`, whose stiffness test did not switch to it).
        not_stiff: bool,
        /// The largest |entry| of the integrated state there.
        largest: f64,
    },
    /// More than `Options::max_events` events fired.
    MaxEvents {
        /// Time of the last event.
        t: f64,
        /// The limit that was hit.
        count: usize,
        /// How long the second half of those events took (from the time the count passed
        /// half the limit to `t`): a span within [`CHATTER_SPAN`] of t says they chatter.
        span: f64,
    },
    /// The model's structure is unusable (more switching functions than bits, an event
    /// target that is not a mode, ...).
    BadModel {
        /// What is wrong.
        what: String,
    },
    /// The times of a time event are unusable at these parameters: a period that is not
    /// positive, or `at each` times that decrease from one row to the next.
    BadSchedule {
        /// The event's name.
        event: String,
        /// What is wrong.
        what: String,
    },
    /// A measure was asked of a solution that was run without `Options::record`.
    NotRecorded,
    /// An observable index is out of range.
    NoSuchObservable {
        /// The index asked for.
        index: usize,
        /// How many observables the model has.
        count: usize,
    },
    /// A qp of the model could not be solved (infeasible, not strictly convex, degenerate...).
    Qp {
        /// Time of the evaluation (0 for a static qp).
        t: f64,
        /// The qp's name.
        qp: String,
        /// Why.
        error: QpError,
    },
    /// A parameter index is out of range (finite differences).
    NoSuchParam {
        /// The index asked for.
        index: usize,
        /// How many parameters the model has.
        count: usize,
    },
}

impl SolveError {
    /// Whether the caller asked for something that cannot run (no or a bad horizon, wrong
    /// parameters, a bad option or index), as opposed to a run that started and failed.
    pub fn is_bad_input(&self) -> bool {
        matches!(
            self,
            SolveError::NoHorizon
                | SolveError::BadHorizon { .. }
                | SolveError::ParamCount { .. }
                | SolveError::BadParam { .. }
                | SolveError::BadOption { .. }
                | SolveError::BadSchedule { .. }
                | SolveError::NoSuchObservable { .. }
                | SolveError::NoSuchParam { .. }
        )
    }

    /// The spec's diagnostic for the numerical failures (`nonfinite`, `step_size_underflow`,
    /// `max_events`, `max_steps`); `None` for bad input.
    pub fn diagnostic(&self) -> Option<Diagnostic> {
        let (kind, t) = match self {
            SolveError::NonFinite { t, .. } => (DiagnosticKind::Nonfinite, *t),
            SolveError::StepSizeUnderflow { t, .. } => (DiagnosticKind::StepSizeUnderflow, *t),
            SolveError::MaxEvents { t, .. } => (DiagnosticKind::MaxEvents, *t),
            SolveError::MaxSteps { t, .. } => (DiagnosticKind::MaxSteps, *t),
            _ => return None,
        };
        Some(Diagnostic {
            kind,
            t,
            message: self.to_string(),
        })
    }
}

impl fmt::Display for SolveError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SolveError::NoHorizon => {
                write!(f, "the model declares no horizon and no end time was given")
            }
            SolveError::BadHorizon { t_end } => {
                write!(
                    f,
                    "the horizon must be finite and positive, got {}",
                    Time(*t_end)
                )
            }
            SolveError::ParamCount { expected, got } => {
                write!(f, "expected {expected} parameter values, got {got}")
            }
            SolveError::BadParam { index, value } => {
                write!(f, "parameter {index} is not finite ({})", Time(*value))
            }
            SolveError::BadOption { what } => write!(f, "bad option: {what}"),
            SolveError::NonFinite { t, what } => {
                write!(f, "non-finite value in {what} at t = {}", Time(*t))
            }
            SolveError::StepSizeUnderflow { t, h, largest } => {
                write!(f, "step size underflow at t = {} (step {h:e}", Time(*t))?;
                write_largest(f, *largest)
            }
            SolveError::MaxSteps {
                t,
                steps,
                h,
                not_stiff,
                largest,
            } => {
                write!(
                    f,
                    "gave up after {steps} steps at t = {} (max_steps, last step {h:e}",
                    Time(*t)
                )?;
                write_largest(f, *largest)?;
                if *not_stiff {
                    write!(
                        f,
                        ": the steps shrank, and not for stiffness (the implicit method was in \
                         use, or `auto` found none); the solution may blow up, or the flow may \
                         be discontinuous or undefined just ahead"
                    )
                } else {
                    write!(
                        f,
                        ": the model is probably stiff: try the method auto or rosenbrock"
                    )
                }
            }
            SolveError::MaxEvents { t, count, span } => {
                write!(
                    f,
                    "stopped after {count} events at t = {} (max_events)",
                    Time(*t)
                )?;
                if *span <= CHATTER_SPAN * t.abs().max(1.0) {
                    write!(
                        f,
                        ": the last {} took {span:.1e} time units; the events chatter: the flow \
                         on both sides of a guard or a kink points into it (a sliding mode, which \
                         the event loop does not follow; a guard with hysteresis, or a flow \
                         that stays on the surface, avoids it)",
                        count - count / 2
                    )?;
                }
                Ok(())
            }
            SolveError::BadModel { what } => write!(f, "unusable model: {what}"),
            SolveError::BadSchedule { event, what } => {
                write!(f, "the times of event `{event}` are unusable: {what}")
            }
            SolveError::NotRecorded => {
                write!(
                    f,
                    "the solution has no trajectory (run with Options::record)"
                )
            }
            SolveError::NoSuchObservable { index, count } => {
                write!(f, "observable {index} out of range (the model has {count})")
            }
            SolveError::NoSuchParam { index, count } => {
                write!(f, "parameter {index} out of range (the model has {count})")
            }
            SolveError::Qp { t, qp, error } => write!(f, "qp `{qp}` at t = {}: {error}", Time(*t)),
        }
    }
}

/// Closes a failure's parenthesis with the largest |entry| of the state it stopped at.
fn write_largest(f: &mut fmt::Formatter<'_>, largest: f64) -> fmt::Result {
    write!(f, "; largest |state| {largest:e})")
}

impl std::error::Error for SolveError {}

#[cfg(test)]
mod tests {
    use super::*;

    /// Times print as the shortest decimal that reads back, in exponent form where that
    /// would be long: an adjoint failure near t = 0 once printed 330 digits.
    #[test]
    fn times_in_messages_are_short() {
        let shown = |t: f64| Time(t).to_string();
        assert_eq!(shown(0.0), "0");
        assert_eq!(shown(2.5), "2.5");
        assert_eq!(shown(1e6), "1000000");
        assert_eq!(shown(3.187270310537978e-300), "3.187270310537978e-300");
        assert_eq!(shown(-2e-7), "-2e-7");
        assert_eq!(shown(1e20), "1e20");
        for t in [3.187270310537978e-300, 0.1 + 0.2, 5.7469577113268375, 1e300] {
            assert_eq!(shown(t).parse::<f64>().expect("reads back"), t);
        }
        let e = SolveError::NonFinite {
            t: 2.3e-310,
            what: "x".into(),
        };
        assert_eq!(e.to_string(), "non-finite value in x at t = 2.3e-310");
    }
}
