//! Node animation: the translation, rotation and scale channels of every animation in the
//! file, evaluated at one time (seconds), replace the animated nodes' own TRS.
//!
//! | glTF | result |
//! |---|---|
//! | channel `translation`, `rotation`, `scale` | that part of the node's TRS at the time; the rest from the node |
//! | sampler `STEP`, `LINEAR` (rotation: shortest-path slerp), `CUBICSPLINE` (Hermite, tangents × the key interval) | as the glTF spec defines them; before the first key the first value, after the last the last |
//! | several animations | all applied at the same time (Blender writes one per object's action); where two target the same node and path, the later one wins, with a warning |
//! | channel `weights` | the node's morph target weights at the time (as many per key as the sampler holds; see `deform.rs`) |
//! | `KHR_animation_pointer` (a channel whose target is a JSON pointer, no node) | cameras' `perspective/yfov`, `znear`, `zfar` and `orthographic/xmag`, `ymag`; `KHR_lights_punctual` lights' `color`, `intensity`, `range`, `spot.innerConeAngle`, `spot.outerConeAngle` (the extension's spelling; `spot/…` read as well): their values at the time (Blender's exporter writes the focal length, a light's power and colour and a spot's size and blend so, with "Export Pointer Animation" in Scene mode; in files it wrote, its animated point and spot intensities are divided by 4π and suns' multiplied by 683, the conversions its static values have and its animated ones lack, and version 5.0's animated innerConeAngle, which holds the Spot Blend, is read as that) |
//! | `KHR_animation_pointer` on a material (`/materials/N/…`) | at the time, in place of the stored value and checked as it is: `pbrMetallicRoughness/baseColorFactor` (VEC4, alpha included), `metallicFactor`, `roughnessFactor`, `emissiveFactor`, `alphaCutoff` (in MASK mode), `normalTexture/scale`; the `extensions/…` factors `KHR_materials_emissive_strength/emissiveStrength`, `KHR_materials_ior/ior`, `KHR_materials_transmission/transmissionFactor`, `KHR_materials_clearcoat/clearcoatFactor`, `clearcoatRoughnessFactor`, `KHR_materials_specular/specularFactor`, `specularColorFactor`, `KHR_materials_anisotropy/anisotropyStrength`, `anisotropyRotation`; `KHR_texture_transform` `offset`, `rotation`, `scale` of `pbrMetallicRoughness/baseColorTexture`, `metallicRoughnessTexture` and `emissiveTexture` (a texture without the extension takes its defaults for the parts not animated). An extension the material lacks is animated from its defaults (the spec calls such a pointer invalid; the value is what the writer meant) | Blender 5.0's exporter (Principled BSDF inputs, sampled every frame, LINEAR or STEP as its sampling fallback says) writes `…/clearcoatRoughnessFactor ` with a trailing space, Specular Tint's `specularColorFactor` as a VEC4 and `anisotropyRotation` in turns where its still value is in radians: in files it wrote pointers are read trimmed, the fourth component dropped and the rotation read as turns. Its emission is colour × strength split per frame into emissiveFactor ≤ 1 and emissiveStrength, whose product is used. It drops an Alpha that is 1 at the exported frame (the material is then OPAQUE with no alpha channel) and a Specular Tint animated without Specular IOR Level: nothing in the file to read |
//! | other pointers (other material properties such as `occlusionTexture/strength` and the sheen, volume and iridescence extensions, textures' `texCoord`, meshes, nodes) | ignored with a warning naming each pointer; a material pointer to a material or texture the file lacks likewise |
//! | a pointer sampler whose output type is not the property's (a VEC3 for baseColorFactor) | error naming the animation, channel and pointer |
//! | an animated node with a `matrix` | the matrix kept, with a warning (the spec allows TRS only) |
//! | malformed sampler (input not scalar floats, counts that differ, times not increasing) | error naming the animation and channel |
//!
//! Blender's exporter writes a frame `f` at `f / fps` seconds (`io_scene_gltf2`,
//! `exp/animation/keyframes.py`: `frame / (fps · fps_base)`), so frame `f` of a Blender export
//! is rendered at that time; see `petzval render --frame` and `--fps`.

use super::accessors::read_accessor;
use super::{named, Loader};
use crate::Result;
use glam::{Quat, Vec3, Vec4};
use gltf::accessor::Dimensions;
use gltf::animation::{Interpolation, Property};
use std::cell::RefCell;
use std::collections::{HashMap, HashSet};

/// The animated parts of one node's TRS at the time asked.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct AnimatedTrs {
    /// Translation.
    pub translation: Option<Vec3>,
    /// Unit rotation.
    pub rotation: Option<Quat>,
    /// Scale.
    pub scale: Option<Vec3>,
}

/// Every animated node's state at the time asked.
#[derive(Debug, Clone, Default)]
pub(super) struct Animated {
    /// Node index → its animated TRS parts.
    pub trs: HashMap<usize, AnimatedTrs>,
    /// Node index → its morph target weights.
    pub weights: HashMap<usize, Vec<f32>>,
    /// JSON pointer (`KHR_animation_pointer`) → the value there.
    pub pointers: HashMap<String, Vec<f32>>,
    /// The material pointers whose values the materials took (the others target a material or
    /// texture the file lacks, and are reported).
    pub used: RefCell<HashSet<String>>,
}

/// One `KHR_animation_pointer` channel as the file states it (read from the JSON before the
/// gltf crate parses the file, which cannot hold such a channel).
#[derive(Debug, Clone)]
pub(super) struct PointerChannel {
    /// Where it is: "animation N 'name', channel C".
    loc: String,
    /// The JSON pointer it animates.
    pointer: Option<String>,
    /// The sampler's input (times) and output (values) accessors.
    input: Option<usize>,
    output: Option<usize>,
    /// The sampler's interpolation (LINEAR when not given).
    interpolation: String,
}

impl PointerChannel {
    /// Channel `channel` of animation `anim` (`samplers`: that animation's sampler list).
    pub(super) fn from_json(
        anim: usize,
        name: Option<&str>,
        channel: usize,
        c: &serde_json::Value,
        samplers: &serde_json::Value,
    ) -> Self {
        let sampler = c.get("sampler").and_then(|s| s.as_u64()).and_then(|i| samplers.get(i as usize));
        let index = |key: &str| sampler.and_then(|s| s.get(key)).and_then(|v| v.as_u64()).map(|v| v as usize);
        PointerChannel {
            loc: format!("{}, channel {channel}", named("animation", anim, name)),
            pointer: c
                .pointer("/target/extensions/KHR_animation_pointer/pointer")
                .and_then(|p| p.as_str())
                .map(str::to_string),
            input: index("input"),
            output: index("output"),
            interpolation: sampler
                .and_then(|s| s.get("interpolation"))
                .and_then(|v| v.as_str())
                .unwrap_or("LINEAR")
                .to_string(),
        }
    }
}

/// How many floats the property at a JSON `pointer` holds, where this loader applies it
/// (cameras', punctual lights' and materials' properties); None for any other pointer.
fn pointer_width(pointer: &str) -> Option<usize> {
    let parts: Vec<&str> = pointer.trim_start_matches('/').split('/').collect();
    let index_ok = |s: &str| s.parse::<usize>().is_ok();
    match parts.as_slice() {
        ["cameras", i, "perspective", "yfov" | "znear" | "zfar"] if index_ok(i) => Some(1),
        ["cameras", i, "orthographic", "xmag" | "ymag" | "znear" | "zfar"] if index_ok(i) => Some(1),
        ["extensions", "KHR_lights_punctual", "lights", i, "intensity" | "range"] if index_ok(i) => Some(1),
        ["extensions", "KHR_lights_punctual", "lights", i, "color"] if index_ok(i) => Some(3),
        ["extensions", "KHR_lights_punctual", "lights", i, "spot.innerConeAngle" | "spot.outerConeAngle"]
            if index_ok(i) =>
        {
            Some(1)
        }
        ["materials", i, property @ ..] if index_ok(i) => material_property_width(property),
        _ => None,
    }
}

/// The textures whose `KHR_texture_transform` this loader applies (`materials.rs`, `info_ref`).
const TRANSFORMED_TEXTURES: [&str; 3] =
    ["pbrMetallicRoughness/baseColorTexture", "pbrMetallicRoughness/metallicRoughnessTexture", "emissiveTexture"];

/// How many floats a material's property (its pointer after `/materials/N/`) holds, where this
/// loader applies it (`materials.rs`); None for any other.
fn material_property_width(property: &[&str]) -> Option<usize> {
    match property {
        ["pbrMetallicRoughness", "baseColorFactor"] => Some(4),
        ["pbrMetallicRoughness", "metallicFactor" | "roughnessFactor"] => Some(1),
        ["emissiveFactor"] => Some(3),
        ["alphaCutoff"] | ["normalTexture", "scale"] => Some(1),
        ["extensions", "KHR_materials_emissive_strength", "emissiveStrength"]
        | ["extensions", "KHR_materials_ior", "ior"]
        | ["extensions", "KHR_materials_transmission", "transmissionFactor"]
        | ["extensions", "KHR_materials_clearcoat", "clearcoatFactor" | "clearcoatRoughnessFactor"]
        | ["extensions", "KHR_materials_specular", "specularFactor"]
        | ["extensions", "KHR_materials_anisotropy", "anisotropyStrength" | "anisotropyRotation"] => Some(1),
        ["extensions", "KHR_materials_specular", "specularColorFactor"] => Some(3),
        [texture @ .., "extensions", "KHR_texture_transform", field] => {
            let texture = texture.join("/");
            if !TRANSFORMED_TEXTURES.contains(&texture.as_str()) {
                return None;
            }
            match *field {
                "offset" | "scale" => Some(2),
                "rotation" => Some(1),
                _ => None,
            }
        }
        _ => None,
    }
}

/// The pointer as this loader keys it: the extension's own spelling of a spot's cone angles
/// (`…/spot.innerConeAngle`, which Blender writes) for the JSON-pointer one (`…/spot/…`).
fn canonical_pointer(pointer: &str) -> String {
    pointer
        .replace("/spot/innerConeAngle", "/spot.innerConeAngle")
        .replace("/spot/outerConeAngle", "/spot.outerConeAngle")
}

/// A sampler's keys: times (s) and values (`n` floats per key; CUBICSPLINE: in-tangent,
/// value, out-tangent, each `n` floats).
struct Keys {
    times: Vec<f32>,
    values: Vec<f32>,
    n: usize,
    interpolation: Interpolation,
}

impl Keys {
    /// The value at `t` (n floats).
    fn at(&self, t: f32) -> Vec<f32> {
        let n = self.n;
        let cubic = self.interpolation == Interpolation::CubicSpline;
        // element k of key i (CUBICSPLINE: its value, between the two tangents)
        let value = |i: usize| {
            let base = if cubic { (3 * i + 1) * n } else { i * n };
            &self.values[base..base + n]
        };
        let last = self.times.len() - 1;
        // 1. Outside the keys: the first or the last value.
        if !(t > self.times[0]) {
            return value(0).to_vec();
        }
        if t >= self.times[last] {
            return value(last).to_vec();
        }
        // 2. The interval [t_i, t_i+1) holding t.
        let i = self.times.partition_point(|&k| k <= t) - 1;
        let dt = self.times[i + 1] - self.times[i];
        let s = (t - self.times[i]) / dt;
        let (a, b) = (value(i), value(i + 1));
        match self.interpolation {
            Interpolation::Step => a.to_vec(),
            Interpolation::Linear => a.iter().zip(b).map(|(x, y)| x + (y - x) * s).collect(),
            Interpolation::CubicSpline => {
                // Hermite: out-tangent of key i, in-tangent of key i + 1, scaled by the interval
                let out_tangent = &self.values[(3 * i + 2) * n..(3 * i + 3) * n];
                let in_tangent = &self.values[(3 * (i + 1)) * n..(3 * (i + 1) + 1) * n];
                let (s2, s3) = (s * s, s * s * s);
                let (h00, h10, h01, h11) =
                    (2.0 * s3 - 3.0 * s2 + 1.0, s3 - 2.0 * s2 + s, -2.0 * s3 + 3.0 * s2, s3 - s2);
                (0..n).map(|k| h00 * a[k] + h10 * dt * out_tangent[k] + h01 * b[k] + h11 * dt * in_tangent[k]).collect()
            }
        }
    }

    /// The rotation at `t`: LINEAR keys by shortest-path slerp, the others as [`Keys::at`];
    /// normalised.
    fn rotation_at(&self, t: f32) -> Quat {
        let q = |v: &[f32]| Quat::from_vec4(Vec4::from_slice(v));
        if self.interpolation == Interpolation::Linear && t > self.times[0] && t < self.times[self.times.len() - 1] {
            let i = self.times.partition_point(|&k| k <= t) - 1;
            let s = (t - self.times[i]) / (self.times[i + 1] - self.times[i]);
            let (a, b) = (q(&self.values[4 * i..4 * i + 4]), q(&self.values[4 * (i + 1)..4 * (i + 2)]));
            let (a, b) = (a.normalize(), b.normalize());
            // glam's slerp takes the shorter arc
            return a.slerp(b, s).normalize();
        }
        q(&self.at(t)).normalize()
    }
}

impl Loader<'_> {
    /// Every animated node's TRS parts and morph target weights at `time_s`.
    pub(super) fn animated_nodes(&mut self, time_s: f32) -> Result<Animated> {
        let mut out = Animated::default();
        let doc = self.doc;
        for anim in doc.animations() {
            let anim_loc = named("animation", anim.index(), anim.name());
            for channel in anim.channels() {
                let loc = format!("{anim_loc}, channel {}", channel.index());
                let target = channel.target();
                let node = target.node();
                let property = target.property();
                let dims = match property {
                    Property::Translation | Property::Scale => Dimensions::Vec3,
                    Property::Rotation => Dimensions::Vec4,
                    Property::MorphTargetWeights => Dimensions::Scalar,
                };
                if property != Property::MorphTargetWeights
                    && matches!(node.transform(), gltf::scene::Transform::Matrix { .. })
                {
                    self.warn(
                        &named("node", node.index(), node.name()),
                        "is animated but has a matrix (glTF allows TRS only); the matrix is kept",
                    );
                    continue;
                }
                // 1. The sampler's keys, checked.
                let sampler = channel.sampler();
                let input = sampler.input();
                let output = sampler.output();
                if input.dimensions() != Dimensions::Scalar {
                    return Err(self.error(&loc, format!("sampler input is {:?}, not SCALAR", input.dimensions())));
                }
                if output.dimensions() != dims {
                    return Err(self.error(&loc, format!("sampler output is {:?}, not {dims:?}", output.dimensions())));
                }
                let times = read_accessor(self, &input).map_err(|e| self.error(&loc, format!("sampler input: {e}")))?;
                let values =
                    read_accessor(self, &output).map_err(|e| self.error(&loc, format!("sampler output: {e}")))?;
                let interpolation = sampler.interpolation();
                let cubic = if interpolation == Interpolation::CubicSpline { 3 } else { 1 };
                let n = match dims {
                    Dimensions::Vec3 => 3,
                    Dimensions::Vec4 => 4,
                    // weights: as many per key as the output holds (one per morph target)
                    _ => (values.len() / (times.len() * cubic).max(1)).max(1),
                };
                let per_key = cubic * n;
                if times.is_empty() || values.len() != times.len() * per_key {
                    return Err(self.error(
                        &loc,
                        format!(
                            "{} key times but {} output floats ({per_key} floats per key)",
                            times.len(),
                            values.len()
                        ),
                    ));
                }
                if times.windows(2).any(|w| !(w[1] > w[0])) || !times.iter().all(|t| t.is_finite()) {
                    return Err(self.error(&loc, "key times are not finite and strictly increasing"));
                }
                let keys = Keys { times, values, n, interpolation };
                // 2. The value at the time.
                let entry = out.trs.entry(node.index()).or_default();
                let replaced = match property {
                    Property::Translation => entry.translation.replace(Vec3::from_slice(&keys.at(time_s))).is_some(),
                    Property::Scale => entry.scale.replace(Vec3::from_slice(&keys.at(time_s))).is_some(),
                    Property::Rotation => entry.rotation.replace(keys.rotation_at(time_s)).is_some(),
                    Property::MorphTargetWeights => out.weights.insert(node.index(), keys.at(time_s)).is_some(),
                };
                if replaced {
                    self.warn(
                        &loc,
                        format!(
                            "{} animates {property:?} again; this animation's value is used",
                            named("node", node.index(), node.name())
                        ),
                    );
                }
            }
        }
        Ok(out)
    }

    /// The values of the `KHR_animation_pointer` channels this loader applies at `time_s`, by
    /// pointer; the others are reported once.
    pub(super) fn animated_pointers(
        &mut self,
        channels: &[PointerChannel],
        time_s: f32,
    ) -> Result<HashMap<String, Vec<f32>>> {
        let mut out = HashMap::new();
        let mut ignored = Vec::new();
        for ch in channels {
            let loc = &ch.loc;
            // Blender 5.0's exporter writes `…/clearcoatRoughnessFactor ` (a trailing space,
            // `exp/material/extensions/clearcoat.py`): its pointers are read trimmed.
            let written = ch.pointer.as_deref().map(|p| if self.blender_written { p.trim_end() } else { p });
            let canonical = written.map(canonical_pointer);
            let Some((pointer, n)) = canonical.as_deref().and_then(|p| Some((p, pointer_width(p)?))) else {
                ignored.push(ch.pointer.clone().unwrap_or_else(|| format!("{loc} (no pointer)")));
                continue;
            };
            // 1. The sampler's keys, checked.
            let interpolation = match ch.interpolation.as_str() {
                "LINEAR" => Interpolation::Linear,
                "STEP" => Interpolation::Step,
                "CUBICSPLINE" => Interpolation::CubicSpline,
                other => return Err(self.error(loc, format!("sampler interpolation '{other}' is not a glTF one"))),
            };
            let accessor = |i: Option<usize>, what: &str| {
                i.and_then(|i| self.doc.accessors().nth(i))
                    .ok_or_else(|| self.error(loc, format!("sampler {what} accessor is missing or does not exist")))
            };
            let (input, output) = (accessor(ch.input, "input")?, accessor(ch.output, "output")?);
            let times = read_accessor(self, &input).map_err(|e| self.error(loc, format!("sampler input: {e}")))?;
            let values = read_accessor(self, &output).map_err(|e| self.error(loc, format!("sampler output: {e}")))?;
            let values = self.pointer_output(values, output.dimensions().multiplicity(), n, pointer, loc)?;
            let per_key = n * if interpolation == Interpolation::CubicSpline { 3 } else { 1 };
            if input.dimensions() != Dimensions::Scalar || times.is_empty() || values.len() != times.len() * per_key {
                return Err(self.error(
                    loc,
                    format!(
                        "{} key times but {} output floats ({per_key} per key for {pointer})",
                        times.len(),
                        values.len()
                    ),
                ));
            }
            if times.windows(2).any(|w| !(w[1] > w[0])) || !times.iter().all(|t| t.is_finite()) {
                return Err(self.error(loc, "key times are not finite and strictly increasing"));
            }
            // 2. The value at the time.
            let keys = Keys { times, values, n, interpolation };
            if out.insert(pointer.to_string(), keys.at(time_s)).is_some() {
                self.warn(loc, format!("{pointer} is animated again; this animation's value is used"));
            }
        }
        if !ignored.is_empty() {
            self.warn(
                "",
                format!(
                    "KHR_animation_pointer: {} not supported (the properties of cameras, punctual lights and materials that this loader reads are); ignored",
                    ignored.join(", ")
                ),
            );
        }
        Ok(out)
    }

    /// A pointer sampler's output values, `width` floats per element where the accessor stores
    /// `stored`: as they are when the two agree; else an error naming the channel, except in
    /// files Blender wrote, whose animated `specularColorFactor` is a VEC4 (Blender 5.0's
    /// Specular Tint is RGBA, `exp/animation/sampled/sampling_cache.py` keeps all four): its
    /// fourth component dropped.
    fn pointer_output(
        &self,
        values: Vec<f32>,
        stored: usize,
        width: usize,
        pointer: &str,
        loc: &str,
    ) -> Result<Vec<f32>> {
        if stored == width {
            return Ok(values);
        }
        if self.blender_written && stored == 4 && pointer.ends_with("/specularColorFactor") {
            return Ok(values.chunks_exact(4).flat_map(|c| c[..3].to_vec()).collect());
        }
        Err(self.error(loc, format!("sampler output has {stored} floats per element, {pointer} holds {width}")))
    }
}
