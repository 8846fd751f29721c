//! `snell sample`: the reconstructed field and its gradient at given points.

use std::io::{BufRead, BufReader, Read, Write};
use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args as ClapArgs;
use glam::DVec3;

use snell::filter::Field;
use snell::human::exact;

use super::common::VolumeArgs;

#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Volume file.
    pub volume: PathBuf,
    /// Reconstruction filter: linear, catmull-rom, bspline2..bspline7, smooth-bspline3.
    #[arg(long)]
    pub filter: String,
    /// Smoothing weight λ of smooth-bspline3, 0 to 1e12 (required by it, refused by the other filters).
    #[arg(long, allow_negative_numbers = true, value_name = "L")]
    pub lambda: Option<f64>,
    /// File of points, one `x,y,z` per line in grid coordinates (`-` for
    /// stdin); blank lines, `#` comments and a first line of column names
    /// (`x,y,z`, as this command writes) are skipped. Points outside the
    /// grid are evaluated with the mirror boundary (SPEC.md), with a warning.
    #[arg(long)]
    pub points: PathBuf,
    #[command(flatten)]
    pub vol: VolumeArgs,
}

/// The number of columns if `t` is a header line naming them (`x,y,z`,
/// or the `x,y,z,value,gx,gy,gz` header `snell sample` writes): words, no
/// numbers, the first three x, y and z.
fn header_columns(t: &str) -> Option<usize> {
    let fields: Vec<&str> = t
        .split([',', ' ', '\t'])
        .filter(|s| !s.is_empty())
        .collect();
    let xyz = fields.len() >= 3
        && fields[..3]
            .iter()
            .zip(["x", "y", "z"])
            .all(|(f, n)| f.eq_ignore_ascii_case(n));
    (xyz && fields.iter().all(|f| f.parse::<f64>().is_err())).then_some(fields.len())
}

/// Longest line of a points file: a row of this command's own output is
/// about 180 bytes; anything far longer is not a points file (stdin from
/// `/dev/zero` would otherwise grow one line until memory ran out).
const MAX_LINE: usize = 4096;

/// Memory a point takes while the file is read (all of it is read, and
/// checked, before the first value is written).
const POINT_BYTES: u64 = std::mem::size_of::<DVec3>() as u64;

fn parse_points(reader: impl BufRead, name: &str, limit: u64) -> anyhow::Result<Vec<DVec3>> {
    let mut out = Vec::new();
    let mut first = true;
    // Numbers per row: three, or as many as a header names (the point is
    // the first three: this command's output reads back as its points).
    let mut columns = 3;
    let mut reader = reader;
    let mut raw = Vec::new();
    for n in 0.. {
        raw.clear();
        // The line and its newline, or one byte past the cap.
        let read = (&mut reader)
            .take(MAX_LINE as u64 + 2)
            .read_until(b'\n', &mut raw)
            .with_context(|| format!("{name}: read error at line {}", n + 1))?;
        if read == 0 {
            break;
        }
        if raw.strip_suffix(b"\n").unwrap_or(&raw).len() > MAX_LINE {
            bail!(
                "{name}: line {} is longer than {MAX_LINE} bytes; expected one point x,y,z per line",
                n + 1
            );
        }
        let line = std::str::from_utf8(&raw)
            .with_context(|| format!("{name}: line {} is not UTF-8 text", n + 1))?;
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        if std::mem::take(&mut first)
            && let Some(c) = header_columns(t)
        {
            columns = c;
            continue;
        }
        let parts: Vec<&str> = t
            .split([',', ' ', '\t'])
            .filter(|s| !s.is_empty())
            .collect();
        let vals: Option<Vec<f64>> = parts.iter().map(|p| p.parse::<f64>().ok()).collect();
        match vals {
            Some(v)
                if (v.len() == 3 || v.len() == columns) && v[..3].iter().all(|x| x.is_finite()) =>
            {
                // The memory the list holds once it grows to take this point.
                let holds = if out.len() == out.capacity() {
                    (out.capacity() * 2).max(4)
                } else {
                    out.capacity()
                };
                if holds as u64 * POINT_BYTES > limit {
                    bail!(
                        "{name}: line {}: more than {} points would exceed the memory limit of {} (set --memory-limit or SNELL_MEMORY_LIMIT to raise it, or split the file)",
                        n + 1,
                        out.len(),
                        snell::volume::limits::human_bytes(limit)
                    );
                }
                out.push(DVec3::new(v[0], v[1], v[2]))
            }
            _ => {
                // A long line quoted whole would bury the message.
                let shown: String = t.chars().take(80).collect();
                let more = if shown.len() < t.len() { "…" } else { "" };
                let what = if columns == 3 {
                    "three finite numbers x,y,z".to_string()
                } else {
                    format!("three finite numbers x,y,z (or {columns}, as the header names)")
                };
                bail!(
                    "{name}: line {}: expected {what}, got '{shown}{more}'",
                    n + 1
                )
            }
        }
    }
    Ok(out)
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let kind = super::common::filter_kind(&a.filter, a.lambda)?;
    let name = a.points.display().to_string();
    let limit = super::common::memory_limit(a.vol.limit.memory_limit.as_deref())?;
    let points = if name == "-" {
        parse_points(std::io::stdin().lock(), "stdin", limit)?
    } else {
        let f = snell::input::open(&a.points).with_context(|| name.clone())?;
        parse_points(BufReader::new(f), &name, limit)?
    };
    let vol = a.vol.load(&a.volume)?;
    if let Some(s) = &a.vol.spacing {
        eprintln!(
            "warning: --spacing {s} has no effect here: points are grid coordinates and gx, gy, gz the change per grid unit (SPEC.md); divide by a spacing for physical units"
        );
    }
    let d = vol.dims();
    let outside = points
        .iter()
        .filter(|p| !(0..3).all(|k| (0.0..=(d[k] - 1) as f64).contains(&p[k])))
        .count();
    if outside > 0 {
        eprintln!(
            "warning: {outside} of {} points lie outside the grid [0, {}] x [0, {}] x [0, {}]; they are evaluated with the mirror boundary (SPEC.md)",
            points.len(),
            d[0] - 1,
            d[1] - 1,
            d[2] - 1
        );
    }
    let field = Field::new(&vol, kind);
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    writeln!(out, "x,y,z,value,gx,gy,gz")?;
    for p in points {
        // Evaluations are relative to the field's offset (`Field`).
        let (v, g) = field.value_grad(p);
        let v = field.offset() + v;
        // The shortest round trip of each value, in scientific notation at
        // the extremes (a gradient of 1e-15 is 22 characters positionally).
        let row = [p.x, p.y, p.z, v, g.x, g.y, g.z].map(exact);
        writeln!(out, "{}", row.join(","))?;
    }
    out.flush()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A header on the first line (this command's own) is skipped, and the
    /// line numbers of errors count every line of the file from 1.
    #[test]
    fn points_skip_a_header_and_number_lines_from_one() {
        let p = parse_points("x,y,z,value,gx,gy,gz\n1,2,3\n".as_bytes(), "p", u64::MAX).unwrap();
        assert_eq!(p, vec![DVec3::new(1.0, 2.0, 3.0)]);
        let p = parse_points("# points\nx y z\n1 2 3\n".as_bytes(), "p", u64::MAX).unwrap();
        assert_eq!(p.len(), 1);
        // This command's output, gradient and all, reads back as its points.
        let p = parse_points(
            "x,y,z,value,gx,gy,gz\n1,2,3,0.5,1e-15,0,-2\n".as_bytes(),
            "p",
            u64::MAX,
        )
        .unwrap();
        assert_eq!(p, vec![DVec3::new(1.0, 2.0, 3.0)]);
        let e = parse_points("x,y,z,value\n1,2\n".as_bytes(), "p", u64::MAX)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("line 2: expected three") && e.contains("or 4"),
            "{e}"
        );
        let e = parse_points("1,2,3\nx,y,z\n".as_bytes(), "p", u64::MAX)
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 2") && e.contains("x,y,z"), "{e}");
        let e = parse_points("x,y,z\n4,5\n".as_bytes(), "p", u64::MAX)
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 2:"), "{e}");
    }

    /// A line without end (stdin from `/dev/zero`) stops at the cap, and
    /// the points stop at the memory limit, each with its line number.
    #[test]
    fn endless_lines_and_too_many_points_are_refused() {
        let zeros = std::io::BufReader::new(std::io::repeat(0));
        let e = parse_points(zeros, "stdin", u64::MAX)
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 1 is longer than 4096 bytes"), "{e}");
        let five = "1,2,3\n4,5,6\n7,8,9\n1,1,1\n2,2,2\n";
        let e = parse_points(five.as_bytes(), "p", 4 * POINT_BYTES)
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 5: more than 4 points"), "{e}");
        let p = parse_points(five.as_bytes(), "p", 8 * POINT_BYTES).unwrap();
        assert_eq!(p.len(), 5);
        // A line of exactly the cap, with its newline, is read.
        let long = format!("1,2,3{}\n", " ".repeat(MAX_LINE - 5));
        assert_eq!(
            parse_points(long.as_bytes(), "p", u64::MAX).unwrap().len(),
            1
        );
        let longer = format!("1,2,3{}\n", " ".repeat(MAX_LINE - 4));
        assert!(parse_points(longer.as_bytes(), "p", u64::MAX).is_err());
        let e = parse_points(&b"1,2,\xff\n"[..], "p", u64::MAX)
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 1 is not UTF-8"), "{e}");
    }
}
