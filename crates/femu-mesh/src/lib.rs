//! Mesh model and mesh I/O for `femu`.
//!
//! The first crate of the pipeline (geometry and mesh → mechanics → DIC → identification → report).
//! It knows nothing about mechanics: a [`Mesh`] is nodes, elements and named sets, and a [`Deck`] is
//! the resolved content of an Abaqus/CalculiX input deck (materials and loads as plain numbers).
//!
//! Node numbering of the elements (counter-clockwise, as in Abaqus):
//!
//! ```text
//!   Quad4 (CPE4, CPE4H)          Tri3 (CPE3)
//!   4 ---- P3 ---- 3              3
//!   |              |              | \
//!   P4            P2             P3   P2
//!   |              |              |     \
//!   1 ---- P1 ---- 2              1 -P1- 2
//! ```
//!
//! Face `Pn` joins local nodes `n` and `n+1` (the last face closes back to node 1).

// The crate's documentation is for its developers (`cargo doc --document-private-items`):
// its items' docs link to the private constants and functions they build on.
#![allow(rustdoc::private_intra_doc_links)]
#![forbid(unsafe_code)]

/// 1 mmHg in MPa (the unit of the seed's contention pressure, 20 mmHg).
pub const MMHG_IN_MPA: f64 = 133.322_387_415e-6;

pub mod atomic;
pub mod decimal;
pub mod deck;
pub mod folder;
pub mod generate;
pub mod inp;
pub mod limits;
pub mod locate;
pub mod mesh;
pub mod mesh3d;
pub mod msh;
pub mod stop;
pub mod vtu;

pub use deck::{BoundaryCondition, Deck, FacePressure, MaterialDef, PointLoad, StepDef};
pub use inp::{read_inp, read_inp3, write_inp, write_inp3, write_inp_file, Deck3, InpError};
pub use locate::{PointInterpolation, PointLocation, PointLocator};
pub use mesh::{Element, ElementKind, Mesh, MeshError};
pub use mesh3d::{Element3, ElementKind3, Mesh3};
pub use msh::{read_msh, read_msh3, MshError, MshModel};
pub use vtu::{
    write_vtu, write_vtu3, write_vtu_with_int_cells, FieldSet, FieldWriter, VtuField, VtuIntField,
    VtuWriter,
};
