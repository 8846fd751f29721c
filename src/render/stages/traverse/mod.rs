//! Stage 3: advance each ray to the next place a crossing can be.
//!
//! - `step`: march at a fixed step (the paper's ray-casting baseline) until the
//!   field changes side between two samples;
//! - `dda`, `octree`: walk the knot-cell lattice (Amanatides–Woo), skipping every
//!   cell (or aligned block of cells) that provably holds no crossing, and stop
//!   at the first candidate cell. Skipping a block is one step: the ray jumps to
//!   where it leaves the block, so the DDA is the octree with a single level;
//! - `distance`: the same walk over the distance field's empty cubes
//!   ([`crate::octree::distance`]), which reach further than aligned blocks.
//!
//! With AVX-512 every cell walk runs eight rays at a time ([`wide`]), with
//! AVX2 four ([`avx2`]), both the one lane walk ([`lanes`]); the scalar
//! walks below are the reference both are tested against, and the path on
//! other CPUs. All of them step through
//! the lattice with [`cell`]'s geometry: a ray's exit from a cell, a box or
//! a block, and its segment's test against a cell's tagged sub-cells.

#[cfg(target_arch = "x86_64")]
pub mod avx2;
mod cell;
#[cfg(all(test, target_arch = "x86_64"))]
mod lane_check;
#[cfg(target_arch = "x86_64")]
pub(crate) mod lanes;
#[cfg(target_arch = "x86_64")]
pub mod wide;

use super::super::context::{Ctx, Skip};
use super::super::packet::{Fate, Queue, Rays};
use super::field_minus_iso;
use crate::classify::CellBound;
use crate::classify::bezier::SUB;
use crate::filter::coeffs::Coefficient;
use crate::octree::TAGGED;
use crate::octree::distance::{Proximity, ReachMap, octant};
use crate::render::stats::Counters;
use crate::roots::inside;
use crate::scene::Traversal;

pub use cell::{
    CellRay, Dda, cell_span, clamped_floor, exit_block, exit_box, exit_cell,
    may_meet_tagged_sub_cell,
};
pub(crate) use cell::{cell_ray, in_range};
use cell::{fmax, fmin};

pub fn traverse<const S: usize, T: Coefficient>(
    ctx: &Ctx<T>,
    rays: &mut Rays,
    input: &[u32],
    solve: &mut Queue,
    record: &mut Queue,
    c: &mut Counters,
) {
    match ctx.traversal() {
        Traversal::Step => {
            for &r in input {
                march::<S, _>(ctx, rays, r, solve, record, c);
            }
        }
        Traversal::Dda | Traversal::Octree | Traversal::Distance => match &ctx.skip {
            Skip::Octree { tree, leaf_level } => {
                #[cfg(target_arch = "x86_64")]
                if lanes::walk_octree(ctx, (tree, *leaf_level), rays, input, solve, record, c) {
                    return;
                }
                let octree = OctreeBlocks {
                    tree,
                    leaf_level: *leaf_level,
                };
                crate::with_isa!(crate::simd::Isa::current(), _L, _M => walk_interleaved(ctx, octree, rays, input, solve, record, c));
            }
            Skip::Distance(p) => {
                #[cfg(target_arch = "x86_64")]
                if lanes::walk_distance(ctx, p, rays, input, solve, record, c) {
                    return;
                }
                crate::with_isa!(crate::simd::Isa::current(), _L, _M => walk_interleaved(ctx, DistanceCubes::new(p), rays, input, solve, record, c));
            }
            Skip::Bound(b) => {
                for &r in input {
                    walk_bound(ctx, b, rays, r, solve, record, c);
                }
            }
        },
    }
}

/// Cell walk over the bound alone (no classification): the incremental DDA,
/// testing each cell's coefficient bound as it goes. Precomputed tags go
/// through [`walk_interleaved`].
fn walk_bound<T: Coefficient>(
    ctx: &Ctx<T>,
    bound: &CellBound,
    rays: &mut Rays,
    r: u32,
    solve: &mut Queue,
    record: &mut Queue,
    c: &mut Counters,
) {
    let i = r as usize;
    let ray = cell_ray(ctx, rays, i);
    let mut w = Dda::new(&ray, rays.cell_of(i), rays.t[i]);
    let t_end = rays.t_end[i];
    if rays.advance[i] {
        rays.advance[i] = false;
        w.advance();
    }
    loop {
        if w.t >= t_end || !in_range(ctx, w.cell) {
            rays.fate[i] = Fate::Escaped;
            record.push(r);
            return;
        }
        c.cells_visited += 1;
        let cell = w.cell;
        if bound.may_cross(ctx.field, cell, ctx.iso) {
            match tagged_segment(ctx, &ray, cell, rays.t_start[i], t_end) {
                Some((ta, tb)) => {
                    rays.t[i] = ta;
                    rays.seg_end[i] = tb;
                    rays.set_cell(i, cell);
                    solve.push(r);
                    return;
                }
                None => c.subcell_skips += 1,
            }
        }
        w.advance();
    }
}

/// Where ray `i`'s walk starts: its piece in cell coordinates, its cell
/// and parameter, stepped past the cell first when `advance` is set (which
/// is cleared): how the interleaved walk starts a ray (the lane walk
/// stages its rays the same way in lanes).
#[inline(always)]
pub(crate) fn walk_start<T: Coefficient>(
    ctx: &Ctx<T>,
    rays: &mut Rays,
    i: usize,
) -> (CellRay, [i64; 3], f64) {
    let ray = cell_ray(ctx, rays, i);
    let mut cell = rays.cell_of(i);
    let mut t = rays.t[i];
    if rays.advance[i] {
        rays.advance[i] = false;
        (t, cell) = exit_cell(&ray, cell, t);
    }
    (ray, cell, t)
}

/// The segment of the ray's piece inside tagged `cell` to solve (from the
/// ray and the cell alone, so it is the same bits however the walk got
/// here), or `None` when it provably meets none of the cell's tagged
/// sub-cells, or the cell's plane proves it clear of the surface
/// ([`crate::classify::plane`]).
#[inline(always)]
fn tagged_segment<T: Coefficient>(
    ctx: &Ctx<T>,
    ray: &CellRay,
    cell: [i64; 3],
    t_start: f64,
    t_end: f64,
) -> Option<(f64, f64)> {
    let (c0, c1) = cell_span(ray, cell);
    let t0 = fmax(c0, t_start);
    let t1 = fmax(fmin(c1, t_end), t0);
    match ctx.masks.and_then(|m| m.get(cell)) {
        // The mask and the plane only decide whether to solve: the solve
        // itself gets the whole segment, so its polynomial (and every root,
        // tangential touch and tolerance decision) is the same bits with or
        // without them.
        Some(mask) => (may_meet_tagged_sub_cell(ray, cell, t0, t1, mask)
            && !plane_clears(ctx, ray, cell, t0, t1))
        .then_some((t0, t1)),
        None => Some((t0, t1)),
    }
}

/// Whether `cell`'s plane, when the scene has planes, proves the segment
/// `t0..t1` of `ray` in it clear of the surface.
#[inline(always)]
fn plane_clears<T: Coefficient>(
    ctx: &Ctx<T>,
    ray: &CellRay,
    cell: [i64; 3],
    t0: f64,
    t1: f64,
) -> bool {
    let Some(planes) = ctx.planes else {
        return false;
    };
    let Some(slot) = planes.slot(cell) else {
        return false;
    };
    let local = |t: f64| std::array::from_fn(|a| ray.ou[a] + t * ray.du[a] - cell[a] as f64);
    planes.clears(planes.at(slot), local(t0), local(t1))
}

/// Where a walk over precomputed tags may jump from a cell.
///
/// The lookup gives a small `Reach` (a block level, or a cube's extent) and
/// the box is built from it after the tagged-cell branch has merged back:
/// carrying the box's six bounds through that merge instead cost the octree
/// walk 15% (single-thread sphere traverse 122 → 141 ms).
trait EmptySpace: Copy {
    type Reach: Copy;
    /// What one ray's lookups read, chosen when its walk starts (a distance
    /// walk reads its octant's map).
    type Local: Copy;
    /// The reach of the cell alone (a tagged cell whose tagged sub-cells the
    /// ray misses).
    const CELL: Self::Reach;
    /// The ray's [`EmptySpace::Local`].
    fn local(&self, ray: &CellRay) -> Self::Local;
    /// How far the empty space around `cell` (in range) reaches for the ray
    /// of `local`; `None` when `cell` is tagged.
    fn reach(&self, local: &Self::Local, cell: [i64; 3]) -> Option<Self::Reach>;
    /// Where the ray leaves the box of `reach` around `cell` (not before
    /// `t`), and the cell it enters there.
    fn exit(&self, ray: &CellRay, cell: [i64; 3], reach: Self::Reach, t: f64) -> (f64, [i64; 3]);
}

/// The octree's aligned blocks, from its flattened skip map: the largest
/// empty block holding the cell (levels below the leaf level count as single
/// cells).
#[derive(Clone, Copy)]
struct OctreeBlocks<'a> {
    tree: &'a crate::octree::Octree,
    leaf_level: u32,
}

impl EmptySpace for OctreeBlocks<'_> {
    /// The block's level.
    type Reach = u32;
    type Local = ();
    const CELL: u32 = 0;

    #[inline(always)]
    fn local(&self, _: &CellRay) {}

    #[inline(always)]
    fn reach(&self, _: &(), cell: [i64; 3]) -> Option<u32> {
        match self.tree.skip_byte(cell) {
            TAGGED => None,
            b if (b as u32) < self.leaf_level => Some(0),
            b => Some(b as u32),
        }
    }

    #[inline(always)]
    fn exit(&self, ray: &CellRay, cell: [i64; 3], level: u32, t: f64) -> (f64, [i64; 3]) {
        exit_block(ray, cell, level, t)
    }
}

/// The distance field's cubes ([`Proximity`]): the empty cube reaching
/// ahead of the ray (or centred on the cell), clipped to the lattice.
#[derive(Clone, Copy)]
struct DistanceCubes<'a> {
    p: &'a Proximity,
    /// Last cell index per axis.
    last: [i64; 3],
}

impl<'a> DistanceCubes<'a> {
    fn new(p: &'a Proximity) -> DistanceCubes<'a> {
        DistanceCubes {
            p,
            last: p.cells().map(|n| n as i64 - 1),
        }
    }
}

impl<'a> EmptySpace for DistanceCubes<'a> {
    /// Cells the cube reaches behind and ahead of the cell, on every axis.
    type Reach = (i64, i64);
    type Local = ReachMap<'a>;
    const CELL: (i64, i64) = (0, 0);

    #[inline(always)]
    fn local(&self, ray: &CellRay) -> ReachMap<'a> {
        self.p.map_for(octant(ray.du))
    }

    #[inline(always)]
    fn reach(&self, map: &ReachMap<'a>, cell: [i64; 3]) -> Option<(i64, i64)> {
        map.empty_reach(cell)
    }

    #[inline(always)]
    fn exit(
        &self,
        ray: &CellRay,
        cell: [i64; 3],
        (back, ahead): (i64, i64),
        t: f64,
    ) -> (f64, [i64; 3]) {
        let (mut lo, mut hi) = (cell, cell);
        for a in 0..3 {
            let (down, up) = if ray.du[a] < 0.0 {
                (ahead, back)
            } else {
                (back, ahead)
            };
            lo[a] = (cell[a] - down).max(0);
            hi[a] = (cell[a] + up).min(self.last[a]);
        }
        exit_box(ray, cell, lo, hi, t)
    }
}

/// One ray's walk in flight: its piece in cell coordinates, where it is, and
/// the bounds of the piece.
#[derive(Clone, Copy)]
struct Walk<L> {
    r: u32,
    ray: CellRay,
    local: L,
    cell: [i64; 3],
    t: f64,
    t_start: f64,
    t_end: f64,
}

/// What one step of a walk found.
enum Step {
    /// Moved on (past a single cell or an empty box).
    On,
    /// A tagged cell whose segment `[ta, tb]` meets a tagged sub-cell.
    Solve(f64, f64),
    /// Left the piece or the lattice.
    Escaped,
}

impl<L: Copy> Walk<L> {
    #[inline(always)]
    fn start<E: EmptySpace<Local = L>, T: Coefficient>(
        ctx: &Ctx<T>,
        space: &E,
        rays: &mut Rays,
        r: u32,
    ) -> Walk<L> {
        let i = r as usize;
        let (ray, cell, t) = walk_start(ctx, rays, i);
        Walk {
            r,
            ray,
            local: space.local(&ray),
            cell,
            t,
            t_start: rays.t_start[i],
            t_end: rays.t_end[i],
        }
    }

    /// One lookup and one box exit: past a single cell or past the empty box
    /// holding it, unless the cell is tagged and its segment meets a tagged
    /// sub-cell.
    #[inline(always)]
    fn step<E: EmptySpace<Local = L>, T: Coefficient>(
        &mut self,
        ctx: &Ctx<T>,
        space: &E,
        c: &mut Counters,
    ) -> Step {
        if self.t >= self.t_end || !in_range(ctx, self.cell) {
            return Step::Escaped;
        }
        c.cells_visited += 1;
        let reach = match space.reach(&self.local, self.cell) {
            Some(reach) => reach,
            None => match tagged_segment(ctx, &self.ray, self.cell, self.t_start, self.t_end) {
                Some((ta, tb)) => return Step::Solve(ta, tb),
                None => {
                    c.subcell_skips += 1;
                    E::CELL
                }
            },
        };
        (self.t, self.cell) = space.exit(&self.ray, self.cell, reach, self.t);
        Step::On
    }
}

/// Rays walked at once by [`walk_interleaved`]. Two measured best for the
/// octree (single-thread traverse stage against one at a time: sphere 131 ->
/// 124 ms, teapot 358 -> 323 ms); more were slower again (sphere: 4 → 127
/// ms, 16 → 130 ms).
const WALKS: usize = 2;

/// The cell walk over precomputed tags (octree blocks or distance cubes),
/// [`WALKS`] rays at a time.
///
/// A single walk is one long dependency chain (each step's exit point gives
/// the next cell, whose lookup gives the next box), so it runs at the
/// latency of its arithmetic. Interleaving independent rays, a step of each
/// in turn, lets the core overlap the chains; a ray that finishes hands its
/// slot to the next one in the queue. Each ray's steps are those of a walk on
/// its own, so the results are the same bits in any order.
#[inline(always)]
fn walk_interleaved<E: EmptySpace, T: Coefficient>(
    ctx: &Ctx<T>,
    space: E,
    rays: &mut Rays,
    input: &[u32],
    solve: &mut Queue,
    record: &mut Queue,
    c: &mut Counters,
) {
    let mut pending = input.iter();
    let mut walks: [Option<Walk<E::Local>>; WALKS] =
        std::array::from_fn(|_| pending.next().map(|&r| Walk::start(ctx, &space, rays, r)));
    let mut live = walks.iter().filter(|w| w.is_some()).count();
    while live > 0 {
        for slot in walks.iter_mut() {
            let Some(w) = slot else { continue };
            let i = w.r as usize;
            match w.step(ctx, &space, c) {
                Step::On => continue,
                Step::Solve(ta, tb) => {
                    rays.t[i] = ta;
                    rays.seg_end[i] = tb;
                    rays.set_cell(i, w.cell);
                    solve.push(w.r);
                }
                Step::Escaped => {
                    rays.fate[i] = Fate::Escaped;
                    record.push(w.r);
                }
            }
            *slot = pending.next().map(|&r| Walk::start(ctx, &space, rays, r));
            if slot.is_none() {
                live -= 1;
            }
        }
    }
}

/// What a lane walk's ended lanes hold, stored from their vectors: the ray,
/// its candidate segment and its cell.
#[cfg(target_arch = "x86_64")]
struct EndedLanes<const N: usize> {
    r: [i64; N],
    t0: [f64; N],
    t1: [f64; N],
    cell: [[i64; N]; 3],
}

#[cfg(target_arch = "x86_64")]
impl<const N: usize> Default for EndedLanes<N> {
    fn default() -> Self {
        EndedLanes {
            r: [0; N],
            t0: [0.0; N],
            t1: [0.0; N],
            cell: [[0; N]; 3],
        }
    }
}

#[cfg(target_arch = "x86_64")]
impl<const N: usize> EndedLanes<N> {
    /// The lanes of bit set `to_solve` go to the solve with their segment
    /// and cell (as [`walk_interleaved`] hands a ray over), those of
    /// `escaped` to the record stage.
    #[inline(always)]
    fn hand_over(
        &self,
        to_solve: u32,
        escaped: u32,
        rays: &mut Rays,
        solve: &mut Queue,
        record: &mut Queue,
    ) {
        let mut m = to_solve;
        while m != 0 {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            let i = self.r[k] as usize;
            rays.t[i] = self.t0[k];
            rays.seg_end[i] = self.t1[k];
            rays.set_cell(i, [self.cell[0][k], self.cell[1][k], self.cell[2][k]]);
            solve.push(self.r[k] as u32);
        }
        let mut m = escaped;
        while m != 0 {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            let i = self.r[k] as usize;
            rays.fate[i] = Fate::Escaped;
            record.push(self.r[k] as u32);
        }
    }
}

/// Fixed-step march for `step`: samples at `t0 + k·h` until the side changes.
fn march<const S: usize, T: Coefficient>(
    ctx: &Ctx<T>,
    rays: &mut Rays,
    r: u32,
    solve: &mut Queue,
    record: &mut Queue,
    c: &mut Counters,
) {
    let i = r as usize;
    let o = rays.origin(i);
    let d = rays.direction(i);
    let dg_len = ctx.to_grid(d).length();
    let h = ctx.settings.step / dg_len;
    let t_end = rays.t_end[i];
    let mut t = rays.t[i];
    let mut g = rays.seg_g[0][i];
    loop {
        if t >= t_end {
            rays.fate[i] = Fate::Escaped;
            record.push(r);
            return;
        }
        let t_next = (t + h).min(t_end);
        c.cells_visited += 1;
        let g_next = field_minus_iso::<S, _>(ctx, ctx.to_grid(o + t_next * d), c);
        if inside(g) != inside(g_next) {
            rays.t[i] = t;
            rays.seg_end[i] = t_next;
            rays.seg_g[0][i] = g;
            rays.seg_g[1][i] = g_next;
            solve.push(r);
            return;
        }
        t = t_next;
        g = g_next;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The tagged cells a ray meets, in order: single-cell steps, or jumps
    /// over the boxes `space` gives.
    fn tagged_met<E: EmptySpace>(
        space: Option<&E>,
        tagged: &dyn Fn([i64; 3]) -> bool,
        n: [i64; 3],
        ray: &CellRay,
    ) -> (Vec<[i64; 3]>, usize) {
        let mut cell = ray.ou.map(|x| x.floor() as i64);
        let mut t = 0.0;
        let mut met = Vec::new();
        let mut visits = 0;
        let local = space.map(|s| s.local(ray));
        while (0..3).all(|a| (0..n[a]).contains(&cell[a])) {
            visits += 1;
            (t, cell) = match space.and_then(|s| Some((s, s.reach(local.as_ref()?, cell)?))) {
                Some((s, reach)) => s.exit(ray, cell, reach, t),
                None => {
                    if tagged(cell) {
                        met.push(cell);
                    }
                    exit_box(ray, cell, cell, cell, t)
                }
            };
        }
        (met, visits)
    }

    #[test]
    fn distance_jumps_never_pass_a_tagged_cell() {
        use crate::classify::Tags;
        let cells = [14usize, 12, 13];
        let n = cells.map(|v| v as i64);
        let count = cells.iter().product::<usize>();
        let flags: Vec<u8> = (0..count)
            .map(|i| ((i * 2654435761usize) % 1000 < 15) as u8)
            .collect();
        let tags = Tags::from_chunks(cells, vec![flags.clone()]);
        let tagged = |c: [i64; 3]| {
            flags[c[0] as usize + cells[0] * (c[1] as usize + cells[1] * c[2] as usize)] == 1
        };
        let mut draws = 0u64;
        let mut next = || {
            draws += 1;
            crate::phantom::uniform(99, draws)
        };
        for budget in [usize::MAX, 0] {
            let p = Proximity::build_within(&tags, budget);
            assert_eq!(p.is_octant(), budget > 0);
            let cubes = DistanceCubes::new(&p);
            let (mut met, mut stepped, mut jumped_visits) = (0, 0, 0);
            for k in 0..3000 {
                let ou: [f64; 3] = std::array::from_fn(|a| next() * cells[a] as f64);
                // Some rays along axes and diagonals, most in general position.
                let du: [f64; 3] = match k % 10 {
                    0 => [1.0, 0.0, 0.0],
                    1 => [0.0, -1.0, 1.0],
                    2 => [-1.0, -1.0, -1.0],
                    _ => std::array::from_fn(|_| next() * 2.0 - 1.0),
                };
                let ray = CellRay::new(ou, du);
                let (plain, all) = tagged_met::<DistanceCubes>(None, &tagged, n, &ray);
                let (jumped, some) = tagged_met(Some(&cubes), &tagged, n, &ray);
                assert_eq!(plain, jumped, "budget {budget} origin {ou:?} dir {du:?}");
                met += plain.len();
                stepped += all;
                jumped_visits += some;
            }
            // The test means something: rays meet tagged cells, and jumps
            // skip most of the others.
            assert!(
                met > 300 && 2 * jumped_visits < stepped,
                "{met} {jumped_visits} {stepped}"
            );
        }
    }
}
