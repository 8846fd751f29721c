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

    /// The glass sphere scene's backdrop (z = 200, u along x), and one ball of
    /// radius 20 at (31.5, 31.5, 31.5) with optional holes.
    fn ball(n: f64, holes: &[(DVec3, f64)], max_events: u32) -> (Scene, Reference) {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/sphere-f32.toml");
        let scene = Scene::load(&path, &[]).unwrap();
        let centre = DVec3::splat(31.5);
        let mut balls = vec![Ball {
            center: centre,
            radius: 20.0,
            solid: true,
        }];
        balls.extend(holes.iter().map(|&(c, r)| Ball {
            center: centre + c,
            radius: r,
            solid: false,
        }));
        let r = Reference {
            balls,
            ior_inside: n,
            ior_outside: 1.0,
            max_events,
            approximate_holes: 0,
        };
        (scene, r)
    }

    /// A ray parallel to the axis at impact parameter `b` through a ball of
    /// radius R and index n is turned by 2(asin(b/R) − asin(b/(nR))) towards
    /// the axis, leaving from the far end of a chord 2R·cos(asin(b/(nR)))
    /// long: the backdrop hit by plane geometry, against the reference's
    /// vector tracing.
    #[test]
    fn a_ball_deflects_rays_as_the_closed_form_says() {
        let (scene, reference) = ball(1.5, &[], 32);
        let (r, n, z_backdrop) = (20.0f64, 1.5f64, 200.0 - 31.5);
        for b in [0.0, 1.0, 7.5, 13.0, 19.0] {
            let o = DVec3::new(31.5 + b, 31.5, -100.0);
            let (hit, events) = reference.trace(&scene, o, DVec3::Z);
            let (u, v) = hit.unwrap_or_else(|| panic!("b = {b}: no backdrop hit"));
            assert_eq!(events, 2, "b = {b}");
            // In the ball's frame, x across and z along the ray.
            let (t1, t2) = ((b / r).asin(), (b / (n * r)).asin());
            let turn = t1 - t2;
            let entry = (b, -(r * r - b * b).sqrt());
            let chord = 2.0 * r * t2.cos();
            let exit = (entry.0 - chord * turn.sin(), entry.1 + chord * turn.cos());
            let want = exit.0 - (z_backdrop - exit.1) * (2.0 * turn).tan();
            assert!(
                (u - want).abs() < 1e-9 * (1.0 + want.abs()),
                "b = {b}: u {u} against {want}"
            );
            assert!(v.abs() < 1e-9, "b = {b}: v {v}");
        }
        // Outside the ball: no event, straight on.
        let (hit, events) = reference.trace(&scene, DVec3::new(52.0, 31.5, -100.0), DVec3::Z);
        assert_eq!((events, hit.map(|h| h.0)), (0, Some(52.0 - 31.5)));
    }

    /// Through a hole's centre along the axis: four interfaces at normal
    /// incidence, undeviated; `max_events` 3 stops the ray without a hit.
    #[test]
    fn a_hole_on_the_axis_adds_two_straight_events() {
        let (scene, reference) = ball(1.5, &[(DVec3::ZERO, 5.0)], 32);
        let o = DVec3::new(31.5, 31.5, -100.0);
        let (hit, events) = reference.trace(&scene, o, DVec3::Z);
        assert_eq!(events, 4);
        let (u, v) = hit.unwrap();
        assert!(u.abs() < 1e-12 && v.abs() < 1e-12, "{u} {v}");
        let (_, stopped) = ball(1.5, &[(DVec3::ZERO, 5.0)], 3);
        assert_eq!(stopped.trace(&scene, o, DVec3::Z), (None, 3));
    }
}
