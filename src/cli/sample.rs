//! `snell sample`: the reconstructed field and its gradient at given points.

use std::io::{BufRead, BufReader, Write};
use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args as ClapArgs;
use glam::DVec3;

use snell::filter::{Field, FilterKind};

use super::common::VolumeArgs;

#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Volume file.
    pub volume: PathBuf,
    /// Reconstruction filter: linear, catmull-rom, bspline2..bspline7, smooth-bspline3.
    #[arg(long)]
    pub filter: String,
    /// Smoothing of smooth-bspline3 (λ >= 0).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub lambda: f64,
    /// File of points, one `x,y,z` per line in grid coordinates (`-` for stdin).
    #[arg(long)]
    pub points: PathBuf,
    #[command(flatten)]
    pub vol: VolumeArgs,
}

fn parse_points(reader: impl BufRead, name: &str) -> anyhow::Result<Vec<DVec3>> {
    let mut out = Vec::new();
    for (n, line) in reader.lines().enumerate() {
        let line = line.with_context(|| format!("{name}: read error at line {}", n + 1))?;
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let parts: Vec<&str> = t
            .split([',', ' ', '\t'])
            .filter(|s| !s.is_empty())
            .collect();
        let vals: Option<Vec<f64>> = parts.iter().map(|p| p.parse::<f64>().ok()).collect();
        match vals {
            Some(v) if v.len() == 3 && v.iter().all(|x| x.is_finite()) => {
                out.push(DVec3::new(v[0], v[1], v[2]))
            }
            _ => {
                // A line of megabytes quoted whole would bury the message.
                let shown: String = t.chars().take(80).collect();
                let more = if shown.len() < t.len() { "…" } else { "" };
                bail!(
                    "{name}: line {}: expected three finite numbers x,y,z, got '{shown}{more}'",
                    n + 1
                )
            }
        }
    }
    Ok(out)
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let kind = FilterKind::parse(&a.filter, a.lambda).context("--filter")?;
    let name = a.points.display().to_string();
    let points = if name == "-" {
        parse_points(std::io::stdin().lock(), "stdin")?
    } else {
        let f = std::fs::File::open(&a.points).with_context(|| name.clone())?;
        parse_points(BufReader::new(f), &name)?
    };
    let vol = a.vol.load(&a.volume)?;
    let field = Field::new(&vol, kind);
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    writeln!(out, "x,y,z,value,gx,gy,gz")?;
    for p in points {
        let (v, g) = field.value_grad(p);
        writeln!(out, "{},{},{},{},{},{},{}", p.x, p.y, p.z, v, g.x, g.y, g.z)?;
    }
    out.flush()?;
    Ok(())
}
