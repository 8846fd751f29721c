//! MetaImage volumes (ITK's MetaIO format): `.mha` with the samples after
//! the header, `.mhd` naming a data file beside it, raw or zlib-compressed.
//!
//! The header is read as MetaIO reads it: `Name = Value` lines, names as
//! written (ITK 5.4 left a volume with `elementspacing = 2 2 2` at spacing
//! 1, checked with SimpleITK 2.5.7), `ElementDataFile` the
//! last field, `HeaderSize` an absolute offset in the data file (`-1`: the
//! samples end the file), and `ElementSize` the spacing where
//! `ElementSpacing` is absent. Only what a scalar grid needs is
//! interpreted; the orientation and origin fields (`TransformMatrix`,
//! `Offset`, ...) are read past, as the renderer works in grid coordinates
//! × spacing (SPEC.md). Other fields are metadata, passed over as MetaIO
//! keeps them, but one a letter or two from an interpreted name gets a
//! warning, since a misspelt `ElementSpacing` would otherwise leave the
//! volume with the wrong geometry, unsaid; the intensity function
//! (`ElementToIntensityFunctionSlope`/`Offset`), which ITK does not apply
//! either (SimpleITK read a slope of 2 and offset of 10 as the stored
//! values), gets a warning when it is not the identity.
//!
//! Not read: several channels per element, ASCII element data
//! (`BinaryData = False`), 64-bit integers, and slices spread over several
//! files (`ElementDataFile = LIST` or a file-name pattern); each is refused
//! by name. Every size is checked before it allocates, seeks or slices.

use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use flate2::Compression;
use flate2::read::ZlibDecoder;
use flate2::write::ZlibEncoder;

use super::raw::{
    byte_range, data_byte_len, finish_volume, map_file, max_gunzipped_len, read_full,
    write_samples, zeroed_buffer,
};
use super::{
    Decoded, Endian, LoadOptions, SampleType, Volume, VolumeError, checked_sample_count,
    decode_samples, limits,
};

/// A header longer than this is not a MetaImage header (binary data
/// without its `ElementDataFile` line, most likely).
const MAX_HEADER_BYTES: usize = 1 << 20;

/// Fields MetaIO reads for an image besides the ones interpreted here:
/// they are read past quietly.
const KNOWN_IGNORED: [&str; 23] = [
    "Comment",
    "AcquisitionDate",
    "ObjectSubType",
    "Name",
    "ID",
    "ParentID",
    "Color",
    "Position",
    "Origin",
    "Offset",
    "TransformMatrix",
    "Rotation",
    "Orientation",
    "CenterOfRotation",
    "DistanceUnits",
    "AnatomicalOrientation",
    "TransformType",
    "Modality",
    "ImagePosition",
    "SequenceID",
    "ElementMin",
    "ElementMax",
    "ElementNBits",
];

/// Reads a `.mha` (data after the header) or `.mhd` (data file named by
/// the header) file.
pub fn read(path: &Path, opts: &LoadOptions) -> Result<Volume, VolumeError> {
    let file = crate::input::open(path).map_err(|e| VolumeError::io(path, e))?;
    let map = map_file(path, &file)?;
    let (header, header_len) = parse_header(path, &map)?;
    let layout = Layout::from_header(path, &header)?;
    let count = checked_sample_count(path, layout.dims, opts.memory_limit)?;
    let need = data_byte_len(path, count, layout.ty)?;
    let [nx, ny, nz] = layout.dims;
    let what = format!(
        "{nx}x{ny}x{nz} samples of {}{}",
        layout.ty,
        if layout.compressed {
            ", zlib compressed"
        } else {
            ""
        }
    );
    // Errors name the header (the file the user gave), warnings the file
    // whose bytes they are about.
    let (decoded, mut warnings) = match &layout.data_file {
        None => {
            let file = DataIn {
                path,
                bytes: &map,
                start: header_len,
            };
            samples_in(path, file, &layout, need, count, opts, &what)?
        }
        Some(data_path) => {
            let data = crate::input::open(data_path).map_err(|e| {
                VolumeError::format(
                    path,
                    format!("ElementDataFile {}: {e}", data_path.display()),
                )
            })?;
            let bytes = map_file(path, &data)?;
            let what = format!("{what} in data file {}", data_path.display());
            let file = DataIn {
                path: data_path,
                bytes: &bytes,
                start: 0,
            };
            samples_in(path, file, &layout, need, count, opts, &what)?
        }
    };
    let mut vol = finish_volume(path, layout.dims, layout.spacing, layout.ty, decoded)?;
    warnings.extend(header.warnings.iter().cloned());
    warnings.extend(intensity_warning(path, &header));
    if mirrored(&header) {
        warnings.push(super::mirror_warning(path, "its TransformMatrix"));
    }
    vol.warnings = warnings;
    Ok(vol)
}

/// Whether the header's 3×3 orientation (`TransformMatrix`, or its MetaIO
/// synonyms `Rotation` and `Orientation`) has a negative determinant: in
/// index order, as snell renders, the volume is then the scan's mirror
/// image. A matrix that is not nine finite numbers says nothing.
fn mirrored(header: &Header) -> bool {
    let Some(text) = ["TransformMatrix", "Rotation", "Orientation"]
        .iter()
        .find_map(|n| header.get(n))
    else {
        return false;
    };
    let m: Vec<f64> = text
        .split_whitespace()
        .map_while(|v| v.parse::<f64>().ok().filter(|x| x.is_finite()))
        .collect();
    let [a, b, c, d, e, f, g, h, i] = m[..] else {
        return false;
    };
    super::reverses_handedness([[a, b, c], [d, e, f], [g, h, i]])
}

/// Writes `vol` as an attached MetaImage (`.mha`): the header ITK writes
/// for a volume at the origin with identity orientation, then the samples
/// in their native type, little endian, zlib-compressed when `compressed`.
/// ITK cannot read compressed data without its `CompressedDataSize`
/// (checked with SimpleITK 2.5: "Uncompress failed"), so the field is
/// written as 20 zeros, the samples compressed as they stream out, and the
/// size written over the zeros (zero-padded, which MetaIO and ITK read as
/// the number). Written atomically.
pub fn write(path: &Path, vol: &Volume, compressed: bool) -> Result<(), VolumeError> {
    crate::atomic::write_atomic(path, |out| {
        let (before, after) = header_text(vol, compressed);
        out.write_all(before.as_bytes())?;
        if !compressed {
            out.write_all(after.as_bytes())?;
            return write_samples(out, vol);
        }
        let slot = out.stream_position()?;
        out.write_all(&[b'0'; SIZE_DIGITS])?;
        out.write_all(after.as_bytes())?;
        let start = out.stream_position()?;
        let mut z = ZlibEncoder::new(&mut *out, Compression::default());
        write_samples(&mut z, vol)?;
        z.finish()?;
        let end = out.stream_position()?;
        out.seek(SeekFrom::Start(slot))?;
        write!(out, "{:0w$}", end - start, w = SIZE_DIGITS)?;
        out.seek(SeekFrom::Start(end))?;
        Ok(())
    })
    .map_err(|e| VolumeError::io(path, e))
}

/// Digits of the `CompressedDataSize` slot: any `u64`.
const SIZE_DIGITS: usize = 20;

/// The header [`write`](fn@write) writes, split where the compressed size goes (the
/// second part empty of it when not compressed).
fn header_text(vol: &Volume, compressed: bool) -> (String, String) {
    let [nx, ny, nz] = vol.dims();
    // Debug formatting of f64 is the shortest text that parses back to the
    // same bits.
    let [sx, sy, sz] = vol.spacing().map(|s| format!("{s:?}"));
    let ty = TYPE_NAMES
        .iter()
        .find(|(t, _)| *t == vol.native_type())
        .map_or("MET_DOUBLE", |(_, n)| *n);
    let start =
        "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n";
    let rest = format!(
        "TransformMatrix = 1 0 0 0 1 0 0 0 1\nOffset = 0 0 0\nCenterOfRotation = 0 0 0\nElementSpacing = {sx} {sy} {sz}\nDimSize = {nx} {ny} {nz}\nElementType = {ty}\nElementDataFile = LOCAL\n"
    );
    if compressed {
        (
            format!("{start}CompressedData = True\nCompressedDataSize = "),
            format!("\n{rest}"),
        )
    } else {
        (
            format!("{start}CompressedData = False\n{rest}"),
            String::new(),
        )
    }
}

/// The header's fields in order, and what is worth a warning.
struct Header {
    fields: Vec<(String, String)>,
    warnings: Vec<String>,
}

impl Header {
    fn get(&self, name: &str) -> Option<&str> {
        self.fields
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
    }
}

/// Reads the `Name = Value` lines up to and including `ElementDataFile`;
/// returns them and the header's length in bytes (where attached samples
/// start).
fn parse_header(path: &Path, bytes: &[u8]) -> Result<(Header, u64), VolumeError> {
    let mut header = Header {
        fields: Vec::new(),
        warnings: Vec::new(),
    };
    let mut at = 0usize;
    let mut line_no = 0usize;
    loop {
        if at >= bytes.len() {
            return Err(VolumeError::format(
                path,
                if header.fields.is_empty() {
                    "empty file: a MetaImage header starts with lines such as 'NDims = 3'".into()
                } else {
                    "the header ends without 'ElementDataFile = ...' (LOCAL, or the data file's name)".to_string()
                },
            ));
        }
        if at > MAX_HEADER_BYTES {
            return Err(VolumeError::format(
                path,
                format!(
                    "no 'ElementDataFile' line in the first {} of the file: not a MetaImage header",
                    limits::human_bytes(MAX_HEADER_BYTES as u64)
                ),
            ));
        }
        let end = bytes[at..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(bytes.len(), |k| at + k + 1);
        let raw = &bytes[at..end];
        at = end;
        line_no += 1;
        let line = raw.strip_suffix(b"\n").unwrap_or(raw);
        let line = line.strip_suffix(b"\r").unwrap_or(line);
        if line.iter().all(|b| b.is_ascii_whitespace()) {
            continue;
        }
        let bad = |msg: String| VolumeError::format(path, format!("header line {line_no}: {msg}"));
        let Some(eq) = line.iter().position(|&b| b == b'=') else {
            return Err(bad(format!(
                "expected 'Name = Value', got '{}'{}",
                excerpt(line),
                if line_no == 1 {
                    " (not a MetaImage header)"
                } else {
                    ""
                }
            )));
        };
        let name = std::str::from_utf8(&line[..eq])
            .ok()
            .map(str::trim)
            .filter(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_graphic()))
            .ok_or_else(|| bad(format!("'{}' is not a field name", excerpt(&line[..eq]))))?;
        // Values are text; a Latin-1 comment is read past as such.
        let value = String::from_utf8_lossy(&line[eq + 1..]).trim().to_string();
        // Two values for what is interpreted leave the volume ambiguous;
        // repeated metadata (two comments) is harmless.
        if INTERPRETED.contains(&name) && header.get(name).is_some() {
            return Err(bad(format!("{name} given twice")));
        }
        if !INTERPRETED.contains(&name)
            && !KNOWN_IGNORED.contains(&name)
            && let Some(meant) = near_miss(name)
        {
            header.warnings.push(format!(
                "{}: header line {line_no}: unknown field '{name}' ignored; did you mean '{meant}'? (MetaIO reads names as written)",
                path.display()
            ));
        }
        let last = name == "ElementDataFile";
        header.fields.push((name.to_string(), value));
        if last {
            return Ok((header, at as u64));
        }
    }
}

/// The fields [`Layout::from_header`] and [`intensity_warning`] interpret.
const INTERPRETED: [&str; 16] = [
    "ObjectType",
    "NDims",
    "DimSize",
    "ElementType",
    "ElementDataFile",
    "ElementSpacing",
    "ElementSize",
    "ElementNumberOfChannels",
    "BinaryData",
    "BinaryDataByteOrderMSB",
    "ElementByteOrderMSB",
    "CompressedData",
    "CompressedDataSize",
    "HeaderSize",
    "ElementToIntensityFunctionSlope",
    "ElementToIntensityFunctionOffset",
];

/// A warning for an intensity function other than the identity: MetaIO
/// keeps it beside the samples and ITK's reader does not apply it, so
/// neither does snell (an iso-value refers to the samples as stored).
fn intensity_warning(path: &Path, h: &Header) -> Option<String> {
    let slope = h.get("ElementToIntensityFunctionSlope");
    let offset = h.get("ElementToIntensityFunctionOffset");
    let identity =
        slope.is_none_or(|v| v.parse() == Ok(1.0)) && offset.is_none_or(|v| v.parse() == Ok(0.0));
    (!identity).then(|| {
        format!(
            "{}: the intensity function (slope {}, offset {}) is not applied, as ITK does not apply it: iso-values refer to the samples as stored",
            path.display(),
            slope.unwrap_or("1"),
            offset.unwrap_or("0")
        )
    })
}

/// The interpreted field an unknown name was likely meant to be: the same
/// in another case, or at most two letters apart. Other unknown names are
/// metadata (ITK writes `ITK_InputFilterName`, say), passed over quietly as
/// MetaIO keeps them.
fn near_miss(name: &str) -> Option<&'static str> {
    INTERPRETED
        .into_iter()
        .find(|f| f.eq_ignore_ascii_case(name) || edit_distance(f, name) <= 2)
}

/// Levenshtein distance between two short names (bytes).
fn edit_distance(a: &str, b: &str) -> usize {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, &ca) in a.iter().enumerate() {
        let mut diag = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let up = row[j + 1];
            row[j + 1] = (up + 1).min(row[j] + 1).min(diag + usize::from(ca != cb));
            diag = up;
        }
    }
    row[b.len()]
}

/// A line as a message quotes it: printable, at most 60 characters.
fn excerpt(line: &[u8]) -> String {
    let text: String = String::from_utf8_lossy(line)
        .chars()
        .map(|c| if c.is_control() { '?' } else { c })
        .collect();
    match text.char_indices().nth(60) {
        Some((k, _)) => format!("{}...", &text[..k]),
        None => text,
    }
}

/// What the header says about the samples.
#[derive(Debug, PartialEq)]
struct Layout {
    dims: [usize; 3],
    spacing: [f64; 3],
    ty: SampleType,
    endian: Endian,
    compressed: bool,
    /// Bytes of zlib data (`CompressedDataSize`), when given.
    compressed_size: Option<u64>,
    /// Where the samples start in the data file.
    header_size: HeaderSize,
    /// The data file; `None` for `LOCAL` (after the header).
    data_file: Option<PathBuf>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum HeaderSize {
    /// No `HeaderSize` (or 0): right after an attached header, at the
    /// start of a data file.
    Follows,
    /// `HeaderSize = N > 0`: at byte `N` of the data file (of the `.mha`
    /// itself for `LOCAL`, as MetaIO seeks it).
    At(u64),
    /// `HeaderSize = -1`: the samples are the file's last bytes.
    AtEnd,
}

impl Layout {
    fn from_header(path: &Path, h: &Header) -> Result<Layout, VolumeError> {
        let bad = |field: &str, msg: String| VolumeError::format(path, format!("{field}: {msg}"));
        let unsupported =
            |field: &str, msg: String| VolumeError::unsupported(path, format!("{field}: {msg}"));
        let required = |field: &str| {
            h.get(field)
                .ok_or_else(|| VolumeError::format(path, format!("the header has no {field}")))
        };
        if let Some(kind) = h.get("ObjectType")
            && kind != "Image"
        {
            return Err(unsupported(
                "ObjectType",
                format!("'{kind}' is not an image (ObjectType = Image)"),
            ));
        }
        let ndims: usize = required("NDims")?
            .parse()
            .ok()
            .filter(|n| (1..=16).contains(n))
            .ok_or_else(|| bad("NDims", "expected a whole number from 1 to 16".into()))?;
        let sizes = numbers::<usize>(required("DimSize")?, ndims)
            .filter(|s| s.iter().all(|&n| n > 0))
            .ok_or_else(|| {
                bad(
                    "DimSize",
                    format!("expected {ndims} whole numbers > 0 (NDims = {ndims})"),
                )
            })?;
        // Axes past the third must be of size 1: a 4-D series is not one
        // volume.
        if let Some(n) = sizes.iter().skip(3).find(|&&n| n != 1) {
            return Err(unsupported(
                "DimSize",
                format!("{ndims} axes with {n} samples past the third: only a 3-D grid renders"),
            ));
        }
        let mut dims = [1usize; 3];
        for (d, &n) in dims.iter_mut().zip(&sizes) {
            *d = n;
        }
        let channels: u64 = match h.get("ElementNumberOfChannels") {
            None => 1,
            Some(v) => v.parse().map_err(|_| {
                bad(
                    "ElementNumberOfChannels",
                    format!("expected a whole number, got '{v}'"),
                )
            })?,
        };
        if channels != 1 {
            return Err(unsupported(
                "ElementNumberOfChannels",
                format!("{channels} channels per element: only scalar volumes render"),
            ));
        }
        let ty = element_type(required("ElementType")?)
            .map_err(|msg| unsupported("ElementType", msg))?;
        let spacing_field = ["ElementSpacing", "ElementSize"]
            .into_iter()
            .find(|f| h.get(f).is_some());
        let mut spacing = [1.0; 3];
        if let Some(field) = spacing_field {
            let values = numbers::<f64>(h.get(field).unwrap_or_default(), ndims)
                .filter(|v| v.iter().all(|s| s.is_finite() && *s > 0.0))
                .ok_or_else(|| {
                    bad(
                        field,
                        format!("expected {ndims} finite numbers > 0 (NDims = {ndims})"),
                    )
                })?;
            for (s, &v) in spacing.iter_mut().zip(&values) {
                *s = v;
            }
        }
        let flag = |field: &str, default: bool| -> Result<bool, VolumeError> {
            match h.get(field) {
                None => Ok(default),
                Some(v) => boolean(v)
                    .ok_or_else(|| bad(field, format!("expected True or False, got '{v}'"))),
            }
        };
        if !flag("BinaryData", true)? {
            return Err(unsupported(
                "BinaryData",
                "False (element data as text) is not read; write the volume with BinaryData = True"
                    .into(),
            ));
        }
        let msb = match h.get("BinaryDataByteOrderMSB") {
            Some(_) => flag("BinaryDataByteOrderMSB", false)?,
            None => flag("ElementByteOrderMSB", false)?,
        };
        let compressed = flag("CompressedData", false)?;
        let compressed_size = match h.get("CompressedDataSize") {
            None => None,
            Some(v) => {
                let n: u64 = v.parse().map_err(|_| {
                    bad(
                        "CompressedDataSize",
                        format!("expected a whole number of bytes, got '{v}'"),
                    )
                })?;
                // MetaIO reads 0 as "not given".
                (n > 0).then_some(n)
            }
        };
        let header_size = match h.get("HeaderSize") {
            None => HeaderSize::Follows,
            Some(v) => match v.parse::<i64>() {
                Ok(-1) => HeaderSize::AtEnd,
                Ok(0) => HeaderSize::Follows,
                Ok(n) if n > 0 => HeaderSize::At(n as u64),
                _ => {
                    return Err(bad(
                        "HeaderSize",
                        format!(
                            "expected a byte count ≥ 0, or -1 for samples that end the file, got '{v}'"
                        ),
                    ));
                }
            },
        };
        if compressed && header_size == HeaderSize::AtEnd {
            return Err(unsupported(
                "HeaderSize",
                "-1 (samples at the end of the file) with CompressedData = True: the compressed length is unknown from the end".into(),
            ));
        }
        let file = required("ElementDataFile")?;
        let data_file = match file {
            "LOCAL" | "Local" | "local" => None,
            f if f.starts_with("LIST") => {
                return Err(unsupported(
                    "ElementDataFile",
                    "LIST (one file per slice) is not read; join the slices into one file".into(),
                ));
            }
            // MetaIO's series: `name%03d.raw first last step`.
            f if f.contains('%') => {
                return Err(unsupported(
                    "ElementDataFile",
                    format!("'{f}' names a series of files; join the slices into one file"),
                ));
            }
            "" => {
                return Err(bad(
                    "ElementDataFile",
                    "empty; expected LOCAL or a file name".into(),
                ));
            }
            f => Some(relative_to(path, f)),
        };
        Ok(Layout {
            dims,
            spacing,
            ty,
            endian: if msb { Endian::Big } else { Endian::Little },
            compressed,
            compressed_size,
            header_size,
            data_file,
        })
    }
}

/// MetaIO's names of the sample types, as [`write`](fn@write) writes them.
const TYPE_NAMES: [(SampleType, &str); 8] = [
    (SampleType::I8, "MET_CHAR"),
    (SampleType::U8, "MET_UCHAR"),
    (SampleType::I16, "MET_SHORT"),
    (SampleType::U16, "MET_USHORT"),
    (SampleType::I32, "MET_INT"),
    (SampleType::U32, "MET_UINT"),
    (SampleType::F32, "MET_FLOAT"),
    (SampleType::F64, "MET_DOUBLE"),
];

/// `ElementType`'s sample type: [`TYPE_NAMES`], and `MET_LONG` and
/// `MET_ULONG`, 4 bytes in MetaIO's table of sizes.
fn element_type(name: &str) -> Result<SampleType, String> {
    if let Some(&(ty, _)) = TYPE_NAMES.iter().find(|(_, n)| *n == name) {
        return Ok(ty);
    }
    match name {
        "MET_LONG" => Ok(SampleType::I32),
        "MET_ULONG" => Ok(SampleType::U32),
        "MET_LONG_LONG" | "MET_ULONG_LONG" => Err(format!(
            "{name} (64-bit integers) is not read; convert to MET_INT, MET_FLOAT or MET_DOUBLE"
        )),
        other => Err(format!(
            "'{other}' is not a scalar type snell reads ({}, MET_LONG, MET_ULONG)",
            TYPE_NAMES.map(|(_, n)| n).join(", ")
        )),
    }
}

/// MetaIO's booleans: `True`/`False` in any case, or `1`/`0`.
fn boolean(v: &str) -> Option<bool> {
    match v.to_ascii_lowercase().as_str() {
        "true" | "1" => Some(true),
        "false" | "0" => Some(false),
        _ => None,
    }
}

/// Exactly `n` whitespace-separated numbers.
fn numbers<T: std::str::FromStr>(value: &str, n: usize) -> Option<Vec<T>> {
    let v: Vec<T> = value
        .split_whitespace()
        .map(|s| s.parse().ok())
        .collect::<Option<_>>()?;
    (v.len() == n).then_some(v)
}

/// A data file's name as MetaIO resolves it: relative to the header's
/// folder unless absolute.
fn relative_to(header: &Path, name: &str) -> PathBuf {
    let p = Path::new(name);
    if p.is_absolute() {
        return p.to_path_buf();
    }
    match header.parent() {
        Some(dir) => dir.join(p),
        None => p.to_path_buf(),
    }
}

/// The file that holds the samples: its name (for warnings), its bytes,
/// and where an attached header ends in them.
struct DataIn<'a> {
    path: &'a Path,
    bytes: &'a [u8],
    start: u64,
}

/// The `count` samples (`need` bytes) in `file`, errors named by the
/// header `path`: decoded, with the number of non-finite ones replaced and
/// the warnings for what followed them.
fn samples_in(
    path: &Path,
    file: DataIn,
    layout: &Layout,
    need: u64,
    count: usize,
    opts: &LoadOptions,
    what: &str,
) -> Result<(Decoded, Vec<String>), VolumeError> {
    let DataIn { bytes, start, .. } = file;
    let len = bytes.len() as u64;
    let from = match layout.header_size {
        HeaderSize::Follows => start,
        HeaderSize::At(n) => n,
        HeaderSize::AtEnd => len
            .checked_sub(need)
            .filter(|&f| f >= start)
            .ok_or_else(|| VolumeError::Truncated {
                path: path.to_path_buf(),
                need,
                got: len.saturating_sub(start),
                what: format!("{what}, at the end of the file (HeaderSize = -1)"),
            })?,
    };
    if from > len {
        return Err(VolumeError::format(
            path,
            format!("HeaderSize points past the end of the file ({from} > {len} bytes)"),
        ));
    }
    let mut warnings = Vec::new();
    let decode = |data: &[u8]| {
        decode_samples(
            path,
            data,
            layout.ty,
            layout.endian,
            count,
            None,
            opts.allow_nan,
        )
    };
    if !layout.compressed {
        let data = byte_range(bytes, from, from.saturating_add(need)).ok_or_else(|| {
            VolumeError::Truncated {
                path: path.to_path_buf(),
                need,
                got: len - from,
                what: what.to_string(),
            }
        })?;
        let after = len - from - need;
        if after > 0 {
            warnings.push(super::gzip::after_samples(file.path, after, count, false));
        }
        return Ok((decode(data)?, warnings));
    }
    let available = len - from;
    let zsize = match layout.compressed_size {
        Some(n) if n > available => {
            return Err(VolumeError::Truncated {
                path: path.to_path_buf(),
                need: n,
                got: available,
                what: format!("CompressedDataSize of {what}"),
            });
        }
        Some(n) => n,
        None => available,
    };
    if need > max_gunzipped_len(zsize) {
        return Err(VolumeError::format(
            path,
            format!(
                "{zsize} bytes of zlib data cannot hold the {need} bytes of {what} (deflate expands at most 1032:1)"
            ),
        ));
    }
    // The decompressed bytes and the decoded samples at once.
    limits::check_bytes(
        path,
        need.saturating_add((count as u64).saturating_mul(4)),
        opts.memory_limit,
        &format!("decompressing {what}"),
    )?;
    let region = byte_range(bytes, from, from + zsize).unwrap_or_default();
    let mut z = ZlibDecoder::new(region);
    let mut buf = zeroed_buffer(path, need as usize)?;
    let corrupt =
        |e: std::io::Error| VolumeError::format(path, format!("zlib data is corrupt: {e}"));
    let got = read_full(&mut z, &mut buf).map_err(corrupt)?;
    if (got as u64) < need {
        return Err(VolumeError::Truncated {
            path: path.to_path_buf(),
            need,
            got: got as u64,
            what: format!("{what}, after decompressing {zsize} bytes"),
        });
    }
    let mut probe = [0u8; 1];
    if z.read(&mut probe).map_err(corrupt)? > 0 {
        warnings.push(format!(
            "{}: more decompressed data after the {count} samples ignored",
            file.path.display()
        ));
    }
    Ok((decode(&buf)?, warnings))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    /// A scratch folder for one test, removed with it.
    struct Dir(PathBuf);

    impl Dir {
        fn new(test: &str) -> Dir {
            let dir = std::env::temp_dir().join(format!("snell-mha-{test}-{}", std::process::id()));
            std::fs::create_dir_all(&dir).unwrap();
            Dir(dir)
        }

        fn path(&self, name: &str) -> PathBuf {
            self.0.join(name)
        }

        fn read(&self, name: &str, bytes: &[u8]) -> Result<Volume, VolumeError> {
            let p = self.path(name);
            std::fs::write(&p, bytes).unwrap();
            read(&p, &LoadOptions::default())
        }
    }

    impl Drop for Dir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    fn header(extra: &str, data_file: &str) -> String {
        format!(
            "ObjectType = Image\nNDims = 3\nBinaryData = True\n{extra}DimSize = 3 2 2\nElementType = MET_USHORT\nElementDataFile = {data_file}\n"
        )
    }

    /// Twelve u16 samples 0, 100, ..., 1100 in `endian` order.
    fn samples(endian: Endian) -> Vec<u8> {
        (0..12u16)
            .flat_map(|i| match endian {
                Endian::Little => (i * 100).to_le_bytes(),
                Endian::Big => (i * 100).to_be_bytes(),
            })
            .collect()
    }

    fn expect_samples(v: &Volume) {
        let want: Vec<f32> = (0..12).map(|i| (i * 100) as f32).collect();
        assert_eq!(v.samples(), &want[..]);
        assert_eq!(v.dims(), [3, 2, 2]);
    }

    #[test]
    fn local_data_with_spacing_and_byte_order() {
        let d = Dir::new("local");
        let mut f = header("ElementSpacing = 0.5 1 1.25\nOffset = 1 2 3\n", "LOCAL").into_bytes();
        f.extend(samples(Endian::Little));
        let v = d.read("a.mha", &f).unwrap();
        expect_samples(&v);
        assert_eq!(v.spacing(), [0.5, 1.0, 1.25]);
        assert!(v.warnings.is_empty(), "{:?}", v.warnings);
        assert_eq!(v.native_type(), SampleType::U16);

        let mut f = header("BinaryDataByteOrderMSB = True\n", "LOCAL").into_bytes();
        f.extend(samples(Endian::Big));
        expect_samples(&d.read("b.mha", &f).unwrap());
        // CRLF lines, and ElementSize standing in for ElementSpacing.
        let mut f = header("ElementSize = 2 2 3\n", "LOCAL")
            .replace('\n', "\r\n")
            .into_bytes();
        f.extend(samples(Endian::Little));
        let v = d.read("c.mha", &f).unwrap();
        expect_samples(&v);
        assert_eq!(v.spacing(), [2.0, 2.0, 3.0]);
    }

    /// A reflecting TransformMatrix warns that the render is a mirror
    /// image; the identity and a rotation (two axes reversed) do not.
    #[test]
    fn mirrored_transform_is_told() {
        let d = Dir::new("mirror");
        for (i, (matrix, warns)) in [
            ("1 0 0 0 1 0 0 0 1", false),
            ("-1 0 0 0 -1 0 0 0 1", false),
            ("-1 0 0 0 1 0 0 0 1", true),
            ("0 1 0 1 0 0 0 0 1", true),
        ]
        .into_iter()
        .enumerate()
        {
            let mut f = header(&format!("TransformMatrix = {matrix}\n"), "LOCAL").into_bytes();
            f.extend(samples(Endian::Little));
            let v = d.read(&format!("m{i}.mha"), &f).unwrap();
            expect_samples(&v);
            assert_eq!(
                v.warnings.iter().any(|w| w.contains("mirror image")),
                warns,
                "{matrix}: {:?}",
                v.warnings
            );
        }
    }

    #[test]
    fn detached_data_with_header_sizes() {
        let d = Dir::new("detached");
        let raw = d.path("d.raw");
        let mut bytes = vec![7u8; 10];
        bytes.extend(samples(Endian::Little));
        std::fs::write(&raw, &bytes).unwrap();
        for hs in ["HeaderSize = 10\n", "HeaderSize = -1\n"] {
            let v = d.read("d.mhd", header(hs, "d.raw").as_bytes()).unwrap();
            expect_samples(&v);
        }
        // Without a HeaderSize the 10 bytes are read as samples: the file
        // then holds 10 bytes too many, a warning.
        let v = d.read("e.mhd", header("", "d.raw").as_bytes()).unwrap();
        assert_eq!(v.warnings.len(), 1, "{:?}", v.warnings);
        assert!(v.warnings[0].contains("10 bytes after the 12 samples"));
        let err = d
            .read("f.mhd", header("", "missing.raw").as_bytes())
            .unwrap_err();
        assert!(err.to_string().contains("ElementDataFile"), "{err}");
        // A name with a space is one file (MetaIO's series need a '%').
        std::fs::write(d.path("my scan.raw"), samples(Endian::Little)).unwrap();
        expect_samples(
            &d.read("g.mhd", header("", "my scan.raw").as_bytes())
                .unwrap(),
        );
        // Errors about the data name the header, the file the user gave.
        std::fs::write(d.path("short.raw"), [0u8; 3]).unwrap();
        let err = d
            .read("h.mhd", header("", "short.raw").as_bytes())
            .unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.starts_with(&d.path("h.mhd").display().to_string()),
            "{msg}"
        );
        assert!(msg.contains("short.raw"), "{msg}");
    }

    #[test]
    fn zlib_data_with_and_without_its_size() {
        let d = Dir::new("zlib");
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        z.write_all(&samples(Endian::Little)).unwrap();
        let packed = z.finish().unwrap();
        for size in [
            String::new(),
            format!("CompressedDataSize = {}\n", packed.len()),
        ] {
            let mut f = header(&format!("CompressedData = True\n{size}"), "LOCAL").into_bytes();
            f.extend(&packed);
            expect_samples(&d.read("z.mha", &f).unwrap());
        }
        // Cut short: an error naming the shortfall, never a panic.
        let mut f = header("CompressedData = True\n", "LOCAL").into_bytes();
        f.extend(&packed[..packed.len() / 2]);
        assert!(d.read("zc.mha", &f).is_err());
        // A size past the file's end.
        let mut f = header(
            "CompressedData = True\nCompressedDataSize = 9999\n",
            "LOCAL",
        )
        .into_bytes();
        f.extend(&packed);
        let err = d.read("zs.mha", &f).unwrap_err().to_string();
        assert!(err.contains("CompressedDataSize"), "{err}");
    }

    #[test]
    fn refuses_what_it_cannot_read_by_name() {
        let d = Dir::new("refuses");
        let cases = [
            (
                header("", "LOCAL").replace("MET_USHORT", "MET_LONG_LONG"),
                "64-bit",
            ),
            (
                header("", "LOCAL").replace("MET_USHORT", "MET_RGB"),
                "MET_RGB",
            ),
            (
                header("ElementNumberOfChannels = 3\n", "LOCAL"),
                "3 channels",
            ),
            (
                header("", "LOCAL").replace("BinaryData = True", "BinaryData = False"),
                "BinaryData",
            ),
            (header("", "LIST"), "LIST"),
            (header("", "slice%03d.raw 1 2 1"), "series"),
            (
                header("", "LOCAL").replace("NDims = 3", "NDims = 4"),
                "DimSize",
            ),
            (
                header("", "LOCAL").replace("DimSize = 3 2 2", "DimSize = 3 0 2"),
                "DimSize",
            ),
            (
                header("", "LOCAL").replace("ObjectType = Image", "ObjectType = Tube"),
                "Tube",
            ),
            (
                header("HeaderSize = -1\nCompressedData = True\n", "LOCAL"),
                "HeaderSize",
            ),
            (header("HeaderSize = 1000000\n", "LOCAL"), "past the end"),
            (
                header("ElementSpacing = 1 0 1\n", "LOCAL"),
                "ElementSpacing",
            ),
            (header("NDims = 3\n", "LOCAL"), "twice"),
            ("NDims 3\n".to_string(), "Name = Value"),
            (
                header("", "LOCAL").replace("ElementDataFile = LOCAL\n", ""),
                "ElementDataFile",
            ),
            (header("", "LOCAL"), "data holds 0 bytes"),
        ];
        for (text, needle) in cases {
            let err = d.read("bad.mha", text.as_bytes()).unwrap_err().to_string();
            assert!(err.contains(needle), "{needle}: {err}");
            assert!(err.contains("bad.mha"), "{err}");
        }
    }

    /// What [`write`] writes reads back bit for bit, every sample type,
    /// raw and compressed, with the spacing's exact bits.
    #[test]
    fn writes_what_it_reads() {
        let d = Dir::new("writes");
        let types = [
            SampleType::I8,
            SampleType::U8,
            SampleType::I16,
            SampleType::U16,
            SampleType::I32,
            SampleType::U32,
            SampleType::F32,
            SampleType::F64,
        ];
        for ty in types {
            let samples: Vec<f32> = (0..60).map(|i| (i * 2 + 1) as f32).collect();
            let vol = Volume::new([5, 4, 3], [0.1, 1.0 / 3.0, 2.5], ty, samples).unwrap();
            for compressed in [false, true] {
                let p = d.path(&format!("{ty}-{compressed}.mha"));
                write(&p, &vol, compressed).unwrap();
                let back = read(&p, &LoadOptions::default()).unwrap();
                assert_eq!(back.native_type(), ty);
                assert_eq!(back.samples(), vol.samples(), "{ty} {compressed}");
                assert_eq!(
                    back.spacing().map(f64::to_bits),
                    vol.spacing().map(f64::to_bits)
                );
                assert!(back.warnings.is_empty(), "{:?}", back.warnings);
            }
        }
    }

    #[test]
    fn unknown_fields_and_intensity_functions_are_warned_of() {
        let d = Dir::new("unknown");
        let mut f = header(
            "ElementSpacng = 2 2 2\nAnatomicalOrientation = RAI\nITK_InputFilterName = NrrdImageIO\nITK_original_spacing = 1 1 1\n",
            "LOCAL",
        )
        .into_bytes();
        f.extend(samples(Endian::Little));
        let v = d.read("w.mha", &f).unwrap();
        assert_eq!(v.spacing(), [1.0; 3]);
        assert_eq!(v.warnings.len(), 1, "{:?}", v.warnings);
        assert!(
            v.warnings[0].contains("'ElementSpacng'") && v.warnings[0].contains("'ElementSpacing'"),
            "{:?}",
            v.warnings
        );

        let mut f = header("ElementToIntensityFunctionSlope = 2\n", "LOCAL").into_bytes();
        f.extend(samples(Endian::Little));
        let v = d.read("i.mha", &f).unwrap();
        expect_samples(&v);
        assert_eq!(v.warnings.len(), 1, "{:?}", v.warnings);
        assert!(
            v.warnings[0].contains("slope 2, offset 0"),
            "{:?}",
            v.warnings
        );
        let mut f = header(
            "ElementToIntensityFunctionSlope = 1\nElementToIntensityFunctionOffset = 0\n",
            "LOCAL",
        )
        .into_bytes();
        f.extend(samples(Endian::Little));
        assert!(d.read("j.mha", &f).unwrap().warnings.is_empty());
    }
}
