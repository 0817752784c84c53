//! `petzval bench bokeh`: camera paths alone against camera paths with bokeh light paths (MIS),
//! on the demo through its real lens and on a night street of small lamps far out of focus:
//! time and relative RMSE against a converged reference over a ladder of samples, then each
//! method's time to equal error.

use super::dof::{cuboid, demo_real_lens, BenchScene};
use super::*;
use glam::{Vec3, Vec4};
use petzval_renderer::film::metrics::relative_rmse;
use petzval_renderer::film::{write_png, Image, ToneMap};
use petzval_renderer::integrator::RenderScene;
use petzval_renderer::render::{render, CameraRig, RenderSettings};
use petzval_renderer::scene::{Environment, Material, Mesh, Scene};
use petzval_renderer::{library_lens, Camera, Error, ExactCamera};

/// A night street through the double Gauss wide open (f/2.03), focused on a bollard 2.5 m away: two rows of
/// small street lamps (8 cm cubes, 4 m up, every 6 m to 60 m) and lit windows on the facades,
/// far out of focus, under a dark blue sky.
fn night_street(w: u32, h: u32) -> Result<BenchScene, Error> {
    let grey =
        |v: f32| Material { base_color: Vec4::new(v, v, v, 1.0), roughness: 0.7, specular: 0.3, ..Material::default() };
    let lamp = Material { emissive: Vec3::new(300.0, 220.0, 120.0), double_sided: true, ..grey(0.0) };
    let window = Material { emissive: Vec3::new(3.0, 2.2, 1.2), double_sided: true, ..grey(0.0) };
    let mut mesh = Mesh::default();
    mesh.append(&cuboid(Vec3::new(-6.0, -1.71, -80.0), Vec3::new(6.0, -1.7, 2.0), 0), 0);
    for side in [-1.0f32, 1.0] {
        mesh.append(&cuboid(Vec3::new(6.0 * side - 0.05, -1.7, -80.0), Vec3::new(6.0 * side + 0.05, 14.0, 2.0), 1), 0);
        for k in 0..10 {
            let z = -5.0 - 6.0 * k as f32;
            let c = Vec3::new(4.5 * side, 2.3, z);
            mesh.append(&cuboid(c - Vec3::splat(0.04), c + Vec3::splat(0.04), 2), 0);
            for row in 0..3 {
                let y = 1.0 + 2.5 * row as f32;
                let x = 6.0 * side - 0.06 * side;
                let lo = Vec3::new(x.min(x + 0.01 * side), y, z - 1.2);
                let hi = Vec3::new(x.max(x + 0.01 * side), y + 1.0, z - 0.4);
                if (k + row) % 3 != 0 {
                    mesh.append(&cuboid(lo, hi, 3), 0);
                }
            }
        }
    }
    mesh.append(&cuboid(Vec3::new(-0.6, -1.7, -2.6), Vec3::new(-0.4, -0.9, -2.4), 1), 0);
    let scene = Scene {
        materials: vec![grey(0.08), grey(0.3), lamp, window],
        environment: Environment::Constant(Vec3::new(0.002, 0.003, 0.008)),
        ..Scene::world(mesh)
    };
    let aspect = w as f64 / h as f64;
    let sensor = Sensor { width_mm: 36.0, height_mm: 36.0 / aspect, ..Sensor::default() };
    let lens = library_lens("double-gauss-50mm")?;
    let camera = ExactCamera::new(sensor, lens, Some(2.5))?;
    Ok(BenchScene {
        name: "night street",
        scene: RenderScene::new(scene)?,
        rig: CameraRig { camera: Camera::Exact(camera), to_world: glam::DAffine3::from_rotation_x(0.08) },
    })
}

/// One run of the ladder.
struct Run {
    scene: &'static str,
    paths: f32,
    spp: u32,
    seconds: f64,
    rel_rmse: f64,
    clipped: f64,
}

/// Relative RMSE of the images clipped at 1 (the display range: the rest of the image beside
/// the highlights).
fn clipped_rmse(reference: &Image, test: &Image) -> f64 {
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (r, t) in reference.rgba.iter().zip(&test.rgba) {
        for k in 0..3 {
            let (r, t) = ((r[k] as f64).min(1.0), (t[k] as f64).min(1.0));
            num += (t - r) * (t - r);
            den += r * r;
        }
    }
    (num / den.max(1e-300)).sqrt()
}

/// Runs the comparison and prints its tables.
pub(super) fn bench_bokeh(
    resolution: &str,
    reference_spp: u32,
    target: f64,
    save: Option<&std::path::Path>,
) -> Result<(), Error> {
    let (w, h) = parse_wxh(resolution)?;
    if let Some(dir) = save {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    let scenes = [demo_real_lens(w, h)?, night_street(w, h)?];
    let base = RenderSettings { width: w, height: h, ..RenderSettings::default() };
    let mut runs = Vec::new();
    for s in &scenes {
        // 1. The reference: camera and light paths (both unbiased; this converges sooner).
        let st = RenderSettings { spp: reference_spp, seed: 99, bokeh_paths: 1.0, ..base.clone() };
        let reference = render(&s.scene, &s.rig, &st, &|_| true)?;
        eprintln!("{}: reference {reference_spp} spp with light paths in {:.1} s", s.name, reference.seconds);
        if let Some(dir) = save {
            write_png(&dir.join(format!("{}-reference.png", slug(s.name))), &reference.image, 0.0, ToneMap::Srgb)?;
        }
        // 2. Each method over a ladder of samples.
        for paths in [0.0f32, 1.0] {
            for spp in [4u32, 16, 64] {
                let st = RenderSettings { spp, seed: 1, bokeh_paths: paths, ..base.clone() };
                let r = render(&s.scene, &s.rig, &st, &|_| true)?;
                let rel_rmse = relative_rmse(&reference.image, &r.image)?;
                let clipped = clipped_rmse(&reference.image, &r.image);
                eprintln!("{}: light paths {paths}, {spp} spp: {:.2} s, rel. RMSE {rel_rmse:.4}", s.name, r.seconds);
                if let Some(dir) = save {
                    let name = format!("{}-paths{paths}-{spp}spp.png", slug(s.name));
                    write_png(&dir.join(name), &r.image, 0.0, ToneMap::Srgb)?;
                }
                runs.push(Run { scene: s.name, paths, spp, seconds: r.seconds, rel_rmse, clipped });
            }
        }
    }
    print_tables(&runs, w, h, reference_spp, target);
    Ok(())
}

fn slug(s: &str) -> String {
    s.chars().map(|c| if c.is_ascii_alphanumeric() { c.to_ascii_lowercase() } else { '-' }).collect()
}

/// The runs, then the time each method needs to reach `target` (from its largest run, with the
/// error falling as 1/√time).
fn print_tables(runs: &[Run], w: u32, h: u32, reference_spp: u32, target: f64) {
    println!(
        "Bokeh light paths: camera paths alone (0) against camera + 1 light path per pixel per sample (1), {w}x{h}, {} threads; reference: {reference_spp} spp with light paths, seed 99. Rel. RMSE over the linear image (the highlights weigh most), and clipped at 1 (the display range).",
        rayon::current_num_threads()
    );
    println!();
    println!("| scene | light paths | spp | seconds | rel. RMSE | rel. RMSE clipped |");
    println!("|---|---|---|---|---|---|");
    for r in runs {
        println!("| {} | {} | {} | {:.2} | {:.4} | {:.4} |", r.scene, r.paths, r.spp, r.seconds, r.rel_rmse, r.clipped);
    }
    println!();
    println!(
        "Time to a relative RMSE of {target} (extrapolated from each method's 64-spp run as error² × time = const):"
    );
    println!();
    println!("| scene | camera paths (s) | with light paths (s) | speed-up | clipped: camera (s) | clipped: light (s) | speed-up |");
    println!("|---|---|---|---|---|---|---|");
    let mut scenes: Vec<&str> = runs.iter().map(|r| r.scene).collect();
    scenes.dedup();
    for scene in scenes {
        let last = |paths: f32| runs.iter().filter(|r| r.scene == scene && r.paths == paths).max_by_key(|r| r.spp);
        let (Some(c), Some(l)) = (last(0.0), last(1.0)) else { continue };
        let t = |r: &Run, e: f64| r.seconds * (e / target).powi(2);
        let (tc, tl) = (t(c, c.rel_rmse), t(l, l.rel_rmse));
        let (kc, kl) = (t(c, c.clipped), t(l, l.clipped));
        println!("| {scene} | {tc:.1} | {tl:.1} | {:.1}× | {kc:.1} | {kl:.1} | {:.1}× |", tc / tl, kc / kl);
    }
}
