//! `snell merge`: the parts of a frame rendered with `--region` into one image.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args as ClapArgs;

use snell::film::merge::{self, Part};
use snell::volume::limits::default_memory_limit;

use super::common::{MemoryLimit, check_distinct, check_format, check_output, given};

#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Part EXRs of one frame (hit-position or colour parts from
    /// `snell render --region`), in any order.
    #[arg(required = true)]
    pub parts: Vec<PathBuf>,
    /// The whole image as EXR (the parts' channels).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Also write an 8-bit PNG (colour parts only).
    #[arg(long, value_name = "OUT.png")]
    pub png: Option<PathBuf>,
    #[command(flatten)]
    pub limit: MemoryLimit,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    a.limit.apply()?;
    check_output(&a.output)?;
    check_format(&a.output, "-o", &["exr"])?;
    if let Some(p) = &a.png {
        check_output(p)?;
        check_format(p, "--png", &["png"])?;
    }
    let inputs: Vec<&std::path::Path> = a.parts.iter().map(|p| p.as_path()).collect();
    check_distinct(&given(&[Some(&a.output), a.png.as_ref()]), &inputs)?;
    let parts: Vec<Part> = a
        .parts
        .iter()
        .map(|p| merge::read_part(p))
        .collect::<Result<_, _>>()?;
    let whole = merge::merge(&parts, default_memory_limit())?;
    if a.png.is_some() && !whole.has_color() {
        anyhow::bail!(
            "{}: the parts have no R, G, B channels (hit-position parts?); drop --png",
            a.parts[0].display()
        );
    }
    // The EXR and the PNG appear together, or neither does.
    let held = snell::atomic::hold();
    whole
        .write_exr(&a.output)
        .with_context(|| a.output.display().to_string())?;
    if let Some(p) = &a.png {
        whole.write_png(p)?;
    }
    held.commit()?;
    eprintln!(
        "merged {} into {} ({}x{}, channels {})",
        snell::human::count(parts.len(), "part"),
        a.output.display(),
        whole.width,
        whole.height,
        whole
            .channels
            .iter()
            .map(|c| c.0.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(())
}
