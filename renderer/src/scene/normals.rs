//! Normals of deformed meshes (skins, morph targets, blend shapes), as Blender recomputes them.
//!
//! | input | type | meaning |
//! |---|---|---|
//! | `rest`, `file` | `[Vec3]` | the vertices' positions and normals as the file stores them (before deformation) |
//! | `deformed` | `[Vec3]` | the vertices' positions after deformation |
//! | `blended` | `[Vec3]` | the deformed normals the file format defines (kept where the file's normals are not the geometry's) |
//! | `triangles` | `[[u32; 3]]` | the mesh's triangles |

use glam::Vec3;

/// Normals a file's normals were derived from its geometry, derived again from the deformed
/// geometry, as Blender does for the meshes Cycles renders (it recomputes the normals of a mesh
/// deformed by an armature or shape keys); other vertices keep `blended` (the file format's
/// deformed normals, e.g. glTF's morph normal displacements and skin cofactor). `rest`, `file`:
/// the vertices' positions and normals before deformation; `deformed`: their positions after;
/// `triangles`: the mesh's triangles (vertex indices).
///
/// Vertices with the same rest position and the same file normal form one smooth group (a UV
/// seam splits vertices, a hard edge or a flat face splits their normals too). A group's normal
/// is the corner-angle-weighted sum of its faces' normals (Blender's vertex normals; two
/// triangles cut from one quad count as that quad, see [`faces_of`]; slivers, whose normal is
/// rounding noise, left out). A
/// vertex counts as derived when that sum over the rest geometry is within 2° of its file
/// normal; then its normal is the same sum over the deformed geometry. (Coplanar flat-shaded
/// faces cannot be told from a smooth-shaded plane in a triangle mesh: deformed, they turn
/// smooth.)
pub fn rederive_normals(rest: &[Vec3], file: &[Vec3], deformed: &[Vec3], blended: &mut [Vec3], triangles: &[[u32; 3]]) {
    use std::collections::HashMap;
    let n = rest.len().min(file.len()).min(deformed.len()).min(blended.len());
    let v3 = |a: &[Vec3], i: usize| a.get(i).copied().unwrap_or(Vec3::ZERO);
    // 1. Smooth groups: rest position and file normal, bit for bit.
    let mut groups: HashMap<[u32; 6], u32> = HashMap::new();
    let group: Vec<u32> = (0..n)
        .map(|i| {
            let key = [v3(rest, i), v3(file, i)].map(|v| v.to_array().map(|x| (x + 0.0).to_bits()));
            let key = [key[0][0], key[0][1], key[0][2], key[1][0], key[1][1], key[1][2]];
            let next = groups.len() as u32;
            *groups.entry(key).or_insert(next)
        })
        .collect();
    // 2. Faces: the triangles, with two consecutive ones that share an edge and lie in one
    //    plane at rest taken as the quad they were triangulated from (Blender's exporter writes
    //    a quad as two such triangles, and Blender's normals weigh the quad's corners).
    let faces = faces_of(triangles, |i| v3(rest, i));
    // 3. Angle-weighted face normals (Newell's, as Blender computes a polygon's) per group.
    let sums = |pos: &[Vec3]| {
        let mut acc = vec![Vec3::ZERO; groups.len()];
        for face in &faces {
            let corners: &[usize] = match face {
                Face::Tri(t) => t,
                Face::Quad(q) => q,
            };
            let k = corners.len();
            let p = |j: usize| v3(pos, corners[j % k]);
            let newell = (0..k).fold(Vec3::ZERO, |sum, j| sum + p(j).cross(p(j + 1)));
            // a sliver (an n-gon's collinear vertices, triangulated) has a normal of rounding
            // noise: left out (its vertices then fail the rest test below, unless other
            // faces carry them)
            let longest = (0..k).map(|j| (p(j + 1) - p(j)).length_squared()).fold(0.0f32, f32::max);
            if !(newell.length() > 1e-3 * longest) {
                continue;
            }
            let normal = newell.normalize();
            for j in 0..k {
                let angle = (p(j + k - 1) - p(j)).angle_between(p(j + 1) - p(j));
                if angle.is_finite() {
                    acc[group[corners[j]] as usize] += normal * angle;
                }
            }
        }
        acc
    };
    let (at_rest, now) = (sums(rest), sums(deformed));
    // 4. Derived vertices take the deformed sum.
    let cos_tolerance = 2.0f32.to_radians().cos();
    for i in 0..n {
        let g = group[i] as usize;
        let (r, d) = (at_rest[g].normalize_or_zero(), now[g].normalize_or_zero());
        if r.dot(v3(file, i).normalize_or_zero()) >= cos_tolerance && d != Vec3::ZERO && d.is_finite() {
            blended[i] = d;
        }
    }
}

/// A face of a deformed mesh: a triangle, or the quad two triangles were cut from.
enum Face {
    /// Three corners, in winding order.
    Tri([usize; 3]),
    /// Four corners, in winding order.
    Quad([usize; 4]),
}

/// The faces of triangle list `triangles`: consecutive triangles (a, b, c), (a', b', c') that
/// share an edge in opposite directions and whose normals (at `rest(i)`) agree within 0.5° are
/// one quad; the others stay triangles.
fn faces_of(triangles: &[[u32; 3]], rest: impl Fn(usize) -> Vec3) -> Vec<Face> {
    let tris: Vec<[usize; 3]> = triangles.iter().map(|t| t.map(|i| i as usize)).collect();
    let normal = |t: &[usize; 3]| (rest(t[1]) - rest(t[0])).cross(rest(t[2]) - rest(t[0])).normalize_or_zero();
    let cos_planar = 0.5f32.to_radians().cos();
    let mut out = Vec::with_capacity(tris.len());
    let mut i = 0;
    while i < tris.len() {
        let t = tris[i];
        let quad = tris.get(i + 1).and_then(|u| {
            // the edge p → q of t that u runs q → p; x: t's other corner, y: u's
            (0..3).find_map(|e| {
                let (x, p, q) = (t[e], t[(e + 1) % 3], t[(e + 2) % 3]);
                let f = (0..3).find(|&f| u[f] == q && u[(f + 1) % 3] == p)?;
                let y = u[(f + 2) % 3];
                (y != x && normal(&t).dot(normal(u)) >= cos_planar).then_some([x, p, y, q])
            })
        });
        match quad {
            Some(q) => {
                out.push(Face::Quad(q));
                i += 2;
            }
            None => {
                out.push(Face::Tri(t));
                i += 1;
            }
        }
    }
    out
}
