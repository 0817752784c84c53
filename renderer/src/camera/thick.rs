//! The thick-lens approximation of a real lens: its paraxial focal length and principal planes,
//! with the camera origin at the real lens's entrance pupil (so switching models keeps the
//! framing).
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `sensor` | [`Sensor`] | mm, degrees | 36 × 24 |
//! | `lens` | [`Lens`]: focal length, principal planes, entrance pupil | — | — |
//! | `f_number` | optional f64 | — | the lens's current |
//! | `focus_distance_m` | optional f64 from the entrance pupil (None = infinity) | m | None |
//! | `aperture` | [`Aperture`] shape | — | the lens's |

use super::ideal::IdealLens;
use super::sensor::PreparedSensor;
use super::{centre_mean, check_positive, geometric_factor, thin_lens_direction, thin_lens_image_distance};
use super::{CameraRay, FilmConnection, Sensor};
use crate::error::Result;
use crate::optics::aperture::{Aperture, PreparedAperture};
use crate::optics::lens::Lens;
use glam::{DVec2, DVec3};

/// The thick-lens approximation of a real lens (see the module docs). Immutable: every derived
/// value is computed by [`ThickCamera::new`].
#[derive(Debug, Clone)]
pub struct ThickCamera {
    sensor: PreparedSensor,
    focal_length_mm: f64,
    front_principal_z_mm: f64,
    rear_principal_z_mm: f64,
    entrance_pupil_z_mm: f64,
    f_number: f64,
    focus_distance_m: Option<f64>,
    aperture: PreparedAperture,
    film_z_mm: f64,
    exposure: f64,
}

impl ThickCamera {
    /// The thick-lens approximation of `lens` (its paraxial focal length and principal planes),
    /// at `f_number` (default: the lens's current), focused at `focus_distance_m` from the
    /// real lens's entrance pupil.
    pub fn new(
        sensor: Sensor,
        lens: &Lens,
        f_number: Option<f64>,
        focus_distance_m: Option<f64>,
        aperture: Aperture,
    ) -> Result<Self> {
        sensor.validate()?;
        let p = lens.paraxial();
        let f_number = f_number.unwrap_or(p.f_number);
        check_positive("f_number", f_number)?;
        let f = p.efl_mm;
        let u = match focus_distance_m {
            None => None,
            Some(d) => {
                check_positive("focus_distance_m", d)?;
                Some(p.front_principal_z_mm - (p.entrance_pupil_z_mm - d * 1e3))
            }
        };
        let v = thin_lens_image_distance(f, u)?;
        let mut cam = ThickCamera {
            sensor: PreparedSensor::new(sensor),
            focal_length_mm: f,
            front_principal_z_mm: p.front_principal_z_mm,
            rear_principal_z_mm: p.rear_principal_z_mm,
            entrance_pupil_z_mm: p.entrance_pupil_z_mm,
            f_number,
            focus_distance_m,
            aperture: PreparedAperture::new(aperture),
            film_z_mm: p.rear_principal_z_mm + v,
            exposure: 1.0,
        };
        let centre = cam.sensor.sensor().axis_film_coord();
        cam.exposure = 1.0 / centre_mean(|u| cam.raw_ray(centre, u).map(|r| r.weight));
        Ok(cam)
    }

    /// Sensor.
    pub fn sensor(&self) -> &Sensor {
        self.sensor.sensor()
    }

    /// Focal length.
    pub fn focal_length_mm(&self) -> f64 {
        self.focal_length_mm
    }

    /// Front principal plane (lens frame).
    pub fn front_principal_z_mm(&self) -> f64 {
        self.front_principal_z_mm
    }

    /// Rear principal plane (lens frame).
    pub fn rear_principal_z_mm(&self) -> f64 {
        self.rear_principal_z_mm
    }

    /// Entrance pupil z of the real lens (the camera origin).
    pub fn entrance_pupil_z_mm(&self) -> f64 {
        self.entrance_pupil_z_mm
    }

    /// f-number.
    pub fn f_number(&self) -> f64 {
        self.f_number
    }

    /// Focus distance (None = infinity).
    pub fn focus_distance_m(&self) -> Option<f64> {
        self.focus_distance_m
    }

    /// Aperture shape.
    pub fn aperture(&self) -> &Aperture {
        self.aperture.aperture()
    }

    /// Film pivot z (lens frame).
    pub fn film_z_mm(&self) -> f64 {
        self.film_z_mm
    }

    fn raw_ray(&self, film: DVec2, lens_u: DVec2) -> Option<CameraRay> {
        // 1. Thin lens at the rear principal plane.
        let p = self.sensor.film_point(film, self.film_z_mm) - DVec3::new(0.0, 0.0, self.rear_principal_z_mm);
        let r = self.aperture_radius_mm();
        let (q, pdf_unit, transmission) = self.aperture.sample_scaled(lens_u, r);
        let l = DVec3::new(q.x, q.y, 0.0);
        if transmission <= 0.0 {
            return None;
        }
        let dir = thin_lens_direction(p, l, self.focal_length_mm);
        let weight = geometric_factor(p, l, self.sensor.normal()) * r * r / pdf_unit * transmission;
        // 2. Leave from the same height on the front principal plane.
        let origin = DVec3::new(l.x, l.y, self.front_principal_z_mm - self.entrance_pupil_z_mm) * 1e-3;
        Some(CameraRay { origin, direction: dir, weight })
    }

    pub(super) fn generate_ray(&self, film: DVec2, lens_u: DVec2) -> Option<CameraRay> {
        self.raw_ray(film, lens_u).map(|r| CameraRay { weight: r.weight * self.exposure, ..r })
    }

    /// Aperture circumradius at the principal planes: F / 2N.
    pub fn aperture_radius_mm(&self) -> f64 {
        0.5 * self.focal_length_mm / self.f_number
    }

    /// The lens as light tracing sees it (its two principal planes).
    fn ideal(&self) -> IdealLens<'_> {
        IdealLens {
            sensor: &self.sensor,
            aperture: &self.aperture,
            radius_mm: self.aperture_radius_mm(),
            focal_mm: self.focal_length_mm,
            film_z_mm: self.film_z_mm,
            rear_z_mm: self.rear_principal_z_mm,
            front_z_m: (self.front_principal_z_mm - self.entrance_pupil_z_mm) * 1e-3,
            natural_vignetting: true,
            exposure: self.exposure,
        }
    }

    /// The camera's density for a sample in the ray measure (see [`super::Camera::sample_density`]).
    pub(super) fn sample_density(&self, film: DVec2, lens_u: DVec2) -> Option<f64> {
        self.ideal().sample_density(film, lens_u)
    }

    /// The disc light paths aim at (see [`super::Camera::light_path_disc`]).
    pub(super) fn light_path_disc(&self) -> (f64, f64) {
        self.ideal().light_path_disc()
    }

    /// Light tracing onto the film (see [`super::Camera::connect`]).
    pub(super) fn connect(&self, from_m: DVec3, to_m: DVec3) -> Option<FilmConnection> {
        self.ideal().connect(from_m, to_m)
    }
}
