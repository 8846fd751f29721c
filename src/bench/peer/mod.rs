//! `snell bench --peer povray`: snell and POV-Ray 3.7 on the same scene, in
//! one run, timed and compared against the analytic reference.
//!
//! The scene is the 64³ u8 glass sphere (`sphere.toml`) at 512×512. snell
//! renders it with its main configuration (octree over Bézier-hull tags, the
//! default classification) and five filters: `linear` and `catmull-rom` are
//! exactly POV-Ray's `interpolate 1` and `interpolate 2` interpolants,
//! `bspline2` is the cheapest B-spline, `bspline3` the scene's filter and
//! `smooth-bspline3` (λ = 1) the most accurate; `bspline2` and `bspline3`
//! also with the octant distance maps in place of the octree (`distance`,
//! [`crate::octree::distance`]). POV-Ray renders it through
//! [`crate::peer::povray`]'s export
//! (`isosurface` over the `density_file df3`, its fastest correct settings:
//! `max_gradient` from the data, `max_trace 1`, a tight `contained_by`,
//! `frequency 0`) with trilinear and tricubic interpolation at accuracy 1e-3
//! and at the careful 1e-4.
//!
//! Every row gets one warm-up and `repeats` timed runs, the median reported,
//! with the same thread count for both renderers (snell's rayon pool,
//! POV-Ray's `Work_Threads`). The timed runs go round-robin, one of every
//! row per round, so that a shared machine's slow spells fall on all rows
//! alike:
//! - **render**: snell's tile loop and film (`Frame.stats.wall`); POV-Ray's
//!   own `Trace Time`.
//! - **prepare**: snell's load, prefilter, classification and octree (and
//!   the distance maps, for those rows), built anew for every run;
//!   POV-Ray's parse and bounding time (it reads the DF3 while parsing and
//!   precomputes nothing else).
//! - **frame** = prepare + render, the in-process time from a scene file to
//!   an image, the fair per-frame comparison.
//! - **process**: the whole `snell render` or `povray` process, start to exit
//!   (start-up, file reading, PNG writing included).
//!
//! POV-Ray's warm-up is its hit-position render (the same tracing work with
//! the backdrop painted with its own coordinates, [`povray::Variant::Hits`]), whose
//! decoded hits give its error. Errors are hit-position distances in checker
//! squares against the analytic spheres, over the pixels whose analytic ray
//! crosses the sphere (the same pixels for every row: POV-Ray reports no
//! event counts).
//!
//! Here: the options, the report's types and the round-robin run; beside
//! it, [`measure`] times a row and measures its hits, [`mod@section`] writes
//! the report into BENCHMARKS.md.

use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::Instant;

use serde::Serialize;

use crate::compare::{HitComparison, compare_hits};
use crate::film::HitImage;
use crate::peer::povray;
use crate::peer::{Interpolation, PeerError};
use crate::reference::Reference;
use crate::scene::Scene;
use crate::volume::LoadOptions;

use super::results::{Machine, TimeStats};
use super::{BenchError, Observer, machine, update};

mod measure;
mod section;

use measure::{PovMeasure, SnellMeasure};
use section::row_line;
pub use section::section;

/// The section of BENCHMARKS.md the comparison fills (`bench:peer`).
pub const PEER_SECTION: &str = "peer";

/// Peers `--peer` accepts.
pub const PEERS: [&str; 1] = ["povray"];

/// The scene file compared.
pub const PEER_SCENE: &str = "sphere.toml";

/// Image side of the comparison (the 512×512).
pub const PEER_SIZE: u32 = 512;

/// Threads per renderer unless told otherwise.
pub const PEER_THREADS: usize = 2;

/// Accuracy of POV-Ray's fast rows and of its careful rows (grid units).
pub const POV_ACCURACY: f64 = 1e-3;
pub const POV_CAREFUL_ACCURACY: f64 = 1e-4;

/// The goal: this many times faster than POV-Ray's tricubic
/// isosurface, at lower error.
pub const GOAL_SPEEDUP: f64 = 25.0;

/// snell's rows: traversal and filter (`smooth-bspline3` with λ = 1). Every
/// filter with the octree (the scenes' default traversal), and the two
/// fastest filters with the octant distance maps too, which a single frame
/// of this small sphere prepares and renders faster.
const SNELL_ROWS: [(&str, &str); 7] = [
    ("octree", "linear"),
    ("octree", "catmull-rom"),
    ("octree", "bspline2"),
    ("octree", "bspline3"),
    ("octree", "smooth-bspline3"),
    ("distance", "bspline2"),
    ("distance", "bspline3"),
];

/// POV-Ray's rows: interpolation and accuracy.
const POV_ROWS: [(Interpolation, f64); 4] = [
    (Interpolation::Tricubic, POV_ACCURACY),
    (Interpolation::Trilinear, POV_ACCURACY),
    (Interpolation::Tricubic, POV_CAREFUL_ACCURACY),
    (Interpolation::Trilinear, POV_CAREFUL_ACCURACY),
];

/// How to run the comparison.
#[derive(Clone, Debug)]
pub struct PeerOptions {
    /// Where the scene files are (`scenes/` of the repository).
    pub scenes_dir: PathBuf,
    /// Where results go: `peer.json`, `peer.md` and the POV-Ray exports
    /// under `peer/` (created if missing).
    pub out_dir: PathBuf,
    /// Timed runs per row after one warm-up.
    pub repeats: usize,
    /// Threads for each renderer.
    pub threads: usize,
    /// Image side (512; tests use less).
    pub size: u32,
    /// Markdown file whose `bench:peer` section is replaced (or appended).
    pub update: Option<PathBuf>,
    /// The command line, recorded with the results.
    pub command: String,
    /// The snell executable, for whole-process times (`None`: not measured).
    pub snell_exe: Option<PathBuf>,
}

/// Everything one comparison measured (`peer.json`).
#[derive(Clone, Debug, Serialize)]
pub struct PeerReport {
    pub peer: String,
    /// `povray --version`'s first line.
    pub peer_version: Option<String>,
    pub machine: Machine,
    pub run: PeerRunInfo,
    pub rows: Vec<PeerRow>,
    /// Each snell row against POV-Ray's tricubic isosurface at accuracy 1e-3.
    pub ratios: Vec<SpeedRatio>,
    /// POV-Ray's hits against snell's identical interpolant (the mapping
    /// check: what is left is POV-Ray's root finder and normal).
    pub same_interpolant: Vec<SameInterpolant>,
    pub warnings: Vec<String>,
}

/// How the comparison was made.
#[derive(Clone, Debug, Serialize)]
pub struct PeerRunInfo {
    pub command: String,
    pub date: String,
    pub scene: String,
    pub width: u32,
    pub height: u32,
    /// Threads of each renderer.
    pub threads: usize,
    pub repeats: usize,
    pub total_s: f64,
    pub other_cpu_share: Option<f64>,
}

/// One renderer configuration, measured.
#[derive(Clone, Debug, Serialize)]
pub struct PeerRow {
    /// `snell` or `povray`.
    pub renderer: String,
    pub label: String,
    /// snell: `--set` overrides of the scene; POV-Ray: its isosurface settings.
    pub settings: Vec<String>,
    /// Timed runs.
    pub runs: usize,
    /// snell: tile loop and film; POV-Ray: its trace time.
    pub render_ms: TimeStats,
    /// snell: load, prefilter, classification, octree; POV-Ray: parse and
    /// bounding (median).
    pub prepare_ms: f64,
    /// prepare + render per run.
    pub frame_ms: TimeStats,
    /// The whole process, start to exit (`None`: not measured).
    pub process_ms: Option<TimeStats>,
    /// CPU time of the render summed over threads (POV-Ray reports it).
    pub render_cpu_ms: Option<f64>,
    /// Hit error against the analytic spheres, checker squares.
    pub error: PeerHitError,
    /// POV-Ray: `max_gradient` written (grid units) and the data's bound.
    pub max_gradient: Option<f64>,
    pub gradient_estimate: Option<f64>,
    /// POV-Ray: the `contained_by` box (grid coordinates).
    pub contained_by: Option<[[usize; 3]; 2]>,
    /// POV-Ray warned that `max_gradient` was too low (it may leave holes).
    pub max_gradient_found: Option<f64>,
    /// How to reproduce one run.
    pub command: String,
}

/// Hit error of a row.
#[derive(Clone, Debug, Serialize)]
pub struct PeerHitError {
    /// Pixels whose analytic ray crosses the sphere and that reach the
    /// backdrop in both images.
    pub refracted_pixels: usize,
    pub p50: f64,
    pub p90: f64,
    pub p99: f64,
    /// Pixels that reach the backdrop in only one of the two images.
    pub validity_mismatch: usize,
    pub pixels: usize,
}

impl PeerHitError {
    fn of(c: &HitComparison) -> PeerHitError {
        PeerHitError {
            refracted_pixels: c.refracted.pixels,
            p50: c.squares(c.refracted.p50),
            p90: c.squares(c.refracted.p90),
            p99: c.squares(c.refracted.p99),
            validity_mismatch: c.validity_mismatch,
            pixels: c.pixels,
        }
    }
}

/// A snell row against POV-Ray's tricubic row at accuracy 1e-3.
#[derive(Clone, Debug, Serialize)]
pub struct SpeedRatio {
    pub snell: String,
    pub povray: String,
    /// POV-Ray's median frame time over snell's.
    pub frame: f64,
    /// POV-Ray's trace time over snell's render time.
    pub render: f64,
    /// Whole processes (when both were measured).
    pub process: Option<f64>,
    pub snell_p50: f64,
    pub povray_p50: f64,
    pub snell_p90: f64,
    pub povray_p90: f64,
    /// Lower error at p50 and p90.
    pub lower_error: bool,
}

/// POV-Ray's hits against snell's identical interpolant.
#[derive(Clone, Debug, Serialize)]
pub struct SameInterpolant {
    pub povray: String,
    pub snell: String,
    pub error: PeerHitError,
}

/// What a finished comparison produced.
pub struct PeerOutcome {
    pub report: PeerReport,
    pub written: Vec<PathBuf>,
}

/// Runs the comparison with `peer` (only `povray`), writes `peer.json` and
/// `peer.md` into `opts.out_dir` and updates `opts.update`. Fails with
/// [`BenchError::PeerMissing`] before doing anything when the peer is not
/// installed.
pub fn peer_bench(
    peer: &str,
    opts: &PeerOptions,
    observer: &mut dyn Observer,
) -> Result<PeerOutcome, BenchError> {
    if !PEERS.contains(&peer) {
        return Err(BenchError::UnknownPeer(peer.to_string()));
    }
    if opts.repeats == 0 {
        return Err(BenchError::NoRepeats);
    }
    if opts.threads == 0 {
        return Err(BenchError::NoThreads);
    }
    if !povray::installed() {
        return Err(BenchError::PeerMissing(PeerError::NotInstalled.to_string()));
    }
    super::prepare_out_dir(&opts.out_dir)?;
    if let Some(p) = &opts.update {
        super::read_update_target(p, PEER_SECTION)?;
    }
    let scene_path = opts.scenes_dir.join(PEER_SCENE);
    if !scene_path.is_file() {
        return Err(BenchError::MissingScene { path: scene_path });
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.threads)
        .build()
        .map_err(|e| BenchError::Threads {
            threads: opts.threads,
            msg: e.to_string(),
        })?;

    let date = machine::utc_now();
    let start = Instant::now();
    let cpu_before = machine::cpu_snapshot();
    let size = [
        format!("image.width={}", opts.size),
        format!("image.height={}", opts.size),
    ];
    let base = Scene::load(&scene_path, &size)?;
    let reference = Reference::from_scene(&base)
        .map_err(|e| BenchError::Measure {
            what: "analytic reference".into(),
            msg: e.to_string(),
        })?
        .render(&base);
    let checker = base.checker_size();
    // Progress counts the timed runs.
    observer.begin((SNELL_ROWS.len() + POV_ROWS.len()) * opts.repeats);

    // Every row is set up (and warmed up) first; then the timed runs go
    // round-robin, one run of each row per round, so that every row's
    // median draws on the same stretch of time. Row by row, a shared
    // machine's slow spells fell on some rows and not others: the ratio of
    // one bspline3 row to POV-Ray's swung from 18.5x to 24.1x between two
    // runs minutes apart.
    let mut snells = Vec::new();
    for (traversal, f) in SNELL_ROWS {
        let mut overrides = size.to_vec();
        overrides.push(format!("render.traversal={traversal}"));
        overrides.push(format!("surface.filter={f}"));
        if f == "smooth-bspline3" {
            overrides.push("surface.lambda=1".into());
        }
        let label = format!(
            "{traversal}+bezier {}",
            if f == "smooth-bspline3" {
                "smooth-bspline3 λ=1"
            } else {
                f
            }
        );
        observer.start(&format!("snell {label}: warm-up"));
        let m = pool.install(|| {
            SnellMeasure::new(opts, &scene_path, label, overrides, &reference, checker)
        })?;
        snells.push(((traversal, f), m));
    }
    let vol = base.load_volume(&LoadOptions::default())?;
    let mut povs = Vec::new();
    for (interp, accuracy) in POV_ROWS {
        let label = format!("{} accuracy {accuracy:e}", interp_name(interp));
        observer.start(&format!("POV-Ray {label}: export and hit render"));
        let dir = opts
            .out_dir
            .join("peer")
            .join(format!("povray-{}-{accuracy:e}", interp_name(interp)));
        povs.push(PovMeasure::new(
            opts, &base, &vol, &dir, label, interp, accuracy, &reference, checker,
        )?);
    }
    for round in 1..=opts.repeats {
        for (_, m) in &mut snells {
            observer.start(&format!(
                "round {round}/{}: snell {}",
                opts.repeats, m.label
            ));
            pool.install(|| m.time_once(opts))?;
            observer.tick();
        }
        for m in &mut povs {
            observer.start(&format!(
                "round {round}/{}: POV-Ray {}",
                opts.repeats, m.label
            ));
            m.time_once(opts)?;
            observer.tick();
        }
    }
    let mut rows = Vec::new();
    let mut snell_hits: Vec<((&str, &str), HitImage)> = Vec::new();
    let mut warnings = Vec::new();
    for (key, m) in snells {
        let (row, hits) = m.finish(opts)?;
        observer.note(&row_line(&row));
        rows.push(row);
        snell_hits.push((key, hits));
    }
    let mut same_interpolant = Vec::new();
    for (m, (interp, _)) in povs.into_iter().zip(POV_ROWS) {
        let label = m.label.clone();
        let (row, hits, warn) = m.finish(opts)?;
        observer.note(&row_line(&row));
        warnings.extend(warn.into_iter().map(|w| format!("POV-Ray {label}: {w}")));
        let same = interp.filter().to_string();
        if let Some((_, sh)) = snell_hits
            .iter()
            .find(|(row, _)| *row == ("octree", same.as_str()))
        {
            let c = compare_hits(&hits, sh, checker).map_err(|e| BenchError::Measure {
                what: label.clone(),
                msg: e.to_string(),
            })?;
            same_interpolant.push(SameInterpolant {
                povray: row.label.clone(),
                snell: format!("octree+bezier {same}"),
                error: PeerHitError::of(&c),
            });
        }
        rows.push(row);
    }
    let total_s = start.elapsed().as_secs_f64();
    let other_cpu_share = match (cpu_before, machine::cpu_snapshot()) {
        (Some(a), Some(b)) => machine::other_cpu_share(&a, &b),
        _ => None,
    };
    if let Some(share) = other_cpu_share
        && share > super::OTHER_CPU_WARNING
    {
        warnings.push(format!(
            "other processes used {:.0}% of the machine's CPU time during the run: the times \
are inflated (both renderers alike only if the load was steady); rerun on a quiet machine",
            100.0 * share
        ));
    }
    let machine = machine::machine();
    if machine.build_profile == "debug" {
        warnings.insert(
            0,
            "debug build: snell's times mean nothing, use --release".into(),
        );
    }
    let ratios = speed_ratios(&rows);
    let report = PeerReport {
        peer: peer.to_string(),
        peer_version: povray_version(),
        machine,
        run: PeerRunInfo {
            command: opts.command.clone(),
            date,
            scene: PEER_SCENE.into(),
            width: base.width,
            height: base.height,
            threads: opts.threads,
            repeats: opts.repeats,
            total_s,
            other_cpu_share,
        },
        rows,
        ratios,
        same_interpolant,
        warnings,
    };
    let mut written = Vec::new();
    let p = opts.out_dir.join("peer.json");
    let json = serde_json::to_string_pretty(&report).map_err(|e| BenchError::Io {
        path: p.clone(),
        source: e.into(),
    })?;
    super::write_text(&p, &(json + "\n"))?;
    written.push(p);
    let p = opts.out_dir.join("peer.md");
    super::write_text(
        &p,
        &format!("# snell bench --peer {peer}\n\n{}", section(&report)),
    )?;
    written.push(p);
    if let Some(p) = &opts.update {
        let doc = super::read_update_target(p, PEER_SECTION)?;
        let new =
            update::replace_section(&doc, PEER_SECTION, &section(&report)).map_err(|source| {
                BenchError::Section {
                    path: p.clone(),
                    source,
                }
            })?;
        super::write_text(p, &new)?;
        written.push(p.clone());
    }
    Ok(PeerOutcome { report, written })
}

fn interp_name(i: Interpolation) -> &'static str {
    match i {
        Interpolation::Trilinear => "trilinear",
        Interpolation::Tricubic => "tricubic",
    }
}

fn speed_ratios(rows: &[PeerRow]) -> Vec<SpeedRatio> {
    let Some(pov) = rows.iter().find(|r| {
        r.renderer == "povray" && r.label == format!("tricubic accuracy {POV_ACCURACY:e}")
    }) else {
        return Vec::new();
    };
    rows.iter()
        .filter(|r| r.renderer == "snell")
        .map(|s| SpeedRatio {
            snell: s.label.clone(),
            povray: pov.label.clone(),
            frame: pov.frame_ms.median / s.frame_ms.median,
            render: pov.render_ms.median / s.render_ms.median,
            process: match (&pov.process_ms, &s.process_ms) {
                (Some(p), Some(q)) => Some(p.median / q.median),
                _ => None,
            },
            snell_p50: s.error.p50,
            povray_p50: pov.error.p50,
            snell_p90: s.error.p90,
            povray_p90: pov.error.p90,
            lower_error: s.error.p50 < pov.error.p50 && s.error.p90 < pov.error.p90,
        })
        .collect()
}

/// `povray --version`'s line naming the version.
fn povray_version() -> Option<String> {
    let bin = povray::povray_binary().ok()?;
    let out = Command::new(bin)
        .arg("--version")
        .stdin(Stdio::null())
        .output()
        .ok()?;
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    text.lines()
        .map(str::trim)
        .find(|l| l.starts_with("POV-Ray"))
        .map(str::to_string)
}
