//! Stage 1: primary rays for every pixel of the region.
//!
//! The pixel-centre ray goes through `(px+0.5, py+0.5)` (SPEC.md) and writes
//! the hit-position image; supersampling adds `n×n` rays per pixel on a grid or
//! jittered within strata, each carrying colour weight `1/n²`. Jitter comes
//! from a counter-based generator keyed by (seed, pixel, sample), so it is the
//! same for any tile size or thread count.

use bumpalo::collections::Vec as BVec;

use super::super::context::Ctx;
use super::super::packet::{Queue, Rays};
use super::super::tile::{Region, Sampling, Tile, rect_slot};
use crate::filter::coeffs::Coefficient;
use crate::phantom::{mix64, uniform};
use crate::scene::{Camera, Projection};
use crate::simd::Isa;

/// Rays traced per pixel (capacity planning).
pub fn rays_per_pixel(sampling: Sampling) -> usize {
    match sampling {
        Sampling::Centre => 1,
        Sampling::Grid { n, centre } | Sampling::Jitter { n, centre, .. } => {
            (n * n) as usize + centre as usize
        }
    }
}

/// Pixel-centre rays of up to [`RUN`] consecutive pixels of a row, from the
/// camera: not yet in the packet, so that the entry stage can record those
/// that go straight to the backdrop without their ever entering it.
pub struct Run {
    /// The first pixel's image index and output slot (the others follow).
    pub pixel: u32,
    pub slot: u32,
    /// Pixels in the run.
    pub len: usize,
    /// Unit directions, `dir[axis][lane]` (lanes past `len` unused).
    pub dir: [[f64; RUN]; 3],
}

/// The region's primary rays: into `rays` (their indices on `out`), or,
/// for the pixel centres of a rectangle under a perspective camera (the
/// usual first pass), as [`Run`]s on `runs` for the entry stage to place.
pub fn generate<'a, T: Coefficient>(
    ctx: &Ctx<T>,
    region: &Region,
    sampling: Sampling,
    rays: &mut Rays,
    out: &mut Queue,
    runs: &mut BVec<'a, Run>,
) {
    let cam = &ctx.scene.camera;
    let width = ctx.scene.width;
    if let (Sampling::Centre, Region::Rect(tile), Projection::Perspective { .. }) =
        (sampling, region, cam.projection)
    {
        crate::with_isa!(Isa::current(), _L, _M => centre_runs(cam, *tile, width, runs));
        return;
    }
    // Pixels come in the region's order; a rectangle's slot is the pixel's
    // row and column in it (`rect_slot`), a list's its position.
    let mut next_slot = 0;
    region.for_each_pixel(width, |px, py| {
        let slot = match region {
            Region::Rect(t) => rect_slot(py - t.y0, px - t.x0),
            Region::List(_) => next_slot,
        };
        let pixel = py * width + px;
        next_slot += 1;
        let (x, y) = (px as f64, py as f64);
        let mut push = |ox: f64, oy: f64, weight: f32, centre: bool| {
            let (o, d) = cam.ray(x + ox, y + oy);
            out.push(rays.push((pixel, slot), weight, centre, o, d));
        };
        match sampling {
            Sampling::Centre => push(0.5, 0.5, 1.0, true),
            Sampling::Grid { n, centre } => {
                let w = 1.0 / (n * n) as f32;
                // With odd n the middle grid ray is the pixel-centre ray.
                let shared = n % 2 == 1;
                if centre && !shared {
                    push(0.5, 0.5, 0.0, true);
                }
                for j in 0..n {
                    for i in 0..n {
                        let is_mid = shared && i == n / 2 && j == n / 2;
                        let (ox, oy) = ((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
                        push(ox, oy, w, centre && is_mid);
                    }
                }
            }
            Sampling::Jitter { n, seed, centre } => {
                let w = 1.0 / (n * n) as f32;
                if centre {
                    push(0.5, 0.5, 0.0, true);
                }
                let key = mix64(seed ^ mix64(pixel as u64));
                for j in 0..n {
                    for i in 0..n {
                        let k = 2 * (j * n + i) as u64;
                        let (ju, jv) = (uniform(key, k), uniform(key, k + 1));
                        push(
                            (i as f64 + ju) / n as f64,
                            (j as f64 + jv) / n as f64,
                            w,
                            false,
                        );
                    }
                }
            }
        }
    });
    rays.complete();
}

/// Pixel-centre rays of a rectangle under a perspective camera: each row in
/// runs of [`RUN`] pixels whose directions come from
/// [`Camera::directions`] in vector lanes, bitwise those of
/// [`Camera::ray`].
#[inline(always)]
fn centre_runs(cam: &Camera, tile: Tile, width: u32, runs: &mut BVec<Run>) {
    runs.reserve(tile.height() as usize * tile.width().div_ceil(RUN as u32) as usize);
    for py in tile.y0..tile.y1 {
        let y = py as f64 + 0.5;
        for x0 in (tile.x0..tile.x1).step_by(RUN) {
            let xs: [f64; RUN] = std::array::from_fn(|l| (x0 + l as u32) as f64 + 0.5);
            runs.push(Run {
                pixel: py * width + x0,
                slot: rect_slot(py - tile.y0, x0 - tile.x0),
                len: RUN.min((tile.x1 - x0) as usize),
                dir: cam.directions(&xs, y).expect("a perspective camera"),
            });
        }
    }
}

/// Pixels per [`Run`]: one AVX-512 vector of `f64`.
pub const RUN: usize = 8;
