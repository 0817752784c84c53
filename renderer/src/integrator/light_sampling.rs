//! Light sampling on a [`RenderScene`]: picking a light, sampling a point on it, and the pdfs MIS
//! needs. It sits above both the lights (what can be sampled) and the acceleration structure
//! (the scene that holds them and answers shadow rays), so neither imports the other's user.

use glam::{Vec2, Vec3};

use super::lights::{env_pdf, env_sample, LightKind, LightSample, LightSelection};
use crate::integrator::accel::{offset_ray_origin, AlphaTest, RenderScene, SurfaceHit};
use crate::scene::{Light, SpotFalloff};

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

/// KHR_lights_punctual spot attenuation for `cd` = cos(angle to the axis): the squared linear
/// ramp in `cd` from 0 at the outer cone to 1 at the inner cone, and a hard edge (1 inside the
/// outer cone, 0 outside) when there is no ramp (inner ≥ outer, e.g. Blender's blend 0, which
/// its exporter writes as inner = outer; also when the cosines round to the same f32).
///
/// The spec's sample code divides by `max(0.001, cos inner − cos outer)`: with inner = outer
/// that is a ramp 0.001 wide in `cd` inside the outer cone, i.e. 0.001/sin(outer) rad (2.4 mrad
/// for a 25° cone, all of a cone narrower than 2.6°) dimmed where the light should be at full
/// intensity up to the edge: the dark band of docs/cycles-comparison.md, disagreement 2.
///
/// With [`SpotFalloff::Blender`] the fade is Cycles' instead: smoothstep((cd − cos outer) /
/// ((1 − cos outer)·blend)), blend = 1 − inner/outer, a step at the outer cone for blend 0.
#[inline]
pub fn spot_attenuation(cd: f32, inner: f32, outer: f32, falloff: SpotFalloff) -> f32 {
    if falloff == SpotFalloff::Blender {
        let cos_outer = outer.cos();
        let blend = if outer > 0.0 { (1.0 - inner / outer).clamp(0.0, 1.0) } else { 0.0 };
        let width = (1.0 - cos_outer) * blend;
        if !(width > 0.0) {
            return if cd > cos_outer { 1.0 } else { 0.0 };
        }
        let t = ((cd - cos_outer) / width).clamp(0.0, 1.0);
        return t * t * (3.0 - 2.0 * t);
    }
    let cos_outer = outer.cos();
    let width = inner.cos() - cos_outer;
    if !(width > 0.0) {
        return if cd > cos_outer { 1.0 } else { 0.0 };
    }
    let a = ((cd - cos_outer) / width).clamp(0.0, 1.0);
    a * a
}

/// A point of the disc of radius `r` about `centre` that faces `p` (Cycles' point and spot
/// lights with a radius and Soft Falloff), uniform in area (concentric map of `u`).
#[inline]
fn disc_point_facing(centre: Vec3, r: f32, p: Vec3, u: Vec2) -> Vec3 {
    let n = (p - centre).normalize_or_zero();
    if n == Vec3::ZERO || !(r > 0.0) {
        return centre;
    }
    let (t, b) = n.any_orthonormal_pair();
    let d = concentric_disc(u);
    centre + (t * d.x + b * d.y) * r
}

/// The emitting point of a point or spot light of radius `r` about `centre` seen from `p`, and
/// its weight w: the light's value at `p` is I·w/|q − p|². A disc facing `p` (Soft Falloff):
/// a point uniform in its area, w = cos at the disc (its radiance I/(π r²) over the area pdf).
/// A sphere: a direction uniform in the cone it subtends, radiance I/(π r²) over the solid-angle
/// pdf 1/(2π(1 − cos θmax)), so w = 2(1 − cos θmax)·t²/r² with t the distance to the hit;
/// inside the sphere a uniform direction, w = 4t²/r². None when `p` is at the centre.
#[inline]
fn emitter_point(centre: Vec3, r: f32, sphere: bool, p: Vec3, u: Vec2) -> Option<(Vec3, f32)> {
    let to_p = p - centre;
    let d2 = to_p.length_squared();
    if !(d2 > 0.0) {
        return None;
    }
    if !(r > 0.0) {
        return Some((centre, 1.0));
    }
    if !sphere {
        let q = disc_point_facing(centre, r, p, u);
        let wi = (q - p).normalize_or_zero();
        let cos_l = (to_p / d2.sqrt()).dot(-wi).max(0.0);
        return Some((q, cos_l));
    }
    let d = d2.sqrt();
    let axis = -to_p / d; // p → centre
    let (wi, t, weight_per_t2) = if d > r {
        // 1 − cos θmax from sin²θmax = r²/d² without cancellation (a small sphere far away
        // would round cos θmax to 1 and lose its light)
        let sin2 = (r * r / d2).min(1.0);
        let one_minus_cos = sin2 / (1.0 + (1.0 - sin2).sqrt());
        let wi = cone_direction(axis, one_minus_cos, u);
        // nearest intersection with the sphere along wi
        let dc = d * wi.dot(axis);
        let t = dc - (r * r - (d2 - dc * dc)).max(0.0).sqrt();
        (wi, t, 2.0 * one_minus_cos / (r * r))
    } else {
        let z = 1.0 - 2.0 * u.x;
        let s = (1.0 - z * z).max(0.0).sqrt();
        let phi = 2.0 * std::f32::consts::PI * u.y;
        let wi = Vec3::new(s * phi.cos(), s * phi.sin(), z);
        let dc = wi.dot(-to_p);
        let t = dc + (r * r - (d2 - dc * dc)).max(0.0).sqrt();
        (wi, t, 4.0 / (r * r))
    };
    let t = t.max(1e-6);
    Some((p + wi * t, weight_per_t2 * t * t))
}

/// Shirley–Chiu concentric map of the unit square onto the unit disc.
#[inline]
fn concentric_disc(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        return Vec2::ZERO;
    }
    let (r, theta) = if o.x.abs() > o.y.abs() {
        (o.x, std::f32::consts::FRAC_PI_4 * (o.y / o.x))
    } else {
        (o.y, std::f32::consts::FRAC_PI_2 - std::f32::consts::FRAC_PI_4 * (o.x / o.y))
    };
    Vec2::new(theta.cos(), theta.sin()) * r
}

/// A direction uniform in the cone about unit `axis` whose half-angle θ has 1 − cos θ =
/// `one_minus_cos` (given as that, which stays exact for narrow cones where cos θ rounds to 1).
#[inline]
fn cone_direction(axis: Vec3, one_minus_cos: f32, u: Vec2) -> Vec3 {
    let x = u.x * one_minus_cos; // 1 − cos of the sampled angle
    let cos_t = 1.0 - x;
    let sin_t = (x * (2.0 - x)).max(0.0).sqrt();
    let phi = 2.0 * std::f32::consts::PI * u.y;
    let (t, b) = axis.any_orthonormal_pair();
    (t * (sin_t * phi.cos()) + b * (sin_t * phi.sin()) + axis * cos_t).normalize()
}

impl RenderScene {
    /// How next-event estimation chooses lights ([`LightSelection::Tree`] unless changed).
    pub fn light_selection(&self) -> LightSelection {
        self.lights.selection
    }

    /// Switches the light selection strategy (the tree is the default).
    pub fn set_light_selection(&mut self, selection: LightSelection) {
        self.lights.selection = selection;
    }

    /// Picks a light for shading point `p` with normal `n` (the shading normal on the side
    /// the light must be on, or zero when there is none): (light index, selection pmf). This is
    /// the choice [`RenderScene::sample_light_at`] makes with the same `u_pick`.
    pub fn pick_light(&self, p: Vec3, n: Vec3, u_pick: f32) -> Option<(usize, f32)> {
        self.lights.pick(p, n, u_pick)
    }

    /// Probability that [`RenderScene::pick_light`] at (p, n) picks light `light` (an index
    /// below [`RenderScene::light_count`]). Equal to the pmf the pick returns.
    pub fn light_pmf(&self, p: Vec3, n: Vec3, light: usize) -> f32 {
        self.lights.pmf(p, n, light)
    }

    /// Light index of emissive triangle `tri` of instance `instance` (None when it is not a light).
    pub fn triangle_light(&self, instance: u32, tri: u32) -> Option<usize> {
        self.lights.triangle_light(instance, tri)
    }

    /// Samples a light for shading point `p` without a surface normal (as
    /// [`RenderScene::sample_light_at`] with `n = 0`).
    pub fn sample_light(&self, p: Vec3, u_pick: f32, u: Vec2) -> Option<LightSample> {
        self.sample_light_at(p, Vec3::ZERO, u_pick, u)
    }

    /// Samples a light for shading point `p` with normal `n` (the shading normal on the side
    /// where light is wanted, or zero): `u_pick` selects the light, `u` the point on it. None
    /// when nothing can be sampled. Lights wholly below `n` are never chosen.
    pub fn sample_light_at(&self, p: Vec3, n: Vec3, u_pick: f32, u: Vec2) -> Option<LightSample> {
        let (i, pmf) = self.lights.pick(p, n, u_pick)?;
        self.sample_chosen_light(p, i, pmf, u)
    }

    /// Samples a point on light `i` (chosen with probability `pmf`) for shading point `p`, as
    /// [`RenderScene::sample_light_at`] does once it has picked it.
    pub(crate) fn sample_chosen_light(&self, p: Vec3, i: usize, pmf: f32, u: Vec2) -> Option<LightSample> {
        match self.lights.kinds[i] {
            LightKind::Punctual(li) => {
                let light = self.scene().lights[li as usize];
                let (wi, radiance, target) = match light {
                    Light::Point { position, intensity, range, radius_m, sphere } => {
                        // 1. The emitting point (the centre, a point of the disc facing p, or of
                        //    the sphere) and its weight; 2. its light at p.
                        let range_w = range_window((position - p).length(), range);
                        let (q, weight) = emitter_point(position, radius_m, sphere, p, u)?;
                        let d = q - p;
                        let d2 = d.length_squared();
                        let dist = d2.sqrt();
                        if !(dist > 0.0) {
                            return None;
                        }
                        (d / dist, intensity * (range_w * weight / d2), Some(q))
                    }
                    Light::Spot {
                        position,
                        direction,
                        intensity,
                        inner_cone_rad,
                        outer_cone_rad,
                        range,
                        falloff,
                        radius_m,
                        sphere,
                    } => {
                        let range_w = range_window((position - p).length(), range);
                        let (q, weight) = emitter_point(position, radius_m, sphere, p, u)?;
                        let d = q - p;
                        let d2 = d.length_squared();
                        let dist = d2.sqrt();
                        if !(dist > 0.0) {
                            return None;
                        }
                        let wi = d / dist;
                        // the cone is seen along the direction the light leaves its emitting point
                        let cd = direction.normalize_or_zero().dot(-wi);
                        let att = spot_attenuation(cd, inner_cone_rad, outer_cone_rad, falloff) * range_w;
                        (wi, intensity * (att * weight / d2), Some(q))
                    }
                    Light::Directional { direction, irradiance, angle_rad } => {
                        let axis = -direction.normalize_or_zero();
                        if axis == Vec3::ZERO {
                            return None;
                        }
                        if !(angle_rad > 0.0) {
                            (axis, irradiance, None)
                        } else {
                            // A sun with an angle (as Cycles): a direction uniform in its cone of
                            // half-angle θ, radiance E / (π sin²θ) so that a surface facing it
                            // receives E; per sample E·2/(1 + cos θ) over the cone's pdf.
                            let half = 0.5 * angle_rad;
                            let s = (0.5 * half).sin();
                            let wi = cone_direction(axis, 2.0 * s * s, u); // 1 − cos θ = 2 sin²(θ/2)
                            (wi, irradiance * (2.0 / (1.0 + half.cos())), None)
                        }
                    }
                };
                if radiance == Vec3::ZERO || !radiance.is_finite() {
                    return None;
                }
                Some(LightSample { wi, radiance, pdf: pmf, delta: true, target })
            }
            LightKind::Triangle { instance, tri } => {
                let scene = self.scene();
                let material_id = self.material_of(instance, tri);
                let mat = &scene.materials[material_id as usize];
                let [a, b, c] = self.world_triangle(instance, tri);
                // Uniform point: barycentrics (1 − √u₀, √u₀(1 − u₁), √u₀·u₁).
                let su = u.x.sqrt();
                let (w0, w1, w2) = (1.0 - su, su * (1.0 - u.y), su * u.y);
                let q = a * w0 + b * w1 + c * w2;
                let cross = (b - a).cross(c - a);
                let area2 = cross.length();
                if !(area2 > 0.0) {
                    return None;
                }
                let nl = cross / area2 * self.instance_sign(instance);
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
                let (uv0, uv1) = self.uvs_at(instance, tri, w1, w2);
                let mut le =
                    mat.emissive * self.texture(mat.emissive_texture, uv0, uv1).map_or(Vec3::ONE, |t| t.truncate());
                // a clear coat dims the emission under it (seen at the flat triangle's cos_l)
                if let Some(c) = self.coat(material_id) {
                    le *= c.emission_weight(cos_l);
                }
                // Cut-outs of the emitter itself: Mask removes, Blend emits with weight alpha
                // (the expected value of stochastic opacity).
                match self.alpha_tests[material_id as usize] {
                    AlphaTest::None | AlphaTest::LightEmitter => {}
                    AlphaTest::Mask(cutoff) => {
                        if self.alpha_at(instance, tri, w1, w2) < cutoff {
                            return None;
                        }
                    }
                    AlphaTest::Stochastic => le *= self.alpha_at(instance, tri, w1, w2).clamp(0.0, 1.0),
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

    /// Pdf (selection × solid angle) with which [`RenderScene::sample_light_at`] at shading
    /// point (`p`, `n`) would have produced the point of `hit` (an emissive triangle seen at
    /// distance `hit.t` along unit `dir`).
    pub fn triangle_light_pdf(&self, p: Vec3, n: Vec3, hit: &SurfaceHit, dir: Vec3) -> f32 {
        self.triangle_light_pdf_from(p, n, hit, dir, hit.t)
    }

    /// [`RenderScene::triangle_light_pdf`] for a shading point `p` at distance `dist` from the
    /// hit along unit `dir` (not the ray's own origin): light paths start on the lens.
    pub fn triangle_light_pdf_from(&self, p: Vec3, n: Vec3, hit: &SurfaceHit, dir: Vec3, dist: f32) -> f32 {
        let pmf = self.lights.triangle_pmf(p, n, hit.instance, hit.triangle);
        self.triangle_light_pdf_with_pmf(pmf, hit, dir, dist)
    }

    /// The solid-angle pdf of the point of `hit` on its emissive triangle, chosen with
    /// probability `pmf`, seen from distance `dist` along unit `dir`.
    pub(crate) fn triangle_light_pdf_with_pmf(&self, pmf: f32, hit: &SurfaceHit, dir: Vec3, dist: f32) -> f32 {
        if pmf == 0.0 {
            return 0.0;
        }
        let [a, b, c] = self.world_triangle(hit.instance, hit.triangle);
        let area = 0.5 * (b - a).cross(c - a).length();
        let cos_l = hit.geometric_normal.dot(dir).abs();
        let pdf = pmf * dist * dist / (area * cos_l);
        if pdf.is_finite() {
            pdf
        } else {
            0.0
        }
    }

    /// Whether any triangle emits (only those can be found by light paths through the lens).
    pub fn has_emissive_triangles(&self) -> bool {
        self.lights.kinds.iter().any(|k| matches!(k, LightKind::Triangle { .. }))
    }

    /// Every emissive triangle the camera can see (light paths through the lens stand for the
    /// camera seeing it; one hidden from the camera has none): (light index, world-space
    /// vertices, power: emission factor's luminance × area, textures not counted).
    pub(crate) fn emissive_triangles(&self) -> impl Iterator<Item = (usize, [Vec3; 3], f32)> + '_ {
        self.lights.kinds.iter().enumerate().filter_map(|(i, k)| match *k {
            LightKind::Triangle { instance, tri } => {
                let mat = &self.scene().materials[self.material_of(instance, tri) as usize];
                if !mat.visible_to_camera {
                    return None;
                }
                let v = self.world_triangle(instance, tri);
                let e = mat.emissive;
                let area = 0.5 * (v[1] - v[0]).cross(v[2] - v[0]).length();
                Some((i, v, (0.2126 * e.x + 0.7152 * e.y + 0.0722 * e.z) * area))
            }
            _ => None,
        })
    }

    /// Pdf (selection × solid angle) of sampling the environment toward `dir` (the environment's
    /// selection pmf is the same at every shading point).
    pub fn env_light_pdf(&self, dir: Vec3) -> f32 {
        let pmf = self.lights.env_pmf();
        if pmf == 0.0 {
            return 0.0;
        }
        pmf * env_pdf(&self.scene().environment, dir)
    }
}
