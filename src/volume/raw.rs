//! (to be written)
use std::path::Path;
use super::{LoadOptions, Volume, VolumeError};
#[allow(unused)]
pub fn read(path: &Path, spec: &super::RawSpec, opts: &LoadOptions) -> Result<Volume, VolumeError> {
    Err(VolumeError::unsupported(path, "raw reader not written yet"))
}
