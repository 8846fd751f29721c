//! The field restricted to a ray segment: an exact polynomial.
//!
//! Inside one knot cell every weight is a single polynomial `W_j(t)` of degree
//! `S-1` per axis, and along a segment `p(s) = p0 + s (p1 - p0)` each local
//! coordinate is linear in `s`. So `f(p(s))` is the tensor sum
//!
//! ```text
//! g(s) = Σ_k Wz_k(s) Σ_j Wy_j(s) Σ_i Wx_i(s) c_ijk  -  iso
//! ```
//!
//! of degree `3(S-1)` (a cubic for trilinear, degree 9 for cubic filters). It
//! is built from one load of the cell's `S³` coefficients; after that, root
//! isolation and Brent cost polynomial arithmetic, not memory.

use super::Field;
use super::coeffs::Coefficient;
use crate::roots::bernstein::MAX_DEGREE;

const N: usize = MAX_DEGREE + 1;

/// Index of the knot cell holding grid coordinate `x` (unclamped): cells are
/// `[i - offset, i + 1 - offset)` with the kernel's knot offset.
#[inline(always)]
pub fn knot_cell(x: f64, offset: f64) -> i64 {
    (x + offset).floor() as i64
}

impl<T: Coefficient> Field<T> {
    /// Monomial coefficients (lowest first, `3(S-1)+1` of them) of
    /// `g(s) = f(p0 + s(p1 - p0)) - iso` for `s ∈ [0, 1]`, where the segment
    /// lies inside knot cell `cell` (indices as [`knot_cell`]). The cell must
    /// be inside the domain's cell range so its support is within the apron.
    #[inline]
    pub fn restrict<const S: usize>(
        &self,
        cell: [i64; 3],
        p0: [f64; 3],
        p1: [f64; 3],
        iso: f64,
        out: &mut [f64; N],
    ) {
        let kernel = self.kernel();
        let off = kernel.knot_offset();
        // Per axis: the S weight polynomials composed with the segment.
        let mut w = [[[0.0f64; S]; S]; 3];
        for a in 0..3 {
            let tau = p0[a] + off - cell[a] as f64;
            let delta = p1[a] - p0[a];
            for (j, wj) in w[a].iter_mut().enumerate() {
                wj.copy_from_slice(kernel.weight_poly(j));
                // Taylor shift: W(tau + y).
                for i in 0..S - 1 {
                    for k in (i..S - 1).rev() {
                        wj[k] += tau * wj[k + 1];
                    }
                }
                // Scale: y = delta * s.
                let mut sc = delta;
                for c in wj.iter_mut().skip(1) {
                    *c *= sc;
                    sc *= delta;
                }
            }
        }
        let lead = ((S - 1) / 2) as i64;
        let coeffs = self.coeffs();
        let base = coeffs.offset(
            (cell[0] - lead) as isize,
            (cell[1] - lead) as isize,
            (cell[2] - lead) as isize,
        );
        let (sy, sz) = (coeffs.stride(1), coeffs.stride(2));
        let data = coeffs.data();
        let d1 = S - 1;
        let mut g = [0.0f64; N];
        for (k, wz) in w[2].iter().enumerate() {
            // B_k(s) = Σ_j A_jk(s) Wy_j(s), degree 2(S-1).
            let mut bk = [0.0f64; N];
            for (j, wy) in w[1].iter().enumerate() {
                let row = &data[base + j * sy + k * sz..][..S];
                // A_jk(s) = Σ_i c_ijk Wx_i(s), degree S-1.
                let mut ajk = [0.0f64; S];
                for (i, wx) in w[0].iter().enumerate() {
                    let c = row[i].to_f64();
                    for m in 0..S {
                        ajk[m] += c * wx[m];
                    }
                }
                for (m, am) in ajk.iter().enumerate() {
                    for (n, wn) in wy.iter().enumerate() {
                        bk[m + n] += am * wn;
                    }
                }
            }
            for (m, bm) in bk.iter().take(2 * d1 + 1).enumerate() {
                for (n, wn) in wz.iter().enumerate() {
                    g[m + n] += bm * wn;
                }
            }
        }
        g[0] -= iso;
        *out = g;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::FilterKind;
    use crate::roots::bernstein::BernsteinBasis;
    use crate::volume::{SampleType, Volume};
    use crate::with_support;
    use glam::DVec3;

    #[test]
    fn restriction_matches_point_evaluation() {
        let dims = [7usize, 6, 8];
        let s: Vec<f32> = (0..dims.iter().product::<usize>())
            .map(|i| ((i * 7919) % 251) as f32)
            .collect();
        let vol = Volume::new(dims, [1.0; 3], SampleType::U8, s).unwrap();
        for name in [
            "linear",
            "catmull-rom",
            "bspline2",
            "bspline3",
            "bspline4",
            "bspline7",
        ] {
            let f = Field::new(&vol, FilterKind::parse(name, 0.0).unwrap());
            let off = f.kernel().knot_offset();
            // A segment inside one knot cell, in general position.
            let c = [2.0 + 0.13 - off, 2.0 + 0.71 - off, 3.0 + 0.42 - off];
            let p0 = [c[0], c[1], c[2]];
            let p1 = [c[0] + 0.8, c[1] - 0.6, c[2] + 0.5];
            let cell = [
                knot_cell(p0[0], off),
                knot_cell(p0[1], off),
                knot_cell(p0[2], off),
            ];
            for a in 0..3 {
                assert_eq!(
                    knot_cell(p1[a], off),
                    cell[a],
                    "{name}: segment leaves the cell"
                );
            }
            let iso = 100.0;
            let mut g = [0.0; N];
            with_support!(f.kernel().support(), S => f.restrict::<S>(cell, p0, p1, iso, &mut g));
            let degree = 3 * (f.kernel().support() - 1);
            let poly = BernsteinBasis::new(degree).segment(&g[..=degree]);
            for i in 0..=10 {
                let s = i as f64 / 10.0;
                let p = DVec3::new(
                    p0[0] + s * (p1[0] - p0[0]),
                    p0[1] + s * (p1[1] - p0[1]),
                    p0[2] + s * (p1[2] - p0[2]),
                );
                let expect = f.value(p) - iso;
                let got = poly.eval(s);
                assert!(
                    (got - expect).abs() < 1e-9,
                    "{name} s={s}: {got} vs {expect}"
                );
            }
        }
    }
}
