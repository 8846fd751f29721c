//! The checkerboard averaged over a pixel's sub-points: the interpolated map
//! scaled to square units once, each sub-point a parity of two floors, a
//! chunk of sub-points at a time in vectors where the CPU rounds in them.

use super::{CHUNK, Grid, Taps, cols, rows};
use crate::filter::kernel::floor_fast;

/// The average of a checkerboard over the sub-points `taps` of the map `g`:
/// the map is scaled to square units once, so each sub-point costs two
/// floors and a parity instead of two divisions and a colour lookup, and
/// only the odd squares are counted (two colours: the mean is a mix).
///
/// With SIMD (AVX2 or AVX-512) a row's sub-points go [`CHUNK`] at a time:
/// the columns combine as vectors, the floors are rounding instructions and
/// each coordinate's parity is `f - 2⌊f/2⌋` in floats — the same count as the
/// integer parity for every input (tested, NaN and huge values included).
pub(super) fn checker_average(
    g: &Grid,
    taps: &Taps,
    size: f64,
    colors: &[[f32; 3]; 2],
) -> [f32; 3] {
    checker_average_on::<BOTH>(g, taps, size, colors)
}

/// Which coordinates of the map [`odd_count`] computes: the others are
/// taken as 0, an even floor, and the caller accounts for their parity.
pub(super) const U: u8 = 1;
pub(super) const V: u8 = 2;
pub(super) const BOTH: u8 = U | V;

/// [`checker_average`] computing only the coordinates in `AXES`. With one
/// (`U`: only `u` may cross into another square; `V`: only `v`), the map
/// must provably stay in the centre's row (or column) of squares over the
/// pixel, as [`Interior::StraddlesU`](crate::film::interior::Interior::StraddlesU) and
/// [`Interior::StraddlesV`](crate::film::interior::Interior::StraddlesV) claim:
/// then each sub-point's parity is its moving coordinate's, flipped when
/// the fixed coordinate's floor (the centre's, which every sub-point
/// shares) is odd: the same count from the same sums, for about half the
/// arithmetic. Most straddling pixels cross one grid line (35k of the
/// sphere's 51k); single thread, its PRSS stage 22.96–23.48 → 22.48–22.87
/// ms (BENCHMARKS.md).
#[inline(always)]
pub(super) fn checker_average_on<const AXES: u8>(
    g: &Grid,
    taps: &Taps,
    size: f64,
    colors: &[[f32; 3]; 2],
) -> [f32; 3] {
    let inv = 1.0 / size;
    // In place: `Grid::map` left its closures out of line.
    let mut gs: Grid = *g;
    for p in gs.iter_mut().flatten() {
        *p = [p[0] * inv, p[1] * inv];
    }
    let n = taps.t.len();
    let isa = crate::simd::Isa::current();
    let mut odd = crate::with_isa!(isa, L, _M => if L >= 4 {
        odd_count_chunked::<L, AXES>(&gs, taps)
    } else {
        odd_count::<AXES>(&gs, taps)
    });
    // A fixed coordinate's floor (the centre's: all sub-points share it)
    // flips every parity when odd.
    let fixed_odd = (0..2).any(|k| AXES & (1 << k) == 0 && floor_fast(gs[2][2][k]) & 1 == 1);
    if fixed_odd {
        odd = n * n - odd;
    }
    let even = n * n - odd;
    std::array::from_fn(|k| {
        ((colors[0][k] as f64 * even as f64 + colors[1][k] as f64 * odd as f64) / (n * n) as f64)
            as f32
    })
}

/// The checkerboard's square parity at every sub-point of `taps` of the map
/// `g`, a row of sub-points per word (bit `ix` of word `jy`): the points
/// [`rows`] and [`cols`] give, bit for bit (the same sums in the same
/// order, a chunk of sub-points at a time), and the parity of
/// `⌊u/size⌋ + ⌊v/size⌋` from the same divisions as [`Backdrop::color`](crate::scene::Backdrop::color), by
/// [`crate::simd::odd_floor_sum_mask`].
pub(super) fn checker_parities(g: &Grid, taps: &Taps, size: f64) -> Vec<u64> {
    let isa = crate::simd::Isa::current();
    crate::with_isa!(isa, L, _M => checker_parities_in::<L>(g, taps, size))
}

#[inline(always)]
fn checker_parities_in<const L: usize>(g: &Grid, taps: &Taps, size: f64) -> Vec<u64> {
    let n = taps.t.len();
    let mut out = Vec::with_capacity(n);
    for wy in &taps.w {
        let r = rows(g, wy);
        let mut row = 0u64;
        for (c, wc) in taps.w_chunks.iter().enumerate() {
            let (mut hx, mut hy) = ([0.0f64; CHUNK], [0.0f64; CHUNK]);
            for (i, ri) in r.iter().enumerate() {
                for m in 0..CHUNK {
                    hx[m] += wc[i][m] * ri[0];
                    hy[m] += wc[i][m] * ri[1];
                }
            }
            let (qx, qy) = (hx.map(|h| h / size), hy.map(|h| h / size));
            // SAFETY: L == 8 only under Isa::Avx512 (`with_isa!`).
            let mask = unsafe { crate::simd::odd_floor_sum_mask::<L>(&qx, &qy) };
            let valid = (n - c * CHUNK).min(CHUNK);
            row |= (mask as u64 & ((1u64 << valid) - 1)) << (c * CHUNK);
        }
        out.push(row);
    }
    out
}

/// Sub-points of `taps` on odd squares of the unit checkerboard, one at a
/// time with integer floors (no rounding instruction on the x86-64 baseline).
fn odd_count<const AXES: u8>(gs: &Grid, taps: &Taps) -> usize {
    let n = taps.t.len();
    let mut odd = 0usize;
    for jy in 0..n {
        let r = rows(gs, &taps.w[jy]);
        for ix in 0..n {
            let h = cols(&r, &taps.w[ix]);
            let f = |k: usize| {
                if AXES & (1 << k) != 0 {
                    floor_fast(h[k])
                } else {
                    0
                }
            };
            odd += (f(0).wrapping_add(f(1)) & 1) as usize;
        }
    }
    odd
}

/// [`odd_count`] a chunk of sub-points at a time, as vectors; only inside a
/// function compiled with a rounding instruction, `L` being that
/// instruction set's lanes (`with_isa!`, see [`checker_average`]): the
/// parities come from [`crate::simd::odd_floor_sum_mask`].
/// The rows of the grid combine for [`CHUNK`] sub-point rows at once (lane
/// `k` is row `cy·CHUNK + k`), then each row's columns for a chunk of
/// sub-points; the sums run in the order of [`rows`] and [`cols`].
/// Only the coordinates in `AXES` are computed; the others stay 0 (even).
#[inline(always)]
fn odd_count_chunked<const L: usize, const AXES: u8>(gs: &Grid, taps: &Taps) -> usize {
    let n = taps.t.len();
    let (du, dv) = (AXES & U != 0, AXES & V != 0);
    let mut odd = 0usize;
    for (cy, wy) in taps.w_chunks.iter().enumerate() {
        // r[i][axis][k]: Σ_j wy[j][k] gs[j][i][axis].
        let mut r = [[[0.0f64; CHUNK]; 2]; 5];
        for (j, row) in gs.iter().enumerate() {
            for (ri, p) in r.iter_mut().zip(row) {
                for k in 0..CHUNK {
                    if du {
                        ri[0][k] += wy[j][k] * p[0];
                    }
                    if dv {
                        ri[1][k] += wy[j][k] * p[1];
                    }
                }
            }
        }
        for k in 0..(n - cy * CHUNK).min(CHUNK) {
            for (c, wc) in taps.w_chunks.iter().enumerate() {
                let (mut hx, mut hy) = ([0.0f64; CHUNK], [0.0f64; CHUNK]);
                for (i, ri) in r.iter().enumerate() {
                    for m in 0..CHUNK {
                        if du {
                            hx[m] += wc[i][m] * ri[0][k];
                        }
                        if dv {
                            hy[m] += wc[i][m] * ri[1][k];
                        }
                    }
                }
                let live = (n - c * CHUNK).min(CHUNK);
                let live_mask = ((1u16 << live) - 1) as u8;
                // SAFETY: L == 8 only under Isa::Avx512 (`with_isa!`).
                let mask = unsafe { crate::simd::odd_floor_sum_mask::<L>(&hx, &hy) };
                odd += (mask & live_mask).count_ones() as usize;
            }
        }
    }
    odd
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::PrssMap;

    #[test]
    fn vector_checker_count_matches_the_integer_count() {
        let mut rng = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng >> 11) as f64 / (1u64 << 53) as f64
        };
        let specials = [f64::NAN, f64::INFINITY, -1e300, 3e18, -9.3e15, 4.5e15 + 1.0];
        for n in [1, 3, 8, 11, 16] {
            for map in [PrssMap::Bilinear, PrssMap::Biquadratic, PrssMap::Bicubic] {
                let taps = Taps::new(n, map);
                for case in 0..200 {
                    let scale = [0.3, 2.0, 40.0][case % 3];
                    let mut g: Grid = std::array::from_fn(|j| {
                        std::array::from_fn(|i| {
                            [
                                scale * (i as f64 + next() - 2.5),
                                scale * (j as f64 + next() - 2.5),
                            ]
                        })
                    });
                    if case % 7 == 0 {
                        g[case % 5][(case / 5) % 5][case % 2] = specials[case % specials.len()];
                    }
                    let want = odd_count::<BOTH>(&g, &taps);
                    // One coordinate alone counts as both with the other
                    // zeroed (an even floor at every sub-point).
                    let zeroed = |k: usize| {
                        let mut z = g;
                        z.iter_mut().flatten().for_each(|p| p[k] = 0.0);
                        odd_count::<BOTH>(&z, &taps)
                    };
                    let (want_u, want_v) = (zeroed(1), zeroed(0));
                    assert_eq!(
                        odd_count::<U>(&g, &taps),
                        want_u,
                        "n {n} {map:?} case {case}"
                    );
                    assert_eq!(
                        odd_count::<V>(&g, &taps),
                        want_v,
                        "n {n} {map:?} case {case}"
                    );
                    for isa in crate::simd::Isa::available() {
                        let (got, got_u, got_v) = crate::with_isa!(isa, L, _M => (
                            odd_count_chunked::<L, BOTH>(&g, &taps),
                            odd_count_chunked::<L, U>(&g, &taps),
                            odd_count_chunked::<L, V>(&g, &taps),
                        ));
                        assert_eq!(got, want, "{isa:?} n {n} {map:?} case {case}");
                        assert_eq!(got_u, want_u, "{isa:?} n {n} {map:?} case {case} u");
                        assert_eq!(got_v, want_v, "{isa:?} n {n} {map:?} case {case} v");
                    }
                }
            }
        }
    }
}
