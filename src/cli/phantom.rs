//! `snell phantom`: synthetic volumes with known ground truth, as NRRD or MetaImage.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args as ClapArgs, Subcommand};

use snell::phantom::{
    Hole, MAX_PHANTOM_SIZE, MarschnerLobbSpec, PhantomError, PhantomFormat, SphereSpec,
};
use snell::volume::{self, Volume};

use super::common::{MemoryLimit, check_format, check_output, triple};
use super::progress::{self, Step};

#[derive(ClapArgs, Debug)]
pub struct Args {
    #[command(subcommand)]
    pub kind: Kind,
}

#[derive(Subcommand, Debug)]
pub enum Kind {
    /// The paper's glass sphere: 1 inside `radius`, Gaussian fringe of `sigma` beyond, optional air holes.
    Sphere(SphereArgs),
    /// Marschner & Lobb (1994) test signal on [-1,1]³.
    MarschnerLobb(MlArgs),
}

#[derive(ClapArgs, Debug)]
pub struct Output {
    /// Output volume: .nrrd or .mha (the extension chooses the format).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Sample format: f32 (0..1), u8 (round 255·v) or u16 (round 65535·v).
    #[arg(long, default_value = "f32")]
    pub format: String,
    /// Standard deviation of added Gaussian noise, in output units (255 for
    /// u8 is full scale), >= 0.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub noise: f64,
    /// Noise seed.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true, value_parser = seed)]
    pub seed: u64,
    /// Compress the samples: gzip in NRRD, zlib in MetaImage.
    #[arg(long)]
    pub gzip: bool,
    #[command(flatten)]
    pub limit: MemoryLimit,
}

#[derive(ClapArgs, Debug)]
pub struct SphereArgs {
    /// Cube side in samples, 1 to 4096.
    #[arg(long, default_value_t = 64, allow_negative_numbers = true, value_parser = phantom_size)]
    pub size: usize,
    /// Radius of the solid core (value 1) in samples (grid units), >= 0.
    #[arg(long, default_value_t = 20.0, allow_negative_numbers = true)]
    pub radius: f64,
    /// Standard deviation of the Gaussian fringe beyond the core, in
    /// samples (grid units), >= 0; 0 makes a hard edge.
    #[arg(long, default_value_t = 3.0, allow_negative_numbers = true)]
    pub sigma: f64,
    /// Centre X,Y,Z in grid coordinates (default: the cube's centre).
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub center: Option<String>,
    /// An air hole CX,CY,CZ,RADIUS,SIGMA in grid units (repeatable).
    #[arg(
        long = "hole",
        value_name = "CX,CY,CZ,R,SIGMA",
        allow_hyphen_values = true
    )]
    pub holes: Vec<String>,
    #[command(flatten)]
    pub out: Output,
}

#[derive(ClapArgs, Debug)]
pub struct MlArgs {
    /// Cube side in samples over [-1, 1]³, 1 to 4096 (41 is the original
    /// paper's lattice).
    #[arg(long, default_value_t = 41, allow_negative_numbers = true, value_parser = phantom_size)]
    pub size: usize,
    /// The signal's α: the amplitude of the radial ripple against the
    /// slope along z, (1 − sin(πz/2) + α(1 + ρ(r))) / (2(1 + α)) (finite;
    /// Marschner & Lobb use 0.25).
    #[arg(long, default_value_t = 0.25, allow_negative_numbers = true)]
    pub alpha: f64,
    /// The frequency f_M of the radial ripple ρ(r) = cos(2π f_M cos(πr/2))
    /// (finite; Marschner & Lobb use 6).
    #[arg(long, default_value_t = 6.0, allow_negative_numbers = true)]
    pub fm: f64,
    #[command(flatten)]
    pub out: Output,
}

/// `--size`: a side from 1 to [`MAX_PHANTOM_SIZE`] samples.
fn phantom_size(s: &str) -> Result<usize, String> {
    let n: usize = s
        .trim()
        .parse()
        .map_err(|_| format!("expected a whole number from 1 to {MAX_PHANTOM_SIZE}, got '{s}'"))?;
    snell::phantom::check_size(n).map_err(|e| match e {
        PhantomError::Setting { msg, .. } => msg,
        e => e.to_string(),
    })?;
    Ok(n)
}

/// `--seed`: any whole number a `u64` holds.
fn seed(s: &str) -> Result<u64, String> {
    s.trim()
        .parse()
        .map_err(|_| format!("expected a whole number from 0 to {}, got '{s}'", u64::MAX))
}

/// A phantom's error with its setting named as the option that sets it.
fn option_error(e: PhantomError) -> anyhow::Error {
    match e {
        PhantomError::Setting { key, msg } => {
            let flag = if key == "holes" { "hole" } else { key };
            anyhow::anyhow!("--{flag}: {msg}")
        }
        e => e.into(),
    }
}

/// Builds a phantom, its progress shown (a 1024³ one takes a while).
fn build(spec: impl FnOnce() -> Result<Volume, PhantomError> + Send) -> anyhow::Result<Volume> {
    progress::watch(&Step::named("building the phantom"), false, spec).map_err(option_error)
}

fn format(s: &str) -> anyhow::Result<PhantomFormat> {
    PhantomFormat::parse(s).with_context(|| format!("--format: expected f32, u8 or u16, got '{s}'"))
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let (vol, out) = match a.kind {
        Kind::Sphere(s) => {
            let holes = s
                .holes
                .iter()
                .map(|h| {
                    let v: Vec<f64> = h
                        .split(',')
                        .map(|p| p.trim().parse::<f64>())
                        .collect::<Result<_, _>>()
                        .with_context(|| format!("--hole '{h}': not numbers"))?;
                    anyhow::ensure!(v.len() == 5, "--hole '{h}': expected CX,CY,CZ,R,SIGMA");
                    Ok(Hole {
                        center: [v[0], v[1], v[2]],
                        radius: v[3],
                        sigma: v[4],
                    })
                })
                .collect::<anyhow::Result<Vec<Hole>>>()?;
            let spec = SphereSpec {
                size: s.size,
                radius: s.radius,
                sigma: s.sigma,
                center: s
                    .center
                    .as_deref()
                    .map(|c| triple::<f64>(c, "--center"))
                    .transpose()?,
                holes,
                format: format(&s.out.format)?,
                noise: s.out.noise,
                seed: s.out.seed,
            };
            check_output(&s.out.output)?;
            check_format(&s.out.output, "-o", &volume::WRITTEN_FORMATS)?;
            s.out.limit.apply()?;
            (build(|| spec.build())?, s.out)
        }
        Kind::MarschnerLobb(m) => {
            let spec = MarschnerLobbSpec {
                size: m.size,
                alpha: m.alpha,
                fm: m.fm,
                format: format(&m.out.format)?,
                noise: m.out.noise,
                seed: m.out.seed,
            };
            check_output(&m.out.output)?;
            check_format(&m.out.output, "-o", &volume::WRITTEN_FORMATS)?;
            m.out.limit.apply()?;
            (build(|| spec.build())?, m.out)
        }
    };
    let writing = Step::named(format!("writing {}", out.output.display()));
    progress::watch(&writing, false, || {
        volume::write(&out.output, &vol, out.gzip)
    })?;
    let d = vol.dims();
    eprintln!(
        "wrote {} ({}x{}x{} {})",
        out.output.display(),
        d[0],
        d[1],
        d[2],
        vol.native_type()
    );
    Ok(())
}
