//! Everything a frame needs that does not depend on camera, backdrop or ior,
//! built only when the scene uses it and cached.
//!
//! ```text
//! volume ──▶ field (prefiltered, per filter) ──▶ tags + octree (per iso and method)
//! ```
//!
//! A [`Cache`] keeps each product in memory, keyed by what determines it, so
//! re-rendering a scene with a new camera or ior rebuilds nothing. With a
//! cache directory, fields and tags are also stored on disk under the volume's
//! content hash and reused by later processes. Disk files are written
//! atomically and validated on read; a damaged or foreign file is ignored
//! (and rebuilt), never trusted.

use std::collections::HashMap;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};
use std::time::Instant;

use crate::classify::{self, Method, SubCellMasks, Tags};
use crate::filter::coeffs::Coeffs;
use crate::filter::{Field, FilterKind};
use crate::lattice::Lattice;
use crate::octree::{Octree, Proximity};
use crate::render::PrepareTimes;
use crate::scene::{Scene, SceneError, Traversal, VolumeSource};
use crate::volume::{LoadOptions, Volume};

/// Cell classification and the skipping structures over it, for one
/// iso-value. The distance field is built only when a traversal asks for it.
pub struct Accel {
    pub method: Method,
    /// The scene's iso-value it was built for.
    pub iso: f64,
    pub octree: Octree,
    proximity: OnceLock<Proximity>,
    masks: OnceLock<Option<SubCellMasks>>,
}

/// Largest memory the sub-cell masks may take (they are an optimisation:
/// without them every tagged cell's segment is solved).
pub const MASK_BUDGET: usize = 2 << 30;

impl Accel {
    /// The distance field, built on first use; returns it and its build time
    /// (0 when it already existed).
    pub fn proximity(&self) -> (&Proximity, f64) {
        let start = Instant::now();
        let mut built = false;
        let p = self.proximity.get_or_init(|| {
            built = true;
            Proximity::build(self.octree.tags())
        });
        (
            p,
            if built {
                start.elapsed().as_secs_f64()
            } else {
                0.0
            },
        )
    }

    /// The distance field if it was built.
    pub fn proximity_if_built(&self) -> Option<&Proximity> {
        self.proximity.get()
    }

    /// Sub-cell masks of the tagged cells, built on first use for the
    /// Bézier classification when they fit [`MASK_BUDGET`] (the paper's BMCC
    /// and ACCC are measured at their own resolution); returns them (or
    /// `None`) and the build time.
    pub fn masks(&self, field: &Field) -> (Option<&SubCellMasks>, f64) {
        let start = Instant::now();
        let mut built = false;
        let m = self.masks.get_or_init(|| {
            built = true;
            let tags = self.octree.tags();
            (matches!(self.method, Method::Bezier(_))
                && SubCellMasks::bytes_for(tags) <= MASK_BUDGET)
                .then(|| SubCellMasks::build(field, tags, field.separating_iso(self.iso)))
        });
        (
            m.as_ref(),
            if built {
                start.elapsed().as_secs_f64()
            } else {
                0.0
            },
        )
    }
}

/// Inputs of one frame.
pub struct Prepared {
    pub volume: Arc<Volume>,
    pub field: Arc<Field>,
    pub accel: Option<Arc<Accel>>,
    /// Build times of what was built for this frame (0 when cached).
    pub times: PrepareTimes,
}

impl Prepared {
    /// Prefilters `volume` for `filter`, without acceleration structures.
    pub fn new(volume: Arc<Volume>, filter: FilterKind) -> Prepared {
        let start = Instant::now();
        let field = Arc::new(Field::new(&volume, filter));
        Prepared {
            volume,
            field,
            accel: None,
            times: PrepareTimes {
                prefilter_s: start.elapsed().as_secs_f64(),
                ..Default::default()
            },
        }
    }

    /// Adds the classification and octree `method` at `iso` (timed).
    pub fn with_accel(mut self, iso: f64, method: Method) -> Prepared {
        let (accel, classify_s, octree_s) = build_accel(&self.field, iso, method, None);
        self.accel = Some(Arc::new(accel));
        self.times.classify_s = classify_s;
        self.times.octree_s = octree_s;
        self
    }

    /// Makes sure the structures `traversal` needs exist (the distance field).
    pub fn ready_for(&mut self, traversal: Traversal) {
        let Some(a) = &self.accel else { return };
        if traversal == Traversal::Distance {
            self.times.octree_s += a.proximity().1;
        }
        if traversal != Traversal::Step {
            self.times.octree_s += a.masks(&self.field).1;
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

fn build_accel(field: &Field, iso: f64, method: Method, tags: Option<Tags>) -> (Accel, f64, f64) {
    let start = Instant::now();
    let tags =
        tags.unwrap_or_else(|| classify::classify(field, field.separating_iso(iso), method).tags);
    let classify_s = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let octree = Octree::build(tags);
    (
        Accel {
            method,
            iso,
            octree,
            proximity: OnceLock::new(),
            masks: OnceLock::new(),
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
    fields: HashMap<(String, String), Arc<Field>>,
    accels: HashMap<(String, String, u64, String), Arc<Accel>>,
    /// Warnings about unusable disk cache files, for the caller to print.
    pub warnings: Vec<String>,
}

impl Cache {
    pub fn new() -> Cache {
        Cache::default()
    }

    /// Also persist fields and tags under `dir` (created if missing).
    pub fn with_dir(dir: &Path) -> std::io::Result<Cache> {
        std::fs::create_dir_all(dir)?;
        Ok(Cache {
            dir: Some(dir.to_path_buf()),
            ..Cache::default()
        })
    }

    /// Drops every volume (and the fields and acceleration structures built
    /// from it) whose [`Cache::volume_key`] is not in `keep`: a run over many
    /// volumes of one scene file (the scaling suite's 64³..1024³ phantoms)
    /// then holds only the ones still to come, not all of them at once.
    pub fn retain_volumes(&mut self, keep: &std::collections::HashSet<String>) {
        self.volumes.retain(|k, _| keep.contains(k));
        self.fields.retain(|(k, _), _| keep.contains(k));
        self.accels.retain(|(k, ..), _| keep.contains(k));
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
        let filter = scene.surface.filter;
        let fkey = (vkey.clone(), filter.cache_key());
        let field = match self.fields.get(&fkey) {
            Some(f) => f.clone(),
            None => {
                let start = Instant::now();
                let disk = self.disk_path(hash, &format!("{}.coef", filter.cache_key()));
                let loaded = disk
                    .as_deref()
                    .and_then(|p| self.read_field(p, filter, &volume));
                let f = Arc::new(match loaded {
                    Some(f) => f,
                    None => {
                        let f = Field::new(&volume, filter);
                        if let Some(p) = &disk {
                            self.write_or_warn(p, |w| write_field(w, &f));
                        }
                        f
                    }
                });
                times.prefilter_s = start.elapsed().as_secs_f64();
                self.fields.insert(fkey.clone(), f.clone());
                f
            }
        };
        let accel = match needs_accel(scene) {
            None => None,
            Some(method) => {
                let iso = scene.surface.iso;
                let akey = (vkey, filter.cache_key(), iso.to_bits(), method.name());
                match self.accels.get(&akey) {
                    Some(a) => Some(a.clone()),
                    None => {
                        let name = format!(
                            "{}-{:016x}-{}.tags",
                            filter.cache_key(),
                            iso.to_bits(),
                            method.name()
                        );
                        let disk = self.disk_path(hash, &name);
                        let lattice = Lattice::new(field.kernel(), field.dims());
                        let cached = disk.as_deref().and_then(|p| self.read_tags(p, &lattice));
                        let from_disk = cached.is_some();
                        let (a, cs, os) = build_accel(&field, iso, method, cached);
                        if !from_disk && let Some(p) = &disk {
                            self.write_or_warn(p, |w| write_tags(w, a.octree.tags()));
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
        };
        p.ready_for(scene.render.traversal);
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

    fn read_field(&mut self, path: &Path, filter: FilterKind, vol: &Volume) -> Option<Field> {
        if !path.exists() {
            return None;
        }
        match read_field(path, filter, vol.dims()) {
            Ok(f) => Some(f),
            Err(e) => {
                self.warnings
                    .push(format!("cache: ignoring {}: {e}", path.display()));
                None
            }
        }
    }

    fn read_tags(&mut self, path: &Path, lattice: &Lattice) -> Option<Tags> {
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

const FIELD_MAGIC: &[u8; 8] = b"SNLCOEF1";
const TAGS_MAGIC: &[u8; 8] = b"SNLTAGS1";

fn write_u64s(w: &mut dyn Write, v: &[u64]) -> std::io::Result<()> {
    for x in v {
        w.write_all(&x.to_le_bytes())?;
    }
    Ok(())
}

fn write_field(w: &mut dyn Write, f: &Field) -> std::io::Result<()> {
    w.write_all(FIELD_MAGIC)?;
    let key = f.kind().cache_key();
    write_u64s(w, &[key.len() as u64])?;
    w.write_all(key.as_bytes())?;
    let d = f.dims();
    write_u64s(w, &[d[0] as u64, d[1] as u64, d[2] as u64])?;
    write_u64s(w, &[f.coeffs().interior().len() as u64])?;
    for v in f.coeffs().interior() {
        w.write_all(&v.to_le_bytes())?;
    }
    Ok(())
}

fn read_exact_vec(r: &mut impl Read, n: usize) -> std::io::Result<Vec<u8>> {
    let mut v = vec![0u8; n];
    r.read_exact(&mut v)?;
    Ok(v)
}

fn read_u64(r: &mut impl Read) -> std::io::Result<u64> {
    let mut b = [0u8; 8];
    r.read_exact(&mut b)?;
    Ok(u64::from_le_bytes(b))
}

fn bad(msg: &str) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidData, msg.to_string())
}

fn read_field(path: &Path, filter: FilterKind, dims: [usize; 3]) -> std::io::Result<Field> {
    let mut r = std::io::BufReader::new(std::fs::File::open(path)?);
    if &read_exact_vec(&mut r, 8)?[..] != FIELD_MAGIC {
        return Err(bad("not a coefficient cache file"));
    }
    let klen = read_u64(&mut r)?;
    if klen > 256 {
        return Err(bad("bad key"));
    }
    let key = read_exact_vec(&mut r, klen as usize)?;
    if key != filter.cache_key().as_bytes() {
        return Err(bad("filter mismatch"));
    }
    let d = [read_u64(&mut r)?, read_u64(&mut r)?, read_u64(&mut r)?];
    if d != dims.map(|x| x as u64) {
        return Err(bad("dims mismatch"));
    }
    let n = read_u64(&mut r)?;
    if n != dims.iter().product::<usize>() as u64 {
        return Err(bad("length mismatch"));
    }
    let mut vals = Vec::with_capacity(n as usize);
    let mut b = [0u8; 8];
    for _ in 0..n {
        r.read_exact(&mut b)?;
        vals.push(f64::from_le_bytes(b));
    }
    if r.read(&mut b)? != 0 {
        return Err(bad("trailing data"));
    }
    if vals.iter().any(|v| !v.is_finite()) {
        return Err(bad("non-finite coefficient"));
    }
    Ok(Field::from_coeffs(
        filter,
        Coeffs::from_interior(dims, &vals, |v| *v),
    ))
}

fn write_tags(w: &mut dyn Write, t: &Tags) -> std::io::Result<()> {
    w.write_all(TAGS_MAGIC)?;
    write_u64s(w, &t.cells.map(|c| c as u64))?;
    write_u64s(w, &[t.words().len() as u64])?;
    write_u64s(w, t.words())
}

fn read_tags(path: &Path, lattice: &Lattice) -> std::io::Result<Tags> {
    let mut r = std::io::BufReader::new(std::fs::File::open(path)?);
    if &read_exact_vec(&mut r, 8)?[..] != TAGS_MAGIC {
        return Err(bad("not a tags cache file"));
    }
    let cells = [read_u64(&mut r)?, read_u64(&mut r)?, read_u64(&mut r)?];
    if cells != lattice.cells.map(|c| c as u64) {
        return Err(bad("lattice mismatch"));
    }
    let n = read_u64(&mut r)?;
    if n != lattice.cell_count().div_ceil(64) as u64 {
        return Err(bad("length mismatch"));
    }
    let words = (0..n)
        .map(|_| read_u64(&mut r))
        .collect::<std::io::Result<Vec<u64>>>()?;
    let mut b = [0u8; 1];
    if r.read(&mut b)? != 0 {
        return Err(bad("trailing data"));
    }
    Tags::from_words(lattice.cells, words).ok_or_else(|| bad("bad tag words"))
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
        assert!(Arc::ptr_eq(&a.field, &b.field));
        assert!(Arc::ptr_eq(
            a.accel.as_ref().unwrap(),
            b.accel.as_ref().unwrap()
        ));
        assert_eq!(b.times, PrepareTimes::default(), "nothing rebuilt");
        // A new iso-value rebuilds the tags, not the field.
        let mut s3 = s1.clone();
        s3.surface.iso = 100.0;
        let c = cache.prepare(&s3, &LoadOptions::default()).unwrap();
        assert!(Arc::ptr_eq(&a.field, &c.field));
        assert!(!Arc::ptr_eq(
            a.accel.as_ref().unwrap(),
            c.accel.as_ref().unwrap()
        ));
        // Keeping the volume keeps everything; dropping it rebuilds all.
        let key = Cache::volume_key(&s1);
        cache.retain_volumes(&[key].into_iter().collect());
        let d = cache.prepare(&s2, &LoadOptions::default()).unwrap();
        assert!(Arc::ptr_eq(&a.field, &d.field));
        cache.retain_volumes(&Default::default());
        let e = cache.prepare(&s2, &LoadOptions::default()).unwrap();
        assert!(!Arc::ptr_eq(&a.field, &e.field) && e.times.prefilter_s > 0.0);
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
        assert_eq!(files.len(), 2, "{files:?}");
        let mut fresh = Cache::with_dir(&dir).unwrap();
        let second = fresh.prepare(&s, &LoadOptions::default()).unwrap();
        assert!(fresh.warnings.is_empty(), "{:?}", fresh.warnings);
        assert_eq!(
            first.field.coeffs().interior(),
            second.field.coeffs().interior()
        );
        assert_eq!(
            first.accel.as_ref().unwrap().octree.tags(),
            second.accel.as_ref().unwrap().octree.tags()
        );
        // Damage every file: the cache warns, rebuilds, and gets the same answer.
        for f in &files {
            let mut b = std::fs::read(f).unwrap();
            let n = b.len();
            b.truncate(n - 3);
            std::fs::write(f, b).unwrap();
        }
        let mut broken = Cache::with_dir(&dir).unwrap();
        let third = broken.prepare(&s, &LoadOptions::default()).unwrap();
        assert_eq!(broken.warnings.len(), 2, "{:?}", broken.warnings);
        assert_eq!(
            first.field.coeffs().interior(),
            third.field.coeffs().interior()
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
