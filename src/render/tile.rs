//! One tile through the pipeline: the render loop, reading like the algorithm.

use std::time::{Duration, Instant};

use bumpalo::Bump;
use bumpalo::collections::Vec as BVec;

use super::context::Ctx;
use super::packet::Rays;
use super::stages::{entry, generate, record, refract, solve, traverse};
use super::stats::{Counters, Stage, StageTimes};
use super::trace::{Span, TileTrace};
use crate::film::TileTarget;
use crate::filter::coeffs::Coefficient;

/// A rectangle of pixels `[x0, x1) × [y0, y1)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tile {
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
}

impl Tile {
    pub fn width(&self) -> u32 {
        self.x1 - self.x0
    }
    pub fn height(&self) -> u32 {
        self.y1 - self.y0
    }
    pub fn pixels(&self) -> usize {
        (self.width() * self.height()) as usize
    }
    /// The common pixels of two rectangles, if any.
    pub fn intersect(&self, o: &Tile) -> Option<Tile> {
        let t = Tile {
            x0: self.x0.max(o.x0),
            y0: self.y0.max(o.y0),
            x1: self.x1.min(o.x1),
            y1: self.y1.min(o.y1),
        };
        (t.x0 < t.x1 && t.y0 < t.y1).then_some(t)
    }
    pub fn contains(&self, x: u32, y: u32) -> bool {
        (self.x0..self.x1).contains(&x) && (self.y0..self.y1).contains(&y)
    }
}

/// The pixels one work item covers: a rectangle, or an explicit sorted list
/// of pixel indices (the second, adaptive pass of PRSS).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Region {
    Rect(Tile),
    List(Vec<u32>),
}

impl Region {
    pub fn pixels(&self) -> usize {
        match self {
            Region::Rect(t) => t.pixels(),
            Region::List(l) => l.len(),
        }
    }

    /// Image pixel indices, in the region's order.
    pub fn for_each_pixel(&self, width: u32, mut f: impl FnMut(u32, u32)) {
        match self {
            Region::Rect(t) => {
                for py in t.y0..t.y1 {
                    for px in t.x0..t.x1 {
                        f(px, py);
                    }
                }
            }
            Region::List(l) => {
                for &p in l {
                    f(p % width, p / width);
                }
            }
        }
    }
}

/// How many rays a pixel gets, where, and with what colour weight.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Sampling {
    /// The pixel-centre ray only (colour weight 1).
    Centre,
    /// `n × n` rays on a regular grid; `centre` also traces the pixel-centre
    /// ray for the hit-position image (shared when `n` is odd).
    Grid { n: u32, centre: bool },
    /// `n × n` strata with one seeded random ray each.
    Jitter { n: u32, seed: u64, centre: bool },
}

/// Row-major tiles of `size` covering a `width × height` image.
pub fn tiles(width: u32, height: u32, size: u32) -> Vec<Tile> {
    let mut out = Vec::new();
    for y0 in (0..height).step_by(size as usize) {
        for x0 in (0..width).step_by(size as usize) {
            out.push(Tile {
                x0,
                y0,
                x1: (x0 + size).min(width),
                y1: (y0 + size).min(height),
            });
        }
    }
    out
}

/// A rectangle's output slot of the pixel at `row`, `col` of the
/// rectangle: `row << 8 | col`. Tiles are at most 256 pixels a side
/// (`render.tile`), so recording decodes a slot with a shift and a mask,
/// not a division by the tile's width.
#[inline(always)]
pub fn rect_slot(row: u32, col: u32) -> u32 {
    debug_assert!(row < MAX_RECT_SIDE && col < MAX_RECT_SIDE);
    row << 8 | col
}

/// Largest side of a rectangle [`rect_slot`] can address.
pub const MAX_RECT_SIDE: u32 = 256;

/// The row of a rectangle's slot ([`rect_slot`]).
#[inline(always)]
fn slot_row(slot: u32) -> usize {
    (slot >> 8) as usize
}

/// The column of a rectangle's slot ([`rect_slot`]).
#[inline(always)]
fn slot_col(slot: u32) -> usize {
    (slot & 0xFF) as usize
}

/// Where output `slot` of `region` lies in its own buffers (the region's
/// pixel order): a rectangle's row by row, a list's in its order.
#[inline(always)]
fn own_index(region: &Region, slot: u32) -> usize {
    match region {
        Region::Rect(t) => slot_row(slot) * t.width() as usize + slot_col(slot),
        Region::List(_) => slot as usize,
    }
}

/// What a tile produces: its pixels, written into the film in place or kept
/// for it, and what the tile did.
pub struct TileOut<'f> {
    pub region: Region,
    pub pixels: Pixels<'f>,
    pub counters: Counters,
    pub times: StageTimes,
    /// When and on which thread the tile ran, with its stage calls (traced
    /// renders only).
    pub trace: Option<TileTrace>,
}

/// Where a tile writes its pixels.
pub enum Pixels<'f> {
    /// In place, in the film's rows (the first pass's rectangles: no
    /// per-tile buffers to allocate and fault in, and no copy into the
    /// film afterwards).
    Film(TileTarget<'f>),
    /// Buffers of its own in the region's pixel order, for the film to
    /// absorb ([`crate::film::Film::blit`]): lists of pixels re-traced
    /// after the post stage.
    Own(OwnPixels),
}

/// A tile's own pixel buffers, in its region's order.
#[derive(Clone, Debug)]
pub struct OwnPixels {
    pub u: Vec<f32>,
    pub v: Vec<f32>,
    pub events: Vec<f32>,
    /// `None` when the tile records no colours (a post stage colours the
    /// film from the hits), so none are zeroed here or copied to the film.
    pub color: Option<Vec<[f32; 3]>>,
}

impl<'f> TileOut<'f> {
    /// A tile writing `region` into `target`, its rectangle of the film.
    pub fn in_film(region: Region, mut target: TileTarget<'f>) -> TileOut<'f> {
        target.clear();
        TileOut::with(region, Pixels::Film(target))
    }

    /// A tile keeping `region`'s pixels (and colours, with `colours`).
    pub fn owning(region: Region, colours: bool) -> TileOut<'f> {
        let n = region.pixels();
        let own = OwnPixels {
            u: vec![f32::NAN; n],
            v: vec![f32::NAN; n],
            events: vec![0.0; n],
            color: colours.then(|| vec![[0.0; 3]; n]),
        };
        TileOut::with(region, Pixels::Own(own))
    }

    /// A tile of `region` writing `pixels`: rectangles at most
    /// [`MAX_RECT_SIDE`] a side, whose slots [`rect_slot`] can address.
    fn with(region: Region, pixels: Pixels<'f>) -> TileOut<'f> {
        if let Region::Rect(t) = &region {
            assert!(
                t.width() <= MAX_RECT_SIDE && t.height() <= MAX_RECT_SIDE,
                "rectangles are at most {MAX_RECT_SIDE} pixels a side"
            );
        }
        TileOut {
            region,
            pixels,
            counters: Counters::default(),
            times: StageTimes::default(),
            trace: None,
        }
    }

    /// Whether the tile records colours.
    pub fn records_colours(&self) -> bool {
        match &self.pixels {
            Pixels::Film(t) => t.colours(),
            Pixels::Own(o) => o.color.is_some(),
        }
    }

    /// Writes the hit position and event count of the pixel at `slot`.
    #[inline(always)]
    pub fn set_hit(&mut self, slot: u32, u: f32, v: f32, events: f32) {
        match &mut self.pixels {
            Pixels::Film(t) => t.set_hit(slot_row(slot), slot_col(slot), [u, v, events]),
            Pixels::Own(o) => {
                let k = own_index(&self.region, slot);
                o.u[k] = u;
                o.v[k] = v;
                o.events[k] = events;
            }
        }
    }

    /// Adds `weight · color` to the pixel at `slot` (tiles recording
    /// colours only).
    #[inline(always)]
    pub fn add_color(&mut self, slot: u32, weight: f32, color: [f32; 3]) {
        match &mut self.pixels {
            Pixels::Film(t) => t.add_color(slot_row(slot), slot_col(slot), weight, color),
            Pixels::Own(o) => {
                let k = own_index(&self.region, slot);
                if let Some(c) = &mut o.color {
                    for i in 0..3 {
                        c[k][i] += weight * color[i];
                    }
                }
            }
        }
    }
}

/// Runs one stage and charges its time (and, when tracing, records the call).
macro_rules! stage {
    ($times:expr, $stage:expr, $call:expr) => {{
        let start = Instant::now();
        let r = $call;
        $times.add($stage, start, start.elapsed());
        r
    }};
}

/// Per-stage times of a tile, and its stage calls when the render is traced.
struct Recorder {
    times: StageTimes,
    spans: Option<Vec<Span>>,
}

impl Recorder {
    #[inline]
    fn add(&mut self, stage: Stage, start: Instant, dur: Duration) {
        self.times.add(stage, dur);
        if let Some(s) = &mut self.spans {
            s.push(Span { stage, start, dur });
        }
    }
}

/// Traces every ray of `out`'s region sampled per `sampling` into `out`,
/// recording the backdrop's colours only where it keeps them (a post stage
/// that colours the film from the hit image replaces them all). Scratch
/// comes from `bump`, which the caller resets between tiles; `traced`
/// records when and where the tile and each stage call ran
/// ([`TileOut::trace`]). Never inlined: one call per tile costs nothing,
/// and profilers get a stable anchor for a tile's work.
#[inline(never)]
pub fn render_tile<'f, const S: usize, T: Coefficient>(
    ctx: &Ctx<T>,
    mut out: TileOut<'f>,
    sampling: Sampling,
    bump: &Bump,
    traced: bool,
) -> TileOut<'f> {
    let tile_start = traced.then(Instant::now);
    let mut counters = Counters::default();
    let mut times = Recorder {
        times: StageTimes::default(),
        spans: traced.then(Vec::new),
    };
    let c = &mut counters;
    let n = out.region.pixels() * generate::rays_per_pixel(sampling);
    let marches = ctx.traversal() == crate::scene::Traversal::Step;
    let mut rays = Rays::with_capacity_in(n, marches, bump);
    let mut primary = BVec::with_capacity_in(n, bump);
    let mut runs = BVec::new_in(bump);
    let mut traverse_q = BVec::with_capacity_in(n, bump);
    let mut solve_q = BVec::with_capacity_in(n, bump);
    let mut refract_q = BVec::with_capacity_in(n, bump);
    let mut record_q = BVec::with_capacity_in(n, bump);

    stage!(
        times,
        Stage::Generate,
        generate::generate(
            ctx,
            &out.region,
            sampling,
            &mut rays,
            &mut primary,
            &mut runs
        )
    );
    stage!(
        times,
        Stage::Entry,
        entry::entry::<S, _>(
            ctx,
            &mut rays,
            &primary,
            &runs,
            &mut traverse_q,
            &mut record_q,
            &mut out,
            c,
            bump
        )
    );
    while !traverse_q.is_empty() {
        stage!(
            times,
            Stage::Traverse,
            traverse::traverse::<S, _>(ctx, &mut rays, &traverse_q, &mut solve_q, &mut record_q, c)
        );
        traverse_q.clear();
        stage!(
            times,
            Stage::Solve,
            solve::solve::<S, _>(ctx, &mut rays, &solve_q, &mut refract_q, &mut traverse_q, c)
        );
        solve_q.clear();
        stage!(
            times,
            Stage::Refract,
            refract::refract::<S, _>(
                ctx,
                &mut rays,
                &refract_q,
                &mut traverse_q,
                &mut record_q,
                c
            )
        );
        refract_q.clear();
    }
    stage!(times, Stage::Record, {
        if generate::rays_per_pixel(sampling) > 1 {
            // A pixel's colour sums its rays, which reach this queue in the
            // order they finished (by round, and by how walks paired up,
            // which depends on the tile): summed in the order they were
            // generated instead, the colour is the same bits for any tile
            // size.
            record_q.sort_unstable();
        }
        record::record(ctx, &rays, &record_q, &mut out, c)
    });
    out.counters = counters;
    out.times = times.times;
    if let (Some(start), Some(spans)) = (tile_start, times.spans) {
        out.trace = Some(TileTrace {
            thread: rayon::current_thread_index(),
            start,
            end: Instant::now(),
            spans,
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::prepare::Prepared;
    use crate::render::testing::small_scene;
    use crate::volume::LoadOptions;

    /// The first pass's pixel-centre rays, generated as runs and placed in
    /// lanes (the rays the approach bound sends straight to the backdrop
    /// recorded without entering the packet), give bit for bit what the
    /// same pixels give one ray at a time (a pixel list takes that path):
    /// hits, event counts, colours and counters, over every traversal, with
    /// and without the approach bound, for a tile that straddles the object
    /// and one whose rays all go straight.
    #[test]
    fn runs_record_what_rays_one_at_a_time_record() {
        for traversal in ["step", "dda", "octree", "distance"] {
            for approach in ["true", "false"] {
                let sets = [
                    "image.width=40".to_string(),
                    "image.height=36".to_string(),
                    format!("render.traversal={traversal:?}"),
                    format!("render.skip_empty_approach={approach}"),
                ];
                let scene = small_scene(127.5, &sets);
                let prep = Prepared::for_scene(&scene, &LoadOptions::default()).unwrap();
                crate::with_field!(&prep.field, f => {
                    let ctx = Ctx::new(&scene, &prep, f.as_ref());
                    let bump = Bump::new();
                    // Across the object (rows of 13: a run of 5 ends each),
                    // and in a corner where every ray goes straight.
                    for tile in [Tile { x0: 11, y0: 9, x1: 24, y1: 30 }, Tile { x0: 0, y0: 0, x1: 8, y1: 3 }] {
                        let mut list = Vec::new();
                        Region::Rect(tile).for_each_pixel(scene.width, |x, y| list.push(y * scene.width + x));
                        let run = |region| {
                            let out = TileOut::owning(region, true);
                            render_tile::<4, _>(&ctx, out, Sampling::Centre, &bump, false)
                        };
                        let (a, b) = (run(Region::Rect(tile)), run(Region::List(list)));
                        let (Pixels::Own(pa), Pixels::Own(pb)) = (&a.pixels, &b.pixels) else {
                            unreachable!("owning tiles")
                        };
                        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                        let what = format!("{traversal} approach {approach} {tile:?}");
                        assert_eq!(bits(&pa.u), bits(&pb.u), "{what}");
                        assert_eq!(bits(&pa.v), bits(&pb.v), "{what}");
                        assert_eq!(bits(&pa.events), bits(&pb.events), "{what}");
                        assert_eq!(pa.color, pb.color, "{what}");
                        assert_eq!(a.counters, b.counters, "{what}");
                        assert!(pa.u.iter().any(|u| u.is_finite()), "{what}");
                    }
                });
            }
        }
    }

    #[test]
    fn tiles_cover_the_image_once() {
        for (w, h, size) in [(37, 20, 16), (1, 1, 16), (64, 64, 16), (5, 300, 7)] {
            let mut covered = vec![0u8; w as usize * h as usize];
            for t in tiles(w, h, size) {
                for y in t.y0..t.y1 {
                    for x in t.x0..t.x1 {
                        covered[(y * w + x) as usize] += 1;
                    }
                }
            }
            assert!(
                covered.iter().all(|&c| c == 1),
                "{w}x{h} in tiles of {size}"
            );
        }
        let t = tiles(37, 20, 16);
        assert_eq!(t.len(), 3 * 2);
        assert_eq!(
            t[2],
            Tile {
                x0: 32,
                y0: 0,
                x1: 37,
                y1: 16
            }
        );
    }
}
