//! Locating and decompressing the data: the raw, ascii and gzip regions of
//! the samples after the header and the skips, and what follows them.

use std::io::{self, BufRead};
use std::path::Path;

use super::super::gzip::{GzMembers, drain};
use super::super::raw::{
    byte_range, data_byte_len, gzip_error, max_gunzipped_len, read_full, skip_bytes, zeroed_buffer,
};
use super::super::{LoadOptions, SampleType, VolumeError, limits};
use super::Extra;
use super::header::excerpt;
use super::layout::{ByteSkip, Layout};

/// The `need` bytes of raw data in `bytes` (a mapped file) after the header
/// and skips, and how many bytes follow them. Too few is truncation; more
/// are left unread, as teem leaves them (a trailing newline is common), and
/// the caller says how many.
pub(super) fn raw_region<'a>(
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
    let after_lines = skip_lines_in(after_header, layout.line_skip)
        .ok_or_else(|| line_skip_past_end(path, layout, what))?;
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
pub(super) fn ascii_region(
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
    let after_lines = skip_lines_in(after_header, layout.line_skip)
        .ok_or_else(|| line_skip_past_end(path, layout, what))?;
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
        macro_rules! float {
            ($t:ty, $range:expr) => {{
                let v = t.parse::<$t>().map_err(|_| bad())?;
                let literal = t.trim_start_matches(['+', '-']).to_ascii_lowercase();
                if v.is_infinite() && !literal.starts_with("inf") {
                    return Err(fmt(format!(
                        "ascii value {i} ('{}') is beyond {}",
                        excerpt(t),
                        $range
                    )));
                }
                slot.copy_from_slice(&v.to_le_bytes())
            }};
        }
        match ty {
            SampleType::I8 => parse!(i8),
            SampleType::U8 => parse!(u8),
            SampleType::I16 => parse!(i16),
            SampleType::U16 => parse!(u16),
            SampleType::I32 => parse!(i32),
            SampleType::U32 => parse!(u32),
            // Rounded once, from the decimal text; a finite number beyond
            // the type (which parses as an infinity) is refused as such, as
            // the binary encodings' are beyond f32, not called infinite for
            // `--allow-nan` to erase.
            SampleType::F32 => float!(f32, "f32's range (±3.4e38)"),
            SampleType::F64 => float!(f64, "f64's range (±1.8e308)"),
        }
    }
    Ok((out, values.count() as u64))
}

/// `bytes` after its first `lines` lines, or `None` when it has fewer.
pub(super) fn skip_lines_in(bytes: &[u8], lines: u64) -> Option<&[u8]> {
    let mut rest = bytes;
    for _ in 0..lines {
        let nl = rest.iter().position(|&b| b == b'\n')?;
        rest = rest.get(nl + 1..)?;
    }
    Some(rest)
}

/// Discards `lines` lines from `src`; returns the bytes discarded, or `None`
/// when the stream ends first. Never buffers a whole line.
pub(super) fn skip_lines_from<R: BufRead>(src: &mut R, lines: u64) -> io::Result<Option<u64>> {
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
pub(super) fn gzip_region<R: BufRead>(
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
        .ok_or_else(|| line_skip_past_end(path, layout, what))?;
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

    // A stream too short for gzip's header reads as empty, not as corrupt:
    // bytes that are not gzip at all are named as such.
    let head = src.fill_buf().map_err(|e| VolumeError::io(path, e))?;
    if !head.is_empty() && !head.starts_with(&[0x1f, 0x8b]) && head != [0x1f] {
        return Err(gzip_error(
            path,
            io::Error::new(
                io::ErrorKind::InvalidData,
                "it does not start with gzip's magic bytes 1f 8b",
            ),
        ));
    }
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
    let mut ring = 0usize;
    let mut more = drain(path, &mut dec, |chunk| {
        if layout.byte_skip == ByteSkip::DataAtEnd {
            ring = ring_write(&mut buf, ring, chunk);
            true
        } else {
            false
        }
    })?;
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

/// Writes `data` into the ring `buf` at `at`; returns the next position.
/// `buf` then holds the last `buf.len()` bytes ever written, oldest at the
/// returned position.
pub(super) fn ring_write(buf: &mut [u8], at: usize, data: &[u8]) -> usize {
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

/// The error of a `line skip` longer than the data it skips in.
fn line_skip_past_end(path: &Path, layout: &Layout, what: &str) -> VolumeError {
    VolumeError::format(
        path,
        format!(
            "line skip {} passes the end of the data ({what})",
            layout.line_skip
        ),
    )
}
