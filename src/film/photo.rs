//! Photographs (PNG, JPEG, or any format the `image` crate recognises by
//! its bytes) read as RGB images in `[0, 1]`: the one path for a scene's
//! backdrop and for the colour images `compare` reads. The size in the
//! header is checked against the memory limit before anything is decoded,
//! and a JPEG must reach its end-of-image marker.

use std::path::Path;

use super::metrics::RgbImage;
use crate::volume::limits::{default_memory_limit, human_bytes};

/// Largest photograph read, in pixels (2^28: 16384 × 16384).
pub const MAX_PIXELS: u64 = 1 << 28;

/// What [`read`] says of bytes of no format it reads (a backdrop reads only
/// these; `compare` reads EXR too, by the file's name, and says so).
pub const NOT_AN_IMAGE: &str = "not a PNG or JPEG image";

/// Reads the photograph at `path`; the error says why, and the caller
/// names the file.
pub fn read(path: &Path) -> Result<RgbImage, String> {
    // Read once: the end-of-image check, the size and the decode all look
    // at these bytes.
    let bytes = crate::input::read(path).map_err(|e| e.to_string())?;
    let limit = default_memory_limit();
    let reader = || {
        let mut r = image::ImageReader::new(std::io::Cursor::new(&bytes[..]))
            .with_guessed_format()
            .map_err(|e| e.to_string())?;
        // The decoder's own allocations under the same limit (the crate's
        // default is 512 MiB whatever the limit).
        let mut limits = image::Limits::default();
        limits.max_alloc = Some(limit);
        r.limits(limits);
        Ok::<_, String>(r)
    };
    let (w, h) = reader()?.into_dimensions().map_err(|e| match e {
        // The image crate's words for bytes it knows no format of.
        image::ImageError::Unsupported(u)
            if matches!(u.kind(), image::error::UnsupportedErrorKind::Format(_)) =>
        {
            NOT_AN_IMAGE.to_string()
        }
        e => e.to_string(),
    })?;
    let pixels = w as u64 * h as u64;
    if pixels == 0 || pixels > MAX_PIXELS {
        return Err(format!(
            "image size {w}x{h} not supported (1 to {MAX_PIXELS} pixels)"
        ));
    }
    // Decoding holds the decoded image (up to 8 bytes a pixel, 16-bit
    // RGBA), its float copy and the pixels (12 each): 32 bytes a pixel by
    // those buffers' sizes (the decoder's own scratch not counted), from a
    // file that may be a few kilobytes.
    let need = pixels * 32;
    if need > limit {
        return Err(format!(
            "a {w}x{h} image needs about {} of memory to decode, over the limit of {}; use a smaller image or raise the limit (--memory-limit or SNELL_MEMORY_LIMIT)",
            human_bytes(need),
            human_bytes(limit)
        ));
    }
    check_jpeg_end(&bytes)?;
    let img = reader()?.decode().map_err(|e| e.to_string())?.to_rgb32f();
    Ok(RgbImage {
        width: img.width(),
        height: img.height(),
        pixels: img.pixels().map(|p| p.0).collect(),
    })
}

/// A JPEG cut short decodes without complaint (the missing rows come out
/// grey), so its markers are walked from the start to the end-of-image
/// marker that closes the image: segments by their lengths, entropy-coded
/// data byte by byte. What follows that marker (a phone's motion-photo
/// video, a trailer) is not looked at. Files that are not JPEGs pass.
fn check_jpeg_end(bytes: &[u8]) -> Result<(), String> {
    if !bytes.starts_with(&[0xFF, 0xD8]) {
        return Ok(());
    }
    if jpeg_has_end(bytes) {
        Ok(())
    } else {
        Err("JPEG without its end-of-image marker (a truncated file?)".into())
    }
}

/// Whether the JPEG in `b` (starting with SOI) reaches its EOI marker.
fn jpeg_has_end(b: &[u8]) -> bool {
    let mut i = 2;
    let mut in_scan = false;
    while i + 1 < b.len() {
        if b[i] != 0xFF {
            if !in_scan {
                return false; // not at a marker outside entropy-coded data
            }
            i += 1;
            continue;
        }
        let m = b[i + 1];
        match m {
            // Stuffed zero, restart markers, fill bytes: still in the scan.
            0x00 | 0xD0..=0xD7 | 0xFF if in_scan => i += if m == 0xFF { 1 } else { 2 },
            0xD9 => return true,
            0xFF => i += 1,
            0x01 | 0xD0..=0xD7 => i += 2,
            _ => {
                // A segment with its length; SOS starts entropy-coded data.
                if i + 3 >= b.len() {
                    return false;
                }
                let len = u16::from_be_bytes([b[i + 2], b[i + 3]]) as usize;
                if len < 2 {
                    return false;
                }
                i += 2 + len;
                in_scan = m == 0xDA;
            }
        }
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jpeg_end_is_found_past_segments_and_scans() {
        let jpeg = std::fs::read(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/photo.jpg"),
        )
        .unwrap();
        assert!(jpeg_has_end(&jpeg));
        // Data after the image (a motion photo's video) does not matter.
        let mut trailed = jpeg.clone();
        trailed.extend(std::iter::repeat_n(0x42, 100_000));
        assert!(jpeg_has_end(&trailed));
        // Cut anywhere before its end, it is refused.
        for cut in [4, 100, jpeg.len() / 3, jpeg.len() / 2, jpeg.len() - 2] {
            assert!(!jpeg_has_end(&jpeg[..cut]), "cut at {cut}");
        }
    }
}
