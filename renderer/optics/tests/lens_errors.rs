//! Malformed TOML lens files: each error names the file, the line and the field's full path
//! (`surface[2].thickness_mm`, `lens.primary_wavelength_nm`, `aperture.image`), never a value
//! or a Rust type, and never panics.

use std::path::PathBuf;

/// A cemented triplet with the stop last (5 surfaces). `lens` is added to the `[lens]` table's
/// first line, `surface[k]` to the first line of surface k + 1 (where it overrides a key of the
/// same name: that key's default line is dropped), and `tail` after the last surface.
fn triplet(lens: &str, surface: [&str; 5], tail: &str) -> String {
    let defaults: [&[&str]; 5] = [
        &["radius_mm = 60.0", "thickness_mm = 6.0", "material = \"TAF1\"", "semi_diameter_mm = 14.0"],
        &["radius_mm = -40.0", "thickness_mm = 2.0", "material = \"H-ZF52\"", "semi_diameter_mm = 14.0"],
        &["radius_mm = 35.0", "thickness_mm = 5.0", "material = \"N-PK52A\"", "semi_diameter_mm = 14.0"],
        &["radius_mm = -150.0", "thickness_mm = 3.0", "semi_diameter_mm = 14.0"],
        &["thickness_mm = 90.0", "semi_diameter_mm = 10.0", "stop = true"],
    ];
    let mut t = String::from("[lens]\n");
    if !lens.is_empty() {
        t += &format!("{lens}\n");
    }
    t += "name = \"review-cemented-triplet\"\nsource = \"held-out review lens\"\n";
    for (extra, lines) in surface.iter().zip(defaults) {
        t += "\n[[surface]]\n";
        let overridden: Vec<&str> = extra.lines().filter_map(|l| l.split_once('=')).map(|(k, _)| k.trim()).collect();
        if !extra.is_empty() {
            t += &format!("{extra}\n");
        }
        for l in lines {
            let key = l.split_once('=').unwrap().0.trim();
            if !overridden.contains(&key) {
                t += &format!("{l}\n");
            }
        }
    }
    t + tail
}

/// 1-based line of the first line of `text` that starts with `what`.
fn line_of(text: &str, what: &str) -> usize {
    text.lines().position(|l| l.starts_with(what)).unwrap_or_else(|| panic!("no line {what:?} in\n{text}")) + 1
}

/// A fresh folder for this test's files.
fn folder(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("petzval-lens-errors-{}-{test}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Writes `text` as `name` and loads it; the error's message (the load must fail).
fn load_error(name: &str, text: &str) -> String {
    let dir = folder(name.trim_end_matches(".toml"));
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    let result = petzval_optics::load_lens_file(&path);
    std::fs::remove_dir_all(&dir).ok();
    match result {
        Ok(_) => panic!("{name} loaded:\n{text}"),
        Err(e) => e.to_string(),
    }
}

/// Asserts that `err` starts with `FILE:LINE: FIELD: ` for the file `name`.
fn assert_names(err: &str, name: &str, line: usize, field: &str) {
    let want = format!("{name}:{line}: {field}: ");
    assert!(err.contains(&want), "expected `{want}` in: {err}");
}

#[test]
fn a_value_of_the_wrong_type_names_the_field_not_the_value() {
    let text = triplet("", ["aspheric = 1e-5", "", "", "", ""], "");
    let err = load_error("aspheric_wrong_type.toml", &text);
    assert_names(&err, "aspheric_wrong_type.toml", line_of(&text, "aspheric ="), "surface[1].aspheric");
    assert!(err.contains("list"), "{err}");

    let text = triplet("", ["", "", "", "thickness_mm = \"6\"", ""], "");
    let err = load_error("thickness_string.toml", &text);
    assert_names(&err, "thickness_string.toml", line_of(&text, "thickness_mm = \"6\""), "surface[4].thickness_mm");
}

#[test]
fn an_unknown_variant_names_the_field_not_the_value() {
    let text = triplet("", ["cylinder = \"z\"", "", "", "", ""], "");
    let err = load_error("cylinder_bad.toml", &text);
    assert_names(&err, "cylinder_bad.toml", line_of(&text, "cylinder ="), "surface[1].cylinder");
    assert!(err.contains("`x` or `y`"), "{err}");
}

#[test]
fn a_bad_material_says_what_is_wrong_and_what_is_accepted() {
    let text = triplet("", ["", "", "material = { nd = 1.5, vd = 60, ng = 1.6 }", "", ""], "");
    let err = load_error("model_glass_extra.toml", &text);
    assert_names(&err, "model_glass_extra.toml", line_of(&text, "material = {"), "surface[3].material");
    assert!(err.contains("`ng`") && err.contains("glass name") && err.contains("nd"), "{err}");
    assert!(!err.contains("MaterialSpec") && !err.contains("untagged"), "a Rust type leaks: {err}");

    // neither a name nor a table
    let text = triplet("", ["", "material = 1.5", "", "", ""], "");
    let err = load_error("material_number.toml", &text);
    assert_names(&err, "material_number.toml", line_of(&text, "material = 1.5"), "surface[2].material");
    assert!(err.contains("glass name") && !err.contains("MaterialSpec"), "{err}");

    // a model glass without its index
    let text = triplet("", ["", "", "", "material = { vd = 60 }", ""], "");
    let err = load_error("material_no_nd.toml", &text);
    assert_names(&err, "material_no_nd.toml", line_of(&text, "material = {"), "surface[4].material");
    assert!(err.contains("`nd`"), "{err}");

    // the good forms still load
    let text = triplet("", ["", "", "material = { nd = 1.5, vd = 60 }", "", ""], "");
    let dir = folder("material_good");
    std::fs::write(dir.join("good.toml"), &text).unwrap();
    let lens = petzval_optics::load_lens_file(&dir.join("good.toml"));
    std::fs::remove_dir_all(&dir).ok();
    lens.unwrap();
}

#[test]
fn a_diverging_lens_names_its_file() {
    let text = r#"
[lens]
name = "review-diverging"
source = "test"
[[surface]]
radius_mm = -40.0
thickness_mm = 3.0
material = "N-BK7"
semi_diameter_mm = 10.0
[[surface]]
radius_mm = 40.0
thickness_mm = 5.0
semi_diameter_mm = 10.0
[[surface]]
thickness_mm = 30.0
semi_diameter_mm = 8.0
stop = true
"#;
    let dir = folder("diverging");
    let path = dir.join("diverging.toml");
    std::fs::write(&path, text).unwrap();
    let lens = petzval_optics::load_lens_file(&path).unwrap();
    std::fs::remove_dir_all(&dir).ok();
    let err = lens.focus_image_distance_mm(None).unwrap_err().to_string();
    assert!(err.contains("diverging.toml") && err.contains("diverging lens"), "{err}");
}

#[test]
fn a_missing_aperture_image_names_the_lens_file_line_and_field() {
    let text = triplet("", ["", "", "", "", ""], "\n[aperture]\nshape = \"image\"\nimage = \"nope.png\"\n");
    let err = load_error("bad_aperture_image.toml", &text);
    assert_names(&err, "bad_aperture_image.toml", line_of(&text, "image ="), "aperture.image");
    assert!(err.contains("nope.png") && err.contains("not a regular file"), "{err}");
}

#[test]
fn lens_table_errors_give_the_fields_own_line() {
    let text = triplet("primary_wavelength_nm = 1000.0", ["", "", "", "", ""], "");
    let err = load_error("wavelength_bad.toml", &text);
    assert_names(&err, "wavelength_bad.toml", line_of(&text, "primary_wavelength_nm"), "lens.primary_wavelength_nm");

    let text = triplet("stop_semi_diameter_mm = 12.0", ["", "", "", "", ""], "");
    let err = load_error("stop_sd_over_housing.toml", &text);
    assert_names(&err, "stop_sd_over_housing.toml", line_of(&text, "stop_semi_"), "lens.stop_semi_diameter_mm");

    let text = triplet("", ["", "", "", "", ""], "\n[aperture]\nshape = \"blades\"\nblade_curvature = 2.0\n");
    let err = load_error("blade_curvature.toml", &text);
    assert_names(&err, "blade_curvature.toml", line_of(&text, "blade_curvature"), "aperture.blade_curvature");
}

#[test]
fn parse_errors_in_a_surface_name_its_index() {
    // a missing field: the line of the surface's header
    let text = triplet("", ["", "thickness_mm = 2.0", "", "", ""], "").replacen("thickness_mm = 2.0\n", "", 1);
    let err = load_error("missing_thickness.toml", &text);
    let header = text.lines().enumerate().filter(|(_, l)| *l == "[[surface]]").nth(1).unwrap().0 + 1;
    assert_names(&err, "missing_thickness.toml", header, "surface[2].thickness_mm");
    assert!(err.contains("missing field"), "{err}");

    let text = triplet("", ["", "", "", "", ""], "").replace("semi_diameter_mm = 10.0\n", "");
    let err = load_error("missing_semi_diameter.toml", &text);
    let header = text.lines().enumerate().filter(|(_, l)| *l == "[[surface]]").nth(4).unwrap().0 + 1;
    assert_names(&err, "missing_semi_diameter.toml", header, "surface[5].semi_diameter_mm");

    let text = triplet("", ["thicknes_mm = 1.0", "", "", "", ""], "");
    let err = load_error("unknown_field.toml", &text);
    assert_names(&err, "unknown_field.toml", line_of(&text, "thicknes_mm"), "surface[1].thicknes_mm");
    assert!(err.contains("unknown field"), "{err}");

    // in other tables, the table's name
    let text = triplet("nmae = \"x\"", ["", "", "", "", ""], "");
    let err = load_error("unknown_lens_field.toml", &text);
    assert_names(&err, "unknown_lens_field.toml", line_of(&text, "nmae"), "lens.nmae");

    let text = triplet("", ["", "", "", "", ""], "\n[aperture]\nblades = \"six\"\n");
    let err = load_error("blades_string.toml", &text);
    assert_names(&err, "blades_string.toml", line_of(&text, "blades ="), "aperture.blades");

    // a list over several lines: the key that starts it
    let text = triplet("", ["", "", "aspheric = [\n  1.0e-6,\n  \"x\",\n]", "", ""], "");
    let err = load_error("aspheric_multiline.toml", &text);
    assert_names(&err, "aspheric_multiline.toml", line_of(&text, "  \"x\""), "surface[3].aspheric");
}

#[test]
fn huge_and_tiny_numbers_print_compactly() {
    let text = triplet("", ["", "", "", "", "thickness_mm = 1e300"], "");
    let err = load_error("huge_thickness.toml", &text);
    assert_names(&err, "huge_thickness.toml", line_of(&text, "thickness_mm = 1e300"), "surface[5].thickness_mm");
    assert!(err.contains("1e300") && err.len() < 200, "{err}");

    let text = triplet("", ["", "", "material = { nd = 1.5, vd = 1e-300 }", "", ""], "");
    let err = load_error("tiny_abbe.toml", &text);
    assert_names(&err, "tiny_abbe.toml", line_of(&text, "material = {"), "surface[3].material");
    assert!(err.contains("1e-300") && err.len() < 200, "{err}");
}
