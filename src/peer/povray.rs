//! POV-Ray 3.7 as a peer: the same scene as an `isosurface` over a
//! `density_file df3` with a glass `interior { ior }`, rendered by `povray`,
//! its timing statistics parsed and its hit positions decoded.
//!
//! # Geometry mapping (what makes pixels comparable)
//! - **World**: POV-Ray gets snell's world coordinates unchanged. POV-Ray's
//!   left-handedness only matters when it builds a camera frame itself
//!   (`look_at`, `angle`); we give it every camera vector explicitly, and all
//!   intersection and refraction arithmetic is handedness-free.
//! - **Camera**: POV-Ray traces pixel `(px, py)` through
//!   `direction + (x/W - 1/2)·right + (1/2 - y/H)·up` with `x = px + 1/2`,
//!   `y = py + 1/2` (pixel centres; measured). With `direction = f`,
//!   `right = 2·tan(fov_y/2)·(W/H)·r` and `up = 2·tan(fov_y/2)·u`, snell's
//!   frame `(f, r, u)` from SPEC.md, that is SPEC.md's ray exactly; `r` points
//!   to image-right (it is `-x` for the example scenes, which is why no axis
//!   needs mirroring). Orthographic: `location + (x/W - 1/2)·right +
//!   (1/2 - y/H)·up` with `right = height·(W/H)·r`, `up = height·u`.
//! - **Volume**: the isosurface lives in grid coordinates,
//!   `function { iso_density - Density((x+1)/Mx, (y+1)/My, (z+1)/Mz) }`,
//!   `M = N + 2` ([`super::df3`]: a mirror border, sample `i` at pattern
//!   coordinate `(i+1)/M`), `contained_by` the grid-aligned box of the cells
//!   that can reach the iso-value (within `0..N-1`), then
//!   `scale spacing`: sample `(i, j, k)` lands on world `(i·sx, j·sy, k·sz)`.
//!   `accuracy` and `max_gradient` are therefore in grid units.
//! - **Surface**: POV-Ray's inside is `function < threshold`; with
//!   `threshold 0` that is `density > iso_density`, snell's object.
//!   `interior { ior ior/outside_ior }`: camera and backdrop sit in the outside
//!   medium, so only the ratio enters Snell's law.
//! - **Backdrop**: `plane { normal, normal·center }`. The checker is POV-Ray's
//!   `checker` (first colour where `⌊a⌋+⌊b⌋+⌊c⌋` is even) in a pattern space
//!   mapped by `matrix` so that `a = u/s`, `b = v/s` and `c = 1/2` on the plane,
//!   i.e. SPEC.md's squares and parity.
//! - **No other light paths**: `finish { ambient 1 diffuse 0 }` on the
//!   backdrop, `pigment { rgbf 1 }` and no reflection, specular or Fresnel on
//!   the glass, no lights, `assumed_gamma 1`, linear output (`File_Gamma=1.0`).
//!   POV-Ray mirrors a ray at total internal reflection, like snell.
//!   `max_trace_level = max_events` (a ray that crossed `max_events` interfaces
//!   has no hit in snell; in POV-Ray it reaches trace level `max_events + 1`
//!   and returns black).
//!
//! # Hit positions
//! The `hits` variant paints the backdrop with its own coordinates, rendered
//! as 16-bit PNG and decoded by [`decode_hits`]. The backdrop is cut into
//! square tiles of side `tile` (the straight view's footprint on the
//! backdrop, [`HitEncoding::for_scene`]), 255 × 255 of them around the
//! footprint: with `a = (u - u0)/tile`, `b = (v - v0)/tile`, red
//! `= a - ⌊a⌋`, green `= b - ⌊b⌋` and blue `= (256·⌊a⌋ + ⌊b⌋ + 1)/65535`.
//! Blue 0 — the black background, a ray lost after `max_trace_level`, or a hit
//! beyond the 255-tile window — decodes as NaN. Resolution `tile/65535`
//! backdrop units (1.9e-3 for the example sphere, 2.4e-4 checker squares)
//! over a window 255 footprints wide: refracted rays land far outside the
//! straight footprint.
//!
//! # What POV-Ray approximates (not the mapping)
//! Its root finder stops within `accuracy` of a crossing along the ray (grid
//! units) and needs `max_gradient ≥` the true gradient or it misses crossings
//! (it then warns; [`PovStats::max_gradient_found`]). Its normal is a forward
//! difference of step `accuracy` (grid units) and tricubic densities are
//! evaluated in single precision, so a smaller `accuracy` trades the
//! difference's bias for rounding noise: against snell's `catmull-rom` on the
//! 512² sphere the refracted hits differ by p50 0.0026 squares at 1e-3 but
//! 0.025 at 1e-4, while trilinear (double precision) improves from 3.5e-4 to
//! 1.1e-4. Event counts are not observable: decoded hit images carry NaN
//! events.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use glam::DVec3;

use super::PeerError;
use super::df3::{
    Df3Mapping, Interpolation, containing_box, gradient_safety, max_gradient, write_df3,
};
use crate::atomic::write_atomic;
use crate::film::HitImage;
use crate::scene::{Pattern, Projection, Scene};
use crate::volume::{LoadOptions, Volume};

/// File names inside the export directory.
pub const DF3_FILE: &str = "volume.df3";
pub const COLOR_POV: &str = "scene.pov";
pub const HITS_POV: &str = "hits.pov";
pub const COLOR_PNG: &str = "color.png";
pub const HITS_PNG: &str = "hits.png";
pub const BACKDROP_PNG: &str = "backdrop.png";
pub const MANIFEST: &str = "peer.json";

/// POV-Ray's limit on `max_trace_level`.
pub const MAX_TRACE_LEVEL: u32 = 256;

/// Which of the two renders.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Variant {
    /// The scene as snell draws it (checker or photo backdrop).
    Color,
    /// The backdrop painted with its own coordinates, for hit positions.
    Hits,
}

impl Variant {
    pub fn name(self) -> &'static str {
        match self {
            Variant::Color => "colour",
            Variant::Hits => "hits",
        }
    }
    pub fn pov_file(self) -> &'static str {
        match self {
            Variant::Color => COLOR_POV,
            Variant::Hits => HITS_POV,
        }
    }
    pub fn png_file(self) -> &'static str {
        match self {
            Variant::Color => COLOR_PNG,
            Variant::Hits => HITS_PNG,
        }
    }
}

/// Isosurface settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PovOptions {
    pub interpolation: Interpolation,
    /// Root-finding accuracy in grid units (1e-3; `careful`: 1e-4).
    pub accuracy: f64,
    /// Use this `max_gradient` instead of the one computed from the data.
    pub max_gradient: Option<f64>,
    /// Factor on the computed gradient bound (default:
    /// [`super::df3::gradient_safety`]).
    pub gradient_safety: Option<f64>,
}

impl PovOptions {
    /// Defaults for `scene`: the interpolation closest to its filter,
    /// accuracy 1e-3 (1e-4 when `careful`), the default gradient safety.
    pub fn new(scene: &Scene, careful: bool) -> PovOptions {
        PovOptions {
            interpolation: Interpolation::from_filter(scene.surface.filter),
            accuracy: if careful { 1e-4 } else { 1e-3 },
            max_gradient: None,
            gradient_safety: None,
        }
    }

    fn check(&self) -> Result<(), PeerError> {
        let pos = |x: f64| x.is_finite() && x > 0.0;
        if !pos(self.accuracy) {
            return Err(PeerError::Invalid(format!(
                "accuracy must be > 0, got {}",
                crate::human::exact(self.accuracy)
            )));
        }
        if let Some(g) = self.max_gradient
            && !pos(g)
        {
            return Err(PeerError::Invalid(format!(
                "max_gradient must be > 0, got {}",
                crate::human::exact(g)
            )));
        }
        if let Some(f) = self.gradient_safety
            && !pos(f)
        {
            return Err(PeerError::Invalid(format!(
                "gradient safety must be > 0, got {}",
                crate::human::exact(f)
            )));
        }
        Ok(())
    }
}

/// Tiles per axis of the hit window.
pub const HIT_TILES: u32 = 255;

/// How the `hits` render encodes backdrop coordinates (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HitEncoding {
    /// Backdrop `u` at the window's low corner.
    pub u0: f64,
    /// Backdrop `v` at the window's low corner.
    pub v0: f64,
    /// Side of one tile in backdrop units.
    pub tile: f64,
}

impl HitEncoding {
    /// Tiles the size of the straight view's footprint on the backdrop (its
    /// larger side), the window centred on the footprint.
    pub fn for_scene(scene: &Scene) -> HitEncoding {
        let cam = &scene.camera;
        let (w, h) = (cam.width as f64, cam.height as f64);
        let mut pts = Vec::new();
        for fy in [0.0, 0.5, 1.0] {
            for fx in [0.0, 0.5, 1.0] {
                let (o, d) = cam.ray(fx * w, fy * h);
                if let Some(p) = scene.backdrop.hit(o, d) {
                    pts.push(p);
                }
            }
        }
        let (mut umin, mut umax, mut vmin, mut vmax) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        if let Some(&(u, v)) = pts.first() {
            (umin, umax, vmin, vmax) = (u, u, v, v);
        }
        for &(u, v) in &pts {
            umin = umin.min(u);
            umax = umax.max(u);
            vmin = vmin.min(v);
            vmax = vmax.max(v);
        }
        let size = (umax - umin).max(vmax - vmin);
        let tile = if size > 0.0 && size.is_finite() {
            size
        } else {
            // No usable footprint: eight checker squares (or units) per tile.
            8.0 * scene.checker_size().unwrap_or(1.0)
        };
        let half = 0.5 * HIT_TILES as f64 * tile;
        HitEncoding {
            u0: 0.5 * (umin + umax) - half,
            v0: 0.5 * (vmin + vmax) - half,
            tile,
        }
    }

    /// Backdrop units per 16-bit step.
    pub fn resolution(&self) -> f64 {
        self.tile / 65535.0
    }

    /// The window's side in backdrop units.
    pub fn window(&self) -> f64 {
        HIT_TILES as f64 * self.tile
    }

    /// Backdrop coordinates of one 16-bit RGB pixel, or `None`.
    pub fn decode(&self, rgb: [u16; 3]) -> Option<(f64, f64)> {
        let k = (rgb[2] as u32).checked_sub(1)?;
        let (a, b) = ((k / 256) as f64, (k % 256) as f64);
        Some((
            self.u0 + (a + rgb[0] as f64 / 65535.0) * self.tile,
            self.v0 + (b + rgb[1] as f64 / 65535.0) * self.tile,
        ))
    }
}

/// Everything exported for one scene, and what the files assume.
#[derive(Clone, Debug, serde::Serialize)]
pub struct PovExport {
    pub dir: PathBuf,
    pub width: u32,
    pub height: u32,
    pub mapping: Df3Mapping,
    pub interpolation: Interpolation,
    /// The iso-value in density units (the pattern's 0..1).
    pub iso_density: f64,
    /// The gradient bound from the data, before the safety factor.
    pub gradient_estimate: f64,
    /// The safety factor applied to it.
    pub gradient_safety: f64,
    /// `max_gradient` as written.
    pub max_gradient: f64,
    pub accuracy: f64,
    /// `ior / outside_ior`.
    pub ior: f64,
    pub max_trace_level: u32,
    /// `contained_by` box corners in grid coordinates: the knot cells whose
    /// upper bound reaches the iso-value ([`super::df3::containing_box`]),
    /// the whole grid when none does.
    pub contained_by: [[usize; 3]; 2],
    pub spacing: [f64; 3],
    pub encoding: HitEncoding,
    /// True when the colour render shows a photograph (`backdrop.png`).
    pub photo: bool,
}

impl PovExport {
    /// `povray` arguments for a render, run in [`PovExport::dir`].
    pub fn args(&self, variant: Variant, threads: usize) -> Vec<String> {
        vec![
            format!("+I{}", variant.pov_file()),
            format!("+O{}", variant.png_file()),
            format!("+W{}", self.width),
            format!("+H{}", self.height),
            "-D".into(),
            "-A".into(),
            "+Q9".into(),
            "+FN16".into(),
            "File_Gamma=1.0".into(),
            format!("Work_Threads={}", threads.max(1)),
        ]
    }

    /// A shell command line for a render.
    pub fn command_line(&self, variant: Variant, threads: usize) -> String {
        format!(
            "cd {} && povray {}",
            crate::human::shell_quote(&self.dir.display().to_string()),
            self.args(variant, threads).join(" ")
        )
    }
}

/// Writes the DF3, both `.pov` files (and the photo, if any) into `dir`
/// (created if missing) plus a `peer.json` manifest of the mapping.
pub fn export(
    dir: &Path,
    scene: &Scene,
    vol: &Volume,
    opts: &PovOptions,
) -> Result<PovExport, PeerError> {
    opts.check()?;
    std::fs::create_dir_all(dir).map_err(|e| PeerError::io(dir, e))?;
    let mapping = write_df3(&dir.join(DF3_FILE), vol)?;
    let estimate = max_gradient(vol, &mapping, opts.interpolation);
    let safety = opts
        .gradient_safety
        .unwrap_or_else(|| gradient_safety(opts.interpolation, vol.dims()));
    let max_gradient = opts.max_gradient.unwrap_or((estimate * safety).max(1e-6));
    let photo = matches!(scene.backdrop.pattern, Pattern::Image(_));
    if let Pattern::Image(tex) = &scene.backdrop.pattern {
        write_texture_png(&dir.join(BACKDROP_PNG), tex)?;
    }
    let ex = PovExport {
        dir: dir.to_path_buf(),
        width: scene.width,
        height: scene.height,
        mapping,
        interpolation: opts.interpolation,
        iso_density: mapping.density(scene.surface.iso),
        gradient_estimate: estimate,
        gradient_safety: safety,
        max_gradient,
        accuracy: opts.accuracy,
        ior: scene.surface.ior / scene.surface.outside_ior,
        max_trace_level: scene.render.max_events.clamp(1, MAX_TRACE_LEVEL),
        contained_by: containing_box(vol, &mapping, opts.interpolation, scene.surface.iso).map_or(
            [[0; 3], vol.dims().map(|n| n.saturating_sub(1))],
            |(lo, hi)| [lo, hi],
        ),
        spacing: vol.spacing(),
        encoding: HitEncoding::for_scene(scene),
        photo,
    };
    write_pov(dir, scene, &ex, Variant::Color)?;
    write_pov(dir, scene, &ex, Variant::Hits)?;
    let manifest = dir.join(MANIFEST);
    let json = serde_json::to_vec_pretty(&ex).map_err(|e| PeerError::Invalid(e.to_string()))?;
    write_atomic(&manifest, |w| std::io::Write::write_all(w, &json))
        .map_err(|e| PeerError::io(&manifest, e))?;
    Ok(ex)
}

/// Writes one variant's `.pov` into `dir`; returns its path.
pub fn write_pov(
    dir: &Path,
    scene: &Scene,
    ex: &PovExport,
    variant: Variant,
) -> Result<PathBuf, PeerError> {
    let text = pov_source(scene, ex, variant)?;
    let path = dir.join(variant.pov_file());
    write_atomic(&path, |w| std::io::Write::write_all(w, text.as_bytes()))
        .map_err(|e| PeerError::io(&path, e))?;
    Ok(path)
}

/// A number as POV-Ray reads it (shortest round-trip form).
fn num(x: f64) -> String {
    format!("{x:?}")
}

fn vec3(v: DVec3) -> String {
    format!("<{}, {}, {}>", num(v.x), num(v.y), num(v.z))
}

fn rgb(c: [f32; 3]) -> String {
    format!("rgb <{}, {}, {}>", c[0], c[1], c[2])
}

/// The text of one variant's `.pov` file.
pub fn pov_source(scene: &Scene, ex: &PovExport, variant: Variant) -> Result<String, PeerError> {
    use std::fmt::Write as _;
    let cam = &scene.camera;
    let aspect = cam.width as f64 / cam.height as f64;
    let camera = match cam.projection {
        Projection::Perspective { tan_half_fov: t } => format!(
            "camera {{\n  perspective\n  location {}\n  direction {}\n  right {}\n  up {}\n}}",
            vec3(cam.position),
            vec3(cam.forward),
            vec3(cam.right * (2.0 * t * aspect)),
            vec3(cam.up * (2.0 * t)),
        ),
        Projection::Orthographic { half_height: hh } => format!(
            "camera {{\n  orthographic\n  location {}\n  direction {}\n  right {}\n  up {}\n}}",
            vec3(cam.position),
            vec3(cam.forward),
            vec3(cam.right * (2.0 * hh * aspect)),
            vec3(cam.up * (2.0 * hh)),
        ),
    };
    let b = &scene.backdrop;
    let [mx, my, mz] = ex.mapping.file_dims;
    let [nx, ny, nz] = ex.mapping.dims;
    let (m, u, v, n, c) = (&ex.mapping, b.u_axis, b.v_axis, b.normal, b.center);
    // Pattern space (a, b, c) → world: center + a·u + b·v + c·n.
    let frame = format!(
        "matrix <{}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}>",
        num(u.x),
        num(u.y),
        num(u.z),
        num(v.x),
        num(v.y),
        num(v.z),
        num(n.x),
        num(n.y),
        num(n.z),
        num(c.x),
        num(c.y),
        num(c.z)
    );
    let background = match variant {
        Variant::Color => rgb(scene.background),
        Variant::Hits => "rgb 0".into(),
    };
    let mut s = String::new();
    let w = &mut s;
    let _ = writeln!(
        w,
        "// {} render of {} for POV-Ray 3.7, written by `snell export-pov`.",
        variant.name(),
        scene.path.display()
    );
    let _ = writeln!(
        w,
        "// Volume: {DF3_FILE}, {}x{}x{} samples plus a one-sample mirror border; \
         density = (value - {}) * {} / 65535.",
        nx,
        ny,
        nz,
        num(m.lo),
        num(m.scale)
    );
    if variant == Variant::Hits {
        let e = &ex.encoding;
        let _ = writeln!(
            w,
            "// Hit positions (16-bit PNG): k = B - 1 (B = 0: no hit), \
             u = {} + (k / 256 + R/65535) * {t}, v = {} + (k % 256 + G/65535) * {t}.",
            num(e.u0),
            num(e.v0),
            t = num(e.tile)
        );
    }
    let _ = writeln!(w, "#version 3.7;");
    let _ = writeln!(
        w,
        "global_settings {{ assumed_gamma 1.0 max_trace_level {} adc_bailout 0 ambient_light rgb 1 }}",
        ex.max_trace_level
    );
    let _ = writeln!(w, "{camera}");
    let _ = writeln!(w, "background {{ {background} }}");
    let _ = writeln!(
        w,
        "#declare Density = function {{ pattern {{ density_file df3 \"{DF3_FILE}\" interpolate {} frequency 0 }} }}",
        ex.interpolation.keyword()
    );
    let _ = writeln!(
        w,
        "isosurface {{\n  function {{ {} - Density((x + 1) / {mx}, (y + 1) / {my}, (z + 1) / {mz}) }}\n  \
         contained_by {{ box {{ {}, {} }} }}\n  threshold 0\n  accuracy {}\n  \
         max_gradient {}\n  max_trace 1\n  \
         texture {{ pigment {{ rgbf 1 }} finish {{ ambient 0 diffuse 0 specular 0 phong 0 reflection 0 }} }}\n  \
         interior {{ ior {} }}\n  scale <{}, {}, {}>\n}}",
        num(ex.iso_density),
        vec3(ex.contained_by[0].map(|c| c as f64).into()),
        vec3(ex.contained_by[1].map(|c| c as f64).into()),
        num(ex.accuracy),
        num(ex.max_gradient),
        num(ex.ior),
        num(ex.spacing[0]),
        num(ex.spacing[1]),
        num(ex.spacing[2]),
    );
    let finish = "finish { ambient 1 diffuse 0 specular 0 phong 0 reflection 0 }";
    let texture = match (variant, &b.pattern) {
        (Variant::Hits, _) => {
            let e = &ex.encoding;
            let _ = writeln!(
                w,
                "#declare BackdropU = function(x, y, z) {{ ((x - {}) * {} + (y - {}) * {} + (z - {}) * {} - {}) / {} }}",
                num(c.x),
                num(u.x),
                num(c.y),
                num(u.y),
                num(c.z),
                num(u.z),
                num(e.u0),
                num(e.tile)
            );
            let _ = writeln!(
                w,
                "#declare BackdropV = function(x, y, z) {{ ((x - {}) * {} + (y - {}) * {} + (z - {}) * {} - {}) / {} }}",
                num(c.x),
                num(v.x),
                num(c.y),
                num(v.y),
                num(c.z),
                num(v.z),
                num(e.v0),
                num(e.tile)
            );
            let _ = writeln!(
                w,
                "#declare InWindow = function(x, y, z) {{ (BackdropU(x, y, z) >= 0) & (BackdropU(x, y, z) < {HIT_TILES}) \
                 & (BackdropV(x, y, z) >= 0) & (BackdropV(x, y, z) < {HIT_TILES}) }}"
            );
            let _ = writeln!(
                w,
                "#declare Tile = function(x, y, z) {{ InWindow(x, y, z) * \
                 (256 * floor(BackdropU(x, y, z)) + floor(BackdropV(x, y, z)) + 1) / 65535 }}"
            );
            format!(
                "texture {{\n    pigment {{ average pigment_map {{\n      \
                 [1 function {{ BackdropU(x, y, z) - floor(BackdropU(x, y, z)) }} color_map {{ [0 rgb 0] [1 rgb <3, 0, 0>] }}]\n      \
                 [1 function {{ BackdropV(x, y, z) - floor(BackdropV(x, y, z)) }} color_map {{ [0 rgb 0] [1 rgb <0, 3, 0>] }}]\n      \
                 [1 function {{ Tile(x, y, z) }} color_map {{ [0 rgb 0] [1 rgb <0, 0, 3>] }}]\n    }} }}\n    {finish}\n  }}"
            )
        }
        (Variant::Color, Pattern::Checker { size, colors }) => format!(
            "texture {{\n    pigment {{ checker color {}, color {} translate <0, 0, -0.5> scale {} {frame} }}\n    {finish}\n  }}",
            rgb(colors[0]),
            rgb(colors[1]),
            num(*size)
        ),
        (Variant::Color, Pattern::Image(tex)) => {
            // Unit square (row 0 on top at y = 1) → u ∈ ±W/2, v ∈ ±H/2.
            format!(
                "texture {{ pigment {{ {} }} {finish} }}\n  \
                 texture {{\n    pigment {{ image_map {{ png \"{BACKDROP_PNG}\" gamma 1.0 interpolate 2 once }} \
                 translate <-0.5, -0.5, 0> scale <{}, {}, 1> {frame} }}\n    {finish}\n  }}",
                rgb(tex.outside),
                num(tex.world_width),
                num(tex.world_height())
            )
        }
    };
    let _ = writeln!(
        w,
        "plane {{\n  {}, {}\n  {texture}\n}}",
        vec3(n),
        num(n.dot(c))
    );
    Ok(s)
}

/// A photograph backdrop as 16-bit PNG, for `image_map` (POV-Ray may only
/// read files in its working directory).
fn write_texture_png(path: &Path, tex: &crate::scene::Texture) -> Result<(), PeerError> {
    use image::ImageEncoder;
    let bytes: Vec<u8> = tex
        .pixels
        .iter()
        .flat_map(|p| p.iter().copied())
        .flat_map(|c| (((c.clamp(0.0, 1.0) * 65535.0).round()) as u16).to_be_bytes())
        .collect();
    write_atomic(path, |w| {
        image::codecs::png::PngEncoder::new(w)
            .write_image(
                &bytes,
                tex.width_px as u32,
                tex.height_px as u32,
                image::ExtendedColorType::Rgb16,
            )
            .map_err(std::io::Error::other)
    })
    .map_err(|e| PeerError::io(path, e))
}

/// POV-Ray's own statistics of one render (seconds as it reports them).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct PovStats {
    pub parse_seconds: Option<f64>,
    pub bounding_seconds: Option<f64>,
    pub trace_seconds: Option<f64>,
    /// CPU seconds of the trace, summed over threads.
    pub trace_cpu_seconds: Option<f64>,
    pub threads: Option<usize>,
    /// Largest gradient POV-Ray met, when it warns about `max_gradient`.
    pub max_gradient_found: Option<f64>,
    /// Warning lines.
    pub warnings: Vec<String>,
}

impl PovStats {
    /// Parse + bounding + trace, POV-Ray's whole render.
    pub fn render_seconds(&self) -> Option<f64> {
        Some(self.parse_seconds? + self.bounding_seconds.unwrap_or(0.0) + self.trace_seconds?)
    }
}

/// Seconds in POV-Ray's `... (1.234 seconds)`.
fn paren_seconds(line: &str) -> Option<f64> {
    let open = line.rfind('(')?;
    let rest = &line[open + 1..];
    rest.split_whitespace().next()?.parse().ok()
}

/// Parses POV-Ray's statistics stream (stderr).
pub fn parse_stats(text: &str) -> PovStats {
    let mut s = PovStats::default();
    let lines: Vec<&str> = text
        .split(['\n', '\r'])
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect();
    for (i, l) in lines.iter().enumerate() {
        if l.starts_with("Parse Time:") {
            s.parse_seconds = paren_seconds(l);
        } else if l.starts_with("Bounding Time:") {
            s.bounding_seconds = paren_seconds(l);
        } else if l.starts_with("Trace Time:") {
            s.trace_seconds = paren_seconds(l);
            if let Some(next) = lines.get(i + 1)
                && let Some(rest) = next.strip_prefix("using ")
            {
                let words: Vec<&str> = rest.split_whitespace().collect();
                s.threads = words.first().and_then(|w| w.parse().ok());
                s.trace_cpu_seconds = words
                    .iter()
                    .position(|w| *w == "with")
                    .and_then(|k| words.get(k + 1))
                    .and_then(|w| w.parse().ok());
            }
        }
        let lower = l.to_ascii_lowercase();
        if lower.contains("warning") && !lower.contains("stream to console") {
            // A warning may continue on the next lines; keep them together.
            let mut text = l.to_string();
            for next in lines.iter().skip(i + 1).take(3) {
                let nl = next.to_ascii_lowercase();
                if nl.contains("warning") || next.starts_with('-') || next.starts_with('=') {
                    break;
                }
                text.push(' ');
                text.push_str(next);
            }
            s.warnings.push(text);
        }
        if let Some(k) = lower.find("maximum gradient found was") {
            let tail = &l[k + "maximum gradient found was".len()..];
            let word = tail.split_whitespace().next().unwrap_or("");
            if let Ok(g) = word.trim_end_matches([',', '.']).parse::<f64>() {
                s.max_gradient_found = Some(s.max_gradient_found.map_or(g, |o: f64| o.max(g)));
            }
        }
    }
    s
}

/// Decodes a `hits` render into a hit image (events unknown: NaN).
pub fn decode_hits(png: &Path, enc: &HitEncoding) -> Result<HitImage, PeerError> {
    let bad = |msg: String| PeerError::Format {
        path: png.to_path_buf(),
        msg,
    };
    let img = image::ImageReader::open(png)
        .map_err(|e| PeerError::io(png, e))?
        .with_guessed_format()
        .map_err(|e| PeerError::io(png, e))?
        .decode()
        .map_err(|e| bad(e.to_string()))?;
    if !matches!(img, image::DynamicImage::ImageRgb16(_)) {
        return Err(bad(format!(
            "expected a 16-bit RGB PNG (+FN16), got {:?}",
            img.color()
        )));
    }
    let img = img.into_rgb16();
    let (w, h) = img.dimensions();
    let n = (w as usize) * (h as usize);
    let (mut u, mut v) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for p in img.pixels() {
        let (a, b) = enc.decode(p.0).unwrap_or((f64::NAN, f64::NAN));
        u.push(a as f32);
        v.push(b as f32);
    }
    Ok(HitImage {
        width: w,
        height: h,
        u,
        v,
        events: vec![f32::NAN; n],
    })
}

/// The `povray` executable on `PATH`.
pub fn povray_binary() -> Result<PathBuf, PeerError> {
    let path = std::env::var_os("PATH").ok_or(PeerError::NotInstalled)?;
    for dir in std::env::split_paths(&path) {
        let p = dir.join("povray");
        if p.is_file() {
            return Ok(p);
        }
    }
    Err(PeerError::NotInstalled)
}

/// True when `povray` is on `PATH`.
pub fn installed() -> bool {
    povray_binary().is_ok()
}

/// One POV-Ray render: its statistics, wall time and output image.
#[derive(Clone, Debug, serde::Serialize)]
pub struct RenderRun {
    pub png: PathBuf,
    pub stats: PovStats,
    /// Whole `povray` process, start to exit.
    pub wall_seconds: f64,
}

/// Renders one variant of an export with `threads` threads.
pub fn render(ex: &PovExport, variant: Variant, threads: usize) -> Result<RenderRun, PeerError> {
    let bin = povray_binary()?;
    let png = ex.dir.join(variant.png_file());
    match std::fs::remove_file(&png) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(PeerError::io(&png, e)),
    }
    let start = Instant::now();
    let out = Command::new(&bin)
        .current_dir(&ex.dir)
        .args(ex.args(variant, threads))
        .stdin(Stdio::null())
        .output()
        .map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => PeerError::NotInstalled,
            _ => PeerError::io(&bin, e),
        })?;
    let wall_seconds = start.elapsed().as_secs_f64();
    let text =
        String::from_utf8_lossy(&out.stderr).into_owned() + &String::from_utf8_lossy(&out.stdout);
    if !out.status.success() || !png.is_file() {
        let msg: Vec<&str> = text
            .lines()
            .map(str::trim)
            .filter(|l| {
                let l = l.to_ascii_lowercase();
                l.contains("error") || l.contains("fatal")
            })
            .take(4)
            .collect();
        return Err(PeerError::Failed {
            variant: variant.name(),
            status: out.status.to_string(),
            msg: if msg.is_empty() {
                format!("no {} written", png.display())
            } else {
                msg.join(" | ")
            },
        });
    }
    Ok(RenderRun {
        png,
        stats: parse_stats(&text),
        wall_seconds,
    })
}

/// A scene rendered by POV-Ray: timings of the colour render (the one to
/// compare with snell's), the hit render, and the decoded hit image.
#[derive(Clone, Debug)]
pub struct PeerRun {
    pub export: PovExport,
    /// The colour image (16-bit PNG).
    pub color_png: PathBuf,
    /// POV-Ray's statistics of the colour render.
    pub stats: PovStats,
    /// Wall time of the colour render's whole `povray` process.
    pub wall_seconds: f64,
    /// The hit render (same tracing work, different backdrop pigment).
    pub hits_run: RenderRun,
    /// Decoded hit positions (`events` NaN: POV-Ray does not report them).
    pub hits: HitImage,
}

impl PeerRun {
    /// POV-Ray's trace time of the colour render.
    pub fn trace_seconds(&self) -> Option<f64> {
        self.stats.trace_seconds
    }
}

/// Exports `scene` into `dir` and renders it with POV-Ray: default options
/// for the scene (interpolation from its filter, accuracy 1e-3, or 1e-4 when
/// `careful`).
pub fn run(dir: &Path, scene: &Scene, threads: usize, careful: bool) -> Result<PeerRun, PeerError> {
    povray_binary()?;
    let vol = scene.load_volume(&LoadOptions::default())?;
    run_with(dir, scene, &vol, &PovOptions::new(scene, careful), threads)
}

/// [`run`] with an already loaded volume and explicit options.
pub fn run_with(
    dir: &Path,
    scene: &Scene,
    vol: &Volume,
    opts: &PovOptions,
    threads: usize,
) -> Result<PeerRun, PeerError> {
    povray_binary()?;
    let ex = export(dir, scene, vol, opts)?;
    let color = render(&ex, Variant::Color, threads)?;
    let hits_run = render(&ex, Variant::Hits, threads)?;
    let hits = decode_hits(&hits_run.png, &ex.encoding)?;
    if (hits.width, hits.height) != (scene.width, scene.height) {
        return Err(PeerError::Format {
            path: hits_run.png.clone(),
            msg: format!(
                "image is {}x{}, the scene is {}x{}",
                hits.width, hits.height, scene.width, scene.height
            ),
        });
    }
    Ok(PeerRun {
        export: ex,
        color_png: color.png,
        stats: color.stats,
        wall_seconds: color.wall_seconds,
        hits_run,
        hits,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stats_are_parsed() {
        let text = "Parser Time\n  Parse Time:       0 hours  0 minutes  0 seconds (0.125 seconds)\n\
              using 1 thread(s) with 0.120 CPU-seconds total\n\
              Bounding Time:    0 hours  0 minutes  0 seconds (0.002 seconds)\n\
              Render Time:\n  Trace Time:       0 hours  0 minutes  3 seconds (3.456 seconds)\n\
              using 2 thread(s) with 6.800 CPU-seconds total\n\
              Possible Parse Error: Warning: The maximum gradient found was 0.312, but max_gradient of\n\
              the isosurface was set to 0.200. The isosurface may contain holes!\n";
        let s = parse_stats(text);
        assert_eq!(s.parse_seconds, Some(0.125));
        assert_eq!(s.bounding_seconds, Some(0.002));
        assert_eq!(s.trace_seconds, Some(3.456));
        assert_eq!(s.threads, Some(2));
        assert_eq!(s.trace_cpu_seconds, Some(6.8));
        assert_eq!(s.max_gradient_found, Some(0.312));
        assert_eq!(s.warnings.len(), 1);
        assert!((s.render_seconds().unwrap() - 3.583).abs() < 1e-12);
    }

    #[test]
    fn encoding_round_trips() {
        let e = HitEncoding {
            u0: -100.0,
            v0: -50.0,
            tile: 2.0,
        };
        assert_eq!(e.decode([0, 65535, 1]), Some((-100.0, -48.0)));
        assert_eq!(e.decode([0, 0, 256 * 3 + 4 + 1]), Some((-94.0, -42.0)));
        assert_eq!(e.decode([100, 100, 0]), None);
        assert!((e.resolution() - 2.0 / 65535.0).abs() < 1e-15);
        assert_eq!(e.window(), 510.0);
    }
}
