//! Depth-of-field methods: Monte Carlo ray tracing through the lens (the reference, in
//! [`crate::render`]) and three fast preview methods that shade the scene once, from the
//! perspective centre, and make the blur from that:
//!
//! * [`Method::Ibrt`]: image-based ray tracing. The scene is shaded into K depth-peeled
//!   [`layers`] (radiance and depth), and every camera ray of the real camera model (any lens,
//!   tilt and shift) is intersected with the layers as height fields ([`ibrt`]).
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `method` | [`Method`]: `mc`, `multiview`, `ibrt`, `spread` | — | `mc` |
//! | `layers` | [`LayerSettings`] (count, spp, margin) | — | 4 layers, 16 spp, 0.15 |
//!
//! `spp` of [`RenderSettings`] keeps its meaning for every method: the camera rays per pixel
//! (lens samples); the shading budget of the preview methods is the layers' `spp`.

pub mod ibrt;
pub mod layers;
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
        Method::Ibrt => {
            let tracer = LayerTracer::new(make_layers(scene, rig, settings, preview)?);
            render_samples(rig, settings, progress, on_pass, &IbrtShader { tracer: &tracer, scene })?
        }
        Method::Spread => {
            spread::check_camera(&rig.camera)?;
            let layers = make_layers(scene, rig, settings, preview)?;
            let spread_settings = spread::SpreadSettings::default();
            let r = spread::render_spread(&layers, Some(scene), &rig.camera, settings, &spread_settings, progress)?;
            if r.complete {
                on_pass(&r.image, r.spp_done);
            }
            r
        }
        Method::Multiview => {
            return Err(Error::settings("method", format!("'{method}' is not built yet")));
        }
    };
    result.seconds = start.elapsed().as_secs_f64();
    Ok(result)
}

/// The layers of `scene` for `rig`'s camera at `settings`' resolution.
pub fn make_layers(
    scene: &RenderScene,
    rig: &CameraRig,
    settings: &RenderSettings,
    preview: &PreviewSettings,
) -> Result<Layers> {
    let frame = LayerFrame::covering(&rig.camera, settings.width, settings.height, preview.layers.margin)?;
    let layer_settings = LayerSettings { max_depth: settings.max_depth, seed: settings.seed, ..preview.layers };
    Layers::trace(scene, rig.to_world, frame, &layer_settings)
}

/// Image-based ray tracing: camera rays looked up in the layers.
struct IbrtShader<'a> {
    tracer: &'a LayerTracer,
    scene: &'a RenderScene,
}

impl SampleShader for IbrtShader<'_> {
    fn shade(&self, ray: &CameraRay, _o: Vec3, _d: Vec3, _clip: (f32, f32), _s: &mut PixelSampler) -> PathSample {
        self.tracer.shade(self.scene, ray)
    }
}
