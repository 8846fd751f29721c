//! Summary statistics of a volume: value range, histogram, iso-value hints.

use super::Volume;

/// Fixed-bin histogram over `[min, max]`.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Histogram {
    pub min: f64,
    pub max: f64,
    pub counts: Vec<u64>,
}

impl Histogram {
    pub fn bin_width(&self) -> f64 {
        (self.max - self.min) / self.counts.len() as f64
    }
    pub fn bin_center(&self, i: usize) -> f64 {
        self.min + (i as f64 + 0.5) * self.bin_width()
    }
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct VolumeStats {
    pub min: f64,
    pub max: f64,
    pub mean: f64,
    pub histogram: Histogram,
    /// Iso-values worth trying: midpoints between the dominant histogram modes
    /// (background and materials), where a clean boundary surface usually lies.
    /// In ascending order, except that values most samples lie above come
    /// last ([`VolumeStats::suggested_above`]): the first is the outermost
    /// surface that wraps an object, what a user most likely wants to see.
    pub suggested_iso: Vec<f64>,
    /// For each suggestion, the share of the samples above it. Over a half,
    /// the surface bounds voids in a bulk rather than an object (the
    /// cropped tooth's embedding at 51.8, 99.4% above it, around a few dark
    /// pockets), and the value is put after the others.
    pub suggested_above: Vec<f64>,
    /// Whether [`VolumeStats::suggested_iso`] comes from two modes or more;
    /// otherwise it is the value range's midpoint, a guess.
    pub iso_from_modes: bool,
}

impl VolumeStats {
    /// Computed on the stored samples, whose differences are exact, then
    /// shifted by the volume's offset ([`Volume::offset`]).
    pub fn compute(vol: &Volume) -> VolumeStats {
        let s = vol.samples();
        let (mut lo, mut hi, mut sum) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
        for &v in s {
            let v = v as f64;
            lo = lo.min(v);
            hi = hi.max(v);
            sum += v;
        }
        let mean = sum / s.len().max(1) as f64;
        let bins = 64usize;
        let mut counts = vec![0u64; bins];
        let width = (hi - lo).max(f64::MIN_POSITIVE);
        for &v in s {
            let b = (((v as f64 - lo) / width) * bins as f64) as usize;
            counts[b.min(bins - 1)] += 1;
        }
        let histogram = Histogram {
            min: lo,
            max: hi,
            counts,
        };
        let (suggested_iso, iso_from_modes) = match suggest_iso(&histogram) {
            Some(iso) => (iso, true),
            None if hi > lo => (vec![0.5 * (lo + hi)], false),
            None => (Vec::new(), false),
        };
        let above = shares_above(s, &suggested_iso);
        let mut ranked: Vec<(f64, f64)> = suggested_iso.into_iter().zip(above).collect();
        // Stable: each kind keeps its ascending order.
        ranked.sort_by_key(|&(_, share)| share > 0.5);
        let (suggested_iso, suggested_above): (Vec<f64>, _) = ranked.into_iter().unzip();
        let off = vol.offset();
        VolumeStats {
            min: off + lo,
            max: off + hi,
            mean: off + mean,
            histogram: Histogram {
                min: off + histogram.min,
                max: off + histogram.max,
                ..histogram
            },
            suggested_iso: suggested_iso.into_iter().map(|v| off + v).collect(),
            suggested_above,
            iso_from_modes,
        }
    }
}

/// For each value of `isos`, the share of `samples` above it.
fn shares_above(samples: &[f32], isos: &[f64]) -> Vec<f64> {
    let n = samples.len().max(1) as f64;
    isos.iter()
        .map(|&v| samples.iter().filter(|&&x| x as f64 > v).count() as f64 / n)
        .collect()
}

/// Finds the histogram's modes (local maxima of the log-count, smoothed) and
/// returns the midpoints between consecutive strong modes. A surface between
/// two materials sits halfway between their typical values. `None` with
/// fewer than two strong modes.
/// How far `v[i]` rises above its key col: the higher of the lowest
/// points between it and a higher value on either side, a side that meets
/// no higher value before its end not counting (for the highest peak, the
/// lowest value of all). A peak's topographic prominence.
fn prominence(v: &[f64], i: usize) -> f64 {
    // The lowest point before a higher value, if one comes.
    let col = |side: &mut dyn Iterator<Item = usize>| {
        let mut low = v[i];
        for k in side {
            if v[k] > v[i] {
                return Some(low);
            }
            low = low.min(v[k]);
        }
        None
    };
    let left = col(&mut (0..i).rev());
    let right = col(&mut (i + 1..v.len()));
    let key = match (left, right) {
        (Some(a), Some(b)) => a.max(b),
        (Some(a), None) | (None, Some(a)) => a,
        (None, None) => v.iter().copied().fold(f64::INFINITY, f64::min),
    };
    v[i] - key
}

fn suggest_iso(h: &Histogram) -> Option<Vec<f64>> {
    let n = h.counts.len();
    if h.max <= h.min {
        return None;
    }
    let log: Vec<f64> = h.counts.iter().map(|&c| ((c + 1) as f64).ln()).collect();
    let smooth: Vec<f64> = (0..n)
        .map(|i| {
            let lo = i.saturating_sub(2);
            let hi = (i + 2).min(n - 1);
            log[lo..=hi].iter().sum::<f64>() / (hi - lo + 1) as f64
        })
        .collect();
    let total: u64 = h.counts.iter().sum();
    let mut modes: Vec<usize> = (0..n)
        .filter(|&i| {
            let left = if i == 0 {
                f64::NEG_INFINITY
            } else {
                smooth[i - 1]
            };
            let right = if i + 1 == n {
                f64::NEG_INFINITY
            } else {
                smooth[i + 1]
            };
            smooth[i] >= left && smooth[i] > right
        })
        // A material worth a surface holds at least 0.2% of the voxels.
        .filter(|&i| {
            let lo = i.saturating_sub(2);
            let hi = (i + 2).min(n - 1);
            let c: u64 = h.counts[lo..=hi].iter().sum();
            c as f64 >= 0.002 * total as f64
        })
        // And stands out: its count at least 1.2 times the deepest valley
        // on the way to a higher mode on either side (its prominence), so
        // the ripples of a smooth ramp (a phantom's Gaussian fringe, a
        // scan's partial-volume shell) are not taken for materials.
        .filter(|&i| prominence(&smooth, i) >= 1.2f64.ln())
        .collect();
    modes.dedup();
    let out: Vec<f64> = modes
        .windows(2)
        .map(|w| 0.5 * (h.bin_center(w[0]) + h.bin_center(w[1])))
        .collect();
    (!out.is_empty()).then_some(out)
}

#[cfg(test)]
mod tests {
    use crate::volume::{SampleType, Volume};

    /// The paper's glass ball: background and ball in two tall modes, the
    /// Gaussian fringe between them a ramp whose shells' ripples are no
    /// materials. One suggestion, the midpoint.
    #[test]
    fn a_fringe_between_two_materials_gives_one_midpoint() {
        let ball = crate::phantom::SphereSpec {
            format: crate::phantom::PhantomFormat::U8,
            ..Default::default()
        }
        .build()
        .unwrap();
        let st = ball.stats();
        assert_eq!(st.suggested_iso, [127.5], "{:?}", st.suggested_iso);
        assert!(st.iso_from_modes);
    }

    #[test]
    fn two_materials_give_a_midpoint() {
        let mut s = vec![10.0f32; 4000];
        s.extend(std::iter::repeat_n(200.0f32, 4000));
        s.extend((0..100).map(|i| 10.0 + i as f32 * 1.9));
        let n = s.len();
        let v = Volume::new([n, 1, 1], [1.0; 3], SampleType::U8, s).unwrap();
        let st = v.stats();
        assert_eq!(st.min, 10.0);
        assert_eq!(st.max, 200.0);
        assert_eq!(st.histogram.counts.iter().sum::<u64>(), n as u64);
        assert!(
            st.suggested_iso.iter().any(|&x| (x - 105.0).abs() < 10.0),
            "{:?}",
            st.suggested_iso
        );
        assert!(st.iso_from_modes);
    }

    /// Suggestions come in ascending order, except that a value most
    /// samples lie above comes last: a block filling all but one face layer
    /// of background, with a brighter core, gives 150 (the core's boundary)
    /// before 50 (the block's bulk around the background's layer, 15/16 of
    /// the samples above it).
    #[test]
    fn a_surface_around_voids_comes_last() {
        let n = 16;
        // The block, and the background as the face x = 0.
        let mut s = vec![100.0f32; n * n * n];
        for (i, v) in s.iter_mut().enumerate() {
            if i % n == 0 {
                *v = 0.0;
            }
        }
        // A bright core of 6³.
        for z in 5..11 {
            for y in 5..11 {
                for x in 5..11 {
                    s[(z * n + y) * n + x] = 200.0;
                }
            }
        }
        let v = Volume::new([n; 3], [1.0; 3], SampleType::U8, s).unwrap();
        let st = v.stats();
        assert!(st.iso_from_modes);
        assert_eq!(st.suggested_iso.len(), 2, "{:?}", st.suggested_iso);
        // 50 lies below 15/16 of the samples: the block's bulk, bounding
        // the background's face layer; 150 bounds the core (5%).
        assert!(
            st.suggested_iso[0] > 100.0 && st.suggested_iso[1] < 100.0,
            "{:?}",
            st.suggested_iso
        );
        assert_eq!(st.suggested_above[0], 216.0 / 4096.0);
        assert_eq!(st.suggested_above[1], 15.0 / 16.0);
    }

    /// A ramp has no two materials: the suggestion is the range's midpoint,
    /// and says so.
    #[test]
    fn one_material_gives_the_midpoint_as_a_guess() {
        let s: Vec<f32> = (0..4096).map(|i| (i % 256) as f32).collect();
        let v = Volume::new([16, 16, 16], [1.0; 3], SampleType::U8, s).unwrap();
        let st = v.stats();
        assert_eq!(st.suggested_iso, vec![127.5]);
        assert!(!st.iso_from_modes);
    }
}
