//! What every factorization of this crate offers: [`Factor`], a square matrix on a pattern
//! analysed once (by the factorization's constructor) and factorized for each new set of
//! values, then solved against; and [`Factorization`], which one it is.
//!
//! Implemented by [`crate::SparseLu`], [`crate::SparseLdlt`] and [`crate::SplitLdlt`];
//! [`crate::SparseSolver`] chooses one for each matrix and solves through this trait.

use crate::linear::{CscPattern, LinearSolveError, MAX_RHS};

/// Which factorization a [`Factor`] is (and which one [`crate::SparseSolver::factorize`] used
/// last).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Factorization {
    Ldlt,
    /// LDLᵀ of the two halves of a bisected mesh at once ([`crate::split::SplitLdlt`]).
    SplitLdlt,
    Lu,
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
