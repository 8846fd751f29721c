//! `snell info`: what is in a volume, and which iso-values to try.

use std::path::PathBuf;

use clap::Args as ClapArgs;
use snell::human::{num_resolving, triple as num3};

use super::common::{VolumeArgs, shell_path};

#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Volume file (.nrrd, .nhdr, .nii, .nii.gz, .mha, .mhd, or raw with --dims/--type).
    pub volume: PathBuf,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub vol: VolumeArgs,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let vol = a.vol.load(&a.volume)?;
    let st = vol.stats();
    // Values to a thousandth of the range: a narrow range far from 0
    // (labels near 1234566) prints with the digits that tell it apart.
    let value = |x: f64| num_resolving(x, (st.max - st.min) / 1000.0);
    let d = vol.dims();
    let sp = vol.spacing();
    // The next step for a new dataset: a scene at the first iso-value worth
    // trying.
    let scene_command = st.suggested_iso.first().map(|&iso| {
        format!(
            "snell scene {}{} -o scene.toml --iso {}",
            shell_path(&a.volume.to_string_lossy()),
            a.vol.flags(),
            value(iso)
        )
    });
    if a.json {
        let j = serde_json::json!({
            "path": a.volume.display().to_string(),
            "dims": d,
            "type": vol.native_type().name(),
            "spacing": sp,
            "extent": vol.extent(),
            "min": st.min,
            "max": st.max,
            "mean": st.mean,
            "histogram": st.histogram,
            "suggested_iso": st.suggested_iso,
            "suggested_above": st.suggested_above,
            "iso_from_modes": st.iso_from_modes,
            "replaced_nonfinite": vol.replaced_nonfinite,
            "scene_command": scene_command,
        });
        println!("{j}");
        return Ok(());
    }
    println!("{}", a.volume.display());
    println!(
        "  dims     {} x {} x {}  ({} samples)",
        d[0],
        d[1],
        d[2],
        vol.len()
    );
    println!("  type     {}", vol.native_type());
    println!("  spacing  {}", num3(sp));
    println!("  extent   {} (world units)", num3(vol.extent()));
    println!(
        "  range    {} .. {}  (mean {})",
        value(st.min),
        value(st.max),
        value(st.mean)
    );
    if st.min == st.max {
        println!(
            "  every sample is {}: no iso-value has a surface in this volume",
            value(st.min)
        );
        return Ok(());
    }
    println!("  histogram (log scale):");
    let h = &st.histogram;
    let maxlog = h
        .counts
        .iter()
        .map(|&c| ((c + 1) as f64).ln())
        .fold(0.0, f64::max);
    for (i, chunk) in h.counts.chunks(4).enumerate() {
        let c: u64 = chunk.iter().sum();
        let lo = h.min + (i * 4) as f64 * h.bin_width();
        let bar = if maxlog > 0.0 {
            ((((c + 1) as f64).ln() / (maxlog + 4f64.ln())) * 50.0) as usize
        } else {
            0
        };
        println!("    {:>12} {:>10} {}", value(lo), c, "#".repeat(bar));
    }
    let iso: Vec<String> = st.suggested_iso.iter().map(|&v| value(v)).collect();
    if st.iso_from_modes {
        // Each with the share of samples above it: past a half, the surface
        // bounds voids in a bulk (listed last).
        let listed: Vec<String> = iso
            .iter()
            .zip(&st.suggested_above)
            .map(|(v, &share)| match 100.0 * share {
                p if p < 0.1 => format!("{v} (<0.1% of samples above)"),
                p => format!("{v} ({p:.1}% of samples above)"),
            })
            .collect();
        println!("  iso-values worth trying: {}", listed.join(", "));
    } else if !iso.is_empty() {
        println!(
            "  iso-values worth trying: {} (the value range's midpoint: the histogram shows no two materials apart)",
            iso.join(", ")
        );
    }
    if let Some(c) = scene_command {
        println!("  a scene for it: {c}");
    }
    Ok(())
}
