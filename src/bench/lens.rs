//! `petzval bench lens`: nanoseconds per traced ray and the exit-pupil rejection rate.

use super::*;
use glam::DVec3;
use petzval_renderer::optics::pupil::ExitPupilBounds;
use petzval_renderer::{load_lens, Error, Ray, Sensor, TraceDirection, LIBRARY};
use std::time::Instant;

pub(super) fn bench_lens(only: Option<String>, rays: usize, fstop: Option<f64>, json: bool) -> Result<(), Error> {
    if let Some(f) = fstop.filter(|f| !(f.is_finite() && *f > 0.0)) {
        return Err(Error::settings("--fstop", format!("must be a positive f-number, got {f}")));
    }
    let names: Vec<String> = match only {
        Some(n) => vec![n],
        None => LIBRARY.iter().map(|e| e.name.to_string()).collect(),
    };
    if !json {
        println!("Exact trace, film → scene, primary wavelength, 1 thread, {rays} rays per lens; film points uniform over a 36×24 mm sensor");
        println!(
            "(clamped to the lens's image circle), rear-plane points from the exit-pupil bounds, focus at infinity, {}.",
            fstop.map_or("each lens wide open".to_string(), |f| format!("stopped down to f/{f}"))
        );
        println!();
        println!("| lens | surfaces | ns/ray (all) | ns/ray (passing) | rejection (pupil bounds) | rejection (whole rear disc) | bounds build ms |");
        println!("|---|---|---|---|---|---|---|");
    }
    for name in names {
        let mut lens = load_lens(&name)?;
        if let Some(f) = fstop {
            lens = lens.stopped_down_or_open(f)?.0;
        }
        let film_z = lens.last_vertex_z_mm() + lens.focus_image_distance_mm(None)?;
        let sensor = Sensor::default();
        let (r_max, _) = sensor.extent();
        let t0 = Instant::now();
        let bounds = ExitPupilBounds::compute(&lens, film_z, 0.0, r_max * 1.001);
        let build_ms = t0.elapsed().as_secs_f64() * 1e3;
        // 1. Sample film points whose bounds are non-empty (inside the image circle).
        let mut rng = SplitMix(0x5eed);
        let samples: Vec<(DVec3, DVec3)> =
            camera_ray_samples(&sensor, &bounds, film_z, rays, &mut rng).into_iter().map(|(_, p, q)| (p, q)).collect();
        let wl = lens.primary_wavelength_nm();
        // 2. Time the traces.
        let t0 = Instant::now();
        let mut pass = 0usize;
        for (p, q) in &samples {
            if lens.trace(&Ray::new(*p, *q - *p), wl, TraceDirection::FilmToScene).is_some() {
                pass += 1;
            }
        }
        let secs = t0.elapsed().as_secs_f64();
        // 3. Rejection without bounds: uniform over the rear element's disc (1.5× radius square as pbrt).
        let rear = lens.rear_semi_diameter_mm();
        let mut pass_disc = 0usize;
        let n_disc = samples.len().min(100_000);
        for (p, _) in samples.iter().take(n_disc) {
            let d = petzval_renderer::optics::aperture::concentric_disk(rng.next2()) * rear;
            let q = DVec3::new(d.x, d.y, lens.last_vertex_z_mm());
            if lens.trace(&Ray::new(*p, q - *p), wl, TraceDirection::FilmToScene).is_some() {
                pass_disc += 1;
            }
        }
        let n = samples.len().max(1);
        let ns_all = secs * 1e9 / n as f64;
        let ns_pass = if pass > 0 { secs * 1e9 / pass as f64 } else { f64::INFINITY };
        let rej = 1.0 - pass as f64 / n as f64;
        let rej_disc = 1.0 - pass_disc as f64 / n_disc.max(1) as f64;
        if json {
            println!(
                "{}",
                serde_json::json!({"lens": name, "f_number": fstop, "surfaces": lens.surfaces().len(), "ns_per_ray": ns_all, "ns_per_passing_ray": ns_pass,
                    "rejection_rate": rej, "rejection_rate_rear_disc": rej_disc, "bounds_build_ms": build_ms})
            );
        } else {
            println!(
                "| {name} | {} | {ns_all:.0} | {ns_pass:.0} | {:.1}% | {:.1}% | {build_ms:.0} |",
                lens.surfaces().len(),
                100.0 * rej,
                100.0 * rej_disc
            );
        }
    }
    Ok(())
}
