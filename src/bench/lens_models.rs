//! `petzval bench lens-models`: speed against error of every lens model per camera ray.

use super::*;
use glam::{DVec2, DVec3};
use petzval_renderer::optics::lrtf::LRTF_BATCH;
use petzval_renderer::{load_lens, Error, Ray, Sensor, TraceDirection, LIBRARY};
use std::time::Instant;

/// Best (smallest) time per ray over [`REPEATS`] runs of `f` over `rays`, in ns; the results
/// are summed into a black box so nothing is optimised away and nothing is stored.
pub(super) fn best_ns_per_ray(rays: &[Ray], f: impl Fn(&Ray) -> f64) -> f64 {
    let mut best = f64::INFINITY;
    for _ in 0..REPEATS {
        let t0 = Instant::now();
        let mut check = 0.0;
        for r in rays {
            check += f(r);
        }
        best = best.min(t0.elapsed().as_secs_f64());
        std::hint::black_box(check);
    }
    best * 1e9 / rays.len().max(1) as f64
}

/// [`best_ns_per_ray`] for a function of [`LRTF_BATCH`] rays at a time (a short last batch is
/// padded with its first ray; the time is still divided by the number of rays).
pub(super) fn best_ns_per_ray_batched(rays: &[Ray], f: impl Fn(&[Ray; LRTF_BATCH]) -> f64) -> f64 {
    let batches: Vec<[Ray; LRTF_BATCH]> =
        rays.chunks(LRTF_BATCH).map(|c| std::array::from_fn(|i| *c.get(i).unwrap_or(&c[0]))).collect();
    let mut best = f64::INFINITY;
    for _ in 0..REPEATS {
        let t0 = Instant::now();
        let mut check = 0.0;
        for b in &batches {
            check += f(b);
        }
        best = best.min(t0.elapsed().as_secs_f64());
        std::hint::black_box(check);
    }
    best * 1e9 / rays.len().max(1) as f64
}

/// Sensor used to express errors in pixels: 36 mm across 1920 pixels.
const PIXEL_PITCH_MM: f64 = 36.0 / 1920.0;

pub(super) fn bench_lens_models(only: Option<String>, rays: usize, resolutions: &str, json: bool) -> Result<(), Error> {
    use petzval_renderer::optics::lrtf::{exit_sphere, BakeOptions, LrtfLookup, LrtfTable};
    use petzval_renderer::optics::pupil::{self, ExitPupilBounds};
    use petzval_renderer::{Camera, CameraSpec, LensModel, ShotContext};
    let res_list: Vec<u32> = resolutions.split(',').filter_map(|r| r.trim().parse().ok()).collect();
    let names: Vec<String> = match only {
        Some(n) => vec![n],
        None => LIBRARY.iter().map(|e| e.name.to_string()).collect(),
    };
    let mut rows: Vec<serde_json::Value> = Vec::new();
    for name in names {
        let lens = load_lens(&name)?;
        let wl = lens.primary_wavelength_nm();
        let efl = lens.paraxial().efl_mm;
        let film_z = lens.last_vertex_z_mm() + lens.focus_image_distance_mm(None)?;
        let sensor = Sensor::default();
        let bounds = ExitPupilBounds::compute(&lens, film_z, 0.0, sensor.extent().0 * 1.001);
        // 1. The camera's ray distribution: film points over the sensor, rear points in bounds.
        let drawn = camera_ray_samples(&sensor, &bounds, film_z, rays, &mut SplitMix(0xbe9c));
        let samples: Vec<Ray> = drawn.iter().map(|(_, p, q)| Ray::new(*p, *q - *p)).collect();
        let film_uv: Vec<DVec2> = drawn.iter().map(|(u, _, _)| *u).collect();
        // The same rays in raster order (sorted by pixel of a 1920-wide image), as a renderer
        // generates them: neighbouring rays share film points, so table cells stay in cache.
        let raster: Vec<Ray> = {
            let mut idx: Vec<(u64, usize)> = film_uv
                .iter()
                .enumerate()
                .map(|(i, u)| (((u.y * 1280.0) as u64) * 1920 + (u.x * 1920.0) as u64, i))
                .collect();
            idx.sort_unstable();
            idx.iter().map(|(_, i)| samples[*i]).collect()
        };
        // 2. Exact reference (timed; best of REPEATS, without storing results).
        let exact_ns = best_ns_per_ray(&samples, |r| {
            lens.trace(r, wl, TraceDirection::FilmToScene).map_or(0.0, |t| t.ray.direction.x)
        });
        let exact: Vec<Option<Ray>> =
            samples.iter().map(|r| lens.trace(r, wl, TraceDirection::FilmToScene).map(|t| t.ray)).collect();
        let mut push = |model: &str,
                        res: Option<u32>,
                        ns: f64,
                        pos_um: Option<f64>,
                        dir_mrad: f64,
                        mean_px: f64,
                        max_px: f64,
                        mis: Option<f64>,
                        extra: serde_json::Value| {
            let mut v = serde_json::json!({
                "lens": name, "model": model, "resolution": res, "ns_per_ray": ns,
                "mean_position_error_um": pos_um, "mean_direction_error_mrad": dir_mrad,
                "mean_image_error_px": mean_px, "max_image_error_px": max_px, "misclassified_fraction": mis,
            });
            if let (Some(o), Some(e)) = (v.as_object_mut(), extra.as_object()) {
                for (k, x) in e {
                    o.insert(k.clone(), x.clone());
                }
            }
            rows.push(v);
        };
        push("exact", None, exact_ns, Some(0.0), 0.0, 0.0, 0.0, Some(0.0), serde_json::json!({}));
        // 3. Pinhole, thin and thick: distortion of the chief ray against the exact lens, on a
        //    grid of film points; time per generated camera ray.
        let grid: Vec<DVec2> = (0..15)
            .flat_map(|i| (0..10).map(move |j| DVec2::new((i as f64 + 0.5) / 15.0, (j as f64 + 0.5) / 10.0)))
            .collect();
        let mut chief: Vec<(DVec3, DVec3)> = Vec::new(); // (film point, exact chief direction)
        for u in &grid {
            let p = sensor.film_point(*u, film_z);
            if let Some(r) = pupil::chief_ray_from_film(&lens, p, wl) {
                chief.push((p, r.direction));
            }
        }
        // The product's cameras (the one builder), wide open and focused at infinity.
        let build = |model: LensModel| -> Result<Camera, Error> {
            let spec = CameraSpec { lens: name.clone(), model, sensor, ..CameraSpec::default() };
            Ok(spec.build(&ShotContext::default())?.camera)
        };
        let analytic: Vec<(&str, Camera)> = vec![
            ("pinhole", build(LensModel::Pinhole)?),
            ("thin", build(LensModel::Thin)?),
            ("thick", build(LensModel::Thick)?),
        ];
        for (model, cam) in analytic {
            let t0 = Instant::now();
            let mut n_ok = 0usize;
            for (i, u) in film_uv.iter().enumerate() {
                let lu = DVec2::new((i as f64 * 0.618_034) % 1.0, (i as f64 * 0.414_214) % 1.0);
                n_ok += cam.generate_ray(*u, lu, wl).is_some() as usize;
            }
            let ns = t0.elapsed().as_secs_f64() * 1e9 / film_uv.len().max(1) as f64;
            let _ = n_ok;
            // these models image a direction θ at h = f·tanθ (rectilinear): compare with the
            // exact chief ray of each film point
            let (mut sum_mrad, mut sum_px, mut max_px) = (0.0, 0.0, 0.0f64);
            for (p, d) in &chief {
                let model_dir = DVec3::new(-p.x, -p.y, -efl.abs()).normalize();
                let ang = d.dot(model_dir).clamp(-1.0, 1.0).acos();
                let h_exact = efl.abs() * (d.x.hypot(d.y) / (-d.z).max(1e-9));
                let px = ((h_exact - p.x.hypot(p.y)).abs() / PIXEL_PITCH_MM).min(1e6);
                sum_mrad += ang * 1e3;
                sum_px += px;
                max_px = max_px.max(px);
            }
            let n = chief.len().max(1) as f64;
            push(
                model,
                None,
                ns,
                None,
                sum_mrad / n,
                sum_px / n,
                max_px,
                None,
                serde_json::json!({"note": "chief-ray distortion against the exact lens; no vignetting"}),
            );
        }
        // 4. LRTF tables at each resolution.
        if lens.is_rotationally_symmetric() {
            for &res in &res_list {
                let t0 = Instant::now();
                let table =
                    LrtfTable::bake(&lens, &BakeOptions { resolution: res, ..BakeOptions::default() }, &|_| {})?;
                let bake_s = t0.elapsed().as_secs_f64();
                let resolve = |r: &Ray, found: LrtfLookup| match found {
                    LrtfLookup::Hit(h) => {
                        (lens.aperture().transmission(h.stop_point.x, h.stop_point.y, lens.stop_semi_diameter_mm())
                            > 0.0)
                            .then_some(h.ray)
                    }
                    LrtfLookup::Miss => None,
                    LrtfLookup::Uncertain => lens.trace(r, wl, TraceDirection::FilmToScene).map(|t| t.ray),
                };
                let map = |r: &Ray| resolve(r, table.lookup(r, wl));
                let with_fallback = |r: &Ray| map(r).map_or(0.0, |o| o.direction.x);
                // the same compiled for the baseline instruction set only (the lookup picks
                // AVX2 + FMA at run time where the CPU has them: `simd_level`)
                let with_fallback_baseline =
                    |r: &Ray| resolve(r, table.lookup_baseline(r, wl)).map_or(0.0, |o| o.direction.x);
                let alone_baseline = |r: &Ray| {
                    if let LrtfLookup::Hit(h) = table.lookup_baseline(r, wl) {
                        h.ray.direction.x
                    } else {
                        0.0
                    }
                };
                // the table lookup alone (no exact fallback, no stop test)
                let alone =
                    |r: &Ray| if let LrtfLookup::Hit(h) = table.lookup(r, wl) { h.ray.direction.x } else { 0.0 };
                // batched: LRTF_BATCH rays per lookup (cells and prefetches first), as the
                // renderer's camera generates them
                let wls = [wl; LRTF_BATCH];
                let batched = |b: &[Ray; LRTF_BATCH]| {
                    let found = table.lookup_batch(b, &wls);
                    (0..LRTF_BATCH).map(|i| resolve(&b[i], found[i]).map_or(0.0, |o| o.direction.x)).sum::<f64>()
                };
                let batched_alone = |b: &[Ray; LRTF_BATCH]| {
                    table
                        .lookup_batch(b, &wls)
                        .iter()
                        .map(|f| if let LrtfLookup::Hit(h) = f { h.ray.direction.x } else { 0.0 })
                        .sum::<f64>()
                };
                let ns_batched = best_ns_per_ray_batched(&samples, batched);
                let lookup_ns_batched = best_ns_per_ray_batched(&samples, batched_alone);
                let ns_batched_raster = best_ns_per_ray_batched(&raster, batched);
                let ns = best_ns_per_ray(&samples, with_fallback);
                let lookup_ns = best_ns_per_ray(&samples, alone);
                let ns_baseline = best_ns_per_ray(&samples, with_fallback_baseline);
                let lookup_ns_baseline = best_ns_per_ray(&samples, alone_baseline);
                let ns_raster = best_ns_per_ray(&raster, with_fallback);
                let lookup_ns_raster = best_ns_per_ray(&raster, alone);
                let out: Vec<Option<Ray>> = samples.iter().map(map).collect();
                let uncertain = samples.iter().filter(|r| matches!(table.lookup(r, wl), LrtfLookup::Uncertain)).count();
                let (mut mis, mut both, mut sum_um, mut sum_mrad, mut sum_px, mut max_px) =
                    (0usize, 0usize, 0.0, 0.0, 0.0, 0.0f64);
                let centre = DVec3::new(0.0, 0.0, table.header.out_centre_z_mm);
                for (e, a) in exact.iter().zip(&out) {
                    match (e, a) {
                        (Some(e), Some(a)) => {
                            both += 1;
                            // distance of the table's ray from the exact ray's line (the offset along
                            // the ray does not matter once it has left the lens)
                            let _ = (exit_sphere, centre);
                            sum_um += (a.origin - e.origin).cross(e.direction).length() * 1e3;
                            // angle between the directions, robust near 0 (unlike acos of the dot)
                            let ang = e.direction.cross(a.direction).length().atan2(e.direction.dot(a.direction));
                            sum_mrad += ang * 1e3;
                            let px = efl.abs() * ang / PIXEL_PITCH_MM;
                            sum_px += px;
                            max_px = max_px.max(px);
                        }
                        (None, None) => {}
                        _ => mis += 1,
                    }
                }
                let nb = both.max(1) as f64;
                push(
                    "lrtf",
                    Some(res),
                    ns,
                    Some(sum_um / nb),
                    sum_mrad / nb,
                    sum_px / nb,
                    max_px,
                    Some(mis as f64 / samples.len().max(1) as f64),
                    serde_json::json!({"lookup_ns": lookup_ns, "ns_per_ray_baseline_isa": ns_baseline, "lookup_ns_baseline_isa": lookup_ns_baseline, "simd": format!("{:?}", petzval_renderer::optics::lrtf::simd_level()), "ns_per_ray_raster": ns_raster, "lookup_ns_raster": lookup_ns_raster, "speedup_vs_exact_raster": exact_ns / ns_raster, "uncertain_fraction": uncertain as f64 / samples.len().max(1) as f64, "table_mib": table.data_bytes() as f64 / (1 << 20) as f64, "bake_seconds": bake_s, "speedup_vs_exact": exact_ns / ns, "ns_per_ray_batched": ns_batched, "lookup_ns_batched": lookup_ns_batched, "ns_per_ray_batched_raster": ns_batched_raster, "speedup_vs_exact_batched": exact_ns / ns_batched, "speedup_vs_exact_batched_raster": exact_ns / ns_batched_raster}),
                );
            }
        }
    }
    if json {
        println!("{}", serde_json::to_string_pretty(&rows).unwrap_or_default());
    } else {
        println!("Errors against the exact trace for the camera's own rays (film points over a 36×24 mm sensor, rear points in the exit-pupil bounds, focus at infinity); image error = EFL × angle, in pixels of 36 mm / 1920 px. Pinhole/thin/thick: chief-ray distortion on a 15×10 film grid.");
        println!();
        println!("Times: best of {REPEATS} runs, one thread; \"raster\": the same rays sorted by film pixel; \"batched\": {LRTF_BATCH} rays per lookup (`lookup_batch`), as the renderer's camera generates them.");
        println!();
        println!(
            "LRTF lookups use {:?} on this CPU (detected at run time); \"baseline\": the same lookup compiled for the baseline instruction set.",
            petzval_renderer::optics::lrtf::simd_level()
        );
        println!();
        println!("| lens | model | res | ns/ray | ns/ray baseline | lookup alone ns | lookup alone baseline | speed-up | ns/ray raster | lookup alone raster | speed-up raster | ns/ray batched | lookup alone batched | speed-up batched | pos µm | dir mrad | mean px | max px | misclassified | uncertain (exact fallback) | MiB |");
        println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
        for r in &rows {
            let f = |k: &str| r[k].as_f64();
            println!(
                "| {} | {} | {} | {:.0} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.4} | {:.3} | {:.3} | {} | {} | {} |",
                r["lens"].as_str().unwrap_or(""),
                r["model"].as_str().unwrap_or(""),
                r["resolution"].as_u64().map(|v| v.to_string()).unwrap_or_default(),
                f("ns_per_ray").unwrap_or(0.0),
                f("ns_per_ray_baseline_isa").map(|v| format!("{v:.0}")).unwrap_or_default(),
                f("lookup_ns").map(|v| format!("{v:.0}")).unwrap_or_default(),
                f("lookup_ns_baseline_isa").map(|v| format!("{v:.0}")).unwrap_or_default(),
                f("speedup_vs_exact").map(|v| format!("{v:.1}×")).unwrap_or_default(),
                f("ns_per_ray_raster").map(|v| format!("{v:.0}")).unwrap_or_default(),
                f("lookup_ns_raster").map(|v| format!("{v:.0}")).unwrap_or_default(),
                f("speedup_vs_exact_raster").map(|v| format!("{v:.1}×")).unwrap_or_default(),
                f("ns_per_ray_batched").map(|v| format!("{v:.0}")).unwrap_or_default(),
                f("lookup_ns_batched").map(|v| format!("{v:.0}")).unwrap_or_default(),
                f("speedup_vs_exact_batched").map(|v| format!("{v:.1}×")).unwrap_or_default(),
                f("mean_position_error_um").map(|v| format!("{v:.2}")).unwrap_or_else(|| "–".into()),
                f("mean_direction_error_mrad").unwrap_or(0.0),
                f("mean_image_error_px").unwrap_or(0.0),
                f("max_image_error_px").unwrap_or(0.0),
                f("misclassified_fraction").map(|v| format!("{:.3}%", v * 100.0)).unwrap_or_else(|| "–".into()),
                f("uncertain_fraction").map(|v| format!("{:.1}%", v * 100.0)).unwrap_or_default(),
                f("table_mib").map(|v| format!("{v:.1}")).unwrap_or_default(),
            );
        }
    }
    Ok(())
}
