//! Stage 2: clip rays against the active box and start their walk where the
//! surface can first be; rays that cannot meet it go straight to the record
//! stage, the others start traversal in the medium the field says they are
//! in.
//!
//! The usual first pass's primary rays arrive as [`Run`]s of a row's pixels,
//! not yet in the packet: a run is clipped and bounded in vector lanes, and
//! its rays that go straight to the backdrop — most of a frame's, around
//! the object (sphere 46%, teapot 60%) — are recorded at once
//! ([`record::record_straight`]), never entering the packet, the queues or
//! the record stage: the same bits, for a few vector operations a ray.

use bumpalo::Bump;
use bumpalo::collections::Vec as BVec;
use glam::DVec3;

use super::super::context::Ctx;
use super::super::packet::{Fate, Queue, Rays};
use super::super::tile::TileOut;
use super::generate::{RUN, Run};
use super::{field_minus_iso, place, record};
use crate::filter::coeffs::Coefficient;
use crate::render::stats::Counters;
use crate::roots::inside;
use crate::scene::Traversal;
use crate::simd::Isa;

/// Places the primary rays: the packet's rays on `input` (any sampling),
/// and the pixel-centre [`Run`]s `runs` (pushed into the packet here, but
/// for the rays recorded straight into `out`).
#[allow(clippy::too_many_arguments)]
pub fn entry<const S: usize, T: Coefficient>(
    ctx: &Ctx<T>,
    rays: &mut Rays,
    input: &[u32],
    runs: &[Run],
    traverse: &mut Queue,
    record: &mut Queue,
    out: &mut TileOut,
    c: &mut Counters,
    bump: &Bump,
) {
    if !runs.is_empty() {
        crate::with_isa!(Isa::current(), _L, _M => entry_runs::<S, _>(ctx, rays, runs, traverse, out, c, bump));
    }
    for &r in input {
        let i = r as usize;
        c.rays += 1;
        let (o, d) = (rays.origin(i), rays.direction(i));
        let span = if ctx.lattice.is_solid() {
            ctx.clip(o, d, 0.0)
        } else {
            None
        };
        match span {
            None => {
                rays.fate[i] = Fate::Escaped;
                record.push(r);
            }
            Some((t0, t1)) => {
                c.rays_entering += 1;
                // The walk starts where the surface can first be (the
                // piece, and so every solve, still starts at `t0`).
                let t_walk = ctx.first_hit.as_ref().map_or(t0, |f| f.at(rays.pixel[i]));
                if t_walk >= t1 {
                    rays.fate[i] = Fate::Escaped;
                    record.push(r);
                    continue;
                }
                enter::<S, _>(ctx, rays, r, (t0, t_walk, t1), traverse, c);
            }
        }
    }
}

/// [`entry`] for runs of pixel-centre rays from the camera: each run's clip,
/// approach bounds and, for the cell traversals, the walk's start ([`place`]:
/// the direction's reciprocal in cell coordinates and the cell there) in
/// lanes, with the same operations as one ray at a time (so the same bits;
/// [`Ctx::clip_lanes`] is tested against [`Ctx::clip`]); the rays that go
/// straight to the backdrop recorded, the others pushed into the packet.
#[inline(always)]
fn entry_runs<const S: usize, T: Coefficient>(
    ctx: &Ctx<T>,
    rays: &mut Rays,
    runs: &[Run],
    traverse: &mut Queue,
    out: &mut TileOut,
    c: &mut Counters,
    bump: &Bump,
) {
    let org = ctx.scene.camera.position;
    let o = org.to_array().map(|v| [v; RUN]);
    let solid = ctx.lattice.is_solid();
    let lanes = ctx.traversal() != Traversal::Step;
    let inv_spacing = ctx.inv_spacing.to_array();
    // The entering rays and where they start, set once the packet is
    // complete.
    let mut entering: BVec<Entering> = BVec::with_capacity_in(runs.len() * RUN, bump);
    for run in runs {
        let spans = if solid {
            ctx.clip_lanes(&o, &run.dir)
        } else {
            [None; RUN]
        };
        let bounds = ctx.first_hit.as_ref().map(|f| f.run(run.pixel));
        let mut straight = 0u8;
        let mut piece = [(0.0, 0.0, 0.0); RUN];
        for (l, span) in spans.iter().enumerate().take(run.len) {
            c.rays += 1;
            let Some((t0, t1)) = *span else {
                straight |= 1 << l;
                continue;
            };
            c.rays_entering += 1;
            let t_walk = bounds.map_or(t0, |b| b[l]);
            if t_walk >= t1 {
                straight |= 1 << l;
            }
            piece[l] = (t0, t_walk.max(t0), t1);
        }
        if straight != 0 {
            record::record_straight(ctx, org.to_array(), &run.dir, straight, run.slot, out, c);
        }
        let enter = !straight & ((1u16 << run.len) - 1) as u8;
        if enter == 0 {
            continue;
        }
        // `place`'s walk start for every lane (`move_walk`: the cell at
        // `to_grid(o + t·d)`).
        let (mut inv, mut cell) = ([[0.0; RUN]; 3], [[0i64; RUN]; 3]);
        if lanes {
            for a in 0..3 {
                for l in 0..RUN {
                    let dg = run.dir[a][l] * inv_spacing[a];
                    inv[a][l] = if dg != 0.0 { 1.0 / dg } else { 0.0 };
                    let at = (o[a][l] + piece[l].1 * run.dir[a][l]) * inv_spacing[a];
                    cell[a][l] = ctx.lattice.cell_of(a, at);
                }
            }
        }
        let first = rays.len() as u32;
        if enter == ((1u16 << run.len) - 1) as u8 {
            rays.push_centre_run((run.pixel, run.slot), run.len, org, &run.dir);
        } else {
            for l in (0..run.len).filter(|&l| enter >> l & 1 == 1) {
                rays.push(
                    (run.pixel + l as u32, run.slot + l as u32),
                    1.0,
                    true,
                    org,
                    DVec3::new(run.dir[0][l], run.dir[1][l], run.dir[2][l]),
                );
            }
        }
        for (i, l) in (first..).zip((0..run.len).filter(|&l| enter >> l & 1 == 1)) {
            entering.push(Entering {
                ray: i,
                piece: piece[l],
                inv: [0, 1, 2].map(|a| inv[a][l]),
                cell: [0, 1, 2].map(|a| cell[a][l]),
            });
        }
    }
    rays.complete();
    for e in &entering {
        let i = e.ray as usize;
        let (t0, t_walk, t1) = e.piece;
        if lanes {
            for a in 0..3 {
                rays.cell_inv[a][i] = e.inv[a];
            }
            rays.t_start[i] = t0;
            rays.t_end[i] = t1;
            rays.advance[i] = false;
            rays.t[i] = t_walk;
            rays.set_cell(i, e.cell);
            set_medium(ctx, rays, i, t0);
            traverse.push(e.ray);
        } else {
            enter::<S, _>(ctx, rays, e.ray, (t0, t_walk, t1), traverse, c);
        }
    }
}

/// A ray of a [`Run`] that enters the active box: its index in the packet,
/// its piece `(t0, t_walk, t1)` and, for the cell traversals, what
/// [`place`] sets for its walk.
struct Entering {
    ray: u32,
    piece: (f64, f64, f64),
    inv: [f64; 3],
    cell: [i64; 3],
}

/// Starts ray `r`'s first piece `t0..t1` in the active box, its walk at
/// `t_walk` (where the surface can first be; the piece, and so every solve,
/// still starts at `t0`), in the medium it enters.
#[inline(always)]
fn enter<const S: usize, T: Coefficient>(
    ctx: &Ctx<T>,
    rays: &mut Rays,
    r: u32,
    (t0, t_walk, t1): (f64, f64, f64),
    traverse: &mut Queue,
    c: &mut Counters,
) {
    let i = r as usize;
    place::<S, _>(ctx, rays, i, (t0, t_walk.max(t0)), t1, c);
    if ctx.traversal() == Traversal::Step {
        // `place` sampled the field at this very point (the march's first
        // sample).
        rays.inside[i] = inside(rays.seg_g[0][i]);
    } else {
        set_medium(ctx, rays, i, t0);
    }
    traverse.push(r);
}

/// The medium of cell-traversal ray `i`, whose piece starts at `t0`: known
/// when it enters through a face of the active box, whose whole surface is
/// on one side ([`Ctx::entry_side`]), else deferred to its first solve
/// ([`Rays::side_known`]).
#[inline(always)]
fn set_medium<T: Coefficient>(ctx: &Ctx<T>, rays: &mut Rays, i: usize, t0: f64) {
    match ctx.entry_side.filter(|_| t0 > 0.0) {
        Some(side) => {
            rays.inside[i] = side;
            rays.side_known[i] = true;
        }
        None => rays.side_known[i] = false,
    }
}

/// Sets ray `i`'s medium from the field at the start of its first piece,
/// where it entered the domain: the point the entry stage found, so deferring
/// this evaluation changes no bit of it.
#[inline]
pub(crate) fn set_side<const S: usize, T: Coefficient>(
    ctx: &Ctx<T>,
    rays: &mut Rays,
    i: usize,
    c: &mut Counters,
) {
    let p = rays.origin(i) + rays.t_start[i] * rays.direction(i);
    let g = field_minus_iso::<S, _>(ctx, ctx.to_grid(p), c);
    rays.inside[i] = inside(g);
    rays.side_known[i] = true;
}
