//! Parametric quadratic programs with exact derivatives and kinks.
//!
//! A QP layer maps data (H, c, A, b), which depend on parameters θ (and, inside a flow, on
//! the state x and time t), to the solution of
//!
//! $$ \min_u \tfrac12 u^\top H u + c^\top u \quad\text{s.t.}\quad a_i^\top u = b_i \ (i \in E),
//! \quad a_i^\top u \le b_i \ (i \in I), $$
//!
//! H symmetric positive definite, constraints numbered from 0 in declaration order.
//! [`QpSolver::solve`] finds u* and the multipliers μ (Hu + c + Aᵀμ = 0, μᵢ ≥ 0 on I) with a
//! dual active-set method that identifies the active set exactly (`active_set.rs`), then
//! classifies each constraint ([`ConstraintStatus`]): *active* (slack zero, multiplier
//! nonzero, or an equality), *weakly active* (slack and multiplier both zero within
//! [`QpOptions::active_tol`], relative to the data's scale) or *inactive*.
//!
//! **Derivatives.** Along a direction (dH, dc, dA, db) of the data (∂/∂θⱼ of the data, or
//! ∂/∂xₖ), differentiating the KKT conditions on the active set B gives
//!
//! $$ H\,du + \sum_{i\in B} a_i\, d\mu_i = -(dH\,u + dc + dA^\top\mu), \qquad
//!    a_i^\top du = db_i - da_i^\top u \ (i \in B), \qquad d\mu_i = 0 \ (i \notin B). $$
//!
//! Without weakly active constraints B is the active set and du is linear in the direction
//! (one factorisation serves every direction). A weakly active constraint is a **kink** of
//! the solution map: which side B falls on depends on the direction. The one-sided
//! derivative u'(θ; d) = lim_{h↓0} (u(θ + hd) − u(θ))/h is the solution of the same
//! system with each weakly active i either in B with dμᵢ ≥ 0 or out of B with
//! aᵢᵀdu ≤ dbᵢ − daᵢᵀu — the KKT conditions of a QP in du (strongly active rows as
//! equalities, weakly active rows as inequalities), which the same active-set method
//! solves: for each direction the neighbouring active set that stays primal and dual
//! feasible. The derivative from the left is −u'(θ; −d) ([`Side`]).
//!
//! **Errors, never wrong numbers.** Non-finite or misshapen data, an H that is not
//! symmetric positive definite, infeasible constraints, and linearly dependent active
//! constraints (the multipliers are then not unique) are [`QpError`]s.
//!
//! The solver is a workspace: [`QpSolver::new`] allocates every buffer for a shape (n
//! variables, the kinds of m constraints) once; `solve` and `directional` allocate nothing
//! (only an error's constraint list does).

mod active_set;
mod bank;
mod derivative;
mod error;
mod factor;
mod flow;
mod layer;
mod solver;

pub use bank::{QpBank, QpFlowKink, QpState};
pub use error::QpError;
pub use flow::FlowPieces;
/// Static description of one qp layer (crate `mvad-info`, shared with the front end).
pub use mvad_info::QpLayerInfo;
pub use solver::QpSolver;

use nalgebra::{DMatrix, DVector};

/// The kind of a constraint aᵢᵀu (op) bᵢ (crate `mvad-info`, shared with the front end).
pub use mvad_info::ConstraintKind;

/// A constraint's role at the solution.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ConstraintStatus {
    /// Slack bounded away from zero: multiplier zero.
    Inactive,
    /// An equality, or an inequality with zero slack and a multiplier bounded away from zero.
    Active,
    /// Slack and multiplier both zero (within the tolerance): a kink of the solution map.
    WeaklyActive,
}

/// Which one-sided derivative: along +d (right) or the limit from −d (left).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// lim_{h↓0} (u(θ) − u(θ − hd))/h = −u'(θ; −d).
    Left,
    /// lim_{h↓0} (u(θ + hd) − u(θ))/h = u'(θ; d).
    Right,
}

/// The data of a QP, or a direction (dH, dc, dA, db) of the data: H (n×n), c (n), A (m×n,
/// one row per constraint), b (m).
#[derive(Clone, Debug, PartialEq)]
pub struct QpData {
    /// The Hessian H (symmetric positive definite for a problem; symmetric for a direction).
    pub h: DMatrix<f64>,
    /// The linear term c.
    pub c: DVector<f64>,
    /// Constraint rows aᵢᵀ.
    pub a: DMatrix<f64>,
    /// Constraint right-hand sides bᵢ.
    pub b: DVector<f64>,
}

impl QpData {
    /// All zeros, for n variables and m constraints.
    pub fn zeros(n: usize, m: usize) -> Self {
        QpData {
            h: DMatrix::zeros(n, n),
            c: DVector::zeros(n),
            a: DMatrix::zeros(m, n),
            b: DVector::zeros(m),
        }
    }
}

/// Tolerances of the solver.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QpOptions {
    /// A slack or a multiplier counts as zero when it is at most this times its scale
    /// (slack: |bᵢ| plus ‖aᵢ‖ times the solution's size, in the metric of H; multiplier:
    /// its force ‖μᵢaᵢ‖ against the size of Hu and c). Decides weakly active constraints.
    pub active_tol: f64,
    /// A constraint whose normal makes an angle with sine below this with the span of the
    /// other active normals (in the metric of H⁻¹) counts as linearly dependent on them.
    pub dependence_tol: f64,
    /// Iteration budget of the active-set method (0: 20(n + m) + 20).
    pub max_iter: usize,
}

impl Default for QpOptions {
    fn default() -> Self {
        QpOptions {
            active_tol: 1e-9,
            dependence_tol: 1e-7,
            max_iter: 0,
        }
    }
}

/// The parts of the KKT residual at a solution, each the largest absolute value over its
/// rows: stationarity ‖Hu + c + Aᵀμ‖∞, primal feasibility, dual feasibility (μᵢ ≥ 0 on
/// inequalities) and complementarity |μᵢ(aᵢᵀu − bᵢ)|.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KktResidual {
    /// ‖Hu + c + Aᵀμ‖∞.
    pub stationarity: f64,
    /// max over equalities of |aᵢᵀu − bᵢ| and over inequalities of max(0, aᵢᵀu − bᵢ).
    pub primal: f64,
    /// max over inequalities of max(0, −μᵢ).
    pub dual: f64,
    /// max over inequalities of |μᵢ(aᵢᵀu − bᵢ)|.
    pub complementarity: f64,
}

impl KktResidual {
    /// The largest of the four parts.
    pub fn max(&self) -> f64 {
        self.stationarity
            .max(self.primal)
            .max(self.dual)
            .max(self.complementarity)
    }
}
