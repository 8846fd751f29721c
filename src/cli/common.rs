//! Options and helpers shared by several subcommands.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::Args;

use snell::filter::{FilterError, FilterKind};
use snell::human::shell_quote;
use snell::volume::{self, Endian, LoadOptions, RawSpec, SampleType, Volume, limits};

/// How to read a volume file (raw files need their layout spelled out).
#[derive(Args, Debug, Clone, Default)]
pub struct VolumeArgs {
    /// Dimensions of a headerless raw file: X,Y,Z.
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub dims: Option<String>,
    /// Sample type of a raw file: u8, i8, u16, i16, u32, i32, f32, f64.
    #[arg(long = "type", value_name = "TYPE")]
    pub sample_type: Option<String>,
    /// Byte order of a raw file (default: little).
    #[arg(long, value_name = "little|big")]
    pub endian: Option<String>,
    /// Voxel spacing X,Y,Z (overrides the file's own).
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub spacing: Option<String>,
    /// Bytes to skip at the start of a raw file (default: 0).
    #[arg(long, value_name = "BYTES", allow_hyphen_values = true, value_parser = byte_offset)]
    pub offset: Option<u64>,
    /// Replace NaN/infinite samples in float data instead of rejecting the file.
    #[arg(long)]
    pub allow_nan: bool,
    #[command(flatten)]
    pub limit: MemoryLimit,
}

/// `--memory-limit`, which every command that reads or builds large data
/// takes, so that a refusal's advice to raise it holds whatever command
/// printed it.
#[derive(Args, Debug, Clone, Default)]
pub struct MemoryLimit {
    /// Largest working set to allow: bytes (1e9), or K, M, G, T with an
    /// optional B or iB (binary multiples: 1G = 1GB = 1GiB = 2^30 bytes);
    /// default: SNELL_MEMORY_LIMIT, else 80% of available memory.
    #[arg(long, value_name = "BYTES", allow_hyphen_values = true)]
    pub memory_limit: Option<String>,
}

impl MemoryLimit {
    /// Sets the limit for every check in this process ([`set_memory_limit`]).
    pub fn apply(&self) -> anyhow::Result<()> {
        set_memory_limit(self.memory_limit.as_deref())
    }
}

/// `--offset`: a whole number of bytes.
fn byte_offset(s: &str) -> Result<u64, String> {
    s.trim().parse().map_err(|_| {
        format!(
            "expected a whole number of bytes from 0 to {}, got '{s}'",
            u64::MAX
        )
    })
}

/// `--memory-limit` for a command whose limit checks read the variable
/// (every check of a scene, its volume and its images, a phantom's): the
/// flag, checked, sets `SNELL_MEMORY_LIMIT` for them all. Called at
/// start-up, before the process starts any other thread.
pub fn set_memory_limit(arg: Option<&str>) -> anyhow::Result<()> {
    if let Some(s) = arg {
        memory_limit(Some(s))?;
        // SAFETY: no other thread runs yet to read the environment.
        unsafe { std::env::set_var("SNELL_MEMORY_LIMIT", s) };
    }
    Ok(())
}

/// `--memory-limit`, or the default limit.
pub fn memory_limit(arg: Option<&str>) -> anyhow::Result<u64> {
    Ok(match arg {
        Some(s) => {
            limits::parse_bytes(s).map_err(|why| anyhow::anyhow!("--memory-limit: {why}"))?
        }
        None => limits::default_memory_limit(),
    })
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
    /// The options for reading `path`. The raw layout options are refused
    /// for a file whose name says its format (its header gives its layout).
    pub fn load_options(&self, path: &Path) -> anyhow::Result<LoadOptions> {
        let memory_limit = memory_limit(self.limit.memory_limit.as_deref())?;
        if let Some(format) = volume::Format::of(path) {
            let given = flags_given([
                ("--dims", self.dims.is_some()),
                ("--type", self.sample_type.is_some()),
                ("--endian", self.endian.is_some()),
                ("--offset", self.offset.is_some()),
            ]);
            if !given.is_empty() {
                bail!(
                    "{}: {} {} only to headerless raw volumes (named .raw or without a known extension); this is {}, whose header gives its layout",
                    path.display(),
                    given.join(", "),
                    if given.len() == 1 { "applies" } else { "apply" },
                    format.describe()
                );
            }
        }
        let spacing = match &self.spacing {
            Some(s) => {
                let sp = triple::<f64>(s, "--spacing")?;
                // The message gives the values.
                volume::check_spacing(sp)
                    .with_context(|| format!("{}: --spacing", path.display()))?;
                Some(sp)
            }
            None => None,
        };
        let raw = match (&self.dims, &self.sample_type) {
            (None, None) if self.endian.is_some() || self.offset.is_some() => {
                bail!("a raw volume needs --dims and --type besides --endian and --offset")
            }
            (None, None) => None,
            (Some(d), Some(t)) => Some(RawSpec {
                dims: triple::<usize>(d, "--dims")?,
                sample_type: SampleType::parse(t).with_context(|| {
                    format!(
                        "--type: unknown sample type '{t}' (u8, i8, u16, i16, u32, i32, f32, f64)"
                    )
                })?,
                endian: match &self.endian {
                    None => Endian::Little,
                    Some(e) => Endian::parse(e)
                        .with_context(|| format!("--endian: expected little or big, got '{e}'"))?,
                },
                spacing: spacing.unwrap_or([1.0; 3]),
                offset: self.offset.unwrap_or(0),
            }),
            _ => bail!("a raw volume needs both --dims and --type"),
        };
        Ok(LoadOptions {
            allow_nan: self.allow_nan,
            memory_limit,
            raw,
        })
    }

    /// The options as given, for a command line that reads the volume the
    /// same way (` --dims 64,64,93 --type u16`, or nothing).
    pub fn flags(&self) -> String {
        let mut out = String::new();
        for (flag, value) in [
            ("--dims", self.dims.clone()),
            ("--type", self.sample_type.clone()),
            ("--endian", self.endian.clone()),
            ("--spacing", self.spacing.clone()),
            ("--offset", self.offset.map(|o| o.to_string())),
        ] {
            if let Some(v) = value {
                // The value as read: the parsers trim around commas.
                let v: String = v.split_whitespace().collect();
                out += &format!(" {flag} {}", shell_quote(&v));
            }
        }
        if self.allow_nan {
            out += " --allow-nan";
        }
        out
    }

    pub fn load(&self, path: &Path) -> anyhow::Result<Volume> {
        self.load_with(path, &self.load_options(path)?)
    }

    /// [`VolumeArgs::load`] with options already taken from the arguments.
    pub fn load_with(&self, path: &Path, opts: &LoadOptions) -> anyhow::Result<Volume> {
        let mut vol = volume::load(path, opts)?;
        for w in &vol.warnings {
            eprintln!("warning: {w}");
        }
        if vol.replaced_nonfinite > 0 {
            eprintln!(
                "warning: {}: replaced {} non-finite samples (--allow-nan)",
                path.display(),
                vol.replaced_nonfinite
            );
        }
        if let Some(s) = &self.spacing {
            vol.set_spacing(triple::<f64>(s, "--spacing")?)
                .with_context(|| format!("{}: --spacing {s}", path.display()))?;
        }
        Ok(vol)
    }
}

/// A path as one word for a POSIX shell ([`shell_quote`]) that a command
/// cannot take for an option: after `./` where it starts with `-`.
pub fn shell_path(s: &str) -> String {
    if s.starts_with('-') {
        shell_quote(&format!("./{s}"))
    } else {
        shell_quote(s)
    }
}

/// `--filter NAME [--lambda L]`: the filter, with errors naming the option
/// at fault. `--lambda` with a filter that does not smooth is refused, as is
/// `smooth-bspline3` without it.
pub fn filter_kind(filter: &str, lambda: Option<f64>) -> anyhow::Result<FilterKind> {
    let kind = FilterKind::with_lambda(filter, lambda).map_err(|e| match e {
        FilterError::Unknown(_) => anyhow::anyhow!("--filter: {e}"),
        FilterError::BadLambda(_) => anyhow::anyhow!("--lambda: {e}"),
        FilterError::NeedsLambda => anyhow::anyhow!(
            "--filter smooth-bspline3 needs --lambda L, {}",
            snell::filter::LAMBDA_HELP
        ),
    })?;
    if let Some(l) = lambda
        && !kind.smooths()
    {
        bail!(
            "--lambda {l} applies only to --filter smooth-bspline3, not to --filter {}: drop --lambda or choose the smoothing spline",
            kind.name()
        );
    }
    Ok(kind)
}

/// A scene file with its `--set` overrides, the settings it wrote but does
/// not use each said in a warning (a `render.step` under an octree, say):
/// every command that reads a scene names them alike.
pub fn load_scene(path: &Path, sets: &[String]) -> anyhow::Result<snell::scene::Scene> {
    Ok(warn_setting_notes(
        path,
        snell::scene::Scene::load(path, sets)?,
    ))
}

/// [`load_scene`] for one part of a frame (`render --region`), held to the
/// memory limit for its part alone ([`snell::scene::Scene::load_part`]).
pub fn load_scene_part(path: &Path, sets: &[String]) -> anyhow::Result<snell::scene::Scene> {
    Ok(warn_setting_notes(
        path,
        snell::scene::Scene::load_part(path, sets)?,
    ))
}

/// [`load_scene`] for a command that reads less of a scene than a render
/// (`reference`, `export-pov`): the notes on settings it does not read at
/// all (`unread(key)`) are dropped, a render's note that a step goes unused
/// under the octree misleading where no traversal runs; the command warns
/// of the `--set`s of such settings in its own words ([`unread_sets`]),
/// and of the scene file's not at all (every scene writes a `[render]`).
pub fn load_scene_reading(
    path: &Path,
    sets: &[String],
    unread: impl Fn(&str) -> bool,
) -> anyhow::Result<snell::scene::Scene> {
    let scene = snell::scene::Scene::load(path, sets)?;
    for n in scene.setting_notes().iter().filter(|n| !unread(&n.key)) {
        eprintln!("warning: {}: {n}", path.display());
    }
    Ok(scene)
}

/// The flags of `flags` that were given (`true`), in order, for a message
/// that names the ones at fault.
pub fn flags_given<const N: usize>(flags: [(&'static str, bool); N]) -> Vec<&'static str> {
    flags
        .into_iter()
        .filter_map(|(flag, on)| on.then_some(flag))
        .collect()
}

/// The keys `--set` wrote that `unread` names, those inside a table
/// value included: the ones a command that reads less of a scene than a
/// render warns of, in its own terms.
pub fn unread_sets(sets: &[String], unread: impl Fn(&str) -> bool) -> Vec<String> {
    sets.iter()
        .flat_map(|s| snell::scene::override_keys(s))
        .filter(|k| unread(k))
        .collect()
}

fn warn_setting_notes(path: &Path, scene: snell::scene::Scene) -> snell::scene::Scene {
    for w in scene.setting_notes() {
        eprintln!("warning: {}: {w}", path.display());
    }
    scene
}

/// Most worker threads a command starts: far above any core count snell
/// could use, and low enough that a typo is refused at once instead of
/// spawning threads until the system refuses.
pub const MAX_THREADS: usize = 1024;

/// `--threads`: a count from 1 to [`MAX_THREADS`].
pub fn thread_count(s: &str) -> Result<usize, String> {
    let n: usize = s
        .trim()
        .parse()
        .map_err(|_| format!("'{s}' is not a thread count"))?;
    if (1..=MAX_THREADS).contains(&n) {
        Ok(n)
    } else {
        Err(format!("must be from 1 to {MAX_THREADS}, got {n}"))
    }
}

/// Refuses to write into a directory that does not exist, before any work.
pub fn check_output(path: &Path) -> anyhow::Result<PathBuf> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        let what = if dir.exists() {
            "is not a directory"
        } else {
            "does not exist"
        };
        bail!(
            "{}: output directory {} {what}",
            path.display(),
            dir.display()
        );
    }
    if path.is_dir() {
        bail!("{}: is a directory", path.display());
    }
    // A symbolic link is written through, a dangling one to the file it
    // names: that file's folder must exist too.
    let written = snell::atomic::written_path(path);
    if written != path
        && let Some(d) = written.parent().filter(|d| !d.as_os_str().is_empty())
        && !d.is_dir()
    {
        bail!(
            "{}: a symbolic link to {}, whose directory does not exist",
            path.display(),
            written.display()
        );
    }
    snell::atomic::check_target(path)
        .map_err(|e| anyhow::anyhow!("{}: {e}; outputs go to files", path.display()))?;
    snell::atomic::check_writable(path).map_err(|e| {
        if e.kind() == std::io::ErrorKind::InvalidFilename {
            // The output is written as `.NAME.PID.N.tmp` beside its target.
            anyhow::anyhow!(
                "{}: the name is too long to write (the temporary file beside it takes about 20 characters more)",
                path.display()
            )
        } else {
            anyhow::anyhow!("{}: cannot write in {}: {e}", path.display(), dir.display())
        }
    })?;
    Ok(path.to_path_buf())
}

/// Refuses an output whose name does not end in one of `formats`: the file is
/// written in that format whatever it is called, and `-o out.jpg` holding PNG
/// data would mislead every program that opens it.
pub fn check_format(path: &Path, flag: &str, formats: &[&str]) -> anyhow::Result<()> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    if ext.as_deref().is_some_and(|e| formats.contains(&e)) {
        return Ok(());
    }
    if let [only] = formats {
        bail!(
            "{flag} {}: writes {}; give the file a .{only} name",
            path.display(),
            only.to_ascii_uppercase(),
        )
    }
    bail!(
        "{flag} {}: the name's extension chooses the format written; give the file a .{} name",
        path.display(),
        formats.join(" or .")
    )
}

/// The paths of the options that were given.
pub fn given<'a>(paths: &[Option<&'a PathBuf>]) -> Vec<&'a Path> {
    paths.iter().flatten().map(|p| p.as_path()).collect()
}

/// Refuses outputs that name one file twice or name an input: the later
/// write would silently replace the earlier output, or the input itself.
pub fn check_distinct(outputs: &[&Path], inputs: &[&Path]) -> anyhow::Result<()> {
    // The file a path names: resolved where it exists, else its directory
    // resolved and its name appended (a dangling link's file, which the
    // write would create).
    let identity = |p: &Path| -> PathBuf {
        let p = &snell::atomic::written_path(p);
        std::fs::canonicalize(p).unwrap_or_else(|_| {
            let dir = match p.parent() {
                Some(d) if !d.as_os_str().is_empty() => d,
                _ => Path::new("."),
            };
            match (std::fs::canonicalize(dir), p.file_name()) {
                (Ok(d), Some(name)) => d.join(name),
                _ => p.to_path_buf(),
            }
        })
    };
    let ins: Vec<PathBuf> = inputs.iter().map(|p| identity(p)).collect();
    // By name, so an orbit's thousands of frame files check in linear time.
    let mut seen: std::collections::HashMap<PathBuf, &Path> = std::collections::HashMap::new();
    for &o in outputs {
        let id = identity(o);
        if let Some(k) = ins.iter().position(|i| *i == id) {
            bail!(
                "{}: is an input of this command ({}); choose another output name",
                o.display(),
                inputs[k].display()
            );
        }
        if let Some(first) = seen.get(&id) {
            bail!(
                "{} and {} name the same file; give each output its own name",
                first.display(),
                o.display()
            );
        }
        seen.insert(id, o);
    }
    Ok(())
}

/// `AxBxC samples: one sample along z makes no cells` for a volume one
/// sample thick along an axis (no cell, so no surface), else `None`.
pub fn no_cells(d: [usize; 3]) -> Option<String> {
    let axis = (0..3).find(|&i| d[i] < 2)?;
    Some(format!(
        "{}x{}x{} samples: one sample along {} makes no cells",
        d[0],
        d[1],
        d[2],
        ["x", "y", "z"][axis]
    ))
}

/// A size in MiB (as [`snell::bench::machine::peak_rss_mib`] reports the
/// process's peak) as `1.5 GiB`.
pub fn human_mib(mib: f64) -> String {
    limits::human_bytes((mib * 1048576.0) as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shell_words_quote_what_a_shell_would_split_or_expand() {
        assert_eq!(shell_path("../data/a-1.nrrd"), "../data/a-1.nrrd");
        assert_eq!(shell_path("my scan.nrrd"), "'my scan.nrrd'");
        assert_eq!(shell_path("it's.nrrd"), "'it'\\''s.nrrd'");
        assert_eq!(shell_path("$HOME*"), "'$HOME*'");
        assert_eq!(shell_path(""), "''");
        assert_eq!(shell_path("-dash.nrrd"), "./-dash.nrrd");
        assert_eq!(shell_path("-a b"), "'./-a b'");
    }

    /// A name that fits the file system but not with the temporary file's
    /// `.NAME.PID.N.tmp` around it is named as too long, before any work.
    #[test]
    fn a_name_too_long_for_its_temporary_file_is_refused_as_such() {
        let dir = std::env::temp_dir().join(format!("snell-long-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let long = dir.join(format!("{}.png", "a".repeat(246)));
        let e = check_output(&long).unwrap_err().to_string();
        assert!(e.contains("the name is too long to write"), "{e}");
        assert!(check_output(&dir.join("short.png")).is_ok());
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0, "no probe left");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
