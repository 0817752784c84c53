//! Single-ray traversal of obvhs CWBVHs with the eight child boxes of a node tested at once.
//!
//! obvhs's own traversal (`CwBvh::ray_traverse`, `ray_traverse_miss`) tests a node's children
//! four at a time with SSE and builds each child's quantised planes from bytes one float at a
//! time (`get_q`, which its authors call the most expensive part). On a CPU with AVX2 the box
//! test here widens every byte row to eight floats with one `vpmovzxbd` + `vcvtdq2ps` and tests
//! all eight children in one pass. The operations per child are obvhs's, in its order and with
//! no fused multiply-add (a ray in the node's grid, `plane · extent/d + (p − o)/d`, the near
//! maximum and the far minimum clamped to [ε, t_max]), so a ray visits the same nodes in the same
//! order and the images are bit-identical to obvhs's traversal. The traversal loop itself is
//! obvhs's `traverse!` macro. Without AVX2 (or with `PETZVAL_SIMD=baseline`) obvhs's functions
//! run unchanged.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `PETZVAL_SIMD` | environment variable (`baseline`: no AVX2) | — | unset (AVX2 when the CPU has it) |

use obvhs::{
    cwbvh::CwBvh,
    ray::{Ray, RayHit},
};

/// Closest hit: as [`CwBvh::ray_traverse`] (same arguments, same result, same closure calls in
/// the same order). `intersect(ray, id)` tests primitive `id` (leaf order) and returns its hit
/// distance, or infinity.
#[inline]
pub(crate) fn closest_hit<F: FnMut(&Ray, usize) -> f32>(bvh: &CwBvh, ray: Ray, hit: &mut RayHit, intersect: F) -> bool {
    #[cfg(target_arch = "x86_64")]
    if super::packet::avx2() {
        // SAFETY: AVX2 was detected on this CPU.
        return unsafe { avx2::closest_hit(bvh, ray, hit, intersect) };
    }
    bvh.ray_traverse(ray, hit, intersect)
}

/// Whether the ray misses every primitive: as [`CwBvh::ray_traverse_miss`] (stops at the first
/// primitive whose distance is below `ray.tmax`).
#[inline]
pub(crate) fn misses<F: FnMut(&Ray, usize) -> f32>(bvh: &CwBvh, ray: Ray, intersect: F) -> bool {
    #[cfg(target_arch = "x86_64")]
    if super::packet::avx2() {
        // SAFETY: AVX2 was detected on this CPU.
        return unsafe { avx2::misses(bvh, ray, intersect) };
    }
    bvh.ray_traverse_miss(ray, intersect)
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use std::arch::x86_64::*;

    use glam::{UVec2, Vec3A};
    use obvhs::{
        cwbvh::{node::CwBvhNode, CwBvh},
        ray::{Ray, RayHit},
    };

    /// obvhs's lower bound on a box entry distance (`cwbvh::node::EPSILON`).
    const NODE_T_MIN: f32 = 0.0001;

    /// The ray's hit mask of `node`'s children, as obvhs's `CwBvhNode::intersect_ray` gives it
    /// (child bits shifted to their slots: inner children in the top byte by traversal
    /// priority, leaf primitives in the low 24 bits).
    #[inline]
    #[target_feature(enable = "avx2")]
    fn node_hits(node: &CwBvhNode, ray: &Ray, oct_inv4: u32) -> u32 {
        // 1. The ray in the node's quantised grid (obvhs: extent · 1/d, (p − o) · 1/d).
        let scale = node.compute_extent() * ray.inv_direction;
        let offset = (Vec3A::from(node.p) - ray.origin) * ray.inv_direction;
        // 2. Each axis' near and far plane rows, eight children at once (bytes → exact floats).
        let row = |b: &[u8; 8]| {
            // SAFETY: reads the row's 8 bytes.
            unsafe { _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(_mm_loadl_epi64(b.as_ptr() as *const __m128i))) }
        };
        let slab = |lo: &[u8; 8], hi: &[u8; 8], negative: bool, s: f32, o: f32| {
            let (near, far) = if negative { (hi, lo) } else { (lo, hi) };
            let (s, o) = (_mm256_set1_ps(s), _mm256_set1_ps(o));
            (_mm256_add_ps(_mm256_mul_ps(row(near), s), o), _mm256_add_ps(_mm256_mul_ps(row(far), s), o))
        };
        let (near_x, far_x) = slab(&node.child_min_x, &node.child_max_x, ray.direction.x < 0.0, scale.x, offset.x);
        let (near_y, far_y) = slab(&node.child_min_y, &node.child_max_y, ray.direction.y < 0.0, scale.y, offset.y);
        let (near_z, far_z) = slab(&node.child_min_z, &node.child_max_z, ray.direction.z < 0.0, scale.z, offset.z);
        // 3. Overlap clamped to [ε, t_max], in obvhs's operand order.
        let t0 = _mm256_max_ps(near_x, _mm256_max_ps(near_y, near_z));
        let t1 = _mm256_min_ps(far_x, _mm256_min_ps(far_y, far_z));
        let t0 = _mm256_max_ps(t0, _mm256_set1_ps(NODE_T_MIN));
        let t1 = _mm256_min_ps(t1, _mm256_set1_ps(ray.tmax));
        let mut hit_children = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t0, t1)) as u32;
        // 4. Each hit child's bits into its slot (empty slots carry no bits).
        let (child_bits8, bit_index8) = node.get_child_and_index_bits(oct_inv4);
        let mut hit_mask = 0u32;
        while hit_children != 0 {
            let c = hit_children.trailing_zeros();
            hit_children &= hit_children - 1;
            let child_bits = ((child_bits8 >> (c * 8)) as u32) & 0xff;
            let bit_index = ((bit_index8 >> (c * 8)) as u32) & 0xff;
            hit_mask |= child_bits << bit_index;
        }
        hit_mask
    }

    /// [`super::closest_hit`] with the AVX2 box test (obvhs's `ray_traverse` otherwise).
    #[target_feature(enable = "avx2")]
    pub(super) fn closest_hit<F: FnMut(&Ray, usize) -> f32>(
        bvh: &CwBvh,
        ray: Ray,
        hit: &mut RayHit,
        mut intersect: F,
    ) -> bool {
        let mut traverse_ray = ray;
        let mut state = bvh.new_traversal(ray.direction);
        let mut node;
        obvhs::traverse!(bvh, node, state, node_hits(node, &traverse_ray, state.oct_inv4), {
            let t = intersect(&traverse_ray, state.primitive_id as usize);
            if t < traverse_ray.tmax {
                hit.primitive_id = state.primitive_id;
                hit.t = t;
                traverse_ray.tmax = t;
            }
        });
        hit.t < ray.tmax
    }

    /// [`super::misses`] with the AVX2 box test (obvhs's `ray_traverse_miss` otherwise).
    #[target_feature(enable = "avx2")]
    pub(super) fn misses<F: FnMut(&Ray, usize) -> f32>(bvh: &CwBvh, ray: Ray, mut intersect: F) -> bool {
        let mut state = bvh.new_traversal(ray.direction);
        let mut node;
        let mut miss = true;
        'outer: {
            obvhs::traverse!(bvh, node, state, node_hits(node, &ray, state.oct_inv4), {
                let t = intersect(&ray, state.primitive_id as usize);
                if t < ray.tmax {
                    miss = false;
                    break 'outer;
                }
            });
        }
        miss
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::hash_u32;
    use glam::Vec3A;
    use obvhs::{cwbvh::builder::build_cwbvh_from_tris, triangle::Triangle, BvhBuildParams};

    fn unit(h: u32) -> f32 {
        (hash_u32(h) >> 8) as f32 / (1u32 << 24) as f32
    }

    /// Whichever build this CPU runs, both queries call the closure on the same primitives in
    /// the same order and return what obvhs's own traversal returns, on 2 000 triangles
    /// (clustered, tiny and huge) and 20 000 rays from inside and outside, some axis-parallel.
    #[test]
    fn same_visits_and_results_as_obvhs() {
        let v = |i: u32| Vec3A::new(unit(i), unit(i + 1), unit(i + 2)) * 4.0 - 2.0;
        let tris: Vec<Triangle> = (0..2000u32)
            .map(|k| {
                let c = v(k * 11);
                let s = if k % 97 == 0 {
                    3.0
                } else if k % 5 == 0 {
                    0.001
                } else {
                    0.1
                };
                Triangle { v0: c + v(k * 11 + 3) * s, v1: c + v(k * 11 + 6) * s, v2: c + v(k * 11 + 9) * s }
            })
            .collect();
        let bvh = build_cwbvh_from_tris(&tris, BvhBuildParams::medium_build(), &mut Default::default());
        let mut hits = 0;
        for i in 0..20_000u32 {
            let origin = v(1_000_000 + i * 7) * if i % 2 == 0 { 1.0 } else { 3.0 };
            let mut dir = v(2_000_000 + i * 7);
            if i % 10 == 0 {
                dir = Vec3A::new(dir.x, 0.0, 0.0);
            }
            let t_max = if i % 3 == 0 { f32::INFINITY } else { 1.5 };
            let ray = Ray::new(origin, dir.normalize_or(Vec3A::X), 0.0, t_max);
            let test = |visits: &mut Vec<usize>, r: &Ray, id: usize| {
                visits.push(id);
                tris[bvh.primitive_indices[id] as usize].intersect(r)
            };
            let (mut ours, mut theirs) = (Vec::new(), Vec::new());
            let (mut hit_a, mut hit_b) = (RayHit::none(), RayHit::none());
            let a = closest_hit(&bvh, ray, &mut hit_a, |r, id| test(&mut ours, r, id));
            let b = bvh.ray_traverse(ray, &mut hit_b, |r, id| test(&mut theirs, r, id));
            assert_eq!(
                (a, hit_a.primitive_id, hit_a.t.to_bits()),
                (b, hit_b.primitive_id, hit_b.t.to_bits()),
                "ray {i}"
            );
            assert_eq!(ours, theirs, "closest-hit visits of ray {i}");
            hits += a as u32;
            let (mut ours, mut theirs) = (Vec::new(), Vec::new());
            let a = misses(&bvh, ray, |r, id| test(&mut ours, r, id));
            let b = bvh.ray_traverse_miss(ray, |r, id| test(&mut theirs, r, id));
            assert_eq!(a, b, "ray {i}");
            assert_eq!(ours, theirs, "any-hit visits of ray {i}");
        }
        assert!((2_000..18_000).contains(&hits), "{hits} of 20 000 rays hit: the case tests too little");
    }
}
