//! UsdGeomCamera (with the schema's fallbacks, which openusd 0.6 does not supply) and the
//! `PetzvalLensAPI` applied schema → the renderer's [`HostCamera`].
//!
//! | attribute | unit in USD | here | fallback |
//! |---|---|---|---|
//! | `focalLength` | tenths of a scene unit | mm = value × 100 × metersPerUnit | 50 |
//! | `horizontalAperture`, `verticalAperture` | tenths of a scene unit | mm, [`FilmBack::usd`] (expandAperture fit) | 20.955, 15.2908 |
//! | `horizontalApertureOffset`, `verticalApertureOffset` | tenths of a scene unit | sensor shift, mm | 0, 0 |
//! | `fStop` | — | f-number; 0 = no depth of field (a pinhole for `thin`) | 0 |
//! | `focusDistance` | scene units | m; 0 = not set (the CLI autofocuses) | 0 |
//! | `clippingRange` | scene units | m | (1, 1000000) |
//! | `projection` | token | `perspective`, or `orthographic`: a window of the apertures' size in tenths of a scene unit (GfCamera's convention), parallel rays | perspective |
//! | `petzval:lens` | asset | a library name, or a lens file resolved relative to its layer | thin |
//! | `petzval:lensModel` | token | auto, exact, lrtf, thick, thin, pinhole | auto |
//! | `petzval:tolerancePx` | float | error budget of auto | 0.25 |
//! | `petzval:tiltX`, `petzval:tiltY` | degrees | sensor tilt | 0 |
//! | `petzval:aperture:blades` | int | 0–2 = circle | 0 |
//! | `petzval:aperture:rotation` | degrees | blade rotation | 0 |
//! | `petzval:aperture:curvature` | 0–1 | straight … circular blades | 0 |
//! | `petzval:aperture:ratio` | > 0 | anamorphic height / width | 1 |
//! | `petzval:aperture:image` | asset | a mask image (PNG/EXR) | none |
//!
//! The `petzval:*` attributes are read only when the prim applies `PetzvalLensAPI`; authored
//! without it they are reported and ignored. All of them may be time-sampled.

use crate::value::{attr_error, Reader};
use crate::xform::StageUnits;
use crate::Error;
use glam::{DMat4, DVec2};
use openusd::usd;
use petzval_renderer::camera::host::{self, FilmBack, HostCamera};
use petzval_renderer::{ApertureShape, LensModel};
use std::path::PathBuf;

/// `PetzvalLensAPI` as authored on a camera.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct PetzvalLens {
    /// Lens: the resolved file path, or the library name as authored.
    pub lens: Option<String>,
    /// Lens model token.
    pub lens_model: Option<String>,
    /// Error budget of auto (px).
    pub tolerance_px: Option<f64>,
    /// Tilt about x (degrees).
    pub tilt_x_deg: f64,
    /// Tilt about y (degrees).
    pub tilt_y_deg: f64,
    /// Blade count (0–2 = circle).
    pub blades: i64,
    /// Blade rotation (degrees).
    pub rotation_deg: f64,
    /// Blade curvature (0 straight, 1 circular).
    pub curvature: f64,
    /// Anamorphic ratio.
    pub ratio: f64,
    /// Aperture mask image (resolved path).
    pub image: Option<String>,
}

/// A UsdGeomCamera with its fallbacks applied, in renderer units.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct UsdCamera {
    /// Prim path.
    pub path: String,
    /// Camera-to-world in the renderer's world (metres, +y up; rigid; looks down −z).
    #[serde(skip)]
    pub to_world: DMat4,
    /// Focal length (mm).
    pub focal_length_mm: f64,
    /// Horizontal aperture (mm).
    pub horizontal_aperture_mm: f64,
    /// Vertical aperture (mm).
    pub vertical_aperture_mm: f64,
    /// Horizontal aperture offset (mm).
    pub horizontal_aperture_offset_mm: f64,
    /// Vertical aperture offset (mm).
    pub vertical_aperture_offset_mm: f64,
    /// f-stop (0 = no depth of field).
    pub f_stop: f64,
    /// Focus distance (m; None when 0 or unauthored).
    pub focus_distance_m: Option<f64>,
    /// Clipping range (m).
    pub clipping_range_m: (f64, f64),
    /// Projection token.
    pub projection: String,
    /// `PetzvalLensAPI` values (None when the schema is not applied).
    pub petzval: Option<PetzvalLens>,
}

fn asset_path(reader: &Reader, prim: &usd::Prim, name: &str) -> Result<Option<String>, Error> {
    Ok(reader.asset(prim, name)?.map(|(authored, resolved)| match resolved {
        Some(r) if !r.is_empty() => r,
        _ => authored,
    }))
}

/// Reads the camera prim (`to_world` is its stage world transform).
pub fn read_camera(
    reader: &Reader,
    prim: &usd::Prim,
    stage_world: DMat4,
    units: &StageUnits,
    warnings: &mut Vec<String>,
) -> Result<UsdCamera, Error> {
    let mpu = units.meters_per_unit;
    let tenth = 100.0 * mpu; // mm per tenth of a scene unit
    let focal = reader.f64_or(prim, "focalLength", 50.0)?;
    let ha = reader.f64_or(prim, "horizontalAperture", 20.955)?;
    let va = reader.f64_or(prim, "verticalAperture", 15.2908)?;
    let ho = reader.f64_or(prim, "horizontalApertureOffset", 0.0)?;
    let vo = reader.f64_or(prim, "verticalApertureOffset", 0.0)?;
    let f_stop = reader.f64_or(prim, "fStop", 0.0)?;
    let focus = reader.f64_or(prim, "focusDistance", 0.0)?;
    let clip = reader.vec2(prim, "clippingRange")?.unwrap_or(DVec2::new(1.0, 1_000_000.0));
    let projection = reader.token(prim, "projection")?.unwrap_or_else(|| "perspective".into());
    for (name, v) in [("focalLength", focal), ("horizontalAperture", ha), ("verticalAperture", va)] {
        if v <= 0.0 {
            return Err(attr_error(prim, name, format!("must be positive, got {v}")));
        }
    }
    if f_stop < 0.0 {
        return Err(attr_error(prim, "fStop", format!("must be 0 (no depth of field) or positive, got {f_stop}")));
    }
    if focus < 0.0 {
        return Err(attr_error(prim, "focusDistance", format!("must not be negative, got {focus}")));
    }
    if !(clip.x >= 0.0 && clip.y > clip.x) {
        return Err(attr_error(prim, "clippingRange", format!("must satisfy 0 ≤ near < far, got {clip}")));
    }
    let applied = prim
        .api_schemas()
        .map_err(|e| attr_error(prim, "apiSchemas", format!("cannot be read: {e:#}")))?
        .iter()
        .any(|s| s.as_str() == "PetzvalLensAPI");
    let petzval = if applied {
        let blades = match reader.raw(prim, "petzval:aperture:blades")? {
            None => 0,
            Some(openusd::sdf::Value::Int(i)) => i as i64,
            Some(openusd::sdf::Value::Int64(i)) => i,
            Some(openusd::sdf::Value::Uint(i)) => i as i64,
            Some(v) => return Err(attr_error(prim, "petzval:aperture:blades", format!("expected an int, got {v:?}"))),
        };
        Some(PetzvalLens {
            lens: asset_path(reader, prim, "petzval:lens")?,
            lens_model: reader.token(prim, "petzval:lensModel")?,
            tolerance_px: reader.f64(prim, "petzval:tolerancePx")?,
            tilt_x_deg: reader.f64_or(prim, "petzval:tiltX", 0.0)?,
            tilt_y_deg: reader.f64_or(prim, "petzval:tiltY", 0.0)?,
            blades,
            rotation_deg: reader.f64_or(prim, "petzval:aperture:rotation", 0.0)?,
            curvature: reader.f64_or(prim, "petzval:aperture:curvature", 0.0)?,
            ratio: reader.f64_or(prim, "petzval:aperture:ratio", 1.0)?,
            image: asset_path(reader, prim, "petzval:aperture:image")?,
        })
    } else {
        if reader.raw(prim, "petzval:lens")?.is_some() {
            warnings.push(format!(
                "{}: petzval:lens is authored but the prim does not apply PetzvalLensAPI; the petzval:* attributes are ignored",
                prim.path()
            ));
        }
        None
    };
    Ok(UsdCamera {
        path: prim.path().to_string(),
        to_world: crate::xform::rigid(units.to_renderer() * stage_world),
        focal_length_mm: focal * tenth,
        horizontal_aperture_mm: ha * tenth,
        vertical_aperture_mm: va * tenth,
        horizontal_aperture_offset_mm: ho * tenth,
        vertical_aperture_offset_mm: vo * tenth,
        f_stop,
        focus_distance_m: if focus > 0.0 { Some(focus * mpu) } else { None },
        clipping_range_m: (clip.x * mpu, clip.y * mpu),
        projection,
        petzval,
    })
}

impl UsdCamera {
    /// The host camera this prim describes (lens `thin` unless `PetzvalLensAPI` names one).
    pub fn host_camera(&self) -> Result<HostCamera, Error> {
        let bad = |attr: &str, message: String| Error::Prim {
            layer: String::new(),
            prim: self.path.clone(),
            message: format!("{attr}: {message}"),
        };
        // Orthographic: the window is the apertures in tenths of a scene unit, so the
        // aperture read as millimetres (× 100 × metersPerUnit) is the window in metres × 1000.
        let ortho_scale_m = match self.projection.as_str() {
            "perspective" => None,
            "orthographic" => Some(self.horizontal_aperture_mm * 1e-3),
            p => {
                return Err(bad(
                    "projection",
                    format!("'{p}' is not a UsdGeomCamera projection (perspective or orthographic)"),
                ))
            }
        };
        let mut cam = HostCamera {
            focal_length_mm: self.focal_length_mm,
            film_back: FilmBack::usd(
                self.horizontal_aperture_mm,
                self.vertical_aperture_mm,
                self.horizontal_aperture_offset_mm,
                self.vertical_aperture_offset_mm,
            ),
            f_number: if self.f_stop > 0.0 { Some(self.f_stop) } else { None },
            focus_distance_m: self.focus_distance_m,
            clip_m: self.clipping_range_m,
            ortho_scale_m,
            ..HostCamera::default()
        };
        if let Some(p) = &self.petzval {
            if let Some(l) = &p.lens {
                cam.lens = l.clone();
            }
            if let Some(m) = &p.lens_model {
                cam.lens_model = m.parse::<LensModel>().map_err(|e| bad("petzval:lensModel", e.to_string()))?;
            }
            if let Some(t) = p.tolerance_px {
                cam.tolerance_px = t;
            }
            cam.tilt_deg = DVec2::new(p.tilt_x_deg, p.tilt_y_deg);
            if p.blades < 0 || p.blades > 1000 {
                return Err(bad("petzval:aperture:blades", format!("must be 0 (circle) or 3…1000, got {}", p.blades)));
            }
            if !(0.0..=1.0).contains(&p.curvature) {
                return Err(bad("petzval:aperture:curvature", format!("must be within 0…1, got {}", p.curvature)));
            }
            let image = p.image.as_ref().map(PathBuf::from);
            let mut aperture =
                host::blender_aperture(p.blades as u32, p.rotation_deg.to_radians(), p.ratio, image.as_deref())
                    .map_err(|e| bad("petzval:aperture", e.to_string()))?;
            if let Some(a) = &mut aperture {
                if let ApertureShape::Blades { curvature, .. } = &mut a.shape {
                    *curvature = p.curvature;
                }
            }
            cam.aperture = aperture;
        }
        cam.validate().map_err(|e| bad("camera", e.to_string()))?;
        Ok(cam)
    }
}
