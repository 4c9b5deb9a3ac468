//! The sensitivity rate of a flow at a persistent qp kink: [`FlowPieces`].
//!
//! A flow reads a qp of the state on the active set its switch bits freeze, so f_x S + f_θ
//! is the derivative of one smooth piece of the solution map. Where a constraint is weakly
//! active *along* the flow (slack and multiplier zero and staying zero: u = argmin ½(u − x)²
//! s.t. u ≤ x + k at k = 0), the perturbed trajectories leave the kink to either side
//! depending on the direction of the perturbation, so the derivative of the solution is
//! one-sided and not linear in it. Column j of S is then its own directional sensitivity,
//!
//! $$ \dot s_j = f_x s_j + f_\theta e_j + f_u\,\big(u'(x,\theta;\ s_j, e_j) - u_x s_j - u_\theta e_j\big), $$
//!
//! with u' the qp's one-sided directional derivative ([`super::QpSolver::directional_on_piece`],
//! `−u'(·; −d)` for the left run). u' is the derivative of the piece whose active set the
//! derivative problem ends with ([`super::QpBank::flow_pieces`]), so column j's rate is the
//! model's own f_x S + f_θ (and ℓ_x S + ℓ_θ) evaluated under that piece's bits: one more
//! evaluation per distinct piece, no new kernel.

use crate::model::{At, HybridModel, ModelAlloc, Point, Switches};
use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector};

/// Buffers of the piecewise sensitivity rate of one run (allocated once, for a model whose
/// flows read qps of the state).
pub struct FlowPieces<M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// Per column of S, the bits of its piece.
    pieces: Vec<Switches>,
    /// Which columns have their rate.
    done: Vec<bool>,
    /// f, f_x S + f_θ, ℓ_x and ℓ_θ under one piece.
    f: OVector<f64, M::N>,
    ds: OMatrix<f64, M::N, M::P>,
    lx: OVector<f64, M::N>,
    lp: OVector<f64, M::P>,
}

impl<M: HybridModel> FlowPieces<M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// The buffers for `model`, or `None` when no flow reads a qp (no qp has switch bits).
    pub fn new(model: &M) -> Option<Self> {
        if !model.qps().iter().any(|q| q.switches.is_some()) {
            return None;
        }
        let (n, p) = (model.nstates(), model.nparams());
        let np = p.value();
        Some(FlowPieces {
            pieces: vec![Switches::new(model.info().switches); np],
            done: vec![false; np],
            f: OVector::zeros_generic(n, Const::<1>),
            ds: OMatrix::zeros_generic(n, p),
            lx: OVector::zeros_generic(n, Const::<1>),
            lp: OVector::zeros_generic(p, Const::<1>),
        })
    }

    /// After the flow's rate at `pt` was evaluated under `pt.sw` — f in `f`, and with
    /// sensitivities (`s` = S) f_x S + f_θ in `ds` and, with a running cost, ℓ_x S + ℓ_θ in
    /// `dq` — replaces the columns whose one-sided derivative follows another piece (see the
    /// module doc). Without `s` it only looks for persistent kinks (the model logs them). A
    /// qp that fails in the analysis leaves NaN in f (and `ds`), which the run reports as
    /// that qp's error.
    pub fn correct(
        &mut self,
        model: &M,
        pt: Point<'_, M::N, M::P>,
        s: Option<&OMatrix<f64, M::N, M::P>>,
        f: &mut OVector<f64, M::N>,
        ds: &mut OMatrix<f64, M::N, M::P>,
        mut dq: Option<&mut OVector<f64, M::P>>,
    ) {
        match model.qp_flow_pieces(pt, f, s, &mut self.pieces) {
            Some(true) => {}
            Some(false) => return,
            None => {
                f.fill(f64::NAN);
                ds.fill(f64::NAN);
                return;
            }
        }
        let Some(s) = s else {
            return;
        };
        let np = s.ncols();
        for j in 0..np {
            self.done[j] = self.pieces[j] == *pt.sw;
        }
        for j in 0..np {
            if self.done[j] {
                continue;
            }
            let piece = &self.pieces[j];
            model.rhs_sens(
                Point::new(pt.mode, piece, pt.t, pt.x, pt.p),
                s,
                &mut self.f,
                &mut self.ds,
            );
            if dq.is_some() {
                let at = At::new(pt.t, pt.x, pt.p);
                model.running_cost_value_grad(piece, at, &mut self.lx, &mut self.lp);
            }
            for k in j..np {
                if self.done[k] || self.pieces[k] != self.pieces[j] {
                    continue;
                }
                ds.column_mut(k).copy_from(&self.ds.column(k));
                if let Some(dq) = dq.as_deref_mut() {
                    dq[k] = self.lp[k] + self.lx.dot(&s.column(k));
                }
                self.done[k] = true;
            }
        }
    }
}
