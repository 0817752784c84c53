//! `petzval bench ...`: benchmarks that print tables (results recorded in docs/performance.md).

use clap::Subcommand;
use glam::{DVec2, DVec3};
use petzval_renderer::optics::pupil::ExitPupilBounds;
use petzval_renderer::{load_lens, Error, Ray, Sensor, TraceDirection, LIBRARY};
use std::time::Instant;

/// Benchmark subcommands.
#[derive(Subcommand)]
pub enum BenchCommand {
    /// ns per traced ray for every library lens (all rays and passing rays) and the exit-pupil
    /// rejection rate, on one thread.
    Lens {
        /// Only this lens.
        #[arg(long)]
        lens: Option<String>,
        /// Rays per lens.
        #[arg(long, default_value_t = 400_000)]
        rays: usize,
        /// Print JSON lines instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Speed against error of every lens model (pinhole, thin, thick, LRTF at several
    /// resolutions, exact) for each library lens.
    LensModels {
        /// Only this lens.
        #[arg(long)]
        lens: Option<String>,
        /// Rays per lens and model.
        #[arg(long, default_value_t = 200_000)]
        rays: usize,
        /// LRTF resolutions.
        #[arg(long, default_value = "32,64,96,128")]
        resolutions: String,
        /// Print a JSON array instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Image-level error of every camera model (pinhole, thin, thick, LRTF at several
    /// resolutions) against the exact render of the built-in demo at equal spp and seed:
    /// relative RMSE, mean LDR-FLIP, render and bake seconds, and the noise floor (the exact
    /// model with another seed).
    RenderModels {
        /// Resolution WxH.
        #[arg(long, default_value = "480x320")]
        resolution: String,
        /// Samples per pixel (every model).
        #[arg(long, default_value_t = 64)]
        spp: u32,
        /// LRTF resolutions.
        #[arg(long, default_value = "32,64,96")]
        resolutions: String,
        /// Seed of every render (the noise floor uses seed + 1).
        #[arg(long, default_value_t = 0)]
        seed: u32,
        /// Write each render as a PNG into this directory.
        #[arg(long)]
        save: Option<std::path::PathBuf>,
        /// Print a JSON array instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Render cost by camera model on the built-in demo (ratio to pinhole), and primary-ray
    /// throughput, BVH build time and memory on a ~1M-triangle scene.
    Render {
        /// Resolution of the camera-model comparison.
        #[arg(long, default_value = "480x320")]
        resolution: String,
        /// Samples per pixel of the camera-model comparison.
        #[arg(long, default_value_t = 16)]
        spp: u32,
        /// Triangles in the throughput scene (about).
        #[arg(long, default_value_t = 1_000_000)]
        triangles: usize,
    },
}

/// Runs a benchmark.
pub fn run(cmd: BenchCommand) -> Result<(), Error> {
    match cmd {
        BenchCommand::Lens { lens, rays, json } => bench_lens(lens, rays, json),
        BenchCommand::Render { resolution, spp, triangles } => bench_render(&resolution, spp, triangles),
        BenchCommand::LensModels { lens, rays, resolutions, json } => bench_lens_models(lens, rays, &resolutions, json),
        BenchCommand::RenderModels { resolution, spp, resolutions, seed, save, json } => {
            bench_render_models(&resolution, spp, &resolutions, seed, save.as_deref(), json)
        }
    }
}

/// A small deterministic generator (SplitMix64) for benchmark samples.
struct SplitMix(u64);
impl SplitMix {
    fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn next2(&mut self) -> DVec2 {
        DVec2::new(self.next_f64(), self.next_f64())
    }
}

/// Up to `count` camera rays as the realistic camera draws them: (image position, film point,
/// rear-plane point inside the exit-pupil bounds), drawn from `rng`; film points outside the
/// image circle (empty bounds) are skipped.
fn camera_ray_samples(
    sensor: &Sensor,
    bounds: &petzval_renderer::optics::pupil::ExitPupilBounds,
    film_z: f64,
    count: usize,
    rng: &mut SplitMix,
) -> Vec<(DVec2, DVec3, DVec3)> {
    let mut out = Vec::with_capacity(count);
    let mut guard = 0;
    while out.len() < count && guard < count * 50 {
        guard += 1;
        let u = rng.next2();
        let p = sensor.film_point(u, film_z);
        if let Some(s) = bounds.sample(DVec2::new(p.x, p.y), rng.next2()) {
            out.push((u, p, s.point));
        }
    }
    out
}

fn bench_lens(only: Option<String>, rays: usize, json: bool) -> Result<(), Error> {
    let names: Vec<String> = match only {
        Some(n) => vec![n],
        None => LIBRARY.iter().map(|e| e.name.to_string()).collect(),
    };
    if !json {
        println!("Exact trace, film → scene, primary wavelength, 1 thread, {rays} rays per lens; film points uniform over a 36×24 mm sensor");
        println!(
            "(clamped to the lens's image circle), rear-plane points from the exit-pupil bounds, focus at infinity."
        );
        println!();
        println!("| lens | surfaces | ns/ray (all) | ns/ray (passing) | rejection (pupil bounds) | rejection (whole rear disc) | bounds build ms |");
        println!("|---|---|---|---|---|---|---|");
    }
    for name in names {
        let lens = load_lens(&name)?;
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
                serde_json::json!({"lens": name, "surfaces": lens.surfaces().len(), "ns_per_ray": ns_all, "ns_per_passing_ray": ns_pass,
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

/// A height field plus a displaced sphere, about `triangles` triangles.
fn dense_scene(triangles: usize) -> petzval_renderer::scene::Scene {
    use glam::{Vec2, Vec3, Vec4};
    use petzval_renderer::scene::{Environment, Material, Scene};
    let mut scene = Scene::default();
    scene.materials.push(Material { metallic: 0.0, roughness: 0.8, ..Material::default() });
    let n = ((triangles as f64 * 0.75 / 2.0).sqrt() as u32).max(2);
    let m = &mut scene.mesh;
    for j in 0..=n {
        for i in 0..=n {
            let (x, z) = (i as f32 / n as f32 * 20.0 - 10.0, j as f32 / n as f32 * 20.0 - 10.0);
            let y = 0.3 * (x * 1.7).sin() * (z * 1.3).cos() + 0.05 * (x * 9.0).sin();
            m.positions.push(Vec3::new(x, y, z));
            m.normals.push(Vec3::Y);
            m.tangents.push(Vec4::ZERO);
            m.uv0.push(Vec2::new(i as f32 / n as f32, j as f32 / n as f32));
        }
    }
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i;
            m.indices.push([a, a + n + 1, a + 1]);
            m.indices.push([a + 1, a + n + 1, a + n + 2]);
            m.material_ids.extend([0, 0]);
        }
    }
    // a bumpy sphere for the remaining quarter
    let rings = ((triangles as f64 * 0.25 / 2.0).sqrt() as u32).max(4);
    let base = m.positions.len() as u32;
    for r in 0..=rings {
        let th = std::f32::consts::PI * r as f32 / rings as f32;
        for k in 0..=rings {
            let ph = std::f32::consts::TAU * k as f32 / rings as f32;
            let d = Vec3::new(th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin());
            let rad = 2.0 + 0.05 * (th * 23.0).sin() * (ph * 17.0).cos();
            m.positions.push(Vec3::new(0.0, 2.5, 0.0) + d * rad);
            m.normals.push(d);
            m.tangents.push(Vec4::ZERO);
            m.uv0.push(Vec2::ZERO);
        }
    }
    for r in 0..rings {
        for k in 0..rings {
            let a = base + r * (rings + 1) + k;
            let b = a + rings + 1;
            m.indices.push([a, b, a + 1]);
            m.indices.push([a + 1, b, b + 1]);
            m.material_ids.extend([0, 0]);
        }
    }
    scene.environment = Environment::Constant(Vec3::ONE);
    scene
}

fn bench_render(resolution: &str, spp: u32, triangles: usize) -> Result<(), Error> {
    use petzval_renderer::integrator::{primary_ray_throughput, RenderScene};
    use petzval_renderer::render::{render, CameraRig, RenderSettings};
    use petzval_renderer::scene::demo;
    use petzval_renderer::{Aperture, Camera, PinholeCamera, RealisticCamera, ThickLensCamera, ThinLensCamera};
    let (w, h) = resolution
        .split_once('x')
        .and_then(|(a, b)| Some((a.parse::<u32>().ok()?, b.parse::<u32>().ok()?)))
        .ok_or_else(|| Error::Camera {
        field: "resolution".into(),
        message: format!("expected WxH, got '{resolution}'"),
    })?;
    // 1. Throughput on a dense scene (one thread).
    let scene = dense_scene(triangles);
    let t0 = Instant::now();
    let rs = RenderScene::new(scene)?;
    let total = t0.elapsed().as_secs_f64();
    let _ = primary_ray_throughput(&rs, 100_000);
    let rps = primary_ray_throughput(&rs, 2_000_000);
    println!("## Scene throughput ({} triangles)", rs.triangle_count());
    println!();
    println!("| BVH build | RenderScene::new | BVH memory | bytes/triangle | primary rays, 1 thread |");
    println!("|---|---|---|---|---|");
    println!(
        "| {:.3} s | {:.3} s | {:.1} MB | {:.1} | {:.2} M rays/s |",
        rs.bvh_build_time().as_secs_f64(),
        total,
        rs.bvh_memory_bytes() as f64 / 1e6,
        rs.bvh_memory_bytes() as f64 / rs.triangle_count() as f64,
        rps / 1e6
    );
    println!();
    // 2. Camera models on the demo, same scene, resolution and spp.
    let (scene, shot) = demo::demo_scene();
    let cam = scene.cameras[0].clone();
    let to_world = glam::DAffine3::from_cols_array(&cam.to_world.to_cols_array().map(|v| v as f64));
    let rs = RenderScene::new(scene)?;
    let aspect = w as f64 / h as f64;
    let sensor = Sensor { width_mm: 36.0, height_mm: 36.0 / aspect, ..Sensor::default() };
    let lens = load_lens(shot.lens)?.stopped_down(shot.f_number)?;
    let f = lens.paraxial().efl_mm;
    let focus = Some(shot.focus_distance_m);
    let models: Vec<(&str, Camera)> = vec![
        ("pinhole", Camera::Pinhole(PinholeCamera::new(sensor, f)?)),
        ("thin", Camera::ThinLens(ThinLensCamera::new(sensor, f, shot.f_number, focus, Aperture::default())?)),
        ("thick", Camera::ThickLens(ThickLensCamera::new(sensor, &lens, None, focus, Aperture::default())?)),
        ("exact (double-gauss-50mm)", Camera::Realistic(RealisticCamera::new(sensor, lens.clone(), focus)?)),
    ];
    let settings = RenderSettings { width: w, height: h, spp, ..RenderSettings::default() };
    println!(
        "## Render time by camera model (built-in demo, {w}x{h}, {spp} spp, {} threads)",
        rayon::current_num_threads()
    );
    println!();
    println!("| camera model | seconds | ratio to pinhole | camera rays/s |");
    println!("|---|---|---|---|");
    let mut pinhole_s = 0.0;
    for (name, camera) in models {
        let rig = CameraRig { camera, to_world };
        let r = render(&rs, &rig, &settings, &|_| true)?;
        if pinhole_s == 0.0 {
            pinhole_s = r.seconds;
        }
        println!(
            "| {name} | {:.2} | {:.2}× | {:.2} M |",
            r.seconds,
            r.seconds / pinhole_s,
            r.camera_rays as f64 / r.seconds / 1e6
        );
    }
    Ok(())
}

/// Timed runs per measurement in `bench lens-models` (the best is reported: the machine may be
/// shared, and interference only ever adds time).
const REPEATS: usize = 5;

/// Best (smallest) time per ray over [`REPEATS`] runs of `f` over `rays`, in ns; the results
/// are summed into a black box so nothing is optimised away and nothing is stored.
fn best_ns_per_ray(rays: &[Ray], f: impl Fn(&Ray) -> f64) -> f64 {
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

/// Sensor used to express errors in pixels: 36 mm across 1920 pixels.
const PIXEL_PITCH_MM: f64 = 36.0 / 1920.0;

fn bench_lens_models(only: Option<String>, rays: usize, resolutions: &str, json: bool) -> Result<(), Error> {
    use petzval_renderer::optics::lrtf::{exit_sphere, BakeOptions, LrtfLookup, LrtfTable};
    use petzval_renderer::optics::pupil::{self, ExitPupilBounds};
    use petzval_renderer::{Aperture, Camera, PinholeCamera, ThickLensCamera, ThinLensCamera};
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
        let analytic: Vec<(&str, Camera)> = vec![
            ("pinhole", Camera::Pinhole(PinholeCamera::new(sensor, efl.abs())?)),
            (
                "thin",
                Camera::ThinLens(ThinLensCamera::new(
                    sensor,
                    efl.abs(),
                    lens.paraxial().f_number,
                    None,
                    Aperture::default(),
                )?),
            ),
            ("thick", Camera::ThickLens(ThickLensCamera::new(sensor, &lens, None, None, Aperture::default())?)),
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
                let map = |r: &Ray| match table.lookup(r, wl) {
                    LrtfLookup::Hit(h) => {
                        (lens.aperture().transmission(h.stop_point.x, h.stop_point.y, lens.stop_semi_diameter_mm())
                            > 0.0)
                            .then_some(h.ray)
                    }
                    LrtfLookup::Miss => None,
                    LrtfLookup::Uncertain => lens.trace(r, wl, TraceDirection::FilmToScene).map(|t| t.ray),
                };
                let with_fallback = |r: &Ray| map(r).map_or(0.0, |o| o.direction.x);
                // the table lookup alone (no exact fallback, no stop test)
                let alone =
                    |r: &Ray| if let LrtfLookup::Hit(h) = table.lookup(r, wl) { h.ray.direction.x } else { 0.0 };
                let ns = best_ns_per_ray(&samples, with_fallback);
                let lookup_ns = best_ns_per_ray(&samples, alone);
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
                    serde_json::json!({"lookup_ns": lookup_ns, "ns_per_ray_raster": ns_raster, "lookup_ns_raster": lookup_ns_raster, "speedup_vs_exact_raster": exact_ns / ns_raster, "uncertain_fraction": uncertain as f64 / samples.len().max(1) as f64, "table_mib": table.data_bytes() as f64 / (1 << 20) as f64, "bake_seconds": bake_s, "speedup_vs_exact": exact_ns / ns}),
                );
            }
        }
    }
    if json {
        println!("{}", serde_json::to_string_pretty(&rows).unwrap_or_default());
    } else {
        println!("Errors against the exact trace for the camera's own rays (film points over a 36×24 mm sensor, rear points in the exit-pupil bounds, focus at infinity); image error = EFL × angle, in pixels of 36 mm / 1920 px. Pinhole/thin/thick: chief-ray distortion on a 15×10 film grid.");
        println!();
        println!("Times: best of {REPEATS} runs, one thread; \"raster\": the same rays sorted by film pixel, as a renderer generates them.");
        println!();
        println!("| lens | model | res | ns/ray | lookup alone ns | speed-up | ns/ray raster | lookup alone raster | speed-up raster | pos µm | dir mrad | mean px | max px | misclassified | uncertain (exact fallback) | MiB |");
        println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
        for r in &rows {
            let f = |k: &str| r[k].as_f64();
            println!(
                "| {} | {} | {} | {:.0} | {} | {} | {} | {} | {} | {} | {:.4} | {:.3} | {:.3} | {} | {} | {} |",
                r["lens"].as_str().unwrap_or(""),
                r["model"].as_str().unwrap_or(""),
                r["resolution"].as_u64().map(|v| v.to_string()).unwrap_or_default(),
                f("ns_per_ray").unwrap_or(0.0),
                f("lookup_ns").map(|v| format!("{v:.0}")).unwrap_or_default(),
                f("speedup_vs_exact").map(|v| format!("{v:.1}×")).unwrap_or_default(),
                f("ns_per_ray_raster").map(|v| format!("{v:.0}")).unwrap_or_default(),
                f("lookup_ns_raster").map(|v| format!("{v:.0}")).unwrap_or_default(),
                f("speedup_vs_exact_raster").map(|v| format!("{v:.1}×")).unwrap_or_default(),
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

/// Parses `WxH`.
fn parse_wxh(resolution: &str) -> Result<(u32, u32), Error> {
    resolution
        .split_once('x')
        .and_then(|(a, b)| Some((a.trim().parse::<u32>().ok()?, b.trim().parse::<u32>().ok()?)))
        .filter(|(w, h)| *w > 0 && *h > 0)
        .ok_or_else(|| Error::Camera {
            field: "resolution".into(),
            message: format!("expected WxH such as 480x320, got '{resolution}'"),
        })
}

/// Parses a comma-separated list of LRTF resolutions.
fn parse_resolutions(list: &str) -> Result<Vec<u32>, Error> {
    list.split(',')
        .filter(|r| !r.trim().is_empty())
        .map(|r| {
            r.trim().parse::<u32>().ok().filter(|v| (8..=512).contains(v)).ok_or_else(|| Error::Camera {
                field: "resolutions".into(),
                message: format!("expected comma-separated LRTF resolutions in 8..=512, got '{r}'"),
            })
        })
        .collect()
}

fn bench_render_models(
    resolution: &str,
    spp: u32,
    resolutions: &str,
    seed: u32,
    save: Option<&std::path::Path>,
    json: bool,
) -> Result<(), Error> {
    use petzval_renderer::film::metrics::{flip_mean, relative_rmse};
    use petzval_renderer::film::{write_png, Image, ToneMap};
    use petzval_renderer::integrator::RenderScene;
    use petzval_renderer::optics::lrtf::{BakeOptions, LrtfTable};
    use petzval_renderer::render::{render, CameraRig, RenderSettings};
    use petzval_renderer::scene::demo;
    use petzval_renderer::{
        Aperture, ApertureShape, Camera, LrtfCamera, PinholeCamera, RealisticCamera, ThickLensCamera, ThinLensCamera,
    };
    use std::sync::Arc;
    let (w, h) = parse_wxh(resolution)?;
    let res_list = parse_resolutions(resolutions)?;
    let settings = RenderSettings { width: w, height: h, spp, seed, ..RenderSettings::default() };
    settings.validate()?;
    if let Some(dir) = save {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    // 1. The demo as `petzval render` shoots it: its lens stopped down, bladed stop, tilted
    //    sensor 36 mm across the larger image dimension, the demo's focus.
    let (scene, shot) = demo::demo_scene();
    let cam = scene
        .cameras
        .first()
        .cloned()
        .ok_or_else(|| Error::Camera { field: "camera".into(), message: "the demo has no camera".into() })?;
    let to_world = glam::DAffine3::from_cols_array(&cam.to_world.to_cols_array().map(|v| v as f64));
    let rs = RenderScene::new(scene)?;
    let aspect = w as f64 / h as f64;
    let (sw, sh) = if w >= h { (36.0, 36.0 / aspect) } else { (36.0 * aspect, 36.0) };
    let sensor = Sensor { width_mm: sw, height_mm: sh, tilt_x_deg: shot.tilt_x_deg, ..Sensor::default() };
    let aperture = Aperture {
        shape: ApertureShape::Blades { count: shot.blades, curvature: 0.0 },
        rotation_rad: shot.blade_rotation_deg.to_radians(),
        anamorphic_ratio: 1.0,
    };
    let lens = load_lens(shot.lens)?.stopped_down(shot.f_number)?.with_aperture(aperture.clone());
    let focus = Some(shot.focus_distance_m);
    let efl = lens.paraxial().efl_mm;
    let f_number = lens.paraxial().f_number;
    // 2. Render every model with the same settings; the exact render is the reference.
    struct Row {
        model: String,
        resolution: Option<u32>,
        seed: u32,
        seconds: f64,
        bake_seconds: Option<f64>,
        image: Image,
    }
    let mut rows: Vec<Row> = Vec::new();
    let mut run = |model: &str, res: Option<u32>, bake: Option<f64>, camera: Camera, seed: u32| -> Result<(), Error> {
        let rig = CameraRig { camera, to_world };
        let r = render(&rs, &rig, &RenderSettings { seed, ..settings.clone() }, &|_| true)?;
        if !json {
            eprintln!("{model}{}: {:.2} s", res.map(|r| format!(" {r}")).unwrap_or_default(), r.seconds);
        }
        if let Some(dir) = save {
            let name = format!(
                "{model}{}{}.png",
                res.map(|r| format!("-{r}")).unwrap_or_default(),
                if seed != settings.seed { "-seed" } else { "" }
            );
            write_png(&dir.join(name), &r.image, 0.0, ToneMap::Srgb)?;
        }
        rows.push(Row {
            model: model.to_string(),
            resolution: res,
            seed,
            seconds: r.seconds,
            bake_seconds: bake,
            image: r.image,
        });
        Ok(())
    };
    run("exact", None, None, Camera::Realistic(RealisticCamera::new(sensor, lens.clone(), focus)?), seed)?;
    run(
        "exact",
        None,
        None,
        Camera::Realistic(RealisticCamera::new(sensor, lens.clone(), focus)?),
        seed.wrapping_add(1),
    )?;
    run("pinhole", None, None, Camera::Pinhole(PinholeCamera::new(sensor, efl)?), seed)?;
    run(
        "thin",
        None,
        None,
        Camera::ThinLens(ThinLensCamera::new(sensor, efl, f_number, focus, aperture.clone())?),
        seed,
    )?;
    run(
        "thick",
        None,
        None,
        Camera::ThickLens(ThickLensCamera::new(sensor, &lens, None, focus, aperture.clone())?),
        seed,
    )?;
    for &res in &res_list {
        let t0 = Instant::now();
        let table = LrtfTable::bake(&lens, &BakeOptions { resolution: res, ..BakeOptions::default() }, &|_| {})?;
        let bake_s = t0.elapsed().as_secs_f64();
        run(
            "lrtf",
            Some(res),
            Some(bake_s),
            Camera::Lrtf(LrtfCamera::new(sensor, lens.clone(), focus, Arc::new(table))?),
            seed,
        )?;
    }
    // 3. Errors against the exact render.
    let reference = rows[0].image.clone();
    let exact_s = rows[0].seconds;
    let mut out: Vec<serde_json::Value> = Vec::new();
    for r in &rows {
        let rel_rmse = relative_rmse(&reference, &r.image)?;
        let flip = flip_mean(&reference, &r.image, 0.0)?;
        let noise_floor = r.model == "exact" && r.seed != seed;
        out.push(serde_json::json!({
            "lens": shot.lens, "model": if noise_floor { "exact (noise floor: seed + 1)" } else { r.model.as_str() },
            "resolution": r.resolution, "seconds": r.seconds, "bake_seconds": r.bake_seconds,
            "rel_rmse": rel_rmse, "flip_mean": flip, "seed": r.seed, "spp": spp, "width": w, "height": h,
            "time_vs_exact": r.seconds / exact_s,
        }));
    }
    if json {
        println!("{}", serde_json::to_string_pretty(&out).unwrap_or_default());
        return Ok(());
    }
    println!(
        "Built-in demo ({}, f/{:.1}, {} blades, tilt {}°, focus {} m), {w}x{h}, {spp} spp, seed {seed}, {} threads; errors against the exact render (FLIP: LDR-FLIP of the sRGB previews at 67 px/degree).",
        shot.lens,
        shot.f_number,
        shot.blades,
        shot.tilt_x_deg,
        shot.focus_distance_m,
        rayon::current_num_threads()
    );
    println!();
    println!("| model | res | render s | × exact time | bake s | rel. RMSE | mean FLIP |");
    println!("|---|---|---|---|---|---|---|");
    for r in &out {
        println!(
            "| {} | {} | {:.2} | {:.2} | {} | {} | {} |",
            r["model"].as_str().unwrap_or(""),
            r["resolution"].as_u64().map(|v| v.to_string()).unwrap_or_default(),
            r["seconds"].as_f64().unwrap_or(0.0),
            r["time_vs_exact"].as_f64().unwrap_or(0.0),
            r["bake_seconds"].as_f64().map(|v| format!("{v:.2}")).unwrap_or_default(),
            r["rel_rmse"].as_f64().map(|v| format!("{v:.4}")).unwrap_or_default(),
            r["flip_mean"].as_f64().map(|v| format!("{v:.4}")).unwrap_or_default(),
        );
    }
    Ok(())
}
