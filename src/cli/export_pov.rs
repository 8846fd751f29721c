//! `snell export-pov`: the scene for POV-Ray 3.7 (DF3 volume, colour and
//! hit-position `.pov` files), and optionally the render itself.

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args as ClapArgs;

use snell::human::{exact, num};
use snell::peer::povray::{self, PovOptions, Variant};
use snell::peer::{Interpolation, PeerError};
use snell::volume::LoadOptions;

use super::common::{
    MemoryLimit, check_distinct, check_output, flags_given, load_scene_reading, unread_sets,
};

#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Scene file (TOML).
    pub scene: PathBuf,
    /// Directory for volume.df3, scene.pov, hits.pov and peer.json (created if missing).
    pub dir: PathBuf,
    /// Override a scene value (repeatable).
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
    pub set: Vec<String>,
    /// Isosurface accuracy 1e-4 instead of 1e-3 (grid units).
    #[arg(long)]
    pub careful: bool,
    /// Density interpolation: 1 (trilinear) or 2 (tricubic Catmull-Rom); default from the scene's filter.
    #[arg(long, value_name = "1|2")]
    pub interpolate: Option<String>,
    /// Use this max_gradient instead of the bound computed from the data.
    #[arg(long, value_name = "G")]
    pub max_gradient: Option<f64>,
    /// Threads for the printed command lines and for --run, 1 to 1024
    /// (default: all cores, as `render`).
    #[arg(long, allow_negative_numbers = true, value_parser = super::common::thread_count)]
    pub threads: Option<usize>,
    /// Also run POV-Ray (colour and hit renders) and report its times.
    #[arg(long)]
    pub run: bool,
    /// With --run: write POV-Ray's decoded hit positions as a hit-position EXR.
    #[arg(long, value_name = "HITS.exr")]
    pub hits: Option<PathBuf>,
    /// With --run: print the result as JSON.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub limit: MemoryLimit,
}

/// POV-Ray traces the scene itself: of the renderer's settings the export
/// reads only `max_events`.
fn unread(key: &str) -> bool {
    key.starts_with("render.") && key != "render.max_events"
}

pub fn run(a: Args) -> anyhow::Result<()> {
    a.limit.apply()?;
    let scene = load_scene_reading(&a.scene, &a.set, unread)?;
    let unread = unread_sets(&a.set, unread);
    if !unread.is_empty() {
        eprintln!(
            "warning: --set {} ignored: POV-Ray traces the exported scene (of the [render] settings the export reads only max_events, as max_trace_level)",
            unread.join(", ")
        );
    }
    let threads = a
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    if !a.run {
        let flags = flags_given([("--hits", a.hits.is_some()), ("--json", a.json)]);
        if !flags.is_empty() {
            bail!(
                "{} {} POV-Ray's run: add --run",
                flags.join(" and "),
                if flags.len() == 1 { "needs" } else { "need" }
            );
        }
    }
    if a.dir.exists() && !a.dir.is_dir() {
        bail!("{}: exists and is not a directory", a.dir.display());
    }
    let mut opts = PovOptions::new(&scene, a.careful);
    if let Some(i) = &a.interpolate {
        opts.interpolation = Interpolation::parse(i)
            .with_context(|| format!("--interpolate: expected 1 or 2, got '{i}'"))?;
    }
    if let Some(g) = a.max_gradient {
        if !(g.is_finite() && g > 0.0) {
            bail!("--max-gradient must be > 0, got {}", snell::human::exact(g));
        }
        opts.max_gradient = Some(g);
    }
    if a.run && !povray::installed() {
        return Err(PeerError::NotInstalled.into());
    }
    // Every file the export (and --run) may write, checked before any is.
    let written: Vec<PathBuf> = [
        povray::DF3_FILE,
        povray::COLOR_POV,
        povray::HITS_POV,
        povray::COLOR_PNG,
        povray::HITS_PNG,
        povray::BACKDROP_PNG,
        povray::MANIFEST,
    ]
    .iter()
    .map(|f| a.dir.join(f))
    .chain(a.hits.clone())
    .collect();
    for w in &written {
        if w.exists() {
            check_output(w)?;
        }
    }
    let written: Vec<&std::path::Path> = written.iter().map(|p| p.as_path()).collect();
    check_distinct(&written, &scene.input_files())?;
    let vol = scene.load_volume(&LoadOptions::default())?;
    // The folder itself, not a missing chain above it (as `--cache`): a
    // mistyped parent is an error, not a tree of new folders.
    let created = !a.dir.exists();
    if created {
        std::fs::create_dir(&a.dir)
            .with_context(|| format!("{}: cannot create directory", a.dir.display()))?;
    }
    if let Some(h) = &a.hits {
        check_output(h)?;
    }
    let dir = a.dir.canonicalize().unwrap_or_else(|_| a.dir.clone());
    // The export's files appear together or not at all (a full disk on
    // the third left the first two), and a folder made for them goes too;
    // the hold ends with the block, before POV-Ray reads them. (A failed
    // commit names its file.)
    let exported = {
        let held = snell::atomic::hold();
        povray::export(&dir, &scene, &vol, &opts)
            .map_err(anyhow::Error::from)
            .and_then(|ex| held.commit().map(|()| ex).map_err(anyhow::Error::from))
    };
    if exported.is_err() && created {
        let _ = std::fs::remove_dir(&a.dir);
    }
    let ex = exported?;
    // POV-Ray interpolates trilinearly or by Catmull-Rom only: a scene of
    // another filter is exported with the nearest, another surface.
    let pov_filter = ex.interpolation.filter();
    if pov_filter != scene.surface.filter {
        eprintln!(
            "note: {}: POV-Ray interpolates its density by {} (interpolate {}), not the scene's {}: compare its hits with `snell render --set surface.filter={}`",
            a.scene.display(),
            pov_filter.name(),
            ex.interpolation.keyword(),
            scene.surface.filter.name(),
            pov_filter.name()
        );
    }

    if !a.json {
        let m = &ex.mapping;
        println!(
            "wrote {}: {}x{}x{} samples (+ mirror border), 16-bit, density = (value - {}) * {} / 65535{}",
            dir.join(povray::DF3_FILE).display(),
            m.dims[0],
            m.dims[1],
            m.dims[2],
            exact(m.lo),
            exact(m.scale),
            if m.exact { " (exact)" } else { "" }
        );
        println!(
            "wrote {} and {}: interpolate {}, iso {} (density {:.9}), ior {}, accuracy {:e}, \
             max_gradient {:.6} (data bound {:.6} x {}), max_trace_level {}",
            dir.join(povray::COLOR_POV).display(),
            dir.join(povray::HITS_POV).display(),
            ex.interpolation.keyword(),
            exact(scene.surface.iso),
            ex.iso_density,
            ex.ior,
            ex.accuracy,
            ex.max_gradient,
            ex.gradient_estimate,
            ex.gradient_safety,
            ex.max_trace_level
        );
        let e = &ex.encoding;
        println!(
            "hits.png decodes as k = B - 1 (B = 0: no hit), u = {} + (k / 256 + R/65535) * {t}, \
             v = {} + (k % 256 + G/65535) * {t} (resolution {:.3e} backdrop units, window {} wide)",
            exact(e.u0),
            exact(e.v0),
            e.resolution(),
            num(e.window()),
            t = e.tile
        );
        println!("colour: {}", ex.command_line(Variant::Color, threads));
        println!("hits:   {}", ex.command_line(Variant::Hits, threads));
    }
    if !a.run {
        return Ok(());
    }
    let color = povray::render(&ex, Variant::Color, threads)?;
    let hits_run = povray::render(&ex, Variant::Hits, threads)?;
    let hits = povray::decode_hits(&hits_run.png, &ex.encoding)?;
    if let Some(h) = &a.hits {
        hits.write_exr(h)?;
    }
    let warnings: Vec<&String> = color
        .stats
        .warnings
        .iter()
        .chain(&hits_run.stats.warnings)
        .collect();
    if a.json {
        let j = serde_json::json!({
            "export": ex,
            "color": color,
            "hits": hits_run,
        });
        println!("{j}");
    } else {
        let f = |x: Option<f64>| x.map_or("?".to_string(), |s| format!("{s:.3} s"));
        for (name, r) in [("colour", &color), ("hits", &hits_run)] {
            println!(
                "{name} render: parse {}, trace {} ({} threads, {} CPU), whole process {:.3} s -> {}",
                f(r.stats.parse_seconds),
                f(r.stats.trace_seconds),
                r.stats.threads.map_or("?".to_string(), |t| t.to_string()),
                f(r.stats.trace_cpu_seconds),
                r.wall_seconds,
                r.png.display()
            );
        }
    }
    for w in warnings {
        eprintln!("warning: povray: {w}");
    }
    Ok(())
}
