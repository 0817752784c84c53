//! Camera specification → [`Camera`]: the one place where a lens name, a lens model and a
//! sensor become a camera, shared by the CLI and the Blender add-on.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `lens` | `"thin"`, `"pinhole"`, a library name or a lens file | — | `"thin"` |
//! | `model` | [`LensModel`]: auto, exact, lrtf[:RES], thick, thin, pinhole | — | auto |
//! | `tolerance_px` | f64: error budget of `auto` (image-plane pixels at the render's resolution) | px | 0.25 |
//! | `focal_length_mm` | f64, thin and pinhole only (a real lens brings its own) | mm | 50 |
//! | `f_number` | optional f64: thin → `None` is a pinhole; real → stops the lens down | — | None |
//! | `focus_distance_m` | optional f64 from the entrance pupil (None = infinity) | m | None |
//! | `aperture` | optional [`Aperture`] shape (None = the lens's own; circle for thin) | — | None |
//! | `sensor` | [`Sensor`] | mm, degrees | 36 × 24 |
//! | `natural_vignetting` | bool, thin and pinhole (cos⁴) | — | true |
//! | `lrtf_file` | optional baked table to use for `lrtf` | — | None |

use super::model_choice::{choose_model, ModelChoice, ShotContext};
use super::{Camera, LrtfCamera, PinholeCamera, RealisticCamera, Sensor, ThickLensCamera, ThinLensCamera};
use crate::error::{Error, Result};
use crate::integrator::RenderScene;
use crate::optics::aperture::Aperture;
use crate::optics::lens::Lens;
use crate::optics::library::load_lens;
use crate::optics::lrtf::{BakeOptions, LrtfTable};
use crate::render::scene_depth_range_m;
use glam::DAffine3;
use std::collections::HashMap;
use std::path::PathBuf;
use std::str::FromStr;
use std::sync::{Arc, Mutex, OnceLock};

/// Default LRTF resolution when `lrtf` is asked for without one.
pub const DEFAULT_LRTF_RESOLUTION: u32 = 96;

/// How a real lens is evaluated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LensModel {
    /// The cheapest model within the error budget (see [`choose_model`]).
    Auto,
    /// Exact trace through every surface.
    Exact,
    /// A ray transfer table of this resolution (baked on demand, cached in the process).
    Lrtf {
        /// Table resolution (cells per axis).
        resolution: u32,
    },
    /// Thick-lens approximation (focal length, principal planes, pupil).
    Thick,
    /// Ideal thin lens of the same focal length (Blender's conventions).
    Thin,
    /// Pinhole (no depth of field, no aberrations).
    Pinhole,
}

impl FromStr for LensModel {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        let bad = || Error::Camera {
            field: "lens_model".into(),
            message: format!("expected auto, exact, lrtf[:RESOLUTION], thick, thin or pinhole, got '{s}'"),
        };
        Ok(match s {
            "auto" => LensModel::Auto,
            "exact" => LensModel::Exact,
            "lrtf" => LensModel::Lrtf { resolution: DEFAULT_LRTF_RESOLUTION },
            "thick" => LensModel::Thick,
            "thin" => LensModel::Thin,
            "pinhole" => LensModel::Pinhole,
            _ => match s.strip_prefix("lrtf:") {
                Some(r) => {
                    let resolution: u32 = r.parse().map_err(|_| bad())?;
                    if !(8..=256).contains(&resolution) {
                        return Err(Error::Camera {
                            field: "lens_model".into(),
                            message: format!("LRTF resolution {resolution} is outside 8..=256"),
                        });
                    }
                    LensModel::Lrtf { resolution }
                }
                None => return Err(bad()),
            },
        })
    }
}

impl std::fmt::Display for LensModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LensModel::Auto => write!(f, "auto"),
            LensModel::Exact => write!(f, "exact"),
            LensModel::Lrtf { resolution } => write!(f, "lrtf:{resolution}"),
            LensModel::Thick => write!(f, "thick"),
            LensModel::Thin => write!(f, "thin"),
            LensModel::Pinhole => write!(f, "pinhole"),
        }
    }
}

/// Everything that defines a camera (see the module's parameter table).
#[derive(Debug, Clone)]
pub struct CameraSpec {
    /// `"thin"`, `"pinhole"`, a library lens name or a lens file path.
    pub lens: String,
    /// Lens model.
    pub model: LensModel,
    /// Error budget of [`LensModel::Auto`] in image-plane pixels.
    pub tolerance_px: f64,
    /// Focal length for thin and pinhole cameras.
    pub focal_length_mm: f64,
    /// f-number (thin: None = pinhole; real lens: None = wide open).
    pub f_number: Option<f64>,
    /// Focus distance from the entrance pupil (None = infinity).
    pub focus_distance_m: Option<f64>,
    /// Stop shape (None = the lens's own, a circle for thin).
    pub aperture: Option<Aperture>,
    /// Sensor.
    pub sensor: Sensor,
    /// cos⁴ falloff for thin and pinhole cameras.
    pub natural_vignetting: bool,
    /// A baked LRTF table to use instead of baking.
    pub lrtf_file: Option<PathBuf>,
}

impl Default for CameraSpec {
    fn default() -> Self {
        CameraSpec {
            lens: "thin".into(),
            model: LensModel::Auto,
            tolerance_px: 0.25,
            focal_length_mm: 50.0,
            f_number: None,
            focus_distance_m: None,
            aperture: None,
            sensor: Sensor::default(),
            natural_vignetting: true,
            lrtf_file: None,
        }
    }
}

/// A camera built from a [`CameraSpec`], with what was decided.
#[derive(Debug, Clone)]
pub struct BuiltCamera {
    /// The camera.
    pub camera: Camera,
    /// The lens's name (`thin`, `pinhole` or the real lens's name).
    pub lens_label: String,
    /// Focal length (mm).
    pub focal_length_mm: f64,
    /// f-number (infinity for a pinhole).
    pub f_number: f64,
    /// The model used and why.
    pub choice: ModelChoice,
}

/// The lens of a spec: ideal or real.
#[derive(Debug, Clone)]
pub(crate) enum SpecLens {
    /// An ideal thin lens (None f-number = pinhole).
    Ideal,
    /// A real lens, stopped down and with the spec's aperture.
    Real(Box<Lens>),
}

impl CameraSpec {
    /// Checks the numbers (the lens is checked when loaded).
    pub fn validate(&self) -> Result<()> {
        let bad = |f: &str, m: String| Err(Error::Camera { field: f.into(), message: m });
        self.sensor.validate()?;
        if !(self.tolerance_px.is_finite() && self.tolerance_px > 0.0) {
            return bad("tolerance_px", format!("must be a positive number of pixels, got {}", self.tolerance_px));
        }
        if !(self.focal_length_mm.is_finite() && self.focal_length_mm > 0.0) {
            return bad("focal_length_mm", format!("must be positive, got {}", self.focal_length_mm));
        }
        if let Some(n) = self.f_number {
            if !(n.is_finite() && n > 0.0) {
                return bad("f_number", format!("must be positive, got {n}"));
            }
        }
        if let Some(d) = self.focus_distance_m {
            if !(d.is_finite() && d > 0.0) {
                return bad("focus_distance_m", format!("must be positive, got {d}"));
            }
        }
        Ok(())
    }

    /// Loads the lens, stopped down and with the spec's aperture.
    pub(crate) fn load_lens(&self) -> Result<SpecLens> {
        if self.lens == "thin" || self.lens == "pinhole" {
            return Ok(SpecLens::Ideal);
        }
        let mut lens = load_lens(&self.lens)?;
        if let Some(n) = self.f_number {
            lens = lens.stopped_down(n)?;
        }
        if let Some(a) = &self.aperture {
            lens = lens.with_aperture(a.clone());
        }
        Ok(SpecLens::Real(Box::new(lens)))
    }

    /// Builds the camera; `shot` (resolution, samples, scene depth range) informs `auto`.
    pub fn build(&self, shot: &ShotContext) -> Result<BuiltCamera> {
        self.validate()?;
        self.build_loaded(self.load_lens()?, shot)
    }

    /// Builds the camera for a shot of `scene` seen from `to_world` at `width` × `height` and
    /// `spp`: the depth range `auto` must honour is probed in the scene through a pinhole of the
    /// lens's focal length. The lens is loaded once.
    pub fn build_for_scene(
        &self,
        scene: &RenderScene,
        to_world: &DAffine3,
        width: u32,
        height: u32,
        spp: u32,
        spectral: bool,
    ) -> Result<BuiltCamera> {
        self.validate()?;
        let lens = self.load_lens()?;
        let probe_focal_mm = match &lens {
            SpecLens::Ideal => self.focal_length_mm,
            SpecLens::Real(l) => l.paraxial().efl_mm,
        };
        let depth_range_m = scene_depth_range_m(scene, to_world, &self.sensor, probe_focal_mm);
        self.build_loaded(lens, &ShotContext { width, height, spp, depth_range_m, spectral })
    }

    fn build_loaded(&self, lens: SpecLens, shot: &ShotContext) -> Result<BuiltCamera> {
        let (choice, camera) = match self.model {
            LensModel::Auto => choose_model(self, &lens, shot)?,
            m => (ModelChoice::fixed(m), None),
        };
        let camera = match camera {
            Some(c) => c,
            None => self.build_model(&lens, choice.model, None)?,
        };
        let (lens_label, focal_length_mm, f_number) = match &lens {
            SpecLens::Ideal if self.is_pinhole() => ("pinhole".to_string(), self.focal_length_mm, f64::INFINITY),
            SpecLens::Ideal => ("thin".to_string(), self.focal_length_mm, self.f_number.unwrap_or(f64::INFINITY)),
            SpecLens::Real(l) => (l.name().to_string(), l.paraxial().efl_mm, l.paraxial().f_number),
        };
        Ok(BuiltCamera { camera, lens_label, focal_length_mm, f_number, choice })
    }

    /// An ideal lens without an aperture: `"pinhole"`, or `"thin"` without an f-number.
    pub(crate) fn is_pinhole(&self) -> bool {
        self.lens == "pinhole" || (self.lens == "thin" && self.f_number.is_none())
    }

    /// The camera of one model (not `Auto`); `exact` is the exact camera when already built
    /// (its exit-pupil bounds are costly), for the LRTF.
    pub(crate) fn build_model(
        &self,
        lens: &SpecLens,
        model: LensModel,
        exact: Option<&RealisticCamera>,
    ) -> Result<Camera> {
        let sensor = self.sensor;
        let focus = self.focus_distance_m;
        match lens {
            SpecLens::Ideal => match (model, self.is_pinhole()) {
                (LensModel::Pinhole, _) | (LensModel::Exact | LensModel::Thin | LensModel::Auto, true) => {
                    let mut c = PinholeCamera::new(sensor, self.focal_length_mm)?;
                    c.natural_vignetting = self.natural_vignetting;
                    Ok(Camera::Pinhole(c))
                }
                (LensModel::Exact | LensModel::Thin | LensModel::Auto, false) => {
                    let n = self.f_number.unwrap_or(f64::INFINITY);
                    let mut c = ThinLensCamera::new(
                        sensor,
                        self.focal_length_mm,
                        n,
                        focus,
                        self.aperture.clone().unwrap_or_default(),
                    )?;
                    c.natural_vignetting = self.natural_vignetting;
                    Ok(Camera::ThinLens(c))
                }
                (m, _) => Err(Error::Camera {
                    field: "lens_model".into(),
                    message: format!(
                        "the {} model needs a real lens (a library name or a lens file), not '{}'",
                        m, self.lens
                    ),
                }),
            },
            SpecLens::Real(lens) => match model {
                LensModel::Exact | LensModel::Auto => {
                    Ok(Camera::Realistic(RealisticCamera::new(sensor, (**lens).clone(), focus)?))
                }
                LensModel::Lrtf { resolution } => {
                    let table = match &self.lrtf_file {
                        Some(path) => Arc::new(LrtfTable::load(path, lens)?),
                        None => cached_lrtf(lens, resolution)?,
                    };
                    let exact = match exact {
                        Some(e) => e.clone(),
                        None => RealisticCamera::new(sensor, (**lens).clone(), focus)?,
                    };
                    Ok(Camera::Lrtf(LrtfCamera::with_exact(exact, table)?))
                }
                LensModel::Thick => {
                    Ok(Camera::ThickLens(ThickLensCamera::new(sensor, lens, None, focus, lens.aperture().clone())?))
                }
                LensModel::Thin => {
                    let p = lens.paraxial();
                    let mut c = ThinLensCamera::new(sensor, p.efl_mm, p.f_number, focus, lens.aperture().clone())?;
                    c.natural_vignetting = true;
                    Ok(Camera::ThinLens(c))
                }
                LensModel::Pinhole => {
                    // The pinhole that frames as the lens does at this focus: the thick lens's
                    // film distance behind its rear principal plane.
                    let thick = ThickLensCamera::new(sensor, lens, None, focus, lens.aperture().clone())?;
                    let mut c = PinholeCamera::new(sensor, thick.film_z_mm() - thick.rear_principal_z_mm)?;
                    c.natural_vignetting = true;
                    Ok(Camera::Pinhole(c))
                }
            },
        }
    }
}

type TableKey = (u64, u32);

fn table_cache() -> &'static Mutex<HashMap<TableKey, Arc<LrtfTable>>> {
    static CACHE: OnceLock<Mutex<HashMap<TableKey, Arc<LrtfTable>>>> = OnceLock::new();
    CACHE.get_or_init(|| Mutex::new(HashMap::new()))
}

/// An LRTF table of `lens` at `resolution`, baked once per process (the stop is applied at
/// lookup, so one table serves every f-number and stop shape of the lens). At most a few
/// tables are kept.
pub fn cached_lrtf(lens: &Lens, resolution: u32) -> Result<Arc<LrtfTable>> {
    let key = (crate::optics::lrtf::lens_hash(lens), resolution);
    if let Some(t) = table_cache().lock().map_err(|_| Error::Internal("LRTF cache poisoned".into()))?.get(&key) {
        return Ok(t.clone());
    }
    let table = Arc::new(LrtfTable::bake(lens, &BakeOptions { resolution, ..BakeOptions::default() }, &|_| {})?);
    let mut cache = table_cache().lock().map_err(|_| Error::Internal("LRTF cache poisoned".into()))?;
    if cache.len() >= 8 {
        cache.clear();
    }
    cache.insert(key, table.clone());
    Ok(table)
}
