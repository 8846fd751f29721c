//! A timeline of one render in the Chrome trace-event format (`snell render
//! --trace trace.json`), for Perfetto (ui.perfetto.dev) or `chrome://tracing`.
//!
//! Each rayon worker is a track; every tile is a complete (`"X"`) event on
//! the track of the thread that ran it, with the stage calls inside it
//! (`generate`, `entry`, then `traverse`, `solve`, `refract` once per pass
//! of the ray queues, `record`) nested as child events at their measured
//! start and duration. The thread that drives the render has its own track
//! with the preparation (`load`, `prefilter`, `classify`, `octree`), the tile
//! loop, `film` and `prss`.
//!
//! Recording costs nothing when off: tiles then carry no spans (one branch
//! per stage call, no allocation), and the timestamps taken are the ones the
//! per-stage profile takes anyway.

use std::path::Path;
use std::time::{Duration, Instant};

use serde_json::{Value, json};

use super::stats::{Counters, PrepareTimes, Stage};

/// One stage call inside a tile.
#[derive(Clone, Copy, Debug)]
pub struct Span {
    pub stage: Stage,
    pub start: Instant,
    pub dur: Duration,
}

/// When and where a tile ran, and its stage calls.
#[derive(Clone, Debug)]
pub struct TileTrace {
    /// Rayon worker index (`None` outside a pool).
    pub thread: Option<usize>,
    pub start: Instant,
    pub end: Instant,
    pub spans: Vec<Span>,
}

/// Track id of the thread that drives the render (prepare, film, PRSS).
pub const MAIN_TID: u64 = 0;

/// A timeline being recorded; times are relative to its creation.
#[derive(Clone, Debug)]
pub struct Trace {
    origin: Instant,
    events: Vec<Value>,
    /// Worker tracks seen (for their names).
    workers: Vec<u64>,
}

impl Default for Trace {
    fn default() -> Self {
        Trace::new()
    }
}

/// Microseconds (the format's unit), to the nanosecond.
fn us(d: Duration) -> f64 {
    d.as_nanos() as f64 / 1e3
}

impl Trace {
    /// Starts a timeline now.
    pub fn new() -> Trace {
        Trace {
            origin: Instant::now(),
            events: Vec::new(),
            workers: Vec::new(),
        }
    }

    fn ts(&self, t: Instant) -> f64 {
        us(t.saturating_duration_since(self.origin))
    }

    /// A complete event on track `tid`.
    pub fn complete(
        &mut self,
        name: &str,
        cat: &str,
        tid: u64,
        start: Instant,
        dur: Duration,
        args: Value,
    ) {
        let mut e = json!({
            "name": name,
            "cat": cat,
            "ph": "X",
            "pid": 1,
            "tid": tid,
            "ts": self.ts(start),
            "dur": us(dur),
        });
        if !args.is_null() {
            e["args"] = args;
        }
        self.events.push(e);
    }

    /// The preparation that started at `start`: its parts laid end to end in
    /// the order they are built (load, prefilter, classify, octree), from
    /// their measured durations, under one `prepare` event of `total`.
    pub fn prepare(&mut self, start: Instant, total: Duration, times: &PrepareTimes) {
        self.complete("prepare", "prepare", MAIN_TID, start, total, Value::Null);
        let mut t = start;
        for (name, s) in [
            ("load", times.load_s),
            ("prefilter", times.prefilter_s),
            ("classify", times.classify_s),
            ("octree", times.octree_s),
        ] {
            if s > 0.0 {
                let d = Duration::from_secs_f64(s);
                self.complete(name, "prepare", MAIN_TID, t, d, Value::Null);
                t += d;
            }
        }
    }

    /// A tile on its worker's track with its stage calls nested inside.
    pub fn tile(&mut self, t: &TileTrace, pass: &str, label: String, pixels: usize, c: &Counters) {
        let tid = t.thread.map_or(MAIN_TID, |i| i as u64 + 1);
        if tid != MAIN_TID && !self.workers.contains(&tid) {
            self.workers.push(tid);
        }
        self.complete(
            &label,
            "tile",
            tid,
            t.start,
            t.end.saturating_duration_since(t.start),
            json!({
                "pass": pass,
                "pixels": pixels,
                "rays": c.rays,
                "cells_visited": c.cells_visited,
                "cells_solved": c.cells_solved,
                "kernel_evals": c.kernel_evals,
            }),
        );
        for s in &t.spans {
            self.complete(s.stage.name(), "stage", tid, s.start, s.dur, Value::Null);
        }
    }

    /// Number of events recorded (metadata excluded).
    pub fn len(&self) -> usize {
        self.events.len()
    }

    pub fn is_empty(&self) -> bool {
        self.events.is_empty()
    }

    /// The trace as a Chrome trace-event JSON object.
    pub fn to_json(&self) -> Value {
        let name = |tid: u64, n: String| json!({"name": "thread_name", "ph": "M", "pid": 1, "tid": tid, "args": {"name": n}});
        let mut events = vec![
            json!({"name": "process_name", "ph": "M", "pid": 1, "args": {"name": "snell render"}}),
            name(MAIN_TID, "frame: prepare, tile loop, film".into()),
        ];
        let mut workers = self.workers.clone();
        workers.sort_unstable();
        for w in workers {
            events.push(name(w, format!("worker {}", w - 1)));
            events.push(json!({"name": "thread_sort_index", "ph": "M", "pid": 1, "tid": w, "args": {"sort_index": w}}));
        }
        events.extend(self.events.iter().cloned());
        json!({ "traceEvents": events, "displayTimeUnit": "ms" })
    }

    /// Writes the trace to `path` (atomically).
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        let j = self.to_json();
        crate::atomic::write_atomic(path, |w| {
            serde_json::to_writer(&mut *w, &j)?;
            std::io::Write::write_all(w, b"\n")
        })
    }
}
