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

use super::{ConstraintKind, ConstraintStatus, QpData, QpError, QpOptions, QpSolver, Side};

/// Static description of one qp layer.
#[derive(Clone, Debug, PartialEq)]
pub struct QpLayerInfo {
    /// The qp's name.
    pub name: String,
    /// Its variables' names (the order of u).
    pub vars: Vec<String>,
    /// Its constraints' kinds, in declaration order.
    pub kinds: Vec<ConstraintKind>,
    /// Whether its data depend on states or t (solved along the trajectory) rather than only
    /// on θ.
    pub dynamic: bool,
}

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

/// The point a cached result belongs to.
#[derive(Clone, Debug)]
struct Key {
    /// Whether the solution at the point is cached.
    valid: bool,
    /// Whether its derivatives are too.
    derivs: bool,
    side: Side,
    t: f64,
    x: Vec<f64>,
    p: Vec<f64>,
}

impl Key {
    /// Whether (t, x, θ) on `side` is the cached point (t and x ignored when static).
    fn matches(&self, dynamic: bool, side: Side, t: f64, x: &[f64], p: &[f64]) -> bool {
        let same = |a: &[f64], b: &[f64]| {
            a.len() == b.len() && a.iter().zip(b).all(|(u, v)| u.to_bits() == v.to_bits())
        };
        self.valid
            && self.side == side
            && same(&self.p, p)
            && (!dynamic || (self.t.to_bits() == t.to_bits() && same(&self.x, x)))
    }
}

/// One qp layer with its solver and buffers.
#[derive(Clone, Debug)]
struct Layer {
    info: QpLayerInfo,
    offset: usize,
    solver: QpSolver,
    data: QpData,
    /// The data slots as the kernel writes them.
    flat: Vec<f64>,
    /// ∂data/∂(x, θ, t), slot d·(n + p + 1) + w.
    jac: Vec<f64>,
    /// Scratch: one direction of the data.
    dir: QpData,
    du: Vec<f64>,
    dm: Vec<f64>,
    key: Key,
    failure: Option<QpError>,
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
}

impl QpBank {
    /// A bank for the given layers of a model with n states and p params; allocates every
    /// buffer.
    pub fn new(layers: Vec<QpLayerInfo>, n: usize, p: usize, opts: QpOptions) -> Self {
        let mut offset = 0;
        let nw = n + p + 1;
        let layers: Vec<Layer> = layers
            .into_iter()
            .map(|info| {
                let (v, m) = (info.vars.len(), info.kinds.len());
                let len = v * v + v + m * v + m;
                let layer = Layer {
                    offset,
                    solver: QpSolver::new(v, &info.kinds, opts),
                    data: QpData::zeros(v, m),
                    flat: vec![0.0; len],
                    jac: vec![0.0; len * nw],
                    dir: QpData::zeros(v, m),
                    du: vec![0.0; v],
                    dm: vec![0.0; m],
                    key: Key {
                        valid: false,
                        derivs: false,
                        side: Side::Right,
                        t: 0.0,
                        x: vec![0.0; n],
                        p: vec![0.0; p],
                    },
                    failure: None,
                    info,
                };
                offset += v;
                layer
            })
            .collect();
        QpBank {
            layers,
            n,
            p,
            u: vec![0.0; offset],
            du: vec![0.0; offset * nw],
            side: Side::Right,
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

    /// Solves every qp at (t, x, θ) and, with `derivs`, differentiates it along each
    /// column of its data Jacobian. `fill(q, data, jac)` writes qp q's data slots and, when
    /// `jac` is given, their Jacobian. Returns false when a qp failed (its entries are NaN).
    pub fn evaluate(
        &mut self,
        t: f64,
        x: &[f64],
        p: &[f64],
        derivs: bool,
        mut fill: impl FnMut(usize, &mut [f64], Option<&mut [f64]>),
    ) -> bool {
        let (side, nw) = (self.side, self.n + self.p + 1);
        let mut ok = true;
        for (q, layer) in self.layers.iter_mut().enumerate() {
            let dynamic = layer.info.dynamic;
            let cached = layer.key.matches(dynamic, side, t, x, p);
            if cached && (layer.key.derivs || !derivs) {
                ok &= layer.failure.is_none();
                continue;
            }
            let rows = layer.info.vars.len();
            let u = &mut self.u[layer.offset..layer.offset + rows];
            let du = &mut self.du[layer.offset * nw..(layer.offset + rows) * nw];
            // At a cached point only the derivatives are missing: no second solve.
            let solve = !cached;
            fill(q, &mut layer.flat, derivs.then_some(&mut layer.jac[..]));
            let result = if solve { layer.solve() } else { Ok(()) }.and_then(|()| match derivs {
                true => layer.differentiate(side, nw, du),
                false => Ok(()),
            });
            match result {
                Ok(()) => {
                    u.copy_from_slice(layer.solver.u().as_slice());
                    layer.failure = None;
                }
                Err(e) => {
                    u.fill(f64::NAN);
                    du.fill(f64::NAN);
                    layer.failure = Some(e);
                    ok = false;
                }
            }
            layer.key.valid = true;
            layer.key.derivs = derivs;
            layer.key.side = side;
            layer.key.t = t;
            copy_prefix(&mut layer.key.x, x);
            copy_prefix(&mut layer.key.p, p);
        }
        ok
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

impl Layer {
    /// Solves at the data in `flat`.
    fn solve(&mut self) -> Result<(), QpError> {
        let flat = &self.flat;
        unflatten(&mut self.data, |d| flat[d]);
        self.solver.solve(&self.data)
    }

    /// Writes ∂u*/∂w into column w of the rows of `du` (n + p + 1 columns) for every
    /// column of `jac`, on `side`.
    fn differentiate(&mut self, side: Side, nw: usize, du: &mut [f64]) -> Result<(), QpError> {
        let len = self.flat.len();
        for w in 0..nw {
            let jac = &self.jac;
            if (0..len).all(|d| jac[d * nw + w] == 0.0) {
                du.iter_mut().skip(w).step_by(nw).for_each(|v| *v = 0.0);
                continue;
            }
            unflatten(&mut self.dir, |d| jac[d * nw + w]);
            self.solver
                .directional(&self.dir, side, &mut self.du, &mut self.dm)?;
            for (k, &v) in self.du.iter().enumerate() {
                du[k * nw + w] = v;
            }
        }
        Ok(())
    }
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
