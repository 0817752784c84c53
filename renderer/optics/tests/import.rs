//! Importers (pbrt `.dat`, Zemax `.zmx`, lentil JSON) and the embedded lens library.
//!
//! Fixtures live in `renderer/optics/tests/data/` (see its README): copies of the shared pbrt tables,
//! a three-entry subset of the lentil database, and `.zmx` files written by optiland
//! (`tests/optics/write_optiland_zmx.py`) with optiland's own paraxial focal lengths in
//! `zmx/expected.json`.

use petzval_optics::import::{import_lentil, import_pbrt, import_zemax, read_prescription};
use petzval_optics::prescription::{CylinderAxis, MaterialSpec, Prescription, SourceMap};
use petzval_optics::{library_lens, Error, Lens, LIBRARY};
use std::path::PathBuf;

fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(rel)
}

fn read(rel: &str) -> String {
    std::fs::read_to_string(data(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

fn bytes(rel: &str) -> Vec<u8> {
    std::fs::read(data(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// The (line, field, message) of a `LensFile` error; panics on success or another error.
fn lens_file_err<T: std::fmt::Debug>(r: Result<T, Error>) -> (usize, String, String) {
    match r {
        Err(Error::LensFile { line, field, message, .. }) => (line, field, message),
        other => panic!("expected Error::LensFile, got {other:?}"),
    }
}

/// Imports then builds, so validation errors count too.
fn build(r: Result<(Prescription, SourceMap), Error>) -> Result<Lens, Error> {
    let (p, map) = r?;
    Lens::new(p, &map, None)
}

/// 1-based line of the first line of `text` containing `needle`.
fn line_containing(text: &str, needle: &str) -> usize {
    text.lines().position(|l| l.contains(needle)).unwrap_or_else(|| panic!("no line with {needle:?}")) + 1
}

fn rel_close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * b.abs().max(1e-12)
}

// ---------------------------------------------------------------------------------------------
// pbrt
// ---------------------------------------------------------------------------------------------

const PBRT: [(&str, &str, f64); 4] = [
    ("dgauss.50mm.dat", "double-gauss-50mm", 50.0),
    ("wide.22mm.dat", "wide-22mm", 22.0),
    ("fisheye.10mm.dat", "fisheye-10mm", 10.0),
    ("telephoto.250mm.dat", "telephoto-250mm", 250.0),
];

#[test]
fn pbrt_tables_import_and_match_their_design_focal_length() {
    for (file, name, efl) in PBRT {
        let text = read(&format!("pbrt/{file}"));
        let (p, map) = import_pbrt(&text, file, name).unwrap();
        assert_eq!(p.lens.name, name);
        assert_eq!(p.lens.focal_length_mm, Some(efl), "{file}: 'Scaled to' header");
        assert!(p.lens.source.ends_with("via pbrt-v4 scenes (Apache-2.0)"), "{}", p.lens.source);
        // One surface per data row, each mapped to its row.
        let rows: Vec<usize> = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
            .map(|(i, _)| i + 1)
            .collect();
        assert_eq!(map.surface_lines, rows, "{file}");
        let stop = p.surfaces.iter().position(|s| s.stop).unwrap();
        let stop_row: Vec<f64> =
            text.lines().nth(rows[stop] - 1).unwrap().split_whitespace().map(|t| t.parse().unwrap()).collect();
        assert_eq!(stop_row[0], 0.0);
        assert_eq!(p.surfaces[stop].semi_diameter_mm, stop_row[3] / 2.0);
        let housing = p.surfaces[stop].housing_semi_diameter_mm.unwrap();
        assert!(housing >= p.surfaces[stop].semi_diameter_mm);
        let lens = Lens::new(p.clone(), &map, None).unwrap();
        assert!(rel_close(lens.paraxial().efl_mm, efl, 0.01), "{file}: EFL {}", lens.paraxial().efl_mm);
        // The library file is this table, converted.
        let lib = library_lens(name).unwrap();
        assert_eq!(lib.prescription().surfaces, p.surfaces, "{name} differs from its pbrt table");
    }
}

#[test]
fn pbrt_reads_thickness_as_distance_to_next_even_with_an_axpos_header() {
    // The shared files say "axpos" in their column header but are to-next.
    let text = read("pbrt/dgauss.50mm.dat");
    assert!(text.contains("axpos"));
    let (p, _) = import_pbrt(&text, "dgauss", "dg").unwrap();
    assert_eq!(p.surfaces[0].thickness_mm, 3.76);
    assert_eq!(
        p.surfaces[0].material,
        MaterialSpec::Model(petzval_optics::prescription::ModelGlass { nd: 1.67, vd: 0.0 })
    );
    assert_eq!(p.surfaces[1].material, MaterialSpec::Name("air".into()));
    assert_eq!(p.surfaces.last().unwrap().thickness_mm, 0.0);
}

#[test]
fn pbrt_detects_kolb_axpos_tables() {
    // The same double Gauss written with axpos = distance from the PREVIOUS surface: the first
    // value is 0 and the last is the rear element's thickness.
    let to_next = read("pbrt/dgauss.50mm.dat");
    let rows: Vec<Vec<&str>> = to_next
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
        .map(|l| l.split_whitespace().collect())
        .collect();
    let mut axpos = String::from("# radius\taxpos\tN\taperture\n");
    for (i, r) in rows.iter().enumerate() {
        let prev = if i == 0 { "0" } else { rows[i - 1][1] };
        axpos.push_str(&format!("{}\t{}\t{}\t{}\n", r[0], prev, r[2], r[3]));
    }
    let (a, _) = import_pbrt(&axpos, "axpos.dat", "dg").unwrap();
    let (b, _) = import_pbrt(&to_next, "dgauss.dat", "dg").unwrap();
    assert!(a.lens.notes.contains("axpos"), "{}", a.lens.notes);
    assert_eq!(a.surfaces, b.surfaces);
    // Without the header the same numbers are read as to-next (and then fail validation:
    // a zero-thickness first element).
    let plain = axpos.replacen("axpos", "thick", 1);
    let (c, _) = import_pbrt(&plain, "plain.dat", "dg").unwrap();
    assert_eq!(c.surfaces[0].thickness_mm, 0.0);
}

#[test]
fn pbrt_reduces_crossing_edges_and_says_so() {
    // A biconvex element (R 20, 4 mm thick) whose edge would be negative at the listed 20 mm
    // aperture: the surfaces meet at sqrt(20² - 18²) = 8.718 mm.
    let text = "# test\n20 4 1.5 20\n-20 3 1 20\n0 30 0 8\n";
    let (p, map) = import_pbrt(text, "t.dat", "t").unwrap();
    assert_eq!(p.surfaces[0].semi_diameter_mm, 8.717);
    assert_eq!(p.surfaces[1].semi_diameter_mm, 8.717);
    assert!(p.lens.notes.contains("reduced"), "{}", p.lens.notes);
    Lens::new(p, &map, None).unwrap();
}

#[test]
fn pbrt_bad_input_names_the_line() {
    let cases: &[(&str, usize, &str)] = &[
        ("", 0, "file"),
        ("# only a comment\n", 0, "file"),
        ("# c\nfoo bar baz qux\n", 2, "radius"),
        ("# c\n29.475 NaN 1.67 25.2\n", 2, "thickness"),
        ("# c\n29.475 inf 1.67 25.2\n", 2, "thickness"),
        ("29.475 3.76 1.67 25.2\n84.83 0.12 1\n", 2, "aperture"),
        ("29.475 3.76 1.67 25.2 7\n", 1, "row"),
        ("1e300 3.76 1.67 25.2\n", 1, "radius"),
        ("29.475 3.76 1.67 -25.2\n", 1, "aperture"),
        ("29.475 3.76 7.5 25.2\n", 1, "N"),
        ("29.475 3.76 1.67 25.2\n84.83 0.12 1 25.2\n", 0, "radius"), // no stop
        ("0 1 0 10\n50 2 1.5 12\n0 1 0 10\n-50 30 1 12\n", 3, "radius"), // two stops
        ("50 2 1.5 12\n0 1 1.5 10\n-50 30 1 12\n", 2, "N"),          // stop followed by glass
        ("50 2 1.5 12\n0 1 0 10\n-50 30 1 12\n", 2, "N"),            // stop right after glass
    ];
    for (text, line, field) in cases {
        let (l, f, m) = lens_file_err(import_pbrt(text, "bad.dat", "bad"));
        assert_eq!((l, f.as_str()), (*line, *field), "{text:?}: {m}");
    }
}

#[test]
fn pbrt_intersecting_elements_are_reported_at_their_row() {
    // 0.1 mm centre thickness between R 10 and R -10 at 10 mm aperture: the surfaces cross
    // almost at once (too much to trim), so validation reports row 3's surface.
    let text = "# c\n0 2 0 4\n10 0.1 1.5 10\n-10 20 1 10\n";
    let (line, field, msg) = lens_file_err(build(import_pbrt(text, "x.dat", "x")));
    assert_eq!(line, 3, "{msg}");
    assert_eq!(field, "surface[2].thickness_mm");
}

// ---------------------------------------------------------------------------------------------
// Zemax
// ---------------------------------------------------------------------------------------------

fn expected_efl(sample: &str) -> f64 {
    let v: serde_json::Value = serde_json::from_str(&read("zmx/expected.json")).unwrap();
    v[sample]["efl_mm"].as_f64().unwrap()
}

#[test]
fn zemax_files_from_optiland_match_optilands_focal_length() {
    for sample in
        ["cooke_triplet", "tessar", "petzval", "double_gauss", "aspheric_singlet_a4", "aspheric_singlet_stop_on_glass"]
    {
        let rel = format!("zmx/{sample}.zmx");
        let lens = build(import_zemax(&bytes(&rel), &rel)).unwrap_or_else(|e| panic!("{sample}: {e}"));
        let efl = lens.paraxial().efl_mm;
        // Same glass data (refractiveindex.info) and primary wavelength as optiland.
        assert!(rel_close(efl, expected_efl(sample), 1e-6), "{sample}: EFL {efl} vs {}", expected_efl(sample));
        assert!(lens.surfaces()[lens.stop_index()].is_stop, "{sample}: the file's STOP surface is the stop");
    }
}

#[test]
fn zemax_maps_surfaces_to_surf_lines_and_keeps_a_curved_stop() {
    let rel = "zmx/cooke_triplet.zmx";
    let text = read(rel);
    let (p, map) = import_zemax(text.as_bytes(), rel).unwrap();
    // Six lens surfaces; the stop is SURF 4 itself (curved, glass in front), as in Zemax.
    assert_eq!(p.surfaces.len(), 6);
    assert!(p.surfaces[3].stop && p.surfaces[3].radius_mm != 0.0);
    let surf = |n: usize| line_containing(&text, &format!("SURF {n}"));
    assert_eq!(map.surface_lines, vec![surf(1), surf(2), surf(3), surf(4), surf(5), surf(6)]);
    assert_eq!(p.surfaces[0].material, MaterialSpec::Name("SK16".into()));
    assert_eq!(p.lens.primary_wavelength_nm, Some(550.0));
    let track: f64 = p.surfaces.iter().map(|s| s.thickness_mm).sum();
    assert!((track - (3.25896 + 6.00755 + 0.99997 + 4.75041 + 2.95208 + 42.20778)).abs() < 1e-9);

    // Tessar: a plane stop in air is used as it is.
    let (t, _) = import_zemax(&bytes("zmx/tessar.zmx"), "tessar.zmx").unwrap();
    assert_eq!(t.surfaces.len(), 8);
    assert!(t.surfaces[4].stop);
}

#[test]
fn zemax_even_asphere_coefficients_are_a4_onwards() {
    let (p, _) = import_zemax(&bytes("zmx/aspheric_singlet_a4.zmx"), "a4.zmx").unwrap();
    let asph: Vec<&Vec<f64>> = p.surfaces.iter().map(|s| &s.aspheric).filter(|a| !a.is_empty()).collect();
    assert_eq!(asph, vec![&vec![-4.690412e-6, -6.404376e-8]]);
    assert!(p.surfaces[0].stop);
    // optiland's own sample has an r² term (PARM 1): kept as aspheric_r2, adding 2·A2 to the
    // paraxial curvature
    let (p, map) = import_zemax(&bytes("zmx/aspheric_singlet.zmx"), "s.zmx").unwrap();
    assert_eq!(p.surfaces[0].aspheric_r2, -2.248851e-4);
    let lens = Lens::new(p, &map, None).unwrap();
    let c = lens.surfaces()[0].shape.paraxial_curvature_per_mm();
    assert!((c - (0.05 - 2.0 * 2.248851e-4)).abs() < 1e-15);
}

/// A Zemax file with one surface of the given TYPE and PARM lines (inch units), a plane stop
/// in front and a plane back.
fn one_surface_zmx(ty: &str, curv: f64, conic: f64, parms: &[(usize, f64)]) -> String {
    let parm: String = parms.iter().map(|(k, v)| format!("  PARM {k} {v:e}\n")).collect();
    format!(
        "VERS 1\nMODE SEQ\nUNIT IN X W X CM MR CPMM\nSURF 0\n  TYPE STANDARD\n  CURV 0\n  DISZ INFINITY\n\
         SURF 1\n  TYPE STANDARD\n  STOP\n  CURV 0\n  DISZ 0.1\n  DIAM 0.2\n\
         SURF 2\n  TYPE {ty}\n  CURV {curv:e}\n  CONI {conic}\n  DISZ 0.2\n  GLAS N-BK7 0 0 1.5168 64.17\n  DIAM 0.2\n{parm}\
         SURF 3\n  TYPE STANDARD\n  CURV 0\n  DISZ 3\n  DIAM 0.2\nSURF 4\n  TYPE STANDARD\n  CURV 0\n  DISZ 0\n"
    )
}

/// ODDASPHE: PARM k is the coefficient of r^k (k = 1..8), odd k → `aspheric_odd`, k = 2 →
/// `aspheric_r2`, even k ≥ 4 → `aspheric`; each converted from the file's unit (inches here)
/// as β·u^(1−k). TOROIDAL: read as a cylinder (PARM 1 = 0: the YZ profile extruded along x;
/// a flat profile with PARM 1 = R: radius R along x); a toroid curved both ways is refused at
/// its PARM 1 line.
#[test]
fn zemax_odd_aspheres_and_cylindrical_toroids_import() {
    let u: f64 = 25.4;
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs();
    let text =
        one_surface_zmx("ODDASPHE", 0.5, -0.3, &[(1, 1e-3), (2, 2e-3), (3, 3e-4), (4, 4e-5), (5, 5e-6), (8, 8e-7)]);
    let (p, _) = import_zemax(text.as_bytes(), "odd.zmx").unwrap();
    let s = &p.surfaces[1];
    assert!(close(s.radius_mm, 2.0 * u) && s.conic == -0.3 && s.cylinder.is_none());
    assert_eq!(s.aspheric_odd.len(), 3);
    for (got, (k, v)) in s.aspheric_odd.iter().zip([(1, 1e-3), (3, 3e-4), (5, 5e-6)]) {
        assert!(close(*got, v * u.powi(1 - k)), "B{k}: {got}");
    }
    assert!(close(s.aspheric_r2, 2e-3 / u));
    assert_eq!(s.aspheric.len(), 3); // A4, A6 (0), A8
    assert!(close(s.aspheric[0], 4e-5 * u.powi(-3)) && s.aspheric[1] == 0.0 && close(s.aspheric[2], 8e-7 * u.powi(-7)));
    // the lens builds and its sag is the sum of the terms
    let (p2, map) = import_zemax(text.as_bytes(), "odd.zmx").unwrap();
    let lens = Lens::new(p2, &map, None).unwrap();
    let r: f64 = 3.0;
    let shape = &lens.surfaces()[1].shape;
    let c = 1.0 / (2.0 * u);
    let mut z = c * r * r / (1.0 + (1.0 - 0.7 * c * c * r * r).sqrt());
    for (k, v) in [(1, 1e-3), (2, 2e-3), (3, 3e-4), (4, 4e-5), (5, 5e-6), (8, 8e-7)] {
        z += v * u.powi(1 - k) * r.powi(k);
    }
    assert!((shape.sag(r, 0.0).unwrap() - z).abs() < 1e-12, "{:?} vs {z}", shape.sag(r, 0.0));

    // TOROIDAL with an infinite radius of rotation: curved along y, its y² and y⁴ terms kept
    let text = one_surface_zmx("TOROIDAL", 0.5, 0.0, &[(1, 0.0), (2, 2e-3), (3, 3e-4)]);
    let (p, _) = import_zemax(text.as_bytes(), "cyl.zmx").unwrap();
    let s = &p.surfaces[1];
    assert_eq!(s.cylinder, Some(petzval_optics::prescription::CylinderAxis::Y));
    assert!(close(s.radius_mm, 2.0 * u) && close(s.aspheric_r2, 2e-3 / u) && close(s.aspheric[0], 3e-4 * u.powi(-3)));
    // a flat profile rotated about an axis R away: a cylinder of radius R along x
    let text = one_surface_zmx("TOROIDAL", 0.0, 0.0, &[(1, 2.0)]);
    let (p, _) = import_zemax(text.as_bytes(), "cylx.zmx").unwrap();
    assert_eq!(p.surfaces[1].cylinder, Some(petzval_optics::prescription::CylinderAxis::X));
    assert!(close(p.surfaces[1].radius_mm, 2.0 * u));
    // EVENASPH has eight terms (PARM 1–8, r² … r¹⁶): a PARM 9 is not a coefficient
    let text = one_surface_zmx("EVENASPH", 0.5, 0.0, &[(2, 1e-4), (9, 1e-3)]);
    let (p, _) = import_zemax(text.as_bytes(), "even9.zmx").unwrap();
    assert_eq!(p.surfaces[1].aspheric.len(), 1, "{:?}", p.surfaces[1].aspheric);
    // a true toroid is refused, naming PARM 1's line
    let text = one_surface_zmx("TOROIDAL", 0.5, 0.0, &[(1, 2.0)]);
    let e = import_zemax(text.as_bytes(), "toroid.zmx").unwrap_err().to_string();
    let line = text.lines().position(|l| l.trim_start().starts_with("PARM 1")).unwrap() + 1;
    assert!(e.starts_with(&format!("toroid.zmx:{line}: PARM 1: a toroid")), "{e}");
}

#[test]
fn zemax_utf16_in_every_byte_order_reads_like_ascii() {
    let ascii = import_zemax(&bytes("zmx/cooke_triplet.zmx"), "c.zmx").unwrap().0;
    let le_bom = bytes("zmx/cooke_triplet_utf16.zmx");
    assert_eq!(&le_bom[..2], &[0xFF, 0xFE]);
    let (p, map) = import_zemax(&le_bom, "c16.zmx").unwrap();
    assert_eq!(p.surfaces, ascii.surfaces);
    // Lines are counted the same way in the UTF-16 file.
    let text = read("zmx/cooke_triplet.zmx");
    assert_eq!(map.surface_lines[0], line_containing(&text, "SURF 1"));
    // Big-endian with a BOM, and little-endian without one.
    let be: Vec<u8> = le_bom.chunks(2).flat_map(|c| [c[1], c[0]]).collect();
    assert_eq!(import_zemax(&be, "be.zmx").unwrap().0.surfaces, ascii.surfaces);
    assert_eq!(import_zemax(&le_bom[2..], "nobom.zmx").unwrap().0.surfaces, ascii.surfaces);
    // And through the file-extension dispatch.
    let (q, _) = read_prescription(&data("zmx/cooke_triplet_utf16.zmx")).unwrap();
    assert_eq!(q.surfaces, ascii.surfaces);
}

#[test]
fn zemax_units_are_converted_to_mm() {
    let text = read("zmx/cooke_triplet.zmx");
    let mm = build(import_zemax(text.as_bytes(), "mm.zmx")).unwrap().paraxial().efl_mm;
    for (unit, scale) in [("CM", 10.0), ("IN", 25.4), ("METER", 1000.0)] {
        let t = text.replace("UNIT MM", &format!("UNIT {unit}"));
        let lens = build(import_zemax(t.as_bytes(), "u.zmx")).unwrap();
        assert!(rel_close(lens.paraxial().efl_mm, mm * scale, 1e-9), "{unit}");
    }
    // Aspheric coefficients scale as length^(1-2k).
    let t = read("zmx/aspheric_singlet_a4.zmx").replace("UNIT MM", "UNIT CM");
    let (p, _) = import_zemax(t.as_bytes(), "a4cm.zmx").unwrap();
    let a = &p.surfaces[1].aspheric;
    assert!(
        rel_close(a[0], -4.690412e-6 * 10f64.powi(-3), 1e-12) && rel_close(a[1], -6.404376e-8 * 10f64.powi(-5), 1e-12)
    );
}

#[test]
fn zemax_unknown_glass_falls_back_to_the_files_nd_vd_or_fails_at_its_line() {
    let text = read("zmx/cooke_triplet.zmx");
    let t = text.replacen("GLAS F2 ", "GLAS NOT-A-GLASS ", 1);
    let (p, _) = import_zemax(t.as_bytes(), "g.zmx").unwrap();
    assert!(matches!(p.surfaces[2].material, MaterialSpec::Model(g) if (g.nd - 1.6200368335524609).abs() < 1e-12));
    assert!(p.lens.notes.contains("NOT-A-GLASS"));
    let t =
        text.replacen("GLAS F2 0 0 1.6200368335524609E+00 3.6351379605603441E+01 0 0 0 0 0 0", "GLAS NOT-A-GLASS", 1);
    let (line, field, _) = lens_file_err(import_zemax(t.as_bytes(), "g.zmx"));
    assert_eq!((line, field.as_str()), (line_containing(&t, "NOT-A-GLASS"), "GLAS"));
}

#[test]
fn zemax_bad_input_names_the_line() {
    let text = read("zmx/cooke_triplet.zmx");
    // Empty, binary garbage and text without surfaces.
    for b in [&b""[..], &[0xde, 0xad, 0xbe, 0xef, 0x00, 0x12][..], b"hello\nworld\n"] {
        let (line, field, _) = lens_file_err(import_zemax(b, "g.zmx"));
        assert_eq!((line, field.as_str()), (0, "SURF"));
    }
    // NaN and garbage numbers.
    let t = text.replacen("CURV -2.2948388798212154E-03", "CURV NaN", 1);
    assert_eq!(lens_file_err(import_zemax(t.as_bytes(), "n.zmx")).0, line_containing(&t, "CURV NaN"));
    let t = text.replacen("DIAM 7.9370137545704882E+00", "DIAM seven", 1);
    assert_eq!(lens_file_err(import_zemax(t.as_bytes(), "n.zmx")).0, line_containing(&t, "DIAM seven"));
    let t = text.replacen("DISZ 6.0075500000000002E+00", "DISZ 1e300", 1);
    assert_eq!(lens_file_err(import_zemax(t.as_bytes(), "n.zmx")).0, line_containing(&t, "DISZ 1e300"));
    // A lens surface without DISZ (missing field): reported at its SURF line.
    let t = text.replacen("  DISZ 6.0075500000000002E+00\n", "", 1);
    let (line, field, _) = lens_file_err(import_zemax(t.as_bytes(), "m.zmx"));
    assert_eq!((line, field.as_str()), (line_containing(&t, "SURF 2"), "DISZ"));
    // Truncated in the middle of a line.
    let cut = text.find("  DISZ 6.00755").unwrap() + "  DISZ".len();
    let t = &text[..cut];
    let (line, field, _) = lens_file_err(import_zemax(t.as_bytes(), "t.zmx"));
    assert_eq!((line, field.as_str()), (t.lines().count(), "DISZ"));
    // Unsupported surface type, non-sequential mode, two stops.
    let t = text.replacen("  TYPE STANDARD\n  CURV -2.29", "  TYPE SZERNSAG\n  CURV -2.29", 1);
    assert_eq!(lens_file_err(import_zemax(t.as_bytes(), "t.zmx")).0, line_containing(&t, "SZERNSAG"));
    let t = text.replace("MODE SEQ", "MODE NSC");
    assert_eq!(lens_file_err(import_zemax(t.as_bytes(), "t.zmx")).0, 2);
    let t = text.replacen("SURF 2\n  TYPE STANDARD\n", "SURF 2\n  TYPE STANDARD\n  STOP\n", 1);
    assert_eq!(lens_file_err(import_zemax(t.as_bytes(), "t.zmx")).0, line_containing(&t, "SURF 4"));
}

#[test]
fn zemax_intersecting_elements_are_reported_at_the_disz_line() {
    // the error names the keyword's own line and the keyword (it named the SURF line before)
    let text = read("zmx/cooke_triplet.zmx");
    let t = text.replacen("DISZ 3.2589600000000001E+00", "DISZ 0.1", 1);
    let (line, field, msg) = lens_file_err(build(import_zemax(t.as_bytes(), "x.zmx")));
    assert_eq!(line, line_containing(&t, "DISZ 0.1"), "{msg}");
    assert!(line > line_containing(&t, "SURF 1") && line < line_containing(&t, "SURF 2"), "{msg}");
    assert_eq!(field, "surface[1].thickness_mm (DISZ)");
}

/// A DIAM past the rim of its sphere (as optiland writes from paraxial ray heights at a very
/// wide field) becomes the rim, with a note: no ray meets the surface farther out anyway.
#[test]
fn zemax_diam_past_the_rim_becomes_the_rim() {
    let text = read("zmx/cooke_triplet.zmx");
    let first = text.find("SURF 1").unwrap();
    let t = format!("{}{}", &text[..first], text[first..].replacen("DIAM 9.1900830893933154E+00", "DIAM 40", 1));
    let (p, map) = import_zemax(t.as_bytes(), "d.zmx").unwrap();
    let r = p.surfaces[0].radius_mm.abs();
    let sd = p.surfaces[0].semi_diameter_mm;
    assert!(sd < r && sd > r * (1.0 - 1e-8), "semi-diameter {sd} vs radius {r}");
    assert!(p.lens.notes.contains("SURF 1: semi-diameter 40.0000 mm is beyond the surface's rim"), "{}", p.lens.notes);
    Lens::new(p, &map, None).unwrap();
}

/// The image surface in front of the last lens surface (a negative last DISZ) is refused at
/// its line, saying why.
#[test]
fn zemax_image_in_front_of_the_lens_is_refused() {
    let text = read("zmx/cooke_triplet.zmx");
    let last = text.rfind("SURF ").unwrap();
    let before_image = text[..last].rfind("SURF ").unwrap();
    let block = &text[before_image..last];
    let disz = block.lines().find(|l| l.trim_start().starts_with("DISZ")).unwrap();
    // the image surface in front of the last lens surface
    let t = format!("{}{}{}", &text[..before_image], block.replacen(disz, "  DISZ -0.5", 1), &text[last..]);
    let (line, field, msg) = lens_file_err(import_zemax(t.as_bytes(), "neg.zmx"));
    assert_eq!(line, line_containing(&t, "DISZ -0.5"), "{msg}");
    assert_eq!(field, "DISZ");
    assert!(msg.contains("0.5 mm in front of the last lens surface"), "{msg}");
}

#[test]
fn zemax_diam_zero_takes_the_neighbours() {
    let text = read("zmx/cooke_triplet.zmx");
    let t = text.replacen("DIAM 7.9370137545704882E+00", "DIAM 0", 1);
    let (p, _) = import_zemax(t.as_bytes(), "d.zmx").unwrap();
    assert_eq!(p.surfaces[1].semi_diameter_mm, 9.190_083_089_393_315);
    assert!(p.lens.notes.contains("DIAM 0"));
}

/// What a camera lens does not carry is named, not dropped in silence: a finite object distance
/// (SURF 0's DISZ) and a curved image surface (the last SURF's CURV). The lens itself is the
/// same.
#[test]
fn zemax_object_distance_and_curved_image_are_noted() {
    let text = read("zmx/cooke_triplet.zmx");
    let (plain, _) = import_zemax(text.as_bytes(), "c.zmx").unwrap();
    assert!(!plain.lens.notes.contains("object distance") && !plain.lens.notes.contains("image surface"));
    let t = text.replacen("DISZ INFINITY", "DISZ 500", 1);
    let sevens = t.find("SURF 7").unwrap();
    let t = format!("{}{}", &t[..sevens], t[sevens..].replacen("CURV 0.0000000000000000E+00", "CURV -0.01", 1));
    let (p, _) = import_zemax(t.as_bytes(), "o.zmx").unwrap();
    assert!(p.lens.notes.contains("object distance (SURF 0 DISZ 500 mm)"), "{}", p.lens.notes);
    assert!(p.lens.notes.contains("image surface's curvature (SURF 7 CURV, radius -100"), "{}", p.lens.notes);
    assert_eq!(p.surfaces.len(), plain.surfaces.len());
}

// ---------------------------------------------------------------------------------------------
// lentil
// ---------------------------------------------------------------------------------------------

const LENTIL: &str = "lentil/lentil-subset.json";

#[test]
fn lentil_entries_import_with_surface_lines() {
    let text = read(LENTIL);
    let lines: Vec<&str> = text.lines().collect();
    for id in ["0001", "0014", "2004"] {
        let (p, map) = import_lentil(&text, LENTIL, id).unwrap();
        assert!(p.lens.source.contains("via the lentil lens database (MIT, (c) 2023 Zeno Pelgrims)"));
        assert_eq!(map.surface_lines.len(), p.surfaces.len());
        // Each surface maps to the `{` of its object, and its radius is in that object.
        for (i, (&l, s)) in map.surface_lines.iter().zip(&p.surfaces).enumerate() {
            assert_eq!(lines[l - 1].trim(), "{", "{id} surface {i}: line {l}");
            let obj: String = lines[l..].iter().take_while(|x| !x.trim().starts_with('}')).copied().collect();
            if s.radius_mm != 0.0 {
                assert!(obj.contains(&format!("\"radius\": {}", s.radius_mm)), "{id} surface {i}: {obj}");
            }
        }
        // Lines increase and lie inside the entry.
        assert!(map.surface_lines.windows(2).all(|w| w[0] < w[1]));
        assert!(map.surface_lines[0] > line_containing(&text, &format!("\"{id}\": {{")));
        Lens::new(p, &map, None).unwrap();
    }
}

#[test]
fn lentil_0001_matches_the_library_and_uses_catalogue_glass() {
    let (p, _) = import_lentil(&read(LENTIL), LENTIL, "0001").unwrap();
    assert_eq!(p.surfaces[0].material, MaterialSpec::Name("SF5".into()));
    let stop = p.surfaces.iter().position(|s| s.stop).unwrap();
    assert_eq!((stop, p.surfaces[stop].radius_mm), (7, 0.0));
    assert_eq!(p.surfaces[stop].semi_diameter_mm, 25.5);
    assert_eq!(p.lens.f_number, Some(1.1078236781618804));
    assert_eq!(p.lens.stop_semi_diameter_mm, Some(25.48163899259926));
    assert_eq!(p.lens.focal_length_mm, Some(100.0));
    assert_eq!(library_lens("angenieux-double-gauss-100mm").unwrap().prescription().surfaces, p.surfaces);
}

#[test]
fn lentil_aspheric_and_cylinder_mapping() {
    let text = read(LENTIL);
    // 0014: aspherical-equation = [A4, A6, A8, A10].
    let (p, _) = import_lentil(&text, LENTIL, "0014").unwrap();
    assert_eq!(p.surfaces[6].aspheric, vec![-1.5313e-05, 9.4893e-08, -1.8128e-09, 8.7528e-12]);
    assert_eq!(p.surfaces[6].conic, 0.0);
    assert_eq!(p.surfaces[19].radius_mm, 0.0, "100000 is lentil's plane");
    assert_eq!(library_lens("aspheric-fisheye-10mm").unwrap().prescription().surfaces, p.surfaces);
    // 2004: lentil "cyl-y" (cylinder axis y) is curved along x.
    let (p, map) = import_lentil(&text, LENTIL, "2004").unwrap();
    assert_eq!(p.surfaces[0].cylinder, Some(CylinderAxis::X));
    assert_eq!(p.surfaces[3].cylinder, None, "plane surface");
    let lens = Lens::new(p.clone(), &map, None).unwrap();
    let px = lens.paraxial();
    let squeeze = px.efl_mm / px.efl_x_mm;
    assert!((1.3..=2.1).contains(&squeeze), "squeeze {squeeze}");
    assert!(rel_close(px.efl_x_mm, 31.0, 0.05), "x EFL {}", px.efl_x_mm);
    assert_eq!(library_lens("schneider-anamorphic-31mm").unwrap().prescription().surfaces, p.surfaces);
}

/// A minimal lentil database with one entry whose surfaces are given as JSON text.
fn lentil_db(surfaces: &str) -> String {
    format!(
        "{{\n  \"7777\": {{\n    \"company\": \"test\",\n    \"focal-length-mm-patent\": 50,\n    \"optical-elements-patent\": [\n{surfaces}\n    ],\n    \"product-name\": \"singlet\",\n    \"year\": 2024\n  }}\n}}\n"
    )
}

fn lentil_surface(radius: &str, thickness: &str, material: &str, ior: &str, housing: &str) -> String {
    format!(
        "      {{\n        \"abbe\": 64.2,\n        \"aspherical-equation\": null,\n        \"housing-radius\": {housing},\n        \"ior\": {ior},\n        \"lens-geometry\": \"spherical\",\n        \"material\": \"{material}\",\n        \"radius\": {radius},\n        \"thickness\": {thickness}\n      }}"
    )
}

/// 1-based line of the `{` of surface `k` in a database made by [`lentil_db`].
fn obj_line(db: &str, k: usize) -> usize {
    let start = line_containing(db, "optical-elements-patent");
    db.lines().enumerate().skip(start).filter(|(_, l)| l.trim() == "{").nth(k).map(|(i, _)| i + 1).unwrap()
}

fn singlet(material: &str, ior: &str) -> String {
    [
        lentil_surface("99999", "2", "iris", "null", "5"),
        lentil_surface("50", "4", material, ior, "8"),
        lentil_surface("-50", "48", "air", "null", "8"),
    ]
    .join(",\n")
}

#[test]
fn lentil_unknown_glass_falls_back_to_ior_or_fails_at_its_surface() {
    let db = lentil_db(&singlet("NOT-A-GLASS", "1.5168"));
    let (p, map) = import_lentil(&db, "db.json", "7777").unwrap();
    assert!(matches!(p.surfaces[1].material, MaterialSpec::Model(g) if g.nd == 1.5168 && g.vd == 64.2));
    assert!(p.lens.notes.contains("NOT-A-GLASS"), "{}", p.lens.notes);
    Lens::new(p, &map, None).unwrap();
    let db = lentil_db(&singlet("NOT-A-GLASS", "null"));
    let (line, field, msg) = lens_file_err(import_lentil(&db, "db.json", "7777"));
    assert_eq!(line, obj_line(&db, 1), "{msg}\n{db}");
    assert_eq!(field, "7777.optical-elements-patent[1].material");
}

#[test]
fn lentil_bad_input_names_the_line() {
    let good = lentil_db(&singlet("abbe", "1.5168"));
    assert!(import_lentil(&good, "db.json", "7777").is_ok());
    // Missing field: the second surface without "thickness" → that surface's `{` line.
    let t =
        good.replacen("        \"thickness\": 4\n", "        \"ior\": 1.5\n", 1).replacen("\"ior\": 1.5168,", "", 1);
    let (line, field, msg) = lens_file_err(import_lentil(&t, "db.json", "7777"));
    assert_eq!((line, field.as_str()), (obj_line(&t, 1), "7777.optical-elements-patent[1].thickness"), "{msg}\n{t}");
    // NaN (not JSON) and huge numbers.
    let t = good.replacen("\"radius\": 50", "\"radius\": NaN", 1);
    assert_eq!(lens_file_err(import_lentil(&t, "db.json", "7777")).0, line_containing(&t, "NaN"));
    let t = good.replacen("\"radius\": 50", "\"radius\": 1e300", 1);
    assert_eq!(lens_file_err(import_lentil(&t, "db.json", "7777")).0, obj_line(&t, 1));
    let t = good.replacen("\"radius\": 50", "\"radius\": 1e999", 1);
    assert_eq!(lens_file_err(import_lentil(&t, "db.json", "7777")).0, line_containing(&t, "1e999"));
    // Empty, garbage, truncated, unknown id, wrong types.
    assert_eq!(lens_file_err(import_lentil("", "db.json", "7777")).0, 1);
    assert_eq!(lens_file_err(import_lentil("%%% garbage", "db.json", "7777")).0, 1);
    let cut = &good[..good.len() / 2];
    // serde reports the end of input, on the line after the last newline.
    assert_eq!(lens_file_err(import_lentil(cut, "db.json", "7777")).0, cut.matches('\n').count() + 1);
    let (line, field, _) = lens_file_err(import_lentil(&good, "db.json", "0000"));
    assert_eq!((line, field.as_str()), (0, "id"));
    let t = good.replacen("\"material\": \"abbe\"", "\"material\": 7", 1);
    assert_eq!(lens_file_err(import_lentil(&t, "db.json", "7777")).0, obj_line(&t, 1));
    let t = good.replacen("\"lens-geometry\": \"spherical\"", "\"lens-geometry\": \"toroidal\"", 1);
    assert_eq!(lens_file_err(import_lentil(&t, "db.json", "7777")).0, obj_line(&t, 0));
}

#[test]
fn lentil_entry_without_or_with_two_irises_names_the_line() {
    let no_iris = lentil_db(&singlet("abbe", "1.5").replacen("\"material\": \"iris\"", "\"material\": \"air\"", 1));
    let (line, field, _) = lens_file_err(import_lentil(&no_iris, "db.json", "7777"));
    assert_eq!(
        (line, field.as_str()),
        (line_containing(&no_iris, "optical-elements-patent"), "7777.optical-elements-patent")
    );
    let two = lentil_db(&[singlet("abbe", "1.5"), lentil_surface("99999", "5", "IRIS", "null", "5")].join(",\n"));
    let (line, field, _) = lens_file_err(import_lentil(&two, "db.json", "7777"));
    assert_eq!((line, field.as_str()), (obj_line(&two, 3), "7777.optical-elements-patent[3].material"));
}

#[test]
fn lentil_intersecting_elements_are_reported_at_their_surface() {
    // 0.1 mm between R 10 and R -10: too much to trim, so validation reports it.
    let db = lentil_db(
        &[
            lentil_surface("99999", "2", "iris", "null", "4"),
            lentil_surface("10", "0.1", "abbe", "1.5", "8"),
            lentil_surface("-10", "20", "air", "null", "8"),
        ]
        .join(",\n"),
    );
    let (line, field, msg) = lens_file_err(build(import_lentil(&db, "db.json", "7777")));
    assert_eq!((line, field.as_str()), (obj_line(&db, 1), "surface[2].thickness_mm"), "{msg}");
}

// ---------------------------------------------------------------------------------------------
// Our own format: stop and housing
// ---------------------------------------------------------------------------------------------

#[test]
fn toml_stop_larger_than_its_housing_names_the_line() {
    let text = "[lens]\nname = \"t\"\nsource = \"test\"\n\n[[surface]]\nthickness_mm = 2.0\nsemi_diameter_mm = 5.0\nstop = true\nhousing_semi_diameter_mm = 4.0\n\n[[surface]]\nradius_mm = 50.0\nthickness_mm = 4.0\nmaterial = \"N-BK7\"\nsemi_diameter_mm = 8.0\n\n[[surface]]\nradius_mm = -50.0\nthickness_mm = 48.0\nsemi_diameter_mm = 8.0\n";
    let (line, field, _) = lens_file_err(Lens::from_toml(text, "t.toml", None));
    assert_eq!((line, field.as_str()), (7, "surface[1].semi_diameter_mm"));
}

// ---------------------------------------------------------------------------------------------
// The library
// ---------------------------------------------------------------------------------------------

/// Library lenses whose paraxial focal length is not within 10 % of a design value, and why.
const EFL_EXCEPTIONS: &[(&str, &str)] = &[(
    "aspheric-fisheye-10mm",
    "the database's 6 mm cannot come from its surface data (paraxial 9.71 mm); no design value is given",
)];

#[test]
fn every_library_lens_loads_and_has_its_design_focal_length() {
    let mut names: Vec<&str> = LIBRARY.iter().map(|e| e.name).collect();
    let sorted = {
        let mut s = names.clone();
        s.sort_unstable();
        s
    };
    assert_eq!(names, sorted, "LIBRARY must be sorted by name");
    names.dedup();
    assert_eq!(names.len(), LIBRARY.len());
    assert!(LIBRARY.len() >= 13);
    for e in LIBRARY {
        let lens = library_lens(e.name).unwrap_or_else(|err| panic!("{}: {err}", e.name));
        let p = lens.prescription();
        assert_eq!(p.lens.name, e.name);
        assert!(e.toml.starts_with("# "), "{}: header comment citing the source", e.name);
        assert!(!p.lens.source.trim().is_empty());
        let px = lens.paraxial();
        match p.lens.focal_length_mm {
            Some(f) => {
                // Anamorphic lenses: the design value belongs to one meridian.
                let ok = rel_close(px.efl_mm, f, 0.10)
                    || (!lens.is_rotationally_symmetric() && rel_close(px.efl_x_mm, f, 0.10));
                assert!(ok, "{}: paraxial EFL {} (x {}) vs design {f}", e.name, px.efl_mm, px.efl_x_mm);
            }
            None => {
                let why = EFL_EXCEPTIONS.iter().find(|(n, _)| *n == e.name);
                assert!(why.is_some(), "{}: no design focal length and no documented reason", e.name);
                assert!(p.lens.notes.contains("paraxial focal length"), "{}: notes must say why", e.name);
            }
        }
        if let Some(n) = p.lens.f_number {
            assert!(rel_close(px.f_number, n, 0.10), "{}: f/{} vs paraxial f/{}", e.name, n, px.f_number);
        }
    }
}

#[test]
fn anamorphic_library_lens_squeezes_along_x() {
    let lens = library_lens("schneider-anamorphic-31mm").unwrap();
    assert!(!lens.is_rotationally_symmetric());
    let px = lens.paraxial();
    assert!(px.efl_x_mm < px.efl_mm);
    assert!((1.3..=2.1).contains(&(px.efl_mm / px.efl_x_mm)));
}

// ---------------------------------------------------------------------------------------------
// Robustness: no input may panic an importer or the lens build.
// ---------------------------------------------------------------------------------------------

#[test]
fn truncated_and_mutated_inputs_never_panic() {
    let check = |r: Result<(Prescription, SourceMap), Error>| {
        if let Ok((p, map)) = r {
            let _ = Lens::new(p, &map, None);
        }
    };
    // Every prefix of a pbrt table and of a Zemax file (also UTF-16, including odd lengths).
    let pbrt = read("pbrt/fisheye.10mm.dat");
    for k in 0..=pbrt.len() {
        if pbrt.is_char_boundary(k) {
            check(import_pbrt(&pbrt[..k], "p.dat", "p"));
        }
    }
    for rel in ["zmx/cooke_triplet.zmx", "zmx/cooke_triplet_utf16.zmx", "zmx/aspheric_singlet_a4.zmx"] {
        let b = bytes(rel);
        for k in 0..=b.len() {
            check(import_zemax(&b[..k], rel));
        }
    }
    // Each number of the pbrt table replaced by awkward values.
    let tokens: Vec<(usize, usize)> = {
        let mut v = Vec::new();
        let mut start = None;
        for (i, c) in pbrt.char_indices() {
            let num = c.is_ascii_digit() || c == '.' || c == '-';
            match (num, start) {
                (true, None) => start = Some(i),
                (false, Some(s)) => {
                    v.push((s, i));
                    start = None;
                }
                _ => {}
            }
        }
        v
    };
    for &(a, b) in &tokens {
        for repl in ["NaN", "1e308", "-1e308", "0", "-0", "1e-300", "-5", "x"] {
            let t = format!("{}{}{}", &pbrt[..a], repl, &pbrt[b..]);
            check(import_pbrt(&t, "p.dat", "p"));
        }
    }
    // Zemax: each numeric field replaced.
    let zmx = read("zmx/cooke_triplet.zmx");
    for (i, line) in zmx.lines().enumerate() {
        let mut toks: Vec<&str> = line.split_whitespace().collect();
        if toks.len() < 2 || toks[0] == "SURF" {
            continue;
        }
        for repl in ["NaN", "1e308", "0", "-1e-300", "INFINITY"] {
            toks[1] = repl;
            let mut lines: Vec<String> = zmx.lines().map(String::from).collect();
            lines[i] = format!("  {}", toks.join(" "));
            check(import_zemax(lines.join("\n").as_bytes(), "z.zmx"));
        }
    }
    // lentil: prefixes of the subset (every 97th byte) and each radius/thickness replaced.
    let json = read(LENTIL);
    for k in (0..json.len()).step_by(97) {
        if json.is_char_boundary(k) {
            for id in ["0001", "0014", "2004"] {
                check(import_lentil(&json[..k], LENTIL, id));
            }
        }
    }
    for key in ["\"radius\": ", "\"thickness\": ", "\"housing-radius\": "] {
        for (pos, _) in json.match_indices(key).step_by(3) {
            let start = pos + key.len();
            let end = start + json[start..].find([',', '\n']).unwrap_or(0);
            for repl in ["0", "-1", "1e300", "null", "\"x\"", "[]", "1e-300"] {
                let t = format!("{}{}{}", &json[..start], repl, &json[end..]);
                for id in ["0001", "0014", "2004"] {
                    check(import_lentil(&t, LENTIL, id));
                }
            }
        }
    }
}

/// Our TOML format: every malformed input names the file, the line and the field.
#[test]
fn toml_bad_input_names_file_line_and_field() {
    let good = "[lens]\nname = \"t\"\nsource = \"test\"\n\n[[surface]]\nthickness_mm = 2.0\nsemi_diameter_mm = 3.0\nstop = true\n\n[[surface]]\nradius_mm = 51.0\nthickness_mm = 4.0\nmaterial = \"N-BK7\"\nsemi_diameter_mm = 8.0\n\n[[surface]]\nradius_mm = -51.0\nthickness_mm = 48.0\nsemi_diameter_mm = 8.0\n";
    Lens::from_toml(good, "good.toml", None).unwrap();
    let cases: Vec<(String, usize, &str, &str)> = vec![
        // missing field: serde names it, on the table's line, with the surface's index
        (good.replace("thickness_mm = 4.0\n", ""), 10, "surface[2].thickness_mm", "missing"),
        // unknown field
        (good.replace("radius_mm = 51.0", "radius_mm = 51.0\ncolour = 3"), 12, "surface[2].colour", "unknown"),
        // unknown glass, with a suggestion
        (good.replace("\"N-BK7\"", "\"N-BK8\""), 13, "surface[2].material", "N-BK8"),
        // NaN
        (good.replace("radius_mm = -51.0", "radius_mm = nan"), 17, "surface[3].radius_mm", "finite"),
        // elements that intersect: 0.5 mm centre thickness between R 51 and R −51 at 8 mm
        (good.replace("thickness_mm = 4.0", "thickness_mm = 0.5"), 12, "surface[2].thickness_mm", "intersect"),
        // a stop larger than its housing
        (
            good.replace("stop = true", "stop = true\nhousing_semi_diameter_mm = 2.0"),
            7,
            "surface[1].semi_diameter_mm",
            "housing",
        ),
        // a semi-diameter larger than the radius allows
        (
            good.replace(
                "semi_diameter_mm = 8.0\n\n[[surface]]\nradius_mm = -51.0",
                "semi_diameter_mm = 60.0\n\n[[surface]]\nradius_mm = -51.0",
            ),
            14,
            "surface[2].semi_diameter_mm",
            "radius",
        ),
        // no stop
        (good.replace("stop = true\n", ""), 0, "surface.stop", "no aperture stop"),
        // wrong type
        (good.replace("thickness_mm = 48.0", "thickness_mm = \"far\""), 18, "surface[3].thickness_mm", "invalid type"),
    ];
    for (text, line, field, needle) in cases {
        let err = Lens::from_toml(&text, "bad.toml", None).unwrap_err();
        let msg = err.to_string();
        match err {
            Error::LensFile { file, line: l, field: f, message } => {
                assert_eq!(file, "bad.toml");
                assert_eq!((l, f.as_str()), (line, field), "{msg}");
                assert!(message.contains(needle) || msg.contains(needle), "{msg} should mention '{needle}'");
            }
            other => panic!("expected a LensFile error, got {other}"),
        }
        // a problem of the whole file names the file alone, not a line 0
        assert!(!msg.starts_with("bad.toml:0"), "{msg}");
        assert!(
            msg.starts_with(&if line == 0 { "bad.toml: ".to_string() } else { format!("bad.toml:{line}: ") }),
            "{msg}"
        );
    }
}

/// An unknown glass name gets suggestions that are near it (an edit or two, or most of its
/// letters), not any catalogue name that happens to be a substring of it.
#[test]
fn unknown_glasses_get_near_suggestions_only() {
    let msg = |name: &str| petzval_optics::glass::Material::from_catalog(name).unwrap_err().to_string();
    assert!(msg("N-BK8").ends_with("did you mean N-BK7?"), "{}", msg("N-BK8"));
    assert!(msg("LAK9X").contains("LAK9"), "{}", msg("LAK9X"));
    // K-LLF2 (not a glass; Hikari's J-LLF2 is one edit away) contains "F2" but is not F2
    let m = msg("K-LLF2");
    let suggested: Vec<&str> =
        m.split("did you mean ").nth(1).map(|l| l.trim_end_matches('?').split(", ").collect()).unwrap_or_default();
    assert!(suggested.contains(&"J-LLF2") && !suggested.contains(&"F2"), "{m}");
}

/// Issue 12: every text format reads UTF-8 with a BOM and UTF-16 (as Windows tools write them),
/// with the same result as plain UTF-8; before, JSON with a BOM was refused and UTF-16 TOML gave
/// an error without a line.
#[test]
fn every_text_format_reads_bom_and_utf16() {
    let dir = std::env::temp_dir().join(format!("petzval-encodings-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let toml = std::fs::read_to_string(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("lenses/double-gauss-50mm.toml"))
        .unwrap();
    let dat = read("pbrt/dgauss.50mm.dat");
    let json = read(LENTIL);
    let utf16le = |t: &str| -> Vec<u8> {
        let mut b = vec![0xFF, 0xFE];
        b.extend(t.encode_utf16().flat_map(|u| u.to_le_bytes()));
        b
    };
    let utf16be = |t: &str| -> Vec<u8> {
        let mut b = vec![0xFE, 0xFF];
        b.extend(t.encode_utf16().flat_map(|u| u.to_be_bytes()));
        b
    };
    let bom = |t: &str| -> Vec<u8> { [&[0xEF, 0xBB, 0xBF][..], t.as_bytes()].concat() };
    for (name, text) in [("lens.toml", &toml), ("lens.dat", &dat), ("lenses.json", &json)] {
        let plain = dir.join(format!("plain-{name}"));
        std::fs::write(&plain, text.as_bytes()).unwrap();
        let id = if name.ends_with(".json") { "#0001" } else { "" };
        let expected = read_prescription(&PathBuf::from(format!("{}{id}", plain.display()))).unwrap().0;
        for (enc, bytes) in [("bom", bom(text)), ("utf16le", utf16le(text)), ("utf16be", utf16be(text))] {
            let path = dir.join(format!("{enc}-{name}"));
            std::fs::write(&path, bytes).unwrap();
            let got = read_prescription(&PathBuf::from(format!("{}{id}", path.display())))
                .unwrap_or_else(|e| panic!("{name} as {enc}: {e}"))
                .0;
            assert_eq!(got.surfaces, expected.surfaces, "{name} as {enc}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
