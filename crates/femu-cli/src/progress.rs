//! The terminal's side of a running computation: notes on stderr, progress bars (indicatif)
//! that draw only when stderr is a terminal, nothing at all with `--quiet`; and the stop
//! request: the first Ctrl-C (or SIGTERM) asks the computation to stop at its next check and
//! keep what it finished, a second one ends the process at once.

use femu_study::progress::{Progress, Task};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Duration;

/// Set by the first Ctrl-C / SIGTERM.
static STOP: OnceLock<Arc<AtomicBool>> = OnceLock::new();

/// Installs the Ctrl-C / SIGTERM handler (once per process).
pub fn install_stop_handler() {
    let flag = STOP
        .get_or_init(|| Arc::new(AtomicBool::new(false)))
        .clone();
    let installed = ctrlc::set_handler(move || {
        femu_mesh::stop::request();
        if flag.swap(true, Ordering::SeqCst) {
            // The cases of a batch run in process groups of their own (a Ctrl-C at the
            // terminal does not reach them): they end with this process, not after it.
            let ended = femu_batch::local::end_case_groups(Duration::from_millis(800));
            if ended > 0 {
                eprintln!("\nstopped ({ended} running cases ended)");
            } else {
                eprintln!("\nstopped");
            }
            std::process::exit(130);
        }
        eprintln!("\nstopping after the current unit of work (Ctrl-C again to quit at once)");
    });
    if let Err(e) = installed {
        eprintln!("warning: Ctrl-C will not stop cleanly: {e}");
    }
}

/// Notes and bars on stderr (or nothing, `quiet`).
pub struct Terminal {
    pub quiet: bool,
}

struct Bar(ProgressBar);

impl Task for Bar {
    fn inc(&self, n: usize) {
        self.0.inc(n as u64);
    }
    fn message(&self, text: &str) {
        self.0.set_message(text.to_string());
    }
}

impl Drop for Bar {
    fn drop(&mut self) {
        self.0.finish_and_clear();
    }
}

impl Progress for Terminal {
    fn note(&self, line: &str) {
        if !self.quiet {
            eprintln!("{line}");
        }
    }

    fn warn(&self, line: &str) {
        // Warnings are shown also with --quiet.
        eprintln!("warning: {line}");
    }

    fn stop_flag(&self) -> Option<Arc<AtomicBool>> {
        STOP.get().cloned()
    }

    fn task(&self, what: &str, total: Option<usize>) -> Box<dyn Task + '_> {
        if self.quiet {
            return Box::new(Bar(ProgressBar::hidden()));
        }
        let b =
            ProgressBar::with_draw_target(total.map(|n| n as u64), ProgressDrawTarget::stderr());
        let style = match total {
            Some(_) => ProgressStyle::with_template(
                "{spinner} {prefix} [{bar:30}] {pos}/{len} {msg} ({elapsed}, eta {eta})",
            )
            .expect("a valid template")
            .progress_chars("=> "),
            None => ProgressStyle::with_template("{spinner} {prefix} {msg} ({elapsed})")
                .expect("a valid template"),
        };
        b.set_style(style);
        b.set_prefix(what.to_string());
        b.enable_steady_tick(Duration::from_millis(200));
        Box::new(Bar(b))
    }
}
