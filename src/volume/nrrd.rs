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

use std::fs::File;
use std::io::{self, BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};

use flate2::Compression;
use flate2::write::GzEncoder;

use super::raw::{
    byte_range, data_byte_len, finish_volume, gzip_error, map_file, max_gunzipped_len, read_full,
    skip_bytes, write_samples, zeroed_buffer,
};
use super::{
    Endian, LoadOptions, SampleType, Volume, VolumeError, checked_sample_count, decode_samples,
    limits,
};

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
        let (samples, replaced) = decode_samples(
            path,
            bytes,
            layout.ty,
            layout.endian,
            count,
            None,
            opts.allow_nan,
        )?;
        finish_volume(
            path,
            layout.dims,
            layout.spacing,
            layout.ty,
            samples,
            replaced,
        )
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
    vol.warnings.extend(warnings);
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
    /// stream (gzip): at least this many, counting stops at [`DRAIN_LIMIT`].
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
        if self.data > 0 {
            let n = self.data;
            let s = if n == 1 { "" } else { "s" };
            let what = match (encoding, n >= DRAIN_LIMIT) {
                (Encoding::Raw, _) => format!("{n} byte{s}"),
                (Encoding::Ascii, _) => format!("{n} more value{s}"),
                (Encoding::Gzip, false) => format!("{n} more decompressed byte{s}"),
                (Encoding::Gzip, true) => format!("at least {n} more decompressed bytes"),
            };
            out.push(format!(
                "{}: {what} after the {count} samples ignored",
                path.display()
            ));
        }
        if self.after_gzip > 0 {
            let n = self.after_gzip;
            out.push(format!(
                "{}: {n} byte{} after the gzip data, not gzip, {} ignored",
                path.display(),
                if n == 1 { "" } else { "s" },
                if n == 1 { "was" } else { "were" },
            ));
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
// Header parsing

/// The fields this reader interprets, as parsed from the header lines.
#[derive(Debug, Default)]
struct Fields {
    sample_type: Option<SampleType>,
    dimension: Option<usize>,
    sizes: Option<Vec<usize>>,
    endian: Option<Endian>,
    encoding: Option<Encoding>,
    spacings: Option<Vec<f64>>,
    /// One entry per axis; `None` for a `none` (non-spatial) axis.
    space_directions: Option<Vec<Option<Vec<f64>>>>,
    byte_skip: Option<i64>,
    line_skip: Option<u64>,
    data_file: Option<DataFiles>,
    /// One word per axis, as written (`domain`, `RGB-color`, ...).
    kinds: Option<Vec<String>>,
    /// `space dimension`, and the dimension of a named `space`: the
    /// components a space direction must have.
    space_dimension: Option<usize>,
    space: Option<usize>,
}

/// Reads the header up to the blank line that ends it (or the end of the file,
/// as a detached header may). Returns the fields and the header's length in
/// bytes, i.e. where attached data starts.
fn parse_header<R: BufRead>(path: &Path, reader: &mut R) -> Result<(Fields, u64), VolumeError> {
    let mut line = Vec::new();
    let mut consumed = next_line(path, reader, &mut line, 64)? as u64;
    let magic = String::from_utf8_lossy(trim_eol(&line)).trim().to_string();
    check_magic(path, &magic)?;

    let mut fields = Fields::default();
    let mut line_no = 1usize;
    loop {
        let budget = MAX_HEADER_BYTES.saturating_sub(consumed);
        if budget == 0 {
            return Err(VolumeError::format(
                path,
                format!(
                    "header is longer than {} without the blank line that ends it",
                    limits::human_bytes(MAX_HEADER_BYTES)
                ),
            ));
        }
        let n = next_line(path, reader, &mut line, budget)?;
        if n == 0 {
            break; // end of file: a detached header needs no blank line
        }
        consumed += n as u64;
        line_no += 1;
        if line.last() != Some(&b'\n') && n as u64 == budget {
            continue; // over budget: reported at the top of the loop
        }
        let text = trim_eol(&line);
        if text.is_empty() {
            break;
        }
        let readable = if is_free_text(text) {
            !has_control(text)
        } else {
            is_text(text)
        };
        if !text.starts_with(b"#") && !readable {
            return Err(VolumeError::format(
                path,
                format!(
                    "header line {line_no} is not text (binary data before the blank line that ends the header?)"
                ),
            ));
        }
        let text = String::from_utf8_lossy(text);
        // After `data file: LIST`, each line names a data file.
        if let Some(DataFiles::List { names, .. }) = &mut fields.data_file {
            names.push(text.into_owned());
            continue;
        }
        parse_line(path, line_no, &text, &mut fields)?;
    }
    Ok((fields, consumed))
}

/// Reads one line (with its `\n`) of at most `budget` bytes into `buf`.
fn next_line<R: BufRead>(
    path: &Path,
    reader: &mut R,
    buf: &mut Vec<u8>,
    budget: u64,
) -> Result<usize, VolumeError> {
    buf.clear();
    (&mut *reader)
        .take(budget)
        .read_until(b'\n', buf)
        .map_err(|e| VolumeError::io(path, e))
}

/// UTF-8 without control characters (tabs allowed).
fn is_text(line: &[u8]) -> bool {
    std::str::from_utf8(line).is_ok_and(|s| !s.chars().any(|c| c.is_control() && c != '\t'))
}

/// A line nothing here interprets — a comment, a `key:=value` pair or the
/// `content` field — which old files write in Latin-1 and teem keeps as
/// bytes: it need not be UTF-8, only free of control characters (comments
/// not even that), which binary data before the header's end would hold.
fn is_free_text(line: &[u8]) -> bool {
    if line.starts_with(b"#") {
        return true;
    }
    line.iter().position(|&b| b == b':').is_some_and(|i| {
        line.get(i + 1) == Some(&b'=') || line[..i].trim_ascii().eq_ignore_ascii_case(b"content")
    })
}

/// A control byte other than a tab (ASCII's and DEL).
fn has_control(line: &[u8]) -> bool {
    line.iter().any(|&b| (b < 0x20 && b != b'\t') || b == 0x7f)
}

fn trim_eol(line: &[u8]) -> &[u8] {
    let line = line.strip_suffix(b"\n").unwrap_or(line);
    line.strip_suffix(b"\r").unwrap_or(line)
}

fn check_magic(path: &Path, magic: &str) -> Result<(), VolumeError> {
    let version = magic
        .strip_prefix("NRRD")
        .filter(|v| v.len() == 4 && v.bytes().all(|b| b.is_ascii_digit()))
        .and_then(|v| v.parse::<u32>().ok());
    match version {
        Some(v) if (1..=MAX_VERSION).contains(&v) => Ok(()),
        Some(v) => Err(VolumeError::unsupported(
            path,
            format!(
                "NRRD format version {v} is not supported (only NRRD0001 to NRRD000{MAX_VERSION})"
            ),
        )),
        None => Err(VolumeError::format(
            path,
            "not a NRRD file: it does not start with the magic line NRRD000N",
        )),
    }
}

/// A line's text shortened for an error message.
fn excerpt(text: &str) -> String {
    let mut s: String = text.chars().take(60).collect();
    if s.len() < text.len() {
        s.push_str("...");
    }
    s
}

fn parse_line(
    path: &Path,
    line_no: usize,
    text: &str,
    fields: &mut Fields,
) -> Result<(), VolumeError> {
    if text.starts_with('#') {
        return Ok(());
    }
    let Some((name, rest)) = text.split_once(':') else {
        return Err(VolumeError::format(
            path,
            format!(
                "header line {line_no} is not a \"field: value\" line: {:?}",
                excerpt(text)
            ),
        ));
    };
    if rest.starts_with('=') {
        return Ok(()); // key:=value pair, free-form metadata
    }
    let value = rest.trim();
    let bad =
        |msg: String| VolumeError::format(path, format!("header line {line_no} ({name}): {msg}"));

    // teem matches field names without regard to case (`Spacings:` is
    // `spacings:`), and so must this: skipped, such a line would leave the
    // volume with the wrong geometry and no word said.
    match name.trim().to_ascii_lowercase().as_str() {
        "type" => {
            let ty = parse_type(value).map_err(|e| match e {
                TypeError::Unsupported => VolumeError::unsupported(
                    path,
                    format!(
                        "sample type '{value}' is not supported (only 8-, 16- and 32-bit integers, float and double)"
                    ),
                ),
                TypeError::Unknown => bad(format!("unknown sample type '{}'", excerpt(value))),
            })?;
            set_once(&mut fields.sample_type, ty, &bad)
        }
        "dimension" => set_once(&mut fields.dimension, parse_dimension(value, &bad)?, &bad),
        "sizes" => {
            let sizes = parse_list(value, |s| s.parse::<usize>().ok())
                .map_err(|tok| bad(format!("'{}' is not a size", excerpt(&tok))))?;
            set_once(&mut fields.sizes, sizes, &bad)
        }
        "endian" => {
            let e = Endian::parse(value)
                .ok_or_else(|| bad(format!("'{}' is neither little nor big", excerpt(value))))?;
            set_once(&mut fields.endian, e, &bad)
        }
        "encoding" => {
            let enc = parse_encoding(value).ok_or_else(|| {
                VolumeError::unsupported(
                    path,
                    format!(
                        "encoding '{}' is not supported (only raw, gzip and ascii)",
                        excerpt(value)
                    ),
                )
            })?;
            set_once(&mut fields.encoding, enc, &bad)
        }
        "spacings" => {
            let sp = parse_list(value, |s| s.parse::<f64>().ok())
                .map_err(|tok| bad(format!("'{}' is not a number", excerpt(&tok))))?;
            set_once(&mut fields.spacings, sp, &bad)
        }
        "space directions" | "spacedirections" => {
            let dirs = parse_directions(value).map_err(bad)?;
            set_once(&mut fields.space_directions, dirs, &bad)
        }
        "byte skip" | "byteskip" => {
            let skip = value
                .parse::<i64>()
                .ok()
                .filter(|&s| s >= -1)
                .ok_or_else(|| {
                    bad(format!(
                        "'{}' is not a byte count (or -1 for data at the end of the file)",
                        excerpt(value)
                    ))
                })?;
            set_once(&mut fields.byte_skip, skip, &bad)
        }
        "line skip" | "lineskip" => {
            let skip = value
                .parse::<u64>()
                .map_err(|_| bad(format!("'{}' is not a line count", excerpt(value))))?;
            set_once(&mut fields.line_skip, skip, &bad)
        }
        "data file" | "datafile" => {
            if value.is_empty() {
                return Err(bad("no file named".into()));
            }
            let files = DataFiles::parse(value).map_err(bad)?;
            set_once(&mut fields.data_file, files, &bad)
        }
        "kinds" => {
            let kinds = value.split_whitespace().map(str::to_string).collect();
            set_once(&mut fields.kinds, kinds, &bad)
        }
        "space dimension" | "spacedimension" => set_once(
            &mut fields.space_dimension,
            parse_dimension(value, &bad)?,
            &bad,
        ),
        "space" => {
            let d = space_dimension(value)
                .ok_or_else(|| bad(format!("unknown space '{}'", excerpt(value))))?;
            set_once(&mut fields.space, d, &bad)
        }
        // The rest of teem's fields do not change how the samples are read.
        "content" | "number" | "block size" | "blocksize" | "thicknesses" | "axis mins"
        | "axismins" | "axis maxs" | "axismaxs" | "centers" | "centerings" | "labels" | "units"
        | "min" | "max" | "old min" | "oldmin" | "old max" | "oldmax" | "sample units"
        | "sampleunits" | "space units" | "spaceunits" | "space origin" | "spaceorigin"
        | "measurement frame" | "measurementframe" => Ok(()),
        // teem refuses a field it does not know; a misspelt `spacing:` read
        // as nothing would again give the wrong geometry.
        _ => Err(bad(format!(
            "unknown field '{}' (free-form metadata is written 'key:=value')",
            excerpt(name.trim())
        ))),
    }
}

/// A `dimension` or `space dimension` value: 1 to [`MAX_DIMENSION`].
fn parse_dimension(value: &str, bad: &dyn Fn(String) -> VolumeError) -> Result<usize, VolumeError> {
    value
        .parse::<usize>()
        .ok()
        .filter(|d| (1..=MAX_DIMENSION).contains(d))
        .ok_or_else(|| {
            bad(format!(
                "'{}' is not a dimension from 1 to {MAX_DIMENSION}",
                excerpt(value)
            ))
        })
}

/// The dimension of one of teem's named spaces (`space: LPS`, ...).
fn space_dimension(name: &str) -> Option<usize> {
    Some(match name.to_ascii_lowercase().as_str() {
        "right-anterior-superior"
        | "ras"
        | "left-anterior-superior"
        | "las"
        | "left-posterior-superior"
        | "lps"
        | "scanner-xyz"
        | "3d-right-handed"
        | "3d-left-handed" => 3,
        "right-anterior-superior-time"
        | "rast"
        | "left-anterior-superior-time"
        | "last"
        | "left-posterior-superior-time"
        | "lpst"
        | "scanner-xyz-time"
        | "3d-right-handed-time"
        | "3d-left-handed-time" => 4,
        _ => return None,
    })
}

/// Stores a field, refusing a second occurrence: teem rejects those too, and
/// two conflicting `sizes` lines mean the header cannot be trusted.
fn set_once<T>(
    slot: &mut Option<T>,
    value: T,
    bad: &dyn Fn(String) -> VolumeError,
) -> Result<(), VolumeError> {
    if slot.is_some() {
        return Err(bad("field given twice".into()));
    }
    *slot = Some(value);
    Ok(())
}

/// Whitespace-separated list of at most [`MAX_DIMENSION`] values; the error
/// carries the offending token.
fn parse_list<T>(value: &str, parse: impl Fn(&str) -> Option<T>) -> Result<Vec<T>, String> {
    let mut out = Vec::new();
    for tok in value.split_whitespace() {
        if out.len() == MAX_DIMENSION {
            return Err(format!("more than {MAX_DIMENSION} values"));
        }
        out.push(parse(tok).ok_or_else(|| tok.to_string())?);
    }
    if out.is_empty() {
        return Err(String::new());
    }
    Ok(out)
}

enum TypeError {
    Unsupported,
    Unknown,
}

/// Every NRRD spelling of the supported types (teem's equivalents list).
fn parse_type(value: &str) -> Result<SampleType, TypeError> {
    let norm = value
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
        .to_ascii_lowercase();
    Ok(match norm.as_str() {
        "signed char" | "int8" | "int8_t" => SampleType::I8,
        "uchar" | "unsigned char" | "uint8" | "uint8_t" => SampleType::U8,
        "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => {
            SampleType::I16
        }
        "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => {
            SampleType::U16
        }
        "int" | "signed int" | "int32" | "int32_t" => SampleType::I32,
        "uint" | "unsigned int" | "uint32" | "uint32_t" => SampleType::U32,
        "float" => SampleType::F32,
        "double" => SampleType::F64,
        "longlong"
        | "long long"
        | "long long int"
        | "signed long long"
        | "signed long long int"
        | "int64"
        | "int64_t"
        | "ulonglong"
        | "unsigned long long"
        | "unsigned long long int"
        | "uint64"
        | "uint64_t"
        | "block" => {
            return Err(TypeError::Unsupported);
        }
        _ => return Err(TypeError::Unknown),
    })
}

fn parse_encoding(value: &str) -> Option<Encoding> {
    match value.to_ascii_lowercase().as_str() {
        "raw" => Some(Encoding::Raw),
        "gzip" | "gz" => Some(Encoding::Gzip),
        "ascii" | "txt" | "text" => Some(Encoding::Ascii),
        _ => None,
    }
}

/// Parses `(1,0,0) (0,1,0) none ...`: one vector or `none` per axis, spaces
/// allowed inside the parentheses.
fn parse_directions(value: &str) -> Result<Vec<Option<Vec<f64>>>, String> {
    let mut out = Vec::new();
    let mut rest = value.trim_start();
    while !rest.is_empty() {
        if out.len() == MAX_DIMENSION {
            return Err(format!("more than {MAX_DIMENSION} vectors"));
        }
        if let Some(r) = rest.strip_prefix("none") {
            out.push(None);
            rest = r.trim_start();
            continue;
        }
        let Some(r) = rest.strip_prefix('(') else {
            return Err(format!("expected '(' or 'none' at '{}'", excerpt(rest)));
        };
        let Some((inner, after)) = r.split_once(')') else {
            return Err(format!("missing ')' in '{}'", excerpt(rest)));
        };
        let mut v = Vec::new();
        for comp in inner.split(',') {
            if v.len() == MAX_DIMENSION {
                return Err(format!("vector with more than {MAX_DIMENSION} components"));
            }
            let c = comp
                .trim()
                .parse::<f64>()
                .map_err(|_| format!("'{}' is not a number", excerpt(comp.trim())))?;
            v.push(c);
        }
        out.push(Some(v));
        rest = after.trim_start();
    }
    if out.is_empty() {
        return Err("no vectors".into());
    }
    Ok(out)
}

// ---------------------------------------------------------------------------
// Layout: the validated reading plan

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum ByteSkip {
    Bytes(u64),
    /// `byte skip: -1`: the data is the last bytes of the file.
    DataAtEnd,
}

#[derive(Debug)]
struct Layout {
    dims: [usize; 3],
    spacing: [f64; 3],
    ty: SampleType,
    endian: Endian,
    encoding: Encoding,
    line_skip: u64,
    byte_skip: ByteSkip,
    /// The detached data's files in order (none: attached data); more than
    /// one split the data in equal slabs along the slowest axes.
    data_files: Vec<PathBuf>,
}

impl Layout {
    fn from_fields(path: &Path, f: &Fields) -> Result<Layout, VolumeError> {
        let missing =
            |name: &str| VolumeError::format(path, format!("header has no '{name}' field"));
        let ty = f.sample_type.ok_or_else(|| missing("type"))?;
        let dimension = f.dimension.ok_or_else(|| missing("dimension"))?;
        let sizes = f.sizes.as_deref().ok_or_else(|| missing("sizes"))?;
        let encoding = f.encoding.ok_or_else(|| missing("encoding"))?;
        if sizes.len() != dimension {
            return Err(VolumeError::format(
                path,
                format!(
                    "sizes has {} values but dimension is {dimension}",
                    sizes.len()
                ),
            ));
        }
        let axes = grid_axes(sizes).ok_or_else(|| {
            VolumeError::unsupported(
                path,
                format!(
                    "{dimension}-D data (sizes {}) is not supported: only scalar volumes, with at most three axes longer than 1",
                    join(sizes)
                ),
            )
        })?;
        // An axis of colour or vector components (`kinds: RGB-color domain
        // domain`) would be read as a spatial one: three scalar slices.
        if let Some(kinds) = &f.kinds {
            let spatial = |k: &str| {
                matches!(
                    k.to_ascii_lowercase().as_str(),
                    "domain" | "space" | "time" | "???" | "none"
                )
            };
            if let Some((a, k)) = kinds
                .iter()
                .enumerate()
                .find(|&(a, k)| sizes.get(a).is_some_and(|&n| n > 1) && !spatial(k))
            {
                return Err(VolumeError::unsupported(
                    path,
                    format!(
                        "axis {a} is of kind '{}', not a spatial axis: only scalar volumes are supported",
                        excerpt(k)
                    ),
                ));
            }
        }
        let dims: [usize; 3] = std::array::from_fn(|a| axes.get(a).map_or(1, |&i| sizes[i]));

        // Text has no byte order; its samples are re-encoded little endian.
        let endian = if ty.size() > 1 && encoding != Encoding::Ascii {
            f.endian.ok_or_else(|| {
                VolumeError::format(
                    path,
                    format!("header has no 'endian' field, required for {ty} samples"),
                )
            })?
        } else {
            Endian::Little // irrelevant for single bytes
        };

        let spacing = spacing_from(path, f, dimension, &axes)?;

        let byte_skip = match f.byte_skip.unwrap_or(0) {
            // The end of the file (raw) or of the decompressed data (gzip).
            -1 => ByteSkip::DataAtEnd,
            // parse_line only lets -1 and non-negative values through.
            n => ByteSkip::Bytes(u64::try_from(n).unwrap_or(0)),
        };

        let data_files = match &f.data_file {
            None => Vec::new(),
            Some(files) => files.paths(path, sizes)?,
        };

        Ok(Layout {
            dims,
            spacing,
            ty,
            endian,
            encoding,
            line_skip: f.line_skip.unwrap_or(0),
            byte_skip,
            data_files,
        })
    }
}

fn join<T: std::fmt::Display>(values: &[T]) -> String {
    values
        .iter()
        .map(|v| v.to_string())
        .collect::<Vec<_>>()
        .join(" ")
}

/// The axes read as the grid's x, y and z, in order: all of them up to
/// three; beyond three, every axis longer than 1 and as many of the first
/// unit axes as make three (`sizes: 1 64 64 64` is a 64³ grid, as is `64
/// 64 64 1`). `None` with more than three axes longer than 1.
fn grid_axes(sizes: &[usize]) -> Option<Vec<usize>> {
    if sizes.len() <= 3 {
        return Some((0..sizes.len()).collect());
    }
    let long = sizes.iter().filter(|&&n| n > 1).count();
    if long > 3 {
        return None;
    }
    let mut units = 3 - long;
    Some(
        (0..sizes.len())
            .filter(|&a| {
                sizes[a] > 1 || {
                    let keep = units > 0;
                    units = units.saturating_sub(1);
                    keep
                }
            })
            .collect(),
    )
}

/// Spacing of the grid's axes (`axes`, from [`grid_axes`]): the length of
/// each axis' space direction (the whole vector, so a rotated or sheared
/// grid keeps its true sample distance), else its `spacings` entry, else 1.
/// Orientation itself is dropped: the renderer works in grid coordinates ×
/// spacing. As teem, an axis may not have both a direction and a spacing:
/// which one the writer meant is anyone's guess.
fn spacing_from(
    path: &Path,
    f: &Fields,
    dimension: usize,
    axes: &[usize],
) -> Result<[f64; 3], VolumeError> {
    let fmt = |msg: String| VolumeError::format(path, msg);
    if let (Some(a), Some(b)) = (f.space, f.space_dimension)
        && a != b
    {
        return Err(fmt(format!(
            "space (of dimension {a}) and space dimension ({b}) disagree"
        )));
    }
    if let Some(sp) = &f.spacings
        && sp.len() != dimension
    {
        return Err(fmt(format!(
            "spacings has {} values but dimension is {dimension}",
            sp.len()
        )));
    }
    if let Some(dirs) = &f.space_directions {
        if dirs.len() != dimension {
            return Err(fmt(format!(
                "space directions has {} entries but dimension is {dimension}",
                dirs.len()
            )));
        }
        // Every vector has the space's dimension (the first vector's
        // where the header names no space).
        let want = f
            .space
            .or(f.space_dimension)
            .or_else(|| dirs.iter().flatten().next().map(Vec::len));
        if let Some((axis, v)) = dirs
            .iter()
            .enumerate()
            .find_map(|(a, d)| d.as_ref().filter(|v| Some(v.len()) != want).map(|v| (a, v)))
        {
            return Err(fmt(format!(
                "space direction of axis {axis} has {} components, not the space's {}",
                v.len(),
                want.unwrap_or(0)
            )));
        }
        if let Some(axis) = (0..dimension)
            .find(|&a| dirs[a].is_some() && f.spacings.as_ref().is_some_and(|sp| !sp[a].is_nan()))
        {
            return Err(fmt(format!(
                "axis {axis} has both a space direction and a spacing; give one (teem refuses this too)"
            )));
        }
    }
    let mut spacing = [1.0f64; 3];
    for (&axis, s) in axes.iter().zip(spacing.iter_mut()) {
        if let Some(dirs) = &f.space_directions {
            if let Some(v) = &dirs[axis] {
                *s = vector_length(v).ok_or_else(|| {
                    fmt(format!(
                        "space direction of axis {axis} ({}) must be finite and non-zero",
                        join(v)
                    ))
                })?;
                continue;
            }
            if f.spacings.is_none() {
                return Err(fmt(format!(
                    "space directions gives 'none' for axis {axis}, but it is a spatial axis of the volume"
                )));
            }
        }
        if let Some(sp) = &f.spacings {
            let v = sp[axis];
            // NaN is NRRD's "no spacing known"; the sign only says direction.
            if v.is_nan() {
                continue;
            }
            if !v.is_finite() || v == 0.0 {
                return Err(fmt(format!(
                    "spacing {v} of axis {axis} must be finite and non-zero"
                )));
            }
            *s = v.abs();
        }
    }
    Ok(spacing)
}

/// Length of a direction vector; exact for an axis-aligned one (a diagonal
/// matrix), so written spacings read back bit for bit.
fn vector_length(v: &[f64]) -> Option<f64> {
    if v.iter().any(|c| !c.is_finite()) {
        return None;
    }
    let mut nonzero = v.iter().filter(|c| **c != 0.0);
    let len = match (nonzero.next(), nonzero.next()) {
        (None, _) => return None,
        (Some(c), None) => c.abs(),
        _ => v.iter().map(|c| c * c).sum::<f64>().sqrt(),
    };
    (len.is_finite() && len > 0.0).then_some(len)
}

/// The `data file` field: one file, a printf pattern over a range of
/// integers (`slice%03d.raw 1 64 1`), or `LIST` with the names on the
/// header's remaining lines; the multi-file forms may end with the
/// dimension of each file's slab (default: one less than the data's).
#[derive(Debug, PartialEq)]
enum DataFiles {
    One(String),
    Pattern {
        format: String,
        first: i64,
        last: i64,
        step: i64,
        slab_dim: Option<usize>,
    },
    List {
        slab_dim: Option<usize>,
        names: Vec<String>,
    },
}

impl DataFiles {
    fn parse(value: &str) -> Result<DataFiles, String> {
        let tokens: Vec<&str> = value.split_whitespace().collect();
        let slab_dim = |t: Option<&&str>| -> Result<Option<usize>, String> {
            t.map(|t| {
                t.parse::<usize>()
                    .ok()
                    .filter(|d| (1..=MAX_DIMENSION).contains(d))
                    .ok_or_else(|| format!("'{}' is not a slab dimension", excerpt(t)))
            })
            .transpose()
        };
        if tokens.first() == Some(&"LIST") {
            if tokens.len() > 2 {
                return Err("LIST takes at most a slab dimension after it".into());
            }
            return Ok(DataFiles::List {
                slab_dim: slab_dim(tokens.get(1))?,
                names: Vec::new(),
            });
        }
        let ints: Vec<Option<i64>> = tokens.iter().skip(1).map(|t| t.parse().ok()).collect();
        let is_pattern = (4..=5).contains(&tokens.len())
            && tokens[0].contains('%')
            && ints.iter().take(3).all(Option::is_some);
        if !is_pattern {
            return Ok(DataFiles::One(value.to_string()));
        }
        let [first, last, step] = [ints[0], ints[1], ints[2]].map(|v| v.unwrap_or(0));
        if step == 0 || (step > 0 && first > last) || (step < 0 && first < last) {
            return Err(format!(
                "the range {first} to {last} in steps of {step} names no files"
            ));
        }
        // Checked here, so that expanding the pattern cannot fail.
        format_index(tokens[0], first)?;
        Ok(DataFiles::Pattern {
            format: tokens[0].to_string(),
            first,
            last,
            step,
            slab_dim: slab_dim(tokens.get(4))?,
        })
    }

    /// The files, relative to the header's directory, after checking that
    /// there are as many as the slabs the sizes make.
    fn paths(&self, path: &Path, sizes: &[usize]) -> Result<Vec<PathBuf>, VolumeError> {
        let fmt = |msg: String| VolumeError::format(path, msg);
        let (slab_dim, listed) = match self {
            DataFiles::One(name) => return Ok(vec![relative_to(path, name)]),
            DataFiles::List { slab_dim, names } => (*slab_dim, names.len() as u64),
            DataFiles::Pattern {
                first,
                last,
                step,
                slab_dim,
                ..
            } => (*slab_dim, (last.abs_diff(*first)) / step.unsigned_abs() + 1),
        };
        let dimension = sizes.len();
        let slab_dim = slab_dim.unwrap_or(dimension.saturating_sub(1).max(1));
        if slab_dim > dimension {
            return Err(fmt(format!(
                "data file slab dimension {slab_dim} is above the data's dimension {dimension}"
            )));
        }
        // The sizes were checked against the sample count: no overflow.
        let slabs: u64 = sizes[slab_dim..].iter().map(|&n| n as u64).product();
        if listed != slabs {
            return Err(fmt(format!(
                "data file names {listed} files, but sizes {} in slabs of dimension {slab_dim} make {slabs}",
                join(sizes)
            )));
        }
        Ok(match self {
            DataFiles::One(_) => unreachable!("returned above"),
            DataFiles::List { names, .. } => names.iter().map(|n| relative_to(path, n)).collect(),
            DataFiles::Pattern {
                format,
                first,
                step,
                ..
            } => (0..listed as i64)
                .map(|k| {
                    let name = format_index(format, first + k * step).unwrap_or_default();
                    relative_to(path, &name)
                })
                .collect(),
        })
    }
}

/// `format` with its one integer conversion (`%d`, `%i` or `%u`, with an
/// optional `0` flag and width, as `%03d`) replaced by `i`; `%%` is a `%`.
fn format_index(format: &str, i: i64) -> Result<String, String> {
    let bad = || {
        format!(
            "'{}' is not a file name pattern with one %d",
            excerpt(format)
        )
    };
    let mut out = String::new();
    let mut chars = format.chars().peekable();
    let mut done = false;
    while let Some(c) = chars.next() {
        if c != '%' {
            out.push(c);
            continue;
        }
        if chars.peek() == Some(&'%') {
            chars.next();
            out.push('%');
            continue;
        }
        let zero = chars.next_if_eq(&'0').is_some();
        let mut width = 0usize;
        while let Some(d) = chars.next_if(char::is_ascii_digit) {
            width = (width * 10 + d.to_digit(10).unwrap_or(0) as usize).min(64);
        }
        if done || !matches!(chars.next(), Some('d' | 'i' | 'u')) {
            return Err(bad());
        }
        done = true;
        let digits = i.unsigned_abs().to_string();
        let sign = if i < 0 { "-" } else { "" };
        let len = sign.len() + digits.len();
        let pad = width.saturating_sub(len);
        if zero {
            out.push_str(sign);
            out.extend(std::iter::repeat_n('0', pad));
        } else {
            out.extend(std::iter::repeat_n(' ', pad));
            out.push_str(sign);
        }
        out.push_str(&digits);
    }
    if done { Ok(out) } else { Err(bad()) }
}

/// A data file named in a header: relative to the header's directory.
fn relative_to(header: &Path, name: &str) -> PathBuf {
    let data = Path::new(name);
    if data.is_absolute() {
        return data.to_path_buf();
    }
    header.parent().unwrap_or(Path::new("")).join(data)
}

// ---------------------------------------------------------------------------
// Locating and decompressing the data

/// The `need` bytes of raw data in `bytes` (a mapped file) after the header
/// and skips, and how many bytes follow them. Too few is truncation; more
/// are left unread, as teem leaves them (a trailing newline is common), and
/// the caller says how many.
fn raw_region<'a>(
    path: &Path,
    bytes: &'a [u8],
    start: u64,
    layout: &Layout,
    need: u64,
    what: &str,
) -> Result<(&'a [u8], u64), VolumeError> {
    let truncated = |got: usize| VolumeError::Truncated {
        path: path.to_path_buf(),
        need,
        got: got as u64,
        what: what.to_string(),
    };
    let after_header = byte_range(bytes, start, bytes.len() as u64).unwrap_or(&[]);
    let after_lines = skip_lines_in(after_header, layout.line_skip).ok_or_else(|| {
        VolumeError::format(
            path,
            format!(
                "line skip {} passes the end of the data ({what})",
                layout.line_skip
            ),
        )
    })?;
    let len = after_lines.len() as u64;
    let data = match layout.byte_skip {
        ByteSkip::DataAtEnd => {
            let from = len
                .checked_sub(need)
                .ok_or_else(|| truncated(after_lines.len()))?;
            byte_range(after_lines, from, len).ok_or_else(|| truncated(after_lines.len()))?
        }
        ByteSkip::Bytes(skip) => {
            if skip > len {
                return Err(VolumeError::format(
                    path,
                    format!(
                        "byte skip {skip} passes the end of the data, which holds {len} bytes ({what})"
                    ),
                ));
            }
            byte_range(after_lines, skip, len).unwrap_or(&[])
        }
    };
    let got = data.len() as u64;
    if got < need {
        return Err(truncated(data.len()));
    }
    let samples = byte_range(data, 0, need).ok_or_else(|| truncated(data.len()))?;
    Ok((samples, got - need))
}

/// The samples of ascii data after the header and skips, as the little
/// endian bytes of the native type (so they decode as raw data do), and how
/// many values follow them (left unread, as teem leaves them). Values are
/// separated by whitespace or commas; an integer type takes integers in its
/// range only, as teem's `%d` reads them.
fn ascii_region(
    path: &Path,
    bytes: &[u8],
    start: u64,
    layout: &Layout,
    count: usize,
    opts: &LoadOptions,
    what: &str,
) -> Result<(Vec<u8>, u64), VolumeError> {
    let fmt = |msg: String| VolumeError::format(path, msg);
    let after_header = byte_range(bytes, start, bytes.len() as u64).unwrap_or(&[]);
    let after_lines = skip_lines_in(after_header, layout.line_skip).ok_or_else(|| {
        fmt(format!(
            "line skip {} passes the end of the data ({what})",
            layout.line_skip
        ))
    })?;
    let text = match layout.byte_skip {
        ByteSkip::DataAtEnd => {
            return Err(fmt(
                "byte skip -1 (data at the end of the file) needs the data's length, which ascii data does not have".into(),
            ));
        }
        ByteSkip::Bytes(skip) => byte_range(after_lines, skip, after_lines.len() as u64)
            .ok_or_else(|| {
                fmt(format!(
                    "byte skip {skip} passes the end of the data, which holds {} bytes ({what})",
                    after_lines.len()
                ))
            })?,
    };
    let ty = layout.ty;
    let need = data_byte_len(path, count, ty)?;
    // The bytes and the f32 samples are alive together while decoding.
    limits::check_bytes(
        path,
        need.saturating_add((count as u64).saturating_mul(4)),
        opts.memory_limit,
        &format!("reading {what}"),
    )?;
    let mut out = zeroed_buffer(path, need as usize)?;
    let mut values = text
        .split(|b| b.is_ascii_whitespace() || *b == b',')
        .filter(|t| !t.is_empty());
    for (i, slot) in out.chunks_exact_mut(ty.size()).enumerate() {
        let tok = values.next().ok_or_else(|| {
            fmt(format!(
                "the ascii data holds {i} values but the sizes need {count} ({what})"
            ))
        })?;
        let bad = || {
            let t = String::from_utf8_lossy(tok);
            fmt(format!(
                "ascii value {i} ('{}') is not {}",
                excerpt(&t),
                if !ty.is_float() {
                    format!("an integer in the range of {ty}")
                } else {
                    "a number".to_string()
                }
            ))
        };
        let t = std::str::from_utf8(tok).map_err(|_| bad())?;
        macro_rules! parse {
            ($t:ty) => {
                slot.copy_from_slice(&t.parse::<$t>().map_err(|_| bad())?.to_le_bytes())
            };
        }
        match ty {
            SampleType::I8 => parse!(i8),
            SampleType::U8 => parse!(u8),
            SampleType::I16 => parse!(i16),
            SampleType::U16 => parse!(u16),
            SampleType::I32 => parse!(i32),
            SampleType::U32 => parse!(u32),
            // Rounded once, from the decimal text.
            SampleType::F32 => parse!(f32),
            SampleType::F64 => {
                slot.copy_from_slice(&t.parse::<f64>().map_err(|_| bad())?.to_le_bytes())
            }
        }
    }
    Ok((out, values.count() as u64))
}

/// `bytes` after its first `lines` lines, or `None` when it has fewer.
fn skip_lines_in(bytes: &[u8], lines: u64) -> Option<&[u8]> {
    let mut rest = bytes;
    for _ in 0..lines {
        let nl = rest.iter().position(|&b| b == b'\n')?;
        rest = rest.get(nl + 1..)?;
    }
    Some(rest)
}

/// Discards `lines` lines from `src`; returns the bytes discarded, or `None`
/// when the stream ends first. Never buffers a whole line.
fn skip_lines_from<R: BufRead>(src: &mut R, lines: u64) -> io::Result<Option<u64>> {
    let mut consumed = 0u64;
    for _ in 0..lines {
        loop {
            let buf = src.fill_buf()?;
            if buf.is_empty() {
                return Ok(None);
            }
            match buf.iter().position(|&b| b == b'\n') {
                Some(nl) => {
                    src.consume(nl + 1);
                    consumed += nl as u64 + 1;
                    break;
                }
                None => {
                    let n = buf.len();
                    src.consume(n);
                    consumed += n as u64;
                }
            }
        }
    }
    Ok(Some(consumed))
}

/// Decompresses the `need` bytes of sample data from `src` (positioned at
/// the start of the data file's payload) into a buffer allocated once: after
/// the byte skip, or the stream's last `need` bytes for `byte skip: -1` (as
/// teem does for gzip). Fewer bytes are truncation; what follows the samples
/// is left, as teem leaves it, and counted for a warning.
#[allow(clippy::too_many_arguments)]
fn gzip_region<R: BufRead>(
    path: &Path,
    mut src: R,
    compressed: u64,
    layout: &Layout,
    need: u64,
    count: usize,
    opts: &LoadOptions,
    what: &str,
) -> Result<(Vec<u8>, Extra), VolumeError> {
    let skipped_lines = skip_lines_from(&mut src, layout.line_skip)
        .map_err(|e| VolumeError::io(path, e))?
        .ok_or_else(|| {
            VolumeError::format(
                path,
                format!(
                    "line skip {} passes the end of the data ({what})",
                    layout.line_skip
                ),
            )
        })?;
    let compressed = compressed.saturating_sub(skipped_lines);
    let byte_skip = match layout.byte_skip {
        ByteSkip::Bytes(n) => n,
        ByteSkip::DataAtEnd => 0,
    };

    // Before allocating: can this much gzip data even hold the samples?
    let total = byte_skip.saturating_add(need);
    let most = max_gunzipped_len(compressed);
    if total > most {
        return Err(VolumeError::Truncated {
            path: path.to_path_buf(),
            need: total,
            got: most,
            what: format!(
                "{what}; {compressed} bytes of gzip data decompress to at most {most} bytes"
            ),
        });
    }
    // The compressed bytes and the f32 samples are alive together while decoding.
    limits::check_bytes(
        path,
        need.saturating_add((count as u64).saturating_mul(4)),
        opts.memory_limit,
        &format!("decompressing {what}"),
    )?;
    let need_len = usize::try_from(need).map_err(|_| VolumeError::TooLarge {
        path: path.to_path_buf(),
        msg: format!("{need} bytes of data do not fit in memory"),
    })?;

    let mut dec = GzMembers::new(src);
    let skipped = skip_bytes(&mut dec, byte_skip).map_err(|e| gzip_error(path, e))?;
    if skipped < byte_skip {
        return Err(VolumeError::format(
            path,
            format!(
                "byte skip {byte_skip} passes the end of the decompressed data, which holds {skipped} bytes ({what})"
            ),
        ));
    }
    let mut buf = zeroed_buffer(path, need_len)?;
    let got = read_full(&mut dec, &mut buf).map_err(|e| gzip_error(path, e))?;
    if got < need_len {
        return Err(VolumeError::Truncated {
            path: path.to_path_buf(),
            need,
            got: got as u64,
            what: what.to_string(),
        });
    }
    // Reading on to the stream's end checks its CRC; for `byte skip: -1`
    // the samples are the last `need` bytes seen, kept in `buf` as a ring.
    let mut more = 0u64;
    let mut ring = 0usize;
    let mut chunk = vec![0u8; 64 << 10];
    loop {
        let n = match dec.read(&mut chunk) {
            Ok(0) => break,
            Ok(n) => n.min(chunk.len()),
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => {
                return Err(VolumeError::format(
                    path,
                    "gzip data ends before its trailer: the file is truncated",
                ));
            }
            Err(e) => return Err(gzip_error(path, e)),
        };
        more += n as u64;
        if layout.byte_skip == ByteSkip::DataAtEnd {
            ring = ring_write(&mut buf, ring, &chunk[..n]);
        } else if more >= DRAIN_LIMIT {
            break;
        }
    }
    if layout.byte_skip == ByteSkip::DataAtEnd {
        buf.rotate_left(ring);
        more = 0;
    }
    Ok((
        buf,
        Extra {
            data: more,
            after_gzip: dec.trailing,
        },
    ))
}

/// Decompressed bytes after the samples counted at most, so that a gzip
/// bomb behind a small volume costs a bounded time: the warning then says
/// "at least".
const DRAIN_LIMIT: u64 = 256 << 20;

/// Writes `data` into the ring `buf` at `at`; returns the next position.
/// `buf` then holds the last `buf.len()` bytes ever written, oldest at the
/// returned position.
fn ring_write(buf: &mut [u8], at: usize, data: &[u8]) -> usize {
    let len = buf.len();
    if len == 0 {
        return 0;
    }
    if data.len() >= len {
        buf.copy_from_slice(&data[data.len() - len..]);
        return 0;
    }
    let first = data.len().min(len - at);
    buf[at..at + first].copy_from_slice(&data[..first]);
    let rest = data.len() - first;
    buf[..rest].copy_from_slice(&data[first..]);
    (at + data.len()) % len
}

/// A gzip stream of one or more members, read as one, that stops — as teem's
/// reader, which never looks past the samples, would not fail — at bytes
/// after a whole member that do not start another (gzip's magic `1f 8b`),
/// counting them in `trailing`. A member that is corrupt or cut short is an
/// error as ever.
struct GzMembers<R: BufRead> {
    dec: Option<flate2::bufread::GzDecoder<R>>,
    trailing: u64,
}

impl<R: BufRead> GzMembers<R> {
    fn new(src: R) -> GzMembers<R> {
        GzMembers {
            dec: Some(flate2::bufread::GzDecoder::new(src)),
            trailing: 0,
        }
    }
}

impl<R: BufRead> Read for GzMembers<R> {
    fn read(&mut self, out: &mut [u8]) -> io::Result<usize> {
        loop {
            let Some(dec) = &mut self.dec else {
                return Ok(0);
            };
            let n = dec.read(out)?;
            if n > 0 || out.is_empty() {
                return Ok(n);
            }
            // The member ended, its CRC checked: another, or the end.
            let Some(mut src) = self.dec.take().map(|d| d.into_inner()) else {
                return Ok(0);
            };
            let head = src.fill_buf()?;
            if head.is_empty() {
                return Ok(0);
            }
            if head[0] == 0x1f && head.get(1).is_none_or(|&b| b == 0x8b) {
                self.dec = Some(flate2::bufread::GzDecoder::new(src));
                continue;
            }
            let mut rest = 0u64;
            loop {
                let n = src.fill_buf()?.len();
                if n == 0 {
                    break;
                }
                src.consume(n);
                rest += n as u64;
            }
            self.trailing = rest;
            return Ok(0);
        }
    }
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
    let ty = vol.native_type();
    let mut line = String::new();
    for row in vol.samples().chunks(vol.dims()[0].max(1)) {
        line.clear();
        for (i, &v) in row.iter().enumerate() {
            if i > 0 {
                line.push(' ');
            }
            // Integers as the raw encoding would store them.
            let text = match ty {
                SampleType::I8 => (v.round() as i8).to_string(),
                SampleType::U8 => (v.round() as u8).to_string(),
                SampleType::I16 => (v.round() as i16).to_string(),
                SampleType::U16 => (v.round() as u16).to_string(),
                SampleType::I32 => (v.round() as i32).to_string(),
                SampleType::U32 => (v.round() as u32).to_string(),
                SampleType::F32 => v.to_string(),
                SampleType::F64 => f64::from(v).to_string(),
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
    use super::*;
    use std::io::Cursor;

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
        // Rotated axes: the spacing is each vector's length.
        let l = layout(&format!(
            "{base}dimension: 3\nsizes: 2 2 2\nspace directions: (3,4,0) (0,0,2) (-4,3,0)\n\n"
        ))
        .unwrap();
        assert_eq!(l.spacing, [5.0, 2.0, 5.0]);
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
