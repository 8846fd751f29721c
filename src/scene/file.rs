//! The scene file's format, as serde sees it: one struct per TOML
//! section, unknown keys refused, defaults for what may be left out.
//! [`resolve`](fn@super::resolve) turns it into a validated [`super::Scene`].

use serde::Deserialize;

use super::settings::{FootprintFilter, PrssFallback, PrssMap, Storage, Supersampling, Traversal};

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(super) struct SceneFile {
    pub(super) image: ImageCfg,
    pub(super) camera: CameraCfg,
    pub(super) volume: VolumeCfg,
    pub(super) surface: SurfaceCfg,
    pub(super) backdrop: BackdropCfg,
    #[serde(default)]
    pub(super) render: RenderCfg,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(super) struct ImageCfg {
    pub(super) width: u32,
    pub(super) height: u32,
    /// Colour of rays that never reach the backdrop.
    #[serde(default = "default_background")]
    pub(super) background: [f32; 3],
}

fn default_background() -> [f32; 3] {
    [0.25, 0.35, 0.55]
}

#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
#[serde(rename_all = "lowercase")]
pub(super) enum CameraKind {
    #[default]
    Perspective,
    Orthographic,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(super) struct CameraCfg {
    #[serde(default)]
    pub(super) kind: CameraKind,
    pub(super) position: [f64; 3],
    pub(super) look_at: [f64; 3],
    #[serde(default = "default_up")]
    pub(super) up: [f64; 3],
    pub(super) fov_y: Option<f64>,
    pub(super) height: Option<f64>,
}

fn default_up() -> [f64; 3] {
    [0.0, 1.0, 0.0]
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(super) struct RawCfg {
    pub(super) dims: [usize; 3],
    #[serde(rename = "type")]
    pub(super) sample_type: String,
    #[serde(default = "default_endian")]
    pub(super) endian: String,
    #[serde(default)]
    pub(super) offset: u64,
}

fn default_endian() -> String {
    "little".into()
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(super) struct VolumeCfg {
    pub(super) path: Option<String>,
    /// Read as a [`PhantomSpec`](crate::phantom::PhantomSpec) by
    /// [`phantom_spec`](super::resolve::phantom_spec), whose errors name the
    /// key inside the table (serde's tagged enums lose the path).
    pub(super) phantom: Option<toml::Value>,
    pub(super) raw: Option<RawCfg>,
    /// Overrides the file's spacing.
    pub(super) spacing: Option<[f64; 3]>,
    #[serde(default)]
    pub(super) allow_nan: bool,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(super) struct SurfaceCfg {
    pub(super) filter: String,
    /// The smoothing weight of `smooth-bspline3` (required by it).
    pub(super) lambda: Option<f64>,
    pub(super) iso: f64,
    #[serde(default = "default_ior")]
    pub(super) ior: f64,
    #[serde(default = "default_outside_ior")]
    pub(super) outside_ior: f64,
}

fn default_ior() -> f64 {
    1.5
}

fn default_outside_ior() -> f64 {
    1.0
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(super) struct BackdropCfg {
    pub(super) center: [f64; 3],
    pub(super) normal: [f64; 3],
    pub(super) u_axis: [f64; 3],
    pub(super) checker: Option<f64>,
    /// `[even, odd]` square colours (default white, black).
    pub(super) checker_colors: Option<[[f32; 3]; 2]>,
    pub(super) image: Option<String>,
    pub(super) width: Option<f64>,
    /// Colour beyond the photograph's edges.
    pub(super) outside: Option<[f32; 3]>,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(super) struct RenderCfg {
    #[serde(default)]
    pub(super) traversal: Traversal,
    #[serde(default = "default_step")]
    pub(super) step: f64,
    #[serde(default = "default_max_events")]
    pub(super) max_events: u32,
    #[serde(default = "default_tolerance")]
    pub(super) tolerance: f64,
    /// Tile side in pixels; unset means [`default_tile`].
    #[serde(default)]
    pub(super) tile: Option<u32>,
    /// `none`, `bmcc`, `accc`, `accc2`, `accc4`, `accc8`, `bezier` (see `classify`);
    /// unset means [`DEFAULT_CLASSIFY`](super::DEFAULT_CLASSIFY) for cell traversals.
    #[serde(default)]
    pub(super) classify: Option<String>,
    /// Octree leaf side in cells (a power of two).
    #[serde(default = "default_leaf")]
    pub(super) leaf: u32,
    #[serde(default)]
    pub(super) supersampling: Supersampling,
    #[serde(default = "default_samples")]
    pub(super) samples: u32,
    /// PRSS sub-points per pixel side (and footprint samples of photographs).
    #[serde(default = "default_prss_samples")]
    pub(super) prss_samples: u32,
    /// How PRSS interpolates the hit map between neighbours.
    #[serde(default)]
    pub(super) prss_map: PrssMap,
    #[serde(default)]
    pub(super) prss_fallback: PrssFallback,
    /// The filter of `supersampling = "footprint"`.
    #[serde(default)]
    pub(super) footprint: FootprintFilter,
    /// With `prss_fallback = "trace"`: re-trace pixels whose hit map bends by
    /// more than this many checker squares (or texels) between neighbours.
    #[serde(default = "default_curvature")]
    pub(super) prss_curvature: f64,
    #[serde(default)]
    pub(super) seed: u64,
    /// Coefficient storage: `f64` (default) or `f32`.
    #[serde(default)]
    pub(super) coefficients: Storage,
    /// Skip the cells after a crossing that curvature bounds prove empty.
    #[serde(default = "default_true")]
    pub(super) clear_crossing_cells: bool,
    /// Start primary rays where the first occupied octree block can be.
    #[serde(default = "default_true")]
    pub(super) skip_empty_approach: bool,
    /// Pass over the segments a cell's plane bound proves clear.
    #[serde(default = "default_true")]
    pub(super) skip_clear_segments: bool,
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
pub(super) fn default_tile(rays_per_pixel: u32) -> u32 {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The default tile traces about a thousand rays in its first pass.
    #[test]
    fn default_tile_holds_about_a_thousand_rays() {
        assert_eq!(default_tile(1), 32);
        assert_eq!(default_tile(2), 32);
        assert_eq!(default_tile(5), 16);
        assert_eq!(default_tile(17), 8);
        assert_eq!(default_tile(65), 4);
        assert_eq!(default_tile(4097), 1);
    }
}
