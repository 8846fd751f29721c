//! Steady-state frame time of one scene: prepares once (structures cached, as
//! in an interactive session), renders a warm-up frame, then `--frames N`
//! timed frames, and prints the median and spread with the per-stage CPU
//! profile of the median frame.
//!
//! ```sh
//! cargo bench --bench frame -- scenes/sphere.toml --set render.traversal=octree \
//!     --set render.supersampling=prss --frames 20
//! ```
//!
//! `--prepares N` also times `N` preparations from scratch (as a one-shot
//! `snell render` does them) and prints the median of each step.

use std::path::PathBuf;
use std::time::Instant;

use snell::render::{self, Prepared};
use snell::scene::Scene;
use snell::volume::LoadOptions;

fn main() {
    // As an interactive session would: frames reuse the last one's memory.
    snell::heap::retain_freed_memory();
    let mut scene_path = PathBuf::from("scenes/sphere.toml");
    let mut sets = Vec::new();
    let mut frames = 10usize;
    let mut prepares = 0usize;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--set" => sets.push(
                args.next()
                    .unwrap_or_else(|| usage("--set needs KEY=VALUE")),
            ),
            "--frames" => frames = count(args.next(), "--frames"),
            "--prepares" => prepares = count(args.next(), "--prepares"),
            "--bench" => {}
            s if s.ends_with(".toml") => scene_path = PathBuf::from(s),
            other => usage(&format!("unknown argument {other}")),
        }
    }
    let scene = Scene::load(&scene_path, &sets).unwrap_or_else(|e| fail(&e));
    if prepares > 0 {
        time_preparations(&scene, prepares);
    }
    let t = Instant::now();
    let prep = Prepared::for_scene(&scene, &LoadOptions::default()).unwrap_or_else(|e| fail(&e));
    let first = render::render(&scene, &prep, None);
    println!(
        "{}: prepare + first frame {:.1} ms ({} threads, {})",
        scene_path.display(),
        t.elapsed().as_secs_f64() * 1e3,
        rayon::current_num_threads(),
        snell::bench::machine::cpu_model().unwrap_or_else(|| "unknown CPU".into())
    );
    drop(first);
    let mut runs: Vec<(f64, render::RenderStats)> = (0..frames.max(1))
        .map(|_| {
            let t = Instant::now();
            let f = render::render(&scene, &prep, None);
            (t.elapsed().as_secs_f64() * 1e3, f.stats)
        })
        .collect();
    runs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let median = &runs[runs.len() / 2];
    println!(
        "frame: median {:.2} ms, min {:.2}, max {:.2} over {} frames",
        median.0,
        runs[0].0,
        runs[runs.len() - 1].0,
        runs.len()
    );
    println!("{}", median.1.table());
}

/// `--frames N` or `--prepares N`'s count, or the usage.
fn count(value: Option<String>, flag: &str) -> usize {
    value
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| usage(&format!("{flag} needs a count")))
}

/// Prints `problem` and how to call the bench, and exits with status 2.
fn usage(problem: &str) -> ! {
    eprintln!(
        "frame: {problem}\nusage: cargo bench --bench frame -- [SCENE.toml] [--set KEY=VALUE]... \
         [--frames N] [--prepares N]"
    );
    std::process::exit(2)
}

/// Prints an error loading or preparing the scene and exits with status 1.
fn fail(e: &dyn std::fmt::Display) -> ! {
    eprintln!("frame: {e}");
    std::process::exit(1)
}

/// Prepares `scene` from scratch `n` times and prints the median of the
/// whole preparation and of each of its steps (ms).
fn time_preparations(scene: &Scene, n: usize) {
    let mut rows: Vec<[f64; 5]> = (0..n)
        .map(|_| {
            let t = Instant::now();
            let p =
                Prepared::for_scene(scene, &LoadOptions::default()).unwrap_or_else(|e| fail(&e));
            let wall = t.elapsed().as_secs_f64();
            let s = &p.times;
            [wall, s.load_s, s.prefilter_s, s.classify_s, s.octree_s].map(|v| v * 1e3)
        })
        .collect();
    let names = ["prepare", "load", "prefilter", "classify", "octree"];
    let medians: Vec<String> = (0..names.len())
        .map(|i| {
            rows.sort_by(|a, b| a[i].total_cmp(&b[i]));
            format!("{} {:.2}", names[i], rows[n / 2][i])
        })
        .collect();
    println!("preparation, median of {n} (ms): {}", medians.join(", "));
}
