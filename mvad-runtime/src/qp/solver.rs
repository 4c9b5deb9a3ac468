//! [`QpSolver`]: the workspace of one QP shape, its solve and the classification of the
//! constraints at the solution.

use super::active_set::{Dual, Role, Tols};
use super::factor::SpdFactor;
use super::{ConstraintKind, ConstraintStatus, KktResidual, QpData, QpError, QpOptions};
use nalgebra::DVector;

/// H is accepted as positive definite when every Cholesky pivot keeps L_jj² > this · H_jj
/// (the j-th column of H's square root is not within an angle of sine 1e-7 of the span of
/// the earlier ones).
const CONVEX_TOL2: f64 = 1e-14;

/// A constraint is violated during the iteration when its slack exceeds this times its
/// scale: a few hundred roundings of the data.
const FEAS_TOL: f64 = 1e-13;

/// Relative asymmetry |Hᵢⱼ − Hⱼᵢ| / max|H| tolerated in H.
const SYMMETRY_TOL: f64 = 1e-12;

/// A solver for QPs of one shape: n variables and m constraints of given kinds. Every
/// buffer is allocated by [`QpSolver::new`]; [`QpSolver::solve`] and the derivatives reuse
/// them.
#[derive(Clone, Debug)]
pub struct QpSolver {
    pub(super) kinds: Vec<ConstraintKind>,
    pub(super) opts: QpOptions,
    /// Cholesky factor L of H.
    pub(super) hfac: SpdFactor,
    /// The active-set iteration in v = Lᵀu.
    pub(super) dual: Dual,
    /// The solution u*.
    pub(super) u: DVector<f64>,
    /// Multipliers μ, one per constraint (zero when inactive).
    pub(super) mult: Vec<f64>,
    /// Slacks aᵢᵀu − bᵢ.
    pub(super) slacks: Vec<f64>,
    /// The scale each slack is measured against (`Dual::slack_scale`), and that of the
    /// multipliers' forces (`Dual::force_scale`), at the solution.
    pub(super) slack_scales: Vec<f64>,
    pub(super) force: f64,
    pub(super) status: Vec<ConstraintStatus>,
    /// Scratch: the constraints with zero slack.
    near: Vec<usize>,
    /// Whether some constraint is weakly active.
    pub(super) kink: bool,
    /// Whether `solve` succeeded last time (and the dual still holds its working set).
    pub(super) solved: bool,
    /// Whether the dual's working set and Gram factor are still the solve's (a derivative
    /// on a piece, [`QpSolver::directional_on_piece`], replaces them).
    pub(super) working: bool,
    iterations: usize,
    /// Scratch for a direction's linear term.
    pub(super) q: DVector<f64>,
}

impl QpSolver {
    /// A solver for n variables and constraints of the given kinds, in declaration order.
    pub fn new(n: usize, kinds: &[ConstraintKind], opts: QpOptions) -> Self {
        let m = kinds.len();
        QpSolver {
            kinds: kinds.to_vec(),
            opts,
            hfac: SpdFactor::with_capacity(n),
            dual: Dual::new(n, m),
            u: DVector::zeros(n),
            mult: vec![0.0; m],
            slacks: vec![0.0; m],
            slack_scales: vec![0.0; m],
            force: 0.0,
            status: vec![ConstraintStatus::Inactive; m],
            near: Vec::with_capacity(m),
            kink: false,
            solved: false,
            working: false,
            iterations: 0,
            q: DVector::zeros(n),
        }
    }

    /// Number of variables.
    pub fn nvars(&self) -> usize {
        self.u.len()
    }

    /// Number of constraints.
    pub fn nconstraints(&self) -> usize {
        self.kinds.len()
    }

    /// The constraints' kinds.
    pub fn kinds(&self) -> &[ConstraintKind] {
        &self.kinds
    }

    /// The solution u* of the last successful solve.
    pub fn u(&self) -> &DVector<f64> {
        &self.u
    }

    /// The multipliers μ (Hu + c + Aᵀμ = 0), one per constraint, zero when inactive.
    pub fn multipliers(&self) -> &[f64] {
        &self.mult
    }

    /// Each constraint's status at the solution.
    pub fn status(&self) -> &[ConstraintStatus] {
        &self.status
    }

    /// Whether the solution is at a kink (some constraint is weakly active).
    pub fn is_kink(&self) -> bool {
        self.kink
    }

    /// The weakly active constraints, in declaration order.
    pub fn weakly_active(&self) -> impl Iterator<Item = usize> + '_ {
        self.status
            .iter()
            .enumerate()
            .filter(|(_, s)| **s == ConstraintStatus::WeaklyActive)
            .map(|(i, _)| i)
    }

    /// Iterations the active-set method used in the last solve.
    pub fn iterations(&self) -> usize {
        self.iterations
    }

    pub(super) fn tols(&self) -> Tols {
        let (n, m) = (self.nvars(), self.nconstraints());
        Tols {
            feas: FEAS_TOL,
            dep2: self.opts.dependence_tol * self.opts.dependence_tol,
            max_iter: if self.opts.max_iter == 0 {
                20 * (n + m) + 20
            } else {
                self.opts.max_iter
            },
        }
    }

    /// Checks the sizes and finiteness of data (or of a direction).
    pub(super) fn check_data(&self, d: &QpData) -> Result<(), QpError> {
        let (n, m) = (self.nvars(), self.nconstraints());
        let parts = [
            ("H", (n, n), d.h.shape()),
            ("c", (n, 1), d.c.shape()),
            ("A", (m, n), d.a.shape()),
            ("b", (m, 1), d.b.shape()),
        ];
        for (what, expected, got) in parts {
            if expected != got {
                return Err(QpError::Shape {
                    what,
                    expected,
                    got,
                });
            }
        }
        // One pass over all values: v·0 is 0 for a finite v and NaN otherwise, so the sum is
        // 0 exactly when every value is finite; only then is the part at fault searched.
        let total: f64 = [
            d.h.as_slice(),
            d.c.as_slice(),
            d.a.as_slice(),
            d.b.as_slice(),
        ]
        .iter()
        .flat_map(|s| s.iter())
        .map(|v| v * 0.0)
        .sum();
        if total == 0.0 {
            return Ok(());
        }
        for (what, values) in [
            ("H", d.h.as_slice()),
            ("c", d.c.as_slice()),
            ("A", d.a.as_slice()),
            ("b", d.b.as_slice()),
        ] {
            if values.iter().any(|v| !v.is_finite()) {
                return Err(QpError::NonFinite { what });
            }
        }
        Ok(())
    }

    /// Solves the QP with the given data. On success [`QpSolver::u`],
    /// [`QpSolver::multipliers`] and [`QpSolver::status`] describe the solution, and the
    /// derivatives ([`QpSolver::directional`]) are available.
    pub fn solve(&mut self, data: &QpData) -> Result<(), QpError> {
        self.prepare(data, |_, kind| match kind {
            ConstraintKind::Eq => Role::Eq,
            ConstraintKind::Le => Role::Le,
        })?;
        let tols = self.tols();
        self.iterations = self.dual.solve(&tols)?;
        self.classify()?;
        self.record_slacks();
        self.solved = true;
        self.working = true;
        Ok(())
    }

    /// Solves the QP with a frozen active set: the equalities and the inequalities with
    /// `active(i)` as equalities, the other inequalities dropped — the smooth piece of the
    /// solution map on which that set is active, continued beyond where it is optimal (a
    /// multiplier may be negative, a dropped constraint violated). Statuses are `Active`
    /// for the frozen set and `Inactive` otherwise, so [`QpSolver::directional`] is the
    /// (linear) derivative of that piece. Linearly dependent frozen constraints are
    /// [`QpError::Degenerate`].
    pub fn solve_frozen(
        &mut self,
        data: &QpData,
        active: impl Fn(usize) -> bool,
    ) -> Result<(), QpError> {
        self.prepare(data, |i, kind| match kind {
            ConstraintKind::Le if !active(i) => Role::Off,
            _ => Role::Eq,
        })?;
        let tols = self.tols();
        self.iterations = self.dual.solve(&tols)?;
        self.u.copy_from(&self.dual.v);
        self.hfac.lower_tr_solve_mut(&mut self.u);
        self.mult.fill(0.0);
        self.status.fill(ConstraintStatus::Inactive);
        for (a, &i) in self.dual.idx.iter().enumerate() {
            self.mult[i] = self.dual.sign[a] * self.dual.lam[a];
            self.status[i] = ConstraintStatus::Active;
        }
        self.kink = false;
        self.record_slacks();
        self.solved = true;
        self.working = true;
        Ok(())
    }

    /// Checks the data, factorises H, and sets up the iteration in v = Lᵀu: the normals,
    /// v₀, β, and each constraint's role `role(i, kind)`.
    fn prepare(
        &mut self,
        data: &QpData,
        role: impl Fn(usize, ConstraintKind) -> Role,
    ) -> Result<(), QpError> {
        self.solved = false;
        self.check_data(data)?;
        let n = self.nvars();
        let h = &data.h;
        let hmax = h.amax();
        for j in 0..n {
            for i in j + 1..n {
                if (h[(i, j)] - h[(j, i)]).abs() > SYMMETRY_TOL * hmax {
                    return Err(QpError::NotSymmetric { row: i, col: j });
                }
            }
        }
        self.hfac
            .factor(n, CONVEX_TOL2, |i, j| 0.5 * (h[(i, j)] + h[(j, i)]))
            .map_err(|pivot| QpError::NotConvex { pivot })?;
        let dual = &mut self.dual;
        dual.set_normals(&data.a, &self.hfac);
        dual.v0.copy_from(&data.c);
        self.hfac.lower_solve_mut(&mut dual.v0);
        dual.v0.neg_mut();
        dual.beta.copy_from_slice(data.b.as_slice());
        for (i, (r, &kind)) in dual.role.iter_mut().zip(&self.kinds).enumerate() {
            *r = role(i, kind);
            // A row of zeros involves no variable: 0 (= or ≤) bᵢ. Left out when it holds
            // strictly, an error naming it otherwise.
            if *r != Role::Off && dual.wnorm[i] == 0.0 {
                let (equality, rhs) = (kind == ConstraintKind::Eq, data.b[i]);
                if equality || rhs <= 0.0 {
                    return Err(QpError::Vanishing {
                        constraint: i,
                        equality,
                        rhs,
                    });
                }
                *r = Role::Off;
            }
        }
        Ok(())
    }

    /// The slacks aᵢᵀu − bᵢ at the last solution, one per constraint.
    pub fn slacks(&self) -> &[f64] {
        &self.slacks
    }

    /// Records the slacks of the iterate (the solution, after a solve), with the scales
    /// they and the multipliers' forces are measured against (the derivatives replace the
    /// iteration's state they come from).
    fn record_slacks(&mut self) {
        let force = self.dual.force_scale();
        self.force = force;
        for (i, (s, scale)) in self
            .slacks
            .iter_mut()
            .zip(&mut self.slack_scales)
            .enumerate()
        {
            *s = self.dual.slack(i);
            *scale = self.dual.slack_scale(i, force);
        }
    }

    /// u = L⁻ᵀv, the multipliers per constraint, each constraint's status, and the check
    /// that the constraints with zero slack are linearly independent.
    fn classify(&mut self) -> Result<(), QpError> {
        let dual = &self.dual;
        self.u.copy_from(&dual.v);
        self.hfac.lower_tr_solve_mut(&mut self.u);
        self.mult.fill(0.0);
        for (a, &i) in dual.idx.iter().enumerate() {
            self.mult[i] = dual.sign[a] * dual.lam[a];
        }
        let tol = self.opts.active_tol;
        let force = dual.force_scale();
        self.near.clear();
        self.kink = false;
        for i in 0..self.kinds.len() {
            let slack_zero = dual.slack(i).abs() <= tol * dual.slack_scale(i, force);
            let force_i = self.mult[i].abs() * dual.wnorm[i];
            self.status[i] = match self.kinds[i] {
                ConstraintKind::Eq => ConstraintStatus::Active,
                ConstraintKind::Le if dual.is_member(i) || slack_zero => {
                    if self.mult[i] < 0.0 && force_i > tol * force {
                        // The iteration keeps μ ≥ 0; a negative one means it lost accuracy.
                        return Err(QpError::NoConvergence {
                            iterations: self.iterations,
                        });
                    }
                    if force_i <= tol * force {
                        self.kink = true;
                        ConstraintStatus::WeaklyActive
                    } else {
                        ConstraintStatus::Active
                    }
                }
                ConstraintKind::Le => ConstraintStatus::Inactive,
            };
            if self.status[i] != ConstraintStatus::Inactive {
                self.near.push(i);
            }
        }
        // The working set is independent by construction; the other zero-slack constraints
        // must not spoil that (LICQ), or the multipliers and derivatives are not unique.
        if self.near.len() > dual.idx.len() {
            let near = std::mem::take(&mut self.near);
            let checked = if near.len() > self.nvars() {
                Err(QpError::Degenerate {
                    constraints: near.clone(),
                })
            } else {
                let dep2 = self.tols().dep2;
                self.dual.check_independent(&near, dep2)
            };
            self.near = near;
            checked?;
        }
        Ok(())
    }

    /// The KKT residual of the last solution for the given data (see [`KktResidual`]).
    pub fn kkt_residual(&self, data: &QpData) -> KktResidual {
        let mut stationarity = &data.h * &self.u + &data.c;
        stationarity.gemv_tr(1.0, &data.a, &DVector::from_column_slice(&self.mult), 1.0);
        let mut r = KktResidual {
            stationarity: stationarity.amax(),
            primal: 0.0,
            dual: 0.0,
            complementarity: 0.0,
        };
        for (i, kind) in self.kinds.iter().enumerate() {
            let s = data.a.row(i).tr_dot(&self.u) - data.b[i];
            match kind {
                ConstraintKind::Eq => r.primal = r.primal.max(s.abs()),
                ConstraintKind::Le => {
                    r.primal = r.primal.max(s.max(0.0));
                    r.dual = r.dual.max((-self.mult[i]).max(0.0));
                    r.complementarity = r.complementarity.max((self.mult[i] * s).abs());
                }
            }
        }
        r
    }
}
