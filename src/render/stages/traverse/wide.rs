//! The octree walk (and the plain DDA, its one-level case) and the
//! distance-cube walk eight rays at a time, with AVX-512.
//!
//! The scalar walk ([`super::walk_interleaved`]) spends about 230
//! instructions on a cell visit (cachegrind, sphere): the brick index of
//! the cell, the skip byte, for a tagged cell its segment and sub-cell
//! test, and the exit from the cell or block, with branches the hardware
//! cannot predict. Here eight walks step together: each of those
//! operations is one vector instruction for all eight lanes, the loads are
//! gathers, and every per-lane choice is a mask. At 9b25384 (the octree
//! alone) the whole function was 652 instructions and a step ran through
//! part of them once for about 7 live lanes, so under 100 instructions per
//! visit. A lane whose walk ends, at a candidate cell (to the solve
//! queue) or out of its piece (to the record queue), is refilled with the
//! next ray at once; two groups of lanes step in turn, so one group's
//! arithmetic fills the other's wait on its gathers (9.3 ns from a gather
//! to the next one that needs its result, measured on this Zen 4; 4 ns
//! apart when independent).
//!
//! What it buys is smaller than the instruction counts suggest, likely
//! because Zen 4 runs a 512-bit operation as two 256-bit halves and the
//! gathers are slow. Sphere, single thread, min / median of 5
//! alternating runs: the traverse stage 55.4 / 58.8 → 33.9 / 34.5 ms, the
//! frame 139 / 144 → 119 / 120 ms (BENCHMARKS.md has the runs).
//!
//! The two spaces differ only in what a cell's byte says and the box it
//! gives ([`LaneReach`]): the octree's skip byte is a block level, the
//! distance map's is the edge of the empty cube ahead, read from the map
//! of each lane's own octant (the eight maps lie in one allocation, so
//! that is an offset per lane). Single thread, traverse stage, min of 3
//! alternating runs against the scalar distance walk: sphere 44.3 → 25.8
//! ms, teapot 209 → 143, cranium 127 → 80 — below the octree's lane walk
//! (36, 148, 110) since a ray visits fewer cells (sphere 5.35 per ray
//! against 11.3).
//!
//! Every lane does the scalar walk's arithmetic in the same order (no fused
//! multiply-adds, the same `min`/`max` operand order, whose NaN rule the
//! vector instructions share), so each ray visits the same cells and hands
//! the same segment bits to the solve stage as the scalar walk — tested
//! below against it, ray by ray, through edges and corners and along axes.
//! Only the order rays leave in differs, and nothing downstream depends on
//! it.
//!
//! Rays are taken from the input in chunks of [`CHUNK`]: each chunk's start
//! states (the piece in cell coordinates, its cell and parameter, stepped
//! past the cell when `advance` is set) are laid out contiguously first, so
//! a refill is one masked expand per column.

use std::arch::x86_64::*;
use std::sync::OnceLock;

use super::super::super::context::Ctx;
use super::super::super::packet::{Queue, Rays};
use crate::classify::bezier::SUB;
use crate::classify::plane::CellTests;
use crate::filter::coeffs::Coefficient;
use crate::lattice::Bricked;
use crate::octree::distance::Proximity;
use crate::octree::{BLOCK_ORIGIN_BITS, FIRST_BLOCK_CELLS, Octree, TAGGED};
use crate::render::stats::Counters;

const LANES: usize = 8;

/// Rays staged at a time.
pub(super) const CHUNK: usize = 64;

/// A staged column: a chunk and a lane group of slack, so a full-width load
/// at any position inside the chunk stays inside the column.
/// (Eight lanes of slack also cover [`super::avx2`]'s four.)
pub(super) type Col<T> = [T; CHUNK + LANES];

const _: () = assert!(SUB == 4, "the span masks below assume 4³ sub-cells");

/// Whether this CPU runs the wide walk: AVX-512 (F, DQ) with the
/// vector population count the tagged-cell index needs, when the renderer
/// runs its AVX-512 lanes ([`crate::simd::Isa::current`], so `SNELL_ISA`
/// below `avx512` selects the scalar walk).
pub fn available() -> bool {
    static OK: OnceLock<bool> = OnceLock::new();
    *OK.get_or_init(|| {
        crate::simd::Isa::current() == crate::simd::Isa::Avx512
            && std::arch::is_x86_feature_detected!("avx512vpopcntdq")
    })
}

/// The start states of up to [`CHUNK`] rays, column by column (for both
/// lane walks).
pub(super) struct Staged {
    pub(super) len: usize,
    pub(super) r: Col<i64>,
    pub(super) ou: [Col<f64>; 3],
    pub(super) du: [Col<f64>; 3],
    pub(super) inv: [Col<f64>; 3],
    pub(super) cell: [Col<i64>; 3],
    pub(super) t: Col<f64>,
    pub(super) t_start: Col<f64>,
    pub(super) t_end: Col<f64>,
}

impl Staged {
    pub(super) fn new() -> Staged {
        Staged {
            len: 0,
            r: [0; CHUNK + LANES],
            ou: [[0.0; CHUNK + LANES]; 3],
            du: [[0.0; CHUNK + LANES]; 3],
            inv: [[0.0; CHUNK + LANES]; 3],
            cell: [[0; CHUNK + LANES]; 3],
            t: [0.0; CHUNK + LANES],
            t_start: [0.0; CHUNK + LANES],
            t_end: [0.0; CHUNK + LANES],
        }
    }

    /// Stages `input`'s rays (at most [`CHUNK`]) as the scalar walk starts
    /// them ([`super::walk_start`]), eight at a time: each column is a
    /// gather by ray index, and the rays to step past their cell first do
    /// it in lanes ([`exit_box`] of the cell alone is [`super::exit_cell`],
    /// tested). Staged one ray at a time this was a fifth of the distance
    /// walk's samples (3.9% of the sphere's frame against 13.7% for the
    /// walk); in lanes the traverse stage went 23.5 → 22.3 ms (min of 5).
    #[target_feature(enable = "avx512f,avx512vl,avx512dq")]
    fn stage<T: Coefficient>(&mut self, ctx: &Ctx<T>, rays: &mut Rays, input: &[u32]) {
        debug_assert!(input.len() <= CHUNK);
        for (g, group) in input.chunks(LANES).enumerate() {
            let k = g * LANES;
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
                let at = |col: &mut Col<f64>| col.as_mut_ptr().add(k);
                _mm512_storeu_epi64(self.r.as_mut_ptr().add(k), l.r);
                for a in 0..3 {
                    _mm512_storeu_pd(at(&mut self.ou[a]), l.ou[a]);
                    _mm512_storeu_pd(at(&mut self.du[a]), l.du[a]);
                    _mm512_storeu_pd(at(&mut self.inv[a]), l.inv[a]);
                    _mm512_storeu_epi64(self.cell[a].as_mut_ptr().add(k), l.cell[a]);
                }
                _mm512_storeu_pd(at(&mut self.t), l.t);
                _mm512_storeu_pd(at(&mut self.t_start), l.t_start);
                _mm512_storeu_pd(at(&mut self.t_end), l.t_end);
            }
        }
        self.len = input.len();
    }
}

/// Eight walks in registers (also the refract stage's lane clearing,
/// which steps cells as a walk does).
#[derive(Clone, Copy)]
pub(crate) struct Lanes {
    pub r: __m512i,
    pub ou: [__m512d; 3],
    pub du: [__m512d; 3],
    pub inv: [__m512d; 3],
    pub cell: [__m512i; 3],
    pub t: __m512d,
    pub t_start: __m512d,
    pub t_end: __m512d,
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
            let pd = |col: &[f64]| {
                _mm512_mask_i64gather_pd::<8>(_mm512_setzero_pd(), m, r, col.as_ptr())
            };
            let off = _mm512_set1_pd(ctx.lattice.offset);
            let mut l = Lanes {
                r,
                ou: [_mm512_setzero_pd(); 3],
                du: [_mm512_setzero_pd(); 3],
                inv: [_mm512_setzero_pd(); 3],
                cell: [_mm512_setzero_si512(); 3],
                t: pd(&rays.t),
                t_start: pd(&rays.t_start),
                t_end: pd(&rays.t_end),
            };
            for a in 0..3 {
                let sa = _mm512_set1_pd(ctx.inv_spacing[a]);
                l.ou[a] = _mm512_add_pd(_mm512_mul_pd(pd(&rays.org[a]), sa), off);
                l.du[a] = _mm512_mul_pd(pd(&rays.dir[a]), sa);
                l.inv[a] = pd(&rays.cell_inv[a]);
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

/// What the walk reads, as vectors and base pointers.
struct Space<'a, R> {
    /// Cells per axis (the lattice's, as [`super::in_range`] checks).
    n: [__m512i; 3],
    /// Bricks along x and y ([`crate::lattice::Bricked::index`]'s strides).
    bricks: [__m512i; 2],
    /// The empty space around each cell.
    reach: R,
    /// The tagged-cell index's words and ranks, and the sub-cell masks in
    /// its slot order.
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

/// A byte per cell (bricked, as the tagged-cell index) saying how far the
/// empty space around it reaches, and the box a lane may jump over from it:
/// the lane form of [`super::EmptySpace`].
trait LaneReach {
    /// Each lane of `go`'s byte, from its cell's bricked slot, and the
    /// tag words of the lanes' bricks where the byte came from them (for
    /// the tagged-cell test, which then need not gather them again).
    unsafe fn byte(&self, l: &Lanes, slot: __m512i, go: __mmask8) -> (__m512i, Option<__m512i>);
    /// The lanes whose byte marks a tagged cell, and each lane's reach
    /// (what [`LaneReach::exit`] takes; that of the cell alone where
    /// tagged).
    unsafe fn reach(&self, go: __mmask8, byte: __m512i) -> (__mmask8, __m512i);
    /// Where each lane leaves the box of its `reach` (not before its `t`),
    /// and the cell it enters.
    unsafe fn exit(&self, l: &Lanes, reach: __m512i) -> (__m512d, [__m512i; 3]);
}

/// The byte at `index` of `bytes` (a multiple of 4 long) for each lane of
/// `go`, from the aligned dword holding it.
///
/// # Safety
/// AVX-512 F and DQ; every lane of `go` indexes `bytes`.
#[inline(always)]
unsafe fn gather_bytes(bytes: &[u8], index: __m512i, go: __mmask8) -> __m512i {
    // SAFETY: as the caller guarantees; the dword holding an indexed byte
    // lies in `bytes`, whose length is a multiple of 4.
    unsafe {
        let dword = _mm512_mask_i64gather_epi32::<4>(
            _mm256_setzero_si256(),
            go,
            _mm512_srli_epi64::<2>(index),
            bytes.as_ptr() as *const i32,
        );
        let shift = _mm512_slli_epi64::<3>(_mm512_and_si512(index, _mm512_set1_epi64(3)));
        _mm512_and_si512(
            _mm512_srlv_epi64(_mm512_cvtepu32_epi64(dword), shift),
            _mm512_set1_epi64(0xFF),
        )
    }
}

/// The octree's aligned blocks ([`super::OctreeBlocks`]): a block level
/// per cell, from the flattened skip map (a byte per cell) or from a byte
/// per 4³ brick with the brick's tag word ([`BrickLevels`]).
struct Blocks<M> {
    map: M,
    leaf_level: __m512i,
}

/// Where [`Blocks`] reads each lane's skip byte.
trait SkipBytes {
    /// The skip byte of each lane of `go`, from its cell's bricked slot,
    /// and the brick's tag words where they were read for it.
    unsafe fn byte(&self, slot: __m512i, go: __mmask8) -> (__m512i, Option<__m512i>);
}

/// The flattened skip map, a byte per cell ([`Octree::skip_map`]).
struct ByteMap<'a>(&'a [u8]);

impl SkipBytes for ByteMap<'_> {
    #[inline(always)]
    unsafe fn byte(&self, slot: __m512i, go: __mmask8) -> (__m512i, Option<__m512i>) {
        // SAFETY: called only from the walk, which runs with the features;
        // a lattice cell's slot lies in the map (`layout_fits`).
        (unsafe { gather_bytes(self.0, slot, go) }, None)
    }
}

/// The octree's levels per brick ([`Octree::brick_levels`]) with the
/// bricks' tag words ([`Octree::brick_tags`]): for a large lattice, whose
/// byte map the walk's gathers read far out of cache, the same bytes from
/// a byte per 64 cells (the teapot's 180 KB, in cache) and the tag words
/// (a bit per cell), which the tagged-cell test reads anyway and so
/// takes from here ([`tagged_slot`]). Against the octree's former map
/// of a `u16` per 2³ block (2.9 MB on the teapot), whose gather held a
/// quarter of the walk's samples on the teapot (`perf record`), two
/// threads, four alternating rounds of 20 frames on a Zen 4: traverse
/// stage teapot 103.7–122.0 → 100.3–108.9 ms CPU, cranium 67.4–77.5 →
/// 60.6–71.3; single thread, eight rounds of 5 teapot frames, before
/// the words were taken from here: 105–134 (median 112.6) → 101–114
/// (107). The sphere's byte map (262 KB) is as
/// fast either way (traverse 34.45–34.90 / 34.39–34.52 ms in the quiet
/// rounds of five alternating), so
/// small lattices keep it ([`BRICK_LEVELS_ABOVE`]).
pub(super) struct BrickLevels<'a> {
    pub(super) words: &'a [u64],
    pub(super) levels: &'a [u8],
}

impl<'a> BrickLevels<'a> {
    pub(super) fn of(tree: &'a Octree) -> Self {
        BrickLevels {
            words: tree.brick_tag_words(),
            levels: tree.brick_levels(),
        }
    }
}

impl SkipBytes for BrickLevels<'_> {
    /// [`crate::octree::decode_brick`] per lane.
    #[inline(always)]
    unsafe fn byte(&self, slot: __m512i, go: __mmask8) -> (__m512i, Option<__m512i>) {
        // SAFETY: called only from the walk, which runs with the features;
        // a lattice cell's brick has a tag word and a level, whose table's
        // length is a multiple of 4 (`layout_fits`).
        unsafe {
            let brick = _mm512_srli_epi64::<6>(slot);
            let k = _mm512_and_si512(slot, _mm512_set1_epi64(63));
            let word = _mm512_mask_i64gather_epi64::<8>(
                _mm512_setzero_si512(),
                go,
                brick,
                self.words.as_ptr() as *const i64,
            );
            let level = gather_bytes(self.levels, brick, go);
            let one = _mm512_set1_epi64(1);
            let tagged = _mm512_test_epi64_mask(_mm512_srlv_epi64(word, k), one);
            // The 2³ block's cells (`octree::block_cells`).
            let block = _mm512_sllv_epi64(
                _mm512_set1_epi64(FIRST_BLOCK_CELLS as i64),
                _mm512_and_si512(k, _mm512_set1_epi64(BLOCK_ORIGIN_BITS as i64)),
            );
            let occupied = _mm512_test_epi64_mask(word, block);
            let byte = _mm512_maskz_mov_epi64(!occupied, level);
            let byte = _mm512_mask_mov_epi64(byte, tagged, _mm512_set1_epi64(TAGGED as i64));
            (byte, Some(word))
        }
    }
}

/// Skip-map bytes above which the octree walk reads the brick levels:
/// about where the byte map leaves a core's L2 cache (1–4 MiB on the
/// machines measured). The sphere's 262 KB stays below, the cranium's 7 MB
/// and the teapot's 11.5 MB above.
const BRICK_LEVELS_ABOVE: usize = 2 << 20;

/// Whether the lane walks (this one and [`super::avx2`]'s) read `tree`'s
/// brick levels rather than its byte map ([`BRICK_LEVELS_ABOVE`]).
pub(super) fn reads_brick_levels(tree: &Octree) -> bool {
    tree.skip_map().len() > BRICK_LEVELS_ABOVE
}

impl<M: SkipBytes> LaneReach for Blocks<M> {
    #[inline(always)]
    unsafe fn byte(&self, _: &Lanes, slot: __m512i, go: __mmask8) -> (__m512i, Option<__m512i>) {
        // SAFETY: as the caller guarantees.
        unsafe { self.map.byte(slot, go) }
    }

    #[inline(always)]
    unsafe fn reach(&self, go: __mmask8, byte: __m512i) -> (__mmask8, __m512i) {
        // SAFETY: called only from the walk, which runs with the features.
        unsafe {
            let tagged = _mm512_mask_cmpeq_epi64_mask(go, byte, _mm512_set1_epi64(TAGGED as i64));
            let small = _mm512_cmplt_epu64_mask(byte, self.leaf_level);
            (tagged, _mm512_maskz_mov_epi64(!(tagged | small), byte))
        }
    }

    #[inline(always)]
    unsafe fn exit(&self, l: &Lanes, level: __m512i) -> (__m512d, [__m512i; 3]) {
        // SAFETY: as above.
        unsafe { exit_block(l, level) }
    }
}

/// The distance field's cubes ([`super::DistanceCubes`]): per lane the
/// map of its direction's octant (or the one centred map), the cube's edge
/// per cell, 0 for a tagged cell.
struct Cubes<'a> {
    bytes: &'a [u8],
    /// Per axis, from an octant's map to that of the octant with the axis
    /// reversed: the maps' length times 1, 2, 4 (0 for the centred map).
    octant_step: [__m512i; 3],
    centred: bool,
    /// Last cell index per axis.
    last: [__m512i; 3],
}

impl LaneReach for Cubes<'_> {
    /// The byte at the slot in the lane's octant map
    /// ([`crate::octree::distance::octant`]: bit `a` when the direction
    /// points down axis `a`).
    #[inline(always)]
    unsafe fn byte(&self, l: &Lanes, slot: __m512i, go: __mmask8) -> (__m512i, Option<__m512i>) {
        // SAFETY: as above; the lanes of `go` hold cells of the lattice,
        // whose slots lie in each octant's map (`distance_layout_fits`).
        unsafe {
            let mut index = slot;
            for a in 0..3 {
                let down = _mm512_cmp_pd_mask::<_CMP_LT_OQ>(l.du[a], _mm512_setzero_pd());
                index = _mm512_mask_add_epi64(index, down, index, self.octant_step[a]);
            }
            (gather_bytes(self.bytes, index, go), None)
        }
    }

    /// The reach is the cube's edge less one (0 for the cell alone).
    #[inline(always)]
    unsafe fn reach(&self, go: __mmask8, byte: __m512i) -> (__mmask8, __m512i) {
        // SAFETY: as above.
        unsafe {
            let tagged = _mm512_mask_cmpeq_epi64_mask(go, byte, _mm512_setzero_si512());
            let k = _mm512_max_epi64(
                _mm512_sub_epi64(byte, _mm512_set1_epi64(1)),
                _mm512_setzero_si512(),
            );
            (tagged, k)
        }
    }

    /// [`super::DistanceCubes`]'s box: `k` cells ahead along each axis (and
    /// behind too for centred cubes), clipped to the lattice.
    #[inline(always)]
    unsafe fn exit(&self, l: &Lanes, k: __m512i) -> (__m512d, [__m512i; 3]) {
        // SAFETY: as above.
        unsafe {
            let zero = _mm512_setzero_si512();
            let mut lo = l.cell;
            let mut hi = l.cell;
            for a in 0..3 {
                let (down, up) = if self.centred {
                    (k, k)
                } else {
                    let neg = _mm512_cmp_pd_mask::<_CMP_LT_OQ>(l.du[a], _mm512_setzero_pd());
                    (
                        _mm512_maskz_mov_epi64(neg, k),
                        _mm512_maskz_mov_epi64(!neg, k),
                    )
                };
                lo[a] = _mm512_max_epi64(_mm512_sub_epi64(l.cell[a], down), zero);
                hi[a] = _mm512_min_epi64(_mm512_add_epi64(l.cell[a], up), self.last[a]);
            }
            exit_box(l, lo, hi)
        }
    }
}

/// `(x & 3)` and friends: the bricked slot of each lane's cell.
#[inline(always)]
unsafe fn brick_slot<R>(s: &Space<R>, cell: &[__m512i; 3]) -> __m512i {
    // SAFETY: called only from the walk, which runs with the features.
    unsafe { bricked_index(&s.bricks, cell) }
}

/// [`Bricked::index`] per lane, with `bricks` its bricks along x and y.
#[inline(always)]
pub(crate) unsafe fn bricked_index(bricks: &[__m512i; 2], cell: &[__m512i; 3]) -> __m512i {
    // SAFETY: called only from functions with AVX-512 F and DQ.
    unsafe {
        let [x, y, z] = *cell;
        let three = _mm512_set1_epi64(3);
        let brick = _mm512_add_epi64(
            _mm512_srli_epi64::<2>(x),
            _mm512_mullo_epi64(
                bricks[0],
                _mm512_add_epi64(
                    _mm512_srli_epi64::<2>(y),
                    _mm512_mullo_epi64(bricks[1], _mm512_srli_epi64::<2>(z)),
                ),
            ),
        );
        let within = _mm512_or_si512(
            _mm512_and_si512(x, three),
            _mm512_or_si512(
                _mm512_slli_epi64::<2>(_mm512_and_si512(y, three)),
                _mm512_slli_epi64::<4>(_mm512_and_si512(z, three)),
            ),
        );
        _mm512_or_si512(_mm512_slli_epi64::<6>(brick), within)
    }
}

/// [`crate::classify::tagged::TaggedIndex::slot`] per lane of `go`, from
/// the index's words and ranks and each lane's bricked index `at`: the
/// lanes whose cell is tagged, and their slots. `gathered`: the lanes'
/// words of `words`, where the caller has them already.
///
/// # Safety
/// AVX-512 F, DQ and VPOPCNTDQ; every lane of `go` indexes a cell of the
/// index's lattice.
#[inline(always)]
pub(crate) unsafe fn tagged_slot(
    (words, rank): (&[u64], &[u32]),
    at: __m512i,
    go: __mmask8,
    gathered: Option<__m512i>,
) -> (__mmask8, __m512i) {
    // SAFETY: as the caller guarantees; a lattice cell's brick has a word
    // and a rank.
    unsafe {
        let one = _mm512_set1_epi64(1);
        let brick = _mm512_srli_epi64::<6>(at);
        let bit = _mm512_and_si512(at, _mm512_set1_epi64(63));
        let word = gathered.unwrap_or_else(|| {
            _mm512_mask_i64gather_epi64::<8>(
                _mm512_setzero_si512(),
                go,
                brick,
                words.as_ptr() as *const i64,
            )
        });
        let has = _mm512_mask_test_epi64_mask(go, _mm512_srlv_epi64(word, bit), one);
        let before = _mm512_cvtepu32_epi64(_mm512_mask_i64gather_epi32::<4>(
            _mm256_setzero_si256(),
            go,
            brick,
            rank.as_ptr() as *const i32,
        ));
        let below = _mm512_and_si512(word, _mm512_sub_epi64(_mm512_sllv_epi64(one, bit), one));
        (has, _mm512_add_epi64(before, _mm512_popcnt_epi64(below)))
    }
}

/// [`super::clamped_floor`] per lane: the clamp first, then truncation.
#[inline(always)]
unsafe fn clamped_floor(x: __m512d, lo: __m512d, hi: __m512d) -> __m512i {
    // SAFETY: called only from `walk_octree`, which runs with the
    // features these intrinsics need; memory accesses are marked below.
    unsafe { _mm512_cvttpd_epi64(_mm512_min_pd(_mm512_max_pd(x, lo), hi)) }
}

/// The sub-cell bits whose index along the axis of stride `s = 2^log` (1,
/// 4, 16 in the 4³ layout) lies in `lo..=hi`: `rep·(2^(s(hi+1)) − 2^(s·lo))`, with
/// `rep` one bit per row along that axis — what the scalar walk looks up
/// in [`super::cell::AXIS_SPAN`] (tested equal). Shifts by 64 give 0, so the top
/// row needs no special case.
#[inline(always)]
unsafe fn axis_span(rep: u64, log: u64, lo: __m512i, hi: __m512i) -> __m512i {
    // SAFETY: called only from `walk_octree`, which runs with the
    // features these intrinsics need; memory accesses are marked below.
    unsafe {
        let rep = _mm512_set1_epi64(rep as i64);
        let log = _mm512_set1_epi64(log as i64);
        let one = _mm512_set1_epi64(1);
        let top = _mm512_sllv_epi64(_mm512_add_epi64(hi, one), log);
        let bottom = _mm512_sllv_epi64(lo, log);
        _mm512_sub_epi64(_mm512_sllv_epi64(rep, top), _mm512_sllv_epi64(rep, bottom))
    }
}

/// `rep` and the stride's log₂ per axis of the 4³ sub-cell layout (x
/// fastest).
pub(super) const SPAN_ROWS: [(u64, u64); 3] = [
    (0x1111_1111_1111_1111, 0),
    (0x0001_0001_0001_0001, 2),
    (1, 4),
];

/// [`super::may_meet_tagged_sub_cell`] per lane.
#[inline(always)]
unsafe fn may_meet(l: &Lanes, t0: __m512d, t1: __m512d, mask: __m512i) -> __mmask8 {
    // SAFETY: called only from `walk_octree`, which runs with the
    // features these intrinsics need; memory accesses are marked below.
    unsafe {
        let n = _mm512_set1_pd(SUB as f64);
        let zero = _mm512_setzero_pd();
        let last = _mm512_set1_pd(SUB as f64 - 1.0);
        let eps = _mm512_set1_pd(1e-9);
        let mut bbox = _mm512_set1_epi64(-1);
        for a in 0..3 {
            let cf = _mm512_cvtepi64_pd(l.cell[a]);
            let local = |t: __m512d| {
                _mm512_mul_pd(
                    n,
                    _mm512_sub_pd(_mm512_add_pd(l.ou[a], _mm512_mul_pd(t, l.du[a])), cf),
                )
            };
            let (v0, v1) = (local(t0), local(t1));
            let (lo, hi) = (_mm512_min_pd(v0, v1), _mm512_max_pd(v0, v1));
            let lo = clamped_floor(_mm512_sub_pd(lo, eps), zero, last);
            let hi = clamped_floor(_mm512_add_pd(hi, eps), zero, last);
            let (rep, log) = SPAN_ROWS[a];
            let span = axis_span(rep, log, lo, hi);
            let d = _mm512_sub_pd(v0, v1);
            let nan = _mm512_cmp_pd_mask::<_CMP_UNORD_Q>(d, d);
            bbox = _mm512_and_si512(
                bbox,
                _mm512_mask_mov_epi64(span, nan, _mm512_set1_epi64(-1)),
            );
        }
        _mm512_test_epi64_mask(mask, bbox)
    }
}

/// The lanes of `m` whose cell's plane (in the record at `record`, in
/// 8-byte words) proves the segment `t0..t1` clear of the surface, as
/// [`crate::classify::PlaneBounds::clears`] decides for one (the same
/// operations in the same order).
#[inline(always)]
unsafe fn plane_clears(
    (tests, margin): (&[CellTests], f64),
    l: &Lanes,
    t0: __m512d,
    t1: __m512d,
    record: __m512i,
    m: __mmask8,
) -> __mmask8 {
    // SAFETY: called only from the walk, which runs with the features these
    // intrinsics need; the lanes of `m` hold records of tagged cells, below
    // the records' count.
    unsafe {
        // Three gathers of pairs (the record's words 1 to 3), each split
        // into its two values.
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
        let at = |t: __m512d| {
            let mut v = p[0];
            for a in 0..3 {
                let u = _mm512_sub_pd(
                    _mm512_add_pd(l.ou[a], _mm512_mul_pd(t, l.du[a])),
                    _mm512_cvtepi64_pd(l.cell[a]),
                );
                v = _mm512_add_pd(v, _mm512_mul_pd(p[1 + a], u));
            }
            v
        };
        let e = _mm512_add_pd(p[4], _mm512_set1_pd(margin));
        let ne = _mm512_sub_pd(_mm512_setzero_pd(), e);
        let (v0, v1) = (at(t0), at(t1));
        let above =
            _mm512_cmp_pd_mask::<_CMP_GT_OQ>(v0, e) & _mm512_cmp_pd_mask::<_CMP_GT_OQ>(v1, e);
        let below =
            _mm512_cmp_pd_mask::<_CMP_LT_OQ>(v0, ne) & _mm512_cmp_pd_mask::<_CMP_LT_OQ>(v1, ne);
        m & (above | below)
    }
}

/// [`super::cell_span`] per lane, then clipped to the piece as
/// [`super::tagged_segment`] does.
#[inline(always)]
unsafe fn tagged_segment(l: &Lanes) -> (__m512d, __m512d) {
    // SAFETY: called only from `walk_octree`, which runs with the
    // features these intrinsics need; memory accesses are marked below.
    unsafe {
        let mut c0 = _mm512_set1_pd(f64::NEG_INFINITY);
        let mut c1 = _mm512_set1_pd(f64::INFINITY);
        let one = _mm512_set1_epi64(1);
        for a in 0..3 {
            let moves = _mm512_cmp_pd_mask::<_CMP_NEQ_UQ>(l.du[a], _mm512_setzero_pd());
            let ta = _mm512_mul_pd(
                _mm512_sub_pd(_mm512_cvtepi64_pd(l.cell[a]), l.ou[a]),
                l.inv[a],
            );
            let tb = _mm512_mul_pd(
                _mm512_sub_pd(
                    _mm512_cvtepi64_pd(_mm512_add_epi64(l.cell[a], one)),
                    l.ou[a],
                ),
                l.inv[a],
            );
            c0 = _mm512_mask_max_pd(c0, moves, c0, _mm512_min_pd(ta, tb));
            c1 = _mm512_mask_min_pd(c1, moves, c1, _mm512_max_pd(ta, tb));
        }
        let t0 = _mm512_max_pd(c0, l.t_start);
        let t1 = _mm512_max_pd(_mm512_min_pd(c1, l.t_end), t0);
        (t0, t1)
    }
}

/// [`super::exit_block`] per lane, with per-lane levels (0: the cell): the
/// block's bounds and its walls' times in one pass over the axes, then the
/// exit as [`exit_box`] takes it ([`exit_from`]).
#[inline(always)]
unsafe fn exit_block(l: &Lanes, level: __m512i) -> (__m512d, [__m512i; 3]) {
    // SAFETY: called only from the walk, which runs with the features
    // these intrinsics need.
    unsafe {
        let one = _mm512_set1_epi64(1);
        let size = _mm512_sllv_epi64(one, level);
        let mut lo = [_mm512_setzero_si512(); 3];
        let mut hi = [_mm512_setzero_si512(); 3];
        let mut te = [_mm512_setzero_pd(); 3];
        let mut pos = [0u8; 3];
        let mut neg = [0u8; 3];
        for a in 0..3 {
            lo[a] = _mm512_sllv_epi64(_mm512_srav_epi64(l.cell[a], level), level);
            hi[a] = _mm512_sub_epi64(_mm512_add_epi64(lo[a], size), one);
            (te[a], pos[a], neg[a]) = wall(l, a, lo[a], hi[a]);
        }
        exit_from(l, (lo, hi), te, (pos, neg))
    }
}

/// [`super::exit_box`] per lane: where each lane leaves its box `lo ..= hi`
/// (which holds its cell), not before its `t`, and the cell it enters.
#[inline(always)]
pub(crate) unsafe fn exit_box(
    l: &Lanes,
    lo: [__m512i; 3],
    hi: [__m512i; 3],
) -> (__m512d, [__m512i; 3]) {
    // SAFETY: called only from the walk, which runs with the features
    // these intrinsics need.
    unsafe {
        let mut te = [_mm512_setzero_pd(); 3];
        let mut pos = [0u8; 3];
        let mut neg = [0u8; 3];
        for a in 0..3 {
            (te[a], pos[a], neg[a]) = wall(l, a, lo[a], hi[a]);
        }
        exit_from(l, (lo, hi), te, (pos, neg))
    }
}

/// Along axis `a`, when each lane's ray reaches the wall of `lo ..= hi` it
/// leaves through (∞ along an axis it does not move on), and the lanes
/// moving up and down the axis.
#[inline(always)]
unsafe fn wall(l: &Lanes, a: usize, lo: __m512i, hi: __m512i) -> (__m512d, u8, u8) {
    // SAFETY: called only from the walk's functions, which have the features.
    unsafe {
        let zero = _mm512_setzero_pd();
        let pos = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(l.du[a], zero);
        let neg = _mm512_cmp_pd_mask::<_CMP_LT_OQ>(l.du[a], zero);
        let wall = _mm512_mask_mov_epi64(lo, pos, _mm512_add_epi64(hi, _mm512_set1_epi64(1)));
        let tw = _mm512_mul_pd(_mm512_sub_pd(_mm512_cvtepi64_pd(wall), l.ou[a]), l.inv[a]);
        let te = _mm512_mask_mov_pd(_mm512_set1_pd(f64::INFINITY), pos | neg, tw);
        (te, pos, neg)
    }
}

/// The end of [`exit_box`]: from the walls' times `te` of the box `lo ..= hi`
/// and the direction's signs, the exit axis, time and next cell.
#[inline(always)]
unsafe fn exit_from(
    l: &Lanes,
    (lo, hi): ([__m512i; 3], [__m512i; 3]),
    te: [__m512d; 3],
    (pos, neg): ([u8; 3], [u8; 3]),
) -> (__m512d, [__m512i; 3]) {
    // SAFETY: called only from the walk's functions, which have the features.
    unsafe {
        let one = _mm512_set1_epi64(1);
        // The scalar walk's axis choice: x unless y is strictly sooner (or x
        // is NaN), then that unless z is.
        let first01 = _mm512_cmp_pd_mask::<_CMP_LE_OQ>(te[0], te[1]);
        let t01 = _mm512_mask_mov_pd(te[1], first01, te[0]);
        let before2 = _mm512_cmp_pd_mask::<_CMP_LE_OQ>(t01, te[2]);
        let t_exit = _mm512_mask_mov_pd(te[2], before2, t01);
        let axis = [first01 & before2, !first01 & before2, !before2];
        let t_new = _mm512_max_pd(t_exit, l.t);
        let mut next = l.cell;
        for a in 0..3 {
            let at = _mm512_add_pd(l.ou[a], _mm512_mul_pd(t_new, l.du[a]));
            // Up: floor clamped to [cell, hi]; down: to [lo, cell]; along an
            // axis the ray does not move, [cell, cell] (the clamp gives the
            // cell, as the scalar walk's choice does).
            let floor_lo = _mm512_mask_mov_epi64(l.cell[a], neg[a], lo[a]);
            let floor_hi = _mm512_mask_mov_epi64(l.cell[a], pos[a], hi[a]);
            let inside = clamped_floor(
                at,
                _mm512_cvtepi64_pd(floor_lo),
                _mm512_cvtepi64_pd(floor_hi),
            );
            let past = _mm512_mask_mov_epi64(
                _mm512_mask_mov_epi64(l.cell[a], neg[a], _mm512_sub_epi64(lo[a], one)),
                pos[a],
                _mm512_add_epi64(hi[a], one),
            );
            next[a] = _mm512_mask_mov_epi64(inside, axis[a], past);
        }
        (t_new, next)
    }
}

/// Lanes that end their walk this step.
struct Ended {
    solve: __mmask8,
    escaped: __mmask8,
    t0: __m512d,
    t1: __m512d,
}

/// One step of every `live` lane ([`super::Walk::step`]): lanes that leave
/// their piece or the lattice escape, lanes at a candidate cell end with
/// its segment, the others move past their cell or empty block.
#[inline(always)]
unsafe fn step<R: LaneReach>(
    s: &Space<R>,
    l: &mut Lanes,
    live: __mmask8,
    c: &mut Counters,
) -> Ended {
    // SAFETY: called only from the walk, which runs with the features
    // these intrinsics need; memory accesses are marked below.
    unsafe {
        let mut inside = _mm512_cmp_pd_mask::<_CMP_NGE_UQ>(l.t, l.t_end);
        for a in 0..3 {
            inside &= _mm512_cmplt_epu64_mask(l.cell[a], s.n[a]);
        }
        let go = live & inside;
        let escaped = live & !inside;
        c.cells_visited += go.count_ones() as u64;

        let slot = brick_slot(s, &l.cell);
        // SAFETY: the lanes of `go` hold cells of the lattice.
        let (byte, word) = s.reach.byte(l, slot, go);
        let (tagged, reach) = s.reach.reach(go, byte);

        // Steps with no lane at a tagged cell skip the segments and the
        // sub-cell test: 59% of the steps on the sphere, 48% on the teapot,
        // 50% on the cranium (neighbouring rays reach the surface together).
        let (solve, skipped, t0, t1) = if tagged == 0 {
            (0, 0, _mm512_setzero_pd(), _mm512_setzero_pd())
        } else {
            let (t0, t1) = tagged_segment(l);
            let (solve, skipped) = match s.masks {
                None => (tagged, 0),
                Some((words, rank, masks)) => {
                    // The index's words are gathered for every lane in the
                    // lattice, not just the tagged ones (a cell with its bit
                    // set is a tagged cell): under the predicted branch the
                    // gather starts alongside the skip bytes', and the
                    // mask's gather waits for one gather, not two.
                    // SAFETY (here and the mask's gather): the lanes of `go`
                    // hold lattice cells; a tagged cell's slot is below the
                    // tag count, the masks' length.
                    let (has, index) = tagged_slot((words, rank), slot, go, word);
                    // With planes, each cell's mask and plane are one
                    // record ([`CellTests`]): the plane's gathers read the
                    // line the mask's brought in.
                    let meet = match s.planes {
                        None => {
                            let mask = _mm512_mask_i64gather_epi64::<8>(
                                _mm512_setzero_si512(),
                                has,
                                index,
                                masks.as_ptr() as *const i64,
                            );
                            has & may_meet(l, t0, t1, mask)
                        }
                        Some(planes) => {
                            let record = _mm512_slli_epi64::<2>(index);
                            let mask = _mm512_mask_i64gather_epi64::<8>(
                                _mm512_setzero_si512(),
                                has,
                                record,
                                planes.0.as_ptr() as *const i64,
                            );
                            let meet = has & may_meet(l, t0, t1, mask);
                            if meet == 0 {
                                0
                            } else {
                                meet & !plane_clears(planes, l, t0, t1, record, meet)
                            }
                        }
                    };
                    let has = has & tagged;
                    ((tagged & !has) | (tagged & meet), has & !meet)
                }
            };
            (solve, skipped, t0, t1)
        };
        c.subcell_skips += skipped.count_ones() as u64;

        let moves = go & !solve;
        let (t_new, next) = s.reach.exit(l, reach);
        l.t = _mm512_mask_mov_pd(l.t, moves, t_new);
        for a in 0..3 {
            l.cell[a] = _mm512_mask_mov_epi64(l.cell[a], moves, next[a]);
        }
        Ended {
            solve,
            escaped,
            t0,
            t1,
        }
    }
}

/// Fills the lanes of `free` from the staged chunk at `*pos`, as many as
/// it has left; returns the lanes filled.
#[inline(always)]
unsafe fn refill(l: &mut Lanes, free: __mmask8, staged: &Staged, pos: &mut usize) -> __mmask8 {
    // SAFETY: called only from `walk_octree`, which runs with the
    // features these intrinsics need; memory accesses are marked below.
    unsafe {
        let left = staged.len - *pos;
        let take = if free.count_ones() as usize <= left {
            free
        } else {
            _pdep_u32((1u32 << left) - 1, free as u32) as u8
        };
        let p = *pos;
        // SAFETY (all loads): `p < staged.len ≤ CHUNK`, and every column holds
        // `CHUNK + LANES` values.
        let pd = |old: __m512d, col: &Col<f64>| {
            _mm512_mask_expand_pd(old, take, _mm512_loadu_pd(col.as_ptr().add(p)))
        };
        let epi = |old: __m512i, col: &Col<i64>| {
            _mm512_mask_expand_epi64(old, take, _mm512_loadu_epi64(col.as_ptr().add(p)))
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

/// Whether the sub-cell masks (if any) are indexed in the layout `bricked`
/// of the lattice the walk's byte map covers (they always are when built
/// from one classification; the gathers rely on it).
fn masks_fit<T: Coefficient>(ctx: &Ctx<T>, bricked: Bricked) -> bool {
    ctx.masks.is_none_or(|m| {
        let (index, masks) = m.parts();
        index.bricked() == bricked
            && index.words().0.len() * 64 == bricked.len()
            && index.words().1.len() == index.words().0.len()
            && masks.len() == index.count()
    })
}

/// Whether the wide walk can run over `tree` in `ctx`: the CPU has the
/// features ([`available`]), and the skip map and the sub-cell masks'
/// index cover the lattice in one brick layout.
pub fn fits<T: Coefficient>(ctx: &Ctx<T>, tree: &Octree) -> bool {
    available() && layout_fits(ctx, tree)
}

/// [`fits`] without the CPU check: the octree's skip map and the masks'
/// index cover the lattice in one brick layout (what the AVX2 lane walk,
/// [`super::avx2`], relies on too).
pub(super) fn layout_fits<T: Coefficient>(ctx: &Ctx<T>, tree: &Octree) -> bool {
    tree.tags().cells == ctx.lattice.cells
        && tree.skip_map().len() == tree.bricked().len()
        && tree.brick_levels().len() * 64 >= tree.bricked().len()
        && tree.brick_levels().len().is_multiple_of(4)
        && tree.brick_tag_words().len() * 64 == tree.bricked().len()
        && masks_fit(ctx, tree.bricked())
}

/// [`fits`] for the distance cubes of `p`: the maps (eight octants' or one
/// centred) and the masks' index cover the lattice in one brick layout.
pub fn fits_distance<T: Coefficient>(ctx: &Ctx<T>, p: &Proximity) -> bool {
    available() && distance_layout_fits(ctx, p)
}

/// [`fits_distance`] without the CPU check.
pub(super) fn distance_layout_fits<T: Coefficient>(ctx: &Ctx<T>, p: &Proximity) -> bool {
    let (bytes, stride, centred, bricked) = p.lane_maps();
    let maps = if centred { 1 } else { 8 };
    p.cells() == ctx.lattice.cells
        && bricked == Bricked::new(ctx.lattice.cells)
        && stride == if centred { 0 } else { bricked.len() }
        && bytes.len() == maps * bricked.len()
        && masks_fit(ctx, bricked)
}

/// The tagged cells' records (mask and plane) and the planes' margin, as
/// the walk gathers them: with masks only (the walk looks planes up where
/// a mask passes), kept in the masks' index and built from their masks.
pub(super) fn lane_planes<'a, T: Coefficient>(ctx: &Ctx<'a, T>) -> Option<(&'a [CellTests], f64)> {
    let masks = ctx.masks?;
    ctx.planes.map(|p| {
        let (index, planes, margin) = p.parts();
        let (mask_index, mask_words) = masks.parts();
        assert!(
            std::ptr::eq(index, mask_index) && planes.len() == mask_words.len(),
            "planes and masks share their slots"
        );
        debug_assert!(planes.iter().zip(mask_words).all(|(t, &m)| t.mask == m));
        (planes, margin)
    })
}

/// The sub-cell masks' index and masks, as the walk gathers them.
pub(super) fn lane_masks<'a, T: Coefficient>(
    ctx: &Ctx<'a, T>,
) -> Option<(&'a [u64], &'a [u32], &'a [u64])> {
    ctx.masks.map(|m| {
        let (index, masks) = m.parts();
        let (words, rank) = index.words();
        (words, rank, masks)
    })
}

/// The walk of every ray of `input` to its next candidate cell (pushed on
/// `solve`, its segment in `t`/`seg_end` and its cell set) or out of its
/// piece (pushed on `record`), as [`super::walk_interleaved`] over the
/// octree does.
///
/// # Safety
/// [`fits`] must be true.
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512vpopcntdq,bmi2,popcnt")]
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
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512vpopcntdq,bmi2,popcnt")]
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
        n: ctx.lattice.cells.map(|n| _mm512_set1_epi64(n as i64)),
        bricks: [
            _mm512_set1_epi64(b[0] as i64),
            _mm512_set1_epi64(b[1] as i64),
        ],
        reach: (),
        masks: lane_masks(ctx),
        planes: lane_planes(ctx),
    };
    let leaf_level = _mm512_set1_epi64(leaf_level as i64);
    STAGED.with_borrow_mut(|staged| {
        // SAFETY (both): the caller checked the features.
        let map = BrickLevels::of(tree);
        // The tagged-cell test takes the words the skip bytes were read
        // with: they must be the index's own (they are, in every
        // preparation; the byte map serves any other).
        let shared = space
            .masks
            .is_none_or(|(w, _, _)| std::ptr::eq(w.as_ptr(), map.words.as_ptr()));
        if brick_levels && shared {
            let space = space.with_reach(Blocks { map, leaf_level });
            unsafe { walk(ctx, &space, staged, rays, input, solve, record, c) }
        } else {
            let map = ByteMap(tree.skip_map());
            let space = space.with_reach(Blocks { map, leaf_level });
            unsafe { walk(ctx, &space, staged, rays, input, solve, record, c) }
        }
    });
}

/// [`walk_octree`] over the distance cubes of `p`, as
/// [`super::walk_interleaved`] over them does.
///
/// # Safety
/// [`fits_distance`] must be true.
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512vpopcntdq,bmi2,popcnt")]
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
        n: ctx.lattice.cells.map(|n| _mm512_set1_epi64(n as i64)),
        bricks: [
            _mm512_set1_epi64(b[0] as i64),
            _mm512_set1_epi64(b[1] as i64),
        ],
        reach: Cubes {
            bytes,
            octant_step: [1, 2, 4].map(|m| _mm512_set1_epi64((m * stride) as i64)),
            centred,
            last: ctx.lattice.cells.map(|n| _mm512_set1_epi64(n as i64 - 1)),
        },
        masks: lane_masks(ctx),
        planes: lane_planes(ctx),
    };
    STAGED.with_borrow_mut(|staged| {
        // SAFETY: the caller checked the features.
        unsafe { walk(ctx, &space, staged, rays, input, solve, record, c) }
    });
}

thread_local! {
    /// Each thread's staging area, kept across calls (a traverse call
    /// has a tile's rays or fewer; zeroing 9 KiB per call showed up), for
    /// both lane walks.
    pub(super) static STAGED: std::cell::RefCell<Box<Staged>> = std::cell::RefCell::new(Box::new(Staged::new()));
}

#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512vpopcntdq,bmi2,popcnt")]
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
    let zd = _mm512_setzero_pd();
    let zi = _mm512_setzero_si512();
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
    // Two groups of lanes, stepped in turn: a step is a chain of dependent
    // gathers, and the other group's step fills the wait.
    let mut group = [idle; GROUPS];
    let mut live: [__mmask8; GROUPS] = [0; GROUPS];
    let mut drained = false;
    loop {
        for g in 0..GROUPS {
            while live[g] != 0xFF && !drained {
                if pos == staged.len {
                    match chunks.next() {
                        Some(chunk) => {
                            staged.stage(ctx, rays, chunk);
                            pos = 0;
                        }
                        None => {
                            drained = true;
                            break;
                        }
                    }
                }
                // SAFETY (here and below): this function has the features.
                live[g] |= unsafe { refill(&mut group[g], !live[g], staged, &mut pos) };
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

/// Lane groups in flight.
const GROUPS: usize = 2;

/// Hands the lanes that ended to their queues.
#[inline(always)]
unsafe fn finish(l: &Lanes, e: &Ended, rays: &mut Rays, solve: &mut Queue, record: &mut Queue) {
    let mut out = super::EndedLanes::<LANES>::default();
    // SAFETY: called only from `walk_octree`, which runs with the
    // features these intrinsics need; each array holds LANES values.
    unsafe {
        _mm512_storeu_epi64(out.r.as_mut_ptr(), l.r);
        _mm512_storeu_pd(out.t0.as_mut_ptr(), e.t0);
        _mm512_storeu_pd(out.t1.as_mut_ptr(), e.t1);
        for a in 0..3 {
            _mm512_storeu_epi64(out.cell[a].as_mut_ptr(), l.cell[a]);
        }
    }
    out.hand_over(e.solve as u32, e.escaped as u32, rays, solve, record);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every ray walks as in the scalar walk ([`super::super::lane_check`]).
    #[test]
    fn every_ray_walks_as_in_the_scalar_walk() {
        if !available() {
            return;
        }
        super::super::lane_check::every_ray_walks_as_in_the_scalar_walk::<Wide<false>>();
        super::super::lane_check::every_ray_walks_as_in_the_scalar_walk::<Wide<true>>();
    }

    /// The AVX-512 walk, for the shared check: the octree's blocks read from
    /// the brick levels (`BLOCKS`) or the byte map, whatever the lattice
    /// size.
    struct Wide<const BLOCKS: bool>;

    impl<const BLOCKS: bool> super::super::lane_check::LaneWalk for Wide<BLOCKS> {
        unsafe fn octree<T: Coefficient>(
            ctx: &Ctx<T>,
            tree: (&Octree, u32),
            rays: &mut Rays,
            input: &[u32],
            solve: &mut Queue,
            record: &mut Queue,
            c: &mut Counters,
        ) {
            // The brick levels are read only with the index's own words.
            let words = tree.0.brick_tag_words();
            assert!(
                ctx.masks
                    .is_none_or(|m| std::ptr::eq(m.parts().0.words().0.as_ptr(), words.as_ptr()))
            );
            // SAFETY: the caller's contract.
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
            // SAFETY: the caller's contract.
            unsafe { walk_distance(ctx, p, rays, input, solve, record, c) }
        }

        fn fits<T: Coefficient>(ctx: &Ctx<T>, tree: &Octree) -> bool {
            fits(ctx, tree)
        }

        fn fits_distance<T: Coefficient>(ctx: &Ctx<T>, p: &Proximity) -> bool {
            fits_distance(ctx, p)
        }
    }

    #[test]
    fn spans_are_the_table_of_the_scalar_walk() {
        if !available() {
            return;
        }
        for a in 0..3 {
            for lo in 0..SUB {
                for hi in lo..SUB {
                    // SAFETY: `available` checked the features.
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

    #[target_feature(enable = "avx512f,avx512dq")]
    fn span_of(a: usize, lo: usize, hi: usize) -> u64 {
        let (rep, log) = SPAN_ROWS[a];
        // SAFETY: this function has the features.
        let v = unsafe {
            axis_span(
                rep,
                log,
                _mm512_set1_epi64(lo as i64),
                _mm512_set1_epi64(hi as i64),
            )
        };
        let mut out = [0i64; LANES];
        // SAFETY: `out` holds LANES values.
        unsafe { _mm512_storeu_epi64(out.as_mut_ptr(), v) };
        out[0] as u64
    }
}
