//! The filters against the independent reference vectors in
//! `../shared/reference/` (exact solves, not recursive filters): prefiltered
//! coefficients in 1-D and 3-D, values and gradients at points. SPEC.md asks for
//! 1e-4 absolute on 0..255 data; the default f64 coefficient storage meets it
//! with orders of magnitude to spare (the worst errors are printed). The f32
//! storage option is measured too: high-degree splines on this noise data have
//! coefficients in the tens of thousands, where half an f32 ulp is near 1e-3,
//! so it is held to what rounding the coefficients to f32 can cost, not 1e-4.

use std::path::PathBuf;

use glam::DVec3;
use serde_json::Value;
use snell::filter::{Field, FilterKind};
use snell::volume::{SampleType, Volume};

const TOL: f64 = 1e-4;

fn reference(name: &str) -> Value {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/reference")
        .join(name);
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("reference vectors missing at {}: {e}", path.display()));
    serde_json::from_str(&text).expect("reference JSON parses")
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn kind_of(case: &Value) -> FilterKind {
    FilterKind::parse(
        case["filter"].as_str().unwrap(),
        case["lambda"].as_f64().unwrap(),
    )
    .unwrap()
}

#[test]
fn prefilter_1d_matches_reference() {
    let r = reference("prefilter_1d.json");
    let cases = r["cases"].as_array().unwrap();
    assert!(cases.len() >= 36);
    let mut worst = 0.0f64;
    for case in cases {
        let kind = kind_of(case);
        let signal = floats(&case["signal"]);
        let expect = floats(&case["coefficients"]);
        // Through the 1-D line filter...
        let mut c = signal.clone();
        kind.prefilter().apply_line(&mut c);
        // ...and through the 3-D path on an n×1×1 volume.
        let vol = Volume::new(
            [signal.len(), 1, 1],
            [1.0; 3],
            SampleType::F32,
            signal.iter().map(|&v| v as f32).collect(),
        )
        .unwrap();
        let c3 = Field::new_f32(&vol, kind).coeffs().interior();
        for (i, e) in expect.iter().enumerate() {
            let d = (c[i] - e).abs();
            worst = worst.max(d);
            assert!(
                d < 1e-9 * (1.0 + e.abs()),
                "{kind} n={} i={i}: {} vs {e}",
                signal.len(),
                c[i]
            );
            let d3 = (c3[i] as f64 - e).abs();
            assert!(
                d3 < TOL,
                "{kind} 3-D n={} i={i}: {} vs {e}",
                signal.len(),
                c3[i]
            );
        }
    }
    eprintln!("prefilter_1d: worst |error| (f64 line filter) = {worst:.3e}");
}

#[test]
fn interpolate_3d_matches_reference() {
    let r = reference("interpolate_3d.json");
    let cases = r["cases"].as_array().unwrap();
    assert!(cases.len() >= 30);
    let (mut worst_c, mut worst_v, mut worst_g) = (0.0f64, 0.0f64, 0.0f64);
    for case in cases {
        let kind = kind_of(case);
        let d = floats(&case["dims"]);
        let dims = [d[0] as usize, d[1] as usize, d[2] as usize];
        let samples: Vec<f32> = floats(&case["samples"]).iter().map(|&v| v as f32).collect();
        let vol = Volume::new(dims, [1.0; 3], SampleType::U8, samples).unwrap();
        let field = Field::new(&vol, kind);
        // The prefilter itself runs in f64 and must be exact...
        let mut exact: Vec<f64> = vol.samples().iter().map(|&v| v as f64).collect();
        kind.prefilter().apply_3d(&mut exact, dims);
        // ...and the stored f32 coefficients only round it once (half an ulp).
        let stored = field.coeffs().interior();
        for (i, e) in floats(&case["coefficients"]).iter().enumerate() {
            let err = (exact[i] - e).abs();
            worst_c = worst_c.max(err);
            assert!(
                err < 1e-9 * (1.0 + e.abs()),
                "{kind} {dims:?} coefficient {i}: {} vs {e}",
                exact[i]
            );
            assert!(
                (stored[i] - exact[i]).abs() <= 1e-12 * (1.0 + exact[i].abs()),
                "{kind} {dims:?} stored coefficient {i}: {} vs {}",
                stored[i],
                exact[i]
            );
        }
        let points = case["points"].as_array().unwrap();
        let values = floats(&case["values"]);
        let grads = case["gradients"].as_array().unwrap();
        for (k, p) in points.iter().enumerate() {
            let p = floats(p);
            let (v, g) = field.value_grad(DVec3::new(p[0], p[1], p[2]));
            let mut eg = floats(&grads[k]);
            let ev = (v - values[k]).abs();
            worst_v = worst_v.max(ev);
            assert!(
                ev < TOL,
                "{kind} {dims:?} value at {p:?}: {v} vs {}",
                values[k]
            );
            if kind == FilterKind::Linear {
                // The reference lists 0 for every trilinear gradient, even at
                // generic interior points where the field is not flat, so it
                // carries no gradient information for `linear`. Check ours against
                // central differences of the (reference-matched) values instead.
                assert!(eg.iter().all(|&x| x == 0.0));
                let pc = DVec3::new(p[0], p[1], p[2]);
                let h = 1e-6;
                let on_knot = (0..3).any(|a| (p[a] - p[a].round()).abs() < 2.0 * h);
                if on_knot {
                    continue; // the trilinear field has a kink there
                }
                eg = (0..3)
                    .map(|a| {
                        let mut e = DVec3::ZERO;
                        e[a] = h;
                        (field.value(pc + e) - field.value(pc - e)) / (2.0 * h)
                    })
                    .collect();
            }
            for a in 0..3 {
                let eg_a = (g[a] - eg[a]).abs();
                worst_g = worst_g.max(eg_a);
                assert!(
                    eg_a < TOL,
                    "{kind} {dims:?} gradient[{a}] at {p:?}: {} vs {}",
                    g[a],
                    eg[a]
                );
            }
        }
    }
    eprintln!(
        "interpolate_3d: worst |error| coefficients {worst_c:.3e}, values {worst_v:.3e}, gradients {worst_g:.3e}"
    );
}

/// f32 coefficient storage, measured: its error grows with the spline degree
/// (the prefilter's noise gain), so cubic and below stay within SPEC's 1e-4 on
/// this worst-case white-noise data, while degree 4..7 need f64 to get there.
/// The bound is the rounding's own: a value is a weighted sum of coefficients
/// each off by at most its f32 rounding, so the error is at most the largest
/// rounding times the weights' absolute sum (1 for the non-negative B-spline
/// and linear weights, at most 1.25 per axis for Catmull-Rom's), plus the
/// f64 arithmetic's.
#[test]
fn f32_storage_error_by_degree() {
    let r = reference("interpolate_3d.json");
    // Per filter: the worst error, and the worst of its bound.
    let mut worst: std::collections::BTreeMap<String, (f64, f64)> = Default::default();
    for case in r["cases"].as_array().unwrap() {
        let kind = kind_of(case);
        let d = floats(&case["dims"]);
        let dims = [d[0] as usize, d[1] as usize, d[2] as usize];
        let samples: Vec<f32> = floats(&case["samples"]).iter().map(|&v| v as f32).collect();
        let vol = Volume::new(dims, [1.0; 3], SampleType::U8, samples).unwrap();
        let field = Field::new_f32(&vol, kind);
        let values = floats(&case["values"]);
        let rounding = floats(&case["coefficients"])
            .iter()
            .map(|&c| (c as f32 as f64 - c).abs())
            .fold(0.0, f64::max);
        let weights = if kind.name() == "catmull-rom" {
            1.25f64.powi(3)
        } else {
            1.0
        };
        let bound = rounding * weights + 1e-9;
        let w = worst.entry(kind.to_string()).or_default();
        w.1 = w.1.max(bound);
        for (k, p) in case["points"].as_array().unwrap().iter().enumerate() {
            let p = floats(p);
            let v = field.value(DVec3::new(p[0], p[1], p[2]));
            let err = (v - values[k]).abs();
            assert!(
                err <= bound,
                "{kind}, point {k}: error {err:.3e} over the rounding's {bound:.3e}"
            );
            w.0 = w.0.max(err);
        }
    }
    for (name, (w, bound)) in &worst {
        eprintln!("f32 storage {name:24} worst |value error| {w:.2e} (rounding bound {bound:.2e})");
        let cubic_or_less = ["linear", "catmull-rom", "bspline2", "bspline3"]
            .contains(&name.as_str())
            || name.starts_with("smooth-bspline3");
        if cubic_or_less {
            assert!(*w < TOL, "{name}: {w}");
        }
    }
}
