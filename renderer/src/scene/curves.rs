//! Curves (hair, wires, grass) as round tubes of triangles: the cubic bases, a curve's spans,
//! and the sweep of a ring of vertices along an evaluated centre line. Used by the USD loader
//! (`UsdGeomBasisCurves`) and the Blender add-on (Curves objects).
//!
//! | basis | control points per span | vstep | periodic needs | open needs |
//! |---|---|---|---|---|
//! | [`Basis::Linear`] | 2 | 1 | ≥ 3 points | ≥ 2 points |
//! | [`Basis::Bezier`] | 4 | 3 | a multiple of 3 | 4 + 3k points |
//! | [`Basis::Bspline`] | 4 | 1 | ≥ 3 points | ≥ 4 points |
//! | [`Basis::CatmullRom`] | 4 | 1 | ≥ 3 points | ≥ 4 points |
//!
//! | wrap | ends |
//! |---|---|
//! | [`Wrap::Nonperiodic`] | open, the spans the points make |
//! | [`Wrap::Periodic`] | closed, the first points reused |
//! | [`Wrap::Pinned`] | open, through the end points: repeated as Hydra's `HdsiPinnedCurveExpandingSceneIndex` does (catmullRom once, bspline twice; bezier and linear as nonperiodic) |
//!
//! Tessellation: [`STEPS_PER_SPAN`] rings per cubic span (one per linear span), [`SIDES`]
//! vertices per ring, smooth radial normals, frames carried along the curve by parallel
//! transport (a periodic curve's twist spread over its length); each ring lies in the bisector
//! plane of its two chords, stretched across the bend as a mitre joint (at most
//! [`MITRE_LIMIT`]), so a polyline's tube keeps its radius through its corners. No end caps
//! (hair tips taper; materials are double-sided so an open end shows no hole). A set of curves
//! that would make more than [`MAX_CURVE_TRIANGLES`] triangles is tessellated more coarsely
//! ([`LEVELS`]: fewer rings, then fewer sides), and beyond that only its first curves that fit
//! are kept ([`tube_mesh`] reports both).

use super::Mesh;
use glam::{DVec3, Vec3, Vec4};

/// Rings per cubic span.
pub const STEPS_PER_SPAN: usize = 4;
/// The most a ring is stretched at a bend (a mitre joint; 4: a turn of 151°).
pub const MITRE_LIMIT: f64 = 4.0;
/// Vertices around each ring.
pub const SIDES: usize = 8;
/// Triangles one set of curves (a USD prim, a Blender object) may make; above it the set is
/// tessellated more coarsely.
pub const MAX_CURVE_TRIANGLES: usize = 8_000_000;
/// The tessellations tried, in order, to stay under [`MAX_CURVE_TRIANGLES`]: (rings per cubic
/// span, sides).
pub const LEVELS: [(usize, usize); 6] = [(STEPS_PER_SPAN, SIDES), (2, SIDES), (2, 6), (1, 6), (1, 4), (1, 3)];

/// The cubic basis (or linear).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Basis {
    /// Straight spans between points.
    Linear,
    /// Cubic Bézier, vstep 3.
    Bezier,
    /// Uniform cubic B-spline, vstep 1.
    Bspline,
    /// Catmull-Rom, vstep 1.
    CatmullRom,
}

/// How a curve's ends behave.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wrap {
    /// Open.
    Nonperiodic,
    /// Closed.
    Periodic,
    /// Open, through its first and last points.
    Pinned,
}

impl Basis {
    /// Points from one span's first control point to the next's.
    pub fn vstep(self) -> usize {
        match self {
            Basis::Bezier => 3,
            _ => 1,
        }
    }

    /// The weights of a span's four control points at `t` (pxr's matrices, row vector
    /// `[t³ t² t 1] · M`); linear: the first two.
    pub fn weights(self, t: f64) -> [f64; 4] {
        let m: [[f64; 4]; 4] = match self {
            Basis::Linear => return [1.0 - t, t, 0.0, 0.0],
            Basis::Bezier => {
                [[-1.0, 3.0, -3.0, 1.0], [3.0, -6.0, 3.0, 0.0], [-3.0, 3.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]]
            }
            Basis::Bspline => [
                [-1.0 / 6.0, 3.0 / 6.0, -3.0 / 6.0, 1.0 / 6.0],
                [3.0 / 6.0, -6.0 / 6.0, 3.0 / 6.0, 0.0],
                [-3.0 / 6.0, 0.0, 3.0 / 6.0, 0.0],
                [1.0 / 6.0, 4.0 / 6.0, 1.0 / 6.0, 0.0],
            ],
            Basis::CatmullRom => {
                [[-0.5, 1.5, -1.5, 0.5], [1.0, -2.5, 2.0, -0.5], [-0.5, 0.0, 0.5, 0.0], [0.0, 1.0, 0.0, 0.0]]
            }
        };
        let p = [t * t * t, t * t, t, 1.0];
        std::array::from_fn(|j| (0..4).map(|k| p[k] * m[k][j]).sum())
    }
}

/// One curve's spans: for each span the indices (into the curve's own points) of its control
/// points (two for linear), and the varying index at each of its ends.
#[derive(Debug, Clone, PartialEq)]
pub struct Spans {
    /// Control-point indices per span.
    pub controls: Vec<[usize; 4]>,
    /// Varying-primvar indices (within the curve) at the span's start and end.
    pub varying: Vec<[usize; 2]>,
    /// Varying values the curve takes (`varying` interpolation's count).
    pub varying_count: usize,
    /// The curve is closed.
    pub closed: bool,
}

/// The spans of a curve of `n` points, or None when `n` does not fit the basis and wrap.
pub fn spans(n: usize, basis: Basis, wrap: Wrap) -> Option<Spans> {
    let vstep = basis.vstep();
    // Step 1: the control-point list, with Hydra's phantom points for pinned curves
    let (lead, idx): (usize, Vec<usize>) = match (wrap, basis) {
        (Wrap::Pinned, Basis::CatmullRom) if n >= 2 => {
            (1, std::iter::once(0).chain(0..n).chain(std::iter::once(n - 1)).collect())
        }
        (Wrap::Pinned, Basis::Bspline) if n >= 2 => (2, [0, 0].into_iter().chain(0..n).chain([n - 1, n - 1]).collect()),
        (Wrap::Pinned, Basis::CatmullRom | Basis::Bspline) => return None,
        _ => (0, (0..n).collect()),
    };
    let m = idx.len();
    let periodic = wrap == Wrap::Periodic;
    // Step 2: the spans over that list
    let controls: Vec<[usize; 4]> = match (basis, periodic) {
        (Basis::Linear, false) if m >= 2 => (0..m - 1).map(|i| [idx[i], idx[i + 1], 0, 0]).collect(),
        (Basis::Linear, true) if m >= 3 => (0..m).map(|i| [idx[i], idx[(i + 1) % m], 0, 0]).collect(),
        (_, false) if m >= 4 && (m - 4) % vstep == 0 => {
            (0..(m - 4) / vstep + 1).map(|s| std::array::from_fn(|k| idx[s * vstep + k])).collect()
        }
        (_, true) if m >= 3 && m % vstep == 0 => {
            (0..m / vstep).map(|s| std::array::from_fn(|k| idx[(s * vstep + k) % m])).collect()
        }
        _ => return None,
    };
    // Step 3: varying values: one per span end (shared), as the schema counts them for the
    // authored topology; Hydra's extra pinned spans take the end values
    let authored_spans = controls.len() - 2 * lead.saturating_sub(1);
    let varying_count = if periodic { authored_spans } else { authored_spans + 1 };
    let extra = lead.saturating_sub(1);
    let varying = (0..controls.len())
        .map(|s| {
            let a = s.saturating_sub(extra).min(varying_count - 1);
            let b =
                if periodic { (a + 1) % varying_count } else { (s + 1).saturating_sub(extra).min(varying_count - 1) };
            [a, b]
        })
        .collect();
    Some(Spans { controls, varying, varying_count, closed: periodic })
}

/// Triangles a curve of `sp` makes with `rings` rings per cubic span and `sides`.
pub fn curve_triangles(sp: &Spans, basis: Basis, rings: usize, sides: usize) -> usize {
    let rings = if basis == Basis::Linear { 1 } else { rings };
    2 * sides * sp.controls.len() * rings
}

/// A point on the centre line, with its radius and colour.
#[derive(Debug, Clone, Copy)]
pub struct Sample {
    /// Centre.
    pub p: DVec3,
    /// Tube radius (≥ 0).
    pub radius: f64,
    /// Vertex colour, if the curve has colours.
    pub color: Option<DVec3>,
}

/// The samples along one curve whose points and radii are both evaluated with its basis
/// (vertex interpolation): `rings` per cubic span (1 per linear span), plus the end of an open
/// curve. `radii` has one value per point.
pub fn vertex_samples(points: &[DVec3], radii: &[f64], sp: &Spans, basis: Basis, rings: usize) -> Vec<Sample> {
    let rings = if basis == Basis::Linear { 1 } else { rings };
    let nspans = sp.controls.len();
    let mut out = Vec::with_capacity(nspans * rings + 1);
    for (s, c) in sp.controls.iter().enumerate() {
        let last = s + 1 == nspans && !sp.closed;
        for r in 0..rings + usize::from(last) {
            let w = basis.weights(r as f64 / rings as f64);
            let p: DVec3 = (0..4).map(|j| points[c[j]] * w[j]).sum();
            let radius: f64 = (0..4).map(|j| radii[c[j]] * w[j]).sum();
            out.push(Sample { p, radius: radius.max(0.0), color: None });
        }
    }
    out
}

/// A sample's ring axis and mitre: the unit tangent (the bisector of the chords to its
/// neighbours), the bend direction in the ring's plane, and the stretch along it
/// (1 / cos(half the turn), at most [`MITRE_LIMIT`]) that keeps the tube's radius on both chords.
fn mitres(s: &[Sample], closed: bool) -> Vec<(DVec3, DVec3, f64)> {
    let n = s.len();
    let chord = |a: usize, b: usize| (s[b].p - s[a].p).try_normalize();
    // Step 1: each chord's direction (a zero-length chord, a doubled point, takes a neighbour's)
    let links = if closed { n } else { n - 1 };
    let mut dirs: Vec<Option<DVec3>> = (0..links).map(|i| chord(i, (i + 1) % n)).collect();
    let fill = dirs.iter().flatten().next().copied().unwrap_or(DVec3::Z);
    let mut last = fill;
    for d in dirs.iter_mut() {
        last = d.unwrap_or(last);
        *d = Some(last);
    }
    let dirs: Vec<DVec3> = dirs.into_iter().map(|d| d.unwrap_or(fill)).collect();
    // Step 2: the bisector and stretch at each sample
    (0..n)
        .map(|i| {
            let d_in = if closed { dirs[(i + links - 1) % links] } else { dirs[i.saturating_sub(1).min(links - 1)] };
            let d_out = if closed || i < links { dirs[i % links] } else { dirs[links - 1] };
            let t = (d_in + d_out).try_normalize().unwrap_or(d_out);
            let bend =
                (d_out - d_in).try_normalize().map(|k| (k - t * k.dot(t)).normalize_or_zero()).unwrap_or(DVec3::ZERO);
            let stretch = (1.0 / d_in.dot(t).max(1e-9)).min(MITRE_LIMIT);
            (t, bend, stretch)
        })
        .collect()
}

/// Frames (normal) carried along the tangents by parallel transport.
fn frames(t: &[DVec3], closed: bool) -> Vec<DVec3> {
    let Some(&t0) = t.first() else { return Vec::new() };
    let mut n = t0.any_orthonormal_vector();
    let mut out = Vec::with_capacity(t.len());
    for &ti in t {
        n = (n - ti * n.dot(ti)).try_normalize().unwrap_or_else(|| ti.any_orthonormal_vector());
        out.push(n);
    }
    // a closed curve: spread the twist between the last frame carried on and the first
    if closed && t.len() > 1 {
        let back = (n - t0 * n.dot(t0)).try_normalize().unwrap_or(out[0]);
        let twist = t0.dot(out[0].cross(back)).atan2(out[0].dot(back));
        let len = t.len() as f64;
        for (i, (f, &ti)) in out.iter_mut().zip(t).enumerate() {
            *f = glam::DQuat::from_axis_angle(ti, -twist * i as f64 / len) * *f;
        }
    }
    out
}

/// Appends the tube of `samples` to `mesh`: a ring of `sides` vertices per sample, triangles
/// facing out, all of material `material`; vertex colours where the samples have them.
pub fn sweep(mesh: &mut Mesh, samples: &[Sample], sides: usize, closed: bool, material: u32) {
    if samples.len() < 2 {
        return;
    }
    let m = mitres(samples, closed);
    let t: Vec<DVec3> = m.iter().map(|m| m.0).collect();
    let f = frames(&t, closed);
    let base = mesh.positions.len() as u32;
    for (i, s) in samples.iter().enumerate() {
        let b = t[i].cross(f[i]);
        for j in 0..sides {
            let a = std::f64::consts::TAU * j as f64 / sides as f64;
            let radial = f[i] * a.cos() + b * a.sin();
            let (_, bend, stretch) = m[i];
            let offset = radial + bend * bend.dot(radial) * (stretch - 1.0);
            mesh.positions.push((s.p + offset * s.radius).as_vec3());
            mesh.normals.push(radial.as_vec3());
            if let Some(c) = s.color {
                mesh.colors.push(Vec4::from((c.as_vec3().max(Vec3::ZERO), 1.0)));
            }
        }
    }
    let rings = samples.len();
    let links = if closed { rings } else { rings - 1 };
    let sides32 = sides as u32;
    for i in 0..links {
        let (r0, r1) = (base + i as u32 * sides32, base + ((i + 1) % rings) as u32 * sides32);
        for j in 0..sides32 {
            let jn = (j + 1) % sides32;
            mesh.indices.push([r0 + j, r0 + jn, r1 + j]);
            mesh.indices.push([r0 + jn, r1 + jn, r1 + j]);
            mesh.material_ids.extend([material, material]);
        }
    }
}

/// One curve for [`tube_mesh`]: its points and per-point radii (evaluated with the basis).
#[derive(Debug, Clone)]
pub struct TubeCurve {
    /// Control points.
    pub points: Vec<DVec3>,
    /// Radius at each control point.
    pub radii: Vec<f64>,
    /// Basis.
    pub basis: Basis,
    /// Ends.
    pub wrap: Wrap,
    /// Material index of its triangles.
    pub material: u32,
}

/// What [`tube_mesh`] made.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TubeReport {
    /// Curves tessellated.
    pub tessellated: usize,
    /// Curves skipped: a point count their basis and wrap cannot use.
    pub bad_counts: usize,
    /// Curves left out to stay under [`MAX_CURVE_TRIANGLES`].
    pub over_limit: usize,
    /// Rings per cubic span used.
    pub rings_per_span: usize,
    /// Sides used.
    pub sides: usize,
}

/// The tube mesh of `curves` (points and radii both evaluated with each curve's basis): the
/// finest of [`LEVELS`] under [`MAX_CURVE_TRIANGLES`], else the first curves that fit the
/// coarsest.
pub fn tube_mesh(curves: &[TubeCurve]) -> (Mesh, TubeReport) {
    // Step 1: spans per curve (a radius list too short counts as a bad count)
    let spans: Vec<Option<Spans>> = curves
        .iter()
        .map(|c| spans(c.points.len(), c.basis, c.wrap).filter(|_| c.radii.len() >= c.points.len()))
        .collect();
    let mut report = TubeReport { bad_counts: spans.iter().filter(|s| s.is_none()).count(), ..Default::default() };
    // Step 2: the finest tessellation under the limit
    let total = |rings: usize, sides: usize| -> usize {
        curves.iter().zip(&spans).filter_map(|(c, s)| Some(curve_triangles(s.as_ref()?, c.basis, rings, sides))).sum()
    };
    let (rings, sides) = LEVELS.into_iter().find(|&(r, s)| total(r, s) <= MAX_CURVE_TRIANGLES).unwrap_or(LEVELS[5]);
    report.rings_per_span = rings;
    report.sides = sides;
    // Step 3: sweep each curve
    let mut mesh = Mesh::default();
    let mut made = 0usize;
    for (c, sp) in curves.iter().zip(&spans) {
        let Some(sp) = sp else { continue };
        let tris = curve_triangles(sp, c.basis, rings, sides);
        if made + tris > MAX_CURVE_TRIANGLES {
            report.over_limit += 1;
            continue;
        }
        let s = vertex_samples(&c.points, &c.radii, sp, c.basis, rings);
        sweep(&mut mesh, &s, sides, sp.closed, c.material);
        made += tris;
        report.tessellated += 1;
    }
    (mesh, report)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A straight Catmull-Rom strand of radius 0.1 along +z: rings of 8 at distance 0.1 (the
    /// mitre does not stretch a straight tube), normals radial, and 4 rings per span.
    #[test]
    fn straight_catmull_rom_tube() {
        let points: Vec<DVec3> = (0..4).map(|i| DVec3::new(0.0, 0.0, i as f64)).collect();
        let c = TubeCurve { points, radii: vec![0.1; 4], basis: Basis::CatmullRom, wrap: Wrap::Pinned, material: 3 };
        let (mesh, r) = tube_mesh(&[c]);
        // pinned: 3 spans, 4 rings each plus the end ring
        assert_eq!((r.tessellated, r.bad_counts, r.sides), (1, 0, SIDES));
        assert_eq!(mesh.positions.len(), (3 * 4 + 1) * SIDES);
        assert_eq!(mesh.indices.len(), 2 * SIDES * 3 * 4);
        assert!(mesh.material_ids.iter().all(|&m| m == 3));
        for (p, n) in mesh.positions.iter().zip(&mesh.normals) {
            assert!((p.truncate().length() - 0.1).abs() < 1e-6, "{p}");
            assert!((n.truncate().normalize() - n.truncate()).length() < 1e-6 && n.z.abs() < 1e-6, "{n}");
        }
        // the ends: z = 0 and z = 3 (pinned Catmull-Rom passes through its end points)
        let z = mesh.positions.iter().map(|p| p.z);
        assert!((z.clone().fold(f32::MAX, f32::min)).abs() < 1e-6);
        assert!((z.fold(f32::MIN, f32::max) - 3.0).abs() < 1e-6);
    }

    /// Per-point radii are evaluated with the basis; a count the basis cannot use is skipped.
    #[test]
    fn linear_radii_and_bad_counts() {
        let line = TubeCurve {
            points: vec![DVec3::ZERO, DVec3::X],
            radii: vec![0.2, 0.4],
            basis: Basis::Linear,
            wrap: Wrap::Nonperiodic,
            material: 0,
        };
        let bezier =
            TubeCurve { points: vec![DVec3::ZERO; 5], radii: vec![0.1; 5], basis: Basis::Bezier, ..line.clone() };
        let (mesh, r) = tube_mesh(&[line, bezier]);
        assert_eq!((r.tessellated, r.bad_counts), (1, 1));
        assert_eq!(mesh.positions.len(), 2 * SIDES);
        let ring = |k: usize| glam::Vec2::new(mesh.positions[k * SIDES].y, mesh.positions[k * SIDES].z).length();
        assert!((ring(0) - 0.2).abs() < 1e-6 && (ring(1) - 0.4).abs() < 1e-6, "{} {}", ring(0), ring(1));
    }
}
