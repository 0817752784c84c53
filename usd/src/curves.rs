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
//! Tessellation is the renderer's ([`petzval_renderer::scene::curves`]: [`STEPS_PER_SPAN`] rings
//! per cubic span, [`SIDES`] sides, mitred rings, no end caps). A prim that would make more
//! than [`MAX_CURVE_TRIANGLES`] triangles is tessellated more coarsely (fewer rings, then fewer
//! sides, down to 1 ring per span and 3 sides), and beyond that only its first curves that fit
//! are kept; both with a warning naming the prim.

use crate::value::{attr_error, interpolation_token, Reader};
use crate::Error;
use glam::{DVec3, Vec3};
use openusd::{sdf, usd};
use petzval_renderer::scene::curves::{curve_triangles, sweep, Sample, LEVELS};
pub use petzval_renderer::scene::curves::{
    spans, Basis, Spans, Wrap, MAX_CURVE_TRIANGLES, MITRE_LIMIT, SIDES, STEPS_PER_SPAN,
};
use petzval_renderer::scene::Mesh;

/// Width of a curve that authors no `widths`: 1 scene unit, the constant fallback Hydra render
/// delegates use (HdRPR: "Fallback value is 1.0f with a constant interpolation"). Blender 5.0's
/// USD import leaves such curves without a radius, and Cycles renders them 0.01 m wide.
pub const FALLBACK_WIDTH: f64 = 1.0;
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
    let Some(t) = interpolation_token(prim, name)? else { return Ok(default) };
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
