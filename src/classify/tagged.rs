//! Per-tagged-cell storage: a rank structure over the tag bitset that maps a
//! tagged cell to a dense slot, so data kept for tagged cells only (sub-cell
//! masks, curvature bounds) costs its size per tagged cell, not per cell.
//!
//! The bitset is one word per 4³ brick with prefix popcounts per word, so a
//! lookup is O(1) and the slots of nearby cells sit together.

use std::sync::Arc;

use rayon::prelude::*;

use super::Tags;
use crate::lattice::Bricked;

/// Dense slots of the tagged cells of one classification, shared by the
/// tables kept per tagged cell.
#[derive(Clone, Debug)]
pub struct TaggedIndex {
    bricked: Bricked,
    /// Tagged cells before each word of `words`.
    rank: Vec<u32>,
    /// The tag bitset, one word per 4³ brick ([`Tags::brick_words`]),
    /// shared with the octree that filed them.
    words: Arc<[u64]>,
    count: usize,
}

impl TaggedIndex {
    /// Bytes the index of `tags` takes (to check a memory budget first),
    /// its brick words counted even where it shares the octree's.
    pub fn bytes_for(tags: &Tags) -> usize {
        Bricked::new(tags.cells).len() / 64 * 12
    }

    pub fn build(tags: &Tags) -> TaggedIndex {
        let bricked = Bricked::new(tags.cells);
        TaggedIndex::from_brick_words(bricked, tags.brick_words(&bricked).into())
    }

    /// The index over tags already filed in bricks (`words`, one per brick
    /// of `bricked`: [`Tags::brick_words`]), sharing them.
    pub fn from_brick_words(bricked: Bricked, words: Arc<[u64]>) -> TaggedIndex {
        assert_eq!(words.len() * 64, bricked.len(), "a word per brick");
        let mut rank = Vec::with_capacity(words.len());
        let mut acc = 0u32;
        for w in words.iter() {
            rank.push(acc);
            acc += w.count_ones();
        }
        TaggedIndex {
            bricked,
            rank,
            words,
            count: acc as usize,
        }
    }

    /// The brick layout the index is kept in.
    pub fn bricked(&self) -> Bricked {
        self.bricked
    }

    /// Per brick: the tag bits (bit `k` for the brick's slot `k`), and the
    /// tagged cells before it — [`TaggedIndex::slot`]'s two tables, for lane
    /// code that gathers them.
    pub fn words(&self) -> (&[u64], &[u32]) {
        (&self.words, &self.rank)
    }

    /// Tagged cells (the length of every table over this index).
    pub fn count(&self) -> usize {
        self.count
    }

    /// The slot of cell `c` (in range); `None` when the cell is not tagged.
    #[inline(always)]
    pub fn slot(&self, c: [i64; 3]) -> Option<usize> {
        let i = self.bricked.index(c);
        let (w, b) = (i >> 6, i & 63);
        let word = self.words[w];
        if (word >> b) & 1 == 0 {
            return None;
        }
        Some(self.rank[w] as usize + (word & ((1u64 << b) - 1)).count_ones() as usize)
    }

    /// `value(cell)` for every tagged cell, in slot order, in parallel.
    pub fn table<V: Send>(&self, value: impl Fn([i64; 3]) -> V + Sync + Send) -> Vec<V> {
        self.table_init(|| (), |_, c| value(c))
    }

    /// [`TaggedIndex::table`] with per-thread scratch from `init`.
    pub fn table_init<V: Send, W>(
        &self,
        init: impl Fn() -> W + Sync + Send,
        value: impl Fn(&mut W, [i64; 3]) -> V + Sync + Send,
    ) -> Vec<V> {
        // Set bits only: a brick without tags costs one test, not 64.
        let mut slots: Vec<usize> = Vec::with_capacity(self.count);
        slots.extend(super::tags::set_bits(&self.words));
        slots
            .par_iter()
            .map_init(init, |w, &slot| {
                value(w, self.bricked.cell(slot).map(|v| v as i64))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tagged_cells_get_distinct_dense_slots() {
        let cells = [9usize, 6, 7];
        let tagged = |x: i64, y: i64, z: i64| (x * 5 + y * 3 + z * 7) % 4 == 1;
        let flags: Vec<u8> = (0..7i64)
            .flat_map(|z| {
                (0..6i64).flat_map(move |y| (0..9i64).map(move |x| tagged(x, y, z) as u8))
            })
            .collect();
        let n = flags.iter().filter(|&&b| b == 1).count();
        let tags = Tags::from_chunks(cells, [flags]);
        let index = TaggedIndex::build(&tags);
        assert_eq!(index.count(), n);
        // The table's value at each slot is that slot's cell.
        let table = index.table(|c| c);
        let mut seen = vec![false; n];
        for z in 0..7i64 {
            for y in 0..6i64 {
                for x in 0..9i64 {
                    let c = [x, y, z];
                    match index.slot(c) {
                        Some(s) => {
                            assert!(tags.get(c));
                            assert_eq!(table[s], c);
                            assert!(!seen[s]);
                            seen[s] = true;
                        }
                        None => assert!(!tags.get(c)),
                    }
                }
            }
        }
        assert!(seen.iter().all(|&s| s));
    }
}
