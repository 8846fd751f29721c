//! NIfTI-1 (`.nii`, `.nii.gz`). The first byte chooses the form: odd, the
//! rest is gzip-compressed here first (so mutations reach the header parser
//! behind the decompressor); even, the rest is the file as is.
#![no_main]

use std::io::Write;

use flate2::Compression;
use flate2::write::GzEncoder;
use libfuzzer_sys::fuzz_target;
use snell_fuzz::{check_load, options, put};

fuzz_target!(|data: &[u8]| {
    let Some((&mode, body)) = data.split_first() else {
        return;
    };
    let path = if mode & 1 == 1 {
        let mut gz = GzEncoder::new(Vec::new(), Compression::fast());
        gz.write_all(body).unwrap();
        put("in.nii.gz", &gz.finish().unwrap())
    } else {
        put("in.nii", body)
    };
    check_load(&path, snell::volume::load(&path, &options(mode & 2 == 2)));
});
