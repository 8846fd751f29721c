//! The header: its lines read and checked as teem reads them, into the
//! fields this reader interprets.

use std::io::{BufRead, Read};
use std::path::Path;

use super::super::{Endian, SampleType, VolumeError, limits};
use super::layout::DataFiles;
use super::{Encoding, MAX_DIMENSION, MAX_HEADER_BYTES, MAX_VERSION};

/// The fields this reader interprets, as parsed from the header lines.
#[derive(Debug, Default)]
pub(super) struct Fields {
    pub(super) sample_type: Option<SampleType>,
    pub(super) dimension: Option<usize>,
    pub(super) sizes: Option<Vec<usize>>,
    pub(super) endian: Option<Endian>,
    pub(super) encoding: Option<Encoding>,
    pub(super) spacings: Option<Vec<f64>>,
    /// One entry per axis; `None` for a `none` (non-spatial) axis.
    pub(super) space_directions: Option<Vec<Option<Vec<f64>>>>,
    pub(super) byte_skip: Option<i64>,
    pub(super) line_skip: Option<u64>,
    pub(super) data_file: Option<DataFiles>,
    /// One word per axis, as written (`domain`, `RGB-color`, ...).
    pub(super) kinds: Option<Vec<String>>,
    /// `space dimension`, and the dimension of a named `space`: the
    /// components a space direction must have.
    pub(super) space_dimension: Option<usize>,
    pub(super) space: Option<usize>,
    /// The named `space` is left-handed (`LAS`, `3D-left-handed`): its
    /// directions' determinant has the opposite sign for the same shape.
    pub(super) space_left_handed: bool,
}

/// Reads the header up to the blank line that ends it (or the end of the file,
/// as a detached header may). Returns the fields and the header's length in
/// bytes, i.e. where attached data starts.
pub(super) fn parse_header<R: BufRead>(
    path: &Path,
    reader: &mut R,
) -> Result<(Fields, u64), VolumeError> {
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
pub(super) fn excerpt(text: &str) -> String {
    let mut s: String = text.chars().take(60).collect();
    if s.len() < text.len() {
        s.push_str("...");
    }
    s
}

pub(super) fn parse_line(
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
            let name = value.trim().to_ascii_lowercase();
            fields.space_left_handed = name.starts_with("left-anterior-superior")
                || name.starts_with("las")
                || name.starts_with("3d-left-handed");
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
pub(super) fn space_dimension(name: &str) -> Option<usize> {
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

pub(super) enum TypeError {
    Unsupported,
    Unknown,
}

/// Every NRRD spelling of the supported types (teem's equivalents list).
pub(super) fn parse_type(value: &str) -> Result<SampleType, TypeError> {
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
pub(super) fn parse_directions(value: &str) -> Result<Vec<Option<Vec<f64>>>, String> {
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
