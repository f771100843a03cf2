//! Finite-strain plane-strain solid mechanics for `femu`: from a resolved deck to the
//! equilibrium state, its reactions and contact forces, and the exact parameter sensitivities.
//! Dependencies point one way: model data → elements and loads → solver → sensitivities and
//! output; the sparse linear algebra is a separate crate, [`femu_sparse`], which knows nothing
//! of mechanics. No unsafe code (forbidden here; the AVX2 dispatch of the element loop is
//! `femu_sparse::with_avx2`, a safe function).
//!
//! Model and physics:
//! - [`model`]: a checked model built from a resolved deck; [`build`]: decks and models made
//!   in code; [`loading`]: the seed's three loading tests (contention, compression,
//!   indentation) as named loadings; [`reference`](mod@reference): independent reference
//!   solutions for verification.
//! - [`material`]: the registry of hyperelastic laws (compressible Neo-Hookean, seed Eq. 1;
//!   Mooney–Rivlin; Yeoh; Abaqus forms), their parameters, stress and tangent.
//! - [`element`]: CPE4, CPE4H (mean dilatation), CPE3; [`solid3d`]: their 3D counterparts
//!   C3D8, C3D8H, C3D4, C3D10, with a static 3D solve and its parameter sensitivities (the
//!   model, the loading tests and the solver below are plane-strain).
//! - [`load`]: follower pressure with load stiffness; [`contact`]: rigid plate and cylinder,
//!   node-to-surface augmented-Lagrangian contact; [`interface`]: sliding interfaces between
//!   regions (node-to-segment contact, frictionless or with Coulomb friction).
//!
//! Solving ([`solver`], one file per part under `solver/`):
//! - `assembly`: dof numbering, sparse pattern built once, element slots, residual and tangent
//!   gathered in element order (bitwise equal to a serial scatter), point and pressure loads;
//! - `contact_state`: penalties, multipliers and their Uzawa updates, active sets, step limit,
//!   the second-order correction of trial states on curved bodies;
//! - `active_set`: the contact set of each Newton correction (primal-dual active-set
//!   iterations, low-rank updates of the factorized tangent);
//! - `factor`: the tangent's factorization (LDLᵀ, by halves on two cores for large models, or
//!   LU; from [`femu_sparse`]), analysed once per model;
//! - `newton`: increments, Newton–Raphson with line search and cut-back, the solve reports;
//! - `linearization`: [`solver::Linearization`], the converged state, its tangent, the factors
//!   and the active contact constraints, which is all the sensitivities read of the solver.
//!
//! After the solve:
//! - [`sensitivity`]: exact parameter sensitivities by direct differentiation (seed §2.3).
//! - [`output`]: displacements CSV, VTU with LE and Cauchy stress, summary JSON.

// The crate's documentation is for its developers (`cargo doc --document-private-items`):
// its items' docs link to the private constants and functions they build on.
#![allow(rustdoc::private_intra_doc_links)]
#![forbid(unsafe_code)]

pub mod build;
pub mod contact;
pub mod element;
pub mod interface;
pub mod load;
pub mod loading;
pub mod material;
pub mod model;
pub mod output;
pub mod reference;
pub mod sensitivity;
pub mod solid3d;
pub mod solver;

/// The AVX2 dispatch of the element loop, from [`femu_sparse`] (safe to call; its unsafe stays
/// there).
pub(crate) use femu_sparse::simd;

pub use femu_sparse::Factorization;
pub use material::{Hyperelastic, Material, MaterialLaw, MooneyRivlin, NeoHookean, Yeoh};
pub use model::{Model, ModelError};
pub use solver::{Solution, SolveError, SolveReport, SolverOptions, StaticSolver};
