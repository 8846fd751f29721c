//! Brent's method: inverse quadratic interpolation and secant steps guarded by
//! bisection, so it converges superlinearly on smooth functions and never
//! leaves its bracket.

use super::inside;

/// Outcome of a bracketed solve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Root {
    /// Abscissa of the sign change, within `tol` of the true one.
    pub x: f64,
    /// Function evaluations spent (the two end values are given, not counted).
    pub evals: u32,
}

/// Finds a sign change of `f` in `[a, b]` given `fa = f(a)` and `fb = f(b)` on
/// opposite sides (by [`inside`]). Returns the point where the side changes,
/// to within `tol` (absolute, in `x` units), on its inside side once the
/// bracket is that narrow. Never evaluates outside `[a, b]`.
pub fn solve(mut f: impl FnMut(f64) -> f64, a: f64, b: f64, fa: f64, fb: f64, tol: f64) -> Root {
    debug_assert!(inside(fa) != inside(fb), "Brent needs a bracket");
    // Work on h = f made strictly signed: values <= 0 count as outside, so
    // shift zeros to a tiny negative to keep the bracket logic strict.
    let side = |v: f64| {
        if inside(v) {
            v
        } else {
            v.min(-f64::MIN_POSITIVE)
        }
    };
    let (mut a, mut b) = (a, b);
    let (mut fa, mut fb) = (side(fa), side(fb));
    let mut c = a;
    let mut fc = fa;
    let mut d = b - a;
    let mut e = d;
    let mut evals = 0u32;
    for _ in 0..200 {
        if (fb > 0.0) == (fc > 0.0) {
            c = a;
            fc = fa;
            d = b - a;
            e = d;
        }
        if fc.abs() < fb.abs() {
            a = b;
            b = c;
            c = a;
            fa = fb;
            fb = fc;
            fc = fa;
        }
        let tol1 = 2.0 * f64::EPSILON * b.abs() + 0.5 * tol;
        let xm = 0.5 * (c - b);
        if xm.abs() <= tol1 {
            break;
        }
        if e.abs() >= tol1 && fa.abs() > fb.abs() {
            let s = fb / fa;
            let (mut p, mut q);
            if a == c {
                p = 2.0 * xm * s;
                q = 1.0 - s;
            } else {
                let qq = fa / fc;
                let r = fb / fc;
                p = s * (2.0 * xm * qq * (qq - r) - (b - a) * (r - 1.0));
                q = (qq - 1.0) * (r - 1.0) * (s - 1.0);
            }
            if p > 0.0 {
                q = -q;
            }
            p = p.abs();
            let min1 = 3.0 * xm * q - (tol1 * q).abs();
            let min2 = (e * q).abs();
            if 2.0 * p < min1.min(min2) {
                e = d;
                d = p / q;
            } else {
                d = xm;
                e = d;
            }
        } else {
            d = xm;
            e = d;
        }
        a = b;
        fa = fb;
        b += if d.abs() > tol1 { d } else { tol1.copysign(xm) };
        fb = side(f(b));
        evals += 1;
    }
    // `b` and `c` bracket the change within tol: report the end on the
    // inside (f > iso). Where the outside is a plateau at exactly the
    // iso-value (a scan's flat background, under the linear filter) the
    // field's gradient is zero there, and the plateau's side would give the
    // refraction a degenerate normal; the inside's side is where the field
    // rises, whose gradient is the surface's.
    let x = if (c - b).abs() <= tol {
        if fb > 0.0 { b } else { c }
    } else {
        b
    };
    Root { x, evals }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_simple_roots() {
        let r = solve(|x| x * x - 2.0, 0.0, 2.0, -2.0, 2.0, 1e-12);
        assert!((r.x - 2f64.sqrt()).abs() < 1e-11, "{r:?}");
        assert!(r.evals < 20, "{r:?}");
        let r = solve(|x| (x - 0.3).powi(3), 0.0, 1.0, -0.027, 0.343, 1e-10);
        assert!((r.x - 0.3).abs() < 1e-9, "{r:?}");
    }

    #[test]
    fn stays_in_bracket_and_handles_zero_ends() {
        // f(a) = 0 counts as outside; the change is where f becomes positive.
        let r = solve(|x| x - 0.5, 0.5, 1.0, 0.0, 0.5, 1e-12);
        assert!(
            (0.5..=1.0).contains(&r.x) && (r.x - 0.5).abs() < 1e-11,
            "{r:?}"
        );
        // A step function: converges to the jump by bisection.
        let r = solve(
            |x| if x > 0.7 { 1.0 } else { -1.0 },
            0.0,
            1.0,
            -1.0,
            1.0,
            1e-9,
        );
        assert!((r.x - 0.7).abs() < 2e-9, "{r:?}");
    }

    /// Beside a plateau at exactly the iso-value the root is reported on
    /// the rising side, entering or leaving: never on the plateau, whose
    /// gradient is zero.
    #[test]
    fn plateau_ends_are_reported_on_the_inside() {
        let rise = |x: f64| (x - 0.6).max(0.0);
        let fall = |x: f64| (0.4 - x).max(0.0);
        for tol in [1e-3, 1e-9, 1e-14] {
            let r = solve(rise, 0.0, 1.0, 0.0, 0.4, tol);
            assert!(rise(r.x) > 0.0 && r.x - 0.6 <= tol, "{tol}: {r:?}");
            let r = solve(fall, 0.0, 1.0, 0.4, 0.0, tol);
            assert!(fall(r.x) > 0.0 && 0.4 - r.x <= tol, "{tol}: {r:?}");
        }
    }
}
