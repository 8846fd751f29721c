//! Turntable sequences: the scene's view turned step by step about the
//! volume, for animations and for steady-state frame timing (the
//! preparation is made once; only the camera and the backdrop move).
//!
//! The camera and the backdrop go round together about the vertical axis
//! of the image (the camera's up) through the volume's centre, so the
//! volume seems to turn on a turntable in front of a fixed camera and
//! backdrop, the other way round. Each frame's backdrop coordinates (the
//! hit-position EXR's `u`, `v`) are in that frame's turned backdrop, so a
//! frame compares with frame 0 as if the volume itself had turned.

use glam::{DQuat, DVec3};

use super::{Backdrop, Camera, Scene};

/// Largest number of frames in one orbit (a frame every 0.1°).
pub const MAX_FRAMES: u32 = 3600;

/// A full turn of a scene's view in `frames` equal steps.
#[derive(Clone, Debug)]
pub struct Orbit {
    frames: u32,
    pivot: DVec3,
    axis: DVec3,
    camera: Camera,
    backdrop: [DVec3; 4],
}

/// Why an orbit cannot be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OrbitError {
    #[error("an orbit has 1 to {MAX_FRAMES} frames, got {0}")]
    Frames(u32),
    #[error("the orbit's centre must be finite, got {0}")]
    Pivot(DVec3),
}

impl Orbit {
    /// The orbit of `scene`'s view about the vertical axis (the camera's up)
    /// through `pivot`, in `frames` steps of `360° / frames`; frame 0 is the
    /// scene's own view.
    pub fn new(scene: &Scene, pivot: DVec3, frames: u32) -> Result<Orbit, OrbitError> {
        if !(1..=MAX_FRAMES).contains(&frames) {
            return Err(OrbitError::Frames(frames));
        }
        if !pivot.is_finite() {
            return Err(OrbitError::Pivot(pivot));
        }
        let b = &scene.backdrop;
        Ok(Orbit {
            frames,
            pivot,
            axis: scene.camera.up.normalize(),
            camera: scene.camera,
            backdrop: [b.center, b.normal, b.u_axis, b.v_axis],
        })
    }

    /// The orbit about the centre of a volume's domain (`extent / 2` in
    /// world units, SPEC.md's coordinates), where a scene's camera usually
    /// looks.
    pub fn about_volume(scene: &Scene, extent: [f64; 3], frames: u32) -> Result<Orbit, OrbitError> {
        Orbit::new(scene, DVec3::from_array(extent) * 0.5, frames)
    }

    pub fn frames(&self) -> u32 {
        self.frames
    }

    /// Frame `k`'s turn in degrees: `360 k / frames`.
    pub fn degrees(&self, k: u32) -> f64 {
        360.0 * k as f64 / self.frames as f64
    }

    /// Sets `scene`'s camera and backdrop to frame `k`'s. Frame 0 restores
    /// the view the orbit was made from bit for bit (a turn by zero would
    /// still round the positions, moved to the pivot and back).
    pub fn place(&self, scene: &mut Scene, k: u32) {
        let [center, normal, u_axis, v_axis] = self.backdrop;
        if k.is_multiple_of(self.frames) {
            scene.camera = self.camera;
            set_frame(&mut scene.backdrop, [center, normal, u_axis, v_axis]);
            return;
        }
        let turn = DQuat::from_axis_angle(self.axis, self.degrees(k).to_radians());
        let point = |p: DVec3| self.pivot + turn * (p - self.pivot);
        let c = &self.camera;
        scene.camera = Camera {
            position: point(c.position),
            forward: turn * c.forward,
            right: turn * c.right,
            up: turn * c.up,
            ..*c
        };
        set_frame(
            &mut scene.backdrop,
            [point(center), turn * normal, turn * u_axis, turn * v_axis],
        );
    }
}

/// The backdrop's plane and axes, its pattern kept (a photograph is not
/// copied per frame).
fn set_frame(b: &mut Backdrop, [center, normal, u_axis, v_axis]: [DVec3; 4]) {
    (b.center, b.normal, b.u_axis, b.v_axis) = (center, normal, u_axis, v_axis);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sphere_scene() -> Scene {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/sphere.toml");
        Scene::load(&path, &[]).unwrap()
    }

    /// Every frame keeps the camera's frame orthonormal and its distance to
    /// the pivot, turns the backdrop rigidly with it (the camera's view of
    /// the backdrop is the same in every frame), and a full turn comes back:
    /// frame `frames` (and 0) is the scene's view bit for bit.
    #[test]
    fn frames_turn_camera_and_backdrop_together() {
        let base = sphere_scene();
        let pivot = DVec3::splat(31.5);
        let orbit = Orbit::new(&base, pivot, 7).unwrap();
        let mut s = sphere_scene();
        let close = |a: DVec3, b: DVec3| (a - b).length() < 1e-12 * (1.0 + b.length());
        for k in 0..=7 {
            orbit.place(&mut s, k);
            let c = &s.camera;
            for (a, b) in [(c.forward, c.right), (c.right, c.up), (c.up, c.forward)] {
                assert!(a.dot(b).abs() < 1e-14, "{k}");
            }
            assert!(
                ((c.position - pivot).length() - (base.camera.position - pivot).length()).abs()
                    < 1e-12
            );
            // The backdrop seen from the camera: the same in every frame.
            let seen = |s: &Scene| {
                let (c, b) = (&s.camera, &s.backdrop);
                let rel = b.center - c.position;
                [
                    rel.dot(c.forward),
                    rel.dot(c.right),
                    rel.dot(c.up),
                    b.normal.dot(c.forward),
                    b.u_axis.dot(c.right),
                    b.v_axis.dot(c.up),
                ]
            };
            let (now, then) = (seen(&s), seen(&base));
            for (x, y) in now.iter().zip(then) {
                assert!(
                    (x - y).abs() < 1e-9 * (1.0 + y.abs()),
                    "{k}: {now:?} {then:?}"
                );
            }
            if k % 7 == 0 {
                assert_eq!(s.camera, base.camera);
                assert_eq!(s.backdrop.center, base.backdrop.center);
                assert_eq!(s.backdrop.u_axis, base.backdrop.u_axis);
            } else {
                assert!(!close(s.camera.position, base.camera.position), "{k}");
            }
        }
        // The up axis is the turn's: it never moves.
        orbit.place(&mut s, 3);
        assert!(close(s.camera.up, base.camera.up));
    }

    /// A quarter turn about the sphere scene's vertical axis (y) moves the
    /// camera from -z to the side (+x or -x) of the pivot.
    #[test]
    fn a_quarter_turn_goes_round_the_vertical_axis() {
        let base = sphere_scene();
        let orbit = Orbit::about_volume(&base, [63.0; 3], 4).unwrap();
        let mut s = sphere_scene();
        orbit.place(&mut s, 1);
        let rel = s.camera.position - DVec3::splat(31.5);
        assert!((rel.y).abs() < 1e-9 && (rel.z).abs() < 1e-9, "{rel}");
        assert!((rel.x.abs() - 181.5).abs() < 1e-9, "{rel}");
        assert!((orbit.degrees(1) - 90.0).abs() < 1e-12);
    }

    #[test]
    fn refuses_bad_orbits() {
        let s = sphere_scene();
        assert_eq!(
            Orbit::new(&s, DVec3::ZERO, 0).unwrap_err(),
            OrbitError::Frames(0)
        );
        assert!(Orbit::new(&s, DVec3::ZERO, MAX_FRAMES + 1).is_err());
        assert!(Orbit::new(&s, DVec3::new(f64::NAN, 0.0, 0.0), 3).is_err());
    }
}
