//! `--lens-model auto`: the choice on cases whose answer is known, and the consistency of the
//! choice with the measurements it reports.

use petzval_renderer::{Camera, CameraSpec, LensModel, Sensor, ShotContext};

fn shot(width: u32, height: u32, spp: u32, depth: Option<(f64, f64)>) -> ShotContext {
    ShotContext { width, height, spp, depth_range_m: depth, spectral: false }
}

#[test]
fn pinhole_sized_thin_aperture_picks_pinhole() {
    let spec = CameraSpec {
        lens: "thin".into(),
        f_number: Some(2000.0),
        focus_distance_m: Some(2.0),
        ..CameraSpec::default()
    };
    let built = spec.build(&shot(1920, 1080, 16, Some((0.5, f64::INFINITY)))).unwrap();
    assert_eq!(built.choice.model, LensModel::Pinhole, "{}", built.choice.reason);
    assert_eq!(built.camera.model(), LensModel::Pinhole);
}

#[test]
fn open_thin_lens_keeps_its_depth_of_field() {
    let spec =
        CameraSpec { lens: "thin".into(), f_number: Some(2.8), focus_distance_m: Some(2.0), ..CameraSpec::default() };
    let built = spec.build(&shot(1920, 1080, 16, Some((1.0, 10.0)))).unwrap();
    assert_eq!(built.choice.model, LensModel::Thin, "{}", built.choice.reason);
    // The same lens over a depth range inside its depth of field at a tiny resolution is a pinhole:
    // f/2.8 50 mm focused at 2 m, scene 1.99–2.01 m → CoC ≈ 0.2 µm ≪ one pixel of 36 mm / 64.
    let built = spec.build(&shot(64, 36, 16, Some((1.99, 2.01)))).unwrap();
    assert_eq!(built.choice.model, LensModel::Pinhole, "{}", built.choice.reason);
}

#[test]
fn wide_open_double_gauss_at_4k_is_not_a_thin_lens() {
    let spec = CameraSpec {
        lens: "double-gauss-50mm".into(),
        focus_distance_m: Some(2.0),
        sensor: Sensor { width_mm: 36.0, height_mm: 20.25, ..Sensor::default() },
        ..CameraSpec::default()
    };
    let built = spec.build(&shot(3840, 2160, 64, Some((1.0, f64::INFINITY)))).unwrap();
    let model = built.choice.model;
    assert!(!matches!(model, LensModel::Thin | LensModel::Pinhole), "picked {model}: {}", built.choice.reason);
    // The thin lens was measured and rejected with numbers.
    let thin = built.choice.candidates.iter().find(|c| c.model == LensModel::Thin).expect("thin evaluated");
    assert!(!thin.meets && thin.mean_error_px > spec.tolerance_px, "{thin:?}");
}

#[test]
fn the_choice_is_the_cheapest_candidate_that_meets_the_budget() {
    // A distant scene focused at infinity, many samples: a table pays for its bake.
    let spec = CameraSpec { lens: "double-gauss-50mm".into(), f_number: Some(4.0), ..CameraSpec::default() };
    let built = spec.build(&shot(1920, 1280, 256, Some((20.0, f64::INFINITY)))).unwrap();
    let c = &built.choice;
    for r in &c.candidates {
        eprintln!(
            "{:<9} mean {:.3} max {:.3} irr {:.4} ns {:.1} est {:.2} meets {} {}",
            r.model.to_string(),
            r.mean_error_px,
            r.max_error_px,
            r.irradiance_error,
            r.ns_per_ray,
            r.estimated_seconds,
            r.meets,
            r.note
        );
    }
    let chosen = c.candidates.iter().find(|r| r.model == c.model).expect("chosen is a candidate");
    assert!(chosen.meets, "{}", c.reason);
    assert!(chosen.mean_error_px <= spec.tolerance_px);
    for r in c.candidates.iter().filter(|r| r.meets) {
        assert!(chosen.estimated_seconds <= r.estimated_seconds, "{} is cheaper than the chosen {}", r.model, c.model);
    }
    // the camera is of the model chosen, under the same name
    assert_eq!(built.camera.model(), c.model);
    assert_eq!(built.camera.model().to_string(), c.model.to_string());
}

#[test]
fn lens_model_names_parse_and_bad_ones_name_the_field() {
    assert_eq!("auto".parse::<LensModel>().unwrap(), LensModel::Auto);
    assert_eq!("lrtf:64".parse::<LensModel>().unwrap(), LensModel::Lrtf { resolution: 64 });
    assert_eq!("lrtf".parse::<LensModel>().unwrap().to_string(), "lrtf:96");
    for bad in ["lrtf:x", "lrtf:2", "fast", ""] {
        let e = bad.parse::<LensModel>().unwrap_err().to_string();
        assert!(e.contains("lens_model"), "{e}");
    }
    // A table model needs a real lens.
    let spec = CameraSpec {
        lens: "thin".into(),
        f_number: Some(2.0),
        model: LensModel::Lrtf { resolution: 32 },
        ..CameraSpec::default()
    };
    let e = spec.build(&ShotContext::default()).unwrap_err().to_string();
    assert!(e.contains("needs a real lens"), "{e}");
}

/// A spectral render of a dispersive lens samples exit-pupil bounds that also hold the spectral
/// range's ends (the renderer's own range), whichever model `auto` picks; a render at one
/// wavelength gets the tighter bounds of the primary wavelength.
#[test]
fn spectral_shots_get_bounds_for_the_spectral_range() {
    use petzval_renderer::optics::pupil::SPECTRAL_RANGE_NM;
    use petzval_renderer::spectral::{LAMBDA_MAX_NM, LAMBDA_MIN_NM};
    assert_eq!(SPECTRAL_RANGE_NM, [LAMBDA_MIN_NM as f64, LAMBDA_MAX_NM as f64]);
    assert!(petzval_renderer::library_lens("nikon-normal-52mm").unwrap().has_dispersion());
    for model in [LensModel::Exact, LensModel::Auto] {
        let spec = CameraSpec {
            lens: "nikon-normal-52mm".into(),
            focus_distance_m: Some(2.0),
            model,
            ..CameraSpec::default()
        };
        for spectral in [false, true] {
            let built = spec.build(&ShotContext { spectral, ..shot(320, 200, 16, Some((1.0, 10.0))) }).unwrap();
            let exact = match &built.camera {
                Camera::Exact(c) => c,
                Camera::Lrtf(c) => c.exact(),
                other => panic!("{model:?}: a real lens built a {:?} camera", other.model()),
            };
            let ends = if spectral { SPECTRAL_RANGE_NM.to_vec() } else { Vec::new() };
            assert_eq!(exact.pupil().wavelength_ends_nm, ends, "{model:?}, spectral {spectral}");
        }
    }
}
