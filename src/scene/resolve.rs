//! From the file's sections to a validated [`Scene`]: every value checked
//! with its key named, relative paths resolved beside the scene file, the
//! photograph loaded, and the settings that would have no effect listed.

use std::path::Path;

use glam::DVec3;

use super::file::{CameraKind, SceneFile, default_tile};
use super::words::{plain_serde_message, plain_value};
use super::{
    Backdrop, Camera, CameraError, DEFAULT_CLASSIFY, MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE, MIN_STEP,
    Pattern, Projection, RenderSettings, Scene, SceneError, SettingNote, Supersampling, Surface,
    Texture, Traversal, VolumeSource, unit_scale,
};
use crate::classify::Method;
use crate::filter::FilterKind;
use crate::human::exact;
use crate::phantom::PhantomSpec;
use crate::volume::{Endian, RawSpec, SampleType};

/// Largest magnitude of a `backdrop.center` coordinate. A camera near the
/// volume reaches a plane this far off at backdrop coordinates of about its
/// distance, which the hit EXR's 32-bit floats (to 3.4e38) still hold at
/// grazing angles of 1e-8 radians; a plane much further off overflows them
/// for every view. (Not a bound for every geometry: a camera itself far
/// off can still put its hits beyond them.)
const MAX_BACKDROP_COORD: f64 = 1e30;

/// The whole-number settings' ranges: checked when the scene is resolved,
/// and named by the message for a value that is no whole number at all
/// (`image.width = 1.5`), in place of the range of its Rust type.
const WHOLE_RANGES: [(&str, u32, u32); 7] = [
    ("image.width", 1, MAX_IMAGE_SIDE),
    ("image.height", 1, MAX_IMAGE_SIDE),
    ("render.max_events", 1, 100_000),
    ("render.samples", 1, 64),
    ("render.prss_samples", 1, 64),
    ("render.tile", 1, 256),
    // Checked by the phantom itself.
    (
        "volume.phantom.size",
        1,
        crate::phantom::MAX_PHANTOM_SIZE as u32,
    ),
];

/// The range of whole-number setting `key`, if it has one.
fn whole_range(key: &str) -> Option<(u32, u32)> {
    WHOLE_RANGES
        .iter()
        .find(|(k, ..)| *k == key)
        .map(|&(_, lo, hi)| (lo, hi))
}

/// serde's refusal of `key`'s value in plain words, with the setting's own
/// range where it has one.
pub(super) fn setting_message(key: &str, serde_msg: &str) -> String {
    // The scene's top level holds sections, not settings.
    if !key.contains('.')
        && let Some(rest) = serde_msg.trim().strip_prefix("unknown field ")
    {
        return format!(
            "unknown section {rest}; a setting is written section.key (e.g. --set image.width=64, or width = 64 under [image])"
        );
    }
    plain_serde_message(serde_msg, whole_range(key))
}

fn vec3(v: [f64; 3]) -> DVec3 {
    DVec3::from_array(v)
}

/// Reads `[volume.phantom]`: its `kind`, then the kind's settings, each
/// error with the key inside the table (`volume.phantom.size`).
pub(super) fn phantom_spec(v: toml::Value) -> Result<PhantomSpec, (String, String)> {
    let toml::Value::Table(mut t) = v else {
        return Err((
            "volume.phantom".into(),
            format!(
                "expected a table of phantom settings, got {}",
                plain_value(&v)
            ),
        ));
    };
    let kind = t.remove("kind");
    fn read<T: serde::de::DeserializeOwned>(t: toml::Table) -> Result<T, (String, String)> {
        serde_path_to_error::deserialize(toml::Value::Table(t)).map_err(|e| {
            let key = e.path().to_string();
            let key = if key == "." {
                "volume.phantom".to_string()
            } else {
                format!("volume.phantom.{key}")
            };
            let msg = setting_message(&key, e.into_inner().message());
            (key, msg)
        })
    }
    match kind.as_ref().and_then(|k| k.as_str()) {
        Some("sphere") => Ok(PhantomSpec::Sphere(read(t)?)),
        Some("marschner-lobb") => Ok(PhantomSpec::MarschnerLobb(read(t)?)),
        _ => Err((
            "volume.phantom.kind".into(),
            match kind {
                None => "missing: give kind = \"sphere\" or \"marschner-lobb\"".into(),
                Some(k) => format!(
                    "expected \"sphere\" or \"marschner-lobb\", got {}",
                    plain_value(&k)
                ),
            },
        )),
    }
}

/// The settings in `written` that the resolved scene does not use, as
/// messages (see [`Scene::setting_notes`]).
pub(super) fn ignored_settings(
    written: &[(String, String)],
    f: &SceneFile,
    surface: &Surface,
    render: &RenderSettings,
) -> Vec<SettingNote> {
    let mut unused: Vec<(&str, String)> = Vec::new();
    match f.camera.kind {
        CameraKind::Perspective => unused.push((
            "camera.height",
            "a perspective camera's view is set by fov_y (height is for kind = \"orthographic\")"
                .into(),
        )),
        CameraKind::Orthographic => unused.push((
            "camera.fov_y",
            "an orthographic camera's view is set by height (fov_y is for the perspective camera)"
                .into(),
        )),
    }
    if f.backdrop.checker.is_some() {
        for key in ["backdrop.width", "backdrop.outside"] {
            unused.push((
                key,
                "it applies to a photograph backdrop (image), not to a checkerboard".into(),
            ));
        }
    } else {
        unused.push((
            "backdrop.checker_colors",
            "it applies to a checkerboard backdrop, not to a photograph".into(),
        ));
    }
    if render.traversal == Traversal::Step
        && f.render.classify.as_deref().is_some_and(|c| c != "none")
    {
        unused.push((
            "render.classify",
            "step traversal samples every point and uses no classification".into(),
        ));
    }
    unused.extend(
        unread_render_settings(render)
            .into_iter()
            .map(|(setting, why)| (setting.key(), why)),
    );
    if !surface.filter.smooths() {
        unused.push((
            "surface.lambda",
            format!(
                "it is the smoothing weight of smooth-bspline3; filter {} does not smooth",
                surface.filter.name()
            ),
        ));
    }
    unused
        .into_iter()
        .filter_map(|(key, why)| {
            let (_, value) = written.iter().find(|(k, _)| k == key)?;
            Some(SettingNote {
                key: key.into(),
                text: format!("{} is ignored: {why}", as_written(key, value)),
            })
        })
        .collect()
}

/// A note when the written `backdrop.u_axis` leaves the backdrop's plane
/// by more than a rounding error: the scene uses its projection onto the
/// plane (so that SPEC's `v = cross(normal, u)` is a unit vector in it),
/// which the user should know is not the direction written. Its length
/// never matters: only directions are read.
fn tilted_u_axis(
    written: &[(String, String)],
    u_raw: DVec3,
    normal: DVec3,
    u_axis: DVec3,
) -> Option<SettingNote> {
    let (_, value) = written.iter().find(|(k, _)| k == "backdrop.u_axis")?;
    // The sine of the angle between the axis written and the plane.
    let off = u_raw.dot(normal).abs() / u_raw.length();
    if off <= 1e-6 {
        return None;
    }
    Some(SettingNote {
        key: "backdrop.u_axis".into(),
        text: format!(
            "{} is not in the backdrop's plane ({:.3}° out of it): its projection onto the plane, {}, is the u axis",
            as_written("backdrop.u_axis", value),
            off.min(1.0).asin().to_degrees(),
            super::framing::vector(u_axis.to_array(), crate::human::num)
        ),
    })
}

/// A written setting as a note names it: the `--set` that wrote it, or
/// `[key] = value` from the file.
fn as_written(key: &str, value: &str) -> String {
    match value.strip_prefix("--set ") {
        Some(_) => value.to_string(),
        None => format!("[{key}] = {value}"),
    }
}

/// A `[render]` setting that some traversals or anti-aliasing modes do not
/// read: what [`unread_render_settings`] lists.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum ModeSetting {
    Step,
    Leaf,
    Samples,
    Seed,
    PrssSamples,
    PrssMap,
    PrssFallback,
    PrssCurvature,
    Footprint,
}

impl ModeSetting {
    /// The key as scene files and `--set` spell it.
    pub(super) fn key(self) -> &'static str {
        match self {
            Self::Step => "render.step",
            Self::Leaf => "render.leaf",
            Self::Samples => "render.samples",
            Self::Seed => "render.seed",
            Self::PrssSamples => "render.prss_samples",
            Self::PrssMap => "render.prss_map",
            Self::PrssFallback => "render.prss_fallback",
            Self::PrssCurvature => "render.prss_curvature",
            Self::Footprint => "render.footprint",
        }
    }

    /// Sets it to one fixed value, so that frames that differ only in a
    /// setting neither reads print alike ([`Scene::frame_fingerprint`]).
    pub(super) fn normalise(self, r: &mut RenderSettings) {
        match self {
            Self::Step => r.step = 0.0,
            Self::Leaf => r.leaf = 0,
            Self::Samples => r.samples = 0,
            Self::Seed => r.seed = 0,
            Self::PrssSamples => r.prss_samples = 0,
            Self::PrssMap => r.prss_map = Default::default(),
            Self::PrssFallback => r.prss_fallback = Default::default(),
            Self::PrssCurvature => r.prss_curvature = 0.0,
            Self::Footprint => r.footprint = Default::default(),
        }
    }
}

/// The `[render]` settings the scene's traversal, supersampling and PRSS
/// fallback do not read, each with why: the one list that the warnings
/// (`ignored_settings`) and a `--region` part's frame fingerprint
/// ([`Scene::frame_fingerprint`], which must not tell apart parts that
/// differ only there) both follow.
pub(super) fn unread_render_settings(render: &RenderSettings) -> Vec<(ModeSetting, String)> {
    let mut unread = Vec::new();
    let traversal = setting_name(&render.traversal);
    if render.traversal != Traversal::Step {
        unread.push((
            ModeSetting::Step,
            format!(
                "it is the step of traversal = \"step\"; the {traversal} traversal finds crossings cell by cell"
            ),
        ));
    }
    if render.traversal != Traversal::Octree {
        unread.push((
            ModeSetting::Leaf,
            format!(
                "it is the leaf side of traversal = \"octree\"'s descent, which the {traversal} traversal does not make"
            ),
        ));
    }
    unread.extend(unread_sampling(render));
    unread
}

/// The anti-aliasing settings the scene's supersampling (and PRSS
/// fallback) does not read, each with the modes that do.
fn unread_sampling(render: &RenderSettings) -> Vec<(ModeSetting, String)> {
    use super::PrssFallback as F;
    use ModeSetting as M;
    use Supersampling as S;
    let mode = render.supersampling;
    let post = matches!(mode, S::Prss | S::Footprint);
    let retraces = post && matches!(render.prss_fallback, F::Trace | F::BlendTrace);
    let keys: [(ModeSetting, bool, &str); 7] = [
        (
            M::Samples,
            matches!(mode, S::Grid | S::Jitter) || retraces,
            "grid and jitter, and prss and footprint where prss_fallback re-traces pixels (trace, blend-trace)",
        ),
        (M::Seed, mode == S::Jitter, "jitter"),
        (M::PrssSamples, post, "prss and footprint"),
        // Footprint mode filters each pixel's own surface by its Jacobian:
        // only PRSS interpolates the hit map.
        (M::PrssMap, mode == S::Prss, "prss"),
        (M::PrssFallback, post, "prss and footprint"),
        (
            M::PrssCurvature,
            post && render.prss_fallback == F::Trace,
            "prss and footprint with prss_fallback = \"trace\"",
        ),
        (M::Footprint, mode == S::Footprint, "footprint"),
    ];
    let now = match mode {
        S::None => "render.supersampling is \"none\" (one ray per pixel)".to_string(),
        S::Prss | S::Footprint => format!(
            "render.supersampling is \"{}\" with prss_fallback = \"{}\"",
            setting_name(&mode),
            setting_name(&render.prss_fallback)
        ),
        _ => format!("render.supersampling is \"{}\"", setting_name(&mode)),
    };
    keys.into_iter()
        .filter(|&(_, read, _)| !read)
        .map(|(key, _, readers)| (key, format!("{now}; it is read by {readers}")))
        .collect()
}

/// The name a setting's unit variant has in scene files and reports
/// (`"octree"`): the one serde reads and writes.
pub(crate) fn setting_name<T: serde::Serialize>(v: &T) -> String {
    match serde_json::to_value(v) {
        Ok(serde_json::Value::String(s)) => s,
        _ => "?".into(),
    }
}

pub(super) fn resolve(
    f: SceneFile,
    phantom: Option<PhantomSpec>,
    path: &Path,
    written: &[(String, String)],
) -> Result<Scene, SceneError> {
    let bad = |key: &str, msg: String| SceneError::Key {
        path: path.to_path_buf(),
        key: key.to_string(),
        msg,
    };
    let base = path.parent().unwrap_or(Path::new("."));

    let in_range = |key: &str, v: u32, unit: &str| match whole_range(key) {
        Some((lo, hi)) if !(lo..=hi).contains(&v) => Err(bad(
            key,
            format!("must be from {lo} to {hi}{unit}, got {v}"),
        )),
        _ => Ok(()),
    };

    // [image]
    let (w, h) = (f.image.width, f.image.height);
    in_range("image.width", w, " pixels")?;
    in_range("image.height", h, " pixels")?;
    if (w as u64) * (h as u64) > MAX_IMAGE_PIXELS {
        // Named by the longer side, the one most over its share.
        return Err(bad(
            if w >= h {
                "image.width"
            } else {
                "image.height"
            },
            format!("{w}x{h} exceeds {MAX_IMAGE_PIXELS} pixels"),
        ));
    }
    check_color(&f.image.background).map_err(|m| bad("image.background", m))?;

    // [camera]
    let c = &f.camera;
    let projection = match c.kind {
        CameraKind::Perspective => {
            let fov = c.fov_y.ok_or_else(|| {
                bad(
                    "camera.fov_y",
                    "a perspective camera needs fov_y (degrees)".into(),
                )
            })?;
            if !(fov > 0.0 && fov < 180.0) {
                return Err(bad(
                    "camera.fov_y",
                    format!(
                        "must be between 0 and 180 degrees (both excluded), got {}",
                        exact(fov)
                    ),
                ));
            }
            Projection::Perspective {
                tan_half_fov: (fov.to_radians() / 2.0).tan(),
            }
        }
        CameraKind::Orthographic => {
            let height = c.height.ok_or_else(|| {
                bad(
                    "camera.height",
                    "an orthographic camera needs height (world units)".into(),
                )
            })?;
            Projection::Orthographic {
                half_height: height / 2.0,
            }
        }
    };
    let camera = Camera::new(
        vec3(c.position),
        vec3(c.look_at),
        vec3(c.up),
        projection,
        w,
        h,
    )
    .map_err(|e| {
        let key = match e {
            CameraError::NotFinite(what) | CameraError::TooFar { what, .. } => {
                format!("camera.{what}")
            }
            CameraError::BadHeight(_) | CameraError::ViewOverflow
                if c.kind == CameraKind::Orthographic =>
            {
                "camera.height".into()
            }
            CameraError::BadFov(_) => "camera.fov_y".into(),
            CameraError::UpParallel => "camera.up".into(),
            // position is where the camera is; look_at is what it aims at.
            CameraError::NoDirection => "camera.look_at".into(),
            _ => "camera".into(),
        };
        bad(&key, e.to_string())
    })?;

    // [volume]
    let v = &f.volume;
    if let Some(sp) = v.spacing {
        crate::volume::check_spacing(sp)
            .and_then(|()| crate::volume::check_spacing_ratio(sp))
            .map_err(|e| bad("volume.spacing", e.to_string()))?;
    }
    let volume = match (&v.path, &v.phantom) {
        (Some(_), Some(_)) => {
            return Err(bad(
                "volume",
                "give either path or [volume.phantom], not both".into(),
            ));
        }
        (None, None) => return Err(bad("volume", "needs path or [volume.phantom]".into())),
        (Some(p), None) => {
            let raw = match (&v.raw, crate::volume::Format::of(Path::new(p))) {
                (None, _) => None,
                (Some(_), Some(format)) => {
                    return Err(bad(
                        "volume.raw",
                        format!(
                            "applies only to headerless raw volumes (named .raw or without a known extension); {p} is {}, whose header gives its layout",
                            format.describe()
                        ),
                    ));
                }
                (Some(r), None) => Some(RawSpec {
                    dims: r.dims,
                    sample_type: SampleType::parse(&r.sample_type).ok_or_else(|| {
                        bad(
                            "volume.raw.type",
                            format!("unknown sample type '{}'", r.sample_type),
                        )
                    })?,
                    endian: Endian::parse(&r.endian).ok_or_else(|| {
                        bad(
                            "volume.raw.endian",
                            format!("expected little or big, got '{}'", r.endian),
                        )
                    })?,
                    spacing: v.spacing.unwrap_or([1.0; 3]),
                    offset: r.offset,
                }),
            };
            VolumeSource::File {
                path: base.join(p),
                raw,
                allow_nan: v.allow_nan,
            }
        }
        (None, Some(_)) => {
            let spec = phantom.expect("a phantom table is read before resolving");
            spec.validate().map_err(|e| match e {
                crate::phantom::PhantomError::Setting { key, msg } => {
                    bad(&format!("volume.phantom.{key}"), msg)
                }
                e => bad("volume.phantom", e.to_string()),
            })?;
            VolumeSource::Phantom(spec)
        }
    };
    if let Some(s) = v.spacing
        && !s.iter().all(|x| x.is_finite() && *x > 0.0)
    {
        return Err(bad(
            "volume.spacing",
            format!("must be finite and > 0, got {s:?}"),
        ));
    }

    // [surface]
    let s = &f.surface;
    let filter = FilterKind::with_lambda(&s.filter, s.lambda).map_err(|e| match e {
        crate::filter::FilterError::Unknown(_) => bad("surface.filter", e.to_string()),
        crate::filter::FilterError::BadLambda(_) => bad("surface.lambda", e.to_string()),
        crate::filter::FilterError::NeedsLambda => bad(
            "surface.lambda",
            format!(
                "filter smooth-bspline3 needs lambda, {}",
                crate::filter::LAMBDA_HELP
            ),
        ),
    })?;
    if !s.iso.is_finite() {
        return Err(bad(
            "surface.iso",
            format!("must be finite, got {}", exact(s.iso)),
        ));
    }
    for (key, ior) in [
        ("surface.ior", s.ior),
        ("surface.outside_ior", s.outside_ior),
    ] {
        if !(ior.is_finite() && ior > 0.0) {
            return Err(bad(
                key,
                format!(
                    "index of refraction must be a finite number > 0, got {}",
                    exact(ior)
                ),
            ));
        }
    }
    let surface = Surface {
        filter,
        iso: s.iso,
        ior: s.ior,
        outside_ior: s.outside_ior,
    };

    // [backdrop]
    let b = &f.backdrop;
    let center = vec3(b.center);
    // Only their directions matter: scaled to a largest component of 1, huge
    // vectors (1e155) square without overflowing to an infinite length.
    let normal = unit_scale(vec3(b.normal));
    let u_raw = unit_scale(vec3(b.u_axis));
    for (key, v, raw) in [
        ("backdrop.center", center, b.center),
        ("backdrop.normal", normal, b.normal),
        ("backdrop.u_axis", u_raw, b.u_axis),
    ] {
        if !v.is_finite() {
            return Err(bad(key, format!("must be finite, got {raw:?}")));
        }
    }
    if let Some(&value) = b.center.iter().find(|c| c.abs() > MAX_BACKDROP_COORD) {
        return Err(bad(
            "backdrop.center",
            format!(
                "must lie within ±{MAX_BACKDROP_COORD:e} of the origin on each axis (the hits' backdrop coordinates, 32-bit floats in the hit EXR, would overflow), got {value:e}"
            ),
        ));
    }
    if normal.length() < 1e-12 {
        return Err(bad("backdrop.normal", "must not be zero".into()));
    }
    let normal = normal.normalize();
    // Gram–Schmidt: keep u in the plane; SPEC's v = cross(normal, u) is then unit.
    let u_in_plane = u_raw - u_raw.dot(normal) * normal;
    if u_in_plane.length() < 1e-9 * u_raw.length().max(1e-300) || u_raw.length() == 0.0 {
        return Err(bad(
            "backdrop.u_axis",
            "must not be zero or parallel to normal".into(),
        ));
    }
    let u_axis = u_in_plane.normalize();
    let v_axis = normal.cross(u_axis);
    let backdrop_image = b.image.as_ref().map(|img| base.join(img));
    let pattern = match (b.checker, &b.image) {
        (Some(_), Some(_)) => {
            return Err(bad(
                "backdrop",
                "give either checker or image, not both".into(),
            ));
        }
        (None, None) => {
            return Err(bad(
                "backdrop",
                "needs checker = <size> or image = <file>".into(),
            ));
        }
        (Some(size), None) => {
            if !(size.is_finite() && size > 0.0) {
                return Err(bad(
                    "backdrop.checker",
                    format!(
                        "square size must be a finite number > 0, got {}",
                        exact(size)
                    ),
                ));
            }
            let colors = b.checker_colors.unwrap_or([[1.0; 3], [0.0; 3]]);
            for c in &colors {
                check_color(c).map_err(|m| bad("backdrop.checker_colors", m))?;
            }
            Pattern::Checker { size, colors }
        }
        (None, Some(img)) => {
            let width = b.width.ok_or_else(|| {
                bad(
                    "backdrop.width",
                    "an image backdrop needs width (world units)".into(),
                )
            })?;
            if !(width.is_finite() && width > 0.0) {
                return Err(bad(
                    "backdrop.width",
                    format!("must be a finite number > 0, got {}", exact(width)),
                ));
            }
            let outside = b.outside.unwrap_or(f.image.background);
            check_color(&outside).map_err(|m| bad("backdrop.outside", m))?;
            let file = base.join(img);
            Pattern::Image(
                load_texture(&file, width, outside).map_err(|m| bad("backdrop.image", m))?,
            )
        }
    };
    let backdrop = Backdrop {
        center,
        normal,
        u_axis,
        v_axis,
        pattern,
    };

    // [render]
    let r = &f.render;
    if !(r.step.is_finite() && (MIN_STEP..=16.0).contains(&r.step)) {
        return Err(bad(
            "render.step",
            format!(
                "must be from {MIN_STEP} to 16 voxels, got {}",
                exact(r.step)
            ),
        ));
    }
    in_range("render.max_events", r.max_events, "")?;
    if !(r.tolerance.is_finite() && r.tolerance >= 1e-12 && r.tolerance <= 0.1) {
        return Err(bad(
            "render.tolerance",
            format!(
                "must be from 1e-12 to 0.1 voxels, got {}",
                exact(r.tolerance)
            ),
        ));
    }
    in_range("render.samples", r.samples, "")?;
    let tile = r
        .tile
        .unwrap_or_else(|| default_tile(r.supersampling.first_pass_rays(r.samples) as u32));
    in_range("render.tile", tile, " pixels")?;
    in_range("render.prss_samples", r.prss_samples, "")?;
    let classify = match r.classify.as_deref() {
        // Precomputed tags are cheap (tens of ms, cached) and make the cell
        // walk an order of magnitude faster than bounding every visited cell
        // on the fly, so every cell traversal uses them unless told `none`.
        None if r.traversal != Traversal::Step => Some(DEFAULT_CLASSIFY),
        None | Some("none") => None,
        Some(name) => match Method::parse(name) {
            Some(m) if m.is_conservative() => Some(m),
            _ => {
                return Err(bad(
                    "render.classify",
                    format!(
                        "unknown or non-conservative method '{name}' (none, bmcc, accc, accc2, accc4, accc8, bezier (= bezier2), bezier0, bezier1, bezier3)"
                    ),
                ));
            }
        },
    };
    if matches!(r.traversal, Traversal::Octree | Traversal::Distance) && classify.is_none() {
        let what = match r.traversal {
            Traversal::Distance => "the distance cubes are measured to classified cells",
            _ => "the octree is built over classified cells",
        };
        return Err(bad(
            "render.classify",
            format!("{what}: use bmcc, accc, accc2, accc4, accc8 or bezier (bezier0 .. bezier3)"),
        ));
    }
    // Step traversal samples every point: a classification it was given is
    // reported as ignored (see `ignored_settings`), as a step is under the
    // cell traversals.
    let classify = classify.filter(|_| r.traversal != Traversal::Step);
    if !(r.prss_curvature.is_finite() && r.prss_curvature > 0.0) {
        return Err(bad(
            "render.prss_curvature",
            format!(
                "must be > 0 (checker squares), got {}",
                exact(r.prss_curvature)
            ),
        ));
    }
    if !r.leaf.is_power_of_two() || r.leaf > 64 {
        return Err(bad(
            "render.leaf",
            format!("must be a power of two up to 64, got {}", r.leaf),
        ));
    }
    let render = RenderSettings {
        traversal: r.traversal,
        step: r.step,
        max_events: r.max_events,
        tolerance: r.tolerance,
        tile,
        classify,
        leaf: r.leaf,
        supersampling: r.supersampling,
        samples: r.samples,
        prss_samples: r.prss_samples,
        prss_map: r.prss_map,
        prss_fallback: r.prss_fallback,
        footprint: r.footprint,
        prss_curvature: r.prss_curvature,
        seed: r.seed,
        coefficients: r.coefficients,
        clear_crossing_cells: r.clear_crossing_cells,
        skip_empty_approach: r.skip_empty_approach,
        skip_clear_segments: r.skip_clear_segments,
    };

    let mut notes = ignored_settings(written, &f, &surface, &render);
    notes.extend(tilted_u_axis(
        written,
        u_raw,
        backdrop.normal,
        backdrop.u_axis,
    ));
    let scene = Scene {
        notes,
        overrides: Vec::new(),
        written: Vec::new(),
        file_keys: Vec::new(),
        path: path.to_path_buf(),
        width: w,
        height: h,
        background: f.image.background,
        camera,
        volume,
        spacing: v.spacing,
        surface,
        backdrop,
        backdrop_image,
        render,
    };
    Ok(scene)
}

fn check_color(c: &[f32; 3]) -> Result<(), String> {
    if c.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        // Colours are f32: a component beyond ±3.4e38 was read as infinite.
        Err(format!(
            "colour components must be finite numbers within ±{:e}; read as {c:?}",
            f32::MAX
        ))
    }
}

/// Loads a photograph as an RGB texture in `[0, 1]`.
fn load_texture(path: &Path, world_width: f64, outside: [f32; 3]) -> Result<Texture, String> {
    let photo = crate::film::photo::read(path).map_err(|m| format!("{}: {m}", path.display()))?;
    Ok(Texture {
        width_px: photo.width as usize,
        height_px: photo.height as usize,
        pixels: photo.pixels,
        world_width,
        outside,
    })
}
