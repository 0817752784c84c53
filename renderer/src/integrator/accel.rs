//! Ray casting: the scene's triangles in an obvhs compressed wide BVH (CWBVH), closest-hit and
//! any-hit queries with alpha cut-outs, and surface hits with interpolated attributes.
//!
//! * Triangles are copied into leaf order (the builder's `primitive_indices`), so the
//!   traversal closure reads them sequentially; each keeps its index into `Scene::mesh.indices`.
//! * Intersection is watertight (Woop, Benthin & Wald 2013, with the double-precision fallback
//!   on exactly-zero edge functions), so rays do not leak through shared edges of closed meshes.
//! * Self-intersection: spawned rays start at the barycentric hit position pushed off the surface
//!   along the geometric normal by Wächter & Binder's integer-ULP offset ("A Fast and Robust
//!   Method for Avoiding Self-Intersection", Ray Tracing Gems ch. 6), which scales with the
//!   magnitude of the position; no ray epsilon is needed.
//! * Alpha: `Mask(cutoff)` cuts where base-colour alpha × texture alpha < cutoff. `Blend` is
//!   stochastic transparency: the surface is opaque with probability alpha, decided by a hash of
//!   the ray (origin and direction bits) and the triangle, so the same ray gets the same answer in
//!   `intersect` and `occluded`, and different pixel samples average to alpha coverage.
//!   Cut-outs apply to camera, bounce and shadow rays alike.
//! * Back faces are hit like front faces (no culling).

use std::time::{Duration, Instant};

use glam::{Vec2, Vec3, Vec4};
use obvhs::{
    cwbvh::{builder::build_cwbvh_from_tris, node::CwBvhNode, CwBvh},
    ray::{Ray, RayHit},
    triangle::Triangle,
    BvhBuildParams,
};

use super::lights::LightSet;
use crate::sampler::hash_u32;
use crate::scene::{AlphaMode, Material, Scene, TextureRef};
use crate::Result;

/// BVH build quality (obvhs presets; all PLOC + reinsertion, no spatial splits).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BvhQuality {
    /// `BvhBuildParams::fast_build`: quickest build, a few percent slower traversal.
    Fast,
    /// `BvhBuildParams::medium_build`: the default (good traversal at a moderate build cost).
    #[default]
    Medium,
    /// `BvhBuildParams::slow_build` (spatial pre-splits): best traversal, several times the build.
    High,
}

impl BvhQuality {
    fn params(self) -> BvhBuildParams {
        match self {
            BvhQuality::Fast => BvhBuildParams::fast_build(),
            BvhQuality::Medium => BvhBuildParams::medium_build(),
            BvhQuality::High => BvhBuildParams::slow_build(),
        }
    }
}

/// Flag in [`PackedTri::prim`]: the triangle's material needs an alpha test.
const ALPHA_BIT: u32 = 1 << 31;

/// A triangle in leaf order: its three vertices and its mesh triangle index (| [`ALPHA_BIT`]).
#[derive(Debug, Clone, Copy)]
#[repr(C)]
struct PackedTri {
    v: [[f32; 3]; 3],
    prim: u32,
}

/// How a material's alpha is tested during traversal (precomputed per material).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum AlphaTest {
    /// Always opaque.
    None,
    /// Opaque where alpha ≥ cutoff.
    Mask(f32),
    /// Opaque with probability alpha.
    Stochastic,
}

fn alpha_test_of(m: &Material) -> AlphaTest {
    let factor = m.base_color.w;
    let textured = m.base_color_texture.is_some();
    match m.alpha_mode {
        AlphaMode::Opaque => AlphaTest::None,
        AlphaMode::Mask(cutoff) => {
            if !textured && factor >= cutoff {
                AlphaTest::None
            } else {
                AlphaTest::Mask(cutoff)
            }
        }
        AlphaMode::Blend => {
            if !textured && factor >= 1.0 {
                AlphaTest::None
            } else {
                AlphaTest::Stochastic
            }
        }
    }
}

/// A ray–surface intersection with interpolated attributes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceHit {
    /// Distance along the (unit) ray direction.
    pub t: f32,
    /// Index into `Scene::mesh.indices`.
    pub triangle: u32,
    /// Barycentric weights of vertices 1 and 2 (vertex 0 has `1 − x − y`).
    pub barycentrics: Vec2,
    /// World position, interpolated from the vertices (not `origin + t·dir`).
    pub position: Vec3,
    /// Unit geometric normal from the winding, `(p1 − p0) × (p2 − p0)` (glTF front side); not
    /// flipped toward the ray: see [`SurfaceHit::front_face`].
    pub geometric_normal: Vec3,
    /// Unit shading normal: interpolated vertex normal with the normal map applied; on the same
    /// side as `geometric_normal` (not flipped toward the ray).
    pub shading_normal: Vec3,
    /// Texture coordinates, set 0.
    pub uv0: Vec2,
    /// Texture coordinates, set 1 (= `uv0` when the mesh has no set 1).
    pub uv1: Vec2,
    /// Material index.
    pub material_id: u32,
    /// The ray arrived from the front side (`dir · geometric_normal < 0`).
    pub front_face: bool,
}

impl SurfaceHit {
    /// The UV set a texture reference reads.
    #[inline]
    pub fn uv(&self, set: u32) -> Vec2 {
        if set == 1 {
            self.uv1
        } else {
            self.uv0
        }
    }

    /// The geometric normal on the side of `w` (a direction leaving the surface).
    #[inline]
    pub fn geometric_normal_toward(&self, w: Vec3) -> Vec3 {
        if self.geometric_normal.dot(w) >= 0.0 {
            self.geometric_normal
        } else {
            -self.geometric_normal
        }
    }

    /// Origin for a ray leaving the surface in direction `dir` (robustly offset off the surface).
    #[inline]
    pub fn spawn_origin(&self, dir: Vec3) -> Vec3 {
        offset_ray_origin(self.position, self.geometric_normal_toward(dir))
    }
}

/// Wächter & Binder's offset: moves `p` off a surface with unit normal `n` (pointing to the side
/// the new ray leaves toward) by a few ULPs of `p` (an absolute 1/65536·n near the origin).
#[inline]
pub fn offset_ray_origin(p: Vec3, n: Vec3) -> Vec3 {
    const ORIGIN: f32 = 1.0 / 32.0;
    const FLOAT_SCALE: f32 = 1.0 / 65536.0;
    const INT_SCALE: f32 = 256.0;
    #[inline]
    fn one(p: f32, n: f32) -> f32 {
        if p.abs() < ORIGIN {
            return p + FLOAT_SCALE * n;
        }
        let of = (INT_SCALE * n) as i32;
        let bits = p.to_bits() as i32;
        let moved = if p < 0.0 { bits.wrapping_sub(of) } else { bits.wrapping_add(of) };
        let r = f32::from_bits(moved as u32);
        if r.is_finite() {
            r
        } else {
            p
        }
    }
    Vec3::new(one(p.x, n.x), one(p.y, n.y), one(p.z, n.z))
}

/// Per-ray precomputation of the watertight test.
struct WatertightRay {
    org: [f32; 3],
    k: [usize; 3],
    s: [f32; 3],
}

impl WatertightRay {
    #[inline]
    fn new(org: Vec3, dir: Vec3) -> Self {
        let a = dir.abs();
        let kz = if a.x > a.y {
            if a.x > a.z {
                0
            } else {
                2
            }
        } else if a.y > a.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        let d = dir.to_array();
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        WatertightRay { org: org.to_array(), k: [kx, ky, kz], s: [d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]] }
    }

    /// Returns (t, b1, b2) for a hit with 0 < t < t_max.
    #[inline(always)]
    fn intersect(&self, v: &[[f32; 3]; 3], t_max: f32) -> Option<(f32, f32, f32)> {
        let [kx, ky, kz] = self.k;
        let [sx, sy, sz] = self.s;
        let o = &self.org;
        let a = [v[0][0] - o[0], v[0][1] - o[1], v[0][2] - o[2]];
        let b = [v[1][0] - o[0], v[1][1] - o[1], v[1][2] - o[2]];
        let c = [v[2][0] - o[0], v[2][1] - o[1], v[2][2] - o[2]];
        let ax = a[kx] - sx * a[kz];
        let ay = a[ky] - sy * a[kz];
        let bx = b[kx] - sx * b[kz];
        let by = b[ky] - sy * b[kz];
        let cx = c[kx] - sx * c[kz];
        let cy = c[ky] - sy * c[kz];
        let mut u = cx * by - cy * bx;
        let mut vv = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        if u == 0.0 || vv == 0.0 || w == 0.0 {
            u = (cx as f64 * by as f64 - cy as f64 * bx as f64) as f32;
            vv = (ax as f64 * cy as f64 - ay as f64 * cx as f64) as f32;
            w = (bx as f64 * ay as f64 - by as f64 * ax as f64) as f32;
        }
        if (u < 0.0 || vv < 0.0 || w < 0.0) && (u > 0.0 || vv > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + vv + w;
        if det == 0.0 {
            return None;
        }
        let az = sz * a[kz];
        let bz = sz * b[kz];
        let cz = sz * c[kz];
        let t_scaled = u * az + vv * bz + w * cz;
        if det < 0.0 {
            if t_scaled >= 0.0 || t_scaled < t_max * det {
                return None;
            }
        } else if t_scaled <= 0.0 || t_scaled > t_max * det {
            return None;
        }
        let rcp = 1.0 / det;
        let t = t_scaled * rcp;
        if !(t > 0.0 && t < t_max) {
            return None;
        }
        Some((t, vv * rcp, w * rcp))
    }
}

/// A [`Scene`] prepared for rendering: BVH, light sampling data, per-material flags.
pub struct RenderScene {
    scene: Scene,
    bvh: CwBvh,
    tris: Vec<PackedTri>,
    pub(crate) alpha_tests: Vec<AlphaTest>,
    any_stochastic: bool,
    has_normals: bool,
    has_uv0: bool,
    has_uv1: bool,
    has_tangents: bool,
    pub(crate) lights: LightSet,
    bounds_min: Vec3,
    bounds_max: Vec3,
    build_time: Duration,
    triangle_count: usize,
}

impl std::fmt::Debug for RenderScene {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RenderScene")
            .field("triangles", &self.triangle_count)
            .field("bvh_nodes", &self.bvh.nodes.len())
            .field("lights", &self.lights.len())
            .field("build_time", &self.build_time)
            .finish()
    }
}

impl RenderScene {
    /// Builds the BVH ([`BvhQuality::Medium`]) and the light sampling data.
    ///
    /// Malformed input is repaired, with a note in `scene.warnings`: triangles with out-of-range
    /// vertex indices or non-finite positions are left out of the BVH, out-of-range material ids
    /// get an appended default (white dielectric) material, attribute arrays of the wrong length
    /// are ignored (normals → geometric normal, UVs → 0, tangents → derived from UVs).
    pub fn new(scene: Scene) -> Result<RenderScene> {
        Self::with_quality(scene, BvhQuality::default())
    }

    /// [`RenderScene::new`] with a chosen BVH build quality.
    pub fn with_quality(mut scene: Scene, quality: BvhQuality) -> Result<RenderScene> {
        let nv = scene.mesh.positions.len();
        let nt = scene.mesh.indices.len();

        // Materials: make every id valid.
        if scene.mesh.material_ids.len() != nt {
            scene.warnings.push(format!(
                "mesh has {} material ids for {} triangles; missing ones use a default material",
                scene.mesh.material_ids.len(),
                nt
            ));
            scene.mesh.material_ids.resize(nt, u32::MAX);
        }
        let n_mat = scene.materials.len() as u32;
        let bad_ids = scene.mesh.material_ids.iter().filter(|&&m| m >= n_mat).count();
        if bad_ids > 0 || scene.materials.is_empty() {
            let fallback = scene.materials.len() as u32;
            scene.materials.push(Material {
                name: "petzval-default".into(),
                metallic: 0.0,
                roughness: 0.5,
                ..Material::default()
            });
            for m in scene.mesh.material_ids.iter_mut() {
                if *m >= n_mat {
                    *m = fallback;
                }
            }
            if bad_ids > 0 {
                scene
                    .warnings
                    .push(format!("{bad_ids} triangles had an out-of-range material id; they use a default material"));
            }
        }
        let has_normals = scene.mesh.normals.len() == nv;
        let has_uv0 = scene.mesh.uv0.len() == nv;
        let has_uv1 = scene.mesh.uv1.len() == nv;
        let has_tangents = scene.mesh.tangents.len() == nv;
        if !has_normals && !scene.mesh.normals.is_empty() {
            scene.warnings.push("mesh normal count differs from the vertex count; using geometric normals".into());
        }
        if !has_uv0 && !scene.mesh.uv0.is_empty() {
            scene.warnings.push("mesh uv0 count differs from the vertex count; ignoring UVs".into());
        }

        let alpha_tests: Vec<AlphaTest> = scene.materials.iter().map(alpha_test_of).collect();
        let any_stochastic = alpha_tests.contains(&AlphaTest::Stochastic);

        // Valid triangles.
        let mut valid: Vec<u32> = Vec::with_capacity(nt);
        let mut invalid = 0usize;
        for (i, idx) in scene.mesh.indices.iter().enumerate() {
            if idx.iter().any(|&v| v as usize >= nv) {
                invalid += 1;
                continue;
            }
            let p = idx.map(|v| scene.mesh.positions[v as usize]);
            if !p.iter().all(|q| q.is_finite()) {
                invalid += 1;
                continue;
            }
            let area2 = (p[1] - p[0]).cross(p[2] - p[0]).length_squared();
            if !(area2 > 0.0) || !area2.is_finite() {
                continue; // degenerate: can never be hit
            }
            valid.push(i as u32);
        }
        if invalid > 0 {
            scene
                .warnings
                .push(format!("{invalid} triangles with bad vertex indices or non-finite positions were skipped"));
        }

        let start = Instant::now();
        let obvhs_tris: Vec<Triangle> = valid
            .iter()
            .map(|&i| {
                let idx = scene.mesh.indices[i as usize];
                let p = |k: usize| scene.mesh.positions[idx[k] as usize].to_array().into();
                Triangle { v0: p(0), v1: p(1), v2: p(2) }
            })
            .collect();
        let bvh = if obvhs_tris.is_empty() {
            CwBvh::default()
        } else {
            build_cwbvh_from_tris(&obvhs_tris, quality.params(), &mut Duration::default())
        };
        drop(obvhs_tris);
        let mut bvh = bvh;
        let tris: Vec<PackedTri> = bvh
            .primitive_indices
            .iter()
            .map(|&pi| {
                let i = valid[pi as usize];
                let idx = scene.mesh.indices[i as usize];
                let v = idx.map(|k| scene.mesh.positions[k as usize].to_array());
                let m = scene.mesh.material_ids[i as usize] as usize;
                let flag = if alpha_tests[m] != AlphaTest::None { ALPHA_BIT } else { 0 };
                PackedTri { v, prim: i | flag }
            })
            .collect();
        // Traversal hands out positions in `primitive_indices`, which index `tris` directly.
        bvh.primitive_indices = Vec::new();
        let build_time = start.elapsed();

        let (mut bounds_min, mut bounds_max) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for &i in &valid {
            for &k in &scene.mesh.indices[i as usize] {
                let p = scene.mesh.positions[k as usize];
                bounds_min = bounds_min.min(p);
                bounds_max = bounds_max.max(p);
            }
        }
        if valid.is_empty() {
            bounds_min = Vec3::ZERO;
            bounds_max = Vec3::ZERO;
        }
        let triangle_count = valid.len();
        let lights = LightSet::build(&scene, &valid, bounds_min, bounds_max);

        Ok(RenderScene {
            scene,
            bvh,
            tris,
            alpha_tests,
            any_stochastic,
            has_normals,
            has_uv0,
            has_uv1,
            has_tangents,
            lights,
            bounds_min,
            bounds_max,
            build_time,
            triangle_count,
        })
    }

    /// The scene (meshes, materials, textures, lights, environment).
    #[inline]
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// Gives the scene back.
    pub fn into_scene(self) -> Scene {
        self.scene
    }

    /// Triangles in the BVH (degenerate and invalid triangles are left out).
    pub fn triangle_count(&self) -> usize {
        self.triangle_count
    }

    /// Wall time of the BVH build (including the leaf-order triangle copy).
    pub fn bvh_build_time(&self) -> Duration {
        self.build_time
    }

    /// Bytes of the BVH: nodes and the leaf-order triangle copy (40 B per triangle).
    pub fn bvh_memory_bytes(&self) -> usize {
        self.bvh.nodes.len() * std::mem::size_of::<CwBvhNode>() + self.tris.len() * std::mem::size_of::<PackedTri>()
    }

    /// Number of lights the light sampler chooses from (punctual + emissive triangles + environment).
    pub fn light_count(&self) -> usize {
        self.lights.len()
    }

    /// Axis-aligned bounds of the geometry (min, max); zero when there is none.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        (self.bounds_min, self.bounds_max)
    }

    #[inline]
    fn ray_hash(origin: Vec3, dir: Vec3) -> u32 {
        // The lowest mantissa bits are dropped so that re-normalising a direction (an ULP or
        // two) does not change the decision.
        const M: u32 = !0xf;
        let mut h = hash_u32((origin.x.to_bits() & M) ^ 0x9e37_79b9);
        h = hash_u32(h ^ (origin.y.to_bits() & M));
        h = hash_u32(h ^ (origin.z.to_bits() & M));
        h = hash_u32(h ^ (dir.x.to_bits() & M));
        h = hash_u32(h ^ (dir.y.to_bits() & M));
        hash_u32(h ^ (dir.z.to_bits() & M))
    }

    /// Texture value for a reference at a hit (None when the reference is absent or dangling).
    #[inline]
    pub(crate) fn texture(&self, r: Option<TextureRef>, uv0: Vec2, uv1: Vec2) -> Option<Vec4> {
        let r = r?;
        let tex = self.scene.textures.get(r.index)?;
        Some(tex.sample(if r.uv_set == 1 { uv1 } else { uv0 }))
    }

    /// UV sets at barycentrics (b1, b2) of mesh triangle `tri`.
    #[inline]
    fn uvs_at(&self, tri: u32, b1: f32, b2: f32) -> (Vec2, Vec2) {
        let m = &self.scene.mesh;
        if !self.has_uv0 {
            return (Vec2::ZERO, Vec2::ZERO);
        }
        let [i0, i1, i2] = m.indices[tri as usize].map(|i| i as usize);
        let b0 = 1.0 - b1 - b2;
        let uv0 = m.uv0[i0] * b0 + m.uv0[i1] * b1 + m.uv0[i2] * b2;
        let uv1 = if self.has_uv1 { m.uv1[i0] * b0 + m.uv1[i1] * b1 + m.uv1[i2] * b2 } else { uv0 };
        (uv0, uv1)
    }

    /// Alpha (factor × base-colour texture alpha) of mesh triangle `tri` at barycentrics (b1, b2).
    pub(crate) fn alpha_at(&self, tri: u32, b1: f32, b2: f32) -> f32 {
        let mat = &self.scene.materials[self.scene.mesh.material_ids[tri as usize] as usize];
        let (uv0, uv1) = self.uvs_at(tri, b1, b2);
        let tex = self.texture(mat.base_color_texture, uv0, uv1).map_or(1.0, |t| t.w);
        mat.base_color.w * tex
    }

    /// Whether the surface is there (not cut out) at a candidate hit.
    #[inline(never)]
    fn alpha_passes(&self, tri: u32, b1: f32, b2: f32, ray_hash: u32) -> bool {
        let m = self.scene.mesh.material_ids[tri as usize] as usize;
        match self.alpha_tests[m] {
            AlphaTest::None => true,
            AlphaTest::Mask(cutoff) => self.alpha_at(tri, b1, b2) >= cutoff,
            AlphaTest::Stochastic => {
                let u = (hash_u32(ray_hash ^ hash_u32(tri)) >> 8) as f32 * (1.0 / (1u32 << 24) as f32);
                u < self.alpha_at(tri, b1, b2)
            }
        }
    }

    /// Closest hit along `origin + t·dir`, 0 < t < `t_max` (`dir` is normalised here; `t` is in
    /// world units). Alpha cut-outs are skipped. None for no hit or a non-finite ray.
    pub fn intersect(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<SurfaceHit> {
        let dir = dir.normalize_or_zero();
        if self.tris.is_empty() || dir == Vec3::ZERO || !origin.is_finite() || !(t_max > 0.0) {
            return None;
        }
        // −0.0 → +0.0: obvhs takes the octant from `d < 0` but the inverse from the sign bit,
        // so a −0.0 component would make every node test miss.
        let dir = dir + Vec3::ZERO;
        let wray = WatertightRay::new(origin, dir);
        let ray = Ray::new(origin.to_array().into(), dir.to_array().into(), 0.0, t_max);
        let ray_hash = if self.any_stochastic { Self::ray_hash(origin, dir) } else { 0 };
        let mut hit = RayHit::none();
        let mut best = (u32::MAX, 0.0f32, 0.0f32);
        let tris = &self.tris;
        self.bvh.ray_traverse(ray, &mut hit, |r, id| {
            let tri = &tris[id];
            if let Some((t, b1, b2)) = wray.intersect(&tri.v, r.tmax) {
                if tri.prim & ALPHA_BIT != 0 && !self.alpha_passes(tri.prim & !ALPHA_BIT, b1, b2, ray_hash) {
                    return f32::INFINITY;
                }
                best = (tri.prim & !ALPHA_BIT, b1, b2);
                return t;
            }
            f32::INFINITY
        });
        if best.0 == u32::MAX || !(hit.t < t_max) {
            return None;
        }
        Some(self.surface_hit(best.0, best.1, best.2, hit.t, dir))
    }

    /// Whether anything (after alpha cut-outs) lies on `origin + t·dir`, 0 < t < `t_max`
    /// (`dir` need not be unit; `t` is in units of its length).
    pub fn occluded(&self, origin: Vec3, dir: Vec3, t_max: f32) -> bool {
        if self.tris.is_empty() || !origin.is_finite() || !dir.is_finite() || !(t_max > 0.0) {
            return false;
        }
        let len = dir.length();
        if !(len > 0.0) {
            return false;
        }
        let dir = dir.normalize_or_zero() + Vec3::ZERO; // −0.0 → +0.0 (see `intersect`)
        let t_max = t_max * len;
        let wray = WatertightRay::new(origin, dir);
        let ray = Ray::new(origin.to_array().into(), dir.to_array().into(), 0.0, t_max);
        let ray_hash = if self.any_stochastic { Self::ray_hash(origin, dir) } else { 0 };
        let tris = &self.tris;
        !self.bvh.ray_traverse_miss(ray, |r, id| {
            let tri = &tris[id];
            if let Some((t, b1, b2)) = wray.intersect(&tri.v, r.tmax) {
                if tri.prim & ALPHA_BIT != 0 && !self.alpha_passes(tri.prim & !ALPHA_BIT, b1, b2, ray_hash) {
                    return f32::INFINITY;
                }
                return t;
            }
            f32::INFINITY
        })
    }

    /// Builds the full hit record for mesh triangle `tri` at barycentrics (b1, b2).
    pub fn surface_hit(&self, tri: u32, b1: f32, b2: f32, t: f32, dir: Vec3) -> SurfaceHit {
        let mesh = &self.scene.mesh;
        let [i0, i1, i2] = mesh.indices[tri as usize].map(|i| i as usize);
        let (p0, p1, p2) = (mesh.positions[i0], mesh.positions[i1], mesh.positions[i2]);
        let b0 = 1.0 - b1 - b2;
        let position = p0 * b0 + p1 * b1 + p2 * b2;
        let e1 = p1 - p0;
        let e2 = p2 - p0;
        let ng = e1.cross(e2).normalize_or(Vec3::Z);
        let mut ns = if self.has_normals {
            let n = mesh.normals[i0] * b0 + mesh.normals[i1] * b1 + mesh.normals[i2] * b2;
            let n = n.normalize_or_zero();
            if n == Vec3::ZERO || !n.is_finite() {
                ng
            } else if n.dot(ng) < 0.0 {
                // Vertex normals disagreeing with the winding: keep the shading normal on the
                // geometric side so front/back stay consistent.
                -n
            } else {
                n
            }
        } else {
            ng
        };
        let (uv0, uv1) = self.uvs_at(tri, b1, b2);
        let material_id = mesh.material_ids[tri as usize];
        let mat = &self.scene.materials[material_id as usize];
        if let Some(nref) = mat.normal_texture {
            if let Some(texel) = self.texture(Some(nref), uv0, uv1) {
                let (tangent, bitangent) = self.tangent_frame(tri, [i0, i1, i2], [b0, b1, b2], ns, nref.uv_set);
                let s = mat.normal_scale;
                let m = Vec3::new((texel.x * 2.0 - 1.0) * s, (texel.y * 2.0 - 1.0) * s, texel.z * 2.0 - 1.0);
                let n = (tangent * m.x + bitangent * m.y + ns * m.z).normalize_or_zero();
                if n != Vec3::ZERO && n.is_finite() {
                    ns = n;
                }
            }
        }
        SurfaceHit {
            t,
            triangle: tri,
            barycentrics: Vec2::new(b1, b2),
            position,
            geometric_normal: ng,
            shading_normal: ns,
            uv0,
            uv1,
            material_id,
            front_face: dir.dot(ng) < 0.0,
        }
    }

    /// Orthonormal tangent and bitangent around `n` for normal mapping: the vertex tangents
    /// (glTF: bitangent = n × t · w), else the triangle's UV derivatives (glTF's v axis points
    /// down the image, so the bitangent is −∂p/∂v), else an arbitrary frame.
    fn tangent_frame(&self, tri: u32, idx: [usize; 3], b: [f32; 3], n: Vec3, uv_set: u32) -> (Vec3, Vec3) {
        let mesh = &self.scene.mesh;
        if self.has_tangents {
            let t4: Vec4 = mesh.tangents[idx[0]] * b[0] + mesh.tangents[idx[1]] * b[1] + mesh.tangents[idx[2]] * b[2];
            let t = t4.truncate();
            let t = (t - n * n.dot(t)).normalize_or_zero();
            if t != Vec3::ZERO && t.is_finite() {
                let w = if mesh.tangents[idx[0]].w < 0.0 { -1.0 } else { 1.0 };
                return (t, n.cross(t) * w);
            }
        }
        let uvs: Option<&Vec<Vec2>> = if uv_set == 1 && self.has_uv1 {
            Some(&mesh.uv1)
        } else if self.has_uv0 {
            Some(&mesh.uv0)
        } else {
            None
        };
        if let Some(uvs) = uvs {
            let _ = tri;
            let (p0, p1, p2) = (mesh.positions[idx[0]], mesh.positions[idx[1]], mesh.positions[idx[2]]);
            let (t0, t1, t2) = (uvs[idx[0]], uvs[idx[1]], uvs[idx[2]]);
            let (dp1, dp2) = (p1 - p0, p2 - p0);
            let (du1, du2) = (t1 - t0, t2 - t0);
            let det = du1.x * du2.y - du1.y * du2.x;
            if det.abs() > 1e-20 {
                let r = 1.0 / det;
                let dpdu = (dp1 * du2.y - dp2 * du1.y) * r;
                let dpdv = (dp2 * du1.x - dp1 * du2.x) * r;
                let t = (dpdu - n * n.dot(dpdu)).normalize_or_zero();
                if t != Vec3::ZERO && t.is_finite() {
                    let up = -dpdv;
                    let w = if n.cross(t).dot(up) < 0.0 { -1.0 } else { 1.0 };
                    return (t, n.cross(t) * w);
                }
            }
        }
        let (t, b) = super::bsdf::orthonormal_basis(n);
        (t, b)
    }

    /// Emitted radiance of the hit's material toward the side the ray came from: front side
    /// only unless the material is double sided (glTF). Zero for non-emissive materials.
    pub fn emission(&self, hit: &SurfaceHit) -> Vec3 {
        let mat = &self.scene.materials[hit.material_id as usize];
        if !mat.is_emissive() || !(hit.front_face || mat.double_sided) {
            return Vec3::ZERO;
        }
        let tex = self.texture(mat.emissive_texture, hit.uv0, hit.uv1).map_or(Vec3::ONE, |t| t.truncate());
        mat.emissive * tex
    }
}
