//! Synthetic volumes with known ground truth: the paper's glass sphere (with
//! optional air holes) and the Marschner–Lobb test signal.
//!
//! Both are described by plain specs that deserialize from scene files
//! (`[volume.phantom]`) and map one-to-one onto `snell phantom` options. Noise
//! is counter-based (a hash of seed and voxel index), so a phantom is the same
//! bits whatever the thread count.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::volume::{SampleType, Volume};

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PhantomError {
    #[error("phantom: {0}")]
    Invalid(String),
    /// A setting out of range: its name as in scene files (`size`; the
    /// option of `snell phantom` is `--size`) and what is wrong.
    #[error("phantom {key} {msg}")]
    Setting { key: &'static str, msg: String },
}

/// Largest phantom side in samples.
pub const MAX_PHANTOM_SIZE: usize = 4096;

fn setting(key: &'static str, msg: String) -> PhantomError {
    PhantomError::Setting { key, msg }
}

/// A side from 1 to [`MAX_PHANTOM_SIZE`] samples.
pub fn check_size(size: usize) -> Result<(), PhantomError> {
    if size == 0 || size > MAX_PHANTOM_SIZE {
        return Err(setting(
            "size",
            format!("must be from 1 to {MAX_PHANTOM_SIZE} samples, got {size}"),
        ));
    }
    Ok(())
}

fn check_non_negative(key: &'static str, x: f64) -> Result<(), PhantomError> {
    if !(x.is_finite() && x >= 0.0) {
        return Err(setting(
            key,
            format!(
                "must be a finite number >= 0, got {}",
                crate::human::exact(x)
            ),
        ));
    }
    Ok(())
}

/// Sample encoding of a phantom.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum PhantomFormat {
    /// Values in 0..1 as `f32`.
    #[default]
    F32,
    /// `round(255·v)`.
    U8,
    /// `round(65535·v)`.
    U16,
}

impl PhantomFormat {
    pub fn parse(s: &str) -> Option<PhantomFormat> {
        match s.to_ascii_lowercase().as_str() {
            "f32" | "float" => Some(PhantomFormat::F32),
            "u8" | "uint8" => Some(PhantomFormat::U8),
            "u16" | "uint16" => Some(PhantomFormat::U16),
            _ => None,
        }
    }

    /// Value of `1.0` in output units.
    pub fn full_scale(self) -> f64 {
        match self {
            PhantomFormat::F32 => 1.0,
            PhantomFormat::U8 => 255.0,
            PhantomFormat::U16 => 65535.0,
        }
    }

    fn sample_type(self) -> SampleType {
        match self {
            PhantomFormat::F32 => SampleType::F32,
            PhantomFormat::U8 => SampleType::U8,
            PhantomFormat::U16 => SampleType::U16,
        }
    }

    /// Encodes a value in output units (noise already added).
    fn encode(self, v: f64) -> f32 {
        match self {
            PhantomFormat::F32 => v as f32,
            PhantomFormat::U8 => round_clamp(v, 255.0),
            PhantomFormat::U16 => round_clamp(v, 65535.0),
        }
    }

    /// Whether values round to integers, so that one below half a unit is
    /// stored as 0 whatever it is.
    fn is_integer(self) -> bool {
        !matches!(self, PhantomFormat::F32)
    }
}

/// `v.round().clamp(0.0, max)` as `f32`, bit for bit, without the libm call
/// `f64::round` is on the x86-64 baseline (no rounding instruction) for the
/// positive values below 2⁵² a phantom mostly holds: truncation by
/// conversion and an exact fraction. Zero, negative, huge and NaN values
/// take `round` itself (it keeps the sign of zero).
fn round_clamp(v: f64, max: f64) -> f32 {
    if v > 0.0 && v < 4_503_599_627_370_496.0 {
        let t = (v as i64) as f64;
        let r = if v - t >= 0.5 { t + 1.0 } else { t };
        r.min(max) as f32
    } else {
        v.round().clamp(0.0, max) as f32
    }
}

/// A spherical air hole carved into the sphere.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Hole {
    pub center: [f64; 3],
    pub radius: f64,
    #[serde(default)]
    pub sigma: f64,
}

/// The paper's "constant-valued sphere with a Gaussian fringe".
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SphereSpec {
    #[serde(default = "default_size")]
    pub size: usize,
    #[serde(default = "default_radius")]
    pub radius: f64,
    #[serde(default = "default_sigma")]
    pub sigma: f64,
    /// Default: the volume centre `((size-1)/2)·(1,1,1)`.
    #[serde(default)]
    pub center: Option<[f64; 3]>,
    #[serde(default)]
    pub holes: Vec<Hole>,
    #[serde(default)]
    pub format: PhantomFormat,
    /// Standard deviation of additive Gaussian noise, in output units.
    #[serde(default)]
    pub noise: f64,
    #[serde(default)]
    pub seed: u64,
}

fn default_size() -> usize {
    64
}
fn default_radius() -> f64 {
    20.0
}
fn default_sigma() -> f64 {
    3.0
}
fn default_ml_size() -> usize {
    41
}
fn default_alpha() -> f64 {
    0.25
}
fn default_fm() -> f64 {
    6.0
}

impl Default for SphereSpec {
    fn default() -> Self {
        SphereSpec {
            size: default_size(),
            radius: default_radius(),
            sigma: default_sigma(),
            center: None,
            holes: Vec::new(),
            format: PhantomFormat::F32,
            noise: 0.0,
            seed: 0,
        }
    }
}

/// Radial profile: 1 inside `radius`, a Gaussian fringe of width `sigma` beyond.
#[inline]
pub fn fringe(r: f64, radius: f64, sigma: f64) -> f64 {
    if r <= radius {
        1.0
    } else if sigma <= 0.0 {
        0.0
    } else {
        let d = (r - radius) / sigma;
        (-0.5 * d * d).exp()
    }
}

/// Where `fringe` equals `level` (0 < level ≤ 1): the iso-surface radius.
pub fn fringe_radius(radius: f64, sigma: f64, level: f64) -> Option<f64> {
    if !(level > 0.0 && level <= 1.0) {
        return None;
    }
    Some(radius + sigma * (2.0 * (1.0 / level).ln()).sqrt())
}

impl SphereSpec {
    pub fn center(&self) -> [f64; 3] {
        self.center.unwrap_or([(self.size as f64 - 1.0) / 2.0; 3])
    }

    /// Noise-free value in 0..1 at grid point `p`.
    pub fn value(&self, p: [f64; 3]) -> f64 {
        self.value_at(p, dist(p, self.center()))
    }

    /// [`SphereSpec::value`] at `p`, `r` from the centre.
    fn value_at(&self, p: [f64; 3], r: f64) -> f64 {
        let mut v = fringe(r, self.radius, self.sigma);
        for h in &self.holes {
            v *= 1.0 - fringe(dist(p, h.center), h.radius, h.sigma);
        }
        v
    }

    pub fn validate(&self) -> Result<(), PhantomError> {
        check_size(self.size)?;
        let finite = |x: f64| x.is_finite();
        check_non_negative("radius", self.radius)?;
        check_non_negative("sigma", self.sigma)?;
        check_non_negative("noise", self.noise)?;
        if let Some(c) = self.center
            && !c.iter().all(|v| v.is_finite())
        {
            return Err(setting("center", format!("must be finite, got {c:?}")));
        }
        for h in &self.holes {
            if !h.center.iter().all(|v| v.is_finite())
                || !finite(h.radius)
                || h.radius < 0.0
                || !finite(h.sigma)
                || h.sigma < 0.0
            {
                return Err(setting(
                    "holes",
                    format!(
                        "hole at [{}, {}, {}] with radius {} and sigma {} needs a finite center, radius >= 0 and sigma >= 0",
                        h.center[0], h.center[1], h.center[2], h.radius, h.sigma
                    ),
                ));
            }
        }
        Ok(())
    }

    pub fn build(&self) -> Result<Volume, PhantomError> {
        self.validate()?;
        let n = self.size;
        let c = self.center();
        let far = self.zero_beyond();
        build_grid([n; 3], self.format, self.noise, self.seed, |p| {
            let r = dist(p, c);
            if far.is_some_and(|far| r > far) {
                0.0
            } else {
                self.value_at(p, r)
            }
        })
    }

    /// A distance from the centre beyond which every sample is stored as 0
    /// without evaluating it, when there is one: integer formats without
    /// noise, where the fringe has fallen below half a unit (holes only
    /// lower it). The bound sits a relative 1e-9 beyond the exact one, far
    /// above the rounding of `exp` and of the scaling, so the samples are
    /// those the fringe gives.
    fn zero_beyond(&self) -> Option<f64> {
        let scale = self.format.full_scale();
        (self.format.is_integer() && self.noise == 0.0 && self.sigma > 0.0)
            .then(|| self.radius + self.sigma * (2.0 * (2.0 * scale).ln() * (1.0 + 1e-9)).sqrt())
    }
}

/// Marschner & Lobb (1994): a slowly varying signal with a high-frequency
/// radial ripple near the Nyquist limit of its standard 41³ sampling.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MarschnerLobbSpec {
    #[serde(default = "default_ml_size")]
    pub size: usize,
    #[serde(default = "default_alpha")]
    pub alpha: f64,
    #[serde(default = "default_fm")]
    pub fm: f64,
    #[serde(default)]
    pub format: PhantomFormat,
    #[serde(default)]
    pub noise: f64,
    #[serde(default)]
    pub seed: u64,
}

impl Default for MarschnerLobbSpec {
    fn default() -> Self {
        MarschnerLobbSpec {
            size: default_ml_size(),
            alpha: default_alpha(),
            fm: default_fm(),
            format: PhantomFormat::F32,
            noise: 0.0,
            seed: 0,
        }
    }
}

impl MarschnerLobbSpec {
    /// The continuous signal at `(x, y, z) ∈ [-1, 1]³`, in 0..1.
    pub fn signal(&self, x: f64, y: f64, z: f64) -> f64 {
        use std::f64::consts::PI;
        let r = (x * x + y * y).sqrt();
        let rho_r = (2.0 * PI * self.fm * (PI * r / 2.0).cos()).cos();
        (1.0 - (PI * z / 2.0).sin() + self.alpha * (1.0 + rho_r)) / (2.0 * (1.0 + self.alpha))
    }

    /// Grid coordinate → the signal's `[-1, 1]` coordinate.
    pub fn to_unit(&self, g: f64) -> f64 {
        if self.size < 2 {
            0.0
        } else {
            -1.0 + 2.0 * g / (self.size as f64 - 1.0)
        }
    }

    pub fn validate(&self) -> Result<(), PhantomError> {
        check_size(self.size)?;
        for (key, x) in [("alpha", self.alpha), ("fm", self.fm)] {
            if !x.is_finite() {
                return Err(setting(key, format!("must be finite, got {x}")));
            }
        }
        if self.alpha == -1.0 {
            return Err(setting(
                "alpha",
                "must not be -1 (the signal is divided by 1 + alpha)".into(),
            ));
        }
        check_non_negative("noise", self.noise)
    }

    pub fn build(&self) -> Result<Volume, PhantomError> {
        self.validate()?;
        let n = self.size;
        build_grid([n; 3], self.format, self.noise, self.seed, |p| {
            self.signal(self.to_unit(p[0]), self.to_unit(p[1]), self.to_unit(p[2]))
        })
    }
}

/// Any phantom, as named in scenes (`kind = "sphere"`) and on the command line.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum PhantomSpec {
    Sphere(SphereSpec),
    MarschnerLobb(MarschnerLobbSpec),
}

impl PhantomSpec {
    /// Checks the settings without building the grid.
    pub fn validate(&self) -> Result<(), PhantomError> {
        match self {
            PhantomSpec::Sphere(s) => s.validate(),
            PhantomSpec::MarschnerLobb(m) => m.validate(),
        }
    }

    pub fn build(&self) -> Result<Volume, PhantomError> {
        match self {
            PhantomSpec::Sphere(s) => s.build(),
            PhantomSpec::MarschnerLobb(m) => m.build(),
        }
    }

    pub fn format(&self) -> PhantomFormat {
        match self {
            PhantomSpec::Sphere(s) => s.format,
            PhantomSpec::MarschnerLobb(m) => m.format,
        }
    }

    /// Samples per axis of the grid [`PhantomSpec::build`] makes.
    pub fn dims(&self) -> [usize; 3] {
        match self {
            PhantomSpec::Sphere(s) => [s.size; 3],
            PhantomSpec::MarschnerLobb(m) => [m.size; 3],
        }
    }
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Samples `value` (0..1) on a grid, scales to the format, adds noise, encodes.
fn build_grid(
    dims: [usize; 3],
    format: PhantomFormat,
    noise: f64,
    seed: u64,
    value: impl Fn([f64; 3]) -> f64 + Sync,
) -> Result<Volume, PhantomError> {
    let [nx, ny, nz] = dims;
    // Refused like a volume file's header would be, before allocating
    // (`Scene::load_volume` checks first against the caller's own limit).
    crate::volume::checked_sample_count(
        std::path::Path::new("phantom"),
        dims,
        crate::volume::limits::default_memory_limit(),
    )
    .map_err(|e| PhantomError::Setting {
        key: "size",
        // The message without the path, which the scene's error names.
        msg: match e {
            crate::volume::VolumeError::OverLimit { source, .. } => source.to_string(),
            crate::volume::VolumeError::Format { msg, .. }
            | crate::volume::VolumeError::TooLarge { msg, .. } => msg,
            e => e.to_string(),
        },
    })?;
    let scale = format.full_scale();
    let mut samples = vec![0.0f32; nx * ny * nz];
    samples
        .par_chunks_mut(nx * ny)
        .enumerate()
        .for_each(|(z, slab)| {
            for y in 0..ny {
                for x in 0..nx {
                    let i = x + nx * (y + ny * z);
                    let mut v = value([x as f64, y as f64, z as f64]) * scale;
                    if noise > 0.0 {
                        v += noise * gaussian(seed, i as u64);
                    }
                    slab[x + nx * y] = format.encode(v);
                }
            }
        });
    // Noise or a signal beyond `f32` (a huge `noise`, Marschner–Lobb's
    // `alpha` at -1) would make a volume no reader accepts.
    if let Some(i) = samples.iter().position(|v| !v.is_finite()) {
        let (x, y, z) = (i % nx, i / nx % ny, i / (nx * ny));
        return Err(PhantomError::Invalid(format!(
            "sample ({x}, {y}, {z}) is {} in {} (noise or signal out of range)",
            samples[i],
            format.sample_type()
        )));
    }
    Volume::new(dims, [1.0; 3], format.sample_type(), samples)
        .map_err(|e| PhantomError::Invalid(e.to_string()))
}

/// SplitMix64 finaliser: a good 64-bit mix of a counter.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Uniform in (0, 1) from a counter.
#[inline]
pub fn uniform(seed: u64, counter: u64) -> f64 {
    let bits = mix64(seed ^ mix64(counter)) >> 11;
    (bits as f64 + 0.5) / (1u64 << 53) as f64
}

/// Standard normal from a counter (Box–Muller on two counter-based uniforms).
pub fn gaussian(seed: u64, index: u64) -> f64 {
    let u1 = uniform(seed, 2 * index);
    let u2 = uniform(seed, 2 * index + 1);
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_profile_and_iso_radius() {
        let s = SphereSpec {
            size: 32,
            radius: 8.0,
            sigma: 2.0,
            ..Default::default()
        };
        let v = s.build().unwrap();
        assert_eq!(v.dims(), [32; 3]);
        // The centre (15.5) is between samples; (15,15,15) is inside radius 8.
        assert_eq!(v.get(15, 15, 15), 1.0);
        let r = fringe_radius(8.0, 2.0, 0.5).unwrap();
        assert!((fringe(r, 8.0, 2.0) - 0.5).abs() < 1e-12);
        assert!(fringe_radius(8.0, 2.0, 0.0).is_none());
    }

    #[test]
    fn fast_rounding_is_round_and_clamp() {
        let mut vs = vec![
            0.0,
            -0.0,
            0.49999999999999994,
            0.5,
            1.5,
            2.5,
            254.5,
            255.49,
            255.5,
            1e300,
            -1e-300,
            -0.3,
            -0.5,
            -0.7,
            -3.5,
            4503599627370495.5,
            4503599627370496.0,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            65534.5,
            65535.5,
            1e-320,
        ];
        for i in 0..2000 {
            let x = i as f64 * 0.25;
            vs.extend([
                x,
                f64::from_bits(x.to_bits() + 1),
                f64::from_bits(x.to_bits().max(1) - 1),
            ]);
        }
        for v in vs {
            for max in [255.0, 65535.0] {
                let want = v.round().clamp(0.0, max) as f32;
                assert_eq!(round_clamp(v, max).to_bits(), want.to_bits(), "{v} {max}");
            }
        }
    }

    #[test]
    fn samples_skipped_far_out_are_those_the_fringe_gives() {
        // Every sample as `value` and `encode` give it, with and without the
        // skip; a sharp fringe so that many samples lie beyond the bound.
        for format in [PhantomFormat::U8, PhantomFormat::U16, PhantomFormat::F32] {
            for sigma in [0.7, 3.0] {
                let s = SphereSpec {
                    size: 24,
                    radius: 6.0,
                    sigma,
                    format,
                    holes: vec![Hole {
                        center: [11.0, 12.0, 11.5],
                        radius: 2.0,
                        sigma: 1.0,
                    }],
                    ..Default::default()
                };
                let v = s.build().unwrap();
                let (scale, far, c) = (format.full_scale(), s.zero_beyond(), s.center());
                let mut skipped = 0;
                for z in 0..24 {
                    for y in 0..24 {
                        for x in 0..24 {
                            let p = [x as f64, y as f64, z as f64];
                            let want = format.encode(s.value(p) * scale);
                            assert_eq!(
                                v.get(x, y, z).to_bits(),
                                f64::from(want).to_bits(),
                                "{p:?}"
                            );
                            skipped += far.is_some_and(|r| dist(p, c) > r) as usize;
                        }
                    }
                }
                if !format.is_integer() {
                    assert_eq!(skipped, 0, "{format:?}: no skipping without rounding");
                } else if sigma < 1.0 {
                    assert!(skipped > 1000, "{format:?}: the test must skip samples");
                }
            }
        }
    }

    #[test]
    fn holes_and_formats() {
        let s = SphereSpec {
            size: 40,
            radius: 15.0,
            sigma: 1.5,
            holes: vec![Hole {
                center: [19.5, 19.5, 19.5],
                radius: 4.0,
                sigma: 1.0,
            }],
            format: PhantomFormat::U8,
            ..Default::default()
        };
        let v = s.build().unwrap();
        assert_eq!(v.native_type(), SampleType::U8);
        assert_eq!(v.get(19, 19, 19), 0.0, "hole centre is air");
        assert_eq!(v.get(19, 19, 30), 255.0, "ball body is full");
        assert_eq!(v.get(0, 0, 0), 0.0);
    }

    #[test]
    fn noise_is_seeded_and_centred() {
        let mk = |seed| {
            SphereSpec {
                size: 16,
                noise: 0.1,
                seed,
                radius: 100.0,
                ..Default::default()
            }
            .build()
            .unwrap()
        };
        let (a, b, c) = (mk(7), mk(7), mk(8));
        assert_eq!(a.samples(), b.samples());
        assert_ne!(a.samples(), c.samples());
        let mean: f64 = a.samples().iter().map(|&v| v as f64 - 1.0).sum::<f64>() / a.len() as f64;
        let var: f64 = a
            .samples()
            .iter()
            .map(|&v| (v as f64 - 1.0).powi(2))
            .sum::<f64>()
            / a.len() as f64;
        assert!(mean.abs() < 0.01, "{mean}");
        assert!((var.sqrt() - 0.1).abs() < 0.01, "{}", var.sqrt());
    }

    #[test]
    fn marschner_lobb_matches_definition() {
        let m = MarschnerLobbSpec::default();
        let v = m.build().unwrap();
        assert_eq!(v.dims(), [41; 3]);
        // At the grid centre (0,0,0): (1 - 0 + α(1 + cos(2π·6·1)))/(2(1+α)) = (1+2α)/(2+2α).
        let c = v.get(20, 20, 20);
        assert!((c - 1.5 / 2.5).abs() < 1e-6, "{c}");
        // Off the centre, where every term counts: grid g ↦ -1 + 2g/40, the
        // ripple cos(2π·6·cos(πr/2)) of r = √(x² + y²), the slope -sin(πz/2).
        use std::f64::consts::PI;
        for (g, (x, y, z)) in [
            ([30, 20, 25], (0.5, 0.0, 0.25)),
            ([10, 35, 5], (-0.5, 0.75, -0.75)),
            ([0, 40, 38], (-1.0, 1.0, 0.9)),
        ] {
            let r = f64::hypot(x, y);
            let want = (1.0 - (PI * z / 2.0).sin()
                + 0.25 * (1.0 + (12.0 * PI * (PI * r / 2.0).cos()).cos()))
                / 2.5;
            let got = v.get(g[0], g[1], g[2]);
            assert!((got - want).abs() < 1e-6, "{g:?}: {got} against {want}");
        }
        let (lo, hi) = v
            .samples()
            .iter()
            .fold((f32::MAX, f32::MIN), |(l, h), &x| (l.min(x), h.max(x)));
        assert!(lo >= 0.0 && hi <= 1.0);
    }

    #[test]
    fn specs_deserialize_from_toml() {
        let s: PhantomSpec = toml::from_str(
            "kind = 'sphere'\nsize = 64\nradius = 20.0\nsigma = 3.0\nformat = 'u8'\n[[holes]]\ncenter = [30.0, 30.0, 30.0]\nradius = 5.0\nsigma = 1.0\n",
        )
        .unwrap();
        match s {
            PhantomSpec::Sphere(s) => {
                assert_eq!(s.format, PhantomFormat::U8);
                assert_eq!(s.holes.len(), 1);
            }
            _ => panic!(),
        }
        let m: PhantomSpec = toml::from_str("kind = 'marschner-lobb'\n").unwrap();
        assert_eq!(m, PhantomSpec::MarschnerLobb(MarschnerLobbSpec::default()));
        assert!(toml::from_str::<PhantomSpec>("kind = 'sphere'\nradus = 3.0\n").is_err());
    }
}
