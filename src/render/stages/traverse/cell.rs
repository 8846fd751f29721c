//! A ray's cells: the ray in cell coordinates, the time it leaves a cell,
//! a box or an aligned block of cells, the incremental DDA, and the test of
//! a segment against a cell's tagged sub-cells. The scalar walks, the lane
//! walks and refraction's cell clearing all step with these.

use super::{Coefficient, Ctx, Rays, SUB};

/// `max`/`min` without NaN handling: ray parameters here are never NaN, and
/// the library versions cost a compare-and-blend more on every step.
#[inline(always)]
pub(super) fn fmax(a: f64, b: f64) -> f64 {
    if a > b { a } else { b }
}

#[inline(always)]
pub(super) fn fmin(a: f64, b: f64) -> f64 {
    if a < b { a } else { b }
}

/// `⌊x⌋` clamped into `[lo, hi]`, for integral `0 ≤ lo ≤ hi < 2^63`: the
/// clamp goes first, in floats, so the floor is a truncating conversion
/// (no correction for negatives, which the clamp has removed) — fewer
/// dependent instructions on the walk's chain than flooring first. Equal to
/// `floor(x).clamp(lo, hi)` for every `x`; NaN gives `lo`. Also for a
/// negative `lo` when `lo == hi` (the clamp leaves an integer); otherwise a
/// negative value would truncate towards zero, not floor — lattice cells
/// are never negative.
#[inline(always)]
pub fn clamped_floor(x: f64, lo: f64, hi: f64) -> i64 {
    debug_assert!(lo <= hi && (lo >= 0.0 || lo == hi), "[{lo}, {hi}]");
    let v = fmin(fmax(x, lo), hi);
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_cvttsd_si64, _mm_set_sd};
        // SAFETY: SSE2 is part of the x86-64 baseline. (`as` would add the
        // saturation checks the clamp has made unnecessary.)
        unsafe { _mm_cvttsd_si64(_mm_set_sd(v)) }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        v as i64
    }
}

/// A ray in cell coordinates: origin, direction and its reciprocal.
#[derive(Clone, Copy, Debug)]
pub struct CellRay {
    pub ou: [f64; 3],
    pub du: [f64; 3],
    /// `1/du`, unused where `du == 0`.
    pub inv: [f64; 3],
}

impl CellRay {
    pub fn new(ou: [f64; 3], du: [f64; 3]) -> CellRay {
        CellRay {
            ou,
            du,
            inv: du.map(|d| if d != 0.0 { 1.0 / d } else { 0.0 }),
        }
    }
}

/// The parameter interval where the ray is inside `cell`: a pure function of
/// the ray and the cell, so a segment is the same bits however the walk
/// reached the cell (by single steps or by a jump over a block).
#[inline(always)]
pub fn cell_span(ray: &CellRay, cell: [i64; 3]) -> (f64, f64) {
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    for a in 0..3 {
        if ray.du[a] != 0.0 {
            let ta = (cell[a] as f64 - ray.ou[a]) * ray.inv[a];
            let tb = ((cell[a] + 1) as f64 - ray.ou[a]) * ray.inv[a];
            t0 = fmax(t0, fmin(ta, tb));
            t1 = fmin(t1, fmax(ta, tb));
        }
    }
    (t0, t1)
}

/// `AXIS_SPAN[a][lo][hi]`: the sub-cell bits whose index along axis `a` lies
/// in `lo..=hi` (see [`crate::classify::bezier::SubCells`] for the layout).
pub(super) const AXIS_SPAN: [[[u64; SUB]; SUB]; 3] = {
    let mut t = [[[0u64; SUB]; SUB]; 3];
    let mut a = 0;
    while a < 3 {
        let mut lo = 0;
        while lo < SUB {
            let mut hi = lo;
            while hi < SUB {
                let mut bits = 0u64;
                let mut b = 0;
                while b < SUB * SUB * SUB {
                    let along = [b % SUB, b / SUB % SUB, b / (SUB * SUB)][a];
                    if along >= lo && along <= hi {
                        bits |= 1 << b;
                    }
                    b += 1;
                }
                t[a][lo][hi] = bits;
                hi += 1;
            }
            lo += 1;
        }
        a += 1;
    }
    t
};

/// Whether the segment `[t0, t1]` of the ray in `cell` may meet a tagged
/// sub-cell of `mask` (4³ bits): whether the box of sub-cells spanned by the
/// segment's bounding box (one lookup per axis, widened by 1e-9 against
/// rounding) holds one. When it holds none, the segment provably holds no
/// crossing. A pure function of the ray, the cell and `[t0, t1]`, like
/// [`cell_span`]; a NaN coordinate spans every sub-cell.
///
/// The box holds every sub-cell the segment crosses and a few more, so it
/// lets through some segments that walking the crossed sub-cells would have
/// skipped — sphere: the box rejects 195k of the walk's 215k per frame,
/// teapot 587k of 628k — but it is a few branch-free operations where the
/// walk (first the start sub-cell, then the box, then Amanatides–Woo at
/// quarter-cell resolution) took a branch per step that the hardware could
/// not predict. Single-thread frames, two runs: sphere 161 / 167 → 150 /
/// 155 ms, teapot 491 / 493 → 466 / 472, cranium 319 / 329 → 302 / 306 (the
/// solve stage does the extra segments: sphere 1.25 → 1.33 solves per ray;
/// output bits unchanged).
#[inline(always)]
pub fn may_meet_tagged_sub_cell(
    ray: &CellRay,
    cell: [i64; 3],
    t0: f64,
    t1: f64,
    mask: u64,
) -> bool {
    let n = SUB as f64;
    let last = n - 1.0;
    let mut bbox = u64::MAX;
    for a in 0..3 {
        let local = |t: f64| n * (ray.ou[a] + t * ray.du[a] - cell[a] as f64);
        let (v0, v1) = (local(t0), local(t1));
        let (lo, hi) = (fmin(v0, v1), fmax(v0, v1));
        let span = AXIS_SPAN[a][clamped_floor(lo - 1e-9, 0.0, last) as usize]
            [clamped_floor(hi + 1e-9, 0.0, last) as usize];
        // `fmin`/`fmax` pass a NaN on as the other value; spanning all is
        // the conservative answer.
        bbox &= if (v0 - v1).is_nan() { u64::MAX } else { span };
    }
    mask & bbox != 0
}

/// Where the ray leaves the aligned block of `2^level` cells holding `cell`
/// (not before `t`), and the cell it enters there.
#[inline(always)]
pub fn exit_block(ray: &CellRay, cell: [i64; 3], level: u32, t: f64) -> (f64, [i64; 3]) {
    let size = 1i64 << level;
    let lo = cell.map(|c| (c >> level) << level);
    exit_box(ray, cell, lo, lo.map(|l| l + size - 1), t)
}

/// Where the ray's line leaves the box of cells `lo ..= hi`, and through
/// which axis's face (before [`exit_box`] and [`exit_cell`] keep it from
/// moving backwards).
///
/// The direction's signs are the same for every step of a ray, so the
/// per-axis branches predict well; the choice of the exit axis, which
/// changes from step to step, is made by selects.
#[inline(always)]
fn box_exit_time(ray: &CellRay, lo: [i64; 3], hi: [i64; 3]) -> (f64, usize) {
    let CellRay { ou, du, inv } = *ray;
    let te: [f64; 3] = std::array::from_fn(|a| {
        if du[a] > 0.0 {
            ((hi[a] + 1) as f64 - ou[a]) * inv[a]
        } else if du[a] < 0.0 {
            (lo[a] as f64 - ou[a]) * inv[a]
        } else {
            f64::INFINITY
        }
    });
    let (t01, a01) = if te[0] <= te[1] {
        (te[0], 0)
    } else {
        (te[1], 1)
    };
    if t01 <= te[2] { (t01, a01) } else { (te[2], 2) }
}

/// [`exit_box`] of the single cell `cell`: the exit axis steps past it, the
/// others stay (where `exit_box` would clamp the exit point into the cell),
/// so no exit point is floored. The same result as `exit_box(ray, cell,
/// cell, cell, t)` for every input (tested).
#[inline(always)]
pub fn exit_cell(ray: &CellRay, cell: [i64; 3], t: f64) -> (f64, [i64; 3]) {
    let (t_exit, axis) = box_exit_time(ray, cell, cell);
    // Per-axis steps, then a select: the axis changes from step to step.
    let next = std::array::from_fn(|a| {
        let step = if ray.du[a] > 0.0 {
            1
        } else if ray.du[a] < 0.0 {
            -1
        } else {
            0
        };
        cell[a] + if a == axis { step } else { 0 }
    });
    (fmax(t_exit, t), next)
}

/// Where the ray leaves the box of cells `lo ..= hi` (which holds `cell`;
/// a box of several cells lies in the lattice, so none of its indices is
/// negative — see [`clamped_floor`]), not before `t`, and the cell it
/// enters there.
///
/// The exit axis moves just past the box exactly; the other axes come from
/// the exit point, clamped into the box and never moving backwards, so every
/// step makes progress whatever the rounding (rays along faces, edges and
/// corners included).
#[inline(always)]
pub fn exit_box(
    ray: &CellRay,
    cell: [i64; 3],
    lo: [i64; 3],
    hi: [i64; 3],
    t: f64,
) -> (f64, [i64; 3]) {
    let CellRay { ou, du, .. } = *ray;
    let (t_exit, axis) = box_exit_time(ray, lo, hi);
    let t_new = fmax(t_exit, t);
    let next = std::array::from_fn(|a| {
        let (past, inside) = if du[a] > 0.0 {
            // Inside [cell, hi]: clamped into the box, never backwards.
            let at = ou[a] + t_new * du[a];
            (hi[a] + 1, clamped_floor(at, cell[a] as f64, hi[a] as f64))
        } else if du[a] < 0.0 {
            let at = ou[a] + t_new * du[a];
            (lo[a] - 1, clamped_floor(at, lo[a] as f64, cell[a] as f64))
        } else {
            (cell[a], cell[a])
        };
        if a == axis { past } else { inside }
    });
    (t_new, next)
}

/// Incremental Amanatides–Woo state: the ray's current cell, the parameter
/// where it entered, and where it crosses the next boundary on each axis. A
/// single-cell step is a comparison and two additions; after a jump over an
/// empty block the state is re-seeded from the new cell.
pub struct Dda {
    pub cell: [i64; 3],
    pub t: f64,
    t_max: [f64; 3],
    t_delta: [f64; 3],
    step: [i64; 3],
}

impl Dda {
    #[inline(always)]
    pub fn new(ray: &CellRay, cell: [i64; 3], t: f64) -> Dda {
        let mut d = Dda {
            cell,
            t,
            t_max: [f64::INFINITY; 3],
            t_delta: [f64::INFINITY; 3],
            step: [0; 3],
        };
        for a in 0..3 {
            if ray.du[a] != 0.0 {
                d.step[a] = if ray.du[a] > 0.0 { 1 } else { -1 };
                d.t_delta[a] = ray.inv[a].abs();
            }
        }
        d.seed(ray, cell, t);
        d
    }

    /// Moves to `cell` at `t` (after a jump) and recomputes the boundaries.
    #[inline(always)]
    fn seed(&mut self, ray: &CellRay, cell: [i64; 3], t: f64) {
        self.cell = cell;
        self.t = t;
        for a in 0..3 {
            if self.step[a] != 0 {
                let edge = (cell[a] + (self.step[a] > 0) as i64) as f64;
                self.t_max[a] = fmax((edge - ray.ou[a]) * ray.inv[a], t);
            }
        }
    }

    /// Where the ray leaves the current cell.
    #[inline(always)]
    pub fn cell_exit(&self) -> f64 {
        fmin(fmin(self.t_max[0], self.t_max[1]), self.t_max[2])
    }

    /// Steps into the next cell along the ray.
    #[inline(always)]
    pub fn advance(&mut self) {
        let a = if self.t_max[0] <= self.t_max[1] {
            if self.t_max[0] <= self.t_max[2] { 0 } else { 2 }
        } else if self.t_max[1] <= self.t_max[2] {
            1
        } else {
            2
        };
        self.t = self.t_max[a];
        self.cell[a] += self.step[a];
        self.t_max[a] += self.t_delta[a];
    }
}

/// Whether cell `c` is in the lattice.
#[inline(always)]
pub(crate) fn in_range<T: Coefficient>(ctx: &Ctx<T>, c: [i64; 3]) -> bool {
    let n = ctx.lattice.cells;
    (c[0] as u64) < n[0] as u64 && (c[1] as u64) < n[1] as u64 && (c[2] as u64) < n[2] as u64
}

/// Ray `i`'s current piece in cell coordinates (grid + lattice offset),
/// from its world origin and direction as [`super::super::place`] converts them,
/// and the stored reciprocal.
#[inline(always)]
pub(crate) fn cell_ray<T: Coefficient>(ctx: &Ctx<T>, rays: &Rays, i: usize) -> CellRay {
    let (s, off) = (ctx.inv_spacing, ctx.lattice.offset);
    let mut ray = CellRay {
        ou: [0.0; 3],
        du: [0.0; 3],
        inv: [0.0; 3],
    };
    for a in 0..3 {
        ray.ou[a] = rays.org[a][i] * s[a] + off;
        ray.du[a] = rays.dir[a][i] * s[a];
        ray.inv[a] = rays.cell_inv[a][i];
    }
    ray
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A single cell's exit without flooring is the box exit's, for rays in
    /// every direction (axis-parallel and NaN components included), starting
    /// inside, on and off the cell's faces.
    #[test]
    fn exit_cell_is_the_exit_of_a_one_cell_box() {
        use crate::phantom::{mix64, uniform};
        let odd = [0.0, -0.0, f64::NAN, 1e-300, -1e-300];
        for k in 0..20_000u64 {
            let r = |j: u64| uniform(mix64(k), j);
            let cell = [0, 1, 2].map(|a| (r(a) * 20.0) as i64 - 5);
            let ou: [f64; 3] = std::array::from_fn(|a| {
                let f = match k % 4 {
                    0 => 0.0,
                    1 => 1.0,
                    _ => r(3 + a as u64) * 1.4 - 0.2,
                };
                cell[a] as f64 + f
            });
            let du: [f64; 3] = std::array::from_fn(|a| {
                if (k >> (2 + a)) % 5 == 0 {
                    odd[(k as usize + a) % odd.len()]
                } else {
                    2.0 * r(6 + a as u64) - 1.0
                }
            });
            let ray = CellRay::new(ou, du);
            let t = if k % 3 == 0 { 0.0 } else { r(9) * 0.5 - 0.1 };
            let (ta, ca) = exit_cell(&ray, cell, t);
            let (tb, cb) = exit_box(&ray, cell, cell, cell, t);
            assert_eq!(
                (ta.to_bits(), ca),
                (tb.to_bits(), cb),
                "{ou:?} {du:?} {cell:?} {t}"
            );
        }
    }

    /// The clamp-then-truncate floor is the floor clamped afterwards, at
    /// integers, just off them, outside the range on both sides, and for
    /// NaN and infinities.
    #[test]
    fn clamped_floor_is_the_clamped_floor() {
        let specials = [
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            -0.0,
            1e300,
            -1e300,
        ];
        for (lo, hi) in [(0i64, 0i64), (0, 3), (5, 9), (12, 12)] {
            let mut xs: Vec<f64> = specials.to_vec();
            for k in -3..15 {
                let x = k as f64;
                xs.extend([x, x.next_up(), x.next_down(), x + 0.5, x - 1e-9]);
            }
            for x in xs {
                let want = if x.is_nan() {
                    lo
                } else {
                    (x.floor().clamp(-1e18, 1e18) as i64).clamp(lo, hi)
                };
                assert_eq!(
                    clamped_floor(x, lo as f64, hi as f64),
                    want,
                    "{x} in [{lo}, {hi}]"
                );
            }
        }
    }

    /// Cells a segment crosses, by dense sampling (a brute-force reference).
    fn brute(ou: [f64; 3], du: [f64; 3], t1: f64) -> Vec<[i64; 3]> {
        let mut out: Vec<[i64; 3]> = Vec::new();
        let n = 200_000;
        for k in 0..=n {
            let t = t1 * k as f64 / n as f64;
            let c = [0, 1, 2].map(|a| (ou[a] + t * du[a]).floor() as i64);
            if out.last() != Some(&c) {
                out.push(c);
            }
        }
        out
    }

    fn walk_cells(ou: [f64; 3], du: [f64; 3], t1: f64) -> Vec<[i64; 3]> {
        let mut cell = ou.map(|x| x.floor() as i64);
        let mut t = 0.0;
        let mut out = vec![cell];
        loop {
            let (tn, next) = exit_block(&CellRay::new(ou, du), cell, 0, t);
            if tn >= t1 {
                return out;
            }
            t = tn;
            cell = next;
            out.push(cell);
        }
    }

    #[test]
    fn dda_visits_the_cells_a_segment_crosses() {
        let cases = [
            ([0.3, 0.4, 0.5], [1.0, 0.7, 0.2]),
            ([5.7, 2.2, 3.9], [-0.3, 0.9, -0.5]),
            ([1.5, 1.5, 1.5], [1.0, 0.0, 0.0]),
            ([1.25, 3.5, 0.75], [0.0, -1.0, 0.0]),
        ];
        for (ou, du) in cases {
            let t1 = 6.0;
            let got = walk_cells(ou, du, t1);
            let want = brute(ou, du, t1);
            assert_eq!(got, want, "origin {ou:?} dir {du:?}");
        }
    }

    #[test]
    fn dda_progresses_through_edges_and_corners() {
        // Along a face diagonal through cell corners: every step advances.
        let ou = [1.0, 1.0, 0.5];
        let du = [1.0, 1.0, 0.0];
        let got = walk_cells(ou, du, 4.0);
        for w in got.windows(2) {
            assert!(w[1][0] >= w[0][0] && w[1][1] >= w[0][1] && w[1] != w[0]);
        }
        assert_eq!(*got.last().unwrap(), [4, 4, 0]);
    }

    #[test]
    fn block_exit_skips_whole_blocks() {
        let (t, next) = exit_block(
            &CellRay::new([0.5, 0.5, 0.5], [1.0, 0.25, 0.1]),
            [0, 0, 0],
            2,
            0.0,
        );
        assert_eq!(t, 3.5);
        assert_eq!(next, [4, 1, 0]);
    }
}

#[cfg(test)]
mod sub_cell_tests {
    use super::*;
    use crate::classify::bezier::{SubCells, bernstein_weights, cell_bernstein};
    use crate::filter::{Field, FilterKind};
    use crate::lattice::Lattice;
    use crate::roots::bernstein::{BernsteinBasis, IsolationWork};

    /// The box test against its definition: a mask holding one sub-cell is
    /// met when that sub-cell lies in the box of sub-cells the segment's
    /// end points span, and not met when it lies a sub-cell or more away
    /// from that box on some axis; with every bit set it is always met, with
    /// none never, and NaN ends span everything.
    #[test]
    fn the_box_test_is_the_box_of_the_segment_ends() {
        use crate::phantom::{mix64, uniform};
        let (mut met, mut missed) = (0, 0);
        for k in 0..20_000u64 {
            let r = |j: u64| uniform(mix64(k), j);
            let cell = [0, 1, 2].map(|a| (r(a) * 8.0) as i64 - 2);
            let p0: [f64; 3] = std::array::from_fn(|a| cell[a] as f64 + r(3 + a as u64));
            let p1: [f64; 3] = std::array::from_fn(|a| cell[a] as f64 + r(6 + a as u64));
            let du: [f64; 3] = std::array::from_fn(|a| p1[a] - p0[a]);
            let t0 = r(9) * 2.0 - 1.0;
            let ou: [f64; 3] = std::array::from_fn(|a| p0[a] - t0 * du[a]);
            let ray = CellRay::new(ou, du);
            let t1 = t0 + 1.0;
            // Sub-cell index ranges of the end points, per axis.
            let range: [(f64, f64); 3] = std::array::from_fn(|a| {
                let (x0, x1) = (p0[a] - cell[a] as f64, p1[a] - cell[a] as f64);
                (4.0 * x0.min(x1), 4.0 * x0.max(x1))
            });
            let bit = (r(10) * 64.0) as usize;
            let ijk = [bit % 4, bit / 4 % 4, bit / 16];
            let inside = (0..3).all(|a| {
                let (lo, hi) = range[a];
                (ijk[a] as f64) < hi.ceil().max(1.0) && (ijk[a] as f64) >= lo.floor().min(3.0)
            });
            let clear = (0..3).any(|a| {
                let (lo, hi) = range[a];
                (ijk[a] as f64) >= hi + 1e-6 || (ijk[a] as f64 + 1.0) <= lo - 1e-6
            });
            let got = may_meet_tagged_sub_cell(&ray, cell, t0, t1, 1 << bit);
            if inside {
                assert!(got, "{cell:?} {p0:?} {p1:?} sub-cell {ijk:?}");
                met += 1;
            }
            if clear {
                assert!(!got, "{cell:?} {p0:?} {p1:?} sub-cell {ijk:?}");
                missed += 1;
            }
            assert!(may_meet_tagged_sub_cell(&ray, cell, t0, t1, u64::MAX));
            assert!(!may_meet_tagged_sub_cell(&ray, cell, t0, t1, 0));
        }
        assert!(met > 1000 && missed > 1000, "{met} {missed}");
        // A NaN coordinate spans its axis: x here, while y and z stay in
        // sub-cell 2; a NaN end spans every axis.
        let meets = |ou: [f64; 3], du: [f64; 3], t1: f64, bit: u32| {
            may_meet_tagged_sub_cell(&CellRay::new(ou, du), [0; 3], 0.0, t1, 1 << bit)
        };
        let nan = [f64::NAN, 0.5, 0.5];
        assert!(meets(nan, [1.0, 0.0, 0.0], 0.5, 3 + 4 * (2 + 4 * 2)));
        assert!(!meets(nan, [1.0, 0.0, 0.0], 0.5, 63));
        assert!(meets([0.1; 3], [1.0; 3], f64::NAN, 63));
    }

    #[test]
    fn a_segment_with_a_crossing_meets_a_tagged_sub_cell() {
        let dims = [10usize, 9, 11];
        let vol = crate::volume::scrambled_u8(dims, 5);
        let mut rng = 12345u64;
        let mut next = || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng >> 11) as f64 / (1u64 << 53) as f64
        };
        for name in ["catmull-rom", "bspline3", "linear", "bspline2"] {
            let f = Field::new(&vol, FilterKind::parse(name, 0.0).unwrap());
            let lat = Lattice::new(f.kernel(), dims);
            let iso = f.separating_iso(125.0);
            let beta = bernstein_weights(&f);
            let mut sub = SubCells::new(&f);
            let basis = BernsteinBasis::new(3 * (f.kernel().support() - 1));
            let (mut checked, mut crossings) = (0, 0);
            for _ in 0..20000 {
                let cell = [
                    1 + (next() * 6.0) as i64,
                    1 + (next() * 5.0) as i64,
                    1 + (next() * 7.0) as i64,
                ];
                let mask = sub.mask(
                    &cell_bernstein(&f, cell, iso, &beta),
                    1e-12 * f.max_abs_coeff().max(1.0),
                );
                // A random line through the cell.
                let p: [f64; 3] = std::array::from_fn(|a| cell[a] as f64 + next());
                let d: [f64; 3] = std::array::from_fn(|_| next() * 2.0 - 1.0);
                let ou: [f64; 3] = std::array::from_fn(|a| p[a] - 3.0 * d[a]);
                let ray = CellRay::new(ou, d);
                let (t0, t1) = cell_span(&ray, cell);
                if t1 <= t0 {
                    continue;
                }
                checked += 1;
                let off = lat.offset;
                let p0 = std::array::from_fn(|a| ou[a] + t0 * d[a] - off);
                let p1 = std::array::from_fn(|a| ou[a] + t1 * d[a] - off);
                let mut mono = [0.0; 22];
                crate::with_support!(f.kernel().support(), S => f.restrict::<S>(cell, p0, p1, iso, &mut mono));
                let poly = basis.segment(&mono[..=basis.degree()]);
                let start_in = crate::roots::inside(poly.eval(0.0));
                let mut w = IsolationWork::default();
                if let Some(s) = poly.first_crossing(start_in, 1e-12, &mut w) {
                    crossings += 1;
                    assert!(
                        may_meet_tagged_sub_cell(&ray, cell, t0, t1, mask),
                        "{name} {cell:?}: crossing at s = {s} but no tagged sub-cell met (mask {mask:#x})"
                    );
                }
            }
            assert!(
                checked > 1000 && crossings > 50,
                "{name}: {checked} {crossings}"
            );
        }
    }
}
