//! Zemax OpticStudio sequential `.zmx` files.
//!
//! The file is ASCII/UTF-8 or UTF-16 (little- or big-endian, with a byte-order mark, or
//! without one when every other byte is zero); the encoding is detected from the bytes.
//! Lines keep their numbers through decoding, so errors name the line in the original file.
//!
//! Keywords read (everything else is ignored):
//!
//! | keyword | meaning | our field |
//! |---|---|---|
//! | `MODE SEQ` | sequential (anything else is refused) | — |
//! | `NAME`, `NOTE`, `COMM` | lens title, notes, surface comments | `lens.name` / `notes` |
//! | `UNIT MM\|CM\|IN\|METER` | lens unit; every length is converted to mm | — |
//! | `FNUM f` | image-space f-number | `lens.f_number` |
//! | `WAVM i λ`, `PWAV i` | wavelengths (µm) and the primary one | `lens.wavelengths_nm`, `primary_wavelength_nm` |
//! | `SURF n` | starts surface n; 0 = object, the last = image | one `[[surface]]` per lens surface |
//! | `TYPE STANDARD\|EVENASPH\|ODDASPHE\|TOROIDAL` | surface type (others are refused; a TOROIDAL surface only as a cylinder, below) | — |
//! | `CURV c` | curvature 1/length (0 = plane) | `radius_mm = 1/c` |
//! | `DISZ t` | thickness to the next surface (`INFINITY` on the object) | `thickness_mm` |
//! | `GLAS name ...` | medium after the surface: a catalogue name, or `MODEL`/`___BLANK` with nd and vd in fields 4 and 5 | `material` |
//! | `DIAM sd` | semi-diameter | `semi_diameter_mm` |
//! | `CLAP rmin rmax` | circular aperture: rmax is the clear semi-diameter when given | `semi_diameter_mm` |
//! | `CONI k` | conic constant | `conic` |
//! | `PARM k v` (EVENASPH) | coefficient of r^(2k): PARM 2 = A4, PARM 3 = A6, ... | `aspheric` |
//! | `PARM k v` (ODDASPHE) | coefficient of r^k, k = 1..8: odd k → B_k, PARM 2 → r², even k ≥ 4 → A_k | `aspheric_odd`, `aspheric_r2`, `aspheric` |
//! | `PARM 1 R` (TOROIDAL) | radius of rotation (0 = infinite) | `cylinder` |
//! | `PARM k v` (TOROIDAL, k ≥ 2) | coefficient of y^(2(k−1)) on the YZ profile: PARM 2 = y², PARM 3 = y⁴, ... | `aspheric_r2`, `aspheric` |
//! | `STOP` | this surface is the stop (default: surface 1, as in Zemax) | `stop` |
//!
//! Conversions and choices:
//! - The last lens surface's `DISZ` is its distance to the image surface.
//! - `PARM 1` of an EVENASPH surface (the r² term) becomes `aspheric_r2`.
//! - A TOROIDAL surface is read as a cylinder: with `PARM 1` = 0 (an infinite radius of
//!   rotation) its YZ profile (CURV, CONI, PARM 2...) is extruded along x (`cylinder = "y"`,
//!   curved along y); with a flat profile (CURV 0, no conic or PARM terms) and `PARM 1` = R it is
//!   a cylinder of radius R curved along x (`cylinder = "x"`). A toroid curved both ways is
//!   refused.
//! - A glass name not in our catalogue falls back to the file's own nd/vd (fields 4 and 5 of
//!   the `GLAS` line) as a model glass, with a note; without usable nd it is an error.
//! - A semi-diameter beyond the rim of a sphere or conic (|R| / √(1 + k), e.g. an estimate
//!   from paraxial ray heights at a 160° field) is set to the rim, with a note: no ray can meet
//!   the surface farther out anyway.
//! - The image surface must lie behind the last lens surface: a negative last `DISZ` (an image
//!   inside the lens, as in optiland's Microscope20x) is refused
//!   at that line. Image space may be glass or another medium (an eye's vitreous).
//! - A surface with `DIAM 0` (or none) takes the larger semi-diameter of its nearest
//!   neighbours that have one, with a note.
//! - The stop is the Zemax stop surface itself, curved or not and with glass around it or not,
//!   as in Zemax: the tracer clips by the opening where the ray meets that surface, then refracts.
//! - Neighbouring surfaces whose edges cross inside their common aperture (a DIAM past the
//!   real beam, as optiland writes for a 170° lens) are cut back to the height where they meet,
//!   rounded down to 1 µm, with a note, as for pbrt tables; a cut below half the semi-diameter
//!   is not made (the thickness is then more likely wrong than the DIAM) and validation reports
//!   the crossing at the `DISZ` line.

use super::pbrt::{fit_semi_diameters, join_sentences, short, MAX_LENGTH_MM};
use crate::error::{Error, Result};
use crate::glass::Material;
use crate::prescription::{
    CylinderAxis, LensMeta, MaterialSpec, ModelGlass, Num, Prescription, SourceMap, SurfaceSpec,
};

/// Whether a surface has aspheric terms (r², even or odd).
fn spec_has_polynomial(s: &SurfaceSpec) -> bool {
    s.aspheric_r2 != 0.0 || s.aspheric.iter().chain(&s.aspheric_odd).any(|a| *a != 0.0)
}

/// One SURF block as read.
#[derive(Debug, Default, Clone)]
struct ZSurf {
    /// Line of `SURF n`.
    line: usize,
    number: usize,
    ty: Option<(usize, String)>,
    curv: f64,
    disz: Option<f64>,
    disz_infinite: bool,
    glass: Option<(usize, GlassRef)>,
    diam: Option<f64>,
    clap: Option<f64>,
    conic: f64,
    parms: Vec<(usize, usize, f64)>,
    stop: bool,
    comment: String,
    /// The line of each geometry keyword read (CURV, DISZ, DIAM, CLAP, CONI), for errors.
    key_lines: Vec<(&'static str, usize)>,
}

#[derive(Debug, Clone)]
enum GlassRef {
    Model { nd: f64, vd: f64 },
    Named { name: String, nd: Option<f64>, vd: Option<f64> },
}

/// The largest semi-diameter at which a sphere or conic (with any polynomial terms) exists, a hair
/// inside its rim so the sag stays defined: |R| / √(1 + k) when 1 + k > 0, else none.
fn conic_rim_mm(radius_mm: f64, conic: f64) -> Option<f64> {
    let k1 = 1.0 + conic;
    (radius_mm != 0.0 && k1 > 0.0).then(|| radius_mm.abs() / k1.sqrt() * (1.0 - 1e-9))
}

/// The image surface must lie behind the last lens surface (DISZ ≥ 0), where a sensor can be.
fn check_image_behind_lens(file: &str, last: &ZSurf) -> Result<()> {
    if let Some(d) = last.disz.filter(|d| d.is_finite() && *d < 0.0) {
        let line = last.key_lines.iter().rev().find(|(k, _)| *k == "DISZ").map_or(last.line, |(_, l)| *l);
        return Err(Error::lens_file(
            file,
            line,
            "DISZ",
            format!(
                "the image surface is {} mm in front of the last lens surface (SURF {} DISZ < 0): petzval needs the image behind the lens, where the sensor goes",
                Num(-d),
                last.number
            ),
        ));
    }
    Ok(())
}

/// The stop's housing: the larger semi-diameter of the stop and its neighbours.
fn set_stop_housing(specs: &mut [SurfaceSpec]) {
    if let Some(si) = specs.iter().position(|s| s.stop) {
        let mut housing = specs[si].semi_diameter_mm;
        if si > 0 {
            housing = housing.max(specs[si - 1].semi_diameter_mm);
        }
        if si + 1 < specs.len() {
            housing = housing.max(specs[si + 1].semi_diameter_mm);
        }
        specs[si].housing_semi_diameter_mm = Some(housing);
    }
}

/// Imports a Zemax sequential file from its raw bytes. `file` names the file in errors.
pub fn import_zemax(bytes: &[u8], file: &str) -> Result<(Prescription, SourceMap)> {
    let text = super::decode_text(bytes);
    let mut unit_mm = 1.0;
    let mut name = String::new();
    let mut notes_in_file: Vec<String> = Vec::new();
    let mut f_number = None;
    let mut waves: Vec<(usize, f64)> = Vec::new();
    let mut primary_wave: Option<usize> = None;
    let mut surfs: Vec<ZSurf> = Vec::new();

    let num = |tok: Option<&&str>, line: usize, field: &str| -> Result<f64> {
        let t = tok.ok_or_else(|| Error::lens_file(file, line, field, "missing value"))?;
        let v: f64 = t
            .replace(',', ".")
            .parse()
            .map_err(|_| Error::lens_file(file, line, field, format!("'{}' is not a number", short(t))))?;
        if !v.is_finite() {
            return Err(Error::lens_file(file, line, field, format!("must be a finite number, got {t}")));
        }
        Ok(v)
    };
    let length = |v: f64, line: usize, field: &str, unit_mm: f64| -> Result<f64> {
        let mm = v * unit_mm;
        if !mm.is_finite() || mm.abs() > MAX_LENGTH_MM {
            return Err(Error::lens_file(
                file,
                line,
                field,
                format!("{} is implausibly large (limit {} mm)", Num(v), Num(MAX_LENGTH_MM)),
            ));
        }
        Ok(mm)
    };

    for (i, raw) in text.split('\n').enumerate() {
        let line = i + 1;
        let raw = raw.trim_end_matches('\r');
        let tokens: Vec<&str> = raw.split_whitespace().collect();
        let Some(&key) = tokens.first() else { continue };
        let key = key.trim_start_matches('\u{feff}');
        let rest_text = raw.trim_start().get(key.len()..).unwrap_or("").trim();
        match key {
            "MODE" => {
                if tokens.get(1).map(|m| !m.eq_ignore_ascii_case("SEQ")).unwrap_or(false) {
                    return Err(Error::lens_file(file, line, "MODE", "only sequential (MODE SEQ) files are supported"));
                }
            }
            "NAME" if surfs.is_empty() => name = rest_text.to_string(),
            "NOTE" if surfs.is_empty() => {
                // "NOTE 0 text": the first field is an index.
                let t = rest_text.split_once(char::is_whitespace).map(|(_, t)| t.trim()).unwrap_or("");
                if !t.is_empty() {
                    notes_in_file.push(t.to_string());
                }
            }
            "UNIT" if surfs.is_empty() => {
                let u = tokens.get(1).copied().unwrap_or("").to_ascii_uppercase();
                unit_mm = match u.as_str() {
                    "MM" => 1.0,
                    "CM" => 10.0,
                    "IN" | "INCH" | "INCHES" => 25.4,
                    "M" | "METER" | "METERS" | "METE" | "METRE" => 1000.0,
                    _ => {
                        return Err(Error::lens_file(
                            file,
                            line,
                            "UNIT",
                            format!("unknown lens unit '{}' (expected MM, CM, IN or METER)", short(&u)),
                        ))
                    }
                };
            }
            "FNUM" if surfs.is_empty() => {
                let v = num(tokens.get(1), line, "FNUM")?;
                if v > 0.0 {
                    f_number = Some(v);
                }
            }
            "WAVM" | "WAVL" if surfs.is_empty() => {
                if key == "WAVL" {
                    // Old files: "WAVL w1 w2 w3 ..." in µm.
                    for t in &tokens[1..] {
                        waves.push((waves.len() + 1, num(Some(t), line, "WAVL")?));
                    }
                } else {
                    let k = num(tokens.get(1), line, "WAVM")?;
                    let w = num(tokens.get(2), line, "WAVM")?;
                    waves.push((k as usize, w));
                }
            }
            "PWAV" if surfs.is_empty() => {
                primary_wave = Some(num(tokens.get(1), line, "PWAV")? as usize);
            }
            "SURF" => {
                let n = num(tokens.get(1), line, "SURF")?;
                if n < 0.0 || n.fract() != 0.0 {
                    return Err(Error::lens_file(
                        file,
                        line,
                        "SURF",
                        format!("surface number must be a whole number, got {n}"),
                    ));
                }
                surfs.push(ZSurf { line, number: n as usize, ..Default::default() });
            }
            _ => {
                let Some(s) = surfs.last_mut() else { continue };
                if let Some(k) = ["CURV", "DISZ", "DIAM", "CLAP", "CONI"].into_iter().find(|k| *k == key) {
                    s.key_lines.push((k, line));
                }
                match key {
                    "TYPE" => s.ty = Some((line, tokens.get(1).copied().unwrap_or("").to_string())),
                    "CURV" => s.curv = num(tokens.get(1), line, "CURV")? / unit_mm,
                    "DISZ" => {
                        if tokens.get(1).map(|t| t.eq_ignore_ascii_case("INFINITY")).unwrap_or(false) {
                            s.disz_infinite = true;
                            s.disz = Some(f64::INFINITY);
                        } else {
                            let v = num(tokens.get(1), line, "DISZ")?;
                            if s.number != 0 {
                                s.disz = Some(length(v, line, "DISZ", unit_mm)?);
                            } else {
                                s.disz = Some(v * unit_mm);
                            }
                        }
                    }
                    "GLAS" => {
                        let gname = tokens.get(1).copied().unwrap_or("");
                        if gname.is_empty() {
                            return Err(Error::lens_file(file, line, "GLAS", "missing glass name"));
                        }
                        let nd = tokens
                            .get(4)
                            .and_then(|t| t.replace(',', ".").parse::<f64>().ok())
                            .filter(|v| v.is_finite());
                        let vd = tokens
                            .get(5)
                            .and_then(|t| t.replace(',', ".").parse::<f64>().ok())
                            .filter(|v| v.is_finite());
                        let g = if gname.eq_ignore_ascii_case("MIRROR") {
                            return Err(Error::lens_file(
                                file,
                                line,
                                "GLAS",
                                "mirrors are not supported (refracting lenses only)",
                            ));
                        } else if gname.eq_ignore_ascii_case("MODEL") || gname.eq_ignore_ascii_case("___BLANK") {
                            let nd = num(tokens.get(4), line, "GLAS")?;
                            let vd = num(tokens.get(5), line, "GLAS")?;
                            GlassRef::Model { nd, vd }
                        } else {
                            GlassRef::Named { name: gname.to_string(), nd, vd }
                        };
                        s.glass = Some((line, g));
                    }
                    "DIAM" => s.diam = Some(length(num(tokens.get(1), line, "DIAM")?, line, "DIAM", unit_mm)?),
                    "CLAP" => s.clap = Some(length(num(tokens.get(2), line, "CLAP")?, line, "CLAP", unit_mm)?),
                    "CONI" => s.conic = num(tokens.get(1), line, "CONI")?,
                    "PARM" => {
                        let k = num(tokens.get(1), line, "PARM")?;
                        let v = num(tokens.get(2), line, "PARM")?;
                        if (1.0..=64.0).contains(&k) && k.fract() == 0.0 {
                            s.parms.push((line, k as usize, v));
                        }
                    }
                    "STOP" => s.stop = true,
                    "COMM" => s.comment = rest_text.to_string(),
                    _ => {}
                }
            }
        }
    }

    if surfs.is_empty() {
        return Err(Error::lens_file(file, 0, "SURF", "not a Zemax lens file: no SURF lines"));
    }
    if surfs.len() < 3 {
        return Err(Error::lens_file(
            file,
            surfs[surfs.len() - 1].line,
            "SURF",
            "a lens needs an object surface, at least one lens surface and an image surface",
        ));
    }
    // Object surface: must be in air.
    if let Some((gl, g)) = &surfs[0].glass {
        let air = match g {
            GlassRef::Named { name, .. } => name.eq_ignore_ascii_case("AIR"),
            GlassRef::Model { nd, .. } => *nd == 1.0,
        };
        if !air {
            return Err(Error::lens_file(file, *gl, "GLAS", "object space must be air"));
        }
    }
    let lens_surfs = &surfs[1..surfs.len() - 1];
    check_image_behind_lens(file, &lens_surfs[lens_surfs.len() - 1])?;
    let mut notes: Vec<String> = Vec::new();
    // What a camera lens file does not carry, named rather than dropped in silence: the render
    // focuses with --focus, and the sensor is flat.
    if let Some(d) = surfs[0].disz.filter(|d| d.is_finite()) {
        notes.push(format!(
            "The file's object distance (SURF 0 DISZ {d} mm) is not kept: petzval focuses where the render asks (--focus)."
        ));
    }
    let image = &surfs[surfs.len() - 1];
    if image.curv.abs() > 1e-10 {
        notes.push(format!(
            "The image surface's curvature (SURF {} CURV, radius {:.4} mm) is not kept: the sensor is flat.",
            image.number,
            1.0 / image.curv
        ));
    }

    // Semi-diameters: CLAP max, else DIAM, else from the neighbours.
    let given: Vec<Option<f64>> = lens_surfs.iter().map(|s| s.clap.or(s.diam).filter(|&d| d > 0.0)).collect();
    if given.iter().all(|g| g.is_none()) {
        return Err(Error::lens_file(
            file,
            lens_surfs[0].line,
            "DIAM",
            "no surface has a semi-diameter (DIAM); cannot size the lens",
        ));
    }
    let mut semi = Vec::with_capacity(lens_surfs.len());
    for (k, g) in given.iter().enumerate() {
        match g {
            Some(d) => semi.push(*d),
            None => {
                let prev = given[..k].iter().rev().flatten().next().copied();
                let next = given[k + 1..].iter().flatten().next().copied();
                let d = prev.unwrap_or(0.0).max(next.unwrap_or(0.0));
                notes.push(format!(
                    "SURF {} has no semi-diameter (DIAM 0): set to {d} mm, the larger of its neighbours'.",
                    lens_surfs[k].number
                ));
                semi.push(d);
            }
        }
    }

    // Stop: the STOP surface, or surface 1 as in Zemax.
    let stop_positions: Vec<usize> = lens_surfs.iter().enumerate().filter(|(_, s)| s.stop).map(|(k, _)| k).collect();
    if surfs[0].stop {
        return Err(Error::lens_file(file, surfs[0].line, "STOP", "the object surface cannot be the stop"));
    }
    if surfs[surfs.len() - 1].stop {
        return Err(Error::lens_file(
            file,
            surfs[surfs.len() - 1].line,
            "STOP",
            "the image surface cannot be the stop",
        ));
    }
    if stop_positions.len() > 1 {
        return Err(Error::lens_file(file, lens_surfs[stop_positions[1]].line, "STOP", "more than one STOP surface"));
    }
    let stop_k = stop_positions.first().copied().unwrap_or(0);
    if stop_positions.is_empty() {
        notes.push(format!("No STOP in the file: surface {} is the stop (the Zemax default).", lens_surfs[0].number));
    }

    // Surfaces.
    let mut specs: Vec<SurfaceSpec> = Vec::with_capacity(lens_surfs.len() + 1);
    let mut lines: Vec<usize> = Vec::with_capacity(lens_surfs.len() + 1);
    let mut keywords: Vec<Vec<(String, usize, String)>> = Vec::with_capacity(lens_surfs.len());
    for (k, s) in lens_surfs.iter().enumerate() {
        // our fields' own lines: the keywords that set them
        let key_line = |kw: &str| s.key_lines.iter().rev().find(|(k, _)| *k == kw).map(|(_, l)| *l);
        let mut fields = Vec::new();
        for (field, kw) in [("thickness_mm", "DISZ"), ("radius_mm", "CURV"), ("conic", "CONI")] {
            if let Some(l) = key_line(kw) {
                fields.push((field.to_string(), l, kw.to_string()));
            }
        }
        let semi_kw = if s.clap.is_some() { "CLAP" } else { "DIAM" };
        if let Some(l) = key_line(semi_kw) {
            fields.push(("semi_diameter_mm".to_string(), l, semi_kw.to_string()));
        }
        if let Some((l, _)) = &s.glass {
            fields.push(("material".to_string(), *l, "GLAS".to_string()));
        }
        keywords.push(fields);
        let thickness = match s.disz {
            Some(t) if t.is_finite() => t,
            Some(_) => return Err(Error::lens_file(file, s.line, "DISZ", "a lens surface cannot be INFINITY thick")),
            None => return Err(Error::lens_file(file, s.line, "DISZ", "missing field DISZ (thickness)")),
        };
        let mut spec = SurfaceSpec {
            radius_mm: if s.curv == 0.0 { 0.0 } else { 1.0 / s.curv },
            thickness_mm: thickness,
            semi_diameter_mm: semi[k],
            conic: s.conic,
            ..Default::default()
        };
        if spec.radius_mm.abs() > MAX_LENGTH_MM * 1e3 {
            spec.radius_mm = 0.0; // |CURV| below 1e-10 /mm: a plane
        }
        let ty = s.ty.as_ref().map(|(l, t)| (*l, t.to_ascii_uppercase())).unwrap_or((s.line, "STANDARD".into()));
        match ty.1.as_str() {
            "STANDARD" => {}
            "EVENASPH" => {
                let mut coeffs: Vec<f64> = Vec::new();
                for &(_, pk, v) in &s.parms {
                    if pk == 1 {
                        // α r² in file units → mm: α · u^(−1).
                        spec.aspheric_r2 = v / unit_mm;
                        continue;
                    }
                    if pk > 8 {
                        continue; // EVENASPH has 8 terms (r² … r¹⁶); PARM 9+ are not coefficients
                    }
                    let idx = pk - 2;
                    if coeffs.len() <= idx {
                        coeffs.resize(idx + 1, 0.0);
                    }
                    // α r^(2k) in file units → mm: α · u^(1 − 2k).
                    coeffs[idx] = v * unit_mm.powi(1 - 2 * pk as i32);
                }
                while coeffs.last() == Some(&0.0) {
                    coeffs.pop();
                }
                spec.aspheric = coeffs;
            }
            "ODDASPHE" => {
                let (mut even, mut odd): (Vec<f64>, Vec<f64>) = (Vec::new(), Vec::new());
                for &(_, pk, v) in &s.parms {
                    if !(1..=8).contains(&pk) {
                        continue; // ODDASPHE has 8 terms, β1 r … β8 r⁸
                    }
                    // β r^k in file units → mm: β · u^(1 − k).
                    let b = v * unit_mm.powi(1 - pk as i32);
                    let (list, idx) = match pk {
                        2 => {
                            spec.aspheric_r2 = b;
                            continue;
                        }
                        k if k % 2 == 1 => (&mut odd, (k - 1) / 2),
                        k => (&mut even, (k - 4) / 2),
                    };
                    if list.len() <= idx {
                        list.resize(idx + 1, 0.0);
                    }
                    list[idx] = b;
                }
                for list in [&mut even, &mut odd] {
                    while list.last() == Some(&0.0) {
                        list.pop();
                    }
                }
                spec.aspheric = even;
                spec.aspheric_odd = odd;
            }
            "TOROIDAL" => {
                let mut rotation_mm = 0.0;
                let mut coeffs: Vec<f64> = Vec::new();
                for &(_, pk, v) in &s.parms {
                    match pk {
                        1 => rotation_mm = v * unit_mm,
                        // α y^(2(k−1)) in file units → mm: α · u^(3 − 2k)
                        2 => spec.aspheric_r2 = v / unit_mm,
                        3..=9 => {
                            let idx = pk - 3;
                            if coeffs.len() <= idx {
                                coeffs.resize(idx + 1, 0.0);
                            }
                            coeffs[idx] = v * unit_mm.powi(3 - 2 * pk as i32);
                        }
                        _ => {}
                    }
                }
                while coeffs.last() == Some(&0.0) {
                    coeffs.pop();
                }
                spec.aspheric = coeffs;
                let flat_profile = spec.radius_mm == 0.0 && spec.conic == 0.0 && !spec_has_polynomial(&spec);
                if rotation_mm == 0.0 || !rotation_mm.is_finite() || rotation_mm.abs() > MAX_LENGTH_MM * 1e3 {
                    // infinite radius of rotation: the YZ profile extruded along x
                    spec.cylinder = Some(CylinderAxis::Y);
                } else if flat_profile {
                    // a straight profile rotated about an axis R away: a cylinder curved along x
                    spec.radius_mm = rotation_mm;
                    spec.cylinder = Some(CylinderAxis::X);
                } else {
                    let line = s.parms.iter().find(|p| p.1 == 1).map_or(ty.0, |p| p.0);
                    return Err(Error::lens_file(
                        file,
                        line,
                        "PARM 1",
                        format!(
                            "a toroid (radius of rotation {rotation_mm} mm with a curved YZ profile) is not supported; cylinders are (PARM 1 = 0, or a flat profile with PARM 1 = R)"
                        ),
                    ));
                }
            }
            other => {
                return Err(Error::lens_file(
                    file,
                    ty.0,
                    "TYPE",
                    format!(
                        "surface type {} is not supported (STANDARD, EVENASPH, ODDASPHE and cylindrical TOROIDAL are)",
                        short(other)
                    ),
                ))
            }
        }
        // A semi-diameter past the edge of a sphere or conic (an estimate from paraxial ray
        // heights at a very wide field, e.g. optiland's DIAM): the surface ends at its rim.
        if let Some(rim) = conic_rim_mm(spec.radius_mm, spec.conic).filter(|rim| spec.semi_diameter_mm > *rim) {
            notes.push(format!(
                "SURF {}: semi-diameter {:.4} mm is beyond the surface's rim (radius {:.4} mm, conic {}): set to {:.6} mm.",
                s.number,
                spec.semi_diameter_mm,
                spec.radius_mm,
                spec.conic,
                rim
            ));
            spec.semi_diameter_mm = rim;
        }
        // Glass.
        if let Some((gl, g)) = &s.glass {
            spec.material = match g {
                GlassRef::Model { nd, vd } => {
                    if !((1.0..=3.0).contains(nd) && *vd >= 0.0) {
                        return Err(Error::lens_file(
                            file,
                            *gl,
                            "GLAS",
                            format!(
                                "model glass nd = {nd}, vd = {vd} is outside nd in [1, 3], vd ≥ 0 (infrared materials such as germanium are not supported)"
                            ),
                        ));
                    }
                    MaterialSpec::Model(ModelGlass { nd: *nd, vd: *vd })
                }
                GlassRef::Named { name, nd, vd } => match Material::from_catalog(name) {
                    Ok(Material::Catalog { name: cat_name, .. }) => MaterialSpec::Name(cat_name),
                    Ok(_) => MaterialSpec::default(),
                    Err(e) => match (nd, vd) {
                        (Some(nd), vd) if *nd > 1.0 && *nd <= 3.0 => {
                            let vd = vd.filter(|v| *v > 0.0).unwrap_or(0.0);
                            notes.push(format!(
                                "SURF {}: glass {name} is not in our catalogue; modelled from the file's nd = {nd}, vd = {vd}.",
                                s.number
                            ));
                            MaterialSpec::Model(ModelGlass { nd: *nd, vd })
                        }
                        _ => return Err(Error::lens_file(file, *gl, "GLAS", e.to_string())),
                    },
                },
            };
        }
        if !s.comment.is_empty() {
            notes.push(format!("SURF {}: {}", s.number, s.comment));
        }
        if k == stop_k {
            // The stop is this surface itself, curved or not, with whatever media around it
            // (as in Zemax): the tracer clips by the opening where the ray meets it, then refracts.
            if spec.radius_mm == 0.0 && !spec_has_polynomial(&spec) {
                spec.conic = 0.0; // a conic constant means nothing on a plane
            }
            spec.stop = true;
            specs.push(spec);
            lines.push(s.line);
        } else {
            specs.push(spec);
            lines.push(s.line);
        }
    }

    // Wavelengths in range only (our renderer covers 380..780 nm).
    let nm: Vec<f64> = waves.iter().map(|(_, w)| w * 1000.0).collect();
    let in_range = |w: &f64| (380.0..=780.0).contains(w);
    let wavelengths_nm = (!nm.is_empty() && nm.iter().all(in_range)).then(|| nm.clone());
    if !nm.is_empty() && wavelengths_nm.is_none() {
        notes.push(format!("The file's wavelengths {nm:?} nm are outside 380..780 nm; defaults used."));
    }
    let primary_wavelength_nm =
        primary_wave.and_then(|k| waves.iter().find(|(i, _)| *i == k)).map(|(_, w)| w * 1000.0).filter(in_range);

    let stem = std::path::Path::new(file).file_stem().and_then(|s| s.to_str()).unwrap_or("lens").to_string();
    let title = if name.is_empty() { stem } else { name.clone() };
    let mut source = format!(
        "Zemax OpticStudio file {}",
        std::path::Path::new(file).file_name().and_then(|s| s.to_str()).unwrap_or(file)
    );
    if !name.is_empty() {
        source.push_str(&format!(" ({name})"));
    }
    let mut p = Prescription {
        lens: LensMeta {
            name: title,
            source,
            notes: String::new(),
            focal_length_mm: None,
            f_number,
            wavelengths_nm,
            primary_wavelength_nm,
            stop_semi_diameter_mm: None,
        },
        aperture: Default::default(),
        surfaces: specs,
    };
    // Neighbouring edges that cross (DIAM past the real beam): cut back to where they meet.
    notes.extend(fit_semi_diameters(&mut p));
    set_stop_housing(&mut p.surfaces);
    let mut all_notes = notes_in_file;
    all_notes.extend(notes);
    p.lens.notes = join_sentences(&all_notes);
    Ok((p, SourceMap::new(file, lines).with_field_keywords(keywords)))
}
