//! Detached NRRD: a `.nhdr` header and its data file. The input is
//! `[len: u16 LE][header: len bytes][data file]`; the data goes to `in.raw`
//! and `in.raw.gz` (the seeds' headers name one of them).
#![no_main]

use libfuzzer_sys::fuzz_target;
use snell_fuzz::{check_load, data_file_is_local, options, put};

fuzz_target!(|data: &[u8]| {
    if data.len() < 2 {
        return;
    }
    let len = u16::from_le_bytes([data[0], data[1]]) as usize;
    let rest = &data[2..];
    let (header, payload) = rest.split_at(len.min(rest.len()));
    if !data_file_is_local(header) {
        return;
    }
    put("in.raw", payload);
    put("in.raw.gz", payload);
    let path = put("in.nhdr", header);
    let allow_nan = len & 1 == 1;
    check_load(&path, snell::volume::load(&path, &options(allow_nan)));
});
