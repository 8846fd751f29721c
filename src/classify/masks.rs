//! Sub-cell masks of the tagged cells: which of a cell's 4³ sub-cells the
//! classification keeps — the Bézier hull ([`SubCells`]) or ACCC per
//! sub-cell ([`SubCellBounds`]) — so the traversal hands the solve stage
//! only segments that meet one.
//!
//! Only tagged cells get a mask (8 bytes each, in [`TaggedIndex`] slots).

use std::sync::Arc;

use super::accc_sub::SubCellBounds;
use super::bezier::SubCells;
use super::slack;
use super::tagged::TaggedIndex;
use super::tags::Tags;
use crate::filter::Field;
use crate::filter::coeffs::Coefficient;

/// Sub-cell masks by linear cell index (x fastest), ascending, as the
/// classification finds them ([`crate::classify::bezier::refine_with_masks`],
/// [`crate::classify::accc_sub_with_masks`]) before the tagged cells have
/// slots.
pub type LinearMasks = Vec<(usize, u64)>;

/// One z slab's tags as a classification decides them: rows of
/// `⌈nx/64⌉` words ([`Tags::from_row_words`]), set one cell at a time.
pub(crate) struct SlabTags {
    nx: usize,
    /// Words per row, `⌈nx/64⌉`.
    row: usize,
    words: Vec<u64>,
}

impl SlabTags {
    /// No cell of a slab of `[nx, ny]` cells tagged.
    pub(crate) fn new(nx: usize, ny: usize) -> SlabTags {
        let row = nx.div_ceil(64);
        SlabTags {
            nx,
            row,
            words: vec![0u64; ny * row],
        }
    }

    /// Tags the slab's cell at `i` (`x + nx·y`).
    #[inline]
    pub(crate) fn set(&mut self, i: usize) {
        let (y, x) = (i / self.nx, i % self.nx);
        self.words[y * self.row + (x >> 6)] |= 1 << (x & 63);
    }
}

/// The tags and masks of a classification that decided the lattice `cells`
/// one z slab at a time (each slab's tags, and its masks in ascending
/// order), joined in slab order.
pub(crate) fn join_slabs(
    cells: [usize; 3],
    slabs: Vec<(SlabTags, LinearMasks)>,
) -> (Tags, LinearMasks) {
    let mut all = Vec::new();
    let mut chunks = Vec::with_capacity(slabs.len());
    for (tags, masks) in slabs {
        chunks.push(tags.words);
        all.extend(masks);
    }
    (Tags::from_row_words(cells, chunks), all)
}

/// Sub-cell masks of the tagged cells of one classification.
#[derive(Clone, Debug)]
pub struct SubCellMasks {
    index: Arc<TaggedIndex>,
    /// Per tagged cell, in slot order: the 4³ sub-cells that can hold the
    /// iso-surface.
    masks: Vec<u64>,
}

impl SubCellMasks {
    /// Bytes the masks of `count` tagged cells take (to check a memory
    /// budget first).
    pub fn bytes_for(count: usize) -> usize {
        count * 8
    }

    /// Masks of every tagged cell of `index` by the Bézier hull, for the (separated) iso-value
    /// `iso`.
    pub fn build<T: Coefficient>(
        field: &Field<T>,
        index: Arc<TaggedIndex>,
        iso: f64,
    ) -> SubCellMasks {
        let eps = slack(field);
        let masks = index.table_init(
            || SubCells::new(field),
            |sub, cell| sub.cell_mask(field, cell, iso, eps),
        );
        SubCellMasks { index, masks }
    }

    /// Masks of every tagged cell of `index` by ACCC per `n³` sub-cells
    /// ([`SubCellBounds::cell_mask`]) for the (separated) iso-value `iso`.
    pub fn build_accc<T: Coefficient>(
        field: &Field<T>,
        index: Arc<TaggedIndex>,
        iso: f64,
        n: usize,
    ) -> SubCellMasks {
        let bounds = SubCellBounds::new(field.kernel(), n);
        let masks = index.table_init(
            || bounds.scratch(),
            |w, cell| {
                crate::with_isa!(crate::simd::Isa::current(), _L, _M => {
                    bounds.cell_mask(field, cell, iso, w)
                })
            },
        );
        SubCellMasks { index, masks }
    }

    /// The masks [`crate::classify::classify_with_masks`] found along
    /// with the tags `index` was built from: `(linear cell index, mask)` for
    /// the tagged cells of a lattice of `cells`; `None` unless every tagged
    /// cell has exactly one.
    pub fn from_linear(
        index: Arc<TaggedIndex>,
        cells: [usize; 3],
        linear: &[(usize, u64)],
    ) -> Option<SubCellMasks> {
        if linear.len() != index.count() {
            return None;
        }
        let mut masks = vec![0u64; index.count()];
        let mut filled = vec![false; index.count()];
        let [nx, ny, nz] = cells;
        for &(i, mask) in linear {
            if i >= nx * ny * nz {
                return None;
            }
            let c = crate::lattice::cell_at(cells, i);
            let slot = index.slot(c)?;
            if std::mem::replace(&mut filled[slot], true) {
                return None;
            }
            masks[slot] = mask;
        }
        Some(SubCellMasks { index, masks })
    }

    /// The index the masks are kept in, and the masks in its slot order
    /// (for lane code that gathers them).
    pub fn parts(&self) -> (&TaggedIndex, &[u64]) {
        (&self.index, &self.masks)
    }

    /// The mask of cell `c` (in range); `None` when the cell is not tagged.
    #[inline(always)]
    pub fn get(&self, c: [i64; 3]) -> Option<u64> {
        self.index.slot(c).map(|s| self.masks[s])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classify::bezier::{bernstein_weights, cell_bernstein};
    use crate::classify::{Method, classify};
    use crate::filter::FilterKind;

    /// A cubic B-spline field of scrambled samples and an iso-value
    /// through it.
    fn noisy_bspline3() -> (Field<f64>, f64) {
        let dims = [11usize, 9, 10];
        let vol = crate::volume::scrambled_u8(dims, 13);
        let f = Field::new(&vol, FilterKind::BSpline(3));
        let iso = f.separating_iso(120.0);
        (f, iso)
    }

    #[test]
    fn masks_found_by_the_classification_file_into_their_slots() {
        let (f, iso) = noisy_bspline3();
        let (c, found) = crate::classify::classify_with_masks(&f, iso, Method::Bezier(2), 1 << 30);
        let found = found.expect("within budget");
        let index = Arc::new(TaggedIndex::build(&c.tags));
        let filed = SubCellMasks::from_linear(index.clone(), c.tags.cells, &found).unwrap();
        let built = SubCellMasks::build(&f, index.clone(), iso);
        assert_eq!(filed.masks, built.masks);
        // A list that is not one mask per tagged cell is refused.
        assert!(SubCellMasks::from_linear(index.clone(), c.tags.cells, &found[1..]).is_none());
        let mut twice = found.clone();
        twice[1] = twice[0];
        assert!(SubCellMasks::from_linear(index, c.tags.cells, &twice).is_none());
        // No budget, no masks.
        assert!(
            crate::classify::classify_with_masks(&f, iso, Method::Bezier(2), 0)
                .1
                .is_none()
        );
    }

    #[test]
    fn sub_cell_accc_masks_file_as_built_and_match_their_tags() {
        let (f, iso) = noisy_bspline3();
        for n in [2u8, 4, 8] {
            let method = Method::AcccSub(n);
            let (c, found) = crate::classify::classify_with_masks(&f, iso, method, 1 << 30);
            assert_eq!(
                c.tags,
                classify(&f, iso, method).tags,
                "accc{n}: the same tags"
            );
            let index = Arc::new(TaggedIndex::build(&c.tags));
            let filed = SubCellMasks::from_linear(index.clone(), c.tags.cells, &found.unwrap());
            let built = SubCellMasks::build_accc(&f, index, iso, n as usize);
            assert_eq!(filed.unwrap().masks, built.masks, "accc{n}");
            assert!(built.masks.iter().all(|&m| m != 0));
        }
        // The plain ACCC has no sub-cells to keep.
        assert!(
            crate::classify::classify_with_masks(&f, iso, Method::Accc, 1 << 30)
                .1
                .is_none()
        );
    }

    #[test]
    fn every_tagged_cell_has_its_own_mask() {
        let (f, iso) = noisy_bspline3();
        let tags = classify(&f, iso, Method::Bezier(2)).tags;
        let m = SubCellMasks::build(&f, Arc::new(TaggedIndex::build(&tags)), iso);
        let beta = bernstein_weights(&f);
        let mut sub = SubCells::new(&f);
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
