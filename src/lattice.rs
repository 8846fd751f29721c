//! The knot-cell lattice: the cells in which the field is one polynomial.
//!
//! For kernels with even support (linear, Catmull-Rom, odd-degree B-splines)
//! knots sit at integers and knot cells are the grid cells between 2³ samples;
//! for odd support (even-degree B-splines) knots sit at half-integers and knot
//! cells are the dual cells centred on samples. Traversal, classification and
//! the octree all work on this lattice, so a visited cell is exactly one
//! polynomial piece to solve.
//!
//! Cell coordinates: `u = x + offset` (x in grid units); cell `i` covers
//! `u ∈ [i, i+1)`, clipped to the domain `x ∈ [0, n-1]`.

use crate::filter::Kernel;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lattice {
    /// 0 or 0.5 (see module docs).
    pub offset: f64,
    /// Samples per axis.
    pub samples: [usize; 3],
    /// Cells per axis (`n - 1`, or `n` with half-integer knots; 0 for a flat axis).
    pub cells: [usize; 3],
}

impl Lattice {
    pub fn new(kernel: &Kernel, samples: [usize; 3]) -> Lattice {
        let offset = kernel.knot_offset();
        let cells = samples.map(|n| {
            if n < 2 {
                0
            } else if offset > 0.0 {
                n
            } else {
                n - 1
            }
        });
        Lattice {
            offset,
            samples,
            cells,
        }
    }

    /// False when some axis has a single sample: the domain has no volume.
    pub fn is_solid(&self) -> bool {
        self.cells.iter().all(|&c| c > 0)
    }

    pub fn cell_count(&self) -> usize {
        self.cells.iter().product()
    }

    /// Cell holding grid coordinate `x` along `axis`, clamped into range.
    #[inline(always)]
    pub fn cell_of(&self, axis: usize, x: f64) -> i64 {
        let c = crate::filter::kernel::floor_i64(x + self.offset);
        c.clamp(0, (self.cells[axis] as i64 - 1).max(0))
    }

    /// Linear index of a cell (x fastest).
    #[inline(always)]
    pub fn index(&self, c: [i64; 3]) -> usize {
        c[0] as usize + self.cells[0] * (c[1] as usize + self.cells[1] * c[2] as usize)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn even_and_odd_support() {
        let l3 = Lattice::new(&Kernel::bspline(3), [5, 4, 1]);
        assert_eq!(l3.cells, [4, 3, 0]);
        assert!(!l3.is_solid());
        assert_eq!(l3.cell_of(0, 4.0), 3);
        assert_eq!(l3.cell_of(0, 0.0), 0);
        let l2 = Lattice::new(&Kernel::bspline(2), [5, 4, 2]);
        assert_eq!(l2.cells, [5, 4, 2]);
        assert_eq!(l2.cell_of(0, 0.49), 0);
        assert_eq!(l2.cell_of(0, 0.5), 1);
        assert_eq!(l2.cell_of(0, 4.0), 4);
    }
}
