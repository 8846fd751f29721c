//! `snell reference`: the analytic hit positions of a sphere-phantom scene.

use std::path::PathBuf;

use clap::Args as ClapArgs;

use snell::reference::Reference;

use super::common::{
    MemoryLimit, check_distinct, check_format, check_output, given, load_scene_reading, unread_sets,
};

#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Scene file whose volume is a sphere phantom.
    pub scene: PathBuf,
    /// Output hit-position EXR.
    #[arg(long, value_name = "REF.exr")]
    pub hits: PathBuf,
    /// Also write the colour image these hits give (PNG).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Override a scene value (repeatable).
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
    pub set: Vec<String>,
    #[command(flatten)]
    pub limit: MemoryLimit,
    /// Print no notes (warnings still): the reference prints no table or
    /// progress, so scripts that pass -q to every command may pass it here.
    #[arg(short, long)]
    pub quiet: bool,
}

/// The analytic spheres take one ray per pixel centre: the filter and the
/// renderer's settings but `max_events` do not apply.
fn unread(key: &str) -> bool {
    (key.starts_with("render.") && key != "render.max_events")
        || key == "surface.filter"
        || key == "surface.lambda"
}

pub fn run(a: Args) -> anyhow::Result<()> {
    a.limit.apply()?;
    let scene = load_scene_reading(&a.scene, &a.set, unread)?;
    check_output(&a.hits)?;
    check_format(&a.hits, "--hits", &["exr"])?;
    if let Some(o) = &a.output {
        check_output(o)?;
        check_format(o, "-o", &["png"])?;
    }
    check_distinct(
        &given(&[Some(&a.hits), a.output.as_ref()]),
        &scene.input_files(),
    )?;
    let r =
        Reference::from_scene(&scene).map_err(|e| anyhow::anyhow!("{}: {e}", a.scene.display()))?;
    if r.approximate_holes > 0 {
        eprintln!(
            "warning: {} hole(s) reach into the ball's fringe; their reference sphere is approximate",
            r.approximate_holes
        );
    }
    if let snell::scene::VolumeSource::Phantom(snell::phantom::PhantomSpec::Sphere(spec)) =
        &scene.volume
        && spec.noise > 0.0
        && !a.quiet
    {
        // The reference is the truth the noise hides, what a filter's
        // render of the noisy volume is measured against.
        eprintln!(
            "note: the phantom's noise (σ = {}) is left out: these are the noise-free spheres",
            spec.noise
        );
    }
    let unread = unread_sets(&a.set, unread);
    if !unread.is_empty() {
        eprintln!(
            "warning: --set {} ignored: the reference traces the phantom's analytic spheres, one ray per pixel centre (of the [render] settings it reads only max_events)",
            unread.join(", ")
        );
    }
    let hits = r.render(&scene);
    // The hits and the image appear together, or neither does.
    let held = snell::atomic::hold();
    hits.write_exr(&a.hits)?;
    if let Some(o) = &a.output {
        let rgb: Vec<u8> = (0..hits.u.len())
            .flat_map(|i| {
                let c = if hits.u[i].is_finite() {
                    scene.backdrop.color(hits.u[i] as f64, hits.v[i] as f64)
                } else {
                    scene.background
                };
                c.map(|x| (x.clamp(0.0, 1.0) * 255.0).round() as u8)
            })
            .collect();
        snell::film::write_png_rgb(o, hits.width, hits.height, &rgb)?;
    }
    held.commit()?;
    Ok(())
}
