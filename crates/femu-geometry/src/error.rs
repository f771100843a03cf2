//! The error type of the geometry crate: every message names the file, label, parameter or
//! element concerned.

use std::path::PathBuf;

/// Errors of reading label images, meshing, checking and exporting thigh models.
#[derive(Debug, thiserror::Error)]
pub enum GeometryError {
    #[error("{path}: cannot read the image: {message}")]
    ImageRead { path: PathBuf, message: String },
    #[error("{path}: not a label image: {reason}")]
    NotALabelImage { path: PathBuf, reason: String },
    #[error(
        "{path}: slice {index} does not exist (the volume has {count} axial slices, 0..{count})"
    )]
    NoSuchSlice {
        path: PathBuf,
        index: usize,
        count: usize,
    },
    #[error("pixel size must be a positive finite number of mm, got {0}")]
    InvalidPixelSize(f64),
    #[error("label map: {0}")]
    InvalidLabelMap(String),
    #[error("label {label} occurs in {pixels} pixels (first at column {column}, row {row}) but has no mapping: map it to a region (--map {label}=NAME), to the bone (--bone) or to the background (--background)")]
    UnmappedLabel {
        label: u32,
        pixels: usize,
        column: usize,
        row: usize,
    },
    #[error("bone label {label} does not occur in the image (labels present: {present}): give the femur's label with --bone (or [labels] bone)")]
    BoneLabelAbsent { label: u32, present: String },
    /// A label of the map that no pixel holds: a typo in the map or the wrong image.
    #[error("label {label} (mapped to {region}) does not occur in the image (labels present: {present}): remove it from the map or check the image")]
    MappedLabelAbsent {
        label: u32,
        region: String,
        present: String,
    },
    #[error("no tissue left to mesh: {0}")]
    NoTissue(String),
    /// Tissue in separate bodies of comparable size (two thighs in one slice): which one to
    /// model is the user's choice.
    #[error("the tissue forms {count} separate bodies of {areas} mm² (the smaller ones at least {percent:.0} % of the largest): femu models one cross-section; crop the image to one body, or label the others as background")]
    SeveralBodies {
        count: usize,
        areas: String,
        percent: f64,
    },
    #[error("invalid parameter {name} = {value}: {reason}")]
    InvalidParameter {
        name: String,
        value: String,
        reason: String,
    },
    #[error("meshing failed: {0}")]
    Meshing(String),
    #[error("element {label} (region {region}) is inverted or degenerate (scaled Jacobian {scaled_jacobian:.3e})")]
    BadElement {
        label: i64,
        region: String,
        scaled_jacobian: f64,
    },
    #[error("no material for region '{0}': give it one ([materials.{0}] in a study, or femu mesh labels --materials FILE), or map its label to a Table 1 region (FAT, QUADRICEPS, ISCHIO, GRACILIS, SARTORIUS)")]
    NoMaterial(String),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: cannot draw the picture: {message}")]
    Picture { path: PathBuf, message: String },
}

impl GeometryError {
    /// An [`GeometryError::InvalidParameter`] for `name = value`.
    pub(crate) fn param(name: &str, value: impl std::fmt::Display, reason: &str) -> Self {
        GeometryError::InvalidParameter {
            name: name.to_string(),
            value: value.to_string(),
            reason: reason.to_string(),
        }
    }
}
