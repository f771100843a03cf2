//! Thigh models for `femu`: the built-in parametric thigh, the label-image mesher, mesh quality
//! and exports.
//!
//! The first stage of the pipeline (geometry and mesh → mechanics → DIC → identification →
//! report). Both models produce a [`femu_mesh::generate::GeneratedMesh`] of counter-clockwise
//! 4-node quadrilaterals (CPE4 or CPE4H), conforming across region interfaces, with
//!
//! - element sets named after the regions (`FAT`, `QUADRICEPS`, `ISCHIO`, `GRACILIS`,
//!   `SARTORIUS` for the seed's five tissues; any upper-case name for a user's label map),
//! - the node set `FEMUR` (every node on the femur edge, the fixed hole),
//! - the surfaces `SKIN` and `FEMUR` as `(element, face)` lists, `face` 0-based as in
//!   [`femu_mesh::Element::face_nodes`] (face `k` joins local nodes `k` and `k+1`),
//! - the node set `SKIN` (every node on the skin).
//!
//! How a mesh is made (one code path for both models, see [`mesher`]):
//!
//! ```text
//!  label image ──► classes per pixel ──► islands dropped, holes filled (warnings)
//!  (PNG/TIFF/NIfTI,        (background, bone, regions)
//!   or the analytic
//!   parametric thigh       ──► interface curves between classes, traced on the pixel corners
//!   sampled on a                (staircases), split at junctions where three classes meet
//!   fine raster)           ──► Taubin smoothing of every curve (no shrinkage, no staircase)
//!                          ──► curves resampled at the element size, constrained Delaunay
//!                              triangulation refined to a size and a 30° minimum angle
//!                          ──► every triangle split into three quads (vertex, edge midpoints,
//!                              centroid): all-quad and conforming by construction
//!                          ──► guarded Laplacian smoothing of the free nodes, quality check
//! ```
//!
//! The region curves are the same on both sides of an interface, so the mesh is conforming;
//! the element size is independent of the pixel size; a label map's pixel areas are kept (the
//! smoothing is area-neutral to first order, see the tests for measured errors).

#![forbid(unsafe_code)]

pub mod error;
pub mod export;
pub mod interface_split;
pub mod labels;
pub mod mesher;
pub mod parametric;
pub mod picture;
pub mod quality;
pub mod thigh3d;

pub use error::GeometryError;
pub use export::{
    contention_deck, table1_materials, write_inp_with_surfaces, write_regions_vtu, TABLE1,
};
pub use labels::{parse_label_map, read_label_image, LabelImage, LabelSpec};
pub use mesher::{mesh_label_image, MeshOptions, ThighModel, MAX_ELEMENTS};
pub use parametric::{parametric_thigh, parametric_thigh_on_raster, MeshSize, ThighParams};
pub use picture::write_regions_png;
pub use quality::{quality_report, QualityReport, RegionQuality};

/// The contention pressure of the seed: 20 mmHg in MPa (2.666e-3).
pub const CONTENTION_MPA: f64 = 20.0 * femu_mesh::MMHG_IN_MPA;

/// Names of the seed's five regions, as element-set names.
pub const SEED_REGIONS: [&str; 5] = ["FAT", "QUADRICEPS", "ISCHIO", "GRACILIS", "SARTORIUS"];
