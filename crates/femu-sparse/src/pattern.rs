//! The sparsity pattern of a square matrix in compressed-sparse-column form, built once per
//! mesh and shared by every factorization of it.

use faer::sparse::SymbolicSparseColMatRef;

/// A compressed-sparse-column pattern (square), built once per mesh.
#[derive(Debug, Clone)]
pub struct CscPattern {
    pub n: usize,
    pub col_ptr: Vec<usize>,
    pub row_idx: Vec<usize>,
}

impl CscPattern {
    /// Builds the pattern from (row, col) pairs (duplicates allowed), rows sorted in each
    /// column: the DIC's element couplings, small hand-made matrices (a finite-element mesh
    /// uses [`crate::NodeGraph::dof_pattern`]).
    pub fn from_pairs(n: usize, pairs: &mut Vec<(usize, usize)>) -> Self {
        pairs.sort_unstable_by_key(|&(r, c)| (c, r));
        pairs.dedup();
        let mut col_ptr = vec![0usize; n + 1];
        let mut row_idx = Vec::with_capacity(pairs.len());
        for &(r, c) in pairs.iter() {
            col_ptr[c + 1] += 1;
            row_idx.push(r);
        }
        for c in 0..n {
            col_ptr[c + 1] += col_ptr[c];
        }
        CscPattern {
            n,
            col_ptr,
            row_idx,
        }
    }

    /// This pattern bordered by extra rows and columns: border `(q, rows)` is the equation `q`
    /// (numbered after every equation of `self`, in increasing order) coupled with the sorted
    /// equations `rows` of `self`; the result is `n_total x n_total` and structurally symmetric.
    /// Without borders `self` is returned as it is (no copy).
    pub fn bordered(self, n_total: usize, borders: &[(usize, Vec<usize>)]) -> CscPattern {
        if borders.is_empty() && n_total == self.n {
            return self;
        }
        let mut extra: Vec<Vec<usize>> = vec![Vec::new(); self.n];
        for (q, rows) in borders {
            for &r in rows {
                extra[r].push(*q);
            }
        }
        let mut col_ptr = Vec::with_capacity(n_total + 1);
        let mut row_idx = Vec::with_capacity(
            self.nnz() + 2 * borders.iter().map(|b| b.1.len() + 1).sum::<usize>(),
        );
        col_ptr.push(0);
        for c in 0..self.n {
            row_idx.extend_from_slice(&self.row_idx[self.col_ptr[c]..self.col_ptr[c + 1]]);
            row_idx.extend_from_slice(&extra[c]);
            col_ptr.push(row_idx.len());
        }
        for (q, rows) in borders {
            debug_assert_eq!(
                *q,
                col_ptr.len() - 1,
                "borders are numbered after the base equations"
            );
            row_idx.extend_from_slice(rows);
            row_idx.push(*q);
            col_ptr.push(row_idx.len());
        }
        debug_assert_eq!(col_ptr.len(), n_total + 1);
        CscPattern {
            n: n_total,
            col_ptr,
            row_idx,
        }
    }

    /// Number of stored entries.
    pub fn nnz(&self) -> usize {
        self.row_idx.len()
    }

    /// Position of entry (r, c) in the value array.
    pub fn position(&self, r: usize, c: usize) -> Option<usize> {
        let range = self.col_ptr[c]..self.col_ptr[c + 1];
        self.row_idx[range.clone()]
            .binary_search(&r)
            .ok()
            .map(|k| range.start + k)
    }

    pub(crate) fn symbolic(&self) -> SymbolicSparseColMatRef<'_, usize> {
        SymbolicSparseColMatRef::new_checked(self.n, self.n, &self.col_ptr, None, &self.row_idx)
    }

    /// `y = A x` for values on this pattern.
    pub fn mul_vec(&self, values: &[f64], x: &[f64], y: &mut [f64]) {
        y.fill(0.0);
        for c in 0..self.n {
            for k in self.col_ptr[c]..self.col_ptr[c + 1] {
                y[self.row_idx[k]] += values[k] * x[c];
            }
        }
    }

    /// `Y = A X` for `cols` vectors stored interleaved (`x[i * cols + j]`: row `i` of vector
    /// `j`, and `y` likewise) in one pass over the matrix for all the vectors: each stored
    /// entry is read once, in order, and used for `cols` contiguous multiply-adds (faster than
    /// `cols` separate products, which read the matrix `cols` times).
    pub fn mul_many_interleaved(&self, values: &[f64], x: &[f64], y: &mut [f64], cols: usize) {
        assert!(cols > 0 && x.len() == self.n * cols && y.len() == self.n * cols);
        assert_eq!(values.len(), self.nnz());
        y.fill(0.0);
        for c in 0..self.n {
            let xc = &x[c * cols..(c + 1) * cols];
            for k in self.col_ptr[c]..self.col_ptr[c + 1] {
                let a = values[k];
                let r = self.row_idx[k];
                for (yj, xj) in y[r * cols..(r + 1) * cols].iter_mut().zip(xc) {
                    *yj += a * xj;
                }
            }
        }
    }
}
