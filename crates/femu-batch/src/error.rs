//! femu-batch's errors: one typed [`Error`] for every subcommand, so that a caller tells a bad
//! batch file from cases the schema rejects, a file that cannot be read or written, and a case
//! whose `femu run` failed, by matching the variant rather than reading a string.
//!
//! - femu-study's error passes through unchanged ([`Error::Study`]: `?` converts it, its
//!   message and kind are its own), as do the batch file's ([`SpecError`]) and the cases'
//!   ([`CaseErrors`]).
//! - What femu-batch rejects itself is an [`Error::Input`] (use [`bail!`](crate::bail)).
//! - A file, folder or program that cannot be used is an [`Error::Io`] with its path
//!   ([`IoContext::at`]).
//! - [`Context::with_context`] puts a sentence in front of any error (`"case s01: ..."`),
//!   keeping the typed error underneath; `{:#}` (as the command line prints) shows
//!   `context: cause: cause's cause`.

use std::fmt::Display;
use std::path::{Path, PathBuf};

/// A batch subcommand that cannot run or did not finish.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The batch file or its table (file, line, row and key in the message).
    #[error(transparent)]
    Spec(#[from] SpecError),
    /// Cases whose studies cannot run, every one named with its row and key.
    #[error(transparent)]
    Cases(#[from] CaseErrors),
    /// What femu-batch rejects itself: a folder that is not a batch's, a case the batch lacks,
    /// a `--resume` with another batch file, Slurm resources or a Slurm command's answer.
    #[error("{0}")]
    Input(String),
    /// A file, folder or program that cannot be read, written or started (`message` names it).
    #[error("{message}")]
    Io {
        message: String,
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// femu-study's error: a case's `femu run`, a record or summary read back, the report.
    #[error(transparent)]
    Study(#[from] femu_study::Error),
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    #[error(transparent)]
    Csv(#[from] csv::Error),
    #[error(transparent)]
    Plot(#[from] femu_plot::PlotError),
    /// A sentence in front of an error (which case).
    #[error("{context}")]
    Context {
        context: String,
        #[source]
        source: Box<Error>,
    },
}

/// A batch file that cannot be used: the message names the file and line, the row and key.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct SpecError(pub String);

/// Cases that cannot run: one line per problem, each naming its case, row and key.
#[derive(Debug, thiserror::Error)]
#[error("{} of {total} cases cannot run (nothing was run):\n  {}", .problems.len(), .problems.join("\n  "))]
pub struct CaseErrors {
    pub problems: Vec<String>,
    pub total: usize,
}

/// `Result` with femu-batch's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// An input error with `message`.
    pub fn input(message: impl Into<String>) -> Error {
        Error::Input(message.into())
    }

    /// This error with `context` in front of it.
    pub fn context(self, context: impl Display) -> Error {
        Error::Context {
            context: context.to_string(),
            source: Box::new(self),
        }
    }

    /// femu-study's error under this one, if it is one (under any context): what a caller asks
    /// about a case's run (its [`femu_study::Error::kind`], whether it was interrupted).
    pub fn study(&self) -> Option<&femu_study::Error> {
        match self {
            Error::Study(e) => Some(e),
            Error::Context { source, .. } => source.study(),
            _ => None,
        }
    }

    /// Whether the user asked to stop (a case's run interrupted).
    pub fn is_interrupted(&self) -> bool {
        self.study().is_some_and(femu_study::Error::is_interrupted)
    }
}

/// A sentence in front of an error, as `anyhow::Context` does, keeping the typed cause.
pub trait Context<T> {
    /// The error, if any, with the context `f` makes in front of it (made only on error).
    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T>;
}

impl<T, E: Into<Error>> Context<T> for std::result::Result<T, E> {
    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T> {
        self.map_err(|e| e.into().context(f()))
    }
}

/// An I/O error as an [`Error::Io`] on its path.
pub trait IoContext<T> {
    /// The error, if any, on `path`, with the message `f` makes (made only on error; it names
    /// the path: `cannot write PATH`).
    fn at<C: Display, F: FnOnce() -> C>(self, path: &Path, f: F) -> Result<T>;
}

impl<T> IoContext<T> for std::io::Result<T> {
    fn at<C: Display, F: FnOnce() -> C>(self, path: &Path, f: F) -> Result<T> {
        self.map_err(|source| Error::Io {
            message: f().to_string(),
            path: path.to_path_buf(),
            source,
        })
    }
}

/// Returns an [`Error::Input`] from a format string (as `anyhow::bail!`).
#[macro_export]
macro_rules! bail {
    ($($arg:tt)*) => {
        return Err($crate::error::Error::Input(format!($($arg)*)).into())
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The chain `{:#}` prints: the message and every source after it.
    fn chain(e: &Error) -> String {
        let mut text = e.to_string();
        let mut cause = std::error::Error::source(e);
        while let Some(c) = cause {
            text.push_str(": ");
            text.push_str(&c.to_string());
            cause = c.source();
        }
        text
    }

    #[test]
    fn an_io_error_names_its_path_and_keeps_its_cause() {
        let path = Path::new("/nonexistent-femu-batch-dir/batch.json");
        let e = std::fs::read_to_string(path)
            .at(path, || format!("cannot read {}", path.display()))
            .unwrap_err();
        let Error::Io {
            path: p, source, ..
        } = &e
        else {
            panic!("not an Io error: {e:?}");
        };
        assert_eq!(p, path);
        assert_eq!(source.kind(), std::io::ErrorKind::NotFound);
        assert_eq!(
            chain(&e),
            format!("cannot read {}: {source}", path.display())
        );
    }

    #[test]
    fn a_case_context_keeps_the_study_error_and_its_stop() {
        let stopped: Result<()> =
            Err(femu_study::Error::from(femu_study::progress::Interrupted).into());
        let e = stopped.with_context(|| "case s01").unwrap_err();
        assert!(e.is_interrupted());
        assert!(e.study().is_some());
        assert!(chain(&e).starts_with("case s01: "), "{}", chain(&e));
        let bad: Result<()> = Err(femu_study::Error::input("no such key").into());
        let e = bad.with_context(|| "case s02").unwrap_err();
        assert!(!e.is_interrupted());
        assert_eq!(
            e.study().map(femu_study::Error::kind),
            Some(femu_study::ErrorKind::Input)
        );
        assert_eq!(chain(&e), "case s02: no such key");
    }
}
