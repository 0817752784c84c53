//! `petzval usd set-lens`: writes a lens onto a camera prim as a new layer over the shot,
//! authored with openusd's layer data API and its usda writer.
//!
//! | parameter | meaning |
//! |---|---|
//! | `shot` | the shot's root layer (the new layer sublayers it) |
//! | `camera` | the camera prim's path (must be a `Camera` in the composed shot) |
//! | `lens` | a library name or a lens file (written relative to the new layer when beside it, else absolute) |
//! | `lens_model`, `tilt_deg`, `blades` … | optional `PetzvalLensAPI` attributes (see [`crate::camera`]) |
//! | `out` | the new layer (`.usda`) |
//!
//! The layer holds `over` specs down to the camera, which prepends `PetzvalLensAPI` to its
//! `apiSchemas` and authors `petzval:lens` (and the optional attributes). The shot's stage
//! metadata (upAxis, metersPerUnit, time codes, defaultPrim, renderSettingsPrimPath) is
//! copied, since a stage reads it from its root layer only.

use crate::Error;
use openusd::sdf::{self, ChildrenKey, FieldKey, SpecType, Specifier, Value};
use std::path::{Path, PathBuf};

/// Optional `PetzvalLensAPI` attributes to author with the lens.
#[derive(Debug, Clone, Default)]
pub struct LensAttrs {
    /// `petzval:lensModel`.
    pub lens_model: Option<String>,
    /// `petzval:tolerancePx`.
    pub tolerance_px: Option<f64>,
    /// `petzval:tiltX`, `petzval:tiltY` (degrees).
    pub tilt_deg: Option<(f64, f64)>,
    /// `petzval:aperture:blades`.
    pub blades: Option<i32>,
    /// `petzval:aperture:rotation` (degrees).
    pub rotation_deg: Option<f64>,
}

/// The shot's root-layer metadata copied onto the lens layer.
const STAGE_FIELDS: [&str; 9] = [
    "upAxis",
    "metersPerUnit",
    "kilogramsPerUnit",
    "startTimeCode",
    "endTimeCode",
    "timeCodesPerSecond",
    "framesPerSecond",
    "defaultPrim",
    "renderSettingsPrimPath",
];

/// `path` as written in a layer at `layer_dir`: relative when beside it, else absolute.
fn layer_relative(path: &Path, layer_dir: &Path) -> String {
    let abs = path.canonicalize().unwrap_or_else(|_| path.to_path_buf());
    let dir = layer_dir.canonicalize().unwrap_or_else(|_| layer_dir.to_path_buf());
    match abs.strip_prefix(&dir) {
        Ok(rel) => format!("./{}", rel.display()),
        Err(_) => abs.display().to_string(),
    }
}

/// Writes the lens layer (see the module table).
pub fn set_lens(shot: &Path, camera: &str, lens: &str, attrs: &LensAttrs, out: &Path) -> Result<(), Error> {
    let out_s = out.display().to_string();
    let aerr = |m: String| Error::Author { file: out_s.clone(), message: m };
    // The camera must exist in the composed shot.
    let stage = crate::open_stage(shot)?;
    let cam_path = sdf::path(camera).map_err(|e| Error::Camera {
        file: shot.display().to_string(),
        camera: camera.into(),
        message: format!("not a prim path: {e:#}"),
    })?;
    let prim = stage.prim(cam_path.clone());
    let ty = prim.type_name().ok().flatten().map(|t| t.as_str().to_string());
    if ty.as_deref() != Some("Camera") {
        return Err(Error::Camera {
            file: shot.display().to_string(),
            camera: camera.into(),
            message: match ty {
                Some(t) if !t.is_empty() => format!("is a {t}, not a Camera"),
                _ => "no prim at this path".into(),
            },
        });
    }
    let out_dir: PathBuf = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new(".")).to_path_buf();
    let lens_value =
        if Path::new(lens).is_file() { layer_relative(Path::new(lens), &out_dir) } else { lens.to_string() };

    let mut data = sdf::Data::new();
    let root = sdf::Path::abs_root();
    let names: Vec<String> = cam_path.to_string().trim_start_matches('/').split('/').map(str::to_string).collect();
    {
        let spec = data.create_spec(root.clone(), SpecType::PseudoRoot);
        spec.add(FieldKey::SubLayers, Value::StringVec(vec![layer_relative(shot, &out_dir)]));
        spec.add(ChildrenKey::PrimChildren, Value::TokenVec(vec![names[0].as_str().into()]));
        spec.add(FieldKey::Documentation, Value::String(format!("petzval usd set-lens: {lens} on {camera}")));
        // Stage metadata is read from the root layer only: carry the shot's over, or the new
        // layer would compose with USD's fallbacks (metersPerUnit 0.01, upAxis Y, no frames).
        for field in STAGE_FIELDS {
            if let Ok(Some(v)) = stage.stage_metadata(field) {
                spec.add(field, v);
            }
        }
    }
    let mut path = String::new();
    for (i, name) in names.iter().enumerate() {
        path.push('/');
        path.push_str(name);
        let p = sdf::path(&path).map_err(|e| aerr(format!("{e:#}")))?;
        let spec = data.create_spec(p, SpecType::Prim);
        spec.add(FieldKey::Specifier, Value::Specifier(Specifier::Over));
        if let Some(next) = names.get(i + 1) {
            spec.add(ChildrenKey::PrimChildren, Value::TokenVec(vec![next.as_str().into()]));
        }
    }
    let mut props: Vec<(&str, &str, Value)> =
        vec![("petzval:lens", "asset", Value::AssetPath(sdf::AssetPath::new(lens_value)))];
    if let Some(m) = &attrs.lens_model {
        props.push(("petzval:lensModel", "token", Value::Token(m.as_str().into())));
    }
    if let Some(t) = attrs.tolerance_px {
        props.push(("petzval:tolerancePx", "float", Value::Float(t as f32)));
    }
    if let Some((x, y)) = attrs.tilt_deg {
        props.push(("petzval:tiltX", "float", Value::Float(x as f32)));
        props.push(("petzval:tiltY", "float", Value::Float(y as f32)));
    }
    if let Some(b) = attrs.blades {
        props.push(("petzval:aperture:blades", "int", Value::Int(b)));
    }
    if let Some(r) = attrs.rotation_deg {
        props.push(("petzval:aperture:rotation", "float", Value::Float(r as f32)));
    }
    {
        let spec = data.create_spec(cam_path.clone(), SpecType::Prim);
        spec.add(FieldKey::Specifier, Value::Specifier(Specifier::Over));
        let api = sdf::TokenListOp { prepended_items: vec!["PetzvalLensAPI".into()], ..Default::default() };
        spec.add(FieldKey::ApiSchemas, Value::TokenListOp(api));
        spec.add(ChildrenKey::PropertyChildren, Value::TokenVec(props.iter().map(|p| p.0.into()).collect()));
    }
    for (name, ty, value) in props {
        let p = cam_path.append_property(name).map_err(|e| aerr(format!("{e:#}")))?;
        let spec = data.create_spec(p, SpecType::Attribute);
        spec.add(FieldKey::TypeName, Value::Token(ty.into()));
        spec.add(FieldKey::Custom, Value::Bool(false));
        spec.add(FieldKey::Default, value);
    }
    let text = openusd::usda::TextWriter::write_to_string(&data).map_err(|e| aerr(format!("{e:#}")))?;
    // openusd 0.6's writer prints a one-item list op without brackets, which Pixar's parser
    // accepts for references but not for the token list of apiSchemas.
    let text = text.replace("apiSchemas = \"PetzvalLensAPI\"", "apiSchemas = [\"PetzvalLensAPI\"]");
    std::fs::write(out, text).map_err(|e| aerr(e.to_string()))
}
