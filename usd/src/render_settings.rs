//! UsdRender: the RenderSettings prim a render uses (given, else the stage's
//! `renderSettingsPrimPath` metadata) and its RenderProducts (each rendered in turn).
//!
//! | attribute | on | meaning | fallback |
//! |---|---|---|---|
//! | `camera` (rel) | RenderSettings, overridden by the product's | the camera prim | the first camera |
//! | `resolution` (int2) | RenderSettings, overridden by the product's | pixels | 2048 × 1080 |
//! | `pixelAspectRatio` | RenderSettings, overridden by the product's | non-square pixels: the frame covers `columns × ratio / rows` of the film back (`--pixel-aspect` overrides) | 1 |
//! | `aspectRatioConformPolicy` (token) | RenderSettings, overridden by the product's | how the camera's aperture is fitted to the image's aspect (`--aspect-conform` overrides) | `expandAperture` |
//! | `dataWindowNDC` (float4) | RenderSettings, overridden by the product's | the pixels rendered: a crop inside (0, 0, 1, 1), overscan beyond it (`--data-window` overrides) | (0, 0, 1, 1) |
//! | `includedPurposes` (token[]) | RenderSettings | the purposes of the geometry rendered | `default`, `render` |
//! | `instantaneousShutter`, `disableMotionBlur` | either | nothing to do: petzval renders no motion blur | — |
//! | `disableDepthOfField` (bool) | RenderSettings, overridden by the product's | true: no depth of field (a thin lens renders as a pinhole; a real lens keeps its stop, listed; `--no-dof` asks for it too) | false |
//! | `products` (rel) | RenderSettings | RenderProduct prims; the first is rendered | none |
//! | `productName` | RenderProduct | the output file (`####` = frame) | — |
//! | `orderedVars` (rel) | RenderProduct | RenderVar prims: their `sourceName` picks the EXR's channels (color/Ci/rgba always; depth/z, normal/N, albedo/diffuseColor; others listed as skipped) unless `--aovs` is given | — |

use crate::value::{attr_error, Reader};
use crate::Error;
use openusd::sdf;
use std::path::Path;

/// What a RenderSettings prim asks for.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RenderSettings {
    /// Its prim path.
    pub path: String,
    /// Camera prim (the product's, else the settings').
    pub camera: Option<String>,
    /// Resolution (the product's, else the settings', else 2048 × 1080).
    pub resolution: (u32, u32),
    /// The product's `productName`.
    pub product_name: Option<String>,
    /// The product's RenderVar prims.
    pub vars: Vec<String>,
    /// The EXR channels the RenderVars ask for (`depth`, `normal`, `albedo`; colour is always
    /// written).
    pub aovs: Vec<String>,
    /// Width over height of one pixel (`pixelAspectRatio`).
    pub pixel_aspect: f64,
    /// `aspectRatioConformPolicy` (one of UsdRender's tokens).
    pub aspect_conform: String,
    /// `dataWindowNDC` (xmin, ymin, xmax, ymax); None when unauthored.
    pub data_window_ndc: Option<[f64; 4]>,
    /// `includedPurposes` (the settings'; products cannot change which geometry exists).
    pub included_purposes: Vec<String>,
    /// `disableDepthOfField`.
    pub disable_depth_of_field: bool,
    /// What was ignored.
    pub warnings: Vec<String>,
    /// The RenderProduct these values come from (None: the settings alone).
    pub product_path: Option<String>,
    /// The further products, each rendered in turn with its own camera, resolution and output.
    pub others: Vec<RenderSettings>,
}

fn first_target(prim: &openusd::usd::Prim, rel: &str) -> Result<Option<sdf::Path>, Error> {
    prim.relationship(rel)
        .targets()
        .map(|t| t.into_iter().next())
        .map_err(|e| attr_error(prim, rel, format!("cannot be read: {e:#}")))
}

fn resolution(reader: &Reader, prim: &openusd::usd::Prim) -> Result<Option<(u32, u32)>, Error> {
    match reader.raw(prim, "resolution")? {
        None => Ok(None),
        Some(sdf::Value::Vec2i(v)) if v.x > 0 && v.y > 0 => Ok(Some((v.x as u32, v.y as u32))),
        Some(v) => Err(attr_error(prim, "resolution", format!("expected a positive int2, got {v:?}"))),
    }
}

/// The render settings of the shot at `path`: the prim `settings`, else the one the stage's
/// `renderSettingsPrimPath` names; None when neither is there.
pub fn read(path: &Path, time: Option<f64>, settings: Option<&str>) -> Result<Option<RenderSettings>, Error> {
    let stage = crate::open_stage(path)?;
    let file = path.display().to_string();
    let meta = match stage.stage_metadata("renderSettingsPrimPath") {
        Ok(Some(sdf::Value::String(s))) => Some(s),
        Ok(Some(sdf::Value::Token(t))) => Some(t.as_str().to_string()),
        _ => None,
    };
    let Some(p) = settings.map(str::to_string).or(meta) else { return Ok(None) };
    let bad = |m: String| Error::Prim { layer: file.clone(), prim: p.clone(), message: m };
    let sp = sdf::path(&p).map_err(|e| bad(format!("not a prim path: {e:#}")))?;
    let prim = stage.prim(sp);
    let ty = prim.type_name().ok().flatten().map(|t| t.as_str().to_string()).unwrap_or_default();
    if ty != "RenderSettings" {
        return Err(bad(if ty.is_empty() {
            "no RenderSettings prim at this path".into()
        } else {
            format!("is a {ty}, not a RenderSettings prim")
        }));
    }
    let time = time.or(if stage.has_authored_time_code_range() { Some(stage.start_time_code()) } else { None });
    let reader = Reader { stage: &stage, time };
    let mut out = RenderSettings {
        path: p.clone(),
        camera: first_target(&prim, "camera")?.map(|c| c.to_string()),
        resolution: resolution(&reader, &prim)?.unwrap_or((2048, 1080)),
        product_name: None,
        vars: Vec::new(),
        aovs: Vec::new(),
        pixel_aspect: 1.0,
        aspect_conform: CONFORM_POLICIES[0].to_string(),
        data_window_ndc: None,
        included_purposes: vec!["default".into(), "render".into()],
        disable_depth_of_field: false,
        warnings: Vec::new(),
        product_path: None,
        others: Vec::new(),
    };
    apply_base(&mut out, &reader, &prim)?;
    match reader.raw(&prim, "includedPurposes")? {
        None => {}
        Some(sdf::Value::TokenVec(v)) => out.included_purposes = v.iter().map(|t| t.as_str().to_string()).collect(),
        Some(sdf::Value::StringVec(v)) => out.included_purposes = v,
        Some(v) => return Err(attr_error(&prim, "includedPurposes", format!("expected token[], got {v:?}"))),
    }
    for p in &out.included_purposes {
        if !matches!(p.as_str(), "default" | "render" | "proxy" | "guide") {
            return Err(attr_error(
                &prim,
                "includedPurposes",
                format!("'{p}' is not a purpose (default, render, proxy, guide)"),
            ));
        }
    }
    let products = prim
        .relationship("products")
        .targets()
        .map_err(|e| attr_error(&prim, "products", format!("cannot be read: {e:#}")))?;
    // 2. Each product: its camera, resolution, output and RenderVars over the settings'.
    let base = out.clone();
    for (k, pp) in products.iter().enumerate() {
        let mut o = base.clone();
        o.warnings.clear();
        apply_product(&mut o, &stage, &reader, pp)?;
        if k == 0 {
            out = RenderSettings { warnings: [out.warnings, o.warnings.clone()].concat(), ..o };
        } else {
            out.others.push(o);
        }
    }
    if out.others.iter().any(|o| o.product_name.is_none() || o.product_name == out.product_name) {
        out.warnings.push(format!("{p}.products: products without their own productName share the first's output"));
    }
    Ok(Some(out))
}

/// One RenderProduct over the settings: its camera, resolution, productName and RenderVars.
fn apply_product(
    out: &mut RenderSettings,
    stage: &openusd::usd::Stage,
    reader: &Reader,
    pp: &sdf::Path,
) -> Result<(), Error> {
    let product = stage.prim(pp.clone());
    out.product_path = Some(pp.to_string());
    if let Some(c) = first_target(&product, "camera")? {
        out.camera = Some(c.to_string());
    }
    if let Some(r) = resolution(reader, &product)? {
        out.resolution = r;
    }
    apply_base(out, reader, &product)?;
    out.product_name = reader.token(&product, "productName")?.filter(|s| !s.is_empty());
    let targets = product
        .relationship("orderedVars")
        .targets()
        .map_err(|e| attr_error(&product, "orderedVars", format!("cannot be read: {e:#}")))?;
    out.vars = targets.iter().map(|v| v.to_string()).collect();
    // RenderVars: their sourceName picks the EXR's channels.
    for t in &targets {
        let v = t.to_string();
        let var = stage.prim(t.clone());
        let source = reader.token(&var, "sourceName")?.unwrap_or_default();
        match aov_of_source(&source) {
            Some("") => {}
            Some(a) => {
                if !out.aovs.iter().any(|x| x == a) {
                    out.aovs.push(a.to_string());
                }
            }
            None => out.warnings.push(format!(
                "{v}: RenderVar sourceName '{source}' is not a channel petzval renders (color, depth, normal, albedo); skipped"
            )),
        }
    }
    Ok(())
}

/// UsdRender's `aspectRatioConformPolicy` tokens (the first is the fallback).
pub const CONFORM_POLICIES: [&str; 5] =
    ["expandAperture", "cropAperture", "adjustApertureWidth", "adjustApertureHeight", "adjustPixelAspectRatio"];

/// The RenderSettingsBase attributes authored on `prim` (the settings, then a product over
/// them) other than camera and resolution: pixel aspect, conform policy, data window and the
/// depth-of-field switch.
fn apply_base(out: &mut RenderSettings, reader: &Reader, prim: &openusd::usd::Prim) -> Result<(), Error> {
    if reader.raw(prim, "pixelAspectRatio")?.is_some() {
        let par = reader.f64_or(prim, "pixelAspectRatio", 1.0)?;
        if !(par.is_finite() && par > 0.0) {
            return Err(attr_error(prim, "pixelAspectRatio", format!("must be positive, got {par}")));
        }
        out.pixel_aspect = par;
    }
    if let Some(p) = reader.token(prim, "aspectRatioConformPolicy")? {
        if !CONFORM_POLICIES.contains(&p.as_str()) {
            return Err(attr_error(
                prim,
                "aspectRatioConformPolicy",
                format!("'{p}' is not a policy ({})", CONFORM_POLICIES.join(", ")),
            ));
        }
        out.aspect_conform = p;
    }
    let window = match reader.raw(prim, "dataWindowNDC")? {
        None => None,
        Some(sdf::Value::Vec4f(v)) => Some([v.x, v.y, v.z, v.w].map(f64::from)),
        Some(sdf::Value::Vec4d(v)) => Some([v.x, v.y, v.z, v.w]),
        Some(v) => return Err(attr_error(prim, "dataWindowNDC", format!("expected a float4, got {v:?}"))),
    };
    if let Some(w) = window {
        let ok = w.iter().all(|v| v.is_finite()) && w[0] < w[2] && w[1] < w[3];
        if !ok {
            return Err(attr_error(
                prim,
                "dataWindowNDC",
                format!("{w:?} must be (xmin, ymin, xmax, ymax) with xmin < xmax and ymin < ymax"),
            ));
        }
        out.data_window_ndc = Some(w);
    }
    if let Some(d) = reader.bool(prim, "disableDepthOfField")? {
        out.disable_depth_of_field = d;
    }
    Ok(())
}

/// The channel a RenderVar's `sourceName` names: `Some("")` for the colour (always written),
/// `Some(aov)` for one of ours, `None` for one we do not render. Names as Pixar's, Karma's,
/// Cycles' and RenderMan's exporters write them.
fn aov_of_source(source: &str) -> Option<&'static str> {
    match source.to_ascii_lowercase().as_str() {
        "color" | "ci" | "rgba" | "rgb" | "beauty" | "combined" => Some(""),
        "depth" | "z" | "distance" => Some("depth"),
        "normal" | "n" | "nn" | "normals" => Some("normal"),
        "albedo" | "diffusecolor" | "diffuse_color" | "basecolor" | "base_color" => Some("albedo"),
        _ => None,
    }
}
