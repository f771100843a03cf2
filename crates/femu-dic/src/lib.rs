//! Global finite-element digital image correlation (DIC) for `femu`: the displacement field
//! between a reference and a deformed image as a 4-node quadrilateral (Q4) finite-element
//! field over a region of interest, as Correli-Q4 does in the seed study (§2.1.1), independent
//! of the FE solver.
//!
//! - [`image`]: grey-level images ([`GreyImage`]), pixel size; [`read`]: PNG/TIFF/DICOM input.
//! - [`dicom`]: DICOM ultrasound (uncompressed, JPEG baseline, RLE; multi-frame; palette
//!   colour; Sequence of Ultrasound Regions / Pixel Spacing).
//! - [`mesh`]: ROI (rectangle or mask) and the structured Q4 mesh ([`DicMesh`]).
//! - [`bspline`]: cubic B-spline interpolation of the deformed image.
//! - [`solver`]: modified Gauss–Newton with the sparse Hessian factorized once
//!   ([`correlate`]), pyramid and FFT initialization.
//! - [`regularize`]: the regularization behind the [`regularize::Regularizer`] trait (the
//!   Laplacian penalty of a regularization length).
//! - [`output`]: model frame (mm), the measured-field CSV of `conventions.md`, nodal CSV, VTU.
//! - [`lab`]: the virtual lab (speckle images warped by known displacement fields).
//! - [`noise`]: random error from pairs of images of an unloaded specimen.

// The crate's documentation is for its developers (`cargo doc --document-private-items`):
// its items' docs link to the private constants and functions they build on.
#![allow(rustdoc::private_intra_doc_links)]
#![forbid(unsafe_code)]

pub mod anderson;
pub mod auto;
pub mod bspline;
pub mod check;
pub mod cine;
pub mod command;
pub mod consistency;
pub mod dicom;
mod dicom_scan;
pub mod error;
pub mod fft;
pub mod figures;
pub mod image;
pub mod lab;
pub mod mesh;
pub mod noise;
pub mod output;
pub mod quality;
pub mod read;
pub mod regularize;
pub mod selected;
pub mod sequence;
pub mod solver;
pub mod sparse;
pub mod spec;

pub use error::DicError;
pub use image::{GreyImage, PixelSize};
pub use mesh::{DicMesh, Rect, Roi};
pub use solver::{correlate, Brightness, DicOptions, DicResult};
