//! SIMD across rays, chosen once at run time.
//!
//! Hot stages process rays in *lanes*: `L` rays doing the same arithmetic on
//! `[f64; L]` arrays (vertical SIMD, no horizontal reductions). The lane code
//! is written once, generic over `L` and over [`Madd`] (fused or plain
//! multiply-add), and compiled three times through `#[target_feature]`
//! wrappers: AVX-512 (8 lanes), AVX2 + FMA (4 lanes) and a portable fallback
//! (2 lanes, SSE2). [`Isa::current`] picks the best the CPU has, once.
//!
//! Each ray's result depends only on its own inputs, never on which lane or
//! chunk it lands in, so output is identical for any thread count or tile
//! size. Every level fuses its multiply-adds ([`Fused`]; the portable one
//! with the scalar FMA instruction where the CPU has it, else the C
//! library's `fma`, see [`portable_run`]) and the vector kernels' sums keep
//! one order, so the three levels give the same bits (compared on one
//! x86-64 machine through `SNELL_ISA`; other architectures run the portable
//! level's code, not compared).

use std::sync::OnceLock;

/// The instruction set the lane code runs with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Isa {
    Avx512,
    Avx2,
    Portable,
}

impl Isa {
    /// The best the running CPU supports (`SNELL_ISA=avx512|avx2|portable`
    /// forces a lower one, for comparisons; a value it cannot honour is
    /// ignored with a warning, as the other `SNELL_*` variables' are).
    pub fn current() -> Isa {
        static ISA: OnceLock<Isa> = OnceLock::new();
        *ISA.get_or_init(|| {
            let best = Isa::detect();
            let asked = crate::env::setting("SNELL_ISA");
            let (isa, why) = Isa::chosen(best, asked.as_deref());
            if let Some(why) = why {
                eprintln!("warning: SNELL_ISA: {why}");
            }
            isa
        })
    }

    /// The level `SNELL_ISA = asked` gives on a CPU whose best is `best`,
    /// and why it is not the one asked for, when it is not.
    fn chosen(best: Isa, asked: Option<&str>) -> (Isa, Option<String>) {
        let Some(asked) = asked else {
            return (best, None);
        };
        let level = match asked.trim() {
            "avx512" => Some(Isa::Avx512),
            "avx2" => Some(Isa::Avx2),
            "portable" => Some(Isa::Portable),
            _ => None,
        };
        match level {
            None => (
                best,
                Some(format!(
                    "expected avx512, avx2 or portable, got '{asked}'; using {}",
                    best.name()
                )),
            ),
            Some(l) if l.lanes() > best.lanes() => (
                best,
                Some(format!(
                    "this CPU cannot run {asked}; using {}",
                    best.name()
                )),
            ),
            Some(l) => (l, None),
        }
    }

    /// Every level the running CPU can run, best first (for tests that
    /// hold the levels to the same results).
    pub fn available() -> Vec<Isa> {
        [Isa::Avx512, Isa::Avx2, Isa::Portable]
            .into_iter()
            .filter(|&i| i.lanes() <= Isa::detect().lanes())
            .collect()
    }

    fn detect() -> Isa {
        #[cfg(target_arch = "x86_64")]
        {
            // F16C for the `f16` storage's row loads, and the scalar bit
            // instructions the walk and the tagged-cell index use: every CPU
            // with AVX2 has them.
            let extras = std::arch::is_x86_feature_detected!("f16c")
                && std::arch::is_x86_feature_detected!("popcnt")
                && std::arch::is_x86_feature_detected!("bmi1")
                && std::arch::is_x86_feature_detected!("bmi2")
                && std::arch::is_x86_feature_detected!("lzcnt");
            if std::arch::is_x86_feature_detected!("avx512f")
                && std::arch::is_x86_feature_detected!("avx512vl")
                && std::arch::is_x86_feature_detected!("avx512dq")
                && std::arch::is_x86_feature_detected!("fma")
                && extras
            {
                return Isa::Avx512;
            }
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
                && extras
            {
                return Isa::Avx2;
            }
        }
        Isa::Portable
    }

    pub fn name(self) -> &'static str {
        match self {
            Isa::Avx512 => "avx512",
            Isa::Avx2 => "avx2+fma",
            Isa::Portable => "portable",
        }
    }

    /// Rays per lane group.
    pub fn lanes(self) -> usize {
        match self {
            Isa::Avx512 => 8,
            Isa::Avx2 => 4,
            Isa::Portable => 2,
        }
    }
}

/// `a·b + c`, fused where the instruction set has it.
pub trait Madd: Copy {
    /// One rounding per multiply-add (what the vector kernels do).
    const FUSED: bool;
    fn madd(a: f64, b: f64, c: f64) -> f64;
}

/// One rounding (`vfmadd`); only inside FMA-enabled functions.
#[derive(Clone, Copy)]
pub struct Fused;
impl Madd for Fused {
    const FUSED: bool = true;
    #[inline(always)]
    fn madd(a: f64, b: f64, c: f64) -> f64 {
        a.mul_add(b, c)
    }
}

/// Two roundings; what a CPU without FMA does.
#[derive(Clone, Copy)]
pub struct Plain;
impl Madd for Plain {
    const FUSED: bool = false;
    #[inline(always)]
    fn madd(a: f64, b: f64, c: f64) -> f64 {
        a * b + c
    }
}

/// Runs `$body` with `$L` (lanes) and `$M` (multiply-add) bound for the
/// current instruction set, inside a function compiled for it. `$body` must
/// be an expression; everything it calls should be `#[inline(always)]` so it
/// is compiled with the target's features.
#[macro_export]
macro_rules! with_isa {
    ($isa:expr, $L:ident, $M:ident => $body:expr) => {{
        #[allow(unused_unsafe)]
        match $isa {
            #[cfg(target_arch = "x86_64")]
            $crate::simd::Isa::Avx512 => {
                #[target_feature(
                    enable = "avx512f,avx512vl,avx512dq,fma,avx2,f16c,popcnt,bmi1,bmi2,lzcnt"
                )]
                unsafe fn run<R>(f: impl FnOnce() -> R) -> R {
                    f()
                }
                const $L: usize = 8;
                type $M = $crate::simd::Fused;
                // SAFETY: Isa::Avx512 is only chosen when the CPU has these features.
                unsafe {
                    run(
                        #[inline(always)]
                        || $body,
                    )
                }
            }
            #[cfg(target_arch = "x86_64")]
            $crate::simd::Isa::Avx2 => {
                #[target_feature(enable = "avx2,fma,f16c,popcnt,bmi1,bmi2,lzcnt")]
                unsafe fn run<R>(f: impl FnOnce() -> R) -> R {
                    f()
                }
                const $L: usize = 4;
                type $M = $crate::simd::Fused;
                // SAFETY: Isa::Avx2 is only chosen when the CPU has these features.
                unsafe {
                    run(
                        #[inline(always)]
                        || $body,
                    )
                }
            }
            _ => {
                const $L: usize = 2;
                type $M = $crate::simd::Fused;
                $crate::simd::portable_run(
                    #[inline(always)]
                    || $body,
                )
            }
        }
    }};
}

/// Runs `f`, the portable level's lane code, with the scalar FMA
/// instruction where the CPU has it: every level's multiply-adds are fused
/// ([`Fused`]), so that all give the same bits. Without the instruction
/// each `mul_add` is a call into the C library's correctly rounded `fma`:
/// the same bits, at a cost (portable sphere and teapot frames 3.6–4.5×
/// slower on this project's CPU with every `mul_add` such a call, where the
/// library still uses the instruction; more where it computes `fma` in
/// software).
#[inline(always)]
pub fn portable_run<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "fma")]
        unsafe fn with_fma<R>(f: impl FnOnce() -> R) -> R {
            f()
        }
        static FMA: OnceLock<bool> = OnceLock::new();
        if *FMA.get_or_init(|| std::arch::is_x86_feature_detected!("fma")) {
            // SAFETY: the CPU has FMA (checked above).
            return unsafe { with_fma(f) };
        }
    }
    f()
}

/// Value and gradient of a cubic (support 4) tensor spline from its 4³
/// coefficient neighbourhood, with AVX2 + FMA: each x-row of 4 coefficients
/// is one vector; rows are combined over y (weights and derivative weights),
/// then over z into three accumulators (value/x-derivative, y-derivative,
/// z-derivative), and four dot products of 4 finish it. Row `(j, k)` of the neighbourhood is
/// `nb[j·sy + k·sz ..][..4]`; `w`/`d` are the weights and derivative
/// weights per axis. Rows of `f32` or `f16` coefficients are widened to
/// `f64` as they are loaded ([`Row4`]), so every storage runs the same sums.
///
/// # Safety
/// The CPU must have AVX2, FMA and F16C ([`Isa::Avx2`] or better), and `nb`
/// must hold `3·(sy + sz) + 4` values.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,f16c")]
#[inline]
pub unsafe fn cubic_value_grad<T: Row4>(
    nb: &[T],
    sy: usize,
    sz: usize,
    w: &[[f64; 4]; 3],
    d: &[[f64; 4]; 3],
) -> (f64, [f64; 3]) {
    use std::arch::x86_64::*;
    // Per z-plane k: P_k = Σ_j wy_j c_jk and Q_k = Σ_j dy_j c_jk (vectors
    // along x); then R = Σ_k wz_k P_k, Ry = Σ_k wz_k Q_k, Rz = Σ_k dz_k P_k.
    let wy = w[1].map(|v| _mm256_set1_pd(v));
    let dy = d[1].map(|v| _mm256_set1_pd(v));
    let (mut rv, mut ry, mut rz) = (
        _mm256_setzero_pd(),
        _mm256_setzero_pd(),
        _mm256_setzero_pd(),
    );
    for k in 0..4 {
        let (mut pk, mut qk) = (_mm256_setzero_pd(), _mm256_setzero_pd());
        for j in 0..4 {
            // SAFETY: the caller guarantees the row is inside `nb`.
            let c = unsafe { T::load4(nb.as_ptr().add(j * sy + k * sz)) };
            pk = _mm256_fmadd_pd(wy[j], c, pk);
            qk = _mm256_fmadd_pd(dy[j], c, qk);
        }
        let (wz, dz) = (_mm256_set1_pd(w[2][k]), _mm256_set1_pd(d[2][k]));
        rv = _mm256_fmadd_pd(wz, pk, rv);
        ry = _mm256_fmadd_pd(wz, qk, ry);
        rz = _mm256_fmadd_pd(dz, pk, rz);
    }
    let dot = |a: __m256d, b: &[f64; 4]| {
        // SAFETY: `b` holds 4 f64.
        let p = _mm256_mul_pd(a, unsafe { _mm256_loadu_pd(b.as_ptr()) });
        let s = _mm_add_pd(_mm256_castpd256_pd128(p), _mm256_extractf128_pd(p, 1));
        _mm_cvtsd_f64(_mm_add_sd(s, _mm_unpackhi_pd(s, s)))
    };
    (
        dot(rv, &w[0]),
        [dot(rv, &d[0]), dot(ry, &w[0]), dot(rz, &w[0])],
    )
}

/// [`cubic_value_grad`] without vector instructions, bitwise its result:
/// the same fused multiply-adds in the same order (`f64::mul_add`), and its
/// final dot products as `(p0 + p2) + (p1 + p3)`, so that a CPU without AVX2
/// (`SNELL_ISA=portable`, or another architecture) renders the same bits.
/// Where the CPU has no FMA, `mul_add` is the C library's correctly rounded
/// `fma`: slower, the same result.
#[inline(always)]
pub fn cubic_value_grad_scalar<T: Into<f64> + Copy>(
    nb: &[T],
    sy: usize,
    sz: usize,
    w: &[[f64; 4]; 3],
    d: &[[f64; 4]; 3],
) -> (f64, [f64; 3]) {
    let (mut rv, mut ry, mut rz) = ([0.0f64; 4], [0.0f64; 4], [0.0f64; 4]);
    for k in 0..4 {
        let (mut pk, mut qk) = ([0.0f64; 4], [0.0f64; 4]);
        for j in 0..4 {
            let row = &nb[j * sy + k * sz..][..4];
            for i in 0..4 {
                let c: f64 = row[i].into();
                pk[i] = w[1][j].mul_add(c, pk[i]);
                qk[i] = d[1][j].mul_add(c, qk[i]);
            }
        }
        for i in 0..4 {
            rv[i] = w[2][k].mul_add(pk[i], rv[i]);
            ry[i] = w[2][k].mul_add(qk[i], ry[i]);
            rz[i] = d[2][k].mul_add(pk[i], rz[i]);
        }
    }
    let dot = |r: &[f64; 4], x: &[f64; 4]| {
        let p: [f64; 4] = std::array::from_fn(|i| r[i] * x[i]);
        (p[0] + p[2]) + (p[1] + p[3])
    };
    (
        dot(&rv, &w[0]),
        [dot(&rv, &d[0]), dot(&ry, &w[0]), dot(&rz, &w[0])],
    )
}

/// [`cubic_value_grad`] for 8 neighbourhoods at once under AVX-512, bitwise
/// its result per lane: lane `l`'s neighbourhood starts at `data[base[l]]`
/// (rows `j·sy + k·sz`) and its fractional position on axis `a` is
/// `t[a][l]`; `poly[j]` is the kernel's weight polynomial `j` (lowest
/// coefficient first), evaluated as the scalar weights are. Each of
/// `cubic_value_grad`'s vectors along x becomes four vectors across the
/// lanes, one per x offset; its fused sums and the order of its final dot
/// products, `(p0 + p2) + (p1 + p3)`, are kept. (Left to the compiler, the
/// same loops over lane arrays became 128-bit code, slower than one point
/// at a time.)
///
/// # Safety
/// The CPU must have AVX-512F, FMA and F16C ([`Isa::Avx512`]), and every row
/// `base[l] + j·sy + k·sz .. + 4` (`j, k < 4`) must lie in `data`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,fma,f16c")]
#[inline]
pub unsafe fn cubic_value_grad_x8<T: Row4>(
    data: &[T],
    base: &[usize; 8],
    (sy, sz): (usize, usize),
    t: &[[f64; 8]; 3],
    poly: &[[f64; 4]; 4],
) -> ([f64; 8], [[f64; 8]; 3]) {
    use std::arch::x86_64::*;
    // SAFETY: each `[f64; 8]` is 64 readable bytes.
    let ld = |v: &[f64; 8]| unsafe { _mm512_loadu_pd(v.as_ptr()) };
    let zero = _mm512_setzero_pd();
    // Per axis, weight j and its derivative at `t`: `Kernel::weights_and_derivs`'s
    // Horner steps, a separate multiply and add each.
    let mut w = [[zero; 4]; 3];
    let mut d = [[zero; 4]; 3];
    for a in 0..3 {
        let ta = ld(&t[a]);
        for j in 0..4 {
            let (mut v, mut dv) = (_mm512_set1_pd(poly[j][3]), zero);
            for m in (0..3).rev() {
                dv = _mm512_add_pd(_mm512_mul_pd(dv, ta), v);
                v = _mm512_add_pd(_mm512_mul_pd(v, ta), _mm512_set1_pd(poly[j][m]));
            }
            w[a][j] = v;
            d[a][j] = dv;
        }
    }
    let (mut rv, mut ry, mut rz) = ([zero; 4], [zero; 4], [zero; 4]);
    for k in 0..4 {
        let (mut pk, mut qk) = ([zero; 4], [zero; 4]);
        for j in 0..4 {
            // SAFETY: rows in bounds (caller); AVX-512 (caller).
            let c: [__m512d; 4] = unsafe {
                std::mem::transmute(rows4x8::<T>(
                    data.as_ptr().wrapping_add(j * sy + k * sz),
                    base.as_ptr(),
                ))
            };
            let (wy, dy) = (w[1][j], d[1][j]);
            for i in 0..4 {
                pk[i] = _mm512_fmadd_pd(wy, c[i], pk[i]);
                qk[i] = _mm512_fmadd_pd(dy, c[i], qk[i]);
            }
        }
        let (wz, dz) = (w[2][k], d[2][k]);
        for i in 0..4 {
            rv[i] = _mm512_fmadd_pd(wz, pk[i], rv[i]);
            ry[i] = _mm512_fmadd_pd(wz, qk[i], ry[i]);
            rz[i] = _mm512_fmadd_pd(dz, pk[i], rz[i]);
        }
    }
    let dot = |r: &[__m512d; 4], x: &[__m512d; 4]| -> [f64; 8] {
        let p: [__m512d; 4] = std::array::from_fn(|i| _mm512_mul_pd(r[i], x[i]));
        let s = _mm512_add_pd(_mm512_add_pd(p[0], p[2]), _mm512_add_pd(p[1], p[3]));
        // SAFETY: `__m512d` and `[f64; 8]` have the same size.
        unsafe { std::mem::transmute(s) }
    };
    (
        dot(&rv, &w[0]),
        [dot(&rv, &d[0]), dot(&ry, &w[0]), dot(&rz, &w[0])],
    )
}

/// The restriction of a cubic (support 4) tensor spline to 8 segments at
/// once, one per lane: the monomial coefficients of `g(s) − iso`
/// (`out[m][lane]`, degree 9), bitwise what
/// [`crate::filter::Field::restrict_lanes`] computes with fused
/// multiply-adds — the same operations on the same values in the same
/// order — but with every accumulator a register: the weight
/// polynomials composed with the segment (`tau`, `delta` per axis, lanes),
/// then per neighbourhood row the x-contraction (four cubics), folded over
/// y into sextics and over z into the result. Left to the compiler, the
/// generic loops kept their accumulators in memory and took about 70 ns a
/// segment.
///
/// # Safety
/// The CPU must have AVX-512F and FMA ([`Isa::Avx512`]), and every row
/// `base[l] + j·sy + k·sz .. + 4` (`j, k < 4`) must lie in `data`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,fma,f16c")]
#[inline]
#[allow(clippy::too_many_arguments)]
pub unsafe fn restrict_cubic_x8<T: Row4>(
    data: &[T],
    base: &[usize; 8],
    (sy, sz): (usize, usize),
    tau: &[[f64; 8]; 3],
    delta: &[[f64; 8]; 3],
    poly: &[[f64; 4]; 4],
    iso: f64,
    out: &mut [[f64; 8]],
) {
    use std::arch::x86_64::*;
    // SAFETY: each `[f64; 8]` is 64 readable bytes.
    let ld = |v: &[f64; 8]| unsafe { _mm512_loadu_pd(v.as_ptr()) };
    let zero = _mm512_setzero_pd();
    // w[a][j][m]: weight polynomial j of axis a composed with the segment,
    // coefficient m (a Taylor shift by tau, then powers of delta).
    let mut w = [[[zero; 4]; 4]; 3];
    for a in 0..3 {
        let (t, dl) = (ld(&tau[a]), ld(&delta[a]));
        let d2 = _mm512_mul_pd(dl, dl);
        let d3 = _mm512_mul_pd(d2, dl);
        for j in 0..4 {
            let p = &poly[j];
            let (mut q0, mut q1, mut q2) = (
                _mm512_set1_pd(p[0]),
                _mm512_set1_pd(p[1]),
                _mm512_set1_pd(p[2]),
            );
            let q3 = _mm512_set1_pd(p[3]);
            // The generic loops' Taylor shift, unrolled (kept as a loop, the
            // compiler left `q` in memory): `k` from 2 down to `i`.
            q2 = _mm512_fmadd_pd(t, q3, q2);
            q1 = _mm512_fmadd_pd(t, q2, q1);
            q0 = _mm512_fmadd_pd(t, q1, q0);
            q2 = _mm512_fmadd_pd(t, q3, q2);
            q1 = _mm512_fmadd_pd(t, q2, q1);
            q2 = _mm512_fmadd_pd(t, q3, q2);
            w[a][j] = [
                q0,
                _mm512_mul_pd(q1, dl),
                _mm512_mul_pd(q2, d2),
                _mm512_mul_pd(q3, d3),
            ];
        }
    }
    let mut g = [zero; 10];
    for k in 0..4 {
        let mut bk = [zero; 7];
        for j in 0..4 {
            // SAFETY: rows in bounds (caller); AVX-512 (caller).
            let c = unsafe { rows4x8_regs::<T>(data.as_ptr().wrapping_add(j * sy + k * sz), base) };
            let mut ajk = [zero; 4];
            for i in 0..4 {
                for m in 0..4 {
                    ajk[m] = _mm512_fmadd_pd(c[i], w[0][i][m], ajk[m]);
                }
            }
            for m in 0..4 {
                for n in 0..4 {
                    bk[m + n] = _mm512_fmadd_pd(ajk[m], w[1][j][n], bk[m + n]);
                }
            }
        }
        for m in 0..7 {
            for n in 0..4 {
                g[m + n] = _mm512_fmadd_pd(bk[m], w[2][k][n], g[m + n]);
            }
        }
    }
    g[0] = _mm512_sub_pd(g[0], _mm512_set1_pd(iso));
    for (o, v) in out.iter_mut().zip(g) {
        // SAFETY: `o` is 64 writable bytes.
        unsafe { _mm512_storeu_pd(o.as_mut_ptr(), v) };
    }
}

/// [`restrict_cubic_x8`] for quadratic filters (support 3: the quadratic
/// B-spline): the monomial coefficients of `g(s) − iso` for 8 segments
/// (`out[m][lane]`, degree 6), bitwise what
/// [`crate::filter::Field::restrict_lanes`]'s generic loops compute with
/// fused multiply-adds, every accumulator a register. A row of three
/// coefficients per lane loads as the first three of a row of four
/// ([`rows4x8_regs`]; the fourth is never used). The generic loops
/// gathered each coefficient across the lanes and kept their accumulators
/// in memory.
///
/// # Safety
/// The CPU must have AVX-512F and FMA ([`Isa::Avx512`]), and every row
/// `base[l] + j·sy + k·sz .. + 4` (`j, k < 3`: one value past the
/// neighbourhood's row) must lie in `data`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,fma,f16c")]
#[inline]
#[allow(clippy::too_many_arguments)]
pub unsafe fn restrict_quadratic_x8<T: Row4>(
    data: &[T],
    base: &[usize; 8],
    (sy, sz): (usize, usize),
    tau: &[[f64; 8]; 3],
    delta: &[[f64; 8]; 3],
    poly: &[[f64; 3]; 3],
    iso: f64,
    out: &mut [[f64; 8]],
) {
    use std::arch::x86_64::*;
    // SAFETY: each `[f64; 8]` is 64 readable bytes.
    let ld = |v: &[f64; 8]| unsafe { _mm512_loadu_pd(v.as_ptr()) };
    let zero = _mm512_setzero_pd();
    // w[a][j][m]: as in `restrict_cubic_x8`, the generic loops' Taylor
    // shift (`k` from 1 down to `i`) and powers of delta, unrolled.
    let mut w = [[[zero; 3]; 3]; 3];
    for a in 0..3 {
        let (t, dl) = (ld(&tau[a]), ld(&delta[a]));
        let d2 = _mm512_mul_pd(dl, dl);
        for j in 0..3 {
            let p = &poly[j];
            let (mut q0, mut q1) = (_mm512_set1_pd(p[0]), _mm512_set1_pd(p[1]));
            let q2 = _mm512_set1_pd(p[2]);
            q1 = _mm512_fmadd_pd(t, q2, q1);
            q0 = _mm512_fmadd_pd(t, q1, q0);
            q1 = _mm512_fmadd_pd(t, q2, q1);
            w[a][j] = [q0, _mm512_mul_pd(q1, dl), _mm512_mul_pd(q2, d2)];
        }
    }
    let mut g = [zero; 7];
    for k in 0..3 {
        let mut bk = [zero; 5];
        for j in 0..3 {
            // SAFETY: rows (and the value after each) in bounds (caller);
            // AVX-512 (caller).
            let c = unsafe { rows4x8_regs::<T>(data.as_ptr().wrapping_add(j * sy + k * sz), base) };
            let mut ajk = [zero; 3];
            for i in 0..3 {
                for m in 0..3 {
                    ajk[m] = _mm512_fmadd_pd(c[i], w[0][i][m], ajk[m]);
                }
            }
            for m in 0..3 {
                for n in 0..3 {
                    bk[m + n] = _mm512_fmadd_pd(ajk[m], w[1][j][n], bk[m + n]);
                }
            }
        }
        for m in 0..5 {
            for n in 0..3 {
                g[m + n] = _mm512_fmadd_pd(bk[m], w[2][k][n], g[m + n]);
            }
        }
    }
    g[0] = _mm512_sub_pd(g[0], _mm512_set1_pd(iso));
    for (o, v) in out.iter_mut().zip(g) {
        // SAFETY: `o` is 64 writable bytes.
        unsafe { _mm512_storeu_pd(o.as_mut_ptr(), v) };
    }
}

/// [`crate::filter::Field::value_grad_in`] of a quadratic filter (support 3)
/// at 8 points at once under AVX-512, bitwise its result per lane (the
/// refract stage's gradients for the quadratic B-spline): lane `l`'s
/// neighbourhood starts at `data[base[l]]` and its fractional position on
/// axis `a` is `t[a][l]`; `poly[j]` is the kernel's weight polynomial `j`.
/// The scalar function's operations in its order, none fused: the weights
/// by Horner, each row's products summed over y and z, and its two-way
/// dot products `(0 + w₀r₀ + w₂r₂) + (0 + w₁r₁)`. One point at a time
/// (every filter but the cubics before this), the scalar loops were most
/// of the quadratic spline's refract stage.
///
/// # Safety
/// The CPU must have AVX-512F and F16C ([`Isa::Avx512`]), and every row
/// `base[l] + j·sy + k·sz .. + 4` (`j, k < 3`) must lie in `data`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,f16c")]
#[inline]
pub unsafe fn quadratic_value_grad_x8<T: Row4>(
    data: &[T],
    base: &[usize; 8],
    (sy, sz): (usize, usize),
    t: &[[f64; 8]; 3],
    poly: &[[f64; 3]; 3],
) -> ([f64; 8], [[f64; 8]; 3]) {
    use std::arch::x86_64::*;
    // SAFETY: each `[f64; 8]` is 64 readable bytes.
    let ld = |v: &[f64; 8]| unsafe { _mm512_loadu_pd(v.as_ptr()) };
    let zero = _mm512_setzero_pd();
    let (add, mul) = (|a, b| _mm512_add_pd(a, b), |a, b| _mm512_mul_pd(a, b));
    // `Kernel::weights_and_derivs`: `dv = dv·t + v`, `v = v·t + p[m]`.
    let mut w = [[zero; 3]; 3];
    let mut d = [[zero; 3]; 3];
    for a in 0..3 {
        let ta = ld(&t[a]);
        for j in 0..3 {
            let (mut v, mut dv) = (_mm512_set1_pd(poly[j][2]), zero);
            for m in (0..2).rev() {
                dv = add(mul(dv, ta), v);
                v = add(mul(v, ta), _mm512_set1_pd(poly[j][m]));
            }
            w[a][j] = v;
            d[a][j] = dv;
        }
    }
    let (mut rv, mut ry, mut rz) = ([zero; 3], [zero; 3], [zero; 3]);
    for k in 0..3 {
        for j in 0..3 {
            // SAFETY: rows in bounds (caller); AVX-512 (caller).
            let c = unsafe { rows4x8_regs::<T>(data.as_ptr().wrapping_add(j * sy + k * sz), base) };
            let (a, b, e) = (
                mul(w[1][j], w[2][k]),
                mul(d[1][j], w[2][k]),
                mul(w[1][j], d[2][k]),
            );
            for i in 0..3 {
                rv[i] = add(rv[i], mul(a, c[i]));
                ry[i] = add(ry[i], mul(b, c[i]));
                rz[i] = add(rz[i], mul(e, c[i]));
            }
        }
    }
    // `field::dot` for three terms.
    let dot = |x: &[__m512d; 3], r: &[__m512d; 3]| -> [f64; 8] {
        let even = add(add(zero, mul(x[0], r[0])), mul(x[2], r[2]));
        let odd = add(zero, mul(x[1], r[1]));
        // SAFETY: `__m512d` and `[f64; 8]` have the same size.
        unsafe { std::mem::transmute(add(even, odd)) }
    };
    (
        dot(&w[0], &rv),
        [dot(&d[0], &rv), dot(&w[0], &ry), dot(&w[0], &rz)],
    )
}

/// The safeguarded Newton iteration of
/// [`crate::roots::bernstein::refine_lanes`] for 8 lanes in AVX-512
/// registers, bitwise what its lane loop computes with fused multiply-adds:
/// every step's decision per lane (bracket update, Newton or bisection,
/// the stopping tests) becomes compares and masked moves over all lanes, so
/// a step's eight divisions are one vector division. `mono` holds the
/// monomial rows `0..=d`, `x` the start points, `lo_in` the lanes whose
/// segment starts inside (bit per lane) and `active` the lanes to refine;
/// the others return their start point after one evaluation's count.
///
/// # Safety
/// The CPU must have AVX-512F and FMA ([`Isa::Avx512`]); `d < mono.len()`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,fma")]
#[inline]
pub unsafe fn refine_x8(
    mono: &[[f64; 8]],
    d: usize,
    x: [f64; 8],
    lo_in: u8,
    active: u8,
    iters: usize,
) -> ([f64; 8], [u32; 8]) {
    use std::arch::x86_64::*;
    // SAFETY: each `[f64; 8]` is 64 readable bytes; rows `0..=d` exist.
    let row = |k: usize| unsafe { _mm512_loadu_pd(mono[k].as_ptr()) };
    // Horner for `g` and `g'` together, as the lane loop does.
    let eval = |x: __m512d| {
        let (mut v, mut dv) = (_mm512_setzero_pd(), _mm512_setzero_pd());
        for k in (0..=d).rev() {
            dv = _mm512_fmadd_pd(dv, x, v);
            v = _mm512_fmadd_pd(v, x, row(k));
        }
        (v, dv)
    };
    let zero = _mm512_setzero_pd();
    // SAFETY: 64 readable bytes.
    let mut x = unsafe { _mm512_loadu_pd(x.as_ptr()) };
    let (mut lo, mut hi) = (zero, _mm512_set1_pd(1.0));
    let (mut g, mut dg) = eval(x);
    let mut done: __mmask8 = !active;
    let mut evals = _mm512_set1_epi64(1);
    let one = _mm512_set1_epi64(1);
    for _ in 0..iters {
        let run = !done;
        let step = run & !_mm512_cmp_pd_mask::<_CMP_EQ_OQ>(g, zero);
        // `inside(g) == lo_in`: the bracket end at `x` moves up.
        let up = !(_mm512_cmp_pd_mask::<_CMP_GT_OQ>(g, zero) ^ lo_in);
        lo = _mm512_mask_mov_pd(lo, step & up, x);
        hi = _mm512_mask_mov_pd(hi, step & !up, x);
        let newton = _mm512_sub_pd(x, _mm512_div_pd(g, dg));
        let inside_bracket = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(newton, lo)
            & _mm512_cmp_pd_mask::<_CMP_LT_OQ>(newton, hi);
        let converged = _mm512_cmp_pd_mask::<_CMP_LT_OQ>(
            _mm512_abs_pd(_mm512_sub_pd(newton, x)),
            _mm512_set1_pd(1e-14),
        );
        let moves = step & !converged;
        let mid = _mm512_mul_pd(_mm512_set1_pd(0.5), _mm512_add_pd(lo, hi));
        let next = _mm512_mask_mov_pd(x, moves, _mm512_mask_blend_pd(inside_bracket, mid, newton));
        x = _mm512_mask_mov_pd(x, step & converged & inside_bracket, newton);
        // `next != x` (true for a NaN, as the lane loop's `==` is false).
        done = !(moves & _mm512_cmp_pd_mask::<_CMP_NEQ_UQ>(next, x));
        if done == 0xFF {
            break;
        }
        let (gn, dn) = eval(next);
        let run = !done;
        evals = _mm512_mask_add_epi64(evals, run, evals, one);
        let stalls = _mm512_cmp_pd_mask::<_CMP_GE_OQ>(_mm512_abs_pd(gn), _mm512_abs_pd(g))
            & _mm512_cmp_pd_mask::<_CMP_LT_OQ>(
                _mm512_abs_pd(_mm512_sub_pd(next, x)),
                _mm512_set1_pd(1e-9),
            );
        let take = run & !stalls;
        done = !take;
        x = _mm512_mask_mov_pd(x, take, next);
        g = _mm512_mask_mov_pd(g, take, gn);
        dg = _mm512_mask_mov_pd(dg, take, dn);
    }
    let (mut xs, mut es) = ([0.0f64; 8], [0i64; 8]);
    // SAFETY: 64 writable bytes each.
    unsafe {
        _mm512_storeu_pd(xs.as_mut_ptr(), x);
        _mm512_storeu_si512(es.as_mut_ptr().cast(), evals);
    }
    (xs, es.map(|e| e as u32))
}

/// [`rows4x8`] kept in registers.
///
/// # Safety
/// As [`rows4x8`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,f16c")]
#[inline]
unsafe fn rows4x8_regs<T: Row4>(
    ptr: *const T,
    idx: &[usize; 8],
) -> [std::arch::x86_64::__m512d; 4] {
    use std::arch::x86_64::*;
    // SAFETY: each row `ptr + idx[l] .. + 4` in bounds (caller).
    unsafe {
        let row = |l: usize| T::load4(ptr.add(idx[l]));
        let pair = |lo: usize, hi: usize| {
            _mm512_insertf64x4::<1>(_mm512_castpd256_pd512(row(lo)), row(hi))
        };
        let (z0, z1, z2, z3) = (pair(0, 2), pair(1, 3), pair(4, 6), pair(5, 7));
        let (ac0, bd0) = (_mm512_unpacklo_pd(z0, z1), _mm512_unpackhi_pd(z0, z1));
        let (ac1, bd1) = (_mm512_unpacklo_pd(z2, z3), _mm512_unpackhi_pd(z2, z3));
        [
            _mm512_shuffle_f64x2::<0x88>(ac0, ac1),
            _mm512_shuffle_f64x2::<0x88>(bd0, bd1),
            _mm512_shuffle_f64x2::<0xDD>(ac0, ac1),
            _mm512_shuffle_f64x2::<0xDD>(bd0, bd1),
        ]
    }
}

/// `[data[base[l] + off] for each lane l]`: one hardware gather for 8 lanes
/// (AVX-512) or 4 (AVX2), scalar loads otherwise.
///
/// # Safety
/// Every `base[l] + off` must be in bounds of `data`, and `L` must match the
/// running instruction set as [`with_isa!`] binds it (8 only under
/// [`Isa::Avx512`], 4 only under [`Isa::Avx2`] or better).
#[inline(always)]
pub unsafe fn gather<const L: usize>(data: &[f64], base: &[usize; L], off: usize) -> [f64; L] {
    debug_assert!(base.iter().all(|&b| b + off < data.len()));
    #[cfg(target_arch = "x86_64")]
    {
        let ptr = data.as_ptr().wrapping_add(off);
        if L == 8 {
            // SAFETY: L == 8 runs only under Isa::Avx512; indices in bounds.
            let v = unsafe { gather8(ptr, base.as_ptr()) };
            // SAFETY: L == 8, so [f64; 8] and [f64; L] are the same type.
            return unsafe { std::mem::transmute_copy(&v) };
        }
        if L == 4 {
            // SAFETY: L == 4 runs only under Isa::Avx2 or better.
            let v = unsafe { gather4(ptr, base.as_ptr()) };
            // SAFETY: as above, with 4.
            return unsafe { std::mem::transmute_copy(&v) };
        }
    }
    // SAFETY: the caller guarantees the indices are in bounds.
    std::array::from_fn(|l| unsafe { *data.get_unchecked(base[l] + off) })
}

/// Rows of four: `out[i][l] = data[base[l] + off + i]` as `f64` for
/// `i < 4`, each lane's row loaded as one vector (`f32` rows converted) and
/// the 4 × `L` block transposed in registers — the same values as four
/// [`gather`]s, in half the time where the rows are contiguous (the x-rows
/// of a cubic neighbourhood).
///
/// # Safety
/// As [`gather`], for every `base[l] + off + 3`.
#[inline(always)]
pub unsafe fn gather_rows4<T: Row4, const L: usize>(
    data: &[T],
    base: &[usize; L],
    off: usize,
) -> [[f64; L]; 4] {
    debug_assert!(base.iter().all(|&b| b + off + 3 < data.len()));
    #[cfg(target_arch = "x86_64")]
    {
        let ptr = data.as_ptr().wrapping_add(off);
        if L == 8 {
            // SAFETY: L == 8 runs only under Isa::Avx512; rows in bounds.
            let v = unsafe { rows4x8(ptr, base.as_ptr()) };
            // SAFETY: L == 8, so the types are the same.
            return unsafe { std::mem::transmute_copy(&v) };
        }
        if L == 4 {
            // SAFETY: L == 4 runs only under Isa::Avx2 or better.
            let v = unsafe { rows4x4(ptr, base.as_ptr()) };
            // SAFETY: as above, with 4.
            return unsafe { std::mem::transmute_copy(&v) };
        }
    }
    // SAFETY: the caller guarantees the indices are in bounds.
    std::array::from_fn(|i| {
        std::array::from_fn(|l| unsafe { *data.get_unchecked(base[l] + off + i) }.into())
    })
}

/// Storage [`gather_rows4`] reads: four contiguous values load as one
/// vector of four `f64`.
pub trait Row4: Copy + Into<f64> {
    /// # Safety
    /// `p .. p + 4` readable; the CPU has AVX.
    #[cfg(target_arch = "x86_64")]
    unsafe fn load4(p: *const Self) -> std::arch::x86_64::__m256d;
}

impl Row4 for f64 {
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn load4(p: *const f64) -> std::arch::x86_64::__m256d {
        // SAFETY: forwarded from the caller.
        unsafe { std::arch::x86_64::_mm256_loadu_pd(p) }
    }
}

impl Row4 for half::f16 {
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn load4(p: *const half::f16) -> std::arch::x86_64::__m256d {
        use std::arch::x86_64::{__m128i, _mm_loadl_epi64, _mm256_cvtps_pd};
        // SAFETY: forwarded from the caller; F16C comes with AVX2 on every
        // x86 CPU this runs its vector paths on (checked in `Isa::detect`).
        unsafe {
            let h = _mm_loadl_epi64(p as *const __m128i);
            _mm256_cvtps_pd(cvtph_ps(h))
        }
    }
}

/// Four `f16` (the low 64 bits of `h`) as `f32`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "f16c")]
#[inline]
unsafe fn cvtph_ps(h: std::arch::x86_64::__m128i) -> std::arch::x86_64::__m128 {
    std::arch::x86_64::_mm_cvtph_ps(h)
}

impl Row4 for f32 {
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn load4(p: *const f32) -> std::arch::x86_64::__m256d {
        use std::arch::x86_64::{_mm_loadu_ps, _mm256_cvtps_pd};
        // SAFETY: forwarded from the caller.
        unsafe { _mm256_cvtps_pd(_mm_loadu_ps(p)) }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,f16c")]
#[inline]
unsafe fn rows4x8<T: Row4>(ptr: *const T, idx: *const usize) -> [[f64; 8]; 4] {
    use std::arch::x86_64::*;
    // SAFETY: 8 indices at `idx`; each row `ptr + idx[l] .. + 4` in bounds.
    unsafe {
        let row = |l: usize| T::load4(ptr.add(*idx.add(l)));
        // Lanes (0, 2 | 1, 3) and (4, 6 | 5, 7) side by side, so the final
        // 128-bit shuffles put the lanes back in order.
        let pair = |lo: usize, hi: usize| {
            _mm512_insertf64x4::<1>(_mm512_castpd256_pd512(row(lo)), row(hi))
        };
        let (z0, z1, z2, z3) = (pair(0, 2), pair(1, 3), pair(4, 6), pair(5, 7));
        // (x0 x1)(z0 z1)(x2 x3)(z2 z3) for x = a, b and z = c, d.
        let (ac0, bd0) = (_mm512_unpacklo_pd(z0, z1), _mm512_unpackhi_pd(z0, z1));
        let (ac1, bd1) = (_mm512_unpacklo_pd(z2, z3), _mm512_unpackhi_pd(z2, z3));
        let a = _mm512_shuffle_f64x2::<0x88>(ac0, ac1);
        let c = _mm512_shuffle_f64x2::<0xDD>(ac0, ac1);
        let b = _mm512_shuffle_f64x2::<0x88>(bd0, bd1);
        let d = _mm512_shuffle_f64x2::<0xDD>(bd0, bd1);
        std::mem::transmute([a, b, c, d])
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,f16c")]
#[inline]
unsafe fn rows4x4<T: Row4>(ptr: *const T, idx: *const usize) -> [[f64; 4]; 4] {
    use std::arch::x86_64::*;
    // SAFETY: 4 indices at `idx`; each row `ptr + idx[l] .. + 4` in bounds.
    unsafe {
        let row = |l: usize| T::load4(ptr.add(*idx.add(l)));
        let (r0, r1, r2, r3) = (row(0), row(1), row(2), row(3));
        let (ac0, bd0) = (_mm256_unpacklo_pd(r0, r1), _mm256_unpackhi_pd(r0, r1));
        let (ac1, bd1) = (_mm256_unpacklo_pd(r2, r3), _mm256_unpackhi_pd(r2, r3));
        std::mem::transmute([
            _mm256_permute2f128_pd::<0x20>(ac0, ac1),
            _mm256_permute2f128_pd::<0x20>(bd0, bd1),
            _mm256_permute2f128_pd::<0x31>(ac0, ac1),
            _mm256_permute2f128_pd::<0x31>(bd0, bd1),
        ])
    }
}

/// Bit `l` set when `⌊x[l]⌋ + ⌊y[l]⌋` is odd (wrapping), each floor as
/// [`crate::filter::kernel::floor_fast`] gives it: NaN and `|v| ≥ 2⁶³` floor
/// to `i64::MIN`, an even number. Under AVX-512 (`L == 8`) two rounding
/// instructions, two conversions (whose out-of-range result is that same
/// `i64::MIN`) and an integer test. Otherwise (AVX2 has no packed
/// conversion to 64-bit integers) each coordinate's parity in floats,
/// `f - 2⌊f/2⌋` of `f = ⌊v⌋`: exact for every float (`|v| ≥ 2⁵³` is even),
/// with NaN and `|v| ≥ 2⁶³` counted even — the same bits.
///
/// # Safety
/// `L == 8` only where AVX-512 (F and DQ) is available, as inside
/// [`with_isa!`](crate::with_isa) under [`Isa::Avx512`].
#[inline(always)]
pub unsafe fn odd_floor_sum_mask<const L: usize>(x: &[f64; 8], y: &[f64; 8]) -> u8 {
    #[cfg(target_arch = "x86_64")]
    if L == 8 {
        // SAFETY: the caller runs L == 8 only with AVX-512.
        return unsafe { odd_floor_sum_mask8(x, y) };
    }
    let parity = |v: f64| {
        let f = v.floor();
        if f.abs() < 9.223_372_036_854_776e18 {
            f - 2.0 * (0.5 * f).floor()
        } else {
            0.0
        }
    };
    let mut mask = 0u8;
    for l in 0..8 {
        mask |= ((parity(x[l]) != parity(y[l])) as u8) << l;
    }
    mask
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq")]
#[inline]
unsafe fn odd_floor_sum_mask8(x: &[f64; 8], y: &[f64; 8]) -> u8 {
    use std::arch::x86_64::*;
    // SAFETY: both arrays hold 8 lanes; the features are enabled here.
    unsafe {
        let floor = |v: &[f64; 8]| {
            _mm512_cvttpd_epi64(_mm512_roundscale_pd::<
                { _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC },
            >(_mm512_loadu_pd(v.as_ptr())))
        };
        let sum = _mm512_add_epi64(floor(x), floor(y));
        _mm512_test_epi64_mask(sum, _mm512_set1_epi64(1))
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[inline]
unsafe fn gather8(ptr: *const f64, idx: *const usize) -> [f64; 8] {
    use std::arch::x86_64::*;
    // SAFETY: 8 indices at `idx`; each `ptr + idx[l]` in bounds (caller).
    unsafe {
        let i = _mm512_loadu_si512(idx as *const __m512i);
        std::mem::transmute(_mm512_i64gather_pd::<8>(i, ptr))
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn gather4(ptr: *const f64, idx: *const usize) -> [f64; 4] {
    use std::arch::x86_64::*;
    // SAFETY: 4 indices at `idx`; each `ptr + idx[l]` in bounds (caller).
    unsafe {
        let i = _mm256_loadu_si256(idx as *const __m256i);
        std::mem::transmute(_mm256_i64gather_pd::<8>(ptr, i))
    }
}

/// Asks the core to bring the cache line holding `x` towards L1 without
/// waiting for it (a hint: no effect on results, none off x86-64).
#[inline(always)]
pub fn prefetch<T>(x: &T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch never faults and reads nothing into the program;
    // `x` is a valid reference anyway.
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
            (x as *const T).cast::<i8>(),
        )
    };
    #[cfg(not(target_arch = "x86_64"))]
    let _ = x;
}

/// In a test of one instruction set's kernels: whether they `run` on this
/// CPU. When they do not, the test is skipped, and says so on stderr; with
/// `SNELL_REQUIRE_AVX512` set (CI sets it where the CPU reports AVX-512) it
/// fails instead, so a detection that wrongly turned the wide kernels off
/// cannot pass for a test that checked them.
#[cfg(test)]
pub(crate) fn kernels_run(what: &str, run: bool) -> bool {
    if !run {
        assert!(
            crate::env::setting("SNELL_REQUIRE_AVX512").is_none(),
            "{what}: cannot run on this CPU (or under SNELL_ISA), and SNELL_REQUIRE_AVX512 asks for it"
        );
        eprintln!("skipped: {what} cannot run on this CPU (or under SNELL_ISA)");
    }
    run
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `SNELL_ISA` lowers the level; an unknown name or a level above the
    /// CPU's is ignored with a reason (the caller's warning).
    #[test]
    fn snell_isa_lowers_the_level_or_says_why_not() {
        use Isa::*;
        assert_eq!(Isa::chosen(Avx512, None), (Avx512, None));
        assert_eq!(Isa::chosen(Avx512, Some("avx2")), (Avx2, None));
        assert_eq!(Isa::chosen(Avx2, Some("portable")), (Portable, None));
        assert_eq!(Isa::chosen(Avx2, Some("avx2")), (Avx2, None));
        let (isa, why) = Isa::chosen(Avx2, Some("avx512"));
        assert_eq!(isa, Avx2);
        assert_eq!(why.unwrap(), "this CPU cannot run avx512; using avx2+fma");
        let (isa, why) = Isa::chosen(Avx512, Some("sse"));
        assert_eq!(isa, Avx512);
        assert_eq!(
            why.unwrap(),
            "expected avx512, avx2 or portable, got 'sse'; using avx512"
        );
    }

    #[test]
    fn row_loads_equal_gathers_on_every_isa() {
        let data: Vec<f64> = (0..500)
            .map(|i| (i as f64 * 0.37).sin() * 1e3 + i as f64)
            .collect();
        let base = [17usize, 3, 240, 99, 0, 401, 55, 312];
        for isa in Isa::available() {
            let (rows, gathered) = with_isa!(isa, L, M => {
                let _ = M::madd(0.0, 0.0, 0.0);
                let b: [usize; L] = std::array::from_fn(|l| base[l]);
                // SAFETY: every index + 3 + 9 < 500; L bound by with_isa!.
                let rows = unsafe { gather_rows4::<f64, L>(&data, &b, 9) };
                let g: [[f64; L]; 4] = std::array::from_fn(|i| unsafe { gather::<L>(&data, &b, 9 + i) });
                (rows.iter().flatten().copied().collect::<Vec<_>>(), g.iter().flatten().copied().collect::<Vec<_>>())
            });
            assert_eq!(rows, gathered, "{isa:?}");
            assert_eq!(rows[0], data[base[0] + 9]);
            // f32 rows convert exactly.
            let narrow: Vec<f32> = data.iter().map(|&v| v as f32).collect();
            let rows32 = with_isa!(isa, L, M => {
                let _ = M::madd(0.0, 0.0, 0.0);
                let b: [usize; L] = std::array::from_fn(|l| base[l]);
                // SAFETY: as above.
                let rows = unsafe { gather_rows4::<f32, L>(&narrow, &b, 9) };
                rows.iter().flatten().copied().collect::<Vec<_>>()
            });
            let want: Vec<f64> = gathered.iter().map(|&v| v as f32 as f64).collect();
            assert_eq!(rows32, want, "{isa:?} f32");
        }
    }

    #[test]
    fn dispatch_runs_on_this_cpu() {
        let isa = Isa::current();
        let (lanes, v) = with_isa!(isa, L, M => (L, M::madd(2.0, 3.0, 1.0)));
        assert_eq!(lanes, isa.lanes());
        assert_eq!(v, 7.0);
    }
}
