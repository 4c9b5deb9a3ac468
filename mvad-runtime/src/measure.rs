//! The parameter derivative of an observable's trajectory as a measure.
//!
//! For an observable y = h(t, x, θ) the derivative d y/dθ, taken in the sense of
//! distributions on [0, T], is the measure
//!
//! ```text
//!   μ_y = (h_x S(t) + h_θ) dt + Σ_k α_k δ(t − t_k),   α_k = −J_k t_k',   J_k = y(t_k⁺) − y(t_k⁻)
//! ```
//!
//! (one such measure per parameter): a density on the smooth segments plus Dirac atoms at
//! the events and at the switch crossings of kinks where y jumps (`sign`, `if` in an
//! observable: J = h(sw⁺) − h(sw⁻) at the continuous x(t_c), t_c' the crossing-time
//! sensitivity; a continuous kink, `max`, `abs`, has J ≈ 0, an atom at rounding level).
//! A horizon T(θ) that moves with θ (`horizon EXPR` of params) ends y's support there:
//! t ↦ y(t)·𝟙(t < T) drops from y(T⁻) to 0 at T, J = −y(T⁻), so the measure has the atom
//! α_T = y(T⁻) T' at T. Pairing with a test function gives ⟨μ_y, φ⟩ = d/dθ ∫₀ᵀ φ(t) y(t) dt
//! for φ independent of θ (with a moving horizon, φ continuous at T). The density is evaluated at the
//! recorded nodes of every step (see [`Trajectory`]) under the frozen switch bits of the
//! step's segment (a node at a crossing takes the branch of its own step: no step straddles
//! a kink of h) and interpolated with the same degree-4 polynomial; pairings integrate φ·density step by step with adaptive Gauss–Legendre
//! quadrature (so the result is exact up to the dense output's accuracy for any φ that is
//! smooth on each step) and add Σ_k φ(t_k) α_k.

use crate::error::SolveError;
use crate::model::{At, HybridModel, ModelAlloc};
use crate::reduce::{aitken_iterated, integrate_adaptive};
use crate::solution::{DiagnosticKind, Solution, Trajectory, TRAJ_NODES};
use nalgebra::{Const, DefaultAllocator, Dim, OVector};

/// μ_y for one observable, one density and one set of atoms per parameter.
#[derive(Clone, Debug, PartialEq)]
pub struct Measure {
    /// Index of the observable.
    pub observable: usize,
    /// Its name.
    pub name: String,
    /// Number of parameters p (entries of every density value and atom).
    pub nparams: usize,
    /// Start times of the recorded steps.
    t0: Vec<f64>,
    /// End times of the recorded steps.
    t1: Vec<f64>,
    /// Density at the nodes: per step `TRAJ_NODES × p`.
    nodes: Vec<f64>,
    /// Atoms (t_k, α_k per parameter), in time order.
    pub atoms: Vec<(f64, Vec<f64>)>,
    /// Where each atom of `atoms` comes from (same order).
    pub origins: Vec<AtomOrigin>,
}

/// What placed an atom of a [`Measure`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AtomOrigin {
    /// A user event: its entry `index` in [`Solution::events`] and the jump J of y there.
    Event {
        /// Position in the event table.
        index: usize,
        /// J = y(t_k⁺) − y(t_k⁻).
        jump: f64,
    },
    /// A switch crossing of kink `switch` where y jumps by `jump` (`sign`, `if`).
    Switch {
        /// Index j of the switching function.
        switch: usize,
        /// J = h(sw⁺) − h(sw⁻) at x(t_c).
        jump: f64,
    },
    /// The effective atom of a Zeno tail at the accumulation time.
    ZenoTail,
    /// The end of the support at a horizon T(θ) that moves with θ: J = −y(T⁻), α = y(T⁻) T'.
    Horizon {
        /// J = −y(T⁻).
        jump: f64,
    },
}

/// Builds μ_y for observable `observable` from a solution run with `Options::record` and
/// sensitivities.
pub fn measure<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    solution: &Solution,
    observable: usize,
) -> Result<Measure, SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let info = model.info();
    let nobs = info.nobservables();
    if observable >= nobs {
        return Err(SolveError::NoSuchObservable {
            index: observable,
            count: nobs,
        });
    }
    let traj: &Trajectory = solution
        .trajectory
        .as_ref()
        .ok_or(SolveError::NotRecorded)?;
    let (n, np) = (model.nstates().value(), model.nparams().value());
    if traj.p != np || traj.n != n {
        return Err(SolveError::NotRecorded);
    }
    let mut x = OVector::<f64, M::N>::zeros_generic(model.nstates(), Const::<1>);
    let mut yx = vec![0.0; nobs * n];
    let mut yp = vec![0.0; nobs * np];
    let len = traj.node_len();
    let mut nodes = Vec::with_capacity(traj.len() * TRAJ_NODES * np);
    for k in 0..traj.len() {
        let (a, b) = (traj.t0[k], traj.t1[k]);
        let sw = traj.switches_of_step(k);
        for i in 0..TRAJ_NODES {
            let t = a + (b - a) * i as f64 / (TRAJ_NODES - 1) as f64;
            let node = &traj.data[(k * TRAJ_NODES + i) * len..(k * TRAJ_NODES + i + 1) * len];
            x.as_mut_slice().copy_from_slice(&node[..n]);
            model.observe_jac(sw, At::new(t, &x, params), &mut yx, &mut yp);
            let at = nodes.len();
            nodes.extend_from_slice(&yp[observable * np..(observable + 1) * np]);
            add_density(
                &yx[observable * n..(observable + 1) * n],
                &node[n..],
                &mut nodes[at..],
            );
        }
    }
    let mut atoms: Vec<(f64, Vec<f64>)> = solution
        .events
        .iter()
        .map(|e| (e.t, e.atoms[observable].clone()))
        .collect();
    let mut origins: Vec<AtomOrigin> = solution
        .events
        .iter()
        .enumerate()
        .map(|(index, e)| AtomOrigin::Event {
            index,
            jump: e.jump_observables[observable],
        })
        .collect();
    add_crossing_atoms(model, params, traj, observable, &mut atoms, &mut origins);
    let mut mu = Measure {
        observable,
        name: info.observables[observable].clone(),
        nparams: np,
        t0: traj.t0.clone(),
        t1: traj.t1.clone(),
        nodes,
        atoms,
        origins,
    };
    let zeno = solution.diagnostic(DiagnosticKind::Zeno);
    if let Some(d) = zeno {
        mu.add_zeno_tail_atom(d.t);
    }
    add_horizon_atom(model, params, solution, traj, &mut mu);
    Ok(mu)
}

/// Adds the atom α_T = y(T⁻) T' at a horizon that moves with θ (`Solution::dt_end` not all
/// zero): y(T⁻) is the observable at the last recorded node (the end of the last step, before
/// any event at T) under that step's switch bits. Appended last: nothing lies after T.
fn add_horizon_atom<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    solution: &Solution,
    traj: &Trajectory,
    mu: &mut Measure,
) where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    if solution.dt_end.iter().all(|&d| d == 0.0) || traj.is_empty() {
        return;
    }
    let n = model.nstates().value();
    let last = traj.len() - 1;
    let len = traj.node_len();
    let at = (last * TRAJ_NODES + TRAJ_NODES - 1) * len;
    let mut x = OVector::<f64, M::N>::zeros_generic(model.nstates(), Const::<1>);
    x.as_mut_slice().copy_from_slice(&traj.data[at..at + n]);
    let mut y = vec![0.0; model.info().nobservables()];
    let t = traj.t1[last];
    model.observe(traj.switches_of_step(last), At::new(t, &x, params), &mut y);
    let y_end = y[mu.observable];
    let alpha = solution.dt_end.iter().map(|d| y_end * d).collect();
    mu.atoms.push((solution.t_end, alpha));
    mu.origins.push(AtomOrigin::Horizon { jump: -y_end });
}

/// Adds to `atoms` (kept in time order) the atom α = −J t_c' of observable `observable` at
/// every recorded switch crossing where it jumps (J ≠ 0: an observable that does not read
/// the flipped bit has J = 0 exactly; a continuous kink, `max`, `abs`, leaves J = ±σ(x_c),
/// the rounding of the located crossing, and an atom of that size, which is kept rather
/// than judged away; a crossing recorded without sensitivities has no t' and adds
/// nothing).
fn add_crossing_atoms<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    traj: &Trajectory,
    observable: usize,
    atoms: &mut Vec<(f64, Vec<f64>)>,
    origins: &mut Vec<AtomOrigin>,
) where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    if traj.crossings.is_empty() {
        return;
    }
    let nobs = model.info().nobservables();
    let (mut before, mut after) = (vec![0.0; nobs], vec![0.0; nobs]);
    let mut x = OVector::<f64, M::N>::zeros_generic(model.nstates(), Const::<1>);
    for c in &traj.crossings {
        x.as_mut_slice().copy_from_slice(&c.x);
        model.observe(&c.before, At::new(c.t, &x, params), &mut before);
        model.observe(&c.after, At::new(c.t, &x, params), &mut after);
        let jump = after[observable] - before[observable];
        if jump == 0.0 || c.dt.is_empty() {
            continue;
        }
        let alpha = c.dt.iter().map(|d| -jump * d).collect();
        let at = atoms.partition_point(|a| a.0 <= c.t);
        atoms.insert(at, (c.t, alpha));
        origins.insert(
            at,
            AtomOrigin::Switch {
                switch: c.switch,
                jump,
            },
        );
    }
}

/// Adds h_x S to `out` (one entry per parameter): out_j += Σ_r h_x[r] S[r, j], with S the
/// column-major n×p sensitivity. Started from h_θ, `out` becomes the density h_x S + h_θ.
pub(crate) fn add_density(hx: &[f64], s: &[f64], out: &mut [f64]) {
    let n = hx.len();
    for (j, o) in out.iter_mut().enumerate() {
        let hs: f64 = hx
            .iter()
            .zip(&s[j * n..(j + 1) * n])
            .map(|(h, v)| h * v)
            .sum();
        *o += hs;
    }
}

impl Measure {
    /// Lumps the infinitely many events a Zeno run did not simulate into one effective atom
    /// at the accumulation time t* (the paper's S4: the tail as an effective atom). With
    /// c_K = μ([0, t_K]) after the K-th recorded event, μ([0, t*)) = lim c_K is estimated by
    /// Aitken's Δ² process ([`aitken_iterated`]) over the last five events (three when fewer
    /// were recorded): per-bounce masses of the form (a + bK) r^K, which a parameter of the
    /// restitution gives, need its second pass.
    /// The atom is that limit minus μ([0, t*]) as recorded.
    fn add_zeno_tail_atom(&mut self, t_star: f64) {
        let mut times: Vec<f64> = self
            .atoms
            .iter()
            .map(|a| a.0)
            .filter(|&t| t <= t_star)
            .collect();
        if times.len() < 3 || !t_star.is_finite() {
            return;
        }
        let keep = if times.len() >= 5 { 5 } else { 3 };
        times.drain(..times.len() - keep);
        times.push(t_star);
        let c = self.cumulative(&times);
        let recorded_at_t_star = &c[keep];
        let tail: Vec<f64> = (0..self.nparams)
            .map(|j| {
                let seq: Vec<f64> = c[..keep].iter().map(|v| v[j]).collect();
                aitken_iterated(&seq) - recorded_at_t_star[j]
            })
            .collect();
        let at = self.atoms.partition_point(|a| a.0 <= t_star);
        self.atoms.insert(at, (t_star, tail));
        self.origins.insert(at, AtomOrigin::ZenoTail);
    }

    /// The density h_x S + h_θ at t into `out` (length p); right-continuous at events.
    pub fn density_into(&self, t: f64, out: &mut [f64]) {
        out.fill(0.0);
        if self.t0.is_empty() {
            return;
        }
        let k = self.t0.partition_point(|&s| s <= t).saturating_sub(1);
        self.step_density(k, t, out);
    }

    fn step_density(&self, k: usize, t: f64, out: &mut [f64]) {
        let w = Trajectory::weights_on(self.t0[k], self.t1[k], t);
        let p = self.nparams;
        out.fill(0.0);
        for (i, wi) in w.iter().enumerate() {
            let base = (k * TRAJ_NODES + i) * p;
            for (o, v) in out.iter_mut().zip(&self.nodes[base..base + p]) {
                *o += wi * v;
            }
        }
    }

    /// The density at t, one value per parameter.
    pub fn density(&self, t: f64) -> Vec<f64> {
        let mut out = vec![0.0; self.nparams];
        self.density_into(t, &mut out);
        out
    }

    /// The density on a grid of times: `result[i][j]` at `ts[i]` for parameter j.
    pub fn on_grid(&self, ts: &[f64]) -> Vec<Vec<f64>> {
        ts.iter().map(|&t| self.density(t)).collect()
    }

    /// ⟨μ_y, φ⟩ = Σ_steps ∫ φ·density dt + Σ_k φ(t_k) α_k, one value per parameter.
    pub fn pair(&self, phi: impl Fn(f64) -> f64) -> Vec<f64> {
        let p = self.nparams;
        let mut acc = vec![0.0; p];
        let mut tmp = vec![0.0; 3 * p];
        let mut dens = vec![0.0; p];
        for k in 0..self.t0.len() {
            let mut f = |t: f64, out: &mut [f64]| {
                self.step_density(k, t, &mut dens);
                let ph = phi(t);
                for (o, d) in out.iter_mut().zip(&dens) {
                    *o = ph * d;
                }
            };
            integrate_adaptive(
                &mut f, self.t0[k], self.t1[k], 1e-13, 1e-300, &mut acc, &mut tmp,
            );
        }
        for (t, a) in &self.atoms {
            let ph = phi(*t);
            for (o, v) in acc.iter_mut().zip(a) {
                *o += ph * v;
            }
        }
        acc
    }

    /// The cumulative measure M(t) = μ([0, t]) = ∫₀ᵗ density ds + Σ_{t_k ≤ t} α_k at each
    /// time of the ascending `ts`, one vector per parameter (`result[i][j]` at `ts[i]` for
    /// parameter j). The density is integrated step by step with the adaptive rule of
    /// [`Measure::pair`], so boundary layers inside a step (a stiff lag's 1e-8 transient) are
    /// resolved instead of being sampled on the grid.
    pub fn cumulative(&self, ts: &[f64]) -> Vec<Vec<f64>> {
        let p = self.nparams;
        let mut out = Vec::with_capacity(ts.len());
        let mut acc = vec![0.0; p];
        let mut tmp = vec![0.0; 3 * p];
        let mut pos = self.t0.first().copied().unwrap_or(0.0);
        let mut k = 0;
        for &t in ts {
            while k < self.t0.len() && pos < t {
                if self.t1[k] <= pos {
                    k += 1;
                    continue;
                }
                let start = pos.max(self.t0[k]);
                let end = self.t1[k].min(t);
                let mut f = |s: f64, o: &mut [f64]| self.step_density(k, s, o);
                integrate_adaptive(&mut f, start, end, 1e-12, 1e-300, &mut acc, &mut tmp);
                pos = end;
            }
            let mut m = acc.clone();
            for (_, a) in self.atoms.iter().filter(|(tk, _)| *tk <= t) {
                for (o, v) in m.iter_mut().zip(a) {
                    *o += v;
                }
            }
            out.push(m);
        }
        out
    }

    /// The density part ∫ φ·density dt alone.
    pub fn pair_density(&self, phi: impl Fn(f64) -> f64) -> Vec<f64> {
        let mut acc = self.pair(&phi);
        for (t, a) in &self.atoms {
            let ph = phi(*t);
            for (o, v) in acc.iter_mut().zip(a) {
                *o -= ph * v;
            }
        }
        acc
    }
}
