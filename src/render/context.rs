//! What every stage reads: the scene, the prepared field and the constants
//! derived from them once per frame.

use glam::DVec3;

use super::first_hit::FirstHit;
use crate::classify::{CellBound, CurvatureBounds, SubCellMasks};
use crate::filter::Field;
use crate::filter::coeffs::Coefficient;
use crate::lattice::Lattice;
use crate::octree::{Octree, Proximity};
use crate::prepare::Prepared;
use crate::roots::bernstein::BernsteinBasis;
use crate::scene::{RenderSettings, Scene, Traversal};

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
    pub basis: BernsteinBasis,
    pub skip: Skip<'a>,
    /// Sub-cell masks of the tagged cells (Bézier classification).
    pub masks: Option<&'a SubCellMasks>,
    /// Second-derivative bounds of the tagged cells (B-splines of degree ≥ 2),
    /// when `clear_crossing_cells` is on.
    pub curvature: Option<&'a CurvatureBounds>,
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
        Ctx {
            scene,
            active,
            field,
            iso: field.separating_iso(scene.surface.iso),
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
        if t0 <= t1 && t1.is_finite() {
            Some((t0, t1))
        } else {
            None
        }
    }

    /// World point → grid coordinates.
    #[inline(always)]
    pub fn to_grid(&self, p: DVec3) -> DVec3 {
        p * self.inv_spacing
    }
}
