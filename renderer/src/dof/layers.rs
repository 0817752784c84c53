//! Depth-peeled layers seen from the perspective centre: the shared input of the image-based
//! preview methods. Our ray tracer makes them directly, so no rasteriser and no frustum
//! matrices are needed, under tilt as anywhere else: each texel's jittered rays are peeled (the
//! first hit, then the next front-facing ones), their hits grouped into surfaces (a hit within
//! [`SAME_SURFACE`] of a surface's tangent plane belongs to it), and the K nearest surfaces are
//! the texel's layers, each with its depth, its coverage of the texel (the share of the rays that
//! met it: sub-texel objects and silhouettes keep their energy without mixing surfaces) and its
//! radiance towards the centre (those rays' paths from it). Behind the last surface of a texel
//! lies the environment.
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
/// Distance from the tangent plane of a texel's centre hit, relative to its depth, within which a
/// jittered ray's hit is on the same surface.
pub const SAME_SURFACE: f32 = 0.01;
/// Largest distance from the centre hit, relative to its depth, of a hit on the same surface.
pub const SAME_SURFACE_REACH: f32 = 0.5;
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
        // 0. Layers are seen through a centre of projection, which an orthographic camera has not.
        if matches!(camera, Camera::Orthographic(_)) {
            return Err(Error::settings(
                "method",
                "an orthographic camera renders with --method mc only (the layered methods need a centre of projection)",
            ));
        }
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
    /// Clipping planes along the view axis (m): only what lies between them is layered (as
    /// Monte Carlo's camera rays see only that).
    pub clip_m: (f64, f64),
}

impl Default for LayerSettings {
    fn default() -> Self {
        LayerSettings {
            count: 4,
            spp: 4,
            margin: 0.15,
            texels_per_pixel: 2,
            max_depth: 8,
            seed: 0,
            clip_m: (0.0, f64::INFINITY),
        }
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
    /// Planar depth along −z (m) of layer k's surface at each texel (the mean over the rays that
    /// met it); +inf for the environment behind the texel's last surface.
    pub depth_m: Vec<f32>,
    /// Radiance leaving that surface towards the centre (linear RGB: the mean of the paths from
    /// the hits of the rays that met it), or the environment's mean over the texel.
    pub radiance: Vec<Vec3>,
    /// Share of the jittered rays over each texel that met its surface (1 for the environment):
    /// the surface covers this much of the texel, and the rest shows what lies behind.
    pub coverage: Vec<f32>,
    /// Tangent plane of each surface, camera space: unit geometric normal n and offset n·q for a
    /// point q of it (NaN for the environment); a point p is on it where n·p − offset ≈ 0.
    pub planes: Vec<[f32; 4]>,
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
    /// 1. Surfaces: each texel's `spp` jittered rays peeled (K + 1 hits), their hits grouped by
    ///    surface; the K nearest surfaces by mean depth, then the environment.
    /// 2. Which hidden texels any camera ray can reach: a ray from the pupil towards a hidden
    ///    surface at depth z moves in the image by at most A·(1/z_near − 1/z) (A the pupil
    ///    radius) before reaching it, so a hidden texel is reachable only if layer 0 has a
    ///    texel at or behind z within that radius (an N-buffer of layer 0's maximum depth
    ///    answers the window query in four lookups). Unreachable texels are not shaded.
    /// 3. Radiance: the same rays, each path traced from its hit on each layer's surface.
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
        // 1. Surfaces: each texel's jittered rays, peeled, their hits grouped by surface.
        let jitter = |col: usize, row: usize, s: u32| {
            let mut sampler = PixelSampler::new(col as u32, row as u32, s, settings.seed ^ 0x1a7e_5eed);
            let off = sampler.next_2d();
            let dir = frame.direction(DVec2::new(col as f64 + off.x as f64, row as f64 + off.y as f64));
            ((1.0 / dir.length()) as f32, to_world.transform_vector3(dir).normalize().as_vec3())
        };
        // The clipping planes as distances along a ray of axial cosine `axial`.
        let clip_along = |axial: f32| {
            let (near, far) = settings.clip_m;
            ((near / axial as f64) as f32, (far / axial as f64) as f32)
        };
        let surface_rows: Vec<Vec<Surface>> = (0..frame.height)
            .into_par_iter()
            .map(|row| {
                let mut out = vec![Surface::EMPTY; k_count * frame.width];
                if !keep_going() {
                    return out;
                }
                for col in 0..frame.width {
                    let mut surfaces: Vec<Surface> = Vec::with_capacity(2 * k_count);
                    for s in 0..settings.spp {
                        let (axial, d) = jitter(col, row, s);
                        let mut seen = 0u64;
                        for hit in peel(scene, origin, d, k_count + 1, clip_along(axial)) {
                            let z = hit.t * axial;
                            match surfaces.iter().position(|c| c.holds(&hit)) {
                                Some(i) if seen & (1 << i) == 0 => {
                                    seen |= 1 << i;
                                    surfaces[i].depth_sum += z;
                                    surfaces[i].count += 1;
                                }
                                Some(_) => {}
                                None if surfaces.len() < 64 => {
                                    seen |= 1 << surfaces.len();
                                    surfaces.push(Surface {
                                        position: hit.position,
                                        normal: hit.normal,
                                        depth_sum: z,
                                        count: 1,
                                    });
                                }
                                None => {}
                            }
                        }
                    }
                    // The K nearest surfaces, then the environment.
                    surfaces.sort_by(|a, b| a.depth().total_cmp(&b.depth()));
                    surfaces.truncate(k_count);
                    for (k, c) in surfaces.into_iter().enumerate() {
                        out[k * frame.width + col] = c;
                    }
                }
                out
            })
            .collect();
        let mut surfaces = vec![Surface::EMPTY; k_count * texels];
        for (row, r) in surface_rows.iter().enumerate() {
            for k in 0..k_count {
                let dst = k * texels + row * frame.width;
                surfaces[dst..dst + frame.width].copy_from_slice(&r[k * frame.width..(k + 1) * frame.width]);
            }
        }
        let depth_m: Vec<f32> = surfaces.iter().map(|c| c.depth()).collect();
        let to_camera = to_world.inverse();
        let planes: Vec<[f32; 4]> = surfaces
            .iter()
            .map(|c| {
                let n = to_camera.transform_vector3(c.normal.as_dvec3()).normalize();
                let q = to_camera.transform_point3(c.position.as_dvec3());
                if c.count == 0 || !n.is_finite() {
                    [f32::NAN; 4]
                } else {
                    [n.x as f32, n.y as f32, n.z as f32, n.dot(q) as f32]
                }
            })
            .collect();
        let coverage: Vec<f32> =
            surfaces.iter().map(|c| if c.count == 0 { 1.0 } else { c.count as f32 / settings.spp as f32 }).collect();
        // 2. Reachable texels.
        let shaded = reachable(&frame, &depth_m, k_count, pupil_radius_m);
        // 3. Radiance: the same rays, each shading its hit on each layer's surface.
        let tracer = PathTracer { max_depth: settings.max_depth, ..PathTracer::default() };
        let radiance_rows: Vec<Vec<Vec3>> = (0..frame.height)
            .into_par_iter()
            .map(|row| {
                let mut radiance = vec![Vec3::ZERO; k_count * frame.width];
                if !keep_going() {
                    return radiance;
                }
                for col in 0..frame.width {
                    let at = |k: usize| k * texels + row * frame.width + col;
                    let mut sums = [Vec3::ZERO; MAX_LAYERS];
                    let mut counts = [0u32; MAX_LAYERS];
                    for s in 0..settings.spp {
                        let (axial, d) = jitter(col, row, s);
                        let hits = peel(scene, origin, d, k_count + 1, clip_along(axial));
                        for k in (0..k_count).filter(|&k| shaded[at(k)]) {
                            let surface = &surfaces[at(k)];
                            if surface.count == 0 {
                                // The environment, behind every surface of the texel.
                                sums[k] += crate::integrator::lights::camera_env_radiance(scene.scene(), d);
                                counts[k] += 1;
                                continue;
                            }
                            let Some(i) = hits.iter().position(|h| surface.holds(h)) else { continue };
                            // Start 1 % short of the hit (closer starts can miss it at grazing
                            // angles), but past the previous hit.
                            let (t, previous) = (hits[i].t, if i > 0 { hits[i - 1].t } else { 0.0 });
                            let clip = ((t * 0.99).max(0.5 * (previous + t)), f32::INFINITY);
                            let mut sampler =
                                PixelSampler::new(col as u32, row as u32, s, settings.seed ^ (k as u32 + 1));
                            sums[k] += tracer.trace_clipped(scene, origin, d, clip, &mut sampler).radiance;
                            counts[k] += 1;
                        }
                    }
                    for k in 0..k_count {
                        if counts[k] > 0 {
                            radiance[k * frame.width + col] = sums[k] / counts[k] as f32;
                        }
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
        Ok(Some(Layers { frame, count: k_count, depth_m, radiance, coverage, planes, shaded, to_world }))
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
        crate::integrator::lights::camera_env_radiance(scene.scene(), d)
    }
}

/// One surface met by a texel's jittered rays: the tangent plane of its first hit, and the
/// planar depths and number of the rays that met it (count 0: the environment).
#[derive(Debug, Clone, Copy)]
struct Surface {
    position: Vec3,
    normal: Vec3,
    depth_sum: f32,
    count: u32,
}

impl Surface {
    const EMPTY: Surface = Surface { position: Vec3::ZERO, normal: Vec3::ZERO, depth_sum: 0.0, count: 0 };

    /// Mean planar depth of the rays that met it (+inf for the environment).
    fn depth(&self) -> f32 {
        if self.count == 0 {
            f32::INFINITY
        } else {
            self.depth_sum / self.count as f32
        }
    }

    /// Whether `hit` lies on this surface: within [`SAME_SURFACE`] of its tangent plane and
    /// [`SAME_SURFACE_REACH`] of its first hit, relative to the depth.
    fn holds(&self, hit: &Peeled) -> bool {
        let z = self.depth().min(hit.t);
        self.count > 0
            && (hit.position - self.position).dot(self.normal).abs() <= SAME_SURFACE * z
            && (hit.position - self.position).length() <= SAME_SURFACE_REACH * z
    }
}

/// A peeled hit: distance along the ray, world position and geometric normal.
#[derive(Debug, Clone, Copy)]
struct Peeled {
    t: f32,
    position: Vec3,
    normal: Vec3,
}

/// Within `clip` (distances along the ray), the first hit (what the centre sees, from either side) and the
/// next `k − 1` front-facing hits (double-sided materials count from both sides; the back
/// faces of closed objects are skipped): each peel restarts just past the previous hit.
fn peel(scene: &RenderScene, origin: Vec3, dir: Vec3, k: usize, clip: (f32, f32)) -> Vec<Peeled> {
    let mut out = Vec::with_capacity(k);
    let mut t0 = clip.0.max(0.0);
    let mut guard = 0;
    while out.len() < k && guard < 64 && t0 < clip.1 {
        guard += 1;
        let o = origin + dir * t0;
        let Some(hit) = scene.intersect_seen(o, dir, clip.1 - t0) else { break };
        let t = t0 + hit.t;
        let double_sided = scene.scene().materials[hit.material_id as usize].double_sided;
        if out.is_empty() || hit.front_face || double_sided {
            out.push(Peeled { t, position: hit.position, normal: hit.geometric_normal });
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
