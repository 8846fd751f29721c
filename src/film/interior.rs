//! Which pixels PRSS's fast path over a checkerboard may colour without the
//! general path ([`Interior`]), classified a band of rows at a time.
//!
//! A pixel qualifies when its 5×5 neighbourhood of hits is on the centre's
//! piece (one event count, every hit finite), and it is claimed
//! [`Interior::OneSquare`] when the bicubic map over it provably stays in the
//! centre's checker square: the box of the bilinear map at the pixel's
//! corners, edge midpoints and centre, widened by how far the bicubic map
//! strays from it (`prss::one_square::bicubic_in_one_square` derives the
//! bound). The same test per coordinate tells a pixel that crosses only one grid line
//! of the checkerboard ([`Interior::StraddlesU`], [`Interior::StraddlesV`]),
//! whose sub-points' parities need only the other coordinate.
//!
//! Every term of that bound but the box is a maximum over a window of the
//! neighbourhood — the largest `|hit|` over 5×5, the largest second
//! difference across over 5 rows × 3 columns and 3 × 3, down over 3 × 5 and
//! 3 × 3 — and windows are separable: each row's horizontal maxima are taken
//! once for the five rows that read them, then combined down the columns.
//! Maxima and minima of non-NaN values are exact in any order, and every
//! other value is the same `f32` expression as the per-pixel definition's,
//! so the classes are bit for bit what classifying each pixel's 25 hits on
//! its own gives (tested against that definition). Classified one 5×5 block
//! at a time, the sphere's empty frame spent 20 ns a pixel here.
//!
//! NaN and infinite hits are never on a piece, so a window holding one is
//! [`Interior::No`] whatever its maxima (which NaN may leave meaningless).

use super::Film;

/// How a pixel relates to the fast path of the bicubic map over a
/// checkerboard.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Interior {
    /// Some hit of the 5×5 neighbourhood is missing, not finite or on
    /// another piece (or the pixel is within two of the border): the
    /// general path.
    No,
    /// The whole neighbourhood is on the centre's piece and the map over
    /// the pixel provably stays in the centre's square.
    OneSquare,
    /// On the centre's piece, but the map may reach another square along
    /// both coordinates.
    Straddles,
    /// On the centre's piece, and the map provably stays in the centre's
    /// row of squares (`v`'s square is fixed): only `u` may reach another
    /// square, so a sub-point's parity needs only its `u`.
    StraddlesU,
    /// The same with `u`'s column of squares fixed: only `v` may cross.
    StraddlesV,
}

impl Interior {
    /// The class of a pixel on the centre's piece (`on_piece`) from whether
    /// the map stays in one square along `u` and along `v`.
    #[inline(always)]
    fn of(on_piece: bool, one_u: bool, one_v: bool) -> Interior {
        match (on_piece, one_u, one_v) {
            (false, _, _) => Interior::No,
            (true, true, true) => Interior::OneSquare,
            (true, false, true) => Interior::StraddlesU,
            (true, true, false) => Interior::StraddlesV,
            (true, false, false) => Interior::Straddles,
        }
    }
}

/// Pixels classified at once: one AVX-512 vector of `f32`.
const LANES: usize = 16;
/// The hits a lane of pixels reads along a row: from two before its first
/// pixel to two past its last.
const WIN: usize = LANES + 4;

/// `row[at..at + N]` as an array; past the row's end, a zero-padded copy
/// in `spare` (only a row's last lane). Lanes index it by constant offsets,
/// so they compile to vector loads straight from the row.
#[inline(always)]
fn window<'a, const N: usize>(row: &'a [f32], at: usize, spare: &'a mut [f32; N]) -> &'a [f32; N] {
    match row.get(at..at + N) {
        Some(s) => s.try_into().unwrap(),
        None => {
            *spare = std::array::from_fn(|l| row.get(at + l).copied().unwrap_or(0.0));
            spare
        }
    }
}

/// `s[at..at + LANES]` of a buffer padded by [`LANES`] past its last pixel.
#[inline(always)]
fn lane<T>(s: &[T], at: usize) -> &[T; LANES] {
    s[at..at + LANES].try_into().unwrap()
}

#[inline(always)]
fn lane_mut<T>(s: &mut [T], at: usize) -> &mut [T; LANES] {
    (&mut s[at..at + LANES]).try_into().unwrap()
}

/// Each row's horizontal window maxima, for the rows a band's windows read:
/// row `r` of a column holds pixel `x = i + 2` at `r · stride + i`, and
/// [`LANES`] of padding.
struct RowPass {
    stride: usize,
    /// All five hits around the pixel in its row are finite, with an event
    /// count that is a number (1), or not (0).
    valid5: Vec<u8>,
    /// Least and greatest event count of the five.
    emin5: Vec<f32>,
    emax5: Vec<f32>,
    /// Per coordinate (`u`, `v`): the largest `|second difference across|`
    /// of the three pixels around, and the largest `|hit|` of the five.
    dx3: [Vec<f32>; 2],
    abs5: [Vec<f32>; 2],
}

/// `max`/`min` as a compare and select, NaN-blind like the per-pixel bound
/// (windows with a NaN are refused by their validity).
#[inline(always)]
fn max(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

#[inline(always)]
fn min(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// `|(a − 2b) + c|`, the second difference as the per-pixel bound writes it.
#[inline(always)]
fn second(a: f32, b: f32, c: f32) -> f32 {
    ((a - 2.0 * b) + c).abs()
}

/// The largest and least of five, in the per-pixel bound's order.
#[inline(always)]
fn max5(a: [f32; 5]) -> f32 {
    max(max(max(a[0], a[1]), max(a[2], a[3])), a[4])
}

#[inline(always)]
fn min5(a: [f32; 5]) -> f32 {
    min(min(min(a[0], a[1]), min(a[2], a[3])), a[4])
}

impl RowPass {
    /// The horizontal maxima of film rows `rows`. `w ≥ 5`.
    #[inline(always)]
    fn new(film: &Film, rows: std::ops::Range<usize>) -> RowPass {
        let w = film.width as usize;
        let n = w - 4;
        let stride = n + LANES;
        let len = rows.len() * stride;
        let mut p = RowPass {
            stride,
            valid5: vec![0; len],
            emin5: vec![0.0; len],
            emax5: vec![0.0; len],
            dx3: [vec![0.0; len], vec![0.0; len]],
            abs5: [vec![0.0; len], vec![0.0; len]],
        };
        let mut spare = [[0.0; WIN]; 3];
        for (r, y) in rows.enumerate() {
            let at = y * w;
            for i0 in (0..n).step_by(LANES) {
                // Pixel x = i0 + l + 2 reads x − 2 + d at `[l + d]`.
                let [su, sv, se] = &mut spare;
                let u = window(&film.u[at..at + w], i0, su);
                let v = window(&film.v[at..at + w], i0, sv);
                let e = window(&film.events[at..at + w], i0, se);
                let o = r * stride + i0;
                let v5 = lane_mut(&mut p.valid5, o);
                for l in 0..LANES {
                    let mut all = true;
                    for d in 0..5 {
                        // `|h| < ∞` fails for NaN and ±∞.
                        all &= (u[l + d].abs() < f32::INFINITY)
                            & (v[l + d].abs() < f32::INFINITY)
                            & !e[l + d].is_nan();
                    }
                    v5[l] = all as u8;
                }
                let lo = lane_mut(&mut p.emin5, o);
                for l in 0..LANES {
                    lo[l] = min5(std::array::from_fn(|d| e[l + d]));
                }
                let hi = lane_mut(&mut p.emax5, o);
                for l in 0..LANES {
                    hi[l] = max5(std::array::from_fn(|d| e[l + d]));
                }
                for (k, g) in [u, v].into_iter().enumerate() {
                    let d3 = lane_mut(&mut p.dx3[k], o);
                    for l in 0..LANES {
                        let dx = |d: usize| second(g[l + d - 1], g[l + d], g[l + d + 1]);
                        d3[l] = max(max(dx(1), dx(2)), dx(3));
                    }
                    let a5 = lane_mut(&mut p.abs5[k], o);
                    for l in 0..LANES {
                        a5[l] = max5(std::array::from_fn(|d| g[l + d].abs()));
                    }
                }
            }
        }
        p
    }
}

/// Classifies film rows `y0..y1` into `out` (row-major, `w` per row): the
/// classes of [`Interior`] for checker squares of side `size`, in `f32` with
/// the per-pixel definition's slack (`1e-5` of the largest hit and of the
/// square, far above the rounding of these few operations, so a claim holds
/// for the exact map and for the `f64` sub-points the general path would
/// take). Pixels within two of the film's border are [`Interior::No`].
pub(crate) fn classify_rows(film: &Film, y0: usize, y1: usize, size: f64, out: &mut [Interior]) {
    let (w, h) = (film.width as usize, film.height as usize);
    assert_eq!(out.len(), (y1 - y0) * w);
    out.fill(Interior::No);
    let (first, last) = (y0.max(2), y1.min(h.saturating_sub(2)));
    if w < 5 || first >= last {
        return;
    }
    let isa = crate::simd::Isa::current();
    crate::with_isa!(isa, _L, _M => classify_in(film, first, last, y0, size, out));
}

/// The body of [`classify_rows`] for rows `first..last`, each two or more
/// rows inside the film; `out` starts at row `y0`.
#[inline(always)]
fn classify_in(film: &Film, first: usize, last: usize, y0: usize, size: f64, out: &mut [Interior]) {
    let w = film.width as usize;
    let n = w - 4;
    let pass = RowPass::new(film, first - 2..last + 2);
    let st = pass.stride;
    let inv = (1.0 / size) as f32;
    let slack = 1e-5 * size as f32;
    // Per row and coordinate: the down second differences' maxima at every
    // x (the windows across read x ± 2), padded.
    let mut v3dy = vec![0.0f32; w + LANES];
    let mut spare5 = [[0.0; LANES]; 5];
    let mut spare3 = [[0.0; LANES + 2]; 3];
    let mut ok = vec![false; n + LANES];
    // Per coordinate: the map stays in one square along it.
    let mut one = [vec![true; n + LANES], vec![true; n + LANES]];
    for y in first..last {
        // Pass rows `r0 / st .. + 5` are film rows y − 2 ..= y + 2.
        let r0 = (y - first) * st;
        for i0 in (0..n).step_by(LANES) {
            let v5: [&[u8; LANES]; 5] =
                std::array::from_fn(|j| lane(&pass.valid5, r0 + j * st + i0));
            let lo: [&[f32; LANES]; 5] =
                std::array::from_fn(|j| lane(&pass.emin5, r0 + j * st + i0));
            let hi: [&[f32; LANES]; 5] =
                std::array::from_fn(|j| lane(&pass.emax5, r0 + j * st + i0));
            let o = lane_mut(&mut ok, i0);
            for l in 0..LANES {
                let all = v5[0][l] & v5[1][l] & v5[2][l] & v5[3][l] & v5[4][l];
                let emin = min5(std::array::from_fn(|j| lo[j][l]));
                let emax = max5(std::array::from_fn(|j| hi[j][l]));
                o[l] = (all == 1) & (emin == emax);
            }
        }
        for (k, g) in [&film.u, &film.v].into_iter().enumerate() {
            let rows: [&[f32]; 5] = std::array::from_fn(|j| &g[(y + j - 2) * w..][..w]);
            for x0 in (0..w).step_by(LANES) {
                let [s0, s1, s2, s3, s4] = &mut spare5;
                let c = [
                    window(rows[0], x0, s0),
                    window(rows[1], x0, s1),
                    window(rows[2], x0, s2),
                    window(rows[3], x0, s3),
                    window(rows[4], x0, s4),
                ];
                let out = lane_mut(&mut v3dy, x0);
                for l in 0..LANES {
                    let d = |b: usize| second(c[b - 1][l], c[b][l], c[b + 1][l]);
                    out[l] = max(max(d(1), d(2)), d(3));
                }
            }
            for i0 in (0..n).step_by(LANES) {
                let d3: [&[f32; LANES]; 5] =
                    std::array::from_fn(|j| lane(&pass.dx3[k], r0 + j * st + i0));
                let a5: [&[f32; LANES]; 5] =
                    std::array::from_fn(|j| lane(&pass.abs5[k], r0 + j * st + i0));
                // Pixel x = i0 + l + 2: `vd[l + d]` at x − 2 + d; the rows
                // above, at and below it at x − 1 + d from `[l + d]`.
                let vd: &[f32; WIN] = v3dy[i0..i0 + WIN].try_into().unwrap();
                let [st0, st1, st2] = &mut spare3;
                let (t3, m3, b3) = (
                    window(rows[1], i0 + 1, st0),
                    window(rows[2], i0 + 1, st1),
                    window(rows[3], i0 + 1, st2),
                );
                let one = lane_mut(&mut one[k], i0);
                for l in 0..LANES {
                    let dx3 = max(max(d3[1][l], d3[2][l]), d3[3][l]);
                    let dx5 = max(max(dx3, d3[0][l]), d3[4][l]);
                    let big = max5(std::array::from_fn(|j| a5[j][l]));
                    let dy3 = max(max(vd[l + 1], vd[l + 2]), vd[l + 3]);
                    let dy5 = max(max(dy3, vd[l]), vd[l + 4]);
                    let bend = min(
                        dy3 * 0.125 + dx5 * (5.0 / 32.0),
                        dx3 * 0.125 + dy5 * (5.0 / 32.0),
                    );
                    // The bilinear map at the corners and edge midpoints.
                    let c = m3[l + 1];
                    let (le, ri) = (c + m3[l], c + m3[l + 2]);
                    let (t, b) = (t3[l + 1], b3[l + 1]);
                    let (mut lo, mut hi) = (c, c);
                    for p in [
                        0.5 * le,
                        0.5 * ri,
                        0.5 * (c + t),
                        0.5 * (c + b),
                        0.25 * (le + (t + t3[l])),
                        0.25 * (ri + (t + t3[l + 2])),
                        0.25 * (le + (b + b3[l])),
                        0.25 * (ri + (b + b3[l + 2])),
                    ] {
                        lo = min(lo, p);
                        hi = max(hi, p);
                    }
                    let m = bend + 1e-5 * big + slack;
                    let (a, b) = ((lo - m) * inv, (hi + m) * inv);
                    one[l] = (a.abs() < 1e15) & (b.abs() < 1e15) & (a.floor() == b.floor());
                }
            }
        }
        let row = &mut out[(y - y0) * w + 2..][..n];
        for (i, class) in row.iter_mut().enumerate() {
            *class = Interior::of(ok[i], one[0][i], one[1][i]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::film::prss::footprint_box;

    /// The per-pixel definition: the pixel's 25 hits taken on their own.
    fn reference(film: &Film, x: usize, y: usize, size: f64) -> Interior {
        let (w, h) = (film.width as usize, film.height as usize);
        if x < 2 || y < 2 || x + 2 >= w || y + 2 >= h {
            return Interior::No;
        }
        let at = |j: usize, i: usize| (y + j - 2) * w + x + i - 2;
        let e0 = film.events[at(2, 2)];
        let mut ok = true;
        for j in 0..5 {
            for i in 0..5 {
                let k = at(j, i);
                ok &= film.events[k] == e0
                    && film.u[k].abs() < f32::INFINITY
                    && film.v[k].abs() < f32::INFINITY;
            }
        }
        if !ok {
            return Interior::No;
        }
        let (inv, slack) = ((1.0 / size) as f32, 1e-5 * size as f32);
        let [one_u, one_v] = [&film.u, &film.v].map(|g| {
            let (lo, hi, bend, big) = footprint_box(|j, i| g[at(j, i)]);
            let m = bend + 1e-5 * big + slack;
            let (a, b) = ((lo - m) * inv, (hi + m) * inv);
            a.abs() < 1e15 && b.abs() < 1e15 && a.floor() == b.floor()
        });
        Interior::of(true, one_u, one_v)
    }

    /// A film over a smooth, bending map with noise, pieces of another event
    /// count, and scattered NaN, infinite and huge hits and NaN counts.
    fn film(w: u32, h: u32, seed: u64) -> Film {
        use crate::phantom::{mix64, uniform};
        let mut f = Film::new(w, h);
        let r = |k: u64| uniform(mix64(seed), k);
        let (a, b, bend) = (0.3 + r(1), 0.2 * r(2) - 0.1, 0.02 * r(3));
        // Far from the origin on some films, where the slack for the
        // largest hit is what keeps pixels off square edges.
        let far = if seed % 2 == 1 { 2.0e4 } else { 0.0 };
        for y in 0..h as usize {
            for x in 0..w as usize {
                let i = y * w as usize + x;
                let (xf, yf) = (x as f64, y as f64);
                // Mostly smooth, with rough patches and spikes, so each
                // window term decides some pixel's class.
                let amp = [0.001, 0.001, 0.05, 0.4][(r(10 + 4 * i as u64 + 3) * 4.0) as usize];
                let noise = |k: u64| amp * (r(10 + 4 * i as u64 + k) - 0.5);
                f.u[i] = (far + a * xf + b * yf + bend * xf * xf + noise(0)) as f32;
                f.v[i] = (b * xf + a * yf - bend * xf * yf + noise(1)) as f32;
                f.events[i] = if (xf - 0.7 * yf - 9.0).abs() < 3.0 {
                    2.0
                } else {
                    0.0
                };
                match (r(10 + 4 * i as u64 + 2) * 400.0) as u32 {
                    0 => f.u[i] = f32::NAN,
                    1 => f.v[i] = f32::INFINITY,
                    2 => f.u[i] = 3e30,
                    3 => f.events[i] = f32::NAN,
                    4 => f.events[i] = -0.0,
                    _ => {}
                }
            }
        }
        f
    }

    #[test]
    fn classes_are_the_per_pixel_definition_bitwise() {
        let mut seen = [0usize; 5];
        for (k, (w, h)) in [(5u32, 5u32), (7, 9), (40, 33), (61, 47), (96, 20)]
            .into_iter()
            .enumerate()
        {
            let f = film(w, h, k as u64);
            let (w, h) = (w as usize, h as usize);
            for size in [0.5, 2.0, 7.0] {
                let want: Vec<Interior> = (0..w * h)
                    .map(|p| reference(&f, p % w, p / w, size))
                    .collect();
                // Whole film at once, and in bands of several heights (the
                // band edges change which rows one pass reads).
                for band in [h, 1, 3, 16] {
                    let mut got = vec![Interior::Straddles; w * h];
                    for y0 in (0..h).step_by(band) {
                        let y1 = (y0 + band).min(h);
                        classify_rows(&f, y0, y1, size, &mut got[y0 * w..y1 * w]);
                    }
                    for p in 0..w * h {
                        assert_eq!(got[p], want[p], "{w}x{h} size {size} band {band} at {p}");
                    }
                }
                for c in &want {
                    seen[*c as usize] += 1;
                }
            }
        }
        // The films exercise every class.
        assert!(seen.iter().all(|&n| n > 300), "{seen:?}");
    }
}
