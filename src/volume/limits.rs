//! Memory limits checked before any large allocation.
//!
//! A header can claim any size; we refuse early with a message instead of letting
//! the allocator abort the process. The default limit is 80% of the memory the
//! kernel reports available, overridable with `SNELL_MEMORY_LIMIT` (bytes, or with
//! a `K`/`M`/`G` suffix) or `--memory-limit` on the command line.

use std::path::Path;

use super::VolumeError;

/// Bytes a sample costs at peak: the `f32` sample, the `f64` prefilter work
/// grid, the `f32` padded coefficients, and a byte of slack for cell tags.
pub const WORKING_BYTES_PER_SAMPLE: u64 = 17;

/// Parses `123`, `64K`, `512M`, `1.5G`, `20G` (binary units; a fraction
/// rounds to whole bytes).
pub fn parse_bytes(s: &str) -> Option<u64> {
    let s = s.trim();
    let (num, mul) = match s.chars().last()?.to_ascii_uppercase() {
        'K' => (&s[..s.len() - 1], 1u64 << 10),
        'M' => (&s[..s.len() - 1], 1u64 << 20),
        'G' => (&s[..s.len() - 1], 1u64 << 30),
        'T' => (&s[..s.len() - 1], 1u64 << 40),
        _ => (s, 1),
    };
    let num = num.trim();
    if let Ok(n) = num.parse::<u64>() {
        return n.checked_mul(mul);
    }
    // A fraction of a unit, e.g. 1.5G.
    let x = num.parse::<f64>().ok()? * mul as f64;
    (num.bytes().all(|b| b.is_ascii_digit() || b == b'.') && x < u64::MAX as f64)
        .then(|| x.round() as u64)
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
    if let Ok(s) = std::env::var("SNELL_MEMORY_LIMIT") {
        match parse_bytes(&s) {
            Some(v) => return v,
            None => {
                static WARNED: std::sync::Once = std::sync::Once::new();
                WARNED.call_once(|| {
                    eprintln!(
                        "warning: SNELL_MEMORY_LIMIT='{s}' is not a size like 512M, 1.5G or 8G; ignored"
                    )
                });
            }
        }
    }
    available_memory().map(|m| m / 5 * 4).unwrap_or(16u64 << 30)
}

/// Fails with a message naming `what` when `bytes` exceeds `limit`.
pub fn check_bytes(path: &Path, bytes: u64, limit: u64, what: &str) -> Result<(), VolumeError> {
    if bytes > limit {
        return Err(VolumeError::TooLarge {
            path: path.to_path_buf(),
            msg: format!(
                "{what} needs about {} of memory, over the limit of {} (set --memory-limit or SNELL_MEMORY_LIMIT to raise it)",
                human_bytes(bytes),
                human_bytes(limit)
            ),
        });
    }
    Ok(())
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
        assert_eq!(parse_bytes("1024"), Some(1024));
        assert_eq!(parse_bytes("2K"), Some(2048));
        assert_eq!(parse_bytes("3g"), Some(3 << 30));
        assert_eq!(parse_bytes("x"), None);
        assert_eq!(parse_bytes("99999999999999T"), None);
    }

    #[test]
    fn parses_fractions_and_refuses_signs_and_exponents() {
        assert_eq!(parse_bytes(" 512m "), Some(512 << 20));
        assert_eq!(parse_bytes("1.5G"), Some(3 << 29));
        assert_eq!(parse_bytes("0.5K"), Some(512));
        for bad in [
            "",
            "lots",
            "-5G",
            "1e3",
            "NaN",
            "inf",
            "1.5.2G",
            "99999999999T",
        ] {
            assert_eq!(parse_bytes(bad), None, "{bad}");
        }
    }

    #[test]
    fn formats_sizes() {
        assert_eq!(human_bytes(10), "10 B");
        assert_eq!(human_bytes(3 << 30), "3.0 GiB");
    }
}
