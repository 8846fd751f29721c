//! Subcommands; each module turns parsed arguments into library calls.

mod bench;
mod classify;
mod common;
mod compare;
mod export_pov;
mod info;
mod merge;
mod phantom;
mod progress;
mod reference;
mod render;
mod resample;
mod sample;
mod scene;

use clap::{Parser, Subcommand};

#[derive(Parser, Debug)]
#[command(
    name = "snell",
    version,
    about = "Refraction through iso-surfaces of sampled volumes (Li & Mueller), fast and exact",
    long_about = "snell ray-traces light refracting through an iso-surface of a sampled 3-D volume \
(CT, MRI, phantoms) onto a planar backdrop. Reconstruction by trilinear, Catmull-Rom, \
interpolating B-splines (degree 2..7) or the smoothing cubic B-spline; exact crossings per cell; \
fixed-step ray casting, DDA, octree and distance-map traversal over classified cells; \
supersampling, PRSS and footprint filtering."
)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Describe a volume: dims, type, spacing, value range, histogram, iso-values to try.
    Info(info::Args),
    /// Write a scene file for a volume: camera and checkerboard framed from its extent, iso-value from its histogram.
    Scene(scene::Args),
    /// Evaluate the reconstructed field and its gradient at given points (CSV out; points and gradients in grid units).
    Sample(sample::Args),
    /// Write a synthetic volume (the glass sphere with holes, Marschner-Lobb) as NRRD or MetaImage.
    Phantom(phantom::Args),
    /// Sample a volume's reconstruction on a new lattice over the same domain (e.g. upsample a scan to 1024³), as NRRD or MetaImage.
    Resample(resample::Args),
    /// Render a scene file to PNG, with optional hit-position EXR, float EXR and stats.
    Render(render::Args),
    /// Join the EXR parts of a frame rendered piecewise (`render --region`) into one image.
    Merge(merge::Args),
    /// Trace a sphere-phantom scene through its exact analytic spheres (the accuracy reference).
    Reference(reference::Args),
    /// Compare two hit-position EXRs (hit-error percentiles, validity and event
    /// mismatches) or two colour images, PNG, JPEG or EXR (RMSE, PSNR, SSIM, a difference map).
    Compare(compare::Args),
    /// Count the cells each classification method tags (BMCC, ACCC, Bezier, exact).
    Classify(classify::Args),
    /// Write the scene for POV-Ray 3.7 (DF3 + isosurface .pov files), optionally render it.
    #[command(name = "export-pov")]
    ExportPov(export_pov::Args),
    /// Benchmark run time against error: a suite of configurations to tables, CSV, JSON and plots.
    Bench(bench::Args),
}

pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Info(a) => info::run(a),
        Command::Scene(a) => scene::run(a),
        Command::Sample(a) => sample::run(a),
        Command::Phantom(a) => phantom::run(a),
        Command::Resample(a) => resample::run(a),
        Command::Render(a) => render::run(a),
        Command::Merge(a) => merge::run(a),
        Command::Reference(a) => reference::run(a),
        Command::Compare(a) => compare::run(a),
        Command::Classify(a) => classify::run(a),
        Command::ExportPov(a) => export_pov::run(a),
        Command::Bench(a) => bench::run(a),
    }
}
