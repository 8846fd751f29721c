//! `snell render`: a scene file to images, hit positions and a profile.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicUsize;
use std::time::Instant;

use anyhow::Context;
use clap::Args as ClapArgs;

use snell::film::FrameId;
use snell::render::{self, Prepared};
use snell::scene::{Orbit, Scene};
use snell::volume::LoadOptions;

use super::common::{
    MemoryLimit, check_distinct, check_format, check_output, load_scene, load_scene_part,
};
use super::progress::{self, Count, Step};

#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Scene file (TOML).
    pub scene: PathBuf,
    /// Output image (8-bit PNG).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Also write the hit-position EXR (u, v, events per pixel-centre ray).
    #[arg(long, value_name = "HITS.exr")]
    pub hits: Option<PathBuf>,
    /// Also write the colour image as float EXR.
    #[arg(long, value_name = "COLOR.exr")]
    pub exr: Option<PathBuf>,
    /// Write work counters and per-stage times as JSON.
    #[arg(long, value_name = "STATS.json")]
    pub stats: Option<PathBuf>,
    /// Write a timeline of the preparation and of every tile's stages per
    /// thread (Chrome trace format: open it in ui.perfetto.dev or chrome://tracing).
    #[arg(long, value_name = "TRACE.json")]
    pub trace: Option<PathBuf>,
    /// Worker threads, 1 to 1024 (default: all cores).
    #[arg(long, allow_negative_numbers = true, value_parser = super::common::thread_count)]
    pub threads: Option<usize>,
    /// Override a scene value, e.g. --set surface.ior=1.33 (repeatable).
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
    pub set: Vec<String>,
    /// Keep prefiltered coefficients, cell tags, sub-cell masks and
    /// curvature bounds in DIR, keyed by the volume's content hash, and
    /// reuse them in later runs (a
    /// re-render with a new camera, ior or backdrop skips the classification
    /// and reads the coefficients instead of prefiltering).
    /// A missing DIR is created (with a warning), a missing parent refused.
    #[arg(long, value_name = "DIR")]
    pub cache: Option<PathBuf>,
    /// Render only the pixels [X0, X1) × [Y0, Y1) of the image: one part of a
    /// frame split across jobs. The PNG holds the region; the EXRs place it in
    /// the whole image (OpenEXR data window), for `snell merge`. The pixels
    /// are bitwise those of a whole-frame render.
    #[arg(long, value_name = "X0,Y0,X1,Y1", allow_hyphen_values = true, value_parser = region_value)]
    pub region: Option<String>,
    #[command(flatten)]
    pub limit: MemoryLimit,
    /// Render a turntable of N frames: the camera and the backdrop go round
    /// the volume's centre about the image's vertical axis, 360°/N a frame,
    /// as if the volume turned on a turntable; the preparation is made once.
    /// The output names carry the frame number as printf does, e.g.
    /// -o frames/f-%03d.png (and --hits, --exr likewise); each frame's time is
    /// printed, then the median (steady state: structures cached).
    #[arg(long, value_name = "N", allow_negative_numbers = true, value_parser = frame_count)]
    pub orbit: Option<u32>,
    /// Print no stats table and no progress (the bar on a terminal, the
    /// lines every SNELL_PROGRESS_SECONDS, default 30, in a log).
    #[arg(short, long)]
    pub quiet: bool,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    a.limit.apply()?;
    // A part's frame may pass the memory limit as a whole: its own is
    // checked below, once its window is known.
    let scene = if a.region.is_some() {
        load_scene_part(&a.scene, &a.set)?
    } else {
        load_scene(&a.scene, &a.set)?
    };
    let outputs = Outputs::of(&a)?;
    // The image, hits, colour EXR, stats and timeline appear together when
    // the last is written, or not at all.
    let held = snell::atomic::hold();
    check_distinct(
        &outputs
            .files
            .iter()
            .map(PathBuf::as_path)
            .collect::<Vec<_>>(),
        &scene.input_files(),
    )?;
    let window = a
        .region
        .as_deref()
        .map(|r| parse_region(r, scene.width, scene.height))
        .transpose()?;
    let threads = a.threads.unwrap_or(0);
    if a.threads == Some(0) {
        anyhow::bail!("--threads must be at least 1");
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .context("cannot start worker threads")?;
    let tiles = render::tile_count(&scene, window);
    // The tile scratch of every worker thread that can have a tile, now that
    // their count is known.
    let limit = snell::volume::limits::default_memory_limit();
    let workers = pool.current_num_threads().min(tiles.max(1));
    // A part holds its window (and apron) only.
    let (w, h) = render::traced_size(&scene, window);
    scene.check_memory(limit, workers, window.map(|_| (w, h)))?;
    // The volume and its structures get what the image leaves of the limit:
    // each could pass alone where both together exceed it.
    let (frame_bytes, scratch_bytes) = scene.memory_need_of((w, h), workers);
    let image_bytes = frame_bytes.saturating_add(scratch_bytes);
    let load = LoadOptions {
        memory_limit: limit.saturating_sub(image_bytes),
        ..LoadOptions::default()
    };
    if a.orbit.is_some() {
        // Each frame reuses the memory of the last, as an interactive
        // session's would.
        snell::heap::retain_freed_memory();
    }

    let mut trace = a.trace.as_ref().map(|_| render::Trace::new());
    let prep_start = Instant::now();
    // A 1024³ scan spends half a minute here before its first tile.
    let preparing = Step::named("preparing the volume (load, prefilter, cell tags)");
    // A volume refused for the memory the image leaves says so.
    let over_limit = |e: snell::scene::SceneError| -> anyhow::Error {
        let refused = std::iter::successors(Some(&e as &dyn std::error::Error), |c| c.source())
            .any(|c| c.is::<snell::volume::limits::OverLimit>());
        if image_bytes > 0 && refused {
            let hb = snell::volume::limits::human_bytes;
            anyhow::anyhow!(
                "{e}; that is the memory limit of {} less the {} the {} takes",
                hb(limit),
                hb(image_bytes),
                match window {
                    None => format!("{}x{} image", scene.width, scene.height),
                    Some(w) => format!("{}x{} region", w.width(), w.height()),
                }
            )
        } else {
            e.into()
        }
    };
    let (prep, cache_warnings) = progress::watch(&preparing, a.quiet, || -> anyhow::Result<_> {
        Ok(match &a.cache {
            Some(dir) => {
                let mut cache = snell::prepare::Cache::with_dir(dir)
                    .with_context(|| format!("cache directory {}", dir.display()))?;
                let prep = pool
                    .install(|| cache.prepare(&scene, &load))
                    .map_err(over_limit)?;
                (prep, cache.warnings)
            }
            None => (
                pool.install(|| Prepared::for_scene(&scene, &load))
                    .map_err(over_limit)?,
                Vec::new(),
            ),
        })
    })?;
    for w in &cache_warnings {
        eprintln!("warning: {w}");
    }
    if let Some(t) = &mut trace {
        t.prepare(prep_start, prep_start.elapsed(), &prep.times);
    }
    for w in &prep.volume.warnings {
        eprintln!("warning: {w}");
    }
    if let Some(why) = super::common::no_cells(prep.volume.dims()) {
        eprintln!(
            "warning: {}: the volume is {why}, so no surface; the image shows only the backdrop",
            a.scene.display()
        );
    }
    warn_far_camera(&a.scene, &scene, &prep.volume);
    let (lo, hi) = prep.volume.value_range();
    let iso = scene.surface.iso;
    if !(iso >= lo && iso <= hi) {
        // Trilinear interpolation stays within the samples' range; the other
        // filters overshoot it next to sharp edges.
        let shows = if scene.surface.filter == snell::filter::FilterKind::Linear {
            "the image shows only the backdrop".to_string()
        } else {
            format!(
                "a surface shows only where {} overshoots the samples (next to sharp edges), if anywhere",
                scene.surface.filter.name()
            )
        };
        eprintln!(
            "warning: {}: iso-value {} is outside the data range [{}, {}]; {shows}",
            a.scene.display(),
            snell::human::exact(iso),
            snell::human::num(lo),
            snell::human::num(hi)
        );
    }
    let renderer = Renderer {
        pool: &pool,
        prep: &prep,
        window,
        tiles,
        quiet: a.quiet,
        // Only the parts of a frame need to say which frame they are.
        volume_hash: window.map(|_| prep.volume_hash()),
    };
    match a.orbit {
        None => render_one(&a, &scene, &renderer, &outputs, trace, &held),
        Some(n) => render_orbit(&a, scene, &renderer, &outputs, n, &held),
    }
}

/// What every frame of a run shares: the worker pool, the preparation, and
/// the part of the image to trace.
struct Renderer<'a> {
    pool: &'a rayon::ThreadPool,
    prep: &'a Prepared,
    window: Option<render::tile::Tile>,
    tiles: usize,
    quiet: bool,
    /// The volume's content hash, for the frame fingerprint a `--region`
    /// part's EXR files carry.
    volume_hash: Option<u64>,
}

impl Renderer<'_> {
    /// The fingerprint of `scene`'s frame, for a `--region` part's EXR
    /// files (none for a whole frame).
    fn frame_id(&self, scene: &Scene) -> Option<FrameId> {
        self.volume_hash.map(|h| scene.frame_fingerprint(h))
    }

    /// One frame of `scene`, in the pool (so --threads sets its tile
    /// workers), its progress shown ([`progress::watch`]).
    fn frame(&self, scene: &Scene, trace: Option<&mut render::Trace>) -> render::Frame {
        let done = AtomicUsize::new(0);
        let step = Step {
            what: "rendering".into(),
            count: Some(Count {
                done: &done,
                total: self.tiles,
                unit: "tiles",
            }),
        };
        progress::watch(&step, self.quiet, || {
            self.pool.install(|| match (self.window, trace) {
                (Some(w), t) => render::render_window(scene, self.prep, w, Some(&done), t),
                (None, Some(t)) => render::render_traced(scene, self.prep, Some(&done), t),
                (None, None) => render::render(scene, self.prep, Some(&done)),
            })
        })
    }
}

/// The scene's one frame, its files, stats and timeline, committed
/// together (`held`) before anything more is printed: a closed stderr ends
/// the process on its next line (SIGPIPE), and must not take them along.
fn render_one(
    a: &Args,
    scene: &Scene,
    renderer: &Renderer,
    outputs: &Outputs,
    mut trace: Option<render::Trace>,
    held: &snell::atomic::Held,
) -> anyhow::Result<()> {
    let frame = renderer.frame(scene, trace.as_mut());
    outputs.write(&frame, None, renderer.frame_id(scene))?;
    if let (Some(p), Some(t)) = (&a.trace, &trace) {
        t.write(p).with_context(|| p.display().to_string())?;
    }
    // Last, so its peak memory is the one printed: the timeline's writing
    // may raise it.
    if let Some(p) = &a.stats {
        write_stats(p, &stats_json(a, scene, &frame.stats)?)?;
    }
    held.commit()?;
    warn_undefined(&frame, None);
    if !a.quiet {
        print_table(&frame.stats);
    }
    Ok(())
}

/// `--orbit N`: the frames of a turn, each written as it is done (`held`
/// committed frame by frame), each one's time printed; then the median and
/// the median frame's table. Frame times leave out writing the files.
fn render_orbit(
    a: &Args,
    mut scene: Scene,
    renderer: &Renderer,
    outputs: &Outputs,
    n: u32,
    held: &snell::atomic::Held,
) -> anyhow::Result<()> {
    let orbit = Orbit::about_volume(&scene, renderer.prep.volume.extent(), n)?;
    let mut runs: Vec<(f64, render::RenderStats)> = Vec::with_capacity(n as usize);
    for k in 0..n {
        orbit.place(&mut scene, k);
        let frame = renderer.frame(&scene, None);
        // The frame's own wall time, so the summary's median is the time
        // the median frame's table prints.
        let ms = frame.stats.wall.as_secs_f64() * 1e3;
        outputs.write(&frame, Some(k), renderer.frame_id(&scene))?;
        held.commit()?;
        if !a.quiet {
            eprintln!(
                "frame {k} at {}°: {ms:.1} ms, {}",
                snell::human::num(orbit.degrees(k)),
                outputs.png.name(Some(k)).display()
            );
        }
        warn_undefined(&frame, Some(k));
        runs.push((ms, frame.stats));
    }
    let times: Vec<f64> = runs.iter().map(|r| r.0).collect();
    runs.sort_by(|x, y| x.0.total_cmp(&y.0));
    let (median, stats) = &runs[runs.len() / 2];
    let (min, max) = (runs[0].0, runs[runs.len() - 1].0);
    if let Some(p) = &a.stats {
        let mut j = stats_json(a, &scene, stats)?;
        j["orbit"] = serde_json::json!({
            "frames": n,
            "frame_ms": times,
            "median_ms": median,
            "min_ms": min,
            "max_ms": max,
        });
        write_stats(p, &j)?;
    }
    held.commit()?;
    if !a.quiet {
        eprintln!(
            "{n} frames: median {median:.1} ms (min {min:.1}, max {max:.1}), {:.1} frames a second, writing the files not included; the median frame:",
            1e3 / median
        );
        print_table(stats);
    }
    Ok(())
}

/// Warns of a camera so far away that `f64` rounds its rays' origins by
/// more than a millionth of a voxel ([`snell::scene::Camera::origin_rounding`]):
/// the hits move with it, as no traversal can undo.
fn warn_far_camera(path: &Path, scene: &Scene, volume: &snell::volume::Volume) {
    let extent = glam::DVec3::from_array(volume.extent());
    let voxel = volume.spacing().into_iter().fold(f64::INFINITY, f64::min);
    let rounding = scene.camera.origin_rounding(0.5 * extent);
    if rounding > 1e-6 * voxel {
        let how = match scene.camera.projection {
            snell::scene::Projection::Orthographic { .. } => {
                "an orthographic camera's distance does not change its view: move it closer"
            }
            snell::scene::Projection::Perspective { .. } => {
                "move it closer, with a wider fov_y for the same framing"
            }
        };
        eprintln!(
            "warning: {}: the camera is so far from the volume that f64 rounds its rays' origins by about {:.1e} voxels, which moves the hits; {how}",
            path.display(),
            rounding / voxel
        );
    }
}

/// Warns of rays that ended undefined (frame `k` of an orbit).
fn warn_undefined(frame: &render::Frame, k: Option<u32>) {
    let n = frame.stats.counters.undefined;
    if n > 0 {
        let which = k.map_or(String::new(), |k| format!("frame {k}: "));
        eprintln!("warning: {which}{n} rays ended in an undefined state (reported as background)");
    }
}

/// The stats table and the process's peak memory (volume, coefficients,
/// structures, film): what a large volume needs of the machine.
fn print_table(stats: &render::RenderStats) {
    eprint!("{}", stats.table());
    if let Some(m) = snell::bench::machine::peak_rss_mib() {
        eprintln!("peak memory: {} resident", super::common::human_mib(m));
    }
}

/// A frame's stats as `--stats` writes them, with the scene's settings.
fn stats_json(
    a: &Args,
    scene: &Scene,
    stats: &render::RenderStats,
) -> anyhow::Result<serde_json::Value> {
    let mut j = stats.to_json();
    j["peak_rss_mib"] = serde_json::json!(snell::bench::machine::peak_rss_mib());
    j["scene"] = serde_json::json!(a.scene.display().to_string());
    j["settings"] = serde_json::to_value(scene.render)?;
    j["filter"] = serde_json::json!(scene.surface.filter.to_string());
    Ok(j)
}

fn write_stats(p: &Path, j: &serde_json::Value) -> anyhow::Result<()> {
    snell::atomic::write_atomic(p, |w| {
        use std::io::Write;
        serde_json::to_writer_pretty(&mut *w, j)?;
        w.write_all(b"\n")
    })
    .with_context(|| p.display().to_string())
}

/// The image outputs of a render: one file each, or with `--orbit` a name
/// pattern each (`f-%03d.png`) for the frames.
struct Outputs {
    png: Output,
    hits: Option<Output>,
    exr: Option<Output>,
    /// Every file the render writes (with `--orbit`, every frame's), for
    /// the check against the inputs and each other.
    files: Vec<PathBuf>,
}

/// One image output's file, or its frames' pattern.
struct Output {
    /// The option that names it.
    flag: &'static str,
    path: PathBuf,
    pattern: Option<FramePattern>,
}

impl Output {
    fn new(
        path: &Path,
        flag: &'static str,
        formats: &[&str],
        orbit: Option<u32>,
    ) -> anyhow::Result<Self> {
        check_format(path, flag, formats)?;
        let pattern = match orbit {
            Some(_) => Some(
                FramePattern::parse(path)
                    .with_context(|| format!("{flag} {}: with --orbit", path.display()))?,
            ),
            // A frame pattern without frames is a forgotten --orbit, not a
            // file to be named with a literal `%03d`.
            None if FramePattern::parse(path).is_ok() => anyhow::bail!(
                "{flag} {}: the name holds a frame number (%d); it needs --orbit N (or a plain name for one image)",
                path.display()
            ),
            None => None,
        };
        Ok(Output {
            flag,
            path: path.to_path_buf(),
            pattern,
        })
    }

    /// The file of frame `k` (of the one image without `--orbit`).
    fn name(&self, k: Option<u32>) -> PathBuf {
        match (&self.pattern, k) {
            (Some(p), Some(k)) => p.name(k),
            _ => self.path.clone(),
        }
    }
}

impl Outputs {
    /// The outputs `a` names, checked: writable places, formats, frame
    /// patterns with `--orbit` (and no `--trace`, which times one frame).
    fn of(a: &Args) -> anyhow::Result<Outputs> {
        let named = [
            Some(&a.output),
            a.hits.as_ref(),
            a.exr.as_ref(),
            a.stats.as_ref(),
            a.trace.as_ref(),
        ];
        for p in named.into_iter().flatten() {
            check_output(p)?;
        }
        if a.orbit.is_some() && a.trace.is_some() {
            anyhow::bail!(
                "--trace records one frame's timeline; render it without --orbit (an orbit prints each frame's time, and --stats keeps them)"
            );
        }
        // One file each, whatever the frames: a frame pattern there would
        // name one literal `s%d.json`.
        for (flag, p) in [("--stats", &a.stats), ("--trace", &a.trace)] {
            if let Some(p) = p.as_ref().filter(|p| FramePattern::parse(p).is_ok()) {
                let orbit = if flag == "--stats" && a.orbit.is_some() {
                    " (an orbit's stats keep every frame's time)"
                } else {
                    ""
                };
                anyhow::bail!(
                    "{flag} {}: the name holds a frame number (%d), but {flag} writes one file{orbit}; give it a plain name",
                    p.display()
                );
            }
        }
        let mut out = Outputs {
            png: Output::new(&a.output, "-o", &["png"], a.orbit)?,
            hits: a
                .hits
                .as_deref()
                .map(|h| Output::new(h, "--hits", &["exr"], a.orbit))
                .transpose()?,
            exr: a
                .exr
                .as_deref()
                .map(|e| Output::new(e, "--exr", &["exr"], a.orbit))
                .transpose()?,
            files: Vec::new(),
        };
        let files = out.named_files(a);
        if a.orbit.is_some() {
            // The frames' own names, as the files they will be.
            for o in out.images() {
                check_output(&o.name(Some(0)))?;
            }
            frames_apart(&files)?;
        }
        out.files = files.into_iter().map(|(p, _)| p).collect();
        Ok(out)
    }

    /// Every file the render writes (with `--orbit`, every frame's), each
    /// with the option that names it: `--hits h%d.exr (frame 10)`.
    fn named_files(&self, a: &Args) -> Vec<(PathBuf, String)> {
        let frames: Vec<Option<u32>> = match a.orbit {
            Some(n) => (0..n).map(Some).collect(),
            None => vec![None],
        };
        let images = self.images().flat_map(|o| {
            frames.iter().map(move |&k| {
                let frame = k.map_or(String::new(), |k| format!(" (frame {k})"));
                (o.name(k), format!("{} {}{frame}", o.flag, o.path.display()))
            })
        });
        let others = [("--stats", &a.stats), ("--trace", &a.trace)]
            .into_iter()
            .filter_map(|(flag, p)| {
                p.as_ref()
                    .map(|p| (p.clone(), format!("{flag} {}", p.display())))
            });
        images.chain(others).collect()
    }

    fn images(&self) -> impl Iterator<Item = &Output> {
        std::iter::once(&self.png)
            .chain(self.hits.as_ref())
            .chain(self.exr.as_ref())
    }

    /// Writes frame `k`'s images (the one frame's without `--orbit`), its
    /// EXR files carrying the frame fingerprint `id` (a part's).
    fn write(
        &self,
        frame: &render::Frame,
        k: Option<u32>,
        id: Option<FrameId>,
    ) -> anyhow::Result<()> {
        frame.film.write_png(&self.png.name(k))?;
        if let Some(h) = &self.hits {
            frame.film.write_hits_exr(&h.name(k), id)?;
        }
        if let Some(e) = &self.exr {
            frame.film.write_color_exr(&e.name(k), id)?;
        }
        Ok(())
    }
}

/// Refuses outputs that give two files one name (`h%d.exr` and
/// `h%02d.exr` both name `h10.exr`), or a frame the name of `--stats`,
/// naming the options at fault.
fn frames_apart(files: &[(PathBuf, String)]) -> anyhow::Result<()> {
    let mut named: HashMap<&Path, &str> = HashMap::new();
    for (name, what) in files {
        if let Some(first) = named.insert(name, what) {
            anyhow::bail!(
                "{first} and {what} both name {}; give each output its own name",
                name.display()
            );
        }
    }
    Ok(())
}

/// A file name with one printf frame number, `%d` or `%0Nd` (as ffmpeg and
/// Blender read image sequences): `f-%03d.png` names frame 7 `f-007.png`.
#[derive(Debug, PartialEq)]
struct FramePattern {
    dir: PathBuf,
    before: String,
    width: usize,
    after: String,
}

impl FramePattern {
    /// Reads the name as printf does: one `%d` or `%0Nd` for the frame
    /// number, `%%` for a `%` of the name itself.
    fn parse(path: &Path) -> anyhow::Result<FramePattern> {
        let name = path
            .file_name()
            .and_then(|n| n.to_str())
            .context("the name needs a frame number, as in f-%03d.png")?;
        let (mut before, mut after) = (String::new(), String::new());
        let mut width = None;
        let mut rest = name;
        while let Some(at) = rest.find('%') {
            let text = if width.is_none() {
                &mut before
            } else {
                &mut after
            };
            text.push_str(&rest[..at]);
            let spec = &rest[at + 1..];
            if let Some(more) = spec.strip_prefix('%') {
                text.push('%');
                rest = more;
                continue;
            }
            let digits: String = spec.chars().take_while(|c| c.is_ascii_digit()).collect();
            let Some(more) = spec[digits.len()..].strip_prefix('d') else {
                anyhow::bail!(
                    "'%' must start a frame number, %d or %0Nd (as in f-%03d.png), or be written %% for a '%' of the name"
                );
            };
            if width.is_some() {
                anyhow::bail!(
                    "the file name holds one frame number, %d or %0Nd; it has more than one"
                );
            }
            width = Some(match digits.as_str() {
                "" => 0,
                d if d.starts_with('0') && d.len() == 2 && d != "00" => d[1..].parse()?,
                _ => anyhow::bail!(
                    "a frame number is written %d or %0Nd with N from 1 to 9, got %{digits}d"
                ),
            });
            rest = more;
        }
        let Some(width) = width else {
            anyhow::bail!(
                "the file name needs a frame number, %d or %0Nd, as in f-%03d.png (one file per frame)"
            );
        };
        after.push_str(rest);
        Ok(FramePattern {
            dir: path.parent().map(Path::to_path_buf).unwrap_or_default(),
            before,
            width,
            after,
        })
    }

    fn name(&self, k: u32) -> PathBuf {
        self.dir.join(format!(
            "{}{k:0w$}{}",
            self.before,
            self.after,
            w = self.width
        ))
    }
}

/// `--orbit`: a frame count from 1 to [`MAX_FRAMES`](snell::scene::orbit::MAX_FRAMES).
fn frame_count(s: &str) -> Result<u32, String> {
    let max = snell::scene::orbit::MAX_FRAMES;
    let n: u64 = s
        .trim()
        .parse()
        .map_err(|_| format!("'{s}' is not a frame count"))?;
    match u32::try_from(n) {
        Ok(n) if (1..=max).contains(&n) => Ok(n),
        _ => Err(format!("must be from 1 to {max}, got {n}")),
    }
}

/// `--region`'s value as given. Hyphens are allowed so that `-1,0,8,8` meets
/// [`parse_region`]'s message rather than clap's "unexpected argument"; an
/// option in its place (`--region --cache d`) means the value was forgotten.
fn region_value(s: &str) -> Result<String, String> {
    if s.starts_with("--") {
        return Err(format!(
            "expected X0,Y0,X1,Y1, found the option '{s}' (the region was left out)"
        ));
    }
    Ok(s.to_string())
}

/// `X0,Y0,X1,Y1`: a non-empty pixel rectangle inside the `width × height` image.
fn parse_region(s: &str, width: u32, height: u32) -> anyhow::Result<render::tile::Tile> {
    let v: Vec<u32> = s
        .split(',')
        .map(|p| p.trim().parse::<u32>())
        .collect::<Result<_, _>>()
        .ok()
        .filter(|v: &Vec<u32>| v.len() == 4)
        .with_context(|| {
            format!("--region '{s}': expected X0,Y0,X1,Y1 (four non-negative integers)")
        })?;
    let (x0, y0, x1, y1) = (v[0], v[1], v[2], v[3]);
    if x0 >= x1 || y0 >= y1 || x1 > width || y1 > height {
        anyhow::bail!(
            "--region {s}: need X0 < X1 <= {width} and Y0 < Y1 <= {height} (the image is {width}x{height}; X1, Y1 exclusive)"
        );
    }
    Ok(render::tile::Tile { x0, y0, x1, y1 })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Frame names as printf writes them: `%d`, `%0Nd`, and `%%` for a
    /// `%` of the name.
    #[test]
    fn frame_patterns_read_as_printf_does() {
        let name = |p: &str, k| FramePattern::parse(Path::new(p)).map(|f| f.name(k));
        assert_eq!(
            name("out/f-%03d.png", 7).unwrap(),
            Path::new("out/f-007.png")
        );
        assert_eq!(name("g-%%d-%d.png", 3).unwrap(), Path::new("g-%d-3.png"));
        assert_eq!(name("%d-100%%.exr", 12).unwrap(), Path::new("12-100%.exr"));
        for (bad, says) in [
            ("a%d%d.png", "more than one"),
            ("a%%.png", "needs a frame number"),
            ("a%5d.png", "%0Nd with N from 1 to 9"),
            ("a%s.png", "written %%"),
        ] {
            let e = name(bad, 0).unwrap_err().to_string();
            assert!(e.contains(says), "{bad}: {e}");
        }
    }
}
