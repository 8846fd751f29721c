//! MetaImage (`.mha`, `.mhd`). The input is `[len: u16 LE][header: len
//! bytes][payload]`; it is loaded twice: as `in.mha`, the header with the
//! payload after it, and as `in.mhd`, the header alone with the payload in
//! `in.raw` (the seeds' detached headers name it).
#![no_main]

use libfuzzer_sys::fuzz_target;
use snell_fuzz::{check_load, header_and_payload, metaimage_file_is_local, options, put};

fuzz_target!(|data: &[u8]| {
    let Some((len, header, payload)) = header_and_payload(data) else {
        return;
    };
    if !metaimage_file_is_local(header) {
        return;
    }
    let allow_nan = len & 1 == 1;
    let mha = put("in.mha", &[header, payload].concat());
    check_load(&mha, snell::volume::load(&mha, &options(allow_nan)));
    put("in.raw", payload);
    let mhd = put("in.mhd", header);
    check_load(&mhd, snell::volume::load(&mhd, &options(allow_nan)));
});
