//! snell: refraction through iso-surfaces of sampled volumes, after Li & Mueller,
//! "Accelerated, High-Quality Refraction Computations for Volume Graphics".
//!
//! The pipeline, module by module: [`volume`] (samples and readers) →
//! [`filter`] (prefilter, continuous field) → [`classify`] and [`lattice`]
//! (which cells can hold the surface) → [`render`] (rays as SoA packets per
//! tile through staged queues: generate, entry, traverse, solve, refract,
//! record) → [`film`] (hit positions and colours).
//! [`reference`](mod@reference) and [`compare`] measure accuracy against
//! exact ground truth.

// Hot loops index several structure-of-arrays columns by the same lane index;
// an iterator over one of them would hide that symmetry.
#![allow(clippy::needless_range_loop)]
// These docs are read with the private items (`cargo doc
// --document-private-items`, as CI builds them, warnings denied): the stages'
// internals are the point, so public items link into them.
#![allow(rustdoc::private_intra_doc_links)]

pub mod atomic;
pub mod bench;
pub mod classify;
pub mod compare;
pub mod env;
pub mod film;
pub mod filter;
pub mod heap;
pub mod human;
pub mod input;
pub mod lattice;
pub mod octree;
pub mod peer;
pub mod phantom;
pub mod prepare;
pub mod reference;
pub mod render;
pub mod roots;
pub mod scene;
pub mod simd;
pub mod volume;
