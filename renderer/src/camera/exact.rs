//! The exact model: every camera ray is traced through every surface of a real [`Lens`]
//! (f64), sampling the exit pupil's bounds (after pbrt-v4). The reference all cheaper models
//! are measured against.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `sensor` | [`Sensor`] | mm, degrees | 36 × 24 |
//! | `lens` | [`Lens`], already stopped down and with its stop shape | — | — |
//! | `focus_distance_m` | optional f64 from the entrance pupil (None = infinity) | m | None |

use super::{centre_mean, check_positive, geometric_factor, CameraRay, Sensor};
use crate::error::{Error, Result};
use crate::optics::lens::{Lens, Ray, TraceDirection};
use crate::optics::pupil::ExitPupilBounds;
use glam::{DVec2, DVec3};

/// A real lens traced exactly. Immutable: the film position, exit-pupil bounds and exposure are
/// computed by [`ExactCamera::new`].
#[derive(Debug, Clone)]
pub struct ExactCamera {
    sensor: Sensor,
    lens: Lens,
    focus_distance_m: Option<f64>,
    film_z_mm: f64,
    pupil: ExitPupilBounds,
    exposure: f64,
}

impl ExactCamera {
    /// A camera tracing `lens` (already stopped down), focused at `focus_distance_m` from the
    /// entrance pupil.
    pub fn new(sensor: Sensor, lens: Lens, focus_distance_m: Option<f64>) -> Result<Self> {
        let film_z_mm = Self::film_position_mm(&sensor, &lens, focus_distance_m)?;
        let (r_max, dz) = sensor.extent();
        let pupil = ExitPupilBounds::compute(&lens, film_z_mm, dz, r_max * 1.001);
        let mut cam = ExactCamera { sensor, lens, focus_distance_m, film_z_mm, pupil, exposure: 1.0 };
        let centre = cam.sensor.axis_film_coord();
        let mean = centre_mean(|u| cam.raw_ray(centre, u, cam.lens.primary_wavelength_nm()).map(|r| r.weight));
        if !(mean > 0.0) {
            return Err(Error::camera(
                "lens",
                format!("no light reaches the centre of the sensor through '{}'", cam.lens.name()),
            ));
        }
        cam.exposure = 1.0 / mean;
        Ok(cam)
    }

    /// The film pivot's z for `lens` focused at `focus_distance_m`, with the checks of
    /// [`ExactCamera::new`] that need no tracing: the focus is reachable, and the image and the
    /// tilted sensor clear the rear element.
    pub(super) fn film_position_mm(sensor: &Sensor, lens: &Lens, focus_distance_m: Option<f64>) -> Result<f64> {
        sensor.validate()?;
        if let Some(d) = focus_distance_m {
            check_positive("focus_distance_m", d)?;
        }
        let image_distance = lens.focus_image_distance_mm(focus_distance_m.map(|m| m * 1e3))?;
        let film_z_mm = lens.last_vertex_z_mm() + image_distance;
        let (_, dz) = sensor.extent();
        if film_z_mm - dz <= lens.last_vertex_z_mm() {
            // without tilt the image itself falls inside the lens: say that, not "tilt"
            if dz < 1e-9 {
                return Err(Error::camera(
                    "lens",
                    format!(
                        "'{}' forms its image {:.3} mm inside its rear element (image distance {:.3} mm): no sensor fits there",
                        lens.name(),
                        lens.last_vertex_z_mm() - film_z_mm,
                        image_distance
                    ),
                ));
            }
            return Err(Error::camera("tilt", "the tilted sensor would cut into the rear element"));
        }
        Ok(film_z_mm)
    }

    /// Sensor.
    pub fn sensor(&self) -> &Sensor {
        &self.sensor
    }

    /// The lens (stopped down).
    pub fn lens(&self) -> &Lens {
        &self.lens
    }

    /// Focus distance (None = infinity).
    pub fn focus_distance_m(&self) -> Option<f64> {
        self.focus_distance_m
    }

    /// Film pivot z (lens frame).
    pub fn film_z_mm(&self) -> f64 {
        self.film_z_mm
    }

    /// Exit-pupil bounds used for sampling.
    pub fn pupil(&self) -> &ExitPupilBounds {
        &self.pupil
    }

    /// Exposure normalisation (the centre of a uniform radiance-1 scene reads 1).
    pub(super) fn exposure(&self) -> f64 {
        self.exposure
    }

    fn raw_ray(&self, film: DVec2, lens_u: DVec2, wavelength_nm: f64) -> Option<CameraRay> {
        self.raw_ray_with(film, lens_u, |ray| {
            self.lens.trace(ray, wavelength_nm, TraceDirection::FilmToScene).map(|t| (t.ray, t.transmission))
        })
    }

    /// The camera ray for a film and lens sample, with `through_lens` mapping the ray from the
    /// film to the ray leaving the front and its stop transmission (exact trace or a table).
    #[inline]
    pub(super) fn raw_ray_with(
        &self,
        film: DVec2,
        lens_u: DVec2,
        through_lens: impl Fn(&Ray) -> Option<(Ray, f64)>,
    ) -> Option<CameraRay> {
        // 1. Film point and a rear-plane point inside the exit-pupil bounds.
        let p = self.sensor.film_point(film, self.film_z_mm);
        let s = self.pupil.sample(DVec2::new(p.x, p.y), lens_u)?;
        // 2. Through the lens towards the scene.
        let ray = Ray::new(p, s.point - p);
        let (out, transmission) = through_lens(&ray)?;
        // 3. Irradiance weight cosθ_film cosθ_rear / d² / pdf and stop transmission.
        let weight = geometric_factor(p, s.point, self.sensor.normal()) / s.pdf_area * transmission;
        let z_ep = self.lens.paraxial().entrance_pupil_z_mm;
        let o = out.origin;
        Some(CameraRay { origin: DVec3::new(o.x, o.y, o.z - z_ep) * 1e-3, direction: out.direction, weight })
    }

    pub(super) fn generate_ray(&self, film: DVec2, lens_u: DVec2, wavelength_nm: f64) -> Option<CameraRay> {
        self.raw_ray(film, lens_u, wavelength_nm).map(|r| CameraRay { weight: r.weight * self.exposure, ..r })
    }
}
