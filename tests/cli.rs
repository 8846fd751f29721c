//! The command line end to end: outputs on good input, and on bad input a
//! one-line error naming the file and problem, exit code 2, no panic and no
//! output file.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_snell"))
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn data(name: &str) -> PathBuf {
    root().join("../shared/data").join(name)
}

struct Tmp(PathBuf);
impl Tmp {
    fn new(tag: &str) -> Tmp {
        let p = std::env::temp_dir().join(format!("snell-cli-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir_all(&p).unwrap();
        Tmp(p)
    }
    fn path(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }
    fn write(&self, name: &str, bytes: &[u8]) -> PathBuf {
        let p = self.path(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }
}
impl Drop for Tmp {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn run(args: &[&str]) -> Output {
    bin().args(args).output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Exit 2, one `error:` line containing every `needle`, no panic.
fn assert_fails(o: &Output, needles: &[&str]) {
    let e = stderr(o);
    assert_eq!(o.status.code(), Some(2), "exit code; stderr: {e}");
    assert!(!e.contains("panicked"), "panic: {e}");
    let errs: Vec<&str> = e.lines().filter(|l| l.starts_with("error")).collect();
    assert_eq!(errs.len(), 1, "one error line: {e}");
    for n in needles {
        assert!(errs[0].contains(n), "'{n}' not in: {}", errs[0]);
    }
}

const SPHERE: &str = "scenes/sphere.toml";

fn scene_file(t: &Tmp, name: &str, edit: impl Fn(String) -> String) -> PathBuf {
    let text = std::fs::read_to_string(root().join(SPHERE)).unwrap();
    t.write(name, edit(text).as_bytes())
}

#[test]
fn info_json_has_the_promised_keys() {
    let o = run(&["info", data("cranium-ct.nrrd").to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["dims"], serde_json::json!([256, 256, 108]));
    assert_eq!(j["type"], "u16");
    assert!((j["spacing"][2].as_f64().unwrap() - 1.5).abs() < 1e-9);
    assert!(j["min"].as_f64().unwrap() <= j["max"].as_f64().unwrap());
    let o = run(&[
        "info",
        data("headsq-quarter-ct_64x64x93_u16le.raw")
            .to_str()
            .unwrap(),
        "--dims",
        "64,64,93",
        "--type",
        "u16",
        "--spacing",
        "3.2,3.2,1.5",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("iso-values worth trying"));
}

#[test]
fn sample_prints_csv_in_input_order() {
    let t = Tmp::new("sample");
    let pts = t.write("p.txt", b"# grid points\n10,20,30\n\n10.5 20.25 30.75\n");
    let o = run(&[
        "sample",
        data("engine.nrrd").to_str().unwrap(),
        "--filter",
        "bspline3",
        "--points",
        pts.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines[0], "x,y,z,value,gx,gy,gz");
    assert_eq!(lines.len(), 3);
    assert!(lines[1].starts_with("10,20,30,"));
    assert!(lines[2].starts_with("10.5,20.25,30.75,"));
    assert_eq!(lines[2].split(',').count(), 7);
}

#[test]
fn phantom_writes_a_loadable_nrrd() {
    let t = Tmp::new("phantom");
    let p = t.path("ball.nrrd");
    let o = run(&[
        "phantom",
        "sphere",
        "--size",
        "24",
        "--radius",
        "6",
        "--sigma",
        "1.5",
        "--format",
        "u8",
        "--hole",
        "11.5,11.5,11.5,2,0.5",
        "-o",
        p.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run(&["info", p.to_str().unwrap(), "--json"]);
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["dims"], serde_json::json!([24, 24, 24]));
    assert_eq!(j["type"], "u8");
    assert_eq!(j["max"], 255.0);
    let o = run(&[
        "phantom",
        "marschner-lobb",
        "-o",
        t.path("ml.nrrd").to_str().unwrap(),
        "--gzip",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn render_writes_every_output() {
    let t = Tmp::new("render");
    let (png, hits, exr, stats) = (
        t.path("a.png"),
        t.path("h.exr"),
        t.path("c.exr"),
        t.path("s.json"),
    );
    let o = run(&[
        "render",
        root().join(SPHERE).to_str().unwrap(),
        "-o",
        png.to_str().unwrap(),
        "--hits",
        hits.to_str().unwrap(),
        "--exr",
        exr.to_str().unwrap(),
        "--stats",
        stats.to_str().unwrap(),
        "--threads",
        "2",
        "--set",
        "image.width=64",
        "--set",
        "image.height=48",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("per ray:"), "stats table on stderr");
    for p in [&png, &hits, &exr, &stats] {
        assert!(p.metadata().unwrap().len() > 0, "{}", p.display());
    }
    let s: serde_json::Value = serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
    assert_eq!(s["counters"]["rays"], 64 * 48);
    assert_eq!(s["counters"]["undefined"], 0);
    for stage in [
        "generate", "entry", "traverse", "solve", "refract", "record",
    ] {
        assert!(s["stage_cpu_s"][stage].is_number(), "{stage}");
    }
    // The reference and compare commands close the loop.
    let f32s = root().join("scenes/sphere-f32.toml");
    let r = t.path("ref.exr");
    let o = run(&[
        "reference",
        f32s.to_str().unwrap(),
        "--hits",
        r.to_str().unwrap(),
        "--set",
        "image.width=64",
        "--set",
        "image.height=48",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run(&[
        "compare",
        hits.to_str().unwrap(),
        r.to_str().unwrap(),
        "--checker",
        "8",
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let c: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(c["pixels"], 64 * 48);
}

#[test]
fn iso_outside_the_data_is_a_warning_and_a_backdrop_image() {
    let t = Tmp::new("iso");
    let png = t.path("b.png");
    let o = run(&[
        "render",
        root().join(SPHERE).to_str().unwrap(),
        "-o",
        png.to_str().unwrap(),
        "--set",
        "surface.iso=300",
        "--set",
        "image.width=32",
        "--set",
        "image.height=32",
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("warning") && stderr(&o).contains("outside the data range"));
    assert!(png.exists());
}

#[test]
fn bad_volume_inputs() {
    let t = Tmp::new("badvol");
    let nrrd = |body: &str, data: &[u8]| {
        let mut v = body.as_bytes().to_vec();
        v.extend_from_slice(data);
        v
    };
    let cases: Vec<(PathBuf, Vec<&str>, Vec<&str>)> = vec![
        (t.write("trunc.nrrd", &nrrd("NRRD0004\ntype: uint8\ndimension: 3\nsizes: 4 4 4\nencoding: raw\n\n", &[0; 10])), vec![], vec!["trunc.nrrd"]),
        (t.write("sizes.nrrd", &nrrd("NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\n", &[0; 9])), vec![], vec!["sizes.nrrd", "match"]),
        (t.write("type.nrrd", &nrrd("NRRD0004\ntype: quaternion\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\n", &[0; 8])), vec![], vec!["type.nrrd", "quaternion"]),
        (t.write("enc.nrrd", &nrrd("NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: bzip2\n\n", &[0; 8])), vec![], vec!["enc.nrrd", "bzip2"]),
        (t.write("zero.nrrd", &nrrd("NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 0 2\nencoding: raw\n\n", &[])), vec![], vec!["zero.nrrd"]),
        (t.write("huge.nrrd", &nrrd("NRRD0004\ntype: float\ndimension: 3\nsizes: 100000 100000 100000\nencoding: raw\nendian: little\n\n", &[0; 16])), vec![], vec!["huge.nrrd"]),
        (t.write("garbage.nrrd", b"\x00\x01hello"), vec![], vec!["garbage.nrrd"]),
        (t.write("x.vol", b"abc"), vec![], vec!["x.vol", "unknown volume format"]),
        (t.path("missing.nrrd"), vec![], vec!["missing.nrrd"]),
        (t.write("r.raw", &[0; 10]), vec!["--dims", "2,2,2", "--type", "u16"], vec!["r.raw"]),
        (t.write("r0.raw", &[0; 10]), vec!["--dims", "0,2,2", "--type", "u8"], vec!["r0.raw"]),
        (t.write("rov.raw", &[0; 10]), vec!["--dims", "18446744073709551615,2,2", "--type", "u8"], vec!["rov.raw", "overflow"]),
        (t.write("rt.raw", &[0; 8]), vec!["--dims", "2,2,2", "--type", "u128"], vec!["--type", "u128"]),
        (t.write("rd.raw", &[0; 8]), vec!["--dims", "2,2"], vec!["--dims"]),
        (t.write("big.raw", &[0; 8]), vec!["--dims", "2,2,2", "--type", "u8", "--memory-limit", "16"], vec!["big.raw", "limit"]),
    ];
    for (path, extra, needles) in cases {
        let mut args = vec!["info", path.to_str().unwrap()];
        args.extend(extra.iter());
        assert_fails(&run(&args), &needles);
    }
    // NaN in float data: rejected with counts, accepted with --allow-nan.
    let mut body =
        b"NRRD0004\ntype: float\ndimension: 3\nsizes: 2 1 1\nencoding: raw\nendian: little\n\n"
            .to_vec();
    body.extend_from_slice(&1.0f32.to_le_bytes());
    body.extend_from_slice(&f32::NAN.to_le_bytes());
    let p = t.write("nan.nrrd", &body);
    assert_fails(
        &run(&["info", p.to_str().unwrap()]),
        &["nan.nrrd", "NaN", "--allow-nan"],
    );
    let o = run(&["info", p.to_str().unwrap(), "--allow-nan"]);
    assert!(
        o.status.success() && stderr(&o).contains("warning"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn bad_sample_inputs() {
    let t = Tmp::new("badsample");
    let vol = data("tooth.nrrd");
    let v = vol.to_str().unwrap();
    let good = t.write("good.txt", b"1,2,3\n");
    let bad = t.write("bad.txt", b"1,2,3\n4,5\n");
    let nan = t.write("nan.txt", b"1,2,3\n\n1,nan,3\n");
    assert_fails(
        &run(&[
            "sample",
            v,
            "--filter",
            "bspline3",
            "--points",
            bad.to_str().unwrap(),
        ]),
        &["bad.txt", "line 2"],
    );
    assert_fails(
        &run(&[
            "sample",
            v,
            "--filter",
            "bspline3",
            "--points",
            nan.to_str().unwrap(),
        ]),
        &["nan.txt", "line 3"],
    );
    assert_fails(
        &run(&[
            "sample",
            v,
            "--filter",
            "gauss",
            "--points",
            good.to_str().unwrap(),
        ]),
        &["gauss"],
    );
    assert_fails(
        &run(&[
            "sample",
            v,
            "--filter",
            "smooth-bspline3",
            "--lambda",
            "-1",
            "--points",
            good.to_str().unwrap(),
        ]),
        &["lambda"],
    );
    assert_fails(
        &run(&[
            "sample",
            v,
            "--filter",
            "linear",
            "--points",
            "/nonexistent/p.txt",
        ]),
        &["p.txt"],
    );
}

#[test]
fn bad_scenes_fail_cleanly_without_output() {
    let t = Tmp::new("badscene");
    let out = t.path("never.png");
    let cases: Vec<(PathBuf, Vec<&str>, Vec<&str>)> = vec![
        (
            scene_file(&t, "nokey.toml", |s| s.replace("iso = 127.5\n", "")),
            vec![],
            vec!["nokey.toml", "iso"],
        ),
        (
            scene_file(&t, "filter.toml", |s| s.replace("bspline3", "gaussian")),
            vec![],
            vec!["filter.toml", "surface.filter", "gaussian"],
        ),
        (
            scene_file(&t, "cam.toml", |s| {
                s.replace(
                    "look_at = [31.5, 31.5, 31.5]",
                    "look_at = [31.5, 31.5, -150.0]",
                )
            }),
            vec![],
            vec!["cam.toml", "camera"],
        ),
        (
            scene_file(&t, "ior.toml", |s| s.replace("ior = 1.5", "ior = 0.0")),
            vec![],
            vec!["ior.toml", "surface.ior"],
        ),
        (
            scene_file(&t, "novol.toml", |s| {
                s.replace(
                    "[volume.phantom]\nkind = \"sphere\"",
                    "[volume]\npath = \"nope.nrrd\"\n[volume.phantomx]\nkind = \"sphere\"",
                )
            }),
            vec![],
            vec!["novol.toml"],
        ),
        (
            scene_file(&t, "missing.toml", |s| {
                s.replace("[volume.phantom]\nkind = \"sphere\"\nsize = 64\nradius = 20.0\nsigma = 3.0\nformat = \"u8\"", "[volume]\npath = \"nope.nrrd\"")
            }),
            vec![],
            vec!["nope.nrrd"],
        ),
        (
            scene_file(&t, "syntax.toml", |s| s.replace("[image]", "[image")),
            vec![],
            vec!["syntax.toml"],
        ),
        (
            scene_file(&t, "size.toml", |s| s.replace("width = 512", "width = 0")),
            vec![],
            vec!["size.toml", "image"],
        ),
        (
            root().join(SPHERE),
            vec!["--set", "surface.filter=bspline9"],
            vec!["surface.filter"],
        ),
        (
            root().join(SPHERE),
            vec![
                "--set",
                "camera.up=[0.0, 0.0, 1.0]",
                "--set",
                "camera.position=[31.5, 31.5, -150]",
            ],
            vec!["camera"],
        ),
        (
            root().join(SPHERE),
            vec!["--set", "nonsense"],
            vec!["--set nonsense"],
        ),
        (
            root().join(SPHERE),
            vec!["--threads", "0"],
            vec!["--threads"],
        ),
        (t.path("absent.toml"), vec![], vec!["absent.toml"]),
    ];
    for (scene, extra, needles) in cases {
        let mut args = vec![
            "render",
            scene.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ];
        args.extend(extra.iter());
        assert_fails(&run(&args), &needles);
        assert!(!out.exists(), "no output for {}", scene.display());
    }
    // An output directory that does not exist: refused before rendering.
    let o = run(&[
        "render",
        root().join(SPHERE).to_str().unwrap(),
        "-o",
        "/nonexistent-dir/x.png",
    ]);
    assert_fails(&o, &["/nonexistent-dir"]);
    assert!(
        Path::new(&t.0).read_dir().unwrap().all(|e| {
            let n = e.unwrap().file_name();
            let n = n.to_string_lossy();
            n.ends_with(".toml") && !n.starts_with('.')
        }),
        "no temporary files left"
    );
}

/// A `w×h` grey PNG whose value at `(x, y)` is `f(x, y)`.
fn grey_png(t: &Tmp, name: &str, w: u32, h: u32, f: impl Fn(u32, u32) -> u8) -> PathBuf {
    let p = t.path(name);
    image::RgbImage::from_fn(w, h, |x, y| image::Rgb([f(x, y); 3]))
        .save(&p)
        .unwrap();
    p
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
    let a = grey_png(&t, "a.png", 32, 24, checker);
    // Every value 20/255 brighter: RMSE 20/255, PSNR 20·log10(255/20).
    let b = grey_png(&t, "b.png", 32, 24, |x, y| checker(x, y) + 20);
    let diff = t.path("diff.png");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let o = run(&["compare", &s(&a), &s(&b), "--json", "--diff", &s(&diff)]);
    assert!(o.status.success(), "{}", stderr(&o));
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
    let heat = image::open(&diff).unwrap().to_rgb8();
    assert_eq!(heat.dimensions(), (32, 24));
    let red = (3.0 * 2.0 * d * 255.0f64).round() as u8;
    assert!(
        heat.pixels().all(|p| p.0 == [red, 0, 0]),
        "{:?}",
        heat.get_pixel(0, 0)
    );

    // Text output; an image against itself is perfect.
    let o = run(&["compare", &s(&a), &s(&a)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("RMSE 0.00000")
            && text.contains("PSNR inf dB")
            && text.contains("SSIM 1.0000"),
        "{text}"
    );
    // A local difference shows where it is in the heat map, nowhere else.
    let c = grey_png(&t, "c.png", 32, 24, |x, y| {
        if (10..14).contains(&x) && (5..9).contains(&y) {
            255 - checker(x, y)
        } else {
            checker(x, y)
        }
    });
    let diff2 = t.path("diff2.png");
    let o = run(&["compare", &s(&c), &s(&a), "--diff", &s(&diff2)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let heat = image::open(&diff2).unwrap().to_rgb8();
    for (x, y, p) in heat.enumerate_pixels() {
        let inside = (10..14).contains(&x) && (5..9).contains(&y);
        assert_eq!(p.0 == [255, 255, 255], inside, "({x}, {y}): {:?}", p.0);
        if !inside {
            assert_eq!(p.0, [0, 0, 0]);
        }
    }

    // Different sizes: one error line, exit 2, no diff written.
    let small = grey_png(&t, "small.png", 16, 24, checker);
    let diff3 = t.path("diff3.png");
    let o = run(&["compare", &s(&small), &s(&a), "--diff", &s(&diff3)]);
    assert_fails(&o, &["small.png", "differ in size"]);
    assert!(!diff3.exists());
}
