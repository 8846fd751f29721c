//! Memory limits checked before any large allocation.
//!
//! A header can claim any size; we refuse early with a message instead of letting
//! the allocator abort the process. The default limit is 80% of the memory the
//! kernel reports available, overridable with `SNELL_MEMORY_LIMIT` (bytes, or with
//! a `K`/`M`/`G`/`T` suffix, binary multiples; see [`parse_bytes`]) or `--memory-limit` on the command line.

use std::path::Path;

use super::VolumeError;

/// Bytes a sample costs at peak: the `f32` sample, the `f64` prefilter work
/// grid, the `f32` padded coefficients, and a byte of slack for cell tags.
pub const WORKING_BYTES_PER_SAMPLE: u64 = 17;

/// Parses a size: a byte count (`123`, `1e9`, `512B`), or a number with
/// `K`, `M`, `G` or `T` and an optional `B` or `iB` (`64K`, `512MB`,
/// `1.5G`, `2GiB`), case-insensitive. The multiples are binary whichever
/// way they are written (`1G` = `1GB` = `1GiB` = 2^30 bytes): memory comes
/// in powers of two, and one reading of a suffix spares the user guessing
/// which one was meant. A fraction rounds to whole bytes. Signs,
/// infinities and NaN are refused, and so is a size under one byte (`0`,
/// `0.4`, `1e-9`): a limit of zero bytes would refuse every load. The
/// error says why, to follow the option or variable's name.
pub fn parse_bytes(s: &str) -> Result<u64, String> {
    let bytes = match parse_size(s) {
        Some(Size::Bytes(b)) => b,
        Some(Size::TooLarge) => {
            return Err(format!(
                "'{}' is over the largest size, 2^64 - 1 bytes (16 EiB)",
                s.trim()
            ));
        }
        None => {
            return Err(format!(
                "'{}' is not a size like 512M, 2GB, 1.5GiB or 1e9",
                s.trim()
            ));
        }
    };
    if bytes == 0 {
        return Err(format!(
            "'{}' is under one byte; a limit of zero bytes would refuse every volume",
            s.trim()
        ));
    }
    Ok(bytes)
}

/// A size as written: whole bytes, or more than a `u64` holds.
enum Size {
    Bytes(u64),
    TooLarge,
}

/// [`parse_bytes`] without its bounds: the size in whole bytes, or `None`
/// for what is not a size.
fn parse_size(s: &str) -> Option<Size> {
    let lower = s.trim().to_ascii_lowercase();
    let t = lower
        .strip_suffix("ib")
        .or_else(|| lower.strip_suffix('b'))
        .unwrap_or(&lower);
    // "ib" alone ("5ib") is not a unit: it must follow K, M, G or T.
    let binary_suffix = lower.ends_with("ib");
    let (num, mul) = match t.chars().last()? {
        'k' => (&t[..t.len() - 1], 1u64 << 10),
        'm' => (&t[..t.len() - 1], 1u64 << 20),
        'g' => (&t[..t.len() - 1], 1u64 << 30),
        't' => (&t[..t.len() - 1], 1u64 << 40),
        _ if binary_suffix => return None,
        _ => (t, 1),
    };
    let num = num.trim();
    if !num.is_empty() && num.bytes().all(|b| b.is_ascii_digit()) {
        return Some(
            match num.parse::<u64>().ok().and_then(|n| n.checked_mul(mul)) {
                Some(b) => Size::Bytes(b),
                None => Size::TooLarge,
            },
        );
    }
    // A fraction of a unit (1.5G) or an exponent (1e9): digits, one point,
    // an exponent; no sign, `inf` or `nan`.
    if !num.starts_with(|c: char| c.is_ascii_digit() || c == '.')
        || !num
            .bytes()
            .all(|b| b.is_ascii_digit() || matches!(b, b'.' | b'e' | b'-' | b'+'))
    {
        return None;
    }
    let x = num.parse::<f64>().ok()? * mul as f64;
    // No sign, `inf` or `nan` got here: an infinity is a number past f64's
    // range, and NaN cannot arise.
    if x.is_nan() || x < 0.0 {
        return None;
    }
    Some(if x < u64::MAX as f64 {
        Size::Bytes(x.round() as u64)
    } else {
        Size::TooLarge
    })
}

/// Memory the kernel says is available (`MemAvailable`), if it can be read.
pub fn available_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    text.lines()
        .find(|l| l.starts_with("MemAvailable:"))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|kb| kb.parse::<u64>().ok())
        .map(|kb| kb * 1024)
}

/// `SNELL_MEMORY_LIMIT` if set and valid, else 80% of available memory, else 16 GiB.
pub fn default_memory_limit() -> u64 {
    if let Some(s) = crate::env::setting("SNELL_MEMORY_LIMIT") {
        match parse_bytes(&s) {
            Ok(v) => return v,
            Err(why) => {
                static WARNED: std::sync::Once = std::sync::Once::new();
                WARNED.call_once(|| eprintln!("warning: SNELL_MEMORY_LIMIT: {why}; ignored"));
            }
        }
    }
    available_memory().map(|m| m / 5 * 4).unwrap_or(16u64 << 30)
}

/// Fails with a message naming `what` when `bytes` exceeds `limit`.
pub fn check_bytes(path: &Path, bytes: u64, limit: u64, what: &str) -> Result<(), VolumeError> {
    if bytes > limit {
        return Err(VolumeError::OverLimit {
            path: path.to_path_buf(),
            source: OverLimit {
                what: what.to_string(),
                need: bytes,
                limit,
                hint: " (set --memory-limit or SNELL_MEMORY_LIMIT to raise it)".into(),
            },
        });
    }
    Ok(())
}

/// A working set refused before it was allocated: what needed how many
/// bytes, and the limit it met. A type of its own (the source of the
/// volume's and the scene's errors that carry it) so a caller that lent
/// part of the limit to something else, as `snell render` does to the
/// image, can find it in an error's chain and say so.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error(
    "{what} needs about {} of memory, over the limit of {}{hint}",
    human_bytes(*.need),
    human_bytes(*.limit)
)]
pub struct OverLimit {
    /// What would have been allocated, e.g. "a 64x64x64 volume".
    pub what: String,
    pub need: u64,
    pub limit: u64,
    /// How to get past it (and what else bears on it), appended to the
    /// message.
    pub hint: String,
}

/// `1.5 GiB`-style formatting for messages and reports.
pub fn human_bytes(b: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = b as f64;
    let mut u = 0;
    while v >= 1024.0 && u + 1 < UNITS.len() {
        v /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{b} B")
    } else {
        format!("{v:.1} {}", UNITS[u])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_sizes() {
        assert_eq!(parse_bytes("1024").ok(), Some(1024));
        assert_eq!(parse_bytes("2K").ok(), Some(2048));
        assert_eq!(parse_bytes("3g").ok(), Some(3 << 30));
        assert!(parse_bytes("x").is_err());
        assert!(parse_bytes("99999999999999T").is_err());
    }

    #[test]
    fn parses_fractions_and_refuses_signs_and_words() {
        assert_eq!(parse_bytes(" 512m ").ok(), Some(512 << 20));
        assert_eq!(parse_bytes("1.5G").ok(), Some(3 << 29));
        assert_eq!(parse_bytes("0.5K").ok(), Some(512));
        for bad in [
            "", "lots", "-5G", "-1e3", "NaN", "inf", "infG", "1.5.2G", "5iB", "G", "GB",
        ] {
            let e = parse_bytes(bad).unwrap_err();
            assert!(e.contains("is not a size like"), "{bad}: {e}");
        }
        // Sizes, but beyond what 64 bits count.
        for big in ["99999999999T", "1e30", "18446744073709551616", "1e400"] {
            let e = parse_bytes(big).unwrap_err();
            assert!(e.contains("over the largest size"), "{big}: {e}");
        }
    }

    /// `B` and `iB` suffixes and exponents are accepted; the multiples stay
    /// binary however they are written.
    #[test]
    fn parses_byte_suffixes_and_exponents() {
        assert_eq!(parse_bytes("2GB").ok(), Some(2 << 30));
        assert_eq!(parse_bytes("2GiB").ok(), Some(2 << 30));
        assert_eq!(parse_bytes("2gib").ok(), Some(2 << 30));
        assert_eq!(parse_bytes("512MB").ok(), Some(512 << 20));
        assert_eq!(parse_bytes("1.5TiB").ok(), Some(3 << 39));
        assert_eq!(parse_bytes("64kb").ok(), Some(64 << 10));
        assert_eq!(parse_bytes("100B").ok(), Some(100));
        assert_eq!(parse_bytes("1e9").ok(), Some(1_000_000_000));
        assert_eq!(parse_bytes("1e3").ok(), Some(1000));
        assert_eq!(parse_bytes("2.5e3K").ok(), Some(2_560_000));
    }

    /// A size that rounds to zero bytes would refuse every load: refused,
    /// saying so; half a byte rounds up to one.
    #[test]
    fn refuses_sizes_under_one_byte() {
        for zero in ["0", "0.4", "1e-9", "0K", "0.0000000001G", "0B"] {
            let e = parse_bytes(zero).unwrap_err();
            assert!(e.contains("under one byte"), "{zero}: {e}");
        }
        assert_eq!(parse_bytes("0.5").ok(), Some(1));
        assert_eq!(parse_bytes("1").ok(), Some(1));
    }

    #[test]
    fn formats_sizes() {
        assert_eq!(human_bytes(10), "10 B");
        assert_eq!(human_bytes(3 << 30), "3.0 GiB");
    }
}
