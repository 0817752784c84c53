//! glTF 2.0 loading (`.gltf` with external or embedded buffers, and binary `.glb`).
//!
//! The file is parsed and validated by the `gltf` crate; buffers and images are read here (so
//! that a missing or broken image is a warning with a visible fallback, not a failed load), and
//! accessors are decoded here with checked byte ranges, so no input can make the loader panic.
//! Everything is flattened into one world-space [`Mesh`]; warnings go to [`Scene::warnings`].
//!
//! | glTF | becomes | notes |
//! |---|---|---|
//! | default scene (else the first; else every root node, with a warning) | nodes walked with their matrix or TRS | a cycle in the node graph is an error |
//! | mesh primitive, mode `TRIANGLES` | triangles of [`Scene::mesh`] | other modes skipped with a warning |
//! | `POSITION`, `NORMAL`, `TANGENT`, `TEXCOORD_0/1`, indices | world space: normals by the inverse transpose, tangents by the matrix with `w` × sign(det); det < 0 flips the winding | any component type (normalized integers too, `KHR_mesh_quantization`) and sparse accessors |
//! | no `NORMAL` | flat face normals (vertices unshared), as the glTF spec requires | |
//! | no `TANGENT` | zero tangents | |
//! | non-finite positions | those triangles dropped with a warning; an error if no triangle is left | |
//! | indices out of range, attribute counts that differ | error naming the mesh and primitive | |
//! | material (metallic-roughness) | [`Material`] | base colour and emissive textures sRGB-decoded, others linear |
//! | `KHR_materials_emissive_strength` | × `Material::emissive` | |
//! | `KHR_materials_specular` `specularFactor` | `Material::specular` | specular colour and textures ignored (warning) |
//! | `KHR_materials_ior` | `Material::ior` | |
//! | `KHR_texture_transform` | ignored, with a warning | |
//! | no material | [`Material::default`] (white, metallic 1, roughness 1) | |
//! | image (PNG, JPEG; file, data URI or bufferView) | [`Texture`], sampler wrap modes, `magFilter` nearest → nearest | missing or undecodable: warning and a 1×1 fallback: magenta for base colour, flat for normal maps, white for metallic-roughness, black for emission |
//! | `KHR_lights_punctual` point, spot | [`Light::Point`], [`Light::Spot`]: `color × intensity / 683` W/sr | see below |
//! | `KHR_lights_punctual` directional | [`Light::Directional`]: `color × intensity / 683` W/m² | |
//! | perspective camera | [`SceneCamera`] (rigid part of the node's world transform) | orthographic cameras skipped with a warning |
//!
//! Light units. Blender's glTF exporter (io_scene_gltf2, as bundled with Blender 5.0.1:
//! `io_scene_gltf2/blender/exp/lights.py`, `__gather_intensity`, lines 138–159, with
//! `PBR_WATTS_TO_LUMENS = 683` from `blender/com/conversion.py` line 10), in its default
//! lighting mode `SPEC`, writes a point or spot light of power `P` W as
//! `intensity = P / (4π) × 683` cd (a spot is exported "as if it were a point": no cone factor)
//! and a sun of strength `E` W/m² as `intensity = E × 683` lx. The importer
//! (`blender/imp/light.py`, lines 57–77) inverts exactly that: `P = I / 683 × 4π` and
//! `E = lux / 683`. A Blender point or spot light of power `P` radiates `P / (4π)` W/sr, so the
//! radiant intensity is `I_cd / 683` W/sr for both, and a sun's irradiance is `lux / 683`
//! W/m²: dividing by 683 is the exact inverse of the exporter. Spot cones: the exporter writes
//! `outerConeAngle = spot_size / 2` and `innerConeAngle = outer × (1 − spot_blend)`
//! (`blender/exp/light_spots.py`, lines 28–47); they are kept as glTF angles.

use super::texture::{srgb_to_linear, Wrap};
use super::{AlphaMode, Light, Material, Mesh, Scene, SceneCamera, Texture, TextureRef};
use crate::{Error, Result};
use glam::{Affine3A, Mat3, Mat4, Quat, Vec2, Vec3, Vec4};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::{Mode, Semantic};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Luminous efficacy (lm/W) Blender's glTF exporter uses to convert watts to lumens.
pub const WATTS_TO_LUMENS: f32 = 683.0;

/// Most node instances one file may expand to (a node shared by several parents is instanced
/// once per path; this bounds that).
const MAX_NODE_INSTANCES: usize = 10_000_000;

/// Loads a `.gltf` or `.glb` file into a [`Scene`].
///
/// Fails (naming the file and, where it applies, the glTF object) on an unreadable, corrupt or
/// truncated file, a missing buffer, out-of-range indices or a file whose triangles are all
/// invalid. Problems that leave the scene usable (a missing texture, an unsupported primitive
/// mode or camera type, ignored extensions, dropped non-finite triangles) are reported in
/// [`Scene::warnings`].
pub fn load_gltf(path: &Path) -> Result<Scene> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let base = path.parent().map(|p| if p.as_os_str().is_empty() { Path::new(".") } else { p });
    load_gltf_slice(&bytes, base, &path.display().to_string())
}

/// Loads glTF from memory. `base_dir` resolves relative URIs (None: only embedded data is
/// allowed); `file_name` is used in messages.
pub fn load_gltf_slice(bytes: &[u8], base_dir: Option<&Path>, file_name: &str) -> Result<Scene> {
    // Defence in depth: the loader checks every index and byte range itself, but the `gltf`
    // crate's accessors rely on its validation; a panic there becomes an error, not a crash.
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| Loader::load(bytes, base_dir, file_name)));
    match result {
        Ok(r) => r,
        Err(payload) => {
            let what = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown".into());
            Err(Error::scene(file_name, "", format!("malformed glTF (loader failure: {what})")))
        }
    }
}

/// What a texture is used for: decides the colour decoding and the fallback.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum TexKind {
    /// Base colour: sRGB, magenta fallback.
    BaseColor,
    /// Emission: sRGB, black fallback (a missing image must not turn a surface into a lamp).
    Emissive,
    /// Metallic-roughness: linear, white fallback (the factors alone).
    Linear,
    /// Normal map: linear, flat fallback.
    Normal,
}

impl TexKind {
    fn srgb(self) -> bool {
        matches!(self, TexKind::BaseColor | TexKind::Emissive)
    }

    fn fallback(self) -> (Vec4, &'static str) {
        match self {
            TexKind::BaseColor => (Vec4::new(1.0, 0.0, 1.0, 1.0), "magenta"),
            TexKind::Emissive => (Vec4::new(0.0, 0.0, 0.0, 1.0), "black"),
            TexKind::Linear => (Vec4::ONE, "white"),
            TexKind::Normal => (Vec4::new(0.5, 0.5, 1.0, 1.0), "flat normal"),
        }
    }
}

struct Loader<'a> {
    file: String,
    base: Option<&'a Path>,
    doc: &'a gltf::Document,
    buffers: Vec<Vec<u8>>,
    scene: Scene,
    /// (glTF texture index, kind) → index into `scene.textures`.
    textures: HashMap<(usize, TexKind), usize>,
    /// Decoded images by glTF image index (Err = the reason it is unusable).
    images: HashMap<usize, std::result::Result<Arc<image::DynamicImage>, String>>,
    /// Index of the default material, once a primitive without material needs it.
    default_material: Option<u32>,
    /// Triangles read, and dropped for non-finite positions.
    triangles_read: usize,
    triangles_dropped: usize,
}

fn named(kind: &str, index: usize, name: Option<&str>) -> String {
    match name {
        Some(n) if !n.is_empty() => format!("{kind} {index} '{n}'"),
        _ => format!("{kind} {index}"),
    }
}

impl<'a> Loader<'a> {
    fn load(bytes: &[u8], base: Option<&Path>, file: &str) -> Result<Scene> {
        let err = |m: String| Error::scene(file, "", m);
        if bytes.is_empty() {
            return Err(err("empty file".into()));
        }
        let gltf::Gltf { document, blob } =
            gltf::Gltf::from_slice_without_validation(bytes).map_err(|e| err(format!("not a valid glTF file: {e}")))?;
        // KHR_mesh_quantization only widens the accessor types allowed for attributes, which
        // the accessor reader below handles; the gltf crate does not know the name.
        let mut json = document.into_json();
        json.extensions_required.retain(|e| e != "KHR_mesh_quantization");
        // POSITION accessors must state min and max, which this loader does not use; many
        // writers omit them, so fill them in rather than reject the file.
        // (The gltf crate's validation also indexes the accessor list with this index.)
        let mut positions = Vec::new();
        for (mi, m) in json.meshes.iter().enumerate() {
            for (pi, p) in m.primitives.iter().enumerate() {
                let key = gltf::json::validation::Checked::Valid(Semantic::Positions);
                if let Some(i) = p.attributes.get(&key).map(|i| i.value()) {
                    if i >= json.accessors.len() {
                        let loc = format!("{}, primitive {pi}", named("mesh", mi, m.name.as_deref()));
                        return Err(Error::scene(file, loc, format!("POSITION accessor {i} does not exist")));
                    }
                    positions.push(i);
                }
            }
        }
        for i in positions {
            let acc = &mut json.accessors[i];
            let zero = || gltf::json::Value::from(vec![0.0f64; 3]);
            acc.min.get_or_insert_with(zero);
            acc.max.get_or_insert_with(zero);
        }
        let doc =
            gltf::Document::from_json(json).map_err(|e| err(format!("invalid glTF: {}", describe_gltf_error(&e))))?;
        let version = &doc.as_json().asset.version;
        if !version.starts_with("2.") {
            return Err(err(format!("glTF version {version} is not supported (2.x only)")));
        }
        let mut loader = Loader {
            file: file.to_string(),
            base,
            doc: &doc,
            buffers: Vec::new(),
            scene: Scene::default(),
            textures: HashMap::new(),
            images: HashMap::new(),
            default_material: None,
            triangles_read: 0,
            triangles_dropped: 0,
        };
        loader.warn_extensions();
        loader.load_buffers(blob)?;
        loader.load_materials();
        loader.walk_nodes()?;
        if loader.triangles_read > 0 && loader.scene.mesh.indices.is_empty() && loader.triangles_dropped > 0 {
            return Err(err(format!(
                "all {} triangles have non-finite vertex positions (NaN or infinity)",
                loader.triangles_read
            )));
        }
        Ok(loader.scene)
    }

    fn warn(&mut self, location: &str, message: impl AsRef<str>) {
        let w = if location.is_empty() {
            format!("{}: {}", self.file, message.as_ref())
        } else {
            format!("{}: {}: {}", self.file, location, message.as_ref())
        };
        if !self.scene.warnings.contains(&w) {
            self.scene.warnings.push(w);
        }
    }

    fn error(&self, location: &str, message: impl Into<String>) -> Error {
        Error::scene(&self.file, location, message)
    }

    fn warn_extensions(&mut self) {
        const HANDLED: &[&str] = &[
            "KHR_lights_punctual",
            "KHR_materials_emissive_strength",
            "KHR_materials_ior",
            "KHR_materials_specular",
            "KHR_mesh_quantization",
            "KHR_texture_transform",
        ];
        let used: Vec<String> = self.doc.extensions_used().map(|s| s.to_string()).collect();
        for ext in used {
            if !HANDLED.contains(&ext.as_str()) {
                self.warn("", format!("extension {ext} is not supported and is ignored"));
            }
        }
    }

    // ---------------------------------------------------------------- buffers and images

    /// Reads a URI: a data URI (base64) or a file relative to the glTF file.
    fn read_uri(&self, uri: &str) -> std::result::Result<Vec<u8>, String> {
        if let Some(rest) = uri.strip_prefix("data:") {
            let (_, data) = rest.split_once(";base64,").ok_or("data URI is not base64")?;
            return base64_decode(data).ok_or_else(|| "data URI has invalid base64".to_string());
        }
        let path: PathBuf = if let Some(rest) = uri.strip_prefix("file://") {
            PathBuf::from(percent_decode(rest))
        } else if uri.split('/').next().is_some_and(|first| first.contains(':') && first.len() > 2) {
            return Err(format!("URI scheme of '{uri}' is not supported (files and data URIs only)"));
        } else {
            let base = self.base.ok_or("external file references need a base directory")?;
            base.join(percent_decode(uri))
        };
        std::fs::read(&path).map_err(|e| format!("cannot read {}: {e}", path.display()))
    }

    fn load_buffers(&mut self, mut blob: Option<Vec<u8>>) -> Result<()> {
        let doc = self.doc;
        let buffers: Vec<_> = doc.buffers().collect();
        for b in buffers {
            let loc = named("buffer", b.index(), b.name());
            let mut data = match b.source() {
                gltf::buffer::Source::Bin => {
                    blob.take().ok_or_else(|| self.error(&loc, "refers to the GLB binary chunk, which is missing"))?
                }
                gltf::buffer::Source::Uri(uri) => self.read_uri(uri).map_err(|m| self.error(&loc, m))?,
            };
            if data.len() < b.length() {
                return Err(self.error(
                    &loc,
                    format!("has {} bytes but byteLength is {} (truncated file?)", data.len(), b.length()),
                ));
            }
            data.truncate(b.length());
            self.buffers.push(data);
        }
        Ok(())
    }

    /// The bytes of a buffer view, checked against its buffer.
    fn view_bytes(&self, view: &gltf::buffer::View) -> std::result::Result<&[u8], String> {
        let buf = self.buffers.get(view.buffer().index()).ok_or("buffer not loaded")?;
        let end = view.offset().checked_add(view.length()).ok_or("bufferView range overflows")?;
        buf.get(view.offset()..end).ok_or_else(|| {
            format!(
                "bufferView {} (bytes {}..{end}) lies outside buffer {} ({} bytes)",
                view.index(),
                view.offset(),
                view.buffer().index(),
                buf.len()
            )
        })
    }

    fn decode_image(&mut self, index: usize) -> std::result::Result<Arc<image::DynamicImage>, String> {
        if let Some(r) = self.images.get(&index) {
            return r.clone();
        }
        let r = self.decode_image_uncached(index);
        self.images.insert(index, r.clone());
        r
    }

    fn decode_image_uncached(&self, index: usize) -> std::result::Result<Arc<image::DynamicImage>, String> {
        let json = self.doc.as_json().images.get(index).ok_or("no such image")?;
        let bytes: Vec<u8> = if let Some(view) = json.buffer_view {
            let view = self.doc.views().nth(view.value()).ok_or("no such bufferView")?;
            self.view_bytes(&view)?.to_vec()
        } else if let Some(uri) = &json.uri {
            self.read_uri(uri)?
        } else {
            return Err("image has neither uri nor bufferView".into());
        };
        let format = image::guess_format(&bytes)
            .map_err(|_| "cannot decode image: format not recognised (PNG and JPEG are supported)".to_string())?;
        // The image crate's default limits (512 MiB per allocation) guard against image bombs.
        let reader = image::ImageReader::with_format(std::io::Cursor::new(&bytes), format);
        let img = reader.decode().map_err(|e| format!("cannot decode image: {e}"))?;
        if img.width() == 0 || img.height() == 0 {
            return Err("image is empty".into());
        }
        Ok(Arc::new(img))
    }

    /// Scene texture for a glTF texture used as `kind` (decoded once per kind).
    fn texture(&mut self, tex: &gltf::Texture, kind: TexKind, used_by: &str) -> usize {
        if let Some(&i) = self.textures.get(&(tex.index(), kind)) {
            return i;
        }
        let json_img = self.doc.as_json().images.get(tex.source().index());
        let img_label = json_img
            .and_then(|j| j.name.clone().or_else(|| j.uri.clone().filter(|u| !u.starts_with("data:"))))
            .unwrap_or_else(|| format!("image {}", tex.source().index()));
        let name = match tex.name() {
            Some(n) if !n.is_empty() => format!("{n} ({img_label})"),
            _ => img_label.clone(),
        };
        let sampler = tex.sampler();
        let wrap = |w: gltf::texture::WrappingMode| match w {
            gltf::texture::WrappingMode::ClampToEdge => Wrap::ClampToEdge,
            gltf::texture::WrappingMode::MirroredRepeat => Wrap::MirroredRepeat,
            gltf::texture::WrappingMode::Repeat => Wrap::Repeat,
        };
        let bilinear = !matches!(sampler.mag_filter(), Some(gltf::texture::MagFilter::Nearest));
        let texture = match self.decode_image(tex.source().index()) {
            Ok(img) => {
                let (w, h) = (img.width(), img.height());
                let texels = image_texels(&img, kind.srgb());
                Texture {
                    name: name.clone(),
                    width: w,
                    height: h,
                    texels,
                    wrap_s: wrap(sampler.wrap_s()),
                    wrap_t: wrap(sampler.wrap_t()),
                    bilinear,
                }
            }
            Err(reason) => {
                let (value, label) = kind.fallback();
                let loc = named("texture", tex.index(), tex.name());
                self.warn(&loc, format!("{img_label} (used by {used_by}): {reason}; using a {label} 1×1 fallback"));
                Texture::constant(&format!("{name} (missing)"), value)
            }
        };
        let i = self.scene.textures.len();
        self.scene.textures.push(Arc::new(texture));
        self.textures.insert((tex.index(), kind), i);
        i
    }

    fn texture_ref(&mut self, tex: &gltf::Texture, tex_coord: u32, kind: TexKind, used_by: &str) -> TextureRef {
        let uv_set = if tex_coord > 1 {
            self.warn(used_by, format!("texCoord {tex_coord} is not supported (UV sets 0 and 1 only); using 0"));
            0
        } else {
            tex_coord
        };
        TextureRef { index: self.texture(tex, kind, used_by), uv_set }
    }

    fn info_ref(&mut self, info: Option<gltf::texture::Info>, kind: TexKind, used_by: &str) -> Option<TextureRef> {
        let info = info?;
        if info.texture_transform().is_some() {
            self.warn(used_by, "KHR_texture_transform is not supported and is ignored");
        }
        Some(self.texture_ref(&info.texture(), info.tex_coord(), kind, used_by))
    }

    // ---------------------------------------------------------------- materials

    fn load_materials(&mut self) {
        let doc = self.doc;
        let materials: Vec<_> = doc.materials().collect();
        for m in materials {
            let index = m.index().unwrap_or(0);
            let loc = named("material", index, m.name());
            let pbr = m.pbr_metallic_roughness();
            let mut base_color = Vec4::from_array(pbr.base_color_factor());
            if !base_color.is_finite() {
                self.warn(&loc, "non-finite baseColorFactor; using white");
                base_color = Vec4::ONE;
            }
            let metallic = self.unit_factor(&loc, "metallicFactor", pbr.metallic_factor(), 1.0);
            let roughness = self.unit_factor(&loc, "roughnessFactor", pbr.roughness_factor(), 1.0);
            let base_color_texture =
                self.info_ref(pbr.base_color_texture(), TexKind::BaseColor, &format!("{loc} baseColorTexture"));
            let metallic_roughness_texture = self.info_ref(
                pbr.metallic_roughness_texture(),
                TexKind::Linear,
                &format!("{loc} metallicRoughnessTexture"),
            );
            let (normal_texture, normal_scale) = match m.normal_texture() {
                Some(n) => {
                    let r =
                        self.texture_ref(&n.texture(), n.tex_coord(), TexKind::Normal, &format!("{loc} normalTexture"));
                    let s = if n.scale().is_finite() { n.scale() } else { 1.0 };
                    (Some(r), s)
                }
                None => (None, 1.0),
            };
            let strength = m.emissive_strength().unwrap_or(1.0);
            let mut emissive = Vec3::from_array(m.emissive_factor()) * strength;
            if !emissive.is_finite() || emissive.min_element() < 0.0 {
                self.warn(&loc, "emission is negative or not finite; using none");
                emissive = Vec3::ZERO;
            }
            let emissive_texture =
                self.info_ref(m.emissive_texture(), TexKind::Emissive, &format!("{loc} emissiveTexture"));
            let specular = match m.specular() {
                Some(s) => {
                    if s.specular_texture().is_some()
                        || s.specular_color_texture().is_some()
                        || s.specular_color_factor() != [1.0, 1.0, 1.0]
                    {
                        self.warn(
                            &loc,
                            "KHR_materials_specular: only specularFactor is used (colour and textures ignored)",
                        );
                    }
                    let f = s.specular_factor();
                    if f.is_finite() && f >= 0.0 {
                        f
                    } else {
                        self.warn(&loc, "invalid specularFactor; using 1");
                        1.0
                    }
                }
                None => 1.0,
            };
            let ior = match m.ior() {
                Some(i) if i.is_finite() && i >= 1.0 => i,
                Some(i) => {
                    self.warn(&loc, format!("KHR_materials_ior ior {i} is invalid; using 1.5"));
                    1.5
                }
                None => 1.5,
            };
            let alpha_mode = match m.alpha_mode() {
                gltf::material::AlphaMode::Opaque => AlphaMode::Opaque,
                gltf::material::AlphaMode::Mask => {
                    let c = m.alpha_cutoff().unwrap_or(0.5);
                    AlphaMode::Mask(if c.is_finite() { c } else { 0.5 })
                }
                gltf::material::AlphaMode::Blend => AlphaMode::Blend,
            };
            let name = m.name().map(str::to_string).unwrap_or_else(|| format!("material {index}"));
            self.scene.materials.push(Material {
                name,
                base_color,
                base_color_texture,
                metallic,
                roughness,
                metallic_roughness_texture,
                normal_texture,
                normal_scale,
                emissive,
                emissive_texture,
                specular,
                ior,
                alpha_mode,
                double_sided: m.double_sided(),
            });
        }
    }

    fn unit_factor(&mut self, loc: &str, what: &str, v: f32, default: f32) -> f32 {
        if !v.is_finite() {
            self.warn(loc, format!("{what} is not finite; using {default}"));
            default
        } else if !(0.0..=1.0).contains(&v) {
            self.warn(loc, format!("{what} {v} is outside [0, 1]; clamped"));
            v.clamp(0.0, 1.0)
        } else {
            v
        }
    }

    fn default_material(&mut self) -> u32 {
        if let Some(i) = self.default_material {
            return i;
        }
        let i = self.scene.materials.len() as u32;
        self.scene.materials.push(Material::default());
        self.default_material = Some(i);
        i
    }

    // ---------------------------------------------------------------- node hierarchy

    fn walk_nodes(&mut self) -> Result<()> {
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
                self.add_mesh(&mesh, &world)?;
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

    /// Fails if a node is (indirectly) its own descendant.
    fn check_node_cycles(&self) -> Result<()> {
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

    fn node_matrix(&mut self, node: &gltf::Node, loc: &str) -> Mat4 {
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
                let mut t = Vec3::from_array(translation);
                let mut s = Vec3::from_array(scale);
                let mut q = Quat::from_array(rotation);
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

    fn add_light(&mut self, light: &gltf::khr_lights_punctual::Light, world: &Mat4, node_loc: &str) {
        let loc = format!("{node_loc}, {}", named("light", light.index(), light.name()));
        let color = Vec3::from_array(light.color());
        let intensity = light.intensity();
        if !color.is_finite() || !intensity.is_finite() || color.min_element() < 0.0 || intensity < 0.0 {
            self.warn(&loc, "colour or intensity is negative or not finite; light skipped");
            return;
        }
        let radiometric = color * intensity / WATTS_TO_LUMENS;
        let position = world.w_axis.truncate();
        let dir = world.transform_vector3(Vec3::NEG_Z);
        let range = light.range().filter(|r| r.is_finite() && *r > 0.0);
        let needs_dir = !matches!(light.kind(), gltf::khr_lights_punctual::Kind::Point);
        if !position.is_finite() || (needs_dir && !(dir.is_finite() && dir.length_squared() > 0.0)) {
            self.warn(&loc, "node transform is degenerate or not finite; light skipped");
            return;
        }
        let direction = dir.normalize_or_zero();
        let l = match light.kind() {
            gltf::khr_lights_punctual::Kind::Point => Light::Point { position, intensity: radiometric, range },
            gltf::khr_lights_punctual::Kind::Directional => Light::Directional { direction, irradiance: radiometric },
            gltf::khr_lights_punctual::Kind::Spot { inner_cone_angle, outer_cone_angle } => {
                let mut outer = outer_cone_angle;
                let mut inner = inner_cone_angle;
                if !outer.is_finite() || outer <= 0.0 || outer > std::f32::consts::FRAC_PI_2 {
                    self.warn(&loc, format!("outerConeAngle {outer} is outside (0, π/2]; clamped"));
                    outer = if outer.is_finite() {
                        outer.clamp(1e-4, std::f32::consts::FRAC_PI_2)
                    } else {
                        std::f32::consts::FRAC_PI_4
                    };
                }
                if !inner.is_finite() || inner < 0.0 || inner >= outer {
                    self.warn(&loc, format!("innerConeAngle {inner} is outside [0, outerConeAngle); clamped"));
                    inner = if inner.is_finite() { inner.clamp(0.0, outer) } else { 0.0 };
                }
                Light::Spot {
                    position,
                    direction,
                    intensity: radiometric,
                    inner_cone_rad: inner,
                    outer_cone_rad: outer,
                    range,
                }
            }
        };
        self.scene.lights.push(l);
    }

    fn add_camera(&mut self, camera: &gltf::Camera, world: &Mat4, node: &gltf::Node, node_loc: &str) {
        let loc = format!("{node_loc}, {}", named("camera", camera.index(), camera.name()));
        let p = match camera.projection() {
            gltf::camera::Projection::Perspective(p) => p,
            gltf::camera::Projection::Orthographic(_) => {
                self.warn(&loc, "orthographic cameras are not supported; skipped");
                return;
            }
        };
        let yfov = p.yfov();
        if !yfov.is_finite() || yfov <= 0.0 || yfov >= std::f32::consts::PI {
            self.warn(&loc, format!("yfov {yfov} is outside (0, π); camera skipped"));
            return;
        }
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
        let aspect_ratio = p.aspect_ratio().filter(|a| a.is_finite() && *a > 0.0);
        let mut znear = p.znear();
        if !znear.is_finite() || znear < 0.0 {
            self.warn(&loc, format!("znear {znear} is invalid; using 0"));
            znear = 0.0;
        }
        let zfar = p.zfar().filter(|f| f.is_finite() && *f > znear);
        self.scene.cameras.push(SceneCamera { name, to_world, yfov_rad: yfov, aspect_ratio, znear, zfar });
    }

    // ---------------------------------------------------------------- meshes

    fn add_mesh(&mut self, mesh: &gltf::Mesh, world: &Mat4) -> Result<()> {
        let mesh_loc = named("mesh", mesh.index(), mesh.name());
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
            let m = self.read_primitive(&prim, world, material, &loc)?;
            self.scene.mesh.append(&m, 0);
        }
        Ok(())
    }

    fn attribute_f32(
        &self,
        prim: &gltf::Primitive,
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
        read_accessor(self, &acc).map(Some).map_err(|m| self.error(loc, format!("{what}: {m}")))
    }

    fn read_primitive(&mut self, prim: &gltf::Primitive, world: &Mat4, material: u32, loc: &str) -> Result<Mesh> {
        let Some(positions) = self.attribute_f32(prim, Semantic::Positions, Dimensions::Vec3, None, loc)? else {
            self.warn(loc, "has no POSITION attribute; skipped");
            return Ok(Mesh::default());
        };
        let n = positions.len() / 3;
        let normals = self.attribute_f32(prim, Semantic::Normals, Dimensions::Vec3, Some(n), loc)?;
        let tangents = self.attribute_f32(prim, Semantic::Tangents, Dimensions::Vec4, Some(n), loc)?;
        let uv0 = self.attribute_f32(prim, Semantic::TexCoords(0), Dimensions::Vec2, Some(n), loc)?;
        let uv1 = self.attribute_f32(prim, Semantic::TexCoords(1), Dimensions::Vec2, Some(n), loc)?;

        // Indices.
        let mut flat: Vec<u32> = match prim.indices() {
            Some(acc) => {
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
            None => {
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

        // World-space attributes.
        let lin = Mat3::from_mat4(*world);
        let det = lin.determinant();
        let sign = if det < 0.0 { -1.0 } else { 1.0 };
        // Cofactor matrix = det × inverse transpose: defined even for singular matrices.
        let cof =
            Mat3::from_cols(lin.y_axis.cross(lin.z_axis), lin.z_axis.cross(lin.x_axis), lin.x_axis.cross(lin.y_axis))
                * sign;
        let pos: Vec<Vec3> =
            positions.chunks_exact(3).map(|p| world.transform_point3(Vec3::new(p[0], p[1], p[2]))).collect();

        // Triangles, dropping those with a non-finite vertex and flipping mirrored ones.
        let mut tris: Vec<[u32; 3]> = Vec::with_capacity(flat.len() / 3);
        let mut dropped = 0usize;
        for t in flat.chunks_exact(3) {
            let tri = if det < 0.0 { [t[0], t[2], t[1]] } else { [t[0], t[1], t[2]] };
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
                    }
                    out.indices.push([base, base + 1, base + 2]);
                }
            }
        }
        out.material_ids = vec![material; out.indices.len()];
        Ok(out)
    }
}

/// Linear RGBA texels of a decoded image, row 0 at the top; RGB sRGB-decoded if `srgb`
/// (alpha is always linear).
fn image_texels(img: &image::DynamicImage, srgb: bool) -> Vec<Vec4> {
    let eight_bit = matches!(
        img,
        image::DynamicImage::ImageLuma8(_)
            | image::DynamicImage::ImageLumaA8(_)
            | image::DynamicImage::ImageRgb8(_)
            | image::DynamicImage::ImageRgba8(_)
    );
    if eight_bit {
        let lut: Vec<f32> = (0..256)
            .map(|i| {
                let c = i as f32 / 255.0;
                if srgb {
                    srgb_to_linear(c)
                } else {
                    c
                }
            })
            .collect();
        img.to_rgba8()
            .pixels()
            .map(|p| {
                let [r, g, b, a] = p.0;
                Vec4::new(lut[r as usize], lut[g as usize], lut[b as usize], a as f32 / 255.0)
            })
            .collect()
    } else {
        img.to_rgba32f()
            .pixels()
            .map(|p| {
                let [r, g, b, a] = p.0;
                if srgb {
                    Vec4::new(srgb_to_linear(r), srgb_to_linear(g), srgb_to_linear(b), a)
                } else {
                    Vec4::new(r, g, b, a)
                }
            })
            .collect()
    }
}

fn describe_gltf_error(e: &gltf::Error) -> String {
    match e {
        gltf::Error::Validation(list) => {
            let mut parts: Vec<String> = list.iter().take(5).map(|(path, err)| format!("{path}: {err}")).collect();
            if list.len() > 5 {
                parts.push(format!("and {} more", list.len() - 5));
            }
            parts.join("; ")
        }
        other => other.to_string(),
    }
}

// -------------------------------------------------------------------- accessor decoding

fn component_size(t: DataType) -> usize {
    match t {
        DataType::I8 | DataType::U8 => 1,
        DataType::I16 | DataType::U16 => 2,
        DataType::U32 | DataType::F32 => 4,
    }
}

/// Reads one component at `bytes[0..size]` (little endian), normalized if asked.
fn read_component(bytes: &[u8], t: DataType, normalized: bool) -> f64 {
    let b = |i: usize| bytes.get(i).copied().unwrap_or(0);
    match t {
        DataType::I8 => {
            let v = b(0) as i8 as f64;
            if normalized {
                (v / 127.0).max(-1.0)
            } else {
                v
            }
        }
        DataType::U8 => {
            let v = b(0) as f64;
            if normalized {
                v / 255.0
            } else {
                v
            }
        }
        DataType::I16 => {
            let v = i16::from_le_bytes([b(0), b(1)]) as f64;
            if normalized {
                (v / 32767.0).max(-1.0)
            } else {
                v
            }
        }
        DataType::U16 => {
            let v = u16::from_le_bytes([b(0), b(1)]) as f64;
            if normalized {
                v / 65535.0
            } else {
                v
            }
        }
        DataType::U32 => {
            let v = u32::from_le_bytes([b(0), b(1), b(2), b(3)]) as f64;
            if normalized {
                v / 4294967295.0
            } else {
                v
            }
        }
        DataType::F32 => f32::from_le_bytes([b(0), b(1), b(2), b(3)]) as f64,
    }
}

/// How the elements of an accessor (or of its sparse parts) are laid out.
#[derive(Clone, Copy)]
struct Layout {
    /// Components per element.
    ncomp: usize,
    /// Component type.
    t: DataType,
    /// Normalized integers.
    normalized: bool,
    /// Tightly packed (sparse data), ignoring the view's byteStride.
    tight: bool,
}

/// Reads `count` elements from a view at `offset`, with checked ranges.
fn read_elements(
    loader: &Loader,
    view: &gltf::buffer::View,
    offset: usize,
    count: usize,
    layout: Layout,
) -> std::result::Result<Vec<f64>, String> {
    let Layout { ncomp, t, normalized, tight } = layout;
    let bytes = loader.view_bytes(view)?;
    let csize = component_size(t);
    let esize = csize * ncomp;
    let stride = if tight { esize } else { view.stride().unwrap_or(esize) };
    if stride < esize {
        return Err(format!("byteStride {stride} is smaller than the element size {esize}"));
    }
    if count == 0 {
        return Ok(Vec::new());
    }
    let last = (count - 1)
        .checked_mul(stride)
        .and_then(|x| x.checked_add(offset))
        .and_then(|x| x.checked_add(esize))
        .ok_or("accessor range overflows")?;
    if last > bytes.len() {
        return Err(format!(
            "{count} elements at byteOffset {offset} (stride {stride}) need {last} bytes but bufferView {} has {}",
            view.index(),
            bytes.len()
        ));
    }
    let mut out = Vec::with_capacity(count * ncomp);
    for e in 0..count {
        let start = offset + e * stride;
        for c in 0..ncomp {
            let s = start + c * csize;
            out.push(read_component(&bytes[s..s + csize], t, normalized));
        }
    }
    Ok(out)
}

/// Decodes an accessor (any component type, strided, sparse) into `count × n` f64 values
/// returned as f32 for attributes; indices are exact in f64 before the conversion.
fn read_accessor(loader: &Loader, acc: &gltf::Accessor) -> std::result::Result<Vec<f32>, String> {
    let v = read_accessor_f64(loader, acc)?;
    Ok(v.into_iter().map(|x| x as f32).collect())
}

fn read_accessor_f64(loader: &Loader, acc: &gltf::Accessor) -> std::result::Result<Vec<f64>, String> {
    let ncomp = match acc.dimensions() {
        Dimensions::Scalar => 1,
        Dimensions::Vec2 => 2,
        Dimensions::Vec3 => 3,
        Dimensions::Vec4 => 4,
        d => return Err(format!("matrix accessor type {d:?} is not supported here")),
    };
    let t = acc.data_type();
    let count = acc.count();
    let mut out = match acc.view() {
        Some(view) => {
            let layout = Layout { ncomp, t, normalized: acc.normalized(), tight: false };
            read_elements(loader, &view, acc.offset(), count, layout)?
        }
        None => {
            // Sparse-only (or empty) accessor: zeros. Bound the allocation by the buffer data.
            let total: usize = loader.buffers.iter().map(Vec::len).sum();
            if acc.sparse().is_none() && count > 0 {
                return Err("accessor has neither bufferView nor sparse data".into());
            }
            if count.saturating_mul(ncomp) > total.saturating_mul(8).max(1 << 20) {
                return Err(format!("accessor count {count} is implausibly large"));
            }
            vec![0.0; count * ncomp]
        }
    };
    if let Some(sparse) = acc.sparse() {
        let n = sparse.count();
        let idx = sparse.indices();
        let it = match idx.index_type() {
            gltf::accessor::sparse::IndexType::U8 => DataType::U8,
            gltf::accessor::sparse::IndexType::U16 => DataType::U16,
            gltf::accessor::sparse::IndexType::U32 => DataType::U32,
        };
        let layout = Layout { ncomp: 1, t: it, normalized: false, tight: true };
        let indices =
            read_elements(loader, &idx.view(), idx.offset(), n, layout).map_err(|m| format!("sparse indices: {m}"))?;
        let vals = sparse.values();
        let layout = Layout { ncomp, t, normalized: acc.normalized(), tight: true };
        let values =
            read_elements(loader, &vals.view(), vals.offset(), n, layout).map_err(|m| format!("sparse values: {m}"))?;
        for (k, &i) in indices.iter().enumerate() {
            let i = i as usize;
            if i >= count {
                return Err(format!("sparse index {i} is out of range for {count} elements"));
            }
            out[i * ncomp..(i + 1) * ncomp].copy_from_slice(&values[k * ncomp..(k + 1) * ncomp]);
        }
    }
    Ok(out)
}

// -------------------------------------------------------------------- URIs

/// Decodes standard or URL-safe base64 (padding optional, whitespace ignored).
fn base64_decode(s: &str) -> Option<Vec<u8>> {
    let mut out = Vec::with_capacity(s.len() * 3 / 4);
    let mut acc: u32 = 0;
    let mut bits = 0u32;
    for c in s.bytes() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            b'=' => break,
            b' ' | b'\n' | b'\r' | b'\t' => continue,
            _ => return None,
        };
        acc = (acc << 6) | v as u32;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Some(out)
}

/// Decodes `%XX` escapes of a relative URI (invalid escapes are kept as written).
fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' && i + 2 < b.len() {
            let hex = std::str::from_utf8(&b[i + 1..i + 3]).ok().and_then(|h| u8::from_str_radix(h, 16).ok());
            if let Some(v) = hex {
                out.push(v);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_round_trip() {
        assert_eq!(base64_decode("aGVsbG8=").unwrap(), b"hello");
        assert_eq!(base64_decode("aGVsbG8").unwrap(), b"hello");
        assert_eq!(base64_decode("").unwrap(), b"");
        assert!(base64_decode("a*b").is_none());
    }

    #[test]
    fn percent_decoding() {
        assert_eq!(percent_decode("my%20file.png"), "my file.png");
        assert_eq!(percent_decode("100%"), "100%");
        assert_eq!(percent_decode("a%2"), "a%2");
        assert_eq!(percent_decode("%FF"), "\u{FFFD}");
    }

    #[test]
    fn garbage_never_panics() {
        let mut seed = 12345u64;
        for len in 0..200 {
            let bytes: Vec<u8> = (0..len)
                .map(|_| {
                    seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                    (seed >> 33) as u8
                })
                .collect();
            assert!(load_gltf_slice(&bytes, None, "garbage").is_err());
        }
    }
}
