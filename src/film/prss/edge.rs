//! Where a boundary crosses a pixel, for the `blend` fallbacks: the pixel's
//! piece indicator over its 9×9 neighbourhood, blurred by a Gaussian, read
//! as one straight boundary (value `Φ(d/σ)`, gradient `φ(d/σ)/σ` along its
//! normal) or as none.

use crate::film::footprint;
use crate::film::hitmap::{HitMap, NO_HIT};

/// Standard deviation (pixels) of the Gaussian that blurs the piece
/// indicator to locate a boundary, and the window radius. A sampled straight
/// edge is a staircase; the blur averages its steps, the more so the wider it
/// is, at the price of bending boundaries and nearby features. Measured on
/// the sphere, ball, teapot and photo scenes at 256×256, σ from 0.8 to 1.5
/// changes PSNR by at most 0.4 dB (photo), best at 1.0–1.2.
const EDGE_SIGMA: f64 = 1.2;
const EDGE_RADIUS: i64 = 4;
const EDGE_SIDE: usize = 2 * EDGE_RADIUS as usize + 1;

/// A boundary of the pixel's piece, as a line: sub-point `t` (offset from
/// the centre, pixels) is on the pixel's own side when `d + n·t ≥ 0`.
#[derive(Clone, Copy, Debug)]
pub(super) struct EdgeLine {
    pub(super) d: f64,
    pub(super) n: [f64; 2],
}

/// `Φ⁻¹(p)` for `p ∈ (0, 1)`: Newton's method on [`footprint::phi_cdf`]
/// (monotone on either side of the root) from Acklam's rational
/// approximation of the quantile (its author gives a relative error below
/// 1.15e-9), each step an `erfc` and an `exp`. Over `p` in the fit's range
/// `[1e-4, 1 − 1e-4]` that takes 2 steps, the last one confirming; from 0
/// it took 5.2 on average and up to 13.
fn inverse_phi(p: f64) -> f64 {
    let mut x = quantile_guess(p);
    for _ in 0..60 {
        let f = footprint::phi_cdf(x) - p;
        let dens = (-0.5 * x * x).exp() / (2.0 * std::f64::consts::PI).sqrt();
        let dx = f / dens;
        x -= dx;
        if dx.abs() < 1e-10 {
            break;
        }
    }
    x
}

/// Acklam's approximation of the standard normal quantile, `p ∈ (0, 1)`
/// (0 outside, or for NaN: Newton's start before). The test
/// `inverse_phi_inverts_the_cdf` checks it within 1e-6 of the converged
/// quantile.
fn quantile_guess(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] = [
        7.784_695_709_041_462e-3,
        3.224_671_290_700_398e-1,
        2.445_134_137_142_996,
        3.754_408_661_907_416,
    ];
    const LOW: f64 = 0.024_25;
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    if !(p > 0.0 && p < 1.0) {
        0.0
    } else if p < LOW {
        tail((-2.0 * p.ln()).sqrt())
    } else if p > 1.0 - LOW {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

/// [`edge_line`]'s window: per pixel the Gaussian weight and its gradient
/// weights, and their sums over the whole window.
struct EdgeWeights {
    w: [[f64; 3]; EDGE_SIDE * EDGE_SIDE],
    full_den: f64,
    full_dden: [f64; 2],
}

/// [`EdgeWeights`] for [`EDGE_SIGMA`], computed once (81 `exp` per
/// boundary pixel cost 6% of the stage on the teapot; the 162 divisions for
/// the gradient weights 2% more).
fn edge_weights() -> &'static EdgeWeights {
    static WEIGHTS: std::sync::OnceLock<EdgeWeights> = std::sync::OnceLock::new();
    WEIGHTS.get_or_init(|| {
        let s2 = EDGE_SIGMA * EDGE_SIGMA;
        let w: [[f64; 3]; EDGE_SIDE * EDGE_SIDE] = std::array::from_fn(|k| {
            let i = (k % EDGE_SIDE) as i64 - EDGE_RADIUS;
            let j = (k / EDGE_SIDE) as i64 - EDGE_RADIUS;
            let w = (-((i * i + j * j) as f64) / (2.0 * s2)).exp();
            [w, i as f64 / s2 * w, j as f64 / s2 * w]
        });
        // The sums over a window inside the image, in the loops' order.
        let (mut den, mut dden) = (0.0, [0.0; 2]);
        for [w, gx, gy] in w {
            den += w;
            dden[0] += gx;
            dden[1] += gy;
        }
        EdgeWeights {
            w,
            full_den: den,
            full_dden: dden,
        }
    })
}

/// [`edge_line`]'s sums over the window: the weights of the pixels on the
/// centre's piece, of all pixels in the image, and the same for the
/// gradient weights.
#[derive(Clone, Copy, Debug, PartialEq)]
struct WindowSums {
    num: f64,
    den: f64,
    dnum: [f64; 2],
    dden: [f64; 2],
}

/// [`WindowSums`] of the window around `(x, y)`, wherever it lies.
fn window_sums(map: &HitMap, ew: &EdgeWeights, x: i64, y: i64, centre: Option<f32>) -> WindowSums {
    let r = EDGE_RADIUS;
    let mut s = WindowSums {
        num: 0.0,
        den: 0.0,
        dnum: [0.0; 2],
        dden: [0.0; 2],
    };
    for j in -r..=r {
        for i in -r..=r {
            if !map.inside(x + i, y + j) {
                continue;
            }
            let [w, gx, gy] = ew.w[((j + r) * EDGE_SIDE as i64 + i + r) as usize];
            let same = map.same_piece(x + i, y + j, centre);
            s.den += w;
            s.dden[0] += gx;
            s.dden[1] += gy;
            if same {
                s.num += w;
                s.dnum[0] += gx;
                s.dnum[1] += gy;
            }
        }
    }
    s
}

/// [`window_sums`] of a window inside the image, the same bits: the weights
/// of all pixels sum to the precomputed totals (added in the same order),
/// and the pieces are compared row by row through [`HitMap::keys`].
fn window_sums_inside(
    map: &HitMap,
    ew: &EdgeWeights,
    x: i64,
    y: i64,
    centre: Option<f32>,
) -> WindowSums {
    let r = EDGE_RADIUS;
    let key = centre.unwrap_or(NO_HIT);
    let (mut num, mut dnum) = (0.0, [0.0; 2]);
    for (j, row) in ew.w.chunks_exact(EDGE_SIDE).enumerate() {
        let at = ((y - r + j as i64) * map.w + x - r) as usize;
        // Without branches (across a boundary they go either way; teapot,
        // the edge lines 14–15 → 10–12 M cycles a frame): a pixel off the
        // piece adds an exact zero, so the sums keep their bits.
        for (&k, &[w, gx, gy]) in map.keys()[at..at + EDGE_SIDE].iter().zip(row) {
            let on = if k == key { 1.0 } else { 0.0 };
            num += on * w;
            dnum[0] += on * gx;
            dnum[1] += on * gy;
        }
    }
    WindowSums {
        num,
        den: ew.full_den,
        dnum,
        dden: ew.full_dden,
    }
}

/// Locates the boundary of the pixel's piece near `(x, y)` from the piece
/// indicator of its 9×9 neighbourhood: blurred by a Gaussian, a straight
/// boundary at signed distance `d` reads `Φ(d/σ)` at the centre with gradient
/// `φ(d/σ)/σ` along its normal. `None` when the indicator does not look like
/// one straight boundary (corners, thin features, several pieces), judged by
/// that gradient.
pub(super) fn edge_line(map: &HitMap, x: i64, y: i64, centre: Option<f32>) -> Option<EdgeLine> {
    let ew = edge_weights();
    let r = EDGE_RADIUS;
    let WindowSums {
        num,
        den,
        dnum,
        dden,
    } = if x >= r && y >= r && x + r < map.w && y + r < map.h {
        window_sums_inside(map, ew, x, y, centre)
    } else {
        window_sums(map, ew, x, y, centre)
    };
    let ind = num / den;
    if !(1e-4..=1.0 - 1e-4).contains(&ind) {
        return None;
    }
    let g = [
        (dnum[0] - ind * dden[0]) / den,
        (dnum[1] - ind * dden[1]) / den,
    ];
    let glen = (g[0] * g[0] + g[1] * g[1]).sqrt();
    let q = inverse_phi(ind);
    let expect = (-0.5 * q * q).exp() / ((2.0 * std::f64::consts::PI).sqrt() * EDGE_SIGMA);
    let ratio = glen / expect;
    if !(0.75..=1.33).contains(&ratio) {
        return None;
    }
    Some(EdgeLine {
        d: EDGE_SIGMA * q,
        n: [g[0] / glen, g[1] / glen],
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::film::Film;

    /// The quantile starts within 1e-6 of the converged one, which inverts
    /// `phi_cdf` to its own accuracy, over the whole range edge_line uses.
    #[test]
    fn inverse_phi_inverts_the_cdf() {
        for k in 0..=2000 {
            let p = 1e-4 + (1.0 - 2e-4) * k as f64 / 2000.0;
            let x = inverse_phi(p);
            assert!(
                (footprint::phi_cdf(x) - p).abs() < 1e-12 * (1.0 + 1.0 / p),
                "{p}"
            );
            assert!((quantile_guess(p) - x).abs() < 1e-6, "{p}: {x}");
        }
    }

    /// The window sums of a window inside the image, from the keys and the
    /// precomputed totals, are those of the general loop, bit for bit, for
    /// every centre state: pieces by event count, pixels without a hit, and
    /// non-finite hits or event counts.
    #[test]
    fn inside_window_sums_match_the_general_sums() {
        let (w, h) = (23u32, 19u32);
        let mut f = Film::new(w, h);
        for i in 0..(w * h) as usize {
            let k = (i * 2654435761) % 97;
            f.u[i] = if k < 9 { f32::NAN } else { k as f32 };
            f.v[i] = if k == 11 { f32::INFINITY } else { 1.0 };
            f.events[i] = match k % 5 {
                0 => f32::NAN,
                1 | 2 => 0.0,
                _ => 2.0,
            };
        }
        let map = HitMap::new(&f);
        let ew = edge_weights();
        let r = EDGE_RADIUS;
        let mut same = 0;
        for y in r..h as i64 - r {
            for x in r..w as i64 - r {
                for centre in [None, Some(0.0), Some(2.0), Some(f32::NAN)] {
                    let fast = window_sums_inside(&map, ew, x, y, centre);
                    let slow = window_sums(&map, ew, x, y, centre);
                    assert_eq!(
                        [
                            fast.num,
                            fast.den,
                            fast.dnum[0],
                            fast.dnum[1],
                            fast.dden[0],
                            fast.dden[1]
                        ]
                        .map(f64::to_bits),
                        [
                            slow.num,
                            slow.den,
                            slow.dnum[0],
                            slow.dnum[1],
                            slow.dden[0],
                            slow.dden[1]
                        ]
                        .map(f64::to_bits),
                        "({x}, {y}) {centre:?}"
                    );
                    same += (fast.num > 0.0) as usize;
                }
            }
        }
        assert!(same > 100, "{same}");
    }
}
