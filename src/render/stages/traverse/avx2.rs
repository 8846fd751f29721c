//! The lane walk ([`super::lanes`]) four rays at a time, for CPUs with
//! AVX2 that cannot run the AVX-512 walk (no AVX-512, or no VPOPCNTDQ),
//! and under `SNELL_ISA=avx2`.
//!
//! Without it such CPUs walked one ray at a time ([`super::walk_interleaved`]),
//! and the walk was the frame's largest stage: on an AVX2-only AMD EPYC,
//! single thread, sphere, 32% of the samples against 21% for the solve.
//! What AVX2 lacks is built from what it has:
//!
//! - no mask registers: a lane mask is a vector of all-ones or all-zeros
//!   lanes, blends select, and a `movemask` gives the bits the control flow
//!   needs;
//! - no conversions between `f64` and `i64`: lattice indices are small
//!   integers, converted exactly through the `1.5·2⁵²` constant (whose
//!   mantissa's last bit is one unit), and the clamped floors truncate with
//!   a rounding instruction first;
//! - no 64-bit multiply, compare unsigned, minimum or maximum: the brick
//!   index multiplies 32-bit halves (its factors are below 2³²), the range
//!   test is two signed compares, and blends pick the extremes;
//! - no vector population count: a nibble table (`vpshufb`) summed by
//!   `vpsadbw`;
//! - no expand: a refill permutes the staged columns with a table of 16
//!   patterns, one per set of free lanes.
//!
//! Rays are staged one at a time ([`Staged::stage_scalar`]), and the
//! planes' test runs lane by lane (the trait's default).

use std::arch::x86_64::*;
use std::sync::OnceLock;

use super::super::super::context::Ctx;
use super::super::super::packet::{Queue, Rays};
use super::lanes::{self, LaneIsa, LaneReach, MAX_LANES, Space, Staged};
use crate::filter::coeffs::Coefficient;
use crate::octree::Octree;
use crate::octree::distance::Proximity;
use crate::render::stats::Counters;

/// AVX2 with BMI1, BMI2, POPCNT and LZCNT (four lanes).
#[derive(Clone, Copy)]
pub(crate) struct Avx2;

/// Whether this CPU runs the AVX2 walk: it runs the renderer's AVX2 lanes
/// or better ([`crate::simd::Isa::current`], which also checks BMI and
/// POPCNT), and the AVX-512 walk cannot run ([`super::wide::available`]).
/// `SNELL_ISA=portable` selects the scalar walk.
pub fn available() -> bool {
    static OK: OnceLock<bool> = OnceLock::new();
    *OK.get_or_init(|| {
        crate::simd::Isa::current() != crate::simd::Isa::Portable && !super::wide::available()
    })
}

/// Whether the AVX2 walk can run over `tree` in `ctx` ([`super::wide::fits`]
/// for this CPU).
pub fn fits<T: Coefficient>(ctx: &Ctx<T>, tree: &Octree) -> bool {
    available() && lanes::layout_fits(ctx, tree)
}

/// [`fits`] for the distance cubes of `p`.
pub fn fits_distance<T: Coefficient>(ctx: &Ctx<T>, p: &Proximity) -> bool {
    available() && lanes::distance_layout_fits(ctx, p)
}

/// `1.5·2⁵²`: in `[2⁵², 2⁵³)` a double's last mantissa bit is one unit, so
/// adding an integer of magnitude below 2⁵¹ to its bits adds it to its value.
const MAGIC: f64 = 6_755_399_441_055_744.0;

/// `EXPAND[m]`: for the lanes of bit set `m`, in order, the dword indices
/// of the consecutive staged values `0, 1, …` they take (other lanes 0).
const EXPAND: [[i32; 8]; 16] = {
    let mut t = [[0i32; 8]; 16];
    let mut m = 0;
    while m < 16 {
        let mut j = 0;
        let mut k = 0;
        while k < 4 {
            if m >> k & 1 == 1 {
                t[m][2 * k] = 2 * j;
                t[m][2 * k + 1] = 2 * j + 1;
                j += 1;
            }
            k += 1;
        }
        m += 1;
    }
    t
};

/// The dword lanes 0, 2, 4, 6 of a lane mask: the mask of a gather of
/// 32-bit values by 64-bit indices.
#[inline(always)]
unsafe fn narrow(m: __m256i) -> __m128i {
    // SAFETY: called only from functions with AVX2.
    unsafe {
        _mm256_castsi256_si128(_mm256_permutevar8x32_epi32(
            m,
            _mm256_setr_epi32(0, 2, 4, 6, 0, 0, 0, 0),
        ))
    }
}

// SAFETY: four lanes, at most `MAX_LANES`; the gathers are masked and
// `expand` loads four values. Every method is called only from the walk
// methods below, compiled with the features, or from the lane check on a
// CPU that has them.
unsafe impl LaneIsa for Avx2 {
    const LANES: usize = 4;
    type F = __m256d;
    type I = __m256i;
    /// All-ones or all-zeros lanes.
    type M = __m256i;
    /// The lanes' mask and their permutation.
    type Expand = (__m256i, __m256i);

    #[inline(always)]
    unsafe fn splat(x: f64) -> __m256d {
        unsafe { _mm256_set1_pd(x) }
    }
    #[inline(always)]
    unsafe fn add(a: __m256d, b: __m256d) -> __m256d {
        unsafe { _mm256_add_pd(a, b) }
    }
    #[inline(always)]
    unsafe fn sub(a: __m256d, b: __m256d) -> __m256d {
        unsafe { _mm256_sub_pd(a, b) }
    }
    #[inline(always)]
    unsafe fn mul(a: __m256d, b: __m256d) -> __m256d {
        unsafe { _mm256_mul_pd(a, b) }
    }
    #[inline(always)]
    unsafe fn min(a: __m256d, b: __m256d) -> __m256d {
        unsafe { _mm256_min_pd(a, b) }
    }
    #[inline(always)]
    unsafe fn max(a: __m256d, b: __m256d) -> __m256d {
        unsafe { _mm256_max_pd(a, b) }
    }
    #[inline(always)]
    unsafe fn cmp<const P: i32>(a: __m256d, b: __m256d) -> __m256i {
        unsafe { _mm256_castpd_si256(_mm256_cmp_pd::<P>(a, b)) }
    }
    #[inline(always)]
    unsafe fn sel(m: __m256i, yes: __m256d, no: __m256d) -> __m256d {
        unsafe { _mm256_blendv_pd(no, yes, _mm256_castsi256_pd(m)) }
    }

    #[inline(always)]
    unsafe fn splat_i(x: i64) -> __m256i {
        unsafe { _mm256_set1_epi64x(x) }
    }
    #[inline(always)]
    unsafe fn add_i(a: __m256i, b: __m256i) -> __m256i {
        unsafe { _mm256_add_epi64(a, b) }
    }
    #[inline(always)]
    unsafe fn sub_i(a: __m256i, b: __m256i) -> __m256i {
        unsafe { _mm256_sub_epi64(a, b) }
    }
    #[inline(always)]
    unsafe fn and_i(a: __m256i, b: __m256i) -> __m256i {
        unsafe { _mm256_and_si256(a, b) }
    }
    #[inline(always)]
    unsafe fn or_i(a: __m256i, b: __m256i) -> __m256i {
        unsafe { _mm256_or_si256(a, b) }
    }
    #[inline(always)]
    unsafe fn shl(a: __m256i, n: __m256i) -> __m256i {
        unsafe { _mm256_sllv_epi64(a, n) }
    }
    #[inline(always)]
    unsafe fn shr(a: __m256i, n: __m256i) -> __m256i {
        unsafe { _mm256_srlv_epi64(a, n) }
    }
    #[inline(always)]
    unsafe fn mul_small(a: __m256i, b: __m256i) -> __m256i {
        unsafe { _mm256_mul_epu32(a, b) }
    }
    #[inline(always)]
    unsafe fn popcnt(v: __m256i) -> __m256i {
        unsafe {
            let table = _mm256_setr_epi8(
                0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4, 0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3,
                2, 3, 3, 4,
            );
            let low = _mm256_set1_epi8(0x0f);
            let lo = _mm256_shuffle_epi8(table, _mm256_and_si256(v, low));
            let hi = _mm256_shuffle_epi8(table, _mm256_and_si256(_mm256_srli_epi16::<4>(v), low));
            _mm256_sad_epu8(_mm256_add_epi8(lo, hi), _mm256_setzero_si256())
        }
    }
    #[inline(always)]
    unsafe fn eq_i(a: __m256i, b: __m256i) -> __m256i {
        unsafe { _mm256_cmpeq_epi64(a, b) }
    }
    #[inline(always)]
    unsafe fn gt_i(a: __m256i, b: __m256i) -> __m256i {
        unsafe { _mm256_cmpgt_epi64(a, b) }
    }
    #[inline(always)]
    unsafe fn test(a: __m256i, b: __m256i) -> __m256i {
        unsafe {
            let none = _mm256_cmpeq_epi64(_mm256_and_si256(a, b), _mm256_setzero_si256());
            _mm256_andnot_si256(none, _mm256_set1_epi64x(-1))
        }
    }
    #[inline(always)]
    unsafe fn in_range(x: __m256i, n: __m256i) -> __m256i {
        unsafe {
            let below_n = _mm256_cmpgt_epi64(n, x);
            let negative = _mm256_cmpgt_epi64(_mm256_setzero_si256(), x);
            _mm256_andnot_si256(negative, below_n)
        }
    }
    #[inline(always)]
    unsafe fn sel_i(m: __m256i, yes: __m256i, no: __m256i) -> __m256i {
        unsafe { _mm256_blendv_epi8(no, yes, m) }
    }
    /// Exact through [`MAGIC`] for `|x| < 2⁵¹`; `0` gives `+0.0`, as `as`
    /// does.
    #[inline(always)]
    unsafe fn to_f(x: __m256i) -> __m256d {
        unsafe {
            let magic = _mm256_set1_pd(MAGIC);
            _mm256_sub_pd(
                _mm256_castsi256_pd(_mm256_add_epi64(x, _mm256_castpd_si256(magic))),
                magic,
            )
        }
    }
    /// The clamp first (in the same operand order, so a NaN gives `lo`),
    /// then truncation: the clamp bounds are lattice indices, so the value
    /// is below 2⁵¹ in magnitude and converts exactly through [`MAGIC`].
    #[inline(always)]
    unsafe fn clamped_floor(x: __m256d, lo: __m256d, hi: __m256d) -> __m256i {
        unsafe {
            let v = _mm256_min_pd(_mm256_max_pd(x, lo), hi);
            let whole = _mm256_round_pd::<{ _MM_FROUND_TO_ZERO | _MM_FROUND_NO_EXC }>(v);
            let magic = _mm256_set1_pd(MAGIC);
            _mm256_sub_epi64(
                _mm256_castpd_si256(_mm256_add_pd(whole, magic)),
                _mm256_castpd_si256(magic),
            )
        }
    }

    #[inline(always)]
    unsafe fn mask(bits: u32) -> __m256i {
        unsafe {
            let b = _mm256_setr_epi64x(1, 2, 4, 8);
            _mm256_cmpeq_epi64(_mm256_and_si256(_mm256_set1_epi64x(bits as i64), b), b)
        }
    }
    #[inline(always)]
    unsafe fn bits(m: __m256i) -> u32 {
        unsafe { _mm256_movemask_pd(_mm256_castsi256_pd(m)) as u32 }
    }
    #[inline(always)]
    unsafe fn and_m(a: __m256i, b: __m256i) -> __m256i {
        unsafe { _mm256_and_si256(a, b) }
    }
    #[inline(always)]
    unsafe fn or_m(a: __m256i, b: __m256i) -> __m256i {
        unsafe { _mm256_or_si256(a, b) }
    }
    #[inline(always)]
    unsafe fn and_not_m(a: __m256i, b: __m256i) -> __m256i {
        unsafe { _mm256_andnot_si256(b, a) }
    }

    #[inline(always)]
    unsafe fn gather_i64(base: *const i64, index: __m256i, m: __m256i) -> __m256i {
        unsafe { _mm256_mask_i64gather_epi64::<8>(_mm256_setzero_si256(), base, index, m) }
    }
    #[inline(always)]
    unsafe fn gather_u32(base: *const u32, index: __m256i, m: __m256i) -> __m256i {
        unsafe {
            _mm256_cvtepu32_epi64(_mm256_mask_i64gather_epi32::<4>(
                _mm_setzero_si128(),
                base as *const i32,
                index,
                narrow(m),
            ))
        }
    }
    #[inline(always)]
    unsafe fn store(v: __m256d, to: &mut [f64; MAX_LANES]) {
        unsafe { _mm256_storeu_pd(to.as_mut_ptr(), v) }
    }
    #[inline(always)]
    unsafe fn store_i(v: __m256i, to: &mut [i64; MAX_LANES]) {
        unsafe { _mm256_storeu_si256(to.as_mut_ptr() as *mut __m256i, v) }
    }
    #[inline(always)]
    unsafe fn expander(take: u32) -> (__m256i, __m256i) {
        unsafe {
            let perm = _mm256_loadu_si256(EXPAND[take as usize].as_ptr() as *const __m256i);
            (Self::mask(take), perm)
        }
    }
    #[inline(always)]
    unsafe fn expand(old: __m256d, (m, perm): (__m256i, __m256i), from: *const f64) -> __m256d {
        unsafe {
            let v = _mm256_castps_pd(_mm256_permutevar8x32_ps(
                _mm256_castpd_ps(_mm256_loadu_pd(from)),
                perm,
            ));
            Self::sel(m, v, old)
        }
    }
    #[inline(always)]
    unsafe fn expand_i(old: __m256i, (m, perm): (__m256i, __m256i), from: *const i64) -> __m256i {
        unsafe {
            let v = _mm256_permutevar8x32_epi32(_mm256_loadu_si256(from as *const __m256i), perm);
            Self::sel_i(m, v, old)
        }
    }

    #[inline(always)]
    unsafe fn stage<T: Coefficient>(
        staged: &mut Staged,
        ctx: &Ctx<T>,
        rays: &mut Rays,
        input: &[u32],
    ) {
        staged.stage_scalar(ctx, rays, input);
    }

    lanes::walk_methods!("avx2,bmi1,bmi2,popcnt,lzcnt");
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every ray walks as in the scalar walk, the octree's blocks read from
    /// the brick levels and from the byte map; the spans and conversions
    /// are the scalar walk's ([`super::super::lane_check`]). It runs
    /// wherever the CPU has AVX2, also where the renderer would take the
    /// AVX-512 walk.
    #[test]
    fn lanes_are_the_scalar_walk() {
        let runs = std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("bmi1")
            && std::arch::is_x86_feature_detected!("bmi2")
            && std::arch::is_x86_feature_detected!("popcnt")
            && std::arch::is_x86_feature_detected!("lzcnt");
        // Every AVX-512 CPU has these, so the AVX-512 requirement covers it.
        if !crate::simd::kernels_run("the AVX2 walk", runs) {
            return;
        }
        super::super::lane_check::check_isa::<Avx2>();
    }
}
