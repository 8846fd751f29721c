//! `snell resample`: a volume reconstructed by a filter and sampled on a new
//! lattice over the same domain, as NRRD or MetaImage (e.g. a scan upsampled to 1024³).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use clap::Args as ClapArgs;

use snell::filter::resample::resample;
use snell::volume::{self, SampleType};

use super::common::{VolumeArgs, check_distinct, check_format, check_output, human_mib, triple};
use super::progress::{self, Step};

#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Volume file.
    pub volume: PathBuf,
    /// Output volume: .nrrd or .mha (the extension chooses the format).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Samples per axis of the new lattice: X,Y,Z (the first and last stay on the domain's faces).
    #[arg(long, value_name = "X,Y,Z")]
    pub size: String,
    /// Reconstruction filter: linear, catmull-rom, bspline2..bspline7, smooth-bspline3.
    #[arg(long, default_value = "bspline3")]
    pub filter: String,
    /// Smoothing weight λ of smooth-bspline3, 0 to 1e12 (required by it, refused by the other filters).
    #[arg(long, allow_negative_numbers = true, value_name = "L")]
    pub lambda: Option<f64>,
    /// Sample type written: u8, i8, u16, i16, u32, i32, f32 (integers rounded and clamped; default: the input's, f64 as f32).
    #[arg(long)]
    pub format: Option<String>,
    /// Compress the samples: gzip in NRRD, zlib in MetaImage.
    #[arg(long)]
    pub gzip: bool,
    #[command(flatten)]
    pub vol: VolumeArgs,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let kind = super::common::filter_kind(&a.filter, a.lambda)?;
    let size = triple::<usize>(&a.size, "--size")?;
    let ty = match &a.format {
        None => None,
        Some(s) => Some(
            SampleType::parse(s)
                .filter(|t| *t != SampleType::F64)
                .with_context(|| {
                    format!("--format: expected u8, i8, u16, i16, u32, i32 or f32, got '{s}'")
                })?,
        ),
    };
    check_output(&a.output)?;
    check_format(&a.output, "-o", &volume::WRITTEN_FORMATS)?;
    check_distinct(&[&a.output], &[&a.volume])?;
    let opts = a.vol.load_options(&a.volume)?;
    let reading = Step::named(format!("reading {}", a.volume.display()));
    let vol = progress::watch(&reading, false, || a.vol.load_with(&a.volume, &opts))?;
    let ty = ty.unwrap_or(match vol.native_type() {
        SampleType::F64 => SampleType::F32,
        t => t,
    });
    let (lo, hi) = vol.value_range();
    if let Some((tlo, thi)) = snell::filter::resample::integer_range(ty)
        && (lo < tlo || hi > thi)
    {
        let num = snell::human::num;
        eprintln!(
            "warning: {}: values [{}, {}] do not fit {} [{}, {}]: those beyond are clamped",
            a.volume.display(),
            num(lo),
            num(hi),
            ty.name(),
            num(tlo),
            num(thi)
        );
    }
    let start = Instant::now();
    let resampling = Step::named(format!(
        "resampling to {}x{}x{} with {kind}",
        size[0], size[1], size[2]
    ));
    let out = progress::watch(&resampling, false, || {
        resample(&vol, kind, size, ty, opts.memory_limit)
    })
    .with_context(|| a.volume.display().to_string())?;
    let took = start.elapsed().as_secs_f64();
    drop(vol);
    let writing = Step::named(format!("writing {}", a.output.display()));
    progress::watch(&writing, false, || volume::write(&a.output, &out, a.gzip))?;
    let d = out.dims();
    let s = out.spacing();
    let peak = snell::bench::machine::peak_rss_mib()
        .map(|m| format!(", peak memory {}", human_mib(m)))
        .unwrap_or_default();
    eprintln!(
        "wrote {} ({}x{}x{} {}, spacing {:.6},{:.6},{:.6}; resampled with {} in {:.1} s{peak})",
        a.output.display(),
        d[0],
        d[1],
        d[2],
        ty.name(),
        s[0],
        s[1],
        s[2],
        kind,
        took,
    );
    Ok(())
}
