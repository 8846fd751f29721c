//! A plane per tagged cell and how far the field strays from it, so the
//! solve stage can pass over the segments that stay clear of the
//! iso-surface without restricting the field to them.
//!
//! Many segments the walk hands over hold no crossing (Table 2: 33–64% of
//! the solves with Bézier tags, up to 71% with ACCC): the cell holds the
//! surface, but the ray passes beside it. Over a cell `f - iso` is a
//! tensor polynomial with Bernstein coefficients `b_ijk`; a plane
//! `P(u) = a0 + a·u` (cell-local `u ∈ [0,1]³`) has Bernstein coefficients
//! `P(i/d, j/d, k/d)` (linear precision), so by the convex hull property
//!
//! ```text
//! |f(u) - iso - P(u)| ≤ e = max |b_ijk - P(i/d, j/d, k/d)|   on the cell.
//! ```
//!
//! `P` is linear along a segment, so when `P ± e` keeps one sign at both
//! ends (by more than a margin far above rounding) the segment holds no
//! crossing — the solve would find none, so passing it over changes no
//! output bit. Where the field is smooth on the scale of a cell, `e` is a
//! small part of the field's change across it: on the glass sphere the
//! planes pass over three quarters of the segments the 4³ sub-cell masks
//! let through without a crossing (crossing-free solves 0.47 → 0.11 per
//! ray, BENCHMARKS.md).
//!
//! The plane is the least-squares fit to the control points (any plane
//! gives a valid `e`; this one keeps it small); kept as `f32`, with `e`
//! computed against the stored values and rounded up.

use std::sync::Arc;

use rayon::prelude::*;

use super::bezier::{bernstein_weights, each_patch};
use super::tagged::TaggedIndex;
use crate::filter::Field;
use crate::filter::coeffs::Coefficient;

/// `a0, ax, ay, az` of the plane over the cell's local coordinates, the
/// bound `e` on the field's distance from it, and a zero: six, so lane code
/// gathers them as three pairs.
pub type PlaneBound = [f32; 6];

/// What the walk tests a tagged cell's segment against: its sub-cell mask
/// ([`super::SubCellMasks`]) and its plane, side by side in 32 bytes, so
/// the plane's gathers read the line the mask's brought in. Measured, this
/// did no better than the planes in a table of their own: the sphere's
/// frames gained the same, and the teapot's walk still waited on its
/// records (see [`CACHE_BUDGET`]).
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(32))]
pub struct CellTests {
    pub mask: u64,
    pub plane: PlaneBound,
}

/// The largest table of [`CellTests`] a render uses: the walk gathers a
/// record at every tagged cell a ray reaches, and once the table outgrows
/// a core's cache those gathers wait longer than the solves they spare.
/// Measured (2 threads, alternating builds; BENCHMARKS.md, *One curvature
/// bound per crossing cell, and planes*): the glass sphere's 10,490
/// records (0.3 MiB) cut its solves per ray 1.37 → 1.01 and its frame
/// (distance, PRSS) 31.0 / 30.5 / 31.6 → 29.7 / 29.2 / 32.3 ms; the
/// teapot's 356,477 (10.9 MiB) cut its solves 2.44 → 1.76 but raised its
/// walk 66–76 → 95–97 ms CPU and its frame 93.4 / 99.8 → 100.3 / 101.6
/// ms. 1 MiB is one core's L2 here.
pub const CACHE_BUDGET: usize = 1 << 20;

/// Cells per parallel task of [`PlaneBounds::build`].
const RUN: usize = 256;

/// The planes of the tagged cells of one classification, with their masks.
#[derive(Clone, Debug)]
pub struct PlaneBounds {
    index: Arc<TaggedIndex>,
    tests: Vec<CellTests>,
    /// Added to every `e`: far above the rounding of the Bernstein
    /// coefficients, of the plane's evaluation and of the solve's own
    /// arithmetic, so a segment passed over could not have shown a root.
    margin: f64,
}

impl PlaneBounds {
    /// Bytes the planes of `count` tagged cells take, with their masks.
    pub fn bytes_for(count: usize) -> usize {
        count * size_of::<CellTests>()
    }

    /// The plane of every tagged cell of `index` for `f - iso`, beside its
    /// mask from `masks` (kept in `index`'s slots).
    pub fn build<T: Coefficient>(
        field: &Field<T>,
        index: Arc<TaggedIndex>,
        masks: &[u64],
        iso: f64,
    ) -> Self {
        assert_eq!(masks.len(), index.count(), "one mask per tagged cell");
        let beta = bernstein_weights(field);
        let d = field.kernel().support() - 1;
        let cells = index.table(|cell| cell);
        let mut tests = vec![CellTests::default(); cells.len()];
        // Runs of cells in parallel, each's patches eight at a time.
        tests
            .par_chunks_mut(RUN)
            .zip(cells.par_chunks(RUN))
            .zip(masks.par_chunks(RUN))
            .for_each(|((tests, cells), masks)| {
                each_patch(field, cells, iso, &beta, |k, patch| {
                    tests[k] = CellTests {
                        mask: masks[k],
                        plane: fit(patch, d),
                    };
                });
            });
        PlaneBounds {
            index,
            tests,
            margin: 1e-9 * field.max_abs_coeff().max(iso.abs()).max(1.0),
        }
    }

    /// Where cell `c`'s (in range) plane is; `None` when the cell is not
    /// tagged.
    #[inline(always)]
    pub fn slot(&self, c: [i64; 3]) -> Option<usize> {
        self.index.slot(c)
    }

    #[inline(always)]
    pub fn at(&self, slot: usize) -> &PlaneBound {
        &self.tests[slot].plane
    }

    /// The masks and planes in slot order and the margin, for lane code
    /// that gathers them.
    pub fn parts(&self) -> (&TaggedIndex, &[CellTests], f64) {
        (&self.index, &self.tests, self.margin)
    }

    /// Whether the segment from `u0` to `u1` (the cell's local coordinates)
    /// stays on one side of the iso-surface by the plane of `p`. A NaN
    /// anywhere proves nothing.
    #[inline(always)]
    pub fn clears(&self, p: &PlaneBound, u0: [f64; 3], u1: [f64; 3]) -> bool {
        clears(p, self.margin, u0, u1)
    }
}

/// [`PlaneBounds::clears`] with the planes' `margin`, for lane code that
/// holds the planes' slice rather than the table.
#[inline(always)]
pub fn clears(p: &PlaneBound, margin: f64, u0: [f64; 3], u1: [f64; 3]) -> bool {
    let at =
        |u: [f64; 3]| p[0] as f64 + p[1] as f64 * u[0] + p[2] as f64 * u[1] + p[3] as f64 * u[2];
    let e = p[4] as f64 + margin;
    let (l0, l1) = (at(u0), at(u1));
    (l0 > e && l1 > e) || (l0 < -e && l1 < -e)
}

/// The least-squares plane through the control points `b` (`(d+1)³`, x
/// fastest, at `(i/d, j/d, k/d)`) and its bound, as stored. (Rounding in
/// `e`'s few operations is far below the margin [`PlaneBounds::clears`]
/// adds.)
fn fit(b: &[f64], d: usize) -> PlaneBound {
    let n = d + 1;
    let mut x = [0.0f64; 8];
    for (i, v) in x.iter_mut().enumerate().take(n) {
        *v = i as f64 / d as f64;
    }
    let x = &x[..n];
    // Σ (x_i - 1/2)² over one axis; the points are symmetric about 1/2.
    let sxx: f64 = x.iter().map(|v| (v - 0.5) * (v - 0.5)).sum();
    let (mut sum, mut s) = (0.0, [0.0f64; 3]);
    for (k, plane) in b.chunks_exact(n * n).enumerate() {
        let (mut plane_sum, mut sy) = (0.0, 0.0);
        for (j, row) in plane.chunks_exact(n).enumerate() {
            let row_sum: f64 = row.iter().sum();
            plane_sum += row_sum;
            sy += (x[j] - 0.5) * row_sum;
            s[0] += row.iter().zip(x).map(|(v, xi)| (xi - 0.5) * v).sum::<f64>();
        }
        sum += plane_sum;
        s[1] += sy;
        s[2] += (x[k] - 0.5) * plane_sum;
    }
    let per_axis = (n * n) as f64 * sxx;
    let a = s.map(|v| (v / per_axis) as f32);
    let a0 = (sum / (n * n * n) as f64 - 0.5 * a.iter().map(|&v| v as f64).sum::<f64>()) as f32;
    let [ax, ay, az] = a.map(|v| v as f64);
    let mut e = 0.0f64;
    for (k, plane) in b.chunks_exact(n * n).enumerate() {
        for (j, row) in plane.chunks_exact(n).enumerate() {
            let base = a0 as f64 + ay * x[j] + az * x[k];
            for (v, xi) in row.iter().zip(x) {
                let r = (v - (base + ax * xi)).abs();
                // NaN kept: it proves nothing.
                e = if r > e || r.is_nan() { r } else { e };
            }
        }
    }
    [a0, a[0], a[1], a[2], round_up(e), 0.0]
}

/// The smallest `f32` not below `x` (for `x ≥ 0`; NaN stays NaN).
fn round_up(x: f64) -> f32 {
    let f = x as f32;
    if (f as f64) < x { f.next_up() } else { f }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classify::{Method, classify};
    use crate::filter::FilterKind;
    use crate::lattice::Lattice;
    use crate::phantom::{mix64, uniform};
    use glam::DVec3;

    /// The field minus the iso-value stays within `e` of the plane at random
    /// points of every tagged cell, for every filter; and the sphere's planes
    /// are tight (a small part of the field's change across a cell).
    #[test]
    fn the_field_stays_within_the_bound_of_its_plane() {
        let vol = crate::volume::scrambled_u8([10, 9, 11], 3);
        for name in ["linear", "catmull-rom", "bspline2", "bspline3", "bspline5"] {
            let f = Field::new(&vol, FilterKind::parse(name, 0.0).unwrap());
            let iso = f.separating_iso(120.0);
            let tags = classify(&f, iso, Method::Bmcc).tags;
            let index = Arc::new(TaggedIndex::build(&tags));
            let masks = vec![u64::MAX; index.count()];
            let planes = PlaneBounds::build(&f, index, &masks, iso);
            let lat = Lattice::new(f.kernel(), vol.dims());
            let off = f.kernel().knot_offset();
            let mut checked = 0;
            for i in 0..lat.cell_count() {
                let cell = crate::lattice::cell_at(lat.cells, i);
                let Some(slot) = planes.slot(cell) else {
                    continue;
                };
                let p = planes.at(slot);
                for k in 0..20u64 {
                    let u: [f64; 3] =
                        std::array::from_fn(|a| uniform(mix64(i as u64 * 31 + k), a as u64));
                    let g = DVec3::from_array(std::array::from_fn(|a| cell[a] as f64 - off + u[a]));
                    let v = f.value(g) - iso;
                    let plane =
                        p[0] as f64 + p[1] as f64 * u[0] + p[2] as f64 * u[1] + p[3] as f64 * u[2];
                    assert!(
                        (v - plane).abs() <= p[4] as f64 * (1.0 + 1e-12) + 1e-9,
                        "{name} {cell:?}: {v} vs plane {plane} ± {}",
                        p[4]
                    );
                    checked += 1;
                }
            }
            assert!(checked > 1000, "{name}: {checked}");
        }
    }

    #[test]
    fn planes_clear_segments_beside_the_sphere() {
        let vol = crate::phantom::SphereSpec {
            size: 32,
            radius: 9.0,
            ..Default::default()
        }
        .build()
        .unwrap();
        let f = Field::new(&vol, FilterKind::parse("bspline3", 0.0).unwrap());
        let iso = f.separating_iso(0.5);
        let tags = classify(&f, iso, Method::Bezier(2)).tags;
        let index = Arc::new(TaggedIndex::build(&tags));
        let masks = vec![u64::MAX; index.count()];
        let planes = PlaneBounds::build(&f, index, &masks, iso);
        // Gradient ≈ 0.2 per voxel at the surface (sigma 3); the planes'
        // bounds are a small part of it.
        let worst = planes
            .tests
            .iter()
            .map(|t| t.plane[4])
            .fold(0.0f32, f32::max);
        let grad = planes
            .tests
            .iter()
            .map(|t| (t.plane[1].powi(2) + t.plane[2].powi(2) + t.plane[3].powi(2)).sqrt())
            .fold(f32::INFINITY, f32::min);
        assert!(worst < 0.2 * grad, "e {worst} against |a| {grad}");
        // A segment along a face, far on one side of the plane, is cleared;
        // one through the plane is not; NaN proves nothing.
        let p = [1.0, 2.0, 0.0, 0.0, 0.1, 0.0];
        assert!(planes.clears(&p, [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]));
        assert!(!planes.clears(&p, [0.0; 3], [-1.0, 0.0, 0.0]));
        assert!(!planes.clears(&[f32::NAN, 0.0, 0.0, 0.0, 0.0, 0.0], [0.0; 3], [1.0; 3]));
        assert!(!planes.clears(&[5.0, 0.0, 0.0, 0.0, f32::NAN, 0.0], [0.0; 3], [1.0; 3]));
    }
}
