//! The capture manifest (TOML; paths relative to it): which lens to start from, the sensor, the
//! free parameters with their bounds, and one table per photograph of a point source.
//!
//! `[lens]`:
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `start` | library name or lens file (`.toml`, `.zmx`, `.dat`, `FILE.json#ID`) | — | required |
//! | `table` | the start lens's baked LRTF table (`petzval lrtf bake`); checked against `start`, its resolution, film radius and wavelengths are those of the corrected table `--lrtf` writes | — | none (96³, the sensor's half-diagonal) |
//!
//! `[sensor]`:
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `width_mm`, `height_mm` | f64 > 0: the full sensor | mm | required |
//! | `pixels` | `[columns, rows]` of the full sensor (the pixel pitch follows) | px | required |
//!
//! `[[free]]` (one per fitted parameter; names in [`crate::params`]):
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `param` | parameter name, e.g. `surface.3.radius_mm` | — | required |
//! | `min`, `max` | f64 bounds, `min < max` (integers for `aperture.blades`) | the parameter's | required |
//! | `start` | f64 inside the bounds | the parameter's | the start lens's value |
//!
//! `[[capture]]`:
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `image` | EXR (RGB or Y) or floating-point TIFF (linear), 16-bit PNG or TIFF, 8-bit PNG, TIFF or JPEG (see `transfer`) | — | required |
//! | `transfer` | `"linear"` or `"srgb"` (decoded before fitting; the dark frame too) | — | `"linear"` |
//! | `crop_origin_px` | `[x, y]`: the image's top-left pixel on the full sensor (x right, y down) | px | required |
//! | `source_m` | `[x, y, z]`: the point source, x right, y up, z forward | m | required |
//! | `focus_m` | f64 > 0: focus distance as set on the lens | m | required |
//! | `distances_from` | `"sensor"` or `"entrance_pupil"`: the origin of `source_m` and `focus_m` | — | `"sensor"` |
//! | `f_number` | f64, or `"open"` (the stop fully open) | — | required |
//! | `wavelength_nm` | f64 in 380..780, or `"rgb"` (colour images: three wavelengths) | nm | required |
//! | `exposure` | f64 > 0, relative (a free intensity scale is fitted anyway) | — | 1 |
//! | `dark_frame` | image of the same size and format range (8-bit, 16-bit or floating point), decoded by the capture's `transfer` and subtracted in linear light; its lone bright pixels mark hot ones (`captures`) | — | none |
//! | `mask` | image of the same size; non-zero = use the pixel | — | all pixels |
//! | `saturation` | f64: pixel values at or above it are clipped and masked | image units | 65535 for 16-bit PNG/TIFF, 255 for 8-bit PNG/TIFF, 245 for JPEG (its ringing keeps a clipped core below 255), none for EXR and float TIFF |
//!
//! Images are upright, as cameras write them: a source right of and above the axis shows right
//! of and above the image centre.

use crate::error::{Error, Result};
use crate::params::Param;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// A parsed and validated manifest; paths are resolved against the manifest's folder.
#[derive(Debug, Clone)]
pub struct Manifest {
    /// The manifest file (for messages).
    pub file: PathBuf,
    /// Where the fit starts.
    pub start_lens: String,
    /// The start lens's baked LRTF table (`[lens] table`), if given.
    pub start_table: Option<PathBuf>,
    /// The full sensor.
    pub sensor: SensorSpec,
    /// The fitted parameters, in manifest order.
    pub free: Vec<FreeParam>,
    /// The photographs.
    pub captures: Vec<Capture>,
}

/// The full sensor.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorSpec {
    /// Width of the full sensor.
    pub width_mm: f64,
    /// Height of the full sensor.
    pub height_mm: f64,
    /// `[columns, rows]` of the full sensor.
    pub pixels: [u32; 2],
}

impl SensorSpec {
    /// Pixel pitch along x and y (mm per pixel).
    pub fn pitch_mm(&self) -> (f64, f64) {
        (self.width_mm / self.pixels[0] as f64, self.height_mm / self.pixels[1] as f64)
    }
}

/// One fitted parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct FreeParam {
    /// The parameter.
    pub param: Param,
    /// The name as written.
    pub name: String,
    /// Lower bound.
    pub min: f64,
    /// Upper bound.
    pub max: f64,
    /// Start value (None: the start lens's).
    pub start: Option<f64>,
}

/// Where `source_m` and `focus_m` are measured from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum DistancesFrom {
    /// The sensor plane (the camera's ⦶ mark).
    #[default]
    Sensor,
    /// The lens's entrance pupil.
    EntrancePupil,
}

/// How pixel values encode light.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Transfer {
    /// Linear in light.
    #[default]
    Linear,
    /// sRGB-encoded (decoded before fitting).
    Srgb,
}

/// The stop setting of a capture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FNumber {
    /// Stopped to this f-number.
    Stopped(f64),
    /// Fully open.
    Open,
}

/// The wavelengths of a capture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Wavelength {
    /// One wavelength (a monochrome or filtered image).
    Mono(f64),
    /// Colour: the lens's three design wavelengths for R, G and B.
    Rgb,
}

/// One photograph of a point source.
#[derive(Debug, Clone, PartialEq)]
pub struct Capture {
    /// The manifest file (for messages).
    pub manifest: String,
    /// How messages name this capture: `capture[2] (p02.png)`, its number and image as written.
    pub label: String,
    /// The image (resolved path).
    pub image: PathBuf,
    /// Pixel encoding.
    pub transfer: Transfer,
    /// Whether the manifest set `transfer` (else it is the default, linear).
    pub transfer_given: bool,
    /// The image's top-left pixel on the full sensor.
    pub crop_origin_px: [i64; 2],
    /// The source (m), from [`Capture::distances_from`].
    pub source_m: [f64; 3],
    /// Focus distance as set (m), from [`Capture::distances_from`].
    pub focus_m: f64,
    /// Origin of the distances.
    pub distances_from: DistancesFrom,
    /// Stop setting.
    pub f_number: FNumber,
    /// Wavelengths.
    pub wavelength: Wavelength,
    /// Relative exposure.
    pub exposure: f64,
    /// Dark frame (resolved path).
    pub dark_frame: Option<PathBuf>,
    /// Mask (resolved path).
    pub mask: Option<PathBuf>,
    /// Clipping level (None: the format's default).
    pub saturation: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawManifest {
    lens: RawLens,
    sensor: SensorSpec,
    #[serde(default)]
    free: Vec<RawFree>,
    #[serde(default)]
    capture: Vec<RawCapture>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLens {
    start: String,
    table: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFree {
    param: String,
    min: f64,
    max: f64,
    #[serde(default)]
    start: Option<f64>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum NumberOr {
    Number(f64),
    Word(String),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCapture {
    image: String,
    #[serde(default)]
    transfer: Option<Transfer>,
    crop_origin_px: [i64; 2],
    source_m: [f64; 3],
    focus_m: f64,
    #[serde(default)]
    distances_from: DistancesFrom,
    f_number: NumberOr,
    wavelength_nm: NumberOr,
    #[serde(default = "one")]
    exposure: f64,
    #[serde(default)]
    dark_frame: Option<String>,
    #[serde(default)]
    mask: Option<String>,
    #[serde(default)]
    saturation: Option<f64>,
}

fn one() -> f64 {
    1.0
}

impl Manifest {
    /// Reads and validates a manifest file.
    pub fn load(path: &Path) -> Result<Manifest> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::Io { path: path.into(), source: e })?;
        Manifest::parse(&text, path)
    }

    /// Parses and validates manifest text; `path` names the file and anchors relative paths.
    pub fn parse(text: &str, path: &Path) -> Result<Manifest> {
        let file = path.display().to_string();
        let raw: RawManifest = toml::from_str(text.trim_start_matches('\u{feff}')).map_err(|e| {
            // 1 + the newlines before the span (`lines()` misses a span at a line's start)
            let line = e.span().map(|s| text[..s.start].matches('\n').count() + 1).unwrap_or(0);
            Error::manifest(format!("{file}:{line}"), "manifest", e.message().to_string())
        })?;
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        let resolve = |p: &str| if Path::new(p).is_absolute() { PathBuf::from(p) } else { dir.join(p) };
        let err = |field: String, msg: String| Error::manifest(&file, field, msg);

        // 1. Sensor.
        let s = raw.sensor;
        for (field, v) in [("sensor.width_mm", s.width_mm), ("sensor.height_mm", s.height_mm)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(err(field.into(), format!("must be a positive number of millimetres, got {v}")));
            }
        }
        if s.pixels[0] == 0 || s.pixels[1] == 0 {
            return Err(err("sensor.pixels".into(), format!("must be positive, got {:?}", s.pixels)));
        }
        let (px, py) = s.pitch_mm();
        if (px / py - 1.0).abs() > 0.02 {
            return Err(err(
                "sensor.pixels".into(),
                format!(
                    "contradicts the sensor size: the pixel pitch would be {:.3} µm across and {:.3} µm down",
                    px * 1e3,
                    py * 1e3
                ),
            ));
        }

        // 2. Free parameters.
        let mut free = Vec::with_capacity(raw.free.len());
        for (i, f) in raw.free.iter().enumerate() {
            let field = |k: &str| format!("free[{}].{k}", i + 1);
            let param: Param = f.param.parse().map_err(|m: String| err(field("param"), m))?;
            if free.iter().any(|g: &FreeParam| g.param == param) {
                return Err(err(field("param"), format!("'{}' is listed twice", f.param)));
            }
            if !(f.min.is_finite() && f.max.is_finite() && f.min < f.max) {
                return Err(err(
                    field("min"),
                    format!("bounds must be finite with min < max, got [{}, {}]", f.min, f.max),
                ));
            }
            if param.is_integer() && (f.min.fract() != 0.0 || f.max.fract() != 0.0) {
                return Err(err(field("min"), format!("'{}' is an integer: bounds must be integers", f.param)));
            }
            if let Some(v) = f.start {
                if !(v >= f.min && v <= f.max) {
                    return Err(err(field("start"), format!("{v} is outside [{}, {}]", f.min, f.max)));
                }
            }
            free.push(FreeParam { param, name: f.param.clone(), min: f.min, max: f.max, start: f.start });
        }

        // 3. Captures.
        if raw.capture.is_empty() {
            return Err(err("capture".into(), "no [[capture]] tables: nothing to fit".into()));
        }
        let mut captures = Vec::with_capacity(raw.capture.len());
        for (i, c) in raw.capture.iter().enumerate() {
            let field = |k: &str| format!("capture[{}] ({}).{k}", i + 1, c.image);
            // (the same naming as `Capture::label`)
            if c.source_m.iter().any(|v| !v.is_finite()) {
                return Err(err(field("source_m"), format!("must be finite, got {:?}", c.source_m)));
            }
            if !(c.source_m[2] > 0.0) {
                return Err(err(
                    field("source_m"),
                    format!("z = {} m: the source must be in front of the camera", c.source_m[2]),
                ));
            }
            if !(c.focus_m.is_finite() && c.focus_m > 0.0) {
                return Err(err(field("focus_m"), format!("must be a positive distance in metres, got {}", c.focus_m)));
            }
            if !(c.exposure.is_finite() && c.exposure > 0.0) {
                return Err(err(field("exposure"), format!("must be positive, got {}", c.exposure)));
            }
            let f_number = match &c.f_number {
                NumberOr::Number(n) if n.is_finite() && *n > 0.0 => FNumber::Stopped(*n),
                NumberOr::Word(w) if w == "open" => FNumber::Open,
                NumberOr::Number(n) => return Err(err(field("f_number"), format!("must be positive, got {n}"))),
                NumberOr::Word(w) => {
                    return Err(err(field("f_number"), format!("expected a number or \"open\", got \"{w}\"")));
                }
            };
            let wavelength = match &c.wavelength_nm {
                NumberOr::Number(w) if (380.0..=780.0).contains(w) => Wavelength::Mono(*w),
                NumberOr::Word(w) if w == "rgb" => Wavelength::Rgb,
                NumberOr::Number(w) => {
                    return Err(err(field("wavelength_nm"), format!("{w} nm is outside 380..780 nm")))
                }
                NumberOr::Word(w) => {
                    return Err(err(field("wavelength_nm"), format!("expected a number or \"rgb\", got \"{w}\"")));
                }
            };
            if let Some(v) = c.saturation {
                if !(v.is_finite() && v > 0.0) {
                    return Err(err(field("saturation"), format!("must be positive, got {v}")));
                }
            }
            // The same image at the same crop twice would count it twice (one photograph of
            // several sources may be listed once per crop).
            if let Some(j) = captures
                .iter()
                .position(|p: &Capture| p.image == resolve(&c.image) && p.crop_origin_px == c.crop_origin_px)
            {
                return Err(err(field("image"), format!("the same image and crop as capture[{}]", j + 1)));
            }
            captures.push(Capture {
                manifest: file.clone(),
                label: format!("capture[{}] ({})", i + 1, c.image),
                image: resolve(&c.image),
                transfer: c.transfer.unwrap_or_default(),
                transfer_given: c.transfer.is_some(),
                crop_origin_px: c.crop_origin_px,
                source_m: c.source_m,
                focus_m: c.focus_m,
                distances_from: c.distances_from,
                f_number,
                wavelength,
                exposure: c.exposure,
                dark_frame: c.dark_frame.as_deref().map(resolve),
                mask: c.mask.as_deref().map(resolve),
                saturation: c.saturation,
            });
        }
        // A library name as it is; a file relative to the manifest (never to the working
        // directory, so the manifest means the same wherever it is run from).
        let start = raw.lens.start.as_str();
        let file_part = start.rsplit_once('#').map_or(start, |(f, _)| f);
        let is_library = petzval_optics::LIBRARY.iter().any(|e| e.name == start);
        let start_lens = if is_library || Path::new(file_part).is_absolute() {
            start.to_string()
        } else {
            dir.join(start).display().to_string()
        };
        let start_table = raw.lens.table.as_deref().map(resolve);
        Ok(Manifest { file: path.to_path_buf(), start_lens, start_table, sensor: s, free, captures })
    }
}
