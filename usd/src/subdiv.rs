//! Catmull-Clark subdivision of a polygon cage (`UsdGeomMesh` with `subdivisionScheme =
//! catmullClark`), uniformly to a level, with the final vertices moved to the limit surface, as
//! Blender's Subdivision modifier does (its "Use Limit Surface" default), through OpenSubdiv's
//! rules:
//!
//! | input | type | unit | default | handling |
//! |---|---|---|---|---|
//! | `level` | `u32` | refinement steps | 2 (Blender's render level) | each step splits an n-sided face into n quads |
//! | `interpolateBoundary` | token | — | `edgeOnly` | boundary edges are creases; `edgeAndCorner` also pins vertices with one face; `none` is read as `edgeOnly` |
//! | `creaseIndices`, `creaseLengths`, `creaseSharpnesses` | int[], int[], float[] | sharpness | none | edge sharpness; ≥ 10 is infinitely sharp; semi-sharp creases lose 1 per level ("uniform" creasing) and blend where they end |
//! | `cornerIndices`, `cornerSharpnesses` | int[], float[] | sharpness | none | vertex sharpness, as edges |
//!
//! Rules per vertex (DeRose, Kass & Truong 1998; OpenSubdiv's Sdc): a vertex with no sharp edge
//! or one (a dart) is smooth, with two it is a crease, with more or a sharp vertex it is a corner;
//! where a sharpness falls below zero between a level and the next, the two rules are blended by
//! the fraction left. Edges on a boundary or shared by more than two faces are infinitely sharp.
//! The limit position of a final vertex follows its rule: smooth `(n²·v + 4·Σe + Σd)/(n(n+5))`,
//! crease `(e₀ + 4·v + e₁)/6`, corner `v`; a semi-sharp feature left after the last level counts
//! as sharp there.

use glam::DVec3;
use rustc_hash::FxHashMap as HashMap;

/// Levels a subdivision surface is refined by unless told otherwise: Blender's Subdivision
/// modifier's default render level, and the level Blender's USD import gives such a mesh.
pub const DEFAULT_LEVEL: u32 = 2;

/// Sharpness that never decays (USD: ≥ 10).
pub const INFINITELY_SHARP: f64 = 10.0;

/// Edge sharpness by the edge's two vertices, the smaller first.
pub type EdgeSharpness = HashMap<(u32, u32), f64>;

/// Vertex sharpness by vertex.
pub type VertexSharpness = HashMap<u32, f64>;

/// How boundary vertices refine (USD `interpolateBoundary`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BoundaryRule {
    /// Boundary edges are creases; corners round off.
    EdgeOnly,
    /// Boundary edges are creases and vertices with a single face stay put.
    EdgeAndCorner,
    /// Every boundary vertex stays put and boundary edges stay straight (face-varying linear
    /// boundaries).
    Linear,
    /// Linear everywhere: bilinear refinement (face-varying `all`).
    Bilinear,
}

/// A polygon mesh with crease data, the input and output of one refinement step.
#[derive(Debug, Clone, Default)]
pub struct Cage {
    /// Vertex data (positions, or texture coordinates in `x`, `y`).
    pub points: Vec<DVec3>,
    /// Vertices per face (each ≥ 3).
    pub counts: Vec<u32>,
    /// Face corners' vertex indices.
    pub indices: Vec<u32>,
    /// Edge sharpness by the edge's two vertices, the smaller first (absent: smooth).
    pub creases: EdgeSharpness,
    /// Vertex sharpness (absent: 0).
    pub corners: VertexSharpness,
    /// The cage face every face descends from.
    pub parent: Vec<u32>,
}

/// Sharpness a refinement step leaves ("uniform" creasing).
fn decay(s: f64) -> f64 {
    if s >= INFINITELY_SHARP {
        s
    } else {
        (s - 1.0).max(0.0)
    }
}

fn key(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

/// One edge of the cage: its vertices, the faces it borders and its sharpness.
struct Edge {
    v: [u32; 2],
    faces: u32,
    face_point_sum: DVec3,
    sharpness: f64,
}

/// What a vertex's rule needs from its edges and faces.
#[derive(Clone, Default)]
struct Ring {
    valence: u32,
    faces: u32,
    face_point_sum: DVec3,
    midpoint_sum: DVec3,
    /// Sharp edges (sharpness > 0) and the sum of their far vertices.
    sharp: u32,
    sharp_far_sum: DVec3,
    /// Their sharpness, each at most 1, summed.
    sharp_weight_sum: f64,
    /// Edges still sharp after the step, and those that stop being sharp (with their parent sharpness).
    sharp_after: u32,
    ending_sharpness_sum: f64,
    ending: u32,
}

/// A vertex rule.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Rule {
    Smooth,
    Crease,
    Corner,
}

fn rule(sharp_edges: u32, vertex_sharpness: f64) -> Rule {
    if vertex_sharpness > 0.0 || sharp_edges > 2 {
        Rule::Corner
    } else if sharp_edges == 2 {
        Rule::Crease
    } else {
        Rule::Smooth
    }
}

impl Cage {
    /// Number of faces.
    pub fn face_count(&self) -> usize {
        self.counts.len()
    }

    /// Offsets of each face's first corner.
    fn starts(&self) -> Vec<usize> {
        let mut s = Vec::with_capacity(self.counts.len());
        let mut at = 0usize;
        for &c in &self.counts {
            s.push(at);
            at += c as usize;
        }
        s
    }

    /// The edges (each once) and, per face corner, the edge from that corner to the next.
    fn edges(&self, face_points: &[DVec3], boundary: BoundaryRule) -> (Vec<Edge>, Vec<u32>) {
        // 1. every corner's edge, bucketed by its smaller vertex (no hashing: a vertex has few edges)
        let n = self.indices.len();
        let mut ends = Vec::with_capacity(n);
        let mut start = vec![0u32; self.points.len() + 1];
        let mut at = 0usize;
        for &c in &self.counts {
            let c = c as usize;
            for k in 0..c {
                let (a, b) = key(self.indices[at + k], self.indices[at + (k + 1) % c]);
                start[a as usize + 1] += 1;
                ends.push((a, b));
            }
            at += c;
        }
        for v in 0..self.points.len() {
            start[v + 1] += start[v];
        }
        let mut fill = start.clone();
        let mut bucket = vec![0u32; n];
        for (corner, &(a, _)) in ends.iter().enumerate() {
            bucket[fill[a as usize] as usize] = corner as u32;
            fill[a as usize] += 1;
        }
        // 2. one edge per distinct (smaller, larger) pair, numbered in bucket order
        let mut edges: Vec<Edge> = Vec::with_capacity(n / 2 + 8);
        let mut corner_edge = vec![0u32; n];
        for v in 0..self.points.len() {
            let slots = &bucket[start[v] as usize..start[v + 1] as usize];
            let first_edge = edges.len();
            for &corner in slots {
                let (a, b) = ends[corner as usize];
                let e = match edges[first_edge..].iter().position(|e| e.v[1] == b) {
                    Some(k) => first_edge + k,
                    None => {
                        let sharpness = self.creases.get(&(a, b)).copied().unwrap_or(0.0);
                        edges.push(Edge { v: [a, b], faces: 0, face_point_sum: DVec3::ZERO, sharpness });
                        edges.len() - 1
                    }
                };
                corner_edge[corner as usize] = e as u32;
            }
        }
        // 3. the faces each edge borders
        let mut at = 0usize;
        for (f, &c) in self.counts.iter().enumerate() {
            for k in 0..c as usize {
                let edge = &mut edges[corner_edge[at + k] as usize];
                edge.faces += 1;
                edge.face_point_sum += face_points[f];
            }
            at += c as usize;
        }
        // boundary and non-manifold edges are infinitely sharp
        for e in &mut edges {
            if e.faces != 2 || boundary == BoundaryRule::Bilinear {
                e.sharpness = INFINITELY_SHARP;
            }
        }
        (edges, corner_edge)
    }

    /// Per-vertex sharpness: the authored corners plus what the boundary rule pins.
    fn vertex_sharpness(&self, rings: &[Ring], edges: &[Edge], rule_: BoundaryRule) -> Vec<f64> {
        let mut s = vec![0.0; self.points.len()];
        for (&v, &x) in &self.corners {
            if let Some(t) = s.get_mut(v as usize) {
                *t = x;
            }
        }
        let mut boundary_edges = vec![0u32; self.points.len()];
        for e in edges.iter().filter(|e| e.faces == 1) {
            boundary_edges[e.v[0] as usize] += 1;
            boundary_edges[e.v[1] as usize] += 1;
        }
        for (v, r) in rings.iter().enumerate() {
            let pin = match rule_ {
                BoundaryRule::EdgeOnly => false,
                BoundaryRule::EdgeAndCorner => boundary_edges[v] >= 2 && r.faces == 1,
                BoundaryRule::Linear => boundary_edges[v] > 0,
                BoundaryRule::Bilinear => true,
            };
            if pin {
                s[v] = INFINITELY_SHARP;
            }
        }
        s
    }

    fn rings(&self, edges: &[Edge], face_points: &[DVec3]) -> Vec<Ring> {
        let mut rings = vec![Ring::default(); self.points.len()];
        for e in edges {
            let [a, b] = e.v;
            let mid = (self.points[a as usize] + self.points[b as usize]) * 0.5;
            let after = decay(e.sharpness);
            for (v, far) in [(a, b), (b, a)] {
                let r = &mut rings[v as usize];
                r.valence += 1;
                r.midpoint_sum += mid;
                if e.sharpness > 0.0 {
                    r.sharp += 1;
                    r.sharp_far_sum += self.points[far as usize];
                    r.sharp_weight_sum += e.sharpness.min(1.0);
                    if after > 0.0 {
                        r.sharp_after += 1;
                    } else {
                        r.ending += 1;
                        r.ending_sharpness_sum += e.sharpness;
                    }
                }
            }
        }
        let mut at = 0usize;
        for (f, &c) in self.counts.iter().enumerate() {
            for k in 0..c as usize {
                let r = &mut rings[self.indices[at + k] as usize];
                r.faces += 1;
                r.face_point_sum += face_points[f];
            }
            at += c as usize;
        }
        rings
    }

    /// One Catmull-Clark step: every n-sided face becomes n quads (vertex, next edge's point,
    /// face point, previous edge's point), in face order, keeping the winding.
    pub fn refine(&self, boundary: BoundaryRule) -> Cage {
        let starts = self.starts();
        // 1. face points: the average of the face's vertices
        let face_points: Vec<DVec3> = self
            .counts
            .iter()
            .zip(&starts)
            .map(|(&c, &s)| {
                self.indices[s..s + c as usize].iter().map(|&v| self.points[v as usize]).sum::<DVec3>() / c as f64
            })
            .collect();
        let (edges, corner_edge) = self.edges(&face_points, boundary);
        let rings = self.rings(&edges, &face_points);
        let vsharp = self.vertex_sharpness(&rings, &edges, boundary);
        let nv = self.points.len();
        let nf = self.counts.len();
        let mut points = Vec::with_capacity(nv + edges.len() + nf);
        // 2. vertex points, by the vertex's rule before and after the step
        for (v, r) in rings.iter().enumerate() {
            let p = self.points[v];
            let smooth = if r.faces == r.valence && r.valence >= 3 {
                let n = r.valence as f64;
                (r.face_point_sum / n + 2.0 * r.midpoint_sum / n + (n - 3.0) * p) / n
            } else {
                p
            };
            let at_rule = |rl: Rule| match rl {
                Rule::Smooth => smooth,
                Rule::Crease => (r.sharp_far_sum + 6.0 * p) / 8.0,
                Rule::Corner => p,
            };
            let before = rule(r.sharp, vsharp[v]);
            let after = rule(r.sharp_after, decay(vsharp[v]));
            let q = if before == after {
                at_rule(before)
            } else {
                // the fraction of sharpness that ends in this step
                let w = if vsharp[v] > 0.0 && decay(vsharp[v]) <= 0.0 {
                    vsharp[v]
                } else if r.ending > 0 {
                    r.ending_sharpness_sum / r.ending as f64
                } else {
                    1.0
                }
                .clamp(0.0, 1.0);
                at_rule(before) * w + at_rule(after) * (1.0 - w)
            };
            points.push(q);
        }
        // 3. edge points: smooth (the ends and the two face points), sharp (the midpoint), or between
        for e in &edges {
            let (a, b) = (self.points[e.v[0] as usize], self.points[e.v[1] as usize]);
            let mid = (a + b) * 0.5;
            let q = if e.faces != 2 || e.sharpness >= 1.0 {
                mid
            } else {
                let smooth = (a + b + e.face_point_sum) * 0.25;
                smooth + (mid - smooth) * e.sharpness.max(0.0)
            };
            points.push(q);
        }
        points.extend_from_slice(&face_points);
        // 4. the quads, and what the child edges and vertices inherit
        let edge_base = nv as u32;
        let face_base = (nv + edges.len()) as u32;
        let mut counts = Vec::with_capacity(self.indices.len());
        let mut indices = Vec::with_capacity(self.indices.len() * 4);
        let mut parent = Vec::with_capacity(self.indices.len());
        for (f, (&c, &s)) in self.counts.iter().zip(&starts).enumerate() {
            let c = c as usize;
            for k in 0..c {
                let next = edge_base + corner_edge[s + k];
                let prev = edge_base + corner_edge[s + (k + c - 1) % c];
                indices.extend_from_slice(&[self.indices[s + k], next, face_base + f as u32, prev]);
                counts.push(4);
                parent.push(self.parent.get(f).copied().unwrap_or(f as u32));
            }
        }
        let mut creases = HashMap::default();
        for (i, e) in edges.iter().enumerate() {
            let s = if e.faces != 2 { 0.0 } else { decay(e.sharpness) };
            if s > 0.0 {
                let m = edge_base + i as u32;
                creases.insert(key(e.v[0], m), s);
                creases.insert(key(e.v[1], m), s);
            }
        }
        let corners = self
            .corners
            .iter()
            .filter(|(&v, _)| (v as usize) < nv)
            .map(|(&v, &s)| (v, decay(s)))
            .filter(|&(_, s)| s > 0.0)
            .collect();
        Cage { points, counts, indices, creases, corners, parent }
    }

    /// The limit position of every vertex (the cage must be all quads, as after one step).
    pub fn limit_points(&self, boundary: BoundaryRule) -> Vec<DVec3> {
        let face_points = vec![DVec3::ZERO; self.counts.len()];
        let (edges, _) = self.edges(&face_points, boundary);
        let rings = self.rings(&edges, &face_points);
        let vsharp = self.vertex_sharpness(&rings, &edges, boundary);
        // per vertex: the sum of its edge neighbours and of its quads' diagonal vertices
        let mut diag = vec![DVec3::ZERO; self.points.len()];
        let mut quads_only = true;
        let mut at = 0usize;
        for &c in &self.counts {
            if c == 4 {
                for k in 0..4 {
                    diag[self.indices[at + k] as usize] += self.points[self.indices[at + (k + 2) % 4] as usize];
                }
            } else {
                quads_only = false;
            }
            at += c as usize;
        }
        rings
            .iter()
            .enumerate()
            .map(|(v, r)| {
                let p = self.points[v];
                let smooth = if quads_only && r.faces == r.valence && r.valence >= 3 {
                    let n = r.valence as f64;
                    // edge neighbours: twice the midpoints less n·v
                    let e = 2.0 * r.midpoint_sum - n * p;
                    (n * n * p + 4.0 * e + diag[v]) / (n * (n + 5.0))
                } else {
                    p
                };
                // a sharpness below 1 left after the last level weighs the sharp limit by it
                let (sharp, w) = match rule(r.sharp, vsharp[v]) {
                    Rule::Smooth => return smooth,
                    Rule::Crease => ((r.sharp_far_sum + 4.0 * p) / 6.0, r.sharp_weight_sum / r.sharp as f64),
                    Rule::Corner if vsharp[v] > 0.0 => (p, vsharp[v].min(1.0)),
                    Rule::Corner => (p, r.sharp_weight_sum / r.sharp as f64),
                };
                sharp * w + smooth * (1.0 - w)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_cube() -> Cage {
        let points = (0..8).map(|i| DVec3::new((i & 1) as f64, (i >> 1 & 1) as f64, (i >> 2) as f64) * 2.0 - 1.0);
        Cage {
            points: points.collect(),
            counts: vec![4; 6],
            indices: vec![0, 2, 3, 1, 4, 5, 7, 6, 0, 1, 5, 4, 2, 6, 7, 3, 0, 4, 6, 2, 1, 3, 7, 5],
            ..Default::default()
        }
    }

    #[test]
    fn a_cube_refines_to_the_known_counts_and_stays_symmetric() {
        let c = unit_cube().refine(BoundaryRule::EdgeOnly);
        assert_eq!((c.points.len(), c.face_count()), (26, 24));
        let c = c.refine(BoundaryRule::EdgeOnly);
        assert_eq!((c.points.len(), c.face_count()), (98, 96));
        // an original corner after one step: (Q + 2R + (n − 3)S)/n with n = 3
        let one = unit_cube().refine(BoundaryRule::EdgeOnly);
        let corner = one.points[7];
        assert!((corner - DVec3::splat(5.0 / 9.0)).length() < 1e-12, "{corner}");
        let lim = c.limit_points(BoundaryRule::EdgeOnly);
        let r: Vec<f64> = lim.iter().map(|p| p.length()).collect();
        // the limit surface of a cube is symmetric and lies inside it
        assert!(lim.iter().all(|p| p.abs().max_element() < 1.0));
        let sum: DVec3 = lim.iter().sum();
        assert!(sum.length() < 1e-9);
        assert!(r.iter().all(|&x| x > 0.5));
    }

    #[test]
    fn infinitely_sharp_edges_of_a_cube_keep_it_a_cube() {
        let mut c = unit_cube();
        for f in 0..6 {
            for k in 0..4 {
                let (a, b) = (c.indices[f * 4 + k], c.indices[f * 4 + (k + 1) % 4]);
                c.creases.insert(key(a, b), INFINITELY_SHARP);
            }
        }
        let r = c.refine(BoundaryRule::EdgeOnly).refine(BoundaryRule::EdgeOnly);
        let lim = r.limit_points(BoundaryRule::EdgeOnly);
        // every point stays on the cube's surface
        assert!(lim.iter().all(|p| (p.abs().max_element() - 1.0).abs() < 1e-12));
    }

    #[test]
    fn a_flat_grid_stays_flat_and_linear_boundaries_stay_put() {
        // a 2×2 grid of quads in z = 0
        let points = (0..9).map(|i| DVec3::new((i % 3) as f64, (i / 3) as f64, 0.0)).collect();
        let c = Cage {
            points,
            counts: vec![4; 4],
            indices: vec![0, 1, 4, 3, 1, 2, 5, 4, 3, 4, 7, 6, 4, 5, 8, 7],
            ..Default::default()
        };
        for rule_ in [BoundaryRule::EdgeOnly, BoundaryRule::EdgeAndCorner, BoundaryRule::Linear] {
            let r = c.refine(rule_).refine(rule_);
            let lim = r.limit_points(rule_);
            assert!(lim.iter().all(|p| p.z == 0.0));
            let corner_kept = lim.iter().any(|p| p.truncate().length() < 1e-12);
            assert_eq!(corner_kept, rule_ != BoundaryRule::EdgeOnly, "{rule_:?}");
        }
        // linear boundaries: the grid's outline is unchanged
        let lim = c.refine(BoundaryRule::Linear).limit_points(BoundaryRule::Linear);
        let (lo, hi) = lim.iter().fold((DVec3::MAX, DVec3::MIN), |(a, b), p| (a.min(*p), b.max(*p)));
        assert_eq!((lo.truncate(), hi.truncate()), (glam::DVec2::ZERO, glam::DVec2::splat(2.0)));
    }
}
