//! What every factorization of this crate offers: [`Factor`], a square matrix on a pattern
//! analysed once (by the factorization's constructor) and factorized for each new set of
//! values, then solved against; and [`Factorization`], which one it is.
//!
//! Implemented by [`crate::SparseLu`], [`crate::SparseLdlt`] and [`crate::SplitLdlt`];
//! [`crate::SparseSolver`] chooses one for each matrix and solves through this trait.

use crate::pattern::CscPattern;

/// Largest number of right-hand sides solved at once (the workspace is sized for it once).
pub const MAX_RHS: usize = 16;

/// The linear solve failed (in femu-mech, a singular tangent: a mechanism, or a structural
/// instability). The messages speak of "the tangent", the matrix this crate factorizes for femu.
#[derive(Debug, Clone, thiserror::Error)]
pub enum LinearSolveError {
    #[error("the tangent matrix is singular (no pivot at column {0})")]
    Singular(usize),
    #[error("sparse factorization failed: {0}")]
    Other(String),
}

/// Which factorization a [`Factor`] is (and which one [`crate::SparseSolver::factorize`] used
/// last).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Factorization {
    Ldlt,
    /// LDLᵀ of the two halves of a bisected mesh at once ([`crate::split::SplitLdlt`]).
    SplitLdlt,
    Lu,
    /// An unsymmetric matrix solved by iterative refinement on the LDLᵀ of its symmetric part
    /// (see [`crate::SparseSolver::refine_on_symmetric_part`]).
    LdltOfSymmetricPart,
}

/// A sparse direct factorization on one pattern: the symbolic analysis is made once (by the
/// constructor), the numeric factorization for every matrix ([`Factor::factorize`]), and the
/// solves use the last successful one.
pub trait Factor: Send + Sync {
    /// Which factorization this is.
    fn kind(&self) -> Factorization;

    /// Numeric factorization of the matrix with `values` on `pattern` (the pattern the factor
    /// was analysed for). After an error the factor is unusable until a factorization succeeds.
    fn factorize(&mut self, pattern: &CscPattern, values: &[f64]) -> Result<(), LinearSolveError>;

    /// Solves `A X = B` in place for `columns` (1 ..= [`MAX_RHS`]) right-hand sides stored one
    /// after the other (column-major), with the last factorization. Panics before a successful
    /// factorization.
    fn solve_many_in_place(&mut self, rhs: &mut [f64], columns: usize);

    /// Solves `Aᵀ x = rhs` in place with the last factorization (adjoint sensitivities).
    fn solve_transpose_in_place(&mut self, rhs: &mut [f64]);

    /// Solves `A x = rhs` in place with the last factorization.
    fn solve_in_place(&mut self, rhs: &mut [f64]) {
        self.solve_many_in_place(rhs, 1);
    }
}

/// The row count of `columns` right-hand sides stored in `rhs`, after the checks every
/// [`Factor::solve_many_in_place`] makes: a factorization is there, `columns` is within
/// 1 ..= [`MAX_RHS`] (the workspaces are sized for it) and divides the length of `rhs`.
pub(crate) fn rhs_rows(factorized: bool, rhs: &[f64], columns: usize) -> usize {
    assert!(factorized, "solve before factorize");
    assert!((1..=MAX_RHS).contains(&columns) && rhs.len() / columns * columns == rhs.len());
    rhs.len() / columns
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linear::{NodeGraph, SparseLdlt, SparseLu};
    use crate::split::SplitLdlt;
    use rand::{Rng, SeedableRng};

    /// A 16 x 10 grid of quads, every dof free: its pattern, its node split, and symmetric and
    /// unsymmetric values, diagonally dominant (diagonal 20, at most 17 off-diagonal entries of
    /// at most 0.55 per row: condition number below 3).
    fn grid_system() -> (CscPattern, crate::split::DofSplit, Vec<f64>, Vec<f64>) {
        let (nx, ny) = (16usize, 10usize);
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
        let eq: Vec<usize> = (0..2 * n_nodes).collect();
        let pattern = graph.dof_pattern(&eq, eq.len());
        let split = graph.split_by_elimination_tree(&eq).unwrap().unwrap();
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let mut sym = vec![0.0; pattern.nnz()];
        for c in 0..pattern.n {
            for k in pattern.col_ptr[c]..pattern.col_ptr[c + 1] {
                let r = pattern.row_idx[k];
                if r < c {
                    let v = rng.gen_range(-0.5..0.5);
                    sym[k] = v;
                    sym[pattern.position(c, r).unwrap()] = v;
                } else if r == c {
                    sym[k] = 20.0;
                }
            }
        }
        let unsym: Vec<f64> = sym.iter().map(|v| v + rng.gen_range(-0.05..0.05)).collect();
        (pattern, split, sym, unsym)
    }

    /// max |A x - b| for `x` solved against `values` (`transpose`: against Aᵀ).
    fn residual(
        pattern: &CscPattern,
        values: &[f64],
        x: &[f64],
        b: &[f64],
        transpose: bool,
    ) -> f64 {
        let mut ax = vec![0.0; pattern.n];
        for c in 0..pattern.n {
            for k in pattern.col_ptr[c]..pattern.col_ptr[c + 1] {
                let r = pattern.row_idx[k];
                if transpose {
                    ax[c] += values[k] * x[r];
                } else {
                    ax[r] += values[k] * x[c];
                }
            }
        }
        ax.iter()
            .zip(b)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max)
    }

    /// Each factorization, used through the trait: its kind; a solve, three right-hand sides
    /// at once and a transposed solve all leave residuals at rounding level (1e-12 of |b| ≤ 1,
    /// for a matrix of condition number below 3); the solves refuse to run before a
    /// factorization and, for the LDLᵀ, after a failed one.
    #[test]
    fn every_factorization_solves_through_the_trait() {
        let (pattern, split, sym, unsym) = grid_system();
        let n = pattern.n;
        let mut factors: Vec<(Box<dyn Factor>, &[f64])> = vec![
            (Box::new(SparseLdlt::new(&pattern, None).unwrap()), &sym),
            (Box::new(SplitLdlt::new(&pattern, &split).unwrap()), &sym),
            (Box::new(SparseLu::new(&pattern).unwrap()), &unsym),
        ];
        let kinds: Vec<Factorization> = factors.iter().map(|f| f.0.kind()).collect();
        assert_eq!(
            kinds,
            [
                Factorization::Ldlt,
                Factorization::SplitLdlt,
                Factorization::Lu
            ]
        );
        let mut rng = rand::rngs::StdRng::seed_from_u64(4);
        let b: Vec<f64> = (0..3 * n).map(|_| rng.gen_range(-1.0..1.0)).collect();
        for (factor, values) in &mut factors {
            let kind = factor.kind();
            let unfactorized = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                factor.solve_in_place(&mut b[..n].to_vec())
            }));
            assert!(unfactorized.is_err(), "{kind:?} solved before factorizing");
            factor.factorize(&pattern, values).unwrap();
            let mut x = b[..n].to_vec();
            factor.solve_in_place(&mut x);
            let r = residual(&pattern, values, &x, &b[..n], false);
            assert!(r < 1e-12, "{kind:?}: residual {r}");
            let mut xs = b.clone();
            factor.solve_many_in_place(&mut xs, 3);
            for j in 0..3 {
                let range = j * n..(j + 1) * n;
                let r = residual(&pattern, values, &xs[range.clone()], &b[range], false);
                assert!(r < 1e-12, "{kind:?}: residual {r} of column {j}");
            }
            let mut xt = b[..n].to_vec();
            factor.solve_transpose_in_place(&mut xt);
            let r = residual(&pattern, values, &xt, &b[..n], true);
            assert!(r < 1e-12, "{kind:?}: transposed residual {r}");
            // Equation 0 decoupled and without stiffness (a singular matrix): an LDLᵀ fails and
            // leaves no factors to solve with (faer's LU reports structural singularity only,
            // which this pattern cannot show).
            if kind == Factorization::Lu {
                continue;
            }
            let mut bad = values.to_vec();
            for k in pattern.col_ptr[0]..pattern.col_ptr[1] {
                let r = pattern.row_idx[k];
                bad[k] = 0.0;
                bad[pattern.position(0, r).unwrap()] = 0.0;
            }
            assert!(
                factor.factorize(&pattern, &bad).is_err(),
                "{kind:?} factorized a singular matrix"
            );
            let failed = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                factor.solve_in_place(&mut b[..n].to_vec())
            }));
            assert!(
                failed.is_err(),
                "{kind:?} solved after a failed factorization"
            );
        }
        // The LU's transposed solve differs from its plain one: the values are unsymmetric.
        let (lu, _) = &mut factors[2];
        lu.factorize(&pattern, &unsym).unwrap();
        let (mut x, mut xt) = (b[..n].to_vec(), b[..n].to_vec());
        lu.solve_in_place(&mut x);
        lu.solve_transpose_in_place(&mut xt);
        assert!(x.iter().zip(&xt).any(|(a, b)| (a - b).abs() > 1e-6));
    }
}
