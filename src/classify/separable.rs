//! Per-cell reductions over each cell's `S³` coefficient support, computed
//! separably (x windows, then y, then z) — the paper's "splatting", as a
//! gather.
//!
//! A cell's support along an axis is the `S` consecutive coefficients
//! `k0 .. k0+S-1` with `k0 = cell - (S-1)/2`, and coefficient `k0 + j` carries
//! weight `W_j`. ACCC folds a window with dot products against per-axis
//! weight bounds (BMCC, an OR of sign flags, runs on words of bits in
//! [`mod@super::bmcc`], and is tested against this). The volume is processed in
//! chunks of z-slabs in parallel, so memory stays a few slabs per thread
//! whatever the volume size.

use rayon::prelude::*;

use super::tags::Tags;
use crate::filter::Field;
use crate::filter::coeffs::Coefficient;
use crate::lattice::Lattice;

/// Bytes of intermediate values a chunk may hold.
const CHUNK_BYTES: usize = 48 << 20;

/// The z ranges `z0..z1` of `ncz` cell slabs that a pass takes in parallel:
/// as many slabs of `per_slab` bytes of intermediates as `budget` holds,
/// and at least eight chunks where there are slabs enough.
pub(super) fn slab_chunks(ncz: usize, per_slab: usize, budget: usize) -> Vec<(usize, usize)> {
    let zc = (budget / per_slab.max(1)).clamp(1, ncz.div_ceil(8).max(1));
    (0..ncz)
        .step_by(zc)
        .map(|z0| (z0, (z0 + zc).min(ncz)))
        .collect()
}

/// Computes `decide(reduce_z(reduce_y(reduce_x(map(c)))))` for every cell.
/// `reduce` receives the `S` values of one window in weight order `j`.
pub fn per_cell<V, M, R, D, T: Coefficient>(
    field: &Field<T>,
    lattice: &Lattice,
    map: M,
    reduce: R,
    decide: D,
) -> Tags
where
    V: Copy + Default + Send + Sync,
    M: Fn(f64) -> V + Sync,
    R: Fn(&[V]) -> V + Sync,
    D: Fn(V) -> bool + Sync,
{
    if lattice.cell_count() == 0 {
        return Tags::empty(lattice.cells);
    }
    crate::with_support!(field.kernel().support(), S => {
        per_cell_s::<S, V, M, R, D, T>(field, lattice, map, reduce, decide)
    })
}

/// [`per_cell`] for support `S`: each window an `[V; S]` array, whose
/// reduction the compiler then unrolls.
#[inline(always)]
fn per_cell_s<const S: usize, V, M, R, D, T: Coefficient>(
    field: &Field<T>,
    lattice: &Lattice,
    map: M,
    reduce: R,
    decide: D,
) -> Tags
where
    V: Copy + Default + Send + Sync,
    M: Fn(f64) -> V + Sync,
    R: Fn(&[V]) -> V + Sync,
    D: Fn(V) -> bool + Sync,
{
    let [ncx, ncy, ncz] = lattice.cells;
    let s = S;
    let lead = ((s - 1) / 2) as isize;
    let coeffs = field.coeffs();
    let data = coeffs.data();
    let slab = ncx * ncy;
    let per_slab = (ncy + s) * ncx * std::mem::size_of::<V>() * 2;
    let chunks = slab_chunks(ncz, per_slab, CHUNK_BYTES);
    let out: Vec<Vec<u8>> = chunks
        .par_iter()
        .map(|&(z0, z1)| {
            let nzk = z1 - z0 + s - 1; // coefficient slabs this chunk reads
            let nyk = ncy + s - 1;
            // x pass: X[kz][ky][cx]
            let mut x = vec![V::default(); nzk * nyk * ncx];
            let mut row = vec![V::default(); ncx + s - 1];
            for kz in 0..nzk {
                let gz = z0 as isize - lead + kz as isize;
                for ky in 0..nyk {
                    let gy = ky as isize - lead;
                    let base = coeffs.offset(-lead, gy, gz);
                    for (i, r) in row.iter_mut().enumerate() {
                        *r = map(data[base + i].to_f64());
                    }
                    let dst = &mut x[(kz * nyk + ky) * ncx..][..ncx];
                    for (cx, d) in dst.iter_mut().enumerate() {
                        let win: [V; S] = std::array::from_fn(|j| row[cx + j]);
                        *d = reduce(&win);
                    }
                }
            }
            // y pass: Y[kz][cy][cx]
            let mut y = vec![V::default(); nzk * ncy * ncx];
            for kz in 0..nzk {
                for cy in 0..ncy {
                    for cx in 0..ncx {
                        let win: [V; S] =
                            std::array::from_fn(|j| x[(kz * nyk + cy + j) * ncx + cx]);
                        y[(kz * ncy + cy) * ncx + cx] = reduce(&win);
                    }
                }
            }
            drop(x);
            // z pass and decision.
            let mut flags = vec![0u8; (z1 - z0) * slab];
            for cz in 0..z1 - z0 {
                for c in 0..slab {
                    let win: [V; S] = std::array::from_fn(|k| y[(cz + k) * slab + c]);
                    flags[cz * slab + c] = decide(reduce(&win)) as u8;
                }
            }
            flags
        })
        .collect();
    Tags::from_chunks(lattice.cells, out)
}
