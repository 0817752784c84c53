//! Light traced onto the film through an ideal lens (the [`thin`](super::thin) and
//! [`thick`](super::thick) models), for bokeh light paths ([`crate::bokeh`]).
//!
//! The ideal lens sits at a principal plane: a ray crossing it at height l (mm) leaves with its
//! slope (dx/dz, dy/dz) changed by −l/f, whichever way it travels (the mapping
//! [`thin_lens_direction`](super::thin_lens_direction) gives camera rays). The thick lens has two
//! planes, front (object side) and rear (image side), and a ray keeps its height from one to the
//! other.
//!
//! Unlike a real lens, this mapping does not conserve étendue exactly: it is a shear in slope
//! space, and the ray measure at a plane is dA·d²s/(1 + |s|²)². So a ray's density in the
//! object-side ray measure (the one light paths are drawn in) is its film-side density times
//! J = ((1 + |s_object|²)/(1 + |s_film|²))², and the camera's importance carries the same J.
//! Paraxially J = 1.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `radius_mm` | f64: aperture circumradius | mm | F/2N |
//! | `focal_mm` | f64: the lens's focal length as focused | mm | — |
//! | `film_z_mm` | f64: the sensor's pivot (lens frame) | mm | — |
//! | `rear_z_mm` | f64: image-side principal plane (lens frame; 0 for the thin lens) | mm | 0 |
//! | `front_z_m` | f64: object-side principal plane (camera space; 0 for the thin lens) | m | 0 |
//! | `natural_vignetting` | bool: the camera's weight includes cosθ_film cosθ_lens / d² | — | true |

use super::sensor::PreparedSensor;
use super::{geometric_factor, thin_lens_direction, FilmConnection};
use crate::optics::aperture::PreparedAperture;
use glam::{DVec2, DVec3};

/// An ideal lens as a camera model uses it (borrowed from the camera, see the module docs).
pub(super) struct IdealLens<'a> {
    pub sensor: &'a PreparedSensor,
    pub aperture: &'a PreparedAperture,
    pub radius_mm: f64,
    pub focal_mm: f64,
    pub film_z_mm: f64,
    pub rear_z_mm: f64,
    pub front_z_m: f64,
    pub natural_vignetting: bool,
    /// The camera's exposure normalisation.
    pub exposure: f64,
}

/// Étendue factor J = ((1 + |s_object|²)/(1 + |s_film|²))² of a ray with these slopes.
#[inline]
fn etendue_factor(s_object: DVec2, s_film: DVec2) -> f64 {
    let r = (1.0 + s_object.length_squared()) / (1.0 + s_film.length_squared());
    r * r
}

impl IdealLens<'_> {
    /// Density (per unit lens area, mm⁻²) of the camera's lens samples at lens point `l` (mm):
    /// uniform over the aperture's sampling domain, which holds every point the stop transmits,
    /// or a mask's transmission there ([`crate::optics::aperture::PreparedAperture::pdf_unit_at`]).
    fn lens_pdf_mm2(&self, l: DVec2) -> f64 {
        self.aperture.pdf_unit_at(l / self.radius_mm) / (self.radius_mm * self.radius_mm)
    }

    /// The camera strategy's density for sample (`film`, `lens_u`) in the object-side ray
    /// measure, per unit film density (see [`super::Camera::sample_density`]). None when the
    /// stop blocks the sample.
    pub(super) fn sample_density(&self, film: DVec2, lens_u: DVec2) -> Option<f64> {
        // 1. The camera's film and lens points, as its rays are made.
        let p = self.sensor.film_point(film, self.film_z_mm) - DVec3::new(0.0, 0.0, self.rear_z_mm);
        let (q, _, transmission) = self.aperture.sample_scaled(lens_u, self.radius_mm);
        let l = DVec3::new(q.x, q.y, 0.0);
        if transmission <= 0.0 {
            return None;
        }
        // 2. Film-side density pdf / g, times the étendue factor of its slopes.
        let g = geometric_factor(p, l, self.sensor.normal());
        let d = thin_lens_direction(p, l, self.focal_mm);
        let s_object = DVec2::new(d.x, d.y) / d.z.abs();
        let s_film = DVec2::new(l.x - p.x, l.y - p.y) / p.z.abs();
        (g > 0.0 && d.z != 0.0 && p.z != 0.0).then(|| self.lens_pdf_mm2(q) / g * etendue_factor(s_object, s_film))
    }

    /// The disc light paths aim at (see [`super::Camera::light_path_disc`]): the stop at the
    /// object-side principal plane, every point it transmits inside the opening's bounding
    /// circle.
    pub(super) fn light_path_disc(&self) -> (f64, f64) {
        (self.front_z_m, 1e-3 * self.radius_mm * self.aperture.aperture().bounding_radius_factor())
    }

    /// Light tracing: where the ray from `from_m` towards `to_m` (camera space, metres) lands on
    /// the film. None when it travels away from the lens, the stop blocks it or it misses the
    /// sensor plane.
    pub(super) fn connect(&self, from_m: DVec3, to_m: DVec3) -> Option<FilmConnection> {
        // 1. Where the ray crosses the object-side principal plane (it must travel towards +z,
        //    the film, and start in front of the plane).
        let d = (to_m - from_m).normalize();
        if !(d.z > 1e-9) || !from_m.is_finite() {
            return None;
        }
        let t = (self.front_z_m - from_m.z) / d.z;
        if !(t > 0.0) {
            return None;
        }
        let entry_m = from_m + d * t;
        let l = DVec3::new(entry_m.x * 1e3, entry_m.y * 1e3, 0.0);
        let transmission = self.aperture.transmission(l.x, l.y, self.radius_mm);
        if !(transmission > 0.0) {
            return None;
        }
        // 2. The lens bends the slope by −l/f; from the same height on the image side.
        let s_object = DVec2::new(d.x, d.y) / d.z;
        let s_film = s_object - DVec2::new(l.x, l.y) / self.focal_mm;
        let dir = DVec3::new(s_film.x, s_film.y, 1.0);
        // 3. Onto the sensor plane (relative to the image-side plane).
        let n = self.sensor.normal();
        let denom = dir.dot(n);
        if !(denom > 1e-12) {
            return None;
        }
        let pivot = DVec3::new(0.0, 0.0, self.film_z_mm - self.rear_z_mm);
        let s = (pivot - l).dot(n) / denom;
        if !(s > 0.0) {
            return None;
        }
        let x = l + dir * s;
        // 4. The camera's density for this ray and its importance, both with the étendue factor.
        let g = geometric_factor(x, l, n);
        if !(g > 0.0) {
            return None;
        }
        let j = etendue_factor(s_object, s_film);
        let vignetting = if self.natural_vignetting { 1.0 } else { 1.0 / g };
        Some(FilmConnection {
            film: self.sensor.film_coord(x + DVec3::new(0.0, 0.0, self.rear_z_mm), self.film_z_mm),
            importance: transmission * self.exposure * j * vignetting,
            camera_density: self.lens_pdf_mm2(DVec2::new(l.x, l.y)) / g * j,
            entry_m,
        })
    }
}
