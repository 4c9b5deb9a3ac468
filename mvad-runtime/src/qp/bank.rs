//! [`QpBank`]: the qp layers of one model, evaluated at a point for both doors.
//!
//! A model's kernels read the qp solutions u* and their derivatives ∂u*/∂(x, θ, t) as
//! inputs. Before such a kernel runs, the back end (generated code or the interpreter)
//! calls [`QpBank::evaluate`] with a closure that writes each qp's data — the slots
//! H (row-major), c, A (row-major), b — and, when derivatives are wanted, their Jacobian
//! ∂data/∂(x, θ, t) (slot d·(n + p + 1) + w). The bank solves each qp
//! ([`QpSolver::solve`]), then for each column w whose data direction is not zero takes the
//! derivative along it ([`QpSolver::directional`], on the side [`QpBank::set_side`] chose),
//! and exposes u* and ∂u*/∂w as flat slices ([`QpBank::u`], [`QpBank::du`]).
//!
//! Results are cached per qp by the point they were computed at (θ alone for a static qp),
//! so a back end that evaluates several kernels at one point solves once. Every buffer is
//! allocated by [`QpBank::new`]; an evaluation allocates nothing. A qp that fails leaves NaN
//! in its entries and its error in [`QpBank::failure`].
//!
//! A qp that a flow reads has switch bits (`QpLayerInfo::switches`): evaluations with the
//! run's frozen bits solve on the active set they hold, and [`QpBank::switch_value`] /
//! [`QpBank::switch_grad`] are its switching functions (see `layer.rs`).

use super::layer::Layer;
#[cfg(doc)]
use super::QpSolver;
use super::{ConstraintKind, ConstraintStatus, QpError, QpLayerInfo, QpOptions, Side};
use crate::model::Switches;

/// A qp's solution at one point: what `grad --json` reports under `"qp"`.
#[derive(Clone, Debug, PartialEq)]
pub struct QpState {
    /// u*, one value per variable.
    pub u: Vec<f64>,
    /// μ, one per constraint (zero when inactive).
    pub multipliers: Vec<f64>,
    /// Each constraint's status.
    pub status: Vec<ConstraintStatus>,
}

impl QpState {
    /// The constraints with zero slack (active or weakly active), in declaration order.
    pub fn active(&self) -> Vec<usize> {
        self.indices(|s| s != ConstraintStatus::Inactive)
    }

    /// The weakly active constraints: kinks of the solution map.
    pub fn weakly_active(&self) -> Vec<usize> {
        self.indices(|s| s == ConstraintStatus::WeaklyActive)
    }

    fn indices(&self, keep: impl Fn(ConstraintStatus) -> bool) -> Vec<usize> {
        (0..self.status.len())
            .filter(|&i| keep(self.status[i]))
            .collect()
    }
}

/// A constraint of a qp read by a flow that was weakly active *along* the flow (not just
/// where its switching function crosses zero): a kink of the cost in θ, met between `first`
/// and `last` (the times of the evaluations that found it).
#[derive(Clone, Debug, PartialEq)]
pub struct QpFlowKink {
    /// The qp's index.
    pub qp: usize,
    /// The constraint's index in the qp.
    pub constraint: usize,
    /// The earliest time it was met.
    pub first: f64,
    /// The latest time it was met.
    pub last: f64,
}

/// The qp layers of a model (see the module documentation).
#[derive(Clone, Debug)]
pub struct QpBank {
    layers: Vec<Layer>,
    n: usize,
    p: usize,
    u: Vec<f64>,
    du: Vec<f64>,
    side: Side,
    /// The switch index of the first qp switch bit, and the (qp, constraint) of each.
    switch_base: usize,
    switch_owner: Vec<(usize, usize)>,
    /// Scratch: ∂σ/∂(x, θ, t) of a switching function.
    grad: Vec<f64>,
    /// The persistent kinks [`QpBank::flow_pieces`] met since [`QpBank::clear_flow_kinks`].
    flow_kinks: Vec<QpFlowKink>,
}

impl QpBank {
    /// A bank for the given layers of a model with n states and p params; allocates every
    /// buffer.
    pub fn new(layers: Vec<QpLayerInfo>, n: usize, p: usize, opts: QpOptions) -> Self {
        let mut offset = 0;
        let mut switch_owner = Vec::new();
        let mut switch_base = usize::MAX;
        for (q, info) in layers.iter().enumerate() {
            if let Some(first) = info.switches {
                switch_base = switch_base.min(first);
                let le = (0..info.kinds.len()).filter(|&i| info.kinds[i] == ConstraintKind::Le);
                for (k, i) in le.enumerate() {
                    switch_owner.push((first + k, q, i));
                }
            }
        }
        switch_owner.sort_unstable();
        let switch_owner: Vec<(usize, usize)> =
            switch_owner.into_iter().map(|(_, q, i)| (q, i)).collect();
        let layers: Vec<Layer> = layers
            .into_iter()
            .map(|info| {
                let v = info.vars.len();
                let layer = Layer::new(info, offset, n, p, opts);
                offset += v;
                layer
            })
            .collect();
        let nw = n + p + 1;
        QpBank {
            layers,
            n,
            p,
            u: vec![0.0; offset],
            du: vec![0.0; offset * nw],
            side: Side::Right,
            switch_base: if switch_owner.is_empty() {
                0
            } else {
                switch_base
            },
            switch_owner,
            grad: vec![0.0; nw],
            flow_kinks: Vec::new(),
        }
    }

    /// The layers' static descriptions.
    pub fn infos(&self) -> impl Iterator<Item = &QpLayerInfo> {
        self.layers.iter().map(|l| &l.info)
    }

    /// Which one-sided derivative [`QpBank::evaluate`] gives at a kink from now on.
    pub fn set_side(&mut self, side: Side) {
        self.side = side;
    }

    /// u*, all qps' variables flattened in declaration order.
    pub fn u(&self) -> &[f64] {
        &self.u
    }

    /// ∂u*/∂(x, θ, t), row-major: row k (a variable), column i for x_i, n + j for θ_j,
    /// n + p for t.
    pub fn du(&self) -> &[f64] {
        &self.du
    }

    /// The last evaluation's failure, if a qp could not be solved: (qp index, error).
    pub fn failure(&self) -> Option<(usize, &QpError)> {
        self.layers
            .iter()
            .enumerate()
            .find_map(|(q, l)| l.failure.as_ref().map(|e| (q, e)))
    }

    /// Solves every qp at (t, x, θ) — on the active sets the bits `frozen` hold for the qps
    /// that have switch bits, when given (a flow's evaluation) — and, with `derivs`,
    /// differentiates it along each column of its data Jacobian. `fill(q, data, jac)` writes
    /// qp q's data slots and, when `jac` is given, their Jacobian. Returns false when a qp
    /// failed (its entries are NaN).
    pub fn evaluate(
        &mut self,
        t: f64,
        x: &[f64],
        p: &[f64],
        frozen: Option<&Switches>,
        derivs: bool,
        mut fill: impl FnMut(usize, &mut [f64], Option<&mut [f64]>),
    ) -> bool {
        let (side, nw) = (self.side, self.n + self.p + 1);
        let mut ok = true;
        for (q, layer) in self.layers.iter_mut().enumerate() {
            let rows = layer.info.vars.len();
            let u = &mut self.u[layer.offset..layer.offset + rows];
            let du = &mut self.du[layer.offset * nw..(layer.offset + rows) * nw];
            let fill_q = |data: &mut [f64], jac: Option<&mut [f64]>| fill(q, data, jac);
            ok &= layer.evaluate(t, x, p, frozen, derivs, side, fill_q, u, du);
        }
        ok
    }

    /// The one-sided derivative of a flow that reads qps of the state, where one of them is
    /// weakly active along the flow (see `Layer::flow_pieces`): at a point (t, x, θ) of the
    /// flow with frozen bits `sw` and rate `f`, each qp with switch bits is checked for a
    /// constraint whose slack and multiplier are both zero at the point and stay zero along
    /// the flow (a persistent kink: logged, see [`QpBank::flow_kinks`]). There the
    /// derivative of the solution is one-sided and not linear in the direction: with `s`
    /// (S = ∂x/∂θ column-major, n × p), `pieces[j]` receives the bits of the smooth piece
    /// whose derivative is the one-sided derivative along column j's direction
    /// (dx, dθ) = (S_j, e_j), on the side [`QpBank::set_side`] chose — `sw` with the kink's
    /// bits set as that derivative holds them. Returns whether there is such a kink
    /// (`pieces` is untouched otherwise); a qp that fails is `Err` (and its
    /// [`QpBank::failure`]). Allocates nothing but a log entry per new kink.
    #[allow(clippy::too_many_arguments)]
    pub fn flow_pieces(
        &mut self,
        t: f64,
        x: &[f64],
        p: &[f64],
        sw: &Switches,
        f: &[f64],
        s: Option<&[f64]>,
        pieces: &mut [Switches],
        mut fill: impl FnMut(usize, &mut [f64], Option<&mut [f64]>),
    ) -> Result<bool, (usize, QpError)> {
        let side = self.side;
        let ncols = s.map_or(0, |s| s.len() / x.len().max(1));
        let mut any = false;
        let log = &mut self.flow_kinks;
        for (q, layer) in self.layers.iter_mut().enumerate() {
            let mut fresh = !any;
            let found = layer.flow_pieces(
                (t, x, p),
                sw,
                side,
                f,
                s,
                |data, jac| fill(q, data, jac),
                |i| log_kink(log, q, i, t),
                |j, bit, held| {
                    if fresh {
                        pieces[..ncols].iter_mut().for_each(|pc| pc.clone_from(sw));
                        fresh = false;
                    }
                    pieces[j].set(bit, held);
                },
            );
            match found {
                Ok(found) => any |= found,
                Err(e) => {
                    layer.failure = Some(e.clone());
                    return Err((q, e));
                }
            }
        }
        Ok(any)
    }

    /// Pins qp q: its pointwise evaluations (not a flow's, whose bits freeze it) solve on
    /// the active set `active` (m entries, [`QpSolver::solve_frozen`]) until `None` unpins
    /// it — the smooth piece a one-sided derivative follows ([`QpBank::pointwise_piece`]).
    pub fn pin(&mut self, q: usize, active: Option<&[bool]>) {
        if let Some(layer) = self.layers.get_mut(q) {
            layer.pin(active);
        }
    }

    /// Where qp q, solved pointwise at (t, x, θ), has a weakly active constraint: writes
    /// into `active` (m entries) the active set of the piece whose derivative is the
    /// one-sided derivative (on the side [`QpBank::set_side`] chose) along the direction dx
    /// of the state, e_j of the params and dt of time, and returns true; false away from a
    /// kink. Unpins q. A qp that fails is `Err` (and its [`QpBank::failure`]).
    #[allow(clippy::too_many_arguments)]
    pub fn pointwise_piece(
        &mut self,
        q: usize,
        (t, x, p): (f64, &[f64], &[f64]),
        (dx, j, dt): (&[f64], usize, f64),
        active: &mut [bool],
        mut fill: impl FnMut(usize, &mut [f64], Option<&mut [f64]>),
    ) -> Result<bool, QpError> {
        let side = self.side;
        let Some(layer) = self.layers.get_mut(q) else {
            return Ok(false);
        };
        let fill_q = |data: &mut [f64], jac: Option<&mut [f64]>| fill(q, data, jac);
        let found = layer.pointwise_piece((t, x, p), (dx, j, dt), side, fill_q, active);
        if let Err(e) = &found {
            layer.failure = Some(e.clone());
        }
        found
    }

    /// The persistent kinks met by [`QpBank::flow_pieces`] since the last
    /// [`QpBank::clear_flow_kinks`], in the order first met.
    pub fn flow_kinks(&self) -> &[QpFlowKink] {
        &self.flow_kinks
    }

    /// Forgets the persistent kinks met so far (at the start of a run).
    pub fn clear_flow_kinks(&mut self) {
        self.flow_kinks.clear();
    }

    /// The qp and constraint of the model's switch index j, if it is a qp switch bit.
    pub fn switch_owner(&self, j: usize) -> Option<(usize, usize)> {
        j.checked_sub(self.switch_base)
            .and_then(|k| self.switch_owner.get(k))
            .copied()
    }

    /// The switching function σ = sᵢ + μᵢ of qp switch j at (t, x, θ) (pointwise solve):
    /// negative while constraint i is inactive, positive while it is active; NaN if j is not
    /// a qp switch or the qp fails.
    pub fn switch_value(
        &mut self,
        j: usize,
        t: f64,
        x: &[f64],
        p: &[f64],
        fill: impl FnMut(usize, &mut [f64], Option<&mut [f64]>),
    ) -> f64 {
        let Some((q, i)) = self.switch_owner(j) else {
            return f64::NAN;
        };
        if !self.evaluate(t, x, p, None, false, fill) {
            return f64::NAN;
        }
        self.layers[q].switch_value(i)
    }

    /// σ of qp switch j and its gradient: ∂σ/∂x into `gx`, ∂σ/∂θ into `gp`; returns
    /// (σ, ∂σ/∂t). NaN everywhere if j is not a qp switch or the qp fails.
    #[allow(clippy::too_many_arguments)]
    pub fn switch_grad(
        &mut self,
        j: usize,
        t: f64,
        x: &[f64],
        p: &[f64],
        mut fill: impl FnMut(usize, &mut [f64], Option<&mut [f64]>),
        gx: &mut [f64],
        gp: &mut [f64],
    ) -> (f64, f64) {
        let nan = |gx: &mut [f64], gp: &mut [f64]| {
            gx.fill(f64::NAN);
            gp.fill(f64::NAN);
            (f64::NAN, f64::NAN)
        };
        let Some((q, i)) = self.switch_owner(j) else {
            return nan(gx, gp);
        };
        if !self.evaluate(t, x, p, None, false, &mut fill) {
            return nan(gx, gp);
        }
        let fill_q = |data: &mut [f64], jac: Option<&mut [f64]>| fill(q, data, jac);
        match self.layers[q].switch_grad(i, fill_q, &mut self.grad) {
            Ok(value) => {
                let (n, np) = (self.n, self.p);
                copy_prefix(gx, &self.grad[..n]);
                copy_prefix(gp, &self.grad[n..n + np]);
                (value, self.grad[n + np])
            }
            Err(e) => {
                self.layers[q].failure = Some(e);
                nan(gx, gp)
            }
        }
    }

    /// The first weakly active constraint at the last evaluation, as (qp, constraint): where
    /// the solution map has a kink. Allocates nothing.
    pub fn kink(&self) -> Option<(usize, usize)> {
        self.layers.iter().enumerate().find_map(|(q, l)| {
            if l.failure.is_some() || !l.solver.is_kink() {
                return None;
            }
            l.solver.weakly_active().next().map(|i| (q, i))
        })
    }

    /// Every qp's state at the last evaluation (solution, multipliers, statuses), or the
    /// first failure.
    pub fn states(&self) -> Result<Vec<QpState>, (usize, QpError)> {
        if let Some((q, e)) = self.failure() {
            return Err((q, e.clone()));
        }
        Ok(self
            .layers
            .iter()
            .map(|l| QpState {
                u: l.solver.u().iter().copied().collect(),
                multipliers: l.solver.multipliers().to_vec(),
                status: l.solver.status().to_vec(),
            })
            .collect())
    }
}

/// Records that constraint i of qp q is a persistent kink at time t.
fn log_kink(log: &mut Vec<QpFlowKink>, q: usize, i: usize, t: f64) {
    match log.iter_mut().find(|k| k.qp == q && k.constraint == i) {
        Some(k) => {
            k.first = k.first.min(t);
            k.last = k.last.max(t);
        }
        None => log.push(QpFlowKink {
            qp: q,
            constraint: i,
            first: t,
            last: t,
        }),
    }
}

fn copy_prefix(dst: &mut [f64], src: &[f64]) {
    let k = dst.len().min(src.len());
    dst[..k].copy_from_slice(&src[..k]);
}
