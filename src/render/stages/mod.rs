//! The pipeline's stages. Each one drains an input queue of ray indices and
//! pushes every ray into exactly one output queue (but for the straight rays
//! below):
//!
//! ```text
//! generate ─▶ entry ─┬─▶ traverse ─┬─▶ solve ─┬─▶ refract ─┬─▶ traverse
//!                    │             │          └─▶ traverse  └─▶ record (max events)
//!                    │             └─▶ record (left the volume)
//!                    └─▶ record (cannot meet the surface)
//! ```
//!
//! The first pass's pixel-centre rays reach the entry stage as runs of
//! directions, not yet in the packet; the entry stage records the ones that
//! go straight to the backdrop itself ([`record::record_straight`]), so only
//! rays that may meet the surface enter the packet and the queues.
//!
//! Stages that touch the field are generic over the kernel support `S`, so
//! their inner loops are compiled per filter.

pub mod entry;
pub mod generate;
pub mod record;
pub mod refract;
pub mod solve;
pub mod traverse;

use glam::DVec3;

use super::context::Ctx;
use super::packet::Rays;
use crate::filter::coeffs::Coefficient;
use crate::render::stats::Counters;
use crate::scene::Traversal;

/// Starts ray `i`'s current piece at parameter `t` (it must lie in the
/// domain box up to `t_end`) and its walk at `t_walk ≥ t`, where the surface
/// can first be: sets the walk's cell, and for step traversal (whose walk
/// starts with its piece) the field value there (the start of the next
/// bracket).
#[inline]
pub(crate) fn place<const S: usize, T: Coefficient>(
    ctx: &Ctx<T>,
    rays: &mut Rays,
    i: usize,
    (t, t_walk): (f64, f64),
    t_end: f64,
    c: &mut Counters,
) {
    let dg = ctx.to_grid(rays.direction(i));
    for a in 0..3 {
        rays.cell_inv[a][i] = if dg[a] != 0.0 { 1.0 / dg[a] } else { 0.0 };
    }
    rays.t_start[i] = t;
    rays.t_end[i] = t_end;
    rays.advance[i] = false;
    let p = move_walk(ctx, rays, i, t_walk);
    if ctx.traversal() == Traversal::Step {
        rays.seg_g[0][i] = field_minus_iso::<S, _>(ctx, p, c);
    }
}

/// Moves ray `i`'s walk (not its piece) to parameter `t`, in the cell
/// there; returns that point in grid coordinates.
#[inline(always)]
fn move_walk<T: Coefficient>(ctx: &Ctx<T>, rays: &mut Rays, i: usize, t: f64) -> DVec3 {
    let p = ctx.to_grid(rays.origin(i) + t * rays.direction(i));
    rays.t[i] = t;
    rays.set_cell(
        i,
        [
            ctx.lattice.cell_of(0, p.x),
            ctx.lattice.cell_of(1, p.y),
            ctx.lattice.cell_of(2, p.z),
        ],
    );
    p
}

/// `f(p) - iso` at a grid point, clamped into the domain.
///
/// Always inlined: the step march calls it ~577 times a ray (the lobster),
/// and left to the compiler it became a call from c72cfd5 on (likely once
/// the portable lanes gave it more callers), which made step-0.1 frames
/// 28% slower (a call per step; the lost set-up hoisting and register
/// spills are the likely cost, not inspected in the machine code).
#[inline(always)]
pub(crate) fn field_minus_iso<const S: usize, T: Coefficient>(
    ctx: &Ctx<T>,
    p: DVec3,
    c: &mut Counters,
) -> f64 {
    c.kernel_evals += 1;
    let hi = ctx.field.dims().map(|n| (n - 1) as f64);
    let q = [
        p.x.clamp(0.0, hi[0]),
        p.y.clamp(0.0, hi[1]),
        p.z.clamp(0.0, hi[2]),
    ];
    ctx.field.value_in::<S>(q) - ctx.iso
}
