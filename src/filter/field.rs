//! The continuous field `f(x) = Σ_k c_k φ(x-k)` and its analytic gradient.
//!
//! A [`Field`] owns the prefiltered, padded coefficients and the kernel. Point
//! evaluation computes the `S` weights per axis once (and their derivatives for
//! the gradient), then sweeps the `S³` neighbourhood row by row: each row is a
//! contiguous run of `S` coefficients thanks to the apron, so the inner loop is
//! branch-free. The support is a const generic, chosen once per call by
//! `with_support!`, so every loop has a compile-time trip count.

use glam::DVec3;

use crate::volume::Volume;

use super::coeffs::{APRON, Coefficient};
use super::{Coeffs, FilterKind, Kernel};

/// Runs `$body` with `$S` bound to the kernel support as a `const usize`.
#[macro_export]
macro_rules! with_support {
    ($support:expr, $S:ident => $body:expr) => {
        match $support {
            2 => {
                const $S: usize = 2;
                $body
            }
            3 => {
                const $S: usize = 3;
                $body
            }
            4 => {
                const $S: usize = 4;
                $body
            }
            5 => {
                const $S: usize = 5;
                $body
            }
            6 => {
                const $S: usize = 6;
                $body
            }
            7 => {
                const $S: usize = 7;
                $body
            }
            8 => {
                const $S: usize = 8;
                $body
            }
            s => unreachable!("kernel support {s}"),
        }
    };
}

/// What a field built from `vol` keeps its coefficients relative to: the
/// volume's offset, or `0.0` (not `-0.0`) for a volume without one, so the
/// coefficients of such a volume are its samples bit for bit.
pub fn volume_frame(vol: &Volume) -> f64 {
    if vol.offset() == 0.0 {
        0.0
    } else {
        vol.offset()
    }
}

/// A reconstructed volume: coefficients + kernel, evaluable anywhere.
/// `T` is the coefficient storage ([`Coefficient`]); arithmetic is `f64`.
///
/// The coefficients may be stored relative to an [`Field::offset`] and
/// multiplied by a power of two, [`Field::scale`]: the reconstruction is
/// then `offset + Σ w·c / scale`, and every evaluation returns the `Σ w·c`
/// part. The renderer and the classifications compare evaluations only
/// with [`Field::separating_iso`], which maps the scene's iso-value into
/// the same frame, and the surface's normal is the gradient's direction,
/// so a shifted and scaled field renders the same surface. Every storage
/// keeps a volume held relative to an offset ([`Volume::offset`]) relative
/// to it ([`volume_frame`]), so that `f32` and `f16` round the data's
/// variation and not the offset's digits, and the iso-value's nudge above
/// rounding noise ([`Field::separating_iso`]) scales with the data's
/// variation, not with the offset (at 1e-11 of 101325 it would move a
/// surface whose values vary by 1e-6 off the data); `f16` storage is centred on the scene's
/// iso-value this way: near the surface the
/// stored values are then small, where `f16`'s absolute precision is
/// fine, instead of near the iso-value, where its 11 bits round by the
/// data's scale over 2048; and scaled, so that a field of any magnitude
/// lies in `f16`'s normal range, neither in its subnormals (a field of
/// values near 1e-9 would round to zero) nor beyond 65504.
#[derive(Clone, Debug)]
pub struct Field<T: Coefficient = f64> {
    kind: FilterKind,
    kernel: Kernel,
    coeffs: Coeffs<T>,
    /// Largest coefficient magnitude (computed once; see `separating_iso`).
    max_abs: f64,
    /// How many coefficients' magnitudes have each binary exponent (entry
    /// `e` of the 2048: magnitudes in `[2^(e−1023), 2^(e−1022))`, zero and
    /// subnormals in entry 0), for their typical magnitude and the largest
    /// below a bound ([`Field::separating_iso`]); counted on first use,
    /// which only fields with outliers or an iso-value of 0 have.
    exponents: std::sync::OnceLock<Box<[u64; 2048]>>,
    /// What the coefficients are relative to (0 unless shifted).
    offset: f64,
    /// The power of two they are multiplied by (1 unless scaled).
    scale: f64,
}

impl<T: Coefficient> Field<T> {
    /// Prefilters `vol` for `kind` in place in the padded grid of `T`
    /// (parallel over lines, each line in `f64`: with `f32` storage that
    /// rounds once per axis pass) and keeps the coefficients relative to the
    /// volume's offset ([`volume_frame`]), the field's [`Field::offset`] (the
    /// prefilter maps a constant to itself, so the offset passes through it
    /// unchanged).
    pub fn new_in(vol: &Volume, kind: FilterKind) -> Field<T> {
        let frame = volume_frame(vol);
        let mut coeffs = Coeffs::<T>::from_volume(vol, frame);
        let prefilter = kind.prefilter();
        if !prefilter.is_identity() {
            let dims = coeffs.dims();
            let origin = coeffs.interior_offset(0, 0, 0);
            let strides = [coeffs.stride(0), coeffs.stride(1), coeffs.stride(2)];
            prefilter.apply_3d_strided(coeffs.data_mut(), dims, origin, strides);
            coeffs.fill_apron();
        }
        debug_assert!(APRON >= kind.kernel().support() / 2);
        Field::from_coeffs(kind, coeffs).with_frame(frame, 1.0)
    }
}

impl Field<f64> {
    /// [`Field::new_in`] with `f64` coefficients: the renderer adds no error
    /// to the filter's own.
    pub fn new(vol: &Volume, kind: FilterKind) -> Field<f64> {
        Field::new_in(vol, kind)
    }
}

impl Field<f32> {
    /// Like [`Field::new`] but stores `f32` coefficients (half the memory),
    /// relative to the volume's offset as [`Field::new_in`] stores them; the
    /// prefilter runs in `f64` on a full copy and rounds once (the reference
    /// the tests hold [`Field::new_in`] to).
    pub fn new_f32(vol: &Volume, kind: FilterKind) -> Field<f32> {
        let prefilter = kind.prefilter();
        let frame = volume_frame(vol);
        let coeffs = if prefilter.is_identity() {
            Coeffs::from_volume(vol, frame)
        } else {
            let mut work: Vec<f64> = vol.samples().iter().map(|&v| v as f64).collect();
            prefilter.apply_3d(&mut work, vol.dims());
            Coeffs::from_interior(vol.dims(), &work, |v: &f64| *v as f32)
        };
        Field::from_coeffs(kind, coeffs).with_frame(frame, 1.0)
    }
}

impl<T: Coefficient> Field<T> {
    /// Wraps ready-made coefficients (e.g. loaded from a cache).
    pub fn from_coeffs(kind: FilterKind, coeffs: Coeffs<T>) -> Field<T> {
        let max_abs = coeffs
            .data()
            .iter()
            .fold(0.0f64, |m, c| m.max(c.to_f64().abs()));
        Field {
            kind,
            kernel: kind.kernel(),
            coeffs,
            max_abs,
            exponents: std::sync::OnceLock::new(),
            offset: 0.0,
            scale: 1.0,
        }
    }

    /// This field with its coefficients taken as stored relative to
    /// `offset` and multiplied by `scale` (a power of two): the field
    /// `offset + Σ w·c / scale` (see [`Field`]).
    pub fn with_frame(self, offset: f64, scale: f64) -> Field<T> {
        debug_assert!(scale > 0.0 && scale.to_bits() & ((1 << 52) - 1) == 0);
        Field {
            offset,
            scale,
            ..self
        }
    }

    /// What the stored coefficients, and so every evaluation, are relative
    /// to: the reconstructed value is `offset() + value(p) / scale()`.
    pub fn offset(&self) -> f64 {
        self.offset
    }

    /// The power of two the stored coefficients, and so every evaluation,
    /// are multiplied by ([`Field::offset`]).
    pub fn scale(&self) -> f64 {
        self.scale
    }

    pub fn kind(&self) -> FilterKind {
        self.kind
    }
    pub fn kernel(&self) -> &Kernel {
        &self.kernel
    }
    pub fn coeffs(&self) -> &Coeffs<T> {
        &self.coeffs
    }
    pub fn dims(&self) -> [usize; 3] {
        self.coeffs.dims()
    }

    /// Offset in [`Coeffs::data`] of the first of the `S³` coefficients whose
    /// basis functions cover knot cell `cell` (in range; `S` the kernel's
    /// support): its x-rows start at `+ j·stride(1) + k·stride(2)`.
    #[inline(always)]
    pub fn support_offset(&self, cell: [i64; 3]) -> usize {
        let lead = ((self.kernel.support() - 1) / 2) as i64;
        self.coeffs.offset(
            (cell[0] - lead) as isize,
            (cell[1] - lead) as isize,
            (cell[2] - lead) as isize,
        )
    }

    /// Largest coefficient magnitude: the scale of rounding in evaluations.
    pub fn max_abs_coeff(&self) -> f64 {
        self.max_abs
    }

    /// The iso-value nudged just above evaluation rounding noise.
    ///
    /// Weights sum to one only to within rounding, so a plateau at exactly the
    /// iso-value evaluates to `iso ± 1e-13` and would flicker between inside
    /// and outside. Deciding sides against `iso + ε`, with `ε` far above f64
    /// summation noise (≈1e-14 of the coefficient scale) yet far below any
    /// geometric tolerance, makes "equal to the iso-value" reliably outside.
    ///
    /// The scale is the largest coefficient magnitude up to a million times
    /// the iso-value's or the coefficients' typical one (the median of the
    /// nonzero magnitudes), whichever is larger: a sentinel or fill value
    /// far beyond the data (1e20, NetCDF's 9.97e36) would otherwise move the
    /// whole surface by its 1e-11, or off the data altogether, and the
    /// typical magnitude bounds it where the iso-value cannot (an iso-value
    /// of 0, a signed distance's). Magnitudes are counted by binary exponent
    /// ([`Field::from_coeffs`]), so the scale is the bound of the largest
    /// one's power of two, within 2× of it.
    ///
    /// The result is in the frame of the stored coefficients (`iso` less
    /// [`Field::offset`], times [`Field::scale`]): what evaluations are
    /// compared with.
    pub fn separating_iso(&self, iso: f64) -> f64 {
        let magnitude = self.magnitude_up_to(1e6 * iso.abs() * self.scale);
        let iso = (iso - self.offset) * self.scale;
        iso + 1e-11 * iso.abs().max(magnitude).max(f64::MIN_POSITIVE)
    }

    /// The largest coefficient magnitude not above `bound` or a million
    /// times the typical one, whichever is larger, rounded up to its power
    /// of two; the largest of all where none is that small.
    fn magnitude_up_to(&self, bound: f64) -> f64 {
        if self.max_abs <= bound {
            return self.max_abs;
        }
        let exponent = |a: f64| ((a.to_bits() >> 52) & 0x7ff) as usize;
        // The upper bound of exponent `e`'s magnitudes.
        let power = |e: usize| f64::from_bits(((e as u64 + 1).min(0x7fe)) << 52);
        let counts = self.exponents.get_or_init(|| {
            use rayon::prelude::*;
            self.coeffs
                .data()
                .par_chunks(1 << 16)
                .map(|chunk| {
                    let mut counts = Box::new([0u64; 2048]);
                    for c in chunk {
                        counts[exponent(c.to_f64().abs())] += 1;
                    }
                    counts
                })
                .reduce(
                    || Box::new([0; 2048]),
                    |mut a, b| {
                        a.iter_mut().zip(b.iter()).for_each(|(x, y)| *x += y);
                        a
                    },
                )
        });
        let nonzero: u64 = counts[1..].iter().sum();
        let mut below = 0;
        let typical = (1..2048)
            .find(|&e| {
                below += counts[e];
                2 * below >= nonzero
            })
            .map_or(0.0, power);
        let bound = bound.max(1e6 * typical);
        if self.max_abs <= bound {
            return self.max_abs;
        }
        (0..=exponent(bound))
            .rev()
            .find(|&e| counts[e] > 0)
            .map_or(self.max_abs, |e| power(e).min(bound))
    }

    /// Maps a grid coordinate into the domain `[0, n-1]` by the mirror symmetry
    /// of the field, returning the sign the derivative picks up on the way.
    #[inline]
    fn fold(x: f64, n: usize) -> (f64, f64) {
        if n == 1 {
            return (0.0, 1.0);
        }
        let m = (n - 1) as f64;
        if (0.0..=m).contains(&x) {
            return (x, 1.0);
        }
        let p = 2.0 * m;
        let r = x.rem_euclid(p);
        if r <= m { (r, 1.0) } else { (p - r, -1.0) }
    }

    /// `f` at grid coordinate `p` (any point; outside the domain by mirroring).
    pub fn value(&self, p: DVec3) -> f64 {
        let n = self.dims();
        let q = [
            Self::fold(p.x, n[0]).0,
            Self::fold(p.y, n[1]).0,
            Self::fold(p.z, n[2]).0,
        ];
        with_support!(self.kernel.support(), S => self.value_in::<S>(q))
    }

    /// `f` and `∇f` (per grid unit) at grid coordinate `p`.
    pub fn value_grad(&self, p: DVec3) -> (f64, DVec3) {
        let n = self.dims();
        let (fx, sx) = Self::fold(p.x, n[0]);
        let (fy, sy) = Self::fold(p.y, n[1]);
        let (fz, sz) = Self::fold(p.z, n[2]);
        let (v, g) =
            with_support!(self.kernel.support(), S => self.value_grad_in::<S>([fx, fy, fz]));
        (v, DVec3::new(g[0] * sx, g[1] * sy, g[2] * sz))
    }

    /// [`Field::value_grad`] for many points in structure-of-arrays form:
    /// `p = [xs, ys, zs]` (grid coordinates, any point), `out = [values, gx,
    /// gy, gz]`, all the same length.
    ///
    /// Points go through in SIMD lanes ([`crate::simd`]): each lane locates
    /// its point, computes its weights and gathers its own neighbourhood, and
    /// every contraction is the same multiply-add across lanes, so the loads
    /// of several points are in flight at once. The result agrees with
    /// [`Field::value_grad`] to rounding.
    pub fn value_grad_batch(&self, p: [&[f64]; 3], out: [&mut [f64]; 4]) {
        let n = p[0].len();
        assert!(p.iter().all(|a| a.len() == n) && out.iter().all(|a| a.len() == n));
        let dims = self.dims();
        let isa = crate::simd::Isa::current();
        let [ov, ox, oy, oz] = out;
        #[cfg(target_arch = "x86_64")]
        if self.kernel.support() == 4
            && isa != crate::simd::Isa::Portable
            && let Some(data) = T::as_f64_slice(self.coeffs.data())
        {
            // SAFETY: the instruction set was checked above.
            unsafe { self.cubic_batch(data, p, [ov, ox, oy, oz]) };
            return;
        }
        crate::with_isa!(isa, L, M => with_support!(self.kernel.support(), S => {
            let mut start = 0;
            while start < n {
                let len = (n - start).min(L);
                // Short groups repeat their last point; extra lanes are dropped.
                let mut q = [[0.0f64; L]; 3];
                let mut sign = [[1.0f64; L]; 3];
                for l in 0..L {
                    let i = start + l.min(len - 1);
                    for a in 0..3 {
                        let (x, s) = Self::fold(p[a][i], dims[a]);
                        q[a][l] = x;
                        sign[a][l] = s;
                    }
                }
                let (v, g) = self.value_grad_lanes::<S, L, M>(&q);
                for l in 0..len {
                    let i = start + l;
                    ov[i] = v[l];
                    ox[i] = g[0][l] * sign[0][l];
                    oy[i] = g[1][l] * sign[1][l];
                    oz[i] = g[2][l] * sign[2][l];
                }
                start += len;
            }
        }));
    }

    /// [`Field::value_grad_in`], through the AVX2/FMA cubic kernel where the
    /// support is 4 and the CPU has them (any storage): what a stage that
    /// needs one gradient at a time calls.
    #[inline(always)]
    pub fn value_grad_fast<const S: usize>(&self, p: [f64; 3]) -> (f64, [f64; 3]) {
        if S == 4 {
            #[cfg(target_arch = "x86_64")]
            if crate::simd::Isa::current() != crate::simd::Isa::Portable {
                // SAFETY: support 4 and AVX2/FMA/F16C (every non-portable
                // level, `Isa::detect`) checked above.
                return unsafe { self.cubic_value_grad_in(p) };
            }
            return self.cubic_value_grad_portable(p);
        }
        self.value_grad_in::<S>(p)
    }

    /// A cubic kernel's neighbourhood of `p` (rows and their strides) and
    /// its weights and derivative weights per axis: what both cubic kernels
    /// contract.
    #[inline(always)]
    #[allow(clippy::type_complexity)]
    fn cubic_support(&self, p: [f64; 3]) -> (&[T], usize, usize, [[f64; 4]; 3], [[f64; 4]; 3]) {
        let mut w = [[0.0; 4]; 3];
        let mut d = [[0.0; 4]; 3];
        let mut k = [0isize; 3];
        for a in 0..3 {
            let (ka, t) = self.kernel.locate(p[a]);
            k[a] = ka;
            (w[a], d[a]) = self.kernel.weights_and_derivs::<4>(t);
        }
        let (nb, sy, sz) = self.neighbourhood::<4>(self.coeffs.offset(k[0], k[1], k[2]));
        (nb, sy, sz, w, d)
    }

    /// [`Field::cubic_value_grad_in`] without vector instructions, bitwise its
    /// result ([`crate::simd::cubic_value_grad_scalar`]): the instruction
    /// set does not change a cubic filter's normals.
    #[inline(always)]
    fn cubic_value_grad_portable(&self, p: [f64; 3]) -> (f64, [f64; 3]) {
        let (nb, sy, sz, w, d) = self.cubic_support(p);
        crate::simd::cubic_value_grad_scalar(nb, sy, sz, &w, &d)
    }

    /// [`Field::value_grad_batch`] for cubic kernels over `f64` coefficients
    /// `data`, with AVX2 and FMA: four points at a time locate themselves and
    /// compute their weights in vector lanes, then each point's neighbourhood
    /// is contracted row by row ([`crate::simd::cubic_value_grad`]).
    ///
    /// # Safety
    /// The support must be 4 and the CPU must have AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn cubic_batch(&self, data: &[f64], p: [&[f64]; 3], out: [&mut [f64]; 4]) {
        use crate::simd::{Fused, Madd};
        const L: usize = 4;
        let n = p[0].len();
        let dims = self.dims();
        let (sy, sz) = (self.coeffs.stride(1), self.coeffs.stride(2));
        let span = 3 * (sy + sz) + 4;
        let [ov, ox, oy, oz] = out;
        let mut start = 0;
        while start < n {
            let len = (n - start).min(L);
            let mut sign = [[1.0f64; L]; 3];
            let mut cell = [[0isize; L]; 3];
            let mut t = [[0.0f64; L]; 3];
            for l in 0..L {
                let i = start + l.min(len - 1);
                for a in 0..3 {
                    let (x, s) = Self::fold(p[a][i], dims[a]);
                    sign[a][l] = s;
                    (cell[a][l], t[a][l]) = self.kernel.locate(x);
                }
            }
            // w[a][j][l], d[a][j][l]: Horner across the lanes.
            let mut w = [[[0.0f64; L]; 4]; 3];
            let mut d = [[[0.0f64; L]; 4]; 3];
            for a in 0..3 {
                for j in 0..4 {
                    let poly = self.kernel.weight_poly(j);
                    let mut v = [poly[3]; L];
                    let mut dv = [0.0f64; L];
                    for m in (0..3).rev() {
                        for l in 0..L {
                            dv[l] = Fused::madd(dv[l], t[a][l], v[l]);
                            v[l] = Fused::madd(v[l], t[a][l], poly[m]);
                        }
                    }
                    w[a][j] = v;
                    d[a][j] = dv;
                }
            }
            for l in 0..len {
                let base = self.coeffs.offset(cell[0][l], cell[1][l], cell[2][l]);
                let nb = &data[base..base + span];
                let wl: [[f64; 4]; 3] =
                    std::array::from_fn(|a| std::array::from_fn(|j| w[a][j][l]));
                let dl: [[f64; 4]; 3] =
                    std::array::from_fn(|a| std::array::from_fn(|j| d[a][j][l]));
                // SAFETY: `nb` holds the whole neighbourhood; AVX2/FMA per caller.
                let (v, g) = unsafe { crate::simd::cubic_value_grad(nb, sy, sz, &wl, &dl) };
                let i = start + l;
                ov[i] = v;
                ox[i] = g[0] * sign[0][l];
                oy[i] = g[1] * sign[1][l];
                oz[i] = g[2] * sign[2][l];
            }
            start += len;
        }
    }

    /// [`Field::value_grad_in`] for cubic kernels (support 4) with AVX2 and
    /// FMA: one vector per neighbourhood row ([`crate::simd::cubic_value_grad`]),
    /// `f32` and `f16` rows widened as they load.
    ///
    /// # Safety
    /// The support must be 4 and the CPU must have AVX2, FMA and F16C.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,f16c")]
    #[inline]
    pub unsafe fn cubic_value_grad_in(&self, p: [f64; 3]) -> (f64, [f64; 3]) {
        let (nb, sy, sz, w, d) = self.cubic_support(p);
        // SAFETY: a `neighbourhood` holds every row; AVX2/FMA/F16C per caller.
        unsafe { crate::simd::cubic_value_grad(nb, sy, sz, &w, &d) }
    }

    /// [`Field::value_grad_fast`] at `L` in-domain points `q[a][l]`, bitwise
    /// its result point by point. For cubic kernels (any storage)
    /// under AVX-512 (`L == 8`) the points are located
    /// ([`Kernel::locate_lanes`]), weighted and contracted in vector lanes
    /// together by
    /// [`crate::simd::cubic_value_grad_x8`]: one point at a time, the
    /// weights and the final horizontal sums were a chain of scalar work per
    /// crossing (single-thread sphere refract stage 32 → 30 ms). `f32` and
    /// `f16` rows are widened as they load, as in the scalar kernel.
    ///
    /// The quadratic B-spline (support 3) under AVX-512 takes
    /// [`crate::simd::quadratic_value_grad_x8`] the same way (its single
    /// points' [`Field::value_grad_in`] bitwise; single-thread sphere refract
    /// stage 25.6 → 18.3 ms). Every other filter or vector width takes
    /// [`Field::value_grad_fast`] lane by lane.
    ///
    /// # Safety
    /// `L` must be bound by [`crate::with_isa!`] for the running instruction
    /// set (8 lanes only under AVX-512).
    #[inline(always)]
    pub unsafe fn value_grad_fast_lanes<const S: usize, const L: usize>(
        &self,
        q: &[[f64; L]; 3],
    ) -> ([f64; L], [[f64; L]; 3]) {
        #[cfg(target_arch = "x86_64")]
        if (S == 3 || S == 4) && L == 8 {
            let data = self.coeffs.data();
            let mut t = [[0.0f64; 8]; 3];
            let mut cell = [[0isize; 8]; 3];
            for a in 0..3 {
                let qa: [f64; 8] = std::array::from_fn(|l| q[a][l]);
                (cell[a], t[a]) = self.kernel.locate_lanes(&qa);
            }
            let (sy, sz) = (self.coeffs.stride(1), self.coeffs.stride(2));
            let base: [usize; 8] =
                std::array::from_fn(|l| self.coeffs.offset(cell[0][l], cell[1][l], cell[2][l]));
            // Rows of `S` from each base; the quadratic kernel reads each
            // row of three as a row of four.
            let span = (S - 1) * (sy + sz) + 4;
            let inside = base.iter().all(|&b| b + span <= data.len());
            let found = if S == 4 {
                assert!(inside, "neighbourhood inside the grid");
                let poly: [[f64; 4]; 4] =
                    std::array::from_fn(|j| std::array::from_fn(|m| self.kernel.weight_poly(j)[m]));
                // SAFETY: every row lies in `base + span <= data.len()`
                // (asserted); L == 8 only under AVX-512 (caller).
                Some(unsafe { crate::simd::cubic_value_grad_x8(data, &base, (sy, sz), &t, &poly) })
            } else if inside {
                let poly: [[f64; 3]; 3] =
                    std::array::from_fn(|j| std::array::from_fn(|m| self.kernel.weight_poly(j)[m]));
                // SAFETY: every row and the value after it lie in `data`
                // (checked); L == 8 only under AVX-512 (caller).
                Some(unsafe {
                    crate::simd::quadratic_value_grad_x8(data, &base, (sy, sz), &t, &poly)
                })
            } else {
                None
            };
            if let Some((v, g)) = found {
                return (
                    std::array::from_fn(|l| v[l]),
                    std::array::from_fn(|a| std::array::from_fn(|l| g[a][l])),
                );
            }
        }
        let mut val = [0.0; L];
        let mut grad = [[0.0; L]; 3];
        for l in 0..L {
            let (v, g) = self.value_grad_fast::<S>([q[0][l], q[1][l], q[2][l]]);
            val[l] = v;
            for a in 0..3 {
                grad[a][l] = g[a];
            }
        }
        (val, grad)
    }

    /// Value and gradient at `L` in-domain points at once (lane layout).
    #[inline(always)]
    fn value_grad_lanes<const S: usize, const L: usize, M: crate::simd::Madd>(
        &self,
        q: &[[f64; L]; 3],
    ) -> ([f64; L], [[f64; L]; 3]) {
        // Per axis: weights and derivative weights, lane-wise.
        let mut w = [[[0.0f64; L]; S]; 3];
        let mut d = [[[0.0f64; L]; S]; 3];
        let mut cell = [[0isize; L]; 3];
        for a in 0..3 {
            let mut t = [0.0f64; L];
            for l in 0..L {
                let (k, tl) = self.kernel.locate(q[a][l]);
                cell[a][l] = k;
                t[l] = tl;
            }
            for j in 0..S {
                let poly = self.kernel.weight_poly(j);
                let mut v = [poly[S - 1]; L];
                let mut dv = [0.0f64; L];
                for m in (0..S - 1).rev() {
                    for l in 0..L {
                        dv[l] = M::madd(dv[l], t[l], v[l]);
                        v[l] = M::madd(v[l], t[l], poly[m]);
                    }
                }
                w[a][j] = v;
                d[a][j] = dv;
            }
        }
        let (sy, sz) = (self.coeffs.stride(1), self.coeffs.stride(2));
        let data = self.coeffs.data();
        let span = (S - 1) * (sy + sz) + S;
        let base: [usize; L] = std::array::from_fn(|l| {
            let b = self.coeffs.offset(cell[0][l], cell[1][l], cell[2][l]);
            assert!(b + span <= data.len(), "neighbourhood inside the grid");
            b
        });
        let (mut val, mut gx, mut gy, mut gz) =
            ([0.0f64; L], [0.0f64; L], [0.0f64; L], [0.0f64; L]);
        for k in 0..S {
            let (mut pv, mut px, mut py) = ([0.0f64; L], [0.0f64; L], [0.0f64; L]);
            for j in 0..S {
                let row = j * sy + k * sz;
                let (mut rv, mut rd) = ([0.0f64; L], [0.0f64; L]);
                for i in 0..S {
                    // SAFETY: row + i < span and base + span <= data.len().
                    let c: [f64; L] = std::array::from_fn(|l| {
                        unsafe { data.get_unchecked(base[l] + row + i) }.to_f64()
                    });
                    for l in 0..L {
                        rv[l] = M::madd(w[0][i][l], c[l], rv[l]);
                        rd[l] = M::madd(d[0][i][l], c[l], rd[l]);
                    }
                }
                for l in 0..L {
                    pv[l] = M::madd(w[1][j][l], rv[l], pv[l]);
                    px[l] = M::madd(w[1][j][l], rd[l], px[l]);
                    py[l] = M::madd(d[1][j][l], rv[l], py[l]);
                }
            }
            for l in 0..L {
                val[l] = M::madd(w[2][k][l], pv[l], val[l]);
                gx[l] = M::madd(w[2][k][l], px[l], gx[l]);
                gy[l] = M::madd(w[2][k][l], py[l], gy[l]);
                gz[l] = M::madd(d[2][k][l], pv[l], gz[l]);
            }
        }
        (val, [gx, gy, gz])
    }

    /// The `S³` neighbourhood starting at `base`, checked once: every row
    /// `base + j·sy + k·sz .. +S` (j, k < S) lies inside the returned slice.
    #[inline(always)]
    fn neighbourhood<const S: usize>(&self, base: usize) -> (&[T], usize, usize) {
        let (sy, sz) = (self.coeffs.stride(1), self.coeffs.stride(2));
        let end = base + (S - 1) * (sy + sz) + S;
        (&self.coeffs.data()[base..end], sy, sz)
    }

    /// Value at a point known to be inside the domain. Hot path of ray casting.
    ///
    /// Reduced x, then y, then z, with independent dot products at each step:
    /// a single running sum would chain all `S³` additions back to back and
    /// leave the core waiting on add latency.
    #[inline(always)]
    pub fn value_in<const S: usize>(&self, p: [f64; 3]) -> f64 {
        let (kx, tx) = self.kernel.locate(p[0]);
        let (ky, ty) = self.kernel.locate(p[1]);
        let (kz, tz) = self.kernel.locate(p[2]);
        let wx = self.kernel.weights::<S>(tx);
        let wy = self.kernel.weights::<S>(ty);
        let wz = self.kernel.weights::<S>(tz);
        let (nb, sy, sz) = self.neighbourhood::<S>(self.coeffs.offset(kx, ky, kz));
        let mut planes = [0.0; S];
        for (k, plane) in planes.iter_mut().enumerate() {
            let mut rows = [0.0; S];
            for (j, r) in rows.iter_mut().enumerate() {
                *r = dot_row::<S, T>(&wx, nb, j * sy + k * sz);
            }
            *plane = dot(&wy, &rows);
        }
        dot(&wz, &planes)
    }

    /// Value and gradient at a point known to be inside the domain.
    ///
    /// Row-vector form: with `c_jk` the neighbourhood row along x, the value
    /// and x-derivative are `wx·R` and `dx·R` for `R = Σ_jk wy_j wz_k c_jk`,
    /// and the y and z derivatives `wx·Σ dy_j wz_k c_jk`, `wx·Σ wy_j dz_k
    /// c_jk`: three vector multiply-adds per row (the loops over `i` are the
    /// vector lanes), four dot products at the end.
    #[inline(always)]
    pub fn value_grad_in<const S: usize>(&self, p: [f64; 3]) -> (f64, [f64; 3]) {
        let (kx, tx) = self.kernel.locate(p[0]);
        let (ky, ty) = self.kernel.locate(p[1]);
        let (kz, tz) = self.kernel.locate(p[2]);
        let (wx, dx) = self.kernel.weights_and_derivs::<S>(tx);
        let (wy, dy) = self.kernel.weights_and_derivs::<S>(ty);
        let (wz, dz) = self.kernel.weights_and_derivs::<S>(tz);
        let (nb, sy, sz) = self.neighbourhood::<S>(self.coeffs.offset(kx, ky, kz));
        let (mut rv, mut ry, mut rz) = ([0.0; S], [0.0; S], [0.0; S]);
        for k in 0..S {
            for j in 0..S {
                let row = j * sy + k * sz;
                debug_assert!(row + S <= nb.len());
                // SAFETY: rows of a `neighbourhood` hold `row .. row + S`.
                let c: [f64; S] =
                    std::array::from_fn(|i| unsafe { nb.get_unchecked(row + i) }.to_f64());
                let (a, b, e) = (wy[j] * wz[k], dy[j] * wz[k], wy[j] * dz[k]);
                for i in 0..S {
                    rv[i] += a * c[i];
                    ry[i] += b * c[i];
                    rz[i] += e * c[i];
                }
            }
        }
        (dot(&wx, &rv), [dot(&dx, &rv), dot(&wx, &ry), dot(&wx, &rz)])
    }
}

/// `Σ a_i b_i` with two interleaved partial sums (half the add latency chain).
#[inline(always)]
fn dot<const S: usize>(a: &[f64; S], b: &[f64; S]) -> f64 {
    let (mut e, mut o) = (0.0, 0.0);
    let mut i = 0;
    while i + 1 < S {
        e += a[i] * b[i];
        o += a[i + 1] * b[i + 1];
        i += 2;
    }
    if i < S {
        e += a[i] * b[i];
    }
    e + o
}

/// `Σ_i w_i · nb[row + i]` over one row of the neighbourhood.
#[inline(always)]
fn dot_row<const S: usize, T: Coefficient>(w: &[f64; S], nb: &[T], row: usize) -> f64 {
    debug_assert!(row + S <= nb.len());
    // SAFETY: callers pass rows of a `neighbourhood`, whose slice holds
    // `row .. row + S` for every row of the S³ block.
    let c: [f64; S] = std::array::from_fn(|i| unsafe { nb.get_unchecked(row + i) }.to_f64());
    dot(w, &c)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::SampleType;

    fn ramp(dims: [usize; 3]) -> Volume {
        let mut s = Vec::new();
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    s.push((2 * x + 3 * y + 5 * z) as f32);
                }
            }
        }
        Volume::new(dims, [1.0; 3], SampleType::F32, s).unwrap()
    }

    /// The nudge scales with the data near the iso-value's magnitude, not
    /// with a fill value a million times beyond it; an iso-value of 0 keeps
    /// the largest coefficient's scale.
    #[test]
    fn separating_iso_ignores_outliers() {
        let mut vol = ramp([6, 5, 4]);
        let data: Vec<f32> = vol.samples().to_vec();
        let plain = Field::new(&vol, FilterKind::Linear);
        let eps = |f: &Field, iso: f64| f.separating_iso(iso) - iso;
        let near = |a: f64, b: f64| (a - b).abs() <= 1e-4 * b;
        assert!(near(eps(&plain, 10.0), 1e-11 * plain.max_abs_coeff()));
        let mut filled = data.clone();
        filled[7] = 9.96921e36;
        vol = Volume::new([6, 5, 4], [1.0; 3], SampleType::F32, filled).unwrap();
        let f = Field::new(&vol, FilterKind::Linear);
        // The ramp's largest value rounded up to its power of two (64).
        assert!(near(eps(&f, 10.0), 1e-11 * 64.0));
        assert!(eps(&f, 10.0) >= eps(&plain, 10.0));
        // At 0 the typical magnitude bounds the scale in the iso-value's
        // place (a signed distance with a fill value lost its surface).
        assert!(near(eps(&f, 0.0), 1e-11 * 64.0));
        // Everything beyond the bound: the largest of all, as before.
        let big = Volume::new([2; 3], [1.0; 3], SampleType::F32, vec![1e30; 8]).unwrap();
        let f = Field::new(&big, FilterKind::Linear);
        assert!(near(eps(&f, 1.0), 1e-11 * 1e30f32 as f64));
    }

    /// A volume held relative to an offset keeps it in every storage: narrow
    /// coefficients round the data's own variation, as those of the same
    /// values unshifted do, not the constant's digits (f32's step at 101325
    /// is 0.0078), and the iso-value's nudge is as small beside the data's
    /// variation as unshifted (1e-11 of 101325, 1e-6, would move a surface
    /// whose values vary by 1e-6 off the data).
    #[test]
    fn storage_keeps_the_volume_offset() {
        let dims = [12, 11, 10];
        let base = crate::volume::scrambled_u8(dims, 5);
        let values = |shift: f64| -> Vec<f64> {
            base.samples()
                .iter()
                .map(|&v| shift + v as f64 / 7.0)
                .collect()
        };
        let vol =
            |shift| Volume::from_f64(dims, [1.0; 3], SampleType::F64, &values(shift)).unwrap();
        let (plain, shifted) = (vol(0.0), vol(101325.0));
        assert!(shifted.offset() != 0.0, "f32 rounds these values");
        let points: Vec<DVec3> = (0..200)
            .map(|i| {
                let t = i as f64;
                DVec3::new(
                    (t * 0.377).rem_euclid(11.0),
                    (t * 0.613).rem_euclid(10.0),
                    (t * 0.291).rem_euclid(9.0),
                )
            })
            .collect();
        // The worst error of `vol`'s narrow fields at the points, against
        // its f64 field.
        let worst = |vol: &Volume, kind: FilterKind| -> [f64; 2] {
            let exact = Field::new(vol, kind);
            assert_eq!(exact.offset(), volume_frame(vol));
            let narrow = [Field::<f32>::new_in(vol, kind), Field::new_f32(vol, kind)];
            narrow.map(|f| {
                assert_eq!(f.offset(), volume_frame(vol));
                points
                    .iter()
                    .map(|&p| (f.value(p) - exact.value(p)).abs())
                    .fold(0.0f64, f64::max)
            })
        };
        for name in ["linear", "bspline3", "bspline7"] {
            let kind = FilterKind::parse(name, 0.0).unwrap();
            let (a, b) = (worst(&plain, kind), worst(&shifted, kind));
            for k in 0..2 {
                // (beyond f64's own rounding of sums near 101325)
                assert!(b[k] <= 2.0 * a[k] + 1e-9, "{name} {k}: {b:?} against {a:?}");
            }
            // The iso-value maps into the coefficients' frame, nudged by
            // 1e-11 of the data's scale (about 36), as unshifted.
            let iso = 101330.0;
            let f = Field::new_f32(&shifted, kind);
            assert!((f.separating_iso(iso) - (iso - shifted.offset())).abs() < 1e-6);
            let f = Field::new(&shifted, kind);
            let nudge = f.separating_iso(iso) - (iso - shifted.offset());
            let unshifted =
                Field::new(&plain, kind).separating_iso(iso - 101325.0) - (iso - 101325.0);
            assert!(
                nudge > 0.0 && nudge <= 2.0 * unshifted,
                "{name}: {nudge:e} against {unshifted:e}"
            );
        }
    }

    #[test]
    fn f32_storage_prefiltered_in_place_is_within_rounding() {
        // In place, each axis pass rounds to f32; from a full f64 copy, only
        // the end does. Both stay within a few f32 ulps of the f64 field.
        let vol = crate::volume::scrambled_u8([19, 14, 11], 3);
        for name in ["linear", "bspline3", "bspline7", "smooth-bspline3"] {
            let kind = FilterKind::parse(name, 1.0).unwrap();
            let exact = Field::new(&vol, kind).coeffs().interior();
            let scale = exact.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let worst = |c: Vec<f32>| {
                c.iter()
                    .zip(&exact)
                    .map(|(a, b)| (*a as f64 - b).abs() / scale)
                    .fold(0.0f64, f64::max)
            };
            let in_place = worst(Field::<f32>::new_in(&vol, kind).coeffs().interior());
            let rounded_once = worst(Field::new_f32(&vol, kind).coeffs().interior());
            let ulp = f32::EPSILON as f64;
            assert!(rounded_once <= 0.5 * ulp, "{name}: {rounded_once:e}");
            assert!(in_place <= 4.0 * ulp, "{name}: {in_place:e}");
            if name != "linear" {
                assert!(in_place > 0.0, "{name}: f32 storage rounds");
            }
        }
    }

    #[test]
    fn batch_evaluation_matches_single_points() {
        let dims = [9usize, 7, 8];
        let vol = crate::volume::scrambled_u8(dims, 3);
        // 37 points: full lane groups and a short tail, inside and outside.
        let pts: Vec<[f64; 3]> = (0..37)
            .map(|k| {
                let t = k as f64;
                [
                    (t * 0.731) % 11.0 - 1.0,
                    (t * 0.377) % 8.0,
                    (t * 1.913) % 10.0 - 0.5,
                ]
            })
            .collect();
        let xs: Vec<f64> = pts.iter().map(|p| p[0]).collect();
        let ys: Vec<f64> = pts.iter().map(|p| p[1]).collect();
        let zs: Vec<f64> = pts.iter().map(|p| p[2]).collect();
        for name in ["linear", "catmull-rom", "bspline2", "bspline3", "bspline7"] {
            let f = Field::new(&vol, FilterKind::parse(name, 0.0).unwrap());
            let (mut v, mut gx, mut gy, mut gz) =
                (vec![0.0; 37], vec![0.0; 37], vec![0.0; 37], vec![0.0; 37]);
            f.value_grad_batch([&xs, &ys, &zs], [&mut v, &mut gx, &mut gy, &mut gz]);
            for (k, p) in pts.iter().enumerate() {
                let (ev, eg) = f.value_grad(DVec3::from_array(*p));
                let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * (1.0 + b.abs());
                assert!(close(v[k], ev), "{name} {p:?}: {} vs {ev}", v[k]);
                assert!(
                    close(gx[k], eg.x) && close(gy[k], eg.y) && close(gz[k], eg.z),
                    "{name} {p:?}"
                );
            }
        }
    }

    /// The refraction stage's lane gradients are the one-point ones bit for
    /// bit, whatever the filter, storage and vector width (every width the
    /// CPU runs; under AVX-512 cubic filters take the lane kernel, over
    /// every storage), at points all over the domain, its faces and corners
    /// included.
    #[test]
    fn lane_gradients_are_the_single_point_ones_bitwise() {
        let dims = [11usize, 9, 10];
        let vol = crate::volume::scrambled_u8(dims, 7);
        let hi = dims.map(|n| (n - 1) as f64);
        let points: Vec<[f64; 3]> = (0..203u64)
            .map(|k| {
                let r = |j: u64| crate::phantom::uniform(crate::phantom::mix64(k), j);
                std::array::from_fn(|a| match (k + a as u64) % 7 {
                    0 => 0.0,
                    1 => hi[a],
                    _ => r(a as u64) * hi[a],
                })
            })
            .collect();
        for name in ["linear", "catmull-rom", "bspline2", "bspline3", "bspline5"] {
            let kind = FilterKind::parse(name, 0.0).unwrap();
            let f64_field = Field::new(&vol, kind);
            let f32_field = Field::<f32>::new_in(&vol, kind);
            let f16_field = Field::<half::f16>::new_in(&vol, kind);
            let bits = |(v, g): (f64, [f64; 3])| (v.to_bits(), g.map(f64::to_bits));
            for isa in crate::simd::Isa::available() {
                crate::with_support!(f64_field.kernel().support(), S => {
                    let lanes = (
                        lanes_of::<S, _>(isa, &f64_field, &points),
                        lanes_of::<S, _>(isa, &f32_field, &points),
                        lanes_of::<S, _>(isa, &f16_field, &points),
                    );
                    for (k, p) in points.iter().enumerate() {
                        let want = (
                            f64_field.value_grad_fast::<S>(*p),
                            f32_field.value_grad_fast::<S>(*p),
                            f16_field.value_grad_fast::<S>(*p),
                        );
                        assert_eq!(bits(lanes.0[k]), bits(want.0), "{name} f64 {isa:?} at {p:?}");
                        assert_eq!(bits(lanes.1[k]), bits(want.1), "{name} f32 {isa:?} at {p:?}");
                        assert_eq!(bits(lanes.2[k]), bits(want.2), "{name} f16 {isa:?} at {p:?}");
                    }
                });
            }
        }
    }

    /// [`Field::value_grad_fast_lanes`] over the points, at the width of
    /// `isa` (short groups padded with their first point).
    fn lanes_of<const S: usize, T: Coefficient>(
        isa: crate::simd::Isa,
        f: &Field<T>,
        pts: &[[f64; 3]],
    ) -> Vec<(f64, [f64; 3])> {
        let mut out = Vec::new();
        crate::with_isa!(isa, L, _M => {
            for group in pts.chunks(L) {
                let q: [[f64; L]; 3] =
                    std::array::from_fn(|a| std::array::from_fn(|l| group[l.min(group.len() - 1)][a]));
                // SAFETY: L is bound by `with_isa!`.
                let (v, g) = unsafe { f.value_grad_fast_lanes::<S, L>(&q) };
                for l in 0..group.len() {
                    out.push((v[l], [g[0][l], g[1][l], g[2][l]]));
                }
            }
        });
        out
    }

    #[test]
    fn interpolating_filters_reproduce_samples() {
        let vol = ramp([6, 5, 7]);
        for name in [
            "linear",
            "catmull-rom",
            "bspline2",
            "bspline3",
            "bspline5",
            "bspline7",
        ] {
            let f = Field::new(&vol, FilterKind::parse(name, 0.0).unwrap());
            for (x, y, z) in [(0, 0, 0), (5, 4, 6), (2, 3, 1), (3, 0, 6)] {
                let v = f.value(DVec3::new(x as f64, y as f64, z as f64));
                let s = vol.get(x, y, z);
                assert!((v - s).abs() < 1e-4, "{name} at ({x},{y},{z}): {v} vs {s}");
            }
        }
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let vol = crate::volume::scrambled_u8([7, 6, 8], 0);
        for name in [
            "linear",
            "catmull-rom",
            "bspline2",
            "bspline3",
            "bspline4",
            "bspline6",
        ] {
            let f = Field::new(&vol, FilterKind::parse(name, 0.0).unwrap());
            let p = DVec3::new(2.37, 3.61, 4.18);
            let (v, g) = f.value_grad(p);
            assert!((v - f.value(p)).abs() < 1e-9);
            let h = 1e-5;
            for a in 0..3 {
                let mut e = DVec3::ZERO;
                e[a] = h;
                let fd = (f.value(p + e) - f.value(p - e)) / (2.0 * h);
                assert!(
                    (fd - g[a]).abs() < 1e-4 * (1.0 + g[a].abs()),
                    "{name} axis {a}: {fd} vs {}",
                    g[a]
                );
            }
        }
    }

    #[test]
    fn mirror_outside_domain_and_flat_axes() {
        let vol = ramp([5, 4, 1]);
        let f = Field::new(&vol, FilterKind::BSpline(3));
        let (a, ga) = f.value_grad(DVec3::new(-0.7, 1.2, 0.0));
        let (b, gb) = f.value_grad(DVec3::new(0.7, 1.2, 0.0));
        assert!((a - b).abs() < 1e-9);
        assert!((ga.x + gb.x).abs() < 1e-9 && (ga.y - gb.y).abs() < 1e-9);
        // A dimension of 1 is constant along that axis.
        let (_, g) = f.value_grad(DVec3::new(2.0, 1.5, 0.3));
        assert!(g.z.abs() < 1e-12);
    }
}
