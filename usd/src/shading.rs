//! UsdShade: the material bound to a gprim (resolved as pxr's `ComputeBoundMaterial` for
//! purpose `full` does: `full` bindings before all-purpose ones, direct and collection bindings,
//! `strongerThanDescendants`; see [`crate::binding`]) → a Material prim → its
//! `outputs:surface` shader. `UsdPreviewSurface` maps onto the renderer's material; its
//! inputs may be values or connections to a `UsdUVTexture`.
//!
//! | UsdPreviewSurface input | renderer | fallback |
//! |---|---|---|
//! | `diffuseColor` | base colour (texture: `rgb`, `sourceColorSpace` sRGB/raw/auto; a `UsdPrimvarReader_float3`: the gprim's primvar `varname` as vertex colours, its `fallback` where the primvar is missing) | (0.18, 0.18, 0.18) |
//! | `metallic` | metallic | 0 |
//! | `roughness` | roughness | 0.5 |
//! | `emissiveColor` | emitted radiance | 0 |
//! | `opacity`, `opacityThreshold` | alpha; threshold > 0 = mask, else blend when < 1 | 1, 0 |
//! | `ior` | dielectric F0 | 1.5 |
//! | `clearcoat`, `clearcoatRoughness` | clear coat weight and roughness (IOR 1.5, untinted) | 0, 0.01 |
//! | `specular` (Blender's Specular IOR Level, not in the spec) | specular strength × 2 (0.5 = F0 of the IOR) | 0.5 |
//! | `normal` (UsdUVTexture, raw) | tangent-space normal map | none |
//!
//! An unbound gprim uses its `primvars:displayColor` (one value: the material's colour; more:
//! vertex colours, by their interpolation) or 18 % grey. A shader that
//! is not UsdPreviewSurface, or a texture that cannot be read, is listed once as a warning and
//! renders magenta (the project's visible fallback).

use crate::value::Reader;
use crate::Error;
use glam::{Vec3, Vec4};
use openusd::{sdf, usd};
use petzval_renderer::scene::texture::Wrap;
use petzval_renderer::scene::{AlphaMode, Material, Scene, Texture, TextureRef, UvTransform};
use std::collections::HashMap;
use std::sync::Arc;

/// The visible fallback colour.
const MAGENTA: Vec4 = Vec4::new(1.0, 0.0, 1.0, 1.0);

/// Materials created so far, keyed by (binding, double-sided).
#[derive(Default)]
pub struct Materials {
    by_key: HashMap<(String, bool), u32>,
    textures: HashMap<(String, bool), usize>,
    /// The primvar a material's textures read (`UsdPrimvarReader_float2.varname`), by id.
    st_names: HashMap<u32, String>,
    /// The colour primvar a material's base colour reads (a `UsdPrimvarReader_float3`'s
    /// varname, or an unbound gprim's `displayColor`) and the colour where it is missing, by id.
    color_primvars: HashMap<u32, (String, Vec3)>,
    pending_color: Option<(String, Vec3)>,
    /// The varname found while reading the current material.
    pending_st: Option<String>,
    /// sRGB images are filtered encoded and decoded after, as Cycles renders Blender's images
    /// (on stages Blender wrote); otherwise decoded before filtering.
    filter_encoded: bool,
}

fn source_prim(stage: &usd::Stage, prim: &usd::Prim, input: &str) -> Option<(usd::Prim, String)> {
    let c = prim.attribute(input).connections().ok()?;
    let first = c.into_iter().next()?;
    let output = first.to_string().rsplit('.').next().unwrap_or("").to_string();
    Some((stage.prim(first.prim_path()), output))
}

impl Materials {
    /// No materials yet; `filter_encoded`: filter sRGB images encoded, as Cycles does (for
    /// stages Blender wrote).
    pub fn filtering_encoded(filter_encoded: bool) -> Materials {
        Materials { filter_encoded, ..Materials::default() }
    }

    /// The texture-coordinate primvar (without `primvars:`) material `id` reads, when its
    /// textures name one through a `UsdPrimvarReader_float2`.
    pub fn st_name(&self, id: u32) -> Option<&str> {
        self.st_names.get(&id).map(String::as_str)
    }

    /// The primvar (without `primvars:`) whose values colour the vertices of gprims using
    /// material `id`, and the colour where a gprim lacks it.
    pub fn color_primvar(&self, id: u32) -> Option<(&str, Vec3)> {
        self.color_primvars.get(&id).map(|(n, c)| (n.as_str(), *c))
    }

    /// The material id for a gprim: the material `binding` bound to it ([`crate::binding`]),
    /// else its display colour.
    pub fn material_for(
        &mut self,
        reader: &Reader,
        scene: &mut Scene,
        gprim: &usd::Prim,
        binding: Option<sdf::Path>,
        double_sided: bool,
        warnings: &mut Vec<String>,
    ) -> Result<u32, Error> {
        let key = match &binding {
            Some(b) => b.to_string(),
            None => match display_color(reader, gprim)? {
                DisplayColor::One(c) => format!("displayColor:{},{},{}", c.x, c.y, c.z),
                DisplayColor::PerElement => "displayColor:primvar".to_string(),
            },
        };
        if let Some(&id) = self.by_key.get(&(key.clone(), double_sided)) {
            return Ok(id);
        }
        self.pending_st = None;
        self.pending_color = None;
        let mut m = match &binding {
            Some(b) => self.read_material(reader, scene, &reader.stage.prim(b.clone()), warnings)?,
            None => match display_color(reader, gprim)? {
                DisplayColor::One(c) => preview_default(&key, c),
                DisplayColor::PerElement => {
                    self.pending_color = Some(("displayColor".into(), Vec3::splat(0.18)));
                    preview_default(&key, Vec3::ONE)
                }
            },
        };
        m.double_sided = double_sided;
        // the values as the renderer takes them (f32): a 1e39 or inf would reach shading as inf
        let finite = m.base_color.is_finite()
            && m.emissive.is_finite()
            && [m.metallic, m.roughness, m.normal_scale, m.specular, m.ior].iter().all(|v| v.is_finite());
        if !finite {
            return Err(Error::Prim {
                layer: String::new(),
                prim: m.name.clone(),
                message: format!(
                    "material values are not finite in single precision (base colour {:?}, emission {:?}, metallic {}, roughness {}, ior {})",
                    m.base_color.to_array(),
                    m.emissive.to_array(),
                    m.metallic,
                    m.roughness,
                    m.ior
                ),
            });
        }
        scene.materials.push(m);
        let id = (scene.materials.len() - 1) as u32;
        if let Some(st) = self.pending_st.take() {
            self.st_names.insert(id, st);
        }
        if let Some(c) = self.pending_color.take() {
            self.color_primvars.insert(id, c);
        }
        self.by_key.insert((key, double_sided), id);
        Ok(id)
    }

    fn read_material(
        &mut self,
        reader: &Reader,
        scene: &mut Scene,
        material: &usd::Prim,
        warnings: &mut Vec<String>,
    ) -> Result<Material, Error> {
        let stage = reader.stage;
        let name = material.path().to_string();
        let Some((shader, _)) = source_prim(stage, material, "outputs:surface") else {
            warnings.push(format!("{name}: material has no outputs:surface connection; rendered magenta"));
            return Ok(preview_default(&name, MAGENTA.truncate()));
        };
        let id = reader.token(&shader, "info:id")?.unwrap_or_default();
        if id != "UsdPreviewSurface" {
            warnings.push(format!(
                "{}: shader '{}' is not supported (only UsdPreviewSurface); rendered magenta",
                shader.path(),
                if id.is_empty() { "(no info:id)" } else { &id }
            ));
            return Ok(preview_default(&name, MAGENTA.truncate()));
        }
        let mut m = preview_default(&name, Vec3::splat(0.18));
        // colour inputs: value or texture
        let diffuse_source = source_prim(stage, &shader, "inputs:diffuseColor");
        let primvar_reader = match &diffuse_source {
            Some((src, _)) => matches!(
                reader.token(src, "info:id")?.as_deref(),
                Some("UsdPrimvarReader_float3" | "UsdPrimvarReader_float4")
            ),
            None => false,
        };
        if let (true, Some((src, _))) = (primvar_reader, &diffuse_source) {
            // the gprim's colour primvar, white here; the spec's fallback is black
            let fallback = reader.vec3(src, "inputs:fallback")?.map_or(Vec3::ZERO, |c| c.as_vec3());
            match reader.token(src, "inputs:varname")? {
                Some(v) if !v.is_empty() => self.pending_color = Some((v, fallback)),
                _ => {
                    warnings
                        .push(format!("{}: UsdPrimvarReader has no inputs:varname; its fallback is used", src.path()));
                    self.pending_color = Some((String::new(), fallback));
                }
            }
            m.base_color = Vec4::ONE;
        } else if let Some((tex, _)) = diffuse_source {
            m.base_color_texture = self.texture(reader, scene, &tex, true, warnings)?;
            m.base_color = Vec4::ONE;
        } else if let Some(c) = reader.vec3(&shader, "inputs:diffuseColor")? {
            m.base_color = c.as_vec3().extend(1.0);
        }
        if let Some((tex, _)) = source_prim(stage, &shader, "inputs:emissiveColor") {
            m.emissive_texture = self.texture(reader, scene, &tex, true, warnings)?;
            m.emissive = Vec3::ONE;
        } else if let Some(c) = reader.vec3(&shader, "inputs:emissiveColor")? {
            m.emissive = c.as_vec3();
        }
        if let Some((tex, _)) = source_prim(stage, &shader, "inputs:normal") {
            m.normal_texture = self.texture(reader, scene, &tex, false, warnings)?;
        }
        for (input, slot) in [("inputs:metallic", 0), ("inputs:roughness", 1)] {
            if source_prim(stage, &shader, input).is_some() {
                warnings.push(format!("{}: {input} from a texture is not supported; its value is used", shader.path()));
            }
            if let Some(v) = reader.f64(&shader, input)? {
                let v = (v as f32).clamp(0.0, 1.0);
                if slot == 0 {
                    m.metallic = v;
                } else {
                    m.roughness = v;
                }
            }
        }
        // The clear coat (IOR 1.5 and untinted, as the spec has it).
        for input in ["inputs:clearcoat", "inputs:clearcoatRoughness"] {
            if source_prim(stage, &shader, input).is_some() {
                warnings.push(format!("{}: {input} from a texture is not supported; its value is used", shader.path()));
            }
        }
        if let Some(v) = reader.f64(&shader, "inputs:clearcoat")? {
            m.coat = if v.is_finite() { (v as f32).clamp(0.0, 1.0) } else { 0.0 };
        }
        m.coat_roughness = match reader.f64(&shader, "inputs:clearcoatRoughness")? {
            Some(v) if v.is_finite() => (v as f32).clamp(0.0, 1.0),
            _ => 0.01,
        };
        // Not a UsdPreviewSurface input in the spec: Blender's exporter writes its Principled
        // BSDF's Specular IOR Level here (0.5 = the dielectric F0 of the IOR), which is half of
        // the renderer's (KHR_materials_specular) factor.
        if let Some(level) = reader.f64(&shader, "inputs:specular")? {
            m.specular = (2.0 * level).max(0.0) as f32;
        }
        if let Some(ior) = reader.f64(&shader, "inputs:ior")? {
            if ior >= 1.0 {
                m.ior = ior as f32;
            }
        }
        // Opacity: a value, or the alpha of the diffuse colour's texture (Blender's export of an
        // image's alpha wired into the Principled BSDF's Alpha), which the renderer takes from
        // the base colour texture as glTF does.
        let diffuse_texture = source_prim(stage, &shader, "inputs:diffuseColor").map(|(p, _)| p.path().to_string());
        let (opacity, textured) = match source_prim(stage, &shader, "inputs:opacity") {
            Some((src, output)) => {
                let same = diffuse_texture.as_deref() == Some(src.path().to_string().as_str());
                if output == "outputs:a" && same && m.base_color_texture.is_some() {
                    (1.0, true)
                } else {
                    warnings.push(format!(
                        "{}: inputs:opacity from {}.{output} is not supported (only the alpha of the diffuseColor's texture); rendered opaque",
                        shader.path(),
                        src.path()
                    ));
                    (1.0, false)
                }
            }
            None => (reader.f64(&shader, "inputs:opacity")?.unwrap_or(1.0) as f32, false),
        };
        let threshold = reader.f64(&shader, "inputs:opacityThreshold")?.unwrap_or(0.0) as f32;
        m.base_color.w = opacity.clamp(0.0, 1.0);
        m.alpha_mode = if threshold > 0.0 && (textured || opacity < 1.0) {
            AlphaMode::Mask(threshold)
        } else if textured || opacity < 1.0 {
            AlphaMode::Blend
        } else {
            AlphaMode::Opaque
        };
        Ok(m)
    }

    fn texture(
        &mut self,
        reader: &Reader,
        scene: &mut Scene,
        tex: &usd::Prim,
        color: bool,
        warnings: &mut Vec<String>,
    ) -> Result<Option<TextureRef>, Error> {
        let id = reader.token(tex, "info:id")?.unwrap_or_default();
        if id != "UsdUVTexture" {
            warnings.push(format!("{}: shader '{id}' feeding a material input is not supported; ignored", tex.path()));
            return Ok(None);
        }
        let file = reader.asset(tex, "inputs:file")?;
        let space = reader.token(tex, "inputs:sourceColorSpace")?.unwrap_or_else(|| "auto".into());
        let wrap = |name: &str| -> Result<Wrap, Error> {
            Ok(match reader.token(tex, name)?.as_deref() {
                Some("clamp") => Wrap::ClampToEdge,
                Some("mirror") => Wrap::MirroredRepeat,
                _ => Wrap::Repeat,
            })
        };
        let (ws, wt) = (wrap("inputs:wrapS")?, wrap("inputs:wrapT")?);
        // inputs:st ← [UsdTransform2d ←] UsdPrimvarReader_float2 (varname)
        let mut transform = None;
        if let Some((mut src, _)) = source_prim(reader.stage, tex, "inputs:st") {
            let mut reaches_reader = true;
            if reader.token(&src, "info:id")?.as_deref() == Some("UsdTransform2d") {
                let rotation_deg = reader.f64(&src, "inputs:rotation")?.unwrap_or(0.0);
                let scale = reader.vec2(&src, "inputs:scale")?.unwrap_or(glam::DVec2::ONE);
                let translation = reader.vec2(&src, "inputs:translation")?.unwrap_or(glam::DVec2::ZERO);
                let finite = rotation_deg.is_finite() && scale.is_finite() && translation.is_finite();
                if !finite {
                    warnings.push(format!("{}: UsdTransform2d has non-finite inputs; not applied", src.path()));
                } else if rotation_deg != 0.0 || scale != glam::DVec2::ONE || translation != glam::DVec2::ZERO {
                    transform = Some(uv_transform(rotation_deg, scale, translation));
                }
                match source_prim(reader.stage, &src, "inputs:in") {
                    Some((s, _)) => src = s,
                    None => reaches_reader = false,
                }
            }
            if reaches_reader && reader.token(&src, "info:id")?.as_deref() == Some("UsdPrimvarReader_float2") {
                if let Some(v) = reader.token(&src, "inputs:varname")? {
                    self.pending_st = Some(v);
                }
            }
        }
        let path = match &file {
            Some((authored, Some(resolved))) if !resolved.is_empty() => (authored.clone(), resolved.clone()),
            Some((authored, _)) => (authored.clone(), authored.clone()),
            None => {
                warnings.push(format!("{}: inputs:file is not authored; rendered magenta", tex.path()));
                (String::new(), String::new())
            }
        };
        let srgb = color && space != "raw";
        let key = (path.1.clone(), srgb);
        if let Some(&i) = self.textures.get(&key) {
            return Ok(Some(TextureRef { index: i, uv_set: 0, transform }));
        }
        let srgb_encoded = srgb && self.filter_encoded;
        let t = match load_image(&path.1, srgb && !srgb_encoded) {
            Ok((w, h, texels)) => Texture {
                name: path.0.clone(),
                width: w,
                height: h,
                texels,
                wrap_s: ws,
                wrap_t: wt,
                bilinear: true,
                srgb_encoded,
            },
            Err(e) => {
                if !path.1.is_empty() {
                    warnings.push(format!(
                        "{}: inputs:file '{}' cannot be read ({e}); rendered magenta",
                        tex.path(),
                        path.0
                    ));
                }
                Texture::constant("missing", MAGENTA)
            }
        };
        scene.textures.push(Arc::new(t));
        let i = scene.textures.len() - 1;
        self.textures.insert(key, i);
        Ok(Some(TextureRef { index: i, uv_set: 0, transform }))
    }
}

/// The bytes of `inner` in the usdz package `package` (a zip archive).
pub(crate) fn read_packaged(package: &str, inner: &str) -> Result<Vec<u8>, String> {
    use std::io::Read;
    if openusd::ar::is_package_relative_path(inner) {
        return Err("nested packages are not read".into());
    }
    let file = std::fs::File::open(package).map_err(|e| format!("{package}: {e}"))?;
    let mut zip = zip::ZipArchive::new(file).map_err(|e| format!("{package}: {e}"))?;
    let mut entry = zip.by_name(inner).map_err(|e| format!("{package}[{inner}]: {e}"))?;
    let mut bytes = Vec::new();
    entry.read_to_end(&mut bytes).map_err(|e| format!("{package}[{inner}]: {e}"))?;
    Ok(bytes)
}

/// (width, height, texels), decoded to linear with `srgb`: before filtering, as USD's renderers
/// (Storm's sRGB textures, Karma, RenderMan) do; only Cycles filters sRGB images encoded (see
/// `Texture`), which this crate follows on stages Blender wrote, as the add-on does.
fn load_image(path: &str, srgb: bool) -> Result<(u32, u32, Vec<Vec4>), String> {
    let img = match openusd::ar::split_package_relative_path_outer(path) {
        Some((package, inner)) => {
            let bytes = read_packaged(&package, &inner)?;
            image::load_from_memory(&bytes).map_err(|e| e.to_string())?
        }
        None => image::ImageReader::open(path)
            .map_err(|e| e.to_string())?
            .with_guessed_format()
            .map_err(|e| e.to_string())?
            .decode()
            .map_err(|e| e.to_string())?,
    };
    let rgba = img.to_rgba32f();
    let decode = |c: f32| if srgb { petzval_renderer::scene::texture::srgb_to_linear(c) } else { c };
    let texels = rgba.pixels().map(|p| Vec4::new(decode(p[0]), decode(p[1]), decode(p[2]), p[3])).collect();
    Ok((img.width(), img.height(), texels))
}

/// An unbound gprim's `primvars:displayColor`.
enum DisplayColor {
    /// One colour (or none authored: 18 % grey).
    One(Vec3),
    /// A colour per face, point or corner: vertex colours.
    PerElement,
}

fn display_color(reader: &Reader, prim: &usd::Prim) -> Result<DisplayColor, Error> {
    Ok(match reader.vec3s(prim, "primvars:displayColor")? {
        Some(c)
            if c.len() > 1
                && prim.type_name().ok().flatten().is_some_and(|t| matches!(t.as_str(), "Mesh" | "BasisCurves")) =>
        {
            DisplayColor::PerElement
        }
        Some(c) if !c.is_empty() => DisplayColor::One(c[0].as_vec3()),
        _ => DisplayColor::One(Vec3::splat(0.18)),
    })
}

/// UsdPreviewSurface's fallbacks with this base colour.
fn preview_default(name: &str, color: Vec3) -> Material {
    Material {
        name: name.to_string(),
        base_color: color.extend(1.0),
        metallic: 0.0,
        roughness: 0.5,
        ..Material::default()
    }
}

/// UsdTransform2d (`st' = R(rotation) · (st ⊙ scale) + translation`, rotation counter-clockwise
/// in degrees, as the UsdPreviewSurface spec defines it) in the renderer's texture coordinates,
/// whose v runs down from the top (`v = 1 − t`): `m = D A D`, `offset = D (A e + b) + e` with
/// `D = diag(1, −1)`, `e = (0, 1)`.
fn uv_transform(rotation_deg: f64, scale: glam::DVec2, translation: glam::DVec2) -> UvTransform {
    let a = glam::DMat2::from_angle(rotation_deg.to_radians()) * glam::DMat2::from_diagonal(scale);
    let d = glam::DMat2::from_diagonal(glam::DVec2::new(1.0, -1.0));
    let e = glam::DVec2::new(0.0, 1.0);
    let m = d * a * d;
    let offset = d * (a * e + translation) + e;
    UvTransform { m: m.as_mat2(), offset: offset.as_vec2() }
}
