//! Headerless raw volumes: the options a user gives (`--dims`, `--type`,
//! `--endian`, `--spacing`, `--offset`) decoded from the input's first 23
//! bytes, the file from the rest.
//!
//! Layout: dims 3 × u16 LE, type u8 (mod 9: the 8 types, or a name the
//! parser must refuse), endian u8, offset u16 LE, spacing 3 × f32 LE
//! (any bits: zero, negative, NaN), allow-nan u8, then the file.
#![no_main]

use libfuzzer_sys::fuzz_target;
use snell::volume::{Endian, LoadOptions, RawSpec, SampleType};
use snell_fuzz::{check_load, options, put};

const TYPES: [&str; 9] = ["u8", "i8", "u16", "i16", "u32", "i32", "f32", "f64", "u128"];

fuzz_target!(|data: &[u8]| {
    if data.len() < 23 {
        return;
    }
    let u16_at = |i: usize| u16::from_le_bytes([data[i], data[i + 1]]);
    let f32_at = |i: usize| f32::from_le_bytes(data[i..i + 4].try_into().unwrap());
    let dims = [u16_at(0), u16_at(2), u16_at(4)].map(usize::from);
    let path = put("in.raw", &data[23..]);
    let Some(sample_type) = SampleType::parse(TYPES[data[6] as usize % TYPES.len()]) else {
        return;
    };
    let endian = Endian::parse(if data[7] & 1 == 1 { "big" } else { "little" }).unwrap();
    let spec = RawSpec {
        dims,
        sample_type,
        endian,
        offset: u16_at(8) as u64,
        spacing: [f32_at(10), f32_at(14), f32_at(18)].map(f64::from),
    };
    let opts = LoadOptions {
        raw: Some(spec),
        ..options(data[22] & 1 == 1)
    };
    check_load(&path, snell::volume::load(&path, &opts));
});
