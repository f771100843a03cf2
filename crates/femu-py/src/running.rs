//! Long calls from Python: the work runs on its own thread without the GIL, while the calling
//! thread waits for it, shows its progress and watches for Ctrl-C.
//!
//! The work tells its progress through femu's [`Progress`] trait; here that trait sends events
//! down a channel, and the calling thread hands them to a Python reporter object (tqdm bars in
//! a notebook or on a terminal, see `python/femu/_progress.py`), so that Python is only ever
//! called from the thread that called femu. Between events (at least every 100 ms) the calling
//! thread runs the interpreter's signal handlers (`PyErr_CheckSignals`): a Ctrl-C (or a
//! notebook's interrupt) sets the stop flag the steps and the optimizers check between their
//! units of work, the work stops keeping what it finished, and the call raises
//! `KeyboardInterrupt`.

use crate::errors;
use femu_study::progress::{Progress, Task};
use pyo3::exceptions::PyKeyboardInterrupt;
use pyo3::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::{channel, Receiver, Sender};
use std::sync::Arc;
use std::time::Duration;

/// What the work tells its user.
enum Event {
    Note(String),
    Warn(String),
    Start {
        id: usize,
        what: String,
        total: Option<usize>,
    },
    Inc {
        id: usize,
        n: usize,
    },
    Message {
        id: usize,
        text: String,
    },
    End {
        id: usize,
    },
}

/// femu's [`Progress`] as a channel of events, with the stop flag.
struct ChannelProgress {
    tx: Sender<Event>,
    stop: Arc<AtomicBool>,
    next_task: AtomicUsize,
}

struct ChannelTask {
    tx: Sender<Event>,
    id: usize,
}

impl Task for ChannelTask {
    fn inc(&self, n: usize) {
        let _ = self.tx.send(Event::Inc { id: self.id, n });
    }
    fn message(&self, text: &str) {
        let _ = self.tx.send(Event::Message {
            id: self.id,
            text: text.to_string(),
        });
    }
}

impl Drop for ChannelTask {
    fn drop(&mut self) {
        let _ = self.tx.send(Event::End { id: self.id });
    }
}

impl Progress for ChannelProgress {
    fn note(&self, line: &str) {
        let _ = self.tx.send(Event::Note(line.to_string()));
    }
    fn warn(&self, line: &str) {
        let _ = self.tx.send(Event::Warn(line.to_string()));
    }
    fn task(&self, what: &str, total: Option<usize>) -> Box<dyn Task + '_> {
        let id = self.next_task.fetch_add(1, Ordering::Relaxed);
        let _ = self.tx.send(Event::Start {
            id,
            what: what.to_string(),
            total,
        });
        Box::new(ChannelTask {
            tx: self.tx.clone(),
            id,
        })
    }
    fn stop_flag(&self) -> Option<Arc<AtomicBool>> {
        Some(self.stop.clone())
    }
}

/// Hands `event` to the reporter (`None`: quiet): its methods `note(line)`, `warn(line)`,
/// `start(id, what, total)`, `inc(id, n)`, `message(id, text)`, `end(id)`.
fn deliver(reporter: Option<&Bound<'_, PyAny>>, event: Event) -> PyResult<()> {
    let Some(r) = reporter else {
        return Ok(());
    };
    match event {
        Event::Note(line) => r.call_method1("note", (line,)),
        Event::Warn(line) => r.call_method1("warn", (line,)),
        Event::Start { id, what, total } => r.call_method1("start", (id, what, total)),
        Event::Inc { id, n } => r.call_method1("inc", (id, n)),
        Event::Message { id, text } => r.call_method1("message", (id, text)),
        Event::End { id } => r.call_method1("end", (id,)),
    }
    .map(|_| ())
}

/// Waits up to 100 ms for the next event without holding the GIL.
fn next_event(py: Python<'_>, rx: Receiver<Event>) -> (Receiver<Event>, Option<Event>) {
    py.detach(move || {
        let e = rx.recv_timeout(Duration::from_millis(100)).ok();
        (rx, e)
    })
}

/// Runs `work` on its own thread without the GIL (see the module documentation); its errors
/// become the exceptions of [`errors`], a Ctrl-C `KeyboardInterrupt`, a panic a `FemuError`.
pub fn run<T: Send>(
    py: Python<'_>,
    reporter: Option<&Bound<'_, PyAny>>,
    work: impl FnOnce(&dyn Progress) -> femu_study::error::Result<T> + Send,
) -> PyResult<T> {
    let (tx, rx) = channel();
    let progress = ChannelProgress {
        tx,
        stop: Arc::new(AtomicBool::new(false)),
        next_task: AtomicUsize::new(0),
    };
    let (outcome, first_error) = std::thread::scope(|scope| {
        let progress = &progress;
        let worker = scope.spawn(move || work(progress));
        let mut rx = rx;
        // The first Python error while waiting (a KeyboardInterrupt, a reporter that raised):
        // the work is asked to stop, and this error is raised once it has.
        let mut first_error: Option<PyErr> = None;
        let stop_on = |e: PyErr, first: &mut Option<PyErr>| {
            progress.stop.store(true, Ordering::SeqCst);
            first.get_or_insert(e);
        };
        loop {
            let finished = worker.is_finished();
            let (back, event) = next_event(py, rx);
            rx = back;
            let mut pending: Vec<Event> = event.into_iter().collect();
            pending.extend(rx.try_iter());
            for e in pending {
                if let Err(err) = deliver(reporter, e) {
                    stop_on(err, &mut first_error);
                }
            }
            if let Err(err) = py.check_signals() {
                stop_on(err, &mut first_error);
            }
            if finished {
                break;
            }
        }
        // Events sent after the last look (the work's final notes).
        for e in rx.try_iter() {
            if let Err(err) = deliver(reporter, e) {
                first_error.get_or_insert(err);
            }
        }
        (worker.join(), first_error)
    });
    let result = match outcome {
        Ok(r) => r,
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown".into());
            return Err(errors::FemuError::new_err(format!(
                "internal error (a panic, please report it): {what}"
            )));
        }
    };
    match (first_error, result) {
        // Stopped by Ctrl-C: the work's own account of what it kept. Whatever the work returned
        // after the request is the stop's end, also when a part of it reports the stop as its
        // own failure (a forward solve inside an optimizer start; the command line reads it the
        // same way: `femu_study::progress::is_interrupted`).
        (Some(e), Err(w)) if e.is_instance_of::<PyKeyboardInterrupt>(py) => Err(
            PyKeyboardInterrupt::new_err(format!("{}; what was finished is kept", w.chain())),
        ),
        // The request came as the work finished: its results are whole.
        (Some(e), Ok(_)) if e.is_instance_of::<PyKeyboardInterrupt>(py) => {
            Err(PyKeyboardInterrupt::new_err(
                "stopped as the computation finished: its results are complete; what was finished is kept",
            ))
        }
        (Some(e), _) => Err(e),
        (None, r) => r.map_err(errors::to_py),
    }
}
