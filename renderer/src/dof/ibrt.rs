//! Image-based ray tracing: camera rays of any model (thin lens, tilt-shift sensor, a real lens
//! traced or through its table) intersected with the [`Layers`] as height fields, instead of the
//! scene.
//!
//! * A ray's image in the layer frame is a straight segment, affine in inverse depth w = 1/z:
//!   tangent(w) = a + b·w with a the vanishing point; it is walked texel by texel (a 2-D DDA)
//!   from the nearest layer depth to the farthest.
//! * Each layer texel is a surface element spanning depths [lo, hi]: half-way to each neighbour
//!   on the same surface (a depth step below [`SURFACE_JUMP`], or inverse depth continuing
//!   the opposite neighbour's step within [`PLANAR_TOLERANCE`]: planes at grazing angles) and at least ±[`THICKNESS`] of its
//!   depth, so continuous surfaces are watertight and depth discontinuities stay open. The ray hits
//!   the first element whose span meets the ray's depth span over the texel (partial occlusion:
//!   a ray that passes an edge of a near layer reaches the layers behind it).
//! * Acceleration: a min/max mip pyramid of the spans over all layers (an N-buffer restricted to
//!   power-of-two squares); the walk jumps over the largest block whose span the ray's depth
//!   span misses.
//! * A ray that leaves the frame or passes every layer sees the environment in its direction
//!   (highlights outside the frame are lost: one of the method's limits).

use super::layers::Layers;
use crate::camera::CameraRay;
use crate::integrator::{PathSample, RenderScene};
use glam::{DVec2, DVec3, Vec3};

/// Relative depth step above which two neighbouring texels are on different surfaces.
pub const SURFACE_JUMP: f32 = 0.03;
/// Largest second difference of inverse depth, relative to the step, of three texels on one
/// surface (0 on a plane).
pub const PLANAR_TOLERANCE: f32 = 0.25;
/// Most partly covering elements one ray passes through before the environment.
pub const MAX_PARTIAL_HITS: usize = 8;
/// Least half-thickness of a layer element, relative to its depth.
pub const THICKNESS: f32 = 2e-3;

/// The layers prepared for ray queries (spans and their min/max pyramid).
#[derive(Debug, Clone)]
pub struct LayerTracer {
    layers: Layers,
    /// Per layer and texel: depth span [lo, hi] (m); lo = +inf where the layer is empty.
    span: Vec<[f32; 2]>,
    /// Pyramid level l ≥ 1: per 2^l block, [min lo, max hi] over all layers; level 0 is the
    /// per-texel union over the layers.
    mips: Vec<Vec<[f32; 2]>>,
    /// Width of each pyramid level.
    level_widths: Vec<usize>,
    /// Nearest and farthest finite depth.
    depth_range: [f32; 2],
}

impl LayerTracer {
    /// Prepares `layers`.
    pub fn new(layers: Layers) -> LayerTracer {
        let f = layers.frame;
        let (w, h) = (f.width, f.height);
        // 1. Per-element spans from the neighbours on the same surface.
        let mut span = vec![[f32::INFINITY, f32::NEG_INFINITY]; layers.count * f.texels()];
        for k in 0..layers.count {
            for y in 0..h {
                for x in 0..w {
                    let i = layers.index(k, x, y);
                    let z = layers.depth_m[i];
                    if !z.is_finite() {
                        continue;
                    }
                    let (mut lo, mut hi) = (z * (1.0 - THICKNESS), z * (1.0 + THICKNESS));
                    let neighbours = [(-1i64, 0i64), (1, 0), (0, -1), (0, 1), (-1, -1), (1, 1), (-1, 1), (1, -1)];
                    let layers = &layers;
                    let depths_at = |nx: i64, ny: i64| {
                        let inside = nx >= 0 && ny >= 0 && nx < w as i64 && ny < h as i64;
                        (0..layers.count)
                            .map(move |kk| {
                                if inside {
                                    layers.depth_m[layers.index(kk, nx as usize, ny as usize)]
                                } else {
                                    f32::INFINITY
                                }
                            })
                            .filter(|z| z.is_finite())
                    };
                    for (dx, dy) in neighbours {
                        // The same surface may sit in another layer at the neighbour: it is the same
                        // surface if the depth step is small, or if inverse depth (affine in the
                        // image for a plane) continues the step from the opposite neighbour, as it
                        // does on a plane seen at a grazing angle.
                        let (x, y) = (x as i64, y as i64);
                        for zn in depths_at(x + dx, y + dy) {
                            let step = (1.0 / zn - 1.0 / z).abs();
                            let planar = depths_at(x - dx, y - dy)
                                .any(|zo| (1.0 / zn - 2.0 / z + 1.0 / zo).abs() < PLANAR_TOLERANCE * step);
                            if (zn - z).abs() < SURFACE_JUMP * z || planar {
                                let mid = 0.5 * (z + zn);
                                lo = lo.min(mid);
                                hi = hi.max(mid);
                            }
                        }
                    }
                    span[i] = [lo, hi];
                }
            }
        }
        // 2. The pyramid: level 0 = union over layers, then 2 × 2 reductions.
        let mut level0 = vec![[f32::INFINITY, f32::NEG_INFINITY]; f.texels()];
        for k in 0..layers.count {
            for (t, m) in level0.iter_mut().enumerate() {
                let s = span[k * f.texels() + t];
                m[0] = m[0].min(s[0]);
                m[1] = m[1].max(s[1]);
            }
        }
        let mut depth_range = [f32::INFINITY, 0.0f32];
        for m in &level0 {
            if m[0].is_finite() {
                depth_range[0] = depth_range[0].min(m[0]);
                depth_range[1] = depth_range[1].max(m[1]);
            }
        }
        let mut mips = vec![level0];
        let (mut lw, mut lh) = (w, h);
        while lw > 1 || lh > 1 {
            let (nw, nh) = (lw.div_ceil(2), lh.div_ceil(2));
            let prev = mips.last().expect("level 0 exists");
            let mut next = vec![[f32::INFINITY, f32::NEG_INFINITY]; nw * nh];
            for y in 0..lh {
                for x in 0..lw {
                    let s = prev[y * lw + x];
                    let m = &mut next[(y / 2) * nw + x / 2];
                    m[0] = m[0].min(s[0]);
                    m[1] = m[1].max(s[1]);
                }
            }
            mips.push(next);
            (lw, lh) = (nw, nh);
        }
        let mut level_widths = vec![w];
        while level_widths.len() < mips.len() {
            level_widths.push(level_widths.last().expect("level 0 exists").div_ceil(2));
        }
        LayerTracer { layers, span, mips, level_widths, depth_range }
    }

    /// The layers.
    pub fn layers(&self) -> &Layers {
        &self.layers
    }

    /// The radiance along camera-space ray `ray` (origin in metres), as a path sample (alpha:
    /// the coverage of the layer elements it met; depth along the ray to the first). Elements
    /// that cover part of their texel ([`Layers::coverage`]) pass the rest on to what lies
    /// behind them. Only elements whose distance along the ray lies within `clip` (m, the
    /// clipping planes) count; beyond them the environment shows, as in Monte Carlo.
    pub fn shade(&self, scene: &RenderScene, ray: &CameraRay, clip: (f32, f32)) -> PathSample {
        let mut out = PathSample::miss(Vec3::ZERO);
        let mut transmitted = 1.0f32;
        let mut after_z = 0.0f64;
        let d = ray.direction.normalize();
        for _ in 0..MAX_PARTIAL_HITS {
            let Some((index, z)) = self.intersect_beyond(ray.origin, ray.direction, after_z) else { break };
            let t = ((z + ray.origin.z) / -d.z) as f32;
            if t > clip.1 {
                break;
            }
            after_z = z;
            if t < clip.0 {
                continue;
            }
            if out.depth_m.is_infinite() {
                out.depth_m = t;
            }
            let coverage = self.layers.coverage[index];
            out.radiance += transmitted * coverage * self.layers.radiance[index];
            out.alpha += transmitted * coverage;
            transmitted *= 1.0 - coverage;
            if transmitted < 1e-3 {
                return out;
            }
        }
        out.radiance += transmitted * self.layers.environment(scene, ray.direction);
        out
    }

    /// The first layer element along the ray: its index and planar depth (m).
    pub fn intersect(&self, origin: DVec3, dir: DVec3) -> Option<(usize, f64)> {
        self.intersect_beyond(origin, dir, 0.0)
    }

    /// The first layer element along the ray deeper than `after_z` (m): its index and planar
    /// depth.
    pub fn intersect_beyond(&self, origin: DVec3, dir: DVec3, after_z: f64) -> Option<(usize, f64)> {
        let frame = self.layers.frame;
        let [z_near, z_far] = self.depth_range;
        if !(z_near.is_finite()) || dir.z >= -1e-9 {
            return None;
        }
        // 1. The segment in texel coordinates, affine in w = 1/z: texel(w) = p0 + (p1 − p0)·s
        //    with w = w0 + (w1 − w0)·s, from the nearest depth to the farthest.
        let a = DVec2::new(dir.x / -dir.z, dir.y / -dir.z);
        let b = DVec2::new(origin.x + origin.z * a.x, origin.y + origin.z * a.y);
        let z0 = (z_near as f64 * 0.999).max(-origin.z + 1e-6).max(after_z * (1.0 - 2.0 * THICKNESS as f64));
        let z1 = z_far as f64 * 1.001;
        if z1 <= z0 {
            return None;
        }
        let (w0, w1) = (1.0 / z0, 1.0 / z1);
        let p0 = frame.texel_of_tangent(a + b * w0);
        let p1 = frame.texel_of_tangent(a + b * w1);
        // 2. Clip to the frame.
        let size = DVec2::new(frame.width as f64, frame.height as f64);
        let (s_in, s_out) = clip_segment(p0, p1, size)?;
        let depth_at = |s: f64| 1.0 / (w0 + (w1 - w0) * s);
        let delta = p1 - p0;
        // 3. Walk (maximum-mipmap traversal): at the current level, jump the block if the ray's
        //    depth span misses the block's, and go up a level; otherwise go down one, and at
        //    level 0 test the texel's elements.
        let mut s = s_in;
        let top = self.mips.len() - 1;
        let mut level = top.min(4);
        let mut guard = 0usize;
        while s < s_out && guard < 1 << 22 {
            guard += 1;
            let p = p0 + delta * (s + 1e-9);
            let tx = p.x.floor().clamp(0.0, size.x - 1.0) as usize;
            let ty = p.y.floor().clamp(0.0, size.y - 1.0) as usize;
            let (bx, by) = (tx >> level, ty >> level);
            let m = self.mips[level][by * self.level_widths[level] + bx];
            let cell = (1usize << level) as f64;
            let exit = cell_exit(p0, delta, s, DVec2::new(bx as f64 * cell, by as f64 * cell), cell).min(s_out);
            let (za, zb) = (depth_at(s) as f32, depth_at(exit) as f32);
            if !(m[0] <= zb && za <= m[1]) {
                s = exit.max(s + 1e-12);
                level = (level + 1).min(top);
                continue;
            }
            if level > 0 {
                level -= 1;
                continue;
            }
            // The texel: the nearest element whose span meets the ray's.
            let mut best: Option<(usize, f64)> = None;
            for k in 0..self.layers.count {
                let i = self.layers.index(k, tx, ty);
                let [lo, hi] = self.span[i];
                let z = self.layers.depth_m[i] as f64;
                if lo <= zb && za <= hi && z > after_z && best.is_none_or(|(_, bz)| z < bz) {
                    best = Some((i, z));
                }
            }
            if best.is_some() {
                return best;
            }
            s = exit.max(s + 1e-12);
        }
        None
    }
}

/// The parameter range [s_in, s_out] ⊂ [0, 1] of segment p0 → p1 inside [0, size]; None if
/// the segment misses.
fn clip_segment(p0: DVec2, p1: DVec2, size: DVec2) -> Option<(f64, f64)> {
    let (mut s_in, mut s_out) = (0.0f64, 1.0f64);
    let d = p1 - p0;
    for axis in 0..2 {
        let (o, v, hi) = (p0[axis], d[axis], size[axis]);
        if v.abs() < 1e-15 {
            if o < 0.0 || o >= hi {
                return None;
            }
            continue;
        }
        let (mut t0, mut t1) = ((0.0 - o) / v, (hi - o) / v);
        if t0 > t1 {
            std::mem::swap(&mut t0, &mut t1);
        }
        s_in = s_in.max(t0);
        s_out = s_out.min(t1);
    }
    (s_in < s_out).then_some((s_in, s_out))
}

/// Where the segment p0 + delta·s, at parameter `s` inside the square cell [corner, corner +
/// size]², leaves it.
fn cell_exit(p0: DVec2, delta: DVec2, s: f64, corner: DVec2, size: f64) -> f64 {
    let mut exit = f64::INFINITY;
    for axis in 0..2 {
        let v = delta[axis];
        if v.abs() < 1e-15 {
            continue;
        }
        let bound = if v > 0.0 { corner[axis] + size } else { corner[axis] };
        let t = (bound - p0[axis]) / v;
        exit = exit.min(t);
    }
    exit.max(s)
}
