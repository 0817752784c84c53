//! `petzval.render`: a [`PyCamera`] and render settings → an image, on a worker thread with
//! the GIL released, and the progress callback on the caller's thread.

use numpy::ndarray::{Array2, Array3};
use numpy::IntoPyArray;
use petzval_renderer::film::{Image, PixelFilter};
use petzval_renderer::integrator::RenderScene;
use petzval_renderer::render::{CameraRig, RenderResult, RenderSettings};
use petzval_renderer::{bokeh, dof};
use petzval_renderer::{shot, Error};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::camera::PyCamera;
use crate::errors::*;
use crate::scene::PyScene;

pub(crate) struct Shared {
    fraction: AtomicU32,
    cancel: AtomicBool,
    latest: Mutex<Option<(Image, u32)>>,
    spp_done: AtomicU32,
}

pub(crate) fn image_arrays(py: Python<'_>, img: &Image) -> (Py<PyAny>, Py<PyAny>) {
    let (w, h) = (img.width as usize, img.height as usize);
    let rgba: Vec<f32> = img.rgba.iter().flatten().copied().collect();
    let rgba = Array3::from_shape_vec((h, w, 4), rgba).unwrap_or_else(|_| Array3::zeros((h, w, 4)));
    let depth = Array2::from_shape_vec((h, w), img.depth.clone()).unwrap_or_else(|_| Array2::zeros((h, w)));
    (rgba.into_pyarray(py).into_any().unbind(), depth.into_pyarray(py).into_any().unbind())
}

/// Renders a scene through a camera (see the stub for every argument).
#[pyfunction]
#[pyo3(signature = (scene, camera, width, height, *, crop = None, spp = 64, seed = 0, max_depth = 8, filter_width_px = 1.5, spectral = false, threads = 0, progress = None, progress_interval_s = 0.1, method = "mc", layers = 4, layer_spp = 4, bokeh_paths = None, adaptive_threshold = 0.0, adaptive_min_samples = 0))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn render(
    py: Python<'_>,
    scene: &PyScene,
    camera: &PyCamera,
    width: u32,
    height: u32,
    crop: Option<(u32, u32, u32, u32)>,
    spp: u32,
    seed: u32,
    max_depth: u32,
    filter_width_px: f64,
    spectral: bool,
    threads: usize,
    progress: Option<Py<PyAny>>,
    progress_interval_s: f64,
    method: &str,
    layers: usize,
    layer_spp: u32,
    bokeh_paths: Option<f32>,
    adaptive_threshold: f32,
    adaptive_min_samples: u32,
) -> PyResult<Py<PyDict>> {
    guard(|| {
        // 1. Settings, checked before any work.
        if !(filter_width_px.is_finite() && (0.0..=16.0).contains(&filter_width_px)) {
            return Err(settings_err("filter_width_px", format!("must be in [0, 16] px, got {filter_width_px}")));
        }
        let (clip_start_m, clip_end_m) = camera.host.clip_m;
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
            bokeh_paths: bokeh_paths.unwrap_or(0.0),
            adaptive_threshold,
            adaptive_min_samples,
            pixel_origin: [0, 0],
        };
        settings.validate().map_err(py_err)?;
        let method: dof::Method = method.parse().map_err(py_err)?;
        let layer_settings = dof::LayerSettings { count: layers, spp: layer_spp, ..dof::LayerSettings::default() };
        layer_settings.validate().map_err(py_err)?;
        let preview = dof::PreviewSettings { layers: layer_settings };
        if !(progress_interval_s.is_finite() && progress_interval_s > 0.0) {
            return Err(settings_err("progress_interval_s", format!("must be positive, got {progress_interval_s}")));
        }
        if threads > 1024 {
            return Err(settings_err("threads", format!("{threads} is more than 1024 (0 uses every core)")));
        }
        let to_world = camera.to_world;
        let spec = camera.host.camera_spec(width, height).map_err(py_err)?;
        let mut scene_data = scene.scene.clone();
        if !scene.all_tangents {
            scene_data.meshes.iter_mut().for_each(|m| m.tangents.clear());
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
                    let mut warnings = render_scene.scene().warnings.clone();
                    let built = shot::build_for_scene(&spec, &render_scene, &to_world, width, height, spp, spectral)?;
                    warnings.extend(built.warnings.iter().cloned());
                    let rig = CameraRig { camera: built.camera, to_world };
                    let settings = RenderSettings {
                        spectral: settings.spectral && rig.camera.is_dispersive(),
                        // None = auto, as `petzval render --bokeh-paths auto`
                        bokeh_paths: match bokeh_paths {
                            None if method == dof::Method::Mc => bokeh::auto_paths(&render_scene, &rig.camera),
                            None => 0.0,
                            Some(v) => v,
                        },
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
                    let result = dof::render_method(
                        method,
                        &render_scene,
                        &rig,
                        &settings,
                        &preview,
                        &on_progress,
                        Some(&on_pass),
                    )?;
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
