//! `petzval._native`: Petzval's Python module (pyo3) — lenses, scenes built from numpy buffers,
//! and rendering with a progress callback. The only crate that depends on pyo3 and the only
//! place where the renderer's errors become Python exceptions. No Rust panic crosses into
//! Python: every entry point runs under [`guard`], which turns a panic into `PetzvalError`.
//!
//! The API, its conventions (glTF axes, top-row-first images, glTF UVs) and the meaning of
//! every argument are documented in `python/petzval/_native.pyi`.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `render(..., lens)` | `"thin"`, `"pinhole"`, library name or lens file | — | `"thin"` |
//! | `render(..., lens_model)` | auto, exact, lrtf[:RES], thick, thin, pinhole | — | auto |
//! | `render(..., tolerance_px)` | f64 | px | 0.25 |
//! | `render(..., focal_length_mm)` | f64 (thin, pinhole) | mm | 50 |
//! | `render(..., sensor_width_mm, sensor_height_mm)` | f64 | mm | 36, 24 |
//! | `render(..., shift_x, shift_y)` | f64, Blender's (fraction of the fitted sensor side) | — | 0 |
//! | `render(..., tilt_x_deg, tilt_y_deg)` | f64 | degrees | 0 |
//! | `render(..., fstop)` | optional f64 (None: pinhole for thin, wide open for real) | — | None |
//! | `render(..., focus_distance_m)` | optional f64 (None = infinity) | m | None |
//! | `render(..., spp, seed, max_depth)` | u32 | — | 64, 0, 8 |
//! | `render(..., filter_width_px)` | f32, Cycles' filter_width | px | 1.5 |
//! | `render(..., progress_interval_s)` | f64 | s | 0.1 |

// `!(x > 0.0)` is our NaN-rejecting validation: unlike `x <= 0.0` it is also true for NaN, which
// is exactly what every such check wants (a NaN setting or sample must be refused).
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use glam::{DAffine3, DMat3, DMat4, DVec2, DVec3, DVec4, Vec2, Vec3, Vec4};
use numpy::ndarray::{Array2, Array3};
use numpy::{AllowTypeChange, IntoPyArray, PyArrayLike1, PyArrayLike2, PyArrayLike3};
use petzval_renderer::film::{Image, PixelFilter};
use petzval_renderer::integrator::RenderScene;
use petzval_renderer::render::{render_observed, CameraRig, RenderResult, RenderSettings};
use petzval_renderer::scene::environment::EnvironmentMap;
use petzval_renderer::scene::texture::Wrap;
use petzval_renderer::scene::{AlphaMode, Environment, Light, Material, Mesh, Texture, TextureRef};
use petzval_renderer::{
    Aperture, ApertureMask, ApertureShape, CameraSpec, Error, Lens, LensModel, Ray, Sensor, TraceDirection, LIBRARY,
};
use pyo3::exceptions::{PyException, PyFileNotFoundError, PyOSError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

pyo3::create_exception!(_native, PetzvalError, PyException, "Base class of every Petzval error.");
pyo3::create_exception!(_native, InvalidLensError, PetzvalError, "A lens file or lens name is invalid.");
pyo3::create_exception!(_native, InvalidSceneError, PetzvalError, "Scene data is invalid.");
pyo3::create_exception!(_native, InvalidSettingsError, PetzvalError, "Camera or render settings are invalid.");
pyo3::create_exception!(_native, CancelledError, PetzvalError, "The render was cancelled before a pass finished.");

/// Maps the renderer's errors to Python exceptions.
fn py_err(e: impl Into<Error>) -> PyErr {
    use petzval_renderer::optics::Error as OpticsError;
    let e = e.into();
    let msg = e.to_string();
    match e {
        Error::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound => PyFileNotFoundError::new_err(msg),
        Error::Io { .. } => PyOSError::new_err(msg),
        Error::Optics(OpticsError::UnknownLens(_)) => PyFileNotFoundError::new_err(msg),
        Error::Optics(OpticsError::Io { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => {
            PyFileNotFoundError::new_err(msg)
        }
        Error::Optics(OpticsError::Io { .. }) => PyOSError::new_err(msg),
        Error::Optics(OpticsError::ApertureImage { .. }) => InvalidSettingsError::new_err(msg),
        Error::Optics(_) => InvalidLensError::new_err(msg),
        Error::Camera { .. } | Error::Settings { .. } => InvalidSettingsError::new_err(msg),
        Error::Scene { .. } => InvalidSceneError::new_err(msg),
        Error::Metrics(_) | Error::Internal(_) => PetzvalError::new_err(msg),
    }
}

fn panic_message(p: Box<dyn std::any::Any + Send>) -> String {
    p.downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".into())
}

/// Runs `f`, turning a Rust panic into `PetzvalError` (no panic crosses into Python).
fn guard<T>(f: impl FnOnce() -> PyResult<T>) -> PyResult<T> {
    catch_unwind(AssertUnwindSafe(f))
        .unwrap_or_else(|p| Err(PetzvalError::new_err(format!("internal error (please report): {}", panic_message(p)))))
}

fn scene_err(name: &str, field: &str, message: String) -> PyErr {
    InvalidSceneError::new_err(format!(
        "{}{field}: {message}",
        if name.is_empty() { String::new() } else { format!("'{name}': ") }
    ))
}

fn settings_err(field: &str, message: String) -> PyErr {
    InvalidSettingsError::new_err(format!("{field}: {message}"))
}

fn vec3_arg(name: &str, field: &str, v: &[f64]) -> PyResult<Vec3> {
    match v {
        [a, b, c] if a.is_finite() && b.is_finite() && c.is_finite() => Ok(Vec3::new(*a as f32, *b as f32, *c as f32)),
        _ => Err(scene_err(name, field, format!("expected 3 finite numbers, got {v:?}"))),
    }
}

fn non_negative_rgb(name: &str, field: &str, v: &[f64]) -> PyResult<Vec3> {
    let c = vec3_arg(name, field, v)?;
    if c.min_element() < 0.0 {
        return Err(scene_err(name, field, format!("must be non-negative, got {v:?}")));
    }
    Ok(c)
}

/// A 4×4 object-to-world matrix (rows as Blender prints them, column vectors) as an affine map.
fn affine_from_rows(name: &str, field: &str, m: &numpy::ndarray::ArrayView2<'_, f64>) -> PyResult<DAffine3> {
    if m.shape() != [4, 4] {
        return Err(scene_err(name, field, format!("expected a (4, 4) matrix, got {:?}", m.shape())));
    }
    if m.iter().any(|v| !v.is_finite()) {
        return Err(scene_err(name, field, "has non-finite entries".into()));
    }
    let col = |c: usize| DVec4::new(m[[0, c]], m[[1, c]], m[[2, c]], m[[3, c]]);
    let mat = DMat4::from_cols(col(0), col(1), col(2), col(3));
    if (mat.row(3) - DVec4::new(0.0, 0.0, 0.0, 1.0)).abs().max_element() > 1e-9 {
        return Err(scene_err(name, field, "is projective (last row is not 0 0 0 1)".into()));
    }
    let a = DAffine3::from_mat4(mat);
    if !(a.matrix3.determinant().abs() > 1e-18) {
        return Err(scene_err(name, field, "is singular".into()));
    }
    Ok(a)
}

// ---------------------------------------------------------------------------------------------
// Lenses

/// The lens library: name, description, focal length, f-number, source.
#[pyfunction]
fn library_lenses(py: Python<'_>) -> PyResult<Py<PyList>> {
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
struct PyLens {
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

/// A scene assembled from buffers.
#[pyclass(name = "Scene", module = "petzval._native")]
struct PyScene {
    scene: petzval_renderer::scene::Scene,
    /// Every mesh so far came with tangents (else tangents are derived from UVs for all).
    all_tangents: bool,
}

fn parse_alpha_mode(mode: &str, cutoff: f64) -> PyResult<AlphaMode> {
    Ok(match mode {
        "opaque" => AlphaMode::Opaque,
        "blend" => AlphaMode::Blend,
        "mask" => AlphaMode::Mask(cutoff as f32),
        m => {
            return Err(InvalidSceneError::new_err(format!(
                "alpha_mode: expected 'opaque', 'blend' or 'mask', got '{m}'"
            )))
        }
    })
}

impl PyScene {
    fn texture_ref(&self, name: &str, field: &str, index: Option<usize>) -> PyResult<Option<TextureRef>> {
        match index {
            None => Ok(None),
            Some(i) if i < self.scene.textures.len() => Ok(Some(TextureRef { index: i, uv_set: 0 })),
            Some(i) => Err(scene_err(
                name,
                field,
                format!("texture {i} does not exist ({} textures)", self.scene.textures.len()),
            )),
        }
    }
}

#[pymethods]
impl PyScene {
    #[new]
    fn new() -> Self {
        PyScene { scene: petzval_renderer::scene::Scene::default(), all_tangents: true }
    }

    /// Adds a texture from (H, W, 4|3) linear values, row 0 at the top.
    #[pyo3(signature = (pixels, name = "", interpolation = "linear", extension = "repeat"))]
    fn add_texture(
        &mut self,
        pixels: PyArrayLike3<'_, f32, AllowTypeChange>,
        name: &str,
        interpolation: &str,
        extension: &str,
    ) -> PyResult<usize> {
        guard(|| {
            let a = pixels.as_array();
            let (h, w, c) = a.dim();
            if h == 0 || w == 0 || !(c == 3 || c == 4) {
                return Err(scene_err(name, "pixels", format!("expected an (H, W, 3|4) image, got {:?}", a.shape())));
            }
            let bilinear = match interpolation {
                "linear" | "cubic" | "smart" => true,
                "closest" => false,
                i => {
                    return Err(scene_err(name, "interpolation", format!("expected 'linear' or 'closest', got '{i}'")))
                }
            };
            let wrap = match extension {
                "repeat" => Wrap::Repeat,
                "clip" | "extend" => Wrap::ClampToEdge,
                "mirror" => Wrap::MirroredRepeat,
                e => {
                    return Err(scene_err(
                        name,
                        "extension",
                        format!("expected 'repeat', 'clip' or 'mirror', got '{e}'"),
                    ))
                }
            };
            let mut texels = Vec::with_capacity(h * w);
            for y in 0..h {
                for x in 0..w {
                    let g = |k: usize| {
                        let v = a[[y, x, k]];
                        if v.is_finite() {
                            v
                        } else {
                            0.0
                        }
                    };
                    texels.push(Vec4::new(g(0), g(1), g(2), if c == 4 { g(3) } else { 1.0 }));
                }
            }
            self.scene.textures.push(Arc::new(Texture {
                name: name.to_string(),
                width: w as u32,
                height: h as u32,
                texels,
                wrap_s: wrap,
                wrap_t: wrap,
                bilinear,
            }));
            Ok(self.scene.textures.len() - 1)
        })
    }

    /// Adds a glTF metallic-roughness material; returns its index.
    #[pyo3(signature = (name, base_color = vec![0.8, 0.8, 0.8, 1.0], metallic = 0.0, roughness = 0.5, ior = 1.5, specular = 1.0, emission = vec![0.0, 0.0, 0.0], alpha_mode = "opaque", alpha_cutoff = 0.5, base_color_texture = None, metallic_roughness_texture = None, normal_texture = None, normal_scale = 1.0, emission_texture = None, double_sided = true))]
    #[allow(clippy::too_many_arguments)]
    fn add_material(
        &mut self,
        name: &str,
        base_color: Vec<f64>,
        metallic: f64,
        roughness: f64,
        ior: f64,
        specular: f64,
        emission: Vec<f64>,
        alpha_mode: &str,
        alpha_cutoff: f64,
        base_color_texture: Option<usize>,
        metallic_roughness_texture: Option<usize>,
        normal_texture: Option<usize>,
        normal_scale: f64,
        emission_texture: Option<usize>,
        double_sided: bool,
    ) -> PyResult<usize> {
        guard(|| {
            let bc = match base_color.as_slice() {
                [r, g, b] => Vec4::new(*r as f32, *g as f32, *b as f32, 1.0),
                [r, g, b, a] => Vec4::new(*r as f32, *g as f32, *b as f32, *a as f32),
                v => return Err(scene_err(name, "base_color", format!("expected 3 or 4 numbers, got {v:?}"))),
            };
            if !bc.is_finite() || bc.min_element() < 0.0 {
                return Err(scene_err(
                    name,
                    "base_color",
                    format!("must be finite and non-negative, got {base_color:?}"),
                ));
            }
            for (field, v, lo, hi) in [
                ("metallic", metallic, 0.0, 1.0),
                ("roughness", roughness, 0.0, 1.0),
                ("ior", ior, 1.0, 10.0),
                ("specular", specular, 0.0, 100.0),
                ("normal_scale", normal_scale, -100.0, 100.0),
                ("alpha_cutoff", alpha_cutoff, 0.0, 1.0),
            ] {
                if !(v.is_finite() && v >= lo && v <= hi) {
                    return Err(scene_err(name, field, format!("{v} is outside [{lo}, {hi}]")));
                }
            }
            let m = Material {
                name: name.to_string(),
                base_color: bc,
                base_color_texture: self.texture_ref(name, "base_color_texture", base_color_texture)?,
                metallic: metallic as f32,
                roughness: roughness as f32,
                metallic_roughness_texture: self.texture_ref(
                    name,
                    "metallic_roughness_texture",
                    metallic_roughness_texture,
                )?,
                normal_texture: self.texture_ref(name, "normal_texture", normal_texture)?,
                normal_scale: normal_scale as f32,
                emissive: non_negative_rgb(name, "emission", &emission)?,
                emissive_texture: self.texture_ref(name, "emission_texture", emission_texture)?,
                specular: specular as f32,
                ior: ior as f32,
                alpha_mode: parse_alpha_mode(alpha_mode, alpha_cutoff)
                    .map_err(|e| scene_err(name, "", e.to_string()))?,
                double_sided,
            };
            self.scene.materials.push(m);
            Ok(self.scene.materials.len() - 1)
        })
    }

    /// Adds a triangle mesh (see the stub).
    #[pyo3(signature = (positions, triangles, material_ids = None, normals = None, uvs = None, tangents = None, transform = None, name = ""))]
    #[allow(clippy::too_many_arguments)]
    fn add_mesh(
        &mut self,
        positions: PyArrayLike2<'_, f32, AllowTypeChange>,
        triangles: PyArrayLike2<'_, i64, AllowTypeChange>,
        material_ids: Option<PyArrayLike1<'_, i64, AllowTypeChange>>,
        normals: Option<PyArrayLike2<'_, f32, AllowTypeChange>>,
        uvs: Option<PyArrayLike2<'_, f32, AllowTypeChange>>,
        tangents: Option<PyArrayLike2<'_, f32, AllowTypeChange>>,
        transform: Option<PyArrayLike2<'_, f64, AllowTypeChange>>,
        name: &str,
    ) -> PyResult<()> {
        guard(|| {
            // 1. Shapes and values.
            let p = positions.as_array();
            let t = triangles.as_array();
            if p.ncols() != 3 {
                return Err(scene_err(name, "positions", format!("expected (N, 3), got {:?}", p.shape())));
            }
            if t.ncols() != 3 {
                return Err(scene_err(name, "triangles", format!("expected (M, 3), got {:?}", t.shape())));
            }
            let (nv, nt) = (p.nrows(), t.nrows());
            if p.iter().any(|v| !v.is_finite()) {
                return Err(scene_err(name, "positions", "contain non-finite values".into()));
            }
            if let Some(bad) = t.iter().find(|&&i| i < 0 || i as usize >= nv) {
                return Err(scene_err(name, "triangles", format!("index {bad} is outside 0..{nv}")));
            }
            let xf = match &transform {
                Some(m) => affine_from_rows(name, "transform", &m.as_array())?,
                None => DAffine3::IDENTITY,
            };
            let normal_xf: DMat3 = xf.matrix3.inverse().transpose();
            let flip = xf.matrix3.determinant() < 0.0;
            // 2. World-space attributes.
            let mut mesh = Mesh::default();
            mesh.positions = (0..nv)
                .map(|i| {
                    xf.transform_point3(DVec3::new(p[[i, 0]] as f64, p[[i, 1]] as f64, p[[i, 2]] as f64)).as_vec3()
                })
                .collect();
            mesh.indices = (0..nt)
                .map(|i| {
                    let tri = [t[[i, 0]] as u32, t[[i, 1]] as u32, t[[i, 2]] as u32];
                    // A mirroring transform turns the winding; keep faces facing outwards.
                    if flip {
                        [tri[0], tri[2], tri[1]]
                    } else {
                        tri
                    }
                })
                .collect();
            mesh.material_ids = match &material_ids {
                Some(m) => {
                    let m = m.as_array();
                    if m.len() != nt {
                        return Err(scene_err(name, "material_ids", format!("{} ids for {nt} triangles", m.len())));
                    }
                    if let Some(bad) = m.iter().find(|&&i| i < 0 || i as usize >= self.scene.materials.len().max(1)) {
                        return Err(scene_err(
                            name,
                            "material_ids",
                            format!("material {bad} does not exist ({} materials)", self.scene.materials.len()),
                        ));
                    }
                    m.iter().map(|&i| i as u32).collect()
                }
                None => vec![0; nt],
            };
            mesh.normals = match &normals {
                Some(n) => {
                    let n = n.as_array();
                    if n.shape() != [nv, 3] {
                        return Err(scene_err(name, "normals", format!("expected ({nv}, 3), got {:?}", n.shape())));
                    }
                    (0..nv)
                        .map(|i| {
                            let v = normal_xf * DVec3::new(n[[i, 0]] as f64, n[[i, 1]] as f64, n[[i, 2]] as f64);
                            v.normalize_or_zero().as_vec3()
                        })
                        .collect()
                }
                None => face_normals(&mesh.positions, &mesh.indices),
            };
            if mesh.normals.iter().any(|n| !n.is_finite()) {
                return Err(scene_err(name, "normals", "contain non-finite values".into()));
            }
            mesh.uv0 = match &uvs {
                Some(u) => {
                    let u = u.as_array();
                    if u.shape() != [nv, 2] {
                        return Err(scene_err(name, "uvs", format!("expected ({nv}, 2), got {:?}", u.shape())));
                    }
                    (0..nv)
                        .map(|i| Vec2::new(u[[i, 0]], u[[i, 1]]))
                        .map(|v| if v.is_finite() { v } else { Vec2::ZERO })
                        .collect()
                }
                None => vec![Vec2::ZERO; nv],
            };
            match &tangents {
                Some(tg) => {
                    let tg = tg.as_array();
                    if tg.shape() != [nv, 4] {
                        return Err(scene_err(name, "tangents", format!("expected ({nv}, 4), got {:?}", tg.shape())));
                    }
                    mesh.tangents = (0..nv)
                        .map(|i| {
                            let v = (xf.matrix3 * DVec3::new(tg[[i, 0]] as f64, tg[[i, 1]] as f64, tg[[i, 2]] as f64))
                                .normalize_or_zero()
                                .as_vec3();
                            let w = if flip { -tg[[i, 3]] } else { tg[[i, 3]] };
                            Vec4::new(v.x, v.y, v.z, if w < 0.0 { -1.0 } else { 1.0 })
                        })
                        .collect();
                }
                None => {
                    self.all_tangents = false;
                    mesh.tangents = vec![Vec4::ZERO; nv];
                }
            }
            self.scene.mesh.append(&mesh, 0);
            Ok(())
        })
    }

    /// A point light (W/sr per channel).
    #[pyo3(signature = (position, intensity_w_sr, name = ""))]
    fn add_point_light(&mut self, position: Vec<f64>, intensity_w_sr: Vec<f64>, name: &str) -> PyResult<()> {
        guard(|| {
            let light = Light::Point {
                position: vec3_arg(name, "position", &position)?,
                intensity: non_negative_rgb(name, "intensity_w_sr", &intensity_w_sr)?,
                range: None,
            };
            self.scene.lights.push(light);
            Ok(())
        })
    }

    /// A spot light.
    #[pyo3(signature = (position, direction, intensity_w_sr, inner_cone_rad, outer_cone_rad, name = ""))]
    fn add_spot_light(
        &mut self,
        position: Vec<f64>,
        direction: Vec<f64>,
        intensity_w_sr: Vec<f64>,
        inner_cone_rad: f64,
        outer_cone_rad: f64,
        name: &str,
    ) -> PyResult<()> {
        guard(|| {
            let d = vec3_arg(name, "direction", &direction)?.normalize_or_zero();
            if d == Vec3::ZERO {
                return Err(scene_err(name, "direction", "must not be zero".into()));
            }
            if !(outer_cone_rad > 0.0
                && outer_cone_rad <= std::f64::consts::PI
                && inner_cone_rad >= 0.0
                && inner_cone_rad <= outer_cone_rad)
            {
                return Err(scene_err(
                    name,
                    "cone",
                    format!("need 0 ≤ inner ({inner_cone_rad}) ≤ outer ({outer_cone_rad}) ≤ π"),
                ));
            }
            self.scene.lights.push(Light::Spot {
                position: vec3_arg(name, "position", &position)?,
                direction: d,
                intensity: non_negative_rgb(name, "intensity_w_sr", &intensity_w_sr)?,
                inner_cone_rad: inner_cone_rad as f32,
                outer_cone_rad: outer_cone_rad as f32,
                range: None,
            });
            Ok(())
        })
    }

    /// A directional light.
    #[pyo3(signature = (direction, irradiance_w_m2, name = ""))]
    fn add_sun_light(&mut self, direction: Vec<f64>, irradiance_w_m2: Vec<f64>, name: &str) -> PyResult<()> {
        guard(|| {
            let d = vec3_arg(name, "direction", &direction)?.normalize_or_zero();
            if d == Vec3::ZERO {
                return Err(scene_err(name, "direction", "must not be zero".into()));
            }
            self.scene.lights.push(Light::Directional {
                direction: d,
                irradiance: non_negative_rgb(name, "irradiance_w_m2", &irradiance_w_m2)?,
            });
            Ok(())
        })
    }

    /// A uniform environment.
    fn set_environment_color(&mut self, rgb: Vec<f64>) -> PyResult<()> {
        guard(|| {
            let c = non_negative_rgb("world", "rgb", &rgb)?;
            self.scene.environment = if c == Vec3::ZERO { Environment::Black } else { Environment::Constant(c) };
            Ok(())
        })
    }

    /// An equirectangular environment, row 0 at the top.
    #[pyo3(signature = (pixels, strength = 1.0, rotation_rad = 0.0, name = ""))]
    fn set_environment_map(
        &mut self,
        pixels: PyArrayLike3<'_, f32, AllowTypeChange>,
        strength: f64,
        rotation_rad: f64,
        name: &str,
    ) -> PyResult<()> {
        guard(|| {
            let a = pixels.as_array();
            let (h, w, c) = a.dim();
            if h == 0 || w == 0 || c < 3 {
                return Err(scene_err(name, "pixels", format!("expected an (H, W, 3|4) image, got {:?}", a.shape())));
            }
            let texels: Vec<Vec3> = (0..h)
                .flat_map(|y| (0..w).map(move |x| (y, x)))
                .map(|(y, x)| Vec3::new(a[[y, x, 0]], a[[y, x, 1]], a[[y, x, 2]]))
                .collect();
            let label = if name.is_empty() { "environment" } else { name };
            let map = EnvironmentMap::new(label, w, h, texels, strength as f32, rotation_rad as f32).map_err(py_err)?;
            self.scene.environment = Environment::Map(map);
            Ok(())
        })
    }

    /// Triangles so far.
    #[getter]
    fn triangle_count(&self) -> usize {
        self.scene.mesh.triangle_count()
    }

    /// Warnings so far.
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.scene.warnings.clone()
    }
}

/// Area-weighted vertex normals (unit; +z where a vertex has no area around it).
fn face_normals(positions: &[Vec3], indices: &[[u32; 3]]) -> Vec<Vec3> {
    let mut n = vec![Vec3::ZERO; positions.len()];
    for t in indices {
        let (a, b, c) = (positions[t[0] as usize], positions[t[1] as usize], positions[t[2] as usize]);
        let f = (b - a).cross(c - a);
        for &i in t {
            n[i as usize] += f;
        }
    }
    n.into_iter().map(|v| v.try_normalize().unwrap_or(Vec3::Z)).collect()
}

// ---------------------------------------------------------------------------------------------
// Rendering

/// Sensor of the frame from Blender's sensor size and fit; shift in mm from Blender's shift.
fn blender_sensor(
    width: u32,
    height: u32,
    sensor_width_mm: f64,
    sensor_height_mm: f64,
    fit: &str,
    shift: DVec2,
    tilt: DVec2,
) -> PyResult<Sensor> {
    let aspect = width as f64 / height as f64;
    let horizontal = match fit {
        "auto" | "AUTO" => width >= height,
        "horizontal" | "HORIZONTAL" => true,
        "vertical" | "VERTICAL" => false,
        f => return Err(settings_err("sensor_fit", format!("expected 'auto', 'horizontal' or 'vertical', got '{f}'"))),
    };
    // Blender: with AUTO the sensor width spans the larger side; shifts are fractions of the
    // fitted side.
    let (sw, sh, fitted) = match (fit, horizontal) {
        ("auto" | "AUTO", true) => (sensor_width_mm, sensor_width_mm / aspect, sensor_width_mm),
        ("auto" | "AUTO", false) => (sensor_width_mm * aspect, sensor_width_mm, sensor_width_mm),
        (_, true) => (sensor_width_mm, sensor_width_mm / aspect, sensor_width_mm),
        (_, false) => (sensor_height_mm * aspect, sensor_height_mm, sensor_height_mm),
    };
    let s = Sensor { width_mm: sw, height_mm: sh, shift_mm: shift * fitted, tilt_x_deg: tilt.x, tilt_y_deg: tilt.y };
    s.validate().map_err(py_err)?;
    Ok(s)
}

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

struct Shared {
    fraction: AtomicU32,
    cancel: AtomicBool,
    latest: Mutex<Option<(Image, u32)>>,
    spp_done: AtomicU32,
}

fn image_arrays(py: Python<'_>, img: &Image) -> (Py<PyAny>, Py<PyAny>) {
    let (w, h) = (img.width as usize, img.height as usize);
    let rgba: Vec<f32> = img.rgba.iter().flatten().copied().collect();
    let rgba = Array3::from_shape_vec((h, w, 4), rgba).unwrap_or_else(|_| Array3::zeros((h, w, 4)));
    let depth = Array2::from_shape_vec((h, w), img.depth.clone()).unwrap_or_else(|_| Array2::zeros((h, w)));
    (rgba.into_pyarray(py).into_any().unbind(), depth.into_pyarray(py).into_any().unbind())
}

/// Renders a scene (see the stub for every argument).
#[pyfunction]
#[pyo3(signature = (scene, camera_to_world, width, height, *, lens = "thin".to_string(), lens_model = "auto".to_string(), tolerance_px = 0.25, focal_length_mm = 50.0, sensor_width_mm = 36.0, sensor_height_mm = 24.0, sensor_fit = "auto".to_string(), shift_x = 0.0, shift_y = 0.0, tilt_x_deg = 0.0, tilt_y_deg = 0.0, fstop = None, focus_distance_m = None, aperture_blades = 0, aperture_rotation_rad = 0.0, aperture_ratio = 1.0, aperture_image = None, clip_start_m = 0.0, clip_end_m = f64::INFINITY, crop = None, spp = 64, seed = 0, max_depth = 8, filter_width_px = 1.5, natural_vignetting = false, spectral = false, threads = 0, progress = None, progress_interval_s = 0.1))]
#[allow(clippy::too_many_arguments)]
fn render(
    py: Python<'_>,
    scene: &PyScene,
    camera_to_world: PyArrayLike2<'_, f64, AllowTypeChange>,
    width: u32,
    height: u32,
    lens: String,
    lens_model: String,
    tolerance_px: f64,
    focal_length_mm: f64,
    sensor_width_mm: f64,
    sensor_height_mm: f64,
    sensor_fit: String,
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
    crop: Option<(u32, u32, u32, u32)>,
    spp: u32,
    seed: u32,
    max_depth: u32,
    filter_width_px: f64,
    natural_vignetting: bool,
    spectral: bool,
    threads: usize,
    progress: Option<Py<PyAny>>,
    progress_interval_s: f64,
) -> PyResult<Py<PyDict>> {
    guard(|| {
        // 1. Settings, checked before any work.
        let settings = RenderSettings {
            width,
            height,
            spp,
            seed,
            max_depth,
            spectral,
            time_limit: None,
            filter: if filter_width_px > 0.0 {
                PixelFilter::BlackmanHarris { width_px: 2.0 * filter_width_px as f32 }
            } else {
                PixelFilter::Box { width_px: 1.0 }
            },
            clip_start_m,
            clip_end_m,
            crop: crop.map(|(x0, y0, x1, y1)| [x0, y0, x1, y1]),
        };
        settings.validate().map_err(py_err)?;
        if !(filter_width_px.is_finite() && filter_width_px >= 0.0) {
            return Err(settings_err("filter_width_px", format!("must be ≥ 0, got {filter_width_px}")));
        }
        if !(progress_interval_s.is_finite() && progress_interval_s > 0.0) {
            return Err(settings_err("progress_interval_s", format!("must be positive, got {progress_interval_s}")));
        }
        let to_world = rigid(
            affine_from_rows("camera", "camera_to_world", &camera_to_world.as_array())
                .map_err(|e| settings_err("camera_to_world", e.to_string()))?,
        )?;
        let sensor = blender_sensor(
            width,
            height,
            sensor_width_mm,
            sensor_height_mm,
            &sensor_fit,
            DVec2::new(shift_x, shift_y),
            DVec2::new(tilt_x_deg, tilt_y_deg),
        )?;
        if !aperture_rotation_rad.is_finite() {
            return Err(settings_err("aperture_rotation_rad", format!("must be finite, got {aperture_rotation_rad}")));
        }
        if threads > 1024 {
            return Err(settings_err("threads", format!("{threads} is more than 1024 (0 uses every core)")));
        }
        if focus_distance_m.is_some_and(|d| d.is_nan()) {
            return Err(settings_err("focus_distance_m", "is NaN (None or inf focuses at infinity)".into()));
        }
        if !(aperture_ratio.is_finite() && aperture_ratio > 0.0) {
            return Err(settings_err("aperture_ratio", format!("must be positive, got {aperture_ratio}")));
        }
        let aperture = match (&aperture_image, aperture_blades) {
            (Some(path), _) => Some(Aperture {
                shape: ApertureShape::Mask(Arc::new(ApertureMask::load(std::path::Path::new(path)).map_err(py_err)?)),
                rotation_rad: aperture_rotation_rad,
                anamorphic_ratio: aperture_ratio,
            }),
            (None, n) if n >= 3 => Some(Aperture {
                shape: ApertureShape::Blades { count: n, curvature: 0.0 },
                rotation_rad: aperture_rotation_rad,
                anamorphic_ratio: aperture_ratio,
            }),
            (None, _) if aperture_ratio != 1.0 => {
                Some(Aperture { shape: ApertureShape::Circle, rotation_rad: 0.0, anamorphic_ratio: aperture_ratio })
            }
            _ => None,
        };
        let model: LensModel = lens_model.parse().map_err(py_err)?;
        let spec = CameraSpec {
            lens: lens.clone(),
            model,
            tolerance_px,
            focal_length_mm,
            f_number: fstop,
            focus_distance_m: focus_distance_m.filter(|d| *d != f64::INFINITY),
            aperture,
            sensor,
            natural_vignetting,
            lrtf_file: None,
        };
        spec.validate().map_err(py_err)?;
        let mut scene_data = scene.scene.clone();
        if !scene.all_tangents {
            scene_data.mesh.tangents.clear();
        }
        // 2. Build, decide and render on a worker thread; this thread (holding the GIL only to
        //    call `progress`) polls it.
        let shared = Arc::new(Shared {
            fraction: AtomicU32::new(0),
            cancel: AtomicBool::new(false),
            latest: Mutex::new(None),
            spp_done: AtomicU32::new(0),
        });
        let pool = if threads > 0 {
            Some(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .map_err(|e| PetzvalError::new_err(e.to_string()))?,
            )
        } else {
            None
        };
        type Outcome = Result<(RenderResult, String, String, Vec<String>), Error>;
        let work = {
            let shared = shared.clone();
            move || -> Outcome {
                let run = || -> Outcome {
                    let render_scene = RenderScene::new(scene_data)?;
                    let warnings = render_scene.scene().warnings.clone();
                    let built = spec.build_for_scene(&render_scene, &to_world, width, height, spp, spectral)?;
                    let rig = CameraRig { camera: built.camera, to_world };
                    let settings = RenderSettings {
                        spectral: settings.spectral && rig.camera.is_dispersive(),
                        ..settings.clone()
                    };
                    let on_progress = |f: f32| {
                        shared.fraction.store(f.to_bits(), Ordering::Relaxed);
                        !shared.cancel.load(Ordering::Relaxed)
                    };
                    let on_pass = |img: &Image, spp_done: u32| {
                        shared.spp_done.store(spp_done, Ordering::Relaxed);
                        if let Ok(mut l) = shared.latest.lock() {
                            *l = Some((img.clone(), spp_done));
                        }
                    };
                    let result = render_observed(&render_scene, &rig, &settings, &on_progress, &on_pass)?;
                    Ok((result, built.choice.model.to_string(), built.choice.reason, warnings))
                };
                match &pool {
                    Some(p) => p.install(run),
                    None => run(),
                }
            }
        };
        let interval = Duration::from_secs_f64(progress_interval_s);
        let (outcome, callback_error) = std::thread::scope(|s| {
            let handle = s.spawn(move || catch_unwind(AssertUnwindSafe(work)));
            let mut callback_error: Option<PyErr> = None;
            loop {
                // Wait (without the GIL) until the interval passes or the work ends.
                let finished = py.detach(|| {
                    let t0 = Instant::now();
                    while t0.elapsed() < interval {
                        if handle.is_finished() {
                            return true;
                        }
                        std::thread::sleep(Duration::from_millis(5));
                    }
                    handle.is_finished()
                });
                if let (Some(cb), None) = (&progress, &callback_error) {
                    let snapshot = shared.latest.lock().ok().and_then(|mut l| l.take());
                    let fraction = f32::from_bits(shared.fraction.load(Ordering::Relaxed));
                    // samples done so far always; the image only when a pass finished since the last call
                    let (spp_done, rgba) = match &snapshot {
                        Some((img, n)) => (*n, Some(image_arrays(py, img).0)),
                        None => (shared.spp_done.load(Ordering::Relaxed), None),
                    };
                    match cb.call1(py, (fraction, spp_done, rgba)) {
                        Ok(r) => {
                            if let Ok(false) = r.extract::<bool>(py) {
                                shared.cancel.store(true, Ordering::Relaxed);
                            }
                        }
                        Err(e) => {
                            shared.cancel.store(true, Ordering::Relaxed);
                            callback_error = Some(e);
                        }
                    }
                }
                if finished {
                    break;
                }
            }
            let joined = handle.join().unwrap_or_else(Err);
            (joined, callback_error)
        });
        if let Some(e) = callback_error {
            return Err(e);
        }
        let (result, model_name, reason, warnings) = match outcome {
            Ok(Ok(v)) => v,
            Ok(Err(e)) => return Err(py_err(e)),
            Err(p) => {
                return Err(PetzvalError::new_err(format!("internal error (please report): {}", panic_message(p))))
            }
        };
        if result.spp_done == 0 {
            return Err(CancelledError::new_err("cancelled before the first pass finished"));
        }
        // 3. The result.
        let (rgba, depth) = image_arrays(py, &result.image);
        let d = PyDict::new(py);
        d.set_item("rgba", rgba)?;
        d.set_item("depth", depth)?;
        d.set_item("spp", result.spp_done)?;
        d.set_item("complete", result.complete)?;
        d.set_item("seconds", result.seconds)?;
        d.set_item("camera_rays", result.camera_rays)?;
        d.set_item("dropped_samples", result.dropped_samples)?;
        d.set_item("lens_model", model_name)?;
        d.set_item("lens_model_reason", reason)?;
        d.set_item("warnings", warnings)?;
        Ok(d.unbind())
    })
}

/// The module.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("PetzvalError", py.get_type::<PetzvalError>())?;
    m.add("InvalidLensError", py.get_type::<InvalidLensError>())?;
    m.add("InvalidSceneError", py.get_type::<InvalidSceneError>())?;
    m.add("InvalidSettingsError", py.get_type::<InvalidSettingsError>())?;
    m.add("CancelledError", py.get_type::<CancelledError>())?;
    m.add_class::<PyLens>()?;
    m.add_class::<PyScene>()?;
    m.add_function(wrap_pyfunction!(library_lenses, m)?)?;
    m.add_function(wrap_pyfunction!(render, m)?)?;
    Ok(())
}
