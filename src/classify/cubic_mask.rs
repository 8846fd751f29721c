//! The sub-cell mask of a cubic patch ([`super::bezier::SubCells::mask`] for
//! support 4: B-splines of degree 3, Catmull-Rom, the smoothing spline) in
//! AVX-512 registers.
//!
//! A cubic cell's tensor Bernstein patch is 4³ = 64 values, eight vectors of
//! eight: vector `r` holds plane `z = r / 2`, rows `y = 2(r % 2)` and
//! `2(r % 2) + 1`, four values along x each. The de Casteljau halvings are
//! then vector arithmetic: along z between whole planes (two vectors each),
//! along y between rows brought together by 128-bit lane shuffles, along x
//! between the values of a row by permutes. Each child value is the same
//! average of the same two values, in the same order, as the scalar halving
//! ([`super::bezier`]'s `halve_into`), so the masks are bit for bit its masks
//! (tested over random patches here, and against the scalar masks over
//! every tagged cell of a scrambled volume in [`super::bezier`]'s tests).
//!
//! The masks were two thirds of the Bézier classification of the 64³
//! sphere (`snell render` of an 8×8 image, one thread: 15 → 5 ms with the
//! masks left out). Here a mask of one of the 128³ sphere's tagged cells
//! takes 313 ns against 942 for the scalar halving (`cargo bench --bench
//! stages -- 'sub-cell'`, and with `SNELL_ISA=avx2` for the scalar). Of
//! the shuffles, the ones along x are the dearest (nine per vector); taking
//! the left half's rounds with the previous value instead, so that blends
//! place both halves, measured slower (450 against 400 ns on random
//! patches), and testing each child vector by vector rather than from its
//! lanes' extremes cost 32 mask operations a child (530 ns).

use std::arch::x86_64::*;

/// A cubic patch in registers (see the module's layout).
type Patch = [__m512d; 8];

/// `0.5 · (a + b)`, the halving's one operation.
#[inline(always)]
unsafe fn avg(a: __m512d, b: __m512d) -> __m512d {
    // SAFETY: called only from AVX-512 F code (`mask`, and the tests'
    // `children`).
    unsafe { _mm512_mul_pd(_mm512_set1_pd(0.5), _mm512_add_pd(a, b)) }
}

/// de Casteljau at 1/2 across four vectors (one value per lane each): the
/// left and right halves, vector by vector.
#[inline(always)]
unsafe fn split4(p: [__m512d; 4]) -> ([__m512d; 4], [__m512d; 4]) {
    // SAFETY: as above.
    unsafe {
        let a = [avg(p[0], p[1]), avg(p[1], p[2]), avg(p[2], p[3])];
        let b = [avg(a[0], a[1]), avg(a[1], a[2])];
        let c = avg(b[0], b[1]);
        ([p[0], a[0], b[0], c], [c, b[1], a[2], p[3]])
    }
}

/// Lanes `i` and `j` of each row of `a` and `b`, the first two of each
/// row of the result (the rest unused).
#[inline(always)]
unsafe fn pick(a: __m512d, i: i64, b: __m512d, j: i64) -> __m512d {
    // SAFETY: as above.
    unsafe {
        let idx = _mm512_setr_epi64(i, 8 + j, 0, 0, 4 + i, 12 + j, 0, 0);
        _mm512_permutex2var_pd(a, idx, b)
    }
}

/// Halves along x: each vector's two rows of four, within the vector.
#[inline(always)]
unsafe fn halve_x(p: &Patch) -> (Patch, Patch) {
    // SAFETY: as above.
    unsafe {
        // Lane i of a row takes lane i + 1 (the last repeats itself; what it
        // computes is never used).
        let next = _mm512_setr_epi64(1, 2, 3, 3, 5, 6, 7, 7);
        // The first two lanes of each row of two picks, side by side.
        let join = _mm512_setr_epi64(0, 1, 8, 9, 4, 5, 12, 13);
        let mut left = [_mm512_setzero_pd(); 8];
        let mut right = [_mm512_setzero_pd(); 8];
        for r in 0..8 {
            let w = p[r];
            let w1 = avg(w, _mm512_permutexvar_pd(next, w));
            let w2 = avg(w1, _mm512_permutexvar_pd(next, w1));
            let w3 = avg(w2, _mm512_permutexvar_pd(next, w2));
            // Left row: w[0], w1[0], w2[0], w3[0]; right row: w3[0], w2[1],
            // w1[2], w[3].
            left[r] = _mm512_permutex2var_pd(pick(w, 0, w1, 0), join, pick(w2, 0, w3, 0));
            right[r] = _mm512_permutex2var_pd(pick(w3, 0, w2, 1), join, pick(w1, 2, w, 3));
        }
        (left, right)
    }
}

/// Halves along y: row `y` of two planes brought into one vector, split
/// across the four rows, and put back.
#[inline(always)]
unsafe fn halve_y(p: &Patch) -> (Patch, Patch) {
    // SAFETY: as above.
    unsafe {
        let mut left = [_mm512_setzero_pd(); 8];
        let mut right = [_mm512_setzero_pd(); 8];
        // Planes (0, 1), then (2, 3): vectors 0..4, then 4..8.
        for q in [0, 4] {
            let (a0, a1, b0, b1) = (p[q], p[q + 2], p[q + 1], p[q + 3]);
            // Rows 0 and 1 of both planes, then rows 2 and 3.
            let rows = [
                _mm512_shuffle_f64x2::<0x44>(a0, a1),
                _mm512_shuffle_f64x2::<0xEE>(a0, a1),
                _mm512_shuffle_f64x2::<0x44>(b0, b1),
                _mm512_shuffle_f64x2::<0xEE>(b0, b1),
            ];
            let (l, r) = split4(rows);
            for (out, h) in [(&mut left, l), (&mut right, r)] {
                out[q] = _mm512_shuffle_f64x2::<0x44>(h[0], h[1]);
                out[q + 2] = _mm512_shuffle_f64x2::<0xEE>(h[0], h[1]);
                out[q + 1] = _mm512_shuffle_f64x2::<0x44>(h[2], h[3]);
                out[q + 3] = _mm512_shuffle_f64x2::<0xEE>(h[2], h[3]);
            }
        }
        (left, right)
    }
}

/// Halves along z: whole planes, two vectors each.
#[inline(always)]
unsafe fn halve_z(p: &Patch) -> (Patch, Patch) {
    // SAFETY: as above.
    unsafe {
        let mut left = [_mm512_setzero_pd(); 8];
        let mut right = [_mm512_setzero_pd(); 8];
        for h in 0..2 {
            let (l, r) = split4([p[h], p[2 + h], p[4 + h], p[6 + h]]);
            for k in 0..4 {
                left[2 * k + h] = l[k];
                right[2 * k + h] = r[k];
            }
        }
        (left, right)
    }
}

/// The eight half-size children of `p` (child `x + 2y + 4z` into
/// `out[x + 2y + 4z]` when `out` is given), halved along x, then y, then z
/// (the scalar `octants`' order), and the bits of those that straddle the
/// iso-value. Inlined, so with `None` the children are never stored.
#[inline(always)]
unsafe fn octants(p: &Patch, eps: f64, mut out: Option<&mut [Patch; 8]>) -> u8 {
    // SAFETY: as above.
    unsafe {
        let mut bits = 0u8;
        let (x0, x1) = halve_x(p);
        for (i, xi) in [x0, x1].iter().enumerate() {
            let (y0, y1) = halve_y(xi);
            for (j, yj) in [y0, y1].iter().enumerate() {
                let (z0, z1) = halve_z(yj);
                bits |= (straddles(&z0, eps) as u8) << (i + 2 * j);
                bits |= (straddles(&z1, eps) as u8) << (i + 2 * j + 4);
                if let Some(out) = out.as_deref_mut() {
                    out[i + 2 * j] = z0;
                    out[i + 2 * j + 4] = z1;
                }
            }
        }
        bits
    }
}

/// Whether the patch has a value `<= eps` and one `> -eps` (NaN counts as
/// neither), as the scalar `straddles`: each lane's least and greatest
/// value first (`min(v, acc)` keeps `acc` when `v` is NaN), then one
/// comparison each.
#[inline(always)]
unsafe fn straddles(p: &Patch, eps: f64) -> bool {
    // SAFETY: as above.
    unsafe {
        let mut lo = _mm512_set1_pd(f64::INFINITY);
        let mut hi = _mm512_set1_pd(f64::NEG_INFINITY);
        for v in p {
            lo = _mm512_min_pd(*v, lo);
            hi = _mm512_max_pd(*v, hi);
        }
        _mm512_cmp_pd_mask::<_CMP_LE_OQ>(lo, _mm512_set1_pd(eps)) != 0
            && _mm512_cmp_pd_mask::<_CMP_GT_OQ>(hi, _mm512_set1_pd(-eps)) != 0
    }
}

/// [`super::bezier::SubCells::mask`] of the cubic patch `b` (64 values, x
/// fastest): bit `i + 4(j + 4k)` for each quarter-cell whose hull straddles
/// the iso-value within `eps`, through the halves that do.
///
/// # Safety
/// The CPU must have AVX-512 F.
#[target_feature(enable = "avx512f")]
pub unsafe fn mask(b: &[f64; 64], eps: f64) -> u64 {
    // SAFETY: the caller guarantees AVX-512 F; the loads read the 64 values.
    unsafe {
        let p = load(b);
        if !straddles(&p, eps) {
            return 0;
        }
        let mut halves = [[_mm512_setzero_pd(); 8]; 8];
        let straddling = octants(&p, eps, Some(&mut halves));
        let mut mask = 0u64;
        for (h, half) in halves.iter().enumerate() {
            if straddling >> h & 1 == 0 {
                continue;
            }
            let quarters = octants(half, eps, None);
            let (hx, hy, hz) = (h & 1, h >> 1 & 1, h >> 2);
            for q in 0..8 {
                if quarters >> q & 1 != 0 {
                    let (i, j, k) = (2 * hx + (q & 1), 2 * hy + (q >> 1 & 1), 2 * hz + (q >> 2));
                    mask |= 1 << (i + 4 * (j + 4 * k));
                }
            }
        }
        mask
    }
}

/// The 64 values of `b` as a patch.
#[inline(always)]
unsafe fn load(b: &[f64; 64]) -> Patch {
    // SAFETY: the loads read `b`'s 64 values; as above for the features.
    unsafe {
        let mut p = [_mm512_setzero_pd(); 8];
        for (r, v) in p.iter_mut().enumerate() {
            *v = _mm512_loadu_pd(b.as_ptr().add(8 * r));
        }
        p
    }
}

/// The eight children of `b` as [`mask`] computes them, for tests.
#[cfg(test)]
#[target_feature(enable = "avx512f")]
unsafe fn children(b: &[f64; 64]) -> Vec<f64> {
    // SAFETY: as in `mask`; the stores write 64 values per child.
    unsafe {
        let p = load(b);
        let mut halves = [[_mm512_setzero_pd(); 8]; 8];
        octants(&p, 0.0, Some(&mut halves));
        let mut out = vec![0.0; 512];
        for (c, half) in halves.iter().enumerate() {
            for (r, v) in half.iter().enumerate() {
                _mm512_storeu_pd(out.as_mut_ptr().add(64 * c + 8 * r), *v);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classify::bezier::{SubCells, octants_scalar};
    use crate::phantom::{mix64, uniform};

    fn avx512() -> bool {
        std::arch::is_x86_feature_detected!("avx512f")
    }

    /// Patches with values of both signs at several scales, some all of one
    /// sign, with zeros of both signs, NaNs, infinities and subnormals.
    fn patches() -> Vec<[f64; 64]> {
        let specials = [
            0.0,
            -0.0,
            f64::NAN,
            f64::INFINITY,
            -f64::INFINITY,
            1e-310,
            -3e-308,
        ];
        (0..4000u64)
            .map(|k| {
                let scale = [1e-9, 1.0, 300.0, 1e12][k as usize % 4];
                let shift = [0.0, 0.5, -0.5, 0.9, -0.9][k as usize % 5];
                std::array::from_fn(|e| {
                    let v = scale * (2.0 * uniform(mix64(k), e as u64) - 1.0 + shift);
                    if k % 17 == 0 && e as u64 == k % 64 {
                        specials[(k / 17) as usize % specials.len()]
                    } else {
                        v
                    }
                })
            })
            .collect()
    }

    #[test]
    fn children_are_the_scalar_halvings_bit_for_bit() {
        if !crate::simd::kernels_run("the AVX-512 cubic masks", avx512()) {
            return;
        }
        for b in patches() {
            // SAFETY: AVX-512 F checked above.
            let got = unsafe { children(&b) };
            let want = octants_scalar::<4>(&b);
            for (e, (g, w)) in got.iter().zip(&want).enumerate() {
                assert!(
                    g.to_bits() == w.to_bits() || (g.is_nan() && w.is_nan()),
                    "child {} element {}: {g} != {w}",
                    e / 64,
                    e % 64
                );
            }
        }
    }

    #[test]
    fn masks_are_the_scalar_masks() {
        if !crate::simd::kernels_run("the AVX-512 cubic masks", avx512()) {
            return;
        }
        let mut sub = SubCells::scalar_for_support(4);
        let (mut nonzero, mut partial) = (0, 0);
        for b in patches() {
            for eps in [0.0, 1e-12, 0.25] {
                let want = sub.mask_scalar::<4>(&b, eps);
                // SAFETY: AVX-512 F checked above.
                let got = unsafe { mask(&b, eps) };
                assert_eq!(got, want, "eps {eps}");
                nonzero += (want != 0) as usize;
                partial += (want != 0 && want != u64::MAX) as usize;
            }
        }
        // The patches exercise empty, partial and full masks.
        assert!(nonzero > 3000 && partial > 2000, "{nonzero} {partial}");
    }
}
