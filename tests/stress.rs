//! The numerical stress suite: scenes at the edges of the numbers, each with
//! an asserted outcome. Every render in it is also checked for what must hold
//! always: no NaN or infinite pixel, no ray ending in an undefined state
//! (`Counters::undefined`), hit positions either both finite or both NaN (no
//! backdrop hit), and no more events than `max_events`.
//!
//! All cases run in one test so the table "case | expected | observed" comes
//! out whole (on stderr, and as markdown in `$SNELL_TABLE_DIR/stress.md` when
//! that variable is set; docs/robustness.md holds a copy). A failing case is
//! recorded, the rest still run, and the test fails at the end.

mod common;

use std::fmt::Write as _;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use snell::compare::{HitComparison, compare_hits};
use snell::film::HitImage;
use snell::phantom::{PhantomFormat, SphereSpec};
use snell::reference::Reference;
use snell::render::{self, Frame, Prepared};
use snell::scene::Scene;
use snell::volume::{SampleType, Volume};

fn scenes_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes")
}

/// A scene from `scenes/NAME` with `--set` overrides.
fn scene(name: &str, set: &[&str]) -> Scene {
    let text = std::fs::read_to_string(scenes_dir().join(name)).unwrap();
    let o: Vec<String> = set.iter().map(|s| s.to_string()).collect();
    Scene::parse(&text, &scenes_dir().join(name), &o).unwrap_or_else(|e| panic!("{e}"))
}

/// The f32 glass sphere (64³, iso 0.5) at `px`×`px` pixels, plus overrides.
fn sphere(px: u32, set: &[&str]) -> Scene {
    let w = format!("image.width={px}");
    let h = format!("image.height={px}");
    let mut all = vec![w.as_str(), h.as_str()];
    all.extend_from_slice(set);
    scene("sphere-f32.toml", &all)
}

/// Renders with the scene's own volume, or with `vol` in its place, in the
/// scene's coefficient storage, and checks the invariants every frame must
/// satisfy.
fn render(scene: &Scene, vol: Option<Volume>) -> Frame {
    let vol = match vol {
        Some(v) => v,
        None => scene.load_volume(&Default::default()).unwrap(),
    };
    // The scene's own acceleration (octree and tags when it asks for them),
    // so the suite stresses the path users render with.
    let mut prep = Prepared::new_in(
        Arc::new(vol),
        scene.surface.filter,
        scene.render.coefficients,
        scene.surface.iso,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    if let Some(method) = snell::prepare::needs_accel(scene) {
        prep = prep.with_accel(scene.surface.iso, method);
        prep.ready_for(&scene.render);
    }
    let f = render::render(scene, &prep, None);
    let c = &f.stats.counters;
    assert_eq!(c.undefined, 0, "rays ended in an undefined state");
    assert!(
        f.film.color.iter().flatten().all(|v| v.is_finite()),
        "non-finite pixel"
    );
    for i in 0..f.film.u.len() {
        let (u, v) = (f.film.u[i], f.film.v[i]);
        assert!(
            (u.is_finite() && v.is_finite()) || (u.is_nan() && v.is_nan()),
            "pixel {i}: hit ({u}, {v})"
        );
        assert!(f.film.events[i] <= scene.render.max_events as f32);
    }
    f
}

fn reference(scene: &Scene) -> HitImage {
    Reference::from_scene(scene).unwrap().render(scene)
}

fn cmp(a: &Frame, b: &HitImage) -> HitComparison {
    compare_hits(&a.film.hits(), b, Some(8.0)).unwrap()
}

/// `b`'s hits divided by `s` (to compare a scene scaled by `s` with the original).
fn unscaled(b: &Frame, s: f64) -> HitImage {
    let mut h = b.film.hits();
    for x in h.u.iter_mut().chain(h.v.iter_mut()) {
        *x = (*x as f64 / s) as f32;
    }
    h
}

fn sphere_volume(scale: f32) -> Volume {
    let v = SphereSpec {
        format: PhantomFormat::F32,
        ..Default::default()
    }
    .build()
    .unwrap();
    let s = v.samples().iter().map(|x| x * scale).collect();
    Volume::new(v.dims(), [1.0; 3], SampleType::F32, s).unwrap()
}

/// A volume of `dims` with samples `f(x, y, z)`.
fn volume(dims: [usize; 3], f: impl Fn(f64, f64, f64) -> f64) -> Volume {
    let mut s = Vec::with_capacity(dims.iter().product());
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                s.push(f(x as f64, y as f64, z as f64) as f32);
            }
        }
    }
    Volume::new(dims, [1.0; 3], SampleType::F32, s).unwrap()
}

/// A shell of radius 12 about the centre of a 40³ grid with radial profile `p(r - 12)`.
fn shell(p: impl Fn(f64) -> f64) -> Volume {
    volume([40; 3], |x, y, z| {
        let r = ((x - 19.5).powi(2) + (y - 19.5).powi(2) + (z - 19.5).powi(2)).sqrt();
        p(r - 12.0)
    })
}

const SHELL_VIEW: [&str; 4] = [
    "camera.position=[19.5, 19.5, -80.0]",
    "camera.look_at=[19.5, 19.5, 19.5]",
    "backdrop.center=[19.5, 19.5, 120.0]",
    "surface.ior=1.05",
];

/// Events differing between two renders of the same pixels.
fn events_differ(a: &Frame, b: &Frame) -> usize {
    (0..a.film.events.len())
        .filter(|&i| a.film.events[i] != b.film.events[i])
        .count()
}

fn frac(n: usize, of: usize) -> f64 {
    n as f64 / of.max(1) as f64
}

/// A thin shell seen through its middle with the scene's traversal and a
/// dense step (0.01) on the same volume: at least a quarter of the pixels
/// must cross both of the shell's walls going in and again going out (4+
/// events), and the two renders must agree on the events of 99% of the
/// pixels.
fn shell_walls_found(vol: impl Fn() -> Volume, set: &[&str]) -> String {
    let dda = render(&sphere(48, set), Some(vol()));
    let dense = [set, &["render.traversal=step", "render.step=0.01"]].concat();
    let step = render(&sphere(48, &dense), Some(vol()));
    let m = dda.film.events.len();
    let through = dda.film.events.iter().filter(|&&e| e >= 4.0).count();
    let d = events_differ(&dda, &step);
    assert!(through > m / 4, "{through}");
    assert!(frac(d, m) <= 0.01, "{d}");
    format!("{through} of {m} pixels cross 4+ times; dda vs step differ on {d}")
}

type Case = (&'static str, &'static str, fn() -> String);

/// Every case: name, expected outcome, and the check (which asserts the
/// expectation and returns what it observed).
fn cases() -> Vec<Case> {
    vec![
        (
            "iso = the u8 maximum (255: the ball's inner plateau), linear",
            "nothing exceeds the iso-value: no refraction; bounded work",
            || {
                let f = render(
                    &scene(
                        "sphere.toml",
                        &[
                            "image.width=64",
                            "image.height=64",
                            "surface.filter=linear",
                            "surface.iso=255.0",
                        ],
                    ),
                    None,
                );
                let c = f.stats.counters;
                assert_eq!(c.refractions + c.reflections, 0);
                assert!(c.isolation_intervals < 200 * c.rays);
                format!(
                    "0 refractions; {:.1} isolation intervals per ray",
                    c.isolation_intervals as f64 / c.rays as f64
                )
            },
        ),
        (
            "iso = 0 (the zero plateau around the ball), linear",
            "the ball's whole support is the object; bounded work on the plateau",
            || {
                let f = render(
                    &scene(
                        "sphere.toml",
                        &[
                            "image.width=64",
                            "image.height=64",
                            "surface.filter=linear",
                            "surface.iso=0.0",
                        ],
                    ),
                    None,
                );
                let c = f.stats.counters;
                assert!(c.refractions > 0);
                assert!(c.isolation_intervals < 200 * c.rays);
                format!(
                    "{} refractions; {:.1} isolation intervals per ray",
                    c.refractions,
                    c.isolation_intervals as f64 / c.rays as f64
                )
            },
        ),
        (
            "iso = a sample value (u8 sphere, iso 128 vs 128.001), bspline3",
            "continuous in the iso-value: events equal on >= 99% of pixels",
            || {
                let base = ["image.width=64", "image.height=64"];
                let at = render(
                    &scene("sphere.toml", &[&base[..], &["surface.iso=128.0"]].concat()),
                    None,
                );
                let near = render(
                    &scene(
                        "sphere.toml",
                        &[&base[..], &["surface.iso=128.001"]].concat(),
                    ),
                    None,
                );
                let d = events_differ(&at, &near);
                assert!(frac(d, at.film.events.len()) <= 0.01, "{d}");
                format!("events differ on {d} of {} pixels", at.film.events.len())
            },
        ),
        (
            "flat plateau exactly at the iso-value (0 / 100 / 200 steps, iso 100), linear",
            "the plateau counts as outside: same events as iso 100 + 1e-6 on >= 99%",
            || {
                let vol = || {
                    volume([64; 3], |x, y, z| {
                        let r =
                            ((x - 31.5).powi(2) + (y - 31.5).powi(2) + (z - 31.5).powi(2)).sqrt();
                        if r < 10.0 {
                            200.0
                        } else if r < 20.0 {
                            100.0
                        } else {
                            0.0
                        }
                    })
                };
                let at = render(
                    &sphere(48, &["surface.filter=linear", "surface.iso=100.0"]),
                    Some(vol()),
                );
                let above = render(
                    &sphere(48, &["surface.filter=linear", "surface.iso=100.000001"]),
                    Some(vol()),
                );
                let d = events_differ(&at, &above);
                assert!(frac(d, at.film.events.len()) <= 0.01, "{d}");
                assert!(at.stats.counters.refractions > 0, "the 200 core refracts");
                // Step traversal brackets the plateau's edge between two
                // samples: its crossing must land on the rising side, whose
                // gradient is the surface's, not on the plateau (zero
                // gradient, a ray that goes on unbent).
                let step = render(
                    &sphere(
                        48,
                        &[
                            "surface.filter=linear",
                            "surface.iso=100.0",
                            "render.traversal=step",
                            "render.step=0.1",
                        ],
                    ),
                    Some(vol()),
                );
                let ks = step.stats.counters;
                assert_eq!(ks.degenerate_normals, 0);
                let c = cmp(&step, &at.film.hits());
                assert!(
                    c.events_equal_fraction >= 0.99 && c.squares(c.p99) <= 1e-3,
                    "{c:?}"
                );
                format!(
                    "{} refractions; events differ from iso+1e-6 on {d} of {}; step 0.1: {} degenerate normals, events equal {:.1}%, p99 {:.1e} squares",
                    at.stats.counters.refractions,
                    at.film.events.len(),
                    ks.degenerate_normals,
                    100.0 * c.events_equal_fraction,
                    c.squares(c.p99)
                )
            },
        ),
        (
            "vanishing gradient at the crossing: f = (z - 31.5)^3, iso 0, bspline3",
            "the normal is the gradient's limiting direction: hits equal the ramp f = z - 31.5 (same plane) to 1e-3 squares",
            || {
                let set = ["surface.iso=0.0", "camera.fov_y=5.0"];
                let cubic = render(
                    &sphere(32, &set),
                    Some(volume([64; 3], |_, _, z| (z - 31.5).powi(3))),
                );
                let ramp = render(&sphere(32, &set), Some(volume([64; 3], |_, _, z| z - 31.5)));
                let c = cmp(&cubic, &ramp.film.hits());
                assert_eq!(c.validity_mismatch, 0);
                assert_eq!(c.event_mismatch, 0);
                assert!(c.squares(c.max) < 1e-3, "{c:?}");
                let k = cubic.stats.counters;
                assert!(k.refractions > 0);
                format!(
                    "{} refractions, {} degenerate normals; max hit difference from the ramp {:.1e} squares",
                    k.refractions,
                    k.degenerate_normals,
                    c.squares(c.max)
                )
            },
        ),
        (
            "signed distance at iso 0 with a fill value: 20 - r about the grid's centre, one corner sample 1e20",
            "a value far from the surface moves it nowhere: hits bitwise equal to the render without the fill value",
            || {
                let dims = sphere_volume(1.0).dims();
                let c = dims.map(|n| (n - 1) as f64 / 2.0);
                let sdf = |x: f64, y: f64, z: f64| {
                    20.0 - ((x - c[0]).powi(2) + (y - c[1]).powi(2) + (z - c[2]).powi(2)).sqrt()
                };
                let plain = volume(dims, sdf);
                let mut filled = plain.samples().to_vec();
                filled[0] = 1e20;
                let filled = Volume::new(dims, [1.0; 3], SampleType::F32, filled).unwrap();
                let set = ["surface.iso=0", "surface.filter=linear"];
                let a = render(&sphere(48, &set), Some(plain));
                let b = render(&sphere(48, &set), Some(filled));
                let c = cmp(&b, &a.film.hits());
                let refracted = c.refracted.pixels;
                assert!(refracted > 0, "the sphere refracts: {c:?}");
                let bits = |f: &Frame| {
                    let h = f.film.hits();
                    h.u.iter()
                        .chain(&h.v)
                        .map(|x| x.to_bits())
                        .collect::<Vec<_>>()
                };
                assert!(bits(&a) == bits(&b), "{c:?}");
                format!("bitwise equal, {refracted} refracted pixels")
            },
        ),
        (
            "tiny gradient: sphere values x 1e-30 (iso 0.5e-30)",
            "scale invariant: events equal to the unscaled render on >= 99.5%, p99 <= 1e-3 squares",
            || {
                let f = render(
                    &sphere(48, &["surface.iso=0.5e-30"]),
                    Some(sphere_volume(1e-30)),
                );
                let one = render(&sphere(48, &[]), Some(sphere_volume(1.0)));
                let c = cmp(&f, &one.film.hits());
                assert!(
                    c.events_equal_fraction >= 0.995 && c.squares(c.p99) <= 1e-3,
                    "{c:?}"
                );
                format!(
                    "events equal {:.2}%, p99 {:.1e} squares",
                    100.0 * c.events_equal_fraction,
                    c.squares(c.p99)
                )
            },
        ),
        (
            "offset: f64 sphere values + 101325 (a pressure's scale; iso 101325.5), and sphere values x 1e-6 + 101325 (iso 101325 + 0.5e-6), f64, f32 and f16 coefficients",
            "stored relative to an offset, as precise as the unshifted values the shifted ones hold, in the same storage: against their f64 render, at most 2x the event and validity mismatches of their render in that storage (none in f64), p90 and p99 within 2x its own plus 1e-3 and 0.05 squares",
            || {
                let v = sphere_volume(1.0);
                let mut out = Vec::new();
                // A variation of 1e-6 lies 1e-11 below the offset, the scale
                // of the iso-value's nudge were it taken from the offset.
                for scale in [1.0, 1e-6] {
                    let shifted: Vec<f64> = v
                        .samples()
                        .iter()
                        .map(|&x| 101325.0 + scale * x as f64)
                        .collect();
                    let vol =
                        Volume::from_f64(v.dims(), [1.0; 3], SampleType::F64, &shifted).unwrap();
                    assert!(
                        vol.offset() != 0.0,
                        "f32 rounds these values: an offset is needed"
                    );
                    // The unshifted values the shifted ones hold (f64 keeps
                    // 101325 + 1e-6·x to 1.5e-5 of x), so the renders differ
                    // by what the renderer adds, not by the data's rounding.
                    let held: Vec<f32> = shifted
                        .iter()
                        .map(|&y| ((y - 101325.0) / scale) as f32)
                        .collect();
                    let held = Volume::new(v.dims(), [1.0; 3], SampleType::F32, held).unwrap();
                    let iso = format!("surface.iso={}", 101325.0 + 0.5 * scale);
                    let wide = render(
                        &sphere(48, &["render.coefficients=f64"]),
                        Some(held.clone()),
                    );
                    for storage in ["f64", "f32", "f16"] {
                        let coefficients = format!("render.coefficients={storage}");
                        let f = render(&sphere(48, &[&iso, &coefficients]), Some(vol.clone()));
                        let c = cmp(&f, &wide.film.hits());
                        // What the storage costs the unshifted values.
                        let one = render(&sphere(48, &[&coefficients]), Some(held.clone()));
                        let own = cmp(&one, &wide.film.hits());
                        assert!(
                            c.event_mismatch + c.validity_mismatch
                                <= 2 * (own.event_mismatch + own.validity_mismatch)
                                && c.squares(c.p90) <= 1e-3 + 2.0 * own.squares(own.p90)
                                && c.squares(c.p99) <= 0.05 + 2.0 * own.squares(own.p99),
                            "x {scale:e}, {storage}: {c:?}, unshifted {own:?}"
                        );
                        out.push(format!(
                            "x {scale:e}, {storage}: events equal {:.2}%, p90 {:.1e}, p99 {:.1e} squares (unshifted: {:.2}%, {:.1e}, {:.1e})",
                            100.0 * c.events_equal_fraction,
                            c.squares(c.p90),
                            c.squares(c.p99),
                            100.0 * own.events_equal_fraction,
                            own.squares(own.p90),
                            own.squares(own.p99)
                        ));
                    }
                }
                out.join("; ")
            },
        ),
        (
            "f16 coefficients of sphere values x 1e-9 (within f16's subnormals) and x 1e6 (beyond 65504)",
            "scaled into f16's normal range: as close to the unscaled f64 render as the unscaled f16 render is (events equal on >= 99.5%, refracted p90 within 2x the unscaled f16's)",
            || {
                let f16 = "render.coefficients=f16";
                let wide = render(&sphere(48, &[]), Some(sphere_volume(1.0)));
                let f16_error = |k: f32, iso: &str| {
                    let f = render(&sphere(48, &[iso, f16]), Some(sphere_volume(k)));
                    cmp(&f, &wide.film.hits())
                };
                let one = f16_error(1.0, "surface.iso=0.5");
                let squares = |c: &HitComparison| {
                    format!(
                        "events equal {:.2}%, refracted p90 {:.1e}, p99 {:.1e} squares",
                        100.0 * c.events_equal_fraction,
                        c.squares(c.refracted.p90),
                        c.squares(c.refracted.p99)
                    )
                };
                let mut out = vec![format!("against f64: x 1: {}", squares(&one))];
                for (k, iso) in [(1e-9f32, "surface.iso=0.5e-9"), (1e6, "surface.iso=0.5e6")] {
                    let c = f16_error(k, iso);
                    assert!(
                        c.events_equal_fraction >= 0.995
                            && c.refracted.p90 <= 2.0 * one.refracted.p90,
                        "{k}: {c:?}, unscaled {one:?}"
                    );
                    out.push(format!("x {k:e}: {}", squares(&c)));
                }
                out.join("; ")
            },
        ),
        (
            "a fill value (NetCDF's 9.97e36) in a slab along one face and a corner voxel, away from a ball's surface (f32, iso 0.5), linear",
            "the surface does not move: the frame is bitwise the one without the fill",
            || {
                // A smooth ball from 0 to 1, with and without the fill; the
                // view keeps to the middle, where no ray meets the slab.
                let ball = |x: f64, y: f64, z: f64| {
                    let r = ((x - 19.5).powi(2) + (y - 19.5).powi(2) + (z - 19.5).powi(2)).sqrt();
                    1.0 / (1.0 + ((r - 10.0) / 1.5).exp())
                };
                let fill = 9.96921e36;
                let filled = move |x: f64, y: f64, z: f64| {
                    if x < 3.0 || x + y + z == 0.0 {
                        fill
                    } else {
                        ball(x, y, z)
                    }
                };
                let set = [
                    &SHELL_VIEW[..3],
                    &[
                        "camera.fov_y=10.0",
                        "surface.filter=linear",
                        "surface.iso=0.5",
                        "surface.ior=1.1",
                    ],
                ]
                .concat();
                let clean = render(&sphere(48, &set), Some(volume([40; 3], ball)));
                let with_fill = render(&sphere(48, &set), Some(volume([40; 3], filled)));
                let f = |h: &Frame| {
                    let m = &h.film;
                    m.u.iter()
                        .chain(&m.v)
                        .chain(&m.events)
                        .map(|x| x.to_bits())
                        .collect::<Vec<_>>()
                };
                let (a, b) = (f(&with_fill), f(&clean));
                let differ = a.iter().zip(&b).filter(|(x, y)| x != y).count();
                let r = clean.stats.counters.refractions;
                assert!(r > 500, "{r} refractions: the ball is in view");
                assert_eq!(differ, 0, "{differ} of {} hit values differ", a.len());
                format!("{r} refractions; {differ} of {} hit values differ", a.len())
            },
        ),
        (
            "one-voxel-thick shell (u8-like, r = 12 +- 0.5), linear",
            "both walls found: >= 4 events through the middle; dda = dense step on >= 99%",
            || {
                let vol = || shell(|d| if d.abs() <= 0.5 { 255.0 } else { 0.0 });
                let set = [
                    &SHELL_VIEW[..],
                    &["surface.filter=linear", "surface.iso=127.5"],
                ]
                .concat();
                shell_walls_found(vol, &set)
            },
        ),
        (
            "sub-voxel shell (Gaussian ridge sigma 0.5, iso 0.8: 0.67 voxel thick), bspline3",
            "not missed: >= 4 events through the middle; dda = dense step on >= 99%",
            || {
                let vol = || shell(|d| (-d * d / (2.0 * 0.25)).exp());
                let set = [&SHELL_VIEW[..], &["surface.iso=0.8"]].concat();
                shell_walls_found(vol, &set)
            },
        ),
        (
            "rays in the tangent plane of a planar surface (f = y, iso 20 = a sample row; rows of rays at y = 20 and 20 +- 1e-9)",
            "touching is not crossing: 0 events, every ray reaches the backdrop",
            || {
                // Three rows of an orthographic camera 3e-9 high: pixel
                // centres at sy = 2/3, 0, -2/3 of its half height, so the
                // middle row lies in the plane y = 20 and the others 1e-9
                // off it.
                let s = sphere(
                    16,
                    &[
                        "image.height=3",
                        "surface.iso=20.0",
                        "camera.kind=\"orthographic\"",
                        "camera.height=3e-9",
                        "camera.position=[31.5, 20.0, -100.0]",
                        "camera.look_at=[31.5, 20.0, 31.5]",
                    ],
                );
                let rows: Vec<f64> = (0..3)
                    .map(|r| s.camera.ray(8.5, r as f64 + 0.5).0.y - 20.0)
                    .collect();
                assert_eq!(rows[1], 0.0, "the middle row lies in the plane");
                for off in [rows[0], rows[2]] {
                    assert!((off.abs() - 1e-9).abs() < 1e-12, "rows {rows:?}");
                }
                let f = render(&s, Some(volume([64; 3], |_, y, _| y)));
                assert_eq!(f.film.events.len(), 48);
                assert!(f.film.events.iter().all(|&e| e == 0.0));
                assert!(f.film.u.iter().all(|u| u.is_finite()));
                format!(
                    "rows at y = 20 {:+.1e}, 20, 20 {:+.1e}: 0 events on all 48 pixels",
                    rows[0], rows[2]
                )
            },
        ),
        (
            "grazing rays: orthographic close-up of the sphere's silhouette (4 x 4 units)",
            "matches the analytic spheres: events equal on >= 97% of pixels",
            || {
                // The iso-0.5 radius of the phantom: 20 + 3·sqrt(2 ln 2).
                let r = 20.0 + 3.0 * (2.0 * 2f64.ln()).sqrt();
                let pos = format!("camera.position=[{}, 31.5, -100.0]", 31.5 + r);
                let at = format!("camera.look_at=[{}, 31.5, 31.5]", 31.5 + r);
                let s = sphere(
                    64,
                    &[
                        "camera.kind=\"orthographic\"",
                        "camera.height=4.0",
                        &pos,
                        &at,
                    ],
                );
                let f = render(&s, None);
                let c = cmp(&f, &reference(&s));
                assert!(c.events_equal_fraction >= 0.97, "{c:?}");
                format!(
                    "events equal {:.2}% ({} of {} pixels differ)",
                    100.0 * c.events_equal_fraction,
                    c.event_mismatch,
                    c.pixels
                )
            },
        ),
        (
            "axis-parallel rays along grid lines, cell faces and cell centres (orthographic)",
            "matches the analytic spheres: events equal >= 99%, p50 <= 0.02 squares",
            || {
                let mut out = Vec::new();
                for (x, y, what) in [
                    (31.5, 31.5, "edges"),
                    (31.5, 32.0, "faces"),
                    (32.0, 32.0, "centres"),
                ] {
                    let pos = format!("camera.position=[{x}, {y}, -100.0]");
                    let at = format!("camera.look_at=[{x}, {y}, 31.5]");
                    let s = sphere(
                        64,
                        &[
                            "camera.kind=\"orthographic\"",
                            "camera.height=64.0",
                            &pos,
                            &at,
                        ],
                    );
                    let c = cmp(&render(&s, None), &reference(&s));
                    assert!(c.events_equal_fraction >= 0.99, "{what}: {c:?}");
                    assert!(c.squares(c.refracted.p50) <= 0.02, "{what}: {c:?}");
                    out.push(format!("{what} {:.1}%", 100.0 * c.events_equal_fraction));
                }
                format!("events equal: {}", out.join(", "))
            },
        ),
        (
            "backdrop in front of the ball (z = -50) and through its centre (z = 31.5)",
            "the plane is opaque: every ray ends on it, before the ball or at most one event in; events equal the analytic spheres on >= 99%, refracted p90 <= 0.01 units; step 0.1 agrees",
            || {
                let mut out = Vec::new();
                for z in ["-50.0", "31.5"] {
                    let at = format!("backdrop.center=[31.5, 31.5, {z}]");
                    let s = sphere(64, &[at.as_str()]);
                    let f = render(&s, None);
                    let k = f.stats.counters;
                    assert_eq!(k.missed_backdrop + k.terminated + k.undefined, 0, "{z}");
                    let most = f.film.events.iter().fold(0.0f32, |m, &e| m.max(e));
                    assert!(most <= 1.0, "{z}: {most} events");
                    let r = cmp(&f, &reference(&s));
                    assert_eq!(r.validity_mismatch, 0, "{z}: {r:?}");
                    // (No refracted pixel in front: a NaN p90 passes.)
                    let p90 = r.refracted.p90;
                    assert!(
                        r.events_equal_fraction >= 0.99 && (p90.is_nan() || p90 <= 0.01),
                        "{z}: {r:?}"
                    );
                    let step = render(
                        &sphere(
                            64,
                            &[at.as_str(), "render.traversal=step", "render.step=0.1"],
                        ),
                        None,
                    );
                    let c = cmp(&step, &f.film.hits());
                    assert!(c.events_equal_fraction >= 0.99, "{z}: {c:?}");
                    out.push(format!(
                        "z = {z}: {} refractions, 0 misses, events equal {:.1}%",
                        k.refractions,
                        100.0 * r.events_equal_fraction
                    ));
                }
                out.join("; ")
            },
        ),
        (
            "ior 1.0001 (nearly index-matched glass)",
            "matches the analytic spheres (>= 99% events, p90 <= 0.01 units); within 0.2 units of straight at p90",
            || {
                let s = sphere(64, &["surface.ior=1.0001"]);
                let f = render(&s, None);
                assert!(f.stats.counters.refractions > 0);
                let r = cmp(&f, &reference(&s));
                assert!(
                    r.events_equal_fraction >= 0.99 && r.refracted.p90 <= 0.01,
                    "{r:?}"
                );
                let straight = render(&sphere(64, &["surface.ior=1.0"]), None);
                let c = cmp(&f, &straight.film.hits());
                assert!(c.p50 < 0.01 && c.p90 < 0.2, "{c:?}");
                format!(
                    "vs analytic: events {:.1}%, p90 {:.1e}; vs straight: p90 {:.3} units",
                    100.0 * r.events_equal_fraction,
                    r.refracted.p90,
                    c.p90
                )
            },
        ),
        (
            "ior 4.0, max_events 6, f32 ball with two air holes",
            "total internal reflection at the holes (a plain sphere has none, by symmetry); stopped rays have no hit; >= 98% events match the analytic spheres",
            || {
                let s = scene(
                    "ball-two-holes.toml",
                    &[
                        "image.width=64",
                        "image.height=64",
                        "volume.phantom.format=f32",
                        "surface.iso=0.5",
                        "surface.ior=4.0",
                        "render.max_events=6",
                    ],
                );
                let f = render(&s, None);
                let c = f.stats.counters;
                assert!(c.reflections > 0 && c.terminated > 0);
                for i in 0..f.film.u.len() {
                    if f.film.events[i] == 6.0 {
                        assert!(f.film.u[i].is_nan());
                    }
                }
                let r = cmp(&f, &reference(&s));
                assert!(r.events_equal_fraction >= 0.98, "{r:?}");
                format!(
                    "{} reflections, {} rays stopped; events equal {:.1}%",
                    c.reflections,
                    c.terminated,
                    100.0 * r.events_equal_fraction
                )
            },
        ),
        (
            "TIR loop: camera inside an ior-4 ball, off-centre, max_events 2000",
            "trapped rays stop at exactly max_events (which bounds a ray's work; the time is reported, not held to a bound)",
            || {
                let s = sphere(
                    12,
                    &[
                        "surface.ior=4.0",
                        "render.max_events=2000",
                        "camera.position=[40.0, 31.5, 31.5]",
                        "camera.look_at=[40.0, 31.5, 200.0]",
                        "camera.fov_y=90.0",
                    ],
                );
                let t = Instant::now();
                let f = render(&s, None);
                let ms = t.elapsed().as_secs_f64() * 1e3;
                let c = f.stats.counters;
                assert!(c.terminated > 0);
                let stopped = f.film.events.iter().filter(|&&e| e == 2000.0).count();
                assert_eq!(stopped as u64, c.terminated);
                format!(
                    "{} of {} rays stopped at 2000 events; {:.1} ms ({:.2} ms per ray)",
                    c.terminated,
                    c.rays,
                    ms,
                    ms / c.rays as f64
                )
            },
        ),
        (
            "camera inside the object (at the ball's centre)",
            "matches the analytic spheres: >= 99% events, p90 <= 0.1 squares",
            || inside_case("[31.5, 31.5, 31.5]"),
        ),
        (
            "camera inside the volume, outside the object",
            "matches the analytic spheres: >= 99% events, p90 <= 0.1 squares",
            || inside_case("[31.5, 31.5, 4.0]"),
        ),
        (
            "spacing 1e6 (the whole scene scaled by 1e6)",
            "scale invariant: events equal >= 99.5%, hits/1e6 within 1e-3 squares at p99",
            || scaled_case(1e6),
        ),
        (
            "spacing 1e-6 (the whole scene scaled by 1e-6)",
            "scale invariant: events equal >= 99.5%, hits/1e-6 within 1e-3 squares at p99",
            || scaled_case(1e-6),
        ),
        (
            "spacing 1e-3, 1e3 and [1, 2, 0.5] with the camera left in place",
            "defined (an object tiny, huge or squashed in view)",
            || {
                let mut out = Vec::new();
                for sp in [
                    "[0.001, 0.001, 0.001]",
                    "[1000.0, 1000.0, 1000.0]",
                    "[1.0, 2.0, 0.5]",
                ] {
                    let s = format!("volume.spacing={sp}");
                    let f = render(&sphere(32, &[&s]), None);
                    out.push(format!(
                        "{sp}: {} refractions",
                        f.stats.counters.refractions
                    ));
                }
                out.join("; ")
            },
        ),
        (
            "f32 values near 1e38 (sphere x 1e38, iso 0.5e38)",
            "scale invariant: events equal >= 99.5%, p99 <= 1e-3 squares",
            || {
                let f = render(
                    &sphere(48, &["surface.iso=0.5e38"]),
                    Some(sphere_volume(1e38)),
                );
                let one = render(&sphere(48, &[]), Some(sphere_volume(1.0)));
                let c = cmp(&f, &one.film.hits());
                assert!(
                    c.events_equal_fraction >= 0.995 && c.squares(c.p99) <= 1e-3,
                    "{c:?}"
                );
                format!(
                    "events equal {:.2}%, p99 {:.1e} squares",
                    100.0 * c.events_equal_fraction,
                    c.squares(c.p99)
                )
            },
        ),
        (
            "f32 values at f32::MAX (sphere x 3.4e38; B-spline coefficients overshoot f32 range), bspline5",
            "defined; same events as the unscaled render on >= 99%",
            || {
                let set = ["surface.iso=1.7e38", "surface.filter=bspline5"];
                let f = render(&sphere(48, &set), Some(sphere_volume(f32::MAX)));
                let one = render(
                    &sphere(48, &["surface.filter=bspline5"]),
                    Some(sphere_volume(1.0)),
                );
                let c = cmp(&f, &one.film.hits());
                assert!(c.events_equal_fraction >= 0.99, "{c:?}");
                format!("events equal {:.2}%", 100.0 * c.events_equal_fraction)
            },
        ),
        (
            "denormal f32 values (sphere x 1e-40, iso 0.5e-40: 16 significant bits)",
            "defined; events equal to the unscaled render on >= 99%",
            || {
                let f = render(
                    &sphere(48, &["surface.iso=0.5e-40"]),
                    Some(sphere_volume(1e-40)),
                );
                let one = render(&sphere(48, &[]), Some(sphere_volume(1.0)));
                let c = cmp(&f, &one.film.hits());
                assert!(c.events_equal_fraction >= 0.99, "{c:?}");
                format!(
                    "events equal {:.2}%, p90 {:.1e} squares",
                    100.0 * c.events_equal_fraction,
                    c.squares(c.p90)
                )
            },
        ),
        (
            "1xNxM, Nx1xM and NxMx1 volumes (no interior; a disk of 1 in 0 in the plane), bspline3, seen face on",
            "backdrop only: no event, every ray hits the backdrop; the disk behind a layer of 0 (two samples thick) refracts",
            || {
                let mut out = Vec::new();
                for axis in 0..3 {
                    let sets = common::face_on(axis);
                    let sets: Vec<&str> = sets.iter().map(String::as_str).collect();
                    let s = sphere(32, &sets);
                    let slab = |thickness| {
                        render(
                            &s,
                            Some(common::disk_slab(axis, thickness, 1.0, SampleType::F32)),
                        )
                    };
                    let flat = slab(1);
                    let c = flat.stats.counters;
                    assert_eq!(c.refractions + c.reflections, 0, "axis {axis}");
                    assert!(flat.film.u.iter().all(|u| u.is_finite()), "axis {axis}");
                    let control = slab(2).stats.counters;
                    assert!(control.refractions > 0, "axis {axis}: {control:?}");
                    let dims = ["1x16x16", "16x1x16", "16x16x1"][axis];
                    out.push(format!(
                        "{dims}: 0 events ({} refractions two samples thick)",
                        control.refractions
                    ));
                }
                out.join(", ")
            },
        ),
        (
            "2xNxM volume (one cell thick), cubic and linear",
            "defined; the slab refracts",
            || {
                let mut out = Vec::new();
                for filter in ["bspline3", "linear", "bspline2"] {
                    let vol = volume(
                        [2, 64, 64],
                        |x, y, _| if x == 0.0 && y > 20.0 { 1.0 } else { 0.0 },
                    );
                    let fl = format!("surface.filter={filter}");
                    let f = render(
                        &sphere(
                            32,
                            &[
                                &fl,
                                "camera.position=[-100.0, 31.5, 31.5]",
                                "camera.look_at=[0.5, 31.5, 31.5]",
                                "camera.fov_y=40.0",
                                "backdrop.center=[100.0, 31.5, 31.5]",
                                "backdrop.normal=[-1.0, 0.0, 0.0]",
                                "backdrop.u_axis=[0.0, 0.0, 1.0]",
                            ],
                        ),
                        Some(vol),
                    );
                    assert!(f.stats.counters.refractions > 0, "{filter}");
                    out.push(format!(
                        "{filter}: {} refractions",
                        f.stats.counters.refractions
                    ));
                }
                out.join(", ")
            },
        ),
        (
            "camera 1e9 units away (orthographic and perspective), step and dda traversal",
            "defined, and the render ends: rays still march through the volume (the time is reported, not held to a bound)",
            || {
                let mut out = Vec::new();
                for (kind, extra) in [
                    ("orthographic", "camera.height=64.0"),
                    ("perspective", "camera.fov_y=0.000004"),
                ] {
                    for trav in ["dda", "step"] {
                        let k = format!("camera.kind=\"{kind}\"");
                        let tr = format!("render.traversal={trav}");
                        let s = sphere(16, &[&k, extra, &tr, "camera.position=[31.5, 31.5, -1e9]"]);
                        let t = Instant::now();
                        let f = render(&s, None);
                        assert!(f.stats.counters.refractions > 0, "{kind} {trav}");
                        out.push(format!(
                            "{kind}/{trav}: {:.0} ms",
                            t.elapsed().as_secs_f64() * 1e3
                        ));
                    }
                }
                out.join(", ")
            },
        ),
        (
            "NaN and infinite samples replaced on load (allow_nan)",
            "defined: replaced by the finite range, the render is complete",
            || {
                let mut v = sphere_volume(1.0);
                let mut s = v.samples().to_vec();
                for (i, x) in s.iter_mut().enumerate() {
                    match i % 997 {
                        0 => *x = f32::NAN,
                        1 => *x = f32::INFINITY,
                        2 => *x = f32::NEG_INFINITY,
                        _ => {}
                    }
                }
                let bad = s.iter().filter(|x| !x.is_finite()).count();
                snell::volume::replace_nonfinite(&mut s);
                v = Volume::new(v.dims(), [1.0; 3], SampleType::F32, s).unwrap();
                let f = render(&sphere(48, &[]), Some(v));
                assert!(f.stats.counters.refractions > 0);
                format!(
                    "{bad} samples replaced; {} refractions",
                    f.stats.counters.refractions
                )
            },
        ),
    ]
}

fn inside_case(pos: &str) -> String {
    let p = format!("camera.position={pos}");
    let s = sphere(
        64,
        &[
            &p,
            "camera.look_at=[31.5, 31.5, 200.0]",
            "camera.fov_y=60.0",
        ],
    );
    let c = cmp(&render(&s, None), &reference(&s));
    assert!(c.events_equal_fraction >= 0.99, "{c:?}");
    assert!(c.squares(c.refracted.p90) <= 0.1, "{c:?}");
    format!(
        "events equal {:.2}%, p90 {:.1e} squares",
        100.0 * c.events_equal_fraction,
        c.squares(c.refracted.p90)
    )
}

fn scaled_case(k: f64) -> String {
    let set = |k: f64| {
        vec![
            format!("volume.spacing=[{k:e}, {k:e}, {k:e}]"),
            format!(
                "camera.position=[{:e}, {:e}, {:e}]",
                31.5 * k,
                31.5 * k,
                -150.0 * k
            ),
            format!(
                "camera.look_at=[{:e}, {:e}, {:e}]",
                31.5 * k,
                31.5 * k,
                31.5 * k
            ),
            format!(
                "backdrop.center=[{:e}, {:e}, {:e}]",
                31.5 * k,
                31.5 * k,
                200.0 * k
            ),
            format!("backdrop.checker={:e}", 8.0 * k),
        ]
    };
    let run = |k: f64| {
        let o = set(k);
        let o: Vec<&str> = o.iter().map(String::as_str).collect();
        render(&sphere(48, &o), None)
    };
    let c = compare_hits(&unscaled(&run(k), k), &run(1.0).film.hits(), Some(8.0)).unwrap();
    assert!(c.events_equal_fraction >= 0.995, "{c:?}");
    assert!(c.squares(c.p99) <= 1e-3, "{c:?}");
    format!(
        "events equal {:.2}%, p99 {:.1e} squares",
        100.0 * c.events_equal_fraction,
        c.squares(c.p99)
    )
}

fn panic_text(e: &(dyn std::any::Any + Send)) -> String {
    e.downcast_ref::<String>()
        .cloned()
        .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
        .unwrap_or_else(|| "panic".into())
}

#[test]
fn numerical_stress_suite() {
    let mut table = String::from("| case | expected | observed |\n|---|---|---|\n");
    let mut failed = Vec::new();
    for (case, expected, check) in cases() {
        let t = Instant::now();
        let observed = match catch_unwind(AssertUnwindSafe(check)) {
            Ok(o) => o,
            Err(e) => {
                failed.push(case);
                format!("FAILED: {}", panic_text(&*e))
            }
        };
        eprintln!(
            "[{:5.2} s] {case}\n    expected: {expected}\n    observed: {observed}",
            t.elapsed().as_secs_f64()
        );
        let cell = |s: &str| s.replace('|', "/").replace('\n', " ");
        writeln!(
            table,
            "| {} | {} | {} |",
            cell(case),
            cell(expected),
            cell(&observed)
        )
        .unwrap();
    }
    eprintln!("\n{table}");
    if let Some(dir) = std::env::var_os("SNELL_TABLE_DIR") {
        std::fs::write(PathBuf::from(dir).join("stress.md"), &table).unwrap();
    }
    assert!(failed.is_empty(), "failed cases: {failed:?}");
}
