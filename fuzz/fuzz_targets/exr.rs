//! OpenEXR inputs: the input is written to `in.exr` and read as each
//! command reads an EXR — hit positions (`compare`), a colour image
//! (`compare`), a part of a frame (`merge`, then merged on its own). What
//! reads must have channels of the image's size;
//! what does not must say which file. Images over a 16 MiB budget are
//! refused from their headers.
#![no_main]

use libfuzzer_sys::fuzz_target;
use snell::film::HitImage;
use snell::film::merge::{merge, read_part};
use snell::film::metrics::RgbImage;
use snell_fuzz::{MEMORY_LIMIT, limit_memory, put};

fuzz_target!(|data: &[u8]| {
    limit_memory();
    let path = put("in.exr", data);
    let names_file = |msg: String| assert!(msg.contains("in.exr"), "unnamed file: {msg}");
    match HitImage::read_exr_if_hits(&path) {
        Ok(Some((h, _))) => {
            let n = h.width as usize * h.height as usize;
            assert_eq!((h.u.len(), h.v.len(), h.events.len()), (n, n, n));
        }
        Ok(None) => {}
        Err(e) => names_file(e.to_string()),
    }
    match RgbImage::read(&path) {
        Ok(img) => assert_eq!(img.pixels.len(), img.width as usize * img.height as usize),
        Err(e) => names_file(e.to_string()),
    }
    match read_part(&path) {
        Ok(part) => {
            let n = part.width as usize * part.height as usize;
            assert!(part.channels.iter().all(|(_, c)| c.len() == n));
            if let Ok(m) = merge(&[part], MEMORY_LIMIT) {
                let n = m.width as usize * m.height as usize;
                assert!(m.channels.iter().all(|(_, c)| c.len() == n));
            }
        }
        Err(e) => names_file(e.to_string()),
    }
});
