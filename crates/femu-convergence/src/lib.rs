//! Mesh and element validation studies for `femu`, as the seed did before choosing its mesh
//! (seed §2.1.2.1): it compared element formulations and meshes of 6 000 to 26 000 nodes under
//! the reference parameters (Table 1), required the nodal displacement to change by less than
//! 1e-4 mm (far below the DIC noise of about 1e-2 mm), and only then fixed 25 392 CPE4H
//! elements.
//!
//! A study ([`ConvergenceStudy`], a study file's `[convergence]` table as femu-study reads it) meshes the
//! built-in thigh at a sequence of sizes, solves one loading test for each element type, and
//! compares every mesh with the finest of its type at the same physical points — the DIC grid
//! ([`DicGrid`]), located in each mesh by [`femu_mesh::PointInterpolation`] — so meshes that
//! share no node are compared where the measurement will be:
//!
//! ```text
//!   sizes h_1 > h_2 > ... > h_f          for each element type (CPE4H, CPE4, CPE3):
//!   ──► mesh, solve                      u_i(x_k) at the grid points x_k (inside every mesh)
//!   ──► e_i = max_k |u_i(x_k) - u_f(x_k)|,  RMS likewise
//!   ──► rate p from e_i ≈ C (h_i^p - h_f^p)            (rate::fit_rate_against_finest)
//!   ──► recommended: the coarsest mesh with e_i < tolerance (default 1e-4 mm)
//!   ──► locking: the same with every D x d_scale; RMS |u| over the reference's shows CPE4
//!       stiffening (volumetric locking) where CPE4H (mean dilatation) does not
//! ```
//!
//! [`run_study`] does the work and returns a [`StudyResult`]; [`report::write_outputs`] writes
//! the table (CSV, JSON), the figures and `summary.json`.

#![forbid(unsafe_code)]

pub mod rate;
pub mod refine;
pub mod report;
pub mod run;
pub mod split;
pub mod study;

pub use rate::{fit_rate, fit_rate_against_finest, RateFit};
pub use refine::refined_thigh;
pub use run::{run_study, ElementSummary, LockingSummary, MeshRun, StudyResult};
pub use split::{split_deck, split_deck_times, split_deck_with, Curves, SplitError};
pub use study::{ConvergenceStudy, DicGrid, MeshSequence};

use std::path::PathBuf;

/// Why a study could not be run or written.
#[derive(Debug, thiserror::Error)]
pub enum ConvergenceError {
    /// A bad study file: the file, the key and why.
    #[error("{file}: key '{key}': {message}")]
    Study {
        file: String,
        key: String,
        message: String,
    },
    #[error("{path}: {message}")]
    Io { path: PathBuf, message: String },
    #[error("building the thigh mesh ({what}): {source}")]
    Geometry {
        what: String,
        source: femu_geometry::GeometryError,
    },
    #[error("{what}: {message}")]
    Model { what: String, message: String },
    /// No grid point lies inside every mesh of the study.
    #[error("no point of the comparison grid lies inside every mesh ({points} points, origin {origin:?} mm, spacing {spacing} mm): move the [grid] window over the tissue")]
    NoCommonPoints {
        points: usize,
        origin: [f64; 2],
        spacing: f64,
    },
    /// The user asked to stop ([`femu_mesh::stop`]); the solves finished before are kept.
    #[error("interrupted after {} solves", finished.len())]
    Interrupted {
        finished: Vec<MeshRun>,
        source: femu_mesh::stop::Interrupted,
    },
    #[error("{path}: cannot draw the figure: {source}")]
    Plot {
        path: PathBuf,
        source: femu_plot::PlotError,
    },
}
