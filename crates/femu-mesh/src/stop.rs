//! The user's request to stop a computation (Ctrl-C, SIGTERM).
//!
//! A signal is addressed to the whole process, so the request is one process-wide flag: the
//! command line sets it from its signal handler ([`request`]), and the long loops of every
//! crate below — Newton iterations, DIC iterations, mesh sequences, optimizer steps — check it
//! between units of work ([`check`]) and return [`Interrupted`], so that the command stops
//! within a fraction of a second, keeps what it finished and says so. A library user who never
//! calls [`request`] never sees it.
//!
//! Keeping what was finished may itself need a little computation (the identified field of
//! the repeats that finished, solved once for its figure): that work runs [`shielded`], where
//! the request is not seen (a second Ctrl-C still ends the process at once).

use std::cell::Cell;
use std::sync::atomic::{AtomicBool, Ordering};

static REQUESTED: AtomicBool = AtomicBool::new(false);

thread_local! {
    /// Depth of [`shielded`] calls on this thread.
    static SHIELDED: Cell<u32> = const { Cell::new(0) };
}

/// The user asked to stop; what was finished is kept.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("interrupted")]
pub struct Interrupted;

/// Asks every running computation of this process to stop at its next check.
pub fn request() {
    REQUESTED.store(true, Ordering::SeqCst);
}

/// Whether a stop was requested (and this thread is not [`shielded`]).
pub fn requested() -> bool {
    REQUESTED.load(Ordering::Relaxed) && SHIELDED.with(|s| s.get() == 0)
}

/// Runs `f` without seeing a stop request on this thread: the work that keeps what was
/// finished after a stop (writing results, one solve for their figure).
pub fn shielded<T>(f: impl FnOnce() -> T) -> T {
    struct Guard;
    impl Drop for Guard {
        fn drop(&mut self) {
            SHIELDED.with(|s| s.set(s.get() - 1));
        }
    }
    SHIELDED.with(|s| s.set(s.get() + 1));
    let _guard = Guard;
    f()
}

/// `Err(Interrupted)` once a stop was requested.
pub fn check() -> Result<(), Interrupted> {
    if requested() {
        Err(Interrupted)
    } else {
        Ok(())
    }
}
