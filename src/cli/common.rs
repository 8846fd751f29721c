//! Options and helpers shared by several subcommands.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::Args;

use snell::volume::{self, Endian, LoadOptions, RawSpec, SampleType, Volume, limits};

/// How to read a volume file (raw files need their layout spelled out).
#[derive(Args, Debug, Clone, Default)]
pub struct VolumeArgs {
    /// Dimensions of a headerless raw file: X,Y,Z.
    #[arg(long, value_name = "X,Y,Z")]
    pub dims: Option<String>,
    /// Sample type of a raw file: u8, i8, u16, i16, u32, i32, f32, f64.
    #[arg(long = "type", value_name = "TYPE")]
    pub sample_type: Option<String>,
    /// Byte order of a raw file.
    #[arg(long, default_value = "little", value_name = "little|big")]
    pub endian: String,
    /// Voxel spacing X,Y,Z (overrides the file's own).
    #[arg(long, value_name = "X,Y,Z")]
    pub spacing: Option<String>,
    /// Bytes to skip at the start of a raw file.
    #[arg(long, default_value_t = 0)]
    pub offset: u64,
    /// Replace NaN/infinite samples in float data instead of rejecting the file.
    #[arg(long)]
    pub allow_nan: bool,
    /// Largest working set to allow, e.g. 8G (default: 80% of available memory).
    #[arg(long, value_name = "BYTES")]
    pub memory_limit: Option<String>,
}

/// Parses `a,b,c` into three values.
pub fn triple<T: std::str::FromStr>(s: &str, what: &str) -> anyhow::Result<[T; 3]> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        bail!("{what} must be three comma-separated values, got '{s}'");
    }
    let mut out = Vec::with_capacity(3);
    for p in parts {
        out.push(
            p.parse::<T>()
                .map_err(|_| anyhow::anyhow!("{what}: '{p}' is not a valid number"))?,
        );
    }
    match out.try_into() {
        Ok(a) => Ok(a),
        Err(_) => unreachable!("three values"),
    }
}

impl VolumeArgs {
    pub fn load_options(&self) -> anyhow::Result<LoadOptions> {
        let memory_limit = match &self.memory_limit {
            Some(s) => limits::parse_bytes(s)
                .with_context(|| format!("--memory-limit: '{s}' is not a size like 512M or 8G"))?,
            None => limits::default_memory_limit(),
        };
        let spacing = match &self.spacing {
            Some(s) => Some(triple::<f64>(s, "--spacing")?),
            None => None,
        };
        let raw = match (&self.dims, &self.sample_type) {
            (None, None) => None,
            (Some(d), Some(t)) => Some(RawSpec {
                dims: triple::<usize>(d, "--dims")?,
                sample_type: SampleType::parse(t).with_context(|| {
                    format!(
                        "--type: unknown sample type '{t}' (u8, i8, u16, i16, u32, i32, f32, f64)"
                    )
                })?,
                endian: Endian::parse(&self.endian).with_context(|| {
                    format!("--endian: expected little or big, got '{}'", self.endian)
                })?,
                spacing: spacing.unwrap_or([1.0; 3]),
                offset: self.offset,
            }),
            _ => bail!("a raw volume needs both --dims and --type"),
        };
        Ok(LoadOptions {
            allow_nan: self.allow_nan,
            memory_limit,
            raw,
        })
    }

    pub fn load(&self, path: &Path) -> anyhow::Result<Volume> {
        self.load_with(path, &self.load_options()?)
    }

    /// [`VolumeArgs::load`] with options already taken from the arguments.
    pub fn load_with(&self, path: &Path, opts: &LoadOptions) -> anyhow::Result<Volume> {
        let mut vol = volume::load(path, opts)?;
        if vol.replaced_nonfinite > 0 {
            eprintln!(
                "warning: {}: replaced {} non-finite samples (--allow-nan)",
                path.display(),
                vol.replaced_nonfinite
            );
        }
        if let Some(s) = &self.spacing {
            vol.set_spacing(triple::<f64>(s, "--spacing")?)?;
        }
        Ok(vol)
    }
}

/// Refuses to write into a directory that does not exist, before any work.
pub fn check_output(path: &Path) -> anyhow::Result<PathBuf> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        bail!(
            "{}: output directory {} does not exist",
            path.display(),
            dir.display()
        );
    }
    if path.is_dir() {
        bail!("{}: is a directory", path.display());
    }
    Ok(path.to_path_buf())
}

/// A size in MiB (as [`snell::bench::machine::peak_rss_mib`] reports the
/// process's peak) as `1.5 GiB`.
pub fn human_mib(mib: f64) -> String {
    limits::human_bytes((mib * 1048576.0) as u64)
}
