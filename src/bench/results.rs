//! What a benchmark run measured: the data behind `results.json`, the CSV,
//! the markdown tables and the plots (all generated from this, never typed).

use serde::Serialize;

use crate::render::Counters;

use super::suite::Comparison;

/// Everything one `snell bench` run measured.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub suite: String,
    pub description: String,
    pub budget: String,
    pub machine: Machine,
    pub run: RunInfo,
    pub tables: Vec<TableResult>,
    /// Each distinct configuration once (tables refer to these by index).
    pub configurations: Vec<ConfigResult>,
    /// Preparation products (prefiltered fields, tags, octrees), each built
    /// once per scene and reused by every later configuration that needs it.
    pub builds: Vec<BuildResult>,
    /// Ground-truth images rendered for the error columns.
    pub references: Vec<ReferenceResult>,
    pub warnings: Vec<String>,
}

/// The machine the numbers belong to.
#[derive(Clone, Debug, Serialize)]
pub struct Machine {
    pub nproc: usize,
    pub cpu_model: Option<String>,
    pub mem_total_mib: Option<f64>,
    pub os: String,
    pub arch: String,
    pub snell_version: String,
    /// `release` or `debug`: debug timings mean nothing.
    pub build_profile: String,
    /// `git describe --always` of the checkout the binary was built from,
    /// with `-dirty` when code (not Markdown) differed from it then; `None`
    /// for a build outside a git checkout.
    pub git: Option<String>,
}

/// How the run was made.
#[derive(Clone, Debug, Serialize)]
pub struct RunInfo {
    /// The exact command line.
    pub command: String,
    /// Start of the run, UTC (ISO 8601).
    pub date: String,
    pub threads: usize,
    /// Timed runs per configuration (some rows cap it, see `runs`).
    pub repeats: usize,
    pub scenes_dir: String,
    /// Wall time of the whole run, references and builds included.
    pub total_s: f64,
    /// Share of the machine's CPU time that other processes used during the
    /// run (0 on a quiet machine; timings are inflated when it is not).
    pub other_cpu_share: Option<f64>,
}

/// One table, as the report lays it out.
#[derive(Clone, Debug, Serialize)]
pub struct TableResult {
    pub id: String,
    pub title: String,
    pub note: String,
    #[serde(flatten)]
    pub body: TableResultBody,
}

#[derive(Clone, Debug, Serialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum TableResultBody {
    Render {
        comparison: Comparison,
        image_quality: bool,
        rows: Vec<RenderRow>,
    },
    Classify {
        methods: Vec<String>,
        rows: Vec<ClassifyResult>,
    },
}

/// A row of a render table: a configuration under this table's label.
#[derive(Clone, Debug, Serialize)]
pub struct RenderRow {
    pub label: String,
    pub scene: String,
    /// Index into [`Report::configurations`].
    pub config: usize,
    pub baseline: Option<String>,
    /// The table's comparison of this row's median time with its baseline's.
    pub vs_baseline: Option<f64>,
}

/// One distinct configuration, measured.
#[derive(Clone, Debug, Serialize)]
pub struct ConfigResult {
    pub name: String,
    pub scene: String,
    pub scene_label: String,
    pub overrides: Vec<String>,
    /// Ids of the tables that list it.
    pub tables: Vec<String>,
    pub settings: Settings,
    /// Every `[render]` setting as the scene resolved it (the PRSS and
    /// footprint details, max_events, tile, the switches `Settings` leaves
    /// out), so a row can be rendered again exactly.
    pub render: serde_json::Value,
    /// The instruction set the lanes ran under (`avx512`, `avx2`, `portable`).
    pub isa: String,
    /// The frame's identity (`Scene::frame_fingerprint`: volume contents,
    /// image, camera, surface, backdrop and render settings), as the hit
    /// EXRs of `render` carry it.
    pub frame_id: String,
    pub threads: usize,
    /// Timed runs (after one warm-up).
    pub runs: usize,
    pub wall_ms: TimeStats,
    /// CPU time per stage in the median run, summed over threads.
    pub stage_cpu_ms: StageMs,
    pub rays: u64,
    pub rays_per_s: f64,
    pub per_ray: PerRay,
    pub counters: Counters,
    /// Pixels the PRSS `trace` fallback re-traced.
    pub retraced_pixels: u64,
    /// Peak resident set (VmHWM) while this configuration ran, after resetting
    /// the peak at its start. It is the whole process's: what earlier
    /// configurations cached is resident too (see `rss_before_mib`).
    pub peak_rss_mib: Option<f64>,
    /// Resident set when the configuration started.
    pub rss_before_mib: Option<f64>,
    pub error: HitError,
    /// Image quality against a 16×16 supersampled render (anti-aliasing rows).
    pub quality: Option<ImageQuality>,
}

/// The scene settings that identify a configuration, after overrides.
#[derive(Clone, Debug, Serialize)]
pub struct Settings {
    pub filter: String,
    pub iso: f64,
    pub coefficients: String,
    pub traversal: String,
    pub classify: Option<String>,
    pub supersampling: String,
    pub samples: u32,
    pub leaf: u32,
    pub step: f64,
    pub tolerance: f64,
    pub width: u32,
    pub height: u32,
}

/// Wall times of the timed runs (`Frame.stats.wall`).
#[derive(Clone, Debug, Serialize)]
pub struct TimeStats {
    /// The median of the runs' times: for an even count the mean of the
    /// middle two (the lower one would be the minimum of two runs, biasing
    /// the time down). The per-run figures shown with it (stage times,
    /// counters) come from the lower middle run, one that happened.
    pub median: f64,
    pub min: f64,
    pub max: f64,
    pub all: Vec<f64>,
}

impl TimeStats {
    /// Summary of `times`, and the index of the median run. `None` if empty.
    pub fn of(times: &[f64]) -> Option<(TimeStats, usize)> {
        if times.is_empty() {
            return None;
        }
        let mut order: Vec<usize> = (0..times.len()).collect();
        order.sort_by(|&a, &b| times[a].total_cmp(&times[b]));
        let n = times.len();
        let mid = order[(n - 1) / 2];
        let median = if n % 2 == 1 {
            times[mid]
        } else {
            0.5 * (times[mid] + times[order[n / 2]])
        };
        Some((
            TimeStats {
                median,
                min: times[order[0]],
                max: times[order[times.len() - 1]],
                all: times.to_vec(),
            },
            mid,
        ))
    }
}

/// CPU milliseconds per pipeline stage.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct StageMs {
    pub generate: f64,
    pub entry: f64,
    pub traverse: f64,
    pub solve: f64,
    pub refract: f64,
    pub record: f64,
    pub prss: f64,
    pub film: f64,
}

impl StageMs {
    pub const NAMES: [&'static str; 8] = [
        "generate", "entry", "traverse", "solve", "refract", "record", "prss", "film",
    ];

    pub fn values(&self) -> [f64; 8] {
        [
            self.generate,
            self.entry,
            self.traverse,
            self.solve,
            self.refract,
            self.record,
            self.prss,
            self.film,
        ]
    }
}

/// Work per traced ray.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct PerRay {
    pub cells_visited: f64,
    pub cells_solved: f64,
    /// Share of solved cells that held the crossing the ray took.
    pub solved_with_crossing: f64,
    pub kernel_evals: f64,
    pub brent_iters: f64,
}

impl PerRay {
    pub fn of(c: &Counters) -> PerRay {
        let rays = c.rays.max(1) as f64;
        PerRay {
            cells_visited: c.cells_visited as f64 / rays,
            cells_solved: c.cells_solved as f64 / rays,
            solved_with_crossing: c.cells_with_crossing as f64 / c.cells_solved.max(1) as f64,
            kernel_evals: c.kernel_evals as f64 / rays,
            brent_iters: c.brent_iters as f64 / rays,
        }
    }
}

/// Hit-position error of the pixel-centre rays against ground truth.
#[derive(Clone, Debug, Serialize)]
pub struct HitError {
    /// `analytic` (the sphere phantom's exact spheres) or `dense-march`
    /// (step 0.02, tolerance 1e-9 through the same field).
    pub reference: String,
    /// `squares` (checker squares) or `units` (backdrop units, no checker).
    pub unit: String,
    /// Pixels whose ray crossed an interface in either image.
    pub refracted_pixels: usize,
    pub p50: f64,
    pub p90: f64,
    pub p99: f64,
    /// Share of all pixels with equal event counts.
    pub events_equal: f64,
    /// Pixels that reach the backdrop in only one of the two images.
    pub validity_mismatch: usize,
}

/// Colour-image quality against the supersampled reference.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct ImageQuality {
    pub psnr: f64,
    pub ssim: f64,
    pub rmse: f64,
}

/// One preparation product's build time.
#[derive(Clone, Debug, Serialize)]
pub struct BuildResult {
    pub scene: String,
    pub filter: String,
    pub iso: f64,
    /// Classification method, when tags and an octree were built.
    pub classify: Option<String>,
    pub load_ms: f64,
    pub prefilter_ms: f64,
    pub classify_ms: f64,
    pub octree_ms: f64,
    /// The configuration (or reference) that first needed it.
    pub built_for: String,
}

/// A ground-truth render.
#[derive(Clone, Debug, Serialize)]
pub struct ReferenceResult {
    /// `analytic`, `dense-march` or `grid16`.
    pub kind: String,
    pub scene: String,
    /// The overrides it was rendered with.
    pub overrides: Vec<String>,
    pub seconds: f64,
}

/// Cell counts of one volume and filter.
#[derive(Clone, Debug, Serialize)]
pub struct ClassifyResult {
    pub scene: String,
    pub scene_label: String,
    pub filter: String,
    pub iso: f64,
    /// Knot cells in the lattice.
    pub cells: usize,
    pub lattice: [usize; 3],
    pub methods: Vec<MethodCount>,
    /// Whether every method's tags contain the proven crossings (`exact`);
    /// `None` when `exact` was not run.
    pub all_contain_exact: Option<bool>,
}

#[derive(Clone, Debug, Serialize)]
pub struct MethodCount {
    pub method: String,
    pub tagged: usize,
    pub fraction: f64,
    pub ratio_to_bmcc: Option<f64>,
    pub ms: f64,
}

/// A small hand-made report for unit tests of the text and plot outputs.
#[cfg(test)]
pub(crate) fn sample_report() -> Report {
    use super::suite::Comparison;
    let config = |name: &str, scene: &str, median: f64, p90: f64, ss: &str| ConfigResult {
        name: name.into(),
        scene: format!("{scene}.toml"),
        scene_label: scene.into(),
        overrides: vec!["image.width=64".into(), "render.traversal=octree".into()],
        tables: vec!["t".into()],
        settings: Settings {
            filter: "bspline3".into(),
            iso: 127.5,
            coefficients: "f64".into(),
            traversal: "octree".into(),
            classify: Some("bezier".into()),
            supersampling: ss.into(),
            samples: 4,
            leaf: 4,
            step: 0.1,
            tolerance: 1e-7,
            width: 64,
            height: 64,
        },
        render: serde_json::Value::Null,
        isa: "avx2".into(),
        frame_id: "0123456789abcdef".into(),
        threads: 2,
        runs: 3,
        wall_ms: TimeStats::of(&[median * 1.1, median, median * 0.9])
            .unwrap()
            .0,
        stage_cpu_ms: StageMs {
            traverse: median,
            solve: median / 2.0,
            ..Default::default()
        },
        rays: 4096,
        rays_per_s: 4096.0 / (median / 1e3),
        per_ray: PerRay {
            cells_visited: 20.0,
            cells_solved: 3.5,
            solved_with_crossing: 0.26,
            kernel_evals: 1.9,
            brent_iters: 3.5,
        },
        counters: Default::default(),
        retraced_pixels: 0,
        peak_rss_mib: Some(42.0),
        rss_before_mib: Some(40.0),
        error: HitError {
            reference: "analytic".into(),
            unit: "squares".into(),
            refracted_pixels: 1000,
            p50: p90 / 5.0,
            p90,
            p99: p90 * 10.0,
            events_equal: 0.9961,
            validity_mismatch: 0,
        },
        quality: (ss != "none").then_some(ImageQuality {
            psnr: 30.5,
            ssim: 0.95,
            rmse: 0.03,
        }),
    };
    Report {
        suite: "unit".into(),
        description: "A hand-made report.".into(),
        budget: "none".into(),
        machine: Machine {
            nproc: 2,
            cpu_model: Some("Test CPU, 2 cores".into()),
            mem_total_mib: Some(1024.0),
            os: "linux".into(),
            arch: "x86_64".into(),
            snell_version: "0.1.0".into(),
            build_profile: "release".into(),
            git: None,
        },
        run: RunInfo {
            command: "snell bench --suite unit".into(),
            date: "2026-01-01T00:00:00Z".into(),
            threads: 2,
            repeats: 3,
            scenes_dir: "scenes".into(),
            total_s: 75.0,
            other_cpu_share: Some(0.01),
        },
        tables: vec![
            TableResult {
                id: "t".into(),
                title: "Traversal | test".into(),
                note: "A note.".into(),
                body: TableResultBody::Render {
                    comparison: Comparison::Speedup,
                    image_quality: false,
                    rows: vec![
                        RenderRow {
                            label: "step 0.1".into(),
                            scene: "sphere".into(),
                            config: 0,
                            baseline: Some("step 0.1".into()),
                            vs_baseline: Some(1.0),
                        },
                        RenderRow {
                            label: "octree, \"fast\"".into(),
                            scene: "sphere".into(),
                            config: 1,
                            baseline: Some("step 0.1".into()),
                            vs_baseline: Some(25.0),
                        },
                        RenderRow {
                            label: "prss".into(),
                            scene: "sphere".into(),
                            config: 2,
                            baseline: None,
                            vs_baseline: None,
                        },
                    ],
                },
            },
            TableResult {
                id: "c".into(),
                title: "Classification".into(),
                note: "Cells.".into(),
                body: TableResultBody::Classify {
                    methods: vec!["bmcc".into(), "accc".into()],
                    rows: vec![ClassifyResult {
                        scene: "sphere.toml".into(),
                        scene_label: "sphere".into(),
                        filter: "bspline3".into(),
                        iso: 127.5,
                        cells: 250_047,
                        lattice: [63, 63, 63],
                        methods: vec![
                            MethodCount {
                                method: "bmcc".into(),
                                tagged: 31_452,
                                fraction: 0.126,
                                ratio_to_bmcc: Some(1.0),
                                ms: 15.0,
                            },
                            MethodCount {
                                method: "accc".into(),
                                tagged: 20_068,
                                fraction: 0.08,
                                ratio_to_bmcc: Some(20_068.0 / 31_452.0),
                                ms: 39.0,
                            },
                        ],
                        all_contain_exact: None,
                    }],
                },
            },
        ],
        configurations: vec![
            config("step 0.1 bspline3 none", "sphere", 300.0, 1.3, "none"),
            config("octree, \"fast\"", "sphere", 12.0, 1.3, "none"),
            config("octree prss", "sphere", 20.0, 1.3, "prss"),
        ],
        builds: vec![BuildResult {
            scene: "sphere.toml".into(),
            filter: "bspline3".into(),
            iso: 127.5,
            classify: None,
            load_ms: 8.0,
            prefilter_ms: 8.5,
            classify_ms: 0.0,
            octree_ms: 0.0,
            built_for: "step 0.1 bspline3 none".into(),
        }],
        references: vec![ReferenceResult {
            kind: "analytic".into(),
            scene: "sphere.toml".into(),
            overrides: vec![],
            seconds: 0.5,
        }],
        warnings: vec!["a warning".into()],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two runs' median is their mean, not the faster one; the per-run
    /// figures come from the lower middle run.
    #[test]
    fn medians_of_even_counts_are_the_middle_pairs_mean() {
        let (s, mid) = TimeStats::of(&[126.5, 101.5]).unwrap();
        assert_eq!((s.median, mid, s.min, s.max), (114.0, 1, 101.5, 126.5));
        let (s, mid) = TimeStats::of(&[3.0, 1.0, 2.0]).unwrap();
        assert_eq!((s.median, mid), (2.0, 2));
        let (s, mid) = TimeStats::of(&[4.0, 1.0, 2.0, 3.0]).unwrap();
        assert_eq!((s.median, mid), (2.5, 2));
    }
}
