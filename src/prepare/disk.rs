//! The cache directory's files: prefiltered coefficients, cell tags with
//! the sub-cell masks the classification found, and the tagged cells'
//! curvature bounds, each with a magic, its
//! key's parameters and a closing checksum of its values, so a damaged or
//! foreign file is refused (and rebuilt), never trusted.

use std::io::{Read, Write};
use std::path::Path;

use crate::classify::Tags;
use crate::classify::curvature::HessianBound;
use crate::classify::masks::LinearMasks;
use crate::filter::coeffs::{Coefficient, Coeffs};
use crate::filter::{Field, FilterKind};
use crate::lattice::Lattice;
use crate::scene::Storage;
use crate::volume::{Volume, WordHash};

// Version 2 ends each file with a checksum of its values; tags files of
// version 3 hold the sub-cell masks too (older files are ignored and
// rewritten).
const FIELD_MAGIC: &[u8; 8] = b"SNLCOEF2";
const TAGS_MAGIC: &[u8; 8] = b"SNLTAGS3";
const OLD_TAGS_MAGIC: &[u8; 8] = b"SNLTAGS2";
const CURVATURE_MAGIC: &[u8; 8] = b"SNLCURV1";

/// Reads the checksum that ends a file and compares it with `sum`, the hash
/// of the file's values: a damaged file of the right length (a flipped bit,
/// a block of zeros) would otherwise be read as good and render a wrong
/// surface.
fn check_sum(r: &mut impl Read, sum: WordHash) -> std::io::Result<()> {
    if read_u64(r)? != sum.value() {
        return Err(bad("checksum mismatch (damaged file)"));
    }
    Ok(())
}

fn write_u64s(w: &mut dyn Write, v: &[u64]) -> std::io::Result<()> {
    for x in v {
        w.write_all(&x.to_le_bytes())?;
    }
    Ok(())
}

/// A field's name in cache keys and files: the filter's, and the storage
/// unless it is `f64` (so `f64` cache files keep their names); for `f16`
/// also the iso-value its coefficients are centred on, and `scaled`: they
/// are multiplied by a power of two the volume and that centre give
/// (`f16_scale`), which older files, named without the word, were not;
/// for `f32`, `relative`: they are relative to the volume's offset, which
/// older files of a volume with an offset were not.
pub(super) fn field_name(filter: FilterKind, storage: Storage, centre: f64) -> String {
    match storage {
        Storage::F64 => filter.cache_key(),
        Storage::F32 => format!("{}-{}-relative", filter.cache_key(), storage.name()),
        Storage::F16 => format!(
            "{}-{}-scaled-{:016x}",
            filter.cache_key(),
            storage.name(),
            centre.to_bits()
        ),
    }
}

/// The file of a field's coefficients, `name` its [`field_name`]: `f64`
/// coefficients of a volume with an offset are stored relative to it, which
/// older files of such a volume were not, so theirs are `relative` too
/// (those of the volumes without one, the same either way, keep their
/// names).
pub(super) fn coef_file_name(name: &str, storage: Storage, vol: &Volume) -> String {
    if storage == Storage::F64 && vol.offset() != 0.0 {
        format!("{name}-relative.coef")
    } else {
        format!("{name}.coef")
    }
}

/// Coefficients are written as `f64` whatever the storage (exact for `f32`).
pub(super) fn write_field<T: Coefficient>(w: &mut dyn Write, f: &Field<T>) -> std::io::Result<()> {
    w.write_all(FIELD_MAGIC)?;
    let key = f.kind().cache_key();
    write_u64s(w, &[key.len() as u64])?;
    w.write_all(key.as_bytes())?;
    let d = f.dims();
    write_u64s(w, &[d[0] as u64, d[1] as u64, d[2] as u64])?;
    write_u64s(w, &[f.coeffs().interior().len() as u64])?;
    let mut sum = WordHash::new();
    for v in f.coeffs().interior() {
        let bits = v.to_f64().to_bits();
        sum.add(bits);
        w.write_all(&bits.to_le_bytes())?;
    }
    write_u64s(w, &[sum.value()])
}

fn read_exact_vec(r: &mut impl Read, n: usize) -> std::io::Result<Vec<u8>> {
    let mut v = vec![0u8; n];
    r.read_exact(&mut v)?;
    Ok(v)
}

fn read_u64(r: &mut impl Read) -> std::io::Result<u64> {
    let mut b = [0u8; 8];
    r.read_exact(&mut b)?;
    Ok(u64::from_le_bytes(b))
}

fn bad(msg: &str) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidData, msg.to_string())
}

/// Reads a coefficient file straight into the padded grid, a row at a
/// time through one small buffer: read value by value, or copied whole into
/// a buffer whose pages the kernel clears first, the engine's 8.4 M
/// coefficients took longer to read than to prefilter again. (Not mapped:
/// on a shared file system another task's replacement of the file could
/// fault a map, where a read only fails.)
pub(super) fn read_field<T: Coefficient>(
    path: &Path,
    filter: FilterKind,
    dims: [usize; 3],
) -> std::io::Result<Field<T>> {
    let mut r = std::io::BufReader::with_capacity(1 << 20, crate::input::open(path)?);
    if &read_exact_vec(&mut r, 8)?[..] != FIELD_MAGIC {
        return Err(bad("not a coefficient cache file"));
    }
    let klen = read_u64(&mut r)?;
    if klen > 256 {
        return Err(bad("bad key"));
    }
    let key = read_exact_vec(&mut r, klen as usize)?;
    if key != filter.cache_key().as_bytes() {
        return Err(bad("filter mismatch"));
    }
    let d = [read_u64(&mut r)?, read_u64(&mut r)?, read_u64(&mut r)?];
    if d != dims.map(|x| x as u64) {
        return Err(bad("dims mismatch"));
    }
    let n = read_u64(&mut r)?;
    if n != dims.iter().product::<usize>() as u64 {
        return Err(bad("length mismatch"));
    }
    let mut sum = WordHash::new();
    let mut finite = true;
    let mut bytes = vec![0u8; dims[0] * 8];
    let coeffs = Coeffs::from_rows(dims, |row: &mut [T]| {
        r.read_exact(&mut bytes)?;
        let (values, _) = bytes.as_chunks::<8>();
        for (dst, v) in row.iter_mut().zip(values) {
            let bits = u64::from_le_bytes(*v);
            sum.add(bits);
            let value = f64::from_bits(bits);
            finite &= value.is_finite();
            *dst = T::from_f64(value);
        }
        Ok::<(), std::io::Error>(())
    })?;
    check_sum(&mut r, sum)?;
    if r.read(&mut [0u8; 1])? != 0 {
        return Err(bad("trailing data"));
    }
    if !finite {
        return Err(bad("non-finite coefficient"));
    }
    Ok(Field::from_coeffs(filter, coeffs))
}

/// The tags and, where the classification found them, the tagged cells'
/// sub-cell masks (by linear cell index; an empty list for none).
pub(super) fn write_tags(
    w: &mut dyn Write,
    t: &Tags,
    masks: &[(usize, u64)],
) -> std::io::Result<()> {
    w.write_all(TAGS_MAGIC)?;
    write_u64s(w, &t.cells.map(|c| c as u64))?;
    write_u64s(w, &[t.words().len() as u64])?;
    write_u64s(w, t.words())?;
    write_u64s(w, &[masks.len() as u64])?;
    let mut sum = WordHash::new();
    t.words().iter().for_each(|&x| sum.add(x));
    for &(cell, mask) in masks {
        write_u64s(w, &[cell as u64, mask])?;
        sum.add(cell as u64);
        sum.add(mask);
    }
    write_u64s(w, &[sum.value()])
}

/// What [`write_tags`] wrote, for `lattice`. The masks are checked against
/// the tags where they are filed ([`crate::classify::SubCellMasks::from_linear`]).
pub(super) fn read_tags(path: &Path, lattice: &Lattice) -> std::io::Result<(Tags, LinearMasks)> {
    let mut r = std::io::BufReader::new(crate::input::open(path)?);
    let magic = read_exact_vec(&mut r, 8)?;
    if magic == OLD_TAGS_MAGIC {
        return Err(bad("written by an earlier snell, without sub-cell masks"));
    }
    if magic != TAGS_MAGIC {
        return Err(bad("not a tags cache file"));
    }
    let cells = [read_u64(&mut r)?, read_u64(&mut r)?, read_u64(&mut r)?];
    if cells != lattice.cells.map(|c| c as u64) {
        return Err(bad("lattice mismatch"));
    }
    let n = read_u64(&mut r)?;
    if n != lattice.cell_count().div_ceil(64) as u64 {
        return Err(bad("length mismatch"));
    }
    let words = (0..n)
        .map(|_| read_u64(&mut r))
        .collect::<std::io::Result<Vec<u64>>>()?;
    let mut sum = WordHash::new();
    words.iter().for_each(|&x| sum.add(x));
    // None, or one per tagged cell.
    let m = read_u64(&mut r)?;
    let tagged: u64 = words.iter().map(|w| u64::from(w.count_ones())).sum();
    if m != 0 && m != tagged {
        return Err(bad("mask count differs from the tagged cells'"));
    }
    let mut masks = Vec::with_capacity(m as usize);
    for _ in 0..m {
        let (cell, mask) = (read_u64(&mut r)?, read_u64(&mut r)?);
        sum.add(cell);
        sum.add(mask);
        masks.push((cell as usize, mask));
    }
    check_sum(&mut r, sum)?;
    let mut b = [0u8; 1];
    if r.read(&mut b)? != 0 {
        return Err(bad("trailing data"));
    }
    let tags = Tags::from_words(lattice.cells, words).ok_or_else(|| bad("bad tag words"))?;
    Ok((tags, masks))
}

/// The curvature bounds of the tagged cells, in slot order: one
/// [`HessianBound`] per tagged cell, as `f32` bits.
pub(super) fn write_curvature(w: &mut dyn Write, bounds: &[HessianBound]) -> std::io::Result<()> {
    w.write_all(CURVATURE_MAGIC)?;
    write_u64s(w, &[bounds.len() as u64])?;
    let mut sum = WordHash::new();
    let mut buf = Vec::with_capacity(bounds.len().min(1 << 16) * 24);
    for chunk in bounds.chunks(1 << 16) {
        buf.clear();
        for b in chunk {
            for v in b {
                buf.extend_from_slice(&v.to_bits().to_le_bytes());
                sum.add(u64::from(v.to_bits()));
            }
        }
        w.write_all(&buf)?;
    }
    write_u64s(w, &[sum.value()])
}

/// What [`write_curvature`] wrote, for `tagged` tagged cells. A negative
/// bound is refused: it would clear cells the surface crosses (an infinite
/// or NaN one clears nothing, as when it was built).
pub(super) fn read_curvature(path: &Path, tagged: usize) -> std::io::Result<Vec<HessianBound>> {
    let mut r = std::io::BufReader::new(crate::input::open(path)?);
    if read_exact_vec(&mut r, 8)? != CURVATURE_MAGIC {
        return Err(bad("not a curvature cache file"));
    }
    if read_u64(&mut r)? != tagged as u64 {
        return Err(bad("count differs from the tagged cells'"));
    }
    let mut sum = WordHash::new();
    let mut bounds = Vec::with_capacity(tagged);
    let mut raw = [0u8; 24];
    for _ in 0..tagged {
        r.read_exact(&mut raw)?;
        let b: HessianBound = std::array::from_fn(|i| {
            let bits = u32::from_le_bytes(raw[4 * i..4 * i + 4].try_into().unwrap());
            sum.add(u64::from(bits));
            f32::from_bits(bits)
        });
        if b.iter().any(|&v| v < 0.0) {
            return Err(bad("negative curvature bound"));
        }
        bounds.push(b);
    }
    check_sum(&mut r, sum)?;
    let mut b = [0u8; 1];
    if r.read(&mut b)? != 0 {
        return Err(bad("trailing data"));
    }
    Ok(bounds)
}
