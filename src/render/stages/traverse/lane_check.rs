//! The check every lane walk passes: each ray visits the same cells and
//! hands the same segment bits to the solve as the scalar walk
//! ([`super::walk_interleaved`]), over octree blocks, DDA cells and distance
//! cubes, for each instruction set of [`super::lanes`].

use std::sync::Arc;

use bumpalo::Bump;
use glam::DVec3;

use super::cell::AXIS_SPAN;
use super::lanes::{LaneIsa, MAX_LANES, SPAN_ROWS, axis_span, distance_layout_fits, layout_fits};
use super::{DistanceCubes, OctreeBlocks, clamped_floor, walk_interleaved};
use crate::classify::Method;
use crate::classify::bezier::SUB;
use crate::octree::distance::Proximity;
use crate::phantom::{mix64, uniform};
use crate::prepare::Prepared;
use crate::render::context::{Ctx, Skip};
use crate::render::packet::{Queue, Rays};
use crate::render::stats::Counters;
use crate::render::testing::{scrambled_ball, small_scene};
use crate::with_field;

/// Every check of the lane walk for instruction set `S` (whose features the
/// CPU has): the walk against the scalar walk, with the octree's blocks
/// read from the brick levels and from the byte map, then its spans and
/// conversions against the scalar walk's.
pub(super) fn check_isa<S: LaneIsa>() {
    every_ray_walks_as_in_the_scalar_walk::<S>(true);
    every_ray_walks_as_in_the_scalar_walk::<S>(false);
    spans_are_the_table_of_the_scalar_walk::<S>();
    conversions_are_the_scalar_ones::<S>();
}

/// Rays from random points of (and around) the domain in random
/// directions — some along axes, with signed zeros, tiny or NaN
/// components, diagonals through edges and corners — with random pieces, some already past their end, some
/// to step past their cell first. Each walk runs until every ray has
/// escaped, re-entering after each candidate cell as after a solve
/// that found nothing; both walks must hand every ray the same cells
/// and segment bits, and count the same visits and sub-cell skips —
/// over octree blocks, DDA cells, and distance cubes (octant and
/// centred maps).
fn every_ray_walks_as_in_the_scalar_walk<S: LaneIsa>(brick_levels: bool) {
    let odd = [0.0, -0.0, 1e-300, -1e-300, f64::NAN];
    // Segments the planes passed over, by traversal (the scalar walk's
    // skips with planes less its skips without).
    let mut passed = std::collections::HashMap::<&str, u64>::new();
    // Distance walks over the eight octant maps (budget unlimited) and
    // over the centred map (no budget).
    for (traversal, method, seed, budget) in [
        ("octree", Method::Bezier(2), 1, None),
        ("octree", Method::Accc, 2, None),
        ("dda", Method::Bezier(2), 3, None),
        ("octree", Method::Bmcc, 4, None),
        ("distance", Method::Bezier(2), 5, Some(usize::MAX)),
        ("distance", Method::Accc, 6, Some(0)),
        ("distance", Method::Bezier(2), 7, Some(0)),
    ] {
        let walked = if budget.is_some() {
            "octree"
        } else {
            traversal
        };
        let sc = small_scene(120.0, &[format!("render.traversal={walked}")]);
        let prep = Prepared::new(Arc::new(scrambled_ball(seed)), sc.surface.filter)
            .with_accel(sc.surface.iso, method);
        with_field!(&prep.field, f => {
            let ctx = Ctx::new(&sc, &prep, f.as_ref());
            let Skip::Octree { tree, leaf_level } = &ctx.skip else {
                panic!("{traversal} walks the octree");
            };
            assert!(layout_fits(&ctx, tree), "{traversal} {method:?}");
            // The brick levels are read only with the index's own words.
            let words = tree.brick_tag_words();
            assert!(ctx.masks.is_none_or(|m| std::ptr::eq(m.parts().0.words().0.as_ptr(), words.as_ptr())));
            assert_eq!(ctx.masks.is_some(), method.has_masks());
            // Planes come with masks: the walks' plane tests are compared
            // too (and below, shown to pass segments over).
            assert_eq!(ctx.planes.is_some(), method.has_masks(), "{traversal} {method:?}: planes");
            let mut sc_plain = sc.clone();
            sc_plain.render.skip_clear_segments = false;
            let plain = Ctx::new(&sc_plain, &prep, f.as_ref());
            assert!(plain.planes.is_none());
            let cubes = budget.map(|b| Proximity::build_within(tree.tags(), b));
            if let Some(p) = &cubes {
                assert_eq!(p.is_octant(), budget > Some(0));
                assert!(distance_layout_fits(&ctx, p));
            }
            // The scalar walk and the lane walk over the same space.
            let scalar = |rays: &mut Rays, input: &[u32], s: &mut Queue, r: &mut Queue, c: &mut Counters| {
                match &cubes {
                    Some(p) => walk_interleaved(&ctx, DistanceCubes::new(p), rays, input, s, r, c),
                    None => {
                        let octree = OctreeBlocks { tree, leaf_level: *leaf_level };
                        walk_interleaved(&ctx, octree, rays, input, s, r, c)
                    }
                }
            };
            let lanes = |rays: &mut Rays, input: &[u32], s: &mut Queue, r: &mut Queue, c: &mut Counters| {
                // SAFETY: the CPU has the features (the caller's contract);
                // the layouts fit.
                unsafe {
                    match &cubes {
                        Some(p) => S::distance(&ctx, p, rays, input, s, r, c),
                        None => S::octree(&ctx, (tree, *leaf_level), brick_levels, rays, input, s, r, c),
                    }
                }
            };
            let bump = Bump::new();
            let n = 3000;
            let mut rays = Rays::with_capacity_in(n, false, &bump);
            let u = |k: u64, j: u64| uniform(mix64(seed * 100_003 + k), j);
            for k in 0..n as u64 {
                let o = DVec3::new(u(k, 0), u(k, 1), u(k, 2)) * 26.0 - DVec3::splat(1.0);
                let mut d: [f64; 3] = std::array::from_fn(|a| 2.0 * u(k, 3 + a as u64) - 1.0);
                if k.is_multiple_of(7) {
                    let a = (k / 7 % 3) as usize;
                    d[a] = odd[(k / 21) as usize % odd.len()];
                }
                if k.is_multiple_of(11) {
                    d = [0.0, 0.0, 0.0].map(|_| 0.0);
                    d[(k / 11 % 3) as usize] = if k.is_multiple_of(2) { 1.0 } else { -1.0 };
                }
                // Through edges and corners: from cell centres along
                // diagonals, where exit times tie exactly.
                let o = if k.is_multiple_of(13) {
                    d = [0, 1, 2].map(|a| if u(k, 9 + a) < 0.5 { -1.0 } else { 1.0 });
                    if k.is_multiple_of(26) {
                        d[2] = 0.5;
                    }
                    o.floor() + DVec3::splat(0.5)
                } else {
                    o
                };
                rays.push((k as u32, k as u32), 1.0, true, o, DVec3::from_array(d));
            }
            rays.complete();
            let mut c = Counters::default();
            for i in 0..n {
                let k = i as u64;
                let t_end = 40.0 * u(k, 6) - 2.0;
                super::super::place::<4, _>(&ctx, &mut rays, i, (0.0, 0.0), t_end, &mut c);
                rays.advance[i] = k.is_multiple_of(5);
            }
            let mut input: Vec<u32> = (0..n as u32).collect();
            let (mut solved, mut rounds) = (0, 0);
            while !input.is_empty() {
                rounds += 1;
                let mut a = rays.clone();
                let mut b = rays.clone();
                let (mut sa, mut ra) = (Queue::new_in(&bump), Queue::new_in(&bump));
                let (mut sb, mut rb) = (Queue::new_in(&bump), Queue::new_in(&bump));
                let (mut ca, mut cb) = (Counters::default(), Counters::default());
                scalar(&mut a, &input, &mut sa, &mut ra, &mut ca);
                lanes(&mut b, &input, &mut sb, &mut rb, &mut cb);
                if ctx.planes.is_some() {
                    // The scalar walk without planes skips fewer cells.
                    let mut x = rays.clone();
                    let (mut sx, mut rx) = (Queue::new_in(&bump), Queue::new_in(&bump));
                    let mut cx = Counters::default();
                    match &cubes {
                        Some(p) => walk_interleaved(&plain, DistanceCubes::new(p), &mut x, &input, &mut sx, &mut rx, &mut cx),
                        None => {
                            let octree = OctreeBlocks { tree, leaf_level: *leaf_level };
                            walk_interleaved(&plain, octree, &mut x, &input, &mut sx, &mut rx, &mut cx)
                        }
                    }
                    assert!(ca.subcell_skips >= cx.subcell_skips);
                    *passed.entry(traversal).or_default() += ca.subcell_skips - cx.subcell_skips;
                }
                let sorted = |q: &Queue| {
                    let mut v = q.to_vec();
                    v.sort_unstable();
                    v
                };
                assert_eq!(sorted(&sa), sorted(&sb), "{traversal} {method:?} round {rounds}");
                assert_eq!(sorted(&ra), sorted(&rb), "{traversal} {method:?} round {rounds}");
                assert_eq!(
                    (ca.cells_visited, ca.subcell_skips),
                    (cb.cells_visited, cb.subcell_skips)
                );
                for &r in &input {
                    let i = r as usize;
                    let bits = |x: &Rays| {
                        (x.t[i].to_bits(), x.seg_end[i].to_bits(), x.cell_of(i), x.fate[i], x.advance[i])
                    };
                    assert_eq!(bits(&a), bits(&b), "ray {i} round {rounds}");
                }
                solved += sa.len();
                rays = b;
                for &r in sb.iter() {
                    rays.advance[r as usize] = true;
                }
                input = sb.to_vec();
            }
            assert!(solved > 2000 && rounds > 3, "{traversal} {method:?}: {solved} solves in {rounds} rounds");
        });
    }
    // The planes' tests were compared where they passed segments over.
    for traversal in ["octree", "dda", "distance"] {
        assert!(
            passed.get(traversal).is_some_and(|&n| n > 0),
            "{traversal}: {passed:?}"
        );
    }
}

/// The shifted spans are the scalar walk's table.
fn spans_are_the_table_of_the_scalar_walk<S: LaneIsa>() {
    for (a, &(rep, log)) in SPAN_ROWS.iter().enumerate() {
        for lo in 0..SUB {
            for hi in lo..SUB {
                // SAFETY: the CPU has the features (the caller's contract).
                let got = unsafe {
                    let v = axis_span::<S>(rep, log, S::splat_i(lo as i64), S::splat_i(hi as i64));
                    let mut out = [0; MAX_LANES];
                    S::store_i(v, &mut out);
                    out[S::LANES - 1] as u64
                };
                assert_eq!(got, AXIS_SPAN[a][lo][hi], "axis {a} {lo}..={hi}");
            }
        }
    }
}

/// The conversions' edge cases: the exact integer conversion at zero,
/// negatives and large values, and the clamped floor at integers, just
/// off them, NaN and infinities, against the scalar walk's; the population
/// count.
fn conversions_are_the_scalar_ones<S: LaneIsa>() {
    let ints = [
        0i64,
        1,
        -1,
        7,
        -8,
        1 << 40,
        -(1 << 40),
        (1 << 51) - 1,
        -(1 << 51) + 1,
    ];
    let last = S::LANES - 1;
    for &x in &ints {
        let mut out = [0.0; MAX_LANES];
        // SAFETY: as above.
        unsafe { S::store(S::to_f(S::splat_i(x)), &mut out) };
        assert_eq!(out[last].to_bits(), (x as f64).to_bits(), "{x}");
    }
    let xs = [
        0.0,
        -0.0,
        0.5,
        1.0,
        1.0 - 1e-16,
        2.999_999_999,
        3.0,
        3.5,
        -0.3,
        -5.0,
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        1e300,
    ];
    for &x in &xs {
        for (lo, hi) in [(0.0, 3.0), (2.0, 2.0), (-1.0, -1.0), (0.0, 1e6), (5.0, 9.0)] {
            let mut out = [0; MAX_LANES];
            // SAFETY: as above.
            unsafe {
                let v = S::clamped_floor(S::splat(x), S::splat(lo), S::splat(hi));
                S::store_i(v, &mut out);
            }
            assert_eq!(out[last], clamped_floor(x, lo, hi), "{x} in [{lo}, {hi}]");
        }
    }
    for v in [
        0u64,
        1,
        u64::MAX,
        0x8000_0000_0000_0001,
        0x0123_4567_89ab_cdef,
    ] {
        let mut out = [0; MAX_LANES];
        // SAFETY: as above.
        unsafe { S::store_i(S::popcnt(S::splat_i(v as i64)), &mut out) };
        assert_eq!(out[last] as u64, v.count_ones() as u64, "{v:x}");
    }
}
