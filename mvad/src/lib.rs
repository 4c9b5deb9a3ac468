//! # mvad
//!
//! Exact parameter derivatives of hybrid and non-smooth systems, as measures: a density
//! on the smooth segments plus Dirac atoms at the events, reduced to dC/dθ for any cost.
//! This facade re-exports the `hybrid!` macro and the runtime, and loads `.hyb` files
//! into run-time models.

pub use mvad_macros::hybrid;
pub use mvad_runtime as runtime;
pub use mvad_runtime::*;

pub mod batch;
pub mod interp;
pub mod json;
pub mod load;
pub mod setup;
pub mod suite;
pub mod table;

#[doc(hidden)]
pub mod __private;
