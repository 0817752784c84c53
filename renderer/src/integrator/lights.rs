//! Light sampling: one discrete distribution over every light, proportional to emitted power.
//!
//! | light | power used for selection |
//! |---|---|
//! | point | 4π·lum(I) |
//! | spot | 2π·(1 − (cos inner + cos outer)/2)·lum(I) (pbrt's spot power) |
//! | directional | π·r²·lum(E), r = scene bounding-sphere radius |
//! | emissive triangle | π·area·lum(emissive factor) (×2 double sided); the emissive texture is ignored for selection but used for radiance |
//! | environment | 4π²·r²·lum(mean radiance) (mean estimated with the environment's own importance sampling) |
//!
//! The selection pmf is the difference of consecutive entries of the f32 CDF that is actually
//! searched, so selection probabilities and the pmf used in estimators and MIS weights agree
//! exactly (a light whose CDF interval rounds to zero is never picked and has pmf 0, which MIS
//! then treats as BSDF-only).
//!
//! Punctual lights follow KHR_lights_punctual: range window `clamp(1 − (d/range)⁴, 0, 1)²`, spot
//! attenuation `clamp((cd − cos outer)/(cos inner − cos outer), 0, 1)²` with cd the cosine to the
//! axis (Blender's spot blend is a smoothstep on a different variable; glTF is followed here).
//! Emissive triangles emit from their front side (counter-clockwise winding) only, unless the
//! material is double sided.

use std::f32::consts::PI;

use glam::{Vec2, Vec3};

use super::accel::{offset_ray_origin, AlphaTest, RenderScene};
use super::bsdf::luminance;
use crate::scene::{Environment, Light, Scene};

/// Environment radiance toward `dir` (unit, world).
#[inline]
pub fn env_radiance(env: &Environment, dir: Vec3) -> Vec3 {
    env.radiance(dir)
}

/// Samples a direction of the environment: (direction, radiance, solid-angle pdf).
#[inline]
pub fn env_sample(env: &Environment, u: Vec2) -> Option<(Vec3, Vec3, f32)> {
    env.sample(u)
}

/// Solid-angle pdf of [`env_sample`] producing `dir`.
#[inline]
pub fn env_pdf(env: &Environment, dir: Vec3) -> f32 {
    env.pdf(dir)
}

/// Uniform direction on the unit sphere.
#[inline]
pub fn sample_uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum LightKind {
    /// Index into `Scene::lights`.
    Punctual(u32),
    /// Mesh triangle index.
    Triangle(u32),
    Environment,
}

/// A light sample as seen from a shading point.
#[derive(Debug, Clone, Copy)]
pub struct LightSample {
    /// Unit direction from the shading point toward the light.
    pub wi: Vec3,
    /// Incident radiance (area lights, environment) or radiance-equivalent `I/d²`, `E`
    /// (punctual lights), before dividing by `pdf`.
    pub radiance: Vec3,
    /// Selection pmf × solid-angle pdf (area lights, environment) or the selection pmf alone
    /// (delta lights).
    pub pdf: f32,
    /// Delta light (point, spot, directional): no MIS.
    pub delta: bool,
    /// Shadow-ray end point (robustly offset off an area light), or None for lights at
    /// infinity.
    pub target: Option<Vec3>,
}

/// Light list and selection distribution.
#[derive(Debug, Clone, Default)]
pub struct LightSet {
    kinds: Vec<LightKind>,
    /// n + 1 entries, cdf[0] = 0, cdf[n] = 1.
    cdf: Vec<f32>,
    /// Mesh triangle → light index (u32::MAX: not a light); empty when no triangle emits.
    tri_light: Vec<u32>,
    env_light: Option<u32>,
    scene_radius: f32,
}

impl LightSet {
    pub(crate) fn build(scene: &Scene, valid_tris: &[u32], bmin: Vec3, bmax: Vec3) -> LightSet {
        let radius = if bmax.cmpge(bmin).all() { 0.5 * (bmax - bmin).length() } else { 0.0 };
        let radius = radius.max(1e-3);
        let mut kinds = Vec::new();
        let mut power: Vec<f64> = Vec::new();
        for (i, l) in scene.lights.iter().enumerate() {
            let p = match *l {
                Light::Point { intensity, .. } => 4.0 * PI * luminance(intensity),
                Light::Spot { intensity, inner_cone_rad, outer_cone_rad, .. } => {
                    2.0 * PI * (1.0 - 0.5 * (inner_cone_rad.cos() + outer_cone_rad.cos())) * luminance(intensity)
                }
                Light::Directional { irradiance, .. } => PI * radius * radius * luminance(irradiance),
            };
            if p.is_finite() && p > 0.0 {
                kinds.push(LightKind::Punctual(i as u32));
                power.push(p as f64);
            }
        }
        let mesh = &scene.mesh;
        let emissive: Vec<bool> = scene.materials.iter().map(|m| m.is_emissive()).collect();
        let mut tri_light = Vec::new();
        if emissive.iter().any(|&e| e) {
            for &t in valid_tris {
                let m = &scene.materials[mesh.material_ids[t as usize] as usize];
                if !m.is_emissive() {
                    continue;
                }
                let [a, b, c] = mesh.indices[t as usize].map(|i| mesh.positions[i as usize]);
                let area = 0.5 * (b - a).cross(c - a).length();
                let sides = if m.double_sided { 2.0 } else { 1.0 };
                let p = PI * area * luminance(m.emissive) * sides;
                if p.is_finite() && p > 0.0 {
                    if tri_light.is_empty() {
                        tri_light = vec![u32::MAX; mesh.indices.len()];
                    }
                    tri_light[t as usize] = kinds.len() as u32;
                    kinds.push(LightKind::Triangle(t));
                    power.push(p as f64);
                }
            }
        }
        let mut env_light = None;
        if !scene.environment.is_black() {
            // Mean luminance over the sphere, (1/4π)∫L dω, estimated with the environment's own
            // importance sampling (stratified) so that small bright suns are not missed.
            const N: u32 = 32;
            let mut sum = 0.0f64;
            for i in 0..N {
                for j in 0..N {
                    let u = Vec2::new((i as f32 + 0.5) / N as f32, (j as f32 + 0.5) / N as f32);
                    if let Some((_, le, pdf)) = env_sample(&scene.environment, u) {
                        if pdf > 0.0 && pdf.is_finite() {
                            sum += (luminance(le) / pdf) as f64;
                        }
                    }
                }
            }
            let mean = sum / (N * N) as f64 / (4.0 * std::f64::consts::PI);
            if mean > 0.0 && mean.is_finite() {
                env_light = Some(kinds.len() as u32);
                kinds.push(LightKind::Environment);
                power.push(4.0 * (PI as f64).powi(2) * (radius as f64).powi(2) * mean);
            }
        }
        let total: f64 = power.iter().sum();
        let mut cdf = Vec::with_capacity(kinds.len() + 1);
        cdf.push(0.0f32);
        let mut acc = 0.0f64;
        for p in &power {
            acc += p;
            cdf.push((acc / total) as f32);
        }
        if let Some(last) = cdf.last_mut() {
            *last = 1.0;
        }
        if kinds.is_empty() {
            cdf.clear();
        }
        LightSet { kinds, cdf, tri_light, env_light, scene_radius: radius }
    }

    /// Number of lights.
    pub fn len(&self) -> usize {
        self.kinds.len()
    }

    /// No lights at all.
    pub fn is_empty(&self) -> bool {
        self.kinds.is_empty()
    }

    #[inline]
    fn pmf(&self, i: usize) -> f32 {
        self.cdf[i + 1] - self.cdf[i]
    }

    /// Picks a light: (index, pmf).
    #[inline]
    fn pick(&self, u: f32) -> Option<(usize, f32)> {
        if self.kinds.is_empty() {
            return None;
        }
        let u = u.clamp(0.0, 1.0 - f32::EPSILON);
        // First index with cdf[i + 1] > u.
        let i = self.cdf[1..].partition_point(|&c| c <= u).min(self.kinds.len() - 1);
        let p = self.pmf(i);
        if p > 0.0 {
            Some((i, p))
        } else {
            None
        }
    }

    /// Selection pmf of the environment (0 when it is not a light).
    #[inline]
    pub fn env_pmf(&self) -> f32 {
        self.env_light.map_or(0.0, |i| self.pmf(i as usize))
    }

    /// Selection pmf of mesh triangle `tri` as a light (0 when it does not emit).
    #[inline]
    pub fn triangle_pmf(&self, tri: u32) -> f32 {
        match self.tri_light.get(tri as usize) {
            Some(&i) if i != u32::MAX => self.pmf(i as usize),
            _ => 0.0,
        }
    }

    /// Radius of the scene's bounding sphere.
    pub fn scene_radius(&self) -> f32 {
        self.scene_radius
    }
}

/// glTF range window.
#[inline]
fn range_window(d: f32, range: Option<f32>) -> f32 {
    match range {
        Some(r) if r > 0.0 && r.is_finite() => {
            let x = d / r;
            let x2 = x * x;
            let w = (1.0 - x2 * x2).clamp(0.0, 1.0);
            w * w
        }
        _ => 1.0,
    }
}

/// KHR_lights_punctual spot attenuation for `cd` = cos(angle to the axis).
#[inline]
pub fn spot_attenuation(cd: f32, inner: f32, outer: f32) -> f32 {
    let cos_outer = outer.cos();
    let scale = 1.0 / (inner.cos() - cos_outer).max(0.001);
    let a = ((cd - cos_outer) * scale).clamp(0.0, 1.0);
    a * a
}

impl RenderScene {
    /// Samples a light for shading point `p`: `u_pick` selects the light, `u` the point on it. None when nothing can be sampled.
    pub fn sample_light(&self, p: Vec3, u_pick: f32, u: Vec2) -> Option<LightSample> {
        let (i, pmf) = self.lights.pick(u_pick)?;
        match self.lights.kinds[i] {
            LightKind::Punctual(li) => {
                let light = self.scene().lights[li as usize];
                let (wi, radiance, target) = match light {
                    Light::Point { position, intensity, range } => {
                        let d = position - p;
                        let d2 = d.length_squared();
                        let dist = d2.sqrt();
                        if !(dist > 0.0) {
                            return None;
                        }
                        (d / dist, intensity * (range_window(dist, range) / d2), Some(position))
                    }
                    Light::Spot { position, direction, intensity, inner_cone_rad, outer_cone_rad, range } => {
                        let d = position - p;
                        let d2 = d.length_squared();
                        let dist = d2.sqrt();
                        if !(dist > 0.0) {
                            return None;
                        }
                        let wi = d / dist;
                        let cd = direction.normalize_or_zero().dot(-wi);
                        let att = spot_attenuation(cd, inner_cone_rad, outer_cone_rad) * range_window(dist, range);
                        (wi, intensity * (att / d2), Some(position))
                    }
                    Light::Directional { direction, irradiance } => {
                        let wi = -direction.normalize_or_zero();
                        if wi == Vec3::ZERO {
                            return None;
                        }
                        (wi, irradiance, None)
                    }
                };
                if radiance == Vec3::ZERO || !radiance.is_finite() {
                    return None;
                }
                Some(LightSample { wi, radiance, pdf: pmf, delta: true, target })
            }
            LightKind::Triangle(tri) => {
                let scene = self.scene();
                let mesh = &scene.mesh;
                let mat = &scene.materials[mesh.material_ids[tri as usize] as usize];
                let [a, b, c] = mesh.indices[tri as usize].map(|i| mesh.positions[i as usize]);
                // Uniform point: barycentrics (1 − √u₀, √u₀(1 − u₁), √u₀·u₁).
                let su = u.x.sqrt();
                let (w0, w1, w2) = (1.0 - su, su * (1.0 - u.y), su * u.y);
                let q = a * w0 + b * w1 + c * w2;
                let cross = (b - a).cross(c - a);
                let area2 = cross.length();
                if !(area2 > 0.0) {
                    return None;
                }
                let nl = cross / area2;
                let area = 0.5 * area2;
                let d = q - p;
                let dist2 = d.length_squared();
                let dist = dist2.sqrt();
                if !(dist > 0.0) {
                    return None;
                }
                let wi = d / dist;
                let cos_l = -nl.dot(wi); // > 0: p sees the front side
                if cos_l <= 0.0 && !mat.double_sided {
                    return None;
                }
                let cos_l = cos_l.abs();
                if cos_l < 1e-7 {
                    return None;
                }
                let (uv0, uv1) = if mesh.uv0.len() == mesh.positions.len() {
                    let [i0, i1, i2] = mesh.indices[tri as usize].map(|i| i as usize);
                    let uv0 = mesh.uv0[i0] * w0 + mesh.uv0[i1] * w1 + mesh.uv0[i2] * w2;
                    let uv1 = if mesh.uv1.len() == mesh.positions.len() { mesh.uv1[i0] * w0 + mesh.uv1[i1] * w1 + mesh.uv1[i2] * w2 } else { uv0 };
                    (uv0, uv1)
                } else {
                    (Vec2::ZERO, Vec2::ZERO)
                };
                let mut le = mat.emissive * self.texture(mat.emissive_texture, uv0, uv1).map_or(Vec3::ONE, |t| t.truncate());
                // Cut-outs of the emitter itself: Mask removes, Blend emits with weight alpha
                // (the expected value of stochastic opacity).
                match self.alpha_tests[mesh.material_ids[tri as usize] as usize] {
                    AlphaTest::None => {}
                    AlphaTest::Mask(cutoff) => {
                        if self.alpha_at(tri, w1, w2) < cutoff {
                            return None;
                        }
                    }
                    AlphaTest::Stochastic => le *= self.alpha_at(tri, w1, w2).clamp(0.0, 1.0),
                }
                if le == Vec3::ZERO {
                    return None;
                }
                let pdf = pmf * dist2 / (area * cos_l);
                if !(pdf > 0.0) || !pdf.is_finite() {
                    return None;
                }
                let target = offset_ray_origin(q, if nl.dot(wi) < 0.0 { nl } else { -nl });
                Some(LightSample { wi, radiance: le, pdf, delta: false, target: Some(target) })
            }
            LightKind::Environment => {
                let (wi, radiance, pdf) = env_sample(&self.scene().environment, u)?;
                let pdf = pdf * pmf;
                if !(pdf > 0.0) || !pdf.is_finite() || radiance == Vec3::ZERO {
                    return None;
                }
                Some(LightSample { wi, radiance, pdf, delta: false, target: None })
            }
        }
    }

    /// Pdf (selection × solid angle) with which [`RenderScene::sample_light`] would have produced
    /// a point on emissive triangle `tri` seen at distance `dist` along unit `dir`.
    pub fn triangle_light_pdf(&self, tri: u32, dir: Vec3, dist: f32, geometric_normal: Vec3) -> f32 {
        let pmf = self.lights.triangle_pmf(tri);
        if pmf == 0.0 {
            return 0.0;
        }
        let mesh = &self.scene().mesh;
        let [a, b, c] = mesh.indices[tri as usize].map(|i| mesh.positions[i as usize]);
        let area = 0.5 * (b - a).cross(c - a).length();
        let cos_l = geometric_normal.dot(dir).abs();
        let pdf = pmf * dist * dist / (area * cos_l);
        if pdf.is_finite() {
            pdf
        } else {
            0.0
        }
    }

    /// Pdf (selection × solid angle) of sampling the environment toward `dir`.
    pub fn env_light_pdf(&self, dir: Vec3) -> f32 {
        let pmf = self.lights.env_pmf();
        if pmf == 0.0 {
            return 0.0;
        }
        pmf * env_pdf(&self.scene().environment, dir)
    }
}
