//! Second-derivative bounds of the field around each tagged cell, so the
//! refraction stage can prove that a ray leaving a crossing meets no other
//! crossing in the rest of its cell (and the neighbouring cells after it),
//! and skip their solves.
//!
//! Right after a crossing the new piece starts a hair past the root, inside
//! a cell that holds the surface; its segment was then solved again and
//! (nearly always) found nothing: on the glass sphere that was 234k of the
//! frame's 606k solves. A Taylor bound settles it from numbers the
//! refraction already has: with `f(0) - iso = f0` at the crossing, the slope
//! `g1 = ∇f·d` along the new direction and `|f''| ≤ M` on the path,
//!
//! ```text
//! |f(s) - iso| ≥ |g1| s − |f0| − M s²/2,
//! ```
//!
//! a concave quadratic, so when it is positive at both ends of the rest of
//! the cell the segment holds no root. `M` bounds the cell's 3³
//! neighbourhood, tagged or not ([`neighbourhood_bound`]), so the path goes
//! on through the next cells while they are the crossing cell's neighbours,
//! with no other bound to look up.
//!
//! For a B-spline of degree `n ≥ 2` (non-negative weights summing to one) the
//! second derivatives on a cell are B-splines of lower degree over the
//! coefficients' differences (`∂xx` over `Δx² c`, `∂xy` over `ΔxΔy c`), so each
//! is bounded by the largest difference over the cell's support, and
//! `|dᵀ H d| ≤ Σ_ab |d_a| |d_b| h_ab`. Other filters get no bounds: trilinear
//! has kinks across faces and Catmull-Rom negative weights.
//!
//! Kept per tagged cell (24 bytes) rather than computed when needed:
//! computed from the coefficients at each cell a clearance passes, the
//! sphere's refract stage took 211 ms instead of 47 (single thread).

use std::sync::Arc;

use super::tagged::TaggedIndex;
use crate::filter::Field;
use crate::filter::coeffs::Coefficient;
use crate::filter::kernel::Kernel;

/// Bounds on `|∂xx|, |∂yy|, |∂zz|, |∂xy|, |∂xz|, |∂yz|` of the field over a cell
/// (grid units), rounded up to `f32`.
pub type HessianBound = [f32; 6];

/// Whether the field of `kernel` gets curvature bounds (see the module doc).
pub fn applies(kernel: &Kernel) -> bool {
    kernel.is_nonnegative() && kernel.degree() >= 2
}

/// Curvature bounds of the tagged cells of one classification.
#[derive(Clone, Debug)]
pub struct CurvatureBounds {
    index: Arc<TaggedIndex>,
    bounds: Vec<HessianBound>,
}

impl CurvatureBounds {
    /// Bytes the bounds of `count` tagged cells take.
    pub fn bytes_for(count: usize) -> usize {
        count * size_of::<HessianBound>()
    }

    /// The [`neighbourhood_bound`] of every tagged cell of `index`; `None` when the filter has
    /// none ([`applies`]). A bound beyond `f32` is infinite, and one from
    /// non-finite coefficients NaN: either clears nothing.
    pub fn build<T: Coefficient>(field: &Field<T>, index: Arc<TaggedIndex>) -> Option<Self> {
        if !applies(field.kernel()) {
            return None;
        }
        let cells = crate::lattice::Lattice::new(field.kernel(), field.dims()).cells;
        let bounds = index.table(|cell| neighbourhood_bound(field, cell, cells).map(round_up));
        Some(CurvatureBounds { index, bounds })
    }

    /// Bounds [`CurvatureBounds::build`] made before (the disk cache's), in
    /// `index`'s slot order; `None` unless there is one per tagged cell.
    pub fn from_parts(index: Arc<TaggedIndex>, bounds: Vec<HessianBound>) -> Option<Self> {
        (bounds.len() == index.count()).then_some(CurvatureBounds { index, bounds })
    }

    /// Where cell `c`'s (in range) bound is; `None` when the cell is not
    /// tagged. A lookup in two ([`CurvatureBounds::at`]), so callers can
    /// prefetch the bound before they read it.
    #[inline(always)]
    pub fn slot(&self, c: [i64; 3]) -> Option<usize> {
        self.index.slot(c)
    }

    #[inline(always)]
    pub fn at(&self, slot: usize) -> &HessianBound {
        &self.bounds[slot]
    }

    /// The tagged-cell index and the bounds in its slot order, for lane
    /// code that gathers them.
    pub fn parts(&self) -> (&TaggedIndex, &[HessianBound]) {
        (&self.index, &self.bounds)
    }
}

/// `|dᵀ H d|` bounded over a cell from its [`HessianBound`], for any `d`.
#[inline(always)]
pub fn along(h: &HessianBound, d: [f64; 3]) -> f64 {
    let a = d.map(f64::abs);
    h[0] as f64 * a[0] * a[0]
        + h[1] as f64 * a[1] * a[1]
        + h[2] as f64 * a[2] * a[2]
        + 2.0 * (h[3] as f64 * a[0] * a[1] + h[4] as f64 * a[0] * a[2] + h[5] as f64 * a[1] * a[2])
}

/// The smallest `f32` not below `x` (for `x ≥ 0`).
fn round_up(x: f64) -> f32 {
    let f = x as f32;
    if (f as f64) < x { f.next_up() } else { f }
}

/// The largest second difference (along one axis, `∂aa`) or mixed second
/// difference (one step along each of two axes, `∂ab`) of the coefficients in
/// `cell`'s support, per [`HessianBound`] entry (in `f64`, not yet rounded
/// up).
///
/// Compiled for the running instruction set (the differences and maxima of
/// a support's rows fill vector lanes); exact, so the same on every one.
pub fn hessian_bound<T: Coefficient>(field: &Field<T>, cell: [i64; 3]) -> [f64; 6] {
    crate::with_isa!(crate::simd::Isa::current(), _L, _M => {
        crate::with_support!(field.kernel().support(), S => cube_bound::<S, T>(field, cell))
    })
}

/// [`hessian_bound`] over the cells next to `cell` too (its 3³
/// neighbourhood within a lattice of `cells`): the bound a clearance uses on
/// any path from the crossing cell that stays among its neighbours.
///
/// The neighbours' supports together are a cube of `S + 2` coefficients a
/// side, and every difference of one neighbour's support is a difference
/// of that cube and back, so the cube's bound is the largest of the 27
/// cells' bounds (bit for bit: the same differences). At the lattice's
/// faces the cube shifts inward and takes in a cell beyond the
/// neighbourhood, which only loosens the bound; a lattice fewer than three
/// cells across takes the cells' bounds one by one.
pub fn neighbourhood_bound<T: Coefficient>(
    field: &Field<T>,
    cell: [i64; 3],
    cells: [usize; 3],
) -> [f64; 6] {
    if cells.iter().any(|&n| n < 3) {
        return neighbours_one_by_one(field, cell, cells);
    }
    let corner = std::array::from_fn(|a| (cell[a] - 1).clamp(0, cells[a] as i64 - 3));
    macro_rules! cube {
        ($($s:literal => $w:literal),*) => {
            match field.kernel().support() {
                $($s => crate::with_isa!(crate::simd::Isa::current(), _L, _M => {
                    cube_bound::<$w, T>(field, corner)
                }),)*
                _ => neighbours_one_by_one(field, cell, cells),
            }
        };
    }
    cube!(3 => 5, 4 => 6, 5 => 7, 6 => 8, 7 => 9, 8 => 10)
}

/// [`support_bound`] of the cube of `W` coefficients a side from the first
/// one of `corner`'s support: the support itself for `W = S` ([`hessian_bound`]),
/// the supports of the 3³ cells from `corner` for `W = S + 2`
/// ([`neighbourhood_bound`]). Fixed loop bounds: the builds run once per
/// tagged cell, 380k of them on the teapot.
#[inline(always)]
fn cube_bound<const W: usize, T: Coefficient>(field: &Field<T>, corner: [i64; 3]) -> [f64; 6] {
    let coeffs = field.coeffs();
    let (sy, sz) = (coeffs.stride(1), coeffs.stride(2));
    let base = field.support_offset(corner);
    let data = coeffs.data();
    let mut c = [[[0.0f64; W]; W]; W];
    for (k, plane) in c.iter_mut().enumerate() {
        for (j, row) in plane.iter_mut().enumerate() {
            let src = &data[base + j * sy + k * sz..][..W];
            for (x, v) in row.iter_mut().zip(src) {
                *x = v.to_f64();
            }
        }
    }
    support_bound::<W>(&c)
}

/// [`neighbourhood_bound`] as the largest of the in-range neighbours'
/// [`hessian_bound`]s (a NaN kept).
fn neighbours_one_by_one<T: Coefficient>(
    field: &Field<T>,
    cell: [i64; 3],
    cells: [usize; 3],
) -> [f64; 6] {
    let mut m = [0.0f64; 6];
    for dz in -1..=1i64 {
        for dy in -1..=1i64 {
            for dx in -1..=1i64 {
                let c = [cell[0] + dx, cell[1] + dy, cell[2] + dz];
                if (0..3).any(|a| c[a] < 0 || c[a] >= cells[a] as i64) {
                    continue;
                }
                for (acc, h) in m.iter_mut().zip(hessian_bound(field, c)) {
                    if !acc.is_nan() && (h > *acc || h.is_nan()) {
                        *acc = h;
                    }
                }
            }
        }
    }
    m
}

/// [`hessian_bound`] of the support `c[z][y][x]`.
#[inline(always)]
fn support_bound<const S: usize>(c: &[[[f64; S]; S]; S]) -> [f64; 6] {
    // Each entry's largest |difference|, per position along x (lanes,
    // which vectorise), then across them. `f64::max` would drop a NaN
    // (coefficients overflowed to infinity): `keep` holds on to it, so the
    // bound clears nothing; the result is the same whatever the order.
    #[inline(always)]
    fn keep(acc: &mut f64, d: f64) {
        let d = d.abs();
        *acc = if (d > *acc) | d.is_nan() { d } else { *acc };
    }
    let mut lanes = [[0.0f64; S]; 6];
    // One loop nest per entry, over the positions where its difference
    // exists (fixed bounds, no tests inside).
    for plane in c {
        for r in plane {
            for x in 0..S - 2 {
                keep(&mut lanes[0][x], r[x] - 2.0 * r[x + 1] + r[x + 2]);
            }
        }
        for y in 0..S - 2 {
            for x in 0..S {
                keep(
                    &mut lanes[1][x],
                    plane[y][x] - 2.0 * plane[y + 1][x] + plane[y + 2][x],
                );
            }
        }
        for y in 0..S - 1 {
            let (r, u) = (&plane[y], &plane[y + 1]);
            for x in 0..S - 1 {
                keep(&mut lanes[3][x], u[x + 1] - r[x + 1] - u[x] + r[x]);
            }
        }
    }
    for z in 0..S - 2 {
        for y in 0..S {
            for x in 0..S {
                keep(
                    &mut lanes[2][x],
                    c[z][y][x] - 2.0 * c[z + 1][y][x] + c[z + 2][y][x],
                );
            }
        }
    }
    for z in 0..S - 1 {
        for y in 0..S {
            let (r, b) = (&c[z][y], &c[z + 1][y]);
            for x in 0..S - 1 {
                keep(&mut lanes[4][x], b[x + 1] - r[x + 1] - b[x] + r[x]);
            }
        }
        for y in 0..S - 1 {
            let (r, u, b, bu) = (&c[z][y], &c[z][y + 1], &c[z + 1][y], &c[z + 1][y + 1]);
            for x in 0..S {
                keep(&mut lanes[5][x], bu[x] - u[x] - b[x] + r[x]);
            }
        }
    }
    let mut h = [0.0f64; 6];
    for (he, lane) in h.iter_mut().zip(&lanes) {
        for &d in lane {
            keep(he, d);
        }
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classify::{Method, classify};
    use crate::filter::FilterKind;
    use crate::filter::restrict::knot_cell;
    use crate::lattice::Lattice;
    use crate::phantom;
    use crate::volume::{SampleType, Volume};
    use crate::with_support;

    /// The differences one position at a time, as the bound was first
    /// written: the largest |difference| per entry, a NaN kept.
    fn hessian_bound_one_by_one(c: &[f64], s: usize) -> [f64; 6] {
        let at = |x: usize, y: usize, z: usize| c[x + s * (y + s * z)];
        let mut h = [0.0f64; 6];
        let mut keep = |e: usize, d: f64| {
            let d = d.abs();
            if d > h[e] || d.is_nan() {
                h[e] = d
            }
        };
        for z in 0..s {
            for y in 0..s {
                for x in 0..s {
                    let v = at(x, y, z);
                    if x + 2 < s {
                        keep(0, v - 2.0 * at(x + 1, y, z) + at(x + 2, y, z));
                    }
                    if y + 2 < s {
                        keep(1, v - 2.0 * at(x, y + 1, z) + at(x, y + 2, z));
                    }
                    if z + 2 < s {
                        keep(2, v - 2.0 * at(x, y, z + 1) + at(x, y, z + 2));
                    }
                    if x + 1 < s && y + 1 < s {
                        keep(
                            3,
                            at(x + 1, y + 1, z) - at(x + 1, y, z) - at(x, y + 1, z) + v,
                        );
                    }
                    if x + 1 < s && z + 1 < s {
                        keep(
                            4,
                            at(x + 1, y, z + 1) - at(x + 1, y, z) - at(x, y, z + 1) + v,
                        );
                    }
                    if y + 1 < s && z + 1 < s {
                        keep(
                            5,
                            at(x, y + 1, z + 1) - at(x, y + 1, z) - at(x, y, z + 1) + v,
                        );
                    }
                }
            }
        }
        h
    }

    #[test]
    fn lane_differences_give_the_one_by_one_bound() {
        // Bit for bit on every cell of a scrambled volume, and a NaN (from
        // an infinite coefficient) kept wherever one occurs.
        let dims = [9usize, 8, 10];
        let vol = crate::volume::scrambled_u8(dims, 11);
        for name in ["bspline2", "bspline3", "bspline5", "bspline7", "linear"] {
            let f = Field::new(&vol, FilterKind::parse(name, 0.0).unwrap());
            let lat = Lattice::new(f.kernel(), dims);
            let s = f.kernel().support();
            for i in 0..lat.cell_count() {
                let cell = crate::lattice::cell_at(lat.cells, i);
                let support = crate::classify::support_minus_iso(&f, cell, 0.0);
                let want = hessian_bound_one_by_one(&support, s);
                let got = hessian_bound(&f, cell);
                assert_eq!(
                    got.map(f64::to_bits),
                    want.map(f64::to_bits),
                    "{name} {cell:?}"
                );
            }
        }
        // Infinities make NaN differences (inf - 2·inf) in some entries.
        for at in [[0usize, 1], [21, 22], [40, 56], [5, 21], [63, 62]] {
            let mut c = [[[0.0f64; 4]; 4]; 4];
            let mut flat = vec![0.0; 64];
            for (i, v) in flat.iter_mut().enumerate() {
                *v = (i * 37 % 11) as f64;
                if at.contains(&i) {
                    *v = f64::INFINITY;
                }
                c[i / 16][i / 4 % 4][i % 4] = *v;
            }
            let want = hessian_bound_one_by_one(&flat, 4);
            assert!(want.iter().any(|v| v.is_nan()), "{at:?}: a NaN to keep");
            let got = support_bound::<4>(&c);
            assert_eq!(got.map(f64::to_bits), want.map(f64::to_bits), "{at:?}");
        }
    }

    /// [`neighbourhood_bound`] is bit for bit the largest of the cells'
    /// [`hessian_bound`]s over its cube: the in-range neighbours where the
    /// cube is centred on the cell, the 3³ cells from the shifted corner at
    /// the lattice's faces (which hold every in-range neighbour), and the
    /// in-range neighbours one by one on lattices under three cells across.
    #[test]
    fn neighbourhood_bound_covers_the_neighbours() {
        // Largest of `cells`' bounds, a NaN kept, written out here.
        let largest = |f: &Field<f64>, cells: &mut dyn Iterator<Item = [i64; 3]>| {
            let mut m = [0.0f64; 6];
            for c in cells {
                for (acc, h) in m.iter_mut().zip(hessian_bound(f, c)) {
                    if !acc.is_nan() && (h > *acc || h.is_nan()) {
                        *acc = h;
                    }
                }
            }
            m
        };
        let around = |c: [i64; 3], lo: [i64; 3], hi: [i64; 3]| {
            (0..27).filter_map(move |k| {
                let d = [k % 3 - 1, k / 3 % 3 - 1, k / 9 - 1];
                let n: [i64; 3] = std::array::from_fn(|a| c[a] + d[a]);
                (0..3).all(|a| n[a] >= lo[a] && n[a] < hi[a]).then_some(n)
            })
        };
        for dims in [[9usize, 8, 10], [3, 9, 4], [2, 6, 5]] {
            let vol = crate::volume::scrambled_u8(dims, 23);
            for name in ["bspline2", "bspline3", "bspline5", "bspline7"] {
                let f = Field::new(&vol, FilterKind::parse(name, 0.0).unwrap());
                let lat = Lattice::new(f.kernel(), dims);
                let n = lat.cells.map(|v| v as i64);
                let (mut centred, mut shifted, mut small) = (0, 0, 0);
                for i in 0..lat.cell_count() {
                    let cell = crate::lattice::cell_at(lat.cells, i);
                    let got = neighbourhood_bound(&f, cell, lat.cells);
                    let want = if n.iter().any(|&v| v < 3) {
                        small += 1;
                        largest(&f, &mut around(cell, [0; 3], n))
                    } else {
                        let corner: [i64; 3] =
                            std::array::from_fn(|a| (cell[a] - 1).clamp(0, n[a] - 3));
                        let centre = corner.map(|v| v + 1);
                        if centre == cell {
                            centred += 1;
                        } else {
                            shifted += 1;
                            // The shifted cube holds every in-range neighbour.
                            assert!(around(cell, [0; 3], n).all(|c| {
                                (0..3).all(|a| c[a] >= corner[a] && c[a] <= corner[a] + 2)
                            }));
                        }
                        largest(&f, &mut around(centre, [0; 3], n))
                    };
                    assert_eq!(
                        got.map(f64::to_bits),
                        want.map(f64::to_bits),
                        "{name} {dims:?} {cell:?}"
                    );
                }
                if n.iter().any(|&v| v < 3) {
                    assert!(small > 0);
                } else {
                    assert!(centred > 0 && shifted > 0, "{name} {dims:?}");
                }
            }
        }
    }

    /// The second derivative of the exact restriction of the field to random
    /// segments (any direction, inside one cell, any cell) of a random volume
    /// never exceeds [`along`] of the cell's bound.
    #[test]
    fn bounds_the_second_derivative_along_any_segment() {
        let dims = [9usize, 8, 10];
        let mut draws = 0u64;
        let mut rng = || {
            draws += 1;
            phantom::uniform(17, draws)
        };
        let s: Vec<f32> = (0..dims.iter().product::<usize>())
            .map(|_| (rng() * 255.0).floor() as f32)
            .collect();
        let vol = Volume::new(dims, [1.0; 3], SampleType::U8, s).unwrap();
        for name in [
            "bspline2",
            "bspline3",
            "bspline5",
            "bspline7",
            "smooth-bspline3",
        ] {
            let f = Field::new(&vol, FilterKind::parse(name, 0.5).unwrap());
            assert!(applies(f.kernel()));
            let off = f.kernel().knot_offset();
            let degree = 3 * (f.kernel().support() - 1);
            // Every knot cell, boundary ones (over the mirrored apron) too.
            let cells = Lattice::new(f.kernel(), dims).cells;
            for _ in 0..400 {
                let cell = [0, 1, 2].map(|a| (rng() * cells[a] as f64) as i64);
                let h = hessian_bound(&f, cell).map(round_up);
                let p0 = [0, 1, 2].map(|a| cell[a] as f64 - off + rng());
                let p1 = [0, 1, 2].map(|a| cell[a] as f64 - off + rng());
                for a in 0..3 {
                    assert_eq!(knot_cell(p0[a], off), cell[a]);
                    assert_eq!(knot_cell(p1[a], off), cell[a]);
                }
                let mut g = [0.0; crate::roots::bernstein::MAX_DEGREE + 1];
                with_support!(f.kernel().support(), S => f.restrict::<S>(cell, p0, p1, 0.0, &mut g));
                let d = [0, 1, 2].map(|a| p1[a] - p0[a]);
                let m = along(&h, d);
                for k in 0..=10 {
                    let t = k as f64 / 10.0;
                    // g''(t) of the monomial form.
                    let g2: f64 = (2..=degree)
                        .map(|n| (n * (n - 1)) as f64 * g[n] * t.powi(n as i32 - 2))
                        .sum();
                    assert!(g2.abs() <= m * (1.0 + 1e-9) + 1e-9, "{name}: {g2} > {m}");
                }
            }
        }
    }

    /// On samples of a quadratic `q(p)`, which B-splines of degree ≥ 2
    /// reproduce away from the boundary, every second derivative is the
    /// constant it should be and the bounds meet it: they are tight, not just
    /// valid.
    #[test]
    fn bounds_are_attained_on_a_quadratic() {
        let dims = [40usize, 40, 40];
        let q = |x: f64, y: f64, z: f64| 0.5 * x * x + 0.75 * y * y + 0.25 * x * z + y * z;
        // Second derivatives of q: xx, yy, zz, xy, xz, yz.
        let want = [1.0, 1.5, 0.0, 0.0, 0.25, 1.0];
        let mut s = Vec::with_capacity(dims.iter().product());
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    s.push(q(x as f64, y as f64, z as f64) as f32);
                }
            }
        }
        let vol = Volume::new(dims, [1.0; 3], SampleType::F32, s).unwrap();
        for name in ["bspline2", "bspline3", "bspline4"] {
            let f = Field::new(&vol, FilterKind::parse(name, 0.0).unwrap());
            let cell = [19, 20, 21];
            let h = hessian_bound(&f, cell);
            for e in 0..6 {
                assert!(
                    (h[e] - want[e]).abs() < 1e-3,
                    "{name}: entry {e}: {} vs {}",
                    h[e],
                    want[e]
                );
            }
            // Along (1, 1, 1) every term of q's Hessian adds up: the
            // restriction's second derivative is the bound itself.
            let off = f.kernel().knot_offset();
            let p0 = cell.map(|c| c as f64 - off + 0.1);
            let p1 = p0.map(|x| x + 0.8);
            let mut g = [0.0; crate::roots::bernstein::MAX_DEGREE + 1];
            with_support!(f.kernel().support(), S => f.restrict::<S>(cell, p0, p1, 0.0, &mut g));
            let d = [0.8; 3];
            let m = along(&h.map(round_up), d);
            assert!(
                (2.0 * g[2] - m).abs() < 1e-3 * m,
                "{name}: {} vs {m}",
                2.0 * g[2]
            );
        }
    }

    #[test]
    fn only_smooth_non_negative_filters_get_bounds() {
        let vol = phantom::SphereSpec {
            size: 24,
            radius: 8.0,
            sigma: 1.5,
            ..Default::default()
        }
        .build()
        .unwrap();
        for (name, has) in [
            ("linear", false),
            ("catmull-rom", false),
            ("bspline2", true),
            ("bspline3", true),
        ] {
            let f = Field::new(&vol, FilterKind::parse(name, 0.0).unwrap());
            // The phantom's values are 0..1.
            let iso = f.separating_iso(0.5);
            let tags = classify(&f, iso, Method::Bezier(2)).tags;
            let index = Arc::new(TaggedIndex::build(&tags));
            let b = CurvatureBounds::build(&f, index.clone());
            assert_eq!(b.is_some(), has, "{name}");
            if let Some(b) = b {
                assert_eq!(b.bounds.len(), index.count());
                assert!(index.count() > 100);
            }
        }
    }
}
