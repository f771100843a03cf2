//! Errors of the ultrasound crate: every message names the file, line, key or item at fault.

use std::path::PathBuf;

/// An error of the simulator or of the settings / random-error analyses.
#[derive(Debug, thiserror::Error)]
pub enum UsError {
    /// A parameter out of its range (frequency, gain, probe width, ...).
    #[error("{name}: {message}")]
    Parameter { name: String, message: String },
    /// A malformed manifest line.
    #[error("{path}:{line}: {message}")]
    Manifest {
        path: PathBuf,
        line: usize,
        message: String,
    },
    /// An image named by a manifest line that cannot be used.
    #[error("{path}:{line}: image {image}: {message}")]
    Image {
        path: PathBuf,
        line: usize,
        image: PathBuf,
        message: String,
    },
    /// The probe sees no tissue, a scatterer left the mesh, ...
    #[error("{0}")]
    Geometry(String),
    /// Digital image correlation failed.
    #[error("DIC: {0}")]
    Dic(femu_dic::DicError),
    /// A figure could not be drawn.
    #[error("figure {path}: {message}")]
    Plot { path: PathBuf, message: String },
    /// A file could not be written.
    #[error("cannot write {path}: {message}")]
    Write { path: PathBuf, message: String },
}

// Not `#[from]`: the message already holds the DIC error's text, and a `source` would make
// `anyhow` print it twice.
impl From<femu_dic::DicError> for UsError {
    fn from(e: femu_dic::DicError) -> Self {
        UsError::Dic(e)
    }
}

impl UsError {
    pub(crate) fn param(name: &str, message: impl Into<String>) -> Self {
        UsError::Parameter {
            name: name.into(),
            message: message.into(),
        }
    }

    pub(crate) fn write(path: &std::path::Path, e: impl std::fmt::Display) -> Self {
        UsError::Write {
            path: path.to_path_buf(),
            message: e.to_string(),
        }
    }

    pub(crate) fn plot(path: &std::path::Path, e: impl std::fmt::Display) -> Self {
        UsError::Plot {
            path: path.to_path_buf(),
            message: e.to_string(),
        }
    }
}
