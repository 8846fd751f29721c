//! Stage 2: clip rays against the domain box; rays that miss go straight to
//! the record stage, the others start traversal in the medium the field says
//! they are in.

use super::super::context::Ctx;
use super::super::packet::{Fate, Queue, Rays};
use super::{field_minus_iso, place};
use crate::filter::coeffs::Coefficient;
use crate::render::stats::Counters;
use crate::roots::inside;
use crate::scene::Traversal;

pub fn entry<const S: usize, T: Coefficient>(
    ctx: &Ctx<T>,
    rays: &mut Rays,
    input: &[u32],
    traverse: &mut Queue,
    record: &mut Queue,
    c: &mut Counters,
) {
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
                place::<S, _>(ctx, rays, i, (t0, t_walk.max(t0)), t1, c);
                if ctx.traversal() == Traversal::Step {
                    // `place` sampled the field at this very point (the
                    // march's first sample).
                    rays.inside[i] = inside(rays.seg_g[0][i]);
                } else if let Some(side) = ctx.entry_side.filter(|_| t0 > 0.0) {
                    // Entered through a face of the active box, whose whole
                    // surface is on one side (`Ctx::entry_side`).
                    rays.inside[i] = side;
                    rays.side_known[i] = true;
                } else {
                    // Deferred to the first solve (see `Rays::side_known`).
                    rays.side_known[i] = false;
                }
                traverse.push(r);
            }
        }
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
