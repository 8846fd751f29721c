//! Progress of a long step on stderr, where the user watching it is.
//!
//! On a terminal an indicatif bar (a spinner when the amount of work is not
//! known) appears once the step has taken a second and is cleared when it
//! ends. Elsewhere (stderr a file or a pipe, as in a batch job's log) a bar
//! draws nothing, and an offline render of a large scan would log nothing for
//! minutes; there a plain line is written every `SNELL_PROGRESS_SECONDS`
//! seconds instead (default 30, `0` for none), so a short step logs nothing.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{OnceLock, mpsc};
use std::time::{Duration, Instant};

/// How long a step runs before its bar or spinner appears on a terminal.
const BAR_AFTER: Duration = Duration::from_secs(1);

/// How often the watcher looks at the step: the bar's refresh, and how late
/// a log line can be.
const LOOK_EVERY: Duration = Duration::from_millis(25);

/// The log lines' interval when `SNELL_PROGRESS_SECONDS` is not set.
const DEFAULT_LOG_EVERY: Duration = Duration::from_secs(30);

/// A step to watch: what it does and, when known, how much of it is done.
pub struct Step<'a> {
    /// What the step does, as the progress says it ("rendering").
    pub what: String,
    /// Units done so far of a known total, counted by the step as it goes.
    pub count: Option<Count<'a>>,
}

/// Work units done of a total (the render's tiles).
pub struct Count<'a> {
    pub done: &'a AtomicUsize,
    pub total: usize,
    /// The units' name, plural ("tiles").
    pub unit: &'static str,
}

impl Step<'_> {
    /// A step whose amount of work is not known (a spinner on a terminal).
    pub fn named(what: impl Into<String>) -> Step<'static> {
        Step {
            what: what.into(),
            count: None,
        }
    }

    /// The log line at `elapsed` into the step.
    fn line(&self, elapsed: Duration) -> String {
        let so_far = span(elapsed);
        match &self.count {
            None => format!("{}: {so_far} so far", self.what),
            Some(c) => {
                let done = c.done.load(Ordering::Relaxed).min(c.total);
                let left = left_note(elapsed, done as u64, c.total as u64);
                format!(
                    "{}: {done} of {} {} ({}%), {so_far} so far{left}",
                    self.what,
                    c.total,
                    c.unit,
                    done * 100 / c.total.max(1)
                )
            }
        }
    }

    /// The terminal's bar (or spinner), started `so_far` into the step.
    fn bar(&self, so_far: Duration) -> indicatif::ProgressBar {
        match &self.count {
            None => {
                let b = indicatif::ProgressBar::new_spinner().with_elapsed(so_far);
                b.set_style(style(&format!("{{spinner}} {}, {{elapsed}}", self.what)));
                b
            }
            Some(c) => {
                let b = indicatif::ProgressBar::new(c.total as u64).with_elapsed(so_far);
                // indicatif's own `{eta}` extrapolates from the latest
                // ticks' rate, which the bar (started a second in, its first
                // position a jump from 0) showed as "0s" throughout; the log
                // lines' estimate from the whole step's rate is the one shown.
                let left = |s: &indicatif::ProgressState, w: &mut dyn std::fmt::Write| {
                    let note = left_note(s.elapsed(), s.pos(), s.len().unwrap_or(0));
                    let _ = w.write_str(&note);
                };
                b.set_style(
                    style(&format!(
                        "{} [{{bar:40}}] {{pos}}/{{len}} {}{{left}}",
                        self.what, c.unit
                    ))
                    .with_key("left", left),
                );
                b
            }
        }
    }

    /// Brings the terminal's bar up to date.
    fn tick(&self, b: &indicatif::ProgressBar) {
        match &self.count {
            None => b.tick(),
            Some(c) => b.set_position(c.done.load(Ordering::Relaxed) as u64),
        }
    }
}

/// The progress style of every snell bar: `template` with `=> ` bars.
pub fn style(template: &str) -> indicatif::ProgressStyle {
    indicatif::ProgressStyle::with_template(template)
        .expect("valid template")
        .progress_chars("=> ")
}

/// Runs `f` on a worker thread while this one shows `step`'s progress (none
/// when `quiet`). Returns `f`'s value as soon as it ends.
pub fn watch<T: Send>(step: &Step, quiet: bool, f: impl FnOnce() -> T + Send) -> T {
    // Read (and a bad value warned of) whatever is shown, as every
    // `SNELL_*` variable is.
    let every = log_every();
    let show = if quiet {
        Show::Nothing
    } else if std::io::stderr().is_terminal() {
        Show::Bar
    } else {
        every.map_or(Show::Nothing, Show::Log)
    };
    if show == Show::Nothing {
        return f();
    }
    let (finished, ended) = mpsc::channel::<()>();
    std::thread::scope(|s| {
        let worker = s.spawn(|| {
            let out = f();
            // Wakes the watcher now rather than at its next look.
            let _ = finished.send(());
            out
        });
        let start = Instant::now();
        let mut bar: Option<indicatif::ProgressBar> = None;
        let mut logged = 0u32;
        // A panicking worker ends without sending: `is_finished` ends the loop.
        while !worker.is_finished() {
            if ended.recv_timeout(LOOK_EVERY).is_ok() {
                break;
            }
            let elapsed = start.elapsed();
            match show {
                Show::Bar => {
                    if bar.is_none() && elapsed > BAR_AFTER {
                        bar = Some(step.bar(elapsed));
                    }
                    if let Some(b) = &bar {
                        step.tick(b);
                    }
                }
                Show::Log(every) => {
                    if elapsed >= every * (logged + 1) {
                        logged = (elapsed.as_secs_f64() / every.as_secs_f64()) as u32;
                        eprintln!("{}", step.line(elapsed));
                    }
                }
                Show::Nothing => {}
            }
        }
        if let Some(b) = bar {
            b.finish_and_clear();
        }
        worker.join().expect("worker thread panicked")
    })
}

#[derive(Clone, Copy, PartialEq, Debug)]
enum Show {
    Nothing,
    Bar,
    Log(Duration),
}

/// The log lines' interval: `SNELL_PROGRESS_SECONDS` (seconds, fractions
/// allowed; `0` for no lines), else 30 s. A value that is not a number of
/// seconds is ignored with a warning, as `SNELL_MEMORY_LIMIT`'s is.
fn log_every() -> Option<Duration> {
    static EVERY: OnceLock<Option<Duration>> = OnceLock::new();
    *EVERY.get_or_init(|| match snell::env::setting("SNELL_PROGRESS_SECONDS") {
        None => Some(DEFAULT_LOG_EVERY),
        Some(s) => match parse_interval(&s) {
            Ok(every) => every,
            Err(why) => {
                eprintln!("warning: SNELL_PROGRESS_SECONDS: {why}; ignored");
                Some(DEFAULT_LOG_EVERY)
            }
        },
    })
}

/// Seconds from 0 to a day; `None` for 0 (no lines).
fn parse_interval(s: &str) -> Result<Option<Duration>, String> {
    const DAY: f64 = 86_400.0;
    match s.trim().parse::<f64>() {
        Ok(0.0) => Ok(None),
        Ok(x) if x > 0.0 && x <= DAY => Ok(Some(Duration::from_secs_f64(x))),
        _ => Err(format!(
            "expected seconds from 0 (no progress lines) to {DAY}, got '{s}'"
        )),
    }
}

/// `", about 1 min 30 s left"` when `done` of `total` units took `elapsed`:
/// the rest at the step's mean rate so far; empty while nothing is done.
fn left_note(elapsed: Duration, done: u64, total: u64) -> String {
    match done.min(total) {
        0 => String::new(),
        d => {
            let rest = elapsed.mul_f64((total - d) as f64 / d as f64);
            format!(", about {} left", span(rest))
        }
    }
}

/// A duration as a log reads it: `42 s`, `3 min 05 s`, `2 h 07 min`.
fn span(d: Duration) -> String {
    let s = d.as_secs();
    match s {
        0..60 => format!("{s} s"),
        60..3600 => format!("{} min {:02} s", s / 60, s % 60),
        _ => format!("{} h {:02} min", s / 3600, s % 3600 / 60),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spans_read_as_a_log_does() {
        assert_eq!(span(Duration::from_millis(999)), "0 s");
        assert_eq!(span(Duration::from_secs(59)), "59 s");
        assert_eq!(span(Duration::from_secs(185)), "3 min 05 s");
        assert_eq!(
            span(Duration::from_secs(2 * 3600 + 7 * 60 + 59)),
            "2 h 07 min"
        );
    }

    /// A render's step of 400 tiles, `done` of them done.
    fn rendering(done: &AtomicUsize) -> Step<'_> {
        Step {
            what: "rendering".into(),
            count: Some(Count {
                done,
                total: 400,
                unit: "tiles",
            }),
        }
    }

    #[test]
    fn log_lines_say_the_share_done_and_the_time_left() {
        let done = AtomicUsize::new(0);
        let step = rendering(&done);
        assert_eq!(
            step.line(Duration::from_secs(30)),
            "rendering: 0 of 400 tiles (0%), 30 s so far"
        );
        done.store(100, Ordering::Relaxed);
        assert_eq!(
            step.line(Duration::from_secs(30)),
            "rendering: 100 of 400 tiles (25%), 30 s so far, about 1 min 30 s left"
        );
        assert_eq!(
            Step::named("preparing").line(Duration::from_secs(61)),
            "preparing: 1 min 01 s so far"
        );
    }

    /// A terminal that keeps the last line the bar wrote.
    #[derive(Debug, Default, Clone)]
    struct Screen(std::sync::Arc<std::sync::Mutex<String>>);

    impl indicatif::TermLike for Screen {
        fn width(&self) -> u16 {
            120
        }
        fn move_cursor_up(&self, _: usize) -> std::io::Result<()> {
            Ok(())
        }
        fn move_cursor_down(&self, _: usize) -> std::io::Result<()> {
            Ok(())
        }
        fn move_cursor_right(&self, _: usize) -> std::io::Result<()> {
            Ok(())
        }
        fn move_cursor_left(&self, _: usize) -> std::io::Result<()> {
            Ok(())
        }
        fn write_line(&self, s: &str) -> std::io::Result<()> {
            self.write_str(s)
        }
        fn write_str(&self, s: &str) -> std::io::Result<()> {
            if !s.trim().is_empty() {
                *self.0.lock().unwrap() = s.trim_end().to_string();
            }
            Ok(())
        }
        fn clear_line(&self) -> std::io::Result<()> {
            Ok(())
        }
        fn flush(&self) -> std::io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn the_bar_says_the_time_left_as_the_log_lines_do() {
        let done = AtomicUsize::new(0);
        let step = rendering(&done);
        let screen = Screen::default();
        let bar = step.bar(Duration::from_secs(30));
        bar.set_draw_target(indicatif::ProgressDrawTarget::term_like(Box::new(
            screen.clone(),
        )));
        bar.force_draw();
        let nothing_done = screen.0.lock().unwrap().clone();
        assert!(nothing_done.ends_with("0/400 tiles"), "{nothing_done}");
        done.store(100, Ordering::Relaxed);
        step.tick(&bar);
        bar.force_draw();
        let shown = screen.0.lock().unwrap().clone();
        assert!(
            shown.ends_with("100/400 tiles, about 1 min 30 s left"),
            "{shown}"
        );
        assert!(shown.starts_with("rendering ["), "{shown}");
    }

    #[test]
    fn intervals_are_seconds_and_zero_turns_lines_off() {
        assert_eq!(parse_interval("0"), Ok(None));
        assert_eq!(
            parse_interval(" 2.5 "),
            Ok(Some(Duration::from_millis(2500)))
        );
        for bad in ["-1", "NaN", "inf", "1e9", "ten", ""] {
            assert!(parse_interval(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn a_quiet_step_returns_its_value() {
        assert_eq!(watch(&Step::named("adding"), true, || 2 + 2), 4);
    }
}
