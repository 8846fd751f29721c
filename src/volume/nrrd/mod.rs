//! NRRD volumes (teem's "nearly raw raster data"): attached `.nrrd` and
//! detached `.nhdr` headers, raw, gzip or ascii encoded, the data in one file
//! or split over many (`data file: LIST`, or a pattern such as
//! `slice%03d.raw 1 64 1`), plus a writer.
//!
//! The header is read as teem reads it: field names in any case, an unknown
//! field refused (skipped, a misspelt `spacing:` would leave the volume with
//! the wrong geometry, unsaid), Latin-1 kept in what nothing interprets, and
//! data after the samples left unread with a warning
//! ([`Volume::warnings`](super::Volume::warnings)). Only what a scalar 3-D
//! grid needs is interpreted: type, dimension, sizes, endian, encoding,
//! spacing (from `space directions` or `spacings`, never both on one axis),
//! skips and the data files, and `kinds` only to refuse an axis of
//! components (colour, vector) that would otherwise be read as a spatial one.
//! Orientation, origin and key/value pairs are ignored: the renderer works in
//! grid coordinates × spacing (see SPEC.md).
//!
//! Every size a header claims is checked before it is used to allocate, seek or
//! slice, so a hostile header ends in an error naming the file, never a panic
//! or an allocation the machine cannot make.
//!
//! Here: [`read`] in its three steps and the writer. [`header`] reads and
//! checks the header's lines into fields, [`layout`] checks the fields
//! against each other into a reading plan (dims, spacing, type, encoding,
//! skips, data files), and [`data`] finds the samples in the raw, ascii or
//! gzip data that plan names.

use std::fs::File;
use std::io::{self, BufReader, Write};
use std::path::Path;

use flate2::Compression;
use flate2::write::GzEncoder;

use super::raw::{data_byte_len, finish_volume, map_file, write_samples, zeroed_buffer};
use super::{
    LoadOptions, SampleType, Volume, VolumeError, checked_sample_count, decode_samples, limits,
};

mod data;
mod header;
mod layout;

use super::gzip::{after_gzip, after_samples};
use data::{ascii_region, gzip_region, raw_region};
use header::parse_header;
use layout::Layout;

/// A header longer than this is not a NRRD header (most likely binary data
/// without the blank line that should end the header).
const MAX_HEADER_BYTES: u64 = 8 << 20;
/// teem's `NRRD_DIM_MAX`; also bounds the per-axis lists a header can make us
/// allocate.
const MAX_DIMENSION: usize = 16;
/// Header versions this reader understands (`NRRD0001` .. `NRRD0005`).
const MAX_VERSION: u32 = 5;

/// How [`write`](fn@write) encodes the samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Encoding {
    Raw,
    Gzip,
    /// Decimal text, whitespace (or comma) separated: teem's `ascii`, for
    /// small hand-made volumes.
    Ascii,
}

impl Encoding {
    fn name(self) -> &'static str {
        match self {
            Encoding::Raw => "raw",
            Encoding::Gzip => "gzip",
            Encoding::Ascii => "ascii",
        }
    }
}

/// Reads a `.nrrd` (attached data) or `.nhdr` (detached data) file.
pub fn read(path: &Path, opts: &LoadOptions) -> Result<Volume, VolumeError> {
    let file = crate::input::open(path).map_err(|e| VolumeError::io(path, e))?;
    let mut reader = BufReader::new(file);
    let (fields, header_len) = parse_header(path, &mut reader)?;
    let layout = Layout::from_fields(path, &fields)?;
    let count = checked_sample_count(path, layout.dims, opts.memory_limit)?;
    let need = data_byte_len(path, count, layout.ty)?;
    let [nx, ny, nz] = layout.dims;
    let mut what = format!(
        "{nx}x{ny}x{nz} samples of {}, {} encoded",
        layout.ty,
        layout.encoding.name()
    );

    let decode = |bytes: &[u8]| {
        let decoded = decode_samples(
            path,
            bytes,
            layout.ty,
            layout.endian,
            count,
            None,
            opts.allow_nan,
        )?;
        finish_volume(path, layout.dims, layout.spacing, layout.ty, decoded)
    };

    let open = |data_path: &Path| {
        crate::input::open(data_path)
            .map(BufReader::new)
            .map_err(|e| data_file_error(path, data_path, e))
    };
    let enc = layout.encoding;
    let (mut vol, warnings) = match layout.data_files.as_slice() {
        [] => {
            let (vol, extra) = with_data(
                path, reader, header_len, &layout, need, count, opts, &what, decode,
            )?;
            (vol, extra.warnings(path, enc, count))
        }
        [data_path] => {
            what.push_str(&format!(" in data file {}", data_path.display()));
            let src = open(data_path)?;
            let (vol, extra) = with_data(path, src, 0, &layout, need, count, opts, &what, decode)?;
            (vol, extra.warnings(data_path, enc, count))
        }
        files => {
            // Each file holds an equal slab along the slowest axes, after
            // its own skips (teem's NRRD0005 reading).
            let n = files.len();
            let (count_each, need_each) = (count / n, need / n as u64);
            limits::check_bytes(
                path,
                need.saturating_add((count as u64).saturating_mul(4)),
                opts.memory_limit,
                &format!("reading {what} from {n} data files"),
            )?;
            let mut all = zeroed_buffer(path, need as usize)?;
            let mut warnings = Vec::new();
            let slots = all.chunks_exact_mut(need_each as usize);
            for (k, (data_path, slot)) in files.iter().zip(slots).enumerate() {
                let what = format!(
                    "{what}, data file {} of {n}: {}",
                    k + 1,
                    data_path.display()
                );
                let src = open(data_path)?;
                let ((), extra) = with_data(
                    path,
                    src,
                    0,
                    &layout,
                    need_each,
                    count_each,
                    opts,
                    &what,
                    |d| {
                        slot.copy_from_slice(d);
                        Ok(())
                    },
                )?;
                warnings.extend(extra.warnings(data_path, enc, count_each));
            }
            (decode(&all)?, warnings)
        }
    };
    vol.warnings
        .extend(layout.warnings.iter().cloned().chain(warnings));
    Ok(vol)
}

/// Hands `then` the `need` bytes of samples (`count` of them) of the file
/// `src` reads, from `start` (past an attached header) and its skips on, in
/// the layout's encoding; returns its result and what followed the samples.
#[allow(clippy::too_many_arguments)]
fn with_data<T>(
    path: &Path,
    src: BufReader<File>,
    start: u64,
    layout: &Layout,
    need: u64,
    count: usize,
    opts: &LoadOptions,
    what: &str,
    then: impl FnOnce(&[u8]) -> Result<T, VolumeError>,
) -> Result<(T, Extra), VolumeError> {
    match layout.encoding {
        Encoding::Raw => {
            let map = map_file(path, src.get_ref())?;
            let (data, extra) = raw_region(path, &map, start, layout, need, what)?;
            Ok((then(data)?, Extra::raw(extra)))
        }
        Encoding::Ascii => {
            let map = map_file(path, src.get_ref())?;
            let (data, extra) = ascii_region(path, &map, start, layout, count, opts, what)?;
            Ok((then(&data)?, Extra::raw(extra)))
        }
        Encoding::Gzip => {
            let compressed = file_len(path, src.get_ref())?.saturating_sub(start);
            let (data, extra) =
                gzip_region(path, src, compressed, layout, need, count, opts, what)?;
            Ok((then(&data)?, extra))
        }
    }
}

/// What followed the samples, left unread.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Extra {
    /// Bytes after the samples (raw), or after them in the decompressed
    /// stream (gzip): at least this many, counting stops at [`DRAIN_LIMIT`](super::gzip::DRAIN_LIMIT).
    data: u64,
    /// Bytes after the last gzip member that do not start another.
    after_gzip: u64,
}

impl Extra {
    fn raw(data: u64) -> Extra {
        Extra {
            data,
            after_gzip: 0,
        }
    }

    /// The warnings for `path`, a file whose `count` samples were read with
    /// `encoding`.
    fn warnings(self, path: &Path, encoding: Encoding, count: usize) -> Vec<String> {
        let mut out = Vec::new();
        let n = self.data;
        if n > 0 {
            out.push(match encoding {
                Encoding::Ascii => format!(
                    "{}: {n} more value{} after the {count} samples ignored",
                    path.display(),
                    if n == 1 { "" } else { "s" }
                ),
                e => after_samples(path, n, count, e == Encoding::Gzip),
            });
        }
        if self.after_gzip > 0 {
            out.push(after_gzip(path, self.after_gzip));
        }
        out
    }
}

fn file_len(path: &Path, file: &File) -> Result<u64, VolumeError> {
    Ok(file.metadata().map_err(|e| VolumeError::io(path, e))?.len())
}

/// An I/O error on a detached data file, reported against the header (the file
/// the user named) but saying which data file failed.
fn data_file_error(header: &Path, data: &Path, e: io::Error) -> VolumeError {
    VolumeError::io(
        header,
        io::Error::new(e.kind(), format!("data file {}: {e}", data.display())),
    )
}

// ---------------------------------------------------------------------------
// Writing

/// Writes `vol` as a NRRD0004 file with its native sample type, little endian,
/// its spacing as a diagonal `space directions`. The samples are converted back
/// exactly, so reading the file gives the same volume bit for bit.
///
/// The file is written to a temporary name in the same directory and renamed
/// into place, so a failure (full disk, interrupted run) never leaves a partial
/// file under `path`.
pub fn write(path: &Path, vol: &Volume, encoding: Encoding) -> Result<(), VolumeError> {
    crate::atomic::write_atomic(path, |out| {
        out.write_all(header_text(vol, encoding).as_bytes())?;
        match encoding {
            Encoding::Raw => write_samples(out, vol),
            Encoding::Gzip => {
                let mut gz = GzEncoder::new(out, Compression::default());
                write_samples(&mut gz, vol)?;
                gz.finish().map(|_| ())
            }
            Encoding::Ascii => write_text(out, vol),
        }
    })
    .map_err(|e| VolumeError::io(path, e))
}

fn header_text(vol: &Volume, encoding: Encoding) -> String {
    let [nx, ny, nz] = vol.dims();
    let [sx, sy, sz] = vol.spacing();
    let ty = vol.native_type();
    let mut h = String::from("NRRD0004\n# written by snell\n");
    h.push_str(&format!("type: {}\n", nrrd_type_name(ty)));
    h.push_str("dimension: 3\n");
    h.push_str(&format!("sizes: {nx} {ny} {nz}\n"));
    h.push_str("space dimension: 3\n");
    // Debug formatting of f64 is the shortest text that parses back to the same bits.
    h.push_str(&format!(
        "space directions: ({sx:?},0,0) (0,{sy:?},0) (0,0,{sz:?})\n"
    ));
    h.push_str("space origin: (0,0,0)\n");
    h.push_str("kinds: domain domain domain\n");
    if ty.size() > 1 && encoding != Encoding::Ascii {
        h.push_str("endian: little\n");
    }
    h.push_str(&format!("encoding: {}\n\n", encoding.name()));
    h
}

fn nrrd_type_name(ty: SampleType) -> &'static str {
    match ty {
        SampleType::I8 => "int8",
        SampleType::U8 => "uint8",
        SampleType::I16 => "int16",
        SampleType::U16 => "uint16",
        SampleType::I32 => "int32",
        SampleType::U32 => "uint32",
        SampleType::F32 => "float",
        SampleType::F64 => "double",
    }
}

/// The samples as decimal text in the native type, one row along x per
/// line; floats in their shortest form that reads back to the same bits.
fn write_text<W: Write>(out: &mut W, vol: &Volume) -> io::Result<()> {
    let (ty, offset) = (vol.native_type(), vol.offset());
    let mut line = String::new();
    for row in vol.samples().chunks(vol.dims()[0].max(1)) {
        line.clear();
        for (i, &v) in row.iter().enumerate() {
            if i > 0 {
                line.push(' ');
            }
            let v = offset + v as f64;
            // Integers as the raw encoding would store them.
            let text = match ty {
                SampleType::I8 => (v.round() as i8).to_string(),
                SampleType::U8 => (v.round() as u8).to_string(),
                SampleType::I16 => (v.round() as i16).to_string(),
                SampleType::U16 => (v.round() as u16).to_string(),
                SampleType::I32 => (v.round() as i32).to_string(),
                SampleType::U32 => (v.round() as u32).to_string(),
                SampleType::F32 => (v as f32).to_string(),
                SampleType::F64 => v.to_string(),
            };
            line.push_str(&text);
        }
        line.push('\n');
        out.write_all(line.as_bytes())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::io::Cursor;

    use super::data::{ring_write, skip_lines_from, skip_lines_in};
    use super::header::{Fields, TypeError, parse_directions, parse_type};
    use super::layout::{ByteSkip, DataFiles, format_index, grid_axes};
    use super::*;
    use crate::volume::Endian;

    fn header(text: &str) -> Result<(Fields, u64), VolumeError> {
        parse_header(
            Path::new("h.nrrd"),
            &mut Cursor::new(text.as_bytes().to_vec()),
        )
    }

    fn layout(text: &str) -> Result<Layout, VolumeError> {
        let (f, _) = header(text)?;
        Layout::from_fields(Path::new("h.nrrd"), &f)
    }

    #[test]
    fn non_spatial_kinds_are_refused() {
        let base = "NRRD0004\ntype: uchar\ndimension: 3\nencoding: raw\n";
        let with =
            |sizes: &str, kinds: &str| layout(&format!("{base}sizes: {sizes}\nkinds: {kinds}\n\n"));
        assert!(with("4 4 4", "domain domain domain").is_ok());
        assert!(with("4 4 4", "space ??? none").is_ok());
        // A single component is a scalar whatever its axis is called.
        assert!(with("1 4 4", "RGB-color domain domain").is_ok());
        for kinds in [
            "RGB-color domain domain",
            "domain 3-vector domain",
            "domain domain list",
        ] {
            let e = with("3 4 4", kinds).unwrap_err().to_string();
            assert!(e.contains("not a spatial axis"), "{kinds}: {e}");
        }
    }

    #[test]
    fn type_spellings() {
        for (s, t) in [
            ("unsigned char", SampleType::U8),
            ("uchar", SampleType::U8),
            ("uint8_t", SampleType::U8),
            ("signed char", SampleType::I8),
            ("int8", SampleType::I8),
            ("short", SampleType::I16),
            ("signed  short int", SampleType::I16),
            ("int16_t", SampleType::I16),
            ("ushort", SampleType::U16),
            ("unsigned short int", SampleType::U16),
            ("int", SampleType::I32),
            ("uint", SampleType::U32),
            ("uint32_t", SampleType::U32),
            ("float", SampleType::F32),
            ("double", SampleType::F64),
        ] {
            assert_eq!(parse_type(s).ok(), Some(t), "{s}");
        }
        assert!(matches!(parse_type("int64"), Err(TypeError::Unsupported)));
        assert!(matches!(
            parse_type("unsigned long long"),
            Err(TypeError::Unsupported)
        ));
        assert!(matches!(parse_type("block"), Err(TypeError::Unsupported)));
        assert!(matches!(parse_type("quaternion"), Err(TypeError::Unknown)));
    }

    #[test]
    fn header_ends_at_blank_line_and_counts_bytes() {
        let text = "NRRD0004\r\n# comment\r\ntype: uchar\r\ndimension: 3\r\nsizes: 2 3 4\r\nencoding: raw\r\nmy key:=my: value\r\nspace: left-posterior-superior\r\n\r\nDATA";
        let (f, len) = header(text).unwrap();
        assert_eq!(len as usize, text.len() - 4);
        assert_eq!(f.sizes, Some(vec![2, 3, 4]));
        assert_eq!(f.sample_type, Some(SampleType::U8));
    }

    #[test]
    fn detached_header_may_end_at_eof() {
        let (f, _) = header("NRRD0005\ntype: float\ndimension: 3\nsizes: 1 1 1\nendian: big\nencoding: gz\ndatafile: x.raw").unwrap();
        assert_eq!(f.data_file, Some(DataFiles::One("x.raw".into())));
        assert_eq!(f.encoding, Some(Encoding::Gzip));
        assert_eq!(f.endian, Some(Endian::Big));
    }

    #[test]
    fn magic_versions() {
        assert!(header("NRRD0001\n\n").is_ok());
        assert!(matches!(
            header("NRRD0006\n\n"),
            Err(VolumeError::Unsupported { .. })
        ));
        assert!(matches!(
            header("NRRD00\n\n"),
            Err(VolumeError::Format { .. })
        ));
        assert!(matches!(
            header("\u{89}PNG\r\n"),
            Err(VolumeError::Format { .. })
        ));
        assert!(matches!(header(""), Err(VolumeError::Format { .. })));
    }

    #[test]
    fn duplicate_and_malformed_lines() {
        let e = header("NRRD0004\nsizes: 1 1 1\nsizes: 2 2 2\n\n").unwrap_err();
        assert!(e.to_string().contains("twice"), "{e}");
        let e = header("NRRD0004\nthis is not a field\n\n").unwrap_err();
        assert!(e.to_string().contains("line 2"), "{e}");
        assert!(header("NRRD0004\nsizes: 1 -1 1\n\n").is_err());
        assert!(header("NRRD0004\ndimension: 0\n\n").is_err());
        assert!(header("NRRD0004\ndimension: 17\n\n").is_err());
        assert!(header("NRRD0004\nbyte skip: -2\n\n").is_err());
        assert!(header("NRRD0004\nline skip: -1\n\n").is_err());
        let e = header("NRRD0004\ntype: uint8\n\u{1}\u{2}:\u{3}\n\n").unwrap_err();
        assert!(e.to_string().contains("not text"), "{e}");
        assert!(header("NRRD0004\n# caf\u{e9} \u{1}\n\n").is_ok());
    }

    /// Field names as teem matches them: in any case; a name it does not
    /// know is refused, not skipped (a misspelt `spacing:` would otherwise
    /// leave the volume with the wrong geometry, unsaid).
    #[test]
    fn field_names_as_teem_reads_them() {
        let base = "NRRD0005\ntype: uint8\nencoding: raw\ndimension: 3\nsizes: 2 2 2\n";
        let l = layout(&format!("{base}Spacings: 2 3 4\n\n")).unwrap();
        assert_eq!(l.spacing, [2.0, 3.0, 4.0]);
        let l = layout(&format!(
            "{base}SPACE: LPS\nSpace Directions: (2,0,0) (0,3,0) (0,0,4)\n\n"
        ))
        .unwrap();
        assert_eq!(l.spacing, [2.0, 3.0, 4.0]);
        let e = layout(&format!("{base}spacing: 2 3 4\n\n")).unwrap_err();
        assert!(e.to_string().contains("unknown field 'spacing'"), "{e}");
        // teem's other fields are known and change nothing here.
        let l = layout(&format!(
            "{base}space origin: (1,2,3)\ncenterings: cell cell cell\nmeasurement frame: (1,0,0) (0,1,0) (0,0,1)\nthicknesses: 1 1 1\nold min: 0\nsample units: HU\nBlock Size: 1\n\n"
        ))
        .unwrap();
        assert_eq!(l.spacing, [1.0; 3]);
    }

    /// An axis with both a direction and a spacing is refused (teem too);
    /// a direction has the space's number of components.
    #[test]
    fn directions_and_spacings_agree_with_the_space() {
        let base = "NRRD0005\ntype: uint8\nencoding: raw\ndimension: 3\nsizes: 2 2 2\n";
        let dirs = "space directions: (2,0,0) (0,3,0) (0,0,4)\n";
        let e = layout(&format!("{base}{dirs}spacings: 2 3 4\n\n")).unwrap_err();
        assert!(e.to_string().contains("axis 0 has both"), "{e}");
        let l = layout(&format!("{base}{dirs}spacings: nan nan nan\n\n")).unwrap();
        assert_eq!(l.spacing, [2.0, 3.0, 4.0]);
        let e = layout(&format!(
            "{base}space: RAST\nspace directions: (2,0,0,0) (0,3,0,0) (0,0,4)\n\n"
        ))
        .unwrap_err();
        assert!(e.to_string().contains("axis 2 has 3 components"), "{e}");
        let e = layout(&format!("{base}space dimension: 2\n{dirs}\n")).unwrap_err();
        assert!(e.to_string().contains("not the space's 2"), "{e}");
        let e = layout(&format!("{base}space: LPS\nspace dimension: 4\n\n")).unwrap_err();
        assert!(e.to_string().contains("disagree"), "{e}");
        assert!(header("NRRD0005\nspace: somewhere\n\n").is_err());
    }

    /// Latin-1 in what nothing reads (key/value pairs, `content`), as teem
    /// keeps it; control bytes there still mean binary data.
    #[test]
    fn latin1_metadata_is_kept_as_bytes() {
        let mut h = b"NRRD0005\ntype: uint8\n".to_vec();
        h.extend_from_slice(b"patient:=J\xf6rg\ncontent: Sch\xe4del\n\n");
        assert!(parse_header(Path::new("h.nrrd"), &mut Cursor::new(h)).is_ok());
        let h = b"NRRD0005\ntype: uint8\nk:=\xf6\x01\n\n".to_vec();
        let e = parse_header(Path::new("h.nrrd"), &mut Cursor::new(h)).unwrap_err();
        assert!(e.to_string().contains("not text"), "{e}");
        let h = b"NRRD0005\nsizes: 2 \xf6\n\n".to_vec();
        assert!(parse_header(Path::new("h.nrrd"), &mut Cursor::new(h)).is_err());
    }

    #[test]
    fn directions_parse_with_spaces_and_none() {
        let d = parse_directions("( 1, 0,0)  (0,2.5,0) none (0,0,-3)").unwrap();
        assert_eq!(d.len(), 4);
        assert_eq!(d[1], Some(vec![0.0, 2.5, 0.0]));
        assert_eq!(d[2], None);
        assert!(parse_directions("(1,0,0").is_err());
        assert!(parse_directions("(1,x,0)").is_err());
        assert!(parse_directions("1,0,0").is_err());
        assert!(parse_directions("").is_err());
    }

    #[test]
    fn spacing_from_directions_and_spacings() {
        let base = "NRRD0004\ntype: uint8\nencoding: raw\n";
        let l = layout(&format!(
            "{base}dimension: 3\nsizes: 2 2 2\nspace directions: (0.5,0,0) (0,-2,0) (0,0,1.5)\n\n"
        ))
        .unwrap();
        assert_eq!(l.spacing, [0.5, 2.0, 1.5]);
        // One reversed axis: rendered in index order, a mirror image.
        assert_eq!(l.warnings.len(), 1, "{:?}", l.warnings);
        assert!(l.warnings[0].contains("mirror image"), "{:?}", l.warnings);
        // Rotated axes: the spacing is each vector's length; a rotation
        // (two axes reversed among them) keeps the shape, unwarned.
        let l = layout(&format!(
            "{base}dimension: 3\nsizes: 2 2 2\nspace directions: (3,4,0) (0,0,2) (4,-3,0)\n\n"
        ))
        .unwrap();
        assert_eq!(l.spacing, [5.0, 2.0, 5.0]);
        assert!(l.warnings.is_empty(), "{:?}", l.warnings);
        let l = layout(&format!(
            "{base}dimension: 3\nsizes: 2 2 2\nspace directions: (-1,0,0) (0,-1,0) (0,0,1)\n\n"
        ))
        .unwrap();
        assert!(l.warnings.is_empty(), "{:?}", l.warnings);
        // The same rotated axes with the third reversed: mirrored.
        let l = layout(&format!(
            "{base}dimension: 3\nsizes: 2 2 2\nspace directions: (3,4,0) (0,0,2) (-4,3,0)\n\n"
        ))
        .unwrap();
        assert!(
            l.warnings.iter().any(|w| w.contains("mirror image")),
            "{:?}",
            l.warnings
        );
        // In a left-handed space, the same directions are its own frame.
        let l = layout(&format!(
            "{base}dimension: 3\nsizes: 2 2 2\nspace: LAS\nspace directions: (3,4,0) (0,0,2) (-4,3,0)\n\n"
        ))
        .unwrap();
        assert!(l.warnings.is_empty(), "{:?}", l.warnings);
        // Sheared axes (a gantry tilt of 20°): kept as lengths, with a
        // warning naming the axes and their angle.
        let l = layout(&format!(
            "{base}dimension: 3\nsizes: 2 2 2\nspace directions: (1,0,0) (0,1,0) (0,0.3420201433256687,0.9396926207859084)\n\n"
        ))
        .unwrap();
        assert_eq!(l.warnings.len(), 1, "{:?}", l.warnings);
        assert!(
            l.warnings[0].contains("axes 1 and 2 are 70.00° apart"),
            "{:?}",
            l.warnings
        );
        let l = layout(&format!(
            "{base}dimension: 2\nsizes: 2 2\nspacings: 0.25 nan\n\n"
        ))
        .unwrap();
        assert_eq!((l.dims, l.spacing), ([2, 2, 1], [0.25, 1.0, 1.0]));
        assert!(
            layout(&format!(
                "{base}dimension: 3\nsizes: 2 2 2\nspace directions: (1,0,0) none (0,0,1)\n\n"
            ))
            .is_err()
        );
        assert!(
            layout(&format!(
                "{base}dimension: 3\nsizes: 2 2 2\nspace directions: (1,0,0) (0,0,0) (0,0,1)\n\n"
            ))
            .is_err()
        );
        assert!(
            layout(&format!(
                "{base}dimension: 3\nsizes: 2 2 2\nspacings: 1 0 1\n\n"
            ))
            .is_err()
        );
        assert!(
            layout(&format!(
                "{base}dimension: 3\nsizes: 2 2 2\nspacings: 1 1\n\n"
            ))
            .is_err()
        );
    }

    #[test]
    fn higher_dimensions_only_with_unit_axes() {
        let base = "NRRD0004\ntype: uint8\nencoding: raw\ndimension: 4\n";
        let l = layout(&format!(
            "{base}sizes: 3 4 5 1\nspace directions: (1,0,0) (0,1,0) (0,0,2) none\n\n"
        ))
        .unwrap();
        assert_eq!((l.dims, l.spacing), ([3, 4, 5], [1.0, 1.0, 2.0]));
        assert!(matches!(
            layout(&format!("{base}sizes: 3 4 5 2\n\n")),
            Err(VolumeError::Unsupported { .. })
        ));
        // A leading unit axis (a one-component vector axis) is dropped too.
        let l = layout(&format!(
            "{base}sizes: 1 3 4 5\nkinds: vector domain domain domain\nspace directions: none (1,0,0) (0,3,0) (0,0,2)\n\n"
        ))
        .unwrap();
        assert_eq!((l.dims, l.spacing), ([3, 4, 5], [1.0, 3.0, 2.0]));
        assert_eq!(grid_axes(&[3, 1, 1, 1]), Some(vec![0, 1, 2]));
        assert_eq!(grid_axes(&[1, 3, 1, 4]), Some(vec![0, 1, 3]));
        assert_eq!(grid_axes(&[2, 3, 1, 4, 5]), None);
        assert!(layout(&format!("{base}sizes: 3 4 5\n\n")).is_err());
    }

    #[test]
    fn endian_required_only_for_multibyte() {
        let base = "NRRD0004\nencoding: raw\ndimension: 1\nsizes: 4\n";
        assert!(layout(&format!("{base}type: uint8\n\n")).is_ok());
        let e = layout(&format!("{base}type: uint16\n\n")).unwrap_err();
        assert!(e.to_string().contains("endian"), "{e}");
    }

    #[test]
    fn byte_skip_minus_one_is_data_at_the_end() {
        let base = "NRRD0004\ntype: uint8\ndimension: 1\nsizes: 4\nbyte skip: -1\n";
        for enc in ["raw", "gzip"] {
            assert_eq!(
                layout(&format!("{base}encoding: {enc}\n\n"))
                    .unwrap()
                    .byte_skip,
                ByteSkip::DataAtEnd
            );
        }
    }

    #[test]
    fn ring_keeps_the_last_bytes() {
        let mut buf = [0u8; 5];
        let mut at = 0;
        let mut all = Vec::new();
        for chunk in [&b"abc"[..], b"de", b"f", b"ghijklm", b"no"] {
            at = ring_write(&mut buf, at, chunk);
            all.extend_from_slice(chunk);
            let mut got = buf;
            got.rotate_left(at);
            if all.len() >= 5 {
                assert_eq!(&got, &all[all.len() - 5..]);
            }
        }
    }

    #[test]
    fn unsupported_encodings_and_data_files() {
        for enc in ["bzip2", "hex", "zrl", "lzma"] {
            let e = header(&format!("NRRD0004\nencoding: {enc}\n\n")).unwrap_err();
            assert!(
                matches!(e, VolumeError::Unsupported { .. }) && e.to_string().contains(enc),
                "{e}"
            );
        }
    }

    /// teem's three forms of `data file`, and the count of files checked
    /// against the slabs the sizes make.
    #[test]
    fn data_file_forms() {
        let p = Path::new("/d/h.nhdr");
        let paths = |value: &str, sizes: &[usize]| DataFiles::parse(value).unwrap().paths(p, sizes);
        assert_eq!(
            paths("a b.raw", &[2, 2, 2]).unwrap(),
            [Path::new("/d/a b.raw")]
        );
        assert_eq!(
            paths("/x/y.raw", &[2, 2, 2]).unwrap(),
            [Path::new("/x/y.raw")]
        );
        assert_eq!(
            paths("s%03d.raw 8 12 2", &[4, 4, 3]).unwrap(),
            ["/d/s008.raw", "/d/s010.raw", "/d/s012.raw"].map(Path::new)
        );
        assert_eq!(
            paths("s%d.raw 3 1 -1", &[4, 4, 3]).unwrap(),
            ["/d/s3.raw", "/d/s2.raw", "/d/s1.raw"].map(Path::new)
        );
        // Slabs of dimension 1: a file per row.
        assert_eq!(paths("r%u.gz 0 5 1 1", &[4, 3, 2]).unwrap().len(), 6);
        let e = paths("s%03d.raw 1 10 1", &[4, 4, 3]).unwrap_err();
        assert!(e.to_string().contains("names 10 files"), "{e}");
        let e = paths("s%03d.raw 1 1 1 4", &[4, 4, 3]).unwrap_err();
        assert!(e.to_string().contains("slab dimension 4"), "{e}");
        assert!(DataFiles::parse("s%03d.raw 1 10 0").is_err());
        assert!(DataFiles::parse("s%03d.raw 10 1 1").is_err());
        assert!(DataFiles::parse("s%s.raw 1 10 1").is_err());
        assert!(DataFiles::parse("s%d%d.raw 1 10 1").is_err());
        assert!(DataFiles::parse("LIST 2 3").is_err());
        assert_eq!(format_index("a%%%4d", -7).unwrap(), "a%  -7");
        assert_eq!(format_index("%05i", -7).unwrap(), "-0007");

        let text = "NRRD0005\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: LIST\nz0.raw\nsub dir/z1.raw\n";
        let (f, _) = header(text).unwrap();
        let l = Layout::from_fields(p, &f).unwrap();
        assert_eq!(
            l.data_files,
            ["/d/z0.raw", "/d/sub dir/z1.raw"].map(Path::new)
        );
        let (f, _) = header("NRRD0005\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: LIST\nz0.raw\n").unwrap();
        assert!(Layout::from_fields(p, &f).is_err());
    }

    #[test]
    fn skip_lines_helpers() {
        assert_eq!(skip_lines_in(b"a\nb\ncd", 2), Some(&b"cd"[..]));
        assert_eq!(skip_lines_in(b"a\nb", 2), None);
        let mut c = Cursor::new(b"a\nbb\ncd".to_vec());
        assert_eq!(skip_lines_from(&mut c, 2).unwrap(), Some(5));
        let mut c = Cursor::new(b"a".to_vec());
        assert_eq!(skip_lines_from(&mut c, 1).unwrap(), None);
    }
}
