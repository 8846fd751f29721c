//! Fixtures the renderer's unit tests share: a small scene around a 24³
//! volume, and a volume whose many small tagged regions exercise the walks
//! and the crossing-cell clearing.

use crate::scene::Scene;
use crate::volume::{SampleType, Volume};

/// A 8×8 render of a 24³ volume centred at 11.5 (camera in front, backdrop
/// behind), bspline3 at `iso`, with the `--set` overrides `sets`.
pub fn small_scene(iso: f64, sets: &[String]) -> Scene {
    let text = format!(
        "[image]\nwidth = 8\nheight = 8\n\
        [camera]\nkind = 'perspective'\nposition = [11.5, 11.5, -60.0]\nlook_at = [11.5, 11.5, 11.5]\nup = [0.0, 1.0, 0.0]\nfov_y = 20.0\n\
        [volume.phantom]\nkind = 'sphere'\nsize = 24\nradius = 6.0\nsigma = 1.0\n\
        [surface]\nfilter = 'bspline3'\niso = {iso:?}\nior = 1.5\n\
        [backdrop]\ncenter = [11.5, 11.5, 80.0]\nnormal = [0.0, 0.0, -1.0]\nu_axis = [1.0, 0.0, 0.0]\nchecker = 4.0\n"
    );
    Scene::parse(&text, std::path::Path::new("test.toml"), sets).unwrap()
}

/// A 24³ volume: a ball of radius 7 with scrambled samples (0..255, from
/// `seed`) inside — many small tagged regions, high curvature bounds — and
/// a smooth ramp `4r` outside.
pub fn scrambled_ball(seed: u64) -> Volume {
    use crate::phantom::{mix64, uniform};
    let n = 24;
    let c = (n - 1) as f64 / 2.0;
    let mut s = Vec::with_capacity(n * n * n);
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let p = [x, y, z].map(|v| v as f64 - c);
                let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                let k = (x + n * (y + n * z)) as u64;
                s.push(if r < 7.0 {
                    (255.0 * uniform(mix64(seed), k)) as f32
                } else {
                    (r * 4.0) as f32
                });
            }
        }
    }
    Volume::new([n; 3], [1.0; 3], SampleType::F32, s).unwrap()
}
