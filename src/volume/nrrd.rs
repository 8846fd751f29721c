//! NRRD volumes (teem's "nearly raw raster data"): attached `.nrrd` and
//! detached `.nhdr` headers, raw or gzip encoded, plus a writer.
//!
//! Only what a scalar 3-D grid needs is interpreted: type, dimension, sizes,
//! endian, encoding, spacing (from `space directions` or `spacings`), skips and
//! the data file, and `kinds` only to refuse an axis of components (colour,
//! vector) that would otherwise be read as a spatial one. Orientation, origin
//! and key/value pairs are ignored: the renderer works in grid coordinates ×
//! spacing (see SPEC.md).
//!
//! Every size a header claims is checked before it is used to allocate, seek or
//! slice, so a hostile header ends in an error naming the file, never a panic
//! or an allocation the machine cannot make.

use std::fs::File;
use std::io::{self, BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};

use flate2::Compression;
use flate2::read::MultiGzDecoder;
use flate2::write::GzEncoder;

use super::raw::{
    byte_range, data_byte_len, finish_volume, gzip_error, map_file, max_gunzipped_len, read_full,
    skip_bytes, zeroed_buffer,
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

/// How [`write`] encodes the samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Encoding {
    Raw,
    Gzip,
}

impl Encoding {
    fn name(self) -> &'static str {
        match self {
            Encoding::Raw => "raw",
            Encoding::Gzip => "gzip",
        }
    }
}

/// Reads a `.nrrd` (attached data) or `.nhdr` (detached data) file.
pub fn read(path: &Path, opts: &LoadOptions) -> Result<Volume, VolumeError> {
    let file = File::open(path).map_err(|e| VolumeError::io(path, e))?;
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

    match &layout.data_file {
        None => match layout.encoding {
            Encoding::Raw => {
                let map = map_file(path, reader.get_ref())?;
                let data = raw_region(path, &map, header_len, &layout, need, &what)?;
                decode(data)
            }
            Encoding::Gzip => {
                let file_len = file_len(path, reader.get_ref())?;
                let compressed = file_len.saturating_sub(header_len);
                let data =
                    gzip_region(path, reader, compressed, &layout, need, count, opts, &what)?;
                decode(&data)
            }
        },
        Some(data_path) => {
            what.push_str(&format!(" in data file {}", data_path.display()));
            let data_file =
                File::open(data_path).map_err(|e| data_file_error(path, data_path, e))?;
            match layout.encoding {
                Encoding::Raw => {
                    let map = map_file(path, &data_file)?;
                    let data = raw_region(path, &map, 0, &layout, need, &what)?;
                    decode(data)
                }
                Encoding::Gzip => {
                    let compressed = file_len(path, &data_file)?;
                    let src = BufReader::new(data_file);
                    let data =
                        gzip_region(path, src, compressed, &layout, need, count, opts, &what)?;
                    decode(&data)
                }
            }
        }
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
    data_file: Option<String>,
    /// One word per axis, as written (`domain`, `RGB-color`, ...).
    kinds: Option<Vec<String>>,
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
        if !text.starts_with(b"#") && !is_text(text) {
            return Err(VolumeError::format(
                path,
                format!(
                    "header line {line_no} is not text (binary data before the blank line that ends the header?)"
                ),
            ));
        }
        let text = String::from_utf8_lossy(text);
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

/// UTF-8 without control characters (tabs allowed). Comments are exempt, since
/// old files carry Latin-1 there and nothing reads them.
fn is_text(line: &[u8]) -> bool {
    std::str::from_utf8(line).is_ok_and(|s| !s.chars().any(|c| c.is_control() && c != '\t'))
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

    match name {
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
        "dimension" => {
            let d = value
                .parse::<usize>()
                .ok()
                .filter(|d| (1..=MAX_DIMENSION).contains(d))
                .ok_or_else(|| {
                    bad(format!(
                        "'{}' is not a dimension from 1 to {MAX_DIMENSION}",
                        excerpt(value)
                    ))
                })?;
            set_once(&mut fields.dimension, d, &bad)
        }
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
                        "encoding '{}' is not supported (only raw and gzip)",
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
            // The file names of the LIST form follow as the header's remaining
            // lines, so this has to stop the parse right here.
            if value.split_whitespace().next() == Some("LIST") {
                return Err(VolumeError::unsupported(
                    path,
                    "multi-file data ('data file: LIST') is not supported; use a single data file",
                ));
            }
            set_once(&mut fields.data_file, value.to_string(), &bad)
        }
        "kinds" => {
            let kinds = value.split_whitespace().map(str::to_string).collect();
            set_once(&mut fields.kinds, kinds, &bad)
        }
        // Everything else (space, space origin, centers, content, ...)
        // does not change how the samples are read.
        _ => Ok(()),
    }
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
    data_file: Option<PathBuf>,
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
        if sizes.iter().skip(3).any(|&s| s != 1) {
            return Err(VolumeError::unsupported(
                path,
                format!(
                    "{dimension}-D data (sizes {}) is not supported: only scalar volumes, whose axes beyond the third have size 1",
                    join(sizes)
                ),
            ));
        }
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
        let dims: [usize; 3] = std::array::from_fn(|a| sizes.get(a).copied().unwrap_or(1));

        let endian = if ty.size() > 1 {
            f.endian.ok_or_else(|| {
                VolumeError::format(
                    path,
                    format!("header has no 'endian' field, required for {ty} samples"),
                )
            })?
        } else {
            Endian::Little // irrelevant for single bytes
        };

        let spacing = spacing_from(path, f, dimension)?;

        let byte_skip = match f.byte_skip.unwrap_or(0) {
            -1 if encoding == Encoding::Raw => ByteSkip::DataAtEnd,
            -1 => {
                return Err(VolumeError::format(
                    path,
                    "byte skip -1 (data at the end of the file) is only allowed with raw encoding",
                ));
            }
            // parse_line only lets -1 and non-negative values through.
            n => ByteSkip::Bytes(u64::try_from(n).unwrap_or(0)),
        };

        let data_file = match &f.data_file {
            None => None,
            Some(name) => Some(resolve_data_file(path, name)?),
        };

        Ok(Layout {
            dims,
            spacing,
            ty,
            endian,
            encoding,
            line_skip: f.line_skip.unwrap_or(0),
            byte_skip,
            data_file,
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

/// Spacing of the three grid axes: the length of each axis' space direction
/// (the whole vector, so a rotated or sheared grid keeps its true sample
/// distance), else `spacings`, else 1. Orientation itself is dropped: the
/// renderer works in grid coordinates × spacing.
fn spacing_from(path: &Path, f: &Fields, dimension: usize) -> Result<[f64; 3], VolumeError> {
    let mut spacing = [1.0f64; 3];
    if let Some(dirs) = &f.space_directions {
        if dirs.len() != dimension {
            return Err(VolumeError::format(
                path,
                format!(
                    "space directions has {} entries but dimension is {dimension}",
                    dirs.len()
                ),
            ));
        }
        for (axis, (dir, s)) in dirs.iter().zip(spacing.iter_mut()).enumerate() {
            let Some(v) = dir else {
                return Err(VolumeError::format(
                    path,
                    format!(
                        "space directions gives 'none' for axis {axis}, but it is a spatial axis of the volume"
                    ),
                ));
            };
            *s = vector_length(v).ok_or_else(|| {
                VolumeError::format(
                    path,
                    format!(
                        "space direction of axis {axis} ({}) must be finite and non-zero",
                        join(v)
                    ),
                )
            })?;
        }
    } else if let Some(sp) = &f.spacings {
        if sp.len() != dimension {
            return Err(VolumeError::format(
                path,
                format!(
                    "spacings has {} values but dimension is {dimension}",
                    sp.len()
                ),
            ));
        }
        for (axis, (&v, s)) in sp.iter().zip(spacing.iter_mut()).enumerate() {
            // NaN is NRRD's "no spacing known"; the sign only says direction.
            if v.is_nan() {
                continue;
            }
            if !v.is_finite() || v == 0.0 {
                return Err(VolumeError::format(
                    path,
                    format!("spacing {v} of axis {axis} must be finite and non-zero"),
                ));
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

/// The data file of a detached header, relative to the header's directory.
/// The multi-file forms (`LIST`, or a printf pattern with a range) are refused.
fn resolve_data_file(path: &Path, value: &str) -> Result<PathBuf, VolumeError> {
    let tokens: Vec<&str> = value.split_whitespace().collect();
    let is_list = tokens.first() == Some(&"LIST");
    let is_pattern = tokens.len() >= 4
        && tokens.first().is_some_and(|t| t.contains('%'))
        && tokens
            .iter()
            .skip(1)
            .take(3)
            .all(|t| t.parse::<i64>().is_ok());
    if is_list || is_pattern {
        return Err(VolumeError::unsupported(
            path,
            format!(
                "multi-file data ('data file: {}') is not supported; use a single data file",
                excerpt(value)
            ),
        ));
    }
    let data = Path::new(value);
    if data.is_absolute() {
        return Ok(data.to_path_buf());
    }
    let dir = path.parent().unwrap_or(Path::new(""));
    Ok(dir.join(data))
}

// ---------------------------------------------------------------------------
// Locating and decompressing the data

/// The exact `need` bytes of raw data in `bytes` (a mapped file) after the
/// header and skips. Anything but an exact fit is an error: too short is
/// truncation, too long means the sizes do not describe this data.
fn raw_region<'a>(
    path: &Path,
    bytes: &'a [u8],
    start: u64,
    layout: &Layout,
    need: u64,
    what: &str,
) -> Result<&'a [u8], VolumeError> {
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
    if got > need {
        return Err(size_mismatch(path, layout, need, &format!("{got} bytes")));
    }
    Ok(data)
}

/// The error for data longer than the header's sizes say.
fn size_mismatch(path: &Path, layout: &Layout, need: u64, got: &str) -> VolumeError {
    let [nx, ny, nz] = layout.dims;
    VolumeError::format(
        path,
        format!(
            "sizes {nx} {ny} {nz} of {} need {need} bytes but the data holds {got}: the sizes do not match the data length",
            layout.ty
        ),
    )
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

/// Decompresses exactly the `need` bytes of sample data from `src` (positioned
/// at the start of the data file's payload) into a buffer allocated once.
/// Fewer bytes are truncation; more are a size mismatch.
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
) -> Result<Vec<u8>, VolumeError> {
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
        ByteSkip::DataAtEnd => 0, // rejected for gzip in Layout::from_fields
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

    let mut dec = MultiGzDecoder::new(src);
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
    // One more byte tells "exactly the data" from "more data than the sizes say",
    // and makes the decoder check the stream's CRC.
    let mut probe = [0u8; 1];
    loop {
        match dec.read(&mut probe) {
            Ok(0) => break,
            Ok(_) => {
                return Err(size_mismatch(path, layout, need, "more once decompressed"));
            }
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => {
                return Err(VolumeError::format(
                    path,
                    "gzip data ends before its trailer: the file is truncated",
                ));
            }
            Err(e) => return Err(gzip_error(path, e)),
        }
    }
    Ok(buf)
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
    if ty.size() > 1 {
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

/// Streams the samples in the native type, little endian, in chunks so no
/// second copy of the volume is built.
fn write_samples<W: Write>(out: &mut W, vol: &Volume) -> io::Result<()> {
    let ty = vol.native_type();
    let mut buf: Vec<u8> = Vec::with_capacity(64 * 1024);
    for chunk in vol.samples().chunks(8192) {
        buf.clear();
        for &v in chunk {
            encode_sample(ty, v, &mut buf);
        }
        out.write_all(&buf)?;
    }
    Ok(())
}

/// One sample in the native type. Integer volumes hold integral values, so the
/// rounding only guards against samples edited after loading; `as` saturates
/// out-of-range values (and maps NaN to 0), which is the clamp we want.
fn encode_sample(ty: SampleType, v: f32, out: &mut Vec<u8>) {
    match ty {
        SampleType::I8 => out.extend_from_slice(&(v.round() as i8).to_le_bytes()),
        SampleType::U8 => out.extend_from_slice(&(v.round() as u8).to_le_bytes()),
        SampleType::I16 => out.extend_from_slice(&(v.round() as i16).to_le_bytes()),
        SampleType::U16 => out.extend_from_slice(&(v.round() as u16).to_le_bytes()),
        SampleType::I32 => out.extend_from_slice(&(v.round() as i32).to_le_bytes()),
        SampleType::U32 => out.extend_from_slice(&(v.round() as u32).to_le_bytes()),
        SampleType::F32 => out.extend_from_slice(&v.to_le_bytes()),
        SampleType::F64 => out.extend_from_slice(&f64::from(v).to_le_bytes()),
    }
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
        assert_eq!(f.data_file.as_deref(), Some("x.raw"));
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
    fn byte_skip_minus_one_only_raw() {
        let base = "NRRD0004\ntype: uint8\ndimension: 1\nsizes: 4\nbyte skip: -1\n";
        assert_eq!(
            layout(&format!("{base}encoding: raw\n\n"))
                .unwrap()
                .byte_skip,
            ByteSkip::DataAtEnd
        );
        assert!(layout(&format!("{base}encoding: gzip\n\n")).is_err());
    }

    #[test]
    fn unsupported_encodings_and_data_files() {
        for enc in ["bzip2", "ascii", "hex", "zrl", "lzma"] {
            let e = header(&format!("NRRD0004\nencoding: {enc}\n\n")).unwrap_err();
            assert!(
                matches!(e, VolumeError::Unsupported { .. }) && e.to_string().contains(enc),
                "{e}"
            );
        }
        let p = Path::new("/d/h.nhdr");
        assert!(matches!(
            resolve_data_file(p, "LIST"),
            Err(VolumeError::Unsupported { .. })
        ));
        assert!(matches!(
            resolve_data_file(p, "slice%03d.raw 1 10 1"),
            Err(VolumeError::Unsupported { .. })
        ));
        assert_eq!(
            resolve_data_file(p, "a b.raw").unwrap(),
            Path::new("/d/a b.raw")
        );
        assert_eq!(
            resolve_data_file(p, "/x/y.raw").unwrap(),
            Path::new("/x/y.raw")
        );
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

    #[test]
    fn encode_clamps_and_rounds() {
        let mut out = Vec::new();
        encode_sample(SampleType::U8, 300.0, &mut out);
        encode_sample(SampleType::U8, -3.0, &mut out);
        encode_sample(SampleType::I8, 2.6, &mut out);
        encode_sample(SampleType::U16, f32::NAN, &mut out);
        assert_eq!(out, vec![255, 0, 3, 0, 0]);
    }
}
