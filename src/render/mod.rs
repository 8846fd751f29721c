//! The renderer: rays as structure-of-arrays packets per tile, moved through
//! staged queues (see [`stages`]), tiles in parallel.
//!
//! ```text
//! for each tile (in parallel):
//!     generate → entry → { traverse → solve → refract }* → record
//! film ← tiles (in tile order)
//! ```
//!
//! Determinism: every pixel's value is computed by the same arithmetic on the
//! same inputs whichever thread runs its tile, counters are integer sums, and
//! tiles are assembled in a fixed order, so the output is the same bits for
//! any thread count.

pub mod context;
pub mod packet;
pub mod stages;
pub mod stats;
pub mod tile;

use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use bumpalo::Bump;
use rayon::prelude::*;

pub use context::Ctx;
pub use stats::{Counters, PrepareTimes, RenderStats};

use crate::film::Film;
pub use crate::prepare::Prepared;
use crate::scene::{Scene, SceneError};
use crate::volume::LoadOptions;
use crate::with_support;

/// Loads, prepares and renders a scene in one call (on the current rayon pool).
pub fn render_scene(scene: &Scene) -> Result<Frame, SceneError> {
    let prep = Prepared::for_scene(scene, &LoadOptions::default())?;
    Ok(render(scene, &prep, None))
}

/// A rendered frame and how it was made.
pub struct Frame {
    pub film: Film,
    pub stats: RenderStats,
}

/// Renders `scene` with `prep` on the current rayon pool. `progress`, when
/// given, counts finished tiles (for a progress bar).
pub fn render(scene: &Scene, prep: &Prepared, progress: Option<&AtomicUsize>) -> Frame {
    let ctx = Ctx::new(scene, prep);
    let tiles = tile::tiles(scene.width, scene.height, scene.render.tile);
    let start = Instant::now();
    let outs: Vec<tile::TileOut> = tiles
        .par_iter()
        .map_init(Bump::new, |bump, &t| {
            bump.reset();
            let out = with_support!(ctx.field.kernel().support(), S => tile::render_tile::<S>(&ctx, t, bump));
            if let Some(p) = progress {
                p.fetch_add(1, Ordering::Relaxed);
            }
            out
        })
        .collect();
    let film_start = Instant::now();
    let mut film = Film::new(scene.width, scene.height);
    let mut stats = RenderStats {
        threads: rayon::current_num_threads(),
        width: scene.width,
        height: scene.height,
        prepare: prep.times,
        ..Default::default()
    };
    for o in &outs {
        film.blit(o);
        stats.counters.add(&o.counters);
        stats.stage_times.merge(&o.times);
    }
    stats
        .stage_times
        .add(stats::Stage::Film, film_start.elapsed());
    stats.wall = start.elapsed();
    Frame { film, stats }
}
