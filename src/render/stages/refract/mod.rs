//! Stage 5: bend the ray at the crossing by Snell's law.
//!
//! The outward normal is `n = -∇f/|∇f|` (the object is `f > iso`), from the
//! analytic gradient in world units (grid gradient divided by spacing). Total
//! internal reflection mirrors the ray and keeps its medium. A vanishing
//! gradient gives no normal: the ray passes straight but changes medium. After
//! `max_events` events the ray stops with no backdrop hit (SPEC).

#[cfg(target_arch = "x86_64")]
mod wide;

use glam::DVec3;

use super::super::context::Ctx;
use super::super::packet::{Fate, Queue, Rays};
use super::place;
use super::traverse::{CellRay, cell_ray, cell_span, exit_cell, in_range};
use crate::classify::CurvatureBounds;
use crate::classify::curvature;
use crate::filter::coeffs::Coefficient;
use crate::render::stats::Counters;
use crate::scene::Traversal;
use crate::simd::{Isa, prefetch};

/// Result of bending a unit direction `d` at a surface with outward normal
/// `n`, going from index `n1` into `n2`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Bend {
    Refracted(DVec3),
    Reflected(DVec3),
}

/// Snell's law with total internal reflection. `d` and `n` must be unit.
#[inline]
pub fn snell(d: DVec3, n: DVec3, n1: f64, n2: f64) -> Bend {
    // Orient the normal against the incoming ray.
    let nf = if d.dot(n) > 0.0 { -n } else { n };
    let cos_i = (-d.dot(nf)).clamp(0.0, 1.0);
    let eta = n1 / n2;
    let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
    if k < 0.0 {
        Bend::Reflected((d + 2.0 * cos_i * nf).normalize())
    } else {
        Bend::Refracted((eta * d + (eta * cos_i - k.sqrt()) * nf).normalize())
    }
}

pub fn refract<const S: usize, T: Coefficient>(
    ctx: &Ctx<T>,
    rays: &mut Rays,
    input: &[u32],
    traverse: &mut Queue,
    record: &mut Queue,
    c: &mut Counters,
) {
    crate::with_isa!(Isa::current(), L, _M => refract_runs::<S, L, T>(ctx, rays, input, traverse, record, c))
}

/// Crossings per run: two AVX-512 vectors of `f64` (four AVX2 ones), so
/// that one group's gradient loads and arithmetic can overlap the other's
/// (the likely reason for the gain below), and the bending and clipping run
/// over 16 lanes. Against runs of one vector
/// (8), single thread, min of 5 (3) alternating runs: refract stage sphere
/// 15.48 → 15.04 ms, teapot 37.2 → 36.0, cranium 22.8 → 21.8; runs of 32
/// gained nothing more on the sphere.
const RUN: usize = 16;

/// The stage over runs of [`RUN`] crossings: the gradients in vector lanes
/// of `L` ([`Field::value_grad_fast_lanes`]), the bending in lanes of the
/// run ([`bend_lanes`]), then each ray's new piece.
///
/// [`Field::value_grad_fast_lanes`]: crate::filter::Field::value_grad_fast_lanes
#[inline(always)]
fn refract_runs<const S: usize, const L: usize, T: Coefficient>(
    ctx: &Ctx<T>,
    rays: &mut Rays,
    input: &[u32],
    traverse: &mut Queue,
    record: &mut Queue,
    c: &mut Counters,
) {
    let hi = ctx.field.dims().map(|n| (n - 1) as f64);
    // Restart a hair past the crossing so its root is not found again.
    let eps_vox = (10.0 * ctx.settings.tolerance).max(1e-9);
    let mut checks = ClearChecks::default();
    // Far above the rounding of the solve's polynomial, which scales with
    // the largest coefficient (as `Field::separating_iso`'s nudge does).
    let margin = 1e-9
        * ctx
            .iso
            .abs()
            .max(ctx.field.max_abs_coeff())
            .max(f64::MIN_POSITIVE);
    // `n1 / n2` entering and leaving, as `snell` divides them.
    let eta_entering = ctx.ior_outside / ctx.ior_inside;
    let eta_leaving = ctx.ior_inside / ctx.ior_outside;
    #[cfg(target_arch = "x86_64")]
    let lanes = ctx.curvature.is_some_and(wide::fits);
    #[cfg(not(target_arch = "x86_64"))]
    let lanes = false;
    for run in input.chunks(RUN) {
        let mut at = Crossings::default();
        // Lanes past the run's end evaluate at the grid's origin; their
        // results are not read.
        let mut q = [[0.0; RUN]; 3];
        for (l, &r) in run.iter().enumerate() {
            let i = r as usize;
            let d = rays.direction(i);
            let p = rays.origin(i) + rays.t[i] * d;
            let pg = ctx.to_grid(p);
            let ql = [
                pg.x.clamp(0.0, hi[0]),
                pg.y.clamp(0.0, hi[1]),
                pg.z.clamp(0.0, hi[2]),
            ];
            for a in 0..3 {
                at.dir[a][l] = d[a];
                q[a][l] = ql[a];
            }
            at.eta[l] = if rays.inside[i] {
                eta_leaving
            } else {
                eta_entering
            };
            at.point[l] = p;
            at.unclamped[l] = ql == pg.to_array();
        }
        c.kernel_evals += run.len() as u64;
        for h in (0..RUN).step_by(L) {
            if h >= run.len() {
                break;
            }
            let qh: [[f64; L]; 3] = std::array::from_fn(|a| std::array::from_fn(|l| q[a][h + l]));
            // SAFETY: L is bound by `with_isa!` in `refract`.
            let (value, grad) = unsafe { ctx.field.value_grad_fast_lanes::<S, L>(&qh) };
            for l in 0..L {
                at.value[h + l] = value[l];
                for a in 0..3 {
                    at.grad[a][h + l] = grad[a][l];
                }
            }
        }
        let bent = bend_lanes(&at, ctx.inv_spacing, eps_vox);
        let pieces = pieces_lanes(ctx, &at.point, &bent);
        for (l, &r) in run.iter().enumerate() {
            let i = r as usize;
            // The cell whose solve found the crossing.
            let crossing_cell = rays.cell_of(i);
            let entering = !rays.inside[i];
            match bent.outcome[l] {
                Outcome::Degenerate => {
                    c.degenerate_normals += 1;
                    rays.inside[i] = entering;
                }
                Outcome::Refracted => {
                    c.refractions += 1;
                    rays.inside[i] = entering;
                }
                Outcome::Reflected => c.reflections += 1,
            }
            let p = at.point[l];
            let new_dir = DVec3::new(bent.dir[0][l], bent.dir[1][l], bent.dir[2][l]);
            rays.events[i] += 1;
            rays.set_origin(i, p);
            rays.set_direction(i, new_dir);
            if rays.events[i] >= ctx.settings.max_events {
                c.terminated += 1;
                rays.fate[i] = Fate::Terminated;
                record.push(r);
                continue;
            }
            let eps = bent.eps[l];
            match pieces.clip[l] {
                Some((_, t1)) if t1 > eps => {
                    if ctx.traversal() == Traversal::Step {
                        // The march also samples the field where it starts.
                        place::<S, _>(ctx, rays, i, (eps, eps), t1, c);
                    } else {
                        pieces.place(rays, i, l, t1);
                    }
                    let grad = [0, 1, 2].map(|a| at.grad[a][l]);
                    if let Some(bounds) = ctx.curvature
                        && at.unclamped[l]
                        && let Some(check) = ClearCheck::new(
                            bounds,
                            rays,
                            i,
                            crossing_cell,
                            at.value[l] - ctx.iso,
                            grad,
                        )
                    {
                        checks.push(check);
                        if checks.is_full() {
                            clear_cells(ctx, bounds, &mut checks, margin, lanes, rays, c);
                        }
                    }
                    traverse.push(r);
                }
                _ => {
                    rays.fate[i] = Fate::Escaped;
                    record.push(r);
                }
            }
        }
    }
    if let Some(bounds) = ctx.curvature {
        clear_cells(ctx, bounds, &mut checks, margin, lanes, rays, c);
    }
}

/// A run's crossings: the incoming directions, the field and its gradient
/// (grid units) there, and `n1 / n2` for each ray. Lanes past the run's end
/// hold a zero direction and the field at the grid's origin; what they bend
/// to is never read.
#[derive(Default)]
struct Crossings {
    dir: [[f64; RUN]; 3],
    grad: [[f64; RUN]; 3],
    eta: [f64; RUN],
    point: [DVec3; RUN],
    value: [f64; RUN],
    /// The crossing lies in the domain (its gradient was not taken at a
    /// clamped point).
    unclamped: [bool; RUN],
}

#[derive(Clone, Copy, Default, PartialEq, Debug)]
enum Outcome {
    /// No normal (a vanishing or overflowed gradient): straight on.
    #[default]
    Degenerate,
    Refracted,
    Reflected,
}

/// The bent rays of a run: unit directions, what happened, and the restart
/// offset `eps_vox / |new direction in grid units|`.
struct Bent {
    dir: [[f64; RUN]; 3],
    outcome: [Outcome; RUN],
    eps: [f64; RUN],
}

/// [`snell`] at a run of crossings in vector lanes, with the normal
/// `-∇f/|∇f|` from the world-unit gradient: lane by lane the operations of
/// `snell` and glam's `normalize` in their order (no fused multiply-adds),
/// so bitwise the directions bending one ray at a time gives (tested), with
/// the run's square roots and divisions going through the vector unit
/// together instead of one ray after another.
#[inline(always)]
fn bend_lanes(at: &Crossings, inv_spacing: DVec3, eps_vox: f64) -> Bent {
    let mut bent = Bent {
        dir: [[0.0; RUN]; 3],
        outcome: [Outcome::Degenerate; RUN],
        eps: [0.0; RUN],
    };
    let mut v = [[0.0; RUN]; 3];
    let mut degenerate = [false; RUN];
    let mut reflected = [false; RUN];
    for l in 0..RUN {
        let d: [f64; 3] = std::array::from_fn(|a| at.dir[a][l]);
        let g: [f64; 3] = std::array::from_fn(|a| at.grad[a][l] * inv_spacing[a]);
        let len = ((g[0] * g[0]) + (g[1] * g[1]) + (g[2] * g[2])).sqrt();
        degenerate[l] = !(len > 0.0 && len.is_finite());
        let n: [f64; 3] = std::array::from_fn(|a| -g[a] / len);
        // Orient the normal against the incoming ray.
        let dn = (d[0] * n[0]) + (d[1] * n[1]) + (d[2] * n[2]);
        let nf: [f64; 3] = std::array::from_fn(|a| if dn > 0.0 { -n[a] } else { n[a] });
        let cos_i = (-((d[0] * nf[0]) + (d[1] * nf[1]) + (d[2] * nf[2]))).clamp(0.0, 1.0);
        let eta = at.eta[l];
        let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
        reflected[l] = k < 0.0;
        let (s_d, s_n) = if k < 0.0 {
            (1.0, 2.0 * cos_i)
        } else {
            (eta, eta * cos_i - k.sqrt())
        };
        for a in 0..3 {
            // `d + (2 cos_i) nf` reflected: `1.0 * d` is `d` exactly.
            v[a][l] = s_d * d[a] + s_n * nf[a];
        }
    }
    for l in 0..RUN {
        let len = ((v[0][l] * v[0][l]) + (v[1][l] * v[1][l]) + (v[2][l] * v[2][l])).sqrt();
        let recip = 1.0 / len;
        for a in 0..3 {
            bent.dir[a][l] = if degenerate[l] {
                at.dir[a][l]
            } else {
                v[a][l] * recip
            };
        }
        bent.outcome[l] = if degenerate[l] {
            Outcome::Degenerate
        } else if reflected[l] {
            Outcome::Reflected
        } else {
            Outcome::Refracted
        };
        let gd: [f64; 3] = std::array::from_fn(|a| bent.dir[a][l] * inv_spacing[a]);
        bent.eps[l] = eps_vox / ((gd[0] * gd[0]) + (gd[1] * gd[1]) + (gd[2] * gd[2])).sqrt();
    }
    bent
}

/// The new pieces of a run of bent rays, computed in vector lanes: where
/// each leaves the active box ([`Ctx::clip`]), and what [`place`] would set
/// for a piece starting at the restart offset — the reciprocal of its
/// direction in cell coordinates, and the cell there. The same operations on
/// the same values as those functions, so the same bits (tested), with the
/// run's divisions and floors in vector instructions instead of six scalar
/// divisions per ray.
///
/// [`place`]: super::place
struct Pieces {
    clip: [Option<(f64, f64)>; RUN],
    cell_inv: [[f64; RUN]; 3],
    cell: [[i64; RUN]; 3],
    /// The restart offset (grid units over the direction's length).
    eps: [f64; RUN],
}

#[inline(always)]
fn pieces_lanes<T: Coefficient>(ctx: &Ctx<T>, point: &[DVec3; RUN], bent: &Bent) -> Pieces {
    let mut o = [[0.0; RUN]; 3];
    for l in 0..RUN {
        for a in 0..3 {
            o[a][l] = point[l][a];
        }
    }
    let d = &bent.dir;
    let mut p = Pieces {
        clip: ctx.clip_lanes(&o, d),
        cell_inv: [[0.0; RUN]; 3],
        cell: [[0; RUN]; 3],
        eps: bent.eps,
    };
    let inv_spacing = ctx.inv_spacing;
    for a in 0..3 {
        for l in 0..RUN {
            let dg = d[a][l] * inv_spacing[a];
            p.cell_inv[a][l] = if dg != 0.0 { 1.0 / dg } else { 0.0 };
            // `move_walk` at the restart offset: `to_grid(o + eps·d)`.
            let at = (o[a][l] + p.eps[l] * d[a][l]) * inv_spacing[a];
            p.cell[a][l] = ctx.lattice.cell_of(a, at);
        }
    }
    p
}

impl Pieces {
    /// [`place`] for ray `i` (lane `l`): its piece and walk from the
    /// restart offset to `t_end`, for the cell traversals (the march also
    /// samples the field there, so it takes `place` itself).
    ///
    /// [`place`]: super::place
    #[inline(always)]
    fn place(&self, rays: &mut Rays, i: usize, l: usize, t_end: f64) {
        for a in 0..3 {
            rays.cell_inv[a][i] = self.cell_inv[a][l];
        }
        let eps = self.eps[l];
        rays.t_start[i] = eps;
        rays.t_end[i] = t_end;
        rays.advance[i] = false;
        rays.t[i] = eps;
        rays.set_cell(i, [self.cell[0][l], self.cell[1][l], self.cell[2][l]]);
    }
}

/// A ray just placed a hair past a crossing, waiting for the proof that the
/// rest of the cell it starts in, and maybe the cells after it, hold no
/// crossing ([`clear_cells`]).
#[derive(Clone, Copy, Default)]
struct ClearCheck {
    i: usize,
    /// The slot of the cell's curvature bound (being prefetched).
    slot: usize,
    /// `f - iso` and the gradient (grid units) at the crossing.
    f0: f64,
    grad: [f64; 3],
}

/// Refractions per batch of checks.
const BATCH: usize = 32;

/// Checks in flight, settled a batch at a time ([`clear_cells`]).
#[derive(Default)]
struct ClearChecks {
    items: [ClearCheck; BATCH],
    len: usize,
}

impl ClearChecks {
    fn push(&mut self, c: ClearCheck) {
        self.items[self.len] = c;
        self.len += 1;
    }
    fn is_full(&self) -> bool {
        self.len == self.items.len()
    }
}

impl ClearCheck {
    /// A check for ray `i`, just placed a hair past the crossing its solve
    /// found in `crossing_cell` (`f - iso = f0` and gradient `grad` there, grid
    /// units), with the cell's bound prefetched; `None` when the piece starts
    /// in another cell (the bound holds on closed cells along the path from
    /// the crossing) or the cell is not tagged.
    #[inline(always)]
    fn new(
        bounds: &CurvatureBounds,
        rays: &Rays,
        i: usize,
        crossing_cell: [i64; 3],
        f0: f64,
        grad: [f64; 3],
    ) -> Option<ClearCheck> {
        let cell = rays.cell_of(i);
        // Compared per element: an array compare loaded 16 bytes over values
        // just stored 8 at a time, and that load stalled.
        let moved = (0..3).fold(0, |acc, a| acc | (cell[a] ^ crossing_cell[a]));
        if moved != 0 {
            return None;
        }
        let slot = bounds.slot(cell)?;
        prefetch(bounds.at(slot));
        Some(ClearCheck { i, slot, f0, grad })
    }

    /// The clearance of the rest of the cell the new piece starts in, by the
    /// Taylor bound of [`crate::classify::curvature`], or `None` when it does
    /// not hold, or the slope along the new direction does not have the sign
    /// of the ray's medium.
    #[inline(always)]
    fn start<T: Coefficient>(
        &self,
        ctx: &Ctx<T>,
        bounds: &CurvatureBounds,
        rays: &Rays,
        margin: f64,
    ) -> Option<Clearing> {
        let i = self.i;
        let ray = cell_ray(ctx, rays, i);
        let slope: f64 = (0..3).map(|a| self.grad[a] * ray.du[a]).sum();
        // Inside the object means `f > iso`: leaving the crossing into it,
        // `f` must grow. (An overflowed gradient proves nothing.)
        if !slope.is_finite() || slope == 0.0 || (slope > 0.0) != rays.inside[i] {
            return None;
        }
        let cell = rays.cell_of(i);
        let t_end = rays.t_end[i];
        let mut c = Clearing {
            i,
            ray,
            cell,
            t1: cell_span(&ray, cell).1.min(t_end),
            n: 1,
            t0: rays.t[i],
            t_end,
            slope: slope.abs(),
            f0: self.f0.abs(),
            m: curvature::along(bounds.at(self.slot), ray.du),
            origin: cell,
            next: None,
        };
        if !(c.t0 < c.t1 && c.clear(c.m, c.t1, margin)) {
            return None;
        }
        c.look_ahead(ctx);
        Some(c)
    }
}

/// A clearance in progress: the ray's piece, the Taylor bound's terms, the
/// last cell it cleared, and the next one.
#[derive(Clone, Copy)]
struct Clearing {
    i: usize,
    ray: CellRay,
    /// The last cleared cell and its segment's end.
    cell: [i64; 3],
    t1: f64,
    /// Cells cleared so far.
    n: usize,
    t0: f64,
    t_end: f64,
    slope: f64,
    f0: f64,
    /// The `|f''|` bound over the crossing cell's 3³ neighbourhood.
    m: f64,
    /// The crossing cell: the path may not leave its neighbourhood.
    origin: [i64; 3],
    /// The cell the traversal would visit next, if it is one of the
    /// crossing cell's neighbours (in the lattice): the bound holds there.
    next: Option<[i64; 3]>,
}

impl Clearing {
    /// Whether `|f(s) - iso| ≥ slope·s − |f0| − m s²/2`, concave in `s`, stays
    /// above `margin` on `[t0, t1]`: positive at both ends. A NaN anywhere
    /// (an overflowed bound) clears nothing.
    #[inline(always)]
    fn clear(&self, m: f64, t1: f64, margin: f64) -> bool {
        let q = |s: f64| self.slope * s - self.f0 - 0.5 * m * s * s;
        q(self.t0) > margin && q(t1) > margin
    }

    /// Finds the next cell — where [`exit_cell`] leaves the last one, as the
    /// traversal steps — if the bound covers it (none after the last
    /// extension).
    #[inline(always)]
    fn look_ahead<T: Coefficient>(&mut self, ctx: &Ctx<T>) {
        self.next = None;
        if self.t1 >= self.t_end || self.n > MAX_CLEARED {
            return;
        }
        let (_, next) = exit_cell(&self.ray, self.cell, self.t1);
        let near = (0..3).all(|a| (next[a] - self.origin[a]).abs() <= 1);
        if near && in_range(ctx, next) {
            self.next = Some(next);
        }
    }

    /// Tries to clear the next cell too.
    #[inline(always)]
    fn extend<T: Coefficient>(&mut self, ctx: &Ctx<T>, margin: f64) -> bool {
        let Some(next) = self.next else {
            return false;
        };
        let t1 = cell_span(&self.ray, next).1.min(self.t_end);
        if !self.clear(self.m, t1, margin) {
            return false;
        }
        (self.cell, self.t1, self.n) = (next, t1, self.n + 1);
        self.look_ahead(ctx);
        true
    }

    /// The ray steps past the cleared cells: the traversal resumes from the
    /// last one as it would after that cell's solve (same cell, its
    /// segment's end).
    fn apply(&self, rays: &mut Rays, c: &mut Counters) {
        rays.set_cell(self.i, self.cell);
        rays.t[self.i] = self.t1;
        rays.advance[self.i] = true;
        c.cells_cleared += self.n as u64;
    }
}

/// Cells past the crossing's one a check may clear: a path from a cell
/// steps each axis at most once before it leaves the cell's 3³
/// neighbourhood, where the bound ends.
const MAX_CLEARED: usize = 3;

/// Settles the pending checks, breadth first: the crossing cells of the whole
/// batch, then one more cell for each ray still clear, and so on. Each
/// crossing cell's bound is prefetched a batch before it is read (the bounds
/// are scattered); the cells after it need no other.
///
/// One bound per crossing cell, over its neighbourhood ([`curvature`]),
/// rather than each cell's own bound, the largest along the path: the steps
/// past the crossing cell look nothing up. Against per-cell bounds, 2
/// threads, 20-frame medians, two alternating rounds: the sphere's refract
/// stage 17.7 / 17.8 → 14.2 / 13.9 ms CPU, its solves 1.33 → 1.37 per ray
/// (the looser bound clears fewer crossing cells), frames (distance, PRSS)
/// 32.8 / 33.8 → 31.8 / 31.5 ms; the teapot's refract 39.7 / 41.0 → 29.3 /
/// 27.6 ms, solves 2.35 → 2.44, frames (octree, PRSS) 100.3 / 104.8 → 97.8
/// / 91.0 ms; the same hits, bit for bit, on every scene.
///
/// With `lanes` ([`wide::fits`]), the batch goes to the lane clearing,
/// eight checks at a time ([`wide::clear_cells`]), with the same results.
fn clear_cells<T: Coefficient>(
    ctx: &Ctx<T>,
    bounds: &CurvatureBounds,
    checks: &mut ClearChecks,
    margin: f64,
    lanes: bool,
    rays: &mut Rays,
    c: &mut Counters,
) {
    #[cfg(target_arch = "x86_64")]
    if lanes {
        // SAFETY: `lanes` is `wide::fits`; every check's ray was placed when
        // the check was made.
        unsafe { wide::clear_cells(ctx, bounds, &checks.items[..checks.len], margin, rays, c) };
        checks.len = 0;
        return;
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = lanes;
    let mut live: [Option<Clearing>; BATCH] = [None; BATCH];
    let mut n = 0;
    for check in &checks.items[..checks.len] {
        if let Some(cl) = check.start(ctx, bounds, rays, margin) {
            live[n] = Some(cl);
            n += 1;
        }
    }
    checks.len = 0;
    for _ in 0..MAX_CLEARED {
        let mut any = false;
        for slot in live[..n].iter_mut() {
            if let Some(cl) = slot {
                if cl.extend(ctx, margin) {
                    any = true;
                } else {
                    cl.apply(rays, c);
                    *slot = None;
                }
            }
        }
        if !any {
            break;
        }
    }
    for cl in live[..n].iter().flatten() {
        cl.apply(rays, c);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn obeys_snells_law() {
        let n = DVec3::Y; // outward normal
        let d = DVec3::new(0.6, -0.8, 0.0); // hitting from above
        match snell(d, n, 1.0, 1.5) {
            Bend::Refracted(t) => {
                assert!((t.length() - 1.0).abs() < 1e-15);
                let sin_i = d.x.abs();
                let sin_t = t.x.abs();
                assert!((1.0 * sin_i - 1.5 * sin_t).abs() < 1e-14);
                assert!(t.y < 0.0, "continues through the surface");
            }
            b => panic!("{b:?}"),
        }
        // Normal incidence passes straight.
        assert_eq!(snell(-DVec3::Y, n, 1.0, 1.5), Bend::Refracted(-DVec3::Y));
    }

    /// [`bend_lanes`] gives bitwise what bending one ray at a time with
    /// [`snell`] gives (directions, outcomes, restart offsets), for
    /// refraction both ways, total internal reflection, grazing and head-on
    /// incidence, and vanishing, overflowing or NaN gradients.
    #[test]
    fn lanes_bend_as_snell_bitwise() {
        use crate::phantom::{mix64, uniform};
        let inv_spacing = DVec3::new(1.0, 1.0 / 0.7, 1.0 / 1.3);
        let eps_vox = 1e-7;
        let odd = [0.0, -0.0, f64::NAN, f64::INFINITY, 1e300, 1e-300];
        let mut seen = [0; 3];
        for k in 0..2000u64 {
            let r = |j| 2.0 * uniform(mix64(k), j) - 1.0;
            let mut at = Crossings::default();
            for l in 0..RUN {
                let j = 8 * l as u64;
                let d = DVec3::new(r(j), r(j + 1), r(j + 2)).normalize();
                let mut g = DVec3::new(r(j + 3), r(j + 4), r(j + 5)) * 40.0;
                match k % 7 {
                    0 if l == 1 => g = -d * 3.0,                // head-on
                    1 if l == 2 => g = d.cross(DVec3::Y) * 2.0, // grazing
                    2 if l == 3 => g[(k % 3) as usize] = odd[(k / 7 % 6) as usize],
                    3 if l == 4 => g = DVec3::ZERO,
                    _ => {}
                }
                for a in 0..3 {
                    at.dir[a][l] = d[a];
                    at.grad[a][l] = g[a];
                }
                at.eta[l] = if r(j + 6) > 0.0 { 1.0 / 1.5 } else { 1.5 / 1.0 };
            }
            let bent = bend_lanes(&at, inv_spacing, eps_vox);
            for l in 0..RUN {
                let d = DVec3::new(at.dir[0][l], at.dir[1][l], at.dir[2][l]);
                let grad_world =
                    DVec3::new(at.grad[0][l], at.grad[1][l], at.grad[2][l]) * inv_spacing;
                let len = grad_world.length();
                let (n1, n2) = if at.eta[l] < 1.0 {
                    (1.0, 1.5)
                } else {
                    (1.5, 1.0)
                };
                let (want, outcome) = if !(len > 0.0 && len.is_finite()) {
                    (d, Outcome::Degenerate)
                } else {
                    match snell(d, -grad_world / len, n1, n2) {
                        Bend::Refracted(nd) => (nd, Outcome::Refracted),
                        Bend::Reflected(nd) => (nd, Outcome::Reflected),
                    }
                };
                let got = DVec3::new(bent.dir[0][l], bent.dir[1][l], bent.dir[2][l]);
                assert_eq!(bent.outcome[l], outcome, "{k}/{l}");
                assert_eq!(
                    got.to_array().map(f64::to_bits),
                    want.to_array().map(f64::to_bits),
                    "{k}/{l}"
                );
                let eps = eps_vox / (want * inv_spacing).length();
                assert_eq!(bent.eps[l].to_bits(), eps.to_bits(), "{k}/{l}");
                seen[outcome as usize] += 1;
            }
        }
        assert!(seen.iter().all(|&n| n > 200), "{seen:?}");
    }

    #[test]
    fn total_internal_reflection_mirrors() {
        let n = DVec3::Y;
        let d = DVec3::new(0.8, 0.6, 0.0); // inside glass, going out steeply
        match snell(d, n, 1.5, 1.0) {
            Bend::Reflected(t) => {
                assert!((t - DVec3::new(0.8, -0.6, 0.0)).length() < 1e-15);
            }
            b => panic!("{b:?}"),
        }
        // Just below the critical angle it still refracts, grazing.
        let crit = (1.0f64 / 1.5).asin();
        let a = crit - 1e-9;
        let d = DVec3::new(a.sin(), a.cos(), 0.0);
        assert!(matches!(snell(d, n, 1.5, 1.0), Bend::Refracted(_)));
    }
}
