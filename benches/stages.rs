//! Micro-benchmarks of each pipeline stage on fixed inputs, so a regression in
//! one stage is visible on its own: `cargo bench --bench stages`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;

use snell::classify::{self, Method, bezier};
use snell::filter::{Field, FilterKind};
use snell::lattice::cell_at;
use snell::octree::Octree;
use snell::phantom::{PhantomFormat, SphereSpec};
use snell::render::stages::refract::snell as bend;
use snell::render::stages::traverse::{CellRay, exit_block};
use snell::roots::bernstein::{BernsteinBasis, IsolationWork};
use snell::volume::Volume;
use snell::with_support;

fn sphere(size: usize) -> Volume {
    SphereSpec {
        size,
        radius: size as f64 * 0.3,
        sigma: 3.0,
        format: PhantomFormat::U8,
        ..Default::default()
    }
    .build()
    .unwrap()
}

fn prefilter(c: &mut Criterion) {
    let vol = sphere(128);
    let mut g = c.benchmark_group("prefilter-128^3");
    g.sample_size(10);
    for name in ["bspline3", "bspline7", "smooth-bspline3"] {
        let kind = FilterKind::parse(name, 1.0).unwrap();
        g.bench_function(name, |b| b.iter(|| Field::new(black_box(&vol), kind)));
    }
    g.finish();
}

fn evaluation(c: &mut Criterion) {
    let vol = sphere(64);
    let mut g = c.benchmark_group("evaluate");
    for name in ["linear", "catmull-rom", "bspline3", "bspline5", "bspline7"] {
        let f = Field::new(&vol, FilterKind::parse(name, 0.0).unwrap());
        let pts: Vec<[f64; 3]> = (0..1024)
            .map(|i| {
                let t = i as f64 * 0.618_033_988_749;
                [
                    10.0 + (t * 7.1) % 40.0,
                    10.0 + (t * 3.3) % 40.0,
                    10.0 + (t * 5.7) % 40.0,
                ]
            })
            .collect();
        let s = f.kernel().support();
        g.bench_function(format!("{name}/value x1024"), |b| {
            b.iter(|| with_support!(s, S => pts.iter().map(|p| f.value_in::<S>(*p)).sum::<f64>()))
        });
        g.bench_function(format!("{name}/value+gradient x1024"), |b| {
            b.iter(|| with_support!(s, S => pts.iter().map(|p| f.value_grad_in::<S>(*p).0).sum::<f64>()))
        });
    }
    g.finish();
}

fn crossing(c: &mut Criterion) {
    let vol = sphere(64);
    let mut g = c.benchmark_group("solve-cell");
    for name in ["linear", "bspline3", "bspline7"] {
        let f = Field::new(&vol, FilterKind::parse(name, 0.0).unwrap());
        let s = f.kernel().support();
        let basis = BernsteinBasis::new(3 * (s - 1));
        let off = f.kernel().knot_offset();
        // A segment through a cell on the iso-surface (r ≈ 19.2 + ...).
        let cell = [44i64, 31, 31];
        let p0 = [44.05 - off, 31.3 - off, 31.2 - off];
        let p1 = [44.95 - off, 31.8 - off, 31.7 - off];
        let mut buf = [0.0; 22];
        g.bench_function(format!("{name}/restrict"), |b| {
            b.iter(
                || with_support!(s, S => f.restrict::<S>(black_box(cell), p0, p1, 127.5, &mut buf)),
            )
        });
        with_support!(s, S => f.restrict::<S>(cell, p0, p1, 127.5, &mut buf));
        let d = basis.degree();
        g.bench_function(format!("{name}/bernstein"), |b| {
            b.iter(|| basis.segment(black_box(&buf[..=d])))
        });
        // The same segment in every lane: per-segment cost of the SIMD path.
        let (base, tau, delta) = f.lane_segment(cell, p0, p1);
        let isa = snell::simd::Isa::current();
        let lanes = isa.lanes();
        g.bench_function(format!("{name}/lanes {} x{lanes}", isa.name()), |b| {
            b.iter(|| {
                snell::with_isa!(isa, L, M => {
                    let seg = snell::filter::restrict::LaneSegments::<L> {
                        base: [base; L],
                        tau: std::array::from_fn(|a| [tau[a]; L]),
                        delta: std::array::from_fn(|a| [delta[a]; L]),
                    };
                    let mut mono = [[0.0; L]; 22];
                    with_support!(s, S => f.restrict_lanes::<S, L, M>(black_box(&seg), 127.5, &mut mono));
                    basis.bernstein_lanes::<L, M>(&mono)[0][0]
                })
            })
        });
        let poly = basis.segment(&buf[..=d]);
        let mut stack = Vec::with_capacity(64);
        g.bench_function(format!("{name}/isolate+brent"), |b| {
            b.iter(|| {
                let mut w = IsolationWork::default();
                poly.first_crossing_with(black_box(false), 1e-7, &mut w, &mut stack)
            })
        });
    }
    g.finish();
}

fn classification(c: &mut Criterion) {
    let vol = sphere(128);
    let f = Field::new(&vol, FilterKind::BSpline(3));
    let iso = f.separating_iso(127.5);
    let mut g = c.benchmark_group("classify-128^3-bspline3");
    g.sample_size(10);
    for m in [
        Method::Bmcc,
        Method::Accc,
        Method::Bezier(0),
        Method::Bezier(2),
    ] {
        g.bench_function(m.name(), |b| b.iter(|| classify::classify(&f, iso, m)));
    }
    let tags = classify::classify(&f, iso, Method::Accc).tags;
    g.bench_function("octree-build", |b| b.iter(|| Octree::build(tags.clone())));
    // The sub-cell masks of the cells the Bézier hull keeps (a cubic patch
    // in AVX-512 registers where the CPU has it).
    let kept = classify::classify(&f, iso, Method::Bezier(2)).tags;
    let beta = bezier::bernstein_weights(&f);
    let patches: Vec<Vec<f64>> = (0..kept.cells.iter().product::<usize>())
        .filter(|&i| kept.get_index(i))
        .take(2000)
        .map(|i| bezier::cell_bernstein(&f, cell_at(kept.cells, i), iso, &beta))
        .collect();
    let mut sub = bezier::SubCells::new(&f);
    g.bench_function(format!("sub-cell masks x{}", patches.len()), |b| {
        b.iter(|| {
            patches
                .iter()
                .fold(0u64, |a, p| a ^ sub.mask(black_box(p), 1e-9))
        })
    });
    g.finish();
}

fn traversal(c: &mut Criterion) {
    let vol = sphere(64);
    let f = Field::new(&vol, FilterKind::BSpline(3));
    let tags = classify::classify(&f, f.separating_iso(127.5), Method::Accc).tags;
    let tree = Octree::build(tags);
    let ray = CellRay::new([0.5, 2.3, 1.7], [0.8, 0.45, 0.39]);
    let mut g = c.benchmark_group("traverse");
    g.bench_function("exit-block x64", |b| {
        b.iter(|| {
            let (mut t, mut cell) = (0.0, [0i64, 2, 1]);
            for _ in 0..64 {
                (t, cell) = exit_block(black_box(&ray), cell, 0, t);
            }
            cell
        })
    });
    g.bench_function("octree-skip-level x64", |b| {
        b.iter(|| {
            (0..64i64)
                .filter_map(|i| tree.skip_level(black_box([i % 62, (i * 7) % 62, 31]), 0))
                .count()
        })
    });
    g.finish();
}

fn refraction(c: &mut Criterion) {
    let n = DVec3::new(0.3, 0.8, -0.52).normalize();
    let dirs: Vec<DVec3> = (0..256)
        .map(|i| DVec3::new((i as f64 * 0.1).sin(), (i as f64 * 0.07).cos(), 1.0).normalize())
        .collect();
    c.bench_function("refract/snell x256", |b| {
        b.iter(|| {
            dirs.iter()
                .map(|&d| {
                    matches!(
                        bend(d, black_box(n), 1.0, 1.5),
                        snell::render::stages::refract::Bend::Refracted(_)
                    ) as u32
                })
                .sum::<u32>()
        })
    });
}

/// The post stage on a fixed hit image: the sphere scene's pixel-centre
/// hits at 256×256, coloured by PRSS (default bicubic map, and the paper's
/// bilinear 4×4) and by the footprint filters.
fn post(c: &mut Criterion) {
    use snell::film::prss::{self, Mode, PostSettings};
    use snell::scene::{FootprintFilter, PrssMap, Scene};
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let scene = Scene::load(
        &root.join("scenes/sphere.toml"),
        &[
            "image.width=256".into(),
            "image.height=256".into(),
            "render.traversal=octree".into(),
        ],
    )
    .unwrap();
    let film = snell::render::render_scene(&scene).unwrap().film;
    let base = PostSettings::new(Mode::Prss, &scene.render);
    let paper = PostSettings {
        samples: 4,
        map: PrssMap::Bilinear,
        ..base
    };
    let footprint = PostSettings {
        mode: Mode::Footprint,
        ..base
    };
    let ewa = PostSettings {
        footprint: FootprintFilter::Ewa,
        ..footprint
    };
    let mut g = c.benchmark_group("post-256^2");
    for (name, s) in [
        ("prss", base),
        ("prss-paper", paper),
        ("footprint-box", footprint),
        ("footprint-ewa", ewa),
    ] {
        g.bench_function(name, |b| {
            b.iter(|| prss::shade(black_box(&film), &scene.backdrop, scene.background, &s))
        });
    }
}

criterion_group! {
    name = stages;
    // Numbers only: criterion's HTML plots need fonts the plotters build
    // shared with `snell bench` does not carry.
    config = Criterion::default().without_plots();
    targets = prefilter, evaluation, crossing, classification, traversal, refraction, post
}
criterion_main!(stages);
