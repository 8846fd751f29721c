//! Joining the parts of a frame rendered piecewise (`snell render --region`).
//!
//! A part is an EXR whose data window is a rectangle inside the display
//! window of the whole image ([`super::Placement`]). Parts of one frame share
//! the display window and the channel names; together they must cover every
//! pixel exactly once, so a failed or duplicated job of the scheduler that
//! rendered them is an error, never a silently black or doubled region.

use std::path::{Path, PathBuf};

use super::{
    FRAME_ATTRIBUTE, FilmError, FrameId, Placement, to_u8, write_exr_placed, write_png_rgb,
};

/// One part as read: where it sits and its channels (sorted by name).
#[derive(Clone, Debug)]
pub struct Part {
    pub path: PathBuf,
    pub width: u32,
    pub height: u32,
    pub at: Placement,
    pub channels: Vec<(String, Vec<f32>)>,
}

/// The whole image joined from its parts.
#[derive(Clone, Debug, PartialEq)]
pub struct Merged {
    pub width: u32,
    pub height: u32,
    pub channels: Vec<(String, Vec<f32>)>,
}

#[derive(Debug, thiserror::Error)]
pub enum MergeError {
    #[error(transparent)]
    Read(#[from] FilmError),
    #[error("no parts given")]
    NoParts,
    #[error("{path}: {msg}")]
    Part { path: PathBuf, msg: String },
    #[error(
        "{a} and {b} are parts of different frames: {} (frame {} against {}); render every part from the same scene and volume",
        what_differs(&frames[0], &frames[1]),
        frame_name(&frames[0]),
        frame_name(&frames[1])
    )]
    OtherFrame {
        a: PathBuf,
        b: PathBuf,
        /// Boxed: two frame ids would make every merge result as large.
        frames: Box<[Option<FrameId>; 2]>,
    },
    #[error("{a} and {b} both cover pixel ({x}, {y})")]
    Overlap {
        a: PathBuf,
        b: PathBuf,
        x: u32,
        y: u32,
    },
    #[error(
        "the parts leave {count} of {total} pixels uncovered, the first at ({x}, {y}); a part is missing"
    )]
    Gap {
        count: u64,
        total: u64,
        x: u32,
        y: u32,
    },
    #[error(
        "the whole image ({width}x{height}, {channels} channels) needs {bytes} bytes, over the memory limit of {limit}"
    )]
    TooLarge {
        width: u32,
        height: u32,
        channels: usize,
        bytes: u64,
        limit: u64,
    },
}

/// A frame fingerprint as a message names it.
fn frame_name(frame: &Option<FrameId>) -> String {
    match frame {
        Some(f) => format!("{:016x}", f.hash),
        None => "unnamed (a whole frame's file, or a part from another program or an older snell)"
            .into(),
    }
}

/// What differs between two parts' frames, in words: the aspects whose
/// hashes differ when both parts carry them.
fn what_differs(a: &Option<FrameId>, b: &Option<FrameId>) -> String {
    // Each aspect in words, and whether the words are plural.
    let words = |aspect: &'static str| match aspect {
        "volume" => ("the volume's samples or spacing", false),
        "image" => ("the image size or background", false),
        "camera" => ("the camera", false),
        "surface" => ("the surface (filter, iso-value or ior)", false),
        "backdrop" => ("the backdrop", false),
        "render" => ("the [render] settings", true),
        other => (other, false),
    };
    let differ = match (a, b) {
        (Some(a), Some(b)) => a.differing(b),
        _ => None,
    };
    match differ.as_deref() {
        Some([]) | None => "scene settings or volume differ".into(),
        Some(names) => {
            let (names, plurals): (Vec<&str>, Vec<bool>) = names.iter().map(|&n| words(n)).unzip();
            let list = match names.as_slice() {
                [one] => one.to_string(),
                [rest @ .., last] => format!("{} and {last}", rest.join(", ")),
                [] => unreachable!("matched above"),
            };
            let plural = names.len() > 1 || plurals[0];
            format!("{list} {}", if plural { "differ" } else { "differs" })
        }
    }
}

/// Reads one part.
pub fn read_part(path: &Path) -> Result<Part, MergeError> {
    let bad = |msg: String| MergeError::Part {
        path: path.to_path_buf(),
        msg,
    };
    let image = super::read_exr_layer(path).map_err(|e| FilmError::Read {
        path: path.to_path_buf(),
        msg: format!("not a readable OpenEXR part ({e})"),
    })?;
    let display = image.attributes.display_window;
    let layer = &image.layer_data;
    let pos = layer.attributes.layer_position;
    if display.position.0 != 0 || display.position.1 != 0 {
        return Err(bad(format!(
            "display window starts at ({}, {}), not (0, 0)",
            display.position.0, display.position.1
        )));
    }
    let (full_w, full_h) = (display.size.0 as u64, display.size.1 as u64);
    let (w, h) = (layer.size.0 as u64, layer.size.1 as u64);
    if pos.0 < 0 || pos.1 < 0 || pos.0 as u64 + w > full_w || pos.1 as u64 + h > full_h {
        return Err(bad(format!(
            "data window {w}x{h} at ({}, {}) is not inside the {full_w}x{full_h} image",
            pos.0, pos.1
        )));
    }
    if full_w > u32::MAX as u64 || full_h > u32::MAX as u64 {
        return Err(bad(format!("image size {full_w}x{full_h} is too large")));
    }
    let mut channels: Vec<(String, Vec<f32>)> = layer
        .channel_data
        .list
        .iter()
        .map(|c| (c.name.to_string(), c.sample_data.values_as_f32().collect()))
        .collect();
    channels.sort_by(|a, b| a.0.cmp(&b.0));
    let frame = match layer
        .attributes
        .other
        .get(&exr::prelude::Text::from(FRAME_ATTRIBUTE))
    {
        None => None,
        Some(exr::prelude::AttributeValue::Text(t)) => {
            Some(FrameId::parse(&t.to_string()).ok_or_else(|| {
                bad(format!(
                    "its {FRAME_ATTRIBUTE} attribute '{t}' is not a frame fingerprint"
                ))
            })?)
        }
        Some(_) => {
            return Err(bad(format!("its {FRAME_ATTRIBUTE} attribute is not text")));
        }
    };
    Ok(Part {
        path: path.to_path_buf(),
        width: w as u32,
        height: h as u32,
        at: Placement {
            origin: [pos.0 as u32, pos.1 as u32],
            full: [full_w as u32, full_h as u32],
            frame,
        },
        channels,
    })
}

/// Joins parts into the whole image, refusing disagreeing parts, overlaps
/// and gaps, and images whose buffers would exceed `memory_limit` bytes.
pub fn merge(parts: &[Part], memory_limit: u64) -> Result<Merged, MergeError> {
    let first = parts.first().ok_or(MergeError::NoParts)?;
    let names: Vec<&str> = first.channels.iter().map(|c| c.0.as_str()).collect();
    for p in &parts[1..] {
        let bad = |msg: String| MergeError::Part {
            path: p.path.clone(),
            msg,
        };
        if p.at.full != first.at.full {
            return Err(bad(format!(
                "belongs to a {}x{} image, {} to a {}x{} one",
                p.at.full[0],
                p.at.full[1],
                first.path.display(),
                first.at.full[0],
                first.at.full[1]
            )));
        }
        if p.at.frame != first.at.frame {
            return Err(MergeError::OtherFrame {
                a: first.path.clone(),
                b: p.path.clone(),
                frames: Box::new([first.at.frame, p.at.frame]),
            });
        }
        let theirs: Vec<&str> = p.channels.iter().map(|c| c.0.as_str()).collect();
        if theirs != names {
            return Err(bad(format!(
                "has channels {}, {} has {}",
                theirs.join(", "),
                first.path.display(),
                names.join(", ")
            )));
        }
    }
    let [width, height] = first.at.full;
    let n = width as u64 * height as u64;
    // Saturating: a crafted part's display window and channel count can
    // overflow the product, which must then read as too large.
    let bytes = n.saturating_mul(4 * names.len() as u64 + 4);
    if bytes > memory_limit {
        return Err(MergeError::TooLarge {
            width,
            height,
            channels: names.len(),
            bytes,
            limit: memory_limit,
        });
    }
    // Which part owns each pixel (u32::MAX: none yet).
    let mut owner = vec![u32::MAX; n as usize];
    let mut channels: Vec<(String, Vec<f32>)> = names
        .iter()
        .map(|&name| (name.to_string(), vec![0.0f32; n as usize]))
        .collect();
    for (k, p) in parts.iter().enumerate() {
        let [ox, oy] = p.at.origin;
        for row in 0..p.height {
            let dst = ((oy + row) as usize) * width as usize + ox as usize;
            let src = row as usize * p.width as usize;
            let span = dst..dst + p.width as usize;
            if let Some(i) = owner[span.clone()].iter().position(|&o| o != u32::MAX) {
                return Err(MergeError::Overlap {
                    a: parts[owner[dst + i] as usize].path.clone(),
                    b: p.path.clone(),
                    x: ox + i as u32,
                    y: oy + row,
                });
            }
            owner[span.clone()].fill(k as u32);
            for (out, (_, data)) in channels.iter_mut().zip(&p.channels) {
                out.1[span.clone()].copy_from_slice(&data[src..src + p.width as usize]);
            }
        }
    }
    let gaps = owner.iter().filter(|&&o| o == u32::MAX).count() as u64;
    if gaps > 0 {
        let i = owner.iter().position(|&o| o == u32::MAX).unwrap_or(0);
        return Err(MergeError::Gap {
            count: gaps,
            total: n,
            x: (i % width as usize) as u32,
            y: (i / width as usize) as u32,
        });
    }
    Ok(Merged {
        width,
        height,
        channels,
    })
}

impl Merged {
    /// The whole image as one EXR with the parts' channels. Without the
    /// parts' frame fingerprint: it is a whole frame, written as `render`
    /// writes one, so the merge of all parts is byte for byte the file a
    /// render of the whole frame writes.
    pub fn write_exr(&self, path: &Path) -> Result<(), FilmError> {
        let whole = Placement {
            origin: [0, 0],
            full: [self.width, self.height],
            frame: None,
        };
        let channels = self
            .channels
            .iter()
            .map(|(n, d)| (n.as_str(), d.clone()))
            .collect();
        write_exr_placed(path, self.width, self.height, whole, channels)
    }

    fn channel(&self, name: &str) -> Option<&[f32]> {
        self.channels
            .iter()
            .find(|c| c.0 == name)
            .map(|c| c.1.as_slice())
    }

    /// The parts were colour images (`R`, `G`, `B` channels).
    pub fn has_color(&self) -> bool {
        ["R", "G", "B"].iter().all(|c| self.channel(c).is_some())
    }

    /// An 8-bit PNG of the `R`, `G`, `B` channels; black where they are
    /// missing (hit-position parts: check [`Merged::has_color`] first).
    pub fn write_png(&self, path: &Path) -> Result<(), FilmError> {
        let n = self.width as usize * self.height as usize;
        let zeros = vec![0.0f32; n];
        let [r, g, b] = ["R", "G", "B"].map(|c| self.channel(c).unwrap_or(&zeros));
        let bytes: Vec<u8> = (0..n)
            .flat_map(|i| [to_u8(r[i]), to_u8(g[i]), to_u8(b[i])])
            .collect();
        write_png_rgb(path, self.width, self.height, &bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn part(name: &str, origin: [u32; 2], w: u32, h: u32, full: [u32; 2]) -> Part {
        let n = (w * h) as usize;
        Part {
            path: PathBuf::from(name),
            width: w,
            height: h,
            at: Placement {
                origin,
                full,
                frame: None,
            },
            channels: vec![(
                "v".into(),
                (0..n)
                    .map(|i| {
                        ((origin[1] + i as u32 / w) * full[0] + origin[0] + i as u32 % w) as f32
                    })
                    .collect(),
            )],
        }
    }

    /// The refusal names the differing aspects in words, with the verb
    /// agreeing; parts without aspects get the general words.
    #[test]
    fn what_differs_names_the_aspects() {
        let id = |a: [u64; 6]| Some(FrameId::of_aspects(a));
        let base = id([1; 6]);
        let said = |other| what_differs(&base, &other);
        assert_eq!(
            said(id([1, 1, 1, 2, 1, 1])),
            "the surface (filter, iso-value or ior) differs"
        );
        assert_eq!(said(id([1, 1, 1, 1, 1, 2])), "the [render] settings differ");
        assert_eq!(
            said(id([2, 1, 2, 1, 2, 1])),
            "the volume's samples or spacing, the camera and the backdrop differ"
        );
        let old = Some(FrameId {
            hash: 5,
            aspects: None,
        });
        assert_eq!(said(old), "scene settings or volume differ");
    }

    #[test]
    fn parts_join_in_place_and_gaps_or_overlaps_are_errors() {
        let full = [5, 3];
        let parts = [
            part("a", [0, 0], 2, 3, full),
            part("b", [2, 0], 3, 1, full),
            part("c", [2, 1], 3, 2, full),
        ];
        let m = merge(&parts, u64::MAX).unwrap();
        assert_eq!(
            m.channels[0].1,
            (0..15).map(|i| i as f32).collect::<Vec<_>>()
        );
        let e = merge(&parts[..2], u64::MAX).unwrap_err().to_string();
        assert!(
            e.contains("6 of 15 pixels uncovered, the first at (2, 1)"),
            "{e}"
        );
        let dup = [
            parts[0].clone(),
            parts[1].clone(),
            part("d", [1, 1], 2, 1, full),
        ];
        let e = merge(&dup, u64::MAX).unwrap_err().to_string();
        assert!(e.contains("a and d both cover pixel (1, 1)"), "{e}");
        let other = [parts[0].clone(), part("e", [2, 0], 3, 3, [6, 3])];
        let e = merge(&other, u64::MAX).unwrap_err().to_string();
        assert!(e.starts_with("e: belongs to a 6x3 image"), "{e}");
        let e = merge(&parts, 10).unwrap_err().to_string();
        assert!(e.contains("over the memory limit"), "{e}");
        assert!(matches!(merge(&[], 1), Err(MergeError::NoParts)));
        // Channel lists in words, not Rust's debug form.
        let mut rgb = part("f", [2, 0], 3, 1, full);
        rgb.channels = ["B", "G", "R"]
            .map(|c| (c.to_string(), vec![0.0; 3]))
            .to_vec();
        let e = merge(&[parts[0].clone(), rgb], u64::MAX)
            .unwrap_err()
            .to_string();
        assert_eq!(e, "f: has channels B, G, R, a has v");
    }
}
