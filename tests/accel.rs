//! Classification and the octree: conservative on phantoms and real data, and
//! invisible in the output (octree and distance renders are bitwise those of
//! cell-by-cell DDA with no precomputed classification, which skips only the
//! cells its on-the-fly coefficient bound clears).

mod common;

use std::path::PathBuf;
use std::sync::Arc;

use rayon::prelude::*;
use snell::classify::{self, Method};
use snell::filter::{Field, FilterKind};
use snell::lattice::{Lattice, cell_at};
use snell::phantom::{Hole, MarschnerLobbSpec, PhantomFormat, SphereSpec};
use snell::prepare::Prepared;
use snell::render;
use snell::scene::Scene;
use snell::volume::{self, LoadOptions, Volume};

fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(name)
}

fn real(name: &str) -> Volume {
    volume::load(&data(name), &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}"))
}

/// Every conservative method contains the cells that hold a crossing, and
/// the refinements nest within what they refine.
///
/// `exact` tags the cells whose crossing is proven (values on both sides at
/// sub-cell corners), a lower bound of the truth that every method must
/// contain. That alone would not see a wrong "empty" verdict of the Bézier
/// hull test, which `exact` and `bezier` share (a cell so judged is never
/// subdivided, so neither tags it): so every `every`-th cell that BMCC tags
/// and the hull rejects is sampled densely (6³ points of the closed cell),
/// and none may show values on both sides of the iso-value. (BMCC's own
/// soundness, and every method's against dense sampling of whole small
/// volumes, are the property tests' `classification_is_conservative`.)
fn check_conservative(
    what: &str,
    vol: &Volume,
    filter: &str,
    iso: f64,
    methods: &[Method],
    every: usize,
) {
    let field = Field::new(vol, FilterKind::parse(filter, 1.0).unwrap());
    let iso = field.separating_iso(iso);
    let tags = |m| classify::classify(&field, iso, m).tags;
    let exact = tags(Method::Exact);
    assert!(exact.count() > 0, "{what}: the surface exists");
    let mut counts = Vec::new();
    let mut by_method = Vec::new();
    for &m in methods {
        let t = tags(m);
        assert!(
            exact.is_subset_of(&t),
            "{what} {filter}: exact ⊄ {}",
            m.name()
        );
        counts.push((m.name(), t.count()));
        by_method.push((m, t));
    }
    // BMCC's and the hull's tags as the methods gave them, not classified again.
    let get = |m: Method| by_method.iter().find(|(n, _)| *n == m).map(|(_, t)| t);
    let (bmcc, hull) = (
        get(Method::Bmcc).expect("methods hold bmcc"),
        get(Method::Bezier(2)).expect("methods hold bezier"),
    );
    let lattice = Lattice::new(field.kernel(), field.dims());
    let rejected: Vec<usize> = bmcc
        .ones(0..bmcc.len())
        .filter(|&i| !hull.get_index(i))
        .step_by(every)
        .collect();
    let wrong: Vec<[i64; 3]> = rejected
        .par_iter()
        .map(|&i| cell_at(lattice.cells, i))
        .filter(|&c| common::straddles(&field, &lattice, c, iso))
        .collect();
    assert!(
        wrong.is_empty(),
        "{what} {filter}: the Bézier hull rejects cells whose points straddle the iso-value: {:?}",
        &wrong[..wrong.len().min(8)]
    );
    // Finer sub-cells bound over smaller spans, so they tag no more; and
    // with non-negative weights ACCC's bound is within BMCC's.
    let nested = [
        (Method::AcccSub(8), Method::AcccSub(4)),
        (Method::AcccSub(4), Method::AcccSub(2)),
        (Method::AcccSub(2), Method::Accc),
        (Method::Bezier(2), Method::Bezier(0)),
    ];
    let non_negative = filter != "catmull-rom";
    for (inner, outer) in nested
        .into_iter()
        .chain(non_negative.then_some((Method::Accc, Method::Bmcc)))
    {
        if let (Some(a), Some(b)) = (get(inner), get(outer)) {
            assert!(
                a.is_subset_of(b),
                "{what} {filter}: {} ⊄ {}",
                inner.name(),
                outer.name()
            );
        }
    }
    eprintln!(
        "{what} {filter}: exact {}, {} of BMCC's cells the hull rejects sampled densely | {counts:?}",
        exact.count(),
        rejected.len()
    );
}

#[test]
fn conservative_on_phantoms() {
    let all = [
        Method::Bmcc,
        Method::Accc,
        Method::AcccSub(2),
        Method::AcccSub(4),
        Method::AcccSub(8),
        Method::Bezier(0),
        Method::Bezier(2),
    ];
    let sphere = SphereSpec {
        format: PhantomFormat::U8,
        ..Default::default()
    }
    .build()
    .unwrap();
    let holes = SphereSpec {
        format: PhantomFormat::U8,
        holes: vec![
            Hole {
                center: [37.5, 37.5, 31.5],
                radius: 5.0,
                sigma: 1.5,
            },
            Hole {
                center: [25.5, 25.5, 31.5],
                radius: 5.0,
                sigma: 1.5,
            },
        ],
        ..Default::default()
    }
    .build()
    .unwrap();
    let ml = MarschnerLobbSpec::default().build().unwrap();
    for filter in [
        "linear",
        "catmull-rom",
        "bspline2",
        "bspline3",
        "bspline6",
        "smooth-bspline3",
    ] {
        check_conservative("sphere", &sphere, filter, 127.5, &all, 1);
        check_conservative("two holes", &holes, filter, 127.5, &all, 1);
        check_conservative("marschner-lobb", &ml, filter, 0.5, &all, 1);
    }
}

#[test]
fn conservative_on_real_volumes() {
    let quick = [
        Method::Bmcc,
        Method::Accc,
        Method::AcccSub(2),
        Method::Bezier(2),
    ];
    for (name, iso) in [
        ("tooth.nrrd", 120.0),
        ("lobster.nrrd", 35.0),
        ("cranium-ct.nrrd", 524.0),
    ] {
        let vol = real(name);
        for filter in ["bspline3", "catmull-rom"] {
            check_conservative(name, &vol, filter, iso, &quick, 16);
        }
    }
}

fn hits_agree(scene: &Scene, vol: Arc<Volume>, variants: &[&[&str]]) {
    // The unclassified DDA over the scene's own coefficient storage.
    let storage = scene.render.coefficients;
    let base = render::render(
        scene,
        &Prepared::new_in(
            vol.clone(),
            scene.surface.filter,
            storage,
            scene.surface.iso,
        )
        .unwrap(),
        None,
    );
    assert_eq!(base.stats.counters.undefined, 0);
    for v in variants {
        let o: Vec<String> = v.iter().map(|s| s.to_string()).collect();
        let mut s = scene.clone();
        let parsed = Scene::parse(
            &std::fs::read_to_string(&scene.path).unwrap(),
            &scene.path,
            &o.iter().cloned().chain(size_of(scene)).collect::<Vec<_>>(),
        )
        .unwrap();
        s.render = parsed.render;
        let method = s.render.classify.unwrap();
        assert_eq!(s.render.coefficients, storage, "variants keep the storage");
        let prep = Prepared::new_in(vol.clone(), s.surface.filter, storage, s.surface.iso)
            .unwrap()
            .with_accel(s.surface.iso, method);
        let f = render::render(&s, &prep, None);
        // Segments and cell polynomials are pure functions of (ray, cell), so
        // skipping cells can never change a result: bitwise equal, colours too.
        assert_same_bits(&base, &f, &format!("{}: {v:?}", scene.path.display()));
        // BMCC is the on-the-fly coefficient bound, precomputed: never more.
        assert!(
            f.stats.counters.cells_solved <= base.stats.counters.cells_solved,
            "classification never solves more cells"
        );
    }
}

fn size_of(s: &Scene) -> Vec<String> {
    vec![
        format!("image.width={}", s.width),
        format!("image.height={}", s.height),
    ]
}

const VARIANTS: [&[&str]; 8] = [
    &["render.traversal=dda", "render.classify=bmcc"],
    &["render.traversal=dda", "render.classify=accc"],
    &["render.traversal=octree", "render.classify=accc"],
    &["render.traversal=octree", "render.classify=accc4"],
    &["render.traversal=octree", "render.classify=accc8"],
    &[
        "render.traversal=octree",
        "render.classify=bezier",
        "render.leaf=1",
    ],
    &[
        "render.traversal=octree",
        "render.classify=accc2",
        "render.leaf=8",
    ],
    &["render.traversal=distance", "render.classify=bezier"],
];

#[test]
fn f32_storage_renders_match_their_own_dda() {
    // Skipping is exact whatever the storage: classification, masks and
    // the solve all read the same f32 coefficients.
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let f32 = "render.coefficients=f32";
    let o = ["image.width=96", "image.height=96", f32].map(String::from);
    let variants: [&[&str]; 2] = [
        &["render.traversal=octree", "render.classify=bezier", f32],
        &["render.traversal=distance", "render.classify=accc", f32],
    ];
    for name in ["sphere.toml", "lobster.toml"] {
        let scene = Scene::load(&dir.join(name), &o).unwrap();
        let vol = Arc::new(scene.load_volume(&LoadOptions::default()).unwrap());
        hits_agree(&scene, vol, &variants);
    }
}

#[test]
fn octree_renders_match_unclassified_dda() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let small = ["image.width=96", "image.height=96"].map(String::from);
    for name in ["sphere.toml", "ball-two-holes.toml"] {
        let scene = Scene::load(&dir.join(name), &small).unwrap();
        let vol = Arc::new(scene.load_volume(&LoadOptions::default()).unwrap());
        hits_agree(&scene, vol, &VARIANTS);
    }
    // A real volume with Catmull-Rom (signed bound) and the smoothing spline.
    for filter in ["catmull-rom", "smooth-bspline3"] {
        let mut o = small.to_vec();
        o.push(format!("surface.filter={filter}"));
        let scene = Scene::load(&dir.join("lobster.toml"), &o).unwrap();
        let vol = Arc::new(scene.load_volume(&LoadOptions::default()).unwrap());
        hits_agree(&scene, vol, &VARIANTS[2..]);
    }
}

/// Renders `scene` with and without `clear_crossing_cells` over one prepared
/// field and classification; returns both frames.
/// Renders `scene` as given and with `off` applied to a copy, over one
/// preparation.
fn with_and_without(
    scene: &Scene,
    vol: Arc<Volume>,
    off: impl Fn(&mut Scene),
) -> (render::Frame, render::Frame) {
    let method = scene.render.classify.unwrap();
    let prep = Prepared::new_in(
        vol,
        scene.surface.filter,
        scene.render.coefficients,
        scene.surface.iso,
    )
    .unwrap()
    .with_accel(scene.surface.iso, method);
    let mut other = scene.clone();
    off(&mut other);
    (
        render::render(scene, &prep, None),
        render::render(&other, &prep, None),
    )
}

/// The two frames' hits, event counts and colours are the same bits (a
/// failure names the first pixel that differs and how many do).
fn assert_same_bits(a: &render::Frame, b: &render::Frame, what: &str) {
    fn same<T: PartialEq + std::fmt::Debug>(a: &[T], b: &[T], what: &str, name: &str) {
        assert_eq!(a.len(), b.len(), "{what}: {name} length");
        let diff: Vec<usize> = (0..a.len()).filter(|&i| a[i] != b[i]).collect();
        if let Some(&i) = diff.first() {
            panic!(
                "{what}: {name} differs at {} pixels, first {i}: {:?} vs {:?}",
                diff.len(),
                a[i],
                b[i]
            );
        }
    }
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    let (a, b) = (&a.film, &b.film);
    same(&bits(&a.u), &bits(&b.u), what, "u");
    same(&bits(&a.v), &bits(&b.v), what, "v");
    same(&bits(&a.events), &bits(&b.events), what, "events");
    same(&a.color, &b.color, what, "colour");
}

/// Marschner–Lobb's signal at its standard 41³: thin, high-frequency
/// features (case `"ml"` of [`load_case`]).
const ML_SCENE: &str = r#"
[image]
width = 96
height = 96
[camera]
kind = "perspective"
position = [20.0, 14.0, -60.0]
look_at = [20.0, 20.0, 20.0]
up = [0.0, 1.0, 0.0]
fov_y = 40.0
[volume.phantom]
kind = "marschner-lobb"
size = 41
[surface]
filter = "bspline3"
iso = 0.5
ior = 1.33
[backdrop]
center = [20.0, 20.0, 120.0]
normal = [0.0, 0.0, -1.0]
u_axis = [1.0, 0.0, 0.0]
checker = 4.0
[render]
traversal = "distance"
"#;

/// The image size of the bit-for-bit comparisons below.
const SMALL: &str = "image.width=96 image.height=96";

/// Scene `name` of `dir` (or [`ML_SCENE`] for `"ml"`) with the overrides
/// of `small` and `extra`, each a list of `key=value` parted by spaces.
fn load_case(dir: &std::path::Path, name: &str, small: &str, extra: &str) -> Scene {
    let o: Vec<String> = small
        .split_whitespace()
        .chain(extra.split_whitespace())
        .map(String::from)
        .collect();
    if name == "ml" {
        Scene::parse(ML_SCENE, &dir.join("ml.toml"), &o).unwrap()
    } else {
        Scene::load(&dir.join(name), &o).unwrap()
    }
}

/// The solve stage passes over the segments a tagged cell's plane proves
/// clear: the solves there would have found nothing, so every output bit
/// stays the same — smooth and noisy phantoms, holes, Marschner–Lobb's thin
/// features, every cell traversal, both storages, several filters (the
/// planes need sub-cell masks: Bézier tags and ACCC per sub-cell) — while
/// solves drop. (The walk's lane and scalar versions are held to the same
/// decisions by the walk's own tests.)
#[test]
fn passing_over_clear_segments_changes_no_bit() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let cases = [
        ("sphere.toml", "render.traversal=distance"),
        (
            "sphere.toml",
            "render.traversal=octree surface.filter=bspline2",
        ),
        (
            "sphere.toml",
            "render.traversal=dda surface.filter=bspline5 render.classify=accc4",
        ),
        (
            "sphere.toml",
            "volume.phantom.noise=6 surface.filter=catmull-rom render.traversal=distance",
        ),
        (
            "ball-two-holes.toml",
            "render.traversal=octree render.coefficients=f32",
        ),
        (
            "ball-one-hole.toml",
            "render.traversal=distance surface.filter=linear",
        ),
        // Marschner–Lobb's ripples: thin features, planes that fit less well.
        ("ml", "render.traversal=octree"),
    ];
    for (name, extra) in cases {
        let scene = load_case(&dir, name, SMALL, extra);
        let vol = Arc::new(scene.load_volume(&LoadOptions::default()).unwrap());
        let (on, off) = with_and_without(&scene, vol, |s| s.render.skip_clear_segments = false);
        assert_same_bits(&on, &off, &format!("{name} {extra:?}"));
        let (c, d) = (on.stats.counters, off.stats.counters);
        eprintln!(
            "{name} {extra:?}: solves {} -> {}, sub-cell and plane skips {} -> {}",
            d.cells_solved, c.cells_solved, d.subcell_skips, c.subcell_skips
        );
        assert!(
            c.cells_solved < d.cells_solved,
            "{name} {extra:?}: nothing passed over"
        );
        assert_eq!(
            c.cells_solved + c.subcell_skips,
            d.cells_solved + d.subcell_skips,
            "{name} {extra:?}: a pass-over is one solve spared"
        );
    }
}

/// A ray leaving a crossing skips the rest of its cell where the curvature
/// bound proves it empty: the solve there would have found nothing, so every
/// output bit stays the same — on smooth and noisy phantoms, thin features
/// (Marschner–Lobb), every cell traversal, both storages, several B-spline
/// degrees — while solves drop.
#[test]
fn clearing_crossing_cells_changes_no_bit() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let cases = [
        ("sphere.toml", "render.traversal=distance"),
        (
            "sphere.toml",
            "render.traversal=octree surface.filter=bspline2",
        ),
        (
            "sphere.toml",
            "render.traversal=dda surface.filter=bspline5 render.classify=accc",
        ),
        (
            "sphere.toml",
            "volume.phantom.noise=6 surface.filter=smooth-bspline3 surface.lambda=0 \
             render.traversal=distance",
        ),
        (
            "ball-two-holes.toml",
            "render.traversal=octree render.coefficients=f32",
        ),
        (
            "lobster.toml",
            "render.traversal=distance surface.filter=bspline7",
        ),
        ("ml", ""),
        ("ml", "surface.filter=bspline2 render.traversal=octree"),
    ];
    for (name, extra) in cases {
        let scene = load_case(&dir, name, SMALL, extra);
        let vol = Arc::new(scene.load_volume(&LoadOptions::default()).unwrap());
        let (on, off) = with_and_without(&scene, vol, |s| s.render.clear_crossing_cells = false);
        assert_same_bits(&on, &off, &format!("{name} {extra:?}"));
        let (c, d) = (on.stats.counters, off.stats.counters);
        let events = c.refractions + c.reflections;
        eprintln!(
            "{name} {extra:?}: {} cells cleared after {events} crossings, solves {} -> {}",
            c.cells_cleared, d.cells_solved, c.cells_solved
        );
        assert_eq!(d.cells_cleared, 0);
        assert!(c.cells_cleared > 0, "{name} {extra:?}: nothing cleared");
        // A cleared cell is at most one solve saved (masks may have skipped it).
        assert!(c.cells_solved < d.cells_solved);
        assert!(c.cells_solved + c.cells_cleared >= d.cells_solved);
    }
}

/// Primary rays that start their walk at the projected octree's bound (and
/// those that go straight to the backdrop) give the same bits as walking the
/// whole approach: perspective and orthographic cameras, supersampled rays
/// (anywhere in their pixel), a camera inside the domain, both cell
/// traversals that use it, and `f32` storage; the walk visits fewer cells
/// and solves exactly the same ones.
#[test]
fn skipping_the_empty_approach_changes_no_bit() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let cases = [
        ("sphere.toml", "render.traversal=distance"),
        (
            "sphere.toml",
            "render.traversal=octree render.supersampling=jitter render.samples=3",
        ),
        (
            "sphere.toml",
            "render.traversal=distance camera.kind=\"orthographic\" camera.height=70.0",
        ),
        (
            "sphere.toml",
            "render.traversal=octree camera.position=[30.0,28.0,6.0] camera.fov_y=70.0",
        ),
        (
            "ball-two-holes.toml",
            "render.traversal=distance render.coefficients=f32",
        ),
        ("lobster.toml", "render.traversal=octree"),
    ];
    for (name, extra) in cases {
        let scene = load_case(&dir, name, "image.width=96 image.height=80", extra);
        let vol = Arc::new(scene.load_volume(&LoadOptions::default()).unwrap());
        let (on, off) = with_and_without(&scene, vol, |s| s.render.skip_empty_approach = false);
        let what = format!("{name} {extra:?}");
        assert_same_bits(&on, &off, &what);
        let (c, d) = (on.stats.counters, off.stats.counters);
        eprintln!(
            "{what}: cells visited {} -> {}",
            d.cells_visited, c.cells_visited
        );
        assert_eq!(c.cells_solved, d.cells_solved, "{what}: solves");
        assert_eq!(c.refractions, d.refractions, "{what}: refractions");
        assert!(c.cells_visited < d.cells_visited, "{what}: nothing skipped");
    }
}
