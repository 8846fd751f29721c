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
use crate::simd::Madd;

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
        let coeffs = self.coeffs();
        let base = self.support_offset(cell);
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

/// `L` segments restricted together, one per lane.
#[derive(Clone, Copy, Debug)]
pub struct LaneSegments<const L: usize> {
    /// Offset of each lane's `S³` neighbourhood in the coefficient grid.
    pub base: [usize; L],
    /// Per axis: local knot-cell coordinate of the segment start (`τ0`).
    pub tau: [[f64; L]; 3],
    /// Per axis: extent of the segment (`Δ`).
    pub delta: [[f64; L]; 3],
}

impl<T: Coefficient> Field<T> {
    /// Lane inputs of one segment: `cell`, endpoints `p0`, `p1` (grid units).
    #[inline(always)]
    pub fn lane_segment(
        &self,
        cell: [i64; 3],
        p0: [f64; 3],
        p1: [f64; 3],
    ) -> (usize, [f64; 3], [f64; 3]) {
        let off = self.kernel().knot_offset();
        let base = self.support_offset(cell);
        let tau = std::array::from_fn(|a| p0[a] + off - cell[a] as f64);
        let delta = std::array::from_fn(|a| p1[a] - p0[a]);
        (base, tau, delta)
    }

    /// [`Field::restrict`] for `L` segments at once: monomial coefficients of
    /// `g(s) - iso` per lane, `out[m][lane]` for `m ≤ 3(S-1)`; the rows
    /// above may be left as they were (callers reusing `out` keep them zero).
    /// Every lane does the same arithmetic, so the loops over lanes
    /// vectorize; `M` fuses the multiply-adds where the instruction set can.
    /// Under AVX-512 the cubic and quadratic filters take register kernels
    /// with the same operations ([`crate::simd::restrict_cubic_x8`],
    /// [`crate::simd::restrict_quadratic_x8`]: single-thread sphere solve
    /// stage with the quadratic B-spline 15.3 → 12.1 ms).
    #[inline(always)]
    pub fn restrict_lanes<const S: usize, const L: usize, M: Madd>(
        &self,
        seg: &LaneSegments<L>,
        iso: f64,
        out: &mut [[f64; L]; N],
    ) {
        #[cfg(target_arch = "x86_64")]
        if (S == 3 || S == 4)
            && L == 8
            && M::FUSED
            && crate::simd::Isa::current() == crate::simd::Isa::Avx512
        {
            let kernel = self.kernel();
            let (data, sy, sz) = self.lane_rows::<S, L>(&seg.base);
            // Plain copies (`L == 8` here): built by `from_fn`, the cubic
            // solve stage measured 5% slower.
            let lanes = |v: &[[f64; L]; 3]| -> [[f64; 8]; 3] {
                let mut o = [[0.0; 8]; 3];
                for a in 0..3 {
                    o[a].copy_from_slice(&v[a]);
                }
                o
            };
            let (tau, delta) = (lanes(&seg.tau), lanes(&seg.delta));
            let mut base = [0usize; 8];
            base.copy_from_slice(&seg.base);
            if S == 4 {
                let mut poly = [[0.0; 4]; 4];
                for (j, p) in poly.iter_mut().enumerate() {
                    p.copy_from_slice(&kernel.weight_poly(j)[..4]);
                }
                // Degree 9: ten rows (the caller's rows above stay as they
                // are, zero).
                let mut g = [[0.0f64; 8]; 10];
                // SAFETY: AVX-512 and FMA checked above; every row lies in
                // `base + span <= data.len()` (asserted by `lane_rows`).
                unsafe {
                    crate::simd::restrict_cubic_x8(
                        data,
                        &base,
                        (sy, sz),
                        &tau,
                        &delta,
                        &poly,
                        iso,
                        &mut g,
                    )
                };
                for (o, v) in out.iter_mut().zip(&g) {
                    o.copy_from_slice(v);
                }
                return;
            }
            // The quadratic kernel reads each row of three as a row of four.
            let span = 2 * (sy + sz) + 4;
            if base.iter().all(|&b| b + span <= data.len()) {
                let poly: [[f64; 3]; 3] =
                    std::array::from_fn(|j| std::array::from_fn(|m| kernel.weight_poly(j)[m]));
                // Degree 6: seven rows (the caller's rows above stay zero).
                let mut g = [[0.0f64; 8]; 7];
                // SAFETY: AVX-512 and FMA checked above; every row and the
                // value after it lie in `data` (checked above).
                unsafe {
                    crate::simd::restrict_quadratic_x8(
                        data,
                        &base,
                        (sy, sz),
                        &tau,
                        &delta,
                        &poly,
                        iso,
                        &mut g,
                    )
                };
                for (o, v) in out.iter_mut().zip(&g) {
                    o.copy_from_slice(v);
                }
                return;
            }
        }
        self.restrict_lanes_generic::<S, L, M>(seg, iso, out)
    }

    /// The coefficients and their row and plane strides, once every lane's
    /// support-`S` neighbourhood (from offsets `base`, as
    /// [`Field::support_offset`] gives them) is checked to lie inside them:
    /// the lane kernels index rows from `base` without further checks.
    #[inline(always)]
    pub(crate) fn lane_rows<const S: usize, const L: usize>(
        &self,
        base: &[usize; L],
    ) -> (&[T], usize, usize) {
        let coeffs = self.coeffs();
        let (sy, sz) = (coeffs.stride(1), coeffs.stride(2));
        let data = coeffs.data();
        let span = (S - 1) * (sy + sz) + S;
        for &b in base {
            assert!(b + span <= data.len(), "lane neighbourhood inside the grid");
        }
        (data, sy, sz)
    }

    /// [`Field::restrict_lanes`] for any support and lane count, in
    /// loops over lanes left to the compiler.
    #[inline(always)]
    fn restrict_lanes_generic<const S: usize, const L: usize, M: Madd>(
        &self,
        seg: &LaneSegments<L>,
        iso: f64,
        out: &mut [[f64; L]; N],
    ) {
        let kernel = self.kernel();
        let (data, sy, sz) = self.lane_rows::<S, L>(&seg.base);
        // w[a][j][m][lane]: weight polynomial j of axis a composed with the segment.
        let mut w = [[[[0.0f64; L]; S]; S]; 3];
        for a in 0..3 {
            let (tau, delta) = (&seg.tau[a], &seg.delta[a]);
            for j in 0..S {
                let p = kernel.weight_poly(j);
                let q = &mut w[a][j];
                for m in 0..S {
                    q[m] = [p[m]; L];
                }
                for i in 0..S - 1 {
                    for k in (i..S - 1).rev() {
                        let next = q[k + 1];
                        for l in 0..L {
                            q[k][l] = M::madd(tau[l], next[l], q[k][l]);
                        }
                    }
                }
                let mut sc = *delta;
                for c in q.iter_mut().skip(1) {
                    for l in 0..L {
                        c[l] *= sc[l];
                        sc[l] *= delta[l];
                    }
                }
            }
        }
        let d1 = S - 1;
        let mut g = [[0.0f64; L]; N];
        for k in 0..S {
            let mut bk = [[0.0f64; L]; N];
            for j in 0..S {
                let mut ajk = [[0.0f64; L]; S];
                let row = j * sy + k * sz;
                // A cubic's x-row is 4 contiguous coefficients: one vector
                // load per lane and a transpose beat four gathers (same values).
                let rows4 = (S == 4).then(|| {
                    // SAFETY: base + row + 3 < base + span <= data.len()
                    // (asserted by `lane_rows`); L is bound by `with_isa!`.
                    unsafe { crate::simd::gather_rows4::<T, L>(data, &seg.base, row) }
                });
                for i in 0..S {
                    let c: [f64; L] = match &rows4 {
                        Some(r) => r[i],
                        // SAFETY: base + row + i < base + span <= data.len()
                        // (asserted by `lane_rows`); L is bound by `with_isa!`.
                        None => unsafe { T::gather(data, &seg.base, row + i) },
                    };
                    let wx = &w[0][i];
                    for m in 0..S {
                        for l in 0..L {
                            ajk[m][l] = M::madd(c[l], wx[m][l], ajk[m][l]);
                        }
                    }
                }
                let wy = &w[1][j];
                for m in 0..S {
                    for n in 0..S {
                        for l in 0..L {
                            bk[m + n][l] = M::madd(ajk[m][l], wy[n][l], bk[m + n][l]);
                        }
                    }
                }
            }
            let wz = &w[2][k];
            for m in 0..=2 * d1 {
                for n in 0..S {
                    for l in 0..L {
                        g[m + n][l] = M::madd(bk[m][l], wz[n][l], g[m + n][l]);
                    }
                }
            }
        }
        for l in 0..L {
            g[0][l] -= iso;
        }
        *out = g;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The AVX-512 cubic and quadratic kernels give the generic lane loops'
    /// coefficients bit for bit (both fused), for three cubic filters and
    /// the quadratic B-spline over `f64`, `f32` and `f16` storage, on
    /// segments in general position and along axes.
    #[test]
    fn lane_kernels_are_the_generic_restriction_bitwise() {
        use crate::phantom::{mix64, uniform};
        if !crate::simd::kernels_run(
            "the AVX-512 restriction kernels",
            crate::simd::Isa::current() == crate::simd::Isa::Avx512,
        ) {
            return;
        }
        let dims = [12usize, 11, 13];
        let vol = crate::volume::scrambled_u8(dims, 3);
        let mut checked = 0;
        // The cubic kernel (three cubic filters) and the quadratic one.
        for name in ["bspline3", "catmull-rom", "smooth-bspline3", "bspline2"] {
            let kind = FilterKind::parse(name, 0.5).unwrap();
            let f64s = Field::new(&vol, kind);
            let f32s = Field::<f32>::new_f32(&vol, kind);
            let f16s = Field::<half::f16>::new_in(&vol, kind);
            for k in 0..300u64 {
                let r = |j: u64| uniform(mix64(k), j);
                let mut seg = LaneSegments::<8> {
                    base: [0; 8],
                    tau: [[0.0; 8]; 3],
                    delta: [[0.0; 8]; 3],
                };
                for l in 0..8 {
                    let j = 16 * l as u64;
                    let cell = [0, 1, 2].map(|a| 2 + (r(j + a) * 7.0) as i64);
                    let off = f64s.kernel().knot_offset();
                    let p0: [f64; 3] =
                        std::array::from_fn(|a| cell[a] as f64 - off + r(j + 3 + a as u64));
                    let mut p1: [f64; 3] =
                        std::array::from_fn(|a| cell[a] as f64 - off + r(j + 6 + a as u64));
                    if k % 5 == 0 {
                        // Along an axis.
                        p1 = [p0[0], p0[1], p1[2]];
                    }
                    let (base, tau, delta) = f64s.lane_segment(cell, p0, p1);
                    seg.base[l] = base;
                    for a in 0..3 {
                        seg.tau[a][l] = tau[a];
                        seg.delta[a][l] = delta[a];
                    }
                }
                let iso = 100.0 + r(999);
                let isa = crate::simd::Isa::Avx512;
                with_support!(f64s.kernel().support(), S => crate::with_isa!(isa, L, M => {
                    if L == 8 {
                        let seg8 = LaneSegments::<L> {
                            base: std::array::from_fn(|l| seg.base[l]),
                            tau: std::array::from_fn(|a| std::array::from_fn(|l| seg.tau[a][l])),
                            delta: std::array::from_fn(|a| std::array::from_fn(|l| seg.delta[a][l])),
                        };
                        let (mut a, mut b) = ([[0.0; L]; N], [[0.0; L]; N]);
                        let bits = |v: &[[f64; L]; N]| v.map(|r| r.map(f64::to_bits));
                        f64s.restrict_lanes::<S, L, M>(&seg8, iso, &mut a);
                        f64s.restrict_lanes_generic::<S, L, M>(&seg8, iso, &mut b);
                        assert_eq!(bits(&a), bits(&b), "{name} f64 {k}");
                        f16s.restrict_lanes::<S, L, M>(&seg8, iso, &mut a);
                        f16s.restrict_lanes_generic::<S, L, M>(&seg8, iso, &mut b);
                        assert_eq!(bits(&a), bits(&b), "{name} f16 {k}");
                        f32s.restrict_lanes::<S, L, M>(&seg8, iso, &mut a);
                        f32s.restrict_lanes_generic::<S, L, M>(&seg8, iso, &mut b);
                        assert_eq!(bits(&a), bits(&b), "{name} f32 {k}");
                        // The top degree needs motion along every axis.
                        assert!(k % 5 == 0 || a[3 * (S - 1)].iter().all(|&c| c != 0.0));
                    }
                }));
                checked += 1;
            }
        }
        assert_eq!(checked, 1200);
    }
    use crate::filter::FilterKind;
    use crate::roots::bernstein::BernsteinBasis;
    use crate::with_support;
    use glam::DVec3;

    #[test]
    fn restriction_matches_point_evaluation() {
        let dims = [7usize, 6, 8];
        let vol = crate::volume::scrambled_u8(dims, 0);
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
            // The lane version agrees with the scalar one, for every lane.
            let (base, tau, delta) = f.lane_segment(cell, p0, p1);
            let seg = LaneSegments::<4> {
                base: [base; 4],
                tau: std::array::from_fn(|a| [tau[a]; 4]),
                delta: std::array::from_fn(|a| [delta[a]; 4]),
            };
            let mut lanes = [[0.0; 4]; N];
            with_support!(f.kernel().support(), S => f.restrict_lanes::<S, 4, crate::simd::Plain>(&seg, iso, &mut lanes));
            for m in 0..=degree {
                for l in 0..4 {
                    assert!(
                        (lanes[m][l] - g[m]).abs() <= 1e-9 * (1.0 + g[m].abs()),
                        "{name} m={m}"
                    );
                }
            }
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
