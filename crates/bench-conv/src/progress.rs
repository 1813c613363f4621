//! Progress of long jobs: an indicatif bar with ETA on a terminal, and a plain line at
//! every 5 % when stderr is a log file (where indicatif draws nothing).

use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};

/// A progress report over `len` units (runs, frames), safe to share between threads.
#[derive(Debug)]
pub struct Progress {
    bar: ProgressBar,
    /// Plain-text mode: the start time and the last 5 % step printed.
    plain: Option<(Instant, Mutex<u64>)>,
    unit: &'static str,
    /// Plain-text mode: when the last note was printed.
    last_note: Mutex<Option<Instant>>,
}

impl Progress {
    /// A report over `len` units named `unit` ("runs", "frames").
    pub fn new(len: u64, unit: &'static str) -> Self {
        let bar = ProgressBar::new(len);
        bar.set_style(
            ProgressStyle::with_template(&format!(
                "{{elapsed_precise}} [{{bar:40}}] {{pos}}/{{len}} {unit}, ETA {{eta}} {{msg}}"
            ))
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
        );
        let plain = (!std::io::stderr().is_terminal()).then(|| (Instant::now(), Mutex::new(0)));
        Self {
            bar,
            plain,
            unit,
            last_note: Mutex::new(None),
        }
    }

    /// Count `n` more units done; `message` follows the count (e.g. "3 successes").
    pub fn inc(&self, n: u64, message: &str) {
        self.bar.inc(n);
        self.bar.set_message(message.to_string());
        let Some((started, last_step)) = &self.plain else {
            return;
        };
        let (pos, len) = (self.bar.position(), self.bar.length().unwrap_or(0).max(1));
        let step = pos * 20 / len;
        let mut last = last_step.lock().unwrap_or_else(|e| e.into_inner());
        if step > *last {
            *last = step;
            let elapsed = started.elapsed().as_secs_f64();
            let eta = elapsed * (len - pos.min(len)) as f64 / pos.max(1) as f64;
            eprintln!(
                "{} / {len} {} ({} %) in {}, ETA {} {message}",
                pos,
                self.unit,
                pos * 100 / len,
                clock(elapsed),
                clock(eta)
            );
        }
    }

    /// Say what a long unit is doing (a global search's phase): beside the bar on a
    /// terminal, as a line at most every 10 s in a log.
    pub fn note(&self, message: &str) {
        if self.plain.is_none() {
            self.bar.set_message(message.to_string());
            return;
        }
        let mut last = self.last_note.lock().unwrap_or_else(|e| e.into_inner());
        if last.is_none_or(|at| at.elapsed().as_secs_f64() >= 10.0) {
            *last = Some(Instant::now());
            eprintln!("{message}");
        }
    }

    /// Close the bar.
    pub fn finish(&self) {
        self.bar.finish();
    }
}

/// `h:mm:ss`.
fn clock(seconds: f64) -> String {
    let s = seconds.round() as u64;
    format!("{}:{:02}:{:02}", s / 3600, s / 60 % 60, s % 60)
}
