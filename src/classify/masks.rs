//! Sub-cell masks of the tagged cells: which of a cell's 4³ sub-cells the
//! Bézier hull keeps ([`SubCells`]), so the traversal hands the solve stage
//! only segments that meet one.
//!
//! Only tagged cells get a mask (8 bytes each); a rank structure over the tag
//! bitset (prefix popcounts per 64-bit word, in 4³ bricks) maps a cell to its
//! mask in O(1), and masks of nearby cells sit together.

use rayon::prelude::*;

use super::Tags;
use super::bezier::{SubCells, bernstein_weights, cell_bernstein};
use super::slack;
use crate::filter::Field;
use crate::filter::coeffs::Coefficient;
use crate::lattice::Bricked;

/// Sub-cell masks of the tagged cells of one classification.
#[derive(Clone, Debug)]
pub struct SubCellMasks {
    bricked: Bricked,
    /// Tagged cells before each word of `words`.
    rank: Vec<u32>,
    /// The tag bitset, one word per 4³ brick.
    words: Vec<u64>,
    /// Per tagged cell, in brick order: the 4³ sub-cells that can hold the
    /// iso-surface.
    masks: Vec<u64>,
}

impl SubCellMasks {
    /// Bytes the masks of `tags` take (to check a memory budget first).
    pub fn bytes_for(tags: &Tags) -> usize {
        tags.count() * 8 + Bricked::new(tags.cells).len() / 64 * 12
    }

    /// Masks of every tagged cell for the (separated) iso-value `iso`.
    pub fn build<T: Coefficient>(field: &Field<T>, tags: &Tags, iso: f64) -> SubCellMasks {
        let bricked = Bricked::new(tags.cells);
        let mut words = vec![0u64; bricked.len() / 64];
        words.par_iter_mut().enumerate().for_each(|(brick, w)| {
            for k in 0..64 {
                let c = bricked.cell(brick * 64 + k);
                if (0..3).all(|a| c[a] < tags.cells[a]) && tags.get(c.map(|v| v as i64)) {
                    *w |= 1 << k;
                }
            }
        });
        let mut rank = Vec::with_capacity(words.len());
        let mut acc = 0u32;
        for w in &words {
            rank.push(acc);
            acc += w.count_ones();
        }
        // Tagged cells in slot order (brick by brick).
        let cells: Vec<usize> = words
            .iter()
            .enumerate()
            .flat_map(|(brick, &w)| {
                (0..64)
                    .filter(move |k| w >> k & 1 == 1)
                    .map(move |k| brick * 64 + k)
            })
            .collect();
        let s = field.kernel().support();
        let beta = bernstein_weights(field);
        let eps = slack(field);
        let masks = cells
            .par_iter()
            .map_init(
                || SubCells::new(s),
                |sub, &slot| {
                    let cell = bricked.cell(slot).map(|v| v as i64);
                    sub.mask(&cell_bernstein(field, cell, iso, &beta), eps)
                },
            )
            .collect();
        SubCellMasks {
            bricked,
            rank,
            words,
            masks,
        }
    }

    /// The mask of cell `c` (in range); `None` when the cell is not tagged.
    #[inline(always)]
    pub fn get(&self, c: [i64; 3]) -> Option<u64> {
        let i = self.bricked.index(c);
        let (w, b) = (i >> 6, i & 63);
        let word = self.words[w];
        if (word >> b) & 1 == 0 {
            return None;
        }
        let slot = self.rank[w] as usize + (word & ((1u64 << b) - 1)).count_ones() as usize;
        Some(self.masks[slot])
    }

    pub fn bytes(&self) -> usize {
        self.masks.len() * 8 + self.rank.len() * 4 + self.words.len() * 8
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classify::{Method, classify};
    use crate::filter::FilterKind;
    use crate::volume::{SampleType, Volume};

    #[test]
    fn every_tagged_cell_has_its_own_mask() {
        let dims = [11usize, 9, 10];
        let s: Vec<f32> = (0..dims.iter().product::<usize>())
            .map(|i| ((i * 7919 + 13) % 251) as f32)
            .collect();
        let vol = Volume::new(dims, [1.0; 3], SampleType::U8, s).unwrap();
        let f = Field::new(&vol, FilterKind::BSpline(3));
        let iso = f.separating_iso(120.0);
        let tags = classify(&f, iso, Method::Bezier(2)).tags;
        let m = SubCellMasks::build(&f, &tags, iso);
        let beta = bernstein_weights(&f);
        let mut sub = SubCells::new(4);
        let mut seen = 0;
        for z in 0..tags.cells[2] as i64 {
            for y in 0..tags.cells[1] as i64 {
                for x in 0..tags.cells[0] as i64 {
                    let c = [x, y, z];
                    match m.get(c) {
                        Some(mask) => {
                            assert!(tags.get(c));
                            let want = sub.mask(&cell_bernstein(&f, c, iso, &beta), slack(&f));
                            assert_eq!(mask, want, "{c:?}");
                            seen += 1;
                        }
                        None => assert!(!tags.get(c)),
                    }
                }
            }
        }
        assert_eq!(seen, tags.count());
        assert!(seen > 50);
    }
}
