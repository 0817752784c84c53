//! The Petzval lens file format (TOML): parse into typed structs, validate, then build a [`Lens`].
//!
//! Lengths are in millimetres. Surfaces are listed front (scene side) to back (film side).
//!
//! `[lens]` table:
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `name` | string | — | required |
//! | `source` | string: patent number, book and page, and where the data came from | — | required |
//! | `notes` | string | — | `""` |
//! | `focal_length_mm` | f64, design focal length (metadata; the traced value is computed) | mm | none |
//! | `f_number` | f64, design f-number (metadata) | — | none |
//! | `wavelengths_nm` | list of f64, design wavelengths | nm | `[486.1327, 587.5618, 656.2725]` |
//! | `primary_wavelength_nm` | f64 | nm | 587.5618 |
//! | `stop_semi_diameter_mm` | f64: the stop's opening as shipped (≤ its `semi_diameter_mm`) | mm | the stop's `semi_diameter_mm` |
//!
//! `[[surface]]` tables:
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `radius_mm` | f64; 0 = plane; positive = centre of curvature towards the film | mm | 0 |
//! | `thickness_mm` | f64, axial distance to the next surface (last: to the design image plane) | mm | required |
//! | `material` | `"air"`, a catalogue glass name, or `{ nd = .., vd = .. }` (medium after the surface) | — | `"air"` |
//! | `semi_diameter_mm` | f64, clear semi-diameter (for the stop: its widest opening) | mm | required |
//! | `conic` | f64, conic constant k | — | 0 |
//! | `aspheric_r2` | f64, coefficient A2 of r² (adds 2·A2 to the paraxial curvature) | 1/mm | 0 |
//! | `aspheric` | list of f64: A4, A6, A8, ... (coefficients of r⁴, r⁶, ...) | mm^(1-2i) | `[]` |
//! | `aspheric_odd` | list of f64: B1, B3, B5, ... (coefficients of r¹, r³, r⁵, ...: Zemax ODDASPHE; not in the paraxial curvature, and B1 makes a cone point at the vertex) | mm^(1-i) | `[]` |
//! | `cylinder` | `"x"` or `"y"`: the surface is curved only along this axis (anamorphic) | — | none |
//! | `stop` | bool: this surface is the aperture stop (usually a plane in air; a curved or glass surface may be the stop, as in Zemax) | — | false |
//! | `housing_semi_diameter_mm` | f64: mechanical radius around the stop opening | mm | stop `semi_diameter_mm` |
//! | `decenter_x_mm`, `decenter_y_mm` | f64: shift of the element that starts at this surface (x right, y up, looking from the camera towards the scene) | mm | 0 |
//! | `tilt_x_deg`, `tilt_y_deg` | f64 in [−45, 45]: rotation of that element about its front vertex, about the x then the y axis (right-handed: +x tilt turns the element's axis from +z towards −y) | degrees | 0 |
//!
//! Misalignment (`decenter_*`, `tilt_*`) belongs on an element's first surface (air before it,
//! glass after it) and moves every surface of the element, through cemented surfaces, up to the
//! one followed by air again: the element moves as a rigid body (decentre, then tilt about its
//! displaced front vertex). A misaligned lens is no longer rotationally symmetric, so it has no
//! 3-D LRTF table (`auto` renders it exactly); paraxial data (`lens info`, focusing) are those of
//! the aligned design.
//!
//! `[aperture]` table (shape of the stop opening):
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `shape` | `"circle"`, `"blades"` or `"image"` | — | `"circle"` |
//! | `blades` | u32 ≥ 3 (with `shape = "blades"`) | — | 6 |
//! | `rotation_deg` | f64 | degrees | 0 |
//! | `blade_curvature` | f64 in [0, 1]: 0 straight blades, 1 circular | — | 0 |
//! | `anamorphic_ratio` | f64 > 0: opening height / width (Blender's aperture ratio) | — | 1 |
//! | `image` | path of a PNG or EXR mask, relative to the lens file (with `shape = "image"`) | — | none |

use super::glass::Material;
use crate::error::{Error, Result};
use serde::de::Error as _;
use serde::{Deserialize, Serialize};

/// Default design wavelengths: F, d, C.
pub const DEFAULT_WAVELENGTHS_NM: [f64; 3] = [486.1327, 587.5618, 656.2725];

/// A whole lens file.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Prescription {
    /// Metadata.
    pub lens: LensMeta,
    /// The stop's shape.
    #[serde(default, skip_serializing_if = "ApertureSpec::is_default")]
    pub aperture: ApertureSpec,
    /// Surfaces, front to back.
    #[serde(rename = "surface")]
    pub surfaces: Vec<SurfaceSpec>,
}

/// The `[lens]` table.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Default)]
#[serde(deny_unknown_fields)]
pub struct LensMeta {
    /// Short name, e.g. `double-gauss-50mm`.
    pub name: String,
    /// Citation: patent number or book and page, and the data set it came through.
    pub source: String,
    /// Free text.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub notes: String,
    /// Design focal length (metadata).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub focal_length_mm: Option<f64>,
    /// Design f-number (metadata).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub f_number: Option<f64>,
    /// Design wavelengths.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wavelengths_nm: Option<Vec<f64>>,
    /// Primary wavelength.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub primary_wavelength_nm: Option<f64>,
    /// Stop opening as shipped (≤ the stop's semi-diameter).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stop_semi_diameter_mm: Option<f64>,
}

/// A `[[surface]]` table.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Default)]
#[serde(deny_unknown_fields)]
pub struct SurfaceSpec {
    /// Radius of curvature; 0 = plane.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub radius_mm: f64,
    /// Distance to the next surface.
    pub thickness_mm: f64,
    /// Medium after this surface.
    #[serde(default, skip_serializing_if = "MaterialSpec::is_air")]
    pub material: MaterialSpec,
    /// Clear semi-diameter.
    pub semi_diameter_mm: f64,
    /// Conic constant.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub conic: f64,
    /// Coefficient of r² (Zemax EVENASPH PARM 1).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub aspheric_r2: f64,
    /// Even aspheric coefficients A4, A6, ...
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub aspheric: Vec<f64>,
    /// Odd aspheric coefficients B1, B3, ... of r¹, r³, ...
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub aspheric_odd: Vec<f64>,
    /// Cylindrical surface: curved only along this axis.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cylinder: Option<CylinderAxis>,
    /// This surface is the aperture stop.
    #[serde(default, skip_serializing_if = "is_false")]
    pub stop: bool,
    /// Mechanical housing radius around the stop.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub housing_semi_diameter_mm: Option<f64>,
    /// Decentre along x of the element starting here.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub decenter_x_mm: f64,
    /// Decentre along y of the element starting here.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub decenter_y_mm: f64,
    /// Tilt about x of the element starting here.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub tilt_x_deg: f64,
    /// Tilt about y of the element starting here.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub tilt_y_deg: f64,
}

impl SurfaceSpec {
    /// Whether this surface carries a decentre or tilt.
    pub fn is_misaligned(&self) -> bool {
        self.decenter_x_mm != 0.0 || self.decenter_y_mm != 0.0 || self.tilt_x_deg != 0.0 || self.tilt_y_deg != 0.0
    }
}

/// Axis along which a cylindrical surface is curved.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum CylinderAxis {
    /// Curved along x (power in the x–z plane).
    X,
    /// Curved along y (power in the y–z plane).
    Y,
}

/// The medium after a surface: written as a glass name or as `{ nd = .., vd = .. }`
/// (deserialised by hand, so a wrong form gets a message that says which forms are accepted).
#[derive(Debug, Clone, Serialize, PartialEq)]
#[serde(untagged)]
pub enum MaterialSpec {
    /// `"air"` or a catalogue name.
    Name(String),
    /// A model glass.
    Model(ModelGlass),
}

/// `{ nd = .., vd = .. }`.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ModelGlass {
    /// Index at the d line.
    pub nd: f64,
    /// Abbe number; 0 = no dispersion.
    #[serde(default)]
    pub vd: f64,
}

/// What a `material` may be, for serde's "expected ..." messages.
const MATERIAL_FORMS: &str =
    "a glass name (\"air\", a catalogue name such as \"N-BK7\") or a model glass { nd = .., vd = .. }";

impl<'de> Deserialize<'de> for MaterialSpec {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> std::result::Result<Self, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = MaterialSpec;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str(MATERIAL_FORMS)
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> std::result::Result<MaterialSpec, E> {
                Ok(MaterialSpec::Name(v.to_string()))
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(self, map: A) -> std::result::Result<MaterialSpec, A::Error> {
                // the model glass's own (deny_unknown_fields) errors: "unknown field `ng`,
                // expected `nd` or `vd`", "missing field `nd`"
                ModelGlass::deserialize(serde::de::value::MapAccessDeserializer::new(map))
                    .map(MaterialSpec::Model)
                    .map_err(|e| {
                        // the message only (a toml error's display adds lines of context)
                        let e = e.to_string();
                        let first = e.lines().next().unwrap_or_default();
                        A::Error::custom(format!("{first} (a material is {MATERIAL_FORMS})"))
                    })
            }
        }
        deserializer.deserialize_any(Visitor)
    }
}

impl Default for MaterialSpec {
    fn default() -> Self {
        MaterialSpec::Name("air".into())
    }
}

impl MaterialSpec {
    fn is_air(&self) -> bool {
        match self {
            MaterialSpec::Name(n) => n.eq_ignore_ascii_case("air"),
            MaterialSpec::Model(m) => m.nd == 1.0,
        }
    }
}

/// Shape of the stop opening.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "lowercase")]
pub enum ApertureShapeSpec {
    /// A circle.
    #[default]
    Circle,
    /// A regular polygon of blades.
    Blades,
    /// A mask image.
    Image,
}

/// The `[aperture]` table.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ApertureSpec {
    /// Shape.
    #[serde(default)]
    pub shape: ApertureShapeSpec,
    /// Blade count.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub blades: Option<u32>,
    /// Rotation of the shape.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub rotation_deg: f64,
    /// Blade curvature 0..1.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub blade_curvature: f64,
    /// Height / width of the opening.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub anamorphic_ratio: f64,
    /// Mask image path.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub image: Option<String>,
}

impl Default for ApertureSpec {
    fn default() -> Self {
        ApertureSpec {
            shape: ApertureShapeSpec::Circle,
            blades: None,
            rotation_deg: 0.0,
            blade_curvature: 0.0,
            anamorphic_ratio: 1.0,
            image: None,
        }
    }
}

impl ApertureSpec {
    fn is_default(&self) -> bool {
        *self == ApertureSpec::default()
    }
}

fn one() -> f64 {
    1.0
}
fn is_one(v: &f64) -> bool {
    *v == 1.0
}
fn is_zero(v: &f64) -> bool {
    *v == 0.0
}
fn is_false(v: &bool) -> bool {
    !*v
}

/// Where a prescription came from, to name in error messages.
#[derive(Debug, Clone)]
pub struct SourceMap {
    /// File name shown in errors.
    pub file: String,
    /// 1-based line of each surface's table (0 when unknown).
    pub surface_lines: Vec<usize>,
    /// The file's text when it is our TOML (used to find a field's own line).
    text: Option<String>,
    /// Line of the `[aperture]` table.
    pub aperture_line: usize,
    /// Line of the `[lens]` table.
    pub lens_line: usize,
    /// Per surface, the source's own line and keyword of a field (importers: Zemax's `DISZ`
    /// for `thickness_mm`, ...); empty when the source has none.
    pub field_keywords: Vec<Vec<(String, usize, String)>>,
}

impl SourceMap {
    /// A map for a prescription built in memory or by an importer: surface `i` is on `lines[i]`.
    pub fn new(file: impl Into<String>, surface_lines: Vec<usize>) -> Self {
        SourceMap {
            file: file.into(),
            surface_lines,
            text: None,
            aperture_line: 0,
            lens_line: 0,
            field_keywords: Vec::new(),
        }
    }

    /// This map with the source's own line and keyword for fields of each surface
    /// (`keywords[i]`: (our field, line, keyword)), which errors then name.
    pub fn with_field_keywords(mut self, keywords: Vec<Vec<(String, usize, String)>>) -> Self {
        self.field_keywords = keywords;
        self
    }

    /// The source's (line, keyword) of `field` of surface `index`, where the importer knows it.
    fn keyword(&self, index: usize, field: &str) -> Option<(usize, &str)> {
        self.field_keywords.get(index)?.iter().find(|(f, _, _)| f == field).map(|(_, l, k)| (*l, k.as_str()))
    }

    /// Line of `field` inside surface `index` (falls back to the table's line).
    pub fn surface_field_line(&self, index: usize, field: &str) -> usize {
        if let Some((line, _)) = self.keyword(index, field) {
            return line;
        }
        self.field_line(self.surface_lines.get(index).copied().unwrap_or(0), field)
    }

    /// Line of `field` in the table whose header is on line `start` (falls back to `start`).
    fn field_line(&self, start: usize, field: &str) -> usize {
        if let (Some(text), true) = (&self.text, start > 0) {
            for (i, line) in text.lines().enumerate().skip(start) {
                let t = line.trim_start();
                if t.starts_with('[') {
                    break;
                }
                if t.starts_with(field) && t[field.len()..].trim_start().starts_with('=') {
                    return i + 1;
                }
            }
        }
        start
    }

    /// An error about field `field` of the `[lens]` table, on the field's own line.
    pub fn lens_error(&self, field: &str, message: impl Into<String>) -> Error {
        Error::lens_file(&self.file, self.field_line(self.lens_line, field), format!("lens.{field}"), message)
    }

    /// An error about field `field` of the `[aperture]` table, on the field's own line.
    pub fn aperture_error(&self, field: &str, message: impl Into<String>) -> Error {
        Error::lens_file(&self.file, self.field_line(self.aperture_line, field), format!("aperture.{field}"), message)
    }

    /// An error about field `field` of surface `index`.
    pub fn surface_error(&self, index: usize, field: &str, message: impl Into<String>) -> Error {
        let name = match self.keyword(index, field) {
            Some((_, keyword)) => format!("surface[{}].{} ({keyword})", index + 1, field),
            None => format!("surface[{}].{}", index + 1, field),
        };
        Error::lens_file(&self.file, self.surface_field_line(index, field), name, message)
    }
}

/// Parses our TOML lens format. `file` names the file in error messages.
pub fn parse_toml(text: &str, file: &str) -> Result<(Prescription, SourceMap)> {
    // 1. Typed parse: serde reports unknown or missing fields and wrong values with a byte span.
    let p: Prescription = toml::from_str(text).map_err(|e| toml_error(text, file, &e))?;
    // 2. Remember where each table starts, for validation errors.
    let mut surface_lines = Vec::new();
    let mut aperture_line = 0;
    let mut lens_line = 0;
    for (i, line) in text.lines().enumerate() {
        let t = line.trim();
        if t.starts_with("[[surface]]") {
            surface_lines.push(i + 1);
        } else if t.starts_with("[aperture]") {
            aperture_line = i + 1;
        } else if t.starts_with("[lens]") {
            lens_line = i + 1;
        }
    }
    let map = SourceMap {
        file: file.into(),
        surface_lines,
        text: Some(text.to_string()),
        aperture_line,
        lens_line,
        field_keywords: Vec::new(),
    };
    Ok((p, map))
}

/// A TOML or serde error as a [`Error::LensFile`] naming the line and the field's full path
/// (`surface[2].thickness_mm`, `lens.name`, `aperture.image`).
fn toml_error(text: &str, file: &str, e: &toml::de::Error) -> Error {
    let line = e.span().map(|s| line_of(text, s.start)).unwrap_or(0);
    let msg = e.message().trim_end().to_string();
    // the key assigned on the error's line (a value of the wrong type or variant, an unknown
    // key; a key inside an inline table is named by the message); on a table's header line
    // (a missing field), the field serde names
    let key = key_at_line(text, line).or_else(|| named_field(&msg));
    let table = table_at_line(text, line);
    let field = match (table, key) {
        (Some(t), Some(k)) => format!("{t}.{k}"),
        (Some(t), None) => t,
        (None, Some(k)) => k,
        (None, None) => "toml".into(),
    };
    Error::lens_file(file, line, field, friendlier(&msg))
}

/// serde's wording in terms of a lens file: a "sequence" is a list, an "f64" a number.
fn friendlier(msg: &str) -> String {
    msg.replace("expected a sequence", "expected a list of numbers, e.g. [1.0e-5, -2.0e-8]")
        .replace("expected f64", "expected a number")
        .replace("expected u32", "expected a whole number")
}

fn line_of(text: &str, byte: usize) -> usize {
    text[..byte.min(text.len())].bytes().filter(|&b| b == b'\n').count() + 1
}

/// The table that 1-based line `line` belongs to, as a field-path prefix: `lens`, `aperture`,
/// `surface[N]` (1-based, counting `[[surface]]` headers up to and including that line), any
/// other header's name; `None` before the first header.
fn table_at_line(text: &str, line: usize) -> Option<String> {
    let mut table = None;
    let mut surfaces = 0;
    for l in text.lines().take(line) {
        let t = l.trim();
        if let Some(rest) = t.strip_prefix("[[") {
            let name = rest.split("]]").next().unwrap_or("").trim();
            if name == "surface" {
                surfaces += 1;
                table = Some(format!("surface[{surfaces}]"));
            } else {
                table = Some(format!("{name}[]"));
            }
        } else if let Some(rest) = t.strip_prefix('[') {
            table = Some(rest.split(']').next().unwrap_or("").trim().to_string());
        }
    }
    table.filter(|t| !t.is_empty())
}

/// The key assigned on 1-based line `line` (`key = value`), or, when that line continues a value
/// (a list over several lines), on the nearest line above it in the same table.
fn key_at_line(text: &str, line: usize) -> Option<String> {
    let lines: Vec<&str> = text.lines().take(line).collect();
    for l in lines.iter().rev() {
        let t = l.trim_start();
        if t.starts_with('[') {
            return None;
        }
        if let Some((key, _)) = t.split_once('=') {
            let key = key.trim();
            let is_key =
                |k: &str| !k.is_empty() && k.chars().all(|c| c.is_ascii_alphanumeric() || "_.-\"'".contains(c));
            if is_key(key) {
                return Some(key.to_string());
            }
        }
    }
    None
}

/// The field a serde message names: "missing field `thickness_mm`", "unknown field `foo`, ...".
/// Other back-quoted text in serde's messages is a value (`invalid type: floating point
/// `0.00001``, `unknown variant `z``), not a field.
fn named_field(msg: &str) -> Option<String> {
    let rest = msg.strip_prefix("missing field `").or_else(|| msg.strip_prefix("unknown field `"))?;
    Some(rest[..rest.find('`')?].to_string())
}

/// Serialises a prescription to our TOML format.
pub fn to_toml(p: &Prescription) -> String {
    toml::to_string(p).unwrap_or_default()
}

/// A number as error messages show it: as written for ordinary magnitudes, in exponent form
/// (`1e300`, `1e-300`) past 1e9 or below 1e-6, where plain digits would run to hundreds.
pub(crate) struct Num(pub f64);

impl std::fmt::Display for Num {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let a = self.0.abs();
        if a.is_finite() && a != 0.0 && !(1e-6..1e9).contains(&a) {
            write!(f, "{:e}", self.0)
        } else {
            write!(f, "{}", self.0)
        }
    }
}

/// A validated, resolved surface (materials looked up).
#[derive(Debug, Clone)]
pub(crate) struct ResolvedSurface {
    pub spec: SurfaceSpec,
    pub material_after: Material,
}

/// Checks the misalignment fields of surface `i`: finite, in range, and on an element's first
/// surface (air before it, glass after it).
fn check_misalignment(p: &Prescription, i: usize, map: &SourceMap) -> Result<()> {
    let s = &p.surfaces[i];
    for (field, v, limit) in [
        ("decenter_x_mm", s.decenter_x_mm, s.semi_diameter_mm),
        ("decenter_y_mm", s.decenter_y_mm, s.semi_diameter_mm),
        ("tilt_x_deg", s.tilt_x_deg, 45.0),
        ("tilt_y_deg", s.tilt_y_deg, 45.0),
    ] {
        if !v.is_finite() {
            return Err(map.surface_error(i, field, format!("must be a finite number, got {}", Num(v))));
        }
        if v.abs() > limit {
            let unit = if field.ends_with("_deg") { "°" } else { " mm (the surface's semi-diameter)" };
            return Err(map.surface_error(i, field, format!("{} is outside ±{}{unit}", Num(v), Num(limit))));
        }
    }
    if !s.is_misaligned() {
        return Ok(());
    }
    let air_before = i == 0 || p.surfaces[i - 1].material.is_air();
    let field = if s.decenter_x_mm != 0.0 {
        "decenter_x_mm"
    } else if s.decenter_y_mm != 0.0 {
        "decenter_y_mm"
    } else if s.tilt_x_deg != 0.0 {
        "tilt_x_deg"
    } else {
        "tilt_y_deg"
    };
    if s.stop || !air_before || s.material.is_air() {
        return Err(map.surface_error(
            i,
            field,
            format!(
                "misalignment belongs on an element's first surface (air before it, glass after it); surface {} is {}",
                i + 1,
                if s.stop {
                    "the stop"
                } else if !air_before {
                    "inside an element"
                } else {
                    "followed by air"
                }
            ),
        ));
    }
    Ok(())
}

/// The longest length (thickness, semi-diameter) a lens file may give, in mm (every format).
pub const MAX_LENGTH_MM: f64 = 1.0e7;

/// The smallest Abbe number a model glass may have (0 means no dispersion).
pub const MIN_ABBE: f64 = 5.0;
/// The largest Abbe number a model glass may have.
pub const MAX_ABBE: f64 = 1000.0;

/// Checks every field and resolves materials. Geometry checks (intersecting elements) happen
/// in [`super::lens::Lens::new`], where surface shapes exist.
pub(crate) fn resolve(p: &Prescription, map: &SourceMap) -> Result<Vec<ResolvedSurface>> {
    let lens_err = |field: &str, msg: String| map.lens_error(field, msg);
    if p.lens.name.trim().is_empty() {
        return Err(lens_err("name", "must not be empty".into()));
    }
    for (field, v) in [
        ("focal_length_mm", p.lens.focal_length_mm),
        ("f_number", p.lens.f_number),
        ("primary_wavelength_nm", p.lens.primary_wavelength_nm),
        ("stop_semi_diameter_mm", p.lens.stop_semi_diameter_mm),
    ] {
        if let Some(v) = v {
            if !v.is_finite() {
                return Err(lens_err(field, format!("must be a finite number, got {v}")));
            }
        }
    }
    if let Some(w) = p.lens.primary_wavelength_nm {
        if !(380.0..=780.0).contains(&w) {
            return Err(lens_err("primary_wavelength_nm", format!("{} nm is outside 380..780 nm", Num(w))));
        }
    }
    if let Some(ws) = &p.lens.wavelengths_nm {
        if let Some(w) = ws.iter().find(|w| !(380.0..=780.0).contains(*w)) {
            return Err(lens_err("wavelengths_nm", format!("{} nm is outside 380..780 nm", Num(*w))));
        }
    }
    if p.surfaces.len() < 2 {
        return Err(Error::lens_file(&map.file, 0, "surface", "a lens needs at least two surfaces"));
    }
    let stops: Vec<usize> = p.surfaces.iter().enumerate().filter(|(_, s)| s.stop).map(|(i, _)| i).collect();
    match stops.len() {
        0 => {
            return Err(Error::lens_file(
                &map.file,
                0,
                "surface.stop",
                "no aperture stop: mark one surface with `stop = true`",
            ))
        }
        1 => {}
        _ => {
            return Err(map.surface_error(stops[1], "stop", "more than one aperture stop"));
        }
    }
    let mut out = Vec::with_capacity(p.surfaces.len());
    for (i, s) in p.surfaces.iter().enumerate() {
        let finite = |field: &str, v: f64| -> Result<()> {
            if v.is_finite() {
                Ok(())
            } else {
                Err(map.surface_error(i, field, format!("must be a finite number, got {v}")))
            }
        };
        finite("radius_mm", s.radius_mm)?;
        finite("thickness_mm", s.thickness_mm)?;
        finite("semi_diameter_mm", s.semi_diameter_mm)?;
        finite("conic", s.conic)?;
        finite("aspheric_r2", s.aspheric_r2)?;
        for a in &s.aspheric {
            finite("aspheric", *a)?;
        }
        for b in &s.aspheric_odd {
            finite("aspheric_odd", *b)?;
        }
        if s.thickness_mm < 0.0 {
            return Err(map.surface_error(i, "thickness_mm", format!("negative thickness {}", Num(s.thickness_mm))));
        }
        // the same plausibility limit as the .dat, .zmx and lentil importers
        for (field, v) in [("thickness_mm", s.thickness_mm), ("semi_diameter_mm", s.semi_diameter_mm)] {
            if v.abs() > MAX_LENGTH_MM {
                return Err(map.surface_error(
                    i,
                    field,
                    format!("{} mm is implausibly large (limit {} mm)", Num(v), Num(MAX_LENGTH_MM)),
                ));
            }
        }
        if s.semi_diameter_mm <= 0.0 {
            return Err(map.surface_error(
                i,
                "semi_diameter_mm",
                format!("must be positive, got {}", Num(s.semi_diameter_mm)),
            ));
        }
        if s.stop {
            let housing = s.housing_semi_diameter_mm.unwrap_or(s.semi_diameter_mm);
            finite("housing_semi_diameter_mm", housing)?;
            if s.semi_diameter_mm > housing {
                return Err(map.surface_error(
                    i,
                    "semi_diameter_mm",
                    format!(
                        "stop opening {} mm is larger than its housing {} mm",
                        Num(s.semi_diameter_mm),
                        Num(housing)
                    ),
                ));
            }
            if let Some(open) = p.lens.stop_semi_diameter_mm {
                if open <= 0.0 || open > s.semi_diameter_mm {
                    return Err(lens_err(
                        "stop_semi_diameter_mm",
                        format!(
                            "{} mm must be in (0, {}] (the stop's widest opening)",
                            Num(open),
                            Num(s.semi_diameter_mm)
                        ),
                    ));
                }
            }
        } else if s.housing_semi_diameter_mm.is_some() {
            return Err(map.surface_error(i, "housing_semi_diameter_mm", "only the stop has a housing radius"));
        }
        check_misalignment(p, i, map)?;
        let material_after = match &s.material {
            MaterialSpec::Name(n) => {
                Material::from_catalog(n).map_err(|e| map.surface_error(i, "material", e.to_string()))?
            }
            MaterialSpec::Model(m) => {
                if !(m.nd.is_finite() && (1.0..=3.0).contains(&m.nd)) {
                    return Err(map.surface_error(i, "material", format!("nd = {} must be in [1, 3]", Num(m.nd))));
                }
                // 0 = no dispersion; real glasses have Abbe numbers of about 15–100, and a tiny
                // vd would spread the index over the visible range without bound
                if !(m.vd.is_finite() && (m.vd == 0.0 || (MIN_ABBE..=MAX_ABBE).contains(&m.vd))) {
                    return Err(map.surface_error(
                        i,
                        "material",
                        format!("vd = {} must be 0 (no dispersion) or in [{MIN_ABBE}, {MAX_ABBE}]", Num(m.vd)),
                    ));
                }
                if m.nd == 1.0 {
                    Material::Air
                } else {
                    Material::Model { nd: m.nd, vd: m.vd }
                }
            }
        };
        out.push(ResolvedSurface { spec: s.clone(), material_after });
    }
    // Aperture table.
    let a = &p.aperture;
    let ap_err = |field: &str, msg: String| map.aperture_error(field, msg);
    if !(a.anamorphic_ratio.is_finite() && a.anamorphic_ratio > 0.0) {
        return Err(ap_err("anamorphic_ratio", format!("must be positive, got {}", Num(a.anamorphic_ratio))));
    }
    if !(0.0..=1.0).contains(&a.blade_curvature) {
        return Err(ap_err("blade_curvature", format!("must be in [0, 1], got {}", Num(a.blade_curvature))));
    }
    if !a.rotation_deg.is_finite() {
        return Err(ap_err("rotation_deg", "must be finite".into()));
    }
    match a.shape {
        ApertureShapeSpec::Blades => {
            if a.blades.unwrap_or(6) < 3 {
                return Err(ap_err("blades", "needs at least 3 blades".into()));
            }
        }
        ApertureShapeSpec::Image => {
            if a.image.is_none() {
                return Err(ap_err("image", "shape = \"image\" needs `image = \"mask.png\"`".into()));
            }
        }
        ApertureShapeSpec::Circle => {}
    }
    Ok(out)
}
