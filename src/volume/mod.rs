//! Sampled volumes: the grid of samples every other stage reconstructs from.
//!
//! A [`Volume`] keeps its samples as `f32` (the working precision of the whole
//! pipeline) in x-fastest order, `index = x + nx*(y + ny*z)`, together with the
//! file's native sample type (reported by `snell info`, and used to size
//! iso-value suggestions) and its voxel spacing. Sample `(i, j, k)` sits at grid
//! coordinate `(i, j, k)`; world position is grid coordinate × spacing.
//!
//! Readers live in submodules ([`nrrd`], [`nifti`], [`raw`]); all of them decode
//! through [`decode_samples`] and check sizes against [`limits`] *before*
//! allocating, so an absurd header is an error message, not an OOM kill.

mod gzip;
pub mod limits;
pub mod metaimage;
pub mod nifti;
pub mod nrrd;
pub mod raw;
mod stats;

use std::fmt;
use std::path::{Path, PathBuf};

pub use stats::{Histogram, VolumeStats};

/// The sample type a file stores, kept for reporting and for writing back.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SampleType {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl SampleType {
    /// Bytes per sample on disk.
    pub fn size(self) -> usize {
        match self {
            SampleType::I8 | SampleType::U8 => 1,
            SampleType::I16 | SampleType::U16 => 2,
            SampleType::I32 | SampleType::U32 | SampleType::F32 => 4,
            SampleType::F64 => 8,
        }
    }

    pub fn is_float(self) -> bool {
        matches!(self, SampleType::F32 | SampleType::F64)
    }

    /// Short name used on the command line (`--type u16`) and in reports.
    pub fn name(self) -> &'static str {
        match self {
            SampleType::I8 => "i8",
            SampleType::U8 => "u8",
            SampleType::I16 => "i16",
            SampleType::U16 => "u16",
            SampleType::I32 => "i32",
            SampleType::U32 => "u32",
            SampleType::F32 => "f32",
            SampleType::F64 => "f64",
        }
    }

    /// Parses the command-line names (`u8`, `int16`, `float`, ...).
    pub fn parse(s: &str) -> Option<SampleType> {
        Some(match s.to_ascii_lowercase().as_str() {
            "i8" | "int8" | "char" | "signed char" => SampleType::I8,
            "u8" | "uint8" | "uchar" | "unsigned char" => SampleType::U8,
            "i16" | "int16" | "short" => SampleType::I16,
            "u16" | "uint16" | "ushort" | "unsigned short" => SampleType::U16,
            "i32" | "int32" | "int" => SampleType::I32,
            "u32" | "uint32" | "uint" | "unsigned int" => SampleType::U32,
            "f32" | "float" | "float32" => SampleType::F32,
            "f64" | "double" | "float64" => SampleType::F64,
            _ => return None,
        })
    }
}

impl fmt::Display for SampleType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Byte order of multi-byte samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Endian {
    Little,
    Big,
}

impl Endian {
    pub fn parse(s: &str) -> Option<Endian> {
        match s.to_ascii_lowercase().as_str() {
            "little" | "le" => Some(Endian::Little),
            "big" | "be" => Some(Endian::Big),
            _ => None,
        }
    }
}

/// For a scene file given where a volume goes (`snell info scene.toml`):
/// what reads it.
fn scene_hint(path: &std::path::Path) -> &'static str {
    if crate::input::has_extension(path, "toml") {
        "; a .toml file is a scene: render it with `snell render SCENE.toml -o out.png`, or give this command the volume the scene names"
    } else {
        ""
    }
}

/// Everything that can go wrong turning a file into a [`Volume`]. Every message
/// names the file, so the CLI can print it on one line as is.
#[derive(Debug, thiserror::Error)]
pub enum VolumeError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: {msg}")]
    Format { path: PathBuf, msg: String },
    #[error("{path}: {msg}")]
    Unsupported { path: PathBuf, msg: String },
    #[error("{path}: data holds {got} bytes but {need} are needed ({what})")]
    Truncated {
        path: PathBuf,
        need: u64,
        got: u64,
        what: String,
    },
    #[error("{path}: {msg}")]
    TooLarge { path: PathBuf, msg: String },
    /// Over the memory limit, refused before allocating.
    #[error("{path}: {source}")]
    OverLimit {
        path: PathBuf,
        #[source]
        source: limits::OverLimit,
    },
    #[error(
        "{path}: {count} non-finite samples ({nan} NaN, {inf} infinite), first at index {first}; pass --allow-nan (in a scene, --set volume.allow_nan=true) to replace them"
    )]
    NonFinite {
        path: PathBuf,
        count: usize,
        nan: usize,
        inf: usize,
        first: usize,
    },
    #[error(
        "{path}: {count} samples (first at index {first}, {value:e}) are finite but beyond ±{max:e}, the range of the f32 samples snell holds; rescale the data"
    , max = f32::MAX)]
    BeyondF32 {
        path: PathBuf,
        count: usize,
        first: usize,
        value: f64,
    },
    #[error(
        "{path}: unknown volume format (expected .nrrd, .nhdr, .nii, .nii.gz, .mha, .mhd, or raw with --dims and --type){}",
        scene_hint(path)
    )]
    UnknownFormat { path: PathBuf },
    #[error("{0}")]
    Invalid(String),
}

impl VolumeError {
    pub(crate) fn format(path: &Path, msg: impl Into<String>) -> Self {
        VolumeError::Format {
            path: path.to_path_buf(),
            msg: msg.into(),
        }
    }
    pub(crate) fn unsupported(path: &Path, msg: impl Into<String>) -> Self {
        VolumeError::Unsupported {
            path: path.to_path_buf(),
            msg: msg.into(),
        }
    }
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        VolumeError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// How to describe a headerless raw file.
#[derive(Clone, Debug, PartialEq)]
pub struct RawSpec {
    pub dims: [usize; 3],
    pub sample_type: SampleType,
    pub endian: Endian,
    pub spacing: [f64; 3],
    /// Bytes to skip before the first sample.
    pub offset: u64,
}

/// Options shared by every reader.
#[derive(Clone, Debug)]
pub struct LoadOptions {
    /// Replace NaN and infinite samples instead of rejecting the file.
    pub allow_nan: bool,
    /// Largest allowed working-set size in bytes, checked before allocating.
    pub memory_limit: u64,
    /// Treat the input as headerless raw data laid out like this.
    pub raw: Option<RawSpec>,
}

impl Default for LoadOptions {
    fn default() -> Self {
        LoadOptions {
            allow_nan: false,
            memory_limit: limits::default_memory_limit(),
            raw: None,
        }
    }
}

/// A 3-D grid of samples with its spacing.
#[derive(Clone, Debug)]
pub struct Volume {
    dims: [usize; 3],
    spacing: [f64; 3],
    native: SampleType,
    /// The samples less [`Volume::offset`], rounded to `f32`.
    samples: Vec<f32>,
    /// What every stored sample is relative to: none (-0.0) unless the
    /// file's values do not all fit `f32` exactly (`f64`, `u32`, `i32`
    /// data, or a NIfTI scaling) and lie in a range narrow beside their
    /// magnitude, when it is the range's midpoint ([`f32_offset`]), so
    /// `f32` keeps their differences (pressures of 101325 ± 1 Pa, labels
    /// above 2²⁴) instead of rounding them to steps as coarse as the values
    /// are large.
    offset: f64,
    /// Non-finite samples that were replaced on load (`--allow-nan`).
    pub replaced_nonfinite: usize,
    /// What the reader accepted but the user should hear about (bytes after
    /// the samples, say), for the caller to print.
    pub warnings: Vec<String>,
}

impl Volume {
    /// Builds a volume from x-fastest samples. Fails when the sample count does
    /// not match the dims, a dim is 0, or a spacing is not finite and positive.
    pub fn new(
        dims: [usize; 3],
        spacing: [f64; 3],
        native: SampleType,
        samples: Vec<f32>,
    ) -> Result<Volume, VolumeError> {
        check_dims(dims)?;
        check_spacing(spacing)?;
        check_extent(dims, spacing)?;
        let n = dims[0] * dims[1] * dims[2];
        if samples.len() != n {
            return Err(VolumeError::Invalid(format!(
                "volume of dims {}x{}x{} needs {} samples, got {}",
                dims[0],
                dims[1],
                dims[2],
                n,
                samples.len()
            )));
        }
        Ok(Volume {
            dims,
            spacing,
            native,
            samples,
            offset: -0.0,
            replaced_nonfinite: 0,
            warnings: Vec::new(),
        })
    }

    /// The volume whose samples are `offset` plus the ones it holds
    /// ([`Volume::offset`]; a non-finite offset is taken as 0).
    pub fn with_offset(mut self, offset: f64) -> Volume {
        // No offset is -0.0, not 0.0: `x + -0.0 == x` bit for bit for every
        // x, -0.0 included, so adding it back leaves a sample as stored.
        self.offset = if offset.is_finite() && offset != 0.0 {
            offset
        } else {
            -0.0
        };
        self
    }

    /// A volume from samples in `f64`, stored as [`decode_samples`] stores
    /// a file's: exactly when `f32` holds them all, else relative to their
    /// range's midpoint (resampled `f64` data keeps its precision).
    pub fn from_f64(
        dims: [usize; 3],
        spacing: [f64; 3],
        native: SampleType,
        values: &[f64],
    ) -> Result<Volume, VolumeError> {
        let offset = f32_offset(values.iter().copied());
        let samples = values.iter().map(|&v| (v - offset) as f32).collect();
        Ok(Volume::new(dims, spacing, native, samples)?.with_offset(offset))
    }

    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }
    pub fn spacing(&self) -> [f64; 3] {
        self.spacing
    }
    pub fn native_type(&self) -> SampleType {
        self.native
    }
    /// The samples as stored: less [`Volume::offset`] (which is 0 for
    /// every volume whose values `f32` holds exactly).
    pub fn samples(&self) -> &[f32] {
        &self.samples
    }
    /// What [`Volume::samples`] are relative to (-0.0 for none: adding it
    /// changes no sample, not even -0.0).
    pub fn offset(&self) -> f64 {
        self.offset
    }
    pub fn len(&self) -> usize {
        self.samples.len()
    }
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Sets the spacing (e.g. from a scene file that overrides the header).
    pub fn set_spacing(&mut self, spacing: [f64; 3]) -> Result<(), VolumeError> {
        check_spacing(spacing)?;
        check_extent(self.dims, spacing)?;
        self.spacing = spacing;
        Ok(())
    }

    pub fn index(&self, x: usize, y: usize, z: usize) -> usize {
        x + self.dims[0] * (y + self.dims[1] * z)
    }

    /// The sample at `(x, y, z)`, its offset added back.
    pub fn get(&self, x: usize, y: usize, z: usize) -> f64 {
        self.offset + self.samples[self.index(x, y, z)] as f64
    }

    /// World-space extent of the domain: `(n-1) × spacing` per axis.
    pub fn extent(&self) -> [f64; 3] {
        std::array::from_fn(|a| (self.dims[a] - 1) as f64 * self.spacing[a])
    }

    /// The smallest and largest sample (infinities for no samples).
    pub fn value_range(&self) -> (f64, f64) {
        let (lo, hi) = self
            .samples
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), &v| {
                (l.min(v), h.max(v))
            });
        (self.offset + lo as f64, self.offset + hi as f64)
    }

    /// Value range, histogram and suggested iso-values.
    pub fn stats(&self) -> VolumeStats {
        VolumeStats::compute(self)
    }

    /// Content hash of dims, spacing, type and samples, for on-disk caches:
    /// a 64-bit multiply-xorshift over the sample bits, stable across runs
    /// and platforms (unlike `std`'s hasher), about a gigabyte per second.
    pub fn content_hash(&self) -> u64 {
        let mut h = WordHash::new();
        for d in self.dims {
            h.add(d as u64);
        }
        for sp in self.spacing {
            h.add(sp.to_bits());
        }
        h.add(self.native as u64);
        // Only where there is one, so the hashes of the volumes without
        // (every one before offsets) are as they were.
        if self.offset != 0.0 {
            h.add(self.offset.to_bits());
        }
        let mut pairs = self.samples.chunks_exact(2);
        for p in &mut pairs {
            h.add(p[0].to_bits() as u64 | (p[1].to_bits() as u64) << 32);
        }
        for v in pairs.remainder() {
            h.add(v.to_bits() as u64);
        }
        h.value()
    }
}

pub(crate) fn check_dims(dims: [usize; 3]) -> Result<(), VolumeError> {
    if dims.contains(&0) {
        return Err(VolumeError::Invalid(format!(
            "dims {}x{}x{} contain a zero",
            dims[0], dims[1], dims[2]
        )));
    }
    Ok(())
}

/// A 64-bit multiply-xorshift hash of a stream of words, stable across runs
/// and platforms (unlike `std`'s hasher): [`Volume::content_hash`] and the
/// disk cache's checksums.
#[derive(Clone, Copy)]
pub(crate) struct WordHash(u64);

impl WordHash {
    pub(crate) fn new() -> WordHash {
        WordHash(0x243f_6a88_85a3_08d3)
    }

    #[inline]
    pub(crate) fn add(&mut self, w: u64) {
        self.0 = (self.0 ^ w)
            .wrapping_mul(0x9e37_79b9_7f4a_7c15)
            .rotate_left(29);
    }

    pub(crate) fn value(self) -> u64 {
        crate::phantom::mix64(self.0)
    }
}

/// Refuses a spacing that is not finite and positive on every axis, with
/// the values as people write them (the CLI's `--spacing` and the scene's
/// `volume.spacing` report this message under their own names).
pub fn check_spacing(spacing: [f64; 3]) -> Result<(), VolumeError> {
    if spacing.iter().any(|s| !s.is_finite() || *s <= 0.0) {
        return Err(VolumeError::Invalid(format!(
            "each spacing must be a finite number > 0, got {}",
            human_triple(spacing)
        )));
    }
    Ok(())
}

/// `1, 0.5, 2`: a spacing as people write it.
fn human_triple(v: [f64; 3]) -> String {
    v.map(crate::human::num).join(", ")
}

/// Refuses a spacing whose domain overflows: `(n − 1) × spacing` along an
/// axis must be finite, or every world position on it is infinite (a
/// header's `spacings: 1e308` over 103 samples, say).
pub(crate) fn check_extent(dims: [usize; 3], spacing: [f64; 3]) -> Result<(), VolumeError> {
    for a in 0..3 {
        let n = dims[a].saturating_sub(1);
        if !(n as f64 * spacing[a]).is_finite() {
            return Err(VolumeError::Invalid(format!(
                "the extent along {} ({n} spacings of {}) overflows the f64 range; the spacing is too large",
                ["x", "y", "z"][a],
                crate::human::num(spacing[a])
            )));
        }
    }
    Ok(())
}

/// Refuses spacings whose axes differ by more than [`MAX_SPACING_RATIO`]:
/// beyond it the world-to-grid arithmetic rounds the thinnest axis away
/// (measured before the check, the sphere scene seen along x: at spacing
/// `[1e-12, 1, 1]` its 1280 refractions, at `[1e-15, 1, 1]` 112 refractions
/// and 496 reflections, at `[1e-20, 1, 1]` no surface); no scanner comes
/// near it.
/// Checked where a volume is rendered, not where it is read, so that a file
/// with such a header can still be inspected and its spacing overridden.
pub fn check_spacing_ratio(spacing: [f64; 3]) -> Result<(), VolumeError> {
    let (lo, hi) = spacing
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), &s| {
            (lo.min(s), hi.max(s))
        });
    if hi > MAX_SPACING_RATIO * lo {
        return Err(VolumeError::Invalid(format!(
            "spacing {}: its axes differ by more than a factor {MAX_SPACING_RATIO:e}",
            human_triple(spacing)
        )));
    }
    Ok(())
}

/// Largest ratio between the spacings of two axes.
pub const MAX_SPACING_RATIO: f64 = 1e6;

/// Number of samples for `dims`, or an error when the product overflows or the
/// working set (samples plus prefiltered coefficients, `f32` each) would exceed
/// `memory_limit`. Called by every reader before it allocates.
pub fn checked_sample_count(
    path: &Path,
    dims: [usize; 3],
    memory_limit: u64,
) -> Result<usize, VolumeError> {
    if dims.contains(&0) {
        return Err(VolumeError::format(
            path,
            format!("dims {}x{}x{} contain a zero", dims[0], dims[1], dims[2]),
        ));
    }
    let n = dims[0]
        .checked_mul(dims[1])
        .and_then(|v| v.checked_mul(dims[2]))
        .ok_or_else(|| VolumeError::TooLarge {
            path: path.to_path_buf(),
            msg: format!(
                "dims {}x{}x{} overflow the sample count",
                dims[0], dims[1], dims[2]
            ),
        })?;
    limits::check_bytes(
        path,
        (n as u64).saturating_mul(limits::WORKING_BYTES_PER_SAMPLE),
        memory_limit,
        &format!("a {}x{}x{} volume", dims[0], dims[1], dims[2]),
    )?;
    Ok(n)
}

/// Whether a 3×3 orientation (rows or columns: the sign is the same) has a
/// negative determinant: its axes, in index order, form a frame of the
/// other handedness, so the grid rendered as snell renders it (index order,
/// grid coordinates × spacing) is the scan's mirror image.
pub(crate) fn reverses_handedness(m: [[f64; 3]; 3]) -> bool {
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    det < 0.0
}

/// The warning of a file whose orientation (`what`, the format's field)
/// reverses its space's handedness ([`reverses_handedness`]).
pub(crate) fn mirror_warning(path: &Path, what: &str) -> String {
    format!(
        "{}: {what} reverses the handedness of its space (an odd number of axes stored in reverse, as in radiological order); the orientation is dropped and the samples rendered in index order, grid coordinates × spacing, so the volume appears as the scan's mirror image",
        path.display()
    )
}

/// What [`f32`] samples of `values` should be stored relative to: the
/// midpoint of their range where `f32` rounds some of them and the range is
/// narrow beside their magnitude (under half the largest), so relative to
/// it they round far more finely (see [`Volume::offset`]); a whole number
/// for whole values, so labels stay whole. Otherwise 0: where `f32` holds
/// every value exactly, where the range reaches near 0 (an offset would
/// round the values near 0 more coarsely than `f32` rounds the largest),
/// and where a value lies beyond `f32`'s range (refused by the readers).
pub fn f32_offset(values: impl Iterator<Item = f64>) -> f64 {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut exact, mut whole) = (true, true);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
        exact &= (v as f32) as f64 == v;
        whole &= v.fract() == 0.0;
    }
    let largest = lo.abs().max(hi.abs());
    if exact || lo > hi || largest > f32::MAX as f64 || hi - lo >= largest / 2.0 {
        return 0.0;
    }
    let mid = lo / 2.0 + hi / 2.0;
    if whole { mid.round() } else { mid }
}

/// Decoded samples: `f32` values relative to `offset` ([`Volume::offset`]),
/// and how many non-finite ones were replaced.
#[derive(Debug)]
pub struct Decoded {
    pub samples: Vec<f32>,
    pub offset: f64,
    pub replaced: usize,
}

/// Decodes `count` samples of `ty` in `endian` order from `bytes` into `f32`,
/// applying `value = raw * slope + inter` when a scaling is given (NIfTI),
/// relative to an offset where `f32` cannot hold the values exactly
/// ([`f32_offset`]).
/// Non-finite results are counted and either rejected or replaced per `opts`.
pub fn decode_samples(
    path: &Path,
    bytes: &[u8],
    ty: SampleType,
    endian: Endian,
    count: usize,
    scale: Option<(f64, f64)>,
    allow_nan: bool,
) -> Result<Decoded, VolumeError> {
    let need = (count as u64) * ty.size() as u64;
    if (bytes.len() as u64) < need {
        return Err(VolumeError::Truncated {
            path: path.to_path_buf(),
            need,
            got: bytes.len() as u64,
            what: format!("{} samples of {}", count, ty),
        });
    }
    let bytes = &bytes[..need as usize];
    // Each sample goes through f64 so NIfTI scaling and 32-bit integers keep their
    // precision until the single rounding to f32; no wide intermediate buffer, so
    // peak memory stays at the mapped input plus the f32 output.
    // The default intercept is -0.0, not 0.0: `x + -0.0 == x` for every x,
    // including -0.0, so unscaled float samples keep their exact bits.
    let (slope, inter) = scale.unwrap_or((1.0, -0.0));
    let mut out: Vec<f32> = Vec::with_capacity(count);
    // Finite values that f32 cannot hold (f64 data, or a NIfTI scaling):
    // rounded they would read as infinities the file does not have. Other
    // samples fit f32 whatever they are, and skip the test (a 512³ u16
    // volume loads 10% faster without it).
    let may_overflow = ty == SampleType::F64 || scale.is_some();
    // Only these can hold values f32 rounds; the others are stored exactly
    // without a first pass to find out.
    let may_round = may_overflow || matches!(ty, SampleType::I32 | SampleType::U32);
    let mut offset = 0.0;
    let (mut beyond, mut first_beyond) = (0usize, (usize::MAX, 0.0f64));
    macro_rules! dec {
        ($t:ty, $n:expr) => {{
            let value = |c: &[u8]| -> f64 {
                let arr: [u8; $n] = c.try_into().expect("chunk of exact size");
                let v = match endian {
                    Endian::Little => <$t>::from_le_bytes(arr),
                    Endian::Big => <$t>::from_be_bytes(arr),
                };
                v as f64 * slope + inter
            };
            if may_round {
                offset = f32_offset(bytes.chunks_exact($n).map(value));
            }
            if may_overflow {
                for c in bytes.chunks_exact($n) {
                    let w = value(c) - offset;
                    let x = w as f32;
                    if x.is_infinite() && w.is_finite() {
                        if beyond == 0 {
                            first_beyond = (out.len(), w + offset);
                        }
                        beyond += 1;
                    }
                    out.push(x);
                }
            } else {
                out.extend(bytes.chunks_exact($n).map(|c| (value(c) - offset) as f32));
            }
        }};
    }
    match ty {
        SampleType::I8 => dec!(i8, 1),
        SampleType::U8 => dec!(u8, 1),
        SampleType::I16 => dec!(i16, 2),
        SampleType::U16 => dec!(u16, 2),
        SampleType::I32 => dec!(i32, 4),
        SampleType::U32 => dec!(u32, 4),
        SampleType::F32 => dec!(f32, 4),
        SampleType::F64 => dec!(f64, 8),
    }
    if beyond > 0 {
        return Err(VolumeError::BeyondF32 {
            path: path.to_path_buf(),
            count: beyond,
            first: first_beyond.0,
            value: first_beyond.1,
        });
    }
    let mut nan = 0usize;
    let mut inf = 0usize;
    let mut first = usize::MAX;
    for (i, v) in out.iter().enumerate() {
        if !v.is_finite() {
            if v.is_nan() {
                nan += 1;
            } else {
                inf += 1;
            }
            first = first.min(i);
        }
    }
    let bad = nan + inf;
    if bad > 0 {
        if !allow_nan {
            return Err(VolumeError::NonFinite {
                path: path.to_path_buf(),
                count: bad,
                nan,
                inf,
                first,
            });
        }
        replace_nonfinite(&mut out);
    }
    Ok(Decoded {
        samples: out,
        offset,
        replaced: bad,
    })
}

/// Replaces NaN and -inf by the smallest finite sample and +inf by the largest,
/// so every later stage sees a defined field. An all-non-finite volume becomes 0.
pub fn replace_nonfinite(samples: &mut [f32]) {
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for &v in samples.iter() {
        if v.is_finite() {
            lo = lo.min(v);
            hi = hi.max(v);
        }
    }
    if !lo.is_finite() {
        lo = 0.0;
        hi = 0.0;
    }
    for v in samples.iter_mut() {
        if v.is_nan() || *v == f32::NEG_INFINITY {
            *v = lo;
        } else if *v == f32::INFINITY {
            *v = hi;
        }
    }
}

/// Loads a volume, choosing the reader from `opts.raw` or the file name.
pub fn load(path: &Path, opts: &LoadOptions) -> Result<Volume, VolumeError> {
    if path.is_dir() {
        return Err(VolumeError::io(
            path,
            std::io::Error::new(std::io::ErrorKind::InvalidInput, "is a directory"),
        ));
    }
    if let Some(spec) = &opts.raw {
        return raw::read(path, spec, opts);
    }
    match Format::of(path) {
        Some(Format::Nrrd) => nrrd::read(path, opts),
        Some(Format::Nifti) => nifti::read(path, opts),
        Some(Format::MetaImage) => metaimage::read(path, opts),
        None => Err(VolumeError::UnknownFormat {
            path: path.to_path_buf(),
        }),
    }
}

/// Writes `vol` in the format its name chooses: NRRD (`.nrrd`, gzip when
/// `compressed`) or MetaImage (`.mha`, zlib when `compressed`). The
/// detached forms (`.nhdr`, `.mhd`) and NIfTI are read, not written.
pub fn write(path: &Path, vol: &Volume, compressed: bool) -> Result<(), VolumeError> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    match ext.as_deref() {
        Some("nrrd") => {
            let encoding = if compressed {
                nrrd::Encoding::Gzip
            } else {
                nrrd::Encoding::Raw
            };
            nrrd::write(path, vol, encoding)
        }
        Some("mha") => metaimage::write(path, vol, compressed),
        _ => Err(VolumeError::unsupported(
            path,
            format!("volumes are written as .{}", WRITTEN_FORMATS.join(" or .")),
        )),
    }
}

/// The extensions [`write`](fn@write) writes (the one table the CLI's
/// checks name).
pub const WRITTEN_FORMATS: [&str; 2] = ["nrrd", "mha"];

/// The volume formats [`load`] knows by their file names (anything else
/// needs a raw layout).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// `.nrrd`, `.nhdr`
    Nrrd,
    /// `.nii`, `.nii.gz`
    Nifti,
    /// `.mha`, `.mhd`
    MetaImage,
}

impl Format {
    pub fn of(path: &Path) -> Option<Format> {
        let name = path.file_name()?.to_string_lossy().to_ascii_lowercase();
        if name.ends_with(".nrrd") || name.ends_with(".nhdr") {
            Some(Format::Nrrd)
        } else if name.ends_with(".nii") || name.ends_with(".nii.gz") {
            Some(Format::Nifti)
        } else if name.ends_with(".mha") || name.ends_with(".mhd") {
            Some(Format::MetaImage)
        } else {
            None
        }
    }

    /// As a message names it: "a NRRD file".
    pub fn describe(self) -> &'static str {
        match self {
            Format::Nrrd => "a NRRD file",
            Format::Nifti => "a NIfTI-1 file",
            Format::MetaImage => "a MetaImage file",
        }
    }
}

/// A u8 volume of samples without structure, for tests: `(i·7919 + offset)
/// mod 251` at linear index `i` (a multiplicative scramble of the index).
#[cfg(test)]
pub(crate) fn scrambled_u8(dims: [usize; 3], offset: usize) -> Volume {
    let s: Vec<f32> = (0..dims.iter().product::<usize>())
        .map(|i| ((i * 7919 + offset) % 251) as f32)
        .collect();
    Volume::new(dims, [1.0; 3], SampleType::U8, s).unwrap()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every extension [`WRITTEN_FORMATS`] names writes (either case, plain
    /// and compressed) a file that loads back as the volume; any other is
    /// refused with the list.
    #[test]
    fn written_formats_are_what_write_writes() {
        let dir = std::env::temp_dir().join(format!("snell-write-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let vol = scrambled_u8([5, 4, 3], 2);
        for ext in WRITTEN_FORMATS {
            for (name, compressed) in [(ext.to_string(), false), (ext.to_uppercase(), true)] {
                let p = dir.join(format!("v.{name}"));
                write(&p, &vol, compressed).unwrap();
                let back = load(&p, &LoadOptions::default()).unwrap();
                assert_eq!(back.dims(), vol.dims(), "{name}");
                assert_eq!(back.samples(), vol.samples(), "{name}");
            }
        }
        for name in ["v.nhdr", "v.nii", "v.raw", "nrrd", "v.nrrd.txt"] {
            let err = write(&dir.join(name), &vol, false).unwrap_err().to_string();
            assert!(err.contains("written as .nrrd or .mha"), "{name}: {err}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Values f32 would round (labels above 2²⁴, f64 data far from 0) are
    /// stored relative to an offset that keeps their differences; values it
    /// holds exactly keep offset 0, bit for bit as before.
    #[test]
    fn samples_f32_would_round_keep_their_differences() {
        let p = Path::new("x");
        let labels: Vec<u8> = [16_777_216u32, 16_777_217, 16_777_300]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let d =
            decode_samples(p, &labels, SampleType::U32, Endian::Little, 3, None, false).unwrap();
        assert!(d.offset != 0.0);
        let vol = Volume::new([3, 1, 1], [1.0; 3], SampleType::U32, d.samples)
            .unwrap()
            .with_offset(d.offset);
        let got: Vec<f64> = (0..3).map(|x| vol.get(x, 0, 0)).collect();
        assert_eq!(got, [16_777_216.0, 16_777_217.0, 16_777_300.0]);
        assert_eq!(vol.value_range(), (16_777_216.0, 16_777_300.0));
        // f64 data: a pressure field 101325 + [0, 1).
        let values: [f64; 3] = [101325.0, 101325.25, 101325.5 + 1e-6];
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let d = decode_samples(p, &bytes, SampleType::F64, Endian::Little, 3, None, false).unwrap();
        let vol = Volume::new([3, 1, 1], [1.0; 3], SampleType::F64, d.samples)
            .unwrap()
            .with_offset(d.offset);
        for (x, want) in values.iter().enumerate() {
            assert!((vol.get(x, 0, 0) - want).abs() < 1e-7, "{x}");
        }
        let stats = vol.stats();
        assert!((stats.max - values[2]).abs() < 1e-7 && (stats.min - values[0]).abs() < 1e-7);
        // Written and read back (NRRD, f64): the same values.
        let dir = std::env::temp_dir().join(format!("snell-offset-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("o.nrrd");
        write(&file, &vol, false).unwrap();
        let back = load(&file, &LoadOptions::default()).unwrap();
        for x in 0..3 {
            assert!((back.get(x, 0, 0) - values[x]).abs() < 1e-7, "{x}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
        // Exactly held values: no offset, whatever the type.
        for (ty, bytes) in [
            (SampleType::U32, 16_777_216u32.to_le_bytes().to_vec()),
            (SampleType::F64, 0f64.to_le_bytes().to_vec()),
        ] {
            let n = bytes.len() / ty.size();
            let d = decode_samples(p, &bytes, ty, Endian::Little, n, None, false).unwrap();
            assert_eq!(d.offset, 0.0, "{ty}");
        }
        let exact = [f64::from(0.1f32), 3.0];
        let bytes: Vec<u8> = exact.iter().flat_map(|v| v.to_le_bytes()).collect();
        let d = decode_samples(p, &bytes, SampleType::F64, Endian::Little, 2, None, false).unwrap();
        assert_eq!((d.offset, d.samples), (0.0, vec![0.1f32, 3.0]));
    }

    #[test]
    fn decode_big_endian_u16_and_scaling() {
        let bytes = [0x01u8, 0x02, 0xff, 0xff];
        let d = decode_samples(
            Path::new("x"),
            &bytes,
            SampleType::U16,
            Endian::Big,
            2,
            Some((2.0, 1.0)),
            false,
        )
        .unwrap();
        assert_eq!((d.replaced, d.offset), (0, 0.0));
        assert_eq!(
            d.samples,
            vec![(0x0102 * 2 + 1) as f32, (65535 * 2 + 1) as f32]
        );
    }

    /// Finite f64 samples (or scaled ones) beyond f32's range are refused
    /// as such, with or without `allow_nan`: rounded to f32 they would be
    /// infinities the file does not hold, and replacing them would erase them.
    #[test]
    fn decode_refuses_finite_samples_beyond_f32() {
        let mut bytes = Vec::new();
        for v in [0.0f64, 1e39, -1e300, f64::INFINITY] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        for allow_nan in [false, true] {
            let p = Path::new("big.raw");
            let e = decode_samples(
                p,
                &bytes,
                SampleType::F64,
                Endian::Little,
                4,
                None,
                allow_nan,
            )
            .unwrap_err()
            .to_string();
            assert!(
                e.contains("big.raw: 2 samples (first at index 1, 1e39) are finite but beyond"),
                "{e}"
            );
        }
        let e = decode_samples(
            Path::new("s.nii"),
            &[200u8],
            SampleType::U8,
            Endian::Little,
            1,
            Some((1e37, 0.0)),
            false,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("1 samples (first at index 0, 2e39)"), "{e}");
        // f64 infinities are the file's own: the non-finite rule.
        let inf = f64::INFINITY.to_le_bytes();
        let e = decode_samples(
            Path::new("i"),
            &inf,
            SampleType::F64,
            Endian::Little,
            1,
            None,
            false,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("1 infinite"), "{e}");
    }

    #[test]
    fn decode_rejects_nan_unless_allowed() {
        let mut bytes = Vec::new();
        for v in [1.0f32, f32::NAN, 3.0, f32::INFINITY] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        let p = Path::new("f.raw");
        let err =
            decode_samples(p, &bytes, SampleType::F32, Endian::Little, 4, None, false).unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("f.raw") && msg.contains("1 NaN") && msg.contains("first at index 1"));
        let d = decode_samples(p, &bytes, SampleType::F32, Endian::Little, 4, None, true).unwrap();
        assert_eq!(d.replaced, 2);
        assert_eq!(d.samples, vec![1.0, 1.0, 3.0, 3.0]);
    }

    #[test]
    fn decode_reports_truncation() {
        let err = decode_samples(
            Path::new("t.raw"),
            &[0u8; 5],
            SampleType::U16,
            Endian::Little,
            3,
            None,
            false,
        )
        .unwrap_err();
        assert!(matches!(
            err,
            VolumeError::Truncated {
                need: 6,
                got: 5,
                ..
            }
        ));
    }

    /// A spacing each of whose axes is finite, but whose domain is not.
    #[test]
    fn extent_must_be_finite() {
        let v = |s: f64| Volume::new([3, 1, 1], [s, 1.0, 1.0], SampleType::U8, vec![0.0; 3]);
        assert!(v(f64::MAX / 2.0).is_ok());
        let e = v(f64::MAX).unwrap_err();
        assert!(e.to_string().contains("extent along x (2 spacings"), "{e}");
        let mut ok = v(1.0).unwrap();
        assert!(ok.set_spacing([1e308, 1.0, 1.0]).is_err());
        assert_eq!(ok.spacing(), [1.0; 3]);
        // One sample along an axis spans nothing, whatever its spacing.
        let one = Volume::new([1, 1, 1], [f64::MAX; 3], SampleType::U8, vec![0.0]);
        assert!(one.is_ok());
    }

    #[test]
    fn sample_count_overflow_and_limit() {
        let p = Path::new("big.nrrd");
        assert!(matches!(
            checked_sample_count(p, [usize::MAX, 2, 2], u64::MAX),
            Err(VolumeError::TooLarge { .. })
        ));
        assert!(matches!(
            checked_sample_count(p, [1024, 1024, 1024], 1 << 20),
            Err(VolumeError::OverLimit { source, .. }) if source.need == 17 << 30 && source.limit == 1 << 20
        ));
        assert!(checked_sample_count(p, [0, 2, 2], u64::MAX).is_err());
        assert_eq!(checked_sample_count(p, [2, 3, 4], u64::MAX).unwrap(), 24);
    }

    #[test]
    fn new_checks_shape() {
        assert!(Volume::new([2, 2, 2], [1.0; 3], SampleType::U8, vec![0.0; 7]).is_err());
        assert!(Volume::new([2, 2, 2], [1.0, 0.0, 1.0], SampleType::U8, vec![0.0; 8]).is_err());
        let v = Volume::new([2, 3, 4], [1.0, 2.0, 3.0], SampleType::U8, vec![0.0; 24]).unwrap();
        assert_eq!(v.extent(), [1.0, 4.0, 9.0]);
        assert_eq!(v.index(1, 2, 3), 1 + 2 * (2 + 3 * 3));
    }
}
