//! # mvad-runtime
//!
//! Simulates hybrid models, locates their events, carries forward sensitivities
//! S = ∂x/∂θ through every jump and returns the parameter derivative of a trajectory
//! as a measure — a density on the smooth segments plus Dirac atoms at the events —
//! and reduced to dC/dθ for the model's cost; or computes dC/dθ and vector–Jacobian
//! products by one backward (adjoint) sweep ([`adjoint`], [`vjp`](mod@vjp)). Knows nothing of
//! parsing: models come in through the [`HybridModel`] trait.

#[cfg(any(test, feature = "test-fixtures"))]
#[doc(hidden)]
pub mod fixtures;
pub mod model;

pub use model::{
    At, AtOf, Direction, EventInfo, HybridModel, ModelAdjoint, ModelAlloc, ModelDims, ModelInfo,
    ModelSecondOrder, ModelSens, Occurrence, Point, PointOf, Switches, Trigger,
};

pub mod adjoint;
pub mod error;
pub mod event;
pub mod fd;
pub mod integrate;
pub mod measure;
pub mod qp;
pub mod reduce;
pub mod sample;
pub mod sens;
pub mod sink;
pub mod solution;
pub mod solve;
pub mod vjp;

pub use error::SolveError;
pub use fd::{fd_full_gradient, fd_gradient, fd_sweep, FdPoint};
pub use measure::{measure, Measure};
pub use qp::{QpError, QpSolver};
pub use sample::{sample, Samples};
pub use sink::{EventCounts, EventSink, EventView, FirstEvents, Stream};
pub use solution::{
    Diagnostic, DiagnosticKind, ErrorEstimate, EventRecord, GradientMode, Method, Options, Segment,
    Solution, Stats, Trajectory,
};
pub use solve::{solve, solve_with};
pub use vjp::{vjp, Cotangents, Vjp};
