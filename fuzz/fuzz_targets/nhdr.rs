//! Detached NRRD: a `.nhdr` header and its data file. The input is
//! `[len: u16 LE][header: len bytes][data file]`; the data goes to `in.raw`
//! and `in.raw.gz` (the seeds' headers name one of them).
#![no_main]

use libfuzzer_sys::fuzz_target;
use snell_fuzz::{check_load, data_file_is_local, header_and_payload, options, put};

fuzz_target!(|data: &[u8]| {
    let Some((len, header, payload)) = header_and_payload(data) else {
        return;
    };
    if !data_file_is_local(header) {
        return;
    }
    put("in.raw", payload);
    put("in.raw.gz", payload);
    let path = put("in.nhdr", header);
    let allow_nan = len & 1 == 1;
    check_load(&path, snell::volume::load(&path, &options(allow_nan)));
});
