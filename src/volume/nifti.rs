//! NIfTI-1 single-file volumes (`.nii`, and gzip-compressed `.nii.gz`).
//!
//! Only the grid is read: dims, datatype, voxel size (`pixdim`) and the value
//! scaling (`scl_slope`, `scl_inter`). The qform/sform orientation is ignored:
//! the renderer works in grid coordinates × spacing (see SPEC.md). Gzip is
//! recognised by its magic bytes, not the name, since `.nii` files are often
//! compressed without being renamed (and the other way round).

use std::fs::File;
use std::io::{BufReader, Seek, SeekFrom};
use std::path::Path;

use super::gzip::{GzMembers, after_gzip, after_samples, drain};

use super::raw::{
    byte_range, data_byte_len, finish_volume, gzip_error, map_file, max_gunzipped_len, read_full,
    skip_bytes, zeroed_buffer,
};
use super::{
    Endian, LoadOptions, SampleType, Volume, VolumeError, checked_sample_count, decode_samples,
    limits,
};

/// `sizeof_hdr` of NIfTI-1 (and ANALYZE 7.5).
const HEADER_LEN: usize = 348;
/// `sizeof_hdr` of NIfTI-2, recognised only to say it is not supported.
const NIFTI2_HEADER_LEN: i32 = 540;
/// Header plus the 4-byte extension flag: the earliest data can start.
const MIN_VOX_OFFSET: u64 = 352;

/// What the reader needs from the 348-byte header.
#[derive(Debug, PartialEq)]
struct Header {
    dims: [usize; 3],
    ty: SampleType,
    endian: Endian,
    spacing: [f64; 3],
    vox_offset: u64,
    scale: Option<(f64, f64)>,
    /// The orientation (sform, else qform) reverses RAS's handedness: in
    /// index order, as snell renders, the volume is the scan's mirror image.
    mirrored: bool,
}

/// Reads a `.nii` or `.nii.gz` file.
pub fn read(path: &Path, opts: &LoadOptions) -> Result<Volume, VolumeError> {
    let mut file = crate::input::open(path).map_err(|e| VolumeError::io(path, e))?;
    let mut magic = [0u8; 2];
    let got = read_full(&mut file, &mut magic).map_err(|e| VolumeError::io(path, e))?;
    file.seek(SeekFrom::Start(0))
        .map_err(|e| VolumeError::io(path, e))?;
    if got == 2 && magic == [0x1f, 0x8b] {
        read_gzip(path, file, opts)
    } else {
        read_plain(path, file, opts)
    }
}

fn header_truncated(path: &Path, got: usize) -> VolumeError {
    VolumeError::Truncated {
        path: path.to_path_buf(),
        need: HEADER_LEN as u64,
        got: got as u64,
        what: "NIfTI-1 header".into(),
    }
}

fn describe(h: &Header) -> String {
    let [nx, ny, nz] = h.dims;
    format!(
        "{nx}x{ny}x{nz} samples of {} at offset {}",
        h.ty, h.vox_offset
    )
}

fn decode(
    path: &Path,
    h: &Header,
    count: usize,
    bytes: &[u8],
    opts: &LoadOptions,
) -> Result<Volume, VolumeError> {
    let decoded = decode_samples(path, bytes, h.ty, h.endian, count, h.scale, opts.allow_nan)?;
    // Scaled samples are real numbers, whatever the stored integers were: a
    // u16 CT with `scl_inter = -1024` holds negative values, which `snell
    // resample` would clamp to 0 if the volume still called itself u16.
    let ty = if h.scale.is_some() {
        SampleType::F32
    } else {
        h.ty
    };
    let mut vol = finish_volume(path, h.dims, h.spacing, ty, decoded)?;
    if h.mirrored {
        vol.warnings.push(super::mirror_warning(
            path,
            "its orientation (sform, else qform)",
        ));
    }
    Ok(vol)
}

/// Uncompressed: decode straight from a map of the file. Bytes after the image
/// are tolerated (the header is authoritative and says where the image ends),
/// with a warning that counts them.
fn read_plain(path: &Path, file: File, opts: &LoadOptions) -> Result<Volume, VolumeError> {
    let map = map_file(path, &file)?;
    let header_bytes = map
        .get(..HEADER_LEN)
        .ok_or_else(|| header_truncated(path, map.len()))?;
    let h = parse_header(path, header_bytes)?;
    let count = checked_sample_count(path, h.dims, opts.memory_limit)?;
    let need = data_byte_len(path, count, h.ty)?;
    let end = h.vox_offset.saturating_add(need);
    let bytes = byte_range(&map, h.vox_offset, end).ok_or_else(|| VolumeError::Truncated {
        path: path.to_path_buf(),
        need,
        got: (map.len() as u64).saturating_sub(h.vox_offset),
        what: describe(&h),
    })?;
    let mut vol = decode(path, &h, count, bytes, opts)?;
    let after = map.len() as u64 - end;
    if after > 0 {
        vol.warnings.push(after_samples(path, after, count, false));
    }
    Ok(vol)
}

/// Gzip: decompress the header, check the sizes it claims, then decompress
/// the image into a buffer allocated once, and read on to the stream's end
/// (checking its CRC) to count what follows the image for a warning.
fn read_gzip(path: &Path, file: File, opts: &LoadOptions) -> Result<Volume, VolumeError> {
    let compressed = file.metadata().map_err(|e| VolumeError::io(path, e))?.len();
    let mut dec = GzMembers::new(BufReader::new(file));
    let mut header_bytes = [0u8; HEADER_LEN];
    let got = read_full(&mut dec, &mut header_bytes).map_err(|e| gzip_error(path, e))?;
    if got < HEADER_LEN {
        return Err(header_truncated(path, got));
    }
    let h = parse_header(path, &header_bytes)?;
    let count = checked_sample_count(path, h.dims, opts.memory_limit)?;
    let need = data_byte_len(path, count, h.ty)?;

    let total = h.vox_offset.saturating_add(need);
    let most = max_gunzipped_len(compressed);
    if total > most {
        return Err(VolumeError::Truncated {
            path: path.to_path_buf(),
            need: total,
            got: most,
            what: format!(
                "{}; {compressed} bytes of gzip data decompress to at most {most} bytes",
                describe(&h)
            ),
        });
    }
    limits::check_bytes(
        path,
        need.saturating_add((count as u64).saturating_mul(4)),
        opts.memory_limit,
        &format!("decompressing {}", describe(&h)),
    )?;
    let need_len = usize::try_from(need).map_err(|_| VolumeError::TooLarge {
        path: path.to_path_buf(),
        msg: format!("{need} bytes of data do not fit in memory"),
    })?;

    // Extensions between the header and the image are skipped unread.
    let gap = h.vox_offset - HEADER_LEN as u64; // vox_offset >= 352 > 348
    let skipped = skip_bytes(&mut dec, gap).map_err(|e| gzip_error(path, e))?;
    if skipped < gap {
        return Err(VolumeError::Truncated {
            path: path.to_path_buf(),
            need,
            got: 0,
            what: format!(
                "{}; the decompressed file ends at byte {}",
                describe(&h),
                HEADER_LEN as u64 + skipped
            ),
        });
    }
    let mut buf = zeroed_buffer(path, need_len)?;
    let got = read_full(&mut dec, &mut buf).map_err(|e| gzip_error(path, e))?;
    if got < need_len {
        return Err(VolumeError::Truncated {
            path: path.to_path_buf(),
            need,
            got: got as u64,
            what: describe(&h),
        });
    }
    let more = drain(path, &mut dec, |_| false)?;
    let mut vol = decode(path, &h, count, &buf, opts)?;
    if more > 0 {
        vol.warnings.push(after_samples(path, more, count, true));
    }
    if dec.trailing > 0 {
        vol.warnings.push(after_gzip(path, dec.trailing));
    }
    Ok(vol)
}

/// Fixed-offset field access in the header's byte order.
struct Fields<'a> {
    bytes: &'a [u8],
    endian: Endian,
}

impl Fields<'_> {
    fn array<const N: usize>(&self, offset: usize) -> [u8; N] {
        // Offsets are constants within the 348 bytes the caller checked; the
        // fallback only keeps this total.
        let mut out = [0u8; N];
        if let Some(src) = self.bytes.get(offset..offset + N) {
            out.copy_from_slice(src);
        }
        out
    }
    fn i16(&self, offset: usize) -> i16 {
        let a = self.array(offset);
        match self.endian {
            Endian::Little => i16::from_le_bytes(a),
            Endian::Big => i16::from_be_bytes(a),
        }
    }
    fn f32(&self, offset: usize) -> f32 {
        let a = self.array(offset);
        match self.endian {
            Endian::Little => f32::from_le_bytes(a),
            Endian::Big => f32::from_be_bytes(a),
        }
    }
}

// Byte offsets of the NIfTI-1 header fields used here.
const OFF_DIM: usize = 40;
const OFF_DATATYPE: usize = 70;
const OFF_PIXDIM: usize = 76;
const OFF_VOX_OFFSET: usize = 108;
const OFF_SCL_SLOPE: usize = 112;
const OFF_SCL_INTER: usize = 116;
const OFF_MAGIC: usize = 344;
const OFF_QFORM_CODE: usize = 252;
const OFF_SFORM_CODE: usize = 254;
const OFF_SROW_X: usize = 280;

/// Parses and validates the header (`bytes` holds at least 348 bytes).
fn parse_header(path: &Path, bytes: &[u8]) -> Result<Header, VolumeError> {
    let size_bytes: [u8; 4] = Fields {
        bytes,
        endian: Endian::Little,
    }
    .array(0);
    let endian = match (
        i32::from_le_bytes(size_bytes),
        i32::from_be_bytes(size_bytes),
    ) {
        (348, _) => Endian::Little,
        (_, 348) => Endian::Big,
        (NIFTI2_HEADER_LEN, _) | (_, NIFTI2_HEADER_LEN) => {
            return Err(VolumeError::unsupported(
                path,
                "NIfTI-2 files are not supported",
            ));
        }
        (le, _) => {
            return Err(VolumeError::format(
                path,
                format!("not a NIfTI-1 file: sizeof_hdr is {le}, expected 348"),
            ));
        }
    };
    let f = Fields { bytes, endian };

    let magic: [u8; 4] = f.array(OFF_MAGIC);
    match &magic {
        b"n+1\0" => {}
        b"ni1\0" => {
            return Err(VolumeError::unsupported(
                path,
                "NIfTI header/image pairs (.hdr + .img, magic ni1) are not supported; convert to a single .nii",
            ));
        }
        _ => {
            return Err(VolumeError::format(
                path,
                format!(
                    "not a NIfTI-1 file: magic is {:?}, expected \"n+1\" (ANALYZE 7.5 files are not supported)",
                    String::from_utf8_lossy(&magic).trim_end_matches('\0')
                ),
            ));
        }
    }

    let dim: [i16; 8] = std::array::from_fn(|i| f.i16(OFF_DIM + 2 * i));
    let ndim = dim[0];
    if !(1..=7).contains(&ndim) {
        return Err(VolumeError::format(
            path,
            format!("dim[0] is {ndim}, expected 1 to 7"),
        ));
    }
    let ndim = ndim as usize;
    for (i, &d) in dim.iter().enumerate().take(ndim + 1).skip(1) {
        if d < 1 {
            return Err(VolumeError::format(
                path,
                format!("dim[{i}] is {d}, must be at least 1"),
            ));
        }
        if i > 3 && d != 1 {
            return Err(VolumeError::unsupported(
                path,
                format!(
                    "4-D volumes are not supported: dim[{i}] is {d} (dims {})",
                    dim.iter()
                        .skip(1)
                        .take(ndim)
                        .map(|d| d.to_string())
                        .collect::<Vec<_>>()
                        .join("x")
                ),
            ));
        }
    }
    // Axes beyond dim[0] are meaningless in the header and count as size 1.
    let dims: [usize; 3] = std::array::from_fn(|a| {
        if a < ndim {
            usize::try_from(dim[a + 1]).unwrap_or(1)
        } else {
            1
        }
    });

    let code = f.i16(OFF_DATATYPE);
    let ty = datatype(code).map_err(|name| {
        VolumeError::unsupported(path, format!("datatype {code} ({name}) is not supported"))
    })?;

    let spacing: [f64; 3] = std::array::from_fn(|a| {
        let p = f64::from(f.f32(OFF_PIXDIM + 4 * (a + 1)).abs());
        // A voxel size of 0 or NaN is common in hand-made files: 1 is the only
        // sensible reading, and axes beyond dim[0] have none.
        if a < ndim && p.is_finite() && p > 0.0 {
            p
        } else {
            1.0
        }
    });

    let vox = f.f32(OFF_VOX_OFFSET);
    // Up to 2^53 bytes (8 PiB): no file reaches it, and the offset stays
    // exact in the messages that print it.
    const MAX_VOX_OFFSET: f64 = 9_007_199_254_740_992.0;
    let v = f64::from(vox);
    if !vox.is_finite()
        || vox.fract() != 0.0
        || !(MIN_VOX_OFFSET as f64..=MAX_VOX_OFFSET).contains(&v)
    {
        return Err(VolumeError::format(
            path,
            format!(
                "vox_offset is {}, expected a whole number from {MIN_VOX_OFFSET} to 2^53",
                crate::human::exact(v)
            ),
        ));
    }
    let vox_offset = vox as u64; // whole, finite and in range: exact

    let slope = f64::from(f.f32(OFF_SCL_SLOPE));
    let inter = f64::from(f.f32(OFF_SCL_INTER));
    // Per the standard, slope 0 (or not a number) means "unscaled"; an
    // unusable intercept alongside a real slope is read as 0, as nibabel does.
    let scale = if slope.is_finite() && slope != 0.0 {
        let inter = if inter.is_finite() { inter } else { 0.0 };
        (slope != 1.0 || inter != 0.0).then_some((slope, inter))
    } else {
        None
    };

    // Orientation, as NIfTI's methods 3 and 2 give it (method 1, neither
    // code set, has none): the sform's 3×3 part, else the qform, whose
    // quaternion is a rotation and whose qfac (pixdim[0], -1 or else 1)
    // reverses the third axis. Only a grid with three axes has a handedness.
    let mirrored = ndim >= 3
        && if f.i16(OFF_SFORM_CODE) > 0 {
            super::reverses_handedness(std::array::from_fn(|row| {
                std::array::from_fn(|col| f64::from(f.f32(OFF_SROW_X + 16 * row + 4 * col)))
            }))
        } else {
            f.i16(OFF_QFORM_CODE) > 0 && f.f32(OFF_PIXDIM) < 0.0
        };

    Ok(Header {
        dims,
        ty,
        endian,
        spacing,
        vox_offset,
        scale,
        mirrored,
    })
}

/// The supported NIfTI datatype codes; the error is the code's name.
fn datatype(code: i16) -> Result<SampleType, &'static str> {
    Ok(match code {
        2 => SampleType::U8,
        4 => SampleType::I16,
        8 => SampleType::I32,
        16 => SampleType::F32,
        64 => SampleType::F64,
        256 => SampleType::I8,
        512 => SampleType::U16,
        768 => SampleType::U32,
        0 => return Err("unknown"),
        1 => return Err("binary"),
        32 => return Err("complex64"),
        128 => return Err("RGB24"),
        255 => return Err("all"),
        1024 => return Err("int64"),
        1280 => return Err("uint64"),
        1536 => return Err("float128"),
        1792 => return Err("complex128"),
        2048 => return Err("complex256"),
        2304 => return Err("RGBA32"),
        _ => return Err("not a NIfTI-1 datatype"),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A header with the given fields, in `endian` order.
    fn header_bytes(
        endian: Endian,
        dim: [i16; 8],
        datatype: i16,
        pixdim: [f32; 8],
        vox: f32,
        slope: f32,
        inter: f32,
    ) -> Vec<u8> {
        let mut h = vec![0u8; HEADER_LEN];
        let put = |h: &mut Vec<u8>, off: usize, b: &[u8]| h[off..off + b.len()].copy_from_slice(b);
        let i32b = |v: i32| match endian {
            Endian::Little => v.to_le_bytes(),
            Endian::Big => v.to_be_bytes(),
        };
        let i16b = |v: i16| match endian {
            Endian::Little => v.to_le_bytes(),
            Endian::Big => v.to_be_bytes(),
        };
        let f32b = |v: f32| match endian {
            Endian::Little => v.to_le_bytes(),
            Endian::Big => v.to_be_bytes(),
        };
        put(&mut h, 0, &i32b(348));
        for (i, d) in dim.iter().enumerate() {
            put(&mut h, OFF_DIM + 2 * i, &i16b(*d));
        }
        put(&mut h, OFF_DATATYPE, &i16b(datatype));
        for (i, p) in pixdim.iter().enumerate() {
            put(&mut h, OFF_PIXDIM + 4 * i, &f32b(*p));
        }
        put(&mut h, OFF_VOX_OFFSET, &f32b(vox));
        put(&mut h, OFF_SCL_SLOPE, &f32b(slope));
        put(&mut h, OFF_SCL_INTER, &f32b(inter));
        put(&mut h, OFF_MAGIC, b"n+1\0");
        h
    }

    const P: &str = "t.nii";

    fn basic(endian: Endian) -> Vec<u8> {
        header_bytes(
            endian,
            [3, 4, 5, 6, 1, 1, 1, 1],
            512,
            [1.0, 0.5, -2.0, 0.0, 1.0, 1.0, 1.0, 1.0],
            352.0,
            0.0,
            0.0,
        )
    }

    #[test]
    fn parses_both_byte_orders() {
        for endian in [Endian::Little, Endian::Big] {
            let h = parse_header(Path::new(P), &basic(endian)).unwrap();
            assert_eq!(
                h,
                Header {
                    dims: [4, 5, 6],
                    ty: SampleType::U16,
                    endian,
                    spacing: [0.5, 2.0, 1.0],
                    vox_offset: 352,
                    scale: None,
                    mirrored: false,
                }
            );
        }
    }

    /// A mirroring orientation warns, whichever form gives it; a rotation
    /// (two axes reversed) and a header without orientation do not.
    #[test]
    fn mirrored_orientations_are_told() {
        let with = |sform: Option<[[f32; 3]; 3]>, qfac: Option<f32>| {
            let mut h = basic(Endian::Little);
            if let Some(rows) = sform {
                h[OFF_SFORM_CODE..OFF_SFORM_CODE + 2].copy_from_slice(&2i16.to_le_bytes());
                for (i, row) in rows.iter().enumerate() {
                    for (j, v) in row.iter().enumerate() {
                        let o = OFF_SROW_X + 16 * i + 4 * j;
                        h[o..o + 4].copy_from_slice(&v.to_le_bytes());
                    }
                }
            }
            if let Some(q) = qfac {
                h[OFF_QFORM_CODE..OFF_QFORM_CODE + 2].copy_from_slice(&1i16.to_le_bytes());
                h[OFF_PIXDIM..OFF_PIXDIM + 4].copy_from_slice(&q.to_le_bytes());
            }
            parse_header(Path::new(P), &h).unwrap().mirrored
        };
        let flip_x = [[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let turn = [[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]];
        assert!(!with(None, None));
        assert!(with(Some(flip_x), None));
        assert!(!with(Some(turn), None));
        assert!(with(None, Some(-1.0)));
        assert!(!with(None, Some(1.0)));
        // The sform rules where both are set.
        assert!(!with(Some(turn), Some(-1.0)));
    }

    #[test]
    fn pads_low_dimensions_and_ignores_pixdim_beyond() {
        let b = header_bytes(
            Endian::Little,
            [2, 7, 9, 0, 0, 0, 0, 0],
            2,
            [1.0, 2.0, 3.0, 4.0, 0.0, 0.0, 0.0, 0.0],
            352.0,
            1.0,
            0.0,
        );
        let h = parse_header(Path::new(P), &b).unwrap();
        assert_eq!(
            (h.dims, h.spacing, h.scale),
            ([7, 9, 1], [2.0, 3.0, 1.0], None)
        );
    }

    #[test]
    fn scaling_rules() {
        let with = |slope, inter| {
            let b = header_bytes(
                Endian::Little,
                [3, 1, 1, 1, 1, 1, 1, 1],
                4,
                [1.0; 8],
                352.0,
                slope,
                inter,
            );
            parse_header(Path::new(P), &b).unwrap().scale
        };
        assert_eq!(with(2.0, -1.0), Some((2.0, -1.0)));
        assert_eq!(with(0.0, 5.0), None);
        assert_eq!(with(f32::NAN, 5.0), None);
        assert_eq!(with(1.0, 0.0), None);
        assert_eq!(with(0.5, f32::NAN), Some((0.5, 0.0)));
    }

    #[test]
    fn rejects_bad_headers() {
        let p = Path::new(P);
        let mut b = basic(Endian::Little);
        b[0] = 0;
        assert!(matches!(
            parse_header(p, &b),
            Err(VolumeError::Format { .. })
        ));
        let mut b = basic(Endian::Little);
        b[..4].copy_from_slice(&540i32.to_le_bytes());
        assert!(matches!(
            parse_header(p, &b),
            Err(VolumeError::Unsupported { .. })
        ));
        let mut b = basic(Endian::Little);
        b[OFF_MAGIC..OFF_MAGIC + 4].copy_from_slice(b"ni1\0");
        assert!(matches!(
            parse_header(p, &b),
            Err(VolumeError::Unsupported { .. })
        ));
        let b = header_bytes(
            Endian::Little,
            [8, 1, 1, 1, 1, 1, 1, 1],
            2,
            [1.0; 8],
            352.0,
            0.0,
            0.0,
        );
        assert!(parse_header(p, &b).is_err());
        let b = header_bytes(
            Endian::Little,
            [3, 4, -1, 1, 1, 1, 1, 1],
            2,
            [1.0; 8],
            352.0,
            0.0,
            0.0,
        );
        assert!(parse_header(p, &b).is_err());
        let b = header_bytes(
            Endian::Little,
            [4, 4, 4, 4, 3, 1, 1, 1],
            2,
            [1.0; 8],
            352.0,
            0.0,
            0.0,
        );
        let e = parse_header(p, &b).unwrap_err();
        assert!(
            e.to_string().contains("4-D volumes are not supported"),
            "{e}"
        );
        let b = header_bytes(
            Endian::Little,
            [4, 4, 4, 4, 1, 1, 1, 1],
            2,
            [1.0; 8],
            352.0,
            0.0,
            0.0,
        );
        assert_eq!(parse_header(p, &b).unwrap().dims, [4, 4, 4]);
        for vox in [348.0, 352.5, f32::NAN, -1.0, 1e30] {
            let b = header_bytes(
                Endian::Little,
                [3, 1, 1, 1, 1, 1, 1, 1],
                2,
                [1.0; 8],
                vox,
                0.0,
                0.0,
            );
            let e = parse_header(p, &b).unwrap_err().to_string();
            // The offset as the file holds it, not a saturated cast.
            if vox == 1e30 {
                assert!(e.contains("vox_offset is 1.0000000150474662e30"), "{e}");
            }
        }
        for code in [128i16, 32, 1024, 0, 3] {
            let b = header_bytes(
                Endian::Little,
                [3, 1, 1, 1, 1, 1, 1, 1],
                code,
                [1.0; 8],
                352.0,
                0.0,
                0.0,
            );
            let e = parse_header(p, &b).unwrap_err();
            assert!(e.to_string().contains(&code.to_string()), "{e}");
        }
    }
}
