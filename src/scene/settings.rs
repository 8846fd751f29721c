//! Render settings after validation, and the named choices a scene file
//! makes among traversals, anti-aliasing, PRSS maps and coefficient
//! storage (read by serde under the names the file uses).

use serde::Deserialize;

use crate::classify::Method;

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
    /// is precise), times a power of two that puts the field in `f16`'s
    /// normal range whatever its magnitude, then rounded once; a field
    /// whose scaled coefficients still exceed the range (a prefilter's
    /// overshoot of noise, over 2000-fold) is refused. What it costs in accuracy is measured
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
