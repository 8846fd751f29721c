//! Numbers in messages and text reports.
//!
//! [`num`] is for people: at most 7 significant digits, scientific notation
//! for very large and very small magnitudes, so a value range of f32 noise
//! does not print 45 digits. [`exact`] is for machine output (CSV): the
//! shortest text that reads back to the same `f64`, in scientific notation
//! at the extremes instead of Rust's positional `{}` (which writes 1e-20 as
//! 22 characters and 1e300 as 301). JSON goes through `serde_json`, which
//! already writes the shortest round trip.

/// `x` for people: up to 7 significant digits without trailing zeros,
/// positional from 1e-4 to below 1e7, scientific beyond (`1.523944e-29`,
/// `1e308`); `inf`, `-inf`, `NaN` as such.
pub fn num(x: f64) -> String {
    significant(x, 7, 1e-4..1e7)
}

/// `x` as [`num`] writes it, with more significant digits (up to 17) where
/// 7 would not tell apart values `step` apart: the values of a volume
/// whose range is narrow beside their magnitude (labels near 1234566, a
/// pressure of 101325 ± 1) print as themselves, not all alike.
pub fn num_resolving(x: f64, step: f64) -> String {
    let digits = if x.is_finite() && x != 0.0 && step.is_finite() && step > 0.0 {
        let needed = x.abs().log10().floor() - step.log10().floor() + 1.0;
        needed.clamp(7.0, 17.0) as usize
    } else {
        7
    };
    if digits == 7 {
        num(x)
    } else {
        significant(x, digits, 1e-4..10f64.powi(digits as i32))
    }
}

/// `x` to 4 significant digits for tables of measurements: positional
/// from 1e-3 to below 1e6 without trailing zeros (`0.2718`, `6.391`,
/// `2072`), scientific beyond (`1.526e-5`); `0`, `inf`, `NaN` as such.
pub fn sig4(x: f64) -> String {
    significant(x, 4, 1e-3..1e6)
}

/// `x` to `digits` significant digits without trailing zeros, positional
/// when its rounded magnitude lies in `positional`, scientific otherwise.
/// Rounded first, so 999.96 at 4 digits counts as the 1000 it prints as
/// and 9999999.6 at 7 as the `1e7` beyond the positional range.
fn significant(x: f64, digits: usize, positional: std::ops::Range<f64>) -> String {
    if !x.is_finite() {
        return x.to_string();
    }
    if x == 0.0 {
        return "0".into();
    }
    let prec = digits - 1;
    let sci = format!("{x:.prec$e}");
    let rounded: f64 = sci.parse().unwrap_or(x);
    if positional.contains(&rounded.abs()) {
        let exp = rounded.abs().log10().floor() as i32;
        let decimals = (prec as i32 - exp).max(0) as usize;
        return trim_fraction(&format!("{rounded:.decimals$}"));
    }
    match sci.split_once('e') {
        Some((mantissa, exp)) => format!("{}e{exp}", trim_fraction(mantissa)),
        None => sci,
    }
}

/// `n` and its noun, plural but for one: `1 part`, `3 parts`.
pub fn count(n: usize, noun: &str) -> String {
    match n {
        1 => format!("1 {noun}"),
        n => format!("{n} {noun}s"),
    }
}

/// Three numbers as `a x b x c` with [`num`].
pub fn triple(v: [f64; 3]) -> String {
    format!("{} x {} x {}", num(v[0]), num(v[1]), num(v[2]))
}

/// `s` as one word for a POSIX shell: as it is where it holds only
/// characters no shell treats specially, else in single quotes (for the
/// commands snell prints for people to paste).
pub fn shell_quote(s: &str) -> String {
    let plain = !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "._/+-,=:@%".contains(c));
    if plain {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', "'\\''"))
    }
}

/// `x` for machine output: the shortest text that parses back to the same
/// `f64`, positional from 1e-5 to below 1e16, scientific beyond.
pub fn exact(x: f64) -> String {
    let mag = x.abs();
    if !x.is_finite() || x == 0.0 || (1e-5..1e16).contains(&mag) {
        x.to_string()
    } else {
        format!("{x:e}")
    }
}

fn trim_fraction(s: &str) -> String {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn num_resolving_tells_close_values_apart() {
        assert_eq!(num_resolving(1234566.5, 1e-3), "1234566.5");
        assert_eq!(num_resolving(1234567.0, 1e-3), "1234567");
        assert_eq!(num_resolving(16777216.5, 1e-3), "16777216.5");
        assert_eq!(num_resolving(101325.25, 1e-4), "101325.25");
        // Where 7 digits resolve the step, as num writes it.
        assert_eq!(num_resolving(127.5, 0.255), num(127.5));
        assert_eq!(num_resolving(1.5e-30, 1e-33), num(1.5e-30));
        assert_eq!(num_resolving(5.0, 0.0), "5");
        assert_eq!(num_resolving(f64::NAN, 1.0), "NaN");
    }

    #[test]
    fn sig4_keeps_four_digits() {
        for (x, want) in [
            (0.0, "0"),
            (0.27183, "0.2718"),
            (6.3914, "6.391"),
            (2072.4, "2072"),
            (999.96, "1000"),
            (0.5, "0.5"),
            (1.526e-5, "1.526e-5"),
            (-3.2741e4, "-32740"),
            (1.5e6, "1.5e6"),
            (-1.52649e-5, "-1.526e-5"),
            (f64::NAN, "NaN"),
        ] {
            assert_eq!(sig4(x), want, "{x}");
        }
    }

    #[test]
    fn people_get_seven_digits_and_scientific_extremes() {
        assert_eq!(num(0.0), "0");
        assert_eq!(num(1.0), "1");
        assert_eq!(num(-2.5), "-2.5");
        assert_eq!(num(31474.366056460993), "31474.37");
        assert_eq!(num(0.1 + 0.2), "0.3");
        assert_eq!(num(1.5239444297167634e-29), "1.523944e-29");
        assert_eq!(num(-3.848773152033876e-15), "-3.848773e-15");
        assert_eq!(num(1e308), "1e308");
        assert_eq!(num(12345678.0), "1.234568e7");
        assert_eq!(num(9999999.6), "1e7");
        assert_eq!(num(9999999.4), "9999999");
        assert_eq!(num(0.00012345678), "0.0001234568");
        assert_eq!(num(f64::INFINITY), "inf");
        assert_eq!(num(f64::NAN), "NaN");
        assert_eq!(triple([1.0, 0.5, 2.0]), "1 x 0.5 x 2");
    }

    #[test]
    fn machine_output_round_trips() {
        for x in [
            -3.848773152033876e-15,
            1.5239444297167634e-29,
            0.1,
            31474.366056460993,
            1e300,
            123.0,
            -0.0,
            f64::MIN_POSITIVE,
        ] {
            let s = exact(x);
            assert_eq!(s.parse::<f64>().unwrap().to_bits(), x.to_bits(), "{s}");
            assert!(s.len() <= 24, "{s}");
        }
        assert_eq!(exact(-3.848773152033876e-15), "-3.848773152033876e-15");
        assert_eq!(exact(0.5), "0.5");
    }
}
