//! Which cells can hold the iso-surface.
//!
//! [`bound`] gives a conservative value range of the field over one knot cell
//! from its coefficients alone — used on the fly by DDA when no classification
//! was precomputed.

pub mod bound;

pub use bound::CellBound;
