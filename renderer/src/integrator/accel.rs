//! Ray casting: the scene's triangles in obvhs compressed wide BVHs (CWBVH), two levels,
//! closest-hit and any-hit queries with alpha cut-outs, and surface hits with interpolated
//! attributes.
//!
//! * Two levels. A mesh placed by exactly one instance is baked into world space into one
//!   shared bottom-level BVH (as Cycles and Embree do for non-instanced geometry), so a scene
//!   without real instancing pays nothing for the top level. Every mesh placed by two or more
//!   instances gets its own BVH in object space (built once), and a top-level CWBVH over the
//!   instances' world bounds holds them: at an instance leaf the ray is moved into object space
//!   by the precomputed inverse transform, its direction left unnormalised so `t` stays the
//!   world distance. A ray traverses the world BVH first, then the top level with `t_max`
//!   shrunk to the hit found.
//! * Attributes of a hit are brought to world space per hit: positions by the transform,
//!   normals by the inverse transpose, tangents by the linear part (`w` × sign(det)); for a
//!   negative determinant the geometric normal is negated (glTF: mirroring flips the winding),
//!   so the front side stays the side the normals point to. Identity instances skip all this,
//!   and a baked mesh placed by a transform keeps its positions and normals in world space,
//!   computed once by the same operations (the same bits), so its hits read them.
//! * Triangles are copied into leaf order (the builder's `primitive_indices`), so the
//!   traversal closure reads them sequentially; each keeps its index: in the world BVH a
//!   running index over the baked instances' triangles, in an instanced mesh's BVH the mesh
//!   triangle.
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
//!
//! | memory item | bytes |
//! |---|---|
//! | leaf-order triangle | 40 per triangle, once per mesh (or per baked instance) |
//! | BVH node | 80 per node (obvhs `CwBvhNode`) |
//! | instance transforms | 112 per instance (object-to-world, normal matrix, flags) |
//! | world-space attributes | 24 per vertex (position, normal) of a baked mesh placed by a transform |
//! | top-level leaf | 80 per instance of an instanced mesh (world-to-object, indices), plus top-level nodes |

use std::time::{Duration, Instant};

use glam::{Affine3A, Mat3, Vec2, Vec3, Vec4};
use obvhs::{
    aabb::Aabb,
    cwbvh::{
        builder::{build_cwbvh, build_cwbvh_from_tris},
        node::CwBvhNode,
        CwBvh,
    },
    ray::{Ray, RayHit},
    triangle::Triangle,
    BvhBuildParams,
};

use super::bsdf::{Bsdf, Coat};
use super::lights::{EmitterGroup, LightSet};
use super::packet::{self, PACKET};
use super::traverse;
use crate::sampler::hash_u32;
use crate::scene::{cofactor, AlphaMode, AnisotropyTangent, Material, Mesh, Scene, TextureRef};
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

/// The largest coordinate a triangle may have, in scene units (metres): beyond it the BVH's
/// box arithmetic (surface areas, extents) overflows f32 and the builder panics (found by the
/// fuzzing in `renderer/tests/fuzz.rs`: mutated buffers decoding to about 10³⁸).
pub use crate::limits::MAX_COORD;

/// Refuses a scene whose stored triangles exceed [`crate::limits::MAX_STORED_TRIANGLES`] or whose
/// BVH build would need more memory than is available.
fn check_geometry_size(scene: &Scene) -> Result<()> {
    use crate::limits::{check_memory, format_bytes, over_budget, BVH_BYTES_PER_TRIANGLE, MAX_STORED_TRIANGLES};
    let file = if scene.source.is_empty() { "scene" } else { scene.source.as_str() };
    let stored: usize = scene.meshes.iter().map(Mesh::triangle_count).sum();
    if stored > MAX_STORED_TRIANGLES {
        return Err(crate::Error::scene(
            file,
            "",
            format!(
                "{stored} stored triangles are more than the {MAX_STORED_TRIANGLES} the BVH can index (use instancing)"
            ),
        ));
    }
    let need = stored as u64 * BVH_BYTES_PER_TRIANGLE + scene.instances.len() as u64 * 256;
    check_memory(need).map_err(|budget| {
        crate::Error::scene(
            file,
            "",
            format!(
                "building the BVH for {stored} triangles and {} instances needs about {}, {}",
                scene.instances.len(),
                format_bytes(need),
                over_budget(budget)
            ),
        )
    })
}

/// Whether a position is finite and within [`MAX_COORD`].
fn in_range(p: Vec3) -> bool {
    p.is_finite() && p.abs().max_element() <= MAX_COORD
}

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
    /// A light's emitting surface (an area light, as Cycles' lights): no shadow, and seen only
    /// from its front.
    LightEmitter,
}

/// The alpha test of material `m`; `vertex_alpha`: a mesh using it has vertex colours with
/// alpha below 1.
fn alpha_test_of(m: &Material, vertex_alpha: bool) -> AlphaTest {
    if m.light_emitter {
        return AlphaTest::LightEmitter;
    }
    let factor = m.base_color.w;
    let textured = m.base_color_texture.is_some() || vertex_alpha;
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
    /// Index into `Scene::instances`.
    pub instance: u32,
    /// Index into the instance's mesh's `indices`.
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

/// How many surfaces hidden from the camera ([`crate::scene::Material::visible_to_camera`]) one
/// camera ray goes on through before it stops (and sees the environment).
pub const MAX_HIDDEN_LAYERS: u32 = 64;

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

/// The watertight test of one triangle against up to eight rays that share their axis
/// permutation `k` (coherent rays: one pixel's camera rays), as the eight lanes of AVX
/// operations: per lane the same products, differences and comparisons in the same order as
/// [`WatertightRay::intersect`] (no fused operations), so the same bits.
#[cfg(target_arch = "x86_64")]
struct WatertightLanes {
    k: [usize; 3],
    /// Origins' components kx, ky, kz per lane.
    org: [[f32; PACKET]; 3],
    /// Shears sx, sy, sz per lane.
    s: [[f32; PACKET]; 3],
}

/// What [`WatertightLanes::intersect`] finds for a lane mask.
#[cfg(target_arch = "x86_64")]
struct LaneHits {
    /// Lanes with a hit at 0 < t < t_max.
    hit: u8,
    /// Lanes whose edge functions had an exact zero: [`WatertightRay::intersect`] decides them
    /// (its double-precision retry).
    retry: u8,
    t: [f32; PACKET],
    b1: [f32; PACKET],
    b2: [f32; PACKET],
}

#[cfg(target_arch = "x86_64")]
impl WatertightLanes {
    /// The lanes of `rays` in `active`, when they all share one permutation.
    fn new(rays: &[WatertightRay; PACKET], active: u8) -> Option<WatertightLanes> {
        let lead = &rays[active.trailing_zeros() as usize % PACKET];
        let mut lanes = WatertightLanes { k: lead.k, org: [[0.0; PACKET]; 3], s: [[0.0; PACKET]; 3] };
        for (i, r) in rays.iter().enumerate() {
            if active & (1 << i) == 0 {
                continue;
            }
            if r.k != lead.k {
                return None;
            }
            for a in 0..3 {
                lanes.org[a][i] = r.org[lead.k[a]];
                lanes.s[a][i] = r.s[a];
            }
        }
        Some(lanes)
    }

    /// Tests triangle `v` against the lanes of `mask`, with each lane's `t_max`.
    #[target_feature(enable = "avx2")]
    fn intersect(&self, v: &[[f32; 3]; 3], t_max: &[f32; PACKET], mask: u8) -> LaneHits {
        use std::arch::x86_64::*;
        // SAFETY: whole [f32; 8] arrays, unaligned loads and stores.
        let load = |x: &[f32; PACKET]| unsafe { _mm256_loadu_ps(x.as_ptr()) };
        let [kx, ky, kz] = self.k;
        let (ox, oy, oz) = (load(&self.org[0]), load(&self.org[1]), load(&self.org[2]));
        let (sx, sy, sz) = (load(&self.s[0]), load(&self.s[1]), load(&self.s[2]));
        // 1. Vertices relative to the origins, sheared (a[kx] − sx·a[kz], ...).
        let rel = |p: &[f32; 3]| {
            let (x, y, z) = (
                _mm256_sub_ps(_mm256_set1_ps(p[kx]), ox),
                _mm256_sub_ps(_mm256_set1_ps(p[ky]), oy),
                _mm256_sub_ps(_mm256_set1_ps(p[kz]), oz),
            );
            (_mm256_sub_ps(x, _mm256_mul_ps(sx, z)), _mm256_sub_ps(y, _mm256_mul_ps(sy, z)), z)
        };
        let (ax, ay, az_) = rel(&v[0]);
        let (bx, by, bz_) = rel(&v[1]);
        let (cx, cy, cz_) = rel(&v[2]);
        // 2. Edge functions; an exact zero goes to the scalar test's double-precision retry.
        let u = _mm256_sub_ps(_mm256_mul_ps(cx, by), _mm256_mul_ps(cy, bx));
        let vv = _mm256_sub_ps(_mm256_mul_ps(ax, cy), _mm256_mul_ps(ay, cx));
        let w = _mm256_sub_ps(_mm256_mul_ps(bx, ay), _mm256_mul_ps(by, ax));
        let zero = _mm256_setzero_ps();
        let is_zero = _mm256_or_ps(
            _mm256_or_ps(_mm256_cmp_ps::<_CMP_EQ_OQ>(u, zero), _mm256_cmp_ps::<_CMP_EQ_OQ>(vv, zero)),
            _mm256_cmp_ps::<_CMP_EQ_OQ>(w, zero),
        );
        let any_neg = _mm256_or_ps(
            _mm256_or_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(u, zero), _mm256_cmp_ps::<_CMP_LT_OQ>(vv, zero)),
            _mm256_cmp_ps::<_CMP_LT_OQ>(w, zero),
        );
        let any_pos = _mm256_or_ps(
            _mm256_or_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(u, zero), _mm256_cmp_ps::<_CMP_GT_OQ>(vv, zero)),
            _mm256_cmp_ps::<_CMP_GT_OQ>(w, zero),
        );
        let mut fail = _mm256_and_ps(any_neg, any_pos);
        // 3. Determinant and scaled distance, within (0, t_max) on the determinant's side.
        let det = _mm256_add_ps(_mm256_add_ps(u, vv), w);
        fail = _mm256_or_ps(fail, _mm256_cmp_ps::<_CMP_EQ_OQ>(det, zero));
        let (az, bz, cz) = (_mm256_mul_ps(sz, az_), _mm256_mul_ps(sz, bz_), _mm256_mul_ps(sz, cz_));
        let t_scaled = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(u, az), _mm256_mul_ps(vv, bz)), _mm256_mul_ps(w, cz));
        let tm = load(t_max);
        let limit = _mm256_mul_ps(tm, det);
        let neg = _mm256_cmp_ps::<_CMP_LT_OQ>(det, zero);
        let fail_neg =
            _mm256_or_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(t_scaled, zero), _mm256_cmp_ps::<_CMP_LT_OQ>(t_scaled, limit));
        let fail_pos =
            _mm256_or_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t_scaled, zero), _mm256_cmp_ps::<_CMP_GT_OQ>(t_scaled, limit));
        fail = _mm256_or_ps(fail, _mm256_blendv_ps(fail_pos, fail_neg, neg));
        // 4. Distance and barycentrics.
        let rcp = _mm256_div_ps(_mm256_set1_ps(1.0), det);
        let t = _mm256_mul_ps(t_scaled, rcp);
        let ok = _mm256_and_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(t, zero), _mm256_cmp_ps::<_CMP_LT_OQ>(t, tm));
        let retry = _mm256_movemask_ps(is_zero) as u8 & mask;
        let hit = (_mm256_movemask_ps(_mm256_andnot_ps(fail, ok)) as u8) & mask & !retry;
        let mut out = LaneHits { hit, retry, t: [0.0; PACKET], b1: [0.0; PACKET], b2: [0.0; PACKET] };
        // SAFETY: whole [f32; 8] arrays.
        unsafe {
            _mm256_storeu_ps(out.t.as_mut_ptr(), t);
            _mm256_storeu_ps(out.b1.as_mut_ptr(), _mm256_mul_ps(vv, rcp));
            _mm256_storeu_ps(out.b2.as_mut_ptr(), _mm256_mul_ps(w, rcp));
        }
        out
    }
}

/// One bottom-level BVH: nodes and triangles in leaf order.
#[derive(Default)]
struct Blas {
    bvh: CwBvh,
    tris: Vec<PackedTri>,
}

impl Blas {
    /// Builds over `tris` (vertices, and the index kept in [`PackedTri::prim`] with its alpha bit).
    fn build(tris: &[([Vec3; 3], u32)], quality: BvhQuality) -> Blas {
        if tris.is_empty() {
            return Blas::default();
        }
        let obvhs_tris: Vec<Triangle> = tris
            .iter()
            .map(|(v, _)| Triangle {
                v0: v[0].to_array().into(),
                v1: v[1].to_array().into(),
                v2: v[2].to_array().into(),
            })
            .collect();
        let mut bvh = build_cwbvh_from_tris(&obvhs_tris, quality.params(), &mut Duration::default());
        drop(obvhs_tris);
        let packed = bvh
            .primitive_indices
            .iter()
            .map(|&pi| {
                let (v, prim) = tris[pi as usize];
                PackedTri { v: v.map(|p| p.to_array()), prim }
            })
            .collect();
        // Traversal hands out positions in `primitive_indices`, which index `tris` directly.
        bvh.primitive_indices = Vec::new();
        Blas { bvh, tris: packed }
    }

    fn memory_bytes(&self) -> usize {
        self.bvh.nodes.len() * std::mem::size_of::<CwBvhNode>() + self.tris.len() * std::mem::size_of::<PackedTri>()
    }
}

/// An instance's transforms as shading needs them.
#[derive(Debug, Clone, Copy)]
struct InstanceXf {
    object_to_world: Affine3A,
    /// Inverse transpose × sign(det) (up to scale): object normals → world normals.
    normal: Mat3,
    /// sign(det): −1 flips the geometric normal and the tangent handedness.
    sign: f32,
    /// Exactly the identity: attributes are used as stored.
    identity: bool,
}

/// A baked mesh's vertex positions and normals in world space, where its one instance places it
/// by a transform other than the identity: what every hit and light sample would otherwise
/// transform again, computed once with the same operations (so the same bits).
#[derive(Debug, Clone, Default)]
struct WorldAttributes {
    positions: Vec<Vec3>,
    /// Empty when the mesh has no usable normals.
    normals: Vec<Vec3>,
}

impl WorldAttributes {
    /// `mesh`'s attributes placed by `xf` (not the identity).
    fn new(mesh: &Mesh, info: MeshInfo, xf: &InstanceXf) -> Self {
        let positions = mesh.positions.iter().map(|&p| xf.object_to_world.transform_point3(p)).collect();
        let normals = if info.has_normals {
            mesh.normals.iter().map(|&n| (xf.normal * n).normalize_or_zero()).collect()
        } else {
            Vec::new()
        };
        WorldAttributes { positions, normals }
    }

    fn memory_bytes(&self) -> usize {
        (self.positions.len() + self.normals.len()) * std::mem::size_of::<Vec3>()
    }
}

/// A leaf of the top-level BVH.
#[derive(Debug, Clone, Copy)]
struct TlasLeaf {
    world_to_object: Affine3A,
    /// Index into `RenderScene::blases`.
    blas: u32,
    /// Index into `Scene::instances`.
    instance: u32,
}

/// Which attribute arrays of a mesh are usable (lengths match the vertex count).
#[derive(Debug, Clone, Copy, Default)]
struct MeshInfo {
    has_normals: bool,
    /// Some triangle's vertex normals differ (smooth shading): only then can the shadow
    /// terminator's lift be non-zero (Cycles' smooth-normal flag).
    smooth_normals: bool,
    has_uv0: bool,
    has_uv1: bool,
    has_tangents: bool,
    has_colors: bool,
}

/// A candidate hit during traversal.
#[derive(Debug, Clone, Copy)]
enum Candidate {
    /// Running index into the world BVH's baked triangles.
    Baked(u32),
    /// (instance, mesh triangle).
    Instanced(u32, u32),
}

/// Bytes of a [`RenderScene`]'s scene data and acceleration structures (see
/// [`RenderScene::memory`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SceneMemory {
    /// Mesh arrays (`Scene::meshes`, each mesh once).
    pub mesh_bytes: usize,
    /// Instance records (`Scene::instances`).
    pub instance_bytes: usize,
    /// The world BVH of baked (singly-placed) meshes: nodes and leaf-order triangles.
    pub world_bvh_bytes: usize,
    /// World-space positions and normals of baked meshes placed by a transform (read by
    /// shading instead of transforming at every hit).
    pub world_attribute_bytes: usize,
    /// The per-mesh BVHs of instanced meshes (each once).
    pub blas_bytes: usize,
    /// The top level: nodes, leaves and the per-instance transforms.
    pub tlas_bytes: usize,
}

impl SceneMemory {
    /// Everything.
    pub fn total(&self) -> usize {
        self.mesh_bytes
            + self.instance_bytes
            + self.world_bvh_bytes
            + self.world_attribute_bytes
            + self.blas_bytes
            + self.tlas_bytes
    }
}

/// A [`Scene`] prepared for rendering: BVHs, light sampling data, per-material flags.
pub struct RenderScene {
    scene: Scene,
    /// Baked meshes in world space.
    world: Blas,
    /// Baked triangle k belongs to instance `baked_instances[j]` for
    /// `baked_offsets[j] ≤ k < baked_offsets[j + 1]`, as mesh triangle `k − baked_offsets[j]`.
    baked_offsets: Vec<u32>,
    baked_instances: Vec<u32>,
    /// Object-space BVHs of meshes with several instances.
    blases: Vec<Blas>,
    tlas: CwBvh,
    tlas_leaves: Vec<TlasLeaf>,
    /// Per instance (`Scene::instances` order).
    xforms: Vec<InstanceXf>,
    /// Per mesh.
    mesh_info: Vec<MeshInfo>,
    /// Per mesh: a baked mesh's world-space attributes, where its instance transforms it.
    world_attributes: Vec<Option<WorldAttributes>>,
    /// Per mesh, where some material is anisotropic: its texture space (centre, extents) for
    /// radial tangents; empty otherwise.
    texspaces: Vec<(Vec3, Vec3)>,
    pub(crate) alpha_tests: Vec<AlphaTest>,
    /// Per material: its clear coat, built once.
    coats: Vec<Option<Coat>>,
    /// Per material with metallic 0 and no metallic-roughness texture: its BSDF with the base
    /// colour left out ([`Bsdf::with_base`] completes it per hit), built once.
    bsdf_templates: Vec<Option<Bsdf<'static>>>,
    any_stochastic: bool,
    /// Some material is hidden from camera rays.
    any_hidden_from_camera: bool,
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
            .field("world_bvh_nodes", &self.world.bvh.nodes.len())
            .field("instanced_meshes", &self.blases.len())
            .field("tlas_leaves", &self.tlas_leaves.len())
            .field("lights", &self.lights.len())
            .field("build_time", &self.build_time)
            .finish()
    }
}

/// Repairs a mesh's material ids (missing or out of range → `fallback`); returns how many were bad.
fn repair_material_ids(mesh: &mut Mesh, n_mat: u32, fallback: u32) -> usize {
    let nt = mesh.indices.len();
    let mut bad = 0;
    if mesh.material_ids.len() != nt {
        bad += nt.saturating_sub(mesh.material_ids.len());
        mesh.material_ids.resize(nt, fallback);
    }
    for m in mesh.material_ids.iter_mut() {
        if *m >= n_mat {
            *m = fallback;
            bad += 1;
        }
    }
    bad
}

impl RenderScene {
    /// Builds the BVHs ([`BvhQuality::Medium`]) and the light sampling data.
    ///
    /// Malformed input is repaired, with a note in `scene.warnings`: triangles with out-of-range
    /// vertex indices or non-finite positions are left out of the BVH, out-of-range material ids
    /// get an appended default (white dielectric) material, attribute arrays of the wrong length
    /// are ignored (normals → geometric normal, UVs → 0, tangents → derived from UVs), instances
    /// of a missing mesh or with a singular or non-finite transform are skipped.
    pub fn new(scene: Scene) -> Result<RenderScene> {
        Self::with_quality(scene, BvhQuality::default())
    }

    /// [`RenderScene::new`] with a chosen BVH build quality.
    pub fn with_quality(mut scene: Scene, quality: BvhQuality) -> Result<RenderScene> {
        // Limits first: emitted values, stored triangles, the BVH build's memory.
        scene.check_values()?;
        check_geometry_size(&scene)?;
        // Materials: make every id valid.
        let n_mat = scene.materials.len() as u32;
        let needs_fallback = scene.materials.is_empty()
            || scene
                .meshes
                .iter()
                .any(|m| m.material_ids.len() != m.indices.len() || m.material_ids.iter().any(|&i| i >= n_mat));
        if needs_fallback {
            let fallback = scene.materials.len() as u32;
            scene.materials.push(Material {
                name: "petzval-default".into(),
                metallic: 0.0,
                roughness: 0.5,
                ..Material::default()
            });
            let mut bad_ids = 0;
            for (k, mesh) in scene.meshes.iter_mut().enumerate() {
                if mesh.material_ids.len() != mesh.indices.len() {
                    scene.warnings.push(format!(
                        "mesh {k} has {} material ids for {} triangles; missing ones use a default material",
                        mesh.material_ids.len(),
                        mesh.indices.len()
                    ));
                }
                bad_ids += repair_material_ids(mesh, n_mat, fallback);
            }
            if bad_ids > 0 {
                scene
                    .warnings
                    .push(format!("{bad_ids} triangles had an out-of-range material id; they use a default material"));
            }
        }
        let mut mesh_info = Vec::with_capacity(scene.meshes.len());
        for (k, m) in scene.meshes.iter().enumerate() {
            let nv = m.positions.len();
            let finite_uv0 = m.uv0.iter().all(|t| t.is_finite());
            let finite_uv1 = m.uv1.iter().all(|t| t.is_finite());
            if !finite_uv0 || !finite_uv1 {
                scene.warnings.push(format!("mesh {k}: non-finite texture coordinates; ignoring that UV set"));
            }
            let has_normals = m.normals.len() == nv;
            let smooth_normals = has_normals
                && m.indices.iter().any(|t| {
                    let [a, b, c] = t.map(|i| m.normals.get(i as usize).copied().unwrap_or_default());
                    a != b || b != c
                });
            let info = MeshInfo {
                has_normals,
                smooth_normals,
                has_uv0: m.uv0.len() == nv && finite_uv0,
                has_uv1: m.uv1.len() == nv && m.uv0.len() == nv && finite_uv0 && finite_uv1,
                has_tangents: m.tangents.len() == nv,
                has_colors: m.colors.len() == nv && nv > 0,
            };
            if !info.has_normals && !m.normals.is_empty() {
                scene
                    .warnings
                    .push(format!("mesh {k}: normal count differs from the vertex count; using geometric normals"));
            }
            if m.uv0.len() != nv && !m.uv0.is_empty() {
                scene.warnings.push(format!("mesh {k}: uv0 count differs from the vertex count; ignoring UVs"));
            }
            mesh_info.push(info);
        }

        // a vertex colour's alpha below 1 varies its triangles' materials' alpha, as a texture does
        let mut vertex_alpha = vec![false; scene.materials.len()];
        for m in scene.meshes.iter().filter(|m| m.colors.len() == m.positions.len()) {
            if m.colors.iter().any(|c| c.w < 1.0) {
                for &id in &m.material_ids {
                    if let Some(v) = vertex_alpha.get_mut(id as usize) {
                        *v = true;
                    }
                }
            }
        }
        let alpha_tests: Vec<AlphaTest> =
            scene.materials.iter().zip(&vertex_alpha).map(|(m, &v)| alpha_test_of(m, v)).collect();
        let any_stochastic = alpha_tests.contains(&AlphaTest::Stochastic);
        let any_hidden_from_camera = scene.materials.iter().any(|m| !m.visible_to_camera);
        let coats: Vec<Option<Coat>> =
            scene.materials.iter().map(|m| Coat::new(m.coat, m.coat_roughness, m.coat_ior, m.coat_tint)).collect();
        let bsdf_templates = scene
            .materials
            .iter()
            .map(|m| {
                (m.metallic == 0.0 && m.metallic_roughness_texture.is_none() && m.anisotropy.is_none())
                    .then(|| Bsdf::new(Vec3::ZERO, m.metallic, m.roughness, m.specular, m.ior))
            })
            .collect();
        let texspaces =
            if scene.materials.iter().any(|m| m.anisotropy.is_some()) { texture_spaces(&scene.meshes) } else { vec![] };
        let alpha_flag = |mesh: &Mesh, t: u32| {
            if alpha_tests[mesh.material_ids[t as usize] as usize] != AlphaTest::None {
                ALPHA_BIT
            } else {
                0
            }
        };

        // Triangles with valid indices and finite object-space positions, per mesh.
        let mut invalid = 0usize;
        let valid: Vec<Vec<u32>> = scene
            .meshes
            .iter()
            .map(|m| {
                let nv = m.positions.len();
                let mut v = Vec::with_capacity(m.indices.len());
                for (i, idx) in m.indices.iter().enumerate() {
                    if idx.iter().any(|&k| k as usize >= nv) || !idx.iter().all(|&k| in_range(m.positions[k as usize]))
                    {
                        invalid += 1;
                        continue;
                    }
                    v.push(i as u32);
                }
                v
            })
            .collect();
        if invalid > 0 {
            scene
                .warnings
                .push(format!(
                "{invalid} triangles with bad vertex indices or non-finite or out-of-range positions (beyond {MAX_COORD:e}) were skipped"
            ));
        }

        // Instances: validate transforms; count placements per mesh.
        let mut xforms = Vec::with_capacity(scene.instances.len());
        let mut usable = vec![false; scene.instances.len()];
        let mut uses = vec![0u32; scene.meshes.len()];
        let mut skipped = 0usize;
        for (i, inst) in scene.instances.iter().enumerate() {
            let xf = inst.object_to_world;
            let lin = Mat3::from(xf.matrix3);
            let det = lin.determinant();
            let sign = if det < 0.0 { -1.0 } else { 1.0 };
            let inv = xf.inverse();
            let ok = (inst.mesh as usize) < scene.meshes.len()
                && xf.is_finite()
                && det != 0.0
                && det.is_finite()
                && inv.is_finite();
            xforms.push(InstanceXf {
                object_to_world: xf,
                normal: cofactor(lin) * sign,
                sign,
                identity: xf == Affine3A::IDENTITY,
            });
            if ok {
                usable[i] = true;
                uses[inst.mesh as usize] += 1;
            } else {
                skipped += 1;
            }
        }
        if skipped > 0 {
            scene.warnings.push(format!(
                "{skipped} instances refer to a missing mesh or have a singular or non-finite transform; skipped"
            ));
        }

        let start = Instant::now();
        // World BVH: meshes placed once, baked.
        let mut baked: Vec<([Vec3; 3], u32)> = Vec::new();
        let mut baked_offsets = vec![0u32];
        let mut baked_instances = Vec::new();
        let (mut bounds_min, mut bounds_max) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        // Triangles and instances that their transforms place beyond MAX_COORD (never hit).
        let (mut placed_out, mut instances_out) = (0usize, 0usize);
        for (i, inst) in scene.instances.iter().enumerate() {
            if !usable[i] || uses[inst.mesh as usize] != 1 {
                continue;
            }
            let m = &scene.meshes[inst.mesh as usize];
            let xf = &xforms[i];
            let base = baked_offsets[baked_offsets.len() - 1];
            for &t in &valid[inst.mesh as usize] {
                let v = m.indices[t as usize].map(|k| {
                    let p = m.positions[k as usize];
                    if xf.identity {
                        p
                    } else {
                        xf.object_to_world.transform_point3(p)
                    }
                });
                if !v.iter().all(|p| in_range(*p)) {
                    placed_out += 1;
                    continue; // placed out of range by its transform: never hit
                }
                let area2 = (v[1] - v[0]).cross(v[2] - v[0]).length_squared();
                if !(area2 > 0.0) || !area2.is_finite() {
                    continue; // degenerate: never hit
                }
                for p in v {
                    bounds_min = bounds_min.min(p);
                    bounds_max = bounds_max.max(p);
                }
                // The running index is the position in the mesh triangle list + base, so that a
                // hit maps back without a table; skipped triangles leave gaps.
                baked.push((v, (base + t) | alpha_flag(m, t)));
            }
            baked_offsets.push(base + m.indices.len() as u32);
            baked_instances.push(i as u32);
        }
        if baked.len() >= ALPHA_BIT as usize || baked_offsets.last().is_some_and(|&o| o >= ALPHA_BIT) {
            return Err(crate::Error::scene("scene", "", "more than 2³¹ triangles placed once"));
        }
        let mut triangle_count = baked.len();
        let world = Blas::build(&baked, quality);
        drop(baked);
        let mut world_attributes: Vec<Option<WorldAttributes>> = vec![None; scene.meshes.len()];
        for &i in &baked_instances {
            let (xf, k) = (&xforms[i as usize], scene.instances[i as usize].mesh as usize);
            if !xf.identity {
                world_attributes[k] = Some(WorldAttributes::new(&scene.meshes[k], mesh_info[k], xf));
            }
        }

        // Per-mesh BVHs and the top level over their instances.
        let mut blas_of_mesh = vec![u32::MAX; scene.meshes.len()];
        let mut blases = Vec::new();
        let mut blas_bounds: Vec<(Vec3, Vec3)> = Vec::new();
        let mut blas_tris: Vec<usize> = Vec::new();
        for (k, m) in scene.meshes.iter().enumerate() {
            if uses[k] < 2 {
                continue;
            }
            let mut tris = Vec::with_capacity(valid[k].len());
            let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
            for &t in &valid[k] {
                let v = m.indices[t as usize].map(|i| m.positions[i as usize]);
                let area2 = (v[1] - v[0]).cross(v[2] - v[0]).length_squared();
                if !(area2 > 0.0) || !area2.is_finite() {
                    continue;
                }
                for p in v {
                    lo = lo.min(p);
                    hi = hi.max(p);
                }
                tris.push((v, t | alpha_flag(m, t)));
            }
            if tris.is_empty() {
                continue;
            }
            blas_of_mesh[k] = blases.len() as u32;
            blas_tris.push(tris.len());
            blases.push(Blas::build(&tris, quality));
            blas_bounds.push((lo, hi));
        }
        let mut leaves: Vec<TlasLeaf> = Vec::new();
        let mut aabbs: Vec<Aabb> = Vec::new();
        for (i, inst) in scene.instances.iter().enumerate() {
            if !usable[i] {
                continue;
            }
            let b = blas_of_mesh[inst.mesh as usize];
            if b == u32::MAX {
                continue;
            }
            let (lo, hi) = blas_bounds[b as usize];
            let xf = &xforms[i].object_to_world;
            let (mut wlo, mut whi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
            for c in 0..8 {
                let corner = Vec3::new(
                    if c & 1 == 0 { lo.x } else { hi.x },
                    if c & 2 == 0 { lo.y } else { hi.y },
                    if c & 4 == 0 { lo.z } else { hi.z },
                );
                let p = xf.transform_point3(corner);
                wlo = wlo.min(p);
                whi = whi.max(p);
            }
            if !(in_range(wlo) && in_range(whi)) {
                instances_out += 1;
                continue;
            }
            bounds_min = bounds_min.min(wlo);
            bounds_max = bounds_max.max(whi);
            triangle_count += blas_tris[b as usize];
            leaves.push(TlasLeaf { world_to_object: xf.inverse(), blas: b, instance: i as u32 });
            aabbs.push(Aabb::new(wlo.to_array().into(), whi.to_array().into()));
        }
        let (tlas, tlas_leaves) = if aabbs.is_empty() {
            (CwBvh::default(), Vec::new())
        } else {
            let mut tlas = build_cwbvh(&aabbs, quality.params(), &mut Duration::default());
            let ordered = tlas.primitive_indices.iter().map(|&pi| leaves[pi as usize]).collect();
            tlas.primitive_indices = Vec::new();
            (tlas, ordered)
        };
        if placed_out > 0 || instances_out > 0 {
            scene.warnings.push(format!(
                "{placed_out} triangles and {instances_out} instances that their transforms place beyond {MAX_COORD:e} scene units were skipped"
            ));
        }
        let build_time = start.elapsed();
        if world.tris.is_empty() && tlas_leaves.is_empty() {
            bounds_min = Vec3::ZERO;
            bounds_max = Vec3::ZERO;
        }

        // Emissive triangles, per instance in instance order.
        let emissive_mat: Vec<bool> = scene.materials.iter().map(|m| m.is_emissive()).collect();
        let mut emitters = Vec::new();
        if emissive_mat.contains(&true) {
            let emissive_tris: Vec<Vec<u32>> = scene
                .meshes
                .iter()
                .zip(&valid)
                .map(|(m, v)| {
                    v.iter().copied().filter(|&t| emissive_mat[m.material_ids[t as usize] as usize]).collect()
                })
                .collect();
            for (i, inst) in scene.instances.iter().enumerate() {
                let k = inst.mesh as usize;
                if usable[i] && !emissive_tris[k].is_empty() && (uses[k] == 1 || blas_of_mesh[k] != u32::MAX) {
                    emitters.push(EmitterGroup {
                        instance: i as u32,
                        mesh_triangles: scene.meshes[k].indices.len() as u32,
                        triangles: emissive_tris[k].clone(),
                    });
                }
            }
        }
        let world_tri = |inst: u32, tri: u32| world_triangle(&scene, &xforms, &world_attributes, inst, tri);
        let lights = LightSet::build(&scene, &emitters, &world_tri, bounds_min, bounds_max);

        Ok(RenderScene {
            scene,
            world,
            baked_offsets,
            baked_instances,
            blases,
            tlas,
            tlas_leaves,
            xforms,
            mesh_info,
            world_attributes,
            texspaces,
            alpha_tests,
            any_stochastic,
            any_hidden_from_camera,
            coats,
            bsdf_templates,
            lights,
            bounds_min,
            bounds_max,
            build_time,
            triangle_count,
        })
    }

    /// The scene (meshes, instances, materials, textures, lights, environment).
    #[inline]
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// Gives the scene back.
    pub fn into_scene(self) -> Scene {
        self.scene
    }

    /// Triangles the rays see (each instance's counted; degenerate and invalid ones left out).
    pub fn triangle_count(&self) -> usize {
        self.triangle_count
    }

    /// Instances that go through the top-level BVH (those of meshes placed more than once).
    pub fn tlas_instance_count(&self) -> usize {
        self.tlas_leaves.len()
    }

    /// Wall time of the BVH builds (including the leaf-order triangle copies).
    pub fn bvh_build_time(&self) -> Duration {
        self.build_time
    }

    /// Bytes of the BVHs: nodes and leaf-order triangles of every level, and the top level's
    /// per-instance transforms.
    pub fn bvh_memory_bytes(&self) -> usize {
        let m = self.memory();
        m.world_bvh_bytes + m.blas_bytes + m.tlas_bytes
    }

    /// Bytes of the scene data and the acceleration structures, item by item.
    pub fn memory(&self) -> SceneMemory {
        use std::mem::size_of;
        SceneMemory {
            mesh_bytes: self.scene.meshes.iter().map(Mesh::memory_bytes).sum(),
            instance_bytes: self.scene.instances.len() * size_of::<crate::scene::Instance>(),
            world_bvh_bytes: self.world.memory_bytes()
                + (self.baked_offsets.len() + self.baked_instances.len()) * size_of::<u32>(),
            world_attribute_bytes: self.world_attributes.iter().flatten().map(WorldAttributes::memory_bytes).sum(),
            blas_bytes: self.blases.iter().map(Blas::memory_bytes).sum(),
            tlas_bytes: self.tlas.nodes.len() * size_of::<CwBvhNode>()
                + self.tlas_leaves.len() * size_of::<TlasLeaf>()
                + self.xforms.len() * size_of::<InstanceXf>(),
        }
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
        let uv = if r.uv_set == 1 { uv1 } else { uv0 };
        Some(tex.sample(r.transform.map_or(uv, |t| t.apply(uv))))
    }

    /// The mesh instance `inst` places.
    #[inline]
    fn mesh_of(&self, inst: u32) -> (&Mesh, MeshInfo) {
        let k = self.scene.instances[inst as usize].mesh as usize;
        (&self.scene.meshes[k], self.mesh_info[k])
    }

    /// (instance, mesh triangle) of baked triangle `k`.
    #[inline]
    fn resolve_baked(&self, k: u32) -> (u32, u32) {
        let j = self.baked_offsets.partition_point(|&o| o <= k) - 1;
        (self.baked_instances[j], k - self.baked_offsets[j])
    }

    /// sign(det) of instance `inst`'s transform (−1: mirrored, the emitting side flips).
    #[inline]
    pub(crate) fn instance_sign(&self, inst: u32) -> f32 {
        self.xforms[inst as usize].sign
    }

    /// World-space vertices of triangle `tri` of instance `inst`.
    #[inline]
    pub(crate) fn world_triangle(&self, inst: u32, tri: u32) -> [Vec3; 3] {
        world_triangle(&self.scene, &self.xforms, &self.world_attributes, inst, tri)
    }

    /// UV sets at barycentrics (b1, b2) of triangle `tri` of instance `inst`.
    #[inline]
    pub(crate) fn uvs_at(&self, inst: u32, tri: u32, b1: f32, b2: f32) -> (Vec2, Vec2) {
        let (m, info) = self.mesh_of(inst);
        if !info.has_uv0 {
            return (Vec2::ZERO, Vec2::ZERO);
        }
        let [i0, i1, i2] = m.indices[tri as usize].map(|i| i as usize);
        let b0 = 1.0 - b1 - b2;
        let uv0 = m.uv0[i0] * b0 + m.uv0[i1] * b1 + m.uv0[i2] * b2;
        let uv1 = if info.has_uv1 { m.uv1[i0] * b0 + m.uv1[i1] * b1 + m.uv1[i2] * b2 } else { uv0 };
        (uv0, uv1)
    }

    /// The clear coat of material `material_id` (None: uncoated).
    #[inline]
    pub fn coat(&self, material_id: u32) -> Option<&Coat> {
        self.coats.get(material_id as usize).and_then(Option::as_ref)
    }

    /// Material `material_id`'s BSDF without its base colour, where it has metallic 0 and no
    /// metallic-roughness texture (see [`Bsdf::with_base`]); None elsewhere.
    #[inline]
    pub fn bsdf_template(&self, material_id: u32) -> Option<&Bsdf<'static>> {
        self.bsdf_templates.get(material_id as usize).and_then(Option::as_ref)
    }

    /// Material id of triangle `tri` of instance `inst`.
    #[inline]
    pub(crate) fn material_of(&self, inst: u32, tri: u32) -> u32 {
        self.mesh_of(inst).0.material_ids[tri as usize]
    }

    /// Alpha (factor × base-colour texture alpha) of triangle `tri` of instance `inst` at
    /// barycentrics (b1, b2).
    pub(crate) fn alpha_at(&self, inst: u32, tri: u32, b1: f32, b2: f32) -> f32 {
        let mat = &self.scene.materials[self.material_of(inst, tri) as usize];
        let (uv0, uv1) = self.uvs_at(inst, tri, b1, b2);
        let tex = self.texture(mat.base_color_texture, uv0, uv1).map_or(1.0, |t| t.w);
        mat.base_color.w * tex * self.vertex_color(inst, tri, b1, b2).w
    }

    /// The mesh's vertex colour (linear RGBA) at barycentrics (b1, b2) of triangle `tri` of
    /// instance `inst`; white when the mesh has none.
    #[inline]
    pub fn vertex_color(&self, inst: u32, tri: u32, b1: f32, b2: f32) -> Vec4 {
        let (m, info) = self.mesh_of(inst);
        if !info.has_colors {
            return Vec4::ONE;
        }
        let [i0, i1, i2] = m.indices[tri as usize].map(|i| i as usize);
        m.colors[i0] * (1.0 - b1 - b2) + m.colors[i1] * b1 + m.colors[i2] * b2
    }

    /// Whether the surface is there for this ray at (b1, b2) of candidate `c`: not cut out by
    /// its alpha test (`ray_hash` and the triangle key the stochastic decision), and for a
    /// light's emitter (an area light) seen at all: never by a shadow ray (`dir` None), only
    /// from its front by a ray searching the closest hit along `dir`.
    #[inline(never)]
    fn alpha_passes(&self, c: Candidate, b1: f32, b2: f32, ray_hash: u32, dir: Option<Vec3>) -> bool {
        let (inst, tri, key) = match c {
            Candidate::Baked(k) => {
                let (i, t) = self.resolve_baked(k);
                (i, t, k)
            }
            Candidate::Instanced(i, t) => (i, t, t ^ hash_u32(i ^ 0x5bd1_e995)),
        };
        match self.alpha_tests[self.material_of(inst, tri) as usize] {
            AlphaTest::None => true,
            AlphaTest::LightEmitter => dir.is_some_and(|d| {
                let [p0, p1, p2] = self.world_triangle(inst, tri);
                (p1 - p0).cross(p2 - p0).dot(d) * self.instance_sign(inst) < 0.0
            }),
            AlphaTest::Mask(cutoff) => self.alpha_at(inst, tri, b1, b2) >= cutoff,
            AlphaTest::Stochastic => {
                let u = (hash_u32(ray_hash ^ hash_u32(key)) >> 8) as f32 * (1.0 / (1u32 << 24) as f32);
                u < self.alpha_at(inst, tri, b1, b2)
            }
        }
    }

    /// Closest hit along `origin + t·dir`, 0 < t < `t_max` (`dir` is normalised here; `t` is in
    /// world units). Alpha cut-outs are skipped. None for no hit or a non-finite ray.
    pub fn intersect(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<SurfaceHit> {
        let (dir, ray_hash) = self.query_ray(origin, dir, t_max)?;
        let mut best: Option<(Candidate, f32, f32)> = None;
        let mut t_best = t_max;
        if !self.world.tris.is_empty() {
            let wray = WatertightRay::new(origin, dir);
            let ray = Ray::new(origin.to_array().into(), dir.to_array().into(), 0.0, t_best);
            let mut hit = RayHit::none();
            let tris = &self.world.tris;
            traverse::closest_hit(&self.world.bvh, ray, &mut hit, |r, id| {
                let tri = &tris[id];
                if let Some((t, b1, b2)) = wray.intersect(&tri.v, r.tmax) {
                    let c = Candidate::Baked(tri.prim & !ALPHA_BIT);
                    if tri.prim & ALPHA_BIT != 0 && !self.alpha_passes(c, b1, b2, ray_hash, Some(dir)) {
                        return f32::INFINITY;
                    }
                    best = Some((c, b1, b2));
                    return t;
                }
                f32::INFINITY
            });
            if best.is_some() && hit.t < t_best {
                t_best = hit.t;
            }
        }
        self.finish_intersect(origin, dir, t_max, ray_hash, best, t_best)
    }

    /// Closest hits of up to [`PACKET`] rays at once, each as [`RenderScene::intersect`] gives
    /// it (`rays[i]` = (origin, direction, `t_max`); lanes past `rays.len()` are unused). The
    /// world BVH is traversed by the whole packet together (`packet.rs`), instances ray by ray.
    /// Coherent rays (camera rays of one pixel or of a row) share most of their nodes.
    pub fn intersect_packet(&self, rays: &[(Vec3, Vec3, f32)]) -> [Option<SurfaceHit>; PACKET] {
        let mut out: [Option<SurfaceHit>; PACKET] = std::array::from_fn(|_| None);
        // 1. Each lane's query ray, as `intersect` sets it up; invalid lanes stay inactive.
        let mut query = [None; PACKET];
        let mut active = 0u8;
        for (i, &(o, d, t)) in rays.iter().take(PACKET).enumerate() {
            query[i] = self.query_ray(o, d, t);
            active |= (query[i].is_some() as u8) << i;
        }
        let lane = |i: usize| {
            let (o, _, t) = rays.get(i).copied().unwrap_or((Vec3::ZERO, Vec3::Z, 0.0));
            let (d, hash) = query[i].unwrap_or((Vec3::Z, 0));
            (o, d, t, hash)
        };
        let mut best: [Option<(Candidate, f32, f32)>; PACKET] = [None; PACKET];
        let mut t_best: [f32; PACKET] = std::array::from_fn(|i| lane(i).2);
        // 2. The world BVH, the packet together (the closure is `intersect`'s, per lane).
        if !self.world.tris.is_empty() && active != 0 {
            let wrays: [WatertightRay; PACKET] = std::array::from_fn(|i| WatertightRay::new(lane(i).0, lane(i).1));
            let obrays: [Ray; PACKET] = std::array::from_fn(|i| {
                let (o, d, t, _) = lane(i);
                Ray::new(o.to_array().into(), d.to_array().into(), 0.0, t)
            });
            let hashes: [u32; PACKET] = std::array::from_fn(|i| lane(i).3);
            let tris = &self.world.tris;
            // Rays sharing one axis permutation take the 8-lane triangle test (AVX2 builds).
            #[cfg(target_arch = "x86_64")]
            let shared = if packet::avx2() { WatertightLanes::new(&wrays, active) } else { None };
            let t = packet::closest_hits(&self.world.bvh, &obrays, active, |id, lanes, t_max| {
                let tri = &tris[id];
                let c = Candidate::Baked(tri.prim & !ALPHA_BIT);
                // A hit of lane i: kept unless the alpha test lets the ray through.
                let mut take = |i: usize, b1: f32, b2: f32| {
                    if tri.prim & ALPHA_BIT != 0 && !self.alpha_passes(c, b1, b2, hashes[i], Some(lane(i).1)) {
                        return false;
                    }
                    best[i] = Some((c, b1, b2));
                    true
                };
                let mut scalar = lanes;
                #[cfg(target_arch = "x86_64")]
                if let Some(shared) = &shared {
                    // SAFETY: `shared` exists only when AVX2 was detected.
                    let h = unsafe { shared.intersect(&tri.v, t_max, lanes) };
                    let mut left = h.hit;
                    while left != 0 {
                        let i = left.trailing_zeros() as usize;
                        left &= left - 1;
                        if take(i, h.b1[i], h.b2[i]) {
                            t_max[i] = h.t[i];
                        }
                    }
                    scalar = h.retry;
                }
                while scalar != 0 {
                    let i = scalar.trailing_zeros() as usize;
                    scalar &= scalar - 1;
                    if let Some((t, b1, b2)) = wrays[i].intersect(&tri.v, t_max[i]) {
                        if take(i, b1, b2) {
                            t_max[i] = t;
                        }
                    }
                }
            });
            for i in 0..PACKET {
                if best[i].is_some() && t[i] < t_best[i] {
                    t_best[i] = t[i];
                }
            }
        }
        // 3. Instances and the hit records, lane by lane.
        for (i, slot) in out.iter_mut().enumerate() {
            if active & (1 << i) != 0 {
                let (o, d, t, hash) = lane(i);
                *slot = self.finish_intersect(o, d, t, hash, best[i], t_best[i]);
            }
        }
        out
    }

    /// `intersect`'s query ray: the unit direction (−0.0 made +0.0) and the alpha hash, or None
    /// when nothing can be hit.
    #[inline]
    fn query_ray(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<(Vec3, u32)> {
        let dir = dir.normalize_or_zero();
        if (self.world.tris.is_empty() && self.tlas_leaves.is_empty())
            || dir == Vec3::ZERO
            || !origin.is_finite()
            || !(t_max > 0.0)
        {
            return None;
        }
        // −0.0 → +0.0: obvhs takes the octant from `d < 0` but the inverse from the sign bit,
        // so a −0.0 component would make every node test miss.
        let dir = dir + Vec3::ZERO;
        let ray_hash = if self.any_stochastic { Self::ray_hash(origin, dir) } else { 0 };
        Some((dir, ray_hash))
    }

    /// The rest of `intersect` after the world BVH (best candidate so far at `t_best`): the
    /// instances' top level, then the hit record.
    #[inline]
    fn finish_intersect(
        &self,
        origin: Vec3,
        dir: Vec3,
        t_max: f32,
        ray_hash: u32,
        mut best: Option<(Candidate, f32, f32)>,
        mut t_best: f32,
    ) -> Option<SurfaceHit> {
        if !self.tlas_leaves.is_empty() {
            let ray = Ray::new(origin.to_array().into(), dir.to_array().into(), 0.0, t_best);
            let mut hit = RayHit::none();
            traverse::closest_hit(&self.tlas, ray, &mut hit, |r, id| {
                let leaf = &self.tlas_leaves[id];
                let o = leaf.world_to_object.transform_point3(origin);
                let d = leaf.world_to_object.transform_vector3(dir) + Vec3::ZERO;
                let wray = WatertightRay::new(o, d);
                let oray = Ray::new(o.to_array().into(), d.to_array().into(), 0.0, r.tmax);
                let blas = &self.blases[leaf.blas as usize];
                let mut h = RayHit::none();
                let mut found = None;
                traverse::closest_hit(&blas.bvh, oray, &mut h, |r2, id2| {
                    let tri = &blas.tris[id2];
                    if let Some((t, b1, b2)) = wray.intersect(&tri.v, r2.tmax) {
                        let c = Candidate::Instanced(leaf.instance, tri.prim & !ALPHA_BIT);
                        if tri.prim & ALPHA_BIT != 0 && !self.alpha_passes(c, b1, b2, ray_hash, Some(dir)) {
                            return f32::INFINITY;
                        }
                        found = Some((c, b1, b2));
                        return t;
                    }
                    f32::INFINITY
                });
                match found {
                    Some(f) if h.t < r.tmax => {
                        best = Some(f);
                        h.t
                    }
                    _ => f32::INFINITY,
                }
            });
            if hit.t < t_best {
                t_best = hit.t;
            }
        }
        let (c, b1, b2) = best?;
        if !(t_best < t_max) {
            return None;
        }
        let (inst, tri) = match c {
            Candidate::Baked(k) => self.resolve_baked(k),
            Candidate::Instanced(i, t) => (i, t),
        };
        Some(self.surface_hit(inst, tri, b1, b2, t_best, dir))
    }

    /// Whether anything (after alpha cut-outs) lies on `origin + t·dir`, 0 < t < `t_max`
    /// (`dir` need not be unit; `t` is in units of its length).
    pub fn occluded(&self, origin: Vec3, dir: Vec3, t_max: f32) -> bool {
        if (self.world.tris.is_empty() && self.tlas_leaves.is_empty())
            || !origin.is_finite()
            || !dir.is_finite()
            || !(t_max > 0.0)
        {
            return false;
        }
        let len = dir.length();
        if !(len > 0.0) {
            return false;
        }
        let dir = dir.normalize_or_zero() + Vec3::ZERO; // −0.0 → +0.0 (see `intersect`)
        let t_max = t_max * len;
        let ray = Ray::new(origin.to_array().into(), dir.to_array().into(), 0.0, t_max);
        let ray_hash = if self.any_stochastic { Self::ray_hash(origin, dir) } else { 0 };
        if !self.world.tris.is_empty() {
            let wray = WatertightRay::new(origin, dir);
            let tris = &self.world.tris;
            let miss = traverse::misses(&self.world.bvh, ray, |r, id| {
                let tri = &tris[id];
                if let Some((t, b1, b2)) = wray.intersect(&tri.v, r.tmax) {
                    let c = Candidate::Baked(tri.prim & !ALPHA_BIT);
                    if tri.prim & ALPHA_BIT != 0 && !self.alpha_passes(c, b1, b2, ray_hash, None) {
                        return f32::INFINITY;
                    }
                    return t;
                }
                f32::INFINITY
            });
            if !miss {
                return true;
            }
        }
        if self.tlas_leaves.is_empty() {
            return false;
        }
        !traverse::misses(&self.tlas, ray, |r, id| {
            let leaf = &self.tlas_leaves[id];
            let o = leaf.world_to_object.transform_point3(origin);
            let d = leaf.world_to_object.transform_vector3(dir) + Vec3::ZERO;
            let wray = WatertightRay::new(o, d);
            let oray = Ray::new(o.to_array().into(), d.to_array().into(), 0.0, r.tmax);
            let blas = &self.blases[leaf.blas as usize];
            let mut t_hit = f32::INFINITY;
            let miss = traverse::misses(&blas.bvh, oray, |r2, id2| {
                let tri = &blas.tris[id2];
                if let Some((t, b1, b2)) = wray.intersect(&tri.v, r2.tmax) {
                    let c = Candidate::Instanced(leaf.instance, tri.prim & !ALPHA_BIT);
                    if tri.prim & ALPHA_BIT != 0 && !self.alpha_passes(c, b1, b2, ray_hash, None) {
                        return f32::INFINITY;
                    }
                    t_hit = t;
                    return t;
                }
                f32::INFINITY
            });
            if miss {
                f32::INFINITY
            } else {
                t_hit
            }
        })
    }

    /// The tangent an anisotropic material `a` takes at `hit` (world space, unit): its source
    /// ([`AnisotropyTangent`]) made perpendicular to the hit's smooth shading normal, as Cycles'
    /// Tangent node makes it (`cross(N, normalize(cross(T, N)))`), then turned about `n` (the
    /// normal the lobes use) by the rotation. None where it is undefined (on the radial axis,
    /// no UVs): the lobes then keep an arbitrary frame.
    pub fn anisotropy_tangent(&self, hit: &SurfaceHit, a: &crate::scene::Anisotropy, n: Vec3) -> Option<Vec3> {
        let (inst, tri) = (hit.instance, hit.triangle);
        let (mesh, info) = self.mesh_of(inst);
        let idx = mesh.indices[tri as usize].map(|i| i as usize);
        let (b1, b2) = (hit.barycentrics.x, hit.barycentrics.y);
        let b = [1.0 - b1 - b2, b1, b2];
        let xf = &self.xforms[inst as usize];
        // 1. The source, in world space.
        let t = match a.tangent {
            AnisotropyTangent::Radial(axis) => {
                let (centre, extent) = *self.texspaces.get(self.scene.instances[inst as usize].mesh as usize)?;
                let p = mesh.positions[idx[0]] * b[0] + mesh.positions[idx[1]] * b[1] + mesh.positions[idx[2]] * b[2];
                let g = (p - centre) / extent;
                let t_obj = match axis {
                    0 => Vec3::new(0.0, -g.z, g.y),
                    1 => Vec3::new(-g.z, 0.0, g.x),
                    _ => Vec3::new(-g.y, g.x, 0.0),
                };
                if xf.identity {
                    t_obj
                } else {
                    xf.normal * t_obj
                }
            }
            AnisotropyTangent::UvMap => {
                let uvs = info.has_uv0.then(|| idx.map(|i| mesh.uv0[i]));
                let tangents = info.has_tangents.then(|| world_tangents(mesh, xf, idx));
                let p = self.world_triangle(inst, tri);
                let (t, _) = tangent_frame(p, tangents, uvs, b, hit.shading_normal);
                t
            }
        };
        // 2. Perpendicular to the smooth normal, then turned about the lobes' normal.
        let ns = hit.shading_normal;
        let t = ns.cross(t.cross(ns).normalize_or_zero());
        if t == Vec3::ZERO || !t.is_finite() {
            return None;
        }
        let t = if a.rotation_turns != 0.0 {
            let (sin, cos) = (a.rotation_turns * std::f32::consts::TAU).sin_cos();
            t * cos + n.cross(t) * sin + n * (n.dot(t) * (1.0 - cos))
        } else {
            t
        };
        Some(t)
    }

    /// The hit's smooth normal: its vertex normals interpolated (world space, on the geometric
    /// normal's side), before any normal map; the geometric normal where the mesh has none.
    /// Cycles' bump shadowing term compares a normal-mapped normal with it.
    pub fn smooth_normal(&self, hit: &SurfaceHit) -> Vec3 {
        let (inst, (b1, b2)) = (hit.instance, (hit.barycentrics.x, hit.barycentrics.y));
        let (mesh, info) = self.mesh_of(inst);
        let idx = mesh.indices[hit.triangle as usize].map(|i| i as usize);
        self.smooth_normal_at(inst, mesh, info, idx, b1, b2, hit.geometric_normal)
    }

    /// [`RenderScene::smooth_normal`] at (b1, b2) of the triangle with vertex indices `idx` of
    /// instance `inst` (mesh `mesh`), whose geometric normal is `ng`.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn smooth_normal_at(
        &self,
        inst: u32,
        mesh: &Mesh,
        info: MeshInfo,
        idx: [usize; 3],
        b1: f32,
        b2: f32,
        ng: Vec3,
    ) -> Vec3 {
        if !info.has_normals {
            return ng;
        }
        let xf = &self.xforms[inst as usize];
        let world_normals =
            self.world_attributes[self.scene.instances[inst as usize].mesh as usize].as_ref().map(|w| &w.normals[..]);
        // a vertex normal in world space (precomputed for a baked, transformed mesh)
        let world_n = |i: usize| match world_normals {
            Some(w) => w[i],
            None if xf.identity => mesh.normals[i],
            None => (xf.normal * mesh.normals[i]).normalize_or_zero(),
        };
        let b0 = 1.0 - b1 - b2;
        let n = world_n(idx[0]) * b0 + world_n(idx[1]) * b1 + world_n(idx[2]) * b2;
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
    }

    /// Builds the full hit record for triangle `tri` of instance `inst` at barycentrics
    /// (b1, b2), hit at distance `t` along unit `dir`; attributes in world space.
    pub fn surface_hit(&self, inst: u32, tri: u32, b1: f32, b2: f32, t: f32, dir: Vec3) -> SurfaceHit {
        let xf = self.xforms[inst as usize];
        let (mesh, info) = self.mesh_of(inst);
        let idx = mesh.indices[tri as usize].map(|i| i as usize);
        let p = self.world_triangle(inst, tri);
        let b0 = 1.0 - b1 - b2;
        let position = p[0] * b0 + p[1] * b1 + p[2] * b2;
        let ng = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or(Vec3::Z) * xf.sign;
        let mut ns = self.smooth_normal_at(inst, mesh, info, idx, b1, b2, ng);
        let (uv0, uv1) = self.uvs_at(inst, tri, b1, b2);
        let material_id = mesh.material_ids[tri as usize];
        let mat = &self.scene.materials[material_id as usize];
        if let Some(nref) = mat.normal_texture {
            if let Some(texel) = self.texture(Some(nref), uv0, uv1) {
                let tangents = info.has_tangents.then(|| world_tangents(mesh, &xf, idx));
                let uvs = if nref.uv_set == 1 && info.has_uv1 {
                    Some(idx.map(|i| mesh.uv1[i]))
                } else if info.has_uv0 {
                    Some(idx.map(|i| mesh.uv0[i]))
                } else {
                    None
                };
                let (tangent, bitangent) = tangent_frame(p, tangents, uvs, [b0, b1, b2], ns);
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
            instance: inst,
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

    /// Whether camera rays see the hit's surface ([`crate::scene::Material::visible_to_camera`]).
    #[inline]
    pub fn visible_to_camera(&self, hit: &SurfaceHit) -> bool {
        !self.any_hidden_from_camera || self.scene.materials[hit.material_id as usize].visible_to_camera
    }

    /// Where a shadow ray from `hit` toward unit `wi` starts: Cycles' shadow-terminator geometry
    /// offset (Hanika, "Hacking the Shadow Terminator", 2021) with the material's cutoff
    /// ([`crate::scene::Material::terminator_offset`], Blender's default 0.1). Near the
    /// terminator of a smooth-shaded mesh (the light grazing the shading normal `n`, or below
    /// the flat triangle, `ng`; both on the viewer's side) the origin
    /// is lifted toward the smooth surface the vertex normals describe, so that low-poly meshes
    /// are not shadowed by their own facets; elsewhere it is the usual offset origin. A ray
    /// toward a light below the triangle's plane may still hit the triangle (then it is shadowed).
    pub fn shadow_origin(&self, hit: &SurfaceHit, n: Vec3, ng: Vec3, wi: Vec3) -> Vec3 {
        let c = self.scene.materials[hit.material_id as usize].terminator_offset;
        if !(c > 0.0) {
            return hit.spawn_origin(wi);
        }
        // 1. How far into the terminator region: by the shading and the geometric cosines.
        let mut nl = n.dot(wi);
        let ng = if nl < 0.0 { -ng } else { ng };
        nl = nl.abs();
        let ngl = ng.dot(wi);
        let amount = if nl < c { (2.0 - (ngl + nl) / c).clamp(0.0, 1.0) } else { (1.0 - ngl / c).clamp(0.0, 1.0) };
        if !(amount > 0.0) {
            return hit.spawn_origin(wi);
        }
        // 2. The lift toward the smooth surface, and the origin just off the triangle's side
        //    the shading normal is on (so that a ray below the plane can hit the triangle).
        match self.smooth_surface_lift(hit, ng) {
            Some(lift) if lift.is_finite() => offset_ray_origin(hit.position + lift * amount, ng),
            _ => hit.spawn_origin(wi),
        }
    }

    /// The vector from `hit` to the smooth surface its triangle's vertex normals describe (a
    /// quadratic patch through the vertices, held within the vertices' tangent planes; world
    /// space), for `ng` the geometric normal on the viewer's side. None for meshes without
    /// smooth vertex normals (flat shading).
    fn smooth_surface_lift(&self, hit: &SurfaceHit, ng: Vec3) -> Option<Vec3> {
        let (mesh, info) = self.mesh_of(hit.instance);
        if !info.smooth_normals {
            return None;
        }
        // 1. The triangle in object space, and the point and interpolated normal on it.
        let idx = mesh.indices[hit.triangle as usize].map(|i| i as usize);
        let v = idx.map(|i| mesh.positions[i]);
        let nv = idx.map(|i| mesh.normals[i]);
        let w = [1.0 - hit.barycentrics.x - hit.barycentrics.y, hit.barycentrics.x, hit.barycentrics.y];
        let p = v[0] * w[0] + v[1] * w[1] + v[2] * w[2];
        let n_obj = nv[0] * w[0] + nv[1] * w[1] + nv[2] * w[2];
        let xf = &self.xforms[hit.instance as usize];
        let n = if xf.identity { n_obj } else { xf.object_to_world.transform_vector3(n_obj) };
        // 2. Height of the quadratic patch over the flat triangle (along n).
        let e02 = (nv[2] - nv[0]).dot(v[0] - v[2]);
        let e12 = (nv[2] - nv[1]).dot(v[1] - v[2]);
        let e01 = (nv[1] - nv[0]).dot(v[1] - v[0]);
        let (a, b) = (w[0], w[1]);
        let quadratic = e02 * a * (a - 1.0) + (e02 + e12 + e01) * a * b + e12 * b * (b - 1.0);
        // 3. Held by the tangent planes at the vertices (each vertex's plane, raised to the
        //    triangle's far corner along its normal), on the side the normals face.
        let outward = n.dot(ng) > 0.0;
        let s = if outward { 1.0 } else { -1.0 };
        let plane = |i: usize| {
            let reach = (0..3).filter(|&j| j != i).map(|j| s * (v[j] - v[i]).dot(nv[i])).fold(0.0f32, f32::max);
            (s * (v[i] - p).dot(nv[i]) + reach).max(0.0)
        };
        let envelope = plane(0).min(plane(1)).min(plane(2));
        let h = if outward { envelope.max(0.5 * quadratic) } else { (-envelope).min(0.5 * quadratic) };
        Some(n * h)
    }

    /// [`RenderScene::intersect`] as camera rays see the scene: surfaces hidden from the camera
    /// are passed through.
    pub fn intersect_seen(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<SurfaceHit> {
        let hit = self.intersect(origin, dir, t_max)?;
        if self.visible_to_camera(&hit) {
            Some(hit)
        } else {
            self.seen_beyond(&hit, origin, dir, t_max)
        }
    }

    /// The first surface a camera ray from `origin` along unit `dir` sees beyond `hidden`, a
    /// hit of that ray on a surface hidden from the camera, with `t` counted from `origin`
    /// (None past `t_max`, or after [`MAX_HIDDEN_LAYERS`] hidden surfaces).
    pub fn seen_beyond(&self, hidden: &SurfaceHit, origin: Vec3, dir: Vec3, t_max: f32) -> Option<SurfaceHit> {
        let mut next = hidden.spawn_origin(dir);
        for _ in 0..MAX_HIDDEN_LAYERS {
            // 1. Go on from just past the hidden surface, counting the distance from `origin`.
            let t0 = (next - origin).dot(dir).max(0.0);
            let mut hit = self.intersect(next, dir, t_max - t0)?;
            hit.t += t0;
            // 2. Seen, or hidden again.
            if self.visible_to_camera(&hit) {
                return Some(hit);
            }
            next = hit.spawn_origin(dir);
        }
        None
    }

    /// Emitted radiance of the hit's material toward the side the ray (direction `dir`) came
    /// from: front side only unless the material is double sided (glTF), dimmed by a clear coat
    /// over it. Zero for non-emissive materials.
    pub fn emission(&self, hit: &SurfaceHit, dir: Vec3) -> Vec3 {
        let mat = &self.scene.materials[hit.material_id as usize];
        if !mat.is_emissive() || !(hit.front_face || mat.double_sided) {
            return Vec3::ZERO;
        }
        let tex = self.texture(mat.emissive_texture, hit.uv0, hit.uv1).map_or(Vec3::ONE, |t| t.truncate());
        let le = mat.emissive * tex;
        // a clear coat dims the emission under it as it dims the base (as in Cycles)
        match self.coat(hit.material_id) {
            Some(c) => le * c.emission_weight(hit.shading_normal.dot(dir)),
            None => le,
        }
    }
}

/// World-space vertices of triangle `tri` of instance `inst` (a baked mesh's, read from its
/// world-space attributes where it has them).
#[inline]
fn world_triangle(
    scene: &Scene,
    xforms: &[InstanceXf],
    world_attributes: &[Option<WorldAttributes>],
    inst: u32,
    tri: u32,
) -> [Vec3; 3] {
    let xf = &xforms[inst as usize];
    let mesh = scene.instances[inst as usize].mesh as usize;
    let m = &scene.meshes[mesh];
    if let Some(w) = &world_attributes[mesh] {
        return m.indices[tri as usize].map(|k| w.positions[k as usize]);
    }
    m.indices[tri as usize].map(|k| {
        let p = m.positions[k as usize];
        if xf.identity {
            p
        } else {
            xf.object_to_world.transform_point3(p)
        }
    })
}

/// Each mesh's texture space as Blender computes it automatically (`BKE_mesh_texspace_calc`):
/// the centre of its bounding box and its extents, a zero extent counting as 2 (half-size 1)
/// and a tiny one as 2·10⁻⁵.
fn texture_spaces(meshes: &[Mesh]) -> Vec<(Vec3, Vec3)> {
    meshes
        .iter()
        .map(|m| {
            let inf = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
            let (lo, hi) = m.positions.iter().fold(inf, |(lo, hi), p| (lo.min(*p), hi.max(*p)));
            if !(lo.is_finite() && hi.is_finite()) {
                return (Vec3::ZERO, Vec3::splat(2.0));
            }
            let half = ((hi - lo) * 0.5).to_array().map(|h| if h == 0.0 { 1.0 } else { h.max(1e-5) });
            ((lo + hi) * 0.5, Vec3::from_array(half) * 2.0)
        })
        .collect()
}

/// The vertex tangents of triangle `idx` of `mesh` in world space (the xyz part by the
/// instance's matrix, normalised; w × sign(det)), as normal maps and anisotropic lobes use them.
fn world_tangents(mesh: &Mesh, xf: &InstanceXf, idx: [usize; 3]) -> [Vec4; 3] {
    idx.map(|i| {
        let t = mesh.tangents[i];
        if xf.identity || t == Vec4::ZERO {
            t
        } else {
            (xf.object_to_world.matrix3 * glam::Vec3A::from(t.truncate())).normalize_or_zero().extend(t.w * xf.sign)
        }
    })
}

/// Orthonormal tangent and bitangent around `n` for normal mapping: the vertex tangents
/// (glTF: bitangent = n × t · w), else the triangle's UV derivatives (glTF's v axis points
/// down the image, so the bitangent is −∂p/∂v), else an arbitrary frame. Positions and
/// tangents in world space.
fn tangent_frame(
    p: [Vec3; 3],
    tangents: Option<[Vec4; 3]>,
    uvs: Option<[Vec2; 3]>,
    b: [f32; 3],
    n: Vec3,
) -> (Vec3, Vec3) {
    if let Some(tg) = tangents {
        let t4: Vec4 = tg[0] * b[0] + tg[1] * b[1] + tg[2] * b[2];
        let t = t4.truncate();
        let t = (t - n * n.dot(t)).normalize_or_zero();
        if t != Vec3::ZERO && t.is_finite() {
            let w = if tg[0].w < 0.0 { -1.0 } else { 1.0 };
            return (t, n.cross(t) * w);
        }
    }
    if let Some([t0, t1, t2]) = uvs {
        let (dp1, dp2) = (p[1] - p[0], p[2] - p[0]);
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
    super::bsdf::orthonormal_basis(n)
}
