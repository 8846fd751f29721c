//! The `blend` fallback's colour of a boundary pixel: each sub-point shows
//! its own surface or a neighbour's, split by a straight boundary line
//! ([`super::edge`]) or shared by the bilinear hats of the four pixel
//! centres around it; a neighbour off the pixel's piece shows its own hit
//! moved by its own Jacobian ([`Look`]). The sums run over bands of
//! sub-points as bit masks ([`HatBand`]), in lanes over a checkerboard.

use crate::scene::{Backdrop, Pattern};

use super::super::hitmap::{HitMap, Jacobian, Neighbour};
use super::edge::EdgeLine;
use super::one_square::box_in_one_square;
use super::{Ctx, cols, sub_points};

/// The sub-points of [`Ctx::blend`] (the map's, [`sub_points`]) and their
/// bilinear hats: sub-point offset `t` lies toward neighbour `side` (±1) at
/// `a = |t|`; the hats themselves in [`HatBand`]s.
pub(super) struct Hats {
    t: Vec<f64>,
    side: Vec<i64>,
    bands: Vec<HatBand>,
}

impl Hats {
    pub(super) fn new(n: usize) -> Hats {
        let t = sub_points(n);
        let side: Vec<i64> = t.iter().map(|&t| if t < 0.0 { -1 } else { 1 }).collect();
        Hats {
            bands: HatBand::bands(&t, &side),
            side,
            t,
        }
    }
}

/// Whole rows of sub-points, at most 64 of them, for [`Ctx::blend`]'s sums:
/// sub-point `(ix, jy)` is bit `(jy − rows.start)·n + ix` of a mask.
struct HatBand {
    rows: std::ops::Range<usize>,
    /// The sub-points toward each side, `[y side][x side]` (−1, +1).
    quadrant: [[u64; 2]; 2],
    /// The bilinear hats at each sub-point, with `a = |tx|`, `b = |ty|`:
    /// of the pixel itself `(1−a)(1−b)`, of its x neighbour `a(1−b)`, of
    /// its y neighbour `(1−a)b` and of its diagonal neighbour `ab`.
    hat: [[f64; 64]; 4],
    /// The sub-points where each hat is not zero.
    nonzero: [u64; 4],
    /// The hats' sums of [`Ctx::blend`] in lanes: lane `4q + r` is hat `r`
    /// over quadrant `q = 2·(y side) + (x side)`, and step `k` adds each
    /// quadrant's `k`-th sub-point (lowest first, as [`bits`] visits them;
    /// past a quadrant's last, weight 0 at bit 0). So every lane adds its
    /// weights in the order the per-mask sums did, to the same bits (an
    /// empty sum aside: +0 where they gave −0, which adds nothing to a
    /// colour).
    lanes: Vec<HatStep>,
}

/// One step of [`HatBand::lanes`]: per lane the sub-point's bit and weight.
struct HatStep {
    bit: [u64; 16],
    hat: [f64; 16],
}

impl HatBand {
    fn bands(t: &[f64], side: &[i64]) -> Vec<HatBand> {
        let n = t.len();
        let per_band = (64 / n.max(1)).max(1);
        (0..n)
            .step_by(per_band)
            .map(|start| {
                let rows = start..(start + per_band).min(n);
                let mut band = HatBand {
                    rows: rows.clone(),
                    quadrant: [[0; 2]; 2],
                    hat: [[0.0; 64]; 4],
                    nonzero: [0; 4],
                    lanes: Vec::new(),
                };
                for jy in rows {
                    for ix in 0..n {
                        let bit = (jy - start) * n + ix;
                        let (a, b) = (t[ix].abs(), t[jy].abs());
                        let hats = [(1.0 - a) * (1.0 - b), a * (1.0 - b), (1.0 - a) * b, a * b];
                        for (r, w) in hats.into_iter().enumerate() {
                            band.hat[r][bit] = w;
                            band.nonzero[r] |= ((w != 0.0) as u64) << bit;
                        }
                        let half = |s: i64| (s > 0) as usize;
                        band.quadrant[half(side[jy])][half(side[ix])] |= 1 << bit;
                    }
                }
                let quadrants = band.quadrant.concat();
                let longest = quadrants.iter().map(|q| q.count_ones()).max();
                band.lanes = (0..longest.unwrap_or(0) as usize)
                    .map(|k| {
                        let mut step = HatStep {
                            bit: [0; 16],
                            hat: [0.0; 16],
                        };
                        for (q, &quadrant) in quadrants.iter().enumerate() {
                            if let Some(b) = bits(quadrant).nth(k) {
                                for r in 0..4 {
                                    step.bit[4 * q + r] = b as u64;
                                    step.hat[4 * q + r] = band.hat[r][b];
                                }
                            }
                        }
                        step
                    })
                    .collect();
                band
            })
            .collect()
    }
}

/// The ring-1 neighbours of a pixel, classified (index `[dy + 1][dx + 1]`).
pub(super) struct Ring {
    n: [[Neighbour; 3]; 3],
}

impl Ring {
    pub(super) fn new(map: &HitMap, x: i64, y: i64, centre: Option<f32>) -> Ring {
        let mut n = [[Neighbour::Same; 3]; 3];
        for (j, row) in n.iter_mut().enumerate() {
            for (i, c) in row.iter_mut().enumerate() {
                *c = map.neighbour(x + i as i64 - 1, y + j as i64 - 1, centre);
            }
        }
        Ring { n }
    }

    pub(super) fn all_same(&self) -> bool {
        self.n.iter().flatten().all(|c| *c == Neighbour::Same)
    }

    /// What neighbour `(ox, oy)` (not on the centre's piece) shows over the
    /// centre pixel: its own surface, its hit moved by its own Jacobian.
    fn look(
        &self,
        map: &HitMap,
        x: i64,
        y: i64,
        (ox, oy): (i64, i64),
        backdrop: &Backdrop,
        background: [f32; 3],
    ) -> Look {
        let (i, j) = ((ox + 1) as usize, (oy + 1) as usize);
        match self.n[j][i] {
            Neighbour::Same => unreachable!("handled by the caller"),
            Neighbour::NoHit => Look::Fixed(background),
            Neighbour::Other(hit, ev) => {
                let jac = map.jacobian(x + ox, y + oy, hit, ev);
                // The affine map over the pixel's square lies in the box of
                // its four corners: one colour if that is in one square.
                let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
                for (a, b) in [(-0.5, -0.5), (0.5, -0.5), (-0.5, 0.5), (0.5, 0.5)] {
                    let h = jac.apply(hit, a - ox as f64, b - oy as f64);
                    for k in 0..2 {
                        lo[k] = lo[k].min(h[k]);
                        hi[k] = hi[k].max(h[k]);
                    }
                }
                match checker_flat(backdrop, lo, hi) {
                    Some(c) => Look::Fixed(c),
                    None => Look::Moved {
                        hit,
                        jac,
                        at: [ox as f64, oy as f64],
                    },
                }
            }
        }
    }
}

/// What a neighbour off the centre's piece shows over the centre pixel
/// ([`Ring::look`]), resolved before a loop over sub-points.
#[derive(Clone, Copy)]
enum Look {
    /// One colour everywhere: the background, or a surface that stays in
    /// one checker square.
    Fixed([f32; 3]),
    /// The neighbour's hit (at pixel offset `at`) moved by its Jacobian.
    Moved {
        hit: [f64; 2],
        jac: Jacobian,
        at: [f64; 2],
    },
    /// A moved surface over a checkerboard, tabulated: bit `jy·n + ix` is
    /// the square parity at sub-point `(ix, jy)` of `n` per axis.
    Parities {
        odd: u64,
        n: usize,
        colors: [[f32; 3]; 2],
    },
}

impl Look {
    /// The colour at sub-point `(ix, jy)`, offset `(tx, ty)` from the centre
    /// pixel's centre (one at a time: the definition the tabulated and
    /// banded sums are tested against).
    #[cfg(test)]
    fn color(
        &self,
        (ix, jy): (usize, usize),
        (tx, ty): (f64, f64),
        backdrop: &Backdrop,
    ) -> [f32; 3] {
        match *self {
            Look::Fixed(c) => c,
            Look::Moved { hit, jac, at } => {
                let h = jac.apply(hit, tx - at[0], ty - at[1]);
                backdrop.color(h[0], h[1])
            }
            Look::Parities { odd, n, colors } => colors[(odd >> (jy * n + ix) & 1) as usize],
        }
    }

    /// The colours over `band`.
    fn band(&self, band: &HatBand) -> BandColors<'static> {
        match *self {
            Look::Fixed(c) => BandColors::Flat(c),
            Look::Moved { hit, jac, at } => BandColors::Moved { hit, jac, at },
            // At most 8 per axis: one band, all the bits.
            Look::Parities { odd, n, colors } => {
                BandColors::Parities(odd >> (band.rows.start * n), colors)
            }
        }
    }

    /// A moved surface over a checkerboard with at most 8 sub-points per
    /// axis (offsets `t`), as its table of parities — each the colour
    /// `Look::color` (the tests' definition) of `Moved` gives, bit for bit (the same points,
    /// divisions and floors, a row of sub-points per vector; tested) —
    /// so the sub-point loop reads a bit instead of dividing and flooring.
    fn tabulated(self, t: &[f64], backdrop: &Backdrop) -> Look {
        match (self, &backdrop.pattern) {
            (Look::Moved { hit, jac, at }, Pattern::Checker { size, colors }) if t.len() <= 8 => {
                let isa = crate::simd::Isa::current();
                let odd =
                    crate::with_isa!(isa, L, _M => moved_parities::<L>(hit, &jac, at, t, *size));
                Look::Parities {
                    odd,
                    n: t.len(),
                    colors: *colors,
                }
            }
            (look, _) => look,
        }
    }
}

/// [`Look::tabulated`]'s table: for each row of sub-points, the points
/// `Jacobian::apply` gives, over the square size, and their parities by
/// [`crate::simd::odd_floor_sum_mask`] (the floors of [`Backdrop::color`]).
#[inline(always)]
fn moved_parities<const L: usize>(
    hit: [f64; 2],
    jac: &Jacobian,
    at: [f64; 2],
    t: &[f64],
    size: f64,
) -> u64 {
    let n = t.len();
    let [jx, jy] = jac.or_zero();
    let a: [f64; 8] = std::array::from_fn(|m| t.get(m).map_or(0.0, |&tx| tx - at[0]));
    let mut odd = 0u64;
    for (row, &ty) in t.iter().enumerate() {
        let b = ty - at[1];
        let (mut qx, mut qy) = ([0.0f64; 8], [0.0f64; 8]);
        for m in 0..8 {
            qx[m] = (hit[0] + a[m] * jx[0] + b * jy[0]) / size;
            qy[m] = (hit[1] + a[m] * jx[1] + b * jy[1]) / size;
        }
        // SAFETY: L == 8 only under Isa::Avx512 (`with_isa!`).
        let mask = unsafe { crate::simd::odd_floor_sum_mask::<L>(&qx, &qy) };
        odd |= (mask as u64 & ((1u64 << n) - 1)) << (row * n);
    }
    odd
}

/// The colour of a checkerboard over the box `lo..=hi` (backdrop units)
/// when the box, widened by `1e-9` of its coordinates and the square for
/// the rounding of the points in it, lies inside one square: then every
/// point of the box has that colour, exactly as [`Backdrop::color`] gives
/// it. `None` for a photograph, a box across squares, or non-finite or
/// out-of-range bounds.
fn checker_flat(backdrop: &Backdrop, lo: [f64; 2], hi: [f64; 2]) -> Option<[f32; 3]> {
    let Pattern::Checker { size, .. } = &backdrop.pattern else {
        return None;
    };
    let inv = 1.0 / size;
    let one = (0..2).all(|k| {
        let m = 1e-9 * (lo[k].abs() + hi[k].abs() + size);
        box_in_one_square(lo[k], hi[k], m, inv)
    });
    one.then(|| backdrop.color(0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])))
}

impl Ctx<'_> {
    /// Mean over the sub-points of the colour blended from the pixel's own
    /// surface `own` and its neighbours' surfaces. With a boundary `line`,
    /// each sub-point belongs to the side of the line it lies on (the other
    /// side: the nearest neighbour not on the pixel's piece); without one, it
    /// is shared by the bilinear hats of the four pixel centres around it.
    /// Also returns the own surface's total weight.
    ///
    /// The sums run per surface over a band of sub-points at once (all 64
    /// at the default 8 per axis, [`HatBand`]): the surface's sub-points as
    /// a bit mask — a quadrant under one hat, or a side of the line — and
    /// one sum of their weighted colours, a weight total per colour where
    /// the surface shows one or two ([`BandColors`]). Summed a sub-point at
    /// a time, with up to four lookups each, a blended pixel took 1.4 µs
    /// (teapot, single thread: half the PRSS stage, measured by skipping the
    /// sums).
    pub(super) fn blend(
        &self,
        x: i64,
        y: i64,
        ring: &Ring,
        line: Option<EdgeLine>,
        own: &Own,
    ) -> ([f32; 3], f64) {
        let h = &self.hats;
        let n = h.t.len();
        let mut acc = [0.0f64; 3];
        let mut own_total = 0.0;
        let same_at: [[bool; 3]; 3] = ring.n.map(|row| row.map(|c| c == Neighbour::Same));
        let is_same = |(ox, oy): (i64, i64)| same_at[(oy + 1) as usize][(ox + 1) as usize];
        // Each neighbour off the piece is looked up once, on first use, and
        // tabulated for the sub-points.
        let mut looks: [[Option<Look>; 3]; 3] = [[None; 3]; 3];
        let mut add = |sum: [f64; 3]| {
            for k in 0..3 {
                acc[k] += sum[k];
            }
        };
        for band in &h.bands {
            let start = band.rows.start;
            let own_colors = match own {
                Own::Flat(c) => BandColors::Flat(*c),
                Own::Parities { rows, colors } => BandColors::Parities(
                    rows[band.rows.clone()]
                        .iter()
                        .enumerate()
                        .fold(0, |m, (k, &row)| m | row << (k * n)),
                    *colors,
                ),
                Own::Rows(rows) => BandColors::Photo(&rows[band.rows.clone()]),
            };
            let mut look_colors = |o: (i64, i64)| {
                looks[(o.1 + 1) as usize][(o.0 + 1) as usize]
                    .get_or_insert_with(|| {
                        ring.look(&self.map, x, y, o, self.backdrop, self.background)
                            .tabulated(&h.t, self.backdrop)
                    })
                    .band(band)
            };
            let Some(l) = line else {
                // Each quadrant's four hats: toward the pixel itself, its x
                // and y neighbours on the quadrant's sides, and the diagonal
                // (lane `4q + r`, as in [`HatBand::lanes`]).
                let mut lanes: [Option<(BandColors, bool)>; 16] = [None; 16];
                for (qy, sy) in [(0, -1), (1, 1)] {
                    for (qx, sx) in [(0, -1), (1, 1)] {
                        let quadrant = band.quadrant[qy][qx];
                        for (r, o) in [(0, (0, 0)), (1, (sx, 0)), (2, (0, sy)), (3, (sx, sy))] {
                            if quadrant & band.nonzero[r] != 0 {
                                let own = is_same(o);
                                let colors = if own { own_colors } else { look_colors(o) };
                                lanes[4 * (2 * qy + qx) + r] = Some((colors, own));
                            }
                        }
                    }
                }
                match checker_lanes(&lanes) {
                    // Over a checkerboard (the common case): every lane's
                    // weights at once, split by parity.
                    Some((odd, colors)) => {
                        let isa = crate::simd::Isa::current();
                        let (even_w, odd_w) =
                            crate::with_isa!(isa, _L, _M => hat_sums(&band.lanes, &odd));
                        for (k, lane) in lanes.iter().enumerate() {
                            if let Some((_, own)) = lane {
                                let [even_c, odd_c] = colors[k];
                                let (we, wo) = (even_w[k], odd_w[k]);
                                let (e, o) =
                                    (even_c.map(|v| we * v as f64), odd_c.map(|v| wo * v as f64));
                                if *own {
                                    own_total += we + wo;
                                }
                                add(std::array::from_fn(|c| e[c] + o[c]));
                            }
                        }
                    }
                    None => {
                        for (k, lane) in lanes.iter().enumerate() {
                            if let Some((colors, own)) = *lane {
                                let (quadrant, r) = (band.quadrant[k / 8][k / 4 % 2], k % 4);
                                let mask = quadrant & band.nonzero[r];
                                let (sum, total) =
                                    self.band_sum(band, colors, mask, Some(&band.hat[r]));
                                if own {
                                    own_total += total;
                                }
                                add(sum);
                            }
                        }
                    }
                }
                continue;
            };
            let mut own_mask = 0u64;
            let mut masks = [[0u64; 3]; 3];
            for jy in band.rows.clone() {
                let (sy, ty) = (h.side[jy], h.t[jy]);
                for ix in 0..n {
                    let (sx, tx) = (h.side[ix], h.t[ix]);
                    let bit = (jy - start) * n + ix;
                    if l.d + l.n[0] * tx + l.n[1] * ty >= 0.0 {
                        own_mask |= 1 << bit;
                        continue;
                    }
                    let offs = [(0, 0), (sx, 0), (0, sy), (sx, sy)];
                    let hats = std::array::from_fn(|q| band.hat[q][bit]);
                    let pick = other_side(offs, hats, &same_at, (tx, ty));
                    match pick {
                        Some((ox, oy)) => masks[(oy + 1) as usize][(ox + 1) as usize] |= 1 << bit,
                        None => own_mask |= 1 << bit,
                    }
                }
            }
            if own_mask != 0 {
                let (sum, total) = self.band_sum(band, own_colors, own_mask, None);
                own_total += total;
                add(sum);
            }
            for (j, row) in masks.iter().enumerate() {
                for (i, &mask) in row.iter().enumerate() {
                    if mask != 0 {
                        let o = (i as i64 - 1, j as i64 - 1);
                        add(self.band_sum(band, look_colors(o), mask, None).0);
                    }
                }
            }
        }
        let m = (n * n) as f64;
        (acc.map(|v| (v / m) as f32), own_total / m)
    }

    /// The colours of `colors` at the band's sub-points in `mask`, weighted
    /// by `w` (per sub-point; `None`: all 1), summed; and the weights' sum.
    #[inline]
    fn band_sum(
        &self,
        band: &HatBand,
        colors: BandColors,
        mask: u64,
        w: Option<&[f64; 64]>,
    ) -> ([f64; 3], f64) {
        let weight = |m: u64| match w {
            None => m.count_ones() as f64,
            Some(w) => bits(m).map(|i| w[i]).sum(),
        };
        let scaled = |c: [f32; 3], f: f64| c.map(|v| f * v as f64);
        match colors {
            BandColors::Flat(c) => {
                let total = weight(mask);
                (scaled(c, total), total)
            }
            BandColors::Parities(odd, [even_c, odd_c]) => {
                let (we, wo) = (weight(mask & !odd), weight(mask & odd));
                let (e, o) = (scaled(even_c, we), scaled(odd_c, wo));
                (std::array::from_fn(|k| e[k] + o[k]), we + wo)
            }
            BandColors::Moved { .. } | BandColors::Photo(_) => {
                let n = self.hats.t.len();
                let (mut sum, mut total) = ([0.0f64; 3], 0.0);
                for bit in bits(mask) {
                    let (ix, row) = (bit % n, bit / n);
                    let f = w.map_or(1.0, |w| w[bit]);
                    let c = match colors {
                        BandColors::Moved { hit, jac, at } => {
                            let ty = self.hats.t[band.rows.start + row];
                            let p = jac.apply(hit, self.hats.t[ix] - at[0], ty - at[1]);
                            self.backdrop.color(p[0], p[1])
                        }
                        BandColors::Photo(rows) => {
                            let p = cols(&rows[row], &self.taps.w[ix]);
                            self.backdrop.color(p[0], p[1])
                        }
                        _ => unreachable!("one colour or two are summed above"),
                    };
                    for k in 0..3 {
                        sum[k] += f * c[k] as f64;
                    }
                    total += f;
                }
                (sum, total)
            }
        }
    }
}

/// Whose surface a sub-point at offset `t` on the other side of a boundary
/// line shows: of its four surrounding pixel centres `offs` with hats `ws`,
/// the heaviest not on the pixel's piece (the last of equals); else the
/// nearest ring neighbour not on it (`same_at`, indexed `[dy + 1][dx + 1]`);
/// `None` when the whole ring is on it.
fn other_side(
    offs: [(i64, i64); 4],
    ws: [f64; 4],
    same_at: &[[bool; 3]; 3],
    (tx, ty): (f64, f64),
) -> Option<(i64, i64)> {
    let is_same = |(ox, oy): (i64, i64)| same_at[(oy + 1) as usize][(ox + 1) as usize];
    let mut pick: Option<((i64, i64), f64)> = None;
    for q in 0..4 {
        if ws[q] > 0.0 && !is_same(offs[q]) && pick.is_none_or(|(_, w)| ws[q] >= w) {
            pick = Some((offs[q], ws[q]));
        }
    }
    pick.map(|(o, _)| o).or_else(|| {
        let mut best: Option<((i64, i64), f64)> = None;
        for oy in -1..=1 {
            for ox in -1..=1 {
                if is_same((ox, oy)) {
                    continue;
                }
                let dd = (ox as f64 - tx).powi(2) + (oy as f64 - ty).powi(2);
                if best.is_none_or(|(_, b)| dd < b) {
                    best = Some(((ox, oy), dd));
                }
            }
        }
        best.map(|(o, _)| o)
    })
}

/// The lanes of [`Ctx::blend`]'s hats as square parities and their two
/// colours (one colour: no odd sub-point, the colour twice); `None` when a
/// lane's colours are not a checkerboard's (a moved surface, a photograph).
#[allow(clippy::type_complexity)]
fn checker_lanes(
    lanes: &[Option<(BandColors, bool)>; 16],
) -> Option<([u64; 16], [[[f32; 3]; 2]; 16])> {
    let mut odd = [0u64; 16];
    let mut colors = [[[0.0f32; 3]; 2]; 16];
    for (k, lane) in lanes.iter().enumerate() {
        match lane {
            None => {}
            Some((BandColors::Flat(c), _)) => colors[k] = [*c, *c],
            Some((BandColors::Parities(o, c), _)) => (odd[k], colors[k]) = (*o, *c),
            Some(_) => return None,
        }
    }
    Some((odd, colors))
}

/// Per lane, the hat weights of the sub-points on even and on odd squares
/// (bit clear and set in `odd`), each summed in [`HatBand::lanes`]' order —
/// what [`Ctx::band_sum`] sums over a lane's masks, bit for bit: a weight
/// that is not on a side adds an exact zero. Sixteen lanes in step (under
/// AVX-512, two registers) instead of sixteen chains of additions one
/// after another.
#[inline(always)]
fn hat_sums(steps: &[HatStep], odd: &[u64; 16]) -> ([f64; 16], [f64; 16]) {
    let (mut even_w, mut odd_w) = ([0.0f64; 16], [0.0f64; 16]);
    for step in steps {
        for k in 0..16 {
            let h = step.hat[k];
            let ho = if (odd[k] >> step.bit[k]) & 1 == 1 {
                h
            } else {
                0.0
            };
            odd_w[k] += ho;
            even_w[k] += h - ho;
        }
    }
    (even_w, odd_w)
}

/// The set bits of `m`, lowest first.
fn bits(mut m: u64) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (m != 0).then(|| {
            let i = m.trailing_zeros() as usize;
            m &= m - 1;
            i
        })
    })
}

/// The pixel's own surface under its sub-points, for [`Ctx::blend`].
pub(super) enum Own {
    /// One colour everywhere: the background (a pixel without a hit), or
    /// none wanted (the footprint mode adds its own filtered colour).
    Flat([f32; 3]),
    /// A checkerboard: bit `ix` of `rows[jy]` is the square parity at
    /// sub-point `(ix, jy)` ([`super::checker::checker_parities`]).
    Parities {
        rows: Vec<u64>,
        colors: [[f32; 3]; 2],
    },
    /// A photograph: the map's [`super::rows`] of each sub-point row.
    Rows(Vec<[[f64; 2]; 5]>),
}

/// A surface's colours over a band of sub-points, for [`Ctx::band_sum`].
#[derive(Clone, Copy)]
enum BandColors<'a> {
    Flat([f32; 3]),
    /// `colors[bit]` at each sub-point.
    Parities(u64, [[f32; 3]; 2]),
    /// A neighbour's hit moved by its Jacobian to each sub-point
    /// ([`Look::Moved`]).
    Moved {
        hit: [f64; 2],
        jac: Jacobian,
        at: [f64; 2],
    },
    /// The own map over a photograph: the band's [`super::rows`].
    Photo(&'a [[[f64; 2]; 5]]),
}

#[cfg(test)]
mod tests {
    use super::super::checker::checker_parities;
    use super::super::edge::edge_line;
    use super::super::tests::{checker, pieces_film, settings};
    use super::super::{PostStats, Taps, grid, rows};
    use super::*;
    use crate::scene::{PrssFallback, PrssMap};

    /// A tabulated moved surface shows, at every sub-point, the colour the
    /// moved hit gives there, for every instruction set: hits and Jacobians
    /// at several scales, missing derivatives, and NaN, infinite or huge
    /// values.
    #[test]
    fn tabulated_surface_matches_the_moved_hit() {
        let mut draws = 0u64;
        let mut next = || {
            draws += 1;
            crate::phantom::uniform(0x2545_f491, draws)
        };
        let specials = [f64::NAN, f64::INFINITY, -1e300, 3e18, -9.3e15, 4.5e15 + 1.0];
        let (mut checked, mut odd) = (0, 0);
        for n in 1..=8 {
            let t = sub_points(n);
            for case in 0..300 {
                let size = [24.0, 8.0, 0.3][case % 3];
                let scale = [0.1, 3.0, 50.0][case / 3 % 3];
                let mut hit = [1e3 * (next() - 0.5), 1e3 * (next() - 0.5)];
                let mut d = || Some([scale * (next() - 0.5), scale * (next() - 0.5)]);
                let jac = Jacobian {
                    dx: if case % 5 == 0 { None } else { d() },
                    dy: if case % 7 == 0 { None } else { d() },
                };
                if case % 11 == 0 {
                    hit[case % 2] = specials[case / 11 % specials.len()];
                }
                let at = [(case % 3) as f64 - 1.0, (case / 3 % 3) as f64 - 1.0];
                let backdrop = checker(size);
                let moved = Look::Moved { hit, jac, at };
                let tabulated = moved.tabulated(&t, &backdrop);
                assert!(matches!(tabulated, Look::Parities { .. }));
                for isa in crate::simd::Isa::available() {
                    let bits = crate::with_isa!(isa, L, _M => moved_parities::<L>(hit, &jac, at, &t, size));
                    for jy in 0..n {
                        for ix in 0..n {
                            let at_sub = (t[ix], t[jy]);
                            let want = moved.color((ix, jy), at_sub, &backdrop);
                            assert_eq!(tabulated.color((ix, jy), at_sub, &backdrop), want);
                            let Pattern::Checker { colors, .. } = &backdrop.pattern else {
                                unreachable!()
                            };
                            assert_eq!(
                                colors[(bits >> (jy * n + ix) & 1) as usize],
                                want,
                                "{isa:?} n {n} case {case}"
                            );
                            checked += 1;
                            odd += (want == colors[1]) as usize;
                        }
                    }
                }
            }
        }
        // Both colours occur: the comparison can fail.
        assert!(
            odd > checked / 4 && odd < 3 * checked / 4,
            "{odd} of {checked}"
        );
    }

    /// [`Ctx::blend`] by its definition: a sub-point at a time, each of its
    /// weights times its colour added in turn (`own(ix, jy)`: the own
    /// surface's colour at sub-point `(ix, jy)`).
    fn blend_each_sub_point(
        c: &Ctx,
        x: i64,
        y: i64,
        ring: &Ring,
        line: Option<EdgeLine>,
        mut own: impl FnMut(usize, usize) -> [f32; 3],
    ) -> ([f32; 3], f64) {
        let n = c.hats.t.len();
        let mut acc = [0.0f64; 3];
        let mut own_total = 0.0;
        let same_at: [[bool; 3]; 3] = ring.n.map(|row| row.map(|c| c == Neighbour::Same));
        let is_same = |(ox, oy): (i64, i64)| same_at[(oy + 1) as usize][(ox + 1) as usize];
        // Each neighbour off the piece is looked up once, on first use, and
        // tabulated for the sub-points (most it covers are many: a side of
        // the line, or a quadrant's hats).
        let mut looks: [[Option<Look>; 3]; 3] = [[None; 3]; 3];
        let mut color_of = |o: (i64, i64), sub: (usize, usize), t: (f64, f64)| {
            let look = looks[(o.1 + 1) as usize][(o.0 + 1) as usize].get_or_insert_with(|| {
                ring.look(&c.map, x, y, o, c.backdrop, c.background)
                    .tabulated(&c.hats.t, c.backdrop)
            });
            look.color(sub, t, c.backdrop)
        };
        for jy in 0..n {
            let (sy, b) = (c.hats.side[jy], c.hats.t[jy].abs());
            let ty = c.hats.t[jy];
            for ix in 0..n {
                let (sx, a) = (c.hats.side[ix], c.hats.t[ix].abs());
                let tx = c.hats.t[ix];
                // The four pixel centres around the sub-point and their
                // bilinear hats (plain arrays, indexed in a fixed loop, so
                // they stay in registers).
                let offs = [(0, 0), (sx, 0), (0, sy), (sx, sy)];
                let ws = [(1.0 - a) * (1.0 - b), a * (1.0 - b), (1.0 - a) * b, a * b];
                let mut same = 0.0;
                if let Some(l) = line {
                    if l.d + l.n[0] * tx + l.n[1] * ty >= 0.0 {
                        same = 1.0;
                    } else {
                        let pick = other_side(offs, ws, &same_at, (tx, ty));
                        match pick {
                            Some(o) => {
                                let c = color_of(o, (ix, jy), (tx, ty));
                                for k in 0..3 {
                                    acc[k] += c[k] as f64;
                                }
                            }
                            None => same = 1.0,
                        }
                    }
                } else {
                    for q in 0..4 {
                        let (o, w) = (offs[q], ws[q]);
                        if w == 0.0 {
                            continue;
                        }
                        if is_same(o) {
                            same += w;
                        } else {
                            let c = color_of(o, (ix, jy), (tx, ty));
                            for k in 0..3 {
                                acc[k] += w * c[k] as f64;
                            }
                        }
                    }
                }
                if same > 0.0 {
                    own_total += same;
                    let c = own(ix, jy);
                    for k in 0..3 {
                        acc[k] += same * c[k] as f64;
                    }
                }
            }
        }
        let m = (n * n) as f64;
        (acc.map(|v| (v / m) as f32), own_total / m)
    }

    /// The banded sums of [`Ctx::blend`] are its per-sub-point definition's
    /// (up to the order of the additions), with a boundary line and with
    /// the hats, for every own surface (flat, a checkerboard's parities, a
    /// photograph) and every neighbour look (background, one square,
    /// tabulated, moved), at 8, 3 and 11 sub-points per axis (3: a middle
    /// sub-point whose side hats are zero; 11: two bands).
    #[test]
    fn banded_blend_matches_the_per_sub_point_sums() {
        let (w, h) = (48u32, 40u32);
        let f = pieces_film(w, h, true);
        let photo = Backdrop {
            pattern: Pattern::Image(crate::scene::Texture {
                width_px: 16,
                height_px: 12,
                pixels: (0..16 * 12u64)
                    .map(|k| {
                        let r = |j| crate::phantom::uniform(crate::phantom::mix64(k), j) as f32;
                        [r(0), r(1), r(2)]
                    })
                    .collect(),
                world_width: 40.0,
                outside: [0.2, 0.4, 0.6],
            }),
            ..checker(4.0)
        };
        let s = settings(PrssMap::Bicubic, PrssFallback::Blend);
        let (mut lines, mut hats, mut parities, mut moved) = (0, 0, 0, 0);
        for bd in [checker(4.0), photo] {
            for n in [8, 3, 11] {
                let c = Ctx {
                    map: HitMap::new(&f),
                    backdrop: &bd,
                    background: [0.5, 0.25, 0.125],
                    s: &s,
                    taps: Taps::new(n, PrssMap::Bicubic),
                    hats: Hats::new(n),
                    coarse: Vec::new(),
                    unresolved: Vec::new(),
                };
                for y in 0..h as i64 {
                    for x in 0..w as i64 {
                        let centre = c.map.at(x, y);
                        let ring = Ring::new(&c.map, x, y, centre.map(|(_, ev)| ev));
                        if ring.all_same() {
                            continue;
                        }
                        let mut owns = vec![Own::Flat([0.3, 0.6, 0.9])];
                        // The map's rows of each sub-point row, where the
                        // pixel has a hit.
                        let mut map_rows = Vec::new();
                        if let Some((hit, ev)) = centre {
                            let mut st = PostStats::default();
                            let g = grid(&c, (x, y), (hit, ev), 2, &ring, &mut st).unwrap();
                            map_rows = c.taps.w.iter().map(|wy| rows(&g, wy)).collect();
                            owns.push(match &bd.pattern {
                                Pattern::Checker { size, colors } => Own::Parities {
                                    rows: checker_parities(&g, &c.taps, *size),
                                    colors: *colors,
                                },
                                Pattern::Image(_) => Own::Rows(map_rows.clone()),
                            });
                        }
                        let line = edge_line(&c.map, x, y, centre.map(|(_, ev)| ev));
                        for own in &owns {
                            let own_at = |ix: usize, jy: usize| match own {
                                Own::Flat(col) => *col,
                                Own::Parities { rows, colors } => {
                                    colors[(rows[jy] >> ix & 1) as usize]
                                }
                                Own::Rows(rows) => {
                                    let p = cols(&rows[jy], &c.taps.w[ix]);
                                    bd.color(p[0], p[1])
                                }
                            };
                            if let Own::Parities { .. } = own {
                                // The parities are the checkerboard's colours
                                // at the map's points, bit for bit.
                                for jy in 0..n {
                                    for ix in 0..n {
                                        let p = cols(&map_rows[jy], &c.taps.w[ix]);
                                        assert_eq!(own_at(ix, jy), bd.color(p[0], p[1]));
                                    }
                                }
                                parities += 1;
                            }
                            for l in [line, None] {
                                let (got, got_own) = c.blend(x, y, &ring, l, own);
                                let (want, want_own) =
                                    blend_each_sub_point(&c, x, y, &ring, l, own_at);
                                for k in 0..3 {
                                    assert!(
                                        (got[k] - want[k]).abs() <= 1e-6,
                                        "({x}, {y}) n {n} line {l:?}: {got:?} vs {want:?}"
                                    );
                                }
                                assert!((got_own - want_own).abs() <= 1e-12, "({x}, {y})");
                                lines += l.is_some() as usize;
                                hats += l.is_none() as usize;
                            }
                        }
                        moved += (0..9).any(|k| {
                            let o = (k % 3 - 1, k / 3 - 1);
                            ring.n[(o.1 + 1) as usize][(o.0 + 1) as usize] != Neighbour::Same
                                && matches!(
                                    ring.look(&c.map, x, y, o, &bd, c.background)
                                        .tabulated(&c.hats.t, &bd),
                                    Look::Moved { .. }
                                )
                        }) as usize;
                    }
                }
            }
        }
        assert!(
            lines > 100 && hats > 1000 && parities > 200 && moved > 200,
            "{lines} lines, {hats} hats, {parities} checker parities, {moved} moved looks"
        );
    }

    /// The lanes' sums are the per-mask sums [`Ctx::band_sum`] makes, bit
    /// for bit, for every lane and both parities, whatever the sub-point
    /// count (the bands of 3 and 11 per axis have quadrants of unequal
    /// sizes, and 11 two bands).
    #[test]
    fn hat_lanes_sum_as_the_masks_do() {
        let weight = |m: u64, w: &[f64; 64]| -> f64 { bits(m).map(|i| w[i]).sum() };
        let mut checked = 0;
        for n in [8, 3, 5, 11] {
            for band in &Hats::new(n).bands {
                for trial in 0..50u64 {
                    let odd: [u64; 16] = std::array::from_fn(|k| {
                        crate::phantom::mix64(trial * 16 + k as u64 + 1000 * n as u64)
                    });
                    let (even_w, odd_w) = hat_sums(&band.lanes, &odd);
                    for k in 0..16 {
                        let (quadrant, r) = (band.quadrant[k / 8][k / 4 % 2], k % 4);
                        let mask = quadrant & band.nonzero[r];
                        let w = &band.hat[r];
                        for (got, want) in [
                            (even_w[k], weight(mask & !odd[k], w)),
                            (odd_w[k], weight(mask & odd[k], w)),
                        ] {
                            // An empty sum is −0 from `Iterator::sum` and +0
                            // here; either, times a colour, adds nothing.
                            assert!(
                                got.to_bits() == want.to_bits() || (got == 0.0 && want == 0.0),
                                "n {n} lane {k}: {got:e} against {want:e}"
                            );
                        }
                        checked += 1;
                    }
                }
            }
        }
        assert!(checked > 3000);
    }
}
