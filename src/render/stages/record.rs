//! Stage 6: rays that left the volume travel straight to the backdrop; record
//! where they land (the hit-position image) and what colour they see.

use super::super::context::Ctx;
use super::super::packet::{Fate, Rays};
use super::super::tile::TileOut;
use crate::filter::coeffs::Coefficient;
use crate::render::stats::Counters;

/// Records every ray of `input`: its hit position (pixel-centre rays) and,
/// where `out` holds colours, its weighted backdrop colour (skipped when a
/// post stage colours the film from the hit image: single-thread record
/// stage, sphere 6.0 / 5.9 → 3.3 / 3.2 ms, teapot 6.4 / 6.0 → 3.4 / 3.5 ms).
pub fn record<T: Coefficient>(
    ctx: &Ctx<T>,
    rays: &Rays,
    input: &[u32],
    out: &mut TileOut,
    c: &mut Counters,
) {
    for &r in input {
        let i = r as usize;
        let (o, d) = (rays.origin(i), rays.direction(i));
        let hit = match rays.fate[i] {
            Fate::Escaped => {
                if !(o.is_finite() && d.is_finite()) {
                    c.undefined += 1;
                    None
                } else {
                    let h = ctx.scene.backdrop.hit(o, d);
                    if h.is_none() {
                        c.missed_backdrop += 1;
                    }
                    h
                }
            }
            Fate::Terminated => None,
            Fate::Active => {
                c.undefined += 1;
                None
            }
        };
        let local = rays.slot[i] as usize;
        if let Some(colours) = &mut out.color {
            let color = match hit {
                Some((u, v)) => ctx.scene.backdrop.color(u, v),
                None => ctx.scene.background,
            };
            let w = rays.weight[i];
            for k in 0..3 {
                colours[local][k] += w * color[k];
            }
        }
        if rays.centre[i] {
            let (u, v) = hit.unwrap_or((f64::NAN, f64::NAN));
            out.u[local] = u as f32;
            out.v[local] = v as f32;
            out.events[local] = rays.events[i] as f32;
        }
    }
}
