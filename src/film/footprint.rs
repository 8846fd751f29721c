//! Footprint filtering: the backdrop integrated over the pixel's filter mapped
//! through the local Jacobian `J = [dM/dx, dM/dy]` of the hit map.
//!
//! - **Box**: the pixel square maps to a parallelogram; its checker coverage
//!   is computed exactly by polygon clipping, photographs are sampled `n×n`
//!   over it.
//! - **EWA** (Heckbert 1989): the pixel's filter is an isotropic Gaussian of
//!   standard deviation [`EWA_SIGMA`] pixels, which `J` maps to an elliptical
//!   Gaussian of covariance `Σ = σ² J Jᵀ` on the backdrop. For a checker its
//!   integral is computed to ~1e-6: exactly (sums of `Φ`) when the ellipse
//!   meets edges of one direction only, by the Fourier series of the checker
//!   when the ellipse is wide (≥ 1/4 square across), and otherwise by exact
//!   integration along a direction transversal to both edge families and
//!   Gauss–Legendre quadrature across it, split at every checker corner.
//!   For a photograph the texels inside the ellipse are averaged with
//!   Gaussian weights, the ellipse widened by the bilinear reconstruction's
//!   own variance (1/6 texel² per axis), as in Heckbert's EWA.

use crate::scene::{Backdrop, FootprintFilter, Pattern, Texture};

/// Standard deviation of the EWA pixel filter, in pixels: the variance of the
/// unit box (1/12), so EWA and box filter blur equally.
pub const EWA_SIGMA: f64 = 0.288_675_134_594_812_9;

/// Truncation radius of the Gaussian in standard deviations (mass beyond:
/// below 6e-7 in one dimension).
const RADIUS: f64 = 5.0;

/// Most checker lines a thin ellipse's integral crosses before one half is
/// taken instead (each line costs a normal CDF per quadrature node).
const MAX_TRANSVERSAL_LINES: i64 = 4096;

/// Squares (or texels) from the origin beyond which a footprint is not
/// integrated: past 2^52 neighbouring edges are no longer distinct `f64`
/// values, and indices must stay far inside `i64`.
const FAR: f64 = 4.5e15;

/// Most inner checker corners evaluated one bivariate normal CDF each.
const LATTICE_CORNERS: i64 = 16;

/// The filtered backdrop colour of a pixel whose centre maps to `centre` with
/// Jacobian `j` (columns `dM/dx`, `dM/dy`).
pub fn filter(
    backdrop: &Backdrop,
    centre: [f64; 2],
    j: [[f64; 2]; 2],
    kind: FootprintFilter,
    samples: u32,
) -> [f32; 3] {
    match &backdrop.pattern {
        Pattern::Checker { size, colors } => {
            let white = match kind {
                FootprintFilter::Box => box_coverage(centre, j, *size),
                FootprintFilter::Ewa => gaussian_coverage(centre, j, EWA_SIGMA, *size),
            };
            let w = white as f32;
            std::array::from_fn(|k| colors[1][k] + (colors[0][k] - colors[1][k]) * w)
        }
        Pattern::Image(t) => match kind {
            FootprintFilter::Box => {
                let n = samples.max(1) as usize;
                let mut acc = [0.0f64; 3];
                for k in 0..n * n {
                    let a = ((k % n) as f64 + 0.5) / n as f64 - 0.5;
                    let b = ((k / n) as f64 + 0.5) / n as f64 - 0.5;
                    let c = t.sample(
                        centre[0] + a * j[0][0] + b * j[1][0],
                        centre[1] + a * j[0][1] + b * j[1][1],
                    );
                    for i in 0..3 {
                        acc[i] += c[i] as f64;
                    }
                }
                acc.map(|v| (v / (n * n) as f64) as f32)
            }
            FootprintFilter::Ewa => ewa_texture(t, centre, j, EWA_SIGMA),
        },
    }
}

fn parity_white(u: f64, v: f64) -> f64 {
    if (u.floor() + v.floor()).rem_euclid(2.0) == 0.0 {
        1.0
    } else {
        0.0
    }
}

/// White share of the box footprint: the pixel square through `j`.
pub fn box_coverage(centre: [f64; 2], j: [[f64; 2]; 2], size: f64) -> f64 {
    let corner = |a: f64, b: f64| {
        [
            centre[0] + a * j[0][0] + b * j[1][0],
            centre[1] + a * j[0][1] + b * j[1][1],
        ]
    };
    let quad = [
        corner(-0.5, -0.5),
        corner(0.5, -0.5),
        corner(0.5, 0.5),
        corner(-0.5, 0.5),
    ];
    checker_coverage(&quad, size)
        .unwrap_or_else(|| parity_white(centre[0] / size, centre[1] / size))
}

/// Checker squares a footprint may be clipped against, one at a time, before
/// one half is taken instead (see [`checker_coverage`]).
const MAX_CLIPPED_SQUARES: usize = 16_384;

/// The largest error, as a share of the footprint's area, that the one-half
/// shortcut of [`checker_coverage`] may make.
const HALF_TOLERANCE: f64 = 1.0 / 64.0;

/// Fraction of the convex polygon `quad` covered by even checker squares
/// (`floor(u/s) + floor(v/s)` even), exactly, by clipping against every square
/// it overlaps, a row of squares at a time.
///
/// A footprint whose bounding box spans more than 4096 squares is reported
/// as one half where that is provably within [`HALF_TOLERANCE`]: along any line the white and
/// black lengths differ by at most one square's side `s`, so the white area
/// differs from half the area `A` by at most `s·min(W, H)/2` for a polygon of
/// extent `W × H`. A thin sliver along a diagonal stays in squares of one
/// colour however long it is, so it is clipped square by square, up to
/// [`MAX_CLIPPED_SQUARES`]; a sliver longer still gets one half, the share
/// of every direction but the exact diagonals. `None` for a degenerate
/// polygon or one too far out for its squares to be told apart in `f64`:
/// the caller point-samples those.
pub fn checker_coverage(quad: &[[f64; 2]; 4], size: f64) -> Option<f64> {
    let area = polygon_area(quad);
    if !area.is_finite() || area <= 1e-18 * size * size {
        return None;
    }
    let (mut u0, mut u1, mut v0, mut v1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for p in quad {
        u0 = u0.min(p[0]);
        u1 = u1.max(p[0]);
        v0 = v0.min(p[1]);
        v1 = v1.max(p[1]);
    }
    let squares = ((u1 - u0) / size + 1.0) * ((v1 - v0) / size + 1.0);
    if squares > 4096.0 && 0.5 * size * (u1 - u0).min(v1 - v0) <= HALF_TOLERANCE * area {
        return Some(0.5);
    }
    if [u0, u1, v0, v1].iter().any(|&x| (x / size).abs() >= FAR) {
        return None;
    }
    let (j0, j1) = ((v0 / size).floor() as i64, (v1 / size).floor() as i64);
    if j1 - j0 >= MAX_CLIPPED_SQUARES as i64 {
        return Some(0.5);
    }
    let mut white = 0.0;
    let mut clipped = 0usize;
    let mut strip: Vec<[f64; 2]> = Vec::with_capacity(8);
    let mut poly: Vec<[f64; 2]> = Vec::with_capacity(8);
    let mut tmp: Vec<[f64; 2]> = Vec::with_capacity(8);
    for j in j0..=j1 {
        let (b0, b1) = (j as f64 * size, (j + 1) as f64 * size);
        // The row's piece of the footprint, and the squares it spans.
        strip.clear();
        strip.extend_from_slice(quad);
        for (bound, keep_above) in [(b0, true), (b1, false)] {
            clip(&strip, &mut tmp, 1, bound, keep_above);
            std::mem::swap(&mut strip, &mut tmp);
        }
        if strip.len() < 3 {
            continue;
        }
        let (lo, hi) = strip
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p[0]), hi.max(p[0]))
            });
        let (i0, i1) = ((lo / size).floor() as i64, (hi / size).floor() as i64);
        clipped += (i1 - i0 + 1) as usize;
        if clipped > MAX_CLIPPED_SQUARES {
            return Some(0.5);
        }
        // The first even square of the row, then every other one.
        for i in ((i0 + (i0 + j).rem_euclid(2))..=i1).step_by(2) {
            poly.clear();
            poly.extend_from_slice(&strip);
            let (a0, a1) = (i as f64 * size, (i + 1) as f64 * size);
            for (bound, keep_above) in [(a0, true), (a1, false)] {
                clip(&poly, &mut tmp, 0, bound, keep_above);
                std::mem::swap(&mut poly, &mut tmp);
                if poly.is_empty() {
                    break;
                }
            }
            if poly.len() >= 3 {
                white += polygon_area(&poly);
            }
        }
    }
    Some((white / area).clamp(0.0, 1.0))
}

/// Sutherland–Hodgman against one axis-aligned half-plane.
fn clip(src: &[[f64; 2]], dst: &mut Vec<[f64; 2]>, axis: usize, bound: f64, keep_above: bool) {
    dst.clear();
    let inside = |p: &[f64; 2]| {
        if keep_above {
            p[axis] >= bound
        } else {
            p[axis] <= bound
        }
    };
    for k in 0..src.len() {
        let (a, b) = (src[k], src[(k + 1) % src.len()]);
        let (ia, ib) = (inside(&a), inside(&b));
        if ia {
            dst.push(a);
        }
        if ia != ib {
            let t = (bound - a[axis]) / (b[axis] - a[axis]);
            dst.push([a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t]);
        }
    }
}

fn polygon_area(p: &[[f64; 2]]) -> f64 {
    let mut a = 0.0;
    for k in 0..p.len() {
        let (x0, y0) = (p[k][0], p[k][1]);
        let (x1, y1) = (p[(k + 1) % p.len()][0], p[(k + 1) % p.len()][1]);
        a += x0 * y1 - x1 * y0;
    }
    0.5 * a.abs()
}

/// `erfc(x)`, fractional error below 1.2e-7 everywhere (the Chebyshev fit of
/// Press et al., *Numerical Recipes*, §6.2).
pub fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = -z * z - 1.265_512_23
        + t * (1.000_023_68
            + t * (0.374_091_96
                + t * (0.096_784_18
                    + t * (-0.186_288_06
                        + t * (0.278_868_07
                            + t * (-1.135_203_98
                                + t * (1.488_515_87 + t * (-0.822_152_23 + t * 0.170_872_77))))))));
    let r = t * poly.exp();
    if x >= 0.0 { r } else { 2.0 - r }
}

/// The standard normal CDF.
#[inline]
pub fn phi_cdf(x: f64) -> f64 {
    0.5 * erfc(-x * std::f64::consts::FRAC_1_SQRT_2)
}

/// `E[sq(U)]` for `U ~ N(mu, sd²)` where `sq(u) = (-1)^floor(u)`: the 1-D
/// Gaussian-filtered square wave, exactly (truncated at [`RADIUS`]).
fn square_wave_mean(mu: f64, sd: f64) -> f64 {
    if sd <= 0.0 {
        return if mu.floor().rem_euclid(2.0) == 0.0 {
            1.0
        } else {
            -1.0
        };
    }
    // Beyond four squares' deviation the mean is below exp(-8π²) ≈ 1e-34
    // (its Fourier series): zero, without a loop over every square.
    if sd > 4.0 {
        return 0.0;
    }
    let (lo, hi) = (mu - RADIUS * sd, mu + RADIUS * sd);
    let (m0, m1) = (lo.floor() as i64, hi.floor() as i64);
    let mut acc = 0.0;
    let mut prev = phi_cdf(-RADIUS);
    for m in m0..=m1 {
        let end = if m == m1 {
            phi_cdf(RADIUS)
        } else {
            phi_cdf(((m + 1) as f64 - mu) / sd)
        };
        let sign = if m.rem_euclid(2) == 0 { 1.0 } else { -1.0 };
        acc += sign * (end - prev);
        prev = end;
    }
    acc / (phi_cdf(RADIUS) - phi_cdf(-RADIUS))
}

/// Gauss–Legendre nodes and weights on [-1, 1] (Newton on the Legendre
/// polynomial from the usual initial guesses).
fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    use std::f64::consts::PI;
    (0..n)
        .map(|i| {
            let mut x = (PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
            let mut dp = 1.0;
            for _ in 0..100 {
                // P_n(x) and P_n'(x) by the three-term recurrence.
                let (mut p0, mut p1) = (1.0, x);
                for k in 2..=n {
                    let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                    p0 = p1;
                    p1 = p2;
                }
                dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
                let dx = p1 / dp;
                x -= dx;
                if dx.abs() < 1e-16 {
                    break;
                }
            }
            (x, 2.0 / ((1.0 - x * x) * dp * dp))
        })
        .collect()
}

fn gl8() -> &'static [(f64, f64)] {
    static GL: std::sync::OnceLock<Vec<(f64, f64)>> = std::sync::OnceLock::new();
    GL.get_or_init(|| gauss_legendre(8))
}

fn gl20() -> &'static [(f64, f64)] {
    static GL: std::sync::OnceLock<Vec<(f64, f64)>> = std::sync::OnceLock::new();
    GL.get_or_init(|| gauss_legendre(20))
}

/// The bivariate standard normal CDF `P(X ≤ h, Y ≤ k)` with correlation `r`,
/// `|r| ≤ 0.9`: `Φ(h)Φ(k)` plus the density integrated over the correlation
/// (d/dr of the CDF is the density), with `r = sin θ`:
/// `(1/2π) ∫_0^{asin r} exp(-(h² + k² - 2hk sin θ) / (2 cos² θ)) dθ`, by
/// 20-point Gauss–Legendre: the integrand is smooth while `cos θ` stays away
/// from 0.
pub fn bvn_cdf(h: f64, k: f64, r: f64) -> f64 {
    let base = phi_cdf(h) * phi_cdf(k);
    if r == 0.0 {
        return base;
    }
    let top = r.asin();
    let (hh, hk) = (h * h + k * k, 2.0 * h * k);
    let mut acc = 0.0;
    for &(x, w) in gl20() {
        let t = 0.5 * top * (x + 1.0);
        let (sn, cs) = t.sin_cos();
        acc += w * (-(hh - hk * sn) / (2.0 * cs * cs)).exp();
    }
    base + acc * 0.5 * top / (2.0 * std::f64::consts::PI)
}

/// White share of a checker window by the lattice of its corners: with
/// `F(x, y) = P(U ≤ x, V ≤ y)`, every cell's mass is `F` at its four corners,
/// so the white mass is a signed sum of `F` over the lattice (±2 at every
/// inner corner, marginals at the infinite ends).
fn lattice_coverage(
    c: [f64; 2],
    (su, sv, r): (f64, f64, f64),
    (m0, m1): (i64, i64),
    (k0, k1): (i64, i64),
) -> f64 {
    // Lines: -∞, m0+1, ..., m1, +∞ (and likewise in v); cell (i, j) has
    // floor(u) = m0 + i, floor(v) = k0 + j.
    let (nm, nk) = (m1 - m0, k1 - k0);
    let white = |i: i64, j: i64| -> f64 {
        if i < 0 || j < 0 || i > nm || j > nk || (m0 + i + k0 + j).rem_euclid(2) != 0 {
            0.0
        } else {
            1.0
        }
    };
    let mut acc = 0.0;
    for p in 1..=nm + 1 {
        for q in 1..=nk + 1 {
            let coef = white(p - 1, q - 1) - white(p, q - 1) - white(p - 1, q) + white(p, q);
            if coef == 0.0 {
                continue;
            }
            let h = ((m0 + p) as f64 - c[0]) / su;
            let k = ((k0 + q) as f64 - c[1]) / sv;
            let f = match (p == nm + 1, q == nk + 1) {
                (true, true) => 1.0,
                (true, false) => phi_cdf(k),
                (false, true) => phi_cdf(h),
                (false, false) => bvn_cdf(h, k, r),
            };
            acc += coef * f;
        }
    }
    acc.clamp(0.0, 1.0)
}

/// White share of the checker (unit squares, after dividing by `size`) under
/// the Gaussian `N(centre, σ² J Jᵀ)`: the pixel's isotropic Gaussian filter of
/// standard deviation `sigma` pixels mapped through `j`.
pub fn gaussian_coverage(centre: [f64; 2], j: [[f64; 2]; 2], sigma: f64, size: f64) -> f64 {
    let c = [centre[0] / size, centre[1] / size];
    // Pixel-space gradients of u and v (per pixel), in squares.
    let gu = [j[0][0] / size, j[1][0] / size];
    let gv = [j[0][1] / size, j[1][1] / size];
    let s2 = sigma * sigma;
    let suu = s2 * (gu[0] * gu[0] + gu[1] * gu[1]);
    let svv = s2 * (gv[0] * gv[0] + gv[1] * gv[1]);
    let suv = s2 * (gu[0] * gv[0] + gu[1] * gv[1]);
    let (hu, hv) = (RADIUS * suu.sqrt(), RADIUS * svv.sqrt());
    // A footprint reaching past [`FAR`] is point-sampled, as a degenerate
    // one is.
    if !(c[0].abs() + hu < FAR && c[1].abs() + hv < FAR) {
        return parity_white(c[0], c[1]);
    }
    let (m0, m1) = ((c[0] - hu).floor() as i64, (c[0] + hu).floor() as i64);
    let (k0, k1) = ((c[1] - hv).floor() as i64, (c[1] + hv).floor() as i64);
    let u_edges = m0 != m1;
    let v_edges = k0 != k1;
    if !u_edges && !v_edges {
        return parity_white(c[0], c[1]);
    }
    // Edges of one direction only: the square wave along the other is constant.
    if !v_edges {
        let sv = if c[1].floor().rem_euclid(2.0) == 0.0 {
            1.0
        } else {
            -1.0
        };
        return 0.5 * (1.0 + sv * square_wave_mean(c[0], suu.sqrt()));
    }
    if !u_edges {
        let su = if c[0].floor().rem_euclid(2.0) == 0.0 {
            1.0
        } else {
            -1.0
        };
        return 0.5 * (1.0 + su * square_wave_mean(c[1], svv.sqrt()));
    }
    // Wide ellipses: the Fourier series of the checker converges in a few terms.
    let tr = suu + svv;
    let det = (suu * svv - suv * suv).max(0.0);
    let lmin = 0.5 * (tr - (tr * tr - 4.0 * det).max(0.0).sqrt());
    if lmin >= 1.0 / 16.0 {
        return 0.5 * (1.0 + fourier_product(c, suu, suv, svv, lmin));
    }
    let corners = (m1 - m0).saturating_mul(k1 - k0);
    let (su, sv) = (suu.sqrt(), svv.sqrt());
    let r = suv / (su * sv);
    if corners <= LATTICE_CORNERS && r.abs() <= 0.9 {
        return lattice_coverage(c, (su, sv, r), (m0, m1), (k0, k1));
    }
    if corners > 4096 {
        // Thousands of squares under a thin ellipse. Given `V`, `U` is normal
        // with variance `det/svv`, and the square wave's mean under it is at
        // most `(4/π) Σ_{k odd} exp(-k²π² var/2)/k` (its Fourier series);
        // likewise with `U` and `V` swapped. Where that is small the white
        // share is one half; a thin ellipse along a diagonal stays on squares
        // of one colour, so it is integrated, its lines permitting.
        let var = det / suu.min(svv);
        if 0.5 * square_wave_bound(var) <= HALF_TOLERANCE {
            return 0.5;
        }
        if (m1 - m0) + (k1 - k0) > MAX_TRANSVERSAL_LINES {
            // Too long to integrate: one half, as for every direction but
            // the exact diagonals.
            return 0.5;
        }
    }
    transversal_coverage(c, gu, gv, sigma, (m0, m1), (k0, k1), corners <= 32)
}

/// An upper bound of `|E[sq(U)]|` for `U` normal with variance `var`, from
/// the square wave's Fourier series: `(4/π) Σ_{k odd} exp(-k²π² var/2)/k`,
/// summed while its terms matter (at least once; 1 for `var = 0`).
fn square_wave_bound(var: f64) -> f64 {
    use std::f64::consts::PI;
    if var.is_nan() || var <= 0.0 {
        return 1.0;
    }
    let mut acc = 0.0;
    let mut k = 1.0f64;
    loop {
        let term = (-0.5 * k * k * PI * PI * var).exp() / k;
        acc += term;
        if term < 1e-6 || 4.0 / PI * acc >= 1.0 {
            break;
        }
        k += 2.0;
    }
    (4.0 / PI * acc).min(1.0)
}

/// `E[sq(U) sq(V)]` for `(U, V) ~ N(c, Σ)` from the Fourier series of the
/// square waves, `sq(u) = (4/π) Σ_{k odd} sin(kπu)/k`, with every term whose
/// Gaussian damping exceeds 1e-10.
fn fourier_product(c: [f64; 2], suu: f64, suv: f64, svv: f64, lmin: f64) -> f64 {
    use std::f64::consts::PI;
    let q = |a: f64, b: f64| a * a * suu + 2.0 * a * b * suv + b * b * svv;
    let mut acc = 0.0;
    let mut k = 1;
    // exp(-½ λmin π² (k² + l²)) bounds every term's damping.
    let damp = |k: i64, l: i64| (-0.5 * lmin * PI * PI * ((k * k + l * l) as f64)).exp();
    while damp(k, 1) > 1e-10 {
        let mut l = 1;
        while damp(k, l) > 1e-10 {
            let (a, b) = (k as f64 * PI, l as f64 * PI);
            let minus = (a * c[0] - b * c[1]).cos() * (-0.5 * q(a, -b)).exp();
            let plus = (a * c[0] + b * c[1]).cos() * (-0.5 * q(a, b)).exp();
            acc += 0.5 * (minus - plus) / (k * l) as f64;
            l += 2;
        }
        k += 2;
    }
    acc * 16.0 / (PI * PI)
}

/// The general case: integrate exactly along a pixel-space direction `d`
/// transversal to both edge families (each family's lines cross it at ≥ 45°),
/// and by Gauss–Legendre across it in pieces of ≤ 2σ, split at every checker
/// corner (where the exact inner integral has a kink) unless there are too
/// many to matter one by one.
fn transversal_coverage(
    c: [f64; 2],
    gu: [f64; 2],
    gv: [f64; 2],
    sigma: f64,
    (m0, m1): (i64, i64),
    (k0, k1): (i64, i64),
    cut_at_corners: bool,
) -> f64 {
    let norm = |g: [f64; 2]| {
        let l = (g[0] * g[0] + g[1] * g[1]).sqrt();
        [g[0] / l, g[1] / l]
    };
    let (nu, nv) = (norm(gu), norm(gv));
    let dot = nu[0] * nv[0] + nu[1] * nv[1];
    let d = if dot >= 0.0 {
        norm([nu[0] + nv[0], nu[1] + nv[1]])
    } else {
        norm([nu[0] - nv[0], nu[1] - nv[1]])
    };
    let e = [-d[1], d[0]];
    // u(x, w) = c_u + x·au + w·bu along d (x) and across it (w).
    let (au, bu) = (gu[0] * d[0] + gu[1] * d[1], gu[0] * e[0] + gu[1] * e[1]);
    let (av, bv) = (gv[0] * d[0] + gv[1] * d[1], gv[0] * e[0] + gv[1] * e[1]);
    let wmax = RADIUS * sigma;
    // Corners: u = m and v = k.
    let det = au * bv - av * bu;
    let mut cuts: Vec<f64> = vec![-wmax, wmax];
    if cut_at_corners && det.abs() > 1e-300 {
        for m in (m0 + 1)..=m1 {
            for k in (k0 + 1)..=k1 {
                let (du, dv) = (m as f64 - c[0], k as f64 - c[1]);
                let w = (au * dv - av * du) / det;
                if w.abs() < wmax {
                    cuts.push(w);
                }
            }
        }
    }
    cuts.sort_by(f64::total_cmp);
    let mut breaks: Vec<f64> = Vec::with_capacity(16);
    // The exact inner integral at offset w across d.
    let mut inner = |w: f64| -> f64 {
        let (cu, cv) = (c[0] + w * bu, c[1] + w * bv);
        let xmax = RADIUS * sigma;
        breaks.clear();
        for (c0, a) in [(cu, au), (cv, av)] {
            if a.abs() < 1e-300 {
                continue;
            }
            let (lo, hi) = if a > 0.0 {
                (c0 - xmax * a, c0 + xmax * a)
            } else {
                (c0 + xmax * a, c0 - xmax * a)
            };
            for m in (lo.floor() as i64 + 1)..=(hi.floor() as i64) {
                breaks.push((m as f64 - c0) / a);
            }
        }
        breaks.push(xmax);
        breaks.sort_by(f64::total_cmp);
        let mut prev_x = -xmax;
        let mut prev_p = phi_cdf(-RADIUS);
        let mut acc = 0.0;
        for &x in breaks.iter() {
            if x <= prev_x {
                continue;
            }
            let p = phi_cdf(x / sigma);
            let mid = 0.5 * (prev_x + x);
            acc += parity_white(cu + mid * au, cv + mid * av) * (p - prev_p);
            prev_x = x;
            prev_p = p;
        }
        acc
    };
    let mut total = 0.0;
    let mut mass = 0.0;
    let gauss = |w: f64| (-0.5 * (w / sigma).powi(2)).exp();
    for win in cuts.windows(2) {
        let (a, b) = (win[0], win[1]);
        if b <= a {
            continue;
        }
        let pieces = ((b - a) / (2.0 * sigma)).ceil().max(1.0) as usize;
        let h = (b - a) / pieces as f64;
        for p in 0..pieces {
            let mid = a + (p as f64 + 0.5) * h;
            for &(x, wt) in gl8() {
                let w = mid + 0.5 * h * x;
                let g = 0.5 * h * wt * gauss(w);
                total += g * inner(w);
                mass += g * (phi_cdf(RADIUS) - phi_cdf(-RADIUS));
            }
        }
    }
    (total / mass).clamp(0.0, 1.0)
}

/// EWA over a photograph: texels weighted by the elliptical Gaussian in
/// texel space (the pixel's Gaussian through `j`, widened by the bilinear
/// reconstruction's variance, 1/6 texel² per axis), truncated at 3σ. Ellipses
/// over more than 4096 texels are sampled on a coarser texel lattice.
pub fn ewa_texture(t: &Texture, centre: [f64; 2], j: [[f64; 2]; 2], sigma: f64) -> [f32; 3] {
    let (sx, sy) = (
        t.width_px as f64 / t.world_width,
        -(t.height_px as f64) / t.world_height(),
    );
    // Texel coordinates as in Texture::sample (centres at +0.5).
    let cx = (centre[0] / t.world_width + 0.5) * t.width_px as f64 - 0.5;
    let cy = (0.5 - centre[1] / t.world_height()) * t.height_px as f64 - 0.5;
    let jt = [[j[0][0] * sx, j[0][1] * sy], [j[1][0] * sx, j[1][1] * sy]];
    let s2 = sigma * sigma;
    const RECON: f64 = 1.0 / 6.0;
    let a = s2 * (jt[0][0] * jt[0][0] + jt[1][0] * jt[1][0]) + RECON;
    let c = s2 * (jt[0][1] * jt[0][1] + jt[1][1] * jt[1][1]) + RECON;
    let b = s2 * (jt[0][0] * jt[0][1] + jt[1][0] * jt[1][1]);
    // `ac - b²` by Lagrange's identity, a sum of non-negative terms: the
    // difference cancels to nothing, or below zero, for a long footprint of
    // nearly one direction (a Jacobian column zeroed for want of a neighbour).
    let det_jt = jt[0][0] * jt[1][1] - jt[1][0] * jt[0][1];
    let det = s2 * s2 * det_jt * det_jt + RECON * (a + c - 2.0 * RECON) + RECON * RECON;
    const R: f64 = 3.0;
    let (hx, hy) = (R * a.sqrt(), R * c.sqrt());
    // Texel indices as integers: an ellipse past [`FAR`] texels (rays
    // grazing the backdrop) is point-sampled.
    if !(det.is_finite() && cx.abs() + hx < FAR && cy.abs() + hy < FAR) {
        return t.sample(centre[0], centre[1]);
    }
    // The inverse covariance's quadratic form, `(c dx² - 2b dx dy + a dy²)/det`,
    // completed to the square `(a dy - b dx)²/(a det) + dx²/a`: a sum of
    // non-negative terms, where the form as written cancels below zero
    // (and `exp` overflows) for a long, thin ellipse.
    let (inv_a, inv_a_det) = (1.0 / a, 1.0 / (a * det));
    let (x0, x1) = ((cx - hx).ceil() as i64, (cx + hx).floor() as i64);
    let (y0, y1) = ((cy - hy).ceil() as i64, (cy + hy).floor() as i64);
    // At most about 4096 texels visited: a stride per axis, so that a long
    // thin ellipse along an axis is thinned along its length, not across.
    let (nx, ny) = ((x1 - x0 + 1).max(1) as u64, (y1 - y0 + 1).max(1) as u64);
    let stride_y = ny.div_ceil(64);
    let per_row = (4096 / ny.div_ceil(stride_y)).max(1);
    let (stride_x, stride_y) = (nx.div_ceil(per_row) as i64, stride_y as i64);
    let mut acc = [0.0f64; 3];
    let mut wsum = 0.0;
    let mut yi = y0;
    while yi <= y1 {
        let dy = yi as f64 - cy;
        let mut xi = x0;
        while xi <= x1 {
            let dx = xi as f64 - cx;
            let across = a * dy - b * dx;
            let q = across * across * inv_a_det + dx * dx * inv_a;
            if q <= R * R {
                let w = (-0.5 * q).exp();
                let texel = if xi >= 0
                    && yi >= 0
                    && (xi as usize) < t.width_px
                    && (yi as usize) < t.height_px
                {
                    t.pixels[yi as usize * t.width_px + xi as usize]
                } else {
                    t.outside
                };
                for k in 0..3 {
                    acc[k] += w * texel[k] as f64;
                }
                wsum += w;
            }
            xi += stride_x;
        }
        yi += stride_y;
    }
    if wsum <= 0.0 {
        return t.sample(centre[0], centre[1]);
    }
    acc.map(|v| (v / wsum) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The Gaussian-weighted checker by brute force: a fine midpoint rule
    /// over the pixel-space Gaussian (±5σ), independent of every path above.
    fn brute(centre: [f64; 2], j: [[f64; 2]; 2], sigma: f64, size: f64) -> f64 {
        let n = 1200;
        let h = 10.0 * sigma / n as f64;
        let (mut acc, mut mass) = (0.0, 0.0);
        for b in 0..n {
            let y = -5.0 * sigma + (b as f64 + 0.5) * h;
            let gy = (-0.5 * (y / sigma).powi(2)).exp();
            for a in 0..n {
                let x = -5.0 * sigma + (a as f64 + 0.5) * h;
                let g = gy * (-0.5 * (x / sigma).powi(2)).exp();
                let u = centre[0] + x * j[0][0] + y * j[1][0];
                let v = centre[1] + x * j[0][1] + y * j[1][1];
                acc += g * parity_white(u / size, v / size);
                mass += g;
            }
        }
        acc / mass
    }

    #[test]
    fn erfc_and_normal_cdfs() {
        for (x, want) in [
            (0.0, 1.0),
            (0.5, 0.479_500_122_186_953_5),
            (1.0, 0.157_299_207_050_285_1),
            (2.0, 0.004_677_734_981_047_266),
            (-1.0, 1.842_700_792_949_715),
        ] {
            assert!((erfc(x) - want).abs() < 2e-7 * want.max(1e-3), "erfc({x})");
        }
        // Φ₂(0, 0; ρ) = 1/4 + asin(ρ)/2π; independence; symmetry.
        for r in [-0.9, -0.5, 0.3, 0.9] {
            let want = 0.25 + f64::asin(r) / (2.0 * std::f64::consts::PI);
            // (erfc, and so Φ(0)², is good to 1.2e-7.)
            assert!((bvn_cdf(0.0, 0.0, r) - want).abs() < 2e-7, "r = {r}");
        }
        assert!((bvn_cdf(0.7, -0.4, 0.0) - phi_cdf(0.7) * phi_cdf(-0.4)).abs() < 1e-15);
        assert!((bvn_cdf(0.7, -0.4, 0.6) - bvn_cdf(-0.4, 0.7, 0.6)).abs() < 1e-12);
        // Against P(X ≤ h, Y ≤ k) = ∫_{-∞}^h φ(x) Φ((k - ρx)/√(1-ρ²)) dx.
        let (h, k, r) = (0.8, -0.3, -0.7);
        let n = 200_000;
        let dx = (h + 9.0) / n as f64;
        let mut want = 0.0;
        for i in 0..n {
            let x = -9.0 + (i as f64 + 0.5) * dx;
            let dens = (-0.5 * x * x).exp() / (2.0 * std::f64::consts::PI).sqrt();
            want += dens * phi_cdf((k - r * x) / (1.0 - r * r).sqrt()) * dx;
        }
        assert!(
            (bvn_cdf(h, k, r) - want).abs() < 1e-6,
            "{} vs {want}",
            bvn_cdf(h, k, r)
        );
    }

    #[test]
    fn gaussian_coverage_matches_brute_force_on_every_path() {
        let s = EWA_SIGMA;
        type Case = ([f64; 2], [[f64; 2]; 2], &'static str);
        let cases: [Case; 6] = [
            // Edges of one direction only (u = 1 near the centre).
            ([0.98, 0.5], [[0.05, 0.01], [0.0, 0.04]], "1-D"),
            // One corner, correlated ellipse (lattice, one BVN).
            ([1.03, 0.97], [[0.15, 0.1], [-0.05, 0.2]], "corner"),
            // Several corners, moderate ellipse (lattice).
            ([0.4, 0.6], [[1.1, 0.4], [-0.3, 1.3]], "lattice"),
            // Wide ellipse (Fourier).
            ([0.3, 0.1], [[2.5, 0.8], [-0.6, 2.2]], "fourier"),
            // Thin ellipse along the checker diagonal, |r| > 0.9 (transversal).
            ([0.9, 1.05], [[0.6, 0.58], [0.02, -0.02]], "diagonal"),
            // Long thin ellipse over many corners (transversal, no cuts).
            ([0.2, 0.35], [[6.0, 1.5], [0.05, -0.1]], "long"),
        ];
        for (c, j, what) in cases {
            let got = gaussian_coverage(c, j, s, 1.0);
            let want = brute(c, j, s, 1.0);
            assert!(
                (got - want).abs() < 1e-3,
                "{what}: {got} vs brute force {want}"
            );
            // Scale invariance: the same footprint over squares of size 8.
            let j8 = [
                [8.0 * j[0][0], 8.0 * j[0][1]],
                [8.0 * j[1][0], 8.0 * j[1][1]],
            ];
            let got8 = gaussian_coverage([8.0 * c[0], 8.0 * c[1]], j8, s, 8.0);
            assert!((got - got8).abs() < 1e-9, "{what}: scale");
        }
        // Deep inside one square: its colour; a zero Jacobian point-samples.
        assert_eq!(
            gaussian_coverage([0.5, 0.5], [[0.01, 0.0], [0.0, 0.01]], s, 1.0),
            1.0
        );
        assert_eq!(gaussian_coverage([1.5, 0.5], [[0.0; 2]; 2], s, 1.0), 0.0);
    }

    #[test]
    fn gaussian_paths_agree_with_each_other() {
        // Where several exact methods apply they must agree far beyond the
        // brute-force tolerance.
        let s = EWA_SIGMA;
        for (c, j) in [
            ([1.03, 0.97], [[0.15, 0.1], [-0.05, 0.2]]),
            ([0.4, 0.6], [[1.1, 0.4], [-0.3, 1.3]]),
            ([2.7, -1.2], [[0.9, -0.2], [0.3, 1.0]]),
        ] {
            let gu = [j[0][0], j[1][0]];
            let gv = [j[0][1], j[1][1]];
            let s2 = s * s;
            let suu = s2 * (gu[0] * gu[0] + gu[1] * gu[1]);
            let svv = s2 * (gv[0] * gv[0] + gv[1] * gv[1]);
            let suv = s2 * (gu[0] * gv[0] + gu[1] * gv[1]);
            let (su, sv) = (suu.sqrt(), svv.sqrt());
            let m = (
                (c[0] - RADIUS * su).floor() as i64,
                (c[0] + RADIUS * su).floor() as i64,
            );
            let k = (
                (c[1] - RADIUS * sv).floor() as i64,
                (c[1] + RADIUS * sv).floor() as i64,
            );
            let lattice = lattice_coverage(c, (su, sv, suv / (su * sv)), m, k);
            let transversal = transversal_coverage(c, gu, gv, s, m, k, true);
            assert!(
                (lattice - transversal).abs() < 2e-5,
                "{lattice} vs {transversal}"
            );
            let tr = suu + svv;
            let lmin = 0.5 * (tr - (tr * tr - 4.0 * (suu * svv - suv * suv)).sqrt());
            if lmin > 0.01 {
                let fourier = 0.5 * (1.0 + fourier_product(c, suu, suv, svv, lmin.min(1.0 / 16.0)));
                assert!((lattice - fourier).abs() < 2e-5, "{lattice} vs {fourier}");
            }
        }
    }

    /// A 16×8 photograph 16 units wide, red ramping along x.
    fn ramp_texture(outside: f32) -> Texture {
        let (w, h) = (16, 8);
        Texture {
            width_px: w,
            height_px: h,
            pixels: (0..w * h)
                .map(|i| [(i % w) as f32 / 16.0, 0.5, 1.0])
                .collect(),
            world_width: 16.0,
            outside: [outside; 3],
        }
    }

    #[test]
    fn ewa_texture_averages_with_gaussian_weights() {
        // A ramp in x: symmetric weights around a texel centre return it.
        let tex = ramp_texture(0.0);
        // Texel (6, 3) has its centre at u = 6.5 - 8, v = 4 - 3.5.
        let c = ewa_texture(&tex, [-1.5, 0.5], [[1.0, 0.0], [0.0, 1.0]], 1.0);
        assert!(
            (c[0] - 6.0 / 16.0).abs() < 1e-5 && (c[1] - 0.5).abs() < 1e-6,
            "{c:?}"
        );
        // Stretched along x over the texture's edge: outside texels count.
        let e = ewa_texture(&tex, [7.5, 0.5], [[3.0, 0.0], [0.0, 0.1]], 1.0);
        assert!(e[2] < 0.9 && e[2] > 0.1, "{e:?}");
    }

    #[test]
    fn coverage_of_simple_footprints() {
        let sq =
            |u0: f64, v0: f64, w: f64| [[u0, v0], [u0 + w, v0], [u0 + w, v0 + w], [u0, v0 + w]];
        // Inside one white square, one black square, straddling four squares.
        assert_eq!(checker_coverage(&sq(0.1, 0.1, 0.5), 1.0), Some(1.0));
        assert_eq!(checker_coverage(&sq(1.1, 0.1, 0.5), 1.0), Some(0.0));
        let c = checker_coverage(&sq(0.5, 0.5, 1.0), 1.0).unwrap();
        assert!((c - 0.5).abs() < 1e-12);
        // A thin sliver u ∈ [v, v + 0.05] along the white diagonal clips a black
        // triangle of area 0.05²/2 at each of the 3 corners it passes.
        let d = [[0.2, 0.2], [0.25, 0.2], [3.25, 3.2], [3.2, 3.2]];
        let expect = 1.0 - 3.0 * 0.00125 / 0.15;
        assert!((checker_coverage(&d, 1.0).unwrap() - expect).abs() < 1e-9);
        // A rotated square over one corner of four squares: half and half.
        let r = [[1.0, 0.5], [1.5, 1.0], [1.0, 1.5], [0.5, 1.0]];
        assert!((checker_coverage(&r, 1.0).unwrap() - 0.5).abs() < 1e-12);
        assert!(checker_coverage(&[[0.0, 0.0]; 4], 1.0).is_none());
    }

    #[test]
    fn long_and_far_footprints_are_exact_or_bounded_and_finish() {
        // The sliver of the test above, 64 squares long: its bounding box
        // spans 4225 squares, but it stays on the white diagonal.
        let d = [[0.2, 0.2], [0.25, 0.2], [64.25, 64.2], [64.2, 64.2]];
        let expect = 1.0 - 64.0 * 0.00125 / (64.0 * 0.05);
        assert!((checker_coverage(&d, 1.0).unwrap() - expect).abs() < 1e-9);
        // Wide both ways: one half, within the tolerance the bound promises.
        let w = [[0.3, 0.1], [100.3, 0.1], [100.3, 80.1], [0.3, 80.1]];
        assert_eq!(checker_coverage(&w, 1.0), Some(0.5));
        // A sliver too long to clip, and footprints reaching 1e19 squares
        // (rays grazing the backdrop): an answer, not an endless loop.
        let long = [
            [0.2, 0.2],
            [0.25, 0.2],
            [1e5 + 0.25, 1e5 + 0.2],
            [1e5 + 0.2, 1e5 + 0.2],
        ];
        assert_eq!(checker_coverage(&long, 1.0), Some(0.5));
        let far = [[0.0, 0.0], [1e19, 0.0], [1e19, 1.0], [0.0, 1.0]];
        assert_eq!(checker_coverage(&far, 1.0), Some(0.5));
        let out = [
            [1e17, 0.0],
            [1e17 + 64.0, 0.0],
            [1e17 + 64.0, 1.0],
            [1e17, 1.0],
        ];
        assert_eq!(checker_coverage(&out, 1.0), None);
        assert!((0.0..=1.0).contains(&box_coverage([0.5, 0.5], [[1e19, 0.0], [0.0, 1e-30]], 1.0)));

        let s = EWA_SIGMA;
        // A thin ellipse along the diagonal over hundreds of squares: it
        // stays on white squares, as the brute-force integral shows.
        let (c, j) = ([0.5, 0.5], [[300.0, 300.0], [0.001, -0.001]]);
        let (got, want) = (gaussian_coverage(c, j, s, 1.0), brute(c, j, s, 1.0));
        assert!(want > 0.9 && (got - want).abs() < 0.01, "{got} vs {want}");
        // Wide across both families: one half (the Fourier series).
        let got = gaussian_coverage([0.5, 0.5], [[300.0, 0.0], [0.0, 300.0]], s, 1.0);
        assert!((got - 0.5).abs() < 1e-6, "{got}");
        // Thin across the rows but over 2108 columns and 3 rows (4216
        // corners, 2110 lines): the variance of u given v proves one half,
        // exactly, where the integral would give it to a few decimals.
        assert_eq!(
            gaussian_coverage([0.5, 1.5], [[730.0, 0.0], [0.0, 0.4]], s, 1.0),
            0.5
        );
        for j in [
            [[1e19, 0.0], [0.0, 0.0]],
            [[1e19, 1e19], [1e-3, -1e-3]],
            [[1e12, 0.0], [0.0, 1e-9]],
            [[f64::MAX, 0.0], [0.0, f64::MAX]],
        ] {
            let got = gaussian_coverage([0.5, 0.5], j, s, 1.0);
            assert!((0.0..=1.0).contains(&got), "{j:?}: {got}");
        }
    }

    #[test]
    fn ewa_texture_stays_finite_for_degenerate_and_huge_footprints() {
        let tex = ramp_texture(0.25);
        // One column zeroed (a missing neighbour): `ac - b²` computed as a
        // difference cancelled to zero or below for such Jacobians.
        for j in [
            [[7.19e8, 6.02e8], [0.0, 0.0]],
            [[3.3e9, -1.7e9], [0.0, 0.0]],
            [[1e19, 0.0], [0.0, 0.0]],
            [[1e6, 1e6], [1e-6, -1e-6]],
            [[f64::MAX, 0.0], [0.0, f64::MAX]],
        ] {
            let c = ewa_texture(&tex, [0.5, 0.5], j, EWA_SIGMA);
            assert!(c.iter().all(|v| v.is_finite()), "{j:?}: {c:?}");
        }
    }
}
