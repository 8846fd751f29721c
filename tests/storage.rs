//! Coefficient storage: `f32` fields render what `f64` fields render, within
//! the rounding of 4-byte coefficients.

use std::path::PathBuf;

use snell::prepare::Cache;
use snell::render;
use snell::scene::{Scene, Storage};
use snell::volume::LoadOptions;

#[test]
fn f32_storage_stays_within_its_rounding_of_f64() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes/sphere.toml");
    let frame = |storage: &str| {
        let o = [
            "image.width=128",
            "image.height=128",
            "render.traversal=octree",
        ]
        .map(String::from)
        .into_iter()
        .chain([format!("render.coefficients={storage}")])
        .collect::<Vec<_>>();
        let scene = Scene::load(&path, &o).unwrap();
        let prep = Cache::new()
            .prepare(&scene, &LoadOptions::default())
            .unwrap();
        assert_eq!(prep.field.storage().name(), storage);
        render::render(&scene, &prep, None)
    };
    let (a, b) = (frame("f64"), frame("f32"));
    assert_eq!(Storage::F32.name(), "f32");
    let (mut same_events, mut hits, mut diffs) = (0, 0, Vec::new());
    for i in 0..a.film.u.len() {
        if a.film.events[i] != b.film.events[i] {
            continue;
        }
        same_events += 1;
        if a.film.events[i] > 0.0 && a.film.u[i].is_finite() && b.film.u[i].is_finite() {
            hits += 1;
            let d = (a.film.u[i] - b.film.u[i])
                .abs()
                .max((a.film.v[i] - b.film.v[i]).abs());
            diffs.push(d as f64);
        }
    }
    diffs.sort_by(f64::total_cmp);
    let n = a.film.u.len();
    let q = |p: f64| diffs[((diffs.len() - 1) as f64 * p) as usize];
    eprintln!(
        "events equal {same_events}/{n}, refracted {hits}: p50 {:.2e} p90 {:.2e} max {:.2e}",
        q(0.5),
        q(0.9),
        q(1.0)
    );
    assert!(hits > 3000, "the sphere refracts: {hits}");
    assert!(same_events * 1000 >= n * 995, "{same_events} of {n}");
    // The storage really differs (the f32 field is not the f64 one) ...
    assert!(q(1.0) > 0.0, "f32 storage rendered the f64 bits");
    // ... by rounding only: backdrop units, checker squares of 8.
    assert!(
        q(0.5) < 1e-4 && q(0.9) < 1e-3,
        "p50 {} p90 {}",
        q(0.5),
        q(0.9)
    );
}
