//! `petzval bench render`: path-tracing throughput on a dense triangle scene.

use petzval_renderer::{load_lens, Error, Sensor};
use std::time::Instant;

/// A height field plus a displaced sphere, about `triangles` triangles.
pub(super) fn dense_scene(triangles: usize) -> petzval_renderer::scene::Scene {
    use glam::{Vec2, Vec3, Vec4};
    use petzval_renderer::scene::{Environment, Material, Scene};
    let mut scene = Scene::default();
    scene.materials.push(Material { metallic: 0.0, roughness: 0.8, ..Material::default() });
    let n = ((triangles as f64 * 0.75 / 2.0).sqrt() as u32).max(2);
    let mut mesh = petzval_renderer::scene::Mesh::default();
    let m = &mut mesh;
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
    scene.add_world_mesh(mesh);
    scene.environment = Environment::Constant(Vec3::ONE);
    scene
}

pub(super) fn bench_render(resolution: &str, spp: u32, triangles: usize) -> Result<(), Error> {
    use petzval_renderer::integrator::{primary_ray_throughput, primary_ray_throughput_packets, RenderScene};
    use petzval_renderer::render::{render, CameraRig, RenderSettings};
    use petzval_renderer::scene::demo;
    use petzval_renderer::{Aperture, Camera, ExactCamera, PinholeCamera, ThickCamera, ThinCamera};
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
    let _ = primary_ray_throughput_packets(&rs, 100_000);
    let rps_packets = primary_ray_throughput_packets(&rs, 2_000_000);
    println!("## Scene throughput ({} triangles)", rs.triangle_count());
    println!();
    println!(
        "| BVH build | RenderScene::new | BVH memory | bytes/triangle | primary rays, 1 thread | in packets of 8 |"
    );
    println!("|---|---|---|---|---|---|");
    println!(
        "| {:.3} s | {:.3} s | {:.1} MB | {:.1} | {:.2} M rays/s | {:.2} M rays/s |",
        rs.bvh_build_time().as_secs_f64(),
        total,
        rs.bvh_memory_bytes() as f64 / 1e6,
        rs.bvh_memory_bytes() as f64 / rs.triangle_count() as f64,
        rps / 1e6,
        rps_packets / 1e6
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
        ("thin", Camera::Thin(ThinCamera::new(sensor, f, shot.f_number, focus, Aperture::default())?)),
        ("thick", Camera::Thick(ThickCamera::new(sensor, &lens, None, focus, Aperture::default())?)),
        ("exact (double-gauss-50mm)", Camera::Exact(ExactCamera::new(sensor, lens.clone(), focus)?)),
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
