//! What the end-to-end tests share: the repository's and the shared data's
//! paths, a scratch directory per test, `snell` run from one command line,
//! and the dense sampling that classifications are held to. (Each test
//! crate compiles this module and uses part of it.)
#![allow(dead_code)]

use std::path::PathBuf;
use std::process::{Command, Output};

/// The repository.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A volume of `../shared/data/`.
pub fn data(name: &str) -> PathBuf {
    root().join("../shared/data").join(name)
}

pub const SPHERE: &str = "scenes/sphere.toml";

/// The `snell` binary this test crate was built with.
pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_snell"))
}

/// `line` split at spaces into `snell`'s arguments, in each of which
/// `{root}` stands for the repository, `{data}` for the shared volumes'
/// folder, `{sphere}`, `{lobster}`, `{photo}` and `{cranium}` for those
/// scenes' files, and `{tooth}` and `{headsq}` for the tooth CT and the raw
/// head CT (split first, so a path a placeholder stands for stays one
/// argument even with a space in it; a path pasted into `line` must have
/// none).
pub fn args(line: &str) -> Vec<String> {
    let path = |p: PathBuf| p.to_str().unwrap().to_string();
    let vars = [
        ("{sphere}", path(root().join(SPHERE))),
        ("{lobster}", path(root().join("scenes/lobster.toml"))),
        ("{photo}", path(root().join("scenes/sphere-photo.toml"))),
        ("{cranium}", path(root().join("scenes/cranium.toml"))),
        ("{tooth}", path(data("tooth.nrrd"))),
        (
            "{headsq}",
            path(data("headsq-quarter-ct_64x64x93_u16le.raw")),
        ),
        ("{root}", path(root())),
        ("{data}", path(root().join("../shared/data"))),
    ];
    line.split(' ')
        .map(|a| vars.iter().fold(a.to_string(), |a, (k, v)| a.replace(k, v)))
        .collect()
}

/// `snell` with the arguments of `line` (see [`args`]), run in the
/// repository.
pub fn run(line: &str) -> Output {
    bin().args(args(line)).current_dir(root()).output().unwrap()
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Asserts that `o` succeeded, showing its stderr if not, and hands it back.
#[track_caller]
pub fn ok(o: Output) -> Output {
    assert!(o.status.success(), "{}", stderr(&o));
    o
}

/// A scratch directory of its own for one test, removed when dropped.
pub struct Tmp(pub PathBuf);

impl Tmp {
    /// `tag` names the test; the process id keeps concurrent runs apart.
    pub fn new(tag: &str) -> Tmp {
        let p = std::env::temp_dir().join(format!("snell-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir_all(&p).unwrap();
        Tmp(p)
    }

    pub fn path(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }

    pub fn write(&self, name: &str, bytes: &[u8]) -> PathBuf {
        let p = self.path(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    /// `snell` with the arguments of `line` (see [`args`]), run in the
    /// scratch directory, so that the files it names bare are the test's.
    pub fn cmd(&self, line: &str) -> Command {
        let mut c = bin();
        c.args(args(line)).current_dir(&self.0);
        c
    }

    /// What [`Tmp::cmd`]'s command printed, and how it ended.
    pub fn run(&self, line: &str) -> Output {
        self.cmd(line).output().unwrap()
    }

    /// `snell` with the arguments of `line` (see [`args`]), in which
    /// `{tmp}` also stands for the scratch directory, run in the repository
    /// (where commands find `scenes/` by default).
    pub fn cmd_in_repo(&self, line: &str) -> Command {
        let dir = self.0.to_str().unwrap();
        let mut c = bin();
        c.args(args(line).into_iter().map(|a| a.replace("{tmp}", dir)))
            .current_dir(root());
        c
    }

    /// What [`Tmp::cmd_in_repo`]'s command printed, and how it ended.
    pub fn run_in_repo(&self, line: &str) -> Output {
        self.cmd_in_repo(line).output().unwrap()
    }
}

impl Drop for Tmp {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Whether 6³ points spread over the closed knot cell `c` (clipped to the
/// grid) see the field on both sides of `iso`, as the renderer tells inside
/// from outside: dense sampling, the truth the classifications are held to.
pub fn straddles(
    field: &snell::filter::Field,
    lattice: &snell::lattice::Lattice,
    c: [i64; 3],
    iso: f64,
) -> bool {
    const K: usize = 6;
    let n = field.dims();
    let (mut above, mut below) = (false, false);
    for k in 0..K * K * K {
        let q = [k % K, k / K % K, k / (K * K)];
        let p = glam::DVec3::from_array(std::array::from_fn(|a| {
            let lo = (c[a] as f64 - lattice.offset).max(0.0);
            let hi = (c[a] as f64 + 1.0 - lattice.offset).min((n[a] - 1) as f64);
            lo + (hi - lo) * q[a] as f64 / (K - 1) as f64
        }));
        if snell::roots::inside(field.value(p) - iso) {
            above = true;
        } else {
            below = true;
        }
        if above && below {
            return true;
        }
    }
    false
}

/// The `--set`s that look at a 16-sample slab face on along `axis` (0, 1,
/// 2): the camera 50 units before the slab's centre, the backdrop 100
/// behind it, facing back.
pub fn face_on(axis: usize) -> Vec<String> {
    let at = |d: f64| {
        let mut p = [7.5f64; 3];
        p[axis] = d;
        format!("[{:.1}, {:.1}, {:.1}]", p[0], p[1], p[2])
    };
    let mut n = [0.0f64; 3];
    n[axis] = -1.0;
    let (up, u_axis) = if axis == 1 {
        ("[0.0, 0.0, 1.0]", "[1.0, 0.0, 0.0]")
    } else {
        ("[0.0, 1.0, 0.0]", "[0.0, 1.0, 0.0]")
    };
    vec![
        format!("camera.position={}", at(-50.0)),
        format!("camera.look_at={}", at(0.0)),
        format!("camera.up={up}"),
        format!("backdrop.center={}", at(100.0)),
        format!("backdrop.normal=[{:.1}, {:.1}, {:.1}]", n[0], n[1], n[2]),
        format!("backdrop.u_axis={u_axis}"),
    ]
}

/// A 16×16 slab `thickness` samples thick along `axis`, `value` on a disk
/// of radius 6 in its last layer and 0 elsewhere: one sample thick, a
/// plane with a surface in it but no inside; two, the disk behind a layer
/// of 0, which refracts.
pub fn disk_slab(
    axis: usize,
    thickness: usize,
    value: f32,
    ty: snell::volume::SampleType,
) -> snell::volume::Volume {
    let mut dims = [16; 3];
    dims[axis] = thickness;
    let mut data = Vec::with_capacity(dims.iter().product());
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                let p = [x, y, z];
                let r2: f64 = (0..3)
                    .filter(|&a| a != axis)
                    .map(|a| (p[a] as f64 - 7.5).powi(2))
                    .sum();
                let disk = p[axis] + 1 == thickness && r2 < 36.0;
                data.push(if disk { value } else { 0.0 });
            }
        }
    }
    snell::volume::Volume::new(dims, [1.0; 3], ty, data).unwrap()
}
