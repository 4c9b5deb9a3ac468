//! [`SpdFactor`]: nalgebra's Cholesky factorisation of a small symmetric positive definite
//! matrix, on a buffer recycled from one factorisation to the next (no allocation once the
//! buffer has its capacity), with a test of how safely positive each pivot is.
//!
//! For M = NᵀN (a Gram matrix of columns n₁ … n_k) the pivot of column j satisfies
//! L_jj² = ‖(I − P_{j−1}) n_j‖², P_{j−1} the projection on span(n₁ … n_{j−1}), so
//! L_jj² / M_jj = sin² of the angle between n_j and the earlier columns: the factorisation
//! doubles as a test of linear independence with a scale-free tolerance.

use nalgebra::{Cholesky, DMatrix, DVectorViewMut, Dim, Dyn, Matrix, StorageMut};

/// A Cholesky factor L (M = LLᵀ) of a k×k matrix, k at most the capacity given at creation.
#[derive(Clone, Debug)]
pub(super) struct SpdFactor {
    /// The factor of the last successful [`SpdFactor::factor`] (its lower triangle).
    chol: Option<Cholesky<f64, Dyn>>,
    /// The buffer while no factor holds it.
    spare: Vec<f64>,
    /// M's diagonal before factorisation.
    diag: Vec<f64>,
    /// Whether `chol` is a valid factor.
    valid: bool,
    /// The smallest L_jj²/M_jj of the last factorisation (1 when k = 0): sin² of the worst
    /// angle between a column and the earlier ones, a measure of conditioning.
    worst: f64,
}

impl SpdFactor {
    /// Room for matrices up to `kmax`×`kmax` (allocated here, once).
    pub fn with_capacity(kmax: usize) -> Self {
        SpdFactor {
            chol: None,
            spare: Vec::with_capacity(kmax * kmax),
            diag: Vec::with_capacity(kmax),
            valid: false,
            worst: 1.0,
        }
    }

    /// Factorises the symmetric k×k matrix M with entries `entry(i, j)`. Fails with the
    /// first pivot j whose L_jj² is not above `tol2 · M_jj` (or not finite): column j is
    /// (numerically) a combination of the earlier ones, or M is not positive definite.
    pub fn factor(
        &mut self,
        k: usize,
        tol2: f64,
        mut entry: impl FnMut(usize, usize) -> f64,
    ) -> Result<(), usize> {
        self.valid = false;
        self.worst = 1.0;
        if k == 0 {
            // Nothing to factor: keep the buffer where it is.
            self.diag.clear();
            if let Some(ch) = self.chol.take() {
                self.spare = ch.unpack_dirty().data.into();
            }
            self.valid = true;
            return Ok(());
        }
        let mut buf: Vec<f64> = match self.chol.take() {
            Some(ch) => ch.unpack_dirty().data.into(),
            None => std::mem::take(&mut self.spare),
        };
        buf.clear();
        buf.resize(k * k, 0.0);
        self.diag.clear();
        for j in 0..k {
            for i in j..k {
                let e = entry(i, j);
                buf[i + j * k] = e;
                buf[j + i * k] = e;
            }
            self.diag.push(buf[j + j * k]);
        }
        let ch = Cholesky::new_unchecked(DMatrix::from_vec(k, k, buf));
        let l = ch.l_dirty();
        let bad = (0..k).find(|&j| {
            let d = l[(j, j)];
            self.worst = self.worst.min(d * d / self.diag[j]);
            !(d.is_finite() && d * d > tol2 * self.diag[j] && self.diag[j] > 0.0)
        });
        self.chol = Some(ch);
        match bad {
            Some(j) => Err(j),
            None => {
                self.valid = true;
                Ok(())
            }
        }
    }

    /// The smallest L_jj²/M_jj of the last factorisation: 1 for orthogonal columns, near 0
    /// for nearly dependent ones.
    pub fn worst_pivot(&self) -> f64 {
        self.worst
    }

    /// b := M⁻¹ b for the last successful factorisation (b has k entries).
    pub fn solve_mut(&self, b: &mut [f64]) {
        debug_assert!(self.valid);
        if let Some(ch) = &self.chol {
            let k = b.len();
            ch.solve_mut(&mut DVectorViewMut::from_slice(b, k));
        }
    }

    /// B := L⁻¹ B (forward substitution with the factor).
    pub fn lower_solve_mut<C: Dim, S: StorageMut<f64, Dyn, C>>(
        &self,
        b: &mut Matrix<f64, Dyn, C, S>,
    ) {
        self.with_lower(|l| l.solve_lower_triangular_unchecked_mut(b));
    }

    /// B := L⁻ᵀ B (back substitution with the factor's transpose).
    pub fn lower_tr_solve_mut<C: Dim, S: StorageMut<f64, Dyn, C>>(
        &self,
        b: &mut Matrix<f64, Dyn, C, S>,
    ) {
        self.with_lower(|l| l.tr_solve_lower_triangular_unchecked_mut(b));
    }

    /// Runs `solve` on the lower factor L (M = LLᵀ) of the last successful factorisation.
    fn with_lower(&self, solve: impl FnOnce(&DMatrix<f64>)) {
        debug_assert!(self.valid);
        if let Some(ch) = &self.chol {
            solve(ch.l_dirty());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DVector;

    #[test]
    fn factor_solves_and_detects_dependence() {
        let mut f = SpdFactor::with_capacity(3);
        let m = [[4.0, 2.0, 0.0], [2.0, 3.0, 1.0], [0.0, 1.0, 2.0]];
        f.factor(3, 1e-20, |i, j| m[i][j]).unwrap();
        let mut b = [1.0, 2.0, 3.0];
        f.solve_mut(&mut b);
        for (i, row) in m.iter().enumerate() {
            let mb: f64 = row.iter().zip(&b).map(|(a, x)| a * x).sum();
            assert!((mb - [1.0, 2.0, 3.0][i]).abs() < 1e-14);
        }
        // Gram matrix of columns (1, 0), (0, 1), (1, 1): the third depends on the others.
        let cols = [[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]];
        let dot = |i: usize, j: usize| cols[i][0] * cols[j][0] + cols[i][1] * cols[j][1];
        assert_eq!(f.factor(3, 1e-20, dot), Err(2));
        // And the buffer is reused: a smaller factorisation after a failure still works.
        f.factor(2, 1e-20, dot).unwrap();
        let mut x = DVector::from_vec(vec![1.0, 1.0]);
        f.lower_solve_mut(&mut x);
        f.lower_tr_solve_mut(&mut x);
        assert_eq!(x.as_slice(), &[1.0, 1.0]);
    }
}
