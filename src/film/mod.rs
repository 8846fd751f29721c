//! The film: per-pixel results of a frame, and their files.
//!
//! - the hit-position image of SPEC.md (`u`, `v`, `events`, 32-bit float EXR):
//!   where each pixel-centre ray lands on the backdrop, NaN where it never does
//!   (the input of PRSS, and how accuracy is checked);
//! - the colour image, written as 8-bit PNG and optionally float EXR.
//!
//! Every file is written atomically (see [`crate::atomic`]).

pub mod footprint;
pub(crate) mod hitmap;
mod interior;
pub mod merge;
pub mod metrics;
pub mod photo;
pub mod prss;

use std::marker::PhantomData;
use std::path::{Path, PathBuf};

use exr::prelude::{
    AnyChannel, AnyChannels, AttributeValue, Encoding, FlatSamples, Image, ImageAttributes,
    IntegerBounds, Layer, LayerAttributes, SmallVec, Text, Vec2, WritableImage,
};

use crate::atomic::write_atomic;
use crate::render::tile::{Pixels, Region, Tile, TileOut};
use crate::volume::limits::{default_memory_limit, human_bytes};

/// Reads an EXR's first flat layer with all its channels, from a file
/// opened as every input is ([`crate::input::open`]). The headers are read
/// first and an image whose samples would not fit the memory limit
/// ([`default_memory_limit`]) is refused before any of them is allocated:
/// a header of a few hundred bytes can claim a data window of terapixels,
/// and the reader would allocate it at once.
pub(crate) fn read_exr_layer(
    path: &Path,
) -> Result<Image<Layer<AnyChannels<FlatSamples>>>, String> {
    use exr::image::read::{image::ReadLayers, layers::ReadChannels};
    use std::io::{Seek, SeekFrom};
    let file = crate::input::open(path).map_err(|e| e.to_string())?;
    let mut reader = std::io::BufReader::new(file);
    let meta =
        exr::meta::MetaData::read_from_buffered(&mut reader, false).map_err(|e| e.to_string())?;
    let limit = default_memory_limit();
    for header in &meta.headers {
        let size = header.layer_size;
        let channels = header.channels.list.len() as u64;
        // The reader's samples (at most 4 bytes each) and the 32-bit copy
        // the callers take of them.
        let need = (size.0 as u64)
            .saturating_mul(size.1 as u64)
            .saturating_mul(channels)
            .saturating_mul(8);
        if need > limit {
            return Err(format!(
                "an image of {}x{} pixels with {channels} channels needs about {} of memory to read, over the limit of {} (--memory-limit or SNELL_MEMORY_LIMIT raises it)",
                size.0,
                size.1,
                human_bytes(need),
                human_bytes(limit)
            ));
        }
    }
    reader.seek(SeekFrom::Start(0)).map_err(|e| e.to_string())?;
    exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(reader)
        .map_err(|e| e.to_string())
}

#[derive(Debug, thiserror::Error)]
pub enum FilmError {
    #[error("{path}: {msg}")]
    Write { path: PathBuf, msg: String },
    #[error("{path}: {msg}")]
    Read { path: PathBuf, msg: String },
}

/// Per-pixel buffers of a frame, row-major, row 0 at the top.
///
/// A film covers a window of the image: all of it for a whole frame, or a
/// rectangle at `origin` of a `full`-sized image (a `--region` render, one
/// part of a frame split across machines). Its EXR files carry the window as
/// OpenEXR's data window inside the full display window, so `snell merge`
/// (and any compositor) puts the parts back in place.
#[derive(Clone, Debug)]
pub struct Film {
    pub width: u32,
    pub height: u32,
    /// Top-left pixel of this film in the image.
    pub origin: [u32; 2],
    /// Size of the whole image.
    pub full: [u32; 2],
    pub u: Vec<f32>,
    pub v: Vec<f32>,
    pub events: Vec<f32>,
    pub color: Vec<[f32; 3]>,
}

/// A tile's rectangle of a [`Film`], written in place by the tile pass
/// ([`Film::tile_targets`]): row `r`, column `c` of the rectangle is
/// element `r · stride + c` from its first pixel in each buffer.
pub struct TileTarget<'f> {
    u: *mut f32,
    v: *mut f32,
    events: *mut f32,
    color: *mut [f32; 3],
    /// The film's row length.
    stride: usize,
    width: usize,
    height: usize,
    colours: bool,
    _film: PhantomData<&'f mut Film>,
}

// SAFETY: a target reads and writes only inside its rectangle (every access
// checks the row and column against it), the rectangles of one
// `Film::tile_targets` call are disjoint (checked there), and the film's
// buffers outlive the targets (borrowed mutably for `'f`): targets on
// different threads never touch the same value.
unsafe impl Send for TileTarget<'_> {}

impl TileTarget<'_> {
    /// The element of the pixel at `row`, `col` of the rectangle.
    ///
    /// # Panics
    /// When the pixel lies outside the rectangle. This check is what makes
    /// the safe writers below sound: keep it an `assert!`.
    #[inline(always)]
    fn at(&self, row: usize, col: usize) -> usize {
        assert!(
            row < self.height && col < self.width,
            "pixel outside the tile"
        );
        row * self.stride + col
    }

    /// Whether the tile records colours here.
    pub fn colours(&self) -> bool {
        self.colours
    }

    /// Sets the rectangle's pixels to a tile's starting values: no hit
    /// (NaN), no events, and black where colours are recorded.
    pub fn clear(&mut self) {
        for row in 0..self.height {
            for col in 0..self.width {
                self.set_hit(row, col, [f32::NAN, f32::NAN, 0.0]);
                if self.colours {
                    let i = self.at(row, col);
                    // SAFETY: `i` is a pixel of the rectangle (`at`), which
                    // lies in the film's buffers and is this target's alone.
                    unsafe { *self.color.add(i) = [0.0; 3] };
                }
            }
        }
    }

    /// Writes the hit position and event count `[u, v, events]` of the
    /// pixel at `row`, `col`.
    #[inline(always)]
    pub fn set_hit(&mut self, row: usize, col: usize, [u, v, events]: [f32; 3]) {
        let i = self.at(row, col);
        // SAFETY: as in `clear`.
        unsafe {
            *self.u.add(i) = u;
            *self.v.add(i) = v;
            *self.events.add(i) = events;
        }
    }

    /// Adds `weight · color` to the pixel at `row`, `col` (only where the
    /// target records colours).
    #[inline(always)]
    pub fn add_color(&mut self, row: usize, col: usize, weight: f32, color: [f32; 3]) {
        if !self.colours {
            return;
        }
        let i = self.at(row, col);
        // SAFETY: as in `clear`.
        let c = unsafe { &mut *self.color.add(i) };
        for k in 0..3 {
            c[k] += weight * color[k];
        }
    }
}

/// Whether `tiles` come in bands of rows, as [`crate::render::tile::tiles`]
/// orders them: runs of rectangles on the same rows, each left to right
/// without overlap, the runs top to bottom without overlap. No two such
/// rectangles share a pixel.
fn in_bands(tiles: &[Tile]) -> bool {
    let bands: Vec<&[Tile]> = tiles
        .chunk_by(|a, b| (a.y0, a.y1) == (b.y0, b.y1))
        .collect();
    bands.windows(2).all(|b| b[0][0].y1 <= b[1][0].y0)
        && bands
            .iter()
            .all(|run| run.windows(2).all(|t| t[0].x1 <= t[1].x0))
}

/// The hit-position image alone (what `compare` reads back).
#[derive(Clone, Debug, PartialEq)]
pub struct HitImage {
    pub width: u32,
    pub height: u32,
    pub u: Vec<f32>,
    pub v: Vec<f32>,
    pub events: Vec<f32>,
}

impl Film {
    /// A whole-image film.
    pub fn new(width: u32, height: u32) -> Film {
        Film::window(
            Tile {
                x0: 0,
                y0: 0,
                x1: width,
                y1: height,
            },
            [width, height],
        )
    }

    /// A film for the pixels of `window` in an image of size `full`.
    pub fn window(window: Tile, full: [u32; 2]) -> Film {
        let (width, height) = (window.width(), window.height());
        let n = (width as usize) * (height as usize);
        Film {
            width,
            height,
            origin: [window.x0, window.y0],
            full,
            u: vec![f32::NAN; n],
            v: vec![f32::NAN; n],
            events: vec![0.0; n],
            color: vec![[0.0; 3]; n],
        }
    }

    /// A film for the tile pass over `window` of an image of size `full`,
    /// its buffers zeroed but not yet written: fresh pages, which the tiles
    /// fault in as they write their own rectangles ([`Film::tile_targets`])
    /// in parallel, where [`Film::window`]'s fills would first touch every
    /// page on one thread.
    pub fn for_tiles(window: Tile, full: [u32; 2]) -> Film {
        let n = (window.width() as usize) * (window.height() as usize);
        Film {
            width: window.width(),
            height: window.height(),
            origin: [window.x0, window.y0],
            full,
            u: vec![0.0; n],
            v: vec![0.0; n],
            events: vec![0.0; n],
            color: vec![[0.0; 3]; n],
        }
    }

    /// The rectangles `tiles` of the film (image coordinates, inside its
    /// window), each to be written in place by one tile, with colours if
    /// `colours`. The tiles must come in bands of rows as
    /// [`crate::render::tile::tiles`] orders them (a run of rectangles on
    /// the same rows, left to right without overlap, the runs top to bottom
    /// without overlap): then no two share a pixel, and tiles running in
    /// parallel write the film without a copy.
    ///
    /// # Panics
    /// When a rectangle lies outside the window or the tiles are not in
    /// such bands.
    pub fn tile_targets(&mut self, tiles: &[Tile], colours: bool) -> Vec<TileTarget<'_>> {
        let [ox, oy] = self.origin;
        let inside = |t: &Tile| {
            t.x0 >= ox
                && t.y0 >= oy
                && t.x1 <= ox + self.width
                && t.y1 <= oy + self.height
                && t.x0 < t.x1
                && t.y0 < t.y1
        };
        assert!(tiles.iter().all(inside), "a tile outside the film's window");
        assert!(in_bands(tiles), "tiles in bands of rows, without overlap");
        let stride = self.width as usize;
        let (u, v) = (self.u.as_mut_ptr(), self.v.as_mut_ptr());
        let (events, color) = (self.events.as_mut_ptr(), self.color.as_mut_ptr());
        tiles
            .iter()
            .map(|t| {
                let at = (t.y0 - oy) as usize * stride + (t.x0 - ox) as usize;
                // In bounds: the rectangle lies inside the window (checked
                // above), so its first pixel is one of the buffers'.
                TileTarget {
                    u: u.wrapping_add(at),
                    v: v.wrapping_add(at),
                    events: events.wrapping_add(at),
                    color: color.wrapping_add(at),
                    stride,
                    width: t.width() as usize,
                    height: t.height() as usize,
                    colours,
                    _film: PhantomData,
                }
            })
            .collect()
    }

    /// Copies a tile's own pixels into place (hit positions only where the
    /// tile traced pixel-centre rays, colours only where it recorded them);
    /// a tile that wrote the film in place has nothing to copy.
    ///
    /// Tiles are in image coordinates and must lie inside the film's window.
    pub fn blit(&mut self, t: &TileOut, with_hits: bool) {
        let Pixels::Own(own) = &t.pixels else {
            return;
        };
        let [ox, oy] = [self.origin[0] as usize, self.origin[1] as usize];
        let (w, full_w) = (self.width as usize, self.full[0] as usize);
        let mut put = |src: usize, dst: usize, len: usize| {
            if with_hits {
                self.u[dst..dst + len].copy_from_slice(&own.u[src..src + len]);
                self.v[dst..dst + len].copy_from_slice(&own.v[src..src + len]);
                self.events[dst..dst + len].copy_from_slice(&own.events[src..src + len]);
            }
            if let Some(c) = &own.color {
                self.color[dst..dst + len].copy_from_slice(&c[src..src + len]);
            }
        };
        match &t.region {
            Region::Rect(tile) => {
                let tw = tile.width() as usize;
                for row in 0..tile.height() as usize {
                    let dst = (tile.y0 as usize - oy + row) * w + tile.x0 as usize - ox;
                    put(row * tw, dst, tw);
                }
            }
            Region::List(pixels) => {
                for (k, &p) in pixels.iter().enumerate() {
                    let p = p as usize;
                    put(k, (p / full_w - oy) * w + p % full_w - ox, 1);
                }
            }
        }
    }

    /// The pixels of `window` (image coordinates, inside this film's window)
    /// as a film of their own.
    pub fn crop(&self, window: Tile) -> Film {
        let [ox, oy] = self.origin;
        assert!(
            window.x0 >= ox
                && window.y0 >= oy
                && window.x1 <= ox + self.width
                && window.y1 <= oy + self.height,
            "crop window outside the film"
        );
        let rows = |buf: &[f32]| -> Vec<f32> { self.crop_rows(buf, window) };
        let mut out = Film::window(window, self.full);
        out.u = rows(&self.u);
        out.v = rows(&self.v);
        out.events = rows(&self.events);
        out.color = self.crop_rows(&self.color, window);
        out
    }

    fn crop_rows<T: Copy>(&self, buf: &[T], window: Tile) -> Vec<T> {
        let (x0, w) = (
            (window.x0 - self.origin[0]) as usize,
            window.width() as usize,
        );
        (window.y0..window.y1)
            .flat_map(|y| {
                let start = (y - self.origin[1]) as usize * self.width as usize + x0;
                buf[start..start + w].iter().copied()
            })
            .collect()
    }

    /// The film's place in the image, for its EXR files: in the frame
    /// `frame`, when given ([`Placement::frame`]).
    fn placement(&self, frame: Option<FrameId>) -> Placement {
        Placement {
            origin: self.origin,
            full: self.full,
            frame,
        }
    }

    pub fn hits(&self) -> HitImage {
        HitImage {
            width: self.width,
            height: self.height,
            u: self.u.clone(),
            v: self.v.clone(),
            events: self.events.clone(),
        }
    }

    /// 8-bit RGB PNG of the colour image (values clamped to [0, 1]).
    pub fn write_png(&self, path: &Path) -> Result<(), FilmError> {
        let bytes: Vec<u8> = self.color.iter().flat_map(|c| c.map(to_u8)).collect();
        write_png_rgb(path, self.width, self.height, &bytes)
    }

    /// Float RGB EXR of the colour image (of the frame `frame`, when given:
    /// [`Placement::frame`]).
    pub fn write_color_exr(&self, path: &Path, frame: Option<FrameId>) -> Result<(), FilmError> {
        let c = |k: usize| self.color.iter().map(|p| p[k]).collect::<Vec<f32>>();
        write_exr_placed(
            path,
            self.width,
            self.height,
            self.placement(frame),
            vec![("R", c(0)), ("G", c(1)), ("B", c(2))],
        )
    }

    /// The SPEC.md hit-position EXR (of the frame `frame`, when given:
    /// [`Placement::frame`]).
    pub fn write_hits_exr(&self, path: &Path, frame: Option<FrameId>) -> Result<(), FilmError> {
        write_exr_placed(
            path,
            self.width,
            self.height,
            self.placement(frame),
            vec![
                ("u", self.u.clone()),
                ("v", self.v.clone()),
                ("events", self.events.clone()),
            ],
        )
    }
}

/// Where an EXR's pixels (its data window) sit in the whole image (its
/// display window).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Placement {
    pub origin: [u32; 2],
    pub full: [u32; 2],
    /// The frame a part belongs to ([`crate::scene::Scene::frame_fingerprint`]),
    /// written as the layer attribute [`FRAME_ATTRIBUTE`],
    /// so that `snell merge` refuses parts of different frames.
    pub frame: Option<FrameId>,
}

/// The EXR layer attribute that names a part's frame ([`Placement::frame`]).
pub const FRAME_ATTRIBUTE: &str = "snellFrame";

/// The aspects of a scene a [`FrameId`] hashes one by one, in the order its
/// text lists them.
pub const FRAME_ASPECTS: [&str; 6] = ["volume", "image", "camera", "surface", "backdrop", "render"];

/// Which frame a part of a split render belongs to: a hash of the whole
/// frame and one of each of its [`FRAME_ASPECTS`], so that a merge of parts
/// from different frames can say what differs (a job that rendered its part
/// with another ior names the surface, not two opaque numbers).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameId {
    pub hash: u64,
    /// One hash per [`FRAME_ASPECTS`] entry; `None` for a part that carries
    /// the whole frame's hash alone (written by snell before the aspects).
    pub aspects: Option<[u64; FRAME_ASPECTS.len()]>,
}

impl FrameId {
    /// The id of a frame whose aspects hash to `aspects`.
    pub fn of_aspects(aspects: [u64; FRAME_ASPECTS.len()]) -> FrameId {
        let mut h = crate::volume::WordHash::new();
        for a in aspects {
            h.add(a);
        }
        FrameId {
            hash: h.value(),
            aspects: Some(aspects),
        }
    }

    /// The aspects whose hashes differ between `self` and `other`, when
    /// both carry them.
    pub fn differing(&self, other: &FrameId) -> Option<Vec<&'static str>> {
        let (a, b) = (self.aspects?, other.aspects?);
        Some(
            FRAME_ASPECTS
                .iter()
                .zip(a.iter().zip(&b))
                .filter(|(_, (x, y))| x != y)
                .map(|(name, _)| *name)
                .collect(),
        )
    }

    /// Reads the attribute's text: the frame's hash in hexadecimal, then
    /// `aspect=hash` for each of [`FRAME_ASPECTS`] in order (or nothing
    /// more, as older parts were written). `None` for any other text.
    pub fn parse(text: &str) -> Option<FrameId> {
        let hex = |t: &str| {
            (!t.is_empty() && t.len() <= 16 && t.bytes().all(|b| b.is_ascii_hexdigit()))
                .then(|| u64::from_str_radix(t, 16).ok())
                .flatten()
        };
        let mut words = text.split(' ');
        let hash = hex(words.next()?)?;
        let rest: Vec<&str> = words.collect();
        if rest.is_empty() {
            return Some(FrameId {
                hash,
                aspects: None,
            });
        }
        if rest.len() != FRAME_ASPECTS.len() {
            return None;
        }
        let mut aspects = [0; FRAME_ASPECTS.len()];
        for ((slot, word), name) in aspects.iter_mut().zip(rest).zip(FRAME_ASPECTS) {
            *slot = hex(word.strip_prefix(name)?.strip_prefix('=')?)?;
        }
        Some(FrameId {
            hash,
            aspects: Some(aspects),
        })
    }
}

impl std::fmt::Display for FrameId {
    /// The attribute's text ([`FrameId::parse`] reads it back).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:016x}", self.hash)?;
        if let Some(aspects) = self.aspects {
            for (name, a) in FRAME_ASPECTS.iter().zip(aspects) {
                write!(f, " {name}={a:016x}")?;
            }
        }
        Ok(())
    }
}

impl HitImage {
    pub fn write_exr(&self, path: &Path) -> Result<(), FilmError> {
        write_exr_channels(
            path,
            self.width,
            self.height,
            vec![
                ("u", self.u.clone()),
                ("v", self.v.clone()),
                ("events", self.events.clone()),
            ],
        )
    }

    /// Reads a hit-position EXR (channels `u`, `v`, `events`).
    pub fn read_exr(path: &Path) -> Result<HitImage, FilmError> {
        Ok(HitImage::read_exr_placed(path)?.0)
    }

    /// [`HitImage::read_exr`] with the position of its first pixel in the
    /// frame (the EXR's data window): a part rendered with `--region`
    /// starts where its region does.
    pub fn read_exr_placed(path: &Path) -> Result<(HitImage, [i32; 2]), FilmError> {
        HitImage::read_exr_if_hits(path)?.ok_or_else(|| FilmError::Read {
            path: path.to_path_buf(),
            msg: "no channels u, v, events (not a hit-position image)".into(),
        })
    }

    /// [`HitImage::read_exr_placed`] for an EXR that may hold something
    /// else: `None` if it lacks any of the channels `u`, `v`, `events` (a
    /// colour image), an error only if it is not a readable EXR.
    pub fn read_exr_if_hits(path: &Path) -> Result<Option<(HitImage, [i32; 2])>, FilmError> {
        let image = read_exr_layer(path).map_err(|e| FilmError::Read {
            path: path.to_path_buf(),
            msg: e.to_string(),
        })?;
        let layer = &image.layer_data;
        let size = layer.size;
        let channel = |name: &str| -> Option<Vec<f32>> {
            layer
                .channel_data
                .list
                .iter()
                .find(|c| c.name.eq(name))
                .map(|c| c.sample_data.values_as_f32().collect())
        };
        let (Some(u), Some(v), Some(events)) = (channel("u"), channel("v"), channel("events"))
        else {
            return Ok(None);
        };
        let hits = HitImage {
            width: size.width() as u32,
            height: size.height() as u32,
            u,
            v,
            events,
        };
        let at = layer.attributes.layer_position;
        Ok(Some((hits, [at.x(), at.y()])))
    }
}

/// A colour value to 8 bits (clamped to [0, 1], rounded).
pub(crate) fn to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Writes an 8-bit RGB PNG atomically.
pub fn write_png_rgb(path: &Path, width: u32, height: u32, rgb: &[u8]) -> Result<(), FilmError> {
    use image::ImageEncoder;
    write_atomic(path, |w| {
        image::codecs::png::PngEncoder::new(w)
            .write_image(rgb, width, height, image::ExtendedColorType::Rgb8)
            .map_err(std::io::Error::other)
    })
    .map_err(|e| FilmError::Write {
        path: path.to_path_buf(),
        msg: e.to_string(),
    })
}

/// Writes named 32-bit float channels as a single-layer EXR atomically.
pub fn write_exr_channels(
    path: &Path,
    width: u32,
    height: u32,
    channels: Vec<(&str, Vec<f32>)>,
) -> Result<(), FilmError> {
    let whole = Placement {
        origin: [0, 0],
        full: [width, height],
        frame: None,
    };
    write_exr_placed(path, width, height, whole, channels)
}

/// [`write_exr_channels`] for a `width × height` window of a larger image:
/// the data window at `at.origin` inside a display window of `at.full`.
pub fn write_exr_placed(
    path: &Path,
    width: u32,
    height: u32,
    at: Placement,
    channels: Vec<(&str, Vec<f32>)>,
) -> Result<(), FilmError> {
    let list: SmallVec<[AnyChannel<FlatSamples>; 4]> = channels
        .into_iter()
        .map(|(name, data)| AnyChannel::new(name, FlatSamples::F32(data)))
        .collect();
    let mut attributes = LayerAttributes::named("snell");
    attributes.layer_position = Vec2(at.origin[0] as i32, at.origin[1] as i32);
    if let Some(frame) = at.frame {
        attributes.other.insert(
            Text::from(FRAME_ATTRIBUTE),
            AttributeValue::Text(Text::from(frame.to_string().as_str())),
        );
    }
    let layer = Layer::new(
        (width as usize, height as usize),
        attributes,
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(list),
    );
    let display = IntegerBounds::from_dimensions((at.full[0] as usize, at.full[1] as usize));
    let image = Image::new(ImageAttributes::new(display), layer);
    write_atomic(path, |w| {
        image
            .write()
            .to_buffered(w)
            .map_err(|e| std::io::Error::other(e.to_string()))
    })
    .map_err(|e| FilmError::Write {
        path: path.to_path_buf(),
        msg: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::tile::tiles;

    /// A frame id reads back from its text, an older part's bare hash
    /// reads as a hash without aspects, and any other text is refused.
    #[test]
    fn frame_ids_read_back_and_name_what_differs() {
        let a = FrameId::of_aspects([1, 2, 3, 4, 5, u64::MAX]);
        let text = a.to_string();
        assert!(
            text.ends_with(
                " surface=0000000000000004 backdrop=0000000000000005 render=ffffffffffffffff"
            ),
            "{text}"
        );
        assert_eq!(FrameId::parse(&text), Some(a));
        let old = FrameId::parse("00ab");
        assert_eq!(
            old,
            Some(FrameId {
                hash: 0xab,
                aspects: None
            })
        );
        let b = FrameId::of_aspects([1, 2, 7, 4, 5, 0]);
        assert_ne!(a.hash, b.hash);
        assert_eq!(a.differing(&b), Some(vec!["camera", "render"]));
        assert_eq!(a.differing(&a), Some(vec![]));
        assert_eq!(a.differing(&old.unwrap()), None);
        let words: Vec<&str> = text.split(' ').collect();
        for bad in [
            String::new(),
            "xyz".into(),
            "+1".into(),
            "0123456789abcdef0".into(),
            words[..3].join(" "),
            format!("{text} extra=1"),
            text.replace("camera=", "lens="),
            text.replace("render=", "render:"),
            text.replace(' ', "  "),
        ] {
            assert_eq!(FrameId::parse(&bad), None, "{bad:?}");
        }
    }

    /// A tile output whose every value says which pixel and tile it is.
    fn tile_out(region: Region, full_width: u32, tag: f32, colours: bool) -> TileOut<'static> {
        let mut px = Vec::new();
        region.for_each_pixel(full_width, |x, y| px.push((y * full_width + x) as f32));
        let mut out = TileOut::owning(region, colours);
        let Pixels::Own(own) = &mut out.pixels else {
            unreachable!("an owning tile")
        };
        own.u = px.clone();
        own.v = px.iter().map(|p| -p).collect();
        own.events = vec![tag; px.len()];
        own.color = colours.then(|| px.iter().map(|&p| [p, tag, 1.0]).collect());
        out
    }

    /// The rectangles of a pass written in place through their targets give
    /// the film that copying each tile's own pixels gives: whole images and
    /// windows (whose tiles are cut at the window, as a `--region` render's
    /// are), with and without colours, every pixel written. Lists of pixels
    /// are copied.
    #[test]
    fn tiles_written_in_place_are_tiles_copied() {
        let full = [53u32, 41];
        let windows = [
            Tile {
                x0: 0,
                y0: 0,
                x1: 53,
                y1: 41,
            },
            Tile {
                x0: 5,
                y0: 3,
                x1: 40,
                y1: 38,
            },
            Tile {
                x0: 7,
                y0: 17,
                x1: 8,
                y1: 18,
            },
        ];
        for window in windows {
            for (size, colours) in [(16, false), (7, true), (1, true)] {
                let rects: Vec<Tile> = tiles(full[0], full[1], size)
                    .into_iter()
                    .filter_map(|t| t.intersect(&window))
                    .collect();
                let mut copied = Film::window(window, full);
                for (k, t) in rects.iter().enumerate() {
                    copied.blit(
                        &tile_out(Region::Rect(*t), full[0], k as f32, colours),
                        true,
                    );
                }
                let mut in_place = Film::for_tiles(window, full);
                for (k, mut target) in in_place
                    .tile_targets(&rects, colours)
                    .into_iter()
                    .enumerate()
                {
                    target.clear();
                    let t = rects[k];
                    for row in 0..t.height() as usize {
                        for col in 0..t.width() as usize {
                            let p = ((t.y0 as usize + row) * full[0] as usize + t.x0 as usize + col)
                                as f32;
                            target.set_hit(row, col, [p, -p, k as f32]);
                            target.add_color(row, col, 1.0, [p, k as f32, 1.0]);
                        }
                    }
                }
                let bits = |f: &Film| {
                    let b = |x: &[f32]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                    let c: Vec<f32> = f.color.iter().flatten().copied().collect();
                    (b(&f.u), b(&f.v), b(&f.events), b(&c))
                };
                assert_eq!(bits(&copied), bits(&in_place), "{window:?} tile {size}");
                assert!(copied.u.iter().all(|u| !u.is_nan()), "every pixel written");
            }
        }
        // A list of pixels after the rectangles: copied.
        let mut film = Film::new(full[0], full[1]);
        film.blit(
            &tile_out(Region::List(vec![3, 60, 2000]), full[0], 9.0, true),
            true,
        );
        assert_eq!(film.events[60], 9.0);
        assert_eq!(film.u[2000], 2000.0);
        assert_eq!(film.color[3], [3.0, 9.0, 1.0]);
    }

    /// Targets refuse pixels outside their rectangle, and a pass's
    /// rectangles must not overlap.
    #[test]
    fn targets_stay_in_their_rectangles() {
        let t = |x0, y0, x1, y1| Tile { x0, y0, x1, y1 };
        assert!(in_bands(&[t(0, 0, 4, 2), t(4, 0, 9, 2), t(0, 2, 9, 5)]));
        assert!(
            !in_bands(&[t(0, 0, 5, 2), t(4, 0, 9, 2)]),
            "overlap in a row"
        );
        assert!(
            !in_bands(&[t(0, 0, 9, 3), t(0, 2, 9, 5)]),
            "overlapping rows"
        );
        assert!(
            !in_bands(&[t(0, 2, 9, 5), t(0, 0, 9, 2)]),
            "rows out of order"
        );
        let mut film = Film::for_tiles(t(0, 0, 9, 5), [9, 5]);
        let mut targets = film.tile_targets(&[t(0, 0, 4, 2), t(4, 0, 9, 2)], false);
        targets[1].set_hit(1, 4, [1.0, 2.0, 3.0]);
        let outside = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            targets[0].set_hit(0, 4, [1.0, 2.0, 3.0])
        }));
        assert!(outside.is_err(), "column 4 lies in the next tile");
        drop(targets);
        assert_eq!(film.events[9 + 8], 3.0);
        let overlapping = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            film.tile_targets(&[t(0, 0, 5, 2), t(4, 0, 9, 2)], false)
                .len()
        }));
        assert!(overlapping.is_err());
    }

    #[test]
    fn hits_round_trip_with_nan() {
        let dir = std::env::temp_dir().join(format!("snell-film-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut f = Film::new(3, 2);
        f.u = vec![0.5, f32::NAN, -2.0, 1e6, 0.0, 3.25];
        f.v = vec![1.0, f32::NAN, 2.0, -1e-6, 0.0, 7.0];
        f.events = vec![2.0, 32.0, 0.0, 4.0, 0.0, 1.0];
        let p = dir.join("hits.exr");
        f.write_hits_exr(&p, None).unwrap();
        let h = HitImage::read_exr(&p).unwrap();
        assert_eq!((h.width, h.height), (3, 2));
        assert_eq!(h.events, f.events);
        for (read, wrote) in [(&h.u, &f.u), (&h.v, &f.v)] {
            assert_eq!(read.len(), wrote.len());
            for (a, b) in read.iter().zip(wrote) {
                assert!(
                    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                    "{a} {b}"
                );
            }
        }
        f.write_png(&dir.join("c.png")).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
