//! Errors of the DIC crate: every variant names the file, the option or the item at fault.

use std::path::PathBuf;

/// Everything that can go wrong when reading images or correlating them.
#[derive(Debug, thiserror::Error)]
pub enum DicError {
    /// An image file that cannot be opened or decoded.
    #[error("{path}: cannot read the image: {message}")]
    ImageRead { path: PathBuf, message: String },
    /// A DICOM file that is not supported (transfer syntax, photometric interpretation, ...).
    #[error("{path}: {message}")]
    Dicom { path: PathBuf, message: String },
    /// A frame index past the number of frames of a multi-frame file.
    #[error("{path}: frame {frame} requested, but the file holds {frames} frame(s) (frames are numbered from 0)")]
    Frame {
        path: PathBuf,
        frame: usize,
        frames: usize,
    },
    /// The reference and deformed images do not have the same size.
    #[error("the images differ in size: reference {reference:?} px, deformed {deformed:?} px")]
    SizeMismatch {
        reference: (usize, usize),
        deformed: (usize, usize),
    },
    /// The region of interest does not fit the image or is empty.
    #[error("region of interest: {0}")]
    Roi(String),
    /// An option out of its range (element size, tolerance, regularization length, ...).
    #[error("option {name}: {message}")]
    Option { name: String, message: String },
    /// The reference image has no texture over the region of interest (or an element): the
    /// grey-level gradient vanishes, so the displacement is not measurable there.
    #[error("no texture: {0}")]
    NoTexture(String),
    /// The sparse Gauss–Newton matrix could not be factorized.
    #[error("linear solver: {0}")]
    Linear(String),
    /// Non-finite values appeared during the iterations (the images do not correlate).
    #[error("correlation diverged: {0}")]
    Diverged(String),
    /// The user asked to stop ([`femu_mesh::stop`]): between two Gauss–Newton iterations.
    #[error("correlation interrupted")]
    Interrupted(#[from] femu_mesh::stop::Interrupted),
    /// Writing an output file failed.
    #[error("{path}: cannot write: {message}")]
    Write { path: PathBuf, message: String },
    /// The output folder holds an input file (it could be overwritten).
    #[error(transparent)]
    Folder(#[from] femu_mesh::folder::InputInOutput),
}

impl DicError {
    pub(crate) fn option(name: &str, message: impl Into<String>) -> Self {
        DicError::Option {
            name: name.to_string(),
            message: message.into(),
        }
    }
}
