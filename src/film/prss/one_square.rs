//! Whether a pixel's map provably stays inside one checker square: then
//! every sub-point has the centre's colour, and PRSS skips the sub-points
//! without changing a bit of the result.

use super::{Grid, cols, map_weights, rows};
use crate::filter::kernel::floor_fast;
use crate::scene::PrssMap;

/// True when the map over the whole pixel provably stays inside the checker
/// square of the centre: then every sub-point has the centre's colour.
pub(super) fn in_one_square(g: &Grid, map: PrssMap, size: f64) -> bool {
    // The map at t ∈ {-1/2, 0, 1/2}²: the quadrants' corners, whose hull holds
    // each bilinear quadrant; for the biquadratic, converted to the Bernstein
    // control points on the pixel, whose hull holds the patch.
    let w = [-0.5, 0.0, 0.5].map(|t| map_weights(map, t));
    let mut e = [[[0.0; 2]; 3]; 3];
    for (j, wy) in w.iter().enumerate() {
        let r = rows(g, wy);
        for (i, wx) in w.iter().enumerate() {
            e[j][i] = cols(&r, wx);
        }
    }
    match map {
        PrssMap::Bilinear => {}
        PrssMap::Biquadratic => {
            let mid = |l: [f64; 2], m: [f64; 2], r: [f64; 2]| {
                [
                    2.0 * m[0] - 0.5 * (l[0] + r[0]),
                    2.0 * m[1] - 0.5 * (l[1] + r[1]),
                ]
            };
            for row in e.iter_mut() {
                row[1] = mid(row[0], row[1], row[2]);
            }
            for i in 0..3 {
                e[1][i] = mid(e[0][i], e[1][i], e[2][i]);
            }
        }
        PrssMap::Bicubic => return bicubic_in_one_square(g, size),
    }
    // The box of the nine points, widened for the rounding of the points
    // and of the sub-points evaluated in it, as the bicubic test is.
    // A NaN hit makes every point NaN (each is a sum over all 25 taps,
    // zero weights included): the box stays empty (infinite bounds), which
    // `box_in_one_square`'s range test refuses, as it does infinite hits.
    let inv = 1.0 / size;
    (0..2).all(|k| {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for h in e.iter().flatten() {
            lo = lo.min(h[k]);
            hi = hi.max(h[k]);
        }
        let big = lo.abs().max(hi.abs());
        box_in_one_square(lo, hi, 1e-9 * (big + size), inv)
    })
}

/// [`in_one_square`] for the bicubic map, from the pixel's own footprint.
///
/// Per axis, Catmull-Rom between `p1` and `p2` is the straight line minus a
/// blend of the two second differences: `CR(a) = (1-a)p1 + a·p2 −
/// a(1−a)/2·[(1−a)(p0 − 2p1 + p2) + a(p1 − 2p2 + p3)]`, so over a half
/// pixel (`a ≤ 1/2`) it strays from the line by at most `1/8` of the larger
/// `|second difference|`. On a quadrant the map is the rows' Catmull-Rom in
/// `x` combined by Catmull-Rom in `y` (absolute weights summing to at most
/// `5/4`), which is the bilinear map of the quadrant's 2×2 hits, off by at
/// most `(1/8)·max|Δy²| + (5/32)·max|Δx²|` (or the same with the axes
/// swapped; the smaller is taken). The bilinear map stays inside the hull of
/// its values at the quadrant's corners, so the whole pixel stays inside the
/// box of the bilinear map at `t ∈ {−½, 0, ½}²` widened by that margin —
/// about the pixel's footprint on a smooth map, where the 4×4-block bound
/// this replaced was several footprints wide (sphere scene: 139k of 262k
/// pixels reached [`checker_average`](super::checker::checker_average) with it).
///
/// The box holds the centre hit, so when it lies in one square every
/// sub-point has the centre's colour and [`checker_average`](super::checker::checker_average) would return it
/// exactly: the answer changes no colour, only the work. A non-finite grid
/// (or one whose sum overflows) and values beyond the exact range of the
/// floors are never claimed.
fn bicubic_in_one_square(g: &Grid, size: f64) -> bool {
    let inv = 1.0 / size;
    // Both axes at once (see [`Lanes2`]); each lane's sum in the order of
    // `Iterator::sum` (from −0).
    let mut sum = [-0.0f64; 2];
    for p in g.iter().flatten() {
        sum = [sum[0] + p[0], sum[1] + p[1]];
    }
    if !(sum[0].is_finite() && sum[1].is_finite()) {
        return false;
    }
    let (lo, hi, bend, big) = footprint_box(|j, i| Lanes2(g[j][i]));
    // Widened a little more for the rounding of the sums.
    (0..2).all(|k| box_in_one_square(lo.0[k], hi.0[k], bend.0[k] + 1e-9 * (big.0[k] + size), inv))
}

/// Whether `[lo − m, hi + m]` (backdrop units; `inv` is one over the square
/// size) lies inside one checker square, within the exact range of the
/// floors (NaN fails the range test).
pub(super) fn box_in_one_square(lo: f64, hi: f64, m: f64, inv: f64) -> bool {
    let (a, b) = ((lo - m) * inv, (hi + m) * inv);
    a.abs() < 4.0e15 && b.abs() < 4.0e15 && floor_fast(a) == floor_fast(b)
}

/// The arithmetic [`footprint_box`] needs: the `f64` test and the `f32` row
/// pass compute the same bound.
pub(in crate::film) trait Real:
    Copy + std::ops::Add<Output = Self> + std::ops::Sub<Output = Self> + std::ops::Mul<Output = Self>
{
    /// `v`, exactly (the constants used are dyadic).
    fn of(v: f32) -> Self;
    fn abs(self) -> Self;
    /// `max`/`min` as a compare and select, `self` kept unless `other`
    /// beats it (NaN-blind: callers rule NaN out).
    fn max(self, other: Self) -> Self;
    fn min(self, other: Self) -> Self;
}

/// [`Real`] for the float types: `max`/`min` as a compare and select.
macro_rules! real_float {
    ($($t:ty),*) => {$(
        impl Real for $t {
            #[inline(always)]
            fn of(v: f32) -> $t {
                <$t>::from(v)
            }
            #[inline(always)]
            fn abs(self) -> $t {
                <$t>::abs(self)
            }
            #[inline(always)]
            fn max(self, other: $t) -> $t {
                if self > other { self } else { other }
            }
            #[inline(always)]
            fn min(self, other: $t) -> $t {
                if self < other { self } else { other }
            }
        }
    )*};
}

real_float!(f64, f32);

/// Both coordinates of a hit as one [`Real`], lane by lane:
/// [`bicubic_in_one_square`] runs the two axes' chains of sums and compares
/// side by side, each lane doing what `f64` does alone. One axis after the
/// other the test was bound by those chains' latency (timed inside the PRSS
/// stage on the teapot: about 530 cycles a pixel).
#[derive(Clone, Copy)]
struct Lanes2([f64; 2]);

impl std::ops::Add for Lanes2 {
    type Output = Lanes2;
    #[inline(always)]
    fn add(self, o: Lanes2) -> Lanes2 {
        Lanes2([self.0[0] + o.0[0], self.0[1] + o.0[1]])
    }
}

impl std::ops::Sub for Lanes2 {
    type Output = Lanes2;
    #[inline(always)]
    fn sub(self, o: Lanes2) -> Lanes2 {
        Lanes2([self.0[0] - o.0[0], self.0[1] - o.0[1]])
    }
}

impl std::ops::Mul for Lanes2 {
    type Output = Lanes2;
    #[inline(always)]
    fn mul(self, o: Lanes2) -> Lanes2 {
        Lanes2([self.0[0] * o.0[0], self.0[1] * o.0[1]])
    }
}

impl Real for Lanes2 {
    #[inline(always)]
    fn of(v: f32) -> Lanes2 {
        Lanes2([v as f64; 2])
    }
    #[inline(always)]
    fn abs(self) -> Lanes2 {
        Lanes2(self.0.map(f64::abs))
    }
    #[inline(always)]
    fn max(self, o: Lanes2) -> Lanes2 {
        Lanes2(std::array::from_fn(|k| {
            <f64 as Real>::max(self.0[k], o.0[k])
        }))
    }
    #[inline(always)]
    fn min(self, o: Lanes2) -> Lanes2 {
        Lanes2(std::array::from_fn(|k| {
            <f64 as Real>::min(self.0[k], o.0[k])
        }))
    }
}

/// One coordinate of the bicubic map over a pixel, from its 5×5 grid
/// `at(j, i)` (see [`bicubic_in_one_square`] for why): `(lo, hi)`, the box of
/// the bilinear map at the pixel's corners, edge midpoints and centre; `bend`,
/// how far the bicubic map strays from it; and the grid's largest `|value|`,
/// to scale the rounding slack by.
#[inline(always)]
pub(in crate::film) fn footprint_box<R: Real>(at: impl Fn(usize, usize) -> R) -> (R, R, R, R) {
    let zero = R::of(0.0);
    let mut big = zero;
    for j in 0..5 {
        for i in 0..5 {
            big = big.max(at(j, i).abs());
        }
    }
    // Largest |second difference| across x (dx) and down y (dy), at the 3×3
    // centres of all five rows or columns (`…5`) or of the middle three
    // (`…3`).
    let two = R::of(2.0);
    let (mut dx5, mut dx3, mut dy5, mut dy3) = (zero, zero, zero, zero);
    for a in 0..5 {
        for b in 1..4 {
            let ddx = (at(a, b - 1) - two * at(a, b) + at(a, b + 1)).abs();
            let ddy = (at(b - 1, a) - two * at(b, a) + at(b + 1, a)).abs();
            dx5 = dx5.max(ddx);
            dy5 = dy5.max(ddy);
            if (1..4).contains(&a) {
                dx3 = dx3.max(ddx);
                dy3 = dy3.max(ddy);
            }
        }
    }
    let (eighth, five_32) = (R::of(0.125), R::of(5.0 / 32.0));
    let bend = (dy3 * eighth + dx5 * five_32).min(dx3 * eighth + dy5 * five_32);
    let (half, quarter) = (R::of(0.5), R::of(0.25));
    let c = at(2, 2);
    let (mut lo, mut hi) = (c, c);
    for (sy, sx) in [(1, 1), (1, 3), (3, 1), (3, 3)] {
        let (ex, ey) = (at(2, sx), at(sy, 2));
        for p in [
            half * (c + ex),
            half * (c + ey),
            quarter * ((c + ex) + (ey + at(sy, sx))),
        ] {
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    (lo, hi, bend, big)
}
