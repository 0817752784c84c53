//! Depth-peeled layers seen from the perspective centre: the shared input of the image-based
//! preview methods. Our ray tracer makes them directly (the first hit, then the next front-facing intersections
//! along each ray), so no rasteriser and no frustum matrices are needed, under tilt as anywhere else.
//!
//! The layers live in a [`LayerFrame`]: a pinhole at the camera's origin (the thin lens's centre,
//! a real lens's entrance pupil) looking down −z, with a rectilinear grid of texels in tangent
//! coordinates (x/−z, y/−z) that covers every chief ray of the frame plus a margin for blur.
//! Data is batch-shaped (one flat `Vec` per quantity, layer-major), so a GPU back end could take
//! it as it is.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `count` | usize: layers K | — | 4 |
//! | `spp` | u32: path samples per texel and layer (filter-jittered, Blackman–Harris 3 px) | — | 16 |
//! | `margin` | f64: extra frame on each side, as a fraction of the chief rays' extent | — | 0.15 |

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::film::{FilterSampler, PixelFilter};
use crate::integrator::{PathTracer, RenderScene};
use crate::sampler::PixelSampler;
use glam::{DAffine3, DVec2, DVec3, Vec3};
use rayon::prelude::*;

/// Largest tangent of the layer frame (80°): wider fields cannot be one planar pinhole image.
const MAX_TAN: f64 = 5.67;

/// The pinhole image the layers are stored in (camera space, see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LayerFrame {
    /// Texels across.
    pub width: usize,
    /// Texels down.
    pub height: usize,
    /// Tangent coordinates (x/−z, y/−z) of the frame's left-bottom corner.
    pub tan_min: DVec2,
    /// Tangent coordinates of the right-top corner.
    pub tan_max: DVec2,
}

impl LayerFrame {
    /// The frame that covers every chief ray of `camera` (lens sample at the pupil centre) for
    /// an image of `width` × `height` pixels, widened by `margin` of its extent on each side; its
    /// texels are about the size of the image's pixels.
    pub fn covering(camera: &Camera, width: u32, height: u32, margin: f64) -> Result<LayerFrame> {
        // 1. Chief rays on a 33 × 33 grid over the frame (edges included).
        let n = 33;
        let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
        let wavelength =
            camera.real_lens().map_or(crate::optics::glass::WAVELENGTH_D_NM, |l| l.primary_wavelength_nm());
        for j in 0..n {
            for i in 0..n {
                let film = DVec2::new(i as f64 / (n - 1) as f64, j as f64 / (n - 1) as f64);
                let Some(t) = chief_tangent(camera, film, wavelength) else { continue };
                lo = lo.min(t);
                hi = hi.max(t);
            }
        }
        if !(lo.x < hi.x && lo.y < hi.y) {
            return Err(Error::settings("method", "no chief ray of the camera leaves the lens forwards"));
        }
        // 2. Texels the size of the image's pixels across the chief rays' extent (on a
        //    rectilinear image they coincide), and a whole number of them of margin on each
        //    side, within what one pinhole image can hold.
        let size = DVec2::new(width as f64, height as f64);
        let texel = (hi - lo) / size;
        let room_lo = ((lo + DVec2::splat(MAX_TAN)) / texel).floor();
        let room_hi = ((DVec2::splat(MAX_TAN) - hi) / texel).floor();
        let margin_px = (size * margin).ceil();
        let (pad_lo, pad_hi) = (margin_px.min(room_lo).max(DVec2::ZERO), margin_px.min(room_hi).max(DVec2::ZERO));
        let (tan_min, tan_max) = (lo - pad_lo * texel, hi + pad_hi * texel);
        let texels = size + pad_lo + pad_hi;
        Ok(LayerFrame { width: texels.x as usize, height: texels.y as usize, tan_min, tan_max })
    }

    /// Tangent size of one texel.
    pub fn texel_size(&self) -> DVec2 {
        (self.tan_max - self.tan_min) / DVec2::new(self.width as f64, self.height as f64)
    }

    /// Camera-space direction (z = −1, not unit) through continuous texel coordinates `xy`
    /// (texel (i, j) spans [i, i+1) × [j, j+1); row 0 is the top).
    pub fn direction(&self, xy: DVec2) -> DVec3 {
        let d = self.texel_size();
        DVec3::new(self.tan_min.x + xy.x * d.x, self.tan_max.y - xy.y * d.y, -1.0)
    }

    /// Continuous texel coordinates of tangent coordinates `t`.
    pub fn texel_of_tangent(&self, t: DVec2) -> DVec2 {
        let d = self.texel_size();
        DVec2::new((t.x - self.tan_min.x) / d.x, (self.tan_max.y - t.y) / d.y)
    }

    /// Continuous texel coordinates and planar depth (m, along −z) of camera-space point `p`;
    /// None behind the centre.
    pub fn project(&self, p: DVec3) -> Option<(DVec2, f64)> {
        let z = -p.z;
        (z > 0.0).then(|| (self.texel_of_tangent(DVec2::new(p.x / z, p.y / z)), z))
    }

    /// Texels in one layer.
    pub fn texels(&self) -> usize {
        self.width * self.height
    }
}

/// The tangent coordinates of the chief ray through `film` (lens sample at the pupil centre, or
/// the nearest sample the lens lets through).
fn chief_tangent(camera: &Camera, film: DVec2, wavelength_nm: f64) -> Option<DVec2> {
    let tries = [DVec2::splat(0.5), DVec2::new(0.5, 0.45), DVec2::new(0.45, 0.5), DVec2::new(0.5, 0.55)];
    let ray = tries.iter().find_map(|&u| camera.generate_ray(film, u, wavelength_nm))?;
    let d = ray.direction;
    (d.z < -1e-6).then(|| DVec2::new(d.x / -d.z, d.y / -d.z))
}

/// How the layers are made.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LayerSettings {
    /// Layers K (1..=16).
    pub count: usize,
    /// Path samples per texel and layer.
    pub spp: u32,
    /// Frame margin on each side, as a fraction of the chief rays' extent.
    pub margin: f64,
    /// Maximum path depth of the shading.
    pub max_depth: u32,
    /// Seed.
    pub seed: u32,
}

impl Default for LayerSettings {
    fn default() -> Self {
        LayerSettings { count: 4, spp: 16, margin: 0.15, max_depth: 8, seed: 0 }
    }
}

impl LayerSettings {
    /// Checks the settings.
    pub fn validate(&self) -> Result<()> {
        if !(1..=16).contains(&self.count) {
            return Err(Error::settings("layers", format!("{} must be in 1..=16", self.count)));
        }
        if !(1..=65536).contains(&self.spp) {
            return Err(Error::settings("layer_spp", format!("{} must be in 1..=65536", self.spp)));
        }
        if !(0.0..=2.0).contains(&self.margin) {
            return Err(Error::settings("layer_margin", format!("{} must be in 0..=2", self.margin)));
        }
        Ok(())
    }
}

/// K depth-peeled layers of radiance and depth (see the module docs). Index
/// `k · texels + row · width + column`.
#[derive(Debug, Clone)]
pub struct Layers {
    /// The frame.
    pub frame: LayerFrame,
    /// Number of layers K.
    pub count: usize,
    /// Planar depth along −z (m) of layer k's surface at each texel (the k-th front-facing hit
    /// of the texel's centre ray); +inf where the ray has left the scene (the environment shows).
    pub depth_m: Vec<f32>,
    /// Radiance leaving that surface towards the centre (linear RGB, path traced; filter-jittered
    /// samples, each peeling its own k-th hit), or the environment's where the depth is +inf.
    pub radiance: Vec<Vec3>,
    /// Camera-to-world transform the layers were made with.
    pub to_world: DAffine3,
}

impl Layers {
    /// Traces the layers of `scene` seen from `to_world`'s origin through `frame`.
    pub fn trace(
        scene: &RenderScene,
        to_world: DAffine3,
        frame: LayerFrame,
        settings: &LayerSettings,
    ) -> Result<Layers> {
        settings.validate()?;
        let k_count = settings.count;
        let texels = frame.texels();
        let tracer = PathTracer { max_depth: settings.max_depth, ..PathTracer::default() };
        let filter = FilterSampler::new(PixelFilter::default());
        let origin = to_world.transform_point3(DVec3::ZERO).as_vec3();
        // Rows in parallel; each row returns its K × width depths and radiances.
        let rows: Vec<(Vec<f32>, Vec<Vec3>)> = (0..frame.height)
            .into_par_iter()
            .map(|row| {
                let mut depth = vec![f32::INFINITY; k_count * frame.width];
                let mut radiance = vec![Vec3::ZERO; k_count * frame.width];
                for col in 0..frame.width {
                    // 1. Depths: the centre ray's front-facing hits.
                    let centre = frame.direction(DVec2::new(col as f64 + 0.5, row as f64 + 0.5));
                    let d = to_world.transform_vector3(centre).normalize().as_vec3();
                    let axial = (1.0 / centre.length()) as f32;
                    let hits = peel(scene, origin, d, k_count);
                    for (k, t) in hits.iter().enumerate() {
                        depth[k * frame.width + col] = t * axial;
                    }
                    // 2. Radiance: jittered rays, each shading its own k-th hit (or the
                    //    environment once it has left the scene).
                    for s in 0..settings.spp {
                        let mut sampler = PixelSampler::new(col as u32, row as u32, s, settings.seed ^ 0x1a7e_5eed);
                        let off = filter.sample(sampler.next_2d());
                        let dir = frame
                            .direction(DVec2::new(col as f64 + 0.5 + off.x as f64, row as f64 + 0.5 + off.y as f64));
                        let d = to_world.transform_vector3(dir).normalize().as_vec3();
                        let hits = peel(scene, origin, d, k_count);
                        for k in 0..k_count {
                            let mut layer_sampler =
                                PixelSampler::new(col as u32, row as u32, s, settings.seed ^ (k as u32 + 1));
                            let value = match hits.get(k) {
                                Some(&t) => {
                                    // Start 1 % short of the hit (closer starts can miss it at
                                    // grazing angles), but past the previous layer's.
                                    let previous = if k > 0 { hits[k - 1] } else { 0.0 };
                                    let clip = ((t * 0.99).max(0.5 * (previous + t)), f32::INFINITY);
                                    let sample = tracer.trace_clipped(scene, origin, d, clip, &mut layer_sampler);
                                    sample.radiance
                                }
                                None => crate::integrator::lights::env_radiance(&scene.scene().environment, d),
                            };
                            radiance[k * frame.width + col] += value / settings.spp as f32;
                        }
                    }
                }
                (depth, radiance)
            })
            .collect();
        // 3. Rows → layer-major planes.
        let mut depth_m = vec![f32::INFINITY; k_count * texels];
        let mut radiance = vec![Vec3::ZERO; k_count * texels];
        for (row, (d, r)) in rows.into_iter().enumerate() {
            for k in 0..k_count {
                let dst = k * texels + row * frame.width;
                depth_m[dst..dst + frame.width].copy_from_slice(&d[k * frame.width..(k + 1) * frame.width]);
                radiance[dst..dst + frame.width].copy_from_slice(&r[k * frame.width..(k + 1) * frame.width]);
            }
        }
        Ok(Layers { frame, count: k_count, depth_m, radiance, to_world })
    }

    /// Index of layer `k`'s texel (`x`, `y`).
    #[inline]
    pub fn index(&self, k: usize, x: usize, y: usize) -> usize {
        k * self.frame.texels() + y * self.frame.width + x
    }

    /// Radiance of the environment in camera-space direction `dir`.
    pub fn environment(&self, scene: &RenderScene, dir: DVec3) -> Vec3 {
        let d = self.to_world.transform_vector3(dir).normalize().as_vec3();
        crate::integrator::lights::env_radiance(&scene.scene().environment, d)
    }
}

/// Distances along unit `dir` of the first hit (what the centre sees, from either side) and the
/// next `k − 1` front-facing hits (double-sided materials count from both sides; the back
/// faces of closed objects are skipped): each peel restarts just past the previous hit.
fn peel(scene: &RenderScene, origin: Vec3, dir: Vec3, k: usize) -> Vec<f32> {
    let mut out = Vec::with_capacity(k);
    let mut t0 = 0.0f32;
    let mut guard = 0;
    while out.len() < k && guard < 64 {
        guard += 1;
        let o = origin + dir * t0;
        let Some(hit) = scene.intersect(o, dir, f32::INFINITY) else { break };
        let t = t0 + hit.t;
        let double_sided = scene.scene().materials[hit.material_id as usize].double_sided;
        if out.is_empty() || hit.front_face || double_sided {
            out.push(t);
        }
        t0 = t + (t * 1e-4).max(1e-5);
    }
    out
}
