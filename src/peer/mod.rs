//! Peers: other renderers that draw the same scene, for fair comparisons of
//! run time and accuracy against snell.
//!
//! [`povray`] drives POV-Ray 3.7 (`isosurface` over a `density_file df3`,
//! glass `interior { ior }`); [`df3`] writes the volume in POV-Ray's density
//! file format and bounds the gradient POV-Ray's root finder needs. The
//! geometry mapping (camera, axes, backdrop, iso scaling) is exact up to
//! floating-point rounding and the 16-bit quantisation documented in
//! [`df3::Df3Mapping`]; see [`povray`] for the scene side and what POV-Ray
//! itself approximates.

pub mod df3;
pub mod povray;

use std::path::PathBuf;

pub use df3::{
    Df3Mapping, Interpolation, gradient_safety, max_gradient, max_gradient_sampled, read_df3,
    write_df3,
};
pub use povray::{
    HitEncoding, PeerRun, PovExport, PovOptions, PovStats, RenderRun, Variant, decode_hits, export,
    installed, parse_stats, pov_source, render, run, run_with, write_pov,
};

/// What can go wrong exporting a scene to a peer or running it.
#[derive(Debug, thiserror::Error)]
pub enum PeerError {
    #[error(
        "povray is not installed (no `povray` on PATH); install it with `apt-get install povray`"
    )]
    NotInstalled,
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: {msg}")]
    Format { path: PathBuf, msg: String },
    #[error("{0}")]
    Unsupported(String),
    #[error("{0}")]
    Invalid(String),
    #[error("povray {variant} render failed ({status}): {msg}")]
    Failed {
        variant: &'static str,
        status: String,
        msg: String,
    },
    #[error(transparent)]
    Scene(#[from] crate::scene::SceneError),
}

impl PeerError {
    pub(crate) fn io(path: &std::path::Path, source: std::io::Error) -> PeerError {
        PeerError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}
