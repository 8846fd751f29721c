//! Atomic file output: write to a temporary file beside the target, sync, then
//! rename over it. A failure (full disk, bad data, interrupted run) never
//! leaves a partial file under the target's name.
//!
//! A command with several outputs (an image, its hits, its stats) can hold
//! the renames back ([`hold`]) until every output is written, so that a
//! failure on the last leaves none of them; and a signal that ends the
//! process removes the temporary files first ([`discard_and_close`]).

use std::fs::{self, File};
use std::io::{self, BufWriter};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

static COUNTER: AtomicU64 = AtomicU64::new(0);

/// The process's temporary files and held renames.
struct Pending {
    /// Temporary files that exist now: being written, or written and held.
    live: Vec<PathBuf>,
    /// Written temporary files and their targets, in the order written,
    /// while a [`Held`] guard lives.
    held: Vec<(PathBuf, PathBuf)>,
    /// The thread whose writes are held: the command's own (writes from
    /// other threads, and other tests of the same binary, go straight on).
    holding: Option<std::thread::ThreadId>,
    /// Set when the process is ending on a signal: no new file is begun.
    closing: bool,
}

static PENDING: Mutex<Pending> = Mutex::new(Pending {
    live: Vec::new(),
    held: Vec::new(),
    holding: None,
    closing: false,
});

fn pending() -> std::sync::MutexGuard<'static, Pending> {
    // A panic elsewhere while holding the lock leaves the lists usable.
    PENDING.lock().unwrap_or_else(|e| e.into_inner())
}

/// Holds back this thread's [`write_atomic`] renames until [`Held::commit`]:
/// the outputs stay temporary files beside their targets. Dropped without a
/// commit (the command failed), the guard removes them, so a command leaves
/// all its outputs or none. Only for commands that do not read their own
/// outputs back before they end.
#[must_use = "dropping the guard discards the held outputs"]
pub struct Held(());

pub fn hold() -> Held {
    pending().holding = Some(std::thread::current().id());
    Held(())
}

impl Held {
    /// Renames every held file onto its target, in the order written, and
    /// goes on holding the next ones (a turntable commits frame by frame).
    ///
    /// A rename that fails (a target's directory made read-only meanwhile,
    /// say) undoes the ones before it: each target's previous file is kept
    /// under a temporary hard link until every rename has succeeded, and put
    /// back (a target that did not exist is removed), so the outputs still
    /// appear all or none. Where the file system has no hard links, a
    /// replaced file cannot be put back and stays replaced.
    pub fn commit(&self) -> io::Result<()> {
        // Held for the whole commit, so a signal's clean-up waits for it.
        let mut p = pending();
        let held = std::mem::take(&mut p.held);
        let mut renamed: Vec<(&Path, Previous)> = Vec::new();
        let mut failure = None;
        for (tmp, target) in &held {
            if failure.is_none() {
                let previous = Previous::keep(target);
                match fs::rename(tmp, target) {
                    Ok(()) => renamed.push((target, previous)),
                    Err(e) => {
                        previous.discard();
                        failure = Some(io::Error::new(
                            e.kind(),
                            format!("{}: {e}", target.display()),
                        ));
                    }
                }
            }
            if failure.is_some() {
                let _ = fs::remove_file(tmp);
            }
            p.live.retain(|l| l != tmp);
        }
        match failure {
            None => {
                for (_, previous) in renamed {
                    previous.discard();
                }
                Ok(())
            }
            Some(e) => {
                for (target, previous) in renamed.into_iter().rev() {
                    previous.restore(target);
                }
                Err(e)
            }
        }
    }
}

/// What a committed rename replaced, until the whole commit succeeds.
enum Previous {
    /// The target did not exist.
    Absent,
    /// The target's previous file, hard-linked under a temporary name.
    Kept(PathBuf),
    /// The target existed but could not be linked.
    Lost,
}

impl Previous {
    fn keep(target: &Path) -> Previous {
        if fs::symlink_metadata(target).is_err() {
            return Previous::Absent;
        }
        match temp_path(target) {
            Ok(link) if fs::hard_link(target, &link).is_ok() => Previous::Kept(link),
            _ => Previous::Lost,
        }
    }

    fn discard(self) {
        if let Previous::Kept(link) = self {
            let _ = fs::remove_file(link);
        }
    }

    /// Best effort: the commit's error is what the caller reports.
    fn restore(self, target: &Path) {
        match self {
            Previous::Absent => {
                let _ = fs::remove_file(target);
            }
            Previous::Kept(link) => {
                let _ = fs::rename(link, target);
            }
            Previous::Lost => {}
        }
    }
}

impl Drop for Held {
    fn drop(&mut self) {
        let mut p = pending();
        p.holding = None;
        for (tmp, _) in std::mem::take(&mut p.held) {
            let _ = fs::remove_file(&tmp);
            p.live.retain(|l| *l != tmp);
        }
    }
}

/// Removes every temporary file this process has begun and not renamed,
/// and refuses new ones: for a signal handler, just before the process
/// exits.
pub fn discard_and_close() {
    let mut p = pending();
    p.closing = true;
    p.held.clear();
    for tmp in std::mem::take(&mut p.live) {
        let _ = fs::remove_file(&tmp);
    }
}

fn temp_path(path: &Path) -> io::Result<PathBuf> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let name = path.file_name().ok_or_else(|| {
        io::Error::new(io::ErrorKind::InvalidInput, "output path has no file name")
    })?;
    Ok(dir.join(format!(
        ".{}.{}.{}.tmp",
        name.to_string_lossy(),
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    )))
}

/// Refuses a target that exists and is not a regular file: the rename would
/// replace a device, FIFO or socket by a plain file. Commands call it before
/// their work, [`write_atomic`] before every write.
pub fn check_target(path: &Path) -> io::Result<()> {
    match fs::metadata(path) {
        Ok(m) if m.is_dir() => Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "is a directory",
        )),
        Ok(m) if !m.is_file() => Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "is not a regular file (a device, FIFO or socket)",
        )),
        Err(e) if is_link_loop(&e) => Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "is a loop of symbolic links",
        )),
        Ok(_) if !may_write(path) => Err(io::Error::new(
            io::ErrorKind::PermissionDenied,
            "is read-only: its permissions refuse writing it (as a shell's `>` would be refused)",
        )),
        _ => Ok(()),
    }
}

/// Whether this process may write the existing file `path`: the rename
/// would replace a file whose mode forbids writing it, which is the
/// file's owner saying not to (root may write anything, as with `>`).
#[cfg(unix)]
fn may_write(path: &Path) -> bool {
    use std::os::unix::ffi::OsStrExt;
    let Ok(c) = std::ffi::CString::new(path.as_os_str().as_bytes()) else {
        return true;
    };
    // SAFETY: `c` is a valid NUL-terminated string for the call's duration.
    unsafe { libc::access(c.as_ptr(), libc::W_OK) == 0 }
}

#[cfg(not(unix))]
fn may_write(path: &Path) -> bool {
    fs::metadata(path).is_ok_and(|m| !m.permissions().readonly())
}

#[cfg(unix)]
fn is_link_loop(e: &io::Error) -> bool {
    e.raw_os_error() == Some(libc::ELOOP)
}

#[cfg(not(unix))]
fn is_link_loop(_: &io::Error) -> bool {
    false
}

/// Creates and removes a temporary file where [`write_atomic`] will write
/// `path`'s (beside the file a symbolic link names): a command checks at
/// its start that it will be able to write its output, not after its work.
pub fn check_writable(path: &Path) -> io::Result<()> {
    let probe = temp_path(&written_path(path))?;
    let made = begin_temp(&probe).and_then(|_| fs::remove_file(&probe));
    pending().live.retain(|l| *l != probe);
    made
}

/// Creates the temporary file `tmp`, registered first so that a signal's
/// clean-up cannot miss it; refused once the process is ending on a
/// signal. The caller takes it off the list when it is renamed or removed.
fn begin_temp(tmp: &Path) -> io::Result<File> {
    let mut p = pending();
    if p.closing {
        return Err(io::Error::new(io::ErrorKind::Interrupted, "interrupted"));
    }
    p.live.push(tmp.to_path_buf());
    fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(tmp)
}

/// The file a write of `path` replaces: through a symbolic link to the
/// file it names, as other tools write, rather than replacing the link. A
/// dangling link is followed to the file it names, which the write creates
/// (as a shell's `>` does); a loop of links is left as it is, for
/// [`check_target`] to refuse.
pub fn written_path(path: &Path) -> PathBuf {
    let mut at = path.to_path_buf();
    // Linux's own limit on links followed in one lookup.
    for _ in 0..40 {
        match fs::symlink_metadata(&at) {
            Ok(m) if m.file_type().is_symlink() => {
                if let Ok(real) = fs::canonicalize(&at) {
                    return real;
                }
                let Ok(next) = fs::read_link(&at) else {
                    return at;
                };
                at = match at.parent() {
                    Some(dir) if next.is_relative() => dir.join(next),
                    _ => next,
                };
            }
            _ => return at,
        }
    }
    path.to_path_buf()
}

/// Writes `path` through `write`, atomically.
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>,
) -> io::Result<()> {
    // Never over a device, FIFO or socket, which the rename would replace
    // by a plain file.
    let path = &written_path(path);
    check_target(path)?;
    let tmp = temp_path(path)?;
    let written = begin_temp(&tmp).and_then(|file| {
        let mut out = BufWriter::new(file);
        write(&mut out)
            .and_then(|()| out.into_inner().map_err(|e| e.into_error()))
            .and_then(|file| file.sync_all())
    });
    let mut p = pending();
    let held = p.holding == Some(std::thread::current().id());
    let result = written.and_then(|()| {
        if held {
            p.held.push((tmp.clone(), path.to_path_buf()));
            return Ok(());
        }
        fs::rename(&tmp, path)
    });
    if result.is_err() {
        let _ = fs::remove_file(&tmp); // best effort; the write error is what matters
    }
    if result.is_err() || !held {
        p.live.retain(|l| *l != tmp);
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    #[test]
    fn failure_leaves_nothing() {
        let dir = std::env::temp_dir().join(format!("snell-atomic-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let target = dir.join("out.bin");
        write_atomic(&target, |w| w.write_all(b"ok")).unwrap();
        assert_eq!(fs::read(&target).unwrap(), b"ok");
        let err = write_atomic(&target, |w| {
            w.write_all(b"partial")?;
            Err(io::Error::other("boom"))
        });
        assert!(err.is_err());
        assert_eq!(fs::read(&target).unwrap(), b"ok", "old file untouched");
        assert_eq!(fs::read_dir(&dir).unwrap().count(), 1, "no temp file left");
        fs::remove_dir_all(&dir).unwrap();
    }

    /// A write through a symbolic link replaces the file it names and keeps
    /// the link; a dangling link's file is created, as a shell's `>` does.
    #[cfg(unix)]
    #[test]
    fn symbolic_links_are_written_through() {
        let dir = std::env::temp_dir().join(format!("snell-links-{}", std::process::id()));
        fs::create_dir_all(dir.join("real")).unwrap();
        std::os::unix::fs::symlink("real/a.bin", dir.join("a.bin")).unwrap();
        std::os::unix::fs::symlink("b.bin", dir.join("real/b-link.bin")).unwrap();
        std::os::unix::fs::symlink("real/b-link.bin", dir.join("b.bin")).unwrap();
        for (link, file) in [("a.bin", "real/a.bin"), ("b.bin", "real/b.bin")] {
            write_atomic(&dir.join(link), |w| w.write_all(link.as_bytes())).unwrap();
            assert_eq!(fs::read(dir.join(file)).unwrap(), link.as_bytes());
            let m = fs::symlink_metadata(dir.join(link)).unwrap();
            assert!(m.file_type().is_symlink(), "{link} is still a link");
        }
        // A loop is refused, not followed forever nor replaced.
        std::os::unix::fs::symlink("loop2", dir.join("loop1")).unwrap();
        std::os::unix::fs::symlink("loop1", dir.join("loop2")).unwrap();
        assert_eq!(written_path(&dir.join("loop1")), dir.join("loop1"));
        let err = write_atomic(&dir.join("loop1"), |w| w.write_all(b"x")).unwrap_err();
        assert!(err.to_string().contains("loop"), "{err}");
        assert!(
            fs::symlink_metadata(dir.join("loop1"))
                .unwrap()
                .file_type()
                .is_symlink()
        );
        fs::remove_dir_all(&dir).unwrap();
    }

    /// A file whose mode forbids writing it is not replaced (unless the
    /// process may write anything, as root may).
    #[cfg(unix)]
    #[test]
    fn read_only_files_are_not_replaced() {
        use std::os::unix::fs::PermissionsExt;
        let dir = std::env::temp_dir().join(format!("snell-ro-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let target = dir.join("keep.png");
        fs::write(&target, b"old").unwrap();
        fs::set_permissions(&target, fs::Permissions::from_mode(0o444)).unwrap();
        let result = write_atomic(&target, |w| w.write_all(b"new"));
        // SAFETY: geteuid has no preconditions.
        if unsafe { libc::geteuid() } == 0 {
            result.unwrap();
            assert_eq!(fs::read(&target).unwrap(), b"new");
        } else {
            let err = result.unwrap_err();
            assert!(err.to_string().contains("read-only"), "{err}");
            assert_eq!(fs::read(&target).unwrap(), b"old");
        }
        assert_eq!(
            fs::read_dir(&dir).unwrap().count(),
            1,
            "no temporary file left"
        );
        fs::remove_dir_all(&dir).unwrap();
    }

    /// Held outputs appear together on commit, and not at all when the
    /// guard is dropped without one.
    #[test]
    fn held_outputs_appear_together_or_not_at_all() {
        let dir = std::env::temp_dir().join(format!("snell-held-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let names = |d: &Path| {
            let mut v: Vec<String> = fs::read_dir(d)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            v.sort();
            v
        };
        {
            let held = hold();
            write_atomic(&dir.join("a.png"), |w| w.write_all(b"a")).unwrap();
            write_atomic(&dir.join("b.exr"), |w| w.write_all(b"b")).unwrap();
            assert!(!dir.join("a.png").exists(), "held back");
            assert_eq!(names(&dir).len(), 2, "two temporary files");
            held.commit().unwrap();
            assert_eq!(names(&dir), ["a.png", "b.exr"]);
            write_atomic(&dir.join("c.json"), |w| w.write_all(b"c")).unwrap();
            // Dropped without a commit: c.json's temporary file goes.
        }
        assert_eq!(names(&dir), ["a.png", "b.exr"]);
        assert_eq!(fs::read(dir.join("b.exr")).unwrap(), b"b");
        assert!(!pending().live.iter().any(|l| l.starts_with(&dir)));

        // A rename that fails undoes the ones before it: a.png gets its
        // previous file back, new.txt (which did not exist) goes, and the
        // temporary files and links go. (Here the last target became a
        // directory after its write, onto which a file cannot be renamed.)
        {
            let held = hold();
            write_atomic(&dir.join("a.png"), |w| w.write_all(b"a2")).unwrap();
            write_atomic(&dir.join("new.txt"), |w| w.write_all(b"n")).unwrap();
            write_atomic(&dir.join("d"), |w| w.write_all(b"d")).unwrap();
            fs::create_dir(dir.join("d")).unwrap();
            let e = held.commit().unwrap_err();
            assert!(e.to_string().contains("d:"), "{e}");
        }
        assert_eq!(names(&dir), ["a.png", "b.exr", "d"]);
        assert_eq!(fs::read(dir.join("a.png")).unwrap(), b"a");
        assert!(!pending().live.iter().any(|l| l.starts_with(&dir)));
        fs::remove_dir_all(&dir).unwrap();
    }
}
