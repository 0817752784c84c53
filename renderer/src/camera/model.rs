//! One fixed model of a [`CameraSpec`] → [`Camera`]: the constructor calls shared by the builder
//! and the `auto` chooser, and the process-wide cache of baked LRTF tables.

use super::spec::{CameraSpec, LensModel, SpecLens};
use super::{Camera, ExactCamera, LrtfCamera, OrthographicCamera, PinholeCamera, ThickCamera, ThinCamera};
use crate::error::{Error, Result};
use crate::optics::lens::Lens;
use crate::optics::lrtf::{BakeOptions, LrtfTable};
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

/// The camera of one `model` (not `Auto`) of `spec` with its loaded `lens`; `exact` is the
/// exact camera when already built (its exit-pupil bounds are costly), for the LRTF; `spectral`:
/// the render traces more than one wavelength (the exit-pupil bounds must hold at all of them).
pub(crate) fn build_model(
    spec: &CameraSpec,
    lens: &SpecLens,
    model: LensModel,
    exact: Option<&ExactCamera>,
    spectral: bool,
) -> Result<Camera> {
    let sensor = spec.sensor;
    let focus = spec.focus_distance_m;
    // An orthographic projection has no lens: any ideal lens and model but a real lens's.
    if let Some(m_per_mm) = spec.orthographic_m_per_mm {
        return match (lens, model) {
            (
                SpecLens::Ideal,
                LensModel::Auto | LensModel::Orthographic | LensModel::Exact | LensModel::Thin | LensModel::Pinhole,
            ) => {
                let camera = OrthographicCamera::new(sensor, m_per_mm)?;
                Ok(Camera::Orthographic(match spec.f_number.filter(|_| !spec.is_pinhole()) {
                    Some(n) => camera.with_depth_of_field(n, focus, spec.aperture.clone().unwrap_or_default())?,
                    None => camera,
                }))
            }
            (SpecLens::Ideal, m) => Err(Error::camera(
                "lens_model",
                format!("an orthographic camera has no lens to model as {m}; use auto or orthographic"),
            )),
            (SpecLens::Real(l), _) => Err(Error::camera(
                "lens",
                format!(
                    "an orthographic camera has no lens: '{}' cannot be used with it (use thin or pinhole)",
                    l.name()
                ),
            )),
        };
    }
    match lens {
        SpecLens::Ideal => match (model, spec.is_pinhole()) {
            (LensModel::Pinhole, _) | (LensModel::Exact | LensModel::Thin | LensModel::Auto, true) => {
                Ok(Camera::Pinhole(
                    PinholeCamera::new(sensor, spec.focal_length_mm)?.with_natural_vignetting(spec.natural_vignetting),
                ))
            }
            (LensModel::Exact | LensModel::Thin | LensModel::Auto, false) => {
                let n = spec.f_number.unwrap_or(f64::INFINITY);
                let aperture = spec.aperture.clone().unwrap_or_default();
                let c = ThinCamera::new(sensor, spec.focal_length_mm, n, focus, aperture)?;
                Ok(Camera::Thin(c.with_natural_vignetting(spec.natural_vignetting)))
            }
            (LensModel::Orthographic, _) => {
                Err(Error::camera("lens_model", "the orthographic model needs an orthographic scale"))
            }
            (m, _) => Err(Error::camera(
                "lens_model",
                format!("the {} model needs a real lens (a library name or a lens file), not '{}'", m, spec.lens),
            )),
        },
        SpecLens::Real(lens) => match model {
            LensModel::Orthographic => Err(Error::camera(
                "lens_model",
                format!("an orthographic camera has no lens: '{}' cannot be used with it", lens.name()),
            )),
            LensModel::Exact | LensModel::Auto => {
                Ok(Camera::Exact(ExactCamera::with_bounds_for(sensor, (**lens).clone(), focus, spectral)?))
            }
            LensModel::Lrtf { resolution } => {
                let table = match &spec.lrtf_file {
                    Some(path) => Arc::new(LrtfTable::load(path, lens)?),
                    None => cached_lrtf(lens, resolution)?,
                };
                let exact = match exact {
                    Some(e) => e.clone(),
                    None => ExactCamera::with_bounds_for(sensor, (**lens).clone(), focus, spectral)?,
                };
                Ok(Camera::Lrtf(LrtfCamera::with_exact(exact, table)?))
            }
            LensModel::Thick => {
                Ok(Camera::Thick(ThickCamera::new(sensor, lens, None, focus, lens.aperture().clone())?))
            }
            LensModel::Thin => {
                let p = lens.paraxial();
                Ok(Camera::Thin(ThinCamera::new(sensor, p.efl_mm, p.f_number, focus, lens.aperture().clone())?))
            }
            LensModel::Pinhole => {
                // The pinhole that frames as the lens does at this focus: the thick lens's
                // film distance behind its rear principal plane.
                let thick = ThickCamera::new(sensor, lens, None, focus, lens.aperture().clone())?;
                Ok(Camera::Pinhole(PinholeCamera::new(sensor, thick.film_z_mm() - thick.rear_principal_z_mm())?))
            }
        },
    }
}

type TableKey = (u64, u32);

fn table_cache() -> &'static Mutex<HashMap<TableKey, Arc<LrtfTable>>> {
    static CACHE: OnceLock<Mutex<HashMap<TableKey, Arc<LrtfTable>>>> = OnceLock::new();
    CACHE.get_or_init(|| Mutex::new(HashMap::new()))
}

/// An LRTF table of `lens` at `resolution`, baked once per process (the stop is applied at
/// lookup, so one table serves every f-number and stop shape of the lens). At most a few
/// tables are kept.
pub fn cached_lrtf(lens: &Lens, resolution: u32) -> Result<Arc<LrtfTable>> {
    let key = (crate::optics::lrtf::lens_hash(lens), resolution);
    if let Some(t) = table_cache().lock().map_err(|_| Error::Internal("LRTF cache poisoned".into()))?.get(&key) {
        return Ok(t.clone());
    }
    let table = Arc::new(LrtfTable::bake(lens, &BakeOptions { resolution, ..BakeOptions::default() }, &|_| {})?);
    let mut cache = table_cache().lock().map_err(|_| Error::Internal("LRTF cache poisoned".into()))?;
    if cache.len() >= 8 {
        cache.clear();
    }
    cache.insert(key, table.clone());
    Ok(table)
}
