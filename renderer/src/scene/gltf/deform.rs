//! Skins and morph targets: a mesh deformed by the node that uses it.
//!
//! | glTF | becomes | notes |
//! |---|---|---|
//! | morph targets (`POSITION`, `NORMAL`, `TANGENT` displacements) | added to the base attributes × the node's weights, before skinning (the spec's order) | weights: the `weights` channel's at the time asked ([`super::load_gltf_at`]), else the node's `weights`, else the mesh's, else 0; a count that differs from the targets' is padded with 0 or cut, with a warning |
//! | skin (`JOINTS_n` / `WEIGHTS_n` sets, `inverseBindMatrices`) | each vertex moved by Σ wᵢ · world(jointᵢ) · inverseBind(jointᵢ) (linear blend skinning as the spec defines it), its tangent by that matrix | the skinned node's own transform is ignored, as the spec asks; weights normalised to sum 1; a vertex with no weight keeps the node's transform (warning); a joint index out of range with a weight is an error naming the primitive and vertex |
//! | joint transforms | the joints' world matrices along their parent chain, with their animation at the time asked | Blender writes a posed armature as the joints' animation, or (exporter options "Use Current Frame" and rest position off) as their TRS; without a time, a skin whose joints are animated is a warning (the rest pose is rendered; `--frame F` renders the animation) |
//! | normals of a deformed mesh | where the file's normals are the geometry's own (corner-angle-weighted face normals within 2°, per vertex), derived again from the deformed geometry, as Blender recomputes them for the mesh Cycles renders; elsewhere (custom normals, hard edges) the spec's: morph `NORMAL` displacements, then the skin matrix's cofactor | see [`crate::scene::normals`]; coplanar flat-shaded faces turn smooth when deformed (a glTF file cannot tell them from a smooth plane) |
//! | a deformed mesh | its own [`super::super::Mesh`] per node (world space for a skin), not shared | nodes without a skin and with all weights 0 keep sharing the undeformed mesh; the copies are checked against the memory budget (~128 B per vertex) before they are made, an error naming the file and mesh |
//! | morph targets of a `KHR_draco_mesh_compression` primitive | ignored, with a warning | the extension does not carry targets; skins work (their attributes are decoded) |

use super::accessors::read_accessor;
use super::{named, Loader};
use crate::Result;
use glam::{Mat3, Mat4, Vec3};
use gltf::accessor::Dimensions;
use gltf::mesh::Semantic;

/// How one node deforms its mesh.
#[derive(Debug, Clone)]
pub(super) struct Deform {
    /// Morph target weights, one per target (the most any primitive has).
    pub weights: Vec<f32>,
    /// Per joint of the node's skin: world(joint) · inverseBind(joint); None without a skin.
    pub joints: Option<Vec<Mat4>>,
    /// The node's world transform (for vertices a skin gives no weight).
    pub node_world: Mat4,
}

/// A primitive's vertex attributes after deformation (flat floats, as read).
pub(super) struct Deformed {
    /// Positions (xyz per vertex): world space for a skin, object space otherwise.
    pub positions: Vec<f32>,
    /// Normals (xyz), same space.
    pub normals: Option<Vec<f32>>,
    /// Tangents (xyzw), same space.
    pub tangents: Option<Vec<f32>>,
    /// Per vertex, whether its skin matrix mirrors (negative determinant); empty without a skin.
    pub mirrored: Vec<bool>,
}

impl Loader<'_> {
    /// How node `node` (world transform `world`) deforms mesh `mesh`; None where it does not
    /// (no skin, every morph weight 0), so that the mesh stays shared.
    pub(super) fn deformation(
        &mut self,
        node: &gltf::Node,
        mesh: &gltf::Mesh,
        world: &Mat4,
        loc: &str,
    ) -> Result<Option<Deform>> {
        // 1. Morph weights: animated, the node's, the mesh's; one per target.
        let targets = mesh.primitives().map(|p| p.morph_targets().count()).max().unwrap_or(0);
        let (mut weights, source) = match self.animated.weights.get(&node.index()) {
            Some(w) => (w.clone(), "its weights animation"),
            None => match (node.weights(), mesh.weights()) {
                (Some(w), _) => (w.to_vec(), "the node's weights"),
                (None, Some(w)) => (w.to_vec(), "the mesh's weights"),
                (None, None) => (Vec::new(), ""),
            },
        };
        if !weights.is_empty() && weights.len() != targets {
            self.warn(
                loc,
                format!("{source} has {} values for {targets} morph targets; padded with 0 or cut", weights.len()),
            );
        }
        weights.resize(targets, 0.0);
        if weights.iter().any(|w| !w.is_finite()) {
            self.warn(loc, format!("{source} has non-finite values; those are taken as 0"));
            weights.iter_mut().filter(|w| !w.is_finite()).for_each(|w| *w = 0.0);
        }
        // 2. The skin's joint matrices (without a time, the joints' own TRS: say so where an
        //    animation moves them, since Blender writes the rest pose there).
        let joints = match node.skin() {
            Some(skin) => {
                if !self.timed {
                    let joints: Vec<usize> = skin.joints().map(|j| j.index()).collect();
                    let animated = self.doc.animations().flat_map(|a| a.channels().collect::<Vec<_>>()).any(|c| {
                        joints.contains(&c.target().node().index())
                            && c.target().property() != gltf::animation::Property::MorphTargetWeights
                    });
                    if animated {
                        self.warn(
                            loc,
                            "its skin's joints are animated but no time was asked: rendered with the joints' own \
                             transforms (Blender's exporter writes the rest pose there); --frame F renders the \
                             animation",
                        );
                    }
                }
                Some(self.joint_matrices(&skin, loc)?)
            }
            None => None,
        };
        if joints.is_none() && weights.iter().all(|&w| w == 0.0) {
            return Ok(None);
        }
        Ok(Some(Deform { weights, joints, node_world: *world }))
    }

    /// world(joint) · inverseBind(joint) for each joint of `skin`.
    fn joint_matrices(&mut self, skin: &gltf::Skin, loc: &str) -> Result<Vec<Mat4>> {
        let skin_loc = format!("{loc}, {}", named("skin", skin.index(), skin.name()));
        let joints: Vec<usize> = skin.joints().map(|j| j.index()).collect();
        let inverse_bind: Vec<Mat4> = match skin.inverse_bind_matrices() {
            None => vec![Mat4::IDENTITY; joints.len()],
            Some(acc) => {
                let what = format!("inverseBindMatrices (accessor {})", acc.index());
                if acc.dimensions() != Dimensions::Mat4 {
                    return Err(self.error(&skin_loc, format!("{what} has type {:?}, not MAT4", acc.dimensions())));
                }
                let v = read_accessor(self, &acc).map_err(|e| self.error(&skin_loc, format!("{what}: {e}")))?;
                if v.len() / 16 < joints.len() {
                    return Err(self.error(
                        &skin_loc,
                        format!("{what} has {} matrices for {} joints", v.len() / 16, joints.len()),
                    ));
                }
                v.chunks_exact(16).map(Mat4::from_cols_slice).collect()
            }
        };
        let worlds = self.node_worlds();
        let mut out = Vec::with_capacity(joints.len());
        for (k, &j) in joints.iter().enumerate() {
            let m = worlds[j] * inverse_bind[k];
            if !m.is_finite() {
                return Err(self.error(&skin_loc, format!("joint {k} (node {j}) has a non-finite matrix")));
            }
            out.push(m);
        }
        Ok(out)
    }

    /// Every node's world matrix along its parent chain (animated at the time asked), computed
    /// once. A node listed as a child of several parents takes the first.
    fn node_worlds(&mut self) -> &[Mat4] {
        if self.node_worlds.is_none() {
            let doc = self.doc;
            let nodes: Vec<gltf::Node> = doc.nodes().collect();
            let mut parent = vec![None; nodes.len()];
            for n in &nodes {
                for c in n.children() {
                    parent[c.index()].get_or_insert(n.index());
                }
            }
            let locals: Vec<Mat4> =
                nodes.iter().map(|n| self.node_matrix(n, &named("node", n.index(), n.name()))).collect();
            // parents before children: walk each chain up (no cycles: checked before the walk)
            let mut worlds: Vec<Option<Mat4>> = vec![None; nodes.len()];
            for start in 0..nodes.len() {
                let mut chain = vec![start];
                while let Some(p) = parent[*chain.last().unwrap_or(&start)] {
                    if worlds[p].is_some() || chain.len() > nodes.len() {
                        break;
                    }
                    chain.push(p);
                }
                for &i in chain.iter().rev() {
                    if worlds[i].is_none() {
                        let up = parent[i].and_then(|p| worlds[p]).unwrap_or(Mat4::IDENTITY);
                        worlds[i] = Some(up * locals[i]);
                    }
                }
            }
            self.node_worlds = Some(worlds.into_iter().map(|w| w.unwrap_or(Mat4::IDENTITY)).collect());
        }
        self.node_worlds.as_deref().unwrap_or(&[])
    }

    /// Applies `deform` to a primitive's attributes (`n` vertices): morph targets, then the
    /// skin. `draco`: the primitive is Draco-compressed (its targets are ignored).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn deform_primitive(
        &mut self,
        prim: &gltf::Primitive,
        deform: &Deform,
        draco: bool,
        mut positions: Vec<f32>,
        mut normals: Option<Vec<f32>>,
        mut tangents: Option<Vec<f32>>,
        skin_attributes: &[(Vec<f32>, Vec<f32>)],
        indices: &[u32],
        loc: &str,
    ) -> Result<Deformed> {
        let n = positions.len() / 3;
        // the rest positions and the file's normals, kept for re-deriving the normals
        let rest = normals.as_ref().map(|n| (positions.clone(), n.clone()));
        // 1. Morph targets: displacements × weights.
        if draco && prim.morph_targets().next().is_some() {
            self.warn(loc, "morph targets of a Draco-compressed primitive are not supported; ignored");
        } else {
            for (k, target) in prim.morph_targets().enumerate() {
                let w = deform.weights.get(k).copied().unwrap_or(0.0);
                if w == 0.0 {
                    continue;
                }
                let parts =
                    [("POSITION", target.positions()), ("NORMAL", target.normals()), ("TANGENT", target.tangents())];
                for (name, acc) in parts {
                    let Some(acc) = acc else { continue };
                    let what = format!("morph target {k} {name} (accessor {})", acc.index());
                    if acc.dimensions() != Dimensions::Vec3 || acc.count() != n {
                        return Err(self.error(
                            loc,
                            format!("{what} is {} × {:?}, expected {n} × Vec3", acc.count(), acc.dimensions()),
                        ));
                    }
                    let d = read_accessor(self, &acc).map_err(|e| self.error(loc, format!("{what}: {e}")))?;
                    let (base, stride) = match name {
                        "POSITION" => (Some(&mut positions), 3),
                        "NORMAL" => (normals.as_mut(), 3),
                        _ => (tangents.as_mut(), 4),
                    };
                    if let Some(base) = base {
                        for (v, dv) in base.chunks_exact_mut(stride).zip(d.chunks_exact(3)) {
                            for c in 0..3 {
                                v[c] += w * dv[c];
                            }
                        }
                    }
                }
            }
        }
        // 2. The skin: each vertex by its blended joint matrix.
        let Some(joints) = &deform.joints else {
            let normals = normals.map(|blended| rederive(&rest, &positions, blended, indices));
            return Ok(Deformed { positions, normals, tangents, mirrored: Vec::new() });
        };
        let mut mirrored = vec![false; n];
        let mut unweighted = 0usize;
        for v in 0..n {
            // 2a. Σ wᵢ · joint matrix, normalised by Σ wᵢ.
            let mut m = Mat4::ZERO;
            let mut sum = 0.0f32;
            for (set, (ids, ws)) in skin_attributes.iter().enumerate() {
                for c in 0..4 {
                    let w = ws[4 * v + c];
                    if !(w != 0.0) {
                        continue;
                    }
                    let j = ids[4 * v + c];
                    let Some(jm) = (j >= 0.0 && j.fract() == 0.0).then(|| joints.get(j as usize)).flatten() else {
                        return Err(self.error(
                            loc,
                            format!(
                                "JOINTS_{set} of vertex {v} is {j}, not a joint of the node's skin ({} joints)",
                                joints.len()
                            ),
                        ));
                    };
                    if !w.is_finite() || w < 0.0 {
                        return Err(self.error(loc, format!("WEIGHTS_{set} of vertex {v} is {w}")));
                    }
                    m += *jm * w;
                    sum += w;
                }
            }
            let m = if sum > 0.0 {
                m * (1.0 / sum)
            } else {
                unweighted += 1;
                deform.node_world
            };
            // 2b. Position, normal (cofactor: det × inverse transpose), tangent.
            let lin = Mat3::from_mat4(m);
            let det = lin.determinant();
            mirrored[v] = det < 0.0;
            let sign = if det < 0.0 { -1.0 } else { 1.0 };
            let p = m.transform_point3(Vec3::from_slice(&positions[3 * v..3 * v + 3]));
            positions[3 * v..3 * v + 3].copy_from_slice(&p.to_array());
            if let Some(nrm) = normals.as_mut() {
                let cof = normal_matrix(&lin, sign);
                let nv = (cof * Vec3::from_slice(&nrm[3 * v..3 * v + 3])).normalize_or_zero();
                nrm[3 * v..3 * v + 3].copy_from_slice(&nv.to_array());
            }
            if let Some(t) = tangents.as_mut() {
                let tv = (lin * Vec3::from_slice(&t[4 * v..4 * v + 3])).normalize_or_zero();
                t[4 * v..4 * v + 3].copy_from_slice(&tv.to_array());
                t[4 * v + 3] *= sign;
            }
        }
        let normals = normals.map(|blended| rederive(&rest, &positions, blended, indices));
        if unweighted > 0 {
            self.warn(
                loc,
                format!("{unweighted} of {n} skinned vertices have no joint weight; they keep the node's transform"),
            );
        }
        Ok(Deformed { positions, normals, tangents, mirrored })
    }

    /// A skinned primitive's `JOINTS_n` / `WEIGHTS_n` sets (four per vertex each, as floats).
    pub(super) fn skin_attributes(
        &self,
        prim: &gltf::Primitive,
        read: impl Fn(Semantic) -> Result<Option<Vec<f32>>>,
        loc: &str,
    ) -> Result<Vec<(Vec<f32>, Vec<f32>)>> {
        let mut sets = Vec::new();
        for set in 0u32.. {
            let (j, w) = (prim.get(&Semantic::Joints(set)), prim.get(&Semantic::Weights(set)));
            match (j.is_some(), w.is_some()) {
                (false, false) => break,
                (true, true) => {}
                _ => {
                    return Err(self.error(loc, format!("has one of JOINTS_{set} and WEIGHTS_{set} without the other")))
                }
            }
            let (Some(ids), Some(ws)) = (read(Semantic::Joints(set))?, read(Semantic::Weights(set))?) else { break };
            sets.push((ids, ws));
        }
        Ok(sets)
    }
}

/// The cofactor of `lin` (det × inverse transpose, defined even for singular matrices) times
/// `sign` (−1 where `lin` mirrors): what carries normals through `lin`.
pub(super) fn normal_matrix(lin: &Mat3, sign: f32) -> Mat3 {
    Mat3::from_cols(lin.y_axis.cross(lin.z_axis), lin.z_axis.cross(lin.x_axis), lin.x_axis.cross(lin.y_axis)) * sign
}

/// [`crate::scene::normals::rederive_normals`] on flat attribute arrays: `rest` = (positions,
/// the file's normals) before deformation (None without normals), `blended` the deformed
/// normals the spec gives.
fn rederive(rest: &Option<(Vec<f32>, Vec<f32>)>, deformed: &[f32], blended: Vec<f32>, indices: &[u32]) -> Vec<f32> {
    let Some((rest, file)) = rest else { return blended };
    let vecs = |a: &[f32]| a.chunks_exact(3).map(Vec3::from_slice).collect::<Vec<_>>();
    let triangles: Vec<[u32; 3]> = indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
    let mut normals = vecs(&blended);
    crate::scene::normals::rederive_normals(&vecs(rest), &vecs(file), &vecs(deformed), &mut normals, &triangles);
    normals.iter().flat_map(|n| n.to_array()).collect()
}
