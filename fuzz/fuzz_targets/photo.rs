//! Photographs (PNG, JPEG, any format the image crate guesses from the
//! bytes): the input is written to `in.png` and read as `compare` reads a
//! colour image; one that reads is then a scene's backdrop
//! (`backdrop.image`, the same reader), and an 8×8 thumbnail of a small
//! glass sphere over it is rendered, whose every pixel must be finite.
#![no_main]

use std::sync::{Arc, OnceLock};

use libfuzzer_sys::fuzz_target;
use snell::film::metrics::RgbImage;
use snell::prepare::Prepared;
use snell::scene::Scene;
use snell_fuzz::{limit_memory, options, put};

const SCENE: &str = r#"
[image]
width = 8
height = 8
[camera]
kind = "perspective"
position = [7.5, 7.5, -40.0]
look_at = [7.5, 7.5, 7.5]
up = [0.0, 1.0, 0.0]
fov_y = 20.0
[volume.phantom]
kind = "sphere"
size = 16
radius = 5.0
sigma = 1.0
format = "u8"
[surface]
filter = "bspline3"
iso = 127.5
ior = 1.5
[backdrop]
center = [7.5, 7.5, 50.0]
normal = [0.0, 0.0, -1.0]
u_axis = [-1.0, 0.0, 0.0]
image = "in.png"
width = 30.0
[render]
samples = 2
max_events = 16
"#;

fuzz_target!(|data: &[u8]| {
    limit_memory();
    let path = put("in.png", data);
    match RgbImage::read(&path) {
        Ok(img) => {
            assert_eq!(img.pixels.len(), img.width as usize * img.height as usize);
            assert!(img.pixels.iter().flatten().all(|v| v.is_finite()));
        }
        Err(e) => {
            // The backdrop takes the same path (`film::photo::read`): an
            // image that does not read fails the scene the same way.
            assert!(e.to_string().contains("in.png"), "unnamed file: {e}");
            return;
        }
    }
    // The scene's relative image path resolves beside its (unread) file.
    let scene_path = path.with_file_name("photo.toml");
    let scene = match Scene::parse(SCENE, &scene_path, &[]) {
        Ok(s) => s,
        Err(e) => {
            assert!(e.to_string().contains("in.png"), "unnamed file: {e}");
            return;
        }
    };
    static PREP: OnceLock<Prepared> = OnceLock::new();
    let prep = PREP.get_or_init(|| {
        let vol = scene
            .load_volume(&options(false))
            .expect("the sphere phantom");
        Prepared::new(Arc::new(vol), scene.surface.filter)
    });
    let frame = snell::render::render(&scene, prep, None);
    assert!(
        frame.film.color.iter().flatten().all(|v| v.is_finite()),
        "non-finite pixel"
    );
});
