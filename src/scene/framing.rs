//! A camera and a checkerboard placed from a volume's extent alone, and the
//! scene file that holds them (`snell scene`): a new dataset renders without
//! working out coordinates by hand, and the file it gets is the template to
//! edit.
//!
//! The camera looks along one of the grid's axes at the centre of the
//! volume's domain, as the example scenes do (SPEC.md's world coordinates:
//! grid coordinate × spacing), from just far enough that every corner of the
//! domain's box projects inside [`FILL`] of the image's half-width and
//! half-height: the iso-surface lies inside the box, so the object never
//! touches the border. The checkerboard stands behind the box, one largest
//! extent beyond its back face, far enough for refraction to shift it
//! visibly, with squares of a round size about [`SQUARES`] to the image's
//! height.

use glam::DVec3;

use crate::filter::FilterKind;
use crate::human::num;
use crate::volume::{Endian, RawSpec};

/// The share of the image's half-width and half-height the volume's box may
/// fill.
pub const FILL: f64 = 0.9;

/// Default vertical field of view in degrees (the CT scenes').
pub const DEFAULT_FOV_Y: f64 = 30.0;

/// About how many checker squares span the image's height at the backdrop.
pub const SQUARES: f64 = 24.0;

/// The direction the camera looks along: a grid axis and its sign.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct View {
    /// 0, 1, 2 for x, y, z.
    pub axis: usize,
    /// Towards increasing coordinates (the camera on the low side).
    pub positive: bool,
}

impl View {
    /// `+x`, `-y`, `z` (= `+z`), case-insensitive.
    pub fn parse(s: &str) -> Result<View, String> {
        let t = s.trim().to_ascii_lowercase();
        let (positive, letter) = match t.strip_prefix('-') {
            Some(rest) => (false, rest),
            None => (true, t.strip_prefix('+').unwrap_or(&t)),
        };
        let axis = match letter {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            _ => {
                return Err(format!(
                    "expected an axis to look along, +x, -x, +y, -y, +z or -z, got '{s}'"
                ));
            }
        };
        Ok(View { axis, positive })
    }

    /// The view along the volume's thinnest extent, towards increasing
    /// coordinates: its broadest silhouette, and the paper's lobster seen
    /// from above. Ties go to the later axis (z before y before x: a scan's
    /// slice axis).
    pub fn thinnest(extent: [f64; 3]) -> View {
        let mut axis = 2;
        for a in [1, 0] {
            if extent[a] < extent[axis] {
                axis = a;
            }
        }
        View {
            axis,
            positive: true,
        }
    }

    /// `+x` … `-z`.
    pub fn name(self) -> String {
        format!(
            "{}{}",
            if self.positive { '+' } else { '-' },
            ['x', 'y', 'z'][self.axis]
        )
    }

    /// The unit direction the camera looks in.
    pub fn forward(self) -> DVec3 {
        let mut f = DVec3::ZERO;
        f[self.axis] = if self.positive { 1.0 } else { -1.0 };
        f
    }

    /// The camera's `up`: +y looking along z, +z along x or y (a scan's
    /// slice axis up in its side views, as the cranium scene has it).
    pub fn up(self) -> DVec3 {
        if self.axis == 2 { DVec3::Y } else { DVec3::Z }
    }
}

/// Where [`frame`] puts the camera and the checkerboard, in world units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Framing {
    pub position: DVec3,
    pub look_at: DVec3,
    pub up: DVec3,
    /// Vertical field of view in degrees.
    pub fov_y: f64,
    pub backdrop_center: DVec3,
    /// Facing the camera.
    pub backdrop_normal: DVec3,
    /// The camera's right: `u` grows to the right of the image.
    pub u_axis: DVec3,
    pub checker: f64,
}

/// Why a volume cannot be framed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FramingError {
    #[error("the volume's domain is a single point (one sample): there is no surface to frame")]
    Point,
    #[error("the volume's extent must be finite and non-negative, got {0:?}")]
    BadExtent([f64; 3]),
    #[error("the field of view must be between 0 and 180 degrees (both excluded), got {0}")]
    BadFov(f64),
    #[error("the image's aspect ratio must be a finite number > 0, got {0}")]
    BadAspect(f64),
    /// A domain so small that the camera's distance from it would vanish
    /// beside its coordinates (the renderer needs them apart by 1e-12).
    #[error(
        "the volume's domain is {} world units across, under the {MIN_EXTENT:e} a framed camera needs; set a larger spacing",
        num(*.0)
    )]
    TooSmall(f64),
    /// A camera or backdrop beyond the renderer's coordinates.
    #[error(
        "the camera or backdrop would stand up to {} world units out, beyond the {MAX_PLACE:e} a scene may place them; set a smaller spacing or a wider field of view",
        num(*.0)
    )]
    TooFar(f64),
}

/// The smallest domain [`frame`] places a camera for, in world units.
pub const MIN_EXTENT: f64 = 1e-9;

/// The farthest [`frame`] places a camera or backdrop coordinate, well
/// inside the renderer's [`crate::scene::camera::MAX_COORD`].
pub const MAX_PLACE: f64 = 1e140;

/// The camera and backdrop for a volume of `extent` (world units) seen
/// along `view` with a vertical field of view of `fov_y` degrees, in an
/// image `aspect` (width over height) wide. Distances are rounded up to
/// four significant digits and the checker size to 1, 2, 2.5 or 5 times a
/// power of ten, so the file reads well; the rounding keeps the fit.
/// Refused: an extent that is not finite, one too small or too large to
/// place a camera for, a field of view outside (0°, 180°).
pub fn frame(
    extent: [f64; 3],
    view: View,
    fov_y: f64,
    aspect: f64,
) -> Result<Framing, FramingError> {
    if extent.iter().any(|e| !(e.is_finite() && *e >= 0.0)) {
        return Err(FramingError::BadExtent(extent));
    }
    let largest = extent.iter().fold(0.0f64, |m, &e| m.max(e));
    if largest == 0.0 {
        return Err(FramingError::Point);
    }
    if largest < MIN_EXTENT {
        return Err(FramingError::TooSmall(largest));
    }
    if !(fov_y > 0.0 && fov_y < 180.0) {
        return Err(FramingError::BadFov(fov_y));
    }
    if !(aspect.is_finite() && aspect > 0.0) {
        return Err(FramingError::BadAspect(aspect));
    }
    let centre = DVec3::from_array(extent) * 0.5;
    let f = view.forward();
    let up = view.up();
    // SPEC.md's frame: r = f × up, u = r × f.
    let r = f.cross(up);
    let u = r.cross(f);
    let tan = (fov_y.to_radians() * 0.5).tan() * FILL;
    let half_depth = 0.5 * extent[view.axis];
    // A box seen end-on with no breadth (a row of samples) still gets its
    // camera off its near face.
    let mut distance = half_depth + 1e-3 * largest;
    // Each corner c (from the centre) sits d + c·f in front of a camera d
    // before the centre; it projects inside the filled part of the image
    // when its offsets c·u and c·r are within that depth times the half
    // field's tangents.
    for corner in 0..8 {
        let c = DVec3::new(
            if corner & 1 == 0 { -0.5 } else { 0.5 },
            if corner & 2 == 0 { -0.5 } else { 0.5 },
            if corner & 4 == 0 { -0.5 } else { 0.5 },
        ) * DVec3::from_array(extent);
        let needed = (c.dot(u).abs() / tan).max(c.dot(r).abs() / (tan * aspect)) - c.dot(f);
        distance = distance.max(needed);
    }
    let distance = round_up(distance);
    let behind = round_up(half_depth + largest);
    // A bound on every coordinate placed (NaN where an absurd extent
    // overflowed the distances).
    let far = centre.abs().max_element() + distance + behind;
    if far.is_nan() || far > MAX_PLACE {
        return Err(FramingError::TooFar(far));
    }
    let view_height = 2.0 * (fov_y.to_radians() * 0.5).tan() * (distance + behind);
    Ok(Framing {
        position: centre - f * distance,
        look_at: centre,
        up,
        fov_y,
        backdrop_center: centre + f * behind,
        backdrop_normal: -f,
        u_axis: r,
        checker: round_nicely(view_height / SQUARES),
    })
}

/// `x > 0` rounded up to four significant digits.
fn round_up(x: f64) -> f64 {
    let unit = 10f64.powi(x.log10().floor() as i32 - 3);
    (x / unit).ceil() * unit
}

/// `x > 0` to the nearest of 1, 2, 2.5 and 5 times a power of ten, on a
/// log scale.
fn round_nicely(x: f64) -> f64 {
    let decade = 10f64.powi(x.log10().floor() as i32);
    [1.0, 2.0, 2.5, 5.0, 10.0]
        .into_iter()
        .map(|m| m * decade)
        .min_by(|a, b| (a / x).ln().abs().total_cmp(&(b / x).ln().abs()))
        .unwrap_or(decade)
}

/// Where a drafted scene's volume comes from, as its file will say.
#[derive(Clone, Debug, PartialEq)]
pub struct DraftVolume {
    /// The path as the scene file writes it (relative to the file's folder,
    /// or absolute).
    pub path: String,
    /// The layout of a headerless raw file.
    pub raw: Option<RawSpec>,
    /// A spacing that overrides the file's.
    pub spacing: Option<[f64; 3]>,
    pub allow_nan: bool,
}

/// A scene file's contents for a framed volume.
#[derive(Clone, Debug, PartialEq)]
pub struct Draft {
    /// Comment lines at the top (without `#`): where the scene came from.
    pub note: Vec<String>,
    pub volume: DraftVolume,
    pub filter: FilterKind,
    pub iso: f64,
    pub ior: f64,
    pub width: u32,
    pub height: u32,
    pub view: View,
    pub framing: Framing,
}

impl Draft {
    /// The scene file: every section the renderer needs. The values the
    /// user chose (iso-value, ior, λ, spacing, field of view) read back as
    /// the same `f64`; the placed geometry, already rounded, is written to
    /// seven significant digits at most.
    pub fn to_toml(&self) -> String {
        let fr = &self.framing;
        let mut s = String::new();
        for line in &self.note {
            // A line break in a note (a file name may hold one) would end
            // the comment.
            let line: String = line
                .chars()
                .map(|c| if c.is_control() { ' ' } else { c })
                .collect();
            s += &format!("# {line}\n");
        }
        s += &format!(
            "\n[image]\nwidth = {}\nheight = {}\n",
            self.width, self.height
        );
        s += &format!(
            "\n# Looking along {} at the centre of the volume's domain, from where its\n\
             # box fills at most {}% of the image's half-width and half-height.\n\
             [camera]\nkind = \"perspective\"\nposition = {}\nlook_at = {}\nup = {}\nfov_y = {}\n",
            self.view.name(),
            num(FILL * 100.0),
            vector(fr.position.to_array(), float),
            vector(fr.look_at.to_array(), float),
            vector(fr.up.to_array(), float),
            given(fr.fov_y)
        );
        let v = &self.volume;
        s += &format!(
            "\n[volume]\npath = {}\n",
            toml::Value::String(v.path.clone())
        );
        if let Some(sp) = v.spacing {
            s += &format!("spacing = {}\n", vector(sp, given));
        }
        if v.allow_nan {
            s += "allow_nan = true\n";
        }
        if let Some(raw) = &v.raw {
            s += &format!(
                "\n[volume.raw]\ndims = [{}, {}, {}]\ntype = \"{}\"\nendian = \"{}\"\noffset = {}\n",
                raw.dims[0],
                raw.dims[1],
                raw.dims[2],
                raw.sample_type.name(),
                match raw.endian {
                    Endian::Little => "little",
                    Endian::Big => "big",
                },
                raw.offset
            );
        }
        s += &format!("\n[surface]\nfilter = \"{}\"\n", self.filter.name());
        if self.filter.smooths() {
            s += &format!("lambda = {}\n", given(self.filter.lambda()));
        }
        s += &format!("iso = {}\nior = {}\n", given(self.iso), given(self.ior));
        s += &format!(
            "\n[backdrop]\ncenter = {}\nnormal = {}\nu_axis = {}\nchecker = {}\n",
            vector(fr.backdrop_center.to_array(), float),
            vector(fr.backdrop_normal.to_array(), float),
            vector(fr.u_axis.to_array(), float),
            float(fr.checker)
        );
        s += "\n[render]\ntraversal = \"octree\"\n";
        s
    }
}

/// `x` as a TOML float in the digits of `digits`, with a point where they
/// have none (so the value is a float, not an integer); −0 as 0.
fn toml_float(x: f64, digits: fn(f64) -> String) -> String {
    let t = digits(if x == 0.0 { 0.0 } else { x });
    if t.contains(['.', 'e', 'i', 'N']) {
        t
    } else {
        t + ".0"
    }
}

/// A placed, rounded value: [`num`]'s seven significant digits at most.
fn float(x: f64) -> String {
    toml_float(x, num)
}

/// A value the user gave (iso-value, ior, λ, spacing) or the field of
/// view: every digit it takes to read back the same `f64`.
fn given(x: f64) -> String {
    toml_float(x, crate::human::exact)
}

/// `[x, y, z]` in the digits of `value` ([`float`] or [`given`], or
/// [`crate::human::num`] in messages).
pub(super) fn vector(v: [f64; 3], value: fn(f64) -> String) -> String {
    format!("[{}, {}, {}]", value(v[0]), value(v[1]), value(v[2]))
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use crate::scene::{Projection, Scene};

    /// Where world point `p` lands in the image of `fr`'s camera, in
    /// SPEC.md's screen coordinates (`sx`, `sy` in -1..1 across the image).
    fn screen(fr: &Framing, aspect: f64, p: DVec3) -> (f64, f64) {
        let f = (fr.look_at - fr.position).normalize();
        let r = f.cross(fr.up).normalize();
        let u = r.cross(f);
        let d = p - fr.position;
        let t = (fr.fov_y.to_radians() * 0.5).tan();
        let depth = d.dot(f);
        assert!(depth > 0.0, "{p} is behind the camera");
        (d.dot(r) / (depth * t * aspect), d.dot(u) / (depth * t))
    }

    fn corners(extent: [f64; 3]) -> Vec<DVec3> {
        (0..8)
            .map(|c| {
                DVec3::new(
                    if c & 1 == 0 { 0.0 } else { extent[0] },
                    if c & 2 == 0 { 0.0 } else { extent[1] },
                    if c & 4 == 0 { 0.0 } else { extent[2] },
                )
            })
            .collect()
    }

    #[test]
    fn every_corner_lies_inside_the_filled_image_and_the_fit_is_tight() {
        let extents = [
            [300.0, 323.0, 77.0],
            [63.0, 63.0, 63.0],
            [243.1, 243.1, 160.5],
            [1.0, 1000.0, 0.0],
            [1e-6, 2e-6, 3e-6],
            [5e4, 10.0, 10.0],
            [0.0, 1000.0, 0.0],
        ];
        for extent in extents {
            for axis in 0..3 {
                for positive in [true, false] {
                    let view = View { axis, positive };
                    for (fov, aspect) in [(30.0, 1.0), (60.0, 16.0 / 9.0), (10.0, 0.5)] {
                        let fr = frame(extent, view, fov, aspect).unwrap();
                        let mut widest = 0.0f64;
                        for c in corners(extent) {
                            let (sx, sy) = screen(&fr, aspect, c);
                            assert!(
                                sx.abs() <= FILL + 1e-12 && sy.abs() <= FILL + 1e-12,
                                "{extent:?} {} fov {fov}: corner {c} at ({sx}, {sy})",
                                view.name()
                            );
                            widest = widest.max(sx.abs()).max(sy.abs());
                            // The backdrop lies beyond every corner.
                            let n = fr.backdrop_normal;
                            assert!((c - fr.backdrop_center).dot(n) > 0.0);
                        }
                        // Rounding up to four digits (under a thousandth of
                        // the distance) is all that keeps the nearest corner
                        // from the filled edge, unless the box is so thin
                        // across the view that the camera stands at its
                        // least distance from the near face.
                        let largest = extent.iter().fold(0.0f64, |m, &e| m.max(e));
                        let least = round_up(0.5 * extent[axis] + 1e-3 * largest);
                        let distance = (fr.look_at - fr.position).length();
                        let closer = Framing {
                            position: fr.look_at - view.forward() * distance * (1.0 - 1e-3),
                            ..fr
                        };
                        let overflows = corners(extent).into_iter().any(|c| {
                            let (sx, sy) = screen(&closer, aspect, c);
                            sx.abs().max(sy.abs()) > FILL
                        });
                        assert!(
                            distance <= least * (1.0 + 1e-12) || overflows,
                            "{extent:?} {} fov {fov} aspect {aspect}: loose fit {widest} at distance {distance}",
                            view.name()
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn the_backdrop_faces_the_camera_with_u_to_the_right() {
        let fr = frame([300.0, 323.0, 77.0], View::parse("+z").unwrap(), 30.0, 1.0).unwrap();
        assert_eq!(fr.backdrop_normal, -DVec3::Z);
        // SPEC.md: r = f × up = z × y = -x.
        assert_eq!(fr.u_axis, -DVec3::X);
        assert_eq!(fr.look_at, DVec3::new(150.0, 161.5, 38.5));
        assert!(fr.position.z < 0.0 && fr.backdrop_center.z > 77.0);
        // About SQUARES squares over the view's height at the backdrop.
        let t = 15f64.to_radians().tan();
        let squares = 2.0 * t * (fr.backdrop_center.z - fr.position.z) / fr.checker;
        assert!((15.0..40.0).contains(&squares), "{squares}");
    }

    #[test]
    fn views_parse_and_name_themselves() {
        for (s, axis, positive) in [
            ("+x", 0, true),
            ("x", 0, true),
            ("-Y", 1, false),
            (" z ", 2, true),
            ("-z", 2, false),
        ] {
            let v = View::parse(s).unwrap();
            assert_eq!((v.axis, v.positive), (axis, positive), "{s}");
            assert_eq!(View::parse(&v.name()).unwrap(), v);
        }
        for bad in ["", "w", "+-x", "xy", "--z"] {
            let e = View::parse(bad).unwrap_err();
            assert!(e.contains("+x, -x"), "{bad}: {e}");
        }
        assert_eq!(View::thinnest([300.0, 323.0, 77.0]).name(), "+z");
        assert_eq!(View::thinnest([10.0, 323.0, 77.0]).name(), "+x");
        assert_eq!(View::thinnest([63.0, 63.0, 63.0]).name(), "+z");
        assert_eq!(View::thinnest([63.0, 62.0, 62.0]).name(), "+z");
    }

    #[test]
    fn degenerate_inputs_are_refused() {
        let v = View::parse("z").unwrap();
        assert_eq!(frame([0.0; 3], v, 30.0, 1.0), Err(FramingError::Point));
        assert!(matches!(
            frame([f64::NAN, 1.0, 1.0], v, 30.0, 1.0),
            Err(FramingError::BadExtent(_))
        ));
        assert!(matches!(
            frame([f64::INFINITY, 1.0, 1.0], v, 30.0, 1.0),
            Err(FramingError::BadExtent(_))
        ));
        for fov in [0.0, 180.0, -5.0, f64::NAN] {
            assert!(matches!(
                frame([1.0; 3], v, fov, 1.0),
                Err(FramingError::BadFov(_))
            ));
        }
        assert!(matches!(
            frame([1.0; 3], v, 30.0, 0.0),
            Err(FramingError::BadAspect(_))
        ));
        assert_eq!(
            frame([1e-10, 0.0, 0.0], v, 30.0, 1.0),
            Err(FramingError::TooSmall(1e-10))
        );
        assert!(frame([1e-9, 0.0, 0.0], v, 30.0, 1.0).is_ok());
        assert!(matches!(
            frame([1e141, 1.0, 1.0], v, 30.0, 1.0),
            Err(FramingError::TooFar(_))
        ));
        assert!(matches!(
            frame([1.0, 1e140, 1.0], v, 30.0, 1.0),
            Err(FramingError::TooFar(_))
        ));
        for huge in [1e300, f64::MAX] {
            assert!(matches!(
                frame([huge, 1.0, 1.0], v, 0.001, 1.0),
                Err(FramingError::TooFar(_))
            ));
        }
    }

    #[test]
    fn rounding_reads_well() {
        assert_eq!(num(round_up(590.2301)), "590.3");
        assert_eq!(num(round_up(0.0012345)), "0.001235");
        assert_eq!(num(round_up(1234.0)), "1234");
        assert_eq!(round_nicely(24.0), 25.0);
        assert_eq!(round_nicely(1.6), 2.0);
        assert_eq!(round_nicely(0.0037), 0.005);
        assert_eq!(round_nicely(8.0), 10.0);
        assert_eq!(float(-0.0), "0.0");
        assert_eq!(float(30.0), "30.0");
        assert_eq!(float(1e-9), "1e-9");
    }

    fn draft(raw: Option<RawSpec>, filter: FilterKind) -> Draft {
        let view = View::parse("-y").unwrap();
        let extent = [243.1, 243.1, 160.5];
        Draft {
            note: vec!["test".into(), "a name\nwith a break: [x]".into()],
            volume: DraftVolume {
                path: "data/a \"b\".raw".into(),
                raw,
                spacing: Some([0.957, 0.957, 1.5]),
                allow_nan: true,
            },
            filter,
            iso: 524.123456789,
            ior: 1.23456789,
            width: 640,
            height: 480,
            view,
            framing: frame(extent, view, 30.0, 640.0 / 480.0).unwrap(),
        }
    }

    #[test]
    fn the_draft_reads_back_as_the_scene_it_describes() {
        let raw = RawSpec {
            dims: [255, 255, 108],
            sample_type: crate::volume::SampleType::U16,
            endian: Endian::Big,
            spacing: [1.0; 3],
            offset: 7,
        };
        for (raw, filter) in [
            (
                Some(raw),
                FilterKind::SmoothBSpline3 {
                    lambda: 0.123456789,
                },
            ),
            (None, FilterKind::BSpline(3)),
        ] {
            let d = draft(raw.clone(), filter);
            let text = d.to_toml();
            let scene = Scene::parse(&text, Path::new("/tmp/scenes/x.toml"), &[])
                .unwrap_or_else(|e| panic!("{e}\n{text}"));
            assert!(scene.setting_notes().is_empty(), "{text}");
            assert_eq!((scene.width, scene.height), (640, 480));
            assert_eq!(scene.surface.filter, filter);
            // What the user gave reads back to the last bit.
            assert_eq!(scene.surface.iso, 524.123456789);
            assert_eq!(scene.surface.ior, 1.23456789);
            assert_eq!(scene.surface.filter.lambda(), filter.lambda());
            assert_eq!(scene.spacing, Some([0.957, 0.957, 1.5]));
            let fr = &d.framing;
            let close = |a: DVec3, b: DVec3| (a - b).length() <= 1e-6 * (1.0 + b.length());
            assert!(close(scene.camera.position, fr.position), "{text}");
            assert!(close(
                scene.camera.forward,
                (fr.look_at - fr.position).normalize()
            ));
            assert!(matches!(
                scene.camera.projection,
                Projection::Perspective { tan_half_fov } if (tan_half_fov - 15f64.to_radians().tan()).abs() < 1e-12
            ));
            assert_eq!(scene.backdrop.checker_size(), Some(fr.checker));
            match &scene.volume {
                crate::scene::VolumeSource::File {
                    path,
                    raw: read_raw,
                    allow_nan,
                } => {
                    assert_eq!(path, Path::new("/tmp/scenes/data/a \"b\".raw"));
                    assert!(*allow_nan);
                    match (&raw, read_raw) {
                        (Some(a), Some(b)) => {
                            assert_eq!(
                                (a.dims, a.sample_type, a.endian, a.offset),
                                (b.dims, b.sample_type, b.endian, b.offset)
                            )
                        }
                        (None, None) => {}
                        _ => panic!("raw layout lost: {text}"),
                    }
                }
                other => panic!("{other:?}"),
            }
        }
    }
}
