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
//! | UsdSkel binding (`SkelBindingAPI`) | points posed by the skeleton and blend shapes at the time read, normals with them ([`crate::skel`]) | as authored |
//!
//! Vertices stay shared when every primvar is per point (vertex/varying/constant); a uniform
//! or faceVarying primvar gives each face corner its own vertex.

use crate::skel::Skinned;
use crate::subdiv::{BoundaryRule, Cage, EdgeSharpness, VertexSharpness, INFINITELY_SHARP};
use crate::value::{attr_error, interpolation_token, Reader};
use crate::Error;
use glam::{DMat3, DVec2, DVec3, Vec2, Vec3};
use openusd::{sdf, usd};
use petzval_renderer::scene::Mesh;
use rustc_hash::FxHashMap as HashMap;

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
    /// The same primvar with every value mapped.
    fn map<U>(&self, f: impl Fn(T) -> U) -> Primvar<U> {
        Primvar {
            values: self.values.iter().map(|&v| f(v)).collect(),
            interp: self.interp,
            indices: self.indices.clone(),
            name: self.name.clone(),
        }
    }

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
    let Some(t) = interpolation_token(prim, name)? else { return Ok(default) };
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
    /// Catmull-Clark levels applied (None: rendered as authored).
    pub subdivision_level: Option<u32>,
    /// The primvar read as vertex colours.
    pub color_primvar: Option<String>,
    /// Normals were authored (else computed from the geometry).
    pub normals_authored: bool,
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

/// Builds the mesh of `prim` (material ids: `material` for faces outside every subset),
/// Catmull-Clark subdivided to `subdivision` levels when that is given (see [`crate::subdiv`]).
#[allow(clippy::too_many_arguments)]
pub fn build_mesh(
    reader: &Reader,
    prim: &usd::Prim,
    material: u32,
    subsets: &[Subset],
    st_preferred: Option<&str>,
    subdivision: Option<u32>,
    color: Option<(&str, Vec3)>,
    deform: Option<&Skinned>,
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
    // a skinned mesh (crate::skel): its posed points, its normals by each point's skinning
    let points = match deform {
        Some(d) if d.points.len() == points.len() => d.points.clone(),
        _ => points,
    };
    let normal_by = |p: usize, n: DVec3| match deform.and_then(|d| d.linear.get(p)) {
        Some(m) => cofactor(m) * n,
        None => n,
    };
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
    // vertex colours: the material's colour primvar, else its fallback everywhere
    let colors = match color {
        None => None,
        Some((name, fallback)) => {
            let read = if name.is_empty() {
                None
            } else {
                primvar(reader, prim, &format!("primvars:{name}"), Interp::Constant, |r, p, n| r.vec3s(p, n))?
            };
            let pv = read.unwrap_or_else(|| Primvar {
                values: vec![fallback.as_dvec3()],
                interp: Interp::Constant,
                indices: None,
                name: format!("primvars:{name}"),
            });
            pv.check(prim, nfaces, npoints, ncorners)?;
            if let Some(v) = pv.values.iter().find(|v| !v.is_finite()) {
                return Err(attr_error(prim, &pv.name, format!("a colour is not finite: {v}")));
            }
            Some(pv)
        }
    };
    let color_primvar = colors.as_ref().map(|c| c.name.clone());
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
    if let Some(level) = subdivision {
        let topo = Topology { counts: &counts, indices: &indices, holes: &holes, left, face_material: &face_material };
        return subdivided(
            reader,
            prim,
            &points,
            &topo,
            st.as_ref(),
            colors.as_ref(),
            level,
            MeshReport { faces: nfaces, st_primvar, color_primvar, ..Default::default() },
        );
    }
    let welded = [normals.as_ref().map(|n| n.interp), st.as_ref().map(|s| s.interp), colors.as_ref().map(|c| c.interp)]
        .iter()
        .flatten()
        .all(|i| matches!(i, Interp::Vertex | Interp::Constant));

    let mut report = MeshReport {
        faces: nfaces,
        st_primvar: st_primvar.clone(),
        color_primvar,
        normals_authored: normals.is_some(),
        ..Default::default()
    };
    let mut mesh = Mesh::default();
    let to_v2 = |v: DVec2| Vec2::new(v.x as f32, 1.0 - v.y as f32);
    if welded {
        mesh.positions = points.iter().map(|p| p.as_vec3()).collect();
        if let Some(n) = &normals {
            mesh.normals = (0..npoints)
                .map(|p| normal_by(p, n.at(0, p, 0).unwrap_or(DVec3::Z)).as_vec3().normalize_or_zero())
                .collect();
        }
        if let Some(s) = &st {
            mesh.uv0 = (0..npoints).map(|p| to_v2(s.at(0, p, 0).unwrap_or(DVec2::ZERO))).collect();
        }
        if let Some(c) = &colors {
            mesh.colors = (0..npoints).map(|p| to_colour(c.at(0, p, 0).unwrap_or(DVec3::ZERO))).collect();
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
                mesh.normals.push(normal_by(p, n.at(f, p, fv).unwrap_or(DVec3::Z)).as_vec3().normalize_or_zero());
            }
            if let Some(s) = &st {
                mesh.uv0.push(to_v2(s.at(f, p, fv).unwrap_or(DVec2::ZERO)));
            }
            if let Some(c) = &colors {
                mesh.colors.push(to_colour(c.at(f, p, fv).unwrap_or(DVec3::ZERO)));
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

/// The cofactor of `m` (det × inverse transpose, defined for singular matrices too), signed so
/// that it keeps a normal's side under a mirroring `m`: what carries normals through `m`.
fn cofactor(m: &DMat3) -> DMat3 {
    let c = DMat3::from_cols(m.y_axis.cross(m.z_axis), m.z_axis.cross(m.x_axis), m.x_axis.cross(m.y_axis));
    if m.determinant() < 0.0 {
        -c
    } else {
        c
    }
}

/// A colour primvar's value as the renderer's vertex colour (linear RGB, alpha 1, negative
/// channels 0).
fn to_colour(c: DVec3) -> glam::Vec4 {
    c.as_vec3().max(Vec3::ZERO).extend(1.0)
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

/// Triangles a subdivision level may make per mesh; a higher level is lowered to fit.
pub const MAX_SUBDIVIDED_TRIANGLES: usize = 20_000_000;

/// A mesh's faces as read and checked.
struct Topology<'a> {
    counts: &'a [i64],
    indices: &'a [i64],
    holes: &'a std::collections::HashSet<i64>,
    left: bool,
    face_material: &'a [u32],
}

/// The triangles `level` Catmull-Clark steps make of faces with these vertex counts.
pub fn subdivided_triangles(counts: &[i64], level: u32) -> usize {
    let quads: usize = counts.iter().filter(|&&c| c >= 3).map(|&c| c as usize).sum();
    match level {
        0 => counts.iter().filter(|&&c| c >= 3).map(|&c| c as usize - 2).sum(),
        l => {
            quads.saturating_mul(2).saturating_mul(1usize.checked_shl((l - 1).saturating_mul(2)).unwrap_or(usize::MAX))
        }
    }
}

/// Sharpness of creased edges and corners (`creaseIndices`/`Lengths`/`Sharpnesses`,
/// `cornerIndices`/`Sharpnesses`), checked against the points.
fn creases(reader: &Reader, prim: &usd::Prim, npoints: usize) -> Result<(EdgeSharpness, VertexSharpness), Error> {
    let point = |name: &str, i: i64| -> Result<u32, Error> {
        u32::try_from(i)
            .ok()
            .filter(|&v| (v as usize) < npoints)
            .ok_or_else(|| attr_error(prim, name, format!("index {i} is outside the {npoints} points")))
    };
    let mut edges = HashMap::default();
    let idx = reader.ints(prim, "creaseIndices")?.unwrap_or_default();
    let lens = reader.ints(prim, "creaseLengths")?.unwrap_or_default();
    let sharp = reader.floats(prim, "creaseSharpnesses")?.unwrap_or_default();
    if lens.iter().any(|&l| l < 2) {
        return Err(attr_error(prim, "creaseLengths", "a crease needs at least 2 vertices"));
    }
    let total: i64 = lens.iter().sum();
    if total as usize != idx.len() {
        return Err(attr_error(
            prim,
            "creaseIndices",
            format!("has {} indices but creaseLengths adds up to {total}", idx.len()),
        ));
    }
    let crease_edges = (total as usize).saturating_sub(lens.len());
    let per_edge = sharp.len() == crease_edges && sharp.len() != lens.len();
    if !per_edge && sharp.len() != lens.len() {
        return Err(attr_error(
            prim,
            "creaseSharpnesses",
            format!(
                "has {} values: one per crease ({}) or one per crease edge ({crease_edges}) is needed",
                sharp.len(),
                lens.len()
            ),
        ));
    }
    let (mut at, mut edge) = (0usize, 0usize);
    for (c, &l) in lens.iter().enumerate() {
        for k in 0..l as usize - 1 {
            let (a, b) = (point("creaseIndices", idx[at + k])?, point("creaseIndices", idx[at + k + 1])?);
            let s = if per_edge { sharp[edge] } else { sharp[c] };
            edges.insert((a.min(b), a.max(b)), if s.is_finite() { s.min(INFINITELY_SHARP) } else { INFINITELY_SHARP });
            edge += 1;
        }
        at += l as usize;
    }
    let mut corners = HashMap::default();
    let ci = reader.ints(prim, "cornerIndices")?.unwrap_or_default();
    let cs = reader.floats(prim, "cornerSharpnesses")?.unwrap_or_default();
    if ci.len() != cs.len() {
        return Err(attr_error(
            prim,
            "cornerSharpnesses",
            format!("has {} values, cornerIndices has {}", cs.len(), ci.len()),
        ));
    }
    for (&i, &s) in ci.iter().zip(&cs) {
        corners
            .insert(point("cornerIndices", i)?, if s.is_finite() { s.min(INFINITELY_SHARP) } else { INFINITELY_SHARP });
    }
    Ok((edges, corners))
}

/// A primvar's own cage, refined as the mesh's: vertex and constant primvars share the mesh's
/// topology and rules; face-varying and uniform ones are welded per (point, value) and refined
/// by the face-varying rule (`rules`: the boundary rule and the face-varying one, None =
/// bilinear). Returns the refined values and the final cage (its indices per face corner).
fn refine_primvar(
    cage: &Cage,
    face_corner: &[usize],
    pv: &Primvar<DVec3>,
    npoints: usize,
    level: u32,
    rules: (BoundaryRule, Option<BoundaryRule>),
) -> (Vec<DVec3>, Cage) {
    let per_point = matches!(pv.interp, Interp::Vertex | Interp::Constant);
    let mut out = Cage { counts: cage.counts.clone(), parent: cage.parent.clone(), ..Default::default() };
    let mut weld: HashMap<(u32, [u64; 3]), u32> = HashMap::default();
    let mut k = 0usize;
    for (face, &c) in cage.counts.iter().enumerate() {
        let f = cage.parent[face] as usize;
        let first = face_corner[face];
        for j in 0..c as usize {
            let p = cage.indices[k + j];
            let id = if per_point {
                p
            } else {
                let v = pv.at(f, p as usize, first + j).unwrap_or(DVec3::ZERO);
                *weld.entry((p, v.to_array().map(f64::to_bits))).or_insert_with(|| {
                    out.points.push(v);
                    (out.points.len() - 1) as u32
                })
            };
            out.indices.push(id);
        }
        k += c as usize;
    }
    let rule = if per_point {
        out.points = (0..npoints).map(|p| pv.at(0, p, 0).unwrap_or(DVec3::ZERO)).collect();
        out.creases = cage.creases.clone();
        out.corners = cage.corners.clone();
        rules.0
    } else {
        rules.1.unwrap_or(BoundaryRule::Bilinear)
    };
    refine(out, level, rule)
}

/// Refines `cage` by `level` steps and returns the limit positions and the final cage.
fn refine(mut cage: Cage, level: u32, rule: BoundaryRule) -> (Vec<DVec3>, Cage) {
    for _ in 0..level {
        cage = cage.refine(rule);
    }
    if level == 0 {
        return (cage.points.clone(), cage);
    }
    // Semi-sharp creases left after the last level: their vertices' limits need the steps
    // that end them (a refined cage keeps its vertices first), up to two extra steps and the
    // triangle cap; past that the limit weighs the sharp rule by the sharpness left.
    let left = cage.creases.values().chain(cage.corners.values()).copied().filter(|&s| s < INFINITELY_SHARP);
    let extra = left.fold(0.0f64, f64::max).ceil() as u32;
    let fits = cage.counts.len().saturating_mul(2 << (2 * extra.min(2))) <= MAX_SUBDIVIDED_TRIANGLES;
    let limit = if extra > 0 && extra <= 2 && fits {
        let mut finer = cage.refine(rule);
        for _ in 1..extra {
            finer = finer.refine(rule);
        }
        let mut l = finer.limit_points(rule);
        l.truncate(cage.points.len());
        l
    } else {
        cage.limit_points(rule)
    };
    (limit, cage)
}

/// A Catmull-Clark subdivided mesh: the cage refined `level` times, vertices on the limit
/// surface, smooth normals of the result (authored normals do not apply to a subdivision
/// surface), texture coordinates refined by their own interpolation.
#[allow(clippy::too_many_arguments)]
fn subdivided(
    reader: &Reader,
    prim: &usd::Prim,
    points: &[DVec3],
    topo: &Topology,
    st: Option<&Primvar<DVec2>>,
    colors: Option<&Primvar<DVec3>>,
    level: u32,
    mut report: MeshReport,
) -> Result<(Mesh, MeshReport), Error> {
    let boundary = match reader.token(prim, "interpolateBoundary")?.as_deref() {
        None | Some("edgeAndCorner") => BoundaryRule::EdgeAndCorner,
        Some("edgeOnly") | Some("none") => BoundaryRule::EdgeOnly,
        Some(o) => {
            return Err(attr_error(
                prim,
                "interpolateBoundary",
                format!("must be none, edgeOnly or edgeAndCorner, got '{o}'"),
            ))
        }
    };
    let fvar_rule = match reader.token(prim, "faceVaryingLinearInterpolation")?.as_deref() {
        Some("none") => Some(BoundaryRule::EdgeOnly),
        None | Some("cornersOnly") | Some("cornersPlus1") | Some("cornersPlus2") => Some(BoundaryRule::EdgeAndCorner),
        Some("boundaries") => Some(BoundaryRule::Linear),
        Some("all") => None,
        Some(o) => {
            return Err(attr_error(
                prim,
                "faceVaryingLinearInterpolation",
                format!("must be none, cornersOnly, cornersPlus1, cornersPlus2, boundaries or all, got '{o}'"),
            ))
        }
    };
    let (creases, corners) = creases(reader, prim, points.len())?;
    // 1. the cage: faces with ≥ 3 vertices (holes stay in it: they shape their neighbours)
    let mut cage = Cage { points: points.to_vec(), creases, corners, ..Default::default() };
    let mut face_corner = Vec::new();
    let mut corner = 0usize;
    for (f, &c) in topo.counts.iter().enumerate() {
        if c >= 3 {
            cage.counts.push(c as u32);
            cage.indices.extend(topo.indices[corner..corner + c as usize].iter().map(|&i| i as u32));
            cage.parent.push(f as u32);
            face_corner.push(corner);
        } else {
            report.degenerate_faces += 1;
        }
        corner += c as usize;
    }
    // 2. the level, lowered if it would make too many triangles
    let mut level = level;
    while level > 0 && subdivided_triangles(topo.counts, level) > MAX_SUBDIVIDED_TRIANGLES {
        level -= 1;
    }
    report.subdivision_level = Some(level);
    // 3. texture coordinates and colours: their own cages where they are per corner
    let rules = (boundary, fvar_rule);
    let uv_cage =
        st.map(|s| refine_primvar(&cage, &face_corner, &s.map(|v| v.extend(0.0)), points.len(), level, rules));
    let colour_cage = colors.map(|c| refine_primvar(&cage, &face_corner, c, points.len(), level, rules));
    let (limit, fine) = refine(cage, level, boundary);
    // 4. triangles, normals of the refined surface, and per-corner vertices where the
    //    coordinates need them
    let mut mesh = Mesh { positions: limit.iter().map(|p| p.as_vec3()).collect(), ..Default::default() };
    let mut tri_uv: Vec<[u32; 3]> = Vec::new();
    let mut tri_colour: Vec<[u32; 3]> = Vec::new();
    let mut k = 0usize;
    for (face, &c) in fine.counts.iter().enumerate() {
        let f = fine.parent[face] as usize;
        let c = c as usize;
        if !topo.holes.contains(&(f as i64)) {
            for j in 1..c - 1 {
                let t = if topo.left { [0, j + 1, j] } else { [0, j, j + 1] };
                mesh.indices.push(t.map(|i| fine.indices[k + i]));
                tri_uv.push(t.map(|i| uv_cage.as_ref().map_or(0, |(_, u)| u.indices[k + i])));
                tri_colour.push(t.map(|i| colour_cage.as_ref().map_or(0, |(_, u)| u.indices[k + i])));
                mesh.material_ids.push(topo.face_material[f]);
            }
        }
        k += c;
    }
    report.hole_faces = topo.counts.iter().enumerate().filter(|(f, _)| topo.holes.contains(&(*f as i64))).count();
    mesh.normals = smooth_normals(&mesh);
    let to_v2 = |v: DVec3| Vec2::new(v.x as f32, 1.0 - v.y as f32);
    if uv_cage.is_some() || colour_cage.is_some() {
        // one vertex per (position, coordinate, colour)
        let mut out = Mesh { material_ids: std::mem::take(&mut mesh.material_ids), ..Default::default() };
        let mut seen: HashMap<(u32, u32, u32), u32> = HashMap::default();
        for ((t, tu), tc) in mesh.indices.iter().zip(&tri_uv).zip(&tri_colour) {
            let tri = [0, 1, 2].map(|i| {
                *seen.entry((t[i], tu[i], tc[i])).or_insert_with(|| {
                    out.positions.push(mesh.positions[t[i] as usize]);
                    out.normals.push(mesh.normals[t[i] as usize]);
                    if let Some((uvs, _)) = &uv_cage {
                        out.uv0.push(to_v2(uvs[tu[i] as usize]));
                    }
                    if let Some((colours, _)) = &colour_cage {
                        out.colors.push(to_colour(colours[tc[i] as usize]));
                    }
                    (out.positions.len() - 1) as u32
                })
            });
            out.indices.push(tri);
        }
        mesh = out;
    }
    Ok((mesh, report))
}
