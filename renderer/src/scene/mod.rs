//! Scenes: triangle meshes (each stored once, in object space) and instances of them (a mesh
//! and an object-to-world transform), glTF PBR materials and textures, punctual lights,
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
//! | `Material.visible_to_camera` | bool: camera rays see the surface | — | true |
//! | `Material.terminator_offset` | f32: Blender's Shadow Terminator Geometry Offset | cosine | 0.1 |
//! | `Material.transmission` | f32 in [0, 1]: glass share of the dielectric part | — | 0 |
//! | `Material.scatter_tint` | RGB multiplying all scattered light (Blender's Glass and Refraction colour) | — | white |
//! | `Material.metal_fresnel` | [`MetalFresnel`]: F82 tint (Specular/Edge Tint) or constant (Glossy BSDF) | — | F82, white |
//! | `Material.specular_tint` | RGB multiplying the dielectric layer's F0 (Principled Specular Tint) | — | white |
//! | `Material.translucent` | bool: scatters through the surface (Translucent BSDF) | — | false |
//! | `Material.mix` | [`MaterialMix`]: another material scattering with a probability (Mix Shader) | — | none |
//! | `Instance.mesh` | u32 | index into `Scene::meshes` | — |
//! | `Instance.object_to_world` | [`Affine3A`] (any invertible affine map: rotation, non-uniform or negative scale, shear) | metres | — |
//!
//! A mesh referenced by one instance costs what it did when scenes were one flattened mesh (the
//! renderer bakes it into world space); a mesh referenced by many costs one copy plus 80 B per
//! instance here (and about 200 B more per instance in the two-level BVH, see
//! [`crate::integrator::accel`]). A negative-determinant transform mirrors the mesh: its winding
//! flips with it (glTF), so the front side stays the side the normals point to.

use glam::{Affine3A, Vec2, Vec3, Vec4};
use std::sync::Arc;

pub mod curves;
pub mod demo;
pub mod environment;
pub mod gltf;
pub mod normals;
pub mod texture;

pub use environment::Environment;
pub use texture::Texture;

/// Blender's default Shadow Terminator > Geometry Offset (0.1), [`Material::terminator_offset`]'s
/// default: shadow rays whose light direction makes a cosine below about this with the shading
/// or the geometric normal leave from the smooth surface.
pub const TERMINATOR_OFFSET: f32 = 0.1;

/// A reference to a texture and the UV set it reads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TextureRef {
    /// Index into [`Scene::textures`].
    pub index: usize,
    /// UV set (glTF `texCoord`; 0 or 1).
    pub uv_set: u32,
    /// A transform of the texture coordinates before the lookup (USD's `UsdTransform2d`).
    pub transform: Option<UvTransform>,
}

/// An affine map of texture coordinates (the renderer's top-left origin): `uv' = m · uv + offset`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UvTransform {
    /// Linear part.
    pub m: glam::Mat2,
    /// Translation.
    pub offset: Vec2,
}

impl UvTransform {
    /// Applies the map.
    #[inline]
    pub fn apply(&self, uv: Vec2) -> Vec2 {
        self.m * uv + self.offset
    }
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
    /// The emitting surface of a light (an area light from USD or the add-on), which Cycles does
    /// not treat as geometry: it casts no shadow and is seen only from its front (from behind,
    /// rays pass through it).
    pub light_emitter: bool,
    /// Whether camera rays see the surface (Blender's Ray Visibility > Camera, which Blender 5
    /// turns off for lights). When false, a camera ray goes on through it; every other ray
    /// (reflections, bounces, shadow rays) treats it as before.
    pub visible_to_camera: bool,
    /// Blender's Shadow Terminator > Geometry Offset of the objects using it: near the terminator
    /// of a smooth-shaded mesh, shadow rays leave from the smooth surface its vertex normals
    /// describe, within this cosine of grazing (0 = from the flat triangle). Blender's default,
    /// 0.1, for glTF and USD, which do not carry it.
    pub terminator_offset: f32,
    /// Transmission (`KHR_materials_transmission` transmissionFactor, Blender's Transmission
    /// Weight): the share of the dielectric part that is glass, refracting by `ior`.
    pub transmission: f32,
    /// Clear coat weight (Blender's Coat Weight, `KHR_materials_clearcoat` clearcoatFactor,
    /// UsdPreviewSurface clearcoat): 0 = none.
    pub coat: f32,
    /// The coat's perceptual roughness (Coat Roughness, clearcoatRoughnessFactor,
    /// clearcoatRoughness).
    pub coat_roughness: f32,
    /// The coat's index of refraction (Coat IOR; 1.5 for glTF and USD).
    pub coat_ior: f32,
    /// The coat's colour head-on (Coat Tint, linear RGB; white for glTF and USD).
    pub coat_tint: Vec3,
    /// A colour multiplying everything the surface scatters (reflected and refracted, every
    /// lobe), not its emission: the colour of Blender's Glass, Glossy and Refraction BSDFs,
    /// which scale their whole closure. White (none) for glTF and USD.
    pub scatter_tint: Vec3,
    /// The metal's Fresnel reflectance (its F0 is the base colour): Schlick's with Cycles' F82
    /// tint (Blender's Specular Tint on a metallic Principled BSDF, the Metallic BSDF's Edge
    /// Tint; white = plain Schlick, glTF and USD), or the base colour at every angle (Blender's
    /// Glossy BSDF).
    pub metal_fresnel: MetalFresnel,
    /// The dielectric layer's Specular Tint (Blender's Principled Specular Tint on the
    /// non-metallic part, a coloured `KHR_materials_specular` specularColorFactor; linear RGB,
    /// non-negative): F0 × tint head-on, still 1 at grazing, as Cycles has it. White = none.
    pub specular_tint: Vec3,
    /// The surface scatters through itself instead of back (every direction mirrored to the
    /// far side: a Lambertian material becomes Blender's Translucent BSDF). False for glTF and
    /// USD.
    pub translucent: bool,
    /// Blender's Mix Shader: with probability `weight` the surface scatters as another
    /// material (chosen per scattering event, an unbiased estimate of the weighted sum of
    /// the two). Emission, alpha and the shading normal stay this material's. None for glTF
    /// and USD.
    pub mix: Option<MaterialMix>,
    /// Anisotropic specular lobes (Blender's Principled Anisotropic, a Glossy BSDF's
    /// Anisotropy); None: isotropic.
    pub anisotropy: Option<Anisotropy>,
}

/// A metal's Fresnel reflectance against the angle of incidence: see [`Material::metal_fresnel`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MetalFresnel {
    /// Schlick's from F0 (the base colour) to 1 at grazing, less Cycles' F82-tint term
    /// b·μ·(1 − μ)⁶ that makes it `tint` × Schlick's at μ = 1/7 (about 82°; Kutz et al., "Novel
    /// aspects of the Adobe Standard Material"). A white tint is plain Schlick.
    F82 {
        /// Linear RGB in [0, 1].
        tint: Vec3,
    },
    /// The base colour at every angle (no Fresnel: Blender's Glossy BSDF).
    Constant,
}

impl Default for MetalFresnel {
    fn default() -> Self {
        MetalFresnel::F82 { tint: Vec3::ONE }
    }
}

impl MetalFresnel {
    /// Whether it is plain Schlick (F82 with a white tint), the renderer's default path.
    pub fn is_schlick(&self) -> bool {
        matches!(self, MetalFresnel::F82 { tint } if *tint == Vec3::ONE)
    }
}

/// The second half of a Mix Shader: see [`Material::mix`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MaterialMix {
    /// Index of the other material in [`Scene::materials`] (it may mix further).
    pub material: u32,
    /// Probability of scattering as that material, in [0, 1].
    pub weight: f32,
    /// A mask multiplying `weight` where the surface is hit: its red channel, clamped to
    /// [0, 1] (a Mix Shader factor from an image).
    pub weight_texture: Option<TextureRef>,
    /// A factor of the viewing angle multiplying `weight` (a Mix Shader factor from a Fresnel or
    /// Layer Weight node).
    pub weight_angle: Option<AngleWeight>,
}

/// A Mix Shader factor that depends on the angle between the view and the shading normal, as
/// Cycles' nodes compute it (μ = |cos| of that angle; front or back as the geometric normal says).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AngleWeight {
    /// The Fresnel node: the dielectric reflectance of `ior` at μ (1/ior seen from behind).
    Fresnel {
        /// Index of refraction.
        ior: f32,
    },
    /// Layer Weight's Fresnel output: the reflectance of 1/(1 − blend) (its inverse from behind).
    LayerFresnel {
        /// Blend in [0, 1].
        blend: f32,
    },
    /// Layer Weight's Facing output: 1 − μ^k, k = 2·blend up to 0.5, 0.5/(1 − blend) above.
    LayerFacing {
        /// Blend in [0, 1].
        blend: f32,
    },
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
            light_emitter: false,
            visible_to_camera: true,
            terminator_offset: TERMINATOR_OFFSET,
            transmission: 0.0,
            coat: 0.0,
            coat_roughness: 0.03,
            coat_ior: 1.5,
            coat_tint: Vec3::ONE,
            scatter_tint: Vec3::ONE,
            metal_fresnel: MetalFresnel::default(),
            specular_tint: Vec3::ONE,
            translucent: false,
            mix: None,
            anisotropy: None,
        }
    }
}

/// Anisotropic specular lobes: how α = roughness² becomes (α_x along the tangent, α_y across),
/// and the tangent, turned about the shading normal.
///
/// | name | type | unit | default |
/// |---|---|---|---|
/// | `kind` | [`AnisotropyKind`]: Cycles' scaled α, or `KHR_materials_anisotropy`'s | — | — |
/// | `rotation_turns` | tangent turned about the normal (right-handed) | turns | 0 |
/// | `tangent` | [`AnisotropyTangent`] | — | radial about the object's local Z (Blender's unlinked Tangent input) |
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Anisotropy {
    /// How α splits into α_x and α_y.
    pub kind: AnisotropyKind,
    /// The tangent's rotation about the shading normal, in turns (Blender's Anisotropic Rotation,
    /// glTF's anisotropyRotation / 2π).
    pub rotation_turns: f32,
    /// Where the tangent comes from.
    pub tangent: AnisotropyTangent,
}

/// How an anisotropic material's α = roughness² becomes (α_x, α_y).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AnisotropyKind {
    /// Cycles: α scaled by x along the tangent and y across, each side saturated at 1
    /// (Principled Anisotropic A: (1/a, a), a = √(1 − 0.9·A); Glossy BSDF Anisotropy A ≥ 0:
    /// (1 − A, 1/(1 − A)), A < 0: (1/(1 + A), 1 + A)).
    Scale(glam::Vec2),
    /// `KHR_materials_anisotropy`: α_t = mix(α, 1, strength²) along the tangent, α across.
    Khr(f32),
}

impl Anisotropy {
    /// Blender's Principled BSDF Anisotropic `a` (clamped to [0, 1]) and Anisotropic Rotation
    /// (turns), with the tangent `tangent`; None where `a` is 0.
    pub fn principled(a: f32, rotation_turns: f32, tangent: AnisotropyTangent) -> Option<Self> {
        let a = if a.is_finite() { a.clamp(0.0, 1.0) } else { 0.0 };
        if a <= 0.0 {
            return None;
        }
        let aspect = (1.0 - a * 0.9).sqrt();
        let rotation_turns = if rotation_turns.is_finite() { rotation_turns } else { 0.0 };
        let kind = AnisotropyKind::Scale(glam::Vec2::new(1.0 / aspect, aspect));
        Some(Anisotropy { kind, rotation_turns, tangent })
    }

    /// Blender's Glossy BSDF Anisotropy `a` (clamped to ±0.99) and Rotation (turns); None
    /// where |a| ≤ 10⁻⁴ (Cycles' isotropic case).
    pub fn glossy(a: f32, rotation_turns: f32, tangent: AnisotropyTangent) -> Option<Self> {
        let a = if a.is_finite() { a.clamp(-0.99, 0.99) } else { 0.0 };
        if a.abs() <= 1e-4 {
            return None;
        }
        let scale =
            if a < 0.0 { glam::Vec2::new(1.0 / (1.0 + a), 1.0 + a) } else { glam::Vec2::new(1.0 - a, 1.0 / (1.0 - a)) };
        let rotation_turns = if rotation_turns.is_finite() { rotation_turns } else { 0.0 };
        Some(Anisotropy { kind: AnisotropyKind::Scale(scale), rotation_turns, tangent })
    }

    /// `KHR_materials_anisotropy`'s anisotropyStrength (clamped to [0, 1]) and
    /// anisotropyRotation (radians) along the UV map's tangent; None where the strength is 0.
    pub fn khr(strength: f32, rotation_rad: f32) -> Option<Self> {
        let s = if strength.is_finite() { strength.clamp(0.0, 1.0) } else { 0.0 };
        if s <= 0.0 {
            return None;
        }
        let rotation_turns = if rotation_rad.is_finite() { rotation_rad / std::f32::consts::TAU } else { 0.0 };
        Some(Anisotropy { kind: AnisotropyKind::Khr(s), rotation_turns, tangent: AnisotropyTangent::UvMap })
    }
}

/// Where an anisotropic material's tangent comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AnisotropyTangent {
    /// Blender's radial tangent about the object's local X (0), Y (1) or Z (2) axis through
    /// the centre of its texture space (the mesh's bounding box): for Z, (−(y − c_y)/e_y,
    /// (x − c_x)/e_x, 0) with c the centre and e the extents (Cycles' Tangent node, radial;
    /// Blender's default for a Principled BSDF's unlinked Tangent input).
    Radial(u8),
    /// Along +u of the UV map (the mesh's tangents where it has them, else derived from its
    /// UVs; Cycles' Tangent node with a UV map).
    UvMap,
}

impl Material {
    /// Whether the material emits light.
    pub fn is_emissive(&self) -> bool {
        self.emissive.max_element() > 0.0
    }
}

/// How a spot light fades from its inner to its outer cone.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SpotFalloff {
    /// KHR_lights_punctual's: a squared ramp in cos θ from 0 at the outer cone to 1 at the
    /// inner one (glTF files other exporters wrote).
    #[default]
    Gltf,
    /// Blender's (Cycles' `spot_light_attenuation`): a smoothstep in cos θ from 0 at the outer
    /// cone θo over (1 − cos θo)·blend, with blend = 1 − inner/outer (how the inner cone carries
    /// Blender's Spot Blend: inner = outer·(1 − blend)). Live Blender scenes, USD, and glTF files Blender wrote.
    Blender,
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
        /// Radius of the emitter (Blender's Radius, USD `inputs:radius`); 0 = a point. Rendered
        /// as Cycles does with Soft Falloff: a disc of this radius facing the shading point.
        radius_m: f32,
        /// Emit from a sphere of `radius_m` instead (UsdLux's SphereLight; Cycles with Soft
        /// Falloff off): the same intensity far away, I/d² on a surface facing it at any d > r.
        sphere: bool,
    },
    /// Spot light.
    Spot {
        /// Position.
        position: Vec3,
        /// Unit direction the light points to.
        direction: Vec3,
        /// Radiant intensity on the axis (W/sr).
        intensity: Vec3,
        /// Full intensity inside this angle (≥ `outer_cone_rad`: a hard edge at the outer angle).
        inner_cone_rad: f32,
        /// Zero outside this angle.
        outer_cone_rad: f32,
        /// Range.
        range: Option<f32>,
        /// The fade between the cones.
        falloff: SpotFalloff,
        /// Radius of the emitter, as the point light's.
        radius_m: f32,
        /// A sphere rather than a disc, as the point light's.
        sphere: bool,
    },
    /// Directional (sun) light.
    Directional {
        /// Unit direction the light travels.
        direction: Vec3,
        /// Irradiance on a surface facing the light (W/m²).
        irradiance: Vec3,
        /// Angular diameter of the light's disc (Blender's Angle, USD `inputs:angle`); 0 = one
        /// direction. Directions are drawn uniformly in the cone of half this angle, and the
        /// irradiance on a surface facing the light stays `irradiance` (Cycles' normalisation).
        angle_rad: f32,
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
    /// Orthographic: the metres the larger image side spans (Blender's Orthographic Scale;
    /// glTF's 2·max(xmag, ymag)); None = perspective (`yfov_rad`).
    pub ortho_scale_m: Option<f32>,
    /// Near clip distance.
    pub znear: f32,
    /// Far clip distance (None = infinite).
    pub zfar: Option<f32>,
}

/// A triangle mesh in its object space (placed in the world by [`Instance`]s).
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
    /// Vertex colours, linear RGBA, multiplying the material's base colour and alpha (glTF's
    /// `COLOR_0`); empty when absent.
    pub colors: Vec<Vec4>,
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

    /// Bytes of the mesh's arrays (lengths, not capacities).
    pub fn memory_bytes(&self) -> usize {
        use std::mem::size_of;
        self.positions.len() * size_of::<Vec3>()
            + self.normals.len() * size_of::<Vec3>()
            + self.tangents.len() * size_of::<Vec4>()
            + self.uv0.len() * size_of::<Vec2>()
            + self.uv1.len() * size_of::<Vec2>()
            + self.colors.len() * size_of::<Vec4>()
            + self.indices.len() * size_of::<[u32; 3]>()
            + self.material_ids.len() * size_of::<u32>()
    }

    /// This mesh moved by `xf` (positions by `xf`, normals by the inverse transpose, tangents
    /// by the linear part with `w` × sign(det); a mirroring transform flips the winding so the
    /// front side follows the normals), as the renderer sees an instance of it.
    pub fn transformed(&self, xf: &Affine3A) -> Mesh {
        let lin = glam::Mat3::from(xf.matrix3);
        let det = lin.determinant();
        let sign = if det < 0.0 { -1.0 } else { 1.0 };
        let cof = cofactor(lin) * sign;
        Mesh {
            positions: self.positions.iter().map(|&p| xf.transform_point3(p)).collect(),
            normals: self.normals.iter().map(|&n| (cof * n).normalize_or_zero()).collect(),
            tangents: self
                .tangents
                .iter()
                .map(|t| {
                    if *t == Vec4::ZERO {
                        return *t;
                    }
                    (lin * t.truncate()).normalize_or_zero().extend(if t.w < 0.0 { -sign } else { sign })
                })
                .collect(),
            uv0: self.uv0.clone(),
            uv1: self.uv1.clone(),
            colors: self.colors.clone(),
            indices: if det < 0.0 {
                self.indices.iter().map(|t| [t[0], t[2], t[1]]).collect()
            } else {
                self.indices.clone()
            },
            material_ids: self.material_ids.clone(),
        }
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
        // vertex colours: white where one side has none
        if !self.colors.is_empty() || !other.colors.is_empty() {
            self.colors.resize(base as usize, Vec4::ONE);
            if other.colors.is_empty() {
                self.colors.extend(std::iter::repeat_n(Vec4::ONE, other.positions.len()));
            } else {
                self.colors.extend_from_slice(&other.colors);
            }
        }
        self.indices.extend(other.indices.iter().map(|t| [t[0] + base, t[1] + base, t[2] + base]));
        self.material_ids.extend(other.material_ids.iter().map(|m| m + material_offset));
    }
}

/// Cofactor matrix of `m` (= det × inverse transpose; defined for singular matrices too).
pub fn cofactor(m: glam::Mat3) -> glam::Mat3 {
    glam::Mat3::from_cols(m.y_axis.cross(m.z_axis), m.z_axis.cross(m.x_axis), m.x_axis.cross(m.y_axis))
}

/// One placement of a mesh in the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Instance {
    /// Index into [`Scene::meshes`].
    pub mesh: u32,
    /// Object-to-world transform (invertible; a singular or non-finite one is skipped with a
    /// warning when the scene is prepared for rendering).
    pub object_to_world: Affine3A,
}

/// A scene ready to render (before acceleration structures are built).
#[derive(Debug, Clone, Default)]
pub struct Scene {
    /// Meshes in object space, each stored once.
    pub meshes: Vec<Mesh>,
    /// Placements of the meshes (a mesh may have any number, including none).
    pub instances: Vec<Instance>,
    /// Materials (index = material id).
    pub materials: Vec<Material>,
    /// Textures.
    pub textures: Vec<Arc<Texture>>,
    /// Punctual lights.
    pub lights: Vec<Light>,
    /// Environment.
    pub environment: Environment,
    /// Transparent background (Blender's Film > Transparent): camera rays that meet no surface
    /// carry no radiance (alpha 0, RGB 0: premultiplied), while the environment still lights
    /// the scene and shows in reflections and refractions.
    pub transparent_background: bool,
    /// Cameras from the file.
    pub cameras: Vec<SceneCamera>,
    /// Warnings collected while loading (shown to the user once).
    pub warnings: Vec<String>,
    /// The file the scene came from, for messages (empty: built in memory).
    pub source: String,
}

impl Scene {
    /// A scene whose geometry is `mesh`, already in world space (one identity instance).
    pub fn world(mesh: Mesh) -> Scene {
        let mut s = Scene::default();
        s.add_world_mesh(mesh);
        s
    }

    /// Checks every emitted value against [`crate::limits::MAX_RADIANCE`]: an emissive material,
    /// a light or the environment brighter than that (or non-finite) is an error naming it, not an
    /// image of +Inf or black.
    pub fn check_values(&self) -> crate::Result<()> {
        let file = if self.source.is_empty() { "scene" } else { self.source.as_str() };
        let limit = crate::limits::MAX_RADIANCE;
        let check = |location: String, field: &str, v: Vec3| -> crate::Result<()> {
            if v.is_finite() && v.min_element() >= 0.0 && v.max_element() <= limit {
                return Ok(());
            }
            let worst = if v.is_nan() {
                f32::NAN
            } else if v.min_element() < 0.0 {
                v.min_element()
            } else {
                v.max_element()
            };
            Err(crate::Error::scene(
                file,
                location,
                format!(
                    "{field} {worst:e} is outside 0…{limit:e} (the brightest value petzval renders; the film would overflow)"
                ),
            ))
        };
        for (k, m) in self.materials.iter().enumerate() {
            check(format!("material {k} '{}'", m.name), "emission (factor × strength)", m.emissive)?;
            if !(m.scatter_tint.is_finite() && m.scatter_tint.min_element() >= 0.0) {
                return Err(crate::Error::scene(
                    file,
                    format!("material {k} '{}'", m.name),
                    format!("scatter_tint {} must be finite and non-negative", m.scatter_tint),
                ));
            }
            if !(m.specular_tint.is_finite() && m.specular_tint.min_element() >= 0.0) {
                return Err(crate::Error::scene(
                    file,
                    format!("material {k} '{}'", m.name),
                    format!("specular_tint {} must be finite and non-negative", m.specular_tint),
                ));
            }
            self.check_mix(k).map_err(|e| crate::Error::scene(file, format!("material {k} '{}'", m.name), e))?;
        }
        for (k, l) in self.lights.iter().enumerate() {
            match l {
                Light::Point { intensity, .. } => check(format!("light {k} (point)"), "intensity (W/sr)", *intensity)?,
                Light::Spot { intensity, .. } => check(format!("light {k} (spot)"), "intensity (W/sr)", *intensity)?,
                Light::Directional { irradiance, .. } => {
                    check(format!("light {k} (directional)"), "irradiance (W/m²)", *irradiance)?
                }
            }
        }
        match &self.environment {
            Environment::Black => {}
            Environment::Constant(c) => check("environment".into(), "radiance", *c)?,
            Environment::Map(m) => check(
                format!("environment '{}'", m.name()),
                "brightest texel × strength",
                Vec3::splat(m.peak_radiance()),
            )?,
        }
        Ok(())
    }

    /// Checks material `k`'s mix chain: indices in range, weights in [0, 1], no cycle.
    fn check_mix(&self, k: usize) -> std::result::Result<(), String> {
        let (mut at, mut steps) = (k, 0usize);
        while let Some(mix) = self.materials[at].mix {
            if !(mix.weight.is_finite() && (0.0..=1.0).contains(&mix.weight)) {
                return Err(format!("mix weight {} is outside [0, 1]", mix.weight));
            }
            let next = mix.material as usize;
            if next >= self.materials.len() {
                return Err(format!("mix material {next} is out of range ({} materials)", self.materials.len()));
            }
            steps += 1;
            if next == k || steps > self.materials.len() {
                return Err("its mix materials form a cycle".into());
            }
            at = next;
        }
        Ok(())
    }

    /// Stores a mesh (without placing it) and returns its index for [`Scene::add_instance`].
    pub fn add_mesh(&mut self, mesh: Mesh) -> u32 {
        self.meshes.push(mesh);
        (self.meshes.len() - 1) as u32
    }

    /// Places mesh `mesh` with `object_to_world`; returns the instance index.
    pub fn add_instance(&mut self, mesh: u32, object_to_world: Affine3A) -> u32 {
        self.instances.push(Instance { mesh, object_to_world });
        (self.instances.len() - 1) as u32
    }

    /// Stores a mesh already in world space with one identity instance (returns the mesh index).
    pub fn add_world_mesh(&mut self, mesh: Mesh) -> u32 {
        let m = self.add_mesh(mesh);
        self.add_instance(m, Affine3A::IDENTITY);
        m
    }

    /// Every instance baked into one world-space mesh (what scenes were before instancing;
    /// instances of missing meshes are left out).
    pub fn flattened_mesh(&self) -> Mesh {
        let mut out = Mesh::default();
        for inst in &self.instances {
            if let Some(m) = self.meshes.get(inst.mesh as usize) {
                out.append(&m.transformed(&inst.object_to_world), 0);
            }
        }
        out
    }

    /// Replaces meshes and instances by [`Scene::flattened_mesh`] with one identity instance.
    pub fn flatten(&mut self) {
        let mesh = self.flattened_mesh();
        self.meshes.clear();
        self.instances.clear();
        self.add_world_mesh(mesh);
    }

    /// Triangles over all instances (a mesh counted once per instance).
    pub fn instanced_triangle_count(&self) -> usize {
        self.instances.iter().filter_map(|i| self.meshes.get(i.mesh as usize)).map(Mesh::triangle_count).sum()
    }
}
