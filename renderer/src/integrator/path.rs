//! Unidirectional path tracing with next-event estimation and multiple importance sampling.
//!
//! * At each vertex: one light sample (NEE) and one BSDF sample. Emissive triangles and the
//!   environment are reached by both and weighted with the power heuristic (β = 2); punctual
//!   lights (delta) only by NEE. Emission seen by the camera ray counts fully. Light selection
//!   depends on the shading point (position and shading normal, as in Cycles; see
//!   [`super::lights`]), so the light pdf in the weight of an emitter hit is evaluated for the
//!   vertex the ray left from.
//! * Light samples are evaluated without the geometric normal's test and their shadow rays
//!   leave from the smooth surface near a terminator, as Cycles does with its default Shadow
//!   Terminator Geometry Offset ([`RenderScene::shadow_origin`]): smooth-shaded low-poly meshes
//!   are lit up to their terminator. Normal-mapped surfaces keep the test (Cycles' bump
//!   shadowing term is zero there), so no light leaks through a normal-mapped wall. BSDF
//!   samples through the geometric surface are dropped.
//! * `max_depth` counts scattering events (pbrt's convention): 0 = emission only, 1 = direct
//!   lighting, ... Emitters reached by the last BSDF sample still count.
//! * Russian roulette as Cycles does it: at every hit after `rr_start_depth` bounces (default 1:
//!   from the second hit on), once its emission is counted, the rest of the path (next-event
//!   estimation and further bounces) survives with probability min(1, √(max component of the
//!   throughput)) and is divided by it.
//! * Sample dimensions per bounce, always all consumed in this order so streams stay aligned:
//!   light pick (1), light point (2), BSDF lobe (1), BSDF direction (2), roulette (1).
//! * Camera rays go on through surfaces hidden from the camera
//!   ([`crate::scene::Material::visible_to_camera`]); every later ray sees them.
//! * Nothing is clamped. A non-finite radiance is dropped (returned as zero) and flagged in
//!   [`PathSample::dropped`].

use glam::Vec3;

use super::accel::{RenderScene, SurfaceHit};
use super::bsdf::{ensure_valid_specular_reflection, fresnel_dielectric, Bsdf, SurfaceBsdf};
use super::lights::{camera_env_radiance, env_radiance};
use crate::sampler::PixelSampler;
use crate::scene::{AngleWeight, MaterialMix};

/// Which estimators reach emissive triangles and the environment (for tests and comparisons;
/// punctual lights always use light sampling).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LightStrategy {
    /// Light and BSDF sampling combined by the power heuristic.
    #[default]
    Mis,
    /// Light sampling only (emitters hit by BSDF samples are ignored after the camera ray).
    LightOnly,
    /// BSDF sampling only (no light samples for area lights and the environment).
    BsdfOnly,
}

/// The weight of emission hit by the camera ray itself: `(hit, unit direction) → weight`.
pub type DirectWeight<'a> = &'a dyn Fn(&SurfaceHit, Vec3) -> f32;

/// The path tracer's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathTracer {
    /// Maximum number of scattering events (bounces).
    pub max_depth: u32,
    /// Bounces before Russian roulette starts (1: at the second hit, as Cycles with its
    /// default Min Light Bounces of 0).
    pub rr_start_depth: u32,
    /// Estimators for area lights and the environment.
    pub strategy: LightStrategy,
}

impl Default for PathTracer {
    fn default() -> Self {
        PathTracer { max_depth: 8, rr_start_depth: 1, strategy: LightStrategy::Mis }
    }
}

/// What one camera ray returns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathSample {
    /// Radiance (linear RGB, W·sr⁻¹·m⁻²).
    pub radiance: Vec3,
    /// 1 if the camera ray hit geometry, else 0 (the environment still adds radiance).
    pub alpha: f32,
    /// Distance to the first hit along the ray (m); infinite on a miss.
    pub depth_m: f32,
    /// First-hit shading normal (world, facing the camera); zero on a miss.
    pub normal: Vec3,
    /// First-hit base colour (factor × texture); zero on a miss.
    pub albedo: Vec3,
    /// The radiance was not finite and was dropped (then `radiance` is zero).
    pub dropped: bool,
}

impl PathSample {
    /// A sample that hit nothing and carries `radiance` (the environment's, or zero).
    pub fn miss(radiance: Vec3) -> PathSample {
        PathSample {
            radiance,
            alpha: 0.0,
            depth_m: f32::INFINITY,
            normal: Vec3::ZERO,
            albedo: Vec3::ZERO,
            dropped: false,
        }
    }
}

/// Power heuristic (β = 2) weight of strategy `a` against `b`.
#[inline]
pub fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    let s = a2 + b2;
    if s > 0.0 && s.is_finite() {
        a2 / s
    } else if a.is_infinite() && !b.is_infinite() {
        1.0
    } else {
        0.0
    }
}

/// Base colour (factor × texture × vertex colour, linear RGB) at a hit.
pub fn base_color(scene: &RenderScene, hit: &SurfaceHit) -> Vec3 {
    base_color_of(scene, hit, hit.material_id)
}

/// Base colour of material `id` at a hit (a mix component's, or the hit's own material's).
fn base_color_of(scene: &RenderScene, hit: &SurfaceHit, id: u32) -> Vec3 {
    let mat = &scene.scene().materials[id as usize];
    let base_tex = scene.texture(mat.base_color_texture, hit.uv0, hit.uv1).map_or(Vec3::ONE, |t| t.truncate());
    let vertex = scene.vertex_color(hit.instance, hit.triangle, hit.barycentrics.x, hit.barycentrics.y);
    mat.base_color.truncate() * base_tex * vertex.truncate()
}

/// A mix's probability at a hit seen from direction `wo` (unit, away from the surface): its
/// weight, times its mask's red channel and its angle factor where it has them.
fn mix_weight(scene: &RenderScene, hit: &SurfaceHit, wo: Vec3, mix: &MaterialMix) -> f32 {
    let mut w = match scene.texture(mix.weight_texture, hit.uv0, hit.uv1) {
        Some(t) if t.x.is_finite() => mix.weight * t.x.clamp(0.0, 1.0),
        Some(_) => 0.0,
        None => mix.weight,
    };
    if let Some(angle) = mix.weight_angle {
        let backfacing = hit.geometric_normal.dot(wo) < 0.0;
        let f = angle_factor(&angle, hit.shading_normal.dot(wo).abs(), backfacing);
        w *= if f.is_finite() { f.clamp(0.0, 1.0) } else { 0.0 };
    }
    w
}

/// A Fresnel or Layer Weight node's factor at μ = |cos θ| (see [`AngleWeight`]), as Cycles'
/// nodes compute it; `backfacing` when the view is behind the surface.
pub fn angle_factor(a: &AngleWeight, mu: f32, backfacing: bool) -> f32 {
    let mu = mu.clamp(0.0, 1.0);
    let fresnel = |eta: f32| fresnel_dielectric(mu, if backfacing { 1.0 / eta } else { eta });
    match *a {
        AngleWeight::Fresnel { ior } => fresnel(ior.max(1e-5)),
        AngleWeight::LayerFresnel { blend } => fresnel(1.0 / (1.0 - blend.clamp(0.0, 1.0)).max(1e-5)),
        AngleWeight::LayerFacing { blend } => {
            let b = blend.clamp(0.0, 1.0 - 1e-5);
            let k = if b < 0.5 { 2.0 * b } else { 0.5 / (1.0 - b) };
            1.0 - mu.powf(k)
        }
    }
}

/// The albedo output's colour at a hit seen from `wo`: the base colour times the scatter tint,
/// averaged over a mix chain by its weights.
fn albedo(scene: &RenderScene, hit: &SurfaceHit, wo: Vec3) -> Vec3 {
    let mats = &scene.scene().materials;
    let (mut id, mut share, mut sum) = (hit.material_id, 1.0f32, Vec3::ZERO);
    loop {
        let m = &mats[id as usize];
        let w = m.mix.as_ref().map_or(0.0, |x| mix_weight(scene, hit, wo, x));
        sum += share * (1.0 - w) * base_color_of(scene, hit, id) * m.scatter_tint;
        match m.mix {
            Some(x) if w > 0.0 => {
                share *= w;
                id = x.material;
            }
            _ => return sum,
        }
    }
}

/// The material that scatters at a hit of material `id` seen from `wo` (unit, away from the
/// surface): `id` itself, or one along its mix chain ([`crate::scene::Material::mix`]) chosen
/// by `u` in [0, 1); with `u` remapped to [0, 1) for the lobe choice, so no sample dimension is
/// added.
pub fn scattering_material(scene: &RenderScene, hit: &SurfaceHit, wo: Vec3, id: u32, u: f32) -> (u32, f32) {
    let mats = &scene.scene().materials;
    let (mut id, mut u) = (id, u);
    while let Some(mix) = &mats[id as usize].mix {
        let w = mix_weight(scene, hit, wo, mix);
        if u < w {
            u /= w;
            id = mix.material;
        } else {
            u = (u - w) / (1.0 - w);
            break;
        }
    }
    (id, u.clamp(0.0, 1.0 - f32::EPSILON / 2.0))
}

/// The BSDF of a hit's material (and its base colour).
pub fn material_bsdf<'s>(scene: &'s RenderScene, hit: &SurfaceHit) -> (Bsdf<'s>, Vec3) {
    material_bsdf_of(scene, hit, hit.material_id)
}

/// The BSDF of material `id` at a hit (and its base colour).
#[inline(always)]
fn material_bsdf_of<'s>(scene: &'s RenderScene, hit: &SurfaceHit, id: u32) -> (Bsdf<'s>, Vec3) {
    let mat = &scene.scene().materials[id as usize];
    let base = base_color_of(scene, hit, id);
    let mut bsdf = match scene.bsdf_template(id) {
        // 1. Metallic 0, no texture for it: the material's BSDF, built once, with this base.
        Some(template) => template.with_base(base),
        // 2. Otherwise built here (anisotropic: its albedo tables at (α_x·α_y)^¼).
        None => {
            let (mut metallic, mut roughness) = (mat.metallic, mat.roughness);
            if let Some(mr) = scene.texture(mat.metallic_roughness_texture, hit.uv0, hit.uv1) {
                metallic *= mr.z;
                roughness *= mr.y;
            }
            let bsdf = match &mat.anisotropy {
                None => Bsdf::new(base, metallic, roughness, mat.specular, mat.ior),
                Some(a) => {
                    let (alphas, table_roughness) = Bsdf::anisotropic_alphas(roughness, a.kind);
                    Bsdf::new(base, metallic, table_roughness, mat.specular, mat.ior).with_anisotropic_alphas(alphas)
                }
            };
            if metallic > 0.0 && !mat.metal_fresnel.is_schlick() {
                bsdf.with_metal_fresnel(&mat.metal_fresnel)
            } else {
                bsdf
            }
        }
    };
    if mat.specular_tint != Vec3::ONE {
        bsdf = bsdf.with_specular_tint(&mat.specular_tint);
    }
    let bsdf = bsdf.with_transmission(mat.transmission, mat.ior).with_coat(scene.coat(id));
    (bsdf, base)
}

impl PathTracer {
    /// Traces one camera ray (`dir` need not be unit).
    pub fn trace(&self, scene: &RenderScene, origin: Vec3, dir: Vec3, sampler: &mut PixelSampler) -> PathSample {
        self.trace_clipped(scene, origin, dir, (0.0, f32::INFINITY), sampler)
    }

    /// Traces one camera ray that sees only what lies between `clip.0` and `clip.1` along it
    /// (clipping planes; beyond them the environment shows, as in Blender). Depth is still
    /// measured from `origin`.
    pub fn trace_clipped(
        &self,
        scene: &RenderScene,
        origin: Vec3,
        dir: Vec3,
        clip: (f32, f32),
        sampler: &mut PixelSampler,
    ) -> PathSample {
        self.trace_weighted(scene, origin, dir, clip, sampler, None)
    }

    /// [`PathTracer::trace_clipped`] with the emission that the camera ray itself hits
    /// weighted by `direct_weight(hit, dir)` (the camera path's MIS weight against light
    /// paths traced from emitters through the lens; None = 1).
    pub fn trace_weighted(
        &self,
        scene: &RenderScene,
        origin: Vec3,
        dir: Vec3,
        clip: (f32, f32),
        sampler: &mut PixelSampler,
        direct_weight: Option<DirectWeight>,
    ) -> PathSample {
        self.trace_from(scene, origin, dir, clip, sampler, direct_weight, None)
    }

    /// The camera ray's first query in [`PathTracer::trace_weighted`]: (start, unit direction,
    /// `t_max`) as passed to [`RenderScene::intersect`], or None when nothing is traced. The
    /// render loop finds these first hits a packet at a time ([`RenderScene::intersect_packet`]).
    pub fn camera_query(origin: Vec3, dir: Vec3, clip: (f32, f32)) -> Option<(Vec3, Vec3, f32)> {
        let d = dir.normalize_or_zero();
        if d == Vec3::ZERO || !origin.is_finite() || !d.is_finite() {
            return None;
        }
        let (t_near, t_far) = (clip.0.max(0.0), clip.1);
        let t_max = if t_far > t_near { t_far - t_near } else { 0.0 };
        Some((origin + d * t_near, d, t_max))
    }

    /// [`PathTracer::trace_weighted`] given the camera ray's first hit, found already for the
    /// query [`PathTracer::camera_query`] returns (`first_hit`: what `intersect` gives for it).
    #[allow(clippy::too_many_arguments)]
    pub fn trace_weighted_from_hit(
        &self,
        scene: &RenderScene,
        origin: Vec3,
        dir: Vec3,
        clip: (f32, f32),
        sampler: &mut PixelSampler,
        direct_weight: Option<DirectWeight>,
        first_hit: Option<SurfaceHit>,
    ) -> PathSample {
        self.trace_from(scene, origin, dir, clip, sampler, direct_weight, Some(first_hit))
    }

    /// The path, with the first hit given (`Some`) or found here (`None`).
    #[allow(clippy::too_many_arguments)]
    fn trace_from(
        &self,
        scene: &RenderScene,
        origin: Vec3,
        dir: Vec3,
        clip: (f32, f32),
        sampler: &mut PixelSampler,
        direct_weight: Option<DirectWeight>,
        mut first_hit: Option<Option<SurfaceHit>>,
    ) -> PathSample {
        let mut out = PathSample::miss(Vec3::ZERO);
        let Some((mut o, mut d, mut t_max)) = Self::camera_query(origin, dir, clip) else {
            return out;
        };
        let t_near = clip.0.max(0.0);
        let env = &scene.scene().environment;
        let mut l = Vec3::ZERO;
        let mut beta = Vec3::ONE;
        let mut prev_pdf = 0.0f32; // BSDF pdf of the ray being traced (0 for the camera ray)
                                   // Shading point (position, shading normal on the side of the path) the ray being
                                   // traced left from: light selection there depends on it, so MIS needs it.
        let (mut prev_p, mut prev_n) = (Vec3::ZERO, Vec3::ZERO);
        let mut depth = 0u32;
        let nee = self.strategy != LightStrategy::BsdfOnly;
        // The first hit's BSDF, built once for its base colour (the albedo output) and its shading.
        let mut first_bsdf: Option<Bsdf> = None;
        loop {
            let mut found = match first_hit.take() {
                Some(given) => given,
                None if t_max > 0.0 => scene.intersect(o, d, t_max),
                None => None,
            };
            // A surface hidden from camera rays: the camera ray goes on through it.
            if depth == 0 {
                if let Some(hidden) = found.as_ref().filter(|h| !scene.visible_to_camera(h)) {
                    found = scene.seen_beyond(hidden, o, d, t_max);
                }
            }
            let Some(hit) = found else {
                let le = if depth == 0 { camera_env_radiance(scene.scene(), d) } else { env_radiance(env, d) };
                if le != Vec3::ZERO {
                    let w = if depth == 0 {
                        1.0
                    } else {
                        match self.strategy {
                            LightStrategy::Mis => power_heuristic(prev_pdf, scene.env_light_pdf(d)),
                            LightStrategy::BsdfOnly => 1.0,
                            // Not a light at all (black) → nothing else can find it.
                            LightStrategy::LightOnly => {
                                if scene.lights.env_pmf() > 0.0 {
                                    0.0
                                } else {
                                    1.0
                                }
                            }
                        }
                    };
                    l += beta * le * w;
                }
                break;
            };
            let wo = -d;
            if depth == 0 {
                out.alpha = 1.0;
                out.depth_m = hit.t + t_near;
                let mat = &scene.scene().materials[hit.material_id as usize];
                if mat.mix.is_none() && mat.scatter_tint == Vec3::ONE {
                    let (bsdf, base) = material_bsdf(scene, &hit);
                    out.albedo = base;
                    first_bsdf = Some(bsdf);
                } else {
                    out.albedo = albedo(scene, &hit, wo);
                }
                let n = hit.shading_normal;
                out.normal = if n.dot(wo) >= 0.0 { n } else { -n };
            }

            // Emission.
            let le = scene.emission(&hit, d);
            if le != Vec3::ZERO {
                let w = if depth == 0 {
                    direct_weight.map_or(1.0, |f| f(&hit, d))
                } else {
                    let light_pdf = scene.triangle_light_pdf(prev_p, prev_n, &hit, d);
                    match self.strategy {
                        LightStrategy::Mis => power_heuristic(prev_pdf, light_pdf),
                        LightStrategy::BsdfOnly => 1.0,
                        LightStrategy::LightOnly => {
                            if light_pdf > 0.0 {
                                0.0
                            } else {
                                1.0
                            }
                        }
                    }
                };
                l += beta * le * w;
            }
            if depth >= self.max_depth {
                break;
            }

            let u_pick = sampler.next_1d();
            let u_light = sampler.next_2d();
            let u_lobe = sampler.next_1d();
            let u_bsdf = sampler.next_2d();
            let u_rr = sampler.next_1d();

            // Russian roulette on the rest of the path (Cycles' rule): the emission found here
            // already counts; what follows survives with probability √(max throughput).
            if depth >= self.rr_start_depth {
                let q = beta.max_element().sqrt().min(1.0);
                if !(u_rr < q) {
                    break;
                }
                beta /= q;
            }

            // The material that scatters (one of a Mix Shader's, chosen by the lobe sample).
            let (scatter_id, u_lobe) = if scene.scene().materials[hit.material_id as usize].mix.is_some() {
                scattering_material(scene, &hit, wo, hit.material_id, u_lobe)
            } else {
                (hit.material_id, u_lobe)
            };
            let scatter_mat = &scene.scene().materials[scatter_id as usize];
            let (tint, translucent) = (scatter_mat.scatter_tint, scatter_mat.translucent);
            let bsdf = match first_bsdf.take() {
                Some(b) if scatter_id == hit.material_id => b,
                _ => material_bsdf_of(scene, &hit, scatter_id).0,
            };
            // A translucent surface (Blender's Translucent BSDF) scatters through itself: its
            // Lambertian BSDF placed as if seen from the far side (wo mirrored through the
            // surface), so that it scatters there.
            let wo_s = if translucent { wo - 2.0 * wo.dot(hit.geometric_normal) * hit.geometric_normal } else { wo };
            // A normal-mapped surface keeps the geometric normal's test: Cycles' bump shadowing
            // term is zero for light below the geometric surface.
            let bumped = scene.scene().materials[hit.material_id as usize].normal_texture.is_some();
            // With Cycles' Bump Map Correction (Blender's default): a shading normal that would
            // reflect the view below the surface is turned toward the geometric normal for the
            // specular lobes. Cycles does it wherever the shading normal is not the geometric
            // one: under normal maps, whose diffuse lobe is also masked against the smooth
            // normal (`bump_shadowing`), and on smooth-shaded meshes, near whose low-poly
            // silhouettes the lobes would otherwise reflect into the surface (their diffuse lobe
            // keeps the shading normal: it is its own smooth normal).
            // Anisotropic lobes take the material's tangent about the lobes' normal.
            let aniso =
                if bsdf.is_anisotropic() { scene.scene().materials[scatter_id as usize].anisotropy } else { None };
            let place = |shading: Vec3| {
                let sb = SurfaceBsdf::new(bsdf, hit.geometric_normal, shading, wo_s);
                match aniso.as_ref().and_then(|a| scene.anisotropy_tangent(&hit, a, sb.n)) {
                    Some(t) => sb.with_tangent(t),
                    None => sb,
                }
            };
            let sb = if bumped || (bsdf.has_specular() && hit.shading_normal != hit.geometric_normal) {
                let ng = hit.geometric_normal_toward(wo_s);
                let n = if hit.shading_normal.dot(ng) >= 0.0 { hit.shading_normal } else { -hit.shading_normal };
                let corrected = ensure_valid_specular_reflection(ng, wo_s, n);
                if bumped {
                    place(corrected).with_normal_map(scene.smooth_normal(&hit), n)
                } else if corrected == n {
                    place(hit.shading_normal)
                } else {
                    place(corrected).with_normal_map(n, n)
                }
            } else {
                place(hit.shading_normal)
            };

            // Next-event estimation (lights chosen by the shading normal, as Cycles does, from
            // both sides where the BSDF transmits; the shadow ray leaves from the smooth surface
            // near a terminator).
            let select_n = if translucent || sb.bsdf.transmits() { Vec3::ZERO } else { sb.n };
            if let Some(ls) = scene.sample_light_at(hit.position, select_n, u_pick, u_light) {
                if ls.delta || nee {
                    let f = tint * if bumped { sb.eval(wo_s, ls.wi) } else { sb.eval_light(wo_s, ls.wi) };
                    if f != Vec3::ZERO {
                        let origin = scene.shadow_origin(&hit, sb.n, sb.ng, ls.wi);
                        let visible = match ls.target {
                            Some(t) => {
                                let to = t - origin;
                                // Stop just short of the (offset) light point.
                                !scene.occluded(origin, to, 1.0 - 1e-4)
                            }
                            None => !scene.occluded(origin, ls.wi, f32::INFINITY),
                        };
                        if visible {
                            let w = if ls.delta || self.strategy != LightStrategy::Mis {
                                1.0
                            } else {
                                let bsdf_pdf = if bumped { sb.pdf(wo_s, ls.wi) } else { sb.pdf_light(wo_s, ls.wi) };
                                power_heuristic(ls.pdf, bsdf_pdf)
                            };
                            if ls.pdf > 0.0 {
                                l += beta * f * ls.radiance * (w / ls.pdf);
                            }
                        }
                    }
                }
            }

            // BSDF sample.
            let Some(bs) = sb.sample(wo_s, u_bsdf, u_lobe) else { break };
            beta *= bs.weight * tint;
            if !(beta.max_element() > 0.0) || !beta.is_finite() {
                break;
            }
            prev_pdf = bs.pdf;
            prev_p = hit.position;
            prev_n = select_n;
            o = hit.spawn_origin(bs.wi);
            d = bs.wi;
            t_max = f32::INFINITY;
            depth += 1;
        }
        if l.is_finite() {
            out.radiance = l;
        } else {
            out.dropped = true;
        }
        out
    }
}
