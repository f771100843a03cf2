//! **Derived from faer 0.24.4** (<https://codeberg.org/sarah-quinones/faer>), MIT licence,
//! copyright sarah quiñones el kazdadi: the licence text is `LICENSE-faer` beside this file.
//! [`super::FAER_VERSION`] names the release this copy was checked against, and a test fails
//! when Cargo.lock moves faer (or `private-gemm-x86`, whose kernel is called here) to another
//! one.
//!
//! The source is faer's `factorize_supernodal_numeric_ldlt` (`faer/src/sparse/linalg/
//! cholesky.rs`, module `supernodal`): the same left-looking loop over the supernodes, the same
//! assembly of a supernode's columns through a global-to-local row map, the same descendant
//! update `L_s -= L_d D_d L_dᵀ` on the lower triangle by the kernel faer's `spicy_matmul`
//! calls (`private_gemm_x86::gemm`, `faer/src/linalg/matmul/internal/mod.rs`), and the same
//! dense LDLᵀ, unit triangular solve and `D⁻¹` scaling of each supernode. Changed here:
//!
//! - the factorization stops at the separator (`n_interior` columns; see below);
//! - the matrix is read through a [`LowerView`] (the entries of a half read from the whole
//!   tangent's values) instead of a `SparseColMatRef`;
//! - `f64` and `usize` only; no regularization, no parallelism (one half per core already);
//! - the descendants of each supernode are listed once per pattern ([`PartialLdlt::new`])
//!   instead of read from faer's row structure, and the workspace is kept between calls;
//! - without AVX2 and FMA the update runs in plain loops (faer uses its own portable matmul).
//!
//! Left-looking supernodal LDLᵀ stopped at the separator: the interior columns of a half are
//! factorized and the separator's columns only receive the interior's updates, so that they hold
//! the Schur complement `Ŝ = K_SS - K_SA K_AA⁻¹ K_AS` (lower triangle) when it returns.
//!
//! The whole factorization would go on to factorize the dense separator block (`s³/3` flops)
//! and [`crate::split`] then multiply it back into `Ŝ = L_SS D_S L_SSᵀ` (another `s³/3`); both
//! are skipped. For supernode `s` (columns `[s₀, s₁)`, rows: its
//! diagonal block then its pattern), every descendant `d` with rows in `s` subtracts
//! `L_{rows ≥ s₀, d} D_d L_{[s₀, s₁), d}ᵀ` (Duff & Reid 1983; the lower triangle only),
//! limited to `d`'s interior columns; then an interior supernode is factorized in place
//! (`L_top D L_topᵀ`, `L_bot ← L_bot L_top⁻ᵀ D⁻¹`), and a supernode holding the last interior
//! columns and the first separator ones is factorized up to the boundary and Schur-updates the
//! rest of its columns.

use crate::factor::LinearSolveError;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::ldlt::factor::{
    cholesky_in_place, cholesky_in_place_scratch, LdltError,
};
use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::solve_unit_lower_triangular_in_place;
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;
use faer::{Accum, MatMut, MatRef, Par};

const NONE: usize = usize::MAX;

/// The lower triangle of a matrix (CSC, rows sorted) whose values are read from another
/// matrix's: entry `k` (row `row_idx[k]`) is `values[source[k]]`. A half's entries are read
/// straight from the tangent's values, without a copy.
#[derive(Debug, Clone, Copy)]
pub struct LowerView<'a> {
    pub col_ptr: &'a [usize],
    pub row_idx: &'a [usize],
    pub source: &'a [usize],
    pub values: &'a [f64],
}

/// The structure and the workspace of [`PartialLdlt::factorize`], built once per pattern.
pub struct PartialLdlt {
    /// Per supernode `s`, the supernodes `d < s` with rows in `s` (CSR, `d` increasing): the
    /// row structure of the supernodal factor.
    descendants_ptr: Vec<usize>,
    descendants: Vec<usize>,
    /// Position of a global row in the current supernode (`NONE` outside it).
    global_to_local: Vec<usize>,
    /// Target rows and columns of one update.
    row_idx: Vec<usize>,
    col_idx: Vec<usize>,
    /// `D`-scaled rows of the boundary supernode's Schur update.
    scaled: Vec<f64>,
    mem: MemBuffer,
    avx2_fma: bool,
}

/// The supernode range `[begin, end)`, its pattern and its value range.
fn supernode(symbolic: &SymbolicSupernodalCholesky<usize>, s: usize) -> (usize, usize, &[usize]) {
    let begin = symbolic.supernode_begin()[s];
    let end = symbolic.supernode_end()[s];
    let start = symbolic.col_ptr_for_row_idx()[s];
    let pattern = &symbolic.row_idx()[start..start + symbolic.nnz_per_super()[s]];
    (begin, end, pattern)
}

impl PartialLdlt {
    pub fn new(symbolic: &SymbolicSupernodalCholesky<usize>) -> Self {
        let n = symbolic.nrows();
        let n_super = symbolic.n_supernodes();
        let mut super_of = vec![0usize; n];
        for s in 0..n_super {
            let (begin, end, _) = supernode(symbolic, s);
            super_of[begin..end].fill(s);
        }
        // (s, d) pairs: d's pattern rows are sorted, so the rows of one s are consecutive.
        let mut pairs: Vec<(usize, usize)> = Vec::new();
        let (mut max_rows, mut max_cols) = (0, 0);
        for d in 0..n_super {
            let (begin, end, pattern) = supernode(symbolic, d);
            max_rows = max_rows.max(end - begin + pattern.len());
            max_cols = max_cols.max(end - begin);
            let mut last = NONE;
            for &r in pattern {
                let s = super_of[r];
                if s != last {
                    pairs.push((s, d));
                    last = s;
                }
            }
        }
        let mut descendants_ptr = vec![0usize; n_super + 1];
        for &(s, _) in &pairs {
            descendants_ptr[s + 1] += 1;
        }
        for s in 0..n_super {
            descendants_ptr[s + 1] += descendants_ptr[s];
        }
        let mut next = descendants_ptr.clone();
        let mut descendants = vec![0usize; pairs.len()];
        for &(s, d) in &pairs {
            descendants[next[s]] = d;
            next[s] += 1;
        }
        PartialLdlt {
            descendants_ptr,
            descendants,
            global_to_local: vec![NONE; n],
            row_idx: vec![0; max_rows],
            col_idx: vec![0; max_rows],
            scaled: vec![0.0; max_rows * max_cols],
            mem: MemBuffer::new(cholesky_in_place_scratch::<f64>(
                max_cols,
                Par::Seq,
                Default::default(),
            )),
            avx2_fma: has_avx2_fma(),
        }
    }

    /// Factorizes the first `n_interior` columns of `a` (its lower triangle has the pattern
    /// analysed by `symbolic`) into `l_values` and leaves the Schur complement on the other
    /// columns in their places. A zero interior pivot is an error naming its column.
    pub fn factorize(
        &mut self,
        symbolic: &SymbolicSupernodalCholesky<usize>,
        l_values: &mut [f64],
        a: LowerView<'_>,
        n_interior: usize,
    ) -> Result<(), LinearSolveError> {
        let offsets = symbolic.col_ptr_for_val();
        assert_eq!(l_values.len(), symbolic.len_val());
        assert_eq!(a.col_ptr.len(), symbolic.nrows() + 1);
        assert_eq!(a.row_idx.len(), a.source.len());
        for s in 0..symbolic.n_supernodes() {
            let (s_start, s_end, s_pattern) = supernode(symbolic, s);
            let s_ncols = s_end - s_start;
            let s_nrows = s_ncols + s_pattern.len();
            for (i, &row) in s_pattern.iter().enumerate() {
                self.global_to_local[row] = i + s_ncols;
            }
            let (head, tail) = l_values.split_at_mut(offsets[s]);
            let ls = &mut tail[..offsets[s + 1] - offsets[s]];
            ls.fill(0.0);
            for j in s_start..s_end {
                let jj = j - s_start;
                for k in a.col_ptr[j]..a.col_ptr[j + 1] {
                    let (i, v) = (a.row_idx[k], a.values[a.source[k]]);
                    if i < j {
                        continue;
                    }
                    let ii = if i >= s_end {
                        self.global_to_local[i]
                    } else {
                        i - s_start
                    };
                    ls[ii + jj * s_nrows] += v;
                }
            }
            for &d in &self.descendants[self.descendants_ptr[s]..self.descendants_ptr[s + 1]] {
                let (d_start, d_end, d_pattern) = supernode(symbolic, d);
                // Only the interior columns of a descendant update (separator columns are not
                // eliminated).
                let d_cols = (d_end - d_start).min(n_interior.saturating_sub(d_start));
                if d_cols == 0 {
                    continue;
                }
                let d_nrows = d_end - d_start + d_pattern.len();
                let ld = &head[offsets[d]..offsets[d + 1]];
                let first = d_pattern.partition_point(|&r| r < s_start);
                let mid = d_pattern[first..].partition_point(|&r| r < s_end);
                let rows = d_pattern.len() - first;
                for (i, &r) in d_pattern[first..].iter().enumerate() {
                    self.row_idx[i] = if i < mid {
                        r - s_start
                    } else {
                        self.global_to_local[r]
                    };
                }
                for (j, &r) in d_pattern[first..first + mid].iter().enumerate() {
                    self.col_idx[j] = r - s_start;
                }
                let update = Update {
                    rows,
                    cols: mid,
                    depth: d_cols,
                    lower: &ld[d_end - d_start + first..],
                    stride: d_nrows,
                    diag: ld,
                };
                update.apply(
                    ls,
                    s_nrows,
                    &self.row_idx[..rows],
                    &self.col_idx[..mid],
                    self.avx2_fma,
                );
            }
            let m = s_ncols.min(n_interior.saturating_sub(s_start));
            if m > 0 {
                self.eliminate(ls, s_nrows, s_ncols, m)
                    .map_err(|e| match e {
                        LdltError::ZeroPivot { index } => {
                            LinearSolveError::Singular(s_start + index)
                        }
                    })?;
            }
            for &row in s_pattern {
                self.global_to_local[row] = NONE;
            }
        }
        Ok(())
    }

    /// Eliminates the first `m` columns of a supernode's block `ls` (`nrows` x `ncols`,
    /// column-major): `L_top D L_topᵀ` of the `m` x `m` diagonal block, `L_bot ← L_bot L_top⁻ᵀ
    /// D⁻¹` below it, and, when `m < ncols`, the Schur update of the remaining columns.
    fn eliminate(
        &mut self,
        ls: &mut [f64],
        nrows: usize,
        ncols: usize,
        m: usize,
    ) -> Result<(), LdltError> {
        let mut block = MatMut::from_column_major_slice_mut(ls, nrows, ncols);
        let (mut left, right) = block.rb_mut().split_at_col_mut(m);
        let (mut top, mut bot) = left.rb_mut().split_at_row_mut(m);
        cholesky_in_place(
            top.rb_mut(),
            Default::default(),
            Par::Seq,
            MemStack::new(&mut self.mem),
            Default::default(),
        )?;
        for j in 1..m {
            for i in 0..j {
                top[(i, j)] = 0.0;
            }
        }
        solve_unit_lower_triangular_in_place(top.rb(), bot.rb_mut().transpose_mut(), Par::Seq);
        for j in 0..m {
            let d = top[(j, j)].recip();
            for i in 0..nrows - m {
                bot[(i, j)] *= d;
            }
        }
        let rest = ncols - m;
        if rest > 0 {
            // right[m.., :] -= bot · D · bot[..rest]ᵀ (the rows of the remaining columns'
            // diagonal block and their pattern rows; the strict upper part is never read).
            let scaled = &mut self.scaled[..rest * m];
            for j in 0..m {
                let d = top[(j, j)];
                for i in 0..rest {
                    scaled[i + j * rest] = bot[(i, j)] * d;
                }
            }
            let (_, right_bot) = right.split_at_row_mut(m);
            matmul(
                right_bot,
                Accum::Add,
                bot.rb(),
                MatRef::from_column_major_slice(scaled, rest, m).transpose(),
                -1.0,
                Par::Seq,
            );
        }
        Ok(())
    }
}

/// `C[row_idx, col_idx] -= A · D · Bᵀ` on the lower triangle of a supernode's block, where
/// `A` (`rows` x `depth`) is a descendant's factor from its first row in the target on, `B` its
/// first `cols` rows and `D` the descendant's pivots (the diagonal of its block).
struct Update<'a> {
    rows: usize,
    cols: usize,
    depth: usize,
    /// `A`, column-major with column stride `stride`.
    lower: &'a [f64],
    stride: usize,
    /// The descendant's block, whose diagonal holds `D`.
    diag: &'a [f64],
}

impl Update<'_> {
    /// Applies the update, with faer's AVX2/FMA kernel when `simd` (the CPU has both; see
    /// [`has_avx2_fma`]), in plain loops otherwise.
    #[allow(unsafe_code)] // the one call into `private-gemm-x86`; see the SAFETY note
    fn apply(
        &self,
        c: &mut [f64],
        c_rows: usize,
        row_idx: &[usize],
        col_idx: &[usize],
        simd: bool,
    ) {
        if self.rows == 0 || self.cols == 0 {
            return;
        }
        // The bounds the kernel relies on.
        assert!(row_idx.iter().all(|&i| i < c_rows));
        assert!(col_idx.iter().all(|&j| (j + 1) * c_rows <= c.len()));
        assert!((self.depth - 1) * self.stride + self.rows <= self.lower.len());
        assert!((self.depth - 1) * (self.stride + 1) < self.diag.len());
        if simd {
            #[cfg(target_arch = "x86_64")]
            {
                let alpha = -1.0f64;
                // SAFETY: the destination is `c` (column-major, `c_rows` rows) addressed only
                // through `row_idx` x `col_idx`, in bounds as asserted; `A` is `rows` x `depth`
                // with column stride `stride` inside `lower`, `Bᵀ` its first `cols` rows (the
                // same storage, transposed: row stride `stride`, column stride 1), `D` the
                // `depth` diagonal entries of `diag` (stride `stride + 1`), all in bounds as
                // asserted; AVX2 and FMA were detected; one thread. This is the call faer's
                // `spicy_matmul` makes for its supernodal LDLᵀ.
                unsafe {
                    private_gemm_x86::gemm(
                        private_gemm_x86::DType::F64,
                        private_gemm_x86::IType::U64,
                        private_gemm_x86::InstrSet::Avx256,
                        self.rows,
                        self.cols,
                        self.depth,
                        c.as_mut_ptr() as *mut (),
                        1,
                        c_rows as isize,
                        row_idx.as_ptr() as *const (),
                        col_idx.as_ptr() as *const (),
                        private_gemm_x86::DstKind::Lower,
                        private_gemm_x86::Accum::Add,
                        self.lower.as_ptr() as *const (),
                        1,
                        self.stride as isize,
                        false,
                        self.diag.as_ptr() as *const (),
                        (self.stride + 1) as isize,
                        self.lower.as_ptr() as *const (),
                        self.stride as isize,
                        1,
                        false,
                        &raw const alpha as *const (),
                        1,
                    );
                }
                return;
            }
        }
        self.apply_portable(c, c_rows, row_idx, col_idx);
    }

    /// The same update in plain loops (machines without AVX2 and FMA; the tests' reference).
    fn apply_portable(&self, c: &mut [f64], c_rows: usize, row_idx: &[usize], col_idx: &[usize]) {
        // Rows and columns come from the same sorted pattern: row i is on or below column j
        // for i >= j.
        for (j, &cj) in col_idx.iter().enumerate() {
            let col = &mut c[cj * c_rows..(cj + 1) * c_rows];
            for (i, &ri) in row_idx.iter().enumerate().skip(j) {
                let mut sum = 0.0;
                for k in 0..self.depth {
                    let at = k * self.stride;
                    sum += self.lower[i + at] * (self.diag[at + k] * self.lower[j + at]);
                }
                col[ri] -= sum;
            }
        }
    }
}

impl std::fmt::Debug for PartialLdlt {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PartialLdlt")
            .field("supernodes", &(self.descendants_ptr.len() - 1))
            .field("updates", &self.descendants.len())
            .finish()
    }
}

/// Whether the CPU has AVX2 and FMA, which the `private-gemm-x86` kernel of [`Update::apply`]
/// is compiled for.
fn has_avx2_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linear::NodeGraph;
    use crate::split::supernodal;
    use faer::sparse::linalg::cholesky::{
        factorize_symbolic_cholesky, CholeskySymbolicParams, SymbolicCholesky, SymmetricOrdering,
    };
    use faer::sparse::linalg::SupernodalThreshold;
    use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
    use faer::Side;
    use rand::{Rng, SeedableRng};

    /// A 14 x 9 grid of quads with its equations in AMD's node order, a random symmetric
    /// positive definite matrix on it (per element `BᵀB + I`, assembled): the lower triangle
    /// (CSC, rows sorted) and faer's supernodal symbolic analysis of it (identity ordering,
    /// supernodes forced, as the halves of `split` are analysed).
    fn system() -> (
        usize,
        Vec<usize>,
        Vec<usize>,
        Vec<f64>,
        SymbolicCholesky<usize>,
    ) {
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        let (nx, ny) = (14, 9);
        let node = |i: usize, j: usize| j * (nx + 1) + i;
        let quads: Vec<[usize; 4]> = (0..ny)
            .flat_map(|j| {
                (0..nx).map(move |i| {
                    [
                        node(i, j),
                        node(i + 1, j),
                        node(i + 1, j + 1),
                        node(i, j + 1),
                    ]
                })
            })
            .collect();
        let n_nodes = (nx + 1) * (ny + 1);
        let graph = NodeGraph::from_elements(n_nodes, quads.iter().map(|q| &q[..]));
        let (_, rank) = graph.amd_node_order().unwrap();
        let n = 2 * n_nodes;
        let mut dense = vec![0.0; n * n];
        for q in &quads {
            let dofs: Vec<usize> = q
                .iter()
                .flat_map(|&a| [2 * rank[a], 2 * rank[a] + 1])
                .collect();
            let b: Vec<f64> = (0..64).map(|_| rng.gen_range(-1.0..1.0)).collect();
            for r in 0..8 {
                for c in 0..8 {
                    let v: f64 = (0..8).map(|k| b[k * 8 + r] * b[k * 8 + c]).sum();
                    dense[dofs[r] + dofs[c] * n] += v + f64::from(u8::from(r == c));
                }
            }
        }
        let (mut col_ptr, mut row_idx, mut values) = (vec![0], Vec::new(), Vec::new());
        for c in 0..n {
            for r in c..n {
                let v = dense[r + c * n];
                if v != 0.0 {
                    row_idx.push(r);
                    values.push(v);
                }
            }
            col_ptr.push(row_idx.len());
        }
        // With the identity ordering faer's symbolic analysis reads the upper triangle as
        // given (whatever the side), its numeric factorization the lower one.
        let (mut upper_ptr, mut upper_idx) = (vec![0], Vec::new());
        for c in 0..n {
            upper_idx.extend((0..=c).filter(|&r| dense[r + c * n] != 0.0));
            upper_ptr.push(upper_idx.len());
        }
        let upper = SymbolicSparseColMatRef::new_checked(n, n, &upper_ptr, None, &upper_idx);
        let symbolic = factorize_symbolic_cholesky(
            upper,
            Side::Upper,
            SymmetricOrdering::Identity,
            CholeskySymbolicParams {
                supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
                ..Default::default()
            },
        )
        .unwrap();
        (n, col_ptr, row_idx, values, symbolic)
    }

    /// The view of a lower triangle holding its own values (`source` the identity).
    fn own_values<'a>(
        col_ptr: &'a [usize],
        row_idx: &'a [usize],
        source: &'a [usize],
        values: &'a [f64],
    ) -> LowerView<'a> {
        LowerView {
            col_ptr,
            row_idx,
            source,
            values,
        }
    }

    /// Stopped inside a supernode (so that one supernode holds interior and separator
    /// columns), the partial factorization gives faer's whole factor on the interior columns and
    /// `L_SS D_S L_SSᵀ` (from faer's factor) on the separator; the plain-loop update gives the
    /// same as the SIMD kernel.
    #[test]
    fn partial_ldlt_matches_the_whole_factorization() {
        let (n, col_ptr, row_idx, values, symbolic) = system();
        let sn = supernodal(&symbolic);
        let a = SparseColMatRef::new(
            SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx),
            &values,
        );
        let source: Vec<usize> = (0..values.len()).collect();
        let view = own_values(&col_ptr, &row_idx, &source, &values);
        // The boundary: one column into the last supernode of at least three columns that
        // starts past the middle.
        let straddled = (0..sn.n_supernodes())
            .rev()
            .find(|&s| {
                let (b, e) = (sn.supernode_begin()[s], sn.supernode_end()[s]);
                e - b >= 3 && b > n / 2
            })
            .expect("a wide supernode");
        let n_interior = sn.supernode_begin()[straddled] + 1;
        let s = n - n_interior;
        assert!(s >= 10, "separator of {s} equations");

        let mut whole = vec![0.0; symbolic.len_val()];
        let mut mem = MemBuffer::new(
            symbolic.factorize_numeric_ldlt_scratch::<f64>(Par::Seq, Default::default()),
        );
        symbolic
            .factorize_numeric_ldlt(
                &mut whole,
                a,
                Side::Lower,
                Default::default(),
                Par::Seq,
                MemStack::new(&mut mem),
                Default::default(),
            )
            .unwrap();
        // Dense L (unit diagonal) and D of the whole factor.
        let mut l = vec![0.0; n * n];
        let mut d = vec![0.0; n];
        let offsets = sn.col_ptr_for_val();
        for k in 0..sn.n_supernodes() {
            let (begin, end, pattern) = supernode(sn, k);
            let rows = end - begin + pattern.len();
            let block = &whole[offsets[k]..offsets[k + 1]];
            for jj in 0..end - begin {
                d[begin + jj] = block[jj + jj * rows];
                l[begin + jj + (begin + jj) * n] = 1.0;
                for ii in jj + 1..end - begin {
                    l[begin + ii + (begin + jj) * n] = block[ii + jj * rows];
                }
                for (idx, &r) in pattern.iter().enumerate() {
                    l[r + (begin + jj) * n] = block[end - begin + idx + jj * rows];
                }
            }
        }

        for simd in [true, false] {
            let mut partial = PartialLdlt::new(sn);
            partial.avx2_fma &= simd;
            let mut l_values = vec![0.0; symbolic.len_val()];
            partial
                .factorize(sn, &mut l_values, view, n_interior)
                .unwrap();
            let scale = whole.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let mut schur_scale = 0.0f64;
            let mut max_diff = [0.0f64; 2];
            for k in 0..sn.n_supernodes() {
                let (begin, end, pattern) = supernode(sn, k);
                let rows = end - begin + pattern.len();
                let block = &l_values[offsets[k]..offsets[k + 1]];
                for jj in 0..end - begin {
                    let j = begin + jj;
                    for ii in jj..rows {
                        let i = if ii < end - begin {
                            begin + ii
                        } else {
                            pattern[ii - (end - begin)]
                        };
                        let got = block[ii + jj * rows];
                        if j < n_interior {
                            let expected = whole[offsets[k] + ii + jj * rows];
                            max_diff[0] = max_diff[0].max((got - expected).abs());
                        } else {
                            // Ŝ_ij = Σ_{k ≥ n_interior} L_ik d_k L_jk.
                            let expected: f64 = (n_interior..=j)
                                .map(|q| l[i + q * n] * d[q] * l[j + q * n])
                                .sum();
                            schur_scale = schur_scale.max(expected.abs());
                            max_diff[1] = max_diff[1].max((got - expected).abs());
                        }
                    }
                }
            }
            // Same operations as faer's on the interior (up to the order of the updates'
            // additions) and one product of factors from a matrix of condition ~1e2 on the
            // separator: rounding level.
            assert!(
                max_diff[0] <= 1e-12 * scale,
                "interior (simd {simd}): {max_diff:?}"
            );
            assert!(
                max_diff[1] <= 1e-11 * schur_scale,
                "separator (simd {simd}): {max_diff:?}, scale {schur_scale}"
            );
        }
    }

    /// A zero interior pivot is reported with its column.
    #[test]
    fn partial_ldlt_reports_a_zero_pivot() {
        let (n, col_ptr, row_idx, mut values, symbolic) = system();
        let sn = supernodal(&symbolic);
        // Column 0 zeroed: its pivot is exactly zero.
        for v in &mut values[col_ptr[0]..col_ptr[1]] {
            *v = 0.0;
        }
        let source: Vec<usize> = (0..values.len()).collect();
        let view = own_values(&col_ptr, &row_idx, &source, &values);
        let mut l_values = vec![0.0; symbolic.len_val()];
        let err = PartialLdlt::new(sn)
            .factorize(sn, &mut l_values, view, n / 2)
            .unwrap_err();
        assert!(matches!(err, LinearSolveError::Singular(0)), "{err}");
    }
}
