//! Optics: hard numerical cases, property tests and exit-pupil bounds against brute force.

use glam::{DVec2, DVec3};
use petzval_optics::pupil::{ExitPupilBounds, DEFENSIVE_FRACTION, SPECTRAL_RANGE_NM};
use petzval_optics::{library_lens, Absorbed, Lens, Ray, StopMode, TraceDirection};
use proptest::prelude::*;

const WL: f64 = 587.5618;

fn lens(text: &str) -> Lens {
    Lens::from_toml(text, "test.toml", None).expect("test lens must build")
}

/// A thick N-BK7 slab between two planes, 10 mm thick.
const PLATE: &str = r#"
[lens]
name = "plate"
source = "test"
[[surface]]
thickness_mm = 1.0
semi_diameter_mm = 20.0
stop = true
[[surface]]
thickness_mm = 10.0
material = { nd = 1.5, vd = 0 }
semi_diameter_mm = 20.0
[[surface]]
thickness_mm = 20.0
semi_diameter_mm = 20.0
"#;

#[test]
fn plane_parallel_plate_shifts_ray_by_snell() {
    let l = lens(PLATE);
    let theta: f64 = 0.4;
    let d = DVec3::new(theta.sin(), 0.0, theta.cos());
    let out = l.trace(&Ray::new(DVec3::new(0.0, 0.0, -5.0), d), WL, TraceDirection::SceneToFilm).unwrap();
    // direction unchanged, lateral offset inside the slab = t·tan θ'
    assert!((out.ray.direction - d).length() < 1e-14);
    let theta_t = (theta.sin() / 1.5).asin();
    let x_expected = 6.0 * theta.tan() + 10.0 * theta_t.tan();
    assert!((out.ray.origin.x - x_expected).abs() < 1e-12, "{} vs {x_expected}", out.ray.origin.x);
    assert!((out.ray.origin.z - 11.0).abs() < 1e-12);
}

#[test]
fn on_axis_ray_stays_on_axis() {
    for name in ["double-gauss-50mm", "fisheye-10mm", "telephoto-250mm", "wide-22mm"] {
        let l = library_lens(name).unwrap();
        let out = l.trace(&Ray::new(DVec3::new(0.0, 0.0, -10.0), DVec3::Z), WL, TraceDirection::SceneToFilm).unwrap();
        assert_eq!(out.ray.origin.x, 0.0, "{name}");
        assert_eq!(out.ray.origin.y, 0.0, "{name}");
        assert_eq!(out.ray.direction, DVec3::Z, "{name}");
    }
}

#[test]
fn total_internal_reflection_is_absorbed() {
    let prism = lens(
        r#"
[lens]
name = "steep"
source = "test"
[[surface]]
thickness_mm = 1.0
semi_diameter_mm = 9.0
stop = true
[[surface]]
radius_mm = 0
thickness_mm = 3.0
material = { nd = 1.9, vd = 0 }
semi_diameter_mm = 9.0
[[surface]]
radius_mm = 10.0
thickness_mm = 20.0
semi_diameter_mm = 9.0
"#,
    );
    // A parallel ray at height 8 mm meets the back sphere (R = 10) at incidence asin(0.8) = 53° > critical 31.8°.
    let res = prism.trace_detailed(
        &Ray::new(DVec3::new(0.0, 8.0, -1.0), DVec3::Z),
        WL,
        TraceDirection::SceneToFilm,
        StopMode::Apply,
    );
    assert_eq!(res.err(), Some(Absorbed::TotalInternalReflection(2)));
}

#[test]
fn grazing_and_tangent_rays_never_nan() {
    let l = library_lens("double-gauss-50mm").unwrap();
    let mut n_pass = 0;
    for i in 0..2000 {
        let a = (i as f64 / 2000.0) * std::f64::consts::FRAC_PI_2 * 0.9999;
        let d = DVec3::new(a.sin(), 0.0, a.cos());
        for y in [-12.0, -6.0, 0.0, 6.0, 12.0] {
            let ray = Ray::new(DVec3::new(-30.0 * a.tan(), y, -30.0), d);
            if let Some(t) = l.trace(&ray, WL, TraceDirection::SceneToFilm) {
                assert!(t.ray.origin.is_finite() && t.ray.direction.is_finite());
                assert!((t.ray.direction.length() - 1.0).abs() < 1e-12);
                n_pass += 1;
            }
        }
    }
    assert!(n_pass > 0);
    // A ray exactly tangent to the first sphere (R = 29.475) at its apex height is a miss, not NaN.
    let r = 29.475;
    let tangent = Ray::new(DVec3::new(0.0, r, r - 50.0), DVec3::Z);
    let res = l.trace_detailed(&tangent, WL, TraceDirection::SceneToFilm, StopMode::Apply);
    assert!(res.is_err());
}

#[test]
fn ray_through_exact_edge_passes_and_just_beyond_is_clipped() {
    let l = lens(PLATE);
    let at_edge = Ray::new(DVec3::new(20.0, 0.0, -1.0), DVec3::Z);
    assert!(l.trace(&at_edge, WL, TraceDirection::SceneToFilm).is_some());
    let beyond = Ray::new(DVec3::new(20.0 + 1e-9, 0.0, -1.0), DVec3::Z);
    assert_eq!(
        l.trace_detailed(&beyond, WL, TraceDirection::SceneToFilm, StopMode::Apply).err(),
        Some(Absorbed::Clipped(0))
    );
}

#[test]
fn huge_radius_behaves_like_a_plane() {
    let flat = lens(&PLATE.replace("radius_mm = 0\n", ""));
    let curved = lens(&PLATE.replacen("thickness_mm = 10.0", "radius_mm = 1e5\nthickness_mm = 10.0", 1));
    let d = DVec3::new(0.2, 0.1, 1.0).normalize();
    let r = Ray::new(DVec3::new(3.0, -2.0, -5.0), d);
    let a = flat.trace(&r, WL, TraceDirection::SceneToFilm).unwrap();
    let b = curved.trace(&r, WL, TraceDirection::SceneToFilm).unwrap();
    // sag at r ≈ 4 mm is 8e-5 mm; the refracted directions differ by ~ r/R
    assert!((a.ray.direction - b.ray.direction).length() < 1e-4);
    assert!(b.ray.origin.is_finite());
}

#[test]
fn f_0_95_lens_traces_marginal_rays() {
    let l = lens(
        r#"
[lens]
name = "fast"
source = "test: biconvex f ≈ 50 mm opened to f/0.95"
[[surface]]
thickness_mm = 0.5
semi_diameter_mm = 27.0
stop = true
[[surface]]
radius_mm = 45.0
thickness_mm = 22.0
material = { nd = 1.9, vd = 0 }
semi_diameter_mm = 28.0
[[surface]]
radius_mm = -200.0
thickness_mm = 20.0
semi_diameter_mm = 28.0
"#,
    );
    let l = l.stopped_down(0.95).unwrap();
    assert!((l.paraxial().f_number - 0.95).abs() < 1e-9);
    let h = 0.5 * l.paraxial().entrance_pupil_diameter_mm;
    let out = l.trace(&Ray::new(DVec3::new(0.0, 0.999 * h, -1.0), DVec3::Z), WL, TraceDirection::SceneToFilm).unwrap();
    assert!(out.ray.direction.is_finite());
    assert!(out.ray.direction.y < -0.4, "marginal ray must converge steeply at f/0.95");
    assert!(l.stopped_down(0.5).is_err(), "cannot open past the stop's housing");
}

/// Parallel rays at `field_deg` from the axis (in the x–z plane, from the scene) over a wide grid
/// in front of the lens: how many pass, with every output finite.
fn rays_passing_at_field(l: &Lens, field_deg: f64) -> usize {
    let a = field_deg.to_radians();
    let d = DVec3::new(a.sin(), 0.0, a.cos());
    let front = l.surfaces()[0].semi_diameter_mm;
    // a grid on the plane through the axis point (0, 0, front/2) perpendicular to the beam
    let e1 = DVec3::new(a.cos(), 0.0, -a.sin());
    let centre = DVec3::new(0.0, 0.0, 0.5 * front);
    let mut pass = 0;
    for i in 0..1200 {
        for j in 0..100 {
            let u = -3.0 * front + 6.0 * front * i as f64 / 1199.0;
            let v = -front + 2.0 * front * j as f64 / 99.0;
            let p = centre + e1 * u + DVec3::Y * v - d * 100.0;
            if let Some(t) = l.trace(&Ray::new(p, d), WL, TraceDirection::SceneToFilm) {
                assert!(t.ray.origin.is_finite() && t.ray.direction.is_finite());
                pass += 1;
            }
        }
    }
    pass
}

#[test]
fn fisheyes_pass_light_at_their_full_field() {
    // Muller 155.9° fisheye (pbrt data): light passes up to about 76.6° from the axis (153°
    // full field); the design's 155.9° needs a front element larger than the file's 30.34 mm
    // aperture, and optiland's trace agrees on the vignetting (tests/optics).
    let l = library_lens("fisheye-10mm").unwrap();
    assert!(rays_passing_at_field(&l, 76.5) > 0, "fisheye-10mm passes nothing at 76.5°");
    assert_eq!(rays_passing_at_field(&l, 77.9), 0, "the file's apertures cut the beam before 77.9°");
    // the 181° aspheric fisheye: light from 90.5°, i.e. from behind the front vertex plane
    let a = library_lens("aspheric-fisheye-10mm").unwrap();
    assert!(rays_passing_at_field(&a, 90.5) > 0, "aspheric-fisheye-10mm passes nothing at 90.5°");
}

#[test]
fn aspheric_newton_failure_is_absorbed_not_nan() {
    let wild = lens(
        r#"
[lens]
name = "wild"
source = "test: absurd aspheric coefficients"
[[surface]]
thickness_mm = 1.0
semi_diameter_mm = 10.0
stop = true
[[surface]]
radius_mm = 20.0
thickness_mm = 5.0
material = { nd = 1.5, vd = 0 }
semi_diameter_mm = 1.0
aspheric = [1e-1, -1e-1, 1e-1]
[[surface]]
radius_mm = -20.0
thickness_mm = 20.0
semi_diameter_mm = 1.0
"#,
    );
    let mut absorbed = 0;
    for i in 0..400 {
        let y = -12.0 + 24.0 * i as f64 / 400.0;
        let d = DVec3::new(0.0, 0.3, 1.0).normalize();
        match wild.trace(&Ray::new(DVec3::new(0.0, y, -1.0), d), WL, TraceDirection::SceneToFilm) {
            Some(t) => assert!(t.ray.origin.is_finite() && t.ray.direction.is_finite()),
            None => absorbed += 1,
        }
    }
    assert!(absorbed > 0);
}

fn arb_scene_ray() -> impl Strategy<Value = (f64, f64, f64, f64)> {
    (-10.0..10.0f64, -10.0..10.0f64, -0.3..0.3f64, -0.3..0.3f64)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    /// Forward then backward returns the ray within 1e-9 mm.
    #[test]
    fn forward_then_backward_returns_the_ray((x, y, dx, dy) in arb_scene_ray()) {
        let l = library_lens("double-gauss-50mm").unwrap();
        let ray = Ray::new(DVec3::new(x, y, -5.0), DVec3::new(dx, dy, 1.0));
        if let Some(fwd) = l.trace(&ray, WL, TraceDirection::SceneToFilm) {
            let back_in = Ray::new(fwd.ray.origin + fwd.ray.direction * 30.0, -fwd.ray.direction);
            let back = l.trace(&back_in, WL, TraceDirection::FilmToScene).expect("the reverse ray must pass");
            // back.origin lies on the first surface, on the original ray's line
            let v = back.ray.origin - ray.origin;
            let off_line = (v - ray.direction * v.dot(ray.direction)).length();
            prop_assert!(off_line < 1e-9, "off line by {off_line}");
            prop_assert!((back.ray.direction + ray.direction).length() < 1e-9);
        }
    }

    /// The soft-clipping trace agrees with the hard one: its clearance is non-negative exactly
    /// when the hard trace passes (up to 1e-9 mm at a rim), and a passing ray comes out the same.
    /// Checked on the open Double Gauss and on a hexagonal, curved-blade stop.
    #[test]
    fn soft_clearance_sign_matches_the_hard_trace((x, y, dx, dy) in arb_scene_ray(), blades in 0u32..2) {
        let open = library_lens("double-gauss-50mm").unwrap();
        let l = if blades == 1 {
            let shape = petzval_optics::ApertureShape::Blades { count: 6, curvature: 0.4 };
            open.with_aperture(petzval_optics::Aperture { shape, rotation_rad: 0.3, anamorphic_ratio: 1.0 })
                .stopped_down(4.0).unwrap()
        } else {
            open
        };
        let ones = vec![1.0; l.surfaces().len()];
        let ray = Ray::new(DVec3::new(x, y, -5.0), DVec3::new(dx, dy, 1.0));
        let hard = l.trace(&ray, WL, TraceDirection::SceneToFilm);
        match (hard, l.trace_soft(&ray, WL, TraceDirection::SceneToFilm, &ones)) {
            (Some(h), Ok((s, c))) => {
                prop_assert!(c >= -1e-9, "passing ray with clearance {c}");
                prop_assert!((h.ray.origin - s.ray.origin).length() < 1e-12);
                prop_assert!((h.ray.direction - s.ray.direction).length() < 1e-12);
            }
            (None, Ok((_, c))) => prop_assert!(c <= 1e-9, "absorbed ray with clearance {c}"),
            (Some(_), Err(a)) => prop_assert!(false, "soft trace lost a passing ray: {a:?}"),
            (None, Err(_)) => {}
        }
    }

    /// Tracing commutes with rotation about the optical axis.
    #[test]
    fn tracing_commutes_with_rotation((x, y, dx, dy) in arb_scene_ray(), angle in 0.0..std::f64::consts::TAU) {
        let l = library_lens("double-gauss-50mm").unwrap();
        let rot = glam::DMat3::from_rotation_z(angle);
        let ray = Ray::new(DVec3::new(x, y, -5.0), DVec3::new(dx, dy, 1.0));
        let rray = Ray::new(rot * ray.origin, rot * ray.direction);
        let a = l.trace(&ray, WL, TraceDirection::SceneToFilm);
        let b = l.trace(&rray, WL, TraceDirection::SceneToFilm);
        match (a, b) {
            (Some(a), Some(b)) => {
                prop_assert!((rot * a.ray.origin - b.ray.origin).length() < 1e-9);
                prop_assert!((rot * a.ray.direction - b.ray.direction).length() < 1e-9);
            }
            (None, None) => {}
            _ => prop_assert!(false, "vignetting must not depend on the azimuth"),
        }
    }
}

/// Uniform numbers in [0, 1) from a 64-bit LCG seeded with `seed` (the brute-force tests' rays).
fn uniform(seed: u64) -> impl FnMut() -> f64 {
    let mut state = seed;
    move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// A brute-force ray: a film point uniform in the disc of radius `r_max` on the sensor plane
/// `film_z + slope · (x, y)`, and a rear-plane point uniform in the square of half side `rear`
/// (four draws of `rnd`). Returns (film point's x, y; film point; rear point).
fn random_ray(
    rnd: &mut impl FnMut() -> f64,
    r_max: f64,
    film_z: f64,
    slope: DVec2,
    rear: f64,
    l: &Lens,
) -> (DVec2, DVec3, DVec3) {
    let r = r_max * rnd().sqrt();
    let phi = std::f64::consts::TAU * rnd();
    let f = DVec2::new(r * phi.cos(), r * phi.sin());
    let film = DVec3::new(f.x, f.y, film_z + slope.dot(f));
    let q = DVec3::new(rear * (2.0 * rnd() - 1.0), rear * (2.0 * rnd() - 1.0), l.last_vertex_z_mm());
    (f, film, q)
}

/// Exit-pupil bounds never cut off a ray that passes (brute force over the rear plane).
#[test]
fn exit_pupil_bounds_contain_every_passing_ray() {
    let blades = petzval_optics::Aperture {
        shape: petzval_optics::ApertureShape::Blades { count: 5, curvature: 0.0 },
        rotation_rad: 0.4,
        anamorphic_ratio: 1.0,
    };
    let lenses = vec![
        ("double-gauss-50mm", library_lens("double-gauss-50mm").unwrap()),
        ("wide-22mm", library_lens("wide-22mm").unwrap()),
        ("telephoto-250mm", library_lens("telephoto-250mm").unwrap()),
        ("fisheye-10mm", library_lens("fisheye-10mm").unwrap()),
        ("aspheric-fisheye-10mm", library_lens("aspheric-fisheye-10mm").unwrap()),
        (
            "double-gauss-50mm f/4 5 blades",
            library_lens("double-gauss-50mm").unwrap().stopped_down(4.0).unwrap().with_aperture(blades.clone()),
        ),
        ("double-gauss-50mm wide open 5 blades", library_lens("double-gauss-50mm").unwrap().with_aperture(blades)),
        ("schneider-anamorphic-31mm", library_lens("schneider-anamorphic-31mm").unwrap()),
    ];
    for (name, l) in lenses {
        let film_z = l.last_vertex_z_mm() + l.focus_image_distance_mm(None).unwrap();
        let (passed, outside, sampled_in_bounds, pass_in_bounds) = brute_force_bounds(&l, film_z, 200_000, 12345);
        assert!(passed > 1000, "{name}: too few passing rays ({passed})");
        assert_eq!(outside, 0, "{name}: {outside} of {passed} passing rays fall outside the bounds");
        let rejection = 1.0 - pass_in_bounds as f64 / sampled_in_bounds as f64;
        eprintln!("{name}: rejection inside bounds {:.1}%", 100.0 * rejection);
        // issue 14: at most 20 % of the rays sampled in the domain are absorbed; the bladed
        // stop at f/4 too, now outlined per film cell (29 % in its circumscribed circle before).
        // Wide open, the 5-blade stop: 22.9 % (21.8–22.4 % before its cells took 9 film points
        // and raised their corners; its circumscribed circle would let about a
        // third be absorbed: the pentagon fills 76 % of it). The anamorphic lens, also per film
        // cell: at most 35 % (70 % with its former union box).
        let limit = if name.contains("anamorphic") {
            0.35
        } else if name.contains("wide open") {
            0.25
        } else {
            0.20
        };
        assert!(rejection <= limit, "{name}: {:.1}% of the rays sampled in the bounds are absorbed", 100.0 * rejection);
    }
}

/// Brute force against the bounds for film plane `film_z` over a 21.7 mm film radius: `rays`
/// rays from random film points to random points of the rear plane (a square of 1.5× its
/// semi-diameter), a third each at the primary wavelength (against the primary bounds) and at
/// the spectral range's ends (against the spectral bounds, which spectral renders sample at
/// every wavelength). Returns (passing rays, passing rays outside their bounds, primary rays
/// sampled inside the bounds, and of those the passing ones). Asserts that every passing ray has
/// a positive sampling density (the defensive disc holds it, inside the bounds or not).
fn brute_force_bounds(l: &Lens, film_z: f64, rays: usize, seed: u64) -> (usize, usize, usize, usize) {
    let r_max = 21.7;
    let b = ExitPupilBounds::compute(l, film_z, 0.0, r_max);
    let spectral = ExitPupilBounds::compute_spectral(l, film_z, 0.0, r_max);
    let rear = 1.5 * l.rear_semi_diameter_mm();
    let mut rnd = uniform(seed);
    let (mut passed, mut outside, mut sampled_in_bounds, mut pass_in_bounds) = (0, 0, 0, 0);
    for i in 0..rays {
        let (_, film, q) = random_ray(&mut rnd, r_max, film_z, DVec2::ZERO, rear, l);
        let wl = [WL, SPECTRAL_RANGE_NM[0], SPECTRAL_RANGE_NM[1]][i % 3];
        let ok = l.trace(&Ray::new(film, q - film), wl, TraceDirection::FilmToScene).is_some();
        let bounds = if i % 3 == 0 { &b } else { &spectral };
        let inside = bounds.contains(DVec2::new(film.x, film.y), DVec2::new(q.x, q.y));
        if inside && i % 3 == 0 {
            sampled_in_bounds += 1;
            pass_in_bounds += ok as usize;
        }
        if ok {
            passed += 1;
            outside += !inside as usize;
            let density = bounds.pdf_area(DVec2::new(film.x, film.y), DVec2::new(q.x, q.y));
            assert!(density > 0.0, "{}: a passing ray at {wl} nm has no sampling density", l.name());
        }
    }
    (passed, outside, sampled_in_bounds, pass_in_bounds)
}

/// Every lens of the library, wide open at infinity and at 0.6 m, and at f/8 focused at 1 m:
/// no passing ray falls outside the bounds (300 000 rays each). Stopped down, the image circle
/// of aspheric-fisheye-10mm ends in regions smaller than the bounds' grid at 380 nm (lateral
/// colour carries the blue image circle past the primary one): before the rim's finer trace,
/// 1 of its 262 passing rays fell outside.
#[test]
fn exit_pupil_bounds_hold_for_every_library_lens() {
    for entry in petzval_optics::LIBRARY {
        let lens = library_lens(entry.name).unwrap();
        for (f_number, focus_mm) in [(None, None), (None, Some(600.0)), (Some(8.0), Some(1000.0))] {
            let l = match f_number {
                Some(n) => lens.stopped_down(n).unwrap(),
                None => lens.clone(),
            };
            let film_z = l.last_vertex_z_mm() + l.focus_image_distance_mm(focus_mm).unwrap();
            let (passed, outside, _, _) = brute_force_bounds(&l, film_z, 300_000, 999);
            let stop = f_number.map_or("wide open".to_string(), |n| format!("at f/{n}"));
            let focus = focus_mm.map_or("at infinity".to_string(), |d| format!("focused at {d} mm"));
            let case = format!("{} {stop}, {focus}", entry.name);
            assert!(passed > 200, "{case}: too few passing rays ({passed})");
            assert_eq!(outside, 0, "{case}: {outside} of {passed} passing rays fall outside the bounds");
        }
    }
}

/// A stress sweep of the film cells (not run by default: `cargo test --release -p
/// petzval-optics --test optics exit_pupil_bounds_stress -- --ignored --nocapture`, with
/// PETZVAL_STRESS_SEED to change the rays): every library lens with 5 blades at f/4 focused at
/// 1 m, 7 blades wide open, a round stop on a sensor tilted 5°, and 6 blades at f/8 on a
/// sensor tilted about both axes, 400 000 rays each. Every passing ray must have a positive
/// sampling density. The traced bounds alone missed a ray now and then (seeds 5 and 123: one
/// passing ray outside in 2 of the 208 case-seed runs over seeds 4242, 77, 5 and 123;
/// docs/performance.md, session 20; none since session 37's rim cells); the defensive disc
/// holds those, and the count is printed.
#[test]
#[ignore]
fn exit_pupil_bounds_stress_bladed_and_tilted() {
    let seed = std::env::var("PETZVAL_STRESS_SEED").ok().and_then(|s| s.parse().ok()).unwrap_or(4242u64);
    let blades = |count: u32, rotation_rad: f64| petzval_optics::Aperture {
        shape: petzval_optics::ApertureShape::Blades { count, curvature: 0.0 },
        rotation_rad,
        anamorphic_ratio: 1.0,
    };
    let (mut failures, mut misses) = (Vec::new(), 0);
    for entry in petzval_optics::LIBRARY {
        let lens = library_lens(entry.name).unwrap();
        let stopped = |n: f64| lens.stopped_down(n).unwrap_or_else(|_| lens.clone());
        let cases = [
            ("5 blades f/4, 1 m", stopped(4.0).with_aperture(blades(5, 0.3)), Some(1000.0), DVec2::ZERO),
            ("7 blades wide open", lens.with_aperture(blades(7, 0.1)), None, DVec2::ZERO),
            ("round stop, tilted", lens.clone(), Some(2000.0), DVec2::new(5f64.to_radians().tan(), 0.0)),
            ("6 blades f/8, tilted", stopped(8.0).with_aperture(blades(6, 0.0)), Some(1500.0), DVec2::new(0.03, -0.05)),
        ];
        for (case, l, focus_mm, slope) in cases {
            let film_z = l.last_vertex_z_mm() + l.focus_image_distance_mm(focus_mm).unwrap();
            let r_max = 21.7;
            let spectral = l.has_dispersion();
            let b = if slope == DVec2::ZERO {
                ExitPupilBounds::compute_spectral(&l, film_z, 0.0, r_max)
            } else {
                ExitPupilBounds::compute_on_plane(&l, film_z, slope.length() * r_max, slope, r_max, spectral)
            };
            let rear = 1.5 * l.rear_semi_diameter_mm();
            let mut rnd = uniform(seed);
            let (mut passed, mut outside, mut no_density) = (0, 0, 0);
            for i in 0..400_000 {
                let (f, film, q) = random_ray(&mut rnd, r_max, film_z, slope, rear, &l);
                let wl = if spectral { [WL, SPECTRAL_RANGE_NM[0], SPECTRAL_RANGE_NM[1]][i % 3] } else { WL };
                if l.trace(&Ray::new(film, q - film), wl, TraceDirection::FilmToScene).is_some() {
                    passed += 1;
                    outside += !b.contains(f, DVec2::new(q.x, q.y)) as usize;
                    let density = b.pdf_area(f, DVec2::new(q.x, q.y));
                    no_density += (density.is_nan() || density <= 0.0) as usize;
                }
            }
            eprintln!(
                "{} {case}: {outside} of {passed} passing rays outside the traced bounds, {no_density} without density",
                entry.name
            );
            misses += outside;
            if no_density > 0 {
                failures.push(format!("{} {case}: {no_density} of {passed}", entry.name));
            }
        }
    }
    eprintln!("{misses} passing rays outside the traced bounds in all (the defensive disc holds them)");
    assert!(failures.is_empty(), "passing rays without sampling density: {failures:?}");
}

/// On a tilted sensor (6° about y, 4° about x) the bounds still hold every passing ray: the radial
/// outlines over the plane's z span, the film cells (anamorphic lens, bladed stop) at each film
/// point's own z on the plane.
#[test]
fn exit_pupil_bounds_hold_on_a_tilted_sensor() {
    let blades = petzval_optics::Aperture {
        shape: petzval_optics::ApertureShape::Blades { count: 6, curvature: 0.0 },
        rotation_rad: 10f64.to_radians(),
        anamorphic_ratio: 1.0,
    };
    let demo_blades = petzval_optics::Aperture {
        shape: petzval_optics::ApertureShape::Blades { count: 7, curvature: 0.0 },
        rotation_rad: 10f64.to_radians(),
        anamorphic_ratio: 1.0,
    };
    let lenses = vec![
        ("double-gauss-50mm", library_lens("double-gauss-50mm").unwrap()),
        (
            "double-gauss-50mm wide open 7 blades",
            library_lens("double-gauss-50mm").unwrap().with_aperture(demo_blades.clone()),
        ),
        (
            "double-gauss-50mm f/2.1 7 blades (the demo)",
            library_lens("double-gauss-50mm").unwrap().stopped_down(2.1).unwrap().with_aperture(demo_blades),
        ),
        (
            "double-gauss-50mm f/2.8 6 blades",
            library_lens("double-gauss-50mm").unwrap().stopped_down(2.8).unwrap().with_aperture(blades),
        ),
        ("schneider-anamorphic-31mm", library_lens("schneider-anamorphic-31mm").unwrap()),
    ];
    let slope = DVec2::new(6f64.to_radians().tan(), 4f64.to_radians().tan());
    for (name, l) in lenses {
        let film_z = l.last_vertex_z_mm() + l.focus_image_distance_mm(None).unwrap();
        let r_max = 21.7;
        let dz = slope.length() * r_max;
        let b = ExitPupilBounds::compute_on_plane(&l, film_z, dz, slope, r_max, false);
        let rear = 1.5 * l.rear_semi_diameter_mm();
        let mut rnd = uniform(777u64);
        let (mut passed, mut outside, mut sampled, mut sampled_pass) = (0, 0, 0, 0);
        let (mut rim_sampled, mut rim_pass) = (0, 0);
        for _ in 0..200_000 {
            let (f, film, q) = random_ray(&mut rnd, r_max, film_z, slope, rear, &l);
            let ok = l.trace(&Ray::new(film, q - film), WL, TraceDirection::FilmToScene).is_some();
            if ok {
                passed += 1;
                outside += !b.contains(f, DVec2::new(q.x, q.y)) as usize;
                assert!(b.pdf_area(f, DVec2::new(q.x, q.y)) > 0.0, "{name}: a passing ray has no sampling density");
            }
            // the rejection of the traced domain's own samples (the defensive disc adds at most
            // DEFENSIVE_FRACTION more, `pupil_samples_mix_in_the_defensive_disc`); film points
            // whose radial interval found no ray, at the image circle's rim, where a film cell
            // found some, counted apart (served by the cell since session 37, before by the
            // defensive disc alone)
            if let Some(s) = b.sample_bounds(f, DVec2::new(rnd(), rnd())) {
                let pass = l.trace(&Ray::new(film, s.point - film), WL, TraceDirection::FilmToScene).is_some() as usize;
                if b.box_for_radius(f.length()).is_empty() {
                    (rim_sampled, rim_pass) = (rim_sampled + 1, rim_pass + pass);
                } else {
                    (sampled, sampled_pass) = (sampled + 1, sampled_pass + pass);
                }
            }
        }
        let rejection = 1.0 - sampled_pass as f64 / sampled as f64;
        let rim = match rim_sampled {
            0 => String::new(),
            n => format!("; {n} more samples at the rim served by cells only: {rim_pass} pass"),
        };
        eprintln!(
            "{name}, tilted: {outside} of {passed} passing rays outside, rejection {:.1}%{rim}",
            100.0 * rejection
        );
        assert!(passed > 1000, "{name}: too few passing rays ({passed})");
        assert_eq!(outside, 0, "{name}: {outside} of {passed} passing rays fall outside the bounds");
        // measured 22.8 / 24.8 / 24.4 / 18.7 / 37.0 % (22.8 / 24.4 / 24.0 / 18.2 / 36.6 % before
        // the film cells took 9 film points and raised their corners, which cut the passing rays
        // found outside them in stress runs about tenfold; film cells over the z span instead of
        // on the plane: 24.6 % for the 6-blade stop, 42.6 % anamorphic)
        let limit = if name.contains("anamorphic") { 0.40 } else { 0.25 };
        assert!(rejection <= limit, "{name}: {:.1}% of the sampled rays are absorbed", 100.0 * rejection);
    }
}

/// The traced domain is sampled uniformly: every sample lies inside it, and its area (the
/// inverse pdf) equals the share of a box's points that `contains` accepts.
#[test]
fn exit_pupil_domain_is_sampled_uniformly() {
    for name in ["double-gauss-50mm", "fisheye-10mm", "schneider-anamorphic-31mm"] {
        let l = library_lens(name).unwrap();
        let film_z = l.last_vertex_z_mm() + l.focus_image_distance_mm(None).unwrap();
        let b = ExitPupilBounds::compute(&l, film_z, 0.0, 21.7);
        // the anamorphic lens: outlines per film cell, about centres that move with the point,
        // inside one union box (not rotated with the film point)
        let rotate = !b.union_only;
        if !rotate {
            assert!(
                b.cells.as_ref().is_some_and(|c| c.outlines.iter().flatten().count() > 16),
                "{name}: no cell outlines"
            );
        }
        for (k, r) in [0.0, 7.3, 15.1, 20.9, 9.8].into_iter().enumerate() {
            let film = DVec2::new(r * 0.6, r * 0.8);
            let bx = b.box_for_radius(r);
            if bx.is_empty() {
                continue; // outside the image circle
            }
            let n = 256;
            let mut inside_rot = 0usize;
            let mut area = 0.0;
            for i in 0..n {
                for j in 0..n {
                    let u = DVec2::new((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
                    let s = b.sample_bounds(film, u).unwrap();
                    assert!(b.contains(film, DVec2::new(s.point.x, s.point.y)), "{name} r={r}: a sample outside");
                    area = 1.0 / s.pdf_area;
                    // a point of the (unrotated, film on +x) box, rotated to the film's azimuth
                    let q = bx.min + (bx.max - bx.min) * u;
                    let p = if rotate { DVec2::new(0.6 * q.x - 0.8 * q.y, 0.8 * q.x + 0.6 * q.y) } else { q };
                    inside_rot += b.contains(film, p) as usize;
                }
            }
            let mc = bx.area() * inside_rot as f64 / (n * n) as f64;
            assert!((mc / area - 1.0).abs() < 0.01, "{name} interval {k}: domain area {area} mm², contains() {mc} mm²");
            assert!((b.domain_area_at(film) - area).abs() < 1e-12);
            if rotate {
                assert!((b.domain_area(r) - area).abs() < 1e-12);
            }
        }
    }
}

/// The pupil samples mix the traced bounds with the defensive disc: each sample's density is
/// the mixture's, as `pdf_area` gives it for the point, and the share of samples the traced
/// bounds do not hold is at most the disc's share.
#[test]
fn pupil_samples_mix_in_the_defensive_disc() {
    for name in ["double-gauss-50mm", "fisheye-10mm", "schneider-anamorphic-31mm"] {
        let l = library_lens(name).unwrap();
        let film_z = l.last_vertex_z_mm() + l.focus_image_distance_mm(None).unwrap();
        let b = ExitPupilBounds::compute(&l, film_z, 0.0, 21.7);
        let radius = b.defensive_radius_mm.expect("a defensive disc");
        assert!(radius >= l.rear_semi_diameter_mm(), "{name}: disc {radius} mm inside the rear element");
        for r in [0.0, 7.3, 15.1, 20.9] {
            let film = DVec2::new(r * 0.6, r * 0.8);
            let n = 256;
            let (mut drawn, mut outside) = (0usize, 0usize);
            for i in 0..n {
                for j in 0..n {
                    let u = DVec2::new((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
                    let Some(s) = b.sample(film, u) else { continue };
                    let p = DVec2::new(s.point.x, s.point.y);
                    drawn += 1;
                    outside += !b.contains(film, p) as usize;
                    let pdf = b.pdf_area(film, p);
                    assert!(
                        (s.pdf_area / pdf - 1.0).abs() < 1e-12,
                        "{name} r={r}: sample density {} against pdf_area {pdf}",
                        s.pdf_area
                    );
                    assert!(p.length() <= radius * (1.0 + 1e-12) || b.contains(film, p));
                }
            }
            let disc_share = DEFENSIVE_FRACTION * (n * n) as f64;
            assert!(drawn as f64 >= disc_share, "{name} r={r}: {drawn} samples drawn");
            assert!(outside as f64 <= disc_share + 1.0, "{name} r={r}: {outside} samples outside the bounds");
        }
    }
}

/// The defensive disc makes a bounds miss cost noise, not bias. double-gauss-50mm's outlines
/// are shrunk to 70 % of their size about their centres (a grossly wrong trace), and the area
/// of the rear-plane region whose rays pass from one film point is estimated three ways with
/// 1 000 000 samples each: brute force in the disc (the reference), the shrunk bounds alone
/// (biased low: they miss part of the region), and the mixture with the disc (unbiased: within
/// 4.5 standard errors of the reference).
#[test]
fn defensive_disc_removes_the_bias_of_a_bounds_miss() {
    let l = library_lens("double-gauss-50mm").unwrap();
    let film_z = l.last_vertex_z_mm() + l.focus_image_distance_mm(None).unwrap();
    let mut b = ExitPupilBounds::compute(&l, film_z, 0.0, 21.7);
    for o in b.outlines.iter_mut().flatten() {
        o.radii.iter_mut().for_each(|r| *r *= 0.7);
        o.area *= 0.49; // every triangle scales alike, so the area cdf stays valid
    }
    let radius = b.defensive_radius_mm.unwrap();
    let film = DVec2::new(11.0, 6.0);
    let fp = DVec3::new(film.x, film.y, film_z);
    let passes = |p: DVec3| l.trace(&Ray::new(fp, p - fp), WL, TraceDirection::FilmToScene).is_some();
    // mean and standard error of pass(p)/pdf(p) over `n` samples drawn by `draw`
    let estimate = |draw: &dyn Fn(DVec2) -> Option<(DVec3, f64)>, seed: u64| {
        let mut rnd = uniform(seed);
        let n = 1_000_000;
        let (mut sum, mut sum2) = (0.0, 0.0);
        for _ in 0..n {
            let u = DVec2::new(rnd(), rnd());
            if let Some((p, pdf)) = draw(u) {
                if passes(p) {
                    let x = 1.0 / pdf;
                    (sum, sum2) = (sum + x, sum2 + x * x);
                }
            }
        }
        let mean = sum / n as f64;
        (mean, ((sum2 / n as f64 - mean * mean) / n as f64).sqrt())
    };
    let rear_z = b.rear_z_mm;
    let disc_area = std::f64::consts::PI * radius * radius;
    let (reference, se_ref) = estimate(
        &|u| {
            let d = petzval_optics::aperture::concentric_disk(u) * radius;
            Some((DVec3::new(d.x, d.y, rear_z), 1.0 / disc_area))
        },
        1,
    );
    let (bounds_only, se_b) = estimate(&|u| b.sample_bounds(film, u).map(|s| (s.point, s.pdf_area)), 2);
    let (mixture, se_m) = estimate(&|u| b.sample(film, u).map(|s| (s.point, s.pdf_area)), 3);
    eprintln!(
        "passing area {reference:.3} ± {se_ref:.3} mm²; shrunk bounds alone {bounds_only:.3} ± {se_b:.3}; \
         with the disc {mixture:.3} ± {se_m:.3}"
    );
    assert!(reference > 1.0, "too small a region ({reference} mm²)");
    let se = (se_ref * se_ref + se_m * se_m).sqrt();
    assert!((mixture - reference).abs() < 4.5 * se, "mixture {mixture} ± {se_m} against {reference} ± {se_ref}");
    assert!(
        bounds_only < reference - 10.0 * (se_ref * se_ref + se_b * se_b).sqrt(),
        "the shrunk bounds are not biased"
    );
}

#[test]
fn focusing_moves_the_sensor_and_refuses_the_impossible() {
    let l = library_lens("double-gauss-50mm").unwrap();
    let inf = l.focus_image_distance_mm(None).unwrap();
    let near = l.focus_image_distance_mm(Some(1000.0)).unwrap();
    assert!(near > inf);
    // Newton's equation from the focal points: x x' = f²
    let p = l.paraxial();
    let object_z = p.entrance_pupil_z_mm - 1000.0;
    let x = p.front_focal_z_mm - object_z;
    let x_img = l.last_vertex_z_mm() + near - p.rear_focal_z_mm;
    assert!((x * x_img - p.efl_mm * p.efl_mm).abs() < 1e-6 * p.efl_mm * p.efl_mm);
    // real rays from the object point converge at the sensor (small aperture: within 5 µm)
    let small = l.stopped_down(16.0).unwrap();
    let film_z = l.last_vertex_z_mm() + near;
    let mut hits = vec![];
    for k in -3..=3 {
        let h = 0.1 * k as f64;
        let target = DVec3::new(0.0, h, p.entrance_pupil_z_mm);
        let o = DVec3::new(0.0, 0.0, object_z);
        if let Some(t) = small.trace(&Ray::new(o, target - o), WL, TraceDirection::SceneToFilm) {
            let s = (film_z - t.ray.origin.z) / t.ray.direction.z;
            hits.push((t.ray.origin + t.ray.direction * s).y);
        }
    }
    assert!(hits.len() >= 5);
    assert!(hits.iter().all(|y| y.abs() < 5e-3), "{hits:?}");
    let err = l.focus_image_distance_mm(Some(30.0)).unwrap_err().to_string();
    assert!(err.contains("cannot focus"), "{err}");
}

/// Tracing scene → film through a lens is tracing film → scene through its reversal (mirrored
/// in z): a film → scene ray, sent back, arrives at its film point in the reversed lens.
#[test]
fn reversed_lens_traces_rays_backwards() {
    use petzval_optics::{library_lens, Ray, TraceDirection};
    for name in [
        "double-gauss-50mm",
        "cooke-speed-panchro-25mm",
        "fisheye-10mm",
        "aspheric-fisheye-10mm",
        "petzval-portrait-100mm",
    ] {
        let lens = library_lens(name).unwrap();
        let rev = lens.reversed().unwrap();
        assert_eq!(rev.surfaces().len(), lens.surfaces().len());
        assert!(
            (rev.paraxial().efl_mm - lens.paraxial().efl_mm).abs() < 1e-9 * lens.paraxial().efl_mm.abs(),
            "{name}: EFL"
        );
        // twice reversed: the same optics
        let back = rev.reversed().unwrap();
        assert!((back.paraxial().bfl_mm - lens.paraxial().bfl_mm).abs() < 1e-9, "{name}: BFL after two reversals");
        let l = lens.last_vertex_z_mm();
        let mirror = |v: glam::DVec3| glam::DVec3::new(v.x, v.y, l - v.z);
        let mirror_dir = |v: glam::DVec3| glam::DVec3::new(v.x, v.y, -v.z);
        let film_z = l + lens.focus_image_distance_mm(None).unwrap();
        let wl = lens.primary_wavelength_nm();
        let mut passed = 0;
        let mut rnd = uniform(99u64);
        for _ in 0..4000 {
            let p = glam::DVec3::new(12.0 * (rnd() - 0.5), 12.0 * (rnd() - 0.5), film_z);
            let r = lens.rear_semi_diameter_mm() * rnd().sqrt();
            let phi = std::f64::consts::TAU * rnd();
            let target = glam::DVec3::new(r * phi.cos(), r * phi.sin(), l);
            let din = (target - p).normalize();
            let Some(out) = lens.trace(&Ray::new(p, din), wl, TraceDirection::FilmToScene) else { continue };
            passed += 1;
            // back from the scene side, mirrored into the reversed lens
            let start = out.ray.origin + out.ray.direction * 5.0;
            let back_ray = Ray::new(mirror(start), mirror_dir(-out.ray.direction));
            let arrived = rev
                .trace(&back_ray, wl, TraceDirection::FilmToScene)
                .unwrap_or_else(|| panic!("{name}: the reversed ray was absorbed"));
            let o = mirror(arrived.ray.origin);
            let d = mirror_dir(arrived.ray.direction);
            assert!((d + din).length() < 1e-9, "{name}: direction {d} vs {}", -din);
            // the line through o along d passes through the film point p
            let miss = (p - o).cross(d).length();
            assert!(miss < 1e-8, "{name}: misses the film point by {miss} mm");
        }
        assert!(passed > 200, "{name}: only {passed} rays to compare");
    }
}

/// A lens of a wide open stop and one biconvex singlet, the singlet decentred and tilted as
/// given: the misalignment fields of the format.
fn misaligned_singlet(dx: f64, dy: f64, tx: f64, ty: f64) -> petzval_optics::Lens {
    let text = format!(
        r#"
[lens]
name = "misaligned singlet"
source = "test"
[[surface]]
thickness_mm = 5.0
semi_diameter_mm = 20.0
stop = true
[[surface]]
radius_mm = 60.0
thickness_mm = 6.0
material = "N-BK7"
semi_diameter_mm = 15.0
decenter_x_mm = {dx}
decenter_y_mm = {dy}
tilt_x_deg = {tx}
tilt_y_deg = {ty}
[[surface]]
radius_mm = -60.0
thickness_mm = 55.0
semi_diameter_mm = 15.0
"#
    );
    petzval_optics::Lens::from_toml(&text, "misaligned.toml", None).unwrap()
}

/// A decentred and tilted element traces as the aligned element seen by a ray moved the other
/// way: trace(misaligned, r) = T(trace(aligned, T⁻¹ r)) where T is the element's rigid motion
/// about its front vertex (the wide stop clips nothing and refracts nothing). Checked in both
/// directions, and the reversed lens sends the rays back.
#[test]
fn misaligned_element_is_the_aligned_one_moved() {
    use glam::{DMat3, DVec3};
    use petzval_optics::{Ray, TraceDirection};
    let aligned = misaligned_singlet(0.0, 0.0, 0.0, 0.0);
    assert!(aligned.is_rotationally_symmetric());
    for (dx, dy, tx, ty) in [(0.7, 0.0, 0.0, 0.0), (0.0, -0.4, 0.0, 0.0), (0.0, 0.0, 2.0, 0.0), (0.3, 0.2, -1.5, 3.0)] {
        let lens = misaligned_singlet(dx, dy, tx, ty);
        assert!(!lens.is_rotationally_symmetric(), "misalignment breaks the symmetry");
        let pivot = DVec3::new(0.0, 0.0, 5.0);
        let offset = DVec3::new(dx, dy, 0.0);
        let rot = DMat3::from_rotation_y(f64::to_radians(ty)) * DMat3::from_rotation_x(f64::to_radians(tx));
        let to_element = |p: DVec3| rot.transpose() * (p - pivot - offset) + pivot;
        let to_lens = |p: DVec3| rot * (p - pivot) + pivot + offset;
        let wl = lens.primary_wavelength_nm();
        let mut checked = 0;
        for k in 0..200 {
            let (a, b) = ((k % 20) as f64 / 19.0 - 0.5, (k / 20) as f64 / 9.0 - 0.5);
            let ray = Ray::new(DVec3::new(16.0 * a, 16.0 * b, -30.0), DVec3::new(0.02 * b, -0.03 * a, 1.0));
            let moved = Ray::new(to_element(ray.origin), rot.transpose() * ray.direction);
            let got = lens.trace(&ray, wl, TraceDirection::SceneToFilm);
            let want = aligned.trace(&moved, wl, TraceDirection::SceneToFilm);
            match (got, want) {
                (Some(g), Some(w)) => {
                    // the outgoing ray leaves the last surface: compare the lines at z = 80
                    let at = |o: DVec3, d: DVec3| o + d * ((80.0 - o.z) / d.z);
                    let wo = to_lens(w.ray.origin);
                    let wd = rot * w.ray.direction;
                    assert!((g.ray.origin - wo).length() < 1e-9, "origin {:?} vs {:?}", g.ray.origin, wo);
                    assert!((g.ray.direction - wd).length() < 1e-12);
                    assert!((at(g.ray.origin, g.ray.direction) - at(wo, wd)).length() < 1e-9);
                    checked += 1;
                }
                (None, None) => {}
                (g, w) => panic!("({dx}, {dy}, {tx}, {ty}) ray {k}: misaligned {g:?}, moved aligned {w:?}"),
            }
        }
        assert!(checked > 150, "most rays pass: {checked}");
        // the reversed lens carries the same physical placement
        let rev = lens.reversed().unwrap();
        assert!(!rev.is_rotationally_symmetric());
        let l = lens.last_vertex_z_mm();
        let mirror = |v: DVec3| DVec3::new(v.x, v.y, l - v.z);
        let mirror_dir = |v: DVec3| DVec3::new(v.x, v.y, -v.z);
        let ray = Ray::new(DVec3::new(2.0, -1.0, -30.0), DVec3::new(0.01, 0.02, 1.0));
        let out = lens.trace(&ray, wl, TraceDirection::SceneToFilm).unwrap();
        let back = Ray::new(mirror(out.ray.origin + out.ray.direction * 5.0), mirror_dir(-out.ray.direction));
        let front = rev.trace(&back, wl, TraceDirection::SceneToFilm).unwrap();
        // reversed, the ray leaves through the (mirrored) stop plane towards the original origin
        let o = mirror(front.ray.origin);
        let d = mirror_dir(front.ray.direction);
        let closest = o + d * (ray.origin - o).dot(d);
        assert!((closest - ray.origin).length() < 1e-8, "({dx}, {dy}, {tx}, {ty}): back at {closest:?}");
        // the round trip through the format keeps the fields
        let again = petzval_optics::Lens::new(
            lens.prescription().clone(),
            &petzval_optics::prescription::SourceMap::new("again", vec![]),
            None,
        )
        .unwrap();
        assert_eq!(again.surfaces()[1].placement, lens.surfaces()[1].placement);
        assert_eq!(lens.surfaces()[1].placement, lens.surfaces()[2].placement, "both surfaces move together");
    }
}

/// Misalignment belongs on an element's first surface and is range-checked, with errors
/// naming the field.
#[test]
fn misalignment_errors_name_the_field() {
    let base = |extra_stop: &str, extra_front: &str, extra_back: &str| {
        format!(
            "[lens]\nname = \"x\"\nsource = \"t\"\n[[surface]]\nthickness_mm = 5.0\nsemi_diameter_mm = 20.0\nstop = true\n{extra_stop}\n[[surface]]\nradius_mm = 60.0\nthickness_mm = 6.0\nmaterial = \"N-BK7\"\nsemi_diameter_mm = 15.0\n{extra_front}\n[[surface]]\nradius_mm = -60.0\nthickness_mm = 55.0\nsemi_diameter_mm = 15.0\n{extra_back}\n"
        )
    };
    for (text, field) in [
        (base("", "", "decenter_x_mm = 0.5"), "surface[3].decenter_x_mm"),
        (base("tilt_y_deg = 1.0", "", ""), "surface[1].tilt_y_deg"),
        (base("", "tilt_x_deg = 60.0", ""), "surface[2].tilt_x_deg"),
        (base("", "decenter_y_mm = 16.0", ""), "surface[2].decenter_y_mm"),
        (base("", "decenter_y_mm = nan", ""), "surface[2].decenter_y_mm"),
    ] {
        let err = petzval_optics::Lens::from_toml(&text, "m.toml", None).unwrap_err().to_string();
        assert!(err.contains(field), "{err} should name {field}");
    }
}

/// Image space in glass (an eye's vitreous, a lens cemented to its sensor): the image-side
/// paraxial distances scale with its index n′. One surface of radius R into n′ = 1.5168: EFL =
/// R/(n′ − 1), BFL = n′·R/(n′ − 1), the rear principal plane at the vertex, and a real ray near
/// the axis crosses it at the rear focal point (the BFL was R/(n′ − 1) before, 20 mm short).
#[test]
fn image_space_in_glass_scales_the_image_side() {
    let l = lens(
        "[lens]\nname = \"image-in-glass\"\nsource = \"test\"\n\n[[surface]]\nthickness_mm = 2.0\nsemi_diameter_mm = 4.0\nstop = true\n\n[[surface]]\nradius_mm = 20.0\nthickness_mm = 60.0\nmaterial = { nd = 1.5168, vd = 0 }\nsemi_diameter_mm = 8.0\n",
    );
    let n = l.index_after(1, l.primary_wavelength_nm());
    let p = l.paraxial();
    let efl = 20.0 / (n - 1.0);
    assert!((p.efl_mm - efl).abs() < 1e-9 * efl, "{p:?}");
    assert!((p.bfl_mm - n * efl).abs() < 1e-9 * efl, "{p:?}");
    assert!((p.rear_principal_z_mm - 2.0).abs() < 1e-9, "{p:?}");
    let t = l
        .trace(&Ray::new(DVec3::new(0.0, 1e-3, -5.0), DVec3::Z), l.primary_wavelength_nm(), TraceDirection::SceneToFilm)
        .unwrap();
    let z_cross = t.ray.origin.z - t.ray.origin.y * t.ray.direction.z / t.ray.direction.y;
    assert!(
        (z_cross - p.rear_focal_z_mm).abs() < 1e-4,
        "real ray crosses at {z_cross}, paraxial {}",
        p.rear_focal_z_mm
    );
    // focused at 1 m, the image distance is the real rays' too
    let v = l.focus_image_distance_mm(Some(1000.0)).unwrap();
    let object_z = p.entrance_pupil_z_mm - 1000.0;
    let o = DVec3::new(0.0, 0.0, object_z);
    let t = l
        .trace(&Ray::new(o, DVec3::new(0.0, 1e-3, 2.0) - o), l.primary_wavelength_nm(), TraceDirection::SceneToFilm)
        .unwrap();
    let z_cross = t.ray.origin.z - t.ray.origin.y * t.ray.direction.z / t.ray.direction.y;
    assert!(
        (z_cross - (l.last_vertex_z_mm() + v)).abs() < 1e-3,
        "real {z_cross}, paraxial {}",
        l.last_vertex_z_mm() + v
    );
}

/// Lenses stopped down far beyond their makers' range, where the passing region from a film
/// point is a speck of the rear grid's cell (wide-22mm at f/96: 0.13 mm against 0.56 mm
/// cells), round and with 6 blades: the bounds exist (the camera used to fail with "no light
/// reaches the centre of the sensor"), no passing ray falls outside them, and few sampled rays
/// are absorbed (at most 10 %, 25 % with blades). Brute force about each film point's chief ray
/// (the region lies about it), a square of half side `window` on the rear plane: 200 000 rays
/// per case. Before the fine search, wide-22mm at f/22 lost 489 of its 7 485 passing rays here
/// (only the defensive disc drew them) and 34 % of the sampled rays were absorbed.
#[test]
fn exit_pupil_bounds_hold_for_lenses_stopped_down_far() {
    let blades = six_blades(0.3);
    let cases = [
        ("wide-22mm", 22.0, false, 1.5),
        ("wide-22mm", 96.0, false, 0.5),
        ("wide-22mm", 96.0, true, 0.5),
        ("telephoto-250mm", 128.0, false, 1.0),
        ("double-gauss-50mm", 64.0, false, 1.0),
        ("double-gauss-50mm", 256.0, false, 0.5),
        ("double-gauss-50mm", 256.0, true, 0.5),
        ("double-gauss-50mm", 1000.0, false, 0.2),
        // stops far below the rear grid's cell: the fine search's spacing follows the
        // paraxial size of the region (before: 57 % absorbed at f/8000, 99.6 % at f/100 000)
        ("double-gauss-50mm", 8000.0, false, 0.01),
    ];
    for (name, f_number, bladed, window) in cases {
        let mut l = library_lens(name).unwrap().stopped_down(f_number).unwrap();
        if bladed {
            l = l.with_aperture(blades.clone());
        }
        let case = format!("{name} at f/{f_number}{}", if bladed { " with 6 blades" } else { "" });
        let film_z = l.last_vertex_z_mm() + l.focus_image_distance_mm(Some(1500.0)).unwrap();
        let b = ExitPupilBounds::compute(&l, film_z, 0.0, 21.7);
        let (passed, outside, rejection) = brute_force_near_chief(&l, &b, (film_z, DVec2::ZERO), window, 200_000);
        eprintln!("{case}: {passed} passing, {outside} outside, {:.1} % of sampled rays absorbed", 100.0 * rejection);
        assert!(passed > 1000, "{case}: too few passing rays ({passed})");
        assert_eq!(outside, 0, "{case}: {outside} of {passed} passing rays fall outside the bounds");
        let limit = if bladed { 0.25 } else { 0.10 };
        assert!(rejection <= limit, "{case}: {:.1} % of the sampled rays are absorbed", 100.0 * rejection);
    }
}

/// Stops far below the rear grid's cell (double-gauss-50mm with 6 blades, the demo's sensor
/// tilted 6°, focused at 0.55 m): over a 17 × 17 lattice of the film, the share of samples drawn
/// in the bounds that pass (4 × 4 stratified per film point): 59.3 % at f/2000, 17.3 % at
/// f/8000. Before the fine search's spacing followed the region's paraxial size, the bounds were
/// far larger than the speck of a region: 56.1 % and 3.4 % (the demo at 16 spp rendered 7 % of its
/// pixels black at f/2000, 84 % at f/8000; now 0 % and 3 %).
#[test]
fn bounds_of_tiny_stops_keep_their_samples() {
    let blades = six_blades(0.3);
    for (f_number, at_least) in [(2000.0, 0.5), (8000.0, 0.12)] {
        let l =
            library_lens("double-gauss-50mm").unwrap().stopped_down(f_number).unwrap().with_aperture(blades.clone());
        let wl = l.primary_wavelength_nm();
        let film_z = l.last_vertex_z_mm() + l.focus_image_distance_mm(Some(550.0)).unwrap();
        // The sensor plane tilted 6° about x: z = film_z + slope.y · y.
        let slope = DVec2::new(0.0, 6f64.to_radians().tan());
        let b = ExitPupilBounds::compute_on_plane(&l, film_z, 12.0 * slope.y, slope, 21.7, false);
        let (mut drawn, mut passed) = (0usize, 0usize);
        for i in 0..=16 {
            for j in 0..=16 {
                let (x, y) = (-18.0 + 36.0 * i as f64 / 16.0, -12.0 + 24.0 * j as f64 / 16.0);
                let fp = DVec3::new(x, y, film_z + slope.y * y);
                for k in 0..16 {
                    let u = DVec2::new((k % 4) as f64 + 0.5, (k / 4) as f64 + 0.5) / 4.0;
                    let Some(s) = b.sample_bounds(DVec2::new(x, y), u) else { continue };
                    drawn += 1;
                    let ray = Ray::new(fp, s.point - fp);
                    passed += usize::from(l.trace(&ray, wl, TraceDirection::FilmToScene).is_some());
                }
            }
        }
        let share = passed as f64 / drawn.max(1) as f64;
        eprintln!("f/{f_number}: {passed} of {drawn} samples pass ({:.1} %)", 100.0 * share);
        assert!(share >= at_least, "f/{f_number}: only {:.1} % of the samples pass", 100.0 * share);
    }
}

/// Every library lens at f/16 and f/32 focused at 1.5 m: no passing ray outside the bounds and
/// at most 20 % of the sampled rays absorbed (35 % on the anamorphic lens, outlined per film
/// cell), by brute force about each film point's chief ray (a square of 0.3× the rear
/// semi-diameter, 40 000 rays each). Before the fine search, the rear grid lost passing regions
/// smaller than its cells: at f/32, all of them on wide-22mm, angenieux-double-gauss-100mm and
/// aspheric-fisheye-10mm (only the defensive disc drew those rays), 182 of 330 on
/// nikon-normal-52mm, 115 of 420 on zeiss-biotar-100mm; at f/22, 34 of 429 on wide-22mm.
#[test]
fn exit_pupil_bounds_hold_stopped_down_on_every_library_lens() {
    for entry in petzval_optics::LIBRARY {
        for f_number in [16.0, 32.0] {
            let l = library_lens(entry.name).unwrap().stopped_down(f_number).unwrap();
            let film_z = l.last_vertex_z_mm() + l.focus_image_distance_mm(Some(1500.0)).unwrap();
            let window = 0.3 * l.rear_semi_diameter_mm();
            let b = ExitPupilBounds::compute(&l, film_z, 0.0, 21.7);
            let (passed, outside, rejection) = brute_force_near_chief(&l, &b, (film_z, DVec2::ZERO), window, 40_000);
            let case = format!("{} at f/{f_number}", entry.name);
            eprintln!(
                "{case}: {passed} passing, {outside} outside, {:.1} % of sampled rays absorbed",
                100.0 * rejection
            );
            assert!(passed > 50, "{case}: too few passing rays ({passed})");
            assert_eq!(outside, 0, "{case}: {outside} of {passed} passing rays fall outside the bounds");
            let limit = if entry.name.contains("anamorphic") { 0.35 } else { 0.20 };
            assert!(rejection <= limit, "{case}: {:.1} % of the sampled rays are absorbed", 100.0 * rejection);
        }
    }
}

/// A stop of 6 straight blades turned by `rotation_rad`.
fn six_blades(rotation_rad: f64) -> petzval_optics::Aperture {
    petzval_optics::Aperture {
        shape: petzval_optics::ApertureShape::Blades { count: 6, curvature: 0.0 },
        rotation_rad,
        anamorphic_ratio: 1.0,
    }
}

/// Brute force about the chief ray against bounds `b` for the sensor plane `film_z + slope ·
/// (x, y)` over a 21.7 mm film radius: `rays` film points uniform in the disc, each with a
/// rear-plane point uniform in the square of half side `window` about its chief ray's aim
/// point, and one sampled from the bounds. Returns (passing rays, passing rays outside the
/// bounds, share of the sampled rays absorbed).
fn brute_force_near_chief(
    l: &Lens,
    b: &ExitPupilBounds,
    (film_z, slope): (f64, DVec2),
    window: f64,
    rays: usize,
) -> (usize, usize, f64) {
    let mut rnd = uniform(7);
    let (mut passed, mut outside, mut sampled, mut sampled_passing) = (0, 0, 0, 0);
    let passes =
        |film: DVec3, rear: DVec3| l.trace(&Ray::new(film, rear - film), WL, TraceDirection::FilmToScene).is_some();
    for _ in 0..rays {
        let (f, film, _) = random_ray(&mut rnd, 21.7, film_z, slope, 0.0, l);
        let Some(aim) = petzval_optics::pupil::chief_aim_from_film(l, film, WL) else { continue };
        let q = aim + window * DVec2::new(2.0 * rnd() - 1.0, 2.0 * rnd() - 1.0);
        let ok = passes(film, DVec3::new(q.x, q.y, l.last_vertex_z_mm()));
        passed += ok as usize;
        outside += (ok && !b.contains(f, q)) as usize;
        if let Some(s) = b.sample_bounds(f, DVec2::new(rnd(), rnd())) {
            sampled += 1;
            sampled_passing += passes(film, s.point) as usize;
        }
    }
    (passed, outside, 1.0 - sampled_passing as f64 / sampled.max(1) as f64)
}

/// The chief ray of a lens without rotational symmetry behind its stop leaves the film point's
/// radial plane: aimed in both coordinates, it passes a stop of f/1000 (a few hundredths of a
/// millimetre) from film points at every azimuth across the field, on a singlet decentred and
/// tilted behind its stop (aimed in the radial plane only, most of them missed the stop), as on
/// schneider-anamorphic-31mm (whose cylinders stand in front of the stop) and double-gauss-50mm.
#[test]
fn chief_rays_pass_a_tiny_stop_off_the_radial_plane() {
    let decentred = misaligned_singlet(0.5, 0.3, 2.0, -1.0);
    for (name, lens) in [
        ("a singlet decentred and tilted behind its stop", decentred),
        ("schneider-anamorphic-31mm", library_lens("schneider-anamorphic-31mm").unwrap()),
        ("double-gauss-50mm", library_lens("double-gauss-50mm").unwrap()),
    ] {
        let l = lens.stopped_down(1000.0).unwrap();
        let film_z = l.last_vertex_z_mm() + l.focus_image_distance_mm(None).unwrap();
        let (mut tried, mut passed) = (0, 0);
        for k in 0..24 {
            let phi = std::f64::consts::TAU * k as f64 / 24.0 + 0.1;
            for r in [1.0, 6.0, 12.0] {
                let film = DVec3::new(r * phi.cos(), r * phi.sin(), film_z);
                let Some(aim) = petzval_optics::pupil::chief_aim_from_film(&l, film, WL) else { continue };
                tried += 1;
                let rear = DVec3::new(aim.x, aim.y, l.last_vertex_z_mm());
                passed += l.trace(&Ray::new(film, rear - film), WL, TraceDirection::FilmToScene).is_some() as usize;
            }
        }
        assert!(tried >= 60, "{name}: the chief ray was aimed from {tried} of 72 film points");
        assert_eq!(passed, tried, "{name}: {passed} of {tried} chief rays pass the f/1000 stop");
    }
}

/// Small stops on a tilted sensor (5° about y, a little about x; bounds traced on the sensor's
/// plane, as the exact camera has them): no passing ray outside the bounds and at most 20 % of
/// the sampled rays absorbed, round and with 6 blades, by brute force about each film point's
/// chief ray (40 000 rays each). One outline per film radius could not follow a speck that
/// moves with each film point's z too: round stops absorbed 82 % (wide-22mm at f/32) and 45 %
/// (double-gauss-50mm at f/32) before they went to the film cells.
#[test]
fn exit_pupil_bounds_hold_for_small_stops_on_tilted_sensors() {
    let blades = six_blades(0.0);
    let cases = [
        ("wide-22mm", 32.0, false),
        ("wide-22mm", 32.0, true),
        ("double-gauss-50mm", 32.0, false),
        ("double-gauss-50mm", 128.0, true),
        ("telephoto-250mm", 64.0, false),
    ];
    for (name, f_number, bladed) in cases {
        let mut l = library_lens(name).unwrap().stopped_down(f_number).unwrap();
        if bladed {
            l = l.with_aperture(blades.clone());
        }
        let case = format!("{name} at f/{f_number}{}, tilted", if bladed { " with 6 blades" } else { "" });
        let slope = DVec2::new(5f64.to_radians().tan(), 0.02);
        let film_z = l.last_vertex_z_mm() + l.focus_image_distance_mm(Some(1500.0)).unwrap();
        let r_max = 21.7;
        let b = ExitPupilBounds::compute_on_plane(&l, film_z, slope.length() * r_max, slope, r_max, false);
        let window = 0.3 * l.rear_semi_diameter_mm();
        let (passed, outside, rejection) = brute_force_near_chief(&l, &b, (film_z, slope), window, 40_000);
        eprintln!("{case}: {passed} passing, {outside} outside, {:.1} % of sampled rays absorbed", 100.0 * rejection);
        assert!(passed > 50, "{case}: too few passing rays ({passed})");
        assert_eq!(outside, 0, "{case}: {outside} of {passed} passing rays fall outside the bounds");
        assert!(rejection <= 0.20, "{case}: {:.1} % of the sampled rays are absorbed", 100.0 * rejection);
    }
}

/// A sweep about each film point's chief ray (not run by default: `cargo test --release -p
/// petzval-optics --test optics exit_pupil_bounds_sweep -- --ignored --nocapture`): every
/// library lens with 5 blades (PETZVAL_SWEEP_BLADES, 0 for its round stop) at f/8 and f/32
/// (PETZVAL_SWEEP_FSTOPS, comma-separated) focused at 1.5 m and 0.55 m, on the sensor's plane,
/// 200 000 rays each (PETZVAL_SWEEP_RAYS). Prints each case's passing rays, those outside the
/// bounds, the rejection of the bounds' samples and the bounds' build time; no passing ray may
/// fall outside (12 did in these 52 cases before session 37's rim cells).
#[test]
#[ignore]
fn exit_pupil_bounds_sweep_about_chief_rays() {
    let var = |name: &str, default: &str| std::env::var(name).unwrap_or_else(|_| default.to_string());
    let rays: usize = var("PETZVAL_SWEEP_RAYS", "200000").parse().unwrap();
    let blades: u32 = var("PETZVAL_SWEEP_BLADES", "5").parse().unwrap();
    let f_numbers: Vec<f64> = var("PETZVAL_SWEEP_FSTOPS", "8,32").split(',').map(|v| v.parse().unwrap()).collect();
    let mut outside_total = 0;
    for entry in petzval_optics::LIBRARY {
        for &f_number in &f_numbers {
            for focus_mm in [1500.0, 550.0] {
                let mut l = library_lens(entry.name).unwrap().stopped_down(f_number).unwrap();
                if blades > 0 {
                    l = l.with_aperture(petzval_optics::Aperture {
                        shape: petzval_optics::ApertureShape::Blades { count: blades, curvature: 0.0 },
                        rotation_rad: 0.4,
                        anamorphic_ratio: 1.0,
                    });
                }
                let film_z = l.last_vertex_z_mm() + l.focus_image_distance_mm(Some(focus_mm)).unwrap();
                let start = std::time::Instant::now();
                let b = ExitPupilBounds::compute_on_plane(&l, film_z, 0.0, DVec2::ZERO, 21.7, false);
                let build_s = start.elapsed().as_secs_f64();
                let window = 0.3 * l.rear_semi_diameter_mm();
                let (passed, outside, rejection) = brute_force_near_chief(&l, &b, (film_z, DVec2::ZERO), window, rays);
                eprintln!(
                    "{} f/{f_number} focus {focus_mm} mm: {passed} passing, {outside} outside, {:.1} % absorbed, \
                     build {build_s:.2} s",
                    entry.name,
                    100.0 * rejection
                );
                outside_total += outside;
            }
        }
    }
    assert_eq!(outside_total, 0, "{outside_total} passing rays fell outside the bounds");
}

/// Film points at the rim of the image circle, whose film cells have no outline (the region is
/// vignetted there and not star-shaped about its centre), or whose outlines were traced from
/// film points the region changes shape between (element rims and the stop bind in turn). No
/// passing ray falls outside the bounds: before the outlines were checked between their film
/// points, 1–2 rays in 10⁴ did here (anamorphic lens at f/16, a 5-blade fisheye at f/16).
#[test]
fn exit_pupil_bounds_hold_at_the_rim_of_the_image_circle() {
    let blades = |l: Lens| {
        l.with_aperture(petzval_optics::Aperture {
            shape: petzval_optics::ApertureShape::Blades { count: 5, curvature: 0.0 },
            rotation_rad: 0.4,
            anamorphic_ratio: 1.0,
        })
    };
    let stopped = |name: &str, f_number: f64| library_lens(name).unwrap().stopped_down(f_number).unwrap();
    let cases = [
        ("schneider-anamorphic-31mm at f/16, 1.5 m", blades(stopped("schneider-anamorphic-31mm", 16.0)), 1500.0),
        ("schneider-anamorphic-31mm at f/16, 1.5 m, round", stopped("schneider-anamorphic-31mm", 16.0), 1500.0),
        ("schneider-anamorphic-31mm at f/96, 0.55 m, round", stopped("schneider-anamorphic-31mm", 96.0), 550.0),
        ("fisheye-10mm at f/16, 5 blades, 1.5 m", blades(stopped("fisheye-10mm", 16.0)), 1500.0),
        ("fisheye-10mm at f/16, 5 blades, 0.55 m", blades(stopped("fisheye-10mm", 16.0)), 550.0),
    ];
    for (case, l, focus_mm) in cases {
        let film_z = l.last_vertex_z_mm() + l.focus_image_distance_mm(Some(focus_mm)).unwrap();
        let b = ExitPupilBounds::compute_on_plane(&l, film_z, 0.0, DVec2::ZERO, 21.7, false);
        let window = 0.3 * l.rear_semi_diameter_mm();
        let (passed, outside, rejection) = brute_force_near_chief(&l, &b, (film_z, DVec2::ZERO), window, 300_000);
        eprintln!("{case}: {passed} passing, {outside} outside, {:.1} % of sampled rays absorbed", 100.0 * rejection);
        assert!(passed > 300, "{case}: too few passing rays ({passed})");
        assert_eq!(outside, 0, "{case}: {outside} of {passed} passing rays fall outside the bounds");
    }
}

/// A lens without rotational symmetry stopped down far: at the rim of the image circle the film
/// cells have no outline, and their box spans the small region's slide across the cell, so
/// samples from film points that receive light mostly missed it (70–100 % absorbed per cell on
/// the anamorphic lens at f/96, rendered as blocks of speckle). The outline of the region that
/// passes the stop (the elements' rims ignored), about each film point's interpolated chief-ray
/// aim, follows the region: at most 20 % of the samples there are absorbed (13.0 % measured;
/// 56.4 % with boxes about the aims alone), and the chief ray lies in the bounds.
#[test]
fn rim_cells_of_a_small_stop_follow_the_region() {
    let l = library_lens("schneider-anamorphic-31mm").unwrap().stopped_down(96.0).unwrap();
    let film_z = l.last_vertex_z_mm() + l.focus_image_distance_mm(Some(550.0)).unwrap();
    let b = ExitPupilBounds::compute_on_plane(&l, film_z, 0.0, DVec2::ZERO, 21.7, false);
    let cells = b.cells.as_ref().expect("the anamorphic lens is outlined per film cell");
    let mut rnd = uniform(5);
    let (mut sampled, mut passing, mut film_points) = (0usize, 0usize, 0usize);
    for _ in 0..400_000 {
        let (f, film, _) = random_ray(&mut rnd, 21.7, film_z, DVec2::ZERO, 0.0, &l);
        // (film points that receive light, in a cell without an outline of the passing region)
        let u = (f + DVec2::splat(cells.half_side_mm)) / (2.0 * cells.half_side_mm) * cells.cells as f64;
        let k = (u.y as usize).min(cells.cells - 1) * cells.cells + (u.x as usize).min(cells.cells - 1);
        let rim = cells.outlines[k].is_none() && !cells.boxes[k].is_empty();
        if !rim || petzval_optics::pupil::chief_ray_from_film(&l, film, WL).is_none() {
            continue;
        }
        film_points += 1;
        // every such film point's chief ray passes, and lies in its bounds
        let aim = petzval_optics::pupil::chief_aim_from_film(&l, film, WL).unwrap();
        assert!(b.contains(f, aim), "the chief ray from film point {f:?} falls outside the bounds");
        if let Some(s) = b.sample_bounds(f, DVec2::new(rnd(), rnd())) {
            sampled += 1;
            passing += l.trace(&Ray::new(film, s.point - film), WL, TraceDirection::FilmToScene).is_some() as usize;
        }
    }
    let rejection = 1.0 - passing as f64 / sampled as f64;
    eprintln!("{film_points} lit film points in rim cells: {:.1} % of their samples absorbed", 100.0 * rejection);
    assert!(film_points > 10_000, "too few film points in rim cells ({film_points})");
    assert!(rejection <= 0.20, "{:.1} % of the rim cells' samples are absorbed", 100.0 * rejection);
}
