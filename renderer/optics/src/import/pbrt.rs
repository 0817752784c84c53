//! pbrt `.dat` lens tables (the `RealisticCamera` lens files of pbrt-v3/v4).
//!
//! One row per surface, front (scene) to back (film), lengths in mm, `#` comments:
//!
//! | column | meaning | our field |
//! |---|---|---|
//! | 1 `radius` | radius of curvature; 0 = the aperture stop (a plane) | `radius_mm` |
//! | 2 `thickness` | axial distance to the NEXT surface (pbrt-v4 reads it so; the last row's value is the back focus, which pbrt replaces when it focuses) | `thickness_mm` |
//! | 3 `N` | index n_d of the medium after the surface; 0 or 1 = air | `material = { nd = N, vd = 0 }` |
//! | 4 `aperture` | clear aperture DIAMETER | `semi_diameter_mm` = aperture / 2 |
//!
//! pbrt files carry no dispersion data, so glass is a model glass without dispersion
//! (`vd = 0`). The stop's opening is its aperture / 2; its housing is the largest
//! semi-diameter of it and its two neighbours.
//!
//! Two conventions for column 2 exist. pbrt-v4 (and the scaled files of the pbrt-v4 scenes)
//! use "distance to the next surface"; that is the default here. Kolb et al.'s original
//! tables use "axpos", the distance from the PREVIOUS surface (the first row's value is then
//! 0 and the last surface's distance to the film is not given). Their column header says
//! `axpos`, but so does the header of the scaled pbrt-v4 files whose data are to-next, so the
//! header alone proves nothing. [`import_pbrt`] switches to the axpos reading only when the
//! header says `axpos` AND the first row's distance is 0 AND the last row's is positive (read
//! as to-next such a table would have a zero-thickness first element and a nonzero back
//! focus, which no real table has). [`import_pbrt_axpos`] forces the axpos reading.
//!
//! When a table's semi-diameters make two neighbouring surfaces cross at their edges (the
//! books give rounded apertures), the smaller of the two is reduced to the largest value at
//! which they do not cross, and `notes` says so (see [`fit_semi_diameters`]).

use crate::error::{Error, Result};
use crate::prescription::{LensMeta, MaterialSpec, ModelGlass, Num, Prescription, SourceMap, SurfaceSpec};
use crate::surface::Shape;

// Largest accepted length (radius, thickness, aperture) in a lens table, mm: anything larger is
// a typo or garbage, and would overflow the tracer's arithmetic (shared by every format).
pub(super) use crate::prescription::MAX_LENGTH_MM;

/// Which meaning column 2 of a pbrt table has.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Convention {
    /// Distance to the next surface (pbrt-v4).
    ToNext,
    /// Distance from the previous surface (Kolb's "axpos").
    Axpos,
}

/// One parsed data row.
struct Row {
    line: usize,
    radius: f64,
    thickness: f64,
    n: f64,
    aperture: f64,
}

/// Imports a pbrt lens table. `file` names the file in errors, `name` becomes `lens.name`.
/// Column 2 is read as the distance to the next surface unless the table is reliably in
/// Kolb's axpos convention (see the module docs).
pub fn import_pbrt(text: &str, file: &str, name: &str) -> Result<(Prescription, SourceMap)> {
    let (header, rows) = parse(text, file)?;
    let axpos_header = header.iter().any(|(_, h)| h.to_ascii_lowercase().contains("axpos"));
    if axpos_header && rows.len() >= 2 && rows[0].thickness == 0.0 && rows[rows.len() - 1].thickness > 0.0 {
        return import_pbrt_axpos(text, file, name);
    }
    build(header, rows, file, name, Convention::ToNext)
}

/// Imports a pbrt lens table in Kolb's "axpos" convention: column 2 is the distance from the
/// PREVIOUS surface (the first row's value is ignored). The last surface's distance to the
/// film is unknown and set to 0, which the lens reads as "focus at the paraxial back focus".
pub fn import_pbrt_axpos(text: &str, file: &str, name: &str) -> Result<(Prescription, SourceMap)> {
    let (header, rows) = parse(text, file)?;
    build(header, rows, file, name, Convention::Axpos)
}

/// Header comments as (line, text).
type Header = Vec<(usize, String)>;

/// Splits the text into header comments and data rows.
fn parse(text: &str, file: &str) -> Result<(Header, Vec<Row>)> {
    let mut header = Vec::new();
    let mut rows = Vec::new();
    const COLUMNS: [&str; 4] = ["radius", "thickness", "N", "aperture"];
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let (data, comment) = match raw.find('#') {
            Some(k) => (&raw[..k], Some(&raw[k + 1..])),
            None => (raw, None),
        };
        if let Some(c) = comment {
            if rows.is_empty() {
                let c = c.trim().trim_matches(|ch: char| ch == '"' || ch.is_whitespace());
                if !c.is_empty() {
                    header.push((line, c.to_string()));
                }
            }
        }
        let data = data.trim().trim_start_matches('\u{feff}');
        if data.is_empty() {
            continue;
        }
        let tokens: Vec<&str> = data.split_whitespace().collect();
        if tokens.len() < 4 {
            return Err(Error::lens_file(
                file,
                line,
                COLUMNS[tokens.len()],
                format!("truncated row: expected 4 columns (radius thickness N aperture), got {}", tokens.len()),
            ));
        }
        if tokens.len() > 4 {
            return Err(Error::lens_file(
                file,
                line,
                "row",
                format!("expected 4 columns (radius thickness N aperture), got {}", tokens.len()),
            ));
        }
        let mut v = [0.0; 4];
        for (k, t) in tokens.iter().enumerate() {
            let x: f64 = t
                .parse()
                .map_err(|_| Error::lens_file(file, line, COLUMNS[k], format!("'{}' is not a number", short(t))))?;
            if !x.is_finite() {
                return Err(Error::lens_file(file, line, COLUMNS[k], format!("must be a finite number, got {t}")));
            }
            if x.abs() > MAX_LENGTH_MM && k != 2 {
                return Err(Error::lens_file(
                    file,
                    line,
                    COLUMNS[k],
                    format!("{} mm is implausibly large (limit {} mm)", Num(x), Num(MAX_LENGTH_MM)),
                ));
            }
            v[k] = x;
        }
        if v[3] <= 0.0 {
            return Err(Error::lens_file(
                file,
                line,
                "aperture",
                format!("aperture diameter must be positive, got {}", v[3]),
            ));
        }
        if !(v[2] == 0.0 || (1.0..=3.0).contains(&v[2])) {
            return Err(Error::lens_file(
                file,
                line,
                "N",
                format!("index {} must be 0 or 1 (air) or in (1, 3] (glass)", v[2]),
            ));
        }
        if v[0] == 0.0 && !(v[2] == 0.0 || v[2] == 1.0) {
            return Err(Error::lens_file(
                file,
                line,
                "N",
                format!("the aperture stop (radius 0) must be followed by air (N = 0 or 1), got N = {}", v[2]),
            ));
        }
        rows.push(Row { line, radius: v[0], thickness: v[1], n: v[2], aperture: v[3] });
    }
    if rows.is_empty() {
        return Err(Error::lens_file(
            file,
            0,
            "file",
            "no lens rows (expected `radius thickness N aperture` per line)",
        ));
    }
    Ok((header, rows))
}

fn build(
    header: Header,
    rows: Vec<Row>,
    file: &str,
    name: &str,
    convention: Convention,
) -> Result<(Prescription, SourceMap)> {
    let stops: Vec<usize> = rows.iter().enumerate().filter(|(_, r)| r.radius == 0.0).map(|(i, _)| i).collect();
    match stops.len() {
        0 => return Err(Error::lens_file(file, 0, "radius", "no aperture stop: pbrt marks it with a row of radius 0")),
        1 => {}
        _ => {
            return Err(Error::lens_file(
                file,
                rows[stops[1]].line,
                "radius",
                format!("a second aperture stop (radius 0; the first is on line {})", rows[stops[0]].line),
            ))
        }
    }
    if stops[0] > 0 {
        let before = &rows[stops[0] - 1];
        if !(before.n == 0.0 || before.n == 1.0) {
            return Err(Error::lens_file(
                file,
                rows[stops[0]].line,
                "N",
                format!(
                    "the aperture stop must sit in air, but the row before it (line {}) has glass N = {}",
                    before.line, before.n
                ),
            ));
        }
    }
    let n = rows.len();
    let mut surfaces = Vec::with_capacity(n);
    for (i, r) in rows.iter().enumerate() {
        let thickness = match convention {
            Convention::ToNext => r.thickness,
            Convention::Axpos => rows.get(i + 1).map(|next| next.thickness).unwrap_or(0.0),
        };
        let material = if r.n == 0.0 || r.n == 1.0 {
            MaterialSpec::default()
        } else {
            MaterialSpec::Model(ModelGlass { nd: r.n, vd: 0.0 })
        };
        surfaces.push(SurfaceSpec {
            radius_mm: r.radius,
            thickness_mm: thickness,
            material,
            semi_diameter_mm: r.aperture / 2.0,
            stop: r.radius == 0.0,
            ..Default::default()
        });
    }
    let s = stops[0];
    let stop_sd = surfaces[s].semi_diameter_mm;
    let mut housing = stop_sd;
    if s > 0 {
        housing = housing.max(surfaces[s - 1].semi_diameter_mm);
    }
    if s + 1 < n {
        housing = housing.max(surfaces[s + 1].semi_diameter_mm);
    }
    surfaces[s].housing_semi_diameter_mm = Some(housing);

    // Metadata from the header comments: "Scaled to 50 mm from 100 mm", "F/2", "16mm/f4".
    let texts: Vec<&str> = header
        .iter()
        .map(|(_, h)| h.as_str())
        .filter(|h| {
            let first = h.split_whitespace().next().unwrap_or("").to_ascii_lowercase();
            first != "radius"
        })
        .collect();
    let focal_length_mm = texts.iter().find_map(|h| scaled_to_mm(h));
    let f_number = texts.iter().find_map(|h| f_number_in(h));
    let mut source = texts.join("; ");
    if !source.is_empty() {
        source.push_str("; ");
    }
    source.push_str("via pbrt-v4 scenes (Apache-2.0)");
    let mut notes = vec![format!(
        "Imported from the pbrt lens table {file}, reading column 2 as {}; glass is modelled from N(d) alone (pbrt gives no dispersion).",
        match convention {
            Convention::ToNext => "the distance to the next surface",
            Convention::Axpos => "axpos, the distance from the previous surface (the back focus is left to the paraxial value)",
        }
    )];
    let mut p = Prescription {
        lens: LensMeta {
            name: name.to_string(),
            source,
            notes: String::new(),
            focal_length_mm,
            f_number,
            stop_semi_diameter_mm: None,
            ..Default::default()
        },
        aperture: Default::default(),
        surfaces,
    };
    notes.extend(fit_semi_diameters(&mut p));
    p.lens.notes = join_sentences(&notes);
    let map = SourceMap::new(file, rows.iter().map(|r| r.line).collect());
    Ok((p, map))
}

/// Joins notes into one paragraph, ending each with a full stop.
pub(super) fn join_sentences<S: AsRef<str>>(parts: &[S]) -> String {
    let mut out = String::new();
    for p in parts {
        let p = p.as_ref().trim();
        if p.is_empty() {
            continue;
        }
        if !out.is_empty() {
            out.push(' ');
        }
        out.push_str(p);
        if !p.ends_with(['.', '!', '?', ')']) {
            out.push('.');
        }
    }
    out
}

/// "Scaled to 50 mm from 100 mm" → 50.
fn scaled_to_mm(h: &str) -> Option<f64> {
    let lower = h.to_ascii_lowercase();
    let k = lower.find("scaled to")?;
    leading_number(&lower[k + "scaled to".len()..])
}

/// "F/2", "F/5.6", "16mm/f4", "f2.8" → the f-number.
fn f_number_in(h: &str) -> Option<f64> {
    let lower = h.to_ascii_lowercase();
    let bytes = lower.as_bytes();
    for (k, &b) in bytes.iter().enumerate() {
        if b != b'f' {
            continue;
        }
        // A word boundary (or '/') before, then "/" or nothing, then a number.
        let before_ok = k == 0 || !bytes[k - 1].is_ascii_alphanumeric();
        if !before_ok {
            continue;
        }
        let rest = &lower[k + 1..];
        let rest = rest.strip_prefix('/').unwrap_or(rest);
        if rest.starts_with(|c: char| c.is_ascii_digit()) {
            if let Some(v) = leading_number(rest) {
                if v > 0.3 && v < 128.0 {
                    return Some(v);
                }
            }
        }
    }
    None
}

/// The number at the start of `s` (after spaces), e.g. " 50 mm" → 50.
pub(super) fn leading_number(s: &str) -> Option<f64> {
    let s = s.trim_start();
    let end = s.find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(s.len());
    let v: f64 = s[..end].trim_end_matches('.').parse().ok()?;
    v.is_finite().then_some(v)
}

/// At most 40 characters of `s`, for error messages about garbage input.
pub(super) fn short(s: &str) -> String {
    let mut out: String = s.chars().take(40).collect();
    if s.chars().count() > 40 {
        out.push('…');
    }
    out
}

/// The shape a surface spec describes.
pub(super) fn shape_of(s: &SurfaceSpec) -> Shape {
    Shape {
        curvature_per_mm: if s.radius_mm == 0.0 { 0.0 } else { 1.0 / s.radius_mm },
        conic: s.conic,
        a2: s.aspheric_r2,
        aspheric: s.aspheric.clone(),
        aspheric_odd: s.aspheric_odd.clone(),
        cylinder: s.cylinder,
    }
}

/// Largest r in [0, r_max] over which `shape` has a sag (along x and y).
fn sag_domain(shape: &Shape, r_max: f64) -> f64 {
    let ok = |r: f64| shape.sag(r, 0.0).is_some() && shape.sag(0.0, r).is_some();
    if ok(r_max) {
        return r_max;
    }
    let (mut lo, mut hi) = (0.0, r_max);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if ok(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

/// Reduces semi-diameters that the lens validation would reject, where the fix is small:
///
/// 1. a semi-diameter beyond the surface's sag domain (|R| for a sphere) becomes 99.9 % of
///    that limit;
/// 2. where two neighbouring surfaces cross inside their common aperture, the smaller
///    semi-diameter of the pair becomes the largest height at which they do not cross
///    (rounded down to 1 µm).
///
/// A fix that would cut a semi-diameter below half its value is not made (the table is then
/// wrong rather than rounded, and validation reports it). The stop's opening
/// (`lens.stop_semi_diameter_mm`) is clamped to a reduced stop. Returns one note per change.
pub(crate) fn fit_semi_diameters(p: &mut Prescription) -> Vec<String> {
    let mut notes = Vec::new();
    let n = p.surfaces.len();
    let valid = |v: f64| v.is_finite() && v > 0.0;
    if p.surfaces.iter().any(|s| {
        !(valid(s.semi_diameter_mm) && s.thickness_mm.is_finite() && s.radius_mm.is_finite() && s.conic.is_finite())
            || s.aspheric.iter().chain(&s.aspheric_odd).any(|a| !a.is_finite())
    }) {
        return notes;
    }
    // 1. Sag domain.
    for (i, s) in p.surfaces.iter_mut().enumerate() {
        let shape = shape_of(s);
        let r = sag_domain(&shape, s.semi_diameter_mm);
        if r < s.semi_diameter_mm {
            let new = (r * 0.999 * 1000.0).floor() / 1000.0;
            if new >= 0.5 * s.semi_diameter_mm {
                notes.push(format!(
                    "Surface {} semi-diameter reduced from {} to {} mm (the table's value exceeds what its curvature allows).",
                    i + 1,
                    s.semi_diameter_mm,
                    new
                ));
                s.semi_diameter_mm = new;
            }
        }
    }
    // 2. Crossing neighbours.
    let mut z = 0.0;
    for i in 0..n.saturating_sub(1) {
        let (za, zb) = (z, z + p.surfaces[i].thickness_mm);
        z = zb;
        let (a, b) = (&p.surfaces[i], &p.surfaces[i + 1]);
        let (sa, sb) = (shape_of(a), shape_of(b));
        let r_max = a.semi_diameter_mm.min(b.semi_diameter_mm);
        let gap = |r: f64| -> f64 {
            let mut g = f64::INFINITY;
            for (x, y) in [(r, 0.0), (0.0, r)] {
                match (sa.sag(x, y), sb.sag(x, y)) {
                    (Some(ha), Some(hb)) => g = g.min((zb + hb) - (za + ha)),
                    _ => g = f64::NEG_INFINITY,
                }
            }
            g
        };
        const STEPS: usize = 1024;
        let mut first_bad = None;
        for k in 0..=STEPS {
            let r = r_max * k as f64 / STEPS as f64;
            if gap(r) < 0.0 {
                first_bad = Some(k);
                break;
            }
        }
        let Some(k) = first_bad else { continue };
        if k == 0 {
            continue; // crossing on the axis: a negative thickness, reported by validation
        }
        let (mut lo, mut hi) = (r_max * (k - 1) as f64 / STEPS as f64, r_max * k as f64 / STEPS as f64);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if gap(mid) >= 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let new = (lo * 1000.0).floor() / 1000.0;
        if new < 0.5 * r_max {
            continue;
        }
        let what = if matches!(&a.material, MaterialSpec::Name(m) if m.eq_ignore_ascii_case("air"))
            || matches!(&a.material, MaterialSpec::Model(m) if m.nd == 1.0)
        {
            "air gap"
        } else {
            "element"
        };
        let targets: Vec<usize> = [i, i + 1].into_iter().filter(|&j| p.surfaces[j].semi_diameter_mm <= r_max).collect();
        let old = r_max;
        for &j in &targets {
            p.surfaces[j].semi_diameter_mm = new;
        }
        let which = match targets.as_slice() {
            [j] => format!("Surface {} semi-diameter", j + 1),
            _ => format!("Surfaces {} and {} semi-diameters", i + 1, i + 2),
        };
        notes.push(format!(
            "{which} reduced from {old} to {new} mm: at the listed value the edges of surfaces {} and {} would cross ({what}).",
            i + 1,
            i + 2
        ));
    }
    // The stop's opening must still fit.
    if let Some(stop) = p.surfaces.iter().find(|s| s.stop) {
        if let Some(open) = p.lens.stop_semi_diameter_mm {
            if open > stop.semi_diameter_mm {
                p.lens.stop_semi_diameter_mm = Some(stop.semi_diameter_mm);
            }
        }
    }
    notes
}
