//! One bit per knot cell: "may hold the iso-surface".

use crate::lattice::{Bricked, Lattice};

/// A bitset over the cells of a lattice (x fastest).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Tags {
    pub cells: [usize; 3],
    words: Vec<u64>,
    count: usize,
}

impl Tags {
    /// Packs per-cell flags (x fastest) given as consecutive byte chunks.
    pub fn from_chunks(cells: [usize; 3], chunks: impl IntoIterator<Item = Vec<u8>>) -> Tags {
        let n = cells.iter().product::<usize>();
        let mut words = vec![0u64; n.div_ceil(64)];
        let mut i = 0usize;
        let mut count = 0;
        for chunk in chunks {
            for b in chunk {
                if b != 0 {
                    words[i >> 6] |= 1 << (i & 63);
                    count += 1;
                }
                i += 1;
            }
        }
        assert_eq!(i, n, "chunks must cover every cell once");
        Tags {
            cells,
            words,
            count,
        }
    }

    /// Packs rows of cells (x fastest), each given as `⌈nx/64⌉` words whose
    /// first `nx` bits are the row's tags (bits past them are ignored), the
    /// rows in order in consecutive chunks: [`Tags::from_chunks`] for
    /// producers that work on words of bits.
    pub fn from_row_words(cells: [usize; 3], chunks: impl IntoIterator<Item = Vec<u64>>) -> Tags {
        let (words, count) = pack_rows(cells, chunks);
        Tags {
            cells,
            words,
            count,
        }
    }

    /// No cell tagged.
    pub fn empty(cells: [usize; 3]) -> Tags {
        let n = cells.iter().product::<usize>();
        Tags {
            cells,
            words: vec![0; n.div_ceil(64)],
            count: 0,
        }
    }

    pub fn len(&self) -> usize {
        self.cells.iter().product()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Number of tagged cells.
    pub fn count(&self) -> usize {
        self.count
    }

    /// The tags of cells `start..start + out.len()` (linear indices, which
    /// must be in range) as bytes, 1 where tagged: a word's worth at a time,
    /// for loops that consume whole rows.
    #[inline]
    pub fn bytes_into(&self, start: usize, out: &mut [u8]) {
        let mut i = start;
        for chunk in out.chunks_mut(64) {
            let bits = word_at(&self.words, i);
            for (k, o) in chunk.iter_mut().enumerate() {
                *o = (bits >> k) as u8 & 1;
            }
            i += chunk.len();
        }
    }

    /// The tags in the bricked layout: per 4³ brick of `bricked` (made for
    /// these cells) one word, bit `k` the brick's cell `k`
    /// ([`Bricked::cell_in`]; 0 past the lattice). Each row's tags are read
    /// a word at a time and filed four cells (one brick row) at a time.
    pub fn brick_words(&self, bricked: &Bricked) -> Vec<u64> {
        use rayon::prelude::*;
        let [nx, ny, nz] = self.cells;
        let [bx, by, _] = bricked.bricks();
        let mut out = vec![0u64; bricked.len() / 64];
        if self.cells.contains(&0) {
            return out; // no bricks (a flat lattice)
        }
        out.par_chunks_mut(bx * by).enumerate().for_each_init(
            || vec![0u64; nx.div_ceil(64)],
            |row, (zb, slab)| {
                for z in 4 * zb..(4 * zb + 4).min(nz) {
                    for y in 0..ny {
                        row_bits(&self.words, nx * (y + ny * z), nx, row);
                        let at = (y & 3) * 4 + (z & 3) * 16;
                        let bricks = &mut slab[(y >> 2) * bx..][..bx];
                        for (xb, w) in bricks.iter_mut().enumerate() {
                            let nibble = row[xb >> 4] >> (4 * (xb & 15)) & 0xf;
                            *w |= nibble << at;
                        }
                    }
                }
            },
        );
        out
    }

    /// The tagged cells' linear indices in `range` (in range), ascending:
    /// a word at a time, so untagged stretches cost a word per 64 cells.
    pub fn ones(&self, range: std::ops::Range<usize>) -> impl Iterator<Item = usize> + '_ {
        let (start, end) = (range.start, range.end.max(range.start));
        let first = start >> 6;
        let last = end.div_ceil(64);
        (first..last).flat_map(move |w| {
            let mut bits = self.words[w];
            if w == first {
                bits &= u64::MAX << (start & 63);
            }
            if w + 1 == last && end & 63 != 0 {
                bits &= u64::MAX >> (64 - (end & 63));
            }
            word_ones(w, bits)
        })
    }

    #[inline(always)]
    pub fn get_index(&self, i: usize) -> bool {
        (self.words[i >> 6] >> (i & 63)) & 1 != 0
    }

    /// The tag of cell `c` (which must be in range).
    #[inline(always)]
    pub fn get(&self, c: [i64; 3]) -> bool {
        self.get_index(crate::lattice::linear_index(self.cells, c))
    }

    /// True when every tag here is also set in `other`.
    pub fn is_subset_of(&self, other: &Tags) -> bool {
        self.cells == other.cells
            && self
                .words
                .iter()
                .zip(&other.words)
                .all(|(a, b)| a & !b == 0)
    }

    /// Cells tagged in both (the intersection of two valid bounds is valid).
    pub fn and(&self, other: &Tags) -> Tags {
        assert_eq!(self.cells, other.cells);
        let words: Vec<u64> = self
            .words
            .iter()
            .zip(&other.words)
            .map(|(a, b)| a & b)
            .collect();
        let count = words.iter().map(|w| w.count_ones() as usize).sum();
        Tags {
            cells: self.cells,
            words,
            count,
        }
    }

    /// Cells tagged here but not in `other`.
    pub fn excess_over(&self, other: &Tags) -> usize {
        self.words
            .iter()
            .zip(&other.words)
            .map(|(a, b)| (a & !b).count_ones() as usize)
            .sum()
    }

    /// The smallest box of cells `[lo, hi]` (inclusive) holding every tagged
    /// cell, or `None` when nothing is tagged. Rays that miss this box can
    /// skip the traversal altogether.
    pub fn bounds(&self) -> Option<[[usize; 3]; 2]> {
        let mut lo = [usize::MAX; 3];
        let mut hi = [0usize; 3];
        for i in set_bits(&self.words) {
            let c = crate::lattice::cell_at(self.cells, i).map(|v| v as usize);
            for a in 0..3 {
                lo[a] = lo[a].min(c[a]);
                hi[a] = hi[a].max(c[a]);
            }
        }
        (lo[0] <= hi[0]).then_some([lo, hi])
    }

    pub fn words(&self) -> &[u64] {
        &self.words
    }

    /// Rebuilds from raw words (cache files); `None` if the size is wrong.
    pub fn from_words(cells: [usize; 3], words: Vec<u64>) -> Option<Tags> {
        let n = cells.iter().product::<usize>();
        if words.len() != n.div_ceil(64) {
            return None;
        }
        let tail = n % 64;
        if tail != 0 && words.last().is_some_and(|w| w >> tail != 0) {
            return None;
        }
        let count = words.iter().map(|w| w.count_ones() as usize).sum();
        Some(Tags {
            cells,
            words,
            count,
        })
    }

    pub fn lattice_matches(&self, lattice: &Lattice) -> bool {
        self.cells == lattice.cells
    }

    pub fn bytes(&self) -> usize {
        self.words.len() * 8
    }
}

/// Linear bits (x fastest) over `cells` from rows of `⌈nx/64⌉` words each
/// (the first `nx` bits of a row are its cells; bits past them are
/// ignored), the rows in order in consecutive chunks; and how many are set.
pub(crate) fn pack_rows(
    cells: [usize; 3],
    chunks: impl IntoIterator<Item = Vec<u64>>,
) -> (Vec<u64>, usize) {
    let n = cells.iter().product::<usize>();
    let nx = cells[0];
    let mut words = vec![0u64; n.div_ceil(64)];
    let (mut i, mut count) = (0usize, 0usize);
    for chunk in chunks {
        if nx == 0 {
            continue;
        }
        for row in chunk.chunks_exact(nx.div_ceil(64)) {
            let mut left = nx;
            for &word in row {
                let take = left.min(64);
                let word = if take < 64 {
                    word & ((1u64 << take) - 1)
                } else {
                    word
                };
                count += word.count_ones() as usize;
                let (q, r) = (i >> 6, i & 63);
                words[q] |= word << r;
                if r != 0 && r + take > 64 {
                    words[q + 1] |= word >> (64 - r);
                }
                i += take;
                left -= take;
            }
        }
    }
    assert_eq!(i, n, "rows must cover every cell once");
    (words, count)
}

/// The positions of the set bits of `words` (bit `k` of word `w` is
/// `64·w + k`), ascending: a word per 64 clear bits.
pub(crate) fn set_bits(words: &[u64]) -> impl Iterator<Item = usize> + '_ {
    words
        .iter()
        .enumerate()
        .flat_map(|(w, &bits)| word_ones(w, bits))
}

/// The set bits of `bits`, word `w` of a bitset, as bitset positions.
#[inline(always)]
fn word_ones(w: usize, mut bits: u64) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (bits != 0).then(|| {
            let k = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            64 * w + k
        })
    })
}

/// The 64 bits of `words` from bit `i` on (bits past the end read as 0).
#[inline(always)]
fn word_at(words: &[u64], i: usize) -> u64 {
    let (w, s) = (i >> 6, i & 63);
    let mut bits = words[w] >> s;
    if s != 0
        && let Some(next) = words.get(w + 1)
    {
        bits |= next << (64 - s);
    }
    bits
}

/// Bits `start .. start + len` of the linear bits `words` (which must hold
/// them) into `out` from bit 0, zero past `len` (`out` may be longer).
#[inline]
pub(crate) fn row_bits(words: &[u64], start: usize, len: usize, out: &mut [u64]) {
    for (k, o) in out.iter_mut().enumerate() {
        let take = len.saturating_sub(64 * k).min(64);
        if take == 0 {
            *o = 0;
            continue;
        }
        let bits = word_at(words, start + 64 * k);
        *o = if take < 64 {
            bits & ((1u64 << take) - 1)
        } else {
            bits
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pack_count_subset() {
        let a = Tags::from_chunks(
            [3, 2, 2],
            vec![vec![1, 0, 0, 1, 0, 0], vec![0, 0, 1, 0, 0, 1]],
        );
        assert_eq!(a.count(), 4);
        assert!(a.get([0, 0, 0]) && a.get([0, 1, 0]) && a.get([2, 0, 1]) && a.get([2, 1, 1]));
        assert!(!a.get([1, 0, 0]));
        let b = Tags::from_chunks([3, 2, 2], vec![vec![1; 12]]);
        assert!(a.is_subset_of(&b) && !b.is_subset_of(&a));
        assert_eq!(b.excess_over(&a), 8);
        let w = Tags::from_words([3, 2, 2], a.words().to_vec()).unwrap();
        assert_eq!(w, a);
        assert!(Tags::from_words([3, 2, 2], vec![u64::MAX]).is_none());
    }

    #[test]
    fn brick_words_are_the_tags() {
        for cells in [
            [13usize, 11, 6],
            [64, 4, 4],
            [130, 5, 9],
            [1, 1, 1],
            [3, 9, 2],
            [5, 0, 3],
            [0, 4, 4],
        ] {
            let n: usize = cells.iter().product();
            let flags: Vec<u8> = (0..n).map(|i| ((i * 7919) % 7 < 2) as u8).collect();
            let t = Tags::from_chunks(cells, vec![flags]);
            let bricked = Bricked::new(cells);
            let words = t.brick_words(&bricked);
            assert_eq!(words.len() * 64, bricked.len());
            for (b, &w) in words.iter().enumerate() {
                let origin = bricked.brick_origin(b);
                for k in 0..64 {
                    let c = Bricked::cell_in(origin, k);
                    let want = (0..3).all(|a| c[a] < cells[a]) && t.get(c.map(|v| v as i64));
                    assert_eq!(w >> k & 1 == 1, want, "{cells:?} brick {b} cell {k}");
                }
            }
        }
    }

    /// Every fifth cell of a 13×11×2 lattice tagged: rows end inside
    /// words and runs cross them. The flags (a byte per cell) and the tags.
    fn scattered_tags() -> (Vec<u8>, Tags) {
        let cells = [13usize, 11, 2];
        let n = cells.iter().product::<usize>();
        let flags: Vec<u8> = (0..n).map(|i| ((i * 7919) % 5 == 0) as u8).collect();
        let t = Tags::from_chunks(cells, vec![flags.clone()]);
        (flags, t)
    }

    #[test]
    fn ones_are_the_tagged_cells_in_range() {
        let (flags, t) = scattered_tags();
        let n = flags.len();
        for start in 0..n {
            for end in [start, start + 1, start + 63, start + 64, start + 130, n] {
                let end = end.min(n);
                let want: Vec<usize> = (start..end).filter(|&i| flags[i] == 1).collect();
                assert_eq!(
                    t.ones(start..end).collect::<Vec<_>>(),
                    want,
                    "{start}..{end}"
                );
            }
        }
    }

    #[test]
    fn row_bytes_are_the_tags() {
        // Every start and length, across word boundaries and to the end.
        let (flags, t) = scattered_tags();
        let n = flags.len();
        for start in 0..n {
            for len in [0, 1, 13, 63, 64, 65, 130, n - start] {
                let len = len.min(n - start);
                let mut out = vec![9u8; len];
                t.bytes_into(start, &mut out);
                assert_eq!(out, flags[start..start + len], "start {start} len {len}");
            }
        }
    }
}
