//! Scene files: what to render, parsed from TOML into a validated [`Scene`].
//!
//! A scene names an image size, a camera, a volume (a file or a phantom), the
//! refracting surface (filter, iso-value, indices of refraction), the backdrop
//! and render settings. `--set section.key=value` overrides are applied to the
//! parsed TOML table before validation, so an override is checked exactly like
//! a value written in the file. Every error names the file and the key.
//!
//! From text to scene: `file` (the TOML schema serde reads) → `overrides`
//! (`--set` applied to the parsed table) → `resolve` (every value checked,
//! paths resolved beside the file, the photograph loaded) → [`Scene`].
//! `words` rewords serde's and TOML's refusals for people; [`settings`]
//! holds the render settings and their named choices; [`camera`],
//! [`backdrop`] and [`orbit`] the geometry; [`framing`] places a camera
//! and a checkerboard for a volume and writes the scene file (`snell
//! scene`).

pub mod backdrop;
pub mod camera;
mod file;
pub mod framing;
pub mod orbit;
mod overrides;
mod resolve;
pub mod settings;
mod words;

use std::path::{Path, PathBuf};

use glam::DVec3;

pub use backdrop::{Backdrop, Pattern, Texture};
pub use camera::{Camera, CameraError, Projection};
pub use orbit::{Orbit, OrbitError};
pub use overrides::{apply_override, override_key, override_keys};
pub(crate) use resolve::setting_name;
pub use settings::{
    FootprintFilter, PrssFallback, PrssMap, RenderSettings, Storage, Supersampling, Traversal,
};

use file::SceneFile;
use overrides::{blame_override, culprit_override, written_keys};
use resolve::{phantom_spec, resolve, setting_message};
use words::syntax_error;

use crate::classify::Method;
use crate::film::FrameId;
use crate::filter::FilterKind;
use crate::phantom::{PhantomError, PhantomSpec};
use crate::volume::{LoadOptions, RawSpec, Volume, VolumeError};

/// Classification the cell traversals (`dda`, `octree`, `distance`) use when
/// the scene names none; `classify = "none"` makes `dda` bound each visited
/// cell from its coefficients on the fly instead.
pub const DEFAULT_CLASSIFY: Method = Method::Bezier(2);

/// Largest image side accepted (and 2^28 pixels in all).
pub const MAX_IMAGE_SIDE: u32 = 32768;
pub const MAX_IMAGE_PIXELS: u64 = 1 << 28;

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
    /// An error on a key a `--set` wrote; `over_limit` keeps the refusal's
    /// type when the key sized a working set over the memory limit.
    #[error("--set {arg}: {msg}")]
    Override {
        arg: String,
        msg: String,
        #[source]
        over_limit: Option<crate::volume::limits::OverLimit>,
    },
    #[error(transparent)]
    Volume(#[from] VolumeError),
    #[error("{path}: phantom: {msg}")]
    Phantom { path: PathBuf, msg: String },
    /// A working set over the memory limit, refused before it was allocated;
    /// `key` names the setting that sized it.
    #[error("{path}: [{key}] {source}")]
    OverLimit {
        path: PathBuf,
        key: String,
        #[source]
        source: crate::volume::limits::OverLimit,
    },
    #[error("render.coefficients = \"{storage}\": {msg}")]
    Storage { storage: &'static str, msg: String },
}

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
    /// use or uses otherwise than written, one message each (see
    /// [`Scene::setting_notes`]).
    notes: Vec<SettingNote>,
    /// The `--set` overrides it was read with, to name one as the cause of
    /// an error found later (in [`Scene::load_volume`]).
    overrides: Vec<String>,
    /// The keys the file or `--set` wrote (see [`written_keys`]).
    written: Vec<(String, String)>,
    /// The keys the file alone wrote.
    file_keys: Vec<String>,
}

/// A setting the scene does not use as written, and the message that says
/// so (a command that reads less of a scene than a render passes over the
/// notes on what it does not read, and says so in its own words).
#[derive(Clone, Debug, PartialEq)]
pub struct SettingNote {
    /// The setting's key, `render.step`.
    pub key: String,
    /// The message: the setting as written, and why it goes unused.
    pub text: String,
}

impl std::fmt::Display for SettingNote {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.text)
    }
}

impl Scene {
    /// The settings the user wrote (in the file or with `--set`; defaults
    /// never count) that have no effect on this scene, each as a message
    /// naming the key and why: `camera.fov_y`/`camera.height` of the other
    /// projection, `backdrop.width`/`outside` with a checker and
    /// `checker_colors` with a photograph, `render.step` with a cell
    /// traversal, the anti-aliasing settings with `supersampling = "none"`
    /// (and `footprint` without the footprint mode), and `surface.lambda`
    /// with a filter that does not smooth; and one setting used otherwise
    /// than written: a `backdrop.u_axis` out of the backdrop's plane, whose
    /// projection onto it is used.
    pub fn setting_notes(&self) -> &[SettingNote] {
        &self.notes
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

    /// Reads, overrides and validates a scene file, refusing a frame whose
    /// buffers alone would pass the memory limit.
    pub fn load(path: &Path, overrides: &[String]) -> Result<Scene, SceneError> {
        Scene::load_checked(path, overrides, true)
    }

    /// [`Scene::load`] for a renderer of one part of the frame (`render
    /// --region`): the whole frame's buffers may pass the memory limit, as
    /// a frame split across machines does; the renderer checks its part's
    /// ([`Scene::check_memory`] with its window).
    pub fn load_part(path: &Path, overrides: &[String]) -> Result<Scene, SceneError> {
        Scene::load_checked(path, overrides, false)
    }

    fn load_checked(path: &Path, overrides: &[String], frame: bool) -> Result<Scene, SceneError> {
        // A volume or an image given where a scene goes is the likely
        // mistake behind a file that is not TOML: say so, and how to make
        // a scene for a volume.
        const NOT_A_SCENE: &str = "a scene is a TOML text file (scenes/*.toml); for a volume, `snell scene VOLUME -o SCENE.toml` writes one";
        let text = crate::input::read_to_string(path).map_err(|source| {
            if source.kind() == std::io::ErrorKind::InvalidData {
                SceneError::Syntax {
                    path: path.to_path_buf(),
                    msg: format!("not a scene file: it is not text ({source}); {NOT_A_SCENE}"),
                }
            } else {
                SceneError::Io {
                    path: path.to_path_buf(),
                    source,
                }
            }
        })?;
        let toml_named = crate::input::has_extension(path, "toml");
        let scene = Scene::parse_unchecked(&text, path, overrides).map_err(|e| match e {
            SceneError::Syntax { path, msg } if !toml_named => SceneError::Syntax {
                path,
                msg: format!("{msg} (is it a scene file? {NOT_A_SCENE})"),
            },
            e => e,
        })?;
        if frame {
            scene.check_frame_memory()?;
        }
        Ok(scene)
    }

    /// Parses scene text; `path` is used for messages and relative paths.
    /// An error caused by a `--set` override names that override, not the
    /// file. A frame whose buffers alone would pass the memory limit is
    /// refused, as [`Scene::load`] does.
    pub fn parse(text: &str, path: &Path, overrides: &[String]) -> Result<Scene, SceneError> {
        let scene = Scene::parse_unchecked(text, path, overrides)?;
        scene.check_frame_memory()?;
        Ok(scene)
    }

    /// The frame's buffers and one tile's scratch, the least a render of
    /// the whole frame needs, against the memory limit: so that whether a
    /// scene file is accepted does not depend on the machine's cores; a
    /// renderer checks again with its own thread count (`snell render` does
    /// once its pool is built).
    fn check_frame_memory(&self) -> Result<(), SceneError> {
        self.memory_check(crate::volume::limits::default_memory_limit(), None, None)
            .map_err(|e| blame_override(e, &self.overrides, &self.written, &self.file_keys))
    }

    fn parse_unchecked(text: &str, path: &Path, overrides: &[String]) -> Result<Scene, SceneError> {
        let mut table: toml::Table = text
            .parse()
            .map_err(|e: toml::de::Error| syntax_error(text, path, &e))?;
        let mut file_written = Vec::new();
        written_keys(&table, "", &mut file_written);
        let file_keys: Vec<String> = file_written.into_iter().map(|(k, _)| k).collect();
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
        let key_error = |key: String, msg: String| SceneError::Key {
            path: path.to_path_buf(),
            key,
            msg,
        };
        // `[[image]]` makes a list of tables, which serde would report as
        // the section's first setting of the wrong type.
        for (name, value) in &table {
            if let toml::Value::Array(items) = value
                && items.iter().any(|v| v.is_table())
            {
                return Err(key_error(
                    name.clone(),
                    format!(
                        "is written [[{name}]], a list of tables; a scene has one, written [{name}]"
                    ),
                ));
            }
        }
        let de = toml::Value::Table(table);
        let result = serde_path_to_error::deserialize(de)
            .map_err(|e| {
                let key = e.path().to_string();
                let key = if key == "." { "scene".into() } else { key };
                let msg = setting_message(&key, e.into_inner().message());
                key_error(key, msg)
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
                scene.file_keys = file_keys;
                Ok(scene)
            }
            Err(e) => Err(blame_override(e, overrides, &written, &file_keys)),
        }
    }

    /// Loads (or builds) the volume and applies the scene's spacing override.
    /// An error on a key a `--set` wrote names that `--set`, as does the
    /// reader's error on a file a `--set volume.path` named.
    pub fn load_volume(&self, opts: &LoadOptions) -> Result<Volume, SceneError> {
        self.load_volume_unblamed(opts)
            .map_err(|e| blame_override(e, &self.overrides, &self.written, &self.file_keys))
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
                    // The file the scene file names is missing: said as
                    // the scene's setting, with where a relative path is
                    // looked for.
                    VolumeError::Io { path: file, source }
                        if source.kind() == std::io::ErrorKind::NotFound
                            && file == *path
                            && culprit_override("volume.path", &self.overrides).is_none() =>
                    {
                        SceneError::Key {
                            path: self.path.clone(),
                            key: "volume.path".into(),
                            msg: format!(
                                "{}: no such file (a relative path is read from the scene file's folder)",
                                file.display()
                            ),
                        }
                    }
                    // The file a `--set volume.path` named.
                    e => match culprit_override("volume.path", &self.overrides) {
                        Some(o) => SceneError::Override {
                            arg: o.clone(),
                            msg: match &e {
                                VolumeError::Io { path: file, source }
                                    if source.kind() == std::io::ErrorKind::NotFound
                                        && file == path =>
                                {
                                    format!(
                                        "{}: no such file (a relative path given with --set is read from the working directory)",
                                        file.display()
                                    )
                                }
                                e => e.to_string(),
                            },
                            over_limit: match e {
                                VolumeError::OverLimit { source, .. } => Some(source),
                                _ => None,
                            },
                        },
                        None => e.into(),
                    },
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
                        VolumeError::OverLimit { source, .. } => SceneError::OverLimit {
                            path: self.path.clone(),
                            key: "volume.phantom.size".into(),
                            source,
                        },
                        e => phantom_error(e.to_string()),
                    })?;
                // Its settings were checked when the scene was read.
                spec.build().map_err(|e| match e {
                    PhantomError::Invalid(msg) => phantom_error(msg),
                    PhantomError::Setting { key, msg } => SceneError::Key {
                        path: self.path.clone(),
                        key: format!("volume.phantom.{key}"),
                        msg,
                    },
                })?
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

    /// Memory a render needs besides the volume: frame buffers for the
    /// `w`×`h` pixels of its film (the whole image, or a `--region` part's
    /// window and apron), and one tile's ray packet per worker thread (a
    /// tile traces its part of the film, so no more than the film's pixels
    /// however large `render.tile` is).
    pub fn memory_need_of(&self, (w, h): (u32, u32), threads: usize) -> (u64, u64) {
        let tile = self.render.tile;
        let tile_pixels = u64::from(tile.min(w)) * u64::from(tile.min(h));
        let tile_rays = tile_pixels * self.rays_per_pixel();
        (
            u64::from(w) * u64::from(h) * FRAME_BYTES_PER_PIXEL,
            threads.max(1) as u64 * tile_rays * TILE_BYTES_PER_RAY,
        )
    }

    /// Refuses (before anything is allocated) a render whose frame buffers
    /// and tile scratch for `threads` worker threads would exceed `limit`
    /// bytes; `part`: the size of the film a `--region` render holds (its
    /// window and apron), `None` for the whole frame. An error on a key a
    /// `--set` wrote names that `--set`.
    pub fn check_memory(
        &self,
        limit: u64,
        threads: usize,
        part: Option<(u32, u32)>,
    ) -> Result<(), SceneError> {
        self.memory_check(limit, Some(threads), part)
            .map_err(|e| blame_override(e, &self.overrides, &self.written, &self.file_keys))
    }

    fn memory_check(
        &self,
        limit: u64,
        threads: Option<usize>,
        part: Option<(u32, u32)>,
    ) -> Result<(), SceneError> {
        let size = part.unwrap_or((self.width, self.height));
        let (frame, scratch) = self.memory_need_of(size, threads.unwrap_or(1));
        let need = frame.saturating_add(scratch);
        if need <= limit {
            return Ok(());
        }
        let hb = crate::volume::limits::human_bytes;
        Err(SceneError::Key {
            path: self.path.clone(),
            // The tiles' scratch grows with the rays a pixel takes and the
            // tile's size: the setting to lower is the one that made it.
            key: if scratch <= frame {
                "image"
            } else if self.rays_per_pixel() > 1 {
                "render.samples"
            } else {
                "render.tile"
            }
            .into(),
            msg: format!(
                "{} at {} per pixel needs about {} of memory (frame {}, tile scratch {} for {} of {}x{}-pixel tiles), over the limit of {}; lower the {}, render.samples, render.tile or --threads, or raise the limit (--memory-limit or SNELL_MEMORY_LIMIT)",
                match part {
                    None => format!("a {}x{} image", self.width, self.height),
                    Some((w, h)) => format!(
                        "a {w}x{h} part (region and apron) of a {}x{} image",
                        self.width, self.height
                    ),
                },
                match self.rays_per_pixel() {
                    1 => "1 ray".to_string(),
                    n => format!("{n} rays"),
                },
                hb(need),
                hb(frame),
                hb(scratch),
                match threads.map(|n| n.max(1)) {
                    None => "at least one thread".to_string(),
                    Some(1) => "1 thread".to_string(),
                    Some(n) => format!("{n} threads"),
                },
                self.render.tile,
                self.render.tile,
                hb(limit),
                if part.is_some() { "region" } else { "size" }
            ),
        })
    }
}

impl Scene {
    /// A fingerprint of the frame this scene renders from a volume whose
    /// [`Volume::content_hash`] is `volume_hash`: its image size, camera,
    /// surface, backdrop (a photograph by its pixels), render settings and
    /// the volume's samples and spacing; not the scene's or the volume's
    /// file names (each machine of a split render may read them from its own
    /// path), nor what leaves the pixels as they are: the tile size, the
    /// walk's shortcuts, and the settings the frame does not read (those
    /// its warnings call ignored: `step` with a cell traversal, a seed
    /// without jitter, …), nor which cell traversal and classification find
    /// the crossings (DDA, octree and distance cubes over any tags give the
    /// same bits, `tests/accel.rs`; the step march does not). The parts of
    /// one frame (`render --region`) carry it, and `snell merge` refuses
    /// parts whose fingerprints differ.
    pub fn frame_fingerprint(&self, volume_hash: u64) -> FrameId {
        let b = &self.backdrop;
        let pattern = match &b.pattern {
            Pattern::Checker { .. } => format!("{:?}", b.pattern),
            Pattern::Image(t) => {
                let mut h = crate::volume::WordHash::new();
                for p in &t.pixels {
                    h.add(u64::from(p[0].to_bits()) | u64::from(p[1].to_bits()) << 32);
                    h.add(u64::from(p[2].to_bits()));
                }
                format!(
                    "image {}x{} {:?} {:?} {:x}",
                    t.width_px,
                    t.height_px,
                    t.world_width,
                    t.outside,
                    h.value()
                )
            }
        };
        let mut render = self.render;
        render.tile = 0;
        render.clear_crossing_cells = true;
        render.skip_empty_approach = true;
        render.skip_clear_segments = true;
        // A setting the frame does not read does not make another frame.
        for (setting, _) in resolve::unread_render_settings(&self.render) {
            setting.normalise(&mut render);
        }
        // Nor does the way the cells holding crossings are found.
        if render.traversal != Traversal::Step {
            render.traversal = Traversal::Dda;
            render.classify = None;
            render.leaf = 0;
        }
        // In the order of FRAME_ASPECTS.
        let aspects = [
            (volume_hash, format!("{:?}", self.spacing)),
            (
                0,
                format!("{}x{} {:?}", self.width, self.height, self.background),
            ),
            (0, format!("{:?}", self.camera)),
            (0, format!("{:?}", self.surface)),
            (
                0,
                format!("{:?} {:?} {:?} {pattern}", b.center, b.normal, b.u_axis),
            ),
            (0, format!("{render:?}")),
        ]
        .map(|(seed, text)| {
            let mut h = crate::volume::WordHash::new();
            h.add(seed);
            for word in text.as_bytes().chunks(8) {
                let mut w = [0u8; 8];
                w[..word.len()].copy_from_slice(word);
                h.add(u64::from_le_bytes(w));
            }
            h.value()
        });
        FrameId::of_aspects(aspects)
    }
}

/// `v` divided by its largest absolute component (zero and non-finite
/// vectors unchanged): the same direction, with a length from 1 to √3.
pub(crate) fn unit_scale(v: DVec3) -> DVec3 {
    let m = v.abs().max_element();
    if m > 0.0 && m.is_finite() { v / m } else { v }
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
        // One key per --set: a second after a line break is refused, not
        // dropped; a value broken over lines is still one value.
        let e = parse(&["image.width=16\nimage.height=4"])
            .unwrap_err()
            .to_string();
        assert!(e.contains("line break and more keys"), "{e}");
        let s = parse(&["camera.up=[0.0,\n 1.0, 0.0]"]).unwrap();
        assert_eq!(s.camera.up, DVec3::Y);
    }

    /// The default tile follows the first pass's rays per pixel; a tile
    /// the scene names is kept, and checked.
    #[test]
    fn tile_defaults_to_the_supersampling_and_is_checked() {
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
                &["backdrop.normal=[0.0, 0.0, nan]"],
                "--set backdrop.normal=[0.0, 0.0, nan]: ",
            ),
            (&["foo.bar=1"], "--set foo.bar=1: [foo] "),
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
        // One line: where, what, and the line itself.
        assert_eq!(
            e,
            "bad.toml: line 1, column 7: unclosed table, expected `]` (in: [image)"
        );
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

    /// An error on a key the file wrote names the file, and the overrides of
    /// its section that may have caused it; the others are left out.
    #[test]
    fn file_errors_list_the_overrides_of_their_section() {
        let e = parse(&["camera.kind=orthographic", "surface.ior=1.4"])
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("test.toml: [camera.height] ")
                && e.ends_with(" (read with --set camera.kind=orthographic)"),
            "{e}"
        );
        let e = parse_text(
            |s| s.replace("size = 32", "size = 32\nradius = \"ten\""),
            &["volume.phantom.sigma=2.0"],
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.starts_with("test.toml: [volume.phantom.radius] ")
                && e.contains("--set volume.phantom.sigma"),
            "{e}"
        );
        // No override of the section: the message alone.
        let e = parse_text(
            |s| s.replace("ior = 1.5", "ior = -1.5"),
            &["image.width=32"],
        )
        .unwrap_err()
        .to_string();
        assert!(!e.contains("--set"), "{e}");
    }

    /// A relative path typed with `--set` is read from the current
    /// directory; the file's own paths from the file's folder.
    #[test]
    fn override_paths_are_read_from_the_current_directory() {
        let file = |s: &Scene| match &s.volume {
            VolumeSource::File { path, .. } => path.clone(),
            v => panic!("{v:?}"),
        };
        let s = Scene::parse(
            SCENE,
            Path::new("scenes/test.toml"),
            &["volume.path=data/v.nrrd".into()],
        )
        .unwrap();
        let cwd = std::env::current_dir().unwrap();
        assert_eq!(file(&s), cwd.join("data/v.nrrd"));
        let s = Scene::parse(
            &SCENE.replace(
                "[volume.phantom]\nkind = \"sphere\"\nsize = 32\nformat = \"u8\"",
                "[volume]\npath = \"data/v.nrrd\"",
            ),
            Path::new("scenes/test.toml"),
            &[],
        )
        .unwrap();
        assert_eq!(file(&s), Path::new("scenes/data/v.nrrd"));
        let s = Scene::parse(
            SCENE,
            Path::new("t.toml"),
            &["volume.path=/abs/v.nrrd".into()],
        )
        .unwrap();
        assert_eq!(file(&s), Path::new("/abs/v.nrrd"));
    }

    /// A `--set` that names one volume source drops the other, whichever
    /// key of it it names; a raw layout goes with the file it described.
    #[test]
    fn a_set_switches_the_volume_source() {
        let file_scene = |s: &str| {
            s.replace(
                "[volume.phantom]\nkind = \"sphere\"\nsize = 32\nformat = \"u8\"",
                "[volume]\npath = \"v.raw\"\n[volume.raw]\ndims = [2, 2, 2]\ntype = \"u8\"",
            )
        };
        assert!(matches!(
            parse_text(file_scene, &[]).unwrap().volume,
            VolumeSource::File { raw: Some(_), .. }
        ));
        for set in [
            "volume.phantom.kind=sphere",
            "volume.phantom={kind=\"sphere\"}",
        ] {
            let s = parse_text(file_scene, &[set]).unwrap();
            assert!(matches!(s.volume, VolumeSource::Phantom(_)), "{set}");
        }
        let s = parse_text(|s| s.to_string(), &["volume.path=v.nrrd"]).unwrap();
        assert!(matches!(s.volume, VolumeSource::File { raw: None, .. }));
        // A --set of a file whose name gives its format drops the raw
        // layout; one in the file itself is refused, as the command line's
        // --dims and --type are.
        let s = parse_text(file_scene, &["volume.path=v.nrrd"]).unwrap();
        assert!(matches!(s.volume, VolumeSource::File { raw: None, .. }));
        let e = parse_text(|s| file_scene(s).replace("v.raw", "v.nrrd"), &[])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("[volume.raw]") && e.contains("a NRRD file, whose header gives its layout"),
            "{e}"
        );
    }

    /// A `--set` of one backdrop pattern drops the other's settings: a
    /// photograph over a checkerboard, a checkerboard over a photograph.
    #[test]
    fn a_set_switches_the_backdrop_pattern() {
        let s = parse(&["backdrop.checker_colors=[[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]"]).unwrap();
        assert!(matches!(s.backdrop.pattern, Pattern::Checker { .. }));
        let photo_path = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/photo.jpg");
        let set_photo = format!("backdrop.image={photo_path}");
        let s = parse(&[&set_photo, "backdrop.width=100.0"]).unwrap();
        assert!(s.setting_notes().is_empty(), "{:?}", s.setting_notes());
        assert!(s.backdrop_image.is_some());
        let photo = |t: &str| {
            t.replace(
                "checker = 8.0",
                &format!("image = \"{photo_path}\"\nwidth = 80.0"),
            )
        };
        let s = parse_text(photo, &["backdrop.checker=4.0"]).unwrap();
        assert!(matches!(s.backdrop.pattern, Pattern::Checker { size, .. } if size == 4.0));
        assert!(s.backdrop_image.is_none());
        // Of two, the last wins; both in the file is a contradiction.
        let s = parse(&[&set_photo, "backdrop.checker=4.0"]).unwrap();
        assert!(s.backdrop_image.is_none());
        let both = |t: &str| {
            t.replace(
                "checker = 8.0",
                &format!("checker = 8.0\nimage = \"{photo_path}\""),
            )
        };
        let e = parse_text(both, &[]).unwrap_err();
        assert!(e.to_string().contains("not both"), "{e}");
    }

    /// A `--set` of another phantom kind drops the last kind's shape (a
    /// sphere's size and radius mean nothing to Marschner–Lobb), keeping
    /// what every kind has (the format); the same kind keeps everything.
    #[test]
    fn a_set_switches_the_phantom_kind() {
        use crate::phantom::{PhantomFormat, PhantomSpec};
        let s = parse(&["volume.phantom.kind=marschner-lobb"]).unwrap();
        match s.volume {
            VolumeSource::Phantom(PhantomSpec::MarschnerLobb(m)) => {
                assert_eq!((m.size, m.format), (41, PhantomFormat::U8));
            }
            v => panic!("{v:?}"),
        }
        let s = parse(&["volume.phantom.kind=sphere"]).unwrap();
        match s.volume {
            VolumeSource::Phantom(PhantomSpec::Sphere(p)) => assert_eq!(p.size, 32),
            v => panic!("{v:?}"),
        }
    }

    /// A section written as a list of tables is named as such, not as its
    /// first setting of the wrong type.
    #[test]
    fn a_section_written_as_a_list_is_named() {
        let e = parse_text(|s| s.replace("[image]", "[[image]]"), &[])
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "test.toml: [image] is written [[image]], a list of tables; a scene has one, written [image]"
        );
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
            "test.toml: [image.width] expected a whole number from 1 to 32768, got 32.0"
        );
        assert_eq!(
            set("surface=3"),
            "--set surface=3: expected a table of surface settings, got 3"
        );
        assert_eq!(
            set("camera.kind=3"),
            "--set camera.kind=3: expected the name of a choice, in quotes"
        );
        assert_eq!(
            set("camera.position=[1,2,3,4]"),
            "--set camera.position=[1,2,3,4]: too many values in the array (4)"
        );
        assert_eq!(
            file("size = 32", "size = -64"),
            "test.toml: [volume.phantom.size] expected a whole number from 1 to 4096, got -64"
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
        let e = parse(&["backdrop.center=[31.5, 31.5, 1e300]"])
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("--set backdrop.center=[31.5, 31.5, 1e300]: ") && e.contains("1e30 "),
            "{e}"
        );
        assert!(parse(&["backdrop.center=[31.5, 31.5, 1e29]"]).is_ok());
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
        assert!(parse(&[]).unwrap().setting_notes().is_empty());
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
        let ignored = s.setting_notes();
        assert_eq!(ignored.len(), 7, "{ignored:?}");
        assert!(
            ignored[0]
                .text
                .starts_with("--set camera.height=3 is ignored"),
            "{ignored:?}"
        );
        // A key inside a table an override wrote is that override's, as
        // in errors.
        let s = parse(&["render={seed=7}"]).unwrap();
        assert_eq!(
            s.setting_notes()
                .iter()
                .map(|n| n.text.as_str())
                .collect::<Vec<_>>(),
            [
                "--set render={seed=7} is ignored: render.supersampling is \"none\" (one ray per pixel); it is read by jitter"
            ]
        );
        // In the file, named by its key.
        let s = parse_text(
            |s| s.replace("fov_y = 20.0", "fov_y = 20.0\nheight = 5.0"),
            &[],
        )
        .unwrap();
        assert_eq!(s.setting_notes().len(), 1);
        assert!(
            s.setting_notes()[0]
                .text
                .starts_with("[camera.height] = 5.0 is ignored")
        );
        // Used: the smoothing spline's lambda, the step of step traversal,
        // footprint settings with footprint supersampling.
        let s = parse(&[
            "surface.filter=smooth-bspline3",
            "surface.lambda=1",
            "render.traversal=step",
            "render.step=0.5",
            "render.supersampling=footprint",
            "render.footprint=ewa",
            "render.prss_samples=3",
            "render.classify=none",
        ])
        .unwrap();
        assert!(s.setting_notes().is_empty(), "{:?}", s.setting_notes());
        // A u axis out of the plane is projected, and said to be; its
        // length and a rounding error's tilt are not worth a word.
        let s = parse(&["backdrop.u_axis=[2.0, 0.0, 1e-9]"]).unwrap();
        assert!(s.setting_notes().is_empty(), "{:?}", s.setting_notes());
        assert_eq!(s.backdrop.u_axis, DVec3::X);
        let s = parse(&["backdrop.u_axis=[1.0, 0.0, 1.0]"]).unwrap();
        assert_eq!(
            s.setting_notes()
                .iter()
                .map(|n| (n.key.as_str(), n.text.as_str()))
                .collect::<Vec<_>>(),
            [(
                "backdrop.u_axis",
                "--set backdrop.u_axis=[1.0, 0.0, 1.0] is not in the backdrop's plane (45.000° out of it): its projection onto the plane, [1, 0, 0], is the u axis"
            )]
        );
    }

    /// The cell traversals and classifications give one frame: parts
    /// rendered with any of them merge; the step march is another frame.
    #[test]
    fn fingerprints_ignore_how_crossing_cells_are_found() {
        let print = |o: &[&str]| {
            let o: Vec<String> = o.iter().map(|s| s.to_string()).collect();
            Scene::parse(SCENE, Path::new("t.toml"), &o)
                .unwrap()
                .frame_fingerprint(1)
        };
        let dda = print(&["render.traversal=dda", "render.classify=none"]);
        for (traversal, classify) in [
            ("octree", "bezier"),
            ("octree", "accc8"),
            ("distance", "bezier"),
            ("dda", "bmcc"),
        ] {
            let t = format!("render.traversal={traversal}");
            let c = format!("render.classify={classify}");
            assert_eq!(print(&[&t, &c]), dda, "{traversal} {classify}");
        }
        assert_ne!(
            print(&["render.traversal=step", "render.classify=none"]),
            dda
        );
    }

    /// A setting the frame does not read leaves its fingerprint as it is;
    /// one it reads changes it. Swept over every traversal, mode and
    /// fallback, so each key the unread list can hold is normalised.
    #[test]
    fn fingerprints_ignore_the_unread_settings() {
        let print = |o: &[String]| {
            let o: Vec<String> = o.to_vec();
            Scene::parse(SCENE, Path::new("t.toml"), &o)
                .unwrap()
                .frame_fingerprint(1)
        };
        let others = [
            "render.step=0.5",
            "render.leaf=4",
            "render.samples=3",
            "render.seed=5",
            "render.prss_samples=4",
            "render.prss_map=bilinear",
            "render.prss_curvature=0.5",
            "render.footprint=ewa",
        ];
        for traversal in ["step", "dda", "octree", "distance"] {
            for mode in ["none", "grid", "jitter", "prss", "footprint"] {
                for fallback in ["mirror", "blend", "blend-trace", "nearest", "trace"] {
                    let classify = if traversal == "step" {
                        "none"
                    } else {
                        "bezier"
                    };
                    let base: Vec<String> = [
                        format!("render.traversal={traversal}"),
                        format!("render.classify={classify}"),
                        format!("render.supersampling={mode}"),
                        format!("render.prss_fallback={fallback}"),
                    ]
                    .into();
                    let scene = Scene::parse(SCENE, Path::new("t.toml"), &base).unwrap();
                    let unread: Vec<&str> = resolve::unread_render_settings(&scene.render)
                        .into_iter()
                        .map(|(setting, _)| setting.key())
                        .collect();
                    let before = print(&base);
                    for other in others {
                        let key = other.split('=').next().unwrap();
                        let after = print(&[base.clone(), vec![other.to_string()]].concat());
                        // The octree's leaf size changes which cells are
                        // walked, never a crossing.
                        let same =
                            unread.contains(&key) || (traversal != "step" && key == "render.leaf");
                        assert_eq!(
                            before == after,
                            same,
                            "{base:?} + {other}: unread {unread:?}"
                        );
                        let named = before.differing(&after).unwrap();
                        assert_eq!(named, if same { vec![] } else { vec!["render"] });
                    }
                }
            }
        }
        // Each other setting names its own aspect of the frame, and the
        // volume's samples name the volume.
        let base = print(&[]);
        for (set, aspects) in [
            ("surface.ior=1.7", &["surface"][..]),
            ("surface.filter=linear", &["surface"]),
            ("camera.fov_y=21.0", &["camera"]),
            // The camera's aspect ratio follows the image's.
            ("image.width=65", &["image", "camera"]),
            ("backdrop.checker=3.0", &["backdrop"]),
            ("volume.spacing=[1.0, 1.0, 2.0]", &["volume"]),
        ] {
            let after = print(&[set.to_string()]);
            assert_eq!(base.differing(&after).unwrap(), aspects, "{set}");
        }
        let scene = Scene::parse(SCENE, Path::new("t.toml"), &[]).unwrap();
        let other_volume = scene.frame_fingerprint(2);
        assert_eq!(base.differing(&other_volume).unwrap(), vec!["volume"]);
    }

    /// Each anti-aliasing setting is reported where the supersampling mode
    /// (and PRSS's fallback) does not read it, and only there; so are the
    /// octree's leaf and a classification under step traversal.
    #[test]
    fn ignored_settings_follow_what_each_mode_reads() {
        // The settings reported, in any order.
        let ignored = |o: &[&str]| -> Vec<String> {
            let s = parse(o).unwrap();
            let mut keys: Vec<String> = (s.setting_notes().iter())
                .map(|m| {
                    m.text
                        .split(" is ignored")
                        .next()
                        .unwrap()
                        .replace("--set ", "")
                })
                .collect();
            keys.sort();
            keys
        };
        let sorted = |want: &[&str]| {
            let mut w: Vec<String> = want.iter().map(|s| s.to_string()).collect();
            w.sort();
            w
        };
        let all = [
            "render.samples=3",
            "render.seed=2",
            "render.prss_samples=4",
            "render.prss_map=bilinear",
            "render.prss_curvature=0.5",
            "render.footprint=ewa",
        ];
        fn with<'a>(mode: &[&'a str], all: &[&'a str]) -> Vec<&'a str> {
            [mode, all].concat()
        }
        assert_eq!(
            ignored(&with(&["render.supersampling=grid"], &all)),
            sorted(&[
                "render.seed=2",
                "render.prss_samples=4",
                "render.prss_map=bilinear",
                "render.prss_curvature=0.5",
                "render.footprint=ewa",
            ])
        );
        assert_eq!(
            ignored(&with(&["render.supersampling=jitter"], &all)),
            sorted(&[
                "render.prss_samples=4",
                "render.prss_map=bilinear",
                "render.prss_curvature=0.5",
                "render.footprint=ewa",
            ])
        );
        // PRSS with its default fallback (blend) re-traces nothing.
        assert_eq!(
            ignored(&with(&["render.supersampling=prss"], &all)),
            sorted(&[
                "render.footprint=ewa",
                "render.seed=2",
                "render.samples=3",
                "render.prss_curvature=0.5",
            ])
        );
        assert_eq!(
            ignored(&with(
                &["render.supersampling=prss", "render.prss_fallback=trace"],
                &all
            )),
            sorted(&["render.footprint=ewa", "render.seed=2"])
        );
        assert_eq!(
            ignored(&with(
                &[
                    "render.supersampling=footprint",
                    "render.prss_fallback=blend-trace"
                ],
                &all
            )),
            sorted(&[
                "render.seed=2",
                "render.prss_map=bilinear",
                "render.prss_curvature=0.5"
            ])
        );
        assert_eq!(
            ignored(&["render.traversal=distance", "render.leaf=4"]),
            sorted(&["render.leaf=4"])
        );
        assert!(ignored(&["render.traversal=octree", "render.leaf=4"]).is_empty());
        assert_eq!(
            ignored(&["render.traversal=step", "render.classify=bezier"]),
            sorted(&["render.classify=bezier"])
        );
    }
}
