//! Cell classification by the Bézier hull: beyond the paper's ACCC.
//!
//! Inside a knot cell the field is one trivariate polynomial of degree `S-1`
//! per axis. Writing each weight polynomial in the Bernstein basis,
//! `W_i(t) = Σ_p β_ip B_p(t)`, gives the cell's tensor Bernstein coefficients
//! `b_pqr = Σ_ijk c_ijk β_ip β_jq β_kr` (a separable `S×S` transform per axis,
//! `3·S⁴` flops), and `f` over the cell lies in their convex hull. That bound
//! is much tighter than ACCC's (which bounds each weight separately), holds for
//! kernels with negative lobes, and tightens further by de Casteljau
//! subdivision. The 8 corner coefficients of any sub-cell are exact field
//! values, so the same recursion also *proves* crossings: two corners on
//! opposite sides of the iso-value.

use crate::filter::Field;
use crate::filter::coeffs::Coefficient;
use crate::filter::kernel::binomial;
use crate::lattice::{Lattice, cell_at};
use crate::simd::Isa;

use super::masks::{LinearMasks, SlabTags};
use super::{
    Tags, refine_cells, slack, support_minus_iso, support_minus_iso_into, support_minus_iso_lane,
};

/// What the recursion learned about a cell.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// The hull excludes the iso-value: provably no crossing.
    NoCrossing,
    /// Two evaluated points lie on opposite sides: provably a crossing.
    Proven,
    /// Undecided at the depth limit.
    Unknown,
}

/// `β[i][p]`: weight polynomial `i` in the Bernstein basis of degree `S-1`.
pub fn bernstein_weights<T: Coefficient>(field: &Field<T>) -> Vec<f64> {
    let kernel = field.kernel();
    let s = kernel.support();
    let d = s - 1;
    let mut beta = vec![0.0; s * s];
    for i in 0..s {
        let a = kernel.weight_poly(i);
        for p in 0..s {
            beta[i * s + p] = (0..=p)
                .map(|m| binomial(p, m) / binomial(d, m) * a[m])
                .sum();
        }
    }
    beta
}

/// Tensor Bernstein coefficients of `f - iso` over a cell: `β` applied
/// along x, y and z of the cell's coefficient neighbourhood.
pub fn cell_bernstein<T: Coefficient>(
    field: &Field<T>,
    cell: [i64; 3],
    iso: f64,
    beta: &[f64],
) -> Vec<f64> {
    let mut c = support_minus_iso(field, cell, iso);
    let mut x = vec![0.0; c.len()];
    crate::with_support!(field.kernel().support(), S => {
        bernstein_in_place::<S, 1>(&mut c, &mut x, &rows::<S>(beta))
    });
    c
}

/// `m[p][i] = β[i][p]`: row `p` of the map from coefficients to Bernstein.
fn rows<const S: usize>(beta: &[f64]) -> [[f64; S]; S] {
    std::array::from_fn(|p| std::array::from_fn(|i| beta[i * S + p]))
}

/// Coefficients `c` (`L` interleaved `S³` tensors: element `e` of tensor
/// `l` at `e·L + l`) to their tensor Bernstein forms, in place, through
/// scratch `x`. Each tensor gets the operations a single one (`L = 1`)
/// does, in the same order: a lane is one more position along the fastest
/// axis, so the passes' strides are `L` times the tensor's.
#[inline(always)]
fn bernstein_in_place<const S: usize, const L: usize>(
    c: &mut [f64],
    x: &mut [f64],
    m: &[[f64; S]; S],
) {
    let n = S * S * S * L;
    apply_axis::<S>(&c[..n], &mut x[..n], L, m);
    apply_axis::<S>(&x[..n], &mut c[..n], S * L, m);
    apply_axis::<S>(&c[..n], &mut x[..n], S * S * L, m);
    c[..n].copy_from_slice(&x[..n]);
}

/// de Casteljau split at 1/2 along `axis` (the sub-cell masks' halving, for
/// a patch of runtime support `s`).
fn split(b: &[f64], s: usize, axis: usize) -> (Vec<f64>, Vec<f64>) {
    let stride = [1, s, s * s][axis];
    let mut left = vec![0.0; b.len()];
    let mut right = vec![0.0; b.len()];
    crate::with_support!(s, S => halve_into::<S>(b, stride, &mut left, &mut right));
    (left, right)
}

/// Sub-cells per axis of a [`SubCells::mask`]: 4³ = 64, one bit each.
pub const SUB: usize = 4;

/// Which of a cell's `4³` sub-cells can hold the iso-surface, from the Bézier
/// hull of each sub-cell's own patch: a finer classification below the cell
/// lattice, one `u64` per tagged cell. Bit `i + 4(j + 4k)` covers local
/// coordinates `[i/4, (i+1)/4] × [j/4, (j+1)/4] × [k/4, (k+1)/4]`.
///
/// A ray segment through a tagged cell that meets no tagged sub-cell holds no
/// crossing, so the traversal skips it without a solve
/// ([`crate::render::stages::traverse::may_meet_tagged_sub_cell`]); otherwise
/// the whole segment is solved.
pub struct SubCells {
    s: usize,
    /// The filter's weights in the Bernstein basis ([`bernstein_weights`]).
    beta: Vec<f64>,
    /// Scratch tensors (reused between cells, never read before written).
    patch: Vec<f64>,
    halves: Vec<f64>,
    quarters: Vec<f64>,
    x: Vec<f64>,
    y: Vec<f64>,
}

/// Largest `S³` tensor (degree-7 B-spline).
const MAX_TENSOR: usize = 512;

impl SubCells {
    /// Scratch for the masks of `field`'s cells.
    pub fn new<T: Coefficient>(field: &Field<T>) -> SubCells {
        SubCells {
            beta: bernstein_weights(field),
            ..SubCells::for_support(field.kernel().support())
        }
    }

    /// Scratch for the masks of patches of support `s`, without the
    /// weights [`SubCells::cell_mask`] needs.
    fn for_support(s: usize) -> SubCells {
        SubCells {
            s,
            beta: Vec::new(),
            patch: vec![0.0; MAX_TENSOR],
            halves: vec![0.0; 8 * MAX_TENSOR],
            quarters: vec![0.0; 8 * MAX_TENSOR],
            x: vec![0.0; 2 * MAX_TENSOR],
            y: vec![0.0; 4 * MAX_TENSOR],
        }
    }

    /// Buffers for support `s` without a field, so that tests can hold the
    /// register form to [`SubCells::mask_scalar`] on arbitrary patches.
    #[cfg(test)]
    pub(super) fn scalar_for_support(s: usize) -> SubCells {
        SubCells::for_support(s)
    }

    /// The sub-cell mask of a cell with tensor Bernstein coefficients `b` of
    /// `f - iso` ([`cell_bernstein`]); `eps` is the rounding slack of
    /// [`decide`]. Two levels of de Casteljau halving (the same arithmetic as
    /// [`decide`]'s), pruned where a half-cell's hull already excludes the
    /// iso-value.
    pub fn mask(&mut self, b: &[f64], eps: f64) -> u64 {
        crate::with_support!(self.s, S => self.mask_s::<S>(b, eps))
    }

    /// The sub-cell mask of `cell` of `field` (the one [`SubCells::new`] was
    /// made for) for the iso-value `iso`: [`cell_bernstein`] and
    /// [`SubCells::mask`] without allocating.
    #[inline(always)]
    pub fn cell_mask<T: Coefficient>(
        &mut self,
        field: &Field<T>,
        cell: [i64; 3],
        iso: f64,
        eps: f64,
    ) -> u64 {
        crate::with_support!(self.s, S => {
            let mut patch = std::mem::take(&mut self.patch);
            support_minus_iso_into(field, cell, iso, &mut patch);
            bernstein_in_place::<S, 1>(&mut patch, &mut self.x, &rows::<S>(&self.beta));
            let mask = self.mask_s::<S>(&patch, eps);
            self.patch = patch;
            mask
        })
    }

    /// [`SubCells::mask`] for support `S`: a cubic patch in AVX-512
    /// registers when [`Isa::current`] is AVX-512 ([`super::cubic_mask`],
    /// the same masks), otherwise [`SubCells::mask_scalar`].
    ///
    /// [`Isa::current`]: crate::simd::Isa::current
    #[inline(always)]
    fn mask_s<const S: usize>(&mut self, b: &[f64], eps: f64) -> u64 {
        #[cfg(target_arch = "x86_64")]
        if S == 4 && crate::simd::Isa::current() == crate::simd::Isa::Avx512 {
            let patch = b.first_chunk::<64>().expect("a cubic patch has 64 values");
            // SAFETY: `Isa::Avx512` means the CPU has AVX-512 F.
            return unsafe { super::cubic_mask::mask(patch, eps) };
        }
        self.mask_scalar::<S>(b, eps)
    }

    /// Two levels of de Casteljau halving in memory, for any support.
    #[inline(always)]
    pub(super) fn mask_scalar<const S: usize>(&mut self, b: &[f64], eps: f64) -> u64 {
        let n = S * S * S;
        if !straddles(&b[..n], eps) {
            return 0;
        }
        let mut mask = 0u64;
        let (x, y) = (&mut self.x, &mut self.y);
        octants::<S>(b, x, y, &mut self.halves);
        for h in 0..8 {
            let half = &self.halves[h * n..(h + 1) * n];
            if !straddles(half, eps) {
                continue;
            }
            octants::<S>(half, x, y, &mut self.quarters);
            let (hx, hy, hz) = (h & 1, h >> 1 & 1, h >> 2);
            for q in 0..8 {
                if straddles(&self.quarters[q * n..(q + 1) * n], eps) {
                    let (i, j, k) = (2 * hx + (q & 1), 2 * hy + (q >> 1 & 1), 2 * hz + (q >> 2));
                    mask |= 1 << (i + SUB * (j + SUB * k));
                }
            }
        }
        mask
    }
}

/// Whether the hull of coefficients `v` reaches both sides of the iso-value
/// (within the slack `eps`): some `v > -eps` and some `v <= eps`, as
/// [`decide`] tests, from the extremes (lanes of 8, which vectorise; a NaN is
/// ignored either way).
#[inline(always)]
fn straddles(v: &[f64], eps: f64) -> bool {
    let (mut lo, mut hi) = lane_extremes::<8>(v);
    for (l, &x) in v.chunks_exact(8).remainder().iter().enumerate() {
        lo[l] = if x < lo[l] { x } else { lo[l] };
        hi[l] = if x > hi[l] { x } else { hi[l] };
    }
    lo.iter().any(|&x| x <= eps) && hi.iter().any(|&x| x > -eps)
}

/// The least and greatest of `v[l]`, `v[l + L]`, … for each `l < L`, over
/// `v`'s whole chunks of `L` (a NaN never replaces an extreme).
#[inline(always)]
fn lane_extremes<const L: usize>(v: &[f64]) -> ([f64; L], [f64; L]) {
    let (mut lo, mut hi) = ([f64::INFINITY; L], [f64::NEG_INFINITY; L]);
    for c in v.chunks_exact(L) {
        for l in 0..L {
            lo[l] = if c[l] < lo[l] { c[l] } else { lo[l] };
            hi[l] = if c[l] > hi[l] { c[l] } else { hi[l] };
        }
    }
    (lo, hi)
}

/// The 8 half-size children of an `S³` Bernstein patch into `out` (child
/// `x + 2y + 4z` at `out[child·S³..]`), through scratch `x` (2 tensors) and
/// `y` (4 tensors).
#[inline(always)]
fn octants<const S: usize>(b: &[f64], x: &mut [f64], y: &mut [f64], out: &mut [f64]) {
    let n = S * S * S;
    let (x0, x1) = x[..2 * n].split_at_mut(n);
    halve_into::<S>(&b[..n], 1, x0, x1);
    for (i, xi) in [&*x0, &*x1].into_iter().enumerate() {
        // y child index i + 2·(upper half in y)
        let (lo, hi) = y[..4 * n].split_at_mut(2 * n);
        halve_into::<S>(
            xi,
            S,
            &mut lo[i * n..(i + 1) * n],
            &mut hi[i * n..(i + 1) * n],
        );
    }
    let (lo, hi) = out[..8 * n].split_at_mut(4 * n);
    for i in 0..4 {
        halve_into::<S>(
            &y[i * n..(i + 1) * n],
            S * S,
            &mut lo[i * n..(i + 1) * n],
            &mut hi[i * n..(i + 1) * n],
        );
    }
}

/// The eight children of an `S³` patch as [`octants`] computes them, one
/// after another (for tests of the register form).
#[cfg(test)]
pub(super) fn octants_scalar<const S: usize>(b: &[f64]) -> Vec<f64> {
    let n = S * S * S;
    let (mut x, mut y, mut out) = (vec![0.0; 2 * n], vec![0.0; 4 * n], vec![0.0; 8 * n]);
    octants::<S>(b, &mut x, &mut y, &mut out);
    out
}

/// de Casteljau at 1/2 along the axis of `stride` (1, S or S²) of an `S³`
/// tensor: `left` covers `[0, 1/2]`, `right` `[1/2, 1]` on that axis.
///
/// Along y and z the `S` slices of a block are runs of `stride` contiguous
/// values, halved together (vector lanes); along x each line is one block.
#[inline(always)]
fn halve_into<const S: usize>(src: &[f64], stride: usize, left: &mut [f64], right: &mut [f64]) {
    let block = stride * S;
    let mut w = [0.0f64; MAX_TENSOR];
    for start in (0..S * S * S).step_by(block) {
        let w = &mut w[..block];
        w.copy_from_slice(&src[start..start + block]);
        let (l, r) = (
            &mut left[start..start + block],
            &mut right[start..start + block],
        );
        l[..stride].copy_from_slice(&w[..stride]);
        r[(S - 1) * stride..].copy_from_slice(&w[(S - 1) * stride..]);
        for round in 1..S {
            for i in 0..S - round {
                let (a, b) = w[i * stride..(i + 2) * stride].split_at_mut(stride);
                for (x, y) in a.iter_mut().zip(b.iter()) {
                    *x = 0.5 * (*x + *y);
                }
            }
            l[round * stride..(round + 1) * stride].copy_from_slice(&w[..stride]);
            let k = S - 1 - round;
            r[k * stride..(k + 1) * stride].copy_from_slice(&w[k * stride..(k + 1) * stride]);
        }
    }
}

/// `dst = m · src` along the axis of `stride` of a tensor whose extent
/// along it is `S` (the whole of `src`).
#[inline(always)]
fn apply_axis<const S: usize>(src: &[f64], dst: &mut [f64], stride: usize, m: &[[f64; S]; S]) {
    let outer = src.len() / (stride * S);
    for o in 0..outer {
        for inner in 0..stride {
            let base = o * stride * S + inner;
            let line: [f64; S] = std::array::from_fn(|q| src[base + q * stride]);
            for (r, row) in m.iter().enumerate() {
                let mut acc = 0.0;
                for q in 0..S {
                    acc += row[q] * line[q];
                }
                dst[base + r * stride] = acc;
            }
        }
    }
}

/// Decides a Bernstein patch, subdividing up to `depth` times.
pub fn decide(b: &[f64], s: usize, depth: u8, eps: f64) -> Verdict {
    if !straddles(b, eps) {
        return Verdict::NoCrossing;
    }
    let corner =
        |x: usize, y: usize, z: usize| b[x * (s - 1) + s * (y * (s - 1) + s * z * (s - 1))];
    let (mut pos, mut neg) = (false, false);
    for z in 0..2 {
        for y in 0..2 {
            for x in 0..2 {
                let v = corner(x, y, z);
                pos |= v > eps;
                neg |= v <= -eps;
            }
        }
    }
    if pos && neg {
        return Verdict::Proven;
    }
    if depth == 0 {
        return Verdict::Unknown;
    }
    let mut unknown = false;
    let (l, r) = split(b, s, 0);
    for half in [l, r] {
        let (l, r) = split(&half, s, 1);
        for quarter in [l, r] {
            let (l, r) = split(&quarter, s, 2);
            for child in [l, r] {
                match decide(&child, s, depth - 1, eps) {
                    Verdict::Proven => return Verdict::Proven,
                    Verdict::Unknown => unknown = true,
                    Verdict::NoCrossing => {}
                }
            }
        }
    }
    if unknown {
        Verdict::Unknown
    } else {
        Verdict::NoCrossing
    }
}

/// The masks of candidate `cells` (linear indices, ascending) as
/// [`SubCells::cell_mask`] computes them, with the Bernstein transforms of
/// `L` cells at a time in vector lanes (each with the operations of one);
/// `keep(i, mask)` receives each cell with a non-empty mask, in order. The
/// halving behind a mask stays one cell at a time: only about a third of
/// BMCC's candidates reach it, each with its own pruning. (All of it in
/// lanes, the halving's union of the lanes' halves was slower than the
/// cells' own pruning: sphere 64³, 25 → 31 ms single thread.)
///
/// The whole cells' hulls are tested in the lanes too, so only the cells
/// whose hull straddles the iso-value are copied out of them for their
/// masks; for cubics each lane's coefficient rows are read as vectors and
/// transposed into the lanes ([`crate::simd::gather_rows4`], the same
/// values as one at a time).
#[inline(always)]
fn refine_in_lanes<const S: usize, const L: usize, T: Coefficient>(
    field: &Field<T>,
    lattice: &Lattice,
    iso: f64,
    eps: f64,
    sub: &mut SubCells,
    cells: impl Iterator<Item = usize>,
    keep: &mut impl FnMut(usize, u64),
) {
    let m = rows::<S>(&sub.beta);
    let n = S * S * S;
    let mut group = [0usize; L];
    let mut corners = [[0i64; 3]; L];
    let (mut lanes, mut scratch) = (vec![0.0; n * L], vec![0.0; n * L]);
    let mut patch = vec![0.0; n];
    let mut cells = cells.peekable();
    while cells.peek().is_some() {
        let mut len = 0;
        for (slot, i) in group.iter_mut().zip(&mut cells) {
            *slot = i;
            corners[len] = cell_at(lattice.cells, i);
            len += 1;
        }
        supports_into_lanes::<S, L, T>(field, &corners[..len], iso, &mut lanes);
        bernstein_in_place::<S, L>(&mut lanes, &mut scratch, &m);
        let hulls = straddles_lanes::<L>(&lanes[..n * L], eps);
        for (l, &i) in group[..len].iter().enumerate() {
            if !hulls[l] {
                continue;
            }
            for (p, v) in patch.iter_mut().zip(lanes.chunks_exact(L)) {
                *p = v[l];
            }
            let mask = sub.mask_s::<S>(&patch, eps);
            if mask != 0 {
                keep(i, mask);
            }
        }
    }
}

/// Calls `each(k, patch)` with the tensor Bernstein coefficients of
/// `f - iso` over `cells[k]`, for every `k` in order: the patches of eight
/// cells at a time in the lanes of the running instruction set, as
/// [`refine_in_lanes`] builds them (the same values as [`cell_bernstein`]).
pub(crate) fn each_patch<T: Coefficient>(
    field: &Field<T>,
    cells: &[[i64; 3]],
    iso: f64,
    beta: &[f64],
    mut each: impl FnMut(usize, &[f64]),
) {
    crate::with_support!(field.kernel().support(), S => crate::with_isa!(Isa::current(), L, _M => {
        patches_in_lanes::<S, L, T>(field, cells, iso, beta, &mut each)
    }))
}

#[inline(always)]
fn patches_in_lanes<const S: usize, const L: usize, T: Coefficient>(
    field: &Field<T>,
    cells: &[[i64; 3]],
    iso: f64,
    beta: &[f64],
    each: &mut impl FnMut(usize, &[f64]),
) {
    let m = rows::<S>(beta);
    let n = S * S * S;
    let (mut lanes, mut scratch) = (vec![0.0; n * L], vec![0.0; n * L]);
    let mut patch = vec![0.0; n];
    for (g, group) in cells.chunks(L).enumerate() {
        supports_into_lanes::<S, L, T>(field, group, iso, &mut lanes);
        bernstein_in_place::<S, L>(&mut lanes, &mut scratch, &m);
        for l in 0..group.len() {
            for (p, v) in patch.iter_mut().zip(lanes.chunks_exact(L)) {
                *p = v[l];
            }
            each(g * L + l, &patch);
        }
    }
}

/// `c - iso` over the supports of `group` (at most `L` cells) into `L`
/// interleaved tensors (element `e` of lane `l` at `e·L + l`). Cubic rows
/// are read as one vector per lane and transposed in registers; lanes past
/// the group's end repeat its last cell (cubic) or keep earlier values
/// (others), never read.
#[inline(always)]
fn supports_into_lanes<const S: usize, const L: usize, T: Coefficient>(
    field: &Field<T>,
    group: &[[i64; 3]],
    iso: f64,
    lanes: &mut [f64],
) {
    if S == 4 {
        let base: [usize; L] =
            std::array::from_fn(|l| field.support_offset(group[l.min(group.len() - 1)]));
        let (data, sy, sz) = field.lane_rows::<S, L>(&base);
        for k in 0..S {
            for j in 0..S {
                // SAFETY: every row of every lane lies inside `data`
                // (checked by `lane_rows`), and `L` is the lane count
                // `with_isa!` chose for this CPU.
                let r = unsafe { crate::simd::gather_rows4::<T, L>(data, &base, j * sy + k * sz) };
                for (i, row) in r.iter().enumerate() {
                    let e = i + S * (j + S * k);
                    for (v, c) in lanes[e * L..(e + 1) * L].iter_mut().zip(row) {
                        *v = c - iso;
                    }
                }
            }
        }
    } else {
        for (l, &cell) in group.iter().enumerate() {
            support_minus_iso_lane::<S, L, T>(field, cell, iso, l, lanes);
        }
    }
}

/// [`straddles`] of each of `L` interleaved tensors (element `e` of lane
/// `l` at `e·L + l`), lane by lane the same test.
#[inline(always)]
fn straddles_lanes<const L: usize>(v: &[f64], eps: f64) -> [bool; L] {
    let (lo, hi) = lane_extremes::<L>(v);
    std::array::from_fn(|l| lo[l] <= eps && hi[l] > -eps)
}

/// Re-decides the cells `coarse` tagged by their Bézier hulls. With
/// `proven_only`, keeps only cells with a proven crossing (the lower bound of
/// the truth); otherwise keeps every cell not proven empty (conservative).
pub fn refine<T: Coefficient>(
    field: &Field<T>,
    lattice: &Lattice,
    iso: f64,
    coarse: &Tags,
    depth: u8,
    proven_only: bool,
) -> Tags {
    let beta = bernstein_weights(field);
    let s = field.kernel().support();
    let eps = slack(field);
    refine_cells(lattice, coarse, |cell| {
        let b = cell_bernstein(field, cell, iso, &beta);
        match decide(&b, s, depth, eps) {
            Verdict::Proven => true,
            Verdict::Unknown => !proven_only,
            Verdict::NoCrossing => false,
        }
    })
}

/// The Bézier classification at depth 2 ([`refine`] with
/// `Method::Bezier(2)`) together with every kept cell's sub-cell mask, by
/// linear cell index (x fastest, ascending).
///
/// Depth 2 halves each cell twice per axis, as the masks do, and with the
/// same arithmetic: a cell is kept exactly when its mask is not empty. (A
/// crossing [`decide`] proves from a patch's corners lies in a sub-cell whose
/// hull straddles the iso-value: corners survive halving unchanged,
/// neighbouring sub-cells share their face coefficients bit for bit, and a
/// child's hull lies in its parent's.) So one pass gives both, where the
/// classification followed by [`crate::classify::SubCellMasks::build`]
/// expanded and halved every tagged cell twice. Without `keep_masks` only the
/// tags are returned.
pub fn refine_with_masks<T: Coefficient>(
    field: &Field<T>,
    lattice: &Lattice,
    iso: f64,
    coarse: &Tags,
    keep_masks: bool,
) -> (Tags, LinearMasks) {
    refine_with_masks_on(Isa::current(), field, lattice, iso, coarse, keep_masks)
}

/// [`refine_with_masks`] with the Bernstein transforms in the lanes of `isa`
/// (the same tags and masks for every instruction set).
fn refine_with_masks_on<T: Coefficient>(
    isa: Isa,
    field: &Field<T>,
    lattice: &Lattice,
    iso: f64,
    coarse: &Tags,
    keep_masks: bool,
) -> (Tags, LinearMasks) {
    use rayon::prelude::*;
    let eps = slack(field);
    let [nx, ny, nz] = lattice.cells;
    let slab = nx * ny;
    let slabs: Vec<(SlabTags, LinearMasks)> = (0..nz)
        .into_par_iter()
        .map_init(
            || SubCells::new(field),
            |sub, z| {
                let mut flags = SlabTags::new(nx, ny);
                let mut masks = Vec::new();
                let first = z * slab;
                let mut keep = |i: usize, mask: u64| {
                    flags.set(i - first);
                    if keep_masks {
                        masks.push((i, mask));
                    }
                };
                let cells = coarse.ones(first..first + slab);
                crate::with_support!(sub.s, S => crate::with_isa!(isa, L, _M => {
                    refine_in_lanes::<S, L, T>(field, lattice, iso, eps, sub, cells, &mut keep)
                }));
                (flags, masks)
            },
        )
        .collect();
    super::masks::join_slabs(lattice.cells, slabs)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::FilterKind;
    use crate::volume::{SampleType, Volume};
    use glam::DVec3;

    #[test]
    fn patches_in_lanes_are_the_cells_patches() {
        // Bit for bit, for every filter's support, over a group count that
        // leaves a short last group.
        let dims = [9usize, 8, 10];
        let vol = crate::volume::scrambled_u8(dims, 9);
        for name in [
            "linear",
            "catmull-rom",
            "bspline2",
            "bspline3",
            "bspline5",
            "bspline7",
        ] {
            let f = Field::new(&vol, FilterKind::parse(name, 0.0).unwrap());
            let lat = Lattice::new(f.kernel(), dims);
            let beta = bernstein_weights(&f);
            let mut cells: Vec<[i64; 3]> = (0..lat.cell_count())
                .step_by(7)
                .map(|i| cell_at(lat.cells, i))
                .collect();
            if cells.len().is_multiple_of(8) {
                cells.pop();
            }
            let mut seen = 0;
            each_patch(&f, &cells, 101.5, &beta, |k, patch| {
                let want = cell_bernstein(&f, cells[k], 101.5, &beta);
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(patch), bits(&want), "{name} {:?}", cells[k]);
                assert_eq!(k, seen);
                seen += 1;
            });
            assert_eq!(seen, cells.len());
        }
    }

    #[test]
    fn sub_cell_masks_hold_every_sign_change() {
        // Every pair of nearby points on opposite sides of the iso-value must
        // lie in sub-cells the mask keeps (the segment between them crosses).
        let dims = [8usize, 7, 9];
        let vol = crate::volume::scrambled_u8(dims, 5);
        for name in ["linear", "catmull-rom", "bspline2", "bspline3", "bspline5"] {
            let f = Field::new(&vol, FilterKind::parse(name, 0.0).unwrap());
            let lat = Lattice::new(f.kernel(), dims);
            let beta = bernstein_weights(&f);
            let mut sub = SubCells::new(&f);
            let iso = f.separating_iso(125.0);
            let origin_of = |c: [i64; 3]| c.map(|c| c as f64 - lat.offset);
            let (mut kept, mut total, mut sign_changes) = (0, 0, 0);
            for cell in [[2i64, 2, 2], [3, 1, 4], [1, 3, 3], [4, 2, 5]] {
                let b = cell_bernstein(&f, cell, iso, &beta);
                let mask = sub.mask(&b, 1e-9);
                kept += mask.count_ones();
                total += 64;
                let o = origin_of(cell);
                // 16 points per cell axis, 4³ per sub-cell: a sign change
                // between two neighbours inside one sub-cell needs that
                // sub-cell tagged.
                let m = 4 * SUB;
                let val = |i: usize, j: usize, k: usize| {
                    f.value(DVec3::new(
                        o[0] + i as f64 / m as f64,
                        o[1] + j as f64 / m as f64,
                        o[2] + k as f64 / m as f64,
                    )) - iso
                };
                for k in 0..m {
                    for j in 0..m {
                        for i in 0..m {
                            let a = val(i, j, k);
                            let bit = i / 4 + SUB * (j / 4 + SUB * (k / 4));
                            for (di, dj, dk) in [(1, 0, 0), (0, 1, 0), (0, 0, 1)] {
                                let (ni, nj, nk) = (i + di, j + dj, k + dk);
                                if ni / 4 != i / 4 || nj / 4 != j / 4 || nk / 4 != k / 4 {
                                    continue;
                                }
                                if (a > 0.0) != (val(ni, nj, nk) > 0.0) {
                                    sign_changes += 1;
                                    assert!(mask >> bit & 1 == 1, "{name} {cell:?} sub-cell {bit}");
                                }
                            }
                        }
                    }
                }
            }
            assert!(sign_changes > 0, "{name}: the test must see crossings");
            assert!(kept < total, "{name}: the mask must exclude something");
        }
    }

    #[test]
    fn one_pass_gives_the_depth_two_tags_and_their_masks() {
        // Noise with a smooth trend: cells proven at the root, at a half,
        // at a quarter, undecided and empty all occur.
        let dims = [12usize, 10, 11];
        let s: Vec<f32> = (0..dims.iter().product::<usize>())
            .map(|i| ((i * 7919 + 3) % 97) as f32 + (i % dims[0]) as f32 * 9.0)
            .collect();
        let vol = Volume::new(dims, [1.0; 3], SampleType::U8, s).unwrap();
        let mut pruned = false;
        for name in ["linear", "catmull-rom", "bspline2", "bspline3", "bspline5"] {
            let f = Field::new(&vol, FilterKind::parse(name, 0.0).unwrap());
            let lat = Lattice::new(f.kernel(), dims);
            let iso = f.separating_iso(100.0);
            let coarse = crate::classify::prefilter_candidates(&f, &lat, iso);
            let want = refine(&f, &lat, iso, &coarse, 2, false);
            assert!(want.count() > 0, "{name}");
            // Linear's hull is its corners: only higher orders prune.
            pruned |= want.count() < coarse.count();
            let beta = bernstein_weights(&f);
            let mut sub = SubCells::new(&f);
            for isa in Isa::available() {
                let (tags, masks) = refine_with_masks_on(isa, &f, &lat, iso, &coarse, true);
                assert!(
                    tags.is_subset_of(&want) && want.is_subset_of(&tags),
                    "{name} {isa:?}"
                );
                assert_eq!(masks.len(), tags.count(), "{name} {isa:?}");
                for &(i, mask) in &masks {
                    let c = cell_at(lat.cells, i);
                    assert!(tags.get(c), "{name} {c:?}");
                    let b = cell_bernstein(&f, c, iso, &beta);
                    // The scalar halving, whatever form the masks took.
                    let eps = slack(&f);
                    let want = crate::with_support!(f.kernel().support(), S => sub.mask_scalar::<S>(&b, eps));
                    assert_eq!(mask, want, "{name} {c:?} {isa:?}");
                }
            }
            let (_, none) = refine_with_masks(&f, &lat, iso, &coarse, false);
            assert!(none.is_empty());
        }
        assert!(pruned, "the hull must drop some candidates");
    }

    #[test]
    fn bernstein_corners_are_field_values_and_hull_bounds() {
        let dims = [7usize, 6, 8];
        let vol = crate::volume::scrambled_u8(dims, 0);
        for name in ["linear", "catmull-rom", "bspline2", "bspline3", "bspline6"] {
            let f = Field::new(&vol, FilterKind::parse(name, 0.0).unwrap());
            let lat = Lattice::new(f.kernel(), dims);
            let beta = bernstein_weights(&f);
            let sup = f.kernel().support();
            let cell = [2i64, 2, 3];
            let b = cell_bernstein(&f, cell, 0.0, &beta);
            let lo = b.iter().cloned().fold(f64::INFINITY, f64::min);
            let hi = b.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
            let origin = cell.map(|c| c as f64 - lat.offset);
            for q in 0..64 {
                let t = [
                    (q % 4) as f64 / 3.0,
                    (q / 4 % 4) as f64 / 3.0,
                    (q / 16) as f64 / 3.0,
                ];
                let v = f.value(DVec3::new(
                    origin[0] + t[0],
                    origin[1] + t[1],
                    origin[2] + t[2],
                ));
                assert!(
                    v >= lo - 1e-9 && v <= hi + 1e-9,
                    "{name}: {v} outside [{lo}, {hi}]"
                );
            }
            let corner = b[0];
            let v0 = f.value(DVec3::from_array(origin));
            assert!(
                (corner - v0).abs() < 1e-9,
                "{name}: corner {corner} vs {v0}"
            );
            let last = b[sup * sup * sup - 1];
            let v1 = f.value(DVec3::from_array(origin.map(|x| x + 1.0)));
            assert!((last - v1).abs() < 1e-9, "{name}: corner {last} vs {v1}");
        }
    }
}
