//! Progress reporting: bars on a terminal, plain lines otherwise, nothing with `--quiet`; the
//! command line's [`ProgressSink`].

use indicatif::{ProgressBar, ProgressStyle};
use prm_bake::{Phase, ProgressSink};
use std::io::IsTerminal;
use std::time::{Duration, Instant};

#[derive(Clone, Copy, PartialEq)]
enum Mode {
    Bars,
    Lines,
    Quiet,
}

/// Where progress goes (always stderr).
pub struct Progress {
    mode: Mode,
    /// The phase under way.
    current: Option<Current>,
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
        Progress { mode, current: None }
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
}

impl ProgressSink for Progress {
    fn phase_start(&mut self, phase: Phase, total: u64) {
        // The atlas has no steps to show: it only gets its summary line.
        let bar = (self.mode == Mode::Bars && phase != Phase::Atlas).then(|| {
            let bar = ProgressBar::new(total);
            let style = ProgressStyle::with_template("{prefix:>16} [{bar:32}] {pos}/{len} {elapsed_precise} eta {eta}")
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> ");
            bar.set_style(style);
            bar.set_prefix(phase.name());
            bar
        });
        self.current = Some(Current {
            phase,
            bar,
            total,
            done: 0,
            started: Instant::now(),
            last_line: Instant::now(),
        });
    }

    fn phase_advance(&mut self, done: u64) {
        let mode = self.mode;
        let Some(c) = &mut self.current else {
            return;
        };
        let n = done.saturating_sub(c.done);
        c.done = c.done.max(done);
        if let Some(bar) = &c.bar {
            bar.inc(n);
        } else if mode == Mode::Lines && c.last_line.elapsed() > Duration::from_secs(5) {
            c.last_line = Instant::now();
            eprintln!(
                "{}: {}/{} ({:.0}%), {:.1} s",
                c.phase.name(),
                c.done,
                c.total,
                100.0 * c.done as f64 / c.total.max(1) as f64,
                c.started.elapsed().as_secs_f64()
            );
        }
    }

    fn phase_finish(&mut self, phase: Phase, summary: &str, seconds: f64) {
        if let Some(bar) = self.current.take().and_then(|c| c.bar) {
            bar.finish_and_clear();
        }
        self.say(&format!("{:>16}: {summary} ({seconds:.2} s)", phase.name()));
    }

    fn info(&mut self, line: &str) {
        self.say(line);
    }

    fn warn(&mut self, line: &str) {
        Progress::warn(self, line);
    }
}

/// The phase under way.
struct Current {
    phase: Phase,
    bar: Option<ProgressBar>,
    total: u64,
    done: u64,
    started: Instant,
    last_line: Instant,
}
