//! The image sensor: size, shift in its plane and Scheimpflug tilt. Every camera model has one.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `width_mm`, `height_mm` | f64 | mm | 36 × 24 |
//! | `shift_mm` | (f64, f64): sensor moved in its plane; +x frames more of the right | mm | (0, 0) |
//! | `tilt_x_deg` | f64: rotation about the horizontal axis; + moves the image bottom away from the lens, tilting focus towards the ground | degrees | 0 |
//! | `tilt_y_deg` | f64: rotation about the vertical axis; + moves the image's right side away from the lens | degrees | 0 |

use crate::error::{Error, Result};
use glam::{DMat3, DVec2, DVec3};

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
        let bad = |f: &str, m: String| Err(Error::camera(f, m));
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
        self.film_point_rotated(&self.rotation(), film, film_z_mm)
    }

    /// [`Sensor::film_point`] with the sensor's [`Sensor::rotation`] given.
    #[inline]
    fn film_point_rotated(&self, rotation: &DMat3, film: DVec2, film_z_mm: f64) -> DVec3 {
        let sx = (film.x - 0.5) * self.width_mm + self.shift_mm.x;
        let sy = (0.5 - film.y) * self.height_mm + self.shift_mm.y;
        DVec3::new(0.0, 0.0, film_z_mm) + *rotation * DVec3::new(-sx, -sy, 0.0)
    }

    /// The inverse of [`Sensor::film_point`]: the image position of lens-frame point `p` on
    /// the sensor plane (pivot at z = `film_z_mm`).
    pub fn film_coord(&self, p: DVec3, film_z_mm: f64) -> DVec2 {
        self.film_coord_rotated(&self.rotation(), p, film_z_mm)
    }

    /// [`Sensor::film_coord`] with the sensor's [`Sensor::rotation`] given.
    #[inline]
    fn film_coord_rotated(&self, rotation: &DMat3, p: DVec3, film_z_mm: f64) -> DVec2 {
        let local = rotation.transpose() * (p - DVec3::new(0.0, 0.0, film_z_mm));
        let (sx, sy) = (-local.x, -local.y);
        DVec2::new((sx - self.shift_mm.x) / self.width_mm + 0.5, 0.5 - (sy - self.shift_mm.y) / self.height_mm)
    }

    /// The sensor of the pixel grid that continues this sensor's `width` × `height` one to the
    /// pixel rectangle `[x0, y0, x1, y1)` (frame pixels, row 0 at the top; it holds the frame:
    /// overscan): each pixel of the frame keeps its place on the film, the grid's pitch is
    /// unchanged, and the tilt still pivots where the optical axis meets the sensor.
    pub fn extended_to(&self, width: u32, height: u32, [x0, y0, x1, y1]: [i64; 4]) -> Sensor {
        let (pitch_x, pitch_y) = (self.width_mm / width as f64, self.height_mm / height as f64);
        // 1. The same pitch over the larger grid.
        let (w2, h2) = ((x1 - x0) as f64, (y1 - y0) as f64);
        // 2. The grid's centre moves by its offset from the frame's centre (+y frames the top).
        let dx_px = 0.5 * (x0 + x1) as f64 - 0.5 * width as f64;
        let dy_px = 0.5 * (y0 + y1) as f64 - 0.5 * height as f64;
        Sensor {
            width_mm: pitch_x * w2,
            height_mm: pitch_y * h2,
            shift_mm: self.shift_mm + DVec2::new(dx_px * pitch_x, -dy_px * pitch_y),
            ..*self
        }
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

/// A [`Sensor`] with its rotation and normal computed once, for the cameras' per-ray work
/// (the same bits as [`Sensor::film_point`] and [`Sensor::normal`], without their four
/// sines and cosines per call).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PreparedSensor {
    sensor: Sensor,
    rotation: DMat3,
    normal: DVec3,
}

impl PreparedSensor {
    /// Precomputes `sensor`'s rotation and normal.
    pub fn new(sensor: Sensor) -> Self {
        let rotation = sensor.rotation();
        PreparedSensor { sensor, rotation, normal: rotation * DVec3::Z }
    }

    /// The sensor.
    pub fn sensor(&self) -> &Sensor {
        &self.sensor
    }

    /// [`Sensor::normal`].
    #[inline]
    pub fn normal(&self) -> DVec3 {
        self.normal
    }

    /// [`Sensor::film_point`].
    #[inline]
    pub fn film_point(&self, film: DVec2, film_z_mm: f64) -> DVec3 {
        self.sensor.film_point_rotated(&self.rotation, film, film_z_mm)
    }

    /// [`Sensor::film_coord`].
    #[inline]
    pub fn film_coord(&self, p: DVec3, film_z_mm: f64) -> DVec2 {
        self.sensor.film_coord_rotated(&self.rotation, p, film_z_mm)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every pixel of the frame lands on the same film point (within 10⁻¹² mm) on the sensor
    /// extended for overscan, tilted and shifted or not, whichever side the overscan grows.
    #[test]
    fn an_extended_sensor_keeps_the_frame_in_place() {
        let sensors = [
            Sensor::default(),
            Sensor {
                width_mm: 24.0,
                height_mm: 36.0,
                shift_mm: DVec2::new(3.0, -2.0),
                tilt_x_deg: 8.0,
                tilt_y_deg: -5.0,
            },
        ];
        let windows: [[i64; 4]; 3] = [[-10, 0, 40, 20], [0, -7, 55, 31], [-3, -3, 43, 23]];
        for s in sensors {
            for outer in windows {
                let (w, h) = (40u32, 20u32);
                let e = s.extended_to(w, h, outer);
                let [x0, y0, x1, y1] = outer.map(|v| v as f64);
                for (i, j) in [(0.0, 0.0), (39.5, 19.5), (12.25, 7.75), (40.0, 20.0)] {
                    let film = DVec2::new(i / w as f64, j / h as f64);
                    let film_e = DVec2::new((i - x0) / (x1 - x0), (j - y0) / (y1 - y0));
                    let (a, b) = (s.film_point(film, 50.0), e.film_point(film_e, 50.0));
                    assert!((a - b).length() < 1e-12, "{s:?} {outer:?} ({i}, {j}): {a} vs {b}");
                }
                assert_eq!((e.tilt_x_deg, e.tilt_y_deg), (s.tilt_x_deg, s.tilt_y_deg));
            }
        }
    }
}
