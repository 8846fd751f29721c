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
        linear_index(self.cells, c)
    }
}

/// Linear index (x fastest) of cell `c` (in range) of a grid of `cells`.
#[inline(always)]
pub fn linear_index(cells: [usize; 3], c: [i64; 3]) -> usize {
    c[0] as usize + cells[0] * (c[1] as usize + cells[1] * c[2] as usize)
}

/// The cell at linear index `i` of a grid of `cells`: the inverse of
/// [`linear_index`].
#[inline(always)]
pub fn cell_at(cells: [usize; 3], i: usize) -> [i64; 3] {
    let [nx, ny, _] = cells;
    [i % nx, i / nx % ny, i / (nx * ny)].map(|v| v as i64)
}

/// Per-cell storage in 4³ bricks: the 64 cells of a brick are one cache line
/// of bytes (or one `u64` of bits). A ray steps through neighbouring cells,
/// so bricked maps turn most steps' loads into cache hits where a linear
/// layout (x fastest) would jump a slab per step in z on a large volume.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Bricked {
    /// Bricks per axis (cells rounded up to a multiple of 4).
    bricks: [usize; 3],
}

impl Bricked {
    pub fn new(cells: [usize; 3]) -> Bricked {
        Bricked {
            bricks: cells.map(|n| n.div_ceil(4)),
        }
    }

    /// Bricks per axis (the strides of [`Bricked::index`], for lane code
    /// that computes it eight cells at a time).
    pub fn bricks(&self) -> [usize; 3] {
        self.bricks
    }

    /// Slots of a map over all bricks (padding cells included).
    pub fn len(&self) -> usize {
        self.bricks.iter().product::<usize>() * 64
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Slot of cell `c` (which must be in range).
    #[inline(always)]
    pub fn index(&self, c: [i64; 3]) -> usize {
        let [x, y, z] = c.map(|v| v as usize);
        let brick = (x >> 2) + self.bricks[0] * ((y >> 2) + self.bricks[1] * (z >> 2));
        (brick << 6) | (x & 3) | ((y & 3) << 2) | ((z & 3) << 4)
    }

    /// The cell in slot `i` (possibly a padding cell outside the lattice).
    #[inline]
    pub fn cell(&self, i: usize) -> [usize; 3] {
        let o = self.brick_origin(i >> 6);
        Bricked::cell_in(o, i & 63)
    }

    /// The first cell of brick `brick` (three divisions: loops over a
    /// brick's 64 slots take it once and add [`Bricked::cell_in`]).
    #[inline]
    pub fn brick_origin(&self, brick: usize) -> [usize; 3] {
        let (bx, by) = (self.bricks[0], self.bricks[1]);
        [
            (brick % bx) * 4,
            (brick / bx % by) * 4,
            (brick / (bx * by)) * 4,
        ]
    }

    /// Cell `k` (0..64) of the brick starting at `origin`.
    #[inline(always)]
    pub fn cell_in(origin: [usize; 3], k: usize) -> [usize; 3] {
        [
            origin[0] + (k & 3),
            origin[1] + (k >> 2 & 3),
            origin[2] + (k >> 4 & 3),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cell_at_inverts_linear_index() {
        let cells = [5, 3, 4];
        for i in 0..60 {
            let c = cell_at(cells, i);
            assert!(
                (0..3).all(|a| (0..cells[a] as i64).contains(&c[a])),
                "{c:?}"
            );
            assert_eq!(linear_index(cells, c), i);
        }
        assert_eq!(cell_at(cells, 5 + 5 * 3 * 2), [0, 1, 2]);
    }

    #[test]
    fn bricked_slots_are_a_bijection() {
        let cells = [9usize, 5, 6];
        let b = Bricked::new(cells);
        let mut seen = vec![false; b.len()];
        for z in 0..cells[2] {
            for y in 0..cells[1] {
                for x in 0..cells[0] {
                    let i = b.index([x as i64, y as i64, z as i64]);
                    assert!(!seen[i]);
                    seen[i] = true;
                    assert_eq!(b.cell(i), [x, y, z]);
                }
            }
        }
        // Neighbours in a brick share a cache line.
        assert_eq!(b.index([4, 0, 0]) >> 6, b.index([7, 3, 3]) >> 6);
    }

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
