//! The model seam of an [`InterpretedModel`]: `HybridModel` and the fused `ModelSens`
//! product, each method one or two tape runs (`run.rs`).

use mvad_dsl::ir::Point;
use mvad_runtime::qp::{QpBank, QpError, QpLayerInfo, QpState};
use mvad_runtime::{
    At, AtOf, HybridModel, ModelDims, ModelInfo, ModelSens, Occurrence, PointOf, Switches,
};
use nalgebra::Dyn;
use std::cell::RefCell;

use super::run::{at_pt, at_sw, copy_into, pt0, pt_row, pt_theta};
use super::{InterpretedModel, Scratch, M, X};

impl ModelDims for InterpretedModel {
    type N = Dyn;
    type P = Dyn;
}

impl HybridModel for InterpretedModel {
    fn info(&self) -> &ModelInfo {
        &self.info
    }
    fn nstates(&self) -> Dyn {
        Dyn(self.n)
    }
    fn nparams(&self) -> Dyn {
        Dyn(self.p)
    }

    fn initial_state(&self, p: &X, x0: &mut X) {
        let at = pt_theta(p);
        self.vec_out(&self.x0, &at, x0);
    }
    fn initial_state_jac(&self, p: &X, dx0: &mut M) {
        let at = pt_theta(p);
        self.mat(&self.x0_jac, &at, dx0, self.p);
    }
    fn horizon(&self, p: &X) -> Option<f64> {
        let at = pt_theta(p);
        self.horizon.as_ref().map(|(h, _)| self.scalar(h, &at))
    }
    fn horizon_grad(&self, p: &X, dt: &mut X) {
        let at = pt_theta(p);
        match &self.horizon {
            Some((_, g)) => self.vec_out(g, &at, dt),
            None => dt.fill(0.0),
        }
    }

    fn rhs(&self, pt: PointOf<'_, Self>, f: &mut X) {
        let mode = pt.mode;
        match self.mode(mode) {
            Some(m) => self.vec_out(&m.rhs, &at_pt(pt), f),
            None => f.fill(f64::NAN),
        }
    }
    fn rhs_jac_x(&self, pt: PointOf<'_, Self>, fx: &mut M) {
        let mode = pt.mode;
        match self.mode(mode) {
            Some(m) => self.mat(&m.jac_x, &at_pt(pt), fx, self.n),
            None => fx.fill(f64::NAN),
        }
    }
    fn rhs_jac_p(&self, pt: PointOf<'_, Self>, fp: &mut M) {
        let mode = pt.mode;
        match self.mode(mode) {
            Some(m) => self.mat(&m.jac_p, &at_pt(pt), fp, self.p),
            None => fp.fill(f64::NAN),
        }
    }
    fn rhs_dt(&self, pt: PointOf<'_, Self>, ft: &mut X) {
        let mode = pt.mode;
        match self.mode(mode) {
            Some(m) if m.depends_on_t => self.vec_out(&m.dt, &at_pt(pt), ft),
            Some(_) => ft.fill(0.0),
            None => ft.fill(f64::NAN),
        }
    }
    fn rhs_depends_on_t(&self, mode: usize) -> bool {
        self.mode(mode).is_some_and(|m| m.depends_on_t)
    }
    fn flow_is_constant(&self, mode: usize) -> bool {
        self.mode(mode).is_some_and(|m| m.constant)
    }

    fn guard(&self, event: usize, at: AtOf<'_, Self>) -> f64 {
        match self.events.get(event) {
            Some(e) => self.scalar(&e.guard.value, &pt0(at)),
            None => f64::NAN,
        }
    }
    fn guard_is_affine(&self, event: usize) -> bool {
        self.events.get(event).is_some_and(|e| e.affine_guard)
    }
    fn guard_grad(&self, event: usize, at: AtOf<'_, Self>, gx: &mut X, gp: &mut X) -> f64 {
        match self.events.get(event) {
            Some(e) => self.grad(&e.guard, &pt0(at), gx, gp),
            None => {
                gx.fill(f64::NAN);
                gp.fill(f64::NAN);
                f64::NAN
            }
        }
    }
    fn reset(&self, occ: Occurrence, at: AtOf<'_, Self>, xplus: &mut X) {
        let Occurrence { event, j } = occ;
        let row = self.tables.row(event, j);
        match self.events.get(event) {
            Some(e) => self.vec_out(&e.reset, &pt_row(at, &row), xplus),
            None => xplus.fill(f64::NAN),
        }
    }
    fn reset_jac(&self, occ: Occurrence, at: AtOf<'_, Self>, rx: &mut M, rp: &mut M, rt: &mut X) {
        let Occurrence { event, j } = occ;
        let Some(e) = self.events.get(event) else {
            rx.fill(f64::NAN);
            rp.fill(f64::NAN);
            rt.fill(f64::NAN);
            return;
        };
        let (n, np) = (self.n, self.p);
        let tape = &e.reset_jac;
        let row = self.tables.row(event, j);
        self.with(tape, &pt_row(at, &row), |ok, regs, out| {
            Self::mat_out(tape, ok, regs, rx, n, 0);
            Self::mat_out(tape, ok, regs, rp, np, n * n);
            out[..n].fill(if ok { 0.0 } else { f64::NAN });
            if ok {
                for (s, r) in tape.outputs() {
                    if s >= n * n + n * np {
                        out[s - n * n - n * np] = regs[r];
                    }
                }
            }
            copy_into(rt.as_mut_slice(), &out[..n]);
        });
    }

    fn event_time(&self, occ: Occurrence, p: &X) -> f64 {
        let Occurrence { event, j } = occ;
        self.time_of(event, j, p)
    }
    fn event_time_grad(&self, occ: Occurrence, p: &X, dtau: &mut X) {
        let Occurrence { event, j } = occ;
        self.time_grad_of(event, j, p, dtau);
    }

    fn switch_value(&self, j: usize, at: AtOf<'_, Self>) -> f64 {
        let At { t, x, p } = at;
        let at = pt0(at);
        match self.switches.get(j) {
            Some(s) => self.scalar(&s.value, &at),
            // Past the kinks' switching functions: the qps' constraints.
            None => self.qp_bank.borrow_mut().switch_value(
                j,
                t,
                x.as_slice(),
                p.as_slice(),
                self.qp_fill(&at),
            ),
        }
    }
    fn switch_grad(&self, j: usize, at: AtOf<'_, Self>, gx: &mut X, gp: &mut X) -> f64 {
        let At { t, x, p } = at;
        let at = pt0(at);
        match self.switches.get(j) {
            Some(s) => self.grad(s, &at, gx, gp),
            None => {
                let fill = self.qp_fill(&at);
                let (gx, gp) = (gx.as_mut_slice(), gp.as_mut_slice());
                let mut bank = self.qp_bank.borrow_mut();
                bank.switch_grad(j, t, x.as_slice(), p.as_slice(), fill, gx, gp)
                    .1
            }
        }
    }

    fn observe(&self, sw: &Switches, at: AtOf<'_, Self>, y: &mut [f64]) {
        if y.len() < self.info.observables.len() {
            return;
        }
        let mut sc = self.scratch.borrow_mut();
        let at = at_sw(at, sw);
        self.eval(&self.observe, &at, &mut sc.regs, y);
    }
    fn observe_jac(&self, sw: &Switches, at: AtOf<'_, Self>, yx: &mut [f64], yp: &mut [f64]) {
        let nobs = self.info.observables.len();
        let (n, np) = (self.n, self.p);
        if yx.len() < nobs * n || yp.len() < nobs * np {
            return;
        }
        let tape = &self.observe_jac;
        self.with(tape, &at_sw(at, sw), |ok, regs, _| {
            let fill = if ok { 0.0 } else { f64::NAN };
            yx.iter_mut().take(nobs * n).for_each(|v| *v = fill);
            yp.iter_mut().take(nobs * np).for_each(|v| *v = fill);
            if !ok {
                return;
            }
            for (s, r) in tape.outputs() {
                let slot = if s < nobs * n {
                    yx.get_mut(s)
                } else {
                    yp.get_mut(s - nobs * n)
                };
                if let Some(v) = slot {
                    *v = regs[r];
                }
            }
        });
    }

    fn running_cost(&self, sw: &Switches, at: AtOf<'_, Self>) -> f64 {
        match &self.running_cost {
            Some(c) => self.scalar(&c.value, &at_sw(at, sw)),
            None => 0.0,
        }
    }
    fn running_cost_value_grad(
        &self,
        sw: &Switches,
        at: AtOf<'_, Self>,
        lx: &mut X,
        lp: &mut X,
    ) -> f64 {
        match &self.running_cost {
            Some(c) => self.grad(c, &at_sw(at, sw), lx, lp),
            None => {
                lx.fill(0.0);
                lp.fill(0.0);
                0.0
            }
        }
    }
    fn event_cost(&self, occ: Occurrence, at: AtOf<'_, Self>) -> f64 {
        let Occurrence { event, j } = occ;
        let row = self.tables.row(event, j);
        match self.events.get(event).and_then(|e| e.cost.as_ref()) {
            Some(c) => self.scalar(&c.value, &pt_row(at, &row)),
            None => 0.0,
        }
    }
    fn event_cost_grad(&self, occ: Occurrence, at: AtOf<'_, Self>, cx: &mut X, cp: &mut X) -> f64 {
        let Occurrence { event, j } = occ;
        let row = self.tables.row(event, j);
        match self.events.get(event).and_then(|e| e.cost.as_ref()) {
            Some(c) => self.grad(c, &pt_row(at, &row), cx, cp),
            None => {
                cx.fill(0.0);
                cp.fill(0.0);
                0.0
            }
        }
    }
    fn final_cost(&self, at: AtOf<'_, Self>) -> f64 {
        match &self.final_cost {
            Some(c) => self.scalar(&c.value, &pt0(at)),
            None => 0.0,
        }
    }
    fn final_cost_grad(&self, at: AtOf<'_, Self>, cx: &mut X, cp: &mut X) -> f64 {
        match &self.final_cost {
            Some(c) => self.grad(c, &pt0(at), cx, cp),
            None => {
                cx.fill(0.0);
                cp.fill(0.0);
                0.0
            }
        }
    }

    fn qps(&self) -> &[QpLayerInfo] {
        &self.qp_info
    }
    fn qp_states(&self, at: AtOf<'_, Self>) -> Result<Vec<QpState>, (usize, QpError)> {
        self.evaluate_qps(&pt0(at), false);
        self.qp_bank.borrow().states()
    }
    fn qp_bank(&self) -> Option<&RefCell<QpBank>> {
        Some(&self.qp_bank)
    }
    fn qp_flow_pieces(
        &self,
        pt: PointOf<'_, Self>,
        f: &X,
        s: Option<&M>,
        pieces: &mut [Switches],
    ) -> Option<bool> {
        let at = at_pt(pt);
        let Point { t, x, p, .. } = at.pt;
        let s = s.map(|s| s.as_slice());
        let fill = self.qp_fill(&at);
        let mut bank = self.qp_bank.borrow_mut();
        let found = bank.flow_pieces(t, x, p, pt.sw, f.as_slice(), s, pieces, fill);
        found.ok()
    }
    fn qp_piece(
        &self,
        q: usize,
        at: AtOf<'_, Self>,
        (dx, j, dt): (&X, usize, f64),
        active: &mut [bool],
    ) -> Option<bool> {
        let at = pt0(at);
        let Point { t, x, p, .. } = at.pt;
        let fill = self.qp_fill(&at);
        let mut bank = self.qp_bank.borrow_mut();
        let found = bank.pointwise_piece(q, (t, x, p), (dx.as_slice(), j, dt), active, fill);
        found.ok()
    }
}

impl ModelSens for InterpretedModel {
    fn rhs_sens(&self, pt: PointOf<'_, Self>, s: &M, f: &mut X, ds: &mut M) {
        let mode = pt.mode;
        let Some(m) = self.mode(mode) else {
            f.fill(f64::NAN);
            ds.fill(f64::NAN);
            return;
        };
        let (n, np) = (self.n, self.p);
        let nnz = m.sparsity.len();
        if s.nrows() != n || s.ncols() != np || ds.nrows() != n || ds.ncols() != np {
            f.fill(f64::NAN);
            ds.fill(f64::NAN);
            return;
        }
        let mut sc = self.scratch.borrow_mut();
        let Scratch { regs, out, .. } = &mut *sc;
        let at = at_pt(pt);
        self.eval(&m.sens, &at, regs, out);
        copy_into(f.as_mut_slice(), &out[..n]);
        let fp = &out[n + nnz..n + nnz + n * np];
        for r in 0..n {
            for c in 0..np {
                ds[(r, c)] = fp[r * np + c];
            }
        }
        for (e, &(r, k)) in m.sparsity.iter().enumerate() {
            let a = out[n + e];
            for c in 0..np {
                ds[(r, c)] += a * s[(k, c)];
            }
        }
    }
}
