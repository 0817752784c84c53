//! LRTF tables: accuracy against the exact trace, boundary handling, file round trip.

use glam::{DVec2, DVec3};
use petzval_renderer::optics::lrtf::{BakeOptions, LrtfLookup, LrtfTable};
use petzval_renderer::optics::pupil::ExitPupilBounds;
use petzval_renderer::{library_lens, Lens, Ray, StopMode, TraceDirection};

/// Film rays sampled like the realistic camera does: film points over the sensor, rear points
/// in the exit-pupil bounds of the open stop.
fn camera_rays(lens: &Lens, count: usize, seed: u64) -> Vec<Ray> {
    let film_z = lens.last_vertex_z_mm() + lens.focus_image_distance_mm(None).unwrap();
    let bounds = ExitPupilBounds::compute(lens, film_z, 0.0, 21.7);
    let mut state = seed;
    let mut rnd = || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut rays = Vec::with_capacity(count);
    while rays.len() < count {
        let film = DVec3::new(36.0 * (rnd() - 0.5), 24.0 * (rnd() - 0.5), film_z);
        if let Some(s) = bounds.sample(DVec2::new(film.x, film.y), DVec2::new(rnd(), rnd())) {
            rays.push(Ray::new(film, s.point - film));
        }
    }
    rays
}

#[test]
fn lrtf_error_report_double_gauss() {
    let lens = library_lens("double-gauss-50mm").unwrap();
    for res in [96u32] {
        let t0 = std::time::Instant::now();
        let table = LrtfTable::bake(&lens, &BakeOptions { resolution: res, ..Default::default() }, &|_| {}).unwrap();
        let bake_s = t0.elapsed().as_secs_f64();
        let wl = lens.primary_wavelength_nm();
        let rays = camera_rays(&lens, 50_000, 7);
        let (mut n_both, mut mis, mut dir_err, mut max_dir, mut uncertain) = (0usize, 0usize, 0.0f64, 0.0f64, 0usize);
        for r in &rays {
            let exact = lens.trace_detailed(r, wl, TraceDirection::FilmToScene, StopMode::Apply).ok();
            let approx = match table.lookup(r, wl) {
                LrtfLookup::Hit(l) => (lens.aperture().transmission(l.stop_point.x, l.stop_point.y, lens.stop_semi_diameter_mm()) > 0.0).then_some(l),
                LrtfLookup::Miss => None,
                LrtfLookup::Uncertain => {
                    uncertain += 1;
                    continue;
                }
            };
            match (exact, approx) {
                (Some(e), Some(a)) => {
                    n_both += 1;
                    let de = (e.ray.direction - a.ray.direction).length();
                    dir_err += de;
                    max_dir = max_dir.max(de);
                }
                (None, None) => {}
                _ => mis += 1,
            }
        }
        eprintln!(
            "res {res}: bake {bake_s:.2} s, {:.1} MiB, both {n_both}, uncertain {:.2}%, misclassified {:.3}%, mean dir err {:.4} mrad, max {:.4} mrad",
            table.data_bytes() as f64 / (1 << 20) as f64,
            100.0 * uncertain as f64 / rays.len() as f64,
            100.0 * mis as f64 / rays.len() as f64,
            1e3 * dir_err / n_both as f64,
            1e3 * max_dir
        );

    }
}



