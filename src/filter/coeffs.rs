//! The coefficient grid, padded with a mirrored apron.
//!
//! Evaluating `f` near the domain boundary needs coefficients at indices outside
//! `[0, n-1]`, mirrored like the samples (`c[-k] = c[k]`, `c[n-1+k] = c[n-1-k]`).
//! Storing an apron of [`APRON`] mirrored layers on every side turns every
//! neighbourhood access into plain strided loads with no branch, which is what
//! the hot loops want.
//!
//! The storage type is a parameter ([`Coefficient`]): `f64` by default, so the
//! renderer adds no error to the filter's own (high-degree splines on noisy data
//! have coefficients in the thousands that cancel on evaluation; `f32` storage
//! then costs ~1e-4 on 0..255 data), `f32` where memory or bandwidth matters,
//! `f16` (2 bytes, 11 significant bits) where memory matters most.

use crate::volume::Volume;

use super::kernel::MAX_SUPPORT;

/// Apron width: enough for the widest kernel (support 8 reaches 4 past a sample).
pub const APRON: usize = MAX_SUPPORT / 2;

/// Mirror index of `i` into `[0, n-1]` (whole-sample symmetric; `n = 1` is constant).
#[inline]
pub fn mirror(i: isize, n: usize) -> usize {
    if n == 1 {
        return 0;
    }
    let n = n as isize;
    let p = 2 * n - 2;
    let m = i.rem_euclid(p);
    (if m >= n { p - m } else { m }) as usize
}

/// How coefficients are stored: converted to `f64` for every computation.
/// Rows of four load as vectors ([`crate::simd::gather_rows4`]) for every
/// storage.
pub trait Coefficient:
    crate::simd::Row4 + Default + Send + Sync + PartialEq + std::fmt::Debug + 'static
{
    const NAME: &'static str;
    fn to_f64(self) -> f64;
    fn from_f64(v: f64) -> Self;
    /// The slice itself when the storage is already `f64` (vector kernels
    /// load it directly), else `None`.
    fn as_f64_slice(s: &[Self]) -> Option<&[f64]>;

    /// `s[base[l] + off]` as `f64` for each of `L` lanes (one hardware
    /// gather where the storage and instruction set allow).
    ///
    /// # Safety
    /// As [`crate::simd::gather`]: indices in bounds, `L` bound by
    /// [`crate::with_isa!`].
    #[inline(always)]
    unsafe fn gather<const L: usize>(s: &[Self], base: &[usize; L], off: usize) -> [f64; L] {
        // SAFETY: the caller guarantees the indices are in bounds.
        std::array::from_fn(|l| unsafe { s.get_unchecked(base[l] + off) }.to_f64())
    }
}

impl Coefficient for f64 {
    const NAME: &'static str = "f64";
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        v
    }
    #[inline(always)]
    fn as_f64_slice(s: &[Self]) -> Option<&[f64]> {
        Some(s)
    }
    #[inline(always)]
    unsafe fn gather<const L: usize>(s: &[Self], base: &[usize; L], off: usize) -> [f64; L] {
        // SAFETY: forwarded from the caller.
        unsafe { crate::simd::gather(s, base, off) }
    }
}

impl Coefficient for f32 {
    const NAME: &'static str = "f32";
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self as f64
    }
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        v as f32
    }
    #[inline(always)]
    fn as_f64_slice(_: &[Self]) -> Option<&[f64]> {
        None
    }
}

impl Coefficient for half::f16 {
    const NAME: &'static str = "f16";
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self.to_f64()
    }
    /// Rounded to nearest; beyond `±65504` the value becomes infinite
    /// (callers check the range first, see `AnyField::new`).
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        half::f16::from_f64(v)
    }
    #[inline(always)]
    fn as_f64_slice(_: &[Self]) -> Option<&[f64]> {
        None
    }
}

/// Grids from this size on are filled in parallel ([`Coeffs::from_interior`]).
const PARALLEL_FILL_BYTES: usize = 64 << 20;

/// A 3-D grid of coefficients with a mirrored apron.
#[derive(Clone, Debug)]
pub struct Coeffs<T: Coefficient = f64> {
    dims: [usize; 3],
    padded: [usize; 3],
    data: Vec<T>,
}

impl<T: Coefficient> Coeffs<T> {
    /// The samples themselves, padded (coefficients of non-prefiltered kernels,
    /// and the input of in-place prefiltering), less `frame`: their offset
    /// ([`Volume::offset`]) less `frame` added back in `f64`. A frame of the
    /// volume's offset ([`crate::filter::field::volume_frame`]) keeps the
    /// samples as stored.
    pub fn from_volume(vol: &Volume, frame: f64) -> Coeffs<T> {
        let shift = vol.offset() - frame;
        Coeffs::from_interior(vol.dims(), vol.samples(), |v: &f32| {
            T::from_f64(shift + *v as f64)
        })
    }

    /// A zeroed padded grid for `dims`, its pages advised huge, for the
    /// constructors to fill.
    fn zeroed(dims: [usize; 3]) -> Coeffs<T> {
        let padded = dims.map(|n| n + 2 * APRON);
        let mut grid = Coeffs {
            dims,
            padded,
            data: vec![T::default(); padded[0] * padded[1] * padded[2]],
        };
        crate::heap::advise_huge_pages(&mut grid.data);
        grid
    }

    /// Builds a padded grid from x-fastest interior values, converting each.
    ///
    /// A large grid is filled a z slab per task: the fill is the first touch
    /// of its pages, and the kernel zeroes pages on the faulting core, so a
    /// serial fill left the other core idle for most of it (a 1024³ grid's
    /// 8.4 GiB: 23% of a whole render's samples in page zeroing under
    /// `from_volume`). Small grids stay serial.
    pub fn from_interior<S: Sync>(
        dims: [usize; 3],
        src: &[S],
        conv: impl Fn(&S) -> T + Sync,
    ) -> Coeffs<T> {
        assert_eq!(src.len(), dims[0] * dims[1] * dims[2]);
        let mut grid = Coeffs::zeroed(dims);
        let padded = grid.padded;
        let [nx, ny, nz] = dims;
        let slab = padded[0] * padded[1];
        let fill = |z: usize, slab_data: &mut [T]| {
            for y in 0..ny {
                let row = &src[nx * (y + ny * z)..][..nx];
                let off = APRON + padded[0] * (y + APRON);
                for (d, s) in slab_data[off..off + nx].iter_mut().zip(row) {
                    *d = conv(s);
                }
            }
        };
        // The interior slabs are picked by filtering, not by slicing them
        // out first: written that way the frame bench's generate stage,
        // unrelated code, compiled worse (2.51 → 3.04 ms single thread).
        if std::mem::size_of_val(grid.data.as_slice()) >= PARALLEL_FILL_BYTES {
            use rayon::prelude::*;
            grid.data
                .par_chunks_mut(slab)
                .enumerate()
                .filter(|(k, _)| (APRON..APRON + nz).contains(k))
                .for_each(|(k, d)| fill(k - APRON, d));
        } else {
            let slabs = grid.data.chunks_mut(slab).enumerate();
            for (k, d) in slabs.filter(|(k, _)| (APRON..APRON + nz).contains(k)) {
                fill(k - APRON, d);
            }
        }
        grid.fill_apron();
        grid
    }

    /// Builds a padded grid whose interior rows (x fastest, then y, then
    /// z) `row` fills in order, for a sequential source such as a cache
    /// file read without a copy of the whole; stops at `row`'s first error.
    pub fn from_rows<E>(
        dims: [usize; 3],
        mut row: impl FnMut(&mut [T]) -> Result<(), E>,
    ) -> Result<Coeffs<T>, E> {
        let mut grid = Coeffs::zeroed(dims);
        let [nx, ny, nz] = dims;
        for z in 0..nz {
            for y in 0..ny {
                let at = grid.interior_offset(0, y, z);
                row(&mut grid.data[at..at + nx])?;
            }
        }
        grid.fill_apron();
        Ok(grid)
    }

    /// Dims of the interior (the volume's dims).
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Element stride along `axis` in the padded layout.
    #[inline(always)]
    pub fn stride(&self, axis: usize) -> usize {
        match axis {
            0 => 1,
            1 => self.padded[0],
            _ => self.padded[0] * self.padded[1],
        }
    }

    /// Offset of interior element `(x, y, z)`.
    #[inline(always)]
    pub fn interior_offset(&self, x: usize, y: usize, z: usize) -> usize {
        (x + APRON) + self.padded[0] * ((y + APRON) + self.padded[1] * (z + APRON))
    }

    /// Offset of element `(i, j, k)` for indices in `[-APRON, n-1+APRON]`.
    #[inline(always)]
    pub fn offset(&self, i: isize, j: isize, k: isize) -> usize {
        let a = APRON as isize;
        debug_assert!(i >= -a && j >= -a && k >= -a);
        debug_assert!((i + a) < self.padded[0] as isize);
        debug_assert!((j + a) < self.padded[1] as isize);
        debug_assert!((k + a) < self.padded[2] as isize);
        ((i + a) as usize)
            + self.padded[0] * (((j + a) as usize) + self.padded[1] * (k + a) as usize)
    }

    /// Value at any integer index, mirrored like the samples.
    pub fn at(&self, i: isize, j: isize, k: isize) -> T {
        let (x, y, z) = (
            mirror(i, self.dims[0]),
            mirror(j, self.dims[1]),
            mirror(k, self.dims[2]),
        );
        self.data[self.interior_offset(x, y, z)]
    }

    #[inline(always)]
    pub fn data(&self) -> &[T] {
        &self.data
    }

    pub fn data_mut(&mut self) -> &mut [T] {
        &mut self.data
    }

    /// The grid less `shift`, times `scale` (a power of two, so exactly),
    /// in another storage: each value `v` becomes `(v - shift) · scale` (in
    /// `f64`), rounded once to `U`.
    pub fn convert_shifted<U: Coefficient>(&self, shift: f64, scale: f64) -> Coeffs<U> {
        let mut data = vec![U::default(); self.data.len()];
        crate::heap::advise_huge_pages(&mut data);
        for (d, v) in data.iter_mut().zip(&self.data) {
            *d = U::from_f64((v.to_f64() - shift) * scale);
        }
        Coeffs {
            dims: self.dims,
            padded: self.padded,
            data,
        }
    }

    /// Bytes held (for memory reports).
    pub fn bytes(&self) -> usize {
        self.data.len() * std::mem::size_of::<T>()
    }

    /// Interior values in x-fastest order (what `snell sample` and tests compare).
    pub fn interior(&self) -> Vec<T> {
        let mut out = Vec::with_capacity(self.dims.iter().product());
        for z in 0..self.dims[2] {
            for y in 0..self.dims[1] {
                let off = self.interior_offset(0, y, z);
                out.extend_from_slice(&self.data[off..off + self.dims[0]]);
            }
        }
        out
    }

    /// Rewrites the apron from the interior by mirroring, axis by axis (x rows,
    /// then whole y rows, then whole z slabs), so corners come out right.
    pub fn fill_apron(&mut self) {
        let [nx, ny, nz] = self.dims;
        let [px, py, pz] = self.padded;
        let a = APRON as isize;
        // x: within each interior row.
        for z in 0..nz {
            for y in 0..ny {
                let row = self.padded[0] * ((y + APRON) + py * (z + APRON));
                for i in (-a..0).chain(nx as isize..nx as isize + a) {
                    let src = mirror(i, nx) + APRON;
                    self.data[row + (i + a) as usize] = self.data[row + src];
                }
            }
        }
        // y: copy whole padded rows.
        for z in 0..nz {
            for j in (-a..0).chain(ny as isize..ny as isize + a) {
                let src = mirror(j, ny) + APRON;
                let dst = (j + a) as usize;
                let base = px * py * (z + APRON);
                self.data
                    .copy_within(base + px * src..base + px * (src + 1), base + px * dst);
            }
        }
        // z: copy whole padded slabs.
        for k in (-a..0).chain(nz as isize..nz as isize + a) {
            let src = mirror(k, nz) + APRON;
            let dst = (k + a) as usize;
            let slab = px * py;
            self.data
                .copy_within(slab * src..slab * (src + 1), slab * dst);
        }
        debug_assert_eq!(self.data.len(), px * py * pz);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::SampleType;

    #[test]
    fn mirror_matches_spec() {
        assert_eq!(mirror(-1, 5), 1);
        assert_eq!(mirror(-4, 5), 4);
        assert_eq!(mirror(5, 5), 3);
        assert_eq!(mirror(8, 5), 0);
        assert_eq!(mirror(9, 5), 1);
        assert_eq!(mirror(-3, 2), 1);
        assert_eq!(mirror(7, 1), 0);
    }

    /// A grid past [`PARALLEL_FILL_BYTES`], filled a slab per task: every
    /// interior value is its sample's, and the apron mirrors them.
    #[test]
    fn large_grids_fill_like_small_ones() {
        let dims = [203usize, 201, 205];
        let n = dims[0] * dims[1] * dims[2];
        let src: Vec<u32> = (0..n as u32).collect();
        let c: Coeffs<f64> = Coeffs::from_interior(dims, &src, |&v| v as f64 * 0.5);
        assert!(std::mem::size_of_val(c.data()) >= PARALLEL_FILL_BYTES);
        let a = APRON as isize;
        for z in (-a..dims[2] as isize + a).step_by(7) {
            for y in -a..dims[1] as isize + a {
                for x in -a..dims[0] as isize + a {
                    let (i, j, k) = (mirror(x, dims[0]), mirror(y, dims[1]), mirror(z, dims[2]));
                    let want = (i + dims[0] * (j + dims[1] * k)) as f64 * 0.5;
                    assert_eq!(c.data()[c.offset(x, y, z)], want, "({x},{y},{z})");
                }
            }
        }
        // Every interior slab, not only the sampled ones.
        for z in 0..dims[2] {
            let (x, y) = (z % dims[0], (3 * z) % dims[1]);
            let want = (x + dims[0] * (y + dims[1] * z)) as f64 * 0.5;
            assert_eq!(c.data()[c.interior_offset(x, y, z)], want, "slab {z}");
        }
    }

    #[test]
    fn apron_mirrors_every_axis() {
        let dims = [3usize, 2, 1];
        let s: Vec<f32> = (0..6).map(|v| v as f32).collect();
        let vol = Volume::new(dims, [1.0; 3], SampleType::F32, s).unwrap();
        let c: Coeffs<f32> = Coeffs::from_volume(&vol, 0.0);
        let a = APRON as isize;
        for k in -a..1 + a {
            for j in -a..2 + a {
                for i in -a..3 + a {
                    let expect = vol.get(mirror(i, 3), mirror(j, 2), mirror(k, 1));
                    assert_eq!(c.data()[c.offset(i, j, k)] as f64, expect, "({i},{j},{k})");
                }
            }
        }
        assert_eq!(c.interior(), vol.samples());
    }
}
