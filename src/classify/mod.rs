//! Which knot cells can hold the iso-surface (paper section 4.2).
//!
//! Every method is conservative — a cell left untagged provably holds no
//! crossing — except [`Method::Exact`], which tags only cells where a crossing
//! is *proven* (field values on both sides observed) and so bounds the truth
//! from below. Cells are knot cells (see [`crate::lattice`]).
//!
//! | method | bound over a cell | cost |
//! |---|---|---|
//! | `bmcc` | coefficients of the support on both sides of the iso-value (Thévenaz & Unser 2003) | separable OR windows over words of sign bits |
//! | `accc` | the paper's eq. (1): per-coefficient max/min weights over the cell | separable dot products |
//! | `accc2`, `accc4`, `accc8` | eq. (1) per 2³ / 4³ / 8³ sub-cell (the paper's proposed refinement), the straddling sub-cells kept as a 4³ mask | per tagged cell, separable for non-negative kernels |
//! | `bezier` | convex hull of the cell's tensor Bernstein (Bézier) coefficients, refined by de Casteljau subdivision | per tagged cell |
//! | `exact` | crossings proven by sign changes between evaluated points (subdivision to 1/16 cell) | per tagged cell, measuring only |
//!
//! BMCC and ACCC rely on non-negative weights. For Catmull-Rom (negative lobes)
//! `bmcc` and `accc` use the signed-weight interval bound of [`bound`] instead,
//! which stays correct; `bezier` needs no sign assumption at all.

pub mod accc_sub;
pub mod bezier;
mod bmcc;
pub mod bound;
#[cfg(target_arch = "x86_64")]
mod cubic_mask;
pub mod curvature;
pub mod masks;
pub mod plane;
mod separable;
pub mod tagged;
pub mod tags;

use std::time::Instant;

use rayon::prelude::*;

pub use bound::CellBound;
pub use curvature::CurvatureBounds;
pub use masks::SubCellMasks;
pub use plane::PlaneBounds;
pub use tagged::TaggedIndex;
pub use tags::Tags;

use crate::filter::Field;
use crate::filter::coeffs::Coefficient;
use crate::lattice::Lattice;

/// A classification method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Method {
    Bmcc,
    Accc,
    /// ACCC evaluated per `n³` sub-cells (n = 2, 4 or 8).
    AcccSub(u8),
    /// Bézier hull with up to `depth` de Casteljau subdivisions.
    Bezier(u8),
    /// Proven crossings only (a lower bound of the truth).
    Exact,
}

impl serde::Serialize for Method {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.name())
    }
}

/// Subdivision depth of `exact`: sub-cells of 1/16 voxel.
pub const EXACT_DEPTH: u8 = 4;

impl Method {
    pub fn parse(s: &str) -> Option<Method> {
        Some(match s.to_ascii_lowercase().as_str() {
            "bmcc" => Method::Bmcc,
            "accc" => Method::Accc,
            "accc2" => Method::AcccSub(2),
            "accc4" => Method::AcccSub(4),
            "accc8" => Method::AcccSub(8),
            "bezier" => Method::Bezier(2),
            "bezier0" => Method::Bezier(0),
            "bezier1" => Method::Bezier(1),
            "bezier2" => Method::Bezier(2),
            "bezier3" => Method::Bezier(3),
            "exact" => Method::Exact,
            _ => return None,
        })
    }

    pub fn name(&self) -> String {
        match self {
            Method::Bmcc => "bmcc".into(),
            Method::Accc => "accc".into(),
            Method::AcccSub(n) => format!("accc{n}"),
            Method::Bezier(2) => "bezier".into(),
            Method::Bezier(d) => format!("bezier{d}"),
            Method::Exact => "exact".into(),
        }
    }

    /// Whether untagged cells provably hold no crossing.
    pub fn is_conservative(&self) -> bool {
        !matches!(self, Method::Exact)
    }

    /// Whether the method also tells which of a tagged cell's 4³ sub-cells
    /// can hold the surface ([`SubCellMasks`]), for the traversal to skip
    /// the segments that meet none: the Bézier hull's, and ACCC's per
    /// sub-cell (each of its sub-cells sets the 4³ ones it overlaps).
    pub fn has_masks(&self) -> bool {
        match *self {
            Method::Bezier(_) => true,
            Method::AcccSub(n) => (1..=accc_sub::MAX_SUB).contains(&(n as usize)),
            _ => false,
        }
    }

    /// The names [`Method::parse`] accepts, for help and messages.
    pub const NAMES: &'static str =
        "bmcc, accc, accc2, accc4, accc8, bezier (= bezier2), bezier0, bezier1, bezier3, exact";

    /// The methods `snell classify` reports, coarse to fine.
    pub fn all() -> [Method; 8] {
        [
            Method::Bmcc,
            Method::Accc,
            Method::AcccSub(2),
            Method::AcccSub(4),
            Method::AcccSub(8),
            Method::Bezier(0),
            Method::Bezier(2),
            Method::Exact,
        ]
    }
}

/// Tags and what they cost.
#[derive(Clone, Debug)]
pub struct Classification {
    pub method: Method,
    pub tags: Tags,
    pub seconds: f64,
}

/// Classifies every knot cell of `field` for the (already separated) iso-value
/// `iso` (see [`Field::separating_iso`]), in parallel.
pub fn classify<T: Coefficient>(field: &Field<T>, iso: f64, method: Method) -> Classification {
    let start = Instant::now();
    let lattice = Lattice::new(field.kernel(), field.dims());
    let tags = match method {
        Method::Bmcc => bmcc(field, &lattice, iso),
        Method::Accc => accc(field, &lattice, iso),
        Method::AcccSub(n) => {
            let coarse = accc(field, &lattice, iso);
            accc_sub(field, &lattice, iso, &coarse, n as usize)
        }
        Method::Bezier(depth) => {
            let coarse = prefilter_candidates(field, &lattice, iso);
            bezier::refine(field, &lattice, iso, &coarse, depth, false)
        }
        Method::Exact => {
            let coarse = prefilter_candidates(field, &lattice, iso);
            bezier::refine(field, &lattice, iso, &coarse, EXACT_DEPTH, true)
        }
    };
    Classification {
        method,
        tags,
        seconds: start.elapsed().as_secs_f64(),
    }
}

/// [`classify`], and for the methods with sub-cell masks
/// ([`Method::has_masks`]; `Method::Bezier(2)` and `accc2`/`accc4`/`accc8`) the
/// masks of the tagged cells found on the way ([`bezier::refine_with_masks`],
/// [`accc_sub_with_masks`]; the same tags), by linear cell index, when they
/// may fit `mask_budget` bytes (checked against the candidate cells, which
/// bound the tagged ones).
pub fn classify_with_masks<T: Coefficient>(
    field: &Field<T>,
    iso: f64,
    method: Method,
    mask_budget: usize,
) -> (Classification, Option<masks::LinearMasks>) {
    let start = Instant::now();
    let lattice = Lattice::new(field.kernel(), field.dims());
    let fits = |coarse: &Tags| coarse.count() * std::mem::size_of::<(usize, u64)>() <= mask_budget;
    let (tags, masks) = match method {
        Method::Bezier(2) => {
            let coarse = prefilter_candidates(field, &lattice, iso);
            let keep = fits(&coarse);
            let (tags, masks) = bezier::refine_with_masks(field, &lattice, iso, &coarse, keep);
            (tags, keep.then_some(masks))
        }
        Method::AcccSub(n) if method.has_masks() => {
            let coarse = accc(field, &lattice, iso);
            let keep = fits(&coarse);
            let (tags, masks) =
                accc_sub_with_masks(field, &lattice, iso, &coarse, n as usize, keep);
            (tags, keep.then_some(masks))
        }
        _ => return (classify(field, iso, method), None),
    };
    let c = Classification {
        method,
        tags,
        seconds: start.elapsed().as_secs_f64(),
    };
    (c, masks)
}

/// Slack that keeps bounds conservative under summation rounding.
pub(crate) fn slack<T: Coefficient>(field: &Field<T>) -> f64 {
    1e-12 * field.max_abs_coeff().max(1.0)
}

/// The cheapest valid candidate set: BMCC for non-negative kernels (the Bézier
/// coefficients are convex combinations of the support, so they cannot leave
/// its range), the Lebesgue range otherwise.
pub(crate) fn prefilter_candidates<T: Coefficient>(
    field: &Field<T>,
    lattice: &Lattice,
    iso: f64,
) -> Tags {
    if field.kernel().is_nonnegative() {
        bmcc(field, lattice, iso)
    } else {
        lebesgue_range(field, lattice, iso)
    }
}

/// Binary morphological classification: the support holds coefficients on
/// both sides (`> iso` and `<= iso`). For kernels with negative lobes, where
/// that is not a bound, the support's coefficient range widened by the
/// kernel's Lebesgue constant ([`lebesgue_range`]) takes its place.
pub fn bmcc<T: Coefficient>(field: &Field<T>, lattice: &Lattice, iso: f64) -> Tags {
    if !field.kernel().is_nonnegative() {
        return lebesgue_range(field, lattice, iso);
    }
    bmcc::bmcc_bits(field, lattice, iso)
}

/// The paper's equation (1), separably: upper and lower bounds of `f - iso`
/// over the cell from `d = c - iso` weighted by the per-axis weight maxima `M`
/// and minima `m` (`d >= 0` takes `M` for the upper bound, `d < 0` takes `m`).
pub fn accc<T: Coefficient>(field: &Field<T>, lattice: &Lattice, iso: f64) -> Tags {
    let kernel = field.kernel();
    if !kernel.is_nonnegative() {
        return signed_direct(field, lattice, iso);
    }
    let s = kernel.support();
    let (mx, mn): (Vec<f64>, Vec<f64>) = (0..s)
        .map(|j| {
            let (lo, hi) = kernel.weight_range(j, 0.0, 1.0);
            (hi, lo.max(0.0))
        })
        .unzip();
    // Channels: d+·M, d+·m, d-·M, d-·m. The slack that absorbs summation
    // rounding scales with the terms summed, so a bound that is exactly iso
    // (e.g. trilinear, whose minimum weights are 0) stays exact.
    let tags = separable::per_cell(
        field,
        lattice,
        |c| {
            let d = c - iso;
            let (p, n) = if d >= 0.0 { (d, 0.0) } else { (0.0, d) };
            [p, p, n, n]
        },
        |w| {
            let mut acc = [0.0f64; 4];
            for (j, v) in w.iter().enumerate() {
                acc[0] += v[0] * mx[j];
                acc[1] += v[1] * mn[j];
                acc[2] += v[2] * mx[j];
                acc[3] += v[3] * mn[j];
            }
            acc
        },
        |v| {
            let upper = v[0] + v[3];
            let lower = v[1] + v[2];
            let e_up = 1e-12 * (v[0].abs() + v[3].abs());
            let e_lo = 1e-12 * (v[1].abs() + v[2].abs());
            // Some point may exceed iso, and some point may not.
            upper > e_up && lower <= e_lo
        },
    );
    // Where a weight's minimum over the cell is 0 (trilinear), eq. (1) cannot
    // exclude a cell whose coefficients all lie on one side: intersect with
    // BMCC, which can.
    if mn.contains(&0.0) {
        tags.and(&bmcc(field, lattice, iso))
    } else {
        tags
    }
}

/// The coefficient range `[lo, hi]` of the support widened about its middle
/// by the kernel's Lebesgue constant `L` (separable min/max windows): since
/// the weights sum to one, `|f - mid| <= Σ|c - mid||w| <= L·(hi - lo)/2`.
/// Valid for any kernel; for non-negative ones `L = 1` and it is BMCC's range.
pub fn lebesgue_range<T: Coefficient>(field: &Field<T>, lattice: &Lattice, iso: f64) -> Tags {
    let l = field.kernel().lebesgue_constant().powi(3);
    separable::per_cell(
        field,
        lattice,
        |c| [c, c],
        |w| {
            w.iter().fold([f64::INFINITY, f64::NEG_INFINITY], |a, b| {
                [a[0].min(b[0]), a[1].max(b[1])]
            })
        },
        |v| {
            let (mid, half) = (0.5 * (v[0] + v[1]), 0.5 * (v[1] - v[0]));
            let eps = 1e-12 * (mid.abs() + half + iso.abs());
            mid + l * half > iso - eps && mid - l * half <= iso + eps
        },
    )
}

/// Signed kernels: the Lebesgue range, refined cell by cell with the
/// signed-weight interval bound of [`CellBound`]; both are valid, so is their
/// intersection.
fn signed_direct<T: Coefficient>(field: &Field<T>, lattice: &Lattice, iso: f64) -> Tags {
    let coarse = lebesgue_range(field, lattice, iso);
    let b = CellBound::new(field.kernel());
    let eps = slack(field);
    refine_cells(lattice, &coarse, |cell| {
        let (lo, hi) = b.range(field, cell, iso);
        lo <= iso + eps && hi > iso - eps
    })
}

/// ACCC per `n³` sub-cells ([`accc_sub::SubCellBounds`]), for the cells
/// `coarse` tagged: a cell stays tagged if some sub-cell's bound straddles
/// the iso-value.
pub fn accc_sub<T: Coefficient>(
    field: &Field<T>,
    lattice: &Lattice,
    iso: f64,
    coarse: &Tags,
    n: usize,
) -> Tags {
    accc_sub_with_masks(field, lattice, iso, coarse, n, false).0
}

/// [`accc_sub`](fn@accc_sub) and, with `keep_masks`, every kept cell's 4³ sub-cell mask
/// ([`accc_sub::SubCellBounds::cell_mask`]) by linear cell index,
/// ascending.
pub fn accc_sub_with_masks<T: Coefficient>(
    field: &Field<T>,
    lattice: &Lattice,
    iso: f64,
    coarse: &Tags,
    n: usize,
    keep_masks: bool,
) -> (Tags, masks::LinearMasks) {
    let bounds = accc_sub::SubCellBounds::new(field.kernel(), n);
    let [nx, ny, nz] = lattice.cells;
    let slab = nx * ny;
    let slabs: Vec<(masks::SlabTags, masks::LinearMasks)> = (0..nz)
        .into_par_iter()
        .map_init(
            || bounds.scratch(),
            |w, z| {
                let mut flags = masks::SlabTags::new(nx, ny);
                let mut found = Vec::new();
                let first = z * slab;
                crate::with_isa!(crate::simd::Isa::current(), _L, _M => {
                    for i in coarse.ones(first..first + slab) {
                        let cell = crate::lattice::cell_at(lattice.cells, i);
                        let mask = bounds.cell_mask(field, cell, iso, w);
                        if mask != 0 {
                            flags.set(i - first);
                            if keep_masks {
                                found.push((i, mask));
                            }
                        }
                    }
                });
                (flags, found)
            },
        )
        .collect();
    masks::join_slabs(lattice.cells, slabs)
}

/// `c - iso` over a cell's `S³` support, x fastest.
pub(crate) fn support_minus_iso<T: Coefficient>(
    field: &Field<T>,
    cell: [i64; 3],
    iso: f64,
) -> Vec<f64> {
    let s = field.kernel().support();
    let mut out = vec![0.0; s * s * s];
    support_minus_iso_into(field, cell, iso, &mut out);
    out
}

/// [`support_minus_iso`] into the first `S³` entries of `out`.
#[inline(always)]
pub(crate) fn support_minus_iso_into<T: Coefficient>(
    field: &Field<T>,
    cell: [i64; 3],
    iso: f64,
    out: &mut [f64],
) {
    crate::with_support!(field.kernel().support(), S => {
        support_minus_iso_lane::<S, 1, T>(field, cell, iso, 0, out)
    })
}

/// `c - iso` over `cell`'s `S³` support into lane `l` of `out`, `L`
/// interleaved tensors (element `e` of lane `l` at `e·L + l`).
#[inline(always)]
pub(crate) fn support_minus_iso_lane<const S: usize, const L: usize, T: Coefficient>(
    field: &Field<T>,
    cell: [i64; 3],
    iso: f64,
    l: usize,
    out: &mut [f64],
) {
    let coeffs = field.coeffs();
    let base = field.support_offset(cell);
    let (sy, sz) = (coeffs.stride(1), coeffs.stride(2));
    let data = coeffs.data();
    for k in 0..S {
        for j in 0..S {
            let row = &data[base + j * sy + k * sz..][..S];
            let first = S * (j + S * k);
            for (i, c) in row.iter().enumerate() {
                out[(first + i) * L + l] = c.to_f64() - iso;
            }
        }
    }
}

/// Re-decides every tagged cell of `coarse` with `keep`, in parallel.
pub(crate) fn refine_cells(
    lattice: &Lattice,
    coarse: &Tags,
    keep: impl Fn([i64; 3]) -> bool + Sync,
) -> Tags {
    let [nx, ny, nz] = lattice.cells;
    let slab = nx * ny;
    let chunks: Vec<Vec<u8>> = (0..nz)
        .into_par_iter()
        .map(|z| {
            let mut out = vec![0u8; slab];
            for (i, o) in out.iter_mut().enumerate() {
                if coarse.get_index(z * slab + i) {
                    let cell = [(i % nx) as i64, (i / nx) as i64, z as i64];
                    *o = keep(cell) as u8;
                }
            }
            out
        })
        .collect();
    Tags::from_chunks(lattice.cells, chunks)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::FilterKind;
    use crate::volume::Volume;

    fn noisy() -> Volume {
        let dims = [9usize, 8, 10];
        crate::volume::scrambled_u8(dims, 13)
    }

    #[test]
    fn methods_nest_and_contain_the_proven_cells() {
        let vol = noisy();
        for name in ["linear", "catmull-rom", "bspline2", "bspline3", "bspline5"] {
            let f = Field::new(&vol, FilterKind::parse(name, 0.0).unwrap());
            let iso = f.separating_iso(120.0);
            let get = |m| classify(&f, iso, m).tags;
            let (b, a, a2, a4, a8, z0, z2, ex) = (
                get(Method::Bmcc),
                get(Method::Accc),
                get(Method::AcccSub(2)),
                get(Method::AcccSub(4)),
                get(Method::AcccSub(8)),
                get(Method::Bezier(0)),
                get(Method::Bezier(2)),
                get(Method::Exact),
            );
            for (m, t) in [
                ("bmcc", &b),
                ("accc", &a),
                ("accc2", &a2),
                ("accc4", &a4),
                ("accc8", &a8),
                ("bezier0", &z0),
                ("bezier", &z2),
            ] {
                assert!(ex.is_subset_of(t), "{name}: exact ⊄ {m}");
            }
            if f.kernel().is_nonnegative() {
                assert!(a.is_subset_of(&b), "{name}: accc ⊄ bmcc");
            }
            assert!(
                a2.is_subset_of(&a) && a4.is_subset_of(&a2) && a8.is_subset_of(&a4),
                "{name}: sub-cells refine"
            );
            assert!(z2.is_subset_of(&z0), "{name}: subdivision refines");
            assert!(ex.count() > 0, "{name}: noise crosses 120 somewhere");
        }
    }

    #[test]
    fn bmcc_and_accc_separable_match_direct() {
        let vol = noisy();
        let f = Field::new(&vol, FilterKind::BSpline(3));
        let lat = Lattice::new(f.kernel(), f.dims());
        let iso = f.separating_iso(100.0);
        let b = bmcc(&f, &lat, iso);
        let direct = refine_cells(
            &lat,
            &Tags::from_chunks(lat.cells, vec![vec![1; lat.cell_count()]]),
            |c| {
                let d = support_minus_iso(&f, c, iso);
                d.iter().any(|&v| v > 0.0) && d.iter().any(|&v| v <= 0.0)
            },
        );
        assert_eq!(b, direct);
        // accc (separable) equals accc_sub with one sub-cell (direct).
        let a = accc(&f, &lat, iso);
        let all = Tags::from_chunks(lat.cells, vec![vec![1; lat.cell_count()]]);
        assert_eq!(a, accc_sub(&f, &lat, iso, &all, 1));
    }

    #[test]
    fn method_names_round_trip() {
        for m in Method::all() {
            assert_eq!(Method::parse(&m.name()), Some(m));
        }
    }
}
