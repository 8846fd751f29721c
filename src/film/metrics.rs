//! Image quality metrics: RMSE, PSNR and SSIM against a reference image.
//!
//! Colours are compared as stored (sRGB-encoded values in [0, 1], as the PNGs
//! hold them). SSIM follows Wang et al. 2004: luminance (Rec. 709 weights),
//! an 11×11 Gaussian window with σ = 1.5, `C1 = (0.01)²`, `C2 = (0.03)²`, the
//! mean over every window that fits inside the image.

use std::path::Path;

use serde::Serialize;

use super::{FilmError, read_exr_layer};

/// An RGB image in [0, 1] (row 0 at the top).
#[derive(Clone, Debug, PartialEq)]
pub struct RgbImage {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<[f32; 3]>,
}

impl RgbImage {
    /// Reads a PNG/JPEG (8 or 16 bit) or an EXR with `R`, `G`, `B` channels.
    pub fn read(path: &Path) -> Result<RgbImage, FilmError> {
        let err = |msg: String| FilmError::Read {
            path: path.to_path_buf(),
            msg,
        };
        if crate::input::has_extension(path, "exr") {
            let image = read_exr_layer(path).map_err(err)?;
            let layer = &image.layer_data;
            let ch = |name: &str| -> Result<Vec<f32>, FilmError> {
                layer
                    .channel_data
                    .list
                    .iter()
                    .find(|c| c.name.eq(name))
                    .map(|c| c.sample_data.values_as_f32().collect())
                    .ok_or_else(|| err(format!("no channel '{name}' (not a colour image)")))
            };
            let (r, g, b) = (ch("R")?, ch("G")?, ch("B")?);
            return Ok(RgbImage {
                width: layer.size.width() as u32,
                height: layer.size.height() as u32,
                pixels: (0..r.len()).map(|i| [r[i], g[i], b[i]]).collect(),
            });
        }
        super::photo::read(path)
            .map_err(|m| match m.as_str() {
                super::photo::NOT_AN_IMAGE => {
                    "not an image snell reads (PNG or JPEG, or EXR by its name)".to_string()
                }
                _ => m,
            })
            .map_err(err)
    }
}

/// Quality of `a` against reference `b`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ImageComparison {
    pub rmse: f64,
    /// `10·log10(1 / MSE)`; infinite for identical images.
    pub psnr: f64,
    pub ssim: f64,
    pub max_abs: f64,
}

fn luma(c: [f32; 3]) -> f64 {
    0.2126 * c[0] as f64 + 0.7152 * c[1] as f64 + 0.0722 * c[2] as f64
}

pub fn compare_images(a: &RgbImage, b: &RgbImage) -> Result<ImageComparison, String> {
    if (a.width, a.height) != (b.width, b.height) {
        return Err(format!(
            "images differ in size: {}x{} vs {}x{}",
            a.width, a.height, b.width, b.height
        ));
    }
    let mut se = 0.0f64;
    let mut max_abs = 0.0f64;
    for (p, q) in a.pixels.iter().zip(&b.pixels) {
        for k in 0..3 {
            let d = p[k] as f64 - q[k] as f64;
            se += d * d;
            max_abs = max_abs.max(d.abs());
        }
    }
    let mse = se / (3 * a.pixels.len()).max(1) as f64;
    Ok(ImageComparison {
        rmse: mse.sqrt(),
        psnr: 10.0 * (1.0 / mse).log10(),
        ssim: ssim(a, b),
        max_abs,
    })
}

/// Mean SSIM of the luminance channels.
pub fn ssim(a: &RgbImage, b: &RgbImage) -> f64 {
    const R: usize = 5;
    const SIGMA: f64 = 1.5;
    let (w, h) = (a.width as usize, a.height as usize);
    if w <= 2 * R || h <= 2 * R {
        // Too small for a window: fall back to one global window.
        return ssim_global(a, b);
    }
    let g: Vec<f64> = (0..=2 * R)
        .map(|i| {
            let x = i as f64 - R as f64;
            (-x * x / (2.0 * SIGMA * SIGMA)).exp()
        })
        .collect();
    let norm: f64 = g.iter().sum();
    let g: Vec<f64> = g.iter().map(|v| v / norm).collect();
    let ya: Vec<f64> = a.pixels.iter().map(|&c| luma(c)).collect();
    let yb: Vec<f64> = b.pixels.iter().map(|&c| luma(c)).collect();
    // Separable Gaussian of the five moment images, "valid" windows only.
    let moments: [Vec<f64>; 5] = [
        ya.clone(),
        yb.clone(),
        ya.iter().map(|v| v * v).collect(),
        yb.iter().map(|v| v * v).collect(),
        ya.iter().zip(&yb).map(|(p, q)| p * q).collect(),
    ];
    let (ow, oh) = (w - 2 * R, h - 2 * R);
    let blur = |src: &[f64]| -> Vec<f64> {
        let mut tmp = vec![0.0; ow * h];
        for y in 0..h {
            for x in 0..ow {
                tmp[y * ow + x] = (0..=2 * R).map(|k| g[k] * src[y * w + x + k]).sum();
            }
        }
        let mut out = vec![0.0; ow * oh];
        for y in 0..oh {
            for x in 0..ow {
                out[y * ow + x] = (0..=2 * R).map(|k| g[k] * tmp[(y + k) * ow + x]).sum();
            }
        }
        out
    };
    let m: Vec<Vec<f64>> = moments.iter().map(|v| blur(v)).collect();
    let (c1, c2) = (0.01f64.powi(2), 0.03f64.powi(2));
    let mut total = 0.0;
    for i in 0..ow * oh {
        let (mu_a, mu_b) = (m[0][i], m[1][i]);
        let var_a = m[2][i] - mu_a * mu_a;
        let var_b = m[3][i] - mu_b * mu_b;
        let cov = m[4][i] - mu_a * mu_b;
        total += ((2.0 * mu_a * mu_b + c1) * (2.0 * cov + c2))
            / ((mu_a * mu_a + mu_b * mu_b + c1) * (var_a + var_b + c2));
    }
    total / (ow * oh) as f64
}

fn ssim_global(a: &RgbImage, b: &RgbImage) -> f64 {
    let n = a.pixels.len().max(1) as f64;
    let ya: Vec<f64> = a.pixels.iter().map(|&c| luma(c)).collect();
    let yb: Vec<f64> = b.pixels.iter().map(|&c| luma(c)).collect();
    let (ma, mb) = (ya.iter().sum::<f64>() / n, yb.iter().sum::<f64>() / n);
    let va = ya.iter().map(|v| (v - ma).powi(2)).sum::<f64>() / n;
    let vb = yb.iter().map(|v| (v - mb).powi(2)).sum::<f64>() / n;
    let cov = ya
        .iter()
        .zip(&yb)
        .map(|(p, q)| (p - ma) * (q - mb))
        .sum::<f64>()
        / n;
    let (c1, c2) = (0.01f64.powi(2), 0.03f64.powi(2));
    ((2.0 * ma * mb + c1) * (2.0 * cov + c2)) / ((ma * ma + mb * mb + c1) * (va + vb + c2))
}

/// A heat map of `|a - b|` (black = equal, white = 0.5 or more apart).
pub fn diff_image(a: &RgbImage, b: &RgbImage) -> Vec<u8> {
    a.pixels
        .iter()
        .zip(&b.pixels)
        .flat_map(|(p, q)| {
            let d = (0..3).map(|k| (p[k] - q[k]).abs()).fold(0.0f32, f32::max);
            let t = (2.0 * d).min(1.0);
            // black → red → yellow → white
            [
                (3.0 * t).min(1.0),
                (3.0 * t - 1.0).clamp(0.0, 1.0),
                (3.0 * t - 2.0).clamp(0.0, 1.0),
            ]
            .map(|v| (v * 255.0).round() as u8)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn img(f: impl Fn(u32, u32) -> f32) -> RgbImage {
        let (w, h) = (32, 24);
        RgbImage {
            width: w,
            height: h,
            pixels: (0..w * h).map(|i| [f(i % w, i / w); 3]).collect(),
        }
    }

    #[test]
    fn identical_and_shifted() {
        let a = img(|x, y| ((x / 4 + y / 4) % 2) as f32);
        let c = compare_images(&a, &a).unwrap();
        assert_eq!(c.rmse, 0.0);
        assert!(c.psnr.is_infinite());
        assert!((c.ssim - 1.0).abs() < 1e-12);
        let b = img(|x, y| (((x + 1) / 4 + y / 4) % 2) as f32);
        let d = compare_images(&a, &b).unwrap();
        assert!(d.rmse > 0.1 && d.ssim < 0.9 && d.psnr < 20.0, "{d:?}");
        // A uniform offset of 0.1: PSNR 20 dB exactly.
        let e = img(|x, y| 0.1 + 0.8 * ((x / 4 + y / 4) % 2) as f32);
        let f = img(|x, y| 0.2 + 0.8 * ((x / 4 + y / 4) % 2) as f32);
        let g = compare_images(&e, &f).unwrap();
        assert!((g.psnr - 20.0).abs() < 1e-4, "{g:?}");
        assert!(compare_images(&a, &img(|_, _| 0.0)).is_ok());
    }
}
