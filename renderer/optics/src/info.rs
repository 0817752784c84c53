//! Lens report: the first-order data, pupils, field of view and image circle that
//! `petzval lens info --json` prints and the Python module's `Lens.info()` returns.

use super::{paraxial, pupil};
use crate::error::Result;
use crate::lens::Lens;
use serde_json::{json, Value};

/// First-order data, pupils, field of view and image circle of `lens` focused at `focus_m`
/// (None = infinity) for a `sensor` (width, height in mm), as `petzval lens info --json` prints.
pub fn lens_info(lens: &Lens, focus_m: Option<f64>, wavelength: Option<f64>, sensor: (f64, f64)) -> Result<Value> {
    lens.check_forms_image()?;
    let wl = wavelength.unwrap_or(lens.primary_wavelength_nm());
    let p = paraxial::analyse(lens, wl);
    let image_distance = lens.focus_image_distance_mm(focus_m.map(|m| m * 1e3))?;
    let film_z = lens.last_vertex_z_mm() + image_distance;
    let object_z = focus_m.map(|m| p.entrance_pupil_z_mm - m * 1e3);
    let (w, h) = sensor;
    let fov = |x: f64, y: f64| pupil::field_angle_deg(lens, x, y, film_z).map(|a| 2.0 * a);
    let image_circle = pupil::image_circle_radius_mm(lens, film_z, 0.5 * w.hypot(h) * 1.5);
    let widest = lens.with_stop_semi_diameter(lens.max_stop_semi_diameter_mm())?.paraxial().f_number;
    Ok(json!({
        "name": lens.name(),
        "source": lens.prescription().lens.source,
        "file": lens.source_label(),
        "wavelength_nm": wl,
        "efl_mm": p.efl_mm,
        "efl_x_mm": p.efl_x_mm,
        "bfl_mm": p.bfl_mm,
        "ffl_mm": p.ffl_mm,
        "f_number": p.f_number,
        "widest_f_number": widest,
        "working_f_number": paraxial::working_f_number(lens, object_z),
        "entrance_pupil": { "z_mm": p.entrance_pupil_z_mm, "diameter_mm": p.entrance_pupil_diameter_mm },
        "exit_pupil": { "z_mm": p.exit_pupil_z_mm, "diameter_mm": p.exit_pupil_diameter_mm },
        "principal_planes": { "front_z_mm": p.front_principal_z_mm, "back_z_mm": p.rear_principal_z_mm },
        "nodal_points": { "front_z_mm": p.front_nodal_z_mm, "back_z_mm": p.rear_nodal_z_mm },
        "focal_points": { "front_z_mm": p.front_focal_z_mm, "back_z_mm": p.rear_focal_z_mm },
        "focus_m": focus_m,
        "image_distance_mm": image_distance,
        "sensor_z_mm": film_z,
        "total_track_mm": film_z,
        "lens_length_mm": lens.last_vertex_z_mm(),
        "surface_count": lens.surfaces().len(),
        "stop_index": lens.stop_index(),
        "stop_semi_diameter_mm": lens.stop_semi_diameter_mm(),
        "petzval_sum_per_mm": p.petzval_sum_per_mm,
        "petzval_radius_mm": if p.petzval_sum_per_mm != 0.0 { -1.0 / p.petzval_sum_per_mm } else { f64::INFINITY },
        "has_dispersion": lens.has_dispersion(),
        "rotationally_symmetric": lens.is_rotationally_symmetric(),
        "sensor_mm": [w, h],
        "image_circle_radius_mm": image_circle,
        "field_of_view_deg": {
            "horizontal": fov(0.5 * w, 0.0),
            "vertical": fov(0.0, 0.5 * h),
            "diagonal": fov(0.5 * w, 0.5 * h),
    "image_circle": pupil::field_angle_deg(lens, image_circle * (1.0 - 1e-9), 0.0, film_z).map(|a| 2.0 * a),
            "paraxial_diagonal": 2.0 * (0.5 * w.hypot(h) / p.efl_mm.abs()).atan().to_degrees(),
        },
        "thick_lens": {
            "efl_mm": p.efl_mm,
            "front_principal_z_mm": p.front_principal_z_mm,
            "back_principal_z_mm": p.rear_principal_z_mm,
        },
    }))
}
