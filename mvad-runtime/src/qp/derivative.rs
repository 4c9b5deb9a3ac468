//! One-sided directional derivatives of the solution and the multipliers (see the module
//! documentation of `qp` for the KKT system they solve).
//!
//! For a direction d = (dH, dc, dA, db) and a sign s = ±1, the derivative problem is the QP
//! in du with Hessian H, linear term q = s(dH u + dc + dAᵀμ) and rows aᵢᵀdu (= or ≤)
//! s(dbᵢ − daᵢᵀu): the active constraints as equalities, the weakly active ones as
//! inequalities, the rest dropped. In v = Lᵀu it is again a projection, with the normals
//! wᵢ of the solve, so it runs through the same dual iteration; without weakly active
//! constraints it is the polish's equality-constrained solve on the factor the solve left.
//! Its solution, times s, is the right (s = 1) or left (s = −1) derivative.
//!
//! **On a frozen piece.** After [`QpSolver::solve_frozen`] (the smooth piece of a given
//! active set, as a flow reads it) [`QpSolver::piece_weak`] finds the constraints that are
//! weakly active *at the point* although the piece holds them one way: a held constraint
//! whose multiplier is zero, or a dropped one whose slack is zero (the same tolerances as
//! [`QpSolver::solve`]'s classification). [`QpSolver::directional_on_piece`] solves the
//! derivative problem with those as inequalities, the other held constraints as equalities
//! and the other dropped ones left out: the one-sided derivative of the unfrozen solution
//! map along d. The constraints its working set ends with (`piece`) are the active set of
//! the smooth piece whose derivative along d it is, and `again` says which of the weak
//! constraints are weakly active in the derivative problem too (slack and multiplier of the
//! derivative both zero: along d the constraint stays on the kink to first order).

use super::active_set::Role;
use super::{ConstraintKind, ConstraintStatus, QpData, QpError, QpSolver, Side};
use nalgebra::DVectorView;

impl QpSolver {
    /// The one-sided derivative of u* and μ along the data direction d (see [`Side`]),
    /// written to `du` (n entries) and `dmult` (m entries). Away from a kink both sides
    /// agree and are linear in d.
    pub fn directional(
        &mut self,
        d: &QpData,
        side: Side,
        du: &mut [f64],
        dmult: &mut [f64],
    ) -> Result<(), QpError> {
        let s = self.derivative_problem(d, side, du, dmult)?;
        if self.kink {
            for (role, status) in self.dual.role.iter_mut().zip(&self.status) {
                *role = match status {
                    ConstraintStatus::Active => Role::Eq,
                    ConstraintStatus::WeaklyActive => Role::Le,
                    ConstraintStatus::Inactive => Role::Off,
                };
            }
            let tols = self.tols();
            self.dual.solve(&tols)?;
        } else if self.working {
            // The working set is the active set and its Gram factor is the solve's.
            self.dual.resolve_on_working_set();
        } else {
            return Err(QpError::NotSolved);
        }
        self.write_derivative(s, du, dmult);
        Ok(())
    }

    /// After [`QpSolver::solve_frozen`]: marks in `weak` (m entries) the inequalities that
    /// are weakly active at the point — held with a zero multiplier, or dropped with a zero
    /// slack, each within [`super::QpOptions::active_tol`] of its scale — and returns
    /// whether there is one. Allocates nothing.
    pub fn piece_weak(&self, weak: &mut [bool]) -> bool {
        let tol = self.opts.active_tol;
        let mut any = false;
        for (i, w) in weak.iter_mut().enumerate() {
            *w = self.kinds[i] == ConstraintKind::Le
                && if self.status[i] == ConstraintStatus::Active {
                    self.mult[i].abs() * self.dual.wnorm[i] <= tol * self.force
                } else {
                    self.slacks[i].abs() <= tol * self.slack_scales[i]
                };
            any |= *w;
        }
        any
    }

    /// After [`QpSolver::solve_frozen`], the one-sided derivative of the *unfrozen* solution
    /// map along d with the constraints `weak` marks (see [`QpSolver::piece_weak`]) as
    /// inequalities: written to `du` and `dmult` like [`QpSolver::directional`]. For each
    /// weak constraint, `piece[i]` says whether the derivative holds it (the active set of
    /// the piece the derivative follows) and `again[i]` whether it is weakly active in the
    /// derivative problem as well. The solver's working set is the derivative's afterwards:
    /// [`QpSolver::directional`] needs a new solve (until then it is [`QpError::NotSolved`]).
    #[allow(clippy::too_many_arguments)]
    pub fn directional_on_piece(
        &mut self,
        d: &QpData,
        side: Side,
        weak: &[bool],
        du: &mut [f64],
        dmult: &mut [f64],
        piece: &mut [bool],
        again: &mut [bool],
    ) -> Result<(), QpError> {
        let s = self.derivative_problem(d, side, du, dmult)?;
        for (i, role) in self.dual.role.iter_mut().enumerate() {
            *role = if weak[i] {
                Role::Le
            } else if self.status[i] == ConstraintStatus::Active {
                Role::Eq
            } else {
                Role::Off
            };
        }
        let tols = self.tols();
        self.working = false;
        self.dual.solve(&tols)?;
        let tol = self.opts.active_tol;
        let dual = &self.dual;
        let force = dual.force_scale();
        for i in 0..weak.len() {
            piece[i] = dual.is_member(i);
            again[i] = weak[i] && {
                let lam = (dual.idx.iter().position(|&k| k == i)).map_or(0.0, |a| dual.lam[a]);
                dual.slack(i).abs() <= tol * dual.slack_scale(i, force)
                    && lam.abs() * dual.wnorm[i] <= tol * force
            };
        }
        self.write_derivative(s, du, dmult);
        Ok(())
    }

    /// Checks the direction and the outputs and sets up the derivative problem along d on
    /// `side` (q, v₀ = −sL⁻¹q, β); returns s = ±1.
    fn derivative_problem(
        &mut self,
        d: &QpData,
        side: Side,
        du: &[f64],
        dmult: &[f64],
    ) -> Result<f64, QpError> {
        if !self.solved {
            return Err(QpError::NotSolved);
        }
        self.check_data(d)?;
        let (n, m) = (self.nvars(), self.nconstraints());
        if du.len() != n || dmult.len() != m {
            return Err(QpError::Shape {
                what: "derivative output",
                expected: (n, m),
                got: (du.len(), dmult.len()),
            });
        }
        let s = match side {
            Side::Right => 1.0,
            Side::Left => -1.0,
        };
        // q = s(dH u + dc + dAᵀμ), and v₀ = −L⁻¹q.
        self.q.copy_from(&d.c);
        self.q.gemv(1.0, &d.h, &self.u, 1.0);
        let mult = DVectorView::from_slice(&self.mult, m);
        self.q.gemv_tr(1.0, &d.a, &mult, 1.0);
        let dual = &mut self.dual;
        dual.v0.copy_from(&self.q);
        self.hfac.lower_solve_mut(&mut dual.v0);
        dual.v0 *= -s;
        for i in 0..m {
            dual.beta[i] = s * (d.b[i] - d.a.row(i).tr_dot(&self.u));
        }
        Ok(s)
    }

    /// du = s L⁻ᵀv and dμ = s λ from the derivative problem's solution.
    fn write_derivative(&mut self, s: f64, du: &mut [f64], dmult: &mut [f64]) {
        let dual = &mut self.dual;
        self.hfac.lower_tr_solve_mut(&mut dual.v);
        // (+ 0.0 turns the −0.0 of a negated zero into 0.0.)
        for (o, v) in du.iter_mut().zip(dual.v.iter()) {
            *o = s * v + 0.0;
        }
        dmult.fill(0.0);
        for (a, &i) in dual.idx.iter().enumerate() {
            dmult[i] = s * dual.sign[a] * dual.lam[a] + 0.0;
        }
    }
}
