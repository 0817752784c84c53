//! `petzval.Scene`: a scene built from numpy buffers (meshes, materials, textures, lights,
//! environment), validated with errors naming the object and field.

use glam::{DAffine3, DMat4, DVec3, DVec4, Vec2, Vec3, Vec4};
use numpy::{AllowTypeChange, PyArrayLike1, PyArrayLike2, PyArrayLike3};
use petzval_renderer::scene::curves::{tube_mesh, Basis, TubeCurve, Wrap as CurveWrap, MAX_CURVE_TRIANGLES, SIDES};
use petzval_renderer::scene::environment::EnvironmentMap;
use petzval_renderer::scene::texture::Wrap;
use petzval_renderer::scene::{
    AlphaMode, AngleWeight, Anisotropy, AnisotropyTangent, Environment, Light, Material, MaterialMix, Mesh,
    MetalFresnel, SpotFalloff, Texture, TextureRef, UvTransform,
};
use pyo3::prelude::*;
use std::sync::Arc;

use crate::errors::*;

pub(crate) fn vec3_arg(name: &str, field: &str, v: &[f64]) -> PyResult<Vec3> {
    match v {
        [a, b, c] if a.is_finite() && b.is_finite() && c.is_finite() => Ok(Vec3::new(*a as f32, *b as f32, *c as f32)),
        _ => Err(scene_err(name, field, format!("expected 3 finite numbers, got {v:?}"))),
    }
}

pub(crate) fn non_negative_rgb(name: &str, field: &str, v: &[f64]) -> PyResult<Vec3> {
    let c = vec3_arg(name, field, v)?;
    if c.min_element() < 0.0 {
        return Err(scene_err(name, field, format!("must be non-negative, got {v:?}")));
    }
    Ok(c)
}

/// A 4×4 object-to-world matrix (rows as Blender prints them, column vectors) as an affine map.
pub(crate) fn affine_from_rows(name: &str, field: &str, m: &numpy::ndarray::ArrayView2<'_, f64>) -> PyResult<DAffine3> {
    if m.shape() != [4, 4] {
        return Err(scene_err(name, field, format!("expected a (4, 4) matrix, got {:?}", m.shape())));
    }
    if m.iter().any(|v| !v.is_finite()) {
        return Err(scene_err(name, field, "has non-finite entries".into()));
    }
    let col = |c: usize| DVec4::new(m[[0, c]], m[[1, c]], m[[2, c]], m[[3, c]]);
    let mat = DMat4::from_cols(col(0), col(1), col(2), col(3));
    if (mat.row(3) - DVec4::new(0.0, 0.0, 0.0, 1.0)).abs().max_element() > 1e-9 {
        return Err(scene_err(name, field, "is projective (last row is not 0 0 0 1)".into()));
    }
    let a = DAffine3::from_mat4(mat);
    if !(a.matrix3.determinant().abs() > 1e-18) {
        return Err(scene_err(name, field, "is singular".into()));
    }
    Ok(a)
}

// ---------------------------------------------------------------------------------------------
// Lenses

/// A scene assembled from buffers.
#[pyclass(name = "Scene", module = "petzval._native")]
/// A scene under construction from Python.
pub(crate) struct PyScene {
    pub(crate) scene: petzval_renderer::scene::Scene,
    /// Every mesh so far came with tangents (else tangents are derived from UVs for all).
    pub(crate) all_tangents: bool,
}

pub(crate) fn parse_alpha_mode(mode: &str, cutoff: f64) -> PyResult<AlphaMode> {
    Ok(match mode {
        "opaque" => AlphaMode::Opaque,
        "blend" => AlphaMode::Blend,
        "mask" => AlphaMode::Mask(cutoff as f32),
        m => {
            return Err(InvalidSceneError::new_err(format!(
                "alpha_mode: expected 'opaque', 'blend' or 'mask', got '{m}'"
            )))
        }
    })
}

/// An f64 affine map as the scene's f32 one.
fn affine_f32(xf: &DAffine3) -> glam::Affine3A {
    glam::Affine3A::from_cols_array(&xf.to_cols_array().map(|v| v as f32))
}

impl PyScene {
    fn check_mesh_id(&self, name: &str, mesh_id: usize) -> PyResult<()> {
        if mesh_id >= self.scene.meshes.len() {
            return Err(scene_err(
                name,
                "mesh_id",
                format!("mesh {mesh_id} does not exist ({} meshes)", self.scene.meshes.len()),
            ));
        }
        Ok(())
    }

    fn texture_ref(&self, name: &str, field: &str, index: Option<usize>) -> PyResult<Option<TextureRef>> {
        match index {
            None => Ok(None),
            Some(i) if i < self.scene.textures.len() => Ok(Some(TextureRef { index: i, uv_set: 0, transform: None })),
            Some(i) => Err(scene_err(
                name,
                field,
                format!("texture {i} does not exist ({} textures)", self.scene.textures.len()),
            )),
        }
    }
}

#[pymethods]
impl PyScene {
    #[new]
    fn new() -> Self {
        PyScene { scene: petzval_renderer::scene::Scene::default(), all_tangents: true }
    }

    /// Adds a texture from (H, W, 4|3) linear values, row 0 at the top; with `srgb_encoded` the
    /// RGB values are sRGB-encoded (an 8-bit sRGB image), decoded after filtering as Cycles does.
    #[pyo3(signature = (pixels, name = "", interpolation = "linear", extension = "repeat", srgb_encoded = false))]
    fn add_texture(
        &mut self,
        pixels: PyArrayLike3<'_, f32, AllowTypeChange>,
        name: &str,
        interpolation: &str,
        extension: &str,
        srgb_encoded: bool,
    ) -> PyResult<usize> {
        guard(|| {
            let a = pixels.as_array();
            let (h, w, c) = a.dim();
            if h == 0 || w == 0 || !(c == 3 || c == 4) {
                return Err(scene_err(name, "pixels", format!("expected an (H, W, 3|4) image, got {:?}", a.shape())));
            }
            let bilinear = match interpolation {
                "linear" | "cubic" | "smart" => true,
                "closest" => false,
                i => {
                    return Err(scene_err(name, "interpolation", format!("expected 'linear' or 'closest', got '{i}'")))
                }
            };
            let wrap = match extension {
                "repeat" => Wrap::Repeat,
                "clip" | "extend" => Wrap::ClampToEdge,
                "mirror" => Wrap::MirroredRepeat,
                e => {
                    return Err(scene_err(
                        name,
                        "extension",
                        format!("expected 'repeat', 'clip' or 'mirror', got '{e}'"),
                    ))
                }
            };
            let mut texels = Vec::with_capacity(h * w);
            for y in 0..h {
                for x in 0..w {
                    let g = |k: usize| {
                        let v = a[[y, x, k]];
                        if v.is_finite() {
                            v
                        } else {
                            0.0
                        }
                    };
                    texels.push(Vec4::new(g(0), g(1), g(2), if c == 4 { g(3) } else { 1.0 }));
                }
            }
            self.scene.textures.push(Arc::new(Texture {
                name: name.to_string(),
                width: w as u32,
                height: h as u32,
                texels,
                wrap_s: wrap,
                wrap_t: wrap,
                bilinear,
                srgb_encoded,
            }));
            Ok(self.scene.textures.len() - 1)
        })
    }

    /// Adds a glTF metallic-roughness material; returns its index.
    #[pyo3(signature = (name, base_color = vec![0.8, 0.8, 0.8, 1.0], metallic = 0.0, roughness = 0.5, ior = 1.5, specular = 1.0, emission = vec![0.0, 0.0, 0.0], alpha_mode = "opaque", alpha_cutoff = 0.5, base_color_texture = None, metallic_roughness_texture = None, normal_texture = None, normal_scale = 1.0, emission_texture = None, double_sided = true, light_emitter = false, visible_to_camera = true, transmission = 0.0, coat_weight = 0.0, coat_roughness = 0.03, coat_ior = 1.5, coat_tint = vec![1.0, 1.0, 1.0], scatter_tint = vec![1.0, 1.0, 1.0], metal_fresnel = "f82", edge_tint = vec![1.0, 1.0, 1.0], translucent = false, mix_material = None, mix_weight = 0.0, mix_weight_texture = None, mix_weight_angle = None, uv_transforms = None, specular_tint = vec![1.0, 1.0, 1.0], anisotropic = 0.0, anisotropic_rotation = 0.0, anisotropy_model = "principled", anisotropy_tangent = "radial_z"))]
    #[allow(clippy::too_many_arguments)]
    fn add_material(
        &mut self,
        name: &str,
        base_color: Vec<f64>,
        metallic: f64,
        roughness: f64,
        ior: f64,
        specular: f64,
        emission: Vec<f64>,
        alpha_mode: &str,
        alpha_cutoff: f64,
        base_color_texture: Option<usize>,
        metallic_roughness_texture: Option<usize>,
        normal_texture: Option<usize>,
        normal_scale: f64,
        emission_texture: Option<usize>,
        double_sided: bool,
        light_emitter: bool,
        visible_to_camera: bool,
        transmission: f64,
        coat_weight: f64,
        coat_roughness: f64,
        coat_ior: f64,
        coat_tint: Vec<f64>,
        scatter_tint: Vec<f64>,
        metal_fresnel: &str,
        edge_tint: Vec<f64>,
        translucent: bool,
        mix_material: Option<usize>,
        mix_weight: f64,
        mix_weight_texture: Option<usize>,
        mix_weight_angle: Option<(String, f64)>,
        uv_transforms: Option<std::collections::BTreeMap<String, Vec<Vec<f64>>>>,
        specular_tint: Vec<f64>,
        anisotropic: f64,
        anisotropic_rotation: f64,
        anisotropy_model: &str,
        anisotropy_tangent: &str,
    ) -> PyResult<usize> {
        guard(|| {
            let bc = match base_color.as_slice() {
                [r, g, b] => Vec4::new(*r as f32, *g as f32, *b as f32, 1.0),
                [r, g, b, a] => Vec4::new(*r as f32, *g as f32, *b as f32, *a as f32),
                v => return Err(scene_err(name, "base_color", format!("expected 3 or 4 numbers, got {v:?}"))),
            };
            if !bc.is_finite() || bc.min_element() < 0.0 {
                return Err(scene_err(
                    name,
                    "base_color",
                    format!("must be finite and non-negative, got {base_color:?}"),
                ));
            }
            for (field, v, lo, hi) in [
                ("metallic", metallic, 0.0, 1.0),
                ("roughness", roughness, 0.0, 1.0),
                ("ior", ior, 1.0, 10.0),
                ("specular", specular, 0.0, 100.0),
                ("normal_scale", normal_scale, -100.0, 100.0),
                ("alpha_cutoff", alpha_cutoff, 0.0, 1.0),
                ("transmission", transmission, 0.0, 1.0),
                ("coat_weight", coat_weight, 0.0, 1.0),
                ("coat_roughness", coat_roughness, 0.0, 1.0),
                ("coat_ior", coat_ior, 1.0, 10.0),
                ("mix_weight", mix_weight, 0.0, 1.0),
            ] {
                if !(v.is_finite() && v >= lo && v <= hi) {
                    return Err(scene_err(name, field, format!("{v} is outside [{lo}, {hi}]")));
                }
            }
            let tint = non_negative_rgb(name, "edge_tint", &edge_tint)?;
            if tint.max_element() > 1.0 {
                return Err(scene_err(name, "edge_tint", format!("must be within [0, 1], got {edge_tint:?}")));
            }
            let metal_fresnel = match metal_fresnel {
                "f82" => MetalFresnel::F82 { tint },
                "constant" => MetalFresnel::Constant,
                other => {
                    return Err(scene_err(
                        name,
                        "metal_fresnel",
                        format!("expected \"f82\" or \"constant\", got {other:?}"),
                    ))
                }
            };
            // anisotropy: Principled Anisotropic in [0, 1] or a Glossy BSDF's in [-1, 1]
            if !(anisotropic.is_finite() && (-1.0..=1.0).contains(&anisotropic)) {
                return Err(scene_err(name, "anisotropic", format!("{anisotropic} is outside [-1, 1]")));
            }
            if !anisotropic_rotation.is_finite() {
                return Err(scene_err(
                    name,
                    "anisotropic_rotation",
                    format!("must be finite, got {anisotropic_rotation}"),
                ));
            }
            let tangent = match anisotropy_tangent {
                "radial_x" => AnisotropyTangent::Radial(0),
                "radial_y" => AnisotropyTangent::Radial(1),
                "radial_z" => AnisotropyTangent::Radial(2),
                "uv_map" => AnisotropyTangent::UvMap,
                other => {
                    return Err(scene_err(
                        name,
                        "anisotropy_tangent",
                        format!("expected \"radial_x\", \"radial_y\", \"radial_z\" or \"uv_map\", got {other:?}"),
                    ))
                }
            };
            let (a, rot) = (anisotropic as f32, anisotropic_rotation as f32);
            let anisotropy = match anisotropy_model {
                "principled" if anisotropic >= 0.0 => Anisotropy::principled(a, rot, tangent),
                "glossy" => Anisotropy::glossy(a, rot, tangent),
                other => {
                    return Err(scene_err(
                        name,
                        "anisotropy_model",
                        format!("expected \"principled\" (anisotropic in [0, 1]) or \"glossy\", got {other:?} with anisotropic {anisotropic}"),
                    ))
                }
            };
            let angle = match &mix_weight_angle {
                None => None,
                Some((kind, v)) if v.is_finite() => match kind.as_str() {
                    "fresnel" if *v > 0.0 => Some(AngleWeight::Fresnel { ior: *v as f32 }),
                    "layer_fresnel" if (0.0..=1.0).contains(v) => Some(AngleWeight::LayerFresnel { blend: *v as f32 }),
                    "layer_facing" if (0.0..=1.0).contains(v) => Some(AngleWeight::LayerFacing { blend: *v as f32 }),
                    _ => None,
                },
                Some(_) => None,
            };
            if mix_weight_angle.is_some() && angle.is_none() {
                return Err(scene_err(
                    name,
                    "mix_weight_angle",
                    format!(
                        "expected (\"fresnel\", ior > 0), (\"layer_fresnel\", blend in [0, 1]) or (\"layer_facing\", blend in [0, 1]), got {mix_weight_angle:?}"
                    ),
                ));
            }
            // the other material must exist already, so mixes never form a cycle
            let mix = match mix_material {
                Some(k) if k < self.scene.materials.len() => Some(MaterialMix {
                    material: k as u32,
                    weight: mix_weight as f32,
                    weight_texture: self.texture_ref(name, "mix_weight_texture", mix_weight_texture)?,
                    weight_angle: angle,
                }),
                Some(k) => {
                    return Err(scene_err(
                        name,
                        "mix_material",
                        format!(
                            "index {k} is not a material added before this one ({} materials)",
                            self.scene.materials.len()
                        ),
                    ))
                }
                None if mix_weight != 0.0 || mix_weight_texture.is_some() || angle.is_some() => {
                    return Err(scene_err(name, "mix_weight", "is set without a mix_material".to_string()))
                }
                None => None,
            };
            let m = Material {
                name: name.to_string(),
                base_color: bc,
                base_color_texture: self.texture_ref(name, "base_color_texture", base_color_texture)?,
                metallic: metallic as f32,
                roughness: roughness as f32,
                metallic_roughness_texture: self.texture_ref(
                    name,
                    "metallic_roughness_texture",
                    metallic_roughness_texture,
                )?,
                normal_texture: self.texture_ref(name, "normal_texture", normal_texture)?,
                normal_scale: normal_scale as f32,
                emissive: non_negative_rgb(name, "emission", &emission)?,
                emissive_texture: self.texture_ref(name, "emission_texture", emission_texture)?,
                specular: specular as f32,
                ior: ior as f32,
                alpha_mode: parse_alpha_mode(alpha_mode, alpha_cutoff)
                    .map_err(|e| scene_err(name, "", e.to_string()))?,
                double_sided,
                light_emitter,
                visible_to_camera,
                terminator_offset: petzval_renderer::scene::TERMINATOR_OFFSET,
                transmission: transmission as f32,
                coat: coat_weight as f32,
                coat_roughness: coat_roughness as f32,
                coat_ior: coat_ior as f32,
                coat_tint: non_negative_rgb(name, "coat_tint", &coat_tint)?,
                scatter_tint: non_negative_rgb(name, "scatter_tint", &scatter_tint)?,
                metal_fresnel,
                specular_tint: non_negative_rgb(name, "specular_tint", &specular_tint)?,
                translucent,
                mix,
                anisotropy,
            };
            let mut m = m;
            for (field, rows) in uv_transforms.unwrap_or_default() {
                let slot = match field.as_str() {
                    "base_color_texture" => &mut m.base_color_texture,
                    "metallic_roughness_texture" => &mut m.metallic_roughness_texture,
                    "normal_texture" => &mut m.normal_texture,
                    "emission_texture" => &mut m.emissive_texture,
                    "mix_weight_texture" => match m.mix.as_mut() {
                        Some(mix) => &mut mix.weight_texture,
                        None => {
                            return Err(scene_err(name, "uv_transforms", "\"mix_weight_texture\" has no texture".into()))
                        }
                    },
                    other => {
                        return Err(scene_err(
                            name,
                            "uv_transforms",
                            format!("{other:?} is not a texture field (base_color_texture, metallic_roughness_texture, normal_texture, emission_texture, mix_weight_texture)"),
                        ))
                    }
                };
                let Some(tex) = slot.as_mut() else {
                    return Err(scene_err(name, "uv_transforms", format!("{field:?} has no texture")));
                };
                let ok = rows.len() == 2 && rows.iter().all(|r| r.len() == 3 && r.iter().all(|v| v.is_finite()));
                if !ok {
                    return Err(scene_err(
                        name,
                        "uv_transforms",
                        format!("{field:?}: expected 2 rows of 3 finite numbers, got {rows:?}"),
                    ));
                }
                let v = |i: usize, j: usize| rows[i][j] as f32;
                tex.transform = Some(UvTransform {
                    m: glam::Mat2::from_cols(Vec2::new(v(0, 0), v(1, 0)), Vec2::new(v(0, 1), v(1, 1))),
                    offset: Vec2::new(v(0, 2), v(1, 2)),
                });
            }
            self.scene.materials.push(m);
            Ok(self.scene.materials.len() - 1)
        })
    }

    /// Adds a copy of material `material` with an object's ray visibility and shadow-terminator
    /// settings; returns its index (see the stub).
    #[pyo3(signature = (material, visible_to_camera = true, terminator_offset = 0.1))]
    fn material_variant(
        &mut self,
        material: usize,
        visible_to_camera: bool,
        terminator_offset: f64,
    ) -> PyResult<usize> {
        guard(|| {
            let Some(m) = self.scene.materials.get(material) else {
                return Err(scene_err(
                    "",
                    "material",
                    format!("index {material} is out of range ({} materials)", self.scene.materials.len()),
                ));
            };
            if !(terminator_offset.is_finite() && (0.0..=1.0).contains(&terminator_offset)) {
                return Err(scene_err(&m.name, "terminator_offset", format!("{terminator_offset} is outside [0, 1]")));
            }
            let variant = Material {
                name: format!("{} (object settings)", m.name),
                visible_to_camera,
                terminator_offset: terminator_offset as f32,
                ..m.clone()
            };
            self.scene.materials.push(variant);
            Ok(self.scene.materials.len() - 1)
        })
    }

    /// Adds a triangle mesh (see the stub).
    #[pyo3(signature = (positions, triangles, material_ids = None, normals = None, uvs = None, tangents = None, transform = None, name = "", colors = None))]
    #[allow(clippy::too_many_arguments)]
    fn add_mesh(
        &mut self,
        positions: PyArrayLike2<'_, f32, AllowTypeChange>,
        triangles: PyArrayLike2<'_, i64, AllowTypeChange>,
        material_ids: Option<PyArrayLike1<'_, i64, AllowTypeChange>>,
        normals: Option<PyArrayLike2<'_, f32, AllowTypeChange>>,
        uvs: Option<PyArrayLike2<'_, f32, AllowTypeChange>>,
        tangents: Option<PyArrayLike2<'_, f32, AllowTypeChange>>,
        transform: Option<PyArrayLike2<'_, f64, AllowTypeChange>>,
        name: &str,
        colors: Option<PyArrayLike2<'_, f32, AllowTypeChange>>,
    ) -> PyResult<usize> {
        guard(|| {
            // 1. Shapes and values.
            let p = positions.as_array();
            let t = triangles.as_array();
            if p.ncols() != 3 {
                return Err(scene_err(name, "positions", format!("expected (N, 3), got {:?}", p.shape())));
            }
            if t.ncols() != 3 {
                return Err(scene_err(name, "triangles", format!("expected (M, 3), got {:?}", t.shape())));
            }
            let (nv, nt) = (p.nrows(), t.nrows());
            if p.iter().any(|v| !v.is_finite()) {
                return Err(scene_err(name, "positions", "contain non-finite values".into()));
            }
            if let Some(bad) = t.iter().find(|&&i| i < 0 || i as usize >= nv) {
                return Err(scene_err(name, "triangles", format!("index {bad} is outside 0..{nv}")));
            }
            let xf = match &transform {
                Some(m) => affine_from_rows(name, "transform", &m.as_array())?,
                None => DAffine3::IDENTITY,
            };
            // 2. Object-space attributes (the transform places the mesh as its first instance;
            //    the renderer applies it, flipping the winding of a mirroring one).
            let mut mesh = Mesh::default();
            mesh.positions = (0..nv).map(|i| Vec3::new(p[[i, 0]], p[[i, 1]], p[[i, 2]])).collect();
            mesh.indices = (0..nt).map(|i| [t[[i, 0]] as u32, t[[i, 1]] as u32, t[[i, 2]] as u32]).collect();
            mesh.material_ids = match &material_ids {
                Some(m) => {
                    let m = m.as_array();
                    if m.len() != nt {
                        return Err(scene_err(name, "material_ids", format!("{} ids for {nt} triangles", m.len())));
                    }
                    if let Some(bad) = m.iter().find(|&&i| i < 0 || i as usize >= self.scene.materials.len().max(1)) {
                        return Err(scene_err(
                            name,
                            "material_ids",
                            format!("material {bad} does not exist ({} materials)", self.scene.materials.len()),
                        ));
                    }
                    m.iter().map(|&i| i as u32).collect()
                }
                None => vec![0; nt],
            };
            mesh.normals = match &normals {
                Some(n) => {
                    let n = n.as_array();
                    if n.shape() != [nv, 3] {
                        return Err(scene_err(name, "normals", format!("expected ({nv}, 3), got {:?}", n.shape())));
                    }
                    (0..nv).map(|i| Vec3::new(n[[i, 0]], n[[i, 1]], n[[i, 2]]).normalize_or_zero()).collect()
                }
                None => face_normals(&mesh.positions, &mesh.indices),
            };
            if mesh.normals.iter().any(|n| !n.is_finite()) {
                return Err(scene_err(name, "normals", "contain non-finite values".into()));
            }
            mesh.uv0 = match &uvs {
                Some(u) => {
                    let u = u.as_array();
                    if u.shape() != [nv, 2] {
                        return Err(scene_err(name, "uvs", format!("expected ({nv}, 2), got {:?}", u.shape())));
                    }
                    (0..nv)
                        .map(|i| Vec2::new(u[[i, 0]], u[[i, 1]]))
                        .map(|v| if v.is_finite() { v } else { Vec2::ZERO })
                        .collect()
                }
                None => vec![Vec2::ZERO; nv],
            };
            match &tangents {
                Some(tg) => {
                    let tg = tg.as_array();
                    if tg.shape() != [nv, 4] {
                        return Err(scene_err(name, "tangents", format!("expected ({nv}, 4), got {:?}", tg.shape())));
                    }
                    mesh.tangents = (0..nv)
                        .map(|i| {
                            let v = Vec3::new(tg[[i, 0]], tg[[i, 1]], tg[[i, 2]]).normalize_or_zero();
                            Vec4::new(v.x, v.y, v.z, if tg[[i, 3]] < 0.0 { -1.0 } else { 1.0 })
                        })
                        .collect();
                }
                None => {
                    self.all_tangents = false;
                    mesh.tangents = vec![Vec4::ZERO; nv];
                }
            }
            if let Some(c) = &colors {
                let c = c.as_array();
                if c.nrows() != nv || !(c.ncols() == 3 || c.ncols() == 4) {
                    return Err(scene_err(
                        name,
                        "colors",
                        format!("expected ({nv}, 3) or ({nv}, 4), got {:?}", c.shape()),
                    ));
                }
                if c.iter().any(|v| !v.is_finite()) {
                    return Err(scene_err(name, "colors", "contain non-finite values".into()));
                }
                let alpha = |i: usize| if c.ncols() == 4 { c[[i, 3]] } else { 1.0 };
                mesh.colors =
                    (0..nv).map(|i| Vec4::new(c[[i, 0]], c[[i, 1]], c[[i, 2]], alpha(i)).max(Vec4::ZERO)).collect();
            }
            let id = self.scene.add_mesh(mesh);
            self.scene.add_instance(id, affine_f32(&xf));
            Ok(id as usize)
        })
    }

    /// Adds curves (a Blender Curves object) as round tubes (see the stub); returns the mesh id,
    /// or None when no curve makes a tube.
    #[pyo3(signature = (positions, radii, counts, curve_types = None, material_ids = None, transform = None, name = ""))]
    #[allow(clippy::too_many_arguments)]
    fn add_curves(
        &mut self,
        positions: PyArrayLike2<'_, f64, AllowTypeChange>,
        radii: PyArrayLike1<'_, f64, AllowTypeChange>,
        counts: PyArrayLike1<'_, i64, AllowTypeChange>,
        curve_types: Option<PyArrayLike1<'_, i64, AllowTypeChange>>,
        material_ids: Option<PyArrayLike1<'_, i64, AllowTypeChange>>,
        transform: Option<PyArrayLike2<'_, f64, AllowTypeChange>>,
        name: &str,
    ) -> PyResult<Option<usize>> {
        guard(|| {
            // 1. Shapes and values.
            let points = vec3_rows(name, "positions", &positions.as_array())?;
            let np = points.len();
            let radii: Vec<f64> = radii.as_array().iter().copied().collect();
            if radii.len() != np {
                return Err(scene_err(name, "radii", format!("{} radii for {np} points", radii.len())));
            }
            if let Some(r) = radii.iter().find(|r| !(r.is_finite() && **r >= 0.0)) {
                return Err(scene_err(name, "radii", format!("must be finite and non-negative, got {r}")));
            }
            let counts: Vec<i64> = counts.as_array().iter().copied().collect();
            let nc = counts.len();
            if let Some(c) = counts.iter().find(|&&c| c < 0) {
                return Err(scene_err(name, "counts", format!("has a negative count {c}")));
            }
            let sum: i64 = counts.iter().sum();
            if sum != np as i64 {
                return Err(scene_err(name, "counts", format!("add up to {sum} points, but positions has {np}")));
            }
            let per_curve = |field: &str, v: Option<Vec<i64>>| -> PyResult<Vec<i64>> {
                match v {
                    Some(v) if v.len() != nc => {
                        Err(scene_err(name, field, format!("{} values for {nc} curves", v.len())))
                    }
                    Some(v) => Ok(v),
                    None => Ok(vec![0; nc]),
                }
            };
            let types = per_curve("curve_types", curve_types.map(|a| a.as_array().iter().copied().collect()))?;
            let mats = per_curve("material_ids", material_ids.map(|a| a.as_array().iter().copied().collect()))?;
            if let Some(bad) = mats.iter().find(|&&i| i < 0 || i as usize >= self.scene.materials.len().max(1)) {
                return Err(scene_err(
                    name,
                    "material_ids",
                    format!("material {bad} does not exist ({} materials)", self.scene.materials.len()),
                ));
            }
            let xf = match &transform {
                Some(m) => affine_from_rows(name, "transform", &m.as_array())?,
                None => DAffine3::IDENTITY,
            };
            // 2. Each curve's control points in its basis.
            let mut curves = Vec::with_capacity(nc);
            let mut first = 0usize;
            for k in 0..nc {
                let n = counts[k] as usize;
                let range = first..first + n;
                first += n;
                let curve = blender_curve(&points[range.clone()], &radii[range], types[k])
                    .map_err(|m| scene_err(name, &format!("curve_types[{k}]"), m))?;
                curves.push(TubeCurve { material: mats[k] as u32, ..curve });
            }
            // 3. The tubes, one mesh placed by the transform.
            let (mesh, report) = tube_mesh(&curves);
            if report.bad_counts > 0 || report.over_limit > 0 || report.sides != SIDES {
                self.scene.warnings.push(format!(
                    "curves '{name}': {} of {nc} curves tessellated ({} with too few points, {} over the {} triangle \
                     limit), {} rings per span and {} sides",
                    report.tessellated,
                    report.bad_counts,
                    report.over_limit,
                    MAX_CURVE_TRIANGLES,
                    report.rings_per_span,
                    report.sides
                ));
            }
            if mesh.indices.is_empty() {
                return Ok(None);
            }
            if mesh.positions.iter().any(|p| !p.is_finite()) {
                return Err(scene_err(name, "positions", "a tube vertex is not finite in single precision".into()));
            }
            let mut mesh = mesh;
            let nv = mesh.positions.len();
            mesh.uv0 = vec![Vec2::ZERO; nv];
            mesh.tangents = vec![Vec4::ZERO; nv];
            self.all_tangents = false;
            let id = self.scene.add_mesh(mesh);
            self.scene.add_instance(id, affine_f32(&xf));
            Ok(Some(id as usize))
        })
    }

    /// Places mesh `mesh_id` (from `add_mesh`) once more with a (4, 4) object-to-world matrix.
    #[pyo3(signature = (mesh_id, transform, name = ""))]
    fn add_instance(
        &mut self,
        mesh_id: usize,
        transform: PyArrayLike2<'_, f64, AllowTypeChange>,
        name: &str,
    ) -> PyResult<()> {
        guard(|| {
            self.check_mesh_id(name, mesh_id)?;
            let xf = affine_from_rows(name, "transform", &transform.as_array())?;
            self.scene.add_instance(mesh_id as u32, affine_f32(&xf));
            Ok(())
        })
    }

    /// Places mesh `mesh_id` once per (4, 4) matrix of an (N, 4, 4) array (scatters, particle
    /// and point instancers); returns N. Validated before any is added.
    #[pyo3(signature = (mesh_id, transforms, name = ""))]
    fn add_instances(
        &mut self,
        mesh_id: usize,
        transforms: PyArrayLike3<'_, f64, AllowTypeChange>,
        name: &str,
    ) -> PyResult<usize> {
        guard(|| {
            self.check_mesh_id(name, mesh_id)?;
            let a = transforms.as_array();
            let (n, r, c) = a.dim();
            if (r, c) != (4, 4) {
                return Err(scene_err(name, "transforms", format!("expected (N, 4, 4), got {:?}", a.shape())));
            }
            let mut xfs = Vec::with_capacity(n);
            for k in 0..n {
                let m = a.index_axis(numpy::ndarray::Axis(0), k);
                xfs.push(affine_f32(&affine_from_rows(name, &format!("transforms[{k}]"), &m)?));
            }
            for xf in xfs {
                self.scene.add_instance(mesh_id as u32, xf);
            }
            Ok(n)
        })
    }

    /// Meshes so far (each stored once).
    #[getter]
    fn mesh_count(&self) -> usize {
        self.scene.meshes.len()
    }

    /// Instances so far (placements of meshes).
    #[getter]
    fn instance_count(&self) -> usize {
        self.scene.instances.len()
    }

    /// A point light (W/sr per channel) of radius `radius_m` (Blender's Radius: soft shadows;
    /// 0 = a point): a disc facing each shading point as Cycles' Soft Falloff, or a sphere
    /// (`sphere`, Soft Falloff off).
    #[pyo3(signature = (position, intensity_w_sr, name = "", radius_m = 0.0, sphere = false))]
    fn add_point_light(
        &mut self,
        position: Vec<f64>,
        intensity_w_sr: Vec<f64>,
        name: &str,
        radius_m: f64,
        sphere: bool,
    ) -> PyResult<()> {
        guard(|| {
            let light = Light::Point {
                position: vec3_arg(name, "position", &position)?,
                intensity: non_negative_rgb(name, "intensity_w_sr", &intensity_w_sr)?,
                range: None,
                radius_m: light_radius(name, radius_m)?,
                sphere,
            };
            self.scene.lights.push(light);
            Ok(())
        })
    }

    /// A spot light; `falloff` "gltf" (a squared ramp in cos θ between the cones) or "blender"
    /// (Cycles' smoothstep, with Spot Blend = 1 − inner/outer); `radius_m` and `sphere` as the
    /// point light's.
    #[pyo3(signature = (position, direction, intensity_w_sr, inner_cone_rad, outer_cone_rad, name = "", falloff = "gltf", radius_m = 0.0, sphere = false))]
    #[allow(clippy::too_many_arguments)]
    fn add_spot_light(
        &mut self,
        position: Vec<f64>,
        direction: Vec<f64>,
        intensity_w_sr: Vec<f64>,
        inner_cone_rad: f64,
        outer_cone_rad: f64,
        name: &str,
        falloff: &str,
        radius_m: f64,
        sphere: bool,
    ) -> PyResult<()> {
        guard(|| {
            let falloff = match falloff {
                "gltf" => SpotFalloff::Gltf,
                "blender" => SpotFalloff::Blender,
                other => {
                    return Err(scene_err(name, "falloff", format!("expected 'gltf' or 'blender', got '{other}'")))
                }
            };
            let d = vec3_arg(name, "direction", &direction)?.normalize_or_zero();
            if d == Vec3::ZERO {
                return Err(scene_err(name, "direction", "must not be zero".into()));
            }
            if !(outer_cone_rad > 0.0
                && outer_cone_rad <= std::f64::consts::PI
                && inner_cone_rad >= 0.0
                && inner_cone_rad <= outer_cone_rad)
            {
                return Err(scene_err(
                    name,
                    "cone",
                    format!("need 0 ≤ inner ({inner_cone_rad}) ≤ outer ({outer_cone_rad}) ≤ π"),
                ));
            }
            self.scene.lights.push(Light::Spot {
                position: vec3_arg(name, "position", &position)?,
                direction: d,
                intensity: non_negative_rgb(name, "intensity_w_sr", &intensity_w_sr)?,
                inner_cone_rad: inner_cone_rad as f32,
                outer_cone_rad: outer_cone_rad as f32,
                range: None,
                falloff,
                radius_m: light_radius(name, radius_m)?,
                sphere,
            });
            Ok(())
        })
    }

    /// A directional light whose disc spans `angle_rad` (Blender's Angle, the angular diameter;
    /// 0 = parallel light).
    #[pyo3(signature = (direction, irradiance_w_m2, name = "", angle_rad = 0.0))]
    fn add_sun_light(
        &mut self,
        direction: Vec<f64>,
        irradiance_w_m2: Vec<f64>,
        name: &str,
        angle_rad: f64,
    ) -> PyResult<()> {
        guard(|| {
            let d = vec3_arg(name, "direction", &direction)?.normalize_or_zero();
            if d == Vec3::ZERO {
                return Err(scene_err(name, "direction", "must not be zero".into()));
            }
            self.scene.lights.push(Light::Directional {
                direction: d,
                irradiance: non_negative_rgb(name, "irradiance_w_m2", &irradiance_w_m2)?,
                angle_rad: if angle_rad.is_finite() && (0.0..std::f64::consts::PI).contains(&angle_rad) {
                    angle_rad as f32
                } else {
                    return Err(scene_err(name, "angle_rad", format!("must be in [0, π), got {angle_rad}")));
                },
            });
            Ok(())
        })
    }

    /// A uniform environment.
    fn set_environment_color(&mut self, rgb: Vec<f64>) -> PyResult<()> {
        guard(|| {
            let c = non_negative_rgb("world", "rgb", &rgb)?;
            self.scene.environment = if c == Vec3::ZERO { Environment::Black } else { Environment::Constant(c) };
            Ok(())
        })
    }

    /// An equirectangular environment, row 0 at the top.
    #[pyo3(signature = (pixels, strength = 1.0, rotation_rad = 0.0, name = ""))]
    fn set_environment_map(
        &mut self,
        pixels: PyArrayLike3<'_, f32, AllowTypeChange>,
        strength: f64,
        rotation_rad: f64,
        name: &str,
    ) -> PyResult<()> {
        guard(|| {
            let a = pixels.as_array();
            let (h, w, c) = a.dim();
            if h == 0 || w == 0 || c < 3 {
                return Err(scene_err(name, "pixels", format!("expected an (H, W, 3|4) image, got {:?}", a.shape())));
            }
            let texels: Vec<Vec3> = (0..h)
                .flat_map(|y| (0..w).map(move |x| (y, x)))
                .map(|(y, x)| Vec3::new(a[[y, x, 0]], a[[y, x, 1]], a[[y, x, 2]]))
                .collect();
            let label = if name.is_empty() { "environment" } else { name };
            let map = EnvironmentMap::new(label, w, h, texels, strength as f32, rotation_rad as f32).map_err(py_err)?;
            self.scene.environment = Environment::Map(map);
            Ok(())
        })
    }

    /// Triangles so far, over all instances (a mesh counted once per placement).
    /// Film > Transparent: camera rays that meet no surface carry no radiance (RGB and alpha 0);
    /// the environment still lights the scene.
    #[getter]
    fn transparent_background(&self) -> bool {
        self.scene.transparent_background
    }

    #[setter]
    fn set_transparent_background(&mut self, on: bool) {
        self.scene.transparent_background = on;
    }

    #[getter]
    fn triangle_count(&self) -> usize {
        self.scene.instanced_triangle_count()
    }

    /// Warnings so far.
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.scene.warnings.clone()
    }
}

/// Area-weighted vertex normals (unit; +z where a vertex has no area around it).
pub(crate) fn face_normals(positions: &[Vec3], indices: &[[u32; 3]]) -> Vec<Vec3> {
    let mut n = vec![Vec3::ZERO; positions.len()];
    for t in indices {
        let (a, b, c) = (positions[t[0] as usize], positions[t[1] as usize], positions[t[2] as usize]);
        let f = (b - a).cross(c - a);
        for &i in t {
            n[i as usize] += f;
        }
    }
    n.into_iter().map(|v| v.try_normalize().unwrap_or(Vec3::Z)).collect()
}

/// An (N, 3) array of finite values as points.
fn vec3_rows(name: &str, field: &str, a: &numpy::ndarray::ArrayView2<'_, f64>) -> PyResult<Vec<DVec3>> {
    if a.ncols() != 3 {
        return Err(scene_err(name, field, format!("expected (N, 3), got {:?}", a.shape())));
    }
    if a.iter().any(|v| !v.is_finite()) {
        return Err(scene_err(name, field, "contain non-finite values".into()));
    }
    Ok((0..a.nrows()).map(|i| DVec3::new(a[[i, 0]], a[[i, 1]], a[[i, 2]])).collect())
}

/// One Blender curve as Cycles renders it (material 0):
///
/// | `curve_type` | rendered as |
/// |---|---|
/// | 0 CATMULL_ROM | Catmull-Rom through the points, pinned (the end points repeated, as Cycles does) |
/// | 1 POLY | straight spans (Cycles' linear thick curves) |
/// | 2 BEZIER, 3 NURBS | as CATMULL_ROM through the control points (Cycles ignores handles, weights and knots) |
/// | other | an error |
fn blender_curve(p: &[DVec3], r: &[f64], kind: i64) -> Result<TubeCurve, String> {
    let (basis, wrap) = match kind {
        0 | 2 | 3 => (Basis::CatmullRom, CurveWrap::Pinned),
        1 => (Basis::Linear, CurveWrap::Nonperiodic),
        k => return Err(format!("unknown curve type {k} (0 Catmull-Rom, 1 poly, 2 Bézier, 3 NURBS)")),
    };
    Ok(TubeCurve { points: p.to_vec(), radii: r.to_vec(), basis, wrap, material: 0 })
}

/// A light's radius in metres: finite and ≥ 0.
fn light_radius(name: &str, radius_m: f64) -> PyResult<f32> {
    if (0.0..=1e6).contains(&radius_m) {
        Ok(radius_m as f32)
    } else {
        Err(scene_err(name, "radius_m", format!("must be in [0, 1e6] m, got {radius_m}")))
    }
}

// ---------------------------------------------------------------------------------------------

// Rendering
