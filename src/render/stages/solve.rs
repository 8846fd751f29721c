//! Stage 4: find the crossing in the segment the traversal handed over.
//!
//! - cell segments (`dda`, `octree`): restrict the field to the segment (an
//!   exact polynomial), certify or isolate its sign changes by Bernstein
//!   subdivision, refine with Brent — a crossing inside the cell cannot be
//!   missed, two close ones at a silhouette included;
//! - step brackets (`step`): Brent on point evaluations, as the paper does.
//!
//! A found crossing goes to refraction; otherwise the ray goes back to the
//! traversal, past this segment.

use super::super::context::Ctx;
use super::super::packet::{Queue, Rays};
use super::field_minus_iso;
use crate::filter::restrict::knot_cell;
use crate::render::stats::Counters;
use crate::roots::bernstein::{Interval, IsolationWork, MAX_DEGREE};
use crate::roots::{brent, inside};
use crate::scene::Traversal;

pub fn solve<const S: usize>(
    ctx: &Ctx,
    rays: &mut Rays,
    input: &[u32],
    refract: &mut Queue,
    traverse: &mut Queue,
    c: &mut Counters,
) {
    match ctx.traversal() {
        Traversal::Step => {
            for &r in input {
                solve_bracket::<S>(ctx, rays, r, refract, traverse, c);
            }
        }
        Traversal::Dda | Traversal::Octree => {
            let mut g = [0.0; MAX_DEGREE + 1];
            let mut stack = Vec::with_capacity(64);
            for &r in input {
                solve_cell::<S>(ctx, rays, r, &mut g, &mut stack, refract, traverse, c);
            }
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn solve_cell<const S: usize>(
    ctx: &Ctx,
    rays: &mut Rays,
    r: u32,
    g: &mut [f64; MAX_DEGREE + 1],
    stack: &mut Vec<Interval>,
    refract: &mut Queue,
    traverse: &mut Queue,
    c: &mut Counters,
) {
    let i = r as usize;
    let (t0, t1) = (rays.t[i], rays.seg_end[i]);
    let og = ctx.to_grid(rays.origin(i));
    let dg = ctx.to_grid(rays.direction(i));
    let len = dg.length() * (t1 - t0);
    c.cells_solved += 1;
    if len > 1e-13 {
        let p0 = og + t0 * dg;
        let p1 = og + t1 * dg;
        let cell = rays.cell_of(i);
        debug_assert!((0..3).all(|a| {
            let k = knot_cell(0.5 * (p0[a] + p1[a]), ctx.lattice.offset);
            (k - cell[a]).abs() <= 1
        }));
        ctx.field
            .restrict::<S>(cell, p0.to_array(), p1.to_array(), ctx.iso, g);
        let poly = ctx.basis.segment(&g[..=ctx.basis.degree()]);
        let tol = (ctx.settings.tolerance / len).min(0.25);
        let mut work = IsolationWork::default();
        let hit = poly.first_crossing_with(rays.inside[i], tol, &mut work, stack);
        c.isolation_intervals += work.intervals as u64;
        c.brent_iters += work.brent_iters as u64;
        if let Some(s) = hit {
            c.cells_with_crossing += 1;
            rays.t[i] = t0 + s * (t1 - t0);
            refract.push(r);
            return;
        }
    }
    rays.t[i] = t1;
    rays.advance[i] = true;
    traverse.push(r);
}

fn solve_bracket<const S: usize>(
    ctx: &Ctx,
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
            |t| field_minus_iso::<S>(ctx, ctx.to_grid(o + t * d), &mut evals),
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
