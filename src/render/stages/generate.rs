//! Stage 1: primary rays for every pixel of the tile.

use super::super::context::Ctx;
use super::super::packet::{Queue, Rays};
use super::super::tile::Tile;

/// Pushes the pixel-centre ray of each pixel (SPEC: through `(px+0.5, py+0.5)`).
pub fn generate(ctx: &Ctx, tile: &Tile, rays: &mut Rays, out: &mut Queue) {
    let cam = &ctx.scene.camera;
    let width = ctx.scene.width;
    for py in tile.y0..tile.y1 {
        for px in tile.x0..tile.x1 {
            let (o, d) = cam.ray(px as f64 + 0.5, py as f64 + 0.5);
            out.push(rays.push(py * width + px, 1.0, true, o, d));
        }
    }
}
