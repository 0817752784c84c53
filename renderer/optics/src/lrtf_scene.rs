//! The scene → film ray transfer table (for lens-fit: where light from a point source lands on
//! the film). It is the film → scene table ([`LrtfTable`]) of the lens seen from the other
//! side ([`Lens::reversed`]), with coordinates mirrored in z at lookup: a ray of this lens at
//! (x, y, z) heading towards the film is the reversed lens's ray at (x, y, L − z) heading
//! towards its scene, L = [`Lens::last_vertex_z_mm`]. The input dome then stands over the
//! front element, and the direction domain covers the lens's field (its image circle's field
//! angle plus a margin), capped at 89° off the axis by the table's parametrisation.
//!
//! Files are ordinary LRTF files of the reversed lens (the header names "LENS (reversed)" and
//! carries its hash), so a scene → film table is never mistaken for a film → scene one.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `resolution` | u32 | — | 96 |
//! | `field_margin_deg` | f64: directions covered beyond the image circle's field angle | degrees | 5 |

use super::lens::{Lens, Ray};
use super::lrtf::{BakeOptions, LrtfLookup, LrtfTable};
use super::pupil;
use crate::error::Result;
use glam::DVec3;
use std::path::Path;

/// A scene → film table of a lens.
#[derive(Debug, Clone)]
pub struct SceneToFilmTable {
    /// The reversed lens's film → scene table.
    pub table: LrtfTable,
    /// Mirror plane offset L (the lens's last vertex z).
    mirror_z_mm: f64,
    /// The reversed lens (its stop applies at lookup).
    reversed: Lens,
}

impl SceneToFilmTable {
    /// Bakes the table for `lens` at `resolution`, covering directions up to the field angle of
    /// its image circle plus `field_margin_deg`.
    pub fn bake(lens: &Lens, resolution: u32, field_margin_deg: f64, progress: &(dyn Fn(f64) + Sync)) -> Result<Self> {
        let reversed = lens.reversed()?;
        // 1. The field: the steepest incoming direction that reaches the film.
        let film_z = lens.last_vertex_z_mm() + lens.design_back_focus_mm();
        let circle = pupil::image_circle_radius_mm(lens, film_z, 60.0);
        let field_deg = pupil::field_angle_deg(lens, circle * 0.999, 0.0, film_z).unwrap_or(45.0);
        let alpha = (field_deg + field_margin_deg).clamp(1.0, 89.0).to_radians();
        // 2. The reversed lens's "film" is the scene: rays come from at least its back focal
        //    distance and spread over the field.
        let d = (reversed.paraxial().bfl_mm.abs()).max(10.0);
        let options = BakeOptions {
            resolution,
            max_film_radius_mm: d * alpha.tan(),
            min_film_distance_mm: Some(d),
            wavelengths_nm: None,
        };
        let table = LrtfTable::bake(&reversed, &options, progress)?;
        Ok(SceneToFilmTable { table, mirror_z_mm: lens.last_vertex_z_mm(), reversed })
    }

    /// Loads a table saved by [`SceneToFilmTable::save`] and checks it belongs to `lens`.
    pub fn load(path: &Path, lens: &Lens) -> Result<Self> {
        let reversed = lens.reversed()?;
        let table = LrtfTable::load(path, &reversed)?;
        Ok(SceneToFilmTable { table, mirror_z_mm: lens.last_vertex_z_mm(), reversed })
    }

    /// Saves the table.
    pub fn save(&self, path: &Path) -> Result<()> {
        self.table.save(path)
    }

    fn mirror(&self, r: &Ray) -> Ray {
        Ray {
            origin: DVec3::new(r.origin.x, r.origin.y, self.mirror_z_mm - r.origin.z),
            direction: DVec3::new(r.direction.x, r.direction.y, -r.direction.z),
        }
    }

    /// Looks up a ray arriving from the scene (in this lens's coordinates, heading towards +z):
    /// the ray leaving the rear element towards the film, with the stop crossing and margin.
    /// The stop is not applied (see [`SceneToFilmTable::trace`]).
    pub fn lookup(&self, ray: &Ray, wavelength_nm: f64) -> LrtfLookup {
        match self.table.lookup(&self.mirror(ray), wavelength_nm) {
            LrtfLookup::Hit(mut h) => {
                h.ray = self.mirror(&h.ray);
                LrtfLookup::Hit(h)
            }
            other => other,
        }
    }

    /// The ray towards the film and its stop transmission, with the lens's stop (size and
    /// shape of `lens`, which may differ from the baked one) applied; uncertain cells are
    /// traced exactly. `None` when the lens blocks the ray.
    pub fn trace(&self, lens: &Lens, ray: &Ray, wavelength_nm: f64) -> Option<(Ray, f64)> {
        match self.lookup(ray, wavelength_nm) {
            LrtfLookup::Hit(h) => {
                let t = lens.aperture().transmission(h.stop_point.x, h.stop_point.y, lens.stop_semi_diameter_mm());
                (t > 0.0).then_some((h.ray, t))
            }
            LrtfLookup::Miss => None,
            LrtfLookup::Uncertain => lens
                .trace(ray, wavelength_nm, super::lens::TraceDirection::SceneToFilm)
                .map(|t| (t.ray, t.transmission)),
        }
    }

    /// The reversed lens the table was baked for.
    pub fn reversed_lens(&self) -> &Lens {
        &self.reversed
    }
}
