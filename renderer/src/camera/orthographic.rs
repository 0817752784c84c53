//! The orthographic camera (Blender's Orthographic type, glTF's `orthographic` camera, USD's
//! `projection = "orthographic"`): parallel rays along the view axis from a window on the
//! plane of the camera origin; no perspective, no vignetting; depth of field as Cycles gives
//! an orthographic camera.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `sensor` | [`Sensor`] (untilted; the shift moves the window) | mm | 36 × 24 |
//! | `m_per_mm` | f64: scene metres per sensor millimetre (Blender's Orthographic Scale ÷ the fitted sensor side) | m/mm | — |
//! | `f_number` | optional f64: depth of field, an aperture of circumradius 1/(2N) m (Cycles' `aperturesize` for orthographic cameras) | — | None (all sharp) |
//! | `focus_distance_m` | optional f64 from the window plane (None = infinity) | m | None |
//! | `aperture` | [`Aperture`] shape (blades, rotation, ratio, mask) | — | circle |
//!
//! Image position (x, y) in [0,1]² maps to the window point ((x − ½)·w + shift_x,
//! (½ − y)·h + shift_y)·`m_per_mm` (metres, camera space). Without depth of field the ray leaves
//! it along −z with weight 1, so a uniform radiance-1 scene reads 1 everywhere. With it, as
//! Cycles' `camera_sample_orthographic`: the ray leaves from the window point moved by a point
//! `l` of the aperture and passes through the point `focus_distance_m` straight ahead of the
//! window point (direction ∝ (0, 0, −s) − l), its weight the aperture's transmission normalised
//! to a mean of 1. Clipping distances are measured from the window along the ray, as Blender's
//! clip start and end are for an orthographic camera.

use super::{centre_mean, check_positive, CameraRay, Sensor};
use crate::error::{Error, Result};
use crate::optics::aperture::{Aperture, PreparedAperture};
use glam::{DVec2, DVec3};

/// Depth of field of an orthographic camera.
#[derive(Debug, Clone)]
struct OrthoAperture {
    /// Aperture circumradius (metres): 1/(2N).
    radius_m: f64,
    /// Focus distance from the window plane (None = infinity).
    focus_distance_m: Option<f64>,
    shape: PreparedAperture,
    /// 1 / the mean raw weight: a uniform scene reads 1.
    exposure: f64,
}

/// An orthographic camera (see the module docs).
#[derive(Debug, Clone)]
pub struct OrthographicCamera {
    sensor: Sensor,
    m_per_mm: f64,
    dof: Option<OrthoAperture>,
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
        Ok(OrthographicCamera { sensor, m_per_mm, dof: None })
    }

    /// The same camera with depth of field: f-number `f_number` (aperture circumradius
    /// 1/(2N) m), focused `focus_distance_m` from the window plane (None = infinity), through
    /// `aperture`.
    pub fn with_depth_of_field(self, f_number: f64, focus_distance_m: Option<f64>, aperture: Aperture) -> Result<Self> {
        check_positive("f_number", f_number)?;
        if let Some(d) = focus_distance_m {
            check_positive("focus_distance_m", d)?;
        }
        let mut dof = OrthoAperture {
            radius_m: 0.5 / f_number,
            focus_distance_m,
            shape: PreparedAperture::new(aperture),
            exposure: 1.0,
        };
        dof.exposure = 1.0 / centre_mean(|u| dof.lens_point(u).map(|(_, w)| w));
        if !dof.exposure.is_finite() {
            return Err(Error::camera("aperture", "the aperture passes no light"));
        }
        Ok(OrthographicCamera { dof: Some(dof), ..self })
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

    /// The f-number, when the camera has depth of field.
    pub fn f_number(&self) -> Option<f64> {
        self.dof.as_ref().map(|d| 0.5 / d.radius_m)
    }

    pub(super) fn generate_ray(&self, film: DVec2, lens_u: DVec2) -> Option<CameraRay> {
        // 1. Upright image position → window point (the sensor's own convention, un-mirrored).
        let sx = (film.x - 0.5) * self.sensor.width_mm + self.sensor.shift_mm.x;
        let sy = (0.5 - film.y) * self.sensor.height_mm + self.sensor.shift_mm.y;
        let window = DVec3::new(sx * self.m_per_mm, sy * self.m_per_mm, 0.0);
        // 2. Parallel to the view axis, unit weight; or from an aperture point towards the
        //    focused point straight ahead of the window point.
        let Some(dof) = &self.dof else {
            return Some(CameraRay { origin: window, direction: DVec3::NEG_Z, weight: 1.0 });
        };
        let (l, w) = dof.lens_point(lens_u)?;
        let direction = match dof.focus_distance_m {
            Some(s) => (DVec3::new(0.0, 0.0, -s) - l).normalize(),
            None => DVec3::NEG_Z,
        };
        Some(CameraRay { origin: window + l, direction, weight: w * dof.exposure })
    }
}

impl OrthoAperture {
    /// A point of the aperture (metres, z = 0) for sample `u` and its raw weight
    /// (transmission / pdf); None where the stop blocks it.
    fn lens_point(&self, u: DVec2) -> Option<(DVec3, f64)> {
        let r = self.radius_m;
        let (q, pdf_unit, transmission) = self.shape.sample_scaled(u, r);
        let l = DVec3::new(q.x, q.y, 0.0);
        (transmission > 0.0).then(|| (l, transmission * r * r / pdf_unit))
    }
}
