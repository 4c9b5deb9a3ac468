//! The dual active-set iteration of Goldfarb and Idnani, in the variables v = Lᵀu.
//!
//! With H = LLᵀ, wᵢ = L⁻¹aᵢ and v₀ = −L⁻¹c, the QP min ½uᵀHu + cᵀu s.t. aᵢᵀu (= or ≤) βᵢ
//! becomes min ½‖v − v₀‖² s.t. wᵢᵀv (= or ≤) βᵢ: the projection of v₀ on a polyhedron.
//! The iteration starts at the unconstrained minimum v = v₀ with an empty working set and
//! keeps the working set's multipliers dual feasible (λ ≥ 0 for inequalities) and its
//! normals linearly independent, while it adds violated constraints one at a time:
//!
//! - for the entering normal nₚ = σwₚ (σ = ±1 turns an equality violated from below
//!   into the form nₚᵀv ≤ σβₚ), the multiplier t of nₚ grows from 0; stationarity
//!   v − v₀ + Σ λₖnₖ + t nₚ = 0 with the working constraints kept gives the primal direction
//!   z = −(I − P)nₚ (P the projection on the working normals) and the dual direction
//!   dλ = −r, r = G⁻¹Nᵀnₚ, G = NᵀN;
//! - the full step t₁ = violation / ‖z‖² makes constraint p active; the partial step
//!   t₂ = min λₖ/rₖ over working inequalities with rₖ > 0 drops the first whose multiplier
//!   reaches zero. z = 0 (nₚ dependent on the working normals) allows only partial steps,
//!   and no step at all means the constraints are infeasible.
//!
//! When no constraint is violated the working set is the active set; [`Dual::polish`]
//! then solves the KKT system on it from scratch, so v and λ are exact to rounding and do
//! not carry the iteration's accumulated error. Every linear solve is a Cholesky
//! factorisation of G ([`SpdFactor`]), refactored per iteration (k ≤ n is small).

use super::factor::SpdFactor;
use super::QpError;
use nalgebra::{DMatrix, DVector};

/// How a constraint takes part in the current problem.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Role {
    /// Ignored.
    Off,
    /// wᵢᵀv = βᵢ.
    Eq,
    /// wᵢᵀv ≤ βᵢ.
    Le,
}

/// Tolerances of one run.
#[derive(Clone, Copy, Debug)]
pub(super) struct Tols {
    /// A constraint is violated when its slack exceeds this times its scale.
    pub feas: f64,
    /// sin² of the angle under which a normal counts as dependent on others.
    pub dep2: f64,
    /// Iteration budget.
    pub max_iter: usize,
}

/// Rounds of (iterate, polish) before giving up: a polish moves v by rounding only, so a
/// second round is rare and a third means the data are at the edge of what doubles resolve.
const ROUNDS: usize = 3;

/// Working sets whose Gram factor has a pivot ratio L_jj²/G_jj below this (an angle of sine
/// 1e-2 between a normal and the others) get one step of iterative refinement.
const REFINE_BELOW: f64 = 1e-4;

/// The iteration's data and state; buffers sized once for n variables and m constraints.
#[derive(Clone, Debug)]
pub(super) struct Dual {
    /// Columns wᵢ = L⁻¹aᵢ (n×m).
    pub w: DMatrix<f64>,
    /// ‖wᵢ‖.
    pub wnorm: Vec<f64>,
    /// The unconstrained minimum v₀.
    pub v0: DVector<f64>,
    /// Right-hand sides βᵢ.
    pub beta: Vec<f64>,
    /// Each constraint's role.
    pub role: Vec<Role>,
    /// The iterate (the solution after [`Dual::solve`]).
    pub v: DVector<f64>,
    /// Working set: constraint indices, in the order they entered.
    pub idx: Vec<usize>,
    /// Working set: σ of each normal σwᵢ.
    pub sign: Vec<f64>,
    /// Working set: the multiplier of each normal σwᵢ.
    pub lam: Vec<f64>,
    /// Whether constraint i is in the working set.
    member: Vec<bool>,
    /// Primal step direction.
    z: DVector<f64>,
    /// Dual step direction (−dλ), then scratch.
    r: Vec<f64>,
    /// Cholesky factor of the working set's Gram matrix G = NᵀN.
    pub gram: SpdFactor,
}

impl Dual {
    /// Buffers for n variables and m constraints.
    pub fn new(n: usize, m: usize) -> Self {
        Dual {
            w: DMatrix::zeros(n, m),
            wnorm: vec![0.0; m],
            v0: DVector::zeros(n),
            beta: vec![0.0; m],
            role: vec![Role::Off; m],
            v: DVector::zeros(n),
            idx: Vec::with_capacity(n),
            sign: Vec::with_capacity(n),
            lam: Vec::with_capacity(n),
            member: vec![false; m],
            z: DVector::zeros(n),
            r: Vec::with_capacity(n),
            gram: SpdFactor::with_capacity(n),
        }
    }

    /// wᵢᵀx.
    pub fn dot(&self, i: usize, x: &DVector<f64>) -> f64 {
        self.w.column(i).dot(x)
    }

    /// Slack wᵢᵀv − βᵢ of constraint i at the iterate.
    pub fn slack(&self, i: usize) -> f64 {
        self.dot(i, &self.v) - self.beta[i]
    }

    /// The scale a slack of constraint i is measured against: |βᵢ| + ‖wᵢ‖·`force` with
    /// `force` = [`Dual::force_scale`] = ‖v‖ + ‖v₀‖. It is homogeneous in (v₀, β), so every
    /// test is invariant under scaling of the data.
    pub fn slack_scale(&self, i: usize, force: f64) -> f64 {
        self.beta[i].abs() + self.wnorm[i] * force
    }

    /// The scale of the forces λᵢwᵢ: ‖v‖ + ‖v₀‖ (they sum to v₀ − v).
    pub fn force_scale(&self) -> f64 {
        self.v.norm() + self.v0.norm()
    }

    /// Whether constraint i is in the working set.
    pub fn is_member(&self, i: usize) -> bool {
        self.member[i]
    }

    /// Sets wᵢ = L⁻¹aᵢ from the rows of A (m×n) and the factor of H.
    pub fn set_normals(&mut self, a: &DMatrix<f64>, hfac: &SpdFactor) {
        self.w.tr_copy_from(a);
        hfac.lower_solve_mut(&mut self.w);
        for (i, wn) in self.wnorm.iter_mut().enumerate() {
            *wn = self.w.column(i).norm();
        }
    }

    /// Factorises the Gram matrix of the working set; a failure names the working set.
    fn factor_working(&mut self, dep2: f64) -> Result<(), QpError> {
        let (w, idx, sign) = (&self.w, &self.idx, &self.sign);
        self.gram
            .factor(idx.len(), dep2, |a, b| {
                sign[a] * sign[b] * w.column(idx[a]).dot(&w.column(idx[b]))
            })
            .map_err(|j| QpError::Degenerate {
                constraints: idx[..=j].to_vec(),
            })
    }

    /// Checks that the constraints in `cols` have linearly independent normals (the signs σ
    /// flip whole rows and columns of G, which independence does not see). Uses the Gram
    /// factor's buffer, so the working set's factor is lost.
    pub fn check_independent(&mut self, cols: &[usize], dep2: f64) -> Result<(), QpError> {
        let w = &self.w;
        self.gram
            .factor(cols.len(), dep2, |a, b| {
                w.column(cols[a]).dot(&w.column(cols[b]))
            })
            .map_err(|j| QpError::Degenerate {
                constraints: cols[..=j].to_vec(),
            })
    }

    /// Solves the problem set up in `w`, `v0`, `beta` and `role`. Returns the iterations used.
    pub fn solve(&mut self, tols: &Tols) -> Result<usize, QpError> {
        self.v.copy_from(&self.v0);
        self.idx.clear();
        self.sign.clear();
        self.lam.clear();
        self.member.fill(false);
        let mut iters = 0;
        for _ in 0..ROUNDS {
            while let Some((p, sigma)) = self.most_violated(tols.feas) {
                self.add(p, sigma, tols, &mut iters)?;
            }
            self.polish(tols.dep2)?;
            if self.most_violated(tols.feas).is_none() {
                return Ok(iters);
            }
        }
        Err(QpError::NoConvergence { iterations: iters })
    }

    /// The next constraint to add and its σ: an equality outside the working set (in
    /// declaration order), else the inequality with the largest violation in the v-metric
    /// (slack / ‖wᵢ‖), if any exceeds `feas` times its scale.
    fn most_violated(&self, feas: f64) -> Option<(usize, f64)> {
        let mut best: Option<(usize, f64)> = None;
        let force = self.force_scale();
        for (i, role) in self.role.iter().enumerate() {
            if self.member[i] {
                continue;
            }
            match role {
                Role::Off => {}
                Role::Eq => {
                    let sigma = if self.slack(i) < 0.0 { -1.0 } else { 1.0 };
                    return Some((i, sigma));
                }
                Role::Le => {
                    let s = self.slack(i);
                    if s > feas * self.slack_scale(i, force) {
                        let key = if self.wnorm[i] > 0.0 {
                            s / self.wnorm[i]
                        } else {
                            f64::INFINITY
                        };
                        if best.is_none_or(|(_, k)| key > k) {
                            best = Some((i, key));
                        }
                    }
                }
            }
        }
        best.map(|(i, _)| (i, 1.0))
    }

    /// Adds constraint p with normal σwₚ to the working set, dropping working inequalities
    /// whose multipliers reach zero on the way (the partial steps).
    fn add(&mut self, p: usize, sigma: f64, tols: &Tols, iters: &mut usize) -> Result<(), QpError> {
        let mut t = 0.0;
        loop {
            *iters += 1;
            if *iters > tols.max_iter {
                return Err(QpError::NoConvergence { iterations: *iters });
            }
            self.factor_working(tols.dep2)?;
            let k = self.idx.len();
            // r = G⁻¹Nᵀnₚ and z = −nₚ + N r = −(I − P)nₚ.
            self.r.clear();
            for a in 0..k {
                let d = self.w.column(self.idx[a]).dot(&self.w.column(p));
                self.r.push(self.sign[a] * sigma * d);
            }
            self.gram.solve_mut(&mut self.r);
            self.z.copy_from(&self.w.column(p));
            self.z *= -sigma;
            for a in 0..k {
                self.z
                    .axpy(self.r[a] * self.sign[a], &self.w.column(self.idx[a]), 1.0);
            }
            let zz = self.z.norm_squared();
            // NaN counts as dependent.
            let dependent = zz.is_nan() || zz <= tols.dep2 * self.wnorm[p] * self.wnorm[p];
            let viol = sigma * self.slack(p);
            let t1 = if dependent {
                f64::INFINITY
            } else {
                viol.max(0.0) / zz
            };
            let mut t2 = f64::INFINITY;
            let mut leaving = None;
            for a in 0..k {
                if self.role[self.idx[a]] == Role::Le && self.r[a] > 0.0 {
                    let ta = self.lam[a].max(0.0) / self.r[a];
                    if ta < t2 {
                        t2 = ta;
                        leaving = Some(a);
                    }
                }
            }
            if t1.is_infinite() && t2.is_infinite() {
                return Err(
                    if viol <= tols.feas * self.slack_scale(p, self.force_scale()) {
                        let mut constraints = self.idx.clone();
                        constraints.push(p);
                        QpError::Degenerate { constraints }
                    } else {
                        QpError::Infeasible { constraint: p }
                    },
                );
            }
            let step = t1.min(t2);
            if !dependent {
                self.v.axpy(step, &self.z, 1.0);
            }
            for a in 0..k {
                self.lam[a] -= step * self.r[a];
            }
            t += step;
            match leaving {
                Some(a) if t2 < t1 => {
                    let i = self.idx.remove(a);
                    self.sign.remove(a);
                    self.lam.remove(a);
                    self.member[i] = false;
                }
                _ => {
                    self.idx.push(p);
                    self.sign.push(sigma);
                    self.lam.push(t);
                    self.member[p] = true;
                    return Ok(());
                }
            }
        }
    }

    /// Solves the KKT system on the working set from scratch (see
    /// [`Dual::resolve_on_working_set`]), so v and λ carry no error of the iteration.
    pub fn polish(&mut self, dep2: f64) -> Result<(), QpError> {
        self.factor_working(dep2)?;
        self.resolve_on_working_set();
        Ok(())
    }

    /// With G factored for the working set, solves the problem with the working set's
    /// constraints as equalities for the (v₀, β) in `v0` and `beta`:
    /// G λ = (σₖ(w_{iₖ}ᵀv₀ − β_{iₖ}))ₖ and v = v₀ − Σ λₖσₖw_{iₖ}. One factorisation serves
    /// every right-hand side. The result is in `v` and `lam`.
    pub fn resolve_on_working_set(&mut self) {
        for a in 0..self.idx.len() {
            let i = self.idx[a];
            self.lam[a] = self.sign[a] * (self.dot(i, &self.v0) - self.beta[i]);
        }
        self.gram.solve_mut(&mut self.lam);
        self.set_v_from_lam();
        // One step of iterative refinement with the same factor when the working set is
        // poorly conditioned: the working constraints' residual rₖ = σₖ(w_{iₖ}ᵀv − β_{iₖ})
        // gives G δλ = r, λ += δλ, recovering what the Gram matrix's squared condition number
        // costs (stationarity holds by construction of v).
        let k = self.idx.len();
        if k == 0 || self.gram.worst_pivot() > REFINE_BELOW {
            return;
        }
        self.r.clear();
        for a in 0..k {
            let i = self.idx[a];
            self.r
                .push(self.sign[a] * (self.dot(i, &self.v) - self.beta[i]));
        }
        self.gram.solve_mut(&mut self.r);
        for a in 0..k {
            self.lam[a] += self.r[a];
        }
        self.set_v_from_lam();
    }

    /// v = v₀ − Σ λₖσₖw_{iₖ}.
    fn set_v_from_lam(&mut self) {
        self.v.copy_from(&self.v0);
        for a in 0..self.idx.len() {
            self.v.axpy(
                -self.lam[a] * self.sign[a],
                &self.w.column(self.idx[a]),
                1.0,
            );
        }
    }
}
