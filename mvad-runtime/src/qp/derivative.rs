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

use super::active_set::Role;
use super::{ConstraintStatus, QpData, QpError, QpSolver, Side};
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
        if self.kink {
            for (role, status) in dual.role.iter_mut().zip(&self.status) {
                *role = match status {
                    ConstraintStatus::Active => Role::Eq,
                    ConstraintStatus::WeaklyActive => Role::Le,
                    ConstraintStatus::Inactive => Role::Off,
                };
            }
            let tols = self.tols();
            self.dual.solve(&tols)?;
        } else {
            // The working set is the active set and its Gram factor is the solve's.
            dual.resolve_on_working_set();
        }
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
        Ok(())
    }
}
