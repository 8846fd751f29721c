//! Running a suite: timing every configuration, measuring its error against
//! ground truth, and counting classified cells.
//!
//! Per configuration: the ground truth it is compared with is rendered (or
//! taken from this run's cache) first, so its time and memory are not the
//! configuration's; then the peak-RSS counter is reset, the scene is prepared
//! from its scene's [`Cache`] (so prefiltering, classification and the octree
//! are built once per scene and their build time is reported once), one
//! warm-up render runs, then the timed renders. Figures other than the wall
//! times come from the median run.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use crate::classify::{self, Method};
use crate::compare::compare_hits;
use crate::film::HitImage;
use crate::film::metrics::{RgbImage, compare_images};
use crate::lattice::Lattice;
use crate::prepare::{Cache, Prepared};
use crate::reference::Reference;
use crate::render::stats::{STAGES, Stage};
use crate::render::{self, Frame, PrepareTimes};
use crate::scene::{DEFAULT_CLASSIFY, Scene, Supersampling, setting_name};
use crate::volume::LoadOptions;

use super::machine;
use super::results::*;
use super::suite::{ClassifyRow, Experiment, Suite, TableBody};
use super::{BenchError, Observer};

/// Overrides of the dense march that stands in for ground truth where no
/// analytic solution exists: a fixed step 5× finer than the paper's 0.1 and
/// a crossing tolerance near f64 resolution.
pub const DENSE_MARCH: [&str; 5] = [
    "render.traversal=step",
    "render.classify=none",
    "render.step=0.02",
    "render.tolerance=1e-9",
    "render.supersampling=none",
];

/// Rays per pixel side of the image-quality reference.
pub const QUALITY_REFERENCE_SAMPLES: u32 = 16;

/// Render settings that only change how a frame is computed, not what it
/// should converge to; ground truth drops them.
const RENDER_ONLY_KEYS: [&str; 15] = [
    "traversal",
    "step",
    "tolerance",
    "tile",
    "classify",
    "leaf",
    "supersampling",
    "samples",
    "prss_samples",
    "prss_map",
    "prss_fallback",
    "prss_curvature",
    "footprint",
    "seed",
    "threads",
];

/// The overrides that define what the image should be (drops `render.*`
/// settings except those that change the answer, like `max_events`).
pub fn content_overrides(overrides: &[String]) -> Vec<String> {
    overrides
        .iter()
        .filter(|o| {
            let key = o.split_once('=').map_or(o.as_str(), |(k, _)| k).trim();
            match key.strip_prefix("render.") {
                Some(k) => !RENDER_ONLY_KEYS.contains(&k),
                None => true,
            }
        })
        .cloned()
        .collect()
}

/// The analytic reference does not depend on the filter either.
fn geometry_overrides(overrides: &[String]) -> Vec<String> {
    content_overrides(overrides)
        .into_iter()
        .filter(|o| !o.starts_with("surface.filter=") && !o.starts_with("surface.lambda="))
        .collect()
}

/// Overrides of the dense march standing in for ground truth.
fn dense_march_overrides(overrides: &[String]) -> Vec<String> {
    let mut o = content_overrides(overrides);
    o.extend(DENSE_MARCH.iter().map(|s| s.to_string()));
    o
}

/// Overrides of the 16×16 grid-supersampled image-quality reference.
fn quality_reference_overrides(overrides: &[String]) -> Vec<String> {
    let mut o = content_overrides(overrides);
    o.extend([
        "render.traversal=octree".to_string(),
        format!("render.classify={}", DEFAULT_CLASSIFY.name()),
        "render.supersampling=grid".to_string(),
        format!("render.samples={QUALITY_REFERENCE_SAMPLES}"),
    ]);
    o
}

#[derive(Clone)]
struct Truth {
    kind: &'static str,
    hits: Arc<HitImage>,
}

pub(super) struct Runner<'a> {
    scenes_dir: PathBuf,
    repeats: usize,
    observer: &'a mut dyn Observer,
    /// One cache per scene file.
    caches: HashMap<String, Cache>,
    truths: HashMap<String, Truth>,
    quality_refs: HashMap<String, Arc<RgbImage>>,
    /// Content hashes by volume ([`Cache::volume_key`]), for the rows'
    /// frame ids: one pass over each volume, not one per configuration.
    volume_hashes: HashMap<String, u64>,
    builds: Vec<BuildResult>,
    references: Vec<ReferenceResult>,
    warnings: Vec<String>,
    peak_reset_works: bool,
    done: usize,
    total: usize,
}

/// What a suite run produced, before it is laid out as a [`Report`].
pub(super) struct Measured {
    pub tables: Vec<TableResult>,
    pub configurations: Vec<ConfigResult>,
    pub builds: Vec<BuildResult>,
    pub references: Vec<ReferenceResult>,
    pub warnings: Vec<String>,
}

impl<'a> Runner<'a> {
    pub fn new(scenes_dir: &Path, repeats: usize, observer: &'a mut dyn Observer) -> Runner<'a> {
        Runner {
            scenes_dir: scenes_dir.to_path_buf(),
            repeats,
            observer,
            caches: HashMap::new(),
            truths: HashMap::new(),
            quality_refs: HashMap::new(),
            volume_hashes: HashMap::new(),
            builds: Vec::new(),
            references: Vec::new(),
            warnings: Vec::new(),
            peak_reset_works: true,
            done: 0,
            total: 0,
        }
    }

    fn scene_path(&self, file: &str) -> PathBuf {
        self.scenes_dir.join(file)
    }

    fn load(&self, file: &str, overrides: &[String]) -> Result<Scene, BenchError> {
        Ok(Scene::load(&self.scene_path(file), overrides)?)
    }

    /// Loads every scene of the suite with its overrides, so a typo fails in
    /// a second instead of after an hour.
    pub fn check(&self, suite: &Suite) -> Result<(), BenchError> {
        for t in &suite.tables {
            match &t.body {
                TableBody::Render(r) => {
                    for e in &r.experiments {
                        self.load(&e.scene, &e.overrides)?;
                    }
                }
                TableBody::Classify(c) => {
                    for row in &c.rows {
                        self.load(&row.scene, &row.overrides)?;
                    }
                }
            }
        }
        Ok(())
    }

    /// Measures every distinct configuration and classification row, scene
    /// by scene (so one scene's fields, tags and octrees are in memory at a
    /// time and are freed when it is done), then lays out the tables.
    pub fn run(mut self, suite: &Suite) -> Result<Measured, BenchError> {
        // Distinct configurations in order of first appearance, with the
        // table that first lists them.
        let mut index: HashMap<String, usize> = HashMap::new();
        let mut unique: Vec<(&Experiment, &str)> = Vec::new();
        for (t, e) in suite.experiments() {
            if let std::collections::hash_map::Entry::Vacant(v) = index.entry(e.key()) {
                v.insert(unique.len());
                unique.push((e, &t.id));
            }
        }
        // Image quality is measured for a configuration if any table listing
        // it asks, so a shared row is rendered once either way.
        let wants_quality: HashSet<String> = suite
            .tables
            .iter()
            .filter_map(|t| match &t.body {
                TableBody::Render(r) if r.image_quality => Some(r),
                _ => None,
            })
            .flat_map(|r| r.experiments.iter().map(Experiment::key))
            .collect();
        let mut classify_rows: Vec<(usize, usize, &ClassifyRow, &[Method])> = Vec::new();
        for (ti, t) in suite.tables.iter().enumerate() {
            if let TableBody::Classify(c) = &t.body {
                for (ri, row) in c.rows.iter().enumerate() {
                    classify_rows.push((ti, ri, row, &c.methods));
                }
            }
        }
        let mut scenes: Vec<&str> = Vec::new();
        let all_scenes = unique
            .iter()
            .map(|(e, _)| e.scene.as_str())
            .chain(classify_rows.iter().map(|(_, _, r, _)| r.scene.as_str()));
        for sc in all_scenes {
            if !scenes.contains(&sc) {
                scenes.push(sc);
            }
        }
        self.total = unique.len() + classify_rows.len();
        self.observer.begin(self.total);

        let mut configs: Vec<Option<ConfigResult>> = vec![None; unique.len()];
        let mut classified: HashMap<(usize, usize), ClassifyResult> = HashMap::new();
        for scene in scenes {
            // The fields (volume, filter, storage) this scene's experiments
            // and classify rows use, in run order: before each experiment,
            // the cache keeps only those still to come (one 1024³ phantom's
            // structures take 17 GB).
            let mut upcoming: Vec<(usize, (String, String))> = Vec::new();
            for (i, (e, _)) in unique.iter().enumerate() {
                if e.scene == scene {
                    upcoming.push((i, field_key(self.load(&e.scene, &e.overrides)?)));
                }
            }
            for &(_, _, row, _) in &classify_rows {
                if row.scene == scene {
                    upcoming.push((
                        usize::MAX,
                        field_key(self.load(&row.scene, &row.overrides)?),
                    ));
                }
            }
            for (i, (e, table)) in unique.iter().enumerate() {
                if e.scene != scene {
                    continue;
                }
                let keep: HashSet<(String, String)> = upcoming
                    .iter()
                    .filter(|(j, _)| *j >= i)
                    .map(|(_, k)| k.clone())
                    .collect();
                self.cache(scene).retain(&keep);
                let what = format!("{table}: {} ({})", e.name, e.scene_label);
                self.observer.start(&what);
                let c = self.experiment(e, wants_quality.contains(&e.key()))?;
                self.done += 1;
                self.observer.finish(&format!(
                    "[{}/{}] {}",
                    self.done,
                    self.total,
                    summary_line(&c)
                ));
                configs[i] = Some(c);
            }
            for &(ti, ri, row, methods) in &classify_rows {
                if row.scene != scene {
                    continue;
                }
                let what = format!(
                    "{}: classify {} {}",
                    suite.tables[ti].id,
                    row.scene_label,
                    row.overrides
                        .iter()
                        .map(|o| o.split_once('=').map_or(o.as_str(), |(_, v)| v))
                        .collect::<Vec<_>>()
                        .join(" ")
                );
                self.observer.start(&what);
                let r = self.classify_row(row, methods)?;
                self.done += 1;
                self.observer.finish(&format!(
                    "[{}/{}] {what}: {}",
                    self.done,
                    self.total,
                    r.methods
                        .iter()
                        .map(|m| format!("{} {}", m.method, m.tagged))
                        .collect::<Vec<_>>()
                        .join(", ")
                ));
                classified.insert((ti, ri), r);
            }
            // Done with this scene: free its prepared data.
            self.caches.remove(scene);
        }
        let mut configs: Vec<ConfigResult> = configs.into_iter().flatten().collect();

        let mut tables = Vec::new();
        for (ti, t) in suite.tables.iter().enumerate() {
            let body = match &t.body {
                TableBody::Render(r) => {
                    let mut rows: Vec<RenderRow> = r
                        .experiments
                        .iter()
                        .map(|e| RenderRow {
                            label: e.label.clone(),
                            scene: e.scene_label.clone(),
                            config: index[&e.key()],
                            baseline: e.baseline.clone(),
                            vs_baseline: None,
                        })
                        .collect();
                    for row in &rows {
                        let c = &mut configs[row.config];
                        if !c.tables.contains(&t.id) {
                            c.tables.push(t.id.clone());
                        }
                    }
                    let lookup: Vec<(String, String, usize)> = rows
                        .iter()
                        .map(|row| (row.scene.clone(), row.label.clone(), row.config))
                        .collect();
                    for row in &mut rows {
                        if let Some(b) = &row.baseline
                            && let Some((_, _, bi)) =
                                lookup.iter().find(|(s, l, _)| *s == row.scene && l == b)
                        {
                            row.vs_baseline = Some(r.comparison.value(
                                configs[row.config].wall_ms.median,
                                configs[*bi].wall_ms.median,
                            ));
                        }
                    }
                    TableResultBody::Render {
                        comparison: r.comparison,
                        image_quality: r.image_quality,
                        rows,
                    }
                }
                TableBody::Classify(c) => TableResultBody::Classify {
                    methods: c.methods.iter().map(Method::name).collect(),
                    rows: (0..c.rows.len())
                        .filter_map(|ri| classified.remove(&(ti, ri)))
                        .collect(),
                },
            };
            tables.push(TableResult {
                id: t.id.clone(),
                title: t.title.clone(),
                note: t.note.clone(),
                body,
            });
        }
        if !self.peak_reset_works {
            self.warnings.push(
                "/proc/self/clear_refs is not writable: peak memory is the process's peak so far, \
not per configuration"
                    .into(),
            );
        }
        Ok(Measured {
            tables,
            configurations: configs,
            builds: self.builds,
            references: self.references,
            warnings: self.warnings,
        })
    }

    fn cache(&mut self, scene_file: &str) -> &mut Cache {
        self.caches.entry(scene_file.to_string()).or_default()
    }

    /// Prepares `scene` from its scene's cache, recording what was built.
    fn prepare(
        &mut self,
        scene_file: &str,
        scene: &Scene,
        built_for: &str,
    ) -> Result<Prepared, BenchError> {
        let prep = self
            .cache(scene_file)
            .prepare(scene, &LoadOptions::default())?;
        let t: PrepareTimes = prep.times;
        if t != PrepareTimes::default() {
            self.builds.push(BuildResult {
                scene: scene_file.to_string(),
                filter: scene.surface.filter.to_string(),
                iso: scene.surface.iso,
                classify: prep.accel.as_ref().map(|a| a.method.name()),
                load_ms: t.load_s * 1e3,
                prefilter_ms: t.prefilter_s * 1e3,
                classify_ms: t.classify_s * 1e3,
                octree_ms: t.octree_s * 1e3,
                built_for: built_for.to_string(),
            });
        }
        let warnings = std::mem::take(&mut self.cache(scene_file).warnings);
        self.warnings.extend(warnings);
        Ok(prep)
    }

    /// The ground-truth hit image for `e` (rendered once per run): the
    /// analytic spheres for a sphere phantom, else a dense march through the
    /// same field.
    fn truth(&mut self, e: &Experiment, scene: &Scene) -> Result<Truth, BenchError> {
        let analytic = Reference::from_scene(scene).ok();
        let (key, overrides) = match &analytic {
            Some(_) => {
                let o = geometry_overrides(&e.overrides);
                (format!("analytic|{}|{}", e.scene, o.join("|")), o)
            }
            None => {
                let o = dense_march_overrides(&e.overrides);
                (format!("dense|{}|{}", e.scene, o.join("|")), o)
            }
        };
        if let Some(t) = self.truths.get(&key) {
            return Ok(t.clone());
        }
        let start = Instant::now();
        let truth = match analytic {
            Some(reference) => Truth {
                kind: "analytic",
                hits: Arc::new(reference.render(scene)),
            },
            None => {
                let what = format!(
                    "dense-march reference for {} ({})",
                    e.scene_label, scene.surface.filter
                );
                self.observer.start(&what);
                let ref_scene = self.load(&e.scene, &overrides)?;
                let prep = self.prepare(&e.scene, &ref_scene, &what)?;
                let frame = render::render(&ref_scene, &prep, None);
                Truth {
                    kind: "dense-march",
                    hits: Arc::new(frame.film.hits()),
                }
            }
        };
        self.references.push(ReferenceResult {
            kind: truth.kind.into(),
            scene: e.scene.clone(),
            overrides,
            seconds: start.elapsed().as_secs_f64(),
        });
        self.truths.insert(key, truth.clone());
        Ok(truth)
    }

    /// The 16×16 grid-supersampled colour image of `e`'s scene and filter.
    fn quality_reference(&mut self, e: &Experiment) -> Result<Arc<RgbImage>, BenchError> {
        let overrides = quality_reference_overrides(&e.overrides);
        let key = format!("{}|{}", e.scene, overrides.join("|"));
        if let Some(img) = self.quality_refs.get(&key) {
            return Ok(img.clone());
        }
        let scene = self.load(&e.scene, &overrides)?;
        let what = format!(
            "{n}×{n} reference for {} ({})",
            e.scene_label,
            scene.surface.filter,
            n = QUALITY_REFERENCE_SAMPLES
        );
        self.observer.start(&what);
        let start = Instant::now();
        let prep = self.prepare(&e.scene, &scene, &what)?;
        let frame = render::render(&scene, &prep, None);
        self.references.push(ReferenceResult {
            kind: format!("grid{QUALITY_REFERENCE_SAMPLES}"),
            scene: e.scene.clone(),
            overrides,
            seconds: start.elapsed().as_secs_f64(),
        });
        let img = Arc::new(color_image(&frame));
        self.quality_refs.insert(key, img.clone());
        Ok(img)
    }

    fn experiment(
        &mut self,
        e: &Experiment,
        table_wants_quality: bool,
    ) -> Result<ConfigResult, BenchError> {
        let scene = self.load(&e.scene, &e.overrides)?;
        let wants_quality = !e.skip_quality
            && (table_wants_quality || scene.render.supersampling != Supersampling::None);
        // Ground truth first: neither its time nor its memory is the configuration's.
        let truth = self.truth(e, &scene)?;
        let quality_ref = if wants_quality {
            Some(self.quality_reference(e)?)
        } else {
            None
        };

        self.peak_reset_works &= machine::reset_peak_rss();
        let rss_before = machine::rss_mib();
        let prep = self.prepare(&e.scene, &scene, &e.name)?;
        drop(render::render(&scene, &prep, None)); // warm-up
        let runs = self.repeats.min(e.max_repeats.unwrap_or(usize::MAX)).max(1);
        let mut frames: Vec<Frame> = (0..runs)
            .map(|_| render::render(&scene, &prep, None))
            .collect();
        let peak = machine::peak_rss_mib();
        let volume_hash = *self
            .volume_hashes
            .entry(Cache::volume_key(&scene))
            .or_insert_with(|| prep.volume_hash());
        let frame_id = scene.frame_fingerprint(volume_hash).to_string();
        drop(prep);

        let times: Vec<f64> = frames
            .iter()
            .map(|f| f.stats.wall.as_secs_f64() * 1e3)
            .collect();
        let Some((wall_ms, mid)) = TimeStats::of(&times) else {
            unreachable!("at least one timed run");
        };
        let frame = frames.swap_remove(mid);
        drop(frames);

        let cmp =
            compare_hits(&frame.film.hits(), &truth.hits, scene.checker_size()).map_err(|err| {
                BenchError::Measure {
                    what: e.name.clone(),
                    msg: err.to_string(),
                }
            })?;
        let error = HitError {
            reference: truth.kind.to_string(),
            unit: if cmp.checker.is_some() {
                "squares"
            } else {
                "units"
            }
            .into(),
            refracted_pixels: cmp.refracted.pixels,
            p50: cmp.squares(cmp.refracted.p50),
            p90: cmp.squares(cmp.refracted.p90),
            p99: cmp.squares(cmp.refracted.p99),
            events_equal: cmp.events_equal_fraction,
            validity_mismatch: cmp.validity_mismatch,
        };
        let quality = match &quality_ref {
            Some(r) => Some(image_quality(e, &frame, r)?),
            None => None,
        };

        let stats = &frame.stats;
        let st = |s: Stage| stats.stage_times.get(s).as_secs_f64() * 1e3;
        debug_assert_eq!(STAGES.len(), StageMs::NAMES.len());
        let rs = &scene.render;
        Ok(ConfigResult {
            name: e.name.clone(),
            scene: e.scene.clone(),
            scene_label: e.scene_label.clone(),
            overrides: e.overrides.clone(),
            tables: Vec::new(),
            settings: Settings {
                filter: scene.surface.filter.to_string(),
                iso: scene.surface.iso,
                coefficients: rs.coefficients.name().to_string(),
                traversal: setting_name(&rs.traversal),
                classify: rs.classify.map(|m| m.name()),
                supersampling: setting_name(&rs.supersampling),
                samples: rs.samples,
                leaf: rs.leaf,
                step: rs.step,
                tolerance: rs.tolerance,
                width: scene.width,
                height: scene.height,
            },
            render: serde_json::to_value(rs).unwrap_or_default(),
            isa: crate::simd::Isa::current().name().to_string(),
            frame_id,
            threads: stats.threads,
            runs,
            rays: stats.counters.rays,
            rays_per_s: stats.counters.rays as f64 / stats.wall.as_secs_f64().max(1e-12),
            wall_ms,
            stage_cpu_ms: StageMs {
                generate: st(Stage::Generate),
                entry: st(Stage::Entry),
                traverse: st(Stage::Traverse),
                solve: st(Stage::Solve),
                refract: st(Stage::Refract),
                record: st(Stage::Record),
                prss: st(Stage::Prss),
                film: st(Stage::Film),
            },
            per_ray: PerRay::of(&stats.counters),
            counters: stats.counters,
            retraced_pixels: stats.retraced_pixels,
            peak_rss_mib: peak,
            rss_before_mib: rss_before,
            error,
            quality,
        })
    }

    fn classify_row(
        &mut self,
        row: &ClassifyRow,
        methods: &[Method],
    ) -> Result<ClassifyResult, BenchError> {
        // DDA without tags: the cache builds the field only.
        let mut overrides = row.overrides.clone();
        overrides.extend([
            "render.traversal=dda".to_string(),
            "render.classify=none".to_string(),
        ]);
        let scene = self.load(&row.scene, &overrides)?;
        let what = format!("classify {} {}", row.scene_label, scene.surface.filter);
        let prep = self.prepare(&row.scene, &scene, &what)?;
        let field = &prep.field;
        let lattice = Lattice::new(field.kernel(), field.dims());
        let iso = field.separating_iso(scene.surface.iso);
        let results: Vec<classify::Classification> = methods
            .iter()
            .map(|&m| crate::with_field!(field, f => classify::classify(f.as_ref(), iso, m)))
            .collect();
        let bmcc = results
            .iter()
            .find(|r| r.method == Method::Bmcc)
            .map(|r| r.tags.count());
        let exact = results.iter().find(|r| r.method == Method::Exact);
        let total = lattice.cell_count();
        Ok(ClassifyResult {
            scene: row.scene.clone(),
            scene_label: row.scene_label.clone(),
            filter: scene.surface.filter.to_string(),
            iso: scene.surface.iso,
            cells: total,
            lattice: lattice.cells,
            methods: results
                .iter()
                .map(|r| MethodCount {
                    method: r.method.name(),
                    tagged: r.tags.count(),
                    fraction: r.tags.count() as f64 / total.max(1) as f64,
                    ratio_to_bmcc: bmcc
                        .filter(|&b| b > 0)
                        .map(|b| r.tags.count() as f64 / b as f64),
                    ms: r.seconds * 1e3,
                })
                .collect(),
            all_contain_exact: exact.map(|x| results.iter().all(|r| x.tags.is_subset_of(&r.tags))),
        })
    }
}

fn image_quality(
    e: &Experiment,
    frame: &Frame,
    reference: &RgbImage,
) -> Result<ImageQuality, BenchError> {
    let q = compare_images(&color_image(frame), reference).map_err(|msg| BenchError::Measure {
        what: e.name.clone(),
        msg,
    })?;
    Ok(ImageQuality {
        psnr: q.psnr,
        ssim: q.ssim,
        rmse: q.rmse,
    })
}

fn color_image(frame: &Frame) -> RgbImage {
    RgbImage {
        width: frame.film.width,
        height: frame.film.height,
        pixels: frame.film.color.clone(),
    }
}

fn summary_line(c: &ConfigResult) -> String {
    let mut s = format!(
        "{} {}: median {:.1} ms ({} run{}), p90 {:.3} {}",
        c.scene_label,
        c.name,
        c.wall_ms.median,
        c.runs,
        if c.runs == 1 { "" } else { "s" },
        c.error.p90,
        c.error.unit
    );
    if let Some(q) = &c.quality {
        s.push_str(&format!(", PSNR {:.2} dB, SSIM {:.4}", q.psnr, q.ssim));
    }
    s
}

fn field_key(scene: Scene) -> (String, String) {
    Cache::field_key(&scene)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every configuration of every suite, and the ground truth and quality
    /// reference it would need, is a valid scene: a typo in an override fails
    /// here, not an hour into a run.
    #[test]
    fn every_suite_configuration_parses() {
        let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
        for name in super::super::SUITES.iter().chain(&["smoke"]) {
            let suite = Suite::by_name(name).unwrap();
            let mut silent = super::super::Silent;
            let runner = Runner::new(&scenes, 1, &mut silent);
            runner.check(&suite).unwrap();
            for (_, e) in suite.experiments() {
                for o in [
                    dense_march_overrides(&e.overrides),
                    quality_reference_overrides(&e.overrides),
                ] {
                    let s = runner
                        .load(&e.scene, &o)
                        .unwrap_or_else(|err| panic!("{name}: {err}"));
                    assert!((64..=2048).contains(&s.width), "{name}: {}", e.name);
                }
            }
        }
    }

    #[test]
    fn ground_truth_keeps_what_the_image_depends_on() {
        let o: Vec<String> = [
            "image.width=64",
            "surface.filter=bspline2",
            "render.traversal=octree",
            "render.classify=accc",
            "render.max_events=8",
            "render.supersampling=prss",
            "render.leaf=2",
        ]
        .map(String::from)
        .to_vec();
        assert_eq!(
            content_overrides(&o),
            [
                "image.width=64",
                "surface.filter=bspline2",
                "render.max_events=8"
            ]
        );
        assert_eq!(
            geometry_overrides(&o),
            ["image.width=64", "render.max_events=8"]
        );
    }
}
