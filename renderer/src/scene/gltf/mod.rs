//! glTF 2.0 loading (`.gltf` with external or embedded buffers, and binary `.glb`).
//!
//! The file is parsed and validated by the `gltf` crate; buffers and images are read here (so
//! that a missing or broken image is a warning with a visible fallback, not a failed load), and
//! accessors are decoded here with checked byte ranges, so no input can make the loader panic.
//! Each glTF mesh becomes one object-space [`Mesh`](super::Mesh) (read once, however many
//! nodes use it) and each node using it an [`Instance`](super::Instance) with the node's world
//! transform; warnings go to [`Scene::warnings`].
//!
//! | glTF | becomes | notes |
//! |---|---|---|
//! | default scene (else the first; else every root node, with a warning) | nodes walked with their matrix or TRS | a cycle in the node graph is an error |
//! | mesh | one [`Scene::meshes`] entry; each node using it one [`Scene::instances`] entry | the transform applies at render time |
//! | mesh primitive, mode `TRIANGLES` | triangles of its mesh | other modes skipped with a warning |
//! | `POSITION`, `NORMAL`, `TANGENT`, `TEXCOORD_0/1`, indices | object space, as stored; the renderer moves them by the instance (normals by the inverse transpose, tangents by the matrix with `w` × sign(det); det < 0 flips the winding) | any component type (normalized integers too, `KHR_mesh_quantization`) and sparse accessors |
//! | `COLOR_0` (VEC3 or VEC4) | [`Mesh::colors`], multiplying the base colour and alpha (Blender writes it for a Color Attribute node feeding Base Color) | channels clamped to [0, 1]; `COLOR_1…` ignored |
//! | no `NORMAL` | flat face normals (vertices unshared), as the glTF spec requires | |
//! | no `TANGENT` | zero tangents | |
//! | non-finite positions | those triangles dropped with a warning; an error if no triangle is left | |
//! | indices out of range, attribute counts that differ | error naming the mesh and primitive | |
//! | material (metallic-roughness) | [`Material`] | base colour and emissive textures sRGB-decoded, others linear |
//! | `KHR_materials_emissive_strength` | × `Material::emissive` | |
//! | `KHR_materials_specular` `specularFactor` | `Material::specular` | specular colour and textures ignored (warning) |
//! | `KHR_materials_ior` | `Material::ior` | |
//! | `KHR_materials_transmission` `transmissionFactor` | `Material::transmission` (solid glass refracting by `ior`, as Cycles renders Blender's Transmission) | transmission texture ignored (warning); no `KHR_materials_volume` thin-walled case |
//! | `KHR_materials_anisotropy` strength, rotation | `Material::anisotropy`: the spec's lobe (α_t = mix(α, 1, strength²) along the UV tangent turned by the rotation); in files Blender wrote, Blender's Principled Anisotropic on Cycles' default radial tangent (about the mesh's +Y, Blender's Z), as Blender's importer reads it | `anisotropyTexture` ignored (warning) |
//! | `KHR_draco_mesh_compression` | Draco-compressed primitives decoded (`draco-core`, pure Rust): attributes and indices from the decoded mesh, integer attributes normalized where their accessor says so | |
//! | `EXT_texture_webp` | the texture's WebP image, in place of its PNG/JPEG fallback or of the `source` it lacks | |
//! | `EXT_mesh_gpu_instancing` | the node's mesh once per instance, each an [`Instance`](super::Instance) with transform node × T·R·S (Blender writes it with the exporter's GPU Instances option) | `TRANSLATION`, `ROTATION`, `SCALE`; `_`-prefixed attributes ignored; a malformed attribute is an error naming the node |
//! | `KHR_texture_transform` | offset, rotation, scale and texCoord on base colour, metallic-roughness and emissive textures (a normal map's tangent frame is not rotated) | |
//! | no material | [`Material::default`] (white, metallic 1, roughness 1) | |
//! | image (PNG, JPEG; file, data URI or bufferView) | [`Texture`], sampler wrap modes, `magFilter` nearest → nearest; colour images decoded before filtering, as the glTF spec asks, except in files Blender wrote (`asset.generator` "Khronos glTF Blender I/O"), whose colour images are filtered encoded and decoded after, as Cycles renders Blender's sRGB images | missing or undecodable: warning and a 1×1 fallback: magenta for base colour, flat for normal maps, white for metallic-roughness, black for emission |
//! | `KHR_lights_punctual` point, spot | [`Light::Point`], [`Light::Spot`]: `color × intensity / 683` W/sr | see below |
//! | `KHR_lights_punctual` directional | [`Light::Directional`]: `color × intensity / 683` W/m² | |
//! | node animation (`translation`, `rotation`, `scale` channels) | evaluated at the time asked ([`load_gltf_at`]; `petzval render --frame F` asks for F / `--fps`, as Blender's exporter writes frame F at F / fps seconds), else the nodes' own TRS | see `animation.rs` |
//! | `KHR_animation_pointer` channels (cameras, punctual lights, materials: their factors, those of the material extensions above, `alphaCutoff`, texture transforms) | the animated properties' values at the time asked, in place of the stored ones (a material's BSDF is built from them) | see `animation.rs`; Blender 5.0's exporter slips compensated in files it wrote; other pointers warned about by name |
//! | skins, morph targets (and their `weights` animation) | meshes deformed per node, as the spec defines it (linear blend skinning after the morph targets) | see `deform.rs` |
//! | perspective and orthographic cameras | [`SceneCamera`] (rigid part of the node's world transform); orthographic: `ortho_scale_m` = 2·max(xmag, ymag), as Blender's importer reads it | node scale ignored |
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
//! (`blender/exp/light_spots.py`, lines 28–47); they are kept as glTF angles. So a hard spot
//! (blend 0) arrives as inner = outer, which the spec excludes (inner < outer); it is taken as a
//! hard edge without a warning. A soft spot in a file Blender wrote (`asset.generator` "Khronos
//! glTF Blender I/O") fades as Cycles renders Blender's Spot Blend, blend = 1 − inner/outer: a
//! smoothstep in cos θ over `[cos θo, cos θo + (1 − cos θo)·blend]`
//! ([`SpotFalloff::Blender`](crate::scene::SpotFalloff)); in other files it follows
//! KHR_lights_punctual (squared ramp in cos θ from the outer to the inner cone)
//! (tests/blender/test_spot_lights_cycles.py).

//!
//! | file | contents |
//! |---|---|
//! | `mod.rs` | entry points ([`load_gltf`], [`load_gltf_slice`]), the loader state, extensions |
//! | `nodes.rs` | node hierarchy, meshes and primitives, lights, cameras |
//! | `materials.rs` | materials, images and textures |
//! | `accessors.rs` | buffers, URIs (data, files), accessor decoding |
//! | `deform.rs` | skins and morph targets |

mod accessors;
mod animation;
mod deform;
mod materials;
mod nodes;

use super::Scene;
use crate::{Error, Result};
use glam::Vec4;
use gltf::mesh::Semantic;
use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

/// Luminous efficacy (lm/W) Blender's glTF exporter uses to convert watts to lumens.
pub const WATTS_TO_LUMENS: f32 = 683.0;

/// The largest `.gltf`/`.glb` file read (4 GiB; its external buffers have their own limit).
const MAX_FILE_BYTES: u64 = 4 << 30;

/// Loads a `.gltf` or `.glb` file into a [`Scene`].
///
/// Fails (naming the file and, where it applies, the glTF object) on an unreadable, corrupt or
/// truncated file, a missing buffer, out-of-range indices or a file whose triangles are all
/// invalid. Problems that leave the scene usable (a missing texture, an unsupported primitive
/// mode or camera type, ignored extensions, dropped non-finite triangles) are reported in
/// [`Scene::warnings`].
pub fn load_gltf(path: &Path) -> Result<Scene> {
    load_gltf_at(path, None)
}

/// [`load_gltf`] with the file's node animations evaluated at `time_s` seconds (None: the
/// nodes' own transforms; see `animation.rs`).
pub fn load_gltf_at(path: &Path, time_s: Option<f64>) -> Result<Scene> {
    // a regular file only: a device or pipe named as the scene is refused, not read without bound
    let bytes = crate::optics::read_input_file(path, MAX_FILE_BYTES, "glTF file")?;
    let base = path.parent().map(|p| if p.as_os_str().is_empty() { Path::new(".") } else { p });
    load_gltf_slice_at(&bytes, base, &path.display().to_string(), time_s)
}

/// Loads glTF from memory. `base_dir` resolves relative URIs (None: only embedded data is
/// allowed); `file_name` is used in messages.
pub fn load_gltf_slice(bytes: &[u8], base_dir: Option<&Path>, file_name: &str) -> Result<Scene> {
    load_gltf_slice_at(bytes, base_dir, file_name, None)
}

/// [`load_gltf_slice`] with the node animations evaluated at `time_s` seconds.
pub fn load_gltf_slice_at(
    bytes: &[u8],
    base_dir: Option<&Path>,
    file_name: &str,
    time_s: Option<f64>,
) -> Result<Scene> {
    if let Some(t) = time_s.filter(|t| !t.is_finite()) {
        return Err(Error::scene(file_name, "", format!("animation time {t} s is not finite")));
    }
    // Defence in depth: the loader checks every index and byte range itself, but the `gltf`
    // crate's accessors rely on its validation; a panic there becomes an error, not a crash.
    let result =
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| Loader::load(bytes, base_dir, file_name, time_s)));
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
    /// glTF mesh index → scene mesh (None: the mesh has no triangles), once read.
    mesh_ids: HashMap<usize, Option<u32>>,
    /// Index of the default material, once a primitive without material needs it.
    default_material: Option<u32>,
    /// Triangles read, and dropped for non-finite positions.
    triangles_read: usize,
    triangles_dropped: usize,
    /// Blender's exporter wrote the file (`asset.generator` "Khronos glTF Blender I/O …"):
    /// its colour images are filtered as Cycles filters them (see `Loader::texture`).
    blender_written: bool,
    /// Blender 5.0's exporter (`… I/O v5.0.…`) wrote it: its animated `spot.innerConeAngle`
    /// holds the Spot Blend, not the angle (`exp/animation/sampled/sampling_cache.py` stores
    /// the angle where the keyframes do not read it).
    blender_5_0: bool,
    /// The animated nodes' TRS parts and morph weights at the time asked (empty without a time).
    animated: animation::Animated,
    /// Every node's world matrix along its parent chain, once a skin needs them.
    node_worlds: Option<Vec<glam::Mat4>>,
    /// Estimated bytes of the deformed meshes' copies so far (checked against the memory budget).
    deformed_bytes: u64,
    /// A time was asked (`load_gltf_at`): animations are evaluated.
    timed: bool,
}

fn named(kind: &str, index: usize, name: Option<&str>) -> String {
    match name {
        Some(n) if !n.is_empty() => format!("{kind} {index} '{n}'"),
        _ => format!("{kind} {index}"),
    }
}

impl<'a> Loader<'a> {
    fn load(bytes: &[u8], base: Option<&Path>, file: &str, time_s: Option<f64>) -> Result<Scene> {
        let err = |m: String| Error::scene(file, "", m);
        if bytes.is_empty() {
            return Err(err("empty file".into()));
        }
        // A GLB header whose total length is below its own 12 bytes underflows in the gltf
        // crate (a panic where overflow checks are on, as under cargo-fuzz): refuse it here.
        if let [b'g', b'l', b'T', b'F', _, _, _, _, l0, l1, l2, l3, ..] = bytes {
            let length = u32::from_le_bytes([*l0, *l1, *l2, *l3]);
            if length < 12 {
                return Err(err(format!(
                    "not a valid glTF file: the GLB header's length {length} is below its own 12 bytes"
                )));
            }
        }
        let (bytes, pointer_channels) = without_pointer_channels(bytes);
        let gltf::Gltf { document, blob } = gltf::Gltf::from_slice_without_validation(&bytes).map_err(|e| {
            // Blender exports an empty scene without `nodes`, which the gltf crate requires.
            if e.to_string().contains("missing field `nodes`") {
                err("the scene is empty (the file has no nodes): no camera and nothing to render".into())
            } else {
                err(format!("not a valid glTF file: {e}"))
            }
        })?;
        // KHR_mesh_quantization only widens the accessor types allowed for attributes, which
        // the accessor reader below handles; the gltf crate does not know the name.
        let mut json = document.into_json();
        json.extensions_required
            .retain(|e| e != "KHR_mesh_quantization" && e != "EXT_texture_webp" && e != "KHR_draco_mesh_compression");
        use_webp_sources(&mut json);
        point_draco_accessors_at_their_data(&mut json);
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
            scene: Scene { source: file.to_string(), ..Scene::default() },
            textures: HashMap::new(),
            images: HashMap::new(),
            mesh_ids: HashMap::new(),
            default_material: None,
            triangles_read: 0,
            triangles_dropped: 0,
            blender_written: doc
                .as_json()
                .asset
                .generator
                .as_deref()
                .is_some_and(|g| g.starts_with("Khronos glTF Blender I/O")),
            blender_5_0: doc
                .as_json()
                .asset
                .generator
                .as_deref()
                .is_some_and(|g| g.starts_with("Khronos glTF Blender I/O v5.0.")),
            animated: animation::Animated::default(),
            node_worlds: None,
            deformed_bytes: 0,
            timed: false,
        };
        loader.warn_extensions();
        loader.load_buffers(blob)?;
        loader.timed = time_s.is_some();
        if time_s.is_some() && doc.animations().len() == 0 && pointer_channels.is_empty() {
            loader
                .warn("", "a frame was asked for, but the file has no animations: its nodes are rendered as they are");
        }
        if let Some(t) = time_s {
            loader.animated = loader.animated_nodes(t as f32)?;
            loader.animated.pointers = loader.animated_pointers(&pointer_channels, t as f32)?;
        }
        loader.load_materials();
        loader.warn_unused_material_pointers();
        loader.walk_nodes()?;
        if loader.triangles_read > 0
            && loader.scene.meshes.iter().all(|m| m.indices.is_empty())
            && loader.triangles_dropped > 0
        {
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

    /// Reports the animated material properties no material took (the material, or the texture
    /// whose transform is animated, is not in the file).
    fn warn_unused_material_pointers(&mut self) {
        let mut unused: Vec<String> = self
            .animated
            .pointers
            .keys()
            .filter(|k| k.starts_with("/materials/") && !self.animated.used.borrow().contains(*k))
            .cloned()
            .collect();
        unused.sort();
        if !unused.is_empty() {
            self.warn(
                "",
                format!(
                    "KHR_animation_pointer: {} target a material or texture the file does not have; ignored",
                    unused.join(", ")
                ),
            );
        }
    }

    fn warn_extensions(&mut self) {
        const HANDLED: &[&str] = &[
            "KHR_lights_punctual",
            "KHR_materials_clearcoat",
            "KHR_materials_emissive_strength",
            "KHR_materials_ior",
            "KHR_materials_specular",
            "KHR_materials_transmission",
            "KHR_materials_anisotropy",
            "KHR_mesh_quantization",
            "KHR_texture_transform",
            "EXT_texture_webp",
            "KHR_draco_mesh_compression",
            "EXT_mesh_gpu_instancing",
            // its channels are read apart (`without_pointer_channels`, `animation.rs`)
            "KHR_animation_pointer",
        ];
        let used: Vec<String> = self.doc.extensions_used().map(|s| s.to_string()).collect();
        for ext in used {
            if !HANDLED.contains(&ext.as_str()) {
                self.warn("", format!("extension {ext} is not supported and is ignored"));
            }
        }
    }
}

/// `KHR_animation_pointer` channels (a property of a camera, light or material as the target,
/// no node), which the gltf crate cannot parse: removed from the JSON (an animation left without
/// channels goes too) and returned, for `animation` to evaluate. The bytes are returned as they
/// are when there is none (or the JSON does not parse: the gltf crate then reports it).
fn without_pointer_channels(bytes: &[u8]) -> (std::borrow::Cow<'_, [u8]>, Vec<animation::PointerChannel>) {
    use std::borrow::Cow;
    const NAME: &[u8] = b"KHR_animation_pointer";
    let glb = bytes.starts_with(b"glTF").then(|| gltf::binary::Glb::from_slice(bytes).ok()).flatten();
    let json: &[u8] = match &glb {
        Some(g) => &g.json,
        None => bytes,
    };
    if !json.windows(NAME.len()).any(|w| w == NAME) {
        return (Cow::Borrowed(bytes), Vec::new());
    }
    let Ok(mut root) = serde_json::from_slice::<serde_json::Value>(json) else {
        return (Cow::Borrowed(bytes), Vec::new());
    };
    let mut removed = Vec::new();
    if let Some(animations) = root.get_mut("animations").and_then(|a| a.as_array_mut()) {
        for (ai, anim) in animations.iter_mut().enumerate() {
            let samplers = anim.get("samplers").cloned().unwrap_or_default();
            let name = anim.get("name").and_then(|n| n.as_str()).map(str::to_string);
            if let Some(channels) = anim.get_mut("channels").and_then(|c| c.as_array_mut()) {
                for (ci, c) in channels.iter().enumerate() {
                    if c.get("target").and_then(|t| t.get("node")).is_none() {
                        removed.push(animation::PointerChannel::from_json(ai, name.as_deref(), ci, c, &samplers));
                    }
                }
                channels.retain(|c| c.get("target").and_then(|t| t.get("node")).is_some());
            }
        }
        animations.retain(|a| a.get("channels").and_then(|c| c.as_array()).is_none_or(|c| !c.is_empty()));
    }
    if removed.is_empty() {
        return (Cow::Borrowed(bytes), removed);
    }
    let Ok(new_json) = serde_json::to_vec(&root) else { return (Cow::Borrowed(bytes), Vec::new()) };
    match glb {
        Some(g) => {
            let glb = gltf::binary::Glb { header: g.header, json: Cow::Owned(new_json), bin: g.bin };
            match glb.to_vec() {
                Ok(v) => (Cow::Owned(v), removed),
                Err(_) => (Cow::Borrowed(bytes), Vec::new()),
            }
        }
        None => (Cow::Owned(new_json), removed),
    }
}

/// `EXT_texture_webp`: a texture's WebP image (the extension's `source`) replaces its PNG or
/// JPEG fallback, or stands in for the `source` it may lack (Blender writes none without a
/// fallback). An index out of range is left for validation to report.
fn use_webp_sources(json: &mut gltf::json::Root) {
    let n_images = json.images.len();
    for tex in &mut json.textures {
        let webp = tex
            .extensions
            .as_ref()
            .and_then(|e| e.others.get("EXT_texture_webp"))
            .and_then(|w| w.get("source"))
            .and_then(|s| s.as_u64());
        if let Some(i) = webp.filter(|&i| (i as usize) < n_images) {
            tex.source = gltf::json::Index::new(i as u32);
        }
    }
}

/// `KHR_draco_mesh_compression`: a compressed primitive's accessors (its indices and the
/// attributes the extension lists) have no bufferView (the data is in the extension's); they
/// are pointed at the extension's bufferView so that the document validates, and read from the
/// decoded mesh instead ([`Loader::read_primitive`]).
fn point_draco_accessors_at_their_data(json: &mut gltf::json::Root) {
    let mut fix: Vec<(usize, u32)> = Vec::new();
    for m in &json.meshes {
        for p in &m.primitives {
            let Some(ext) = draco_extension(p) else { continue };
            let Some(view) = ext.get("bufferView").and_then(|v| v.as_u64()) else { continue };
            // only what the compressed mesh holds: an attribute it lacks keeps its own data
            // (or, without any, fails validation rather than reading compressed bytes)
            let compressed = |name: &str| ext.get("attributes").and_then(|a| a.get(name)).is_some();
            let attributes = p.attributes.iter().filter_map(|(semantic, a)| match semantic {
                gltf::json::validation::Checked::Valid(s) if compressed(&s.to_string()) => Some(a.value()),
                _ => None,
            });
            fix.extend(attributes.chain(p.indices.map(|i| i.value())).map(|a| (a, view as u32)));
        }
    }
    for (a, view) in fix {
        if let Some(acc) = json.accessors.get_mut(a) {
            if acc.buffer_view.is_none() && acc.sparse.is_none() && (view as usize) < json.buffer_views.len() {
                acc.buffer_view = Some(gltf::json::Index::new(view));
            }
        }
    }
}

/// A primitive's `KHR_draco_mesh_compression` object, if it has one.
pub(super) fn draco_extension(p: &gltf::json::mesh::Primitive) -> Option<&gltf::json::Value> {
    p.extensions.as_ref()?.others.get("KHR_draco_mesh_compression")
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

#[cfg(test)]
mod tests {
    use super::accessors::{base64_decode, percent_decode};
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
