//! The terminal's side of a running computation: notes on stderr, progress bars (indicatif)
//! that draw only when stderr is a terminal, nothing at all with `--quiet`.

use femu_study::progress::{Progress, Task};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::time::Duration;

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
