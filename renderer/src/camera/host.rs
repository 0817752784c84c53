//! Host camera conventions, written once for every front end (the CLI, the Python module /
//! Blender add-on, USD later): how a host application's camera description becomes a
//! [`CameraSpec`] and the clipping range. Parse into typed values, validate every field (NaN,
//! negative, out of range; errors name the field), then construct.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `lens` | `"thin"`, `"pinhole"`, a library name or a lens file | — | `"thin"` |
//! | `lens_model` | [`LensModel`] | — | auto |
//! | `tolerance_px` | f64 > 0: error budget of `auto` | px | 0.25 |
//! | `focal_length_mm` | f64 > 0 (thin, pinhole; see [`focal_length_from_yfov_mm`]) | mm | 50 |
//! | `film_back` | [`FilmBack`]: sensor size, [`SensorFit`] and [`Shift`] | mm | 36 × 24, auto, no shift |
//! | `tilt_deg` | (f64, f64) within ±60 | degrees | (0, 0) |
//! | `f_number` | optional f64 > 0 (thin: None = pinhole; real: None = wide open) | — | None |
//! | `focus_distance_m` | optional f64 > 0; `inf` = None = infinity; NaN is an error | m | None |
//! | `aperture` | optional [`Aperture`] (see [`parse_aperture`], [`blender_aperture`]) | — | None |
//! | `clip_m` | (start, end): 0 ≤ start < end, planes perpendicular to the view axis | m | (0, ∞) |
//! | `natural_vignetting` | bool: cos⁴ falloff for thin and pinhole | — | true |
//! | `lrtf_file` | optional baked table for `lrtf` | — | None |
//! | `ortho_scale_m` | optional f64 > 0: an orthographic camera whose film back's fitted side (its height for [`SensorFit::Vertical`], else its width) spans this many metres, as Blender's Orthographic Scale | m | None (perspective) |
//!
//! Sensor fit ([`SensorFit`]): Blender's `AUTO` (the sensor width spans the larger image side),
//! `HORIZONTAL` (the width spans the image width), `VERTICAL` (the height spans the image
//! height), and USD's `expandAperture` conform policy ([`SensorFit::Expand`]: the horizontal
//! and vertical apertures are grown, never cropped, to the image's aspect). Shift is either in
//! millimetres on the sensor (the CLI, USD's aperture offsets) or Blender's fraction of the
//! fitted sensor side.

use super::{check_positive, CameraSpec, LensModel, Sensor};
use crate::error::{Error, Result};
use crate::optics::aperture::{Aperture, ApertureMask, ApertureShape};
use glam::DVec2;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::Arc;

/// How the sensor's size is fitted to the frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SensorFit {
    /// Blender's AUTO: the sensor width spans the larger image side.
    Auto,
    /// Blender's HORIZONTAL: the sensor width spans the image width.
    Horizontal,
    /// Blender's VERTICAL: the sensor height spans the image height.
    Vertical,
    /// USD's `expandAperture`: the larger of the two apertures at the image's aspect.
    Expand,
    /// USD's `cropAperture`: the smaller of the two apertures at the image's aspect.
    Crop,
}

impl FromStr for SensorFit {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "auto" | "AUTO" => Ok(SensorFit::Auto),
            "horizontal" | "HORIZONTAL" => Ok(SensorFit::Horizontal),
            "vertical" | "VERTICAL" => Ok(SensorFit::Vertical),
            "expand" | "expandAperture" => Ok(SensorFit::Expand),
            "crop" | "cropAperture" => Ok(SensorFit::Crop),
            f => Err(Error::camera(
                "sensor_fit",
                format!("expected 'auto', 'horizontal', 'vertical', 'expand' or 'crop', got '{f}'"),
            )),
        }
    }
}

/// UsdRender's `aspectRatioConformPolicy`: how a film back whose aspect differs from the
/// image's (columns × pixel aspect / rows) is fitted to it (the CLI's `--aspect-conform`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ConformPolicy {
    /// `expandAperture`: the aperture grows to the image's aspect (more of the scene).
    #[default]
    ExpandAperture,
    /// `cropAperture`: the aperture shrinks to the image's aspect (less of the scene).
    CropAperture,
    /// `adjustApertureWidth`: the height is kept, the width follows.
    AdjustApertureWidth,
    /// `adjustApertureHeight`: the width is kept, the height follows.
    AdjustApertureHeight,
    /// `adjustPixelAspectRatio`: the pixels take the aspect that makes the image cover the
    /// aperture exactly (any authored pixel aspect is disregarded).
    AdjustPixelAspectRatio,
}

impl FromStr for ConformPolicy {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "expandAperture" => Ok(ConformPolicy::ExpandAperture),
            "cropAperture" => Ok(ConformPolicy::CropAperture),
            "adjustApertureWidth" => Ok(ConformPolicy::AdjustApertureWidth),
            "adjustApertureHeight" => Ok(ConformPolicy::AdjustApertureHeight),
            "adjustPixelAspectRatio" => Ok(ConformPolicy::AdjustPixelAspectRatio),
            p => Err(Error::camera(
                "aspect_conform",
                format!("expected expandAperture, cropAperture, adjustApertureWidth, adjustApertureHeight or adjustPixelAspectRatio, got '{p}'"),
            )),
        }
    }
}

impl std::fmt::Display for ConformPolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            ConformPolicy::ExpandAperture => "expandAperture",
            ConformPolicy::CropAperture => "cropAperture",
            ConformPolicy::AdjustApertureWidth => "adjustApertureWidth",
            ConformPolicy::AdjustApertureHeight => "adjustApertureHeight",
            ConformPolicy::AdjustPixelAspectRatio => "adjustPixelAspectRatio",
        })
    }
}

impl ConformPolicy {
    /// `film_back` (its width and height the aperture) fitted by this policy to a `width` ×
    /// `height` pixel image: the fit, and for `adjustPixelAspectRatio` the pixel aspect.
    pub fn apply(self, film_back: FilmBack, width: u32, height: u32) -> FilmBack {
        match self {
            ConformPolicy::ExpandAperture => FilmBack { fit: SensorFit::Expand, ..film_back },
            ConformPolicy::CropAperture => FilmBack { fit: SensorFit::Crop, ..film_back },
            ConformPolicy::AdjustApertureWidth => FilmBack { fit: SensorFit::Vertical, ..film_back },
            ConformPolicy::AdjustApertureHeight => FilmBack { fit: SensorFit::Horizontal, ..film_back },
            ConformPolicy::AdjustPixelAspectRatio => FilmBack {
                fit: SensorFit::Expand,
                pixel_aspect: film_back.width_mm / film_back.height_mm * height as f64 / width.max(1) as f64,
                ..film_back
            },
        }
    }
}

/// Shift of the sensor in its plane (+x frames more of the right, +y more of the top).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shift {
    /// In millimetres on the sensor (the CLI's `--shift-x/-y`, USD's aperture offsets).
    Mm(DVec2),
    /// Blender's `shift_x/y`: fractions of the fitted sensor side.
    FitFraction(DVec2),
}

/// A host camera's film back: sensor size, fit and shift.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FilmBack {
    /// Sensor (or USD horizontal aperture) width.
    pub width_mm: f64,
    /// Sensor (or USD vertical aperture) height.
    pub height_mm: f64,
    /// How the size is fitted to the frame.
    pub fit: SensorFit,
    /// Shift in the sensor plane.
    pub shift: Shift,
    /// Width over height of one pixel (1 = square; USD's `pixelAspectRatio`): the frame's
    /// aspect on the sensor is `columns × pixel_aspect / rows`.
    pub pixel_aspect: f64,
}

impl Default for FilmBack {
    fn default() -> Self {
        FilmBack {
            width_mm: 36.0,
            height_mm: 24.0,
            fit: SensorFit::Auto,
            shift: Shift::Mm(DVec2::ZERO),
            pixel_aspect: 1.0,
        }
    }
}

impl FilmBack {
    /// USD's camera film back: `horizontalAperture`, `verticalAperture` and their offsets (all
    /// mm), fitted with the default `expandAperture` policy.
    pub fn usd(horizontal_mm: f64, vertical_mm: f64, horizontal_offset_mm: f64, vertical_offset_mm: f64) -> Self {
        FilmBack {
            width_mm: horizontal_mm,
            height_mm: vertical_mm,
            fit: SensorFit::Expand,
            shift: Shift::Mm(DVec2::new(horizontal_offset_mm, vertical_offset_mm)),
            pixel_aspect: 1.0,
        }
    }

    /// The side an orthographic scale spans: the height for [`SensorFit::Vertical`], else the
    /// width (Blender's AUTO and HORIZONTAL fits, and USD's horizontal aperture).
    pub fn fitted_side_mm(&self) -> f64 {
        match self.fit {
            SensorFit::Vertical => self.height_mm,
            _ => self.width_mm,
        }
    }

    /// The sensor of a `width` × `height` pixel frame with this film back, tilted by `tilt_deg`.
    pub fn sensor(&self, width: u32, height: u32, tilt_deg: DVec2) -> Result<Sensor> {
        if width == 0 || height == 0 {
            return Err(Error::settings("resolution", format!("{width}x{height} must be at least 1x1")));
        }
        check_positive("sensor_width_mm", self.width_mm)?;
        check_positive("sensor_height_mm", self.height_mm)?;
        check_positive("pixel_aspect", self.pixel_aspect)?;
        let aspect = width as f64 * self.pixel_aspect / height as f64;
        let (sw, sh, fitted) = match self.fit {
            SensorFit::Auto if width >= height => (self.width_mm, self.width_mm / aspect, self.width_mm),
            SensorFit::Auto => (self.width_mm * aspect, self.width_mm, self.width_mm),
            SensorFit::Horizontal => (self.width_mm, self.width_mm / aspect, self.width_mm),
            SensorFit::Vertical => (self.height_mm * aspect, self.height_mm, self.height_mm),
            SensorFit::Expand => {
                let sw = self.width_mm.max(self.height_mm * aspect);
                (sw, sw / aspect, sw)
            }
            SensorFit::Crop => {
                let sw = self.width_mm.min(self.height_mm * aspect);
                (sw, sw / aspect, sw)
            }
        };
        let shift_mm = match self.shift {
            Shift::Mm(s) => s,
            Shift::FitFraction(s) => s * fitted,
        };
        let sensor = Sensor { width_mm: sw, height_mm: sh, shift_mm, tilt_x_deg: tilt_deg.x, tilt_y_deg: tilt_deg.y };
        sensor.validate()?;
        Ok(sensor)
    }
}

/// glTF's (and Blender's exported) vertical field of view → the focal length (mm) that frames
/// it on `sensor`, the film of the `width` × `height` frame as the CLI fits it: the vertical
/// field spans the sensor's height, whatever the pixels' aspect (with non-square pixels the
/// height is not the width × height / width in pixels).
pub fn focal_length_from_yfov_mm(yfov_rad: f64, width: u32, height: u32, sensor: &Sensor) -> Result<f64> {
    if !(yfov_rad > 0.0 && yfov_rad < std::f64::consts::PI) {
        return Err(Error::camera("yfov", format!("the camera's field of view must be in (0, π) rad, got {yfov_rad}")));
    }
    if width == 0 || height == 0 {
        return Err(Error::camera("resolution", format!("{width}×{height} has no pixels")));
    }
    Ok(0.5 * sensor.height_mm / (yfov_rad * 0.5).tan())
}

/// The aperture from its text form: `circle`, `blades:N[:ROTATION_DEG]` (N ≥ 3) or
/// `image:MASK.png` (the CLI's `--aperture`).
pub fn parse_aperture(s: &str) -> Result<Aperture> {
    let bad = |m: &str| {
        Error::camera("aperture", format!("{m} (got '{s}'; expected circle, blades:N[:ROTATION_DEG] or image:PATH)"))
    };
    if s == "circle" {
        return Ok(Aperture::default());
    }
    if let Some(rest) = s.strip_prefix("blades:") {
        let mut it = rest.split(':');
        let n: u32 = it.next().and_then(|v| v.parse().ok()).ok_or_else(|| bad("blade count must be a whole number"))?;
        if n < 3 {
            return Err(bad("at least 3 blades"));
        }
        let rot: f64 = match it.next() {
            Some(r) => r.parse().map_err(|_| bad("rotation must be a number of degrees"))?,
            None => 0.0,
        };
        if !rot.is_finite() {
            return Err(bad("rotation must be finite"));
        }
        if it.next().is_some() {
            return Err(bad("too many fields"));
        }
        return Ok(Aperture {
            shape: ApertureShape::Blades { count: n, curvature: 0.0 },
            rotation_rad: rot.to_radians(),
            anamorphic_ratio: 1.0,
        });
    }
    if let Some(path) = s.strip_prefix("image:") {
        let mask = ApertureMask::load(Path::new(path))?;
        return Ok(Aperture { shape: ApertureShape::Mask(Arc::new(mask)), rotation_rad: 0.0, anamorphic_ratio: 1.0 });
    }
    Err(bad("unknown aperture"))
}

/// The aperture from Blender's camera fields: `blades` (0–2 = a circle, as Blender),
/// `rotation_rad`, `ratio` (anamorphic, > 0) and an optional mask image. `None` = the lens's
/// own stop (a circle for thin).
pub fn blender_aperture(blades: u32, rotation_rad: f64, ratio: f64, image: Option<&Path>) -> Result<Option<Aperture>> {
    if !rotation_rad.is_finite() {
        return Err(Error::camera("aperture_rotation_rad", format!("must be finite, got {rotation_rad}")));
    }
    check_positive("aperture_ratio", ratio)?;
    Ok(match (image, blades) {
        (Some(path), _) => Some(Aperture {
            shape: ApertureShape::Mask(Arc::new(ApertureMask::load(path)?)),
            rotation_rad,
            anamorphic_ratio: ratio,
        }),
        (None, n) if n >= 3 => Some(Aperture {
            shape: ApertureShape::Blades { count: n, curvature: 0.0 },
            rotation_rad,
            anamorphic_ratio: ratio,
        }),
        (None, _) if ratio != 1.0 => {
            Some(Aperture { shape: ApertureShape::Circle, rotation_rad: 0.0, anamorphic_ratio: ratio })
        }
        _ => None,
    })
}

/// A focus distance as hosts give it: `inf` (or None) is infinity; NaN, zero and negative
/// distances are errors.
pub fn focus_distance_m(value: Option<f64>) -> Result<Option<f64>> {
    match value {
        None => Ok(None),
        Some(d) if d == f64::INFINITY => Ok(None),
        Some(d) if d.is_nan() => Err(Error::camera("focus_distance_m", "is NaN (None or inf focuses at infinity)")),
        Some(d) => {
            check_positive("focus_distance_m", d)?;
            Ok(Some(d))
        }
    }
}

/// The clipping range: `0 ≤ start < end` (end may be infinite), along the view axis.
pub fn clip_range_m(start_m: f64, end_m: f64) -> Result<(f64, f64)> {
    if !(start_m >= 0.0 && start_m.is_finite()) || end_m.is_nan() || end_m <= start_m {
        return Err(Error::settings(
            "clip",
            format!("clip start {start_m} and end {end_m} must satisfy 0 ≤ start < end"),
        ));
    }
    Ok((start_m, end_m))
}

/// `on`/`off` (the CLI's `--natural-vignetting`).
pub fn parse_on_off(field: &str, s: &str) -> Result<bool> {
    match s {
        "on" => Ok(true),
        "off" => Ok(false),
        v => Err(Error::camera(field, format!("expected on or off, got '{v}'"))),
    }
}

/// A host application's camera, as the front ends describe it (see the module's table).
#[derive(Debug, Clone)]
pub struct HostCamera {
    /// `"thin"`, `"pinhole"`, a library lens name or a lens file.
    pub lens: String,
    /// Lens model.
    pub lens_model: LensModel,
    /// Error budget of `auto` (px).
    pub tolerance_px: f64,
    /// Focal length for thin and pinhole.
    pub focal_length_mm: f64,
    /// Film back.
    pub film_back: FilmBack,
    /// Sensor tilt (x, y).
    pub tilt_deg: DVec2,
    /// f-number (thin: None = pinhole; real: None = wide open).
    pub f_number: Option<f64>,
    /// Focus distance (None or inf = infinity).
    pub focus_distance_m: Option<f64>,
    /// Stop shape (None = the lens's own).
    pub aperture: Option<Aperture>,
    /// Clipping planes (start, end).
    pub clip_m: (f64, f64),
    /// cos⁴ falloff for thin and pinhole.
    pub natural_vignetting: bool,
    /// A baked LRTF table.
    pub lrtf_file: Option<PathBuf>,
    /// Orthographic: the metres the film back's fitted side spans (None = perspective).
    pub ortho_scale_m: Option<f64>,
}

impl Default for HostCamera {
    fn default() -> Self {
        HostCamera {
            lens: "thin".into(),
            lens_model: LensModel::Auto,
            tolerance_px: 0.25,
            focal_length_mm: 50.0,
            film_back: FilmBack::default(),
            tilt_deg: DVec2::ZERO,
            f_number: None,
            focus_distance_m: None,
            aperture: None,
            clip_m: (0.0, f64::INFINITY),
            natural_vignetting: true,
            lrtf_file: None,
            ortho_scale_m: None,
        }
    }
}

impl HostCamera {
    /// Checks every field that does not depend on the frame size.
    pub fn validate(&self) -> Result<()> {
        check_positive("tolerance_px", self.tolerance_px)?;
        check_positive("focal_length_mm", self.focal_length_mm)?;
        if let Some(n) = self.f_number {
            check_positive("f_number", n)?;
        }
        focus_distance_m(self.focus_distance_m)?;
        clip_range_m(self.clip_m.0, self.clip_m.1)?;
        if let Some(s) = self.ortho_scale_m {
            check_positive("ortho_scale_m", s)?;
        }
        for (f, t) in [("tilt_x_deg", self.tilt_deg.x), ("tilt_y_deg", self.tilt_deg.y)] {
            if !(t.is_finite() && t.abs() < 60.0) {
                return Err(Error::camera(f, format!("must be within ±60°, got {t}")));
            }
        }
        Ok(())
    }

    /// The camera spec for a `width` × `height` frame (everything validated).
    pub fn camera_spec(&self, width: u32, height: u32) -> Result<CameraSpec> {
        self.validate()?;
        let spec = CameraSpec {
            lens: self.lens.clone(),
            model: self.lens_model,
            tolerance_px: self.tolerance_px,
            focal_length_mm: self.focal_length_mm,
            f_number: self.f_number,
            focus_distance_m: focus_distance_m(self.focus_distance_m)?,
            aperture: self.aperture.clone(),
            sensor: self.film_back.sensor(width, height, self.tilt_deg)?,
            natural_vignetting: self.natural_vignetting,
            lrtf_file: self.lrtf_file.clone(),
            orthographic_m_per_mm: self.ortho_scale_m.map(|s| s / self.film_back.fitted_side_mm()),
        };
        spec.validate()?;
        Ok(spec)
    }
}
