//! Property tests (proptest) of the numerical building blocks, each against a
//! brute-force or closed-form reference:
//!
//! - the cell walk (incremental DDA and block jumps) visits exactly the cells
//!   a segment crosses, rays along axes, faces, edges and corners included;
//! - Brent returns a root within tolerance whenever it is given a bracket;
//! - refraction keeps unit length, obeys Snell's law and reflects exactly at
//!   total internal reflection;
//! - every conservative classification (and the traversal's on-the-fly cell
//!   bound) tags every cell where dense sampling sees the iso-value crossed;
//! - prefiltering then evaluating reproduces the samples for every
//!   interpolating filter, short axes included.
//!
//! Case counts keep the file at about a second in release.

mod common;

use glam::DVec3;
use proptest::prelude::*;

use snell::classify::{self, CellBound, Method};
use snell::filter::{Field, FilterKind};
use snell::lattice::Lattice;
use snell::phantom::uniform;
use snell::render::stages::refract::{Bend, snell as bend};
use snell::render::stages::traverse::{CellRay, Dda, cell_span, exit_block};
use snell::roots::{brent, inside};
use snell::volume::{SampleType, Volume};

// ---------------------------------------------------------------------------
// Cell walk.

/// The cells the segment `(0, t1)` passes through for a positive length, in
/// order: every boundary crossing on every axis, sorted, and the cell of each
/// gap's midpoint (gaps under 1e-9 are touches, not crossings).
fn reference_cells(ou: [f64; 3], du: [f64; 3], t1: f64) -> Vec<[i64; 3]> {
    let mut ts = vec![0.0, t1];
    for a in 0..3 {
        if du[a] != 0.0 {
            let end = ou[a] + t1 * du[a];
            let (lo, hi) = (ou[a].min(end), ou[a].max(end));
            for k in lo.ceil() as i64..=hi.floor() as i64 {
                let t = (k as f64 - ou[a]) / du[a];
                if t > 0.0 && t < t1 {
                    ts.push(t);
                }
            }
        }
    }
    ts.sort_by(f64::total_cmp);
    let mut out: Vec<[i64; 3]> = Vec::new();
    for w in ts.windows(2) {
        if w[1] - w[0] > 1e-9 {
            let tm = 0.5 * (w[0] + w[1]);
            let c = [0, 1, 2].map(|a| (ou[a] + tm * du[a]).floor() as i64);
            if out.last() != Some(&c) {
                out.push(c);
            }
        }
    }
    out
}

/// The cells the renderer's walk visits, single steps only: the same loop as
/// `traverse::walk` without skipping.
fn dda_cells(ou: [f64; 3], du: [f64; 3], t1: f64) -> Vec<[i64; 3]> {
    let ray = CellRay::new(ou, du);
    let mut w = Dda::new(&ray, ou.map(|x| x.floor() as i64), 0.0);
    let mut out = Vec::new();
    while w.t < t1 {
        out.push(w.cell);
        assert!(out.len() < 10_000, "the walk does not end");
        w.advance();
    }
    out
}

/// Length of the part of `[0, t1]` the ray spends in `cell`.
fn time_in(ray: &CellRay, cell: [i64; 3], t1: f64) -> f64 {
    let (c0, c1) = cell_span(ray, cell);
    (c1.min(t1) - c0.max(0.0)).max(0.0)
}

/// The walk steps to a face neighbour along the ray's direction, contains the
/// reference as a subsequence, and visits nothing else but zero-length touches
/// (where it passes exactly through an edge or a corner).
fn check_walk(ou: [f64; 3], du: [f64; 3], t1: f64) -> Result<(), TestCaseError> {
    let got = dda_cells(ou, du, t1);
    let want = reference_cells(ou, du, t1);
    let ray = CellRay::new(ou, du);
    for w in got.windows(2) {
        let moved: Vec<usize> = (0..3).filter(|&a| w[0][a] != w[1][a]).collect();
        prop_assert_eq!(moved.len(), 1, "one axis per step: {:?}", w);
        let a = moved[0];
        prop_assert_eq!(
            w[1][a] - w[0][a],
            du[a].signum() as i64,
            "steps along the ray: {:?}",
            w
        );
    }
    let mut j = 0;
    for &c in &got {
        if j < want.len() && want[j] == c {
            j += 1;
        } else {
            let len = time_in(&ray, c, t1);
            prop_assert!(
                len <= 1e-9,
                "extra cell {:?} holds the ray for {}: got {:?}, want {:?}",
                c,
                len,
                got,
                want
            );
        }
    }
    prop_assert_eq!(
        j,
        want.len(),
        "missed cells: got {:?}, want {:?}",
        got,
        want
    );
    Ok(())
}

/// Jumps over aligned blocks of random levels: every crossed cell lies in a
/// visited block, in order, and every jump moves forward.
fn check_blocks(ou: [f64; 3], du: [f64; 3], t1: f64, levels: &[u32]) -> Result<(), TestCaseError> {
    let want = reference_cells(ou, du, t1);
    let ray = CellRay::new(ou, du);
    let mut cell = ou.map(|x| x.floor() as i64);
    let mut t = 0.0;
    let mut j = 0;
    for step in 0..10_000usize {
        let level = levels[step % levels.len()];
        let lo = cell.map(|c| (c >> level) << level);
        let inside_block =
            |c: [i64; 3]| (0..3).all(|a| c[a] >= lo[a] && c[a] < lo[a] + (1 << level));
        while j < want.len() && inside_block(want[j]) {
            j += 1;
        }
        let (tn, next) = exit_block(&ray, cell, level, t);
        prop_assert!(tn >= t && next != cell, "no progress at {:?}", cell);
        if tn >= t1 {
            prop_assert_eq!(j, want.len(), "blocks skipped crossed cells {:?}", want);
            return Ok(());
        }
        t = tn;
        cell = next;
    }
    Err(TestCaseError::fail("the block walk does not end"))
}

fn generic_ray() -> impl Strategy<Value = ([f64; 3], [f64; 3], f64)> {
    (
        prop::array::uniform3(0.0..12.0f64),
        prop::array::uniform3(-1.0..1.0f64),
        0.1..20.0f64,
    )
        .prop_filter("a direction", |(_, d, _)| {
            d.iter().map(|x| x * x).sum::<f64>() > 1e-4
        })
}

/// Origins on a quarter-voxel lattice (integers: faces, edges, corners) and
/// directions with zero and equal components (axis-parallel, face and space
/// diagonals through corners), all exact in binary.
fn lattice_ray() -> impl Strategy<Value = ([f64; 3], [f64; 3], f64)> {
    let dir = prop::sample::select(vec![-2.0, -1.0, -0.5, -0.25, 0.0, 0.0, 0.25, 0.5, 1.0, 2.0]);
    (
        prop::array::uniform3((0i32..48).prop_map(|k| k as f64 / 4.0)),
        [dir.clone(), dir.clone(), dir],
        (1i32..80).prop_map(|k| k as f64 / 4.0),
    )
        .prop_filter("a direction", |(_, d, _)| d.iter().any(|&x| x != 0.0))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(3000))]

    #[test]
    fn dda_visits_exactly_the_crossed_cells((o, d, t1) in generic_ray()) {
        check_walk(o, d, t1)?;
    }

    #[test]
    fn dda_on_faces_edges_and_corners((o, d, t1) in lattice_ray()) {
        check_walk(o, d, t1)?;
    }

    #[test]
    fn block_jumps_never_skip_a_crossed_cell(
        (o, d, t1) in prop_oneof![generic_ray(), lattice_ray()],
        levels in prop::collection::vec(0u32..4, 1..6),
    ) {
        check_blocks(o, d, t1, &levels)?;
    }
}

// ---------------------------------------------------------------------------
// Brent.

/// Functions with a single sign change at `r` (outside below, inside above
/// when `s > 0`): linear with any slope, a flat triple root, a saturating
/// tanh, and a step.
fn single_change(family: u8, r: f64, k: f64, s: f64) -> impl Fn(f64) -> f64 {
    move |x: f64| {
        let y = x - r;
        s * match family {
            0 => k * y,
            1 => k * y * y * y,
            2 => (k * y).tanh(),
            _ => {
                if y > 0.0 {
                    1.0
                } else {
                    -1.0
                }
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(3000))]

    #[test]
    fn brent_finds_the_bracketed_change(
        a in -10.0..10.0f64,
        width_exp in -6.0..1.3f64,
        frac in 0.001..0.999f64,
        family in 0u8..4,
        k_exp in -8.0..8.0f64,
        negate in any::<bool>(),
        tol_exp in -12.0..-3.0f64,
    ) {
        let b = a + 10f64.powf(width_exp);
        let r = a + frac * (b - a);
        let s = if negate { -1.0 } else { 1.0 };
        let f = single_change(family, r, 10f64.powf(k_exp), s);
        let tol = 10f64.powf(tol_exp);
        let (fa, fb) = (f(a), f(b));
        prop_assume!(inside(fa) != inside(fb));
        let mut outside_calls = 0;
        let root = brent::solve(
            |x| {
                if !(a..=b).contains(&x) {
                    outside_calls += 1;
                }
                f(x)
            },
            a, b, fa, fb, tol,
        );
        prop_assert_eq!(outside_calls, 0, "evaluated outside the bracket");
        prop_assert!((a..=b).contains(&root.x), "{:?} outside [{}, {}]", root, a, b);
        let err = (root.x - r).abs();
        prop_assert!(
            err <= tol + 4.0 * f64::EPSILON * r.abs().max(1.0),
            "family {} root {} found {:?}, error {:e} > tol {:e}", family, r, root, err, tol
        );
        prop_assert!(root.evals <= 200);
    }

    /// Several roots: the answer is within tolerance of *a* sign change.
    #[test]
    fn brent_with_many_roots_lands_on_one(
        a in -5.0..5.0f64,
        width in 0.5..10.0f64,
        omega in 0.1..50.0f64,
        phase in 0.0..6.3f64,
        tol_exp in -12.0..-3.0f64,
    ) {
        let f = |x: f64| (omega * x + phase).sin();
        let mut b = a + width;
        if inside(f(a)) == inside(f(b)) {
            // Half a period further, the sine has the other sign.
            b += std::f64::consts::PI / omega;
        }
        let tol = 10f64.powf(tol_exp);
        let (fa, fb) = (f(a), f(b));
        prop_assume!(inside(fa) != inside(fb));
        let root = brent::solve(f, a, b, fa, fb, tol);
        let slack = tol + 8.0 * f64::EPSILON * root.x.abs().max(1.0);
        let (lo, hi) = ((root.x - slack).max(a), (root.x + slack).min(b));
        let side = |x: f64| inside(if x == a { fa } else if x == b { fb } else { f(x) });
        prop_assert!(side(lo) != side(hi), "no change within {:e} of {:?}", slack, root);
    }
}

// ---------------------------------------------------------------------------
// Refraction.

fn unit() -> impl Strategy<Value = DVec3> {
    prop::array::uniform3(-1.0..1.0f64)
        .prop_filter("not tiny", |v| DVec3::from_array(*v).length() > 1e-3)
        .prop_map(|v| DVec3::from_array(v).normalize())
}

fn ior() -> impl Strategy<Value = f64> {
    prop_oneof![
        prop::sample::select(vec![1.0, 1.0001, 1.33, 1.5, 2.42, 4.0]),
        1.0..4.0f64,
    ]
}

/// Checks one bend of `d` at the surface with normal `n` from `n1` into `n2`.
fn check_bend(d: DVec3, n: DVec3, n1: f64, n2: f64) -> Result<(), TestCaseError> {
    let sin_i = d.cross(n).length();
    let s = n1 / n2 * sin_i;
    let out = bend(d, n, n1, n2);
    match out {
        Bend::Refracted(t) => {
            prop_assert!(
                s <= 1.0 + 1e-9,
                "refracted beyond the critical angle: {}",
                s
            );
            prop_assert!((t.length() - 1.0).abs() <= 1e-12, "|t| = {}", t.length());
            let sin_t = t.cross(n).length();
            prop_assert!(
                (n1 * sin_i - n2 * sin_t).abs() <= 1e-9 * n1.max(n2),
                "Snell: {} sin {} vs {} sin {}",
                n1,
                sin_i,
                n2,
                sin_t
            );
            // Through the surface, in the plane of incidence.
            if d.dot(n).abs() > 1e-9 {
                prop_assert!(t.dot(n) * d.dot(n) >= 0.0, "went back: d {} t {}", d, t);
            }
            prop_assert!(
                t.dot(d.cross(n)).abs() <= 1e-9,
                "left the plane of incidence"
            );
        }
        Bend::Reflected(r) => {
            prop_assert!(s >= 1.0 - 1e-9, "reflected below the critical angle: {}", s);
            let mirror = d - 2.0 * d.dot(n) * n;
            prop_assert!(
                (r - mirror).length() <= 1e-12,
                "r {} vs mirror {}",
                r,
                mirror
            );
            prop_assert!((r.length() - 1.0).abs() <= 1e-12);
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(5000))]

    #[test]
    fn refraction_is_unit_snell_and_tir(d in unit(), n in unit(), n1 in ior(), n2 in ior()) {
        check_bend(d, n, n1, n2)?;
        // Either side of the surface, and either orientation of the normal.
        check_bend(d, -n, n1, n2)?;
    }

    /// Grazing incidence exactly in the surface, and exactly along the normal.
    #[test]
    fn refraction_at_grazing_and_normal_incidence(n in unit(), n1 in ior(), n2 in ior(), k in unit()) {
        let g = k.cross(n);
        prop_assume!(g.length() > 1e-3);
        check_bend(g.normalize(), n, n1, n2)?;
        check_bend(-n, n, n1, n2)?;
        match bend(-n, n, n1, n2) {
            Bend::Refracted(t) => prop_assert!((t + n).length() <= 1e-15, "bent at normal incidence: {}", t),
            b => prop_assert!(false, "normal incidence reflected: {:?}", b),
        }
    }
}

// ---------------------------------------------------------------------------
// Classification and prefiltering on random volumes.

const CLASSIFY_FILTERS: [&str; 6] = [
    "linear",
    "catmull-rom",
    "bspline2",
    "bspline3",
    "bspline5",
    "smooth-bspline3",
];

/// A random volume: white noise, or a smooth random blob field (both kinds of
/// surfaces, fragmented and coherent).
fn random_volume(dims: [usize; 3], seed: u64, smooth: bool) -> Volume {
    let n = dims.iter().product::<usize>();
    let centres: Vec<[f64; 4]> = (0..4)
        .map(|k| std::array::from_fn(|a| uniform(seed, 100 + 4 * k + a as u64)))
        .collect();
    let samples = (0..n)
        .map(|i| {
            if !smooth {
                return (255.0 * uniform(seed, i as u64)).round() as f32;
            }
            let p = [i % dims[0], i / dims[0] % dims[1], i / (dims[0] * dims[1])];
            let v: f64 = centres
                .iter()
                .map(|c| {
                    let r2: f64 = (0..3)
                        .map(|a| (p[a] as f64 - c[a] * dims[a] as f64).powi(2))
                        .sum();
                    (-r2 / (1.0 + 4.0 * c[3])).exp()
                })
                .sum();
            v as f32
        })
        .collect();
    Volume::new(dims, [1.0; 3], SampleType::F32, samples).unwrap()
}

/// Cells where a dense grid of points (the closed cell, 6³) sees values on
/// both sides of `iso` ([`common::straddles`]).
fn crossed_cells(field: &Field, lattice: &Lattice, iso: f64) -> Vec<[i64; 3]> {
    let c = lattice.cells.map(|n| n as i64);
    (0..c[2])
        .flat_map(|z| (0..c[1]).flat_map(move |y| (0..c[0]).map(move |x| [x, y, z])))
        .filter(|&cell| common::straddles(field, lattice, cell, iso))
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn classification_is_conservative(
        dims in prop::array::uniform3(2usize..7),
        seed in any::<u64>(),
        smooth in any::<bool>(),
        filter in prop::sample::select(CLASSIFY_FILTERS.to_vec()),
        iso_frac in 0.02..0.98f64,
    ) {
        let vol = random_volume(dims, seed, smooth);
        let (lo, hi) = vol
            .samples()
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| (l.min(v as f64), h.max(v as f64)));
        let field = Field::new(&vol, FilterKind::parse(filter, 0.5).unwrap());
        let iso = field.separating_iso(lo + iso_frac * (hi - lo));
        let lattice = Lattice::new(field.kernel(), field.dims());
        let crossed = crossed_cells(&field, &lattice, iso);
        let bound = CellBound::new(field.kernel());
        for &c in &crossed {
            prop_assert!(bound.may_cross(&field, c, iso), "{}: cell bound skips {:?}", filter, c);
        }
        for m in [
            Method::Bmcc,
            Method::Accc,
            Method::AcccSub(2),
            Method::AcccSub(4),
            Method::Bezier(0),
            Method::Bezier(2),
        ] {
            let tags = classify::classify(&field, iso, m).tags;
            for &c in &crossed {
                prop_assert!(tags.get(c), "{} {}: untagged cell {:?} holds a crossing", filter, m.name(), c);
            }
        }
    }
}

const INTERPOLATING: [&str; 9] = [
    "linear",
    "catmull-rom",
    "bspline2",
    "bspline3",
    "bspline4",
    "bspline5",
    "bspline6",
    "bspline7",
    "smooth-bspline3",
];

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    /// Interpolating filters (and the smoothing spline at λ = 0) give back
    /// every sample at its grid point, for any axis length from 1 up.
    #[test]
    fn prefilter_then_evaluate_reproduces_samples(
        dims in prop::array::uniform3(1usize..9),
        seed in any::<u64>(),
        scale_exp in -3.0..6.0f64,
        filter in prop::sample::select(INTERPOLATING.to_vec()),
    ) {
        let scale = 10f64.powf(scale_exp);
        let n = dims.iter().product::<usize>();
        let samples: Vec<f32> = (0..n)
            .map(|i| (scale * (2.0 * uniform(seed, i as u64) - 1.0)) as f32)
            .collect();
        let vol = Volume::new(dims, [1.0; 3], SampleType::F32, samples).unwrap();
        let field = Field::new(&vol, FilterKind::parse(filter, 0.0).unwrap());
        let mag = vol.samples().iter().fold(0.0f64, |m, &v| m.max((v as f64).abs()));
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    let want = vol.get(x, y, z);
                    let got = field.value(DVec3::new(x as f64, y as f64, z as f64));
                    prop_assert!(
                        (got - want).abs() <= 1e-9 * mag,
                        "{} {:?} at ({}, {}, {}): {} vs {}", filter, dims, x, y, z, got, want
                    );
                }
            }
        }
    }
}
