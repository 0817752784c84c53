//! Cameras: pinhole, thin lens, thick lens and realistic (exact trace through a [`Lens`]), each
//! with a sensor that can be shifted and tilted (Scheimpflug).
//!
//! Camera space: metres, x right, y up, looking down −z (glTF / Blender). The origin is the
//! perspective centre: the pinhole, the thin lens, or the entrance pupil of a real lens (the
//! thick-lens model of a real lens keeps the same origin, so switching models keeps the framing).
//! Focus distances are measured from that origin along the axis.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `sensor.width_mm`, `sensor.height_mm` | f64 | mm | 36 × 24 |
//! | `sensor.shift_mm` | (f64, f64): sensor moved in its plane; +x frames more of the right | mm | (0, 0) |
//! | `sensor.tilt_x_deg` | f64: rotation about the horizontal axis; + moves the image bottom away from the lens, tilting focus towards the ground | degrees | 0 |
//! | `sensor.tilt_y_deg` | f64: rotation about the vertical axis; + moves the image's right side away from the lens | degrees | 0 |
//! | `focal_length_mm` (pinhole, thin) | f64 | mm | 50 |
//! | `f_number` (thin, thick) | f64 | — | 2.8 (thin), the lens's (thick) |
//! | `focus_distance_m` | f64 or infinity | m | infinity |
//! | `natural_vignetting` | bool: include the cos⁴ falloff (pinhole, thin lens) | — | true |
//!
//! Exposure: the weight of each ray is normalised so that the centre of the image of a uniform
//! radiance-1 scene reads 1 at any f-number (as in Blender); natural (cos⁴) and mechanical
//! vignetting show as falloff towards the corners.

mod focus_plane;
mod model_choice;
mod spec;

pub use focus_plane::FocusPlane;
pub use model_choice::{CandidateReport, ModelChoice, ShotContext};
pub use spec::{cached_lrtf, BuiltCamera, CameraSpec, LensModel, DEFAULT_LRTF_RESOLUTION};

use crate::error::{Error, Result};
use crate::optics::aperture::Aperture;
use crate::optics::lens::{Lens, Ray, TraceDirection};
use crate::optics::lrtf::{LrtfLookup, LrtfTable};
use crate::optics::pupil::ExitPupilBounds;
use glam::{DMat3, DVec2, DVec3};
use std::sync::Arc;

/// A ray leaving the camera, in camera space (metres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraRay {
    /// Origin (metres).
    pub origin: DVec3,
    /// Unit direction.
    pub direction: DVec3,
    /// Radiometric weight (irradiance per unit radiance, exposure-normalised).
    pub weight: f64,
}

/// The image sensor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sensor {
    /// Width.
    pub width_mm: f64,
    /// Height.
    pub height_mm: f64,
    /// Shift in the sensor plane.
    pub shift_mm: DVec2,
    /// Tilt about the horizontal axis.
    pub tilt_x_deg: f64,
    /// Tilt about the vertical axis.
    pub tilt_y_deg: f64,
}

impl Default for Sensor {
    fn default() -> Self {
        Sensor { width_mm: 36.0, height_mm: 24.0, shift_mm: DVec2::ZERO, tilt_x_deg: 0.0, tilt_y_deg: 0.0 }
    }
}

impl Sensor {
    /// Checks the fields.
    pub fn validate(&self) -> Result<()> {
        let bad = |f: &str, m: String| Err(Error::Camera { field: f.into(), message: m });
        if !(self.width_mm.is_finite() && self.width_mm > 0.0) {
            return bad("sensor_width_mm", format!("must be positive, got {}", self.width_mm));
        }
        if !(self.height_mm.is_finite() && self.height_mm > 0.0) {
            return bad("sensor_height_mm", format!("must be positive, got {}", self.height_mm));
        }
        if !self.shift_mm.is_finite() {
            return bad("shift_mm", "must be finite".into());
        }
        for (f, t) in [("tilt_x_deg", self.tilt_x_deg), ("tilt_y_deg", self.tilt_y_deg)] {
            if !(t.is_finite() && t.abs() < 60.0) {
                return bad(f, format!("must be within ±60°, got {t}"));
            }
        }
        Ok(())
    }

    /// Rotation of the sensor plane (lens frame).
    pub fn rotation(&self) -> DMat3 {
        DMat3::from_rotation_y(-self.tilt_y_deg.to_radians()) * DMat3::from_rotation_x(self.tilt_x_deg.to_radians())
    }

    /// Unit normal of the sensor plane (lens frame, pointing towards +z).
    pub fn normal(&self) -> DVec3 {
        self.rotation() * DVec3::Z
    }

    /// Film point in the lens frame for an image position `film` in [0,1]² (0,0 = top left),
    /// with the sensor's pivot (where the axis meets it) at z = `film_z_mm`. The image is
    /// inverted on the film, so the upright image position maps to the mirrored film point.
    pub fn film_point(&self, film: DVec2, film_z_mm: f64) -> DVec3 {
        let sx = (film.x - 0.5) * self.width_mm + self.shift_mm.x;
        let sy = (0.5 - film.y) * self.height_mm + self.shift_mm.y;
        DVec3::new(0.0, 0.0, film_z_mm) + self.rotation() * DVec3::new(-sx, -sy, 0.0)
    }

    /// Image position (in [0,1]² when the shift is small) where the optical axis meets the sensor.
    pub fn axis_film_coord(&self) -> DVec2 {
        DVec2::new(0.5 - self.shift_mm.x / self.width_mm, 0.5 + self.shift_mm.y / self.height_mm)
    }

    /// Largest distance of a film point from the optical axis, and the largest |Δz| of the
    /// tilted sensor from its pivot.
    pub fn extent(&self) -> (f64, f64) {
        let mut r: f64 = 0.0;
        let mut dz: f64 = 0.0;
        for (u, v) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
            let p = self.film_point(DVec2::new(u, v), 0.0);
            r = r.max(p.x.hypot(p.y));
            dz = dz.max(p.z.abs());
        }
        (r, dz)
    }
}

/// A pinhole camera.
#[derive(Debug, Clone)]
pub struct PinholeCamera {
    /// Sensor.
    pub sensor: Sensor,
    /// Pinhole-to-film distance.
    pub focal_length_mm: f64,
    /// Apply cos⁴ falloff.
    pub natural_vignetting: bool,
}

/// An ideal thin lens with Blender's (Cycles') conventions: the field of view is that of the
/// focal length F at any focus distance s (the film stays at F behind the lens and the lens's
/// power changes to focus: its focal length is F·s/(F + s)), and the aperture's circumradius is
/// F/(2N). Real lenses, traced or as thick lenses, breathe physically instead.
#[derive(Debug, Clone)]
pub struct ThinLensCamera {
    /// Sensor.
    pub sensor: Sensor,
    /// Focal length F: sets the field of view.
    pub focal_length_mm: f64,
    /// f-number (aperture circumradius = F / 2N).
    pub f_number: f64,
    /// Focus distance (None = infinity).
    pub focus_distance_m: Option<f64>,
    /// Aperture shape.
    pub aperture: Aperture,
    /// Apply cos⁴ falloff (the exposure normalisation for either setting is precomputed, so
    /// this may be changed after construction).
    pub natural_vignetting: bool,
    film_z_mm: f64,
    /// Focal length of the lens focused at the focus distance: F·s/(F + s).
    lens_focal_mm: f64,
    /// Exposure normalisation with and without natural vignetting.
    exposure: [f64; 2],
}

/// The thick-lens approximation of a real lens (its focal length and principal planes).
#[derive(Debug, Clone)]
pub struct ThickLensCamera {
    /// Sensor.
    pub sensor: Sensor,
    /// Focal length.
    pub focal_length_mm: f64,
    /// Front principal plane (lens frame).
    pub front_principal_z_mm: f64,
    /// Rear principal plane (lens frame).
    pub rear_principal_z_mm: f64,
    /// Entrance pupil z of the real lens (camera origin).
    pub entrance_pupil_z_mm: f64,
    /// f-number.
    pub f_number: f64,
    /// Focus distance (None = infinity).
    pub focus_distance_m: Option<f64>,
    /// Aperture shape.
    pub aperture: Aperture,
    film_z_mm: f64,
    exposure: f64,
}

/// A real lens traced exactly.
#[derive(Debug, Clone)]
pub struct RealisticCamera {
    /// Sensor.
    pub sensor: Sensor,
    /// The lens (stopped down).
    pub lens: Lens,
    /// Focus distance (None = infinity).
    pub focus_distance_m: Option<f64>,
    /// Film pivot z (lens frame).
    pub film_z_mm: f64,
    /// Exit-pupil bounds for sampling.
    pub pupil: ExitPupilBounds,
    exposure: f64,
}

/// Every camera model.
#[derive(Debug, Clone)]
pub enum Camera {
    /// Pinhole.
    Pinhole(PinholeCamera),
    /// Thin lens.
    ThinLens(ThinLensCamera),
    /// Thick-lens approximation of a real lens.
    ThickLens(ThickLensCamera),
    /// Exact trace through a real lens.
    Realistic(RealisticCamera),
    /// A real lens through its ray transfer table.
    Lrtf(LrtfCamera),
}

/// Thin-lens refraction: direction of the ray that left film point `p` (relative to the lens,
/// z > 0) through lens point `l` (z = 0) for focal length `f`: towards the conjugate of `p`.
#[inline]
fn thin_lens_direction(p: DVec3, l: DVec3, f: f64) -> DVec3 {
    (-p - l * ((p.z - f) / f)).normalize()
}

/// Image distance for an object `u` mm in front of a thin lens of focal length `f`.
fn thin_lens_image_distance(f: f64, u: Option<f64>) -> Result<f64> {
    match u {
        None => Ok(f),
        Some(u) if u > f => Ok(1.0 / (1.0 / f - 1.0 / u)),
        Some(u) => Err(Error::camera(
            "focus_distance_m",
            format!("cannot focus at {:.4} m: closer than the focal length {:.4} m", u * 1e-3, f * 1e-3),
        )),
    }
}

/// Radiometric factor cosθ_film · cosθ_lens / d² for a ray from `film` to `lens_pt`.
#[inline]
fn geometric_factor(film: DVec3, lens_pt: DVec3, film_normal: DVec3) -> f64 {
    let v = lens_pt - film;
    let d2 = v.length_squared();
    let dir = v / d2.sqrt();
    (dir.dot(film_normal)).abs() * dir.z.abs() / d2
}

/// Stratified estimate of the mean weight at the image centre, for exposure normalisation.
fn centre_mean(mut raw: impl FnMut(DVec2) -> Option<f64>) -> f64 {
    let n = 256;
    let mut sum = 0.0;
    for i in 0..n {
        for j in 0..n {
            let u = DVec2::new((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
            sum += raw(u).unwrap_or(0.0);
        }
    }
    sum / (n * n) as f64
}

impl PinholeCamera {
    /// A pinhole camera.
    pub fn new(sensor: Sensor, focal_length_mm: f64) -> Result<Self> {
        sensor.validate()?;
        check_positive("focal_length_mm", focal_length_mm)?;
        Ok(PinholeCamera { sensor, focal_length_mm, natural_vignetting: true })
    }

    fn generate_ray(&self, film: DVec2) -> Option<CameraRay> {
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

impl ThinLensCamera {
    /// A thin-lens camera focused at `focus_distance_m` (None = infinity).
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
        let mut cam = ThinLensCamera {
            sensor,
            focal_length_mm,
            f_number,
            focus_distance_m,
            aperture,
            natural_vignetting: true,
            film_z_mm: focal_length_mm,
            lens_focal_mm,
            exposure: [1.0; 2],
        };
        let centre = cam.sensor.axis_film_coord();
        let natural = 1.0 / centre_mean(|u| cam.raw_ray(centre, u).map(|r| r.weight));
        cam.natural_vignetting = false;
        let flat = 1.0 / centre_mean(|u| cam.raw_ray(centre, u).map(|r| r.weight));
        cam.natural_vignetting = true;
        cam.exposure = [natural, flat];
        Ok(cam)
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
        let (q, pdf_unit) = self.aperture.sample_unit(lens_u);
        let l = DVec3::new(q.x * r, q.y * r, 0.0);
        let transmission = self.aperture.transmission(l.x, l.y, r);
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

    fn generate_ray(&self, film: DVec2, lens_u: DVec2) -> Option<CameraRay> {
        let exposure = self.exposure[if self.natural_vignetting { 0 } else { 1 }];
        self.raw_ray(film, lens_u).map(|r| CameraRay { weight: r.weight * exposure, ..r })
    }
}

impl ThickLensCamera {
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
        let mut cam = ThickLensCamera {
            sensor,
            focal_length_mm: f,
            front_principal_z_mm: p.front_principal_z_mm,
            rear_principal_z_mm: p.rear_principal_z_mm,
            entrance_pupil_z_mm: p.entrance_pupil_z_mm,
            f_number,
            focus_distance_m,
            aperture,
            film_z_mm: p.rear_principal_z_mm + v,
            exposure: 1.0,
        };
        let centre = cam.sensor.axis_film_coord();
        cam.exposure = 1.0 / centre_mean(|u| cam.raw_ray(centre, u).map(|r| r.weight));
        Ok(cam)
    }

    /// Film pivot z (lens frame).
    pub fn film_z_mm(&self) -> f64 {
        self.film_z_mm
    }

    fn raw_ray(&self, film: DVec2, lens_u: DVec2) -> Option<CameraRay> {
        // 1. Thin lens at the rear principal plane.
        let p = self.sensor.film_point(film, self.film_z_mm) - DVec3::new(0.0, 0.0, self.rear_principal_z_mm);
        let r = 0.5 * self.focal_length_mm / self.f_number;
        let (q, pdf_unit) = self.aperture.sample_unit(lens_u);
        let l = DVec3::new(q.x * r, q.y * r, 0.0);
        let transmission = self.aperture.transmission(l.x, l.y, r);
        if transmission <= 0.0 {
            return None;
        }
        let dir = thin_lens_direction(p, l, self.focal_length_mm);
        let weight = geometric_factor(p, l, self.sensor.normal()) * r * r / pdf_unit * transmission;
        // 2. Leave from the same height on the front principal plane.
        let origin = DVec3::new(l.x, l.y, self.front_principal_z_mm - self.entrance_pupil_z_mm) * 1e-3;
        Some(CameraRay { origin, direction: dir, weight })
    }

    fn generate_ray(&self, film: DVec2, lens_u: DVec2) -> Option<CameraRay> {
        self.raw_ray(film, lens_u).map(|r| CameraRay { weight: r.weight * self.exposure, ..r })
    }
}

impl RealisticCamera {
    /// A camera tracing `lens` (already stopped down), focused at `focus_distance_m` from the
    /// entrance pupil.
    pub fn new(sensor: Sensor, lens: Lens, focus_distance_m: Option<f64>) -> Result<Self> {
        sensor.validate()?;
        if let Some(d) = focus_distance_m {
            check_positive("focus_distance_m", d)?;
        }
        let image_distance = lens.focus_image_distance_mm(focus_distance_m.map(|m| m * 1e3))?;
        let film_z_mm = lens.last_vertex_z_mm() + image_distance;
        let (r_max, dz) = sensor.extent();
        if film_z_mm - dz <= lens.last_vertex_z_mm() {
            return Err(Error::Camera {
                field: "tilt".into(),
                message: "the tilted sensor would cut into the rear element".into(),
            });
        }
        let pupil = ExitPupilBounds::compute(&lens, film_z_mm, dz, r_max * 1.001);
        let mut cam = RealisticCamera { sensor, lens, focus_distance_m, film_z_mm, pupil, exposure: 1.0 };
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

    fn raw_ray(&self, film: DVec2, lens_u: DVec2, wavelength_nm: f64) -> Option<CameraRay> {
        self.raw_ray_with(film, lens_u, |ray| {
            self.lens.trace(ray, wavelength_nm, TraceDirection::FilmToScene).map(|t| (t.ray, t.transmission))
        })
    }

    /// The camera ray for a film and lens sample, with `through_lens` mapping the ray from the
    /// film to the ray leaving the front and its stop transmission (exact trace or a table).
    #[inline]
    fn raw_ray_with(
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

    fn generate_ray(&self, film: DVec2, lens_u: DVec2, wavelength_nm: f64) -> Option<CameraRay> {
        self.raw_ray(film, lens_u, wavelength_nm).map(|r| CameraRay { weight: r.weight * self.exposure, ..r })
    }
}

/// A real lens evaluated through its baked ray transfer table ([`LrtfTable`]); rays in cells
/// that straddle a vignetting boundary are traced exactly.
#[derive(Debug, Clone)]
pub struct LrtfCamera {
    /// The same camera traced exactly (sensor, lens, focus, pupil bounds, exposure).
    pub exact: RealisticCamera,
    /// The table.
    pub table: Arc<LrtfTable>,
}

impl LrtfCamera {
    /// A camera through `table`, which must have been baked for `lens` and cover the sensor.
    pub fn new(sensor: Sensor, lens: Lens, focus_distance_m: Option<f64>, table: Arc<LrtfTable>) -> Result<Self> {
        Self::with_exact(RealisticCamera::new(sensor, lens, focus_distance_m)?, table)
    }

    /// A camera through `table` for an exact camera already built (its pupil bounds and
    /// exposure are reused).
    pub fn with_exact(exact: RealisticCamera, table: Arc<LrtfTable>) -> Result<Self> {
        let h = &table.header;
        let (r, dz) = exact.sensor.extent();
        if r > h.max_film_radius_mm {
            return Err(Error::Camera {
                field: "lens_model".into(),
                message: format!("the LRTF table covers film points up to {:.1} mm from the axis; this sensor reaches {r:.1} mm: re-bake with a larger --max-film-radius", h.max_film_radius_mm),
            });
        }
        if exact.film_z_mm - dz - h.in_base_z_mm < h.min_film_distance_mm - 1e-9 {
            return Err(Error::Camera {
                field: "lens_model".into(),
                message: "the sensor comes closer to the lens than the LRTF table covers: re-bake it".into(),
            });
        }
        Ok(LrtfCamera { exact, table })
    }

    fn raw_ray(&self, film: DVec2, lens_u: DVec2, wavelength_nm: f64) -> Option<CameraRay> {
        let lens = &self.exact.lens;
        self.exact.raw_ray_with(film, lens_u, |ray| match self.table.lookup(ray, wavelength_nm) {
            LrtfLookup::Hit(hit) => {
                let tr = lens.aperture().transmission(hit.stop_point.x, hit.stop_point.y, lens.stop_semi_diameter_mm());
                (tr > 0.0).then_some((hit.ray, tr))
            }
            LrtfLookup::Miss => None,
            LrtfLookup::Uncertain => {
                lens.trace(ray, wavelength_nm, TraceDirection::FilmToScene).map(|t| (t.ray, t.transmission))
            }
        })
    }

    fn generate_ray(&self, film: DVec2, lens_u: DVec2, wavelength_nm: f64) -> Option<CameraRay> {
        self.raw_ray(film, lens_u, wavelength_nm).map(|r| CameraRay { weight: r.weight * self.exact.exposure, ..r })
    }
}

fn check_positive(field: &str, v: f64) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(Error::Camera { field: field.into(), message: format!("must be a positive number, got {v}") })
    }
}

impl Camera {
    /// Generates a ray for image position `film` in [0,1]² (top left = (0,0)), lens sample
    /// `lens_u` in [0,1)² and wavelength. `None` when the sample is blocked.
    #[inline]
    pub fn generate_ray(&self, film: DVec2, lens_u: DVec2, wavelength_nm: f64) -> Option<CameraRay> {
        match self {
            Camera::Pinhole(c) => c.generate_ray(film),
            Camera::ThinLens(c) => c.generate_ray(film, lens_u),
            Camera::ThickLens(c) => c.generate_ray(film, lens_u),
            Camera::Realistic(c) => c.generate_ray(film, lens_u, wavelength_nm),
            Camera::Lrtf(c) => c.generate_ray(film, lens_u, wavelength_nm),
        }
    }

    /// The sensor.
    pub fn sensor(&self) -> &Sensor {
        match self {
            Camera::Pinhole(c) => &c.sensor,
            Camera::ThinLens(c) => &c.sensor,
            Camera::ThickLens(c) => &c.sensor,
            Camera::Realistic(c) => &c.sensor,
            Camera::Lrtf(c) => &c.exact.sensor,
        }
    }

    /// Whether wavelengths take different paths: a real lens with dispersive glass, traced or
    /// through a table with more than one wavelength. Only then is spectral rendering needed.
    pub fn is_dispersive(&self) -> bool {
        match self {
            Camera::Realistic(c) => c.lens.has_dispersion(),
            Camera::Lrtf(c) => c.exact.lens.has_dispersion() && c.table.header.wavelengths_nm.len() > 1,
            _ => false,
        }
    }

    /// Model name.
    pub fn model_name(&self) -> &'static str {
        match self {
            Camera::Pinhole(_) => "pinhole",
            Camera::ThinLens(_) => "thin",
            Camera::ThickLens(_) => "thick",
            Camera::Realistic(_) => "exact",
            Camera::Lrtf(_) => "lrtf",
        }
    }

    /// The plane of sharp focus (camera space), from the thin-lens mapping (the thick-lens
    /// approximation for real lenses). For an untilted sensor it is perpendicular to the axis.
    pub fn focus_plane(&self) -> Option<FocusPlane> {
        focus_plane::focus_plane(self)
    }
}
