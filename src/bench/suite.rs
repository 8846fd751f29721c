//! What a benchmark suite measures: named tables of experiments, each a scene
//! file with `--set`-style overrides.
//!
//! Suites are data, not code paths: the runner treats every render table the
//! same way, so adding a configuration is adding a row here. Rows that are the
//! same configuration (same scene file, same overrides) in several tables are
//! rendered once and reported in each.

use crate::classify::Method;

use super::BenchError;

/// A named list of tables.
#[derive(Clone, Debug)]
pub struct Suite {
    pub name: String,
    /// One sentence: what the suite is for.
    pub description: String,
    /// Honest wall-time budget on the 2-core reference machine (release build),
    /// shown before the run starts so nobody is surprised by an hour-long run.
    pub budget: String,
    pub tables: Vec<Table>,
}

/// One table of the report.
#[derive(Clone, Debug)]
pub struct Table {
    /// Short stable id (file names, JSON keys, CSV column).
    pub id: String,
    pub title: String,
    /// What the table shows and how to read it (printed under the title).
    pub note: String,
    pub body: TableBody,
}

#[derive(Clone, Debug)]
pub enum TableBody {
    Render(RenderTable),
    Classify(ClassifyTable),
}

/// Rows of renders, timed and measured for error.
#[derive(Clone, Debug)]
pub struct RenderTable {
    pub experiments: Vec<Experiment>,
    /// How a row relates to its baseline row (if it names one).
    pub comparison: Comparison,
    /// Measure image quality (PSNR, SSIM against a 16×16 supersampled render)
    /// for every row, not only the anti-aliased ones: the `none` baseline of
    /// an anti-aliasing table needs it to show what anti-aliasing buys.
    pub image_quality: bool,
}

/// How the "vs" column of a render table is computed from the median times.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Comparison {
    /// `time / baseline` ("ratio to none": the cost of anti-aliasing).
    Ratio,
    /// `baseline / time` ("speedup vs step").
    Speedup,
    /// `1 - time / baseline` ("time saved by the octree").
    Saving,
}

impl Comparison {
    pub fn header(self, baseline: &str) -> String {
        match self {
            Comparison::Ratio => format!("× {baseline}"),
            Comparison::Speedup => format!("speedup vs {baseline}"),
            Comparison::Saving => format!("saving vs {baseline}"),
        }
    }

    pub fn value(self, time: f64, baseline: f64) -> f64 {
        match self {
            Comparison::Ratio => time / baseline,
            Comparison::Speedup => baseline / time,
            Comparison::Saving => 1.0 - time / baseline,
        }
    }

    pub fn format(self, v: f64) -> String {
        if !v.is_finite() {
            return "–".into();
        }
        match self {
            Comparison::Ratio | Comparison::Speedup => format!("{v:.2}×"),
            Comparison::Saving => format!("{:.1}%", 100.0 * v),
        }
    }
}

/// One configuration: a scene file plus overrides.
#[derive(Clone, Debug, PartialEq)]
pub struct Experiment {
    /// Scene file name inside the scenes directory, e.g. `sphere.toml`.
    pub scene: String,
    /// Short name of the scene for tables and plots (`sphere`, `cranium`).
    pub scene_label: String,
    /// Row label, unique within the table for its scene.
    pub label: String,
    /// Descriptive name of the configuration, the same in every table that
    /// holds it (plots, CSV).
    pub name: String,
    /// `section.key=value` overrides, applied in order.
    pub overrides: Vec<String>,
    /// Label of the row (same table, same scene) this one is compared with.
    pub baseline: Option<String>,
    /// At most this many timed runs, whatever `--repeats` says: slow
    /// baselines (step traversal) would otherwise dominate the budget.
    pub max_repeats: Option<usize>,
    /// No PSNR/SSIM even for an anti-aliased row: where only time matters
    /// and the 16×16 reference would cost more than the rest (2048² frames).
    pub skip_quality: bool,
}

impl Experiment {
    /// The identity of the configuration: rows with equal keys are rendered once.
    pub fn key(&self) -> String {
        format!("{}|{}", self.scene, self.overrides.join("|"))
    }
}

/// Cell classification counts for several methods, per volume and filter.
#[derive(Clone, Debug)]
pub struct ClassifyTable {
    pub rows: Vec<ClassifyRow>,
    pub methods: Vec<Method>,
}

/// One volume (from a scene file, at the scene's iso-value unless
/// overridden) reconstructed with one filter.
#[derive(Clone, Debug)]
pub struct ClassifyRow {
    pub scene: String,
    pub scene_label: String,
    pub overrides: Vec<String>,
}

impl ClassifyRow {
    pub fn key(&self) -> String {
        format!("{}|{}", self.scene, self.overrides.join("|"))
    }
}

/// Names accepted by [`Suite::by_name`] (`smoke` is for tests and not listed).
pub const SUITES: [&str; 4] = ["quick", "paper", "full", "scaling"];

impl Suite {
    pub fn by_name(name: &str) -> Result<Suite, BenchError> {
        match name {
            "quick" => Ok(quick()),
            "paper" => Ok(paper()),
            "full" => Ok(full()),
            "scaling" => Ok(scaling()),
            "smoke" => Ok(smoke()),
            other => Err(BenchError::UnknownSuite(other.to_string())),
        }
    }

    /// Every render experiment, in table order.
    pub fn experiments(&self) -> impl Iterator<Item = (&Table, &Experiment)> {
        self.tables.iter().flat_map(|t| match &t.body {
            TableBody::Render(r) => r.experiments.iter().map(move |e| (t, e)).collect(),
            TableBody::Classify(_) => Vec::new(),
        })
    }
}

// ---------------------------------------------------------------------------
// Building blocks. Every configuration is spelled through these helpers so the
// same configuration gets the same overrides (and so is rendered once).

const SIDE_512: [&str; 2] = ["image.width=512", "image.height=512"];

/// A filter and its parameter as overrides (λ only for the smoothing spline).
fn filter(name: &str) -> Vec<String> {
    match name {
        "smooth-bspline3" => vec![
            "surface.filter=smooth-bspline3".into(),
            "surface.lambda=1".into(),
        ],
        other => vec![format!("surface.filter={other}")],
    }
}

fn filter_label(name: &str) -> &str {
    match name {
        "smooth-bspline3" => "smooth-bspline3 λ=1",
        other => other,
    }
}

/// Traversal (and classification) as overrides; labels as in the paper.
fn traversal(kind: &str) -> (String, Vec<String>) {
    let t = |s: &str| format!("render.traversal={s}");
    let c = |s: &str| format!("render.classify={s}");
    let (label, o) = match kind {
        "step" => ("step 0.1", vec![t("step"), "render.step=0.1".into()]),
        "dda" => ("dda", vec![t("dda"), c("none")]),
        "dda+bmcc" => ("dda+bmcc", vec![t("dda"), c("bmcc")]),
        "dda+accc" => ("dda+accc", vec![t("dda"), c("accc")]),
        "octree+bmcc" => ("octree+bmcc", vec![t("octree"), c("bmcc")]),
        "octree+accc" => ("octree+accc", vec![t("octree"), c("accc")]),
        "octree+accc4" => ("octree+accc4", vec![t("octree"), c("accc4")]),
        "octree+accc8" => ("octree+accc8", vec![t("octree"), c("accc8")]),
        "octree+bezier" => ("octree+bezier", vec![t("octree"), c("bezier")]),
        "distance+bezier" => ("distance+bezier", vec![t("distance"), c("bezier")]),
        other => unreachable!("no traversal preset '{other}'"),
    };
    (label.to_string(), o)
}

/// Anti-aliasing as overrides.
fn antialias(kind: &str) -> (String, Vec<String>) {
    let s = |m: &str| format!("render.supersampling={m}");
    let prss = |extra: &[&str]| {
        let mut o = vec![s("prss")];
        o.extend(extra.iter().map(|e| e.to_string()));
        o
    };
    let (label, o) = match kind {
        "none" => ("none", vec![s("none")]),
        "grid3" => ("real 3×3", vec![s("grid"), "render.samples=3".into()]),
        "grid4" => ("real 4×4", vec![s("grid"), "render.samples=4".into()]),
        "prss" => ("prss", prss(&[])),
        // The paper's PRSS: straight lines to the 8 neighbours, 4×4
        // sub-points, the whole pixel on the centre's surface.
        "prss-paper" => (
            "prss (paper)",
            prss(&[
                "render.prss_map=bilinear",
                "render.prss_fallback=mirror",
                "render.prss_samples=4",
            ]),
        ),
        "prss-bilinear" => ("prss bilinear", prss(&["render.prss_map=bilinear"])),
        "prss-biquadratic" => ("prss biquadratic", prss(&["render.prss_map=biquadratic"])),
        "prss-4" => ("prss 4×4", prss(&["render.prss_samples=4"])),
        "prss-mirror" => ("prss mirror", prss(&["render.prss_fallback=mirror"])),
        "prss-nearest" => ("prss nearest", prss(&["render.prss_fallback=nearest"])),
        "prss-blend-trace" => (
            "prss blend-trace",
            prss(&["render.prss_fallback=blend-trace"]),
        ),
        "prss-trace" => ("prss trace", prss(&["render.prss_fallback=trace"])),
        "footprint" => ("footprint", vec![s("footprint")]),
        "footprint-ewa" => (
            "footprint ewa",
            vec![s("footprint"), "render.footprint=ewa".into()],
        ),
        other => unreachable!("no anti-aliasing preset '{other}'"),
    };
    (label.to_string(), o)
}

struct Scn {
    file: &'static str,
    label: &'static str,
}

const SPHERE: Scn = Scn {
    file: "sphere.toml",
    label: "sphere",
};
const CRANIUM: Scn = Scn {
    file: "cranium.toml",
    label: "cranium",
};
const LOBSTER: Scn = Scn {
    file: "lobster.toml",
    label: "lobster",
};
const TEAPOT: Scn = Scn {
    file: "teapot.toml",
    label: "teapot",
};
const SPHERE_F32: Scn = Scn {
    file: "sphere-f32.toml",
    label: "sphere-f32",
};
const BALL: Scn = Scn {
    file: "ball-two-holes.toml",
    label: "ball-two-holes",
};

/// The paper's four datasets (the cranium CT stands in for "cthead").
const PAPER_SCENES: [Scn; 4] = [SPHERE, CRANIUM, LOBSTER, TEAPOT];

/// An experiment from parts; overrides are concatenated in a fixed order
/// (size, filter, traversal, anti-aliasing, extra) so equal configurations
/// get equal keys.
fn exp(
    scene: &Scn,
    size: &[&str],
    filter_name: &str,
    trav: &str,
    aa: &str,
    extra: &[&str],
) -> Experiment {
    let (tl, to) = traversal(trav);
    let (al, ao) = antialias(aa);
    let mut overrides: Vec<String> = size.iter().map(|s| s.to_string()).collect();
    overrides.extend(filter(filter_name));
    overrides.extend(to);
    overrides.extend(ao);
    overrides.extend(extra.iter().map(|s| s.to_string()));
    let mut name = format!("{tl} {} {al}", filter_label(filter_name));
    for e in extra {
        name.push(' ');
        name.push_str(e.strip_prefix("render.").unwrap_or(e));
    }
    Experiment {
        scene: scene.file.into(),
        scene_label: scene.label.into(),
        label: name.clone(),
        name,
        overrides,
        baseline: None,
        max_repeats: if trav == "step" { Some(1) } else { None },
        skip_quality: false,
    }
}

impl Experiment {
    fn named(mut self, label: impl Into<String>) -> Experiment {
        self.label = label.into();
        self
    }
    fn vs(mut self, baseline: impl Into<String>) -> Experiment {
        self.baseline = Some(baseline.into());
        self
    }
    fn repeats_at_most(mut self, n: usize) -> Experiment {
        self.max_repeats = Some(n);
        self
    }
    fn called(mut self, name: impl Into<String>) -> Experiment {
        self.name = name.into();
        self
    }
    fn without_quality(mut self) -> Experiment {
        self.skip_quality = true;
        self
    }
}

fn render_table(
    id: &str,
    title: &str,
    note: &str,
    comparison: Comparison,
    image_quality: bool,
    experiments: Vec<Experiment>,
) -> Table {
    Table {
        id: id.into(),
        title: title.into(),
        note: note.into(),
        body: TableBody::Render(RenderTable {
            experiments,
            comparison,
            image_quality,
        }),
    }
}

fn classify_table(id: &str, title: &str, note: &str, rows: Vec<ClassifyRow>) -> Table {
    Table {
        id: id.into(),
        title: title.into(),
        note: note.into(),
        body: TableBody::Classify(ClassifyTable {
            rows,
            methods: vec![
                Method::Bmcc,
                Method::Accc,
                Method::AcccSub(2),
                Method::AcccSub(4),
                Method::AcccSub(8),
                Method::Bezier(2),
                Method::Exact,
            ],
        }),
    }
}

fn classify_row(scene: &Scn, filter_name: &str, extra: &[&str]) -> ClassifyRow {
    let mut overrides = filter(filter_name);
    overrides.extend(extra.iter().map(|s| s.to_string()));
    ClassifyRow {
        scene: scene.file.into(),
        scene_label: scene.label.into(),
        overrides,
    }
}

// ---------------------------------------------------------------------------
// Tables shared by several suites.

const TRAVERSAL_NOTE: &str = "Each acceleration on the u8 glass sphere with the cubic B-spline: \
fixed-step ray casting (the paper's baseline), the cell DDA with a bound per cell computed on \
the fly, the DDA over ACCC-tagged cells, the octree over ACCC or Bézier-hull tags, and \
the distance field's cubes reaching ahead of the ray (beyond the paper) over Bézier-hull tags. \
Error is against the analytic spheres; exact methods should not lose accuracy to step.";

fn traversal_table(size: &[&str]) -> Table {
    let rows = [
        "step",
        "dda",
        "dda+accc",
        "octree+accc",
        "octree+bezier",
        "distance+bezier",
    ]
    .iter()
    .map(|t| {
        let (l, _) = traversal(t);
        exp(&SPHERE, size, "bspline3", t, "none", &[])
            .named(l)
            .vs("step 0.1")
    })
    .collect();
    render_table(
        "traversal",
        "Traversal and classification (sphere, bspline3)",
        TRAVERSAL_NOTE,
        Comparison::Speedup,
        false,
        rows,
    )
}

fn filters_table(size: &[&str], filters: &[&str]) -> Table {
    let rows = filters
        .iter()
        .map(|f| exp(&SPHERE, size, f, "octree+bezier", "none", &[]).named(filter_label(f)))
        .collect();
    render_table(
        "filters",
        "Reconstruction filters (sphere, octree+bezier)",
        "Cost and accuracy of each filter on the quantised sphere: the smoothing spline \
removes the u8 rounding noise that the interpolating filters reproduce.",
        Comparison::Ratio,
        false,
        rows,
    )
}

const AA_NOTE: &str = "Anti-aliasing on octree+bezier: real N×N supersampling traces N² \
rays per pixel; PRSS and footprint filtering reuse the pixel-centre hit image. PSNR and SSIM \
are against a 16×16 grid-supersampled render of the same scene and filter; the hit error is \
the same for every row (anti-aliasing never changes the pixel-centre hits).";

fn antialias_table(id: &str, title: &str, filter_name: &str, modes: &[&str]) -> Table {
    antialias_scenes_table(id, title, &[(&SPHERE, filter_name)], modes)
}

/// Anti-aliasing rows for each `(scene, filter)`, compared with that scene's
/// `none` row.
fn antialias_scenes_table(id: &str, title: &str, scenes: &[(&Scn, &str)], modes: &[&str]) -> Table {
    let mut rows = Vec::new();
    for (scene, filter_name) in scenes {
        for m in modes {
            let (l, _) = antialias(m);
            let mut e = exp(scene, &SIDE_512, filter_name, "octree+bezier", m, &[])
                .named(l)
                .vs("none");
            // N² rays per pixel: one timed run keeps the suites in budget.
            if m.starts_with("grid") {
                e = e.repeats_at_most(1);
            }
            rows.push(e);
        }
    }
    render_table(id, title, AA_NOTE, Comparison::Ratio, true, rows)
}

fn sphere_classify_rows() -> Vec<ClassifyRow> {
    ["bspline2", "bspline3"]
        .iter()
        .map(|f| classify_row(&SPHERE, f, &[]))
        .collect()
}

const CLASSIFY_NOTE: &str = "Knot cells each method tags as possibly holding the iso-surface \
(fewer is better; every method is conservative). `exact` counts cells with a proven crossing, \
a lower bound of the truth; the error column checks that every method contains it.";

// ---------------------------------------------------------------------------
// The suites.

fn quick() -> Suite {
    Suite {
        name: "quick".into(),
        description: "The sphere at 512×512: traversal, filters, anti-aliasing and \
classification, in under three minutes."
            .into(),
        budget: "about 2–3 minutes".into(),
        tables: vec![
            traversal_table(&SIDE_512),
            filters_table(
                &SIDE_512,
                &[
                    "linear",
                    "catmull-rom",
                    "bspline2",
                    "bspline3",
                    "smooth-bspline3",
                ],
            ),
            antialias_table(
                "antialiasing",
                "Anti-aliasing (sphere, bspline3, octree+bezier)",
                "bspline3",
                &["none", "grid4", "prss", "footprint", "footprint-ewa"],
            ),
            classify_table(
                "classification",
                "Cell classification (sphere 64³, iso 127.5)",
                CLASSIFY_NOTE,
                sphere_classify_rows(),
            ),
        ],
    }
}

fn paper_tables() -> Vec<Table> {
    let mut tables = Vec::new();
    // Table 1.
    for (id, f) in [("table1-cr", "catmull-rom"), ("table1-b3", "bspline3")] {
        tables.push(antialias_table(
            id,
            &format!(
                "Table 1: anti-aliasing, sphere, {} (paper: step 0.1; here octree+bezier)",
                filter_label(f)
            ),
            f,
            &["none", "grid4", "prss", "footprint"],
        ));
    }
    // The quality the issue asks for, on the three checker scenes (each with
    // its scene file's filter).
    tables.push(antialias_scenes_table(
        "aa-quality",
        "Anti-aliasing quality: sphere, ball with two holes, teapot",
        &[
            (&SPHERE, "bspline3"),
            (&BALL, "bspline3"),
            (&TEAPOT, "smooth-bspline3"),
        ],
        &[
            "none",
            "grid3",
            "grid4",
            "prss",
            "prss-paper",
            "footprint",
            "footprint-ewa",
        ],
    ));
    // Table 2.
    let mut rows = Vec::new();
    for s in &PAPER_SCENES {
        for t in [
            "step",
            "dda+bmcc",
            "octree+bmcc",
            "dda+accc",
            "octree+accc",
            "octree+accc4",
            "octree+accc8",
            "octree+bezier",
            "distance+bezier",
        ] {
            let (l, _) = traversal(t);
            rows.push(
                exp(s, &SIDE_512, "bspline3", t, "none", &[])
                    .named(l)
                    .vs("step 0.1"),
            );
        }
    }
    tables.push(render_table(
        "table2",
        "Table 2: acceleration, bspline3 (paper Table 2, plus octree+accc4/accc8, octree+bezier and distance+bezier)",
        "Ray casting with step 0.1 against the DDA and the octree over BMCC and ACCC tags \
(the paper's columns; it also applied PRSS, which costs little), plus the octree over ACCC \
per 4³ and 8³ sub-cells (the refinement the paper proposes, with the sub-cells kept as 4³ masks \
the walk tests each segment against), over Bézier-hull tags, and the distance field's cubes reaching ahead of the ray over the Bézier-hull tags. Error: the sphere against its analytic spheres, the CT scenes against a \
dense march (step 0.02, tolerance 1e-9) through the same field.",
        Comparison::Speedup,
        false,
        rows,
    ));
    // Table 3.
    let mut rows = Vec::new();
    for s in &PAPER_SCENES {
        for f in ["bspline2", "bspline3"] {
            rows.push(classify_row(s, f, &[]));
        }
    }
    tables.push(classify_table(
        "table3",
        "Table 3: cells tagged, ACCC vs BMCC (and Bézier)",
        &format!(
            "{CLASSIFY_NOTE} The paper reports accc/bmcc; sphere at iso 127.5, the CT scenes \
at their scenes' iso-values."
        ),
        rows,
    ));
    // Table 4. The paper's DDA column is its DDA over ACCC tags (its Table 4
    // spline-3 times equal Table 2's DDA/ACCC ones), so that is the DDA here.
    let mut rows = Vec::new();
    for s in &PAPER_SCENES {
        for f in ["linear", "catmull-rom", "bspline2", "bspline3", "bspline6"] {
            let fl = filter_label(f);
            rows.push(exp(s, &SIDE_512, f, "dda+accc", "none", &[]).named(format!("dda {fl}")));
            rows.push(
                exp(s, &SIDE_512, f, "octree+bezier", "none", &[])
                    .named(format!("octree {fl}"))
                    .vs(format!("dda {fl}")),
            );
        }
    }
    tables.push(render_table(
        "table4",
        "Table 4: DDA vs octree per filter",
        "The DDA over ACCC tags (the paper's DDA) against the octree with the default \
classification (Bézier hull) for each filter; the last column is the time the octree saves. \
Catmull-Rom's negative lobes rule out the paper's ACCC; here it gets a signed-weight bound \
instead.",
        Comparison::Saving,
        false,
        rows,
    ));
    tables
}

/// Volume sides of the scaling suite (the 1024³ phantom's f64 coefficients
/// alone take 8.8 GB).
pub const SCALING_SIDES: [usize; 5] = [64, 128, 256, 512, 1024];
/// Image sides of the scaling suite.
pub const SCALING_IMAGES: [u32; 5] = [128, 256, 512, 1024, 2048];

/// Overrides that turn `sphere-f32.toml` (or `sphere.toml`) into the same
/// picture of an `n`³ phantom: radius, fringe, camera distance, backdrop
/// distance and checker scale with `n`, so every size shows the same object
/// sampled finer. The scaling suite uses the f32 phantom: u8 steps of 1/255
/// on a fringe `n/64` times wider tilt the normals `n/64` times more, which
/// would make the larger volumes noisier objects rather than finer samples.
pub fn scaled_sphere(n: usize) -> Vec<String> {
    let s = n as f64 / 64.0;
    let c = (n as f64 - 1.0) / 2.0;
    vec![
        format!("volume.phantom.size={n}"),
        format!("volume.phantom.radius={}", 20.0 * s),
        format!("volume.phantom.sigma={}", 3.0 * s),
        format!("camera.position=[{c}, {c}, {}]", c - 181.5 * s),
        format!("camera.look_at=[{c}, {c}, {c}]"),
        format!("backdrop.center=[{c}, {c}, {}]", c + 168.5 * s),
        format!("backdrop.checker={}", 8.0 * s),
    ]
}

/// The `n` of a scaled-sphere configuration (from its overrides).
pub fn phantom_side(overrides: &[String]) -> Option<usize> {
    overrides
        .iter()
        .find_map(|o| o.strip_prefix("volume.phantom.size="))
        .and_then(|v| v.parse().ok())
}

fn scaling() -> Suite {
    let config = "octree+bezier bspline3 prss";
    // The largest two also with f32 and f16 coefficients (half and a
    // quarter of their memory), each right after its f64 row so the cache
    // drops the f64 field first.
    let volume: Vec<Experiment> = SCALING_SIDES
        .iter()
        .flat_map(|&n| {
            let storages: &[&str] = if n >= 512 {
                &["f64", "f32", "f16"]
            } else {
                &["f64"]
            };
            storages.iter().map(move |&st| {
                let mut extra = scaled_sphere(n);
                let mut label = format!("{n}³");
                if st != "f64" {
                    extra.push(format!("render.coefficients={st}"));
                    label = format!("{n}³ {st}");
                }
                let extra: Vec<&str> = extra.iter().map(|s| s.as_str()).collect();
                exp(
                    &SPHERE_F32,
                    &SIDE_512,
                    "bspline3",
                    "octree+bezier",
                    "prss",
                    &extra,
                )
                .named(label.clone())
                .called(format!("{config}, sphere {label}"))
                .vs("64³")
                .without_quality()
            })
        })
        .collect();
    let image: Vec<Experiment> = SCALING_IMAGES
        .iter()
        .map(|&w| {
            let size = [format!("image.width={w}"), format!("image.height={w}")];
            let size: Vec<&str> = size.iter().map(|s| s.as_str()).collect();
            exp(&SPHERE_F32, &size, "bspline3", "octree+bezier", "prss", &[])
                .named(format!("{w}×{w}"))
                .called(format!("{config}, {w}×{w}"))
                .vs("128×128")
                .without_quality()
        })
        .collect();
    Suite {
        name: "scaling".into(),
        description: "Frame time against volume size (f32 sphere phantoms 64³ to 1024³ at \
512×512) and against image size (128² to 2048² at 64³): it should follow the surface area \
crossed, not the voxel count."
            .into(),
        budget: "about 12 minutes and 17 GB of memory for the 1024³ phantom (on a 24 GB \
machine set SNELL_MEMORY_LIMIT=22G: the default limit is 80% of what is free)"
            .into(),
        tables: vec![
            render_table(
                "scaling-volume",
                "Scaling with volume size (f32 sphere n³, 512×512, bspline3, octree+bezier, PRSS)",
                "The same picture of ever finer phantoms: radius, fringe, camera and backdrop \
scale with n. Time per frame with everything prepared; the preparation (prefilter, \
classification, octree) grows with the voxel count and is in the Preparation table. Ratio: \
frame time over the 64³ frame's; the voxel count grows 4096× from 64³ to 1024³, the surface \
area in cells 256×. Rows marked f32 and f16 store the coefficients in 4 and 2 bytes instead \
of 8 (`render.coefficients = \"f32\"`, `\"f16\"`): compare their peak memory and error with \
the f64 row.",
                Comparison::Ratio,
                false,
                volume,
            ),
            render_table(
                "scaling-image",
                "Scaling with image size (f32 sphere 64³, bspline3, octree+bezier, PRSS)",
                "Ratio: frame time over the 128×128 frame's; the pixel count grows 256× to \
2048×2048.",
                Comparison::Ratio,
                false,
                image,
            ),
        ],
    }
}

fn paper() -> Suite {
    Suite {
        name: "paper".into(),
        description: "The paper's Tables 1–4 at 512×512 on the sphere, cranium, lobster and \
teapot, with error columns, and anti-aliasing quality on the sphere, ball and teapot."
            .into(),
        // Measured: 22 min 13 s for the whole suite on the 2-core machine
        // (`snell bench --suite paper`, 2026-11-23, BENCHMARKS.md).
        budget: "about 25 minutes on 2 cores (22 min measured), most of it the fixed-step \
baselines and the dense-march ground truth of the CT scenes"
            .into(),
        tables: paper_tables(),
    }
}

fn full() -> Suite {
    let mut tables = paper_tables();
    tables.push(filters_table(&SIDE_512, &crate::filter::FILTER_NAMES));
    let leaves = [1, 2, 4, 8]
        .iter()
        .map(|l| {
            let leaf = format!("render.leaf={l}");
            exp(
                &SPHERE,
                &SIDE_512,
                "bspline3",
                "octree+bezier",
                "none",
                &[&leaf],
            )
            .named(format!("leaf {l}"))
            .vs("leaf 1")
        })
        .collect();
    tables.push(render_table(
        "leaf",
        "Octree leaf size (sphere, bspline3, octree+bezier)",
        "Octree leaves of 1–8 cells: smaller leaves skip more empty space; a step costs \
the same at any level (one byte of the flattened skip map).",
        Comparison::Ratio,
        false,
        leaves,
    ));
    tables.push(antialias_table(
        "prss-variants",
        "PRSS variants (sphere, bspline3, octree+bezier)",
        "bspline3",
        &[
            "none",
            "prss",
            "prss-paper",
            "prss-bilinear",
            "prss-biquadratic",
            "prss-4",
            "prss-mirror",
            "prss-nearest",
            "prss-blend-trace",
            "prss-trace",
            "footprint",
            "footprint-ewa",
        ],
    ));
    let step_aa = ["none", "grid4", "prss"]
        .iter()
        .map(|m| {
            let (l, _) = antialias(m);
            exp(&SPHERE, &SIDE_512, "smooth-bspline3", "step", m, &[])
                .named(format!("step 0.1 {l}"))
                .vs("step 0.1 none")
                .repeats_at_most(1)
        })
        .collect();
    tables.push(render_table(
        "table1-step",
        "Table 1 as in the paper: step 0.1, sphere, smooth-bspline3 λ=1",
        "The paper's setting for Table 1 (ray casting at step 0.1), where every ray is \
expensive and real supersampling multiplies that cost.",
        Comparison::Ratio,
        true,
        step_aa,
    ));
    Suite {
        name: "full".into(),
        description: "The paper suite plus every filter, octree leaf sizes, PRSS variants and \
Table 1 at the paper's step 0.1."
            .into(),
        budget: "the paper suite's 25 minutes plus the extra tables, about 45 minutes on 2 cores"
            .into(),
        tables,
    }
}

/// A few seconds: a 64×64 sphere in three configurations, for tests.
fn smoke() -> Suite {
    const SIDE_64: [&str; 2] = ["image.width=64", "image.height=64"];
    let trav = ["step", "octree+bezier"]
        .iter()
        .map(|t| {
            let (l, _) = traversal(t);
            exp(&SPHERE, &SIDE_64, "bspline3", t, "none", &[])
                .named(l)
                .vs("step 0.1")
        })
        .collect();
    let aa = ["none", "prss"]
        .iter()
        .map(|m| {
            let (l, _) = antialias(m);
            exp(&SPHERE, &SIDE_64, "bspline3", "octree+bezier", m, &[])
                .named(l)
                .vs("none")
        })
        .collect();
    let mut classify = classify_table(
        "classification",
        "Cell classification (sphere 64³)",
        CLASSIFY_NOTE,
        vec![classify_row(&SPHERE, "bspline3", &[])],
    );
    if let TableBody::Classify(c) = &mut classify.body {
        c.methods = vec![Method::Bmcc, Method::Accc, Method::Bezier(2)];
    }
    Suite {
        name: "smoke".into(),
        description: "A 64×64 sphere in three configurations (tests).".into(),
        budget: "a few seconds".into(),
        tables: vec![
            render_table(
                "traversal",
                "Traversal (sphere 64×64, bspline3)",
                TRAVERSAL_NOTE,
                Comparison::Speedup,
                false,
                trav,
            ),
            render_table(
                "antialiasing",
                "Anti-aliasing (sphere 64×64, bspline3)",
                "PRSS against none; PSNR/SSIM against a 16×16 grid render.",
                Comparison::Ratio,
                true,
                aa,
            ),
            classify,
        ],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_suite_is_well_formed() {
        for name in SUITES.iter().chain(&["smoke"]) {
            let s = Suite::by_name(name).unwrap();
            assert!(!s.tables.is_empty());
            for t in &s.tables {
                if let TableBody::Render(r) = &t.body {
                    let mut seen = std::collections::HashSet::new();
                    for e in &r.experiments {
                        assert!(
                            seen.insert((e.scene.clone(), e.label.clone())),
                            "{name}/{}: duplicate row {}",
                            t.id,
                            e.label
                        );
                        if let Some(b) = &e.baseline {
                            assert!(
                                r.experiments
                                    .iter()
                                    .any(|o| &o.label == b && o.scene == e.scene),
                                "{name}/{}: {} compares with missing row {b}",
                                t.id,
                                e.label
                            );
                        }
                    }
                }
            }
        }
        assert!(matches!(
            Suite::by_name("nope"),
            Err(BenchError::UnknownSuite(_))
        ));
    }

    /// At n = 64 the scaled overrides are `sphere.toml`'s own geometry, and
    /// at every n the picture is the same: the scene scales about the centre.
    #[test]
    fn scaled_sphere_is_the_same_picture() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let load = |set: &[String]| {
            crate::scene::Scene::load(&root.join("scenes/sphere.toml"), set).unwrap()
        };
        let base = load(&[]);
        let at64 = load(&scaled_sphere(64));
        let mut f32_set = scaled_sphere(64);
        f32_set.extend(SIDE_512.map(String::from));
        let f32_file =
            crate::scene::Scene::load(&root.join("scenes/sphere-f32.toml"), &f32_set).unwrap();
        assert_eq!(
            format!("{:?}", base.camera),
            format!("{:?}", f32_file.camera)
        );
        assert_eq!(format!("{:?}", base.camera), format!("{:?}", at64.camera));
        assert_eq!(
            format!("{:?}", base.backdrop),
            format!("{:?}", at64.backdrop)
        );
        assert_eq!(format!("{:?}", base.volume), format!("{:?}", at64.volume));
        let scaling = Suite::by_name("scaling").unwrap();
        assert!(
            scaling
                .experiments()
                .all(|(_, e)| e.scene == "sphere-f32.toml")
        );
        let big = load(&scaled_sphere(1024));
        assert_eq!(phantom_side(&scaled_sphere(1024)), Some(1024));
        assert_eq!(big.width, base.width);
        let (c, s) = (511.5, 16.0);
        let cam = format!("{:?}", big.camera);
        assert!(cam.contains(&format!("{:?}", c - 181.5 * s)), "{cam}");
    }

    #[test]
    fn shared_configurations_have_equal_keys() {
        // The quick suite's octree+bezier bspline3 row appears in three tables.
        let s = Suite::by_name("quick").unwrap();
        let mut keys: Vec<String> = s.experiments().map(|(_, e)| e.key()).collect();
        let n = keys.len();
        keys.sort();
        keys.dedup();
        assert_eq!(n - keys.len(), 2, "octree+bezier bspline3 none is shared");
    }
}
