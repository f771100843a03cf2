//! Sparse direct solvers on a pattern built once: symbolic analysis once per pattern, numeric
//! factorization many times (every Newton iteration of femu-mech) with a workspace allocated
//! once.
//!
//! The node graph ([`NodeGraph`]) and its orderings, faer's supernodal LDLᵀ ([`SparseLdlt`]) and
//! sparse LU ([`SparseLu`]); [`crate::solver::SparseSolver`] chooses between them.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, LdltRef, SymbolicCholesky, SymmetricOrdering,
};
use faer::sparse::linalg::lu::{factorize_symbolic_lu, LuRef, NumericLu, SymbolicLu};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::Side;
use faer::{Conj, MatMut, Par};

use crate::factor::{rhs_rows, Factor, Factorization, LinearSolveError, MAX_RHS};
use crate::pattern::CscPattern;

/// The node adjacency graph of a mesh (CSR, sorted, each node adjacent to itself): the sparse
/// pattern and the fill-reducing ordering are computed on it, a quarter of the size of the dof
/// graph, then expanded to the two dofs of each node.
#[derive(Debug, Clone)]
pub struct NodeGraph {
    pub ptr: Vec<usize>,
    pub adj: Vec<usize>,
}

impl NodeGraph {
    /// Nodes are adjacent when they share an element.
    ///
    /// Built without a list per node: the elements of each node are gathered first (CSR, by
    /// counting), then each node's neighbours are the nodes of its elements, sorted and
    /// deduplicated in one reused buffer.
    pub fn from_elements<'a>(n_nodes: usize, elements: impl Iterator<Item = &'a [usize]>) -> Self {
        let elements: Vec<&[usize]> = elements.collect();
        // Elements of each node: `node_el[node_el_ptr[n]..node_el_ptr[n + 1]]`.
        let mut node_el_ptr = vec![0usize; n_nodes + 1];
        for nodes in &elements {
            for &a in *nodes {
                node_el_ptr[a + 1] += 1;
            }
        }
        for n in 0..n_nodes {
            node_el_ptr[n + 1] += node_el_ptr[n];
        }
        let mut fill = node_el_ptr.clone();
        let mut node_el = vec![0usize; node_el_ptr[n_nodes]];
        for (e, nodes) in elements.iter().enumerate() {
            for &a in *nodes {
                node_el[fill[a]] = e;
                fill[a] += 1;
            }
        }
        let mut ptr = Vec::with_capacity(n_nodes + 1);
        let mut adj = Vec::with_capacity(4 * node_el.len() + n_nodes);
        let mut buf: Vec<usize> = Vec::new();
        ptr.push(0);
        for n in 0..n_nodes {
            buf.clear();
            buf.push(n);
            for &e in &node_el[node_el_ptr[n]..node_el_ptr[n + 1]] {
                buf.extend_from_slice(elements[e]);
            }
            buf.sort_unstable();
            buf.dedup();
            adj.extend_from_slice(&buf);
            ptr.push(adj.len());
        }
        NodeGraph { ptr, adj }
    }

    /// The pattern on the free dofs, `eq[2 n + i]` being the equation of dof i of node n
    /// (`usize::MAX` if prescribed). Equations must be numbered node by node (increasing with
    /// the node index), so that rows come out sorted.
    pub fn dof_pattern(&self, eq: &[usize], n_eq: usize) -> CscPattern {
        let mut col_ptr = vec![0usize; n_eq + 1];
        let mut row_idx = Vec::with_capacity(4 * self.adj.len());
        for node in 0..self.ptr.len() - 1 {
            for i in 0..2 {
                let c = eq[2 * node + i];
                if c == usize::MAX {
                    continue;
                }
                for &m in &self.adj[self.ptr[node]..self.ptr[node + 1]] {
                    for k in 0..2 {
                        let r = eq[2 * m + k];
                        if r != usize::MAX {
                            row_idx.push(r);
                        }
                    }
                }
                col_ptr[c + 1] = row_idx.len();
            }
        }
        debug_assert!(col_ptr.windows(2).all(|w| w[0] <= w[1]));
        CscPattern {
            n: n_eq,
            col_ptr,
            row_idx,
        }
    }

    /// Approximate-minimum-degree ordering of the node graph expanded to free dofs:
    /// `order[k]` is the equation eliminated k-th.
    pub fn fill_reducing_dof_order(
        &self,
        eq: &[usize],
        n_eq: usize,
    ) -> Result<Vec<usize>, LinearSolveError> {
        let (perm, _) = self.amd_node_order()?;
        let mut order = Vec::with_capacity(n_eq);
        for &node in &perm {
            for i in 0..2 {
                let q = eq[2 * node + i];
                if q != usize::MAX {
                    order.push(q);
                }
            }
        }
        Ok(order)
    }

    /// Approximate-minimum-degree ordering of the nodes: `(perm, perm_inv)`, `perm[k]` being the
    /// node eliminated k-th.
    pub fn amd_node_order(&self) -> Result<(Vec<usize>, Vec<usize>), LinearSolveError> {
        let n = self.ptr.len() - 1;
        let mut perm = vec![0usize; n];
        let mut perm_inv = vec![0usize; n];
        let a = SymbolicSparseColMatRef::new_checked(n, n, &self.ptr, None, &self.adj);
        let mut mem = MemBuffer::new(faer::sparse::linalg::amd::order_scratch::<usize>(
            n,
            self.adj.len(),
        ));
        faer::sparse::linalg::amd::order(
            &mut perm,
            &mut perm_inv,
            a,
            Default::default(),
            MemStack::new(&mut mem),
        )
        .map_err(|e| LinearSolveError::Other(format!("AMD ordering: {e:?}")))?;
        Ok((perm, perm_inv))
    }
}

/// Sparse LU with reused symbolic factorization and workspace.
pub struct SparseLu {
    symbolic: SymbolicLu<usize>,
    numeric: NumericLu<usize, f64>,
    mem: MemBuffer,
    par: Par,
    factorized: bool,
}

impl std::fmt::Debug for SparseLu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SparseLu")
            .field("factorized", &self.factorized)
            .finish()
    }
}

impl SparseLu {
    /// Symbolic analysis (column ordering, elimination structure) of `pattern`.
    pub fn new(pattern: &CscPattern) -> Result<Self, LinearSolveError> {
        let symbolic = factorize_symbolic_lu(pattern.symbolic(), Default::default())
            .map_err(|e| LinearSolveError::Other(format!("{e:?}")))?;
        let par = Par::rayon(0);
        let req = StackReq::any_of(&[
            symbolic.factorize_numeric_lu_scratch::<f64>(par, Default::default()),
            symbolic.solve_in_place_scratch::<f64>(MAX_RHS, par),
        ]);
        Ok(SparseLu {
            symbolic,
            numeric: NumericLu::new(),
            mem: MemBuffer::new(req),
            par,
            factorized: false,
        })
    }
}

impl Factor for SparseLu {
    fn kind(&self) -> Factorization {
        Factorization::Lu
    }

    fn factorize(&mut self, pattern: &CscPattern, values: &[f64]) -> Result<(), LinearSolveError> {
        self.factorized = false;
        let a = SparseColMatRef::new(pattern.symbolic(), values);
        let stack = MemStack::new(&mut self.mem);
        self.symbolic
            .factorize_numeric_lu(&mut self.numeric, a, self.par, stack, Default::default())
            .map_err(|e| match e {
                faer::sparse::linalg::LuError::SymbolicSingular { index } => {
                    LinearSolveError::Singular(index)
                }
                other => LinearSolveError::Other(format!("{other:?}")),
            })?;
        self.factorized = true;
        Ok(())
    }

    fn solve_many_in_place(&mut self, rhs: &mut [f64], columns: usize) {
        let n = rhs_rows(self.factorized, rhs, columns);
        let lu = LuRef::new_unchecked(&self.symbolic, &self.numeric);
        let stack = MemStack::new(&mut self.mem);
        lu.solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(rhs, n, columns),
            self.par,
            stack,
        );
    }

    fn solve_transpose_in_place(&mut self, rhs: &mut [f64]) {
        let n = rhs_rows(self.factorized, rhs, 1);
        let lu = LuRef::new_unchecked(&self.symbolic, &self.numeric);
        let stack = MemStack::new(&mut self.mem);
        lu.solve_transpose_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(rhs, n, 1),
            self.par,
            stack,
        );
    }
}

/// Sparse LDLᵀ (no pivoting; for symmetric matrices, definite or mildly indefinite).
pub struct SparseLdlt {
    symbolic: SymbolicCholesky<usize>,
    l_values: Vec<f64>,
    mem: MemBuffer,
    par: Par,
    factorized: bool,
}

impl SparseLdlt {
    /// Symbolic analysis with the given elimination order (`order[k]`: the row eliminated
    /// k-th), or an approximate-minimum-degree ordering of the pattern; only the lower triangle
    /// of the pattern is read.
    pub fn new(pattern: &CscPattern, order: Option<&[usize]>) -> Result<Self, LinearSolveError> {
        let inverse: Option<Vec<usize>> = order.map(|o| {
            let mut inv = vec![0usize; o.len()];
            for (k, &q) in o.iter().enumerate() {
                inv[q] = k;
            }
            inv
        });
        let ordering = match (order, &inverse) {
            (Some(fwd), Some(inv)) => {
                SymmetricOrdering::Custom(faer::perm::PermRef::new_checked(fwd, inv, pattern.n))
            }
            _ => SymmetricOrdering::Amd,
        };
        // Supernodal always: faer's automatic choice takes the simplicial (up-looking)
        // factorization for the 2-D tangents of a few thousand elements, where the supernodal
        // one is faster (the compression and indentation solves on 4 101 elements: 0.80 the CPU
        // time of the whole process).
        let symbolic = factorize_symbolic_cholesky(
            pattern.symbolic(),
            Side::Lower,
            ordering,
            faer::sparse::linalg::cholesky::CholeskySymbolicParams {
                supernodal_flop_ratio_threshold:
                    faer::sparse::linalg::SupernodalThreshold::FORCE_SUPERNODAL,
                ..Default::default()
            },
        )
        .map_err(|e| LinearSolveError::Other(format!("{e:?}")))?;
        let par = Par::rayon(0);
        let req = StackReq::any_of(&[
            symbolic.factorize_numeric_ldlt_scratch::<f64>(par, Default::default()),
            symbolic.solve_in_place_scratch::<f64>(MAX_RHS, par),
        ]);
        Ok(SparseLdlt {
            l_values: vec![0.0; symbolic.len_val()],
            symbolic,
            mem: MemBuffer::new(req),
            par,
            factorized: false,
        })
    }
}

impl Factor for SparseLdlt {
    fn kind(&self) -> Factorization {
        Factorization::Ldlt
    }

    /// Reads the lower triangle of `values`.
    fn factorize(&mut self, pattern: &CscPattern, values: &[f64]) -> Result<(), LinearSolveError> {
        self.factorized = false;
        let a = SparseColMatRef::new(pattern.symbolic(), values);
        let stack = MemStack::new(&mut self.mem);
        self.symbolic
            .factorize_numeric_ldlt(
                &mut self.l_values,
                a,
                Side::Lower,
                Default::default(),
                self.par,
                stack,
                Default::default(),
            )
            .map_err(|e| LinearSolveError::Other(format!("LDLT: {e:?}")))?;
        let non_finite = {
            use rayon::prelude::*;
            self.l_values
                .par_iter()
                .with_min_len(1 << 14)
                .any(|v| !v.is_finite())
        };
        if non_finite {
            return Err(LinearSolveError::Other(
                "LDLT produced non-finite factors".into(),
            ));
        }
        self.factorized = true;
        Ok(())
    }

    fn solve_many_in_place(&mut self, rhs: &mut [f64], columns: usize) {
        let n = rhs_rows(self.factorized, rhs, columns);
        let ldlt = LdltRef::new(&self.symbolic, &self.l_values);
        let stack = MemStack::new(&mut self.mem);
        ldlt.solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(rhs, n, columns),
            self.par,
            stack,
        );
    }

    /// The matrix is symmetric: `Aᵀ x = A x`.
    fn solve_transpose_in_place(&mut self, rhs: &mut [f64]) {
        self.solve_in_place(rhs);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sweep finds the same transposed positions as a search per entry, on a bordered
    /// pattern, and refuses an unsymmetric pattern.
    #[test]
    fn node_graph_of_two_quads() {
        let graph =
            NodeGraph::from_elements(6, [[0usize, 1, 4, 3], [1, 2, 5, 4]].iter().map(|e| &e[..]));
        let lists: Vec<&[usize]> = (0..6)
            .map(|n| &graph.adj[graph.ptr[n]..graph.ptr[n + 1]])
            .collect();
        assert_eq!(lists[0], [0, 1, 3, 4]);
        assert_eq!(lists[1], [0, 1, 2, 3, 4, 5]);
        assert_eq!(lists[5], [1, 2, 4, 5]);
    }
}
