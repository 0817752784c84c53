//! Cameras: radiometry (cos⁴), sensor tilt and the plane of sharp focus.

use glam::{DVec2, DVec3};
use petzval_renderer::{library_lens, Aperture, Camera, ExactCamera, PinholeCamera, Sensor, ThinCamera};

const WL: f64 = 587.5618;

/// Mean weight over a stratified lens grid: the irradiance from a uniform radiance-1 scene.
fn irradiance(cam: &Camera, film: DVec2) -> f64 {
    irradiance_n(cam, film, 48)
}

fn irradiance_n(cam: &Camera, film: DVec2, n: usize) -> f64 {
    let mut sum = 0.0;
    for i in 0..n {
        for j in 0..n {
            let u = DVec2::new((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
            if let Some(r) = cam.generate_ray(film, u, WL) {
                assert!(r.weight.is_finite() && r.direction.is_finite());
                sum += r.weight;
            }
        }
    }
    sum / (n * n) as f64
}

#[test]
fn pinhole_and_thin_lens_show_cos4_falloff() {
    let sensor = Sensor::default();
    let pin = Camera::Pinhole(PinholeCamera::new(sensor, 50.0).unwrap());
    let thin = Camera::Thin(ThinCamera::new(sensor, 50.0, 16.0, None, Aperture::default()).unwrap());
    for (u, v) in [(0.5, 0.5), (1.0, 0.5), (1.0, 1.0), (0.75, 0.2)] {
        let sx = (u - 0.5) * 36.0;
        let sy = (0.5 - v) * 24.0;
        let cos = 50.0 / (50.0f64 * 50.0 + sx * sx + sy * sy).sqrt();
        let expected = cos.powi(4);
        let e_pin = irradiance(&pin, DVec2::new(u, v));
        assert!((e_pin - expected).abs() < 1e-12, "pinhole {e_pin} vs {expected}");
        let e_thin = irradiance(&thin, DVec2::new(u, v));
        // small aperture (f/16): the exact disc integral differs from cos⁴ by < 0.2%
        assert!((e_thin / expected - 1.0).abs() < 2e-3, "thin {e_thin} vs {expected}");
    }
}

#[test]
fn realistic_centre_is_normalised_and_corners_fall_off() {
    let lens = library_lens("double-gauss-50mm").unwrap().stopped_down(8.0).unwrap();
    let cam = Camera::Exact(ExactCamera::new(Sensor::default(), lens, None).unwrap());
    // the exposure constant is a 256² stratified integral; an independent 400² estimate agrees
    let centre = irradiance_n(&cam, DVec2::new(0.5, 0.5), 400);
    assert!((centre - 1.0).abs() < 2e-3, "{centre}");
    let corner = irradiance(&cam, DVec2::new(1.0, 1.0));
    // cos⁴ at 23.4° is 0.71; with pupil aberration and mechanical vignetting it is lower, not higher
    assert!(corner < 0.8 && corner > 0.2, "corner {corner}");
}

/// For a tilted sensor, rays through the lens from one film point converge on the predicted
/// plane of sharp focus.
#[test]
fn tilted_sensor_focus_plane_thin_lens_is_exact() {
    let sensor = Sensor { tilt_x_deg: 10.0, ..Sensor::default() };
    let cam = Camera::Thin(ThinCamera::new(sensor, 50.0, 2.0, Some(3.0), Aperture::default()).unwrap());
    let plane = cam.focus_plane().unwrap();
    // hinge rule: J = f / sin(tilt), with f the lens's focal length as focused (Blender's thin
    // lens keeps the film at F = 50 mm and focuses by its power: f = F·s/(F + s))
    let f = 0.05 * 3.0 / (0.05 + 3.0);
    let j = f / 10f64.to_radians().sin();
    assert!((plane.hinge_distance_m.unwrap() - j).abs() < 1e-9, "{:?} vs {j}", plane.hinge_distance_m);
    // With the bottom of the sensor tilted away, the plane of focus swings down towards the
    // ground: pixels below the centre see it in front of the camera.
    for film in [DVec2::new(0.5, 0.55), DVec2::new(0.5, 0.9), DVec2::new(0.2, 0.75)] {
        let rays: Vec<_> = [DVec2::new(0.1, 0.5), DVec2::new(0.9, 0.5), DVec2::new(0.5, 0.1)]
            .iter()
            .filter_map(|u| cam.generate_ray(film, *u, WL))
            .collect();
        let pts: Vec<DVec3> =
            rays.iter().map(|r| r.origin + r.direction * plane.intersect(r.origin, r.direction).unwrap()).collect();
        for p in &pts[1..] {
            assert!((*p - pts[0]).length() < 1e-9, "rays meet the plane at one point");
        }
    }
}

#[test]
fn sensor_tilted_30_degrees_realistic_focus_plane_verified_by_tracing() {
    let lens = library_lens("double-gauss-50mm").unwrap().stopped_down(4.0).unwrap();
    let sensor = Sensor { tilt_x_deg: 30.0, width_mm: 24.0, height_mm: 16.0, ..Sensor::default() };
    let cam = Camera::Exact(ExactCamera::new(sensor, lens, Some(2.0)).unwrap());
    let plane = cam.focus_plane().unwrap();
    assert!(plane.hinge_distance_m.is_some());
    let mut checked = 0;
    for film in [DVec2::new(0.5, 0.55), DVec2::new(0.5, 0.7), DVec2::new(0.3, 0.9)] {
        // best focus: the point along the bundle where its spread is smallest
        let rays: Vec<_> = (0..64)
            .filter_map(|k| {
                let u = DVec2::new((k % 8) as f64 / 8.0 + 0.0625, (k / 8) as f64 / 8.0 + 0.0625);
                cam.generate_ray(film, u, WL)
            })
            .collect();
        if rays.len() < 8 {
            continue;
        }
        let mean_dir = rays.iter().fold(DVec3::ZERO, |a, r| a + r.direction).normalize();
        let spread_at = |t: f64| {
            let pts: Vec<DVec3> =
                rays.iter().map(|r| r.origin + r.direction * (t / r.direction.dot(mean_dir))).collect();
            let c = pts.iter().fold(DVec3::ZERO, |a, p| a + *p) / pts.len() as f64;
            pts.iter().map(|p| (*p - c).length_squared()).sum::<f64>()
        };
        let (mut lo, mut hi) = (0.1f64, 100.0f64);
        for _ in 0..200 {
            let m1 = lo + (hi - lo) / 3.0;
            let m2 = hi - (hi - lo) / 3.0;
            if spread_at(m1) < spread_at(m2) {
                hi = m2
            } else {
                lo = m1
            }
        }
        let t_best = 0.5 * (lo + hi);
        let c = rays[0].origin;
        let t_plane = plane.intersect(c, mean_dir).unwrap();
        let rel = (t_best - t_plane).abs() / t_plane;
        assert!(rel < 0.05, "film {film:?}: traced best focus {t_best:.4} m vs plane {t_plane:.4} m");
        checked += 1;
    }
    assert!(checked >= 2);
}

/// Spectral rays: through a lens with dispersive glass the same film and lens sample leave in
/// different directions for blue and red (lateral colour grows off axis); a lens without
/// dispersion gives the same ray for every wavelength.
#[test]
fn dispersive_lens_separates_wavelengths() {
    let lens = library_lens("zeiss-biotar-100mm").unwrap();
    assert!(lens.has_dispersion());
    let cam = Camera::Exact(ExactCamera::new(Sensor::default(), lens, None).unwrap());
    let u = DVec2::new(0.5, 0.5);
    let (mut centre, mut corner) = (0.0f64, 0.0f64);
    for (film, out) in [(DVec2::new(0.5, 0.5), &mut centre), (DVec2::new(0.95, 0.9), &mut corner)] {
        let b = cam.generate_ray(film, u, 486.1327).unwrap();
        let r = cam.generate_ray(film, u, 656.2725).unwrap();
        *out = b.direction.angle_between(r.direction);
    }
    assert!(corner > 1e-4, "lateral colour at the corner: {corner} rad");
    assert!(corner > 5.0 * centre, "it grows off axis: centre {centre}, corner {corner}");
    let plain = library_lens("double-gauss-50mm").unwrap();
    assert!(!plain.has_dispersion());
    let cam = Camera::Exact(ExactCamera::new(Sensor::default(), plain, None).unwrap());
    let b = cam.generate_ray(DVec2::new(0.9, 0.9), u, 450.0).unwrap();
    let r = cam.generate_ray(DVec2::new(0.9, 0.9), u, 650.0).unwrap();
    assert_eq!(b.direction, r.direction);
}
