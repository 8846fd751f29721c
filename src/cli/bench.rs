//! `snell bench`: run a benchmark suite (time against error) and write its
//! results, tables and plots; see `snell::bench`.

use std::path::PathBuf;
use std::time::Duration;

use clap::Args as ClapArgs;

use snell::bench::{self, DEFAULT_REPEATS, Observer, Options, Suite, peer, targets};

#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Suite: quick (under 3 minutes on 2 cores), paper (the paper's Tables 1-4
    /// with error columns and anti-aliasing quality, about 25 minutes), full
    /// (paper plus filters, octree leaf sizes, PRSS variants, about 45 minutes)
    /// or scaling (frame time against volume size 64³..1024³ and image size
    /// 128²..2048², with a plot; about 10 minutes and 16 GB).
    /// (default: quick, or none when --peer is given).
    #[arg(long)]
    pub suite: Option<String>,
    /// Compare with a peer renderer on the 64³ glass sphere at 512×512 (POV-Ray
    /// 3.7's isosurface: `apt-get install povray`), timing both and measuring
    /// both against the analytic reference; fills the `bench:peer` section of
    /// --update. Skipped with a message when the peer is not installed.
    #[arg(long, value_name = "povray")]
    pub peer: Option<String>,
    /// Image side of the peer comparison (tests use a small one).
    #[arg(long, default_value_t = snell::bench::peer::PEER_SIZE, hide = true)]
    pub peer_size: u32,
    /// Output directory for results.json, results.csv, tables.md and plots.
    #[arg(long, default_value = "bench-out")]
    pub out: PathBuf,
    /// Timed runs per configuration after one warm-up (the median is reported).
    #[arg(long, default_value_t = DEFAULT_REPEATS)]
    pub repeats: usize,
    /// Replace this suite's section of a markdown file (e.g. BENCHMARKS.md).
    #[arg(long, value_name = "BENCHMARKS.md")]
    pub update: Option<PathBuf>,
    /// Worker threads (default: all cores; 2 for each renderer with --peer,
    /// and 2 with --targets, whose verdicts need 2); 1 to 1024.
    #[arg(long, allow_negative_numbers = true, value_parser = super::common::thread_count)]
    pub threads: Option<usize>,
    /// Directory of the scene files.
    #[arg(long, default_value = "scenes")]
    pub scenes: PathBuf,
    /// Measure every speed target of the product in one run and print each
    /// with its verdict (issue 7's frame times, prefilter rate and POV-Ray
    /// ratio, issue 4's octree over step 0.1 on every dataset): rounds over
    /// all configurations, about 3 minutes with POV-Ray on 2 cores. Fills
    /// the `bench:targets` section of --update.
    #[arg(long, conflicts_with_all = ["suite", "peer", "repeats"])]
    pub targets: bool,
    /// Rounds of --targets (each target's value is the median over rounds).
    #[arg(long, default_value_t = 3, requires = "targets")]
    pub rounds: usize,
    /// Timed frames per configuration and round of --targets.
    #[arg(long, default_value_t = 10, requires = "targets")]
    pub frames: usize,
    /// --targets without POV-Ray.
    #[arg(long, requires = "targets")]
    pub targets_skip_peer: bool,
    /// Image side of --targets (tests use a small one; verdicts need 512).
    #[arg(long, default_value_t = snell::bench::targets::TARGET_SIZE, hide = true, requires = "targets")]
    pub targets_size: u32,
    /// Volume side of --targets' prefilter measurement.
    #[arg(long, default_value_t = snell::bench::targets::PREFILTER_SIZE, hide = true, requires = "targets")]
    pub prefilter_size: usize,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    // The file a run of minutes ends by updating is checked before the run.
    if let Some(u) = &a.update {
        super::common::check_output(u)?;
    }
    if a.targets {
        return run_targets(&a);
    }
    let suite = match (&a.suite, &a.peer) {
        (Some(name), _) => Some(Suite::by_name(name)?),
        (None, None) => Some(Suite::by_name("quick")?),
        (None, Some(_)) => None,
    };
    if let Some(peer) = &a.peer
        && !peer::PEERS.contains(&peer.as_str())
    {
        return Err(bench::BenchError::UnknownPeer(peer.clone()).into());
    }
    if let Some(suite) = suite {
        run_suite(&a, &suite)?;
    }
    if let Some(peer) = &a.peer {
        run_peer(&a, peer)?;
    }
    Ok(())
}

fn run_suite(a: &Args, suite: &Suite) -> anyhow::Result<()> {
    let opts = Options {
        scenes_dir: a.scenes.clone(),
        out_dir: a.out.clone(),
        repeats: a.repeats,
        threads: a.threads,
        update: a.update.clone(),
        command: command_line(),
    };
    let mut bar = Bar::new(if !cfg!(debug_assertions) {
        format!(
            "snell bench --suite {}: {} Budget: {}.",
            suite.name, suite.description, suite.budget
        )
    } else {
        "warning: debug build: the times mean nothing, use --release".into()
    });
    let outcome = bench::bench(suite, &opts, &mut bar)?;
    bar.done();
    // The progress counted classification rows as steps too.
    let classified: usize = (outcome.report.tables.iter())
        .map(|t| match &t.body {
            bench::results::TableResultBody::Classify { rows, .. } => rows.len(),
            _ => 0,
        })
        .sum();
    let classified = match classified {
        0 => String::new(),
        1 => " and 1 classification".into(),
        n => format!(" and {n} classifications"),
    };
    eprintln!(
        "{} configurations{classified} in {}; wrote:",
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

fn run_peer(a: &Args, name: &str) -> anyhow::Result<()> {
    let opts = peer::PeerOptions {
        scenes_dir: a.scenes.clone(),
        out_dir: a.out.clone(),
        repeats: a.repeats,
        threads: a.threads.unwrap_or(peer::PEER_THREADS),
        size: a.peer_size,
        update: a.update.clone(),
        command: command_line(),
        snell_exe: std::env::current_exe().ok(),
    };
    if opts.size == 0 {
        anyhow::bail!("--peer-size must be at least 1");
    }
    let mut banner = format!(
        "snell bench --peer {name}: snell and {name} on the glass sphere at {s}x{s}, {} threads each, one warm-up and {} timed runs per row, round-robin (under a minute at 512x512 on 2 cores).",
        opts.threads,
        opts.repeats,
        s = opts.size
    );
    if cfg!(debug_assertions) {
        banner.push_str("\nwarning: debug build: snell's times mean nothing, use --release");
    }
    let mut bar = Bar::new(banner);
    let outcome = match peer::peer_bench(name, &opts, &mut bar) {
        Ok(o) => o,
        Err(bench::BenchError::PeerMissing(msg)) => {
            bar.done();
            eprintln!("skipping the {name} comparison: {msg}");
            return Ok(());
        }
        Err(e) => return Err(e.into()),
    };
    bar.done();
    for x in &outcome.report.ratios {
        eprintln!(
            "POV-Ray {} time / snell {} time: {:.2}x per frame, {:.2}x trace / render; p50 error {:.3} (snell) vs {:.3} (POV-Ray) squares",
            x.povray, x.snell, x.frame, x.render, x.snell_p50, x.povray_p50
        );
    }
    eprintln!(
        "{} rows in {}; wrote:",
        outcome.report.rows.len(),
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

fn run_targets(a: &Args) -> anyhow::Result<()> {
    let opts = targets::TargetOptions {
        scenes_dir: a.scenes.clone(),
        out_dir: a.out.clone(),
        rounds: a.rounds,
        frames: a.frames,
        threads: a.threads.unwrap_or(targets::TARGET_THREADS),
        size: a.targets_size,
        prefilter_size: a.prefilter_size,
        peer: !a.targets_skip_peer,
        update: a.update.clone(),
        command: command_line(),
    };
    let mut banner = format!(
        "snell bench --targets: {} rounds over every target's configurations, {} threads, {}x{} (about 3 minutes on 2 cores with POV-Ray).",
        opts.rounds, opts.threads, opts.size, opts.size
    );
    if cfg!(debug_assertions) {
        banner.push_str("\nwarning: debug build: the times mean nothing, use --release");
    }
    let mut bar = Bar::new(banner);
    let outcome = targets::run_targets(&opts, &mut bar)?;
    bar.done();
    print!("{}", targets::section(&outcome.report));
    eprintln!(
        "{} targets in {}; wrote:",
        outcome.report.rows.len(),
        bench::report::fmt_duration(outcome.report.total_s)
    );
    for p in &outcome.written {
        eprintln!("  {}", p.display());
    }
    Ok(())
}

/// The command as typed, quoted where a shell would need it.
fn command_line() -> String {
    std::env::args()
        .map(|a| snell::human::shell_quote(&a))
        .collect::<Vec<_>>()
        .join(" ")
}

/// Progress on stderr: a banner saying what the run does, a bar with an
/// ETA (configurations done of all) and one line per finished
/// configuration, which stays in the scroll-back (and is all that shows
/// when stderr is not a terminal).
struct Bar {
    bar: Option<indicatif::ProgressBar>,
    /// Printed when the run begins: after its inputs and outputs have been
    /// checked, so a bad flag's error is not preceded by a promise of
    /// minutes of work.
    banner: String,
}

impl Bar {
    fn new(banner: String) -> Bar {
        Bar { bar: None, banner }
    }

    fn done(&mut self) {
        if let Some(b) = self.bar.take() {
            b.finish_and_clear();
        }
    }
}

impl Observer for Bar {
    fn begin(&mut self, total: usize) {
        eprintln!("{}", self.banner);
        let b = indicatif::ProgressBar::new(total as u64);
        b.set_style(super::progress::style(
            "[{bar:30}] {pos}/{len} runs, {elapsed} elapsed, ETA {eta}  {wide_msg}",
        ));
        b.enable_steady_tick(Duration::from_millis(500));
        self.bar = Some(b);
    }

    fn start(&mut self, what: &str) {
        if let Some(b) = &self.bar {
            b.set_message(what.to_string());
        }
    }

    fn finish(&mut self, line: &str) {
        self.note(line);
        self.tick();
    }

    fn tick(&mut self) {
        if let Some(b) = &self.bar {
            b.inc(1);
        }
    }

    fn note(&mut self, line: &str) {
        match &self.bar {
            Some(b) => b.suspend(|| eprintln!("{line}")),
            None => eprintln!("{line}"),
        }
    }
}
