//! Throughput of the reconstruction filters (issues 2 and 7):
//!
//! - `prefilter/256^3/FILTER`: `Field::new` on a 256³ u8 sphere, everything the
//!   renderer pays (padding, the three passes, the apron);
//! - `prefilter-pass/512^3/FILTER/AXIS`: one pass along x, y or z over the
//!   interior of a padded 512³ grid (input restored untimed before each run);
//! - `eval/FILTER/...`: value + gradient at 4096 pseudo-random points of a 64³
//!   sphere, through the per-point API (`value_grad_in`, what the refract
//!   stage calls), as a dependent chain (latency: each point waits for the
//!   previous result), and through the SoA batch API (SIMD lanes); the
//!   random points miss the cache on most rows, so `batch along rays`
//!   repeats the batch on points as a ray caster asks for them (64 rays of
//!   64 samples 0.1 voxel apart).
//!
//! ```sh
//! CARGO_TARGET_DIR=/work/target-filter cargo bench --bench filter
//! CARGO_TARGET_DIR=/work/target-filter cargo bench --bench filter -- 'eval/bspline3'
//! ```
//!
//! Criterion prints elements per second: voxels for the prefilter, points for
//! evaluation. All single-threaded except the prefilter, which uses every core.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, SamplingMode, Throughput, criterion_group, criterion_main};

use snell::bench::prefilter_pass::PrefilterPasses;
use snell::filter::{Field, FilterKind, PREFILTERED_NAMES as PREFILTERED};
use snell::phantom::{PhantomFormat, SphereSpec};
use snell::volume::Volume;
use snell::with_support;

const EVALUATED: [&str; 8] = [
    "linear",
    "catmull-rom",
    "bspline2",
    "bspline3",
    "bspline4",
    "bspline5",
    "bspline6",
    "bspline7",
];

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

fn kind(name: &str) -> FilterKind {
    FilterKind::parse(name, 1.0).unwrap()
}

fn prefilter_256(c: &mut Criterion) {
    let vol = sphere(256);
    let mut g = c.benchmark_group("prefilter/256^3");
    g.sample_size(10);
    g.sampling_mode(SamplingMode::Flat);
    g.warm_up_time(Duration::from_secs(1));
    g.throughput(Throughput::Elements(vol.len() as u64));
    for name in PREFILTERED {
        let k = kind(name);
        g.bench_function(name, |b| b.iter(|| Field::new(black_box(&vol), k)));
    }
    g.finish();
}

fn prefilter_pass_512(c: &mut Criterion) {
    let vol = sphere(512);
    let mut passes = PrefilterPasses::of(&vol);
    drop(vol);
    let mut g = c.benchmark_group("prefilter-pass/512^3");
    g.sample_size(10);
    g.sampling_mode(SamplingMode::Flat);
    g.warm_up_time(Duration::from_secs(1));
    g.measurement_time(Duration::from_secs(5));
    g.throughput(Throughput::Elements(passes.voxels() as u64));
    for name in PREFILTERED {
        let pf = kind(name).prefilter();
        for (axis, an) in ["x", "y", "z"].into_iter().enumerate() {
            g.bench_function(format!("{name}/{an}"), |b| {
                b.iter_custom(|iters| (0..iters).map(|_| passes.time(&pf, axis)).sum())
            });
        }
    }
    g.finish();
}

/// 4096 pseudo-random points spread over the sphere's interior.
fn points() -> Vec<[f64; 3]> {
    (0..4096)
        .map(|i| {
            let t = i as f64 * 0.618_033_988_749;
            [
                6.0 + (t * 7.1) % 50.0,
                6.0 + (t * 3.3) % 50.0,
                6.0 + (t * 5.7) % 50.0,
            ]
        })
        .collect()
}

fn eval(c: &mut Criterion) {
    let vol = sphere(64);
    let pts = points();
    let (xs, ys, zs): (Vec<f64>, Vec<f64>, Vec<f64>) = (
        pts.iter().map(|p| p[0]).collect(),
        pts.iter().map(|p| p[1]).collect(),
        pts.iter().map(|p| p[2]).collect(),
    );
    // The same number of points as a ray caster asks for them: 64 rays
    // through the sphere, 64 samples each, 0.1 voxel apart.
    let ray_pts: Vec<[f64; 3]> = (0..pts.len())
        .map(|k| {
            let (ray, step) = (k / 64, (k % 64) as f64 * 0.1);
            let a = ray as f64 * 0.37;
            [
                20.0 + 0.3 * (ray % 8) as f64 + step * a.cos(),
                20.0 + 0.3 * (ray / 8) as f64 + step * a.sin(),
                20.0 + step * 0.5,
            ]
        })
        .collect();
    let (rx, ry, rz): (Vec<f64>, Vec<f64>, Vec<f64>) = (
        ray_pts.iter().map(|p| p[0]).collect(),
        ray_pts.iter().map(|p| p[1]).collect(),
        ray_pts.iter().map(|p| p[2]).collect(),
    );
    let mut out = [
        vec![0.0; pts.len()],
        vec![0.0; pts.len()],
        vec![0.0; pts.len()],
        vec![0.0; pts.len()],
    ];
    let mut g = c.benchmark_group("eval");
    g.throughput(Throughput::Elements(pts.len() as u64));
    for name in EVALUATED {
        let f = Field::new(&vol, kind(name));
        let s = f.kernel().support();
        g.bench_function(format!("{name}/value+grad"), |b| {
            b.iter(|| {
                with_support!(s, S => pts.iter().map(|p| {
                    let (v, g) = f.value_grad_in::<S>(black_box(*p));
                    v + g[0] + g[1] + g[2]
                }).sum::<f64>())
            })
        });
        g.bench_function(format!("{name}/value+grad latency"), |b| {
            b.iter(|| {
                let mut carry = 0.0;
                for p in &pts {
                    // `carry * 0.0` is not foldable (NaN, ∞): the next point
                    // waits for this one's result.
                    let q = [p[0] + carry * 0.0, p[1], p[2]];
                    let (v, g) = with_support!(s, S => f.value_grad_in::<S>(q));
                    carry = v + g[0] + g[1] + g[2];
                }
                carry
            })
        });
        g.bench_function(format!("{name}/value+grad batch"), |b| {
            b.iter(|| {
                let [v, gx, gy, gz] = &mut out;
                f.value_grad_batch([&xs, &ys, &zs], [v, gx, gy, gz]);
                black_box(v[0] + gx[1] + gy[2] + gz[3])
            })
        });
        g.bench_function(format!("{name}/value+grad batch along rays"), |b| {
            b.iter(|| {
                let [v, gx, gy, gz] = &mut out;
                f.value_grad_batch([&rx, &ry, &rz], [v, gx, gy, gz]);
                black_box(v[0] + gx[1] + gy[2] + gz[3])
            })
        });
        g.bench_function(format!("{name}/value"), |b| {
            b.iter(|| {
                with_support!(s, S => pts.iter().map(|p| f.value_in::<S>(black_box(*p))).sum::<f64>())
            })
        });
    }
    g.finish();
}

criterion_group! {
    name = filter;
    config = Criterion::default().without_plots();
    targets = prefilter_256, prefilter_pass_512, eval
}
criterion_main!(filter);
