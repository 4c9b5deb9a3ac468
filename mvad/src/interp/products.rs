//! The capability products of a loaded model, from the same kernels `hybrid!` compiles:
//! the vector–Jacobian products of [`ModelAdjoint`] and the exact second-order products of
//! [`ModelSecondOrder`].
//!
//! Each product runs one tape into the shared registers and walks only the tape's non-zero
//! outputs: λᵀG sums λ_r·G_{rk} into column k over the non-zero entries (r, k), and
//! A S + b adds b's entries, then a_e·S_{k·} for each non-zero entry e = (r, k) of A. The
//! sums run in entry order, starting from b, exactly as the generated code writes them, so
//! the two doors agree to rounding. A call allocates nothing (scratch is the model's) and
//! costs the number of non-zeros plus the size of its outputs, never n·p unless S is read.

use mvad_dsl::eval::Tape;
use mvad_dsl::ir::ExprArena;
use mvad_dsl::schedule::SecondOrderKernels;
use mvad_runtime::model::differences;
use mvad_runtime::{At, ModelAdjoint, ModelSecondOrder, Occurrence, Point, Switches};
use nalgebra::Dyn;

use super::run::{at_pt, at_sw, pt0, pt_theta, TapeAt};
use super::{InterpretedModel, ModeTapes, Scratch, M, X};

/// The tapes of [`SecondOrderKernels`], with their entry tables.
#[derive(Clone, Debug)]
pub(super) struct SecondTapes {
    rows: usize,
    x_entries: Vec<(usize, usize)>,
    p_entries: Vec<(usize, usize)>,
    dx: Tape,
    dx_terms: Vec<(usize, usize)>,
    /// Whether G_x entry e has any term in `dx` (entries without one are skipped, as the
    /// generated code skips them).
    has_dx: Vec<bool>,
    dt: Tape,
}

impl SecondTapes {
    pub(super) fn new(ar: &ExprArena, so: &SecondOrderKernels) -> Self {
        let mut has_dx = vec![false; so.x_entries.len()];
        for &(e, _) in &so.dx_terms {
            if let Some(h) = has_dx.get_mut(e) {
                *h = true;
            }
        }
        SecondTapes {
            rows: so.rows,
            x_entries: so.x_entries.clone(),
            p_entries: so.p_entries.clone(),
            dx: Tape::new(ar, &so.dx),
            dx_terms: so.dx_terms.clone(),
            has_dx,
            dt: Tape::new(ar, &so.dt),
        }
    }

    /// out += a·S_{k·} into row r of `out` (`rows`×p, column-major) for entry (r, k); S is
    /// n×p column-major.
    fn add_row(&self, (r, k): (usize, usize), a: f64, s: &[f64], n: usize, out: &mut [f64]) {
        let rows = self.rows;
        for (c, o) in out.iter_mut().skip(r).step_by(rows).enumerate() {
            *o += a * s[k + c * n];
        }
    }

    /// out = ∂ₓ(G_x S + G_θ)·v = (Σᵢ vᵢ ∂G_x/∂xᵢ) S + Σᵢ vᵢ ∂G_θ/∂xᵢ (`rows`×p, column-major),
    /// `w` scratch for the G_x entries. NaN when the tape cannot run.
    #[allow(clippy::too_many_arguments)]
    fn dir_x(
        &self,
        model: &InterpretedModel,
        at: &TapeAt<'_>,
        sc: &mut Scratch,
        s: &[f64],
        v: &[f64],
        out: &mut [f64],
    ) {
        let n = model.n;
        let Scratch { regs, w, .. } = sc;
        let nx = self.x_entries.len();
        if !model.run(&self.dx, at, regs) || w.len() < nx {
            out.fill(f64::NAN);
            return;
        }
        out.fill(0.0);
        w[..nx].fill(0.0);
        for ((_, reg), &(e, i)) in self.dx.outputs().zip(&self.dx_terms) {
            let term = regs[reg] * v[i];
            if e < nx {
                w[e] += term;
            } else {
                let (r, c) = self.p_entries[e - nx];
                out[r + c * self.rows] += term;
            }
        }
        for e in (0..nx).filter(|&e| self.has_dx[e]) {
            self.add_row(self.x_entries[e], w[e], s, n, out);
        }
    }

    /// out = ∂ₜ(G_x S + G_θ) (`rows`×p, column-major); returns ∂ₜG₀ when the kernel has it
    /// (ℓ), else 0. NaN when the tape cannot run.
    fn dt(
        &self,
        model: &InterpretedModel,
        at: &TapeAt<'_>,
        regs: &mut [f64],
        s: &[f64],
        out: &mut [f64],
    ) -> f64 {
        let n = model.n;
        if !model.run(&self.dt, at, regs) {
            out.fill(f64::NAN);
            return f64::NAN;
        }
        let nx = self.x_entries.len();
        let ne = nx + self.p_entries.len();
        out.fill(0.0);
        let mut dt_row = 0.0;
        for (slot, reg) in self.dt.outputs() {
            if slot >= nx && slot < ne {
                let (r, c) = self.p_entries[slot - nx];
                out[r + c * self.rows] = regs[reg];
            } else if slot >= ne {
                dt_row = regs[reg];
            }
        }
        for (slot, reg) in self.dt.outputs().take_while(|&(slot, _)| slot < nx) {
            self.add_row(self.x_entries[slot], regs[reg], s, n, out);
        }
        dt_row
    }
}

/// vx_k = Σ_{(i,k)} w_i·a over the (row, column, value) triples, in order, after a zero fill.
/// The NaN outputs of a vector–Jacobian product whose tape could not run (or was handed
/// vectors of the wrong sizes).
fn nan_vjp(vx: &mut X, vp: &mut X) -> f64 {
    vx.fill(f64::NAN);
    vp.fill(f64::NAN);
    f64::NAN
}

fn transposed(w: &[f64], triples: impl Iterator<Item = (usize, usize, f64)>, out: &mut [f64]) {
    out.fill(0.0);
    for (i, k, a) in triples {
        out[k] += w[i] * a;
    }
}

impl InterpretedModel {
    /// Runs the reset Jacobian tape of occurrence `occ` at `at` and hands `f` whether it ran
    /// (and the cotangents' sizes were right, `sizes`) and the product μ ↦ (μᵀR_x into vx, μᵀR_θ
    /// into vp, returning μᵀR_t) over the tape's non-zero outputs: one evaluation serves any
    /// number of cotangents.
    fn with_reset_jac<R>(
        &self,
        occ: Occurrence,
        at: At<'_, nalgebra::Dyn, nalgebra::Dyn>,
        sizes: bool,
        f: impl FnOnce(bool, &mut dyn FnMut(&X, &mut X, &mut X) -> f64) -> R,
    ) -> R {
        let Occurrence { event, j } = occ;
        let (n, np) = (self.n, self.p);
        let row = self.tables.row(event, j);
        let mut sc = self.scratch.borrow_mut();
        let at = TapeAt {
            row: &row,
            ..pt0(at)
        };
        let e = self.events.get(event).filter(|_| sizes);
        let Some(e) = e.filter(|e| self.run(&e.reset_jac, &at, &mut sc.regs)) else {
            return f(false, &mut |_, _, _| f64::NAN);
        };
        let regs = &sc.regs;
        let vals = || e.reset_jac.outputs().map(|(slot, reg)| (slot, regs[reg]));
        let (nn, nnp) = (n * n, n * n + n * np);
        let mut vjp = |mu: &X, vx: &mut X, vp: &mut X| {
            if vx.len() != n || vp.len() != np {
                return nan_vjp(vx, vp);
            }
            let mu = mu.as_slice();
            transposed(
                mu,
                vals()
                    .filter(|&(s, _)| s < nn)
                    .map(|(s, a)| (s / n, s % n, a)),
                vx.as_mut_slice(),
            );
            transposed(
                mu,
                vals()
                    .filter(|&(s, _)| s >= nn && s < nnp)
                    .map(|(s, a)| ((s - nn) / np, (s - nn) % np, a)),
                vp.as_mut_slice(),
            );
            vals()
                .filter(|&(s, _)| s >= nnp)
                .fold(0.0, |acc, (s, a)| acc + mu[s - nnp] * a)
        };
        f(true, &mut vjp)
    }

    /// Runs ℓ's gradient tape at `at` when w ≠ 0 and the model has a running cost, and hands
    /// each of its non-zero outputs whose slot is in `slots` (x: 0..n, θ: n..n+p) to `add`;
    /// false when the tape cannot run.
    fn running_cost_slots(
        &self,
        at: &TapeAt<'_>,
        regs: &mut [f64],
        w: f64,
        slots: std::ops::Range<usize>,
        mut add: impl FnMut(usize, f64),
    ) -> bool {
        let Some(c) = self.running_cost.as_ref().filter(|_| w != 0.0) else {
            return true;
        };
        if !self.run(&c.grad, at, regs) {
            return false;
        }
        for (slot, reg) in c.grad.outputs().filter(|(s, _)| slots.contains(s)) {
            add(slot, regs[reg]);
        }
        true
    }

    /// Runs the tape that `tape` picks of the point's mode at `pt` into the scratch
    /// registers, then `body` with the mode's tapes, the registers and the tape point;
    /// `body` says whether it could finish. False when the mode does not exist, the caller's
    /// `sizes` do not hold, or a tape cannot run: the caller then fills its outputs with NaN.
    fn with_mode_tape(
        &self,
        pt: Point<'_, Dyn, Dyn>,
        sizes: bool,
        tape: impl Fn(&ModeTapes) -> &Tape,
        body: impl FnOnce(&ModeTapes, &mut [f64], &TapeAt<'_>) -> bool,
    ) -> bool {
        let mut sc = self.scratch.borrow_mut();
        let at = at_pt(pt);
        match self.mode(pt.mode).filter(|_| sizes) {
            Some(m) if self.run(tape(m), &at, &mut sc.regs) => body(m, &mut sc.regs, &at),
            _ => false,
        }
    }

    /// Whether `s` is n×p and `out` n×p (or, for ℓ, `out` has p entries).
    fn sens_shapes(&self, s: &M, out_len: usize, rows: usize) -> bool {
        s.nrows() == self.n && s.ncols() == self.p && out_len == rows * self.p
    }
}

impl ModelAdjoint for InterpretedModel {
    fn rhs_vjp(&self, pt: Point<'_, Self::N, Self::P>, lambda: &X, vx: &mut X, vp: &mut X) {
        let (n, np) = (self.n, self.p);
        let sizes = lambda.len() == n && vx.len() == n && vp.len() == np;
        let done = self.with_mode_tape(
            pt,
            sizes,
            |m| &m.jac,
            |m, regs, _| {
                let (xe, pe) = (&m.second.x_entries, &m.second.p_entries);
                let nx = xe.len();
                let lam = lambda.as_slice();
                let vals = || m.jac.outputs().map(|(slot, reg)| (slot, regs[reg]));
                transposed(
                    lam,
                    vals()
                        .take_while(|&(slot, _)| slot < nx)
                        .map(|(slot, a)| (xe[slot].0, xe[slot].1, a)),
                    vx.as_mut_slice(),
                );
                transposed(
                    lam,
                    vals()
                        .skip_while(|&(slot, _)| slot < nx)
                        .map(|(slot, a)| (pe[slot - nx].0, pe[slot - nx].1, a)),
                    vp.as_mut_slice(),
                );
                true
            },
        );
        if !done {
            vx.fill(f64::NAN);
            vp.fill(f64::NAN);
        }
    }

    /// −(λᵀf_x + w ℓ_x): the flow's f_x tape (its non-zero entries only), then ℓ's gradient
    /// tape over its x slots (when w ≠ 0); nothing of size p is touched.
    fn adjoint_rate(&self, pt: Point<'_, Self::N, Self::P>, lambda: &X, w: f64, out: &mut X) {
        let n = self.n;
        let sizes = lambda.len() == n && out.len() == n;
        let done = self.with_mode_tape(
            pt,
            sizes,
            |m| &m.jac_x,
            |m, regs, at| {
                let vals = m.jac_x.outputs().map(|(s, reg)| (s / n, s % n, regs[reg]));
                transposed(lambda.as_slice(), vals, out.as_mut_slice());
                out.neg_mut();
                let rc = |s: usize, v: f64| out[s] -= w * v;
                self.running_cost_slots(at, regs, w, 0..n, rc)
            },
        );
        if !done {
            out.fill(f64::NAN);
        }
    }

    /// ℓ_x: ℓ's gradient tape over its x slots only (its θ outputs are not read).
    fn running_cost_grad_x(&self, sw: &Switches, at: At<'_, Self::N, Self::P>, lx: &mut X) {
        lx.fill(0.0);
        if lx.len() != self.n {
            lx.fill(f64::NAN);
            return;
        }
        let mut sc = self.scratch.borrow_mut();
        let put = |s: usize, v: f64| lx[s] = v;
        if !self.running_cost_slots(&at_sw(at, sw), &mut sc.regs, 1.0, 0..self.n, put) {
            lx.fill(f64::NAN);
        }
    }

    /// g −= a·(λᵀf_θ + w ℓ_θ) over the non-zero entries of the flow's f_θ tape and the θ
    /// slots of ℓ's gradient tape: O(non-zeros), never O(p).
    fn adjoint_quadrature_add(
        &self,
        pt: Point<'_, Self::N, Self::P>,
        lambda: &X,
        w: f64,
        a: f64,
        g: &mut X,
    ) {
        let (n, np) = (self.n, self.p);
        let sizes = lambda.len() == n && g.len() == np;
        let done = self.with_mode_tape(
            pt,
            sizes,
            |m| &m.jac_p,
            |m, regs, at| {
                for (slot, reg) in m.jac_p.outputs() {
                    let (r, k) = (slot / np, slot % np);
                    g[k] -= a * (lambda[r] * regs[reg]);
                }
                let aw = a * w;
                let rc = |s: usize, v: f64| g[s - n] -= aw * v;
                self.running_cost_slots(at, regs, w, n..n + np, rc)
            },
        );
        if !done {
            g.fill(f64::NAN);
        }
    }

    fn gradient_support(&self, mode: usize) -> Option<&[usize]> {
        self.mode(mode).map(|m| m.gradient_support.as_slice())
    }

    #[allow(clippy::too_many_arguments)]
    fn reset_vjp(
        &self,
        occ: Occurrence,
        at: At<'_, Self::N, Self::P>,
        mu: &X,
        vx: &mut X,
        vp: &mut X,
    ) -> f64 {
        self.with_reset_jac(occ, at, mu.len() == self.n, |ok, vjp| {
            if ok {
                vjp(mu, vx, vp)
            } else {
                nan_vjp(vx, vp)
            }
        })
    }

    /// One run of the reset's Jacobian tape for both cotangents.
    fn reset_vjp_pair(
        &self,
        occ: Occurrence,
        at: At<'_, Self::N, Self::P>,
        (mu1, mu2): (&X, &X),
        (vx1, vp1): (&mut X, &mut X),
        (vx2, vp2): (&mut X, &mut X),
    ) -> (f64, f64) {
        let sizes = mu1.len() == self.n && mu2.len() == self.n;
        self.with_reset_jac(occ, at, sizes, |ok, vjp| {
            if ok {
                (vjp(mu1, vx1, vp1), vjp(mu2, vx2, vp2))
            } else {
                (nan_vjp(vx1, vp1), nan_vjp(vx2, vp2))
            }
        })
    }

    fn initial_state_vjp(&self, p: &X, mu: &X, vp: &mut X) {
        let (n, np) = (self.n, self.p);
        let mut sc = self.scratch.borrow_mut();
        let at = pt_theta(p);
        if mu.len() != n || vp.len() != np || !self.run(&self.x0_jac, &at, &mut sc.regs) {
            vp.fill(f64::NAN);
            return;
        }
        let regs = &sc.regs;
        let vals = self.x0_jac.outputs();
        transposed(
            mu.as_slice(),
            vals.map(|(s, reg)| (s / np, s % np, regs[reg])),
            vp.as_mut_slice(),
        );
    }
}

/// A flow or ℓ that reads a qp of the state has no symbolic second derivatives (the qp's
/// KKT derivatives are first derivatives): its products are the defaults' difference
/// quotients, `mvad_runtime::model::differences`.
impl ModelSecondOrder for InterpretedModel {
    fn rhs_sens_dir_x(&self, pt: Point<'_, Self::N, Self::P>, s: &M, v: &X, out: &mut M) {
        if self.second_by_differences {
            return differences::rhs_sens_dir_x(self, pt, s, v, out);
        }
        let mode = pt.mode;
        let ok = v.len() == self.n && self.sens_shapes(s, out.len(), self.n);
        match self.mode(mode).filter(|_| ok) {
            Some(m) => {
                let mut sc = self.scratch.borrow_mut();
                let at = at_pt(pt);
                let (s, v) = (s.as_slice(), v.as_slice());
                m.second.dir_x(self, &at, &mut sc, s, v, out.as_mut_slice());
            }
            None => out.fill(f64::NAN),
        }
    }

    fn rhs_sens_dt(&self, pt: Point<'_, Self::N, Self::P>, s: &M, out: &mut M) {
        if self.second_by_differences {
            return differences::rhs_sens_dt(self, pt, s, out);
        }
        let mode = pt.mode;
        let ok = self.sens_shapes(s, out.len(), self.n);
        match self.mode(mode).filter(|_| ok) {
            Some(m) if m.depends_on_t => {
                let mut sc = self.scratch.borrow_mut();
                let at = at_pt(pt);
                let o = out.as_mut_slice();
                m.second.dt(self, &at, &mut sc.regs, s.as_slice(), o);
            }
            Some(_) => out.fill(0.0),
            None => out.fill(f64::NAN),
        }
    }
    fn running_cost_sens_dir_x(
        &self,
        sw: &Switches,
        at: At<'_, Self::N, Self::P>,
        s: &M,
        v: &X,
        out: &mut X,
    ) {
        if self.second_by_differences {
            return differences::running_cost_sens_dir_x(self, sw, at, s, v, out);
        }
        if v.len() != self.n || !self.sens_shapes(s, out.len(), 1) {
            out.fill(f64::NAN);
            return;
        }
        match &self.running_cost_second {
            Some(so) => {
                let mut sc = self.scratch.borrow_mut();
                let at = at_sw(at, sw);
                let (s, v) = (s.as_slice(), v.as_slice());
                so.dir_x(self, &at, &mut sc, s, v, out.as_mut_slice());
            }
            None => out.fill(0.0),
        }
    }

    fn running_cost_sens_dt(
        &self,
        sw: &Switches,
        at: At<'_, Self::N, Self::P>,
        s: &M,
        out: &mut X,
    ) -> f64 {
        if self.second_by_differences {
            return differences::running_cost_sens_dt(self, sw, at, s, out);
        }
        if !self.sens_shapes(s, out.len(), 1) {
            out.fill(f64::NAN);
            return f64::NAN;
        }
        match &self.running_cost_second {
            Some(so) => {
                let mut sc = self.scratch.borrow_mut();
                let at = at_sw(at, sw);
                so.dt(self, &at, &mut sc.regs, s.as_slice(), out.as_mut_slice())
            }
            None => {
                out.fill(0.0);
                0.0
            }
        }
    }
}
