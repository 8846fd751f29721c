//! `snell compare`: two hit-position EXRs (hit-error statistics) or two images
//! (RMSE, PSNR, SSIM, and an error image on request).

use std::path::{Path, PathBuf};

use clap::Args as ClapArgs;

use snell::compare::compare_hits;
use snell::film::HitImage;
use snell::film::metrics::{RgbImage, compare_images, diff_image};
use snell::input::has_extension;
use snell::scene::Scene;

use super::common::{MemoryLimit, check_distinct, check_format, check_output};

#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Image or hit-position EXR to assess.
    pub a: PathBuf,
    /// Reference to compare against (e.g. from `snell reference`, or a 16×16 supersampled render).
    pub b: PathBuf,
    /// Checker square size, to report hit errors in squares (> 0).
    #[arg(long, allow_negative_numbers = true)]
    pub checker: Option<f64>,
    /// Take the checker size from this scene file.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Write a heat map of the per-pixel colour difference (images only).
    #[arg(long, value_name = "DIFF.png")]
    pub diff: Option<PathBuf>,
    /// Also list up to N disagreeing pixels (hit images): event or validity
    /// mismatches first, then the largest hit distances.
    #[arg(long, value_name = "N")]
    pub list: Option<usize>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub limit: MemoryLimit,
}

/// A hit-position EXR's hits and place in its frame; `None` for a colour
/// image (PNG, JPEG, or an EXR without the hit channels). An EXR that does
/// not read is an error here, with the reader's reason.
fn read_hits(p: &Path) -> anyhow::Result<Option<(HitImage, [i32; 2])>> {
    if !has_extension(p, "exr") {
        return Ok(None);
    }
    Ok(HitImage::read_exr_if_hits(p)?)
}

pub fn run(a: Args) -> anyhow::Result<()> {
    a.limit.apply()?;
    if let Some(d) = &a.diff {
        check_output(d)?;
        check_format(d, "--diff", &["png"])?;
        check_distinct(&[d], &[&a.a, &a.b])?;
    }
    let (hits_a, hits_b) = (read_hits(&a.a)?, read_hits(&a.b)?);
    let (hit_a, hit_b) = (hits_a.is_some(), hits_b.is_some());
    if hit_a != hit_b {
        let (hit, other) = if hit_a { (&a.a, &a.b) } else { (&a.b, &a.a) };
        let what = if has_extension(other, "exr") {
            "an EXR without u, v, events channels, a colour image"
        } else {
            "not an EXR"
        };
        anyhow::bail!(
            "{} is a hit-position EXR but {} is {what}: compare hits with hits, colour images with colour images",
            hit.display(),
            other.display()
        );
    }
    // Options of the other kind of comparison would be ignored silently.
    if let (Some((ha, at_a)), Some((hb, at_b))) = (hits_a, hits_b) {
        anyhow::ensure!(
            a.diff.is_none(),
            "--diff draws colour differences; {} and {} are hit-position EXRs",
            a.a.display(),
            a.b.display()
        );
        anyhow::ensure!(
            a.checker.is_none() || a.scene.is_none(),
            "give --checker or --scene, not both"
        );
        let checker = match (&a.checker, &a.scene) {
            (Some(c), _) => Some(*c),
            (None, Some(s)) => {
                let size = Scene::load(s, &[])?.checker_size();
                if size.is_none() {
                    eprintln!(
                        "note: {}: its backdrop is a photograph, not a checkerboard: hit errors are in backdrop units only, without checker squares",
                        s.display()
                    );
                }
                size
            }
            (None, None) => None,
        };
        if let Some(c) = checker {
            anyhow::ensure!(
                c.is_finite() && c > 0.0,
                "--checker must be a finite number > 0, got {}",
                snell::human::exact(c)
            );
        }
        // Parts of a frame (`render --region`) of one size but from different
        // places would be compared pixel by pixel as if they were one place.
        anyhow::ensure!(
            at_a == at_b,
            "{} starts at pixel ({}, {}) of its frame, {} at ({}, {}): they cover different regions",
            a.a.display(),
            at_a[0],
            at_a[1],
            a.b.display(),
            at_b[0],
            at_b[1]
        );
        let c = compare_hits(&ha, &hb, checker)
            .map_err(|e| anyhow::anyhow!("{} vs {}: {e}", a.a.display(), a.b.display()))?;
        let listed = match a.list {
            Some(n) => snell::compare::disagreements(&ha, &hb, n)
                .map_err(|e| anyhow::anyhow!("{} vs {}: {e}", a.a.display(), a.b.display()))?,
            None => Vec::new(),
        };
        if a.json {
            let mut j = c.to_json();
            if a.list.is_some() {
                j["disagreements"] = serde_json::to_value(&listed)?;
            }
            println!("{j}");
        } else {
            print!("{}", c.table());
            if a.list.is_some() {
                println!(
                    "pixel (x, y)   events A/B   hit A                    hit B                    distance"
                );
                let fmt = |h: Option<[f32; 2]>| match h {
                    Some(p) => format!("({:.4}, {:.4})", p[0], p[1]),
                    None => "none".to_string(),
                };
                for d in &listed {
                    println!(
                        "({:4}, {:4})   {:>3}/{:<3}     {:24} {:24} {}",
                        d.x,
                        d.y,
                        d.events[0],
                        d.events[1],
                        fmt(d.hit[0]),
                        fmt(d.hit[1]),
                        d.distance.map_or("-".to_string(), snell::human::sig4)
                    );
                }
            }
        }
        return Ok(());
    }
    anyhow::ensure!(
        a.checker.is_none() && a.scene.is_none() && a.list.is_none(),
        "--checker, --scene and --list apply to hit-position EXRs; {} and {} are colour images",
        a.a.display(),
        a.b.display()
    );
    let ia = RgbImage::read(&a.a)?;
    let ib = RgbImage::read(&a.b)?;
    let c = compare_images(&ia, &ib)
        .map_err(|e| anyhow::anyhow!("{} vs {}: {e}", a.a.display(), a.b.display()))?;
    if let Some(d) = &a.diff {
        snell::film::write_png_rgb(d, ia.width, ia.height, &diff_image(&ia, &ib))?;
    }
    if a.json {
        println!("{}", serde_json::to_value(c)?);
    } else {
        println!(
            "RMSE {:.5}  PSNR {:.2} dB  SSIM {:.4}  max |diff| {:.4}",
            c.rmse, c.psnr, c.ssim, c.max_abs
        );
    }
    Ok(())
}
