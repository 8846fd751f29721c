//! The continuous field `f(x) = Σ_k c_k φ(x-k)` and its analytic gradient.
//!
//! A [`Field`] owns the prefiltered, padded coefficients and the kernel. Point
//! evaluation computes the `S` weights per axis once (and their derivatives for
//! the gradient), then sweeps the `S³` neighbourhood row by row: each row is a
//! contiguous run of `S` coefficients thanks to the apron, so the inner loop is
//! branch-free. The support is a const generic, chosen once per call by
//! [`with_support!`], so every loop has a compile-time trip count.

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

/// A reconstructed volume: coefficients + kernel, evaluable anywhere.
/// `T` is the coefficient storage ([`Coefficient`]); arithmetic is `f64`.
#[derive(Clone, Debug)]
pub struct Field<T: Coefficient = f64> {
    kind: FilterKind,
    kernel: Kernel,
    coeffs: Coeffs<T>,
    /// Largest coefficient magnitude (computed once; see `separating_iso`).
    max_abs: f64,
}

impl Field<f64> {
    /// Prefilters `vol` for `kind` in place in the padded `f64` grid (parallel
    /// over lines) and keeps the coefficients.
    pub fn new(vol: &Volume, kind: FilterKind) -> Field<f64> {
        let mut coeffs = Coeffs::<f64>::from_volume(vol);
        let prefilter = kind.prefilter();
        if !prefilter.is_identity() {
            let dims = coeffs.dims();
            let origin = coeffs.interior_offset(0, 0, 0);
            let strides = [coeffs.stride(0), coeffs.stride(1), coeffs.stride(2)];
            prefilter.apply_3d_strided(coeffs.data_mut(), dims, origin, strides);
            coeffs.fill_apron();
        }
        debug_assert!(APRON >= kind.kernel().support() / 2);
        Field::from_coeffs(kind, coeffs)
    }
}

impl Field<f32> {
    /// Like [`Field::new`] but stores `f32` coefficients (half the memory); the
    /// prefilter still runs in `f64`, rounding once.
    pub fn new_f32(vol: &Volume, kind: FilterKind) -> Field<f32> {
        let prefilter = kind.prefilter();
        let coeffs = if prefilter.is_identity() {
            Coeffs::from_volume(vol)
        } else {
            let mut work: Vec<f64> = vol.samples().iter().map(|&v| v as f64).collect();
            prefilter.apply_3d(&mut work, vol.dims());
            Coeffs::from_interior(vol.dims(), &work, |v: &f64| *v as f32)
        };
        Field::from_coeffs(kind, coeffs)
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
        }
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
    pub fn separating_iso(&self, iso: f64) -> f64 {
        iso + 1e-11 * iso.abs().max(self.max_abs_coeff()).max(f64::MIN_POSITIVE)
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
    pub fn value_grad_batch(&self, p: [&[f64]; 3], out: [&mut [f64]; 4]) {
        let n = p[0].len();
        assert!(p.iter().all(|a| a.len() == n) && out.iter().all(|a| a.len() == n));
        let [ov, ox, oy, oz] = out;
        for i in 0..n {
            let (v, g) = self.value_grad(DVec3::new(p[0][i], p[1][i], p[2][i]));
            ov[i] = v;
            ox[i] = g.x;
            oy[i] = g.y;
            oz[i] = g.z;
        }
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
    #[inline(always)]
    pub fn value_grad_in<const S: usize>(&self, p: [f64; 3]) -> (f64, [f64; 3]) {
        let (kx, tx) = self.kernel.locate(p[0]);
        let (ky, ty) = self.kernel.locate(p[1]);
        let (kz, tz) = self.kernel.locate(p[2]);
        let (wx, dx) = self.kernel.weights_and_derivs::<S>(tx);
        let (wy, dy) = self.kernel.weights_and_derivs::<S>(ty);
        let (wz, dz) = self.kernel.weights_and_derivs::<S>(tz);
        let (nb, sy, sz) = self.neighbourhood::<S>(self.coeffs.offset(kx, ky, kz));
        // Per plane k: Σ_j wy·(Σ_i wx c), Σ_j wy·(Σ_i dx c), Σ_j dy·(Σ_i wx c).
        let (mut pv, mut px, mut py) = ([0.0; S], [0.0; S], [0.0; S]);
        for k in 0..S {
            let (mut rv, mut rd) = ([0.0; S], [0.0; S]);
            for j in 0..S {
                let row = j * sy + k * sz;
                rv[j] = dot_row::<S, T>(&wx, nb, row);
                rd[j] = dot_row::<S, T>(&dx, nb, row);
            }
            pv[k] = dot(&wy, &rv);
            px[k] = dot(&wy, &rd);
            py[k] = dot(&dy, &rv);
        }
        (dot(&wz, &pv), [dot(&wz, &px), dot(&wz, &py), dot(&dz, &pv)])
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
                let s = vol.get(x, y, z) as f64;
                assert!((v - s).abs() < 1e-4, "{name} at ({x},{y},{z}): {v} vs {s}");
            }
        }
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let mut s = Vec::new();
        for i in 0..(7 * 6 * 8) {
            s.push(((i * 7919) % 251) as f32);
        }
        let vol = Volume::new([7, 6, 8], [1.0; 3], SampleType::U8, s).unwrap();
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
