//! Aperture stop shapes through the real tracer: blades, anamorphic ratio and an image mask.

use glam::DVec3;
use petzval_optics::{Lens, Ray, TraceDirection};

const WL: f64 = 587.5618;

fn singlet_with(aperture: &str) -> String {
    format!(
        r#"
[lens]
name = "stop-test"
source = "test"
{aperture}
[[surface]]
thickness_mm = 2.0
semi_diameter_mm = 5.0
stop = true
[[surface]]
radius_mm = 51.0
thickness_mm = 4.0
material = "N-BK7"
semi_diameter_mm = 8.0
[[surface]]
radius_mm = -51.0
thickness_mm = 48.0
semi_diameter_mm = 8.0
"#
    )
}

/// Fraction of a grid of axial rays over the stop's bounding square that passes.
fn pass_fraction(lens: &Lens) -> f64 {
    let n = 200;
    let mut pass = 0;
    for i in 0..n {
        for j in 0..n {
            let x = -5.0 + 10.0 * (i as f64 + 0.5) / n as f64;
            let y = -5.0 + 10.0 * (j as f64 + 0.5) / n as f64;
            if let Some(t) = lens.trace(&Ray::new(DVec3::new(x, y, -1.0), DVec3::Z), WL, TraceDirection::SceneToFilm) {
                if t.transmission > 0.5 {
                    pass += 1;
                }
            }
        }
    }
    pass as f64 / (n * n) as f64
}

#[test]
fn blade_count_sets_the_area() {
    let circle = Lens::from_toml(&singlet_with(""), "t.toml", None).unwrap();
    let hexagon =
        Lens::from_toml(&singlet_with("[aperture]\nshape = \"blades\"\nblades = 6\nrotation_deg = 15"), "t.toml", None)
            .unwrap();
    let (c, h) = (pass_fraction(&circle), pass_fraction(&hexagon));
    let ratio = h / c;
    let expected = 3.0 * 3f64.sqrt() / 2.0 / std::f64::consts::PI; // hexagon / circumcircle
    assert!((ratio - expected).abs() < 0.01, "{ratio} vs {expected}");
}

#[test]
fn anamorphic_ratio_halves_the_width() {
    let circle = Lens::from_toml(&singlet_with(""), "t.toml", None).unwrap();
    let oval = Lens::from_toml(&singlet_with("[aperture]\nanamorphic_ratio = 2.0"), "t.toml", None).unwrap();
    let ratio = pass_fraction(&oval) / pass_fraction(&circle);
    assert!((ratio - 0.5).abs() < 0.01, "{ratio}");
    assert!(oval.trace(&Ray::new(DVec3::new(3.0, 0.0, -1.0), DVec3::Z), WL, TraceDirection::SceneToFilm).is_none());
    assert!(oval.trace(&Ray::new(DVec3::new(0.0, 4.0, -1.0), DVec3::Z), WL, TraceDirection::SceneToFilm).is_some());
}

#[test]
fn image_mask_blocks_where_it_is_black() {
    let dir = std::env::temp_dir().join(format!("petzval-mask-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // A mask whose right half (+x) is black.
    let mut img = image::GrayImage::new(64, 64);
    for (x, _, p) in img.enumerate_pixels_mut() {
        p.0 = [if x < 32 { 255 } else { 0 }];
    }
    img.save(dir.join("half.png")).unwrap();
    let text = singlet_with("[aperture]\nshape = \"image\"\nimage = \"half.png\"");
    std::fs::write(dir.join("lens.toml"), &text).unwrap();
    let lens = petzval_optics::load_lens_file(&dir.join("lens.toml")).unwrap();
    let left = lens.trace(&Ray::new(DVec3::new(-3.0, 1.0, -1.0), DVec3::Z), WL, TraceDirection::SceneToFilm);
    let right = lens.trace(&Ray::new(DVec3::new(3.0, 1.0, -1.0), DVec3::Z), WL, TraceDirection::SceneToFilm);
    assert!(left.is_some() && right.is_none());
    // a missing mask file is a clear error naming the file
    std::fs::write(dir.join("bad.toml"), singlet_with("[aperture]\nshape = \"image\"\nimage = \"nope.png\"")).unwrap();
    let err = petzval_optics::load_lens_file(&dir.join("bad.toml")).unwrap_err().to_string();
    assert!(err.contains("nope.png"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}
