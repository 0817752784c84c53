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
use super::{Camera, ExactCamera, LrtfCamera};
use crate::error::Result;
use crate::optics::lrtf::LrtfTable;

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

    /// The checks of [`CameraSpec::build`] that cost no tracing, for a front end to run before it
    /// loads a scene: the numbers, the lens (it loads and forms an image), the model fits the
    /// lens, the focus is reachable and the sensor clears the rear element, and a baked table
    /// (`lrtf_file`) belongs to the lens and covers the sensor. Left to the build: the exact
    /// camera's exit-pupil bounds and whether light reaches the sensor's centre, LRTF bakes and
    /// `auto`'s comparison.
    pub fn check(&self) -> Result<()> {
        self.validate()?;
        let lens = self.load_lens()?;
        if self.orthographic_m_per_mm.is_some() {
            // no lens to trace: the build is the check (it refuses a real lens)
            return build_model(self, &lens, self.model, None, false).map(|_| ());
        }
        let SpecLens::Real(l) = &lens else {
            // ideal lenses build at no cost
            let model = if self.model == LensModel::Auto { LensModel::Thin } else { self.model };
            return build_model(self, &lens, model, None, false).map(|_| ());
        };
        l.check_forms_image()?;
        match self.model {
            LensModel::Auto | LensModel::Exact => {
                ExactCamera::film_position_mm(&self.sensor, l, self.focus_distance_m)?;
            }
            LensModel::Lrtf { .. } => {
                let film_z = ExactCamera::film_position_mm(&self.sensor, l, self.focus_distance_m)?;
                if let Some(path) = &self.lrtf_file {
                    LrtfCamera::check_coverage(&LrtfTable::load(path, l)?, &self.sensor, film_z)?;
                }
            }
            m @ (LensModel::Thick | LensModel::Thin | LensModel::Pinhole | LensModel::Orthographic) => {
                build_model(self, &lens, m, None, false)?;
            }
        }
        Ok(())
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
            None => build_model(self, &lens, choice.model, None, shot.spectral)?,
        };
        let (lens_label, focal_length_mm, f_number) = match &lens {
            SpecLens::Ideal if self.orthographic_m_per_mm.is_some() => {
                ("orthographic".to_string(), self.focal_length_mm, self.f_number.unwrap_or(f64::INFINITY))
            }
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
        // A stop too small for the pupil sampling to follow renders nearly black: say so.
        let exact = match &camera {
            Camera::Exact(c) => Some(c),
            Camera::Lrtf(c) => Some(c.exact()),
            _ => None,
        };
        if let Some(c) = exact {
            // Most of the frame off the lens's image (a large shift, a sensor far beyond the
            // image circle): black, which is right, but say why.
            let r_sensor = c.sensor().extent().0;
            let r = crate::optics::pupil::image_circle_radius_mm(c.lens(), c.film_z_mm(), r_sensor);
            let outside = c.share_outside_image();
            if r < 0.5 * r_sensor {
                warnings.push(format!(
                    "'{lens_label}' covers a circle of radius {r:.2} mm, {:.0} % of the sensor's half-diagonal ({r_sensor:.1} mm): the rest of the frame is black (a smaller sensor, or less shift, frames it)",
                    100.0 * r / r_sensor
                ));
            } else if outside >= FRAME_OUTSIDE_WARNING {
                warnings.push(format!(
                    "{:.0} % of the frame lies outside the image of lens '{lens_label}' (no light passes the lens there, so those pixels are black): check the sensor shift and size",
                    outside * 100.0
                ));
            }
            let acceptance = c.pupil_acceptance().unwrap_or(1.0);
            if acceptance < LOW_PUPIL_ACCEPTANCE {
                warnings.push(format!(
                    "lens '{lens_label}' at f/{f_number:.4}: only {:.2} % of the pupil samples pass the lens (its exit pupil is {:.3} µm across, a speck the pupil sampling cannot follow); the image is unbiased but will be very noisy: open the aperture",
                    acceptance * 100.0,
                    c.lens().paraxial().exit_pupil_diameter_mm * 1e3
                ));
            }
        }
        Ok(BuiltCamera { camera, lens_label, focal_length_mm, f_number, choice, warnings })
    }
}

/// Share of passing pupil samples ([`ExactCamera::pupil_acceptance`]) below which a build warns.
const LOW_PUPIL_ACCEPTANCE: f64 = 0.05;

/// Share of the frame outside the lens's image ([`ExactCamera::share_outside_image`]) from which
/// a build warns (a circular fisheye's frame corners stay below it).
const FRAME_OUTSIDE_WARNING: f64 = 0.5;
