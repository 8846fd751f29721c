//! Volume file readers against the real data in `shared/data` and against
//! hand-made good and bad files.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use flate2::Compression;
use flate2::write::GzEncoder;
use snell::volume::nrrd::Encoding;
use snell::volume::*;

// ---------------------------------------------------------------------------
// Helpers

/// A fresh directory under the system temp dir, removed when dropped.
struct TempDir(PathBuf);

impl TempDir {
    fn new(tag: &str) -> TempDir {
        static COUNTER: AtomicU64 = AtomicU64::new(0);
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0);
        let dir = std::env::temp_dir().join(format!(
            "snell-volume-io-{tag}-{}-{nanos}-{}",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        fs::create_dir_all(&dir).unwrap();
        TempDir(dir)
    }

    fn path(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }

    fn write(&self, name: &str, bytes: &[u8]) -> PathBuf {
        let p = self.path(name);
        if let Some(parent) = p.parent() {
            fs::create_dir_all(parent).unwrap();
        }
        fs::write(&p, bytes).unwrap();
        p
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = fs::remove_dir_all(&self.0);
    }
}

fn data_dir() -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data");
    assert!(
        dir.is_dir(),
        "test data directory {} does not exist: the real volumes live in shared/data next to the project checkout (CI provides it)",
        dir.display()
    );
    dir
}

fn opts() -> LoadOptions {
    LoadOptions::default()
}

/// The error of `res`, after checking that its message names `path`.
fn error_naming(res: Result<Volume, VolumeError>, path: &Path) -> VolumeError {
    let err = match res {
        Ok(v) => panic!(
            "expected an error for {}, got a {:?} volume",
            path.display(),
            v.dims()
        ),
        Err(e) => e,
    };
    let msg = err.to_string();
    assert!(
        msg.contains(&path.display().to_string()),
        "error message does not name {}: {msg}",
        path.display()
    );
    err
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut enc = GzEncoder::new(Vec::new(), Compression::default());
    enc.write_all(bytes).unwrap();
    enc.finish().unwrap()
}

/// Bytes that do not compress, so a cut gzip stream loses real data.
fn noise(len: usize) -> Vec<u8> {
    let mut state = 0x2545_f491_4f6c_dd1du64;
    (0..len)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 24) as u8
        })
        .collect()
}

/// An attached NRRD: header lines (without magic and blank line) plus data.
fn nrrd_bytes(fields: &str, data: &[u8]) -> Vec<u8> {
    let mut out = format!("NRRD0004\n{fields}\n").into_bytes();
    out.extend_from_slice(data);
    out
}

fn bits(samples: &[f32]) -> Vec<u32> {
    samples.iter().map(|v| v.to_bits()).collect()
}

// ---------------------------------------------------------------------------
// Real data (shared/data/README.md)

const REAL_NRRD: &[(&str, [usize; 3], SampleType, [f64; 3])] = &[
    (
        "engine.nrrd",
        [256, 256, 128],
        SampleType::U8,
        [1.0, 1.0, 1.0],
    ),
    (
        "tooth.nrrd",
        [103, 94, 161],
        SampleType::U8,
        [1.0, 1.0, 1.0],
    ),
    (
        "bonsai.nrrd",
        [256, 256, 256],
        SampleType::U8,
        [1.0, 1.0, 1.0],
    ),
    (
        "aneurism.nrrd",
        [256, 256, 256],
        SampleType::U8,
        [1.0, 1.0, 1.0],
    ),
    (
        "lobster.nrrd",
        [301, 324, 56],
        SampleType::U8,
        [1.0, 1.0, 1.4],
    ),
    (
        "boston-teapot.nrrd",
        [256, 256, 178],
        SampleType::U8,
        [1.0, 1.0, 1.0],
    ),
    (
        "cranium-ct.nrrd",
        [256, 256, 108],
        SampleType::U16,
        [0.957, 0.957, 1.5],
    ),
];
const HEADSQ: &str = "headsq-quarter-ct_64x64x93_u16le.raw";
const MNI: &str = "mni152-2009a-t1.nii.gz";

/// Each real volume's samples as an independent decoder read them (Python's
/// `gzip` and `array`, samples in file order): their sum, their sum weighted
/// by file position modulo 1009 (which a reordering, a byte swap or a lost
/// row changes), and their maximum.
const CONTENTS: [(&str, u64, u64, u32); 9] = [
    ("aneurism.nrrd", 17938365, 9013652071, 255),
    ("bonsai.nrrd", 230038784, 115906682223, 255),
    ("boston-teapot.nrrd", 75147291, 37864678180, 255),
    ("cranium-ct.nrrd", 3100431465, 1562631904384, 4010),
    ("engine.nrrd", 187475057, 94500684194, 255),
    ("lobster.nrrd", 71788564, 36187505402, 255),
    ("tooth.nrrd", 160814065, 81044777229, 255),
    (HEADSQ, 193392317, 97825511278, 3926),
    (MNI, 333468829, 168048120574, 255),
];

fn check_real(vol: &Volume, name: &str, dims: [usize; 3], ty: SampleType, spacing: [f64; 3]) {
    assert_eq!(vol.dims(), dims, "{name} dims");
    assert_eq!(vol.native_type(), ty, "{name} type");
    for (got, want) in vol.spacing().iter().zip(spacing) {
        // The README rounds to three decimals (0.957 for 0.9570312).
        assert!(
            (got - want).abs() < 5e-4,
            "{name} spacing {:?}",
            vol.spacing()
        );
    }
    assert_eq!(vol.replaced_nonfinite, 0);
    let (lo, hi) = vol
        .samples()
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    let type_max = match ty {
        SampleType::U8 => 255.0,
        SampleType::U16 => 65535.0,
        _ => f32::MAX,
    };
    assert!(
        lo >= 0.0 && hi <= type_max && hi > lo,
        "{name} range {lo}..{hi}"
    );
    let &(_, sum, weighted, max) = CONTENTS.iter().find(|c| c.0 == name).unwrap();
    let (mut s, mut w) = (0u64, 0u64);
    for (i, &v) in vol.samples().iter().enumerate() {
        assert!(v.fract() == 0.0 && v >= 0.0, "{name}: sample {i} is {v}");
        s += v as u64;
        w += v as u64 * (i % 1009) as u64;
    }
    assert_eq!((s, w, hi as u32), (sum, weighted, max), "{name}: contents");
}

fn load_real_nrrd(name: &str) {
    let &(_, dims, ty, spacing) = REAL_NRRD.iter().find(|r| r.0 == name).unwrap();
    let path = data_dir().join(name);
    let vol = load(&path, &opts()).unwrap_or_else(|e| panic!("{e}"));
    check_real(&vol, name, dims, ty, spacing);
}

#[test]
fn real_engine() {
    load_real_nrrd("engine.nrrd");
}
#[test]
fn real_tooth() {
    load_real_nrrd("tooth.nrrd");
}
#[test]
fn real_bonsai() {
    load_real_nrrd("bonsai.nrrd");
}
#[test]
fn real_aneurism() {
    load_real_nrrd("aneurism.nrrd");
}
#[test]
fn real_lobster() {
    load_real_nrrd("lobster.nrrd");
}
#[test]
fn real_boston_teapot() {
    load_real_nrrd("boston-teapot.nrrd");
}
#[test]
fn real_cranium_ct() {
    load_real_nrrd("cranium-ct.nrrd");
}

#[test]
fn real_headsq_raw() {
    let path = data_dir().join(HEADSQ);
    let spec = RawSpec {
        dims: [64, 64, 93],
        sample_type: SampleType::U16,
        endian: Endian::Little,
        spacing: [3.2, 3.2, 1.5],
        offset: 0,
    };
    let via_raw = raw::read(&path, &spec, &opts()).unwrap_or_else(|e| panic!("{e}"));
    check_real(
        &via_raw,
        HEADSQ,
        [64, 64, 93],
        SampleType::U16,
        [3.2, 3.2, 1.5],
    );
    let o = LoadOptions {
        raw: Some(spec.clone()),
        ..opts()
    };
    let via_load = load(&path, &o).unwrap();
    assert_eq!(bits(via_load.samples()), bits(via_raw.samples()));

    // One slice too many in --dims: truncated. One too few: a mismatch that
    // suggests the dims the length fits.
    let more = RawSpec {
        dims: [64, 64, 94],
        ..spec.clone()
    };
    let e = error_naming(raw::read(&path, &more, &opts()), &path);
    assert!(matches!(e, VolumeError::Truncated { .. }), "{e}");
    let fewer = RawSpec {
        dims: [64, 64, 92],
        ..spec
    };
    let e = error_naming(raw::read(&path, &fewer, &opts()), &path);
    let msg = e.to_string();
    assert!(matches!(e, VolumeError::Format { .. }), "{e}");
    assert!(msg.contains("761856") && msg.contains("64x64x93"), "{msg}");
}

#[test]
fn real_mni152_nifti() {
    let path = data_dir().join(MNI);
    let vol = load(&path, &opts()).unwrap_or_else(|e| panic!("{e}"));
    check_real(&vol, MNI, [197, 233, 189], SampleType::U8, [1.0, 1.0, 1.0]);
}

#[test]
fn real_data_dir_has_no_untested_volume() {
    let mut untested = Vec::new();
    for entry in fs::read_dir(data_dir()).unwrap() {
        let name = entry.unwrap().file_name().to_string_lossy().into_owned();
        let known = REAL_NRRD.iter().any(|r| r.0 == name) || name == HEADSQ || name == MNI;
        if !known && name != "README.md" {
            untested.push(name);
        }
    }
    assert!(
        untested.is_empty(),
        "files in shared/data without a test: {untested:?}"
    );
}

// ---------------------------------------------------------------------------
// NRRD writing and reading back

const ALL_TYPES: [SampleType; 8] = [
    SampleType::U8,
    SampleType::I8,
    SampleType::U16,
    SampleType::I16,
    SampleType::U32,
    SampleType::I32,
    SampleType::F32,
    SampleType::F64,
];

/// Samples exercising each type's extremes (as loading would produce them).
fn samples_for(ty: SampleType, n: usize) -> Vec<f32> {
    let extremes: Vec<f32> = match ty {
        SampleType::U8 => vec![0.0, 1.0, 127.0, 128.0, 254.0, 255.0],
        SampleType::I8 => vec![-128.0, -1.0, 0.0, 1.0, 127.0],
        SampleType::U16 => vec![0.0, 1.0, 32768.0, 65534.0, 65535.0],
        SampleType::I16 => vec![-32768.0, -1.0, 0.0, 1.0, 32767.0],
        SampleType::U32 => vec![0.0, 1.0, 16_777_216.0, u32::MAX as f32, 4_294_967_040.0],
        SampleType::I32 => vec![i32::MIN as f32, -1.0, 0.0, 16_777_216.0, i32::MAX as f32],
        SampleType::F32 => vec![
            0.0,
            -0.0,
            f32::from_bits(1),
            f32::MIN_POSITIVE,
            f32::MAX,
            f32::MIN,
            0.1,
            -3.25,
        ],
        SampleType::F64 => vec![0.0, -0.0, f32::from_bits(1), f32::MAX, -1e-30, 0.1, 1e30],
    };
    let signed = matches!(
        ty,
        SampleType::I8 | SampleType::I16 | SampleType::I32 | SampleType::F32 | SampleType::F64
    );
    (0..n)
        .map(|i| {
            if i % 2 == 0 {
                extremes[(i / 2) % extremes.len()]
            } else {
                let v = (i * 37 % 120) as f32;
                if signed && i % 4 == 1 { -v } else { v }
            }
        })
        .collect()
}

fn roundtrip(ty: SampleType, encoding: Encoding) {
    let dir = TempDir::new("roundtrip");
    let dims = [5, 4, 3];
    // A spacing with a long decimal expansion must survive the text header.
    let spacing = [0.5, 1.25, 0.1 + 0.857_031_2];
    let samples = samples_for(ty, 60);
    let vol = Volume::new(dims, spacing, ty, samples.clone()).unwrap();
    let path = dir.path(&format!("rt-{ty}.nrrd"));
    nrrd::write(&path, &vol, encoding).unwrap_or_else(|e| panic!("{e}"));
    let entries: Vec<_> = fs::read_dir(&dir.0).unwrap().collect();
    assert_eq!(entries.len(), 1, "temporary file left behind");

    for back in [nrrd::read(&path, &opts()), load(&path, &opts())] {
        let back = back.unwrap_or_else(|e| panic!("{ty} {encoding:?}: {e}"));
        assert_eq!(back.dims(), dims);
        assert_eq!(back.native_type(), ty);
        assert_eq!(
            bits_f64(back.spacing()),
            bits_f64(spacing),
            "{ty} {encoding:?}"
        );
        assert_eq!(bits(back.samples()), bits(&samples), "{ty} {encoding:?}");
    }
}

fn bits_f64(v: [f64; 3]) -> [u64; 3] {
    v.map(f64::to_bits)
}

#[test]
fn nrrd_roundtrip_raw_every_type() {
    for ty in ALL_TYPES {
        roundtrip(ty, Encoding::Raw);
    }
}

#[test]
fn nrrd_roundtrip_gzip_every_type() {
    for ty in ALL_TYPES {
        roundtrip(ty, Encoding::Gzip);
    }
}

#[test]
fn nrrd_roundtrip_ascii_every_type() {
    for ty in ALL_TYPES {
        roundtrip(ty, Encoding::Ascii);
    }
}

/// teem's ascii encoding: values separated by any whitespace or commas, an
/// integer type's values integers in its range; too few is an error, more
/// are left with a warning.
#[test]
fn nrrd_ascii_values() {
    let dir = TempDir::new("ascii");
    let read = |name: &str, ty: &str, text: &str| {
        let path = dir.write(
            name,
            &nrrd_bytes(
                &format!("type: {ty}\ndimension: 3\nsizes: 2 2 1\nencoding: ascii\n"),
                text.as_bytes(),
            ),
        );
        nrrd::read(&path, &opts())
    };
    let vol = read("ok.nrrd", "short", " -3,4\n\t5 ,, 6\n").unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(vol.samples(), &[-3.0, 4.0, 5.0, 6.0]);
    assert!(vol.warnings.is_empty(), "{:?}", vol.warnings);
    let vol = read("more.nrrd", "float", "1 2.5e1 -0.125 7 8 9").unwrap();
    assert_eq!(vol.samples(), &[1.0, 25.0, -0.125, 7.0]);
    assert!(
        vol.warnings[0].contains("2 more values"),
        "{:?}",
        vol.warnings
    );
    let e = read("few.nrrd", "uchar", "1 2 3").unwrap_err();
    assert!(e.to_string().contains("holds 3 values"), "{e}");
    let e = read("range.nrrd", "uchar", "1 2 256 4").unwrap_err();
    assert!(e.to_string().contains("'256'"), "{e}");
    let e = read("frac.nrrd", "int", "1 2 3.5 4").unwrap_err();
    assert!(e.to_string().contains("'3.5'"), "{e}");
    let e = read("nan.nrrd", "double", "1 2 nan 4").unwrap_err();
    assert!(matches!(e, VolumeError::NonFinite { nan: 1, .. }), "{e}");
    // A finite number beyond f32 is not an infinity the file holds.
    let e = read("big.nrrd", "float", "1 1e50 3 4").unwrap_err();
    assert!(
        e.to_string()
            .contains("ascii value 1 ('1e50') is beyond f32's range"),
        "{e}"
    );
    let e = read("big64.nrrd", "double", "1 2 -1e400 4").unwrap_err();
    assert!(
        e.to_string()
            .contains("ascii value 2 ('-1e400') is beyond f64's range"),
        "{e}"
    );
    let e = read("inf.nrrd", "float", "1 -inf 3 4").unwrap_err();
    assert!(matches!(e, VolumeError::NonFinite { inf: 1, .. }), "{e}");
}

/// Data split over files, one slab each (teem's `data file` pattern and
/// `LIST` forms), each with its own skips: the same volume as from one file.
#[test]
fn nrrd_multi_file_data() {
    let dir = TempDir::new("multi");
    let data: Vec<u8> = (0..48u8).collect(); // 4 x 3 x 4 u8
    let want: Vec<f32> = data.iter().map(|&b| b as f32).collect();
    let fields = "NRRD0005\ntype: uint8\ndimension: 3\nsizes: 4 3 4\n";
    for (k, slab) in data.chunks(12).enumerate() {
        // Raw slices behind a line of text, gzip and ascii ones plain.
        let mut raw = b"slice header\n".to_vec();
        raw.extend_from_slice(slab);
        dir.write(&format!("raw/z{:02}.raw", k + 1), &raw);
        dir.write(&format!("gz/z{k}.gz"), &gzip(slab));
        let text: Vec<String> = slab.iter().map(|b| b.to_string()).collect();
        dir.write(&format!("txt-{k}.txt"), text.join(" ").as_bytes());
    }
    let headers = [
        (
            "raw.nhdr",
            "encoding: raw\nline skip: 1\ndata file: raw/z%02d.raw 1 4 1\n".to_string(),
        ),
        (
            "gz.nhdr",
            "encoding: gzip\ndata file: gz/z%d.gz 3 0 -1 2\n".to_string(),
        ),
        (
            "txt.nhdr",
            "encoding: ascii\ndata file: LIST\ntxt-0.txt\ntxt-1.txt\ntxt-2.txt\ntxt-3.txt\n"
                .to_string(),
        ),
    ];
    for (name, rest) in headers {
        let path = dir.write(name, format!("{fields}{rest}").as_bytes());
        let vol = nrrd::read(&path, &opts()).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(vol.dims(), [4, 3, 4], "{name}");
        let mut expect = want.clone();
        if name == "gz.nhdr" {
            // Files 3, 2, 1, 0: the slabs in reverse.
            expect = want.chunks(12).rev().flatten().copied().collect();
        }
        assert_eq!(vol.samples(), &expect[..], "{name}");
        assert!(vol.warnings.is_empty(), "{name}: {:?}", vol.warnings);
    }
    // A missing slice names its file; a short one says which.
    let path = dir.write(
        "missing.nhdr",
        format!("{fields}encoding: raw\ndata file: raw/z%02d.raw 2 5 1\n").as_bytes(),
    );
    let e = error_naming(nrrd::read(&path, &opts()), &path);
    assert!(e.to_string().contains("z05.raw"), "{e}");
    dir.write("cut/c0.raw", &data[..12]);
    dir.write("cut/c1.raw", &data[..5]);
    let path = dir.write(
        "short.nhdr",
        b"NRRD0005\ntype: uint8\ndimension: 3\nsizes: 4 3 2\nencoding: raw\ndata file: cut/c%d.raw 0 1 1\n",
    );
    let e = error_naming(nrrd::read(&path, &opts()), &path);
    assert!(
        matches!(
            e,
            VolumeError::Truncated {
                need: 12,
                got: 5,
                ..
            }
        ) && e.to_string().contains("data file 2 of 2"),
        "{e}"
    );
}

#[test]
fn nrrd_roundtrip_real_volume() {
    let dir = TempDir::new("roundtrip-real");
    let src = load(&data_dir().join("cranium-ct.nrrd"), &opts()).unwrap();
    let path = dir.path("cranium.nrrd");
    nrrd::write(&path, &src, Encoding::Gzip).unwrap();
    let back = nrrd::read(&path, &opts()).unwrap();
    assert_eq!(back.dims(), src.dims());
    assert_eq!(bits_f64(back.spacing()), bits_f64(src.spacing()));
    assert_eq!(back.native_type(), SampleType::U16);
    assert_eq!(back.content_hash(), src.content_hash());
}

/// A real scan written as ITK writes MetaImage files — attached and
/// zlib-compressed with the orientation fields ITK adds, and detached, big
/// endian, in a subfolder behind a header of its own bytes — reads back
/// as the NRRD it came from: the same samples, type and spacing.
#[test]
fn metaimage_reads_a_real_scan_as_itk_writes_it() {
    let dir = TempDir::new("metaimage");
    let src = load(&data_dir().join("cranium-ct.nrrd"), &opts()).unwrap();
    assert_eq!(src.native_type(), SampleType::U16);
    let [nx, ny, nz] = src.dims();
    let [sx, sy, sz] = src.spacing();
    let le: Vec<u8> = src
        .samples()
        .iter()
        .flat_map(|&v| (v as u16).to_le_bytes())
        .collect();
    let be: Vec<u8> = src
        .samples()
        .iter()
        .flat_map(|&v| (v as u16).to_be_bytes())
        .collect();
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), Compression::default());
    z.write_all(&le).unwrap();
    let packed = z.finish().unwrap();
    let header = |fields: &str, file: &str| {
        format!(
            "ObjectType = Image\nNDims = 3\n{fields}TransformMatrix = 1 0 0 0 1 0 0 0 1\nOffset = 0 0 0\nCenterOfRotation = 0 0 0\nAnatomicalOrientation = RAI\nElementSpacing = {sx} {sy} {sz}\nDimSize = {nx} {ny} {nz}\nElementType = MET_USHORT\nElementDataFile = {file}\n"
        )
    };
    let attached = [
        header(
            &format!(
                "BinaryData = True\nBinaryDataByteOrderMSB = False\nCompressedData = True\nCompressedDataSize = {}\n",
                packed.len()
            ),
            "LOCAL",
        )
        .into_bytes(),
        packed,
    ]
    .concat();
    let mha = dir.write("cranium.mha", &attached);
    dir.write(
        "data/cranium.raw",
        &[b"ITK-ish preamble".as_slice(), &be].concat(),
    );
    let mhd = dir.write(
        "cranium.mhd",
        header(
            "BinaryDataByteOrderMSB = True\nHeaderSize = 16\n",
            "data/cranium.raw",
        )
        .as_bytes(),
    );
    for path in [mha, mhd] {
        let back = load(&path, &opts()).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(back.dims(), src.dims());
        assert_eq!(bits_f64(back.spacing()), bits_f64(src.spacing()));
        assert_eq!(back.native_type(), SampleType::U16);
        assert_eq!(
            back.content_hash(),
            src.content_hash(),
            "{}",
            path.display()
        );
        assert!(back.warnings.is_empty(), "{:?}", back.warnings);
    }
}

#[test]
fn nrrd_write_replaces_existing_file_and_fails_cleanly() {
    let dir = TempDir::new("write-fail");
    let vol = Volume::new([2, 2, 2], [1.0; 3], SampleType::U8, vec![7.0; 8]).unwrap();
    let path = dir.write("out.nrrd", b"old contents");
    nrrd::write(&path, &vol, Encoding::Raw).unwrap();
    assert_eq!(nrrd::read(&path, &opts()).unwrap().samples(), &[7.0; 8]);

    // Renaming onto a directory fails: the error names the path and no
    // temporary file stays behind.
    let blocked = dir.path("blocked.nrrd");
    fs::create_dir(&blocked).unwrap();
    fs::write(blocked.join("keep"), b"x").unwrap();
    let err = nrrd::write(&blocked, &vol, Encoding::Gzip).unwrap_err();
    assert!(
        err.to_string().contains(&blocked.display().to_string()),
        "{err}"
    );
    let mut names: Vec<String> = fs::read_dir(&dir.0)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, vec!["blocked.nrrd", "out.nrrd"]);

    let missing_dir = dir.path("no/such/dir/out.nrrd");
    let err = nrrd::write(&missing_dir, &vol, Encoding::Raw).unwrap_err();
    assert!(
        err.to_string().contains(&missing_dir.display().to_string()),
        "{err}"
    );
}

// ---------------------------------------------------------------------------
// NRRD variants

#[test]
fn nhdr_detached_raw_pair_big_endian() {
    let dir = TempDir::new("nhdr-pair");
    let values: [i16; 12] = [
        -32768, -2, -1, 0, 1, 2, 300, 1000, 4096, 12345, 32766, 32767,
    ];
    let data: Vec<u8> = values.iter().flat_map(|v| v.to_be_bytes()).collect();
    dir.write("pair.raw", &data);
    let header = "NRRD0004\n# detached\ntype: short\ndimension: 3\nsizes: 3 2 2\nspacings: 0.5 0.5 2\nendian: big\nencoding: raw\ndata file: pair.raw\n";
    let path = dir.write("pair.nhdr", header.as_bytes());
    let vol = load(&path, &opts()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(vol.dims(), [3, 2, 2]);
    assert_eq!(vol.spacing(), [0.5, 0.5, 2.0]);
    assert_eq!(vol.native_type(), SampleType::I16);
    let want: Vec<f32> = values.iter().map(|&v| v as f32).collect();
    assert_eq!(vol.samples(), &want[..]);
    // x fastest: sample (1, 0, 1) is index 1 + 3*(0 + 2*1) = 7.
    assert_eq!(vol.get(1, 0, 1), 1000.0);
}

#[test]
fn nhdr_detached_gzip_in_subdirectory() {
    let dir = TempDir::new("nhdr-gz");
    let values = [1.5f32, -2.25, 3.0, 1e-3, 7.0, 8.0];
    let data: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    dir.write("sub/data.raw.gz", &gzip(&data));
    let header = "NRRD0005\ntype: float\ndimension: 2\nsizes: 3 2\nspace directions: (0,2) (3,0)\nendian: little\nencoding: gz\ndatafile: sub/data.raw.gz\n\n# after the blank line: ignored\n";
    let path = dir.write("g.nhdr", header.as_bytes());
    let vol = nrrd::read(&path, &opts()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(vol.dims(), [3, 2, 1]);
    assert_eq!(vol.spacing(), [2.0, 3.0, 1.0]);
    assert_eq!(vol.samples(), &values[..]);
}

#[test]
fn nhdr_line_skip_byte_skip_and_data_at_end() {
    let dir = TempDir::new("nhdr-skip");
    let mut data = b"preamble line one\nline two\nXYZ".to_vec();
    data.extend_from_slice(&[10, 20, 30, 40]);
    dir.write("skip.dat", &data);
    let fields = "type: uint8\ndimension: 1\nsizes: 4\nencoding: raw\ndata file: skip.dat\n";
    let path = dir.write(
        "skip.nhdr",
        format!("NRRD0004\n{fields}line skip: 2\nbyte skip: 3\n").as_bytes(),
    );
    let vol = nrrd::read(&path, &opts()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(vol.samples(), &[10.0, 20.0, 30.0, 40.0]);

    let path = dir.write(
        "end.nhdr",
        format!("NRRD0004\n{fields}byte skip: -1\n").as_bytes(),
    );
    let vol = nrrd::read(&path, &opts()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(vol.samples(), &[10.0, 20.0, 30.0, 40.0]);

    // Gzip with a line skip before the stream and a byte skip inside it.
    let mut gz_file = b"text\n".to_vec();
    gz_file.extend(gzip(&[9, 9, 1, 2, 3, 4]));
    dir.write("skip.gz", &gz_file);
    let path = dir.write(
        "gz.nhdr",
        b"NRRD0004\ntype: uint8\ndimension: 1\nsizes: 4\nencoding: gzip\ndata file: skip.gz\nline skip: 1\nbyte skip: 2\n",
    );
    let vol = nrrd::read(&path, &opts()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(vol.samples(), &[1.0, 2.0, 3.0, 4.0]);
}

#[test]
fn nhdr_missing_data_file_names_both_files() {
    let dir = TempDir::new("nhdr-missing");
    let path = dir.write(
        "m.nhdr",
        b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: gone.raw\n",
    );
    let e = error_naming(nrrd::read(&path, &opts()), &path);
    assert!(matches!(e, VolumeError::Io { .. }), "{e}");
    assert!(e.to_string().contains("gone.raw"), "{e}");

    let path = dir.write(
        "list.nhdr",
        b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: LIST\na.raw\nb.raw\n",
    );
    let e = error_naming(nrrd::read(&path, &opts()), &path);
    assert!(matches!(e, VolumeError::Io { .. }), "{e}");
    assert!(e.to_string().contains("a.raw"), "{e}");
}

#[test]
fn nrrd_big_endian_attached_raw_and_gzip() {
    let dir = TempDir::new("big-endian");
    let values = [0u16, 1, 258, 65535, 40000, 7];
    let data: Vec<u8> = values.iter().flat_map(|v| v.to_be_bytes()).collect();
    let fields = "type: unsigned short\ndimension: 3\nsizes: 3 1 2\nendian: big\n";
    let path = dir.write(
        "be.nrrd",
        &nrrd_bytes(&format!("{fields}encoding: raw\n"), &data),
    );
    let vol = nrrd::read(&path, &opts()).unwrap_or_else(|e| panic!("{e}"));
    let want: Vec<f32> = values.iter().map(|&v| f32::from(v)).collect();
    assert_eq!(vol.samples(), &want[..]);

    let path = dir.write(
        "be-gz.nrrd",
        &nrrd_bytes(&format!("{fields}encoding: gzip\n"), &gzip(&data)),
    );
    assert_eq!(nrrd::read(&path, &opts()).unwrap().samples(), &want[..]);

    let doubles = [1.0f64, -0.5, 1e10];
    let data: Vec<u8> = doubles.iter().flat_map(|v| v.to_be_bytes()).collect();
    let path = dir.write(
        "be-f64.nrrd",
        &nrrd_bytes(
            "type: double\ndimension: 1\nsizes: 3\nendian: big\nencoding: raw\n",
            &data,
        ),
    );
    let vol = nrrd::read(&path, &opts()).unwrap();
    assert_eq!(vol.samples(), &[1.0, -0.5, 1e10]);
    assert_eq!(vol.native_type(), SampleType::F64);
}

#[test]
fn nrrd_crlf_header_comments_and_key_values() {
    let dir = TempDir::new("crlf");
    let text = "NRRD0003\r\n# a comment\r\ncontent: test\r\ntype: uchar\r\ndimension: 3\r\nsizes: 2 1 1\r\nkinds: domain domain domain\r\ncenters: cell cell cell\r\nspace: right-anterior-superior\r\nspace origin: (0,0,0)\r\nmy/key:=some: value\r\nencoding: raw\r\n\r\n";
    let mut bytes = text.as_bytes().to_vec();
    bytes.extend_from_slice(&[5, 6]);
    let path = dir.write("crlf.nrrd", &bytes);
    let vol = nrrd::read(&path, &opts()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(vol.samples(), &[5.0, 6.0]);
}

// ---------------------------------------------------------------------------
// Bad NRRD inputs

const U16_4X4X4: &str = "type: uint16\ndimension: 3\nsizes: 4 4 4\nendian: little\n";

#[test]
fn nrrd_truncated_raw() {
    let dir = TempDir::new("trunc-raw");
    let path = dir.write(
        "t.nrrd",
        &nrrd_bytes(&format!("{U16_4X4X4}encoding: raw\n"), &[0u8; 127]),
    );
    let e = error_naming(nrrd::read(&path, &opts()), &path);
    assert!(
        matches!(
            e,
            VolumeError::Truncated {
                need: 128,
                got: 127,
                ..
            }
        ),
        "{e}"
    );
    // Header without its blank line and no data at all.
    let path = dir.write(
        "nodata.nrrd",
        format!("NRRD0004\n{U16_4X4X4}encoding: raw\n").as_bytes(),
    );
    let e = error_naming(nrrd::read(&path, &opts()), &path);
    assert!(matches!(e, VolumeError::Truncated { got: 0, .. }), "{e}");
}

#[test]
fn nrrd_truncated_gzip() {
    let dir = TempDir::new("trunc-gz");
    let fields = "type: uint8\ndimension: 3\nsizes: 16 16 16\nencoding: gzip\n";
    let compressed = gzip(&noise(4096));
    let cut = &compressed[..compressed.len() / 2];
    let path = dir.write("half.nrrd", &nrrd_bytes(fields, cut));
    let e = error_naming(nrrd::read(&path, &opts()), &path);
    assert!(
        matches!(e, VolumeError::Truncated { need: 4096, got, .. } if got < 4096),
        "{e}"
    );

    // All samples there but the gzip trailer (CRC, length) cut off.
    let cut = &compressed[..compressed.len() - 4];
    let path = dir.write("trailer.nrrd", &nrrd_bytes(fields, cut));
    let e = error_naming(nrrd::read(&path, &opts()), &path);
    assert!(e.to_string().contains("truncated"), "{e}");

    // A stream that decompresses to fewer bytes than the sizes need.
    let path = dir.write("short.nrrd", &nrrd_bytes(fields, &gzip(&noise(4000))));
    let e = error_naming(nrrd::read(&path, &opts()), &path);
    assert!(
        matches!(
            e,
            VolumeError::Truncated {
                need: 4096,
                got: 4000,
                ..
            }
        ),
        "{e}"
    );

    // Not gzip at all.
    let path = dir.write("notgz.nrrd", &nrrd_bytes(fields, &noise(4096)));
    let e = error_naming(nrrd::read(&path, &opts()), &path);
    assert!(matches!(e, VolumeError::Format { .. }), "{e}");
}

/// Data longer than the sizes need is read as teem reads it: the samples
/// first, the rest left, with a warning saying how much.
#[test]
fn nrrd_data_after_the_samples_is_left_with_a_warning() {
    let dir = TempDir::new("after");
    let mut data: Vec<u8> = (0..128u8).collect();
    data.extend_from_slice(b"\n\n");
    let path = dir.write(
        "long.nrrd",
        &nrrd_bytes(&format!("{U16_4X4X4}encoding: raw\n"), &data),
    );
    let vol = nrrd::read(&path, &opts()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(vol.samples()[0], 256.0);
    assert_eq!(vol.warnings.len(), 1, "{:?}", vol.warnings);
    assert!(
        vol.warnings[0].contains("2 bytes after the 64 samples"),
        "{:?}",
        vol.warnings
    );

    let path = dir.write(
        "long-gz.nrrd",
        &nrrd_bytes(&format!("{U16_4X4X4}encoding: gzip\n"), &gzip(&[0u8; 200])),
    );
    let vol = nrrd::read(&path, &opts()).unwrap_or_else(|e| panic!("{e}"));
    assert!(
        vol.warnings[0].contains("72 more decompressed bytes"),
        "{:?}",
        vol.warnings
    );

    // Two gzip members are one stream: together they fit exactly.
    let mut two = gzip(&[1u8; 64]);
    two.extend(gzip(&[2u8; 64]));
    let path = dir.write(
        "members.nrrd",
        &nrrd_bytes(&format!("{U16_4X4X4}encoding: gzip\n"), &two),
    );
    let vol = nrrd::read(&path, &opts()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(vol.samples()[0], 257.0);
    assert_eq!(vol.samples()[63], 514.0);
    assert!(vol.warnings.is_empty(), "{:?}", vol.warnings);

    // Bytes after the last member that are not gzip are left too.
    two.extend_from_slice(b"\njunk");
    let path = dir.write(
        "junk.nrrd",
        &nrrd_bytes(&format!("{U16_4X4X4}encoding: gzip\n"), &two),
    );
    let vol = nrrd::read(&path, &opts()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(vol.samples()[63], 514.0);
    assert!(
        vol.warnings[0].contains("5 bytes after the gzip data, not gzip, were ignored"),
        "{:?}",
        vol.warnings
    );

    // ... but a damaged member after the samples is still an error: its
    // checksum covers them.
    let mut bad = gzip(&[0u8; 200]);
    let n = bad.len();
    bad[n - 8] ^= 1;
    let path = dir.write(
        "crc.nrrd",
        &nrrd_bytes(&format!("{U16_4X4X4}encoding: gzip\n"), &bad),
    );
    let e = error_naming(nrrd::read(&path, &opts()), &path);
    assert!(e.to_string().contains("corrupt"), "{e}");
}

/// `byte skip: -1` with gzip: the samples are the decompressed stream's
/// last bytes (teem, pynrrd).
#[test]
fn nrrd_gzip_data_at_the_end() {
    let dir = TempDir::new("gz-end");
    let data: Vec<u8> = (0..=255u8).cycle().take(5000).collect();
    for members in [1, 3] {
        let mut gz = Vec::new();
        for part in data.chunks(data.len().div_ceil(members)) {
            gz.extend(gzip(part));
        }
        let path = dir.write(
            &format!("end{members}.nrrd"),
            &nrrd_bytes(
                "type: uint8\ndimension: 3\nsizes: 4 4 4\nencoding: gzip\nbyte skip: -1\n",
                &gz,
            ),
        );
        let vol = nrrd::read(&path, &opts()).unwrap_or_else(|e| panic!("{e}"));
        let want: Vec<f32> = data[data.len() - 64..].iter().map(|&b| b as f32).collect();
        assert_eq!(vol.samples(), &want[..]);
        assert!(vol.warnings.is_empty(), "{:?}", vol.warnings);
    }
}

#[test]
fn nrrd_unknown_and_unsupported_types() {
    let dir = TempDir::new("types");
    let rest = "dimension: 3\nsizes: 2 2 2\nendian: little\nencoding: raw\n";
    let path = dir.write(
        "q.nrrd",
        &nrrd_bytes(&format!("type: quaternion\n{rest}"), &[0u8; 8]),
    );
    let e = error_naming(nrrd::read(&path, &opts()), &path);
    assert!(
        matches!(e, VolumeError::Format { .. }) && e.to_string().contains("quaternion"),
        "{e}"
    );
    let path = dir.write(
        "l.nrrd",
        &nrrd_bytes(&format!("type: int64\n{rest}"), &[0u8; 64]),
    );
    let e = error_naming(nrrd::read(&path, &opts()), &path);
    assert!(
        matches!(e, VolumeError::Unsupported { .. }) && e.to_string().contains("int64"),
        "{e}"
    );
    let path = dir.write("missing.nrrd", &nrrd_bytes(rest, &[0u8; 8]));
    let e = error_naming(nrrd::read(&path, &opts()), &path);
    assert!(e.to_string().contains("type"), "{e}");
}

#[test]
fn nrrd_unknown_encodings() {
    let dir = TempDir::new("encodings");
    for enc in ["bzip2", "hex", "base64"] {
        let path = dir.write(
            &format!("{enc}.nrrd"),
            &nrrd_bytes(
                &format!("type: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: {enc}\n"),
                &[0u8; 8],
            ),
        );
        let e = error_naming(nrrd::read(&path, &opts()), &path);
        assert!(
            matches!(e, VolumeError::Unsupported { .. }) && e.to_string().contains(enc),
            "{e}"
        );
    }
}

#[test]
fn nrrd_zero_dims() {
    let dir = TempDir::new("zero");
    let path = dir.write(
        "z.nrrd",
        &nrrd_bytes(
            "type: uint8\ndimension: 3\nsizes: 4 0 4\nencoding: raw\n",
            &[],
        ),
    );
    let e = error_naming(nrrd::read(&path, &opts()), &path);
    assert!(e.to_string().contains("zero"), "{e}");
}

#[test]
fn nrrd_dims_product_overflows() {
    let dir = TempDir::new("overflow");
    let path = dir.write(
        "o.nrrd",
        &nrrd_bytes(
            "type: uint8\ndimension: 3\nsizes: 4294967296 4294967296 4294967296\nencoding: raw\n",
            &[0u8; 8],
        ),
    );
    let unlimited = LoadOptions {
        memory_limit: u64::MAX,
        ..opts()
    };
    let e = error_naming(nrrd::read(&path, &unlimited), &path);
    assert!(
        matches!(e, VolumeError::TooLarge { .. }) && e.to_string().contains("overflow"),
        "{e}"
    );
    // Larger than any usize: a size that does not even parse.
    let path = dir.write(
        "p.nrrd",
        &nrrd_bytes(
            "type: uint8\ndimension: 3\nsizes: 99999999999999999999999 1 1\nencoding: raw\n",
            &[0u8; 8],
        ),
    );
    error_naming(nrrd::read(&path, &unlimited), &path);
}

#[test]
fn nrrd_dims_over_memory_limit_fail_before_allocating() {
    let dir = TempDir::new("limit");
    for enc in ["raw", "gzip"] {
        // 10^15 samples over a 9-byte file: the default limit refuses it.
        let path = dir.write(
            &format!("huge-{enc}.nrrd"),
            &nrrd_bytes(
                &format!(
                    "type: uint8\ndimension: 3\nsizes: 100000 100000 100000\nencoding: {enc}\n"
                ),
                b"tiny file",
            ),
        );
        let e = error_naming(nrrd::read(&path, &opts()), &path);
        assert!(matches!(e, VolumeError::OverLimit { .. }), "{e}");

        // A small explicit limit refuses a billion samples.
        let path = dir.write(
            &format!("big-{enc}.nrrd"),
            &nrrd_bytes(
                &format!("type: float\ndimension: 3\nsizes: 1000 1000 1000\nendian: little\nencoding: {enc}\n"),
                b"tiny",
            ),
        );
        let small = LoadOptions {
            memory_limit: 1 << 20,
            ..opts()
        };
        let e = error_naming(nrrd::read(&path, &small), &path);
        assert!(matches!(e, VolumeError::OverLimit { .. }), "{e}");

        // No limit at all: the tiny data still fails before a terabyte buffer
        // is allocated (an attempt would abort the test process).
        let unlimited = LoadOptions {
            memory_limit: u64::MAX,
            ..opts()
        };
        let path = dir.write(
            &format!("claim-{enc}.nrrd"),
            &nrrd_bytes(
                &format!("type: uint8\ndimension: 3\nsizes: 100000 100000 100\nencoding: {enc}\n"),
                &gzip(b"tiny"),
            ),
        );
        let e = error_naming(nrrd::read(&path, &unlimited), &path);
        assert!(matches!(e, VolumeError::Truncated { .. }), "{e}");
    }
}

#[test]
fn nan_rejected_unless_allowed() {
    let dir = TempDir::new("nan");
    let values = [1.0f32, f32::NAN, 3.0, f32::INFINITY, -2.0, 0.5, 7.0, 8.0];
    let data: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    let fields = "type: float\ndimension: 3\nsizes: 2 2 2\nendian: little\nencoding: raw\n";
    let path = dir.write("nan.nrrd", &nrrd_bytes(fields, &data));
    let e = error_naming(nrrd::read(&path, &opts()), &path);
    let msg = e.to_string();
    assert!(
        matches!(
            e,
            VolumeError::NonFinite {
                count: 2,
                nan: 1,
                inf: 1,
                first: 1,
                ..
            }
        ),
        "{msg}"
    );
    assert!(
        msg.contains("2 non-finite") && msg.contains("1 NaN") && msg.contains("1 infinite"),
        "{msg}"
    );

    let allow = LoadOptions {
        allow_nan: true,
        ..opts()
    };
    let vol = nrrd::read(&path, &allow).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(vol.replaced_nonfinite, 2);
    assert!(vol.samples().iter().all(|v| v.is_finite()));
    assert_eq!(vol.samples()[1], -2.0); // NaN becomes the smallest finite sample
    assert_eq!(vol.samples()[3], 8.0); // +inf the largest
}

// ---------------------------------------------------------------------------
// NIfTI

/// A single-file NIfTI-1 image: header, 4 extension bytes, then `data`.
#[allow(clippy::too_many_arguments)]
fn nifti_bytes(
    big: bool,
    dim: [i16; 8],
    datatype: i16,
    pixdim: [f32; 3],
    slope: f32,
    inter: f32,
    vox_offset: f32,
    data: &[u8],
) -> Vec<u8> {
    let mut h = vec![0u8; 348];
    let mut put = |off: usize, b: &[u8]| h[off..off + b.len()].copy_from_slice(b);
    let i32b = |v: i32| {
        if big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    };
    let i16b = |v: i16| {
        if big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    };
    let f32b = |v: f32| {
        if big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    };
    put(0, &i32b(348));
    for (i, d) in dim.iter().enumerate() {
        put(40 + 2 * i, &i16b(*d));
    }
    put(70, &i16b(datatype));
    put(76, &f32b(1.0));
    for (i, p) in pixdim.iter().enumerate() {
        put(80 + 4 * i, &f32b(*p));
    }
    put(108, &f32b(vox_offset));
    put(112, &f32b(slope));
    put(116, &f32b(inter));
    put(344, b"n+1\0");
    h.resize(vox_offset.max(348.0) as usize, 0);
    h.extend_from_slice(data);
    h
}

#[test]
fn nifti_little_big_and_gzip() {
    let dir = TempDir::new("nifti");
    let values: [i16; 8] = [-5, 0, 1, 2, 300, -300, 32767, -32768];
    let le: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    let be: Vec<u8> = values.iter().flat_map(|v| v.to_be_bytes()).collect();
    let dim = [3, 2, 2, 2, 1, 1, 1, 1];
    let want: Vec<f32> = values.iter().map(|&v| f32::from(v)).collect();

    let le_file = nifti_bytes(false, dim, 4, [0.5, 1.0, 2.0], 0.0, 0.0, 352.0, &le);
    let be_file = nifti_bytes(true, dim, 4, [0.5, 1.0, 2.0], 0.0, 0.0, 352.0, &be);
    for (name, bytes) in [
        ("le.nii", le_file.clone()),
        ("be.nii", be_file.clone()),
        ("le.nii.gz", gzip(&le_file)),
        ("be.nii.gz", gzip(&be_file)),
        // gzip found by its magic bytes, whatever the name says
        ("really-gz.nii", gzip(&le_file)),
    ] {
        let path = dir.write(name, &bytes);
        let vol = load(&path, &opts()).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(vol.dims(), [2, 2, 2], "{name}");
        assert_eq!(vol.spacing(), [0.5, 1.0, 2.0], "{name}");
        assert_eq!(vol.native_type(), SampleType::I16, "{name}");
        assert_eq!(vol.samples(), &want[..], "{name}");
        assert!(vol.warnings.is_empty(), "{name}: {:?}", vol.warnings);
    }
    // What follows the image is read past with a warning, as in NRRD and
    // MetaImage: bytes after it, another gzip member, bytes after the gzip
    // data that start no member; the samples are the same.
    let with = |a: &[u8], b: &[u8]| [a, b].concat();
    for (name, bytes, warning) in [
        (
            "tail.nii",
            with(&le_file, b"0123456789"),
            "10 bytes after the 8 samples ignored",
        ),
        (
            "members.nii.gz",
            with(&gzip(&le_file), &gzip(b"more")),
            "4 more decompressed bytes after the 8 samples ignored",
        ),
        (
            "garbage.nii.gz",
            with(&gzip(&le_file), b"garbage"),
            "7 bytes after the gzip data, not gzip, were ignored",
        ),
    ] {
        let path = dir.write(name, &bytes);
        let vol = load(&path, &opts()).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(vol.samples(), &want[..], "{name}");
        assert_eq!(vol.warnings.len(), 1, "{name}: {:?}", vol.warnings);
        assert!(
            vol.warnings[0].contains(warning),
            "{name}: {:?}",
            vol.warnings
        );
    }
    // A member cut short is an error, not a warning.
    let cut = with(&gzip(&le_file), &gzip(b"more")[..12]);
    let path = dir.write("cut-member.nii.gz", &cut);
    let e = load(&path, &opts()).unwrap_err().to_string();
    assert!(
        e.contains("cut-member.nii.gz: gzip data ends before its trailer"),
        "{e}"
    );
}

#[test]
fn nifti_scaling_extensions_and_pixdim_fallback() {
    let dir = TempDir::new("nifti-scale");
    let data = [0u8, 1, 2, 255];
    // vox_offset 400: 48 bytes of extensions to skip; pixdim 0 and NaN read as 1.
    let bytes = nifti_bytes(
        false,
        [3, 4, 1, 1, 1, 1, 1, 1],
        2,
        [0.0, f32::NAN, -3.0],
        2.0,
        -1.0,
        400.0,
        &data,
    );
    for (name, bytes) in [("s.nii", bytes.clone()), ("s.nii.gz", gzip(&bytes))] {
        let path = dir.write(name, &bytes);
        let vol = load(&path, &opts()).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(vol.samples(), &[-1.0, 1.0, 3.0, 509.0], "{name}");
        // Scaled values (here -1 and 509) are no longer the stored u8s.
        assert_eq!(vol.native_type(), SampleType::F32, "{name}");
        assert_eq!(vol.spacing(), [1.0, 1.0, 3.0], "{name}");
    }
}

#[test]
fn nifti_bad_sizeof_hdr() {
    let dir = TempDir::new("nifti-sizeof");
    let mut bytes = nifti_bytes(
        false,
        [3, 1, 1, 1, 1, 1, 1, 1],
        2,
        [1.0; 3],
        0.0,
        0.0,
        352.0,
        &[0],
    );
    bytes[..4].copy_from_slice(&349i32.to_le_bytes());
    let path = dir.write("bad.nii", &bytes);
    let e = error_naming(nifti::read(&path, &opts()), &path);
    assert!(e.to_string().contains("sizeof_hdr"), "{e}");
    let path = dir.write("bad.nii.gz", &gzip(&bytes));
    let e = error_naming(nifti::read(&path, &opts()), &path);
    assert!(e.to_string().contains("sizeof_hdr"), "{e}");
}

#[test]
fn nifti_4d_unsupported() {
    let dir = TempDir::new("nifti-4d");
    let bytes = nifti_bytes(
        false,
        [4, 2, 2, 2, 3, 1, 1, 1],
        2,
        [1.0; 3],
        0.0,
        0.0,
        352.0,
        &[0u8; 24],
    );
    let path = dir.write("4d.nii", &bytes);
    let e = error_naming(nifti::read(&path, &opts()), &path);
    assert!(
        matches!(e, VolumeError::Unsupported { .. })
            && e.to_string().contains("4-D volumes are not supported"),
        "{e}"
    );
    // A fourth axis of size 1 is just a 3-D volume.
    let bytes = nifti_bytes(
        false,
        [4, 2, 2, 2, 1, 1, 1, 1],
        2,
        [1.0; 3],
        0.0,
        0.0,
        352.0,
        &[0u8; 8],
    );
    let path = dir.write("3d-as-4d.nii", &bytes);
    assert_eq!(nifti::read(&path, &opts()).unwrap().dims(), [2, 2, 2]);
}

#[test]
fn nifti_unsupported_datatype_and_truncation() {
    let dir = TempDir::new("nifti-bad");
    let rgb = nifti_bytes(
        false,
        [3, 2, 1, 1, 1, 1, 1, 1],
        128,
        [1.0; 3],
        0.0,
        0.0,
        352.0,
        &[0u8; 6],
    );
    let path = dir.write("rgb.nii", &rgb);
    let e = error_naming(nifti::read(&path, &opts()), &path);
    assert!(
        matches!(e, VolumeError::Unsupported { .. }) && e.to_string().contains("128"),
        "{e}"
    );

    let full = nifti_bytes(
        false,
        [3, 4, 4, 4, 1, 1, 1, 1],
        16,
        [1.0; 3],
        0.0,
        0.0,
        352.0,
        &[0u8; 256],
    );
    let cut = &full[..full.len() - 1];
    for (name, bytes) in [("cut.nii", cut.to_vec()), ("cut.nii.gz", gzip(cut))] {
        let path = dir.write(name, &bytes);
        let e = error_naming(nifti::read(&path, &opts()), &path);
        assert!(
            matches!(
                e,
                VolumeError::Truncated {
                    need: 256,
                    got: 255,
                    ..
                }
            ),
            "{name}: {e}"
        );
    }
    // Only part of the header.
    let path = dir.write("head.nii", &full[..100]);
    let e = error_naming(nifti::read(&path, &opts()), &path);
    assert!(
        matches!(
            e,
            VolumeError::Truncated {
                need: 348,
                got: 100,
                ..
            }
        ),
        "{e}"
    );

    // Huge dims claimed by a tiny compressed file, with no memory limit.
    let huge = nifti_bytes(
        false,
        [3, 32767, 32767, 32767, 1, 1, 1, 1],
        2,
        [1.0; 3],
        0.0,
        0.0,
        352.0,
        &[],
    );
    let path = dir.write("huge.nii.gz", &gzip(&huge));
    let unlimited = LoadOptions {
        memory_limit: u64::MAX,
        ..opts()
    };
    let e = error_naming(nifti::read(&path, &unlimited), &path);
    assert!(matches!(e, VolumeError::Truncated { .. }), "{e}");
    let e = error_naming(nifti::read(&path, &opts()), &path);
    assert!(matches!(e, VolumeError::OverLimit { .. }), "{e}");
}

// ---------------------------------------------------------------------------
// Raw

#[test]
fn raw_offset_big_endian_and_errors() {
    let dir = TempDir::new("raw");
    let mut bytes = vec![0xAA; 6];
    for v in [1u32, 2, 70000, u32::MAX] {
        bytes.extend_from_slice(&v.to_be_bytes());
    }
    let path = dir.write("v.bin", &bytes);
    let spec = RawSpec {
        dims: [2, 2, 1],
        sample_type: SampleType::U32,
        endian: Endian::Big,
        spacing: [1.0, 2.0, 3.0],
        offset: 6,
    };
    let vol = raw::read(&path, &spec, &opts()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(vol.samples(), &[1.0, 2.0, 70000.0, u32::MAX as f32]);
    assert_eq!(vol.spacing(), [1.0, 2.0, 3.0]);

    let e = error_naming(
        raw::read(
            &path,
            &RawSpec {
                offset: 7,
                ..spec.clone()
            },
            &opts(),
        ),
        &path,
    );
    assert!(matches!(e, VolumeError::Truncated { .. }), "{e}");
    let e = error_naming(
        raw::read(
            &path,
            &RawSpec {
                offset: 2,
                ..spec.clone()
            },
            &opts(),
        ),
        &path,
    );
    let msg = e.to_string();
    assert!(
        msg.contains("do not match the file length") && msg.contains("22 bytes"),
        "{msg}"
    );
    let e = error_naming(
        raw::read(
            &path,
            &RawSpec {
                spacing: [1.0, 0.0, 1.0],
                ..spec.clone()
            },
            &opts(),
        ),
        &path,
    );
    assert!(e.to_string().contains("spacing"), "{e}");
    let e = error_naming(
        raw::read(
            &path,
            &RawSpec {
                dims: [usize::MAX, 2, 2],
                ..spec
            },
            &opts(),
        ),
        &path,
    );
    assert!(matches!(e, VolumeError::TooLarge { .. }), "{e}");
}

// ---------------------------------------------------------------------------
// Garbage and empty files

#[test]
fn garbage_files_are_errors_naming_the_file() {
    let dir = TempDir::new("garbage");
    let junk = noise(5000);
    for name in ["g.nrrd", "g.nhdr", "g.nii", "g.nii.gz", "g.vol"] {
        let path = dir.write(name, &junk);
        let e = error_naming(load(&path, &opts()), &path);
        if name == "g.vol" {
            assert!(matches!(e, VolumeError::UnknownFormat { .. }), "{e}");
        }
    }
    // Gzip magic followed by junk.
    let mut fake = vec![0x1f, 0x8b];
    fake.extend(noise(500));
    let path = dir.write("fake.nii.gz", &fake);
    error_naming(load(&path, &opts()), &path);
    // A NRRD header that never ends: binary data without the blank line.
    let mut endless = b"NRRD0004\ntype: uint8\n".to_vec();
    endless.extend(noise(20000));
    let path = dir.write("endless.nrrd", &endless);
    error_naming(load(&path, &opts()), &path);
}

#[test]
fn empty_files_are_errors_naming_the_file() {
    let dir = TempDir::new("empty");
    for name in ["e.nrrd", "e.nhdr", "e.nii", "e.nii.gz"] {
        let path = dir.write(name, b"");
        error_naming(load(&path, &opts()), &path);
    }
    let path = dir.write("e.raw", b"");
    let spec = RawSpec {
        dims: [1, 1, 1],
        sample_type: SampleType::U8,
        endian: Endian::Little,
        spacing: [1.0; 3],
        offset: 0,
    };
    let e = error_naming(raw::read(&path, &spec, &opts()), &path);
    assert!(
        matches!(
            e,
            VolumeError::Truncated {
                need: 1,
                got: 0,
                ..
            }
        ),
        "{e}"
    );
    // An empty detached data file.
    dir.write("empty.raw", b"");
    let path = dir.write(
        "empty-data.nhdr",
        b"NRRD0004\ntype: uint8\ndimension: 1\nsizes: 1\nencoding: raw\ndata file: empty.raw\n",
    );
    let e = error_naming(nrrd::read(&path, &opts()), &path);
    assert!(matches!(e, VolumeError::Truncated { got: 0, .. }), "{e}");
}

#[test]
fn missing_file_is_io_error_naming_it() {
    let dir = TempDir::new("missing");
    for name in ["none.nrrd", "none.nii", "none.nii.gz"] {
        let path = dir.path(name);
        let e = error_naming(load(&path, &opts()), &path);
        assert!(matches!(e, VolumeError::Io { .. }), "{e}");
    }
}

/// Mutated copies of valid files (header values swapped for hostile ones, bytes
/// flipped, files cut short) load or fail, but never panic or abort.
#[test]
fn mutated_files_never_panic() {
    let dir = TempDir::new("mutate");
    let mut rng = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = move |n: usize| {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        (rng % n.max(1) as u64) as usize
    };
    let vol = Volume::new(
        [4, 3, 2],
        [1.0, 2.0, 0.5],
        SampleType::I16,
        samples_for(SampleType::I16, 24),
    )
    .unwrap();
    let raw_path = dir.path("seed-raw.nrrd");
    let gz_path = dir.path("seed-gz.nrrd");
    nrrd::write(&raw_path, &vol, Encoding::Raw).unwrap();
    nrrd::write(&gz_path, &vol, Encoding::Gzip).unwrap();
    let nii = nifti_bytes(
        false,
        [3, 4, 3, 2, 1, 1, 1, 1],
        4,
        [1.0; 3],
        0.0,
        0.0,
        352.0,
        &[7u8; 48],
    );
    let seeds: Vec<(&str, Vec<u8>)> = vec![
        ("nrrd", fs::read(&raw_path).unwrap()),
        ("nrrd", fs::read(&gz_path).unwrap()),
        ("nii", nii.clone()),
        ("nii.gz", gzip(&nii)),
    ];
    let hostile = [
        "0",
        "-1",
        "-2",
        "1",
        "2",
        "3",
        "4",
        "17",
        "nan",
        "inf",
        "-0",
        "1e308",
        "4294967296",
        "18446744073709551615",
        "99999999999999999999",
        "(1,0,0)",
        "none",
        "",
        "LIST",
        "%d 1 2 3",
    ];
    let limited = LoadOptions {
        memory_limit: 64 << 20,
        ..opts()
    };
    for i in 0..1500 {
        let (ext, seed) = &seeds[next(seeds.len())];
        let mut bytes = seed.clone();
        match next(4) {
            0 if ext.starts_with("nrrd") => {
                // Replace one header value token with a hostile one.
                let text = String::from_utf8_lossy(&bytes).into_owned();
                let header_end = text.find("\n\n").unwrap_or(0);
                let mut header: Vec<String> =
                    text[..header_end].lines().map(str::to_string).collect();
                let line = 1 + next(header.len() - 1);
                if let Some((name, value)) = header[line].clone().split_once(": ") {
                    let mut toks: Vec<String> = value.split(' ').map(str::to_string).collect();
                    let t = next(toks.len());
                    toks[t] = hostile[next(hostile.len())].to_string();
                    header[line] = format!("{name}: {}", toks.join(" "));
                }
                let mut out = header.join("\n").into_bytes();
                out.extend_from_slice(&bytes[header_end..]);
                bytes = out;
            }
            1 => bytes.truncate(next(bytes.len() + 1)),
            _ => {
                for _ in 0..1 + next(4) {
                    let at = next(bytes.len());
                    bytes[at] = next(256) as u8;
                }
            }
        }
        let path = dir.write(&format!("m{i}.{ext}"), &bytes);
        if let Err(e) = load(&path, &limited) {
            assert!(e.to_string().contains(&path.display().to_string()), "{e}");
        }
        let _ = fs::remove_file(&path);
    }
}
