//! Why a quadratic program has no trustworthy solution: [`QpError`], with the data in its
//! variants. A QP that solves returns exact-to-rounding values; every other outcome is one
//! of these errors, never a wrong number.

use std::fmt;

/// A parametric QP that could not be solved or differentiated.
#[derive(Clone, Debug, PartialEq)]
pub enum QpError {
    /// The data do not have the sizes the solver was built for.
    Shape {
        /// Which part of the data (`H`, `c`, `A`, `b`).
        what: &'static str,
        /// Rows and columns expected.
        expected: (usize, usize),
        /// Rows and columns given.
        got: (usize, usize),
    },
    /// A NaN or an infinity in the data.
    NonFinite {
        /// Which part of the data (`H`, `c`, `A`, `b`).
        what: &'static str,
    },
    /// H is not symmetric: H[row, col] ≠ H[col, row] beyond rounding.
    NotSymmetric {
        /// Row of the offending entry.
        row: usize,
        /// Column of the offending entry.
        col: usize,
    },
    /// H is not (numerically) positive definite: the objective is not strictly convex, so
    /// the QP may be unbounded or have many solutions.
    NotConvex {
        /// The first Cholesky pivot that is not safely positive (a variable index).
        pivot: usize,
    },
    /// No point satisfies the constraints: the named constraint cannot be met together with
    /// the ones the solver had made active.
    Infeasible {
        /// The constraint that could not be satisfied.
        constraint: usize,
    },
    /// The active constraints are linearly dependent (LICQ fails): the multipliers are not
    /// unique and the solution map has no derivative the KKT system can give.
    Degenerate {
        /// The active constraints, the dependent one last.
        constraints: Vec<usize>,
    },
    /// Every coefficient of a constraint's row aᵢ is zero, so it involves no variable and
    /// reads 0 = bᵢ or 0 ≤ bᵢ: degenerate (its multiplier is undetermined) when that holds
    /// with equality, infeasible when it fails. (With bᵢ > 0 an inequality is simply left
    /// out.)
    Vanishing {
        /// The constraint.
        constraint: usize,
        /// Whether it is an equality.
        equality: bool,
        /// Its right-hand side bᵢ.
        rhs: f64,
    },
    /// A derivative was asked of a solver whose last solve failed or never ran.
    NotSolved,
    /// The active-set iteration did not finish within its budget (cycling on degenerate data).
    NoConvergence {
        /// Iterations used.
        iterations: usize,
    },
}

impl fmt::Display for QpError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            QpError::Shape { what, expected, got } => write!(
                f,
                "qp data `{what}` is {}×{}, expected {}×{}",
                got.0, got.1, expected.0, expected.1
            ),
            QpError::NonFinite { what } => write!(f, "qp data `{what}` is not finite"),
            QpError::NotSymmetric { row, col } => {
                write!(f, "qp Hessian is not symmetric at ({row}, {col})")
            }
            QpError::NotConvex { pivot } => write!(
                f,
                "qp objective is not strictly convex (Hessian not positive definite at variable {pivot})"
            ),
            QpError::Infeasible { constraint } => {
                write!(f, "qp is infeasible: constraint {constraint} cannot be satisfied")
            }
            QpError::Degenerate { constraints } => {
                write!(f, "qp is degenerate: active constraints ")?;
                for (k, i) in constraints.iter().enumerate() {
                    if k > 0 {
                        write!(f, ", ")?;
                    }
                    write!(f, "{i}")?;
                }
                write!(f, " are linearly dependent")
            }
            QpError::Vanishing {
                constraint,
                equality,
                rhs,
            } => {
                let op = if *equality { "=" } else { "<=" };
                write!(
                    f,
                    "qp constraint {constraint} no longer involves any variable: its \
                     coefficients all vanish here, leaving 0 {op} {}, ",
                    rhs + 0.0
                )?;
                if *rhs == 0.0 {
                    write!(f, "which holds with equality for every value (degenerate)")
                } else {
                    write!(f, "which no value satisfies (infeasible)")
                }
            }
            QpError::NotSolved => write!(f, "qp derivative asked before a successful solve"),
            QpError::NoConvergence { iterations } => write!(
                f,
                "qp active-set iteration did not converge in {iterations} iterations"
            ),
        }
    }
}

impl std::error::Error for QpError {}
