//! UsdGeomXformable: `xformOpOrder` composed to a local transform (openusd 0.6 has no
//! transform cache, so this is it), and the stage's `upAxis`/`metersPerUnit` correction.
//!
//! | op | value | matrix (column vectors) |
//! |---|---|---|
//! | `translate` | 3-vector | T |
//! | `scale` | 3-vector | S |
//! | `rotateX`/`Y`/`Z` | degrees | R about the axis |
//! | `rotateXYZ` … `rotateZYX` | 3 degrees | `rotateABC` = R_C · R_B · R_A (A applied first) |
//! | `orient` | quaternion | R |
//! | `transform` | matrix4d (row-vector, as USD stores it) | its transpose |
//! | `!invert!` prefix | — | the inverse of the op |
//! | `!resetXformStack!` first | — | the parent transform is dropped |
//!
//! The ops compose in order, the first outermost: `[translate, rotateXYZ, scale]` is T · R · S.
//! An op named in `xformOpOrder` but not authored is an error naming the attribute (as
//! `UsdGeomXformable` reports it).

use crate::value::{attr_error, quat, Reader};
use crate::Error;
use glam::{DMat4, DQuat, DVec3};
use openusd::{sdf, usd};

/// A prim's local transform and whether it resets the parent's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalXform {
    /// Local-to-parent matrix (column vectors).
    pub matrix: DMat4,
    /// `!resetXformStack!` was the first op: the prim's world transform is `matrix` alone.
    pub resets: bool,
}

/// The op names in `xformOpOrder` (empty when unauthored).
pub fn op_order(prim: &usd::Prim) -> Result<Vec<String>, Error> {
    // xformOpOrder is uniform: read its default.
    let v = prim.attribute("xformOpOrder").get::<sdf::Value>();
    match v {
        Ok(None) | Ok(Some(sdf::Value::ValueBlock)) => Ok(Vec::new()),
        Ok(Some(sdf::Value::TokenVec(t))) => Ok(t.iter().map(|t| t.as_str().to_string()).collect()),
        Ok(Some(sdf::Value::StringVec(t))) => Ok(t),
        Ok(Some(_)) => Err(attr_error(prim, "xformOpOrder", "expected a token[]")),
        Err(e) => Err(attr_error(prim, "xformOpOrder", format!("cannot be read: {e:#}"))),
    }
}

fn axis_rot(axis: char, deg: f64) -> DMat4 {
    let r = deg.to_radians();
    match axis {
        'X' => DMat4::from_rotation_x(r),
        'Y' => DMat4::from_rotation_y(r),
        _ => DMat4::from_rotation_z(r),
    }
}

/// Whether pxr reads xform ops on a prim of type `ty`: a typeless prim and a `Scope` are not
/// `UsdGeomXformable`, and the ops they author are ignored (identity, no reset).
pub fn is_xformable(ty: &str) -> bool {
    !matches!(ty, "" | "Scope")
}

/// The local transform of `prim` at the reader's time (identity for a prim that is not
/// [`is_xformable`]).
pub fn local_xform(reader: &Reader, prim: &usd::Prim) -> Result<LocalXform, Error> {
    let ty = prim.type_name().ok().flatten();
    if !is_xformable(ty.as_ref().map_or("", |t| t.as_str())) {
        return Ok(LocalXform { matrix: DMat4::IDENTITY, resets: false });
    }
    let order = op_order(prim)?;
    let mut m = DMat4::IDENTITY;
    let mut resets = false;
    for (i, op) in order.iter().enumerate() {
        if op == "!resetXformStack!" {
            if i == 0 {
                resets = true;
                continue;
            }
            // A reset later in the order discards the ops before it (UsdGeomXformable).
            m = DMat4::IDENTITY;
            resets = true;
            continue;
        }
        let (invert, name) = match op.strip_prefix("!invert!") {
            Some(n) => (true, n),
            None => (false, op.as_str()),
        };
        let Some(rest) = name.strip_prefix("xformOp:") else {
            return Err(attr_error(prim, "xformOpOrder", format!("'{op}' is not an xformOp")));
        };
        let ty = rest.split(':').next().unwrap_or("");
        let missing = || attr_error(prim, name, "is named in xformOpOrder but has no value");
        let om = match ty {
            "translate" => DMat4::from_translation(reader.vec3(prim, name)?.ok_or_else(missing)?),
            "scale" => DMat4::from_scale(reader.vec3(prim, name)?.ok_or_else(missing)?),
            "rotateX" | "rotateY" | "rotateZ" => {
                let a = reader.f64(prim, name)?.ok_or_else(missing)?;
                axis_rot(ty.chars().last().unwrap_or('Z'), a)
            }
            "rotateXYZ" | "rotateXZY" | "rotateYXZ" | "rotateYZX" | "rotateZXY" | "rotateZYX" => {
                let v = reader.vec3(prim, name)?.ok_or_else(missing)?;
                let mut r = DMat4::IDENTITY;
                for axis in ty["rotate".len()..].chars() {
                    let a = match axis {
                        'X' => v.x,
                        'Y' => v.y,
                        _ => v.z,
                    };
                    // the first-named axis is applied first: it is innermost
                    r = axis_rot(axis, a) * r;
                }
                r
            }
            "orient" => {
                let q = match reader.raw(prim, name)? {
                    Some(sdf::Value::Quatf(q)) => quat(q.x as f64, q.y as f64, q.z as f64, q.w as f64),
                    Some(sdf::Value::Quatd(q)) => quat(q.x, q.y, q.z, q.w),
                    Some(sdf::Value::Quath(q)) => quat(q.x.to_f64(), q.y.to_f64(), q.z.to_f64(), q.w.to_f64()),
                    Some(_) => return Err(attr_error(prim, name, "expected a quaternion")),
                    None => return Err(missing()),
                };
                DMat4::from_quat(q)
            }
            "transform" => match reader.raw(prim, name)? {
                Some(sdf::Value::Matrix4d(mat)) => DMat4::from_cols_array(&mat.0),
                Some(_) => return Err(attr_error(prim, name, "expected a matrix4d")),
                None => return Err(missing()),
            },
            _ => return Err(attr_error(prim, name, format!("unknown xformOp type '{ty}'"))),
        };
        let om = if invert {
            if om.determinant().abs() < 1e-300 {
                return Err(attr_error(prim, name, "!invert! of a singular op"));
            }
            om.inverse()
        } else {
            om
        };
        if !om.is_finite() {
            return Err(attr_error(prim, name, "is not finite"));
        }
        m *= om;
    }
    Ok(LocalXform { matrix: m, resets })
}

/// The stage's `upAxis` and `metersPerUnit` (with USD's fallbacks Y and 0.01).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StageUnits {
    /// `"Y"` or `"Z"`.
    pub up_axis_z: bool,
    /// Metres per scene unit.
    pub meters_per_unit: f64,
    /// The root layer's `doc` says Blender wrote it ("Blender v5.0.1"): some of Blender's
    /// conventions differ from UsdLux's (see `lights.rs`).
    pub blender_authored: bool,
}

impl StageUnits {
    /// Reads them from the stage metadata.
    pub fn read(stage: &usd::Stage) -> Result<StageUnits, Error> {
        let layer = stage.root_layer().identifier().to_string();
        let bad = |field: &str, message: String| Error::Stage { layer: layer.clone(), field: field.into(), message };
        let up = match stage.stage_metadata("upAxis") {
            Ok(Some(sdf::Value::Token(t))) => t.as_str().to_string(),
            Ok(Some(sdf::Value::String(t))) => t,
            Ok(None) => "Y".into(),
            Ok(Some(v)) => return Err(bad("upAxis", format!("expected a token, got {v:?}"))),
            Err(e) => return Err(bad("upAxis", format!("{e:#}"))),
        };
        let up_axis_z = match up.as_str() {
            "Y" => false,
            "Z" => true,
            u => return Err(bad("upAxis", format!("must be Y or Z, got '{u}'"))),
        };
        let meters_per_unit = match stage.stage_metadata("metersPerUnit") {
            Ok(Some(sdf::Value::Double(v))) => v,
            Ok(Some(sdf::Value::Float(v))) => v as f64,
            Ok(Some(sdf::Value::Int(v))) => v as f64,
            Ok(None) => 0.01,
            Ok(Some(v)) => return Err(bad("metersPerUnit", format!("expected a double, got {v:?}"))),
            Err(e) => return Err(bad("metersPerUnit", format!("{e:#}"))),
        };
        if !(meters_per_unit > 0.0 && meters_per_unit.is_finite()) {
            return Err(bad("metersPerUnit", format!("must be positive, got {meters_per_unit}")));
        }
        let blender_authored = match stage.stage_metadata(sdf::FieldKey::Documentation.as_str()) {
            Ok(Some(sdf::Value::String(d))) => d.trim_start().starts_with("Blender"),
            _ => false,
        };
        Ok(StageUnits { up_axis_z, meters_per_unit, blender_authored })
    }

    /// Stage world → renderer world (metres, +y up): a rotation of −90° about x for Z-up
    /// stages, then the unit scale.
    pub fn to_renderer(&self) -> DMat4 {
        let rot = if self.up_axis_z { DMat4::from_rotation_x(-std::f64::consts::FRAC_PI_2) } else { DMat4::IDENTITY };
        DMat4::from_scale(DVec3::splat(self.meters_per_unit)) * rot
    }
}

/// The rigid part of `m` (translation kept, the 3×3 part orthonormalised; scale and shear
/// dropped): cameras and lights are placed by it.
pub fn rigid(m: DMat4) -> DMat4 {
    let (_, r, t) = m.to_scale_rotation_translation();
    let r = if r.is_finite() { r.normalize() } else { DQuat::IDENTITY };
    DMat4::from_rotation_translation(r, t)
}
