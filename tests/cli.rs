//! The command line end to end: outputs on good input, and on bad input a
//! one-line error naming the file and problem, exit code 2, no panic and no
//! output file.

mod common;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use common::{SPHERE, Tmp, args, bin, ok, root, run, stderr};

/// Exit 2, one `error:` line containing every `needle`, no panic.
fn assert_fails(o: &Output, needles: &[&str]) {
    let e = stderr(o);
    assert_eq!(o.status.code(), Some(2), "exit code; stderr: {e}");
    assert!(!e.contains("panicked"), "panic: {e}");
    let errs: Vec<&str> = e.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(errs.len(), 1, "one error line: {e}");
    for n in needles {
        assert!(errs[0].contains(n), "'{n}' not in: {}", errs[0]);
    }
}

fn scene_file(t: &Tmp, name: &str, edit: impl Fn(String) -> String) -> PathBuf {
    let text = std::fs::read_to_string(root().join(SPHERE)).unwrap();
    t.write(name, edit(text).as_bytes())
}

#[test]
fn info_json_has_the_promised_keys() {
    let o = ok(run("info {data}/cranium-ct.nrrd --json"));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["dims"], serde_json::json!([256, 256, 108]));
    assert_eq!(j["type"], "u16");
    assert!((j["spacing"][2].as_f64().unwrap() - 1.5).abs() < 1e-9);
    assert!(j["min"].as_f64().unwrap() <= j["max"].as_f64().unwrap());
    // The cropped tooth's first suggestion is its surface (the data's
    // README: 120), not the value 99% of its samples lie above, which
    // bounds a few dark pockets (51.8).
    let o = run("info {tooth} --json");
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let (iso, above) = (&j["suggested_iso"], &j["suggested_above"]);
    assert!((iso[0].as_f64().unwrap() - 120.0).abs() < 5.0, "{iso}");
    assert!(
        above[0].as_f64().unwrap() < 0.5 && above[2].as_f64().unwrap() > 0.5,
        "{above}"
    );
    let o = ok(run(
        "info {headsq} --dims 64,64,93 --type u16 --spacing 3.2,3.2,1.5",
    ));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("iso-values worth trying"), "{text}");
    assert!(
        text.contains(
            "u16le.raw --dims 64,64,93 --type u16 --spacing 3.2,3.2,1.5 -o scene.toml --iso "
        ),
        "{text}"
    );
}

/// Bytes after a NRRD's samples (a trailing newline, say) are left as teem
/// leaves them: the command succeeds and a warning says how many.
#[test]
fn info_warns_of_data_after_the_samples() {
    let t = Tmp::new("after");
    t.write(
        "long.nrrd",
        &nrrd(
            "type: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n",
            &[7; 9],
        ),
    );
    let o = t.run("info long.nrrd --json");
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["dims"], serde_json::json!([2, 2, 2]));
    let err = stderr(&o);
    assert!(
        err.starts_with("warning: ")
            && err.contains("long.nrrd: 1 byte after the 8 samples ignored"),
        "{err}"
    );
}

#[test]
fn sample_prints_csv_in_input_order() {
    let t = Tmp::new("sample");
    t.write("p.txt", b"# grid points\n10,20,30\n\n10.5 20.25 30.75\n");
    let sample = |points: &str| {
        t.run(&format!(
            "sample {{data}}/engine.nrrd --filter bspline3 --points {points}"
        ))
    };
    let o = ok(sample("p.txt"));
    let out = String::from_utf8_lossy(&o.stdout);
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines[0], "x,y,z,value,gx,gy,gz");
    assert_eq!(lines.len(), 3);
    assert!(lines[1].starts_with("10,20,30,"));
    assert!(lines[2].starts_with("10.5,20.25,30.75,"));
    assert_eq!(lines[2].split(',').count(), 7);
    assert!(stderr(&o).is_empty(), "{}", stderr(&o));
    // Points off the grid are evaluated (mirror boundary) and counted.
    t.write("off.txt", b"-1,20,30\n10,20,30\n10,20,1e6\n");
    let o = ok(sample("off.txt"));
    assert_eq!(String::from_utf8_lossy(&o.stdout).lines().count(), 4);
    let err = stderr(&o);
    assert!(
        err.starts_with("warning: 2 of 3 points lie outside the grid") && err.contains("mirror"),
        "{err}"
    );
}

/// A volume held relative to an offset (f64 values f32 would round) is
/// sampled at its own values, the offset added back.
#[test]
fn sample_adds_a_volume_offset_back() {
    let t = Tmp::new("sample-offset");
    let values: Vec<f64> = (0..8).map(|i| 101325.0 + 1e-6 * i as f64).collect();
    let mut nrrd =
        b"NRRD0004\ntype: double\ndimension: 3\nsizes: 2 2 2\nencoding: raw\nendian: little\n\n"
            .to_vec();
    for v in &values {
        nrrd.extend_from_slice(&v.to_le_bytes());
    }
    t.write("p.nrrd", &nrrd);
    t.write("pts.txt", b"0,0,0\n1,1,1\n");
    let o = ok(t.run("sample p.nrrd --filter linear --points pts.txt"));
    let out = String::from_utf8_lossy(&o.stdout);
    let got: Vec<f64> = out
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(3).unwrap().parse().unwrap())
        .collect();
    for (g, w) in got.iter().zip([values[0], values[7]]) {
        assert!((g - w).abs() <= 1e-12, "{out}");
    }
}

#[test]
fn phantom_writes_loadable_nrrd_and_metaimage() {
    let t = Tmp::new("phantom");
    ok(t.run(
        "phantom sphere --size 24 --radius 6 --sigma 1.5 --format u8 \
         --hole 11.5,11.5,11.5,2,0.5 -o ball.nrrd",
    ));
    let o = t.run("info ball.nrrd --json");
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["dims"], serde_json::json!([24, 24, 24]));
    assert_eq!(j["type"], "u8");
    assert_eq!(j["max"], 255.0);
    // The same phantom as NRRD and as MetaImage, compressed: the same
    // samples.
    let ml = |name: &str| {
        ok(t.run(&format!("phantom marschner-lobb -o {name} --gzip")));
        snell::volume::load(&t.path(name), &Default::default()).unwrap()
    };
    let (nrrd, mha) = (ml("ml.nrrd"), ml("ml.mha"));
    assert_eq!(mha.dims(), nrrd.dims());
    assert_eq!(mha.content_hash(), nrrd.content_hash());
}

/// `snell resample` upsamples a real scan: the lattice asked for, the
/// world extent kept (spacing shrunk by `(n − 1)/(m − 1)`), the scan's own
/// type, and a render of it through the scan's scene reports its peak
/// memory.
#[test]
fn resample_upsamples_a_scan_that_renders() {
    let t = Tmp::new("resample");
    let o = ok(t.run(
        "resample {data}/cranium-ct.nrrd -o up.nrrd --size 301,301,128 \
         --filter smooth-bspline3 --lambda 1",
    ));
    assert!(stderr(&o).contains("301x301x128 u16"), "{}", stderr(&o));
    assert!(!stderr(&o).contains("warning"), "{}", stderr(&o));
    // A type too narrow for the scan's values clamps them, and says so.
    let o = ok(t.run("resample {data}/cranium-ct.nrrd -o small.nrrd --size 16,16,8 --format u8"));
    assert!(
        stderr(&o).contains("do not fit u8 [0, 255]: those beyond are clamped"),
        "{}",
        stderr(&o)
    );
    let info = |p: &str| -> serde_json::Value {
        let o = ok(t.run(&format!("info {p} --json")));
        serde_json::from_slice(&o.stdout).unwrap()
    };
    let (a, b) = (info("{data}/cranium-ct.nrrd"), info("up.nrrd"));
    assert_eq!(b["dims"], serde_json::json!([301, 301, 128]));
    assert_eq!(b["type"], "u16");
    for k in 0..3 {
        let extent = |j: &serde_json::Value| j["extent"][k].as_f64().unwrap();
        assert!(
            (extent(&a) - extent(&b)).abs() < 1e-9 * extent(&a),
            "axis {k}"
        );
    }
    let o = ok(t.run(&format!(
        "render {{cranium}} --set volume.path={} --set surface.filter=bspline3 \
         --set image.width=96 --set image.height=96 -o up.png --stats up.json",
        t.path("up.nrrd").display()
    )));
    assert!(stderr(&o).contains("peak memory:"), "{}", stderr(&o));
    let stats = std::fs::read(t.path("up.json")).unwrap();
    let j: serde_json::Value = serde_json::from_slice(&stats).unwrap();
    assert!(j["peak_rss_mib"].as_f64().unwrap() > 10.0, "{j}");
    assert!(j["counters"]["refractions"].as_u64().unwrap() > 0, "{j}");
}

/// `snell classify` on the paper's ball: every method's tags hold the exact
/// ones, ACCC tags fewer cells than BMCC (the paper's Table 3 ratio), the
/// Bézier hull fewer still, and the table form names the methods.
#[test]
fn classify_reports_each_method_against_exact() {
    let t = Tmp::new("classify");
    ok(t.run("phantom sphere --size 32 --radius 10 --sigma 1.5 --format u8 -o ball.nrrd"));
    let o = ok(t.run("classify ball.nrrd --filter bspline3 --iso 127.5 --json"));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["lattice"], serde_json::json!([31, 31, 31]));
    let methods = j["methods"].as_array().unwrap();
    let tagged = |name: &str| {
        let m = methods.iter().find(|m| m["method"] == name).unwrap();
        assert_eq!(m["contains_exact"], true, "{name} misses exact cells");
        m["tagged"].as_u64().unwrap()
    };
    let (bmcc, accc, bezier, exact) = (
        tagged("bmcc"),
        tagged("accc"),
        tagged("bezier"),
        tagged("exact"),
    );
    assert!(
        exact > 0 && exact <= bezier && bezier < accc && accc < bmcc,
        "{methods:?}"
    );
    let ratio = j["accc_over_bmcc"].as_f64().unwrap();
    assert!((ratio - accc as f64 / bmcc as f64).abs() < 1e-12);
    // The iso-surface (r ≈ 11.8) crosses about 1.5·4π·11.8² ≈ 2600 cells.
    assert!((1000..4000).contains(&exact), "{exact} exact cells");

    let o = ok(t.run("classify ball.nrrd --filter catmull-rom --iso 127.5 --methods bmcc,accc"));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("bmcc") && out.contains("accc"), "{out}");
}

#[test]
fn render_writes_every_output() {
    let t = Tmp::new("render");
    let o = ok(t.run(
        "render {sphere} -o a.png --hits h.exr --exr c.exr --stats s.json --threads 2 \
         --set image.width=64 --set image.height=48",
    ));
    assert!(stderr(&o).contains("per ray:"), "stats table on stderr");
    for name in ["a.png", "h.exr", "c.exr", "s.json"] {
        assert!(t.path(name).metadata().unwrap().len() > 0, "{name}");
    }
    let s: serde_json::Value =
        serde_json::from_slice(&std::fs::read(t.path("s.json")).unwrap()).unwrap();
    assert_eq!(s["counters"]["rays"], 64 * 48);
    assert_eq!(s["counters"]["undefined"], 0);
    for stage in [
        "generate", "entry", "traverse", "solve", "refract", "record",
    ] {
        assert!(s["stage_cpu_s"][stage].is_number(), "{stage}");
    }
    // The reference and compare commands close the loop.
    ok(t.run(
        "reference {root}/scenes/sphere-f32.toml --hits ref.exr \
         --set image.width=64 --set image.height=48",
    ));
    let o = ok(t.run("compare h.exr ref.exr --checker 8 --json"));
    let c: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(c["pixels"], 64 * 48);
}

/// A camera far enough for f64 to round its rays' origins by more than a
/// millionth of a voxel is warned of; one at the stress suite's 1e9 is not.
#[test]
fn a_far_camera_is_warned_of() {
    let t = Tmp::new("far");
    let run = |d: &str, kind: &str| {
        ok(t.run(&format!(
            "render {{sphere}} -o f.png -q --set image.width=8 --set image.height=8 \
             --set camera.kind={kind} --set camera.height=50 --set camera.fov_y=1e-9 \
             --set camera.position=[31.5,31.5,-{d}]"
        )))
    };
    for kind in ["orthographic", "perspective"] {
        let o = run("1e12", kind);
        assert!(
            stderr(&o).contains("rounds its rays' origins by about 1.1e-4 voxels"),
            "{}",
            stderr(&o)
        );
        assert!(!stderr(&run("1e9", kind)).contains("rounds"));
    }
}

#[test]
fn iso_outside_the_data_is_a_warning_and_a_backdrop_image() {
    let t = Tmp::new("iso");
    let o = ok(t.run(
        "render {sphere} -o b.png --set surface.iso=300 \
         --set image.width=32 --set image.height=32 -q --hits b.exr",
    ));
    assert!(stderr(&o).contains("warning") && stderr(&o).contains("outside the data range"));
    assert!(stderr(&o).contains("only where bspline3 overshoots the samples"));
    assert!(t.path("b.png").exists());
    // Every ray goes straight to the backdrop: no crossing anywhere.
    let h = snell::film::HitImage::read_exr(&t.path("b.exr")).unwrap();
    assert_eq!(h.events.len(), 32 * 32);
    assert!(h.events.iter().all(|&e| e == 0.0), "crossings found");
    assert!(
        h.u.iter().chain(&h.v).all(|x| x.is_finite()),
        "every ray hits the backdrop"
    );
    // Trilinear interpolation cannot leave the samples' range.
    let o = ok(t.run(
        "render {sphere} -o l.png --set surface.iso=300 --set surface.filter=linear \
         --set image.width=16 --set image.height=16 -q",
    ));
    assert!(stderr(&o).contains("[0, 255]; the image shows only the backdrop"));
    // Catmull-Rom overshoots a sharp-edged ball (no smoothing): an
    // iso-value above every sample still cuts a surface, as the warning says.
    let o = ok(t.run(
        "render {sphere} -o c.png --set volume.phantom.sigma=0 --set surface.iso=260 \
         --set surface.filter=catmull-rom --set image.width=64 --set image.height=64 \
         -q --hits c.exr",
    ));
    assert!(stderr(&o).contains("only where catmull-rom overshoots the samples"));
    let h = snell::film::HitImage::read_exr(&t.path("c.exr")).unwrap();
    assert!(h.events.iter().any(|&e| e > 0.0), "an overshoot surface");
}

/// A volume one sample thick has no cells: the render completes, showing
/// the backdrop through the volume's plane, and says why. The control, the
/// same plane behind a layer of 0 (two samples thick), refracts in the same
/// view, so the camera does face the plane.
#[test]
fn a_volume_one_sample_thick_is_a_warning_and_a_backdrop_image() {
    let t = Tmp::new("flat");
    let render = |name: &str, sizes: &str, data: &[u8]| {
        let path = t.write(
            &format!("{name}.nrrd"),
            &nrrd(
                &format!("type: uint8\ndimension: 3\nsizes: {sizes}\nencoding: raw\n"),
                data,
            ),
        );
        let o = ok(t.run(&format!(
            "render {{sphere}} -o {name}.png --set volume.path={} -q --hits {name}.exr \
             --set image.width=16 --set image.height=16 --set camera.position=[3.5,2.5,-50] \
             --set camera.look_at=[3.5,2.5,0] --set camera.fov_y=5",
            path.display()
        )));
        let h = snell::film::HitImage::read_exr(&t.path(&format!("{name}.exr"))).unwrap();
        (stderr(&o), h)
    };
    let (err, flat) = render("flat", "8 6 1", &[200; 48]);
    assert!(
        err.contains("the volume is 8x6x1 samples: one sample along z makes no cells"),
        "{err}"
    );
    assert!(flat.events.iter().all(|&e| e == 0.0));
    assert!(
        flat.u.iter().all(|u| u.is_finite()),
        "every ray meets the backdrop"
    );
    let layered: Vec<u8> = [[0; 48], [200; 48]].concat();
    let (_, control) = render("control", "8 6 2", &layered);
    assert!(
        control.events.iter().all(|&e| e > 0.0),
        "the two-sample slab refracts every ray"
    );
}

/// One bad input for `snell`: what it is, the arguments (run in the test's
/// scratch directory, so its files are named bare), words the error line must
/// contain, and an environment variable to set besides the table's
/// `SNELL_MEMORY_LIMIT`.
struct Bad {
    kind: &'static str,
    what: &'static str,
    args: Vec<String>,
    needles: Vec<&'static str>,
    env: Option<(&'static str, &'static str)>,
}

/// `cmd` is a command line as [`args`] reads it.
fn bad(kind: &'static str, what: &'static str, cmd: &str, needles: &[&'static str]) -> Bad {
    Bad {
        kind,
        what,
        args: args(cmd),
        needles: needles.to_vec(),
        env: None,
    }
}

/// The memory limit every bad-input run gets unless the case sets its own, so
/// the messages that quote it read the same on every machine.
const TABLE_MEMORY_LIMIT: &str = "4G";

fn nrrd(fields: &str, data: &[u8]) -> Vec<u8> {
    let mut v = format!("NRRD0004\n{fields}\n").into_bytes();
    v.extend_from_slice(data);
    v
}

/// A NIfTI-1 header for a 2x2x2 volume of `datatype`, with `sizeof_hdr`, and
/// `extra` bytes of data after it.
fn nifti(sizeof_hdr: i32, datatype: i16, bitpix: i16, extra: usize) -> Vec<u8> {
    let mut h = vec![0u8; 352];
    h[0..4].copy_from_slice(&sizeof_hdr.to_le_bytes());
    for (i, d) in [3i16, 2, 2, 2, 1, 1, 1, 1].iter().enumerate() {
        h[40 + 2 * i..42 + 2 * i].copy_from_slice(&d.to_le_bytes());
    }
    h[70..72].copy_from_slice(&datatype.to_le_bytes());
    h[72..74].copy_from_slice(&bitpix.to_le_bytes());
    for i in 0..8 {
        h[76 + 4 * i..80 + 4 * i].copy_from_slice(&1.0f32.to_le_bytes());
    }
    h[108..112].copy_from_slice(&352.0f32.to_le_bytes());
    h[344..348].copy_from_slice(b"n+1\0");
    h.resize(352 + extra, 0);
    h
}

/// Every file, in the scratch directory (recursively), with its contents.
fn listing(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.push((p.clone(), Vec::new()));
            out.extend(listing(&p));
        } else {
            out.push((p.clone(), std::fs::read(&p).unwrap()));
        }
    }
    out.sort();
    out
}

/// Every bad input the command line is known to meet, across volume files,
/// scenes and flags: each must exit 2 with exactly one `error:` line that
/// names the problem, never panic, and leave no file behind (output or
/// temporary). The table of messages goes to `$SNELL_TABLE_DIR/bad-inputs.md`
/// when that variable is set (docs/robustness.md holds a copy).
#[test]
fn bad_inputs_fail_cleanly_without_output() {
    let t = Tmp::new("bad");
    let u8_3 = "type: uint8\ndimension: 3";

    t.write(
        "trunc.nrrd",
        &nrrd(&format!("{u8_3}\nsizes: 4 4 4\nencoding: raw\n"), &[0; 10]),
    );
    t.write(
        "sizes.nrrd",
        &nrrd(
            &format!("{u8_3}\nsizes: 2 2 2\nspacing: 1 1 1\nencoding: raw\n"),
            &[0; 8],
        ),
    );
    t.write(
        "type.nrrd",
        &nrrd(
            "type: quaternion\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n",
            &[0; 8],
        ),
    );
    t.write(
        "enc.nrrd",
        &nrrd(&format!("{u8_3}\nsizes: 2 2 2\nencoding: bzip2\n"), &[0; 8]),
    );
    t.write(
        "zero.nrrd",
        &nrrd(&format!("{u8_3}\nsizes: 2 0 2\nencoding: raw\n"), &[]),
    );
    t.write("huge.nrrd", &nrrd("type: float\ndimension: 3\nsizes: 100000 100000 100000\nencoding: raw\nendian: little\n", &[0; 16]));
    t.write(
        "gz.nrrd",
        &nrrd(
            &format!("{u8_3}\nsizes: 2 2 2\nencoding: gzip\n"),
            b"not gzip data",
        ),
    );
    // Shorter than gzip's header: once read as no data at all.
    t.write(
        "gz8.nrrd",
        &nrrd(
            &format!("{u8_3}\nsizes: 2 2 2\nencoding: gzip\n"),
            b"notgzip!",
        ),
    );
    t.write(
        "d4.nrrd",
        &nrrd(
            "type: uint8\ndimension: 4\nsizes: 2 2 2 2\nencoding: raw\n",
            &[0; 16],
        ),
    );
    t.write(
        "det.nhdr",
        &nrrd(
            &format!("{u8_3}\nsizes: 2 2 2\nencoding: raw\ndata file: nothere.raw"),
            &[],
        ),
    );
    let mut nan = nrrd(
        "type: float\ndimension: 3\nsizes: 2 1 1\nencoding: raw\nendian: little\n",
        &[],
    );
    nan.extend_from_slice(&1.0f32.to_le_bytes());
    nan.extend_from_slice(&f32::NAN.to_le_bytes());
    t.write("nan.nrrd", &nan);
    t.write("garbage.nrrd", b"\x00\x01hello");
    t.write("empty.nrrd", b"");
    t.write("short.nii", &[0; 100]);
    t.write("sizeof.nii", &nifti(999, 2, 8, 8));
    t.write("cplx.nii", &nifti(348, 32, 64, 64));
    t.write("x.vol", b"abc");
    let mha = |extra: &str, ty: &str| {
        format!(
            "ObjectType = Image\nNDims = 3\nDimSize = 2 2 2\n{extra}ElementType = {ty}\nElementDataFile = LOCAL\n"
        )
    };
    t.write("rgb.mha", mha("", "MET_RGB").as_bytes());
    t.write(
        "chan.mha",
        mha("ElementNumberOfChannels = 3\n", "MET_UCHAR").as_bytes(),
    );
    t.write(
        "cut.mha",
        &[mha("", "MET_USHORT").as_bytes(), &[0u8; 5]].concat(),
    );
    t.write(
        "list.mhd",
        mha("", "MET_UCHAR").replace("LOCAL", "LIST").as_bytes(),
    );
    t.write(
        "zcut.mha",
        &[
            mha("CompressedData = True\n", "MET_UCHAR").as_bytes(),
            b"\x78\x9c",
        ]
        .concat(),
    );
    t.write("r.raw", &[0; 10]);
    t.write("good.txt", b"1,2,3\n");
    t.write("fields.txt", b"1,2,3\n4,5\n");
    t.write("nanpts.txt", b"1,2,3\n\n1,nan,3\n");
    t.write("notexr.exr", b"hi");
    scene_file(&t, "nokey.toml", |s| s.replace("iso = 127.5\n", ""));
    scene_file(&t, "filter.toml", |s| s.replace("bspline3", "gaussian"));
    scene_file(&t, "samepos.toml", |s| {
        s.replace(
            "look_at = [31.5, 31.5, 31.5]",
            "look_at = [31.5, 31.5, -150.0]",
        )
    });
    scene_file(&t, "ior.toml", |s| s.replace("ior = 1.5", "ior = 0.0"));
    scene_file(&t, "ok.toml", |s| s.to_string());
    scene_file(&t, "scene.pov", |s| s.to_string());
    // The photograph scene over a JPEG cut short, and over a PNG of its own.
    let photo_scene = std::fs::read_to_string(root().join("scenes/sphere-photo.toml")).unwrap();
    let jpeg = std::fs::read(root().join("scenes/photo.jpg")).unwrap();
    t.write("cut.jpg", &jpeg[..jpeg.len() / 2]);
    t.write(
        "cut.toml",
        photo_scene.replace("photo.jpg", "cut.jpg").as_bytes(),
    );
    let mut png = Vec::new();
    image::RgbImage::from_pixel(4, 4, image::Rgb([200, 100, 50]))
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    t.write("bd.png", &png);
    // The same PNG with its header claiming 100000 × 100000 pixels (the
    // header's CRC made to match).
    let mut huge_png = png.clone();
    huge_png[16..24]
        .copy_from_slice(&[100_000u32.to_be_bytes(), 100_000u32.to_be_bytes()].concat());
    let mut crc = flate2::Crc::new();
    crc.update(&huge_png[12..29]);
    huge_png[29..33].copy_from_slice(&crc.sum().to_be_bytes());
    t.write("huge.png", &huge_png);
    t.write(
        "bd.toml",
        photo_scene.replace("photo.jpg", "bd.png").as_bytes(),
    );
    // Two parts of one frame, for comparisons of different regions.
    for (name, region) in [("k0", "0,0,64,4"), ("k1", "0,4,64,8")] {
        ok(t.run(&format!(
            "render ok.toml -q --region {region} -o {name}.png --hits {name}.exr"
        )));
    }
    // A part whose header claims 10^10 pixels in a file of a few hundred
    // bytes: refused from the header, before the reader allocates them.
    let mut huge = std::fs::read(t.path("k0.exr")).unwrap();
    let key = b"dataWindow\0box2i\0";
    let at = huge.windows(key.len()).position(|w| w == key).unwrap() + key.len() + 4;
    for (i, v) in [0i32, 0, 99_999, 99_999].into_iter().enumerate() {
        huge[at + 4 * i..at + 4 * i + 4].copy_from_slice(&v.to_le_bytes());
    }
    t.write("huge.exr", &huge);
    scene_file(&t, "section.toml", |s| {
        s.replace("[volume.phantom]", "[volume.phantomx]")
    });
    scene_file(&t, "novolume.toml", |s| {
        s.replace(
            "[volume.phantom]\nkind = \"sphere\"\nsize = 64\nradius = 20.0\nsigma = 3.0\nformat = \"u8\"",
            "[volume]\npath = \"nope.nrrd\"",
        )
    });
    scene_file(&t, "syntax.toml", |s| s.replace("[image]", "[image"));
    scene_file(&t, "seed.toml", |s| {
        s.replace("[render]", "[render]\nseed = 18446744073709551615")
    });
    scene_file(&t, "far.toml", |s| {
        s.replace(
            "position = [31.5, 31.5, -150.0]",
            "position = [31.5, 31.5, -1e307]",
        )
    });
    scene_file(&t, "iortext.toml", |s| {
        s.replace("ior = 1.5", "ior = \"1.5\"")
    });
    scene_file(&t, "wfloat.toml", |s| {
        s.replace("width = 512", "width = 32.0")
    });
    scene_file(&t, "negsize.toml", |s| s.replace("size = 64", "size = -64"));
    scene_file(&t, "u12.toml", |s| {
        s.replace("format = \"u8\"", "format = \"u12\"")
    });
    scene_file(&t, "bigiso.toml", |s| {
        s.replace("iso = 127.5", "iso = 1e400")
    });
    scene_file(&t, "negradius.toml", |s| {
        s.replace("radius = 20.0", "radius = -20.0")
    });
    scene_file(&t, "size.toml", |s| s.replace("width = 512", "width = 0"));

    // One line per case: kind, what, command, words the message must hold.
    #[rustfmt::skip]
    let cases = vec![
        bad("file", "NRRD: raw data shorter than the sizes", "info trunc.nrrd", &["trunc.nrrd"]),
        bad("file", "NRRD: a misspelt field", "info sizes.nrrd", &["sizes.nrrd", "unknown field 'spacing'"]),
        bad("file", "NRRD: unknown type", "info type.nrrd", &["type.nrrd", "quaternion"]),
        bad("file", "NRRD: unsupported encoding", "info enc.nrrd", &["enc.nrrd", "bzip2"]),
        bad("file", "NRRD: an axis of size 0", "info zero.nrrd", &["zero.nrrd"]),
        bad("file", "NRRD: sizes over the memory limit", "info huge.nrrd", &["huge.nrrd", "limit"]),
        bad("file", "NRRD: gzip encoding, data not gzip", "info gz.nrrd", &["gz.nrrd", "gzip"]),
        bad("file", "NRRD: gzip encoding, 8 bytes not gzip", "info gz8.nrrd", &["gz8.nrrd", "gzip data is corrupt", "magic bytes"]),
        bad("file", "NRRD: 4-D data", "info d4.nrrd", &["d4.nrrd", "4-D"]),
        bad("file", "NHDR: data file missing", "info det.nhdr", &["det.nhdr", "nothere.raw"]),
        bad("file", "NRRD: NaN in float data", "info nan.nrrd", &["nan.nrrd", "NaN", "--allow-nan"]),
        bad("file", "not a NRRD (binary junk)", "info garbage.nrrd", &["garbage.nrrd"]),
        bad("file", "empty file", "info empty.nrrd", &["empty.nrrd"]),
        bad("file", "NIfTI: shorter than its header", "info short.nii", &["short.nii", "348"]),
        bad("file", "NIfTI: wrong sizeof_hdr", "info sizeof.nii", &["sizeof.nii", "sizeof_hdr"]),
        bad("file", "NIfTI: complex datatype", "info cplx.nii", &["cplx.nii", "complex64"]),
        bad("file", "MetaImage: an RGB element type", "info rgb.mha", &["rgb.mha", "ElementType", "MET_RGB"]),
        bad("file", "MetaImage: three channels", "info chan.mha", &["chan.mha", "3 channels"]),
        bad("file", "MetaImage: samples cut short", "info cut.mha", &["cut.mha", "5 bytes", "16"]),
        bad("file", "MetaImage: one file per slice", "info list.mhd", &["list.mhd", "LIST"]),
        bad("file", "MetaImage: zlib data cut short", "info zcut.mha", &["zcut.mha", "8"]),
        bad("file", "unknown extension", "info x.vol", &["x.vol", "unknown volume format"]),
        bad("file", "volume file missing", "info missing.nrrd", &["missing.nrrd"]),
        bad("scene", "a --set volume file missing", "render {sphere} -o out.png --set volume.path=gone.nrrd", &["--set volume.path=gone.nrrd", "gone.nrrd: no such file", "read from the working directory"]),
        bad("file", "raw: file shorter than --dims", "info r.raw --dims 2,2,2 --type u16", &["r.raw"]),
        bad("file", "raw: --offset past the end", "info r.raw --dims 2,2,2 --type u8 --offset 100", &["r.raw", "100-byte offset"]),
        bad("file", "raw: a zero dimension", "info r.raw --dims 0,2,2 --type u8", &["r.raw"]),
        bad("file", "raw: dims whose product overflows", "info r.raw --dims 18446744073709551615,2,2 --type u8", &["r.raw", "overflow"]),
        bad("file", "raw: over --memory-limit", "info r.raw --dims 2,2,2 --type u8 --memory-limit 16", &["r.raw", "limit"]),
        Bad {
            env: Some(("SNELL_MEMORY_LIMIT", "64")),
            ..bad("file", "raw: over SNELL_MEMORY_LIMIT=64", "info r.raw --dims 2,2,2 --type u8", &["r.raw", "limit"])
        },
        bad("flag", "--type unknown", "info r.raw --dims 2,2,2 --type u128", &["--type", "u128"]),
        bad("flag", "--dims with two values", "info r.raw --dims 2,2 --type u8", &["--dims"]),
        bad("flag", "--dims without --type", "info r.raw --dims 2,2,2", &["--type"]),
        bad("flag", "--endian neither little nor big", "info r.raw --dims 2,2,2 --type u8 --endian middle", &["--endian", "middle"]),
        bad("flag", "--memory-limit not a size", "info r.raw --dims 2,2,2 --type u8 --memory-limit lots", &["--memory-limit", "lots"]),
        bad("flag", "--spacing with a zero", "info r.raw --dims 2,2,2 --type u8 --spacing 0,1,1", &["r.raw", "spacing"]),
        bad("flag", "--region outside the image", "render {sphere} -o out.png --region 500,0,513,10", &["--region", "X1 <= 512"]),
        bad("flag", "--region empty", "render {sphere} -o out.png --region 10,10,10,20", &["--region", "X0 < X1"]),
        bad("flag", "--region not four numbers", "render {sphere} -o out.png --region 1,2,-3,4", &["--region '1,2,-3,4'"]),
        bad("flag", "--region starting with a minus", "render {sphere} -o out.png --region -1,0,10,10", &["--region '-1,0,10,10'", "X0,Y0,X1,Y1"]),
        bad("flag", "--region without its value", "render --region --quiet {sphere} -o out.png", &["'--quiet'", "the region was left out"]),
        bad("flag", "--orbit without a frame number", "render {sphere} -o out.png --orbit 8", &["-o out.png", "--orbit", "%03d"]),
        bad("flag", "--orbit with a bad frame number", "render {sphere} -o f%3d.png --orbit 8", &["%0Nd", "got %3d"]),
        bad("flag", "--orbit patterns meeting", "render {sphere} -o f%d.png --hits h%d.exr --exr h%02d.exr --orbit 12", &["--hits h%d.exr (frame 10)", "--exr h%02d.exr (frame 10)", "h10.exr"]),
        bad("flag", "--orbit with --trace", "render {sphere} -o f%d.png --orbit 8 --trace t.json", &["--trace", "--orbit"]),
        bad("flag", "--orbit with a frame pattern for --stats", "render {sphere} -o f%d.png --orbit 2 --stats s%d.json", &["--stats s%d.json", "one file", "plain name"]),
        bad("flag", "--orbit 0", "render {sphere} -o f%d.png --orbit 0", &["--orbit", "must be from 1 to 3600"]),
        bad("file", "merge: a part that is not an EXR", "merge empty.nrrd -o out.exr", &["empty.nrrd", "OpenEXR"]),
        bad("flag", "--threads 0", "render {sphere} -o out.png --threads 0", &["--threads"]),
        bad("flag", "--threads not a number", "render {sphere} -o out.png --threads two", &["--threads", "two"]),
        bad("flag", "--threads beyond 1024", "render {sphere} -o out.png --threads 100000", &["--threads", "1024"]),
        bad("flag", "-o not named .png", "render {sphere} -o out.jpg", &["out.jpg", ".png"]),
        bad("flag", "--hits and --exr one file", "render {sphere} -o out.png --hits h.exr --exr h.exr", &["h.exr", "same file"]),
        bad("flag", "--stats over the scene file", "render ok.toml -o out.png --stats ok.toml", &["ok.toml", "input"]),
        bad("flag", "-o a device", "render {sphere} -o /dev/null", &["/dev/null", "regular file"]),
        bad("flag", "--memory-limit not a size (render)", "render {sphere} -o out.png --memory-limit lots", &["--memory-limit", "lots"]),
        bad("flag", "--cache is a file", "render {sphere} -o out.png --cache good.txt", &["good.txt", "not a directory"]),
        bad("flag", "a frame pattern without --orbit", "render {sphere} -o f-%03d.png", &["-o f-%03d.png", "--orbit"]),
        bad("flag", "--cache in a missing folder", "render {sphere} -o out.png --cache nofolder/cache", &["nofolder", "parent", "does not exist"]),
        bad("flag", "merge -o not named .exr", "merge k0.exr k1.exr -o out.png", &["out.png", ".exr"]),
        bad("flag", "merge -o over a part", "merge k0.exr k1.exr -o k1.exr", &["k1.exr", "input"]),
        bad("flag", "-o over the backdrop photograph", "render bd.toml -o bd.png", &["bd.png", "input"]),
        bad("flag", "export-pov over its own scene file", "export-pov scene.pov .", &["scene.pov", "input"]),
        bad("flag", "export-pov into a folder whose parent is missing", "export-pov ok.toml missing/pov", &["missing/pov", "cannot create directory"]),
        bad("flag", "bench --update a device", "bench --update /dev/null", &["/dev/null", "regular file"]),
        bad("flag", "--set without =", "render {sphere} -o out.png --set nonsense", &["--set nonsense"]),
        bad("flag", "-o into a missing directory", "render {sphere} -o /nonexistent-dir/x.png", &["/nonexistent-dir"]),
        bad("flag", "-o is a directory", "render {sphere} -o .", &["is a directory"]),
        bad("flag", "--hits into a missing directory", "render {sphere} -o out.png --hits /nonexistent-dir/h.exr", &["/nonexistent-dir"]),
        bad("flag", "sample --filter unknown", "sample {tooth} --filter gauss --points good.txt", &["gauss"]),
        bad("flag", "sample --lambda negative", "sample {tooth} --filter smooth-bspline3 --lambda -1 --points good.txt", &["--lambda:", "0 to 1e12", "-1"]),
        bad("flag", "sample --lambda with a filter that does not smooth", "sample {tooth} --filter bspline3 --lambda 1 --points good.txt", &["--lambda 1", "--filter bspline3"]),
        bad("flag", "sample smooth-bspline3 without --lambda", "sample {tooth} --filter smooth-bspline3 --points good.txt", &["smooth-bspline3", "needs --lambda"]),
        bad("flag", "resample --lambda with a filter that does not smooth", "resample {tooth} -o up.nrrd --size 8,8,8 --lambda 1", &["--lambda", "--filter bspline3"]),
        bad("flag", "classify --lambda with a filter that does not smooth", "classify {tooth} --filter linear --lambda 1 --iso 100", &["--lambda", "--filter linear"]),
        bad("flag", "classify --methods unknown", "classify {tooth} --filter linear --iso 100 --methods foo", &["'foo'", "bezier0", "exact"]),
        bad("flag", "compare --checker negative", "compare k0.exr k0.exr --checker -1", &["--checker", "-1"]),
        bad("flag", "info --offset negative", "info r.raw --dims 2,2,2 --type u8 --offset -1", &["--offset", "whole number of bytes"]),
        bad("flag", "info --spacing negative", "info r.raw --dims 2,2,2 --type u8 --spacing -1,1,1", &["r.raw", "--spacing", "got -1, 1, 1", "> 0"]),
        bad("flag", "phantom --radius negative", "phantom sphere --radius -3 -o p.nrrd", &["--radius", "-3"]),
        bad("flag", "--endian of a NRRD file", "info {tooth} --endian big", &["tooth.nrrd", "--endian applies only to headerless raw"]),
        bad("flag", "--offset of a NRRD file", "info {tooth} --offset 100", &["tooth.nrrd", "--offset applies only to headerless raw"]),
        bad("flag", "--dims and --type of a NRRD file", "info {tooth} --dims 10,10,10 --type u8", &["tooth.nrrd", "--dims, --type apply only", "NRRD"]),
        bad("flag", "--spacing whose extent overflows", "info {tooth} --spacing 1e308,1,1", &["--spacing 1e308,1,1", "along x", "overflows"]),
        bad("flag", "--memory-limit a negative size", "info r.raw --dims 2,2,2 --type u8 --memory-limit -2G", &["--memory-limit", "'-2G'", "2GB"]),
        bad("flag", "sample --lambda above 1e12", "sample {tooth} --filter smooth-bspline3 --lambda 1e20 --points good.txt", &["--lambda:", "1e12", "got 1e20"]),
        bad("file", "raw: a directory", "info . --dims 2,2,2 --type u8", &["is a directory"]),
        bad("file", "sample points: a row of two numbers", "sample {tooth} --filter bspline3 --points fields.txt", &["fields.txt", "line 2"]),
        bad("file", "sample points: NaN", "sample {tooth} --filter bspline3 --points nanpts.txt", &["nanpts.txt", "line 3"]),
        bad("file", "sample points file missing", "sample {tooth} --filter linear --points nopoints.txt", &["nopoints.txt"]),
        bad("flag", "resample --size with a zero", "resample {tooth} -o up.nrrd --size 0,64,64", &["tooth.nrrd", "along x"]),
        bad("flag", "resample --size with two values", "resample {tooth} -o up.nrrd --size 64,64", &["--size"]),
        bad("flag", "resample --format unknown", "resample {tooth} -o up.nrrd --size 8,8,8 --format u3", &["--format", "u3"]),
        bad("flag", "resample --filter unknown", "resample {tooth} -o up.nrrd --size 8,8,8 --filter gauss", &["gauss"]),
        bad("file", "resample: input missing", "resample missing.nrrd -o up.nrrd --size 8,8,8", &["missing.nrrd"]),
        bad("flag", "resample -o into a missing directory", "resample {tooth} -o /nonexistent-dir/up.nrrd --size 8,8,8", &["/nonexistent-dir"]),
        bad("file", "resample: lattice over the memory limit", "resample {tooth} -o up.nrrd --size 2048,2048,2048", &["tooth.nrrd", "2048x2048x2048", "limit"]),
        bad("flag", "phantom --size 0", "phantom sphere --size 0 -o p.nrrd", &["--size", "from 1 to 4096"]),
        bad("flag", "phantom --size beyond 4096", "phantom sphere --size 5000 -o p.nrrd", &["--size", "from 1 to 4096", "5000"]),
        bad("flag", "phantom over --memory-limit", "phantom sphere --size 512 --memory-limit 100M -o p.nrrd", &["--size", "512x512x512", "100.0 MiB"]),
        bad("flag", "phantom --format unknown", "phantom sphere --format u3 -o p.nrrd", &["--format", "u3"]),
        bad("flag", "phantom --hole with two numbers", "phantom sphere --hole 1,2 -o p.nrrd", &["--hole"]),
        bad("flag", "phantom --noise beyond f32", "phantom sphere --size 8 --noise 1e39 --format f32 -o p.nrrd", &["phantom", "f32"]),
        bad("flag", "phantom Marschner-Lobb alpha -1", "phantom marschner-lobb --size 8 --alpha=-1 -o p.nrrd", &["alpha", "must not be -1"]),
        bad("flag", "unknown subcommand", "frobnicate", &["frobnicate"]),
        bad("file", "compare: not an EXR", "compare notexr.exr notexr.exr", &["notexr.exr"]),
        bad("file", "compare: EXR missing", "compare nothere.exr notexr.exr", &["nothere.exr"]),
        bad("file", "compare: hits against a missing file", "compare k0.exr nothere.exr", &["nothere.exr", "No such file"]),
        bad("file", "compare: hits of two regions", "compare k0.exr k1.exr", &["k0.exr", "k1.exr", "different regions"]),
        bad("flag", "compare --diff of hits", "compare k0.exr k0.exr --diff d.png", &["--diff"]),
        bad("file", "merge: an EXR header claiming 10^10 pixels", "merge huge.exr -o out.exr", &["huge.exr", "100000x100000", "limit"]),
        bad("file", "compare: an EXR header claiming 10^10 pixels", "compare huge.exr k0.exr", &["huge.exr", "100000x100000", "limit"]),
        bad("scene", "required key missing", "render nokey.toml -o out.png", &["nokey.toml", "iso"]),
        bad("scene", "unknown filter", "render filter.toml -o out.png", &["filter.toml", "surface.filter", "gaussian"]),
        bad("scene", "camera look_at at its own position", "render samepos.toml -o out.png", &["samepos.toml", "[camera.look_at]"]),
        bad("scene", "ior 0", "render ior.toml -o out.png", &["ior.toml", "surface.ior"]),
        bad("scene", "unknown section", "render section.toml -o out.png", &["section.toml", "phantomx"]),
        bad("scene", "the scene's volume file missing", "render novolume.toml -o out.png", &["novolume.toml: [volume.path]", "nope.nrrd: no such file", "read from the scene file's folder"]),
        bad("scene", "TOML syntax error", "render syntax.toml -o out.png", &["syntax.toml"]),
        bad("scene", "image width 0", "render size.toml -o out.png", &["size.toml", "image"]),
        bad("scene", "scene file missing", "render absent.toml -o out.png", &["absent.toml"]),
        bad("scene", "--set unknown filter", "render {sphere} -o out.png --set surface.filter=bspline9", &["surface.filter"]),
        bad("scene", "--set camera up along the view", "render {sphere} -o out.png --set camera.up=[0,0,1]", &["camera"]),
        bad("scene", "--set unknown key", "render {sphere} -o out.png --set image.foo=3", &["image.foo"]),
        bad("scene", "--set negative width", "render {sphere} -o out.png --set image.width=-5", &["image.width"]),
        bad("scene", "--set render.tile=0", "render {sphere} -o out.png --set render.tile=0", &["render.tile"]),
        bad("scene", "--set unknown traversal", "render {sphere} -o out.png --set render.traversal=teleport", &["render.traversal", "teleport"]),
        bad("scene", "--set iso NaN", "render {sphere} -o out.png --set surface.iso=nan", &["surface.iso", "NaN"]),
        bad("scene", "--set fov_y 180", "render {sphere} -o out.png --set camera.fov_y=180", &["camera.fov_y"]),
        bad("scene", "smooth-bspline3 without lambda", "render {sphere} -o out.png --set surface.filter=smooth-bspline3", &["--set surface.filter=smooth-bspline3:", "[surface.lambda]", "needs lambda"]),
        bad("scene", "--set lambda negative", "render {sphere} -o out.png --set surface.lambda=-1", &["--set surface.lambda=-1:", "0 to 1e12"]),
        bad("scene", "seed beyond TOML's integers", "render seed.toml -o out.png", &["seed.toml", "[render.seed]", "up to 9223372036854775807", "18446744073709551615"]),
        bad("scene", "--set seed beyond TOML's integers", "render {sphere} -o out.png --set render.seed=18446744073709551615", &["--set render.seed=18446744073709551615:", "up to 9223372036854775807"]),
        bad("scene", "camera position too far out", "render far.toml -o out.png", &["far.toml", "[camera.position]", "1e150", "-1e307"]),
        bad("scene", "ior as text", "render iortext.toml -o out.png", &["[surface.ior]", "expected a number, got the text \"1.5\""]),
        bad("scene", "image width with a fraction", "render wfloat.toml -o out.png", &["[image.width]", "expected a whole number from 1 to 32768, got 32.0"]),
        bad("scene", "--set a section to a number", "render {sphere} -o out.png --set surface=3", &["--set surface=3:", "expected a table of surface settings, got 3"]),
        bad("scene", "phantom size negative", "render negsize.toml -o out.png", &["negsize.toml", "[volume.phantom.size]", "got -64"]),
        bad("scene", "phantom format unknown", "render u12.toml -o out.png", &["u12.toml", "[volume.phantom.format]", "u12"]),
        bad("scene", "iso beyond f64", "render bigiso.toml -o out.png", &["bigiso.toml", "[surface.iso]", "1e400", "finite"]),
        bad("scene", "--set iso beyond f64", "render {sphere} -o out.png --set surface.iso=1e400", &["--set surface.iso=1e400:", "finite"]),
        bad("scene", "phantom radius negative", "render negradius.toml -o out.png", &["negradius.toml", "[volume.phantom.radius]", "-20"]),
        bad("scene", "--set phantom radius negative", "render {sphere} -o out.png --set volume.phantom.radius=-20", &["--set volume.phantom.radius=-20:", ">= 0"]),
        bad("scene", "--set orthographic height negative", "render {sphere} -o out.png --set camera.kind=orthographic --set camera.height=-1", &["--set camera.height=-1:", "> 0"]),
        bad("scene", "a raw volume without [volume.raw]", "render {cranium} -o out.png --set volume.path={headsq}", &["--set volume.path=", "[volume.raw]", "dims", "type"]),
        bad("scene", "a raw layout for a NRRD file", "render {sphere} -o out.png --set volume.path={tooth} --set volume.raw={dims=[2,2,2],type=\"u8\"}", &["--set volume.raw=", "headerless raw volumes", "a NRRD file, whose header gives its layout"]),
        bad("scene", "--set backdrop centre beyond 1e30", "render {sphere} -o out.png --set backdrop.center=[31.5,31.5,1e300]", &["--set backdrop.center=", "±1e30"]),
        bad("scene", "--set an image backdrop without its width", "render {sphere} -o out.png --set backdrop.image=\"photo.jpg\"", &["backdrop.width", "needs"]),
        bad("scene", "phantom over the memory limit", "render {sphere} -o out.png --set volume.phantom.size=4096", &["--set volume.phantom.size=4096:", "limit"]),
        bad("scene", "phantom beyond 4096 samples a side", "render {sphere} -o out.png --set volume.phantom.size=100000", &["--set volume.phantom.size=100000:", "from 1 to 4096"]),
        Bad {
            env: Some(("SNELL_MEMORY_LIMIT", "1M")),
            ..bad("scene", "image over SNELL_MEMORY_LIMIT=1M", "render {sphere} -o out.png --hits h.exr", &["[image]", "limit of 1.0 MiB"])
        },
        bad("scene", "reference of a scene without a sphere phantom", "reference {lobster} --hits h.exr -o ref.png", &["sphere phantom"]),
        bad("scene", "reference of a phantom of negative radius", "reference {sphere} --hits h.exr --set volume.phantom.radius=-5", &["radius", "-5"]),
        bad("scene", "reference of a sphere its grid clips", "reference {sphere} --hits h.exr --set volume.phantom.size=16", &["does not fit"]),
        bad("scene", "spacing ratio beyond 1e6", "render {sphere} -o out.png --set volume.spacing=[1e-15,1,1]", &["volume.spacing", "1e6"]),
        bad("scene", "a JPEG backdrop cut short", "render cut.toml -o out.png", &["cut.jpg", "end-of-image"]),
        bad("scene", "an EXR as the backdrop photograph", "render bd.toml -o out.png --set backdrop.image=\"k0.exr\"", &["k0.exr", "not a PNG or JPEG image"]),
        bad("file", "compare: a JPEG cut short", "compare cut.jpg cut.jpg", &["cut.jpg", "end-of-image"]),
        bad("file", "compare: a PNG header claiming 10^10 pixels", "compare huge.png bd.png", &["huge.png", "100000x100000"]),
        Bad {
            env: Some(("SNELL_MEMORY_LIMIT", "4M")),
            ..bad("scene", "photograph over SNELL_MEMORY_LIMIT=4M", "render {photo} -o out.png --set image.width=16 --set image.height=16", &["photo.jpg", "limit"])
        },
        Bad {
            env: Some(("SNELL_MEMORY_LIMIT", "5M")),
            ..bad("scene", "distance maps over SNELL_MEMORY_LIMIT=5M", "render {sphere} -o out.png --set image.width=16 --set image.height=16 --set render.traversal=distance", &["render.traversal", "limit"])
        },
        bad("scene", "--set image width 0", "render {sphere} -o out.png --set image.width=0", &["--set image.width=0:", "from 1 to 32768"]),
        bad("scene", "--set look_at at the camera's position", "render {sphere} -o out.png --set camera.look_at=[31.5,31.5,-150]", &["--set camera.look_at=", "coincide"]),
        bad("scene", "--set an unknown camera kind", "render {sphere} -o out.png --set camera.kind=fisheye", &["--set camera.kind=fisheye:", "\"perspective\" or \"orthographic\""]),
        bad("scene", "--set a seed past u64", "render {sphere} -o out.png --set render.seed=99999999999999999999", &["--set render.seed=", "up to 9223372036854775807"]),
        bad("flag", "--memory-limit under one byte", "info r.raw --dims 2,2,2 --type u8 --memory-limit 0.4", &["--memory-limit", "under one byte"]),
        bad("flag", "scene --view not an axis", "scene {tooth} -o s.toml --view w", &["--view", "+x, -x, +y, -y, +z or -z", "'w'"]),
        bad("flag", "scene --fov 180", "scene {tooth} -o s.toml --fov 180", &["--fov", "180"]),
        bad("flag", "scene --width 0", "scene {tooth} -o s.toml --width 0", &["--width", "from 1 to 32768"]),
        bad("flag", "scene --iso NaN", "scene {tooth} -o s.toml --iso nan", &["--iso", "NaN"]),
        bad("flag", "scene -o not a .toml name", "scene {tooth} -o s.png", &["-o s.png", "a .toml name"]),
        bad("flag", "scene -o a file that exists, without --force", "scene {tooth} -o nokey.toml", &["nokey.toml", "exists", "--force"]),
        bad("flag", "scene --fov under 0.1", "scene {tooth} -o s.toml --fov 0.01", &["--fov", "from 0.1 to 179"]),
        bad("file", "scene of a volume one sample thick", "scene r.raw --dims 4,2,1 --type u8 --offset 2 -o s.toml", &["r.raw", "4x2x1", "along z", "no surface"]),
        bad("flag", "scene --spacing 1e-15 (a domain too small to frame)", "scene {tooth} -o s.toml --spacing 1e-15,1e-15,1e-15", &["tooth.nrrd", "under the 1e-9", "larger spacing"]),
        bad("flag", "scene --spacing with axes 1e7 apart", "scene {tooth} -o s.toml --spacing 1,1,1e7", &["tooth.nrrd", "factor 1e6"]),
        bad("file", "scene of a constant volume", "scene r.raw --dims 2,2,2 --type u8 --offset 2 -o s.toml", &["r.raw", "every sample is 0", "no iso-surface"]),
    ];

    let before = listing(&t.0);
    let shorten = |s: &str| {
        s.replace(&format!("{}/", root().display()), "")
            .replace(&format!("{}/", t.0.display()), "")
    };
    let mut table = format!(
        "Every command runs in a scratch directory holding the inputs, with `SNELL_MEMORY_LIMIT={TABLE_MEMORY_LIMIT}` unless the case sets its own; paths are shown relative to the repository.\n\n\
         | # | kind | bad input | command | message (the one `error:` line) | exit |\n|---|---|---|---|---|---|\n"
    );
    let mut seen = std::collections::HashSet::new();
    for (i, c) in cases.iter().enumerate() {
        assert!(seen.insert(c.what), "duplicate case '{}'", c.what);
        let (k, v) = c.env.unwrap_or(("SNELL_MEMORY_LIMIT", TABLE_MEMORY_LIMIT));
        let o = bin()
            .args(&c.args)
            .current_dir(&t.0)
            .env("SNELL_MEMORY_LIMIT", TABLE_MEMORY_LIMIT)
            .env(k, v)
            .output()
            .unwrap();
        let e = stderr(&o);
        assert_fails(&o, &c.needles);
        assert!(
            listing(&t.0) == before,
            "'{}' left a file behind or changed one: {e}",
            c.what
        );
        let line = e.lines().find(|l| l.starts_with("error:")).unwrap();
        let quoted: Vec<String> = c
            .args
            .iter()
            .map(|a| snell::human::shell_quote(a))
            .collect();
        let cmd = match c.env {
            Some((k, v)) => format!(
                "{k}={} snell {}",
                snell::human::shell_quote(v),
                quoted.join(" ")
            ),
            None => format!("snell {}", quoted.join(" ")),
        };
        writeln!(
            table,
            "| {} | {} | {} | `{}` | {} | {} |",
            i + 1,
            c.kind,
            c.what,
            shorten(&cmd),
            shorten(line).replace('|', "\\|"),
            o.status.code().unwrap()
        )
        .unwrap();
    }
    assert!(cases.len() >= 30);
    eprint!("{table}");
    if let Some(dir) = std::env::var_os("SNELL_TABLE_DIR") {
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(Path::new(&dir).join("bad-inputs.md"), &table).unwrap();
    }
}

/// What a first-time user meets on good input: warnings for settings a
/// scene writes but does not use (and none for a plain scene), short
/// numbers in text reports, `sample` reading its own output, sizes with B
/// and iB and exponents, the help of classify and phantom, export-pov's
/// threads as render's, and compare's note on a photograph scene.
#[test]
fn first_use_messages_warnings_and_help() {
    let t = Tmp::new("first");
    let png = t.path("o.png");
    let small = "--set image.width=8 --set image.height=8";
    // From the repository, so that the scene is named as a user would.
    let from_root = |line: &str| {
        let o = ok(bin().args(args(line)).current_dir(root()).output().unwrap());
        stderr(&o)
    };
    let render = |extra: &str| {
        from_root(&format!(
            "render {SPHERE} -o {} {small} -q{extra}",
            png.display()
        ))
    };
    let plain = render("");
    assert!(!plain.contains("warning:"), "{plain}");
    let e = render(
        " --set camera.height=3 --set backdrop.width=3 --set render.step=0.5 \
         --set render.samples=3 --set render.footprint=ewa --set render.seed=3 \
         --set surface.lambda=5",
    );
    for key in [
        "camera.height",
        "backdrop.width",
        "render.step",
        "render.samples",
        "render.footprint",
        "render.seed",
        "surface.lambda",
    ] {
        assert!(
            e.lines()
                .any(|l| l.starts_with("warning:") && l.contains(&format!("--set {key}="))),
            "{key}: {e}"
        );
    }
    // A command that runs no traversal says so in its own words, once, and
    // not as a render would ("the octree finds crossings cell by cell");
    // a setting it reads as a render does is noted alike.
    let reference = |sets: &str| {
        from_root(&format!(
            "reference {SPHERE} --hits {} {small} {sets}",
            t.path("ref.exr").display()
        ))
    };
    let e = reference("--set render.step=0.5 --set camera.height=3");
    assert!(
        e.contains("warning: --set render.step ignored: the reference traces"),
        "{e}"
    );
    assert!(!e.contains("cell by cell"), "{e}");
    assert!(
        e.contains("warning: scenes/sphere.toml: --set camera.height=3 is ignored"),
        "{e}"
    );
    // What the analytic reference does not read at all, it says so of.
    let e = reference(
        "--set render.supersampling=grid --set render.samples=4 --set render.max_events=8",
    );
    assert!(
        e.contains("warning: --set render.supersampling, render.samples ignored: the reference traces the phantom's analytic spheres"),
        "{e}"
    );
    // So of the settings inside a table it is given.
    let e = reference("--set render={samples=4,max_events=8}");
    assert!(
        e.contains("warning: --set render.samples ignored: the reference traces"),
        "{e}"
    );
    // The same settings used: no warning.
    let e = render(
        " --set render.supersampling=footprint --set render.footprint=ewa \
         --set render.traversal=step --set render.classify=none --set render.step=0.5",
    );
    assert!(!e.contains("warning:"), "{e}");

    // Text reports: a default f32 phantom's range and the sample CSV.
    ok(t.run("phantom sphere -o p.nrrd"));
    let o = t.run("info p.nrrd");
    let out = String::from_utf8_lossy(&o.stdout).into_owned();
    let range = out.lines().find(|l| l.contains("range")).unwrap();
    assert!(range.len() < 60 && range.contains("e-"), "{range}");
    t.write("pts.txt", b"3.3,40.7,31.5\n31.5,31.5,31.5\n");
    let sample = |points: &str| {
        let line = format!("sample p.nrrd --filter bspline3 --points {points}");
        String::from_utf8_lossy(&ok(t.run(&line)).stdout).into_owned()
    };
    let csv = sample("pts.txt");
    assert!(csv.lines().all(|l| l.len() < 160), "{csv}");
    // Its own output, header and all, reads back as the same points.
    t.write("again.csv", csv.as_bytes());
    assert_eq!(sample("again.csv"), csv);

    for size in ["2GiB", "2GB", "1e9", "512mb"] {
        let o = t.run(&format!("info p.nrrd --memory-limit {size}"));
        assert!(o.status.success(), "{size}: {}", stderr(&o));
    }
    // A limit that rounds to zero bytes would refuse every volume.
    for size in ["0", "0.4", "1e-9"] {
        let o = t.run(&format!("info p.nrrd --memory-limit {size}"));
        assert!(!o.status.success(), "{size}");
        assert!(
            stderr(&o).contains("under one byte"),
            "{size}: {}",
            stderr(&o)
        );
    }

    let help = |line: &str| String::from_utf8_lossy(&run(line).stdout).into_owned();
    let h = help("classify --help");
    for word in [
        "smooth-bspline3",
        "bezier0",
        "accc8",
        "exact",
        "--lambda <L>",
    ] {
        assert!(h.contains(word), "classify --help lacks {word}: {h}");
    }
    let h = help("phantom sphere --help");
    assert!(
        h.contains("Radius of the solid core") && h.contains("grid units"),
        "{h}"
    );
    let h = help("phantom marschner-lobb --help");
    assert!(h.contains("ripple") && h.contains("1 to 4096"), "{h}");

    // export-pov's printed command lines use every core, as render does.
    let cores = std::thread::available_parallelism().unwrap().get();
    let o = ok(t.run("export-pov {sphere} pov"));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains(&format!("Work_Threads={cores}")), "{out}");
    let window = out.lines().find(|l| l.contains("window")).unwrap();
    let wide = window.split("window ").nth(1).unwrap();
    assert!(wide.split(' ').next().unwrap().len() <= 9, "{window}");

    // compare --scene of a photograph backdrop says why there are no squares.
    ok(t.run(&format!(
        "render {{sphere}} -o o.png --hits h.exr {small} -q"
    )));
    let o = ok(t.run("compare h.exr h.exr --scene {photo}"));
    assert!(
        stderr(&o).starts_with("note: ") && stderr(&o).contains("photograph"),
        "{}",
        stderr(&o)
    );
}

/// `snell scene` frames a volume so that the object lies inside the image:
/// every border pixel's ray goes straight to the backdrop, some inner ones
/// refract; the volume's path is written relative to the scene's folder;
/// a raw volume keeps its layout; an existing file is replaced only with
/// `--force`.
#[test]
fn scene_frames_a_volume_that_renders() {
    let t = Tmp::new("scene");
    ok(t.run("phantom sphere --size 24 --radius 5 --sigma 1.5 --format u8 -o ball.nrrd"));
    std::fs::create_dir(t.path("scenes")).unwrap();
    for (name, volume, expect_view) in [
        ("ball", "ball.nrrd --view -x", "-x"),
        (
            "headsq",
            "{headsq} --dims 64,64,93 --type u16 --width 48 --height 32",
            "+y",
        ),
    ] {
        let scene = format!("scenes/{name}.toml");
        let o = t.run(&format!("scene {volume} -o {scene}"));
        let e = stderr(&o);
        assert!(o.status.success(), "{e}");
        assert!(e.contains(&format!("looking along {expect_view}")), "{e}");
        let text = std::fs::read_to_string(t.path(&scene)).unwrap();
        if name == "ball" {
            assert!(text.contains("path = \"../ball.nrrd\""), "{text}");
            assert!(
                text.contains("filter = \"smooth-bspline3\"\nlambda = 1.0"),
                "{text}"
            );
        } else {
            assert!(
                text.contains("[volume.raw]\ndims = [64, 64, 93]\ntype = \"u16\""),
                "{text}"
            );
        }
        let o = ok(t.run(&format!(
            "render {scene} -o {name}.png --hits {name}.exr \
             --set image.width=48 --set image.height=32 -q"
        )));
        assert!(!stderr(&o).contains("warning"), "{}", stderr(&o));
        let h = snell::film::HitImage::read_exr(&t.path(&format!("{name}.exr"))).unwrap();
        let (w, ht) = (h.width as usize, h.height as usize);
        let mut inner = 0;
        for y in 0..ht {
            for x in 0..w {
                let i = y * w + x;
                let border = x == 0 || y == 0 || x == w - 1 || y == ht - 1;
                if border {
                    assert_eq!(
                        h.events[i], 0.0,
                        "{name}: border pixel ({x}, {y}) crosses the surface"
                    );
                }
                if h.events[i] == 0.0 {
                    assert!(
                        h.u[i].is_finite() && h.v[i].is_finite(),
                        "{name}: ({x}, {y}) misses the backdrop"
                    );
                } else {
                    inner += 1;
                }
            }
        }
        assert!(
            inner >= w * ht / 20,
            "{name}: only {inner} pixels meet the surface"
        );
    }
    // Through a symbolic link -o to a scene elsewhere, the path is relative
    // to the folder of the file written; a dangling link counts as a file
    // that exists, and --force writes the file it names (whose folder must
    // exist).
    #[cfg(unix)]
    {
        std::fs::create_dir(t.path("links")).unwrap();
        std::fs::write(t.path("scenes/linked.toml"), "").unwrap();
        let link = t.path("links/ball.toml");
        std::os::unix::fs::symlink("../scenes/linked.toml", &link).unwrap();
        std::os::unix::fs::symlink("../scenes/new.toml", t.path("links/new.toml")).unwrap();
        std::os::unix::fs::symlink("../nowhere/gone.toml", t.path("links/gone.toml")).unwrap();
        for l in ["ball", "new"] {
            let o = t.run(&format!("scene ball.nrrd -o links/{l}.toml"));
            assert_fails(&o, &[".toml", "exists", "--force"]);
        }
        let o = t.run("scene ball.nrrd -o links/gone.toml --force");
        assert_fails(&o, &["gone.toml", "whose directory does not exist"]);
        ok(t.run("scene ball.nrrd -o links/new.toml --force"));
        let text = std::fs::read_to_string(t.path("scenes/new.toml")).unwrap();
        assert!(text.contains("path = \"../ball.nrrd\""), "{text}");
        ok(t.run("scene ball.nrrd -o links/ball.toml --force"));
        let text = std::fs::read_to_string(t.path("scenes/linked.toml")).unwrap();
        assert!(text.contains("path = \"../ball.nrrd\""), "{text}");
        assert!(
            std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink()
        );
    }
    // A scene file is replaced only when asked.
    let write = |extra: &str| -> (Output, String) {
        let o = t.run(&format!("scene ball.nrrd -o scenes/ball.toml {extra}"));
        let text = std::fs::read_to_string(t.path("scenes/ball.toml")).unwrap();
        (o, text)
    };
    let (o, _) = write("--iso 100 --filter bspline3");
    assert_fails(&o, &["ball.toml", "exists", "--force"]);
    let (o, text) = write("--iso 100 --filter bspline3 --force");
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        text.contains("filter = \"bspline3\"\niso = 100.0"),
        "{text}"
    );
    // The smoothing spline named takes the default λ as when defaulted, and
    // the values given are written to the last digit.
    let (o, text) = write("--filter smooth-bspline3 --iso 100.123456789 --ior 1.23456789 --force");
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        text.contains("lambda = 1.0\niso = 100.123456789\nior = 1.23456789\n"),
        "{text}"
    );
}

/// Volumes with an axis of one or two samples (no cells, or one layer of
/// them), in the camera's view, render with every traversal: not a panic,
/// and the same hits from each, every ray meeting the backdrop.
#[test]
fn thin_volumes_render_with_every_traversal() {
    let t = Tmp::new("thin");
    for size in [1, 2] {
        let mut first: Option<Vec<u8>> = None;
        for traversal in ["step", "dda", "octree", "distance"] {
            let o = t.run(&format!(
                "render {{sphere}} -q -o out.png --hits out.exr --set image.width=16 \
                 --set image.height=16 --set volume.phantom.size={size} \
                 --set render.traversal={traversal} --set camera.position=[0.5,0.5,-20] \
                 --set camera.look_at=[0.5,0.5,0.5] --set camera.fov_y=5"
            ));
            assert!(
                o.status.success(),
                "size {size}, {traversal}: {}",
                stderr(&o)
            );
            let h = snell::film::HitImage::read_exr(&t.path("out.exr")).unwrap();
            assert!(
                h.u.iter().all(|u| u.is_finite()),
                "size {size}, {traversal}"
            );
            let bytes = std::fs::read(t.path("out.exr")).unwrap();
            match &first {
                None => first = Some(bytes),
                Some(f) => assert!(
                    *f == bytes,
                    "size {size}: {traversal}'s hits differ from step's"
                ),
            }
        }
    }
}

#[test]
fn nan_samples_load_with_allow_nan() {
    let t = Tmp::new("allownan");
    let mut body =
        b"NRRD0004\ntype: float\ndimension: 3\nsizes: 2 1 1\nencoding: raw\nendian: little\n\n"
            .to_vec();
    body.extend_from_slice(&1.0f32.to_le_bytes());
    body.extend_from_slice(&f32::NAN.to_le_bytes());
    t.write("nan.nrrd", &body);
    let o = t.run("info nan.nrrd --allow-nan");
    assert!(
        o.status.success() && stderr(&o).contains("warning"),
        "{}",
        stderr(&o)
    );
}

/// The render's memory need (frame buffers and tile scratch) is checked
/// against the limit before anything is allocated: over it, exit 2 and no
/// output; the same limit lets a smaller image through.
#[test]
fn image_over_the_memory_limit_is_refused() {
    let t = Tmp::new("memlimit");
    // The sphere at `size`² pixels under an 8 MiB limit, writing
    // `name`.png, with `extra` arguments.
    let render = |name: &str, size: u32, extra: &str| {
        let line = format!(
            "render {{sphere}} -q -o {name}.png --set image.width={size} --set image.height={size}{extra}"
        );
        t.cmd(&line)
            .env("SNELL_MEMORY_LIMIT", "8M")
            .output()
            .unwrap()
    };
    let exists = |name: &str| t.path(name).exists();
    // 1024² pixels at 96 bytes of frame each: 96 MiB, over 8 MiB.
    assert_fails(
        &render("big", 1024, " --hits big.exr"),
        &["[image]", "1024x1024", "8.0 MiB"],
    );
    assert_eq!(t.0.read_dir().unwrap().count(), 0, "nothing left behind");
    // A part of that frame holds its region (and apron) only: 16² fits,
    // 400² does not, and says it is a part.
    ok(render("big", 1024, " --region 0,0,16,16"));
    std::fs::remove_file(t.path("big.png")).unwrap();
    assert_fails(
        &render("big", 1024, " --region 0,0,400,400"),
        &[
            "a 400x400 part (region and apron) of a 1024x1024 image",
            "lower the region",
        ],
    );
    assert!(!exists("big.png"));
    // 32² pixels (96 KiB) and the 64³ u8 phantom (4.3 MiB) fit.
    ok(render("small", 32, " --hits small.exr"));
    // A tile larger than the image holds the image's rays only: 16² pixels
    // of 16 rays, not 256² of them (hundreds of MiB).
    ok(render(
        "tiled",
        16,
        " --set render.supersampling=grid --set render.samples=4 --set render.tile=256",
    ));
    assert!(exists("small.png") && exists("small.exr"));
    // 256² pixels (6.4 MiB) fit alone, and so does the phantom, but not
    // both: the volume gets what the image leaves.
    assert_fails(
        &render("both", 256, " --hits both.exr"),
        &[
            "64x64x64 volume needs about 4.2 MiB",
            "the memory limit of 8.0 MiB less the 6.4 MiB the 256x256 image takes",
        ],
    );
    assert!(!exists("both.png") && !exists("both.exr"));
    // The same when a `--set` sized the volume and the error names it.
    assert_fails(
        &render("both", 256, " --set volume.phantom.size=64"),
        &[
            "--set volume.phantom.size=64: a 64x64x64 volume needs about 4.2 MiB",
            "the memory limit of 8.0 MiB less the 6.4 MiB the 256x256 image takes",
        ],
    );
    assert!(!exists("both.png"));
}

/// Separate processes with 1 and 2 worker threads, and with another tile
/// size, and from a cold and a warm `--cache`, write byte-identical
/// hit-position EXRs (and PNGs).
#[test]
fn hits_are_bitwise_identical_across_threads_and_tiles() {
    let t = Tmp::new("determinism");
    // The cached runs: the first fills the cache, the second renders from
    // coefficients and tags read back from disk; both must match exactly.
    let runs = [
        ("t1", "--threads 1"),
        ("t2", "--threads 2"),
        ("t2-tile7", "--threads 2 --set render.tile=7"),
        ("cache-cold", "--cache cache"),
        ("cache-warm", "--cache cache"),
    ];
    let mut outputs = Vec::new();
    for (name, extra) in runs {
        let o = t.run(&format!(
            "render {{sphere}} -q -o {name}.png --hits {name}.exr \
             --set image.width=90 --set image.height=70 {extra}"
        ));
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        outputs.push((
            name,
            std::fs::read(t.path(&format!("{name}.exr"))).unwrap(),
            std::fs::read(t.path(&format!("{name}.png"))).unwrap(),
        ));
    }
    // The image is not trivial: many rays refract through the sphere.
    let h = snell::film::HitImage::read_exr(&t.path("t1.exr")).unwrap();
    assert_eq!((h.width, h.height), (90, 70));
    let refracted = h.events.iter().filter(|&&e| e >= 2.0).count();
    assert!(refracted > 500, "{refracted} refracted pixels");
    let cached = std::fs::read_dir(t.path("cache")).unwrap().count();
    assert!(
        cached >= 3,
        "{cached} files in the cache (coefficients, tags, curvature bounds)"
    );
    let (_, hits1, png1) = &outputs[0];
    for (name, hits, png) in &outputs[1..] {
        assert!(hits == hits1, "{name}: hit EXR differs from --threads 1");
        assert!(png == png1, "{name}: PNG differs from --threads 1");
    }
}

/// Every instruction set (`SNELL_ISA`: AVX-512, AVX2, the portable lanes;
/// a level the CPU lacks falls back to the best it has) writes the same
/// hits, PNG and colour EXR: the cubic filters' dedicated vector kernels
/// and the generic lanes keep one order of fused multiply-adds. On a CT
/// scan, whose rays cross many interfaces, where a last-bit difference
/// grows into other crossings; with PRSS, which reads the hits' map.
#[test]
fn instruction_sets_give_the_same_bits() {
    let t = Tmp::new("isa");
    let teapot = root().join("scenes/teapot.toml");
    for filter in ["bspline3", "catmull-rom", "bspline2", "linear"] {
        let mut first: Option<Vec<Vec<u8>>> = None;
        for isa in ["avx512", "avx2", "portable"] {
            let o = t
                .cmd(&format!(
                    "render {} -q -o {isa}.png --hits {isa}.exr --exr {isa}-c.exr \
                     --set image.width=64 --set image.height=64 --set surface.filter={filter} \
                     --set surface.lambda=0 --set render.supersampling=prss --stats {isa}.json",
                    teapot.display()
                ))
                .env("SNELL_ISA", isa)
                .output()
                .unwrap();
            assert!(o.status.success(), "{filter} {isa}: {}", stderr(&o));
            // The level asked for ran, or the CPU lacks it (then the
            // comparison is weaker, and says so; CI on an AVX-512 CPU
            // requires it).
            let stats: serde_json::Value =
                serde_json::from_slice(&std::fs::read(t.path(&format!("{isa}.json"))).unwrap())
                    .unwrap();
            let ran = stats["isa"].as_str().unwrap();
            let here = (snell::simd::Isa::available().iter()).any(|i| i.name().starts_with(isa));
            if here || snell::env::setting("SNELL_REQUIRE_AVX512").is_some() {
                assert!(ran.starts_with(isa), "{filter}: {isa} asked, {ran} ran");
            } else {
                eprintln!("this CPU cannot run {isa}: compared {ran} in its place");
            }
            let files: Vec<Vec<u8>> = ["png", "exr"]
                .iter()
                .map(|e| std::fs::read(t.path(&format!("{isa}.{e}"))).unwrap())
                .chain([std::fs::read(t.path(&format!("{isa}-c.exr"))).unwrap()])
                .collect();
            match &first {
                None => {
                    let h = snell::film::HitImage::read_exr(&t.path(&format!("{isa}.exr")));
                    let deep = h.unwrap().events.iter().filter(|&&e| e >= 4.0).count();
                    assert!(deep > 100, "{filter}: {deep} pixels with 4 events or more");
                    first = Some(files);
                }
                Some(f) => {
                    for (k, what) in ["PNG", "hits", "colour EXR"].iter().enumerate() {
                        assert!(
                            f[k] == files[k],
                            "{filter}: {isa}'s {what} differs from avx512's"
                        );
                    }
                }
            }
        }
    }
}

/// An input that is a FIFO (a volume, a volume's data file, a scene, a
/// photograph, an image or EXR, a points file) is refused at once instead
/// of waiting for a writer forever, by every reader; so is a device. Each
/// command must end within seconds.
#[cfg(unix)]
#[test]
fn inputs_that_are_not_files_are_refused_without_waiting() {
    let t = Tmp::new("fifo");
    let fifo = |name: &str| {
        let p = t.path(name);
        let c = std::ffi::CString::new(p.to_str().unwrap()).unwrap();
        // SAFETY: a valid NUL-terminated path; mkfifo only creates a node.
        assert_eq!(
            unsafe { libc::mkfifo(c.as_ptr(), 0o600) },
            0,
            "mkfifo {name}"
        );
    };
    for name in ["v.nrrd", "v.nii", "v.mha", "v.raw", "data.raw"] {
        fifo(name);
    }
    t.write(
        "d.nhdr",
        b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: data.raw\n",
    );
    t.write(
        "d.mhd",
        b"NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = data.raw\n",
    );
    // The other inputs: a scene, a backdrop photograph, images and hit
    // EXRs to compare, parts to merge, points to sample.
    for name in ["scene.toml", "photo.jpg", "a.png", "a.exr", "points.csv"] {
        fifo(name);
    }
    t.write(
        "v2.nrrd",
        b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\n\0\0\0\0\0\0\0\0",
    );
    // Where a `--set` path is resolved from is the scene's business: the
    // photograph is named in full.
    let photo = format!(
        "render {{photo}} --set backdrop.image={} -o out.exr",
        t.path("photo.jpg").display()
    );
    for line in [
        "info v.nrrd",
        "info v.nii",
        "info v.mha",
        "info v.raw --dims 2,2,2 --type u8",
        "info d.nhdr",
        "info d.mhd",
        "info /dev/zero --dims 2,2,2 --type u8",
        "render scene.toml -o out.exr",
        &photo,
        "compare a.png a.png",
        "compare a.exr a.exr",
        "merge a.exr -o out.exr",
        "sample v2.nrrd --filter linear --points points.csv",
    ] {
        let mut child = t
            .cmd(line)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let start = std::time::Instant::now();
        while child.try_wait().unwrap().is_none() {
            if start.elapsed() > std::time::Duration::from_secs(20) {
                let _ = child.kill();
                panic!("{line} still waiting after 20 s");
            }
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        let o = child.wait_with_output().unwrap();
        assert_fails(&o, &["not a regular file"]);
    }
}

/// `render --orbit 8` writes every frame under its pattern's names and
/// times them in `--stats`; frame 0 is the plain render bit for bit; the
/// quarter turns see the sphere phantom exactly as frame 0 does (its grid
/// maps onto itself under a quarter turn about its centre, and the camera
/// and backdrop turn together), while the 45° frames, across the grid's
/// diagonals, do not.
#[test]
fn orbit_turns_the_view_about_the_volume() {
    let t = Tmp::new("orbit");
    let size = "--set image.width=64 --set image.height=48";
    let o = ok(t.run(&format!(
        "render {{sphere}} -o f-%02d.png --hits h-%02d.exr --stats s.json --orbit 8 {size}"
    )));
    let err = stderr(&o);
    assert!(err.contains("frame 2 at 90°"), "{err}");
    assert!(err.contains("8 frames: median"), "{err}");
    for k in 0..8 {
        assert!(t.path(&format!("f-{k:02}.png")).is_file(), "frame {k}");
    }
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(t.path("s.json")).unwrap()).unwrap();
    assert_eq!(s["orbit"]["frames"], 8);
    assert_eq!(s["orbit"]["frame_ms"].as_array().unwrap().len(), 8);

    ok(t.run(&format!(
        "render {{sphere}} -q -o plain.png --hits plain.exr {size}"
    )));
    let plain = t.path("plain.exr");
    let read = |p: &Path| snell::film::HitImage::read_exr(p).unwrap();
    let frame = |k: usize| read(&t.path(&format!("h-{k:02}.exr")));
    let f0 = frame(0);
    assert_eq!(
        std::fs::read(t.path("h-00.exr")).unwrap(),
        std::fs::read(&plain).unwrap(),
        "frame 0 is the plain render"
    );
    let refracted = f0.events.iter().filter(|&&e| e >= 2.0).count();
    assert!(refracted > 500, "{refracted}");
    let differing = |f: &snell::film::HitImage| {
        (0..f0.events.len())
            .filter(|&i| {
                f.events[i] != f0.events[i]
                    || (f.u[i] - f0.u[i]).abs() > 1e-3
                    || (f.v[i] - f0.v[i]).abs() > 1e-3
            })
            .count()
    };
    for k in [2, 4, 6] {
        assert_eq!(differing(&frame(k)), 0, "quarter turn {k}");
    }
    for k in [1, 3, 5, 7] {
        let d = differing(&frame(k));
        assert!(
            d > 20,
            "the 45° frame {k} differs from frame 0 on only {d} pixels"
        );
    }
}

/// Off a terminal (a batch job's log) a long render writes a plain progress
/// line every `SNELL_PROGRESS_SECONDS`; `-q`, `0` or a short render write
/// none, and a value that is not seconds is a warning, not a failure.
#[test]
fn logs_get_progress_lines_instead_of_a_bar() {
    let t = Tmp::new("progress");
    let render = |every: &str, size: &str, quiet: bool| {
        let q = if quiet { " -q" } else { "" };
        let line = format!(
            "render {{sphere}} -o a.png --set image.width={size} --set image.height={size}{q}"
        );
        let o = ok(t
            .cmd(&line)
            .env("SNELL_PROGRESS_SECONDS", every)
            .output()
            .unwrap());
        stderr(&o)
    };
    let lines = |err: &str| {
        err.lines()
            .filter(|l| l.starts_with("rendering: "))
            .map(str::to_string)
            .collect::<Vec<_>>()
    };
    // 2048² takes some 16 times the 512² frame: many 50 ms intervals.
    let err = render("0.05", "2048", false);
    let logged = lines(&err);
    assert!(!logged.is_empty(), "{err}");
    for l in &logged {
        assert!(
            l.contains(" of 4096 tiles (") && l.contains(" so far"),
            "{l}"
        );
    }
    assert!(err.contains("per ray:"), "the stats table follows: {err}");
    assert!(lines(&render("0.05", "2048", true)).is_empty(), "-q");
    assert!(
        lines(&render("0", "1024", false)).is_empty(),
        "0 turns lines off"
    );
    assert!(
        lines(&render("30", "64", false)).is_empty(),
        "a short render"
    );
    let err = render("soon", "64", false);
    assert!(
        err.contains("warning: SNELL_PROGRESS_SECONDS: expected seconds"),
        "{err}"
    );
}

/// A frame rendered as three `--region` parts and joined by `snell merge`
/// equals the whole-frame render bit for bit — hit positions and colour —
/// with each post stage that reads neighbouring pixels (PRSS with both
/// fallbacks, the EWA footprint) and with real supersampling.
#[test]
fn region_parts_merge_to_the_whole_frame() {
    let t = Tmp::new("region");
    let bits = |name: &str| -> Vec<(String, Vec<u32>)> {
        let part = snell::film::merge::read_part(&t.path(name)).unwrap();
        assert_eq!((part.at.origin, part.at.full), ([0, 0], [96, 80]));
        part.channels
            .into_iter()
            .map(|(n, d)| (n, d.iter().map(|x| x.to_bits()).collect()))
            .collect()
    };
    let frame = "render {sphere} -q --set image.width=96 --set image.height=80 \
                 --set render.traversal=octree";
    for (m, sets) in [
        "--set render.supersampling=prss",
        "--set render.supersampling=prss --set render.prss_fallback=blend-trace",
        "--set render.supersampling=footprint --set render.footprint=ewa",
        "--set render.supersampling=grid --set render.samples=2",
    ]
    .iter()
    .enumerate()
    {
        let render = |name: &str, region: &str| {
            let o = t.run(&format!(
                "{frame} {sets} -o {name}.png --hits {name}-hits.exr --exr {name}-color.exr{region}"
            ));
            assert!(o.status.success(), "{sets} {region}: {}", stderr(&o));
        };
        let whole = format!("whole{m}");
        render(&whole, "");
        let regions = ["0,0,37,50", "37,0,96,50", "0,50,96,80"];
        for (k, r) in regions.iter().enumerate() {
            render(&format!("part{m}-{k}"), &format!(" --region {r}"));
        }
        let part = image::open(t.path(&format!("part{m}-1.png"))).unwrap();
        assert_eq!((part.width(), part.height()), (59, 50));
        if m == 0 {
            // The stats say which part of which frame they measured.
            ok(t.run(&format!(
                "{frame} {sets} -o s.png --stats s.json --region 37,0,96,50"
            )));
            let j: serde_json::Value =
                serde_json::from_slice(&std::fs::read(t.path("s.json")).unwrap()).unwrap();
            assert_eq!(j["region"], serde_json::json!([37, 0, 96, 50]));
            assert_eq!(
                (j["width"].as_u64(), j["height"].as_u64()),
                (Some(96), Some(80))
            );
            let o = ok(t.run(&format!(
                "{} {sets} -o s.png --region 37,0,96,50",
                frame.replace(" -q", "")
            )));
            let table = String::from_utf8_lossy(&o.stdout).to_string() + &stderr(&o);
            assert!(
                table.contains("59x50 region 37,0,96,50 of 96x80 in"),
                "{table}"
            );
        }
        for kind in ["hits", "color"] {
            let parts = [2, 0, 1].map(|k| format!("part{m}-{k}-{kind}.exr"));
            let png = match kind {
                "color" => format!(" --png merged{m}.png"),
                _ => String::new(),
            };
            let merged = format!("merged{m}-{kind}.exr");
            ok(t.run(&format!("merge {} -o {merged}{png}", parts.join(" "))));
            assert!(
                bits(&merged) == bits(&format!("{whole}-{kind}.exr")),
                "{sets}: merged {kind} differ from the whole frame"
            );
            // The file itself, header included: a merged frame is a whole
            // frame, without the parts' fingerprint.
            let bytes = |n: &str| std::fs::read(t.path(n)).unwrap();
            assert!(
                bytes(&merged) == bytes(&format!("{whole}-{kind}.exr")),
                "{sets}: merged {kind} file differs from the whole frame's"
            );
        }
        let png = |n: &str| image::open(t.path(n)).unwrap().to_rgb8().into_raw();
        assert!(png(&format!("merged{m}.png")) == png(&format!("{whole}.png")));
    }
    // A missing part, overlapping parts and hit parts into a PNG are errors.
    let (p0, p1, p2) = ("part0-0-hits.exr", "part0-1-hits.exr", "part0-2-hits.exr");
    let o = t.run(&format!("merge {p0} {p1} -o bad.exr"));
    assert_fails(&o, &["2880 of 7680 pixels uncovered", "(0, 50)"]);
    let o = t.run(&format!("merge {p0} {p0} {p1} {p2} -o bad.exr"));
    assert_fails(&o, &["both cover pixel (0, 0)"]);
    let o = t.run(&format!("merge {p0} {p1} {p2} -o bad.exr --png bad.png"));
    assert_fails(&o, &["no R, G, B channels"]);
    assert!(!t.path("bad.exr").exists() && !t.path("bad.png").exists());
    // A part of another frame (another ior) is refused, naming both parts;
    // one rendered with another tile size and thread count, a walk shortcut
    // off, an ignored step, and another cell traversal and classification
    // is the same frame's, bit for bit.
    let other = |name: &str, sets: &str| {
        ok(t.run(&format!(
            "{frame} --region 0,50,96,80 --set render.supersampling=prss \
             -o {name}.png --hits {name}.exr {sets}"
        )));
    };
    other("ior", "--set surface.ior=1.3");
    let o = t.run(&format!("merge {p0} {p1} ior.exr -o bad.exr"));
    assert_fails(
        &o,
        &[
            "part0-0-hits.exr and",
            "ior.exr are parts of different frames: the surface (filter, iso-value or ior) differs (frame ",
        ],
    );
    other(
        "ior-grid",
        "--set surface.ior=1.3 --set render.supersampling=grid --set render.samples=2",
    );
    let o = t.run(&format!("merge {p0} {p1} ior-grid.exr -o bad.exr"));
    assert_fails(
        &o,
        &[
            "frames: the surface (filter, iso-value or ior) and the [render] settings differ (frame ",
        ],
    );
    other(
        "tiled",
        "--set render.tile=8 --threads 1 --set render.clear_crossing_cells=false \
         --set render.step=0.5 --set render.traversal=distance --set render.classify=accc8",
    );
    ok(t.run(&format!("merge {p0} {p1} tiled.exr -o mixed.exr")));
    ok(t.run(&format!("merge {p0} {p1} {p2} -o same.exr")));
    assert!(
        std::fs::read(t.path("mixed.exr")).unwrap() == std::fs::read(t.path("same.exr")).unwrap(),
        "a part by other cell traversal changes the merged frame"
    );
    let o = t.run("render {sphere} -o r.png --region 0,0,600,10");
    assert_fails(&o, &["--region", "X1 <= 512"]);
    let o = t.run("render {sphere} -o r.png --region 5,5,5");
    assert_fails(&o, &["--region '5,5,5'", "X0,Y0,X1,Y1"]);
}

/// A `w×h` grey PNG whose value at `(x, y)` is `f(x, y)`.
fn grey_png(t: &Tmp, name: &str, w: u32, h: u32, f: impl Fn(u32, u32) -> u8) {
    image::RgbImage::from_fn(w, h, |x, y| image::Rgb([f(x, y); 3]))
        .save(t.path(name))
        .unwrap();
}

#[test]
fn compare_images_reports_metrics_and_writes_a_diff() {
    let t = Tmp::new("cmpimg");
    let checker = |x: u32, y: u32| {
        if (x / 4 + y / 4).is_multiple_of(2) {
            200
        } else {
            40
        }
    };
    grey_png(&t, "a.png", 32, 24, checker);
    // Every value 20/255 brighter: RMSE 20/255, PSNR 20·log10(255/20).
    grey_png(&t, "b.png", 32, 24, |x, y| checker(x, y) + 20);
    let o = ok(t.run("compare a.png b.png --json --diff diff.png"));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let num = |k: &str| j[k].as_f64().unwrap_or_else(|| panic!("{k} in {j}"));
    let d = 20.0 / 255.0;
    assert!((num("rmse") - d).abs() < 1e-6, "{j}");
    assert!((num("max_abs") - d).abs() < 1e-6, "{j}");
    assert!(
        (num("psnr") - 20.0 * (255.0f64 / 20.0).log10()).abs() < 1e-4,
        "{j}"
    );
    // Same structure, shifted mean: SSIM just below 1.
    assert!(num("ssim") > 0.9 && num("ssim") < 1.0, "{j}");
    // The heat map: same size, every pixel |diff| = 20/255 → (3·2d, 0, 0).
    let heat = image::open(t.path("diff.png")).unwrap().to_rgb8();
    assert_eq!(heat.dimensions(), (32, 24));
    let red = (3.0 * 2.0 * d * 255.0f64).round() as u8;
    assert!(
        heat.pixels().all(|p| p.0 == [red, 0, 0]),
        "{:?}",
        heat.get_pixel(0, 0)
    );

    // Text output; an image against itself is perfect.
    let o = ok(t.run("compare a.png a.png"));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("RMSE 0.00000")
            && text.contains("PSNR inf dB")
            && text.contains("SSIM 1.0000"),
        "{text}"
    );
    // A local difference shows where it is in the heat map, nowhere else.
    grey_png(&t, "c.png", 32, 24, |x, y| {
        if (10..14).contains(&x) && (5..9).contains(&y) {
            255 - checker(x, y)
        } else {
            checker(x, y)
        }
    });
    ok(t.run("compare c.png a.png --diff diff2.png"));
    let heat = image::open(t.path("diff2.png")).unwrap().to_rgb8();
    for (x, y, p) in heat.enumerate_pixels() {
        let inside = (10..14).contains(&x) && (5..9).contains(&y);
        assert_eq!(p.0 == [255, 255, 255], inside, "({x}, {y}): {:?}", p.0);
        if !inside {
            assert_eq!(p.0, [0, 0, 0]);
        }
    }

    // Different sizes: one error line, exit 2, no diff written.
    grey_png(&t, "small.png", 16, 24, checker);
    let o = t.run("compare small.png a.png --diff diff3.png");
    assert_fails(&o, &["small.png", "differ in size"]);
    assert!(!t.path("diff3.png").exists());
}

/// Every key a scene file takes stands in README.md's table of keys: each
/// section's refusal of an unknown key lists that section's keys, and
/// every one of them must be a row's (`a.b.c`, or a bare `d` after it in
/// the same cell, which shares its section).
#[test]
fn every_scene_key_is_in_the_readme_table() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let mut documented = Vec::new();
    for row in readme.lines().filter(|l| l.starts_with("| `")) {
        let cell = row.split('|').nth(1).unwrap();
        let mut section = String::new();
        for item in cell.split(',').map(|i| i.trim().trim_matches('`')) {
            match item.rsplit_once('.') {
                Some((s, _)) => {
                    section = s.to_string();
                    documented.push(item.to_string());
                }
                None => documented.push(format!("{section}.{item}")),
            }
        }
    }
    let scene = root().join("scenes/sphere.toml");
    let listed = |section: &str, set: &str| -> Vec<String> {
        let e = snell::scene::Scene::load(&scene, &[set.to_string()])
            .unwrap_err()
            .to_string();
        let (_, keys) = e
            .split_once("expected one of ")
            .unwrap_or_else(|| panic!("{set}: {e}"));
        keys.split(", ")
            .map(|k| format!("{section}.{}", k.trim().trim_matches('`')))
            .collect()
    };
    let mut keys = Vec::new();
    for section in [
        "image",
        "camera",
        "volume",
        "volume.raw",
        "surface",
        "backdrop",
        "render",
    ] {
        keys.extend(listed(section, &format!("{section}.zzz=1")));
    }
    for kind in ["sphere", "marschner-lobb"] {
        keys.extend(listed(
            "volume.phantom",
            &format!("volume.phantom={{kind=\"{kind}\", zzz=1}}"),
        ));
    }
    assert!(keys.len() > 50, "{keys:?}");
    // A table (`volume.raw`) is documented by its keys.
    let missing: Vec<&String> = keys
        .iter()
        .filter(|k| {
            !documented
                .iter()
                .any(|d| d == *k || d.starts_with(&format!("{k}.")))
        })
        .collect();
    assert!(
        missing.is_empty(),
        "not in README.md's table of scene keys: {missing:?}"
    );
}

/// An output that cannot be written is refused before the render, and the
/// render's other outputs are not left behind (`/proc` takes no new files,
/// even from root).
#[test]
fn an_unwritable_output_is_refused_before_the_work() {
    let t = Tmp::new("unwritable");
    let o = t.run(
        "render {sphere} -o o.png --stats /proc/snell-stats.json \
         --set image.width=32 --set image.height=32",
    );
    assert_fails(&o, &["/proc/snell-stats.json: cannot write in /proc"]);
    assert!(!t.path("o.png").exists(), "no image from a failed command");
    assert_eq!(listing(&t.0), Vec::new());
}

/// Interrupted while its outputs are being written (Ctrl-C, SIGTERM), a
/// render leaves no temporary file and ends by the signal, as the shell
/// expects of an interrupted command; its outputs appear all together or
/// not at all. A signal it was started to ignore (`nohup`) stays ignored.
#[test]
fn an_interrupted_render_leaves_no_debris() {
    use std::os::unix::process::ExitStatusExt;
    for signal in [libc::SIGINT, libc::SIGTERM] {
        let t = Tmp::new(&format!("interrupt-{signal}"));
        // On a loaded machine the render may finish its writes between the
        // sight of a temporary file and the signal: then all its outputs
        // are there (never some), and it is tried again.
        let mut attempts = 0;
        let o = loop {
            attempts += 1;
            let mut cmd = t.cmd(
                "render {sphere} -o o.png --hits h.exr --exr c.exr \
                 --set image.width=2048 --set image.height=2048 -q",
            );
            // A test run started in the background of a shell ignores
            // SIGINT, and so would the render (as it should): the child
            // starts with the default disposition, as from a terminal.
            // SAFETY: `signal` is async-signal-safe; nothing else runs
            // between fork and exec.
            unsafe {
                use std::os::unix::process::CommandExt;
                cmd.pre_exec(|| {
                    libc::signal(libc::SIGINT, libc::SIG_DFL);
                    Ok(())
                });
            }
            let mut child = cmd.stderr(std::process::Stdio::piped()).spawn().unwrap();
            // Waits for the first temporary output file, then interrupts.
            let start = std::time::Instant::now();
            let mut writing = false;
            while child.try_wait().unwrap().is_none() && start.elapsed().as_secs() < 60 {
                let names: Vec<String> = std::fs::read_dir(&t.0)
                    .unwrap()
                    .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                    .collect();
                if names.iter().any(|n| n.ends_with(".tmp")) {
                    writing = true;
                    // SAFETY: signalling our own child process.
                    unsafe { libc::kill(child.id() as i32, signal) };
                    break;
                }
                std::thread::sleep(std::time::Duration::from_micros(200));
            }
            let o = child.wait_with_output().unwrap();
            assert!(writing, "the render ended before its outputs were begun");
            if o.status.signal().is_none() && o.status.success() && attempts < 5 {
                // `listing` sorts by path.
                let left: Vec<String> = listing(&t.0)
                    .into_iter()
                    .map(|(p, _)| p.file_name().unwrap().to_string_lossy().into_owned())
                    .collect();
                assert_eq!(left, ["c.exr", "h.exr", "o.png"], "all outputs or none");
                for f in left {
                    std::fs::remove_file(t.path(&f)).unwrap();
                }
                continue;
            }
            break o;
        };
        assert_eq!(
            o.status.signal(),
            Some(signal),
            "{}: {}",
            o.status,
            stderr(&o)
        );
        assert!(stderr(&o).contains("interrupted"), "{}", stderr(&o));
        let left: Vec<PathBuf> = listing(&t.0).into_iter().map(|(p, _)| p).collect();
        assert!(left.is_empty(), "{left:?}");
    }
    // Under nohup (SIGHUP ignored from the start) the hang-up is ignored.
    let t = Tmp::new("nohup");
    let mut child = Command::new("nohup")
        .arg(env!("CARGO_BIN_EXE_snell"))
        .args(args(
            "render {sphere} -q -o o.png --set image.width=1024 --set image.height=1024",
        ))
        .current_dir(&t.0)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(100));
    // SAFETY: signalling our own child process.
    unsafe { libc::kill(child.id() as i32, libc::SIGHUP) };
    let status = child.wait().unwrap();
    assert!(status.success(), "{status:?}");
    assert!(t.path("o.png").exists());
}
