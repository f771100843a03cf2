//! Finite-strain plane-strain solid mechanics for `femu`.
//!
//! - [`material`]: compressible Neo-Hookean (Abaqus form, seed Eq. 1), stress and tangent.
//! - [`element`]: CPE4, CPE4H (mean dilatation), CPE3.
//! - [`load`]: follower pressure with load stiffness.
//! - [`model`]: a checked model built from a resolved deck.
//! - [`solver`]: incremental Newton–Raphson with line search and cut-back, sparse LU reused.
//! - The sparse factorizations (faer LDLᵀ/LU; large models by halves on two cores) live in
//!   [`femu_sparse`].
//! - [`sensitivity`]: exact parameter sensitivities by direct differentiation (seed §2.3).
//! - [`output`]: displacements CSV, VTU with LE and Cauchy stress, summary JSON.

#![forbid(unsafe_code)]

pub mod build;
pub mod contact;
pub mod element;
pub mod load;
pub mod loading;
pub mod material;
pub mod model;
pub mod output;
pub mod reference;
pub mod sensitivity;
pub mod solver;

/// The AVX2 dispatch of the element loop, from [`femu_sparse`] (safe to call; its unsafe stays
/// there).
pub(crate) use femu_sparse::simd;

pub use femu_sparse::Factorization;
pub use material::{Hyperelastic, NeoHookean};
pub use model::{Model, ModelError};
pub use solver::{Solution, SolveError, SolveReport, SolverOptions, StaticSolver};
