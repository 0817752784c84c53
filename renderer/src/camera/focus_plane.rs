//! The plane of sharp focus of a (possibly tilted) sensor: Scheimpflug and hinge rules.
//!
//! A thin lens maps planes to planes, so the conjugates of three film points span the plane of
//! sharp focus exactly; for real lenses the thick-lens approximation (focal length, principal
//! planes) is used, and tests verify it by tracing.

use super::{Camera, ExactCamera};
use glam::DVec3;

/// The plane of sharp focus, in camera space (metres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FocusPlane {
    /// A point on the plane (where the optical axis meets it, when it does).
    pub point_m: DVec3,
    /// Unit normal (towards the camera).
    pub normal: DVec3,
    /// Distance from the lens centre (front principal point) to the hinge line, where the plane
    /// of focus meets the plane through the lens parallel to the sensor (f / sin tilt); `None`
    /// for an untilted sensor.
    pub hinge_distance_m: Option<f64>,
    /// Angle between the plane of focus and the sensor plane (degrees).
    pub angle_to_sensor_deg: f64,
}

impl FocusPlane {
    /// Parameter t at which `origin + t·dir` meets the plane (`None` if parallel or behind).
    pub fn intersect(&self, origin: DVec3, dir: DVec3) -> Option<f64> {
        let den = self.normal.dot(dir);
        if den.abs() < 1e-15 {
            return None;
        }
        let t = self.normal.dot(self.point_m - origin) / den;
        (t > 0.0).then_some(t)
    }
}

/// Conjugate (object-side, relative to the front principal point) of film point `p` (relative to
/// the rear principal point) for focal length `f`.
fn conjugate(p: DVec3, f: f64) -> DVec3 {
    -p * (f / (p.z - f))
}

/// Thin-lens data of a real lens's camera: focal length, film pivot relative to the rear
/// principal plane, front principal point in camera space.
fn real_lens_data(c: &ExactCamera) -> (f64, f64, f64) {
    let p = c.lens().paraxial();
    (p.efl_mm, c.film_z_mm() - p.rear_principal_z_mm, p.front_principal_z_mm - p.entrance_pupil_z_mm)
}

/// Thin-lens data of a camera with a lens: focal length as focused, film pivot relative to the
/// rear principal plane (the image distance), and the front principal point in camera space (all
/// mm). None for the pinhole.
pub(crate) fn thin_lens_data(cam: &Camera) -> Option<(f64, f64, f64)> {
    Some(match cam {
        Camera::Pinhole(_) | Camera::Orthographic(_) => return None,
        Camera::Thin(c) => (c.lens_focal_length_mm(), c.film_distance_mm(), 0.0),
        Camera::Thick(c) => (
            c.focal_length_mm(),
            c.film_z_mm() - c.rear_principal_z_mm(),
            c.front_principal_z_mm() - c.entrance_pupil_z_mm(),
        ),
        Camera::Exact(c) => real_lens_data(c),
        Camera::Lrtf(c) => real_lens_data(c.exact()),
    })
}

pub(super) fn focus_plane(cam: &Camera) -> Option<FocusPlane> {
    // 1. Thin-lens data: focal length, film pivot relative to the rear principal plane, and the
    //    front principal point in camera space.
    let (f, film_z, front_cam_z_mm) = thin_lens_data(cam)?;
    let sensor = cam.sensor();
    let rot = sensor.rotation();
    let pivot = DVec3::new(0.0, 0.0, film_z);
    // 2. Conjugates of three film points span the plane.
    let pts: Vec<DVec3> = [DVec3::ZERO, DVec3::new(5.0, 0.0, 0.0), DVec3::new(0.0, 5.0, 0.0)]
        .iter()
        .map(|d| conjugate(pivot + rot * *d, f) + DVec3::new(0.0, 0.0, front_cam_z_mm))
        .collect();
    let mut normal = (pts[1] - pts[0]).cross(pts[2] - pts[0]).normalize();
    if !normal.is_finite() {
        return None;
    }
    if normal.z < 0.0 {
        normal = -normal;
    }
    // Point where the axis meets the plane (or the conjugate of the pivot if parallel).
    let centre = DVec3::new(0.0, 0.0, front_cam_z_mm);
    let point = if normal.z.abs() > 1e-12 {
        let t = normal.dot(pts[0] - centre) / normal.z;
        centre + DVec3::Z * t
    } else {
        pts[0]
    };
    // 3. Hinge line: the plane of focus meets the plane through the lens parallel to the sensor.
    let film_n = sensor.normal();
    let line_dir = normal.cross(film_n);
    let hinge = if line_dir.length() < 1e-12 {
        None
    } else {
        // closest point of the line to the lens centre: solve in the two plane equations
        let n1 = normal;
        let n2 = film_n;
        let d1 = n1.dot(point);
        let d2 = n2.dot(centre);
        let n12 = n1.dot(n2);
        let det = 1.0 - n12 * n12;
        let c1 = (d1 - d2 * n12) / det;
        let c2 = (d2 - d1 * n12) / det;
        let q = c1 * n1 + c2 * n2;
        Some((q - centre).length() * 1e-3)
    };
    let angle = normal.dot(film_n).clamp(-1.0, 1.0).acos().to_degrees();
    Some(FocusPlane { point_m: point * 1e-3, normal, hinge_distance_m: hinge, angle_to_sensor_deg: angle })
}
