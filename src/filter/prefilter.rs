//! Prefiltering: from samples to B-spline coefficients by recursive filtering.
//!
//! Interpolating B-splines need coefficients `c` with `Σ_k c_k β^n(i-k) = s_i`,
//! i.e. the samples filtered by `1 / B_n(z)`; the smoothing spline filters by
//! `1 / (B_3(z) + λ(-z + 2 - 1/z)^2)`. Both denominators are symmetric Laurent
//! polynomials with `D(1) = 1`, so the filter factors into causal/anti-causal
//! first-order sections, one per pole `|z_i| < 1` (Unser, Aldroubi & Eden 1993),
//! each normalised to unit DC gain.
//!
//! The boundary is the whole-sample mirror of SPEC.md, for which the first
//! causal coefficient has a closed form over one period `2n - 2` — so the
//! result is exact (to rounding) for any line length, including 2, 3 and 5.
//! Long lines use the same sum truncated where `|z|^k` drops below 1e-18.
//!
//! Smoothing splines with `λ > 1/144` have a complex-conjugate pole pair; those
//! lines are filtered in complex arithmetic, which yields a real result.

use std::ops::{Add, Div, Mul, Sub};

use num_complex::Complex64;
use rayon::prelude::*;

use super::coeffs::Coefficient;

/// One factor of the prefilter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Pole {
    Real(f64),
    /// A conjugate pair `z, conj(z)` (two sections, filtered as one where
    /// that keeps the rounding small: see [`pair_weight`]).
    ConjugatePair(Complex64),
}

/// A recursive prefilter; no poles means the identity (linear, Catmull-Rom).
#[derive(Clone, Debug, PartialEq)]
pub struct Prefilter {
    poles: Vec<Pole>,
}

/// Number of adjacent lines filtered together (as SIMD-friendly lanes).
/// A bundle's row is then 256 contiguous bytes in the y and z passes: 32
/// gave the fastest passes of 8, 16, 32 and 64 on a 512³ grid (16 left the
/// y pass at half the others' rate on a Zen 4; BENCHMARKS.md, *The
/// prefilter's passes*), and a bundle (128 KiB for 512 samples, twice that
/// as complex lanes) still fits in L2.
const LANES: usize = 32;

impl Prefilter {
    pub fn identity() -> Prefilter {
        Prefilter { poles: Vec::new() }
    }

    /// Poles of the interpolating B-spline of degree `n` (the roots of the
    /// sampled kernel inside the unit circle; Thévenaz, Blu & Unser 2000).
    pub fn bspline(n: usize) -> Prefilter {
        let poles: Vec<f64> = match n {
            0 | 1 => vec![],
            2 => vec![8f64.sqrt() - 3.0],
            3 => vec![3f64.sqrt() - 2.0],
            4 => vec![
                (664.0 - 438976f64.sqrt()).sqrt() + 304f64.sqrt() - 19.0,
                (664.0 + 438976f64.sqrt()).sqrt() - 304f64.sqrt() - 19.0,
            ],
            5 => vec![
                (135.0 / 2.0 - (17745.0f64 / 4.0).sqrt()).sqrt() + (105.0f64 / 4.0).sqrt()
                    - 13.0 / 2.0,
                (135.0 / 2.0 + (17745.0f64 / 4.0).sqrt()).sqrt()
                    - (105.0f64 / 4.0).sqrt()
                    - 13.0 / 2.0,
            ],
            6 => vec![
                -0.488_294_589_303_044_8,
                -0.081_679_271_076_237_51,
                -0.001_414_151_808_325_817_7,
            ],
            7 => vec![
                -0.535_280_430_796_438_2,
                -0.122_554_615_192_326_69,
                -0.009_148_694_809_608_277,
            ],
            _ => panic!("B-spline degree {n} has no prefilter table"),
        };
        Prefilter {
            poles: poles.into_iter().map(Pole::Real).collect(),
        }
    }

    /// Poles of the cubic smoothing spline `1/(B_3(z) + λ(-z + 2 - 1/z)^2)`.
    ///
    /// With `w = z + 1/z` the denominator is the quadratic
    /// `λw² + (1/6 - 4λ)w + (2/3 + 4λ)`; each root `w` gives the pole
    /// `z = (w ∓ sqrt(w² - 4))/2` inside the unit circle, computed as the
    /// reciprocal of the outer root to avoid cancellation.
    pub fn smoothing_cubic(lambda: f64) -> Prefilter {
        assert!(lambda >= 0.0 && lambda.is_finite());
        if lambda == 0.0 {
            return Prefilter::bspline(3);
        }
        let a = lambda;
        let b = 1.0 / 6.0 - 4.0 * lambda;
        let c = 2.0 / 3.0 + 4.0 * lambda;
        let disc = b * b - 4.0 * a * c; // = 1/36 - 4λ
        let pole_of = |w: Complex64| -> Complex64 {
            let r = (w * w - 4.0).sqrt();
            let (p, m) = (w + r, w - r);
            let outer = if p.norm() >= m.norm() { p } else { m } * 0.5;
            1.0 / outer
        };
        if disc >= 0.0 {
            let q = -0.5 * (b + b.signum() * disc.sqrt());
            let (w1, w2) = (q / a, c / q);
            let z1 = pole_of(Complex64::new(w1, 0.0));
            let z2 = pole_of(Complex64::new(w2, 0.0));
            let mut poles = Vec::new();
            for z in [z1, z2] {
                if z.im.abs() <= 1e-300 {
                    poles.push(Pole::Real(z.re));
                } else {
                    // w real with |w| < 2 puts z on the unit circle; cannot happen
                    // for λ > 0 (D(w) > 0 on [-2, 2]), but stay total.
                    poles.push(Pole::ConjugatePair(z));
                }
            }
            Prefilter { poles }
        } else {
            let w = Complex64::new(-b, (-disc).sqrt()) / (2.0 * a);
            Prefilter {
                poles: vec![Pole::ConjugatePair(pole_of(w))],
            }
        }
    }

    pub fn is_identity(&self) -> bool {
        self.poles.is_empty()
    }

    pub fn poles(&self) -> &[Pole] {
        &self.poles
    }

    /// Product of the section gains `(1 - z)(1 - 1/z)`, which gives unit DC gain.
    fn gain(&self) -> f64 {
        let mut g = Complex64::new(1.0, 0.0);
        for p in &self.poles {
            match *p {
                Pole::Real(z) => g *= (1.0 - z) * (1.0 - 1.0 / z),
                Pole::ConjugatePair(z) => {
                    for z in [z, z.conj()] {
                        g *= (1.0 - z) * (1.0 - 1.0 / z);
                    }
                }
            }
        }
        g.re
    }

    /// Filters one line in place (used by tests and 1-D tools).
    pub fn apply_line(&self, line: &mut [f64]) {
        if self.is_identity() || line.len() < 2 {
            return;
        }
        let mut scratch = Scratch::default();
        self.filter_bundle(line, line.len(), 1, &mut scratch);
    }

    /// Filters a bundle of `lanes` lines stored interleaved (`buf[k*lanes + l]`),
    /// gain included: the real poles' sections in turn, then each conjugate
    /// pair (see [`pair_weight`]).
    fn filter_bundle(&self, buf: &mut [f64], n: usize, lanes: usize, scratch: &mut Scratch) {
        let gain = self.gain();
        for v in buf.iter_mut() {
            *v *= gain;
        }
        for p in &self.poles {
            if let Pole::Real(z) = *p {
                filter_lanes(buf, n, lanes, z, &mut scratch.rinit);
            }
        }
        for p in &self.poles {
            let Pole::ConjugatePair(z) = *p else {
                continue;
            };
            let cbuf = &mut scratch.complex;
            cbuf.clear();
            cbuf.extend(buf.iter().map(|&v| Complex64::new(v, 0.0)));
            filter_lanes(cbuf, n, lanes, z, &mut scratch.cinit);
            match pair_weight(z) {
                Some(w) => {
                    for (o, c) in buf.iter_mut().zip(cbuf.iter()) {
                        *o = w * c.im;
                    }
                }
                None => {
                    filter_lanes(cbuf, n, lanes, z.conj(), &mut scratch.cinit);
                    for (o, c) in buf.iter_mut().zip(cbuf.iter()) {
                        *o = c.re;
                    }
                }
            }
        }
    }

    /// Prefilters an x-fastest `f64` grid of `dims` in place along x, y and z.
    ///
    /// All three passes run in `f64` with a single rounding when the caller
    /// stores the result: an `f32` intermediate would be amplified by the next
    /// pass (the prefilter's gain at Nyquist is 3 for cubic, ~50 for degree 7).
    /// Lines are processed in bundles of adjacent lines, in parallel; each line's
    /// arithmetic is the same whatever thread runs it, so the result does not
    /// depend on the thread count.
    pub fn apply_3d(&self, data: &mut [f64], dims: [usize; 3]) {
        assert_eq!(data.len(), dims[0] * dims[1] * dims[2]);
        self.apply_3d_strided(data, dims, 0, [1, dims[0], dims[0] * dims[1]]);
    }

    /// Like [`Prefilter::apply_3d`] on the `dims` block at `origin` of a larger
    /// grid with the given strides (the interior of a padded grid).
    pub fn apply_3d_strided<T: Coefficient>(
        &self,
        data: &mut [T],
        dims: [usize; 3],
        origin: usize,
        strides: [usize; 3],
    ) {
        if self.is_identity() || dims.contains(&0) {
            return;
        }
        for axis in 0..3 {
            self.apply_axis_strided(data, dims, origin, strides, axis);
        }
    }

    /// One pass of [`Prefilter::apply_3d_strided`]: filters every line along
    /// `axis` (0 = x, 1 = y, 2 = z) of the `dims` block at `origin`. Lines
    /// are filtered in `f64` whatever the storage `T`, which rounds once per
    /// pass.
    pub fn apply_axis_strided<T: Coefficient>(
        &self,
        data: &mut [T],
        dims: [usize; 3],
        origin: usize,
        strides: [usize; 3],
        axis: usize,
    ) {
        if self.is_identity() || dims.contains(&0) {
            return;
        }
        let last = origin + (0..3).map(|a| (dims[a] - 1) * strides[a]).sum::<usize>();
        assert!(last < data.len(), "prefilter block exceeds the grid");
        if dims[axis] < 2 {
            return;
        }
        let (b, c) = match axis {
            0 => (1, 2),
            1 => (0, 2),
            _ => (0, 1),
        };
        let bundles_b = dims[b].div_ceil(LANES);
        let count = bundles_b * dims[c];
        let (stride_a, stride_b, stride_c) = (strides[axis], strides[b], strides[c]);
        let len = dims[axis];
        let ptr = SyncPtr(data.as_mut_ptr());
        (0..count).into_par_iter().for_each_init(
            || (Vec::<f64>::new(), Scratch::default()),
            |(buf, scratch), bundle| {
                let ic = bundle / bundles_b;
                let ib0 = (bundle % bundles_b) * LANES;
                let lanes = LANES.min(dims[b] - ib0);
                buf.clear();
                buf.resize(len * lanes, 0.0);
                let base = origin + ib0 * stride_b + ic * stride_c;
                // SAFETY: bundles cover disjoint sets of lines (distinct
                // (ib, ic) pairs), so no two tasks touch the same element, and
                // every offset is at most `last < data.len()` (checked above);
                // a row's slice (lanes adjacent in memory, `stride_b == 1`)
                // holds only this bundle's elements and lives for one row.
                // The pointer is read once: read through the closure's
                // capture it was reloaded for every element. The y and z
                // passes' rows are contiguous and copy as vectors
                // (BENCHMARKS.md, *The prefilter's passes*).
                let p = ptr.get();
                unsafe {
                    for (k, row) in buf.chunks_exact_mut(lanes).enumerate() {
                        let at = p.add(base + k * stride_a);
                        if stride_b == 1 {
                            let src = std::slice::from_raw_parts(at, lanes);
                            for (v, s) in row.iter_mut().zip(src) {
                                *v = s.to_f64();
                            }
                        } else {
                            for (l, v) in row.iter_mut().enumerate() {
                                *v = (*at.add(l * stride_b)).to_f64();
                            }
                        }
                    }
                }
                self.filter_bundle(buf, len, lanes, scratch);
                unsafe {
                    for (k, row) in buf.chunks_exact(lanes).enumerate() {
                        let at = p.add(base + k * stride_a);
                        if stride_b == 1 {
                            let dst = std::slice::from_raw_parts_mut(at, lanes);
                            for (d, &v) in dst.iter_mut().zip(row) {
                                *d = T::from_f64(v);
                            }
                        } else {
                            for (l, &v) in row.iter().enumerate() {
                                *at.add(l * stride_b) = T::from_f64(v);
                            }
                        }
                    }
                }
            },
        );
    }
}

/// The conjugate pair `z, z̄` by partial fractions: the two sections in
/// cascade, `H_z H_z̄`, equal `B H_z + B̄ H_z̄` with the section
/// `H_z(q) = -z / ((1 - z/q)(1 - z q))` and `B = |z|² / ((z̄ - z)(1 - |z|²))`,
/// which is imaginary; on a real line `H_z̄ s` is the conjugate of `H_z s`, so
/// the pair's output is `2 Re(B H_z s) = w · Im(H_z s)` with
/// `w = -2 Im(B) = -|z|² / (Im(z) (1 - |z|²))`. One complex section instead
/// of two halves the pair's arithmetic (the smoothing spline's prefilter
/// above `λ = 1/144`, the slowest pass of all).
///
/// Returns `None` where `|w|` is large — a pair close to the real axis
/// (`λ` within a relative 7e-6 above 1/144), whose two terms nearly
/// cancel, or close to the unit circle (`λ` above about 1025) — so the
/// caller runs the cascade instead: the weight scales the section's
/// rounding, and past [`MAX_PAIR_WEIGHT`] that would cost more than a few
/// bits.
fn pair_weight(z: Complex64) -> Option<f64> {
    let r2 = z.norm_sqr();
    let w = -r2 / (z.im * (1.0 - r2));
    (w.is_finite() && w.abs() <= MAX_PAIR_WEIGHT).then_some(w)
}

/// The largest partial-fraction weight [`pair_weight`] accepts: at most
/// about five bits of the section's rounding (`λ = 1` has 1.0, `λ = 1000`
/// 31.6).
const MAX_PAIR_WEIGHT: f64 = 32.0;

/// Reusable per-thread buffers.
#[derive(Default)]
struct Scratch {
    complex: Vec<Complex64>,
    rinit: Vec<f64>,
    cinit: Vec<Complex64>,
}

/// A raw pointer that may cross threads; see the SAFETY note at its use.
struct SyncPtr<T>(*mut T);
impl<T> Clone for SyncPtr<T> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<T> Copy for SyncPtr<T> {}
unsafe impl<T> Send for SyncPtr<T> {}
unsafe impl<T> Sync for SyncPtr<T> {}
impl<T> SyncPtr<T> {
    #[inline(always)]
    fn get(self) -> *mut T {
        self.0
    }
}

/// Arithmetic the filter sections need, for real and complex lanes alike.
trait Sample:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Mul<f64, Output = Self>
{
    fn zero() -> Self;
    fn one() -> Self;
    fn norm(self) -> f64;
    fn powi(self, e: usize) -> Self;
}

impl Sample for f64 {
    fn zero() -> Self {
        0.0
    }
    fn one() -> Self {
        1.0
    }
    fn norm(self) -> f64 {
        self.abs()
    }
    fn powi(self, e: usize) -> Self {
        f64::powi(self, e as i32)
    }
}

impl Sample for Complex64 {
    fn zero() -> Self {
        Complex64::new(0.0, 0.0)
    }
    fn one() -> Self {
        Complex64::new(1.0, 0.0)
    }
    fn norm(self) -> f64 {
        Complex64::norm(self)
    }
    fn powi(self, e: usize) -> Self {
        Complex64::powu(&self, e as u32)
    }
}

/// One causal + anti-causal section with pole `z` over `lanes` interleaved lines
/// of length `n ≥ 2`, mirror boundary, exact initialisation.
fn filter_lanes<T: Sample>(buf: &mut [T], n: usize, lanes: usize, z: T, init: &mut Vec<T>) {
    debug_assert!(n >= 2 && buf.len() == n * lanes);
    let period = 2 * n - 2;
    let horizon = (f64::ln(1e-18) / z.norm().ln()).ceil();
    init.clear();
    init.resize(lanes, T::zero());
    if horizon.is_finite() && (n as f64) > horizon + 1.0 {
        // |z|^(n-1) < 1e-18: the mirrored half of the period and the 1/(1-z^p)
        // factor are below rounding, so the plain truncated sum is exact.
        let h = horizon as usize;
        let mut zk = T::one();
        for k in 0..=h {
            let row = &buf[k * lanes..(k + 1) * lanes];
            for (acc, &v) in init.iter_mut().zip(row) {
                *acc = *acc + v * zk;
            }
            zk = zk * z;
        }
    } else {
        // c+[0] = (s0 + z^(n-1) s_(n-1) + Σ_{k=1}^{n-2} (z^k + z^(2n-2-k)) s_k) / (1 - z^(2n-2))
        for k in 0..n {
            let w = if k == 0 {
                T::one()
            } else if k == n - 1 {
                z.powi(n - 1)
            } else {
                z.powi(k) + z.powi(period - k)
            };
            let row = &buf[k * lanes..(k + 1) * lanes];
            for (acc, &v) in init.iter_mut().zip(row) {
                *acc = *acc + v * w;
            }
        }
        let denom = T::one() - z.powi(period);
        for acc in init.iter_mut() {
            *acc = *acc / denom;
        }
    }
    buf[..lanes].copy_from_slice(init);
    // Causal: c+[k] = s[k] + z c+[k-1].
    for k in 1..n {
        let (prev, cur) = buf.split_at_mut(k * lanes);
        let prev = &prev[(k - 1) * lanes..];
        for (c, &p) in cur[..lanes].iter_mut().zip(prev) {
            *c = *c + z * p;
        }
    }
    // Anti-causal init: c[n-1] = z/(z²-1) (c+[n-1] + z c+[n-2]).
    let f = z / (z * z - T::one());
    {
        let (head, last) = buf.split_at_mut((n - 1) * lanes);
        let before = &head[(n - 2) * lanes..];
        for (c, &p) in last.iter_mut().zip(before) {
            *c = f * (*c + z * p);
        }
    }
    // Anti-causal: c[k] = z (c[k+1] - c+[k]).
    for k in (0..n - 1).rev() {
        let (cur, next) = buf.split_at_mut((k + 1) * lanes);
        let cur = &mut cur[k * lanes..];
        for (c, &nx) in cur.iter_mut().zip(&next[..lanes]) {
            *c = z * (nx - *c);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::kernel::Kernel;

    /// Reconstructs samples from coefficients with the mirror boundary.
    fn reconstruct(c: &[f64], k: &Kernel) -> Vec<f64> {
        let n = c.len() as isize;
        let mirror = |i: isize| -> usize {
            if n == 1 {
                return 0;
            }
            let p = 2 * n - 2;
            let m = i.rem_euclid(p);
            (if m >= n { p - m } else { m }) as usize
        };
        (0..n)
            .map(|i| {
                (-8..=8)
                    .map(|d| c[mirror(i + d)] * k.phi(-d as f64))
                    .sum::<f64>()
            })
            .collect()
    }

    #[test]
    fn bspline_poles_are_roots_of_sampled_kernel() {
        for n in 2..=7 {
            let k = Kernel::bspline(n);
            for p in Prefilter::bspline(n).poles() {
                let Pole::Real(z) = *p else { panic!() };
                let terms = (-4..=4).map(|i| k.phi(i as f64) * z.powi(i));
                let (b, scale) = terms.fold((0.0, 0.0), |(s, m), t| (s + t, m + t.abs()));
                assert!(b.abs() < 1e-13 * scale, "degree {n} pole {z}: B(z) = {b}");
            }
        }
    }

    #[test]
    fn interpolation_reproduces_samples_on_short_and_long_lines() {
        for n in 2..=7 {
            let k = Kernel::bspline(n);
            let pf = Prefilter::bspline(n);
            for len in [2usize, 3, 4, 5, 17, 100] {
                let s: Vec<f64> = (0..len)
                    .map(|i| ((i * 37 + 11) % 29) as f64 * 9.0)
                    .collect();
                let mut c = s.clone();
                pf.apply_line(&mut c);
                let r = reconstruct(&c, &k);
                for (a, b) in r.iter().zip(&s) {
                    assert!((a - b).abs() < 1e-9, "degree {n} len {len}: {a} vs {b}");
                }
            }
        }
    }

    /// A conjugate pair filtered by partial fractions ([`pair_weight`]) gives
    /// the two sections in cascade to rounding, over the λ where it is used,
    /// and `λ` just above 1/144 or very large falls back to the cascade.
    #[test]
    fn conjugate_pair_by_partial_fractions_matches_the_cascade() {
        let mut used = 0;
        for lambda in [0.0070, 0.008, 0.05, 0.3, 1.0, 7.0, 100.0, 900.0, 1e4] {
            let pf = Prefilter::smoothing_cubic(lambda);
            let [Pole::ConjugatePair(z)] = pf.poles() else {
                panic!("λ {lambda}: {:?}", pf.poles());
            };
            for len in [2usize, 3, 5, 17, 200] {
                let s: Vec<f64> = (0..len).map(|i| ((i * 53 + 7) % 31) as f64 * 8.0).collect();
                let mut got = s.clone();
                pf.apply_line(&mut got);
                let mut c: Vec<Complex64> = s
                    .iter()
                    .map(|&v| Complex64::new(v * pf.gain(), 0.0))
                    .collect();
                let mut init = Vec::new();
                filter_lanes(&mut c, len, 1, *z, &mut init);
                filter_lanes(&mut c, len, 1, z.conj(), &mut init);
                let scale = s.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                for (i, (g, w)) in got.iter().zip(&c).enumerate() {
                    assert!(
                        (g - w.re).abs() <= 1e-13 * scale,
                        "λ {lambda} len {len} i {i}: {g} vs {}",
                        w.re
                    );
                }
            }
            used += usize::from(pair_weight(*z).is_some());
        }
        assert_eq!(
            used, 8,
            "the pairs of λ 0.007..900 use the partial fractions, 1e4 not"
        );
        let near = Prefilter::smoothing_cubic(1.0 / 144.0 * (1.0 + 1e-9));
        let [Pole::ConjugatePair(z)] = near.poles() else {
            panic!("{:?}", near.poles());
        };
        assert_eq!(
            pair_weight(*z),
            None,
            "a nearly real pair takes the cascade"
        );
    }

    #[test]
    fn smoothing_spline_solves_its_normal_equation() {
        // (B3 + λ D²) c = s with D the second difference, mirror boundary.
        let k = Kernel::bspline(3);
        for lambda in [0.001, 1.0 / 144.0, 0.1, 1.0, 10.0] {
            let pf = Prefilter::smoothing_cubic(lambda);
            for len in [2usize, 3, 5, 17, 60] {
                let s: Vec<f64> = (0..len).map(|i| ((i * 53 + 7) % 31) as f64 * 8.0).collect();
                let mut c = s.clone();
                pf.apply_line(&mut c);
                let n = len as isize;
                let m = |i: isize| -> f64 {
                    let p = 2 * n - 2;
                    let r = i.rem_euclid(p);
                    c[(if r >= n { p - r } else { r }) as usize]
                };
                for i in 0..n {
                    let b3: f64 = (-1..=1).map(|d| m(i + d) * k.phi(d as f64)).sum();
                    // (-z + 2 - 1/z)^2 taps: 1, -4, 6, -4, 1
                    let d2 = m(i - 2) - 4.0 * m(i - 1) + 6.0 * m(i) - 4.0 * m(i + 1) + m(i + 2);
                    let lhs = b3 + lambda * d2;
                    assert!(
                        (lhs - s[i as usize]).abs() < 1e-8,
                        "λ {lambda} len {len} i {i}: {lhs} vs {}",
                        s[i as usize]
                    );
                }
            }
        }
    }
}
