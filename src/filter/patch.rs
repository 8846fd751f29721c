//! Per-cell power-basis patches: the field inside each tagged cell as one
//! trivariate polynomial in local coordinates, precomputed.
//!
//! Inside a knot cell `f(t) = Σ_pqr a_pqr tx^p ty^q tz^r` with `t ∈ [0,1]³`
//! and `a_pqr = Σ_ijk c_ijk P_ip P_jq P_kr` (`P` = the kernel's weight
//! polynomials in monomial form). Many rays solve the same tagged cells, so
//! computing `a` once per cell (a separable `3·S⁴` transform) turns each
//! ray's restriction into a 3-D Horner scheme over `a` — about a third of the
//! arithmetic of composing weight polynomials with the coefficients per ray
//! (~490 against ~1500 flops for cubic).
//!
//! Only tagged cells get a patch; a rank structure over the tag bitset (prefix
//! popcounts per 64-bit word) maps a cell to its patch in O(1).

use rayon::prelude::*;

use super::Field;
use crate::classify::Tags;
use crate::classify::bezier::{SubCells, bernstein_weights, cell_bernstein};
use crate::classify::slack;
use crate::lattice::Bricked;
use crate::roots::bernstein::MAX_DEGREE;
use crate::simd::Madd;

const N: usize = MAX_DEGREE + 1;

/// The monomial weight matrix `P[i][m]` of a kernel (`W_i(t) = Σ_m P_im t^m`).
pub fn weight_matrix(field: &Field) -> Vec<f64> {
    let kernel = field.kernel();
    let s = kernel.support();
    (0..s * s)
        .map(|k| kernel.weight_poly(k / s)[k % s])
        .collect()
}

/// Power-basis patches of `L` cells at once from their coefficient
/// neighbourhoods (`bases`, as [`Field::lane_segment`] gives them), into
/// `out[p + S(q + S r)][lane]`: three separable passes, each a fixed-order
/// chain of multiply-adds. Precomputed and on-the-fly patches both come from
/// here, so they are the same bits.
#[inline(always)]
pub fn patch_lanes<const S: usize, const L: usize, M: Madd>(
    field: &Field,
    weights: &[f64],
    bases: &[usize; L],
    out: &mut [[f64; L]],
    tmp: &mut [[f64; L]],
) {
    let coeffs = field.coeffs();
    let (sy, sz) = (coeffs.stride(1), coeffs.stride(2));
    let data = coeffs.data();
    let span = (S - 1) * (sy + sz) + S;
    for l in 0..L {
        assert!(
            bases[l] + span <= data.len(),
            "lane neighbourhood inside the grid"
        );
    }
    let s3 = S * S * S;
    let (a, b) = (&mut out[..s3], &mut tmp[..s3]);
    for k in 0..S {
        for j in 0..S {
            for i in 0..S {
                let off = i + j * sy + k * sz;
                // SAFETY: base + off < base + span <= data.len() (asserted).
                a[i + S * (j + S * k)] =
                    std::array::from_fn(|l| unsafe { *data.get_unchecked(bases[l] + off) });
            }
        }
    }
    // x: b[m, j, k] = Σ_i a[i, j, k] P[i][m]; then y into a; then z into b.
    // A plain function marked inline(always), not a closure: closures are not
    // inlined reliably, and outside the caller's `target_feature` context the
    // multiply-adds would become library calls.
    #[inline(always)]
    fn pass<const S: usize, const L: usize, M: Madd>(
        weights: &[f64],
        src: &[[f64; L]],
        dst: &mut [[f64; L]],
        stride: usize,
    ) {
        for o in 0..S * S * S / (stride * S) {
            for inner in 0..stride {
                let base = o * stride * S + inner;
                for m in 0..S {
                    let mut acc = [0.0f64; L];
                    for i in 0..S {
                        let w = weights[i * S + m];
                        let v = &src[base + i * stride];
                        for l in 0..L {
                            acc[l] = M::madd(v[l], w, acc[l]);
                        }
                    }
                    dst[base + m * stride] = acc;
                }
            }
        }
    }
    pass::<S, L, M>(weights, a, b, 1);
    pass::<S, L, M>(weights, b, a, S);
    pass::<S, L, M>(weights, a, b, S * S);
    a.copy_from_slice(b);
}

/// Power-basis tensors of the tagged cells of one classification.
#[derive(Clone, Debug)]
pub struct Patches {
    support: usize,
    /// The tag bitset in 4³ bricks, one word per brick ([`Bricked`]), and
    /// the tagged cells before each word: patches of nearby cells sit
    /// together, and finding one is a popcount.
    bricked: Bricked,
    rank: Vec<u32>,
    words: Vec<u64>,
    /// `support³` coefficients per tagged cell, `a[p + S(q + S r)]`.
    data: Vec<f64>,
    /// Per tagged cell, which of its 4³ sub-cells can hold the iso-surface
    /// ([`SubCells`]); `None` keeps every sub-cell (the classification's own
    /// resolution, for the paper's methods).
    masks: Option<Vec<u64>>,
}

impl Patches {
    /// Bytes the patches of `tags` would take (to check a memory budget first).
    pub fn bytes_for(tags: &Tags, support: usize) -> usize {
        tags.count() * (support.pow(3) * 8 + 8) + Bricked::new(tags.cells).len() / 64 * 12
    }

    /// Patches of every tagged cell, computed with the lane routine of the
    /// running instruction set (so they match on-the-fly patches bit for
    /// bit), and with `sub_cells` their Bézier sub-cell masks for the
    /// (separated) iso-value `iso`.
    pub fn build(field: &Field, tags: &Tags, iso: f64, sub_cells: bool) -> Patches {
        let s = field.kernel().support();
        let bricked = Bricked::new(tags.cells);
        let mut words = vec![0u64; bricked.len() / 64];
        words.par_iter_mut().enumerate().for_each(|(brick, w)| {
            for k in 0..64 {
                let c = bricked.cell(brick * 64 + k);
                if (0..3).all(|a| c[a] < tags.cells[a]) && tags.get(c.map(|v| v as i64)) {
                    *w |= 1 << k;
                }
            }
        });
        let mut rank = Vec::with_capacity(words.len());
        let mut acc = 0u32;
        for w in &words {
            rank.push(acc);
            acc += w.count_ones();
        }
        let s3 = s * s * s;
        // Tagged cells in slot order (brick by brick).
        let cells: Vec<usize> = words
            .iter()
            .enumerate()
            .flat_map(|(brick, &w)| {
                (0..64)
                    .filter(move |k| w >> k & 1 == 1)
                    .map(move |k| brick * 64 + k)
            })
            .collect();
        let weights = weight_matrix(field);
        let lead = ((s - 1) / 2) as i64;
        let cell_of = |slot: usize| bricked.cell(slot).map(|v| v as i64);
        let base_of = |idx: usize| {
            let cell = cell_of(idx);
            field.coeffs().offset(
                (cell[0] - lead) as isize,
                (cell[1] - lead) as isize,
                (cell[2] - lead) as isize,
            )
        };
        let isa = crate::simd::Isa::current();
        let lanes = isa.lanes();
        let mut data = vec![0.0f64; cells.len() * s3];
        data.par_chunks_mut(s3 * lanes)
            .zip(cells.par_chunks(lanes))
            .for_each(|(out, group)| {
                crate::with_isa!(isa, L, M => crate::with_support!(s, S => {
                    let bases: [usize; L] = std::array::from_fn(|l| base_of(group[l.min(group.len() - 1)]));
                    let mut buf = vec![[0.0f64; L]; S * S * S];
                    let mut tmp = vec![[0.0f64; L]; S * S * S];
                    patch_lanes::<S, L, M>(field, &weights, &bases, &mut buf, &mut tmp);
                    for (l, cell_out) in out.chunks_mut(S * S * S).enumerate() {
                        for (k, v) in cell_out.iter_mut().enumerate() {
                            *v = buf[k][l];
                        }
                    }
                }))
            });
        let beta = bernstein_weights(field);
        let eps = slack(field);
        let masks = sub_cells.then(|| {
            cells
                .par_iter()
                .map_init(
                    || SubCells::new(s),
                    |sub, &slot| sub.mask(&cell_bernstein(field, cell_of(slot), iso, &beta), eps),
                )
                .collect()
        });
        Patches {
            support: s,
            bricked,
            rank,
            words,
            data,
            masks,
        }
    }

    /// The sub-cell mask of the patch in `slot` ([`Patches::slot`]).
    #[inline(always)]
    pub fn mask(&self, slot: usize) -> u64 {
        self.masks.as_ref().map_or(u64::MAX, |m| m[slot])
    }

    /// The patch of cell `c`, if tagged.
    #[inline(always)]
    pub fn slot(&self, c: [i64; 3]) -> Option<usize> {
        let i = self.bricked.index(c);
        let (w, b) = (i >> 6, i & 63);
        let word = self.words[w];
        if (word >> b) & 1 == 0 {
            return None;
        }
        Some(self.rank[w] as usize + (word & ((1u64 << b) - 1)).count_ones() as usize)
    }

    pub fn bytes(&self) -> usize {
        self.data.len() * 8
            + self.masks.as_ref().map_or(0, |m| m.len() * 8)
            + self.rank.len() * 4
            + self.words.len() * 8
    }

    /// Copies the patches of `slots` into lane layout.
    #[inline(always)]
    pub fn gather<const S: usize, const L: usize>(&self, slots: &[usize; L], out: &mut [[f64; L]]) {
        debug_assert_eq!(S, self.support);
        let s3 = S * S * S;
        for l in 0..L {
            assert!(
                (slots[l] + 1) * s3 <= self.data.len(),
                "patch slot in range"
            );
        }
        for (k, o) in out[..s3].iter_mut().enumerate() {
            // SAFETY: slot*s3 + k < (slot+1)*s3 <= data.len() (asserted).
            *o = std::array::from_fn(|l| unsafe { *self.data.get_unchecked(slots[l] * s3 + k) });
        }
    }
}

/// `g(s) = f(τ0 + sΔ) - iso` for `L` segments from their cells' patches
/// (lane layout, [`patch_lanes`]).
///
/// With `X_p(s) = (τx + Δx·s)^p` expanded once per lane into a table of
/// monomial coefficients (and likewise `Y_q`, `Z_r`), the restriction is
/// three contractions, `Σ_p a_pqr X_p`, then `Σ_q · Y_q`, then `Σ_r · Z_r`,
/// each a product of polynomials whose degrees are fixed by `S` alone: every
/// loop bound is a compile-time constant, so the whole routine unrolls into
/// straight-line multiply-adds over lanes (about 390 per lane for cubic).
#[inline(always)]
pub fn restrict_patch_lanes<const S: usize, const L: usize, M: Madd>(
    patch: &[[f64; L]],
    tau: &[[f64; L]; 3],
    delta: &[[f64; L]; 3],
    iso: f64,
    out: &mut [[f64; L]; N],
) {
    let patch = &patch[..S * S * S];
    // pw[a][p][k]: coefficient of s^k in (τa + Δa·s)^p (zero for k > p).
    let mut pw = [[[[0.0f64; L]; S]; S]; 3];
    for a in 0..3 {
        pw[a][0][0] = [1.0; L];
        for p in 1..S {
            for k in 0..=p {
                let mut v = [0.0f64; L];
                for l in 0..L {
                    let keep = if k < p { pw[a][p - 1][k][l] } else { 0.0 };
                    let lift = if k > 0 { pw[a][p - 1][k - 1][l] } else { 0.0 };
                    v[l] = M::madd(lift, delta[a][l], keep * tau[a][l]);
                }
                pw[a][p][k] = v;
            }
        }
    }
    let d1 = S - 1;
    let mut g = [[0.0f64; L]; N];
    for r in 0..S {
        // Q_r(s) = Σ_q Y_q(s) Σ_p a_pqr X_p(s), degree 2(S-1).
        let mut qr = [[0.0f64; L]; N];
        for q in 0..S {
            let mut px = [[0.0f64; L]; S];
            for p in 0..S {
                let a = &patch[p + S * (q + S * r)];
                for k in 0..=p {
                    for l in 0..L {
                        px[k][l] = M::madd(a[l], pw[0][p][k][l], px[k][l]);
                    }
                }
            }
            for j in 0..=q {
                for k in 0..S {
                    for l in 0..L {
                        qr[k + j][l] = M::madd(px[k][l], pw[1][q][j][l], qr[k + j][l]);
                    }
                }
            }
        }
        for j in 0..=r {
            for m in 0..=2 * d1 {
                for l in 0..L {
                    g[m + j][l] = M::madd(qr[m][l], pw[2][r][j][l], g[m + j][l]);
                }
            }
        }
    }
    for l in 0..L {
        g[0][l] -= iso;
    }
    *out = g;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classify::{Method, classify};
    use crate::filter::FilterKind;
    use crate::lattice::Lattice;
    use crate::simd::Plain;
    use crate::volume::{SampleType, Volume};
    use crate::with_support;

    #[test]
    fn patch_restriction_matches_direct_restriction() {
        let dims = [9usize, 8, 10];
        let s: Vec<f32> = (0..dims.iter().product::<usize>())
            .map(|i| ((i * 7919 + 13) % 251) as f32)
            .collect();
        let vol = Volume::new(dims, [1.0; 3], SampleType::U8, s).unwrap();
        for name in ["linear", "catmull-rom", "bspline2", "bspline3", "bspline6"] {
            let f = Field::new(&vol, FilterKind::parse(name, 0.0).unwrap());
            let iso = f.separating_iso(120.0);
            let tags = classify(&f, iso, Method::Bmcc).tags;
            let patches = Patches::build(&f, &tags, iso, true);
            let lat = Lattice::new(f.kernel(), dims);
            let off = lat.offset;
            let mut checked = 0;
            for z in 1..lat.cells[2] as i64 - 1 {
                for y in 1..lat.cells[1] as i64 - 1 {
                    for x in 1..lat.cells[0] as i64 - 1 {
                        let cell = [x, y, z];
                        let Some(slot) = patches.slot(cell) else {
                            continue;
                        };
                        let p0 = [
                            x as f64 - off + 0.13,
                            y as f64 - off + 0.71,
                            z as f64 - off + 0.42,
                        ];
                        let p1 = [p0[0] + 0.8, p0[1] - 0.6, p0[2] + 0.5];
                        let mut direct = [0.0; N];
                        with_support!(f.kernel().support(), S => f.restrict::<S>(cell, p0, p1, iso, &mut direct));
                        let (_, tau, delta) = f.lane_segment(cell, p0, p1);
                        let mut lanes = [[0.0; 2]; N];
                        let mut buf = vec![[0.0; 2]; 512];
                        with_support!(f.kernel().support(), S => {
                            patches.gather::<S, 2>(&[slot; 2], &mut buf);
                            restrict_patch_lanes::<S, 2, Plain>(
                                &buf,
                                &std::array::from_fn(|a| [tau[a]; 2]),
                                &std::array::from_fn(|a| [delta[a]; 2]),
                                iso,
                                &mut lanes,
                            )
                        });
                        // On-the-fly patches are the same bits as precomputed ones
                        // (with the same lane routine).
                        let (base, _, _) = f.lane_segment(cell, p0, p1);
                        let mut fly = vec![[0.0; 2]; 512];
                        let mut tmp = vec![[0.0; 2]; 512];
                        let w = weight_matrix(&f);
                        if crate::simd::Isa::current() == crate::simd::Isa::Portable {
                            with_support!(f.kernel().support(), S => patch_lanes::<S, 2, Plain>(&f, &w, &[base; 2], &mut fly, &mut tmp));
                            assert_eq!(fly, buf, "{name} {cell:?}");
                        }
                        let deg = 3 * (f.kernel().support() - 1);
                        for m in 0..=deg {
                            let scale = 1.0 + direct[m].abs();
                            assert!(
                                (lanes[m][0] - direct[m]).abs() <= 1e-9 * scale,
                                "{name} {cell:?} m={m}: {} vs {}",
                                lanes[m][0],
                                direct[m]
                            );
                        }
                        checked += 1;
                    }
                }
            }
            assert!(checked > 10, "{name}");
        }
    }
}
