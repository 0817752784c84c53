//! Packet traversal: eight rays through one obvhs CWBVH together, for coherent rays (camera
//! rays of one pixel or of neighbouring pixels).
//!
//! Each node is fetched and decoded once for the whole packet; each of its children is tested
//! against all eight rays at once (the rays are the lanes), and a child is visited, with the
//! mask of the rays that hit its box, when any ray does. The box test of every (ray, child) pair
//! is obvhs's own (`CwBvhNode::intersect_ray`: the ray moved into the node's quantised grid, the
//! same products, sums, minima and maxima in the same order, no fused operations), so a ray
//! reaches the same leaves as it would alone unless the packet has already shortened it.
//! Children are visited in the order obvhs gives the packet's first ray; leaves before inner
//! children, as obvhs does. A ray keeps the closest hit it finds (`t < t_max`, first found on
//! a tie), so its result equals the single-ray traversal's except when two primitives are hit
//! at exactly the same distance (then the one visited first wins, which can differ).
//!
//! On x86-64 with AVX2 (detected once per process) the box test runs as 8-lane AVX operations,
//! one lane per ray, with the same operations as the baseline build (no fused ones), so both
//! builds visit the same nodes and give the same bits.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | [`PACKET`] | lanes | rays | 8 |
//! | `PETZVAL_SIMD` | environment variable (`baseline`: no AVX2) | — | unset (AVX2 when the CPU has it) |

use obvhs::cwbvh::{node::CwBvhNode, CwBvh};
use obvhs::ray::Ray;

/// Rays per packet.
pub const PACKET: usize = 8;

/// obvhs's lower bound on a box entry distance (`cwbvh::node::EPSILON`).
const NODE_T_MIN: f32 = 0.0001;

/// Deepest stack a traversal can need: 7 siblings left per level of a BVH at most 32 deep
/// (obvhs's own traversal-stack bound), plus the root.
const STACK: usize = 7 * 32 + 8;

/// SSE `maxps` semantics: `a` if `a > b`, else `b` (so `b` when either is NaN).
#[inline(always)]
fn max_ps(a: f32, b: f32) -> f32 {
    if a > b {
        a
    } else {
        b
    }
}

/// SSE `minps` semantics: `a` if `a < b`, else `b`.
#[inline(always)]
fn min_ps(a: f32, b: f32) -> f32 {
    if a < b {
        a
    } else {
        b
    }
}

/// The packet in structure-of-arrays form: origins, inverse directions and direction signs.
struct Lanes {
    origin: [[f32; PACKET]; 3],
    inv_dir: [[f32; PACKET]; 3],
    negative: [[bool; PACKET]; 3],
    /// `negative` as all-ones (−NaN) / zero floats, for blends.
    negative_mask: [[f32; PACKET]; 3],
    /// Per axis, the direction sign every active ray shares (`Some(true)`: all negative), or
    /// None when they differ. Where it is shared, near and far planes are chosen once per
    /// node instead of per lane (the same values as the blends pick).
    shared_negative: [Option<bool>; 3],
}

impl Lanes {
    /// The packet's lanes; `active` marks the rays whose signs count for `shared_negative`.
    fn new(rays: &[Ray; PACKET], active: u8) -> Lanes {
        let mut l = Lanes {
            origin: [[0.0; PACKET]; 3],
            inv_dir: [[0.0; PACKET]; 3],
            negative: [[false; PACKET]; 3],
            negative_mask: [[0.0; PACKET]; 3],
            shared_negative: [None; 3],
        };
        for (i, r) in rays.iter().enumerate() {
            for a in 0..3 {
                l.origin[a][i] = r.origin[a];
                l.inv_dir[a][i] = r.inv_direction[a];
                l.negative[a][i] = r.direction[a] < 0.0;
                l.negative_mask[a][i] = f32::from_bits(if l.negative[a][i] { u32::MAX } else { 0 });
            }
        }
        for a in 0..3 {
            let neg = (0..PACKET).fold(0u8, |m, i| m | ((l.negative[a][i] as u8) << i)) & active;
            l.shared_negative[a] = if neg == 0 {
                Some(false)
            } else if neg == active {
                Some(true)
            } else {
                None
            };
        }
        l
    }

    /// [`Lanes::child_masks`] in 8-lane AVX operations (the same operations per lane).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    fn child_masks_avx2(&self, node: &CwBvhNode, t_max: &[f32; PACKET], lanes: u8) -> [u8; 8] {
        use std::arch::x86_64::*;
        // 1. Every ray in the node's quantised grid (obvhs: extent · 1/d, (p − o) · 1/d).
        let extent = node.compute_extent();
        // SAFETY: the loads read whole [f32; 8] arrays (unaligned loads).
        let load = |v: &[f32; PACKET]| unsafe { _mm256_loadu_ps(v.as_ptr()) };
        let mut scale = [_mm256_setzero_ps(); 3];
        let mut offset = [_mm256_setzero_ps(); 3];
        let mut neg = [_mm256_setzero_ps(); 3];
        for a in 0..3 {
            let inv = load(&self.inv_dir[a]);
            scale[a] = _mm256_mul_ps(_mm256_set1_ps(extent[a]), inv);
            offset[a] = _mm256_mul_ps(_mm256_sub_ps(_mm256_set1_ps(node.p[a]), load(&self.origin[a])), inv);
            neg[a] = load(&self.negative_mask[a]);
        }
        let t_max = load(t_max);
        let eps = _mm256_set1_ps(NODE_T_MIN);
        // 2. The children's quantised planes as floats, all eight at once per plane row (exact:
        //    small integers). Where the packet shares a direction sign, the row is already the
        //    near or the far one, so no lane needs a blend.
        let bytes = [
            (&node.child_min_x, &node.child_max_x),
            (&node.child_min_y, &node.child_max_y),
            (&node.child_min_z, &node.child_max_z),
        ];
        let mut rows = [[[0.0f32; 8]; 2]; 3];
        for a in 0..3 {
            let (lo, hi) = bytes[a];
            let (first, second) = match self.shared_negative[a] {
                Some(true) => (hi, lo),
                _ => (lo, hi),
            };
            for (row, b) in rows[a].iter_mut().zip([first, second]) {
                // SAFETY: reads the row's 8 bytes, writes 8 floats into an [f32; 8].
                unsafe {
                    let v = _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(_mm_loadl_epi64(b.as_ptr() as *const __m128i)));
                    _mm256_storeu_ps(row.as_mut_ptr(), v);
                }
            }
        }
        let mut masks = [0u8; 8];
        for (c, mask) in masks.iter_mut().enumerate() {
            if node.child_meta[c] == 0 {
                continue;
            }
            // 3. Slab distances per axis: near and far by the shared sign, else blended by
            //    each lane's sign.
            let mut near = [_mm256_setzero_ps(); 3];
            let mut far = [_mm256_setzero_ps(); 3];
            for a in 0..3 {
                let t_first = _mm256_add_ps(_mm256_mul_ps(_mm256_set1_ps(rows[a][0][c]), scale[a]), offset[a]);
                let t_second = _mm256_add_ps(_mm256_mul_ps(_mm256_set1_ps(rows[a][1][c]), scale[a]), offset[a]);
                (near[a], far[a]) = match self.shared_negative[a] {
                    Some(_) => (t_first, t_second),
                    None => (_mm256_blendv_ps(t_first, t_second, neg[a]), _mm256_blendv_ps(t_second, t_first, neg[a])),
                };
            }
            // 4. Overlap clamped to [ε, t_max], in obvhs's operand order.
            let t0 = _mm256_max_ps(near[0], _mm256_max_ps(near[1], near[2]));
            let t1 = _mm256_min_ps(far[0], _mm256_min_ps(far[1], far[2]));
            let t0 = _mm256_max_ps(t0, eps);
            let t1 = _mm256_min_ps(t1, t_max);
            *mask = (_mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t0, t1)) as u8) & lanes;
        }
        masks
    }

    /// The mask of lanes (rays) that hit each of `node`'s eight child boxes, given each ray's
    /// current `t_max`; 0 for empty slots and for lanes outside `lanes`.
    #[inline(always)]
    fn child_masks(&self, node: &CwBvhNode, t_max: &[f32; PACKET], lanes: u8) -> [u8; 8] {
        // 1. Every ray in the node's quantised grid (obvhs: extent · 1/d, (p − o) · 1/d).
        let extent = node.compute_extent();
        let mut scale = [[0.0f32; PACKET]; 3];
        let mut offset = [[0.0f32; PACKET]; 3];
        for a in 0..3 {
            for i in 0..PACKET {
                scale[a][i] = extent[a] * self.inv_dir[a][i];
                offset[a][i] = (node.p[a] - self.origin[a][i]) * self.inv_dir[a][i];
            }
        }
        let planes = [
            (&node.child_min_x, &node.child_max_x),
            (&node.child_min_y, &node.child_max_y),
            (&node.child_min_z, &node.child_max_z),
        ];
        let mut masks = [0u8; 8];
        for (c, mask) in masks.iter_mut().enumerate() {
            if node.child_meta[c] == 0 {
                continue;
            }
            // 2. Slab distances per axis, near and far chosen by the ray's direction sign.
            let mut near = [[0.0f32; PACKET]; 3];
            let mut far = [[0.0f32; PACKET]; 3];
            for a in 0..3 {
                let (lo, hi) = (planes[a].0[c] as f32, planes[a].1[c] as f32);
                for i in 0..PACKET {
                    let t_lo = lo * scale[a][i] + offset[a][i];
                    let t_hi = hi * scale[a][i] + offset[a][i];
                    let neg = self.negative[a][i];
                    near[a][i] = if neg { t_hi } else { t_lo };
                    far[a][i] = if neg { t_lo } else { t_hi };
                }
            }
            // 3. Overlap clamped to [ε, t_max], in obvhs's operand order.
            let mut m = 0u8;
            for i in 0..PACKET {
                let t0 = max_ps(near[0][i], max_ps(near[1][i], near[2][i]));
                let t1 = min_ps(far[0][i], min_ps(far[1][i], far[2][i]));
                let t0 = max_ps(t0, NODE_T_MIN);
                let t1 = min_ps(t1, t_max[i]);
                m |= ((t0 <= t1) as u8) << i;
            }
            *mask = m & lanes;
        }
        masks
    }
}

/// Closest hits of up to eight rays (`active`: bit i set = `rays[i]` is traced). `intersect(id,
/// lanes, t_max)` tests primitive `id` (leaf order) against the rays of mask `lanes` and lowers
/// `t_max[i]` to the distance of a closer hit of ray i (the packet's current distances, which
/// it must only lower). Returns each lane's final `t_max`: the closest hit's distance, or the
/// ray's own `tmax` when nothing closer was hit.
pub(crate) fn closest_hits<F: FnMut(usize, u8, &mut [f32; PACKET])>(
    bvh: &CwBvh,
    rays: &[Ray; PACKET],
    active: u8,
    intersect: F,
) -> [f32; PACKET] {
    #[cfg(target_arch = "x86_64")]
    if *USE_AVX2 {
        // SAFETY: AVX2 was detected on this CPU.
        return unsafe { closest_hits_avx2(bvh, rays, active, intersect) };
    }
    closest_hits_any(bvh, rays, active, intersect, Lanes::child_masks)
}

/// Whether this process runs the AVX2 build of the packet code (see [`USE_AVX2`]).
#[inline]
pub(crate) fn avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        *USE_AVX2
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Whether this process runs the AVX2 build of the traversal (detected at first use;
/// `PETZVAL_SIMD=baseline` forces the baseline). Both builds do the same operations.
#[cfg(target_arch = "x86_64")]
static USE_AVX2: std::sync::LazyLock<bool> = std::sync::LazyLock::new(|| {
    !std::env::var("PETZVAL_SIMD").is_ok_and(|v| v == "baseline") && std::arch::is_x86_feature_detected!("avx2")
});

/// [`closest_hits_any`] compiled with AVX2 (no FMA: the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn closest_hits_avx2<F: FnMut(usize, u8, &mut [f32; PACKET])>(
    bvh: &CwBvh,
    rays: &[Ray; PACKET],
    active: u8,
    intersect: F,
) -> [f32; PACKET] {
    // (The closure inherits this function's AVX2, so it calls the AVX2 box test directly.)
    closest_hits_any(bvh, rays, active, intersect, |l: &Lanes, n: &CwBvhNode, t: &[f32; PACKET], m: u8| {
        l.child_masks_avx2(n, t, m)
    })
}

/// The traversal, for any instruction set.
#[inline(always)]
fn closest_hits_any<
    F: FnMut(usize, u8, &mut [f32; PACKET]),
    M: Fn(&Lanes, &CwBvhNode, &[f32; PACKET], u8) -> [u8; 8],
>(
    bvh: &CwBvh,
    rays: &[Ray; PACKET],
    active: u8,
    mut intersect: F,
    child_masks: M,
) -> [f32; PACKET] {
    let mut t_max: [f32; PACKET] = std::array::from_fn(|i| rays[i].tmax);
    if bvh.nodes.is_empty() || active == 0 {
        return t_max;
    }
    let lanes = Lanes::new(rays, active);
    // Child order: obvhs's for the packet's first ray (priority slot ^ (7 − octant), highest first).
    let lead = &rays[active.trailing_zeros() as usize];
    let oct_inv = (if lead.direction.x < 0.0 { 0 } else { 4 })
        | (if lead.direction.y < 0.0 { 0 } else { 2 })
        | (if lead.direction.z < 0.0 { 0 } else { 1 });
    // Stack entries: node index << 8 | lane mask.
    // (A deeper BVH than obvhs allows spills into `spill`, popped first.)
    let mut stack = [0u64; STACK];
    let mut spill: Vec<u64> = Vec::new();
    let mut top = 1usize;
    stack[0] = active as u64;
    loop {
        let entry = if let Some(e) = spill.pop() {
            e
        } else if top > 0 {
            top -= 1;
            stack[top]
        } else {
            break;
        };
        let node = &bvh.nodes[(entry >> 8) as usize];
        let masks = child_masks(&lanes, node, &t_max, entry as u8);
        // 1. Leaf children: every primitive against every ray that reached it.
        for (c, &m) in masks.iter().enumerate() {
            if m == 0 || !node.is_leaf(c) {
                continue;
            }
            let (first, count) = node.child_primitives(c);
            for id in first..first + count {
                intersect(id as usize, m, &mut t_max);
            }
        }
        // 2. Inner children, pushed lowest priority first so the highest is visited next.
        let mut order = [(0u8, 0u8, 0u32); 8];
        let mut n = 0;
        for (c, &m) in masks.iter().enumerate() {
            if m == 0 || node.is_leaf(c) {
                continue;
            }
            let priority = ((node.child_meta[c] & 0b11111).wrapping_sub(24)) ^ oct_inv;
            order[n] = (priority, m, node.child_node_index(c));
            n += 1;
        }
        order[..n].sort_unstable_by_key(|&(p, _, _)| p);
        for &(_, m, child) in &order[..n] {
            let e = ((child as u64) << 8) | m as u64;
            if top < STACK && spill.is_empty() {
                stack[top] = e;
                top += 1;
            } else {
                spill.push(e);
            }
        }
    }
    t_max
}
