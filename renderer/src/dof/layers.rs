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
//! | `spp` | u32: path samples per texel and layer (jittered over the texel) | — | 4 |
//! | `texels_per_pixel` | u32: layer texels across one image pixel (in-focus detail survives the resampling) | — | 2 |
//! | `margin` | f64: extra frame on each side, as a fraction of the chief rays' extent | — | 0.15 |

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::integrator::{PathTracer, RenderScene};
use crate::sampler::PixelSampler;
use glam::{DAffine3, DVec2, DVec3, Vec3};
use rayon::prelude::*;

/// Most layers.
pub const MAX_LAYERS: usize = 16;
/// Relative depth within which a jittered ray's hit is on the surface of the texel's centre ray.
pub const SAME_SURFACE: f32 = 0.05;
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
    /// texels are `texels_per_pixel` across one of the image's pixels.
    pub fn covering(
        camera: &Camera,
        width: u32,
        height: u32,
        margin: f64,
        texels_per_pixel: u32,
    ) -> Result<LayerFrame> {
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
        let size = DVec2::new(width as f64, height as f64) * texels_per_pixel.max(1) as f64;
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
    /// Layer texels across one image pixel.
    pub texels_per_pixel: u32,
    /// Maximum path depth of the shading.
    pub max_depth: u32,
    /// Seed.
    pub seed: u32,
}

impl Default for LayerSettings {
    fn default() -> Self {
        LayerSettings { count: 4, spp: 4, margin: 0.15, texels_per_pixel: 2, max_depth: 8, seed: 0 }
    }
}

impl LayerSettings {
    /// Checks the settings.
    pub fn validate(&self) -> Result<()> {
        if !(1..=MAX_LAYERS).contains(&self.count) {
            return Err(Error::settings("layers", format!("{} must be in 1..=16", self.count)));
        }
        if !(1..=65536).contains(&self.spp) {
            return Err(Error::settings("layer_spp", format!("{} must be in 1..=65536", self.spp)));
        }
        if !(1..=4).contains(&self.texels_per_pixel) {
            return Err(Error::settings("layer_texels", format!("{} must be in 1..=4", self.texels_per_pixel)));
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
    /// Radiance leaving that surface towards the centre (linear RGB, path traced; rays jittered
    /// over the texel, each shading its hit on that surface: within [`SAME_SURFACE`] of the
    /// centre's depth; rays that miss the surface do not count), or the environment's where the depth is +inf.
    pub radiance: Vec<Vec3>,
    /// Whether each texel was shaded: every texel of layer 0, and the hidden texels some camera
    /// ray can reach (the others hold zero radiance and are never looked up).
    pub shaded: Vec<bool>,
    /// Camera-to-world transform the layers were made with.
    pub to_world: DAffine3,
}

impl Layers {
    /// Traces the layers of `scene` seen from `to_world`'s origin through `frame`, for a camera
    /// whose rays cross the pupil plane (z = 0) within `pupil_radius_m` of the axis; None when
    /// `keep_going` turned false (checked per row).
    ///
    /// 1. Depths: every layer's depth from each texel's centre ray.
    /// 2. Which hidden texels any camera ray can reach: a ray from the pupil towards a hidden
    ///    surface at depth z moves in the image by at most A·(1/z_near − 1/z) (A the pupil
    ///    radius) before reaching it, so a hidden texel is reachable only if layer 0 has a
    ///    texel at or behind z within that radius (an N-buffer of layer 0's maximum depth
    ///    answers the window query in four lookups). Unreachable texels are not shaded.
    /// 3. Radiance: jittered rays over each texel, each shading its hit on the centre ray's
    ///    surface of each layer (so silhouettes do not mix surfaces into one layer).
    pub fn trace(
        scene: &RenderScene,
        to_world: DAffine3,
        frame: LayerFrame,
        settings: &LayerSettings,
        pupil_radius_m: f64,
        keep_going: &(dyn Fn() -> bool + Sync),
    ) -> Result<Option<Layers>> {
        settings.validate()?;
        let k_count = settings.count;
        let texels = frame.texels();
        let origin = to_world.transform_point3(DVec3::ZERO).as_vec3();
        // 1. Depths.
        let depth_rows: Vec<Vec<f32>> = (0..frame.height)
            .into_par_iter()
            .map(|row| {
                let mut depth = vec![f32::INFINITY; k_count * frame.width];
                if !keep_going() {
                    return depth;
                }
                for col in 0..frame.width {
                    let centre = frame.direction(DVec2::new(col as f64 + 0.5, row as f64 + 0.5));
                    let d = to_world.transform_vector3(centre).normalize().as_vec3();
                    let axial = (1.0 / centre.length()) as f32;
                    for (k, t) in peel(scene, origin, d, k_count).iter().enumerate() {
                        depth[k * frame.width + col] = t * axial;
                    }
                }
                depth
            })
            .collect();
        let mut depth_m = vec![f32::INFINITY; k_count * texels];
        for (row, d) in depth_rows.iter().enumerate() {
            for k in 0..k_count {
                let dst = k * texels + row * frame.width;
                depth_m[dst..dst + frame.width].copy_from_slice(&d[k * frame.width..(k + 1) * frame.width]);
            }
        }
        // 2. Reachable texels.
        let shaded = reachable(&frame, &depth_m, k_count, pupil_radius_m);
        // 3. Radiance, rows in parallel.
        let tracer = PathTracer { max_depth: settings.max_depth, ..PathTracer::default() };
        let env = &scene.scene().environment;
        let radiance_rows: Vec<Vec<Vec3>> = (0..frame.height)
            .into_par_iter()
            .map(|row| {
                let mut radiance = vec![Vec3::ZERO; k_count * frame.width];
                if !keep_going() {
                    return radiance;
                }
                for col in 0..frame.width {
                    let wanted = |k: usize| shaded[k * texels + row * frame.width + col];
                    let centre_depth = |k: usize| depth_m[k * texels + row * frame.width + col];
                    let mut sums = [Vec3::ZERO; MAX_LAYERS];
                    let mut counts = [0u32; MAX_LAYERS];
                    // Radiance from the path at hit `i` of ray `d` (peeled hits `hits`).
                    let shade = |d: Vec3, hits: &[f32], i: usize, sampler: &mut PixelSampler| {
                        // Start 1 % short of the hit (closer starts can miss it at grazing
                        // angles), but past the previous hit.
                        let t = hits[i];
                        let previous = if i > 0 { hits[i - 1] } else { 0.0 };
                        let clip = ((t * 0.99).max(0.5 * (previous + t)), f32::INFINITY);
                        tracer.trace_clipped(scene, origin, d, clip, sampler).radiance
                    };
                    for s in 0..settings.spp {
                        let mut sampler = PixelSampler::new(col as u32, row as u32, s, settings.seed ^ 0x1a7e_5eed);
                        let off = sampler.next_2d();
                        let dir = frame.direction(DVec2::new(col as f64 + off.x as f64, row as f64 + off.y as f64));
                        let axial = (1.0 / dir.length()) as f32;
                        let d = to_world.transform_vector3(dir).normalize().as_vec3();
                        // One hit more than layers: at this position the surface may lie deeper.
                        let hits = peel(scene, origin, d, k_count + 1);
                        for k in (0..k_count).filter(|&k| wanted(k)) {
                            let z = centre_depth(k);
                            let mut layer_sampler =
                                PixelSampler::new(col as u32, row as u32, s, settings.seed ^ (k as u32 + 1));
                            if !z.is_finite() {
                                sums[k] += crate::integrator::lights::env_radiance(env, d);
                                counts[k] += 1;
                                continue;
                            }
                            // This ray's hit on the centre's surface: the nearest in depth, if
                            // within SAME_SURFACE of it (else the surface does not cover this
                            // position and the sample says nothing about it).
                            let nearest = (0..hits.len()).min_by(|&a, &b| {
                                (hits[a] * axial - z).abs().total_cmp(&(hits[b] * axial - z).abs())
                            });
                            if let Some(i) = nearest.filter(|&i| (hits[i] * axial - z).abs() <= SAME_SURFACE * z) {
                                sums[k] += shade(d, &hits, i, &mut layer_sampler);
                                counts[k] += 1;
                            }
                        }
                    }
                    for k in (0..k_count).filter(|&k| wanted(k)) {
                        let value = if counts[k] > 0 {
                            sums[k] / counts[k] as f32
                        } else {
                            // No jittered ray met the surface: shade the centre ray's own hit.
                            let centre = frame.direction(DVec2::new(col as f64 + 0.5, row as f64 + 0.5));
                            let d = to_world.transform_vector3(centre).normalize().as_vec3();
                            let hits = peel(scene, origin, d, k + 1);
                            let mut sampler = PixelSampler::new(col as u32, row as u32, 0, settings.seed ^ 0x5eed_c0de);
                            if hits.len() > k {
                                shade(d, &hits, k, &mut sampler)
                            } else {
                                crate::integrator::lights::env_radiance(env, d)
                            }
                        };
                        radiance[k * frame.width + col] = value;
                    }
                }
                radiance
            })
            .collect();
        let mut radiance = vec![Vec3::ZERO; k_count * texels];
        for (row, r) in radiance_rows.iter().enumerate() {
            for k in 0..k_count {
                let dst = k * texels + row * frame.width;
                radiance[dst..dst + frame.width].copy_from_slice(&r[k * frame.width..(k + 1) * frame.width]);
            }
        }
        if !keep_going() {
            return Ok(None);
        }
        Ok(Some(Layers { frame, count: k_count, depth_m, radiance, shaded, to_world }))
    }

    /// Share of the hidden layers' surface texels (k ≥ 1, finite depth) that were shaded.
    pub fn hidden_shaded_fraction(&self) -> f64 {
        let t = self.frame.texels();
        let (mut n, mut shaded) = (0usize, 0usize);
        for i in t..self.count * t {
            if self.depth_m[i].is_finite() {
                n += 1;
                shaded += self.shaded[i] as usize;
            }
        }
        if n == 0 {
            0.0
        } else {
            shaded as f64 / n as f64
        }
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

/// Which texels some camera ray can reach (see [`Layers::trace`], step 2): all of layer 0, and
/// a hidden texel at depth z where layer 0 has a texel at or behind z (or the environment)
/// within A·(1/z_near − 1/z) of it.
fn reachable(frame: &LayerFrame, depth_m: &[f32], k_count: usize, pupil_radius_m: f64) -> Vec<bool> {
    let (w, h) = (frame.width, frame.height);
    let texels = frame.texels();
    let mut out = vec![false; k_count * texels];
    out[..texels].fill(true);
    if k_count == 1 {
        return out;
    }
    let layer0 = &depth_m[..texels];
    let z_near = layer0.iter().copied().fold(f32::INFINITY, f32::min) as f64;
    let texel = frame.texel_size().min_element();
    let nbuffer = NBuffer::max_of(layer0, w, h);
    for k in 1..k_count {
        for y in 0..h {
            for x in 0..w {
                let i = k * texels + y * w + x;
                let z = depth_m[i];
                if !z.is_finite() {
                    continue;
                }
                let reach = pupil_radius_m * (1.0 / z_near - 1.0 / z as f64).max(0.0) / texel;
                let r = (reach.ceil() as usize + 1).min(w.max(h));
                out[i] = nbuffer.max_in(x, y, r) >= z * (1.0 - 4e-3);
            }
        }
    }
    out
}

/// An N-buffer (Décoret 2005): level i holds, at each texel, the maximum over the 2^i × 2^i
/// square whose top-left corner it is, so the maximum over any square is four lookups.
struct NBuffer {
    width: usize,
    height: usize,
    levels: Vec<Vec<f32>>,
}

impl NBuffer {
    fn max_of(values: &[f32], width: usize, height: usize) -> NBuffer {
        let mut levels = vec![values.to_vec()];
        let mut size = 1usize;
        while size * 2 <= width.max(height) {
            let prev = levels.last().expect("level 0 exists");
            let mut next = prev.clone();
            for y in 0..height {
                for x in 0..width {
                    let (x2, y2) = ((x + size).min(width - 1), (y + size).min(height - 1));
                    let m = prev[y * width + x]
                        .max(prev[y * width + x2])
                        .max(prev[y2 * width + x])
                        .max(prev[y2 * width + x2]);
                    next[y * width + x] = m;
                }
            }
            levels.push(next);
            size *= 2;
        }
        NBuffer { width, height, levels }
    }

    /// Maximum over the square of half-side `r` around (x, y), clipped to the image.
    fn max_in(&self, x: usize, y: usize, r: usize) -> f32 {
        let (x0, y0) = (x.saturating_sub(r), y.saturating_sub(r));
        let (x1, y1) = ((x + r).min(self.width - 1), (y + r).min(self.height - 1));
        let side = (x1 - x0 + 1).max(y1 - y0 + 1);
        let level = (usize::BITS - 1 - side.leading_zeros()) as usize;
        let level = level.min(self.levels.len() - 1);
        let n = 1usize << level;
        let l = &self.levels[level];
        let xs = [x0, (x1 + 1).saturating_sub(n).max(x0)];
        let ys = [y0, (y1 + 1).saturating_sub(n).max(y0)];
        let mut m = f32::NEG_INFINITY;
        for &yy in &ys {
            for &xx in &xs {
                m = m.max(l[yy * self.width + xx]);
            }
        }
        m
    }
}
