//! The ideal thin lens with Blender's (Cycles') conventions: the field of view is that of the
//! focal length F at any focus distance s (the film stays at F behind the lens and the lens's
//! power changes to focus: its focal length is F·s/(F + s)), and the aperture's circumradius is
//! F/(2N). Real lenses, traced or as thick lenses, breathe physically instead.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `sensor` | [`Sensor`] | mm, degrees | 36 × 24 |
//! | `focal_length_mm` | f64: F, sets the field of view | mm | 50 |
//! | `f_number` | f64: aperture circumradius = F / 2N | — | 2.8 |
//! | `focus_distance_m` | optional f64 (None = infinity) | m | None |
//! | `aperture` | [`Aperture`] shape | — | circle |
//! | `natural_vignetting` | bool: include the cos⁴ falloff | — | true |
//!
//! Every derived value (film distance, the focused lens's focal length, the exposure
//! normalisation with and without natural vignetting) is computed by [`ThinCamera::new`]; the
//! camera is immutable afterwards ([`ThinCamera::with_natural_vignetting`] picks the other
//! precomputed normalisation).

use super::ideal::IdealLens;
use super::sensor::PreparedSensor;
use super::{centre_mean, check_positive, geometric_factor, thin_lens_direction, CameraRay, FilmConnection, Sensor};
use crate::error::Result;
use crate::optics::aperture::{Aperture, PreparedAperture};
use glam::{DVec2, DVec3};

/// An ideal thin lens (see the module docs).
#[derive(Debug, Clone)]
pub struct ThinCamera {
    sensor: PreparedSensor,
    focal_length_mm: f64,
    f_number: f64,
    focus_distance_m: Option<f64>,
    aperture: PreparedAperture,
    natural_vignetting: bool,
    film_z_mm: f64,
    /// Focal length of the lens focused at the focus distance: F·s/(F + s).
    lens_focal_mm: f64,
    /// Exposure normalisation with and without natural vignetting.
    exposure: [f64; 2],
}

impl ThinCamera {
    /// A thin-lens camera focused at `focus_distance_m` (None = infinity), with natural
    /// vignetting.
    pub fn new(
        sensor: Sensor,
        focal_length_mm: f64,
        f_number: f64,
        focus_distance_m: Option<f64>,
        aperture: Aperture,
    ) -> Result<Self> {
        sensor.validate()?;
        check_positive("focal_length_mm", focal_length_mm)?;
        check_positive("f_number", f_number)?;
        if let Some(d) = focus_distance_m {
            check_positive("focus_distance_m", d)?;
        }
        // Film at F; the lens focuses at s by its power: 1/f = 1/F + 1/s.
        let lens_focal_mm = match focus_distance_m {
            Some(s) => focal_length_mm * s * 1e3 / (focal_length_mm + s * 1e3),
            None => focal_length_mm,
        };
        let mut cam = ThinCamera {
            sensor: PreparedSensor::new(sensor),
            focal_length_mm,
            f_number,
            focus_distance_m,
            aperture: PreparedAperture::new(aperture),
            natural_vignetting: true,
            film_z_mm: focal_length_mm,
            lens_focal_mm,
            exposure: [1.0; 2],
        };
        let centre = cam.sensor.sensor().axis_film_coord();
        let natural = 1.0 / centre_mean(|u| cam.raw_ray(centre, u).map(|r| r.weight));
        cam.natural_vignetting = false;
        let flat = 1.0 / centre_mean(|u| cam.raw_ray(centre, u).map(|r| r.weight));
        cam.natural_vignetting = true;
        cam.exposure = [natural, flat];
        Ok(cam)
    }

    /// The same camera with or without the cos⁴ falloff (both normalisations are precomputed).
    pub fn with_natural_vignetting(self, natural_vignetting: bool) -> Self {
        ThinCamera { natural_vignetting, ..self }
    }

    /// Sensor.
    pub fn sensor(&self) -> &Sensor {
        self.sensor.sensor()
    }

    /// Focal length F (sets the field of view).
    pub fn focal_length_mm(&self) -> f64 {
        self.focal_length_mm
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

    /// Whether the cos⁴ falloff is applied.
    pub fn natural_vignetting(&self) -> bool {
        self.natural_vignetting
    }

    /// Aperture circumradius.
    pub fn aperture_radius_mm(&self) -> f64 {
        0.5 * self.focal_length_mm / self.f_number
    }

    /// Lens-to-film distance (= F).
    pub fn film_distance_mm(&self) -> f64 {
        self.film_z_mm
    }

    /// Focal length of the lens as focused: F·s/(F + s).
    pub fn lens_focal_length_mm(&self) -> f64 {
        self.lens_focal_mm
    }

    fn raw_ray(&self, film: DVec2, lens_u: DVec2) -> Option<CameraRay> {
        let p = self.sensor.film_point(film, self.film_z_mm);
        let r = self.aperture_radius_mm();
        let (q, pdf_unit, transmission) = self.aperture.sample_scaled(lens_u, r);
        let l = DVec3::new(q.x, q.y, 0.0);
        if transmission <= 0.0 {
            return None;
        }
        let pdf = pdf_unit / (r * r);
        let dir = thin_lens_direction(p, l, self.lens_focal_mm);
        let weight = if self.natural_vignetting {
            geometric_factor(p, l, self.sensor.normal()) / pdf * transmission
        } else {
            transmission / pdf
        };
        Some(CameraRay { origin: l * 1e-3, direction: dir, weight })
    }

    pub(super) fn generate_ray(&self, film: DVec2, lens_u: DVec2) -> Option<CameraRay> {
        let exposure = self.exposure[if self.natural_vignetting { 0 } else { 1 }];
        self.raw_ray(film, lens_u).map(|r| CameraRay { weight: r.weight * exposure, ..r })
    }

    /// The lens as light tracing sees it (one plane at the camera origin).
    fn ideal(&self) -> IdealLens<'_> {
        IdealLens {
            sensor: &self.sensor,
            aperture: &self.aperture,
            radius_mm: self.aperture_radius_mm(),
            focal_mm: self.lens_focal_mm,
            film_z_mm: self.film_z_mm,
            rear_z_mm: 0.0,
            front_z_m: 0.0,
            natural_vignetting: self.natural_vignetting,
            exposure: self.exposure[if self.natural_vignetting { 0 } else { 1 }],
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
