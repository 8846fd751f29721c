//! BMCC a machine word at a time: the sign of `c - iso` as two bits per
//! coefficient (above, and at or below), each cell's window over its support
//! an OR of shifted words along x, then of rows along y and of slabs along z.
//!
//! The same tags as the separable byte windows of [`super::separable`] (a
//! test holds them together), 64 cells per operation instead of one: the
//! byte windows were half of the Bézier-hull classification of a 256³
//! sphere, whose candidates they are (BMCC 53–57 ms of 104–111 ms, `snell
//! classify`; in words 17–20 ms, BENCHMARKS.md).

use rayon::prelude::*;

use super::tags::Tags;
use crate::filter::Field;
use crate::filter::coeffs::Coefficient;
use crate::lattice::Lattice;

/// Bytes of window words a chunk of z-slabs may hold.
const CHUNK_BYTES: usize = 16 << 20;

/// Cells whose support holds coefficients both above `iso` and at or below
/// it (a NaN coefficient is neither). Only a bound for non-negative kernels;
/// [`super::bmcc()`] decides which to use.
pub(super) fn bmcc_bits<T: Coefficient>(field: &Field<T>, lattice: &Lattice, iso: f64) -> Tags {
    if lattice.cell_count() == 0 {
        return Tags::empty(lattice.cells);
    }
    crate::with_support!(field.kernel().support(), S => bits_s::<S, T>(field, lattice, iso))
}

/// [`bmcc_bits`] for support `S`, over chunks of z-slabs in parallel (a few
/// slabs of words per thread whatever the volume's size).
fn bits_s<const S: usize, T: Coefficient>(field: &Field<T>, lattice: &Lattice, iso: f64) -> Tags {
    let [ncx, ncy, ncz] = lattice.cells;
    let lead = ((S - 1) / 2) as isize;
    let coeffs = field.coeffs();
    let data = coeffs.data();
    // Words per row of cells; a coefficient row has `S - 1` more bits, so
    // one more word holds it.
    let w = ncx.div_ceil(64);
    let nyk = ncy + S - 1;
    let per_slab = nyk * w * 2 * std::mem::size_of::<u64>() * 2;
    let chunks = super::separable::slab_chunks(ncz, per_slab, CHUNK_BYTES);
    let out: Vec<Vec<u64>> = chunks
        .par_iter()
        .map(|&(z0, z1)| {
            // Coefficient slabs this chunk reads.
            let nzk = z1 - z0 + S - 1;
            // x pass: per coefficient row, the windows of its cells, above
            // and below: X[kz][ky][word].
            let (mut xa, mut xb) = (vec![0u64; nzk * nyk * w], vec![0u64; nzk * nyk * w]);
            let (mut ra, mut rb) = (vec![0u64; w + 1], vec![0u64; w + 1]);
            for kz in 0..nzk {
                let gz = z0 as isize - lead + kz as isize;
                for ky in 0..nyk {
                    let gy = ky as isize - lead;
                    let base = coeffs.offset(-lead, gy, gz);
                    ra.fill(0);
                    rb.fill(0);
                    for (i, v) in data[base..base + ncx + S - 1].iter().enumerate() {
                        let v = v.to_f64();
                        ra[i >> 6] |= ((v > iso) as u64) << (i & 63);
                        rb[i >> 6] |= ((v <= iso) as u64) << (i & 63);
                    }
                    let at = (kz * nyk + ky) * w;
                    window_or::<S>(&ra, &mut xa[at..at + w]);
                    window_or::<S>(&rb, &mut xb[at..at + w]);
                }
            }
            // y pass: Y[kz][cy][word].
            let (mut ya, mut yb) = (vec![0u64; nzk * ncy * w], vec![0u64; nzk * ncy * w]);
            for kz in 0..nzk {
                for cy in 0..ncy {
                    let at = (kz * ncy + cy) * w;
                    for j in 0..S {
                        let from = (kz * nyk + cy + j) * w;
                        for k in 0..w {
                            ya[at + k] |= xa[from + k];
                            yb[at + k] |= xb[from + k];
                        }
                    }
                }
            }
            drop((xa, xb));
            // z pass and the decision: both sides somewhere in the support.
            let mut rows = vec![0u64; (z1 - z0) * ncy * w];
            for (i, tags) in rows.iter_mut().enumerate() {
                let (cz, rest) = (i / (ncy * w), i % (ncy * w));
                let (mut a, mut b) = (0u64, 0u64);
                for k in 0..S {
                    let from = (cz + k) * ncy * w + rest;
                    a |= ya[from];
                    b |= yb[from];
                }
                *tags = a & b;
            }
            rows
        })
        .collect();
    Tags::from_row_words(lattice.cells, out)
}

/// `out`'s bit `c` = the OR of `row`'s bits `c .. c + S` (`row` one word
/// longer than `out`).
#[inline(always)]
fn window_or<const S: usize>(row: &[u64], out: &mut [u64]) {
    for (k, o) in out.iter_mut().enumerate() {
        let (lo, hi) = (row[k], row[k + 1]);
        let mut acc = lo;
        for j in 1..S {
            acc |= (lo >> j) | (hi << (64 - j));
        }
        *o = acc;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::FilterKind;

    /// BMCC by the separable byte windows, as it was computed before words.
    fn byte_windows<T: Coefficient>(f: &Field<T>, lat: &Lattice, iso: f64) -> Tags {
        super::super::separable::per_cell(
            f,
            lat,
            |c| [(c > iso) as u8, (c <= iso) as u8],
            |w| w.iter().fold([0u8; 2], |a, b| [a[0] | b[0], a[1] | b[1]]),
            |v| v[0] != 0 && v[1] != 0,
        )
    }

    /// The word windows tag exactly the cells the byte windows do, for every
    /// non-negative kernel's support, on lattices whose rows end inside a
    /// word, fill one exactly, or span several, at iso-values that split the
    /// data unevenly, with `f64` and `f32` coefficients.
    #[test]
    fn word_windows_are_the_byte_windows() {
        for dims in [
            [9usize, 8, 10],
            [64, 3, 5],
            [65, 4, 3],
            [130, 3, 4],
            [2, 2, 2],
        ] {
            let vol = crate::volume::scrambled_u8(dims, 7);
            for name in [
                "linear", "bspline2", "bspline3", "bspline4", "bspline5", "bspline6", "bspline7",
            ] {
                let f = crate::filter::Field::new(&vol, FilterKind::parse(name, 0.0).unwrap());
                let lat = Lattice::new(f.kernel(), dims);
                for iso in [20.5, 127.5, 240.0] {
                    let want = byte_windows(&f, &lat, iso);
                    let got = bmcc_bits(&f, &lat, iso);
                    assert_eq!(got, want, "{name} {dims:?} iso {iso}");
                    assert_eq!(got.count(), want.count());
                    let f32s = crate::filter::Field::new_f32(&vol, f.kind());
                    let want32 = byte_windows(&f32s, &lat, iso);
                    assert_eq!(bmcc_bits(&f32s, &lat, iso), want32, "{name} f32");
                }
                // NaN coefficients are on neither side.
                let mut c = f.coeffs().clone();
                let n = c.data().len();
                for k in (0..n).step_by(13) {
                    c.data_mut()[k] = f64::NAN;
                }
                let nan = crate::filter::Field::from_coeffs(f.kind(), c);
                let want = byte_windows(&nan, &lat, 127.5);
                assert_eq!(bmcc_bits(&nan, &lat, 127.5), want, "{name} {dims:?} NaN");
            }
        }
    }
}
