//! Stage 5: bend the ray at the crossing by Snell's law.
//!
//! The outward normal is `n = -∇f/|∇f|` (the object is `f > iso`), from the
//! analytic gradient in world units (grid gradient divided by spacing). Total
//! internal reflection mirrors the ray and keeps its medium. A vanishing
//! gradient gives no normal: the ray passes straight but changes medium. After
//! `max_events` events the ray stops with no backdrop hit (SPEC).

use glam::DVec3;

use super::super::context::Ctx;
use super::super::packet::{Fate, Queue, Rays};
use super::place;
use crate::filter::coeffs::Coefficient;
use crate::render::stats::Counters;

/// Result of bending a unit direction `d` at a surface with outward normal
/// `n`, going from index `n1` into `n2`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Bend {
    Refracted(DVec3),
    Reflected(DVec3),
}

/// Snell's law with total internal reflection. `d` and `n` must be unit.
#[inline]
pub fn snell(d: DVec3, n: DVec3, n1: f64, n2: f64) -> Bend {
    // Orient the normal against the incoming ray.
    let nf = if d.dot(n) > 0.0 { -n } else { n };
    let cos_i = (-d.dot(nf)).clamp(0.0, 1.0);
    let eta = n1 / n2;
    let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
    if k < 0.0 {
        Bend::Reflected((d + 2.0 * cos_i * nf).normalize())
    } else {
        Bend::Refracted((eta * d + (eta * cos_i - k.sqrt()) * nf).normalize())
    }
}

pub fn refract<const S: usize, T: Coefficient>(
    ctx: &Ctx<T>,
    rays: &mut Rays,
    input: &[u32],
    traverse: &mut Queue,
    record: &mut Queue,
    c: &mut Counters,
) {
    let hi = ctx.field.dims().map(|n| (n - 1) as f64);
    // Restart a hair past the crossing so its root is not found again.
    let eps_vox = (10.0 * ctx.settings.tolerance).max(1e-9);
    for &r in input {
        let i = r as usize;
        let d = rays.direction(i);
        let p = rays.origin(i) + rays.t[i] * d;
        let pg = ctx.to_grid(p);
        let q = [
            pg.x.clamp(0.0, hi[0]),
            pg.y.clamp(0.0, hi[1]),
            pg.z.clamp(0.0, hi[2]),
        ];
        c.kernel_evals += 1;
        let (_, grad) = ctx.field.value_grad_fast::<S>(q);
        let grad_world = DVec3::from_array(grad) * ctx.inv_spacing;
        let len = grad_world.length();
        let entering = !rays.inside[i];
        let (n1, n2) = if entering {
            (ctx.ior_outside, ctx.ior_inside)
        } else {
            (ctx.ior_inside, ctx.ior_outside)
        };
        let new_dir = if !(len > 0.0 && len.is_finite()) {
            c.degenerate_normals += 1;
            rays.inside[i] = entering;
            d
        } else {
            match snell(d, -grad_world / len, n1, n2) {
                Bend::Refracted(nd) => {
                    c.refractions += 1;
                    rays.inside[i] = entering;
                    nd
                }
                Bend::Reflected(nd) => {
                    c.reflections += 1;
                    nd
                }
            }
        };
        rays.events[i] += 1;
        rays.set_origin(i, p);
        rays.set_direction(i, new_dir);
        if rays.events[i] >= ctx.settings.max_events {
            c.terminated += 1;
            rays.fate[i] = Fate::Terminated;
            record.push(r);
            continue;
        }
        let eps = eps_vox / ctx.to_grid(new_dir).length();
        match ctx.clip(p, new_dir, 0.0) {
            Some((_, t1)) if t1 > eps => {
                place::<S, _>(ctx, rays, i, eps, t1, c);
                traverse.push(r);
            }
            _ => {
                rays.fate[i] = Fate::Escaped;
                record.push(r);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn obeys_snells_law() {
        let n = DVec3::Y; // outward normal
        let d = DVec3::new(0.6, -0.8, 0.0); // hitting from above
        match snell(d, n, 1.0, 1.5) {
            Bend::Refracted(t) => {
                assert!((t.length() - 1.0).abs() < 1e-15);
                let sin_i = d.x.abs();
                let sin_t = t.x.abs();
                assert!((1.0 * sin_i - 1.5 * sin_t).abs() < 1e-14);
                assert!(t.y < 0.0, "continues through the surface");
            }
            b => panic!("{b:?}"),
        }
        // Normal incidence passes straight.
        assert_eq!(snell(-DVec3::Y, n, 1.0, 1.5), Bend::Refracted(-DVec3::Y));
    }

    #[test]
    fn total_internal_reflection_mirrors() {
        let n = DVec3::Y;
        let d = DVec3::new(0.8, 0.6, 0.0); // inside glass, going out steeply
        match snell(d, n, 1.5, 1.0) {
            Bend::Reflected(t) => {
                assert!((t - DVec3::new(0.8, -0.6, 0.0)).length() < 1e-15);
            }
            b => panic!("{b:?}"),
        }
        // Just below the critical angle it still refracts, grazing.
        let crit = (1.0f64 / 1.5).asin();
        let a = crit - 1e-9;
        let d = DVec3::new(a.sin(), a.cos(), 0.0);
        assert!(matches!(snell(d, n, 1.5, 1.0), Bend::Refracted(_)));
    }
}
