//! The pinhole camera: no depth of field, no aberrations; the cheapest model.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `sensor` | [`Sensor`] | mm, degrees | 36 × 24 |
//! | `focal_length_mm` | f64: pinhole-to-film distance | mm | 50 |
//! | `natural_vignetting` | bool: include the cos⁴ falloff | — | true |

use super::sensor::PreparedSensor;
use super::{check_positive, geometric_factor, CameraRay, Sensor};
use crate::error::Result;
use glam::{DVec2, DVec3};

/// A pinhole camera.
#[derive(Debug, Clone)]
pub struct PinholeCamera {
    sensor: PreparedSensor,
    focal_length_mm: f64,
    natural_vignetting: bool,
}

impl PinholeCamera {
    /// A pinhole camera `focal_length_mm` in front of `sensor`, with natural vignetting.
    pub fn new(sensor: Sensor, focal_length_mm: f64) -> Result<Self> {
        sensor.validate()?;
        check_positive("focal_length_mm", focal_length_mm)?;
        Ok(PinholeCamera { sensor: PreparedSensor::new(sensor), focal_length_mm, natural_vignetting: true })
    }

    /// The same camera with or without the cos⁴ falloff.
    pub fn with_natural_vignetting(self, natural_vignetting: bool) -> Self {
        PinholeCamera { natural_vignetting, ..self }
    }

    /// Sensor.
    pub fn sensor(&self) -> &Sensor {
        self.sensor.sensor()
    }

    /// Pinhole-to-film distance.
    pub fn focal_length_mm(&self) -> f64 {
        self.focal_length_mm
    }

    /// Whether the cos⁴ falloff is applied.
    pub fn natural_vignetting(&self) -> bool {
        self.natural_vignetting
    }

    pub(super) fn generate_ray(&self, film: DVec2) -> Option<CameraRay> {
        let p = self.sensor.film_point(film, self.focal_length_mm);
        let dir = (-p).normalize();
        let weight = if self.natural_vignetting {
            // cos θ_film · cos θ / d² relative to the centre (f²): cos⁴ for an untilted sensor
            geometric_factor(p, DVec3::ZERO, self.sensor.normal()) * self.focal_length_mm * self.focal_length_mm
        } else {
            1.0
        };
        Some(CameraRay { origin: DVec3::ZERO, direction: dir, weight })
    }
}
