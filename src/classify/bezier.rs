//! Cell classification by the Bézier hull: beyond the paper's ACCC.
//!
//! Inside a knot cell the field is one trivariate polynomial of degree `S-1`
//! per axis. Writing each weight polynomial in the Bernstein basis,
//! `W_i(t) = Σ_p β_ip B_p(t)`, gives the cell's tensor Bernstein coefficients
//! `b_pqr = Σ_ijk c_ijk β_ip β_jq β_kr` (a separable `S×S` transform per axis,
//! `3·S⁴` flops), and `f` over the cell lies in their convex hull. That bound
//! is much tighter than ACCC's (which bounds each weight separately), holds for
//! kernels with negative lobes, and tightens further by de Casteljau
//! subdivision. The 8 corner coefficients of any sub-cell are exact field
//! values, so the same recursion also *proves* crossings: two corners on
//! opposite sides of the iso-value.

use crate::filter::Field;
use crate::filter::kernel::binomial;
use crate::lattice::Lattice;

use super::{Tags, refine_cells, slack, support_minus_iso};

/// What the recursion learned about a cell.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// The hull excludes the iso-value: provably no crossing.
    NoCrossing,
    /// Two evaluated points lie on opposite sides: provably a crossing.
    Proven,
    /// Undecided at the depth limit.
    Unknown,
}

/// `β[i][p]`: weight polynomial `i` in the Bernstein basis of degree `S-1`.
pub fn bernstein_weights(field: &Field) -> Vec<f64> {
    let kernel = field.kernel();
    let s = kernel.support();
    let d = s - 1;
    let mut beta = vec![0.0; s * s];
    for i in 0..s {
        let a = kernel.weight_poly(i);
        for p in 0..s {
            beta[i * s + p] = (0..=p)
                .map(|m| binomial(p, m) / binomial(d, m) * a[m])
                .sum();
        }
    }
    beta
}

/// Applies `β` along `axis` of an `s³` tensor (x fastest).
fn transform(src: &[f64], s: usize, axis: usize, beta: &[f64]) -> Vec<f64> {
    let stride = [1, s, s * s][axis];
    let mut out = vec![0.0; s * s * s];
    for (idx, o) in out.iter_mut().enumerate() {
        let p = (idx / stride) % s;
        let base = idx - p * stride;
        let mut acc = 0.0;
        for i in 0..s {
            acc += src[base + i * stride] * beta[i * s + p];
        }
        *o = acc;
    }
    out
}

/// Tensor Bernstein coefficients of `f - iso` over a cell.
pub fn cell_bernstein(field: &Field, cell: [i64; 3], iso: f64, beta: &[f64]) -> Vec<f64> {
    let s = field.kernel().support();
    let c = support_minus_iso(field, cell, iso);
    let x = transform(&c, s, 0, beta);
    let y = transform(&x, s, 1, beta);
    transform(&y, s, 2, beta)
}

/// de Casteljau split at 1/2 along `axis`.
fn split(b: &[f64], s: usize, axis: usize) -> (Vec<f64>, Vec<f64>) {
    let stride = [1, s, s * s][axis];
    let mut left = vec![0.0; b.len()];
    let mut right = vec![0.0; b.len()];
    let mut work = vec![0.0; s];
    for base in 0..b.len() {
        if !(base / stride).is_multiple_of(s) {
            continue;
        }
        for (i, w) in work.iter_mut().enumerate() {
            *w = b[base + i * stride];
        }
        left[base] = work[0];
        right[base + (s - 1) * stride] = work[s - 1];
        for r in 1..s {
            for i in 0..s - r {
                work[i] = 0.5 * (work[i] + work[i + 1]);
            }
            left[base + r * stride] = work[0];
            right[base + (s - 1 - r) * stride] = work[s - 1 - r];
        }
    }
    (left, right)
}

/// Decides a Bernstein patch, subdividing up to `depth` times.
pub fn decide(b: &[f64], s: usize, depth: u8, eps: f64) -> Verdict {
    let above = b.iter().any(|&v| v > -eps);
    let below = b.iter().any(|&v| v <= eps);
    if !above || !below {
        return Verdict::NoCrossing;
    }
    let corner =
        |x: usize, y: usize, z: usize| b[x * (s - 1) + s * (y * (s - 1) + s * z * (s - 1))];
    let (mut pos, mut neg) = (false, false);
    for z in 0..2 {
        for y in 0..2 {
            for x in 0..2 {
                let v = corner(x, y, z);
                pos |= v > eps;
                neg |= v <= -eps;
            }
        }
    }
    if pos && neg {
        return Verdict::Proven;
    }
    if depth == 0 {
        return Verdict::Unknown;
    }
    let mut unknown = false;
    let (l, r) = split(b, s, 0);
    for half in [l, r] {
        let (l, r) = split(&half, s, 1);
        for quarter in [l, r] {
            let (l, r) = split(&quarter, s, 2);
            for child in [l, r] {
                match decide(&child, s, depth - 1, eps) {
                    Verdict::Proven => return Verdict::Proven,
                    Verdict::Unknown => unknown = true,
                    Verdict::NoCrossing => {}
                }
            }
        }
    }
    if unknown {
        Verdict::Unknown
    } else {
        Verdict::NoCrossing
    }
}

/// Re-decides the cells `coarse` tagged by their Bézier hulls. With
/// `proven_only`, keeps only cells with a proven crossing (the lower bound of
/// the truth); otherwise keeps every cell not proven empty (conservative).
pub fn refine(
    field: &Field,
    lattice: &Lattice,
    iso: f64,
    coarse: &Tags,
    depth: u8,
    proven_only: bool,
) -> Tags {
    let beta = bernstein_weights(field);
    let s = field.kernel().support();
    let eps = slack(field);
    refine_cells(lattice, coarse, |cell| {
        let b = cell_bernstein(field, cell, iso, &beta);
        match decide(&b, s, depth, eps) {
            Verdict::Proven => true,
            Verdict::Unknown => !proven_only,
            Verdict::NoCrossing => false,
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::FilterKind;
    use crate::volume::{SampleType, Volume};
    use glam::DVec3;

    #[test]
    fn bernstein_corners_are_field_values_and_hull_bounds() {
        let dims = [7usize, 6, 8];
        let s: Vec<f32> = (0..dims.iter().product::<usize>())
            .map(|i| ((i * 7919) % 251) as f32)
            .collect();
        let vol = Volume::new(dims, [1.0; 3], SampleType::U8, s).unwrap();
        for name in ["linear", "catmull-rom", "bspline2", "bspline3", "bspline6"] {
            let f = Field::new(&vol, FilterKind::parse(name, 0.0).unwrap());
            let lat = Lattice::new(f.kernel(), dims);
            let beta = bernstein_weights(&f);
            let sup = f.kernel().support();
            let cell = [2i64, 2, 3];
            let b = cell_bernstein(&f, cell, 0.0, &beta);
            let lo = b.iter().cloned().fold(f64::INFINITY, f64::min);
            let hi = b.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
            let origin = cell.map(|c| c as f64 - lat.offset);
            for q in 0..64 {
                let t = [
                    (q % 4) as f64 / 3.0,
                    (q / 4 % 4) as f64 / 3.0,
                    (q / 16) as f64 / 3.0,
                ];
                let v = f.value(DVec3::new(
                    origin[0] + t[0],
                    origin[1] + t[1],
                    origin[2] + t[2],
                ));
                assert!(
                    v >= lo - 1e-9 && v <= hi + 1e-9,
                    "{name}: {v} outside [{lo}, {hi}]"
                );
            }
            let corner = b[0];
            let v0 = f.value(DVec3::from_array(origin));
            assert!(
                (corner - v0).abs() < 1e-9,
                "{name}: corner {corner} vs {v0}"
            );
            let last = b[sup * sup * sup - 1];
            let v1 = f.value(DVec3::from_array(origin.map(|x| x + 1.0)));
            assert!((last - v1).abs() < 1e-9, "{name}: corner {last} vs {v1}");
        }
    }
}
