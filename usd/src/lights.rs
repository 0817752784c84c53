//! UsdLux lights → the renderer's lights, emissive meshes and environment, in the units
//! Blender's USD exporter writes (checked against Blender 5.0's `wm.usd_export`: a 1000 W
//! point light of radius 0.1 is written as `intensity = 1000/π` with `normalize = 1`, a 100 W
//! 2 × 1 area light as `100/π`, a 3 W/m² sun as `0.75`).
//!
//! Emitted radiance L = `intensity` × 2^`exposure` × `color` × (blackbody tint of
//! `colorTemperature` when `enableColorTemperature`), divided by the light's area when
//! `normalize` is on (areas in m², after metersPerUnit).
//!
//! | light | renderer | conversion | fallbacks |
//! |---|---|---|---|
//! | `SphereLight` | point light (spot with `shaping:cone:angle`) of radius r: a sphere (0 with `treatAsPoint`; in stages Blender wrote, Blender's default Soft Falloff, a disc facing each point, since its USD does not record the setting) | radiant intensity = L · π r² (normalize: intensity/4 · 2^E · color) W/sr; cone: outer = angle, fading as Blender's Spot Blend = softness ([`SpotFalloff::Blender`](petzval_renderer::scene::SpotFalloff)) | radius 0.5, normalize off |
//! | `RectLight` | a one-sided emissive quad facing −z, a light's emitter (no shadow, not there from behind: `Material::light_emitter`) | radiance L | width 1, height 1 |
//! | `DiskLight` | a one-sided emissive 32-gon facing −z | radiance L | radius 0.5 |
//! | `DistantLight` | directional light along −z, directions spread over its `angle` (angular diameter, degrees; twice the value in stages Blender wrote, whose exporter writes half the diameter) | irradiance = 4 · intensity · 2^E · color W/m² (Blender's factor) with `normalize`; without it intensity is the disc's radiance, so the irradiance is that times π tan²(angle/2) (Cycles' unnormalized sun), except at angle 0 | angle 0.53, normalize off |
//! | `DomeLight` | environment: `texture:file` (EXR, latlong) × intensity · 2^E · color, or the constant colour; turned about +y by the light's yaw | — | — |
//! | `CylinderLight` | the side of a one-sided emissive cylinder along x (48 sides), radiance L | radius 0.5, length 1 |
//!
//! Colour temperature is UsdLux's blackbody colour (luminance 1, [`blackbody_rgb`]): pxr's and
//! Blender's, so 6500 K is slightly blue-magenta, not white. Blender 5.0 writes
//! `enableColorTemperature = 1` on every light and `colorTemperature` only away from 6500 K, so
//! on a stage it wrote an enabled light without an authored temperature keeps its colour.
//! A sphere light with radius 0 and normalize off is treated as normalized (it has no area).

use crate::value::{layer_of_prim, Reader};
use crate::xform::StageUnits;
use crate::Error;
use glam::{DMat4, DVec3, Vec2, Vec3};
use openusd::usd;
use petzval_renderer::scene::{Light, Material, Mesh, Scene};

/// One light as read (for reports).
#[derive(Debug, Clone, serde::Serialize)]
pub struct LightInfo {
    /// Prim path.
    pub prim: String,
    /// USD type.
    pub kind: String,
    /// What it became in the renderer.
    pub renderer: String,
    /// Linear RGB of the converted quantity (W/sr, radiance or W/m²).
    pub value: [f32; 3],
}

/// Blackbody colours (linear Rec.709, brightest channel 1) from 1000 K to 10 000 K in steps of
/// 500 K: John Walker's "Colour Rendering of Spectra" (specrend.c), the table UsdLux's
/// `colorTemperature` is defined by.
const BLACKBODY_KNOTS: [[f32; 3]; 19] = [
    [1.000000, 0.027490, 0.000000],
    [1.000000, 0.149664, 0.000000],
    [1.000000, 0.256644, 0.008095],
    [1.000000, 0.372033, 0.067450],
    [1.000000, 0.476725, 0.153601],
    [1.000000, 0.570376, 0.259196],
    [1.000000, 0.653480, 0.377155],
    [1.000000, 0.726878, 0.501606],
    [1.000000, 0.791543, 0.628050],
    [1.000000, 0.848462, 0.753228],
    [1.000000, 0.898581, 0.874905],
    [1.000000, 0.942771, 0.991642],
    [0.906947, 0.890456, 1.000000],
    [0.828247, 0.841838, 1.000000],
    [0.765791, 0.801896, 1.000000],
    [0.715255, 0.768579, 1.000000],
    [0.673683, 0.740423, 1.000000],
    [0.638992, 0.716359, 1.000000],
    [0.609681, 0.695588, 1.000000],
];

/// A blackbody's linear Rec.709 colour at `kelvin` (clamped to 1000–10 000 K), luminance 1: a
/// Catmull-Rom spline through [`BLACKBODY_KNOTS`] (end knots repeated), as pxr's
/// `UsdLuxBlackbodyTemperatureAsRgb` and Blender's Blackbody give it. 6500 K is not white
/// ((1.043, 0.984, 1.035)): D65 is off the Planckian locus.
pub fn blackbody_rgb(kelvin: f64) -> Vec3 {
    // 1. The segment and the parameter within it.
    let last = BLACKBODY_KNOTS.len() - 1;
    let x = ((kelvin as f32 - 1000.0) / 9000.0).clamp(0.0, 1.0) * last as f32;
    let seg = (x.floor() as usize).min(last);
    let t = x - seg as f32;
    let knot = |i: isize| Vec3::from(BLACKBODY_KNOTS[i.clamp(0, last as isize) as usize]);
    let s = seg as isize;
    let (p0, p1, p2, p3) = (knot(s - 1), knot(s), knot(s + 1), knot(s + 2));
    // 2. The Catmull-Rom cubic between p1 and p2.
    let a = -0.5 * p0 + 1.5 * p1 - 1.5 * p2 + 0.5 * p3;
    let b = p0 - 2.5 * p1 + 2.0 * p2 - 0.5 * p3;
    let c = -0.5 * p0 + 0.5 * p2;
    let rgb = ((a * t + b) * t + c) * t + p1;
    // 3. Luminance 1, and no negative overshoot.
    let y = 0.2126 * rgb.x + 0.7152 * rgb.y + 0.0722 * rgb.z;
    if y > 0.0 {
        (rgb / y).max(Vec3::ZERO)
    } else {
        Vec3::ONE
    }
}

/// What a light prim adds to the scene besides lights, materials and the environment.
pub struct LightOutput<'a> {
    /// The scene (lights, materials and environment are added to it).
    pub scene: &'a mut Scene,
    /// Warnings.
    pub warnings: &'a mut Vec<String>,
    /// Lights read.
    pub infos: &'a mut Vec<LightInfo>,
    /// Emissive meshes of area lights to place at the light's stage-world transform.
    pub meshes: Vec<(Mesh, DMat4, String)>,
}

/// Reads one light prim of type `ty` placed at `world` (stage world).
pub fn read_light(
    r: &Reader,
    units: &StageUnits,
    w: &mut LightOutput,
    prim: &usd::Prim,
    ty: &str,
    world: DMat4,
) -> Result<(), Error> {
    let path = prim.path().to_string();
    let mpu = units.meters_per_unit;
    let intensity = r.f64_or(prim, "inputs:intensity", 1.0)?;
    let exposure = r.f64_or(prim, "inputs:exposure", 0.0)?;
    let color = r.vec3(prim, "inputs:color")?.unwrap_or(DVec3::ONE);
    let normalize = r.bool(prim, "inputs:normalize")?.unwrap_or(false);
    let mut tint = Vec3::ONE;
    if r.bool(prim, "inputs:enableColorTemperature")?.unwrap_or(false) {
        // Blender 5.0's exporter writes enableColorTemperature = 1 on every light, whether its
        // Temperature is in use or not, and colorTemperature only when it is not 6500 K: on a
        // stage it wrote, an unauthored temperature is Blender's default light (Temperature off,
        // white in Cycles), an authored one a temperature the user set.
        let k = r.f64(prim, "inputs:colorTemperature")?;
        if let Some(kelvin) = k.filter(|k| !k.is_finite()) {
            return Err(crate::value::attr_error(
                prim,
                "inputs:colorTemperature",
                format!("must be finite, got {kelvin}"),
            ));
        }
        if k.is_some() || !units.blender_authored {
            tint = blackbody_rgb(k.unwrap_or(6500.0));
        }
    }
    if intensity < 0.0 || !color.is_finite() || color.min_element() < 0.0 {
        return Err(crate::value::attr_error(prim, "inputs:intensity", "intensity and color must be non-negative"));
    }
    let base = (color * intensity * 2f64.powf(exposure)).as_vec3() * tint;
    let limit = petzval_renderer::limits::MAX_RADIANCE;
    if !(base.is_finite() && base.max_element() <= limit) {
        return Err(crate::value::attr_error(
            prim,
            "inputs:intensity",
            format!(
                "intensity × 2^exposure × color = {:e} is beyond {limit:e}, the brightest value petzval renders",
                base.max_element()
            ),
        ));
    }
    let to_r = units.to_renderer() * world;
    let rigid = crate::xform::rigid(to_r);
    let pos = rigid.transform_point3(DVec3::ZERO).as_vec3();
    let dir = rigid.transform_vector3(DVec3::NEG_Z).normalize_or_zero().as_vec3();
    // finite in single precision, as the renderer takes them (a 1e39 or inf would reach it as inf)
    if !(pos.is_finite() && dir.is_finite()) {
        return Err(crate::value::attr_error(prim, "xformOpOrder", "the light's world transform is not finite"));
    }
    if !base.is_finite() {
        return Err(crate::value::attr_error(
            prim,
            "inputs:intensity",
            "intensity × color × 2^exposure is not finite in single precision",
        ));
    }
    let info = |renderer: &str, v: Vec3| LightInfo {
        prim: path.clone(),
        kind: ty.to_string(),
        renderer: renderer.to_string(),
        value: v.to_array(),
    };
    match ty {
        "SphereLight" => {
            let radius = r.f64_or(prim, "inputs:radius", 0.5)? * mpu;
            let i = if normalize || radius <= 0.0 {
                base / 4.0
            } else {
                base * (std::f64::consts::PI * radius * radius) as f32
            };
            // the emitter's size (soft shadows), unless the light says it is a point
            if !(radius.is_finite() && radius >= 0.0) {
                return Err(crate::value::attr_error(prim, "inputs:radius", format!("must be ≥ 0, got {radius}")));
            }
            let radius_m = if r.bool(prim, "treatAsPoint")?.unwrap_or(false) { 0.0 } else { radius as f32 };
            // UsdLux's sphere emits from its surface; Blender writes its point lights as spheres
            // but renders them by default with Soft Falloff (a disc facing each point), which
            // its USD does not record: stages Blender wrote get the default.
            let sphere = !units.blender_authored;
            let cone = r.f64(prim, "inputs:shaping:cone:angle")?;
            match cone {
                Some(a) if a < 180.0 => {
                    let soft = r.f64_or(prim, "inputs:shaping:cone:softness", 0.0)?.clamp(0.0, 1.0);
                    let outer = (a.max(0.0) as f32).to_radians();
                    w.scene.lights.push(Light::Spot {
                        position: pos,
                        direction: dir,
                        intensity: i,
                        inner_cone_rad: outer * (1.0 - soft as f32),
                        outer_cone_rad: outer,
                        range: None,
                        // softness is Blender's Spot Blend (its USD exporter and importer)
                        falloff: petzval_renderer::scene::SpotFalloff::Blender,
                        radius_m,
                        sphere,
                    });
                    w.infos.push(info("spot (W/sr)", i));
                }
                _ => {
                    w.scene.lights.push(Light::Point { position: pos, intensity: i, range: None, radius_m, sphere });
                    w.infos.push(info("point (W/sr)", i));
                }
            }
        }
        "DistantLight" => {
            let e = base * 4.0;
            // angular diameter in degrees (UsdLux's fallback 0.53, the Sun's)
            let angle = r.f64_or(prim, "inputs:angle", 0.53)?;
            if !(angle.is_finite() && (0.0..180.0).contains(&angle)) {
                return Err(crate::value::attr_error(
                    prim,
                    "inputs:angle",
                    format!("must be in [0, 180) degrees, got {angle}"),
                ));
            }
            // Blender writes half its sun's angular diameter (and reads it back doubled)
            let diameter = if units.blender_authored { 2.0 * angle } else { angle };
            // Unnormalized, intensity is the disc's radiance (UsdLux), so the irradiance is
            // that over the disc's solid angle, as Cycles' unnormalized sun takes it (π tan² of
            // the half angle); a sun without an angle has no disc and stays normalized.
            let half_rad = (diameter.min(179.0) / 2.0).to_radians();
            let e = if normalize || diameter <= 0.0 {
                e
            } else {
                e * (std::f64::consts::PI * half_rad.tan().powi(2)) as f32
            };
            w.scene.lights.push(Light::Directional {
                direction: dir,
                irradiance: e,
                angle_rad: (diameter.min(179.0) as f32).to_radians(),
            });
            w.infos.push(info("directional (W/m²)", e));
        }
        "RectLight" | "DiskLight" | "CylinderLight" => {
            let (mesh, area_units) = if ty == "RectLight" {
                let wd = r.f64_or(prim, "inputs:width", 1.0)?;
                let ht = r.f64_or(prim, "inputs:height", 1.0)?;
                (quad(wd as f32, ht as f32), wd * ht)
            } else if ty == "CylinderLight" {
                let rad = r.f64_or(prim, "inputs:radius", 0.5)?;
                let len = r.f64_or(prim, "inputs:length", 1.0)?;
                (crate::shapes::cylinder_side_x(rad as f32, len as f32), std::f64::consts::TAU * rad * len)
            } else {
                let rad = r.f64_or(prim, "inputs:radius", 0.5)?;
                (disk(rad as f32, 32), std::f64::consts::PI * rad * rad)
            };
            if r.asset(prim, "inputs:texture:file")?.is_some() {
                w.warnings.push(format!("{path}: inputs:texture:file on a {ty} is not supported; uniform emission"));
            }
            let area_m2 = area_units * mpu * mpu;
            let l = if normalize && area_m2 > 0.0 { base / area_m2 as f32 } else { base };
            // a light's emitter, not geometry, as in Cycles: no shadow, not there from behind
            // (and no reflection off the panel: no specular layer). Camera rays see it, except
            // on a stage Blender wrote: Blender 5 hides lights from the camera by default and its
            // exporter does not record the setting.
            let mut m = Material {
                name: path.clone(),
                base_color: glam::Vec4::new(0.0, 0.0, 0.0, 1.0),
                metallic: 0.0,
                specular: 0.0,
                emissive: l,
                light_emitter: true,
                visible_to_camera: !units.blender_authored,
                ..Material::default()
            };
            m.double_sided = false;
            w.scene.materials.push(m);
            let mid = (w.scene.materials.len() - 1) as u32;
            let mut mesh = mesh;
            mesh.material_ids = vec![mid; mesh.indices.len()];
            w.infos.push(info("emissive mesh (radiance)", l));
            w.meshes.push((mesh, world, path.clone()));
        }
        "DomeLight" | "DomeLight_1" => {
            let strength = (intensity * 2f64.powf(exposure)) as f32;
            let c = color.as_vec3() * tint;
            // The map's pole is the light's local stage-up axis (what Blender's exporter writes).
            let up = rigid.transform_vector3(if units.up_axis_z { DVec3::Z } else { DVec3::Y });
            let x = rigid.transform_vector3(DVec3::X);
            // The light's yaw about +y (renderer), for the map.
            let yaw = (-x.z).atan2(x.x) as f32;
            let file = r.asset(prim, "inputs:texture:file")?;
            let env = match file {
                Some((authored, resolved)) => {
                    let p = resolved.filter(|s| !s.is_empty()).unwrap_or(authored.clone());
                    let format = r.token(prim, "inputs:texture:format")?.unwrap_or_else(|| "automatic".into());
                    if format != "automatic" && format != "latlong" {
                        w.warnings.push(format!("{path}: inputs:texture:format '{format}' is read as latlong"));
                    }
                    if up.y < 0.999 {
                        w.warnings.push(format!(
                            "{path}: the dome is tilted off the up axis; only its turn about the up axis is applied"
                        ));
                    }
                    // A map inside a usdz package is read from the archive.
                    let loaded = match openusd::ar::split_package_relative_path_outer(&p) {
                        Some((package, inner)) => crate::shading::read_packaged(&package, &inner).and_then(|bytes| {
                            petzval_renderer::scene::environment::load_environment_exr_bytes(&bytes, &p, strength, yaw)
                                .map_err(|e| e.to_string())
                        }),
                        None => petzval_renderer::scene::environment::load_environment_exr(
                            std::path::Path::new(&p),
                            strength,
                            yaw,
                        )
                        .map_err(|e| e.to_string()),
                    };
                    match loaded {
                        Ok(mut env) => {
                            if c != Vec3::ONE {
                                w.warnings.push(format!("{path}: inputs:color on a textured dome is ignored"));
                            }
                            std::mem::swap(&mut w.scene.environment, &mut env);
                            w.infos.push(info("environment map (× strength)", Vec3::splat(strength)));
                            return Ok(());
                        }
                        Err(e) => {
                            w.warnings.push(format!(
                                "{}: {path}.inputs:texture:file '{authored}' cannot be read ({e}); the dome is magenta",
                                layer_of_prim(prim)
                            ));
                            petzval_renderer::scene::Environment::Constant(Vec3::new(1.0, 0.0, 1.0) * strength)
                        }
                    }
                }
                None => petzval_renderer::scene::Environment::Constant(c * strength),
            };
            if let petzval_renderer::scene::Environment::Constant(v) = &env {
                w.infos.push(info("environment constant (radiance)", *v));
            }
            w.scene.environment = env;
        }
        _ => {
            w.warnings.push(format!("{path}: {ty} is not supported and was skipped"));
        }
    }
    Ok(())
}

/// A w × h quad in the xy plane facing −z.
fn quad(wd: f32, ht: f32) -> Mesh {
    let (a, b) = (wd / 2.0, ht / 2.0);
    Mesh {
        positions: vec![Vec3::new(-a, -b, 0.0), Vec3::new(a, -b, 0.0), Vec3::new(a, b, 0.0), Vec3::new(-a, b, 0.0)],
        normals: vec![Vec3::NEG_Z; 4],
        uv0: vec![Vec2::new(0.0, 1.0), Vec2::new(1.0, 1.0), Vec2::new(1.0, 0.0), Vec2::new(0.0, 0.0)],
        indices: vec![[0, 2, 1], [0, 3, 2]],
        ..Mesh::default()
    }
}

/// A disk of radius r in the xy plane facing −z: a 32-gon of the disc's area (one inscribed in
/// the circle lacked 0.64 % of the disc's area, hence of its light). The 48-sided cylinder keeps
/// its inscribed prism (0.07 % of its side's area short).
fn disk(radius: f32, n: u32) -> Mesh {
    // the polygon's circumradius that gives it the disc's area
    let radius = radius * (std::f32::consts::PI / (0.5 * n as f32 * (std::f32::consts::TAU / n as f32).sin())).sqrt();
    let mut m = Mesh { positions: vec![Vec3::ZERO], ..Mesh::default() };
    for k in 0..n {
        let a = k as f32 / n as f32 * std::f32::consts::TAU;
        m.positions.push(Vec3::new(radius * a.cos(), radius * a.sin(), 0.0));
    }
    for k in 0..n {
        let (i, j) = (1 + k, 1 + (k + 1) % n);
        m.indices.push([0, j, i]);
    }
    m.normals = vec![Vec3::NEG_Z; m.positions.len()];
    m
}
