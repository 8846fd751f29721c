//! Root finding for iso-surface crossings.
//!
//! - [`brent`]: Brent's method (Brent 1973) on a bracketing interval, as the
//!   paper uses for higher-order filters;
//! - [`bernstein`]: certified isolation of the sign changes of a polynomial on
//!   `[0, 1]` by its Bernstein coefficients (convex hull + Descartes' rule of
//!   signs), so a crossing inside a cell is never lost, even two close ones at a
//!   silhouette.
//!
//! Sign convention, shared by every stage: a value is *inside* (`+`) when
//! `f - iso > 0` and *outside* (`-`) otherwise, so touching the iso-value
//! from below without exceeding it is not a crossing.

pub mod bernstein;
pub mod brent;

/// Inside (`true`) when `g = f - iso > 0`.
#[inline(always)]
pub fn inside(g: f64) -> bool {
    g > 0.0
}
