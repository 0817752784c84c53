//! UsdGeomBasisCurves (hair, wires, grass) → the renderer's triangle [`Mesh`]: each curve's
//! centre line is evaluated with its basis and swept by a round tube of triangles.
//!
//! | attribute | handling | fallback |
//! |---|---|---|
//! | `type` | `linear` (straight spans between points) or `cubic` | `cubic` |
//! | `basis` (cubic) | `bezier` (vstep 3), `bspline` (vstep 1), `catmullRom` (vstep 1), pxr's matrices | `bezier` |
//! | `wrap` | `nonperiodic`; `periodic` (closed, the first points reused); `pinned`: the end points repeated as Hydra's `HdsiPinnedCurveExpandingSceneIndex` does (catmullRom once, bspline twice; bezier and linear as nonperiodic) | `nonperiodic` |
//! | `curveVertexCounts`, `points` | one curve per count; a curve whose count its type, basis and wrap cannot use is skipped with a warning | required |
//! | `widths` (else `primvars:widths`) | tube diameter; `constant`, `uniform` (per curve), `vertex` (per point, evaluated with the basis), `varying` (per span end, linear; `faceVarying` as `varying`) | [`FALLBACK_WIDTH`] |
//! | `normals` | ignored: every curve renders as a round tube (authored normals would orient ribbons) | — |
//! | colour primvar (the material's `UsdPrimvarReader_float3` varname, an unbound prim's `displayColor`) | vertex colours, by the interpolations above | the material's colour |
//!
//! Tessellation: [`STEPS_PER_SPAN`] rings per cubic span (one per linear span), [`SIDES`]
//! vertices per ring, smooth radial normals, frames carried along the curve by parallel
//! transport (a periodic curve's twist spread over its length); each ring lies in the bisector
//! plane of its two chords, stretched across the bend as a mitre joint (at most
//! [`MITRE_LIMIT`]), so a polyline's tube keeps its radius through its corners. No end caps (hair tips taper;
//! the material is double-sided so an open end shows no hole). A prim that would make more than
//! [`MAX_CURVE_TRIANGLES`] triangles is tessellated more coarsely (fewer rings, then fewer
//! sides, down to 1 ring per span and 3 sides), and beyond that only its first curves that fit
//! are kept; both with a warning naming the prim.

use crate::value::{attr_error, Reader};
use crate::Error;
use glam::{DVec3, Vec3, Vec4};
use openusd::{sdf, usd};
use petzval_renderer::scene::Mesh;

/// Width of a curve that authors no `widths`: 1 scene unit, the constant fallback Hydra render
/// delegates use (HdRPR: "Fallback value is 1.0f with a constant interpolation"). Blender 5.0's
/// USD import leaves such curves without a radius, and Cycles renders them 0.01 m wide.
pub const FALLBACK_WIDTH: f64 = 1.0;
/// Rings per cubic span.
pub const STEPS_PER_SPAN: usize = 4;
/// The most a ring is stretched at a bend (a mitre joint; 4: a turn of 151°).
pub const MITRE_LIMIT: f64 = 4.0;
/// Vertices around each ring.
pub const SIDES: usize = 8;
/// Triangles one curves prim may make; a prim above it is tessellated more coarsely.
pub const MAX_CURVE_TRIANGLES: usize = 8_000_000;

/// The coarser tessellations tried, in order, when a prim would exceed [`MAX_CURVE_TRIANGLES`]:
/// (rings per cubic span, sides).
const LEVELS: [(usize, usize); 6] = [(STEPS_PER_SPAN, SIDES), (2, SIDES), (2, 6), (1, 6), (1, 4), (1, 3)];

/// The cubic basis (or linear).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Basis {
    /// `type = linear`.
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
    fn vstep(self) -> usize {
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

/// A curve primvar's interpolation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Interp {
    Constant,
    Uniform,
    Vertex,
    Varying,
}

/// A curve primvar (values already expanded through `:indices`).
struct CurvePrimvar {
    values: Vec<DVec3>,
    interp: Interp,
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
        "vertex" => Interp::Vertex,
        "varying" | "faceVarying" => Interp::Varying,
        o => return Err(attr_error(prim, name, format!("unknown interpolation '{o}'"))),
    })
}

/// Reads a primvar, expands its `:indices` and checks its count against the curves.
fn read_primvar(
    reader: &Reader,
    prim: &usd::Prim,
    name: &str,
    default: Interp,
    values: Vec<DVec3>,
    counts: &Counts,
) -> Result<CurvePrimvar, Error> {
    // Step 1: interpolation and indices
    let interp = interpolation(prim, name, default)?;
    let values = match reader.ints(prim, &format!("{name}:indices"))? {
        None => values,
        Some(ix) => ix
            .iter()
            .map(|&i| usize::try_from(i).ok().and_then(|i| values.get(i).copied()))
            .collect::<Option<Vec<_>>>()
            .ok_or_else(|| {
                attr_error(prim, &format!("{name}:indices"), format!("an index is outside the {} values", values.len()))
            })?,
    };
    // Step 2: the count the interpolation needs
    let need = match interp {
        Interp::Constant => 1,
        Interp::Uniform => counts.curves,
        Interp::Vertex => counts.points,
        Interp::Varying => counts.varying,
    };
    if values.len() < need {
        return Err(attr_error(
            prim,
            name,
            format!("{interp:?} interpolation needs {need} values, has {}", values.len()),
        ));
    }
    if let Some(v) = values.iter().find(|v| !v.is_finite()) {
        return Err(attr_error(prim, name, format!("a value is not finite: {v}")));
    }
    Ok(CurvePrimvar { values, interp })
}

/// Element counts of a prim's curves.
struct Counts {
    curves: usize,
    points: usize,
    varying: usize,
}

/// One curve as laid out in the prim's arrays.
struct Curve {
    /// Index of its first point.
    first: usize,
    /// Its spans (None: its count does not fit the basis and wrap).
    spans: Option<Spans>,
    /// Index of its first varying value.
    first_varying: usize,
}

impl CurvePrimvar {
    /// The value on curve `c` (index `k`), span `s` at parameter `t`.
    fn at(&self, k: usize, c: &Curve, basis: Basis, s: usize, t: f64) -> DVec3 {
        let Some(sp) = &c.spans else { return DVec3::ZERO };
        match self.interp {
            Interp::Constant => self.values[0],
            Interp::Uniform => self.values[k],
            Interp::Vertex => {
                let w = basis.weights(t);
                (0..4).map(|j| self.values[c.first + sp.controls[s][j]] * w[j]).sum()
            }
            Interp::Varying => {
                let [a, b] = sp.varying[s];
                self.values[c.first_varying + a].lerp(self.values[c.first_varying + b], t)
            }
        }
    }
}

/// What was read and made of one curves prim.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct CurvesReport {
    /// Curves authored.
    pub curves: usize,
    /// Curves tessellated.
    pub tessellated: usize,
    /// Curves skipped: a vertex count the basis and wrap cannot use.
    pub bad_counts: usize,
    /// Curves left out to stay under [`MAX_CURVE_TRIANGLES`].
    pub over_limit: usize,
    /// `type`.
    pub kind: String,
    /// `basis` (cubic) or `linear`.
    pub basis: String,
    /// `wrap`.
    pub wrap: String,
    /// Rings per span used.
    pub rings_per_span: usize,
    /// Sides used.
    pub sides: usize,
    /// `widths` was authored (else [`FALLBACK_WIDTH`]).
    pub widths_authored: bool,
    /// The colour primvar read, if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub color_primvar: Option<String>,
}

/// The prim's basis and wrap, checked.
fn basis_and_wrap(reader: &Reader, prim: &usd::Prim) -> Result<(Basis, Wrap, String, String, String), Error> {
    let kind = reader.token(prim, "type")?.unwrap_or_else(|| "cubic".into());
    let basis_t = reader.token(prim, "basis")?.unwrap_or_else(|| "bezier".into());
    let wrap_t = reader.token(prim, "wrap")?.unwrap_or_else(|| "nonperiodic".into());
    let basis = match (kind.as_str(), basis_t.as_str()) {
        ("linear", _) => Basis::Linear,
        ("cubic", "bezier") => Basis::Bezier,
        ("cubic", "bspline") => Basis::Bspline,
        ("cubic", "catmullRom") => Basis::CatmullRom,
        ("cubic", b) => {
            return Err(attr_error(prim, "basis", format!("must be bezier, bspline or catmullRom, got '{b}'")))
        }
        (k, _) => return Err(attr_error(prim, "type", format!("must be linear or cubic, got '{k}'"))),
    };
    let wrap = match wrap_t.as_str() {
        "nonperiodic" => Wrap::Nonperiodic,
        "periodic" => Wrap::Periodic,
        "pinned" => Wrap::Pinned,
        w => return Err(attr_error(prim, "wrap", format!("must be nonperiodic, periodic or pinned, got '{w}'"))),
    };
    let basis_name = if basis == Basis::Linear { "linear".to_string() } else { basis_t };
    Ok((basis, wrap, kind, basis_name, wrap_t))
}

/// The prim's curves with their spans, checked against `points`.
fn layout(prim: &usd::Prim, counts: &[i64], npoints: usize, basis: Basis, wrap: Wrap) -> Result<Vec<Curve>, Error> {
    let mut out = Vec::with_capacity(counts.len());
    let (mut first, mut first_varying) = (0usize, 0usize);
    for &c in counts {
        let n = usize::try_from(c)
            .map_err(|_| attr_error(prim, "curveVertexCounts", format!("has a negative count {c}")))?;
        let spans = spans(n, basis, wrap);
        let nv = spans.as_ref().map(|s| s.varying_count).unwrap_or(0);
        out.push(Curve { first, spans, first_varying });
        first = first.saturating_add(n);
        first_varying += nv;
    }
    if first != npoints {
        return Err(attr_error(
            prim,
            "curveVertexCounts",
            format!("adds up to {first} points, but points has {npoints}"),
        ));
    }
    Ok(out)
}

/// A point on the centre line, with its radius and colour.
#[derive(Debug, Clone, Copy)]
struct Sample {
    p: DVec3,
    radius: f64,
    color: Option<DVec3>,
}

/// The samples along curve `k`: `rings` per span (plus the end of an open curve).
fn samples(
    k: usize,
    c: &Curve,
    basis: Basis,
    rings: usize,
    points: &CurvePrimvar,
    widths: &CurvePrimvar,
    color: Option<&CurvePrimvar>,
) -> Vec<Sample> {
    let Some(sp) = &c.spans else { return Vec::new() };
    let rings = if basis == Basis::Linear { 1 } else { rings };
    let nspans = sp.controls.len();
    let mut out = Vec::with_capacity(nspans * rings + 1);
    for s in 0..nspans {
        let last = s + 1 == nspans && !sp.closed;
        for r in 0..rings + usize::from(last) {
            let t = r as f64 / rings as f64;
            out.push(Sample {
                p: points.at(k, c, basis, s, t),
                radius: (widths.at(k, c, basis, s, t).x * 0.5).max(0.0),
                color: color.map(|cp| cp.at(k, c, basis, s, t)),
            });
        }
    }
    out
}

/// The evaluated centre line of every curve of `prim` with `rings` samples per cubic span
/// (for checks against other evaluators); skipped curves give empty lists.
pub fn centre_lines(reader: &Reader, prim: &usd::Prim, rings: usize) -> Result<Vec<Vec<DVec3>>, Error> {
    let read = read_curves(reader, prim, None)?;
    Ok((0..read.curves.len())
        .map(|k| {
            samples(k, &read.curves[k], read.basis, rings, &read.points, &read.widths, None)
                .iter()
                .map(|s| s.p)
                .collect()
        })
        .collect())
}

/// Everything read from a curves prim.
struct ReadCurves {
    basis: Basis,
    curves: Vec<Curve>,
    points: CurvePrimvar,
    widths: CurvePrimvar,
    color: Option<CurvePrimvar>,
    report: CurvesReport,
}

fn read_curves(reader: &Reader, prim: &usd::Prim, color: Option<(&str, Vec3)>) -> Result<ReadCurves, Error> {
    // Step 1: topology
    let (basis, wrap, kind, basis_name, wrap_name) = basis_and_wrap(reader, prim)?;
    let points = reader.vec3s(prim, "points")?.ok_or_else(|| attr_error(prim, "points", "BasisCurves need points"))?;
    if let Some(p) = points.iter().find(|p| !p.is_finite()) {
        return Err(attr_error(prim, "points", format!("a point is not finite: {p}")));
    }
    let counts = reader.ints(prim, "curveVertexCounts")?.unwrap_or_default();
    let curves = layout(prim, &counts, points.len(), basis, wrap)?;
    let n = Counts {
        curves: curves.len(),
        points: points.len(),
        varying: curves.iter().map(|c| c.spans.as_ref().map_or(0, |s| s.varying_count)).sum(),
    };
    // Step 2: widths (diameters), as authored or the fallback
    let widths_name = ["widths", "primvars:widths"]
        .into_iter()
        .find(|name| prim.attribute(*name).get::<sdf::Value>().ok().flatten().is_some());
    let widths = match widths_name {
        Some(name) => {
            let w = reader.floats(prim, name)?.unwrap_or_default();
            let w: Vec<DVec3> = w.into_iter().map(|x| DVec3::new(x, 0.0, 0.0)).collect();
            read_primvar(reader, prim, name, Interp::Vertex, w, &n)?
        }
        None => CurvePrimvar { values: vec![DVec3::new(FALLBACK_WIDTH, 0.0, 0.0)], interp: Interp::Constant },
    };
    // Step 3: the colour primvar, else the material's fallback everywhere
    let color_pv = match color {
        None => None,
        Some((name, fallback)) => {
            let attr = format!("primvars:{name}");
            match (!name.is_empty()).then(|| reader.vec3s(prim, &attr)).transpose()?.flatten() {
                Some(v) => Some((read_primvar(reader, prim, &attr, Interp::Constant, v, &n)?, Some(attr))),
                None => Some((CurvePrimvar { values: vec![fallback.as_dvec3()], interp: Interp::Constant }, None)),
            }
        }
    };
    let report = CurvesReport {
        curves: curves.len(),
        bad_counts: curves.iter().filter(|c| c.spans.is_none()).count(),
        kind,
        basis: basis_name,
        wrap: wrap_name,
        widths_authored: widths_name.is_some(),
        color_primvar: color_pv.as_ref().and_then(|c| c.1.clone()),
        ..Default::default()
    };
    let points = CurvePrimvar { values: points, interp: Interp::Vertex };
    Ok(ReadCurves { basis, curves, points, widths, color: color_pv.map(|c| c.0), report })
}

/// Triangles a curve of `spans` spans makes with `rings` rings per cubic span and `sides`.
fn curve_triangles(sp: &Spans, basis: Basis, rings: usize, sides: usize) -> usize {
    let rings = if basis == Basis::Linear { 1 } else { rings };
    2 * sides * sp.controls.len() * rings
}

/// Builds the tube mesh of curves prim `prim` (all triangles `material`; vertex colours from
/// `color`: the primvar name, or "" for none, and the colour where it is missing).
pub fn build_curves(
    reader: &Reader,
    prim: &usd::Prim,
    material: u32,
    color: Option<(&str, Vec3)>,
) -> Result<(Mesh, CurvesReport), Error> {
    let read = read_curves(reader, prim, color)?;
    let mut report = read.report.clone();
    // Step 1: the finest tessellation under the limit, else the curves that fit the coarsest
    let total = |rings: usize, sides: usize| -> usize {
        read.curves.iter().filter_map(|c| c.spans.as_ref()).map(|s| curve_triangles(s, read.basis, rings, sides)).sum()
    };
    let (rings, sides) = LEVELS.into_iter().find(|&(r, s)| total(r, s) <= MAX_CURVE_TRIANGLES).unwrap_or(LEVELS[5]);
    report.rings_per_span = if read.basis == Basis::Linear { 1 } else { rings };
    report.sides = sides;
    // Step 2: sweep a tube along each curve
    let mut mesh = Mesh::default();
    let mut made = 0usize;
    for (k, c) in read.curves.iter().enumerate() {
        let Some(sp) = &c.spans else { continue };
        let tris = curve_triangles(sp, read.basis, rings, sides);
        if made + tris > MAX_CURVE_TRIANGLES {
            report.over_limit += 1;
            continue;
        }
        let s = samples(k, c, read.basis, rings, &read.points, &read.widths, read.color.as_ref());
        sweep(&mut mesh, &s, sides, sp.closed, material);
        made += tris;
        report.tessellated += 1;
    }
    // Step 3: single precision as the renderer takes it (1e39 in points or widths is not)
    if mesh.positions.iter().any(|p| !p.is_finite()) {
        return Err(attr_error(
            prim,
            "widths",
            "a tube vertex is not finite in single precision (points or widths too large)",
        ));
    }
    Ok((mesh, report))
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
/// facing out.
fn sweep(mesh: &mut Mesh, samples: &[Sample], sides: usize, closed: bool, material: u32) {
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
