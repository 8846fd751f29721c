//! Reconstruction kernels as tables of weight polynomials.
//!
//! Every kernel here is piecewise polynomial with unit-spaced knots, so for a
//! point `x` the `S` (support) non-zero weights are polynomials in the fractional
//! position `t ∈ [0, 1)` inside the current *knot cell*:
//!
//! ```text
//! k0 = floor(x - S/2) + 1,   t = (x - S/2) - floor(x - S/2),
//! f(x) = Σ_{j<S} c[k0 + j] · W_j(t),   W_j(t) = φ(t + S/2 - 1 - j).
//! ```
//!
//! Knots sit at integers for even `S` (linear, Catmull-Rom, odd-degree
//! B-splines) and at half-integers for odd `S` (even-degree B-splines). Storing
//! the `W_j` as coefficient tables makes weights, derivative weights, the
//! restriction of `f` to a ray segment (a polynomial) and the weight bounds of
//! cell classification all come from one source.

/// Largest support of any kernel (B-spline of degree 7).
pub const MAX_SUPPORT: usize = 8;

/// A separable, piecewise-polynomial reconstruction kernel.
#[derive(Clone, Debug, PartialEq)]
pub struct Kernel {
    support: usize,
    /// `poly[j][m]` is the coefficient of `t^m` in `W_j(t)`.
    poly: [[f64; MAX_SUPPORT]; MAX_SUPPORT],
    nonnegative: bool,
}

impl Kernel {
    /// The centred B-spline of degree `n` (support `n + 1`), from its truncated
    /// power form `β^n(x) = 1/n! Σ_k (-1)^k C(n+1,k) (x + (n+1)/2 - k)_+^n`.
    ///
    /// For `t ∈ [0,1)` the argument `t + S/2 - 1 - j + (n+1)/2 - k` is `t + a`
    /// with the integer `a = S - 1 - j - k`, so every term is an integer
    /// polynomial: the table is exact up to the single division by `n!`.
    pub fn bspline(n: usize) -> Kernel {
        assert!(
            (1..MAX_SUPPORT).contains(&n),
            "B-spline degree {n} out of range"
        );
        let s = n + 1;
        let mut poly = [[0.0; MAX_SUPPORT]; MAX_SUPPORT];
        let fact: f64 = (1..=n).map(|v| v as f64).product();
        for (j, row) in poly.iter_mut().enumerate().take(s) {
            for k in 0..s - j {
                let a = (s - 1 - j - k) as f64;
                let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
                let c = sign * binomial(s, k);
                // (t + a)^n = Σ_m C(n,m) a^(n-m) t^m
                for (m, coef) in row.iter_mut().enumerate().take(n + 1) {
                    *coef += c * binomial(n, m) * a.powi((n - m) as i32);
                }
            }
            for coef in row.iter_mut() {
                *coef /= fact;
            }
        }
        Kernel {
            support: s,
            poly,
            nonnegative: true,
        }
    }

    /// Keys' cubic convolution with `a = -0.5` (Catmull-Rom): interpolating, with
    /// negative lobes.
    pub fn catmull_rom() -> Kernel {
        let mut poly = [[0.0; MAX_SUPPORT]; MAX_SUPPORT];
        // Weights of samples i-1, i, i+1, i+2 at x = i + t.
        poly[0][..4].copy_from_slice(&[0.0, -0.5, 1.0, -0.5]);
        poly[1][..4].copy_from_slice(&[1.0, 0.0, -2.5, 1.5]);
        poly[2][..4].copy_from_slice(&[0.0, 0.5, 2.0, -1.5]);
        poly[3][..4].copy_from_slice(&[0.0, 0.0, -0.5, 0.5]);
        Kernel {
            support: 4,
            poly,
            nonnegative: false,
        }
    }

    /// Number of samples that weigh on a point along one axis.
    #[inline]
    pub fn support(&self) -> usize {
        self.support
    }

    /// Degree of each weight polynomial (and of `f` along an axis in a knot cell).
    pub fn degree(&self) -> usize {
        self.support - 1
    }

    /// True when every weight is ≥ 0, which makes coefficient ranges bound `f`.
    pub fn is_nonnegative(&self) -> bool {
        self.nonnegative
    }

    /// Where knot cells start relative to sample positions: 0 (knots at integers)
    /// or 0.5 (knots at half-integers, even-degree B-splines).
    pub fn knot_offset(&self) -> f64 {
        if self.support.is_multiple_of(2) {
            0.0
        } else {
            0.5
        }
    }

    /// Coefficients of `W_j` (lowest power first), `support` entries.
    #[inline]
    pub fn weight_poly(&self, j: usize) -> &[f64] {
        &self.poly[j][..self.support]
    }

    /// First sample index and fractional position for coordinate `x`.
    #[inline]
    pub fn locate(&self, x: f64) -> (isize, f64) {
        let shifted = x - 0.5 * self.support as f64;
        let fl = floor_i64(shifted);
        (fl as isize + 1, shifted - fl as f64)
    }

    /// [`Kernel::locate`] for `L` coordinates at once, with the same bits
    /// for every coordinate below 2⁵³ in magnitude: `f64::floor` where
    /// `locate` truncates and corrects (the correction is only there for the
    /// x86-64 baseline, which has no rounding instruction), so inside a
    /// function compiled for SSE 4.1 or later the lanes round in vector
    /// instructions.
    #[inline(always)]
    pub fn locate_lanes<const L: usize>(&self, x: &[f64; L]) -> ([isize; L], [f64; L]) {
        let half = 0.5 * self.support as f64;
        let (mut first, mut t) = ([0isize; L], [0.0f64; L]);
        for l in 0..L {
            let shifted = x[l] - half;
            let fl = shifted.floor();
            first[l] = fl as isize + 1;
            t[l] = shifted - fl;
        }
        (first, t)
    }

    /// The `S` weights at fractional position `t`.
    #[inline(always)]
    pub fn weights<const S: usize>(&self, t: f64) -> [f64; S] {
        debug_assert_eq!(S, self.support);
        std::array::from_fn(|j| horner(&self.poly[j][..S], t))
    }

    /// The `S` weights and their derivatives (d/dx) at fractional position `t`.
    #[inline(always)]
    pub fn weights_and_derivs<const S: usize>(&self, t: f64) -> ([f64; S], [f64; S]) {
        debug_assert_eq!(S, self.support);
        let mut w = [0.0; S];
        let mut d = [0.0; S];
        for j in 0..S {
            let p = &self.poly[j];
            let (mut v, mut dv) = (p[S - 1], 0.0);
            for m in (0..S - 1).rev() {
                dv = dv * t + v;
                v = v * t + p[m];
            }
            w[j] = v;
            d[j] = dv;
        }
        (w, d)
    }

    /// The kernel itself, `φ(x)`, for any real `x`.
    pub fn phi(&self, x: f64) -> f64 {
        let s = self.support as f64;
        let u = x + 0.5 * s;
        if !(0.0..s).contains(&u) {
            return 0.0;
        }
        let jp = u.floor();
        let t = u - jp;
        let j = self.support - 1 - jp as usize;
        horner(self.weight_poly(j), t)
    }

    /// `max_t Σ_j |W_j(t)|` per axis (1 for non-negative kernels, 1.25 for
    /// Catmull-Rom), slightly rounded up: how far `f` can overshoot the range
    /// of its coefficients. Sampled finely; the sum of absolute weights is
    /// piecewise polynomial, so a margin of 1e-6 covers the sampling.
    pub fn lebesgue_constant(&self) -> f64 {
        if self.nonnegative {
            return 1.0;
        }
        let mut m = 0.0f64;
        for i in 0..=4096 {
            let t = i as f64 / 4096.0;
            let sum: f64 = (0..self.support)
                .map(|j| horner(self.weight_poly(j), t).abs())
                .sum();
            m = m.max(sum);
        }
        m + 1e-6
    }

    /// Exact range `[min, max]` of `W_j(t)` for `t ∈ [t0, t1]`, from the end
    /// points and every interior critical point (roots of `W_j'`, located by
    /// sign changes on a fine grid and bisection). Widened by a few ulps so
    /// bounds built from it stay conservative under rounding.
    pub fn weight_range(&self, j: usize, t0: f64, t1: f64) -> (f64, f64) {
        let p = self.weight_poly(j);
        let dp: Vec<f64> = (1..p.len()).map(|m| p[m] * m as f64).collect();
        let mut lo = horner(p, t0).min(horner(p, t1));
        let mut hi = horner(p, t0).max(horner(p, t1));
        const GRID: usize = 256;
        let mut a = t0;
        let mut fa = horner(&dp, a);
        for i in 1..=GRID {
            let b = t0 + (t1 - t0) * i as f64 / GRID as f64;
            let fb = horner(&dp, b);
            if fa == 0.0 || fa.signum() != fb.signum() {
                let (mut l, mut r, mut fl) = (a, b, fa);
                for _ in 0..60 {
                    let m = 0.5 * (l + r);
                    let fm = horner(&dp, m);
                    if fm == 0.0 {
                        l = m;
                        r = m;
                        break;
                    }
                    if fm.signum() == fl.signum() {
                        l = m;
                        fl = fm;
                    } else {
                        r = m;
                    }
                }
                let v = horner(p, 0.5 * (l + r));
                lo = lo.min(v);
                hi = hi.max(v);
            }
            a = b;
            fa = fb;
        }
        let pad = 1e-14 * (1.0 + lo.abs().max(hi.abs()));
        (lo - pad, hi + pad)
    }
}

/// `floor(x)` as an integer without a libm call (the generic x86-64 target
/// has no rounding instruction, and this sits in every point evaluation and
/// traversal step). Saturates for huge or infinite `x`.
#[inline(always)]
pub fn floor_i64(x: f64) -> i64 {
    let i = x as i64;
    i.saturating_sub(((i as f64) > x) as i64)
}

/// [`floor_i64`] without the saturation checks Rust's `as` adds (a NaN test
/// and two range compares): one truncating conversion, a compare and a
/// saturating subtract, for the traversal's steps and the checkerboard
/// parities. Exact for finite `|x| < 2^63`; NaN and anything larger give
/// `i64::MIN` on x86-64 (its "integer indefinite"; [`floor_i64`]'s
/// saturation elsewhere), never undefined behaviour.
#[inline(always)]
pub fn floor_fast(x: f64) -> i64 {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_cvttsd_si64, _mm_set_sd};
        // SAFETY: SSE2 is part of the x86-64 baseline.
        let i = unsafe { _mm_cvttsd_si64(_mm_set_sd(x)) };
        i.saturating_sub(((i as f64) > x) as i64)
    }
    #[cfg(not(target_arch = "x86_64"))]
    floor_i64(x)
}

/// Evaluates `Σ p[m] t^m`.
#[inline(always)]
pub fn horner(p: &[f64], t: f64) -> f64 {
    let mut v = 0.0;
    for &c in p.iter().rev() {
        v = v * t + c;
    }
    v
}

/// `C(n, k)` as an exact `f64` (all values used here are far below 2^53).
pub fn binomial(n: usize, k: usize) -> f64 {
    if k > n {
        return 0.0;
    }
    let k = k.min(n - k);
    let mut v = 1.0f64;
    for i in 0..k {
        v = v * (n - i) as f64 / (i + 1) as f64;
    }
    v.round()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floors_match_libm_and_stay_defined_out_of_range() {
        for x in [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            2.75,
            -2.75,
            1e15 + 0.5,
            -9.3e15,
            4.2e18,
        ] {
            assert_eq!(floor_i64(x), x.floor() as i64, "{x}");
            assert_eq!(floor_fast(x), x.floor() as i64, "{x}");
        }
        // Saturating, and never an overflow (a debug-build panic before).
        assert_eq!(floor_i64(-1e300), i64::MIN);
        assert_eq!(floor_i64(f64::NEG_INFINITY), i64::MIN);
        assert_eq!(floor_i64(1e300), i64::MAX);
        assert_eq!(floor_i64(f64::NAN), 0);
        if cfg!(target_arch = "x86_64") {
            for x in [
                f64::NAN,
                1e300,
                -1e300,
                f64::INFINITY,
                f64::NEG_INFINITY,
                9.3e18,
            ] {
                assert_eq!(floor_fast(x), i64::MIN, "{x}");
            }
        }
    }

    fn cox_de_boor(n: usize, x: f64) -> f64 {
        // Centred B-spline by the recurrence β^n(x) = ((n+1)/2 + x) β^{n-1}(x+1/2)
        // + ((n+1)/2 - x) β^{n-1}(x-1/2), all over n: an independent construction.
        if n == 0 {
            return if (-0.5..0.5).contains(&x) { 1.0 } else { 0.0 };
        }
        let h = (n as f64 + 1.0) / 2.0;
        ((h + x) * cox_de_boor(n - 1, x + 0.5) + (h - x) * cox_de_boor(n - 1, x - 0.5)) / n as f64
    }

    #[test]
    fn bspline_tables_match_recurrence() {
        for n in 1..=7 {
            let k = Kernel::bspline(n);
            for i in 0..=400 {
                let x = -4.5 + i as f64 * 0.0225 + 1e-9;
                let (a, b) = (k.phi(x), cox_de_boor(n, x));
                assert!((a - b).abs() < 1e-12, "degree {n} at {x}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn weights_partition_unity_and_derivs_sum_zero() {
        let ks: Vec<Kernel> = (1..=7)
            .map(Kernel::bspline)
            .chain([Kernel::catmull_rom()])
            .collect();
        for k in &ks {
            for i in 0..50 {
                let t = i as f64 / 49.0;
                let sum: f64 = (0..k.support()).map(|j| horner(k.weight_poly(j), t)).sum();
                assert!((sum - 1.0).abs() < 1e-13, "support {} t {t}", k.support());
            }
        }
        let k = Kernel::bspline(3);
        let (w, d) = k.weights_and_derivs::<4>(0.3);
        assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-14);
        assert!(d.iter().sum::<f64>().abs() < 1e-14);
        // Derivative of W_3 = t^3/6 is t^2/2.
        assert!((d[3] - 0.045).abs() < 1e-15);
    }

    #[test]
    fn catmull_rom_interpolates() {
        let k = Kernel::catmull_rom();
        assert_eq!(k.phi(0.0), 1.0);
        assert_eq!(k.phi(1.0), 0.0);
        assert_eq!(k.phi(-1.0), 0.0);
        assert!((k.phi(0.5) - 0.5625).abs() < 1e-15);
        assert!((k.phi(1.5) + 0.0625).abs() < 1e-15);
    }

    #[test]
    fn locate_matches_definition() {
        let k3 = Kernel::bspline(3);
        assert_eq!(k3.locate(2.25), (1, 0.25));
        let k2 = Kernel::bspline(2);
        // Odd support: knot cells start at half-integers.
        assert_eq!(k2.locate(2.25), (1, 0.75));
        assert_eq!(k2.locate(2.75), (2, 0.25));
        for x in [0.0, 0.3, 1.7, 5.5, 6.0] {
            for k in [&k2, &k3] {
                let (k0, t) = k.locate(x);
                let w: Vec<f64> = (0..k.support())
                    .map(|j| horner(k.weight_poly(j), t))
                    .collect();
                for (j, wj) in w.iter().enumerate() {
                    let expect = k.phi(x - (k0 + j as isize) as f64);
                    assert!((wj - expect).abs() < 1e-14);
                }
            }
        }
    }

    #[test]
    fn lanes_locate_as_one_at_a_time() {
        // Integers, half-integers and their neighbours either side, where a
        // floor that rounds differently would show.
        let mut xs = vec![0.0, -0.0, 1e-300, 0.3, 1.7, 5.5, 6.0, 63.0, 1e6 + 0.5, -2.5];
        for i in 0..40 {
            let x = i as f64 * 0.5;
            xs.extend([
                x,
                f64::from_bits(x.to_bits() + 1),
                x - f64::EPSILON * x.max(1.0),
            ]);
        }
        for k in [Kernel::bspline(2), Kernel::bspline(3), Kernel::bspline(6)] {
            for c in xs.chunks(8) {
                let mut q = [0.25; 8];
                q[..c.len()].copy_from_slice(c);
                let (first, t) = k.locate_lanes(&q);
                for l in 0..8 {
                    let (f, tl) = k.locate(q[l]);
                    assert_eq!((first[l], t[l].to_bits()), (f, tl.to_bits()), "{}", q[l]);
                }
            }
        }
    }

    #[test]
    fn weight_range_finds_interior_extrema() {
        let k2 = Kernel::bspline(2);
        // Centre weight of the quadratic B-spline peaks at 0.75 mid-cell.
        let (lo, hi) = k2.weight_range(1, 0.0, 1.0);
        assert!((hi - 0.75).abs() < 1e-12 && (lo - 0.5).abs() < 1e-12);
        let cr = Kernel::catmull_rom();
        let (lo, _) = cr.weight_range(0, 0.0, 1.0);
        // -t/2 + t^2 - t^3/2 has its minimum -2/27 at t = 1/3.
        assert!((lo + 2.0 / 27.0).abs() < 1e-12);
    }
}
