//! Stage 3: advance each ray to the next place a crossing can be.
//!
//! - `step`: march at a fixed step (the paper's ray-casting baseline) until the
//!   field changes side between two samples;
//! - `dda`, `octree`: walk the knot-cell lattice (Amanatides–Woo), skipping every
//!   cell (or aligned block of cells) that provably holds no crossing, and stop
//!   at the first candidate cell. Skipping a block is one step: the ray jumps to
//!   where it leaves the block, so the DDA is the octree with a single level.

use super::super::context::{Ctx, Skip};
use super::super::packet::{Fate, Queue, Rays};
use super::field_minus_iso;
use crate::filter::kernel::floor_i64;
use crate::render::stats::Counters;
use crate::roots::inside;
use crate::scene::Traversal;

pub fn traverse<const S: usize>(
    ctx: &Ctx,
    rays: &mut Rays,
    input: &[u32],
    solve: &mut Queue,
    record: &mut Queue,
    c: &mut Counters,
) {
    match ctx.traversal() {
        Traversal::Step => {
            for &r in input {
                march::<S>(ctx, rays, r, solve, record, c);
            }
        }
        Traversal::Dda | Traversal::Octree | Traversal::Distance => {
            for &r in input {
                walk(ctx, rays, r, solve, record, c);
            }
        }
    }
}

/// A ray in cell coordinates: origin, direction and its reciprocal.
#[derive(Clone, Copy, Debug)]
pub struct CellRay {
    pub ou: [f64; 3],
    pub du: [f64; 3],
    /// `1/du`, unused where `du == 0`.
    pub inv: [f64; 3],
}

impl CellRay {
    pub fn new(ou: [f64; 3], du: [f64; 3]) -> CellRay {
        CellRay {
            ou,
            du,
            inv: du.map(|d| if d != 0.0 { 1.0 / d } else { 0.0 }),
        }
    }
}

/// The parameter interval where the ray is inside `cell`: a pure function of
/// the ray and the cell, so a segment is the same bits however the walk
/// reached the cell (by single steps or by a jump over a block).
#[inline(always)]
pub fn cell_span(ray: &CellRay, cell: [i64; 3]) -> (f64, f64) {
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    for a in 0..3 {
        if ray.du[a] != 0.0 {
            let ta = (cell[a] as f64 - ray.ou[a]) * ray.inv[a];
            let tb = ((cell[a] + 1) as f64 - ray.ou[a]) * ray.inv[a];
            t0 = t0.max(ta.min(tb));
            t1 = t1.min(ta.max(tb));
        }
    }
    (t0, t1)
}

/// Where the ray leaves the aligned block of `2^level` cells holding `cell`
/// (not before `t`), and the cell it enters there.
#[inline(always)]
pub fn exit_block(ray: &CellRay, cell: [i64; 3], level: u32, t: f64) -> (f64, [i64; 3]) {
    let size = 1i64 << level;
    let lo = cell.map(|c| (c >> level) << level);
    exit_box(ray, cell, lo, lo.map(|l| l + size - 1), t)
}

/// Where the ray leaves the box of cells `lo ..= hi` (which holds `cell`),
/// not before `t`, and the cell it enters there.
///
/// The exit axis moves just past the box exactly; the other axes come from
/// the exit point, clamped into the box and never moving backwards, so every
/// step makes progress whatever the rounding (rays along faces, edges and
/// corners included).
#[inline(always)]
pub fn exit_box(
    ray: &CellRay,
    cell: [i64; 3],
    lo: [i64; 3],
    hi: [i64; 3],
    t: f64,
) -> (f64, [i64; 3]) {
    let CellRay { ou, du, inv } = *ray;
    let mut t_exit = f64::INFINITY;
    let mut axis = 0;
    for a in 0..3 {
        let ta = if du[a] > 0.0 {
            ((hi[a] + 1) as f64 - ou[a]) * inv[a]
        } else if du[a] < 0.0 {
            (lo[a] as f64 - ou[a]) * inv[a]
        } else {
            f64::INFINITY
        };
        if ta < t_exit {
            t_exit = ta;
            axis = a;
        }
    }
    let t_new = t_exit.max(t);
    let mut next = cell;
    for a in 0..3 {
        if a == axis {
            next[a] = if du[a] > 0.0 { hi[a] + 1 } else { lo[a] - 1 };
        } else if du[a] != 0.0 {
            let at = floor_i64(ou[a] + t_new * du[a]).clamp(lo[a], hi[a]);
            next[a] = if du[a] > 0.0 {
                at.max(cell[a])
            } else {
                at.min(cell[a])
            };
        }
    }
    (t_new, next)
}

/// Incremental Amanatides–Woo state: the ray's current cell, the parameter
/// where it entered, and where it crosses the next boundary on each axis. A
/// single-cell step is a comparison and two additions; after a jump over an
/// empty block the state is re-seeded from the new cell.
pub struct Dda {
    pub cell: [i64; 3],
    pub t: f64,
    t_max: [f64; 3],
    t_delta: [f64; 3],
    step: [i64; 3],
}

impl Dda {
    #[inline(always)]
    pub fn new(ray: &CellRay, cell: [i64; 3], t: f64) -> Dda {
        let mut d = Dda {
            cell,
            t,
            t_max: [f64::INFINITY; 3],
            t_delta: [f64::INFINITY; 3],
            step: [0; 3],
        };
        for a in 0..3 {
            if ray.du[a] != 0.0 {
                d.step[a] = if ray.du[a] > 0.0 { 1 } else { -1 };
                d.t_delta[a] = ray.inv[a].abs();
            }
        }
        d.seed(ray, cell, t);
        d
    }

    /// Moves to `cell` at `t` (after a jump) and recomputes the boundaries.
    #[inline(always)]
    fn seed(&mut self, ray: &CellRay, cell: [i64; 3], t: f64) {
        self.cell = cell;
        self.t = t;
        for a in 0..3 {
            if self.step[a] != 0 {
                let edge = (cell[a] + (self.step[a] > 0) as i64) as f64;
                self.t_max[a] = ((edge - ray.ou[a]) * ray.inv[a]).max(t);
            }
        }
    }

    /// Where the ray leaves the current cell.
    #[inline(always)]
    pub fn cell_exit(&self) -> f64 {
        self.t_max[0].min(self.t_max[1]).min(self.t_max[2])
    }

    /// Steps into the next cell along the ray.
    #[inline(always)]
    pub fn advance(&mut self) {
        let a = if self.t_max[0] <= self.t_max[1] {
            if self.t_max[0] <= self.t_max[2] { 0 } else { 2 }
        } else if self.t_max[1] <= self.t_max[2] {
            1
        } else {
            2
        };
        self.t = self.t_max[a];
        self.cell[a] += self.step[a];
        self.t_max[a] += self.t_delta[a];
    }
}

#[inline(always)]
fn in_range(ctx: &Ctx, c: [i64; 3]) -> bool {
    let n = ctx.lattice.cells;
    (c[0] as u64) < n[0] as u64 && (c[1] as u64) < n[1] as u64 && (c[2] as u64) < n[2] as u64
}

/// Cell walk for `dda`, `octree` and `distance`: single cells step by the
/// incremental DDA, skipped blocks and cubes by [`exit_box`].
fn walk(
    ctx: &Ctx,
    rays: &mut Rays,
    r: u32,
    solve: &mut Queue,
    record: &mut Queue,
    c: &mut Counters,
) {
    let i = r as usize;
    let og = ctx.to_grid(rays.origin(i));
    let dg = ctx.to_grid(rays.direction(i));
    let off = ctx.lattice.offset;
    let ray = CellRay::new([og.x + off, og.y + off, og.z + off], [dg.x, dg.y, dg.z]);
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
        let skip = match &ctx.skip {
            Skip::Bound(b) => (!b.may_cross(ctx.field, cell, ctx.iso)).then_some(0),
            Skip::Octree { tree, leaf_level } => tree.skip_level_fast(cell, *leaf_level),
            Skip::Distance(p) => match p.get(cell) {
                0 => None,
                1 => Some(0),
                d => {
                    // The cube of radius d-1 around the cell is empty.
                    let r = d as i64 - 1;
                    let n = ctx.lattice.cells;
                    let lo = std::array::from_fn(|a| (cell[a] - r).max(0));
                    let hi = std::array::from_fn(|a| (cell[a] + r).min(n[a] as i64 - 1));
                    let (t, next) = exit_box(&ray, cell, lo, hi, w.t);
                    w.seed(&ray, next, t);
                    continue;
                }
            },
        };
        match skip {
            None => {
                rays.t[i] = w.t;
                rays.seg_end[i] = w.cell_exit().min(t_end);
                rays.set_cell(i, cell);
                solve.push(r);
                return;
            }
            Some(0) => w.advance(),
            Some(level) => {
                let (t, next) = exit_block(&ray, cell, level, w.t);
                w.seed(&ray, next, t);
            }
        }
    }
}

/// Fixed-step march for `step`: samples at `t0 + k·h` until the side changes.
fn march<const S: usize>(
    ctx: &Ctx,
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
        let g_next = field_minus_iso::<S>(ctx, ctx.to_grid(o + t_next * d), c);
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

    /// Cells a segment crosses, by dense sampling (a brute-force reference).
    fn brute(ou: [f64; 3], du: [f64; 3], t1: f64) -> Vec<[i64; 3]> {
        let mut out: Vec<[i64; 3]> = Vec::new();
        let n = 200_000;
        for k in 0..=n {
            let t = t1 * k as f64 / n as f64;
            let c = [0, 1, 2].map(|a| (ou[a] + t * du[a]).floor() as i64);
            if out.last() != Some(&c) {
                out.push(c);
            }
        }
        out
    }

    fn walk_cells(ou: [f64; 3], du: [f64; 3], t1: f64) -> Vec<[i64; 3]> {
        let mut cell = ou.map(|x| x.floor() as i64);
        let mut t = 0.0;
        let mut out = vec![cell];
        loop {
            let (tn, next) = exit_block(&CellRay::new(ou, du), cell, 0, t);
            if tn >= t1 {
                return out;
            }
            t = tn;
            cell = next;
            out.push(cell);
        }
    }

    #[test]
    fn dda_visits_the_cells_a_segment_crosses() {
        let cases = [
            ([0.3, 0.4, 0.5], [1.0, 0.7, 0.2]),
            ([5.7, 2.2, 3.9], [-0.3, 0.9, -0.5]),
            ([1.5, 1.5, 1.5], [1.0, 0.0, 0.0]),
            ([1.25, 3.5, 0.75], [0.0, -1.0, 0.0]),
        ];
        for (ou, du) in cases {
            let t1 = 6.0;
            let got = walk_cells(ou, du, t1);
            let want = brute(ou, du, t1);
            assert_eq!(got, want, "origin {ou:?} dir {du:?}");
        }
    }

    #[test]
    fn dda_progresses_through_edges_and_corners() {
        // Along a face diagonal through cell corners: every step advances.
        let ou = [1.0, 1.0, 0.5];
        let du = [1.0, 1.0, 0.0];
        let got = walk_cells(ou, du, 4.0);
        for w in got.windows(2) {
            assert!(w[1][0] >= w[0][0] && w[1][1] >= w[0][1] && w[1] != w[0]);
        }
        assert_eq!(*got.last().unwrap(), [4, 4, 0]);
    }

    #[test]
    fn block_exit_skips_whole_blocks() {
        let (t, next) = exit_block(
            &CellRay::new([0.5, 0.5, 0.5], [1.0, 0.25, 0.1]),
            [0, 0, 0],
            2,
            0.0,
        );
        assert_eq!(t, 3.5);
        assert_eq!(next, [4, 1, 0]);
    }
}
