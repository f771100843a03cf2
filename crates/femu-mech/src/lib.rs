//! Finite-strain plane-strain solid mechanics for `femu`.
//!
//! - [`material`]: the registry of hyperelastic laws (compressible Neo-Hookean, seed Eq. 1;
//!   Mooney–Rivlin; Yeoh; Abaqus forms), their parameters, stress and tangent.
//! - [`element`]: CPE4, CPE4H (mean dilatation), CPE3.
//! - [`load`]: follower pressure with load stiffness.
//! - [`model`]: a checked model built from a resolved deck.
//! - [`solver`]: incremental Newton–Raphson with line search and cut-back, sparse LU reused.
//! - [`linear`], [`split`] and [`supernodal`]: the sparse factorizations (faer LDLᵀ/LU; large
//!   models by halves on two cores, each half's LDLᵀ stopped at the separator).
//! - [`sensitivity`]: exact parameter sensitivities by direct differentiation (seed §2.3).
//! - [`output`]: displacements CSV, VTU with LE and Cauchy stress, summary JSON.

pub mod build;
pub mod contact;
pub mod element;
pub mod linear;
pub mod load;
pub mod loading;
pub mod material;
pub mod model;
pub mod output;
pub mod reference;
pub mod sensitivity;
pub(crate) mod simd;
pub mod solver;
pub mod split;
pub mod supernodal;

pub use material::{Hyperelastic, Material, MaterialLaw, MooneyRivlin, NeoHookean, Yeoh};
pub use model::{Model, ModelError};
pub use solver::{Solution, SolveError, SolveReport, SolverOptions, StaticSolver};
