//! Attached NRRD (`.nrrd`): header and data in one file, raw or gzip.
#![no_main]

use libfuzzer_sys::fuzz_target;
use snell_fuzz::{check_load, data_file_is_local, options, put};

fuzz_target!(|data: &[u8]| {
    if !data_file_is_local(data) {
        return;
    }
    let path = put("in.nrrd", data);
    let allow_nan = data.last().is_some_and(|b| b & 1 == 1);
    check_load(&path, snell::volume::load(&path, &options(allow_nan)));
});
