//! Measuring one row: snell's in-process runs and `snell render`
//! processes, POV-Ray's runs, and each row's hit error against the analytic
//! spheres.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Instant;

use crate::compare::compare_hits;
use crate::film::HitImage;
use crate::peer::Interpolation;
use crate::peer::povray::{self, PovOptions, Variant};
use crate::prepare::Prepared;
use crate::render;
use crate::scene::Scene;
use crate::volume::LoadOptions;

use super::super::BenchError;
use super::super::results::TimeStats;
use super::{PeerHitError, PeerOptions, PeerRow};

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
pub(super) struct SnellMeasure {
    pub(super) label: String,
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
    pub(super) fn new(
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
            std::fs::create_dir_all(d).map_err(super::super::io_err(d))?;
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
    pub(super) fn time_once(&mut self, opts: &PeerOptions) -> Result<(), BenchError> {
        let (p, r, _) = SnellMeasure::run_scene(&self.scene)?;
        self.times.push(p, r);
        if let Some(exe) = &opts.snell_exe {
            let start = Instant::now();
            let out = Command::new(exe)
                .args(&self.args)
                .stdin(Stdio::null())
                .output()
                .map_err(super::super::io_err(exe))?;
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
    pub(super) fn finish(self, opts: &PeerOptions) -> Result<(PeerRow, HitImage), BenchError> {
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
pub(super) struct PovMeasure {
    pub(super) label: String,
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
    pub(super) fn new(
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
    pub(super) fn time_once(&mut self, opts: &PeerOptions) -> Result<(), BenchError> {
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
    pub(super) fn finish(
        self,
        opts: &PeerOptions,
    ) -> Result<(PeerRow, HitImage, Vec<String>), BenchError> {
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
