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
    pristine: Coeffs<f64>,
    work: Vec<f64>,
}

impl PrefilterPasses {
    /// The padded `f64` grid of `vol`'s samples (before any filtering).
    pub fn of(vol: &Volume) -> PrefilterPasses {
        let pristine = Coeffs::<f64>::from_volume(vol, 0.0);
        let work = pristine.data().to_vec();
        PrefilterPasses { pristine, work }
    }

    /// Voxels a pass filters (the interior).
    pub fn voxels(&self) -> usize {
        self.pristine.dims().iter().product()
    }

    /// Restores the input, untimed, then filters it along `axis` (0 = x, 1
    /// = y, 2 = z) with `pf`; returns the pass's time.
    pub fn time(&mut self, pf: &Prefilter, axis: usize) -> Duration {
        self.work.copy_from_slice(self.pristine.data());
        let (dims, origin, strides) = self.layout();
        let t = Instant::now();
        pf.apply_axis_strided(
            std::hint::black_box(&mut self.work),
            dims,
            origin,
            strides,
            axis,
        );
        t.elapsed()
    }

    /// The interior's dims, its offset and the grid's strides, as
    /// [`Prefilter::apply_axis_strided`] takes them.
    fn layout(&self) -> ([usize; 3], usize, [usize; 3]) {
        let g = &self.pristine;
        (
            g.dims(),
            g.interior_offset(0, 0, 0),
            [g.stride(0), g.stride(1), g.stride(2)],
        )
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
        let mut want = p.pristine.data().to_vec();
        let (dims, origin, strides) = p.layout();
        pf.apply_axis_strided(&mut want, dims, origin, strides, 1);
        p.time(&pf, 0);
        p.time(&pf, 1);
        assert_eq!(p.work, want);
        assert_ne!(p.work, p.pristine.data(), "the pass changed the grid");
    }
}
