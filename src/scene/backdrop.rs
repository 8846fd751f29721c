//! The planar backdrop: where refracted rays land, and what they see there.
//!
//! Coordinates follow SPEC.md: `u = (p - center)·u_axis`,
//! `v = (p - center)·v_axis`, `v_axis = cross(normal, u_axis)`. A photograph is
//! placed centred on `center`, `width` world units wide, reading upright when
//! seen from the side the normal points to: image columns grow with `u` and
//! rows grow with `-v` (row 0 at `v = +height/2`).

use glam::DVec3;

/// What the backdrop shows.
#[derive(Clone, Debug)]
pub enum Pattern {
    /// Squares of `size`: `colors[0]` where `floor(u/s) + floor(v/s)` is even.
    Checker { size: f64, colors: [[f32; 3]; 2] },
    /// A photograph, bilinearly sampled; `outside` beyond its edges.
    Image(Texture),
}

/// An RGB image in `[0, 1]`, row 0 at the top.
#[derive(Clone, Debug)]
pub struct Texture {
    pub width_px: usize,
    pub height_px: usize,
    pub pixels: Vec<[f32; 3]>,
    /// World width covered by the image; the height follows its aspect ratio.
    pub world_width: f64,
    pub outside: [f32; 3],
}

impl Texture {
    pub fn world_height(&self) -> f64 {
        self.world_width * self.height_px as f64 / self.width_px as f64
    }

    /// Bilinear lookup at backdrop coordinates.
    pub fn sample(&self, u: f64, v: f64) -> [f32; 3] {
        let (w, h) = (self.world_width, self.world_height());
        // Continuous pixel coordinates with pixel centres at +0.5.
        let x = (u / w + 0.5) * self.width_px as f64 - 0.5;
        let y = (0.5 - v / h) * self.height_px as f64 - 0.5;
        if !(x > -1.0 && y > -1.0 && x < self.width_px as f64 && y < self.height_px as f64) {
            return self.outside;
        }
        let (x0, y0) = (
            crate::filter::kernel::floor_i64(x) as f64,
            crate::filter::kernel::floor_i64(y) as f64,
        );
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let clampx = |i: f64| (i.max(0.0) as usize).min(self.width_px - 1);
        let clampy = |i: f64| (i.max(0.0) as usize).min(self.height_px - 1);
        let (xa, xb, ya, yb) = (clampx(x0), clampx(x0 + 1.0), clampy(y0), clampy(y0 + 1.0));
        let p = |xi: usize, yi: usize| self.pixels[yi * self.width_px + xi];
        let (a, b, c, d) = (p(xa, ya), p(xb, ya), p(xa, yb), p(xb, yb));
        std::array::from_fn(|k| {
            let top = a[k] + (b[k] - a[k]) * fx;
            let bot = c[k] + (d[k] - c[k]) * fx;
            top + (bot - top) * fy
        })
    }
}

/// The backdrop plane and its pattern.
#[derive(Clone, Debug)]
pub struct Backdrop {
    pub center: DVec3,
    pub normal: DVec3,
    pub u_axis: DVec3,
    pub v_axis: DVec3,
    pub pattern: Pattern,
}

impl Backdrop {
    /// The ray parameter where the ray meets the plane, if it does with
    /// `t > 0`. The plane is opaque from either side: a ray stops at the
    /// first point of its path on it, before or inside the volume too.
    #[inline]
    pub fn plane_t(&self, origin: DVec3, dir: DVec3) -> Option<f64> {
        let denom = dir.dot(self.normal);
        if denom == 0.0 || !denom.is_finite() {
            return None;
        }
        let t = (self.center - origin).dot(self.normal) / denom;
        (t > 0.0 && t.is_finite()).then_some(t)
    }

    /// Backdrop coordinates of the ray's hit, if it hits with `t > 0`.
    #[inline]
    pub fn hit(&self, origin: DVec3, dir: DVec3) -> Option<(f64, f64)> {
        let t = self.plane_t(origin, dir)?;
        let p = origin + t * dir - self.center;
        Some((p.dot(self.u_axis), p.dot(self.v_axis)))
    }

    /// Colour at backdrop coordinates.
    #[inline]
    pub fn color(&self, u: f64, v: f64) -> [f32; 3] {
        match &self.pattern {
            Pattern::Checker { size, colors } => {
                use crate::filter::kernel::floor_fast;
                // Integer parity: no libm floor or fmod in the hottest lookup.
                let parity = floor_fast(u / size).wrapping_add(floor_fast(v / size)) & 1;
                if parity == 0 { colors[0] } else { colors[1] }
            }
            Pattern::Image(tex) => tex.sample(u, v),
        }
    }

    /// Size of one checker square (backdrop units), for error reports.
    pub fn checker_size(&self) -> Option<f64> {
        match &self.pattern {
            Pattern::Checker { size, .. } => Some(*size),
            Pattern::Image(_) => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn checker() -> Backdrop {
        Backdrop {
            center: DVec3::new(0.0, 0.0, 10.0),
            normal: DVec3::new(0.0, 0.0, -1.0),
            u_axis: DVec3::X,
            v_axis: DVec3::new(0.0, 0.0, -1.0).cross(DVec3::X),
            pattern: Pattern::Checker {
                size: 2.0,
                colors: [[1.0; 3], [0.0; 3]],
            },
        }
    }

    #[test]
    fn hit_coordinates_follow_spec() {
        let b = checker();
        assert_eq!(b.v_axis, DVec3::new(0.0, -1.0, 0.0));
        let (u, v) = b.hit(DVec3::new(1.0, 2.0, 0.0), DVec3::Z).unwrap();
        assert_eq!((u, v), (1.0, -2.0));
        assert!(b.hit(DVec3::ZERO, -DVec3::Z).is_none());
        assert!(b.hit(DVec3::ZERO, DVec3::X).is_none());
    }

    #[test]
    fn checker_parity() {
        let b = checker();
        assert_eq!(b.color(0.5, 0.5), [1.0; 3]);
        assert_eq!(b.color(2.5, 0.5), [0.0; 3]);
        assert_eq!(b.color(-0.5, 0.5), [0.0; 3]);
        assert_eq!(b.color(-0.5, -0.5), [1.0; 3]);
    }

    #[test]
    fn texture_placement_is_upright_and_bilinear() {
        let tex = Texture {
            width_px: 2,
            height_px: 2,
            // top-left red, top-right green, bottom-left blue, bottom-right white
            pixels: vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0; 3]],
            world_width: 4.0,
            outside: [0.5; 3],
        };
        assert_eq!(tex.sample(-1.0, 1.0), [1.0, 0.0, 0.0]);
        assert_eq!(tex.sample(1.0, -1.0), [1.0; 3]);
        assert_eq!(tex.sample(0.0, 1.0), [0.5, 0.5, 0.0]);
        assert_eq!(tex.sample(5.0, 0.0), [0.5; 3]);
    }
}
