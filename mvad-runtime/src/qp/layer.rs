//! One qp layer of a [`super::QpBank`]: its solver, its data and Jacobian as the kernels
//! write them, the point its results belong to, and its switching functions.
//!
//! **Frozen active sets.** A qp whose solution a flow reads has one switch bit per
//! inequality constraint: bit set ⇔ the constraint is held active. Under frozen bits the
//! layer solves the equality-constrained QP on that set ([`QpSolver::solve_frozen`]), a
//! smooth function of (t, x, θ), so no integration step straddles a change of the active
//! set. Its switching function σᵢ = sᵢ + μᵢ (slack plus multiplier of the pointwise solve)
//! is negative while constraint i is inactive (μᵢ = 0, sᵢ < 0), positive while it is active
//! (sᵢ = 0, μᵢ > 0) and crosses zero where it activates or releases; its gradient is that of
//! the piece the constraint is on (μᵢ on the set that holds it, sᵢ on the set that drops
//! it). Both pieces vanish on the same surface, so either gives the crossing time's
//! derivative t' = −(σ_x S + σ_θ)/(σ_x f + σ_t).

use super::{
    ConstraintKind, ConstraintStatus, QpData, QpError, QpLayerInfo, QpOptions, QpSolver, Side,
};
use crate::model::Switches;
use nalgebra::{DMatrix, DVector};

/// The point a cached result belongs to.
#[derive(Clone, Debug)]
struct Key {
    /// Whether the solution at the point is cached.
    valid: bool,
    /// Whether its derivatives are too.
    derivs: bool,
    side: Side,
    /// Whether it was a frozen solve (then `bits` is its active set).
    frozen: bool,
    bits: Vec<bool>,
    t: f64,
    x: Vec<f64>,
    p: Vec<f64>,
}

/// One qp with its solver and buffers (allocated once).
#[derive(Clone, Debug)]
pub(super) struct Layer {
    pub(super) info: QpLayerInfo,
    /// The index of its first variable in the bank's u*.
    pub(super) offset: usize,
    pub(super) solver: QpSolver,
    pub(super) failure: Option<QpError>,
    data: QpData,
    /// The data slots as the kernel writes them: H (row-major), c, A (row-major), b.
    flat: Vec<f64>,
    /// ∂data/∂(x, θ, t), slot d·(n + p + 1) + w.
    jac: Vec<f64>,
    /// Scratch: one direction of the data, and the derivative along it.
    dir: QpData,
    du: Vec<f64>,
    dm: Vec<f64>,
    /// The frozen active set of the current evaluation.
    bits: Vec<bool>,
    /// Scratch: u* while derivatives are taken.
    u_star: DVector<f64>,
    /// Scratch of the piece analysis (`flow_pieces`), one entry per constraint: weakly
    /// active on the frozen piece (then: along the flow too), held by a derivative, weakly
    /// active in a derivative.
    weak: Vec<bool>,
    piece: Vec<bool>,
    again: Vec<bool>,
    /// A pointwise evaluation solves on `pin_bits` when `pinned` (see `QpBank::pin`).
    pinned: bool,
    pin_bits: Vec<bool>,
    key: Key,
}

impl Layer {
    /// A layer for a model with n states and p params.
    pub(super) fn new(
        info: QpLayerInfo,
        offset: usize,
        n: usize,
        p: usize,
        opts: QpOptions,
    ) -> Self {
        let (v, m) = (info.vars.len(), info.kinds.len());
        let len = v * v + v + m * v + m;
        Layer {
            offset,
            solver: QpSolver::new(v, &info.kinds, opts),
            failure: None,
            data: QpData::zeros(v, m),
            flat: vec![0.0; len],
            jac: vec![0.0; len * (n + p + 1)],
            dir: QpData::zeros(v, m),
            du: vec![0.0; v],
            dm: vec![0.0; m],
            bits: vec![false; m],
            u_star: DVector::zeros(v),
            weak: vec![false; m],
            piece: vec![false; m],
            again: vec![false; m],
            pinned: false,
            pin_bits: vec![false; m],
            key: Key {
                valid: false,
                derivs: false,
                side: Side::Right,
                frozen: false,
                bits: vec![false; m],
                t: 0.0,
                x: vec![0.0; n],
                p: vec![0.0; p],
            },
            info,
        }
    }

    /// Reads the frozen active set from `sw` when the layer has switch bits and `sw` is
    /// given, else the pinned one if the layer is pinned; returns whether the evaluation is
    /// frozen.
    fn load_bits(&mut self, sw: Option<&Switches>) -> bool {
        let (Some(sw), Some(first)) = (sw, self.info.switches) else {
            if self.pinned {
                self.bits.copy_from_slice(&self.pin_bits);
            }
            return self.pinned;
        };
        let mut j = first;
        for (bit, kind) in self.bits.iter_mut().zip(&self.info.kinds) {
            if *kind == ConstraintKind::Le {
                *bit = sw.get(j);
                j += 1;
            }
        }
        true
    }

    /// Whether (t, x, θ) with these settings is the cached point.
    fn cached(&self, frozen: bool, side: Side, t: f64, x: &[f64], p: &[f64]) -> bool {
        let same = |a: &[f64], b: &[f64]| {
            a.len() == b.len() && a.iter().zip(b).all(|(u, v)| u.to_bits() == v.to_bits())
        };
        let k = &self.key;
        k.valid
            && k.side == side
            && k.frozen == frozen
            && (!frozen || k.bits == self.bits)
            && same(&k.p, p)
            && (!self.info.dynamic || (k.t.to_bits() == t.to_bits() && same(&k.x, x)))
    }

    /// Solves at (t, x, θ) (frozen by `sw` when the layer has bits) and, with `derivs`,
    /// differentiates on `side`; writes u* into `u` and ∂u*/∂w into column w of the rows of
    /// `du` (n + p + 1 columns). `fill` writes the data and, when asked, their Jacobian.
    /// Cached: at the same point nothing is recomputed, and a solve without derivatives is
    /// reused when they are asked for later.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn evaluate(
        &mut self,
        t: f64,
        x: &[f64],
        p: &[f64],
        sw: Option<&Switches>,
        derivs: bool,
        side: Side,
        fill: impl FnOnce(&mut [f64], Option<&mut [f64]>),
        u: &mut [f64],
        du: &mut [f64],
    ) -> bool {
        let frozen = self.load_bits(sw);
        let cached = self.cached(frozen, side, t, x, p);
        if cached && (self.key.derivs || !derivs || self.failure.is_some()) {
            return self.failure.is_none();
        }
        fill(&mut self.flat, derivs.then_some(&mut self.jac[..]));
        let nw = du.len() / u.len().max(1);
        let solved = if cached { Ok(()) } else { self.solve(frozen) };
        let result = solved.and_then(|()| match derivs {
            true => self.differentiate(side, nw, du),
            false => Ok(()),
        });
        let ok = match result {
            Ok(()) => {
                u.copy_from_slice(self.solver.u().as_slice());
                self.failure = None;
                true
            }
            Err(e) => {
                u.fill(f64::NAN);
                du.fill(f64::NAN);
                self.failure = Some(e);
                false
            }
        };
        let key = &mut self.key;
        key.valid = true;
        key.derivs = derivs;
        key.side = side;
        key.frozen = frozen;
        key.bits.copy_from_slice(&self.bits);
        key.t = t;
        copy_prefix(&mut key.x, x);
        copy_prefix(&mut key.p, p);
        ok
    }

    /// Solves at the data in `flat`, on the frozen set `bits` if `frozen`.
    fn solve(&mut self, frozen: bool) -> Result<(), QpError> {
        let flat = &self.flat;
        unflatten(&mut self.data, |d| flat[d]);
        if frozen {
            let bits = &self.bits;
            self.solver.solve_frozen(&self.data, |i| bits[i])
        } else {
            self.solver.solve(&self.data)
        }
    }

    /// The parts that derivatives along the data columns need, and beside them A and the
    /// u* scratch (borrowed apart).
    fn directions(&mut self) -> (Directions<'_>, &DMatrix<f64>, &mut DVector<f64>) {
        let d = Directions {
            solver: &mut self.solver,
            jac: &self.jac,
            dir: &mut self.dir,
            du: &mut self.du,
            dm: &mut self.dm,
        };
        (d, &self.data.a, &mut self.u_star)
    }

    /// ∂u*/∂w into column w of the rows of `du`.
    fn differentiate(&mut self, side: Side, nw: usize, du: &mut [f64]) -> Result<(), QpError> {
        self.directions().0.each(side, nw, |w, col| match col {
            None => du.iter_mut().skip(w).step_by(nw).for_each(|v| *v = 0.0),
            Some((dw, _, _)) => {
                for (k, &v) in dw.iter().enumerate() {
                    du[k * nw + w] = v;
                }
            }
        })
    }

    /// The piece analysis of a flow's evaluation at (t, x, θ) under the bits of `sw` (see
    /// [`super::QpBank::flow_pieces`]). A constraint weakly active on the frozen piece
    /// ([`QpSolver::piece_weak`]) is a persistent kink when it stays weakly active along the
    /// flow, (dx, dθ, dt) = (f, 0, 1): the derivative problem along that direction leaves its
    /// slack and multiplier both zero too (a crossing moves one of them, and its new piece is
    /// the one the frozen bits already hold). For each persistent constraint i, `persistent(i)`
    /// is called; with `s` (the columns of S, column-major n × ncols), for each column j the
    /// one-sided derivative along (S_j, e_j, 0) on `side` chooses whether i is held, and
    /// `on_piece(j, bit, held)` is called with i's switch bit. Returns whether some
    /// constraint is a persistent kink. Leaves the cache invalid when it took derivatives.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn flow_pieces(
        &mut self,
        (t, x, p): (f64, &[f64], &[f64]),
        sw: &Switches,
        side: Side,
        f: &[f64],
        s: Option<&[f64]>,
        mut fill: impl FnMut(&mut [f64], Option<&mut [f64]>),
        mut persistent: impl FnMut(usize),
        mut on_piece: impl FnMut(usize, usize, bool),
    ) -> Result<bool, QpError> {
        let Some(first) = self.info.switches else {
            return Ok(false);
        };
        self.load_bits(Some(sw));
        if !(self.cached(true, self.key.side, t, x, p) && self.failure.is_none()) {
            self.key.valid = false;
            fill(&mut self.flat, None);
            self.solve(true)?;
        }
        if !self.solver.piece_weak(&mut self.weak) {
            return Ok(false);
        }
        // The derivatives below replace the solve's working set.
        self.key.valid = false;
        fill(&mut self.flat, Some(&mut self.jac[..]));
        let (n, nw) = (x.len(), x.len() + p.len() + 1);
        mix(&mut self.dir, &self.jac, nw, f, &[(nw - 1, 1.0)]);
        self.derive_on_piece(Side::Right)?;
        std::mem::swap(&mut self.weak, &mut self.again);
        if !self.weak.iter().any(|&w| w) {
            return Ok(false);
        }
        self.weak
            .iter()
            .enumerate()
            .filter(|(_, &w)| w)
            .for_each(|(i, _)| persistent(i));
        let Some(s) = s else {
            return Ok(true);
        };
        for j in 0..s.len() / n.max(1) {
            mix(
                &mut self.dir,
                &self.jac,
                nw,
                &s[j * n..(j + 1) * n],
                &[(n + j, 1.0)],
            );
            self.derive_on_piece(side)?;
            let le = (0..self.weak.len()).filter(|&i| self.info.kinds[i] == ConstraintKind::Le);
            for (bit, i) in le.enumerate() {
                if self.weak[i] {
                    on_piece(j, first + bit, self.piece[i]);
                }
            }
        }
        Ok(true)
    }

    /// The one-sided derivative along `self.dir` with the constraints `self.weak` marks as
    /// inequalities ([`QpSolver::directional_on_piece`]): the piece it follows into
    /// `self.piece`, which weak constraints stay weak along it into `self.again`.
    fn derive_on_piece(&mut self, side: Side) -> Result<(), QpError> {
        let (du, dm) = (&mut self.du, &mut self.dm);
        let (piece, again) = (&mut self.piece, &mut self.again);
        (self.solver).directional_on_piece(&self.dir, side, &self.weak, du, dm, piece, again)
    }

    /// Pins pointwise evaluations to the active set `active` (m entries; `None` unpins).
    pub(super) fn pin(&mut self, active: Option<&[bool]>) {
        self.pinned = active.is_some();
        if let Some(a) = active {
            self.pin_bits.copy_from_slice(a);
        }
    }

    /// At a pointwise solve at (t, x, θ) with a weakly active constraint: the active set of
    /// the smooth piece whose derivative is the one-sided derivative (on `side`) along the
    /// direction dx of the state, e_j of the params and dt of time, into `active`; false
    /// (and `active` untouched) away from a kink. Leaves the cache invalid when it took
    /// the derivative.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn pointwise_piece(
        &mut self,
        (t, x, p): (f64, &[f64], &[f64]),
        (dx, j, dt): (&[f64], usize, f64),
        side: Side,
        mut fill: impl FnMut(&mut [f64], Option<&mut [f64]>),
        active: &mut [bool],
    ) -> Result<bool, QpError> {
        self.pinned = false;
        self.load_bits(None);
        if !(self.cached(false, self.key.side, t, x, p) && self.failure.is_none()) {
            self.key.valid = false;
            fill(&mut self.flat, None);
            self.solve(false)?;
        }
        if !self.solver.is_kink() {
            return Ok(false);
        }
        self.key.valid = false;
        fill(&mut self.flat, Some(&mut self.jac[..]));
        let (n, nw) = (x.len(), x.len() + p.len() + 1);
        mix(
            &mut self.dir,
            &self.jac,
            nw,
            dx,
            &[(n + j, 1.0), (nw - 1, dt)],
        );
        for (w, s) in self.weak.iter_mut().zip(self.solver.status()) {
            *w = *s == ConstraintStatus::WeaklyActive;
        }
        self.derive_on_piece(side)?;
        active.copy_from_slice(&self.piece);
        Ok(true)
    }

    /// σᵢ = sᵢ + μᵢ of the last (pointwise) solve: the switching function of inequality i.
    pub(super) fn switch_value(&self, i: usize) -> f64 {
        self.solver.slacks()[i] + self.solver.multipliers()[i]
    }

    /// After a pointwise solve at a point: σᵢ and its gradient (∂/∂x, ∂/∂θ, ∂/∂t in
    /// `grad`) on the piece constraint i is on — the set of the active and weakly active
    /// constraints frozen, and σᵢ = μᵢ if i is in it, sᵢ otherwise; a weakly active i is in
    /// it when σᵢ ≥ 0. `fill` writes the data
    /// and their Jacobian. Leaves the solver frozen: the cache is dropped.
    pub(super) fn switch_grad(
        &mut self,
        i: usize,
        fill: impl FnOnce(&mut [f64], Option<&mut [f64]>),
        grad: &mut [f64],
    ) -> Result<f64, QpError> {
        let value = self.switch_value(i);
        // A weakly active constraint is on the piece its σᵢ's sign says: μᵢ's when σᵢ ≥ 0,
        // sᵢ's when σᵢ < 0 (a slack of −10⁻¹³ within the tolerance), so that the rate
        // agrees with the value it belongs to (μᵢ's rate is the Hessian's scale times sᵢ's:
        // the other piece's would be off by that factor wherever σᵢ is not zero).
        let held = match self.solver.status()[i] {
            ConstraintStatus::Active => true,
            ConstraintStatus::Inactive => false,
            ConstraintStatus::WeaklyActive => value >= 0.0,
        };
        for (bit, s) in self.bits.iter_mut().zip(self.solver.status()) {
            *bit = *s != ConstraintStatus::Inactive;
        }
        self.bits[i] = held;
        self.key.valid = false;
        fill(&mut self.flat, Some(&mut self.jac[..]));
        self.solve(true)?;
        let (mut d, a, u_star) = self.directions();
        u_star.copy_from(d.solver.u());
        d.each(Side::Right, grad.len(), |w, col| {
            grad[w] = match col {
                None => 0.0,
                Some((_, dm, _)) if held => dm[i],
                // dsᵢ = aᵢᵀdu + daᵢᵀu − dbᵢ.
                Some((du, _, dir)) => {
                    a.row(i).iter().zip(du).map(|(x, y)| x * y).sum::<f64>()
                        + dir.a.row(i).tr_dot(u_star)
                        - dir.b[i]
                }
            };
        })?;
        Ok(value)
    }
}

/// The borrowed parts of a layer that derivatives along its data columns need.
struct Directions<'a> {
    solver: &'a mut QpSolver,
    jac: &'a [f64],
    dir: &'a mut QpData,
    du: &'a mut [f64],
    dm: &'a mut [f64],
}

impl Directions<'_> {
    /// Calls `per_column(w, Some((du, dμ, direction)))` with the derivative of u* and μ
    /// along every non-zero column w of the data Jacobian, `per_column(w, None)` for a zero
    /// column.
    fn each(
        &mut self,
        side: Side,
        nw: usize,
        mut per_column: impl FnMut(usize, Option<(&[f64], &[f64], &QpData)>),
    ) -> Result<(), QpError> {
        let len = self.jac.len() / nw.max(1);
        for w in 0..nw {
            let jac = self.jac;
            if (0..len).all(|d| jac[d * nw + w] == 0.0) {
                per_column(w, None);
                continue;
            }
            unflatten(self.dir, |d| jac[d * nw + w]);
            self.solver.directional(self.dir, side, self.du, self.dm)?;
            per_column(w, Some((self.du, self.dm, self.dir)));
        }
        Ok(())
    }
}

/// The data direction Σ_k ∂data/∂x_k · dx_k + Σ ∂data/∂w_e · c_e over `extra` = [(w_e, c_e)],
/// from the Jacobian `jac` (slot d·nw + w): a state direction dx plus other columns.
fn mix(dir: &mut QpData, jac: &[f64], nw: usize, dx: &[f64], extra: &[(usize, f64)]) {
    unflatten(dir, |d| {
        let row = &jac[d * nw..d * nw + dx.len()];
        let along_x: f64 = row.iter().zip(dx).map(|(a, b)| a * b).sum();
        along_x + extra.iter().map(|&(w, c)| jac[d * nw + w] * c).sum::<f64>()
    });
}

/// Fills `data` from slot values: H (row-major v×v), c (v), A (row-major m×v), b (m).
fn unflatten(data: &mut QpData, slot: impl Fn(usize) -> f64) {
    let (v, m) = (data.c.len(), data.b.len());
    for i in 0..v {
        for j in 0..v {
            data.h[(i, j)] = slot(i * v + j);
        }
        data.c[i] = slot(v * v + i);
    }
    let off = v * v + v;
    for i in 0..m {
        for j in 0..v {
            data.a[(i, j)] = slot(off + i * v + j);
        }
        data.b[i] = slot(off + m * v + i);
    }
}

fn copy_prefix(dst: &mut [f64], src: &[f64]) {
    let k = dst.len().min(src.len());
    dst[..k].copy_from_slice(&src[..k]);
}
