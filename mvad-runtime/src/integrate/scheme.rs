//! The schemes that take the steps, and what differs between them (stages, FSAL slot,
//! error order), looked up in one place.

use super::rosenbrock;
use super::tsit5::{self, TSIT5};
use super::verner::{self, VERNER9};
use crate::solution::Method;

/// The scheme taking the steps (what [`Method::Auto`] is using at the moment). Everything that
/// differs between schemes is looked up here or dispatched in `attempt`/`dense`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scheme {
    /// Tsitouras 5(4).
    Tsit5,
    /// Verner 9(8).
    Verner9,
    /// Rodas5P (linearly implicit).
    Rodas5P,
    /// Y + h·F for a constant F: exact, one step to the stop time (see the module doc).
    Exact,
}

impl Scheme {
    /// The scheme a run of `method` starts with.
    pub fn initial(method: Method) -> Scheme {
        match method {
            Method::Auto | Method::Tsit5 => Scheme::Tsit5,
            Method::Verner9 => Scheme::Verner9,
            Method::Rosenbrock => Scheme::Rodas5P,
        }
    }

    /// The method that names this scheme.
    pub fn method(self) -> Method {
        match self {
            Scheme::Tsit5 => Method::Tsit5,
            Scheme::Verner9 => Method::Verner9,
            Scheme::Rodas5P => Method::Rosenbrock,
            // Exact steps stand in for whatever method was asked for.
            Scheme::Exact => Method::Auto,
        }
    }

    /// (order of the error estimate + 1, stage slots, stages evaluated by an attempt, slot
    /// left holding F(t + h, Y₁) after an accepted step).
    pub(super) const fn info(self) -> (f64, usize, usize, Option<usize>) {
        match self {
            Scheme::Tsit5 => (
                TSIT5.error_order,
                tsit5::STAGES,
                tsit5::STAGES,
                Some(TSIT5.fsal_slot()),
            ),
            Scheme::Verner9 => (
                VERNER9.error_order,
                verner::STAGES_WITH_DENSE,
                verner::STAGES,
                Some(VERNER9.fsal_slot()),
            ),
            Scheme::Rodas5P => (5.0, rosenbrock::STAGES, rosenbrock::STAGES, None),
            // F is constant: the next step's first stage is this one's.
            Scheme::Exact => (1.0, 1, 1, Some(0)),
        }
    }

    /// Order of the error estimate + 1 (the exponent base of the controller).
    pub fn error_order(self) -> f64 {
        self.info().0
    }

    /// Stage slots a run of `method` needs (for every scheme it may use).
    pub fn slots(method: Method) -> usize {
        match method {
            Method::Auto => Scheme::Tsit5.info().1.max(Scheme::Rodas5P.info().1),
            m => Scheme::initial(m).info().1,
        }
    }
}
