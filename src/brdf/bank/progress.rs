//! A progress line on stderr for the slow first build of a path bank (tens of seconds to
//! minutes, issue 24): on a terminal one line updated in place at most once a second,
//! elsewhere (a log, a pipe) a line every 10 s; a last line with the time taken. Nothing is
//! printed for a build that ends within the first second, nor when the environment
//! variable `PPRENDER_PROGRESS` is `0`, `off`, `false` or `no`.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Instant;

/// Where the lines go.
pub type Sink = Box<dyn Fn(&str) + Send + Sync>;

/// Whether `PPRENDER_PROGRESS` allows progress lines (module docs).
pub fn enabled_by_env() -> bool {
    match std::env::var("PPRENDER_PROGRESS") {
        Ok(v) => !matches!(
            v.trim().to_ascii_lowercase().as_str(),
            "0" | "off" | "false" | "no"
        ),
        Err(_) => true,
    }
}

/// Reports a build's progress (module docs); [`Reporter::update`] may be called from any
/// thread, as often as work completes: it prints only when a line is due.
pub struct Reporter {
    header: String,
    label: String,
    start: Instant,
    /// Milliseconds after `start` before which nothing more is printed.
    next_ms: AtomicU64,
    printed: AtomicBool,
    interactive: bool,
    enabled: bool,
    sink: Sink,
}

impl Reporter {
    /// A reporter on stderr, in place when stderr is a terminal: `header` is printed once
    /// (when the first line is due), then lines that start with `label` (short, so that
    /// the line updated in place does not wrap).
    pub fn new(header: impl Into<String>, label: impl Into<String>) -> Self {
        Self::with_sink(
            header,
            label,
            enabled_by_env(),
            std::io::stderr().is_terminal(),
            1000,
            Box::new(|s| eprint!("{s}")),
        )
    }

    /// A reporter writing to `sink`, silent for the first `delay_ms` milliseconds.
    pub fn with_sink(
        header: impl Into<String>,
        label: impl Into<String>,
        enabled: bool,
        interactive: bool,
        delay_ms: u64,
        sink: Sink,
    ) -> Self {
        Reporter {
            header: header.into(),
            label: label.into(),
            start: Instant::now(),
            next_ms: AtomicU64::new(delay_ms),
            printed: AtomicBool::new(false),
            interactive,
            enabled,
            sink,
        }
    }

    fn emit(&self, line: &str) {
        if self.interactive {
            (self.sink)(&format!("\r{line}\x1b[K"));
        } else {
            (self.sink)(&format!("{line}\n"));
        }
    }

    /// `done` of `total` units of work are complete.
    pub fn update(&self, done: u64, total: u64) {
        if !self.enabled {
            return;
        }
        let ms = self.start.elapsed().as_millis() as u64;
        let next = self.next_ms.load(Ordering::Relaxed);
        if ms < next {
            return;
        }
        let step = if self.interactive { 1000 } else { 10_000 };
        if self
            .next_ms
            .compare_exchange(next, ms + step, Ordering::Relaxed, Ordering::Relaxed)
            .is_err()
        {
            return; // another thread prints this one
        }
        if !self.printed.swap(true, Ordering::Relaxed) {
            (self.sink)(&format!("{}\n", self.header));
        }
        let f = (done as f64 / total.max(1) as f64).clamp(0.0, 1.0);
        let secs = ms as f64 / 1000.0;
        let left = if f > 0.0 {
            format!(", about {:.0} s left", secs * (1.0 - f) / f)
        } else {
            String::new()
        };
        self.emit(&format!(
            "{}: {:.0}%, {secs:.0} s{left}",
            self.label,
            100.0 * f
        ));
    }

    /// The work is done: the last line, if any was printed.
    pub fn finish(&self) {
        if self.enabled && self.printed.load(Ordering::Relaxed) {
            let secs = self.start.elapsed().as_secs_f64();
            let line = format!("{}: done in {secs:.0} s", self.label);
            if self.interactive {
                (self.sink)(&format!("\r{line}\x1b[K\n"));
            } else {
                (self.sink)(&format!("{line}\n"));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::{Arc, Mutex};

    fn collect(enabled: bool, interactive: bool, delay_ms: u64) -> (Reporter, Arc<Mutex<String>>) {
        let out = Arc::new(Mutex::new(String::new()));
        let o = out.clone();
        let r = Reporter::with_sink(
            "header",
            "bank",
            enabled,
            interactive,
            delay_ms,
            Box::new(move |s| o.lock().unwrap().push_str(s)),
        );
        (r, out)
    }

    #[test]
    fn a_header_then_lines_then_the_time_taken() {
        let (r, out) = collect(true, false, 0);
        r.update(25, 100);
        r.update(50, 100); // within 10 s of the last line: not printed
        r.finish();
        let s = out.lock().unwrap().clone();
        let lines: Vec<&str> = s.lines().collect();
        assert_eq!(lines.len(), 3, "{s:?}");
        assert_eq!(lines[0], "header");
        assert!(
            lines[1].starts_with("bank: 25%, 0 s, about 0 s left"),
            "{s:?}"
        );
        assert!(lines[2].starts_with("bank: done in"), "{s:?}");
        // in place on a terminal
        let (r, out) = collect(true, true, 0);
        r.update(1, 2);
        r.finish();
        let s = out.lock().unwrap().clone();
        assert!(
            s.starts_with("header\n\rbank: 50%") && s.ends_with("\x1b[K\n"),
            "{s:?}"
        );
    }

    #[test]
    fn quick_or_disabled_builds_print_nothing() {
        for (enabled, delay) in [(true, 60_000), (false, 0)] {
            let (r, out) = collect(enabled, false, delay);
            r.update(1, 2);
            r.finish();
            assert!(out.lock().unwrap().is_empty());
        }
    }
}
