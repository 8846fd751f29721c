//! The lock-step cell walk of [`super::wide`] four rays at a time, for CPUs
//! with AVX2 but without AVX-512.
//!
//! Without it such CPUs walked one ray at a time ([`super::walk_interleaved`]),
//! and the walk was the frame's largest stage: on an AVX2-only AMD EPYC,
//! single thread, sphere, 32% of the samples against 21% for the solve.
//! The algorithm is [`super::wide`]'s, step for step and in the same
//! operation order, so every ray visits the same cells and hands the same
//! segment bits to the solve as the scalar walk (tested below, ray by ray).
//! What AVX2 lacks is built from what it has:
//!
//! - no mask registers: a lane mask is a vector of all-ones or all-zeros
//!   lanes, blends select, and a `movemask` gives the bits the control flow
//!   needs;
//! - no conversions between `f64` and `i64`: lattice indices are small
//!   integers, converted exactly through the `1.5·2⁵²` constant (whose
//!   mantissa's last bit is one unit), and the clamped floors truncate with
//!   a rounding instruction first;
//! - no 64-bit multiply, shift right arithmetic or compare unsigned: the
//!   brick index multiplies 32-bit halves (its factors are below 2³²), and
//!   the lanes whose cells could be negative are masked off before any use;
//! - no vector population count: a nibble table (`vpshufb`) summed by
//!   `vpsadbw`;
//! - no expand: a refill permutes the staged columns with a table of 16
//!   patterns, one per set of free lanes.

use std::arch::x86_64::*;
use std::sync::OnceLock;

use super::super::super::context::Ctx;
use super::super::super::packet::{Queue, Rays};
use super::wide::{
    BrickLevels, CHUNK, Col, SPAN_ROWS, STAGED, Staged, distance_layout_fits, lane_masks,
    lane_planes, layout_fits, reads_brick_levels,
};
use crate::classify::bezier::SUB;
use crate::classify::plane::{self, CellTests};
use crate::filter::coeffs::Coefficient;
use crate::octree::distance::Proximity;
use crate::octree::{BLOCK_ORIGIN_BITS, FIRST_BLOCK_CELLS, Octree, TAGGED};
use crate::render::stats::Counters;

const LANES: usize = 4;

/// All lanes.
const FULL: u32 = (1 << LANES) - 1;

const _: () = assert!(SUB == 4, "the span masks assume 4³ sub-cells");

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
    available() && layout_fits(ctx, tree)
}

/// [`fits`] for the distance cubes of `p`.
pub fn fits_distance<T: Coefficient>(ctx: &Ctx<T>, p: &Proximity) -> bool {
    available() && distance_layout_fits(ctx, p)
}

impl Staged {
    /// Stages `input`'s rays (at most [`CHUNK`]) exactly as the scalar walk
    /// starts them ([`super::walk_start`], the same function).
    #[inline(always)]
    fn stage_scalar<T: Coefficient>(&mut self, ctx: &Ctx<T>, rays: &mut Rays, input: &[u32]) {
        debug_assert!(input.len() <= CHUNK);
        for (k, &r) in input.iter().enumerate() {
            let i = r as usize;
            let (ray, cell, t) = super::walk_start(ctx, rays, i);
            self.r[k] = r as i64;
            for a in 0..3 {
                self.ou[a][k] = ray.ou[a];
                self.du[a][k] = ray.du[a];
                self.inv[a][k] = ray.inv[a];
                self.cell[a][k] = cell[a];
            }
            self.t[k] = t;
            self.t_start[k] = rays.t_start[i];
            self.t_end[k] = rays.t_end[i];
        }
        self.len = input.len();
    }
}

/// Four walks in registers.
#[derive(Clone, Copy)]
struct Lanes {
    r: __m256i,
    ou: [__m256d; 3],
    du: [__m256d; 3],
    inv: [__m256d; 3],
    cell: [__m256i; 3],
    t: __m256d,
    t_start: __m256d,
    t_end: __m256d,
}

/// The lanes of bit set `bits` as a lane mask.
#[inline(always)]
unsafe fn lane_mask(bits: u32) -> __m256i {
    // SAFETY: called only from functions with AVX2.
    unsafe {
        let b = _mm256_setr_epi64x(1, 2, 4, 8);
        _mm256_cmpeq_epi64(_mm256_and_si256(_mm256_set1_epi64x(bits as i64), b), b)
    }
}

/// The bit set of lane mask `m`.
#[inline(always)]
unsafe fn bits(m: __m256i) -> u32 {
    // SAFETY: as above.
    unsafe { _mm256_movemask_pd(_mm256_castsi256_pd(m)) as u32 }
}

/// A comparison's result as a lane mask.
#[inline(always)]
unsafe fn of_pd(m: __m256d) -> __m256i {
    // SAFETY: as above.
    unsafe { _mm256_castpd_si256(m) }
}

/// `yes` in the lanes of `m`, `no` in the others.
#[inline(always)]
unsafe fn sel_pd(m: __m256i, yes: __m256d, no: __m256d) -> __m256d {
    // SAFETY: as above.
    unsafe { _mm256_blendv_pd(no, yes, _mm256_castsi256_pd(m)) }
}

/// [`sel_pd`] for integer lanes.
#[inline(always)]
unsafe fn sel(m: __m256i, yes: __m256i, no: __m256i) -> __m256i {
    // SAFETY: as above.
    unsafe { _mm256_blendv_epi8(no, yes, m) }
}

/// The lanes of bit set `m` whose cell's plane (at `slot`) proves the
/// segment `t0..t1` clear of the surface, one lane at a time with
/// [`crate::classify::plane::clears`].
#[inline(always)]
unsafe fn plane_clears(
    (tests, margin): (&[CellTests], f64),
    l: &Lanes,
    t0: __m256d,
    t1: __m256d,
    slot: __m256i,
    m: u32,
) -> u32 {
    // SAFETY: called only from functions with AVX2; each array holds four
    // lanes.
    unsafe {
        let pd = |v: __m256d| {
            let mut o = [0.0; 4];
            _mm256_storeu_pd(o.as_mut_ptr(), v);
            o
        };
        let (t0, t1) = (pd(t0), pd(t1));
        let ou = l.ou.map(pd);
        let du = l.du.map(pd);
        let mut cell = [[0i64; 4]; 3];
        for (a, c) in cell.iter_mut().enumerate() {
            _mm256_storeu_si256(c.as_mut_ptr() as *mut __m256i, l.cell[a]);
        }
        let mut slots = [0i64; 4];
        _mm256_storeu_si256(slots.as_mut_ptr() as *mut __m256i, slot);
        let mut clear = 0;
        for k in (0..4).filter(|&k| m >> k & 1 == 1) {
            let local =
                |t: f64| std::array::from_fn(|a| ou[a][k] + t * du[a][k] - cell[a][k] as f64);
            let p = &tests[slots[k] as usize].plane;
            if plane::clears(p, margin, local(t0[k]), local(t1[k])) {
                clear |= 1 << k;
            }
        }
        clear
    }
}

/// The dword lanes 0, 2, 4, 6 of a lane mask: the mask of a gather of
/// 32-bit values by 64-bit indices.
#[inline(always)]
unsafe fn narrow(m: __m256i) -> __m128i {
    // SAFETY: as above.
    unsafe {
        _mm256_castsi256_si128(_mm256_permutevar8x32_epi32(
            m,
            _mm256_setr_epi32(0, 2, 4, 6, 0, 0, 0, 0),
        ))
    }
}

/// `1.5·2⁵²`: in `[2⁵², 2⁵³)` a double's last mantissa bit is one unit, so
/// adding an integer of magnitude below 2⁵¹ to its bits adds it to its value.
const MAGIC: f64 = 6_755_399_441_055_744.0;

/// `x as f64` per lane, exact for `|x| < 2⁵¹` (lattice indices are far
/// smaller); `0` gives `+0.0`, as `as` does.
#[inline(always)]
unsafe fn to_pd(x: __m256i) -> __m256d {
    // SAFETY: as above.
    unsafe {
        let magic = _mm256_set1_pd(MAGIC);
        _mm256_sub_pd(
            _mm256_castsi256_pd(_mm256_add_epi64(x, _mm256_castpd_si256(magic))),
            magic,
        )
    }
}

/// [`super::clamped_floor`] per lane: the clamp first (in the same operand
/// order, so a NaN gives `lo`), then truncation — the clamp bounds are
/// lattice indices, so the value is below 2⁵¹ in magnitude and converts
/// exactly through [`MAGIC`].
#[inline(always)]
unsafe fn clamped_floor(x: __m256d, lo: __m256d, hi: __m256d) -> __m256i {
    // SAFETY: as above.
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

/// Each 64-bit lane's population count.
#[inline(always)]
unsafe fn popcnt(v: __m256i) -> __m256i {
    // SAFETY: as above.
    unsafe {
        let table = _mm256_setr_epi8(
            0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4, 0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2,
            3, 3, 4,
        );
        let low = _mm256_set1_epi8(0x0f);
        let lo = _mm256_shuffle_epi8(table, _mm256_and_si256(v, low));
        let hi = _mm256_shuffle_epi8(table, _mm256_and_si256(_mm256_srli_epi16::<4>(v), low));
        _mm256_sad_epu8(_mm256_add_epi8(lo, hi), _mm256_setzero_si256())
    }
}

/// What the walk reads, as vectors and base pointers.
struct Space<'a, R> {
    n: [__m256i; 3],
    bricks: [__m256i; 2],
    reach: R,
    masks: Option<(&'a [u64], &'a [u32], &'a [u64])>,
    /// The tagged cells' planes in the same slot order, and their margin.
    planes: Option<(&'a [CellTests], f64)>,
}

impl<'a, R> Space<'a, R> {
    /// The same lattice and masks with another reach.
    fn with_reach<Q>(&self, reach: Q) -> Space<'a, Q> {
        Space {
            n: self.n,
            bricks: self.bricks,
            reach,
            masks: self.masks,
            planes: self.planes,
        }
    }
}

/// [`super::wide`]'s `LaneReach` in four lanes: the byte per cell saying how
/// far the empty space around it reaches, and the box a lane may jump over.
trait LaneReach {
    /// Each lane of `go`'s byte, from its cell's bricked slot.
    unsafe fn byte(&self, l: &Lanes, slot: __m256i, go: __m256i) -> __m256i;
    /// The lanes of `go` whose byte marks a tagged cell, and each lane's
    /// reach (that of the cell alone where tagged).
    unsafe fn reach(&self, go: __m256i, byte: __m256i) -> (__m256i, __m256i);
    /// Where each lane leaves the box of its `reach` (not before its `t`),
    /// and the cell it enters.
    unsafe fn exit(&self, l: &Lanes, reach: __m256i) -> (__m256d, [__m256i; 3]);
}

/// The byte at `index` of `bytes` (a multiple of 4 long) for each lane of
/// `go`, from the aligned dword holding it.
///
/// # Safety
/// AVX2; every lane of `go` indexes `bytes`.
#[inline(always)]
unsafe fn gather_bytes(bytes: &[u8], index: __m256i, go: __m256i) -> __m256i {
    // SAFETY: as the caller guarantees; the dword holding an indexed byte
    // lies in `bytes`, whose length is a multiple of 4.
    unsafe {
        let dword = _mm256_mask_i64gather_epi32::<4>(
            _mm_setzero_si128(),
            bytes.as_ptr() as *const i32,
            _mm256_srli_epi64::<2>(index),
            narrow(go),
        );
        let shift = _mm256_slli_epi64::<3>(_mm256_and_si256(index, _mm256_set1_epi64x(3)));
        _mm256_and_si256(
            _mm256_srlv_epi64(_mm256_cvtepu32_epi64(dword), shift),
            _mm256_set1_epi64x(0xFF),
        )
    }
}

/// The octree's blocks, a block level per cell, from the byte map or the
/// brick levels ([`super::wide`]'s `Blocks`).
struct Blocks<M> {
    map: M,
    leaf_level: __m256i,
}

/// Where [`Blocks`] reads each lane's skip byte.
trait SkipBytes {
    /// The skip byte of each lane of `go`, from its cell's bricked slot.
    unsafe fn byte(&self, slot: __m256i, go: __m256i) -> __m256i;
}

/// The flattened skip map, a byte per cell ([`Octree::skip_map`]).
struct ByteMap<'a>(&'a [u8]);

impl SkipBytes for ByteMap<'_> {
    #[inline(always)]
    unsafe fn byte(&self, slot: __m256i, go: __m256i) -> __m256i {
        // SAFETY: called only from the walk, which runs with AVX2; a
        // lattice cell's slot lies in the map (`layout_fits`).
        unsafe { gather_bytes(self.0, slot, go) }
    }
}

/// The octree's levels per brick with the bricks' tag words
/// ([`BrickLevels`]), for the lattices [`reads_brick_levels`] picks. `SNELL_ISA=avx2`, two threads, four
/// alternating rounds of 10 teapot frames on a Zen 4 against the octree's
/// former map of a `u16` per 2³ block: traverse stage 146.5–162.8 →
/// 135.3–153.4 ms CPU (better in three rounds of four).
impl SkipBytes for BrickLevels<'_> {
    /// [`crate::octree::decode_brick`] per lane.
    #[inline(always)]
    unsafe fn byte(&self, slot: __m256i, go: __m256i) -> __m256i {
        // SAFETY: called only from the walk, which runs with AVX2; a
        // lattice cell's brick has a tag word and a level, whose table's
        // length is a multiple of 4 (`layout_fits`).
        unsafe {
            let brick = _mm256_srli_epi64::<6>(slot);
            let k = _mm256_and_si256(slot, _mm256_set1_epi64x(63));
            let word = _mm256_mask_i64gather_epi64::<8>(
                _mm256_setzero_si256(),
                self.words.as_ptr() as *const i64,
                brick,
                go,
            );
            let level = gather_bytes(self.levels, brick, go);
            let one = _mm256_set1_epi64x(1);
            let zero = _mm256_setzero_si256();
            let tagged = _mm256_cmpeq_epi64(_mm256_and_si256(_mm256_srlv_epi64(word, k), one), one);
            // The 2³ block's cells (`octree::block_cells`).
            let block = _mm256_sllv_epi64(
                _mm256_set1_epi64x(FIRST_BLOCK_CELLS as i64),
                _mm256_and_si256(k, _mm256_set1_epi64x(BLOCK_ORIGIN_BITS as i64)),
            );
            let empty = _mm256_cmpeq_epi64(_mm256_and_si256(word, block), zero);
            let byte = _mm256_and_si256(empty, level);
            sel(tagged, _mm256_set1_epi64x(TAGGED as i64), byte)
        }
    }
}

impl<M: SkipBytes> LaneReach for Blocks<M> {
    #[inline(always)]
    unsafe fn byte(&self, _: &Lanes, slot: __m256i, go: __m256i) -> __m256i {
        // SAFETY: as the caller guarantees.
        unsafe { self.map.byte(slot, go) }
    }

    #[inline(always)]
    unsafe fn reach(&self, go: __m256i, byte: __m256i) -> (__m256i, __m256i) {
        // SAFETY: called only from the walk, which runs with AVX2.
        unsafe {
            let tagged = _mm256_and_si256(
                go,
                _mm256_cmpeq_epi64(byte, _mm256_set1_epi64x(TAGGED as i64)),
            );
            // Bytes and levels are below 256: the signed compare is the
            // unsigned one.
            let small = _mm256_cmpgt_epi64(self.leaf_level, byte);
            (
                tagged,
                _mm256_andnot_si256(_mm256_or_si256(tagged, small), byte),
            )
        }
    }

    #[inline(always)]
    unsafe fn exit(&self, l: &Lanes, level: __m256i) -> (__m256d, [__m256i; 3]) {
        // SAFETY: as above.
        unsafe { exit_block(l, level) }
    }
}

/// The distance field's cubes: per lane the map of its direction's octant
/// (or the one centred map), the cube's edge per cell, 0 for a tagged cell.
struct Cubes<'a> {
    bytes: &'a [u8],
    octant_step: [__m256i; 3],
    centred: bool,
    last: [__m256i; 3],
}

impl LaneReach for Cubes<'_> {
    #[inline(always)]
    unsafe fn byte(&self, l: &Lanes, slot: __m256i, go: __m256i) -> __m256i {
        // SAFETY: as above; the lanes of `go` hold cells of the lattice,
        // whose slots lie in each octant's map (`distance_layout_fits`).
        unsafe {
            let mut index = slot;
            for a in 0..3 {
                let down = of_pd(_mm256_cmp_pd::<_CMP_LT_OQ>(l.du[a], _mm256_setzero_pd()));
                index = _mm256_add_epi64(index, _mm256_and_si256(down, self.octant_step[a]));
            }
            gather_bytes(self.bytes, index, go)
        }
    }

    #[inline(always)]
    unsafe fn reach(&self, go: __m256i, byte: __m256i) -> (__m256i, __m256i) {
        // SAFETY: as above.
        unsafe {
            let zero = _mm256_setzero_si256();
            let tagged = _mm256_and_si256(go, _mm256_cmpeq_epi64(byte, zero));
            let k = _mm256_sub_epi64(byte, _mm256_set1_epi64x(1));
            (tagged, _mm256_andnot_si256(_mm256_cmpgt_epi64(zero, k), k))
        }
    }

    #[inline(always)]
    unsafe fn exit(&self, l: &Lanes, k: __m256i) -> (__m256d, [__m256i; 3]) {
        // SAFETY: as above.
        unsafe {
            let zero = _mm256_setzero_si256();
            let mut lo = l.cell;
            let mut hi = l.cell;
            for a in 0..3 {
                let (down, up) = if self.centred {
                    (k, k)
                } else {
                    let neg = of_pd(_mm256_cmp_pd::<_CMP_LT_OQ>(l.du[a], _mm256_setzero_pd()));
                    (_mm256_and_si256(neg, k), _mm256_andnot_si256(neg, k))
                };
                let below = _mm256_sub_epi64(l.cell[a], down);
                lo[a] = _mm256_andnot_si256(_mm256_cmpgt_epi64(zero, below), below);
                let above = _mm256_add_epi64(l.cell[a], up);
                hi[a] = sel(_mm256_cmpgt_epi64(above, self.last[a]), self.last[a], above);
            }
            exit_box(l, lo, hi)
        }
    }
}

/// [`crate::lattice::Bricked::index`] per lane, for cells of the lattice
/// (other lanes get values never used).
#[inline(always)]
unsafe fn bricked_index(bricks: &[__m256i; 2], cell: &[__m256i; 3]) -> __m256i {
    // SAFETY: as above.
    unsafe {
        let [x, y, z] = *cell;
        let three = _mm256_set1_epi64x(3);
        // Brick counts and brick coordinates are below 2³²: the 32-bit
        // multiplies are exact.
        let brick = _mm256_add_epi64(
            _mm256_srli_epi64::<2>(x),
            _mm256_mul_epu32(
                bricks[0],
                _mm256_add_epi64(
                    _mm256_srli_epi64::<2>(y),
                    _mm256_mul_epu32(bricks[1], _mm256_srli_epi64::<2>(z)),
                ),
            ),
        );
        let within = _mm256_or_si256(
            _mm256_and_si256(x, three),
            _mm256_or_si256(
                _mm256_slli_epi64::<2>(_mm256_and_si256(y, three)),
                _mm256_slli_epi64::<4>(_mm256_and_si256(z, three)),
            ),
        );
        _mm256_or_si256(_mm256_slli_epi64::<6>(brick), within)
    }
}

/// The tagged-cell index's slot per lane of `go`: the lanes whose cell is
/// tagged, and their slots ([`super::wide`]'s `tagged_slot`).
///
/// # Safety
/// AVX2; every lane of `go` indexes a cell of the index's lattice.
#[inline(always)]
unsafe fn tagged_slot(
    (words, rank): (&[u64], &[u32]),
    at: __m256i,
    go: __m256i,
) -> (__m256i, __m256i) {
    // SAFETY: as the caller guarantees; a lattice cell's brick has a word
    // and a rank.
    unsafe {
        let one = _mm256_set1_epi64x(1);
        let brick = _mm256_srli_epi64::<6>(at);
        let bit = _mm256_and_si256(at, _mm256_set1_epi64x(63));
        let word = _mm256_mask_i64gather_epi64::<8>(
            _mm256_setzero_si256(),
            words.as_ptr() as *const i64,
            brick,
            go,
        );
        let has = _mm256_and_si256(
            go,
            _mm256_cmpeq_epi64(_mm256_and_si256(_mm256_srlv_epi64(word, bit), one), one),
        );
        let before = _mm256_cvtepu32_epi64(_mm256_mask_i64gather_epi32::<4>(
            _mm_setzero_si128(),
            rank.as_ptr() as *const i32,
            brick,
            narrow(go),
        ));
        let below = _mm256_and_si256(word, _mm256_sub_epi64(_mm256_sllv_epi64(one, bit), one));
        (has, _mm256_add_epi64(before, popcnt(below)))
    }
}

/// The sub-cell bits whose index along the axis of stride `2^log` lies in
/// `lo..=hi` (the wide walk's `axis_span`; shifts by 64 give 0 here too).
#[inline(always)]
unsafe fn axis_span(rep: u64, log: u64, lo: __m256i, hi: __m256i) -> __m256i {
    // SAFETY: as above.
    unsafe {
        let rep = _mm256_set1_epi64x(rep as i64);
        let log = _mm256_set1_epi64x(log as i64);
        let one = _mm256_set1_epi64x(1);
        let top = _mm256_sllv_epi64(_mm256_add_epi64(hi, one), log);
        let bottom = _mm256_sllv_epi64(lo, log);
        _mm256_sub_epi64(_mm256_sllv_epi64(rep, top), _mm256_sllv_epi64(rep, bottom))
    }
}

/// [`super::may_meet_tagged_sub_cell`] per lane, as a lane mask.
#[inline(always)]
unsafe fn may_meet(l: &Lanes, t0: __m256d, t1: __m256d, mask: __m256i) -> __m256i {
    // SAFETY: as above.
    unsafe {
        let n = _mm256_set1_pd(SUB as f64);
        let zero = _mm256_setzero_pd();
        let last = _mm256_set1_pd(SUB as f64 - 1.0);
        let eps = _mm256_set1_pd(1e-9);
        let all = _mm256_set1_epi64x(-1);
        let mut bbox = all;
        for a in 0..3 {
            let cf = to_pd(l.cell[a]);
            let local = |t: __m256d| {
                _mm256_mul_pd(
                    n,
                    _mm256_sub_pd(_mm256_add_pd(l.ou[a], _mm256_mul_pd(t, l.du[a])), cf),
                )
            };
            let (v0, v1) = (local(t0), local(t1));
            let (lo, hi) = (_mm256_min_pd(v0, v1), _mm256_max_pd(v0, v1));
            let lo = clamped_floor(_mm256_sub_pd(lo, eps), zero, last);
            let hi = clamped_floor(_mm256_add_pd(hi, eps), zero, last);
            let (rep, log) = SPAN_ROWS[a];
            let span = axis_span(rep, log, lo, hi);
            let d = _mm256_sub_pd(v0, v1);
            let nan = of_pd(_mm256_cmp_pd::<_CMP_UNORD_Q>(d, d));
            bbox = _mm256_and_si256(bbox, sel(nan, all, span));
        }
        let none = _mm256_cmpeq_epi64(_mm256_and_si256(mask, bbox), _mm256_setzero_si256());
        _mm256_andnot_si256(none, all)
    }
}

/// [`super::cell_span`] per lane, clipped to the piece as
/// [`super::tagged_segment`] does.
#[inline(always)]
unsafe fn tagged_segment(l: &Lanes) -> (__m256d, __m256d) {
    // SAFETY: as above.
    unsafe {
        let mut c0 = _mm256_set1_pd(f64::NEG_INFINITY);
        let mut c1 = _mm256_set1_pd(f64::INFINITY);
        let one = _mm256_set1_epi64x(1);
        for a in 0..3 {
            let moves = of_pd(_mm256_cmp_pd::<_CMP_NEQ_UQ>(l.du[a], _mm256_setzero_pd()));
            let ta = _mm256_mul_pd(_mm256_sub_pd(to_pd(l.cell[a]), l.ou[a]), l.inv[a]);
            let tb = _mm256_mul_pd(
                _mm256_sub_pd(to_pd(_mm256_add_epi64(l.cell[a], one)), l.ou[a]),
                l.inv[a],
            );
            c0 = sel_pd(moves, _mm256_max_pd(c0, _mm256_min_pd(ta, tb)), c0);
            c1 = sel_pd(moves, _mm256_min_pd(c1, _mm256_max_pd(ta, tb)), c1);
        }
        let t0 = _mm256_max_pd(c0, l.t_start);
        let t1 = _mm256_max_pd(_mm256_min_pd(c1, l.t_end), t0);
        (t0, t1)
    }
}

/// [`super::exit_block`] per lane, with per-lane levels (0: the cell).
/// The lanes that use the result hold lattice cells, which are not
/// negative, so the logical shift right is the arithmetic one.
#[inline(always)]
unsafe fn exit_block(l: &Lanes, level: __m256i) -> (__m256d, [__m256i; 3]) {
    // SAFETY: as above.
    unsafe {
        let one = _mm256_set1_epi64x(1);
        let size = _mm256_sllv_epi64(one, level);
        let mut lo = [_mm256_setzero_si256(); 3];
        let mut hi = [_mm256_setzero_si256(); 3];
        for a in 0..3 {
            lo[a] = _mm256_sllv_epi64(_mm256_srlv_epi64(l.cell[a], level), level);
            hi[a] = _mm256_sub_epi64(_mm256_add_epi64(lo[a], size), one);
        }
        exit_box(l, lo, hi)
    }
}

/// [`super::exit_box`] per lane: where each lane leaves its box `lo ..= hi`
/// (which holds its cell), not before its `t`, and the cell it enters.
#[inline(always)]
unsafe fn exit_box(l: &Lanes, lo: [__m256i; 3], hi: [__m256i; 3]) -> (__m256d, [__m256i; 3]) {
    // SAFETY: as above.
    unsafe {
        let zero = _mm256_setzero_pd();
        let one = _mm256_set1_epi64x(1);
        let mut te = [zero; 3];
        let mut pos = [_mm256_setzero_si256(); 3];
        let mut neg = [_mm256_setzero_si256(); 3];
        for a in 0..3 {
            pos[a] = of_pd(_mm256_cmp_pd::<_CMP_GT_OQ>(l.du[a], zero));
            neg[a] = of_pd(_mm256_cmp_pd::<_CMP_LT_OQ>(l.du[a], zero));
            let wall = sel(pos[a], _mm256_add_epi64(hi[a], one), lo[a]);
            let tw = _mm256_mul_pd(_mm256_sub_pd(to_pd(wall), l.ou[a]), l.inv[a]);
            te[a] = sel_pd(
                _mm256_or_si256(pos[a], neg[a]),
                tw,
                _mm256_set1_pd(f64::INFINITY),
            );
        }
        // The scalar walk's axis choice: x unless y is strictly sooner (or x
        // is NaN), then that unless z is.
        let first01 = of_pd(_mm256_cmp_pd::<_CMP_LE_OQ>(te[0], te[1]));
        let t01 = sel_pd(first01, te[0], te[1]);
        let before2 = of_pd(_mm256_cmp_pd::<_CMP_LE_OQ>(t01, te[2]));
        let t_exit = sel_pd(before2, t01, te[2]);
        let axis = [
            _mm256_and_si256(first01, before2),
            _mm256_andnot_si256(first01, before2),
            _mm256_andnot_si256(before2, _mm256_set1_epi64x(-1)),
        ];
        let t_new = _mm256_max_pd(t_exit, l.t);
        let mut next = l.cell;
        for a in 0..3 {
            let at = _mm256_add_pd(l.ou[a], _mm256_mul_pd(t_new, l.du[a]));
            let floor_lo = sel(neg[a], lo[a], l.cell[a]);
            let floor_hi = sel(pos[a], hi[a], l.cell[a]);
            let inside = clamped_floor(at, to_pd(floor_lo), to_pd(floor_hi));
            let past = sel(
                pos[a],
                _mm256_add_epi64(hi[a], one),
                sel(neg[a], _mm256_sub_epi64(lo[a], one), l.cell[a]),
            );
            next[a] = sel(axis[a], past, inside);
        }
        (t_new, next)
    }
}

/// Lanes that end their walk this step (bit sets), and the segments of
/// those that go to the solve.
struct Ended {
    solve: u32,
    escaped: u32,
    t0: __m256d,
    t1: __m256d,
}

/// One step of every `live` lane ([`super::Walk::step`]).
#[inline(always)]
unsafe fn step<R: LaneReach>(s: &Space<R>, l: &mut Lanes, live: u32, c: &mut Counters) -> Ended {
    // SAFETY: called only from the walk, which runs with AVX2; memory
    // accesses are marked below.
    unsafe {
        let zero = _mm256_setzero_si256();
        let live_m = lane_mask(live);
        let mut inside = of_pd(_mm256_cmp_pd::<_CMP_NGE_UQ>(l.t, l.t_end));
        for a in 0..3 {
            // `0 ≤ cell < n`: the unsigned compare, for counts below 2⁶³.
            let below_n = _mm256_cmpgt_epi64(s.n[a], l.cell[a]);
            let negative = _mm256_cmpgt_epi64(zero, l.cell[a]);
            inside = _mm256_and_si256(inside, _mm256_andnot_si256(negative, below_n));
        }
        let go = _mm256_and_si256(live_m, inside);
        let go_bits = bits(go);
        let escaped = live & !go_bits;
        c.cells_visited += go_bits.count_ones() as u64;

        let slot = bricked_index(&s.bricks, &l.cell);
        // SAFETY: the lanes of `go` hold cells of the lattice.
        let byte = s.reach.byte(l, slot, go);
        let (tagged, reach) = s.reach.reach(go, byte);

        let (solve, skipped, t0, t1) = if bits(tagged) == 0 {
            (zero, zero, _mm256_setzero_pd(), _mm256_setzero_pd())
        } else {
            let (t0, t1) = tagged_segment(l);
            let (solve, skipped) = match s.masks {
                None => (tagged, zero),
                Some((words, rank, masks)) => {
                    // SAFETY (here and the mask's gather): the lanes of `go`
                    // hold lattice cells; a tagged cell's slot is below the
                    // tag count, the masks' length.
                    let (has, index) = tagged_slot((words, rank), slot, go);
                    let mask = _mm256_mask_i64gather_epi64::<8>(
                        zero,
                        masks.as_ptr() as *const i64,
                        index,
                        has,
                    );
                    let mut meet = _mm256_and_si256(has, may_meet(l, t0, t1, mask));
                    if let Some(planes) = s.planes
                        && bits(meet) != 0
                    {
                        let clear = lane_mask(plane_clears(planes, l, t0, t1, index, bits(meet)));
                        meet = _mm256_andnot_si256(clear, meet);
                    }
                    let has = _mm256_and_si256(has, tagged);
                    (
                        _mm256_or_si256(
                            _mm256_andnot_si256(has, tagged),
                            _mm256_and_si256(tagged, meet),
                        ),
                        _mm256_andnot_si256(meet, has),
                    )
                }
            };
            (solve, skipped, t0, t1)
        };
        c.subcell_skips += bits(skipped).count_ones() as u64;

        let moves = _mm256_andnot_si256(solve, go);
        let (t_new, next) = s.reach.exit(l, reach);
        l.t = sel_pd(moves, t_new, l.t);
        for a in 0..3 {
            l.cell[a] = sel(moves, next[a], l.cell[a]);
        }
        Ended {
            solve: bits(solve),
            escaped,
            t0,
            t1,
        }
    }
}

/// `EXPAND[m]`: for the lanes of bit set `m`, in order, the dword indices
/// of the consecutive staged values `0, 1, …` they take (other lanes 0).
const EXPAND: [[i32; 8]; 16] = {
    let mut t = [[0i32; 8]; 16];
    let mut m = 0;
    while m < 16 {
        let mut j = 0;
        let mut k = 0;
        while k < LANES {
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

/// Fills the lanes of `free` from the staged chunk at `*pos`, as many as it
/// has left (the lowest free lanes first); returns the lanes filled.
#[inline(always)]
unsafe fn refill(l: &mut Lanes, free: u32, staged: &Staged, pos: &mut usize) -> u32 {
    // SAFETY: called only from the walk, which runs with AVX2; memory
    // accesses are marked below.
    unsafe {
        let left = staged.len - *pos;
        let mut take = free;
        while take.count_ones() as usize > left {
            take &= !(1 << (31 - take.leading_zeros()));
        }
        let p = *pos;
        let m = lane_mask(take);
        let perm = _mm256_loadu_si256(EXPAND[take as usize].as_ptr() as *const __m256i);
        // SAFETY (all loads): `p < staged.len ≤ CHUNK`, and every column holds
        // `CHUNK + LANES` values.
        let pd = |old: __m256d, col: &Col<f64>| {
            let v = _mm256_castps_pd(_mm256_permutevar8x32_ps(
                _mm256_castpd_ps(_mm256_loadu_pd(col.as_ptr().add(p))),
                perm,
            ));
            sel_pd(m, v, old)
        };
        let epi = |old: __m256i, col: &Col<i64>| {
            let v = _mm256_permutevar8x32_epi32(
                _mm256_loadu_si256(col.as_ptr().add(p) as *const __m256i),
                perm,
            );
            sel(m, v, old)
        };
        l.r = epi(l.r, &staged.r);
        for a in 0..3 {
            l.ou[a] = pd(l.ou[a], &staged.ou[a]);
            l.du[a] = pd(l.du[a], &staged.du[a]);
            l.inv[a] = pd(l.inv[a], &staged.inv[a]);
            l.cell[a] = epi(l.cell[a], &staged.cell[a]);
        }
        l.t = pd(l.t, &staged.t);
        l.t_start = pd(l.t_start, &staged.t_start);
        l.t_end = pd(l.t_end, &staged.t_end);
        *pos += take.count_ones() as usize;
        take
    }
}

/// The walk of every ray of `input` to its next candidate cell or out of
/// its piece, as [`super::walk_interleaved`] over the octree does.
///
/// # Safety
/// [`fits`] must be true.
#[target_feature(enable = "avx2,bmi1,bmi2,popcnt,lzcnt")]
pub unsafe fn walk_octree<T: Coefficient>(
    ctx: &Ctx<T>,
    tree: (&Octree, u32),
    rays: &mut Rays,
    input: &[u32],
    solve: &mut Queue,
    record: &mut Queue,
    c: &mut Counters,
) {
    let brick_levels = reads_brick_levels(tree.0);
    // SAFETY: the caller's contract.
    unsafe { walk_octree_on(ctx, tree, brick_levels, rays, input, solve, record, c) }
}

/// [`walk_octree`] reading the brick levels (`brick_levels`) or the byte
/// map.
///
/// # Safety
/// [`fits`] must be true.
#[target_feature(enable = "avx2,bmi1,bmi2,popcnt,lzcnt")]
#[allow(clippy::too_many_arguments)]
unsafe fn walk_octree_on<T: Coefficient>(
    ctx: &Ctx<T>,
    (tree, leaf_level): (&Octree, u32),
    brick_levels: bool,
    rays: &mut Rays,
    input: &[u32],
    solve: &mut Queue,
    record: &mut Queue,
    c: &mut Counters,
) {
    let b = tree.bricked().bricks();
    let space = Space {
        n: ctx.lattice.cells.map(|n| _mm256_set1_epi64x(n as i64)),
        bricks: [
            _mm256_set1_epi64x(b[0] as i64),
            _mm256_set1_epi64x(b[1] as i64),
        ],
        reach: (),
        masks: lane_masks(ctx),
        planes: lane_planes(ctx),
    };
    let leaf_level = _mm256_set1_epi64x(leaf_level as i64);
    STAGED.with_borrow_mut(|staged| {
        // SAFETY (both): the caller checked the features.
        if brick_levels {
            let map = BrickLevels::of(tree);
            let space = space.with_reach(Blocks { map, leaf_level });
            unsafe { walk(ctx, &space, staged, rays, input, solve, record, c) }
        } else {
            let map = ByteMap(tree.skip_map());
            let space = space.with_reach(Blocks { map, leaf_level });
            unsafe { walk(ctx, &space, staged, rays, input, solve, record, c) }
        }
    });
}

/// [`walk_octree`] over the distance cubes of `p`.
///
/// # Safety
/// [`fits_distance`] must be true.
#[target_feature(enable = "avx2,bmi1,bmi2,popcnt,lzcnt")]
pub unsafe fn walk_distance<T: Coefficient>(
    ctx: &Ctx<T>,
    p: &Proximity,
    rays: &mut Rays,
    input: &[u32],
    solve: &mut Queue,
    record: &mut Queue,
    c: &mut Counters,
) {
    let (bytes, stride, centred, bricked) = p.lane_maps();
    let b = bricked.bricks();
    let space = Space {
        n: ctx.lattice.cells.map(|n| _mm256_set1_epi64x(n as i64)),
        bricks: [
            _mm256_set1_epi64x(b[0] as i64),
            _mm256_set1_epi64x(b[1] as i64),
        ],
        reach: Cubes {
            bytes,
            octant_step: [1, 2, 4].map(|m| _mm256_set1_epi64x((m * stride) as i64)),
            centred,
            last: ctx.lattice.cells.map(|n| _mm256_set1_epi64x(n as i64 - 1)),
        },
        masks: lane_masks(ctx),
        planes: lane_planes(ctx),
    };
    STAGED.with_borrow_mut(|staged| {
        // SAFETY: the caller checked the features.
        unsafe { walk(ctx, &space, staged, rays, input, solve, record, c) }
    });
}

/// Lane groups in flight, stepped in turn so one group's arithmetic fills
/// the other's wait on its gathers.
const GROUPS: usize = 2;

#[target_feature(enable = "avx2,bmi1,bmi2,popcnt,lzcnt")]
#[allow(clippy::too_many_arguments)]
unsafe fn walk<T: Coefficient, R: LaneReach>(
    ctx: &Ctx<T>,
    space: &Space<R>,
    staged: &mut Staged,
    rays: &mut Rays,
    input: &[u32],
    solve: &mut Queue,
    record: &mut Queue,
    c: &mut Counters,
) {
    staged.len = 0;
    let mut chunks = input.chunks(CHUNK);
    let mut pos = 0;
    let zd = _mm256_setzero_pd();
    let zi = _mm256_setzero_si256();
    let idle = Lanes {
        r: zi,
        ou: [zd; 3],
        du: [zd; 3],
        inv: [zd; 3],
        cell: [zi; 3],
        t: zd,
        t_start: zd,
        t_end: zd,
    };
    let mut group = [idle; GROUPS];
    let mut live = [0u32; GROUPS];
    let mut drained = false;
    loop {
        for g in 0..GROUPS {
            while live[g] != FULL && !drained {
                if pos == staged.len {
                    match chunks.next() {
                        Some(chunk) => {
                            staged.stage_scalar(ctx, rays, chunk);
                            pos = 0;
                        }
                        None => {
                            drained = true;
                            break;
                        }
                    }
                }
                // SAFETY (here and below): this function has the features.
                live[g] |= unsafe { refill(&mut group[g], FULL & !live[g], staged, &mut pos) };
            }
        }
        if live.iter().all(|&m| m == 0) {
            return;
        }
        let mut ended: [Option<Ended>; GROUPS] = std::array::from_fn(|_| None);
        for g in 0..GROUPS {
            if live[g] != 0 {
                ended[g] = Some(unsafe { step(space, &mut group[g], live[g], c) });
            }
        }
        for g in 0..GROUPS {
            if let Some(e) = &ended[g] {
                let done = e.solve | e.escaped;
                if done != 0 {
                    unsafe { finish(&group[g], e, rays, solve, record) };
                    live[g] &= !done;
                }
            }
        }
    }
}

/// Hands the lanes that ended to their queues.
#[inline(always)]
unsafe fn finish(l: &Lanes, e: &Ended, rays: &mut Rays, solve: &mut Queue, record: &mut Queue) {
    let mut out = super::EndedLanes::<LANES>::default();
    // SAFETY: called only from the walk, which runs with AVX2; each array
    // holds LANES values.
    unsafe {
        _mm256_storeu_si256(out.r.as_mut_ptr() as *mut __m256i, l.r);
        _mm256_storeu_pd(out.t0.as_mut_ptr(), e.t0);
        _mm256_storeu_pd(out.t1.as_mut_ptr(), e.t1);
        for a in 0..3 {
            _mm256_storeu_si256(out.cell[a].as_mut_ptr() as *mut __m256i, l.cell[a]);
        }
    }
    out.hand_over(e.solve, e.escaped, rays, solve, record);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every ray walks as in the scalar walk ([`super::super::lane_check`]).
    #[test]
    fn every_ray_walks_as_in_the_scalar_walk() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        super::super::lane_check::every_ray_walks_as_in_the_scalar_walk::<Avx2<false>>();
        super::super::lane_check::every_ray_walks_as_in_the_scalar_walk::<Avx2<true>>();
    }

    /// The AVX2 walk, for the shared check; it runs wherever the CPU has
    /// AVX2, also where the renderer would take the AVX-512 walk. The
    /// octree's blocks come from the brick levels (`BLOCKS`) or the byte
    /// map, whatever the lattice size.
    struct Avx2<const BLOCKS: bool>;

    impl<const BLOCKS: bool> super::super::lane_check::LaneWalk for Avx2<BLOCKS> {
        unsafe fn octree<T: Coefficient>(
            ctx: &Ctx<T>,
            tree: (&Octree, u32),
            rays: &mut Rays,
            input: &[u32],
            solve: &mut Queue,
            record: &mut Queue,
            c: &mut Counters,
        ) {
            // SAFETY: the CPU has AVX2 (the test checked), and the caller
            // checked the layout.
            unsafe { walk_octree_on(ctx, tree, BLOCKS, rays, input, solve, record, c) }
        }

        unsafe fn distance<T: Coefficient>(
            ctx: &Ctx<T>,
            p: &Proximity,
            rays: &mut Rays,
            input: &[u32],
            solve: &mut Queue,
            record: &mut Queue,
            c: &mut Counters,
        ) {
            // SAFETY: as above.
            unsafe { walk_distance(ctx, p, rays, input, solve, record, c) }
        }

        fn fits<T: Coefficient>(ctx: &Ctx<T>, tree: &Octree) -> bool {
            layout_fits(ctx, tree)
        }

        fn fits_distance<T: Coefficient>(ctx: &Ctx<T>, p: &Proximity) -> bool {
            distance_layout_fits(ctx, p)
        }
    }

    /// The shifted spans are the scalar walk's table.
    #[test]
    fn spans_are_the_table_of_the_scalar_walk() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        for a in 0..3 {
            for lo in 0..SUB {
                for hi in lo..SUB {
                    // SAFETY: the CPU has AVX2.
                    let got = unsafe { span_of(a, lo, hi) };
                    assert_eq!(
                        got,
                        super::super::cell::AXIS_SPAN[a][lo][hi],
                        "axis {a} {lo}..={hi}"
                    );
                }
            }
        }
    }

    #[target_feature(enable = "avx2")]
    fn span_of(a: usize, lo: usize, hi: usize) -> u64 {
        let (rep, log) = SPAN_ROWS[a];
        let mut out = [0i64; LANES];
        // SAFETY: this function has the features; `out` holds LANES values.
        unsafe {
            let v = axis_span(
                rep,
                log,
                _mm256_set1_epi64x(lo as i64),
                _mm256_set1_epi64x(hi as i64),
            );
            _mm256_storeu_si256(out.as_mut_ptr() as *mut __m256i, v);
        }
        out[0] as u64
    }

    /// The conversions' edge cases: the exact integer conversion at zero,
    /// negatives and large values, and the clamped floor at integers, just
    /// off them, NaN and infinities, against the scalar walk's.
    #[test]
    fn conversions_are_the_scalar_ones() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
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
        for &x in &ints {
            // SAFETY: the CPU has AVX2.
            let got = unsafe { to_pd_of(x) };
            assert_eq!(got.to_bits(), (x as f64).to_bits(), "{x}");
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
                // SAFETY: as above.
                let got = unsafe { clamped_floor_of(x, lo, hi) };
                assert_eq!(
                    got,
                    super::super::clamped_floor(x, lo, hi),
                    "{x} in [{lo}, {hi}]"
                );
            }
        }
        for v in [
            0u64,
            1,
            u64::MAX,
            0x8000_0000_0000_0001,
            0x0123_4567_89ab_cdef,
        ] {
            // SAFETY: as above.
            let got = unsafe { popcnt_of(v) };
            assert_eq!(got, v.count_ones() as u64, "{v:x}");
        }
    }

    #[target_feature(enable = "avx2")]
    fn to_pd_of(x: i64) -> f64 {
        let mut out = [0.0; LANES];
        // SAFETY: this function has the features; `out` holds LANES values.
        unsafe { _mm256_storeu_pd(out.as_mut_ptr(), to_pd(_mm256_set1_epi64x(x))) };
        out[3]
    }

    #[target_feature(enable = "avx2")]
    fn clamped_floor_of(x: f64, lo: f64, hi: f64) -> i64 {
        let mut out = [0i64; LANES];
        // SAFETY: as above.
        unsafe {
            let v = clamped_floor(_mm256_set1_pd(x), _mm256_set1_pd(lo), _mm256_set1_pd(hi));
            _mm256_storeu_si256(out.as_mut_ptr() as *mut __m256i, v);
        }
        out[2]
    }

    #[target_feature(enable = "avx2")]
    fn popcnt_of(v: u64) -> u64 {
        let mut out = [0i64; LANES];
        // SAFETY: as above.
        unsafe {
            let p = popcnt(_mm256_set1_epi64x(v as i64));
            _mm256_storeu_si256(out.as_mut_ptr() as *mut __m256i, p);
        }
        out[1] as u64
    }
}
