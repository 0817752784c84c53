//! Scenes: triangle meshes in world space, glTF PBR materials and textures, punctual lights,
//! an environment and the file's cameras. Built by the glTF loader ([`gltf`]), the
//! built-in demo ([`demo`]) or in memory (the Blender add-on and the USD stage).
//!
//! Units: metres; world space is glTF's (+y up, right-handed). Colours are linear Rec.709.
//! Light units are Blender's radiometric ones: glTF candela and lux are divided by 683 lm/W
//! (the luminous efficacy the Blender glTF exporter uses), so a scene exported from Blender
//! renders with the brightness Cycles gives it.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `environment` | [`Environment`]: constant colour or equirectangular EXR map | radiance | black |
//! | `Light::Point.intensity` | RGB | W/sr | — |
//! | `Light::Spot.inner_cone_rad`, `outer_cone_rad` | f32 | radians | 0, π/4 |
//! | `Light::Directional.irradiance` | RGB | W/m² | — |
//! | `Material.alpha_cutoff` | f32 (alpha mask) | — | 0.5 |

use glam::{Affine3A, Vec2, Vec3, Vec4};
use std::sync::Arc;

pub mod demo;
pub mod environment;
pub mod gltf;
pub mod texture;

pub use environment::Environment;
pub use texture::Texture;

/// A reference to a texture and the UV set it reads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TextureRef {
    /// Index into [`Scene::textures`].
    pub index: usize,
    /// UV set (glTF `texCoord`; 0 or 1).
    pub uv_set: u32,
}

/// How alpha is used.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AlphaMode {
    /// Alpha ignored.
    Opaque,
    /// Cut out below the cutoff.
    Mask(f32),
    /// Blended: treated as stochastic transparency with probability 1 − alpha.
    Blend,
}

/// A glTF metallic-roughness material.
#[derive(Debug, Clone, PartialEq)]
pub struct Material {
    /// Name (for reports).
    pub name: String,
    /// Base colour (linear RGB) and alpha.
    pub base_color: Vec4,
    /// Base colour texture (sRGB-decoded, multiplies `base_color`).
    pub base_color_texture: Option<TextureRef>,
    /// Metallic factor.
    pub metallic: f32,
    /// Perceptual roughness factor.
    pub roughness: f32,
    /// Metallic (B) and roughness (G) texture.
    pub metallic_roughness_texture: Option<TextureRef>,
    /// Tangent-space normal map.
    pub normal_texture: Option<TextureRef>,
    /// Normal map scale.
    pub normal_scale: f32,
    /// Emitted radiance (factor × `KHR_materials_emissive_strength`), linear RGB.
    pub emissive: Vec3,
    /// Emissive texture (multiplies `emissive`).
    pub emissive_texture: Option<TextureRef>,
    /// Dielectric specular strength (`KHR_materials_specular` specularFactor; 1 = F0 of 0.04).
    pub specular: f32,
    /// Index of refraction for the dielectric F0 (`KHR_materials_ior`, default 1.5).
    pub ior: f32,
    /// Alpha mode.
    pub alpha_mode: AlphaMode,
    /// Double sided.
    pub double_sided: bool,
}

impl Default for Material {
    fn default() -> Self {
        Material {
            name: "default".into(),
            base_color: Vec4::ONE,
            base_color_texture: None,
            metallic: 1.0,
            roughness: 1.0,
            metallic_roughness_texture: None,
            normal_texture: None,
            normal_scale: 1.0,
            emissive: Vec3::ZERO,
            emissive_texture: None,
            specular: 1.0,
            ior: 1.5,
            alpha_mode: AlphaMode::Opaque,
            double_sided: false,
        }
    }
}

impl Material {
    /// Whether the material emits light.
    pub fn is_emissive(&self) -> bool {
        self.emissive.max_element() > 0.0
    }
}

/// A punctual light (KHR_lights_punctual), in world space.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Light {
    /// Point light.
    Point {
        /// Position.
        position: Vec3,
        /// Radiant intensity per channel (W/sr).
        intensity: Vec3,
        /// Range (glTF `range`; None = infinite).
        range: Option<f32>,
    },
    /// Spot light.
    Spot {
        /// Position.
        position: Vec3,
        /// Unit direction the light points to.
        direction: Vec3,
        /// Radiant intensity on the axis (W/sr).
        intensity: Vec3,
        /// Full intensity inside this angle.
        inner_cone_rad: f32,
        /// Zero outside this angle.
        outer_cone_rad: f32,
        /// Range.
        range: Option<f32>,
    },
    /// Directional (sun) light.
    Directional {
        /// Unit direction the light travels.
        direction: Vec3,
        /// Irradiance on a surface facing the light (W/m²).
        irradiance: Vec3,
    },
}

/// A camera stored in the scene file.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneCamera {
    /// Name (glTF node or camera name).
    pub name: String,
    /// Camera-to-world transform (rigid; camera looks down −z, +y up).
    pub to_world: Affine3A,
    /// Vertical field of view (perspective), radians.
    pub yfov_rad: f32,
    /// Aspect ratio width / height if the file states one.
    pub aspect_ratio: Option<f32>,
    /// Near clip distance.
    pub znear: f32,
    /// Far clip distance (None = infinite).
    pub zfar: Option<f32>,
}

/// Triangle meshes flattened into world space.
#[derive(Debug, Clone, Default)]
pub struct Mesh {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Vertex normals (unit; computed from faces when the file has none).
    pub normals: Vec<Vec3>,
    /// Vertex tangents (xyz, w = handedness); zero when absent.
    pub tangents: Vec<Vec4>,
    /// UV set 0.
    pub uv0: Vec<Vec2>,
    /// UV set 1 (empty when absent).
    pub uv1: Vec<Vec2>,
    /// Triangles (vertex indices).
    pub indices: Vec<[u32; 3]>,
    /// Material index per triangle.
    pub material_ids: Vec<u32>,
}

impl Mesh {
    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len()
    }

    /// Appends another mesh, offsetting its indices and material ids.
    pub fn append(&mut self, other: &Mesh, material_offset: u32) {
        let base = self.positions.len() as u32;
        let has_uv1 = !self.uv1.is_empty() || !other.uv1.is_empty();
        if has_uv1 && self.uv1.is_empty() {
            self.uv1 = vec![Vec2::ZERO; self.positions.len()];
        }
        self.positions.extend_from_slice(&other.positions);
        self.normals.extend_from_slice(&other.normals);
        self.tangents.extend_from_slice(&other.tangents);
        self.uv0.extend_from_slice(&other.uv0);
        if has_uv1 {
            if other.uv1.is_empty() {
                self.uv1.extend(std::iter::repeat_n(Vec2::ZERO, other.positions.len()));
            } else {
                self.uv1.extend_from_slice(&other.uv1);
            }
        }
        self.indices.extend(other.indices.iter().map(|t| [t[0] + base, t[1] + base, t[2] + base]));
        self.material_ids.extend(other.material_ids.iter().map(|m| m + material_offset));
    }
}

/// A scene ready to render (before acceleration structures are built).
#[derive(Debug, Clone, Default)]
pub struct Scene {
    /// All triangles in world space.
    pub mesh: Mesh,
    /// Materials (index = material id).
    pub materials: Vec<Material>,
    /// Textures.
    pub textures: Vec<Arc<Texture>>,
    /// Punctual lights.
    pub lights: Vec<Light>,
    /// Environment.
    pub environment: Environment,
    /// Cameras from the file.
    pub cameras: Vec<SceneCamera>,
    /// Warnings collected while loading (shown to the user once).
    pub warnings: Vec<String>,
}
