//! Fitted parameters: their names, and reading and writing them on a lens prescription and the
//! camera around it.
//!
//! | name | type | unit | meaning |
//! |---|---|---|---|
//! | `surface.N.radius_mm` | f64 | mm | radius of curvature of surface N (numbered from 1, front to back, as `petzval lens info` lists them) |
//! | `surface.N.thickness_mm` | f64 | mm | axial distance from surface N to the next |
//! | `surface.N.conic` | f64 | — | conic constant |
//! | `surface.N.nd`, `surface.N.vd` | f64 | — | the medium after surface N as a model glass (a catalogue glass starts from its own nd, Vd) |
//! | `surface.N.semi_diameter_mm` | f64 | mm | clear semi-diameter |
//! | `surface.N.decenter_x_mm`, `surface.N.decenter_y_mm` | f64 | mm | decentre of the element starting at surface N (x right, y up, looking from the camera towards the scene) |
//! | `surface.N.tilt_x_deg`, `surface.N.tilt_y_deg` | f64 | degrees | tilt of that element about its front vertex |
//! | `stop.position_mm` | f64 | mm | axial position of the stop from the first vertex (the gaps before and after it change, the rest stays) |
//! | `stop.semi_diameter_mm` | f64 | mm | the stop's widest opening (captures at `f_number = "open"` use it) |
//! | `aperture.blades` | integer ≥ 3 (0 = circular) | — | blade count |
//! | `aperture.rotation_deg` | f64 | degrees | rotation of the blade polygon |
//! | `aperture.curvature` | f64 in [0, 1] | — | blade curvature |
//! | `sensor.tilt_x_deg`, `sensor.tilt_y_deg` | f64 | degrees | sensor tilt (the renderer's tilt-shift convention) |
//! | `sensor.offset_mm` | f64 | mm | the sensor's displacement along the axis from where the focus setting puts it, positive away from the lens |
//! | `focus.scale` | f64 | — | factor on every capture's `focus_m` |
//! | `correction.TERM` | f64 | mrad | a coefficient of the LRTF correction (TERM: `defocus`, `scale`, `spherical`, `coma`, `astigmatism`, `field_curvature`, `distortion` nine fifth-order terms, `pupil_scale` (parts per thousand); see [`crate::correction`]) |

use crate::correction::{Coefficients, Term, TERMS, TERM_NAMES};
use petzval_optics::prescription::{ApertureShapeSpec, MaterialSpec, ModelGlass, Prescription};
use petzval_optics::Material;
use std::str::FromStr;

/// A field of one surface.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SurfaceField {
    /// `radius_mm`.
    RadiusMm,
    /// `thickness_mm`.
    ThicknessMm,
    /// `conic`.
    Conic,
    /// `nd`.
    Nd,
    /// `vd`.
    Vd,
    /// `semi_diameter_mm`.
    SemiDiameterMm,
    /// `decenter_x_mm`.
    DecenterXMm,
    /// `decenter_y_mm`.
    DecenterYMm,
    /// `tilt_x_deg`.
    TiltXDeg,
    /// `tilt_y_deg`.
    TiltYDeg,
}

/// One fittable parameter (see the module's table).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Param {
    /// A field of surface `index` (1-based).
    Surface {
        /// Surface number, from 1.
        index: usize,
        /// The field.
        field: SurfaceField,
    },
    /// `stop.position_mm`.
    StopPositionMm,
    /// `stop.semi_diameter_mm`.
    StopSemiDiameterMm,
    /// `aperture.blades`.
    ApertureBlades,
    /// `aperture.rotation_deg`.
    ApertureRotationDeg,
    /// `aperture.curvature`.
    ApertureCurvature,
    /// `sensor.tilt_x_deg`.
    SensorTiltXDeg,
    /// `sensor.tilt_y_deg`.
    SensorTiltYDeg,
    /// `sensor.offset_mm`.
    SensorOffsetMm,
    /// `focus.scale`.
    FocusScale,
    /// `correction.TERM`: a coefficient of the LRTF correction.
    Correction(Term),
}

const SURFACE_FIELDS: [(&str, SurfaceField); 10] = [
    ("radius_mm", SurfaceField::RadiusMm),
    ("thickness_mm", SurfaceField::ThicknessMm),
    ("conic", SurfaceField::Conic),
    ("nd", SurfaceField::Nd),
    ("vd", SurfaceField::Vd),
    ("semi_diameter_mm", SurfaceField::SemiDiameterMm),
    ("decenter_x_mm", SurfaceField::DecenterXMm),
    ("decenter_y_mm", SurfaceField::DecenterYMm),
    ("tilt_x_deg", SurfaceField::TiltXDeg),
    ("tilt_y_deg", SurfaceField::TiltYDeg),
];

const OTHER: [(&str, Param); 9] = [
    ("stop.position_mm", Param::StopPositionMm),
    ("stop.semi_diameter_mm", Param::StopSemiDiameterMm),
    ("aperture.blades", Param::ApertureBlades),
    ("aperture.rotation_deg", Param::ApertureRotationDeg),
    ("aperture.curvature", Param::ApertureCurvature),
    ("sensor.tilt_x_deg", Param::SensorTiltXDeg),
    ("sensor.tilt_y_deg", Param::SensorTiltYDeg),
    ("sensor.offset_mm", Param::SensorOffsetMm),
    ("focus.scale", Param::FocusScale),
];

impl FromStr for Param {
    type Err = String;
    fn from_str(s: &str) -> Result<Param, String> {
        if let Some((_, p)) = OTHER.iter().find(|(n, _)| *n == s) {
            return Ok(*p);
        }
        if let Some(term) = s.strip_prefix("correction.") {
            return term.parse().map(Param::Correction).map_err(|m| format!("'{s}': {m}"));
        }
        let unknown = || {
            format!(
                "unknown parameter '{s}': expected surface.N.{{{}}}, correction.{{{}}} or one of {}",
                SURFACE_FIELDS.map(|(n, _)| n).join(","),
                TERM_NAMES.map(|(n, _)| n).join(","),
                OTHER.map(|(n, _)| n).join(", ")
            )
        };
        let rest = s.strip_prefix("surface.").ok_or_else(unknown)?;
        let (n, field) = rest.split_once('.').ok_or_else(unknown)?;
        let index: usize = n.parse().map_err(|_| format!("'{s}': surface number '{n}' is not a positive integer"))?;
        if index == 0 {
            return Err(format!("'{s}': surfaces are numbered from 1"));
        }
        let (_, field) = SURFACE_FIELDS.iter().find(|(name, _)| *name == field).ok_or_else(unknown)?;
        Ok(Param::Surface { index, field: *field })
    }
}

impl std::fmt::Display for Param {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Param::Surface { index, field } => {
                let name = SURFACE_FIELDS.iter().find(|(_, g)| g == field).map(|(n, _)| *n).unwrap_or("?");
                write!(f, "surface.{index}.{name}")
            }
            Param::Correction(t) => write!(f, "correction.{}", t.name()),
            other => write!(f, "{}", OTHER.iter().find(|(_, p)| p == other).map(|(n, _)| *n).unwrap_or("?")),
        }
    }
}

impl Param {
    /// Whether the parameter takes integer values only.
    pub fn is_integer(&self) -> bool {
        matches!(self, Param::ApertureBlades)
    }

    /// Whether the parameter belongs to the lens (else to the camera around it).
    pub fn is_lens(&self) -> bool {
        !matches!(
            self,
            Param::SensorTiltXDeg
                | Param::SensorTiltYDeg
                | Param::SensorOffsetMm
                | Param::FocusScale
                | Param::Correction(_)
        )
    }

    /// Whether the parameter is a coefficient of the LRTF correction.
    pub fn is_correction(&self) -> bool {
        matches!(self, Param::Correction(_))
    }
}

/// The camera's fitted parameters (the lens's are in its prescription).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraParams {
    /// Sensor tilt about x.
    pub sensor_tilt_x_deg: f64,
    /// Sensor tilt about y.
    pub sensor_tilt_y_deg: f64,
    /// Sensor displacement along the axis, positive away from the lens.
    pub sensor_offset_mm: f64,
    /// Factor on every focus distance.
    pub focus_scale: f64,
}

impl Default for CameraParams {
    fn default() -> Self {
        CameraParams { sensor_tilt_x_deg: 0.0, sensor_tilt_y_deg: 0.0, sensor_offset_mm: 0.0, focus_scale: 1.0 }
    }
}

/// Everything a fit changes: the lens prescription, the camera parameters and the LRTF
/// correction.
#[derive(Debug, Clone, PartialEq)]
pub struct Model {
    /// The lens.
    pub prescription: Prescription,
    /// The camera.
    pub camera: CameraParams,
    /// Coefficients of the LRTF correction (all zero: none).
    pub correction: Coefficients,
}

impl Model {
    /// A lens with the default camera and no correction.
    pub fn new(prescription: Prescription) -> Model {
        Model { prescription, camera: CameraParams::default(), correction: [0.0; TERMS] }
    }

    /// Whether the model corrects the lens's rays (a correction coefficient is not zero).
    pub fn has_correction(&self) -> bool {
        self.correction.iter().any(|c| *c != 0.0)
    }

    fn stop_index(&self) -> Result<usize, String> {
        self.prescription.surfaces.iter().position(|s| s.stop).ok_or_else(|| "the lens has no stop".to_string())
    }

    fn surface_index(&self, param: &Param, index: usize) -> Result<usize, String> {
        let n = self.prescription.surfaces.len();
        if index > n {
            return Err(format!("{param}: the lens has {n} surfaces"));
        }
        Ok(index - 1)
    }

    /// The parameter's current value.
    pub fn get(&self, param: &Param) -> Result<f64, String> {
        let p = &self.prescription;
        Ok(match *param {
            Param::Surface { index, field } => {
                let s = &p.surfaces[self.surface_index(param, index)?];
                match field {
                    SurfaceField::RadiusMm => s.radius_mm,
                    SurfaceField::ThicknessMm => s.thickness_mm,
                    SurfaceField::Conic => s.conic,
                    SurfaceField::Nd => material_nd_vd(&s.material, param)?.0,
                    SurfaceField::Vd => material_nd_vd(&s.material, param)?.1,
                    SurfaceField::SemiDiameterMm => s.semi_diameter_mm,
                    SurfaceField::DecenterXMm => s.decenter_x_mm,
                    SurfaceField::DecenterYMm => s.decenter_y_mm,
                    SurfaceField::TiltXDeg => s.tilt_x_deg,
                    SurfaceField::TiltYDeg => s.tilt_y_deg,
                }
            }
            Param::StopPositionMm => {
                let k = self.stop_index()?;
                p.surfaces[..k].iter().map(|s| s.thickness_mm).sum()
            }
            Param::StopSemiDiameterMm => p.surfaces[self.stop_index()?].semi_diameter_mm,
            Param::ApertureBlades => match p.aperture.shape {
                ApertureShapeSpec::Blades => p.aperture.blades.unwrap_or(6) as f64,
                _ => 0.0,
            },
            Param::ApertureRotationDeg => p.aperture.rotation_deg,
            Param::ApertureCurvature => p.aperture.blade_curvature,
            Param::SensorTiltXDeg => self.camera.sensor_tilt_x_deg,
            Param::SensorTiltYDeg => self.camera.sensor_tilt_y_deg,
            Param::SensorOffsetMm => self.camera.sensor_offset_mm,
            Param::FocusScale => self.camera.focus_scale,
            Param::Correction(t) => self.correction[t.index()],
        })
    }

    /// Sets the parameter (the lens is validated when it is built).
    pub fn set(&mut self, param: &Param, value: f64) -> Result<(), String> {
        if !value.is_finite() {
            return Err(format!("{param}: {value} is not a finite number"));
        }
        match *param {
            Param::Surface { index, field } => {
                let i = self.surface_index(param, index)?;
                let s = &mut self.prescription.surfaces[i];
                match field {
                    SurfaceField::RadiusMm => s.radius_mm = value,
                    SurfaceField::ThicknessMm => s.thickness_mm = value,
                    SurfaceField::Conic => s.conic = value,
                    SurfaceField::Nd | SurfaceField::Vd => {
                        let (mut nd, mut vd) = material_nd_vd(&s.material, param)?;
                        if field == SurfaceField::Nd {
                            nd = value;
                        } else {
                            vd = value;
                        }
                        s.material = MaterialSpec::Model(ModelGlass { nd, vd });
                    }
                    SurfaceField::SemiDiameterMm => s.semi_diameter_mm = value,
                    SurfaceField::DecenterXMm => s.decenter_x_mm = value,
                    SurfaceField::DecenterYMm => s.decenter_y_mm = value,
                    SurfaceField::TiltXDeg => s.tilt_x_deg = value,
                    SurfaceField::TiltYDeg => s.tilt_y_deg = value,
                }
            }
            Param::StopPositionMm => {
                let k = self.stop_index()?;
                if k == 0 {
                    return Err(format!("{param}: the stop is the first surface; nothing in front of it can change"));
                }
                let delta = value - self.get(param)?;
                let s = &mut self.prescription.surfaces;
                s[k - 1].thickness_mm += delta;
                s[k].thickness_mm -= delta;
            }
            Param::StopSemiDiameterMm => {
                let k = self.stop_index()?;
                let s = &mut self.prescription.surfaces[k];
                s.semi_diameter_mm = value;
                if let Some(h) = s.housing_semi_diameter_mm {
                    s.housing_semi_diameter_mm = Some(h.max(value));
                }
                self.prescription.lens.stop_semi_diameter_mm = None;
            }
            Param::ApertureBlades => {
                let n = value.round();
                let a = &mut self.prescription.aperture;
                if n == 0.0 {
                    a.shape = ApertureShapeSpec::Circle;
                    a.blades = None;
                } else {
                    a.shape = ApertureShapeSpec::Blades;
                    a.blades = Some(n.max(3.0) as u32);
                }
            }
            Param::ApertureRotationDeg => self.prescription.aperture.rotation_deg = value,
            Param::ApertureCurvature => self.prescription.aperture.blade_curvature = value,
            Param::SensorTiltXDeg => self.camera.sensor_tilt_x_deg = value,
            Param::SensorTiltYDeg => self.camera.sensor_tilt_y_deg = value,
            Param::SensorOffsetMm => self.camera.sensor_offset_mm = value,
            Param::FocusScale => self.camera.focus_scale = value,
            Param::Correction(t) => self.correction[t.index()] = value,
        }
        Ok(())
    }
}

/// (nd, Vd) of a medium: a model glass's own, a catalogue glass's from its dispersion formula.
fn material_nd_vd(m: &MaterialSpec, param: &Param) -> Result<(f64, f64), String> {
    match m {
        MaterialSpec::Model(g) => Ok((g.nd, g.vd)),
        MaterialSpec::Name(name) => {
            let material = Material::from_catalog(name).map_err(|e| format!("{param}: {e}"))?;
            if material == Material::Air {
                return Err(format!("{param}: the medium after this surface is air (fit glass, not air gaps)"));
            }
            Ok(material.nd_vd())
        }
    }
}
