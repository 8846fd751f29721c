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
    pub suggested_iso: Vec<f64>,
    /// Whether [`VolumeStats::suggested_iso`] comes from two modes or more;
    /// otherwise it is the value range's midpoint, a guess.
    pub iso_from_modes: bool,
}

impl VolumeStats {
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
        VolumeStats {
            min: lo,
            max: hi,
            mean,
            histogram,
            suggested_iso,
            iso_from_modes,
        }
    }
}

/// Finds the histogram's modes (local maxima of the log-count, smoothed) and
/// returns the midpoints between consecutive strong modes. A surface between
/// two materials sits halfway between their typical values. `None` with
/// fewer than two strong modes.
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
