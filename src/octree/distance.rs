//! Empty-space skipping by distance: beyond the paper's octree.
//!
//! A ray only ever moves *ahead*, into the octant of its direction's signs.
//! So for each of the eight octants every cell stores the edge `k` of the
//! largest cube of cells anchored at it and reaching ahead into that octant
//! (`c + [0, k-1]³` with the octant's signs) that holds no tagged cell: 0 for
//! a tagged cell, saturating at 255, cells past the lattice counting as
//! empty. A ray in a cell with `k > 0` jumps to where it leaves that cube in
//! one step.
//!
//! The octree can only skip *aligned* blocks, which shrink to single cells
//! next to a surface whatever the ray's direction; a cube centred on the ray
//! (the chessboard distance) must stop at surfaces behind and beside it too.
//! The octant cube ignores everything behind the ray: it holds the part of
//! the centred cube ahead, so it is never smaller, and a ray leaving a surface
//! sees the open space at once. Single thread, the glass sphere: 15.4 cells
//! visited per ray with the octree, 15.6 with centred cubes, 7.4 with octant
//! cubes.
//!
//! Eight maps cost a byte per cell each; beyond [`OCTANT_BUDGET`] a single
//! centred map is built instead (one byte per cell, the exact chessboard
//! distance transform), and the walk jumps over centred cubes.
//!
//! Both maps are stored in 4³ bricks ([`Bricked`]) like the octree's skip map,
//! so a ray's successive loads stay in few cache lines.

use rayon::prelude::*;

use crate::classify::Tags;
use crate::lattice::Bricked;

/// Largest memory the eight octant maps may take.
pub const OCTANT_BUDGET: usize = 2 << 30;

#[derive(Clone, Debug)]
pub struct Proximity {
    cells: [usize; 3],
    bricked: Bricked,
    reach: Reach,
}

#[derive(Clone, Debug)]
enum Reach {
    /// Per octant (bit `a` set: negative direction along axis `a`), the edge
    /// of the empty cube anchored at each cell reaching ahead: the eight
    /// maps one after another in one allocation, so the lane walk reaches
    /// each lane's octant by an offset from one base.
    Octants(Vec<u8>),
    /// Chessboard distance to the nearest tagged cell: the cube of radius
    /// `d - 1` centred on the cell is empty.
    Centred(Vec<u8>),
}

/// The octant of direction `du`: bit `a` set when it points down axis `a`
/// (an axis it does not move along counts as up).
#[inline(always)]
pub fn octant(du: [f64; 3]) -> usize {
    (du[0] < 0.0) as usize | ((du[1] < 0.0) as usize) << 1 | ((du[2] < 0.0) as usize) << 2
}

/// Bytes the maps of a lattice of `cells` take at their peak: the eight
/// octant maps within [`OCTANT_BUDGET`], else the centred map and the
/// linear copy it is built in.
pub fn map_bytes(cells: [usize; 3]) -> u64 {
    let n = Bricked::new(cells).len() as u64;
    if 8 * n <= OCTANT_BUDGET as u64 {
        8 * n
    } else {
        2 * n
    }
}

impl Proximity {
    /// Octant maps of `tags` when they fit [`OCTANT_BUDGET`], else the
    /// centred map.
    pub fn build(tags: &Tags) -> Proximity {
        Proximity::build_within(tags, OCTANT_BUDGET)
    }

    /// [`Proximity::build`] with an explicit budget for the octant maps.
    pub fn build_within(tags: &Tags, budget: usize) -> Proximity {
        let bricked = Bricked::new(tags.cells);
        // A lattice with no cells (an axis of one sample) has no maps to
        // build; no ray enters it.
        let reach = if bricked.is_empty() {
            Reach::Centred(Vec::new())
        } else if 8 * bricked.len() <= budget {
            let mut maps = vec![0u8; 8 * bricked.len()];
            // The lane walk gathers a byte per step from anywhere in them:
            // huge pages spare it most TLB misses on large lattices
            // (BENCHMARKS.md: teapot traverse 8–10% less single thread). The
            // price is paid here, once: on a 2-core VM some builds waited
            // for their huge pages (teapot: the octree step 175–211 ms in
            // 9 of 12 runs, 269–325 in 3, against 189–215 without; the
            // kernel counted no compaction stalls).
            crate::heap::advise_huge_pages(&mut maps);
            maps.par_chunks_mut(bricked.len())
                .enumerate()
                .for_each(|(o, map)| octant_map(tags, o, map));
            Reach::Octants(maps)
        } else {
            let mut map = vec![0u8; bricked.len()];
            crate::heap::advise_huge_pages(&mut map);
            to_bricked(tags.cells, &centred_map(tags), &mut map);
            Reach::Centred(map)
        };
        Proximity {
            cells: tags.cells,
            bricked,
            reach,
        }
    }

    /// Whether the octant maps were built (else the centred map).
    pub fn is_octant(&self) -> bool {
        matches!(self.reach, Reach::Octants(_))
    }

    /// The map a ray heading into `octant` reads: chosen once per ray, so
    /// each step of its walk is one load instead of a chain through the
    /// map's variant and the octant's table.
    #[inline(always)]
    pub fn map_for(&self, octant: usize) -> ReachMap<'_> {
        let (bytes, centred) = match &self.reach {
            Reach::Octants(maps) => (
                &maps[octant * self.bricked.len()..][..self.bricked.len()],
                false,
            ),
            Reach::Centred(map) => (&map[..], true),
        };
        ReachMap {
            bricked: self.bricked,
            bytes,
            centred,
        }
    }

    pub fn cells(&self) -> [usize; 3] {
        self.cells
    }

    pub fn bytes(&self) -> usize {
        self.lane_maps().0.len()
    }

    /// For the lane walk: every map's bytes, the distance from one octant's
    /// map to the next (0 for the single centred map), whether the cubes
    /// are centred, and the bricked layout they share.
    pub fn lane_maps(&self) -> (&[u8], usize, bool, Bricked) {
        match &self.reach {
            Reach::Octants(maps) => (maps, self.bricked.len(), false, self.bricked),
            Reach::Centred(map) => (map, 0, true, self.bricked),
        }
    }
}

/// One ray's view of a [`Proximity`] ([`Proximity::map_for`]).
#[derive(Clone, Copy, Debug)]
pub struct ReachMap<'a> {
    bricked: Bricked,
    bytes: &'a [u8],
    /// Centred cubes (else cubes anchored at the cell, reaching ahead).
    centred: bool,
}

impl ReachMap<'_> {
    /// The empty box a ray in cell `c` (in range) heading into this map's
    /// octant may jump over, as the cells it reaches behind and ahead of `c`
    /// on every axis; `None` when `c` is tagged.
    #[inline(always)]
    pub fn empty_reach(&self, c: [i64; 3]) -> Option<(i64, i64)> {
        match self.bytes[self.bricked.index(c)] as i64 {
            0 => None,
            k if self.centred => Some((k - 1, k - 1)),
            k => Some((0, k - 1)),
        }
    }
}

/// An x-fastest map into `out` in the bricked layout: a brick's rows of 4
/// cells are contiguous in both, so rows move 4 bytes at a time.
fn to_bricked(cells: [usize; 3], linear: &[u8], out: &mut [u8]) {
    let bricked = Bricked::new(cells);
    let [nx, ny, nz] = cells;
    debug_assert_eq!(out.len(), bricked.len());
    for z in 0..nz {
        for y in 0..ny {
            let row = &linear[nx * (y + ny * z)..][..nx];
            for (x0, run) in row.chunks(4).enumerate() {
                let at = bricked.index([4 * x0 as i64, y as i64, z as i64]);
                out[at..at + run.len()].copy_from_slice(run);
            }
        }
    }
}

/// The octant map for octant `o` into `out`, in the bricked layout.
///
/// The cube of edge `k` anchored at `c` is `c` and the cubes of edge `k - 1`
/// anchored at its seven neighbours ahead, so `D(c) = 1 + min D(c + e)` over
/// those neighbours (0 when tagged). Sweeping from the far corner, the six
/// neighbours in the next row or slab are already final and combine as a
/// vector along the row; only the neighbour ahead in the row is a recurrence,
/// solved in whole-row vector passes ([`row_reach`]).
///
/// The sweep keeps two slabs of `D` (the one it fills and the one ahead)
/// and files each finished row into the bricked map: a whole lattice of
/// `D` per octant, written and copied, was most of the build (the
/// teapot's eight were 92 MB of fresh pages for the kernel to clear).
fn octant_map(tags: &Tags, o: usize, out: &mut [u8]) {
    let [nx, ny, nz] = tags.cells;
    if nx * ny * nz == 0 {
        return;
    }
    let bricked = Bricked::new(tags.cells);
    let neg = [o & 1 != 0, o & 2 != 0, o & 4 != 0];
    // Visiting order along an axis: the cell ahead comes first.
    let order = |n: usize, neg: bool| -> Vec<usize> {
        if neg {
            (0..n).collect()
        } else {
            (0..n).rev().collect()
        }
    };
    let ahead = |v: usize, n: usize, neg: bool| -> Option<usize> {
        if neg {
            v.checked_sub(1)
        } else {
            (v + 1 < n).then_some(v + 1)
        }
    };
    // The slab being filled and the one ahead of it, rows of `nx`.
    let (mut slab, mut ahead_slab) = (vec![0u8; nx * ny], vec![0u8; nx * ny]);
    // G(x): the three final neighbours at the same x; E(x): 1 + the six
    // of them (0 where tagged); the row's tags as bytes; scratch.
    let mut g = vec![255u8; nx];
    let mut e = vec![0u8; nx];
    let mut tagged = vec![0u8; nx];
    let mut scratch = vec![0u8; nx];
    for &z in &order(nz, neg[2]) {
        let za = ahead(z, nz, neg[2]);
        for &y in &order(ny, neg[1]) {
            let ya = ahead(y, ny, neg[1]);
            g.fill(255);
            let mut take = |r: &[u8]| {
                for (gx, &v) in g.iter_mut().zip(r) {
                    *gx = (*gx).min(v);
                }
            };
            if let Some(ya) = ya {
                take(&slab[nx * ya..][..nx]);
            }
            if za.is_some() {
                take(&ahead_slab[nx * y..][..nx]);
                if let Some(ya) = ya {
                    take(&ahead_slab[nx * ya..][..nx]);
                }
            }
            tags.bytes_into(nx * (y + ny * z), &mut tagged);
            // F(x) = min(G(x), G(x ahead)); E(x) = 1 + F(x), or 0 where
            // tagged (`t` is 0 or 1: all ones keeps the value, all zeros
            // clears it).
            let keep = |f: u8, t: u8| f.saturating_add(1) & t.wrapping_sub(1);
            if neg[0] {
                e[0] = keep(g[0], tagged[0]);
                for x in 1..nx {
                    e[x] = keep(g[x].min(g[x - 1]), tagged[x]);
                }
            } else {
                e[nx - 1] = keep(g[nx - 1], tagged[nx - 1]);
                for x in 0..nx - 1 {
                    e[x] = keep(g[x].min(g[x + 1]), tagged[x]);
                }
            }
            let row = &mut slab[nx * y..][..nx];
            row_reach(&mut e, &mut scratch, neg[0]);
            row.copy_from_slice(&e);
            // A brick's rows of 4 cells are contiguous in both layouts, and
            // bricks along x are 64 slots apart.
            // (Fixed-size copies: a slice's length would call `memmove`.)
            let first = bricked.index([0, y as i64, z as i64]);
            let mut runs = row.chunks_exact(4);
            for (x0, run) in runs.by_ref().enumerate() {
                let at = first + 64 * x0;
                out[at..at + 4].copy_from_slice(run);
            }
            let rest = runs.remainder();
            if !rest.is_empty() {
                let at = first + 64 * (nx / 4);
                out[at..at + rest.len()].copy_from_slice(rest);
            }
        }
        std::mem::swap(&mut slab, &mut ahead_slab);
    }
}

/// Solves a row's recurrence `D(x) = min(E(x), D(x ahead) + 1)` (saturating
/// at 255, which past the row's end is) in place of `E`: `D(x)` is the
/// least `E(x + j) + j` over the cells `j` ahead, and passes with offsets 1,
/// 2, 4, … each double the reach — whole-row minimums and saturating adds
/// the compiler puts in vector lanes, where the cell-by-cell recurrence was a
/// chain of three dependent instructions per cell. `ahead_is_lower`: the
/// cell ahead is at `x - 1` (else `x + 1`).
fn row_reach(d: &mut Vec<u8>, scratch: &mut Vec<u8>, ahead_is_lower: bool) {
    let n = d.len();
    let mut k = 1usize;
    // Offsets past 255 cannot lower a saturated sum.
    while k < n.min(256) {
        let step = k as u8;
        let (src, dst) = (&d[..], &mut scratch[..]);
        if ahead_is_lower {
            dst[..k].copy_from_slice(&src[..k]);
            for ((o, &here), &there) in dst[k..].iter_mut().zip(&src[k..]).zip(src) {
                *o = here.min(there.saturating_add(step));
            }
        } else {
            dst[n - k..].copy_from_slice(&src[n - k..]);
            for ((o, &here), &there) in dst.iter_mut().zip(src).zip(&src[k..]) {
                *o = here.min(there.saturating_add(step));
            }
        }
        std::mem::swap(d, scratch);
        k *= 2;
    }
}

/// The chessboard distance to the nearest tagged cell, x-fastest: two raster
/// passes with the full 26-neighbourhood and unit weights compute it exactly
/// (Rosenfeld & Pfaltz 1966, in 3-D).
fn centred_map(tags: &Tags) -> Vec<u8> {
    let [nx, ny, nz] = tags.cells;
    let n = nx * ny * nz;
    let mut d: Vec<u8> = (0..n)
        .map(|i| if tags.get_index(i) { 0 } else { 255 })
        .collect();
    let idx = |x: usize, y: usize, z: usize| x + nx * (y + ny * z);
    for forward in [true, false] {
        let zs: Vec<usize> = if forward {
            (0..nz).collect()
        } else {
            (0..nz).rev().collect()
        };
        for &z in &zs {
            for yi in 0..ny {
                let y = if forward { yi } else { ny - 1 - yi };
                for xi in 0..nx {
                    let x = if forward { xi } else { nx - 1 - xi };
                    let i = idx(x, y, z);
                    if d[i] == 0 {
                        continue;
                    }
                    let mut m = d[i];
                    // The 13 neighbours before (x, y, z) in this pass's order.
                    for dz in -1i64..=1 {
                        for dy in -1i64..=1 {
                            for dx in -1i64..=1 {
                                let key = (dz, dy, dx);
                                let before = if forward {
                                    key < (0, 0, 0)
                                } else {
                                    key > (0, 0, 0)
                                };
                                if !before {
                                    continue;
                                }
                                let q = [x as i64 + dx, y as i64 + dy, z as i64 + dz];
                                if (0..3).any(|a| q[a] < 0 || q[a] >= tags.cells[a] as i64) {
                                    continue;
                                }
                                let v = d[idx(q[0] as usize, q[1] as usize, q[2] as usize)];
                                m = m.min(v.saturating_add(1));
                            }
                        }
                    }
                    d[i] = m;
                }
            }
        }
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lattice_without_cells_builds_without_maps() {
        // A volume with an axis of one sample has no cells.
        for cells in [[0, 4, 4], [3, 0, 1], [0, 0, 0]] {
            let tags = Tags::from_words(cells, Vec::new()).unwrap();
            for budget in [0, OCTANT_BUDGET] {
                let p = Proximity::build_within(&tags, budget);
                assert_eq!(p.cells, cells);
            }
        }
    }

    fn random_tags(cells: [usize; 3], per_mille: usize) -> (Tags, Vec<[usize; 3]>) {
        let n = cells.iter().product::<usize>();
        let on: Vec<usize> = (0..n)
            .filter(|i| (i * 2654435761usize) % 1000 < per_mille)
            .collect();
        let mut flags = vec![0u8; n];
        for &i in &on {
            flags[i] = 1;
        }
        let at = |i: usize| {
            [
                i % cells[0],
                i / cells[0] % cells[1],
                i / (cells[0] * cells[1]),
            ]
        };
        (
            Tags::from_chunks(cells, vec![flags]),
            on.into_iter().map(at).collect(),
        )
    }

    fn each_cell(cells: [usize; 3], mut f: impl FnMut([usize; 3])) {
        for z in 0..cells[2] {
            for y in 0..cells[1] {
                for x in 0..cells[0] {
                    f([x, y, z]);
                }
            }
        }
    }

    /// The cube's edge in cells (0: the cell is tagged).
    fn edge(reach: Option<(i64, i64)>) -> usize {
        reach.map_or(0, |(_, ahead)| ahead as usize + 1)
    }

    fn cheb(a: [usize; 3], b: [usize; 3]) -> usize {
        (0..3).map(|k| a[k].abs_diff(b[k])).max().unwrap()
    }

    #[test]
    fn octant_cubes_match_brute_force() {
        // A tagged cell at chessboard distance m ahead of c (in c's octant)
        // bounds the anchored cube's edge to m; the largest is the nearest.
        // Rows past 256 cells reach the maps' saturation inside a row.
        for (cells, per_mille) in [
            ([9usize, 7, 8], 20),
            ([13, 5, 6], 4),
            ([3, 4, 2], 0),
            ([1, 3, 2], 100),
            ([300, 3, 2], 3),
        ] {
            let (tags, on) = random_tags(cells, per_mille);
            let p = Proximity::build(&tags);
            assert!(p.is_octant());
            for o in 0..8 {
                let neg = [o & 1 != 0, o & 2 != 0, o & 4 != 0];
                each_cell(cells, |c| {
                    let want = on
                        .iter()
                        .filter(|t| {
                            (0..3).all(|a| if neg[a] { t[a] <= c[a] } else { t[a] >= c[a] })
                        })
                        .map(|&t| cheb(t, c))
                        .min()
                        .unwrap_or(255)
                        .min(255);
                    let reach = p.map_for(o).empty_reach(c.map(|v| v as i64));
                    assert!(reach.is_none_or(|(back, _)| back == 0), "only ahead");
                    assert_eq!(edge(reach), want, "{cells:?} octant {o} cell {c:?}");
                });
            }
        }
    }

    #[test]
    fn centred_cubes_match_brute_force_chessboard_distance() {
        let cells = [9usize, 7, 8];
        let (tags, on) = random_tags(cells, 20);
        let p = Proximity::build_within(&tags, 0);
        assert!(!p.is_octant());
        each_cell(cells, |c| {
            let want = on.iter().map(|&t| cheb(t, c)).min().unwrap().min(255);
            let reach = p.map_for(3).empty_reach(c.map(|v| v as i64));
            assert!(reach.is_none_or(|(back, ahead)| back == ahead), "centred");
            assert_eq!(edge(reach), want, "cell {c:?}");
        });
    }

    #[test]
    fn octant_cubes_are_never_smaller_than_centred_ones() {
        let cells = [11usize, 10, 9];
        let (tags, _) = random_tags(cells, 6);
        let (oct, cen) = (Proximity::build(&tags), Proximity::build_within(&tags, 0));
        for o in 0..8 {
            each_cell(cells, |c| {
                let c = c.map(|v| v as i64);
                assert!(edge(oct.map_for(o).empty_reach(c)) >= edge(cen.map_for(o).empty_reach(c)));
            });
        }
    }
}
