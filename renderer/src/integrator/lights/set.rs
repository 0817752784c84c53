//! The light set: light list, power distribution and light tree built from a scene.

use std::f32::consts::{FRAC_PI_2, PI};

use glam::{Vec2, Vec3};

use super::tree::{LightBounds, LightTree};
use super::{env_sample, LightKind, LightSelection};
use crate::integrator::bsdf::luminance;
use crate::scene::{Light, Scene};

// ------------------------------------------------------------------------------------------
// The light set.

/// The emissive triangles of one instance, for [`LightSet::build`].
#[derive(Debug, Clone)]
pub struct EmitterGroup {
    /// Index into `Scene::instances`.
    pub instance: u32,
    /// Triangles of the instance's mesh (the size of its slot in the triangle → light table).
    pub mesh_triangles: u32,
    /// Its valid triangles with an emissive material.
    pub triangles: Vec<u32>,
}

/// Light list and selection distributions.
#[derive(Debug, Clone, Default)]
pub struct LightSet {
    pub(in crate::integrator) kinds: Vec<LightKind>,
    /// Power distribution: n + 1 entries, cdf[0] = 0, cdf[n] = 1.
    cdf: Vec<f32>,
    /// Instance → start of its slot in `tri_light` (u32::MAX: no emitter); empty when no
    /// triangle emits.
    tri_light_base: Vec<u32>,
    /// Slot start + mesh triangle → light index (u32::MAX: not a light).
    tri_light: Vec<u32>,
    env_light: Option<u32>,
    scene_radius: f32,
    tree: LightTree,
    pub(in crate::integrator) selection: LightSelection,
}

impl LightSet {
    /// Builds the light list from the scene's punctual lights and environment and the emissive
    /// triangles in `emitters` (`world_tri` gives a triangle's world-space vertices).
    pub(crate) fn build(
        scene: &Scene,
        emitters: &[EmitterGroup],
        world_tri: &dyn Fn(u32, u32) -> [Vec3; 3],
        bmin: Vec3,
        bmax: Vec3,
    ) -> LightSet {
        let radius = if bmax.cmpge(bmin).all() { 0.5 * (bmax - bmin).length() } else { 0.0 };
        let radius = radius.max(1e-3);
        let mut kinds = Vec::new();
        let mut power: Vec<f64> = Vec::new();
        // Tree: bounded lights with their bounds, lights at infinity.
        let mut bounded: Vec<(u32, LightBounds)> = Vec::new();
        let mut infinite: Vec<(u32, f64)> = Vec::new();
        let cos_half_pi = FRAC_PI_2.cos();
        for (i, l) in scene.lights.iter().enumerate() {
            let p = match *l {
                Light::Point { intensity, .. } => 4.0 * PI * luminance(intensity),
                Light::Spot { intensity, inner_cone_rad, outer_cone_rad, .. } => {
                    2.0 * PI * (1.0 - 0.5 * (inner_cone_rad.cos() + outer_cone_rad.cos())) * luminance(intensity)
                }
                Light::Directional { irradiance, .. } => PI * radius * radius * luminance(irradiance),
            };
            if !(p.is_finite() && p > 0.0) {
                continue;
            }
            let li = kinds.len() as u32;
            kinds.push(LightKind::Punctual(i as u32));
            power.push(p as f64);
            // a light with a radius emits from anywhere within it
            let point = |position: Vec3, radius_m: f32, intensity: Vec3, w: Vec3, cos_o: f32, cos_e: f32| LightBounds {
                bmin: position - Vec3::splat(radius_m.max(0.0)),
                bmax: position + Vec3::splat(radius_m.max(0.0)),
                phi: 4.0 * PI * luminance(intensity),
                w,
                cos_o,
                cos_e,
                two_sided: false,
            };
            let b = match *l {
                Light::Point { position, intensity, radius_m, .. } => {
                    Some(point(position, radius_m, intensity, Vec3::Z, -1.0, cos_half_pi))
                }
                Light::Spot { position, direction, intensity, inner_cone_rad, outer_cone_rad, radius_m, .. } => {
                    let w = direction.normalize_or_zero();
                    if w == Vec3::ZERO {
                        Some(point(position, radius_m, intensity, Vec3::Z, -1.0, cos_half_pi))
                    } else {
                        // Zero beyond the outer cone whatever the inner one (see
                        // spot_attenuation, a step at the outer cone when inner = outer); the
                        // θe floor is a margin for rounding in the importance's cone test.
                        let outer = outer_cone_rad.clamp(0.0, PI);
                        let theta_o = inner_cone_rad.clamp(0.0, outer);
                        let theta_e = (outer - theta_o).max(1e-3);
                        // a disc point's cone is the centre's turned by up to the disc's angle
                        // from the shading point: the tree's box bound covers that spread
                        Some(point(position, radius_m, intensity, w, theta_o.cos(), theta_e.cos()))
                    }
                }
                Light::Directional { .. } => None,
            };
            match b {
                Some(b) if b.bmin.is_finite() && b.phi > 0.0 && b.phi.is_finite() => bounded.push((li, b)),
                Some(_) => {}
                None => infinite.push((li, p as f64)),
            }
        }
        let mut tri_light_base = Vec::new();
        let mut tri_light = Vec::new();
        for g in emitters {
            let mesh = &scene.meshes[scene.instances[g.instance as usize].mesh as usize];
            for &t in &g.triangles {
                let m = &scene.materials[mesh.material_ids[t as usize] as usize];
                if !m.is_emissive() {
                    continue;
                }
                let [a, b, c] = world_tri(g.instance, t);
                let cross = (b - a).cross(c - a);
                let area = 0.5 * cross.length();
                let sides = if m.double_sided { 2.0 } else { 1.0 };
                let p = PI * area * luminance(m.emissive) * sides;
                if p.is_finite() && p > 0.0 {
                    if tri_light_base.is_empty() {
                        tri_light_base = vec![u32::MAX; scene.instances.len()];
                    }
                    let base = &mut tri_light_base[g.instance as usize];
                    if *base == u32::MAX {
                        *base = tri_light.len() as u32;
                        tri_light.resize(tri_light.len() + g.mesh_triangles as usize, u32::MAX);
                    }
                    let li = kinds.len() as u32;
                    tri_light[(*base + t) as usize] = li;
                    kinds.push(LightKind::Triangle { instance: g.instance, tri: t });
                    power.push(p as f64);
                    // The emitting side's normal: the winding's, negated for a mirroring instance.
                    let sign = if scene.instances[g.instance as usize].object_to_world.matrix3.determinant() < 0.0 {
                        -1.0
                    } else {
                        1.0
                    };
                    let w = cross.normalize_or_zero() * sign;
                    if w != Vec3::ZERO {
                        bounded.push((
                            li,
                            LightBounds {
                                bmin: a.min(b).min(c),
                                bmax: a.max(b).max(c),
                                phi: p,
                                w,
                                cos_o: 1.0,
                                cos_e: cos_half_pi,
                                two_sided: m.double_sided,
                            },
                        ));
                    }
                }
            }
        }
        // The environment is a light only where it varies with direction. A uniform one (a
        // constant, or a map of one colour) is found by BSDF samples alone, as Cycles does with
        // its world's Sampling on Auto (`LightManager::test_enabled_lights`: background MIS off
        // for a background shader without spatial variation): cosine or glossy samples already
        // follow what it lights, and next-event estimation keeps its samples for the other lights.
        let mut env_light = None;
        if !scene.environment.is_uniform() && !scene.environment.is_black() {
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
                let li = kinds.len() as u32;
                env_light = Some(li);
                kinds.push(LightKind::Environment);
                let p = 4.0 * (PI as f64).powi(2) * (radius as f64).powi(2) * mean;
                power.push(p);
                infinite.push((li, p));
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
        let tree = LightTree::build(bounded, infinite, kinds.len());
        LightSet {
            kinds,
            cdf,
            tri_light_base,
            tri_light,
            env_light,
            scene_radius: radius,
            tree,
            selection: LightSelection::default(),
        }
    }

    /// Number of lights.
    pub fn len(&self) -> usize {
        self.kinds.len()
    }

    /// No lights at all.
    pub fn is_empty(&self) -> bool {
        self.kinds.is_empty()
    }

    /// Power-distribution pmf of light `i`.
    #[inline]
    fn power_pmf(&self, i: usize) -> f32 {
        self.cdf[i + 1] - self.cdf[i]
    }

    /// Picks a light by power: (index, pmf).
    #[inline]
    fn power_pick(&self, u: f32) -> Option<(usize, f32)> {
        if self.kinds.is_empty() {
            return None;
        }
        let u = u.clamp(0.0, 1.0 - f32::EPSILON);
        // First index with cdf[i + 1] > u.
        let i = self.cdf[1..].partition_point(|&c| c <= u).min(self.kinds.len() - 1);
        let p = self.power_pmf(i);
        if p > 0.0 {
            Some((i, p))
        } else {
            None
        }
    }

    /// Picks a light for shading point `p` with normal `n` (zero: unknown): (index, pmf).
    #[inline]
    pub(crate) fn pick(&self, p: Vec3, n: Vec3, u: f32) -> Option<(usize, f32)> {
        match self.selection {
            LightSelection::Tree => self.tree.pick(p, n, u),
            LightSelection::Power => self.power_pick(u),
        }
    }

    /// Probability that [`LightSet::pick`] at (p, n) returns light `i`.
    #[inline]
    pub(crate) fn pmf(&self, p: Vec3, n: Vec3, i: usize) -> f32 {
        if i >= self.kinds.len() {
            return 0.0;
        }
        match self.selection {
            LightSelection::Tree => self.tree.pmf(p, n, i),
            LightSelection::Power => self.power_pmf(i),
        }
    }

    /// Selection pmf of the environment (0 when it is not a light); the same at every shading
    /// point.
    #[inline]
    pub fn env_pmf(&self) -> f32 {
        self.env_light.map_or(0.0, |i| self.pmf(Vec3::ZERO, Vec3::ZERO, i as usize))
    }

    /// Light index of triangle `tri` of instance `instance` (None when it does not emit).
    #[inline]
    pub fn triangle_light(&self, instance: u32, tri: u32) -> Option<usize> {
        let base = *self.tri_light_base.get(instance as usize)?;
        if base == u32::MAX {
            return None;
        }
        match self.tri_light.get(base as usize + tri as usize) {
            Some(&i) if i != u32::MAX => Some(i as usize),
            _ => None,
        }
    }

    /// Selection pmf of triangle `tri` of instance `instance` as a light for shading point
    /// (p, n) (0 when it does not emit).
    #[inline]
    pub fn triangle_pmf(&self, p: Vec3, n: Vec3, instance: u32, tri: u32) -> f32 {
        self.triangle_light(instance, tri).map_or(0.0, |i| self.pmf(p, n, i))
    }

    /// Radius of the scene's bounding sphere.
    pub fn scene_radius(&self) -> f32 {
        self.scene_radius
    }

    /// Depth of the light tree (levels of 4-wide nodes; 0: no bounded light).
    pub fn tree_depth(&self) -> u32 {
        self.tree.depth
    }
}
