//! (to be written)
use std::path::Path;
use super::{LoadOptions, Volume, VolumeError};
#[allow(unused)]
pub fn read(path: &Path, opts: &LoadOptions) -> Result<Volume, VolumeError> {
    Err(VolumeError::unsupported(path, "nifti reader not written yet"))
}
