//! The renderer: rays as structure-of-arrays packets per tile, moved through
//! staged queues (see [`stages`]), tiles in parallel.
//!
//! ```text
//! for each tile (in parallel), into its rectangle of the film:
//!     generate → entry → { traverse → solve → refract }* → record
//! post stage (PRSS, footprint) over the film
//! ```
//!
//! Determinism: every pixel's value is computed by the same arithmetic on the
//! same inputs whichever thread runs its tile, each tile writes only its own
//! rectangle, and counters are integer sums added in tile order, so the
//! output is the same bits for any thread count.

pub mod context;
pub mod first_hit;
pub mod packet;
pub mod stages;
pub mod stats;
#[cfg(test)]
pub(crate) mod testing;
pub mod tile;
pub mod trace;

use std::cell::RefCell;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use bumpalo::Bump;
use rayon::prelude::*;

pub use context::Ctx;
pub use stats::{Counters, PrepareTimes, RenderStats};
pub use trace::Trace;

use crate::film::{Film, TileTarget, prss};
use crate::filter::Field;
use crate::filter::coeffs::Coefficient;
pub use crate::prepare::Prepared;
use crate::scene::{Scene, SceneError, Supersampling};
use crate::volume::LoadOptions;
use crate::with_support;
use tile::{Region, Sampling};

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
///
/// Real supersampling traces `n×n` rays per pixel in the tile pass. PRSS and
/// footprint filtering trace only pixel-centre rays, then colour the film from
/// the hit positions in a final stage; with the `trace` fallback, the pixels it
/// cannot interpolate get real sub-pixel rays in a second, adaptive pass.
pub fn render(scene: &Scene, prep: &Prepared, progress: Option<&AtomicUsize>) -> Frame {
    render_with(scene, prep, None, progress, None)
}

/// Pixels of apron a windowed render traces around its window when a post
/// stage colours the film: PRSS reads hit-map taps up to 2 pixels away and
/// fits boundaries over `EDGE_RADIUS` = 4, and `blend-trace` marks pixels
/// from a ring around that; 8 covers all of it (the window's pixels are then
/// bitwise those of the whole frame, tested).
pub const POST_APRON: u32 = 8;

/// Renders only the pixels of `window` (image coordinates): one part of a
/// frame split across processes or machines. The film covers the window
/// (with its place in the image, see [`Film`]), bitwise equal to the same
/// pixels of a whole-frame render; `snell merge` joins the parts.
pub fn render_window(
    scene: &Scene,
    prep: &Prepared,
    window: tile::Tile,
    progress: Option<&AtomicUsize>,
    trace: Option<&mut Trace>,
) -> Frame {
    render_with(scene, prep, Some(window), progress, trace)
}

/// The tiles a render of `window` (the whole image when `None`) traces in
/// its first pass, for progress bars.
pub fn tile_count(scene: &Scene, window: Option<tile::Tile>) -> usize {
    let traced = traced_window(scene, window);
    tile::tiles(scene.width, scene.height, scene.render.tile)
        .into_iter()
        .filter(|t| t.intersect(&traced).is_some())
        .count()
}

fn post_mode(scene: &Scene) -> Option<prss::Mode> {
    match scene.render.supersampling {
        Supersampling::Prss => Some(prss::Mode::Prss),
        Supersampling::Footprint => Some(prss::Mode::Footprint),
        _ => None,
    }
}

/// The size of the film a render of `window` (the whole image for `None`)
/// holds: the window and its apron ([`traced_window`]).
pub fn traced_size(scene: &Scene, window: Option<tile::Tile>) -> (u32, u32) {
    let t = traced_window(scene, window);
    (t.width(), t.height())
}

/// The pixels a render of `window` traces: the window and, when a post stage
/// reads neighbours, its apron, within the image.
fn traced_window(scene: &Scene, window: Option<tile::Tile>) -> tile::Tile {
    let image = tile::Tile {
        x0: 0,
        y0: 0,
        x1: scene.width,
        y1: scene.height,
    };
    let Some(w) = window else { return image };
    let apron = if post_mode(scene).is_some() {
        POST_APRON
    } else {
        0
    };
    tile::Tile {
        x0: w.x0.saturating_sub(apron),
        y0: w.y0.saturating_sub(apron),
        x1: w.x1.saturating_add(apron).min(image.x1),
        y1: w.y1.saturating_add(apron).min(image.y1),
    }
}

/// [`render`], recording a timeline of every tile and stage into `trace`
/// (see [`trace`]).
pub fn render_traced(
    scene: &Scene,
    prep: &Prepared,
    progress: Option<&AtomicUsize>,
    trace: &mut Trace,
) -> Frame {
    render_with(scene, prep, None, progress, Some(trace))
}

fn render_with(
    scene: &Scene,
    prep: &Prepared,
    window: Option<tile::Tile>,
    progress: Option<&AtomicUsize>,
    trace: Option<&mut Trace>,
) -> Frame {
    crate::with_field!(&prep.field, f => render_field(scene, prep, f.as_ref(), window, progress, trace))
}

/// [`render_with`] over the prepared field in its storage `T`.
fn render_field<T: Coefficient>(
    scene: &Scene,
    prep: &Prepared,
    field: &Field<T>,
    window: Option<tile::Tile>,
    progress: Option<&AtomicUsize>,
    mut trace: Option<&mut Trace>,
) -> Frame {
    let traced = trace.is_some();
    let ctx = Ctx::new(scene, prep, field);
    let rs = &scene.render;
    let n = rs.samples;
    let first = match rs.supersampling {
        Supersampling::None | Supersampling::Prss | Supersampling::Footprint => Sampling::Centre,
        Supersampling::Grid => Sampling::Grid { n, centre: true },
        Supersampling::Jitter => Sampling::Jitter {
            n,
            seed: rs.seed,
            centre: true,
        },
    };
    let traced_rect = traced_window(scene, window);
    let rects: Vec<tile::Tile> = tile::tiles(scene.width, scene.height, rs.tile)
        .into_iter()
        .filter_map(|t| t.intersect(&traced_rect))
        .collect();
    let start = Instant::now();
    // A post stage colours the film from the hit image: the first pass
    // records hits only.
    let post = post_mode(scene);
    let mut film = Film::for_tiles(traced_rect, [scene.width, scene.height]);
    let mut stats = RenderStats {
        threads: rayon::current_num_threads(),
        width: scene.width,
        height: scene.height,
        region: window.map(|w| [w.x0, w.y0, w.x1, w.y1]),
        prepare: prep.times,
        ..Default::default()
    };
    // The first pass's tiles write their rectangles of the film in place.
    let targets = film.tile_targets(&rects, post.is_none());
    let tiles = rects
        .iter()
        .zip(targets)
        .map(|(&rect, target)| (Region::Rect(rect), Some(target)))
        .collect();
    let outs = trace_regions(&ctx, tiles, first, false, progress, traced);
    if let Some(t) = trace.as_deref_mut() {
        t.complete(
            "tiles",
            "render",
            trace::MAIN_TID,
            start,
            start.elapsed(),
            serde_json::json!({ "tiles": outs.len() }),
        );
        record_tiles(t, &outs, "primary");
    }
    let film_start = Instant::now();
    add_stats(&mut stats, &outs);
    drop(outs);
    let mut film_time = film_start.elapsed();
    if let Some(t) = trace.as_deref_mut() {
        t.complete(
            "film",
            "render",
            trace::MAIN_TID,
            film_start,
            film_time,
            serde_json::Value::Null,
        );
    }

    if let Some(mode) = post {
        let post_start = Instant::now();
        let settings = prss::PostSettings::new(mode, rs);
        let post = prss::shade(&film, &scene.backdrop, scene.background, &settings);
        film.color = post.color;
        stats.post = Some(post.stats);
        stats
            .stage_times
            .add(stats::Stage::Prss, post_start.elapsed());
        if let Some(t) = trace.as_deref_mut() {
            t.complete(
                "prss",
                "render",
                trace::MAIN_TID,
                post_start,
                post_start.elapsed(),
                serde_json::json!({ "flagged_pixels": post.flagged.len() }),
            );
        }
        // Flagged film pixels as image pixel indices, the apron's dropped.
        let keep = window.unwrap_or(traced_rect);
        let flagged: Vec<u32> = post
            .flagged
            .iter()
            .map(|&p| {
                let (x, y) = (
                    p % film.width + film.origin[0],
                    p / film.width + film.origin[1],
                );
                (x, y)
            })
            .filter(|&(x, y)| keep.contains(x, y))
            .map(|(x, y)| y * scene.width + x)
            .collect();
        if !flagged.is_empty() {
            stats.retraced_pixels = flagged.len() as u64;
            let regions = flagged
                .chunks((rs.tile * rs.tile) as usize)
                .map(|c| (Region::List(c.to_vec()), None))
                .collect();
            let retrace_start = Instant::now();
            let outs = trace_regions(
                &ctx,
                regions,
                Sampling::Grid { n, centre: false },
                true,
                None,
                traced,
            );
            let t = Instant::now();
            for o in &outs {
                film.blit(o, false);
            }
            add_stats(&mut stats, &outs);
            film_time += t.elapsed();
            if let Some(tr) = trace {
                tr.complete(
                    "re-trace",
                    "render",
                    trace::MAIN_TID,
                    retrace_start,
                    t.saturating_duration_since(retrace_start),
                    serde_json::json!({ "regions": outs.len() }),
                );
                record_tiles(tr, &outs, "re-trace");
                tr.complete(
                    "film",
                    "render",
                    trace::MAIN_TID,
                    t,
                    t.elapsed(),
                    serde_json::Value::Null,
                );
            }
        }
    }
    if let Some(w) = window.filter(|&w| w != traced_rect) {
        let t = Instant::now();
        film = film.crop(w);
        film_time += t.elapsed();
    }
    stats.stage_times.add(stats::Stage::Film, film_time);
    stats.wall = start.elapsed();
    Frame { film, stats }
}

thread_local! {
    /// Each thread's tile scratch, reset per tile and kept across tiles and
    /// frames, so that a tile's packets and queues reuse memory already
    /// faulted in.
    static TILE_ARENA: RefCell<Bump> = RefCell::new(Bump::new());
}

/// Traces regions in parallel, each into its rectangle of the film where
/// it has one, else into buffers of its own (with colours if `colours`);
/// results come back in region order.
///
/// Every tile is a task of its own (`with_max_len(1)`), so a thread that
/// runs out of tiles takes them from another thread's share one at a
/// time. By default rayon cuts the tiles into a few runs per thread (four
/// on two threads) and a thread finishes a run it has started alone: on
/// this shared machine, where one core at times ran a third slower, the
/// other finished its 512 tiles of the sphere 14 ms before it (`snell
/// render --trace`, two runs of six), idle for a quarter of the tile pass.
fn trace_regions<'f, T: Coefficient>(
    ctx: &Ctx<T>,
    regions: Vec<(Region, Option<TileTarget<'f>>)>,
    sampling: Sampling,
    colours: bool,
    progress: Option<&AtomicUsize>,
    traced: bool,
) -> Vec<tile::TileOut<'f>> {
    regions
        .into_par_iter()
        .with_max_len(1)
        .map(|(region, target)| {
            let out = match target {
                Some(target) => tile::TileOut::in_film(region, target),
                None => tile::TileOut::owning(region, colours),
            };
            let out = TILE_ARENA.with_borrow_mut(|bump| {
                bump.reset();
                with_support!(ctx.field.kernel().support(), S => tile::render_tile::<S, _>(ctx, out, sampling, bump, traced))
            });
            if let Some(p) = progress {
                p.fetch_add(1, Ordering::Relaxed);
            }
            out
        })
        .collect()
}

/// Adds the tiles' counters and stage times to the stats, in region order.
fn add_stats(stats: &mut RenderStats, outs: &[tile::TileOut]) {
    for o in outs {
        stats.counters.add(&o.counters);
        stats.stage_times.merge(&o.times);
    }
}

/// Adds traced tiles to the timeline (tiles without a trace are skipped).
fn record_tiles(trace: &mut Trace, outs: &[tile::TileOut], pass: &str) {
    for o in outs {
        let Some(t) = &o.trace else { continue };
        let label = match &o.region {
            Region::Rect(r) => format!("tile {},{}", r.x0, r.y0),
            Region::List(l) => format!("pixels {}..", l.first().copied().unwrap_or(0)),
        };
        trace.tile(t, pass, label, o.region.pixels(), &o.counters);
    }
}
