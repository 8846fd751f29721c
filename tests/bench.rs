//! `snell bench` end to end through the real binary: the hidden `smoke`
//! suite (a 64×64 sphere in three configurations) writes every promised
//! output with the promised fields, updates a markdown section in place, and
//! bad input fails with one error line and exit code 2.

mod common;

use std::process::Output;

use common::{Tmp, ok, stderr};

fn number(v: &serde_json::Value, path: &str) -> f64 {
    let mut cur = v;
    for k in path.split('.') {
        cur = &cur[k];
    }
    cur.as_f64()
        .unwrap_or_else(|| panic!("{path} is not a number: {cur}"))
}

#[test]
fn smoke_suite_writes_every_output() {
    let tmp = Tmp::new("smoke");
    let out = tmp.path("out");
    let md = tmp.path("BENCHMARKS.md");
    let intro = "# Benchmarks\n\nHand-written intro.\n\n<!-- bench:smoke:begin -->\nstale\n<!-- bench:smoke:end -->\n\nHand-written outro.\n";
    std::fs::write(&md, intro).unwrap();
    ok(tmp.run_in_repo(
        "bench --suite smoke --out {tmp}/out --repeats 2 --threads 2 --update {tmp}/BENCHMARKS.md",
    ));

    for f in [
        "results.json",
        "results.csv",
        "tables.md",
        "time_vs_error.png",
        "time_vs_error.svg",
        "stages.png",
        "stages.svg",
    ] {
        let len = std::fs::metadata(out.join(f))
            .unwrap_or_else(|e| panic!("{f}: {e}"))
            .len();
        assert!(len > 0, "{f} is empty");
    }
    assert!(
        std::fs::read(out.join("time_vs_error.png"))
            .unwrap()
            .starts_with(b"\x89PNG")
    );

    let j: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("results.json")).unwrap()).unwrap();
    assert_eq!(j["suite"], "smoke");
    // Machine and run provenance.
    assert!(number(&j, "machine.nproc") >= 1.0);
    assert!(j["machine"].get("cpu_model").is_some());
    assert_eq!(j["machine"]["snell_version"], env!("CARGO_PKG_VERSION"));
    let command = j["run"]["command"].as_str().unwrap();
    assert!(command.contains("bench --suite smoke"), "{command}");
    assert!(j["run"]["date"].as_str().unwrap().ends_with('Z'));
    assert_eq!(number(&j, "run.threads"), 2.0);
    assert_eq!(number(&j, "run.repeats"), 2.0);

    let configs = j["configurations"].as_array().unwrap();
    assert_eq!(configs.len(), 3, "three distinct configurations");
    for c in configs {
        let name = c["name"].as_str().unwrap();
        let (median, min, max) = (
            number(c, "wall_ms.median"),
            number(c, "wall_ms.min"),
            number(c, "wall_ms.max"),
        );
        assert!(min > 0.0 && min <= median && median <= max, "{name}");
        assert_eq!(
            c["wall_ms"]["all"].as_array().unwrap().len() as f64,
            number(c, "runs")
        );
        for stage in [
            "generate", "entry", "traverse", "solve", "refract", "record", "prss", "film",
        ] {
            assert!(
                number(c, &format!("stage_cpu_ms.{stage}")) >= 0.0,
                "{name}: {stage}"
            );
        }
        assert!(number(c, "rays_per_s") > 0.0, "{name}");
        for k in [
            "cells_visited",
            "cells_solved",
            "solved_with_crossing",
            "kernel_evals",
            "brent_iters",
        ] {
            assert!(number(c, &format!("per_ray.{k}")) >= 0.0, "{name}: {k}");
        }
        assert_eq!(c["error"]["reference"], "analytic", "{name}");
        assert_eq!(c["error"]["unit"], "squares", "{name}");
        let (p50, p90, p99) = (
            number(c, "error.p50"),
            number(c, "error.p90"),
            number(c, "error.p99"),
        );
        assert!(0.0 <= p50 && p50 <= p90 && p90 <= p99, "{name}");
        assert!(number(c, "error.events_equal") > 0.9, "{name}");
        if cfg!(target_os = "linux") {
            assert!(number(c, "peak_rss_mib") > 0.0, "{name}");
        }
        // Enough to render the row again: every [render] setting, the
        // coefficient storage, the instruction set, the frame's identity.
        assert!(number(c, "render.max_events") >= 1.0, "{name}");
        assert!(c["render"]["prss_samples"].is_u64(), "{name}");
        assert_eq!(c["settings"]["coefficients"], "f64", "{name}");
        assert!(c["isa"].as_str().is_some_and(|s| !s.is_empty()), "{name}");
        assert!(
            c["frame_id"].as_str().is_some_and(|s| s.len() >= 16),
            "{name}"
        );
    }
    // Rows of other settings are other frames.
    assert_ne!(configs[0]["frame_id"], configs[1]["frame_id"]);
    // Anti-aliasing rows carry image quality against the 16×16 render;
    // the shared octree row got it for the anti-aliasing table.
    let prss = configs
        .iter()
        .find(|c| c["settings"]["supersampling"] == "prss")
        .unwrap();
    assert!(number(prss, "quality.psnr") > 10.0);
    assert!(number(prss, "quality.ssim") > 0.5);
    let step = configs
        .iter()
        .find(|c| c["settings"]["traversal"] == "step")
        .unwrap();
    assert!(step["quality"].is_null(), "no anti-aliasing, no quality");
    assert_eq!(number(step, "runs"), 1.0, "step is capped at one timed run");

    // Tables: speedups vs step, classification counts.
    let tables = j["tables"].as_array().unwrap();
    let trav = &tables[0];
    assert_eq!(trav["kind"], "render");
    let rows = trav["rows"].as_array().unwrap();
    assert_eq!(rows[0]["vs_baseline"].as_f64(), Some(1.0));
    assert!(
        rows[1]["vs_baseline"].as_f64().unwrap() > 1.0,
        "octree beats step"
    );
    let classify = tables.iter().find(|t| t["kind"] == "classify").unwrap();
    let counts = &classify["rows"][0]["methods"];
    assert_eq!(counts[0]["method"], "bmcc");
    assert!(counts[1]["tagged"].as_u64().unwrap() <= counts[0]["tagged"].as_u64().unwrap());
    assert!(!j["builds"].as_array().unwrap().is_empty());

    // CSV: a header and one row per configuration.
    let csv = std::fs::read_to_string(out.join("results.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + configs.len());
    assert!(csv.starts_with("id,scene,name,"));

    // tables.md and the updated section, with the hand-written text kept.
    let tables_md = std::fs::read_to_string(out.join("tables.md")).unwrap();
    assert!(
        tables_md.contains("| configuration | median ms |"),
        "{tables_md}"
    );
    let updated = std::fs::read_to_string(&md).unwrap();
    assert!(updated.starts_with(
        "# Benchmarks\n\nHand-written intro.\n\n<!-- bench:smoke:begin -->\nGenerated by `"
    ));
    assert!(updated.ends_with("<!-- bench:smoke:end -->\n\nHand-written outro.\n"));
    assert!(!updated.contains("stale"));
    assert!(updated.contains("| step 0.1 |"));
}

/// Exit 2 and one `error:` line containing `needle`, no panic.
fn assert_fails(o: &Output, needle: &str) {
    let e = stderr(o);
    assert_eq!(o.status.code(), Some(2), "stderr: {e}");
    assert!(!e.contains("panicked"), "{e}");
    let errors: Vec<&str> = e.lines().filter(|l| l.starts_with("error")).collect();
    assert_eq!(errors.len(), 1, "{e}");
    assert!(
        errors[0].contains(needle),
        "'{needle}' not in {}",
        errors[0]
    );
}

#[test]
fn bad_input_fails_fast_with_one_line() {
    let tmp = Tmp::new("bad");
    let out = tmp.path("out");
    let bench = |line: &str| tmp.run_in_repo(line);
    assert_fails(
        &bench("bench --suite nope --out {tmp}/out"),
        "unknown suite 'nope'",
    );
    // Output below a regular file cannot be created.
    let file = tmp.write("file", b"x");
    assert_fails(
        &bench("bench --suite smoke --out {tmp}/file/out"),
        file.to_str().unwrap(),
    );
    assert_fails(
        &bench("bench --suite smoke --out {tmp}/file"),
        "not a directory",
    );
    assert_fails(
        &bench("bench --suite smoke --out {tmp}/out --repeats 0"),
        "--repeats",
    );
    assert_fails(
        &bench("bench --suite smoke --out {tmp}/out --threads 0"),
        "--threads",
    );
    // Without its scene files nothing is made, not even the output folder.
    assert_fails(
        &bench("bench --suite smoke --out {tmp}/fresh-out --scenes {tmp}"),
        "sphere.toml",
    );
    assert!(!tmp.path("fresh-out").exists(), "fresh-out was created");
    // Malformed markers are refused before any rendering.
    let md = tmp.path("B.md");
    std::fs::write(
        &md,
        "<!-- bench:smoke:end -->\n<!-- bench:smoke:begin -->\n",
    )
    .unwrap();
    assert_fails(
        &bench("bench --suite smoke --out {tmp}/out --update {tmp}/B.md"),
        "B.md",
    );
    assert!(!out.join("results.json").exists(), "nothing was run");
}

/// `snell bench --peer povray` at 64×64 with one timed run: `peer.json` holds
/// every row (snell and POV-Ray, times and errors against the analytic
/// spheres) and the speed ratios, and the `bench:peer` section is written in
/// place. Without POV-Ray on PATH the comparison is skipped with a message
/// naming the package, exit 0 and nothing written.
#[test]
fn peer_comparison() {
    let tmp = Tmp::new("peer");
    let out = tmp.path("out");
    let md = tmp.path("BENCHMARKS.md");
    let intro = "# B\n\n<!-- bench:peer:begin -->\nstale\n<!-- bench:peer:end -->\n\ntail\n";
    std::fs::write(&md, intro).unwrap();
    let line = "bench --peer povray --peer-size 64 --repeats 1 --out {tmp}/out \
                --update {tmp}/BENCHMARKS.md";

    // No povray on PATH: skipped, not failed.
    let o = ok(tmp
        .cmd_in_repo(line)
        .env("PATH", "/nonexistent")
        .output()
        .unwrap());
    assert!(
        stderr(&o).contains("skipping the povray comparison")
            && stderr(&o).contains("apt-get install povray"),
        "{}",
        stderr(&o)
    );
    assert!(!out.join("peer.json").exists());
    assert_eq!(std::fs::read_to_string(&md).unwrap(), intro);
    assert_fails(
        &tmp.run_in_repo("bench --peer blender --out {tmp}/out"),
        "unknown peer 'blender'",
    );

    if !snell::peer::installed() {
        assert!(
            snell::env::setting("SNELL_REQUIRE_POVRAY").is_none(),
            "povray is not found, and SNELL_REQUIRE_POVRAY asks for it"
        );
        eprintln!("skipping the POV-Ray run: povray is not installed (apt-get install povray)");
        return;
    }
    ok(tmp.run_in_repo(line));
    let j: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("peer.json")).unwrap()).unwrap();
    assert_eq!(j["peer"], "povray");
    assert!(j["peer_version"].as_str().unwrap().starts_with("POV-Ray"));
    assert_eq!(number(&j, "run.width"), 64.0);
    assert_eq!(number(&j, "run.threads"), 2.0);
    let rows = j["rows"].as_array().unwrap();
    let count = |r: &str| rows.iter().filter(|x| x["renderer"] == r).count();
    assert_eq!((count("snell"), count("povray")), (7, 4));
    let labels: Vec<&str> = rows.iter().map(|r| r["label"].as_str().unwrap()).collect();
    assert!(
        labels.contains(&"octree+bezier bspline2") && labels.contains(&"distance+bezier bspline2"),
        "{labels:?}"
    );
    for r in rows {
        let label = r["label"].as_str().unwrap();
        for k in ["render_ms.median", "frame_ms.median", "process_ms.median"] {
            assert!(number(r, k) > 0.0, "{label}: {k}");
        }
        assert!(number(r, "frame_ms.median") >= number(r, "render_ms.median"));
        let (p50, p90) = (number(r, "error.p50"), number(r, "error.p90"));
        assert!(0.0 < p50 && p50 <= p90, "{label}");
        // Every row is measured on the same refracted pixels (less those
        // that miss the backdrop in one image), and each
        // renderer is close to the analytic spheres (a mapping slip would
        // be many squares off).
        let (n, n0) = (
            number(r, "error.refracted_pixels"),
            number(&rows[0], "error.refracted_pixels"),
        );
        assert!((n - n0).abs() <= 0.02 * n0, "{label}: {n} vs {n0} pixels");
        assert!(p50 < 0.5, "{label}: p50 {p50}");
        if r["renderer"] == "povray" {
            assert!(r["max_gradient_found"].is_null(), "{label}: holes");
        }
    }
    let ratios = j["ratios"].as_array().unwrap();
    assert_eq!(ratios.len(), 7);
    assert!(ratios.iter().all(|x| number(x, "frame") > 0.0));
    // POV-Ray and snell's identical interpolant give the same surface.
    for x in j["same_interpolant"].as_array().unwrap() {
        assert!(number(x, "error.p50") < 0.05, "{x}");
    }
    let updated = std::fs::read_to_string(&md).unwrap();
    assert!(updated.starts_with("# B\n\n<!-- bench:peer:begin -->\nGenerated by `"));
    assert!(updated.ends_with("<!-- bench:peer:end -->\n\ntail\n"));
    assert!(
        updated.contains("| POV-Ray | tricubic accuracy 1e-3 |"),
        "{updated}"
    );
    assert!(updated.contains("× faster, frame"), "{updated}");
    assert!(out.join("peer.md").is_file());
}

/// `snell bench --targets` at a small size: every target gets a row with a
/// measured value, no verdict (not at the targets' size), the same section in
/// `targets.md` and the updated markdown file, whose text outside the
/// markers is kept.
#[test]
fn targets_report_every_target() {
    let t = Tmp::new("targets");
    let md = t.path("B.md");
    std::fs::write(&md, "# mine\n\nkept\n").unwrap();
    let out = t.path("out");
    ok(t.run_in_repo(
        "bench --targets --targets-size 24 --prefilter-size 24 --rounds 2 --frames 1 \
         --targets-skip-peer --out {tmp}/out --update {tmp}/B.md",
    ));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("targets.json")).unwrap()).unwrap();
    let rows = v["rows"].as_array().unwrap();
    let names: Vec<&str> = rows.iter().map(|r| r["target"].as_str().unwrap()).collect();
    for want in [
        "sphere frame",
        "teapot frame",
        "cranium frame",
        "sphere: octree",
        "cranium: octree",
        "lobster: octree",
        "teapot: octree",
        "prefilter",
    ] {
        assert!(
            names.iter().any(|n| n.starts_with(want)),
            "{want} missing from {names:?}"
        );
    }
    assert_eq!(rows.len(), 13, "{names:?}");
    // Each dataset's ratio with the default classification and with issue
    // 4's ACCC (per 8³ sub-cells).
    for set in ["sphere", "cranium", "lobster", "teapot"] {
        for method in ["bezier", "accc8"] {
            assert!(
                rows.iter().any(|r| {
                    r["target"]
                        .as_str()
                        .unwrap()
                        .starts_with(&format!("{set}: "))
                        && r["configuration"]
                            .as_str()
                            .unwrap()
                            .contains(&format!("octree+{method} "))
                }),
                "{set} with {method} missing from {names:?}"
            );
        }
    }
    // Issue 7's frames are stated for bspline3 on every scene, the CT
    // scenes included (their scene files use the smoothing spline).
    let frames: Vec<_> = rows
        .iter()
        .filter(|r| r["issue"] == 7 && r["unit"] == "ms")
        .collect();
    assert_eq!(frames.len(), 4, "{names:?}");
    for r in frames {
        let c = r["configuration"].as_str().unwrap();
        assert!(c.starts_with("bspline3, "), "{r}");
    }
    for r in rows {
        let value = r["value"].as_f64().unwrap();
        let rounds: Vec<f64> = r["rounds"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(rounds.len(), 2, "{r}");
        // The value is the median of its rounds (of two: their mean).
        assert!(
            (value - 0.5 * (rounds[0] + rounds[1])).abs() <= 1e-9 * value,
            "{r}"
        );
        assert!(value > 0.0 && value.is_finite(), "{r}");
        assert!(r["met"].is_null(), "a verdict at 24×24: {r}");
        // Even this small, the octree beats stepping at 0.1.
        if r["issue"] == 4 {
            assert!(rounds.iter().all(|&x| x > 1.0), "{r}");
        }
    }
    // The octree and step 0.1 find the same crossings on every dataset.
    for r in rows.iter().filter(|r| r["issue"] == 4) {
        let d = r["detail"].as_str().unwrap();
        let per_ray: Vec<f64> = d
            .split("events per ray (round 1) ")
            .nth(1)
            .unwrap()
            .split(", ")
            .map(|x| x.split(' ').next().unwrap().parse().unwrap())
            .collect();
        assert!((per_ray[0] - per_ray[1]).abs() < 0.05, "{d}");
    }
    assert!(v["skipped"][0].as_str().unwrap().contains("POV-Ray"));
    let section = std::fs::read_to_string(out.join("targets.md")).unwrap();
    assert_eq!(section.matches("\n| ").count(), rows.len() + 1, "{section}");
    let doc = std::fs::read_to_string(&md).unwrap();
    assert!(doc.starts_with("# mine\n\nkept\n"), "{doc}");
    assert!(doc.contains("<!-- bench:targets:begin -->") && doc.contains(section.trim()));
    for bad in ["--rounds", "--frames"] {
        let o = t.run_in_repo(&format!("bench --targets {bad} 0 --out {{tmp}}/out"));
        assert_fails(&o, "--rounds and --frames must be at least 1");
    }
    let o = t.run_in_repo("bench --targets --targets-size 0 --out {tmp}/out");
    assert_fails(&o, "--targets-size and --prefilter-size must be at least 1");
}
