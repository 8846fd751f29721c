//! Shared harness code for the fuzz targets: a per-process scratch directory
//! (the readers take paths, and memory-map or stream their files), small
//! memory limits so no input can make the process allocate much, and the
//! invariants every successful load must satisfy.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use snell::volume::{LoadOptions, Volume, VolumeError};

/// Working-set limit for fuzzed volumes: big enough for every seed, small
/// enough that a hostile header is refused long before libFuzzer's RSS limit.
pub const MEMORY_LIMIT: u64 = 16 << 20;

/// Sets `SNELL_MEMORY_LIMIT` to [`MEMORY_LIMIT`] for the readers that take
/// their limit from it (images, EXRs, photographs), so a hostile header is
/// refused long before libFuzzer's RSS limit. Call it first in a target.
pub fn limit_memory() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // SAFETY: called on the fuzzer's thread before the target has
        // started any other thread (the first input's call), so nothing
        // reads the environment meanwhile.
        unsafe { std::env::set_var("SNELL_MEMORY_LIMIT", MEMORY_LIMIT.to_string()) };
    });
}

/// A directory private to this process, under `$SNELL_FUZZ_SCRATCH` or
/// else on tmpfs when there is one.
pub fn scratch() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        // fuzz/run.sh names a directory it removes afterwards.
        let shm = Path::new("/dev/shm");
        let base = if let Some(d) = std::env::var_os("SNELL_FUZZ_SCRATCH") {
            PathBuf::from(d)
        } else if shm.is_dir() {
            shm.to_path_buf()
        } else {
            std::env::temp_dir()
        };
        let dir = base.join(format!("snell-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("scratch directory");
        dir
    })
}

/// Writes `bytes` to `name` in the scratch directory.
pub fn put(name: &str, bytes: &[u8]) -> PathBuf {
    let p = scratch().join(name);
    std::fs::write(&p, bytes).expect("scratch write");
    p
}

pub fn options(allow_nan: bool) -> LoadOptions {
    LoadOptions {
        allow_nan,
        memory_limit: MEMORY_LIMIT,
        raw: None,
    }
}

/// A detached-header input, `[len: u16 LE][header: len bytes][payload]`:
/// `len`, the header and the payload (`None` under two bytes).
pub fn header_and_payload(data: &[u8]) -> Option<(usize, &[u8], &[u8])> {
    let (len, rest) = data.split_first_chunk::<2>()?;
    let len = u16::from_le_bytes(*len) as usize;
    let (header, payload) = rest.split_at(len.min(rest.len()));
    Some((len, header, payload))
}

/// False when a NRRD header names a data file outside the scratch directory
/// (an absolute path, a parent directory, a device): the fuzzer must only
/// ever read the files it wrote.
pub fn data_file_is_local(header: &[u8]) -> bool {
    let text = String::from_utf8_lossy(header);
    // From the first `data file` line on: the LIST form names its files on
    // the lines after it.
    let mut lines = text.lines().skip_while(|l| {
        let l = l.trim_start().to_ascii_lowercase();
        !(l.starts_with("data file") || l.starts_with("datafile"))
    });
    !lines.any(|l| l.contains('/') || l.contains('\\') || l.contains(".."))
}

/// False when a MetaImage header's `ElementDataFile` could name a file
/// outside the scratch directory (a path with a folder, a parent, a
/// device): the fuzzer must only ever read the files it wrote.
pub fn metaimage_file_is_local(header: &[u8]) -> bool {
    let text = String::from_utf8_lossy(header);
    // Every line that could be the field (names are matched as written,
    // but be generous: any line that mentions it).
    !text
        .lines()
        .filter(|l| l.contains("ElementDataFile"))
        .any(|l| l.contains('/') || l.contains('\\') || l.contains(".."))
}

/// What every load must give: a consistent volume of finite samples, or an
/// error whose one-line message names the file it is about.
pub fn check_load(path: &Path, res: Result<Volume, VolumeError>) {
    match res {
        Ok(v) => {
            let d = v.dims();
            assert!(d.iter().all(|&n| n > 0), "zero dim {d:?}");
            assert_eq!(v.samples().len(), d[0] * d[1] * d[2], "sample count");
            assert!(
                v.spacing().iter().all(|s| s.is_finite() && *s > 0.0),
                "spacing {:?}",
                v.spacing()
            );
            assert!(
                v.samples().iter().all(|s| s.is_finite()),
                "non-finite sample survived loading"
            );
        }
        Err(e) => {
            let msg = e.to_string();
            let name = path.file_name().unwrap().to_string_lossy();
            assert!(msg.contains(&*name), "error does not name the file: {msg}");
            assert!(!msg.is_empty());
        }
    }
}
