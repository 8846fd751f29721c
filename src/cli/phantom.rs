//! `snell phantom`: synthetic volumes with known ground truth, as NRRD.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args as ClapArgs, Subcommand};

use snell::phantom::{Hole, MarschnerLobbSpec, PhantomFormat, SphereSpec};
use snell::volume::nrrd;

use super::common::{check_format, check_output, triple};

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
    /// Output NRRD file.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Sample format: f32 (0..1), u8 (round 255·v) or u16 (round 65535·v).
    #[arg(long, default_value = "f32")]
    pub format: String,
    /// Standard deviation of added Gaussian noise, in output units.
    #[arg(long, default_value_t = 0.0)]
    pub noise: f64,
    /// Noise seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Write gzip-encoded NRRD.
    #[arg(long)]
    pub gzip: bool,
}

#[derive(ClapArgs, Debug)]
pub struct SphereArgs {
    /// Cube side in samples.
    #[arg(long, default_value_t = 64)]
    pub size: usize,
    #[arg(long, default_value_t = 20.0)]
    pub radius: f64,
    #[arg(long, default_value_t = 3.0)]
    pub sigma: f64,
    /// Centre X,Y,Z in grid coordinates (default: the cube's centre).
    #[arg(long)]
    pub center: Option<String>,
    /// An air hole CX,CY,CZ,RADIUS,SIGMA (repeatable).
    #[arg(long = "hole", value_name = "CX,CY,CZ,R,SIGMA")]
    pub holes: Vec<String>,
    #[command(flatten)]
    pub out: Output,
}

#[derive(ClapArgs, Debug)]
pub struct MlArgs {
    #[arg(long, default_value_t = 41)]
    pub size: usize,
    #[arg(long, default_value_t = 0.25)]
    pub alpha: f64,
    #[arg(long, default_value_t = 6.0)]
    pub fm: f64,
    #[command(flatten)]
    pub out: Output,
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
            check_format(&s.out.output, "-o", &["nrrd"])?;
            (spec.build()?, s.out)
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
            check_format(&m.out.output, "-o", &["nrrd"])?;
            (spec.build()?, m.out)
        }
    };
    let enc = if out.gzip {
        nrrd::Encoding::Gzip
    } else {
        nrrd::Encoding::Raw
    };
    nrrd::write(&out.output, &vol, enc)?;
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
