//! The LRTF model: a real lens evaluated through its baked ray transfer table
//! ([`LrtfTable`], film → scene); rays in cells that straddle a vignetting boundary are traced
//! exactly. The film position, pupil bounds and exposure are those of the [`ExactCamera`] of
//! the same lens.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `exact` | [`ExactCamera`]: sensor, lens, focus | — | — |
//! | `table` | [`LrtfTable`] baked for the lens, covering the sensor | — | baked at 96 on demand |

use super::{CameraRay, ExactCamera, Sensor, CAMERA_BATCH};
use crate::error::{Error, Result};
use crate::optics::lens::{Lens, Ray, TraceDirection};
use crate::optics::lrtf::{LrtfLookup, LrtfTable};
use glam::DVec2;
use std::sync::Arc;

/// A real lens evaluated through its ray transfer table (see the module docs).
#[derive(Debug, Clone)]
pub struct LrtfCamera {
    exact: ExactCamera,
    table: Arc<LrtfTable>,
}

impl LrtfCamera {
    /// A camera through `table`, which must have been baked for `lens` and cover the sensor.
    pub fn new(sensor: Sensor, lens: Lens, focus_distance_m: Option<f64>, table: Arc<LrtfTable>) -> Result<Self> {
        Self::with_exact(ExactCamera::new(sensor, lens, focus_distance_m)?, table)
    }

    /// A camera through `table` for an exact camera already built (its pupil bounds and
    /// exposure are reused).
    pub fn with_exact(exact: ExactCamera, table: Arc<LrtfTable>) -> Result<Self> {
        Self::check_coverage(&table, exact.sensor(), exact.film_z_mm())?;
        Ok(LrtfCamera { exact, table })
    }

    /// The table covers the sensor with its film pivot at `film_z_mm`.
    pub(super) fn check_coverage(table: &LrtfTable, sensor: &Sensor, film_z_mm: f64) -> Result<()> {
        let h = &table.header;
        let (r, dz) = sensor.extent();
        if r > h.max_film_radius_mm {
            return Err(Error::camera(
                "lens_model",
                format!("the LRTF table covers film points up to {:.1} mm from the axis; this sensor reaches {r:.1} mm: re-bake with a larger --max-film-radius", h.max_film_radius_mm),
            ));
        }
        if film_z_mm - dz - h.in_base_z_mm < h.min_film_distance_mm - 1e-9 {
            return Err(Error::camera(
                "lens_model",
                "the sensor comes closer to the lens than the LRTF table covers: re-bake it",
            ));
        }
        Ok(())
    }

    /// The same camera traced exactly (sensor, lens, focus, pupil bounds, exposure).
    pub fn exact(&self) -> &ExactCamera {
        &self.exact
    }

    /// This camera without the exact model's defensive pupil disc
    /// ([`ExactCamera::without_defensive_disc`]).
    pub fn without_defensive_disc(&self) -> LrtfCamera {
        LrtfCamera { exact: self.exact.without_defensive_disc(), table: self.table.clone() }
    }

    /// The table.
    pub fn table(&self) -> &Arc<LrtfTable> {
        &self.table
    }

    fn raw_ray(&self, film: DVec2, lens_u: DVec2, wavelength_nm: f64) -> Option<CameraRay> {
        let lens = self.exact.lens();
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

    pub(super) fn generate_ray(&self, film: DVec2, lens_u: DVec2, wavelength_nm: f64) -> Option<CameraRay> {
        self.raw_ray(film, lens_u, wavelength_nm).map(|r| CameraRay { weight: r.weight * self.exact.exposure(), ..r })
    }

    /// [`LrtfCamera::generate_ray`] of [`CAMERA_BATCH`] samples through one batched table
    /// lookup ([`LrtfTable::lookup_batch`]): the same rays, bit for bit.
    pub(super) fn generate_ray_batch(
        &self,
        film: &[DVec2; CAMERA_BATCH],
        lens_u: &[DVec2; CAMERA_BATCH],
        wavelength_nm: &[f64; CAMERA_BATCH],
    ) -> [Option<CameraRay>; CAMERA_BATCH] {
        let lens = self.exact.lens();
        // 1. Film rays (a lane whose pupil sample is not drawn looks up a stand-in ray).
        let film_rays: [Option<(Ray, f64)>; CAMERA_BATCH] =
            std::array::from_fn(|i| self.exact.film_ray(film[i], lens_u[i]));
        let Some(stand_in) = film_rays.iter().flatten().next().map(|(r, _)| *r) else {
            return [None; CAMERA_BATCH];
        };
        let rays: [Ray; CAMERA_BATCH] = std::array::from_fn(|i| film_rays[i].map_or(stand_in, |(r, _)| r));
        // 2. Through the table, every lane at once; uncertain lanes traced exactly.
        let found = self.table.lookup_batch(&rays, wavelength_nm);
        std::array::from_fn(|i| {
            let (ray, geometric) = film_rays[i]?;
            let (out, transmission) = match found[i] {
                LrtfLookup::Hit(hit) => {
                    let tr =
                        lens.aperture().transmission(hit.stop_point.x, hit.stop_point.y, lens.stop_semi_diameter_mm());
                    (tr > 0.0).then_some((hit.ray, tr))?
                }
                LrtfLookup::Miss => return None,
                LrtfLookup::Uncertain => {
                    let t = lens.trace(&ray, wavelength_nm[i], TraceDirection::FilmToScene)?;
                    (t.ray, t.transmission)
                }
            };
            // 3. In camera space, with the exposure.
            let r = self.exact.leaving_ray(out, geometric, transmission);
            Some(CameraRay { weight: r.weight * self.exact.exposure(), ..r })
        })
    }
}
