//! The composed stage → the renderer's instanced [`Scene`]: one walk over the prim tree at
//! one time code, composing transforms (no transform cache in openusd 0.6), building each
//! mesh once and placing it by instances.
//!
//! | prim | result |
//! |---|---|
//! | inactive, `visibility = invisible`, a `purpose` not included (guide and proxy by default; [`crate::Purposes`]) | skipped with its subtree |
//! | `class` or `over` (after composition; a point-instancer prototype excepted) | skipped with its subtree (still read as a composition source) |
//! | typeless (`def "X"`) | its xform ops, `visibility` and `purpose` ignored (a `Scope`'s xform ops too), as pxr |
//! | `Mesh` | one mesh, one instance |
//! | native instance (`instanceable`) | the prototype's meshes built once (per distinct material binding the instance prim and its ancestors pass down), one instance each per instance prim |
//! | `PointInstancer` | the prototypes' meshes built once; instance i = instancer · T(positions[i]) · R(orientations[i]) · S(scales[i]) · prototype root; `invisibleIds` (against `ids`, else the index) skipped; the instancer's children are not rendered directly |
//! | `Camera` | a [`UsdCamera`] (cameras in prototypes are ignored) |
//! | UsdLux lights | see [`crate::lights`] |
//! | `Cube`, `Sphere`, `Cylinder`, `Cone`, `Capsule`, `Plane` | tessellated ([`crate::shapes`]), one instance |
//! | `BasisCurves` | tessellated into round tubes ([`crate::curves`]), one instance |
//! | other gprims (`Points`, `NurbsCurves`, `HermiteCurves`, `NurbsPatch`, `TetMesh`, `Volume`) | listed once as unsupported |
//!
//! The renderer's world is metres with +y up: every instance transform is pre-multiplied by
//! the stage's `upAxis`/`metersPerUnit` correction ([`StageUnits::to_renderer`]).

use crate::binding::{InheritedBinding, Resolver};
use crate::camera::{read_camera, UsdCamera};
use crate::lights;
use crate::mesh::{build_mesh, Subset};
use crate::shading::Materials;
use crate::skel::{skinned_points, Skinned};
use crate::value::{attr_error, layer_of_prim, Reader};
use crate::xform::{local_xform, StageUnits};
use crate::Error;
use glam::{Affine3A, DMat4, DQuat, DVec3};
use openusd::{sdf, usd};
use petzval_renderer::scene::normals::rederive_normals;
use petzval_renderer::scene::{Light, Scene};
use std::collections::{BTreeSet, HashMap};

/// One mesh as loaded (for reports and tests).
#[derive(Debug, Clone, serde::Serialize)]
pub struct MeshInfo {
    /// The prim it came from.
    pub prim: String,
    /// Triangles after triangulation.
    pub triangles: usize,
    /// Vertices stored.
    pub vertices: usize,
    /// Faces authored (a curves prim: its curves).
    pub faces: usize,
    /// Faces skipped with fewer than three vertices.
    pub degenerate_faces: usize,
    /// Faces skipped as holes.
    pub hole_faces: usize,
    /// Instances placing it.
    pub instances: usize,
    /// Object-space bounds (min, max) of its vertices.
    pub bounds: [[f32; 3]; 2],
    /// The texture-coordinate primvar read.
    pub st_primvar: Option<String>,
    /// Catmull-Clark levels the mesh was subdivided by (absent: rendered as authored).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub subdivision_level: Option<u32>,
    /// The primvar read as vertex colours (absent: none).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub color_primvar: Option<String>,
    /// The material of its faces outside material subsets, by name (a Material's prim path,
    /// or `displayColor:…` for an unbound gprim; absent: an area light's emitter).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub material: Option<String>,
    /// The face subsets with a material of their own: (subset prim, material name).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub subset_materials: Vec<(String, String)>,
    /// A `BasisCurves` prim's curves and tessellation (absent: not curves).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub curves: Option<crate::curves::CurvesReport>,
}

fn bounds(m: &petzval_renderer::scene::Mesh) -> [[f32; 3]; 2] {
    let lo = m.positions.iter().fold(glam::Vec3::splat(f32::INFINITY), |a, &b| a.min(b));
    let hi = m.positions.iter().fold(glam::Vec3::splat(f32::NEG_INFINITY), |a, &b| a.max(b));
    if m.positions.is_empty() {
        [[0.0; 3]; 2]
    } else {
        [lo.to_array(), hi.to_array()]
    }
}

/// What the walk found besides the scene.
#[derive(Debug, Clone, Default)]
pub struct StageInfo {
    /// One entry per scene mesh (same index).
    pub meshes: Vec<MeshInfo>,
    /// The prim path each scene instance stands for (same index as `Scene::instances`;
    /// point-instancer instances read `INSTANCER[i]/…`).
    pub instance_paths: Vec<String>,
    /// Stage world transform (stage units, stage up axis) of each instance.
    pub instance_stage_xf: Vec<DMat4>,
    /// Lights read.
    pub lights: Vec<lights::LightInfo>,
    /// Point instancers: (path, instances placed, instances hidden by invisibleIds).
    pub point_instancers: Vec<(String, usize, usize)>,
    /// Native instances: (instance prim, prototype path).
    pub native_instances: Vec<(String, String)>,
}

/// A built mesh's identity: prim path, the material of faces outside subsets, and each subset
/// with a material of its own (subset path, material).
type MeshKey = (String, u32, Vec<(String, u32)>);

/// A placement found by the walk: mesh, stage-world transform, path.
type Placement = (u32, DMat4, String);

/// Walks a stage.
pub struct Walker<'a> {
    /// Value reader.
    pub reader: Reader<'a>,
    /// Units.
    pub units: StageUnits,
    /// Scene built so far.
    pub scene: Scene,
    /// Cameras found.
    pub cameras: Vec<UsdCamera>,
    /// Report.
    pub info: StageInfo,
    /// Warnings (deduplicated at the end).
    pub warnings: Vec<String>,
    /// Catmull-Clark levels for meshes with `subdivisionScheme = catmullClark`.
    pub subdivision_level: u32,
    /// The geometry purposes rendered.
    pub purposes: crate::Purposes,
    /// The purpose an ancestor other than `default` passes down (None: none did).
    inherited_purpose: Option<String>,
    /// Walking a point-instancer prototype, whose prims render whatever their specifier.
    in_point_prototype: bool,
    /// The material bindings the native instances being expanded pass down.
    binding: InheritedBinding,
    /// Material binding resolution.
    bindings: Resolver,
    materials: Materials,
    /// Meshes built, by prim and the materials of their faces (outside subsets, then each
    /// subset with its own).
    meshes_by_prim: HashMap<MeshKey, u32>,
    /// Skinned meshes, whose points are in world space already (their prims' transforms do
    /// not apply).
    world_space_meshes: BTreeSet<String>,
    prototypes: HashMap<String, Vec<Placement>>,
    unsupported: BTreeSet<String>,
}

/// Refuses a stage whose instancing (nested point instancers, instanceable prims) expands to
/// more than [`petzval_renderer::limits::MAX_NODE_INSTANCES`] placed meshes, before they are made.
fn check_expansion(prim: &usd::Prim, attr: &str, count: usize) -> Result<(), Error> {
    let limit = petzval_renderer::limits::MAX_NODE_INSTANCES;
    if count > limit {
        return Err(attr_error(
            prim,
            attr,
            format!("the stage expands to more than {limit} placed meshes here (nested instancing); the limit keeps a small file from exhausting memory"),
        ));
    }
    Ok(())
}

fn is_light(ty: &str) -> bool {
    matches!(
        ty,
        "SphereLight" | "DiskLight" | "RectLight" | "CylinderLight" | "DistantLight" | "DomeLight" | "DomeLight_1"
    )
}

impl<'a> Walker<'a> {
    /// A walker over `stage` at `time`.
    pub fn new(stage: &'a usd::Stage, time: Option<f64>) -> Result<Self, Error> {
        let units = StageUnits::read(stage)?;
        Ok(Walker {
            subdivision_level: crate::subdiv::DEFAULT_LEVEL,
            purposes: crate::Purposes::default(),
            inherited_purpose: None,
            in_point_prototype: false,
            binding: InheritedBinding::default(),
            bindings: Resolver::default(),
            reader: Reader { stage, time },
            units,
            scene: Scene::default(),
            cameras: Vec::new(),
            info: StageInfo::default(),
            warnings: Vec::new(),
            materials: Materials::filtering_encoded(units.blender_authored),
            meshes_by_prim: HashMap::new(),
            world_space_meshes: BTreeSet::new(),
            prototypes: HashMap::new(),
            unsupported: BTreeSet::new(),
        })
    }

    /// Walks every root prim and fills the scene.
    pub fn run(&mut self) -> Result<(), Error> {
        let root = self.reader.stage.prim(sdf::Path::abs_root());
        let mut out = Vec::new();
        for child in children(&root)? {
            self.walk(&child, DMat4::IDENTITY, &mut out, false)?;
        }
        let to_r = self.units.to_renderer();
        for (mesh, xf, path) in out {
            let m = to_r * xf;
            check_placement(&path, &m)?;
            self.scene.add_instance(mesh, Affine3A::from_mat4(m.as_mat4()));
            self.info.meshes[mesh as usize].instances += 1;
            self.info.instance_paths.push(path);
            self.info.instance_stage_xf.push(xf);
        }
        // every light as the renderer takes it (a finite intensity times a huge area is not)
        for (k, l) in self.scene.lights.iter().enumerate() {
            let finite = match *l {
                Light::Point { position, intensity, .. } => position.is_finite() && intensity.is_finite(),
                Light::Spot { position, direction, intensity, inner_cone_rad, outer_cone_rad, .. } => {
                    position.is_finite()
                        && direction.is_finite()
                        && intensity.is_finite()
                        && inner_cone_rad.is_finite()
                        && outer_cone_rad.is_finite()
                }
                Light::Directional { direction, irradiance, .. } => direction.is_finite() && irradiance.is_finite(),
            };
            if !finite {
                let prim = self.info.lights.get(k).map(|i| i.prim.clone()).unwrap_or_else(|| format!("light {k}"));
                return Err(Error::Prim {
                    layer: String::new(),
                    prim,
                    message: "the light's position, direction or power is not finite in single precision".into(),
                });
            }
        }
        for t in &self.unsupported {
            self.warnings.push(format!("prims of type {t} are not supported and were skipped"));
        }
        let mut seen = BTreeSet::new();
        self.warnings.retain(|w| seen.insert(w.clone()));
        self.scene.warnings = self.warnings.clone();
        Ok(())
    }

    fn walk(&mut self, prim: &usd::Prim, parent: DMat4, out: &mut Vec<Placement>, in_proto: bool) -> Result<(), Error> {
        let path = prim.path().to_string();
        let err = |e: anyhow::Error| Error::Prim {
            layer: layer_of_prim(prim),
            prim: path.clone(),
            message: format!("{e:#}"),
        };
        if !prim.is_active().map_err(err)? {
            return Ok(());
        }
        // pxr's default predicate: a prim is scene content only when it and its ancestors are
        // `def` (an `over` is undefined, a `class` abstract). They stay composition sources:
        // inherits, references and native prototypes read them through openusd. A
        // point-instancer prototype is drawn whatever its specifier (Blender writes its
        // prototypes under `over "Prototypes"`, as Hydra draws them).
        if !self.in_point_prototype && prim.specifier().map_err(err)? != Some(sdf::Specifier::Def) {
            return Ok(());
        }
        let ty = prim.type_name().map_err(err)?.map(|t| t.as_str().to_string()).unwrap_or_default();
        if matches!(ty.as_str(), "Material" | "Shader" | "NodeGraph" | "GeomSubset") || ty.starts_with("Render") {
            return Ok(());
        }
        // A typeless prim is neither Imageable nor Xformable (a Scope is Imageable only): pxr
        // ignores the visibility, purpose ([`local_xform`]: and xform ops) they author.
        let imageable = !ty.is_empty();
        if imageable && self.reader.token(prim, "visibility")?.as_deref() == Some("invisible") {
            return Ok(());
        }
        // The prim's purpose (an ancestor's other than default wins); a subtree of a purpose
        // not rendered is skipped, default-purpose geometry only where `default` is not.
        let own_purpose = if imageable { self.reader.token(prim, "purpose")? } else { None };
        let purpose = match (&self.inherited_purpose, own_purpose) {
            (Some(p), _) => p.clone(),
            (None, Some(p)) => p,
            (None, None) => "default".to_string(),
        };
        let default_purpose = !matches!(purpose.as_str(), "render" | "proxy" | "guide");
        if !default_purpose && !self.purposes.includes(&purpose) {
            return Ok(());
        }
        let local = local_xform(&self.reader, prim)?;
        let world = if local.resets { local.matrix } else { parent * local.matrix };
        if prim.is_instance().map_err(err)? {
            if let Some(proto) = prim.prototype().map_err(err)? {
                let proto_s = proto.to_string();
                self.info.native_instances.push((path.clone(), proto_s.clone()));
                // the instance prim's and its ancestors' bindings reach the proxies
                let inner = self.bindings.enter(&self.binding, prim, &proto, &mut self.warnings)?;
                let outer = std::mem::replace(&mut self.binding, inner);
                let placements = self.prototype_placements(&proto, false);
                self.binding = outer;
                let placements = placements?;
                check_expansion(prim, "instanceable", out.len() + placements.len())?;
                for (m, rel, sub) in placements {
                    out.push((m, world * rel, format!("{path}{sub}")));
                }
                return Ok(());
            }
        }
        match ty.as_str() {
            "Mesh" | "BasisCurves" | "Cube" | "Sphere" | "Cylinder" | "Cone" | "Capsule" | "Plane"
                if !default_purpose || self.purposes.default =>
            {
                let mesh = self.mesh(prim, &ty)?;
                let xf = if self.world_space_meshes.contains(&path) { DMat4::IDENTITY } else { world };
                out.push((mesh, xf, path.clone()));
            }
            "PointInstancer" => {
                self.point_instancer(prim, world, out)?;
                return Ok(());
            }
            "Camera" if !in_proto => {
                let cam = read_camera(&self.reader, prim, world, &self.units, &mut self.warnings)?;
                self.cameras.push(cam);
            }
            t if is_light(t) => {
                if in_proto {
                    self.warnings.push(format!("{path}: lights inside instance prototypes are not supported"));
                } else {
                    let mut o = lights::LightOutput {
                        scene: &mut self.scene,
                        warnings: &mut self.warnings,
                        infos: &mut self.info.lights,
                        meshes: Vec::new(),
                    };
                    lights::read_light(&self.reader, &self.units, &mut o, prim, t, world)?;
                    for (mesh, xf, p) in o.meshes {
                        self.add_placed_mesh(mesh, xf, p);
                    }
                }
            }
            "" | "Xform" | "Scope" => {}
            "Points" | "NurbsCurves" | "NurbsPatch" | "HermiteCurves" | "TetMesh" | "Volume" => {
                self.unsupported.insert(ty.clone());
            }
            _ => {}
        }
        let outer_purpose = self.inherited_purpose.clone();
        if !default_purpose {
            self.inherited_purpose = Some(purpose);
        }
        for child in children(prim)? {
            self.walk(&child, world, out, in_proto)?;
        }
        self.inherited_purpose = outer_purpose;
        Ok(())
    }

    /// The meshes under a prototype with their transforms relative to it. A native prototype
    /// (`/__Prototype_N`) contributes its descendants; a point-instancer prototype also its
    /// own root transform (`include_root`).
    fn prototype_placements(&mut self, proto: &sdf::Path, include_root: bool) -> Result<Vec<Placement>, Error> {
        let key = format!("{proto}#{include_root}#{:?}", self.binding.key());
        if let Some(p) = self.prototypes.get(&key) {
            return Ok(p.clone());
        }
        let prim = self.reader.stage.prim(proto.clone());
        let mut out = Vec::new();
        let outer = std::mem::replace(&mut self.in_point_prototype, include_root);
        let walked = self.prototype_walk(&prim, proto, include_root, &mut out);
        self.in_point_prototype = outer;
        walked?;
        self.prototypes.insert(key, out.clone());
        Ok(out)
    }

    fn prototype_walk(
        &mut self,
        prim: &usd::Prim,
        proto: &sdf::Path,
        include_root: bool,
        out: &mut Vec<Placement>,
    ) -> Result<(), Error> {
        if include_root {
            self.walk(prim, DMat4::IDENTITY, out, true)?;
            let root = proto.to_string();
            for p in out.iter_mut() {
                p.2 = p.2.strip_prefix(&root).unwrap_or(&p.2).to_string();
            }
        } else {
            for child in children(prim)? {
                self.walk(&child, DMat4::IDENTITY, out, true)?;
            }
            let root = proto.to_string();
            for p in out.iter_mut() {
                p.2 = p.2.strip_prefix(&root).unwrap_or(&p.2).to_string();
            }
        }
        Ok(())
    }

    fn mesh(&mut self, prim: &usd::Prim, ty: &str) -> Result<u32, Error> {
        let path = prim.path().to_string();
        // the materials of the mesh and of its face subsets (pxr's bound materials, through
        // the native instance being expanded)
        // tubes are open at their ends: seen from both sides
        let double_sided = ty == "BasisCurves" || self.reader.bool(prim, "doubleSided")?.unwrap_or(false);
        let binding = self.bindings.bound_material(prim, &self.binding, &mut self.warnings)?;
        let material = self.materials.material_for(
            &self.reader,
            &mut self.scene,
            prim,
            binding.clone(),
            double_sided,
            &mut self.warnings,
        )?;
        let mut subsets = Vec::new();
        // face subsets are a mesh's (a curves prim has no faces)
        let is_curves = ty == "BasisCurves";
        for child in children(prim)? {
            let ty = child.type_name().ok().flatten().map(|t| t.as_str().to_string()).unwrap_or_default();
            if ty != "GeomSubset" || is_curves {
                continue;
            }
            let et = self.reader.token(&child, "elementType")?.unwrap_or_else(|| "face".into());
            if et != "face" {
                continue;
            }
            let bound = self.bindings.bound_material(&child, &self.binding, &mut self.warnings)?;
            if bound.is_none() || bound == binding {
                continue;
            }
            let faces = self.reader.ints(&child, "indices")?.unwrap_or_default();
            let m = self.materials.material_for(
                &self.reader,
                &mut self.scene,
                &child,
                bound,
                double_sided,
                &mut self.warnings,
            )?;
            subsets.push(Subset { faces, material: m, path: child.path().to_string() });
        }
        let cache_key =
            (path.clone(), material, subsets.iter().map(|s| (s.path.clone(), s.material)).collect::<Vec<_>>());
        if let Some(&m) = self.meshes_by_prim.get(&cache_key) {
            return Ok(m);
        }
        // A subdivision surface (Blender writes its Subdivision modifier's cage with the scheme
        // when exporting "Best Match"): Catmull-Clark refined. Only an authored scheme counts
        // (every Blender mesh authors "none"; USD's fallback is catmullClark, which most files
        // leave unauthored for plain polygon meshes).
        let scheme = if ty == "Mesh" { self.reader.token(prim, "subdivisionScheme")? } else { None };
        let subdivision = match scheme.as_deref() {
            Some("catmullClark") => Some(self.subdivision_level),
            None | Some("none") | Some("bilinear") => None,
            Some(other) => {
                self.warnings.push(format!(
                    "{}: {path}: subdivisionScheme = {other}: rendered as its control cage (only catmullClark is subdivided)",
                    layer_of_prim(prim)
                ));
                None
            }
        };
        let mut curves_report = None;
        let (mesh, report) = if ty == "BasisCurves" {
            let color = self.materials.color_primvar(material).map(|(n, c)| (n.to_string(), c));
            let (mesh, r) = crate::curves::build_curves(
                &self.reader,
                prim,
                material,
                color.as_ref().map(|(n, c)| (n.as_str(), *c)),
            )?;
            self.curve_warnings(prim, &r);
            let report = crate::mesh::MeshReport {
                faces: r.curves,
                color_primvar: r.color_primvar.clone(),
                ..Default::default()
            };
            curves_report = Some(r);
            (mesh, report)
        } else if ty == "Mesh" {
            let st = self.materials.st_name(material).map(str::to_string);
            let color = self.materials.color_primvar(material).map(|(n, c)| (n.to_string(), c));
            let build = |deform: Option<&Skinned>| {
                build_mesh(
                    &self.reader,
                    prim,
                    material,
                    &subsets,
                    st.as_deref(),
                    subdivision,
                    color.as_ref().map(|(n, c)| (n.as_str(), *c)),
                    deform,
                )
            };
            // A skinned mesh (UsdSkel): posed, placed by its skeleton when skinned; normals it
            // authors that are its geometry's own are derived again from the posed geometry.
            match skinned_points(&self.reader, prim, &mut self.warnings)? {
                Some(skinned) => {
                    let (mut mesh, report) = build(Some(&skinned))?;
                    if report.normals_authored && subdivision.is_none() {
                        let (at_rest, _) = build(None)?;
                        let mut normals = std::mem::take(&mut mesh.normals);
                        rederive_normals(
                            &at_rest.positions,
                            &at_rest.normals,
                            &mesh.positions,
                            &mut normals,
                            &mesh.indices,
                        );
                        mesh.normals = normals;
                    }
                    if skinned.world_space {
                        self.world_space_meshes.insert(path.clone());
                    }
                    (mesh, report)
                }
                None => build(None)?,
            }
        } else {
            let mut m = crate::shapes::shape_mesh(&self.reader, prim, ty)?.unwrap_or_default();
            m.material_ids = vec![material; m.indices.len()];
            let faces = m.indices.len();
            (m, crate::mesh::MeshReport { faces, ..Default::default() })
        };
        if let (Some(want), Some(got)) = (subdivision, report.subdivision_level) {
            if got < want {
                self.warnings.push(format!(
                    "{}: {path}: subdivided {got} levels, not {want}: {want} would make more than {} triangles",
                    layer_of_prim(prim),
                    crate::mesh::MAX_SUBDIVIDED_TRIANGLES
                ));
            }
        }
        if report.degenerate_faces > 0 {
            self.warnings.push(format!(
                "{}: {path}: {} of {} faces have fewer than 3 vertices and were skipped",
                layer_of_prim(prim),
                report.degenerate_faces,
                report.faces
            ));
        }
        self.info.meshes.push(MeshInfo {
            prim: path.clone(),
            triangles: mesh.triangle_count(),
            vertices: mesh.positions.len(),
            faces: report.faces,
            degenerate_faces: report.degenerate_faces,
            hole_faces: report.hole_faces,
            instances: 0,
            bounds: bounds(&mesh),
            st_primvar: report.st_primvar.clone(),
            subdivision_level: report.subdivision_level,
            color_primvar: report.color_primvar.clone(),
            material: Some(self.scene.materials[material as usize].name.clone()),
            subset_materials: subsets
                .iter()
                .map(|s| (s.path.clone(), self.scene.materials[s.material as usize].name.clone()))
                .collect(),
            curves: curves_report,
        });
        let id = self.scene.add_mesh(mesh);
        self.meshes_by_prim.insert(cache_key, id);
        Ok(id)
    }

    /// The warnings a curves prim's tessellation leaves: curves skipped, coarser tessellation.
    fn curve_warnings(&mut self, prim: &usd::Prim, r: &crate::curves::CurvesReport) {
        let head = format!("{}: {}", layer_of_prim(prim), prim.path());
        if r.bad_counts > 0 {
            self.warnings.push(format!(
                "{head}.curveVertexCounts: {} of {} curves have a vertex count {} {} curves ({}) cannot use and were skipped",
                r.bad_counts, r.curves, r.kind, r.basis, r.wrap
            ));
        }
        let limit = crate::curves::MAX_CURVE_TRIANGLES;
        let default_rings = if r.basis == "linear" { 1 } else { crate::curves::STEPS_PER_SPAN };
        if (r.rings_per_span, r.sides) != (default_rings, crate::curves::SIDES) {
            self.warnings.push(format!(
                "{head}: {} curves tessellated with {} rings per span and {} sides (not {} and {}) to stay under {limit} triangles",
                r.curves, r.rings_per_span, r.sides, crate::curves::STEPS_PER_SPAN, crate::curves::SIDES
            ));
        }
        if r.over_limit > 0 {
            self.warnings.push(format!(
                "{head}: {} of {} curves were left out: even at 1 ring per span and 3 sides they make more than {limit} triangles",
                r.over_limit, r.curves
            ));
        }
    }

    fn point_instancer(&mut self, prim: &usd::Prim, world: DMat4, out: &mut Vec<Placement>) -> Result<(), Error> {
        let path = prim.path().to_string();
        let r = &self.reader;
        let protos = prim
            .relationship("prototypes")
            .targets()
            .map_err(|e| attr_error(prim, "prototypes", format!("cannot be read: {e:#}")))?;
        let proto_indices = r.ints(prim, "protoIndices")?.unwrap_or_default();
        let n = proto_indices.len();
        let positions = r.vec3s(prim, "positions")?.unwrap_or_default();
        if positions.len() != n {
            return Err(attr_error(
                prim,
                "positions",
                format!("has {} entries, protoIndices has {n}", positions.len()),
            ));
        }
        let orient = match r.quats(prim, "orientations")? {
            Some(q) => Some(q),
            None => r.quats(prim, "orientationsf")?,
        };
        let scales = r.vec3s(prim, "scales")?;
        for (name, len) in [("orientations", orient.as_ref().map(Vec::len)), ("scales", scales.as_ref().map(Vec::len))]
        {
            if let Some(l) = len {
                if l != n {
                    return Err(attr_error(prim, name, format!("has {l} entries, protoIndices has {n}")));
                }
            }
        }
        let ids = r.ints(prim, "ids")?;
        let invisible: std::collections::HashSet<i64> =
            r.ints(prim, "invisibleIds")?.unwrap_or_default().into_iter().collect();
        let mut proto_places = Vec::with_capacity(protos.len());
        for p in &protos {
            proto_places.push(self.prototype_placements(p, true)?);
        }
        // Up front: what this instancer adds (before any is made).
        let adds: usize = proto_indices
            .iter()
            .filter_map(|&k| usize::try_from(k).ok().and_then(|k| proto_places.get(k)))
            .map(Vec::len)
            .fold(0usize, usize::saturating_add);
        check_expansion(prim, "protoIndices", out.len().saturating_add(adds))?;
        let mut placed = 0;
        let mut hidden = 0;
        let mut bad_index = 0;
        for i in 0..n {
            let id = ids.as_ref().and_then(|v| v.get(i).copied()).unwrap_or(i as i64);
            if invisible.contains(&id) {
                hidden += 1;
                continue;
            }
            let Some(places) = usize::try_from(proto_indices[i]).ok().and_then(|k| proto_places.get(k)) else {
                bad_index += 1;
                continue;
            };
            let q = orient.as_ref().map(|o| o[i]).unwrap_or(DQuat::IDENTITY);
            let s = scales.as_ref().map(|s| s[i]).unwrap_or(DVec3::ONE);
            let xf = world * DMat4::from_scale_rotation_translation(s, q, positions[i]);
            for (m, rel, sub) in places {
                out.push((*m, xf * *rel, format!("{path}[{i}]{sub}")));
            }
            placed += 1;
        }
        if bad_index > 0 {
            self.warnings.push(format!(
                "{}: {path}.protoIndices: {bad_index} instances name a prototype outside the {} prototypes and were skipped",
                layer_of_prim(prim),
                protos.len()
            ));
        }
        self.info.point_instancers.push((path, placed, hidden));
        Ok(())
    }

    /// Adds a mesh placed at `stage_xf` (for area lights).
    pub fn add_placed_mesh(&mut self, mesh: petzval_renderer::scene::Mesh, stage_xf: DMat4, path: String) {
        let m = self.units.to_renderer() * stage_xf;
        if let Err(e) = check_placement(&path, &m) {
            self.warnings.push(format!("{e}: skipped"));
            return;
        }
        self.info.meshes.push(MeshInfo {
            prim: path.clone(),
            triangles: mesh.triangle_count(),
            vertices: mesh.positions.len(),
            faces: mesh.triangle_count(),
            degenerate_faces: 0,
            hole_faces: 0,
            instances: 1,
            bounds: bounds(&mesh),
            st_primvar: None,
            subdivision_level: None,
            color_primvar: None,
            material: None,
            subset_materials: Vec::new(),
            curves: None,
        });
        let id = self.scene.add_mesh(mesh);
        self.scene.add_instance(id, Affine3A::from_mat4(m.as_mat4()));
        self.info.instance_paths.push(path);
        self.info.instance_stage_xf.push(stage_xf);
    }
}

/// A placement the renderer can use: finite in single precision (`1e39` or `inf` in an xform op
/// would otherwise reach the BVH and the shading as infinities).
fn check_placement(path: &str, world: &DMat4) -> Result<(), Error> {
    if world.as_mat4().is_finite() {
        return Ok(());
    }
    Err(Error::Prim {
        layer: String::new(),
        prim: path.to_string(),
        message: "its world transform is not finite in single precision (an xform op or a PointInstancer value is too large or not a number)".into(),
    })
}

fn children(prim: &usd::Prim) -> Result<Vec<usd::Prim>, Error> {
    prim.children().map_err(|e| Error::Prim {
        layer: layer_of_prim(prim),
        prim: prim.path().to_string(),
        message: format!("children cannot be composed: {e:#}"),
    })
}
