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

/// `PreparedAperture` (per-blade tables, no trigonometry per point) gives the same bits as
/// `Aperture`: transmission on random points and on points within 10⁻⁶ … 10⁻¹⁶ of the blade
/// edges and vertices, and the samples of `sample_unit` (but a mask's), for straight and curved blades,
/// rotations, anamorphic ratios, a mask, a circle, a blade count past the tables, and
/// non-finite points.
#[test]
fn prepared_apertures_match_the_plain_ones_bit_for_bit() {
    use glam::DVec2;
    use petzval_optics::{Aperture, ApertureMask, ApertureShape, PreparedAperture};
    use std::sync::Arc;
    let mask = ApertureMask {
        width: 4,
        height: 4,
        transmission: (0..16).map(|i| i as f32 / 15.0).collect(),
        path: "test".into(),
    };
    let mut apertures = vec![
        Aperture::default(),
        Aperture { shape: ApertureShape::Mask(Arc::new(mask)), rotation_rad: 0.7, anamorphic_ratio: 1.0 },
        Aperture {
            shape: ApertureShape::Blades { count: 40, curvature: 0.0 },
            rotation_rad: 0.1,
            anamorphic_ratio: 1.0,
        },
    ];
    for count in [3, 5, 6, 7, 9, 16] {
        for curvature in [0.0, 0.3, 1.0] {
            for (rotation_rad, anamorphic_ratio) in [(0.0, 1.0), (0.3, 1.0), (10f64.to_radians(), 0.5), (-2.0, 1.33)] {
                apertures.push(Aperture {
                    shape: ApertureShape::Blades { count, curvature },
                    rotation_rad,
                    anamorphic_ratio,
                });
            }
        }
    }
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let radius_mm = 7.3;
    let (mut tested, mut inside, mut outside) = (0usize, 0usize, 0usize);
    for aperture in &apertures {
        let prepared = PreparedAperture::new(aperture.clone());
        let mut check = |x: f64, y: f64| {
            let (a, b) = (aperture.transmission(x, y, radius_mm), prepared.transmission(x, y, radius_mm));
            assert_eq!(a.to_bits(), b.to_bits(), "{aperture:?} at ({x}, {y}): {a} against {b}");
            tested += 1;
            if a > 0.0 {
                inside += 1;
            } else {
                outside += 1;
            }
        };
        // 1. Random points over the circumscribed square.
        for _ in 0..4000 {
            check((2.0 * next() - 1.0) * 1.1 * radius_mm, (2.0 * next() - 1.0) * 1.1 * radius_mm);
        }
        // Non-finite points and a zero radius are closed in both.
        for (x, y) in [(f64::NAN, 0.0), (0.0, f64::NAN), (f64::INFINITY, 0.0), (0.0, f64::NEG_INFINITY)] {
            check(x, y);
        }
        assert_eq!(prepared.transmission(1.0, 1.0, 0.0).to_bits(), aperture.transmission(1.0, 1.0, 0.0).to_bits());
        // 2. Points on the sampled boundary, nudged in and out by tiny steps (the samples of
        //    `sample_unit` with u.y at a triangle's edge lie on the polygon's outline).
        for i in 0..400 {
            let u = DVec2::new((i as f64 + 0.5) / 400.0, next());
            let (p, _) = aperture.sample_unit(u);
            for scale in [1.0, 1.0 + 1e-16, 1.0 - 1e-16, 1.0 + 1e-12, 1.0 - 1e-12, 1.0 + 1e-6, 1.0 - 1e-6] {
                let q = p * (scale * radius_mm);
                check(q.x, q.y);
            }
            let edge = aperture.sample_unit(DVec2::new(u.x, 0.0)).0 * radius_mm;
            check(edge.x, edge.y);
        }
        // 3. `sample_unit`: the same points and densities (a mask's are drawn by transmission
        //    instead: `mask_samples_follow_transmission`).
        let is_mask = matches!(aperture.shape, ApertureShape::Mask(_));
        for _ in 0..if is_mask { 0 } else { 2000 } {
            let u = DVec2::new(next(), next());
            let (a, b) = (aperture.sample_unit(u), prepared.sample_unit(u));
            assert_eq!(
                (a.0.x.to_bits(), a.0.y.to_bits(), a.1.to_bits()),
                (b.0.x.to_bits(), b.0.y.to_bits(), b.1.to_bits()),
                "{aperture:?} sample at {u:?}"
            );
        }
        // 4. `sample_scaled`: the scaled point, its density and the transmission test's own
        //    result, bit for bit, where it skips the test (inside a straight-blade polygon) and
        //    where it does not (u.x at a triangle's outer edge, to 10⁻¹⁶, and u.y at 0 and 1).
        let mut us: Vec<DVec2> = (0..2000).map(|_| DVec2::new(next(), next())).collect();
        for i in 0..200 {
            let k = (i % 40) as f64;
            for eps in [0.0, 1e-16, 1e-12, 1e-9, 1e-7, 1e-6, 3e-6] {
                us.push(DVec2::new(((k + 1.0) / 40.0 - eps).max(0.0), next()));
                us.push(DVec2::new(next(), if i % 2 == 0 { eps } else { 1.0 - eps }));
            }
        }
        for u in us {
            let (q, pdf) = prepared.sample_unit(u);
            let p = DVec2::new(q.x * radius_mm, q.y * radius_mm);
            let want =
                (p.x.to_bits(), p.y.to_bits(), pdf.to_bits(), prepared.transmission(p.x, p.y, radius_mm).to_bits());
            let (sp, spdf, st) = prepared.sample_scaled(u, radius_mm);
            assert_eq!(
                want,
                (sp.x.to_bits(), sp.y.to_bits(), spdf.to_bits(), st.to_bits()),
                "{aperture:?} sample_scaled at {u:?}"
            );
        }
    }
    assert!(tested >= 540_000 && inside > 100_000 && outside > 100_000, "{tested} {inside} {outside}");
}

/// A mask's lens samples are drawn in proportion to its transmission (an aperture image on an
/// ideal lens): every sample lands where the mask transmits, its weight (transmission over
/// density) is the same everywhere, `pdf_unit_at` gives the density the sample had, and the
/// samples' histogram over the pixels follows their transmission. Before, the mask's square was
/// sampled uniformly and weighted by transmission: a slit mask's lens samples were 0 or
/// 1/coverage, and in-focus areas of a thin-lens render 36× noisier (the add-on's review).
#[test]
fn mask_samples_follow_transmission() {
    use glam::DVec2;
    use petzval_optics::{Aperture, ApertureMask, ApertureShape, PreparedAperture};
    use std::sync::Arc;
    // a 6 × 4 mask: a slit of varying transmission, zero elsewhere
    let (w, h) = (6usize, 4usize);
    let transmission: Vec<f32> =
        (0..w * h).map(|i| if i / w == 1 { 0.2 + 0.15 * (i % w) as f32 } else { 0.0 }).collect();
    let total: f64 = transmission.iter().map(|&t| t as f64).sum();
    let mask = Arc::new(ApertureMask { width: w, height: h, transmission: transmission.clone(), path: "slit".into() });
    for (rotation_rad, anamorphic_ratio) in [(0.0, 1.0), (0.7, 1.0), (-0.3, 1.6)] {
        let a = PreparedAperture::new(Aperture {
            shape: ApertureShape::Mask(mask.clone()),
            rotation_rad,
            anamorphic_ratio,
        });
        let weight = total * (4.0 / (w * h) as f64) / anamorphic_ratio;
        let mut counts = vec![0usize; w * h];
        let n = 64 * 64;
        for i in 0..n {
            let u = DVec2::new((i as f64 + 0.5) / n as f64, (((i * 37) % 64) as f64 + 0.5) / 64.0);
            let (q, pdf, t) = a.sample_scaled(u, 1.0);
            assert!(t > 0.0, "sample {u:?} at {q:?} where the mask is opaque");
            assert!((t / pdf - weight).abs() < 1e-9 * weight, "weight {} against {weight}", t / pdf);
            assert!((a.pdf_unit_at(q) - pdf).abs() < 1e-9 * pdf, "pdf_unit_at {} against {pdf}", a.pdf_unit_at(q));
            // which pixel (the mask's own lookup: squeeze and rotation undone)
            let (s, c) = rotation_rad.sin_cos();
            let (x, y) = (q.x * anamorphic_ratio, q.y);
            let (mu, mv) = (c * x + s * y, -s * x + c * y);
            let px = (((mu + 1.0) * 0.5 * w as f64) as usize).min(w - 1);
            let py = (((1.0 - mv) * 0.5 * h as f64) as usize).min(h - 1);
            counts[py * w + px] += 1;
        }
        for (i, &c) in counts.iter().enumerate() {
            let want = transmission[i] as f64 / total * n as f64;
            assert!((c as f64 - want).abs() <= 2.0, "pixel {i}: {c} samples, {want:.1} expected");
        }
    }
}
