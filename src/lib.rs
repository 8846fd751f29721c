//! snell: refraction through iso-surfaces of sampled volumes, after Li & Mueller,
//! "Accelerated, High-Quality Refraction Computations for Volume Graphics".

pub mod filter;
pub mod volume;
