//! One prefilter pass timed alone: the unit of issue 7's prefilter-rate
//! target, shared by `snell bench --targets` and `benches/filter.rs` so
//! both time the same thing.
//!
//! The grid is the padded `f64` coefficient grid `Field::new` filters; each
//! pass filters the interior along one axis, from the same input every time
//! (restored untimed before the pass), so no pass runs on another's output.

use std::time::{Duration, Instant};

use crate::filter::{Coeffs, Prefilter};
use crate::volume::Volume;

/// A volume's padded coefficient grid, kept pristine, and a working copy to
/// filter.
pub struct PrefilterPasses {
    dims: [usize; 3],
    origin: usize,
    strides: [usize; 3],
    pristine: Vec<f64>,
    work: Vec<f64>,
}

impl PrefilterPasses {
    /// The padded `f64` grid of `vol`'s samples (before any filtering).
    pub fn of(vol: &Volume) -> PrefilterPasses {
        let grid = Coeffs::<f64>::from_volume(vol);
        let dims = grid.dims();
        let origin = grid.interior_offset(0, 0, 0);
        let strides = [grid.stride(0), grid.stride(1), grid.stride(2)];
        let pristine = grid.data().to_vec();
        drop(grid);
        let work = pristine.clone();
        PrefilterPasses {
            dims,
            origin,
            strides,
            pristine,
            work,
        }
    }

    /// Voxels a pass filters (the interior).
    pub fn voxels(&self) -> usize {
        self.dims.iter().product()
    }

    /// Restores the input, untimed, then filters it along `axis` (0 = x, 1
    /// = y, 2 = z) with `pf`; returns the pass's time.
    pub fn time(&mut self, pf: &Prefilter, axis: usize) -> Duration {
        self.work.copy_from_slice(&self.pristine);
        let t = Instant::now();
        pf.apply_axis_strided(
            std::hint::black_box(&mut self.work),
            self.dims,
            self.origin,
            self.strides,
            axis,
        );
        t.elapsed()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::FilterKind;

    /// Every pass starts from the pristine input: a pass after another
    /// leaves what one pass alone makes of the input, not two passes' worth.
    #[test]
    fn each_pass_filters_the_pristine_input() {
        let vol = crate::volume::scrambled_u8([7, 6, 5], 3);
        let pf = FilterKind::parse("bspline3", 0.0).unwrap().prefilter();
        let mut p = PrefilterPasses::of(&vol);
        assert_eq!(p.voxels(), 7 * 6 * 5);
        let mut want = p.pristine.clone();
        pf.apply_axis_strided(&mut want, p.dims, p.origin, p.strides, 1);
        p.time(&pf, 0);
        p.time(&pf, 1);
        assert_eq!(p.work, want);
        assert_ne!(p.work, p.pristine, "the pass changed the grid");
    }
}
