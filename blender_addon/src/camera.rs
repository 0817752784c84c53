//! `petzval.Camera`: one camera description for `petzval.render`, with Blender's camera
//! semantics (sensor fit, shift as a fraction of the fitted side, aperture blades/rotation/ratio).
//! Parsed and validated when constructed (an invalid field raises `InvalidSettingsError` naming
//! it; an unknown keyword raises `TypeError` naming it), then immutable. The conventions
//! themselves live in the renderer's `camera::host`, shared with the CLI.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `camera_to_world` | (4, 4) matrix, glTF axes, column vectors | m | — |
//! | `lens` | `"thin"`, `"pinhole"`, library name or lens file | — | `"thin"` |
//! | `lens_model` | auto, exact, lrtf[:RES], thick, thin, pinhole | — | auto |
//! | `tolerance_px` | f64 | px | 0.25 |
//! | `focal_length_mm` | f64 (thin, pinhole) | mm | 50 |
//! | `sensor_width_mm`, `sensor_height_mm` | f64 | mm | 36, 24 |
//! | `sensor_fit` | auto, horizontal, vertical (Blender), expand (USD) | — | auto |
//! | `shift_x`, `shift_y` | f64, Blender's (fraction of the fitted sensor side) | — | 0 |
//! | `tilt_x_deg`, `tilt_y_deg` | f64 | degrees | 0 |
//! | `fstop` | optional f64 (None: pinhole for thin, wide open for real) | — | None |
//! | `focus_distance_m` | optional f64 (None or inf = infinity) | m | None |
//! | `aperture_blades`, `aperture_rotation_rad`, `aperture_ratio` | Blender's | —, rad, — | 0, 0, 1 |
//! | `aperture_image` | optional mask image path | — | None |
//! | `clip_start_m`, `clip_end_m` | f64 | m | 0, inf |
//! | `natural_vignetting` | bool (thin, pinhole; off as Cycles) | — | false |
//! | `ortho_scale_m` | optional f64: orthographic, Blender's Orthographic Scale (spans the fitted sensor side) | m | None (perspective) |

use glam::{DAffine3, DMat3, DVec2, DVec3};
use numpy::{AllowTypeChange, PyArrayLike2};
use petzval_renderer::camera::host::{self, FilmBack, HostCamera, SensorFit, Shift};
use petzval_renderer::LensModel;
use pyo3::prelude::*;

use crate::errors::*;
use crate::scene::affine_from_rows;

/// Rigid camera-to-world transform (scale removed, axes re-orthonormalised).
fn rigid(m: DAffine3) -> PyResult<DAffine3> {
    let x = m.matrix3.x_axis.normalize_or_zero();
    let y0 = m.matrix3.y_axis;
    let y = (y0 - x * x.dot(y0)).normalize_or_zero();
    let z = x.cross(y);
    if x == DVec3::ZERO || y == DVec3::ZERO || z.dot(m.matrix3.z_axis) <= 0.0 {
        return Err(settings_err("camera_to_world", "is degenerate or mirrored".into()));
    }
    Ok(DAffine3 { matrix3: DMat3::from_cols(x, y, z), translation: m.translation })
}

/// A camera for `petzval.render` (see the stub for every argument).
#[pyclass(name = "Camera", module = "petzval._native", frozen)]
pub(crate) struct PyCamera {
    /// The camera as the host conventions describe it (validated).
    pub(crate) host: HostCamera,
    /// Rigid camera-to-world transform.
    pub(crate) to_world: DAffine3,
}

#[pymethods]
impl PyCamera {
    #[new]
    #[pyo3(signature = (camera_to_world, *, lens = "thin", lens_model = "auto", tolerance_px = 0.25, focal_length_mm = 50.0, sensor_width_mm = 36.0, sensor_height_mm = 24.0, sensor_fit = "auto", shift_x = 0.0, shift_y = 0.0, tilt_x_deg = 0.0, tilt_y_deg = 0.0, fstop = None, focus_distance_m = None, aperture_blades = 0, aperture_rotation_rad = 0.0, aperture_ratio = 1.0, aperture_image = None, clip_start_m = 0.0, clip_end_m = f64::INFINITY, natural_vignetting = false, ortho_scale_m = None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        camera_to_world: PyArrayLike2<'_, f64, AllowTypeChange>,
        lens: &str,
        lens_model: &str,
        tolerance_px: f64,
        focal_length_mm: f64,
        sensor_width_mm: f64,
        sensor_height_mm: f64,
        sensor_fit: &str,
        shift_x: f64,
        shift_y: f64,
        tilt_x_deg: f64,
        tilt_y_deg: f64,
        fstop: Option<f64>,
        focus_distance_m: Option<f64>,
        aperture_blades: u32,
        aperture_rotation_rad: f64,
        aperture_ratio: f64,
        aperture_image: Option<String>,
        clip_start_m: f64,
        clip_end_m: f64,
        natural_vignetting: bool,
        ortho_scale_m: Option<f64>,
    ) -> PyResult<Self> {
        guard(|| {
            // 1. Parse into typed values.
            let to_world = rigid(
                affine_from_rows("camera", "camera_to_world", &camera_to_world.as_array())
                    .map_err(|e| settings_err("camera_to_world", e.to_string()))?,
            )?;
            let lens_model: LensModel = lens_model.parse().map_err(py_err)?;
            let fit: SensorFit = sensor_fit.parse().map_err(py_err)?;
            if !(shift_x.is_finite() && shift_y.is_finite()) {
                return Err(settings_err("shift", format!("must be finite, got ({shift_x}, {shift_y})")));
            }
            let aperture = host::blender_aperture(
                aperture_blades,
                aperture_rotation_rad,
                aperture_ratio,
                aperture_image.as_deref().map(std::path::Path::new),
            )
            .map_err(py_err)?;
            // 2. Construct and validate every field that does not depend on the frame.
            let host = HostCamera {
                lens: lens.to_string(),
                lens_model,
                tolerance_px,
                focal_length_mm,
                film_back: FilmBack {
                    width_mm: sensor_width_mm,
                    height_mm: sensor_height_mm,
                    fit,
                    shift: Shift::FitFraction(DVec2::new(shift_x, shift_y)),
                    pixel_aspect: 1.0,
                },
                tilt_deg: DVec2::new(tilt_x_deg, tilt_y_deg),
                f_number: fstop,
                focus_distance_m,
                aperture,
                clip_m: (clip_start_m, clip_end_m),
                natural_vignetting,
                lrtf_file: None,
                ortho_scale_m,
            };
            host.validate().map_err(py_err)?;
            host.film_back.sensor(1, 1, host.tilt_deg).map_err(py_err)?;
            Ok(PyCamera { host, to_world })
        })
    }

    /// The lens argument.
    #[getter]
    fn lens(&self) -> String {
        self.host.lens.clone()
    }

    /// The lens model asked for (its one name).
    #[getter]
    fn lens_model(&self) -> String {
        self.host.lens_model.to_string()
    }

    fn __repr__(&self) -> String {
        format!("Camera(lens={:?}, lens_model={:?})", self.host.lens, self.host.lens_model.to_string())
    }
}
