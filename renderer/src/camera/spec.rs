//! Camera specification: what a front end asks for (lens name, lens model, sensor, focus,
//! aperture). [`CameraSpec::build`](super::builder) turns it into a [`Camera`](super::Camera).
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
//! | `orthographic_m_per_mm` | optional f64: an orthographic projection, scene metres per sensor millimetre (ideal lenses only) | m/mm | None (perspective) |

use super::Sensor;
use crate::error::{Error, Result};
use crate::optics::aperture::Aperture;
use crate::optics::lens::Lens;
use crate::optics::library::load_lens;
use std::path::PathBuf;
use std::str::FromStr;

/// Default LRTF resolution when `lrtf` is asked for without one.
pub const DEFAULT_LRTF_RESOLUTION: u32 = 96;

/// How a real lens is evaluated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LensModel {
    /// The cheapest model within the error budget (see [`ModelChoice`](super::ModelChoice)).
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
    /// Parallel projection ([`CameraSpec::orthographic_m_per_mm`]; no lens at all).
    Orthographic,
}

impl LensModel {
    /// The candidates `auto` evaluates for a real lens, cheapest first (exact is the reference
    /// and the fallback).
    pub const AUTO_CANDIDATES: [LensModel; 7] = [
        LensModel::Pinhole,
        LensModel::Thin,
        LensModel::Thick,
        LensModel::Lrtf { resolution: 32 },
        LensModel::Lrtf { resolution: 64 },
        LensModel::Lrtf { resolution: 96 },
        LensModel::Lrtf { resolution: 128 },
    ];

    /// Nominal cost of one camera ray (ns, one core) for a lens of `surfaces` surfaces: the
    /// fixed cost model of `auto` (measured with `petzval bench lens` and `bench lens-models`,
    /// see docs/speed-vs-error.md), so its choice is the same on every run.
    pub fn nominal_ns_per_ray(self, surfaces: usize) -> f64 {
        let exact = 40.0 * surfaces as f64;
        match self {
            LensModel::Pinhole | LensModel::Orthographic => 30.0,
            LensModel::Thin => 50.0,
            LensModel::Thick => 60.0,
            LensModel::Lrtf { .. } => 30.0 + 0.02 * exact,
            LensModel::Exact | LensModel::Auto => exact,
        }
    }
}

impl FromStr for LensModel {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        let bad = || {
            Error::camera(
                "lens_model",
                format!("expected auto, exact, lrtf[:RESOLUTION], thick, thin, pinhole or orthographic, got '{s}'"),
            )
        };
        Ok(match s {
            "auto" => LensModel::Auto,
            "exact" => LensModel::Exact,
            "lrtf" => LensModel::Lrtf { resolution: DEFAULT_LRTF_RESOLUTION },
            "thick" => LensModel::Thick,
            "thin" => LensModel::Thin,
            "pinhole" => LensModel::Pinhole,
            "orthographic" => LensModel::Orthographic,
            _ => match s.strip_prefix("lrtf:") {
                Some(r) => {
                    let resolution: u32 = r.parse().map_err(|_| bad())?;
                    if !(8..=256).contains(&resolution) {
                        return Err(Error::camera(
                            "lens_model",
                            format!("LRTF resolution {resolution} is outside 8..=256"),
                        ));
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
            LensModel::Orthographic => write!(f, "orthographic"),
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
    /// An orthographic projection: scene metres per sensor millimetre (None = perspective).
    pub orthographic_m_per_mm: Option<f64>,
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
            orthographic_m_per_mm: None,
        }
    }
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
        let bad = |f: &str, m: String| Err(Error::camera(f, m));
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
        if let Some(k) = self.orthographic_m_per_mm {
            if !(k.is_finite() && k > 0.0) {
                return bad("orthographic_m_per_mm", format!("must be positive, got {k}"));
            }
        }
        if self.model == LensModel::Orthographic && self.orthographic_m_per_mm.is_none() {
            return bad("lens_model", "the orthographic model needs an orthographic scale".into());
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
            // wider than the lens opens: fully open, as a camera body does (the build warns)
            lens = lens.stopped_down_or_open(n)?.0;
        }
        if let Some(a) = &self.aperture {
            lens = lens.with_aperture(a.clone());
        }
        Ok(SpecLens::Real(Box::new(lens)))
    }

    /// An ideal lens without an aperture: `"pinhole"`, or `"thin"` without an f-number.
    pub(crate) fn is_pinhole(&self) -> bool {
        self.lens == "pinhole" || (self.lens == "thin" && self.f_number.is_none())
    }
}
