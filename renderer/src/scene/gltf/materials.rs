//! Materials (metallic-roughness and extensions), images and textures.

use super::{named, Loader, TexKind};
use crate::scene::texture::{srgb_to_linear, Wrap};
use crate::scene::{AlphaMode, Anisotropy, AnisotropyTangent, Material, Texture, TextureRef, UvTransform};
use glam::{Vec2, Vec3, Vec4};
use std::sync::Arc;

impl Loader<'_> {
    pub(super) fn decode_image(&mut self, index: usize) -> std::result::Result<Arc<image::DynamicImage>, String> {
        if let Some(r) = self.images.get(&index) {
            return r.clone();
        }
        let r = self.decode_image_uncached(index);
        self.images.insert(index, r.clone());
        r
    }

    pub(super) fn decode_image_uncached(&self, index: usize) -> std::result::Result<Arc<image::DynamicImage>, String> {
        let json = self.doc.as_json().images.get(index).ok_or("no such image")?;
        let bytes: Vec<u8> = if let Some(view) = json.buffer_view {
            let view = self.doc.views().nth(view.value()).ok_or("no such bufferView")?;
            self.view_bytes(&view)?.to_vec()
        } else if let Some(uri) = &json.uri {
            self.read_uri(uri, super::accessors::MAX_IMAGE_FILE_BYTES, false)?
        } else {
            return Err("image has neither uri nor bufferView".into());
        };
        let format = image::guess_format(&bytes)
            .map_err(|_| "cannot decode image: format not recognised (PNG, JPEG and WebP are supported)".to_string())?;
        // The image crate's default limits (512 MiB per allocation) guard against image bombs.
        let reader = image::ImageReader::with_format(std::io::Cursor::new(&bytes), format);
        let img = reader.decode().map_err(|e| format!("cannot decode image: {e}"))?;
        if img.width() == 0 || img.height() == 0 {
            return Err("image is empty".into());
        }
        Ok(Arc::new(img))
    }

    /// Scene texture for a glTF texture used as `kind` (decoded once per kind).
    pub(super) fn texture(&mut self, tex: &gltf::Texture, kind: TexKind, used_by: &str) -> usize {
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
                // Colour images are decoded before filtering, as the glTF spec asks ("to achieve
                // correct filtering, the transfer function should be decoded before performing
                // linear interpolation"), except in a file Blender wrote: its images are
                // Blender's, which Cycles filters encoded and decodes after (an image in the
                // sRGB colour space, `compress_as_srgb`; see Texture), so the render of the
                // export matches Cycles' render of the scene.
                // (Nearest filtering returns a texel as it is: decoded at load, the same values
                // without a decode per lookup.)
                let srgb_encoded = kind.srgb() && self.blender_written && bilinear;
                let texels = image_texels(&img, kind.srgb() && !srgb_encoded);
                Texture {
                    name: name.clone(),
                    width: w,
                    height: h,
                    texels,
                    wrap_s: wrap(sampler.wrap_s()),
                    wrap_t: wrap(sampler.wrap_t()),
                    bilinear,
                    srgb_encoded,
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

    pub(super) fn texture_ref(
        &mut self,
        tex: &gltf::Texture,
        tex_coord: u32,
        kind: TexKind,
        used_by: &str,
    ) -> TextureRef {
        let uv_set = if tex_coord > 1 {
            self.warn(used_by, format!("texCoord {tex_coord} is not supported (UV sets 0 and 1 only); using 0"));
            0
        } else {
            tex_coord
        };
        TextureRef { index: self.texture(tex, kind, used_by), uv_set, transform: None }
    }

    /// A texture info's [`TextureRef`] with its `KHR_texture_transform`: `pointer` is the
    /// info's JSON pointer (`/materials/N/…Texture`), whose animated offset, rotation and scale
    /// (KHR_animation_pointer) replace the stored ones, or the extension's defaults where the
    /// info has no transform.
    pub(super) fn info_ref(
        &mut self,
        info: Option<gltf::texture::Info>,
        kind: TexKind,
        used_by: &str,
        pointer: &str,
    ) -> Option<TextureRef> {
        let info = info?;
        // 1. The transform's parts: animated, else stored, else the extension's defaults.
        let stored = info.texture_transform();
        let key = |field: &str| format!("{pointer}/extensions/KHR_texture_transform/{field}");
        let offset = self.animated_values(&key("offset"), 2);
        let rotation = self.animated_values(&key("rotation"), 1);
        let scale = self.animated_values(&key("scale"), 2);
        let animated = offset.is_some() || rotation.is_some() || scale.is_some();
        let part = |a: Option<Vec<f32>>, own: Option<[f32; 2]>, default: f32| {
            a.map_or(own.unwrap_or([default; 2]), |v| [v[0], v[1]])
        };
        let [tx, ty] = part(offset, stored.as_ref().map(|t| t.offset()), 0.0);
        let [sx, sy] = part(scale, stored.as_ref().map(|t| t.scale()), 1.0);
        let r = rotation.map_or(stored.as_ref().map_or(0.0, |t| t.rotation()), |v| v[0]);
        // 2. uv' = T·R·S·uv (glTF's UVs already have the renderer's top-left origin); the
        // extension's texCoord overrides the texture info's.
        let tex_coord = stored.as_ref().and_then(|t| t.tex_coord()).unwrap_or(info.tex_coord());
        let transform = if stored.is_none() && !animated {
            None
        } else if ![tx, ty, r, sx, sy].iter().all(|v| v.is_finite()) {
            self.warn(used_by, "KHR_texture_transform has non-finite values; ignored");
            None
        } else {
            let (sin, cos) = r.sin_cos();
            let m = glam::Mat2::from_cols(Vec2::new(cos * sx, -sin * sx), Vec2::new(sin * sy, cos * sy));
            Some(UvTransform { m, offset: Vec2::new(tx, ty) })
        };
        let mut r = self.texture_ref(&info.texture(), tex_coord, kind, used_by);
        r.transform = transform;
        Some(r)
    }

    /// The value at JSON `pointer` at the time asked (`width` floats), where a
    /// KHR_animation_pointer channel animates it; the pointer is marked as used.
    fn animated_values(&self, pointer: &str, width: usize) -> Option<Vec<f32>> {
        let v = self.animated.pointers.get(pointer).filter(|v| v.len() == width)?;
        self.animated.used.borrow_mut().insert(pointer.to_string());
        Some(v.clone())
    }

    /// [`Loader::animated_values`] of one float, else `own`.
    fn animated_or(&self, pointer: &str, own: f32) -> f32 {
        self.animated_values(pointer, 1).map_or(own, |v| v[0])
    }

    // ---------------------------------------------------------------- materials

    pub(super) fn load_materials(&mut self) {
        let doc = self.doc;
        let materials: Vec<_> = doc.materials().collect();
        for m in materials {
            let index = m.index().unwrap_or(0);
            let loc = named("material", index, m.name());
            let pbr = m.pbr_metallic_roughness();
            // A property animated through KHR_animation_pointer takes its value at the time
            // asked (`animation.rs`), checked as the stored one is.
            let key = |property: &str| format!("/materials/{index}/{property}");
            let mut base_color = self
                .animated_values(&key("pbrMetallicRoughness/baseColorFactor"), 4)
                .map_or(Vec4::from_array(pbr.base_color_factor()), |v| Vec4::from_slice(&v));
            if !base_color.is_finite() {
                self.warn(&loc, "non-finite baseColorFactor; using white");
                base_color = Vec4::ONE;
            }
            let metallic = self.animated_or(&key("pbrMetallicRoughness/metallicFactor"), pbr.metallic_factor());
            let metallic = self.unit_factor(&loc, "metallicFactor", metallic, 1.0);
            let roughness = self.animated_or(&key("pbrMetallicRoughness/roughnessFactor"), pbr.roughness_factor());
            let roughness = self.unit_factor(&loc, "roughnessFactor", roughness, 1.0);
            let base_color_texture = self.info_ref(
                pbr.base_color_texture(),
                TexKind::BaseColor,
                &format!("{loc} baseColorTexture"),
                &key("pbrMetallicRoughness/baseColorTexture"),
            );
            let metallic_roughness_texture = self.info_ref(
                pbr.metallic_roughness_texture(),
                TexKind::Linear,
                &format!("{loc} metallicRoughnessTexture"),
                &key("pbrMetallicRoughness/metallicRoughnessTexture"),
            );
            let (normal_texture, normal_scale) = match m.normal_texture() {
                Some(n) => {
                    let r =
                        self.texture_ref(&n.texture(), n.tex_coord(), TexKind::Normal, &format!("{loc} normalTexture"));
                    let s = self.animated_or(&key("normalTexture/scale"), n.scale());
                    (Some(r), if s.is_finite() { s } else { 1.0 })
                }
                None => (None, 1.0),
            };
            let strength = m.emissive_strength().unwrap_or(1.0);
            let strength =
                self.animated_or(&key("extensions/KHR_materials_emissive_strength/emissiveStrength"), strength);
            let factor =
                self.animated_values(&key("emissiveFactor"), 3).map_or(m.emissive_factor(), |v| [v[0], v[1], v[2]]);
            let mut emissive = Vec3::from_array(factor) * strength;
            if !emissive.is_finite() || emissive.min_element() < 0.0 {
                self.warn(&loc, "emission is negative or not finite; using none");
                emissive = Vec3::ZERO;
            }
            let emissive_texture = self.info_ref(
                m.emissive_texture(),
                TexKind::Emissive,
                &format!("{loc} emissiveTexture"),
                &key("emissiveTexture"),
            );
            let (specular, specular_tint) = self.specular(&loc, &m, &key("extensions/KHR_materials_specular"));
            let ior = self.animated_values(&key("extensions/KHR_materials_ior/ior"), 1).map(|v| v[0]).or(m.ior());
            let ior = match ior {
                Some(i) if i.is_finite() && i >= 1.0 => i,
                Some(i) => {
                    self.warn(&loc, format!("KHR_materials_ior ior {i} is invalid; using 1.5"));
                    1.5
                }
                None => 1.5,
            };
            let transmission = m.transmission();
            if transmission.as_ref().is_some_and(|t| t.transmission_texture().is_some()) {
                self.warn(&loc, "KHR_materials_transmission: transmissionTexture ignored (the factor is used)");
            }
            let transmission = self.animated_or(
                &key("extensions/KHR_materials_transmission/transmissionFactor"),
                transmission.map_or(0.0, |t| t.transmission_factor()),
            );
            let transmission = self.unit_factor(&loc, "transmissionFactor", transmission, 0.0);
            let (coat, coat_roughness) = self.clearcoat(
                &loc,
                m.extension_value("KHR_materials_clearcoat"),
                &key("extensions/KHR_materials_clearcoat"),
            );
            let anisotropy = self.anisotropy(
                &loc,
                m.extension_value("KHR_materials_anisotropy"),
                &key("extensions/KHR_materials_anisotropy"),
            );
            // (an animated cutoff is taken in every mode, as the spec's default is; MASK uses it)
            let cutoff = self.animated_or(&key("alphaCutoff"), m.alpha_cutoff().unwrap_or(0.5));
            let alpha_mode = match m.alpha_mode() {
                gltf::material::AlphaMode::Opaque => AlphaMode::Opaque,
                gltf::material::AlphaMode::Mask => AlphaMode::Mask(if cutoff.is_finite() { cutoff } else { 0.5 }),
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
                light_emitter: false,
                visible_to_camera: true,
                terminator_offset: crate::scene::TERMINATOR_OFFSET,
                transmission,
                coat,
                coat_roughness,
                coat_ior: 1.5,
                coat_tint: Vec3::ONE,
                scatter_tint: Vec3::ONE,
                metal_fresnel: Default::default(),
                specular_tint,
                translucent: false,
                mix: None,
                anisotropy,
            });
        }
    }

    /// `KHR_materials_specular` (`pointer`: the material's extension object's JSON pointer,
    /// whose animated factors replace the stored ones): F0 = F0(ior)·specularColorFactor·
    /// specularFactor. Blender's exporter writes Specular IOR Level × 2 as specularFactor up to
    /// 1, and above 1 as a scale of specularColorFactor, which also carries Specular Tint (its
    /// F90 is 1 either way, as here): specularColorFactor = tint × max(1, level × 2). So the part
    /// of the colour above 1 is the level, the rest the tint; F0 is the spec's for any values.
    /// Returns (specular level, tint).
    fn specular(&mut self, loc: &str, m: &gltf::Material, pointer: &str) -> (f32, Vec3) {
        let stored = m.specular();
        let animated_factor = self.animated_values(&format!("{pointer}/specularFactor"), 1);
        let animated_color = self.animated_values(&format!("{pointer}/specularColorFactor"), 3);
        if stored.is_none() && animated_factor.is_none() && animated_color.is_none() {
            return (1.0, Vec3::ONE);
        }
        if stored.as_ref().is_some_and(|s| s.specular_texture().is_some() || s.specular_color_texture().is_some()) {
            self.warn(
                loc,
                "KHR_materials_specular: specularTexture and specularColorTexture are not supported (the factors are used)",
            );
        }
        let f = animated_factor.map_or(stored.as_ref().map_or(1.0, |s| s.specular_factor()), |v| v[0]);
        let c = animated_color
            .map_or(stored.as_ref().map_or(Vec3::ONE, |s| Vec3::from_array(s.specular_color_factor())), |v| {
                Vec3::from_slice(&v)
            });
        if f.is_finite() && f >= 0.0 && c.is_finite() && c.min_element() >= 0.0 {
            let level = c.max_element().max(1.0);
            (f * level, c / level)
        } else {
            self.warn(loc, "invalid specularFactor or specularColorFactor; using 1");
            (1.0, Vec3::ONE)
        }
    }

    /// `KHR_materials_clearcoat` (coat weight and roughness; a coat of IOR 1.5, untinted): the
    /// factors are used (animated ones at `pointer`/…, the extension object's JSON pointer,
    /// replacing the stored ones), the textures and the coat's own normal map are reported and
    /// ignored.
    fn clearcoat(&mut self, loc: &str, ext: Option<&serde_json::Value>, pointer: &str) -> (f32, f32) {
        let parsed = self.material_extension::<Clearcoat>(loc, "KHR_materials_clearcoat", ext, "the coat");
        let (weight, roughness) = match &parsed {
            Some(p) => (p.clearcoat_factor, p.clearcoat_roughness_factor),
            None => (0.0, 0.0),
        };
        for (what, present) in [
            ("clearcoatTexture", parsed.as_ref().is_some_and(|p| p.clearcoat_texture.is_some())),
            ("clearcoatRoughnessTexture", parsed.as_ref().is_some_and(|p| p.clearcoat_roughness_texture.is_some())),
            ("clearcoatNormalTexture", parsed.as_ref().is_some_and(|p| p.clearcoat_normal_texture.is_some())),
        ] {
            if present {
                self.warn(loc, format!("KHR_materials_clearcoat: {what} ignored (the factors are used)"));
            }
        }
        let weight = self.animated_or(&format!("{pointer}/clearcoatFactor"), weight);
        let roughness = self.animated_or(&format!("{pointer}/clearcoatRoughnessFactor"), roughness);
        let weight = self.unit_factor(loc, "clearcoatFactor", weight, 0.0);
        let roughness = self.unit_factor(loc, "clearcoatRoughnessFactor", roughness, 0.0);
        (weight, roughness)
    }

    /// `KHR_materials_anisotropy` (strength and rotation, animated ones at `pointer`/…, the
    /// extension object's JSON pointer, replacing the stored ones; the texture is reported and
    /// ignored). The spec's lobe (α_t = mix(α, 1, strength²) along the UV tangent turned by the
    /// rotation), except in files Blender wrote: Blender's exporter writes its Principled
    /// Anisotropic as the strength and its importer reads it back so, with Cycles' default
    /// tangent (radial about the object's Z axis, glTF's +Y), so those render as Cycles renders
    /// the material. Blender 5.0's exporter writes an animated rotation in Blender's turns, not
    /// the radians of its stored one (`exp/animation/sampled/data/keyframes.py` lacks the
    /// conversion; its importer reads the animated value back as turns): in its files that
    /// value is read as turns.
    fn anisotropy(&mut self, loc: &str, ext: Option<&serde_json::Value>, pointer: &str) -> Option<Anisotropy> {
        let parsed: Option<AnisotropyExt> =
            self.material_extension(loc, "KHR_materials_anisotropy", ext, "the anisotropy");
        let animated_strength = self.animated_values(&format!("{pointer}/anisotropyStrength"), 1);
        let animated_rotation = self.animated_values(&format!("{pointer}/anisotropyRotation"), 1);
        if parsed.is_none() && animated_strength.is_none() && animated_rotation.is_none() {
            return None;
        }
        if parsed.as_ref().is_some_and(|p| p.anisotropy_texture.is_some()) {
            self.warn(loc, "KHR_materials_anisotropy: anisotropyTexture ignored (the strength and rotation are used)");
        }
        let strength = animated_strength.map_or(parsed.as_ref().map_or(0.0, |p| p.anisotropy_strength), |v| v[0]);
        let animated_unit = if self.blender_written { std::f32::consts::TAU } else { 1.0 };
        let rotation =
            animated_rotation.map_or(parsed.as_ref().map_or(0.0, |p| p.anisotropy_rotation), |v| v[0] * animated_unit);
        let strength = self.unit_factor(loc, "anisotropyStrength", strength, 0.0);
        let rotation = if rotation.is_finite() {
            rotation
        } else {
            self.warn(loc, "anisotropyRotation is not finite; using 0");
            0.0
        };
        if self.blender_written {
            Anisotropy::principled(strength, rotation / std::f32::consts::TAU, AnisotropyTangent::Radial(1))
        } else {
            Anisotropy::khr(strength, rotation)
        }
    }

    /// A material extension's object `ext` parsed as `T`; a malformed one is a warning naming
    /// the extension, and `what` is then ignored.
    fn material_extension<T: serde::de::DeserializeOwned>(
        &mut self,
        loc: &str,
        name: &str,
        ext: Option<&serde_json::Value>,
        what: &str,
    ) -> Option<T> {
        match serde_json::from_value(ext?.clone()) {
            Ok(parsed) => Some(parsed),
            Err(e) => {
                self.warn(loc, format!("{name}: {e}; {what} is ignored"));
                None
            }
        }
    }

    pub(super) fn unit_factor(&mut self, loc: &str, what: &str, v: f32, default: f32) -> f32 {
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

    pub(super) fn default_material(&mut self) -> u32 {
        if let Some(i) = self.default_material {
            return i;
        }
        let i = self.scene.materials.len() as u32;
        self.scene.materials.push(Material::default());
        self.default_material = Some(i);
        i
    }
}

/// Whether an image stores 8 bits per channel.
fn is_eight_bit(img: &image::DynamicImage) -> bool {
    matches!(
        img,
        image::DynamicImage::ImageLuma8(_)
            | image::DynamicImage::ImageLumaA8(_)
            | image::DynamicImage::ImageRgb8(_)
            | image::DynamicImage::ImageRgba8(_)
    )
}

/// Linear RGBA texels of a decoded image, row 0 at the top; RGB sRGB-decoded if `srgb`
/// (alpha is always linear).
fn image_texels(img: &image::DynamicImage, srgb: bool) -> Vec<Vec4> {
    if is_eight_bit(img) {
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

/// The `KHR_materials_anisotropy` extension object of a material.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields, rename_all = "camelCase")]
struct AnisotropyExt {
    #[serde(default)]
    anisotropy_strength: f32,
    #[serde(default)]
    anisotropy_rotation: f32,
    #[serde(default)]
    anisotropy_texture: Option<serde_json::Value>,
    #[serde(default)]
    #[allow(dead_code)]
    extensions: Option<serde_json::Value>,
    #[serde(default)]
    #[allow(dead_code)]
    extras: Option<serde_json::Value>,
}

/// The `KHR_materials_clearcoat` extension object of a material.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields, rename_all = "camelCase")]
struct Clearcoat {
    #[serde(default)]
    clearcoat_factor: f32,
    #[serde(default)]
    clearcoat_roughness_factor: f32,
    #[serde(default)]
    clearcoat_texture: Option<serde_json::Value>,
    #[serde(default)]
    clearcoat_roughness_texture: Option<serde_json::Value>,
    #[serde(default)]
    clearcoat_normal_texture: Option<serde_json::Value>,
    #[serde(default)]
    #[allow(dead_code)]
    extensions: Option<serde_json::Value>,
    #[serde(default)]
    #[allow(dead_code)]
    extras: Option<serde_json::Value>,
}
