//! Light bounds (pbrt-v4 `LightBounds`) and the 4-wide light tree (see the module docs of [`super`]).

use std::f32::consts::{FRAC_PI_2, PI};

use glam::{Quat, Vec3, Vec4};

// ------------------------------------------------------------------------------------------
// Light bounds and the light tree.

/// Largest f32 below 1.
const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

#[inline]
fn safe_acos(x: f32) -> f32 {
    x.clamp(-1.0, 1.0).acos()
}

#[inline]
fn safe_sqrt(x: f32) -> f32 {
    x.max(0.0).sqrt()
}

/// Angle between unit vectors (numerically robust, as pbrt).
#[inline]
fn angle_between(a: Vec3, b: Vec3) -> f32 {
    if a.dot(b) < 0.0 {
        PI - 2.0 * ((a + b).length() * 0.5).clamp(-1.0, 1.0).asin()
    } else {
        2.0 * ((b - a).length() * 0.5).clamp(-1.0, 1.0).asin()
    }
}

/// Smallest cone (axis, cos half-angle) holding cones a and b (pbrt-v4's `Union`), slightly
/// widened so that rounding never makes it too narrow.
fn cone_union(wa: Vec3, cos_a: f32, wb: Vec3, cos_b: f32) -> (Vec3, f32) {
    if cos_a <= -1.0 || cos_b <= -1.0 {
        return (wa, -1.0);
    }
    if wa == wb && cos_a == cos_b {
        return (wa, cos_a);
    }
    let (ta, tb) = (safe_acos(cos_a), safe_acos(cos_b));
    let td = angle_between(wa, wb);
    if (td + tb).min(PI) <= ta {
        return (wa, cos_a);
    }
    if (td + ta).min(PI) <= tb {
        return (wb, cos_b);
    }
    let to = 0.5 * (ta + td + tb) + 1e-5;
    if to >= PI {
        return (wa, -1.0);
    }
    let wr = wa.cross(wb);
    if wr.length_squared() < 1e-20 {
        return (wa, -1.0);
    }
    let w = (Quat::from_axis_angle(wr.normalize(), to - ta) * wa).normalize();
    if !w.is_finite() {
        return (wa, -1.0);
    }
    (w, to.cos())
}

/// Spatial and directional bounds of one light or a group of lights (pbrt-v4's `LightBounds`).
#[derive(Debug, Clone, Copy)]
pub(super) struct LightBounds {
    pub(super) bmin: Vec3,
    pub(super) bmax: Vec3,
    /// Emission power (luminance).
    pub(super) phi: f32,
    /// Axis of the cone of emission normals.
    pub(super) w: Vec3,
    /// cos θo: spread of the emission normals about `w`.
    pub(super) cos_o: f32,
    /// cos θe: how far beyond the normals light is emitted (π/2 for area lights).
    pub(super) cos_e: f32,
    pub(super) two_sided: bool,
}

impl LightBounds {
    #[inline]
    fn centroid(&self) -> Vec3 {
        0.5 * (self.bmin + self.bmax)
    }

    fn union(&self, o: &LightBounds) -> LightBounds {
        let (w, cos_o) = cone_union(self.w, self.cos_o, o.w, o.cos_o);
        LightBounds {
            bmin: self.bmin.min(o.bmin),
            bmax: self.bmax.max(o.bmax),
            phi: self.phi + o.phi,
            w,
            cos_o,
            cos_e: self.cos_e.min(o.cos_e),
            two_sided: self.two_sided || o.two_sided,
        }
    }

    /// pbrt-v4's SAH-like cost of a cluster: power × orientation measure M_Ω × surface area ×
    /// `kr` (aspect-ratio term of the parent along the split axis).
    fn cost(&self, kr: f32) -> f32 {
        let m_omega = if self.cos_e == FRAC_PI_2.cos() {
            // Emission over the hemisphere about each normal (area lights): θe = π/2, so
            // θw = min(θo + π/2, π) and cos(θo − 2θw) = ∓cos θo.
            if self.cos_o >= 1.0 {
                PI
            } else {
                let theta_o = safe_acos(self.cos_o);
                let sin_o = safe_sqrt(1.0 - self.cos_o * self.cos_o);
                let (theta_w, cos_ow) =
                    if theta_o < FRAC_PI_2 { (theta_o + FRAC_PI_2, -self.cos_o) } else { (PI, self.cos_o) };
                2.0 * PI * (1.0 - self.cos_o)
                    + FRAC_PI_2 * (2.0 * theta_w * sin_o - cos_ow - 2.0 * theta_o * sin_o + self.cos_o)
            }
        } else {
            let theta_o = safe_acos(self.cos_o);
            let theta_e = safe_acos(self.cos_e);
            let theta_w = (theta_o + theta_e).min(PI);
            let sin_o = safe_sqrt(1.0 - self.cos_o * self.cos_o);
            2.0 * PI * (1.0 - self.cos_o)
                + FRAC_PI_2
                    * (2.0 * theta_w * sin_o - (theta_o - 2.0 * theta_w).cos() - 2.0 * theta_o * sin_o + self.cos_o)
        };
        let d = self.bmax - self.bmin;
        let area = 2.0 * (d.x * d.y + d.y * d.z + d.z * d.x);
        self.phi * m_omega * area * kr
    }
}

/// A node of the binary light BVH as built (the input of the 4-wide tree).
#[derive(Debug, Clone, Copy)]
struct BinNode {
    bounds: LightBounds,
    leaf: bool,
    /// Leaf: the light's index; interior: the second child's node index (the first child is
    /// the next node).
    index: u32,
}

/// Lanes per node of the sampled tree.
const LANES: usize = 4;
/// `Node4::child` flag: the lane is a single light (index in the low bits).
const LEAF: u32 = 1 << 31;

/// A node of the sampled tree: up to four children ("lanes"), each a light or a node, with
/// what the importance needs, structure-of-arrays so that the four importances are computed
/// side by side (SIMD). Unused lanes have `phi = 0` (importance 0).
#[derive(Debug, Clone, Copy, Default)]
struct Node4 {
    /// Bounding-sphere centre (= bounding-box centre).
    cx: Vec4,
    cy: Vec4,
    cz: Vec4,
    /// Bounding-sphere radius (slightly padded) and its square.
    radius: Vec4,
    radius2: Vec4,
    /// The importance inside the bounding sphere: phi / r² (phi · 10³⁰ where r = 0).
    phi_inside: Vec4,
    /// Axis of the cone of emission normals.
    wx: Vec4,
    wy: Vec4,
    wz: Vec4,
    phi: Vec4,
    cos_o: Vec4,
    sin_o: Vec4,
    cos_e: Vec4,
    /// 1: two sided, 0: one sided.
    two_sided: Vec4,
    /// `LEAF | light index`, or the child node's index.
    child: [u32; LANES],
}

/// Lane-wise square root (exactly rounded, as f32::sqrt).
#[inline(always)]
fn sqrt4(v: Vec4) -> Vec4 {
    Vec4::from_array(v.to_array().map(f32::sqrt))
}

impl Node4 {
    fn set_lane(&mut self, k: usize, b: &LightBounds, child: u32) {
        let center = b.centroid();
        let r = (b.bmax - center).length().max((center - b.bmin).length());
        // Pad against rounding in `center` (absolute) and in the radius (relative).
        let r = if r > 0.0 { r * (1.0 + 1e-5) + center.abs().max_element() * 4.0 * f32::EPSILON } else { 0.0 };
        let w = b.w.normalize_or(Vec3::Z);
        self.cx[k] = center.x;
        self.cy[k] = center.y;
        self.cz[k] = center.z;
        self.radius[k] = r;
        self.radius2[k] = r * r;
        self.phi_inside[k] = if r * r > 0.0 { b.phi / (r * r) } else { b.phi * 1e30 };
        self.wx[k] = w.x;
        self.wy[k] = w.y;
        self.wz[k] = w.z;
        self.phi[k] = b.phi;
        self.cos_o[k] = b.cos_o;
        self.sin_o[k] = safe_sqrt(1.0 - b.cos_o * b.cos_o);
        self.cos_e[k] = b.cos_e;
        self.two_sided[k] = if b.two_sided { 1.0 } else { 0.0 };
        self.child[k] = child;
    }

    /// Importances of the four lanes for a receiver at `p` with normal `n` (zero: no normal,
    /// no receiver-cosine term), after pbrt-v4's `LightBounds::Importance`:
    /// `phi · cos θ' / d²` (× `cos θi'` with a normal), θ' the smallest angle between an
    /// emission normal of the cone and a direction from the lights to `p`, θi' the smallest
    /// angle between `n` and a direction from `p` to the lights (θb: half-angle of the cone
    /// from `p` to the bounding sphere). Zero only when no light of the lane can reach `p`
    /// (θ' ≥ θe; the bounds are conservative) or, with a normal, when all of the lane is below
    /// the surface (θi' ≥ π/2; the BSDFs here never transmit). Inside the bounding sphere:
    /// `phi / r²`.
    #[inline]
    fn importance(&self, p: Vec3, n: Vec3) -> Vec4 {
        let (one, zero) = (Vec4::ONE, Vec4::ZERO);
        let dx = Vec4::splat(p.x) - self.cx;
        let dy = Vec4::splat(p.y) - self.cy;
        let dz = Vec4::splat(p.z) - self.cz;
        let dist2 = dx * dx + dy * dy + dz * dz;
        let inside = dist2.cmple(self.radius2);
        let inv_dist = one / sqrt4(dist2);
        // Unit direction from the lights to p.
        let (ux, uy, uz) = (dx * inv_dist, dy * inv_dist, dz * inv_dist);
        let sin_b = (self.radius * inv_dist).min(one);
        let cos_b = sqrt4((one - sin_b * sin_b).max(zero));
        let cw = self.wx * ux + self.wy * uy + self.wz * uz;
        let cos_w = Vec4::select(self.two_sided.cmpgt(zero), cw.abs(), cw);
        let sin_w = sqrt4((one - cos_w * cos_w).max(zero));
        // θx = max(0, θw − θo).
        let in_cone = cos_w.cmpgt(self.cos_o);
        let cos_x = Vec4::select(in_cone, one, cos_w * self.cos_o + sin_w * self.sin_o);
        let sin_x = Vec4::select(in_cone, zero, sin_w * self.cos_o - cos_w * self.sin_o);
        // θ' = max(0, θx − θb).
        let cos_p = Vec4::select(cos_x.cmpgt(cos_b), one, cos_x * cos_b + sin_x * sin_b);
        // θi' = max(0, θi − θb).
        let cos_pi = if n != Vec3::ZERO {
            let cos_i = -(Vec4::splat(n.x) * ux + Vec4::splat(n.y) * uy + Vec4::splat(n.z) * uz);
            let sin_i = sqrt4((one - cos_i * cos_i).max(zero));
            Vec4::select(cos_i.cmpgt(cos_b), one, cos_i * cos_b + sin_i * sin_b)
        } else {
            one
        };
        let culled = cos_p.cmple(self.cos_e) | cos_pi.cmple(zero);
        let outside = Vec4::select(culled, zero, self.phi * cos_p * cos_pi / dist2);
        let imp = Vec4::select(inside, self.phi_inside, outside);
        // NaN-free, finite, ≥ 0.
        Vec4::select(imp.cmpgt(zero), imp.min(Vec4::splat(1e30)), zero)
    }

    /// Selection probabilities of the lanes: importance / sum, or None when all are zero.
    #[inline]
    fn probabilities(&self, p: Vec3, n: Vec3) -> Option<[f32; LANES]> {
        let c = self.importance(p, n);
        let sum = ((c.x + c.y) + c.z) + c.w;
        if !(sum > 0.0) {
            return None;
        }
        Some((c * (1.0 / sum)).to_array())
    }
}

/// Where a light sits in the tree sampler.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Slot {
    /// In the tree: two bits per level, the lane taken (level 0 in the lowest bits).
    Tree(u128),
    /// At infinity: index into `LightTree::infinite`.
    Infinite(u32),
    /// Never sampled by the tree (unbounded position).
    None,
}

/// The light tree and the lights at infinity.
#[derive(Debug, Clone, Default)]
pub(super) struct LightTree {
    /// 4-wide nodes, root first.
    nodes: Vec<Node4>,
    /// Lights at infinity (light indices).
    infinite: Vec<u32>,
    /// Their power distribution: n + 1 entries, 0 … 1.
    infinite_cdf: Vec<f32>,
    slots: Vec<Slot>,
    /// Probability of sampling a light at infinity.
    p_infinite: f32,
    /// Depth of the binary tree and of the 4-wide tree.
    bin_depth: u32,
    pub(super) depth: u32,
}

/// Probability of sampling the lights at infinity as a group when there are bounded lights too
/// (pbrt-v4 gives each light at infinity the weight of the whole tree, `n / (n + 1)`; here they
/// count as one group, which bounds the variance penalty of either group by a factor 2).
pub const P_INFINITE: f32 = 0.5;

/// Binary tree depth from which splits are median splits, so that the depth stays below 64
/// (at most 63 levels of two trail bits in the 4-wide tree).
const SAH_MAX_DEPTH: u32 = 32;
const BUCKETS: usize = 12;

impl LightTree {
    /// `infinite`: (light index, power) of the lights at infinity.
    pub(super) fn build(bounded: Vec<(u32, LightBounds)>, infinite: Vec<(u32, f64)>, n_lights: usize) -> LightTree {
        let mut slots = vec![Slot::None; n_lights];
        for (k, &(i, _)) in infinite.iter().enumerate() {
            slots[i as usize] = Slot::Infinite(k as u32);
        }
        // Among themselves, lights at infinity are chosen by power.
        let total: f64 = infinite.iter().map(|&(_, p)| p).sum();
        let mut infinite_cdf = vec![0.0f32];
        let mut acc = 0.0f64;
        for &(_, p) in &infinite {
            acc += p;
            infinite_cdf.push((acc / total) as f32);
        }
        if let Some(last) = infinite_cdf.last_mut() {
            *last = 1.0;
        }
        let infinite = infinite.into_iter().map(|(i, _)| i).collect();
        let mut tree =
            LightTree { nodes: Vec::new(), infinite, infinite_cdf, slots, p_infinite: 0.0, bin_depth: 0, depth: 0 };
        let mut items = bounded;
        if !items.is_empty() {
            let mut bin = Vec::with_capacity(2 * items.len() - 1);
            build_binary(&mut bin, &mut items, 0, &mut tree.bin_depth);
            let lanes: Vec<usize> = if bin[0].leaf { vec![0] } else { vec![1, bin[0].index as usize] };
            tree.nodes.reserve(bin.len() / 3 + 1);
            tree.collapse(&bin, lanes, 0, 0);
        }
        tree.p_infinite = match (tree.infinite.is_empty(), tree.nodes.is_empty()) {
            (true, _) => 0.0,
            (false, true) => 1.0,
            (false, false) => P_INFINITE,
        };
        tree
    }

    /// Adds a 4-wide node with the given binary nodes as lanes (first expanding interior
    /// lanes, brightest first, until there are four), recursively; returns its index.
    fn collapse(&mut self, bin: &[BinNode], mut lanes: Vec<usize>, trail: u128, depth: u32) -> u32 {
        self.depth = self.depth.max(depth + 1);
        while lanes.len() < LANES {
            let best = lanes
                .iter()
                .enumerate()
                .filter(|(_, &l)| !bin[l].leaf)
                .max_by(|a, b| bin[*a.1].bounds.phi.total_cmp(&bin[*b.1].bounds.phi))
                .map(|(k, &l)| (k, l));
            let Some((k, l)) = best else { break };
            lanes.remove(k);
            lanes.push(l + 1);
            lanes.push(bin[l].index as usize);
        }
        let idx = self.nodes.len();
        self.nodes.push(Node4::default());
        for (k, &l) in lanes.iter().enumerate() {
            let t = trail | ((k as u128) << (2 * depth));
            let child = if bin[l].leaf {
                self.slots[bin[l].index as usize] = Slot::Tree(t);
                LEAF | bin[l].index
            } else {
                self.collapse(bin, vec![l + 1, bin[l].index as usize], t, depth + 1)
            };
            self.nodes[idx].set_lane(k, &bin[l].bounds, child);
        }
        idx as u32
    }

    /// Power pmf of light at infinity `k` within its group.
    #[inline]
    pub(super) fn infinite_pmf(&self, k: usize) -> f32 {
        self.infinite_cdf[k + 1] - self.infinite_cdf[k]
    }

    /// Picks a light for (p, n): (light index, pmf).
    pub(super) fn pick(&self, p: Vec3, n: Vec3, u: f32) -> Option<(usize, f32)> {
        let u = u.clamp(0.0, ONE_MINUS_EPSILON);
        let p_inf = self.p_infinite;
        if u < p_inf {
            let u = (u / p_inf).min(ONE_MINUS_EPSILON);
            // First k with cdf[k + 1] > u.
            let k = self.infinite_cdf[1..].partition_point(|&c| c <= u).min(self.infinite.len() - 1);
            let pmf = p_inf * self.infinite_pmf(k);
            return if pmf > 0.0 { Some((self.infinite[k] as usize, pmf)) } else { None };
        }
        if self.nodes.is_empty() {
            return None;
        }
        let mut u = ((u - p_inf) / (1.0 - p_inf)).min(ONE_MINUS_EPSILON);
        let mut pmf = 1.0 - p_inf;
        let mut node = &self.nodes[0];
        loop {
            let prob = node.probabilities(p, n)?;
            // The lane whose interval [Σ_{j<k} prob_j, Σ_{j≤k} prob_j) holds u (the last
            // non-zero lane when rounding leaves u beyond the end).
            let mut last = 0;
            for (k, &q) in prob.iter().enumerate() {
                if q > 0.0 {
                    last = k;
                }
            }
            let mut k = 0;
            while k < last && !(prob[k] > 0.0 && u < prob[k]) {
                u -= prob[k];
                k += 1;
            }
            u = (u / prob[k]).clamp(0.0, ONE_MINUS_EPSILON);
            pmf *= prob[k];
            let child = node.child[k];
            if child & LEAF != 0 {
                return Some(((child & !LEAF) as usize, pmf));
            }
            node = &self.nodes[child as usize];
        }
    }

    /// Probability that [`LightTree::pick`] returns `light` at (p, n): the same float
    /// operations along the light's trail of lanes.
    pub(super) fn pmf(&self, p: Vec3, n: Vec3, light: usize) -> f32 {
        match self.slots.get(light) {
            Some(&Slot::Infinite(k)) => self.p_infinite * self.infinite_pmf(k as usize),
            Some(&Slot::Tree(mut trail)) => {
                let mut pmf = 1.0 - self.p_infinite;
                let mut node = &self.nodes[0];
                loop {
                    let Some(prob) = node.probabilities(p, n) else { return 0.0 };
                    let k = (trail & 3) as usize;
                    trail >>= 2;
                    pmf *= prob[k];
                    let child = node.child[k];
                    if child & LEAF != 0 {
                        return pmf;
                    }
                    node = &self.nodes[child as usize];
                }
            }
            _ => 0.0,
        }
    }
}

/// Builds the binary light BVH over `items` top-down (pbrt-v4's `buildBVH`: SAH-like cost over
/// 12 buckets per axis; median split where that fails or below [`SAH_MAX_DEPTH`]); returns the
/// bounds of `items`.
fn build_binary(
    nodes: &mut Vec<BinNode>,
    items: &mut [(u32, LightBounds)],
    depth: u32,
    max_depth: &mut u32,
) -> LightBounds {
    *max_depth = (*max_depth).max(depth);
    if items.len() == 1 {
        let (li, b) = items[0];
        nodes.push(BinNode { bounds: b, leaf: true, index: li });
        return b;
    }
    let (mut bmin, mut bmax) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    let (mut cmin, mut cmax) = (bmin, bmax);
    for (_, b) in items.iter() {
        bmin = bmin.min(b.bmin);
        bmax = bmax.max(b.bmax);
        let c = b.centroid();
        cmin = cmin.min(c);
        cmax = cmax.max(c);
    }
    let diag = bmax - bmin;
    // Best split: (cost, axis, last bucket of the first child).
    let mut best: Option<(f32, usize, usize)> = None;
    if depth < SAH_MAX_DEPTH {
        for dim in 0..3 {
            if !(cmax[dim] > cmin[dim]) {
                continue;
            }
            // Bucket bounds, for the cost only (node bounds are exact unions of the children):
            // the normal cone is about the power-weighted mean normal, its spread the largest
            // angle to a light's cone (no trigonometry, unlike exact cone unions).
            let mut buckets: [Option<LightBounds>; BUCKETS] = [None; BUCKETS];
            let mut wsum = [Vec3::ZERO; BUCKETS];
            for (_, b) in items.iter() {
                let k = bucket_of(b.centroid()[dim], cmin[dim], cmax[dim]);
                wsum[k] += b.w * b.phi;
                buckets[k] = Some(match buckets[k] {
                    Some(a) => LightBounds {
                        bmin: a.bmin.min(b.bmin),
                        bmax: a.bmax.max(b.bmax),
                        phi: a.phi + b.phi,
                        w: Vec3::ZERO,
                        cos_o: 1.0,
                        cos_e: a.cos_e.min(b.cos_e),
                        two_sided: a.two_sided || b.two_sided,
                    },
                    None => LightBounds { w: Vec3::ZERO, cos_o: 1.0, ..*b },
                });
            }
            for k in 0..BUCKETS {
                if let Some(bk) = buckets[k].as_mut() {
                    bk.w = wsum[k].normalize_or(Vec3::Z);
                }
            }
            for (_, b) in items.iter() {
                let k = bucket_of(b.centroid()[dim], cmin[dim], cmax[dim]);
                if let Some(bk) = buckets[k].as_mut() {
                    bk.cos_o = bk.cos_o.min(cos_angle_sum(bk.w.dot(b.w), b.cos_o));
                }
            }
            let kr = diag.max_element() / diag[dim];
            // Suffix unions.
            let mut suffix: [Option<LightBounds>; BUCKETS] = [None; BUCKETS];
            let mut acc: Option<LightBounds> = None;
            for k in (0..BUCKETS).rev() {
                acc = join(acc, buckets[k]);
                suffix[k] = acc;
            }
            let mut prefix: Option<LightBounds> = None;
            for k in 0..BUCKETS - 1 {
                prefix = join(prefix, buckets[k]);
                let (Some(l), Some(r)) = (prefix, suffix[k + 1]) else { continue };
                let cost = l.cost(kr) + r.cost(kr);
                if cost.is_finite() && best.is_none_or(|(c, _, _)| cost < c) {
                    best = Some((cost, dim, k));
                }
            }
        }
    }
    let mut mid = match best {
        Some((_, dim, split)) => {
            let mut i = 0;
            for j in 0..items.len() {
                if bucket_of(items[j].1.centroid()[dim], cmin[dim], cmax[dim]) <= split {
                    items.swap(i, j);
                    i += 1;
                }
            }
            i
        }
        None => 0,
    };
    if mid == 0 || mid == items.len() {
        // Median along the widest centroid axis.
        mid = items.len() / 2;
        let ext = cmax - cmin;
        let dim = if ext.x >= ext.y && ext.x >= ext.z {
            0
        } else if ext.y >= ext.z {
            1
        } else {
            2
        };
        items.select_nth_unstable_by(mid, |a, b| a.1.centroid()[dim].total_cmp(&b.1.centroid()[dim]));
    }
    let node = nodes.len();
    // Placeholder, filled in once the children are built.
    nodes.push(BinNode { bounds: items[0].1, leaf: false, index: 0 });
    let (left, right) = items.split_at_mut(mid);
    let b0 = build_binary(nodes, left, depth + 1, max_depth);
    let second = nodes.len() as u32;
    let b1 = build_binary(nodes, right, depth + 1, max_depth);
    let b = b0.union(&b1);
    nodes[node] = BinNode { bounds: b, leaf: false, index: second };
    b
}

/// cos(α + β) from cos α and cos β (−1 when α + β ≥ π).
#[inline]
fn cos_angle_sum(cos_a: f32, cos_b: f32) -> f32 {
    let cos_a = cos_a.clamp(-1.0, 1.0);
    if cos_a <= -cos_b {
        -1.0
    } else {
        cos_a * cos_b - safe_sqrt(1.0 - cos_a * cos_a) * safe_sqrt(1.0 - cos_b * cos_b)
    }
}

#[inline]
fn bucket_of(c: f32, lo: f32, hi: f32) -> usize {
    let t = (c - lo) / (hi - lo);
    ((t * BUCKETS as f32) as usize).min(BUCKETS - 1)
}

#[inline]
fn join(a: Option<LightBounds>, b: Option<LightBounds>) -> Option<LightBounds> {
    match (a, b) {
        (Some(a), Some(b)) => Some(a.union(&b)),
        (a, None) => a,
        (None, b) => b,
    }
}
