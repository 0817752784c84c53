//! The exact model: every camera ray is traced through every surface of a real [`Lens`]
//! (f64), sampling the exit pupil's bounds (after pbrt-v4). The reference all cheaper models
//! are measured against.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `sensor` | [`Sensor`] | mm, degrees | 36 × 24 |
//! | `lens` | [`Lens`], already stopped down and with its stop shape | — | — |
//! | `focus_distance_m` | optional f64 from the entrance pupil (None = infinity) | m | None |

use super::sensor::PreparedSensor;
use super::{centre_mean, check_positive, geometric_factor, CameraRay, FilmConnection, Sensor};
use crate::error::{Error, Result};
use crate::optics::lens::{Lens, Ray, TraceDirection};
use crate::optics::pupil::ExitPupilBounds;
use glam::{DVec2, DVec3};

/// A real lens traced exactly. Immutable: the film position, exit-pupil bounds and exposure are
/// computed by [`ExactCamera::new`].
#[derive(Debug, Clone)]
pub struct ExactCamera {
    sensor: PreparedSensor,
    lens: Lens,
    focus_distance_m: Option<f64>,
    film_z_mm: f64,
    pupil: ExitPupilBounds,
    exposure: f64,
    /// A plane (lens frame z) wholly in front of the first surface: light paths enter there.
    front_plane_z_mm: f64,
}

impl ExactCamera {
    /// A camera tracing `lens` (already stopped down), focused at `focus_distance_m` from the
    /// entrance pupil.
    pub fn new(sensor: Sensor, lens: Lens, focus_distance_m: Option<f64>) -> Result<Self> {
        Self::with_bounds_for(sensor, lens, focus_distance_m, false)
    }

    /// [`ExactCamera::new`]; with `spectral`, the exit-pupil bounds also hold every passing ray
    /// at the ends of the spectral range (a spectral render of a dispersive lens samples them
    /// at every wavelength), else at the primary wavelength only (tighter).
    pub fn with_bounds_for(sensor: Sensor, lens: Lens, focus_distance_m: Option<f64>, spectral: bool) -> Result<Self> {
        let film_z_mm = Self::film_position_mm(&sensor, &lens, focus_distance_m)?;
        let (r_max, dz) = sensor.extent();
        // The sensor plane through (0, 0, film_z) with normal n: z = film_z − (n.x·x + n.y·y)/n.z.
        let n = sensor.normal();
        let slope = DVec2::new(-n.x / n.z, -n.y / n.z);
        let pupil = ExitPupilBounds::compute_on_plane(&lens, film_z_mm, dz, slope, r_max * 1.001, spectral);
        let front_plane_z_mm = front_plane_z_mm(&lens);
        let mut cam = ExactCamera {
            sensor: PreparedSensor::new(sensor),
            lens,
            focus_distance_m,
            film_z_mm,
            pupil,
            exposure: 1.0,
            front_plane_z_mm,
        };
        let centre = cam.sensor.sensor().axis_film_coord();
        // The exposure integrates a fixed grid of lens samples over the traced bounds: the
        // defensive disc's share of a fixed grid would fall on two curves across the disc
        // (0.16 % too bright on the demo's lens) and adds nothing inside the bounds.
        let disc = cam.pupil.defensive_radius_mm.take();
        let mean = centre_mean(|u| cam.raw_ray(centre, u, cam.lens.primary_wavelength_nm()).map(|r| r.weight));
        cam.pupil.defensive_radius_mm = disc;
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

    /// The film points of the build's checks: a 17 × 17 lattice over the frame (lens frame).
    fn check_lattice(&self) -> impl Iterator<Item = DVec3> + '_ {
        const LATTICE: usize = 16;
        (0..=LATTICE).flat_map(move |i| {
            (0..=LATTICE).map(move |j| {
                let uv = DVec2::new(i as f64, j as f64) / LATTICE as f64;
                self.sensor.film_point(uv, self.film_z_mm)
            })
        })
    }

    /// The share of pupil samples drawn in the exit-pupil bounds that pass the lens, over
    /// [`ExactCamera::check_lattice`]'s film points (those the bounds cover; 4 × 4 stratified
    /// samples each; None when they cover none). Near 1 for tight bounds; tiny where the stop is
    /// so small that its region is a speck the bounds cannot follow (the image is still
    /// unbiased, but nearly all its samples are lost).
    pub fn pupil_acceptance(&self) -> Option<f64> {
        let wl = self.lens.primary_wavelength_nm();
        let (mut drawn, mut passed) = (0usize, 0usize);
        for p in self.check_lattice() {
            // 1. Each stratified sample of the film point's bounds.
            for k in 0..16 {
                let u = DVec2::new((k % 4) as f64 + 0.5, (k / 4) as f64 + 0.5) / 4.0;
                let Some(s) = self.pupil.sample_bounds(DVec2::new(p.x, p.y), u) else { continue };
                // 2. Whether its ray passes.
                drawn += 1;
                let ray = Ray::new(p, s.point - p);
                passed += usize::from(self.lens.trace(&ray, wl, TraceDirection::FilmToScene).is_some());
            }
        }
        (drawn > 0).then(|| passed as f64 / drawn as f64)
    }

    /// The share of the frame ([`ExactCamera::check_lattice`]'s film points) where no ray passes
    /// the lens: the exit-pupil bounds are empty there (beyond the image circle, or vignetted
    /// whole).
    pub fn share_outside_image(&self) -> f64 {
        let (mut points, mut outside) = (0usize, 0usize);
        for p in self.check_lattice() {
            points += 1;
            outside += usize::from(!(self.pupil.domain_area_at(DVec2::new(p.x, p.y)) > 0.0));
        }
        outside as f64 / points as f64
    }

    /// Sensor.
    pub fn sensor(&self) -> &Sensor {
        self.sensor.sensor()
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

    /// This camera drawing its pupil samples in the traced bounds only, without the defensive
    /// disc (same exposure): for lens samples shared by every pixel (multi-view), where one
    /// sample falling in the disc would darken a whole view instead of one pixel's sample.
    pub fn without_defensive_disc(&self) -> ExactCamera {
        let mut cam = self.clone();
        cam.pupil.defensive_radius_mm = None;
        cam
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
        let (ray, geometric) = self.film_ray(film, lens_u)?;
        // 2. Through the lens towards the scene.
        let (out, transmission) = through_lens(&ray)?;
        // 3. Irradiance weight and stop transmission, in camera space.
        Some(self.leaving_ray(out, geometric, transmission))
    }

    /// Step 1 of a camera ray: the ray from the film point towards a rear-plane point inside
    /// the exit-pupil bounds, and its geometric weight cosθ_film cosθ_rear / d² / pdf. None
    /// when the pupil sample is not drawn.
    #[inline]
    pub(super) fn film_ray(&self, film: DVec2, lens_u: DVec2) -> Option<(Ray, f64)> {
        let p = self.sensor.film_point(film, self.film_z_mm);
        let s = self.pupil.sample(DVec2::new(p.x, p.y), lens_u)?;
        Some((Ray::new(p, s.point - p), geometric_factor(p, s.point, self.sensor.normal()) / s.pdf_area))
    }

    /// Step 3 of a camera ray: the ray `out` that left the lens (lens frame, mm) in camera
    /// space (m, origin at the entrance pupil), weighted by `geometric` × `transmission`.
    #[inline]
    pub(super) fn leaving_ray(&self, out: Ray, geometric: f64, transmission: f64) -> CameraRay {
        let z_ep = self.lens.paraxial().entrance_pupil_z_mm;
        let o = out.origin;
        CameraRay {
            origin: DVec3::new(o.x, o.y, o.z - z_ep) * 1e-3,
            direction: out.direction,
            weight: geometric * transmission,
        }
    }

    /// The camera strategy's density for the sample (`film`, `lens_u`) in the ray (étendue)
    /// measure, per unit film density: pdf of the rear-plane point / (cosθ_film cosθ_rear / d²),
    /// for weighting camera paths against light paths. None when the sample is not drawn.
    pub(super) fn sample_density(&self, film: DVec2, lens_u: DVec2) -> Option<f64> {
        let p = self.sensor.film_point(film, self.film_z_mm);
        let s = self.pupil.sample(DVec2::new(p.x, p.y), lens_u)?;
        let g = geometric_factor(p, s.point, self.sensor.normal());
        (g > 0.0).then(|| s.pdf_area / g)
    }

    /// Light tracing: where the ray from `from_m` towards `to_m` (camera space, metres) lands
    /// on the film after the lens, at `wavelength_nm`. None when the lens absorbs it or it
    /// misses the sensor plane.
    pub(super) fn connect(&self, from_m: DVec3, to_m: DVec3, wavelength_nm: f64) -> Option<FilmConnection> {
        // 1. The object-space ray in the lens frame (mm), started where it enters the lens.
        let z_ep = self.lens.paraxial().entrance_pupil_z_mm;
        let o = from_m * 1e3 + DVec3::new(0.0, 0.0, z_ep);
        let d = (to_m - from_m).normalize();
        if !(d.z > 1e-9) || !o.is_finite() {
            return None;
        }
        let t_entry = (self.front_plane_z_mm - o.z) / d.z;
        if !(t_entry > 0.0) {
            return None; // the source is inside the lens
        }
        let entry = o + d * t_entry;
        // 2. Through the lens to the film side.
        let traced =
            self.lens.trace(&Ray { origin: entry, direction: d }, wavelength_nm, TraceDirection::SceneToFilm)?;
        let r = traced.ray;
        // 3. Onto the sensor plane.
        let n = self.sensor.normal();
        let denom = r.direction.dot(n);
        if !(denom > 1e-12) {
            return None;
        }
        let t = (DVec3::new(0.0, 0.0, self.film_z_mm) - r.origin).dot(n) / denom;
        if !(t >= 0.0) {
            return None;
        }
        let x = r.origin + r.direction * t;
        // 4. The camera's density for this ray: its rear-plane point and the pupil domain.
        let fxy = DVec2::new(x.x, x.y);
        let ts = (self.pupil.rear_z_mm - r.origin.z) / r.direction.z;
        let s = r.origin + r.direction * ts;
        let g = geometric_factor(x, s, n);
        let pdf_area = self.pupil.pdf_area(fxy, DVec2::new(s.x, s.y));
        let camera_density = if g > 0.0 && pdf_area > 0.0 { pdf_area / g } else { 0.0 };
        let entry_m = DVec3::new(entry.x, entry.y, entry.z - z_ep) * 1e-3;
        Some(FilmConnection {
            film: self.sensor.film_coord(x, self.film_z_mm),
            importance: traced.transmission * self.exposure,
            camera_density,
            entry_m,
        })
    }

    pub(super) fn generate_ray(&self, film: DVec2, lens_u: DVec2, wavelength_nm: f64) -> Option<CameraRay> {
        self.raw_ray(film, lens_u, wavelength_nm).map(|r| CameraRay { weight: r.weight * self.exposure, ..r })
    }
}

/// A plane (lens frame z) wholly in front of `lens`'s first surface: its vertex, less the
/// surface's forward sag at the rim, less a margin for a tilted first element.
fn front_plane_z_mm(lens: &Lens) -> f64 {
    let Some(first) = lens.surfaces().first() else { return 0.0 };
    let h = first.semi_diameter_mm.max(first.housing_semi_diameter_mm);
    let sag = [(h, 0.0), (0.0, h), (h * std::f64::consts::FRAC_1_SQRT_2, h * std::f64::consts::FRAC_1_SQRT_2)]
        .iter()
        .map(|&(x, y)| first.shape.sag(x, y).unwrap_or(-h))
        .fold(0.0f64, f64::min);
    let tilt_margin = if first.placement.is_some() { h } else { 0.0 };
    first.z_mm + sag - tilt_margin - 0.01
}
