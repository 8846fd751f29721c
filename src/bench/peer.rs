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
//! the backdrop painted with its own coordinates, [`Variant::Hits`]), whose
//! decoded hits give its error. Errors are hit-position distances in checker
//! squares against the analytic spheres, over the pixels whose analytic ray
//! crosses the sphere (the same pixels for every row: POV-Ray reports no
//! event counts).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use serde::Serialize;

use crate::compare::{HitComparison, compare_hits};
use crate::film::HitImage;
use crate::peer::povray::{self, PovOptions, Variant};
use crate::peer::{Interpolation, PeerError};
use crate::prepare::Prepared;
use crate::reference::Reference;
use crate::render;
use crate::scene::Scene;
use crate::volume::LoadOptions;

use super::report::{fmt_duration, fmt_ms, fmt_sig};
use super::results::{Machine, TimeStats};
use super::{BenchError, Observer, machine, update};

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

fn measure_err(what: &str) -> impl FnOnce(String) -> BenchError + '_ {
    move |msg| BenchError::Measure {
        what: what.to_string(),
        msg,
    }
}

/// `hits` against the analytic reference over the reference's refracted
/// pixels (event counts of `hits` are ignored, so every row is measured on
/// the same pixels as POV-Ray, which reports none).
fn error_vs_reference(
    what: &str,
    hits: &HitImage,
    reference: &HitImage,
    checker: Option<f64>,
) -> Result<PeerHitError, BenchError> {
    let mut h = hits.clone();
    h.events.iter_mut().for_each(|e| *e = f32::NAN);
    let c = compare_hits(&h, reference, checker).map_err(|e| measure_err(what)(e.to_string()))?;
    Ok(PeerHitError::of(&c))
}

fn stats_of(what: &str, v: &[f64]) -> Result<TimeStats, BenchError> {
    TimeStats::of(v)
        .map(|(s, _)| s)
        .ok_or_else(|| measure_err(what)("no timed run".into()))
}

fn median(v: &[f64]) -> f64 {
    TimeStats::of(v).map_or(f64::NAN, |(s, _)| s.median)
}

/// The timings of a row's runs so far.
#[derive(Default)]
struct Timings {
    prepare: Vec<f64>,
    rendered: Vec<f64>,
    frames: Vec<f64>,
    process: Vec<f64>,
    cpu: Vec<f64>,
}

impl Timings {
    /// One in-process run: its preparation and render times (ms).
    fn push(&mut self, prepare: f64, render: f64) {
        self.prepare.push(prepare);
        self.rendered.push(render);
        self.frames.push(prepare + render);
    }
}

/// A snell row being measured: cold prepare + render per run in this
/// process, then the whole `snell render` process.
struct SnellMeasure {
    label: String,
    overrides: Vec<String>,
    scene: Scene,
    /// `snell render`'s arguments for the process runs.
    args: Vec<String>,
    times: Timings,
    /// The warm-up's hits (every run's, bit for bit) and their error.
    hits: HitImage,
    error: PeerHitError,
}

impl SnellMeasure {
    /// Loads the row's scene and renders it once, untimed (the warm-up),
    /// measuring its hits against `reference`.
    fn new(
        opts: &PeerOptions,
        scene_path: &Path,
        label: String,
        overrides: Vec<String>,
        reference: &HitImage,
        checker: Option<f64>,
    ) -> Result<SnellMeasure, BenchError> {
        let scene = Scene::load(scene_path, &overrides)?;
        let png = opts.out_dir.join("peer").join(format!(
            "snell-{}.png",
            scene
                .surface
                .filter
                .to_string()
                .replace([' ', '=', '(', ')'], "")
        ));
        if let Some(d) = png.parent() {
            std::fs::create_dir_all(d).map_err(super::io_err(d))?;
        }
        let mut args: Vec<String> = vec![
            "render".into(),
            scene_path.display().to_string(),
            "-o".into(),
            png.display().to_string(),
            "--threads".into(),
            opts.threads.to_string(),
            "--quiet".into(),
        ];
        for o in &overrides {
            args.push("--set".into());
            args.push(o.clone());
        }
        let (_, _, warm_up) = SnellMeasure::run_scene(&scene)?;
        let hits = warm_up.film.hits();
        let error = error_vs_reference(&label, &hits, reference, checker)?;
        Ok(SnellMeasure {
            label,
            overrides,
            scene,
            args,
            times: Timings::default(),
            hits,
            error,
        })
    }

    /// Prepares and renders the scene: the preparation's and the render's
    /// times (ms) and the frame.
    fn run_scene(scene: &Scene) -> Result<(f64, f64, render::Frame), BenchError> {
        let t = Instant::now();
        let prep = Prepared::for_scene(scene, &LoadOptions::default())?;
        let prepare_ms = t.elapsed().as_secs_f64() * 1e3;
        let frame = render::render(scene, &prep, None);
        Ok((prepare_ms, frame.stats.wall.as_secs_f64() * 1e3, frame))
    }

    /// One timed run in this process, and one `snell render` process when
    /// the executable is known.
    fn time_once(&mut self, opts: &PeerOptions) -> Result<(), BenchError> {
        let (p, r, _) = SnellMeasure::run_scene(&self.scene)?;
        self.times.push(p, r);
        if let Some(exe) = &opts.snell_exe {
            let start = Instant::now();
            let out = Command::new(exe)
                .args(&self.args)
                .stdin(Stdio::null())
                .output()
                .map_err(super::io_err(exe))?;
            self.times.process.push(start.elapsed().as_secs_f64() * 1e3);
            if !out.status.success() {
                return Err(measure_err(&self.label)(format!(
                    "snell render failed: {}",
                    String::from_utf8_lossy(&out.stderr).trim()
                )));
            }
        }
        Ok(())
    }

    /// The row, and its hits.
    fn finish(self, opts: &PeerOptions) -> Result<(PeerRow, HitImage), BenchError> {
        let label = &self.label;
        let t = &self.times;
        let row = PeerRow {
            renderer: "snell".into(),
            label: label.clone(),
            settings: self.overrides,
            runs: opts.repeats,
            render_ms: stats_of(label, &t.rendered)?,
            prepare_ms: median(&t.prepare),
            frame_ms: stats_of(label, &t.frames)?,
            process_ms: if t.process.is_empty() {
                None
            } else {
                Some(stats_of(label, &t.process)?)
            },
            render_cpu_ms: None,
            error: self.error,
            max_gradient: None,
            gradient_estimate: None,
            contained_by: None,
            max_gradient_found: None,
            command: format!("snell {}", self.args.join(" ")),
        };
        Ok((row, self.hits))
    }
}

/// A POV-Ray row being measured: its export and hit render (the warm-up,
/// and the error), then timed colour renders.
struct PovMeasure {
    label: String,
    interpolation: Interpolation,
    accuracy: f64,
    ex: povray::PovExport,
    hits: HitImage,
    error: PeerHitError,
    warnings: Vec<String>,
    max_gradient_found: Option<f64>,
    times: Timings,
}

impl PovMeasure {
    #[allow(clippy::too_many_arguments)]
    fn new(
        opts: &PeerOptions,
        scene: &Scene,
        vol: &crate::volume::Volume,
        dir: &Path,
        label: String,
        interpolation: Interpolation,
        accuracy: f64,
        reference: &HitImage,
        checker: Option<f64>,
    ) -> Result<PovMeasure, BenchError> {
        let pov_opts = PovOptions {
            interpolation,
            accuracy,
            max_gradient: None,
            gradient_safety: None,
        };
        let ex = povray::export(dir, scene, vol, &pov_opts)?;
        let hits_run = povray::render(&ex, Variant::Hits, opts.threads)?;
        let hits = povray::decode_hits(&hits_run.png, &ex.encoding)?;
        if (hits.width, hits.height) != (scene.width, scene.height) {
            return Err(measure_err(&label)(format!(
                "POV-Ray wrote {}x{}, the scene is {}x{}",
                hits.width, hits.height, scene.width, scene.height
            )));
        }
        let error = error_vs_reference(&label, &hits, reference, checker)?;
        Ok(PovMeasure {
            label,
            interpolation,
            accuracy,
            ex,
            hits,
            error,
            warnings: hits_run.stats.warnings.clone(),
            max_gradient_found: hits_run.stats.max_gradient_found,
            times: Timings::default(),
        })
    }

    /// One timed colour render.
    fn time_once(&mut self, opts: &PeerOptions) -> Result<(), BenchError> {
        let r = povray::render(&self.ex, Variant::Color, opts.threads)?;
        let s = &r.stats;
        let trace = s.trace_seconds.ok_or_else(|| {
            measure_err(&self.label)("POV-Ray reported no trace time (statistics missing)".into())
        })?;
        let p = s.parse_seconds.unwrap_or(0.0) + s.bounding_seconds.unwrap_or(0.0);
        self.times.push(p * 1e3, trace * 1e3);
        self.times.process.push(r.wall_seconds * 1e3);
        if let Some(c) = s.trace_cpu_seconds {
            self.times.cpu.push(c * 1e3);
        }
        for w in &s.warnings {
            if !self.warnings.contains(w) {
                self.warnings.push(w.clone());
            }
        }
        if let Some(g) = s.max_gradient_found {
            self.max_gradient_found = Some(self.max_gradient_found.map_or(g, |o: f64| o.max(g)));
        }
        Ok(())
    }

    /// The row, its hits and its warnings.
    fn finish(self, opts: &PeerOptions) -> Result<(PeerRow, HitImage, Vec<String>), BenchError> {
        let label = &self.label;
        let (ex, t) = (&self.ex, &self.times);
        let row = PeerRow {
            renderer: "povray".into(),
            label: label.clone(),
            settings: vec![
                format!("interpolate {}", self.interpolation.keyword()),
                format!("accuracy {:e}", self.accuracy),
                format!("max_gradient {:.4}", ex.max_gradient),
                "max_trace 1".into(),
                format!("max_trace_level {}", ex.max_trace_level),
            ],
            runs: opts.repeats,
            render_ms: stats_of(label, &t.rendered)?,
            prepare_ms: median(&t.prepare),
            frame_ms: stats_of(label, &t.frames)?,
            process_ms: Some(stats_of(label, &t.process)?),
            render_cpu_ms: (!t.cpu.is_empty()).then(|| median(&t.cpu)),
            error: self.error,
            max_gradient: Some(ex.max_gradient),
            gradient_estimate: Some(ex.gradient_estimate),
            contained_by: Some(ex.contained_by),
            max_gradient_found: self.max_gradient_found,
            command: ex.command_line(Variant::Color, opts.threads),
        };
        Ok((row, self.hits, self.warnings))
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

fn row_line(r: &PeerRow) -> String {
    format!(
        "{} {}: frame {} ms, render {} ms{}, p50 {} p90 {} squares",
        if r.renderer == "snell" {
            "snell"
        } else {
            "POV-Ray"
        },
        r.label,
        fmt_ms(r.frame_ms.median),
        fmt_ms(r.render_ms.median),
        r.process_ms.as_ref().map_or(String::new(), |p| format!(
            ", process {} ms",
            fmt_ms(p.median)
        )),
        fmt_sig(r.error.p50),
        fmt_sig(r.error.p90)
    )
}

fn ratio(v: f64) -> String {
    if !v.is_finite() {
        "–".into()
    } else if v >= 10.0 {
        format!("{v:.1}×")
    } else {
        format!("{v:.2}×")
    }
}

/// The `bench:peer` section: provenance, the table, the ratios, the mapping
/// check and the notes.
pub fn section(r: &PeerReport) -> String {
    use std::fmt::Write as _;
    let m = &r.machine;
    let mut s = String::new();
    let _ = write!(
        s,
        "Generated by `{}` on {} — {}, {} cores (nproc), {} threads for each renderer \
(snell's pool, POV-Ray's `Work_Threads`), {} build of snell {}{}, {} — {} at {}×{} — one \
warm-up and {} timed run{} per row, taken round-robin (one of every row per round), median \
reported — whole run {}{}.\n\n",
        r.run.command,
        r.run.date,
        m.cpu_model.as_deref().unwrap_or("unknown CPU"),
        m.nproc,
        r.run.threads,
        m.build_profile,
        m.snell_version,
        m.git
            .as_deref()
            .map_or(String::new(), |g| format!(" at {g}")),
        r.peer_version
            .as_deref()
            .unwrap_or("POV-Ray (version unknown)"),
        r.run.scene,
        r.run.width,
        r.run.height,
        r.run.repeats,
        if r.run.repeats == 1 { "" } else { "s" },
        fmt_duration(r.run.total_s),
        r.run.other_cpu_share.map_or(String::new(), |x| format!(
            ", other processes used {:.0}% of the CPU meanwhile",
            100.0 * x
        ))
    );
    let pov_label = format!("POV-Ray tricubic {POV_ACCURACY:e}");
    let _ = writeln!(
        s,
        "| renderer | configuration | frame ms | min–max | render ms | prepare ms | process ms | \
{pov_label} ÷ this, frame | ÷ this, process | err p50 | err p90 | err p99 | reach backdrop in one only |"
    );
    let _ = writeln!(
        s,
        "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"
    );
    let pov = r.rows.iter().find(|x| {
        x.renderer == "povray" && x.label == format!("tricubic accuracy {POV_ACCURACY:e}")
    });
    for row in &r.rows {
        let (vs_frame, vs_process) = match pov {
            Some(p) => (
                ratio(p.frame_ms.median / row.frame_ms.median),
                match (&p.process_ms, &row.process_ms) {
                    (Some(a), Some(b)) => ratio(a.median / b.median),
                    _ => "–".into(),
                },
            ),
            None => ("–".into(), "–".into()),
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {}–{} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            if row.renderer == "snell" {
                "snell"
            } else {
                "POV-Ray"
            },
            row.label,
            fmt_ms(row.frame_ms.median),
            fmt_ms(row.frame_ms.min),
            fmt_ms(row.frame_ms.max),
            fmt_ms(row.render_ms.median),
            fmt_ms(row.prepare_ms),
            row.process_ms
                .as_ref()
                .map_or("–".into(), |p| fmt_ms(p.median)),
            vs_frame,
            vs_process,
            fmt_sig(row.error.p50),
            fmt_sig(row.error.p90),
            fmt_sig(row.error.p99),
            row.error.validity_mismatch
        );
    }
    let _ = write!(
        s,
        "\nframe = prepare + render, in-process: snell's prepare is load, prefilter, \
classification and octree (and the distance maps for the distance rows; built anew every run), its render the tile loop and film; POV-Ray's \
prepare is its parse and bounding time (it reads the DF3 while parsing and precomputes nothing \
else), its render its own `Trace Time`. process = the whole `snell render` or `povray` process, \
start to exit (start-up, PNG writing included). Errors: hit-position distance in checker squares \
against the analytic spheres, over the pixels whose analytic ray crosses the sphere ({} of them \
for the first row; the same pixels for every row, as POV-Ray reports no event counts, less those \
that reach the backdrop in only one image, which the last column counts).\n\n",
        r.rows.first().map_or(0, |x| x.error.refracted_pixels)
    );
    if !r.ratios.is_empty() {
        let _ = write!(
            s,
            "**snell against POV-Ray's tricubic isosurface (accuracy {POV_ACCURACY:e})** — speed \
ratio POV-Ray time ÷ snell time, and the errors side by side:\n\n\
| snell configuration | × faster, frame | × faster, render vs trace | × faster, whole process | \
err p50 snell / POV-Ray | err p90 snell / POV-Ray | lower error |\n\
| --- | ---: | ---: | ---: | ---: | ---: | --- |\n"
        );
        for x in &r.ratios {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} / {} | {} / {} | {} |",
                x.snell,
                ratio(x.frame),
                ratio(x.render),
                x.process.map_or("–".into(), ratio),
                fmt_sig(x.snell_p50),
                fmt_sig(x.povray_p50),
                fmt_sig(x.snell_p90),
                fmt_sig(x.povray_p90),
                if x.lower_error { "yes" } else { "no" }
            );
        }
        let best = r
            .ratios
            .iter()
            .filter(|x| x.lower_error)
            .max_by(|a, b| a.frame.total_cmp(&b.frame));
        let _ = writeln!(
            s,
            "\nGoal (issue 8): at least {GOAL_SPEEDUP}× faster than POV-Ray's tricubic isosurface \
at lower error — {}.",
            match best {
                Some(b) if b.frame >= GOAL_SPEEDUP =>
                    format!("**met** by {} ({} per frame)", b.snell, ratio(b.frame)),
                Some(b) => format!(
                    "**not met**: the fastest snell row with lower error ({}) is {} faster per \
frame, {} by render against trace and {} by whole process",
                    b.snell,
                    ratio(b.frame),
                    ratio(b.render),
                    b.process.map_or("–".into(), ratio)
                ),
                None => "**not met**: no snell row has lower error at both p50 and p90".into(),
            }
        );
    }
    if !r.same_interpolant.is_empty() {
        let _ = write!(
            s,
            "\n**Mapping check**: POV-Ray's hits against snell's identical interpolant (DF3 \
`interpolate 1` is snell's `linear`, `interpolate 2` its `catmull-rom`, both with the mirror \
boundary through the DF3's one-sample border). What remains is POV-Ray's own approximation: its \
root finder stops within `accuracy` of the crossing and its normal is a forward difference of \
step `accuracy` (tricubic densities in single precision).\n\n\
| POV-Ray | snell | p50 | p90 | p99 | reach backdrop in one only |\n\
| --- | --- | ---: | ---: | ---: | ---: |\n"
        );
        for x in &r.same_interpolant {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} | {} |",
                x.povray,
                x.snell,
                fmt_sig(x.error.p50),
                fmt_sig(x.error.p90),
                fmt_sig(x.error.p99),
                x.error.validity_mismatch
            );
        }
    }
    let pov_rows: Vec<&PeerRow> = r.rows.iter().filter(|x| x.renderer == "povray").collect();
    if let Some(p) = pov_rows.first() {
        let gradients: Vec<String> = pov_rows
            .iter()
            .filter(|x| x.label.ends_with(&format!("{POV_ACCURACY:e}")))
            .map(|x| {
                format!(
                    "{} {} (data bound {})",
                    x.label.split(' ').next().unwrap_or(""),
                    x.max_gradient.map_or("?".into(), |g| format!("{g:.4}")),
                    x.gradient_estimate
                        .map_or("?".into(), |g| format!("{g:.4}"))
                )
            })
            .collect();
        let _ = write!(
            s,
            "\nPOV-Ray settings (`snell export-pov`, as issue 8 asks): `isosurface` over a 16-bit \
`density_file df3` with `frequency 0`, `max_gradient` from the data ({}; grid units), \
`max_trace 1` (the default), `contained_by` {}, glass `interior {{ ior 1.5 }}`, \
`-A +Q9`, no lights. Command of one run: `{}`.",
            gradients.join(", "),
            p.contained_by.map_or("the volume's box".to_string(), |[lo, hi]| format!(
                "the box {lo:?}–{hi:?} (grid coordinates) of the cells whose conservative bound \
reaches the iso-value"
            )),
            p.command
        );
        let holes: Vec<String> = pov_rows
            .iter()
            .filter_map(|x| {
                x.max_gradient_found
                    .map(|g| format!("{} (found {g:.4})", x.label))
            })
            .collect();
        if holes.is_empty() {
            s.push_str(" POV-Ray did not warn about `max_gradient` in any run.\n");
        } else {
            let _ = writeln!(
                s,
                " POV-Ray warned that `max_gradient` was too low in: {}.",
                holes.join(", ")
            );
        }
    }
    s.push('\n');
    for w in &r.warnings {
        let _ = writeln!(s, "> warning: {w}\n");
    }
    s
}
