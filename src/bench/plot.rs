//! Plots of a report, each as PNG and SVG: time against error with the Pareto
//! front, CPU time per stage, and (for the scaling suite) frame time against
//! volume and image size.
//!
//! Text in the PNGs is drawn with a DejaVu Sans subset compiled into the
//! binary (see `font/LICENSE.txt`), so plots look the same on every machine
//! and need no system fonts.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::coord::ranged1d::SegmentValue;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters::style::{FontStyle, register_font};

use super::BenchError;
use super::pareto;
use super::report::{fmt_ms, fmt_sig, fmt_tick};
use super::results::{Report, StageMs, TableResultBody};
use super::suite::phantom_side;

const FONT: &[u8] = include_bytes!("font/DejaVuSans-subset.ttf");
const FAMILY: &str = "sans-serif";

fn ensure_font() -> Result<(), String> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| register_font(FAMILY, FontStyle::Normal, FONT).is_ok());
    if ok {
        Ok(())
    } else {
        Err("the embedded font cannot be read".into())
    }
}

/// Above this many points, only the Pareto front is labelled (the rest would
/// be an unreadable pile of text; results.csv names every point).
const MAX_LABELLED_POINTS: usize = 30;

/// One configuration in the time-vs-error plot.
#[derive(Clone, Debug, PartialEq)]
pub struct Point {
    pub label: String,
    /// Points of one group (a scene) share a colour and a Pareto front:
    /// times of different scenes are not alternatives to each other.
    pub group: String,
    pub time_ms: f64,
    pub error: f64,
}

/// The time-vs-error points of a report (p90 refracted-pixel error).
pub fn time_vs_error_points(r: &Report) -> Vec<Point> {
    r.configurations
        .iter()
        .map(|c| Point {
            label: c.name.clone(),
            group: c.scene_label.clone(),
            time_ms: c.wall_ms.median,
            error: c.error.p90,
        })
        .collect()
}

/// One stacked bar of the stages plot.
#[derive(Clone, Debug, PartialEq)]
pub struct Bar {
    pub label: String,
    pub stages_ms: [f64; 8],
}

pub fn stage_bars(r: &Report) -> Vec<Bar> {
    r.configurations
        .iter()
        .map(|c| Bar {
            label: format!("{}: {}", c.scene_label, c.name),
            stages_ms: c.stage_cpu_ms.values(),
        })
        .collect()
}

fn err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// Distinct colours for groups (scenes).
const GROUP_COLORS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

/// One colour per stage, in pipeline order.
const STAGE_COLORS: [RGBColor; 8] = [
    RGBColor(166, 206, 227), // generate
    RGBColor(31, 120, 180),  // entry
    RGBColor(178, 223, 138), // traverse
    RGBColor(51, 160, 44),   // solve
    RGBColor(251, 154, 153), // refract
    RGBColor(227, 26, 28),   // record
    RGBColor(253, 191, 111), // prss
    RGBColor(255, 127, 0),   // film
];

/// A log-axis range covering `values` (positive, finite) with some margin.
fn log_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, 0.0f64), |(l, h), v| (l.min(v), h.max(v)));
    if !(lo.is_finite() && hi > 0.0) {
        return (0.1, 10.0);
    }
    let (lo, hi) = if hi / lo < 1.5 {
        (lo / 1.5, hi * 1.5)
    } else {
        (lo, hi)
    };
    (lo / 1.6, hi * 1.6)
}

fn draw_time_vs_error<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    points: &[Point],
) -> Result<(), String> {
    area.fill(&WHITE).map_err(err)?;
    // Errors of exactly zero cannot sit on a log axis: they go to a floor a
    // decade below the smallest positive error, and the axis says so.
    let min_pos = points
        .iter()
        .map(|p| p.error)
        .filter(|e| *e > 0.0 && e.is_finite())
        .fold(f64::INFINITY, f64::min);
    let floor = if min_pos.is_finite() {
        min_pos / 10.0
    } else {
        1e-6
    };
    let shown: Vec<Point> = points
        .iter()
        .filter(|p| p.time_ms > 0.0 && p.time_ms.is_finite() && !p.error.is_nan())
        .map(|p| Point {
            error: if p.error > 0.0 { p.error } else { floor },
            ..p.clone()
        })
        .collect();
    let has_zero = points.iter().any(|p| p.error == 0.0);
    let (x0, x1) = log_range(shown.iter().map(|p| p.time_ms));
    let (y0, y1) = log_range(shown.iter().map(|p| p.error).filter(|e| e.is_finite()));

    let mut chart = ChartBuilder::on(area)
        .caption(title, (FAMILY, 22))
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
        .map_err(err)?;
    let y_desc = if has_zero {
        format!(
            "refracted-pixel p90 hit error (checker squares; 0 drawn at {})",
            fmt_sig(floor)
        )
    } else {
        "refracted-pixel p90 hit error (checker squares)".to_string()
    };
    chart
        .configure_mesh()
        .x_desc("median wall time (ms)")
        .y_desc(y_desc)
        .label_style((FAMILY, 14))
        .axis_desc_style((FAMILY, 16))
        .x_labels(8)
        .y_labels(8)
        .x_label_formatter(&|v| fmt_tick(*v))
        .y_label_formatter(&|v| fmt_tick(*v))
        .light_line_style(BLACK.mix(0.04))
        .bold_line_style(BLACK.mix(0.12))
        .draw()
        .map_err(err)?;

    let mut groups: Vec<&str> = Vec::new();
    for p in &shown {
        if !groups.contains(&p.group.as_str()) {
            groups.push(&p.group);
        }
    }
    let label_all = shown.len() <= MAX_LABELLED_POINTS;
    for (gi, g) in groups.iter().enumerate() {
        let color = GROUP_COLORS[gi % GROUP_COLORS.len()];
        let members: Vec<&Point> = shown.iter().filter(|p| p.group == *g).collect();
        let coords: Vec<(f64, f64)> = members.iter().map(|p| (p.time_ms, p.error)).collect();
        let front = pareto::front(&coords);
        chart
            .draw_series(LineSeries::new(
                front.iter().map(|&i| coords[i]),
                color.stroke_width(2),
            ))
            .map_err(err)?;
        chart
            .draw_series(
                front
                    .iter()
                    .map(|&i| Circle::new(coords[i], 9, color.stroke_width(2))),
            )
            .map_err(err)?;
        chart
            .draw_series(coords.iter().map(|&c| Circle::new(c, 4, color.filled())))
            .map_err(err)?
            .label(*g)
            .legend(move |(x, y)| Circle::new((x, y), 4, color.filled()));
    }
    // Labels, placed in pixel space so they do not overprint each other.
    let font = (FAMILY, 12).into_font().into_text_style(area);
    let mut labelled: Vec<(&Point, (i32, i32))> = Vec::new();
    for g in &groups {
        let members: Vec<&Point> = shown.iter().filter(|p| p.group == *g).collect();
        let coords: Vec<(f64, f64)> = members.iter().map(|p| (p.time_ms, p.error)).collect();
        let front = pareto::front(&coords);
        for (i, p) in members.iter().enumerate() {
            if label_all || front.contains(&i) {
                labelled.push((p, chart.backend_coord(&(p.time_ms, p.error))));
            }
        }
    }
    let sizes: Vec<(i32, i32)> = labelled
        .iter()
        .map(|(p, _)| {
            area.estimate_text_size(&p.label, &font)
                .map(|(w, h)| (w as i32, h as i32))
                .map_err(err)
        })
        .collect::<Result<_, _>>()?;
    let markers: Vec<(i32, i32)> = shown
        .iter()
        .map(|p| chart.backend_coord(&(p.time_ms, p.error)))
        .collect();
    let (xr, yr) = chart.plotting_area().get_pixel_range();
    let anchors: Vec<(i32, i32)> = labelled.iter().map(|(_, a)| *a).collect();
    let spots = place_labels(
        &anchors,
        &sizes,
        &markers,
        ((xr.start, yr.start), (xr.end, yr.end)),
    );
    for (((p, anchor), at), (w, h)) in labelled.iter().zip(spots).zip(&sizes) {
        // A leader from the point to its label's nearest edge: a label
        // pushed aside by others can sit nearer another point than its own.
        let edge = (
            anchor.0.clamp(at.0, at.0 + w),
            anchor.1.clamp(at.1, at.1 + h),
        );
        area.draw(&PathElement::new(
            vec![*anchor, edge],
            BLACK.mix(0.35).stroke_width(1),
        ))
        .map_err(err)?;
        area.draw(&Text::new(p.label.clone(), at, font.clone()))
            .map_err(err)?;
    }
    chart
        .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
        .map_err(err)?
        .label("Pareto front (ringed, connected)")
        .legend(|(x, y)| Circle::new((x, y), 6, BLACK.stroke_width(2)));
    chart
        .configure_series_labels()
        .label_font((FAMILY, 14))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.4))
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(err)?;
    area.present().map_err(err)?;
    Ok(())
}

/// Top-left corners for labels of size `sizes` beside points at `anchors`
/// (pixels), avoiding each other and the point `markers` where possible:
/// candidates right and left of the point, stepping away vertically; a label
/// that fits nowhere takes its first candidate (overprinting beats vanishing).
pub fn place_labels(
    anchors: &[(i32, i32)],
    sizes: &[(i32, i32)],
    markers: &[(i32, i32)],
    bounds: ((i32, i32), (i32, i32)),
) -> Vec<(i32, i32)> {
    type Rect = (i32, i32, i32, i32);
    let overlaps = |a: &Rect, b: &Rect| a.0 < b.2 && b.0 < a.2 && a.1 < b.3 && b.1 < a.3;
    let ((bx0, by0), (bx1, by1)) = bounds;
    let mut taken: Vec<Rect> = markers
        .iter()
        .map(|&(x, y)| (x - 5, y - 5, x + 5, y + 5))
        .collect();
    let mut order: Vec<usize> = (0..anchors.len()).collect();
    order.sort_by_key(|&i| (anchors[i].0, anchors[i].1));
    let mut out = vec![(0, 0); anchors.len()];
    for i in order {
        let ((x, y), (w, h)) = (anchors[i], sizes[i]);
        let mut candidates = Vec::new();
        for level in 0..8 {
            let step = level * (h + 2);
            for dy in [-h - 4 - step, 4 + step] {
                candidates.push((x + 9, y + dy));
                candidates.push((x - 9 - w, y + dy));
            }
        }
        let fits = |&(cx, cy): &(i32, i32)| {
            let r = (cx, cy, cx + w, cy + h);
            cx >= bx0
                && cy >= by0
                && cx + w <= bx1
                && cy + h <= by1
                && !taken.iter().any(|t| overlaps(t, &r))
        };
        let at = candidates
            .iter()
            .copied()
            .find(|c| fits(c))
            .unwrap_or(candidates[0]);
        taken.push((at.0, at.1, at.0 + w, at.1 + h));
        out[i] = at;
    }
    out
}

/// Width of the legend strip right of the stages chart.
const STAGE_LEGEND_WIDTH: u32 = 150;

fn draw_stages<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    bars: &[Bar],
) -> Result<(), String> {
    area.fill(&WHITE).map_err(err)?;
    let (w, _) = area.dim_in_pixel();
    let (main, legend) = area.split_horizontally(w.saturating_sub(STAGE_LEGEND_WIDTH));
    let n = bars.len().max(1);
    let max_total = bars
        .iter()
        .map(|b| b.stages_ms.iter().sum::<f64>())
        .fold(0.0f64, f64::max)
        .max(1e-3);
    let label_chars = bars
        .iter()
        .map(|b| b.label.chars().count())
        .max()
        .unwrap_or(10);
    // Segment i holds bar n-1-i, so the first configuration is at the top.
    let label_of = |v: &SegmentValue<usize>| match v {
        SegmentValue::CenterOf(i) if *i < n => bars
            .get(n - 1 - *i)
            .map(|b| b.label.clone())
            .unwrap_or_default(),
        _ => String::new(),
    };
    let mut chart = ChartBuilder::on(&main)
        .caption(title, (FAMILY, 22))
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size((label_chars as u32 * 7 + 20).min(560))
        // A discrete range includes its end: n segments are 0..=n-1.
        .build_cartesian_2d(0.0..max_total * 1.12, (0..n - 1).into_segmented())
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("CPU time in the median run (ms, summed over threads)")
        .label_style((FAMILY, 13))
        .axis_desc_style((FAMILY, 16))
        .y_labels(n)
        .y_label_formatter(&label_of)
        .x_label_formatter(&|v| fmt_tick(*v))
        .disable_y_mesh()
        .light_line_style(WHITE.mix(0.0))
        .bold_line_style(BLACK.mix(0.12))
        .draw()
        .map_err(err)?;
    for (si, color) in STAGE_COLORS.iter().enumerate() {
        let rects = bars.iter().enumerate().map(move |(bi, b)| {
            let x0: f64 = b.stages_ms[..si].iter().sum();
            let x1 = x0 + b.stages_ms[si];
            let seg = n - 1 - bi;
            let mut r = Rectangle::new(
                [
                    (x0, SegmentValue::Exact(seg)),
                    (x1, SegmentValue::Exact(seg + 1)),
                ],
                color.filled(),
            );
            r.set_margin(3, 3, 0, 0);
            r
        });
        chart.draw_series(rects).map_err(err)?;
    }
    // Totals at the bar ends keep short bars readable beside long ones.
    chart
        .draw_series(bars.iter().enumerate().map(|(bi, b)| {
            let total: f64 = b.stages_ms.iter().sum();
            EmptyElement::at((total, SegmentValue::CenterOf(n - 1 - bi)))
                + Text::new(
                    format!("{} ms", fmt_ms(total)),
                    (6, 0),
                    (FAMILY, 12)
                        .into_font()
                        .into_text_style(&main)
                        .pos(Pos::new(HPos::Left, VPos::Center)),
                )
        }))
        .map_err(err)?;
    // The legend in its own strip: inside the chart it would cover bars.
    for (si, name) in StageMs::NAMES.iter().enumerate() {
        let y = 60 + 24 * si as i32;
        legend
            .draw(&Rectangle::new(
                [(10, y), (26, y + 14)],
                STAGE_COLORS[si].filled(),
            ))
            .map_err(err)?;
        legend
            .draw(&Text::new(
                *name,
                (34, y + 7),
                (FAMILY, 14)
                    .into_font()
                    .into_text_style(&legend)
                    .pos(Pos::new(HPos::Left, VPos::Center)),
            ))
            .map_err(err)?;
    }
    area.present().map_err(err)?;
    Ok(())
}

/// One panel of the scaling plot: frame time against a size.
#[derive(Clone, Debug, PartialEq)]
pub struct Scaling {
    pub title: String,
    pub x_desc: String,
    /// `(size, median frame ms)`, sizes increasing.
    pub points: Vec<(f64, f64)>,
    /// Reference growth laws `(label, exponent)`, drawn through the first point.
    pub laws: Vec<(String, f64)>,
}

/// The scaling panels of a report: `scaling-volume` against the phantom's
/// side, `scaling-image` against the image's side (empty for other suites).
pub fn scaling_panels(r: &Report) -> Vec<Scaling> {
    let mut out = Vec::new();
    for t in &r.tables {
        let TableResultBody::Render { rows, .. } = &t.body else {
            continue;
        };
        let size = |c: usize| -> Option<f64> {
            let c = &r.configurations[c];
            match t.id.as_str() {
                // One curve: the default f64 storage (the f32 rows sit at
                // the same sizes and are read from the table).
                "scaling-volume"
                    if c.overrides
                        .iter()
                        .any(|o| o.starts_with("render.coefficients=")) =>
                {
                    None
                }
                "scaling-volume" => phantom_side(&c.overrides).map(|n| n as f64),
                "scaling-image" => Some(c.settings.width as f64),
                _ => None,
            }
        };
        let mut points: Vec<(f64, f64)> = rows
            .iter()
            .filter_map(|row| {
                Some((
                    size(row.config)?,
                    r.configurations[row.config].wall_ms.median,
                ))
            })
            .filter(|&(x, y)| x > 0.0 && y > 0.0 && y.is_finite())
            .collect();
        if points.is_empty() {
            continue;
        }
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (x_desc, laws) = if t.id == "scaling-volume" {
            (
                "phantom side n (voxels; image fixed)",
                vec![
                    ("∝ n³ (voxel count)".to_string(), 3.0),
                    ("∝ n² (surface cells)".to_string(), 2.0),
                ],
            )
        } else {
            (
                "image side (pixels; volume fixed)",
                vec![("∝ side² (pixel count)".to_string(), 2.0)],
            )
        };
        out.push(Scaling {
            title: t.title.clone(),
            x_desc: x_desc.into(),
            points,
            laws,
        });
    }
    out
}

/// A log-axis tick label only at 1, 2 and 5 times a power of ten: the sizes
/// axis spans decades, and labelling every sub-tick (600 700 800 900 1000)
/// makes the labels run into each other.
fn sparse_tick(v: f64) -> String {
    let m = v / 10f64.powf(v.log10().floor());
    if [1.0, 2.0, 5.0].iter().any(|k| (m - k).abs() < 1e-6) {
        fmt_tick(v)
    } else {
        String::new()
    }
}

fn draw_scaling<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    panels: &[Scaling],
) -> Result<(), String> {
    area.fill(&WHITE).map_err(err)?;
    let area = area.titled(title, (FAMILY, 22)).map_err(err)?;
    let cells = area.split_evenly((1, panels.len().max(1)));
    for (panel, cell) in panels.iter().zip(&cells) {
        let (x0, x1) = log_range(panel.points.iter().map(|p| p.0));
        let (y0, y1) = log_range(panel.points.iter().map(|p| p.1));
        // Out to whole decades: a range inside one decade gets no labelled
        // tick on a log axis.
        let (y0, y1) = (
            y0.min(10f64.powf(y0.log10().floor())),
            y1.max(10f64.powf(y1.log10().ceil())),
        );
        let mut chart = ChartBuilder::on(cell)
            .caption(&panel.title, (FAMILY, 15))
            .margin(20)
            .x_label_area_size(50)
            .y_label_area_size(70)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc(panel.x_desc.as_str())
            .y_desc("median frame time (ms)")
            .label_style((FAMILY, 14))
            .axis_desc_style((FAMILY, 15))
            .x_label_formatter(&|v| sparse_tick(*v))
            .y_label_formatter(&|v| fmt_tick(*v))
            .light_line_style(BLACK.mix(0.04))
            .bold_line_style(BLACK.mix(0.12))
            .draw()
            .map_err(err)?;
        let (bx, by) = panel.points[0];
        for (i, (label, k)) in panel.laws.iter().enumerate() {
            let color = GROUP_COLORS[(i + 1) % GROUP_COLORS.len()];
            // Only the part of the law inside the chart (it rises steeply).
            let law: Vec<(f64, f64)> = (0..=64)
                .map(|j| x0 * (x1 / x0).powf(j as f64 / 64.0))
                .map(|x| (x, by * (x / bx).powf(*k)))
                .filter(|&(_, y)| y >= y0 && y <= y1)
                .collect();
            chart
                .draw_series(LineSeries::new(law, color.mix(0.7).stroke_width(2)))
                .map_err(err)?
                .label(label.as_str())
                .legend(move |(x, y)| PathElement::new([(x - 10, y), (x + 10, y)], color));
        }
        let color = GROUP_COLORS[0];
        chart
            .draw_series(LineSeries::new(
                panel.points.iter().copied(),
                color.stroke_width(3),
            ))
            .map_err(err)?
            .label("measured")
            .legend(move |(x, y)| Circle::new((x, y), 4, color.filled()));
        chart
            .draw_series(
                panel
                    .points
                    .iter()
                    .map(|&p| Circle::new(p, 5, color.filled())),
            )
            .map_err(err)?;
        chart
            .draw_series(panel.points.iter().map(|&(x, y)| {
                Text::new(
                    format!("{} ms", fmt_ms(y)),
                    (x, y),
                    (FAMILY, 13).into_font(),
                )
            }))
            .map_err(err)?;
        chart
            .configure_series_labels()
            .label_font((FAMILY, 14))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.4))
            .position(SeriesLabelPosition::UpperLeft)
            .draw()
            .map_err(err)?;
    }
    area.present().map_err(err)?;
    Ok(())
}

/// Draws into a PNG (RGB buffer, encoded like the renderer's images).
fn write_png(
    path: &Path,
    size: (u32, u32),
    draw: impl FnOnce(&DrawingArea<BitMapBackend, Shift>) -> Result<(), String>,
) -> Result<(), BenchError> {
    let plot_err = |msg: String| BenchError::Plot {
        path: path.to_path_buf(),
        msg,
    };
    ensure_font().map_err(plot_err)?;
    let mut buf = vec![0u8; size.0 as usize * size.1 as usize * 3];
    {
        let area = BitMapBackend::with_buffer(&mut buf, size).into_drawing_area();
        draw(&area).map_err(plot_err)?;
    }
    crate::film::write_png_rgb(path, size.0, size.1, &buf).map_err(|e| BenchError::Plot {
        path: path.to_path_buf(),
        msg: e.to_string(),
    })
}

/// Draws into an SVG file.
fn write_svg(
    path: &Path,
    size: (u32, u32),
    draw: impl FnOnce(&DrawingArea<SVGBackend, Shift>) -> Result<(), String>,
) -> Result<(), BenchError> {
    let plot_err = |msg: String| BenchError::Plot {
        path: path.to_path_buf(),
        msg,
    };
    ensure_font().map_err(plot_err)?;
    let mut svg = String::new();
    {
        let area = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        draw(&area).map_err(plot_err)?;
    }
    crate::atomic::write_atomic(path, |w| std::io::Write::write_all(w, svg.as_bytes())).map_err(
        |source| BenchError::Io {
            path: path.to_path_buf(),
            source,
        },
    )
}

/// Writes `time_vs_error.{png,svg}`, `stages.{png,svg}` and, for the
/// scaling suite, `scaling.{png,svg}` into `dir`.
pub fn write_plots(r: &Report, dir: &Path) -> Result<Vec<PathBuf>, BenchError> {
    let mut written = Vec::new();
    let points = time_vs_error_points(r);
    let title = format!(
        "snell bench {}: time vs error ({} threads)",
        r.suite, r.run.threads
    );
    let size = (1400, 900);
    let p = dir.join("time_vs_error.png");
    write_png(&p, size, |a| draw_time_vs_error(a, &title, &points))?;
    written.push(p);
    let p = dir.join("time_vs_error.svg");
    write_svg(&p, size, |a| draw_time_vs_error(a, &title, &points))?;
    written.push(p);

    let bars = stage_bars(r);
    let title = format!("snell bench {}: CPU time per stage", r.suite);
    let size = (1400, (160 + 26 * bars.len().max(1) as u32).max(300));
    let p = dir.join("stages.png");
    write_png(&p, size, |a| draw_stages(a, &title, &bars))?;
    written.push(p);
    let p = dir.join("stages.svg");
    write_svg(&p, size, |a| draw_stages(a, &title, &bars))?;
    written.push(p);

    let panels = scaling_panels(r);
    if !panels.is_empty() {
        let title = format!(
            "snell bench {}: frame time against size ({} threads)",
            r.suite, r.run.threads
        );
        let size = (700 * panels.len() as u32, 600);
        let p = dir.join("scaling.png");
        write_png(&p, size, |a| draw_scaling(a, &title, &panels))?;
        written.push(p);
        let p = dir.join("scaling.svg");
        write_svg(&p, size, |a| draw_scaling(a, &title, &panels))?;
        written.push(p);
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_both_plots_in_both_formats() {
        let dir = std::env::temp_dir().join(format!("snell-plot-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let r = crate::bench::results::sample_report();
        let written = write_plots(&r, &dir).unwrap();
        assert_eq!(written.len(), 4);
        for p in &written {
            let bytes = std::fs::read(p).unwrap();
            match p.extension().and_then(|e| e.to_str()) {
                Some("png") => assert!(bytes.starts_with(b"\x89PNG"), "{}", p.display()),
                Some("svg") => {
                    let text = String::from_utf8(bytes).unwrap();
                    assert!(text.contains("<svg"), "{}", p.display());
                    // Labels are there: configuration names and stage names.
                    assert!(text.contains("sphere"), "{}", p.display());
                }
                _ => panic!("unexpected file {}", p.display()),
            }
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn points_and_bars_come_from_every_configuration() {
        let r = crate::bench::results::sample_report();
        let pts = time_vs_error_points(&r);
        assert_eq!(pts.len(), 3);
        assert_eq!(pts[1].time_ms, 12.0);
        assert_eq!(pts[1].error, 1.3);
        let bars = stage_bars(&r);
        assert_eq!(bars[0].stages_ms[2], 300.0, "traverse");
        assert_eq!(log_range([1.0, 100.0].into_iter()), (1.0 / 1.6, 160.0));
    }

    #[test]
    fn scaling_suite_gets_its_plot() {
        let mut r = crate::bench::results::sample_report();
        assert!(scaling_panels(&r).is_empty());
        for (i, c) in r.configurations.iter_mut().enumerate() {
            c.overrides.push(format!("volume.phantom.size={}", 64 << i));
        }
        r.tables[0].id = "scaling-volume".into();
        let panels = scaling_panels(&r);
        assert_eq!(panels.len(), 1);
        let xs: Vec<f64> = panels[0].points.iter().map(|p| p.0).collect();
        assert!(
            xs.windows(2).all(|w| w[0] < w[1]) && xs[0] >= 64.0,
            "{xs:?}"
        );
        let dir = std::env::temp_dir().join(format!("snell-scaling-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let written = write_plots(&r, &dir).unwrap();
        assert_eq!(written.len(), 6);
        let svg = std::fs::read_to_string(dir.join("scaling.svg")).unwrap();
        assert!(svg.contains("voxel count") && svg.contains("measured"));
        assert_eq!(sparse_tick(700.0), "");
        assert_eq!(sparse_tick(200.0), fmt_tick(200.0));
        assert_eq!(sparse_tick(1000.0), fmt_tick(1000.0));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn labels_avoid_each_other() {
        // Three points on one row, close together: labels must not overlap.
        let anchors = [(100, 100), (110, 100), (120, 100)];
        let sizes = [(80, 12); 3];
        let spots = place_labels(&anchors, &sizes, &anchors, ((0, 0), (1000, 1000)));
        for i in 0..3 {
            for j in i + 1..3 {
                let (a, b) = (spots[i], spots[j]);
                let disjoint =
                    a.0 + 80 <= b.0 || b.0 + 80 <= a.0 || a.1 + 12 <= b.1 || b.1 + 12 <= a.1;
                assert!(disjoint, "{a:?} {b:?}");
            }
        }
        // A label never leaves the bounds when it can stay inside.
        let spot = place_labels(&[(990, 500)], &[(80, 12)], &[], ((0, 0), (1000, 1000)))[0];
        assert!(spot.0 + 80 <= 1000 && spot.0 >= 0);
    }
}
