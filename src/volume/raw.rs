//! Headerless raw volumes, laid out as the command line describes them
//! (`--dims`, `--type`, `--endian`, `--spacing`, `--offset`).
//!
//! Nothing in such a file says what it holds, so the length check is strict in
//! both directions: a file longer than the description is as likely a wrong
//! `--dims` as one that is shorter, and loading it anyway would silently shear
//! the volume. The file is memory-mapped and decoded straight from the map, so
//! the only copy made is the `f32` sample buffer.
//!
//! This module also holds the byte-level helpers the other readers share
//! (mapping, exact reads, gzip bounds), since they are all about getting raw
//! bytes in front of [`decode_samples`].

use std::fs::File;
use std::io::{self, Read, Write};
use std::ops::Deref;
use std::path::Path;

use memmap2::Mmap;

use super::{
    Decoded, LoadOptions, RawSpec, SampleType, Volume, VolumeError, check_spacing,
    checked_sample_count, decode_samples,
};

/// Reads a headerless volume described by `spec`.
pub fn read(path: &Path, spec: &RawSpec, opts: &LoadOptions) -> Result<Volume, VolumeError> {
    check_spacing(spec.spacing).map_err(|e| VolumeError::format(path, e.to_string()))?;
    let count = checked_sample_count(path, spec.dims, opts.memory_limit)?;
    let ty = spec.sample_type;
    let need = data_byte_len(path, count, ty)?;
    let end = spec.offset.checked_add(need).ok_or_else(|| {
        VolumeError::format(
            path,
            format!(
                "offset {} plus {} bytes of samples overflows a file position",
                spec.offset, need
            ),
        )
    })?;

    let file = crate::input::open(path).map_err(|e| VolumeError::io(path, e))?;
    let len = file.metadata().map_err(|e| VolumeError::io(path, e))?.len();
    let [nx, ny, nz] = spec.dims;
    if len < end {
        // Short of the dims: usually one slice too many, so with the dims
        // the length fits, as for a file too long.
        return Err(VolumeError::Truncated {
            path: path.to_path_buf(),
            need: end,
            got: len,
            what: format!(
                "{nx}x{ny}x{nz} samples of {ty}{}{}",
                offset_phrase(spec.offset),
                fits_phrase(spec, len)
            ),
        });
    }
    if len > end {
        return Err(VolumeError::format(
            path,
            length_mismatch_message(spec, need, len),
        ));
    }

    let map = map_file(path, &file)?;
    let bytes = byte_range(&map, spec.offset, end).ok_or_else(|| VolumeError::Truncated {
        // The file shrank between the length check and the mapping.
        path: path.to_path_buf(),
        need: end,
        got: map.len() as u64,
        what: format!("{nx}x{ny}x{nz} samples of {ty}"),
    })?;
    let decoded = decode_samples(path, bytes, ty, spec.endian, count, None, opts.allow_nan)?;
    finish_volume(path, spec.dims, spec.spacing, ty, decoded)
}

/// Explains a file longer than `spec` says, suggesting the dims (or sample
/// size) the length would fit, since a wrong slice count is the usual cause.
fn length_mismatch_message(spec: &RawSpec, need: u64, len: u64) -> String {
    let [nx, ny, nz] = spec.dims;
    let ty = spec.sample_type;
    let in_all = if spec.offset == 0 {
        String::new()
    } else {
        format!(" ({} in all)", spec.offset.saturating_add(need))
    };
    let mut msg = format!(
        "dims {nx}x{ny}x{nz} of {ty} need {need} bytes{}{in_all}, but the file holds {len} bytes: the dims/type do not match the file length",
        offset_phrase(spec.offset),
    );
    msg.push_str(&fits_phrase(spec, len));
    let avail = len.saturating_sub(spec.offset);
    let count = (nx as u64)
        .saturating_mul(ny as u64)
        .saturating_mul(nz as u64);
    for size in [1u64, 2, 4, 8] {
        if size != ty.size() as u64 && count.checked_mul(size) == Some(avail) {
            msg.push_str(&format!(
                "; it also fits dims {nx}x{ny}x{nz} with a {size}-byte sample type"
            ));
        }
    }
    msg
}

/// `; the length fits dims …` for the dims that keep two of `spec`'s
/// and fit a file of `len` bytes exactly, or nothing if none do.
fn fits_phrase(spec: &RawSpec, len: u64) -> String {
    let ty = spec.sample_type;
    let avail = len.saturating_sub(spec.offset);
    let fits = implied_dims(spec.dims, ty.size() as u64, avail);
    if fits.is_empty() {
        return String::new();
    }
    let list: Vec<String> = fits
        .iter()
        .map(|d| format!("{}x{}x{}", d[0], d[1], d[2]))
        .collect();
    format!("; the length fits dims {} of {ty}", list.join(" or "))
}

fn offset_phrase(offset: u64) -> String {
    if offset == 0 {
        String::new()
    } else {
        format!(" after a {offset}-byte offset")
    }
}

/// Dims that keep two of `dims` and fit `avail` bytes of `size`-byte samples
/// exactly, z first (a wrong slice count is the most common mistake).
fn implied_dims(dims: [usize; 3], size: u64, avail: u64) -> Vec<[usize; 3]> {
    let mut out: Vec<[usize; 3]> = Vec::new();
    if size == 0 || avail == 0 || !avail.is_multiple_of(size) {
        return out;
    }
    let samples = avail / size;
    for axis in [2usize, 1, 0] {
        let others: u64 = (0..3)
            .filter(|&a| a != axis)
            .map(|a| dims[a] as u64)
            .fold(1u64, |acc, d| acc.saturating_mul(d));
        if others == 0 || !samples.is_multiple_of(others) {
            continue;
        }
        let Ok(n) = usize::try_from(samples / others) else {
            continue;
        };
        let mut candidate = dims;
        candidate[axis] = n;
        if n > 0 && candidate != dims && !out.contains(&candidate) {
            out.push(candidate);
        }
    }
    out
}

/// The bytes of a file, mapped read-only. A zero-length file cannot be mapped on
/// Linux (`EINVAL`), so it is represented without a map and reads as empty;
/// every caller then reports it as truncated.
pub(super) enum FileBytes {
    Empty,
    Mapped(Mmap),
}

impl Deref for FileBytes {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        match self {
            FileBytes::Empty => &[],
            FileBytes::Mapped(map) => map,
        }
    }
}

/// Maps `file` read-only so samples decode straight from the page cache.
pub(super) fn map_file(path: &Path, file: &File) -> Result<FileBytes, VolumeError> {
    let len = file.metadata().map_err(|e| VolumeError::io(path, e))?.len();
    if len == 0 {
        return Ok(FileBytes::Empty);
    }
    // SAFETY: the map is read-only and lives only while the file is decoded.
    // Another process truncating or rewriting the file meanwhile could change
    // or fault the mapped bytes; that is the accepted cost of not copying
    // volumes of many GiB, and the same trade every mmap-based reader makes.
    let map = unsafe { Mmap::map(file) }.map_err(|e| VolumeError::io(path, e))?;
    #[cfg(unix)]
    {
        // Only a hint for read-ahead; decoding is correct without it.
        let _ = map.advise(memmap2::Advice::Sequential);
    }
    Ok(FileBytes::Mapped(map))
}

/// `bytes[start..end]` for file positions, or `None` when out of range.
pub(super) fn byte_range(bytes: &[u8], start: u64, end: u64) -> Option<&[u8]> {
    let start = usize::try_from(start).ok()?;
    let end = usize::try_from(end).ok()?;
    bytes.get(start..end)
}

/// Bytes that `count` samples of `ty` occupy, or an error if that overflows.
pub(super) fn data_byte_len(path: &Path, count: usize, ty: SampleType) -> Result<u64, VolumeError> {
    (count as u64)
        .checked_mul(ty.size() as u64)
        .filter(|&n| usize::try_from(n).is_ok())
        .ok_or_else(|| VolumeError::TooLarge {
            path: path.to_path_buf(),
            msg: format!("{count} samples of {ty} overflow the addressable byte count"),
        })
}

/// Wraps decoded samples into a [`Volume`], keeping the file's path in the error
/// (`Volume::new` itself knows no path).
pub(super) fn finish_volume(
    path: &Path,
    dims: [usize; 3],
    spacing: [f64; 3],
    ty: SampleType,
    decoded: Decoded,
) -> Result<Volume, VolumeError> {
    let mut vol = Volume::new(dims, spacing, ty, decoded.samples)
        .map_err(|e| VolumeError::format(path, e.to_string()))?
        .with_offset(decoded.offset);
    vol.replaced_nonfinite = decoded.replaced;
    Ok(vol)
}

/// Deflate cannot expand data by more than 1032:1 (a 258-byte match in two
/// bits), so `compressed` bytes of gzip decompress to at most this many. Lets a
/// reader reject a header that claims terabytes over a tiny file before
/// allocating the buffer for them.
pub(super) fn max_gunzipped_len(compressed: u64) -> u64 {
    compressed.saturating_mul(1032).saturating_add(4096)
}

/// Reads until `buf` is full or the stream ends and returns how many bytes were
/// read. A stream that ends early is not an error here (gzip reports a cut-off
/// member as `UnexpectedEof`): the caller knows what it needed and says so.
pub(super) fn read_full<R: Read>(src: &mut R, buf: &mut [u8]) -> io::Result<usize> {
    let mut got = 0usize;
    while let Some(rest) = buf.get_mut(got..) {
        if rest.is_empty() {
            break;
        }
        match src.read(rest) {
            Ok(0) => break,
            // `min` guards against a reader that claims more than it was given.
            Ok(n) => got += n.min(rest.len()),
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => break,
            Err(e) => return Err(e),
        }
    }
    Ok(got)
}

/// Discards up to `n` bytes of `src` without allocating for them; returns how
/// many were there.
pub(super) fn skip_bytes<R: Read>(src: &mut R, n: u64) -> io::Result<u64> {
    let mut scratch = [0u8; 8192];
    let mut skipped = 0u64;
    while skipped < n {
        let want = usize::try_from(n - skipped)
            .unwrap_or(usize::MAX)
            .min(scratch.len());
        let got = read_full(src, &mut scratch[..want])?;
        skipped += got as u64;
        if got < want {
            break;
        }
    }
    Ok(skipped)
}

/// A gzip stream that failed to decompress, as a format error naming the file.
pub(super) fn gzip_error(path: &Path, err: io::Error) -> VolumeError {
    VolumeError::format(path, format!("gzip data is corrupt: {err}"))
}

/// A buffer of `len` zero bytes, or a `TooLarge` error instead of an abort when
/// the allocator refuses.
pub(super) fn zeroed_buffer(path: &Path, len: usize) -> Result<Vec<u8>, VolumeError> {
    let mut buf = Vec::new();
    buf.try_reserve_exact(len)
        .map_err(|_| VolumeError::TooLarge {
            path: path.to_path_buf(),
            msg: format!(
                "cannot allocate {} for the decompressed data",
                super::limits::human_bytes(len as u64)
            ),
        })?;
    buf.resize(len, 0);
    Ok(buf)
}

/// Streams the samples in the native type, little endian, in chunks so no
/// second copy of the volume is built.
pub(super) fn write_samples<W: Write>(out: &mut W, vol: &Volume) -> io::Result<()> {
    let (ty, offset) = (vol.native_type(), vol.offset());
    let mut buf: Vec<u8> = Vec::with_capacity(64 * 1024);
    for chunk in vol.samples().chunks(8192) {
        buf.clear();
        for &v in chunk {
            encode_sample(ty, offset + v as f64, &mut buf);
        }
        out.write_all(&buf)?;
    }
    Ok(())
}

/// One sample in the native type. Integer volumes hold integral values, so the
/// rounding only guards against samples edited after loading; `as` saturates
/// out-of-range values (and maps NaN to 0), which is the clamp we want.
pub(super) fn encode_sample(ty: SampleType, v: f64, out: &mut Vec<u8>) {
    match ty {
        SampleType::I8 => out.extend_from_slice(&(v.round() as i8).to_le_bytes()),
        SampleType::U8 => out.extend_from_slice(&(v.round() as u8).to_le_bytes()),
        SampleType::I16 => out.extend_from_slice(&(v.round() as i16).to_le_bytes()),
        SampleType::U16 => out.extend_from_slice(&(v.round() as u16).to_le_bytes()),
        SampleType::I32 => out.extend_from_slice(&(v.round() as i32).to_le_bytes()),
        SampleType::U32 => out.extend_from_slice(&(v.round() as u32).to_le_bytes()),
        SampleType::F32 => out.extend_from_slice(&(v as f32).to_le_bytes()),
        SampleType::F64 => out.extend_from_slice(&v.to_le_bytes()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::Endian;

    #[test]
    fn encode_clamps_and_rounds() {
        let mut out = Vec::new();
        encode_sample(SampleType::U8, 300.0, &mut out);
        encode_sample(SampleType::U8, -3.0, &mut out);
        encode_sample(SampleType::I8, 2.6, &mut out);
        encode_sample(SampleType::U16, f64::NAN, &mut out);
        assert_eq!(out, vec![255, 0, 3, 0, 0]);
    }

    #[test]
    fn implied_dims_prefers_z_and_skips_non_multiples() {
        // 64x64x94 u16 = 770048 bytes: only z can absorb the extra slice.
        assert_eq!(
            implied_dims([64, 64, 93], 2, 64 * 64 * 94 * 2),
            vec![[64, 64, 94]]
        );
        // Odd byte count for 2-byte samples: nothing fits.
        assert!(implied_dims([4, 4, 4], 2, 129).is_empty());
        // 4x4x8 samples: z=8, or y=8, or x=8.
        assert_eq!(
            implied_dims([4, 4, 4], 1, 128),
            vec![[4, 4, 8], [4, 8, 4], [8, 4, 4]]
        );
        assert!(implied_dims([4, 4, 4], 1, 0).is_empty());
    }

    #[test]
    fn mismatch_message_names_sizes_and_suggestions() {
        let spec = RawSpec {
            dims: [4, 4, 4],
            sample_type: SampleType::U8,
            endian: Endian::Little,
            spacing: [1.0; 3],
            offset: 0,
        };
        let msg = length_mismatch_message(&spec, 64, 128);
        assert!(
            msg.contains("64 bytes") && msg.contains("128 bytes"),
            "{msg}"
        );
        assert!(msg.contains("4x4x8"), "{msg}");
        assert!(msg.contains("2-byte sample type"), "{msg}");
    }

    #[test]
    fn read_full_and_skip_stop_at_end() {
        let data = [1u8, 2, 3, 4, 5];
        let mut src = &data[..];
        assert_eq!(skip_bytes(&mut src, 2).unwrap(), 2);
        let mut buf = [0u8; 8];
        assert_eq!(read_full(&mut src, &mut buf).unwrap(), 3);
        assert_eq!(&buf[..3], &[3, 4, 5]);
        assert_eq!(skip_bytes(&mut src, 10).unwrap(), 0);
    }

    #[test]
    fn byte_range_rejects_out_of_bounds() {
        let bytes = [0u8; 4];
        assert_eq!(byte_range(&bytes, 1, 3).map(<[u8]>::len), Some(2));
        assert!(byte_range(&bytes, 3, 5).is_none());
        assert!(byte_range(&bytes, u64::MAX, u64::MAX).is_none());
    }
}
