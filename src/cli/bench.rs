//! `snell bench`: run a benchmark suite (time against error) and write its
//! results, tables and plots; see `snell::bench`.

use std::path::PathBuf;
use std::time::Duration;

use clap::Args as ClapArgs;

use snell::bench::{self, DEFAULT_REPEATS, Observer, Options, Suite};

#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Suite: quick (under 3 minutes on 2 cores), paper (the paper's Tables 1-4
    /// with error columns, about 1.5 hours) or full (paper plus filters, octree
    /// leaf sizes, PRSS variants, about 2 hours).
    #[arg(long, default_value = "quick")]
    pub suite: String,
    /// Output directory for results.json, results.csv, tables.md and plots.
    #[arg(long, default_value = "bench-out")]
    pub out: PathBuf,
    /// Timed runs per configuration after one warm-up (the median is reported).
    #[arg(long, default_value_t = DEFAULT_REPEATS)]
    pub repeats: usize,
    /// Replace this suite's section of a markdown file (e.g. BENCHMARKS.md).
    #[arg(long, value_name = "BENCHMARKS.md")]
    pub update: Option<PathBuf>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Directory of the scene files.
    #[arg(long, default_value = "scenes")]
    pub scenes: PathBuf,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let suite = Suite::by_name(&a.suite)?;
    let opts = Options {
        scenes_dir: a.scenes,
        out_dir: a.out,
        repeats: a.repeats,
        threads: a.threads,
        update: a.update,
        command: command_line(),
    };
    if !cfg!(debug_assertions) {
        eprintln!(
            "snell bench --suite {}: {} Budget: {}.",
            suite.name, suite.description, suite.budget
        );
    } else {
        eprintln!("warning: debug build: the times mean nothing, use --release");
    }
    let mut bar = Bar::new();
    let outcome = bench::bench(&suite, &opts, &mut bar)?;
    bar.done();
    eprintln!(
        "{} configurations in {}; wrote:",
        outcome.report.configurations.len(),
        bench::report::fmt_duration(outcome.report.run.total_s)
    );
    for p in &outcome.written {
        eprintln!("  {}", p.display());
    }
    for w in &outcome.report.warnings {
        eprintln!("warning: {w}");
    }
    Ok(())
}

/// The command as typed, quoted where a shell would need it.
fn command_line() -> String {
    std::env::args()
        .map(|a| {
            if !a.is_empty()
                && a.chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c))
            {
                a
            } else {
                format!("'{}'", a.replace('\'', "'\\''"))
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// Progress on stderr: a bar with an ETA (configurations done of all) and
/// one line per finished configuration, which stays in the scroll-back (and
/// is all that shows when stderr is not a terminal).
struct Bar {
    bar: Option<indicatif::ProgressBar>,
}

impl Bar {
    fn new() -> Bar {
        Bar { bar: None }
    }

    fn done(&mut self) {
        if let Some(b) = self.bar.take() {
            b.finish_and_clear();
        }
    }
}

impl Observer for Bar {
    fn begin(&mut self, total: usize) {
        let b = indicatif::ProgressBar::new(total as u64);
        b.set_style(
            indicatif::ProgressStyle::with_template(
                "[{bar:30}] {pos}/{len} configurations, {elapsed} elapsed, ETA {eta}  {wide_msg}",
            )
            .expect("valid template")
            .progress_chars("=> "),
        );
        b.enable_steady_tick(Duration::from_millis(500));
        self.bar = Some(b);
    }

    fn start(&mut self, what: &str) {
        if let Some(b) = &self.bar {
            b.set_message(what.to_string());
        }
    }

    fn finish(&mut self, line: &str) {
        match &self.bar {
            Some(b) => {
                b.suspend(|| eprintln!("{line}"));
                b.inc(1);
            }
            None => eprintln!("{line}"),
        }
    }
}
