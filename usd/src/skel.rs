//! UsdSkel: skinned meshes and blend shapes, posed at the time code read, with openusd's `skel`
//! toolkit (bindings, skeleton topology, animation queries) and the UsdSkel spec's linear blend
//! skinning.
//!
//! | input | handling | fallback |
//! |---|---|---|
//! | `SkelBindingAPI` on a `Mesh` inside a `SkelRoot`, `skel:skeleton` (inherited) | the mesh is skinned | no binding, no skeleton, or outside a `SkelRoot`: the mesh as authored |
//! | `Skeleton`: `joints`, `bindTransforms`, `restTransforms` | joint topology; inverse bind matrices; the pose without animation | no rest pose and no animation: not posed (warning) |
//! | `skel:animationSource` (on the skeleton, else inherited by the mesh) → `SkelAnimation` `translations`, `rotations`, `scales` | the joints' local transforms at the time code (openusd interpolates samples; rotations by slerp); joints it does not name keep their rest transform | |
//! | `primvars:skel:jointIndices` / `jointWeights` (`elementSize`, `vertex` or `constant`), `primvars:skel:geomBindTransform`, `skel:joints` | p′ = Σ wᵢ · skinning(jointᵢ) · geomBind · p (weights as authored, as UsdSkel does) | a joint index out of range, or counts that do not match the points, are errors naming the prim and attribute |
//! | `skel:blendShapes` + `skel:blendShapeTargets` → `BlendShape` `offsets`, `pointIndices`, inbetweens | added to the points before skinning, × the animation's `blendShapeWeights` of the same name (inbetweens piecewise linear) | shapes the animation does not weight: 0 |
//! | the skinned points | in the stage's world space (the skeleton's transform, not the mesh's, places them) | |
//! | normals | the authored normals by the blended skinning matrix's cofactor, then re-derived from the deformed geometry where they are the geometry's own ([`petzval_renderer::scene::normals`]), as Blender recomputes them | |
//! | `primvars:skel:skinningMethod = dualQuaternion` | skinned linearly, with a warning | |

use crate::value::{attr_error, layer_of_prim, Reader};
use crate::xform::local_xform;
use crate::Error;
use glam::{DMat3, DMat4, DVec3};
use openusd::gf;
use openusd::schemas::skel::{
    self, AnimMapper, BlendShape, InfluenceInterpolation, SkelAnimQuery, SkelBindingAPI, Skeleton, SkeletonResolver,
    SkinningMethod,
};
use openusd::{sdf, usd};

/// A mesh's points as its skeleton and blend shapes pose them.
pub struct Skinned {
    /// The deformed points: stage world space when `world_space`, else the mesh's own space.
    pub points: Vec<DVec3>,
    /// Per point, the linear part of its blended skinning transform (identity for blend
    /// shapes alone); normals go by its cofactor.
    pub linear: Vec<DMat3>,
    /// The points are in world space (skinned): the mesh's own transform does not apply.
    pub world_space: bool,
}

/// A USD row-vector matrix as glam's column-vector one (the same sixteen numbers).
fn to_glam(m: &gf::Matrix4d) -> DMat4 {
    DMat4::from_cols_array(&m.0)
}

/// glam's column-vector matrix as a USD row-vector one.
fn to_gf(m: &DMat4) -> gf::Matrix4d {
    gf::Matrix4d(m.to_cols_array())
}

/// The local-to-world transform of the prim at `path` (stage units and axes).
fn world_of(reader: &Reader, path: &sdf::Path) -> Result<DMat4, Error> {
    let mut chain = Vec::new();
    let mut p = Some(path.clone());
    while let Some(q) = p {
        if q.is_abs_root() {
            break;
        }
        p = q.parent();
        chain.push(q);
    }
    let mut world = DMat4::IDENTITY;
    for q in chain.iter().rev() {
        let local = local_xform(reader, &reader.stage.prim(q.clone()))?;
        world = if local.resets { local.matrix } else { world * local.matrix };
    }
    Ok(world)
}

/// Whether a `SkelRoot` encloses `prim` (UsdSkel applies bindings only inside one).
fn inside_skel_root(reader: &Reader, prim: &usd::Prim) -> bool {
    let mut p = prim.path().parent();
    while let Some(q) = p {
        if q.is_abs_root() {
            return false;
        }
        let ty = reader.stage.prim(q.clone()).type_name().ok().flatten();
        if ty.as_ref().is_some_and(|t| t.as_str() == "SkelRoot") {
            return true;
        }
        p = q.parent();
    }
    false
}

/// The points of mesh `prim` posed by its skeleton and blend shapes at the reader's time; None
/// when the mesh is not skinned (its points are then not read here).
pub fn skinned_points(reader: &Reader, prim: &usd::Prim, warnings: &mut Vec<String>) -> Result<Option<Skinned>, Error> {
    let stage = reader.stage;
    let path = prim.path().clone();
    let fail = |attr: &str, e: anyhow::Error| attr_error(prim, attr, format!("{e:#}"));
    // 1. The binding and its skeleton, inside a SkelRoot.
    let Some(binding) = SkelBindingAPI::get(stage, path.clone()).map_err(|e| fail("skel:skeleton", e))? else {
        return Ok(None);
    };
    let Some(skel_path) = binding.inherited_skeleton().map_err(|e| fail("skel:skeleton", e))? else {
        return Ok(None);
    };
    if !inside_skel_root(reader, prim) {
        warnings.push(format!(
            "{}: {path}: bound to a skeleton outside any SkelRoot; rendered as authored (UsdSkel poses only inside one)",
            layer_of_prim(prim)
        ));
        return Ok(None);
    }
    let skel_prim = stage.prim(skel_path.clone());
    let skel_fail = |attr: &str, e: anyhow::Error| attr_error(&skel_prim, attr, format!("{e:#}"));
    let Some(skeleton) = Skeleton::get(stage, skel_path.clone()).map_err(|e| skel_fail("joints", e))? else {
        return Err(attr_error(prim, "skel:skeleton", format!("{skel_path} is not a Skeleton")));
    };
    let resolver = SkeletonResolver::from_skeleton(&skeleton).map_err(|e| skel_fail("joints", e))?;
    let joints = resolver.joint_order().to_vec();
    let n_joints = joints.len();
    if resolver.joint_world_bind_transforms().len() != n_joints {
        return Err(attr_error(
            &skel_prim,
            "bindTransforms",
            format!("has {} matrices for {n_joints} joints", resolver.joint_world_bind_transforms().len()),
        ));
    }
    // 2. The animation: on the skeleton, else inherited by the mesh.
    let skel_binding =
        SkelBindingAPI::get(stage, skel_path.clone()).map_err(|e| skel_fail("skel:animationSource", e))?;
    let anim_path = match skel_binding {
        Some(b) => b.inherited_animation_source().map_err(|e| skel_fail("skel:animationSource", e))?,
        // files written before SkelBindingAPI had to be applied author the relationship alone
        None => skel_prim
            .relationship("skel:animationSource")
            .targets()
            .map_err(|e| skel_fail("skel:animationSource", e))?
            .into_iter()
            .next(),
    };
    let anim_path = match anim_path {
        Some(p) => Some(p),
        None => binding.inherited_animation_source().map_err(|e| fail("skel:animationSource", e))?,
    };
    let anim = match &anim_path {
        Some(p) => SkelAnimQuery::new(stage, p.clone()).map_err(|e| skel_fail("skel:animationSource", e))?,
        None => None,
    };
    let time = reader.time.map(usd::TimeCode::new).unwrap_or(usd::TimeCode::EARLIEST);
    // 3. Blend shapes, in the mesh's space.
    let mut posed = reader.vec3s(prim, "points")?.unwrap_or_default();
    let shape_names = binding.blend_shapes().map_err(|e| fail("skel:blendShapes", e))?;
    if !shape_names.is_empty() {
        let targets = binding.blend_shape_targets().map_err(|e| fail("skel:blendShapeTargets", e))?;
        if targets.len() != shape_names.len() {
            return Err(attr_error(
                prim,
                "skel:blendShapeTargets",
                format!("has {} targets for {} skel:blendShapes", targets.len(), shape_names.len()),
            ));
        }
        let weights = match &anim {
            Some(a) => {
                let w = a.compute_blend_shape_weights(stage, time).map_err(|e| skel_fail("blendShapeWeights", e))?;
                a.blend_shape_order().iter().cloned().zip(w).collect::<Vec<_>>()
            }
            None => Vec::new(),
        };
        for (name, target) in shape_names.iter().zip(&targets) {
            let w = weights.iter().find(|(n, _)| n == name).map_or(0.0, |(_, w)| *w);
            if w == 0.0 || !w.is_finite() {
                continue;
            }
            apply_blend_shape(reader, prim, target, w, &mut posed)?;
        }
    }
    if let Some(p) = posed.iter().find(|p| !p.is_finite()) {
        return Err(attr_error(prim, "skel:blendShapes", format!("a point with its blend shapes is not finite: {p}")));
    }
    // 4. The joints' local transforms at the time: the animation's where it names the joint,
    //    else the rest pose.
    let rest = resolver.rest_pose_local();
    let animated = match &anim {
        Some(a) if !a.joint_order().is_empty() => {
            let local =
                a.compute_joint_local_transforms(stage, time).map_err(|e| skel_fail("skel:animationSource", e))?;
            Some((AnimMapper::new(a.joint_order(), &joints), local))
        }
        _ => None,
    };
    if animated.is_none() && rest.len() != n_joints {
        warnings.push(format!(
            "{}: {skel_path}: no restTransforms and no animation: the skeleton does not pose {path} (its blend shapes still apply)",
            layer_of_prim(&skel_prim)
        ));
        let linear = vec![DMat3::IDENTITY; posed.len()];
        return Ok(Some(Skinned { points: posed, linear, world_space: false }));
    }
    let local: Vec<gf::Matrix4d> = (0..n_joints)
        .map(|j| {
            let from_anim = animated.as_ref().and_then(|(map, local)| map.source_index(j).and_then(|k| local.get(k)));
            from_anim.or(rest.get(j)).copied().unwrap_or(gf::Matrix4d::IDENTITY)
        })
        .collect();
    // 5. Skinning transforms in world space (inverse bind · joint world), in the mesh's order.
    let skel_world = world_of(reader, &skel_path)?;
    let skinning = resolver.compute_skinning_transforms_from_local(&local, to_gf(&skel_world));
    let subset = binding.joint_subset().map_err(|e| fail("skel:joints", e))?;
    let mesh_xforms: Vec<DMat4> = if subset.is_empty() {
        skinning.iter().map(to_glam).collect()
    } else {
        let map = AnimMapper::new(&joints, &subset);
        (0..subset.len()).map(|k| map.source_index(k).map_or(DMat4::IDENTITY, |j| to_glam(&skinning[j]))).collect()
    };
    // 6. Linear blend skinning.
    if binding.skinning_method().map_err(|e| fail("primvars:skel:skinningMethod", e))? == SkinningMethod::DualQuaternion
    {
        warnings.push(format!(
            "{}: {path}: dual-quaternion skinning is not supported; skinned linearly",
            layer_of_prim(prim)
        ));
    }
    let indices = binding.joint_indices().map_err(|e| fail("primvars:skel:jointIndices", e))?;
    let weights = binding.joint_weights().map_err(|e| fail("primvars:skel:jointWeights", e))?;
    let per = binding.elements_per_element().map_err(|e| fail("primvars:skel:jointIndices", e))?.max(1) as usize;
    let constant =
        binding.interpolation().map_err(|e| fail("primvars:skel:jointIndices", e))? == InfluenceInterpolation::Constant;
    let need = if constant { per } else { per * posed.len() };
    if indices.len() != need || weights.len() != need {
        return Err(attr_error(
            prim,
            "primvars:skel:jointIndices",
            format!(
                "has {} indices and {} weights; {need} needed ({} per {})",
                indices.len(),
                weights.len(),
                per,
                if constant { "mesh (constant)" } else { "point" }
            ),
        ));
    }
    if let Some(k) =
        indices.iter().zip(&weights).position(|(&j, &w)| w != 0.0 && (j < 0 || j as usize >= mesh_xforms.len()))
    {
        return Err(attr_error(
            prim,
            "primvars:skel:jointIndices",
            format!("entry {k} is joint {}, outside the {} joints bound", indices[k], mesh_xforms.len()),
        ));
    }
    if let Some(w) = weights.iter().find(|w| !w.is_finite()) {
        return Err(attr_error(prim, "primvars:skel:jointWeights", format!("a weight is not finite: {w}")));
    }
    let geom_bind = binding.geom_bind_transform().map_err(|e| fail("primvars:skel:geomBindTransform", e))?;
    let geom_bind = geom_bind.as_ref().map_or(DMat4::IDENTITY, to_glam);
    let blended = |i: usize| {
        let base = if constant { 0 } else { i * per };
        (base..base + per)
            .filter(|&k| weights[k] != 0.0)
            .fold(DMat4::ZERO, |m, k| m + mesh_xforms[indices[k] as usize] * weights[k] as f64)
            * geom_bind
    };
    let mut linear = Vec::with_capacity(posed.len());
    for (i, p) in posed.iter_mut().enumerate() {
        let m = blended(i);
        *p = m.transform_point3(*p);
        linear.push(DMat3::from_mat4(m));
    }
    if let Some(p) = posed.iter().find(|p| !p.is_finite()) {
        return Err(attr_error(prim, "points", format!("a skinned point is not finite: {p}")));
    }
    Ok(Some(Skinned { points: posed, linear, world_space: true }))
}

/// Adds blend shape `target` (the prim's `skel:blendShapeTargets` entry) × `w` to `points`.
fn apply_blend_shape(
    reader: &Reader,
    prim: &usd::Prim,
    target: &sdf::Path,
    w: f32,
    points: &mut [DVec3],
) -> Result<(), Error> {
    let shape_prim = reader.stage.prim(target.clone());
    let bad = |attr: &str, m: String| attr_error(&shape_prim, attr, m);
    let Some(shape) = BlendShape::get(reader.stage, target.clone()).map_err(|e| bad("offsets", format!("{e:#}")))?
    else {
        return Err(attr_error(prim, "skel:blendShapeTargets", format!("{target} is not a BlendShape")));
    };
    let offsets = shape.offsets().map_err(|e| bad("offsets", format!("{e:#}")))?;
    let point_indices = shape.point_indices().map_err(|e| bad("pointIndices", format!("{e:#}")))?;
    let inbetweens = shape.inbetweens().map_err(|e| bad("inbetweens", format!("{e:#}")))?;
    let pairs: Vec<(f32, &[gf::Vec3f])> =
        inbetweens.iter().filter_map(|b| b.weight.map(|wt| (wt, b.offsets.as_slice()))).collect();
    let offsets =
        if pairs.is_empty() { offsets } else { skel::skinning::resolve_blend_shape_offsets(w, &pairs, &offsets) };
    let scale = if pairs.is_empty() { w } else { 1.0 };
    let targets: Vec<usize> = if point_indices.is_empty() {
        if offsets.len() != points.len() {
            return Err(bad(
                "offsets",
                format!("has {} offsets for {} points (no pointIndices)", offsets.len(), points.len()),
            ));
        }
        (0..points.len()).collect()
    } else {
        if point_indices.len() != offsets.len() {
            return Err(bad(
                "pointIndices",
                format!("has {} indices for {} offsets", point_indices.len(), offsets.len()),
            ));
        }
        if let Some(i) = point_indices.iter().find(|&&i| i < 0 || i as usize >= points.len()) {
            return Err(bad("pointIndices", format!("index {i} is outside the {} points", points.len())));
        }
        point_indices.iter().map(|&i| i as usize).collect()
    };
    for (&i, o) in targets.iter().zip(&offsets) {
        points[i] += DVec3::new(o.x as f64, o.y as f64, o.z as f64) * scale as f64;
    }
    Ok(())
}
