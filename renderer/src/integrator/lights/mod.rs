//! Light sampling: which light a shading point samples, and the point on it.
//!
//! Lights are punctual lights, emissive triangles and the environment where it varies with
//! direction. A uniform environment (a constant, or a map of one colour) is not a light: BSDF
//! samples alone find it, as Cycles finds a world
//! without spatial variation with its Sampling on Auto (background MIS off), so next-event
//! estimation keeps its samples for the other lights. Next-event estimation picks one light per
//! shading point (position `p`, normal `n`):
//!
//! * [`LightSelection::Tree`] (default): a light BVH ("light tree", Conty Estevez & Kulla 2018,
//!   as pbrt-v4's `BVHLightSampler`) over the bounded lights (point, spot, emissive triangles).
//!   Each node has pbrt-v4 `LightBounds`: bounding box, power `phi`, a cone of emission normals
//!   (axis `w`, spread `θo`), the emission falloff `θe` and a two-sided flag. The binary tree is
//!   built top-down with pbrt-v4's SAH-like cost (power × orientation measure × surface area ×
//!   aspect-ratio term, 12 buckets per axis), then collapsed into a 4-wide tree (each node's
//!   children replaced by grandchildren, brightest first) whose four importances are evaluated
//!   with SIMD: half the levels, about half the traversal time. Traversal picks a child with
//!   probability proportional to its importance at (p, n) (pbrt-v4's
//!   `LightBounds::Importance`, with two changes: the distance clamp is the squared
//!   bounding-sphere radius, and the cosine at the receiver is one-sided, taken with the
//!   shading normal on the side the path arrived from, as Cycles takes it, so lights wholly
//!   behind the shaded surface get importance 0 — the BSDFs here never transmit).
//!   Lights at infinity (environment, directional) are chosen with the fixed probability
//!   [`P_INFINITE`] = 1/2 as a group (by power among themselves), the tree otherwise (pbrt-v4
//!   uses `nInfinite / (nInfinite + 1)`, uniform among them; with a sky and a sun that leaves a
//!   third of the samples for all bounded lights).
//!   The selection pmf of a given light, needed by MIS when a BSDF-sampled ray hits an emitter,
//!   is recomputed by retracing the light's path from the root (a per-light trail of the child
//!   taken at each level, as pbrt-v4's bit trail) with the very same float operations as
//!   sampling, so the two agree exactly.
//! * [`LightSelection::Power`]: one global distribution proportional to emitted power
//!   (independent of the shading point).
//!
//! | light | power used for selection |
//! |---|---|
//! | point | 4π·lum(I) |
//! | spot | Power: 2π·(1 − (cos inner + cos outer)/2)·lum(I) (pbrt's spot power); Tree: 4π·lum(I) (the cone is in the bounds, as pbrt-v4) |
//! | directional | π·r²·lum(E), r = scene bounding-sphere radius |
//! | emissive triangle | π·area·lum(emissive factor) (×2 double sided); the emissive texture is ignored for selection but used for radiance |
//! | environment (a map that varies) | 4π²·r²·lum(mean radiance) (mean estimated with the environment's own importance sampling) |
//!
//! The Power pmf is the difference of consecutive entries of the f32 CDF that is actually
//! searched, so selection probabilities and the pmf used in estimators and MIS weights agree
//! exactly (a light whose CDF interval rounds to zero is never picked and has pmf 0, which MIS
//! then treats as BSDF-only). In the tree, a light whose importance is 0 at a shading point (it
//! provably cannot light it) has pmf 0 there; a light is never picked with pmf 0.
//!
//! Punctual lights follow KHR_lights_punctual: range window `clamp(1 − (d/range)⁴, 0, 1)²`, spot
//! attenuation `clamp((cd − cos outer)/(cos inner − cos outer), 0, 1)²` with cd the cosine to the
//! axis, and a hard edge at the outer cone when inner ≥ outer (no 0.001 floor on the
//! denominator, unlike the spec's sample code: see [`spot_attenuation`](crate::integrator::spot_attenuation)).
//! Blender's spot blend is a smoothstep on a different variable; glTF is followed here.
//! Emissive triangles emit from their front side (counter-clockwise winding) only, unless the
//! material is double sided.
//!
//! | file | contents |
//! |---|---|
//! | `tree.rs` | light bounds and the 4-wide light tree |
//! | `set.rs` | [`LightSet`]: the light list, power CDF and tree, built from a scene |
//! | `sample.rs` | [`RenderScene`](super::RenderScene) light sampling: pick, sample a point, pdfs for MIS |

mod set;
mod tree;

pub use set::{EmitterGroup, LightSet};
pub use tree::P_INFINITE;

use std::f32::consts::PI;

use glam::{Vec2, Vec3};

use crate::scene::Environment;

/// Environment radiance toward `dir` (unit, world).
#[inline]
pub fn env_radiance(env: &Environment, dir: Vec3) -> Vec3 {
    env.radiance(dir)
}

/// Environment radiance a camera ray that meets no surface sees toward `dir` (unit, world):
/// none with [`crate::scene::Scene::transparent_background`].
#[inline]
pub fn camera_env_radiance(scene: &crate::scene::Scene, dir: Vec3) -> Vec3 {
    if scene.transparent_background {
        Vec3::ZERO
    } else {
        scene.environment.radiance(dir)
    }
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

/// How next-event estimation chooses a light.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LightSelection {
    /// Light BVH over the bounded lights, traversed by importance at the shading point; lights
    /// at infinity with a fixed probability.
    #[default]
    Tree,
    /// One global distribution proportional to emitted power.
    Power,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum LightKind {
    /// Index into `Scene::lights`.
    Punctual(u32),
    /// Triangle `tri` of instance `instance` (indices into `Scene::instances` and its mesh).
    Triangle {
        /// Instance.
        instance: u32,
        /// Mesh triangle.
        tri: u32,
    },
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
