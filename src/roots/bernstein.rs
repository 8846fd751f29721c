//! Certified isolation of the sign changes of a polynomial on `[0, 1]`.
//!
//! A polynomial `g(s) = Σ b_i B_i^D(s)` in Bernstein form lies in the convex
//! hull of its coefficients, and the number of its roots in `(0, 1)` is at most
//! the number of sign variations of `b` (and of the same parity). So: no
//! variation proves "no crossing here"; exactly one proves exactly one
//! crossing, which Brent then refines; more than one splits the interval at
//! its midpoint by de Casteljau and recurses, left half first, so crossings
//! come out in ray order. Signs follow [`super::inside`] (`> 0` inside), which
//! makes a tangential touch of the iso-value from below not a crossing.

use super::{brent, inside};

/// Largest degree handled: `3 × 7` for the degree-7 B-spline.
pub const MAX_DEGREE: usize = 21;
const N: usize = MAX_DEGREE + 1;

/// One pending interval of the isolation: `[lo, hi]` and its coefficients.
pub type Interval = (f64, f64, [f64; N]);

/// Work counters for the stats.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct IsolationWork {
    /// Intervals examined (1 when the whole segment is certified at once).
    pub intervals: u32,
    /// Brent iterations (polynomial evaluations) spent refining.
    pub brent_iters: u32,
}

/// A polynomial on `[0, 1]` held both in monomial form (for cheap Horner
/// evaluation during Brent) and in Bernstein form (for certification).
#[derive(Clone, Debug)]
pub struct SegmentPoly {
    degree: usize,
    mono: [f64; N],
    bern: [f64; N],
}

/// Matrix converting monomial to Bernstein coefficients for one degree:
/// `b_i = Σ_{j≤i} C(i,j)/C(D,j) a_j`.
#[derive(Clone, Debug)]
pub struct BernsteinBasis {
    degree: usize,
    m: Vec<f64>,
}

impl BernsteinBasis {
    pub fn new(degree: usize) -> BernsteinBasis {
        assert!(degree <= MAX_DEGREE);
        use crate::filter::kernel::binomial;
        let d = degree;
        let mut m = vec![0.0; (d + 1) * (d + 1)];
        for i in 0..=d {
            for j in 0..=i {
                m[i * (d + 1) + j] = binomial(i, j) / binomial(d, j);
            }
        }
        BernsteinBasis { degree, m }
    }

    pub fn degree(&self) -> usize {
        self.degree
    }

    /// Builds the segment polynomial from monomial coefficients.
    #[inline]
    pub fn segment(&self, mono: &[f64]) -> SegmentPoly {
        let d = self.degree;
        debug_assert_eq!(mono.len(), d + 1);
        let mut p = SegmentPoly {
            degree: d,
            mono: [0.0; N],
            bern: [0.0; N],
        };
        p.mono[..=d].copy_from_slice(mono);
        for i in 0..=d {
            let row = &self.m[i * (d + 1)..i * (d + 1) + i + 1];
            let mut acc = 0.0;
            for (w, a) in row.iter().zip(mono) {
                acc += w * a;
            }
            p.bern[i] = acc;
        }
        p
    }
}

impl BernsteinBasis {
    /// Bernstein coefficients of `L` polynomials at once (`mono[m][lane]`).
    #[inline(always)]
    pub fn bernstein_lanes<const L: usize, M: crate::simd::Madd>(
        &self,
        mono: &[[f64; L]; N],
    ) -> [[f64; L]; N] {
        let mut out = [[0.0f64; L]; N];
        self.bernstein_lanes_into::<L, M>(mono, &mut out);
        out
    }

    /// [`BernsteinBasis::bernstein_lanes`] into `out`, writing its rows
    /// `0..=degree` only: a caller that reuses `out` across groups zeroes
    /// it once, not per group (22 rows of `L` lanes each time, a `memset`
    /// call that was 0.7% of the sphere's frame).
    #[inline(always)]
    pub fn bernstein_lanes_into<const L: usize, M: crate::simd::Madd>(
        &self,
        mono: &[[f64; L]; N],
        out: &mut [[f64; L]; N],
    ) {
        let d = self.degree;
        for i in 0..=d {
            let row = &self.m[i * (d + 1)..i * (d + 1) + i + 1];
            let mut acc = [0.0f64; L];
            for (j, &w) in row.iter().enumerate() {
                for l in 0..L {
                    acc[l] = M::madd(w, mono[j][l], acc[l]);
                }
            }
            out[i] = acc;
        }
    }

    /// Lane `l` of `mono`/`bern` as a [`SegmentPoly`].
    #[inline]
    pub fn lane<const L: usize>(
        &self,
        mono: &[[f64; L]; N],
        bern: &[[f64; L]; N],
        l: usize,
    ) -> SegmentPoly {
        let mut p = SegmentPoly {
            degree: self.degree,
            mono: [0.0; N],
            bern: [0.0; N],
        };
        for i in 0..=self.degree {
            p.mono[i] = mono[i][l];
            p.bern[i] = bern[i][l];
        }
        p
    }
}

/// Every lane's control polygon as bits: bit `k` of lane `l` is set when
/// coefficient `k` (of `0..=d`) is [`inside`]. The tests below read the
/// lane's side changes from one word instead of a branch per coefficient.
#[inline(always)]
pub fn lane_sides<const L: usize>(bern: &[[f64; L]; N], d: usize) -> [u32; L] {
    let mut sides = [0u32; L];
    for (k, row) in bern[..=d].iter().enumerate() {
        for l in 0..L {
            sides[l] |= (inside(row[l]) as u32) << k;
        }
    }
    sides
}

/// Bit `k` set: the control polygon of [`lane_sides`] changes side between
/// coefficients `k` and `k + 1`.
#[inline(always)]
fn side_changes(sides: u32, d: usize) -> u32 {
    (sides ^ (sides >> 1)) & ((1u32 << d) - 1)
}

/// True when a lane with control polygon `sides` ([`lane_sides`], degree
/// `d`) provably stays on the `from_inside` side (see [`SegmentPoly::stays`]).
#[inline(always)]
pub fn lane_stays(sides: u32, d: usize, from_inside: bool) -> bool {
    let all = (1u32 << (d + 1)) - 1;
    sides == if from_inside { all } else { 0 }
}

/// A lane with control polygon `sides` has exactly one sign variation in
/// its Bernstein coefficients (so exactly one crossing in `(0, 1)`),
/// starting on the `from_inside` side: the case [`refine_lanes`] solves.
#[inline(always)]
pub fn lane_single_crossing(sides: u32, d: usize, from_inside: bool) -> bool {
    side_changes(sides, d).count_ones() == 1 && (sides & 1 == 1) == from_inside
}

/// Iterations of [`refine_lanes`] at most; bisection alone would reach
/// machine precision on `[0, 1]` in 53.
const REFINE_ITERS: usize = 64;

/// The crossing of every `active` lane (each with exactly one sign variation,
/// see [`lane_single_crossing`]) by safeguarded Newton on the monomial form,
/// all lanes in step: one Horner pass evaluates `g` and `g'` for every lane,
/// so refining three crossings of a group costs one's latency.
///
/// Each lane starts where its Bernstein control polygon changes sign (close
/// to the root for the smooth restrictions of a cell), keeps the bracket
/// `[lo, hi]` the sign changes in, and takes the Newton step when it stays
/// inside the bracket, else bisects. A lane stops when `g` is exactly zero,
/// when its Newton step falls below 1e-14 (taken without another
/// evaluation, if inside the bracket), when a step no longer moves it, or
/// when a short step (below 1e-9) no longer lowers `|g|`: the root then sits
/// at machine precision. A stopped lane is frozen,
/// so its result depends on its own polynomial alone, never on the others in
/// its group. Returns the roots and the evaluations each lane spent. With
/// AVX-512 the steps run as masks over registers ([`crate::simd::refine_x8`],
/// the same bits): the lane loop's branch per lane divided one lane after
/// another.
#[inline(always)]
pub fn refine_lanes<const L: usize, M: crate::simd::Madd>(
    mono: &[[f64; L]; N],
    bern: &[[f64; L]; N],
    sides: &[u32; L],
    d: usize,
    active: [bool; L],
) -> ([f64; L], [u32; L]) {
    let (x, lo_in) = refine_start(bern, sides, d);
    #[cfg(target_arch = "x86_64")]
    if L == 8 && M::FUSED && crate::simd::Isa::current() == crate::simd::Isa::Avx512 {
        let mut x8 = [0.0; 8];
        x8.copy_from_slice(&x);
        // SAFETY: L == 8, so `[[f64; L]; N]` is `[[f64; 8]; N]`; AVX-512 and
        // FMA checked above; `d <= MAX_DEGREE`.
        let (xs, evals) = unsafe {
            let mono8 = &*(mono as *const [[f64; L]; N]).cast::<[[f64; 8]; N]>();
            crate::simd::refine_x8(
                mono8,
                d,
                x8,
                lane_bits(&lo_in),
                lane_bits(&active),
                REFINE_ITERS,
            )
        };
        return (
            std::array::from_fn(|l| xs[l]),
            std::array::from_fn(|l| evals[l]),
        );
    }
    refine_lanes_scalar::<L, M>(mono, d, x, lo_in, active)
}

/// Bit `l` set for each lane `l` that is `true` (`L ≤ 8`): the lane masks of
/// [`crate::simd::refine_x8`].
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn lane_bits<const L: usize>(b: &[bool; L]) -> u8 {
    (0..L).fold(0u8, |m, l| m | (b[l] as u8) << l)
}

/// Where each lane of [`refine_lanes`] starts, where its control polygon
/// first changes side, and whether it starts inside.
#[inline(always)]
fn refine_start<const L: usize>(
    bern: &[[f64; L]; N],
    sides: &[u32; L],
    d: usize,
) -> ([f64; L], [bool; L]) {
    let mut x = [0.5f64; L];
    let mut lo_in = [false; L];
    for l in 0..L {
        lo_in[l] = sides[l] & 1 == 1;
        let changes = side_changes(sides[l], d);
        if changes != 0 {
            let k = changes.trailing_zeros() as usize;
            let (a, b) = (bern[k][l], bern[k + 1][l]);
            let f = (a / (a - b)).clamp(0.0, 1.0);
            x[l] = (k as f64 + f) / d as f64;
        }
    }
    (x, lo_in)
}

/// The iteration of [`refine_lanes`] lane by lane (any instruction set),
/// from the start points `x`.
#[inline(always)]
fn refine_lanes_scalar<const L: usize, M: crate::simd::Madd>(
    mono: &[[f64; L]; N],
    d: usize,
    mut x: [f64; L],
    lo_in: [bool; L],
    active: [bool; L],
) -> ([f64; L], [u32; L]) {
    let eval = |x: &[f64; L]| {
        let (mut v, mut dv) = ([0.0f64; L], [0.0f64; L]);
        for k in (0..=d).rev() {
            for l in 0..L {
                dv[l] = M::madd(dv[l], x[l], v[l]);
                v[l] = M::madd(v[l], x[l], mono[k][l]);
            }
        }
        (v, dv)
    };
    let (mut lo, mut hi) = ([0.0f64; L], [1.0f64; L]);
    let (mut g, mut dg) = eval(&x);
    let mut done = active.map(|a| !a);
    let mut evals = [1u32; L];
    for _ in 0..REFINE_ITERS {
        let mut next = x;
        for l in 0..L {
            if done[l] {
                continue;
            }
            if g[l] == 0.0 {
                done[l] = true;
                continue;
            }
            if inside(g[l]) == lo_in[l] {
                lo[l] = x[l];
            } else {
                hi[l] = x[l];
            }
            let newton = x[l] - g[l] / dg[l];
            let inside_bracket = newton > lo[l] && newton < hi[l];
            if (newton - x[l]).abs() < 1e-14 {
                // Converged: the step is below the root's rounding (and
                // may fall on the bracket end `x` just became).
                if inside_bracket {
                    x[l] = newton;
                }
                done[l] = true;
                continue;
            }
            next[l] = if inside_bracket {
                newton
            } else {
                0.5 * (lo[l] + hi[l])
            };
            if next[l] == x[l] {
                done[l] = true;
            }
        }
        if done.iter().all(|&d| d) {
            break;
        }
        // Through memory: the loop above chose the lanes' next points one
        // by one, in scalar registers, and the compiler then evaluated the
        // polynomial lane by lane too (16 scalar multiply-adds per Horner
        // step with AVX-512). Read back as an array, the evaluation runs
        // in vector lanes: the same fused operations, so the same bits
        // (single-thread solve stage: sphere 34.4 / 35.2 → 33.4 / 33.1 ms,
        // teapot 110.3 / 112.9 → 107.7 / 105.6 ms).
        let (gn, dn) = eval(std::hint::black_box(&next));
        for l in 0..L {
            if done[l] {
                continue;
            }
            evals[l] += 1;
            let step = (next[l] - x[l]).abs();
            if gn[l].abs() >= g[l].abs() && step < 1e-9 {
                done[l] = true;
                continue;
            }
            (x[l], g[l], dg[l]) = (next[l], gn[l], dn[l]);
        }
    }
    (x, evals)
}

impl SegmentPoly {
    /// `g(s)` by Horner on the monomial form.
    #[inline(always)]
    pub fn eval(&self, s: f64) -> f64 {
        let mut v = 0.0;
        for &c in self.mono[..=self.degree].iter().rev() {
            v = v * s + c;
        }
        v
    }

    /// `g(s)` and `g'(s)` by Horner.
    #[inline(always)]
    pub fn eval_deriv(&self, s: f64) -> (f64, f64) {
        let (mut v, mut d) = (0.0, 0.0);
        for &c in self.mono[..=self.degree].iter().rev() {
            d = d * s + v;
            v = v * s + c;
        }
        (v, d)
    }

    /// Refines a root bracketed in `[lo, hi]` by Newton steps, kept inside
    /// the bracket, until it stops improving: the crossing then sits at
    /// machine precision whatever path Brent took to it, so two ways of
    /// computing the same polynomial agree on the root.
    fn polish(&self, mut x: f64, lo: f64, hi: f64) -> f64 {
        let (mut g, mut d) = self.eval_deriv(x);
        for _ in 0..4 {
            if d == 0.0 || g == 0.0 {
                break;
            }
            let next = (x - g / d).clamp(lo, hi);
            let (gn, dn) = self.eval_deriv(next);
            if gn.abs() >= g.abs() {
                break;
            }
            (x, g, d) = (next, gn, dn);
        }
        x
    }

    /// Bernstein coefficients (for tests and bounds).
    pub fn bernstein(&self) -> &[f64] {
        &self.bern[..=self.degree]
    }

    /// True when the segment provably holds no point on the side opposite to
    /// `from_inside` (so no crossing away from that side can happen on it).
    #[inline]
    pub fn stays(&self, from_inside: bool) -> bool {
        let b = &self.bern[..=self.degree];
        if from_inside {
            b.iter().all(|&v| inside(v))
        } else {
            b.iter().all(|&v| !inside(v))
        }
    }

    /// The first `s ∈ [0, 1]` where the side changes away from `from_inside`
    /// (an exit if inside, an entry if outside), to within `tol` in `s`.
    ///
    /// Changes in the other direction are stepped over: they can only appear
    /// when the segment starts on the wrong side by rounding (just after a
    /// refraction), and passing them puts the ray back on its own side.
    pub fn first_crossing(
        &self,
        from_inside: bool,
        tol: f64,
        work: &mut IsolationWork,
    ) -> Option<f64> {
        self.first_crossing_with(from_inside, tol, work, &mut Vec::new())
    }

    /// [`SegmentPoly::first_crossing`] with a caller-owned stack, so a stage
    /// solving many segments allocates it once.
    pub fn first_crossing_with(
        &self,
        from_inside: bool,
        tol: f64,
        work: &mut IsolationWork,
        stack: &mut Vec<Interval>,
    ) -> Option<f64> {
        let d = self.degree;
        if self.stays(from_inside) {
            // The common case in a cell fringe: certified without subdividing.
            work.intervals += 1;
            return None;
        }
        // Explicit stack of intervals (lo, hi, coefficients), left first; depth
        // first, so it holds at most one pending right half per level.
        stack.clear();
        stack.push((0.0, 1.0, self.bern));
        while let Some((lo, hi, b)) = stack.pop() {
            work.intervals += 1;
            let coeffs = &b[..=d];
            let variations = coeffs
                .windows(2)
                .filter(|w| inside(w[0]) != inside(w[1]))
                .count();
            if variations == 0 {
                continue;
            }
            let start_in = inside(coeffs[0]);
            let end_in = inside(coeffs[d]);
            if variations == 1 || hi - lo <= tol {
                if start_in == end_in {
                    // Even count within tolerance: a tangential touch.
                    continue;
                }
                if start_in != from_inside {
                    // A change back onto our own side: step over it.
                    continue;
                }
                if variations == 1 {
                    let r = brent::solve(|s| self.eval(s), lo, hi, coeffs[0], coeffs[d], tol);
                    work.brent_iters += r.evals;
                    return Some(self.polish(r.x.clamp(lo, hi), lo, hi));
                }
                return Some(0.5 * (lo + hi));
            }
            let (left, right) = split_half(&b, d);
            let mid = 0.5 * (lo + hi);
            stack.push((mid, hi, right));
            stack.push((lo, mid, left));
        }
        None
    }
}

/// de Casteljau subdivision at 1/2.
#[inline]
fn split_half(b: &[f64; N], d: usize) -> ([f64; N], [f64; N]) {
    let mut work = *b;
    let mut left = [0.0; N];
    let mut right = [0.0; N];
    left[0] = work[0];
    right[d] = work[d];
    for r in 1..=d {
        for i in 0..=d - r {
            work[i] = 0.5 * (work[i] + work[i + 1]);
        }
        left[r] = work[0];
        right[d - r] = work[d - r];
    }
    (left, right)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bit tests against their definitions coefficient by coefficient:
    /// side variations counted pairwise, staying as every coefficient on
    /// one side, and the first change of side where the refinement starts;
    /// for every degree, with zeros, negative zeros and NaNs among the
    /// coefficients (none of which is inside).
    #[test]
    fn side_bits_match_the_coefficient_definitions() {
        let values = [1.0, -1.0, 0.0, -0.0, f64::NAN, 2.5e-300, -7.0];
        let mut state = 0x2545_f491_4f6c_dd1du64;
        for case in 0..20_000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let d = 1 + case % MAX_DEGREE;
            let mut bern = [[0.0f64; 1]; N];
            for (k, row) in bern.iter_mut().enumerate().take(d + 1) {
                row[0] = values[(state >> (3 * k % 60)) as usize % values.len()];
            }
            let sides = lane_sides(&bern, d)[0];
            let b: Vec<f64> = bern[..=d].iter().map(|r| r[0]).collect();
            let variations = b
                .windows(2)
                .filter(|w| inside(w[0]) != inside(w[1]))
                .count();
            let first = b.windows(2).position(|w| inside(w[0]) != inside(w[1]));
            for from_inside in [false, true] {
                assert_eq!(
                    lane_single_crossing(sides, d, from_inside),
                    variations == 1 && inside(b[0]) == from_inside,
                    "{b:?}"
                );
                assert_eq!(
                    lane_stays(sides, d, from_inside),
                    b.iter().all(|&v| inside(v) == from_inside),
                    "{b:?}"
                );
            }
            let changes = side_changes(sides, d);
            assert_eq!(
                (changes != 0).then(|| changes.trailing_zeros() as usize),
                first,
                "{b:?}"
            );
        }
    }

    fn poly_from_roots(roots: &[f64], scale: f64, degree: usize) -> Vec<f64> {
        // scale · Π (s - r_i), padded with zero leading coefficients.
        let mut p = vec![scale];
        for &r in roots {
            let mut q = vec![0.0; p.len() + 1];
            for (i, &c) in p.iter().enumerate() {
                q[i] -= r * c;
                q[i + 1] += c;
            }
            p = q;
        }
        p.resize(degree + 1, 0.0);
        p
    }

    #[test]
    fn bernstein_conversion_evaluates_endpoints() {
        let basis = BernsteinBasis::new(9);
        let mono: Vec<f64> = (0..10).map(|i| (i as f64 * 0.7).sin()).collect();
        let p = basis.segment(&mono);
        assert!((p.bernstein()[0] - mono[0]).abs() < 1e-14);
        assert!((p.bernstein()[9] - mono.iter().sum::<f64>()).abs() < 1e-13);
    }

    #[test]
    fn finds_first_of_two_close_crossings() {
        // Grazing: in at 0.500, out at 0.502, within one segment.
        let basis = BernsteinBasis::new(9);
        let mono = poly_from_roots(&[0.5, 0.502], -1.0, 9);
        let p = basis.segment(&mono);
        let mut w = IsolationWork::default();
        let s = p.first_crossing(false, 1e-12, &mut w).unwrap();
        assert!((s - 0.5).abs() < 1e-10, "{s}");
        // Coming from inside, the first exit is the same root's partner... the
        // polynomial is outside at 0, so from_inside=true steps over the entry
        // at 0.5 and reports the exit at 0.502.
        let s = p.first_crossing(true, 1e-12, &mut w).unwrap();
        assert!((s - 0.502).abs() < 1e-10, "{s}");
        // Sampling the ends alone would see no sign change at all:
        assert!(!inside(p.eval(0.0)) && !inside(p.eval(1.0)));
    }

    #[test]
    fn lanes_refine_single_crossings_to_machine_precision_each_on_its_own() {
        // Degree 9: (s - r)·(a + s)·(1 + b s²)·(c - s)⁵, one root r in
        // (0, 1), steep and flat, near either end; every lane against the
        // isolation path's Brent at 1e-14, and against itself among other
        // neighbours (a frozen lane must not move while others iterate).
        let basis = BernsteinBasis::new(9);
        let mut draws = 0u64;
        let mut next = || {
            draws += 1;
            crate::phantom::uniform(0x2545_f491_4f6c_dd1d, draws)
        };
        let mut polys = Vec::new();
        for case in 0..64 {
            let r = if case % 2 == 1 {
                0.001 + 0.998 * next()
            } else {
                [1e-6f64, 0.999_999, 0.5][case / 2 % 3]
            };
            let (a, b, c) = (0.05 + 3.0 * next(), 4.0 * next(), 1.2 + next());
            let scale = [1e-6, 1.0, 300.0][case % 3] * if case % 4 < 2 { 1.0 } else { -1.0 };
            let mut p = vec![-r * scale, scale];
            let lin = vec![c, -1.0];
            for q in [
                vec![a, 1.0],
                vec![1.0, 0.0, b],
                lin.clone(),
                lin.clone(),
                lin.clone(),
                lin.clone(),
                lin,
            ] {
                let mut n = vec![0.0; p.len() + q.len() - 1];
                for (i, &x) in p.iter().enumerate() {
                    for (j, &y) in q.iter().enumerate() {
                        n[i + j] += x * y;
                    }
                }
                p = n;
            }
            assert_eq!(p.len(), 10);
            polys.push((r, p));
        }
        let refine = |lanes: &[&Vec<f64>]| {
            let mut mono = [[0.0f64; 8]; N];
            let mut active = [false; 8];
            for (l, p) in lanes.iter().enumerate() {
                for k in 0..10 {
                    mono[k][l] = p[k];
                }
                active[l] = true;
            }
            let bern = basis.bernstein_lanes::<8, crate::simd::Plain>(&mono);
            let sides = lane_sides(&bern, 9);
            for l in 0..lanes.len() {
                let from_inside = inside(bern[0][l]);
                assert!(lane_single_crossing(sides[l], 9, from_inside), "lane {l}");
                assert!(!lane_stays(sides[l], 9, from_inside), "lane {l}");
            }
            refine_lanes::<8, crate::simd::Plain>(&mono, &bern, &sides, 9, active)
        };
        for batch in polys.chunks(8) {
            let lanes: Vec<&Vec<f64>> = batch.iter().map(|(_, p)| p).collect();
            let (x, evals) = refine(&lanes);
            for (l, (r, p)) in batch.iter().enumerate() {
                let seg = basis.segment(p);
                let want = seg
                    .first_crossing(inside(p[0]), 1e-14, &mut IsolationWork::default())
                    .unwrap();
                assert!((x[l] - want).abs() < 1e-12, "lane {l}: {} vs {want}", x[l]);
                assert!((x[l] - r).abs() < 1e-9, "lane {l}: {} vs root {r}", x[l]);
                assert!(evals[l] <= 12, "lane {l}: {} evaluations", evals[l]);
                // The same polynomial alone in its group: the same bits.
                let (alone, _) = refine(std::slice::from_ref(&p));
                assert_eq!(alone[0].to_bits(), x[l].to_bits(), "lane {l}");
            }
        }
    }

    /// The AVX-512 refinement gives the lane loop's bits: roots and
    /// evaluation counts, over single crossings of every steepness, exact
    /// zeros at the start point, roots a hair from the ends, and lanes left
    /// inactive. (Its stall test, a short step that no longer lowers `|g|`,
    /// is a safeguard none of these reach.)
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn vector_refinement_is_the_lane_loop() {
        use crate::simd::{Fused, Isa};
        if !crate::simd::kernels_run(
            "the AVX-512 refinement",
            Isa::available().contains(&Isa::Avx512),
        ) {
            return;
        }
        let basis = BernsteinBasis::new(9);
        let mut draws = 0u64;
        let mut next = || {
            draws += 1;
            crate::phantom::uniform(0x6a09_e667_f3bc_c909, draws)
        };
        let mut polys: Vec<Vec<f64>> = Vec::new();
        for case in 0..400 {
            let p: Vec<f64> = match case % 4 {
                // One root, a factor steep or flat near it.
                0 | 1 => {
                    let r = next();
                    let roots = [r, 1.0 + 2.0 * next(), -1.0 - next()];
                    let scale = (10.0f64).powf(8.0 * next() - 4.0);
                    let sign = if case % 8 < 4 { 1.0 } else { -1.0 };
                    poly_from_roots(&roots, sign * scale, 9)
                }
                // Exactly zero where the polygon changes side: s - 1/2.
                2 if case % 16 == 2 => poly_from_roots(&[0.5], 1.0, 9),
                // A root a hair from either end, where Newton steps leave
                // the bracket and the lanes bisect.
                2 => {
                    let r = if case % 8 == 2 {
                        1e-7 * next()
                    } else {
                        1.0 - 1e-7 * next()
                    };
                    poly_from_roots(&[r, -0.2 - next(), 1.3 + next()], 1.0 + 9.0 * next(), 9)
                }
                // Any degree-9 polynomial (some not single crossings).
                _ => (0..10).map(|_| 2.0 * next() - 1.0).collect(),
            };
            polys.push(p);
        }
        let mut refined = 0;
        for batch in polys.chunks(8) {
            let mut mono = [[0.0f64; 8]; N];
            for (l, p) in batch.iter().enumerate() {
                for k in 0..10 {
                    mono[k][l] = p[k];
                }
            }
            let bern = basis.bernstein_lanes::<8, Fused>(&mono);
            let sides = lane_sides(&bern, 9);
            // Lane 5 is left inactive even when it could be refined.
            let active: [bool; 8] = std::array::from_fn(|l| {
                l < batch.len() && lane_single_crossing(sides[l], 9, sides[l] & 1 == 1) && l != 5
            });
            let (x0, lo_in) = refine_start(&bern, &sides, 9);
            let want = refine_lanes_scalar::<8, Fused>(&mono, 9, x0, lo_in, active);
            // SAFETY: AVX-512 checked above.
            let got = unsafe {
                crate::simd::refine_x8(
                    &mono,
                    9,
                    x0,
                    lane_bits(&lo_in),
                    lane_bits(&active),
                    REFINE_ITERS,
                )
            };
            for l in 0..8 {
                assert_eq!(
                    got.0[l].to_bits(),
                    want.0[l].to_bits(),
                    "lane {l}: {} vs {}",
                    got.0[l],
                    want.0[l]
                );
                assert_eq!(got.1[l], want.1[l], "lane {l} evaluations");
            }
            refined += active.iter().filter(|&&a| a).count();
        }
        assert!(refined > 150, "{refined} lanes refined");
    }

    #[test]
    fn tangent_touch_is_not_a_crossing() {
        let basis = BernsteinBasis::new(3);
        let mono = poly_from_roots(&[0.4, 0.4], -1.0, 3); // -(s-0.4)^2 <= 0
        let p = basis.segment(&mono);
        let mut w = IsolationWork::default();
        assert_eq!(p.first_crossing(false, 1e-9, &mut w), None);
        // The hull alone cannot certify it (a control point is positive); the
        // subdivision down to the tolerance does, with bounded work.
        assert!(!p.stays(false));
        assert!(w.intervals < 200, "{w:?}");
    }

    #[test]
    fn certifies_empty_segments_in_one_step() {
        let basis = BernsteinBasis::new(9);
        let mono = poly_from_roots(&[1.5, 2.0, -0.5], 1.0, 9);
        let p = basis.segment(&mono);
        let mut w = IsolationWork::default();
        let side = inside(p.eval(0.0));
        assert_eq!(p.first_crossing(side, 1e-9, &mut w), None);
        assert!(w.intervals <= 3, "{w:?}");
    }

    #[test]
    fn many_roots_in_order() {
        let basis = BernsteinBasis::new(21);
        let roots = [0.1, 0.2, 0.35, 0.36, 0.9];
        let mono = poly_from_roots(&roots, 1.0, 21);
        let p = basis.segment(&mono);
        let mut w = IsolationWork::default();
        // g(0) < 0 (odd count of roots, positive scale): outside; first entry 0.1.
        let s = p.first_crossing(false, 1e-12, &mut w).unwrap();
        assert!((s - 0.1).abs() < 1e-9, "{s}");
        let s = p.first_crossing(true, 1e-12, &mut w).unwrap();
        assert!((s - 0.2).abs() < 1e-9, "{s}");
    }
}
