//! The errors of a study file: every one names the file, the table and key, and the line.

use std::path::PathBuf;

/// A study file that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    /// The file cannot be read.
    #[error("cannot read study file {path}: {error}")]
    Read {
        path: PathBuf,
        error: std::io::Error,
    },
    /// Not TOML, or a key the schema does not know (the TOML parser's message names the key
    /// and the line).
    #[error("{0}")]
    Syntax(String),
    /// A key whose value the study rejects: `at` is `"[noise] sigma_mm (line 3)"`.
    #[error("{at}: {message}")]
    Key { at: String, message: String },
    /// A whole-study inconsistency not tied to one key.
    #[error("{0}")]
    Study(String),
    /// An error inside a named study file.
    #[error("study file {file}: {error}")]
    InFile {
        file: PathBuf,
        error: Box<StudyError>,
    },
}

impl StudyError {
    /// A key error at `at` (from [`super::lines::KeyLines::at`]).
    pub fn key(at: impl Into<String>, message: impl Into<String>) -> StudyError {
        StudyError::Key {
            at: at.into(),
            message: message.into(),
        }
    }

    /// The same error, said to come from `file`.
    pub fn in_file(self, file: &std::path::Path) -> StudyError {
        StudyError::InFile {
            file: file.to_path_buf(),
            error: Box::new(self),
        }
    }
}
