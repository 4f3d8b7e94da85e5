//! The progress line on stderr.

use std::io::{IsTerminal, Write};
use std::time::{Duration, Instant};

use gridscada_sim::scenario::{self, Scenario};

/// The progress line on stderr: a bar when it is a terminal, a plain line
/// every 10 % otherwise; a quiet one (a run beside another, whose bar it
/// would overwrite) says only when it starts and ends.
pub(super) struct Progress {
    label: String,
    tty: bool,
    quiet: bool,
    started: Instant,
    last_draw: Instant,
    last_tenth: u64,
}

impl Progress {
    pub(super) fn new(label: &str, scn: &Scenario, quiet: bool) -> Self {
        let p = Progress {
            label: format!("{} [{}]", scn.name, label),
            tty: std::io::stderr().is_terminal() && !quiet,
            quiet,
            started: Instant::now(),
            last_draw: Instant::now(),
            last_tenth: 0,
        };
        if !p.tty {
            eprintln!("{}: starting", p.label);
        }
        p
    }

    pub(super) fn update(&mut self, now: Duration, total: Duration) {
        if self.quiet {
            return;
        }
        let frac = (now.as_secs_f64() / total.as_secs_f64().max(1e-9)).clamp(0.0, 1.0);
        let wall = self.started.elapsed().as_secs_f64().max(1e-6);
        let speed = now.as_secs_f64() / wall;
        if self.tty {
            if self.last_draw.elapsed() < Duration::from_millis(200) {
                return;
            }
            self.last_draw = Instant::now();
            let filled = (frac * 30.0) as usize;
            eprint!(
                "\r{} [{}{}] {} / {}  ×{:.0} ",
                self.label,
                "#".repeat(filled),
                ".".repeat(30 - filled),
                scenario::time::format_offset(Duration::from_secs(now.as_secs())),
                scenario::time::format_offset(total),
                speed
            );
            let _ = std::io::stderr().flush();
        } else {
            let tenth = (frac * 10.0) as u64;
            if tenth > self.last_tenth && tenth < 10 {
                self.last_tenth = tenth;
                eprintln!(
                    "{}: {} of {} plant time, ×{:.0}",
                    self.label,
                    scenario::time::format_offset(Duration::from_secs(now.as_secs())),
                    scenario::time::format_offset(total),
                    speed
                );
            }
        }
    }

    pub(super) fn done(&mut self, total: Duration) {
        let wall = self.started.elapsed().as_secs_f64().max(1e-6);
        if self.tty {
            eprint!("\r\x1b[2K");
        }
        eprintln!(
            "{}: {} of plant time in {:.1} s of wall time (×{:.0})",
            self.label,
            scenario::time::format_offset(total),
            wall,
            total.as_secs_f64() / wall
        );
    }
}
