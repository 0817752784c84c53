//! Entries of the lentil lens database (`lenses.json` of the lentil project's
//! polynomial-optics code, MIT licence, (c) 2023 Zeno Pelgrims).
//!
//! The file is one JSON object keyed by entry id (`"0001"`, ...). An entry's
//! `optical-elements-patent` list holds the surfaces front (scene) to back (film):
//!
//! | lentil field | meaning | our field |
//! |---|---|---|
//! | `radius` | radius of curvature; \|R\| ≥ 99999 is lentil's placeholder for a plane | `radius_mm` (0 for a plane) |
//! | `thickness` | distance to the next surface (a list `[short, mid, long]` for zoom lenses: the first is used) | `thickness_mm` |
//! | `material` | `"air"`; `"iris"`/`"IRIS"` = the aperture stop (a plane); `"abbe"` = model glass from `ior`/`abbe`; else a glass name | `material`, `stop` |
//! | `ior`, `abbe` | n_d and V_d of the medium after the surface | `{ nd, vd }` for `"abbe"` and as a fallback |
//! | `housing-radius` | semi-diameter (the iris's: its widest opening) | `semi_diameter_mm` |
//! | `lens-geometry` | `"spherical"`, `"aspherical"`, `"cyl-x"`, `"cyl-y"` | `aspheric`, `cylinder` |
//! | `aspherical-equation` | `[A4, A6, A8, A10]` | `aspheric` (conic 0) |
//!
//! Meaning taken from lentil's own tracer (`polynomial-optics/src/raytrace.h` and
//! `lenssystem.h` in zpelgrims/lentil):
//! - `evaluate_aspherical` computes z = h²/R / (1 + √(1 − (1+k) h²/R²)) + c₀h⁴ + c₁h⁶ + c₂h⁸ +
//!   c₃h¹⁰, so the equation's four numbers are A4, A6, A8, A10 of our `aspheric` list. The
//!   JSON reader passes its "is aspheric" flag (1) where the `.fx` reader passes the conic
//!   constant; the database gives no conic, so we use k = 0.
//! - `"cyl-y"` sets `cylinder_axis_y = true`, and `cylindrical_xy(..., cyl_y = true)`
//!   intersects x² + (z − c)² = R² with normal (x/R, 0, ·): a cylinder whose AXIS is y, curved
//!   along x. So lentil `cyl-y` → our `cylinder = "x"`, and `cyl-x` (y² + (z − c)² = R²) →
//!   `cylinder = "y"`. lentil's drawing code agrees: it draws `cyl-y` surfaces flat in its
//!   y–z side view.
//!
//! A glass name is looked up in our catalogue (the catalogue's spelling is written); when it
//! is not there, the entry's `ior`/`abbe` become a model glass and `notes` says so. The iris
//! gets its `housing-radius` as its opening and the larger neighbouring semi-diameter as its
//! housing. `lens.focal_length_mm` is `focal-length-mm-patent`; `lens.f_number` and
//! `lens.stop_semi_diameter_mm` come from the entry's `fstop.unscaled` and
//! `max-fstop-aperture-radius.unscaled` when they fit the iris and agree (within 5 %) with
//! our paraxial f-number at that opening. Housing radii that make neighbouring surfaces cross
//! are reduced as for pbrt tables (see [`super::pbrt`]), with a note.
//!
//! Line numbers: each surface maps to the line of its `{` in the file, found by a tolerant
//! scan of the text that tracks strings, nesting and keys.

use super::pbrt::{fit_semi_diameters, join_sentences, short, MAX_LENGTH_MM};
use crate::error::{Error, Result};
use crate::glass::Material;
use crate::lens::Lens;
use crate::prescription::{
    CylinderAxis, LensMeta, MaterialSpec, ModelGlass, Num, Prescription, SourceMap, SurfaceSpec,
};
use serde_json::Value;

/// lentil writes 99999, 100000 or 999999 for a flat surface.
const PLANE_RADIUS: f64 = 99999.0;

/// Imports one entry of the lentil database. `file` names the file in errors; `id` is the
/// entry's key, e.g. `"0001"`.
pub fn import_lentil(text: &str, file: &str, id: &str) -> Result<(Prescription, SourceMap)> {
    let root: Value =
        serde_json::from_str(text).map_err(|e| Error::lens_file(file, e.line(), "json", e.to_string()))?;
    let Some(obj) = root.as_object() else {
        return Err(Error::lens_file(file, 1, "json", "expected a JSON object keyed by lens id"));
    };
    let lines = scan_lines(text, id);
    let entry_line = lines.entry.unwrap_or(0);
    let Some(entry) = obj.get(id) else {
        let mut ids: Vec<&str> = obj.keys().map(|k| k.as_str()).collect();
        ids.sort_unstable();
        let list = ids.iter().take(40).copied().collect::<Vec<_>>().join(", ");
        return Err(Error::lens_file(file, 0, "id", format!("no entry '{}' in the database (ids: {list})", short(id))));
    };
    let Some(entry) = entry.as_object() else {
        return Err(Error::lens_file(file, entry_line, id, "the entry is not a JSON object"));
    };
    let elements_field = format!("{id}.optical-elements-patent");
    let elements = entry
        .get("optical-elements-patent")
        .ok_or_else(|| Error::lens_file(file, entry_line, &elements_field, "missing field"))?
        .as_array()
        .ok_or_else(|| {
            Error::lens_file(file, lines.elements.unwrap_or(entry_line), &elements_field, "must be a list of surfaces")
        })?;
    if elements.is_empty() {
        return Err(Error::lens_file(file, lines.elements.unwrap_or(entry_line), &elements_field, "no surfaces"));
    }

    let mut notes: Vec<String> = Vec::new();
    let mut surfaces = Vec::with_capacity(elements.len());
    let mut surface_lines = Vec::with_capacity(elements.len());
    let mut medium_is_air = true;
    for (i, el) in elements.iter().enumerate() {
        let line = lines.surfaces.get(i).copied().unwrap_or(entry_line);
        let field = |f: &str| format!("{elements_field}[{i}].{f}");
        let err = |f: &str, msg: String| Error::lens_file(file, line, field(f), msg);
        let Some(el) = el.as_object() else {
            return Err(err("", "a surface must be a JSON object".into()));
        };
        let number = |f: &str, required: bool| -> Result<Option<f64>> {
            match el.get(f) {
                None | Some(Value::Null) if !required => Ok(None),
                None => Err(err(f, "missing field".into())),
                Some(Value::Null) => Err(err(f, "must be a number, got null".into())),
                Some(v) => {
                    let x = match v {
                        Value::Array(a) if f == "thickness" => a.first().and_then(|x| x.as_f64()),
                        _ => v.as_f64(),
                    }
                    .ok_or_else(|| err(f, format!("must be a number, got {}", short(&v.to_string()))))?;
                    if !x.is_finite() {
                        return Err(err(f, format!("must be a finite number, got {x}")));
                    }
                    Ok(Some(x))
                }
            }
        };
        let material = match el.get("material") {
            Some(Value::String(s)) => s.clone(),
            None => return Err(err("material", "missing field".into())),
            Some(v) => return Err(err("material", format!("must be a string, got {}", short(&v.to_string())))),
        };
        let radius = number("radius", true)?.unwrap_or(0.0);
        let thickness = number("thickness", true)?.unwrap_or(0.0);
        let housing = number("housing-radius", true)?.unwrap_or(0.0);
        if matches!(el.get("thickness"), Some(Value::Array(_))) && !notes.iter().any(|n| n.starts_with("Zoom")) {
            notes.push("Zoom lens: the first (short) zoom position's thicknesses are used.".into());
        }
        for (f, v) in [("radius", radius), ("thickness", thickness), ("housing-radius", housing)] {
            if v.abs() > MAX_LENGTH_MM {
                return Err(err(f, format!("{} mm is implausibly large (limit {} mm)", Num(v), Num(MAX_LENGTH_MM))));
            }
        }
        if housing <= 0.0 {
            return Err(err("housing-radius", format!("must be positive, got {housing}")));
        }
        let m = material.trim().to_ascii_lowercase();
        let is_stop = m == "iris";
        let geometry = match el.get("lens-geometry") {
            None | Some(Value::Null) => "spherical".to_string(),
            Some(Value::String(g)) => g.to_ascii_lowercase(),
            Some(v) => return Err(err("lens-geometry", format!("must be a string, got {}", short(&v.to_string())))),
        };
        let mut spec = SurfaceSpec {
            radius_mm: if radius.abs() >= PLANE_RADIUS || is_stop { 0.0 } else { radius },
            thickness_mm: thickness,
            semi_diameter_mm: housing,
            stop: is_stop,
            ..Default::default()
        };
        match geometry.as_str() {
            "spherical" => {}
            "aspherical" => {
                let coeffs = match el.get("aspherical-equation") {
                    Some(Value::Array(a)) => a
                        .iter()
                        .map(|c| c.as_f64().filter(|c| c.is_finite()))
                        .collect::<Option<Vec<f64>>>()
                        .ok_or_else(|| err("aspherical-equation", "must be a list of numbers".into()))?,
                    None | Some(Value::Null) => Vec::new(),
                    Some(v) => {
                        return Err(err(
                            "aspherical-equation",
                            format!("must be a list, got {}", short(&v.to_string())),
                        ))
                    }
                };
                let mut coeffs = coeffs;
                while coeffs.last() == Some(&0.0) {
                    coeffs.pop();
                }
                spec.aspheric = coeffs;
            }
            // lentil cyl-y: cylinder axis along y, curved along x (see the module docs).
            "cyl-y" if spec.radius_mm != 0.0 => spec.cylinder = Some(CylinderAxis::X),
            "cyl-x" if spec.radius_mm != 0.0 => spec.cylinder = Some(CylinderAxis::Y),
            "cyl-x" | "cyl-y" => {}
            other => {
                return Err(err(
                    "lens-geometry",
                    format!("unknown '{}' (expected spherical, aspherical, cyl-x or cyl-y)", short(other)),
                ))
            }
        }
        if is_stop {
            if !medium_is_air {
                return Err(err("material", "the iris sits inside glass (the medium before it is not air)".into()));
            }
            spec.aspheric.clear();
            spec.cylinder = None;
        } else if m == "air" {
            medium_is_air = true;
        } else {
            let ior = number("ior", false)?;
            let abbe = number("abbe", false)?.filter(|v| *v > 0.0).unwrap_or(0.0);
            let model = |what: &str| -> Result<MaterialSpec> {
                match ior {
                    Some(n) if (1.0..=3.0).contains(&n) => Ok(MaterialSpec::Model(ModelGlass { nd: n, vd: abbe })),
                    Some(n) => Err(err("ior", format!("{n} must be in [1, 3]"))),
                    None => Err(err("ior", format!("{what}: needs `ior` (and `abbe`)"))),
                }
            };
            spec.material = if m == "abbe" {
                model("material \"abbe\"")?
            } else {
                match Material::from_catalog(&material) {
                    Ok(g) => match &g {
                        Material::Catalog { name, .. } => {
                            if let Some(n) = ior {
                                let (nd, _) = g.nd_vd();
                                if (nd - n).abs() > 0.005 {
                                    notes.push(format!(
                                        "Surface {}: catalogue {name} has nd = {nd:.4}, the entry says {n}; the catalogue glass is used.",
                                        i + 1
                                    ));
                                }
                            }
                            MaterialSpec::Name(name.clone())
                        }
                        _ => MaterialSpec::default(),
                    },
                    Err(e) => {
                        let spec = model(&e.to_string()).map_err(|_| {
                            Error::lens_file(
                                file,
                                line,
                                field("material"),
                                format!("{e}, and the entry gives no `ior` to model it"),
                            )
                        })?;
                        if let MaterialSpec::Model(g) = &spec {
                            notes.push(format!(
                                "Surface {}: glass {} is not in our catalogue; modelled from the entry's nd = {}, vd = {}.",
                                i + 1,
                                material,
                                g.nd,
                                g.vd
                            ));
                        }
                        spec
                    }
                }
            };
            medium_is_air = matches!(&spec.material, MaterialSpec::Name(n) if n.eq_ignore_ascii_case("air"))
                || matches!(&spec.material, MaterialSpec::Model(g) if g.nd == 1.0);
        }
        surfaces.push(spec);
        surface_lines.push(line);
    }
    match surfaces.iter().filter(|s| s.stop).count() {
        0 => {
            return Err(Error::lens_file(
                file,
                lines.elements.unwrap_or(entry_line),
                &elements_field,
                "no aperture stop: no surface has material \"iris\"",
            ))
        }
        1 => {}
        _ => {
            let second = surfaces.iter().enumerate().filter(|(_, s)| s.stop).nth(1).map(|(i, _)| i).unwrap_or(0);
            return Err(Error::lens_file(
                file,
                surface_lines.get(second).copied().unwrap_or(entry_line),
                format!("{elements_field}[{second}].material"),
                "a second iris (aperture stop)",
            ));
        }
    }
    // Stop housing: the larger neighbour.
    if let Some(si) = surfaces.iter().position(|s| s.stop) {
        let mut housing = surfaces[si].semi_diameter_mm;
        if si > 0 {
            housing = housing.max(surfaces[si - 1].semi_diameter_mm);
        }
        if si + 1 < surfaces.len() {
            housing = housing.max(surfaces[si + 1].semi_diameter_mm);
        }
        surfaces[si].housing_semi_diameter_mm = Some(housing);
    }

    // Metadata.
    let s = |k: &str| entry.get(k).and_then(|v| v.as_str()).map(str::trim).filter(|v| !v.is_empty());
    let f = |k: &str| entry.get(k).and_then(|v| v.as_f64()).filter(|v| v.is_finite() && *v > 0.0);
    let unscaled = |k: &str| {
        entry.get(k).and_then(|v| v.get("unscaled")).and_then(|v| v.as_f64()).filter(|v| v.is_finite() && *v > 0.0)
    };
    let year = entry.get("year").and_then(|v| v.as_i64());
    let company = s("company").filter(|c| !matches!(*c, "unknown" | "unsure" | "test"));
    let product = s("product-name").filter(|c| *c != "unknown");
    let focal = f("focal-length-mm-patent");
    let mut cite = Vec::new();
    match (s("patent-number"), year) {
        (Some(pn), Some(y)) => cite.push(format!("patent {pn} ({y})")),
        (Some(pn), None) => cite.push(format!("patent {pn}")),
        (None, Some(y)) => cite.push(format!("no patent number given (year {y} per the database)")),
        (None, None) => {}
    }
    let maker = [company, product].iter().flatten().copied().collect::<Vec<_>>().join(" ");
    if !maker.is_empty() {
        cite.push(maker);
    }
    if let Some(loc) = s("patent-location").filter(|l| l.starts_with("http")) {
        cite.push(loc.to_string());
    }
    cite.push(format!("via the lentil lens database (MIT, (c) 2023 Zeno Pelgrims), entry {id}"));
    let name = {
        let mut parts: Vec<String> = Vec::new();
        if let Some(c) = company {
            parts.push(c.to_string());
        }
        parts.push(product.unwrap_or("lens").to_string());
        if let Some(fl) = focal {
            parts.push(format!("{}mm", fl.round()));
        }
        kebab(&parts.join("-"))
    };
    let mut all_notes = Vec::new();
    if let Some(n) = s("notes") {
        all_notes.push(n.to_string());
    }
    all_notes.extend(notes);
    let mut p = Prescription {
        lens: LensMeta { name, source: cite.join("; "), focal_length_mm: focal, ..Default::default() },
        aperture: Default::default(),
        surfaces,
    };
    let fit = fit_semi_diameters(&mut p);
    all_notes.extend(fit);

    // f-number and stop opening from the entry, when they fit and agree with the optics.
    if let (Some(fstop), Some(radius)) = (unscaled("fstop"), unscaled("max-fstop-aperture-radius")) {
        let stop_sd = p.surfaces.iter().find(|s| s.stop).map(|s| s.semi_diameter_mm);
        if let Some(sd) = stop_sd {
            if radius <= sd {
                let mut trial = p.clone();
                trial.lens.stop_semi_diameter_mm = Some(radius);
                let map = SourceMap::new(file, surface_lines.clone());
                // When the lens does not build, validation reports why later; keep the data.
                if let Ok(lens) = Lens::new(trial, &map, None) {
                    let ours = lens.paraxial().f_number.abs();
                    if (ours - fstop).abs() <= 0.05 * fstop {
                        p.lens.f_number = Some(fstop);
                        p.lens.stop_semi_diameter_mm = Some(radius);
                    } else {
                        all_notes.push(format!(
                            "The entry's f/{fstop:.3} at iris radius {radius:.3} mm does not match the paraxial f/{ours:.3}; not used."
                        ));
                    }
                }
            } else {
                all_notes.push(format!(
                    "The entry's max-fstop-aperture-radius {radius:.3} mm exceeds the iris ({sd} mm); not used."
                ));
            }
        }
    }
    p.lens.notes = join_sentences(&all_notes);
    Ok((p, SourceMap::new(file, surface_lines)))
}

/// "Angenieux Double-Gauss 100mm" → "angenieux-double-gauss-100mm".
fn kebab(s: &str) -> String {
    let mut out = String::new();
    for c in s.chars() {
        if c.is_ascii_alphanumeric() {
            out.push(c.to_ascii_lowercase());
        } else if !out.ends_with('-') && !out.is_empty() {
            out.push('-');
        }
    }
    out.trim_end_matches('-').to_string()
}

/// Lines of an entry, its surface list and each surface object.
#[derive(Debug, Default)]
struct EntryLines {
    entry: Option<usize>,
    elements: Option<usize>,
    surfaces: Vec<usize>,
}

/// Finds the lines of entry `id`, its `optical-elements-patent` list and that list's objects,
/// by scanning the text: strings (with escapes) are skipped, nesting is tracked, and the key
/// before each `:` is remembered. Malformed text only yields fewer lines.
fn scan_lines(text: &str, id: &str) -> EntryLines {
    #[derive(Clone)]
    struct Frame {
        is_object: bool,
        key: Option<String>,
    }
    let mut out = EntryLines::default();
    let mut stack: Vec<Frame> = Vec::new();
    let mut line = 1;
    let mut chars = text.chars().peekable();
    let mut last_string: Option<String> = None;
    // Path markers: depth of the entry object and of the elements array, when inside them.
    let mut entry_depth: Option<usize> = None;
    let mut elements_depth: Option<usize> = None;
    while let Some(c) = chars.next() {
        match c {
            '\n' => line += 1,
            '"' => {
                let mut s = String::new();
                while let Some(d) = chars.next() {
                    match d {
                        '\\' => {
                            if let Some(e) = chars.next() {
                                if e == '\n' {
                                    line += 1;
                                }
                                s.push(e);
                            }
                        }
                        '"' => break,
                        '\n' => {
                            line += 1;
                            s.push(d);
                        }
                        _ => s.push(d),
                    }
                }
                last_string = Some(s);
            }
            ':' => {
                if let Some(top) = stack.last_mut() {
                    if top.is_object {
                        top.key = last_string.take();
                    }
                }
            }
            ',' => {
                last_string = None;
                if let Some(top) = stack.last_mut() {
                    if top.is_object {
                        top.key = None;
                    }
                }
            }
            '{' | '[' => {
                let depth = stack.len();
                let parent_key = stack.last().and_then(|f| if f.is_object { f.key.clone() } else { None });
                if c == '{' && depth == 1 && parent_key.as_deref() == Some(id) && out.entry.is_none() {
                    out.entry = Some(line);
                    entry_depth = Some(depth + 1);
                } else if c == '['
                    && entry_depth == Some(depth)
                    && parent_key.as_deref() == Some("optical-elements-patent")
                {
                    out.elements = Some(line);
                    elements_depth = Some(depth + 1);
                } else if c == '{' && elements_depth == Some(depth) {
                    out.surfaces.push(line);
                }
                stack.push(Frame { is_object: c == '{', key: None });
                last_string = None;
            }
            '}' | ']' => {
                stack.pop();
                let depth = stack.len();
                if elements_depth == Some(depth + 1) {
                    elements_depth = None;
                }
                if entry_depth == Some(depth + 1) {
                    entry_depth = None;
                }
            }
            _ => {}
        }
    }
    out
}
