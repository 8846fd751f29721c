//! Everything a frame needs that does not depend on camera, backdrop or ior,
//! built only when the scene uses it and cached.
//!
//! ```text
//! volume ──▶ field (prefiltered, per filter and storage) ──▶ tags + octree (per iso and method)
//! ```
//!
//! A [`Cache`] keeps each product in memory, keyed by what determines it, so
//! re-rendering a scene with a new camera or ior rebuilds nothing. With a
//! cache directory, fields and tags are also stored on disk under the volume's
//! content hash and reused by later processes. Disk files are written
//! atomically and validated on read ([`disk`] holds their format); a damaged
//! or foreign file is ignored (and rebuilt), never trusted.

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Instant;

use crate::classify::{
    self, CurvatureBounds, Method, PlaneBounds, SubCellMasks, TaggedIndex, Tags, curvature, plane,
};
use crate::filter::coeffs::Coefficient;
use crate::filter::field::volume_frame;
use crate::filter::{Field, FilterKind};
use crate::lattice::Lattice;
use crate::octree::{Octree, Proximity};
use crate::render::PrepareTimes;
use crate::scene::{RenderSettings, Scene, SceneError, Storage, Traversal, VolumeSource};
use crate::volume::{LoadOptions, Volume};

mod disk;

use disk::{
    coef_file_name, field_name, read_curvature, read_field, read_tags, write_curvature,
    write_field, write_tags,
};

/// Runs `$body` with `$f` bound to the `&Arc<Field<T>>` inside an
/// [`AnyField`], whatever its storage `T`.
#[macro_export]
macro_rules! with_field {
    ($any:expr, $f:ident => $body:expr) => {
        match $any {
            $crate::prepare::AnyField::F64($f) => $body,
            $crate::prepare::AnyField::F32($f) => $body,
            $crate::prepare::AnyField::F16($f) => $body,
        }
    };
}

/// Cell classification and the skipping structures over it, for one
/// iso-value. The distance field is built only when a traversal asks for it.
pub struct Accel {
    pub method: Method,
    /// The scene's iso-value it was built for.
    pub iso: f64,
    pub octree: Octree,
    proximity: OnceLock<Proximity>,
    tagged: OnceLock<Arc<TaggedIndex>>,
    masks: OnceLock<Option<SubCellMasks>>,
    /// The masks the classification found along with the tags, or the disk
    /// cache stored with them (by linear cell index), until [`Accel::masks`]
    /// files them by slot.
    found_masks: Mutex<Option<classify::masks::LinearMasks>>,
    curvature: OnceLock<Option<CurvatureBounds>>,
    planes: OnceLock<Option<PlaneBounds>>,
}

/// Largest memory each per-tagged-cell table, counted with the whole index
/// it shares, may take: they are optimisations — without masks every tagged cell's
/// segment is solved, without curvature bounds every crossing cell's rest.
pub const TABLE_BUDGET: usize = 2 << 30;

/// Runs `build` once into `cell`; returns the value and the build time (0
/// when it already existed).
fn timed_once<V>(cell: &OnceLock<V>, build: impl FnOnce() -> V) -> (&V, f64) {
    let start = Instant::now();
    let mut built = false;
    let v = cell.get_or_init(|| {
        built = true;
        build()
    });
    (
        v,
        if built {
            start.elapsed().as_secs_f64()
        } else {
            0.0
        },
    )
}

impl Accel {
    /// The distance field, built on first use; returns it and its build time
    /// (0 when it already existed).
    pub fn proximity(&self) -> (&Proximity, f64) {
        timed_once(&self.proximity, || Proximity::build(self.octree.tags()))
    }

    /// The distance field if it was built.
    pub fn proximity_if_built(&self) -> Option<&Proximity> {
        self.proximity.get()
    }

    /// Whether a table of `bytes` over the tagged cells fits [`TABLE_BUDGET`].
    fn table_fits(&self, bytes: usize) -> bool {
        TaggedIndex::bytes_for(self.octree.tags()) + bytes <= TABLE_BUDGET
    }

    fn tagged(&self) -> Arc<TaggedIndex> {
        self.tagged
            .get_or_init(|| {
                Arc::new(TaggedIndex::from_brick_words(
                    self.octree.bricked(),
                    self.octree.brick_tags(),
                ))
            })
            .clone()
    }

    /// Sub-cell masks of the tagged cells, built on first use for the
    /// methods that have them ([`Method::has_masks`]: the Bézier hull, and
    /// ACCC per 2³, 4³ or 8³ sub-cells; the paper's BMCC and ACCC are measured at
    /// their own resolution) when they fit [`TABLE_BUDGET`]: filed from those
    /// the classification found (or the disk cache kept), else computed;
    /// returns them (or `None`) and the build time.
    pub fn masks(&self, field: &AnyField) -> (Option<&SubCellMasks>, f64) {
        let (m, s) = timed_once(&self.masks, || {
            // Taken whatever happens, so an unused find is not kept.
            let found = self
                .found_masks
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .take();
            let count = self.octree.tags().count();
            if !(self.method.has_masks() && self.table_fits(SubCellMasks::bytes_for(count))) {
                return None;
            }
            let cells = self.octree.tags().cells;
            found
                .and_then(|linear| SubCellMasks::from_linear(self.tagged(), cells, &linear))
                .or_else(|| {
                    let iso = field.separating_iso(self.iso);
                    Some(with_field!(field, f => match self.method {
                        Method::AcccSub(n) => {
                            SubCellMasks::build_accc(f.as_ref(), self.tagged(), iso, n as usize)
                        }
                        _ => SubCellMasks::build(f.as_ref(), self.tagged(), iso),
                    }))
                })
        });
        (m.as_ref(), s)
    }

    /// Curvature bounds of the tagged cells, built on first use when the
    /// filter has them ([`crate::classify::curvature::applies`]) and they fit
    /// [`TABLE_BUDGET`]; returns them (or `None`) and the build time.
    pub fn curvature(&self, field: &AnyField) -> (Option<&CurvatureBounds>, f64) {
        let (b, s) = timed_once(&self.curvature, || {
            let count = self.octree.tags().count();
            let fits = self.table_fits(CurvatureBounds::bytes_for(count));
            // Checked before the shared index is built for nothing (masks may
            // not need it either).
            with_field!(field, f => {
                (fits && curvature::applies(f.kernel()))
                    .then(|| CurvatureBounds::build(f.as_ref(), self.tagged()))
                    .flatten()
            })
        });
        (b.as_ref(), s)
    }

    /// The planes of the tagged cells ([`crate::classify::plane`]), built on
    /// first use for the methods with sub-cell masks (a refinement within
    /// the cell, as those are; the paper's BMCC and ACCC stay as it measured
    /// them) when their records fit [`plane::CACHE_BUDGET`]; returns them
    /// (or `None`) and the build time.
    pub fn planes(&self, field: &AnyField) -> (Option<&PlaneBounds>, f64) {
        let (p, s) = timed_once(&self.planes, || {
            let count = self.octree.tags().count();
            let iso = field.separating_iso(self.iso);
            let bytes = PlaneBounds::bytes_for(count);
            if !(self.method.has_masks() && bytes <= plane::CACHE_BUDGET && self.table_fits(bytes))
            {
                return None;
            }
            let masks = self.masks(field).0?;
            Some(with_field!(field, f => {
                PlaneBounds::build(f.as_ref(), self.tagged(), masks.parts().1, iso)
            }))
        });
        (p.as_ref(), s)
    }
}

/// The prefiltered field in the coefficient storage the scene chose
/// (`[render] coefficients`).
#[derive(Clone, Debug)]
pub enum AnyField {
    F64(Arc<Field<f64>>),
    F32(Arc<Field<f32>>),
    F16(Arc<Field<half::f16>>),
}

impl AnyField {
    /// Prefilters `vol` for `filter` into `storage`. `f16` stores the
    /// coefficients less `centre` (the iso-value it will render; any other
    /// iso renders correctly too, only less precisely — see [`Field`]) and
    /// refuses them when they lie beyond its range.
    pub fn new(
        vol: &Volume,
        filter: FilterKind,
        storage: Storage,
        centre: f64,
    ) -> Result<AnyField, SceneError> {
        Ok(match storage {
            Storage::F64 => AnyField::F64(Arc::new(Field::new(vol, filter))),
            Storage::F32 => AnyField::F32(Arc::new(f32_field(vol, filter, Storage::F32)?)),
            Storage::F16 => AnyField::F16(Arc::new(f16_field(
                f32_field(vol, filter, Storage::F16)?,
                centre,
                f16_scale(vol, centre),
            )?)),
        })
    }

    /// What the stored coefficients are relative to ([`Field::offset`]).
    pub fn offset(&self) -> f64 {
        with_field!(self, f => f.offset())
    }

    pub fn storage(&self) -> Storage {
        match self {
            AnyField::F64(_) => Storage::F64,
            AnyField::F32(_) => Storage::F32,
            AnyField::F16(_) => Storage::F16,
        }
    }

    /// The `f64` field, if that is the storage.
    pub fn as_f64(&self) -> Option<&Field<f64>> {
        match self {
            AnyField::F64(f) => Some(f),
            _ => None,
        }
    }

    pub fn kernel(&self) -> &crate::filter::Kernel {
        with_field!(self, f => f.kernel())
    }

    pub fn dims(&self) -> [usize; 3] {
        with_field!(self, f => f.dims())
    }

    pub fn separating_iso(&self, iso: f64) -> f64 {
        with_field!(self, f => f.separating_iso(iso))
    }

    /// Whether both are the same cached field.
    pub fn ptr_eq(&self, other: &AnyField) -> bool {
        match (self, other) {
            (AnyField::F64(a), AnyField::F64(b)) => Arc::ptr_eq(a, b),
            (AnyField::F32(a), AnyField::F32(b)) => Arc::ptr_eq(a, b),
            (AnyField::F16(a), AnyField::F16(b)) => Arc::ptr_eq(a, b),
            _ => false,
        }
    }
}

/// `vol` prefiltered into `f32` coefficients, or an error when some overflow
/// it: samples near f32's own limit, grown by the prefilter, would round to
/// infinities and leave the surface undefined where they lie (`storage`,
/// the scene's choice, names the setting in the message).
fn f32_field(vol: &Volume, filter: FilterKind, storage: Storage) -> Result<Field<f32>, SceneError> {
    use rayon::prelude::*;
    let f = Field::<f32>::new_in(vol, filter);
    let overflows = f
        .coeffs()
        .data()
        .par_chunks(1 << 16)
        .any(|chunk| chunk.iter().any(|c| !c.is_finite()));
    if overflows {
        // As f32 (which holds them: these are the samples f32 overflows
        // near), the shortest digits.
        let (lo, hi) = vol.value_range();
        let (lo, hi) = (lo as f32, hi as f32);
        return Err(SceneError::Storage {
            storage: storage.name(),
            msg: format!(
                "the prefiltered coefficients overflow f32's range (±{:e}) for samples from {lo:e} to {hi:e}; use \"f64\"",
                f32::MAX
            ),
        });
    }
    Ok(f)
}

/// The power of two `f16` coefficients are stored multiplied by
/// ([`Field::scale`]): the one that brings the samples' largest distance
/// from `centre` into `[16, 32)`, so that a field of any magnitude lies in
/// `f16`'s normal range (11 significant bits down to 2^-14, a 2^-19 of
/// that distance), not in its subnormals, and leaves the prefilter's
/// overshoot a factor of 2047 below `f16`'s largest value (65504): noise
/// at the Nyquist rate grows 3·3·3 = 27 times under the cubic prefilter,
/// 6363 times under degree 7's. A function of the volume and the centre
/// alone, so a disk cache's file needs no record of it.
pub(super) fn f16_scale(vol: &Volume, centre: f64) -> f64 {
    let (lo, hi) = vol.value_range();
    let reach = (hi - centre).abs().max((lo - centre).abs());
    if !(reach.is_finite() && reach > 0.0) {
        return 1.0;
    }
    let exponent = 4 - reach.log2().floor() as i32;
    2f64.powi(exponent.clamp(-1000, 1000))
}

/// The field `f` less `centre`, times `scale` ([`f16_scale`]), rounded once
/// to `f16` (so the values near the surface at iso `centre` are small, where
/// `f16` is precise), or an error naming the largest when some still lie
/// beyond `f16`'s range (they would become infinite).
fn f16_field(f: Field<f32>, centre: f64, scale: f64) -> Result<Field<half::f16>, SceneError> {
    // `f`'s coefficients are relative to its offset (the volume's).
    let shift = centre - f.offset();
    // NaN-propagating: a NaN coefficient or centre is refused too.
    let max = f.coeffs().data().iter().fold(0.0f64, |m, c| {
        let d = (c.to_f64() - shift).abs();
        if d > m || d.is_nan() { d } else { m }
    });
    if max.is_nan() || max * scale > half::f16::MAX.to_f64() {
        return Err(SceneError::Storage {
            storage: Storage::F16.name(),
            msg: format!(
                "the largest prefiltered coefficient less the iso-value {}, {max:.6e}, \
                 is over 2000 times the samples' largest distance from it (the prefilter's \
                 overshoot of noisy data): beyond f16's range (±65504) once scaled; use \"f32\" or \"f64\"",
                crate::human::exact(centre)
            ),
        });
    }
    let coeffs = f.coeffs().convert_shifted(shift, scale);
    Ok(Field::from_coeffs(f.kind(), coeffs).with_frame(centre, scale))
}

/// Inputs of one frame.
pub struct Prepared {
    pub volume: Arc<Volume>,
    pub field: AnyField,
    pub accel: Option<Arc<Accel>>,
    /// Build times of what was built for this frame (0 when cached).
    pub times: PrepareTimes,
    /// [`Volume::content_hash`] where the preparation computed it (a disk
    /// cache keys its files by it), so a caller needing it too (a region's
    /// frame fingerprint) need not read every sample again.
    content_hash: Option<u64>,
}

impl Prepared {
    /// Prefilters `volume` for `filter`, without acceleration structures.
    pub fn new(volume: Arc<Volume>, filter: FilterKind) -> Prepared {
        Prepared::new_in(volume, filter, Storage::F64, 0.0).expect("f64 holds every coefficient")
    }

    /// [`Prepared::new`] with coefficients stored as `storage` (`f16`
    /// centred on `centre`, see [`AnyField::new`]).
    pub fn new_in(
        volume: Arc<Volume>,
        filter: FilterKind,
        storage: Storage,
        centre: f64,
    ) -> Result<Prepared, SceneError> {
        let start = Instant::now();
        let field = AnyField::new(&volume, filter, storage, centre)?;
        Ok(Prepared {
            volume,
            field,
            accel: None,
            times: PrepareTimes {
                prefilter_s: start.elapsed().as_secs_f64(),
                ..Default::default()
            },
            content_hash: None,
        })
    }

    /// The volume's [`Volume::content_hash`]: the preparation's, or
    /// computed now where it had no need of it.
    pub fn volume_hash(&self) -> u64 {
        self.content_hash
            .unwrap_or_else(|| self.volume.content_hash())
    }

    /// Adds the classification and octree `method` at `iso` (timed).
    pub fn with_accel(mut self, iso: f64, method: Method) -> Prepared {
        let (accel, classify_s, octree_s) = build_accel(&self.field, iso, method, None);
        self.accel = Some(Arc::new(accel));
        self.times.classify_s = classify_s;
        self.times.octree_s = octree_s;
        self
    }

    /// Makes sure the structures a render with `render` needs exist (the
    /// distance field, the masks and curvature bounds of the tagged cells),
    /// with their build time in the stats.
    pub fn ready_for(&mut self, render: &RenderSettings) {
        let Some(a) = &self.accel else { return };
        let traversal = render.traversal;
        if traversal == Traversal::Distance {
            self.times.octree_s += a.proximity().1;
        }
        if traversal != Traversal::Step {
            self.times.octree_s += a.masks(&self.field).1;
        }
        if render.clears_crossing_cells() {
            self.times.octree_s += a.curvature(&self.field).1;
        }
        if render.skips_clear_segments() {
            self.times.octree_s += a.planes(&self.field).1;
        }
    }

    /// Loads and prepares what `scene` needs, without caching.
    pub fn for_scene(scene: &Scene, opts: &LoadOptions) -> Result<Prepared, SceneError> {
        Cache::new().prepare(scene, opts)
    }
}

/// Whether a scene's traversal uses precomputed classification.
pub fn needs_accel(scene: &Scene) -> Option<Method> {
    match scene.render.traversal {
        Traversal::Step => None,
        Traversal::Dda | Traversal::Octree | Traversal::Distance => scene.render.classify,
    }
}

/// The cell structures of `field` at `iso` for `method`: classified here,
/// or from `cached` tags and the masks stored with them (none stored: the
/// masks are built when first asked for).
fn build_accel(
    field: &AnyField,
    iso: f64,
    method: Method,
    cached: Option<(Tags, classify::masks::LinearMasks)>,
) -> (Accel, f64, f64) {
    let start = Instant::now();
    let (tags, found_masks) = match cached {
        Some((tags, masks)) => (tags, (!masks.is_empty()).then_some(masks)),
        None => {
            let iso = field.separating_iso(iso);
            let (c, masks) = with_field!(field, f => {
                classify::classify_with_masks(f.as_ref(), iso, method, TABLE_BUDGET)
            });
            (c.tags, masks)
        }
    };
    let classify_s = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let octree = Octree::build(tags);
    (
        Accel {
            method,
            iso,
            octree,
            proximity: OnceLock::new(),
            tagged: OnceLock::new(),
            masks: OnceLock::new(),
            found_masks: Mutex::new(found_masks),
            curvature: OnceLock::new(),
            planes: OnceLock::new(),
        },
        classify_s,
        start.elapsed().as_secs_f64(),
    )
}

/// In-memory (and optionally on-disk) cache of volumes, fields and accels.
#[derive(Default)]
pub struct Cache {
    dir: Option<PathBuf>,
    volumes: HashMap<String, (Arc<Volume>, u64)>,
    fields: HashMap<(String, String), AnyField>,
    accels: HashMap<(String, String, u64, String), Arc<Accel>>,
    /// Warnings about unusable disk cache files, for the caller to print.
    pub warnings: Vec<String>,
}

impl Cache {
    pub fn new() -> Cache {
        Cache::default()
    }

    /// Also persist fields and tags under `dir`. A missing `dir` is
    /// created, with a warning, but not a missing parent: a mistyped path
    /// would otherwise give each job of a split frame a cache of its own.
    pub fn with_dir(dir: &Path) -> std::io::Result<Cache> {
        let mut warnings = Vec::new();
        if dir.exists() && !dir.is_dir() {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "exists and is not a directory",
            ));
        }
        if !dir.exists() && std::fs::symlink_metadata(dir).is_ok() {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "is a symbolic link that leads to no directory (dangling, or a loop)",
            ));
        }
        if !dir.exists() {
            let parent = dir.parent().filter(|p| !p.as_os_str().is_empty());
            if let Some(p) = parent.filter(|p| !p.is_dir()) {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::NotFound,
                    format!(
                        "its parent {} does not exist (only the cache directory itself is created)",
                        p.display()
                    ),
                ));
            }
            std::fs::create_dir(dir)?;
            warnings.push(format!(
                "cache directory {} did not exist: created it, empty",
                dir.display()
            ));
        }
        Ok(Cache {
            dir: Some(dir.to_path_buf()),
            warnings,
            ..Cache::default()
        })
    }

    /// Drops every field (and the acceleration structures built on it) whose
    /// [`Cache::field_key`] is not in `keep`, and every volume no kept field
    /// comes from: a run over many volumes of one scene file (the scaling
    /// suite's 64³..1024³ phantoms, in two storages) then holds only the ones
    /// still to come, not all of them at once.
    pub fn retain(&mut self, keep: &std::collections::HashSet<(String, String)>) {
        self.volumes.retain(|k, _| keep.iter().any(|(v, _)| v == k));
        self.fields.retain(|k, _| keep.contains(k));
        self.accels
            .retain(|(v, f, ..), _| keep.contains(&(v.clone(), f.clone())));
    }

    /// Identity of a scene's field: its volume's ([`Cache::volume_key`]),
    /// and its filter and coefficient storage.
    pub fn field_key(scene: &Scene) -> (String, String) {
        (
            Cache::volume_key(scene),
            field_name(
                scene.surface.filter,
                scene.render.coefficients,
                scene.surface.iso,
            ),
        )
    }

    /// Identity of a scene's volume: its file (canonical path, raw layout)
    /// or phantom parameters, and its spacing.
    pub fn volume_key(scene: &Scene) -> String {
        let src = match &scene.volume {
            VolumeSource::File {
                path,
                raw,
                allow_nan,
            } => {
                let canon = path.canonicalize().unwrap_or_else(|_| path.clone());
                format!("file:{}:{:?}:{}", canon.display(), raw, allow_nan)
            }
            VolumeSource::Phantom(spec) => {
                format!(
                    "phantom:{}",
                    serde_json::to_string(spec).unwrap_or_default()
                )
            }
        };
        format!("{src}:{:?}", scene.spacing)
    }

    /// Everything `scene` needs, built or taken from the cache.
    pub fn prepare(&mut self, scene: &Scene, opts: &LoadOptions) -> Result<Prepared, SceneError> {
        let mut times = PrepareTimes::default();
        let vkey = Cache::volume_key(scene);
        let (volume, hash) = match self.volumes.get(&vkey) {
            Some(v) => v.clone(),
            None => {
                let start = Instant::now();
                let v = Arc::new(scene.load_volume(opts)?);
                let hash = if self.dir.is_some() {
                    v.content_hash()
                } else {
                    0
                };
                times.load_s = start.elapsed().as_secs_f64();
                self.volumes.insert(vkey.clone(), (v.clone(), hash));
                (v, hash)
            }
        };
        check_distance_maps(scene, &volume, opts.memory_limit)?;
        let filter = scene.surface.filter;
        let storage = scene.render.coefficients;
        let centre = scene.surface.iso;
        let fkey = (vkey.clone(), field_name(filter, storage, centre));
        let field = match self.fields.get(&fkey) {
            Some(f) => f.clone(),
            None => {
                let start = Instant::now();
                let disk = self.disk_path(hash, &coef_file_name(&fkey.1, storage, &volume));
                let loaded = disk
                    .as_deref()
                    .and_then(|p| self.read_field(p, filter, storage, centre, &volume));
                let f = match loaded {
                    Some(f) => f,
                    None => {
                        let f = AnyField::new(&volume, filter, storage, centre)?;
                        if let Some(p) = &disk {
                            self.write_or_warn(p, |w| with_field!(&f, f => write_field(w, f)));
                        }
                        f
                    }
                };
                times.prefilter_s = start.elapsed().as_secs_f64();
                self.fields.insert(fkey.clone(), f.clone());
                f
            }
        };
        // Where the curvature bounds go once built, when the disk cache had
        // none for a new accel.
        let mut curvature_to_write = None;
        let accel = match needs_accel(scene) {
            None => None,
            Some(method) => {
                let iso = scene.surface.iso;
                let akey = (vkey, fkey.1.clone(), iso.to_bits(), method.name());
                match self.accels.get(&akey) {
                    Some(a) => Some(a.clone()),
                    None => {
                        let name = format!("{}-{:016x}-{}", fkey.1, iso.to_bits(), method.name());
                        let disk = self.disk_path(hash, &format!("{name}.tags"));
                        let lattice = Lattice::new(field.kernel(), field.dims());
                        let cached = disk.as_deref().and_then(|p| self.read_tags(p, &lattice));
                        let from_disk = cached.is_some();
                        let (mut a, cs, mut os) = build_accel(&field, iso, method, cached);
                        if !from_disk && let Some(p) = &disk {
                            // Not shared yet: the masks need no lock.
                            let found = a.found_masks.get_mut().unwrap_or_else(|e| e.into_inner());
                            let masks = found.as_deref().unwrap_or_default();
                            self.write_or_warn(p, |w| write_tags(w, a.octree.tags(), masks));
                        }
                        if scene.render.clears_crossing_cells()
                            && let Some(p) = self.disk_path(hash, &format!("{name}.curv"))
                        {
                            let start = Instant::now();
                            if !self.seed_curvature(&a, &p) {
                                curvature_to_write = Some(p);
                            }
                            os += start.elapsed().as_secs_f64();
                        }
                        times.classify_s = cs;
                        times.octree_s = os;
                        let a = Arc::new(a);
                        self.accels.insert(akey, a.clone());
                        Some(a)
                    }
                }
            }
        };
        let mut p = Prepared {
            volume,
            field,
            accel,
            times,
            content_hash: self.dir.is_some().then_some(hash),
        };
        p.ready_for(&scene.render);
        if let Some(path) = curvature_to_write
            && let Some(b) = p.accel.as_ref().and_then(|a| a.curvature.get()?.as_ref())
        {
            self.write_or_warn(&path, |w| write_curvature(w, b.parts().1));
        }
        let t = &p.times;
        if t.load_s + t.prefilter_s + t.classify_s + t.octree_s > 0.0 {
            // Something was built: its transients go back to the kernel.
            crate::heap::release_free_memory();
        }
        Ok(p)
    }

    fn disk_path(&self, hash: u64, name: &str) -> Option<PathBuf> {
        self.dir
            .as_ref()
            .map(|d| d.join(format!("{hash:016x}-{name}")))
    }

    fn write_or_warn(
        &mut self,
        path: &Path,
        write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
    ) {
        if let Err(e) = crate::atomic::write_atomic(path, |w| write(w)) {
            self.warnings
                .push(format!("cache: cannot write {}: {e}", path.display()));
        }
    }

    fn read_field(
        &mut self,
        path: &Path,
        filter: FilterKind,
        storage: Storage,
        centre: f64,
        vol: &Volume,
    ) -> Option<AnyField> {
        if !path.exists() {
            return None;
        }
        let read = match storage {
            // Stored relative to the volume's offset (`Field::new_in`).
            Storage::F64 => read_field(path, filter, vol.dims())
                .map(|f: Field<f64>| AnyField::F64(Arc::new(f.with_frame(volume_frame(vol), 1.0)))),
            Storage::F32 => read_field(path, filter, vol.dims())
                .map(|f: Field<f32>| AnyField::F32(Arc::new(f.with_frame(volume_frame(vol), 1.0)))),
            // Stored less `centre` (the file's name says which), times the
            // scale the volume and the centre give.
            Storage::F16 => read_field(path, filter, vol.dims()).map(|f: Field<half::f16>| {
                AnyField::F16(Arc::new(f.with_frame(centre, f16_scale(vol, centre))))
            }),
        };
        match read {
            Ok(f) => Some(f),
            Err(e) => {
                self.warnings
                    .push(format!("cache: ignoring {}: {e}", path.display()));
                None
            }
        }
    }

    /// Gives `a` the curvature bounds the cache keeps at `path`, if it has
    /// them for these tags; whether it did.
    fn seed_curvature(&mut self, a: &Accel, path: &Path) -> bool {
        if !path.exists() {
            return false;
        }
        match read_curvature(path, a.octree.tags().count()) {
            Ok(bounds) => {
                let b = CurvatureBounds::from_parts(a.tagged(), bounds);
                b.is_some() && a.curvature.set(b).is_ok()
            }
            Err(e) => {
                self.warnings
                    .push(format!("cache: ignoring {}: {e}", path.display()));
                false
            }
        }
    }

    fn read_tags(
        &mut self,
        path: &Path,
        lattice: &Lattice,
    ) -> Option<(Tags, classify::masks::LinearMasks)> {
        if !path.exists() {
            return None;
        }
        match read_tags(path, lattice) {
            Ok(t) => Some(t),
            Err(e) => {
                self.warnings
                    .push(format!("cache: ignoring {}: {e}", path.display()));
                None
            }
        }
    }
}

/// The distance traversal's maps ([`crate::octree::distance::map_bytes`]),
/// on top of the working set the volume's loader checked
/// ([`crate::volume::limits::WORKING_BYTES_PER_SAMPLE`]), which they can
/// push nearly half over the limit. A filter's lattice has as many cells as
/// samples per axis or one fewer: the larger of the two maps is counted.
fn check_distance_maps(scene: &Scene, volume: &Volume, limit: u64) -> Result<(), SceneError> {
    if scene.render.traversal != Traversal::Distance {
        return Ok(());
    }
    let [x, y, z] = volume.dims();
    let need = (x as u64 * y as u64 * z as u64)
        .saturating_mul(crate::volume::limits::WORKING_BYTES_PER_SAMPLE)
        .saturating_add(
            crate::octree::distance::map_bytes([x, y, z])
                .max(crate::octree::distance::map_bytes([x, y, z].map(|n| n - 1))),
        );
    if need <= limit {
        return Ok(());
    }
    Err(SceneError::OverLimit {
        path: scene.path.clone(),
        key: "render.traversal".into(),
        source: crate::volume::limits::OverLimit {
            what: format!("the distance traversal over a {x}x{y}x{z} volume with its maps"),
            need,
            limit,
            hint: "; use render.traversal = \"octree\" or raise the limit (--memory-limit or SNELL_MEMORY_LIMIT)".into(),
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene() -> Scene {
        let text =
            std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/sphere.toml"))
                .unwrap();
        let o = [
            "image.width=16",
            "image.height=16",
            "render.traversal=octree",
            "volume.phantom.size=24",
            "volume.phantom.radius=7.0",
        ]
        .map(String::from);
        Scene::parse(&text, Path::new("scenes/x.toml"), &o).unwrap()
    }

    #[test]
    fn memory_cache_reuses_everything_for_a_new_camera_or_ior() {
        let mut cache = Cache::new();
        let s1 = scene();
        let a = cache.prepare(&s1, &LoadOptions::default()).unwrap();
        assert!(a.times.prefilter_s > 0.0 && a.accel.is_some());
        let mut s2 = s1.clone();
        s2.surface.ior = 1.33;
        s2.camera.position.x += 3.0;
        let b = cache.prepare(&s2, &LoadOptions::default()).unwrap();
        assert!(a.field.ptr_eq(&b.field));
        assert!(Arc::ptr_eq(
            a.accel.as_ref().unwrap(),
            b.accel.as_ref().unwrap()
        ));
        assert_eq!(b.times, PrepareTimes::default(), "nothing rebuilt");
        // A new iso-value rebuilds the tags, not the field.
        let mut s3 = s1.clone();
        s3.surface.iso = 100.0;
        let c = cache.prepare(&s3, &LoadOptions::default()).unwrap();
        assert!(a.field.ptr_eq(&c.field));
        assert!(!Arc::ptr_eq(
            a.accel.as_ref().unwrap(),
            c.accel.as_ref().unwrap()
        ));
        // Keeping the field keeps everything; keeping another storage's
        // field drops this one (and its tags) but keeps the volume; keeping
        // nothing rebuilds all.
        let key = Cache::field_key(&s1);
        cache.retain(&[key.clone()].into_iter().collect());
        let d = cache.prepare(&s2, &LoadOptions::default()).unwrap();
        assert!(a.field.ptr_eq(&d.field));
        let mut narrow = s2.clone();
        narrow.render.coefficients = Storage::F32;
        cache.retain(&[Cache::field_key(&narrow)].into_iter().collect());
        let f = cache.prepare(&s2, &LoadOptions::default()).unwrap();
        assert!(!a.field.ptr_eq(&f.field) && f.times.prefilter_s > 0.0);
        assert_eq!(f.times.load_s, 0.0, "the volume stays");
        assert!(f.times.classify_s > 0.0, "tags of a dropped field go too");
        cache.retain(&Default::default());
        let e = cache.prepare(&s2, &LoadOptions::default()).unwrap();
        assert!(!a.field.ptr_eq(&e.field) && e.times.prefilter_s > 0.0);
        assert!(e.times.load_s > 0.0);
    }

    /// A missing cache directory is created with a warning; one whose
    /// parent is missing is refused, and nothing is created.
    #[test]
    fn cache_directory_is_created_but_not_its_parents() {
        let root = std::env::temp_dir().join(format!("snell-cache-dir-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        std::fs::create_dir(&root).unwrap();
        let dir = root.join("cache");
        let c = Cache::with_dir(&dir).unwrap();
        assert!(dir.is_dir());
        assert!(
            c.warnings.len() == 1 && c.warnings[0].contains("did not exist"),
            "{:?}",
            c.warnings
        );
        assert!(Cache::with_dir(&dir).unwrap().warnings.is_empty());
        let deep = root.join("typo/cache");
        let e = Cache::with_dir(&deep).err().unwrap().to_string();
        assert!(e.contains("parent") && e.contains("typo"), "{e}");
        assert!(!root.join("typo").exists());
        // A link in a loop, or to nothing, is named as such.
        #[cfg(unix)]
        for (link, to) in [("a", "b"), ("b", "a"), ("gone", "nothing")] {
            std::os::unix::fs::symlink(root.join(to), root.join(link)).unwrap();
        }
        #[cfg(unix)]
        for link in ["a", "gone"] {
            let e = Cache::with_dir(&root.join(link)).err().unwrap().to_string();
            assert!(
                e.contains("symbolic link that leads to no directory"),
                "{e}"
            );
        }
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn disk_cache_round_trips_and_rejects_damage() {
        let dir = std::env::temp_dir().join(format!("snell-cache-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let s = scene();
        let first = Cache::with_dir(&dir)
            .unwrap()
            .prepare(&s, &LoadOptions::default())
            .unwrap();
        let files: Vec<PathBuf> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        // Coefficients, tags with masks, curvature bounds.
        assert_eq!(files.len(), 3, "{files:?}");
        let mut fresh = Cache::with_dir(&dir).unwrap();
        let second = fresh.prepare(&s, &LoadOptions::default()).unwrap();
        assert!(fresh.warnings.is_empty(), "{:?}", fresh.warnings);
        // The hash the files are keyed by is the one a caller gets, as
        // without a cache.
        assert_eq!(second.content_hash, Some(second.volume.content_hash()));
        let memory = Cache::new().prepare(&s, &LoadOptions::default()).unwrap();
        assert_eq!(memory.content_hash, None);
        assert_eq!(memory.volume_hash(), second.volume_hash());
        assert_eq!(
            first.field.as_f64().unwrap().coeffs().interior(),
            second.field.as_f64().unwrap().coeffs().interior()
        );
        assert_eq!(
            first.accel.as_ref().unwrap().octree.tags(),
            second.accel.as_ref().unwrap().octree.tags()
        );
        // The sub-cell masks the classification found are stored with the
        // tags, and the masks filed from them are the first render's.
        let (a1, a2) = (
            first.accel.as_ref().unwrap(),
            second.accel.as_ref().unwrap(),
        );
        let tags_file = files.iter().find(|f| f.extension().unwrap() == "tags");
        let lattice = Lattice::new(first.field.kernel(), first.field.dims());
        let (_, stored) = read_tags(tags_file.unwrap(), &lattice).unwrap();
        assert_eq!(
            stored.len(),
            a1.octree.tags().count(),
            "a mask per tagged cell"
        );
        let masks = |a: &Accel, f: &AnyField| a.masks(f).0.unwrap().parts().1.to_vec();
        assert_eq!(masks(a1, &first.field), masks(a2, &second.field));
        // The curvature bounds come back from their file, as built, and
        // were not built again (already there before `ready_for` asked).
        let bits = |a: &Accel| {
            let b = a.curvature.get().unwrap().as_ref().unwrap().parts().1;
            b.iter()
                .flatten()
                .map(|v| v.to_bits())
                .collect::<Vec<u32>>()
        };
        assert!(!bits(a1).is_empty());
        assert_eq!(bits(a1), bits(a2));
        // What a warm cache renders with is the file's (bounds that no
        // build gives, written in its place), not a rebuild.
        let curv = files.iter().find(|f| f.extension().unwrap() == "curv");
        let count = a1.octree.tags().count();
        let kept = std::fs::read(curv.unwrap()).unwrap();
        let mut planted = Vec::new();
        disk::write_curvature(&mut planted, &vec![[7.0f32; 6]; count]).unwrap();
        std::fs::write(curv.unwrap(), &planted).unwrap();
        let read = Cache::with_dir(&dir)
            .unwrap()
            .prepare(&s, &LoadOptions::default())
            .unwrap();
        assert_eq!(
            bits(read.accel.as_ref().unwrap()),
            vec![7.0f32.to_bits(); 6 * count]
        );
        std::fs::write(curv.unwrap(), &kept).unwrap();
        // A bound below zero would clear cells the surface crosses: refused
        // even behind a good checksum.
        let mut negative = vec![[1.0f32; 6]; count];
        negative[count / 2][3] = -1.0;
        let mut bytes = Vec::new();
        disk::write_curvature(&mut bytes, &negative).unwrap();
        let bad = dir.join("negative.curv");
        std::fs::write(&bad, &bytes).unwrap();
        let e = read_curvature(&bad, count).unwrap_err().to_string();
        assert!(e.contains("negative"), "{e}");
        assert!(read_curvature(&bad, count + 1).is_err(), "count checked");
        std::fs::remove_file(&bad).unwrap();
        assert!(read_curvature(curv.unwrap(), count).is_ok());
        // Damage every file, cut short or one bit flipped in its values (the
        // length unchanged): the cache warns, rebuilds, and gets the same
        // answer.
        for flip in [false, true] {
            for f in &files {
                let mut b = std::fs::read(f).unwrap();
                let n = b.len();
                if flip {
                    b[n - 20] ^= 0x10;
                } else {
                    b.truncate(n - 3);
                }
                std::fs::write(f, b).unwrap();
            }
            let mut broken = Cache::with_dir(&dir).unwrap();
            let third = broken.prepare(&s, &LoadOptions::default()).unwrap();
            assert_eq!(broken.warnings.len(), 3, "{:?}", broken.warnings);
            if flip {
                assert!(
                    broken.warnings.iter().all(|w| w.contains("checksum")),
                    "{:?}",
                    broken.warnings
                );
            }
            assert_eq!(
                first.field.as_f64().unwrap().coeffs().interior(),
                third.field.as_f64().unwrap().coeffs().interior()
            );
            assert_eq!(
                first.accel.as_ref().unwrap().octree.tags(),
                third.accel.as_ref().unwrap().octree.tags()
            );
            assert_eq!(bits(a1), bits(third.accel.as_ref().unwrap()));
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Samples near f32's limit, prefiltered, overflow f32 (and so f16):
    /// both storages refuse them, naming the overflow, where f64 holds them.
    #[test]
    fn coefficients_that_overflow_f32_are_refused() {
        let samples: Vec<f32> = (0..8)
            .map(|k| if k % 2 == 0 { 3.4e38 } else { -3.4e38 })
            .collect();
        let vol = Volume::new([2; 3], [1.0; 3], crate::volume::SampleType::F32, samples).unwrap();
        let cubic = FilterKind::BSpline(3);
        assert!(AnyField::new(&vol, cubic, Storage::F64, 0.0).is_ok());
        for storage in [Storage::F32, Storage::F16] {
            let e = AnyField::new(&vol, cubic, storage, 0.0)
                .unwrap_err()
                .to_string();
            assert!(
                e.contains(storage.name())
                    && e.contains("overflow f32's range")
                    && e.contains("-3.4e38 to 3.4e38"),
                "{e}"
            );
        }
        // Unfiltered, the same samples fit.
        assert!(AnyField::new(&vol, FilterKind::Linear, Storage::F32, 0.0).is_ok());
    }

    #[test]
    fn f32_fields_are_cached_apart_and_round_trip_exactly() {
        let dir = std::env::temp_dir().join(format!("snell-cache32-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let mut s = scene();
        s.render.coefficients = Storage::F32;
        let mut cache = Cache::with_dir(&dir).unwrap();
        let wide = cache.prepare(&scene(), &LoadOptions::default()).unwrap();
        let narrow = cache.prepare(&s, &LoadOptions::default()).unwrap();
        assert_eq!(narrow.field.storage(), Storage::F32);
        assert!(
            narrow.times.prefilter_s > 0.0,
            "an f32 field is its own entry"
        );
        assert!(!narrow.field.ptr_eq(&wide.field));
        let names: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        let f32_file = names.iter().find(|n| n.ends_with("-f32-relative.coef"));
        assert!(f32_file.is_some(), "{names:?}");
        assert_eq!(names.iter().filter(|n| n.ends_with(".coef")).count(), 2);
        let mut reader = Cache::with_dir(&dir).unwrap();
        let read = reader.prepare(&s, &LoadOptions::default()).unwrap();
        assert!(reader.warnings.is_empty(), "{:?}", reader.warnings);
        let coeffs = |p: &Prepared| match &p.field {
            AnyField::F32(f) => f.coeffs().interior(),
            _ => panic!("not f32 storage"),
        };
        assert_eq!(coeffs(&narrow), coeffs(&read), "bitwise from disk");
        assert_eq!(
            narrow.accel.as_ref().unwrap().octree.tags(),
            read.accel.as_ref().unwrap().octree.tags()
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
