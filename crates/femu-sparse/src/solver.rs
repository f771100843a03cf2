//! [`SparseSolver`] checks the symmetry of every matrix: a symmetric one (in femu-mech:
//! hyperelastic elements, dead loads, follower pressure on closed outlines, which is
//! conservative, rigid bodies with their bordered force equation) is factorized by supernodal
//! LDLᵀ with an AMD ordering ([`SparseLdlt`]), by halves on two cores for large models
//! ([`SplitLdlt`]); an unsymmetric one (pressure on part of an outline) by sparse LU with
//! partial pivoting ([`SparseLu`]).

use crate::factor::{Factor, Factorization};
use crate::factor::{LinearSolveError, MAX_RHS};
use crate::linear::{SparseLdlt, SparseLu};
use crate::pattern::CscPattern;
use crate::split::{DofSplit, SplitLdlt};

/// Position of the transposed entry of each stored entry of `pattern` (rows sorted in each
/// column), or `None` if the pattern is not structurally symmetric.
///
/// One sweep instead of a binary search per entry: visiting the columns in increasing order,
/// the entries `(r, c)` of row `r` come in increasing `c`, which is exactly the order of the
/// rows of column `r`; so the transposed entry of the k-th visited entry of row `r` is the k-th
/// entry of column `r`, and checking that its row is `c` verifies the symmetry.
fn transpose_positions(pattern: &CscPattern) -> Option<Vec<u32>> {
    debug_assert!(pattern.nnz() <= u32::MAX as usize, "checked by the caller");
    let mut next: Vec<usize> = pattern.col_ptr[..pattern.n].to_vec();
    let mut transpose = Vec::with_capacity(pattern.nnz());
    for c in 0..pattern.n {
        for &r in &pattern.row_idx[pattern.col_ptr[c]..pattern.col_ptr[c + 1]] {
            let t = next[r];
            if t >= pattern.col_ptr[r + 1] || pattern.row_idx[t] != c {
                return None;
            }
            next[r] += 1;
            transpose.push(t as u32);
        }
    }
    Some(transpose)
}

/// Factorizes matrices on one pattern (Newton tangents in femu-mech), choosing LDLᵀ for
/// symmetric values and LU otherwise; both symbolic analyses are made at most once.
pub struct SparseSolver {
    /// Position of the transposed entry of each stored entry (32 bits: half the memory
    /// traffic of the asymmetry check before every factorization).
    transpose: Vec<u32>,
    /// The factorization tried first, for symmetric matrices ([`SparseLdlt`] or [`SplitLdlt`]).
    ldlt: Box<dyn Factor>,
    /// Analysed at the first unsymmetric (or not LDLᵀ-factorizable) matrix.
    lu: Option<SparseLu>,
    last: Option<Factorization>,
    /// Relative asymmetry above which LU is used.
    pub symmetry_tolerance: f64,
}

impl std::fmt::Debug for SparseSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SparseSolver")
            .field("last", &self.last)
            .finish()
    }
}

impl SparseSolver {
    /// Symbolic analysis for `pattern` (structurally symmetric), with an optional elimination
    /// order for the LDLᵀ (see [`SparseLdlt::new`]).
    pub fn new(pattern: &CscPattern, order: Option<&[usize]>) -> Result<Self, LinearSolveError> {
        Self::with_symmetric_factor(pattern, || {
            SparseLdlt::new(pattern, order).map(|f| Box::new(f) as Box<dyn Factor>)
        })
    }

    /// As [`Self::new`], with symmetric matrices factorized by halves of `split` in parallel
    /// ([`SplitLdlt`]).
    pub fn new_split(pattern: &CscPattern, split: &DofSplit) -> Result<Self, LinearSolveError> {
        Self::with_symmetric_factor(pattern, || {
            SplitLdlt::new(pattern, split).map(|f| Box::new(f) as Box<dyn Factor>)
        })
    }

    /// The transposed positions and the symbolic analysis (`factor`) are independent: one
    /// thread each.
    fn with_symmetric_factor(
        pattern: &CscPattern,
        factor: impl FnOnce() -> Result<Box<dyn Factor>, LinearSolveError> + Send,
    ) -> Result<Self, LinearSolveError> {
        if pattern.nnz() > u32::MAX as usize {
            return Err(LinearSolveError::Other(format!(
                "the tangent has {} entries, more than this solver addresses (2^32)",
                pattern.nnz()
            )));
        }
        let (transpose, ldlt) = rayon::join(|| transpose_positions(pattern), factor);
        let transpose = transpose.ok_or_else(|| {
            LinearSolveError::Other("pattern is not structurally symmetric".into())
        })?;
        Ok(SparseSolver {
            transpose,
            ldlt: ldlt?,
            lu: None,
            last: None,
            symmetry_tolerance: 1e-12,
        })
    }

    /// max |A - Aᵀ| / max |A| (in parallel over the entries: it runs before every
    /// factorization; maxima do not depend on the order).
    pub fn asymmetry(&self, values: &[f64]) -> f64 {
        use rayon::prelude::*;
        let (amax, dmax) = self
            .transpose
            .par_iter()
            .with_min_len(1 << 14)
            .enumerate()
            .map(|(k, &t)| (values[k].abs(), (values[k] - values[t as usize]).abs()))
            .reduce(|| (0.0f64, 0.0f64), |a, b| (a.0.max(b.0), a.1.max(b.1)));
        if amax > 0.0 {
            dmax / amax
        } else {
            0.0
        }
    }

    /// Factorizes `values`: LDLᵀ if symmetric and it succeeds, LU otherwise.
    pub fn factorize(
        &mut self,
        pattern: &CscPattern,
        values: &[f64],
    ) -> Result<Factorization, LinearSolveError> {
        self.last = None;
        if self.asymmetry(values) <= self.symmetry_tolerance
            && self.ldlt.factorize(pattern, values).is_ok()
        {
            self.last = Some(self.ldlt.kind());
            return Ok(self.ldlt.kind());
        }
        let lu = match &mut self.lu {
            Some(lu) => lu,
            None => self.lu.insert(SparseLu::new(pattern)?),
        };
        lu.factorize(pattern, values)?;
        self.last = Some(Factorization::Lu);
        Ok(Factorization::Lu)
    }

    /// The factorization used last, through which the solves go.
    fn factor(&mut self) -> &mut dyn Factor {
        match self.last {
            Some(Factorization::Lu) => self.lu.as_mut().expect("factorized"),
            Some(_) => self.ldlt.as_mut(),
            None => panic!("solve before factorize"),
        }
    }

    /// Solves `A x = rhs` in place with the last factorization.
    pub fn solve_in_place(&mut self, rhs: &mut [f64]) {
        self.factor().solve_in_place(rhs);
    }

    /// Solves `A X = B` in place for `columns` (≤ [`MAX_RHS`]) right-hand sides stored one
    /// after the other: one pass over the factors for all of them.
    pub fn solve_many_in_place(&mut self, rhs: &mut [f64], columns: usize) {
        self.factor().solve_many_in_place(rhs, columns);
    }

    /// Solves `Aᵀ x = rhs` in place with the last factorization.
    pub fn solve_transpose_in_place(&mut self, rhs: &mut [f64]) {
        self.factor().solve_transpose_in_place(rhs);
    }

    /// `Y = A X` for `cols` vectors stored interleaved (as [`CscPattern::mul_many_interleaved`]),
    /// by rows in parallel: row `r` of `A` is column `r` read through the transposed positions,
    /// so each output row is a gather owned by one thread (no scatter, no reduction).
    pub fn mul_many_interleaved(
        &self,
        pattern: &CscPattern,
        values: &[f64],
        x: &[f64],
        y: &mut [f64],
        cols: usize,
    ) {
        assert!(cols > 0 && x.len() == pattern.n * cols && y.len() == pattern.n * cols);
        assert_eq!(values.len(), pattern.nnz());
        /// The product with the number of columns known at compile time (registers, no
        /// bounds checks in the inner loop).
        fn rows<const C: usize>(
            pattern: &CscPattern,
            transpose: &[u32],
            values: &[f64],
            x: &[f64],
            y: &mut [f64],
        ) {
            use rayon::prelude::*;
            y.par_chunks_exact_mut(C)
                .with_min_len(256)
                .enumerate()
                .for_each(|(r, yr)| {
                    let mut acc = [0.0; C];
                    for k in pattern.col_ptr[r]..pattern.col_ptr[r + 1] {
                        let a = values[transpose[k] as usize];
                        let c = pattern.row_idx[k];
                        let xr: &[f64; C] = x[c * C..(c + 1) * C].try_into().expect("C values");
                        for j in 0..C {
                            acc[j] += a * xr[j];
                        }
                    }
                    yr.copy_from_slice(&acc);
                });
        }
        macro_rules! dispatch {
            ($($c:literal)*) => {
                match cols {
                    $($c => rows::<$c>(pattern, &self.transpose, values, x, y),)*
                    _ => unreachable!("at most MAX_RHS columns"),
                }
            };
        }
        assert!(cols <= MAX_RHS);
        dispatch!(1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16);
    }

    /// The factorization used last.
    pub fn last(&self) -> Option<Factorization> {
        self.last
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linear::NodeGraph;

    #[test]
    fn transpose_positions_match_a_search_per_entry() {
        let graph =
            NodeGraph::from_elements(6, [[0usize, 1, 4, 3], [1, 2, 5, 4]].iter().map(|e| &e[..]));
        // Node 3 fully prescribed, node 5 x only.
        let eq = [
            0,
            1,
            2,
            3,
            4,
            5,
            usize::MAX,
            usize::MAX,
            6,
            7,
            usize::MAX,
            8,
        ];
        let base = graph.dof_pattern(&eq, 9);
        let p = base.bordered(10, &[(9, vec![0, 4, 8])]);
        let t = transpose_positions(&p).unwrap();
        for c in 0..p.n {
            for k in p.col_ptr[c]..p.col_ptr[c + 1] {
                assert_eq!(Some(t[k] as usize), p.position(c, p.row_idx[k]));
            }
        }
        let mut pairs = vec![(0, 0), (1, 0), (1, 1), (2, 1), (2, 2), (1, 2)];
        assert!(transpose_positions(&CscPattern::from_pairs(3, &mut pairs)).is_none());
        let mut pairs = vec![(0, 0), (1, 0), (1, 1), (2, 2), (0, 2)];
        assert!(transpose_positions(&CscPattern::from_pairs(3, &mut pairs)).is_none());
    }

    /// Adjacency of two quads sharing an edge: sorted, self included.
    #[test]
    fn solves_small_unsymmetric_system() {
        // [[4, 1, 0], [2, 5, 1], [0, 1, 3]]
        let mut pairs = vec![(0, 0), (0, 1), (1, 0), (1, 1), (1, 2), (2, 1), (2, 2)];
        let p = CscPattern::from_pairs(3, &mut pairs);
        let mut v = vec![0.0; p.nnz()];
        for &(r, c, x) in &[
            (0, 0, 4.0),
            (0, 1, 1.0),
            (1, 0, 2.0),
            (1, 1, 5.0),
            (1, 2, 1.0),
            (2, 1, 1.0),
            (2, 2, 3.0),
        ] {
            v[p.position(r, c).unwrap()] = x;
        }
        let mut lu = SparseLu::new(&p).unwrap();
        lu.factorize(&p, &v).unwrap();
        let x = [1.0, -2.0, 0.5];
        let mut b = [0.0; 3];
        p.mul_vec(&v, &x, &mut b);
        lu.solve_in_place(&mut b);
        for k in 0..3 {
            assert!((b[k] - x[k]).abs() < 1e-13);
        }
        // Three vectors at once, interleaved, as three products.
        let xs = [1.0, -2.0, 0.5, 0.25, 3.0, -1.0, 2.0, 0.0, 4.0];
        let mut interleaved = [0.0; 9];
        for i in 0..3 {
            for j in 0..3 {
                interleaved[i * 3 + j] = xs[j * 3 + i];
            }
        }
        let mut y = [0.0; 9];
        p.mul_many_interleaved(&v, &interleaved, &mut y, 3);
        for j in 0..3 {
            p.mul_vec(&v, &xs[j * 3..(j + 1) * 3], &mut b);
            for i in 0..3 {
                assert_eq!(y[i * 3 + j], b[i]);
            }
        }
        let mut ts = SparseSolver::new(&p, None).unwrap();
        // The parallel row-wise product equals the column-wise one (unsymmetric values).
        let mut y_rows = [0.0; 9];
        ts.mul_many_interleaved(&p, &v, &interleaved, &mut y_rows, 3);
        assert_eq!(y_rows, y);
        assert_eq!(ts.factorize(&p, &v).unwrap(), Factorization::Lu);
        p.mul_vec(&v, &x, &mut b);
        ts.solve_in_place(&mut b);
        assert!(b.iter().zip(&x).all(|(a, e)| (a - e).abs() < 1e-13));
        // Symmetrize: LDLT is chosen.
        v[p.position(1, 0).unwrap()] = 1.0;
        v[p.position(2, 1).unwrap()] = 1.0;
        assert_eq!(ts.factorize(&p, &v).unwrap(), Factorization::Ldlt);
        p.mul_vec(&v, &x, &mut b);
        ts.solve_in_place(&mut b);
        assert!(b.iter().zip(&x).all(|(a, e)| (a - e).abs() < 1e-13));
    }
}
