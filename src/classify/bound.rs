//! Conservative value bounds of the field over one knot cell.
//!
//! With non-negative weights that sum to one (B-splines), `f` over a cell lies
//! between the smallest and largest coefficient of the cell's `S³` support. A
//! kernel with negative lobes (Catmull-Rom) breaks that; for it we bound each
//! term `(c - iso)·w_i·w_j·w_k` by the range of the weight product over the
//! cell (per-axis weight ranges, multiplied as intervals), which is still
//! exact-safe, only looser.

use crate::filter::coeffs::Coefficient;
use crate::filter::{Field, Kernel};

/// How to bound a cell for one kernel.
#[derive(Clone, Debug)]
pub enum CellBound {
    /// Min/max of the coefficients (non-negative kernels).
    CoefficientRange { support: usize },
    /// Interval products of signed weights: `lo/hi[i + S(j + S k)]`,
    /// intersected with the coefficient range widened by the Lebesgue
    /// constant `lebesgue` (per axis, cubed).
    SignedWeights {
        support: usize,
        lo: Vec<f64>,
        hi: Vec<f64>,
        lebesgue: f64,
    },
}

impl CellBound {
    pub fn new(kernel: &Kernel) -> CellBound {
        let s = kernel.support();
        if kernel.is_nonnegative() {
            return CellBound::CoefficientRange { support: s };
        }
        let ranges: Vec<(f64, f64)> = (0..s).map(|j| kernel.weight_range(j, 0.0, 1.0)).collect();
        let mut lo = vec![0.0; s * s * s];
        let mut hi = vec![0.0; s * s * s];
        for k in 0..s {
            for j in 0..s {
                for i in 0..s {
                    let (mn, mx) = interval_product(ranges[i], ranges[j], ranges[k]);
                    lo[i + s * (j + s * k)] = mn;
                    hi[i + s * (j + s * k)] = mx;
                }
            }
        }
        CellBound::SignedWeights {
            support: s,
            lo,
            hi,
            lebesgue: kernel.lebesgue_constant().powi(3),
        }
    }

    /// `[min, max]` bound of `f` over knot cell `cell` (which must be in range).
    pub fn range<T: Coefficient>(&self, field: &Field<T>, cell: [i64; 3], iso: f64) -> (f64, f64) {
        let coeffs = field.coeffs();
        let s = match self {
            CellBound::CoefficientRange { support } | CellBound::SignedWeights { support, .. } => {
                *support
            }
        };
        let base = field.support_offset(cell);
        let (sy, sz) = (coeffs.stride(1), coeffs.stride(2));
        let data = coeffs.data();
        match self {
            CellBound::CoefficientRange { .. } => {
                let (mut mn, mut mx) = (f64::INFINITY, f64::NEG_INFINITY);
                for k in 0..s {
                    for j in 0..s {
                        for c in &data[base + j * sy + k * sz..][..s] {
                            let c = c.to_f64();
                            mn = mn.min(c);
                            mx = mx.max(c);
                        }
                    }
                }
                (mn, mx)
            }
            CellBound::SignedWeights {
                lo, hi, lebesgue, ..
            } => {
                let (mut low, mut high) = (0.0, 0.0);
                let (mut cmin, mut cmax) = (f64::INFINITY, f64::NEG_INFINITY);
                for k in 0..s {
                    for j in 0..s {
                        let row = &data[base + j * sy + k * sz..][..s];
                        for (i, c) in row.iter().enumerate() {
                            let c = c.to_f64();
                            cmin = cmin.min(c);
                            cmax = cmax.max(c);
                            let d = c - iso;
                            let w = i + s * (j + s * k);
                            if d >= 0.0 {
                                low += d * lo[w];
                                high += d * hi[w];
                            } else {
                                low += d * hi[w];
                                high += d * lo[w];
                            }
                        }
                    }
                }
                let (mid, half) = (0.5 * (cmin + cmax), 0.5 * (cmax - cmin));
                (
                    (iso + low).max(mid - lebesgue * half),
                    (iso + high).min(mid + lebesgue * half),
                )
            }
        }
    }

    /// False only when the cell provably holds no crossing of `iso`.
    #[inline]
    pub fn may_cross<T: Coefficient>(&self, field: &Field<T>, cell: [i64; 3], iso: f64) -> bool {
        let (lo, hi) = self.range(field, cell, iso);
        lo <= iso && iso <= hi
    }
}

/// The range of `x·y·z` over the box of intervals `a × b × c` (any signs):
/// the least and largest product of their ends.
#[inline]
pub(crate) fn interval_product(a: (f64, f64), b: (f64, f64), c: (f64, f64)) -> (f64, f64) {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for x in [a.0, a.1] {
        for y in [b.0, b.1] {
            for z in [c.0, c.1] {
                let p = x * y * z;
                lo = lo.min(p);
                hi = hi.max(p);
            }
        }
    }
    (lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::FilterKind;
    use crate::lattice::Lattice;
    use glam::DVec3;

    #[test]
    fn bounds_contain_dense_samples() {
        let dims = [6usize, 5, 7];
        let vol = crate::volume::scrambled_u8(dims, 0);
        for name in ["linear", "catmull-rom", "bspline2", "bspline3"] {
            let f = Field::new(&vol, FilterKind::parse(name, 0.0).unwrap());
            let lat = Lattice::new(f.kernel(), dims);
            let b = CellBound::new(f.kernel());
            for cz in 0..lat.cells[2] as i64 {
                for cy in 0..lat.cells[1] as i64 {
                    for cx in 0..lat.cells[0] as i64 {
                        let (lo, hi) = b.range(&f, [cx, cy, cz], 100.0);
                        for q in 0..27 {
                            let t = [
                                (q % 3) as f64 / 2.0,
                                (q / 3 % 3) as f64 / 2.0,
                                (q / 9) as f64 / 2.0,
                            ];
                            let x = [cx, cy, cz].map(|c| c as f64 - lat.offset);
                            let p = DVec3::new(x[0] + t[0], x[1] + t[1], x[2] + t[2])
                                .clamp(DVec3::ZERO, DVec3::new(5.0, 4.0, 6.0));
                            let v = f.value(p);
                            assert!(
                                v >= lo - 1e-9 && v <= hi + 1e-9,
                                "{name} cell {cx},{cy},{cz}: {v} not in [{lo},{hi}]"
                            );
                        }
                    }
                }
            }
        }
    }
}
