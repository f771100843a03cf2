//! What a long computation tells its user while it runs: notes (a finished stage's numbers) and
//! tasks (a bar over known units or a spinner); and how the user stops it (Ctrl-C on a terminal,
//! an interrupt in a notebook): the steps check [`Progress::cancelled`] between units of work and
//! stop with [`Interrupted`], keeping what they finished. The command line draws the progress
//! with indicatif, a notebook could with tqdm, a test with nothing ([`Quiet`]).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// The user asked to stop; what was finished is kept (the stop request of the whole process
/// is [`femu_mesh::stop`], set by the command line's signal handler).
pub use femu_mesh::stop::Interrupted;

/// Whether an error is the end of an interruption: it is of kind
/// [`ErrorKind::Interrupted`](crate::ErrorKind::Interrupted) or its chain holds [`Interrupted`],
/// or the user asked to stop before it was returned (a computation that stopped midway may
/// report the stop as its own failure, e.g. a forward solve inside an optimizer start).
pub fn is_interrupted(e: &crate::Error) -> bool {
    chain_is_interrupted(e)
}

/// [`is_interrupted`] for any error chain (a caller's, which may hold femu-study's errors among
/// others): a link is [`Interrupted`] or a femu-study error of that kind, or the user asked to
/// stop.
pub fn chain_is_interrupted(e: &(dyn std::error::Error + 'static)) -> bool {
    let mut link = Some(e);
    while let Some(c) = link {
        if c.is::<Interrupted>()
            || c.downcast_ref::<crate::Error>()
                .is_some_and(crate::Error::is_interrupted)
        {
            return true;
        }
        link = c.source();
    }
    femu_mesh::stop::requested()
}

/// The user's side of a running computation.
pub trait Progress: Sync {
    /// A line for the user.
    fn note(&self, line: &str);
    /// A warning for the user (also recorded in the results where one is kept).
    fn warn(&self, line: &str) {
        self.note(&format!("warning: {line}"));
    }
    /// A task of `total` units (`None`: of unknown length) starts; it ends when dropped.
    fn task(&self, what: &str, total: Option<usize>) -> Box<dyn Task + '_>;
    /// Whether the user asked to stop (checked between units of work).
    fn cancelled(&self) -> bool {
        femu_mesh::stop::requested() || self.stop_flag().is_some_and(|f| f.load(Ordering::Relaxed))
    }
    /// The flag a stop request sets, for computations below this crate that check it
    /// themselves (an optimizer between forward solves).
    fn stop_flag(&self) -> Option<Arc<AtomicBool>> {
        None
    }
    /// `Err(Interrupted)` if the user asked to stop.
    fn check(&self) -> Result<(), Interrupted> {
        if self.cancelled() {
            Err(Interrupted)
        } else {
            Ok(())
        }
    }
}

/// A running task (see [`Progress::task`]).
pub trait Task: Send + Sync {
    /// `n` more units done.
    fn inc(&self, n: usize);
    /// What the task is doing now.
    fn message(&self, text: &str);
}

/// Tells nothing.
#[derive(Debug, Clone, Copy, Default)]
pub struct Quiet;

struct NoTask;

impl Task for NoTask {
    fn inc(&self, _: usize) {}
    fn message(&self, _: &str) {}
}

impl Progress for Quiet {
    fn note(&self, _: &str) {}
    fn task(&self, _: &str, _: Option<usize>) -> Box<dyn Task + '_> {
        Box::new(NoTask)
    }
}

/// Prints each note on standard error as it comes, no progress bars (examples and scripts that
/// log to a file).
#[derive(Debug, Clone, Copy, Default)]
pub struct Notes;

impl Progress for Notes {
    fn note(&self, line: &str) {
        eprintln!("{line}");
    }
    fn task(&self, _: &str, _: Option<usize>) -> Box<dyn Task + '_> {
        Box::new(NoTask)
    }
}
