//! Typed reads of composed attribute values at one time code: every read names the layer,
//! prim path and attribute when the authored value has the wrong type, and falls back to the
//! schema's value (written by the caller, since openusd 0.6 has no schema registry) when the
//! attribute is unauthored.
//!
//! | read | accepted USD types |
//! |---|---|
//! | [`Reader::f64`] | `float`, `double`, `half`, `int` |
//! | [`Reader::vec3s`] | `point3f[]`, `normal3f[]`, `vector3f[]`, `color3f[]`, `float3[]`, their `d`/`h` forms |
//! | [`Reader::vec2s`] | `texCoord2f[]`, `float2[]`, their `d`/`h` forms |
//! | [`Reader::ints`] | `int[]`, `uint[]`, `int64[]` |
//! | [`Reader::quats`] | `quath[]`, `quatf[]`, `quatd[]` |
//! | [`Reader::bool`] | `bool`, integers (time samples authored as `1: 1`) |
//! | [`Reader::token`] | `token`, `string` |
//! | [`Reader::asset`] | `asset` (resolved path when openusd resolved it) |

use crate::Error;
use glam::{DQuat, DVec2, DVec3};
use openusd::{sdf, usd};

/// Reads attribute values of one stage at one time code.
pub struct Reader<'a> {
    /// The composed stage.
    pub stage: &'a usd::Stage,
    /// Time code (None = the default value).
    pub time: Option<f64>,
}

/// The strongest layer that has an opinion on `prim` (for error messages).
pub fn layer_of_prim(prim: &usd::Prim) -> String {
    match prim.prim_stack() {
        Ok(stack) if !stack.is_empty() => stack[0].0.clone(),
        _ => prim.stage().root_layer().identifier().to_string(),
    }
}

/// The strongest layer with an opinion on the attribute, else the prim's.
pub fn layer_of_attr(prim: &usd::Prim, name: &str) -> String {
    match prim.attribute(name).property_stack() {
        Ok(stack) if !stack.is_empty() => stack[0].0.clone(),
        _ => layer_of_prim(prim),
    }
}

/// A type-mismatch or invalid-value error for `prim.name`.
pub fn attr_error(prim: &usd::Prim, name: &str, message: impl Into<String>) -> Error {
    Error::Attribute {
        layer: layer_of_attr(prim, name),
        prim: prim.path().to_string(),
        attribute: name.to_string(),
        message: message.into(),
    }
}

/// The variant's name (for "expected X, got Y").
fn kind(v: &sdf::Value) -> String {
    let s = format!("{v:?}");
    s.split(['(', ' ', '{']).next().unwrap_or("?").to_string()
}

fn f16(h: half::f16) -> f64 {
    h.to_f64()
}

impl Reader<'_> {
    /// The composed raw value (None when unauthored or blocked).
    pub fn raw(&self, prim: &usd::Prim, name: &str) -> Result<Option<sdf::Value>, Error> {
        let attr = prim.attribute(name);
        let r = match self.time {
            Some(t) => attr.get_at::<sdf::Value>(usd::TimeCode::new(t)),
            None => attr.get::<sdf::Value>(),
        };
        match r {
            Ok(Some(sdf::Value::ValueBlock)) | Ok(Some(sdf::Value::None)) => Ok(None),
            Ok(v) => Ok(v),
            Err(e) => Err(attr_error(prim, name, format!("cannot be read: {e:#}"))),
        }
    }

    /// Between two time samples authored as integer literals (`1: 0, 10: 90` in usda),
    /// openusd 0.6 holds the earlier value instead of interpolating (pxr stores them as the
    /// attribute's float type and interpolates): interpolate here, linearly, as pxr does.
    fn int_samples_lerp<T>(
        &self,
        prim: &usd::Prim,
        name: &str,
        read: impl Fn(sdf::Value) -> Option<T>,
        lerp: impl Fn(T, T, f64) -> T,
    ) -> Option<T> {
        let t = self.time?;
        let attr = prim.attribute(name);
        let (lo, hi) = attr.bracketing_time_samples(usd::TimeCode::new(t)).ok()??;
        if hi <= lo {
            return None;
        }
        let a = read(attr.get_at::<sdf::Value>(usd::TimeCode::new(lo)).ok()??)?;
        let b = read(attr.get_at::<sdf::Value>(usd::TimeCode::new(hi)).ok()??)?;
        Some(lerp(a, b, (t - lo) / (hi - lo)))
    }

    /// A scalar number.
    pub fn f64(&self, prim: &usd::Prim, name: &str) -> Result<Option<f64>, Error> {
        let v = self.raw(prim, name)?;
        if matches!(v, Some(sdf::Value::Int(_) | sdf::Value::Int64(_))) {
            let num = |v: sdf::Value| match v {
                sdf::Value::Int(i) => Some(i as f64),
                sdf::Value::Int64(i) => Some(i as f64),
                sdf::Value::Float(f) => Some(f as f64),
                sdf::Value::Double(f) => Some(f),
                _ => None,
            };
            if let Some(x) = self.int_samples_lerp(prim, name, num, |a, b, u| a + (b - a) * u) {
                return Ok(Some(x));
            }
        }
        Ok(match v {
            None => None,
            Some(sdf::Value::Float(v)) => Some(v as f64),
            Some(sdf::Value::Double(v)) => Some(v),
            Some(sdf::Value::Half(v)) => Some(f16(v)),
            // usda time samples keep the literal's type: `1: 0` reads as an int64
            Some(sdf::Value::Int(v)) => Some(v as f64),
            Some(sdf::Value::Int64(v)) => Some(v as f64),
            Some(sdf::Value::Uint(v)) => Some(v as f64),
            Some(sdf::Value::Uint64(v)) => Some(v as f64),
            Some(v) => return Err(attr_error(prim, name, format!("expected a float or double, got {}", kind(&v)))),
        })
    }

    /// A finite scalar number, or `fallback` when unauthored.
    pub fn f64_or(&self, prim: &usd::Prim, name: &str, fallback: f64) -> Result<f64, Error> {
        let v = self.f64(prim, name)?.unwrap_or(fallback);
        if !v.is_finite() {
            return Err(attr_error(prim, name, format!("must be finite, got {v}")));
        }
        Ok(v)
    }

    /// A boolean.
    pub fn bool(&self, prim: &usd::Prim, name: &str) -> Result<Option<bool>, Error> {
        Ok(match self.raw(prim, name)? {
            None => None,
            Some(sdf::Value::Bool(b)) => Some(b),
            // usda time samples keep the literal's type: Blender writes `1: 1` for a bool
            Some(sdf::Value::Int(i)) => Some(i != 0),
            Some(sdf::Value::Int64(i)) => Some(i != 0),
            Some(sdf::Value::Uint(i)) => Some(i != 0),
            Some(sdf::Value::Uint64(i)) => Some(i != 0),
            Some(v) => return Err(attr_error(prim, name, format!("expected a bool, got {}", kind(&v)))),
        })
    }

    /// A token (or string).
    pub fn token(&self, prim: &usd::Prim, name: &str) -> Result<Option<String>, Error> {
        Ok(match self.raw(prim, name)? {
            None => None,
            Some(sdf::Value::Token(t)) => Some(t.as_str().to_string()),
            Some(sdf::Value::String(s)) => Some(s),
            Some(v) => return Err(attr_error(prim, name, format!("expected a token, got {}", kind(&v)))),
        })
    }

    /// An asset path: (authored, resolved when openusd resolved it).
    pub fn asset(&self, prim: &usd::Prim, name: &str) -> Result<Option<(String, Option<String>)>, Error> {
        Ok(match self.raw(prim, name)? {
            None => None,
            Some(sdf::Value::AssetPath(a)) => {
                if a.is_empty() {
                    None
                } else {
                    Some((a.asset_path().to_string(), a.resolved_path().map(str::to_string)))
                }
            }
            Some(sdf::Value::String(s)) if !s.is_empty() => Some((s, None)),
            Some(sdf::Value::Token(t)) if !t.as_str().is_empty() => Some((t.as_str().to_string(), None)),
            Some(v) => return Err(attr_error(prim, name, format!("expected an asset path, got {}", kind(&v)))),
        })
    }

    /// One 3-vector (colour, translation, scale…).
    pub fn vec3(&self, prim: &usd::Prim, name: &str) -> Result<Option<DVec3>, Error> {
        let v = self.raw(prim, name)?;
        if matches!(v, Some(sdf::Value::Vec3i(_))) {
            let vec = |v: sdf::Value| match v {
                sdf::Value::Vec3i(v) => Some(DVec3::new(v.x as f64, v.y as f64, v.z as f64)),
                sdf::Value::Vec3f(v) => Some(DVec3::new(v.x as f64, v.y as f64, v.z as f64)),
                sdf::Value::Vec3d(v) => Some(DVec3::new(v.x, v.y, v.z)),
                _ => None,
            };
            if let Some(x) = self.int_samples_lerp(prim, name, vec, |a, b, u| a.lerp(b, u)) {
                return Ok(Some(x));
            }
        }
        Ok(match v {
            None => None,
            Some(sdf::Value::Vec3f(v)) => Some(DVec3::new(v.x as f64, v.y as f64, v.z as f64)),
            Some(sdf::Value::Vec3d(v)) => Some(DVec3::new(v.x, v.y, v.z)),
            Some(sdf::Value::Vec3h(v)) => Some(DVec3::new(f16(v.x), f16(v.y), f16(v.z))),
            Some(sdf::Value::Vec3i(v)) => Some(DVec3::new(v.x as f64, v.y as f64, v.z as f64)),
            Some(v) => return Err(attr_error(prim, name, format!("expected a 3-vector, got {}", kind(&v)))),
        })
    }

    /// One 2-vector.
    pub fn vec2(&self, prim: &usd::Prim, name: &str) -> Result<Option<DVec2>, Error> {
        Ok(match self.raw(prim, name)? {
            None => None,
            Some(sdf::Value::Vec2f(v)) => Some(DVec2::new(v.x as f64, v.y as f64)),
            Some(sdf::Value::Vec2d(v)) => Some(DVec2::new(v.x, v.y)),
            Some(sdf::Value::Vec2h(v)) => Some(DVec2::new(f16(v.x), f16(v.y))),
            Some(v) => return Err(attr_error(prim, name, format!("expected a 2-vector, got {}", kind(&v)))),
        })
    }

    /// An array of 3-vectors.
    pub fn vec3s(&self, prim: &usd::Prim, name: &str) -> Result<Option<Vec<DVec3>>, Error> {
        Ok(match self.raw(prim, name)? {
            None => None,
            Some(v) => {
                Some(vec3s_of(&v).ok_or_else(|| {
                    attr_error(prim, name, format!("expected an array of 3-vectors, got {}", kind(&v)))
                })?)
            }
        })
    }

    /// An array of 2-vectors.
    pub fn vec2s(&self, prim: &usd::Prim, name: &str) -> Result<Option<Vec<DVec2>>, Error> {
        Ok(match self.raw(prim, name)? {
            None => None,
            Some(sdf::Value::Vec2fVec(v)) => Some(v.iter().map(|p| DVec2::new(p.x as f64, p.y as f64)).collect()),
            Some(sdf::Value::Vec2dVec(v)) => Some(v.iter().map(|p| DVec2::new(p.x, p.y)).collect()),
            Some(sdf::Value::Vec2hVec(v)) => Some(v.iter().map(|p| DVec2::new(f16(p.x), f16(p.y))).collect()),
            Some(v) => return Err(attr_error(prim, name, format!("expected an array of 2-vectors, got {}", kind(&v)))),
        })
    }

    /// An array of floats.
    pub fn floats(&self, prim: &usd::Prim, name: &str) -> Result<Option<Vec<f64>>, Error> {
        Ok(match self.raw(prim, name)? {
            None => None,
            Some(sdf::Value::FloatVec(v)) => Some(v.iter().map(|&x| x as f64).collect()),
            Some(sdf::Value::DoubleVec(v)) => Some(v),
            Some(sdf::Value::HalfVec(v)) => Some(v.iter().map(|&x| f16(x)).collect()),
            Some(v) => return Err(attr_error(prim, name, format!("expected an array of floats, got {}", kind(&v)))),
        })
    }

    /// An array of integers.
    pub fn ints(&self, prim: &usd::Prim, name: &str) -> Result<Option<Vec<i64>>, Error> {
        Ok(match self.raw(prim, name)? {
            None => None,
            Some(sdf::Value::IntVec(v)) => Some(v.iter().map(|&x| x as i64).collect()),
            Some(sdf::Value::UintVec(v)) => Some(v.iter().map(|&x| x as i64).collect()),
            Some(sdf::Value::Int64Vec(v)) => Some(v),
            Some(sdf::Value::Uint64Vec(v)) => Some(v.iter().map(|&x| x.min(i64::MAX as u64) as i64).collect()),
            Some(v) => return Err(attr_error(prim, name, format!("expected an array of integers, got {}", kind(&v)))),
        })
    }

    /// An array of quaternions (unit, as glam's).
    pub fn quats(&self, prim: &usd::Prim, name: &str) -> Result<Option<Vec<DQuat>>, Error> {
        Ok(match self.raw(prim, name)? {
            None => None,
            Some(sdf::Value::QuathVec(v)) => {
                Some(v.iter().map(|q| quat(f16(q.x), f16(q.y), f16(q.z), f16(q.w))).collect())
            }
            Some(sdf::Value::QuatfVec(v)) => {
                Some(v.iter().map(|q| quat(q.x as f64, q.y as f64, q.z as f64, q.w as f64)).collect())
            }
            Some(sdf::Value::QuatdVec(v)) => Some(v.iter().map(|q| quat(q.x, q.y, q.z, q.w)).collect()),
            Some(v) => {
                return Err(attr_error(prim, name, format!("expected an array of quaternions, got {}", kind(&v))))
            }
        })
    }
}

/// A quaternion, normalised (identity when zero or not finite).
pub fn quat(x: f64, y: f64, z: f64, w: f64) -> DQuat {
    let q = DQuat::from_xyzw(x, y, z, w);
    let l = q.length();
    if l > 0.0 && l.is_finite() {
        q / l
    } else {
        DQuat::IDENTITY
    }
}

/// Any array of 3-vectors as f64.
pub fn vec3s_of(v: &sdf::Value) -> Option<Vec<DVec3>> {
    Some(match v {
        sdf::Value::Vec3fVec(v) => v.iter().map(|p| DVec3::new(p.x as f64, p.y as f64, p.z as f64)).collect(),
        sdf::Value::Vec3dVec(v) => v.iter().map(|p| DVec3::new(p.x, p.y, p.z)).collect(),
        sdf::Value::Vec3hVec(v) => v.iter().map(|p| DVec3::new(f16(p.x), f16(p.y), f16(p.z))).collect(),
        _ => return None,
    })
}

/// A primvar's `interpolation` metadata as its token (`None` when unauthored); each schema maps
/// the token to its own element counts.
pub(crate) fn interpolation_token(prim: &usd::Prim, name: &str) -> Result<Option<String>, Error> {
    let v = prim
        .attribute(name)
        .get_metadata::<sdf::Value>("interpolation")
        .map_err(|e| attr_error(prim, name, format!("interpolation cannot be read: {e:#}")))?;
    match v {
        None => Ok(None),
        Some(sdf::Value::Token(t)) => Ok(Some(t.as_str().to_string())),
        Some(sdf::Value::String(s)) => Ok(Some(s)),
        Some(v) => Err(attr_error(prim, name, format!("interpolation must be a token, got {v:?}"))),
    }
}
