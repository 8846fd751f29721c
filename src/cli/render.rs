//! `snell render`: a scene file to images, hit positions and a profile.

use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args as ClapArgs;

use snell::render::{self, Prepared};
use snell::volume::LoadOptions;

use super::common::{check_distinct, check_format, check_output, given, load_scene};

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
    #[arg(long, value_parser = super::common::thread_count)]
    pub threads: Option<usize>,
    /// Override a scene value, e.g. --set surface.ior=1.33 (repeatable).
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
    pub set: Vec<String>,
    /// Keep prefiltered coefficients and cell tags in DIR, keyed by the
    /// volume's content hash, and reuse them in later runs (a re-render with
    /// a new camera, ior or backdrop skips the prefilter and classification).
    #[arg(long, value_name = "DIR")]
    pub cache: Option<PathBuf>,
    /// Render only the pixels [X0, X1) × [Y0, Y1) of the image: one part of a
    /// frame split across jobs. The PNG holds the region; the EXRs place it in
    /// the whole image (OpenEXR data window), for `snell merge`. The pixels
    /// are bitwise those of a whole-frame render.
    #[arg(long, value_name = "X0,Y0,X1,Y1")]
    pub region: Option<String>,
    /// Largest working set to allow: bytes (1e9), or K, M, G, T with an
    /// optional B or iB (binary multiples: 1G = 1GB = 1GiB = 2^30 bytes), e.g.
    /// 8G or 1.5GiB (default: the SNELL_MEMORY_LIMIT variable, else 80% of
    /// available memory).
    #[arg(long, value_name = "BYTES", allow_hyphen_values = true)]
    pub memory_limit: Option<String>,
    /// Do not print the stats table.
    #[arg(short, long)]
    pub quiet: bool,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    if let Some(s) = &a.memory_limit {
        super::common::memory_limit(Some(s))?;
        // Every limit check of the scene, its volume and its image reads the
        // variable, so the flag sets it for them all.
        // SAFETY: at start-up, before this process starts any other thread.
        unsafe { std::env::set_var("SNELL_MEMORY_LIMIT", s) };
    }
    let scene = load_scene(&a.scene, &a.set)?;
    let outputs = given(&[
        Some(&a.output),
        a.hits.as_ref(),
        a.exr.as_ref(),
        a.stats.as_ref(),
        a.trace.as_ref(),
    ]);
    for p in &outputs {
        check_output(p)?;
    }
    check_format(&a.output, "-o", &["png"])?;
    if let Some(h) = &a.hits {
        check_format(h, "--hits", &["exr"])?;
    }
    if let Some(e) = &a.exr {
        check_format(e, "--exr", &["exr"])?;
    }
    check_distinct(&outputs, &scene.input_files())?;
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
    scene.check_memory(
        snell::volume::limits::default_memory_limit(),
        pool.current_num_threads().min(tiles.max(1)),
    )?;

    let mut trace = a.trace.as_ref().map(|_| render::Trace::new());
    let prep_start = Instant::now();
    let prep = match &a.cache {
        Some(dir) => {
            let mut cache = snell::prepare::Cache::with_dir(dir)
                .with_context(|| format!("cache directory {}", dir.display()))?;
            let prep = pool.install(|| cache.prepare(&scene, &LoadOptions::default()))?;
            for w in &cache.warnings {
                eprintln!("warning: {w}");
            }
            prep
        }
        None => pool.install(|| Prepared::for_scene(&scene, &LoadOptions::default()))?,
    };
    if let Some(t) = &mut trace {
        t.prepare(prep_start, prep_start.elapsed(), &prep.times);
    }
    for w in &prep.volume.warnings {
        eprintln!("warning: {w}");
    }
    let (lo, hi) = prep.volume.value_range();
    let iso = scene.surface.iso;
    if !(iso >= lo as f64 && iso <= hi as f64) {
        eprintln!(
            "warning: {}: iso-value {iso} is outside the data range [{lo}, {hi}]; the image shows only the backdrop",
            a.scene.display()
        );
    }
    let done = AtomicUsize::new(0);
    let (finished, ended) = mpsc::channel::<()>();
    let frame = std::thread::scope(|s| {
        // The render runs inside the pool, so --threads sets its tile workers.
        let worker = s.spawn(|| {
            let frame = pool.install(|| match (window, &mut trace) {
                (Some(w), t) => render::render_window(&scene, &prep, w, Some(&done), t.as_mut()),
                (None, Some(t)) => render::render_traced(&scene, &prep, Some(&done), t),
                (None, None) => render::render(&scene, &prep, Some(&done)),
            });
            // Wakes the progress loop now rather than at its next tick.
            let _ = finished.send(());
            frame
        });
        progress_bar(&done, tiles, &worker, &ended);
        worker.join().expect("render thread panicked")
    });

    frame.film.write_png(&a.output)?;
    if let Some(p) = &a.hits {
        frame.film.write_hits_exr(p)?;
    }
    if let Some(p) = &a.exr {
        frame.film.write_color_exr(p)?;
    }
    // The whole process's peak (volume, coefficients, structures, film):
    // what a large volume needs of the machine.
    let peak_mib = snell::bench::machine::peak_rss_mib();
    if let Some(p) = &a.stats {
        let mut j = frame.stats.to_json();
        j["peak_rss_mib"] = serde_json::json!(peak_mib);
        j["scene"] = serde_json::json!(a.scene.display().to_string());
        j["settings"] = serde_json::to_value(scene.render)?;
        j["filter"] = serde_json::json!(scene.surface.filter.to_string());
        snell::atomic::write_atomic(p, |w| {
            use std::io::Write;
            serde_json::to_writer_pretty(&mut *w, &j)?;
            w.write_all(b"\n")
        })
        .with_context(|| p.display().to_string())?;
    }
    if let (Some(p), Some(t)) = (&a.trace, &trace) {
        t.write(p).with_context(|| p.display().to_string())?;
    }
    if frame.stats.counters.undefined > 0 {
        eprintln!(
            "warning: {} rays ended in an undefined state (reported as background)",
            frame.stats.counters.undefined
        );
    }
    if !a.quiet {
        eprint!("{}", frame.stats.table());
        if let Some(m) = peak_mib {
            eprintln!("peak memory: {} resident", super::common::human_mib(m));
        }
    }
    Ok(())
}

/// Shows a bar on stderr once a render has run for a second, updated every
/// 25 ms; returns as soon as the worker sends on `ended` (or has ended
/// without sending, by a panic). It slept 25 ms between looks at the
/// worker, which kept every `snell render` waiting for the tick after its
/// render had ended (the glass sphere's whole process 68 → 53 ms, medians
/// of 15).
fn progress_bar<T>(
    done: &AtomicUsize,
    total: usize,
    worker: &std::thread::ScopedJoinHandle<T>,
    ended: &mpsc::Receiver<()>,
) {
    let start = Instant::now();
    let mut bar: Option<indicatif::ProgressBar> = None;
    while !worker.is_finished() {
        if ended.recv_timeout(Duration::from_millis(25)).is_ok() {
            break;
        }
        if bar.is_none() && start.elapsed() > Duration::from_secs(1) {
            let b = indicatif::ProgressBar::new(total as u64);
            b.set_style(
                indicatif::ProgressStyle::with_template(
                    "rendering [{bar:40}] {pos}/{len} tiles, {eta} left",
                )
                .expect("valid template")
                .progress_chars("=> "),
            );
            bar = Some(b);
        }
        if let Some(b) = &bar {
            b.set_position(done.load(Ordering::Relaxed) as u64);
        }
    }
    if let Some(b) = bar {
        b.finish_and_clear();
    }
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
