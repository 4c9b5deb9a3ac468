//! Why a step could not be taken: the integrator's error type.

use std::fmt;

/// Why a step could not be taken.
#[derive(Clone, Debug, PartialEq)]
pub enum StepError {
    /// The step size fell below what the floating-point resolution of t allows.
    StepSizeUnderflow {
        /// Time at which the integrator is stuck.
        t: f64,
        /// The step size it would need.
        h: f64,
        /// The largest |entry| of the integrated state there (a solution that blows up
        /// shows here).
        largest: f64,
    },
    /// A NaN or infinity appeared and shrinking the step did not remove it.
    NonFinite {
        /// Time of the step start (for a flow that is undefined beyond some t*, the last
        /// step creeps up to t* before giving up, so this is t* to rounding).
        t: f64,
        /// The expression it came from: `flow of mode `m``, `sensitivity equation of the
        /// flow of mode `m``, `running cost`, `running-cost gradient`, or `state x` when
        /// every evaluated stage was finite but their combination overflowed.
        what: String,
    },
    /// `Options::max_steps` step attempts (accepted + rejected) were used up.
    MaxSteps {
        /// Time reached.
        t: f64,
        /// The limit that was hit.
        steps: usize,
        /// The step size the integrator had come down to.
        h: f64,
        /// Whether stiffness is ruled out as the cause: the implicit scheme was in use, or
        /// `auto` was (its stiffness test did not switch). Suggesting an implicit method
        /// would then mislead.
        not_stiff: bool,
        /// The largest |entry| of the integrated state there.
        largest: f64,
    },
}

impl fmt::Display for StepError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StepError::StepSizeUnderflow { t, h, largest } => write!(
                f,
                "step size underflow at t = {t:e} (h = {h:e}, largest |state| {largest:e})"
            ),
            StepError::NonFinite { t, what } => write!(f, "non-finite {what} at t = {t:e}"),
            StepError::MaxSteps {
                t,
                steps,
                h,
                not_stiff,
                largest,
            } => write!(
                f,
                "gave up after {steps} steps at t = {t:e} (max_steps; last step {h:e}, \
                 largest |state| {largest:e}{})",
                if *not_stiff {
                    ", not for stiffness"
                } else {
                    ""
                }
            ),
        }
    }
}

impl std::error::Error for StepError {}
