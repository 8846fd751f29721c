//! ACCC per sub-cell: the refinement the paper proposes in section 4.2.4 and
//! leaves untried.
//!
//! Equation (1) bounds `f - iso` over a cell by the per-axis weight maxima and
//! minima over the whole cell. Over an `n`-th of the cell per axis the
//! weights vary less, so their ranges, and the bound, are tighter: a cell
//! stays tagged when one of its `n³` sub-cells' bounds straddles the
//! iso-value. The per-axis weight ranges are multiplied as intervals, so the
//! bound also holds for kernels with negative lobes.
//!
//! The sub-cells that straddle are kept as the cell's mask in the 4³ layout
//! of [`crate::classify::SubCellMasks`] (a sub-cell of `n = 2` covers 2³ of
//! them, one of `n = 8` lies in one), so the traversal hands the solve stage
//! only the segments that meet one, as it does for the Bézier
//! classification's masks.

use super::bezier::SUB;
use super::bound::interval_product;
use crate::filter::Field;
use crate::filter::coeffs::Coefficient;
use crate::filter::kernel::Kernel;

/// Most sub-cells per axis.
pub const MAX_SUB: usize = 8;

/// ACCC's bound per sub-cell for one kernel and `n` sub-cells per axis.
pub struct SubCellBounds {
    n: usize,
    s: usize,
    how: How,
    /// Per sub-cell, the bits of the 4³ mask it sets ([`coverage`]).
    covers: Vec<u64>,
}

enum How {
    /// Non-negative kernels: a product of weight ranges is the product of
    /// their minima and of their maxima, so each bound is a tensor
    /// contraction of `d = c - iso` with per-axis vectors, axis by axis —
    /// `n·S³ + n²·S² + n³·S` multiply-adds where the sub-cells one by one
    /// take `n³·S³`. The four bounds' contractions run together as the
    /// lanes of `[f64; 4]` (the channels `pos·hi³`, `pos·lo³`, `neg·hi³`,
    /// `neg·lo³`, see [`Scratch`]), so each pass is one vector operation
    /// where four scalar ones were. `w[a·S + j]`: weight `j`'s maximum and
    /// minimum (clamped at 0) over sub-interval `a`, as `[hi, lo, hi, lo]`.
    Separable { w: Vec<[f64; 4]> },
    /// Kernels with negative lobes: the interval product of every support
    /// term over every sub-cell, tabulated once (it does not depend on the
    /// cell), at `sub · S³ + i + S·(j + S·k)`.
    Table(Vec<(f64, f64)>),
}

/// Scratch for [`SubCellBounds`], one per thread.
pub struct Scratch {
    d: Vec<f64>,
    /// `[pos, pos, neg, neg]` per support term, `pos = max(d, 0)` and
    /// `neg = min(d, 0)`.
    t: Vec<[f64; 4]>,
    z: Vec<[f64; 4]>,
    y: Vec<[f64; 4]>,
    /// Per sub-cell: `pos·hi³`, `pos·lo³`, `neg·hi³`, `neg·lo³`.
    out: Vec<[f64; 4]>,
}

impl SubCellBounds {
    pub fn new(kernel: &Kernel, n: usize) -> SubCellBounds {
        assert!(
            (1..=MAX_SUB).contains(&n),
            "1 to {MAX_SUB} sub-cells per axis"
        );
        let s = kernel.support();
        // ranges[a][j]: (lo, hi) of weight j over [a/n, (a+1)/n].
        let ranges: Vec<Vec<(f64, f64)>> = (0..n)
            .map(|a| {
                (0..s)
                    .map(|j| kernel.weight_range(j, a as f64 / n as f64, (a + 1) as f64 / n as f64))
                    .collect()
            })
            .collect();
        let how = if kernel.is_nonnegative() {
            // The weights are never negative: a minimum below 0 is the
            // range's widening against rounding, and 0 still bounds them.
            How::Separable {
                w: ranges
                    .iter()
                    .flatten()
                    .map(|&(lo, hi)| {
                        let lo = lo.max(0.0);
                        [hi, lo, hi, lo]
                    })
                    .collect(),
            }
        } else {
            let s3 = s * s * s;
            let mut table = vec![(0.0, 0.0); n * n * n * s3];
            for sub in 0..n * n * n {
                let (ax, ay, az) = (sub % n, sub / n % n, sub / (n * n));
                for k in 0..s {
                    for j in 0..s {
                        for i in 0..s {
                            table[sub * s3 + i + s * (j + s * k)] =
                                interval_product(ranges[ax][i], ranges[ay][j], ranges[az][k]);
                        }
                    }
                }
            }
            How::Table(table)
        };
        SubCellBounds {
            n,
            s,
            how,
            covers: coverage(n),
        }
    }

    pub fn scratch(&self) -> Scratch {
        let (n, s) = (self.n, self.s);
        Scratch {
            d: vec![0.0; s * s * s],
            t: vec![[0.0; 4]; s * s * s],
            z: vec![[0.0; 4]; n * s * s],
            y: vec![[0.0; 4]; n * n * s],
            out: vec![[0.0; 4]; n * n * n],
        }
    }

    /// The cell's 4³ mask (bit `i + 4·(j + 4·k)`, x fastest) of the
    /// sub-cells that meet one of ours whose bound of `f - iso` straddles
    /// zero, for `cell` of `field` at the (separated) iso-value `iso`: a
    /// straddling half of `accc2` sets the 2³ quarters it covers, an eighth
    /// of `accc8` the quarter it lies in. Non-zero exactly when the cell is
    /// tagged. The slack scales with the terms summed, so summation
    /// rounding cannot untag a sub-cell whose bound is exactly at the
    /// iso-value. Inlined, so that callers under [`crate::with_isa!`]
    /// compile its lanes for the running instruction set (the same
    /// operations, so the same bits).
    #[inline(always)]
    pub fn cell_mask<T: Coefficient>(
        &self,
        field: &Field<T>,
        cell: [i64; 3],
        iso: f64,
        w: &mut Scratch,
    ) -> u64 {
        super::support_minus_iso_into(field, cell, iso, &mut w.d);
        let mut mask = 0u64;
        match &self.how {
            How::Separable { w: weights } => {
                for (t, &v) in w.t.iter_mut().zip(&w.d) {
                    let (pos, neg) = (v.max(0.0), v.min(0.0));
                    *t = [pos, pos, neg, neg];
                }
                contract(
                    self.n, self.s, &w.t, weights, &mut w.z, &mut w.y, &mut w.out,
                );
                for (sub, &[ph, pl, nh, nl]) in w.out.iter().enumerate() {
                    let (up, down) = (ph + nl, pl + nh);
                    // Σ |d|·max weight product.
                    let eps = 1e-12 * (ph - nh);
                    if down <= eps && up > -eps {
                        mask |= self.covers[sub];
                    }
                }
            }
            How::Table(table) => {
                let s3 = self.s * self.s * self.s;
                for (terms, &covers) in table.chunks_exact(s3).zip(&self.covers) {
                    let (mut lo, mut hi, mut mag) = (0.0, 0.0, 0.0);
                    for (v, &(pl, ph)) in w.d.iter().zip(terms) {
                        if *v >= 0.0 {
                            lo += v * pl;
                            hi += v * ph;
                        } else {
                            lo += v * ph;
                            hi += v * pl;
                        }
                        mag += v.abs() * ph.abs().max(pl.abs());
                    }
                    let eps = 1e-12 * mag;
                    if lo <= eps && hi > -eps {
                        mask |= covers;
                    }
                }
            }
        }
        mask
    }
}

/// Per sub-cell of `n³` (x fastest), the 4³ sub-cells it overlaps: along an
/// axis, sub-cell `a` spans `[a/n, (a+1)/n]`, which meets quarters
/// `⌊4a/n⌋ ..= ⌈4(a+1)/n⌉ − 1`.
fn coverage(n: usize) -> Vec<u64> {
    let span = |a: usize| (a * SUB / n)..(((a + 1) * SUB).div_ceil(n));
    (0..n * n * n)
        .map(|sub| {
            let (ax, ay, az) = (sub % n, sub / n % n, sub / (n * n));
            let mut m = 0u64;
            for k in span(az) {
                for j in span(ay) {
                    for i in span(ax) {
                        m |= 1 << (i + SUB * (j + SUB * k));
                    }
                }
            }
            m
        })
        .collect()
}

/// `out[ax + n·(ay + n·az)] = Σ t[i + S·(j + S·k)]·w[ax·S + i]·w[ay·S + j]·w[az·S + k]`
/// lane by lane, one axis at a time (z, then y, then x), with `z` and `y`
/// as scratch.
#[inline(always)]
fn contract(
    n: usize,
    s: usize,
    t: &[[f64; 4]],
    w: &[[f64; 4]],
    z: &mut [[f64; 4]],
    y: &mut [[f64; 4]],
    out: &mut [[f64; 4]],
) {
    #[inline(always)]
    fn dot(terms: impl Iterator<Item = ([f64; 4], [f64; 4])>) -> [f64; 4] {
        let mut acc = [0.0; 4];
        for (a, b) in terms {
            for l in 0..4 {
                acc[l] += a[l] * b[l];
            }
        }
        acc
    }
    // z[(az·S + j)·S + i]
    for az in 0..n {
        let wz = &w[az * s..][..s];
        for j in 0..s {
            for i in 0..s {
                z[(az * s + j) * s + i] = dot((0..s).map(|k| (t[i + s * (j + s * k)], wz[k])));
            }
        }
    }
    // y[(az·n + ay)·S + i]
    for az in 0..n {
        for ay in 0..n {
            let wy = &w[ay * s..][..s];
            for i in 0..s {
                y[(az * n + ay) * s + i] = dot((0..s).map(|j| (z[(az * s + j) * s + i], wy[j])));
            }
        }
    }
    for az in 0..n {
        for ay in 0..n {
            let row = &y[(az * n + ay) * s..][..s];
            for ax in 0..n {
                let wx = &w[ax * s..][..s];
                out[ax + n * (ay + n * az)] = dot(row.iter().copied().zip(wx.iter().copied()));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classify::{Method, accc, accc_sub, accc_sub_with_masks, classify};
    use crate::filter::FilterKind;
    use crate::lattice::Lattice;

    fn noisy(filter: &str) -> (Field<f64>, f64) {
        let vol = crate::volume::scrambled_u8([10, 9, 11], 7);
        let f = Field::new(&vol, FilterKind::parse(filter, 0.0).unwrap());
        let iso = f.separating_iso(120.0);
        (f, iso)
    }

    /// Every point of sub-cell `(i, j, k)` of 4³ sampled on a 5³ grid
    /// (faces included): whether `f - iso` takes both signs there.
    fn sign_change_in(
        f: &Field<f64>,
        lattice: &Lattice,
        cell: [i64; 3],
        sub: [usize; 3],
        iso: f64,
    ) -> bool {
        let (mut pos, mut neg) = (false, false);
        for k in 0..5 {
            for j in 0..5 {
                for i in 0..5 {
                    let at = [i, j, k];
                    let p: [f64; 3] = std::array::from_fn(|a| {
                        cell[a] as f64 - lattice.offset
                            + (sub[a] as f64 + at[a] as f64 / 4.0) / SUB as f64
                    });
                    let v = f.value(glam::DVec3::from_array(p)) - iso;
                    pos |= v > 0.0;
                    neg |= v <= 0.0;
                }
            }
        }
        pos && neg
    }

    #[test]
    fn masks_hold_every_sub_cell_with_a_sign_change_and_match_the_tags() {
        for filter in ["bspline3", "bspline2", "catmull-rom"] {
            let (f, iso) = noisy(filter);
            let lattice = Lattice::new(f.kernel(), f.dims());
            let coarse = accc(&f, &lattice, iso);
            for n in [2usize, 4, 8] {
                let (tags, masks) = accc_sub_with_masks(&f, &lattice, iso, &coarse, n, true);
                // The same tags as without masks, one non-empty mask per tag.
                assert_eq!(
                    tags,
                    accc_sub(&f, &lattice, iso, &coarse, n),
                    "{filter} {n}"
                );
                assert_eq!(masks.len(), tags.count());
                assert!(masks.windows(2).all(|w| w[0].0 < w[1].0), "ascending");
                let mut checked = 0;
                for &(i, mask) in &masks {
                    assert_ne!(mask, 0);
                    let cell = crate::lattice::cell_at(lattice.cells, i);
                    for b in 0..64 {
                        let sub = [b % SUB, b / SUB % SUB, b / (SUB * SUB)];
                        if sign_change_in(&f, &lattice, cell, sub, iso) {
                            checked += 1;
                            assert!(
                                mask >> b & 1 == 1,
                                "{filter} accc{n}: cell {cell:?} sub {sub:?}"
                            );
                        }
                    }
                }
                assert!(
                    checked > 100,
                    "{filter}: the test saw crossings ({checked})"
                );
            }
        }
    }

    #[test]
    fn halves_cover_their_quarters_and_tighten_the_whole_cell() {
        // A smooth surface: noise keeps every sub-cell of a tagged cell.
        let vol = crate::phantom::SphereSpec {
            size: 24,
            radius: 8.0,
            sigma: 1.5,
            ..Default::default()
        }
        .build()
        .unwrap();
        let f = Field::new(&vol, FilterKind::BSpline(3));
        let iso = f.separating_iso(0.5);
        let lattice = Lattice::new(f.kernel(), f.dims());
        let coarse = accc(&f, &lattice, iso);
        let halves = SubCellBounds::new(f.kernel(), 2);
        let quarters = SubCellBounds::new(f.kernel(), 4);
        let mut w = halves.scratch();
        let mut w4 = quarters.scratch();
        let (mut bits2, mut bits4) = (0, 0);
        for i in (0..coarse.cells.iter().product()).filter(|&i| coarse.get_index(i)) {
            let cell = crate::lattice::cell_at(lattice.cells, i);
            let (m2, m4) = (
                halves.cell_mask(&f, cell, iso, &mut w),
                quarters.cell_mask(&f, cell, iso, &mut w4),
            );
            // A half's bits come in whole 2³ blocks of quarters.
            for b in 0..64 {
                let base = (b % 4 / 2 * 2) + 4 * (b / 4 % 4 / 2 * 2) + 16 * (b / 16 / 2 * 2);
                let block = [0, 1, 4, 5, 16, 17, 20, 21].map(|o| m2 >> (base + o) & 1);
                assert!(block.iter().all(|&v| v == block[0]), "{cell:?}");
            }
            // Each quarter lies in its half, whose weight bounds span more:
            // a quarter kept is in a half kept.
            assert_eq!(
                m4 & !m2,
                0,
                "{cell:?}: quarters {m4:#x} outside halves {m2:#x}"
            );
            (bits2, bits4) = (bits2 + m2.count_ones(), bits4 + m4.count_ones());
        }
        // Finer sub-cells keep fewer of the cell's volume.
        assert!(bits4 < bits2, "{bits4} < {bits2}");
        // The method tags some cells, all among the coarse ones.
        let t4 = classify(&f, iso, Method::AcccSub(4)).tags;
        assert!(t4.count() > 0 && t4.is_subset_of(&coarse));
    }
}
