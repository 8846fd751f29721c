//! The validated reading plan: the header's fields checked against each
//! other and turned into dims, spacing, sample type, encoding, skips and
//! data files.

use std::path::{Path, PathBuf};

use super::super::{Endian, SampleType, VolumeError};
use super::header::{Fields, excerpt};
use super::{Encoding, MAX_DIMENSION};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum ByteSkip {
    Bytes(u64),
    /// `byte skip: -1`: the data is the last bytes of the file.
    DataAtEnd,
}

#[derive(Debug)]
pub(super) struct Layout {
    pub(super) dims: [usize; 3],
    pub(super) spacing: [f64; 3],
    pub(super) ty: SampleType,
    pub(super) endian: Endian,
    pub(super) encoding: Encoding,
    pub(super) line_skip: u64,
    pub(super) byte_skip: ByteSkip,
    /// The detached data's files in order (none: attached data); more than
    /// one split the data in equal slabs along the slowest axes.
    pub(super) data_files: Vec<PathBuf>,
    /// What the header says that the volume does not keep, for
    /// [`Volume::warnings`](super::super::Volume::warnings).
    pub(super) warnings: Vec<String>,
}

impl Layout {
    pub(super) fn from_fields(path: &Path, f: &Fields) -> Result<Layout, VolumeError> {
        let missing =
            |name: &str| VolumeError::format(path, format!("header has no '{name}' field"));
        let ty = f.sample_type.ok_or_else(|| missing("type"))?;
        let dimension = f.dimension.ok_or_else(|| missing("dimension"))?;
        let sizes = f.sizes.as_deref().ok_or_else(|| missing("sizes"))?;
        let encoding = f.encoding.ok_or_else(|| missing("encoding"))?;
        if sizes.len() != dimension {
            return Err(VolumeError::format(
                path,
                format!(
                    "sizes has {} values but dimension is {dimension}",
                    sizes.len()
                ),
            ));
        }
        let axes = grid_axes(sizes).ok_or_else(|| {
            VolumeError::unsupported(
                path,
                format!(
                    "{dimension}-D data (sizes {}) is not supported: only scalar volumes, with at most three axes longer than 1",
                    join(sizes)
                ),
            )
        })?;
        // An axis of colour or vector components (`kinds: RGB-color domain
        // domain`) would be read as a spatial one: three scalar slices.
        if let Some(kinds) = &f.kinds {
            let spatial = |k: &str| {
                matches!(
                    k.to_ascii_lowercase().as_str(),
                    "domain" | "space" | "time" | "???" | "none"
                )
            };
            if let Some((a, k)) = kinds
                .iter()
                .enumerate()
                .find(|&(a, k)| sizes.get(a).is_some_and(|&n| n > 1) && !spatial(k))
            {
                return Err(VolumeError::unsupported(
                    path,
                    format!(
                        "axis {a} is of kind '{}', not a spatial axis: only scalar volumes are supported",
                        excerpt(k)
                    ),
                ));
            }
        }
        let dims: [usize; 3] = std::array::from_fn(|a| axes.get(a).map_or(1, |&i| sizes[i]));

        // Text has no byte order; its samples are re-encoded little endian.
        let endian = if ty.size() > 1 && encoding != Encoding::Ascii {
            f.endian.ok_or_else(|| {
                VolumeError::format(
                    path,
                    format!("header has no 'endian' field, required for {ty} samples"),
                )
            })?
        } else {
            Endian::Little // irrelevant for single bytes
        };

        let spacing = spacing_from(path, f, dimension, &axes)?;
        let warnings = shear(f, &axes)
            .map(|(a, b, degrees)| {
                format!(
                    "{}: the space directions of axes {a} and {b} are {degrees:.2}° apart, not 90° (a sheared grid, as of a gantry-tilted CT); the volume is rendered on a rectangular grid with each axis' sample distance, so its shape is not the scan's",
                    path.display()
                )
            })
            .into_iter()
            .chain(
                mirrored(f, &axes)
                    .then(|| crate::volume::mirror_warning(path, "its 'space directions' field")),
            )
            .collect();

        let byte_skip = match f.byte_skip.unwrap_or(0) {
            // The end of the file (raw) or of the decompressed data (gzip).
            -1 => ByteSkip::DataAtEnd,
            // parse_line only lets -1 and non-negative values through.
            n => ByteSkip::Bytes(u64::try_from(n).unwrap_or(0)),
        };

        let data_files = match &f.data_file {
            None => Vec::new(),
            Some(files) => files.paths(path, sizes)?,
        };

        Ok(Layout {
            dims,
            spacing,
            ty,
            endian,
            encoding,
            line_skip: f.line_skip.unwrap_or(0),
            byte_skip,
            data_files,
            warnings,
        })
    }
}

/// The first pair of the grid's axes (`axes`) whose space directions are
/// further than 0.01° from perpendicular, with their angle in degrees.
/// Rotated grids pass (their orientation is dropped, their shape kept);
/// sheared ones do not keep their shape.
fn shear(f: &Fields, axes: &[usize]) -> Option<(usize, usize, f64)> {
    let dirs = f.space_directions.as_ref()?;
    let dir = |a: usize| dirs.get(a).and_then(|d| d.as_deref());
    for (i, &a) in axes.iter().enumerate() {
        for &b in &axes[i + 1..] {
            let (Some(u), Some(v)) = (dir(a), dir(b)) else {
                continue;
            };
            let (lu, lv) = (vector_length(u)?, vector_length(v)?);
            let cos = u.iter().zip(v).map(|(x, y)| x * y).sum::<f64>() / (lu * lv);
            let degrees = cos.clamp(-1.0, 1.0).acos().to_degrees();
            if (degrees - 90.0).abs() > 0.01 {
                return Some((a, b, degrees));
            }
        }
    }
    None
}

/// Whether the three grid axes' space directions (`axes`) form a frame of
/// the other handedness than the space's (a negative determinant in a
/// right-handed space such as LPS or RAS): rendered in index order, as
/// snell renders every volume, such a scan is its own mirror image. A
/// rotation alone (an even number of reversed axes among them) keeps the
/// shape and passes.
fn mirrored(f: &Fields, axes: &[usize]) -> bool {
    let Some(dirs) = f.space_directions.as_ref() else {
        return false;
    };
    let dir = |a: usize| -> Option<[f64; 3]> {
        let d = dirs.get(a)?.as_deref()?;
        (d.len() == 3 && d.iter().all(|c| c.is_finite())).then(|| [d[0], d[1], d[2]])
    };
    let (Some(u), Some(v), Some(w)) = (
        axes.first().and_then(|&a| dir(a)),
        axes.get(1).and_then(|&a| dir(a)),
        axes.get(2).and_then(|&a| dir(a)),
    ) else {
        return false;
    };
    crate::volume::reverses_handedness([u, v, w]) != f.space_left_handed
}

pub(super) fn join<T: std::fmt::Display>(values: &[T]) -> String {
    values
        .iter()
        .map(|v| v.to_string())
        .collect::<Vec<_>>()
        .join(" ")
}

/// The axes read as the grid's x, y and z, in order: all of them up to
/// three; beyond three, every axis longer than 1 and as many of the first
/// unit axes as make three (`sizes: 1 64 64 64` is a 64³ grid, as is `64
/// 64 64 1`). `None` with more than three axes longer than 1.
pub(super) fn grid_axes(sizes: &[usize]) -> Option<Vec<usize>> {
    if sizes.len() <= 3 {
        return Some((0..sizes.len()).collect());
    }
    let long = sizes.iter().filter(|&&n| n > 1).count();
    if long > 3 {
        return None;
    }
    let mut units = 3 - long;
    Some(
        (0..sizes.len())
            .filter(|&a| {
                sizes[a] > 1 || {
                    let keep = units > 0;
                    units = units.saturating_sub(1);
                    keep
                }
            })
            .collect(),
    )
}

/// Spacing of the grid's axes (`axes`, from [`grid_axes`]): the length of
/// each axis' space direction (the whole vector, so a rotated or sheared
/// grid keeps its true sample distance), else its `spacings` entry, else 1.
/// Orientation itself is dropped: the renderer works in grid coordinates ×
/// spacing. As teem, an axis may not have both a direction and a spacing:
/// which one the writer meant is anyone's guess.
fn spacing_from(
    path: &Path,
    f: &Fields,
    dimension: usize,
    axes: &[usize],
) -> Result<[f64; 3], VolumeError> {
    let fmt = |msg: String| VolumeError::format(path, msg);
    if let (Some(a), Some(b)) = (f.space, f.space_dimension)
        && a != b
    {
        return Err(fmt(format!(
            "space (of dimension {a}) and space dimension ({b}) disagree"
        )));
    }
    if let Some(sp) = &f.spacings
        && sp.len() != dimension
    {
        return Err(fmt(format!(
            "spacings has {} values but dimension is {dimension}",
            sp.len()
        )));
    }
    if let Some(dirs) = &f.space_directions {
        if dirs.len() != dimension {
            return Err(fmt(format!(
                "space directions has {} entries but dimension is {dimension}",
                dirs.len()
            )));
        }
        // Every vector has the space's dimension (the first vector's
        // where the header names no space).
        let want = f
            .space
            .or(f.space_dimension)
            .or_else(|| dirs.iter().flatten().next().map(Vec::len));
        if let Some((axis, v)) = dirs
            .iter()
            .enumerate()
            .find_map(|(a, d)| d.as_ref().filter(|v| Some(v.len()) != want).map(|v| (a, v)))
        {
            return Err(fmt(format!(
                "space direction of axis {axis} has {} components, not the space's {}",
                v.len(),
                want.unwrap_or(0)
            )));
        }
        if let Some(axis) = (0..dimension)
            .find(|&a| dirs[a].is_some() && f.spacings.as_ref().is_some_and(|sp| !sp[a].is_nan()))
        {
            return Err(fmt(format!(
                "axis {axis} has both a space direction and a spacing; give one (teem refuses this too)"
            )));
        }
    }
    let mut spacing = [1.0f64; 3];
    for (&axis, s) in axes.iter().zip(spacing.iter_mut()) {
        if let Some(dirs) = &f.space_directions {
            if let Some(v) = &dirs[axis] {
                *s = vector_length(v).ok_or_else(|| {
                    fmt(format!(
                        "space direction of axis {axis} ({}) must be finite and non-zero",
                        join(v)
                    ))
                })?;
                continue;
            }
            if f.spacings.is_none() {
                return Err(fmt(format!(
                    "space directions gives 'none' for axis {axis}, but it is a spatial axis of the volume"
                )));
            }
        }
        if let Some(sp) = &f.spacings {
            let v = sp[axis];
            // NaN is NRRD's "no spacing known"; the sign only says direction.
            if v.is_nan() {
                continue;
            }
            if !v.is_finite() || v == 0.0 {
                return Err(fmt(format!(
                    "spacing {v} of axis {axis} must be finite and non-zero"
                )));
            }
            *s = v.abs();
        }
    }
    Ok(spacing)
}

/// Length of a direction vector; exact for an axis-aligned one (a diagonal
/// matrix), so written spacings read back bit for bit.
fn vector_length(v: &[f64]) -> Option<f64> {
    if v.iter().any(|c| !c.is_finite()) {
        return None;
    }
    let mut nonzero = v.iter().filter(|c| **c != 0.0);
    let len = match (nonzero.next(), nonzero.next()) {
        (None, _) => return None,
        (Some(c), None) => c.abs(),
        _ => v.iter().map(|c| c * c).sum::<f64>().sqrt(),
    };
    (len.is_finite() && len > 0.0).then_some(len)
}

/// The `data file` field: one file, a printf pattern over a range of
/// integers (`slice%03d.raw 1 64 1`), or `LIST` with the names on the
/// header's remaining lines; the multi-file forms may end with the
/// dimension of each file's slab (default: one less than the data's).
#[derive(Debug, PartialEq)]
pub(super) enum DataFiles {
    One(String),
    Pattern {
        format: String,
        first: i64,
        last: i64,
        step: i64,
        slab_dim: Option<usize>,
    },
    List {
        slab_dim: Option<usize>,
        names: Vec<String>,
    },
}

impl DataFiles {
    pub(super) fn parse(value: &str) -> Result<DataFiles, String> {
        let tokens: Vec<&str> = value.split_whitespace().collect();
        let slab_dim = |t: Option<&&str>| -> Result<Option<usize>, String> {
            t.map(|t| {
                t.parse::<usize>()
                    .ok()
                    .filter(|d| (1..=MAX_DIMENSION).contains(d))
                    .ok_or_else(|| format!("'{}' is not a slab dimension", excerpt(t)))
            })
            .transpose()
        };
        if tokens.first() == Some(&"LIST") {
            if tokens.len() > 2 {
                return Err("LIST takes at most a slab dimension after it".into());
            }
            return Ok(DataFiles::List {
                slab_dim: slab_dim(tokens.get(1))?,
                names: Vec::new(),
            });
        }
        let ints: Vec<Option<i64>> = tokens.iter().skip(1).map(|t| t.parse().ok()).collect();
        let is_pattern = (4..=5).contains(&tokens.len())
            && tokens[0].contains('%')
            && ints.iter().take(3).all(Option::is_some);
        if !is_pattern {
            return Ok(DataFiles::One(value.to_string()));
        }
        let [first, last, step] = [ints[0], ints[1], ints[2]].map(|v| v.unwrap_or(0));
        if step == 0 || (step > 0 && first > last) || (step < 0 && first < last) {
            return Err(format!(
                "the range {first} to {last} in steps of {step} names no files"
            ));
        }
        // Checked here, so that expanding the pattern cannot fail.
        format_index(tokens[0], first)?;
        Ok(DataFiles::Pattern {
            format: tokens[0].to_string(),
            first,
            last,
            step,
            slab_dim: slab_dim(tokens.get(4))?,
        })
    }

    /// The files, relative to the header's directory, after checking that
    /// there are as many as the slabs the sizes make.
    pub(super) fn paths(&self, path: &Path, sizes: &[usize]) -> Result<Vec<PathBuf>, VolumeError> {
        let fmt = |msg: String| VolumeError::format(path, msg);
        let (slab_dim, listed) = match self {
            DataFiles::One(name) => return Ok(vec![relative_to(path, name)]),
            DataFiles::List { slab_dim, names } => (*slab_dim, names.len() as u64),
            DataFiles::Pattern {
                first,
                last,
                step,
                slab_dim,
                ..
            } => (*slab_dim, (last.abs_diff(*first)) / step.unsigned_abs() + 1),
        };
        let dimension = sizes.len();
        let slab_dim = slab_dim.unwrap_or(dimension.saturating_sub(1).max(1));
        if slab_dim > dimension {
            return Err(fmt(format!(
                "data file slab dimension {slab_dim} is above the data's dimension {dimension}"
            )));
        }
        // The sizes were checked against the sample count: no overflow.
        let slabs: u64 = sizes[slab_dim..].iter().map(|&n| n as u64).product();
        if listed != slabs {
            return Err(fmt(format!(
                "data file names {listed} files, but sizes {} in slabs of dimension {slab_dim} make {slabs}",
                join(sizes)
            )));
        }
        Ok(match self {
            DataFiles::One(_) => unreachable!("returned above"),
            DataFiles::List { names, .. } => names.iter().map(|n| relative_to(path, n)).collect(),
            DataFiles::Pattern {
                format,
                first,
                step,
                ..
            } => (0..listed as i64)
                .map(|k| {
                    let name = format_index(format, first + k * step).unwrap_or_default();
                    relative_to(path, &name)
                })
                .collect(),
        })
    }
}

/// `format` with its one integer conversion (`%d`, `%i` or `%u`, with an
/// optional `0` flag and width, as `%03d`) replaced by `i`; `%%` is a `%`.
pub(super) fn format_index(format: &str, i: i64) -> Result<String, String> {
    let bad = || {
        format!(
            "'{}' is not a file name pattern with one %d",
            excerpt(format)
        )
    };
    let mut out = String::new();
    let mut chars = format.chars().peekable();
    let mut done = false;
    while let Some(c) = chars.next() {
        if c != '%' {
            out.push(c);
            continue;
        }
        if chars.peek() == Some(&'%') {
            chars.next();
            out.push('%');
            continue;
        }
        let zero = chars.next_if_eq(&'0').is_some();
        let mut width = 0usize;
        while let Some(d) = chars.next_if(char::is_ascii_digit) {
            width = (width * 10 + d.to_digit(10).unwrap_or(0) as usize).min(64);
        }
        if done || !matches!(chars.next(), Some('d' | 'i' | 'u')) {
            return Err(bad());
        }
        done = true;
        let digits = i.unsigned_abs().to_string();
        let sign = if i < 0 { "-" } else { "" };
        let len = sign.len() + digits.len();
        let pad = width.saturating_sub(len);
        if zero {
            out.push_str(sign);
            out.extend(std::iter::repeat_n('0', pad));
        } else {
            out.extend(std::iter::repeat_n(' ', pad));
            out.push_str(sign);
        }
        out.push_str(&digits);
    }
    if done { Ok(out) } else { Err(bad()) }
}

/// A data file named in a header: relative to the header's directory.
fn relative_to(header: &Path, name: &str) -> PathBuf {
    let data = Path::new(name);
    if data.is_absolute() {
        return data.to_path_buf();
    }
    header.parent().unwrap_or(Path::new("")).join(data)
}
