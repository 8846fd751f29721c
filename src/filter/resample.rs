//! A volume resampled on a new lattice through its reconstruction: the
//! field `f` of a filter (SPEC's grid coordinates and mirror boundary)
//! evaluated at the points of a finer (or coarser) grid spanning the same
//! domain. It makes large test volumes from real scans — a CT upsampled to
//! 1024³ has the scan's anatomy at the size of the biggest volumes users
//! render — and its samples are the filter's own reconstruction, so a
//! render of the upsampled volume with `linear` shows the surface the
//! original shows with the resampling filter (up to the output type's
//! rounding).
//!
//! Output sample `j` of an axis with `n` input and `m` output samples sits at
//! grid coordinate `x = j·(n − 1)/(m − 1)`: the first and last samples stay
//! on the domain's faces, and the spacing grows by `(n − 1)/(m − 1)`, so the
//! world extent is unchanged.
//!
//! Grid-aligned, the tensor-product evaluation separates: the prefiltered
//! coefficients are resampled along x for every padded row, those rows along
//! y, then along z — `S` multiply-adds per output value and pass, where
//! evaluating each point on its own costs `S³`. Each pass's rows are
//! independent (rayon), and each keeps the apron rows the next pass's taps
//! reach, so the mirror boundary is the field's own. The passes are the
//! order [`Field::value`] sums in (x, then y, then z), each tap sum in
//! ascending order; the values agree with it to rounding (tested).

use rayon::prelude::*;

use super::coeffs::APRON;
use super::{Field, FilterKind};
use crate::volume::{SampleType, Volume, VolumeError, limits};

/// Where output sample `j` of `m` lies among `n` input samples (grid
/// coordinate), exactly `0` and `n − 1` at the ends.
fn position(j: usize, n: usize, m: usize) -> f64 {
    if m == 1 {
        0.0
    } else {
        (j * (n - 1)) as f64 / (m - 1) as f64
    }
}

/// Per output sample of an axis: the padded index of its first tap and the
/// `S` weights.
fn taps<const S: usize>(field: &Field, n: usize, m: usize) -> Vec<(usize, [f64; S])> {
    let kernel = field.kernel();
    (0..m)
        .map(|j| {
            let (first, t) = kernel.locate(position(j, n, m));
            // Within [-APRON, n - 1 + APRON] for x in [0, n - 1].
            ((first + APRON as isize) as usize, kernel.weights::<S>(t))
        })
        .collect()
}

/// `Σ_s w[s] · rows[s]` element by element into `out` (the rows `len` long,
/// `stride` apart in `src`, the first at `at`).
#[inline(always)]
fn combine<const S: usize>(src: &[f64], at: usize, stride: usize, w: &[f64; S], out: &mut [f64]) {
    let len = out.len();
    let first = &src[at..at + len];
    for (o, &v) in out.iter_mut().zip(first) {
        *o = w[0] * v;
    }
    for (s, &ws) in w.iter().enumerate().skip(1) {
        let row = &src[at + s * stride..at + s * stride + len];
        for (o, &v) in out.iter_mut().zip(row) {
            *o += ws * v;
        }
    }
}

/// Bytes the passes hold at their peak (the input volume aside).
fn peak_bytes(padded: [usize; 3], m: [usize; 3]) -> u64 {
    let [p0, p1, p2] = padded.map(|v| v as u64);
    let [m0, m1, m2] = m.map(|v| v as u64);
    let coeffs = 8 * p0 * p1 * p2;
    let along_x = 8 * m0 * p1 * p2;
    let along_y = 8 * m0 * m1 * p2;
    let out = 4 * m0 * m1 * m2;
    (coeffs + along_x).max(along_x + along_y).max(along_y + out)
}

/// The value stored for a sample of type `ty`: integers rounded and clamped
/// to the type's range (interpolating filters overshoot near edges).
fn store(ty: SampleType, v: f64) -> f32 {
    let (lo, hi) = match ty {
        SampleType::I8 => (i8::MIN as f64, i8::MAX as f64),
        SampleType::U8 => (0.0, u8::MAX as f64),
        SampleType::I16 => (i16::MIN as f64, i16::MAX as f64),
        SampleType::U16 => (0.0, u16::MAX as f64),
        SampleType::I32 => (i32::MIN as f64, i32::MAX as f64),
        SampleType::U32 => (0.0, u32::MAX as f64),
        SampleType::F32 | SampleType::F64 => return v as f32,
    };
    v.round().clamp(lo, hi) as f32
}

/// `vol` reconstructed with `kind` and sampled on a `dims` lattice over the
/// same domain, stored as `ty` (see the module notes). An axis of one sample
/// stays one sample; every other axis needs at least two. Fails before
/// allocating when the passes would need more than `memory_limit` bytes.
pub fn resample(
    vol: &Volume,
    kind: FilterKind,
    dims: [usize; 3],
    ty: SampleType,
    memory_limit: u64,
) -> Result<Volume, VolumeError> {
    let here = std::path::Path::new("resample");
    let n = vol.dims();
    for a in 0..3 {
        let axis = ["x", "y", "z"][a];
        if dims[a] == 0 || (n[a] > 1 && dims[a] < 2) || (n[a] == 1 && dims[a] != 1) {
            return Err(VolumeError::Invalid(format!(
                "resample: {} output samples along {axis} for {} input samples (an axis of one sample stays one; others need at least two)",
                dims[a], n[a]
            )));
        }
    }
    let count = dims
        .iter()
        .try_fold(1usize, |acc, &d| acc.checked_mul(d))
        .filter(|&c| c.checked_mul(8).is_some())
        .ok_or_else(|| {
            VolumeError::Invalid(format!(
                "resample: {}x{}x{} samples do not fit in memory",
                dims[0], dims[1], dims[2]
            ))
        })?;
    let padded = n.map(|v| v + 2 * APRON);
    limits::check_bytes(
        here,
        peak_bytes(padded, dims),
        memory_limit,
        &format!("resampling to {}x{}x{}", dims[0], dims[1], dims[2]),
    )?;
    let field = Field::new(vol, kind);
    let samples = crate::with_support!(field.kernel().support(), S => {
        passes::<S>(field, n, dims, ty, count)
    });
    let spacing: [f64; 3] = std::array::from_fn(|a| {
        if dims[a] == 1 {
            vol.spacing()[a]
        } else {
            vol.spacing()[a] * (n[a] - 1) as f64 / (dims[a] - 1) as f64
        }
    });
    Volume::new(dims, spacing, ty, samples)
}

/// The three separable passes (x over every padded row, y over every padded
/// slab, z), each freeing its input.
fn passes<const S: usize>(
    field: Field,
    n: [usize; 3],
    m: [usize; 3],
    ty: SampleType,
    count: usize,
) -> Vec<f32> {
    let [m0, m1, m2] = m;
    let (tx, ty_, tz) = (
        taps::<S>(&field, n[0], m0),
        taps::<S>(&field, n[1], m1),
        taps::<S>(&field, n[2], m2),
    );
    let coeffs = field.coeffs();
    let (p0, p1) = (coeffs.stride(1), coeffs.stride(2) / coeffs.stride(1));
    let p2 = coeffs.data().len() / coeffs.stride(2);
    // x: every padded row (y, z) of the coefficients to m0 values.
    let mut along_x = vec![0.0f64; m0 * p1 * p2];
    along_x
        .par_chunks_mut(m0)
        .zip(coeffs.data().par_chunks(p0))
        .for_each(|(out, row)| {
            for (o, (first, w)) in out.iter_mut().zip(&tx) {
                let c = &row[*first..*first + S];
                let mut acc = w[0] * c[0];
                for (ws, cs) in w.iter().zip(c).skip(1) {
                    acc += ws * cs;
                }
                *o = acc;
            }
        });
    drop(field);
    // y: each padded z slab's rows to m1 rows.
    let mut along_y = vec![0.0f64; m0 * m1 * p2];
    along_y.par_chunks_mut(m0).enumerate().for_each(|(r, out)| {
        let (z, y) = (r / m1, r % m1);
        let (first, w) = &ty_[y];
        combine::<S>(&along_x, (z * p1 + first) * m0, m0, w, out);
    });
    drop(along_x);
    // z: each output slice from S slices, stored as `ty`.
    let slice = m0 * m1;
    let mut out = vec![0.0f32; count];
    out.par_chunks_mut(slice.max(1))
        .enumerate()
        .for_each(|(z, dst)| {
            let (first, w) = &tz[z];
            let mut acc = vec![0.0f64; m0];
            for (y, d) in dst.chunks_mut(m0).enumerate() {
                combine::<S>(&along_y, first * slice + y * m0, slice, w, &mut acc);
                for (o, &v) in d.iter_mut().zip(&acc) {
                    *o = store(ty, v);
                }
            }
        });
    out
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;

    fn scan() -> Volume {
        // Smooth plus a rough part, anisotropic spacing, u16 range.
        let d = [9usize, 7, 6];
        let s = (0..d[0] * d[1] * d[2])
            .map(|i| {
                let (x, y, z) = (i % d[0], i / d[0] % d[1], i / (d[0] * d[1]));
                (1000.0
                    + 300.0 * (x as f64 * 0.7).sin() * (y as f64 * 0.5).cos()
                    + 40.0 * z as f64
                    + ((i * 7919) % 13) as f64)
                    .round() as f32
            })
            .collect();
        Volume::new(d, [0.9, 1.1, 1.5], SampleType::U16, s).unwrap()
    }

    /// Every output sample is the field at its lattice point, to rounding,
    /// for filters with supports 2 to 8 (and an axis left alone); the
    /// spacing keeps the world extent.
    #[test]
    fn samples_are_the_field_at_the_new_lattice() {
        let vol = scan();
        for name in ["linear", "catmull-rom", "bspline3", "bspline4", "bspline7"] {
            let kind = FilterKind::parse(name, 0.0).unwrap();
            let field = Field::new(&vol, kind);
            let m = [17, 7, 11];
            let r = resample(&vol, kind, m, SampleType::F32, u64::MAX).unwrap();
            assert_eq!(r.dims(), m);
            for a in 0..3 {
                let (e0, e1) = (vol.extent()[a], r.extent()[a]);
                assert!((e0 - e1).abs() <= 1e-12 * e0, "{name} axis {a}");
            }
            for k in 0..m[2] {
                for j in 0..m[1] {
                    for i in 0..m[0] {
                        // 9 → 17 samples: half steps; 7 → 7; 6 → 11: half steps.
                        let p = DVec3::new(i as f64 * 0.5, j as f64, k as f64 * 0.5);
                        let want = field.value(p);
                        let got = r.get(i, j, k) as f64;
                        // The output is f32: its rounding, and the sums' order.
                        assert!(
                            (got - want).abs() <= 1e-6 * want.abs() + 1e-9,
                            "{name} ({i},{j},{k}): {got} vs {want}"
                        );
                    }
                }
            }
        }
    }

    /// An interpolating filter on the input's own lattice gives the samples
    /// back (rounded to the type), and the lattice ends are the domain's.
    #[test]
    fn same_lattice_reproduces_the_samples() {
        let vol = scan();
        for name in ["linear", "catmull-rom", "bspline3", "bspline5"] {
            let kind = FilterKind::parse(name, 0.0).unwrap();
            let r = resample(&vol, kind, vol.dims(), SampleType::U16, u64::MAX).unwrap();
            assert_eq!(r.native_type(), SampleType::U16);
            assert_eq!(r.spacing(), vol.spacing(), "{name}");
            assert_eq!(r.samples(), vol.samples(), "{name}");
        }
        assert_eq!(position(0, 9, 17), 0.0);
        assert_eq!(position(16, 9, 17), 8.0);
        assert_eq!(position(1000, 108, 1001), 107.0);
    }

    /// Integer outputs are rounded and clamped to the type's range.
    #[test]
    fn integer_types_round_and_clamp() {
        let d = [4usize, 4, 4];
        let s = (0..64)
            .map(|i| if i % 3 == 0 { 255.0 } else { 0.0 })
            .collect();
        let vol = Volume::new(d, [1.0; 3], SampleType::U8, s).unwrap();
        let kind = FilterKind::parse("bspline3", 0.0).unwrap();
        let f = resample(&vol, kind, [9, 9, 9], SampleType::F32, u64::MAX).unwrap();
        let u = resample(&vol, kind, [9, 9, 9], SampleType::U8, u64::MAX).unwrap();
        // The interpolating spline overshoots [0, 255] between samples.
        assert!(f.samples().iter().any(|&v| !(0.0..=255.0).contains(&v)));
        for (&a, &b) in f.samples().iter().zip(u.samples()) {
            assert_eq!(b, (a as f64).round().clamp(0.0, 255.0) as f32);
        }
    }

    /// Impossible lattices and budgets are errors, not panics or huge
    /// allocations.
    #[test]
    fn bad_lattices_are_refused() {
        let vol = scan();
        let kind = FilterKind::parse("bspline3", 0.0).unwrap();
        let err = |m: [usize; 3], limit: u64| {
            resample(&vol, kind, m, SampleType::F32, limit)
                .unwrap_err()
                .to_string()
        };
        assert!(err([0, 7, 6], u64::MAX).contains("along x"));
        assert!(err([9, 1, 6], u64::MAX).contains("along y"));
        assert!(err([usize::MAX, 2, 2], u64::MAX).contains("do not fit"));
        assert!(err([1 << 21, 1 << 21, 1 << 21], u64::MAX).contains("do not fit"));
        assert!(err([1024, 1024, 1024], 1 << 30).contains("memory"));
        let flat = Volume::new([5, 5, 1], [1.0; 3], SampleType::F32, vec![1.0; 25]).unwrap();
        assert!(resample(&flat, kind, [9, 9, 2], SampleType::F32, u64::MAX).is_err());
        let r = resample(&flat, kind, [9, 9, 1], SampleType::F32, u64::MAX).unwrap();
        assert!(r.samples().iter().all(|&v| (v - 1.0).abs() < 1e-6));
    }
}
