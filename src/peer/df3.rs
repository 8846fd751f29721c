//! POV-Ray density files (DF3) and how a snell [`Volume`] maps onto one.
//!
//! # The file
//! A DF3 is a big-endian `u16` header `(nx, ny, nz)` followed by the samples,
//! x fastest, as 8-, 16- or 32-bit big-endian unsigned integers (POV-Ray infers
//! the width from the file size). We always write 16 bits; POV-Ray divides by
//! 65535, so the `density_file` pattern returns `counts / 65535`.
//!
//! # Values
//! A sample `v` (the volume's native units) is stored as
//! `counts = (v - lo) · scale`, `lo` = the volume's minimum:
//! - integer-valued volumes whose range fits (`max - lo ≤ 65535`, e.g. every
//!   u8 and u16 volume) use the integer `scale = floor(65535 / (max - lo))`,
//!   so `counts` is exact — a full-range u8 volume gets `scale = 257`, i.e.
//!   density `= v / 255` exactly;
//! - anything else (float volumes, wider integers) uses
//!   `scale = 65535 / (max - lo)` and rounds to the nearest count: an error of at
//!   most `(max - lo) / 131070` in value.
//!
//! The iso-value maps the same way: `iso_density = (iso - lo) · scale / 65535`
//! ([`Df3Mapping::density`]).
//!
//! # Positions (measured on POV-Ray 3.7.0.10, see `tests/peer.rs`)
//! POV-Ray places sample `p` of an `M`-sample axis at pattern coordinate `p / M`
//! (not `p / (M-1)`): `interpolate 1` is exact trilinear interpolation between
//! samples `⌊M·e⌋` and `⌊M·e⌋ + 1`; `interpolate 2` is exact Catmull-Rom
//! (cubic convolution, `a = -0.5`, evaluated in single precision) on the four
//! samples around. Neighbours beyond the last sample wrap to the first ones, and
//! the neighbour before sample 0 is read from a wrong index (it depends on the
//! other axes' sizes), so neither matches SPEC.md's mirror boundary. We
//! therefore write a **one-sample mirror border**: the file holds `N + 2`
//! samples per axis, file sample `p` = volume sample `mirror(p - 1)`. Volume
//! sample `i` is file sample `i + 1`, at pattern coordinate `(i + 1) / (N + 2)`,
//! and every cell of the volume's domain `[0, N-1]` reads only file samples
//! `0..=N+1`: both interpolants then equal snell's `linear` and `catmull-rom`
//! filters with the mirror boundary exactly (up to float rounding), including
//! the boundary cells. Negative Catmull-Rom undershoot is clamped to 0 by
//! POV-Ray; it only occurs below `lo ≤ iso`, so the surface is unaffected.

use std::io::Write;
use std::path::Path;

use rayon::prelude::*;

use super::PeerError;
use crate::atomic::write_atomic;
use crate::filter::FilterKind;
use crate::volume::Volume;

/// Largest count a 16-bit DF3 sample holds; POV-Ray divides by it.
pub const DF3_MAX: f64 = 65535.0;

/// POV-Ray's `density_file ... interpolate N`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Interpolation {
    /// `interpolate 1`: trilinear, snell's `linear`.
    Trilinear,
    /// `interpolate 2`: tricubic Catmull-Rom, snell's `catmull-rom`.
    Tricubic,
}

impl Interpolation {
    /// The number POV-Ray's `interpolate` keyword takes.
    pub fn keyword(self) -> u8 {
        match self {
            Interpolation::Trilinear => 1,
            Interpolation::Tricubic => 2,
        }
    }

    /// The closest POV-Ray interpolation to a snell filter: trilinear for
    /// `linear`, tricubic (Catmull-Rom) for every cubic or higher filter.
    pub fn from_filter(f: FilterKind) -> Interpolation {
        match f {
            FilterKind::Linear => Interpolation::Trilinear,
            _ => Interpolation::Tricubic,
        }
    }

    /// The snell filter POV-Ray's interpolation equals.
    pub fn filter(self) -> FilterKind {
        match self {
            Interpolation::Trilinear => FilterKind::Linear,
            Interpolation::Tricubic => FilterKind::CatmullRom,
        }
    }

    /// `1`, `2`, or the names `trilinear`/`linear`, `tricubic`/`catmull-rom`.
    pub fn parse(s: &str) -> Option<Interpolation> {
        match s.trim().to_ascii_lowercase().as_str() {
            "1" | "trilinear" | "linear" => Some(Interpolation::Trilinear),
            "2" | "tricubic" | "catmull-rom" => Some(Interpolation::Tricubic),
            _ => None,
        }
    }
}

/// How a volume's samples and grid map onto its DF3 file (see the module
/// docs for the exact rules).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Df3Mapping {
    /// The volume's dims.
    pub dims: [usize; 3],
    /// The file's dims: `dims + 2` (a one-sample mirror border per side).
    pub file_dims: [usize; 3],
    /// Value stored as count 0 (the volume's minimum).
    pub lo: f64,
    /// Counts per unit of value.
    pub scale: f64,
    /// True when every sample is stored without rounding.
    pub exact: bool,
}

impl Df3Mapping {
    /// The mapping for `vol` (fails only when a dim does not fit the 16-bit
    /// header).
    pub fn for_volume(vol: &Volume) -> Result<Df3Mapping, PeerError> {
        let dims = vol.dims();
        let file_dims = dims.map(|n| n + 2);
        if let Some(n) = file_dims.iter().find(|&&n| n > u16::MAX as usize) {
            return Err(PeerError::Unsupported(format!(
                "a DF3 axis holds at most {} samples, the volume needs {n} (with its border)",
                u16::MAX
            )));
        }
        let (mut lo, mut hi, mut integral) = (f64::INFINITY, f64::NEG_INFINITY, true);
        let offset = vol.offset();
        for &v in vol.samples() {
            let v = offset + v as f64;
            lo = lo.min(v);
            hi = hi.max(v);
            integral &= v.fract() == 0.0;
        }
        let span = hi - lo;
        let (scale, exact) = if span <= 0.0 || !span.is_finite() {
            (1.0, true)
        } else if integral && span <= DF3_MAX {
            ((DF3_MAX / span).floor(), true)
        } else {
            (DF3_MAX / span, false)
        };
        Ok(Df3Mapping {
            dims,
            file_dims,
            lo,
            scale,
            exact,
        })
    }

    /// Counts for value `v`, before rounding.
    pub fn counts(&self, v: f64) -> f64 {
        (v - self.lo) * self.scale
    }

    /// The stored count of a sample.
    pub fn quantize(&self, v: f64) -> u16 {
        self.counts(v).round().clamp(0.0, DF3_MAX) as u16
    }

    /// What POV-Ray's pattern returns for value `v` (the iso-value's image
    /// is the isosurface threshold).
    pub fn density(&self, v: f64) -> f64 {
        self.counts(v) / DF3_MAX
    }

    /// Pattern coordinate of grid coordinate `g` on `axis`: `(g + 1) / (N + 2)`.
    pub fn pattern_coord(&self, axis: usize, g: f64) -> f64 {
        (g + 1.0) / self.file_dims[axis] as f64
    }
}

/// Whole-sample mirror of index `i` into `0..n` (SPEC.md's boundary).
pub(crate) fn mirror(i: i64, n: usize) -> usize {
    if n <= 1 {
        return 0;
    }
    let p = 2 * (n as i64 - 1);
    let m = i.rem_euclid(p);
    (if m > n as i64 - 1 { p - m } else { m }) as usize
}

/// Writes `vol` as a 16-bit DF3 with a one-sample mirror border, atomically,
/// and returns the mapping used.
pub fn write_df3(path: &Path, vol: &Volume) -> Result<Df3Mapping, PeerError> {
    let m = Df3Mapping::for_volume(vol)?;
    let [nx, ny, nz] = m.dims;
    let [fx, fy, fz] = m.file_dims;
    write_atomic(path, |w| {
        for d in m.file_dims {
            w.write_all(&(d as u16).to_be_bytes())?;
        }
        let mut row = Vec::with_capacity(fx * 2);
        for pz in 0..fz {
            let z = mirror(pz as i64 - 1, nz);
            for py in 0..fy {
                let y = mirror(py as i64 - 1, ny);
                row.clear();
                for px in 0..fx {
                    let x = mirror(px as i64 - 1, nx);
                    let c = m.quantize(vol.get(x, y, z));
                    row.extend_from_slice(&c.to_be_bytes());
                }
                w.write_all(&row)?;
            }
        }
        Ok(())
    })
    .map_err(|e| PeerError::io(path, e))?;
    Ok(m)
}

/// A parsed DF3 file.
#[derive(Clone, Debug, PartialEq)]
pub struct Df3 {
    pub dims: [usize; 3],
    /// 1, 2 or 4.
    pub bytes_per_sample: usize,
    /// Samples, x fastest.
    pub samples: Vec<u32>,
}

/// Reads a DF3 file (any sample width), inferring the width from the size as
/// POV-Ray does.
pub fn read_df3(path: &Path) -> Result<Df3, PeerError> {
    let bytes = crate::input::read(path).map_err(|e| PeerError::io(path, e))?;
    let bad = |msg: String| PeerError::Format {
        path: path.to_path_buf(),
        msg,
    };
    if bytes.len() < 6 {
        return Err(bad(format!(
            "{} bytes is too short for a DF3 header",
            bytes.len()
        )));
    }
    let dims: [usize; 3] =
        std::array::from_fn(|a| u16::from_be_bytes([bytes[2 * a], bytes[2 * a + 1]]) as usize);
    let n = dims[0] * dims[1] * dims[2];
    let body = &bytes[6..];
    let width = match (n, body.len()) {
        (0, _) => return Err(bad(format!("dims {dims:?} contain a zero"))),
        (n, len) if len == n => 1,
        (n, len) if len == 2 * n => 2,
        (n, len) if len == 4 * n => 4,
        (n, len) => {
            return Err(bad(format!(
                "{len} data bytes do not hold {n} samples of 1, 2 or 4 bytes"
            )));
        }
    };
    let samples = body
        .chunks_exact(width)
        .map(|c| match width {
            1 => c[0] as u32,
            2 => u16::from_be_bytes([c[0], c[1]]) as u32,
            _ => u32::from_be_bytes([c[0], c[1], c[2], c[3]]),
        })
        .collect();
    Ok(Df3 {
        dims,
        bytes_per_sample: width,
        samples,
    })
}

/// Catmull-Rom weights (taps `-1..=2`) and their derivatives at `t ∈ [0, 1)`.
fn catmull_rom(t: f64) -> ([f64; 4], [f64; 4]) {
    let (t2, t3) = (t * t, t * t * t);
    (
        [
            0.5 * (-t3 + 2.0 * t2 - t),
            0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
            0.5 * (-3.0 * t3 + 4.0 * t2 + t),
            0.5 * (t3 - t2),
        ],
        [
            0.5 * (-3.0 * t2 + 4.0 * t - 1.0),
            0.5 * (9.0 * t2 - 10.0 * t),
            0.5 * (-9.0 * t2 + 8.0 * t + 1.0),
            0.5 * (3.0 * t2 - 2.0 * t),
        ],
    )
}

/// One output position along an axis: the four sample indices (mirrored) and
/// the value and derivative weights.
struct Tap {
    idx: [usize; 4],
    wv: [f64; 4],
    wd: [f64; 4],
}

fn taps(n: usize, sub: usize) -> Vec<Tap> {
    let mut out = Vec::with_capacity(n.saturating_sub(1) * sub + 1);
    let mk = |c: usize, t: f64| {
        let (wv, wd) = catmull_rom(t);
        Tap {
            idx: std::array::from_fn(|k| mirror(c as i64 + k as i64 - 1, n)),
            wv,
            wd,
        }
    };
    for c in 0..n.saturating_sub(1) {
        for s in 0..sub {
            out.push(mk(c, s as f64 / sub as f64));
        }
    }
    out.push(mk(n - 1, 0.0));
    out
}

/// Sub-positions per cell at which the tricubic gradient is sampled: 4 for
/// volumes up to 2²² samples, 2 beyond (the cost grows with their cube).
pub fn gradient_subdivision(dims: [usize; 3]) -> usize {
    if dims.iter().product::<usize>() <= 1 << 22 {
        4
    } else {
        2
    }
}

/// The largest gradient magnitude of POV-Ray's interpolated density (in DF3
/// density units per grid unit, the isosurface's object space), as
/// `max_gradient` needs it.
///
/// - Trilinear: exact. Each gradient component is linear along the other two
///   axes, so `|∇|²` is convex along every axis and peaks at a cell corner,
///   where the components are the cell's edge differences.
/// - Tricubic: the analytic Catmull-Rom gradient sampled at
///   [`gradient_subdivision`] points per cell and axis (cell corners
///   included) — an estimate from below; callers add a safety factor.
pub fn max_gradient(vol: &Volume, m: &Df3Mapping, interp: Interpolation) -> f64 {
    max_gradient_sampled(vol, m, interp, gradient_subdivision(vol.dims()))
}

/// The factor on [`max_gradient`] that makes it a safe `max_gradient`:
/// 1.01 for trilinear (an exact bound; the margin covers rounding); for
/// tricubic 1.05 with 4 samples per cell and 1.1 with 2 (measured against 2·10⁶
/// random points: on white noise, the worst case, the true maximum is up to
/// 2.3% resp. 3.6% above the samples; on the example sphere 0.01% resp. 0.3%).
pub fn gradient_safety(interp: Interpolation, dims: [usize; 3]) -> f64 {
    match (interp, gradient_subdivision(dims)) {
        (Interpolation::Trilinear, _) => 1.01,
        (Interpolation::Tricubic, 4) => 1.05,
        (Interpolation::Tricubic, _) => 1.1,
    }
}

/// [`max_gradient`] with the tricubic gradient sampled at `sub` points per
/// cell and axis (ignored for trilinear).
pub fn max_gradient_sampled(
    vol: &Volume,
    m: &Df3Mapping,
    interp: Interpolation,
    sub: usize,
) -> f64 {
    let sub = sub.max(1);
    let [nx, ny, nz] = vol.dims();
    let offset = vol.offset();
    let d: Vec<f64> = vol
        .samples()
        .par_iter()
        .map(|&v| m.quantize(offset + v as f64) as f64 / DF3_MAX)
        .collect();
    let at = |x: usize, y: usize, z: usize| d[x + nx * (y + ny * z)];
    match interp {
        Interpolation::Trilinear => (0..nz.saturating_sub(1).max(1))
            .into_par_iter()
            .map(|z0| {
                let z1 = (z0 + 1).min(nz - 1);
                let mut best = 0.0f64;
                for y0 in 0..ny.saturating_sub(1).max(1) {
                    let y1 = (y0 + 1).min(ny - 1);
                    for x0 in 0..nx.saturating_sub(1).max(1) {
                        let x1 = (x0 + 1).min(nx - 1);
                        let (xs, ys, zs) = ([x0, x1], [y0, y1], [z0, z1]);
                        let c = |i: usize, j: usize, k: usize| at(xs[i], ys[j], zs[k]);
                        for i in 0..2 {
                            for j in 0..2 {
                                for k in 0..2 {
                                    let gx = c(1, j, k) - c(0, j, k);
                                    let gy = c(i, 1, k) - c(i, 0, k);
                                    let gz = c(i, j, 1) - c(i, j, 0);
                                    best = best.max(gx * gx + gy * gy + gz * gz);
                                }
                            }
                        }
                    }
                }
                best
            })
            .reduce(|| 0.0, f64::max)
            .sqrt(),
        Interpolation::Tricubic => {
            let (tx, ty, tz) = (taps(nx, sub), taps(ny, sub), taps(nz, sub));
            tz.par_iter()
                .map(|t| {
                    // Filter along z: value and derivative planes.
                    let mut pv = vec![0.0f64; nx * ny];
                    let mut pd = vec![0.0f64; nx * ny];
                    for k in 0..4 {
                        let z = t.idx[k];
                        let plane = &d[nx * ny * z..nx * ny * (z + 1)];
                        for (i, &s) in plane.iter().enumerate() {
                            pv[i] += t.wv[k] * s;
                            pd[i] += t.wd[k] * s;
                        }
                    }
                    let (mut vv, mut vd, mut dv) =
                        (vec![0.0f64; nx], vec![0.0f64; nx], vec![0.0f64; nx]);
                    let mut best = 0.0f64;
                    for u in &ty {
                        vv.fill(0.0);
                        vd.fill(0.0);
                        dv.fill(0.0);
                        for k in 0..4 {
                            let row = nx * u.idx[k];
                            for x in 0..nx {
                                vv[x] += u.wv[k] * pv[row + x];
                                vd[x] += u.wd[k] * pv[row + x];
                                dv[x] += u.wv[k] * pd[row + x];
                            }
                        }
                        for w in &tx {
                            let (mut gx, mut gy, mut gz) = (0.0, 0.0, 0.0);
                            for k in 0..4 {
                                let i = w.idx[k];
                                gx += w.wd[k] * vv[i];
                                gy += w.wv[k] * vd[i];
                                gz += w.wv[k] * dv[i];
                            }
                            best = best.max(gx * gx + gy * gy + gz * gz);
                        }
                    }
                    best
                })
                .reduce(|| 0.0, f64::max)
                .sqrt()
        }
    }
}

/// The smallest grid-aligned box `[lo, hi]` (grid coordinates, inclusive)
/// outside of which POV-Ray's interpolant of `vol` stays at or below `iso`
/// (native units): the `contained_by` box.
///
/// POV-Ray finds surfaces only inside `contained_by` and spends its root
/// search on every ray segment through it, so the box should be tight — but
/// it must hold the whole inside region, not just the surface (an object
/// cut open by the data's edge is inside right up to that face). A knot cell
/// joins the box when its conservative upper bound reaches `iso` ([`CellBound`]:
/// the sample range for trilinear, signed-weight intervals for Catmull-Rom's
/// overshoot), lowered by one DF3 count for the quantization and POV-Ray's
/// single-precision evaluation. `None` when no cell can reach `iso` (the
/// isosurface is empty; any box then renders the same).
///
/// [`CellBound`]: crate::classify::bound::CellBound
pub fn containing_box(
    vol: &Volume,
    m: &Df3Mapping,
    interp: Interpolation,
    iso: f64,
) -> Option<([usize; 3], [usize; 3])> {
    let dims = vol.dims();
    if dims.iter().any(|&n| n < 2) {
        return Some(([0; 3], dims.map(|n| n.saturating_sub(1))));
    }
    let field = crate::filter::Field::new(vol, interp.filter());
    let bound = crate::classify::bound::CellBound::new(field.kernel());
    let count = if m.scale > 0.0 { 1.0 / m.scale } else { 0.0 };
    let threshold = iso - count - 1e-6 * iso.abs().max(count) - field.offset();
    // The bounds are relative to the field's offset, as its evaluations are.
    let iso = iso - field.offset();
    let [cx, cy, cz] = dims.map(|n| n - 1);
    let merge =
        |a: Option<([usize; 3], [usize; 3])>, b: Option<([usize; 3], [usize; 3])>| match (a, b) {
            (Some((al, ah)), Some((bl, bh))) => Some((
                std::array::from_fn(|i| al[i].min(bl[i])),
                std::array::from_fn(|i| ah[i].max(bh[i])),
            )),
            (a, None) => a,
            (None, b) => b,
        };
    (0..cz)
        .into_par_iter()
        .map(|z| {
            let mut found = None;
            for y in 0..cy {
                for x in 0..cx {
                    let (_, hi) = bound.range(&field, [x as i64, y as i64, z as i64], iso);
                    if hi >= threshold {
                        found = merge(found, Some(([x, y, z], [x + 1, y + 1, z + 1])));
                    }
                }
            }
            found
        })
        .reduce(|| None, merge)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::SampleType;

    #[test]
    fn mirror_matches_spec() {
        assert_eq!(mirror(-1, 5), 1);
        assert_eq!(mirror(-2, 5), 2);
        assert_eq!(mirror(5, 5), 3);
        assert_eq!(mirror(6, 5), 2);
        assert_eq!(mirror(3, 2), 1);
        assert_eq!(mirror(-1, 2), 1);
        assert_eq!(mirror(7, 1), 0);
    }

    /// The box holds every point where the interpolant exceeds the iso-value
    /// (dense sampling), including an inside region cut open by the data's
    /// edge, and is tighter than the grid.
    #[test]
    fn containing_box_holds_the_inside() {
        let n = 16usize;
        let mut s = Vec::new();
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    // A ball around (7, 6, 5) plus a slab x < 1.5 that meets the x = 0 face.
                    let r = ((x as f64 - 7.0).powi(2)
                        + (y as f64 - 6.0).powi(2)
                        + (z as f64 - 5.0).powi(2))
                    .sqrt();
                    let ball = (2.5 - r).clamp(0.0, 1.0);
                    let slab = if x == 0 && (4..8).contains(&y) && z == 3 {
                        1.0
                    } else {
                        0.0
                    };
                    s.push((255.0 * f64::max(ball, slab)).round() as f32);
                }
            }
        }
        let v = Volume::new([n; 3], [1.0; 3], SampleType::U8, s).unwrap();
        let m = Df3Mapping::for_volume(&v).unwrap();
        let iso = 100.0;
        for interp in [Interpolation::Trilinear, Interpolation::Tricubic] {
            let (lo, hi) = containing_box(&v, &m, interp, iso).unwrap();
            assert_eq!(lo[0], 0, "{interp:?}: the slab touches x = 0");
            assert!(
                hi[0] < n - 1 && lo[2] > 0,
                "{interp:?}: not tight: {lo:?} {hi:?}"
            );
            let field = crate::filter::Field::new(&v, interp.filter());
            let k = 4 * (n - 1);
            for p in 0..=k * k * k {
                let g = [
                    p % (k + 1),
                    (p / (k + 1)) % (k + 1),
                    p / ((k + 1) * (k + 1)),
                ]
                .map(|i| i as f64 / 4.0);
                if field.offset() + field.value(glam::DVec3::from(g)) > iso {
                    for a in 0..3 {
                        assert!(
                            lo[a] as f64 <= g[a] && g[a] <= hi[a] as f64,
                            "{interp:?}: {g:?} outside {lo:?}..{hi:?}"
                        );
                    }
                }
            }
        }
        assert_eq!(containing_box(&v, &m, Interpolation::Tricubic, 400.0), None);
    }

    #[test]
    fn u8_maps_exactly() {
        let v = Volume::new([2, 1, 1], [1.0; 3], SampleType::U8, vec![0.0, 255.0]).unwrap();
        let m = Df3Mapping::for_volume(&v).unwrap();
        assert_eq!((m.lo, m.scale, m.exact), (0.0, 257.0, true));
        assert_eq!(m.density(127.5), 0.5);
        assert_eq!(m.quantize(255.0), 65535);
        let f = Volume::new([2, 1, 1], [1.0; 3], SampleType::F32, vec![-1.0, 0.5]).unwrap();
        let m = Df3Mapping::for_volume(&f).unwrap();
        assert!(!m.exact);
        assert_eq!(m.quantize(0.5), 65535);
        assert_eq!(m.quantize(-1.0), 0);
    }

    #[test]
    fn trilinear_gradient_is_the_steepest_edge() {
        // A ramp of 0, 255 along x: density jumps by 1 per grid unit.
        let v = Volume::new(
            [2, 2, 1],
            [1.0; 3],
            SampleType::U8,
            vec![0.0, 255.0, 0.0, 255.0],
        )
        .unwrap();
        let m = Df3Mapping::for_volume(&v).unwrap();
        assert!((max_gradient(&v, &m, Interpolation::Trilinear) - 1.0).abs() < 1e-12);
        // Catmull-Rom on a mirrored two-sample ramp: slope 1.5 mid-cell.
        let g = max_gradient(&v, &m, Interpolation::Tricubic);
        assert!((g - 1.5).abs() < 1e-12, "{g}");
    }
}
