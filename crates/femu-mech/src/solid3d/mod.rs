//! Three-dimensional finite-strain solid elements: C3D8 (trilinear hexahedron, 2x2x2 Gauss),
//! C3D8H (the same with a constant pressure, mean dilatation), C3D4 (linear tetrahedron) and
//! C3D10 (quadratic tetrahedron, 4-point rule), in the Abaqus node orders.
//!
//! Total Lagrangian form, as the plane-strain elements of [`crate::element`]: with
//! `F = I + Σ_a u_a ⊗ ∇_X N_a` at each Gauss point,
//!
//! ```text
//! f_ai   = Σ_g w_g P_iJ ∂N_a/∂X_J
//! K_aibk = Σ_g w_g A_iJkL ∂N_a/∂X_J ∂N_b/∂X_L
//! ```
//!
//! with P and A of the same [`Hyperelastic`](crate::material::Hyperelastic) laws through their
//! 3D invariant derivatives ([`pk1_3d`](crate::material::pk1_3d),
//! [`tangent_3d`](crate::material::tangent_3d)). Local dof `3a + i` is component `i` of local
//! node `a`. The element results are written into the same
//! [`ElementResult`](crate::element::ElementResult) as the 2D elements'.
//!
//! - [`shape`]: the shape functions and integration rules;
//! - [`kernel`]: reference geometry, energy, force, tangent, averaged Cauchy stress, and the
//!   parameter-energy forces of the sensitivities;
//! - [`assembly`]: a static solve (sparse assembly on [`femu_sparse`], and the Newton driver
//!   of the plane-strain solver: load increments, line search, cut-back) for prescribed
//!   displacements, dead nodal loads and follower pressures, and the exact parameter
//!   sensitivities of its solution;
//! - [`pressure`]: follower pressure on the faces of every type, with its load stiffness.

pub mod assembly;
pub mod deck;
pub mod kernel;
pub mod pressure;
pub mod shape;

pub use assembly::{sensitivities, solve, Body3, Element3, Options3, Solution3, Solve3Error};
pub use kernel::{
    averages, evaluate, rate_forces, unit_energy_forces, Averages3, GaussPoint3, Geometry3,
    MAX_DOFS_3D, MAX_GAUSS_3D, MAX_NODES_3D,
};
pub use shape::Kind3;
