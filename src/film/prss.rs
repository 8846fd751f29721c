//! The final stage: anti-aliasing from the hit-position image alone.
//!
//! Refraction maps the image plane onto the backdrop, `M: (x, y) → (u, v)`,
//! and the hit-position image samples `M` at pixel centres. A pixel's colour
//! should be the backdrop averaged over `M(pixel square)`; one ray per pixel
//! point-samples it instead, which aliases wherever `M` minifies (the sphere's
//! rim, paper Fig. 2). Both modes here reconstruct `M` over the pixel from its
//! neighbours, without tracing another ray:
//!
//! - **PRSS** (the paper, section 4.3): the square is split into four quadrants
//!   around the centre; in each, `M` is interpolated between the centre and the
//!   neighbours on that side — bilinearly from the 3×3 ring, or bicubically
//!   (Catmull-Rom) from the 5×5 ring — and `n×n` sub-points mapped through it
//!   sample the backdrop; their mean is the pixel (a box filter).
//! - **Footprint**: the Jacobian of `M` from central differences maps the square
//!   to a parallelogram on the backdrop, whose checker coverage is computed
//!   exactly by polygon clipping (an analytic box filter); photographs are
//!   sampled `n×n` over it.
//!
//! Interpolating across a discontinuity of `M` would smear unrelated backdrop
//! regions together, so a neighbour is used only if it reaches the backdrop
//! and crossed the same number of interfaces. Quadrants without such
//! neighbours fall back per [`PrssFallback`]: mirror the opposite neighbour
//! (assume `M` is locally linear), use the centre hit, or flag the pixel for
//! real sub-pixel rays (adaptive supersampling, traced by the renderer).

use rayon::prelude::*;
use serde::Serialize;

use crate::scene::{Backdrop, Pattern, PrssFallback};

use super::Film;

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
    /// 1: 3×3 bilinear, 2: 5×5 bicubic (PRSS only).
    pub ring: u32,
    pub fallback: PrssFallback,
    /// With the `Trace` fallback, pixels whose map bends more than this many
    /// backdrop features (checker squares, or photo texels) between
    /// neighbours are re-traced too: interpolation would misplace sub-samples.
    pub curvature: f64,
}

/// What the stage did, for the stats.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct PostStats {
    /// Pixels with a backdrop hit.
    pub pixels: u64,
    /// Quadrants interpolated from consistent neighbours.
    pub quadrants_interpolated: u64,
    /// Quadrants completed by mirroring the opposite neighbour.
    pub quadrants_mirrored: u64,
    /// Quadrants that fell back to the centre hit.
    pub quadrants_nearest: u64,
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

/// The hit map with neighbour lookups.
struct Hits<'a> {
    film: &'a Film,
    w: i64,
    h: i64,
}

impl Hits<'_> {
    #[inline]
    fn at(&self, x: i64, y: i64) -> Option<([f64; 2], f32)> {
        if x < 0 || y < 0 || x >= self.w || y >= self.h {
            return None;
        }
        let i = (y * self.w + x) as usize;
        let (u, v) = (self.film.u[i], self.film.v[i]);
        if u.is_finite() && v.is_finite() {
            Some(([u as f64, v as f64], self.film.events[i]))
        } else {
            None
        }
    }

    /// The neighbour's hit if it is consistent with events `ev`.
    #[inline]
    fn consistent(&self, x: i64, y: i64, ev: f32) -> Option<[f64; 2]> {
        self.at(x, y).filter(|(_, e)| *e == ev).map(|(h, _)| h)
    }
}

fn lerp2(a: [f64; 2], b: [f64; 2], t: f64) -> [f64; 2] {
    [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t]
}

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

fn add(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] + b[0], a[1] + b[1]]
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

/// How one quadrant maps its sub-points.
enum Quad {
    /// Bilinear corners: centre, x-neighbour, y-neighbour, diagonal.
    Bilinear([[f64; 2]; 4]),
    /// Catmull-Rom over a 4×4 patch (rows: y offsets -1..2, cols: x -1..2).
    Bicubic(Box<[[[f64; 2]; 4]; 4]>),
}

impl Quad {
    fn map(&self, a: f64, b: f64) -> [f64; 2] {
        match self {
            Quad::Bilinear(c) => lerp2(lerp2(c[0], c[1], a), lerp2(c[2], c[3], a), b),
            Quad::Bicubic(p) => {
                let (wa, wb) = (cr(a), cr(b));
                let mut out = [0.0; 2];
                for (j, row) in p.iter().enumerate() {
                    for (i, h) in row.iter().enumerate() {
                        out[0] += wb[j] * wa[i] * h[0];
                        out[1] += wb[j] * wa[i] * h[1];
                    }
                }
                out
            }
        }
    }
}

/// A pixel with a backdrop hit: position, hit and event count.
#[derive(Clone, Copy)]
struct Centre {
    x: i64,
    y: i64,
    hit: [f64; 2],
    events: f32,
}

/// Builds the map of quadrant `(sx, sy)` of pixel `p`; `None` means the pixel
/// should be re-traced.
fn quadrant(
    hits: &Hits,
    p: Centre,
    (sx, sy): (i64, i64),
    s: &PostSettings,
    st: &mut PostStats,
) -> Option<Quad> {
    let Centre {
        x,
        y,
        hit: centre,
        events: ev,
    } = p;
    let n = |dx: i64, dy: i64| hits.consistent(x + dx * sx, y + dy * sy, ev);
    if s.ring == 2 {
        let mut patch = Box::new([[[0.0; 2]; 4]; 4]);
        let mut ok = true;
        'outer: for (j, row) in patch.iter_mut().enumerate() {
            for (i, h) in row.iter_mut().enumerate() {
                match n(i as i64 - 1, j as i64 - 1) {
                    Some(v) => *h = v,
                    None => {
                        ok = false;
                        break 'outer;
                    }
                }
            }
        }
        if ok {
            st.quadrants_interpolated += 1;
            return Some(Quad::Bicubic(patch));
        }
    }
    if let (Some(hx), Some(hy), Some(hd)) = (n(1, 0), n(0, 1), n(1, 1)) {
        st.quadrants_interpolated += 1;
        return Some(Quad::Bilinear([centre, hx, hy, hd]));
    }
    match s.fallback {
        PrssFallback::Trace => None,
        PrssFallback::Nearest => {
            st.quadrants_nearest += 1;
            Some(Quad::Bilinear([centre; 4]))
        }
        PrssFallback::Mirror => {
            // Each side from its own neighbour, or mirrored from the opposite one.
            let side = |fwd: Option<[f64; 2]>, back: Option<[f64; 2]>| {
                fwd.or_else(|| back.map(|b| add(centre, sub(centre, b))))
            };
            let hx = side(n(1, 0), n(-1, 0));
            let hy = side(n(0, 1), n(0, -1));
            match (hx, hy) {
                (Some(hx), Some(hy)) => {
                    let hd = n(1, 1).unwrap_or_else(|| add(hx, sub(hy, centre)));
                    st.quadrants_mirrored += 1;
                    Some(Quad::Bilinear([centre, hx, hy, hd]))
                }
                _ => {
                    st.quadrants_nearest += 1;
                    Some(Quad::Bilinear([centre; 4]))
                }
            }
        }
    }
}

fn average(samples: impl Iterator<Item = [f32; 3]>, count: usize) -> [f32; 3] {
    let mut acc = [0.0f64; 3];
    for c in samples {
        for k in 0..3 {
            acc[k] += c[k] as f64;
        }
    }
    acc.map(|v| (v / count as f64) as f32)
}

/// Size of the backdrop's smallest feature: a checker square or a texel.
fn feature_size(backdrop: &Backdrop) -> f64 {
    match &backdrop.pattern {
        Pattern::Checker { size, .. } => *size,
        Pattern::Image(t) => t.world_width / t.width_px as f64,
    }
}

/// True when the second difference of the map along x or y exceeds `limit`:
/// a bilinear patch would put sub-samples that far off.
fn bends(hits: &Hits, x: i64, y: i64, centre: [f64; 2], ev: f32, limit: f64) -> bool {
    [(1, 0), (0, 1)].iter().any(|&(dx, dy)| {
        match (
            hits.consistent(x + dx, y + dy, ev),
            hits.consistent(x - dx, y - dy, ev),
        ) {
            (Some(f), Some(b)) => {
                let d2 = [f[0] + b[0] - 2.0 * centre[0], f[1] + b[1] - 2.0 * centre[1]];
                (d2[0] * d2[0] + d2[1] * d2[1]).sqrt() > limit
            }
            _ => false,
        }
    })
}

/// PRSS colour of one pixel, or `None` to re-trace it.
fn prss_pixel(
    hits: &Hits,
    x: i64,
    y: i64,
    backdrop: &Backdrop,
    s: &PostSettings,
    st: &mut PostStats,
) -> Option<[f32; 3]> {
    let (centre, ev) = hits.at(x, y)?;
    if s.fallback == PrssFallback::Trace
        && bends(hits, x, y, centre, ev, s.curvature * feature_size(backdrop))
    {
        st.pixels_curved += 1;
        return None;
    }
    let n = s.samples.max(1) as usize;
    let mut quads: [Option<Quad>; 4] = [None, None, None, None];
    let p = Centre {
        x,
        y,
        hit: centre,
        events: ev,
    };
    for (q, side) in [(-1, -1), (1, -1), (-1, 1), (1, 1)].into_iter().enumerate() {
        quads[q] = Some(quadrant(hits, p, side, s, st)?);
    }
    // A bilinear patch maps into the convex hull of its corners: if all the
    // quadrants' corners (centre, edge midpoints, pixel corners) fall in one
    // checker square, every sub-sample has that square's colour.
    if let Pattern::Checker { size, .. } = &backdrop.pattern
        && quads.iter().all(|q| matches!(q, Some(Quad::Bilinear(_))))
    {
        let square = |h: [f64; 2]| {
            use crate::filter::kernel::floor_i64;
            (floor_i64(h[0] / size), floor_i64(h[1] / size))
        };
        let first = square(centre);
        let same = quads.iter().all(|q| {
            let q = q.as_ref().expect("built above");
            [(0.5, 0.0), (0.0, 0.5), (0.5, 0.5)]
                .iter()
                .all(|&(a, b)| square(q.map(a, b)) == first)
        });
        if same {
            return Some(backdrop.color(centre[0], centre[1]));
        }
    }
    let samples = (0..n * n).map(|k| {
        let (i, j) = (k % n, k / n);
        let dx = (i as f64 + 0.5) / n as f64 - 0.5;
        let dy = (j as f64 + 0.5) / n as f64 - 0.5;
        let q = (dx > 0.0) as usize + 2 * (dy > 0.0) as usize;
        let h = quads[q]
            .as_ref()
            .expect("built above")
            .map(dx.abs(), dy.abs());
        backdrop.color(h[0], h[1])
    });
    Some(average(samples, n * n))
}

/// Footprint colour of one pixel, or `None` to re-trace it.
fn footprint_pixel(
    hits: &Hits,
    x: i64,
    y: i64,
    backdrop: &Backdrop,
    s: &PostSettings,
    st: &mut PostStats,
) -> Option<[f32; 3]> {
    let (centre, ev) = hits.at(x, y)?;
    // Central differences where both sides are consistent, one-sided otherwise.
    let deriv = |dx: i64, dy: i64| -> Option<[f64; 2]> {
        let f = hits.consistent(x + dx, y + dy, ev);
        let b = hits.consistent(x - dx, y - dy, ev);
        match (f, b) {
            (Some(f), Some(b)) => Some(sub(f, b).map(|v| 0.5 * v)),
            (Some(f), None) => Some(sub(f, centre)),
            (None, Some(b)) => Some(sub(centre, b)),
            (None, None) => None,
        }
    };
    if s.fallback == PrssFallback::Trace
        && bends(hits, x, y, centre, ev, s.curvature * feature_size(backdrop))
    {
        st.pixels_curved += 1;
        return None;
    }
    let (jx, jy) = match (deriv(1, 0), deriv(0, 1)) {
        (Some(a), Some(b)) => {
            st.quadrants_interpolated += 4;
            (a, b)
        }
        _ if s.fallback == PrssFallback::Trace => return None,
        (a, b) => {
            st.quadrants_nearest += 4;
            (a.unwrap_or([0.0; 2]), b.unwrap_or([0.0; 2]))
        }
    };
    let corner = |a: f64, b: f64| {
        [
            centre[0] + a * jx[0] + b * jy[0],
            centre[1] + a * jx[1] + b * jy[1],
        ]
    };
    match &backdrop.pattern {
        Pattern::Checker { size, colors } => {
            let quad = [
                corner(-0.5, -0.5),
                corner(0.5, -0.5),
                corner(0.5, 0.5),
                corner(-0.5, 0.5),
            ];
            let white = checker_coverage(&quad, *size).unwrap_or_else(|| {
                // Degenerate footprint: point-sample.
                let c = ((centre[0] / size).floor() + (centre[1] / size).floor()).rem_euclid(2.0);
                if c == 0.0 { 1.0 } else { 0.0 }
            });
            let w = white as f32;
            Some(std::array::from_fn(|k| {
                colors[1][k] + (colors[0][k] - colors[1][k]) * w
            }))
        }
        Pattern::Image(_) => {
            let n = s.samples.max(1) as usize;
            let samples = (0..n * n).map(|k| {
                let a = ((k % n) as f64 + 0.5) / n as f64 - 0.5;
                let b = ((k / n) as f64 + 0.5) / n as f64 - 0.5;
                let h = corner(a, b);
                backdrop.color(h[0], h[1])
            });
            Some(average(samples, n * n))
        }
    }
}

/// Fraction of the convex polygon `quad` covered by even checker squares
/// (`floor(u/s) + floor(v/s)` even), exactly, by clipping against every square
/// it overlaps. `None` for a degenerate polygon. Footprints covering more than
/// 4096 squares average to within 1/64 of one half and are reported as 0.5.
pub fn checker_coverage(quad: &[[f64; 2]; 4], size: f64) -> Option<f64> {
    let area = polygon_area(quad);
    if !area.is_finite() || area <= 1e-18 * size * size {
        return None;
    }
    let (mut u0, mut u1, mut v0, mut v1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for p in quad {
        u0 = u0.min(p[0]);
        u1 = u1.max(p[0]);
        v0 = v0.min(p[1]);
        v1 = v1.max(p[1]);
    }
    let (i0, i1) = ((u0 / size).floor() as i64, (u1 / size).floor() as i64);
    let (j0, j1) = ((v0 / size).floor() as i64, (v1 / size).floor() as i64);
    if (i1 - i0 + 1).saturating_mul(j1 - j0 + 1) > 4096 {
        return Some(0.5);
    }
    let mut white = 0.0;
    let mut poly: Vec<[f64; 2]> = Vec::with_capacity(8);
    let mut tmp: Vec<[f64; 2]> = Vec::with_capacity(8);
    for j in j0..=j1 {
        for i in i0..=i1 {
            if (i + j).rem_euclid(2) != 0 {
                continue;
            }
            poly.clear();
            poly.extend_from_slice(quad);
            let (a0, a1) = (i as f64 * size, (i + 1) as f64 * size);
            let (b0, b1) = (j as f64 * size, (j + 1) as f64 * size);
            for (axis, bound, keep_above) in
                [(0, a0, true), (0, a1, false), (1, b0, true), (1, b1, false)]
            {
                clip(&poly, &mut tmp, axis, bound, keep_above);
                std::mem::swap(&mut poly, &mut tmp);
                if poly.is_empty() {
                    break;
                }
            }
            if poly.len() >= 3 {
                white += polygon_area(&poly);
            }
        }
    }
    Some((white / area).clamp(0.0, 1.0))
}

/// Sutherland–Hodgman against one axis-aligned half-plane.
fn clip(src: &[[f64; 2]], dst: &mut Vec<[f64; 2]>, axis: usize, bound: f64, keep_above: bool) {
    dst.clear();
    let inside = |p: &[f64; 2]| {
        if keep_above {
            p[axis] >= bound
        } else {
            p[axis] <= bound
        }
    };
    for k in 0..src.len() {
        let (a, b) = (src[k], src[(k + 1) % src.len()]);
        let (ia, ib) = (inside(&a), inside(&b));
        if ia {
            dst.push(a);
        }
        if ia != ib {
            let t = (bound - a[axis]) / (b[axis] - a[axis]);
            dst.push(lerp2(a, b, t));
        }
    }
}

fn polygon_area(p: &[[f64; 2]]) -> f64 {
    let mut a = 0.0;
    for k in 0..p.len() {
        let (x0, y0) = (p[k][0], p[k][1]);
        let (x1, y1) = (p[(k + 1) % p.len()][0], p[(k + 1) % p.len()][1]);
        a += x0 * y1 - x1 * y0;
    }
    0.5 * a.abs()
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
    let hits = Hits {
        film,
        w: film.width as i64,
        h: film.height as i64,
    };
    let rows: Vec<(Vec<[f32; 3]>, Vec<u32>, PostStats)> = (0..film.height as i64)
        .into_par_iter()
        .map(|y| {
            let mut st = PostStats::default();
            let mut colors = Vec::with_capacity(film.width as usize);
            let mut flagged = Vec::new();
            for x in 0..film.width as i64 {
                let pixel = (y * hits.w + x) as u32;
                let Some(_) = hits.at(x, y) else {
                    // No backdrop hit: background, unless a neighbour has one
                    // (a silhouette against the background), which Trace refines.
                    let edge = s.fallback == PrssFallback::Trace
                        && [(1, 0), (-1, 0), (0, 1), (0, -1)]
                            .iter()
                            .any(|(dx, dy)| hits.at(x + dx, y + dy).is_some());
                    if edge {
                        flagged.push(pixel);
                        st.pixels_flagged += 1;
                    }
                    colors.push(background);
                    continue;
                };
                st.pixels += 1;
                let c = match s.mode {
                    Mode::Prss => prss_pixel(&hits, x, y, backdrop, s, &mut st),
                    Mode::Footprint => footprint_pixel(&hits, x, y, backdrop, s, &mut st),
                };
                match c {
                    Some(c) => colors.push(c),
                    None => {
                        flagged.push(pixel);
                        st.pixels_flagged += 1;
                        let i = pixel as usize;
                        colors.push(backdrop.color(film.u[i] as f64, film.v[i] as f64));
                    }
                }
            }
            (colors, flagged, st)
        })
        .collect();
    let mut out = PostResult {
        color: Vec::with_capacity((film.width * film.height) as usize),
        flagged: Vec::new(),
        stats: PostStats::default(),
    };
    for (c, f, st) in rows {
        out.color.extend(c);
        out.flagged.extend(f);
        out.stats.add(&st);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coverage_of_simple_footprints() {
        let sq =
            |u0: f64, v0: f64, w: f64| [[u0, v0], [u0 + w, v0], [u0 + w, v0 + w], [u0, v0 + w]];
        // Inside one white square, one black square, straddling four squares.
        assert_eq!(checker_coverage(&sq(0.1, 0.1, 0.5), 1.0), Some(1.0));
        assert_eq!(checker_coverage(&sq(1.1, 0.1, 0.5), 1.0), Some(0.0));
        let c = checker_coverage(&sq(0.5, 0.5, 1.0), 1.0).unwrap();
        assert!((c - 0.5).abs() < 1e-12);
        // A thin sliver u ∈ [v, v + 0.05] along the white diagonal clips a black
        // triangle of area 0.05²/2 at each of the 3 corners it passes.
        let d = [[0.2, 0.2], [0.25, 0.2], [3.25, 3.2], [3.2, 3.2]];
        let expect = 1.0 - 3.0 * 0.00125 / 0.15;
        assert!((checker_coverage(&d, 1.0).unwrap() - expect).abs() < 1e-9);
        // A rotated square over one corner of four squares: half and half.
        let r = [[1.0, 0.5], [1.5, 1.0], [1.0, 1.5], [0.5, 1.0]];
        assert!((checker_coverage(&r, 1.0).unwrap() - 0.5).abs() < 1e-12);
        assert!(checker_coverage(&[[0.0, 0.0]; 4], 1.0).is_none());
    }
}
