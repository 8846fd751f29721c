//! Benchmarks as a product feature: run time against error, per configuration.
//!
//! A [`Suite`] is a list of tables of experiments (a scene file plus `--set`
//! overrides). [`bench`](fn@bench) renders each distinct configuration once to warm up
//! and then `repeats` times, reports the median wall time with the per-stage
//! profile, work counters and peak memory of the median run, measures the hit
//! error against ground truth (the analytic spheres for sphere phantoms, a
//! dense march otherwise) and, for anti-aliasing, image quality against a
//! 16×16 supersampled render. It writes `results.json`, `results.csv`,
//! `tables.md` and the plots, and can replace a suite's section of
//! BENCHMARKS.md, so published tables are always generated, never typed.
//!
//! Timings are only comparable within one run (same machine, same thread
//! count, same build); the provenance line of every table says which.

pub mod machine;
pub mod pareto;
pub mod peer;
pub mod plot;
pub mod prefilter_pass;
pub mod report;
pub mod results;
mod runner;
pub mod suite;
pub mod targets;
pub mod update;

use std::path::{Path, PathBuf};
use std::time::Instant;

pub use results::Report;
pub use runner::{DENSE_MARCH, QUALITY_REFERENCE_SAMPLES, content_overrides};
pub use suite::{SUITES, Suite};

use crate::scene::SceneError;

/// Share of CPU time used by other processes above which a run is flagged.
const OTHER_CPU_WARNING: f64 = 0.05;

/// Timed runs per configuration unless told otherwise.
pub const DEFAULT_REPEATS: usize = 3;

#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error("unknown suite '{0}' (expected one of: quick, paper, full, scaling)")]
    UnknownSuite(String),
    #[error("unknown peer '{0}' (expected: povray)")]
    UnknownPeer(String),
    /// The peer renderer is not installed: callers skip the comparison.
    #[error("{0}")]
    PeerMissing(String),
    #[error(transparent)]
    Peer(#[from] crate::peer::PeerError),
    #[error("--repeats must be at least 1")]
    NoRepeats,
    #[error("--threads must be at least 1")]
    NoThreads,
    #[error("--rounds and --frames must be at least 1")]
    NoRounds,
    #[error("--targets-size and --prefilter-size must be at least 1")]
    NoTargetSize,
    #[error("cannot start {threads} worker threads: {msg}")]
    Threads { threads: usize, msg: String },
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("output directory {}: not a directory", path.display())]
    NotADirectory { path: PathBuf },
    #[error("output directory {}: {what} ({source})", path.display())]
    OutDir {
        path: PathBuf,
        what: &'static str,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: scene file not found (run from the repository root or pass --scenes DIR)", path.display())]
    MissingScene { path: PathBuf },
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error("{what}: {msg}")]
    Measure { what: String, msg: String },
    #[error("{}: {source}", path.display())]
    Section {
        path: PathBuf,
        #[source]
        source: update::SectionError,
    },
    #[error("{}: plot: {msg}", path.display())]
    Plot { path: PathBuf, msg: String },
}

/// Hears about progress (the CLI draws a progress bar). Calls come from the
/// thread running the suite.
pub trait Observer: Send {
    /// The run will measure `total` items (configurations and classification rows).
    fn begin(&mut self, _total: usize) {}
    /// Work on something (a configuration, a reference image) starts.
    fn start(&mut self, _what: &str) {}
    /// An item finished; `line` summarises it.
    fn finish(&mut self, _line: &str) {}
    /// One of the `total` steps is done, with nothing to say.
    fn tick(&mut self) {}
    /// A line to show without counting a step.
    fn note(&mut self, _line: &str) {}
}

/// An observer that ignores everything.
pub struct Silent;
impl Observer for Silent {}

/// How to run a suite.
#[derive(Clone, Debug)]
pub struct Options {
    /// Where the scene files are (`scenes/` of the repository).
    pub scenes_dir: PathBuf,
    /// Where results go (created if missing).
    pub out_dir: PathBuf,
    pub repeats: usize,
    /// Worker threads (`None`: all cores).
    pub threads: Option<usize>,
    /// Markdown file whose section of this suite is replaced (or appended).
    pub update: Option<PathBuf>,
    /// The command line, recorded with the results.
    pub command: String,
}

/// Everything a finished run produced.
pub struct Outcome {
    pub report: Report,
    /// Files written, in order.
    pub written: Vec<PathBuf>,
}

/// Runs `suite`, writes its outputs into `opts.out_dir` and updates
/// `opts.update`. Inputs and output locations are checked before the first
/// render, so a bad path fails in a second rather than after the run.
pub fn bench(
    suite: &Suite,
    opts: &Options,
    observer: &mut dyn Observer,
) -> Result<Outcome, BenchError> {
    if opts.repeats == 0 {
        return Err(BenchError::NoRepeats);
    }
    if opts.threads == Some(0) {
        return Err(BenchError::NoThreads);
    }
    // What can be refused is refused before the output directory exists.
    check_scene_files(suite, &opts.scenes_dir)?;
    if let Some(p) = &opts.update {
        read_update_target(p, &suite.name)?;
    }
    prepare_out_dir(&opts.out_dir)?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.threads.unwrap_or(0))
        .build()
        .map_err(|e| BenchError::Threads {
            threads: opts.threads.unwrap_or(0),
            msg: e.to_string(),
        })?;

    let date = machine::utc_now();
    let start = Instant::now();
    let cpu_before = machine::cpu_snapshot();
    let runner = runner::Runner::new(&opts.scenes_dir, opts.repeats, observer);
    runner.check(suite)?;
    let measured = pool.install(|| runner.run(suite))?;
    let total_s = start.elapsed().as_secs_f64();
    let other_cpu_share = match (cpu_before, machine::cpu_snapshot()) {
        (Some(a), Some(b)) => machine::other_cpu_share(&a, &b),
        _ => None,
    };
    let mut warnings = measured.warnings;
    if let Some(share) = other_cpu_share
        && share > OTHER_CPU_WARNING
    {
        warnings.push(format!(
            "other processes used {:.0}% of the machine's CPU time during the run: the times \
are inflated; rerun on a quiet machine",
            100.0 * share
        ));
    }
    let machine = machine::machine();
    if machine.build_profile == "debug" {
        warnings.insert(
            0,
            "debug build: the times mean nothing, use --release".into(),
        );
    }
    let report = Report {
        suite: suite.name.clone(),
        description: suite.description.clone(),
        budget: suite.budget.clone(),
        machine,
        run: results::RunInfo {
            command: opts.command.clone(),
            date,
            threads: pool.current_num_threads(),
            repeats: opts.repeats,
            scenes_dir: opts.scenes_dir.display().to_string(),
            total_s,
            other_cpu_share,
        },
        tables: measured.tables,
        configurations: measured.configurations,
        builds: measured.builds,
        references: measured.references,
        warnings,
    };
    let mut written = write_outputs(&report, &opts.out_dir)?;
    if let Some(p) = &opts.update {
        update_markdown(p, &report)?;
        written.push(p.clone());
    }
    Ok(Outcome { report, written })
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> BenchError + '_ {
    move |source| BenchError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Creates the output directory and proves it is writable.
fn prepare_out_dir(dir: &Path) -> Result<(), BenchError> {
    if dir.exists() && !dir.is_dir() {
        return Err(BenchError::NotADirectory {
            path: dir.to_path_buf(),
        });
    }
    let out_dir = |what: &'static str| {
        move |source| BenchError::OutDir {
            path: dir.to_path_buf(),
            what,
            source,
        }
    };
    std::fs::create_dir_all(dir).map_err(out_dir("cannot create it"))?;
    let probe = dir.join(format!(".snell-bench-probe-{}", std::process::id()));
    std::fs::write(&probe, b"").map_err(out_dir("cannot write files in it"))?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

/// The current text of the markdown file to update (empty if it does not
/// exist yet), after checking its markers and that it can be written.
fn read_update_target(path: &Path, suite: &str) -> Result<String, BenchError> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            let dir = match path.parent() {
                Some(d) if !d.as_os_str().is_empty() => d,
                _ => Path::new("."),
            };
            if !dir.is_dir() {
                return Err(BenchError::Io {
                    path: path.to_path_buf(),
                    source: std::io::Error::new(
                        std::io::ErrorKind::NotFound,
                        format!("directory {} does not exist", dir.display()),
                    ),
                });
            }
            String::new()
        }
        Err(e) => return Err(io_err(path)(e)),
    };
    update::check(&text, suite).map_err(|source| BenchError::Section {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(text)
}

fn check_scene_files(suite: &Suite, dir: &Path) -> Result<(), BenchError> {
    let mut files: Vec<&str> = suite.experiments().map(|(_, e)| e.scene.as_str()).collect();
    for t in &suite.tables {
        if let suite::TableBody::Classify(c) = &t.body {
            files.extend(c.rows.iter().map(|r| r.scene.as_str()));
        }
    }
    for f in files {
        let path = dir.join(f);
        if !path.is_file() {
            return Err(BenchError::MissingScene { path });
        }
    }
    Ok(())
}

fn write_text(path: &Path, text: &str) -> Result<(), BenchError> {
    crate::atomic::write_atomic(path, |w| std::io::Write::write_all(w, text.as_bytes()))
        .map_err(io_err(path))
}

/// Writes `results.json`, `results.csv`, `tables.md` and the plots.
pub fn write_outputs(report: &Report, dir: &Path) -> Result<Vec<PathBuf>, BenchError> {
    let mut written = Vec::new();
    let p = dir.join("results.json");
    let json = serde_json::to_string_pretty(report).map_err(|e| BenchError::Io {
        path: p.clone(),
        source: e.into(),
    })?;
    write_text(&p, &(json + "\n"))?;
    written.push(p);
    let p = dir.join("results.csv");
    write_text(&p, &report::csv(report))?;
    written.push(p);
    let p = dir.join("tables.md");
    write_text(&p, &report::tables_md(report))?;
    written.push(p);
    written.extend(plot::write_plots(report, dir)?);
    Ok(written)
}

/// Replaces (or appends) the report's suite section in the markdown file.
pub fn update_markdown(path: &Path, report: &Report) -> Result<(), BenchError> {
    let doc = read_update_target(path, &report.suite)?;
    let new = update::replace_section(&doc, &report.suite, &report::section(report)).map_err(
        |source| BenchError::Section {
            path: path.to_path_buf(),
            source,
        },
    )?;
    write_text(path, &new)
}
