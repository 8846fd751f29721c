//! Opening the files snell reads. Every input must be a regular file:
//! opening a FIFO that has no writer waits forever, and the readers map,
//! seek or re-read bytes that a socket or device does not hold as a file
//! does. The file is opened without waiting and then looked at, so such
//! an input is refused at once with a message that says why.

use std::fs::File;
use std::io;
use std::path::Path;

/// Opens `path` for reading if it is a regular file (symbolic links
/// followed).
pub fn open(path: &Path) -> io::Result<File> {
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        // No effect on a regular file's reads or maps.
        options.custom_flags(libc::O_NONBLOCK);
    }
    let file = options.open(path)?;
    let meta = file.metadata()?;
    if meta.is_dir() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "is a directory",
        ));
    }
    if !meta.is_file() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "not a regular file (a FIFO, socket or device); inputs are read from files",
        ));
    }
    Ok(file)
}

/// Whether `path`'s name ends in `.ext` in any case (`.EXR` too): the
/// readers that choose a format by name, or word a message by it, ask this.
pub fn has_extension(path: &Path, ext: &str) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case(ext))
}

/// Reads a whole input file as UTF-8 text (a scene).
pub fn read_to_string(path: &Path) -> io::Result<String> {
    let mut text = String::new();
    io::Read::read_to_string(&mut open(path)?, &mut text)?;
    Ok(text)
}

/// Reads a whole input file.
pub fn read(path: &Path) -> io::Result<Vec<u8>> {
    let mut bytes = Vec::new();
    io::Read::read_to_end(&mut open(path)?, &mut bytes)?;
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_directories_and_devices_and_reads_files() {
        let dir = std::env::temp_dir();
        assert!(open(&dir).unwrap_err().to_string().contains("directory"));
        let e = open(Path::new("/dev/zero")).unwrap_err();
        assert!(e.to_string().contains("not a regular file"), "{e}");
        let p = dir.join(format!("snell-input-{}.txt", std::process::id()));
        std::fs::write(&p, "text").unwrap();
        assert_eq!(read_to_string(&p).unwrap(), "text");
        assert_eq!(read(&p).unwrap(), b"text");
        std::fs::remove_file(&p).unwrap();
    }
}
