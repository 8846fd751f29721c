//! Gzip streams as the readers take them: members read as one stream, bytes
//! after the last member that start no other counted rather than refused,
//! and what follows the samples read (so the last member's CRC is checked)
//! and counted; and the warnings every reader gives for what follows a
//! volume's samples, in the file or in its decompressed stream.

use std::io::{self, BufRead, Read};
use std::path::Path;

use super::VolumeError;
use super::raw::gzip_error;

/// Decompressed bytes after the samples counted at most, so that a gzip
/// bomb behind a small volume costs a bounded time: the warning then says
/// "at least".
pub(super) const DRAIN_LIMIT: u64 = 256 << 20;

/// A gzip stream of one or more members, read as one, that stops — as teem's
/// reader, which never looks past the samples, would not fail — at bytes
/// after a whole member that do not start another (gzip's magic `1f 8b`),
/// counting them in `trailing`. A member that is corrupt or cut short is an
/// error as ever.
pub(super) struct GzMembers<R: BufRead> {
    dec: Option<flate2::bufread::GzDecoder<R>>,
    pub(super) trailing: u64,
}

impl<R: BufRead> GzMembers<R> {
    pub(super) fn new(src: R) -> GzMembers<R> {
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

/// The warning for what follows a volume's `count` samples: `n` more bytes
/// of the file, or of the decompressed stream (counted up to
/// [`DRAIN_LIMIT`], beyond which it says "at least").
pub(super) fn after_samples(path: &Path, n: u64, count: usize, decompressed: bool) -> String {
    let s = if n == 1 { "" } else { "s" };
    let what = match (decompressed, n >= DRAIN_LIMIT) {
        (false, _) => format!("{n} byte{s}"),
        (true, false) => format!("{n} more decompressed byte{s}"),
        (true, true) => format!("at least {n} more decompressed bytes"),
    };
    format!(
        "{}: {what} after the {count} samples ignored",
        path.display()
    )
}

/// The warning for `n` bytes after the last gzip member that start no
/// other ([`GzMembers::trailing`]).
pub(super) fn after_gzip(path: &Path, n: u64) -> String {
    format!(
        "{}: {n} byte{} after the gzip data, not gzip, {} ignored",
        path.display(),
        if n == 1 { "" } else { "s" },
        if n == 1 { "was" } else { "were" },
    )
}

/// Reads `dec` on to its end, which checks the last member's CRC, handing
/// each decompressed chunk to `each`; stops at [`DRAIN_LIMIT`] bytes unless
/// `each` asked for the whole stream (returned `true`). Returns the bytes
/// read. A stream cut before its trailer is an error that says so.
pub(super) fn drain(
    path: &Path,
    dec: &mut impl Read,
    mut each: impl FnMut(&[u8]) -> bool,
) -> Result<u64, VolumeError> {
    let mut more = 0u64;
    let mut chunk = vec![0u8; 64 << 10];
    loop {
        let n = match dec.read(&mut chunk) {
            Ok(0) => return Ok(more),
            Ok(n) => n.min(chunk.len()),
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => {
                return Err(VolumeError::format(
                    path,
                    // A damaged byte near the end can read as an early end too.
                    "gzip data ends before its trailer: the file is truncated or damaged",
                ));
            }
            Err(e) => return Err(gzip_error(path, e)),
        };
        more += n as u64;
        if !each(&chunk[..n]) && more >= DRAIN_LIMIT {
            return Ok(more);
        }
    }
}
