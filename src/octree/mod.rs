//! The top-down octree over classified cells (paper section 4.1).
//!
//! Level `l` has one occupancy bit per aligned block of `2^l` cells per axis,
//! set when any cell inside is tagged; level 0 is the tags themselves. A ray
//! asks, for its current cell, for the *largest* empty block containing it,
//! and jumps to where it leaves that block in one step (see `exit_block` in
//! the traversal stage), so big empty regions cost one step. The paper
//! descends from the root; the answer (the largest empty ancestor) is the
//! same climbing from the cell, which costs one probe for the tagged cells
//! where most visits happen, so [`Octree::skip_level`] climbs. Below the leaf level the tree is not consulted: inside an occupied
//! leaf the walk is a plain DDA over the cell tags. The leaf size, a traversal
//! parameter (one tree serves every leaf size), trades tree lookups per step
//! against cells stepped through one by one.

pub mod distance;

use std::sync::Arc;

use rayon::prelude::*;

pub use distance::Proximity;

use crate::classify::Tags;
use crate::lattice::Bricked;

/// Occupancy bits of one level.
#[derive(Clone, Debug)]
struct Level {
    dims: [usize; 3],
    words: Vec<u64>,
}

impl Level {
    #[inline(always)]
    fn get(&self, c: [usize; 3]) -> bool {
        let i = c[0] + self.dims[0] * (c[1] + self.dims[1] * c[2]);
        (self.words[i >> 6] >> (i & 63)) & 1 != 0
    }

    /// Parent level of the occupancy bits `words` (linear, x fastest) over
    /// `dims`: a block is occupied if any of its 2³ children is. A word at a
    /// time: the OR of a block row's (up to) four child rows, of each bit
    /// pair along x, and the pairs' even bits gathered into the parent row.
    fn coarsen(dims: [usize; 3], words: &[u64]) -> Level {
        let parent = dims.map(|n| n.div_ceil(2));
        let wc = parent[0].div_ceil(64);
        let wf = dims[0].div_ceil(64);
        let rows: Vec<Vec<u64>> = (0..parent[2])
            .into_par_iter()
            .map(|z| {
                let mut out = vec![0u64; parent[1] * wc];
                // Two parent words take four child words (`2·wc ≥ wf`).
                let mut any = vec![0u64; 2 * wc];
                let mut child = vec![0u64; wf];
                for y in 0..parent[1] {
                    any.fill(0);
                    for cz in (2 * z..2 * z + 2).filter(|&c| c < dims[2]) {
                        for cy in (2 * y..2 * y + 2).filter(|&c| c < dims[1]) {
                            let start = dims[0] * (cy + dims[1] * cz);
                            crate::classify::tags::row_bits(words, start, dims[0], &mut child);
                            for (a, c) in any.iter_mut().zip(&child) {
                                *a |= c;
                            }
                        }
                    }
                    for (j, o) in out[y * wc..][..wc].iter_mut().enumerate() {
                        let lo = even_bits(any[2 * j] | any[2 * j] >> 1);
                        let hi = even_bits(any[2 * j + 1] | any[2 * j + 1] >> 1);
                        *o = lo | hi << 32;
                    }
                }
                out
            })
            .collect();
        let (words, _) = crate::classify::tags::pack_rows(parent, rows);
        Level {
            dims: parent,
            words,
        }
    }
}

/// Bits 0, 2, 4, … 62 of `x` as bits 0 … 31.
#[inline(always)]
fn even_bits(x: u64) -> u64 {
    let mut x = x & 0x5555_5555_5555_5555;
    x = (x | x >> 1) & 0x3333_3333_3333_3333;
    x = (x | x >> 2) & 0x0f0f_0f0f_0f0f_0f0f;
    x = (x | x >> 4) & 0x00ff_00ff_00ff_00ff;
    x = (x | x >> 8) & 0x0000_ffff_0000_ffff;
    (x | x >> 16) & 0x0000_0000_ffff_ffff
}

/// Occupancy pyramid over cell tags, flattened for traversal.
#[derive(Clone, Debug)]
pub struct Octree {
    tags: Tags,
    /// `levels[l - 1]` is level `l` (level 0 is `tags`).
    levels: Vec<Level>,
    /// Per cell: [`TAGGED`], or the level of the largest empty block holding
    /// it — the answer of a descent through `levels`, precomputed, so a
    /// traversal step is one byte load instead of a walk down the tree.
    /// Stored in 4³ bricks ([`Bricked`]) for locality along rays.
    skip: Vec<u8>,
    /// The level every empty 2³ block of a brick shares, a byte per brick
    /// ([`Octree::brick_levels`]): with the brick's tag word, every cell's
    /// skip byte, from 1/64 of the skip map.
    brick_levels: Vec<u8>,
    bricked: Bricked,
    /// The tags filed in `bricked`, a word per brick ([`Tags::brick_words`]):
    /// the skip map is made from them, and the tagged-cell index shares them
    /// ([`Octree::brick_tags`]).
    brick_tags: Arc<[u64]>,
    /// Box of cells holding every tag ([`Tags::bounds`]).
    bounds: Option<[[usize; 3]; 2]>,
}

/// Marks a tagged cell in the flattened skip map.
pub const TAGGED: u8 = u8::MAX;

impl Octree {
    /// Builds every level up to the root (a single block covering the lattice).
    pub fn build(tags: Tags) -> Octree {
        let mut levels: Vec<Level> = Vec::new();
        let mut dims = tags.cells;
        while dims.iter().any(|&d| d > 1) {
            let next = match levels.last() {
                None => Level::coarsen(dims, tags.words()),
                Some(prev) => Level::coarsen(prev.dims, &prev.words),
            };
            dims = next.dims;
            levels.push(next);
        }
        let bricked = Bricked::new(tags.cells);
        let brick_tags: Arc<[u64]> = tags.brick_words(&bricked).into();
        let brick_levels = brick_levels(&levels, &bricked);
        let skip = flatten(&tags, &brick_tags, &brick_levels, &bricked);
        let bounds = tags.bounds();
        Octree {
            tags,
            levels,
            skip,
            brick_levels,
            bricked,
            brick_tags,
            bounds,
        }
    }

    /// The tags a word per 4³ brick of [`Octree::bricked`], as
    /// [`TaggedIndex::from_brick_words`] takes them.
    ///
    /// [`TaggedIndex::from_brick_words`]: crate::classify::tagged::TaggedIndex::from_brick_words
    pub fn brick_tags(&self) -> Arc<[u64]> {
        self.brick_tags.clone()
    }

    /// [`Octree::brick_tags`] borrowed, for lane code that gathers them.
    pub fn brick_tag_words(&self) -> &[u64] {
        &self.brick_tags
    }

    /// Height of the tree: the root is level `top()`.
    pub fn top(&self) -> u32 {
        self.levels.len() as u32
    }

    /// The smallest box of cells holding every tagged cell.
    pub fn bounds(&self) -> Option<[[usize; 3]; 2]> {
        self.bounds
    }

    pub fn tags(&self) -> &Tags {
        &self.tags
    }

    /// The flattened skip map ([`Octree::skip_byte`] per slot of
    /// [`Octree::bricked`]), for lane code that gathers it; its length is
    /// a multiple of 64.
    pub fn skip_map(&self) -> &[u8] {
        &self.skip
    }

    /// Per brick of [`Octree::bricked`], the level of the largest empty
    /// block holding each of its cells whose 2³ block holds no tagged
    /// cell (the level of the brick's own largest empty block where the
    /// brick is empty, else 1; 0 for a lattice of one cell). A cell's skip
    /// byte follows from it and the brick's tag word
    /// ([`Octree::skip_byte_from_bricks`]), so a walk over these bytes and
    /// [`Octree::brick_tags`] visits the cells it would over the skip map,
    /// from a byte per 64 cells (the teapot's 180 KB against the block
    /// map's 2.9 MB) and the tag words the tagged-cell test reads anyway.
    /// Its length is a multiple of 4.
    pub fn brick_levels(&self) -> &[u8] {
        &self.brick_levels
    }

    /// The skip byte of cell `c` (in range) from [`Octree::brick_levels`]
    /// and the brick's tag word.
    #[inline(always)]
    pub fn skip_byte_from_bricks(&self, c: [i64; 3]) -> u8 {
        let i = self.bricked.index(c);
        decode_brick(self.brick_tags[i >> 6], self.brick_levels[i >> 6], i & 63)
    }

    /// The brick layout of [`Octree::skip_map`].
    pub fn bricked(&self) -> Bricked {
        self.bricked
    }

    pub fn bytes(&self) -> usize {
        self.tags.bytes()
            + self.levels.iter().map(|l| l.words.len() * 8).sum::<usize>()
            + self.skip.len()
            + self.brick_levels.len()
            + self.brick_tags.len() * 8
    }

    /// The occupied blocks of `2^level` cells (`1 ≤ level ≤ top()`), as
    /// block coordinates: block `b` holds cells `b·2^level ..` on each axis.
    pub fn occupied_blocks(&self, level: u32) -> Vec<[usize; 3]> {
        let Some(l) = level
            .checked_sub(1)
            .and_then(|i| self.levels.get(i as usize))
        else {
            return Vec::new();
        };
        let [nx, ny, nz] = l.dims;
        let mut out = Vec::new();
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    if l.get([x, y, z]) {
                        out.push([x, y, z]);
                    }
                }
            }
        }
        out
    }

    /// The flattened map's byte for cell `c` (in range): [`TAGGED`], or the
    /// level of the largest empty block holding it.
    #[inline(always)]
    pub fn skip_byte(&self, c: [i64; 3]) -> u8 {
        self.skip[self.bricked.index(c)]
    }

    /// [`Octree::skip_level`] from the flattened map: one load.
    #[inline(always)]
    pub fn skip_level_fast(&self, c: [i64; 3], leaf_level: u32) -> Option<u32> {
        match self.skip[self.bricked.index(c)] {
            TAGGED => None,
            l if (l as u32) < leaf_level.max(1) => Some(0),
            l => Some(l as u32),
        }
    }

    /// For cell `c` (in range): `None` when the cell is tagged (solve it),
    /// else the level of the largest empty block holding it (skip that block).
    /// Blocks below `leaf_level` are not used: inside an occupied leaf the walk
    /// steps cell by cell (`leaf_level = top()` makes it a plain DDA).
    #[inline]
    pub fn skip_level(&self, c: [i64; 3], leaf_level: u32) -> Option<u32> {
        if self.tags.get(c) {
            return None;
        }
        let u = [c[0] as usize, c[1] as usize, c[2] as usize];
        // The leaf holding the cell must be empty to skip more than the cell.
        let top = self.top();
        let first = leaf_level.max(1);
        if first > top || self.levels[(first - 1) as usize].get(u.map(|v| v >> first)) {
            return Some(0);
        }
        let mut l = first;
        while l < top && !self.levels[l as usize].get(u.map(|v| v >> (l + 1))) {
            l += 1;
        }
        Some(l)
    }
}

/// The skip byte of brick cell `k` (`< 64`) from its brick's tag word and
/// level ([`Octree::brick_levels`]).
#[inline(always)]
pub fn decode_brick(word: u64, level: u8, k: usize) -> u8 {
    if word >> k & 1 == 1 {
        TAGGED
    } else if word & block_cells(k) != 0 {
        0
    } else {
        level
    }
}

/// [`Octree::brick_levels`]: per brick, the level of the largest empty
/// block holding an empty 2³ block of it (the largest `l ≥ 1` whose block
/// at every level from 2 up to `l` is empty), 0 for a lattice of one cell.
fn brick_levels(levels: &[Level], bricked: &Bricked) -> Vec<u8> {
    let top = levels.len();
    let bricks = bricked.len() / 64;
    // Padded to whole dwords, which the lane walk gathers.
    let mut out = vec![0u8; bricks.next_multiple_of(4)];
    out[..bricks]
        .par_iter_mut()
        .enumerate()
        .for_each(|(brick, o)| {
            let origin = bricked.brick_origin(brick);
            // Blocks of 4 cells and more (levels from 2) hold the whole
            // brick: their walk is the same for its 64 cells.
            let mut shared = 1.min(top);
            while shared < top && !levels[shared].get(origin.map(|v| v >> (shared + 1))) {
                shared += 1;
            }
            *o = shared as u8;
        });
    out
}

/// Per cell, the level of the largest empty aligned block holding it (the
/// largest `l` whose block at every level up to `l` is empty), or `TAGGED`.
///
/// `tag_words`: a brick's tags in one word ([`Tags::brick_words`]): its
/// cells' tags, and the level-1 blocks (2³, whole inside the brick) they
/// make, are bits of it; `brick_levels` ([`brick_levels`]) gives the rest
/// ([`decode_brick`]).
fn flatten(tags: &Tags, tag_words: &[u64], brick_levels: &[u8], bricked: &Bricked) -> Vec<u8> {
    let mut skip = vec![0u8; bricked.len()];
    // Gathered at random by the lane walk, as the distance maps are.
    crate::heap::advise_huge_pages(&mut skip);
    skip.par_chunks_mut(64)
        .zip(tag_words.par_iter().zip(brick_levels))
        .enumerate()
        .for_each(|(brick, (out, (&tagged, &level)))| {
            let origin = bricked.brick_origin(brick);
            for (k, o) in out.iter_mut().enumerate() {
                let c = Bricked::cell_in(origin, k);
                if (0..3).any(|a| c[a] >= tags.cells[a]) {
                    continue; // padding: never visited
                }
                *o = decode_brick(tagged, level, k);
            }
        });
    skip
}

/// The brick bits of the 2³ block holding brick cell `k` (bit `x | y << 2 |
/// z << 4` for brick coordinates 0..4): the block's first cell clears each
/// coordinate's low bit ([`BLOCK_ORIGIN_BITS`]), and its eight cells add 0
/// or 1 to each ([`FIRST_BLOCK_CELLS`]). The lane walks shift the same
/// constants.
#[inline(always)]
fn block_cells(k: usize) -> u64 {
    FIRST_BLOCK_CELLS << (k & BLOCK_ORIGIN_BITS)
}

/// The brick bits of the 2³ block at the brick's origin.
pub const FIRST_BLOCK_CELLS: u64 = 0x0033_0033;

/// The bits of a brick cell index `k` that locate its 2³ block (each
/// coordinate's high bit).
pub const BLOCK_ORIGIN_BITS: usize = 0b10_1010;

#[cfg(test)]
mod tests {
    use super::*;

    fn tags_with(cells: [usize; 3], on: &[[usize; 3]]) -> Tags {
        let n = cells.iter().product::<usize>();
        let mut flags = vec![0u8; n];
        for c in on {
            flags[c[0] + cells[0] * (c[1] + cells[1] * c[2])] = 1;
        }
        Tags::from_chunks(cells, vec![flags])
    }

    #[test]
    fn skips_the_largest_empty_block() {
        let t = tags_with([13, 9, 5], &[[12, 8, 4], [1, 1, 1]]);
        let o = Octree::build(t);
        assert_eq!(o.top(), 4);
        assert_eq!(o.skip_level([12, 8, 4], 0), None);
        assert_eq!(o.skip_level([1, 1, 1], 0), None);
        assert_eq!(
            o.skip_level([0, 0, 0], 0),
            Some(0),
            "neighbour of a tagged cell"
        );
        // (9,0,0) lies in the empty 8-block [8,16)×[0,8)×[0,8).
        assert_eq!(o.skip_level([9, 0, 0], 0), Some(3));
        // (5,5,3): its 4-block [4,8)×[4,8)×[0,4) is empty, its 8-block holds (1,1,1).
        assert_eq!(o.skip_level([5, 5, 3], 0), Some(2));
        let empty = Octree::build(Tags::empty([13, 9, 5]));
        assert_eq!(empty.skip_level([3, 3, 3], 0), Some(4), "the root is empty");
        // The flattened map answers every cell and leaf level identically.
        for o in [&o, &empty] {
            for z in 0..5 {
                for y in 0..9 {
                    for x in 0..13 {
                        for leaf in 0..5 {
                            let c = [x, y, z];
                            assert_eq!(
                                o.skip_level(c, leaf),
                                o.skip_level_fast(c, leaf),
                                "{c:?} leaf {leaf}"
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn leaves_fall_back_to_cell_tags() {
        let t = tags_with([16, 16, 16], &[[5, 5, 5]]);
        let o = Octree::build(t);
        assert_eq!(o.skip_level([5, 5, 5], 2), None);
        assert_eq!(
            o.skip_level([4, 4, 4], 2),
            Some(0),
            "same leaf: step cell by cell"
        );
        assert_eq!(o.skip_level([12, 12, 12], 2), Some(3));
        // A leaf level at the root makes it a plain DDA over the tags.
        assert_eq!(o.skip_level([12, 12, 12], o.top()), Some(0));
    }

    /// The cells of a lattice of `cells` that a uniform draw from `seed`
    /// puts under `density`.
    fn scattered(cells: [usize; 3], seed: u64, density: f64) -> Vec<[usize; 3]> {
        let n: usize = cells.iter().product();
        (0..n)
            .filter(|&k| crate::phantom::uniform(seed, k as u64) < density)
            .map(|k| crate::lattice::cell_at(cells, k).map(|v| v as usize))
            .collect()
    }

    /// The skip map, and the brick levels with the tag words, give every
    /// cell's level as the descent through the tree does: over scattered
    /// tags on lattices with partial bricks and 2³ blocks, one cell, and
    /// none.
    #[test]
    fn brick_levels_give_the_skip_bytes() {
        let mut checked = [0usize; 3];
        for (cells, seed) in [
            ([13, 9, 5], 1u64),
            ([31, 17, 22], 2),
            ([1, 1, 1], 3),
            ([2, 7, 1], 4),
            ([70, 9, 40], 5),
        ] {
            for density in [0.0, 0.0005, 0.002, 0.05, 0.5] {
                let on = scattered(cells, seed, density);
                let o = Octree::build(tags_with(cells, &on));
                assert!(o.brick_levels().len().is_multiple_of(4));
                assert!(o.brick_levels().len() * 64 >= o.skip_map().len());
                for z in 0..cells[2] as i64 {
                    for y in 0..cells[1] as i64 {
                        for x in 0..cells[0] as i64 {
                            let b = o.skip_level([x, y, z], 0).map_or(TAGGED, |l| l as u8);
                            assert_eq!(o.skip_byte([x, y, z]), b, "{cells:?} {x},{y},{z}");
                            assert_eq!(
                                o.skip_byte_from_bricks([x, y, z]),
                                b,
                                "{cells:?} {x},{y},{z}"
                            );
                            checked[match b {
                                TAGGED => 0,
                                0 => 1,
                                _ => 2,
                            }] += 1;
                        }
                    }
                }
            }
        }
        assert!(checked.iter().all(|&k| k > 100), "{checked:?}");
    }

    /// The index over the octree's brick tags is the index over its tags.
    #[test]
    fn brick_tags_index_the_tags() {
        use crate::classify::tagged::TaggedIndex;
        for (cells, seed) in [([13usize, 9, 5], 1u64), ([1, 1, 1], 2), ([31, 2, 7], 3)] {
            let on = scattered(cells, seed, 0.1);
            let o = Octree::build(tags_with(cells, &on));
            let shared = TaggedIndex::from_brick_words(o.bricked(), o.brick_tags());
            let own = TaggedIndex::build(o.tags());
            assert_eq!(shared.count(), own.count());
            assert_eq!(shared.words(), own.words());
            for k in 0..cells.iter().product() {
                let c = crate::lattice::cell_at(cells, k);
                assert_eq!(shared.slot(c), own.slot(c), "{cells:?} {c:?}");
            }
        }
    }

    /// Every level's bits are the OR of its 2³ children, checked cell by
    /// cell against the level below, and each cell's skip byte is the climb
    /// through them; on lattices whose rows end inside a word, fill one or
    /// two exactly, or span several, with odd extents.
    #[test]
    fn levels_are_the_or_of_their_children() {
        for (cells, seed) in [
            ([13usize, 9, 5], 1u64),
            ([64, 3, 3], 2),
            ([128, 2, 5], 3),
            ([129, 5, 2], 4),
            ([300, 3, 3], 5),
            ([1, 1, 1], 6),
            ([1, 7, 3], 7),
        ] {
            for density in [0.0, 0.003, 0.05, 0.6] {
                let on = scattered(cells, seed, density);
                let o = Octree::build(tags_with(cells, &on));
                let below = |c: [usize; 3], l: usize| -> bool {
                    if l == 0 {
                        o.tags.get(c.map(|v| v as i64))
                    } else {
                        o.levels[l - 1].get(c)
                    }
                };
                let mut fine = cells;
                for (l, level) in o.levels.iter().enumerate() {
                    assert_eq!(level.dims, fine.map(|v| v.div_ceil(2)));
                    let [px, py, pz] = level.dims;
                    for z in 0..pz {
                        for y in 0..py {
                            for x in 0..px {
                                let mut want = false;
                                for d in 0..8 {
                                    let c =
                                        [2 * x + (d & 1), 2 * y + (d >> 1 & 1), 2 * z + (d >> 2)];
                                    if (0..3).all(|a| c[a] < fine[a]) {
                                        want |= below(c, l);
                                    }
                                }
                                assert_eq!(
                                    level.get([x, y, z]),
                                    want,
                                    "{cells:?} level {} {x},{y},{z}",
                                    l + 1
                                );
                            }
                        }
                    }
                    // Nothing set past the level's cells.
                    let bits = level.dims.iter().product::<usize>();
                    if bits % 64 != 0 {
                        assert_eq!(level.words.last().unwrap() >> (bits % 64), 0);
                    }
                    fine = level.dims;
                }
                // The skip map: the level below the first occupied ancestor.
                for z in 0..cells[2] {
                    for y in 0..cells[1] {
                        for x in 0..cells[0] {
                            let c = [x, y, z];
                            let want = if o.tags.get(c.map(|v| v as i64)) {
                                TAGGED
                            } else {
                                let mut l = 0;
                                while l < o.levels.len()
                                    && !o.levels[l].get(c.map(|v| v >> (l + 1)))
                                {
                                    l += 1;
                                }
                                l as u8
                            };
                            assert_eq!(o.skip_byte(c.map(|v| v as i64)), want, "{cells:?} {c:?}");
                        }
                    }
                }
            }
        }
    }
}
