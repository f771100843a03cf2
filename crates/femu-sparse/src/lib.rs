//! Sparse direct solvers for `femu`, knowing nothing of mechanics: a square matrix on a
//! compressed-sparse-column pattern built once (from the node graph of a mesh with two unknowns
//! per node, optionally bordered by a few dense equations), factorized many times.
//!
//! - [`linear`]: the pattern ([`CscPattern`], [`NodeGraph`]: sparsity, AMD ordering), faer's
//!   supernodal LDLᵀ and sparse LU with their symbolic analyses and workspaces reused.
//! - [`solver`]: [`SparseSolver`], which checks the symmetry of each matrix and factorizes it by
//!   LDLᵀ when symmetric (by halves for large models), by LU otherwise.
//! - [`split`]: the LDLᵀ of a bisected mesh by halves on two cores, coupled through a dense
//!   Schur complement on the separator ([`SplitLdlt`]; the first level of nested dissection).
//! - [`factor`]: [`Factor`], what the three factorizations offer (factorize on the pattern
//!   analysed once, solve for one or several right-hand sides, solve with the transpose).
//! - [`vendored`]: code derived from faer 0.24.4 (MIT, its licence beside it), checked by a test
//!   against the faer in Cargo.lock: the left-looking supernodal LDLᵀ stopped at the separator
//!   ([`PartialLdlt`]), with the only call into `private-gemm-x86` (unsafe, see below).
//! - [`simd`]: [`with_avx2`], a safe run-time dispatch that runs a hot loop in a copy compiled
//!   for AVX2 when the CPU has it (used by the triangular solves here and by femu-mech's
//!   element loop), with the same results to the bit.
//!
//! **Unsafe code** is denied in this crate except in two places, each allowed item by item with
//! a `SAFETY` note on every block: the AVX2 call in [`simd`] (the CPU feature is checked first)
//! and the supernodal update kernel in [`vendored::faer_supernodal`] (bounds asserted before the
//! call). Every other crate of the workspace that needs none forbids it.

#![deny(unsafe_code)]
#![deny(clippy::undocumented_unsafe_blocks)]

pub mod factor;
pub mod linear;
pub mod pattern;
pub mod simd;
pub mod solver;
pub mod split;
pub mod vendored;

pub use factor::{Factor, Factorization, LinearSolveError, MAX_RHS};
pub use linear::{NodeGraph, SparseLdlt, SparseLu};
pub use pattern::CscPattern;
pub use simd::{has_avx2, with_avx2};
pub use solver::SparseSolver;
pub use split::{DofSplit, SplitLdlt};
pub use vendored::faer_supernodal::{LowerView, PartialLdlt};
