//! Scene files: TOML parsing, `--set` overrides and validation, then loading
//! the volume (files or phantoms, under a small memory limit) and, for small
//! volumes, a thumbnail render (at most 8×8 pixels, 2×2 samples, 64 events)
//! whose every pixel must be finite, with no ray ending undefined.
//!
//! Input: the scene text, then optionally a NUL byte and one `--set`
//! argument per line.
#![no_main]

use libfuzzer_sys::fuzz_target;
use snell::prepare::Prepared;
use snell::scene::Scene;
use snell_fuzz::options;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    // Only files the fuzzer wrote or the repository's data: no devices.
    if ["/dev", "/proc", "/sys", "stdin"]
        .iter()
        .any(|s| text.contains(s))
    {
        return;
    }
    let (scene_text, sets) = text.split_once('\0').unwrap_or((text, ""));
    let sets: Vec<String> = sets.lines().map(str::to_string).collect();
    // Relative paths resolve beside the repository's scenes (the file itself
    // is never read: the text comes from the input).
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/fuzz.toml");
    let Ok(mut scene) = Scene::parse(scene_text, &path, &sets) else {
        return;
    };
    let Ok(vol) = scene.load_volume(&options(false)) else {
        return;
    };
    if vol.len() > 32 * 32 * 32 {
        return;
    }
    scene.width = scene.width.min(8);
    scene.height = scene.height.min(8);
    scene.camera.width = scene.width;
    scene.camera.height = scene.height;
    scene.render.samples = scene.render.samples.min(2);
    scene.render.max_events = scene.render.max_events.min(64);
    let prep = Prepared::new(std::sync::Arc::new(vol), scene.surface.filter);
    let frame = snell::render::render(&scene, &prep, None);
    assert!(
        frame
            .film
            .color
            .iter()
            .all(|c| c.iter().all(|v| v.is_finite())),
        "non-finite pixel"
    );
    assert_eq!(frame.stats.counters.undefined, 0, "rays ended undefined");
});
