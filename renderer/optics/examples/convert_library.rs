//! Converts the shared lens data (pbrt tables and lentil database entries) into the embedded
//! lens library (`renderer/optics/lenses/*.toml`), validates every lens and prints a table of design
//! versus paraxial focal lengths.
//!
//! ```text
//! cargo run -p petzval-optics --example convert_library -- /work/shared/lenses renderer/optics/lenses
//! ```
//!
//! The first argument is the shared data directory (with `pbrt/*.dat` and
//! `lentil-lenses.json`), the second the output directory. Library-specific choices (names,
//! the one rescaled entry) live in [`JOBS`] below; everything else is the importers'.
//! With `--check`, nothing is written: the existing files are compared with what would be
//! written, and the exit status says whether they are up to date.

use petzval_optics::import::{import_lentil, import_pbrt};
use petzval_optics::prescription::{to_toml, Prescription};
use petzval_optics::Lens;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Where a library lens comes from.
enum From {
    /// A pbrt table under `pbrt/`.
    Pbrt(&'static str),
    /// A lentil database entry id.
    Lentil(&'static str),
}

/// One library lens.
struct Job {
    name: &'static str,
    from: From,
    /// Rescale so the paraxial EFL is this (only where the entry says its data are not at
    /// the stated scale).
    scale_to_efl_mm: Option<f64>,
    /// Drop the entry's design focal length (it contradicts the entry's own data; `note` says
    /// why).
    drop_design_focal: bool,
    /// Added at the front of `notes`.
    note: &'static str,
}

const JOBS: &[Job] = &[
    Job { name: "double-gauss-50mm", from: From::Pbrt("dgauss.50mm.dat"), scale_to_efl_mm: None, drop_design_focal: false, note: "" },
    Job { name: "wide-22mm", from: From::Pbrt("wide.22mm.dat"), scale_to_efl_mm: None, drop_design_focal: false, note: "" },
    Job { name: "fisheye-10mm", from: From::Pbrt("fisheye.10mm.dat"), scale_to_efl_mm: None, drop_design_focal: false, note: "" },
    Job { name: "telephoto-250mm", from: From::Pbrt("telephoto.250mm.dat"), scale_to_efl_mm: None, drop_design_focal: false, note: "" },
    Job { name: "angenieux-double-gauss-100mm", from: From::Lentil("0001"), scale_to_efl_mm: None, drop_design_focal: false, note: "" },
    Job {
        name: "petzval-portrait-100mm",
        from: From::Lentil("0003"),
        scale_to_efl_mm: Some(100.0),
        drop_design_focal: false,
        note: "The entry's data are not at its stated 100 mm scale (its own note: \"should be scaled to 100mm\"; lentil traces 85.9 mm): every length was scaled so the paraxial focal length is 100 mm.",
    },
    Job { name: "kodak-petzval-100mm", from: From::Lentil("0006"), scale_to_efl_mm: None, drop_design_focal: false, note: "" },
    Job { name: "cooke-speed-panchro-25mm", from: From::Lentil("0007"), scale_to_efl_mm: None, drop_design_focal: false, note: "" },
    Job { name: "nikon-normal-52mm", from: From::Lentil("0008"), scale_to_efl_mm: None, drop_design_focal: false, note: "" },
    Job { name: "zeiss-biotar-100mm", from: From::Lentil("0009"), scale_to_efl_mm: None, drop_design_focal: false, note: "" },
    Job {
        name: "aspheric-fisheye-10mm",
        from: From::Lentil("0014"),
        scale_to_efl_mm: None,
        drop_design_focal: true,
        note: "The database states a 6 mm focal length, but the surface data give a paraxial focal length of 9.71 mm, which does not depend on the aspheric or conic terms; lentil's own 5.48 mm is a real ray at half the rear housing radius through its aspheric code (which reads only A4 and A8 from the database and uses conic 1). The data are kept at their scale and no design focal length is given. Rays pass beyond 90 degrees half-field, as the 181 degree claim says.",
    },
    Job {
        name: "schneider-anamorphic-31mm",
        from: From::Lentil("2004"),
        scale_to_efl_mm: None,
        drop_design_focal: false,
        note: "Anamorphic: the front cylinder group (lentil cyl-y) is curved along x, so the x meridian carries the squeeze; the design focal length (31 mm) is the x-meridian value.",
    },
];

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let check = args.iter().any(|a| a == "--check");
    let paths: Vec<&String> = args.iter().filter(|a| !a.starts_with("--")).collect();
    let (Some(data), Some(out)) = (paths.first(), paths.get(1)) else {
        eprintln!("usage: convert_library [--check] SHARED_LENS_DIR OUTPUT_DIR");
        return ExitCode::from(2);
    };
    let (data, out) = (PathBuf::from(data), PathBuf::from(out));
    let mut failed = false;
    println!(
        "| name | source | surfaces | design EFL mm | paraxial EFL mm (y / x) | f-number (file / paraxial at shipped stop) |"
    );
    println!("|---|---|---|---|---|---|");
    for job in JOBS {
        match convert(job, &data) {
            Ok((text, lens)) => {
                let p = lens.prescription();
                let px = lens.paraxial();
                let efl = if (px.efl_x_mm - px.efl_mm).abs() > 1e-6 * px.efl_mm.abs() {
                    format!("{:.2} / {:.2}", px.efl_mm, px.efl_x_mm)
                } else {
                    format!("{:.2}", px.efl_mm)
                };
                let short_source: String = p.lens.source.chars().take(60).collect();
                println!(
                    "| {} | {}… | {} | {} | {} | {} / {:.2} |",
                    job.name,
                    short_source,
                    p.surfaces.len(),
                    p.lens.focal_length_mm.map(|f| format!("{f}")).unwrap_or("—".into()),
                    efl,
                    p.lens.f_number.map(|f| format!("{f:.2}")).unwrap_or("—".into()),
                    px.f_number
                );
                let path = out.join(format!("{}.toml", job.name));
                if check {
                    let old = std::fs::read_to_string(&path).unwrap_or_default();
                    if old != text {
                        eprintln!("{}: out of date", path.display());
                        failed = true;
                    }
                } else if let Err(e) = std::fs::write(&path, text) {
                    eprintln!("{}: {e}", path.display());
                    failed = true;
                }
            }
            Err(e) => {
                eprintln!("{}: {e}", job.name);
                failed = true;
            }
        }
    }
    if failed {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}

/// Imports, adjusts and validates one lens; returns the TOML text and the lens built from it.
fn convert(job: &Job, data: &Path) -> Result<(String, Lens), String> {
    let (mut p, map, rel) = match job.from {
        From::Pbrt(file) => {
            let path = data.join("pbrt").join(file);
            let text = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
            let (p, map) = import_pbrt(&text, &format!("pbrt/{file}"), job.name).map_err(|e| e.to_string())?;
            (p, map, format!("pbrt/{file}"))
        }
        From::Lentil(id) => {
            let path = data.join("lentil-lenses.json");
            let text = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
            let (p, map) = import_lentil(&text, "lentil-lenses.json", id).map_err(|e| e.to_string())?;
            (p, map, format!("lentil-lenses.json, entry {id}"))
        }
    };
    p.lens.name = job.name.to_string();
    let mut scale_note = String::new();
    if let Some(target) = job.scale_to_efl_mm {
        let lens = Lens::new(p.clone(), &map, None).map_err(|e| e.to_string())?;
        let s = target / lens.paraxial().efl_mm;
        scale(&mut p, s);
        p.lens.focal_length_mm = Some(target);
        scale_note = format!(" (Scale factor {s:.6}; lengths rounded to 1 nm.)");
    }
    if job.drop_design_focal {
        p.lens.focal_length_mm = None;
    }
    if p.surfaces.iter().any(|s| s.cylinder.is_some()) {
        let lens = Lens::new(p.clone(), &map, None).map_err(|e| e.to_string())?;
        let px = lens.paraxial();
        push_note(
            &mut p,
            &format!(
                "Paraxial focal lengths: {:.2} mm (x meridian), {:.2} mm (y meridian); squeeze {:.3}.",
                px.efl_x_mm,
                px.efl_mm,
                px.efl_mm / px.efl_x_mm
            ),
        );
    }
    if !job.note.is_empty() {
        let old = std::mem::take(&mut p.lens.notes);
        p.lens.notes = format!("{}{scale_note}", job.note);
        if !old.is_empty() {
            p.lens.notes.push(' ');
            p.lens.notes.push_str(&old);
        }
    }
    // Validate as imported (with the importer's line map) ...
    Lens::new(p.clone(), &map, None).map_err(|e| e.to_string())?;
    // ... and as written.
    let text = format!("{}{}", header(job.name, &p, &rel), inline_materials(&to_toml(&p)));
    let lens = Lens::from_toml(&text, &format!("library:{}", job.name), None).map_err(|e| e.to_string())?;
    if lens.prescription() != &p {
        return Err("the TOML does not read back to the same prescription".into());
    }
    Ok((text, lens))
}

fn push_note(p: &mut Prescription, note: &str) {
    if !p.lens.notes.is_empty() {
        p.lens.notes.push(' ');
    }
    p.lens.notes.push_str(note);
}

/// Scales every length by `s` (aspheric A_{2k} by s^(1-2k), odd B_i by s^(1-i)), rounding
/// lengths to 1 nm.
fn scale(p: &mut Prescription, s: f64) {
    let r = |x: f64| (x * s * 1e6).round() / 1e6;
    for surf in &mut p.surfaces {
        surf.radius_mm = r(surf.radius_mm);
        surf.thickness_mm = r(surf.thickness_mm);
        surf.semi_diameter_mm = r(surf.semi_diameter_mm);
        if let Some(h) = surf.housing_semi_diameter_mm.as_mut() {
            *h = r(*h);
        }
        surf.aspheric_r2 /= s;
        for (j, a) in surf.aspheric.iter_mut().enumerate() {
            let order = 2 * (j as i32 + 2);
            *a *= s.powi(1 - order);
        }
        for (j, b) in surf.aspheric_odd.iter_mut().enumerate() {
            let order = 2 * j as i32 + 1;
            *b *= s.powi(1 - order);
        }
    }
    if let Some(open) = p.lens.stop_semi_diameter_mm.as_mut() {
        *open = r(*open);
    }
}

/// Rewrites `[surface.material]` sub-tables (`nd = ..`, `vd = ..`) as inline
/// `material = { nd = .., vd = .. }` in their surface, for readability. The caller checks that
/// the result reads back to the same prescription.
fn inline_materials(toml: &str) -> String {
    let lines: Vec<&str> = toml.lines().collect();
    let mut out: Vec<String> = Vec::with_capacity(lines.len());
    let mut i = 0;
    while i < lines.len() {
        if lines[i].trim() == "[surface.material]" {
            let mut fields = Vec::new();
            let mut j = i + 1;
            while j < lines.len() && !lines[j].trim().is_empty() && !lines[j].trim_start().starts_with('[') {
                fields.push(lines[j].trim().to_string());
                j += 1;
            }
            // Drop the blank line before the sub-table, then append to the surface's keys.
            while out.last().map(|l| l.trim().is_empty()).unwrap_or(false) {
                out.pop();
            }
            out.push(format!("material = {{ {} }}", fields.join(", ")));
            i = j;
            continue;
        }
        out.push(lines[i].to_string());
        i += 1;
    }
    let mut s = out.join("\n");
    s.push('\n');
    s
}

/// The comment block at the top of a library file.
fn header(name: &str, p: &Prescription, rel: &str) -> String {
    let mut h = String::new();
    h.push_str(&format!("# {name}\n"));
    for chunk in wrap(&format!("Source: {}", p.lens.source), 96) {
        h.push_str(&format!("# {chunk}\n"));
    }
    h.push_str(&format!(
        "# Generated from the shared lens data ({rel}) by\n#   cargo run -p petzval-optics --example convert_library -- /work/shared/lenses renderer/optics/lenses\n# Change the converter or the importers, not this file.\n\n"
    ));
    h
}

fn wrap(s: &str, width: usize) -> Vec<String> {
    let mut lines = Vec::new();
    let mut cur = String::new();
    for word in s.split_whitespace() {
        if !cur.is_empty() && cur.len() + 1 + word.len() > width {
            lines.push(std::mem::take(&mut cur));
        }
        if !cur.is_empty() {
            cur.push(' ');
        }
        cur.push_str(word);
    }
    if !cur.is_empty() {
        lines.push(cur);
    }
    lines
}
