//! The node hierarchy: transforms, meshes and their primitives, lights and cameras.

use super::accessors::read_accessor;
use super::deform::{normal_matrix, Deform};
use super::{named, Loader, WATTS_TO_LUMENS};
use crate::limits::MAX_NODE_INSTANCES;
use crate::scene::{Light, Mesh, SceneCamera, SpotFalloff};
use crate::{Error, Result};
use glam::{Affine3A, Mat3, Mat4, Quat, Vec2, Vec3, Vec4};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::{Mode, Semantic};

impl Loader<'_> {
    // ---------------------------------------------------------------- node hierarchy

    pub(super) fn walk_nodes(&mut self) -> Result<()> {
        self.check_node_cycles()?;
        let roots: Vec<usize> = match self.doc.default_scene().or_else(|| self.doc.scenes().next()) {
            Some(s) => s.nodes().map(|n| n.index()).collect(),
            None => {
                let n = self.doc.nodes().count();
                let mut is_child = vec![false; n];
                for node in self.doc.nodes() {
                    for c in node.children() {
                        if let Some(slot) = is_child.get_mut(c.index()) {
                            *slot = true;
                        }
                    }
                }
                let roots: Vec<usize> = (0..n).filter(|&i| !is_child[i]).collect();
                if !roots.is_empty() {
                    self.warn("", "the file has no scene; using every root node");
                }
                roots
            }
        };
        let doc = self.doc;
        let nodes: Vec<gltf::Node> = doc.nodes().collect();
        let mut stack: Vec<(usize, Mat4)> = roots.into_iter().rev().map(|i| (i, Mat4::IDENTITY)).collect();
        let mut instances = 0usize;
        while let Some((index, parent)) = stack.pop() {
            instances += 1;
            if instances > MAX_NODE_INSTANCES {
                return Err(self.error("", "node hierarchy expands to too many node instances (shared subtrees)"));
            }
            let Some(node) = nodes.get(index).cloned() else { continue };
            let loc = named("node", index, node.name());
            let local = self.node_matrix(&node, &loc);
            let world = parent * local;
            if let Some(mesh) = node.mesh() {
                // A skin or morph weights: the mesh deformed for this node (`deform.rs`).
                let deform = self.deformation(&node, &mesh, &world, &loc)?;
                let id = match &deform {
                    Some(d) => self.read_deformed_mesh(&mesh, d)?,
                    None => self.shared_mesh(&mesh)?,
                };
                match self.gpu_instances(&node, &loc)? {
                    // A skinned mesh is in world space already (the node's transform ignored).
                    _ if deform.as_ref().is_some_and(|d| d.joints.is_some()) => {
                        if node.extension_value("EXT_mesh_gpu_instancing").is_some() {
                            self.warn(&loc, "EXT_mesh_gpu_instancing on a skinned mesh is not supported; ignored");
                        }
                        self.place_mesh(id, &mesh, &Mat4::IDENTITY);
                    }
                    // EXT_mesh_gpu_instancing: the mesh once per instance, the node's
                    // transform applied after the instance's.
                    Some(locals) => {
                        instances += locals.len();
                        if instances > MAX_NODE_INSTANCES {
                            return Err(self.error(&loc, "EXT_mesh_gpu_instancing: too many instances"));
                        }
                        for m in locals {
                            self.place_mesh(id, &mesh, &(world * m));
                        }
                    }
                    None => self.place_mesh(id, &mesh, &world),
                }
            }
            if let Some(light) = node.light() {
                self.add_light(&light, &world, &loc);
            }
            if let Some(camera) = node.camera() {
                self.add_camera(&camera, &world, &node, &loc);
            }
            for c in node.children().collect::<Vec<_>>().into_iter().rev() {
                stack.push((c.index(), world));
            }
        }
        Ok(())
    }

    /// The instance transforms of a node's `EXT_mesh_gpu_instancing` (None without it): per
    /// instance T · R · S from its `TRANSLATION`, `ROTATION` (unit quaternion, float or
    /// normalized integers) and `SCALE` attributes, each optional (0, identity, 1); attributes
    /// whose names start with `_` (application data) are ignored. A missing or malformed
    /// attribute is an error naming the node; a rotation of length zero or a non-finite
    /// instance is skipped with a warning.
    fn gpu_instances(&mut self, node: &gltf::Node, loc: &str) -> Result<Option<Vec<Mat4>>> {
        const EXT: &str = "EXT_mesh_gpu_instancing";
        let Some(ext) = node.extension_value(EXT) else { return Ok(None) };
        let file = self.file.clone();
        let fail = |what: String| Error::scene(&file, loc, format!("{EXT}: {what}"));
        let Some(attributes) = ext.get("attributes").and_then(|a| a.as_object()) else {
            return Err(fail("has no `attributes` object".into()));
        };
        // 1. Each attribute's values (VEC3 for translation and scale, VEC4 for rotation).
        let read = |name: &str, dims: Dimensions| -> Result<Option<Vec<f32>>> {
            let Some(v) = attributes.get(name) else { return Ok(None) };
            let index = v.as_u64().ok_or_else(|| fail(format!("attribute {name} is not an accessor index")))?;
            let acc = self
                .doc
                .accessors()
                .nth(index as usize)
                .ok_or_else(|| fail(format!("attribute {name}: accessor {index} does not exist")))?;
            if acc.dimensions() != dims {
                return Err(fail(format!(
                    "attribute {name}: accessor {index} is {:?}, not {dims:?}",
                    acc.dimensions()
                )));
            }
            read_accessor(self, &acc).map(Some).map_err(|e| fail(format!("attribute {name}: accessor {index}: {e}")))
        };
        let translation = read("TRANSLATION", Dimensions::Vec3)?;
        let rotation = read("ROTATION", Dimensions::Vec4)?;
        let scale = read("SCALE", Dimensions::Vec3)?;
        for name in attributes.keys() {
            if !name.starts_with('_') && !["TRANSLATION", "ROTATION", "SCALE"].contains(&name.as_str()) {
                self.warn(loc, format!("{EXT}: attribute {name} is not supported and is ignored"));
            }
        }
        // 2. One instance count for all of them.
        let counts = [(&translation, 3), (&rotation, 4), (&scale, 3)].map(|(v, n)| v.as_ref().map(|v| v.len() / n));
        let Some(count) = counts.iter().flatten().next().copied() else {
            return Err(fail("has none of the attributes TRANSLATION, ROTATION and SCALE".into()));
        };
        if counts.iter().flatten().any(|&c| c != count) {
            return Err(fail(format!(
                "its attributes have different counts ({counts:?}: translation, rotation, scale)"
            )));
        }
        // 3. T · R · S per instance.
        let mut out = Vec::with_capacity(count);
        let mut skipped = 0usize;
        for i in 0..count {
            let t = translation.as_ref().map_or(Vec3::ZERO, |v| Vec3::from_slice(&v[3 * i..3 * i + 3]));
            let q = rotation.as_ref().map_or(Quat::IDENTITY, |v| Quat::from_slice(&v[4 * i..4 * i + 4]));
            let s = scale.as_ref().map_or(Vec3::ONE, |v| Vec3::from_slice(&v[3 * i..3 * i + 3]));
            if !(t.is_finite() && s.is_finite() && q.is_finite() && q.length_squared() > 1e-12) {
                skipped += 1;
                continue;
            }
            out.push(Mat4::from_scale_rotation_translation(s, q.normalize(), t));
        }
        if skipped > 0 {
            self.warn(
                loc,
                format!("{EXT}: {skipped} of {count} instances have a non-finite or zero transform; skipped"),
            );
        }
        Ok(Some(out))
    }

    /// Fails if a node is (indirectly) its own descendant.
    pub(super) fn check_node_cycles(&self) -> Result<()> {
        let children: Vec<Vec<usize>> = self.doc.nodes().map(|n| n.children().map(|c| c.index()).collect()).collect();
        let n = children.len();
        // 0 = unvisited, 1 = on the current path, 2 = done.
        let mut state = vec![0u8; n];
        for start in 0..n {
            if state[start] != 0 {
                continue;
            }
            let mut stack: Vec<(usize, usize)> = vec![(start, 0)];
            state[start] = 1;
            while let Some(&mut (node, ref mut next)) = stack.last_mut() {
                if let Some(&child) = children[node].get(*next) {
                    *next += 1;
                    match state.get(child).copied() {
                        Some(0) => {
                            state[child] = 1;
                            stack.push((child, 0));
                        }
                        Some(1) => {
                            let name = self.doc.nodes().nth(child).and_then(|c| c.name().map(str::to_string));
                            return Err(self.error(
                                &named("node", child, name.as_deref()),
                                "node hierarchy has a cycle (a node is its own ancestor)",
                            ));
                        }
                        _ => {}
                    }
                } else {
                    state[node] = 2;
                    stack.pop();
                }
            }
        }
        Ok(())
    }

    pub(super) fn node_matrix(&mut self, node: &gltf::Node, loc: &str) -> Mat4 {
        match node.transform() {
            gltf::scene::Transform::Matrix { matrix } => {
                let m = Mat4::from_cols_array_2d(&matrix);
                if !m.is_finite() {
                    self.warn(loc, "matrix is not finite; using identity");
                    return Mat4::IDENTITY;
                }
                m
            }
            gltf::scene::Transform::Decomposed { translation, rotation, scale } => {
                // the animated parts at the time asked, where the node is animated
                let anim = self.animated.trs.get(&node.index()).copied().unwrap_or_default();
                let mut t = anim.translation.unwrap_or(Vec3::from_array(translation));
                let mut s = anim.scale.unwrap_or(Vec3::from_array(scale));
                let mut q = anim.rotation.unwrap_or(Quat::from_array(rotation));
                if !t.is_finite() {
                    self.warn(loc, "translation is not finite; using 0");
                    t = Vec3::ZERO;
                }
                if !s.is_finite() {
                    self.warn(loc, "scale is not finite; using 1");
                    s = Vec3::ONE;
                }
                if !q.is_finite() || q.length_squared() < 1e-12 {
                    self.warn(loc, "rotation is not a valid quaternion; using identity");
                    q = Quat::IDENTITY;
                }
                Mat4::from_scale_rotation_translation(s, q.normalize(), t)
            }
        }
    }

    // ---------------------------------------------------------------- lights and cameras

    /// The value of the one-float property at JSON `pointer` at the time asked, where a
    /// KHR_animation_pointer channel animates it; else `own`.
    fn pointer_value(&self, pointer: &str, own: f32) -> f32 {
        match self.animated.pointers.get(pointer) {
            Some(v) if v.len() == 1 => v[0],
            _ => own,
        }
    }

    pub(super) fn add_light(&mut self, light: &gltf::khr_lights_punctual::Light, world: &Mat4, node_loc: &str) {
        let loc = format!("{node_loc}, {}", named("light", light.index(), light.name()));
        // A property animated through KHR_animation_pointer takes its value at the time asked.
        let key = |prop: &str| format!("/extensions/KHR_lights_punctual/lights/{}/{prop}", light.index());
        let animated = |prop: &str, v: f32| self.pointer_value(&key(prop), v);
        let color = match self.animated.pointers.get(&key("color")) {
            Some(c) if c.len() == 3 => Vec3::from_slice(c),
            _ => Vec3::from_array(light.color()),
        };
        let intensity = match self.animated.pointers.get(&key("intensity")) {
            Some(v) if v.len() == 1 => {
                // Blender 5.0's exporter writes animated intensities without part of the
                // conversion its static ones have (`exp/animation/sampled/data/keyframes.py`
                // against `exp/lights.py`): point and spot lights as W·683 (no 1/4π), suns as
                // W/m² (no ·683); other files as the spec's units.
                let blender = match light.kind() {
                    _ if !self.blender_written => 1.0,
                    gltf::khr_lights_punctual::Kind::Directional => WATTS_TO_LUMENS,
                    _ => 1.0 / (4.0 * std::f32::consts::PI),
                };
                v[0] * blender
            }
            _ => light.intensity(),
        };
        if !color.is_finite() || !intensity.is_finite() || color.min_element() < 0.0 || intensity < 0.0 {
            self.warn(&loc, "colour or intensity is negative or not finite; light skipped");
            return;
        }
        let radiometric = color * intensity / WATTS_TO_LUMENS;
        if !radiometric.is_finite() {
            // each finite, their product not (found by the fuzzing of issue 12)
            self.warn(&loc, "colour × intensity is not finite; light skipped");
            return;
        }
        let position = world.w_axis.truncate();
        let dir = world.transform_vector3(Vec3::NEG_Z);
        let range = light.range().map(|r| animated("range", r)).filter(|r| r.is_finite() && *r > 0.0);
        let needs_dir = !matches!(light.kind(), gltf::khr_lights_punctual::Kind::Point);
        if !position.is_finite() || (needs_dir && !(dir.is_finite() && dir.length_squared() > 0.0)) {
            self.warn(&loc, "node transform is degenerate or not finite; light skipped");
            return;
        }
        let direction = dir.normalize_or_zero();
        let l = match light.kind() {
            gltf::khr_lights_punctual::Kind::Point => {
                Light::Point { position, intensity: radiometric, range, radius_m: 0.0, sphere: false }
            }
            gltf::khr_lights_punctual::Kind::Directional => {
                Light::Directional { direction, irradiance: radiometric, angle_rad: 0.0 }
            }
            gltf::khr_lights_punctual::Kind::Spot { inner_cone_angle, outer_cone_angle } => {
                let mut outer = animated("spot.outerConeAngle", outer_cone_angle);
                let mut inner = match self.animated.pointers.get(&key("spot.innerConeAngle")) {
                    // Blender 5.0 writes the animated Spot Blend there (see `blender_5_0`)
                    Some(v) if v.len() == 1 && self.blender_5_0 => outer * (1.0 - v[0].clamp(0.0, 1.0)),
                    Some(v) if v.len() == 1 => v[0],
                    _ => inner_cone_angle,
                };
                if !outer.is_finite() || outer <= 0.0 || outer > std::f32::consts::FRAC_PI_2 {
                    self.warn(&loc, format!("outerConeAngle {outer} is outside (0, π/2]; clamped"));
                    outer = if outer.is_finite() {
                        outer.clamp(1e-4, std::f32::consts::FRAC_PI_2)
                    } else {
                        std::f32::consts::FRAC_PI_4
                    };
                }
                // inner = outer (outside the spec's [0, outer)) is what Blender's exporter writes
                // for a hard-edged spot (blend 0): taken as that, a step at the outer cone
                // (see integrator::spot_attenuation), without a warning.
                if !inner.is_finite() || inner < 0.0 || inner > outer {
                    self.warn(&loc, format!("innerConeAngle {inner} is outside [0, outerConeAngle]; clamped"));
                    inner = if inner.is_finite() { inner.clamp(0.0, outer) } else { 0.0 };
                }
                Light::Spot {
                    position,
                    direction,
                    intensity: radiometric,
                    inner_cone_rad: inner,
                    outer_cone_rad: outer,
                    range,
                    // Blender's exporter writes Spot Blend as inner = outer·(1 − blend); its
                    // files get Cycles' smoothstep (what Blender renders), others the spec's ramp.
                    falloff: if self.blender_written { SpotFalloff::Blender } else { SpotFalloff::Gltf },
                    radius_m: 0.0,
                    sphere: false,
                }
            }
        };
        self.scene.lights.push(l);
    }

    pub(super) fn add_camera(&mut self, camera: &gltf::Camera, world: &Mat4, node: &gltf::Node, node_loc: &str) {
        let loc = format!("{node_loc}, {}", named("camera", camera.index(), camera.name()));
        // Perspective: the vertical field of view; orthographic: the larger side's extent,
        // 2·max(xmag, ymag), as Blender's importer reads it back into its Orthographic Scale.
        // A property animated through KHR_animation_pointer takes its value at the time asked.
        let animated = |prop: &str, v: f32| self.pointer_value(&format!("/cameras/{}/{prop}", camera.index()), v);
        let (yfov, ortho_scale_m, aspect_ratio, znear, zfar) = match camera.projection() {
            gltf::camera::Projection::Perspective(p) => {
                let yfov = animated("perspective/yfov", p.yfov());
                let (znear, zfar) =
                    (animated("perspective/znear", p.znear()), p.zfar().map(|z| animated("perspective/zfar", z)));
                if !yfov.is_finite() || yfov <= 0.0 || yfov >= std::f32::consts::PI {
                    self.warn(&loc, format!("yfov {yfov} is outside (0, π); camera skipped"));
                    return;
                }
                (yfov, None, p.aspect_ratio().filter(|a| a.is_finite() && *a > 0.0), znear, zfar)
            }
            gltf::camera::Projection::Orthographic(o) => {
                let (xmag, ymag) =
                    (animated("orthographic/xmag", o.xmag()).abs(), animated("orthographic/ymag", o.ymag()).abs());
                if !(xmag.is_finite() && ymag.is_finite() && xmag > 0.0 && ymag > 0.0) {
                    self.warn(
                        &loc,
                        format!("orthographic xmag {} / ymag {} must be non-zero; camera skipped", o.xmag(), o.ymag()),
                    );
                    return;
                }
                let (znear, zfar) =
                    (animated("orthographic/znear", o.znear()), animated("orthographic/zfar", o.zfar()));
                (0.5, Some(2.0 * xmag.max(ymag)), Some(xmag / ymag), znear, Some(zfar))
            }
        };
        // Rigid part: keep the viewing direction (−z) exactly, make +y orthogonal to it.
        let position = world.w_axis.truncate();
        let back = world.transform_vector3(Vec3::Z);
        let up = world.transform_vector3(Vec3::Y);
        let z = back.normalize_or_zero();
        let y = (up - z * up.dot(z)).normalize_or_zero();
        let x = y.cross(z);
        if !position.is_finite() || z == Vec3::ZERO || y == Vec3::ZERO || !x.is_finite() {
            self.warn(&loc, "node transform is degenerate or not finite; camera skipped");
            return;
        }
        let to_world = Affine3A::from_mat3_translation(Mat3::from_cols(x, y, z), position);
        let name = node
            .name()
            .filter(|n| !n.is_empty())
            .or(camera.name().filter(|n| !n.is_empty()))
            .map(str::to_string)
            .unwrap_or_else(|| format!("camera {}", camera.index()));
        let mut znear = znear;
        if !znear.is_finite() || znear < 0.0 {
            self.warn(&loc, format!("znear {znear} is invalid; using 0"));
            znear = 0.0;
        }
        let zfar = zfar.filter(|f| f.is_finite() && *f > znear);
        self.scene.cameras.push(SceneCamera {
            name,
            to_world,
            yfov_rad: yfov,
            aspect_ratio,
            ortho_scale_m,
            znear,
            zfar,
        });
    }

    // ---------------------------------------------------------------- meshes

    /// glTF mesh `mesh` undeformed, read once (object space, all its triangle primitives in one
    /// [`Mesh`]) and shared by every node using it; None when it has no triangles.
    fn shared_mesh(&mut self, mesh: &gltf::Mesh) -> Result<Option<u32>> {
        if let Some(&id) = self.mesh_ids.get(&mesh.index()) {
            return Ok(id);
        }
        let m = self.read_mesh(mesh, None)?;
        let id = (!m.indices.is_empty()).then(|| self.scene.add_mesh(m));
        self.mesh_ids.insert(mesh.index(), id);
        Ok(id)
    }

    /// glTF mesh `mesh` as `deform` deforms it (one node's own copy); None without triangles.
    fn read_deformed_mesh(&mut self, mesh: &gltf::Mesh, deform: &Deform) -> Result<Option<u32>> {
        // Each deformed node holds its own copy: a file that deforms one large mesh for many
        // nodes is refused before the copies exhaust memory (~128 B per vertex with the
        // loader's temporaries).
        let vertices: u64 =
            mesh.primitives().filter_map(|p| p.get(&Semantic::Positions)).map(|a| a.count() as u64).sum();
        self.deformed_bytes = self.deformed_bytes.saturating_add(vertices.saturating_mul(128));
        if let Err(budget) = crate::limits::check_memory(self.deformed_bytes) {
            return Err(self.error(
                &named("mesh", mesh.index(), mesh.name()),
                format!(
                    "the skinned or morphed copies of the file's meshes need {}, {}",
                    crate::limits::format_bytes(self.deformed_bytes),
                    crate::limits::over_budget(budget)
                ),
            ));
        }
        let m = self.read_mesh(mesh, Some(deform))?;
        Ok((!m.indices.is_empty()).then(|| self.scene.add_mesh(m)))
    }

    /// An instance of scene mesh `id` (glTF mesh `mesh`, for messages) placed by `world`.
    fn place_mesh(&mut self, id: Option<u32>, mesh: &gltf::Mesh, world: &Mat4) {
        let Some(id) = id else { return };
        if !world.is_finite() {
            // a chain of finite node transforms can still overflow f32 (issue 12's fuzzing)
            self.warn(&named("mesh", mesh.index(), mesh.name()), "its node's world transform is not finite; skipped");
            return;
        }
        self.scene.add_instance(id, Affine3A::from_mat4(*world));
    }

    fn read_mesh(&mut self, mesh: &gltf::Mesh, deform: Option<&Deform>) -> Result<Mesh> {
        let mesh_loc = named("mesh", mesh.index(), mesh.name());
        let mut out = Mesh::default();
        for prim in mesh.primitives() {
            let loc = format!("{mesh_loc}, primitive {}", prim.index());
            if prim.mode() != Mode::Triangles {
                self.warn(&loc, format!("mode {:?} is not supported (triangles only); skipped", prim.mode()));
                continue;
            }
            let material = match prim.material().index() {
                Some(i) if i < self.scene.materials.len() => i as u32,
                _ => self.default_material(),
            };
            let m = self.read_primitive(&prim, &Mat4::IDENTITY, material, &loc, deform)?;
            out.append(&m, 0);
        }
        Ok(out)
    }

    /// A primitive's attribute as floats (`count` elements if given), read from its decoded
    /// Draco mesh where it has one and the attribute is compressed.
    #[allow(clippy::too_many_arguments)]
    fn attribute_f32(
        &self,
        prim: &gltf::Primitive,
        draco: Option<&Draco>,
        semantic: Semantic,
        dims: Dimensions,
        count: Option<usize>,
        loc: &str,
    ) -> Result<Option<Vec<f32>>> {
        let Some(acc) = prim.get(&semantic) else { return Ok(None) };
        let what = format!("attribute {semantic:?} (accessor {})", acc.index());
        if acc.dimensions() != dims {
            return Err(self.error(loc, format!("{what} has type {:?}, expected {dims:?}", acc.dimensions())));
        }
        if let Some(n) = count {
            if acc.count() != n {
                return Err(self.error(loc, format!("{what} has {} elements but POSITION has {n}", acc.count())));
            }
        }
        if let Some(d) = draco {
            if let Some(v) = d.values(&semantic.to_string(), &acc, dims.multiplicity()) {
                return v.map(Some).map_err(|m| self.error(loc, format!("{what}: {m}")));
            }
        }
        read_accessor(self, &acc).map(Some).map_err(|m| self.error(loc, format!("{what}: {m}")))
    }

    /// The primitive's `KHR_draco_mesh_compression` data, decoded; None without the extension.
    fn decode_draco(&self, prim: &gltf::Primitive, loc: &str) -> Result<Option<Draco>> {
        let Some(ext) = prim.extension_value("KHR_draco_mesh_compression") else { return Ok(None) };
        let err = |m: String| self.error(loc, format!("KHR_draco_mesh_compression: {m}"));
        let view = ext
            .get("bufferView")
            .and_then(|v| v.as_u64())
            .and_then(|v| self.doc.views().nth(v as usize))
            .ok_or_else(|| err("no valid bufferView".into()))?;
        let mut ids = std::collections::HashMap::new();
        if let Some(map) = ext.get("attributes").and_then(|a| a.as_object()) {
            for (name, id) in map {
                let id = id.as_u64().filter(|&i| i <= u32::MAX as u64);
                ids.insert(
                    name.clone(),
                    id.ok_or_else(|| err(format!("attribute {name}: not a Draco attribute id")))? as u32,
                );
            }
        }
        let bytes = self.view_bytes(&view).map_err(err)?;
        // at most 64 M points and 1 GiB of decoded attributes (a corrupt stream may claim more)
        let limits = draco_core::DecodeLimits::default()
            .with_max_points(1 << 26)
            .with_max_faces(1 << 27)
            .with_max_decoded_bytes(1 << 30);
        let mut buffer = draco_core::DecoderBuffer::new(bytes).with_limits(limits);
        let mut mesh = draco_core::Mesh::new();
        draco_core::MeshDecoder::new()
            .decode(&mut buffer, &mut mesh)
            .map_err(|e| err(format!("cannot decode the compressed mesh: {e}")))?;
        Ok(Some(Draco { mesh, ids }))
    }

    /// `COLOR_0` (VEC3 or VEC4; floats or normalized integers) as linear RGBA, each channel
    /// clamped to [0, 1] as the spec bounds it; a non-finite colour is white.
    fn vertex_colors(
        &self,
        prim: &gltf::Primitive,
        d: Option<&Draco>,
        n: usize,
        loc: &str,
    ) -> Result<Option<Vec<Vec4>>> {
        let Some(acc) = prim.get(&Semantic::Colors(0)) else { return Ok(None) };
        let dims = acc.dimensions();
        let k = match dims {
            Dimensions::Vec3 => 3,
            Dimensions::Vec4 => 4,
            d => {
                return Err(self.error(
                    loc,
                    format!("attribute COLOR_0 (accessor {}) has type {d:?}, expected Vec3 or Vec4", acc.index()),
                ))
            }
        };
        let v = self.attribute_f32(prim, d, Semantic::Colors(0), dims, Some(n), loc)?.unwrap_or_default();
        let rgba = |c: &[f32]| Vec4::new(c[0], c[1], c[2], if k == 4 { c[3] } else { 1.0 });
        let colors =
            v.chunks_exact(k).map(rgba).map(|c| if c.is_finite() { c.clamp(Vec4::ZERO, Vec4::ONE) } else { Vec4::ONE });
        Ok(Some(colors.collect()))
    }

    pub(super) fn read_primitive(
        &mut self,
        prim: &gltf::Primitive,
        world: &Mat4,
        material: u32,
        loc: &str,
        deform: Option<&Deform>,
    ) -> Result<Mesh> {
        let draco = self.decode_draco(prim, loc)?;
        let d = draco.as_ref();
        let Some(positions) = self.attribute_f32(prim, d, Semantic::Positions, Dimensions::Vec3, None, loc)? else {
            self.warn(loc, "has no POSITION attribute; skipped");
            return Ok(Mesh::default());
        };
        let n = positions.len() / 3;
        let normals = self.attribute_f32(prim, d, Semantic::Normals, Dimensions::Vec3, Some(n), loc)?;
        let tangents = self.attribute_f32(prim, d, Semantic::Tangents, Dimensions::Vec4, Some(n), loc)?;
        let uv0 = self.attribute_f32(prim, d, Semantic::TexCoords(0), Dimensions::Vec2, Some(n), loc)?;
        let uv1 = self.attribute_f32(prim, d, Semantic::TexCoords(1), Dimensions::Vec2, Some(n), loc)?;
        let colors = self.vertex_colors(prim, d, n, loc)?;
        // Indices (a Draco mesh's faces).
        let mut flat: Vec<u32> = match (draco.as_ref(), prim.indices()) {
            (Some(d), _) => {
                let faces = d.faces();
                if let Some(k) = faces.iter().position(|&i| i as usize >= n) {
                    return Err(self.error(
                        loc,
                        format!("KHR_draco_mesh_compression: index {k} is {}, out of range for {n} vertices", faces[k]),
                    ));
                }
                faces
            }
            (None, Some(acc)) => {
                let what = format!("indices (accessor {})", acc.index());
                if acc.dimensions() != Dimensions::Scalar
                    || !matches!(acc.data_type(), DataType::U8 | DataType::U16 | DataType::U32)
                {
                    return Err(self.error(loc, format!("{what} must be unsigned integer scalars")));
                }
                let v = read_accessor(self, &acc).map_err(|m| self.error(loc, format!("{what}: {m}")))?;
                let mut out = Vec::with_capacity(v.len());
                for (k, &i) in v.iter().enumerate() {
                    if !(i >= 0.0 && (i as usize) < n) {
                        return Err(self.error(loc, format!("{what}: index {k} is {i}, out of range for {n} vertices")));
                    }
                    out.push(i as u32);
                }
                out
            }
            (None, None) => {
                if n > u32::MAX as usize {
                    return Err(self.error(loc, "too many vertices"));
                }
                (0..n as u32).collect()
            }
        };
        if !flat.len().is_multiple_of(3) {
            self.warn(
                loc,
                format!("{} indices is not a multiple of 3; the last {} ignored", flat.len(), flat.len() % 3),
            );
            flat.truncate(flat.len() - flat.len() % 3);
        }
        // A skin or morph weights (`deform.rs`): positions, normals and tangents deformed.
        let (positions, normals, tangents, mirrored) = match deform {
            None => (positions, normals, tangents, Vec::new()),
            Some(df) => {
                let skin = match df.joints {
                    Some(_) => self.skin_attributes(
                        prim,
                        |s| self.attribute_f32(prim, d, s, Dimensions::Vec4, Some(n), loc),
                        loc,
                    )?,
                    None => Vec::new(),
                };
                let r =
                    self.deform_primitive(prim, df, d.is_some(), positions, normals, tangents, &skin, &flat, loc)?;
                (r.positions, r.normals, r.tangents, r.mirrored)
            }
        };

        // World-space attributes.
        let lin = Mat3::from_mat4(*world);
        let det = lin.determinant();
        let sign = if det < 0.0 { -1.0 } else { 1.0 };
        let cof = normal_matrix(&lin, sign);
        let pos: Vec<Vec3> =
            positions.chunks_exact(3).map(|p| world.transform_point3(Vec3::new(p[0], p[1], p[2]))).collect();

        // Triangles, dropping those with a non-finite vertex and flipping mirrored ones.
        let mut tris: Vec<[u32; 3]> = Vec::with_capacity(flat.len() / 3);
        let mut dropped = 0usize;
        for t in flat.chunks_exact(3) {
            // mirrored by the node, or by the skin at the triangle's first vertex
            let flip = (det < 0.0) != mirrored.get(t[0] as usize).copied().unwrap_or(false);
            let tri = if flip { [t[0], t[2], t[1]] } else { [t[0], t[1], t[2]] };
            if tri.iter().all(|&i| pos[i as usize].is_finite()) {
                tris.push(tri);
            } else {
                dropped += 1;
            }
        }
        self.triangles_read += flat.len() / 3;
        self.triangles_dropped += dropped;
        if dropped > 0 {
            self.warn(
                loc,
                format!("dropped {dropped} of {} triangles with non-finite vertex positions", flat.len() / 3),
            );
        }

        let to_vec2 = |v: &Option<Vec<f32>>| -> Option<Vec<Vec2>> {
            v.as_ref().map(|v| {
                v.chunks_exact(2)
                    .map(|c| {
                        let uv = Vec2::new(c[0], c[1]);
                        if uv.is_finite() {
                            uv
                        } else {
                            Vec2::ZERO
                        }
                    })
                    .collect()
            })
        };
        let uv0 = to_vec2(&uv0);
        let uv1 = to_vec2(&uv1);
        let tangents: Option<Vec<Vec4>> = tangents.map(|t| {
            t.chunks_exact(4)
                .map(|c| {
                    let d = lin * Vec3::new(c[0], c[1], c[2]);
                    let w = if c[3] < 0.0 { -sign } else { sign };
                    if d.is_finite() && d.length_squared() > 0.0 {
                        d.normalize().extend(w)
                    } else {
                        Vec4::ZERO
                    }
                })
                .collect()
        });

        let face_normal = |t: &[u32; 3]| {
            let (a, b, c) = (pos[t[0] as usize], pos[t[1] as usize], pos[t[2] as usize]);
            (b - a).cross(c - a)
        };

        let mut out = Mesh::default();
        match normals {
            Some(nrm) => {
                // Shared vertices; compact to the ones the kept triangles use.
                let mut world_n: Vec<Vec3> =
                    nrm.chunks_exact(3).map(|c| (cof * Vec3::new(c[0], c[1], c[2])).normalize_or_zero()).collect();
                if world_n.iter().any(|v| *v == Vec3::ZERO || !v.is_finite()) {
                    // Replace unusable normals by area-weighted vertex normals.
                    let mut acc = vec![Vec3::ZERO; n];
                    for t in &tris {
                        let f = face_normal(t);
                        if f.is_finite() {
                            for &i in t {
                                acc[i as usize] += f;
                            }
                        }
                    }
                    for (v, a) in world_n.iter_mut().zip(&acc) {
                        if *v == Vec3::ZERO || !v.is_finite() {
                            *v = a.try_normalize().unwrap_or(Vec3::Y);
                        }
                    }
                }
                let mut remap = vec![u32::MAX; n];
                for t in &tris {
                    let mut nt = [0u32; 3];
                    for (k, &i) in t.iter().enumerate() {
                        let i = i as usize;
                        if remap[i] == u32::MAX {
                            remap[i] = out.positions.len() as u32;
                            out.positions.push(pos[i]);
                            out.normals.push(world_n[i]);
                            out.tangents.push(tangents.as_ref().map_or(Vec4::ZERO, |t| t[i]));
                            out.uv0.push(uv0.as_ref().map_or(Vec2::ZERO, |u| u[i]));
                            if let Some(u) = &uv1 {
                                out.uv1.push(u[i]);
                            }
                            if let Some(c) = &colors {
                                out.colors.push(c[i]);
                            }
                        }
                        nt[k] = remap[i];
                    }
                    out.indices.push(nt);
                }
            }
            None => {
                // Flat normals: every triangle gets its own three vertices.
                for t in &tris {
                    let f = face_normal(t);
                    let normal = if f.is_finite() { f.try_normalize().unwrap_or(Vec3::Y) } else { Vec3::Y };
                    let base = out.positions.len() as u32;
                    for &i in t {
                        let i = i as usize;
                        out.positions.push(pos[i]);
                        out.normals.push(normal);
                        out.tangents.push(tangents.as_ref().map_or(Vec4::ZERO, |t| t[i]));
                        out.uv0.push(uv0.as_ref().map_or(Vec2::ZERO, |u| u[i]));
                        if let Some(u) = &uv1 {
                            out.uv1.push(u[i]);
                        }
                        if let Some(c) = &colors {
                            out.colors.push(c[i]);
                        }
                    }
                    out.indices.push([base, base + 1, base + 2]);
                }
            }
        }
        out.material_ids = vec![material; out.indices.len()];
        Ok(out)
    }
}

/// A primitive's decoded `KHR_draco_mesh_compression` mesh and the extension's map from
/// attribute semantics to Draco attribute ids.
struct Draco {
    mesh: draco_core::Mesh,
    ids: std::collections::HashMap<String, u32>,
}

impl Draco {
    /// Attribute `name`'s values (`components` per point, as floats; integers normalized where
    /// the accessor says so), or None when the attribute is not compressed.
    fn values(
        &self,
        name: &str,
        acc: &gltf::Accessor,
        components: usize,
    ) -> Option<std::result::Result<Vec<f32>, String>> {
        let id = *self.ids.get(name)?;
        let Some(att) = self.mesh.attribute_by_unique_id(id) else {
            return Some(Err(format!("Draco attribute {id} is not in the compressed mesh")));
        };
        let n = self.mesh.num_points();
        if acc.count() != n {
            return Some(Err(format!("accessor count {} but the compressed mesh has {n} points", acc.count())));
        }
        let mut v = att.read_f32s(n, components);
        if acc.normalized() {
            use draco_core::DataType as T;
            let (scale, signed) = match att.data_type() {
                T::Uint8 => (255.0, false),
                T::Uint16 => (65_535.0, false),
                T::Int8 => (127.0, true),
                T::Int16 => (32_767.0, true),
                _ => (1.0, false),
            };
            for x in &mut v {
                *x /= scale;
                if signed {
                    *x = x.max(-1.0);
                }
            }
        }
        Some(Ok(v))
    }

    /// The triangles' point indices, three per face.
    fn faces(&self) -> Vec<u32> {
        (0..self.mesh.num_faces() as u32).flat_map(|f| self.mesh.face(draco_core::FaceIndex(f)).map(|p| p.0)).collect()
    }
}
