//! Petzval's USD stage: a USD shot (`.usda`, `.usdc`, `.usdz`, composed by `openusd` 0.6)
//! → the renderer's instanced [`Scene`], its cameras as [`HostCamera`]s (with the
//! `PetzvalLensAPI` lens data), lights and materials, at one time code.
//!
//! | parameter | type | meaning | default |
//! |---|---|---|---|
//! | `path` | file | the shot's root layer | — |
//! | `time` | optional f64 | time code to read (`--frame`) | the stage's `startTimeCode` if authored, else the default values |
//! | `subdivision_level` | u32 | Catmull-Clark levels of `subdivisionScheme = catmullClark` meshes (`--subdivision-level`) | 2 |
//!
//! Modules: [`value`] (typed reads, errors naming layer/prim/attribute), [`xform`] (xform ops,
//! up axis, units), [`mesh`] (UsdGeomMesh), [`curves`] (UsdGeomBasisCurves as tubes), [`skel`] (UsdSkel skinning and blend shapes), [`subdiv`] (Catmull-Clark), [`shapes`] (intrinsic shapes), [`stage`] (the walk, instancing),
//! [`camera`] (UsdGeomCamera + `PetzvalLensAPI`), [`lights`] (UsdLux), [`shading`]
//! (UsdPreviewSurface), [`render_settings`] (UsdRender), [`author`] (`set-lens`). What is and is not read: `docs/usd.md`.
//!
//! Composition (sublayers, references, payloads, variants, native instancing) is openusd's;
//! a reference or payload it cannot resolve is listed as a warning (openusd reports it as a
//! recoverable composition error) and the rest of the stage still loads.

pub mod author;
pub mod binding;
pub mod camera;
pub mod curves;
#[doc(hidden)]
pub mod fuzzing;
pub mod lights;
pub mod mesh;
pub mod render_settings;
pub mod shading;
pub mod shapes;
pub mod skel;
pub mod stage;
pub mod subdiv;
pub mod value;
pub mod xform;

pub use camera::{PetzvalLens, UsdCamera};
pub use stage::{MeshInfo, StageInfo};
pub use xform::StageUnits;

use openusd::usd;
use petzval_renderer::camera::host::HostCamera;
use petzval_renderer::scene::Scene;
use std::path::Path;

/// Errors of the USD stage: each names the layer, prim path and attribute where it has them.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The stage cannot be opened.
    #[error("{file}: cannot open the USD stage: {message}")]
    Open {
        /// The root layer's file.
        file: String,
        /// openusd's message.
        message: String,
    },
    /// Bad stage metadata.
    #[error("{layer}: stage metadata {field}: {message}")]
    Stage {
        /// Layer.
        layer: String,
        /// Metadata field.
        field: String,
        /// What is wrong.
        message: String,
    },
    /// A bad or unreadable attribute.
    #[error("{layer}: {prim}.{attribute}: {message}")]
    Attribute {
        /// The strongest layer with an opinion on it.
        layer: String,
        /// Prim path.
        prim: String,
        /// Attribute name.
        attribute: String,
        /// What is wrong.
        message: String,
    },
    /// A bad prim.
    #[error("{layer}{}{prim}: {message}", if layer.is_empty() { "" } else { ": " })]
    Prim {
        /// Layer (may be empty when the value no longer knows it).
        layer: String,
        /// Prim path.
        prim: String,
        /// What is wrong.
        message: String,
    },
    /// A camera asked for is not there.
    #[error("{file}: camera {camera}: {message}")]
    Camera {
        /// The shot.
        file: String,
        /// The prim path asked for.
        camera: String,
        /// What is wrong.
        message: String,
    },
    /// Authoring failed (`set-lens`).
    #[error("{file}: cannot write: {message}")]
    Author {
        /// Output layer.
        file: String,
        /// openusd's message.
        message: String,
    },
    /// An error of the renderer (lens files, camera validation).
    #[error(transparent)]
    Renderer(#[from] petzval_renderer::Error),
}

/// A loaded shot at one time code.
pub struct UsdShot {
    /// The root layer's path.
    pub file: String,
    /// The scene (metres, +y up), warnings included.
    pub scene: Scene,
    /// Every camera prim found (outside prototypes), in traversal order.
    pub cameras: Vec<UsdCamera>,
    /// Units of the stage.
    pub units: StageUnits,
    /// The time code read (None = default values).
    pub time: Option<f64>,
    /// Meshes, instances and lights as read.
    pub info: StageInfo,
    /// The stage's authored frame range (start, end, time codes per second).
    pub frame_range: Option<(f64, f64, f64)>,
}

/// Whether `path` names a USD file by its extension.
pub fn is_usd_path(path: &Path) -> bool {
    matches!(
        path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase()).as_deref(),
        Some("usd" | "usda" | "usdc" | "usdz")
    )
}

/// Opens the stage (all payloads loaded).
pub fn open_stage(path: &Path) -> Result<usd::Stage, Error> {
    let file = path.display().to_string();
    if !path.is_file() {
        return Err(Error::Open { file, message: "no such file".into() });
    }
    let s = path.to_str().ok_or_else(|| Error::Open { file: file.clone(), message: "path is not UTF-8".into() })?;
    // openusd is young: a panic inside it on malformed input must not take the process down.
    match std::panic::catch_unwind(|| usd::Stage::open(s)) {
        Ok(Ok(stage)) => Ok(stage),
        Ok(Err(e)) => Err(Error::Open { file, message: format!("{e:#}") }),
        Err(_) => Err(Error::Open { file, message: "openusd panicked while reading the file".into() }),
    }
}

/// Loads the shot at `path` at time code `time` (see the module table for the default).
pub fn load(path: &Path, time: Option<f64>) -> Result<UsdShot, Error> {
    load_with(path, &LoadOptions { time, ..Default::default() })
}

/// How a shot is read: [`load`]'s time code and the subdivision level.
#[derive(Debug, Clone, Copy)]
pub struct LoadOptions {
    /// Time code to read (`--frame`); None: the stage's `startTimeCode` if authored.
    pub time: Option<f64>,
    /// Catmull-Clark levels for meshes whose `subdivisionScheme` is `catmullClark`
    /// (`--subdivision-level`; 0 renders the cage).
    pub subdivision_level: u32,
    /// The `purpose` values rendered (a RenderSettings' `includedPurposes`).
    pub purposes: Purposes,
}

impl Default for LoadOptions {
    fn default() -> Self {
        LoadOptions { time: None, subdivision_level: subdiv::DEFAULT_LEVEL, purposes: Purposes::default() }
    }
}

/// Which geometry purposes a render includes (UsdRender's `includedPurposes`). A prim's
/// purpose is its authored `purpose` unless an ancestor's is other than `default`, which it
/// then inherits (UsdGeomImageable).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Purposes {
    /// `default`.
    pub default: bool,
    /// `render`.
    pub render: bool,
    /// `proxy`.
    pub proxy: bool,
    /// `guide`.
    pub guide: bool,
}

impl Default for Purposes {
    fn default() -> Self {
        Purposes { default: true, render: true, proxy: false, guide: false }
    }
}

impl Purposes {
    /// The purposes named (`default`, `render`, `proxy`, `guide`; others are ignored).
    pub fn from_names<S: AsRef<str>>(names: &[S]) -> Self {
        let has = |p: &str| names.iter().any(|n| n.as_ref() == p);
        Purposes { default: has("default"), render: has("render"), proxy: has("proxy"), guide: has("guide") }
    }

    /// Whether geometry of purpose `p` is rendered (an unknown purpose counts as `default`).
    pub fn includes(&self, p: &str) -> bool {
        match p {
            "render" => self.render,
            "proxy" => self.proxy,
            "guide" => self.guide,
            _ => self.default,
        }
    }
}

/// [`load`] with every option.
pub fn load_with(path: &Path, options: &LoadOptions) -> Result<UsdShot, Error> {
    let time = options.time;
    let stage = open_stage(path)?;
    let file = path.display().to_string();
    let frame_range = if stage.has_authored_time_code_range() {
        Some((stage.start_time_code(), stage.end_time_code(), stage.time_codes_per_second()))
    } else {
        None
    };
    let time = time.or(frame_range.map(|r| r.0));
    let mut walker = stage::Walker::new(&stage, time)?;
    walker.subdivision_level = options.subdivision_level;
    walker.purposes = options.purposes;
    let run = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| walker.run()));
    match run {
        Ok(r) => r?,
        Err(_) => {
            return Err(Error::Open { file, message: "openusd panicked while composing the stage".into() });
        }
    }
    let mut warnings: Vec<String> = stage.composition_errors().iter().map(|e| format!("composition: {e}")).collect();
    warnings.append(&mut walker.warnings);
    let mut seen = std::collections::BTreeSet::new();
    warnings.retain(|w| seen.insert(w.clone()));
    let mut scene = walker.scene;
    scene.warnings = warnings;
    scene.source = path.display().to_string();
    Ok(UsdShot { file, scene, cameras: walker.cameras, units: walker.units, time, info: walker.info, frame_range })
}

impl UsdShot {
    /// The camera at prim `path`, or the first camera when `path` is None. A `path` without a
    /// '/' is a name: the camera whose prim, or whose parent prim, has it (Blender exports a
    /// camera object `Camera` as `/root/Camera/Camera`), when exactly one does.
    pub fn camera(&self, path: Option<&str>) -> Result<&UsdCamera, Error> {
        let names = || self.cameras.iter().map(|c| c.path.as_str()).collect::<Vec<_>>().join(", ");
        if let Some(name) = path.filter(|p| !p.contains('/') && !p.is_empty()) {
            let named = |c: &&UsdCamera| {
                let mut parts = c.path.rsplit('/');
                parts.next() == Some(name) || parts.next() == Some(name)
            };
            let found: Vec<&UsdCamera> = self.cameras.iter().filter(named).collect();
            return match found.as_slice() {
                [one] => Ok(one),
                _ => Err(Error::Camera {
                    file: self.file.clone(),
                    camera: name.into(),
                    message: if found.is_empty() {
                        format!("no Camera prim, or parent of one, has this name (cameras: {})", {
                            let n = names();
                            if n.is_empty() {
                                "none".to_string()
                            } else {
                                n
                            }
                        })
                    } else {
                        format!(
                            "several cameras have this name: {}; give a prim path",
                            found.iter().map(|c| c.path.as_str()).collect::<Vec<_>>().join(", ")
                        )
                    },
                }),
            };
        }
        match path {
            Some(p) => self.cameras.iter().find(|c| c.path == p).ok_or_else(|| Error::Camera {
                file: self.file.clone(),
                camera: p.into(),
                message: format!("no Camera prim at this path (cameras: {})", {
                    let n = names();
                    if n.is_empty() {
                        "none".to_string()
                    } else {
                        n
                    }
                }),
            }),
            None => self.cameras.first().ok_or_else(|| Error::Camera {
                file: self.file.clone(),
                camera: "(first)".into(),
                message: "the stage has no Camera prim".into(),
            }),
        }
    }

    /// The host camera of `camera`.
    pub fn host_camera(&self, camera: &UsdCamera) -> Result<HostCamera, Error> {
        camera.host_camera()
    }

    /// A JSON report of what was loaded (`petzval usd info --json`). `instances` lists every
    /// instance with its renderer-world and stage-world matrices (column-major).
    pub fn info_json(&self, instances: bool) -> serde_json::Value {
        use serde_json::json;
        let cams: Vec<_> = self
            .cameras
            .iter()
            .map(|c| {
                let mut v = serde_json::to_value(c).unwrap_or_default();
                v["to_world"] = json!(c.to_world.to_cols_array());
                v
            })
            .collect();
        let mut out = json!({
            "file": self.file,
            "time": self.time,
            "frame_range": self.frame_range,
            "up_axis": if self.units.up_axis_z { "Z" } else { "Y" },
            "meters_per_unit": self.units.meters_per_unit,
            "meshes": self.info.meshes,
            "mesh_count": self.scene.meshes.len(),
            "instance_count": self.scene.instances.len(),
            "instanced_triangles": self.scene.instanced_triangle_count(),
            "stored_triangles": self.scene.meshes.iter().map(|m| m.triangle_count()).sum::<usize>(),
            "materials": self.scene.materials.iter().map(|m| json!({
                "name": m.name,
                "base_color": m.base_color.to_array(),
                "metallic": m.metallic,
                "roughness": m.roughness,
                "emissive": m.emissive.to_array(),
                "ior": m.ior,
                "coat": m.coat,
                "coat_roughness": m.coat_roughness,
                "double_sided": m.double_sided,
                "base_color_texture": m.base_color_texture.map(|t| self.scene.textures[t.index].name.clone()),
                "base_color_uv_transform": m.base_color_texture.and_then(|t| t.transform).map(|t| {
                    [t.m.x_axis.x, t.m.y_axis.x, t.m.x_axis.y, t.m.y_axis.y, t.offset.x, t.offset.y]
                }),
            })).collect::<Vec<_>>(),
            "point_instancers": self.info.point_instancers.iter().map(|(p, n, h)| json!({"prim": p, "instances": n, "hidden": h})).collect::<Vec<_>>(),
            "native_instances": self.info.native_instances.iter().map(|(p, q)| json!({"prim": p, "prototype": q})).collect::<Vec<_>>(),
            "cameras": cams,
            "lights": self.info.lights,
            "environment": match &self.scene.environment {
                petzval_renderer::scene::Environment::Constant(c) => json!({"constant": c.to_array()}),
                _ => json!("map"),
            },
            "warnings": self.scene.warnings,
        });
        if instances {
            out["instances"] = self
                .scene
                .instances
                .iter()
                .zip(&self.info.instance_paths)
                .zip(&self.info.instance_stage_xf)
                .map(|((i, p), s)| {
                    json!({
                        "mesh": i.mesh,
                        "path": p,
                        "stage_world": s.to_cols_array(),
                        "world": glam::Mat4::from(i.object_to_world).to_cols_array(),
                    })
                })
                .collect();
        }
        out
    }
}
