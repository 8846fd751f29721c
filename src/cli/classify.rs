//! `snell classify`: how many cells each classification method tags, how that
//! compares with the paper's Table 3 (ACCC/BMCC), and how far each is from
//! the proven crossings.

use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::Context;
use clap::Args as ClapArgs;

use snell::classify::{self, Method};
use snell::filter::Field;
use snell::lattice::Lattice;

use super::common::VolumeArgs;
use super::progress::{self, Count, Step};

#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Volume file.
    pub volume: PathBuf,
    /// Reconstruction filter: linear, catmull-rom, bspline2..bspline7, smooth-bspline3.
    #[arg(long)]
    pub filter: String,
    /// Smoothing weight λ of smooth-bspline3, 0 to 1e12 (required by it, refused by the other filters).
    #[arg(long, allow_negative_numbers = true, value_name = "L")]
    pub lambda: Option<f64>,
    /// Iso-value (in the volume's units).
    #[arg(long, allow_negative_numbers = true)]
    pub iso: f64,
    /// Methods to run, comma-separated (default: all but bezier1 and
    /// bezier3): bmcc (binary morphology), accc (the paper's weight-extreme
    /// bound), accc2/accc4/accc8 (ACCC per 2³/4³/8³ sub-cells), bezier0
    /// (the cell's Bézier hull, no subdivision), bezier = bezier2 (the hull
    /// refined by 2 levels of de Casteljau subdivision; renders use it),
    /// bezier1, bezier3, exact (proven crossings only: the lower bound the
    /// others are measured against).
    #[arg(long, value_delimiter = ',', value_name = "M1,M2,...")]
    pub methods: Vec<String>,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub vol: VolumeArgs,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let kind = super::common::filter_kind(&a.filter, a.lambda)?;
    anyhow::ensure!(a.iso.is_finite(), "--iso must be finite");
    let methods: Vec<Method> = if a.methods.is_empty() {
        Method::all().to_vec()
    } else {
        a.methods
            .iter()
            .map(|m| {
                Method::parse(m).with_context(|| {
                    format!(
                        "--methods: unknown method '{m}' (expected {})",
                        Method::NAMES
                    )
                })
            })
            .collect::<anyhow::Result<_>>()?
    };
    let reading = Step::named(format!("reading {}", a.volume.display()));
    let vol = progress::watch(&reading, false, || a.vol.load(&a.volume))?;
    let (lo, hi) = vol.value_range();
    if !(a.iso >= lo && a.iso <= hi) {
        eprintln!(
            "warning: {}: iso-value {} is outside the data range [{}, {}]; few or no cells hold the surface",
            a.volume.display(),
            snell::human::exact(a.iso),
            snell::human::num(lo),
            snell::human::num(hi)
        );
    }
    let start = std::time::Instant::now();
    let field = progress::watch(&Step::named("prefiltering"), false, || {
        Field::new(&vol, kind)
    });
    let prefilter_s = start.elapsed().as_secs_f64();
    let lattice = Lattice::new(field.kernel(), field.dims());
    let iso = field.separating_iso(a.iso);
    let done = AtomicUsize::new(0);
    let classifying = Step {
        what: "classifying".into(),
        count: Some(Count {
            done: &done,
            total: methods.len(),
            unit: "methods",
        }),
    };
    let results: Vec<classify::Classification> = progress::watch(&classifying, false, || {
        methods
            .iter()
            .map(|&m| {
                let r = classify::classify(&field, iso, m);
                done.fetch_add(1, Ordering::Relaxed);
                r
            })
            .collect()
    });
    let count = |m: Method| {
        results
            .iter()
            .find(|r| r.method == m)
            .map(|r| r.tags.count())
    };
    let exact = results.iter().find(|r| r.method == Method::Exact);
    let bmcc = count(Method::Bmcc);
    let total = lattice.cell_count();
    let rows: Vec<serde_json::Value> = results
        .iter()
        .map(|r| {
            let n = r.tags.count();
            serde_json::json!({
                "method": r.method.name(),
                "tagged": n,
                "fraction": n as f64 / total.max(1) as f64,
                // None where BMCC tags nothing: 0/0 is no ratio.
                "ratio_to_bmcc": bmcc.filter(|&b| b > 0).map(|b| n as f64 / b as f64),
                "excess_over_exact": exact.map(|e| r.tags.excess_over(&e.tags)),
                "contains_exact": exact.map(|e| e.tags.is_subset_of(&r.tags)),
                "classify_s": r.seconds,
            })
        })
        .collect();
    if a.json {
        let j = serde_json::json!({
            "volume": a.volume.display().to_string(),
            "filter": kind.to_string(),
            "iso": a.iso,
            "cells": total,
            "lattice": lattice.cells,
            "prefilter_s": prefilter_s,
            "methods": rows,
            "accc_over_bmcc": match (count(Method::Accc), bmcc) { (Some(x), Some(b)) if b > 0 => Some(x as f64 / b as f64), _ => None },
        });
        println!("{j}");
        return Ok(());
    }
    println!(
        "{} — {} at iso {} — {} knot cells ({}x{}x{}), prefilter {:.1} ms",
        a.volume.display(),
        kind,
        snell::human::exact(a.iso),
        total,
        lattice.cells[0],
        lattice.cells[1],
        lattice.cells[2],
        prefilter_s * 1e3
    );
    println!(
        "{:10} {:>12} {:>9} {:>9} {:>14} {:>10}",
        "method", "tagged", "of cells", "vs bmcc", "over exact", "time ms"
    );
    for (r, j) in results.iter().zip(&rows) {
        let fmt_opt = |v: &serde_json::Value, pct: bool| match v.as_f64() {
            Some(x) if pct => format!("{:.1}%", 100.0 * x),
            Some(x) => format!("{x}"),
            None => "-".into(),
        };
        println!(
            "{:10} {:>12} {:>9} {:>9} {:>14} {:>10.1}",
            r.method.name(),
            r.tags.count(),
            fmt_opt(&j["fraction"], true),
            fmt_opt(&j["ratio_to_bmcc"], true),
            fmt_opt(&j["excess_over_exact"], false),
            r.seconds * 1e3
        );
    }
    if let Some(e) = exact {
        let all_contain = results.iter().all(|r| e.tags.is_subset_of(&r.tags));
        println!(
            "exact ⊆ every method: {}",
            if all_contain { "yes" } else { "NO" }
        );
    }
    Ok(())
}
