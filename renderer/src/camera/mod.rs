//! Cameras: one model per file — [`pinhole`], [`thin`] lens, [`thick`] lens, [`exact`] trace
//! through a real [`Lens`](crate::optics::lens::Lens) and [`lrtf`] (its ray transfer table) —
//! each with a [`Sensor`] that can be shifted and tilted (Scheimpflug); [`CameraSpec::build`]
//! is the one builder every front end uses (the CLI, the Python module, the benchmarks and the
//! `auto` chooser), and [`host`] holds the host applications' camera conventions (Blender,
//! glTF, USD). The camera layer knows nothing of scenes or rendering: scene-dependent steps
//! (depth probe, autofocus) live in [`crate::shot`].
//!
//! One name per model everywhere: [`LensModel`]'s `Display`/`FromStr` names (the CLI's
//! `--lens-model` values `auto|exact|lrtf[:RES]|thick|thin|pinhole`) are the [`Camera`]
//! variants, the module names, the Python `lens_model` values, the Blender enum and the EXR
//! `lensModel` metadata.
//!
//! Camera space: metres, x right, y up, looking down −z (glTF / Blender). The origin is the
//! perspective centre: the pinhole, the thin lens, or the entrance pupil of a real lens (the
//! thick-lens model of a real lens keeps the same origin, so switching models keeps the framing).
//! Focus distances are measured from that origin along the axis.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `sensor` | [`Sensor`] (see [`sensor`]) | mm, degrees | 36 × 24 |
//! | `focal_length_mm` (pinhole, thin) | f64 | mm | 50 |
//! | `f_number` (thin, thick) | f64 | — | 2.8 (thin), the lens's (thick) |
//! | `focus_distance_m` | f64 or infinity | m | infinity |
//! | `natural_vignetting` | bool: include the cos⁴ falloff (pinhole, thin lens) | — | true |
//!
//! Exposure: the weight of each ray is normalised so that the centre of the image of a uniform
//! radiance-1 scene reads 1 at any f-number (as in Blender); natural (cos⁴) and mechanical
//! vignetting show as falloff towards the corners.

mod builder;
pub mod exact;
mod focus_plane;
pub mod host;
mod ideal;
pub mod lrtf;
mod model;
mod model_choice;
pub mod orthographic;
pub mod pinhole;
pub mod sensor;
mod spec;
pub mod thick;
pub mod thin;

pub use builder::BuiltCamera;
pub use exact::ExactCamera;
pub(crate) use focus_plane::thin_lens_data;
pub use focus_plane::FocusPlane;
pub use lrtf::LrtfCamera;
pub use model::cached_lrtf;
pub use model_choice::{CandidateReport, ModelChoice, ShotContext};
pub use orthographic::OrthographicCamera;
pub use pinhole::PinholeCamera;
pub use sensor::Sensor;
pub(crate) use spec::SpecLens;
pub use spec::{CameraSpec, LensModel, DEFAULT_LRTF_RESOLUTION};
pub use thick::ThickCamera;
pub use thin::ThinCamera;

use crate::error::{Error, Result};
use glam::{DVec2, DVec3};

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

/// Where light from a scene point lands on the film (light tracing through the camera).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FilmConnection {
    /// Image position in [0,1]² (top left = (0,0)), as [`Camera::generate_ray`] takes it.
    pub film: DVec2,
    /// Importance per unit radiance before the pixel filter: stop transmission × exposure
    /// (a camera ray's weight is this × cosθ_film cosθ_rear / d² / pdf).
    pub importance: f64,
    /// The camera strategy's density for this ray, as [`Camera::sample_density`] gives it
    /// (0 when the camera cannot draw it).
    pub camera_density: f64,
    /// Where the ray enters the lens (camera space, metres): visibility is tested up to here.
    pub entry_m: DVec3,
}

/// Every camera model; each variant is named as its [`LensModel`].
#[derive(Debug, Clone)]
pub enum Camera {
    /// Pinhole.
    Pinhole(PinholeCamera),
    /// Ideal thin lens (Blender's conventions).
    Thin(ThinCamera),
    /// Thick-lens approximation of a real lens.
    Thick(ThickCamera),
    /// Exact trace through a real lens.
    Exact(ExactCamera),
    /// A real lens through its ray transfer table.
    Lrtf(LrtfCamera),
    /// Parallel projection (no lens).
    Orthographic(OrthographicCamera),
}

/// Thin-lens refraction: direction of the ray that left film point `p` (relative to the lens,
/// z > 0) through lens point `l` (z = 0) for focal length `f`: towards the conjugate of `p`.
#[inline]
pub(crate) fn thin_lens_direction(p: DVec3, l: DVec3, f: f64) -> DVec3 {
    (-p - l * ((p.z - f) / f)).normalize()
}

/// Image distance for an object `u` mm in front of a thin lens of focal length `f`.
pub(crate) fn thin_lens_image_distance(f: f64, u: Option<f64>) -> Result<f64> {
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
pub(crate) fn geometric_factor(film: DVec3, lens_pt: DVec3, film_normal: DVec3) -> f64 {
    let v = lens_pt - film;
    let d2 = v.length_squared();
    let dir = v / d2.sqrt();
    (dir.dot(film_normal)).abs() * dir.z.abs() / d2
}

/// Stratified estimate of the mean weight at the image centre, for exposure normalisation.
pub(crate) fn centre_mean(mut raw: impl FnMut(DVec2) -> Option<f64>) -> f64 {
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

pub(crate) fn check_positive(field: &str, v: f64) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(Error::camera(field, format!("must be a positive number, got {v}")))
    }
}

/// Samples per [`Camera::generate_ray_batch`] (the LRTF table's batch).
pub const CAMERA_BATCH: usize = crate::optics::lrtf::LRTF_BATCH;

impl Camera {
    /// The camera for lens samples shared by every pixel (multi-view's views): real lenses draw
    /// their pupil samples in the traced bounds only ([`ExactCamera::without_defensive_disc`]);
    /// other models are unchanged.
    pub fn for_shared_lens_samples(&self) -> Camera {
        match self {
            Camera::Exact(c) => Camera::Exact(c.without_defensive_disc()),
            Camera::Lrtf(c) => Camera::Lrtf(c.without_defensive_disc()),
            other => other.clone(),
        }
    }

    /// Generates a ray for image position `film` in [0,1]² (top left = (0,0)), lens sample
    /// `lens_u` in [0,1)² and wavelength. `None` when the sample is blocked.
    #[inline]
    pub fn generate_ray(&self, film: DVec2, lens_u: DVec2, wavelength_nm: f64) -> Option<CameraRay> {
        match self {
            Camera::Pinhole(c) => c.generate_ray(film),
            Camera::Thin(c) => c.generate_ray(film, lens_u),
            Camera::Thick(c) => c.generate_ray(film, lens_u),
            Camera::Exact(c) => c.generate_ray(film, lens_u, wavelength_nm),
            Camera::Lrtf(c) => c.generate_ray(film, lens_u, wavelength_nm),
            Camera::Orthographic(c) => c.generate_ray(film, lens_u),
        }
    }

    /// [`Camera::generate_ray`] of [`CAMERA_BATCH`] samples at once: the same rays, bit for
    /// bit; the LRTF model looks its lanes up in one batched table lookup (their cells found
    /// and prefetched first), the other models ray by ray.
    #[inline]
    pub fn generate_ray_batch(
        &self,
        film: &[DVec2; CAMERA_BATCH],
        lens_u: &[DVec2; CAMERA_BATCH],
        wavelength_nm: &[f64; CAMERA_BATCH],
    ) -> [Option<CameraRay>; CAMERA_BATCH] {
        match self {
            Camera::Lrtf(c) => c.generate_ray_batch(film, lens_u, wavelength_nm),
            _ => std::array::from_fn(|i| self.generate_ray(film[i], lens_u[i], wavelength_nm[i])),
        }
    }

    /// Whether light can be traced from the scene onto the film ([`Camera::connect`]): every
    /// model with a lens. The thin and thick lenses map light exactly as they map camera rays;
    /// the LRTF model's light paths are traced exactly (its table maps film → scene only; the
    /// two agree within the table's error, a fraction of a pixel). Not the pinhole nor the
    /// orthographic camera.
    pub fn can_connect(&self) -> bool {
        !matches!(self, Camera::Pinhole(_) | Camera::Orthographic(_))
    }

    /// The camera strategy's density for sample (`film`, `lens_u`) in the ray (étendue)
    /// measure, per unit film density (mm⁻² of the rear plane over the geometric factor), for
    /// combining camera paths with light paths. None for models that cannot connect.
    pub fn sample_density(&self, film: DVec2, lens_u: DVec2) -> Option<f64> {
        match self {
            Camera::Pinhole(_) | Camera::Orthographic(_) => None,
            Camera::Thin(c) => c.sample_density(film, lens_u),
            Camera::Thick(c) => c.sample_density(film, lens_u),
            Camera::Exact(c) => c.sample_density(film, lens_u),
            Camera::Lrtf(c) => c.exact().sample_density(film, lens_u),
        }
    }

    /// Light tracing: where the ray from `from_m` towards `to_m` (camera space, metres) lands
    /// on the film, at `wavelength_nm`; None when blocked or for models that cannot connect.
    pub fn connect(&self, from_m: DVec3, to_m: DVec3, wavelength_nm: f64) -> Option<FilmConnection> {
        match self {
            Camera::Pinhole(_) | Camera::Orthographic(_) => None,
            Camera::Thin(c) => c.connect(from_m, to_m),
            Camera::Thick(c) => c.connect(from_m, to_m),
            Camera::Exact(c) => c.connect(from_m, to_m, wavelength_nm),
            Camera::Lrtf(c) => c.exact().connect(from_m, to_m, wavelength_nm),
        }
    }

    /// Where bokeh light paths aim (camera space, metres): the plane z = `.0` and the radius
    /// `.1` of a disc about the axis through which every ray that reaches the film passes, for
    /// models that can connect. The thin and thick lenses: the opening's bounding circle at the
    /// (object-side) principal plane, exactly. Real lenses (exact, LRTF): at the camera origin,
    /// the pupil moves and changes with the field, so the radius is measured
    /// ([`real_lens_disc_m`]); a ray outside the disc is left to camera paths, so the radius
    /// biases nothing.
    pub fn light_path_disc(&self) -> Option<(f64, f64)> {
        match self {
            Camera::Pinhole(_) | Camera::Orthographic(_) => None,
            Camera::Thin(c) => Some(c.light_path_disc()),
            Camera::Thick(c) => Some(c.light_path_disc()),
            Camera::Exact(c) => self.entrance_pupil_radius_m().map(|r| (0.0, real_lens_disc_m(c, r))),
            Camera::Lrtf(c) => self.entrance_pupil_radius_m().map(|r| (0.0, real_lens_disc_m(c.exact(), r))),
        }
    }

    /// Radius of the entrance pupil (metres, paraxial, about the camera origin), for models
    /// that can connect: the aperture's circumradius for the thin and thick lenses.
    pub fn entrance_pupil_radius_m(&self) -> Option<f64> {
        match self {
            Camera::Pinhole(_) | Camera::Orthographic(_) => None,
            Camera::Thin(c) => Some(1e-3 * c.aperture_radius_mm()),
            Camera::Thick(c) => Some(1e-3 * c.aperture_radius_mm()),
            Camera::Exact(c) => Some(0.5e-3 * c.lens().paraxial().entrance_pupil_diameter_mm),
            Camera::Lrtf(c) => Some(0.5e-3 * c.exact().lens().paraxial().entrance_pupil_diameter_mm),
        }
    }

    /// The sensor.
    pub fn sensor(&self) -> &Sensor {
        match self {
            Camera::Pinhole(c) => c.sensor(),
            Camera::Thin(c) => c.sensor(),
            Camera::Thick(c) => c.sensor(),
            Camera::Exact(c) => c.sensor(),
            Camera::Lrtf(c) => c.exact().sensor(),
            Camera::Orthographic(c) => c.sensor(),
        }
    }

    /// The real lens traced (exact and LRTF models), else None.
    pub fn real_lens(&self) -> Option<&crate::optics::lens::Lens> {
        match self {
            Camera::Exact(c) => Some(c.lens()),
            Camera::Lrtf(c) => Some(c.exact().lens()),
            _ => None,
        }
    }

    /// Whether wavelengths take different paths: a real lens with dispersive glass, traced or
    /// through a table with more than one wavelength. Only then is spectral rendering needed.
    pub fn is_dispersive(&self) -> bool {
        match self {
            Camera::Exact(c) => c.lens().has_dispersion(),
            Camera::Lrtf(c) => c.exact().lens().has_dispersion() && c.table().header.wavelengths_nm.len() > 1,
            _ => false,
        }
    }

    /// The model of this camera (its `Display` is the model's one name; an LRTF carries its
    /// table's resolution).
    pub fn model(&self) -> LensModel {
        match self {
            Camera::Pinhole(_) => LensModel::Pinhole,
            Camera::Thin(_) => LensModel::Thin,
            Camera::Thick(_) => LensModel::Thick,
            Camera::Exact(_) => LensModel::Exact,
            Camera::Lrtf(c) => LensModel::Lrtf { resolution: c.table().header.resolution },
            Camera::Orthographic(_) => LensModel::Orthographic,
        }
    }

    /// The plane of sharp focus (camera space), from the thin-lens mapping (the thick-lens
    /// approximation for real lenses). For an untilted sensor it is perpendicular to the axis.
    pub fn focus_plane(&self) -> Option<FocusPlane> {
        focus_plane::focus_plane(self)
    }
}

/// Radius (m) of the light-path disc of a real lens whose paraxial entrance pupil has radius
/// `ep_radius_m`: where camera rays through the lens cross the plane z = 0, the largest radius
/// over a 17 × 17 grid of film points × 64 lens samples each (a Hammersley set), grown by 5 %
/// and 0.2 mm for the rays between the samples; at most 1.25 × the pupil plus 0.5 mm (the
/// fixed radius used before, which a fisheye's far-field rays would exceed).
fn real_lens_disc_m(camera: &exact::ExactCamera, ep_radius_m: f64) -> f64 {
    let bound_m = 1.25 * ep_radius_m + 0.5e-3;
    let wavelength_nm = camera.lens().primary_wavelength_nm();
    let mut widest_m = 0.0f64;
    for fy in 0..=16 {
        for fx in 0..=16 {
            let film = DVec2::new(fx as f64 / 16.0, fy as f64 / 16.0);
            for k in 0..64u32 {
                let lens_u = DVec2::new((k as f64 + 0.5) / 64.0, k.reverse_bits() as f64 / 2f64.powi(32));
                let Some(ray) = camera.generate_ray(film, lens_u, wavelength_nm) else { continue };
                if ray.direction.z.abs() < 1e-9 {
                    continue;
                }
                let p = ray.origin - ray.direction * (ray.origin.z / ray.direction.z);
                let r = DVec2::new(p.x, p.y).length();
                if r.is_finite() {
                    widest_m = widest_m.max(r);
                }
            }
        }
    }
    if widest_m > 0.0 {
        (1.05 * widest_m + 0.2e-3).min(bound_m)
    } else {
        bound_m
    }
}
