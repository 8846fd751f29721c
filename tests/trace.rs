//! `snell render --trace`: the timeline is valid Chrome trace-event JSON with
//! one event per tile on its worker's track, the tile's stage calls nested
//! inside it, the preparation and film on the frame track, and stage totals
//! equal to the stats' per-stage profile (the same measurements).

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;

use serde_json::Value;

use common::{Tmp, bin, root};

fn render(dir: &std::path::Path, set: &[&str]) -> (Value, Value) {
    let (trace, stats) = (dir.join("trace.json"), dir.join("stats.json"));
    let mut cmd = bin();
    cmd.current_dir(root())
        .args(["render", "scenes/sphere.toml", "-q", "--threads", "2", "-o"])
        .arg(dir.join("out.png"))
        .arg("--trace")
        .arg(&trace)
        .arg("--stats")
        .arg(&stats);
    for s in set {
        cmd.args(["--set", s]);
    }
    let o = cmd.output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let read = |p: &PathBuf| -> Value {
        serde_json::from_slice(&std::fs::read(p).unwrap()).expect("valid JSON")
    };
    (read(&trace), read(&stats))
}

fn f(e: &Value, k: &str) -> f64 {
    e[k].as_f64()
        .unwrap_or_else(|| panic!("{k} is not a number in {e}"))
}

#[test]
fn trace_has_every_tile_and_its_stages() {
    let tmp = Tmp::new("tiles");
    // 40×24 pixels in 16-pixel tiles: 3 × 2 tiles, the last column and row partial.
    let (trace, stats) = render(
        &tmp.0,
        &[
            "image.width=40",
            "image.height=24",
            "render.tile=16",
            "render.traversal=octree",
        ],
    );
    assert_eq!(trace["displayTimeUnit"], "ms");
    let events = trace["traceEvents"].as_array().expect("traceEvents array");
    for e in events {
        let ph = e["ph"].as_str().expect("ph");
        assert!(ph == "X" || ph == "M", "{e}");
        assert!(e["name"].is_string() && e["pid"].is_u64(), "{e}");
        if ph == "X" {
            assert!(e["tid"].is_u64(), "{e}");
            assert!(f(e, "ts") >= 0.0 && f(e, "dur") >= 0.0, "{e}");
        }
    }
    let cat = |c: &str| -> Vec<&Value> { events.iter().filter(|e| e["cat"] == c).collect() };

    // One event per tile, named by its corner, with its pixel count.
    let tiles = cat("tile");
    let names: BTreeSet<&str> = tiles.iter().map(|e| e["name"].as_str().unwrap()).collect();
    let expected: BTreeSet<&str> = [
        "tile 0,0",
        "tile 16,0",
        "tile 32,0",
        "tile 0,16",
        "tile 16,16",
        "tile 32,16",
    ]
    .into();
    assert_eq!(names, expected);
    assert_eq!(tiles.len(), 6);
    let pixels: u64 = tiles
        .iter()
        .map(|e| e["args"]["pixels"].as_u64().unwrap())
        .sum();
    assert_eq!(pixels, 40 * 24);
    let rays: u64 = tiles
        .iter()
        .map(|e| e["args"]["rays"].as_u64().unwrap())
        .sum();
    assert_eq!(rays, stats["counters"]["rays"].as_u64().unwrap());

    // Tiles run on worker tracks (at most 2 with --threads 2), each named.
    let workers: BTreeSet<u64> = tiles.iter().map(|e| e["tid"].as_u64().unwrap()).collect();
    assert!(!workers.is_empty() && workers.len() <= 2, "{workers:?}");
    for w in &workers {
        assert!(
            events.iter().any(|e| e["ph"] == "M"
                && e["name"] == "thread_name"
                && e["tid"].as_u64() == Some(*w)
                && e["args"]["name"].as_str().unwrap().starts_with("worker")),
            "worker track {w} has no name"
        );
    }

    // Every stage call lies inside a tile on the same track, and every tile
    // has generate, entry and record.
    let stages = cat("stage");
    let eps = 1e-3; // µs, the format's rounding
    let mut per_tile: BTreeMap<&str, BTreeSet<&str>> = BTreeMap::new();
    let mut totals: BTreeMap<&str, f64> = BTreeMap::new();
    for s in &stages {
        let (ts, end) = (f(s, "ts"), f(s, "ts") + f(s, "dur"));
        let parent = tiles
            .iter()
            .find(|t| {
                t["tid"] == s["tid"]
                    && f(t, "ts") <= ts + eps
                    && end <= f(t, "ts") + f(t, "dur") + eps
            })
            .unwrap_or_else(|| panic!("stage {s} is in no tile"));
        let name = s["name"].as_str().unwrap();
        per_tile
            .entry(parent["name"].as_str().unwrap())
            .or_default()
            .insert(name);
        *totals.entry(name).or_default() += f(s, "dur");
    }
    for t in &expected {
        let s = &per_tile[t];
        for stage in ["generate", "entry", "record"] {
            assert!(s.contains(stage), "{t}: no {stage} in {s:?}");
        }
    }
    // The trace and the stats profile are the same measurements.
    for (stage, us) in totals {
        let s = f(&stats["stage_cpu_s"], stage) * 1e6;
        assert!(
            (us - s).abs() <= 1e-3 * s.max(1.0),
            "{stage}: trace {us} µs, stats {s} µs"
        );
    }

    // The frame track: the preparation with its parts, the tile loop, the film.
    let prepare = cat("prepare");
    let parts: BTreeSet<&str> = prepare
        .iter()
        .map(|e| e["name"].as_str().unwrap())
        .collect();
    for p in ["prepare", "load", "prefilter", "classify", "octree"] {
        assert!(parts.contains(p), "no {p} in {parts:?}");
    }
    let frame: BTreeSet<&str> = cat("render")
        .iter()
        .map(|e| e["name"].as_str().unwrap())
        .collect();
    assert!(
        frame.contains("tiles") && frame.contains("film"),
        "{frame:?}"
    );
}

#[test]
fn trace_records_the_prss_stage_and_re_traced_pixels() {
    let tmp = Tmp::new("prss");
    let (trace, stats) = render(
        &tmp.0,
        &[
            "image.width=48",
            "image.height=48",
            "render.traversal=octree",
            "render.supersampling=prss",
            "render.prss_fallback=trace",
        ],
    );
    let events = trace["traceEvents"].as_array().unwrap();
    let named = |n: &str| events.iter().filter(|e| e["name"] == n).count();
    assert_eq!(named("prss"), 1);
    let retraced = stats["retraced_pixels"].as_u64().unwrap();
    let retrace_tiles = events
        .iter()
        .filter(|e| e["cat"] == "tile" && e["args"]["pass"] == "re-trace")
        .count();
    assert_eq!(
        retrace_tiles > 0,
        retraced > 0,
        "{retraced} pixels re-traced"
    );
    assert_eq!(named("re-trace"), usize::from(retraced > 0));
}
