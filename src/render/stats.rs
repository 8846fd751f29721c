//! Work counters and per-stage times: the profile users read after a render.
//!
//! Counters are integers summed over tiles, so they are identical for any
//! thread count; stage times are each thread's wall-clock time in the
//! stage, summed over threads (`stage_cpu_s`, "thread ms"): the stage's CPU
//! time while the threads run undisturbed, more on a loaded machine, where
//! a thread waiting for a core is still counted.

use std::time::Duration;

use serde::Serialize;

/// The pipeline's stages, in order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    Generate = 0,
    Entry = 1,
    Traverse = 2,
    Solve = 3,
    Refract = 4,
    Record = 5,
    /// Anti-aliasing from the hit-position image (PRSS, footprint).
    Prss = 6,
    Film = 7,
}

pub const STAGES: [Stage; 8] = [
    Stage::Generate,
    Stage::Entry,
    Stage::Traverse,
    Stage::Solve,
    Stage::Refract,
    Stage::Record,
    Stage::Prss,
    Stage::Film,
];

impl Stage {
    pub fn name(self) -> &'static str {
        match self {
            Stage::Generate => "generate",
            Stage::Entry => "entry",
            Stage::Traverse => "traverse",
            Stage::Solve => "solve",
            Stage::Refract => "refract",
            Stage::Record => "record",
            Stage::Prss => "prss",
            Stage::Film => "film",
        }
    }
}

/// Counters of the work a render did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Counters {
    /// Rays traced (primary rays, all samples).
    pub rays: u64,
    /// Rays whose path entered the volume's bounds.
    pub rays_entering: u64,
    /// Cells (or octree nodes) the traversal examined.
    pub cells_visited: u64,
    /// Tagged cells passed without a solve: the box of sub-cells the ray's
    /// segment spans holds none of their tagged sub-cells
    /// ([`crate::classify::bezier::SubCells`]), or the cell's plane proves
    /// the segment clear of the surface ([`crate::classify::plane`]).
    pub subcell_skips: u64,
    /// Cells passed without a solve right after a crossing — the rest of the
    /// one the new piece starts in and the crossing cell's neighbours after
    /// it, tagged or not — where the curvature bound proves them empty
    /// ([`crate::classify::curvature`]).
    pub cells_cleared: u64,
    /// Cells whose crossing problem was solved (restriction built and isolated).
    pub cells_solved: u64,
    /// Solved cells that held the crossing the ray took.
    pub cells_with_crossing: u64,
    /// Point evaluations of the field (value or value+gradient).
    pub kernel_evals: u64,
    /// Root-refinement evaluations over all solves: the lane-parallel Newton
    /// of single crossings, Brent after subdivision, Brent on step brackets
    /// (the name predates the Newton refinement; kept for the stats files).
    pub brent_iters: u64,
    /// Bernstein intervals examined during isolation.
    pub isolation_intervals: u64,
    /// Refractions.
    pub refractions: u64,
    /// Total internal reflections.
    pub reflections: u64,
    /// Crossings where the gradient vanished (ray continued straight).
    pub degenerate_normals: u64,
    /// Rays stopped by `max_events` (no backdrop hit).
    pub terminated: u64,
    /// Rays that left towards no backdrop (parallel or pointing away).
    pub missed_backdrop: u64,
    /// Rays that ended in an undefined state (NaN or infinite values). Must be 0.
    pub undefined: u64,
}

impl Counters {
    pub fn add(&mut self, o: &Counters) {
        self.rays += o.rays;
        self.rays_entering += o.rays_entering;
        self.cells_visited += o.cells_visited;
        self.subcell_skips += o.subcell_skips;
        self.cells_cleared += o.cells_cleared;
        self.cells_solved += o.cells_solved;
        self.cells_with_crossing += o.cells_with_crossing;
        self.kernel_evals += o.kernel_evals;
        self.brent_iters += o.brent_iters;
        self.isolation_intervals += o.isolation_intervals;
        self.refractions += o.refractions;
        self.reflections += o.reflections;
        self.degenerate_normals += o.degenerate_normals;
        self.terminated += o.terminated;
        self.missed_backdrop += o.missed_backdrop;
        self.undefined += o.undefined;
    }
}

/// Time spent per stage.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StageTimes(pub [Duration; 8]);

impl StageTimes {
    #[inline]
    pub fn add(&mut self, stage: Stage, d: Duration) {
        self.0[stage as usize] += d;
    }
    pub fn merge(&mut self, o: &StageTimes) {
        for (a, b) in self.0.iter_mut().zip(o.0.iter()) {
            *a += *b;
        }
    }
    pub fn get(&self, stage: Stage) -> Duration {
        self.0[stage as usize]
    }
    pub fn total(&self) -> Duration {
        self.0.iter().sum()
    }
}

/// Everything measured about one render.
#[derive(Clone, Debug, Default)]
pub struct RenderStats {
    pub counters: Counters,
    pub stage_times: StageTimes,
    /// Wall time of the tile loop.
    pub wall: Duration,
    /// One-time preparation (prefilter, classification, octree), if done now.
    pub prepare: PrepareTimes,
    pub threads: usize,
    pub width: u32,
    pub height: u32,
    /// The part of the `width × height` frame rendered (`render --region`):
    /// `[x0, y0, x1, y1]`, exclusive ends; `None` for the whole frame.
    pub region: Option<[u32; 4]>,
    /// What the anti-aliasing stage did (PRSS, footprint).
    pub post: Option<crate::film::prss::PostStats>,
    /// Rays traced in the adaptive second pass (PRSS fallback `trace`).
    pub retraced_pixels: u64,
}

/// Build times of the structures a scene needs (zero when cached).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct PrepareTimes {
    pub load_s: f64,
    pub prefilter_s: f64,
    pub classify_s: f64,
    pub octree_s: f64,
}

impl RenderStats {
    /// A JSON object with every counter, per-ray ratios and stage times.
    pub fn to_json(&self) -> serde_json::Value {
        let c = &self.counters;
        let rays = c.rays.max(1) as f64;
        let mut stages = serde_json::Map::new();
        for s in STAGES {
            stages.insert(
                s.name().into(),
                serde_json::json!(self.stage_times.get(s).as_secs_f64()),
            );
        }
        serde_json::json!({
            "width": self.width,
            "height": self.height,
            "region": self.region,
            "threads": self.threads,
            // The kernels' instruction set (`SNELL_ISA` may lower it).
            "isa": crate::simd::Isa::current().name(),
            "wall_s": self.wall.as_secs_f64(),
            "rays_per_s": c.rays as f64 / self.wall.as_secs_f64().max(1e-12),
            "counters": c,
            "per_ray": {
                "cells_visited": c.cells_visited as f64 / rays,
                "cells_solved": c.cells_solved as f64 / rays,
                "kernel_evals": c.kernel_evals as f64 / rays,
                "brent_iters": c.brent_iters as f64 / rays,
            },
            "solve_efficiency": c.cells_with_crossing as f64 / c.cells_solved.max(1) as f64,
            "stage_cpu_s": stages,
            "prepare": self.prepare,
            "post": self.post,
            "retraced_pixels": self.retraced_pixels,
        })
    }

    /// A short human-readable table.
    pub fn table(&self) -> String {
        let c = &self.counters;
        let rays = c.rays.max(1) as f64;
        let total = self.stage_times.total().as_secs_f64().max(1e-12);
        let mut s = String::new();
        let size = match self.region {
            None => format!("{}x{}", self.width, self.height),
            Some([x0, y0, x1, y1]) => format!(
                "{}x{} region {x0},{y0},{x1},{y1} of {}x{}",
                x1 - x0,
                y1 - y0,
                self.width,
                self.height
            ),
        };
        s.push_str(&format!(
            "{size} in {:.1} ms wall ({} threads), {:.2} Mrays/s\n",
            self.wall.as_secs_f64() * 1e3,
            self.threads,
            c.rays as f64 / self.wall.as_secs_f64().max(1e-12) / 1e6
        ));
        let p = &self.prepare;
        if p.load_s + p.prefilter_s + p.classify_s + p.octree_s > 0.0 {
            s.push_str(&format!(
                "prepare: load {:.1} ms, prefilter {:.1} ms, classify {:.1} ms, octree {:.1} ms\n",
                p.load_s * 1e3,
                p.prefilter_s * 1e3,
                p.classify_s * 1e3,
                p.octree_s * 1e3
            ));
        }
        s.push_str(&format!(
            "{:9} {:>9} {:>7}\n",
            "stage", "thread ms", "share"
        ));
        for st in STAGES {
            let t = self.stage_times.get(st).as_secs_f64();
            s.push_str(&format!(
                "{:9} {:9.2} {:6.1}%\n",
                st.name(),
                t * 1e3,
                100.0 * t / total
            ));
        }
        s.push_str(&format!(
            "per ray: {:.2} cells visited, {:.2} solved ({:.0}% held a crossing), {:.2} cleared by curvature, {:.2} kernel evals, {:.2} root-refinement evaluations (brent_iters in --stats)\n",
            c.cells_visited as f64 / rays,
            c.cells_solved as f64 / rays,
            100.0 * c.cells_with_crossing as f64 / c.cells_solved.max(1) as f64,
            c.cells_cleared as f64 / rays,
            c.kernel_evals as f64 / rays,
            c.brent_iters as f64 / rays,
        ));
        if let Some(p) = &self.post {
            s.push_str(&format!(
                "anti-aliasing: {} quadrants interpolated, {} mirrored, {} nearest; {} pixels blended across a boundary; {} pixels re-traced ({} for curvature)\n",
                p.quadrants_interpolated,
                p.quadrants_mirrored,
                p.quadrants_nearest,
                p.pixels_blended,
                p.pixels_flagged,
                p.pixels_curved
            ));
        }
        s.push_str(&format!(
            "events: {} refractions, {} total internal reflections, {} degenerate normals; {} rays stopped by max_events, {} missed the backdrop, {} undefined\n",
            c.refractions, c.reflections, c.degenerate_normals, c.terminated, c.missed_backdrop, c.undefined
        ));
        s
    }
}
