//! `snell scene`: a scene file for a volume, the camera and checkerboard
//! placed from its extent ([`snell::scene::framing`]), the iso-value from
//! its histogram unless given: the step between `snell info` and `snell
//! render` for a new dataset.

use std::path::{Component, Path, PathBuf};

use anyhow::{Context, bail};
use clap::Args as ClapArgs;

use snell::filter::FilterKind;
use snell::human::num;
use snell::scene::framing::{self, DEFAULT_FOV_Y, Draft, DraftVolume, View};
use snell::scene::{MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE, Scene};

use super::common::{
    VolumeArgs, check_distinct, check_format, check_output, filter_kind, shell_path,
};
use super::progress::{self, Step};

#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Volume file (.nrrd, .nhdr, .nii, .nii.gz, .mha, .mhd, or raw with --dims/--type).
    pub volume: PathBuf,
    /// The scene file to write (.toml).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Iso-value of the surface (default: the first `snell info` suggests,
    /// the lowest boundary between the histogram's modes that wraps an
    /// object rather than voids).
    #[arg(long, allow_negative_numbers = true)]
    pub iso: Option<f64>,
    /// Reconstruction filter: linear, catmull-rom, bspline2..bspline7,
    /// smooth-bspline3 (default, with λ = 1: the example CT scenes' choice,
    /// a scan's noise smoothed out of the glass).
    #[arg(long)]
    pub filter: Option<String>,
    /// Smoothing weight λ of smooth-bspline3, 0 to 1e12 (default 1; refused by the other filters).
    #[arg(long, allow_negative_numbers = true, value_name = "L")]
    pub lambda: Option<f64>,
    /// Index of refraction of the object (where the field exceeds the
    /// iso-value); the example CT scenes' weak glass by default.
    #[arg(long, default_value_t = 1.3, allow_negative_numbers = true)]
    pub ior: f64,
    /// Axis the camera looks along: +x, -x, +y, -y, +z, -z (default: +
    /// along the volume's thinnest extent, its broadest silhouette).
    #[arg(long, allow_hyphen_values = true)]
    pub view: Option<String>,
    /// Image width in pixels.
    #[arg(long, default_value_t = 512, value_parser = image_side)]
    pub width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 512, value_parser = image_side)]
    pub height: u32,
    /// Vertical field of view in degrees, from 0.1 to 179 (narrower puts
    /// the camera so far out that precision fails; a scene file takes any).
    #[arg(long, default_value_t = DEFAULT_FOV_Y, allow_negative_numbers = true)]
    pub fov: f64,
    /// Replace the output file if it exists (a scene file is often edited
    /// by hand, so it is not overwritten by default).
    #[arg(long)]
    pub force: bool,
    #[command(flatten)]
    pub vol: VolumeArgs,
}

/// The narrowest and widest `--fov`, in degrees.
const MIN_FOV: f64 = 0.1;
const MAX_FOV: f64 = 179.0;

/// `--width`, `--height`: a side the renderer accepts.
fn image_side(s: &str) -> Result<u32, String> {
    match s.trim().parse::<u32>() {
        Ok(n) if (1..=MAX_IMAGE_SIDE).contains(&n) => Ok(n),
        _ => Err(format!(
            "expected a whole number of pixels from 1 to {MAX_IMAGE_SIDE}, got '{s}'"
        )),
    }
}

pub fn run(a: Args) -> anyhow::Result<()> {
    // The smoothing spline, named or by default, takes λ = 1 unless given.
    let name = a.filter.as_deref().unwrap_or("smooth-bspline3");
    let smooths = FilterKind::with_lambda(name, Some(1.0)).is_ok_and(|k| k.smooths());
    let lambda = if smooths {
        Some(a.lambda.unwrap_or(1.0))
    } else {
        a.lambda
    };
    let filter = filter_kind(name, lambda)?;
    if (a.width as u64) * (a.height as u64) > MAX_IMAGE_PIXELS {
        bail!(
            "--width {} --height {}: over the renderer's {MAX_IMAGE_PIXELS} pixels",
            a.width,
            a.height
        );
    }
    if !(a.ior.is_finite() && a.ior > 0.0) {
        bail!("--ior must be a finite number > 0, got {}", a.ior);
    }
    if let Some(iso) = a.iso
        && !iso.is_finite()
    {
        bail!("--iso must be a finite number, got {iso}");
    }
    if !(MIN_FOV..=MAX_FOV).contains(&a.fov) {
        bail!(
            "--fov must be from {MIN_FOV} to {MAX_FOV} degrees, got {}",
            a.fov
        );
    }
    let view = a
        .view
        .as_deref()
        .map(View::parse)
        .transpose()
        .map_err(|e| anyhow::anyhow!("--view: {e}"))?;
    check_format(&a.output, "-o", &["toml"])?;
    check_output(&a.output)?;
    check_distinct(&[&a.output], &[&a.volume])?;
    // A dangling symbolic link exists too: writing would replace it.
    if !a.force && std::fs::symlink_metadata(&a.output).is_ok() {
        bail!(
            "{}: exists; --force replaces it (a scene file is often edited by hand)",
            a.output.display()
        );
    }
    let volume_path = path_from(&a.output, &a.volume)?;
    let opts = a.vol.load_options(&a.volume)?;
    let reading = Step::named(format!("reading {}", a.volume.display()));
    let vol = progress::watch(&reading, false, || a.vol.load_with(&a.volume, &opts))?;
    // The scene reader's own check of a spacing (here one --spacing set).
    snell::volume::check_spacing_ratio(vol.spacing())
        .with_context(|| a.volume.display().to_string())?;
    if let Some(why) = super::common::no_cells(vol.dims()) {
        bail!(
            "{}: {why} there, so no surface to frame",
            a.volume.display()
        );
    }
    let stats = vol.stats();
    if stats.min == stats.max {
        bail!(
            "{}: every sample is {}: there is no iso-surface to frame",
            a.volume.display(),
            num(stats.min)
        );
    }
    // As `snell info` prints them: to a thousandth of the range.
    let value = |x: f64| snell::human::num_resolving(x, (stats.max - stats.min) / 1000.0);
    // Framed first: a volume that cannot be framed fails before anything
    // about its iso-value is said.
    let extent = vol.extent();
    let view = view.unwrap_or_else(|| View::thinnest(extent));
    let aspect = a.width as f64 / a.height as f64;
    let fr = framing::frame(extent, view, a.fov, aspect)
        .with_context(|| a.volume.display().to_string())?;
    let iso = match a.iso {
        Some(iso) => {
            if !(iso > stats.min && iso < stats.max) {
                eprintln!(
                    "warning: --iso {}: not between the smallest and the largest sample ({} .. {}); the render will likely show only the backdrop",
                    value(iso),
                    value(stats.min),
                    value(stats.max)
                );
            }
            iso
        }
        None => {
            let iso = stats
                .suggested_iso
                .first()
                .copied()
                .unwrap_or(0.5 * (stats.min + stats.max));
            if stats.iso_from_modes {
                eprintln!(
                    "iso {} (the lowest boundary between the histogram's modes that wraps an object rather than voids; `snell info` lists the others; --iso chooses)",
                    value(iso)
                );
            } else {
                eprintln!(
                    "warning: iso {} is the value range's midpoint: the histogram shows no two materials apart; try others with --iso",
                    value(iso)
                );
            }
            iso
        }
    };
    let draft = Draft {
        note: vec![
            format!(
                "{} ({}x{}x{} {}, extent {} world units), framed by `snell scene`.",
                a.volume.display(),
                vol.dims()[0],
                vol.dims()[1],
                vol.dims()[2],
                vol.native_type().name(),
                snell::human::triple(extent)
            ),
            "Edit freely: README.md lists every key.".into(),
        ],
        volume: DraftVolume {
            path: volume_path,
            raw: opts.raw.clone(),
            spacing: a.vol.spacing.is_some().then(|| vol.spacing()),
            allow_nan: a.vol.allow_nan,
        },
        filter,
        iso,
        ior: a.ior,
        width: a.width,
        height: a.height,
        view,
        framing: fr,
    };
    let text = draft.to_toml();
    // What is written is a scene the renderer reads (its volume is not
    // read again here).
    let scene = Scene::parse(&text, &a.output, &[]).map_err(|e| {
        anyhow::anyhow!(
            "internal error, please report it: the drafted scene does not read back: {e}"
        )
    })?;
    debug_assert!(scene.setting_notes().is_empty());
    snell::atomic::write_atomic(&a.output, |w| {
        use std::io::Write;
        w.write_all(text.as_bytes())
    })
    .with_context(|| format!("cannot write {}", a.output.display()))?;
    eprintln!(
        "wrote {}: {}x{}, looking along {} from {} world units, iso {}, {}, checker {}",
        a.output.display(),
        a.width,
        a.height,
        view.name(),
        num((fr.look_at - fr.position).length()),
        value(iso),
        filter,
        num(fr.checker)
    );
    eprintln!(
        "render it with: snell render {} -o image.png",
        shell_path(&a.output.to_string_lossy())
    );
    Ok(())
}

/// The volume's path as the scene file at `scene` writes it: relative to
/// the folder of the file written (scene paths are read from there; through
/// a symbolic link `-o`, the folder of the file it names), or absolute
/// where the two share only the root. The volume's own name is kept, a
/// symbolic link included; the folders are resolved.
fn path_from(scene: &Path, volume: &Path) -> anyhow::Result<String> {
    let folder = |p: &Path| -> anyhow::Result<PathBuf> {
        let dir = match p.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        std::fs::canonicalize(dir)
            .with_context(|| format!("{}: folder {}", p.display(), dir.display()))
    };
    let Some(name) = volume.file_name() else {
        bail!("{}: not a file name", volume.display());
    };
    let volume_abs = folder(volume)?.join(name);
    let written = snell::atomic::written_path(scene);
    let path = relative(&volume_abs, &folder(&written)?).unwrap_or(volume_abs);
    match path.to_str() {
        Some(s) => Ok(s.to_string()),
        None => bail!(
            "{}: the path ({}) is not UTF-8, which a scene file (TOML) cannot hold; give the volume a UTF-8 name, or a symbolic link to it in a folder with one",
            volume.display(),
            path.display()
        ),
    }
}

/// `target` as seen from `base` (both absolute and resolved), or `None`
/// where they share nothing but the root.
fn relative(target: &Path, base: &Path) -> Option<PathBuf> {
    let t: Vec<Component> = target.components().collect();
    let b: Vec<Component> = base.components().collect();
    let common = t.iter().zip(&b).take_while(|(x, y)| x == y).count();
    // Only the root (or a prefix and root) in common: absolute reads better.
    if t[..common]
        .iter()
        .all(|c| matches!(c, Component::RootDir | Component::Prefix(_)))
    {
        return None;
    }
    let mut out = PathBuf::new();
    for _ in common..b.len() {
        out.push("..");
    }
    for c in &t[common..] {
        out.push(c);
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_paths_climb_to_the_shared_folder() {
        let r = |t: &str, b: &str| relative(Path::new(t), Path::new(b));
        assert_eq!(
            r("/work/shared/data/lobster.nrrd", "/work/main/scenes"),
            Some(PathBuf::from("../../shared/data/lobster.nrrd"))
        );
        assert_eq!(
            r("/work/main/scenes/a.nrrd", "/work/main/scenes"),
            Some(PathBuf::from("a.nrrd"))
        );
        assert_eq!(
            r("/work/main/data/a.nrrd", "/work/main"),
            Some(PathBuf::from("data/a.nrrd"))
        );
        assert_eq!(r("/data/a.nrrd", "/home/me"), None);
    }
}
