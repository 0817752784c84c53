//! UsdGeom intrinsic shapes tessellated into triangle meshes (with the schema's fallbacks).
//!
//! | prim | attributes (fallback) | tessellation |
//! |---|---|---|
//! | `Cube` | `size` (2) | 12 triangles, flat normals |
//! | `Sphere` | `radius` (1) | 48 × 24 latitude-longitude, smooth normals |
//! | `Cylinder` | `radius` (1), `height` (2), `axis` (Z) | 48 sides + two caps |
//! | `Cone` | `radius` (1), `height` (2), `axis` (Z) | 48 sides + the base cap; apex at +height/2 |
//! | `Capsule` | `radius` (0.5), `height` (1, the cylinder part), `axis` (Z) | 48 sides, hemispheres of 12 rings |
//! | `Plane` | `width` (2), `length` (2), `axis` (Z) | 2 triangles facing +axis |

use crate::value::{attr_error, Reader};
use crate::Error;
use glam::{Mat3, Vec2, Vec3};
use openusd::usd;
use petzval_renderer::scene::Mesh;
use std::f32::consts::{PI, TAU};

const SEG: u32 = 48;

/// Rotation taking the shape's +z axis to `axis`.
fn axis_frame(reader: &Reader, prim: &usd::Prim) -> Result<Mat3, Error> {
    Ok(match reader.token(prim, "axis")?.as_deref() {
        None | Some("Z") => Mat3::IDENTITY,
        // z → x, keeping a right-handed frame: (x, y, z) → (z, x, y)
        Some("X") => Mat3::from_cols(Vec3::Y, Vec3::Z, Vec3::X),
        // z → y: (x, y, z) → (y, z, x)
        Some("Y") => Mat3::from_cols(Vec3::Z, Vec3::X, Vec3::Y),
        Some(a) => return Err(attr_error(prim, "axis", format!("must be X, Y or Z, got '{a}'"))),
    })
}

fn positive(reader: &Reader, prim: &usd::Prim, name: &str, fallback: f64) -> Result<f32, Error> {
    let v = reader.f64_or(prim, name, fallback)?;
    if v < 0.0 {
        return Err(attr_error(prim, name, format!("must not be negative, got {v}")));
    }
    Ok(v as f32)
}

/// A surface of revolution about +z: `profile` lists (radius, z, normal radial, normal z)
/// from bottom to top; rings are joined by quads.
fn revolve(profile: &[(f32, f32, f32, f32)]) -> Mesh {
    let mut m = Mesh::default();
    let ring = SEG + 1;
    for (k, &(r, z, nr, nz)) in profile.iter().enumerate() {
        for s in 0..ring {
            let a = s as f32 / SEG as f32 * TAU;
            let (sa, ca) = a.sin_cos();
            m.positions.push(Vec3::new(r * ca, r * sa, z));
            m.normals.push(Vec3::new(nr * ca, nr * sa, nz).normalize_or_zero());
            m.uv0.push(Vec2::new(s as f32 / SEG as f32, 1.0 - k as f32 / (profile.len() - 1).max(1) as f32));
        }
    }
    for k in 0..profile.len() as u32 - 1 {
        for s in 0..SEG {
            let a = k * ring + s;
            let (b, c, d) = (a + 1, a + ring + 1, a + ring);
            m.indices.push([a, b, c]);
            m.indices.push([a, c, d]);
        }
    }
    m
}

/// A disc cap at height `z` facing `up` (+1 or −1).
fn cap(m: &mut Mesh, r: f32, z: f32, up: f32) {
    let centre = m.positions.len() as u32;
    m.positions.push(Vec3::new(0.0, 0.0, z));
    m.normals.push(Vec3::Z * up);
    m.uv0.push(Vec2::splat(0.5));
    for s in 0..SEG {
        let a = s as f32 / SEG as f32 * TAU;
        m.positions.push(Vec3::new(r * a.cos(), r * a.sin(), z));
        m.normals.push(Vec3::Z * up);
        m.uv0.push(Vec2::new(0.5 + 0.5 * a.cos(), 0.5 - 0.5 * a.sin()));
    }
    for s in 0..SEG {
        let (i, j) = (centre + 1 + s, centre + 1 + (s + 1) % SEG);
        m.indices.push(if up > 0.0 { [centre, i, j] } else { [centre, j, i] });
    }
}

/// The tessellated shape of `prim` (type `ty`), or None when `ty` is not an intrinsic shape.
pub fn shape_mesh(reader: &Reader, prim: &usd::Prim, ty: &str) -> Result<Option<Mesh>, Error> {
    let mut m = match ty {
        "Cube" => {
            let h = positive(reader, prim, "size", 2.0)? / 2.0;
            let mut m = Mesh::default();
            for (n, u, v) in [
                (Vec3::X, Vec3::Y, Vec3::Z),
                (Vec3::NEG_X, Vec3::Z, Vec3::Y),
                (Vec3::Y, Vec3::Z, Vec3::X),
                (Vec3::NEG_Y, Vec3::X, Vec3::Z),
                (Vec3::Z, Vec3::X, Vec3::Y),
                (Vec3::NEG_Z, Vec3::Y, Vec3::X),
            ] {
                let b = m.positions.len() as u32;
                for (su, sv) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                    m.positions.push((n + u * su + v * sv) * h);
                    m.normals.push(n);
                    m.uv0.push(Vec2::new((su + 1.0) / 2.0, (1.0 - sv) / 2.0));
                }
                m.indices.push([b, b + 1, b + 2]);
                m.indices.push([b, b + 2, b + 3]);
            }
            return Ok(Some(with_material(m)));
        }
        "Sphere" => {
            let r = positive(reader, prim, "radius", 1.0)?;
            let rings = 24;
            let profile: Vec<_> = (0..=rings)
                .map(|k| {
                    let t = -PI / 2.0 + PI * k as f32 / rings as f32;
                    (r * t.cos(), r * t.sin(), t.cos(), t.sin())
                })
                .collect();
            return Ok(Some(with_material(revolve(&profile))));
        }
        "Cylinder" => {
            let r = positive(reader, prim, "radius", 1.0)?;
            let h = positive(reader, prim, "height", 2.0)? / 2.0;
            let mut m = revolve(&[(r, -h, 1.0, 0.0), (r, h, 1.0, 0.0)]);
            cap(&mut m, r, h, 1.0);
            cap(&mut m, r, -h, -1.0);
            m
        }
        "Cone" => {
            let r = positive(reader, prim, "radius", 1.0)?;
            let h = positive(reader, prim, "height", 2.0)? / 2.0;
            let (nr, nz) = (2.0 * h, r); // side normal ∝ (height, radius)
            let mut m = revolve(&[(r, -h, nr, nz), (0.0, h, nr, nz)]);
            cap(&mut m, r, -h, -1.0);
            m
        }
        "Capsule" => {
            let r = positive(reader, prim, "radius", 0.5)?;
            let h = positive(reader, prim, "height", 1.0)? / 2.0;
            let rings = 12;
            let mut profile = Vec::new();
            for k in 0..=rings {
                let t = -PI / 2.0 + PI / 2.0 * k as f32 / rings as f32;
                profile.push((r * t.cos(), -h + r * t.sin(), t.cos(), t.sin()));
            }
            for k in 0..=rings {
                let t = PI / 2.0 * k as f32 / rings as f32;
                profile.push((r * t.cos(), h + r * t.sin(), t.cos(), t.sin()));
            }
            revolve(&profile)
        }
        "Plane" => {
            let w = positive(reader, prim, "width", 2.0)? / 2.0;
            let l = positive(reader, prim, "length", 2.0)? / 2.0;
            Mesh {
                positions: vec![
                    Vec3::new(-w, -l, 0.0),
                    Vec3::new(w, -l, 0.0),
                    Vec3::new(w, l, 0.0),
                    Vec3::new(-w, l, 0.0),
                ],
                normals: vec![Vec3::Z; 4],
                uv0: vec![Vec2::new(0.0, 1.0), Vec2::new(1.0, 1.0), Vec2::new(1.0, 0.0), Vec2::new(0.0, 0.0)],
                indices: vec![[0, 1, 2], [0, 2, 3]],
                ..Mesh::default()
            }
        }
        _ => return Ok(None),
    };
    let rot = axis_frame(reader, prim)?;
    for p in &mut m.positions {
        *p = rot * *p;
    }
    for n in &mut m.normals {
        *n = rot * *n;
    }
    Ok(Some(with_material(m)))
}

/// The side of a cylinder of `radius` and `length` along x (a `CylinderLight`'s emitter).
pub fn cylinder_side_x(radius: f32, length: f32) -> Mesh {
    let mut m = revolve(&[(radius, -length / 2.0, 1.0, 0.0), (radius, length / 2.0, 1.0, 0.0)]);
    let rot = Mat3::from_cols(Vec3::Y, Vec3::Z, Vec3::X);
    for p in &mut m.positions {
        *p = rot * *p;
    }
    for n in &mut m.normals {
        *n = rot * *n;
    }
    m
}

fn with_material(mut m: Mesh) -> Mesh {
    m.material_ids = vec![0; m.indices.len()];
    m
}
