//! Progress of a long job (dataset export, evaluation, soak): a bar on a terminal
//! (indicatif); on anything else (a log file, CI) plain lines, one each time another
//! `every_percent` is done, or none.

use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

pub struct Progress {
    what: String,
    total: u64,
    bar: Option<ProgressBar>,
    done: AtomicU64,
    every_percent: u64,
    started: Instant,
}

impl Progress {
    /// `total` units of `what`; `every_percent` is the plain lines' step (0: none).
    pub fn new(what: impl Into<String>, total: u64, every_percent: u64) -> Progress {
        let what = what.into();
        let bar = std::io::stderr().is_terminal().then(|| {
            let style = ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len}, {elapsed} (~{eta} to go)")
                .expect("a valid progress template")
                .progress_chars("=> ");
            let bar = ProgressBar::new(total).with_style(style);
            bar.set_message(what.clone());
            bar
        });
        Progress { what, total, bar, done: AtomicU64::new(0), every_percent, started: Instant::now() }
    }

    /// One more unit done (from any thread).
    pub fn inc(&self) {
        let done = self.done.fetch_add(1, Ordering::Relaxed) + 1;
        if let Some(bar) = &self.bar {
            bar.inc(1);
            return;
        }
        if self.every_percent == 0 {
            return;
        }
        let percent = |d: u64| d * 100 / self.total.max(1);
        if percent(done) / self.every_percent > percent(done - 1) / self.every_percent || done == self.total {
            let elapsed = self.started.elapsed().as_secs_f64();
            let to_go = elapsed / done as f64 * self.total.saturating_sub(done) as f64;
            eprintln!(
                "[{:>3}%] {}: {done} / {}, {elapsed:.0} s elapsed, ~{to_go:.0} s to go",
                percent(done),
                self.what,
                self.total
            );
        }
    }
}

impl Drop for Progress {
    /// The bar leaves the terminal as it found it; the job prints its own result.
    fn drop(&mut self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}
