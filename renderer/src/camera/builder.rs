//! The one public camera builder: [`CameraSpec::build`] loads the lens once, lets `auto` pick
//! the model (or takes the one asked for) and constructs the camera. The CLI, the Python
//! module, the benchmarks and the `auto` chooser's candidates all come through here (or
//! through its one-model step), so every front end renders the same camera for the same spec.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `spec` | [`CameraSpec`] (see its parameter table) | — | — |
//! | `shot` | [`ShotContext`]: resolution, spp, scene depth range, spectral | px | 1920 × 1280, 64 spp |

use super::model::build_model;
use super::model_choice::{choose_model, ModelChoice, ShotContext};
use super::spec::{CameraSpec, LensModel, SpecLens};
use super::Camera;
use crate::error::Result;

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
    /// What the build changed from the request (an f-number wider than the lens opens).
    pub warnings: Vec<String>,
}

impl CameraSpec {
    /// Builds the camera; `shot` (resolution, samples, scene depth range) informs `auto`.
    pub fn build(&self, shot: &ShotContext) -> Result<BuiltCamera> {
        self.validate()?;
        self.build_loaded(self.load_lens()?, shot)
    }

    /// Builds the camera with the lens already loaded by [`CameraSpec::load_lens`].
    pub(crate) fn build_loaded(&self, lens: SpecLens, shot: &ShotContext) -> Result<BuiltCamera> {
        if let SpecLens::Real(l) = &lens {
            l.check_forms_image()?;
        }
        let (choice, camera) = match self.model {
            LensModel::Auto => choose_model(self, &lens, shot)?,
            m => (ModelChoice::fixed(m), None),
        };
        let camera = match camera {
            Some(c) => c,
            None => build_model(self, &lens, choice.model, None)?,
        };
        let (lens_label, focal_length_mm, f_number) = match &lens {
            SpecLens::Ideal if self.is_pinhole() => ("pinhole".to_string(), self.focal_length_mm, f64::INFINITY),
            SpecLens::Ideal => ("thin".to_string(), self.focal_length_mm, self.f_number.unwrap_or(f64::INFINITY)),
            SpecLens::Real(l) => (l.name().to_string(), l.paraxial().efl_mm, l.paraxial().f_number),
        };
        let mut warnings = Vec::new();
        if let (SpecLens::Real(_), Some(asked)) = (&lens, self.f_number) {
            if f_number > asked * (1.0 + 1e-6) {
                warnings.push(format!(
                    "lens '{lens_label}' opens only to f/{f_number:.3}: rendering fully open (f/{asked} was asked)"
                ));
            }
        }
        Ok(BuiltCamera { camera, lens_label, focal_length_mm, f_number, choice, warnings })
    }
}
