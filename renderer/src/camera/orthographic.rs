//! The orthographic camera (Blender's Orthographic type, glTF's `orthographic` camera, USD's
//! `projection = "orthographic"`): parallel rays along the view axis from a window on the
//! plane of the camera origin; no perspective, no depth of field, no vignetting.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `sensor` | [`Sensor`] (untilted; the shift moves the window) | mm | 36 × 24 |
//! | `m_per_mm` | f64: scene metres per sensor millimetre (Blender's Orthographic Scale ÷ the fitted sensor side) | m/mm | — |
//!
//! Image position (x, y) in [0,1]² maps to the window point ((x − ½)·w + shift_x,
//! (½ − y)·h + shift_y)·`m_per_mm` (metres, camera space) and the ray leaves it along −z with
//! weight 1, so a uniform radiance-1 scene reads 1 everywhere. Clipping distances are measured
//! from the window along the ray, as Blender's clip start and end are for an orthographic camera.

use super::{check_positive, CameraRay, Sensor};
use crate::error::{Error, Result};
use glam::{DVec2, DVec3};

/// An orthographic camera (see the module docs).
#[derive(Debug, Clone)]
pub struct OrthographicCamera {
    sensor: Sensor,
    m_per_mm: f64,
}

impl OrthographicCamera {
    /// An orthographic camera whose `sensor` maps to a window `m_per_mm` metres per millimetre.
    /// A tilted sensor is refused: tilting the window of parallel rays changes nothing a
    /// Scheimpflug tilt is for.
    pub fn new(sensor: Sensor, m_per_mm: f64) -> Result<Self> {
        sensor.validate()?;
        check_positive("orthographic_m_per_mm", m_per_mm)?;
        if sensor.tilt_x_deg != 0.0 || sensor.tilt_y_deg != 0.0 {
            return Err(Error::camera(
                "tilt_deg",
                "an orthographic camera has no lens to tilt the sensor against; set the tilt to 0",
            ));
        }
        Ok(OrthographicCamera { sensor, m_per_mm })
    }

    /// Sensor.
    pub fn sensor(&self) -> &Sensor {
        &self.sensor
    }

    /// Scene metres per sensor millimetre.
    pub fn m_per_mm(&self) -> f64 {
        self.m_per_mm
    }

    /// The window's width and height (metres).
    pub fn window_m(&self) -> (f64, f64) {
        (self.sensor.width_mm * self.m_per_mm, self.sensor.height_mm * self.m_per_mm)
    }

    pub(super) fn generate_ray(&self, film: DVec2) -> Option<CameraRay> {
        // 1. Upright image position → window point (the sensor's own convention, un-mirrored).
        let sx = (film.x - 0.5) * self.sensor.width_mm + self.sensor.shift_mm.x;
        let sy = (0.5 - film.y) * self.sensor.height_mm + self.sensor.shift_mm.y;
        // 2. Parallel to the view axis, unit weight.
        let origin = DVec3::new(sx * self.m_per_mm, sy * self.m_per_mm, 0.0);
        Some(CameraRay { origin, direction: DVec3::NEG_Z, weight: 1.0 })
    }
}
