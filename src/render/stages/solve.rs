//! Stage 4: find the crossing in the segment the traversal handed over.
//!
//! - cell segments (`dda`, `octree`): restrict the field to the segment (an
//!   exact polynomial), certify or isolate its sign changes by Bernstein
//!   subdivision — a crossing inside the cell cannot be missed, two close
//!   ones at a silhouette included — and refine: a segment with a single
//!   certified crossing (nearly all) by Newton in lanes with the others of
//!   its group, isolated ones by Brent;
//! - step brackets (`step`): Brent on point evaluations, as the paper does.
//!
//! A found crossing goes to refraction; otherwise the ray goes back to the
//! traversal, past this segment.

use super::super::context::Ctx;
use super::super::packet::{Queue, Rays};
use super::entry::set_side;
use super::field_minus_iso;
use crate::filter::coeffs::Coefficient;
use crate::filter::restrict::LaneSegments;
use crate::render::stats::Counters;
use crate::roots::bernstein::{
    Interval, IsolationWork, MAX_DEGREE, lane_sides, lane_single_crossing, lane_stays, refine_lanes,
};
use crate::roots::{brent, inside};
use crate::scene::Traversal;
use crate::simd::{Isa, Madd, prefetch};
use crate::with_isa;

pub fn solve<const S: usize, T: Coefficient>(
    ctx: &Ctx<T>,
    rays: &mut Rays,
    input: &[u32],
    refract: &mut Queue,
    traverse: &mut Queue,
    c: &mut Counters,
) {
    match ctx.traversal() {
        Traversal::Step => {
            for &r in input {
                solve_bracket::<S, _>(ctx, rays, r, refract, traverse, c);
            }
        }
        Traversal::Dda | Traversal::Octree | Traversal::Distance => {
            let isa = Isa::current();
            with_isa!(isa, L, M => solve_cells::<S, L, M, _>(ctx, rays, input, refract, traverse, c))
        }
    }
}

/// Cell segments in groups of `L` lanes: the restriction of the field to each
/// segment (straight from the cell's coefficient neighbourhood) and its
/// Bernstein form for the whole group in SIMD. Lanes whose Bernstein coefficients change sign once hold
/// exactly one crossing: they are refined together by Newton
/// ([`refine_lanes`]; single thread, sphere: 3.0 evaluations per crossing
/// where Brent took 4.0 before its polish's uncounted Newton steps, solve
/// stage 110 → 82 ms). Lanes with
/// more sign changes go on to scalar isolation and Brent.
///
/// A cubic's coefficient rows are read as one vector per lane and transposed
/// in registers instead of one hardware gather per coefficient (same values;
/// single-thread sphere solve stage 79 → 70 ms).
///
/// Restricting from the coefficients costs more multiply-adds than from a
/// precomputed power-basis patch per cell, but measured faster on every scene
/// (single-thread solve stage: sphere −28%, teapot −16%, cranium −22%), since a patch is 512
/// bytes per cell to gather and the coefficients are already in cache.
///
/// A segment is the cell's slab interval clipped to the ray's current piece,
/// and the restriction depends on the cell and the segment alone, so every
/// traversal (DDA, octree, distance) solves a given cell identically.
#[inline(always)]
fn solve_cells<const S: usize, const L: usize, M: Madd, T: Coefficient>(
    ctx: &Ctx<T>,
    rays: &mut Rays,
    input: &[u32],
    refract: &mut Queue,
    traverse: &mut Queue,
    c: &mut Counters,
) {
    // Grown only by the rare lanes that need isolation.
    let mut stack: Vec<Interval> = Vec::new();
    let d = ctx.basis.degree();
    let coeffs = ctx.field.coeffs();
    let data = coeffs.data();
    let rows = [coeffs.stride(1), coeffs.stride(2)];
    // Small grids stay in cache, where the prefetches only cost (sphere
    // 64³: solve stage +7%).
    let far = std::mem::size_of_val(data) > PREFETCH_ABOVE;
    // Every group writes the rows `0..=d` of both; the rows above stay zero.
    // Zeroed once here rather than per group (two `memset` calls of 1.4 KiB
    // per group were 1.4% of the sphere's frame).
    let mut mono = [[0.0; L]; MAX_DEGREE + 1];
    let mut bern = [[0.0; L]; MAX_DEGREE + 1];
    let groups = input.chunks(L);
    let mut ahead = input.chunks(L).skip(1);
    for group in groups {
        if let Some(next) = ahead.next().filter(|_| far) {
            prefetch_rows::<S, T>(ctx, rays, next, data, rows);
        }
        let (seg, span) = segments::<L, T>(ctx, rays, group);
        ctx.field
            .restrict_lanes::<S, L, M>(&seg, ctx.iso, &mut mono);
        ctx.basis.bernstein_lanes_into::<L, M>(&mono, &mut bern);
        let sides = lane_sides(&bern, d);
        // Lanes with one certified crossing are refined together.
        let mut single = [false; L];
        for (l, &r) in group.iter().enumerate() {
            let i = r as usize;
            if span.len[l] > 1e-13 {
                if !rays.side_known[i] {
                    set_side::<S, _>(ctx, rays, i, c);
                }
                single[l] = lane_single_crossing(sides[l], d, rays.inside[i]);
            }
        }
        let (roots, evals) = if single.iter().any(|&s| s) {
            refine_lanes::<L, M>(&mono, &bern, &sides, d, single)
        } else {
            ([0.0; L], [0; L])
        };
        for (l, &r) in group.iter().enumerate() {
            let i = r as usize;
            let (t0, t1, len) = (span.t0[l], span.t1[l], span.len[l]);
            c.cells_solved += 1;
            let mut hit = None;
            if single[l] {
                c.isolation_intervals += 1;
                c.brent_iters += evals[l] as u64;
                hit = Some(roots[l]);
            } else if len > 1e-13 {
                let from_inside = rays.inside[i];
                if lane_stays(sides[l], d, from_inside) {
                    c.isolation_intervals += 1;
                } else {
                    let poly = ctx.basis.lane(&mono, &bern, l);
                    let tol = (ctx.settings.tolerance / len).min(0.25);
                    let mut work = IsolationWork::default();
                    hit = poly.first_crossing_with(from_inside, tol, &mut work, &mut stack);
                    c.isolation_intervals += work.intervals as u64;
                    c.brent_iters += work.brent_iters as u64;
                }
            }
            match hit {
                Some(s) => {
                    c.cells_with_crossing += 1;
                    rays.t[i] = t0 + s * (t1 - t0);
                    refract.push(r);
                }
                None => {
                    rays.t[i] = t1;
                    rays.advance[i] = true;
                    traverse.push(r);
                }
            }
        }
    }
}

/// Each lane's segment ends and length (world units along the ray).
struct Spans<const L: usize> {
    t0: [f64; L],
    t1: [f64; L],
    len: [f64; L],
}

/// The segments of `group` (at most `L` rays) in lanes: each ray's segment
/// from the traversal (`t` to `seg_end` in its cell) in the cell's local
/// coordinates ([`Field::lane_segment`]), and its ends and length. Short
/// groups repeat their last ray; its lane results are ignored.
///
/// [`Field::lane_segment`]: crate::filter::Field::lane_segment
#[inline(always)]
fn segments<const L: usize, T: Coefficient>(
    ctx: &Ctx<T>,
    rays: &Rays,
    group: &[u32],
) -> (LaneSegments<L>, Spans<L>) {
    #[cfg(target_arch = "x86_64")]
    if L == 8 && Isa::current() == Isa::Avx512 {
        let mut idx = [0u32; 8];
        for (l, v) in idx.iter_mut().enumerate() {
            *v = group[l.min(group.len() - 1)];
        }
        let (mut seg, mut span) = empty_segments::<L>();
        // SAFETY: AVX-512 and L == 8 checked above; every index is a ray's.
        unsafe { segments_x8(ctx, rays, &idx, &mut seg, &mut span) };
        return (seg, span);
    }
    segments_scalar(ctx, rays, group)
}

#[inline(always)]
fn empty_segments<const L: usize>() -> (LaneSegments<L>, Spans<L>) {
    (
        LaneSegments::<L> {
            base: [0; L],
            tau: [[0.0; L]; 3],
            delta: [[0.0; L]; 3],
        },
        Spans {
            t0: [0.0; L],
            t1: [0.0; L],
            len: [0.0; L],
        },
    )
}

/// [`segments`] one ray at a time (any instruction set).
#[inline(always)]
fn segments_scalar<const L: usize, T: Coefficient>(
    ctx: &Ctx<T>,
    rays: &Rays,
    group: &[u32],
) -> (LaneSegments<L>, Spans<L>) {
    let (mut seg, mut span) = empty_segments::<L>();
    for l in 0..L {
        let i = group[l.min(group.len() - 1)] as usize;
        let og = ctx.to_grid(rays.origin(i));
        let dg = ctx.to_grid(rays.direction(i));
        let cell = rays.cell_of(i);
        // The traversal's segment: the part of the cell from its first to
        // its last tagged sub-cell on this ray.
        let (t0, t1) = (rays.t[i], rays.seg_end[i]);
        let (p0, p1) = (og + t0 * dg, og + t1 * dg);
        let (base, ta, de) = ctx.field.lane_segment(cell, p0.to_array(), p1.to_array());
        seg.base[l] = base;
        for a in 0..3 {
            seg.tau[a][l] = ta[a];
            seg.delta[a][l] = de[a];
        }
        (span.t0[l], span.t1[l], span.len[l]) = (t0, t1, dg.length() * (t1 - t0));
    }
    (seg, span)
}

/// The scalar loop of [`segments`] for eight rays in AVX-512 lanes, its
/// operations in the same order (no fused multiply-adds), so the same
/// bits: the ray columns gathered by index, the neighbourhood offset from
/// the one of cell 0 (it is affine in the cell).
///
/// # Safety
/// AVX-512 F, VL and DQ; `L == 8`; every index is below the rays' count.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl,avx512dq")]
unsafe fn segments_x8<const L: usize, T: Coefficient>(
    ctx: &Ctx<T>,
    rays: &Rays,
    idx: &[u32; 8],
    seg: &mut LaneSegments<L>,
    span: &mut Spans<L>,
) {
    use std::arch::x86_64::*;
    let coeffs = ctx.field.coeffs();
    let strides = [1, coeffs.stride(1), coeffs.stride(2)];
    let origin = ctx.field.support_offset([0, 0, 0]);
    let off = _mm512_set1_pd(ctx.field.kernel().knot_offset());
    // SAFETY: the caller's contract; each array holds L = 8 values.
    unsafe {
        let r = _mm512_cvtepu32_epi64(_mm256_loadu_epi32(idx.as_ptr() as *const i32));
        let pd = |col: &[f64]| _mm512_i64gather_pd::<8>(r, col.as_ptr());
        let (t0, t1) = (pd(&rays.t), pd(&rays.seg_end));
        let mut base = _mm512_set1_epi64(origin as i64);
        let mut len2 = _mm512_setzero_pd();
        for a in 0..3 {
            let s = _mm512_set1_pd(ctx.inv_spacing[a]);
            let og = _mm512_mul_pd(pd(&rays.org[a]), s);
            let dg = _mm512_mul_pd(pd(&rays.dir[a]), s);
            let cell = _mm512_cvtepi32_epi64(_mm512_i64gather_epi32::<4>(r, rays.cell[a].as_ptr()));
            let p0 = _mm512_add_pd(og, _mm512_mul_pd(t0, dg));
            let p1 = _mm512_add_pd(og, _mm512_mul_pd(t1, dg));
            let ta = _mm512_sub_pd(_mm512_add_pd(p0, off), _mm512_cvtepi64_pd(cell));
            _mm512_storeu_pd(seg.tau[a].as_mut_ptr(), ta);
            _mm512_storeu_pd(seg.delta[a].as_mut_ptr(), _mm512_sub_pd(p1, p0));
            base = _mm512_add_epi64(
                base,
                _mm512_mullo_epi64(cell, _mm512_set1_epi64(strides[a] as i64)),
            );
            // `dg.length()`: x² + y², then + z².
            let sq = _mm512_mul_pd(dg, dg);
            len2 = if a == 0 { sq } else { _mm512_add_pd(len2, sq) };
        }
        let len = _mm512_mul_pd(_mm512_sqrt_pd(len2), _mm512_sub_pd(t1, t0));
        _mm512_storeu_epi64(seg.base.as_mut_ptr() as *mut i64, base);
        _mm512_storeu_pd(span.t0.as_mut_ptr(), t0);
        _mm512_storeu_pd(span.t1.as_mut_ptr(), t1);
        _mm512_storeu_pd(span.len.as_mut_ptr(), len);
    }
}

/// Coefficient bytes above which [`solve_cells`] prefetches: about a core's
/// L2 cache (4 MiB on this Xeon; less on many machines).
const PREFETCH_ABOVE: usize = 4 << 20;

/// Asks for the coefficient rows the segments of `group` will read (each
/// cell's `S²` rows of `S`), one group before they are restricted: on a
/// large volume the neighbourhoods are scattered across memory, and the
/// restriction would otherwise wait for each row in turn.
#[inline(always)]
fn prefetch_rows<const S: usize, T: Coefficient>(
    ctx: &Ctx<T>,
    rays: &Rays,
    group: &[u32],
    data: &[T],
    [sy, sz]: [usize; 2],
) {
    for &r in group {
        let base = ctx.field.support_offset(rays.cell_of(r as usize));
        for k in 0..S {
            for j in 0..S {
                let at = base + j * sy + k * sz;
                if let (Some(first), Some(last)) = (data.get(at), data.get(at + S - 1)) {
                    prefetch(first);
                    prefetch(last);
                }
            }
        }
    }
}

fn solve_bracket<const S: usize, T: Coefficient>(
    ctx: &Ctx<T>,
    rays: &mut Rays,
    r: u32,
    refract: &mut Queue,
    traverse: &mut Queue,
    c: &mut Counters,
) {
    let i = r as usize;
    let (ta, tb) = (rays.t[i], rays.seg_end[i]);
    let (ga, gb) = (rays.seg_g[0][i], rays.seg_g[1][i]);
    c.cells_solved += 1;
    if inside(ga) == rays.inside[i] {
        let o = rays.origin(i);
        let d = rays.direction(i);
        let tol = ctx.settings.tolerance / ctx.to_grid(d).length();
        let mut evals = Counters::default();
        let root = brent::solve(
            |t| field_minus_iso::<S, _>(ctx, ctx.to_grid(o + t * d), &mut evals),
            ta,
            tb,
            ga,
            gb,
            tol,
        );
        c.kernel_evals += evals.kernel_evals;
        c.brent_iters += root.evals as u64;
        c.cells_with_crossing += 1;
        rays.t[i] = root.x;
        refract.push(r);
    } else {
        // A change back onto the ray's own side (it started a hair on the
        // wrong side after a refraction): step over it.
        rays.t[i] = tb;
        rays.seg_g[0][i] = gb;
        traverse.push(r);
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use bumpalo::Bump;
    use glam::DVec3;

    use super::*;
    use crate::classify::Method;
    use crate::phantom::{mix64, uniform};
    use crate::prepare::Prepared;
    use crate::with_field;

    /// The lane setup of the segments gives bitwise what the scalar loop
    /// gives: offsets, local coordinates, extents, ends and lengths, for
    /// full and short groups, rays along axes included, on a grid with
    /// anisotropic spacing.
    #[test]
    fn lane_segments_are_the_scalar_ones() {
        if !crate::simd::kernels_run("the AVX-512 solve lanes", Isa::current() == Isa::Avx512) {
            return;
        }
        let sc = crate::render::testing::small_scene(127.5, &[]);
        let m = 24;
        let samples = (0..m * m * m)
            .map(|k| {
                let p = [k % m, k / m % m, k / (m * m)].map(|v| v as f64 - 11.5);
                (255.0 - 20.0 * (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()) as f32
            })
            .collect();
        let volume = crate::volume::Volume::new(
            [m; 3],
            [1.0, 0.7, 1.3],
            crate::volume::SampleType::F32,
            samples,
        )
        .unwrap();
        let prep = Prepared::new(Arc::new(volume), sc.surface.filter)
            .with_accel(sc.surface.iso, Method::Bezier(2));
        with_field!(&prep.field, f => {
            let ctx = Ctx::new(&sc, &prep, f.as_ref());
            let bump = Bump::new();
            let n = 1003;
            let mut rays = Rays::with_capacity_in(n, false, &bump);
            let u = |k: u64, j: u64| uniform(mix64(k), j);
            for k in 0..n as u64 {
                let o = DVec3::new(u(k, 0) * 23.0, u(k, 1) * 16.0, u(k, 2) * 29.0);
                let mut d = DVec3::new(u(k, 3), u(k, 4), u(k, 5)) * 2.0 - DVec3::ONE;
                if k.is_multiple_of(5) {
                    d[(k / 5 % 3) as usize] = 0.0;
                }
                rays.push((k as u32, k as u32), 1.0, true, o, d.normalize());
            }
            rays.complete();
            let mut c = Counters::default();
            for i in 0..n {
                super::super::place::<4, _>(&ctx, &mut rays, i, (1e-3, 1e-3), 40.0, &mut c);
                rays.seg_end[i] = rays.t[i] + 1.7 * u(i as u64, 6);
            }
            let input: Vec<u32> = (0..n as u32).collect();
            for group in input.chunks(8) {
                let (sa, pa) = segments::<8, _>(&ctx, &rays, group);
                let (sb, pb) = segments_scalar::<8, _>(&ctx, &rays, group);
                let bits = |v: &[f64; 8]| v.map(f64::to_bits);
                assert_eq!(sa.base, sb.base);
                for a in 0..3 {
                    assert_eq!(bits(&sa.tau[a]), bits(&sb.tau[a]));
                    assert_eq!(bits(&sa.delta[a]), bits(&sb.delta[a]));
                }
                assert_eq!(bits(&pa.t0), bits(&pb.t0));
                assert_eq!(bits(&pa.t1), bits(&pb.t1));
                assert_eq!(bits(&pa.len), bits(&pb.len));
            }
        });
    }
}
