//! `petzval bench render-models`: the demo rendered with every lens model, error against time.

use super::*;
use petzval_renderer::{Error, Sensor};
use std::time::Instant;

pub(super) fn bench_render_models(
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
    use petzval_renderer::render::{render, CameraRig, RenderSettings};
    use petzval_renderer::scene::demo;
    use petzval_renderer::{Aperture, ApertureShape, Camera, CameraSpec, LensModel, ShotContext};
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
    // Every camera comes from the product's builder, so each model is the one `petzval render
    // --lens-model MODEL` renders.
    let spec = |model: LensModel| CameraSpec {
        lens: shot.lens.to_string(),
        model,
        f_number: Some(shot.f_number),
        focus_distance_m: Some(shot.focus_distance_m),
        aperture: Some(aperture.clone()),
        sensor,
        ..CameraSpec::default()
    };
    let shot_context = ShotContext { width: w, height: h, spp, depth_range_m: None, spectral: false };
    let build = |model: LensModel| -> Result<Camera, Error> { Ok(spec(model).build(&shot_context)?.camera) };
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
    run("exact", None, None, build(LensModel::Exact)?, seed)?;
    run("exact", None, None, build(LensModel::Exact)?, seed.wrapping_add(1))?;
    run("pinhole", None, None, build(LensModel::Pinhole)?, seed)?;
    run("thin", None, None, build(LensModel::Thin)?, seed)?;
    run("thick", None, None, build(LensModel::Thick)?, seed)?;
    for &res in &res_list {
        // the builder bakes the table (once per process): its time is the bake's
        let t0 = Instant::now();
        let camera = build(LensModel::Lrtf { resolution: res })?;
        let bake_s = t0.elapsed().as_secs_f64();
        run("lrtf", Some(res), Some(bake_s), camera, seed)?;
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
