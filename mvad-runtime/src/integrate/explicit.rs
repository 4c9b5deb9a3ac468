//! One explicit Runge–Kutta stage loop over a Butcher tableau given as data.
//!
//! An embedded pair with continuous extension is the tableau
//!
//! ```text
//!   k_i = F(t₀ + c_i h, Y₀ + h Σ_{j<i} a_ij k_j)          i = 1..S    (the step)
//!   Y₁  = Y₀ + h Σ_i b_i k_i,      e = h Σ_i (b_i − b̂_i) k_i
//!   k_i = F(t₀ + c_i h, Y₀ + h Σ_j a_ij k_j)              i = S+1..K  (interpolation stages)
//!   Y(t₀ + θh) = Y₀ + h Σ_{i≤K} b_i(θ) k_i,   b_i(θ) = Σ_{m=1..D} r_im θ^m
//! ```
//!
//! h is signed: the same loop integrates backwards. With `last_stage_is_solution` (FSAL, as
//! Tsit5: a_S,· = b, c_S = 1) the argument of stage S is Y₁ itself and k_S = F(t₀ + h, Y₁) is
//! the next step's first stage; otherwise (Verner) the first interpolation stage, row a_{S+1},·
//! = b, is that stage and is evaluated when the step is accepted.
//!
//! Stage counts are const parameters, so every loop below has compile-time bounds.

use super::system::{ImplicitSystem, StageVector};
use super::Integrator;

/// An explicit embedded Runge–Kutta pair with S stages, K − S interpolation stages and a
/// continuous extension of polynomial degree D (see the module doc).
pub(super) struct Tableau<const S: usize, const K: usize, const D: usize> {
    /// Nodes c_i of all K stages.
    pub c: [f64; K],
    /// Rows a_i,· of the coupling matrix, trailing zeros left out (row i has at most i entries
    /// for i < S; interpolation rows may couple to interpolation stages before them).
    pub a: [&'static [f64]; K],
    /// Weights b_i of the solution.
    pub b: [f64; S],
    /// Error weights b_i − b̂_i.
    pub btilde: [f64; S],
    /// Coefficients r_i1..r_iD of the dense-output polynomials b_i(θ).
    pub dense: [[f64; D]; K],
    /// Order of the error estimate + 1 (the exponent base of the step-size controller).
    pub error_order: f64,
    /// FSAL: row S−1 of a is b and c_{S−1} = 1 (0-based), so Y₁ is the last stage's argument.
    pub last_stage_is_solution: bool,
    /// Record Hairer's stiffness estimate h·‖k_S − k_{S−1}‖/‖Y₁ − Y_{S−1}‖ (valid only when
    /// the last two stages are both evaluated at t₀ + h).
    pub stiffness_test: bool,
}

impl<const S: usize, const K: usize, const D: usize> Tableau<S, K, D> {
    /// Slot that holds F(t₀ + h, Y₁) after an accepted step (the next step's first stage).
    pub const fn fsal_slot(&self) -> usize {
        if self.last_stage_is_solution {
            S - 1
        } else {
            S
        }
    }

    /// The degree D of the continuous extension in θ.
    pub const fn degree(&self) -> usize {
        D
    }

    /// The weights b_i(θ) of the continuous extension (Horner's scheme).
    #[inline]
    pub fn weights(&self, theta: f64) -> [f64; K] {
        let mut w = [0.0; K];
        for (wi, r) in w.iter_mut().zip(&self.dense) {
            let mut acc = 0.0;
            for coef in r.iter().rev() {
                acc = (acc + coef) * theta;
            }
            *wi = acc;
        }
        w
    }

    /// Y(t₀ + θh) = Y₀ + h Σ b_i(θ) k_i for every integrated part.
    #[inline]
    pub fn dense<V: StageVector>(
        &self,
        k: &[V],
        y0: &V,
        h: f64,
        theta: f64,
        all: bool,
        out: &mut V,
    ) {
        out.combine(y0, h, &self.weights(theta), &k[..K], all);
    }

    /// The primary part of [`Tableau::dense`] as a polynomial in θ:
    /// Y₀ + h Σ_i b_i(θ) k_i = Σ_{m=0..D} θᵐ c_m with c₀ = Y₀ and c_m = h Σ_i r_im k_i, into
    /// `coefs[0..=D]`.
    #[inline]
    pub fn poly_primary<V: StageVector>(&self, k: &[V], y0: &V, h: f64, coefs: &mut [V::Primary]) {
        y0.primary_into(&mut coefs[0]);
        for (m, c) in coefs[1..=D].iter_mut().enumerate() {
            let column: [f64; K] = std::array::from_fn(|i| self.dense[i][m]);
            V::lincomb_primary(c, h, &column, &k[..K]);
        }
    }

    /// The primary part of [`Tableau::dense`].
    #[inline]
    pub fn dense_primary<V: StageVector>(
        &self,
        k: &[V],
        y0: &V,
        h: f64,
        theta: f64,
        out: &mut V::Primary,
    ) {
        V::combine_primary(out, y0, h, &self.weights(theta), &k[..K]);
    }
}

impl<Sys: ImplicitSystem> Integrator<Sys> {
    /// One attempt of the pair `tab` from (t, y) with k[0] = F(t, y): stages into k[1..S], the
    /// candidate into `ynew`, the error into `yerr`; returns ‖yerr‖ (and records Hairer's
    /// stiffness ratio when the tableau asks for it).
    #[inline]
    pub(super) fn explicit_attempt<const S: usize, const K: usize, const D: usize>(
        &mut self,
        tab: &Tableau<S, K, D>,
        h: f64,
    ) -> f64 {
        let all = self.sys.all_parts();
        let reads = self.sys.reads_secondary();
        let t = self.t;
        for i in 1..S {
            // A stage argument needs only what F reads, unless it is the solution itself.
            let dst = if tab.last_stage_is_solution && i == S - 1 {
                self.ynew.combine(&self.y, h, tab.a[i], &self.k[..i], all);
                &self.ynew
            } else {
                let (y, ks) = (&self.y, &self.k[..i]);
                self.tmp.combine_argument(y, h, tab.a[i], ks, reads);
                &self.tmp
            };
            self.sys.eval(t + tab.c[i] * h, dst, &mut self.k[i]);
        }
        if !tab.last_stage_is_solution {
            self.ynew.combine(&self.y, h, &tab.b, &self.k[..S], all);
        }
        // Only the parts under error control are needed.
        let ctrl = self.sys.controls_all();
        self.yerr.lincomb(h, &tab.btilde, &self.k[..S], ctrl);
        if tab.stiffness_test {
            // Both k_S and k_{S−1} are F at t + h, at Y_{S−1} (in tmp) and Y_S = Y₁.
            let num = self.k[S - 1].primary_dist_sq(&self.k[S - 2]);
            let den = self.ynew.primary_dist_sq(&self.tmp);
            self.stiff_ratio = if den > 0.0 {
                h.abs() * (num / den).sqrt()
            } else {
                0.0
            };
        }
        self.error_norm()
    }

    /// Interpolation stages `stages` (within S..K) of the accepted step from t_prev of length h
    /// (each needs the stages before it).
    pub(super) fn explicit_interp_stages<const S: usize, const K: usize, const D: usize>(
        &mut self,
        tab: &Tableau<S, K, D>,
        stages: std::ops::Range<usize>,
        h: f64,
    ) {
        let reads = self.sys.reads_secondary();
        let t0 = self.t_prev;
        for i in stages {
            let row = tab.a[i];
            self.tmp
                .combine_argument(&self.y_prev, h, row, &self.k[..row.len()], reads);
            self.sys.eval(t0 + tab.c[i] * h, &self.tmp, &mut self.k[i]);
        }
    }
}

/// Checks of a tableau against the order conditions it must satisfy (used by the tables' tests).
#[cfg(test)]
pub(super) fn check_tableau<const S: usize, const K: usize, const D: usize>(
    tab: &Tableau<S, K, D>,
    order: i32,
    embedded_order: i32,
    dense_order: i32,
    eps: f64,
) {
    use approx::assert_relative_eq;
    // Row sums equal the nodes.
    for i in 0..K {
        assert_relative_eq!(tab.a[i].iter().sum::<f64>(), tab.c[i], epsilon = eps);
        assert!(
            tab.a[i].len() <= i.max(1),
            "row {i} couples to a later stage"
        );
    }
    // Quadrature conditions: b exact to degree order−1, b̂ to degree embedded_order−1.
    for q in 1..=order {
        let s: f64 = (0..S).map(|i| tab.b[i] * tab.c[i].powi(q - 1)).sum();
        assert_relative_eq!(s, 1.0 / q as f64, epsilon = eps);
    }
    for q in 1..=embedded_order {
        let s: f64 = (0..S)
            .map(|i| (tab.b[i] - tab.btilde[i]) * tab.c[i].powi(q - 1))
            .sum();
        assert_relative_eq!(s, 1.0 / q as f64, epsilon = eps);
    }
    // The interpolant: b_i(0) = 0, b_i(1) = b_i, and Σ b_i(θ) c_i^(q−1) = θ^q/q.
    assert!(tab.weights(0.0).iter().all(|w| *w == 0.0));
    let w1 = tab.weights(1.0);
    for (i, wi) in w1.iter().enumerate() {
        let bi = if i < S { tab.b[i] } else { 0.0 };
        assert_relative_eq!(*wi, bi, epsilon = 1e3 * eps);
    }
    let th = 0.37;
    let w = tab.weights(th);
    for q in 1..=dense_order {
        let s: f64 = (0..K).map(|i| w[i] * tab.c[i].powi(q - 1)).sum();
        assert_relative_eq!(s, th.powi(q) / q as f64, epsilon = eps);
    }
    // The FSAL stage is F(t₀ + h, Y₁).
    let fsal = tab.fsal_slot();
    assert_eq!(tab.c[fsal], 1.0);
    for (j, a) in tab.a[fsal].iter().enumerate() {
        assert_relative_eq!(*a, tab.b[j], epsilon = 1e-16);
    }
}
