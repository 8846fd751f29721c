//! What every stage reads: the scene, the prepared field and the constants
//! derived from them once per frame.

use glam::DVec3;

use super::first_hit::FirstHit;
use crate::classify::{CellBound, CurvatureBounds, PlaneBounds, SubCellMasks};
use crate::filter::Field;
use crate::filter::coeffs::Coefficient;
use crate::lattice::Lattice;
use crate::octree::{Octree, Proximity};
use crate::prepare::Prepared;
use crate::roots::bernstein::BernsteinBasis;
use crate::roots::inside;
use crate::scene::{RenderSettings, Scene, Traversal};
use crate::with_support;

/// How the traversal decides which cells to skip.
pub enum Skip<'a> {
    /// A bound from the cell's coefficients, computed per visited cell.
    Bound(CellBound),
    /// Precomputed tags under an octree; `leaf_level` is where the top-down
    /// search stops (the root's level for a plain DDA over the tags).
    Octree { tree: &'a Octree, leaf_level: u32 },
    /// Cubes of empty cells from the distance field.
    Distance(&'a Proximity),
}

/// Shared, read-only state of one frame, over a field whose coefficients
/// are stored as `T`.
pub struct Ctx<'a, T: Coefficient = f64> {
    pub scene: &'a Scene,
    pub field: &'a Field<T>,
    /// The scene's iso-value, nudged above rounding noise
    /// ([`Field::separating_iso`]); every side decision uses it.
    pub iso: f64,
    pub lattice: Lattice,
    pub spacing: DVec3,
    pub inv_spacing: DVec3,
    /// World-space upper corner of the domain (lower corner is the origin).
    pub box_max: DVec3,
    /// The part of the domain rays must traverse: with precomputed tags, the
    /// box of tagged cells grown by one cell (so no tagged cell's segment is
    /// ever clipped by it); else the domain. Empty (`lo > hi`) when nothing is
    /// tagged. Rays that miss it skip the traversal altogether.
    pub active: [DVec3; 2],
    /// The medium of every ray entering the active box through one of its
    /// faces, when the box lies strictly inside the domain
    /// ([`entry_side`]); `None` makes each ray evaluate the field where it
    /// enters.
    pub entry_side: Option<bool>,
    pub basis: BernsteinBasis,
    pub skip: Skip<'a>,
    /// Sub-cell masks of the tagged cells ([`crate::classify::Method::has_masks`]).
    pub masks: Option<&'a SubCellMasks>,
    /// Second-derivative bounds of the tagged cells (B-splines of degree ≥ 2),
    /// when `clear_crossing_cells` is on.
    pub curvature: Option<&'a CurvatureBounds>,
    /// Planes of the tagged cells, when `skip_clear_segments` is on and the
    /// classification has them ([`crate::prepare::Accel::planes`]).
    pub planes: Option<&'a PlaneBounds>,
    /// Where primary rays may start their walk, per pixel block, when
    /// [`RenderSettings::skips_empty_approach`].
    pub first_hit: Option<FirstHit>,
    pub settings: RenderSettings,
    /// Indices of refraction inside and outside the object.
    pub ior_inside: f64,
    pub ior_outside: f64,
}

impl<'a, T: Coefficient> Ctx<'a, T> {
    /// `field` is `prep`'s field in its storage.
    pub fn new(scene: &'a Scene, prep: &'a Prepared, field: &'a Field<T>) -> Ctx<'a, T> {
        let spacing = prep.volume.spacing();
        let kernel = field.kernel();
        let lattice = Lattice::new(kernel, field.dims());
        let spacing = DVec3::from_array(spacing);
        let n = field.dims();
        let box_max = DVec3::new(
            (n[0] - 1) as f64 * spacing.x,
            (n[1] - 1) as f64 * spacing.y,
            (n[2] - 1) as f64 * spacing.z,
        );
        let active = match &prep.accel {
            Some(a) if scene.render.traversal != Traversal::Step => match a.octree.bounds() {
                Some([lo, hi]) => {
                    let off = lattice.offset;
                    let lo = DVec3::from_array(lo.map(|c| c as f64 - 1.0 - off));
                    let hi = DVec3::from_array(hi.map(|c| c as f64 + 2.0 - off));
                    [(lo * spacing).max(DVec3::ZERO), (hi * spacing).min(box_max)]
                }
                None => [DVec3::ONE, DVec3::ZERO],
            },
            _ => [DVec3::ZERO, box_max],
        };
        let iso = field.separating_iso(scene.surface.iso);
        let inside_domain = active[0].cmple(active[1]).all()
            && active[0].cmpgt(DVec3::ZERO).all()
            && active[1].cmplt(box_max).all();
        Ctx {
            scene,
            active,
            entry_side: inside_domain.then(|| entry_side(field, iso, active[0] / spacing)),
            field,
            iso,
            lattice,
            spacing,
            inv_spacing: DVec3::ONE / spacing,
            box_max,
            basis: BernsteinBasis::new(3 * (kernel.support() - 1)),
            skip: match (&prep.accel, scene.render.traversal) {
                (Some(a), Traversal::Octree) => Skip::Octree {
                    tree: &a.octree,
                    leaf_level: scene.render.leaf.max(1).ilog2().max(1),
                },
                (Some(a), Traversal::Dda) => Skip::Octree {
                    tree: &a.octree,
                    leaf_level: a.octree.top(),
                },
                (Some(a), Traversal::Distance) => Skip::Distance(a.proximity().0),
                _ => Skip::Bound(CellBound::new(kernel)),
            },
            // Built on demand if `Prepared::ready_for` did not (then untimed).
            masks: prep.accel.as_ref().and_then(|a| a.masks(&prep.field).0),
            curvature: if scene.render.clears_crossing_cells() {
                prep.accel.as_ref().and_then(|a| a.curvature(&prep.field).0)
            } else {
                None
            },
            planes: if scene.render.skips_clear_segments() {
                prep.accel.as_ref().and_then(|a| a.planes(&prep.field).0)
            } else {
                None
            },
            first_hit: match &prep.accel {
                Some(a) if scene.render.skips_empty_approach() => Some(FirstHit::build(
                    &scene.camera,
                    &a.octree,
                    spacing,
                    lattice.offset,
                )),
                _ => None,
            },
            settings: scene.render,
            ior_inside: scene.surface.ior,
            ior_outside: scene.surface.outside_ior,
        }
    }

    pub fn traversal(&self) -> Traversal {
        self.settings.traversal
    }

    /// Parameter interval `[t0, t1]` (with `t0 >= t_min`) where the ray is
    /// inside the active box ([`Ctx::active`]), if any. Slab test with explicit handling of
    /// directions parallel to a face.
    #[inline]
    pub fn clip(&self, o: DVec3, d: DVec3, t_min: f64) -> Option<(f64, f64)> {
        if self.active[0].cmpgt(self.active[1]).any() {
            return None;
        }
        let mut t0 = t_min;
        let mut t1 = f64::INFINITY;
        for a in 0..3 {
            let (lo, hi) = (self.active[0][a], self.active[1][a]);
            if d[a] == 0.0 {
                if o[a] < lo || o[a] > hi {
                    return None;
                }
                continue;
            }
            let inv = 1.0 / d[a];
            let (mut ta, mut tb) = ((lo - o[a]) * inv, (hi - o[a]) * inv);
            if ta > tb {
                std::mem::swap(&mut ta, &mut tb);
            }
            t0 = t0.max(ta);
            t1 = t1.min(tb);
        }
        t1 = self.before_backdrop(o, d, t1);
        if t0 <= t1 && t1.is_finite() {
            Some((t0, t1))
        } else {
            None
        }
    }

    /// [`Ctx::clip`] from `t_min = 0` for `N` rays in lanes (origins
    /// `o[axis][lane]`, directions `d`): the same operations in the same
    /// order for every lane, so bitwise what each ray alone gives (tested),
    /// with the divisions of all lanes in vector instructions.
    #[inline(always)]
    pub fn clip_lanes<const N: usize>(
        &self,
        o: &[[f64; N]; 3],
        d: &[[f64; N]; 3],
    ) -> [Option<(f64, f64)>; N] {
        if self.active[0].cmpgt(self.active[1]).any() {
            return [None; N];
        }
        let mut t0 = [0.0f64; N];
        let mut t1 = [f64::INFINITY; N];
        let mut missed = [false; N];
        for a in 0..3 {
            let (lo, hi) = (self.active[0][a], self.active[1][a]);
            for l in 0..N {
                let (o, d) = (o[a][l], d[a][l]);
                if d == 0.0 {
                    missed[l] |= o < lo || o > hi;
                    continue;
                }
                let inv = 1.0 / d;
                let (ta, tb) = ((lo - o) * inv, (hi - o) * inv);
                let (ta, tb) = if ta > tb { (tb, ta) } else { (ta, tb) };
                t0[l] = t0[l].max(ta);
                t1[l] = t1[l].min(tb);
            }
        }
        for l in 0..N {
            let at = |v: &[[f64; N]; 3]| DVec3::new(v[0][l], v[1][l], v[2][l]);
            t1[l] = self.before_backdrop(at(o), at(d), t1[l]);
        }
        std::array::from_fn(|l| {
            (!missed[l] && t0[l] <= t1[l] && t1[l].is_finite()).then_some((t0[l], t1[l]))
        })
    }

    /// `t1` cut short where the ray meets the backdrop first: the plane is
    /// opaque, so a backdrop in front of the volume or through it ends the
    /// ray's walk there, and the record stage finds that hit (the same
    /// [`Backdrop::plane_t`](crate::scene::Backdrop::plane_t) from the same
    /// origin). A backdrop beyond the box, every usual scene's, leaves
    /// `t1` as it is, bit for bit.
    #[inline(always)]
    fn before_backdrop(&self, o: DVec3, d: DVec3, t1: f64) -> f64 {
        match self.scene.backdrop.plane_t(o, d) {
            Some(t) if t < t1 => t,
            _ => t1,
        }
    }

    /// World point → grid coordinates.
    #[inline(always)]
    pub fn to_grid(&self, p: DVec3) -> DVec3 {
        p * self.inv_spacing
    }
}

/// The field's side of `iso` on the whole surface of an active box that lies
/// strictly inside the domain, from one evaluation at its corner `corner`
/// (grid coordinates).
///
/// The box is the tagged cells' bounding box grown by one cell, so every
/// point of its surface (and every point a rounding error away) lies in a
/// closed cell left untagged, where the classification proved `f - iso`
/// non-zero with a margin above evaluation rounding. The surface is
/// connected and `f` continuous, so that sign is one constant over it, and
/// every point evaluation there gives it: primary rays that enter through a
/// face need no evaluation of their own.
fn entry_side<T: Coefficient>(field: &Field<T>, iso: f64, corner: DVec3) -> bool {
    let n = field.dims();
    let q: [f64; 3] = std::array::from_fn(|a| corner[a].clamp(0.0, (n[a] - 1) as f64));
    inside(with_support!(field.kernel().support(), S => field.value_in::<S>(q)) - iso)
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::classify::Method;
    use crate::phantom::{mix64, uniform};
    use crate::volume::{SampleType, Volume};
    use crate::with_field;

    /// `n³` samples: `inner` in a ball of radius `n/4` about the centre,
    /// `outer` elsewhere.
    fn ball(n: usize, inner: f32, outer: f32) -> Volume {
        let c = (n - 1) as f64 / 2.0;
        let mut s = Vec::with_capacity(n * n * n);
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    let r2 = [x, y, z]
                        .iter()
                        .map(|&v| (v as f64 - c).powi(2))
                        .sum::<f64>();
                    s.push(if r2 <= (n as f64 / 4.0).powi(2) {
                        inner
                    } else {
                        outer
                    });
                }
            }
        }
        Volume::new([n; 3], [1.0; 3], SampleType::F32, s).unwrap()
    }

    fn scene(traversal: &str) -> Scene {
        crate::render::testing::small_scene(100.0, &[format!("render.traversal={traversal}")])
    }

    /// The lanes clip as [`Ctx::clip`] does, bit for bit: rays from inside
    /// and outside the active box, along axes (zero components, inside and
    /// outside the slab), towards and away from it, and with NaN or
    /// infinite components; and an empty box clips everything.
    #[test]
    fn lanes_clip_as_each_ray_does() {
        let sc = scene("octree");
        let prep = Prepared::new(Arc::new(ball(24, 200.0, 0.0)), sc.surface.filter)
            .with_accel(sc.surface.iso, Method::Bezier(2));
        with_field!(&prep.field, f => {
            let ctx = Ctx::new(&sc, &prep, f.as_ref());
            let odd = [0.0, -0.0, f64::NAN, f64::INFINITY, 1e-300];
            let mut some = 0;
            for k in 0..4000u64 {
                let u = |j| 2.0 * uniform(mix64(k), j) - 1.0;
                let mut o = [[0.0; 8]; 3];
                let mut d = [[0.0; 8]; 3];
                for l in 0..8 {
                    let j = 8 * l as u64;
                    let mut ol = DVec3::splat(11.5) + 20.0 * DVec3::new(u(j), u(j + 1), u(j + 2));
                    // Half of them aimed near the ball.
                    let aim = DVec3::splat(11.5) + 4.0 * DVec3::new(u(j + 3), u(j + 4), u(j + 5));
                    let mut dl = if k % 2 == 0 {
                        (aim - ol).normalize()
                    } else {
                        DVec3::new(u(j + 3), u(j + 4), u(j + 5)).normalize()
                    };
                    if (k + l as u64).is_multiple_of(6) {
                        dl[(k % 3) as usize] = odd[(k / 6 % 5) as usize];
                    }
                    if (k + l as u64).is_multiple_of(13) {
                        ol[(k % 3) as usize] = odd[(k / 13 % 5) as usize];
                    }
                    for a in 0..3 {
                        o[a][l] = ol[a];
                        d[a][l] = dl[a];
                    }
                }
                let got = ctx.clip_lanes(&o, &d);
                for l in 0..8 {
                    let (ol, dl) = (
                        DVec3::new(o[0][l], o[1][l], o[2][l]),
                        DVec3::new(d[0][l], d[1][l], d[2][l]),
                    );
                    let want = ctx.clip(ol, dl, 0.0);
                    let bits = |c: Option<(f64, f64)>| c.map(|(a, b)| (a.to_bits(), b.to_bits()));
                    assert_eq!(bits(got[l]), bits(want), "{k}/{l}: {ol:?} {dl:?}");
                    some += want.is_some() as usize;
                }
            }
            assert!(some > 12_000 && some < 30_000, "{some}");
        });
    }

    /// Rays from every side entering the active box through a face find the
    /// field on the side [`Ctx::entry_side`] states, for a ball above the
    /// iso-value in a background below it and the other way round; a box
    /// reaching the domain's boundary gives no side.
    #[test]
    fn entry_side_is_the_field_side_on_every_face() {
        for (inner, outer, expect) in [(200.0, 0.0, false), (0.0, 200.0, true)] {
            let sc = scene("octree");
            let prep = Prepared::new(Arc::new(ball(24, inner, outer)), sc.surface.filter)
                .with_accel(sc.surface.iso, Method::Bezier(2));
            with_field!(&prep.field, f => {
                let ctx = Ctx::new(&sc, &prep, f.as_ref());
                assert_eq!(ctx.entry_side, Some(expect));
                let centre = DVec3::splat(11.5);
                let mut entered = 0;
                for k in 0..4000u64 {
                    let u = |j| 2.0 * uniform(mix64(k), j) - 1.0;
                    let from = centre + 60.0 * DVec3::new(u(0), u(1), u(2)).normalize();
                    let to = centre + 8.0 * DVec3::new(u(3), u(4), u(5));
                    let d = (to - from).normalize();
                    let Some((t0, _)) = ctx.clip(from, d, 0.0) else { continue };
                    assert!(t0 > 0.0);
                    let q = ctx.to_grid(from + t0 * d).to_array();
                    let g = with_support!(4, S => f.value_in::<S>(q)) - ctx.iso;
                    assert_eq!(inside(g), expect, "ray {k} enters at {q:?}");
                    entered += 1;
                }
                assert!(entered > 3000, "{entered}");
            });
        }
        // Above the iso-value but for two layers at x = 0, 1: tagged cells
        // reach the domain's boundary.
        let n = 24;
        let s = (0..n * n * n)
            .map(|i| if i % n < 2 { 0.0 } else { 200.0 })
            .collect();
        let vol = Volume::new([n; 3], [1.0; 3], SampleType::F32, s).unwrap();
        let sc = scene("octree");
        let prep = Prepared::new(Arc::new(vol), sc.surface.filter)
            .with_accel(sc.surface.iso, Method::Bezier(2));
        with_field!(&prep.field, f => {
            assert_eq!(Ctx::new(&sc, &prep, f.as_ref()).entry_side, None);
        });
        // Without classification every ray evaluates its own side.
        let sc = scene("dda");
        let prep = Prepared::new(Arc::new(ball(n, 200.0, 0.0)), sc.surface.filter);
        with_field!(&prep.field, f => {
            assert_eq!(Ctx::new(&sc, &prep, f.as_ref()).entry_side, None);
        });
    }
}
