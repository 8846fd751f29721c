//! Reconstruction filters: from samples to a continuous field `f(x)` with an
//! analytic gradient.
//!
//! - [`kernel`]: the kernels as tables of weight polynomials per knot cell;
//! - [`prefilter`]: exact recursive prefiltering (interpolating and smoothing
//!   B-splines);
//! - [`coeffs`]: the padded coefficient grid with a mirrored apron;
//! - [`field`]: evaluation of value and gradient at points;
//! - [`resample`]: the field sampled on a new lattice (upsampled scans).
//!
//! Names follow SPEC.md: `linear`, `catmull-rom`, `bspline2`..`bspline7`,
//! `smooth-bspline3` (with `λ ≥ 0`).

pub mod coeffs;
pub mod field;
pub mod kernel;
pub mod prefilter;
pub mod resample;
pub mod restrict;

use std::fmt;

pub use coeffs::Coeffs;
pub use field::Field;
pub use kernel::Kernel;
pub use prefilter::Prefilter;

/// Every filter the command line and scenes accept, in the order reports list them.
pub const FILTER_NAMES: [&str; 9] = [
    "linear",
    "catmull-rom",
    "bspline2",
    "bspline3",
    "bspline4",
    "bspline5",
    "bspline6",
    "bspline7",
    "smooth-bspline3",
];

/// The filters whose coefficients are prefiltered (the B-splines), in
/// [`FILTER_NAMES`]' order.
pub const PREFILTERED_NAMES: [&str; 7] = [
    "bspline2",
    "bspline3",
    "bspline4",
    "bspline5",
    "bspline6",
    "bspline7",
    "smooth-bspline3",
];

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FilterError {
    #[error(
        "unknown filter '{0}' (expected one of: linear (or trilinear, bspline1), catmull-rom, bspline2 .. bspline7, smooth-bspline3)"
    )]
    Unknown(String),
    #[error(
        "the smoothing weight λ must be a number from 0 to 1e12, got {}",
        crate::human::num(*.0)
    )]
    BadLambda(f64),
    #[error("smooth-bspline3 needs λ, {LAMBDA_HELP}")]
    NeedsLambda,
}

/// What the smoothing spline's `λ` is and which values to give, for every
/// message that asks for it (the scene's `lambda`, the CLI's `--lambda`).
pub const LAMBDA_HELP: &str =
    "its smoothing weight (0 to 1e12; 1 smooths away u8 rounding noise, 0 is bspline3)";

/// The largest smoothing `λ` accepted. Far below it the smoothing spline is
/// already flat (at `λ = 1e6` the 32³ sphere phantom reconstructs to its mean
/// within 1e-4, at 1e12 within 1e-10, its gradient 1e-12); above about 1e15
/// its poles are so close to the unit circle that the prefilter's sums
/// overflow to NaN.
pub const MAX_LAMBDA: f64 = 1e12;

/// Which reconstruction filter, with its parameter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FilterKind {
    /// Trilinear (the B-spline of degree 1).
    Linear,
    /// Keys' cubic convolution, `a = -0.5`.
    CatmullRom,
    /// Interpolating B-spline of degree 2..=7 (prefiltered).
    BSpline(u8),
    /// Cubic smoothing B-spline with its `λ`.
    SmoothBSpline3 { lambda: f64 },
}

impl FilterKind {
    /// Parses a SPEC.md filter name; `lambda` is used by `smooth-bspline3` only
    /// but must be valid for every filter (a scene may switch filters with
    /// `--set`).
    pub fn parse(name: &str, lambda: f64) -> Result<FilterKind, FilterError> {
        if !(0.0..=MAX_LAMBDA).contains(&lambda) {
            return Err(FilterError::BadLambda(lambda));
        }
        let kind = match name.trim().to_ascii_lowercase().as_str() {
            "linear" | "trilinear" | "bspline1" => FilterKind::Linear,
            "catmull-rom" | "catmullrom" | "cubic-convolution" => FilterKind::CatmullRom,
            "smooth-bspline3" => FilterKind::SmoothBSpline3 { lambda },
            other => match other
                .strip_prefix("bspline")
                .and_then(|d| d.parse::<u8>().ok())
            {
                Some(d @ 2..=7) => FilterKind::BSpline(d),
                _ => return Err(FilterError::Unknown(name.to_string())),
            },
        };
        Ok(kind)
    }

    /// Parses a filter name with its smoothing weight as written: `λ` is
    /// checked when given, and required by `smooth-bspline3` (there is no
    /// default weight: 0 would silently be `bspline3`). A `λ` given with a
    /// filter that does not smooth is not an error here; the caller says
    /// whether it is ([`FilterKind::smooths`]).
    pub fn with_lambda(name: &str, lambda: Option<f64>) -> Result<FilterKind, FilterError> {
        let kind = FilterKind::parse(name, 0.0)?;
        if let Some(l) = lambda
            && !(0.0..=MAX_LAMBDA).contains(&l)
        {
            return Err(FilterError::BadLambda(l));
        }
        match (kind, lambda) {
            (FilterKind::SmoothBSpline3 { .. }, None) => Err(FilterError::NeedsLambda),
            (FilterKind::SmoothBSpline3 { .. }, Some(lambda)) => {
                Ok(FilterKind::SmoothBSpline3 { lambda })
            }
            (kind, _) => Ok(kind),
        }
    }

    /// Whether the filter has a smoothing weight (`smooth-bspline3`).
    pub fn smooths(&self) -> bool {
        matches!(self, FilterKind::SmoothBSpline3 { .. })
    }

    /// The SPEC.md name.
    pub fn name(&self) -> String {
        match self {
            FilterKind::Linear => "linear".into(),
            FilterKind::CatmullRom => "catmull-rom".into(),
            FilterKind::BSpline(d) => format!("bspline{d}"),
            FilterKind::SmoothBSpline3 { .. } => "smooth-bspline3".into(),
        }
    }

    /// `λ` for the smoothing spline, 0 otherwise.
    pub fn lambda(&self) -> f64 {
        match self {
            FilterKind::SmoothBSpline3 { lambda } => *lambda,
            _ => 0.0,
        }
    }

    pub fn kernel(&self) -> Kernel {
        match self {
            FilterKind::Linear => Kernel::bspline(1),
            FilterKind::CatmullRom => Kernel::catmull_rom(),
            FilterKind::BSpline(d) => Kernel::bspline(*d as usize),
            FilterKind::SmoothBSpline3 { .. } => Kernel::bspline(3),
        }
    }

    pub fn prefilter(&self) -> Prefilter {
        match self {
            FilterKind::Linear | FilterKind::CatmullRom => Prefilter::identity(),
            FilterKind::BSpline(d) => Prefilter::bspline(*d as usize),
            FilterKind::SmoothBSpline3 { lambda } => Prefilter::smoothing_cubic(*lambda),
        }
    }

    /// Stable key for caches: name plus the exact bits of λ.
    pub fn cache_key(&self) -> String {
        format!("{}-{:016x}", self.name(), self.lambda().to_bits())
    }
}

impl fmt::Display for FilterKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FilterKind::SmoothBSpline3 { lambda } => write!(f, "smooth-bspline3(λ={lambda})"),
            other => f.write_str(&other.name()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The prefiltered list is exactly the filters (in their order) whose
    /// prefilter does something, at the λ the benches parse them with.
    #[test]
    fn prefiltered_names_are_the_filters_with_a_prefilter() {
        let prefiltered: Vec<&str> = FILTER_NAMES
            .into_iter()
            .filter(|n| !FilterKind::parse(n, 1.0).unwrap().prefilter().is_identity())
            .collect();
        assert_eq!(prefiltered, PREFILTERED_NAMES);
    }

    #[test]
    fn parses_spec_names() {
        assert_eq!(FilterKind::parse("linear", 0.0), Ok(FilterKind::Linear));
        assert_eq!(
            FilterKind::parse("catmull-rom", 0.0),
            Ok(FilterKind::CatmullRom)
        );
        for d in 2..=7u8 {
            assert_eq!(
                FilterKind::parse(&format!("bspline{d}"), 0.0),
                Ok(FilterKind::BSpline(d))
            );
        }
        assert_eq!(
            FilterKind::parse("smooth-bspline3", 1.0),
            Ok(FilterKind::SmoothBSpline3 { lambda: 1.0 })
        );
        assert!(matches!(
            FilterKind::parse("bspline8", 0.0),
            Err(FilterError::Unknown(_))
        ));
        assert!(matches!(
            FilterKind::parse("gauss", 0.0),
            Err(FilterError::Unknown(_))
        ));
        assert_eq!(
            FilterKind::parse("smooth-bspline3", -1.0),
            Err(FilterError::BadLambda(-1.0))
        );
        assert!(FilterKind::parse("linear", f64::NAN).is_err());
    }

    /// The smoothing spline has no default weight; a weight is checked
    /// whenever it is given, and unknown names are reported first.
    #[test]
    fn with_lambda_requires_and_checks_the_weight() {
        assert_eq!(
            FilterKind::with_lambda("smooth-bspline3", None),
            Err(FilterError::NeedsLambda)
        );
        assert_eq!(
            FilterKind::with_lambda("smooth-bspline3", Some(0.5)),
            Ok(FilterKind::SmoothBSpline3 { lambda: 0.5 })
        );
        assert_eq!(
            FilterKind::with_lambda("bspline3", Some(-1.0)),
            Err(FilterError::BadLambda(-1.0))
        );
        assert_eq!(
            FilterKind::with_lambda("bspline3", Some(2.0)),
            Ok(FilterKind::BSpline(3))
        );
        assert_eq!(
            FilterKind::with_lambda("bspline3", None),
            Ok(FilterKind::BSpline(3))
        );
        assert!(matches!(
            FilterKind::with_lambda("gauss", Some(-1.0)),
            Err(FilterError::Unknown(_))
        ));
        assert!(FilterKind::SmoothBSpline3 { lambda: 0.0 }.smooths());
        assert!(!FilterKind::Linear.smooths());
    }
}
