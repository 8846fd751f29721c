//! The crossing-cell clearing ([`super::clear_cells`]) eight checks at a
//! time, with AVX-512.
//!
//! A check reads the crossing cell's neighbourhood bound (one gather per
//! entry, prefetched when the check was made), then steps through at most
//! [`MAX_CLEARED`] + 1 cells of the neighbourhood, evaluating the Taylor
//! bound at each segment's end: a few dozen flops a cell and no loads.
//! Eight checks run together, every per-check choice a mask. (With a bound
//! per cell, each step looked up the next cell's slot in the tagged-cell
//! index and gathered its bound, a dependent chain of scattered loads that
//! the batch's four groups stepping in turn hid; they still step in turn.)
//!
//! Every lane does the scalar clearing's arithmetic in the same order (no
//! fused multiply-adds; `f64::min` as the compiler lowers it), so each ray
//! ends on the same cell and parameter with the same count of cleared
//! cells — tested below against the scalar clearing, check by check.

use std::arch::x86_64::*;

use super::{ClearCheck, MAX_CLEARED};
use crate::classify::CurvatureBounds;
use crate::filter::coeffs::Coefficient;
use crate::render::context::Ctx;
use crate::render::packet::Rays;
use crate::render::stages::traverse::wide::{self as walk, Lanes, exit_box};
use crate::render::stats::Counters;

const LANES: usize = 8;

/// Whether the lane clearing can run over `bounds`: the CPU has the lane
/// walk's features ([`walk::available`]), and every slot of the index has
/// its bound (it always does; the gathers rely on it).
pub fn fits(bounds: &CurvatureBounds) -> bool {
    let (index, table) = bounds.parts();
    walk::available() && table.len() == index.count()
}

/// What the lanes read: the bounds and the lattice.
struct Space {
    /// The bounds' six `f32` values, slot after slot.
    bounds: *const f32,
    n: [__m512i; 3],
    margin: __m512d,
}

/// Eight clearings in progress ([`super::Clearing`] per lane).
#[derive(Clone, Copy)]
struct Clearings {
    ray: Lanes,
    /// The last cleared cell and its segment's end.
    cell: [__m512i; 3],
    t1: __m512d,
    /// Cells cleared so far.
    n: __m512i,
    t0: __m512d,
    t_end: __m512d,
    slope: __m512d,
    f0: __m512d,
    m: __m512d,
    /// The crossing cell: the path may not leave its 3³ neighbourhood.
    origin: [__m512i; 3],
    /// Lanes with a next cell in the neighbourhood, and the cell.
    has_next: __mmask8,
    next: [__m512i; 3],
}

/// Settles `checks` as [`super::clear_cells`] does.
///
/// # Safety
/// [`fits`] must be true for `bounds`, and each check's ray must
/// have been placed (its piece set) since it was made.
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512vpopcntdq,bmi2,popcnt")]
pub unsafe fn clear_cells<T: Coefficient>(
    ctx: &Ctx<T>,
    bounds: &CurvatureBounds,
    checks: &[ClearCheck],
    margin: f64,
    rays: &mut Rays,
    c: &mut Counters,
) {
    let (_, table) = bounds.parts();
    let space = Space {
        bounds: table.as_ptr() as *const f32,
        n: ctx.lattice.cells.map(|n| _mm512_set1_epi64(n as i64)),
        margin: _mm512_set1_pd(margin),
    };
    // The groups step together, one cell each in turn.
    let mut groups: [Option<(Clearings, __mmask8)>; GROUPS] = [None; GROUPS];
    for batch in checks.chunks(LANES * GROUPS) {
        for (g, group) in groups.iter_mut().zip(batch.chunks(LANES)) {
            // SAFETY: this function has the features; the caller's contract.
            *g = Some(unsafe { start(ctx, &space, group, rays) });
        }
        for _ in 0..MAX_CLEARED {
            let mut any = false;
            for g in groups.iter_mut() {
                if let Some((cl, live)) = g
                    && *live != 0
                {
                    // SAFETY: as above.
                    *live = unsafe { step(&space, cl, *live, rays, c) };
                    any |= *live != 0;
                }
            }
            if !any {
                break;
            }
        }
        for g in groups.iter_mut() {
            if let Some((cl, live)) = g.take() {
                // SAFETY: as above.
                unsafe { apply(&cl, live, rays, c) };
            }
        }
    }
}

/// Groups of [`LANES`] checks stepping together.
const GROUPS: usize = super::BATCH / LANES;

/// `f64::min(a, b)` per lane as the compiler lowers it on x86-64: `b` where
/// `a` is NaN, else `b < a ? b : a`.
#[inline(always)]
unsafe fn min_as_scalar(a: __m512d, b: __m512d) -> __m512d {
    // SAFETY: called only from functions with AVX-512 F.
    unsafe {
        let nan = _mm512_cmp_pd_mask::<_CMP_UNORD_Q>(a, a);
        _mm512_mask_mov_pd(_mm512_min_pd(b, a), nan, b)
    }
}

/// [`crate::render::stages::traverse::cell_span`]'s end per lane, then
/// `min(t_end)` as the scalar clearing takes it.
#[inline(always)]
unsafe fn span_end(ray: &Lanes, cell: &[__m512i; 3], t_end: __m512d) -> __m512d {
    // SAFETY: called only from functions with AVX-512 F and DQ.
    unsafe {
        let one = _mm512_set1_epi64(1);
        let mut t1 = _mm512_set1_pd(f64::INFINITY);
        for a in 0..3 {
            let moves = _mm512_cmp_pd_mask::<_CMP_NEQ_UQ>(ray.du[a], _mm512_setzero_pd());
            let ta = _mm512_mul_pd(
                _mm512_sub_pd(_mm512_cvtepi64_pd(cell[a]), ray.ou[a]),
                ray.inv[a],
            );
            let tb = _mm512_mul_pd(
                _mm512_sub_pd(
                    _mm512_cvtepi64_pd(_mm512_add_epi64(cell[a], one)),
                    ray.ou[a],
                ),
                ray.inv[a],
            );
            t1 = _mm512_mask_min_pd(t1, moves, t1, _mm512_max_pd(ta, tb));
        }
        min_as_scalar(t1, t_end)
    }
}

/// [`crate::classify::curvature::along`] per lane of `m`, from the bounds
/// at `slot`.
#[inline(always)]
unsafe fn along(s: &Space, slot: __m512i, m: __mmask8, du: &[__m512d; 3]) -> __m512d {
    // SAFETY: called only from functions with AVX-512 F and DQ; the lanes
    // of `m` hold slots of tagged cells, below the bounds' count.
    unsafe {
        let six = _mm512_mullo_epi64(slot, _mm512_set1_epi64(6));
        let h: [__m512d; 6] = std::array::from_fn(|k| {
            _mm512_cvtps_pd(_mm512_mask_i64gather_ps::<4>(
                _mm256_setzero_ps(),
                m,
                _mm512_add_epi64(six, _mm512_set1_epi64(k as i64)),
                s.bounds,
            ))
        });
        let a = du.map(|d| _mm512_abs_pd(d));
        let sq = |h: __m512d, x: __m512d, y: __m512d| _mm512_mul_pd(_mm512_mul_pd(h, x), y);
        let diag = _mm512_add_pd(
            _mm512_add_pd(sq(h[0], a[0], a[0]), sq(h[1], a[1], a[1])),
            sq(h[2], a[2], a[2]),
        );
        let off = _mm512_add_pd(
            _mm512_add_pd(sq(h[3], a[0], a[1]), sq(h[4], a[0], a[2])),
            sq(h[5], a[1], a[2]),
        );
        _mm512_add_pd(diag, _mm512_mul_pd(_mm512_set1_pd(2.0), off))
    }
}

impl Clearings {
    /// [`super::Clearing::clear`] per lane with bound `m` and end `t1`.
    #[inline(always)]
    unsafe fn clear(&self, s: &Space, m: __m512d, t1: __m512d) -> __mmask8 {
        // SAFETY: called only from functions with AVX-512 F.
        unsafe {
            let half_m = _mm512_mul_pd(_mm512_set1_pd(0.5), m);
            let q = |x: __m512d| {
                _mm512_sub_pd(
                    _mm512_sub_pd(_mm512_mul_pd(self.slope, x), self.f0),
                    _mm512_mul_pd(_mm512_mul_pd(half_m, x), x),
                )
            };
            _mm512_cmp_pd_mask::<_CMP_GT_OQ>(q(self.t0), s.margin)
                & _mm512_cmp_pd_mask::<_CMP_GT_OQ>(q(t1), s.margin)
        }
    }

    /// [`super::Clearing::look_ahead`] for the lanes of `m`.
    #[inline(always)]
    unsafe fn look_ahead(&mut self, s: &Space, m: __mmask8) {
        // SAFETY: called only from functions with the lane walk's features.
        unsafe {
            let within = _mm512_cmp_pd_mask::<_CMP_NGE_UQ>(self.t1, self.t_end)
                & _mm512_cmple_epi64_mask(self.n, _mm512_set1_epi64(MAX_CLEARED as i64));
            let go = m & within;
            let mut at = self.ray;
            at.cell = self.cell;
            at.t = self.t1;
            let (_, next) = exit_box(&at, self.cell, self.cell);
            let mut inside = go;
            for a in 0..3 {
                inside &= _mm512_cmplt_epu64_mask(next[a], s.n[a]);
            }
            let one = _mm512_set1_epi64(1);
            for a in 0..3 {
                let d = _mm512_abs_epi64(_mm512_sub_epi64(next[a], self.origin[a]));
                inside &= _mm512_cmple_epi64_mask(d, one);
            }
            self.has_next = (self.has_next & !m) | inside;
            for a in 0..3 {
                self.next[a] = _mm512_mask_mov_epi64(self.next[a], m, next[a]);
            }
        }
    }
}

/// Up to [`LANES`] checks started as [`super::ClearCheck::start`] starts
/// each: the clearings and the lanes still clear.
#[inline(always)]
unsafe fn start<T: Coefficient>(
    ctx: &Ctx<T>,
    s: &Space,
    group: &[ClearCheck],
    rays: &Rays,
) -> (Clearings, __mmask8) {
    // SAFETY: called only from `clear_cells`, which has the features; the
    // gathers read rays of `group` (indices below the rays' count) under the
    // mask of its lanes, and each array holds `LANES` values.
    unsafe {
        let valid = ((1u32 << group.len()) - 1) as __mmask8;
        let mut idx = [0i64; LANES];
        let mut slot = [0i64; LANES];
        let mut f0 = [0.0; LANES];
        let mut grad = [[0.0; LANES]; 3];
        let mut inside: __mmask8 = 0;
        for (l, ch) in group.iter().enumerate() {
            idx[l] = ch.i as i64;
            slot[l] = ch.slot as i64;
            f0[l] = ch.f0;
            for a in 0..3 {
                grad[a][l] = ch.grad[a];
            }
            inside |= (rays.inside[ch.i] as u8) << l;
        }
        let r = _mm512_loadu_epi64(idx.as_ptr());
        let zero = _mm512_setzero_pd();
        let ray = Lanes::gather(ctx, rays, r, valid);
        // `ClearCheck::start`: the slope along the new direction must have
        // the sign of the ray's medium (a sum from zero, whose sign of zero
        // no test below can see).
        let slope = _mm512_add_pd(
            _mm512_add_pd(
                _mm512_mul_pd(_mm512_loadu_pd(grad[0].as_ptr()), ray.du[0]),
                _mm512_mul_pd(_mm512_loadu_pd(grad[1].as_ptr()), ray.du[1]),
            ),
            _mm512_mul_pd(_mm512_loadu_pd(grad[2].as_ptr()), ray.du[2]),
        );
        let finite =
            _mm512_cmp_pd_mask::<_CMP_LT_OQ>(_mm512_abs_pd(slope), _mm512_set1_pd(f64::INFINITY));
        let nonzero = _mm512_cmp_pd_mask::<_CMP_NEQ_UQ>(slope, zero);
        let rising = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(slope, zero);
        let mut live = valid & finite & nonzero & !(rising ^ inside);
        let cell = ray.cell;
        let mut cl = Clearings {
            ray,
            cell,
            t1: span_end(&ray, &cell, ray.t_end),
            n: _mm512_set1_epi64(1),
            t0: ray.t,
            t_end: ray.t_end,
            slope: _mm512_abs_pd(slope),
            f0: _mm512_abs_pd(_mm512_loadu_pd(f0.as_ptr())),
            m: along(s, _mm512_loadu_epi64(slot.as_ptr()), valid, &ray.du),
            origin: cell,
            has_next: 0,
            next: cell,
        };
        live &= _mm512_cmp_pd_mask::<_CMP_LT_OQ>(cl.t0, cl.t1) & cl.clear(s, cl.m, cl.t1);
        cl.look_ahead(s, live);
        (cl, live)
    }
}

/// [`super::Clearing::extend`] for the `live` lanes of `cl`: those whose
/// next cell clears step into it; the others stop, and their rays step past
/// the cells they cleared. The lanes still clear.
#[inline(always)]
unsafe fn step(
    s: &Space,
    cl: &mut Clearings,
    live: __mmask8,
    rays: &mut Rays,
    c: &mut Counters,
) -> __mmask8 {
    // SAFETY: called only from `clear_cells`, which has the features; the
    // lanes of `live` hold started clearings.
    unsafe {
        // `Clearing::extend` for the lanes with a next cell.
        let ext = live & cl.has_next;
        let m = cl.m;
        let t1 = span_end(&cl.ray, &cl.next, cl.t_end);
        let ok = ext & cl.clear(s, m, t1);
        apply(cl, live & !ok, rays, c);
        for a in 0..3 {
            cl.cell[a] = _mm512_mask_mov_epi64(cl.cell[a], ok, cl.next[a]);
        }
        cl.t1 = _mm512_mask_mov_pd(cl.t1, ok, t1);
        cl.m = _mm512_mask_mov_pd(cl.m, ok, m);
        cl.n = _mm512_mask_add_epi64(cl.n, ok, cl.n, _mm512_set1_epi64(1));
        cl.look_ahead(s, ok);
        ok
    }
}

/// [`super::Clearing::apply`] for the lanes of `m`.
#[inline(always)]
unsafe fn apply(cl: &Clearings, m: __mmask8, rays: &mut Rays, c: &mut Counters) {
    if m == 0 {
        return;
    }
    // SAFETY: called only from functions with AVX-512 F; each array holds
    // `LANES` values.
    unsafe {
        let mut r = [0i64; LANES];
        let mut cell = [[0i64; LANES]; 3];
        let mut t1 = [0.0; LANES];
        let mut n = [0i64; LANES];
        _mm512_storeu_epi64(r.as_mut_ptr(), cl.ray.r);
        for a in 0..3 {
            _mm512_storeu_epi64(cell[a].as_mut_ptr(), cl.cell[a]);
        }
        _mm512_storeu_pd(t1.as_mut_ptr(), cl.t1);
        _mm512_storeu_epi64(n.as_mut_ptr(), cl.n);
        let mut bits = m;
        while bits != 0 {
            let l = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let i = r[l] as usize;
            rays.set_cell(i, [cell[0][l], cell[1][l], cell[2][l]]);
            rays.t[i] = t1[l];
            rays.advance[i] = true;
            c.cells_cleared += n[l] as u64;
        }
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use bumpalo::Bump;
    use glam::DVec3;

    use super::super::{ClearChecks, clear_cells as scalar_clear_cells};
    use super::*;
    use crate::classify::Method;
    use crate::phantom::{mix64, uniform};
    use crate::prepare::Prepared;
    use crate::render::testing::{scrambled_ball, small_scene};
    use crate::with_field;

    /// Checks of rays placed at random points in random directions (some
    /// along axes, some with signed zeros), a hair past their start, with
    /// slopes of either sign, small and large, and small `f - iso`: the
    /// lane clearing leaves every
    /// ray on the same cell and parameter bits, with the same `advance`, as
    /// the scalar clearing, and counts the same cleared cells.
    #[test]
    fn lanes_clear_as_the_scalar_clearing() {
        if !crate::simd::kernels_run("the AVX-512 walk", walk::available()) {
            return;
        }
        let sc = small_scene(40.0, &[]);
        for seed in 1..4u64 {
            let prep = Prepared::new(Arc::new(scrambled_ball(seed)), sc.surface.filter)
                .with_accel(sc.surface.iso, Method::Bezier(2));
            with_field!(&prep.field, f => {
                let ctx = Ctx::new(&sc, &prep, f.as_ref());
                let bounds = ctx.curvature.expect("bspline3 has curvature bounds");
                assert!(fits(bounds));
                let bump = Bump::new();
                let n = 4000;
                let mut rays = Rays::with_capacity_in(n, false, &bump);
                let u = |k: u64, j: u64| uniform(mix64(seed * 7919 + k), j);
                for k in 0..n as u64 {
                    let o = DVec3::new(u(k, 0), u(k, 1), u(k, 2)) * 23.0;
                    let mut d: [f64; 3] = std::array::from_fn(|a| 2.0 * u(k, 3 + a as u64) - 1.0);
                    if k.is_multiple_of(9) {
                        d[(k / 9 % 3) as usize] = if k.is_multiple_of(2) { 0.0 } else { -0.0 };
                    }
                    if k.is_multiple_of(23) {
                        d = [0.0; 3];
                        d[(k / 23 % 3) as usize] = 1.0;
                    }
                    rays.push((k as u32, k as u32), 1.0, true, o, DVec3::from_array(d).normalize());
                }
                rays.complete();
                let mut c = Counters::default();
                let mut all = Vec::new();
                for i in 0..n {
                    let k = i as u64;
                    super::super::super::place::<4, _>(&ctx, &mut rays, i, (1e-3, 1e-3), 5.0 + 30.0 * u(k, 6), &mut c);
                    rays.inside[i] = u(k, 7) < 0.5;
                    let Some(slot) = bounds.slot(rays.cell_of(i)) else { continue };
                    // Mostly slopes that clear, some of the wrong sign, some
                    // too small for the curvature.
                    let dir = rays.direction(i).to_array();
                    let sign = if rays.inside[i] == (u(k, 8) < 0.9) { 1.0 } else { -1.0 };
                    let scale = 4000.0 * u(k, 9) * u(k, 9);
                    let grad = std::array::from_fn(|a| sign * scale * dir[a] + 3.0 * (u(k, 10 + a as u64) - 0.5));
                    // `f - iso` a hair from the crossing, as refraction leaves it.
                    all.push(ClearCheck { i, slot, f0: 1e-3 * (2.0 * u(k, 13) - 1.0), grad });
                }
                assert!(all.len() > 1000, "{} checks", all.len());
                let settle = |lanes: bool| {
                    let mut r = rays.clone();
                    let mut c = Counters::default();
                    for batch in all.chunks(super::super::BATCH) {
                        let mut checks = ClearChecks::default();
                        for ch in batch {
                            checks.push(*ch);
                        }
                        scalar_clear_cells(&ctx, bounds, &mut checks, 1e-9, lanes, &mut r, &mut c);
                    }
                    (r, c.cells_cleared)
                };
                let (a, ca) = settle(false);
                let (b, cb) = settle(true);
                assert_eq!(ca, cb);
                let moved = all.iter().filter(|ch| a.advance[ch.i]).count();
                assert!(moved > 300 && moved < all.len() - 100, "{moved} of {}", all.len());
                assert!(ca as usize > moved + 200, "{ca} cells over {moved} rays: few chains");
                for ch in &all {
                    let i = ch.i;
                    let bits = |x: &Rays| (x.t[i].to_bits(), x.cell_of(i), x.advance[i]);
                    assert_eq!(bits(&a), bits(&b), "seed {seed} ray {i}");
                }
            });
        }
    }
}
