//! The sparse symmetric positive definite system of the Gauss–Newton iterations: a CSC pattern
//! built once per mesh (femu-sparse's [`CscPattern`]) and faer's supernodal Cholesky (`L Lᵀ`, approximate-minimum-degree
//! ordering), symbolic analysis and numeric factorization done once, solves in place with a
//! workspace allocated once (no allocation per iteration).

use crate::error::DicError;
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, LltRef, SymbolicCholesky, SymmetricOrdering,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};

pub use femu_sparse::CscPattern;

/// `xᵀ A x` for `A` stored in full on `pattern`.
pub fn quadratic_form(pattern: &CscPattern, values: &[f64], x: &[f64]) -> f64 {
    let mut s = 0.0;
    for c in 0..pattern.n {
        for k in pattern.col_ptr[c]..pattern.col_ptr[c + 1] {
            s += x[pattern.row_idx[k]] * values[k] * x[c];
        }
    }
    s
}

fn pattern_symbolic(pattern: &CscPattern) -> SymbolicSparseColMatRef<'_, usize> {
    SymbolicSparseColMatRef::new_checked(
        pattern.n,
        pattern.n,
        &pattern.col_ptr,
        None,
        &pattern.row_idx,
    )
}

/// Sparse Cholesky factorization with its workspace.
pub struct Cholesky {
    symbolic: SymbolicCholesky<usize>,
    l_values: Vec<f64>,
    mem: MemBuffer,
    par: Par,
}

impl std::fmt::Debug for Cholesky {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Cholesky")
            .field("n", &self.symbolic.nrows())
            .field("nnz(L)", &self.l_values.len())
            .finish()
    }
}

impl Cholesky {
    /// Symbolic analysis and numeric factorization of the symmetric matrix with `values` on
    /// `pattern` (only the lower triangle is read). A non-positive pivot is an error naming
    /// the equation (`2 node + component`).
    pub fn factorize(pattern: &CscPattern, values: &[f64]) -> Result<Self, DicError> {
        let symbolic = factorize_symbolic_cholesky(
            pattern_symbolic(pattern),
            Side::Lower,
            SymmetricOrdering::Amd,
            Default::default(),
        )
        .map_err(|e| DicError::Linear(format!("symbolic Cholesky: {e:?}")))?;
        // Sequential: the systems are small (thousands of equations) next to the pixel loops.
        let par = Par::Seq;
        let req = StackReq::any_of(&[
            symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()),
            symbolic.solve_in_place_scratch::<f64>(1, par),
        ]);
        let mut mem = MemBuffer::new(req);
        let mut l_values = vec![0.0; symbolic.len_val()];
        let a = SparseColMatRef::new(pattern_symbolic(pattern), values);
        symbolic
            .factorize_numeric_llt(
                &mut l_values,
                a,
                Side::Lower,
                Default::default(),
                par,
                MemStack::new(&mut mem),
                Default::default(),
            )
            .map_err(|e| match e {
                faer::linalg::cholesky::llt::factor::LltError::NonPositivePivot { index } => {
                    DicError::Linear(format!(
                        "the Gauss-Newton matrix is singular (pivot {index} of {} is not positive)",
                        pattern.n
                    ))
                }
            })?;
        if l_values.iter().any(|v| !v.is_finite()) {
            return Err(DicError::Linear(
                "Cholesky produced non-finite factors".into(),
            ));
        }
        Ok(Cholesky {
            symbolic,
            l_values,
            mem,
            par,
        })
    }

    /// Solves `A x = rhs` in place (no allocation).
    pub fn solve_in_place(&mut self, rhs: &mut [f64]) {
        let n = rhs.len();
        let llt = LltRef::new(&self.symbolic, &self.l_values);
        llt.solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(rhs, n, 1),
            self.par,
            MemStack::new(&mut self.mem),
        );
    }

    /// Solves `A X = R` in place for the `ncols` columns of `rhs` (column-major, `n` rows each),
    /// with a workspace of its own (allocated per call: for the covariance, not the iterations).
    pub fn solve_columns_in_place(&self, rhs: &mut [f64], ncols: usize) {
        let n = self.symbolic.nrows();
        debug_assert_eq!(rhs.len(), n * ncols);
        let mut mem = MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(ncols, self.par));
        let llt = LltRef::new(&self.symbolic, &self.l_values);
        llt.solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(rhs, n, ncols),
            self.par,
            MemStack::new(&mut mem),
        );
    }

    /// Number of stored entries of the factor.
    pub fn factor_nnz(&self) -> usize {
        self.l_values.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 1D Laplacian plus identity (SPD) solved against a dense reference.
    #[test]
    fn solves_spd_system() {
        let n = 7;
        let mut pairs = Vec::new();
        for i in 0..n {
            pairs.push((i, i));
            if i + 1 < n {
                pairs.push((i, i + 1));
                pairs.push((i + 1, i));
            }
        }
        let p = CscPattern::from_pairs(n, &mut pairs);
        let mut v = vec![0.0; p.nnz()];
        for c in 0..n {
            for k in p.col_ptr[c]..p.col_ptr[c + 1] {
                v[k] = if p.row_idx[k] == c { 3.0 } else { -1.0 };
            }
        }
        let x: Vec<f64> = (0..n).map(|i| (i as f64).sin() + 0.5).collect();
        let mut b = vec![0.0; n];
        p.mul_vec(&v, &x, &mut b);
        let mut ch = Cholesky::factorize(&p, &v).unwrap();
        ch.solve_in_place(&mut b);
        for i in 0..n {
            assert!((b[i] - x[i]).abs() < 1e-12);
        }
        let mut ax = vec![0.0; n];
        p.mul_vec(&v, &x, &mut ax);
        let xax: f64 = x.iter().zip(&ax).map(|(a, b)| a * b).sum();
        assert!((quadratic_form(&p, &v, &x) - xax).abs() < 1e-12);
        // Singular: a zero row.
        let z = vec![0.0; p.nnz()];
        assert!(matches!(
            Cholesky::factorize(&p, &z),
            Err(DicError::Linear(_))
        ));
    }
}
