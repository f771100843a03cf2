//! Domain-split sparse LDLᵀ: the two halves of the mesh factorized at the same time, one per
//! core, coupled through a dense Schur complement on the separator.
//!
//! faer's supernodal LDLᵀ runs its supernodes one after the other, so on a plane mesh it uses one
//! core. The elimination tree of the AMD ordering has, near its root, two groups of disjoint
//! subtrees of about equal work ([`NodeGraph::split_by_elimination_tree`]); their equations are
//! the interiors `A` and `B`, which are not coupled, and the ancestors left over are a vertex
//! separator `S`, so that the tangent is, in the order `[A, B, S]`,
//!
//! ```text
//!     K = | K_AA   0     K_AS |
//!         | 0      K_BB  K_BS |
//!         | K_SA   K_SB  K_SS |
//! ```
//!
//! Each half `M_A = [K_AA K_AS; K_SA K_SS]` (a principal submatrix of `K`, so as definite as
//! `K`) is analysed by faer (supernodal symbolic LDLᵀ) with its interior in AMD's order and the
//! separator last (the same factor entries as AMD's whole factorization, so no extra fill), and
//! factorized by [`PartialLdlt`] (derived from faer's, [`crate::vendored`]) up to the separator:
//! its interior columns hold `L_AA`, `D_A` and `L_SA`, and its separator columns are left
//! holding `Ŝ_A = K_SS - K_SA K_AA⁻¹ K_AS`. The Schur complement of `K` on the separator is then
//! `S̃ = Ŝ_A + Ŝ_B - K_SS` (dense: Cholesky when definite, LU with partial pivoting otherwise),
//! and a solve is the block forward substitution through the interiors of both factors (in
//! parallel), a dense solve on the separator, and the block back substitution (in parallel).
//! This is the first level of a nested-dissection multifrontal factorization (George 1973;
//! Duff & Reid 1983).

use crate::factor::{rhs_rows, Factor, Factorization};
use crate::factor::{LinearSolveError, MAX_RHS};
use crate::linear::NodeGraph;
use crate::pattern::CscPattern;
use crate::vendored::faer_supernodal::{LowerView, PartialLdlt};
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::reborrow::ReborrowMut;
use faer::sparse::linalg::cholesky::supernodal::{SupernodalLdltRef, SymbolicSupernodalCholesky};
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, SymbolicCholesky, SymbolicCholeskyRaw,
    SymmetricOrdering,
};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::SymbolicSparseColMatRef;
use faer::{MatMut, MatRef, Par, Side};

const NONE: usize = usize::MAX;

/// A cut of the free equations: two interiors (each in its elimination order) that do not
/// touch, and the separator between them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DofSplit {
    pub interiors: [Vec<usize>; 2],
    pub separator: Vec<usize>,
}

/// The transposed pattern (rows sorted).
fn transpose(pattern: &CscPattern) -> CscPattern {
    let n = pattern.n;
    let mut col_ptr = vec![0usize; n + 1];
    for &r in &pattern.row_idx {
        col_ptr[r + 1] += 1;
    }
    for c in 0..n {
        col_ptr[c + 1] += col_ptr[c];
    }
    let mut next = col_ptr.clone();
    let mut row_idx = vec![0usize; pattern.nnz()];
    for c in 0..n {
        for &r in &pattern.row_idx[pattern.col_ptr[c]..pattern.col_ptr[c + 1]] {
            row_idx[next[r]] = c;
            next[r] += 1;
        }
    }
    CscPattern {
        n,
        col_ptr,
        row_idx,
    }
}

/// The supernodal structure of a factorization made with supernodes forced.
pub(crate) fn supernodal(symbolic: &SymbolicCholesky<usize>) -> &SymbolicSupernodalCholesky<usize> {
    match symbolic.raw() {
        SymbolicCholeskyRaw::Supernodal(s) => s,
        SymbolicCholeskyRaw::Simplicial(_) => unreachable!("supernodes are forced"),
    }
}

/// Largest share of the work one half may take in [`NodeGraph::split_by_elimination_tree`].
pub const MAX_HALF_SHARE: f64 = 0.55;

/// Largest separator (nodes) [`NodeGraph::split_by_elimination_tree`] looks for.
pub const MAX_SEPARATOR_NODES: usize = 1000;

impl NodeGraph {
    /// Splits along the elimination tree of the AMD ordering: two groups of disjoint subtrees
    /// that share the factorization work about equally, and the separator made of the
    /// ancestors they leave (the top of the tree, where AMD's factor is already dense). The
    /// halves keep AMD's order, so the split adds no fill: the total factor is AMD's.
    ///
    /// Starting from the roots, the candidate subtrees are shared between two groups (heaviest
    /// first into the lighter group); while the heavier group exceeds [`MAX_HALF_SHARE`] of the
    /// work, the heaviest subtree's root moves to the separator and its children become
    /// candidates. The work of a subtree is the sum over its node columns of (free dofs x
    /// column count)², the flops of their elimination. `None` when no balance is found within
    /// [`MAX_SEPARATOR_NODES`].
    pub fn split_by_elimination_tree(
        &self,
        eq: &[usize],
    ) -> Result<Option<DofSplit>, LinearSolveError> {
        use faer::sparse::linalg::cholesky::simplicial::prefactorize_symbolic_cholesky;
        let n_nodes = self.ptr.len() - 1;
        let (perm, perm_inv) = self.amd_node_order()?;
        // Upper triangle of the node graph in elimination order.
        let mut col_ptr = Vec::with_capacity(n_nodes + 1);
        let mut row_idx = Vec::with_capacity(self.adj.len() / 2 + n_nodes);
        col_ptr.push(0);
        for &node in &perm {
            let k = perm_inv[node];
            let start = row_idx.len();
            row_idx.extend(
                self.adj[self.ptr[node]..self.ptr[node + 1]]
                    .iter()
                    .map(|&m| perm_inv[m])
                    .filter(|&r| r <= k),
            );
            row_idx[start..].sort_unstable();
            col_ptr.push(row_idx.len());
        }
        let mut etree = vec![0isize; n_nodes];
        let mut counts = vec![0usize; n_nodes];
        let mut mem = MemBuffer::new(StackReq::new::<usize>(n_nodes));
        prefactorize_symbolic_cholesky::<usize>(
            &mut etree,
            &mut counts,
            SymbolicSparseColMatRef::new_checked(n_nodes, n_nodes, &col_ptr, None, &row_idx),
            MemStack::new(&mut mem),
        );
        let parent = |k: usize| usize::try_from(etree[k]).ok();
        // Subtree work (a parent is eliminated after its children).
        // A node's free dofs (prescribed ones are not in the tangent).
        let dofs = |node: usize| {
            (usize::from(eq[2 * node] != NONE) + usize::from(eq[2 * node + 1] != NONE)) as f64
        };
        // The work of a column: its squared entry count (free dofs times the node's count).
        let mut work: Vec<f64> = counts
            .iter()
            .zip(&perm)
            .map(|(&c, &node)| (dofs(node) * c as f64).powi(2))
            .collect();
        let mut children: Vec<Vec<usize>> = vec![Vec::new(); n_nodes];
        let mut candidates = Vec::new();
        for k in 0..n_nodes {
            match parent(k) {
                Some(p) => {
                    work[p] += work[k];
                    children[p].push(k);
                }
                None => candidates.push(k),
            }
        }
        let mut separator: Vec<usize> = Vec::new();
        let bins = loop {
            candidates.sort_unstable_by(|&a, &b| work[b].total_cmp(&work[a]));
            let total: f64 = candidates.iter().map(|&k| work[k]).sum();
            let mut bins = [Vec::new(), Vec::new()];
            let mut load = [0.0f64; 2];
            for &k in &candidates {
                let lighter = usize::from(load[1] < load[0]);
                bins[lighter].push(k);
                load[lighter] += work[k];
            }
            if total > 0.0 && load[0].max(load[1]) <= MAX_HALF_SHARE * total {
                break bins;
            }
            if candidates.is_empty() || separator.len() >= MAX_SEPARATOR_NODES {
                return Ok(None);
            }
            let heaviest = candidates.remove(0);
            separator.push(heaviest);
            candidates.extend_from_slice(&children[heaviest]);
        };
        // Label every elimination step: separator 2, then each subtree by its group (top down).
        let mut label = vec![u8::MAX; n_nodes];
        for &k in &separator {
            label[k] = 2;
        }
        for (b, roots) in bins.iter().enumerate() {
            for &k in roots {
                label[k] = b as u8;
            }
        }
        for k in (0..n_nodes).rev() {
            if label[k] == u8::MAX {
                label[k] = label[parent(k).expect("a non-root outside the separator")];
            }
        }
        let mut interiors = [Vec::new(), Vec::new()];
        let mut separator_eqs = Vec::new();
        for (k, &node) in perm.iter().enumerate() {
            let dofs = [eq[2 * node], eq[2 * node + 1]]
                .into_iter()
                .filter(|&q| q != NONE);
            match label[k] {
                2 => separator_eqs.extend(dofs),
                b => interiors[b as usize].extend(dofs),
            }
        }
        if interiors.iter().any(|i| i.is_empty()) {
            return Ok(None);
        }
        Ok(Some(DofSplit {
            interiors,
            separator: separator_eqs,
        }))
    }
}

/// Runs `$half.$method::<K>()` for the run-time column count `$k` (1 ..= [`MAX_RHS`]), compiled
/// for AVX2 where the CPU has it ([`crate::simd`]).
macro_rules! with_columns {
    ($half:ident, $k:expr, $method:ident) => {
        with_columns!(@ $half, $k, $method; 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16)
    };
    (@ $half:ident, $k:expr, $method:ident; $($n:literal)*) => {{
        const _: () = assert!(MAX_RHS == 16, "one arm per column count");
        match $k {
            $($n => crate::simd::with_avx2(
                #[inline(always)]
                || $half.$method::<$n>(),
            ),)*
            _ => unreachable!("at most MAX_RHS columns"),
        }
    }};
}

/// One half: the interior's equations then the separator's, factorized up to the separator.
struct Half {
    /// Equation of each local row, in elimination order: `n_interior` interior ones, then the
    /// separator's.
    eqs: Vec<usize>,
    n_interior: usize,
    /// Lower triangle of this half's matrix (local numbering, rows sorted).
    pattern: CscPattern,
    /// Position in the tangent's values of each stored entry of `pattern`.
    source: Vec<usize>,
    symbolic: SymbolicCholesky<usize>,
    l_values: Vec<f64>,
    /// 1 / D of the interior pivots.
    inv_d: Vec<f64>,
    /// The interior's factorization, stopped at the separator.
    partial: PartialLdlt,
    /// `Ŝ = K_SS - K_SA K_AA⁻¹ K_AS` (s x s column-major, lower triangle).
    schur: Vec<f64>,
    /// Local right-hand sides, interleaved (`work[i * k + j]`: local row `i` of column `j` of
    /// `k` ≤ MAX_RHS), and the rows of one supernode's pattern (gathered or updated) for them.
    work: Vec<f64>,
    tmp: Vec<f64>,
}

impl Half {
    fn new(
        pattern: &CscPattern,
        interior: &[usize],
        separator: &[usize],
    ) -> Result<Self, LinearSolveError> {
        let n_interior = interior.len();
        let eqs: Vec<usize> = interior.iter().chain(separator).copied().collect();
        let n = eqs.len();
        let mut local = vec![NONE; pattern.n];
        for (i, &q) in eqs.iter().enumerate() {
            local[q] = i;
        }
        // The pattern is structurally symmetric: the lower triangle of the half holds at most
        // (entries of its columns + n) / 2 (no growth, no copies of these 2 MB vectors).
        let capacity = (eqs
            .iter()
            .map(|&q| pattern.col_ptr[q + 1] - pattern.col_ptr[q])
            .sum::<usize>()
            + n)
            / 2;
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx = Vec::with_capacity(capacity);
        let mut source = Vec::with_capacity(capacity);
        let mut column: Vec<(usize, usize)> = Vec::new();
        col_ptr.push(0);
        for (j, &q) in eqs.iter().enumerate() {
            column.clear();
            for k in pattern.col_ptr[q]..pattern.col_ptr[q + 1] {
                let i = local[pattern.row_idx[k]];
                if i != NONE && i >= j {
                    column.push((i, k));
                }
            }
            column.sort_unstable();
            row_idx.extend(column.iter().map(|c| c.0));
            source.extend(column.iter().map(|c| c.1));
            col_ptr.push(row_idx.len());
        }
        let lower = CscPattern {
            n,
            col_ptr,
            row_idx,
        };
        // With the identity ordering faer's symbolic analysis reads the upper triangle as
        // given (whatever the side), and its supernodal numeric factorization the lower one.
        let upper = transpose(&lower);
        let symbolic = factorize_symbolic_cholesky(
            SymbolicSparseColMatRef::new_checked(n, n, &upper.col_ptr, None, &upper.row_idx),
            Side::Upper,
            SymmetricOrdering::Identity,
            CholeskySymbolicParams {
                supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
                ..Default::default()
            },
        )
        .map_err(|e| LinearSolveError::Other(format!("symbolic LDLT of a half: {e:?}")))?;
        let SymbolicCholeskyRaw::Supernodal(supernodal) = symbolic.raw() else {
            return Err(LinearSolveError::Other(
                "expected a supernodal factorization".into(),
            ));
        };
        let max_pattern = (0..supernodal.n_supernodes())
            .map(|s| supernodal.nnz_per_super()[s])
            .max()
            .unwrap_or(0);
        let s = separator.len();
        let partial = PartialLdlt::new(supernodal);
        Ok(Half {
            l_values: vec![0.0; symbolic.len_val()],
            eqs,
            n_interior,
            pattern: lower,
            source,
            symbolic,
            inv_d: vec![0.0; n_interior],
            partial,
            schur: vec![0.0; s * s],
            work: vec![0.0; n * MAX_RHS],
            tmp: vec![0.0; max_pattern * MAX_RHS],
        })
    }

    /// Factorizes this half of `tangent` and forms its separator Schur complement.
    fn factorize(&mut self, tangent: &[f64]) -> Result<(), LinearSolveError> {
        let n = self.eqs.len();
        let a = LowerView {
            col_ptr: &self.pattern.col_ptr,
            row_idx: &self.pattern.row_idx,
            source: &self.source,
            values: tangent,
        };
        let n_interior = self.n_interior;
        let s = n - n_interior;
        let symbolic = supernodal(&self.symbolic);
        let eqs = &self.eqs;
        self.partial
            .factorize(symbolic, &mut self.l_values, a, n_interior)
            .map_err(|e| match e {
                // A local column: its equation.
                LinearSolveError::Singular(i) => LinearSolveError::Singular(eqs[i]),
                other => other,
            })?;
        // The interior pivots, and the separator's columns: Ŝ's lower triangle.
        self.schur.fill(0.0);
        let factor = SupernodalLdltRef::new(symbolic, &self.l_values);
        for sn in 0..symbolic.n_supernodes() {
            let node = factor.supernode(sn);
            let start = node.start();
            let ls = node.val();
            let ncols = ls.ncols();
            for jj in 0..ncols {
                let j = start + jj;
                if j < n_interior {
                    self.inv_d[j] = ls[(jj, jj)].recip();
                    continue;
                }
                let lj = j - n_interior;
                let col = &mut self.schur[lj * s..(lj + 1) * s];
                for ii in jj..ncols {
                    col[start + ii - n_interior] = ls[(ii, jj)];
                }
                for (idx, &r) in node.pattern().iter().enumerate() {
                    col[r - n_interior] = ls[(ncols + idx, jj)];
                }
            }
        }
        // Non-finite factors are caught at the pivots, without a pass over all of L: an entry
        // L_ij comes out non-finite from a zero or non-finite pivot d_j, or from non-finite
        // input, and then turns non-finite the pivot d_i of its row's column (d_i -= L_ij² d_j)
        // or, for a separator row, the Schur complement, which `SplitLdlt::factorize` checks.
        if !self.inv_d.iter().all(|d| d.is_finite()) {
            return Err(LinearSolveError::Other(
                "LDLT produced non-finite factors".into(),
            ));
        }
        Ok(())
    }

    /// Loads the interior rows of `rhs` (`k` columns of length `n_total`, column-major) into
    /// `work`, interleaved (`work[i * k + j]` is row `i` of column `j`), and runs the forward
    /// substitution through the interior: afterwards the interior rows hold `L_AA⁻¹ b_A` and
    /// the separator rows `-L_SA L_AA⁻¹ b_A`.
    fn forward(&mut self, rhs: &[f64], n_total: usize, k: usize) {
        let n = self.eqs.len();
        let n_interior = self.n_interior;
        let x = &mut self.work[..n * k];
        // Column by column: the rows of one column are read in elimination order, scattered
        // over a block that stays in cache (all the columns at once would miss at every read).
        for (j, b) in rhs.chunks_exact(n_total).take(k).enumerate() {
            for (i, &q) in self.eqs[..n_interior].iter().enumerate() {
                x[i * k + j] = b[q];
            }
        }
        x[n_interior * k..].fill(0.0);
        with_columns!(self, k, forward_interleaved)
    }

    /// With the separator's solution `x_s` (`s` x `k`, column-major), scales the interior by
    /// `D⁻¹` and runs the back substitution through the interior (see [`Self::write_interior`]).
    fn backward(&mut self, x_s: &[f64], k: usize) {
        let n = self.eqs.len();
        let n_interior = self.n_interior;
        let s = n - n_interior;
        let x = &mut self.work[..n * k];
        let (interior, separator) = x.split_at_mut(n_interior * k);
        for (row, d) in interior.chunks_exact_mut(k).zip(&self.inv_d) {
            for v in row {
                *v *= d;
            }
        }
        for (i, row) in separator.chunks_exact_mut(k).enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = x_s[j * s + i];
            }
        }
        with_columns!(self, k, backward_interleaved)
    }

    /// The forward substitution of [`Self::forward`] for `K` right-hand sides interleaved in
    /// `work`, in plain loops over the supernodes' columns, each step done for the `K` columns
    /// at once (a short vector the compiler keeps in registers): most supernodes are 2–8
    /// columns wide, where a call to a dense kernel per supernode costs more than its
    /// arithmetic. The update of each of a supernode's pattern rows is summed apart, then
    /// subtracted once. Every right-hand side sees the same operations in the same order
    /// whatever `K`, so solving columns together or one by one gives the same bits (unit
    /// test); compiled for AVX2 when the CPU has it ([`crate::simd`]).
    #[inline(always)]
    fn forward_interleaved<const K: usize>(&mut self) {
        let x = &mut self.work[..self.eqs.len() * K];
        for block in interior_blocks(&self.symbolic, &self.l_values, self.n_interior) {
            let (start, size, m) = (block.start, block.size, block.interior);
            let (pattern, values) = (block.pattern, block.values);
            let rows = size + pattern.len();
            // Each pattern row's update is summed over the supernode's interior columns in
            // column order from zero, then subtracted once (pattern rows come after the
            // supernode). One or two right-hand sides: column by column into a buffer, in the
            // pass that updates the diagonal block; more: row by row in registers, once the
            // diagonal block is solved (no buffer traffic).
            let update = &mut self.tmp[..if K <= 2 { pattern.len() * K } else { 0 }];
            update.fill(0.0);
            for (j, column) in values.chunks_exact(rows).take(m).enumerate() {
                let xj: [f64; K] = std::array::from_fn(|c| x[(start + j) * K + c]);
                for (xi, l) in x[(start + j + 1) * K..(start + size) * K]
                    .chunks_exact_mut(K)
                    .zip(&column[j + 1..size])
                {
                    for c in 0..K {
                        xi[c] -= l * xj[c];
                    }
                }
                for (t, l) in update.chunks_exact_mut(K).zip(&column[size..]) {
                    for c in 0..K {
                        t[c] += l * xj[c];
                    }
                }
            }
            let (head, tail) = x.split_at_mut((start + m) * K);
            let solved = &head[start * K..];
            for (p, &r) in pattern.iter().enumerate() {
                let xr = &mut tail[(r - start - m) * K..(r - start - m + 1) * K];
                let acc: [f64; K] = if K <= 2 {
                    std::array::from_fn(|c| update[p * K + c])
                } else {
                    let mut acc = [0.0; K];
                    for (j, xj) in solved.chunks_exact(K).enumerate() {
                        let l = values[j * rows + size + p];
                        for c in 0..K {
                            acc[c] += l * xj[c];
                        }
                    }
                    acc
                };
                for c in 0..K {
                    xr[c] -= acc[c];
                }
            }
        }
    }

    /// The back substitution of [`Self::backward`] for `K` right-hand sides interleaved in
    /// `work` (scaled by `D⁻¹`, separator rows set), as dot products in plain loops against the
    /// supernode's pattern rows gathered once into a contiguous buffer (see
    /// [`Self::forward_interleaved`]).
    #[inline(always)]
    fn backward_interleaved<const K: usize>(&mut self) {
        let x = &mut self.work[..self.eqs.len() * K];
        for block in interior_blocks(&self.symbolic, &self.l_values, self.n_interior).rev() {
            let (start, size, m) = (block.start, block.size, block.interior);
            let (pattern, values) = (block.pattern, block.values);
            let rows = size + pattern.len();
            let below = &mut self.tmp[..pattern.len() * K];
            for (b, &r) in below.chunks_exact_mut(K).zip(pattern) {
                b.copy_from_slice(&x[r * K..(r + 1) * K]);
            }
            for j in (0..m).rev() {
                let column = &values[j * rows..(j + 1) * rows];
                let mut sum = [0.0; K];
                for (xi, l) in x[(start + j + 1) * K..(start + size) * K]
                    .chunks_exact(K)
                    .zip(&column[j + 1..size])
                {
                    for c in 0..K {
                        sum[c] += l * xi[c];
                    }
                }
                let dot = dot4::<K>(&column[size..], below);
                let xj = &mut x[(start + j) * K..(start + j + 1) * K];
                for c in 0..K {
                    xj[c] -= sum[c] + dot[c];
                }
            }
        }
    }

    /// Writes the interior's solution into `out` (`k` columns of length `n_total`).
    fn write_interior(&self, out: &mut [f64], n_total: usize, k: usize) {
        // Column by column, as the load in [`Self::forward`].
        for (j, o) in out.chunks_exact_mut(n_total).take(k).enumerate() {
            for (i, &q) in self.eqs[..self.n_interior].iter().enumerate() {
                o[q] = self.work[i * k + j];
            }
        }
    }

    /// Row `i` of the separator in column `j` of `k` after [`Self::forward`].
    fn separator_value(&self, i: usize, j: usize, k: usize) -> f64 {
        self.work[(self.n_interior + i) * k + j]
    }
}

/// Domain-split LDLᵀ of symmetric tangents on one pattern (see the module documentation).
pub struct SplitLdlt {
    halves: [Half; 2],
    separator: Vec<usize>,
    /// (position in the tangent's values, column-major index in s x s) of every stored entry of
    /// `K_SS`.
    k_ss: Vec<(usize, usize)>,
    /// `S̃`, then its Cholesky factor (lower triangle) or its LU factors (s x s column-major).
    dense: Vec<f64>,
    /// Whether `dense` holds a Cholesky factor (`S̃` definite) or LU factors.
    dense_cholesky: bool,
    perm: Vec<usize>,
    perm_inv: Vec<usize>,
    dense_mem: MemBuffer,
    /// Separator right-hand sides (s x MAX_RHS) and an output buffer for the interiors.
    separator_rhs: Vec<f64>,
    factorized: bool,
}

impl std::fmt::Debug for SplitLdlt {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SplitLdlt")
            .field(
                "interiors",
                &[self.halves[0].n_interior, self.halves[1].n_interior],
            )
            .field("separator", &self.separator.len())
            .field("factorized", &self.factorized)
            .finish()
    }
}

impl SplitLdlt {
    /// Symbolic analysis of both halves of `pattern` (structurally symmetric, full) for `split`.
    pub fn new(pattern: &CscPattern, split: &DofSplit) -> Result<Self, LinearSolveError> {
        let mut seen = vec![0u8; pattern.n];
        for &q in split.interiors.iter().flatten().chain(&split.separator) {
            if q >= pattern.n || seen[q] != 0 {
                return Err(LinearSolveError::Other(format!(
                    "the split lists equation {q} twice or out of range"
                )));
            }
            seen[q] = 1;
        }
        if seen.contains(&0) {
            return Err(LinearSolveError::Other("the split misses equations".into()));
        }
        // The interiors must not touch.
        let mut part = vec![2u8; pattern.n];
        for (p, interior) in split.interiors.iter().enumerate() {
            for &q in interior {
                part[q] = p as u8;
            }
        }
        for c in 0..pattern.n {
            for &r in &pattern.row_idx[pattern.col_ptr[c]..pattern.col_ptr[c + 1]] {
                if part[c] < 2 && part[r] < 2 && part[r] != part[c] {
                    return Err(LinearSolveError::Other(format!(
                        "equations {r} and {c} of different halves are coupled"
                    )));
                }
            }
        }
        let (a, b) = rayon::join(
            || Half::new(pattern, &split.interiors[0], &split.separator),
            || Half::new(pattern, &split.interiors[1], &split.separator),
        );
        let s = split.separator.len();
        let mut local = vec![NONE; pattern.n];
        for (i, &q) in split.separator.iter().enumerate() {
            local[q] = i;
        }
        let mut k_ss = Vec::new();
        for (j, &c) in split.separator.iter().enumerate() {
            for k in pattern.col_ptr[c]..pattern.col_ptr[c + 1] {
                let i = local[pattern.row_idx[k]];
                if i != NONE {
                    k_ss.push((k, i + j * s));
                }
            }
        }
        let req = StackReq::any_of(&[
            faer::linalg::cholesky::llt::factor::cholesky_in_place_scratch::<f64>(
                s,
                DENSE_PAR,
                Default::default(),
            ),
            faer::linalg::lu::partial_pivoting::factor::lu_in_place_scratch::<usize, f64>(
                s,
                s,
                DENSE_PAR,
                Default::default(),
            ),
            faer::linalg::lu::partial_pivoting::solve::solve_in_place_scratch::<usize, f64>(
                s,
                MAX_RHS,
                Par::Seq,
            ),
        ]);
        Ok(SplitLdlt {
            halves: [a?, b?],
            separator: split.separator.clone(),
            k_ss,
            dense: vec![0.0; s * s],
            dense_cholesky: false,
            perm: vec![0; s],
            perm_inv: vec![0; s],
            dense_mem: MemBuffer::new(req),
            separator_rhs: vec![0.0; s * MAX_RHS],
            factorized: false,
        })
    }

    /// `S̃ = Ŝ_A + Ŝ_B - K_SS` into `dense` (both triangles), from the halves' Schur
    /// complements (lower triangles) and the tangent `values`.
    fn assemble_dense(&mut self, values: &[f64]) {
        let s = self.separator.len();
        let [a, b] = &self.halves;
        for ((d, x), y) in self.dense.iter_mut().zip(&a.schur).zip(&b.schur) {
            *d = x + y;
        }
        for &(k, idx) in &self.k_ss {
            self.dense[idx] -= values[k];
        }
        for j in 0..s {
            for i in j + 1..s {
                self.dense[i * s + j] = self.dense[j * s + i];
            }
        }
    }
}

impl Factor for SplitLdlt {
    fn kind(&self) -> Factorization {
        Factorization::SplitLdlt
    }

    /// Reads the symmetric `values` on the pattern given to [`SplitLdlt::new`].
    fn factorize(&mut self, pattern: &CscPattern, values: &[f64]) -> Result<(), LinearSolveError> {
        debug_assert_eq!(values.len(), pattern.nnz());
        self.factorized = false;
        let [a, b] = &mut self.halves;
        let (ra, rb) = rayon::join(|| a.factorize(values), || b.factorize(values));
        ra?;
        rb?;
        let s = self.separator.len();
        if s == 0 {
            self.factorized = true;
            return Ok(());
        }
        self.assemble_dense(values);
        if !self.dense.iter().all(|v| v.is_finite()) {
            return Err(LinearSolveError::Other(
                "LDLT produced a non-finite separator Schur complement".into(),
            ));
        }
        let scale = self.dense.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        // S̃ is definite when the tangent is (a principal submatrix's Schur complement): then
        // Cholesky, half the flops of LU; otherwise S̃ is formed again (Cholesky uses the
        // upper triangle as workspace) for LU with partial pivoting.
        let cholesky = faer::linalg::cholesky::llt::factor::cholesky_in_place(
            MatMut::from_column_major_slice_mut(&mut self.dense, s, s),
            Default::default(),
            DENSE_PAR,
            MemStack::new(&mut self.dense_mem),
            Default::default(),
        );
        // A squared pivot at rounding level of the largest entry: singular, as for LU below.
        self.dense_cholesky =
            cholesky.is_ok() && (0..s).all(|i| self.dense[i * s + i].powi(2) > 1e-14 * scale);
        if self.dense_cholesky {
            self.factorized = true;
            return Ok(());
        }
        self.assemble_dense(values);
        let mut lu = MatMut::from_column_major_slice_mut(&mut self.dense, s, s);
        faer::linalg::lu::partial_pivoting::factor::lu_in_place(
            lu.rb_mut(),
            &mut self.perm,
            &mut self.perm_inv,
            DENSE_PAR,
            MemStack::new(&mut self.dense_mem),
            Default::default(),
        );
        // A pivot at rounding level of the largest entry: the tangent is singular.
        for i in 0..s {
            let p = lu[(i, i)];
            if !p.is_finite() || p.abs() <= 1e-14 * scale {
                return Err(LinearSolveError::Singular(self.separator[i]));
            }
        }
        self.factorized = true;
        Ok(())
    }

    fn solve_many_in_place(&mut self, rhs: &mut [f64], columns: usize) {
        let n = rhs_rows(self.factorized, rhs, columns);
        let k = columns;
        let s = self.separator.len();
        {
            let [a, b] = &mut self.halves;
            let rhs = &*rhs;
            rayon::join(|| a.forward(rhs, n, k), || b.forward(rhs, n, k));
        }
        let [a, b] = &self.halves;
        for j in 0..k {
            for (i, &q) in self.separator.iter().enumerate() {
                self.separator_rhs[j * s + i] =
                    rhs[j * n + q] + a.separator_value(i, j, k) + b.separator_value(i, j, k);
            }
        }
        if s > 0 && self.dense_cholesky {
            faer::linalg::cholesky::llt::solve::solve_in_place_with_conj(
                MatRef::from_column_major_slice(&self.dense, s, s),
                faer::Conj::No,
                MatMut::from_column_major_slice_mut(&mut self.separator_rhs[..s * k], s, k),
                Par::Seq,
                MemStack::new(&mut self.dense_mem),
            );
        } else if s > 0 {
            let lu = MatRef::from_column_major_slice(&self.dense, s, s);
            faer::linalg::lu::partial_pivoting::solve::solve_in_place_with_conj(
                lu,
                lu,
                faer::perm::PermRef::new_checked(&self.perm, &self.perm_inv, s),
                faer::Conj::No,
                MatMut::from_column_major_slice_mut(&mut self.separator_rhs[..s * k], s, k),
                Par::Seq,
                MemStack::new(&mut self.dense_mem),
            );
        }
        let x_s = &self.separator_rhs[..s * k];
        let [a, b] = &mut self.halves;
        rayon::join(|| a.backward(x_s, k), || b.backward(x_s, k));
        a.write_interior(rhs, n, k);
        b.write_interior(rhs, n, k);
        for j in 0..k {
            for (i, &q) in self.separator.iter().enumerate() {
                rhs[j * n + q] = x_s[j * s + i];
            }
        }
    }

    /// The matrix is symmetric: `Aᵀ x = A x`.
    fn solve_transpose_in_place(&mut self, rhs: &mut [f64]) {
        self.solve_in_place(rhs);
    }
}

/// A supernode of a half's factor with interior columns: its first column, its column count,
/// how many of them are interior (all but possibly the last ones), the rows below its diagonal
/// block and its values (column-major, `size + pattern.len()` rows).
struct InteriorBlock<'a> {
    start: usize,
    size: usize,
    interior: usize,
    pattern: &'a [usize],
    values: &'a [f64],
}

/// The supernodes of `symbolic` holding interior columns (the first ones: interior columns are
/// numbered first), in elimination order, with their values in `l_values`.
fn interior_blocks<'a>(
    symbolic: &'a SymbolicCholesky<usize>,
    l_values: &'a [f64],
    n_interior: usize,
) -> impl DoubleEndedIterator<Item = InteriorBlock<'a>> {
    let symbolic = supernodal(symbolic);
    let offsets = symbolic.col_ptr_for_val();
    let factor = SupernodalLdltRef::new(symbolic, l_values);
    let count = symbolic.supernode_begin()[..symbolic.n_supernodes()]
        .partition_point(|&begin| begin < n_interior);
    (0..count).map(move |sn| {
        let node = factor.supernode(sn);
        let (start, size) = (node.start(), node.val().ncols());
        InteriorBlock {
            start,
            size,
            interior: size.min(n_interior - start),
            pattern: node.pattern(),
            values: &l_values[offsets[sn]..offsets[sn + 1]],
        }
    })
}

/// `a · B` for the `K` interleaved columns of `b` (`b[i * K + c]`), each with four partial
/// sums (one chain of dependent additions would wait on the floating-point latency at every
/// entry).
#[inline(always)]
fn dot4<const K: usize>(a: &[f64], b: &[f64]) -> [f64; K] {
    let mut acc = [[0.0; K]; 4];
    let full = a.len() / 4 * 4;
    for (a4, b4) in a[..full].chunks_exact(4).zip(b.chunks_exact(4 * K)) {
        for q in 0..4 {
            for c in 0..K {
                acc[q][c] += a4[q] * b4[q * K + c];
            }
        }
    }
    let mut tail = [0.0; K];
    for (ai, bi) in a[full..].iter().zip(b[full * K..].chunks_exact(K)) {
        for c in 0..K {
            tail[c] += ai * bi[c];
        }
    }
    std::array::from_fn(|c| (acc[0][c] + acc[1][c]) + (acc[2][c] + acc[3][c]) + tail[c])
}

/// The dense separator LU runs after both halves, when both cores are free.
const DENSE_PAR: Par = Par::Rayon(match std::num::NonZeroUsize::new(2) {
    Some(n) => n,
    None => unreachable!(),
});

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linear::SparseLdlt;
    use rand::{Rng, SeedableRng};

    /// An `nx` x `ny` grid of quads (nodes jiggled, seeded), its node graph and coordinates.
    fn grid(
        nx: usize,
        ny: usize,
        rng: &mut rand::rngs::StdRng,
    ) -> (Vec<[usize; 4]>, Vec<[f64; 2]>) {
        let node = |i: usize, j: usize| j * (nx + 1) + i;
        let mut coords = Vec::new();
        for j in 0..=ny {
            for i in 0..=nx {
                coords.push([
                    i as f64 + rng.gen_range(-0.2..0.2),
                    j as f64 + rng.gen_range(-0.2..0.2),
                ]);
            }
        }
        let mut quads = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                quads.push([
                    node(i, j),
                    node(i + 1, j),
                    node(i + 1, j + 1),
                    node(i, j + 1),
                ]);
            }
        }
        (quads, coords)
    }

    /// A symmetric matrix on `pattern`: per element a random symmetric block (positive
    /// definite `BᵀB + I`, or shifted to be indefinite), assembled; plus an optional dense
    /// border row (the last equation) coupled to `border_rows`.
    fn assemble(
        quads: &[[usize; 4]],
        eq: &[usize],
        pattern: &CscPattern,
        shift: f64,
        border: Option<(usize, &[usize])>,
        rng: &mut rand::rngs::StdRng,
    ) -> Vec<f64> {
        let mut values = vec![0.0; pattern.nnz()];
        for q in quads {
            let dofs: Vec<usize> = q.iter().flat_map(|&n| [eq[2 * n], eq[2 * n + 1]]).collect();
            let b: Vec<f64> = (0..64).map(|_| rng.gen_range(-1.0..1.0)).collect();
            for r in 0..8 {
                for c in 0..8 {
                    let mut v: f64 = (0..8).map(|k| b[k * 8 + r] * b[k * 8 + c]).sum();
                    if r == c {
                        v += 1.0 - shift;
                    }
                    if dofs[r] != NONE && dofs[c] != NONE {
                        values[pattern.position(dofs[r], dofs[c]).unwrap()] += v;
                    }
                }
            }
        }
        if let Some((q, rows)) = border {
            for &r in rows {
                let v = rng.gen_range(-1.0..1.0);
                values[pattern.position(r, q).unwrap()] += v;
                values[pattern.position(q, r).unwrap()] += v;
            }
            values[pattern.position(q, q).unwrap()] += 5.0;
        }
        values
    }

    /// A jiggled 30 x 17 grid, bottom fixed (and a border equation if asked), split; its
    /// pattern, the split, random element values (`shift` on the diagonal) and the equations.
    fn grid_system(
        shift: f64,
        with_border: bool,
        rng: &mut rand::rngs::StdRng,
    ) -> (CscPattern, DofSplit, Vec<f64>, usize) {
        let (quads, coords) = grid(30, 17, rng);
        let n_nodes = coords.len();
        let graph = NodeGraph::from_elements(n_nodes, quads.iter().map(|q| &q[..]));
        // The bottom edge fixed, and the x dof of one more node.
        let mut eq = vec![0usize; 2 * n_nodes];
        let mut n_eq = 0;
        for n in 0..n_nodes {
            for i in 0..2 {
                let fixed = coords[n][1] < 0.5 || (n == 40 && i == 0);
                eq[2 * n + i] = if fixed { NONE } else { n_eq };
                n_eq += usize::from(!fixed);
            }
        }
        let mut split = graph
            .split_by_elimination_tree(&eq)
            .unwrap()
            .expect("a grid splits");
        // Two halves of similar size and a separator of the order of a cut across the grid
        // (17 active nodes high, 31 wide).
        let [a, b] = [split.interiors[0].len(), split.interiors[1].len()];
        assert!(a.min(b) * 3 > a.max(b), "{a} vs {b}");
        assert!(
            split.separator.len() <= 2 * 2 * 31,
            "{}",
            split.separator.len()
        );
        let base = graph.dof_pattern(&eq, n_eq);
        let border_rows: Vec<usize> = (0..n_eq).step_by(7).collect();
        let (pattern, n_total) = if with_border {
            split.separator.push(n_eq);
            (
                base.bordered(n_eq + 1, &[(n_eq, border_rows.clone())]),
                n_eq + 1,
            )
        } else {
            (base, n_eq)
        };
        let values = assemble(
            &quads,
            &eq,
            &pattern,
            shift,
            with_border.then_some((n_eq, &border_rows[..])),
            rng,
        );
        (pattern, split, values, n_total)
    }

    fn check(shift: f64, with_border: bool) {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let (pattern, split, values, n_total) = grid_system(shift, with_border, &mut rng);
        let mut split_ldlt = SplitLdlt::new(&pattern, &split).unwrap();
        split_ldlt.factorize(&pattern, &values).unwrap();
        // The definite matrix's S̃ is factorized by Cholesky, the indefinite one's by LU.
        assert_eq!(split_ldlt.dense_cholesky, shift == 0.0);
        let mut whole = SparseLdlt::new(&pattern, None).unwrap();
        whole.factorize(&pattern, &values).unwrap();
        let k = 3;
        let b: Vec<f64> = (0..n_total * k).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let (mut x_split, mut x_whole) = (b.clone(), b.clone());
        split_ldlt.solve_many_in_place(&mut x_split, k);
        whole.solve_many_in_place(&mut x_whole, k);
        // Residuals of the split solve, relative to |b| (both are direct solves of a matrix of
        // condition number ~1e3: agreement to 1e-10 leaves room for rounding).
        let mut ax = vec![0.0; n_total];
        for j in 0..k {
            pattern.mul_vec(&values, &x_split[j * n_total..(j + 1) * n_total], &mut ax);
            let r = ax
                .iter()
                .zip(&b[j * n_total..(j + 1) * n_total])
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(r < 1e-10, "residual {r}");
        }
        let scale = x_whole.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let diff = x_split
            .iter()
            .zip(&x_whole)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(
            diff < 1e-10 * scale,
            "split vs whole: {diff} (scale {scale})"
        );
        // One column at a time (the plain-loop path of Newton corrections) gives the same
        // solutions as the blocked path.
        for j in 0..k {
            let mut one = b[j * n_total..(j + 1) * n_total].to_vec();
            split_ldlt.solve_many_in_place(&mut one, 1);
            let diff = one
                .iter()
                .zip(&x_split[j * n_total..(j + 1) * n_total])
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(
                diff < 1e-12 * scale,
                "one column vs {k}: {diff} (scale {scale})"
            );
        }
        // The substitutions through a half's interior: ten interleaved columns at once in the
        // AVX2 copy (where the CPU has it), in the baseline copy, and each column alone give
        // the same bits.
        for half in &mut split_ldlt.halves {
            const K: usize = 10;
            let n = half.eqs.len();
            let loaded: Vec<f64> = (0..n * K).map(|_| rng.gen_range(-1.0..1.0)).collect();
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<u64>>();
            half.work[..n * K].copy_from_slice(&loaded);
            crate::simd::with_avx2(
                #[inline(always)]
                || {
                    half.forward_interleaved::<K>();
                    half.backward_interleaved::<K>();
                },
            );
            let dispatched = bits(&half.work[..n * K]);
            half.work[..n * K].copy_from_slice(&loaded);
            half.forward_interleaved::<K>();
            half.backward_interleaved::<K>();
            assert_eq!(dispatched, bits(&half.work[..n * K]), "AVX2 vs baseline");
            for j in 0..K {
                for i in 0..n {
                    half.work[i] = loaded[i * K + j];
                }
                half.forward_interleaved::<1>();
                half.backward_interleaved::<1>();
                let alone = bits(&half.work[..n]);
                let together: Vec<u64> = (0..n).map(|i| dispatched[i * K + j]).collect();
                assert_eq!(alone, together, "column {j} alone vs with {K}");
            }
        }
    }

    /// The split solve equals faer's whole LDLᵀ on a definite matrix.
    #[test]
    fn split_ldlt_matches_whole_ldlt() {
        check(0.0, false);
    }

    /// ... on an indefinite one (negative eigenvalues, nonsingular) with a dense border
    /// equation in the separator (a force-controlled rigid body).
    #[test]
    fn split_ldlt_matches_whole_ldlt_indefinite_bordered() {
        check(1.3, true);
    }

    /// A split whose interiors touch, or that misses an equation, is refused.
    /// A NaN anywhere in the tangent (an interior pivot, an interior off-diagonal entry, the
    /// separator) makes the factorization fail, though only pivots and the separator's Schur
    /// complement are checked.
    #[test]
    fn split_ldlt_reports_non_finite_factors() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let (pattern, split, values, _) = grid_system(8.0, false, &mut rng);
        let mut split_ldlt = SplitLdlt::new(&pattern, &split).unwrap();
        split_ldlt
            .factorize(&pattern, &values)
            .expect("finite values factorize");
        let interior = &split.interiors[0];
        let (q0, q1) = (interior[0], interior[interior.len() / 2]);
        let coupled = pattern.row_idx[pattern.col_ptr[q1]..pattern.col_ptr[q1 + 1]]
            .iter()
            .copied()
            .find(|&r| r != q1 && interior.contains(&r))
            .expect("an interior neighbour");
        let s0 = split.separator[0];
        // Symmetric tangents only reach this factorization (it reads one triangle, in its own
        // order): the off-diagonal NaN goes into both mirrored entries.
        for (r, c) in [(q0, q0), (coupled, q1), (s0, s0)] {
            let mut bad = values.clone();
            bad[pattern.position(r, c).unwrap()] = f64::NAN;
            bad[pattern.position(c, r).unwrap()] = f64::NAN;
            assert!(
                split_ldlt.factorize(&pattern, &bad).is_err(),
                "NaN at ({r}, {c}) not reported"
            );
        }
    }

    /// A zero pivot in a half is reported with the tangent's equation (not the half's local
    /// column).
    #[test]
    fn split_ldlt_names_the_equation_of_a_zero_pivot() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let (pattern, split, mut values, _) = grid_system(0.0, false, &mut rng);
        // The first column of the second half is eliminated first: its pivot is its diagonal.
        let q = split.interiors[1][0];
        values[pattern.position(q, q).unwrap()] = 0.0;
        let err = SplitLdlt::new(&pattern, &split)
            .unwrap()
            .factorize(&pattern, &values)
            .unwrap_err();
        assert!(
            matches!(err, LinearSolveError::Singular(e) if e == q),
            "{err} (expected equation {q})"
        );
    }

    #[test]
    fn split_ldlt_refuses_bad_splits() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(1);
        let (quads, coords) = grid(4, 4, &mut rng);
        let graph = NodeGraph::from_elements(coords.len(), quads.iter().map(|q| &q[..]));
        let eq: Vec<usize> = (0..2 * coords.len()).collect();
        let pattern = graph.dof_pattern(&eq, eq.len());
        let good = graph.split_by_elimination_tree(&eq).unwrap().unwrap();
        assert!(SplitLdlt::new(&pattern, &good).is_ok());
        // A separator equation coupled to the second interior, moved into the first.
        let mut touching = good.clone();
        let i = (0..good.separator.len())
            .find(|&i| {
                let q = good.separator[i];
                pattern.row_idx[pattern.col_ptr[q]..pattern.col_ptr[q + 1]]
                    .iter()
                    .any(|r| good.interiors[1].contains(r))
            })
            .unwrap();
        let q = touching.separator.remove(i);
        touching.interiors[0].push(q);
        let err = SplitLdlt::new(&pattern, &touching).unwrap_err().to_string();
        assert!(err.contains("coupled"), "{err}");
        let mut missing = good;
        missing.separator.pop();
        let err = SplitLdlt::new(&pattern, &missing).unwrap_err().to_string();
        assert!(err.contains("misses"), "{err}");
    }
}
