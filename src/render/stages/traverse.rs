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
        Traversal::Dda | Traversal::Octree => {
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

/// Where the ray leaves the aligned block of `2^level` cells holding `cell`
/// (not before `t`), and the cell it enters there.
///
/// The exit axis moves to the neighbouring block exactly; the other axes come
/// from the exit point, clamped into the block and never moving backwards, so
/// every step makes progress whatever the rounding (rays along faces, edges
/// and corners included).
#[inline(always)]
pub fn exit_block(ray: &CellRay, cell: [i64; 3], level: u32, t: f64) -> (f64, [i64; 3]) {
    let CellRay { ou, du, inv } = *ray;
    let size = 1i64 << level;
    let lo = cell.map(|c| (c >> level) << level);
    let mut t_exit = f64::INFINITY;
    let mut axis = 0;
    for a in 0..3 {
        let ta = if du[a] > 0.0 {
            ((lo[a] + size) as f64 - ou[a]) * inv[a]
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
            next[a] = if du[a] > 0.0 { lo[a] + size } else { lo[a] - 1 };
        } else if du[a] != 0.0 {
            let at = floor_i64(ou[a] + t_new * du[a]);
            let at = at.clamp(lo[a], lo[a] + size - 1);
            next[a] = if du[a] > 0.0 {
                at.max(cell[a])
            } else {
                at.min(cell[a])
            };
        }
    }
    (t_new, next)
}

#[inline(always)]
fn in_range(ctx: &Ctx, c: [i64; 3]) -> bool {
    (0..3).all(|a| c[a] >= 0 && (c[a] as usize) < ctx.lattice.cells[a])
}

/// Cell walk for `dda` and `octree`.
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
    let mut cell = rays.cell_of(i);
    let mut t = rays.t[i];
    let t_end = rays.t_end[i];
    if rays.advance[i] {
        rays.advance[i] = false;
        (t, cell) = exit_block(&ray, cell, 0, t);
    }
    loop {
        if t >= t_end || !in_range(ctx, cell) {
            rays.fate[i] = Fate::Escaped;
            record.push(r);
            return;
        }
        c.cells_visited += 1;
        let skip = match &ctx.skip {
            Skip::Bound(b) => (!b.may_cross(ctx.field, cell, ctx.iso)).then_some(0),
            Skip::Octree { tree, leaf_level } => tree.skip_level(cell, *leaf_level),
        };
        match skip {
            None => {
                let (t_next, _) = exit_block(&ray, cell, 0, t);
                rays.t[i] = t;
                rays.seg_end[i] = t_next.min(t_end);
                rays.set_cell(i, cell);
                solve.push(r);
                return;
            }
            Some(level) => (t, cell) = exit_block(&ray, cell, level, t),
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
