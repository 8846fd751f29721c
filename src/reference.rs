//! The analytic reference: the sphere phantom's iso-surfaces as exact spheres.
//!
//! For the phantom `v(r) = 1` inside `R`, `exp(-(r-R)²/2σ²)` beyond, the
//! iso-surface at level `ℓ = iso / full_scale` is the sphere of radius
//! `R + σ·sqrt(2 ln(1/ℓ))`; an air hole (value multiplied by `1 - hole(r)`)
//! inside the ball's plateau bounds the surface `hole(r) = 1 - ℓ`, the sphere
//! of radius `R_h + σ_h·sqrt(2 ln(1/(1-ℓ)))`. Tracing the same camera and
//! backdrop through those spheres with the same refraction model gives the hit
//! positions a perfect reconstruction would — what `compare` measures against.
//!
//! A hole's sphere is exact where its fringe does not overlap the ball's; the
//! constructor reports when a hole reaches into the ball's fringe.

use glam::DVec3;

use crate::film::HitImage;
use crate::phantom::{PhantomSpec, fringe_radius};
use crate::render::stages::refract::{Bend, snell};
use crate::scene::{Scene, VolumeSource};

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReferenceError {
    #[error("the analytic reference needs a sphere phantom volume")]
    NotASphere,
    #[error("the analytic reference needs isotropic spacing, got {0:?}")]
    Anisotropic([f64; 3]),
    #[error("iso-value {iso} is not inside (0, {full}) of the phantom's range: no surface")]
    NoSurface { iso: f64, full: f64 },
    #[error(
        "the iso-surface (radius {radius:.3} about [{}, {}, {}]) does not fit in the phantom's {size}³ grid, which clips it: the analytic spheres would not be what a render sees",
        center[0], center[1], center[2]
    )]
    DoesNotFit {
        radius: f64,
        center: [f64; 3],
        size: usize,
    },
    #[error(transparent)]
    Phantom(#[from] crate::phantom::PhantomError),
}

/// One spherical interface: crossing it toggles membership of its ball.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ball {
    pub center: DVec3,
    pub radius: f64,
    /// True for the outer ball (glass inside), false for a hole (air inside).
    pub solid: bool,
}

/// Nested spheres equivalent to a sphere phantom at one iso-value.
#[derive(Clone, Debug)]
pub struct Reference {
    pub balls: Vec<Ball>,
    pub ior_inside: f64,
    pub ior_outside: f64,
    pub max_events: u32,
    /// Holes whose surface is only approximately a sphere (fringes overlap).
    pub approximate_holes: usize,
}

impl Reference {
    pub fn from_scene(scene: &Scene) -> Result<Reference, ReferenceError> {
        let VolumeSource::Phantom(PhantomSpec::Sphere(spec)) = &scene.volume else {
            return Err(ReferenceError::NotASphere);
        };
        // The phantom `render` would refuse to build is refused here too.
        spec.validate()?;
        let sp = scene.spacing.unwrap_or([1.0; 3]);
        if sp[0] != sp[1] || sp[1] != sp[2] {
            return Err(ReferenceError::Anisotropic(sp));
        }
        let s = sp[0];
        let full = spec.format.full_scale();
        let level = scene.surface.iso / full;
        let no_surface = ReferenceError::NoSurface {
            iso: scene.surface.iso,
            full,
        };
        if !(level > 0.0 && level < 1.0) {
            return Err(no_surface);
        }
        let r_outer = fringe_radius(spec.radius, spec.sigma, level).ok_or(no_surface.clone())?;
        // The sampled ball ends at the grid's faces; the analytic one would not.
        let centre = spec.center();
        if centre
            .iter()
            .any(|&x| x - r_outer < 0.0 || x + r_outer > (spec.size - 1) as f64)
        {
            return Err(ReferenceError::DoesNotFit {
                radius: r_outer,
                center: centre,
                size: spec.size,
            });
        }
        let c = DVec3::from_array(centre) * s;
        let mut balls = vec![Ball {
            center: c,
            radius: r_outer * s,
            solid: true,
        }];
        let mut approximate_holes = 0;
        for h in &spec.holes {
            let r = fringe_radius(h.radius, h.sigma, 1.0 - level).ok_or(no_surface.clone())?;
            let hc = DVec3::from_array(h.center) * s;
            // Exact while the hole's surface stays on the ball's plateau.
            if (hc - c).length() / s + r > spec.radius {
                approximate_holes += 1;
            }
            balls.push(Ball {
                center: hc,
                radius: r * s,
                solid: false,
            });
        }
        Ok(Reference {
            balls,
            ior_inside: scene.surface.ior,
            ior_outside: scene.surface.outside_ior,
            max_events: scene.render.max_events,
            approximate_holes,
        })
    }

    /// Glass where inside the outer ball and outside every hole.
    fn in_glass(&self, p: DVec3, inside: &[bool]) -> bool {
        let _ = p;
        inside[0] && !inside[1..].iter().any(|&b| b)
    }

    /// Traces one ray: backdrop coordinates and event count.
    pub fn trace(&self, scene: &Scene, mut o: DVec3, mut d: DVec3) -> (Option<(f64, f64)>, u32) {
        let mut inside: Vec<bool> = self
            .balls
            .iter()
            .map(|b| (o - b.center).length_squared() < b.radius * b.radius)
            .collect();
        let mut events = 0u32;
        loop {
            // Nearest sphere crossing ahead.
            let mut best: Option<(f64, usize)> = None;
            for (k, b) in self.balls.iter().enumerate() {
                if let Some(t) = first_hit(o, d, b, inside[k])
                    && best.is_none_or(|(bt, _)| t < bt)
                {
                    best = Some((t, k));
                }
            }
            // The backdrop is opaque: met before the next sphere, or with
            // none ahead, it ends the ray.
            let plane = scene.backdrop.plane_t(o, d);
            let Some((t, k)) = best.filter(|&(t, _)| plane.is_none_or(|tp| t < tp)) else {
                return (scene.backdrop.hit(o, d), events);
            };
            let p = o + t * d;
            let before = self.in_glass(p, &inside);
            let mut after_inside = inside.clone();
            after_inside[k] = !after_inside[k];
            let after = self.in_glass(p, &after_inside);
            let n_of = |glass: bool| {
                if glass {
                    self.ior_inside
                } else {
                    self.ior_outside
                }
            };
            let normal = (p - self.balls[k].center).normalize();
            events += 1;
            match snell(d, normal, n_of(before), n_of(after)) {
                Bend::Refracted(nd) => {
                    d = nd;
                    inside = after_inside;
                }
                Bend::Reflected(nd) => d = nd,
            }
            o = p;
            if events >= self.max_events {
                return (None, events);
            }
        }
    }

    /// The hit-position image of `scene` through the analytic spheres.
    pub fn render(&self, scene: &Scene) -> HitImage {
        use rayon::prelude::*;
        let (w, h) = (scene.width, scene.height);
        let rows: Vec<Vec<(f32, f32, f32)>> = (0..h)
            .into_par_iter()
            .map(|py| {
                (0..w)
                    .map(|px| {
                        let (o, d) = scene.camera.ray(px as f64 + 0.5, py as f64 + 0.5);
                        let (hit, ev) = self.trace(scene, o, d);
                        let (u, v) = hit.unwrap_or((f64::NAN, f64::NAN));
                        (u as f32, v as f32, ev as f32)
                    })
                    .collect()
            })
            .collect();
        let flat: Vec<(f32, f32, f32)> = rows.into_iter().flatten().collect();
        HitImage {
            width: w,
            height: h,
            u: flat.iter().map(|p| p.0).collect(),
            v: flat.iter().map(|p| p.1).collect(),
            events: flat.iter().map(|p| p.2).collect(),
        }
    }
}

/// Smallest `t` above a relative epsilon where the ray crosses the sphere,
/// choosing the exit root when starting inside.
fn first_hit(o: DVec3, d: DVec3, b: &Ball, inside: bool) -> Option<f64> {
    let oc = o - b.center;
    let half_b = oc.dot(d);
    let c = oc.length_squared() - b.radius * b.radius;
    let disc = half_b * half_b - c;
    if disc < 0.0 {
        return None;
    }
    let sq = disc.sqrt();
    // Numerically stable pair of roots.
    let q = -half_b - sq.copysign(half_b);
    let (r1, r2) = if q != 0.0 {
        (q, c / q)
    } else {
        (-half_b, -half_b)
    };
    let (t0, t1) = if r1 < r2 { (r1, r2) } else { (r2, r1) };
    let eps = 1e-9 * (1.0 + b.radius);
    if inside {
        (t1 > eps).then_some(t1)
    } else if t0 > eps {
        Some(t0)
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exits_and_entries() {
        let b = Ball {
            center: DVec3::ZERO,
            radius: 2.0,
            solid: true,
        };
        let t = first_hit(DVec3::new(0.0, 0.0, -5.0), DVec3::Z, &b, false).unwrap();
        assert!((t - 3.0).abs() < 1e-12);
        let t = first_hit(DVec3::ZERO, DVec3::Z, &b, true).unwrap();
        assert!((t - 2.0).abs() < 1e-12);
        assert!(first_hit(DVec3::new(0.0, 3.0, -5.0), DVec3::Z, &b, false).is_none());
    }
}
