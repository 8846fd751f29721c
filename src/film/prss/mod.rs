//! The final stage: anti-aliasing from the hit-position image alone.
//!
//! Refraction maps the image plane onto the backdrop, `M: (x, y) → (u, v)`,
//! and the hit-position image samples `M` at pixel centres. A pixel's colour
//! should be the backdrop averaged over `M(pixel square)`; one ray per pixel
//! point-samples it instead, which aliases wherever `M` minifies (the sphere's
//! rim, paper Fig. 2). Both modes here reconstruct `M` over the pixel from its
//! neighbours, without tracing another ray:
//!
//! - **PRSS** (the paper, section 4.3): `M` is interpolated between the pixel
//!   and its neighbours ([`PrssMap`]): bilinearly in each quadrant (straight
//!   lines to the 8 neighbours, the paper's intermediate points), by the
//!   biquadratic through the 3×3 neighbourhood, or by Catmull-Rom through the
//!   5×5 one. `n×n` sub-points mapped through it sample the backdrop; their
//!   mean is the pixel (a box filter, like real supersampling's).
//! - **Footprint** (see [`super::footprint`]): the Jacobian of `M` from
//!   central differences maps the pixel's filter onto the backdrop, a
//!   parallelogram (box) or an ellipse (Gaussian, EWA), integrated there.
//!   A side without a consistent neighbour takes the one-sided difference;
//!   an axis with neither side consistent has a zero column (the footprint
//!   collapses to a point sample along it, counted as a nearest quadrant),
//!   whatever the fallback below says of the other modes.
//!
//! Interpolating across a discontinuity of `M` would smear unrelated backdrop
//! regions together, so a neighbour counts only if it reaches the backdrop and
//! crossed the same number of interfaces ([`super::hitmap`]). Missing
//! neighbours are handled per [`PrssFallback`]:
//!
//! - `mirror`: extrapolated linearly from the consistent ones; the whole pixel
//!   keeps the centre's surface.
//! - `blend` (default): like `mirror`, and the pixel is split between its own
//!   surface and its neighbours'. Where the piece indicator of the 9×9
//!   neighbourhood, blurred by a Gaussian, looks like one straight boundary
//!   (value `Φ(d/σ)` with gradient `φ(d/σ)/σ`), each sub-point takes the side
//!   of that line it lies on; otherwise it is shared by the bilinear hats of
//!   the four pixel centres around it (the expected coverage when the
//!   boundary lies anywhere between them). A neighbour's surface is its hit
//!   moved by its own Jacobian; one without a hit shows the background.
//! - `blend-trace`: `blend`, but the boundary pixels no straight boundary
//!   explains (pieces a pixel or two wide), and their boundary neighbours,
//!   are flagged for real sub-pixel rays.
//! - `nearest`: missing neighbours take the centre's hit.
//! - `trace`: every pixel with a missing neighbour, or whose map bends faster
//!   than [`PostSettings::curvature`], is flagged for real sub-pixel rays
//!   (adaptive supersampling, traced by the renderer).
//!
//! Here: the settings, the map's sub-points, the per-pixel paths and the
//! banded pass over the film. Beside it: [`blend`] shares a boundary pixel
//! between its own surface and its neighbours', [`edge`] locates the
//! straight boundary it splits a pixel by, [`one_square`] proves a pixel's
//! map stays in one checker square (its sub-points then need no work), and
//! [`checker`] averages the checkerboard over the sub-points.

use rayon::prelude::*;
use serde::Serialize;

use crate::scene::{Backdrop, FootprintFilter, Pattern, PrssFallback, PrssMap, RenderSettings};

use super::Film;
use super::footprint;
use super::hitmap::HitMap;
use super::interior::{Interior, classify_rows};

mod blend;
mod checker;
mod edge;
mod one_square;

use blend::{Hats, Own, Ring};
use checker::{U, V, checker_average, checker_average_on, checker_parities};
use edge::edge_line;
#[cfg(test)]
pub(super) use one_square::footprint_box;
use one_square::in_one_square;

/// Rows shaded per parallel task ([`shade`]).
const BAND_ROWS: usize = 16;

/// Which reconstruction to use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    Prss,
    Footprint,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PostSettings {
    pub mode: Mode,
    /// Sub-points per axis.
    pub samples: u32,
    /// How PRSS interpolates the hit map.
    pub map: PrssMap,
    pub fallback: PrssFallback,
    /// With the `Trace` fallback, pixels whose map bends more than this many
    /// backdrop features (checker squares, or photo texels) between
    /// neighbours are re-traced too: interpolation would misplace sub-samples.
    pub curvature: f64,
    /// The footprint filter (footprint mode).
    pub footprint: FootprintFilter,
}

impl PostSettings {
    /// The stage's settings from a scene's render settings.
    pub fn new(mode: Mode, r: &RenderSettings) -> PostSettings {
        PostSettings {
            mode,
            samples: r.prss_samples,
            map: r.prss_map,
            fallback: r.prss_fallback,
            curvature: r.prss_curvature,
            footprint: r.footprint,
        }
    }
}

/// What the stage did, for the stats.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct PostStats {
    /// Pixels with a backdrop hit.
    pub pixels: u64,
    /// Quadrants whose neighbours were all consistent.
    pub quadrants_interpolated: u64,
    /// Quadrants completed by linear extrapolation from consistent neighbours.
    pub quadrants_mirrored: u64,
    /// Quadrants completed with the centre hit.
    pub quadrants_nearest: u64,
    /// Pixels that mixed in their neighbours' surfaces (`blend`).
    pub pixels_blended: u64,
    /// Pixels handed to the renderer for real supersampling.
    pub pixels_flagged: u64,
    /// Of those, pixels flagged because the map bends too fast.
    pub pixels_curved: u64,
}

impl PostStats {
    fn add(&mut self, o: &PostStats) {
        self.pixels += o.pixels;
        self.quadrants_interpolated += o.quadrants_interpolated;
        self.quadrants_mirrored += o.quadrants_mirrored;
        self.quadrants_nearest += o.quadrants_nearest;
        self.pixels_blended += o.pixels_blended;
        self.pixels_flagged += o.pixels_flagged;
        self.pixels_curved += o.pixels_curved;
    }
}

pub struct PostResult {
    pub color: Vec<[f32; 3]>,
    /// Pixels to re-trace with real supersampling (sorted), for `Trace`.
    pub flagged: Vec<u32>,
    pub stats: PostStats,
}

/// Catmull-Rom weights at `t ∈ [0, 1]` for samples at -1, 0, 1, 2.
fn cr(t: f64) -> [f64; 4] {
    let t2 = t * t;
    let t3 = t2 * t;
    [
        -0.5 * t3 + t2 - 0.5 * t,
        1.5 * t3 - 2.5 * t2 + 1.0,
        -1.5 * t3 + 2.0 * t2 + 0.5 * t,
        0.5 * t3 - 0.5 * t2,
    ]
}

/// Interpolation weights over the neighbour offsets -2..=2 (index + 2) at
/// sub-pixel offset `t ∈ [-0.5, 0.5]`; the 2-D map is their tensor product.
pub(crate) fn map_weights(map: PrssMap, t: f64) -> [f64; 5] {
    let mut w = [0.0; 5];
    let s: i64 = if t < 0.0 { -1 } else { 1 };
    let a = t.abs();
    let at = |o: i64| (o + 2) as usize;
    match map {
        PrssMap::Bilinear => {
            w[at(0)] = 1.0 - a;
            w[at(s)] += a;
        }
        PrssMap::Biquadratic => {
            w[at(-1)] = 0.5 * t * (t - 1.0);
            w[at(0)] = 1.0 - t * t;
            w[at(1)] = 0.5 * t * (t + 1.0);
        }
        PrssMap::Bicubic => {
            let c = cr(a);
            w[at(-s)] = c[0];
            w[at(0)] = c[1];
            w[at(s)] = c[2];
            w[at(2 * s)] = c[3];
        }
    }
    w
}

/// `n` sub-point offsets along one axis, centred in the pixel.
fn sub_points(n: usize) -> Vec<f64> {
    (0..n).map(|i| (i as f64 + 0.5) / n as f64 - 0.5).collect()
}

/// The sub-points along one axis: offsets and map weights.
struct Taps {
    t: Vec<f64>,
    w: Vec<[f64; 5]>,
    /// `w` transposed into chunks of [`CHUNK`] sub-points (`w_chunks[c][i][k]`
    /// is weight `i` of sub-point `c·CHUNK + k`; zero past the last), for the
    /// vectorised checkerboard count.
    w_chunks: Vec<[[f64; CHUNK]; 5]>,
}

/// Sub-points per vector chunk of [`checker_average`].
const CHUNK: usize = 8;

impl Taps {
    fn new(n: usize, map: PrssMap) -> Taps {
        let t = sub_points(n);
        let w: Vec<[f64; 5]> = t.iter().map(|&t| map_weights(map, t)).collect();
        let w_chunks = w
            .chunks(CHUNK)
            .map(|c| {
                std::array::from_fn(|i| std::array::from_fn(|k| c.get(k).map_or(0.0, |w| w[i])))
            })
            .collect();
        Taps { t, w, w_chunks }
    }
}

/// The 5×5 neighbourhood of hit positions (rows: y offsets -2..=2), filled
/// where neighbours are missing.
type Grid = [[[f64; 2]; 5]; 5];

/// `Σ_j wy[j] Σ_i wx[i] g[j][i]`, split: combine rows once per sub-point row.
/// Every term is added, zero weights too, in order of `j`: the vectorised
/// `odd_count_chunked` ([`checker`]) sums the same way, so the two agree bit
/// for bit.
fn rows(g: &Grid, wy: &[f64; 5]) -> [[f64; 2]; 5] {
    let mut r = [[0.0; 2]; 5];
    for (j, row) in g.iter().enumerate() {
        for i in 0..5 {
            r[i][0] += wy[j] * row[i][0];
            r[i][1] += wy[j] * row[i][1];
        }
    }
    r
}

fn cols(r: &[[f64; 2]; 5], wx: &[f64; 5]) -> [f64; 2] {
    let mut out = [0.0; 2];
    for i in 0..5 {
        out[0] += wx[i] * r[i][0];
        out[1] += wx[i] * r[i][1];
    }
    out
}

/// Everything a pixel needs to be shaded.
pub(crate) struct Ctx<'a> {
    pub map: HitMap<'a>,
    pub backdrop: &'a Backdrop,
    pub background: [f32; 3],
    pub s: &'a PostSettings,
    taps: Taps,
    /// Bilinear hats, for blending (the same points as `taps`).
    hats: Hats,
    /// Sparser sub-points for footprints well inside a photo's texel scale:
    /// `coarse[k]` has `k + 1` per axis.
    coarse: Vec<Taps>,
    /// With `blend-trace`: boundary pixels no straight boundary explains.
    unresolved: Vec<bool>,
}

fn blends(f: PrssFallback) -> bool {
    matches!(f, PrssFallback::Blend | PrssFallback::BlendTrace)
}

impl Ctx<'_> {
    /// With `blend-trace`: the boundary pixel `(x, y)` (one with neighbours on
    /// other pieces) is unresolved or next to one that is.
    fn retrace_boundary(&self, x: i64, y: i64) -> bool {
        if self.unresolved.is_empty() {
            return false;
        }
        (-1..=1).any(|j| {
            (-1..=1).any(|i| {
                self.map.inside(x + i, y + j)
                    && self.unresolved[((y + j) * self.map.w + x + i) as usize]
            })
        })
    }
}

/// Colour of a pixel without a backdrop hit: the background, blended with
/// neighbours that have one under `blend`; `None` to re-trace it.
fn no_hit_pixel(c: &Ctx, x: i64, y: i64, st: &mut PostStats) -> Option<[f32; 3]> {
    let ring = Ring::new(&c.map, x, y, None);
    if ring.all_same() {
        return Some(c.background);
    }
    match c.s.fallback {
        // A silhouette against the background: re-trace.
        PrssFallback::Trace => None,
        PrssFallback::Blend | PrssFallback::BlendTrace => {
            if c.retrace_boundary(x, y) {
                return None;
            }
            st.pixels_blended += 1;
            let line = edge_line(&c.map, x, y, None);
            Some(c.blend(x, y, &ring, line, &Own::Flat(c.background)).0)
        }
        PrssFallback::Mirror | PrssFallback::Nearest => Some(c.background),
    }
}

/// The 5×5 grid of the pixel's neighbourhood (radius `r`), filled per the
/// fallback; `None` means the pixel should be re-traced.
fn grid(
    c: &Ctx,
    (x, y): (i64, i64),
    (centre, ev): ([f64; 2], f32),
    r: i64,
    ring: &Ring,
    st: &mut PostStats,
) -> Option<Grid> {
    // Which of the 5×5 neighbours are on the centre's piece (`r` ≤ 2), from
    // the piece keys without branches where the window is inside the image
    // (the checked lookups branch on each neighbour, which at a boundary
    // goes either way).
    let mut on = [[false; 5]; 5];
    let m = &c.map;
    if x >= 2 && y >= 2 && x + 2 < m.w && y + 2 < m.h {
        for (j, row) in on.iter_mut().enumerate() {
            let at = ((y + j as i64 - 2) * m.w + x - 2) as usize;
            for (o, &k) in row.iter_mut().zip(&m.keys()[at..at + 5]) {
                *o = k == ev;
            }
        }
    } else {
        for (j, row) in on.iter_mut().enumerate() {
            for (i, o) in row.iter_mut().enumerate() {
                *o = m
                    .consistent(x + i as i64 - 2, y + j as i64 - 2, ev)
                    .is_some();
            }
        }
    }
    let is_on = |i: i64, j: i64| on[(j + 2) as usize][(i + 2) as usize];
    // Quadrant bookkeeping: are the three ring-1 neighbours of each consistent?
    for (sx, sy) in [(-1, -1), (1, -1), (-1, 1), (1, 1)] {
        let ok = is_on(sx, 0) && is_on(0, sy) && is_on(sx, sy);
        if ok {
            st.quadrants_interpolated += 1;
        } else if c.s.fallback == PrssFallback::Nearest {
            st.quadrants_nearest += 1;
        } else {
            st.quadrants_mirrored += 1;
        }
    }
    if c.s.fallback == PrssFallback::Trace && !ring.all_same() {
        return None;
    }
    // A missing neighbour is extrapolated by the centre's Jacobian (or, for
    // `nearest`, takes the centre's hit).
    let all_on = (-r..=r).all(|j| (-r..=r).all(|i| is_on(i, j)));
    let jac =
        (!all_on && c.s.fallback != PrssFallback::Nearest).then(|| m.jacobian(x, y, centre, ev));
    let mut g: Grid = [[centre; 5]; 5];
    for j in -r..=r {
        for i in -r..=r {
            let cell = &mut g[(j + 2) as usize][(i + 2) as usize];
            if is_on(i, j) {
                let p = ((y + j) * m.w + x + i) as usize;
                *cell = [m.film().u[p] as f64, m.film().v[p] as f64];
            } else if let Some(jac) = &jac {
                *cell = jac.apply(centre, i as f64, j as f64);
            }
        }
    }
    Some(g)
}

/// The larger side of the bounding box of the map at the pixel's centre,
/// edge midpoints and corners (backdrop units): the footprint's extent.
fn map_extent(g: &Grid, map: PrssMap) -> f64 {
    let w = [-0.5, 0.0, 0.5].map(|t| map_weights(map, t));
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for wy in &w {
        let r = rows(g, wy);
        for wx in &w {
            let h = cols(&r, wx);
            for k in 0..2 {
                lo[k] = lo[k].min(h[k]);
                hi[k] = hi[k].max(h[k]);
            }
        }
    }
    (hi[0] - lo[0]).max(hi[1] - lo[1])
}

/// With the `trace` fallback: the map bends too fast at pixel `(x, y)` for
/// its neighbours to interpolate it, so it is re-traced (and counted).
fn retrace_for_curvature(
    c: &Ctx,
    (x, y): (i64, i64),
    (centre, ev): ([f64; 2], f32),
    st: &mut PostStats,
) -> bool {
    let curved = c.s.fallback == PrssFallback::Trace
        && c.map
            .bends(x, y, centre, ev, c.s.curvature * feature_size(c.backdrop));
    st.pixels_curved += curved as u64;
    curved
}

/// PRSS colour of one pixel, or `None` to re-trace it.
fn prss_pixel(c: &Ctx, x: i64, y: i64, st: &mut PostStats) -> Option<[f32; 3]> {
    let (centre, ev) = c.map.at(x, y)?;
    let s = c.s;
    if retrace_for_curvature(c, (x, y), (centre, ev), st) {
        return None;
    }
    let r = if s.map == PrssMap::Bicubic { 2 } else { 1 };
    let ring = Ring::new(&c.map, x, y, Some(ev));
    let g = grid(c, (x, y), (centre, ev), r, &ring, st)?;
    let n = c.taps.t.len();
    if blends(s.fallback) && !ring.all_same() {
        if c.retrace_boundary(x, y) {
            return None;
        }
        st.pixels_blended += 1;
        let line = edge_line(&c.map, x, y, Some(ev));
        // The own surface's colour at each sub-point: over a checkerboard,
        // all parities at once; over a photograph, through the map's rows
        // (once per sub-point row). Where the pixel stays in one square the
        // parities are all the centre's, and the sums give what one colour
        // would, bit for bit (a colour times an exact zero weight adds
        // nothing); proving that first ([`in_one_square`]) cost more than
        // the parities (teapot: 17 of 24 M cycles a frame, and 6 of 32
        // thousand blended pixels in one square).
        let own = match &c.backdrop.pattern {
            Pattern::Checker { size, colors } => Own::Parities {
                rows: checker_parities(&g, &c.taps, *size),
                colors: *colors,
            },
            Pattern::Image(_) => Own::Rows(c.taps.w.iter().map(|wy| rows(&g, wy)).collect()),
        };
        let (color, _) = c.blend(x, y, &ring, line, &own);
        return Some(color);
    }
    let taps = match &c.backdrop.pattern {
        Pattern::Checker { size, colors } => {
            if in_one_square(&g, s.map, *size) {
                return Some(c.backdrop.color(centre[0], centre[1]));
            }
            return Some(checker_average(&g, &c.taps, *size, colors));
        }
        Pattern::Image(t) => {
            // A bilinear texture varies on the texel scale: a footprint
            // spanning `e` texels needs about `2e` sub-points per axis.
            let texel = t.world_width / t.width_px as f64;
            let e = map_extent(&g, s.map) / texel;
            let k = (2.0 * e).ceil().max(2.0) as usize;
            if k < n { &c.coarse[k - 1] } else { &c.taps }
        }
    };
    let n = taps.t.len();
    let mut acc = [0.0f64; 3];
    for jy in 0..n {
        let r = rows(&g, &taps.w[jy]);
        for ix in 0..n {
            let h = cols(&r, &taps.w[ix]);
            let col = c.backdrop.color(h[0], h[1]);
            for k in 0..3 {
                acc[k] += col[k] as f64;
            }
        }
    }
    Some(acc.map(|v| (v / (n * n) as f64) as f32))
}

/// PRSS colour of a pixel whose whole 5×5 neighbourhood reaches the backdrop
/// on the centre's piece — most pixels of a frame — for the bicubic map over
/// a checkerboard, classified by [`classify_rows`]. The general path
/// ([`prss_pixel`]) classifies each neighbour and fills a grid; here the
/// film's rows fill it directly, and a pixel in one square takes the
/// centre's colour, which [`checker_average`] would return too. Same colour
/// and stats as the general path.
fn prss_interior_checker(
    c: &Ctx,
    film: &Film,
    (x, y): (i64, i64),
    class: Interior,
    size: f64,
    colors: &[[f32; 3]; 2],
) -> [f32; 3] {
    let w = film.width as usize;
    let centre = y as usize * w + x as usize;
    if class == Interior::OneSquare {
        return c
            .backdrop
            .color(film.u[centre] as f64, film.v[centre] as f64);
    }
    // Array literals: built by nested `array::from_fn`, the rows were
    // closures called out of line and the grid copied into place (a
    // `memmove` per pixel); filled in place, it was zeroed first.
    let row = |j: usize| {
        let start = centre + j * w - 2 * w - 2;
        let (u, v) = (&film.u[start..start + 5], &film.v[start..start + 5]);
        let at = |i: usize| [u[i] as f64, v[i] as f64];
        [at(0), at(1), at(2), at(3), at(4)]
    };
    let g: Grid = [row(0), row(1), row(2), row(3), row(4)];
    match class {
        Interior::StraddlesU => checker_average_on::<U>(&g, &c.taps, size, colors),
        Interior::StraddlesV => checker_average_on::<V>(&g, &c.taps, size, colors),
        _ => checker_average(&g, &c.taps, size, colors),
    }
}

/// Pixels per vector run of [`one_square_colours`].
const ONE_SQUARE_RUN: usize = 8;

/// The checker colours at the hits `u[..8]`, `v[..8]` (film values, as `f64`)
/// into `out`: what [`Backdrop::color`] gives each ([`prss_interior_checker`]
/// for [`Interior::OneSquare`] pixels), with the same divisions and floors,
/// a run at a time ([`crate::simd::odd_floor_sum_mask`]).
fn one_square_colours(
    u: &[f32],
    v: &[f32],
    size: f64,
    colors: &[[f32; 3]; 2],
    out: &mut [[f32; 3]],
) {
    let isa = crate::simd::Isa::current();
    crate::with_isa!(isa, L, _M => {
        let x: [f64; 8] = std::array::from_fn(|l| u[l] as f64 / size);
        let y: [f64; 8] = std::array::from_fn(|l| v[l] as f64 / size);
        // SAFETY: L is bound by `with_isa!` for the running instruction set.
        let odd = unsafe { crate::simd::odd_floor_sum_mask::<L>(&x, &y) };
        for (l, o) in out[..ONE_SQUARE_RUN].iter_mut().enumerate() {
            *o = colors[((odd >> l) & 1) as usize];
        }
    })
}

/// Footprint colour of one pixel, or `None` to re-trace it.
fn footprint_pixel(c: &Ctx, x: i64, y: i64, st: &mut PostStats) -> Option<[f32; 3]> {
    let (centre, ev) = c.map.at(x, y)?;
    let s = c.s;
    if retrace_for_curvature(c, (x, y), (centre, ev), st) {
        return None;
    }
    let ring = Ring::new(&c.map, x, y, Some(ev));
    let jac = c.map.jacobian(x, y, centre, ev);
    match (jac.dx, jac.dy) {
        (Some(_), Some(_)) => st.quadrants_interpolated += 4,
        _ if s.fallback == PrssFallback::Trace => return None,
        _ => st.quadrants_nearest += 4,
    }
    if s.fallback == PrssFallback::Trace && !ring.all_same() {
        return None;
    }
    let own = footprint::filter(c.backdrop, centre, jac.or_zero(), s.footprint, s.samples);
    if blends(s.fallback) && !ring.all_same() {
        if c.retrace_boundary(x, y) {
            return None;
        }
        st.pixels_blended += 1;
        // The neighbours' surfaces where they are, the own surface's filtered
        // colour over the rest.
        let line = edge_line(&c.map, x, y, Some(ev));
        let (others, share) = c.blend(x, y, &ring, line, &Own::Flat([0.0; 3]));
        return Some(std::array::from_fn(|k| others[k] + (share as f32) * own[k]));
    }
    Some(own)
}

/// Size of the backdrop's smallest feature: a checker square or a texel.
fn feature_size(backdrop: &Backdrop) -> f64 {
    match &backdrop.pattern {
        Pattern::Checker { size, .. } => *size,
        Pattern::Image(t) => t.world_width / t.width_px as f64,
    }
}

/// Colours every pixel from the film's hit positions. Rows run in parallel;
/// each pixel's result depends only on its neighbourhood, so the output is
/// the same for any thread count.
pub fn shade(
    film: &Film,
    backdrop: &Backdrop,
    background: [f32; 3],
    s: &PostSettings,
) -> PostResult {
    let n = s.samples.max(1) as usize;
    let map = HitMap::new(film);
    // Pass 1 (blend-trace): which boundary pixels no straight boundary explains.
    let unresolved: Vec<bool> = if s.fallback == PrssFallback::BlendTrace {
        (0..film.height as i64)
            .into_par_iter()
            .flat_map_iter(|y| {
                let map = &map;
                (0..film.width as i64).map(move |x| {
                    let centre = map.at(x, y).map(|(_, e)| e);
                    let ring = Ring::new(map, x, y, centre);
                    !ring.all_same() && edge_line(map, x, y, centre).is_none()
                })
            })
            .collect()
    } else {
        Vec::new()
    };
    let c = Ctx {
        map,
        backdrop,
        background,
        s,
        taps: Taps::new(n, s.map),
        hats: Hats::new(n),
        coarse: (1..n).map(|k| Taps::new(k, s.map)).collect(),
        unresolved,
    };
    // The fast path for pixels inside one piece of the map (see
    // [`prss_interior_checker`]): PRSS with the default bicubic map over a
    // checkerboard, where no fallback other than `trace`'s curvature test
    // can change them.
    let interior = match &backdrop.pattern {
        Pattern::Checker { size, colors }
            if s.mode == Mode::Prss
                && s.map == PrssMap::Bicubic
                && s.fallback != PrssFallback::Trace =>
        {
            Some((*size, colors))
        }
        _ => None,
    };
    // Each band of rows shades into its place in the output: collecting rows
    // and concatenating them was a serial copy of the whole image (sphere,
    // 512×512: 1.5–1.9 ms of a 13 ms stage on 2 threads). Bands, not rows,
    // so the fast path's classification reads each row's window maxima for
    // several rows ([`interior`]).
    let w = film.width as usize;
    let mut color = vec![[0.0f32; 3]; w * film.height as usize];
    let bands: Vec<(Vec<u32>, PostStats)> = color
        .par_chunks_mut((w * BAND_ROWS).max(1))
        .enumerate()
        // One band per task, so an idle thread takes bands one at a time
        // (as the tiles, see `render::trace_regions`).
        .with_max_len(1)
        .map(|(band, colors)| {
            crate::with_isa!(crate::simd::Isa::current(), _L, _M => shade_band(&c, film, band, colors, interior))
        })
        .collect();
    let mut out = PostResult {
        color,
        flagged: Vec::new(),
        stats: PostStats::default(),
    };
    for (f, st) in bands {
        out.flagged.extend(f);
        out.stats.add(&st);
    }
    out
}

/// Shades band `band` of rows into `colors`: the flagged pixels and the
/// band's counters. Inlined into `with_isa!`'s function for the running
/// instruction set, so the per-pixel code between the lane kernels (the
/// classes, the pixel dispatch, the Jacobians and blends) is compiled for it
/// too rather than for baseline SSE2: the same operations, so the same bits
/// (no contraction into fused multiply-adds); sphere PRSS stage 11.48 →
/// 10.96 ms single thread (min of 5 alternating runs), teapot 32.3 → 31.9.
#[inline(always)]
fn shade_band(
    c: &Ctx,
    film: &Film,
    band: usize,
    colors: &mut [[f32; 3]],
    interior: Option<(f64, &[[f32; 3]; 2])>,
) -> (Vec<u32>, PostStats) {
    let (s, backdrop, background) = (c.s, c.backdrop, c.background);
    let w = film.width as usize;
    let y0 = band * BAND_ROWS;
    let rows = colors.len() / w.max(1);
    let mut st = PostStats::default();
    let mut flagged = Vec::new();
    let mut classes = Vec::new();
    if let Some((size, _)) = interior {
        classes = vec![Interior::No; rows * w];
        classify_rows(film, y0, y0 + rows, size, &mut classes);
    }
    let mut i = 0;
    while i < colors.len() {
        // Runs of pixels in one square: their centres' colours in
        // vector lanes (most pixels of a frame).
        if let Some((size, checker)) = interior
            && i % w + ONE_SQUARE_RUN <= w
            && classes[i..i + ONE_SQUARE_RUN]
                .iter()
                .all(|&c| c == Interior::OneSquare)
        {
            let at = y0 * w + i;
            let run = &mut colors[i..i + ONE_SQUARE_RUN];
            one_square_colours(&film.u[at..], &film.v[at..], size, checker, run);
            st.pixels += ONE_SQUARE_RUN as u64;
            st.quadrants_interpolated += 4 * ONE_SQUARE_RUN as u64;
            i += ONE_SQUARE_RUN;
            continue;
        }
        let (x, y) = ((i % w) as i64, (y0 + i / w) as i64);
        let pixel = (y * c.map.w + x) as u32;
        let hit = c.map.at(x, y).is_some();
        let col = if !hit {
            no_hit_pixel(c, x, y, &mut st)
        } else {
            st.pixels += 1;
            match s.mode {
                Mode::Prss => match (interior, classes.get(i)) {
                    (Some((size, colors)), Some(&class)) if class != Interior::No => {
                        st.quadrants_interpolated += 4;
                        Some(prss_interior_checker(c, film, (x, y), class, size, colors))
                    }
                    _ => prss_pixel(c, x, y, &mut st),
                },
                Mode::Footprint => footprint_pixel(c, x, y, &mut st),
            }
        };
        colors[i] = match col {
            Some(col) => col,
            None => {
                flagged.push(pixel);
                st.pixels_flagged += 1;
                let p = pixel as usize;
                if hit {
                    backdrop.color(film.u[p] as f64, film.v[p] as f64)
                } else {
                    background
                }
            }
        };
        i += 1;
    }
    (flagged, st)
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;

    /// The fast path's classes of film row `y`.
    fn interior_row(film: &Film, y: i64, size: f64) -> Vec<Interior> {
        let mut out = vec![Interior::No; film.width as usize];
        classify_rows(film, y as usize, y as usize + 1, size, &mut out);
        out
    }
    use crate::scene::Pattern;

    /// A warped map (minifying in places, so many pixels straddle squares),
    /// a disc on another piece, a hole without hits and, if `straight`, a
    /// third piece behind a straight boundary.
    pub(super) fn pieces_film(w: u32, h: u32, straight: bool) -> Film {
        let mut f = Film::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let i = (y * w + x) as usize;
                let (fx, fy) = (x as f64, y as f64);
                let disc = (fx - 30.0).powi(2) + (fy - 20.0).powi(2) < 64.0;
                let (u, v, e) = if disc {
                    (-3.1 * fx + 0.4 * fy * fy, 2.7 * fy - 0.05 * fx * fy, 2.0)
                } else if straight && fx + 0.3 * fy < 12.37 {
                    (0.2 * fx + 31.0, 0.3 * fy - 1.0, 4.0)
                } else {
                    (
                        0.9 * fx + 2.0 * (0.3 * fy).sin(),
                        0.7 * fy + 0.02 * fx * fx,
                        0.0,
                    )
                };
                f.u[i] = u as f32;
                f.v[i] = v as f32;
                f.events[i] = e;
                if (5..8).contains(&x) && (5..9).contains(&y) {
                    f.u[i] = f32::NAN;
                    f.v[i] = f32::NAN;
                }
            }
        }
        f
    }

    pub(super) fn checker(size: f64) -> Backdrop {
        Backdrop {
            center: DVec3::ZERO,
            normal: DVec3::Z,
            u_axis: DVec3::X,
            v_axis: DVec3::Z.cross(DVec3::X),
            pattern: Pattern::Checker {
                size,
                colors: [[1.0; 3], [0.0; 3]],
            },
        }
    }

    pub(super) fn settings(map: PrssMap, fallback: PrssFallback) -> PostSettings {
        PostSettings {
            mode: Mode::Prss,
            samples: 8,
            map,
            fallback,
            curvature: 0.25,
            footprint: FootprintFilter::Box,
        }
    }

    /// Evaluates the interpolated map of a 5×5 grid at sub-pixel `(tx, ty)`.
    fn eval(map: PrssMap, g: &Grid, tx: f64, ty: f64) -> [f64; 2] {
        cols(&rows(g, &map_weights(map, ty)), &map_weights(map, tx))
    }

    #[test]
    fn maps_interpolate_and_reproduce_polynomials() {
        let poly = |x: f64, y: f64| [1.0 + 2.0 * x - 0.5 * y, -3.0 + 0.25 * x + 1.5 * y];
        let quad = |x: f64, y: f64| [x * x - 0.7 * x * y + 0.3 * y * y + x, 2.0 * y * y - x * y];
        let grid_of = |f: &dyn Fn(f64, f64) -> [f64; 2]| {
            let mut g: Grid = [[[0.0; 2]; 5]; 5];
            for j in 0..5 {
                for i in 0..5 {
                    g[j][i] = f(i as f64 - 2.0, j as f64 - 2.0);
                }
            }
            g
        };
        let (gl, gq) = (grid_of(&poly), grid_of(&quad));
        for map in [PrssMap::Bilinear, PrssMap::Biquadratic, PrssMap::Bicubic] {
            for &t in &[-0.5, -0.3125, 0.0, 0.1875, 0.5] {
                let w = map_weights(map, t);
                assert!(
                    (w.iter().sum::<f64>() - 1.0).abs() < 1e-12,
                    "{map:?} weights sum"
                );
                for &s in &[-0.4375, 0.0625, 0.5] {
                    let (a, b) = (eval(map, &gl, t, s), poly(t, s));
                    assert!(
                        (a[0] - b[0]).abs() < 1e-12 && (a[1] - b[1]).abs() < 1e-12,
                        "{map:?} linear"
                    );
                    if map != PrssMap::Bilinear {
                        let (a, b) = (eval(map, &gq, t, s), quad(t, s));
                        assert!(
                            (a[0] - b[0]).abs() < 1e-12 && (a[1] - b[1]).abs() < 1e-12,
                            "{map:?} quadratic at ({t}, {s}): {a:?} vs {b:?}"
                        );
                    }
                }
            }
            // The map passes through the centre hit.
            assert_eq!(eval(map, &gq, 0.0, 0.0), quad(0.0, 0.0));
        }
    }

    /// A dense sampling of the map over the pixel stays in the centre's unit
    /// square (what a one-square claim promises).
    fn assert_stays_in_square(map: PrssMap, g: &Grid, what: &str) {
        let sq = |h: [f64; 2]| (h[0].floor(), h[1].floor());
        let first = sq(g[2][2]);
        for jy in 0..=40 {
            for ix in 0..=40 {
                let (tx, ty) = (ix as f64 / 40.0 - 0.5, jy as f64 / 40.0 - 0.5);
                let h = eval(map, g, tx, ty);
                assert_eq!(sq(h), first, "{what}, {map:?} at ({tx}, {ty})");
            }
        }
    }

    #[test]
    fn one_square_test_is_sound() {
        // Pseudo-random bending maps: whenever the shortcut claims one square,
        // a dense sampling of the map over the pixel must agree.
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        let (mut claimed, mut row_claimed) = (0, 0);
        for _ in 0..2000 {
            let (cu, cv) = (0.5 + 0.4 * rnd(), 0.5 + 0.4 * rnd());
            let (a, b, c, d) = (0.2 * rnd(), 0.2 * rnd(), 0.2 * rnd(), 0.2 * rnd());
            let bend = 0.3 * rnd();
            let mut g: Grid = [[[0.0; 2]; 5]; 5];
            for j in 0..5 {
                for i in 0..5 {
                    let (x, y) = (i as f64 - 2.0, j as f64 - 2.0);
                    g[j][i] = [
                        cu + a * x + b * y + bend * x * x + 0.05 * rnd(),
                        cv + c * x + d * y - bend * x * y + 0.05 * rnd(),
                    ];
                }
            }
            // The row pass on the same hits (as the film's f32), for the
            // bicubic map: its claims must hold for the map of those hits.
            let mut f = Film::new(5, 5);
            for j in 0..5 {
                for i in 0..5 {
                    f.u[j * 5 + i] = g[j][i][0] as f32;
                    f.v[j * 5 + i] = g[j][i][1] as f32;
                }
            }
            let g32: Grid = std::array::from_fn(|j| {
                std::array::from_fn(|i| [f.u[j * 5 + i] as f64, f.v[j * 5 + i] as f64])
            });
            if interior_row(&f, 2, 1.0)[2] == Interior::OneSquare {
                row_claimed += 1;
                assert_stays_in_square(PrssMap::Bicubic, &g32, "row pass");
            }
            for map in [PrssMap::Bilinear, PrssMap::Biquadratic, PrssMap::Bicubic] {
                if in_one_square(&g, map, 1.0) {
                    claimed += 1;
                    assert_stays_in_square(map, &g, "in_one_square");
                }
            }
        }
        assert!(
            claimed > 100 && row_claimed > 50,
            "the shortcut fires: {claimed}, the row pass: {row_claimed}"
        );
    }

    #[test]
    fn one_square_test_keeps_off_square_edges() {
        // A flat map a rounding error away from a square's edge: every test
        // refuses it (sub-points are evaluated by other arithmetic and may
        // land on the other side), though the nine points share a square.
        let size = 0.1;
        for edge in [3.0f64 * size, -7.0 * size, 1.0e6 * size] {
            for off in [-1e-13f64, 1e-13] {
                let p = edge + off * edge.abs().max(1.0);
                let g: Grid = [[[p, 0.55 * size]; 5]; 5];
                for map in [PrssMap::Bilinear, PrssMap::Biquadratic, PrssMap::Bicubic] {
                    assert!(!in_one_square(&g, map, size), "{map:?} at {p}");
                }
                // Well inside a square the claim stands, unless a hit is
                // not finite.
                let g: Grid = [[[edge + 0.5 * size, 0.55 * size]; 5]; 5];
                for map in [PrssMap::Bilinear, PrssMap::Biquadratic, PrssMap::Bicubic] {
                    assert!(in_one_square(&g, map, size), "{map:?} inside");
                }
                for bad in [f64::NAN, f64::INFINITY] {
                    let mut g = g;
                    g[2][3][1] = bad;
                    for map in [PrssMap::Bilinear, PrssMap::Biquadratic, PrssMap::Bicubic] {
                        assert!(!in_one_square(&g, map, size), "{map:?} with {bad}");
                    }
                }
            }
        }
    }

    /// A film of two flat pieces split by the line `x + slope·y = b` (image
    /// coordinates, pixel centres at +0.5): white on the left (events 0),
    /// black on the right (events 2).
    #[test]
    fn interior_fast_path_matches_the_general_path() {
        // Wherever the fast path applies it must give the general path's
        // colour, also across a stripe of huge values.
        let (w, h) = (48u32, 40u32);
        let mut f = pieces_film(w, h, false);
        for x in 0..w {
            f.u[(33 * w + x) as usize] = 3e30;
        }
        let bd = checker(4.0);
        let s = settings(PrssMap::Bicubic, PrssFallback::Blend);
        let c = Ctx {
            map: HitMap::new(&f),
            backdrop: &bd,
            background: [0.5; 3],
            s: &s,
            taps: Taps::new(8, PrssMap::Bicubic),
            hats: Hats::new(8),
            coarse: (1..8).map(|k| Taps::new(k, PrssMap::Bicubic)).collect(),
            unresolved: Vec::new(),
        };
        let (mut fast, mut mixed, mut claimed, mut across) = (0, 0, 0, [0; 2]);
        for y in 0..h as i64 {
            let classes = interior_row(&f, y, 4.0);
            for x in 0..w as i64 {
                let class = classes[x as usize];
                if class == Interior::No {
                    continue;
                }
                let mut st = PostStats::default();
                let want = prss_pixel(&c, x, y, &mut st).unwrap();
                // The sub-points' own average, whatever the class says.
                let g: Grid = std::array::from_fn(|j| {
                    std::array::from_fn(|i| {
                        let k = ((y + j as i64 - 2) * w as i64 + x + i as i64 - 2) as usize;
                        [f.u[k] as f64, f.v[k] as f64]
                    })
                });
                let all = checker_average(&g, &c.taps, 4.0, &[[1.0; 3], [0.0; 3]]);
                let got = prss_interior_checker(&c, &f, (x, y), class, 4.0, &[[1.0; 3], [0.0; 3]]);
                assert_eq!(got, want, "({x}, {y})");
                assert_eq!(got, all, "({x}, {y}) {class:?}");
                assert_eq!(st.quadrants_interpolated, 4);
                fast += 1;
                mixed += (got[0] != 0.0 && got[0] != 1.0) as usize;
                claimed += (class == Interior::OneSquare) as usize;
                across[0] += (class == Interior::StraddlesU) as usize;
                across[1] += (class == Interior::StraddlesV) as usize;
            }
        }
        assert!(
            fast > 800 && mixed > 200 && claimed > 300 && across.iter().all(|&n| n > 50),
            "{fast} fast pixels, {mixed} mixed, {claimed} in one square, {across:?} across one line"
        );
    }

    fn two_pieces(w: u32, h: u32, slope: f64, b: f64) -> Film {
        let mut f = Film::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let i = (y * w + x) as usize;
                let left = (x as f64 + 0.5) + slope * (y as f64 + 0.5) < b;
                f.u[i] = if left { 4.0 } else { 12.0 };
                f.v[i] = 4.0;
                f.events[i] = if left { 0.0 } else { 2.0 };
            }
        }
        f
    }

    #[test]
    fn boundary_line_is_located_from_the_staircase() {
        let (slope, b) = (0.3, 10.37);
        let f = two_pieces(24, 24, slope, b);
        let map = HitMap::new(&f);
        let norm = (1.0 + slope * slope).sqrt();
        let mut fitted = 0;
        for y in 6..18 {
            for x in 4..16 {
                let centre = map.at(x, y).map(|(_, e)| e);
                if Ring::new(&map, x, y, centre).all_same() {
                    continue;
                }
                let Some(l) = edge_line(&map, x, y, centre) else {
                    continue;
                };
                fitted += 1;
                // Signed distance of the centre to the true line, positive on
                // the centre's own side.
                let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
                let s = (b - px - slope * py) / norm;
                let own = if centre == Some(0.0) { s } else { -s };
                assert!((l.d - own).abs() < 0.2, "({x}, {y}): d {} vs {own}", l.d);

                let n_true = if centre == Some(0.0) {
                    [-1.0 / norm, -slope / norm]
                } else {
                    [1.0 / norm, slope / norm]
                };
                let cos = l.n[0] * n_true[0] + l.n[1] * n_true[1];
                assert!(cos > 0.985, "({x}, {y}): normal {:?} vs {n_true:?}", l.n);
            }
        }
        assert!(fitted >= 20, "{fitted} boundary pixels fitted");
    }

    #[test]
    fn blending_recovers_boundary_coverage() {
        // The box-filtered truth of each pixel is its white area left of the
        // line; `mirror` paints each pixel its centre's colour, `blend`
        // splits it. Blending must be much closer on the boundary pixels.
        let (slope, b) = (0.3, 10.37);
        let (w, h) = (24u32, 24u32);
        let f = two_pieces(w, h, slope, b);
        let bd = checker(8.0);
        let truth = |x: u32, y: u32| {
            let n = 64;
            let mut white = 0;
            for k in 0..n * n {
                let px = x as f64 + ((k % n) as f64 + 0.5) / n as f64;
                let py = y as f64 + ((k / n) as f64 + 0.5) / n as f64;
                white += (px + slope * py < b) as u32;
            }
            white as f64 / (n * n) as f64
        };
        let err = |fb: PrssFallback| {
            let out = shade(&f, &bd, [0.0; 3], &settings(PrssMap::Bicubic, fb));
            let (mut sum, mut count) = (0.0, 0);
            for y in 4..20 {
                for x in 2..20 {
                    let t = truth(x, y);
                    if t > 0.0 && t < 1.0 {
                        sum += (out.color[(y * w + x) as usize][0] as f64 - t).abs();
                        count += 1;
                    }
                }
            }
            (sum / count as f64, out.stats)
        };
        let (mirror, _) = err(PrssFallback::Mirror);
        let (blend, st) = err(PrssFallback::Blend);
        assert!(st.pixels_blended > 0);
        assert!(mirror > 0.15, "mirror: {mirror}");
        assert!(blend < 0.5 * mirror, "blend {blend} vs mirror {mirror}");
    }

    #[test]
    fn blend_trace_flags_only_unexplained_boundaries() {
        // A straight boundary needs no rays; an isolated one-pixel piece does.
        let mut f = two_pieces(16, 16, 0.3, 6.37);
        let bd = checker(8.0);
        let s = settings(PrssMap::Biquadratic, PrssFallback::BlendTrace);
        assert!(shade(&f, &bd, [0.0; 3], &s).flagged.is_empty());
        let i = (12 * 16 + 12) as usize;
        f.events[i] = 4.0;
        let out = shade(&f, &bd, [0.0; 3], &s);
        assert!(out.flagged.contains(&(i as u32)), "{:?}", out.flagged);
        assert!(out.flagged.len() <= 9, "{:?}", out.flagged);
    }
}
