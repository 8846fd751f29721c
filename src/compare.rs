//! How far two hit-position images are apart: the accuracy measure.
//!
//! The error of a pixel is the distance between where its pixel-centre ray
//! lands on the backdrop in the two images, in backdrop units (and in checker
//! squares when a square size is known). Pixels where only one image reaches
//! the backdrop, or where the rays crossed a different number of interfaces,
//! are counted separately: they are topological disagreements, not distances.

use serde::Serialize;

use crate::film::HitImage;

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CompareError {
    #[error("images differ in size: {0}x{1} vs {2}x{3}")]
    Size(u32, u32, u32, u32),
}

/// Percentiles over the refracted pixels only.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RefractedStats {
    pub pixels: usize,
    pub p50: f64,
    pub p90: f64,
    pub p99: f64,
}

/// Hit-error statistics of `a` against `b`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct HitComparison {
    pub pixels: usize,
    /// Pixels that reach the backdrop in both.
    pub both_valid: usize,
    /// Pixels that reach the backdrop in exactly one.
    pub validity_mismatch: usize,
    /// Pixels whose event counts differ (where both images record them).
    pub event_mismatch: usize,
    /// Share of pixels with equal event counts, of those where both images
    /// record them.
    pub events_equal_fraction: f64,
    /// Pixels where either image records no event count (NaN: POV-Ray's
    /// hits, `export-pov --run`, do not count interfaces).
    pub events_unknown: usize,
    /// Percentiles of the hit distance over pixels valid in both (backdrop units).
    pub p50: f64,
    pub p90: f64,
    pub p99: f64,
    pub max: f64,
    pub mean: f64,
    /// The same percentiles over pixels whose ray crossed an interface in
    /// either image (the refracted part, where the error lives).
    pub refracted: RefractedStats,
    /// Checker square size the `*_squares` fields are in, if known.
    pub checker: Option<f64>,
}

impl HitComparison {
    /// A distance in checker squares (or backdrop units if no checker).
    pub fn squares(&self, d: f64) -> f64 {
        self.checker.map_or(d, |s| d / s)
    }

    pub fn to_json(&self) -> serde_json::Value {
        let mut j = serde_json::to_value(self).expect("plain data");
        if self.checker.is_some() {
            j["p50_squares"] = self.squares(self.p50).into();
            j["p90_squares"] = self.squares(self.p90).into();
            j["p99_squares"] = self.squares(self.p99).into();
            j["max_squares"] = self.squares(self.max).into();
            j["refracted"]["p50_squares"] = self.squares(self.refracted.p50).into();
            j["refracted"]["p90_squares"] = self.squares(self.refracted.p90).into();
            j["refracted"]["p99_squares"] = self.squares(self.refracted.p99).into();
        }
        j
    }

    pub fn table(&self) -> String {
        let unit = if self.checker.is_some() {
            "squares"
        } else {
            "units"
        };
        let counted = self.pixels - self.events_unknown;
        let events = match (self.events_unknown, counted) {
            (0, _) => format!(
                "{} with different event counts ({:.3}% equal)",
                self.event_mismatch,
                100.0 * self.events_equal_fraction
            ),
            // POV-Ray's hits, say, carry no event counts.
            (_, 0) => "event counts not compared (no pixel has one in both)".to_string(),
            (_, n) => format!(
                "{} with different event counts ({:.3}% equal of {n} where both count them)",
                self.event_mismatch,
                100.0 * self.events_equal_fraction
            ),
        };
        let mut s = format!(
            "{} pixels: {} reach the backdrop in both, {} in only one, {events}\n",
            self.pixels, self.both_valid, self.validity_mismatch,
        );
        if self.both_valid == 0 {
            s.push_str("hit error: none measured (no pixel reaches the backdrop in both)\n");
            return s;
        }
        let n = crate::human::sig4;
        s.push_str(&format!(
            "hit error (backdrop units): p50 {}  p90 {}  p99 {}  max {}  mean {}\n",
            n(self.p50),
            n(self.p90),
            n(self.p99),
            n(self.max),
            n(self.mean)
        ));
        let r = &self.refracted;
        if r.pixels == 0 {
            s.push_str("refracted pixels: none (no pixel refracts in both)\n");
        } else {
            s.push_str(&format!(
                "refracted pixels ({}): p50 {}  p90 {}  p99 {} {unit}\n",
                r.pixels,
                n(self.squares(r.p50)),
                n(self.squares(r.p90)),
                n(self.squares(r.p99))
            ));
        }
        if self.checker.is_some() {
            s.push_str(&format!(
                "hit error ({unit}):        p50 {}  p90 {}  p99 {}  max {}\n",
                n(self.squares(self.p50)),
                n(self.squares(self.p90)),
                n(self.squares(self.p99)),
                n(self.squares(self.max))
            ));
        }
        s
    }
}

/// Whether two pixels' event counts differ: both known (not NaN) and unequal.
fn events_differ(a: f32, b: f32) -> bool {
    !a.is_nan() && !b.is_nan() && a != b
}

/// Percentile by nearest rank of sorted values (NaN-free).
pub fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let rank = ((p / 100.0) * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

/// One pixel where two hit images disagree.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Disagreement {
    pub x: u32,
    pub y: u32,
    /// Events along each image's pixel-centre ray.
    pub events: [f32; 2],
    /// Backdrop hit of each (`None` where the ray never reached it).
    pub hit: [Option<[f32; 2]>; 2],
    /// Hit distance when both reached the backdrop (backdrop units).
    pub distance: Option<f64>,
}

/// The pixels where `a` and `b` differ in validity or event count first (in
/// pixel order), then the largest hit distances, up to `limit` in all: the
/// cases to look at when two renderers disagree.
pub fn disagreements(
    a: &HitImage,
    b: &HitImage,
    limit: usize,
) -> Result<Vec<Disagreement>, CompareError> {
    if (a.width, a.height) != (b.width, b.height) {
        return Err(CompareError::Size(a.width, a.height, b.width, b.height));
    }
    let hit = |h: &HitImage, i: usize| {
        (h.u[i].is_finite() && h.v[i].is_finite()).then(|| [h.u[i], h.v[i]])
    };
    let row = |i: usize| {
        let (ha, hb) = (hit(a, i), hit(b, i));
        let distance = match (ha, hb) {
            (Some(p), Some(q)) => Some(
                ((p[0] as f64 - q[0] as f64).powi(2) + (p[1] as f64 - q[1] as f64).powi(2)).sqrt(),
            ),
            _ => None,
        };
        Disagreement {
            x: i as u32 % a.width,
            y: i as u32 / a.width,
            events: [a.events[i], b.events[i]],
            hit: [ha, hb],
            distance,
        }
    };
    let n = a.u.len();
    let mut out: Vec<Disagreement> = (0..n)
        .filter(|&i| {
            events_differ(a.events[i], b.events[i]) || hit(a, i).is_some() != hit(b, i).is_some()
        })
        .take(limit)
        .map(row)
        .collect();
    if out.len() < limit {
        let mut rest: Vec<Disagreement> = (0..n)
            .filter(|&i| {
                !events_differ(a.events[i], b.events[i])
                    && hit(a, i).is_some()
                    && hit(b, i).is_some()
            })
            .map(row)
            .filter(|d| d.distance.is_some_and(|v| v > 0.0))
            .collect();
        rest.sort_by(|p, q| {
            q.distance
                .unwrap_or(0.0)
                .total_cmp(&p.distance.unwrap_or(0.0))
        });
        out.extend(rest.into_iter().take(limit - out.len()));
    }
    Ok(out)
}

pub fn compare_hits(
    a: &HitImage,
    b: &HitImage,
    checker: Option<f64>,
) -> Result<HitComparison, CompareError> {
    if (a.width, a.height) != (b.width, b.height) {
        return Err(CompareError::Size(a.width, a.height, b.width, b.height));
    }
    let n = a.u.len();
    let mut d = Vec::with_capacity(n);
    let mut dr = Vec::new();
    let (mut validity, mut events, mut unknown) = (0, 0, 0);
    for i in 0..n {
        let va = a.u[i].is_finite() && a.v[i].is_finite();
        let vb = b.u[i].is_finite() && b.v[i].is_finite();
        if a.events[i].is_nan() || b.events[i].is_nan() {
            unknown += 1;
        } else if a.events[i] != b.events[i] {
            events += 1;
        }
        match (va, vb) {
            (true, true) => {
                let du = a.u[i] as f64 - b.u[i] as f64;
                let dv = a.v[i] as f64 - b.v[i] as f64;
                let dist = (du * du + dv * dv).sqrt();
                d.push(dist);
                if a.events[i] > 0.0 || b.events[i] > 0.0 {
                    dr.push(dist);
                }
            }
            (false, false) => {}
            _ => validity += 1,
        }
    }
    d.sort_by(|x, y| x.total_cmp(y));
    dr.sort_by(|x, y| x.total_cmp(y));
    let mean = if d.is_empty() {
        f64::NAN
    } else {
        d.iter().sum::<f64>() / d.len() as f64
    };
    Ok(HitComparison {
        pixels: n,
        both_valid: d.len(),
        validity_mismatch: validity,
        event_mismatch: events,
        events_equal_fraction: 1.0 - events as f64 / (n - unknown).max(1) as f64,
        events_unknown: unknown,
        p50: percentile(&d, 50.0),
        p90: percentile(&d, 90.0),
        p99: percentile(&d, 99.0),
        max: d.last().copied().unwrap_or(f64::NAN),
        mean,
        refracted: RefractedStats {
            pixels: dr.len(),
            p50: percentile(&dr, 50.0),
            p90: percentile(&dr, 90.0),
            p99: percentile(&dr, 99.0),
        },
        checker,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hits without event counts (POV-Ray's) are compared by position
    /// only: their NaN counts are neither mismatches nor disagreements.
    #[test]
    fn unknown_event_counts_are_not_mismatches() {
        let a = HitImage {
            width: 3,
            height: 1,
            u: vec![0.0, 1.0, 2.0],
            v: vec![0.0; 3],
            events: vec![2.0, 0.0, 4.0],
        };
        let mut b = a.clone();
        b.events = vec![f32::NAN, f32::NAN, 3.0];
        b.u[1] = 1.5;
        let c = compare_hits(&a, &b, None).unwrap();
        assert_eq!((c.event_mismatch, c.events_unknown), (1, 2));
        assert_eq!(c.events_equal_fraction, 0.0);
        assert!(
            c.table().contains(
                "1 with different event counts (0.000% equal of 1 where both count them)"
            )
        );
        let mut none = b.clone();
        none.events = vec![f32::NAN; 3];
        let c = compare_hits(&a, &none, None).unwrap();
        assert!(
            c.table()
                .contains("event counts not compared (no pixel has one in both)"),
            "{}",
            c.table()
        );
        let d = disagreements(&a, &b, 10).unwrap();
        assert_eq!(d.iter().map(|d| d.x).collect::<Vec<_>>(), vec![2, 1]);
    }

    /// Where no pixel reaches the backdrop in both, or none refracts in
    /// both, the table says so instead of printing NaN percentiles.
    #[test]
    fn no_common_pixel_prints_no_nan() {
        let a = HitImage {
            width: 2,
            height: 1,
            u: vec![f32::NAN, 1.0],
            v: vec![f32::NAN, 0.0],
            events: vec![2.0, 0.0],
        };
        let mut b = a.clone();
        b.u = vec![0.5, f32::NAN];
        b.v = vec![0.0, f32::NAN];
        let t = compare_hits(&a, &b, Some(8.0)).unwrap().table();
        assert!(
            t.contains("hit error: none measured (no pixel reaches the backdrop in both)"),
            "{t}"
        );
        assert!(!t.contains("NaN"), "{t}");
        // Both reach it, neither refracts.
        let t = compare_hits(&a, &a, None).unwrap().table();
        assert!(
            t.contains("refracted pixels: none (no pixel refracts in both)"),
            "{t}"
        );
        assert!(!t.contains("NaN"), "{t}");
    }

    #[test]
    fn statistics() {
        let a = HitImage {
            width: 4,
            height: 1,
            u: vec![0.0, 1.0, f32::NAN, 5.0],
            v: vec![0.0, 0.0, 0.0, 0.0],
            events: vec![2.0, 2.0, 0.0, 1.0],
        };
        let mut b = a.clone();
        b.u[0] = 3.0;
        b.v[1] = 0.5;
        b.u[3] = f32::NAN;
        b.events[3] = 3.0;
        let c = compare_hits(&a, &b, Some(2.0)).unwrap();
        assert_eq!(c.both_valid, 2);
        assert_eq!(c.validity_mismatch, 1);
        assert_eq!(c.event_mismatch, 1);
        assert_eq!(c.max, 3.0);
        assert_eq!(c.p50, 0.5);
        assert_eq!(c.squares(c.max), 1.5);
        assert!(
            compare_hits(
                &a,
                &HitImage {
                    width: 2,
                    height: 2,
                    ..a.clone()
                },
                None
            )
            .is_err()
        );
    }

    #[test]
    fn nearest_rank() {
        let v: Vec<f64> = (1..=10).map(|x| x as f64).collect();
        assert_eq!(percentile(&v, 50.0), 5.0);
        assert_eq!(percentile(&v, 90.0), 9.0);
        assert_eq!(percentile(&v, 99.0), 10.0);
    }
}
