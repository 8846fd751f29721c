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
pub mod prss;

use std::path::{Path, PathBuf};

use exr::prelude::{
    AnyChannel, AnyChannels, Encoding, FlatSamples, Image, ImageAttributes, IntegerBounds, Layer,
    LayerAttributes, SmallVec, Vec2, WritableImage, read_first_flat_layer_from_file,
};

use crate::atomic::write_atomic;
use crate::render::tile::{Region, Tile, TileOut};

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

/// Consecutive whole rows of a film's buffers, from image row `origin[1]`
/// (the film's own column origin `origin[0]`), to copy tiles into.
struct RowsMut<'a> {
    width: usize,
    full_width: usize,
    origin: [usize; 2],
    u: &'a mut [f32],
    v: &'a mut [f32],
    events: &'a mut [f32],
    color: &'a mut [[f32; 3]],
}

impl<'a> RowsMut<'a> {
    /// The rows before image row `y` and the rows from it on (`y` at or
    /// past these rows' first, and at most one past their last).
    fn split_at_row(self, y: u32) -> (RowsMut<'a>, RowsMut<'a>) {
        let rows = y as usize - self.origin[1];
        let at = rows * self.width;
        let (u0, u1) = self.u.split_at_mut(at);
        let (v0, v1) = self.v.split_at_mut(at);
        let (e0, e1) = self.events.split_at_mut(at);
        let (c0, c1) = self.color.split_at_mut(at);
        let part = |u, v, events, color, row| RowsMut {
            width: self.width,
            full_width: self.full_width,
            origin: [self.origin[0], row],
            u,
            v,
            events,
            color,
        };
        (
            part(u0, v0, e0, c0, self.origin[1]),
            part(u1, v1, e1, c1, y as usize),
        )
    }

    /// [`Film::blit`] into these rows, which must hold the tile's pixels.
    fn blit(&mut self, t: &TileOut, with_hits: bool) {
        let [ox, oy] = self.origin;
        match &t.region {
            Region::Rect(tile) => {
                let tw = tile.width() as usize;
                for row in 0..tile.height() as usize {
                    let src = row * tw;
                    let dst = (tile.y0 as usize - oy + row) * self.width + tile.x0 as usize - ox;
                    if with_hits {
                        self.u[dst..dst + tw].copy_from_slice(&t.u[src..src + tw]);
                        self.v[dst..dst + tw].copy_from_slice(&t.v[src..src + tw]);
                        self.events[dst..dst + tw].copy_from_slice(&t.events[src..src + tw]);
                    }
                    if let Some(c) = &t.color {
                        self.color[dst..dst + tw].copy_from_slice(&c[src..src + tw]);
                    }
                }
            }
            Region::List(pixels) => {
                for (k, &p) in pixels.iter().enumerate() {
                    let p = p as usize;
                    let p = (p / self.full_width - oy) * self.width + p % self.full_width - ox;
                    if with_hits {
                        self.u[p] = t.u[k];
                        self.v[p] = t.v[k];
                        self.events[p] = t.events[k];
                    }
                    if let Some(c) = &t.color {
                        self.color[p] = c[k];
                    }
                }
            }
        }
    }
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

    /// Copies a tile's results into place (hit positions only where the tile
    /// traced pixel-centre rays, colours only where it recorded them).
    ///
    /// Tiles are in image coordinates and must lie inside the film's window.
    pub fn blit(&mut self, t: &TileOut, with_hits: bool) {
        self.rows_mut().blit(t, with_hits);
    }

    /// [`Film::blit`] for every tile of `outs`, the rectangles' bands of
    /// rows in parallel.
    ///
    /// Consecutive rectangles with the same rows (a row of tiles, as
    /// [`crate::render::tile::tiles`] orders them) form a band, and bands
    /// in increasing row order own disjoint rows of the buffers, so each is
    /// copied by its own task: the copy is the first write to most of a
    /// fresh film's pages, and on one thread it was the whole of a single
    /// render's film stage (sphere 512×512: 2.3–2.8 ms between the tiles
    /// and PRSS). Lists of pixels, and rectangles in any other order, are
    /// copied one after another.
    pub fn blit_all(&mut self, outs: &[TileOut], with_hits: bool) {
        use rayon::prelude::*;
        let Some(bands) = self.bands(outs) else {
            for o in outs {
                self.blit(o, with_hits);
            }
            return;
        };
        // Split the buffers at the bands' rows: one view per band.
        let mut views = Vec::with_capacity(bands.len());
        let mut rest = self.rows_mut();
        for &(y0, y1, tiles) in &bands {
            let (_, from) = rest.split_at_row(y0);
            let (band, after) = from.split_at_row(y1);
            views.push((band, tiles));
            rest = after;
        }
        views
            .into_par_iter()
            .with_max_len(1)
            .for_each(|(mut band, tiles)| {
                for o in tiles {
                    band.blit(o, with_hits);
                }
            });
    }

    /// The bands of rows of `outs` for [`Film::blit_all`]: `(y0, y1, tiles)`
    /// per run of rectangles with the same rows, when every region is a
    /// rectangle and the bands come in increasing, disjoint row order inside
    /// the window; `None` otherwise.
    fn bands<'a>(&self, outs: &'a [TileOut]) -> Option<Vec<(u32, u32, &'a [TileOut])>> {
        let rows = |o: &TileOut| match &o.region {
            Region::Rect(t) => Some((t.y0, t.y1)),
            Region::List(_) => None,
        };
        let bands = outs
            .chunk_by(|a, b| rows(a) == rows(b))
            .map(|run| rows(&run[0]).map(|(y0, y1)| (y0, y1, run)))
            .collect::<Option<Vec<_>>>()?;
        let ordered = bands.windows(2).all(|b| b[0].1 <= b[1].0)
            && bands.first().is_some_and(|b| b.0 >= self.origin[1])
            && bands
                .last()
                .is_some_and(|b| b.1 <= self.origin[1] + self.height);
        ordered.then_some(bands)
    }

    /// All of the film's rows, to write into.
    fn rows_mut(&mut self) -> RowsMut<'_> {
        RowsMut {
            width: self.width as usize,
            full_width: self.full[0] as usize,
            origin: [self.origin[0] as usize, self.origin[1] as usize],
            u: &mut self.u,
            v: &mut self.v,
            events: &mut self.events,
            color: &mut self.color,
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

    /// The film's place in the image, for its EXR files.
    fn placement(&self) -> Placement {
        Placement {
            origin: self.origin,
            full: self.full,
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

    /// Float RGB EXR of the colour image.
    pub fn write_color_exr(&self, path: &Path) -> Result<(), FilmError> {
        let c = |k: usize| self.color.iter().map(|p| p[k]).collect::<Vec<f32>>();
        write_exr_placed(
            path,
            self.width,
            self.height,
            self.placement(),
            vec![("R", c(0)), ("G", c(1)), ("B", c(2))],
        )
    }

    /// The SPEC.md hit-position EXR.
    pub fn write_hits_exr(&self, path: &Path) -> Result<(), FilmError> {
        write_exr_placed(
            path,
            self.width,
            self.height,
            self.placement(),
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
        let err = |msg: String| FilmError::Read {
            path: path.to_path_buf(),
            msg,
        };
        let image = read_first_flat_layer_from_file(path).map_err(|e| err(e.to_string()))?;
        let layer = &image.layer_data;
        let size = layer.size;
        let channel = |name: &str| -> Result<Vec<f32>, FilmError> {
            layer
                .channel_data
                .list
                .iter()
                .find(|c| c.name.eq(name))
                .map(|c| c.sample_data.values_as_f32().collect())
                .ok_or_else(|| err(format!("no channel '{name}' (not a hit-position image)")))
        };
        Ok(HitImage {
            width: size.width() as u32,
            height: size.height() as u32,
            u: channel("u")?,
            v: channel("v")?,
            events: channel("events")?,
        })
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

    /// A tile output whose every value says which pixel and tile it is.
    fn tile_out(region: Region, full_width: u32, tag: f32, colours: bool) -> TileOut {
        let mut px = Vec::new();
        region.for_each_pixel(full_width, |x, y| px.push((y * full_width + x) as f32));
        TileOut {
            region,
            u: px.clone(),
            v: px.iter().map(|p| -p).collect(),
            events: vec![tag; px.len()],
            color: colours.then(|| px.iter().map(|&p| [p, tag, 1.0]).collect()),
            counters: Default::default(),
            times: Default::default(),
            trace: None,
        }
    }

    /// The bands copied in parallel give the film one tile at a time
    /// gives: whole images and windows (whose tiles are cut at the window,
    /// as a `--region` render's are), with and without hits or colours,
    /// and lists of pixels (copied in turn).
    #[test]
    fn parallel_bands_copy_as_tiles_one_at_a_time() {
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
            for (size, with_hits, colours) in [(16, true, false), (7, false, true), (1, true, true)]
            {
                let outs: Vec<TileOut> = tiles(full[0], full[1], size)
                    .into_iter()
                    .filter_map(|t| t.intersect(&window))
                    .enumerate()
                    .map(|(k, t)| tile_out(Region::Rect(t), full[0], k as f32, colours))
                    .collect();
                let mut one = Film::window(window, full);
                for o in &outs {
                    one.blit(o, with_hits);
                }
                let mut bands = Film::window(window, full);
                let split = bands.bands(&outs).expect("rows of rectangles form bands");
                assert_eq!(
                    split.iter().map(|b| b.2.len()).sum::<usize>(),
                    outs.len(),
                    "{window:?} tile {size}"
                );
                bands.blit_all(&outs, with_hits);
                let bits = |f: &Film| {
                    let b = |x: &[f32]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                    let c: Vec<f32> = f.color.iter().flatten().copied().collect();
                    (b(&f.u), b(&f.v), b(&f.events), b(&c))
                };
                assert_eq!(bits(&one), bits(&bands), "{window:?} tile {size}");
                if with_hits {
                    assert!(one.u.iter().all(|u| !u.is_nan()), "every pixel written");
                }
            }
        }
        // Lists of pixels after the rectangles: copied in turn.
        let mut outs: Vec<TileOut> = tiles(full[0], full[1], 16)
            .into_iter()
            .map(|t| tile_out(Region::Rect(t), full[0], 1.0, true))
            .collect();
        outs.push(tile_out(
            Region::List(vec![3, 60, 2000]),
            full[0],
            9.0,
            true,
        ));
        let mut one = Film::new(full[0], full[1]);
        for o in &outs {
            one.blit(o, true);
        }
        let mut bands = Film::new(full[0], full[1]);
        assert!(bands.bands(&outs).is_none(), "a list is copied in turn");
        bands.blit_all(&outs, true);
        assert_eq!(one.events, bands.events);
        assert_eq!(bands.events[60], 9.0);
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
        f.write_hits_exr(&p).unwrap();
        let h = HitImage::read_exr(&p).unwrap();
        assert_eq!((h.width, h.height), (3, 2));
        assert_eq!(h.events, f.events);
        for (a, b) in h.u.iter().zip(&f.u) {
            assert!(a == b || (a.is_nan() && b.is_nan()));
        }
        f.write_png(&dir.join("c.png")).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
