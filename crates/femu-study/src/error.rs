//! femu-study's errors: one typed [`Error`] for every step, so a caller (the command line, the
//! Python module) tells a bad study from a bad input file, a solve that did not converge, a
//! correlation that cannot run or an identification that failed by matching its
//! [`Error::kind`], not by walking a chain of strings.
//!
//! - A computing crate's error passes through unchanged (`?` converts it, its message is the
//!   crate's own).
//! - What femu-study itself rejects is an [`Error::Input`] (use [`bail!`](crate::bail) or
//!   [`input!`](crate::input)).
//! - [`Context::context`] puts a sentence in front of any error (`"test contention: ..."`),
//!   keeping the typed error underneath: the kind of a context error is its cause's kind, and
//!   `{:#}` (as the command line prints) shows `context: cause: cause's cause`.

use std::fmt::Display;

use crate::schema::StudyError;

/// A step that cannot run or did not finish.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The study file or dict (key and line in the message).
    #[error(transparent)]
    Study(#[from] StudyError),
    /// An input femu-study rejects itself (a file, an argument, a combination of keys).
    #[error("{0}")]
    Input(String),
    /// A file that cannot be read or written.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// The user asked to stop; what was finished is kept.
    #[error(transparent)]
    Interrupted(#[from] crate::progress::Interrupted),
    /// The user asked to stop a step that kept part of its work (`message` says what).
    #[error("{message}")]
    Stopped {
        message: String,
        kept: Kept,
        #[source]
        source: crate::progress::Interrupted,
    },
    /// An output folder that would hold one of the inputs.
    #[error(transparent)]
    InputInOutput(#[from] femu_mesh::folder::InputInOutput),
    /// A sentence in front of an error (which step, which file, which test).
    #[error("{context}")]
    Context {
        context: String,
        #[source]
        source: Box<Error>,
    },
    // The computing crates' errors, unchanged.
    #[error(transparent)]
    Solve(#[from] femu_mech::SolveError),
    #[error(transparent)]
    Solve3(#[from] femu_mech::solid3d::Solve3Error),
    #[error(transparent)]
    Model(#[from] femu_mech::ModelError),
    #[error(transparent)]
    Material(#[from] femu_mech::material::MaterialError),
    #[error(transparent)]
    Loading(#[from] femu_mech::loading::LoadingError),
    #[error(transparent)]
    Setup(#[from] femu_mech::build::SetupError),
    #[error(transparent)]
    Sensitivity(#[from] femu_mech::sensitivity::SensitivityError),
    #[error(transparent)]
    Inp(#[from] femu_mesh::InpError),
    #[error(transparent)]
    Msh(#[from] femu_mesh::MshError),
    #[error(transparent)]
    Mesh(#[from] femu_mesh::MeshError),
    #[error(transparent)]
    Geometry(#[from] femu_geometry::GeometryError),
    #[error(transparent)]
    Dic(#[from] femu_dic::error::DicError),
    #[error(transparent)]
    Ultrasound(#[from] femu_ultrasound::UsError),
    #[error(transparent)]
    Plot(#[from] femu_plot::PlotError),
    #[error(transparent)]
    Convergence(#[from] femu_convergence::ConvergenceError),
    #[error(transparent)]
    Fit(#[from] femu_identify::fit::FitError),
    #[error(transparent)]
    Campaign(#[from] femu_identify::campaign::CampaignError),
    #[error(transparent)]
    Fisher(#[from] femu_identify::fisher::FisherError),
    #[error(transparent)]
    Measured(#[from] femu_identify::measured::MeasuredError),
    #[error(transparent)]
    Joint(#[from] femu_identify::joint::JointError),
    #[error(transparent)]
    Check(#[from] femu_identify::discretization::CheckError),
    #[error(transparent)]
    Idic(#[from] femu_identify::idic::IdicError),
    #[error(transparent)]
    IdicRun(#[from] femu_identify::idic::identify::IdicRunError),
    #[error(transparent)]
    Json(#[from] serde_json::Error),
}

/// What a step the user stopped kept (see [`Error::Stopped`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Kept {
    /// Its summary, which says what was stopped.
    Summary,
    /// These files of its folder.
    Files(Vec<String>),
}

/// `Result` with femu-study's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// What kind of failure an [`Error`] is (what a caller acts on).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorKind {
    /// The study file or dict.
    Study,
    /// A deck, mesh, image, label image, measured field or argument.
    Input,
    /// A forward solve that did not converge.
    Solve,
    /// A correlation that cannot run.
    Dic,
    /// An identification that cannot run or whose every start failed.
    Identification,
    /// The user asked to stop.
    Interrupted,
    /// Anything else (a figure that cannot be drawn).
    Other,
}

impl Error {
    /// The kind of this error (a context error has its cause's kind).
    pub fn kind(&self) -> ErrorKind {
        use femu_identify::fit::FitError;
        use femu_identify::idic::identify::IdicRunError;
        match self {
            Error::Context { source, .. } => source.kind(),
            Error::Study(_) => ErrorKind::Study,
            Error::Interrupted(_)
            | Error::Stopped { .. }
            | Error::Solve(femu_mech::SolveError::Interrupted(_))
            | Error::Fit(FitError::Interrupted)
            | Error::IdicRun(IdicRunError::Interrupted) => ErrorKind::Interrupted,
            Error::Input(_)
            | Error::Io(_)
            | Error::InputInOutput(_)
            | Error::Model(_)
            | Error::Material(_)
            | Error::Loading(_)
            | Error::Setup(_)
            | Error::Inp(_)
            | Error::Msh(_)
            | Error::Mesh(_)
            | Error::Geometry(_)
            | Error::Measured(_)
            | Error::Ultrasound(_)
            | Error::Json(_) => ErrorKind::Input,
            Error::Solve3(femu_mech::solid3d::Solve3Error::BadElement { .. }) => ErrorKind::Input,
            Error::Solve(_) | Error::Solve3(_) | Error::Sensitivity(_) | Error::Convergence(_) => {
                ErrorKind::Solve
            }
            Error::Dic(_) => ErrorKind::Dic,
            Error::Fit(_)
            | Error::Campaign(_)
            | Error::Fisher(_)
            | Error::Joint(_)
            | Error::Check(_)
            | Error::Idic(_)
            | Error::IdicRun(_) => ErrorKind::Identification,
            Error::Plot(_) => ErrorKind::Other,
        }
    }

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

    /// The user asked to stop; `message` says what was stopped and what was kept.
    pub fn stopped(message: impl Into<String>, kept: Kept) -> Error {
        Error::Stopped {
            message: message.into(),
            kept,
            source: crate::progress::Interrupted,
        }
    }

    /// What a step the user stopped kept, if this is such a stop (under any context).
    pub fn kept(&self) -> Option<&Kept> {
        match self {
            Error::Context { source, .. } => source.kept(),
            Error::Stopped { kept, .. } => Some(kept),
            _ => None,
        }
    }

    /// Whether this is the end of an interruption.
    pub fn is_interrupted(&self) -> bool {
        self.kind() == ErrorKind::Interrupted
    }

    /// The message and every cause after it, `context: cause: cause's cause` (what `{:#}` of
    /// an `anyhow::Error` shows), for a message kept in a file or a warning.
    pub fn chain(&self) -> String {
        let mut text = self.to_string();
        let mut cause = std::error::Error::source(self);
        while let Some(c) = cause {
            text.push_str(": ");
            text.push_str(&c.to_string());
            cause = c.source();
        }
        text
    }
}

/// A sentence in front of an error, as `anyhow::Context` does, keeping the typed cause.
pub trait Context<T> {
    /// The error, if any, with `context` in front of it.
    fn context<C: Display>(self, context: C) -> Result<T>;
    /// The error, if any, with the context `f` makes in front of it (made only on error).
    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T>;
}

impl<T, E: Into<Error>> Context<T> for std::result::Result<T, E> {
    fn context<C: Display>(self, context: C) -> Result<T> {
        self.map_err(|e| e.into().context(context))
    }
    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T> {
        self.map_err(|e| e.into().context(f()))
    }
}

/// A missing value as an input error saying `context`.
impl<T> Context<T> for Option<T> {
    fn context<C: Display>(self, context: C) -> Result<T> {
        self.ok_or_else(|| Error::Input(context.to_string()))
    }
    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T> {
        self.ok_or_else(|| Error::Input(f().to_string()))
    }
}

/// An [`Error::Input`] from a format string (as `anyhow!`).
#[macro_export]
macro_rules! input {
    ($($arg:tt)*) => {
        $crate::error::Error::Input(format!($($arg)*))
    };
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

    fn solve_failure() -> Result<()> {
        Err(femu_mech::SolveError::TooLarge { entries: 1 << 33 }.into())
    }

    #[test]
    fn context_keeps_the_kind_and_prints_the_chain() {
        let e = solve_failure().context("test contention").unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Solve);
        let chained = e.chain();
        let shown = format!("{:#}", anyhow::Error::from(e));
        assert!(shown.starts_with("test contention: "), "{shown}");
        assert_eq!(chained, shown);
        let bare = Error::input("x").context("y");
        assert_eq!(bare.kind(), ErrorKind::Input);
        assert_eq!(format!("{bare}"), "y");
    }

    #[test]
    fn interruptions_are_found_under_context() {
        let e = Error::from(crate::progress::Interrupted).context("forward tests");
        assert!(e.is_interrupted());
        let fit: Error = femu_identify::fit::FitError::Interrupted.into();
        assert!(fit.context("identification").is_interrupted());
    }

    #[test]
    fn a_missing_option_is_an_input_error() {
        let none: Option<u8> = None;
        let e = none.context("no frame 3").unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Input);
        assert_eq!(e.to_string(), "no frame 3");
    }
}
