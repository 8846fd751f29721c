//! The lane walk ([`super::lanes`]) eight rays at a time, with AVX-512:
//! lane masks are mask registers, conversions between `f64` and `i64` are
//! single instructions, a refill is one masked expand per column, and the
//! planes' test runs in lanes.
//!
//! At 9b25384 (the octree alone) the whole walk was 652 instructions and a
//! step ran through part of them once for about 7 live lanes, so under 100
//! instructions per visit against the scalar walk's 230. What it buys is
//! smaller than the instruction counts suggest, likely because Zen 4 runs
//! a 512-bit operation as two 256-bit halves and the gathers are slow.
//! Sphere, single thread, min / median of 5 alternating runs: the traverse
//! stage 55.4 / 58.8 → 33.9 / 34.5 ms, the frame 139 / 144 → 119 / 120 ms
//! (BENCHMARKS.md has the runs). Over the distance cubes, single thread,
//! traverse stage, min of 3 alternating runs against the scalar distance
//! walk: sphere 44.3 → 25.8 ms, teapot 209 → 143, cranium 127 → 80 — below
//! the octree's lane walk (36, 148, 110) since a ray visits fewer cells
//! (sphere 5.35 per ray against 11.3).

use std::arch::x86_64::*;
use std::sync::OnceLock;

use super::super::super::context::Ctx;
use super::super::super::packet::{Queue, Rays};
use super::lanes::{self, LaneIsa, LaneReach, MAX_LANES, Space, Staged};
use crate::classify::plane::CellTests;
use crate::filter::coeffs::Coefficient;
use crate::octree::Octree;
use crate::octree::distance::Proximity;
use crate::render::stats::Counters;

/// AVX-512 F, VL, DQ and VPOPCNTDQ, with BMI2 (eight lanes).
#[derive(Clone, Copy)]
pub(crate) struct Avx512;

/// Eight walks in registers (also the refract stage's lane clearing).
pub(crate) type Lanes = lanes::Lanes<Avx512>;

/// Whether this CPU runs the wide walk: AVX-512 (F, DQ) with the
/// vector population count the tagged-cell index needs, when the renderer
/// runs its AVX-512 lanes ([`crate::simd::Isa::current`], so `SNELL_ISA`
/// below `avx512` selects another walk).
pub fn available() -> bool {
    static OK: OnceLock<bool> = OnceLock::new();
    *OK.get_or_init(|| {
        crate::simd::Isa::current() == crate::simd::Isa::Avx512
            && std::arch::is_x86_feature_detected!("avx512vpopcntdq")
    })
}

/// Whether the wide walk can run over `tree` in `ctx`: the CPU has the
/// features ([`available`]), and the skip map, brick levels, tag words
/// and the sub-cell masks' index cover the lattice in one brick layout
/// ([`lanes::layout_fits`]).
pub fn fits<T: Coefficient>(ctx: &Ctx<T>, tree: &Octree) -> bool {
    available() && lanes::layout_fits(ctx, tree)
}

/// [`fits`] for the distance cubes of `p`.
pub fn fits_distance<T: Coefficient>(ctx: &Ctx<T>, p: &Proximity) -> bool {
    available() && lanes::distance_layout_fits(ctx, p)
}

/// [`lanes::exit_box`] in eight lanes, for the refract stage's clearing.
///
/// # Safety
/// AVX-512 F, VL and DQ.
#[inline(always)]
pub(crate) unsafe fn exit_box(
    l: &Lanes,
    lo: [__m512i; 3],
    hi: [__m512i; 3],
) -> (__m512d, [__m512i; 3]) {
    // SAFETY: the caller's contract.
    unsafe { lanes::exit_box(l, lo, hi) }
}

/// `col[r]` in the lanes of `m`, 0 in the others.
///
/// # Safety
/// AVX-512 F; every lane of `m` indexes `col`.
#[inline(always)]
unsafe fn gather_pd(col: &[f64], r: __m512i, m: __mmask8) -> __m512d {
    // SAFETY: the caller's contract.
    unsafe { _mm512_mask_i64gather_pd::<8>(_mm512_setzero_pd(), m, r, col.as_ptr()) }
}

impl Lanes {
    /// The rays `r` (lanes of `m`; the others zero) as [`super::cell_ray`]
    /// puts them in cell coordinates — scaled, then offset, no fused
    /// multiply-add — with their cells, parameters and pieces, each column
    /// one gather by ray index.
    ///
    /// # Safety
    /// AVX-512 F, VL and DQ; every lane of `m` holds a ray index below the
    /// rays' count.
    #[inline(always)]
    pub(crate) unsafe fn gather<T: Coefficient>(
        ctx: &Ctx<T>,
        rays: &Rays,
        r: __m512i,
        m: __mmask8,
    ) -> Lanes {
        // SAFETY: the caller's contract.
        unsafe {
            let off = _mm512_set1_pd(ctx.lattice.offset);
            let mut l = Lanes {
                r,
                ou: [_mm512_setzero_pd(); 3],
                du: [_mm512_setzero_pd(); 3],
                inv: [_mm512_setzero_pd(); 3],
                cell: [_mm512_setzero_si512(); 3],
                t: gather_pd(&rays.t, r, m),
                t_start: gather_pd(&rays.t_start, r, m),
                t_end: gather_pd(&rays.t_end, r, m),
            };
            for a in 0..3 {
                let sa = _mm512_set1_pd(ctx.inv_spacing[a]);
                l.ou[a] = _mm512_add_pd(_mm512_mul_pd(gather_pd(&rays.org[a], r, m), sa), off);
                l.du[a] = _mm512_mul_pd(gather_pd(&rays.dir[a], r, m), sa);
                l.inv[a] = gather_pd(&rays.cell_inv[a], r, m);
                l.cell[a] = _mm512_cvtepi32_epi64(_mm512_mask_i64gather_epi32::<4>(
                    _mm256_setzero_si256(),
                    m,
                    r,
                    rays.cell[a].as_ptr(),
                ));
            }
            l
        }
    }
}

/// The plane `p` (offset, then the gradient's three components) at
/// parameter `t` of each lane's ray, in its cell's coordinates, as
/// [`crate::classify::PlaneBounds::clears`] evaluates it (a function, not
/// a closure: see [`LaneIsa`]).
///
/// # Safety
/// AVX-512 F and DQ.
#[inline(always)]
unsafe fn plane_at(p: &[__m512d; 6], l: &Lanes, t: __m512d) -> __m512d {
    // SAFETY: the caller's contract.
    unsafe {
        let mut v = p[0];
        for a in 0..3 {
            let u = _mm512_sub_pd(
                _mm512_add_pd(l.ou[a], _mm512_mul_pd(t, l.du[a])),
                _mm512_cvtepi64_pd(l.cell[a]),
            );
            v = _mm512_add_pd(v, _mm512_mul_pd(p[1 + a], u));
        }
        v
    }
}

// SAFETY: eight lanes, at most `MAX_LANES`; the gathers are masked and
// `expand` loads eight values. Every method is called only from functions
// compiled with the features (the walk methods below, `stage`, and the
// refract stage's clearing) or from the lane check on a CPU that has them.
unsafe impl LaneIsa for Avx512 {
    const LANES: usize = 8;
    type F = __m512d;
    type I = __m512i;
    type M = __mmask8;
    type Expand = __mmask8;

    #[inline(always)]
    unsafe fn splat(x: f64) -> __m512d {
        unsafe { _mm512_set1_pd(x) }
    }
    #[inline(always)]
    unsafe fn add(a: __m512d, b: __m512d) -> __m512d {
        unsafe { _mm512_add_pd(a, b) }
    }
    #[inline(always)]
    unsafe fn sub(a: __m512d, b: __m512d) -> __m512d {
        unsafe { _mm512_sub_pd(a, b) }
    }
    #[inline(always)]
    unsafe fn mul(a: __m512d, b: __m512d) -> __m512d {
        unsafe { _mm512_mul_pd(a, b) }
    }
    #[inline(always)]
    unsafe fn min(a: __m512d, b: __m512d) -> __m512d {
        unsafe { _mm512_min_pd(a, b) }
    }
    #[inline(always)]
    unsafe fn max(a: __m512d, b: __m512d) -> __m512d {
        unsafe { _mm512_max_pd(a, b) }
    }
    #[inline(always)]
    unsafe fn cmp<const P: i32>(a: __m512d, b: __m512d) -> __mmask8 {
        unsafe { _mm512_cmp_pd_mask::<P>(a, b) }
    }
    #[inline(always)]
    unsafe fn sel(m: __mmask8, yes: __m512d, no: __m512d) -> __m512d {
        unsafe { _mm512_mask_mov_pd(no, m, yes) }
    }

    #[inline(always)]
    unsafe fn splat_i(x: i64) -> __m512i {
        unsafe { _mm512_set1_epi64(x) }
    }
    #[inline(always)]
    unsafe fn add_i(a: __m512i, b: __m512i) -> __m512i {
        unsafe { _mm512_add_epi64(a, b) }
    }
    #[inline(always)]
    unsafe fn sub_i(a: __m512i, b: __m512i) -> __m512i {
        unsafe { _mm512_sub_epi64(a, b) }
    }
    #[inline(always)]
    unsafe fn and_i(a: __m512i, b: __m512i) -> __m512i {
        unsafe { _mm512_and_si512(a, b) }
    }
    #[inline(always)]
    unsafe fn or_i(a: __m512i, b: __m512i) -> __m512i {
        unsafe { _mm512_or_si512(a, b) }
    }
    #[inline(always)]
    unsafe fn shl(a: __m512i, n: __m512i) -> __m512i {
        unsafe { _mm512_sllv_epi64(a, n) }
    }
    #[inline(always)]
    unsafe fn shr(a: __m512i, n: __m512i) -> __m512i {
        unsafe { _mm512_srlv_epi64(a, n) }
    }
    #[inline(always)]
    unsafe fn mul_small(a: __m512i, b: __m512i) -> __m512i {
        unsafe { _mm512_mullo_epi64(a, b) }
    }
    #[inline(always)]
    unsafe fn popcnt(a: __m512i) -> __m512i {
        unsafe { _mm512_popcnt_epi64(a) }
    }
    #[inline(always)]
    unsafe fn eq_i(a: __m512i, b: __m512i) -> __mmask8 {
        unsafe { _mm512_cmpeq_epi64_mask(a, b) }
    }
    #[inline(always)]
    unsafe fn gt_i(a: __m512i, b: __m512i) -> __mmask8 {
        unsafe { _mm512_cmpgt_epi64_mask(a, b) }
    }
    #[inline(always)]
    unsafe fn test(a: __m512i, b: __m512i) -> __mmask8 {
        unsafe { _mm512_test_epi64_mask(a, b) }
    }
    #[inline(always)]
    unsafe fn in_range(x: __m512i, n: __m512i) -> __mmask8 {
        // A negative `x` is above any `n` below 2⁶³ unsigned.
        unsafe { _mm512_cmplt_epu64_mask(x, n) }
    }
    #[inline(always)]
    unsafe fn sel_i(m: __mmask8, yes: __m512i, no: __m512i) -> __m512i {
        unsafe { _mm512_mask_mov_epi64(no, m, yes) }
    }
    #[inline(always)]
    unsafe fn max_i(a: __m512i, b: __m512i) -> __m512i {
        unsafe { _mm512_max_epi64(a, b) }
    }
    #[inline(always)]
    unsafe fn min_i(a: __m512i, b: __m512i) -> __m512i {
        unsafe { _mm512_min_epi64(a, b) }
    }
    #[inline(always)]
    unsafe fn to_f(x: __m512i) -> __m512d {
        unsafe { _mm512_cvtepi64_pd(x) }
    }
    #[inline(always)]
    unsafe fn clamped_floor(x: __m512d, lo: __m512d, hi: __m512d) -> __m512i {
        unsafe { _mm512_cvttpd_epi64(_mm512_min_pd(_mm512_max_pd(x, lo), hi)) }
    }

    #[inline(always)]
    unsafe fn mask(bits: u32) -> __mmask8 {
        bits as __mmask8
    }
    #[inline(always)]
    unsafe fn bits(m: __mmask8) -> u32 {
        m as u32
    }
    #[inline(always)]
    unsafe fn and_m(a: __mmask8, b: __mmask8) -> __mmask8 {
        a & b
    }
    #[inline(always)]
    unsafe fn or_m(a: __mmask8, b: __mmask8) -> __mmask8 {
        a | b
    }
    #[inline(always)]
    unsafe fn and_not_m(a: __mmask8, b: __mmask8) -> __mmask8 {
        a & !b
    }

    #[inline(always)]
    unsafe fn gather_i64(base: *const i64, index: __m512i, m: __mmask8) -> __m512i {
        unsafe { _mm512_mask_i64gather_epi64::<8>(_mm512_setzero_si512(), m, index, base) }
    }
    #[inline(always)]
    unsafe fn gather_u32(base: *const u32, index: __m512i, m: __mmask8) -> __m512i {
        unsafe {
            _mm512_cvtepu32_epi64(_mm512_mask_i64gather_epi32::<4>(
                _mm256_setzero_si256(),
                m,
                index,
                base as *const i32,
            ))
        }
    }
    #[inline(always)]
    unsafe fn store(v: __m512d, to: &mut [f64; MAX_LANES]) {
        unsafe { _mm512_storeu_pd(to.as_mut_ptr(), v) }
    }
    #[inline(always)]
    unsafe fn store_i(v: __m512i, to: &mut [i64; MAX_LANES]) {
        unsafe { _mm512_storeu_epi64(to.as_mut_ptr(), v) }
    }
    #[inline(always)]
    unsafe fn expander(take: u32) -> __mmask8 {
        take as __mmask8
    }
    #[inline(always)]
    unsafe fn expand(old: __m512d, take: __mmask8, from: *const f64) -> __m512d {
        unsafe { _mm512_mask_expand_pd(old, take, _mm512_loadu_pd(from)) }
    }
    #[inline(always)]
    unsafe fn expand_i(old: __m512i, take: __mmask8, from: *const i64) -> __m512i {
        unsafe { _mm512_mask_expand_epi64(old, take, _mm512_loadu_epi64(from)) }
    }

    /// Eight rays at a time: each column is a gather by ray index, and the
    /// rays to step past their cell first do it in lanes ([`exit_box`] of
    /// the cell alone is [`super::exit_cell`], tested). Staged one ray at a
    /// time this was a fifth of the distance walk's samples (3.9% of the
    /// sphere's frame against 13.7% for the walk); in lanes the traverse
    /// stage went 23.5 → 22.3 ms (min of 5).
    #[target_feature(enable = "avx512f,avx512vl,avx512dq")]
    unsafe fn stage<T: Coefficient>(
        staged: &mut Staged,
        ctx: &Ctx<T>,
        rays: &mut Rays,
        input: &[u32],
    ) {
        debug_assert!(input.len() <= lanes::CHUNK);
        for (g, group) in input.chunks(Self::LANES).enumerate() {
            let k = g * Self::LANES;
            let m = ((1u32 << group.len()) - 1) as __mmask8;
            // SAFETY: `group` holds the lanes of `m`; every ray index is
            // below the rays' count, so each gather lane of `m` reads inside
            // its column; each staged column holds `k + LANES` values.
            unsafe {
                let r = _mm512_cvtepu32_epi64(_mm256_maskz_loadu_epi32(
                    m,
                    group.as_ptr() as *const i32,
                ));
                let mut advance: __mmask8 = 0;
                for (l, &i) in group.iter().enumerate() {
                    let i = i as usize;
                    advance |= (rays.advance[i] as u8) << l;
                    rays.advance[i] = false;
                }
                let mut l = Lanes::gather(ctx, rays, r, m);
                if advance != 0 {
                    let (t, next) = exit_box(&l, l.cell, l.cell);
                    l.t = _mm512_mask_mov_pd(l.t, advance, t);
                    for a in 0..3 {
                        l.cell[a] = _mm512_mask_mov_epi64(l.cell[a], advance, next[a]);
                    }
                }
                let at = |col: &mut lanes::Col<f64>| col.as_mut_ptr().add(k);
                _mm512_storeu_epi64(staged.r.as_mut_ptr().add(k), l.r);
                for a in 0..3 {
                    _mm512_storeu_pd(at(&mut staged.ou[a]), l.ou[a]);
                    _mm512_storeu_pd(at(&mut staged.du[a]), l.du[a]);
                    _mm512_storeu_pd(at(&mut staged.inv[a]), l.inv[a]);
                    _mm512_storeu_epi64(staged.cell[a].as_mut_ptr().add(k), l.cell[a]);
                }
                _mm512_storeu_pd(at(&mut staged.t), l.t);
                _mm512_storeu_pd(at(&mut staged.t_start), l.t_start);
                _mm512_storeu_pd(at(&mut staged.t_end), l.t_end);
            }
        }
        staged.len = input.len();
    }

    /// In lanes: each plane is three gathers of pairs (the record's words 1
    /// to 3), evaluated as [`crate::classify::PlaneBounds::clears`] does
    /// for one (the same operations in the same order).
    #[inline(always)]
    unsafe fn plane_clears(
        (tests, margin): (&[CellTests], f64),
        l: &Lanes,
        (t0, t1): (__m512d, __m512d),
        record: __m512i,
        m: __mmask8,
    ) -> __mmask8 {
        // SAFETY: the lanes of `m` hold records of tagged cells, below the
        // records' count.
        unsafe {
            let base = _mm512_add_epi64(record, _mm512_set1_epi64(1));
            let evens_then_odds =
                _mm512_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14, 1, 3, 5, 7, 9, 11, 13, 15);
            let mut p = [_mm512_setzero_pd(); 6];
            for k in 0..3 {
                let pairs = _mm512_mask_i64gather_epi64::<8>(
                    _mm512_setzero_si512(),
                    m,
                    _mm512_add_epi64(base, _mm512_set1_epi64(k as i64)),
                    tests.as_ptr() as *const i64,
                );
                let split = _mm512_permutexvar_ps(evens_then_odds, _mm512_castsi512_ps(pairs));
                p[2 * k] = _mm512_cvtps_pd(_mm512_castps512_ps256(split));
                p[2 * k + 1] = _mm512_cvtps_pd(_mm256_castpd_ps(_mm512_extractf64x4_pd::<1>(
                    _mm512_castps_pd(split),
                )));
            }
            let e = _mm512_add_pd(p[4], _mm512_set1_pd(margin));
            let ne = _mm512_sub_pd(_mm512_setzero_pd(), e);
            let (v0, v1) = (plane_at(&p, l, t0), plane_at(&p, l, t1));
            let above =
                _mm512_cmp_pd_mask::<_CMP_GT_OQ>(v0, e) & _mm512_cmp_pd_mask::<_CMP_GT_OQ>(v1, e);
            let below =
                _mm512_cmp_pd_mask::<_CMP_LT_OQ>(v0, ne) & _mm512_cmp_pd_mask::<_CMP_LT_OQ>(v1, ne);
            m & (above | below)
        }
    }

    lanes::walk_methods!("avx512f,avx512vl,avx512dq,avx512vpopcntdq,bmi2,popcnt");
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every ray walks as in the scalar walk, the octree's blocks read from
    /// the brick levels and from the byte map; the spans and conversions
    /// are the scalar walk's ([`super::super::lane_check`]).
    #[test]
    fn lanes_are_the_scalar_walk() {
        if !crate::simd::kernels_run("the AVX-512 walk", available()) {
            return;
        }
        super::super::lane_check::check_isa::<Avx512>();
    }
}
