//! Depth-of-field methods: Monte Carlo ray tracing through the lens (the reference, in
//! [`crate::render`]) and three fast preview methods that shade the scene once, from the
//! perspective centre, and make the blur from that:
//!
//! * [`Method::Ibrt`]: image-based ray tracing. The scene is shaded into K depth-peeled
//!   [`layers`] (radiance and depth), and every camera ray of the real camera model (any lens,
//!   tilt and shift) is intersected with the layers as height fields ([`ibrt`]).
//! * [`Method::Multiview`]: multi-view accumulation. Every lens sample is one pinhole view
//!   shared by all pixels; visibility is traced exactly and the radiance looked up in the layers
//!   ([`multiview`]).
//! * [`Method::Spread`]: PSF spreading. Every layer texel spreads its point-spread function (the
//!   aperture projected from its conjugate point, or a real lens's traced PSF table) onto depth
//!   slices composited front to back ([`spread`]).
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `method` | [`Method`]: `mc`, `multiview`, `ibrt`, `spread` | — | `mc` |
//! | `layers` | [`LayerSettings`] (count, spp, margin) | — | 4 layers, 4 spp per texel, 2 texels per pixel, margin 0.15 |
//!
//! `spp` of [`RenderSettings`] keeps its meaning for every method: the camera rays per pixel
//! (lens samples); the shading budget of the preview methods is the layers' `spp`.

pub mod ibrt;
pub mod layers;
pub mod multiview;
pub mod spread;

pub use ibrt::LayerTracer;
pub use layers::{LayerFrame, LayerSettings, Layers};

use crate::camera::CameraRay;
use crate::error::{Error, Result};
use crate::integrator::{PathSample, RenderScene};
use crate::render::{render_samples, CameraRig, PassObserver, Progress, RenderResult, RenderSettings, SampleShader};
use crate::sampler::PixelSampler;
use glam::Vec3;
use std::fmt;
use std::str::FromStr;
use std::time::Instant;

/// A depth-of-field rendering method (the CLI's `--method`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Method {
    /// Monte Carlo: every camera ray path traced through the scene (the reference).
    #[default]
    Mc,
    /// Multi-view accumulation: pinhole views through samples of the pupil.
    Multiview,
    /// Image-based ray tracing on depth-peeled layers.
    Ibrt,
    /// PSF spreading of layered images.
    Spread,
}

impl Method {
    /// Every method, in the order of the CLI's help.
    pub const ALL: [Method; 4] = [Method::Mc, Method::Multiview, Method::Ibrt, Method::Spread];
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Method::Mc => "mc",
            Method::Multiview => "multiview",
            Method::Ibrt => "ibrt",
            Method::Spread => "spread",
        })
    }
}

impl FromStr for Method {
    type Err = Error;
    fn from_str(s: &str) -> Result<Method> {
        Method::ALL.into_iter().find(|m| m.to_string() == s).ok_or_else(|| {
            Error::settings("method", format!("unknown method '{s}' (expected mc, multiview, ibrt or spread)"))
        })
    }
}

/// Settings of the preview methods (ignored by [`Method::Mc`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PreviewSettings {
    /// The layers.
    pub layers: LayerSettings,
}

/// Renders `scene` through `rig` with `method`; [`Method::Mc`] is [`crate::render::render_observed`].
pub fn render_method(
    method: Method,
    scene: &RenderScene,
    rig: &CameraRig,
    settings: &RenderSettings,
    preview: &PreviewSettings,
    progress: Progress,
    on_pass: PassObserver,
) -> Result<RenderResult> {
    settings.validate()?;
    let start = Instant::now();
    let mut result = match method {
        Method::Mc => return crate::render::render_observed(scene, rig, settings, progress, on_pass),
        _ if settings.adaptive_threshold > 0.0 => {
            return Err(crate::error::Error::settings(
                "adaptive_threshold",
                format!("adaptive sampling is path tracing's (method mc), not the {method} preview's"),
            ))
        }
        Method::Ibrt => {
            let Some(layers) = make_layers(scene, rig, settings, preview, progress)? else {
                return Ok(cancelled(settings, start));
            };
            let tracer = LayerTracer::new(layers);
            render_samples(rig, settings, progress, on_pass, &IbrtShader { tracer: &tracer, scene })?
        }
        Method::Multiview => multiview::render_multiview(scene, rig, settings, preview, progress, on_pass)?.0,
        Method::Spread => {
            // The spread's tables integrate over fixed lens grids: the traced pupil bounds only.
            let camera = rig.camera.for_shared_lens_samples();
            spread::check_camera(&camera)?;
            let Some(layers) = make_layers(scene, rig, settings, preview, progress)? else {
                return Ok(cancelled(settings, start));
            };
            let spread_settings = spread::SpreadSettings::default();
            let r = spread::render_spread(&layers, Some(scene), &camera, settings, &spread_settings, progress)?;
            if let (true, Some(show)) = (r.complete, on_pass) {
                show(&r.image, r.spp_done);
            }
            r
        }
    };
    result.seconds = start.elapsed().as_secs_f64();
    Ok(result)
}

/// What a render cancelled before its first pass returns: a black image, no samples.
pub(crate) fn cancelled(settings: &RenderSettings, start: Instant) -> RenderResult {
    let [x0, y0, x1, y1] = settings.crop.unwrap_or([0, 0, settings.width, settings.height]);
    RenderResult {
        image: crate::film::Film::new(x1 - x0, y1 - y0).image(),
        spp_done: 0,
        complete: false,
        seconds: start.elapsed().as_secs_f64(),
        camera_rays: 0,
        light_paths: 0,
        light_paths_landed: 0,
        dropped_samples: 0,
    }
}

/// The layers of `scene` for `rig`'s camera at `settings`' resolution; None when `progress`
/// cancelled (it is asked with fraction 0 while the layers are traced).
pub fn make_layers(
    scene: &RenderScene,
    rig: &CameraRig,
    settings: &RenderSettings,
    preview: &PreviewSettings,
    progress: Progress,
) -> Result<Option<Layers>> {
    // The frame's chief rays take the lens sample (0.5, 0.5), the pupil's centre in the traced
    // bounds (not in the defensive disc's mixture).
    let frame = LayerFrame::covering(
        &rig.camera.for_shared_lens_samples(),
        settings.width,
        settings.height,
        preview.layers.margin,
        preview.layers.texels_per_pixel,
    )?;
    let layer_settings = LayerSettings {
        max_depth: settings.max_depth,
        seed: settings.seed,
        clip_m: (settings.clip_start_m, settings.clip_end_m),
        ..preview.layers
    };
    let bytes = (frame.texels() * layer_settings.count) as u64 * crate::limits::LAYER_BYTES_PER_TEXEL;
    if let Err(budget) = crate::limits::check_memory(bytes) {
        return Err(Error::settings(
            "layers",
            format!(
                "{} layers of {}x{} texels need about {}, {}",
                layer_settings.count,
                frame.width,
                frame.height,
                crate::limits::format_bytes(bytes),
                crate::limits::over_budget(budget)
            ),
        ));
    }
    Layers::trace(
        scene,
        rig.to_world,
        frame,
        &layer_settings,
        pupil_radius_m(&rig.camera.for_shared_lens_samples()),
        &|| progress(0.0),
    )
}

/// The largest distance from the axis at which the camera's rays cross the pupil plane z = 0
/// (m): the aperture radius of a thin lens, about the entrance pupil's of a real lens (with a
/// quarter of margin for pupil aberration), 0 for a pinhole.
pub fn pupil_radius_m(camera: &crate::camera::Camera) -> f64 {
    let wavelength = camera.real_lens().map_or(crate::optics::glass::WAVELENGTH_D_NM, |l| l.primary_wavelength_nm());
    let mut r = 0.0f64;
    for film in [(0.5, 0.5), (0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0), (0.5, 0.0), (0.0, 0.5)] {
        for i in 0..17 {
            for j in 0..17 {
                let u = glam::DVec2::new(i as f64 / 16.0, j as f64 / 16.0).min(glam::DVec2::splat(0.9999));
                let Some(ray) = camera.generate_ray(glam::DVec2::new(film.0, film.1), u, wavelength) else { continue };
                if ray.direction.z.abs() < 1e-9 {
                    continue;
                }
                let t = -ray.origin.z / ray.direction.z;
                let p = ray.origin + ray.direction * t;
                r = r.max(p.truncate().length());
            }
        }
    }
    r * 1.25
}

/// Image-based ray tracing: camera rays looked up in the layers.
struct IbrtShader<'a> {
    tracer: &'a LayerTracer,
    scene: &'a RenderScene,
}

impl SampleShader for IbrtShader<'_> {
    fn shade(
        &self,
        ray: &CameraRay,
        _o: Vec3,
        _d: Vec3,
        clip: (f32, f32),
        _film: &crate::bokeh::FilmSample,
        _s: &mut PixelSampler,
    ) -> PathSample {
        self.tracer.shade(self.scene, ray, clip)
    }
}
