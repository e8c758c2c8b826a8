//! Progress reporting: bars on a terminal, plain lines otherwise, nothing with `--quiet`.

use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;
use std::time::{Duration, Instant};

#[derive(Clone, Copy, PartialEq)]
enum Mode {
    Bars,
    Lines,
    Quiet,
}

/// Where progress goes (always stderr).
#[derive(Clone, Copy)]
pub struct Progress {
    mode: Mode,
}

impl Progress {
    /// Bars when stderr is a terminal, lines when it is not, nothing when `quiet`.
    pub fn new(quiet: bool) -> Progress {
        let mode = if quiet {
            Mode::Quiet
        } else if std::io::stderr().is_terminal() {
            Mode::Bars
        } else {
            Mode::Lines
        };
        Progress { mode }
    }

    /// A line of information.
    pub fn say(&self, line: &str) {
        if self.mode != Mode::Quiet {
            eprintln!("{line}");
        }
    }

    /// A warning; shown even with `--quiet`.
    pub fn warn(&self, line: &str) {
        eprintln!("warning: {line}");
    }

    /// Starts a phase of `total` steps.
    pub fn phase(&self, name: &str, total: u64) -> Phase {
        let bar = (self.mode == Mode::Bars).then(|| {
            let bar = ProgressBar::new(total);
            let style = ProgressStyle::with_template("{prefix:>16} [{bar:32}] {pos}/{len} {elapsed_precise} eta {eta}")
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> ");
            bar.set_style(style);
            bar.set_prefix(name.to_string());
            bar
        });
        Phase {
            name: name.to_string(),
            mode: self.mode,
            bar,
            total,
            done: 0,
            started: Instant::now(),
            last_line: Instant::now(),
        }
    }
}

/// One phase of the bake.
pub struct Phase {
    name: String,
    mode: Mode,
    bar: Option<ProgressBar>,
    total: u64,
    done: u64,
    started: Instant,
    last_line: Instant,
}

impl Phase {
    /// Steps done so far.
    pub fn done(&self) -> u64 {
        self.done
    }

    /// Records `n` more steps done.
    pub fn inc(&mut self, n: u64) {
        self.done += n;
        if let Some(bar) = &self.bar {
            bar.inc(n);
        } else if self.mode == Mode::Lines && self.last_line.elapsed() > Duration::from_secs(5) {
            self.last_line = Instant::now();
            eprintln!(
                "{}: {}/{} ({:.0}%), {:.1} s",
                self.name,
                self.done,
                self.total,
                100.0 * self.done as f64 / self.total.max(1) as f64,
                self.started.elapsed().as_secs_f64()
            );
        }
    }

    /// Ends the phase with a one-line summary; returns its duration in seconds.
    pub fn finish(self, summary: &str) -> f64 {
        let secs = self.started.elapsed().as_secs_f64();
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
        if self.mode != Mode::Quiet {
            eprintln!("{:>16}: {summary} ({secs:.2} s)", self.name);
        }
        secs
    }
}
