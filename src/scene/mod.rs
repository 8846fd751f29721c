//! Scene files: what to render, parsed from TOML into a validated [`Scene`].
//!
//! A scene names an image size, a camera, a volume (a file or a phantom), the
//! refracting surface (filter, iso-value, indices of refraction), the backdrop
//! and render settings. `--set section.key=value` overrides are applied to the
//! parsed TOML table before validation, so an override is checked exactly like
//! a value written in the file. Every error names the file and the key.

pub mod backdrop;
pub mod camera;
pub mod orbit;

use std::path::{Path, PathBuf};

use glam::DVec3;
use serde::Deserialize;

pub use backdrop::{Backdrop, Pattern, Texture};
pub use camera::{Camera, CameraError, Projection};
pub use orbit::{Orbit, OrbitError};

use crate::classify::Method;
use crate::filter::FilterKind;
use crate::phantom::PhantomSpec;
use crate::volume::{Endian, LoadOptions, RawSpec, SampleType, Volume, VolumeError};

/// Classification the cell traversals (`dda`, `octree`, `distance`) use when
/// the scene names none; `classify = "none"` makes `dda` bound each visited
/// cell from its coefficients on the fly instead.
pub const DEFAULT_CLASSIFY: Method = Method::Bezier(2);

/// Largest image side accepted (and 2^28 pixels in all).
pub const MAX_IMAGE_SIDE: u32 = 32768;
const MAX_IMAGE_PIXELS: u64 = 1 << 28;

/// Bytes a frame holds per pixel at its peak: the film (hit position, events,
/// colour: 24 B), the tiles' outputs before assembly (24 B), the anti-aliasing
/// colour buffer (12 B), and the copies made to encode PNG and EXR files
/// (about 27 B), rounded up.
pub const FRAME_BYTES_PER_PIXEL: u64 = 96;
/// Bytes of tile scratch per ray: the structure-of-arrays packet (153 B:
/// 17 `f64` columns, two of them for step traversal only, 6 of 4 bytes and
/// 5 of one) and its five stage queues (20 B), rounded up.
pub const TILE_BYTES_PER_RAY: u64 = 180;

/// Smallest `step` of step traversal, in voxels: bounds the samples per ray.
pub const MIN_STEP: f64 = 1e-4;

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: {msg}")]
    Syntax { path: PathBuf, msg: String },
    #[error("{path}: [{key}] {msg}")]
    Key {
        path: PathBuf,
        key: String,
        msg: String,
    },
    #[error("--set {arg}: {msg}")]
    Override { arg: String, msg: String },
    #[error(transparent)]
    Volume(#[from] VolumeError),
    #[error("{path}: phantom: {msg}")]
    Phantom { path: PathBuf, msg: String },
    #[error("render.coefficients = \"{storage}\": {msg}")]
    Storage { storage: &'static str, msg: String },
}

// ---------------------------------------------------------------------------
// The file format (what serde sees).

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    image: ImageCfg,
    camera: CameraCfg,
    volume: VolumeCfg,
    surface: SurfaceCfg,
    backdrop: BackdropCfg,
    #[serde(default)]
    render: RenderCfg,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct ImageCfg {
    width: u32,
    height: u32,
    /// Colour of rays that never reach the backdrop.
    #[serde(default = "default_background")]
    background: [f32; 3],
}

fn default_background() -> [f32; 3] {
    [0.25, 0.35, 0.55]
}

#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
#[serde(rename_all = "lowercase")]
enum CameraKind {
    #[default]
    Perspective,
    Orthographic,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct CameraCfg {
    #[serde(default)]
    kind: CameraKind,
    position: [f64; 3],
    look_at: [f64; 3],
    #[serde(default = "default_up")]
    up: [f64; 3],
    fov_y: Option<f64>,
    height: Option<f64>,
}

fn default_up() -> [f64; 3] {
    [0.0, 1.0, 0.0]
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct RawCfg {
    dims: [usize; 3],
    #[serde(rename = "type")]
    sample_type: String,
    #[serde(default = "default_endian")]
    endian: String,
    #[serde(default)]
    offset: u64,
}

fn default_endian() -> String {
    "little".into()
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct VolumeCfg {
    path: Option<String>,
    /// Read as a [`PhantomSpec`] by [`phantom_spec`], whose errors name the
    /// key inside the table (serde's tagged enums lose the path).
    phantom: Option<toml::Value>,
    raw: Option<RawCfg>,
    /// Overrides the file's spacing.
    spacing: Option<[f64; 3]>,
    #[serde(default)]
    allow_nan: bool,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct SurfaceCfg {
    filter: String,
    /// The smoothing weight of `smooth-bspline3` (required by it).
    lambda: Option<f64>,
    iso: f64,
    #[serde(default = "default_ior")]
    ior: f64,
    #[serde(default = "default_outside_ior")]
    outside_ior: f64,
}

fn default_ior() -> f64 {
    1.5
}
fn default_outside_ior() -> f64 {
    1.0
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct BackdropCfg {
    center: [f64; 3],
    normal: [f64; 3],
    u_axis: [f64; 3],
    checker: Option<f64>,
    /// `[even, odd]` square colours (default white, black).
    checker_colors: Option<[[f32; 3]; 2]>,
    image: Option<String>,
    width: Option<f64>,
    /// Colour beyond the photograph's edges.
    outside: Option<[f32; 3]>,
}

/// How the prefiltered coefficients are stored (the arithmetic is `f64`
/// either way).
#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Storage {
    /// 8 bytes per coefficient: the renderer adds no error to the filter's.
    #[default]
    F64,
    /// 4 bytes per coefficient: half the coefficients' memory (the 1024³
    /// phantom's peak 13.8 → 9.9 GiB, BENCHMARKS.md scaling). The
    /// prefilter runs in place, each line in `f64`, rounding to `f32` after
    /// each axis pass (within 4 `f32` ulps of the largest coefficient,
    /// tested); on the glass sphere the hits move by a median 1.5e-5
    /// backdrop units (`tests/storage.rs`).
    F32,
    /// 2 bytes per coefficient (11 significant bits, at most ±65504): a
    /// quarter of `f64`'s memory. Prefiltered as `f32`, less the scene's
    /// iso-value (so the values near the surface are small, where `f16`
    /// is precise), then rounded once; a field whose shifted coefficients
    /// exceed the range is refused. What it costs in accuracy is measured
    /// in BENCHMARKS.md (*Coefficient storage*) and `tests/storage.rs`.
    F16,
}

impl Storage {
    pub fn name(self) -> &'static str {
        match self {
            Storage::F64 => "f64",
            Storage::F32 => "f32",
            Storage::F16 => "f16",
        }
    }
}

/// Space traversal strategy (see `render::stages::traverse`).
#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Traversal {
    /// Fixed-step ray casting with Brent refinement: the paper's baseline.
    Step,
    /// 3-D DDA cell by cell, exact per-cell crossings.
    Dda,
    /// Top-down octree over classified cells, DDA inside occupied leaves.
    /// The default: the fastest one-shot render of the CT scenes (its
    /// structures build quickly; `distance` walks fewer cells but builds
    /// eight maps first, which pays off only on the small sphere — times in
    /// README), with the same hits as `dda` bit for bit.
    #[default]
    Octree,
    /// Jumps over the largest empty cube anchored at the ray's cell and
    /// reaching ahead in its direction's octant (beyond the paper; see
    /// `octree::distance`).
    Distance,
}

/// How each pixel's colour is anti-aliased (see `film::prss`).
#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Supersampling {
    /// One ray through the pixel centre.
    #[default]
    None,
    /// Real supersampling: `samples × samples` rays on a regular grid.
    Grid,
    /// Real supersampling: one jittered ray per stratum (seeded).
    Jitter,
    /// Post-refraction supersampling from the hit-position image (the paper).
    Prss,
    /// The pixel's backdrop footprint from hit-position differences, box or
    /// EWA filtered (`footprint`).
    Footprint,
}

impl Supersampling {
    /// Rays a pixel sends in the first pass with `samples` per axis: the
    /// centre's, and for real supersampling the grid's or strata's too.
    pub fn first_pass_rays(self, samples: u32) -> u64 {
        let n = samples as u64;
        match self {
            Supersampling::Grid | Supersampling::Jitter => n * n + 1,
            _ => 1,
        }
    }
}

/// What PRSS does where a pixel's neighbours cannot be interpolated (no
/// backdrop hit, or a different number of interfaces crossed).
#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum PrssFallback {
    /// Extrapolate the missing neighbours linearly from the centre's own
    /// (consistent) neighbours; the whole pixel keeps the centre's surface.
    Mirror,
    /// Extrapolate like `mirror`, and blend in the neighbours' own surfaces
    /// (or the background where they miss the backdrop) over the part of the
    /// pixel nearer to them, weighted by the bilinear hat of each pixel
    /// centre: the expected coverage when the boundary lies anywhere between
    /// the two centres.
    #[default]
    Blend,
    /// Blend like `blend`, but re-trace with real sub-pixel rays the pixels
    /// whose neighbourhood no straight boundary explains (pieces a pixel or
    /// two wide: chains of internal reflections at a rim), and the boundary
    /// pixels next to them.
    #[serde(rename = "blend-trace")]
    BlendTrace,
    /// Use the centre hit for the missing neighbours.
    Nearest,
    /// Trace real sub-pixel rays for the pixel (adaptive supersampling).
    Trace,
}

/// How PRSS interpolates the hit map between a pixel and its neighbours.
#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum PrssMap {
    /// Straight lines from the centre to each of the 8 neighbours, bilinear in
    /// each quadrant (the paper's intermediate points).
    Bilinear,
    /// The biquadratic through the 3×3 neighbourhood: smooth across the
    /// quadrants, exact for maps that bend quadratically.
    Biquadratic,
    /// Catmull-Rom through the 5×5 neighbourhood (the paper's larger ring).
    #[default]
    Bicubic,
}

/// The filter footprint anti-aliasing integrates the backdrop with.
#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum FootprintFilter {
    /// The pixel square mapped through the Jacobian (a parallelogram), box
    /// filtered: exact coverage for checkers.
    #[default]
    Box,
    /// An elliptical Gaussian (Heckbert's EWA): the pixel's Gaussian mapped
    /// through the Jacobian.
    Ewa,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct RenderCfg {
    #[serde(default)]
    traversal: Traversal,
    #[serde(default = "default_step")]
    step: f64,
    #[serde(default = "default_max_events")]
    max_events: u32,
    #[serde(default = "default_tolerance")]
    tolerance: f64,
    /// Tile side in pixels; unset means [`default_tile`].
    #[serde(default)]
    tile: Option<u32>,
    /// `none`, `bmcc`, `accc`, `accc2`, `accc4`, `accc8`, `bezier` (see `classify`);
    /// unset means [`DEFAULT_CLASSIFY`] for cell traversals.
    #[serde(default)]
    classify: Option<String>,
    /// Octree leaf side in cells (a power of two).
    #[serde(default = "default_leaf")]
    leaf: u32,
    #[serde(default)]
    supersampling: Supersampling,
    #[serde(default = "default_samples")]
    samples: u32,
    /// PRSS sub-points per pixel side (and footprint samples of photographs).
    #[serde(default = "default_prss_samples")]
    prss_samples: u32,
    /// How PRSS interpolates the hit map between neighbours.
    #[serde(default)]
    prss_map: PrssMap,
    #[serde(default)]
    prss_fallback: PrssFallback,
    /// The filter of `supersampling = "footprint"`.
    #[serde(default)]
    footprint: FootprintFilter,
    /// With `prss_fallback = "trace"`: re-trace pixels whose hit map bends by
    /// more than this many checker squares (or texels) between neighbours.
    #[serde(default = "default_curvature")]
    prss_curvature: f64,
    #[serde(default)]
    seed: u64,
    /// Coefficient storage: `f64` (default) or `f32`.
    #[serde(default)]
    coefficients: Storage,
    /// Skip the cells after a crossing that curvature bounds prove empty.
    #[serde(default = "default_true")]
    clear_crossing_cells: bool,
    /// Start primary rays where the first occupied octree block can be.
    #[serde(default = "default_true")]
    skip_empty_approach: bool,
    /// Pass over the segments a cell's plane bound proves clear.
    #[serde(default = "default_true")]
    skip_clear_segments: bool,
}

fn default_step() -> f64 {
    0.1
}
fn default_max_events() -> u32 {
    32
}
fn default_tolerance() -> f64 {
    1e-7
}
/// Rays a default tile traces in its first pass, about.
const TILE_RAYS: u32 = 1024;

/// The default tile side for `rays_per_pixel` first-pass rays: the largest
/// power of two up to 32 whose tile traces at most twice [`TILE_RAYS`]
/// rays (32 pixels at one ray a pixel, 16 at 2×2 grid or jitter
/// supersampling, 8 at 4×4), at least 1. A tile's rays go through the
/// stages together, and it ends with a tail of rounds in which a few rays
/// (several refractions deep, or reflected inside) leave the vector lanes
/// mostly empty; bigger tiles share that tail among more rays, while a
/// packet past the L2 cache costs more than it saves. Measured (2 threads,
/// PRSS, frame bench, 5–6 alternating runs, min): 16-pixel tiles against
/// 32, teapot 124.7 → 117.0 ms, sphere 42.1 → 41.0, cranium within the
/// noise, 64 and 48 as 32, 128 slower; grid supersampling at 4×4 rays (17
/// per pixel), sphere: 8-pixel tiles 553 ms, 16 567, 32 574.
fn default_tile(rays_per_pixel: u32) -> u32 {
    let mut side = 32;
    while side > 1 && side * side * rays_per_pixel > 2 * TILE_RAYS {
        side /= 2;
    }
    side
}
fn default_samples() -> u32 {
    4
}
fn default_prss_samples() -> u32 {
    8
}
fn default_leaf() -> u32 {
    // With the flattened skip map a step costs the same at any level, so
    // the finest leaves skip the most (measured: sphere, teapot and cranium
    // traverse 6–11% faster than with 4-cell leaves).
    1
}
fn default_curvature() -> f64 {
    0.25
}
fn default_true() -> bool {
    true
}

impl Default for RenderCfg {
    fn default() -> Self {
        RenderCfg {
            traversal: Traversal::default(),
            step: default_step(),
            max_events: default_max_events(),
            tolerance: default_tolerance(),
            tile: None,
            classify: None,
            leaf: default_leaf(),
            supersampling: Supersampling::default(),
            samples: default_samples(),
            prss_samples: default_prss_samples(),
            prss_map: PrssMap::default(),
            prss_fallback: PrssFallback::default(),
            footprint: FootprintFilter::default(),
            prss_curvature: default_curvature(),
            seed: 0,
            coefficients: Storage::default(),
            clear_crossing_cells: true,
            skip_empty_approach: true,
            skip_clear_segments: true,
        }
    }
}

// ---------------------------------------------------------------------------
// The validated scene.

/// Where the volume comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum VolumeSource {
    File {
        path: PathBuf,
        raw: Option<RawSpec>,
        allow_nan: bool,
    },
    Phantom(PhantomSpec),
}

/// The refracting iso-surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Surface {
    pub filter: FilterKind,
    pub iso: f64,
    /// Index of refraction where `f > iso` (the object).
    pub ior: f64,
    /// Index of refraction where `f <= iso` (the surrounding medium).
    pub outside_ior: f64,
}

/// Render settings after validation.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct RenderSettings {
    pub traversal: Traversal,
    /// Step of `step` traversal, in voxels (grid units along the ray).
    pub step: f64,
    pub max_events: u32,
    /// Crossing tolerance in voxels.
    pub tolerance: f64,
    /// Tile side in pixels.
    pub tile: u32,
    /// Precomputed classification (`None`: a bound per cell, on the fly).
    pub classify: Option<Method>,
    /// Octree leaf side in cells.
    pub leaf: u32,
    pub supersampling: Supersampling,
    /// `N` for `N×N` rays per pixel (grid, jitter, and pixels the PRSS and
    /// footprint fallbacks re-trace).
    pub samples: u32,
    /// `N` for `N×N` PRSS sub-points per pixel (footprint: samples over a
    /// photograph's box footprint).
    pub prss_samples: u32,
    pub prss_map: PrssMap,
    pub prss_fallback: PrssFallback,
    pub footprint: FootprintFilter,
    pub prss_curvature: f64,
    pub seed: u64,
    pub coefficients: Storage,
    /// A ray leaving a crossing skips the rest of the cell it starts in, and
    /// the cells after it among that cell's neighbours, where the field's
    /// second-derivative bounds
    /// prove they hold no other crossing (B-splines of degree ≥ 2 with
    /// precomputed tags; the solves there would find nothing, so no output
    /// bit changes — tested). Off only to measure what it saves.
    pub clear_crossing_cells: bool,
    /// Primary rays start their walk at a per-pixel-block lower bound on
    /// where they can first meet a tagged cell, from the octree's occupied
    /// blocks projected into the image ([`crate::render::first_hit`]);
    /// octree and distance traversals (`dda` stays the plain walk the paper
    /// measures). No output bit changes — tested. Off only to measure what it
    /// saves.
    pub skip_empty_approach: bool,
    /// The solve stage passes over the segments that a tagged cell's plane
    /// and its bound prove clear of the iso-surface
    /// ([`crate::classify::plane`]; cell traversals with precomputed tags:
    /// the solves there would find nothing, so no output bit changes —
    /// tested). Off only to measure what it saves.
    pub skip_clear_segments: bool,
}

impl RenderSettings {
    /// Whether the solve stage passes over segments its planes prove clear
    /// (see [`RenderSettings::skip_clear_segments`]).
    pub fn skips_clear_segments(&self) -> bool {
        self.traversal != Traversal::Step && self.skip_clear_segments
    }

    /// Whether primary rays skip their empty approach (see
    /// [`RenderSettings::skip_empty_approach`]).
    pub fn skips_empty_approach(&self) -> bool {
        matches!(self.traversal, Traversal::Octree | Traversal::Distance)
            && self.skip_empty_approach
    }

    /// Whether renders clear crossing cells: a cell traversal with
    /// `clear_crossing_cells` on (the bounds exist only with precomputed tags).
    pub fn clears_crossing_cells(&self) -> bool {
        self.traversal != Traversal::Step && self.clear_crossing_cells
    }
}

/// A scene ready to render (the volume is loaded separately, so caches can
/// share it across scenes).
#[derive(Clone, Debug)]
pub struct Scene {
    /// The file it came from, for messages (or a name for built-in scenes).
    pub path: PathBuf,
    pub width: u32,
    pub height: u32,
    pub background: [f32; 3],
    pub camera: Camera,
    pub volume: VolumeSource,
    /// Spacing that overrides the volume's own.
    pub spacing: Option<[f64; 3]>,
    pub surface: Surface,
    pub backdrop: Backdrop,
    /// The photograph the backdrop shows, if any, as a path.
    pub backdrop_image: Option<PathBuf>,
    pub render: RenderSettings,
    /// Settings the scene file or `--set` wrote that this scene does not
    /// use, one message each (see [`Scene::ignored_settings`]).
    ignored: Vec<String>,
    /// The `--set` overrides it was read with, to name one as the cause of
    /// an error found later (in [`Scene::load_volume`]).
    overrides: Vec<String>,
    /// The keys the file or `--set` wrote (see [`written_keys`]).
    written: Vec<(String, String)>,
}

impl Scene {
    /// The settings the user wrote (in the file or with `--set`; defaults
    /// never count) that have no effect on this scene, each as a message
    /// naming the key and why: `camera.fov_y`/`camera.height` of the other
    /// projection, `backdrop.width`/`outside` with a checker and
    /// `checker_colors` with a photograph, `render.step` with a cell
    /// traversal, the anti-aliasing settings with `supersampling = "none"`
    /// (and `footprint` without the footprint mode), and `surface.lambda`
    /// with a filter that does not smooth.
    pub fn ignored_settings(&self) -> &[String] {
        &self.ignored
    }

    /// The files the scene reads: its own, its volume file and its
    /// backdrop photograph (the ones a command must not write over).
    pub fn input_files(&self) -> Vec<&Path> {
        let volume = match &self.volume {
            VolumeSource::File { path, .. } => Some(path.as_path()),
            VolumeSource::Phantom(_) => None,
        };
        std::iter::once(self.path.as_path())
            .chain(volume)
            .chain(self.backdrop_image.as_deref())
            .collect()
    }

    /// Reads, overrides and validates a scene file.
    pub fn load(path: &Path, overrides: &[String]) -> Result<Scene, SceneError> {
        let text = crate::input::read_to_string(path).map_err(|source| SceneError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Scene::parse(&text, path, overrides)
    }

    /// Parses scene text; `path` is used for messages and relative paths.
    /// An error caused by a `--set` override names that override, not the
    /// file.
    pub fn parse(text: &str, path: &Path, overrides: &[String]) -> Result<Scene, SceneError> {
        let mut table: toml::Table = text
            .parse()
            .map_err(|e: toml::de::Error| syntax_error(text, path, &e))?;
        for o in overrides {
            apply_override(&mut table, o)?;
        }
        let mut written = Vec::new();
        written_keys(&table, "", &mut written);
        // A key an override set is named as that override in warnings.
        for (key, shown) in &mut written {
            if let Some(o) = culprit_override(key, overrides) {
                *shown = format!("--set {o}");
            }
        }
        let de = toml::Value::Table(table);
        let key_error = |key: String, msg: String| SceneError::Key {
            path: path.to_path_buf(),
            key,
            msg,
        };
        let result = serde_path_to_error::deserialize(de)
            .map_err(|e| {
                let key = e.path().to_string();
                let key = if key == "." { "scene".into() } else { key };
                key_error(key, plain_serde_message(e.into_inner().message()))
            })
            .and_then(|file: SceneFile| {
                let phantom = match &file.volume.phantom {
                    None => None,
                    Some(v) => Some(phantom_spec(v.clone()).map_err(|(k, m)| key_error(k, m))?),
                };
                resolve(file, phantom, path, &written)
            });
        match result {
            Ok(mut scene) => {
                scene.overrides = overrides.to_vec();
                scene.written = written;
                Ok(scene)
            }
            Err(e) => Err(blame_override(e, overrides, &written)),
        }
    }

    /// Loads (or builds) the volume and applies the scene's spacing override.
    /// An error on a key a `--set` wrote names that `--set`.
    pub fn load_volume(&self, opts: &LoadOptions) -> Result<Volume, SceneError> {
        self.load_volume_unblamed(opts)
            .map_err(|e| blame_override(e, &self.overrides, &self.written))
    }

    fn load_volume_unblamed(&self, opts: &LoadOptions) -> Result<Volume, SceneError> {
        let mut vol = match &self.volume {
            VolumeSource::File {
                path,
                raw,
                allow_nan,
            } => {
                let opts = LoadOptions {
                    allow_nan: *allow_nan || opts.allow_nan,
                    raw: raw.clone(),
                    ..opts.clone()
                };
                crate::volume::load(path, &opts).map_err(|e| match e {
                    // The reader's message names the command line's raw
                    // options; a scene sets them in [volume.raw].
                    VolumeError::UnknownFormat { path: file } => SceneError::Key {
                        path: self.path.clone(),
                        key: "volume.path".into(),
                        msg: format!(
                            "{}: unknown volume format (expected .nrrd, .nhdr, .nii, .nii.gz, .mha or .mhd; a headerless raw file needs a [volume.raw] table with dims = [X, Y, Z] and type = \"u16\" (u8, i8, u16, i16, u32, i32, f32, f64), optionally endian = \"big\" and offset = BYTES)",
                            file.display()
                        ),
                    },
                    e => e.into(),
                })?
            }
            VolumeSource::Phantom(spec) => {
                let phantom_error = |msg: String| SceneError::Phantom {
                    path: self.path.clone(),
                    msg,
                };
                // Against the caller's limit, before the grid is allocated.
                crate::volume::checked_sample_count(&self.path, spec.dims(), opts.memory_limit)
                    .map_err(|e| match e {
                        VolumeError::TooLarge { msg, .. } => SceneError::Key {
                            path: self.path.clone(),
                            key: "volume.phantom.size".into(),
                            msg,
                        },
                        e => phantom_error(e.to_string()),
                    })?;
                // Its settings were checked when the scene was read.
                spec.build().map_err(|e| phantom_error(e.to_string()))?
            }
        };
        if let Some(s) = self.spacing {
            vol.set_spacing(s)?;
        }
        crate::volume::check_spacing_ratio(vol.spacing()).map_err(|e| SceneError::Key {
            path: self.path.clone(),
            key: "volume.spacing".into(),
            msg: format!("the volume's {e}; set volume.spacing to override it"),
        })?;
        Ok(vol)
    }

    /// The scene's checker size, if the backdrop is a checkerboard.
    pub fn checker_size(&self) -> Option<f64> {
        self.backdrop.checker_size()
    }

    /// Most rays one tile traces at once (its packet's capacity).
    pub fn rays_per_pixel(&self) -> u64 {
        let n = self.render.samples as u64;
        match self.render.supersampling {
            Supersampling::Prss | Supersampling::Footprint
                if matches!(
                    self.render.prss_fallback,
                    PrssFallback::Trace | PrssFallback::BlendTrace
                ) =>
            {
                n * n
            }
            s => s.first_pass_rays(self.render.samples),
        }
    }

    /// Memory a render needs besides the volume: frame buffers for every
    /// pixel, and one tile's ray packet per worker thread.
    pub fn memory_need(&self, threads: usize) -> (u64, u64) {
        let pixels = self.width as u64 * self.height as u64;
        let tile = self.render.tile as u64;
        let tile_rays = tile * tile * self.rays_per_pixel();
        (
            pixels * FRAME_BYTES_PER_PIXEL,
            threads.max(1) as u64 * tile_rays * TILE_BYTES_PER_RAY,
        )
    }

    /// Refuses (before anything is allocated) a render whose frame buffers
    /// and tile scratch would exceed `limit` bytes.
    pub fn check_memory(&self, limit: u64, threads: usize) -> Result<(), SceneError> {
        let (frame, scratch) = self.memory_need(threads);
        let need = frame.saturating_add(scratch);
        if need <= limit {
            return Ok(());
        }
        let hb = crate::volume::limits::human_bytes;
        Err(SceneError::Key {
            path: self.path.clone(),
            key: if scratch > frame {
                "render.samples"
            } else {
                "image"
            }
            .into(),
            msg: format!(
                "a {}x{} image at {} rays per pixel needs about {} of memory (frame {}, tile scratch {} for {} of {}x{}-pixel tiles), over the limit of {}; lower the size, render.samples, render.tile or --threads, or raise SNELL_MEMORY_LIMIT (--memory-limit)",
                self.width,
                self.height,
                self.rays_per_pixel(),
                hb(need),
                hb(frame),
                hb(scratch),
                match threads.max(1) {
                    1 => "1 thread".to_string(),
                    n => format!("{n} threads"),
                },
                self.render.tile,
                self.render.tile,
                hb(limit)
            ),
        })
    }
}

/// Applies `section.key=value` (value in TOML syntax; bare words are strings).
pub fn apply_override(table: &mut toml::Table, arg: &str) -> Result<(), SceneError> {
    let err = |msg: &str| SceneError::Override {
        arg: arg.to_string(),
        msg: msg.to_string(),
    };
    let (_, value) = arg
        .split_once('=')
        .ok_or_else(|| err("expected section.key=value"))?;
    let key = override_key(arg);
    let parts: Vec<&str> = key.split('.').collect();
    if parts.iter().any(|p| p.is_empty()) {
        return Err(err("empty key"));
    }
    let value = value.trim();
    let parsed: toml::Value = match format!("v = {value}").parse::<toml::Table>() {
        Ok(mut t) => t.remove("v").unwrap_or(toml::Value::String(value.into())),
        // A number TOML cannot hold is refused as in a file, not taken
        // for a word.
        Err(_) => match number_reason(value) {
            Some(msg) => return Err(err(&msg)),
            None => toml::Value::String(value.to_string()),
        },
    };
    let mut cur = table;
    for p in &parts[..parts.len() - 1] {
        let entry = cur
            .entry(p.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        cur = entry
            .as_table_mut()
            .ok_or_else(|| err(&format!("'{p}' is not a section")))?;
    }
    let last = parts[parts.len() - 1];
    // Switching a volume between file and phantom: drop the other source.
    if parts.len() >= 2 && parts[parts.len() - 2] == "volume" {
        if last == "path" {
            cur.remove("phantom");
        } else if last == "phantom" {
            cur.remove("path");
        }
    }
    cur.insert(last.to_string(), parsed);
    Ok(())
}

fn vec3(v: [f64; 3]) -> DVec3 {
    DVec3::from_array(v)
}

/// `v` divided by its largest absolute component (zero and non-finite
/// vectors unchanged): the same direction, with a length from 1 to √3.
pub(crate) fn unit_scale(v: DVec3) -> DVec3 {
    let m = v.abs().max_element();
    if m > 0.0 && m.is_finite() { v / m } else { v }
}

/// Reads `[volume.phantom]`: its `kind`, then the kind's settings, each
/// error with the key inside the table (`volume.phantom.size`).
fn phantom_spec(v: toml::Value) -> Result<PhantomSpec, (String, String)> {
    let toml::Value::Table(mut t) = v else {
        return Err((
            "volume.phantom".into(),
            format!(
                "expected a table of phantom settings, got {}",
                plain_value(&v)
            ),
        ));
    };
    let kind = t.remove("kind");
    fn read<T: serde::de::DeserializeOwned>(t: toml::Table) -> Result<T, (String, String)> {
        serde_path_to_error::deserialize(toml::Value::Table(t)).map_err(|e| {
            let key = e.path().to_string();
            let key = if key == "." {
                "volume.phantom".to_string()
            } else {
                format!("volume.phantom.{key}")
            };
            (key, plain_serde_message(e.into_inner().message()))
        })
    }
    match kind.as_ref().and_then(|k| k.as_str()) {
        Some("sphere") => Ok(PhantomSpec::Sphere(read(t)?)),
        Some("marschner-lobb") => Ok(PhantomSpec::MarschnerLobb(read(t)?)),
        _ => Err((
            "volume.phantom.kind".into(),
            match kind {
                None => "missing: give kind = \"sphere\" or \"marschner-lobb\"".into(),
                Some(k) => format!(
                    "expected \"sphere\" or \"marschner-lobb\", got {}",
                    plain_value(&k)
                ),
            },
        )),
    }
}

/// A value as the user wrote it, for messages: `the text "1.5"`, `32.0`,
/// `a table`, `an array`.
fn plain_value(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => format!("the text {s:?}"),
        toml::Value::Table(_) => "a table".into(),
        toml::Value::Array(_) => "an array".into(),
        v => v.to_string(),
    }
}

/// serde's messages in plain words: `invalid type: string "1.5", expected
/// f64` becomes `expected a number, got the text "1.5"`, Rust type names
/// become ranges (`u32`: a whole number from 0 to 4294967295; TOML's
/// integers are `i64`, so `u64` and `usize` reach 9223372036854775807) and
/// the struct names the settings they hold. `msg` is the message alone
/// ([`toml::de::Error::message`]): the caller names the key.
pub(crate) fn plain_serde_message(msg: &str) -> String {
    let msg = msg.trim().replace('\n', " ");
    let expected = |e: &str| -> String {
        let e = e.trim();
        match e {
            "f64" | "f32" => "a number".into(),
            "u8" => "a whole number from 0 to 255".into(),
            "u16" => "a whole number from 0 to 65535".into(),
            "u32" => format!("a whole number from 0 to {}", u32::MAX),
            "u64" | "usize" => format!("a whole number from 0 to {}", i64::MAX),
            "i8" | "i16" | "i32" | "i64" | "isize" => "a whole number".into(),
            "a boolean" => "true or false".into(),
            "a string" | "string" => "text in quotes".into(),
            "a sequence" => "an array".into(),
            _ => {
                if let Some(n) = e.strip_prefix("an array of length ") {
                    return format!("an array of {n} values");
                }
                if let Some(name) = e.strip_prefix("struct ") {
                    let what = match name {
                        "SceneFile" => "scene",
                        "ImageCfg" => "image",
                        "CameraCfg" => "camera",
                        "VolumeCfg" => "volume",
                        "RawCfg" => "raw volume",
                        "SurfaceCfg" => "surface",
                        "BackdropCfg" => "backdrop",
                        "RenderCfg" => "render",
                        "SphereSpec" => "sphere phantom",
                        "MarschnerLobbSpec" => "Marschner-Lobb phantom",
                        "Hole" => "hole",
                        other => other,
                    };
                    return format!("a table of {what} settings");
                }
                e.to_string()
            }
        }
    };
    let got = |u: &str| -> String {
        let u = u.trim();
        let unquote = |s: &str| s.trim_matches('`').to_string();
        if let Some(s) = u.strip_prefix("string ") {
            format!("the text {s}")
        } else if let Some(s) = u
            .strip_prefix("floating point ")
            .or_else(|| u.strip_prefix("integer "))
            .or_else(|| u.strip_prefix("boolean "))
        {
            unquote(s)
        } else {
            match u {
                "map" => "a table".into(),
                "sequence" => "an array".into(),
                other => other.to_string(),
            }
        }
    };
    for prefix in ["invalid type: ", "invalid value: "] {
        if let Some(rest) = msg.strip_prefix(prefix)
            && let Some((u, e)) = rest.rsplit_once(", expected ")
        {
            return format!("expected {}, got {}", expected(e), got(u));
        }
    }
    if let Some(rest) = msg.strip_prefix("invalid length ")
        && let Some((n, e)) = rest.split_once(", expected ")
    {
        return format!("expected {}, got {n}", expected(e));
    }
    if let Some(rest) = msg.strip_prefix("missing field ") {
        return format!("missing key {rest}");
    }
    if let Some(rest) = msg.strip_prefix("unknown field ") {
        return format!("unknown key {rest}");
    }
    // serde lists the variants as `a`, `a` or `b`, or one of `a`, `b`, `c`.
    if let Some(rest) = msg.strip_prefix("unknown variant ")
        && let Some((got, expected)) = rest.split_once(", expected ")
    {
        return format!(
            "expected {}, got \"{}\"",
            expected.replace('`', "\""),
            got.trim_matches('`')
        );
    }
    msg
}

/// Why TOML refused `text` if it is a number TOML cannot hold, in the
/// words both a scene file and a `--set` value get: an integer literal
/// outside `i64` (TOML's integers), or a float literal beyond `f64`.
/// Decided from the literal itself, since TOML words these refusals
/// differently by size.
fn number_reason(text: &str) -> Option<String> {
    let text = text.trim();
    let t: String = text.chars().filter(|&c| c != '_').collect();
    let (negative, unsigned) = match t.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, t.strip_prefix('+').unwrap_or(&t)),
    };
    let (radix, digits) = match unsigned.get(..2) {
        Some("0x") if unsigned.len() == t.len() => (16, &unsigned[2..]),
        Some("0o") if unsigned.len() == t.len() => (8, &unsigned[2..]),
        Some("0b") if unsigned.len() == t.len() => (2, &unsigned[2..]),
        _ => (10, unsigned),
    };
    if !digits.is_empty() && digits.chars().all(|c| c.is_digit(radix)) {
        // Digits beyond i128 do not fit i64 either.
        let fits = i128::from_str_radix(digits, radix)
            .ok()
            .and_then(|v| i64::try_from(if negative { -v } else { v }).ok())
            .is_some();
        return (!fits).then(|| {
            if negative {
                format!(
                    "whole numbers go down to {} (TOML integers are signed 64-bit), got {text}",
                    i64::MIN
                )
            } else {
                format!(
                    "whole numbers go up to {} (TOML integers are signed 64-bit), got {text}",
                    i64::MAX
                )
            }
        });
    }
    let float_syntax = unsigned.starts_with(|c: char| c.is_ascii_digit())
        && unsigned
            .chars()
            .all(|c| c.is_ascii_digit() || matches!(c, '.' | 'e' | 'E' | '+' | '-'));
    (float_syntax && t.parse::<f64>().is_ok_and(f64::is_infinite)).then(|| {
        format!("numbers must be finite; {text} is beyond the largest 64-bit float (about 1.8e308)")
    })
}

/// `s` as a TOML key (`camera.look_at`, `"a b".c`), without the `[`/`]`
/// of a header or the `=` after it.
fn is_toml_key(s: &str) -> bool {
    s.split('.').all(|part| {
        let part = part.trim();
        let bare = !part.is_empty()
            && part
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
        let quoted = part.len() >= 2
            && part.starts_with('"')
            && part.ends_with('"')
            && !part[1..part.len() - 1].contains('"');
        bare || quoted
    })
}

/// `line` without a trailing `# comment` (none inside quotes).
fn strip_comment(line: &str) -> &str {
    let mut quoted = false;
    for (i, c) in line.char_indices() {
        match c {
            '"' => quoted = !quoted,
            '#' if !quoted => return &line[..i],
            _ => {}
        }
    }
    line
}

/// The table a `[section]` (or `[[section]]`) header line names, if the
/// line is one.
fn section_header(line: &str) -> Option<String> {
    let l = strip_comment(line).trim();
    let name = l
        .strip_prefix("[[")
        .and_then(|l| l.strip_suffix("]]"))
        .or_else(|| l.strip_prefix('[').and_then(|l| l.strip_suffix(']')))?;
    is_toml_key(name).then(|| dotted_key(name))
}

/// A TOML key as the messages write it: parts trimmed, quotes dropped.
fn dotted_key(key: &str) -> String {
    key.split('.')
        .map(|p| p.trim().trim_matches('"'))
        .collect::<Vec<_>>()
        .join(".")
}

/// A scene file TOML refused: a number out of TOML's range is named by its
/// key (as a `--set` of the same value is); other syntax errors keep TOML's
/// message on one line.
fn syntax_error(text: &str, path: &Path, e: &toml::de::Error) -> SceneError {
    let plain = || SceneError::Syntax {
        path: path.to_path_buf(),
        msg: e.to_string().trim().replace('\n', " "),
    };
    let Some(span) = e.span() else {
        return plain();
    };
    let Some(value) = text.get(span.clone()) else {
        return plain();
    };
    let Some(reason) = number_reason(value) else {
        return plain();
    };
    // The key: a `key =` line (the value may follow it on the line, in an
    // inline array say), under the last `[section]` header above it;
    // inside a multi-line array the line alone names no key.
    let line_start = text[..span.start].rfind('\n').map_or(0, |i| i + 1);
    let line = &text[line_start..span.start];
    let key = line
        .split_once('=')
        .map(|(k, _)| k)
        .filter(|k| is_toml_key(k))
        .map(dotted_key);
    let line_no = text[..span.start].matches('\n').count() + 1;
    let key = match key {
        Some(key) => match text[..line_start].lines().rev().find_map(section_header) {
            Some(section) => format!("{section}.{key}"),
            None => key,
        },
        None => format!("line {line_no}"),
    };
    SceneError::Key {
        path: path.to_path_buf(),
        key,
        msg: reason,
    }
}

/// The key a `--set key=value` sets, as the scene's keys are written
/// (`camera . fov_y` is `camera.fov_y`).
fn override_key(arg: &str) -> String {
    let key = arg.split_once('=').map_or(arg, |(k, _)| k);
    key.split('.').map(str::trim).collect::<Vec<_>>().join(".")
}

/// The override that wrote `key` or a table holding it (the last one, as
/// the last wins in the table).
fn culprit_override<'a>(key: &str, overrides: &'a [String]) -> Option<&'a String> {
    overrides.iter().rev().find(|o| {
        let k = override_key(o);
        key == k || key.starts_with(&format!("{k}.")) || key.starts_with(&format!("{k}["))
    })
}

/// An error on a key an override set (or inside it) is the override's: it
/// names `--set key=value` instead of the file. `written` is what the file
/// and the overrides wrote ([`written_keys`]).
fn blame_override(e: SceneError, overrides: &[String], written: &[(String, String)]) -> SceneError {
    let SceneError::Key { key, msg, path } = e else {
        return e;
    };
    // A missing lambda (nobody wrote one) is the fault of the override
    // that chose the smoothing spline.
    let culprit = culprit_override(&key, overrides).or_else(|| {
        let lambda_missing =
            key == "surface.lambda" && !written.iter().any(|(k, _)| k == "surface.lambda");
        lambda_missing
            .then(|| culprit_override("surface.filter", overrides))
            .flatten()
    });
    match culprit {
        Some(o) => SceneError::Override {
            arg: o.clone(),
            msg: if key == override_key(o) {
                msg
            } else {
                format!("[{key}] {msg}")
            },
        },
        None => SceneError::Key { path, key, msg },
    }
}

/// Every key of `t` as a dotted path with its value as written (TOML;
/// [`Scene::parse`] replaces it by `--set key=value` for an override).
fn written_keys(t: &toml::Table, prefix: &str, out: &mut Vec<(String, String)>) {
    for (k, v) in t {
        let key = format!("{prefix}{k}");
        if let toml::Value::Table(sub) = v {
            written_keys(sub, &format!("{key}."), out);
        }
        out.push((key, v.to_string()));
    }
}

/// The settings in `written` that the resolved scene does not use, as
/// messages (see [`Scene::ignored_settings`]).
fn ignored_settings(
    written: &[(String, String)],
    f: &SceneFile,
    surface: &Surface,
    render: &RenderSettings,
) -> Vec<String> {
    let mut unused: Vec<(&str, String)> = Vec::new();
    match f.camera.kind {
        CameraKind::Perspective => unused.push((
            "camera.height",
            "a perspective camera's view is set by fov_y (height is for kind = \"orthographic\")"
                .into(),
        )),
        CameraKind::Orthographic => unused.push((
            "camera.fov_y",
            "an orthographic camera's view is set by height (fov_y is for the perspective camera)"
                .into(),
        )),
    }
    if f.backdrop.checker.is_some() {
        for key in ["backdrop.width", "backdrop.outside"] {
            unused.push((
                key,
                "it applies to a photograph backdrop (image), not to a checkerboard".into(),
            ));
        }
    } else {
        unused.push((
            "backdrop.checker_colors",
            "it applies to a checkerboard backdrop, not to a photograph".into(),
        ));
    }
    if render.traversal != Traversal::Step {
        unused.push((
            "render.step",
            format!(
                "it is the step of traversal = \"step\"; the {} traversal finds crossings cell by cell",
                setting_name(&render.traversal)
            ),
        ));
    }
    if render.supersampling == Supersampling::None {
        for key in [
            "render.samples",
            "render.prss_samples",
            "render.prss_map",
            "render.prss_fallback",
            "render.prss_curvature",
            "render.footprint",
            "render.seed",
        ] {
            unused.push((
                key,
                "render.supersampling is \"none\" (one ray per pixel); set it to grid, jitter, prss or footprint".into(),
            ));
        }
    } else if render.supersampling != Supersampling::Footprint {
        unused.push((
            "render.footprint",
            format!(
                "it is the filter of supersampling = \"footprint\", not of \"{}\"",
                setting_name(&render.supersampling)
            ),
        ));
    }
    if !surface.filter.smooths() {
        unused.push((
            "surface.lambda",
            format!(
                "it is the smoothing weight of smooth-bspline3; filter {} does not smooth",
                surface.filter.name()
            ),
        ));
    }
    unused
        .into_iter()
        .filter_map(|(key, why)| {
            let (_, value) = written.iter().find(|(k, _)| k == key)?;
            Some(match value.strip_prefix("--set ") {
                Some(_) => format!("{value} is ignored: {why}"),
                None => format!("[{key}] = {value} is ignored: {why}"),
            })
        })
        .collect()
}

/// The name a setting's unit variant has in scene files and reports
/// (`"octree"`): the one serde reads and writes.
pub(crate) fn setting_name<T: serde::Serialize>(v: &T) -> String {
    match serde_json::to_value(v) {
        Ok(serde_json::Value::String(s)) => s,
        _ => "?".into(),
    }
}

fn resolve(
    f: SceneFile,
    phantom: Option<PhantomSpec>,
    path: &Path,
    written: &[(String, String)],
) -> Result<Scene, SceneError> {
    let bad = |key: &str, msg: String| SceneError::Key {
        path: path.to_path_buf(),
        key: key.to_string(),
        msg,
    };
    let base = path.parent().unwrap_or(Path::new("."));

    // [image]
    let (w, h) = (f.image.width, f.image.height);
    for (key, side) in [("image.width", w), ("image.height", h)] {
        if side == 0 || side > MAX_IMAGE_SIDE {
            return Err(bad(
                key,
                format!("must be from 1 to {MAX_IMAGE_SIDE} pixels, got {side}"),
            ));
        }
    }
    if (w as u64) * (h as u64) > MAX_IMAGE_PIXELS {
        // Named by the longer side, the one most over its share.
        return Err(bad(
            if w >= h {
                "image.width"
            } else {
                "image.height"
            },
            format!("{w}x{h} exceeds {MAX_IMAGE_PIXELS} pixels"),
        ));
    }
    check_color(&f.image.background).map_err(|m| bad("image.background", m))?;

    // [camera]
    let c = &f.camera;
    let projection = match c.kind {
        CameraKind::Perspective => {
            let fov = c.fov_y.ok_or_else(|| {
                bad(
                    "camera.fov_y",
                    "a perspective camera needs fov_y (degrees)".into(),
                )
            })?;
            if !(fov > 0.0 && fov < 180.0) {
                return Err(bad(
                    "camera.fov_y",
                    format!("must be between 0 and 180 degrees (both excluded), got {fov}"),
                ));
            }
            Projection::Perspective {
                tan_half_fov: (fov.to_radians() / 2.0).tan(),
            }
        }
        CameraKind::Orthographic => {
            let height = c.height.ok_or_else(|| {
                bad(
                    "camera.height",
                    "an orthographic camera needs height (world units)".into(),
                )
            })?;
            Projection::Orthographic {
                half_height: height / 2.0,
            }
        }
    };
    let camera = Camera::new(
        vec3(c.position),
        vec3(c.look_at),
        vec3(c.up),
        projection,
        w,
        h,
    )
    .map_err(|e| {
        let key = match e {
            CameraError::NotFinite(what) | CameraError::TooFar { what, .. } => {
                format!("camera.{what}")
            }
            CameraError::BadHeight(_) | CameraError::ViewOverflow
                if c.kind == CameraKind::Orthographic =>
            {
                "camera.height".into()
            }
            CameraError::BadFov(_) => "camera.fov_y".into(),
            CameraError::UpParallel => "camera.up".into(),
            // position is where the camera is; look_at is what it aims at.
            CameraError::NoDirection => "camera.look_at".into(),
            _ => "camera".into(),
        };
        bad(&key, e.to_string())
    })?;

    // [volume]
    let v = &f.volume;
    if let Some(sp) = v.spacing {
        crate::volume::check_spacing(sp)
            .and_then(|()| crate::volume::check_spacing_ratio(sp))
            .map_err(|e| bad("volume.spacing", e.to_string()))?;
    }
    let volume = match (&v.path, &v.phantom) {
        (Some(_), Some(_)) => {
            return Err(bad(
                "volume",
                "give either path or [volume.phantom], not both".into(),
            ));
        }
        (None, None) => return Err(bad("volume", "needs path or [volume.phantom]".into())),
        (Some(p), None) => {
            let raw = match &v.raw {
                None => None,
                Some(r) => Some(RawSpec {
                    dims: r.dims,
                    sample_type: SampleType::parse(&r.sample_type).ok_or_else(|| {
                        bad(
                            "volume.raw.type",
                            format!("unknown sample type '{}'", r.sample_type),
                        )
                    })?,
                    endian: Endian::parse(&r.endian).ok_or_else(|| {
                        bad(
                            "volume.raw.endian",
                            format!("expected little or big, got '{}'", r.endian),
                        )
                    })?,
                    spacing: v.spacing.unwrap_or([1.0; 3]),
                    offset: r.offset,
                }),
            };
            VolumeSource::File {
                path: base.join(p),
                raw,
                allow_nan: v.allow_nan,
            }
        }
        (None, Some(_)) => {
            let spec = phantom.expect("a phantom table is read before resolving");
            spec.validate().map_err(|e| match e {
                crate::phantom::PhantomError::Setting { key, msg } => {
                    bad(&format!("volume.phantom.{key}"), msg)
                }
                e => bad("volume.phantom", e.to_string()),
            })?;
            VolumeSource::Phantom(spec)
        }
    };
    if let Some(s) = v.spacing
        && !s.iter().all(|x| x.is_finite() && *x > 0.0)
    {
        return Err(bad(
            "volume.spacing",
            format!("must be finite and > 0, got {s:?}"),
        ));
    }

    // [surface]
    let s = &f.surface;
    let filter = FilterKind::with_lambda(&s.filter, s.lambda).map_err(|e| match e {
        crate::filter::FilterError::Unknown(_) => bad("surface.filter", e.to_string()),
        crate::filter::FilterError::BadLambda(_) => bad("surface.lambda", e.to_string()),
        crate::filter::FilterError::NeedsLambda => bad(
            "surface.lambda",
            format!(
                "filter smooth-bspline3 needs lambda, {}",
                crate::filter::LAMBDA_HELP
            ),
        ),
    })?;
    if !s.iso.is_finite() {
        return Err(bad("surface.iso", format!("must be finite, got {}", s.iso)));
    }
    for (key, ior) in [
        ("surface.ior", s.ior),
        ("surface.outside_ior", s.outside_ior),
    ] {
        if !(ior.is_finite() && ior > 0.0) {
            return Err(bad(
                key,
                format!("index of refraction must be a finite number > 0, got {ior}"),
            ));
        }
    }
    let surface = Surface {
        filter,
        iso: s.iso,
        ior: s.ior,
        outside_ior: s.outside_ior,
    };

    // [backdrop]
    let b = &f.backdrop;
    let center = vec3(b.center);
    // Only their directions matter: scaled to a largest component of 1, huge
    // vectors (1e155) square without overflowing to an infinite length.
    let normal = unit_scale(vec3(b.normal));
    let u_raw = unit_scale(vec3(b.u_axis));
    if !(center.is_finite() && normal.is_finite() && u_raw.is_finite()) {
        return Err(bad(
            "backdrop",
            "center, normal and u_axis must be finite".into(),
        ));
    }
    if normal.length() < 1e-12 {
        return Err(bad("backdrop.normal", "must not be zero".into()));
    }
    let normal = normal.normalize();
    // Gram–Schmidt: keep u in the plane; SPEC's v = cross(normal, u) is then unit.
    let u_in_plane = u_raw - u_raw.dot(normal) * normal;
    if u_in_plane.length() < 1e-9 * u_raw.length().max(1e-300) || u_raw.length() == 0.0 {
        return Err(bad(
            "backdrop.u_axis",
            "must not be zero or parallel to normal".into(),
        ));
    }
    let u_axis = u_in_plane.normalize();
    let v_axis = normal.cross(u_axis);
    let backdrop_image = b.image.as_ref().map(|img| base.join(img));
    let pattern = match (b.checker, &b.image) {
        (Some(_), Some(_)) => {
            return Err(bad(
                "backdrop",
                "give either checker or image, not both".into(),
            ));
        }
        (None, None) => {
            return Err(bad(
                "backdrop",
                "needs checker = <size> or image = <file>".into(),
            ));
        }
        (Some(size), None) => {
            if !(size.is_finite() && size > 0.0) {
                return Err(bad(
                    "backdrop.checker",
                    format!("square size must be a finite number > 0, got {size}"),
                ));
            }
            let colors = b.checker_colors.unwrap_or([[1.0; 3], [0.0; 3]]);
            for c in &colors {
                check_color(c).map_err(|m| bad("backdrop.checker_colors", m))?;
            }
            Pattern::Checker { size, colors }
        }
        (None, Some(img)) => {
            let width = b.width.ok_or_else(|| {
                bad(
                    "backdrop.width",
                    "an image backdrop needs width (world units)".into(),
                )
            })?;
            if !(width.is_finite() && width > 0.0) {
                return Err(bad(
                    "backdrop.width",
                    format!("must be a finite number > 0, got {width}"),
                ));
            }
            let outside = b.outside.unwrap_or(f.image.background);
            check_color(&outside).map_err(|m| bad("backdrop.outside", m))?;
            let file = base.join(img);
            Pattern::Image(
                load_texture(&file, width, outside).map_err(|m| bad("backdrop.image", m))?,
            )
        }
    };
    let backdrop = Backdrop {
        center,
        normal,
        u_axis,
        v_axis,
        pattern,
    };

    // [render]
    let r = &f.render;
    if !(r.step.is_finite() && (MIN_STEP..=16.0).contains(&r.step)) {
        return Err(bad(
            "render.step",
            format!("must be from {MIN_STEP} to 16 voxels, got {}", r.step),
        ));
    }
    if r.max_events == 0 || r.max_events > 100_000 {
        return Err(bad(
            "render.max_events",
            format!("must be from 1 to 100000, got {}", r.max_events),
        ));
    }
    if !(r.tolerance.is_finite() && r.tolerance >= 1e-12 && r.tolerance <= 0.1) {
        return Err(bad(
            "render.tolerance",
            format!("must be from 1e-12 to 0.1 voxels, got {}", r.tolerance),
        ));
    }
    if r.samples == 0 || r.samples > 64 {
        return Err(bad(
            "render.samples",
            format!("must be from 1 to 64, got {}", r.samples),
        ));
    }
    let tile = r
        .tile
        .unwrap_or_else(|| default_tile(r.supersampling.first_pass_rays(r.samples) as u32));
    if tile == 0 || tile > 256 {
        return Err(bad(
            "render.tile",
            format!("must be from 1 to 256 pixels, got {tile}"),
        ));
    }
    if r.prss_samples == 0 || r.prss_samples > 64 {
        return Err(bad(
            "render.prss_samples",
            format!("must be from 1 to 64, got {}", r.prss_samples),
        ));
    }
    let classify = match r.classify.as_deref() {
        // Precomputed tags are cheap (tens of ms, cached) and make the cell
        // walk an order of magnitude faster than bounding every visited cell
        // on the fly, so every cell traversal uses them unless told `none`.
        None if r.traversal != Traversal::Step => Some(DEFAULT_CLASSIFY),
        None | Some("none") => None,
        Some(name) => match Method::parse(name) {
            Some(m) if m.is_conservative() => Some(m),
            _ => {
                return Err(bad(
                    "render.classify",
                    format!(
                        "unknown or non-conservative method '{name}' (none, bmcc, accc, accc2, accc4, accc8, bezier)"
                    ),
                ));
            }
        },
    };
    if matches!(r.traversal, Traversal::Octree | Traversal::Distance) && classify.is_none() {
        return Err(bad(
            "render.classify",
            "the octree is built over classified cells: use bmcc, accc or bezier".into(),
        ));
    }
    if r.traversal == Traversal::Step && classify.is_some() {
        return Err(bad(
            "render.classify",
            "step traversal samples every point and uses no classification".into(),
        ));
    }
    if !(r.prss_curvature.is_finite() && r.prss_curvature > 0.0) {
        return Err(bad(
            "render.prss_curvature",
            format!("must be > 0 (checker squares), got {}", r.prss_curvature),
        ));
    }
    if !r.leaf.is_power_of_two() || r.leaf > 64 {
        return Err(bad(
            "render.leaf",
            format!("must be a power of two up to 64, got {}", r.leaf),
        ));
    }
    let render = RenderSettings {
        traversal: r.traversal,
        step: r.step,
        max_events: r.max_events,
        tolerance: r.tolerance,
        tile,
        classify,
        leaf: r.leaf,
        supersampling: r.supersampling,
        samples: r.samples,
        prss_samples: r.prss_samples,
        prss_map: r.prss_map,
        prss_fallback: r.prss_fallback,
        footprint: r.footprint,
        prss_curvature: r.prss_curvature,
        seed: r.seed,
        coefficients: r.coefficients,
        clear_crossing_cells: r.clear_crossing_cells,
        skip_empty_approach: r.skip_empty_approach,
        skip_clear_segments: r.skip_clear_segments,
    };

    let ignored = ignored_settings(written, &f, &surface, &render);
    let scene = Scene {
        ignored,
        overrides: Vec::new(),
        written: Vec::new(),
        path: path.to_path_buf(),
        width: w,
        height: h,
        background: f.image.background,
        camera,
        volume,
        spacing: v.spacing,
        surface,
        backdrop,
        backdrop_image,
        render,
    };
    // One tile at a time, the least any render needs, so that whether a
    // scene file is accepted does not depend on the machine's cores; a
    // renderer checks again with its own thread count (`snell render` does
    // once its pool is built).
    scene.check_memory(crate::volume::limits::default_memory_limit(), 1)?;
    Ok(scene)
}

fn check_color(c: &[f32; 3]) -> Result<(), String> {
    if c.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(format!("colour {c:?} must be finite"))
    }
}

/// Loads a photograph as an RGB texture in `[0, 1]`.
fn load_texture(path: &Path, world_width: f64, outside: [f32; 3]) -> Result<Texture, String> {
    let photo = crate::film::photo::read(path).map_err(|m| format!("{}: {m}", path.display()))?;
    Ok(Texture {
        width_px: photo.width as usize,
        height_px: photo.height as usize,
        pixels: photo.pixels,
        world_width,
        outside,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const SCENE: &str = r#"
[image]
width = 64
height = 48

[camera]
position = [31.5, 31.5, -150.0]
look_at = [31.5, 31.5, 31.5]
fov_y = 20.0

[volume.phantom]
kind = "sphere"
size = 32
format = "u8"

[surface]
filter = "bspline3"
iso = 127.5
ior = 1.5

[backdrop]
center = [31.5, 31.5, 200.0]
normal = [0.0, 0.0, -1.0]
u_axis = [1.0, 0.0, 0.0]
checker = 8.0
"#;

    fn parse(extra: &[&str]) -> Result<Scene, SceneError> {
        let o: Vec<String> = extra.iter().map(|s| s.to_string()).collect();
        Scene::parse(SCENE, Path::new("test.toml"), &o)
    }

    #[test]
    fn parses_with_defaults() {
        let s = parse(&[]).unwrap();
        assert_eq!((s.width, s.height), (64, 48));
        assert_eq!(s.render.traversal, Traversal::Octree);
        assert_eq!(s.render.max_events, 32);
        assert_eq!(s.surface.outside_ior, 1.0);
        assert!(matches!(s.volume, VolumeSource::Phantom(_)));
        assert_eq!(s.backdrop.v_axis, DVec3::new(0.0, -1.0, 0.0));
    }

    #[test]
    fn overrides_apply_and_are_checked() {
        let s = parse(&[
            "surface.ior=1.33",
            "render.traversal=step",
            "surface.filter=linear",
        ])
        .unwrap();
        assert_eq!(s.surface.ior, 1.33);
        assert_eq!(s.render.traversal, Traversal::Step);
        assert_eq!(s.surface.filter, FilterKind::Linear);
        // An override's error names the override, not the file.
        let e = parse(&["surface.ior=-1"]).unwrap_err().to_string();
        assert!(e.starts_with("--set surface.ior=-1: "), "{e}");
        let e = parse(&["nonsense"]).unwrap_err().to_string();
        assert!(e.contains("--set nonsense"), "{e}");
        let s = parse(&["volume.path=x.nrrd"]).unwrap();
        assert!(matches!(s.volume, VolumeSource::File { .. }));
    }

    /// The default tile traces about a thousand rays in its first pass;
    /// a tile the scene names is kept, and checked.
    #[test]
    fn default_tile_holds_about_a_thousand_rays() {
        assert_eq!(default_tile(1), 32);
        assert_eq!(default_tile(2), 32);
        assert_eq!(default_tile(5), 16);
        assert_eq!(default_tile(17), 8);
        assert_eq!(default_tile(65), 4);
        assert_eq!(default_tile(4097), 1);
        let tile = |o: &[&str]| parse(o).unwrap().render.tile;
        assert_eq!(tile(&[]), 32);
        assert_eq!(tile(&["render.supersampling=prss"]), 32);
        assert_eq!(tile(&["render.supersampling=grid"]), 8);
        assert_eq!(
            tile(&["render.supersampling=jitter", "render.samples=2"]),
            16
        );
        assert_eq!(tile(&["render.supersampling=grid", "render.tile=24"]), 24);
        let e = parse(&["render.tile=257"]).unwrap_err().to_string();
        assert!(e.contains("render.tile") && e.contains("257"), "{e}");
    }

    #[test]
    fn errors_name_the_key() {
        // Each error starts with the override that set its key (the last
        // one given), or with [key] inside the override that caused it.
        let cases: &[(&[&str], &str)] = &[
            (&["surface.filter=gauss"], "--set surface.filter=gauss: "),
            (&["surface.lambda=-2"], "--set surface.lambda=-2: "),
            (
                &["surface.filter=smooth-bspline3"],
                "--set surface.filter=smooth-bspline3: [surface.lambda] ",
            ),
            (
                &["camera.look_at=[31.5, 31.5, -150.0]"],
                "--set camera.look_at=[31.5, 31.5, -150.0]: ",
            ),
            (
                &["camera.up=[0.0, 0.0, 1.0]"],
                "--set camera.up=[0.0, 0.0, 1.0]: ",
            ),
            (&["camera.fov_y=0"], "--set camera.fov_y=0: "),
            (&["image.width=0"], "--set image.width=0: "),
            (&["image.height=40000"], "--set image.height=40000: "),
            (
                &["image.width=20000", "image.height=20000"],
                "--set image.width=20000: ",
            ),
            (&["surface.isoo=3"], "--set surface.isoo=3: "),
            (&["surface.iso=\"high\""], "--set surface.iso=\"high\": "),
            (&["backdrop.checker=0"], "--set backdrop.checker=0: "),
            (
                &["backdrop.u_axis=[0.0, 0.0, 2.0]"],
                "--set backdrop.u_axis=[0.0, 0.0, 2.0]: ",
            ),
            (
                &["render.traversal=octree", "render.classify=none"],
                "--set render.classify=none: ",
            ),
            (&["render.tolerance=0"], "--set render.tolerance=0: "),
            (
                &["volume.phantom={kind=\"sphere\", size=0}"],
                "--set volume.phantom={kind=\"sphere\", size=0}: [volume.phantom.size] ",
            ),
        ];
        for (o, prefix) in cases {
            let e = parse(o).unwrap_err().to_string();
            assert!(e.starts_with(prefix), "{o:?}: {e}");
        }
        // The same settings in the file name the file and the precise key.
        let e = parse_text(|s| s.replace("width = 64", "width = 0"), &[])
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("test.toml: [image.width] "), "{e}");
        let e = parse_text(
            |s| {
                s.replace(
                    "look_at = [31.5, 31.5, 31.5]",
                    "look_at = [31.5, 31.5, -150.0]",
                )
            },
            &[],
        )
        .unwrap_err()
        .to_string();
        assert!(e.starts_with("test.toml: [camera.look_at] "), "{e}");
        // A lambda in the file is the file's fault, whoever chose the
        // smoothing spline.
        let e = parse_text(
            |s| s.replace("ior = 1.5", "ior = 1.5\nlambda = -1.0"),
            &["surface.filter=smooth-bspline3"],
        )
        .unwrap_err()
        .to_string();
        assert!(e.starts_with("test.toml: [surface.lambda] "), "{e}");
        let e = Scene::parse("[image\nwidth=3", Path::new("bad.toml"), &[])
            .unwrap_err()
            .to_string();
        assert!(e.contains("bad.toml") && e.contains("line"), "{e}");
    }

    /// A number TOML cannot hold is named by its key only on a `key =`
    /// line, under a `[section]` header line (a comment may follow it);
    /// anywhere else (inside a multi-line array) by its line.
    #[test]
    fn numbers_out_of_range_in_the_file_name_key_or_line() {
        let err = |text: &str| {
            Scene::parse(&format!("{SCENE}{text}"), Path::new("t.toml"), &[])
                .unwrap_err()
                .to_string()
        };
        let line = |e: &str| SCENE.lines().count() + e.lines().count();
        let e = err("\n[render]  # fast\nseed = 99999999999999999999\n");
        assert!(e.starts_with("t.toml: [render.seed] "), "{e}");
        let e = err("\n[ render ] # [x]\n\"seed\" = -99999999999999999999 # big\n");
        assert!(e.starts_with("t.toml: [render.seed] "), "{e}");
        let tail = "\n[camera2]\npoints = [\n  [1, 1, 1],\n  31.5, 1e400,\n]\n";
        let e = err(tail);
        assert!(
            e.starts_with(&format!("t.toml: [line {}] ", line(tail) - 1)),
            "{e}"
        );
        let tail = "\n[camera2]\npoints = [\n  [1, 1, 1],\n  [1, 99999999999999999999],\n]\n";
        let e = err(tail);
        assert!(
            e.starts_with(&format!("t.toml: [line {}] ", line(tail) - 1)),
            "{e}"
        );
        let e = err("\n[camera2]\npoints = [1, 1e400]\n");
        assert!(e.starts_with("t.toml: [camera2.points] "), "{e}");
    }

    /// Errors found while loading the volume name the `--set` that wrote
    /// the key, as errors found while reading the scene do.
    #[test]
    fn volume_errors_name_their_override() {
        let small = LoadOptions {
            memory_limit: 1 << 20,
            ..LoadOptions::default()
        };
        let load = |o: &[&str]| {
            parse(o)
                .unwrap()
                .load_volume(&small)
                .unwrap_err()
                .to_string()
        };
        let e = load(&["volume.phantom.size=4096"]);
        assert!(e.starts_with("--set volume.phantom.size=4096: "), "{e}");
        let e = load(&["volume.path=x.raw"]);
        assert!(
            e.starts_with("--set volume.path=x.raw: ") && e.contains("[volume.raw]"),
            "{e}"
        );
        // Written in the file, the file is named.
        let e = parse_text(|s| s.replace("size = 32", "size = 4096"), &[])
            .unwrap()
            .load_volume(&small)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("test.toml: [volume.phantom.size] "), "{e}");
    }

    fn parse_text(edit: impl Fn(&str) -> String, o: &[&str]) -> Result<Scene, SceneError> {
        let o: Vec<String> = o.iter().map(|s| s.to_string()).collect();
        Scene::parse(&edit(SCENE), Path::new("test.toml"), &o)
    }

    /// serde's messages in words, each with its precise key; a file and a
    /// `--set` of the same value say the same after their prefixes.
    #[test]
    fn messages_are_plain_and_name_the_key() {
        let file = |from: &str, to: &str| {
            parse_text(|s| s.replace(from, to), &[])
                .unwrap_err()
                .to_string()
        };
        let set = |o: &str| parse(&[o]).unwrap_err().to_string();
        assert_eq!(
            file("ior = 1.5", "ior = \"1.5\""),
            "test.toml: [surface.ior] expected a number, got the text \"1.5\""
        );
        assert_eq!(
            file("width = 64", "width = 32.0"),
            "test.toml: [image.width] expected a whole number from 0 to 4294967295, got 32.0"
        );
        assert_eq!(
            set("surface=3"),
            "--set surface=3: expected a table of surface settings, got 3"
        );
        assert_eq!(
            file("size = 32", "size = -64"),
            "test.toml: [volume.phantom.size] expected a whole number from 0 to 9223372036854775807, got -64"
        );
        assert_eq!(
            file("format = \"u8\"", "format = \"u12\""),
            "test.toml: [volume.phantom.format] expected one of \"f32\", \"u8\", \"u16\", got \"u12\""
        );
        // Numbers TOML cannot hold, whichever way TOML words the refusal
        // (i64 < n <= u64, past u64, below i64, a float past f64).
        for (seed, words) in [
            ("18446744073709551615", "up to 9223372036854775807"),
            ("9223372036854775808", "up to 9223372036854775807"),
            ("99999999999999999999", "up to 9223372036854775807"),
            (
                "999999999999999999999999999999999999999999",
                "up to 9223372036854775807",
            ),
            ("-9223372036854775809", "down to -9223372036854775808"),
            ("-99999999999999999999", "down to -9223372036854775808"),
            ("0xffffffffffffffffff", "up to 9223372036854775807"),
        ] {
            let f = parse_text(|s| format!("{s}\n[render]\nseed = {seed}\n"), &[])
                .unwrap_err()
                .to_string();
            let o = set(&format!("render.seed={seed}"));
            let f = f.strip_prefix("test.toml: [render.seed] ").expect(&f);
            let o = o
                .strip_prefix(&format!("--set render.seed={seed}: "))
                .expect(&o);
            assert_eq!(f, o);
            assert!(f.contains(words) && f.ends_with(seed), "{f}");
        }
        for iso in ["1e400", "-1.5e309", "1_000e306"] {
            let f = file("iso = 127.5", &format!("iso = {iso}"));
            let o = set(&format!("surface.iso={iso}"));
            let f = f.strip_prefix("test.toml: [surface.iso] ").expect(&f);
            let o = o
                .strip_prefix(&format!("--set surface.iso={iso}: "))
                .expect(&o);
            assert_eq!(f, o);
            assert!(f.contains("beyond the largest 64-bit float"), "{f}");
        }
        // A word is still text.
        assert_eq!(
            set("surface.iso=infinity"),
            "--set surface.iso=infinity: expected a number, got the text \"infinity\""
        );
        // Two variants: "a" or "b", in quotes as the values are written.
        assert_eq!(
            set("camera.kind=fisheye"),
            "--set camera.kind=fisheye: expected \"perspective\" or \"orthographic\", got \"fisheye\""
        );
        let e = set("volume.phantom.radius=-20");
        assert_eq!(
            e,
            "--set volume.phantom.radius=-20: must be a finite number >= 0, got -20"
        );
        let e = file("size = 32", "size = 32\nradius = -20.0");
        assert!(e.starts_with("test.toml: [volume.phantom.radius] "), "{e}");
        let e = file(
            "position = [31.5, 31.5, -150.0]",
            "position = [31.5, 31.5, -1e307]",
        );
        assert!(
            e.starts_with("test.toml: [camera.position] ") && e.contains("1e150"),
            "{e}"
        );
        let e = parse(&["camera.kind=orthographic", "camera.height=-1"])
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("--set camera.height=-1: "), "{e}");
        let e = parse(&["surface.lambda=-1"]).unwrap_err().to_string();
        assert!(e.starts_with("--set surface.lambda=-1: "), "{e}");
        let e = parse(&["surface.filter=smooth-bspline3"])
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("--set surface.filter=smooth-bspline3: [surface.lambda] "),
            "{e}"
        );
    }

    /// Settings written but unused are reported; defaults and used
    /// settings are not.
    #[test]
    fn ignored_settings_are_the_written_unused_ones() {
        assert!(parse(&[]).unwrap().ignored_settings().is_empty());
        let s = parse(&[
            "camera.height=3",
            "backdrop.width=2",
            "render.step=0.5",
            "render.samples=3",
            "render.seed=7",
            "render.footprint=ewa",
            "surface.lambda=1",
        ])
        .unwrap();
        let ignored = s.ignored_settings();
        assert_eq!(ignored.len(), 7, "{ignored:?}");
        assert!(
            ignored[0].starts_with("--set camera.height=3 is ignored"),
            "{ignored:?}"
        );
        // A key inside a table an override wrote is that override's, as
        // in errors.
        let s = parse(&["render={seed=7}"]).unwrap();
        assert_eq!(
            s.ignored_settings(),
            [
                "--set render={seed=7} is ignored: render.supersampling is \"none\" (one ray per pixel); set it to grid, jitter, prss or footprint"
            ]
        );
        // In the file, named by its key.
        let s = parse_text(
            |s| s.replace("fov_y = 20.0", "fov_y = 20.0\nheight = 5.0"),
            &[],
        )
        .unwrap();
        assert_eq!(s.ignored_settings().len(), 1);
        assert!(s.ignored_settings()[0].starts_with("[camera.height] = 5.0 is ignored"));
        // Used: the smoothing spline's lambda, the step of step traversal,
        // footprint settings with footprint supersampling.
        let s = parse(&[
            "surface.filter=smooth-bspline3",
            "surface.lambda=1",
            "render.traversal=step",
            "render.step=0.5",
            "render.supersampling=footprint",
            "render.footprint=ewa",
            "render.samples=3",
        ])
        .unwrap();
        assert!(
            s.ignored_settings().is_empty(),
            "{:?}",
            s.ignored_settings()
        );
    }
}
