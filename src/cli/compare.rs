//! `snell compare`: hit-error statistics between two hit-position EXRs.

use std::path::PathBuf;

use clap::Args as ClapArgs;

use snell::compare::compare_hits;
use snell::film::HitImage;
use snell::scene::Scene;

#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Hit-position EXR to assess.
    pub a: PathBuf,
    /// Hit-position EXR to compare against (e.g. from `snell reference`).
    pub b: PathBuf,
    /// Checker square size, to report errors in squares.
    #[arg(long)]
    pub checker: Option<f64>,
    /// Take the checker size from this scene file.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let checker = match (&a.checker, &a.scene) {
        (Some(c), _) => Some(*c),
        (None, Some(s)) => Scene::load(s, &[])?.checker_size(),
        (None, None) => None,
    };
    if let Some(c) = checker {
        anyhow::ensure!(c.is_finite() && c > 0.0, "--checker must be > 0, got {c}");
    }
    let ha = HitImage::read_exr(&a.a)?;
    let hb = HitImage::read_exr(&a.b)?;
    let c = compare_hits(&ha, &hb, checker)
        .map_err(|e| anyhow::anyhow!("{} vs {}: {e}", a.a.display(), a.b.display()))?;
    if a.json {
        println!("{}", c.to_json());
    } else {
        print!("{}", c.table());
    }
    Ok(())
}
