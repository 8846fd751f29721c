//! The cell walks (octree blocks, the plain DDA as its one-level case, and
//! distance cubes) several rays at a time, written once over the vector
//! operations of [`LaneIsa`] and compiled for AVX-512 (eight lanes,
//! [`super::wide`]) and AVX2 (four, [`super::avx2`]).
//!
//! The scalar walk ([`super::walk_interleaved`]) spends about 230
//! instructions on a cell visit (cachegrind, sphere): the brick index of
//! the cell, the skip byte, for a tagged cell its segment and sub-cell
//! test, and the exit from the cell or block, with branches the hardware
//! cannot predict. Here the lanes step together: each of those operations
//! is a vector instruction for all lanes (with AVX-512; AVX2 builds a few,
//! such as the population count, from short sequences), the loads are
//! gathers, and every per-lane choice is a mask. A lane whose walk ends, at a candidate
//! cell (to the solve queue) or out of its piece (to the record queue), is
//! refilled with the next ray at once; two groups of lanes step in turn,
//! so one group's arithmetic fills the other's wait on its gathers (9.3 ns
//! from a gather to the next one that needs its result, measured on a
//! Zen 4; 4 ns apart when independent).
//!
//! The two spaces differ only in what a cell's byte says and the box it
//! gives ([`LaneReach`]): the octree's skip byte is a block level, the
//! distance map's is the edge of the empty cube ahead, read from the map
//! of each lane's own octant (the eight maps lie in one allocation, so
//! that is an offset per lane).
//!
//! Every lane does the scalar walk's arithmetic in the same order (no fused
//! multiply-adds, the same `min`/`max` operand order, whose NaN rule the
//! vector instructions share), so each ray visits the same cells and hands
//! the same segment bits to the solve stage as the scalar walk — tested
//! against it, ray by ray, through edges and corners and along axes, for
//! each instruction set (`lane_check.rs`). Only the order rays leave
//! in differs, and nothing downstream depends on it.
//!
//! Rays are taken from the input in chunks of [`CHUNK`]: each chunk's start
//! states (the piece in cell coordinates, its cell and parameter, stepped
//! past the cell when `advance` is set) are laid out contiguously first, so
//! a refill is one expand per column.

use std::arch::x86_64::_pdep_u32;
use std::arch::x86_64::{
    _CMP_GT_OQ, _CMP_LE_OQ, _CMP_LT_OQ, _CMP_NEQ_UQ, _CMP_NGE_UQ, _CMP_UNORD_Q,
};

use super::super::super::context::Ctx;
use super::super::super::packet::{Queue, Rays};
use super::avx2::Avx2;
use super::wide::Avx512;
use crate::classify::bezier::SUB;
use crate::classify::plane::{self, CellTests};
use crate::filter::coeffs::Coefficient;
use crate::lattice::Bricked;
use crate::octree::distance::Proximity;
use crate::octree::{BLOCK_ORIGIN_BITS, FIRST_BLOCK_CELLS, Octree, TAGGED};
use crate::render::stats::Counters;

/// The most lanes an instruction set walks (AVX-512's eight).
pub(super) const MAX_LANES: usize = 8;

/// Rays staged at a time.
pub(super) const CHUNK: usize = 64;

/// A staged column: a chunk and a lane group of slack, so a full-width load
/// at any position inside the chunk stays inside the column.
pub(super) type Col<T> = [T; CHUNK + MAX_LANES];

const _: () = assert!(SUB == 4, "the span masks below assume 4³ sub-cells");

/// The vector operations the walk is written in, for one instruction set:
/// `F` holds a `f64` per lane, `I` an `i64`, `M` a lane mask. Each
/// operation is the one instruction (or the shortest sequence) the set has
/// for it, with the scalar walk's semantics. The operations are
/// `#[inline(always)]` in every implementation, so they compile into the
/// functions with the set's features that call them: the three walk
/// methods, which each implementation takes from [`walk_methods`] with its
/// features (and, for AVX-512, the staging and the refract stage's
/// clearing). The lane check (`lane_check.rs`) calls them from plain test
/// functions, on a CPU it has checked. On the walk's hot path, code
/// between them is written without closures: a closure does not take its
/// caller's features, and the compiler need not inline it (a walk that
/// grew once left the AVX-512 planes' closure out of line, every operation
/// in it a call, and the distance walk ran 3× slower).
///
/// # Safety
/// Calling any method requires the CPU features of its implementation.
/// Implementing the trait promises `LANES ≤ MAX_LANES`, that a gather
/// reads only the lanes of its mask, and that `expand` reads `LANES`
/// values: the walk's loads rely on them.
pub(crate) unsafe trait LaneIsa: Copy + Sized + 'static {
    /// Lanes per vector (at most [`MAX_LANES`]).
    const LANES: usize;
    /// The bit set of all lanes.
    const FULL: u32 = (1 << Self::LANES) - 1;
    type F: Copy;
    type I: Copy;
    type M: Copy;

    unsafe fn splat(x: f64) -> Self::F;
    unsafe fn add(a: Self::F, b: Self::F) -> Self::F;
    unsafe fn sub(a: Self::F, b: Self::F) -> Self::F;
    unsafe fn mul(a: Self::F, b: Self::F) -> Self::F;
    /// `minpd a, b`: `b` where either is NaN.
    unsafe fn min(a: Self::F, b: Self::F) -> Self::F;
    /// `maxpd a, b`: `b` where either is NaN.
    unsafe fn max(a: Self::F, b: Self::F) -> Self::F;
    /// The comparison of predicate `P` (`_CMP_*`) per lane.
    unsafe fn cmp<const P: i32>(a: Self::F, b: Self::F) -> Self::M;
    /// `yes` in the lanes of `m`, `no` in the others.
    unsafe fn sel(m: Self::M, yes: Self::F, no: Self::F) -> Self::F;

    unsafe fn splat_i(x: i64) -> Self::I;
    unsafe fn add_i(a: Self::I, b: Self::I) -> Self::I;
    unsafe fn sub_i(a: Self::I, b: Self::I) -> Self::I;
    unsafe fn and_i(a: Self::I, b: Self::I) -> Self::I;
    unsafe fn or_i(a: Self::I, b: Self::I) -> Self::I;
    /// Shift left by each lane's count (0 at 64 or more).
    unsafe fn shl(a: Self::I, n: Self::I) -> Self::I;
    /// Logical shift right by each lane's count (0 at 64 or more).
    unsafe fn shr(a: Self::I, n: Self::I) -> Self::I;
    /// `a·b`, for factors below 2³².
    unsafe fn mul_small(a: Self::I, b: Self::I) -> Self::I;
    /// Each lane's population count.
    unsafe fn popcnt(a: Self::I) -> Self::I;
    unsafe fn eq_i(a: Self::I, b: Self::I) -> Self::M;
    /// Signed `a > b`.
    unsafe fn gt_i(a: Self::I, b: Self::I) -> Self::M;
    /// `a & b != 0`.
    unsafe fn test(a: Self::I, b: Self::I) -> Self::M;
    /// `0 ≤ x < n` (for `n` below 2⁶³).
    unsafe fn in_range(x: Self::I, n: Self::I) -> Self::M;
    /// [`LaneIsa::sel`] for integer lanes.
    unsafe fn sel_i(m: Self::M, yes: Self::I, no: Self::I) -> Self::I;
    /// Signed maximum.
    #[inline(always)]
    unsafe fn max_i(a: Self::I, b: Self::I) -> Self::I {
        // SAFETY: as the trait requires.
        unsafe { Self::sel_i(Self::gt_i(b, a), b, a) }
    }
    /// Signed minimum.
    #[inline(always)]
    unsafe fn min_i(a: Self::I, b: Self::I) -> Self::I {
        // SAFETY: as the trait requires.
        unsafe { Self::sel_i(Self::gt_i(a, b), b, a) }
    }
    /// `x as f64`, exact for lattice indices (below 2⁵¹ in magnitude).
    unsafe fn to_f(x: Self::I) -> Self::F;
    /// [`super::clamped_floor`] per lane: the clamp first (a NaN gives
    /// `lo`), then truncation.
    unsafe fn clamped_floor(x: Self::F, lo: Self::F, hi: Self::F) -> Self::I;

    /// The mask of the lanes of bit set `bits`.
    unsafe fn mask(bits: u32) -> Self::M;
    /// The bit set of mask `m`.
    unsafe fn bits(m: Self::M) -> u32;
    unsafe fn and_m(a: Self::M, b: Self::M) -> Self::M;
    unsafe fn or_m(a: Self::M, b: Self::M) -> Self::M;
    /// `a` and not `b`.
    unsafe fn and_not_m(a: Self::M, b: Self::M) -> Self::M;

    /// `base[index]` in the lanes of `m`, 0 in the others.
    ///
    /// # Safety
    /// Also: every lane of `m` indexes inside `base`'s allocation.
    unsafe fn gather_i64(base: *const i64, index: Self::I, m: Self::M) -> Self::I;
    /// `base[index]` zero-extended in the lanes of `m`, 0 in the others.
    ///
    /// # Safety
    /// As [`LaneIsa::gather_i64`].
    unsafe fn gather_u32(base: *const u32, index: Self::I, m: Self::M) -> Self::I;
    unsafe fn store(v: Self::F, to: &mut [f64; MAX_LANES]);
    unsafe fn store_i(v: Self::I, to: &mut [i64; MAX_LANES]);
    /// How a refill places consecutive values into the lanes of a bit set.
    type Expand: Copy;
    unsafe fn expander(take: u32) -> Self::Expand;
    /// The values at `from` in the lanes of the expander's bit set, in
    /// order, and `old` in the others.
    ///
    /// # Safety
    /// Also: [`Self::LANES`] values from `from` are readable.
    unsafe fn expand(old: Self::F, e: Self::Expand, from: *const f64) -> Self::F;
    /// [`LaneIsa::expand`] for integer lanes.
    unsafe fn expand_i(old: Self::I, e: Self::Expand, from: *const i64) -> Self::I;

    /// Stages `input`'s rays (at most [`CHUNK`]) exactly as the scalar walk
    /// starts them ([`super::walk_start`]).
    unsafe fn stage<T: Coefficient>(
        staged: &mut Staged,
        ctx: &Ctx<T>,
        rays: &mut Rays,
        input: &[u32],
    );

    /// The lanes of `m` whose cell's plane (in the record at `record`, in
    /// 8-byte words: four words a [`CellTests`]) proves the segment
    /// `t0..t1` clear of the surface: one lane at a time with
    /// [`crate::classify::plane::clears`], unless the set does it in lanes
    /// (the same operations in the same order).
    #[inline(always)]
    unsafe fn plane_clears(
        (tests, margin): (&[CellTests], f64),
        l: &Lanes<Self>,
        (t0, t1): (Self::F, Self::F),
        record: Self::I,
        m: Self::M,
    ) -> Self::M {
        // SAFETY: as the trait requires; the lanes of `m` hold records of
        // tagged cells.
        unsafe {
            let pd = |v: Self::F| {
                let mut o = [0.0; MAX_LANES];
                Self::store(v, &mut o);
                o
            };
            let (t0, t1) = (pd(t0), pd(t1));
            let ou = l.ou.map(pd);
            let du = l.du.map(pd);
            let cell = l.cell.map(|c| {
                let mut o = [0; MAX_LANES];
                Self::store_i(c, &mut o);
                o
            });
            let mut records = [0; MAX_LANES];
            Self::store_i(record, &mut records);
            let mut clear = 0;
            let mut left = Self::bits(m);
            while left != 0 {
                let k = left.trailing_zeros() as usize;
                left &= left - 1;
                let local =
                    |t: f64| std::array::from_fn(|a| ou[a][k] + t * du[a][k] - cell[a][k] as f64);
                let p = &tests[records[k] as usize >> 2].plane;
                if plane::clears(p, margin, local(t0[k]), local(t1[k])) {
                    clear |= 1 << k;
                }
            }
            Self::mask(clear)
        }
    }

    /// [`octree_body`] compiled with this set's features.
    ///
    /// # Safety
    /// The CPU has the features; [`layout_fits`] holds.
    #[allow(clippy::too_many_arguments)]
    unsafe fn octree<T: Coefficient>(
        ctx: &Ctx<T>,
        tree: (&Octree, u32),
        brick_levels: bool,
        rays: &mut Rays,
        input: &[u32],
        solve: &mut Queue,
        record: &mut Queue,
        c: &mut Counters,
    );

    /// [`distance_body`] compiled with this set's features.
    ///
    /// # Safety
    /// The CPU has the features; [`distance_layout_fits`] holds.
    unsafe fn distance<T: Coefficient>(
        ctx: &Ctx<T>,
        p: &Proximity,
        rays: &mut Rays,
        input: &[u32],
        solve: &mut Queue,
        record: &mut Queue,
        c: &mut Counters,
    );

    /// [`walk_lanes`] compiled with this set's features (called from the
    /// bodies above, inside a closure, which does not inherit them).
    ///
    /// # Safety
    /// The CPU has the features; the space fits the context
    /// ([`layout_fits`] or [`distance_layout_fits`]).
    #[allow(clippy::too_many_arguments)]
    unsafe fn walk<T: Coefficient, R: LaneReach<Self>>(
        ctx: &Ctx<T>,
        space: &Space<Self, R>,
        staged: &mut Staged,
        rays: &mut Rays,
        input: &[u32],
        solve: &mut Queue,
        record: &mut Queue,
        c: &mut Counters,
    );
}

/// The three walk methods of a [`LaneIsa`] implementation, compiled with
/// its features (`$features`, as `#[target_feature(enable = …)]` takes
/// them): each the one call of its body here. The implementing module
/// imports what the signatures name.
macro_rules! walk_methods {
    ($features:literal) => {
        #[target_feature(enable = $features)]
        unsafe fn octree<T: Coefficient>(
            ctx: &Ctx<T>,
            tree: (&Octree, u32),
            brick_levels: bool,
            rays: &mut Rays,
            input: &[u32],
            solve: &mut Queue,
            record: &mut Queue,
            c: &mut Counters,
        ) {
            // SAFETY: this function has the features; the caller's contract.
            unsafe {
                lanes::octree_body::<Self, T>(
                    ctx,
                    tree,
                    brick_levels,
                    rays,
                    input,
                    solve,
                    record,
                    c,
                )
            }
        }

        #[target_feature(enable = $features)]
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
            unsafe { lanes::distance_body::<Self, T>(ctx, p, rays, input, solve, record, c) }
        }

        #[target_feature(enable = $features)]
        unsafe fn walk<T: Coefficient, R: LaneReach<Self>>(
            ctx: &Ctx<T>,
            space: &Space<Self, R>,
            staged: &mut Staged,
            rays: &mut Rays,
            input: &[u32],
            solve: &mut Queue,
            record: &mut Queue,
            c: &mut Counters,
        ) {
            // SAFETY: as above.
            unsafe { lanes::walk_lanes(ctx, space, staged, rays, input, solve, record, c) }
        }
    };
}
pub(super) use walk_methods;

/// The start states of up to [`CHUNK`] rays, column by column.
pub(crate) struct Staged {
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
    fn new() -> Staged {
        Staged {
            len: 0,
            r: [0; CHUNK + MAX_LANES],
            ou: [[0.0; CHUNK + MAX_LANES]; 3],
            du: [[0.0; CHUNK + MAX_LANES]; 3],
            inv: [[0.0; CHUNK + MAX_LANES]; 3],
            cell: [[0; CHUNK + MAX_LANES]; 3],
            t: [0.0; CHUNK + MAX_LANES],
            t_start: [0.0; CHUNK + MAX_LANES],
            t_end: [0.0; CHUNK + MAX_LANES],
        }
    }

    /// Stages `input`'s rays one at a time, exactly as the scalar walk
    /// starts them ([`super::walk_start`], the same function). Kept out of
    /// the walk's loop: scalar code needs none of its features, and a
    /// larger walk can leave the compiler inlining less of it.
    #[inline(never)]
    pub(super) fn stage_scalar<T: Coefficient>(
        &mut self,
        ctx: &Ctx<T>,
        rays: &mut Rays,
        input: &[u32],
    ) {
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

thread_local! {
    /// Each thread's staging area, kept across calls (a traverse call
    /// has a tile's rays or fewer; zeroing 9 KiB per call showed up).
    static STAGED: std::cell::RefCell<Box<Staged>> = std::cell::RefCell::new(Box::new(Staged::new()));
}

/// A group of walks in registers (also the refract stage's lane clearing,
/// which steps cells as a walk does): each ray's piece in cell coordinates
/// ([`super::CellRay`]), its cell, parameter and piece bounds.
pub(crate) struct Lanes<S: LaneIsa> {
    pub r: S::I,
    pub ou: [S::F; 3],
    pub du: [S::F; 3],
    pub inv: [S::F; 3],
    pub cell: [S::I; 3],
    pub t: S::F,
    pub t_start: S::F,
    pub t_end: S::F,
}

impl<S: LaneIsa> Clone for Lanes<S> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<S: LaneIsa> Copy for Lanes<S> {}

/// What the walk reads, as vectors and base pointers.
pub(crate) struct Space<'a, S: LaneIsa, R> {
    /// Cells per axis (the lattice's, as [`super::in_range`] checks).
    n: [S::I; 3],
    /// Bricks along x and y ([`Bricked::index`]'s strides).
    bricks: [S::I; 2],
    /// The empty space around each cell.
    reach: R,
    /// The tagged-cell index's words and ranks, and the sub-cell masks in
    /// its slot order.
    masks: Option<(&'a [u64], &'a [u32], &'a [u64])>,
    /// The tagged cells' records (mask and plane) in the same slot order,
    /// and the planes' margin.
    planes: Option<(&'a [CellTests], f64)>,
}

impl<'a, S: LaneIsa> Space<'a, S, ()> {
    /// The lattice of `ctx` in `bricked`'s layout, with its masks and
    /// planes.
    #[inline(always)]
    unsafe fn of<T: Coefficient>(ctx: &Ctx<'a, T>, bricked: Bricked) -> Self {
        let b = bricked.bricks();
        // SAFETY: called only from functions with the set's features.
        unsafe {
            Space {
                n: ctx.lattice.cells.map(|n| S::splat_i(n as i64)),
                bricks: [S::splat_i(b[0] as i64), S::splat_i(b[1] as i64)],
                reach: (),
                masks: lane_masks(ctx),
                planes: lane_planes(ctx),
            }
        }
    }

    /// The same lattice and masks with a reach.
    fn with_reach<R>(&self, reach: R) -> Space<'a, S, R> {
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
pub(crate) trait LaneReach<S: LaneIsa> {
    /// Each lane of `go`'s byte, from its cell's bricked slot, and the
    /// tag words of the lanes' bricks where the byte came from them (for
    /// the tagged-cell test, which then need not gather them again).
    unsafe fn byte(&self, l: &Lanes<S>, slot: S::I, go: S::M) -> (S::I, Option<S::I>);
    /// The lanes whose byte marks a tagged cell, and each lane's reach
    /// (what [`LaneReach::exit`] takes; that of the cell alone where
    /// tagged).
    unsafe fn reach(&self, go: S::M, byte: S::I) -> (S::M, S::I);
    /// Where each lane leaves the box of its `reach` (not before its `t`),
    /// and the cell it enters.
    unsafe fn exit(&self, l: &Lanes<S>, reach: S::I) -> (S::F, [S::I; 3]);
}

/// The byte at `index` of `bytes` (a multiple of 4 long) for each lane of
/// `go`, from the aligned dword holding it.
///
/// # Safety
/// The set's features; every lane of `go` indexes `bytes`.
#[inline(always)]
unsafe fn gather_bytes<S: LaneIsa>(bytes: &[u8], index: S::I, go: S::M) -> S::I {
    // SAFETY: as the caller guarantees; the dword holding an indexed byte
    // lies in `bytes`, whose length is a multiple of 4.
    unsafe {
        let dword = S::gather_u32(
            bytes.as_ptr() as *const u32,
            S::shr(index, S::splat_i(2)),
            go,
        );
        let shift = S::shl(S::and_i(index, S::splat_i(3)), S::splat_i(3));
        S::and_i(S::shr(dword, shift), S::splat_i(0xFF))
    }
}

/// The octree's aligned blocks ([`super::OctreeBlocks`]): a block level
/// per cell, from the flattened skip map (a byte per cell) or from a byte
/// per 4³ brick with the brick's tag word ([`BrickLevels`]).
struct Blocks<S: LaneIsa, M> {
    map: M,
    leaf_level: S::I,
}

/// Where [`Blocks`] reads each lane's skip byte.
trait SkipBytes<S: LaneIsa> {
    /// The skip byte of each lane of `go`, from its cell's bricked slot,
    /// and the brick's tag words where they were read for it.
    unsafe fn byte(&self, slot: S::I, go: S::M) -> (S::I, Option<S::I>);
}

/// The flattened skip map, a byte per cell ([`Octree::skip_map`]).
struct ByteMap<'a>(&'a [u8]);

impl<S: LaneIsa> SkipBytes<S> for ByteMap<'_> {
    #[inline(always)]
    unsafe fn byte(&self, slot: S::I, go: S::M) -> (S::I, Option<S::I>) {
        // SAFETY: called only from the walk, which runs with the features;
        // a lattice cell's slot lies in the map (`layout_fits`).
        (unsafe { gather_bytes::<S>(self.0, slot, go) }, None)
    }
}

/// The octree's levels per brick ([`Octree::brick_levels`]) with the
/// bricks' tag words ([`Octree::brick_tag_words`]): for a large lattice, whose
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
struct BrickLevels<'a> {
    words: &'a [u64],
    levels: &'a [u8],
}

impl<'a> BrickLevels<'a> {
    fn of(tree: &'a Octree) -> Self {
        BrickLevels {
            words: tree.brick_tag_words(),
            levels: tree.brick_levels(),
        }
    }
}

impl<S: LaneIsa> SkipBytes<S> for BrickLevels<'_> {
    /// [`crate::octree::decode_brick`] per lane.
    #[inline(always)]
    unsafe fn byte(&self, slot: S::I, go: S::M) -> (S::I, Option<S::I>) {
        // SAFETY: called only from the walk, which runs with the features;
        // a lattice cell's brick has a tag word and a level, whose table's
        // length is a multiple of 4 (`layout_fits`).
        unsafe {
            let brick = S::shr(slot, S::splat_i(6));
            let k = S::and_i(slot, S::splat_i(63));
            let word = S::gather_i64(self.words.as_ptr() as *const i64, brick, go);
            let level = gather_bytes::<S>(self.levels, brick, go);
            let tagged = S::test(S::shr(word, k), S::splat_i(1));
            // The 2³ block's cells (`octree::block_cells`).
            let block = S::shl(
                S::splat_i(FIRST_BLOCK_CELLS as i64),
                S::and_i(k, S::splat_i(BLOCK_ORIGIN_BITS as i64)),
            );
            let occupied = S::test(word, block);
            let byte = S::sel_i(occupied, S::splat_i(0), level);
            let byte = S::sel_i(tagged, S::splat_i(TAGGED as i64), byte);
            (byte, Some(word))
        }
    }
}

/// Skip-map bytes above which the octree walk reads the brick levels:
/// about where the byte map leaves a core's L2 cache (1–4 MiB on the
/// machines measured). The sphere's 262 KB stays below, the cranium's 7 MB
/// and the teapot's 11.5 MB above.
const BRICK_LEVELS_ABOVE: usize = 2 << 20;

/// Whether the lane walks read `tree`'s brick levels rather than its byte
/// map ([`BRICK_LEVELS_ABOVE`]).
pub(super) fn reads_brick_levels(tree: &Octree) -> bool {
    tree.skip_map().len() > BRICK_LEVELS_ABOVE
}

impl<S: LaneIsa, M: SkipBytes<S>> LaneReach<S> for Blocks<S, M> {
    #[inline(always)]
    unsafe fn byte(&self, _: &Lanes<S>, slot: S::I, go: S::M) -> (S::I, Option<S::I>) {
        // SAFETY: as the caller guarantees.
        unsafe { self.map.byte(slot, go) }
    }

    #[inline(always)]
    unsafe fn reach(&self, go: S::M, byte: S::I) -> (S::M, S::I) {
        // SAFETY: called only from the walk, which runs with the features.
        unsafe {
            let tagged = S::and_m(go, S::eq_i(byte, S::splat_i(TAGGED as i64)));
            // Bytes and levels are below 256: the signed compare is the
            // unsigned one.
            let small = S::gt_i(self.leaf_level, byte);
            (
                tagged,
                S::sel_i(S::or_m(tagged, small), S::splat_i(0), byte),
            )
        }
    }

    #[inline(always)]
    unsafe fn exit(&self, l: &Lanes<S>, level: S::I) -> (S::F, [S::I; 3]) {
        // SAFETY: as above.
        unsafe { exit_block(l, level) }
    }
}

/// The distance field's cubes ([`super::DistanceCubes`]): per lane the
/// map of its direction's octant (or the one centred map), the cube's edge
/// per cell, 0 for a tagged cell.
struct Cubes<'a, S: LaneIsa> {
    bytes: &'a [u8],
    /// Per axis, from an octant's map to that of the octant with the axis
    /// reversed: the maps' length times 1, 2, 4 (0 for the centred map).
    octant_step: [S::I; 3],
    centred: bool,
    /// Last cell index per axis.
    last: [S::I; 3],
}

impl<S: LaneIsa> LaneReach<S> for Cubes<'_, S> {
    /// The byte at the slot in the lane's octant map
    /// ([`crate::octree::distance::octant`]: bit `a` when the direction
    /// points down axis `a`).
    #[inline(always)]
    unsafe fn byte(&self, l: &Lanes<S>, slot: S::I, go: S::M) -> (S::I, Option<S::I>) {
        // SAFETY: as above; the lanes of `go` hold cells of the lattice,
        // whose slots lie in each octant's map (`distance_layout_fits`).
        unsafe {
            let mut index = slot;
            for a in 0..3 {
                let down = S::cmp::<_CMP_LT_OQ>(l.du[a], S::splat(0.0));
                index = S::add_i(index, S::sel_i(down, self.octant_step[a], S::splat_i(0)));
            }
            (gather_bytes::<S>(self.bytes, index, go), None)
        }
    }

    /// The reach is the cube's edge less one (0 for the cell alone).
    #[inline(always)]
    unsafe fn reach(&self, go: S::M, byte: S::I) -> (S::M, S::I) {
        // SAFETY: as above.
        unsafe {
            let zero = S::splat_i(0);
            let tagged = S::and_m(go, S::eq_i(byte, zero));
            (tagged, S::max_i(S::sub_i(byte, S::splat_i(1)), zero))
        }
    }

    /// [`super::DistanceCubes`]'s box: `k` cells ahead along each axis (and
    /// behind too for centred cubes), clipped to the lattice.
    #[inline(always)]
    unsafe fn exit(&self, l: &Lanes<S>, k: S::I) -> (S::F, [S::I; 3]) {
        // SAFETY: as above.
        unsafe {
            let zero = S::splat_i(0);
            let mut lo = l.cell;
            let mut hi = l.cell;
            for a in 0..3 {
                let (down, up) = if self.centred {
                    (k, k)
                } else {
                    let neg = S::cmp::<_CMP_LT_OQ>(l.du[a], S::splat(0.0));
                    (S::sel_i(neg, k, zero), S::sel_i(neg, zero, k))
                };
                lo[a] = S::max_i(S::sub_i(l.cell[a], down), zero);
                hi[a] = S::min_i(S::add_i(l.cell[a], up), self.last[a]);
            }
            exit_box(l, lo, hi)
        }
    }
}

/// [`Bricked::index`] per lane, with `bricks` its bricks along x and y.
#[inline(always)]
unsafe fn bricked_index<S: LaneIsa>(bricks: &[S::I; 2], cell: &[S::I; 3]) -> S::I {
    // SAFETY: called only from functions with the set's features.
    unsafe {
        let [x, y, z] = *cell;
        let (two, three) = (S::splat_i(2), S::splat_i(3));
        // The factors are below 2³² (`small_factors`, which the layout
        // checks hold): the small multiplies are exact.
        let brick = S::add_i(
            S::shr(x, two),
            S::mul_small(
                bricks[0],
                S::add_i(S::shr(y, two), S::mul_small(bricks[1], S::shr(z, two))),
            ),
        );
        let within = S::or_i(
            S::and_i(x, three),
            S::or_i(
                S::shl(S::and_i(y, three), two),
                S::shl(S::and_i(z, three), S::splat_i(4)),
            ),
        );
        S::or_i(S::shl(brick, S::splat_i(6)), within)
    }
}

/// [`crate::classify::tagged::TaggedIndex::slot`] per lane of `go`, from
/// the index's words and ranks and each lane's bricked index `at`: the
/// lanes whose cell is tagged, and their slots. `gathered`: the lanes'
/// words of `words`, where the caller has them already.
///
/// # Safety
/// The set's features; every lane of `go` indexes a cell of the index's
/// lattice.
#[inline(always)]
unsafe fn tagged_slot<S: LaneIsa>(
    (words, rank): (&[u64], &[u32]),
    at: S::I,
    go: S::M,
    gathered: Option<S::I>,
) -> (S::M, S::I) {
    // SAFETY: as the caller guarantees; a lattice cell's brick has a word
    // and a rank.
    unsafe {
        let one = S::splat_i(1);
        let brick = S::shr(at, S::splat_i(6));
        let bit = S::and_i(at, S::splat_i(63));
        let word =
            gathered.unwrap_or_else(|| S::gather_i64(words.as_ptr() as *const i64, brick, go));
        let has = S::and_m(go, S::test(S::shr(word, bit), one));
        let before = S::gather_u32(rank.as_ptr(), brick, go);
        let below = S::and_i(word, S::sub_i(S::shl(one, bit), one));
        (has, S::add_i(before, S::popcnt(below)))
    }
}

/// The sub-cell bits whose index along the axis of stride `s = 2^log` (1,
/// 4, 16 in the 4³ layout) lies in `lo..=hi`: `rep·(2^(s(hi+1)) − 2^(s·lo))`, with
/// `rep` one bit per row along that axis — what the scalar walk looks up
/// in [`super::cell::AXIS_SPAN`] (tested equal). Shifts by 64 give 0, so the top
/// row needs no special case.
#[inline(always)]
pub(super) unsafe fn axis_span<S: LaneIsa>(rep: u64, log: u64, lo: S::I, hi: S::I) -> S::I {
    // SAFETY: called only from functions with the set's features.
    unsafe {
        let rep = S::splat_i(rep as i64);
        let log = S::splat_i(log as i64);
        let top = S::shl(S::add_i(hi, S::splat_i(1)), log);
        let bottom = S::shl(lo, log);
        S::sub_i(S::shl(rep, top), S::shl(rep, bottom))
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
unsafe fn may_meet<S: LaneIsa>(l: &Lanes<S>, t0: S::F, t1: S::F, mask: S::I) -> S::M {
    // SAFETY: called only from the walk, which runs with the features.
    unsafe {
        let n = S::splat(SUB as f64);
        let zero = S::splat(0.0);
        let last = S::splat(SUB as f64 - 1.0);
        let eps = S::splat(1e-9);
        let all = S::splat_i(-1);
        let mut bbox = all;
        for a in 0..3 {
            let cf = S::to_f(l.cell[a]);
            let (v0, v1) = (
                S::mul(n, S::sub(S::add(l.ou[a], S::mul(t0, l.du[a])), cf)),
                S::mul(n, S::sub(S::add(l.ou[a], S::mul(t1, l.du[a])), cf)),
            );
            let (lo, hi) = (S::min(v0, v1), S::max(v0, v1));
            let lo = S::clamped_floor(S::sub(lo, eps), zero, last);
            let hi = S::clamped_floor(S::add(hi, eps), zero, last);
            let (rep, log) = SPAN_ROWS[a];
            let span = axis_span::<S>(rep, log, lo, hi);
            let d = S::sub(v0, v1);
            let nan = S::cmp::<_CMP_UNORD_Q>(d, d);
            bbox = S::and_i(bbox, S::sel_i(nan, all, span));
        }
        S::test(mask, bbox)
    }
}

/// [`super::cell_span`] per lane, clipped to the piece as
/// [`super::tagged_segment`] does.
#[inline(always)]
unsafe fn tagged_segment<S: LaneIsa>(l: &Lanes<S>) -> (S::F, S::F) {
    // SAFETY: called only from the walk, which runs with the features.
    unsafe {
        let mut c0 = S::splat(f64::NEG_INFINITY);
        let mut c1 = S::splat(f64::INFINITY);
        let one = S::splat_i(1);
        for a in 0..3 {
            let moves = S::cmp::<_CMP_NEQ_UQ>(l.du[a], S::splat(0.0));
            let ta = S::mul(S::sub(S::to_f(l.cell[a]), l.ou[a]), l.inv[a]);
            let tb = S::mul(S::sub(S::to_f(S::add_i(l.cell[a], one)), l.ou[a]), l.inv[a]);
            c0 = S::sel(moves, S::max(c0, S::min(ta, tb)), c0);
            c1 = S::sel(moves, S::min(c1, S::max(ta, tb)), c1);
        }
        let t0 = S::max(c0, l.t_start);
        let t1 = S::max(S::min(c1, l.t_end), t0);
        (t0, t1)
    }
}

/// [`super::exit_block`] per lane, with per-lane levels (0: the cell). The
/// lanes that use the result hold lattice cells, which are not negative,
/// so the logical shift right is the arithmetic one.
#[inline(always)]
unsafe fn exit_block<S: LaneIsa>(l: &Lanes<S>, level: S::I) -> (S::F, [S::I; 3]) {
    // SAFETY: called only from the walk, which runs with the features.
    unsafe {
        let one = S::splat_i(1);
        let size = S::shl(one, level);
        let mut lo = l.cell;
        let mut hi = l.cell;
        for a in 0..3 {
            lo[a] = S::shl(S::shr(l.cell[a], level), level);
            hi[a] = S::sub_i(S::add_i(lo[a], size), one);
        }
        exit_box(l, lo, hi)
    }
}

/// [`super::exit_box`] per lane: where each lane leaves its box `lo ..= hi`
/// (which holds its cell), not before its `t`, and the cell it enters.
#[inline(always)]
pub(crate) unsafe fn exit_box<S: LaneIsa>(
    l: &Lanes<S>,
    lo: [S::I; 3],
    hi: [S::I; 3],
) -> (S::F, [S::I; 3]) {
    // SAFETY: called only from functions with the set's features.
    unsafe {
        let zero = S::splat(0.0);
        let one = S::splat_i(1);
        let mut te = [zero; 3];
        let mut pos = [S::mask(0); 3];
        let mut neg = [S::mask(0); 3];
        for a in 0..3 {
            pos[a] = S::cmp::<_CMP_GT_OQ>(l.du[a], zero);
            neg[a] = S::cmp::<_CMP_LT_OQ>(l.du[a], zero);
            let wall = S::sel_i(pos[a], S::add_i(hi[a], one), lo[a]);
            let tw = S::mul(S::sub(S::to_f(wall), l.ou[a]), l.inv[a]);
            te[a] = S::sel(S::or_m(pos[a], neg[a]), tw, S::splat(f64::INFINITY));
        }
        // The scalar walk's axis choice: x unless y is strictly sooner (or x
        // is NaN), then that unless z is.
        let first01 = S::cmp::<_CMP_LE_OQ>(te[0], te[1]);
        let t01 = S::sel(first01, te[0], te[1]);
        let before2 = S::cmp::<_CMP_LE_OQ>(t01, te[2]);
        let t_exit = S::sel(before2, t01, te[2]);
        let axis = [
            S::and_m(first01, before2),
            S::and_not_m(before2, first01),
            S::and_not_m(S::mask(S::FULL), before2),
        ];
        let t_new = S::max(t_exit, l.t);
        let mut next = l.cell;
        for a in 0..3 {
            let at = S::add(l.ou[a], S::mul(t_new, l.du[a]));
            // Up: floor clamped to [cell, hi]; down: to [lo, cell]; along an
            // axis the ray does not move, [cell, cell] (the clamp gives the
            // cell, as the scalar walk's choice does).
            let floor_lo = S::sel_i(neg[a], lo[a], l.cell[a]);
            let floor_hi = S::sel_i(pos[a], hi[a], l.cell[a]);
            let inside = S::clamped_floor(at, S::to_f(floor_lo), S::to_f(floor_hi));
            let past = S::sel_i(
                pos[a],
                S::add_i(hi[a], one),
                S::sel_i(neg[a], S::sub_i(lo[a], one), l.cell[a]),
            );
            next[a] = S::sel_i(axis[a], past, inside);
        }
        (t_new, next)
    }
}

/// Lanes that end their walk this step (bit sets), and the segments of
/// those that go to the solve.
struct Ended<S: LaneIsa> {
    solve: u32,
    escaped: u32,
    t0: S::F,
    t1: S::F,
}

/// One step of every `live` lane ([`super::Walk::step`]): lanes that leave
/// their piece or the lattice escape, lanes at a candidate cell end with
/// its segment, the others move past their cell or empty block.
#[inline(always)]
unsafe fn step<S: LaneIsa, R: LaneReach<S>>(
    s: &Space<S, R>,
    l: &mut Lanes<S>,
    live: u32,
    c: &mut Counters,
) -> Ended<S> {
    // SAFETY: called only from the walk, which runs with the features;
    // memory accesses are marked below.
    unsafe {
        let mut inside = S::cmp::<_CMP_NGE_UQ>(l.t, l.t_end);
        for a in 0..3 {
            inside = S::and_m(inside, S::in_range(l.cell[a], s.n[a]));
        }
        let go = S::and_m(S::mask(live), inside);
        let go_bits = S::bits(go);
        let escaped = live & !go_bits;
        c.cells_visited += go_bits.count_ones() as u64;

        let slot = bricked_index::<S>(&s.bricks, &l.cell);
        // SAFETY: the lanes of `go` hold cells of the lattice.
        let (byte, word) = s.reach.byte(l, slot, go);
        let (tagged, reach) = s.reach.reach(go, byte);

        // Steps with no lane at a tagged cell skip the segments and the
        // sub-cell test: 59% of the steps on the sphere, 48% on the teapot,
        // 50% on the cranium (neighbouring rays reach the surface together).
        let no = S::mask(0);
        let (solve, skipped, t0, t1) = if S::bits(tagged) == 0 {
            (no, no, S::splat(0.0), S::splat(0.0))
        } else {
            let (t0, t1) = tagged_segment(l);
            let (solve, skipped) = match s.masks {
                None => (tagged, no),
                Some((words, rank, masks)) => {
                    // The index's words are gathered for every lane in the
                    // lattice, not just the tagged ones (a cell with its bit
                    // set is a tagged cell): under the predicted branch the
                    // gather starts alongside the skip bytes', and the
                    // mask's gather waits for one gather, not two.
                    // SAFETY (here and the mask's gather): the lanes of `go`
                    // hold lattice cells; a tagged cell's slot is below the
                    // tag count, the masks' length.
                    let (has, index) = tagged_slot::<S>((words, rank), slot, go, word);
                    // With planes, each cell's mask and plane are one
                    // record ([`CellTests`]): the plane's gathers read the
                    // line the mask's brought in.
                    let meet = match s.planes {
                        None => {
                            let mask = S::gather_i64(masks.as_ptr() as *const i64, index, has);
                            S::and_m(has, may_meet(l, t0, t1, mask))
                        }
                        Some(planes) => {
                            let record = S::shl(index, S::splat_i(2));
                            let mask = S::gather_i64(planes.0.as_ptr() as *const i64, record, has);
                            let meet = S::and_m(has, may_meet(l, t0, t1, mask));
                            if S::bits(meet) == 0 {
                                meet
                            } else {
                                let clear = S::plane_clears(planes, l, (t0, t1), record, meet);
                                S::and_not_m(meet, clear)
                            }
                        }
                    };
                    let has = S::and_m(has, tagged);
                    (
                        S::or_m(S::and_not_m(tagged, has), S::and_m(tagged, meet)),
                        S::and_not_m(has, meet),
                    )
                }
            };
            (solve, skipped, t0, t1)
        };
        c.subcell_skips += S::bits(skipped).count_ones() as u64;

        let moves = S::and_not_m(go, solve);
        let (t_new, next) = s.reach.exit(l, reach);
        l.t = S::sel(moves, t_new, l.t);
        for a in 0..3 {
            l.cell[a] = S::sel_i(moves, next[a], l.cell[a]);
        }
        Ended {
            solve: S::bits(solve),
            escaped,
            t0,
            t1,
        }
    }
}

/// Fills the lanes of `free` from the staged chunk at `*pos`, as many as
/// it has left (the lowest free lanes first); returns the lanes filled.
#[inline(always)]
unsafe fn refill<S: LaneIsa>(l: &mut Lanes<S>, free: u32, staged: &Staged, pos: &mut usize) -> u32 {
    const { assert!(S::LANES <= MAX_LANES) };
    // SAFETY: called only from the walk, which runs with the features
    // (BMI2 among them); memory accesses are marked below.
    unsafe {
        let left = staged.len - *pos;
        let take = if free.count_ones() as usize <= left {
            free
        } else {
            _pdep_u32((1u32 << left) - 1, free)
        };
        let p = *pos;
        let e = S::expander(take);
        // SAFETY (all loads): `p < staged.len ≤ CHUNK`, and every column holds
        // `CHUNK + MAX_LANES` values.
        l.r = S::expand_i(l.r, e, staged.r.as_ptr().add(p));
        for a in 0..3 {
            l.ou[a] = S::expand(l.ou[a], e, staged.ou[a].as_ptr().add(p));
            l.du[a] = S::expand(l.du[a], e, staged.du[a].as_ptr().add(p));
            l.inv[a] = S::expand(l.inv[a], e, staged.inv[a].as_ptr().add(p));
            l.cell[a] = S::expand_i(l.cell[a], e, staged.cell[a].as_ptr().add(p));
        }
        l.t = S::expand(l.t, e, staged.t.as_ptr().add(p));
        l.t_start = S::expand(l.t_start, e, staged.t_start.as_ptr().add(p));
        l.t_end = S::expand(l.t_end, e, staged.t_end.as_ptr().add(p));
        *pos += take.count_ones() as usize;
        take
    }
}

/// Lane groups in flight, stepped in turn so one group's arithmetic fills
/// the other's wait on its gathers. With AVX-512 a group holds 16 vectors
/// and two take the 32 registers; three and four groups measured slower on
/// the lobster, and four no faster with AVX2 (two groups' 32 vectors
/// already exceed its 16 registers; BENCHMARKS.md).
const GROUPS: usize = 2;

/// The walk of every ray of `input` to its next candidate cell (pushed on
/// `solve`, its segment in `t`/`seg_end` and its cell set) or out of its
/// piece (pushed on `record`), as [`super::walk_interleaved`] does: the
/// body of [`LaneIsa::walk`].
///
/// # Safety
/// As [`LaneIsa::walk`]; inlined only into it.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn walk_lanes<S: LaneIsa, T: Coefficient, R: LaneReach<S>>(
    ctx: &Ctx<T>,
    space: &Space<S, R>,
    staged: &mut Staged,
    rays: &mut Rays,
    input: &[u32],
    solve: &mut Queue,
    record: &mut Queue,
    c: &mut Counters,
) {
    // SAFETY (the whole body): the caller has the features; the space fits.
    unsafe {
        staged.len = 0;
        let mut chunks = input.chunks(CHUNK);
        let mut pos = 0;
        let (zd, zi) = (S::splat(0.0), S::splat_i(0));
        let idle = Lanes::<S> {
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
                while live[g] != S::FULL && !drained {
                    if pos == staged.len {
                        match chunks.next() {
                            Some(chunk) => {
                                S::stage(staged, ctx, rays, chunk);
                                pos = 0;
                            }
                            None => {
                                drained = true;
                                break;
                            }
                        }
                    }
                    live[g] |= refill(&mut group[g], S::FULL & !live[g], staged, &mut pos);
                }
            }
            if live.iter().all(|&m| m == 0) {
                return;
            }
            let mut ended: [Option<Ended<S>>; GROUPS] = std::array::from_fn(|_| None);
            for g in 0..GROUPS {
                if live[g] != 0 {
                    ended[g] = Some(step(space, &mut group[g], live[g], c));
                }
            }
            for g in 0..GROUPS {
                if let Some(e) = &ended[g] {
                    let done = e.solve | e.escaped;
                    if done != 0 {
                        finish(&group[g], e, rays, solve, record);
                        live[g] &= !done;
                    }
                }
            }
        }
    }
}

/// Hands the lanes that ended to their queues.
#[inline(always)]
unsafe fn finish<S: LaneIsa>(
    l: &Lanes<S>,
    e: &Ended<S>,
    rays: &mut Rays,
    solve: &mut Queue,
    record: &mut Queue,
) {
    let mut out = super::EndedLanes::<MAX_LANES>::default();
    // SAFETY: called only from the walk, which runs with the features.
    unsafe {
        S::store_i(l.r, &mut out.r);
        S::store(e.t0, &mut out.t0);
        S::store(e.t1, &mut out.t1);
        for a in 0..3 {
            S::store_i(l.cell[a], &mut out.cell[a]);
        }
    }
    out.hand_over(e.solve, e.escaped, rays, solve, record);
}

/// The walk of every ray of `input` to its next candidate cell or out of
/// its piece over the octree (or DDA) `tree`, as
/// [`super::walk_interleaved`] over it does, in the lanes of the best set
/// this CPU runs ([`super::wide`], else [`super::avx2`]) when the layout
/// fits; false, with nothing walked, when no lane walk can run.
pub(super) fn walk_octree<T: Coefficient>(
    ctx: &Ctx<T>,
    tree: (&Octree, u32),
    rays: &mut Rays,
    input: &[u32],
    solve: &mut Queue,
    record: &mut Queue,
    c: &mut Counters,
) -> bool {
    let brick_levels = reads_brick_levels(tree.0);
    if super::wide::fits(ctx, tree.0) {
        // SAFETY: `fits` checked the CPU's features and the layout.
        unsafe { Avx512::octree(ctx, tree, brick_levels, rays, input, solve, record, c) };
    } else if super::avx2::fits(ctx, tree.0) {
        // SAFETY: as above.
        unsafe { Avx2::octree(ctx, tree, brick_levels, rays, input, solve, record, c) };
    } else {
        return false;
    }
    true
}

/// [`walk_octree`] over the distance cubes of `p`.
pub(super) fn walk_distance<T: Coefficient>(
    ctx: &Ctx<T>,
    p: &Proximity,
    rays: &mut Rays,
    input: &[u32],
    solve: &mut Queue,
    record: &mut Queue,
    c: &mut Counters,
) -> bool {
    if super::wide::fits_distance(ctx, p) {
        // SAFETY: `fits_distance` checked the CPU's features and the maps.
        unsafe { Avx512::distance(ctx, p, rays, input, solve, record, c) };
    } else if super::avx2::fits_distance(ctx, p) {
        // SAFETY: as above.
        unsafe { Avx2::distance(ctx, p, rays, input, solve, record, c) };
    } else {
        return false;
    }
    true
}

/// The body of [`LaneIsa::octree`]: the octree's blocks read from the
/// brick levels (`brick_levels`, when the tagged-cell test reads the same
/// tag words) or the byte map.
///
/// # Safety
/// As [`LaneIsa::octree`]; inlined only into it.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn octree_body<S: LaneIsa, T: Coefficient>(
    ctx: &Ctx<T>,
    (tree, leaf_level): (&Octree, u32),
    brick_levels: bool,
    rays: &mut Rays,
    input: &[u32],
    solve: &mut Queue,
    record: &mut Queue,
    c: &mut Counters,
) {
    // SAFETY (the whole body): the caller's contract.
    unsafe {
        let space = Space::<S, ()>::of(ctx, tree.bricked());
        let leaf_level = S::splat_i(leaf_level as i64);
        let map = BrickLevels::of(tree);
        // The tagged-cell test takes the words the skip bytes were read
        // with: they must be the index's own (they are, in every
        // preparation; the byte map serves any other).
        let shared = space
            .masks
            .is_none_or(|(w, _, _)| std::ptr::eq(w.as_ptr(), map.words.as_ptr()));
        STAGED.with_borrow_mut(|staged| {
            if brick_levels && shared {
                let space = space.with_reach(Blocks::<S, _> { map, leaf_level });
                S::walk(ctx, &space, staged, rays, input, solve, record, c)
            } else {
                let map = ByteMap(tree.skip_map());
                let space = space.with_reach(Blocks::<S, _> { map, leaf_level });
                S::walk(ctx, &space, staged, rays, input, solve, record, c)
            }
        });
    }
}

/// The body of [`LaneIsa::distance`].
///
/// # Safety
/// As [`LaneIsa::distance`]; inlined only into it.
#[inline(always)]
pub(super) unsafe fn distance_body<S: LaneIsa, T: Coefficient>(
    ctx: &Ctx<T>,
    p: &Proximity,
    rays: &mut Rays,
    input: &[u32],
    solve: &mut Queue,
    record: &mut Queue,
    c: &mut Counters,
) {
    let (bytes, stride, centred, bricked) = p.lane_maps();
    // SAFETY (the whole body): the caller's contract.
    unsafe {
        let space = Space::<S, ()>::of(ctx, bricked).with_reach(Cubes::<S> {
            bytes,
            octant_step: [1, 2, 4].map(|m| S::splat_i((m * stride) as i64)),
            centred,
            last: ctx.lattice.cells.map(|n| S::splat_i(n as i64 - 1)),
        });
        STAGED
            .with_borrow_mut(|staged| S::walk(ctx, &space, staged, rays, input, solve, record, c));
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

/// Whether [`bricked_index`]'s factors stay below 2³², as
/// [`LaneIsa::mul_small`] needs: the bricks along x, and a brick's index
/// within its x row, below the bricks along y times those along z (true of
/// any lattice that fits in memory: 2³² bricks are 2³⁸ cells).
fn small_factors(bricked: Bricked) -> bool {
    let [bx, by, bz] = bricked.bricks();
    bx < 1 << 32 && by.saturating_mul(bz) <= 1 << 32
}

/// Whether a lane walk can run over `tree` in `ctx`, whatever the CPU: the
/// octree's skip map, brick levels and tag words and the masks' index
/// cover the lattice in one brick layout.
pub(super) fn layout_fits<T: Coefficient>(ctx: &Ctx<T>, tree: &Octree) -> bool {
    tree.tags().cells == ctx.lattice.cells
        && tree.skip_map().len() == tree.bricked().len()
        && tree.brick_levels().len() * 64 >= tree.bricked().len()
        && tree.brick_levels().len().is_multiple_of(4)
        && tree.brick_tag_words().len() * 64 == tree.bricked().len()
        && masks_fit(ctx, tree.bricked())
        && small_factors(tree.bricked())
}

/// [`layout_fits`] for the distance cubes of `p`: the maps (eight
/// octants' or one centred) and the masks' index cover the lattice in one
/// brick layout.
pub(super) fn distance_layout_fits<T: Coefficient>(ctx: &Ctx<T>, p: &Proximity) -> bool {
    let (bytes, stride, centred, bricked) = p.lane_maps();
    let maps = if centred { 1 } else { 8 };
    p.cells() == ctx.lattice.cells
        && bricked == Bricked::new(ctx.lattice.cells)
        && stride == if centred { 0 } else { bricked.len() }
        && bytes.len() == maps * bricked.len()
        && masks_fit(ctx, bricked)
        && small_factors(bricked)
}

/// The tagged cells' records (mask and plane) and the planes' margin, as
/// the walk gathers them: with masks only (the walk looks planes up where
/// a mask passes), kept in the masks' index and built from their masks.
fn lane_planes<'a, T: Coefficient>(ctx: &Ctx<'a, T>) -> Option<(&'a [CellTests], f64)> {
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
fn lane_masks<'a, T: Coefficient>(ctx: &Ctx<'a, T>) -> Option<(&'a [u64], &'a [u32], &'a [u64])> {
    ctx.masks.map(|m| {
        let (index, masks) = m.parts();
        let (words, rank) = index.words();
        (words, rank, masks)
    })
}
