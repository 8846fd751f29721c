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
//! reach, so the mirror boundary is the field's own. The axes combine in
//! the order [`Field::value`] combines them (x, then y, then z), but each
//! tap sum is one ascending chain where it keeps partial sums, so the values
//! agree with it to rounding, not bit for bit (tested).

use rayon::prelude::*;

use super::coeffs::APRON;
use super::{Field, FilterKind};
use crate::volume::{SampleType, Volume, VolumeError, limits};

/// Where output sample `j` of `m` lies among `n` input samples (grid
/// coordinate), exactly `0` and `n − 1` at the ends.
fn position(j: usize, n: usize, m: usize) -> f64 {
    if m == 1 {
        0.0
    } else if j + 1 == m {
        (n - 1) as f64
    } else {
        // In `f64` throughout: `j·(n − 1)` may not fit a `usize`. Rounding
        // can only nudge an inner point, never past the last sample.
        (j as f64 * (n - 1) as f64 / (m - 1) as f64).min((n - 1) as f64)
    }
}

/// Per output sample of an axis: the padded index of its first tap and the
/// `S` weights.
fn taps<const S: usize>(field: &Field, n: usize, m: usize) -> Vec<(usize, [f64; S])> {
    let kernel = field.kernel();
    (0..m)
        .map(|j| {
            let (first, t) = kernel.locate(position(j, n, m));
            // x in [0, n − 1] puts the taps in [−APRON, n − 1 + APRON]: the
            // first at ⌊x − S/2⌋ + 1 ≥ −S/2 + 1, the last ≤ n − 1 + S/2.
            debug_assert!(first >= -(APRON as isize) && first + S as isize <= (n + APRON) as isize);
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

/// Bytes held at the passes' peak: the input volume (borrowed throughout),
/// the tap tables, and the two largest buffers alive together. In `u128`,
/// so no lattice overflows the estimate; `None` beyond `u64`.
fn peak_bytes(n: [usize; 3], padded: [usize; 3], m: [usize; 3], support: usize) -> Option<u64> {
    let [n0, n1, n2] = n.map(|v| v as u128);
    let [p0, p1, p2] = padded.map(|v| v as u128);
    let [m0, m1, m2] = m.map(|v| v as u128);
    let input = 4 * n0 * n1 * n2;
    let taps = (m0 + m1 + m2) * (8 + 8 * support as u128);
    let coeffs = 8 * p0 * p1 * p2;
    let along_x = 8 * m0 * p1 * p2;
    let along_y = 8 * m0 * m1 * p2;
    let out = 4 * m0 * m1 * m2;
    let peak = input + taps + (coeffs + along_x).max(along_x + along_y).max(along_y + out);
    u64::try_from(peak).ok()
}

/// The value stored for a sample of type `ty`, `v` relative to `offset`
/// (as the field's evaluations are, [`Field::offset`]), and so relative to
/// it: integers rounded and clamped to the type's range (interpolating
/// filters overshoot near edges).
fn store(ty: SampleType, v: f64, offset: f64) -> f32 {
    match integer_range(ty) {
        // No offset leaves the value's bits (`-0.0 + v` would turn a `-0.0`
        // into `+0.0`).
        Some((lo, hi)) if offset == 0.0 => v.round().clamp(lo, hi) as f32,
        Some((lo, hi)) => ((offset + v).round().clamp(lo, hi) - offset) as f32,
        None => v as f32,
    }
}

/// The values an integer sample type holds (`None` for floats).
pub fn integer_range(ty: SampleType) -> Option<(f64, f64)> {
    Some(match ty {
        SampleType::I8 => (i8::MIN as f64, i8::MAX as f64),
        SampleType::U8 => (0.0, u8::MAX as f64),
        SampleType::I16 => (i16::MIN as f64, i16::MAX as f64),
        SampleType::U16 => (0.0, u16::MAX as f64),
        SampleType::I32 => (i32::MIN as f64, i32::MAX as f64),
        SampleType::U32 => (0.0, u32::MAX as f64),
        SampleType::F32 | SampleType::F64 => return None,
    })
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
    let n = vol.dims();
    let lattice = format!("{}x{}x{}", dims[0], dims[1], dims[2]);
    for a in 0..3 {
        let axis = ["x", "y", "z"][a];
        if dims[a] == 0 || (n[a] > 1 && dims[a] < 2) || (n[a] == 1 && dims[a] != 1) {
            let samples = |k: usize| crate::human::count(k, "sample");
            return Err(VolumeError::Invalid(format!(
                "a lattice of {} along {axis} for {} of input (an axis of one sample stays one; others need at least two)",
                samples(dims[a]),
                samples(n[a])
            )));
        }
    }
    let padded = n.map(|v| v + 2 * APRON);
    let support = kind.kernel().support();
    let too_many = || {
        VolumeError::Invalid(format!(
            "a {lattice} lattice's samples do not fit in memory"
        ))
    };
    let count = dims
        .iter()
        .try_fold(1usize, |acc, &d| acc.checked_mul(d))
        .ok_or_else(too_many)?;
    let peak = peak_bytes(n, padded, dims, support)
        .filter(|&b| usize::try_from(b).is_ok())
        .ok_or_else(too_many)?;
    limits::check_bytes(
        std::path::Path::new(&format!("{lattice} lattice")),
        peak,
        memory_limit,
        "resampling",
    )?;
    let field = Field::new(vol, kind);
    // The new samples lie near the old ones' range: stored relative to the
    // same offset, as the field evaluates them, they keep the precision the
    // old ones had.
    let offset = field.offset();
    let samples = crate::with_support!(field.kernel().support(), S => {
        passes::<S>(field, n, dims, ty, count, offset)
    });
    let spacing: [f64; 3] = std::array::from_fn(|a| {
        if dims[a] == 1 {
            vol.spacing()[a]
        } else {
            vol.spacing()[a] * (n[a] - 1) as f64 / (dims[a] - 1) as f64
        }
    });
    Ok(Volume::new(dims, spacing, ty, samples)?.with_offset(offset))
}

/// The three separable passes (x over every padded row, y over every padded
/// slab, z), each freeing its input.
fn passes<const S: usize>(
    field: Field,
    n: [usize; 3],
    m: [usize; 3],
    ty: SampleType,
    count: usize,
    offset: f64,
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
    // z: each output slice from S slices, stored as `ty`. A task takes
    // `Z_BLOCK` output slices row by row, so the few input rows they share
    // stay in cache; slice after slice, every output slice read its S input
    // slices whole from memory (1024³: 32 GB of reads).
    let slice = m0 * m1;
    let mut out = vec![0.0f32; count];
    out.par_chunks_mut((slice * Z_BLOCK).max(1))
        .enumerate()
        .for_each(|(block, dst)| {
            let mut acc = vec![0.0f64; m0];
            let slices = dst.len() / slice.max(1);
            for y in 0..m1 {
                for dz in 0..slices {
                    let (first, w) = &tz[block * Z_BLOCK + dz];
                    combine::<S>(&along_y, first * slice + y * m0, slice, w, &mut acc);
                    let d = &mut dst[dz * slice + y * m0..][..m0];
                    for (o, &v) in d.iter_mut().zip(&acc) {
                        *o = store(ty, v, offset);
                    }
                }
            }
        });
    out
}

/// Output slices per task of the z pass.
const Z_BLOCK: usize = 16;

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

    /// `r`'s every sample against the field at `point(i, j, k)`.
    fn assert_is_field(r: &Volume, field: &Field, point: impl Fn(usize, usize, usize) -> DVec3) {
        let m = r.dims();
        for k in 0..m[2] {
            for j in 0..m[1] {
                for i in 0..m[0] {
                    let want = field.value(point(i, j, k));
                    let got = r.get(i, j, k);
                    // The output is f32: its rounding, and the sums' order.
                    assert!(
                        (got - want).abs() <= 1e-6 * want.abs() + 1e-9,
                        "{} ({i},{j},{k}): {got} vs {want}",
                        field.kind()
                    );
                }
            }
        }
    }

    /// Every output sample is the field at its lattice point, to rounding,
    /// for every support from 2 to 8, upsampling and downsampling (with an
    /// axis kept as it was); the spacing keeps the world extent.
    #[test]
    fn samples_are_the_field_at_the_new_lattice() {
        let vol = scan();
        let names = [
            "linear",
            "bspline2",
            "catmull-rom",
            "bspline3",
            "bspline4",
            "bspline5",
            "bspline6",
            "bspline7",
        ];
        for name in names {
            let kind = FilterKind::parse(name, 0.0).unwrap();
            let field = Field::new(&vol, kind);
            // 9 → 17 samples: half steps; 7 → 7; 6 → 11: half steps.
            let up = resample(&vol, kind, [17, 7, 11], SampleType::F32, u64::MAX).unwrap();
            assert_is_field(&up, &field, |i, j, k| {
                DVec3::new(i as f64 * 0.5, j as f64, k as f64 * 0.5)
            });
            // 9 → 5: steps of 2; 7 → 4: steps of 2; 6 → 6.
            let down = resample(&vol, kind, [5, 4, 6], SampleType::F32, u64::MAX).unwrap();
            assert_is_field(&down, &field, |i, j, k| {
                DVec3::new(2.0 * i as f64, 2.0 * j as f64, k as f64)
            });
            for r in [&up, &down] {
                for a in 0..3 {
                    let (e0, e1) = (vol.extent()[a], r.extent()[a]);
                    assert!((e0 - e1).abs() <= 1e-12 * e0, "{name} axis {a}");
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

    /// A volume held relative to an offset (values f32 would round: a
    /// pressure's 101325 + 1e-6·x, labels above 2²⁴) resamples on its own
    /// lattice to its own values, in `f64` and in its integer type.
    #[test]
    fn offset_volumes_keep_their_values() {
        let base = scan();
        let d = base.dims();
        let kind = FilterKind::parse("bspline3", 0.0).unwrap();
        let cases = [
            (SampleType::F64, 101325.0, 1e-6),
            (SampleType::U32, 16_777_216.0, 1.0),
        ];
        for (ty, shift, step) in cases {
            let values: Vec<f64> = base
                .samples()
                .iter()
                .map(|&v| shift + step * (v as f64 / 257.0).round())
                .collect();
            let vol = Volume::from_f64(d, [1.0; 3], ty, &values).unwrap();
            assert!(vol.offset() != 0.0, "{ty:?}: f32 rounds these values");
            let r = resample(&vol, kind, d, ty, u64::MAX).unwrap();
            for (i, &want) in values.iter().enumerate() {
                let (x, y, z) = (i % d[0], i / d[0] % d[1], i / (d[0] * d[1]));
                let got = r.get(x, y, z);
                // Within a thousandth of a step (f32 keeps the differences).
                assert!(
                    (got - want).abs() <= 1e-3 * step,
                    "{ty:?} ({x},{y},{z}): {got} vs {want}"
                );
            }
        }
    }

    /// Integer outputs are rounded and clamped to the type's range.
    #[test]
    fn integer_types_round_and_clamp() {
        // Random 0/255 voxels: the interpolating spline rings past both ends.
        let d = [6usize, 6, 6];
        let s = (0..216)
            .map(|i| 255.0 * (crate::phantom::mix64(i as u64) & 1) as f32)
            .collect();
        let vol = Volume::new(d, [1.0; 3], SampleType::U8, s).unwrap();
        let kind = FilterKind::parse("bspline3", 0.0).unwrap();
        let field = Field::new(&vol, kind);
        let u = resample(&vol, kind, [16, 16, 16], SampleType::U8, u64::MAX).unwrap();
        let (mut over, mut under) = (false, false);
        for k in 0..16 {
            for j in 0..16 {
                for i in 0..16 {
                    // 6 → 16 samples: steps of a third.
                    let p = DVec3::new(i as f64, j as f64, k as f64) / 3.0;
                    let v = field.value(p);
                    (over, under) = (over || v > 255.5, under || v < -0.5);
                    assert_eq!(u.get(i, j, k), v.round().clamp(0.0, 255.0));
                }
            }
        }
        assert!(over && under, "the test must see both clamps");
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
        assert!(err([0, 7, 6], u64::MAX).contains("0 samples along x"));
        assert!(err([9, 1, 6], u64::MAX).contains("along y"));
        assert!(err([usize::MAX, 2, 2], u64::MAX).contains("do not fit"));
        assert!(err([1 << 21, 1 << 21, 1 << 21], u64::MAX).contains("do not fit"));
        // The count fits, the passes' buffers would not.
        assert!(err([1 << 58, 2, 2], u64::MAX).contains("do not fit"));
        assert!(err([1024, 1024, 1024], 1 << 30).contains("memory"));
        let flat: Vec<f32> = (0..25).map(|i| ((i * 37) % 11) as f32).collect();
        let flat = Volume::new([5, 5, 1], [1.0; 3], SampleType::F32, flat).unwrap();
        assert!(resample(&flat, kind, [9, 9, 2], SampleType::F32, u64::MAX).is_err());
        // An axis of one sample stays one, through the same passes.
        let r = resample(&flat, kind, [9, 9, 1], SampleType::F32, u64::MAX).unwrap();
        let field = Field::new(&flat, kind);
        assert_is_field(&r, &field, |i, j, _| {
            DVec3::new(i as f64 * 0.5, j as f64 * 0.5, 0.0)
        });
    }
}
