//! UsdGeomMesh → the renderer's triangle [`Mesh`] in the prim's object space.
//!
//! | attribute | handling | fallback |
//! |---|---|---|
//! | `points` | positions | required |
//! | `faceVertexCounts`, `faceVertexIndices` | fan-triangulated (as Hydra does); faces with fewer than 3 vertices are skipped and counted | required |
//! | `holeIndices` | those faces are skipped | none |
//! | `orientation` | `leftHanded` reverses every face's winding | `rightHanded` |
//! | `primvars:normals` (else `normals`) | constant, uniform, vertex, varying or faceVarying; `:indices` honoured | smooth area-weighted vertex normals |
//! | the material's `UsdPrimvarReader_float2` varname, else `primvars:st`, else the first `texCoord2f[]` primvar | as normals; `t` is flipped to the renderer's top-left origin | none |
//! | `GeomSubset` children (`elementType = face`) | their `material:binding` sets the material of their faces | the mesh's binding |
//!
//! Vertices stay shared when every primvar is per point (vertex/varying/constant); a uniform
//! or faceVarying primvar gives each face corner its own vertex.

use crate::value::{attr_error, Reader};
use crate::Error;
use glam::{DVec2, DVec3, Vec2, Vec3};
use openusd::{sdf, usd};
use petzval_renderer::scene::Mesh;

/// Primvar interpolation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Interp {
    /// One value.
    Constant,
    /// One per face.
    Uniform,
    /// One per point (`vertex` and `varying`).
    Vertex,
    /// One per face corner.
    FaceVarying,
}

/// A primvar's values with their interpolation and optional indices.
#[derive(Debug, Clone)]
pub struct Primvar<T> {
    /// Values.
    pub values: Vec<T>,
    /// Interpolation.
    pub interp: Interp,
    /// Indices into `values` (per element of `interp`).
    pub indices: Option<Vec<i64>>,
    /// The attribute read (for errors).
    pub name: String,
}

impl<T: Copy> Primvar<T> {
    /// The value for face `face`, point `point`, face corner `corner`.
    fn at(&self, face: usize, point: usize, corner: usize) -> Option<T> {
        let e = match self.interp {
            Interp::Constant => 0,
            Interp::Uniform => face,
            Interp::Vertex => point,
            Interp::FaceVarying => corner,
        };
        let i = match &self.indices {
            Some(ix) => usize::try_from(*ix.get(e)?).ok()?,
            None => e,
        };
        self.values.get(i).copied()
    }

    /// Number of elements needed for `interp`.
    fn check(&self, prim: &usd::Prim, faces: usize, points: usize, corners: usize) -> Result<(), Error> {
        let need = match self.interp {
            Interp::Constant => 1,
            Interp::Uniform => faces,
            Interp::Vertex => points,
            Interp::FaceVarying => corners,
        };
        let have = self.indices.as_ref().map(Vec::len).unwrap_or(self.values.len());
        if have < need {
            return Err(attr_error(
                prim,
                &self.name,
                format!("{:?} interpolation needs {need} values, has {have}", self.interp),
            ));
        }
        if let Some(ix) = &self.indices {
            if let Some(bad) = ix.iter().find(|&&i| i < 0 || i as usize >= self.values.len()) {
                return Err(attr_error(
                    prim,
                    &format!("{}:indices", self.name),
                    format!("index {bad} is outside the {} values", self.values.len()),
                ));
            }
        }
        Ok(())
    }
}

fn interpolation(prim: &usd::Prim, name: &str, default: Interp) -> Result<Interp, Error> {
    let v = prim
        .attribute(name)
        .get_metadata::<sdf::Value>("interpolation")
        .map_err(|e| attr_error(prim, name, format!("interpolation cannot be read: {e:#}")))?;
    let t = match v {
        None => return Ok(default),
        Some(sdf::Value::Token(t)) => t.as_str().to_string(),
        Some(sdf::Value::String(s)) => s,
        Some(v) => return Err(attr_error(prim, name, format!("interpolation must be a token, got {v:?}"))),
    };
    Ok(match t.as_str() {
        "constant" => Interp::Constant,
        "uniform" => Interp::Uniform,
        "vertex" | "varying" => Interp::Vertex,
        "faceVarying" => Interp::FaceVarying,
        o => return Err(attr_error(prim, name, format!("unknown interpolation '{o}'"))),
    })
}

fn primvar<T>(
    reader: &Reader,
    prim: &usd::Prim,
    name: &str,
    default: Interp,
    read: impl Fn(&Reader, &usd::Prim, &str) -> Result<Option<Vec<T>>, Error>,
) -> Result<Option<Primvar<T>>, Error> {
    let Some(values) = read(reader, prim, name)? else { return Ok(None) };
    let interp = interpolation(prim, name, default)?;
    let indices = reader.ints(prim, &format!("{name}:indices"))?;
    Ok(Some(Primvar { values, interp, indices, name: name.to_string() }))
}

/// The name of the texture-coordinate primvar: the one the material's
/// `UsdPrimvarReader_float2` names, else `primvars:st`, else the first `texCoord2f[]` primvar.
fn st_name(prim: &usd::Prim, preferred: Option<&str>) -> Option<String> {
    let authored = |n: &str| prim.attribute(n).get::<sdf::Value>().ok().flatten().is_some();
    if let Some(p) = preferred.map(|p| format!("primvars:{p}")) {
        if authored(&p) {
            return Some(p);
        }
    }
    if authored("primvars:st") {
        return Some("primvars:st".into());
    }
    let names = prim.property_names().ok()?;
    names.iter().map(|n| n.as_str().to_string()).find(|n| {
        n.starts_with("primvars:")
            && !n.ends_with(":indices")
            && prim
                .attribute(n.as_str())
                .type_name()
                .ok()
                .flatten()
                .is_some_and(|t| matches!(t.as_str(), "texCoord2f[]" | "texCoord2d[]" | "texCoord2h[]"))
    })
}

/// What was read and reported about one mesh.
#[derive(Debug, Clone, Default)]
pub struct MeshReport {
    /// Faces authored.
    pub faces: usize,
    /// Faces skipped for having fewer than three vertices.
    pub degenerate_faces: usize,
    /// Faces skipped as holes.
    pub hole_faces: usize,
    /// The texture-coordinate primvar read.
    pub st_primvar: Option<String>,
}

/// A face subset: its faces and the material id the caller bound to it.
pub struct Subset {
    /// Face indices.
    pub faces: Vec<i64>,
    /// Material id.
    pub material: u32,
    /// The subset prim's path (for errors).
    pub path: String,
}

/// Builds the mesh of `prim` (material ids: `material` for faces outside every subset).
pub fn build_mesh(
    reader: &Reader,
    prim: &usd::Prim,
    material: u32,
    subsets: &[Subset],
    st_preferred: Option<&str>,
) -> Result<(Mesh, MeshReport), Error> {
    let points = reader.vec3s(prim, "points")?.ok_or_else(|| attr_error(prim, "points", "a Mesh needs points"))?;
    let counts = reader.ints(prim, "faceVertexCounts")?.unwrap_or_default();
    let indices = reader.ints(prim, "faceVertexIndices")?.unwrap_or_default();
    let total: i64 = counts.iter().map(|&c| c.max(0)).sum();
    if counts.iter().any(|&c| c < 0) {
        return Err(attr_error(prim, "faceVertexCounts", "has a negative count"));
    }
    if total as usize != indices.len() {
        return Err(attr_error(
            prim,
            "faceVertexIndices",
            format!("has {} indices but faceVertexCounts adds up to {total}", indices.len()),
        ));
    }
    if let Some(bad) = indices.iter().find(|&&i| i < 0 || i as usize >= points.len()) {
        return Err(attr_error(
            prim,
            "faceVertexIndices",
            format!("index {bad} is outside the {} points", points.len()),
        ));
    }
    if let Some(p) = points.iter().find(|p| !p.is_finite()) {
        return Err(attr_error(prim, "points", format!("a point is not finite: {p}")));
    }
    let left = match reader.token(prim, "orientation")?.as_deref() {
        None | Some("rightHanded") => false,
        Some("leftHanded") => true,
        Some(o) => {
            return Err(attr_error(prim, "orientation", format!("must be rightHanded or leftHanded, got '{o}'")))
        }
    };
    let holes: std::collections::HashSet<i64> =
        reader.ints(prim, "holeIndices")?.unwrap_or_default().into_iter().collect();
    let nfaces = counts.len();
    let ncorners = indices.len();
    let npoints = points.len();

    let normals = match primvar(reader, prim, "primvars:normals", Interp::Vertex, |r, p, n| r.vec3s(p, n))? {
        Some(n) => Some(n),
        None => primvar(reader, prim, "normals", Interp::Vertex, |r, p, n| r.vec3s(p, n))?,
    };
    let st_primvar = st_name(prim, st_preferred);
    let st = match &st_primvar {
        Some(name) => primvar(reader, prim, name, Interp::FaceVarying, |r, p, n| r.vec2s(p, n))?,
        None => None,
    };
    if let Some(n) = &normals {
        n.check(prim, nfaces, npoints, ncorners)?;
    }
    if let Some(s) = &st {
        s.check(prim, nfaces, npoints, ncorners)?;
    }
    // material per face
    let mut face_material = vec![material; nfaces];
    for s in subsets {
        for &f in &s.faces {
            match usize::try_from(f).ok().filter(|&f| f < nfaces) {
                Some(f) => face_material[f] = s.material,
                None => {
                    return Err(Error::Prim {
                        layer: crate::value::layer_of_prim(prim),
                        prim: s.path.clone(),
                        message: format!("indices: face {f} is outside the mesh's {nfaces} faces"),
                    })
                }
            }
        }
    }
    let welded = [normals.as_ref().map(|n| n.interp), st.as_ref().map(|s| s.interp)]
        .iter()
        .flatten()
        .all(|i| matches!(i, Interp::Vertex | Interp::Constant));

    let mut report = MeshReport { faces: nfaces, st_primvar: st_primvar.clone(), ..Default::default() };
    let mut mesh = Mesh::default();
    let to_v2 = |v: DVec2| Vec2::new(v.x as f32, 1.0 - v.y as f32);
    if welded {
        mesh.positions = points.iter().map(|p| p.as_vec3()).collect();
        if let Some(n) = &normals {
            mesh.normals =
                (0..npoints).map(|p| n.at(0, p, 0).unwrap_or(DVec3::Z).as_vec3().normalize_or_zero()).collect();
        }
        if let Some(s) = &st {
            mesh.uv0 = (0..npoints).map(|p| to_v2(s.at(0, p, 0).unwrap_or(DVec2::ZERO))).collect();
        }
    }
    let mut corner = 0usize;
    for (f, &c) in counts.iter().enumerate() {
        let c = c as usize;
        let first = corner;
        corner += c;
        if holes.contains(&(f as i64)) {
            report.hole_faces += 1;
            continue;
        }
        if c < 3 {
            report.degenerate_faces += 1;
            continue;
        }
        let vid = |k: usize, mesh: &mut Mesh| -> u32 {
            let fv = first + k;
            let p = indices[fv] as usize;
            if welded {
                return p as u32;
            }
            mesh.positions.push(points[p].as_vec3());
            if let Some(n) = &normals {
                mesh.normals.push(n.at(f, p, fv).unwrap_or(DVec3::Z).as_vec3().normalize_or_zero());
            }
            if let Some(s) = &st {
                mesh.uv0.push(to_v2(s.at(f, p, fv).unwrap_or(DVec2::ZERO)));
            }
            (mesh.positions.len() - 1) as u32
        };
        let ids: Vec<u32> = (0..c).map(|k| vid(k, &mut mesh)).collect();
        for k in 1..c - 1 {
            let t = if left { [ids[0], ids[k + 1], ids[k]] } else { [ids[0], ids[k], ids[k + 1]] };
            mesh.indices.push(t);
            mesh.material_ids.push(face_material[f]);
        }
    }
    if normals.is_none() {
        mesh.normals = smooth_normals(&mesh);
    }
    Ok((mesh, report))
}

/// Area-weighted vertex normals following the triangles' winding.
pub fn smooth_normals(mesh: &Mesh) -> Vec<Vec3> {
    let mut n = vec![Vec3::ZERO; mesh.positions.len()];
    for t in &mesh.indices {
        let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
        let fnrm = (b - a).cross(c - a);
        for &i in t {
            n[i as usize] += fnrm;
        }
    }
    n.iter().map(|v| v.try_normalize().unwrap_or(Vec3::Y)).collect()
}
