//! Pinhole and orthographic cameras, exactly as SPEC.md defines them.

use glam::DVec3;

/// Projection model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Projection {
    /// `tan(fov_y / 2)`.
    Perspective { tan_half_fov: f64 },
    /// Half the view height in world units.
    Orthographic { half_height: f64 },
}

/// A camera with its orthonormal frame and image size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub position: DVec3,
    /// `f = normalize(look_at - position)`.
    pub forward: DVec3,
    /// `r = normalize(cross(f, up))`.
    pub right: DVec3,
    /// `u = cross(r, f)`.
    pub up: DVec3,
    pub projection: Projection,
    pub width: u32,
    pub height: u32,
}

/// Why a camera cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CameraError {
    #[error("position and look_at coincide")]
    NoDirection,
    #[error("up is zero or parallel to the viewing direction")]
    UpParallel,
    #[error("fov_y must be between 0 and 180 degrees (both excluded), got {0}")]
    BadFov(f64),
    #[error("orthographic height must be a finite number > 0, got {0}")]
    BadHeight(f64),
    /// A vector (`position`, `look_at`, `up`) with a NaN or infinite component.
    #[error("{0} must be finite")]
    NotFinite(&'static str),
    /// `position` or `look_at` too far from the origin: distances between
    /// such points square past the `f64` range.
    #[error(
        "{what} must lie within ±{MAX_COORD:e} of the origin on each axis (further out the camera's distances overflow), got {value:e}"
    )]
    TooFar { what: &'static str, value: f64 },
    /// The image's corner rays leave the `f64` range (a huge orthographic view).
    #[error("the view's corners lie beyond the f64 range; use a smaller height")]
    ViewOverflow,
}

/// Largest magnitude of a `position` or `look_at` coordinate: their
/// difference then squares to at most 1.2e301, far inside `f64`.
pub const MAX_COORD: f64 = 1e150;

impl Camera {
    pub fn new(
        position: DVec3,
        look_at: DVec3,
        up: DVec3,
        projection: Projection,
        width: u32,
        height: u32,
    ) -> Result<Camera, CameraError> {
        for (what, v) in [("position", position), ("look_at", look_at), ("up", up)] {
            if !v.is_finite() {
                return Err(CameraError::NotFinite(what));
            }
        }
        // Finite ends can still be an infinite distance apart (±1e308), or
        // square to infinity on the way to their distance.
        for (what, v) in [("position", position), ("look_at", look_at)] {
            if let Some(&value) = v.to_array().iter().find(|c| c.abs() > MAX_COORD) {
                return Err(CameraError::TooFar { what, value });
            }
        }
        let f = look_at - position;
        if f.length() <= 1e-12 * (1.0 + position.length()) {
            return Err(CameraError::NoDirection);
        }
        let f = f.normalize();
        // Only up's direction matters: scaled to a largest component of 1,
        // a huge `up` (1e155) squares without overflow.
        let up = crate::scene::unit_scale(up);
        let r = f.cross(up);
        if r.length() <= 1e-9 * up.length().max(1e-300) || up.length() == 0.0 {
            return Err(CameraError::UpParallel);
        }
        let r = r.normalize();
        let u = r.cross(f);
        match projection {
            Projection::Perspective { tan_half_fov } => {
                if !(tan_half_fov.is_finite() && tan_half_fov > 0.0) {
                    return Err(CameraError::BadFov(2.0 * tan_half_fov.atan().to_degrees()));
                }
            }
            Projection::Orthographic { half_height } => {
                if !(half_height.is_finite() && half_height > 0.0) {
                    return Err(CameraError::BadHeight(2.0 * half_height));
                }
            }
        }
        let cam = Camera {
            position,
            forward: f,
            right: r,
            up: u,
            projection,
            width,
            height,
        };
        // The image corners (an orthographic view can reach past f64 range).
        let (w, h) = (width as f64, height as f64);
        for (x, y) in [(0.0, 0.0), (w, h)] {
            let (o, d) = cam.ray(x, y);
            if !(o.is_finite() && d.is_finite()) {
                return Err(CameraError::ViewOverflow);
            }
        }
        Ok(cam)
    }

    /// How far `f64` rounding may move a ray's origin, in world units: the
    /// camera's distance from the origin or from `centre` (the volume's),
    /// whichever is larger, times `f64`'s unit roundoff. Far cameras
    /// (1e12 world units from a 64-voxel volume) move hits measurably,
    /// which no traversal can undo; commands warn when this passes a
    /// millionth of a voxel.
    pub fn origin_rounding(&self, centre: DVec3) -> f64 {
        // Lengths scaled by the largest component, which squaring alone
        // would overflow past 1e154 (volumes of spacing 1e300 exist).
        let length = |v: DVec3| {
            let m = v.abs().max_element();
            if m > 0.0 && m.is_finite() {
                m * (v / m).length()
            } else {
                m
            }
        };
        let d = length(self.position).max(length(self.position - centre));
        d * f64::EPSILON / 2.0
    }

    /// Ray through continuous image position `(x, y)` (pixel `(px, py)` has its
    /// centre at `(px + 0.5, py + 0.5)`; row 0 at the top). Returns origin and
    /// unit direction.
    #[inline]
    pub fn ray(&self, x: f64, y: f64) -> (DVec3, DVec3) {
        let (w, h) = (self.width as f64, self.height as f64);
        let sx = 2.0 * x / w - 1.0;
        let sy = 1.0 - 2.0 * y / h;
        let aspect = w / h;
        match self.projection {
            Projection::Perspective { tan_half_fov: t } => {
                let d = self.forward + sx * t * aspect * self.right + sy * t * self.up;
                (self.position, d.normalize())
            }
            Projection::Orthographic { half_height } => {
                let o = self.position
                    + sx * half_height * aspect * self.right
                    + sy * half_height * self.up;
                (o, self.forward)
            }
        }
    }

    /// The unit directions of a perspective camera's rays through
    /// `(xs[l], y)`, `N` at a time (the origin is `position`); `None` for
    /// an orthographic camera. Lane by lane the operations of
    /// [`Camera::ray`] in its order, so bitwise its directions, written over
    /// arrays so the divisions and square root run as vector instructions
    /// (one ray at a time, they took most of the generator's time).
    #[inline(always)]
    pub fn directions<const N: usize>(&self, xs: &[f64; N], y: f64) -> Option<[[f64; N]; 3]> {
        let Projection::Perspective { tan_half_fov: t } = self.projection else {
            return None;
        };
        let (w, h) = (self.width as f64, self.height as f64);
        let sy = 1.0 - 2.0 * y / h;
        let aspect = w / h;
        let (f, r, u) = (self.forward, self.right, self.up);
        let along_up = sy * t;
        let mut d = [[0.0; N]; 3];
        for l in 0..N {
            let across = (2.0 * xs[l] / w - 1.0) * t * aspect;
            for a in 0..3 {
                d[a][l] = f[a] + across * r[a] + along_up * u[a];
            }
        }
        for l in 0..N {
            let len = ((d[0][l] * d[0][l]) + (d[1][l] * d[1][l]) + (d[2][l] * d[2][l])).sqrt();
            let recip = 1.0 / len;
            for row in d.iter_mut() {
                row[l] *= recip;
            }
        }
        Some(d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The origin's rounding of a volume at 1e301 world units is f64's
    /// unit roundoff of that distance, not an overflow to infinity.
    #[test]
    fn origin_rounding_of_huge_extents_is_finite() {
        let projection = Projection::Perspective {
            tan_half_fov: 0.3f64.tan(),
        };
        let c = Camera::new(
            DVec3::new(7.5, 7.5, -40.0),
            DVec3::new(7.5, 7.5, 0.0),
            DVec3::Y,
            projection,
            64,
            64,
        )
        .unwrap();
        let centre = DVec3::splat(3e301);
        let want = 3e301 * 3f64.sqrt() * f64::EPSILON / 2.0;
        let got = c.origin_rounding(centre);
        assert!(
            (got - want).abs() <= 1e-12 * want,
            "{got:e} against {want:e}"
        );
        let near = c.origin_rounding(DVec3::new(7.5, 7.5, 0.0));
        let want = DVec3::new(7.5, 7.5, -40.0).length() * f64::EPSILON / 2.0;
        assert!(
            (near - want).abs() <= 1e-12 * want,
            "{near:e} against {want:e}"
        );
    }

    #[test]
    fn directions_are_the_rays_bitwise() {
        for (pos, w, h, fov) in [
            (DVec3::new(31.5, 31.5, -150.0), 512, 512, 20.0f64),
            (DVec3::new(-3.0, 70.0, 12.5), 301, 77, 63.0),
            (DVec3::new(1e3, -2e2, 5e2), 64, 900, 1.5),
        ] {
            let projection = Projection::Perspective {
                tan_half_fov: (0.5 * fov).to_radians().tan(),
            };
            let c = Camera::new(
                pos,
                DVec3::new(31.5, 20.0, 31.5),
                DVec3::Y,
                projection,
                w,
                h,
            )
            .unwrap();
            for y in [0.0, 0.5, 17.25, h as f64 - 0.5, h as f64] {
                for x0 in (0..w + 8).step_by(8) {
                    let xs: [f64; 8] = std::array::from_fn(|l| (x0 + l as u32) as f64 + 0.5);
                    let d = c.directions(&xs, y).unwrap();
                    for (l, &x) in xs.iter().enumerate() {
                        let (o, want) = c.ray(x, y);
                        assert_eq!(o, c.position);
                        let got = DVec3::new(d[0][l], d[1][l], d[2][l]);
                        assert_eq!(
                            got.to_array().map(f64::to_bits),
                            want.to_array().map(f64::to_bits)
                        );
                    }
                }
            }
            let ortho = Camera {
                projection: Projection::Orthographic { half_height: 3.0 },
                ..c
            };
            assert!(ortho.directions(&[0.5; 4], 0.5).is_none());
        }
    }

    #[test]
    fn spec_frame_and_centre_ray() {
        let c = Camera::new(
            DVec3::new(31.5, 31.5, -150.0),
            DVec3::new(31.5, 31.5, 31.5),
            DVec3::Y,
            Projection::Perspective {
                tan_half_fov: (10f64).to_radians().tan(),
            },
            512,
            512,
        )
        .unwrap();
        assert_eq!(c.right, DVec3::new(-1.0, 0.0, 0.0));
        assert_eq!(c.up, DVec3::Y);
        let (o, d) = c.ray(256.0, 256.0);
        assert_eq!(o, c.position);
        assert!((d - DVec3::Z).length() < 1e-15);
        // Top-left pixel centre looks up and to the camera's right (-x).
        let (_, d) = c.ray(0.5, 0.5);
        assert!(d.y > 0.0 && d.x > 0.0);
    }

    #[test]
    fn orthographic_offsets_origin() {
        let c = Camera::new(
            DVec3::ZERO,
            DVec3::Z,
            DVec3::Y,
            Projection::Orthographic { half_height: 5.0 },
            200,
            100,
        )
        .unwrap();
        let (o, d) = c.ray(200.0, 0.0);
        assert_eq!(d, DVec3::Z);
        assert!((o - DVec3::new(-10.0, 5.0, 0.0)).length() < 1e-12);
    }

    #[test]
    fn degenerate_cameras_are_errors() {
        let p = Projection::Perspective { tan_half_fov: 0.5 };
        assert_eq!(
            Camera::new(DVec3::ONE, DVec3::ONE, DVec3::Y, p, 4, 4),
            Err(CameraError::NoDirection)
        );
        assert_eq!(
            Camera::new(DVec3::ZERO, DVec3::Y, DVec3::Y, p, 4, 4),
            Err(CameraError::UpParallel)
        );
        assert!(matches!(
            Camera::new(
                DVec3::ZERO,
                DVec3::Z,
                DVec3::Y,
                Projection::Orthographic { half_height: 0.0 },
                4,
                4
            ),
            Err(CameraError::BadHeight(_))
        ));
        assert_eq!(
            Camera::new(DVec3::NAN, DVec3::Z, DVec3::Y, p, 4, 4),
            Err(CameraError::NotFinite("position"))
        );
        // Finite ends an infinite distance apart; an orthographic view whose
        // corners leave the f64 range.
        assert_eq!(
            Camera::new(DVec3::splat(-1e308), DVec3::splat(1e308), DVec3::Y, p, 4, 4),
            Err(CameraError::TooFar {
                what: "position",
                value: -1e308
            })
        );
        // One far coordinate, the others near: the distance alone squares
        // past f64 even though no component is infinite, so the check is
        // on each coordinate, and the message gives the limit.
        let e = Camera::new(
            DVec3::new(31.5, 31.5, -1e307),
            DVec3::splat(31.5),
            DVec3::Y,
            p,
            4,
            4,
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            "position must lie within ±1e150 of the origin on each axis (further out the camera's distances overflow), got -1e307"
        );
        let wide = Projection::Orthographic { half_height: 1e308 };
        assert_eq!(
            Camera::new(DVec3::X, DVec3::ZERO, DVec3::Y, wide, 8, 4),
            Err(CameraError::ViewOverflow)
        );
    }
}
