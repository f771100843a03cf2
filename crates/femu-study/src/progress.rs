//! What a long computation tells its user while it runs: notes (a finished stage's numbers) and
//! tasks (a bar over known units or a spinner). The command line draws them with indicatif, a
//! notebook could with tqdm, a test with nothing ([`Quiet`]).

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
        false
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
