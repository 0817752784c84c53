//! Rendering: camera + scene → integrator → film. Pixels are rendered in parallel (rayon, rows
//! of tiles) in progressive passes; each pixel sample draws from its own Sobol stream, so the
//! image is identical for any thread count.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `width`, `height` | u32 | pixels | 960 × 640 |
//! | `spp` | u32, samples per pixel | — | 64 |
//! | `seed` | u32 | — | 0 |
//! | `max_depth` | u32, path vertices | — | 8 |
//! | `spectral` | bool: one wavelength per camera ray (lens dispersion) | — | false |
//! | `time_limit` | optional duration; stops after the pass that crosses it | s | none |
//! | `filter` | [`PixelFilter`] | px | Blackman–Harris spanning 3 px (Cycles' default) |

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::film::{Film, FilterSampler, Image, PixelFilter};
use crate::integrator::{PathTracer, RenderScene};
use crate::sampler::PixelSampler;
use crate::spectral;
use glam::{DAffine3, DVec2, Vec3};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// A camera placed in the world.
#[derive(Debug, Clone)]
pub struct CameraRig {
    /// The camera model.
    pub camera: Camera,
    /// Camera-to-world transform (rigid, metres; camera looks down −z).
    pub to_world: DAffine3,
}

/// Render settings.
#[derive(Debug, Clone)]
pub struct RenderSettings {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Samples per pixel.
    pub spp: u32,
    /// Seed.
    pub seed: u32,
    /// Maximum path depth.
    pub max_depth: u32,
    /// Trace one wavelength per camera ray.
    pub spectral: bool,
    /// Stop after the pass in which this much time has passed.
    pub time_limit: Option<Duration>,
    /// Pixel filter.
    pub filter: PixelFilter,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings { width: 960, height: 640, spp: 64, seed: 0, max_depth: 8, spectral: false, time_limit: None, filter: PixelFilter::default() }
    }
}

impl RenderSettings {
    /// Checks the settings.
    pub fn validate(&self) -> Result<()> {
        let bad = |f: &str, m: String| Err(Error::Camera { field: f.into(), message: m });
        if self.width == 0 || self.height == 0 || self.width > 16384 || self.height > 16384 {
            return bad("resolution", format!("{}x{} is outside 1..16384 per side", self.width, self.height));
        }
        if (self.width as u64) * (self.height as u64) > 100_000_000 {
            return bad("resolution", format!("{}x{} is more than 100 megapixels", self.width, self.height));
        }
        if self.spp == 0 || self.spp > 1 << 20 {
            return bad("spp", format!("{} must be in 1..=1048576", self.spp));
        }
        if self.max_depth == 0 || self.max_depth > 1024 {
            return bad("max_depth", format!("{} must be in 1..=1024", self.max_depth));
        }
        Ok(())
    }
}

/// What a render produced.
#[derive(Debug, Clone)]
pub struct RenderResult {
    /// The image.
    pub image: Image,
    /// Samples per pixel completed in every pixel.
    pub spp_done: u32,
    /// False when stopped early (time limit or cancel).
    pub complete: bool,
    /// Wall time.
    pub seconds: f64,
    /// Camera rays generated (including blocked ones).
    pub camera_rays: u64,
    /// Samples dropped as non-finite.
    pub dropped_samples: u64,
}

/// Progress: fraction done in [0, 1]; return false to cancel.
pub type Progress<'a> = &'a (dyn Fn(f32) -> bool + Sync);

/// Renders `scene` through `rig`.
pub fn render(scene: &RenderScene, rig: &CameraRig, settings: &RenderSettings, progress: Progress) -> Result<RenderResult> {
    settings.validate()?;
    let start = Instant::now();
    let (w, h) = (settings.width, settings.height);
    let mut film = Film::new(w, h);
    let filter = FilterSampler::new(settings.filter);
    let tracer = PathTracer { max_depth: settings.max_depth, ..PathTracer::default() };
    let cancelled = AtomicBool::new(false);
    let camera_rays = AtomicU64::new(0);
    let dropped = AtomicU64::new(0);
    let wavelength_primary = match &rig.camera {
        Camera::Realistic(c) => c.lens.primary_wavelength_nm(),
        Camera::Lrtf(c) => c.exact.lens.primary_wavelength_nm(),
        _ => crate::optics::glass::WAVELENGTH_D_NM,
    };
    // 1. Progressive passes: 1, 1, 2, 4, ... samples, at most 16 spp per pass.
    let mut done = 0u32;
    let mut pass_spp = 1u32;
    let total_work = settings.spp as f64 * h as f64;
    let rows_done = AtomicU64::new(0);
    while done < settings.spp && !cancelled.load(Ordering::Relaxed) {
        let n = pass_spp.min(settings.spp - done);
        let range = done..done + n;
        film.pixels.par_chunks_mut(w as usize).enumerate().for_each(|(y, row)| {
            if cancelled.load(Ordering::Relaxed) {
                return;
            }
            for (x, px) in row.iter_mut().enumerate() {
                for s in range.clone() {
                    // 2. Camera sample: filter offset, lens point, wavelength.
                    let mut sampler = PixelSampler::new(x as u32, y as u32, s, settings.seed);
                    let off = filter.sample(sampler.next_2d());
                    let film_uv = DVec2::new((x as f64 + 0.5 + off.x as f64) / w as f64, (y as f64 + 0.5 + off.y as f64) / h as f64);
                    let lens_u = sampler.next_2d();
                    let u_lambda = sampler.next_1d();
                    let (lambda, lambda_weight) = if settings.spectral { spectral::sample_wavelength(u_lambda) } else { (wavelength_primary as f32, Vec3::ONE) };
                    px.samples += 1;
                    let Some(ray) = rig.camera.generate_ray(film_uv, lens_u.as_dvec2(), lambda as f64) else { continue };
                    // 3. World ray and the path.
                    let o = rig.to_world.transform_point3(ray.origin).as_vec3();
                    let d = rig.to_world.transform_vector3(ray.direction).normalize().as_vec3();
                    let sample = tracer.trace(scene, o, d, &mut sampler);
                    let value = sample.radiance * lambda_weight * ray.weight as f32;
                    if !value.is_finite() || sample.dropped {
                        px.dropped += 1;
                        continue;
                    }
                    px.rgb += value;
                    // Coverage over the light that reaches the film: a sample blocked by the
                    // lens carries no light and says nothing about coverage, and rays are
                    // weighted as their radiance is (so compositing with alpha is exact).
                    let w = ray.weight as f32;
                    px.alpha += sample.alpha * w;
                    px.alpha_weight += w;
                    if sample.depth_m.is_finite() {
                        px.hits += 1;
                        px.depth += sample.depth_m;
                        px.normal += sample.normal;
                        px.albedo += sample.albedo;
                    }
                }
            }
            camera_rays.fetch_add(row.len() as u64 * n as u64, Ordering::Relaxed);
            let r = rows_done.fetch_add(n as u64, Ordering::Relaxed) + n as u64;
            if !progress((r as f64 / total_work) as f32) {
                cancelled.store(true, Ordering::Relaxed);
            }
        });
        if !cancelled.load(Ordering::Relaxed) {
            done += n;
        }
        pass_spp = (pass_spp * 2).min(16);
        if let Some(limit) = settings.time_limit {
            if start.elapsed() >= limit && done < settings.spp {
                break;
            }
        }
    }
    for p in &film.pixels {
        dropped.fetch_add(p.dropped as u64, Ordering::Relaxed);
    }
    Ok(RenderResult {
        image: film.image(),
        spp_done: done,
        complete: done == settings.spp,
        seconds: start.elapsed().as_secs_f64(),
        camera_rays: camera_rays.load(Ordering::Relaxed),
        dropped_samples: dropped.load(Ordering::Relaxed),
    })
}
