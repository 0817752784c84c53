//! `petzval.Lens` and the library listing.

use glam::DVec3;
use numpy::ndarray::Array2;
use numpy::{AllowTypeChange, IntoPyArray, PyArrayLike2};
use petzval_renderer::{Lens, Ray, TraceDirection, LIBRARY};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::errors::*;

/// The lens library: name, description, focal length, f-number, source.
#[pyfunction]
pub(crate) fn library_lenses(py: Python<'_>) -> PyResult<Py<PyList>> {
    guard(|| {
        let out = PyList::empty(py);
        let mut entries: Vec<_> = LIBRARY.iter().collect();
        entries.sort_by_key(|e| e.name);
        for e in entries {
            let lens = petzval_renderer::library_lens(e.name).map_err(py_err)?;
            let d = PyDict::new(py);
            d.set_item("name", e.name)?;
            // The source's first clause names the design ("D-GAUSS F/2 22deg HFOV", a patent).
            let source = &lens.prescription().lens.source;
            let description = source.split(';').next().map(str::trim).filter(|d| !d.is_empty()).unwrap_or(lens.name());
            d.set_item("description", description)?;
            d.set_item("focal_length_mm", lens.paraxial().efl_mm)?;
            d.set_item("f_number", lens.paraxial().f_number)?;
            d.set_item("source", lens.prescription().lens.source.clone())?;
            out.append(d)?;
        }
        Ok(out.unbind())
    })
}

/// A lens: a library name or a lens file.
#[pyclass(name = "Lens", module = "petzval._native", frozen)]
pub(crate) struct PyLens {
    lens: Lens,
}

#[pymethods]
impl PyLens {
    #[new]
    fn new(name_or_path: &str) -> PyResult<Self> {
        guard(|| Ok(PyLens { lens: petzval_renderer::load_lens(name_or_path).map_err(py_err)? }))
    }

    /// The lens's name.
    #[getter]
    fn name(&self) -> String {
        self.lens.name().to_string()
    }

    /// Effective focal length (mm).
    #[getter]
    fn focal_length_mm(&self) -> f64 {
        self.lens.paraxial().efl_mm
    }

    /// f-number (infinity focus).
    #[getter]
    fn f_number(&self) -> f64 {
        self.lens.paraxial().f_number
    }

    /// First-order data as `petzval lens info --json` prints it.
    fn info(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        guard(|| {
            let v = petzval_renderer::optics::info::lens_info(&self.lens, None, None, (36.0, 24.0)).map_err(py_err)?;
            let text = serde_json::to_string(&v).map_err(|e| PetzvalError::new_err(e.to_string()))?;
            Ok(py.import("json")?.call_method1("loads", (text,))?.unbind())
        })
    }

    /// Traces rays through every surface (see the stub).
    #[pyo3(signature = (origins, directions, wavelength_nm = 587.5618, direction = "film_to_scene"))]
    fn trace<'py>(
        &self,
        py: Python<'py>,
        origins: PyArrayLike2<'py, f64, AllowTypeChange>,
        directions: PyArrayLike2<'py, f64, AllowTypeChange>,
        wavelength_nm: f64,
        direction: &str,
    ) -> PyResult<(Py<PyAny>, Py<PyAny>, Py<PyAny>)> {
        guard(|| {
            let dir = match direction {
                "film_to_scene" => TraceDirection::FilmToScene,
                "scene_to_film" => TraceDirection::SceneToFilm,
                d => {
                    return Err(settings_err(
                        "direction",
                        format!("expected 'film_to_scene' or 'scene_to_film', got '{d}'"),
                    ))
                }
            };
            if !(wavelength_nm.is_finite() && (300.0..=1100.0).contains(&wavelength_nm)) {
                return Err(settings_err("wavelength_nm", format!("{wavelength_nm} is outside 300–1100 nm")));
            }
            let (o, d) = (origins.as_array(), directions.as_array());
            if o.ncols() != 3 || d.ncols() != 3 || o.nrows() != d.nrows() {
                return Err(settings_err(
                    "origins/directions",
                    format!("expected two (N, 3) arrays of the same N, got {:?} and {:?}", o.shape(), d.shape()),
                ));
            }
            let n = o.nrows();
            let rays: Vec<(DVec3, DVec3)> = (0..n)
                .map(|i| (DVec3::new(o[[i, 0]], o[[i, 1]], o[[i, 2]]), DVec3::new(d[[i, 0]], d[[i, 1]], d[[i, 2]])))
                .collect();
            let lens = &self.lens;
            let out: Vec<Option<Ray>> = py.detach(|| {
                use rayon::prelude::*;
                rays.par_iter()
                    .map(|(o, d)| {
                        if !(o.is_finite() && d.is_finite() && d.length_squared() > 0.0) {
                            return None;
                        }
                        lens.trace(&Ray::new(*o, d.normalize()), wavelength_nm, dir).map(|t| t.ray)
                    })
                    .collect()
            });
            let mut po = Array2::<f64>::from_elem((n, 3), f64::NAN);
            let mut pd = Array2::<f64>::from_elem((n, 3), f64::NAN);
            let mut ok = numpy::ndarray::Array1::<bool>::from_elem(n, false);
            for (i, r) in out.iter().enumerate() {
                if let Some(r) = r {
                    for k in 0..3 {
                        po[[i, k]] = r.origin[k];
                        pd[[i, k]] = r.direction[k];
                    }
                    ok[i] = true;
                }
            }
            Ok((
                po.into_pyarray(py).into_any().unbind(),
                pd.into_pyarray(py).into_any().unbind(),
                ok.into_pyarray(py).into_any().unbind(),
            ))
        })
    }

    fn __repr__(&self) -> String {
        format!(
            "Lens('{}', f={:.2} mm, f/{:.2})",
            self.lens.name(),
            self.lens.paraxial().efl_mm,
            self.lens.paraxial().f_number
        )
    }
}

// ---------------------------------------------------------------------------------------------
// Scenes
