//! `petzval bench instances`: memory and render time of a heavily instanced scene, and the
//! built-in demo's render time with and without the two-level BVH's top level.
//!
//! | parameter | meaning | default |
//! |---|---|---|
//! | `--instances` | copies of the mesh (on a square grid, random rotation and scale) | 10 000 |
//! | `--triangles` | triangles of the instanced mesh (about; a bumpy UV sphere) | 10 000 |
//! | `--resolution` | image size of the instanced render and of the demo renders | 320x240 |
//! | `--spp` | samples per pixel (both) | 4 |
//! | `--repeats` | demo renders per configuration (the fastest is reported) | 3 |
//! | `--save` | write the instanced render as this PNG | none |

use glam::{Affine3A, Quat, Vec2, Vec3, Vec4};
use petzval_renderer::film::{write_png, ToneMap};
use petzval_renderer::integrator::RenderScene;
use petzval_renderer::render::{render, CameraRig, RenderSettings};
use petzval_renderer::scene::{demo, Environment, Light, Material, Mesh, Scene};
use petzval_renderer::{Camera, Error, PinholeCamera, Sensor};
use std::time::Instant;

use super::{parse_wxh, SplitMix};

/// A bumpy UV sphere of radius about 0.4 with about `triangles` triangles.
fn bumpy_sphere(triangles: usize) -> Mesh {
    let rings = ((triangles as f64 / 4.0).sqrt() as u32).max(3);
    let segments = 2 * rings;
    let mut m = Mesh::default();
    for i in 0..=rings {
        let th = std::f32::consts::PI * i as f32 / rings as f32;
        for j in 0..=segments {
            let ph = std::f32::consts::TAU * j as f32 / segments as f32;
            let n = Vec3::new(th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin());
            let r = 0.4 * (1.0 + 0.06 * (7.0 * th).sin() * (5.0 * ph).cos());
            m.positions.push(n * r);
            m.normals.push(n);
            m.tangents.push(Vec4::ZERO);
            m.uv0.push(Vec2::new(j as f32 / segments as f32, i as f32 / rings as f32));
        }
    }
    for i in 0..rings {
        for j in 0..segments {
            let a = i * (segments + 1) + j;
            let b = a + segments + 1;
            if i > 0 {
                m.indices.push([a, a + 1, b]);
            }
            if i + 1 < rings {
                m.indices.push([a + 1, b + 1, b]);
            }
        }
    }
    m.material_ids = vec![0; m.indices.len()];
    m
}

/// `n` instances of `mesh` on a square grid (1 m pitch), on a ground plane, under a sun.
fn scatter_scene(mesh: Mesh, n: usize) -> (Scene, f32) {
    let mut s = Scene {
        materials: vec![
            Material {
                base_color: Vec4::new(0.7, 0.35, 0.2, 1.0),
                metallic: 0.0,
                roughness: 0.5,
                ..Material::default()
            },
            Material {
                base_color: Vec4::new(0.4, 0.4, 0.4, 1.0),
                metallic: 0.0,
                roughness: 0.9,
                ..Material::default()
            },
        ],
        environment: Environment::Constant(Vec3::new(0.3, 0.35, 0.45)),
        ..Scene::default()
    };
    s.lights.push(Light::Directional {
        direction: Vec3::new(-0.4, -1.0, -0.3).normalize(),
        irradiance: Vec3::splat(2.0),
        angle_rad: 0.0,
    });
    let side = (n as f64).sqrt().ceil() as usize;
    let half = side as f32 * 0.5;
    let id = s.add_mesh(mesh);
    let mut rng = SplitMix(7);
    for k in 0..n {
        let (i, j) = (k % side, k / side);
        let scale = 0.6 + 0.6 * rng.next_f64() as f32;
        let rot = Quat::from_rotation_y(std::f32::consts::TAU * rng.next_f64() as f32);
        let p = Vec3::new(i as f32 - half + 0.5, 0.4 * scale, j as f32 - half + 0.5);
        s.add_instance(id, Affine3A::from_scale_rotation_translation(Vec3::new(scale, scale * 1.3, scale), rot, p));
    }
    let g = half + 2.0;
    let ground = Mesh {
        positions: vec![Vec3::new(-g, 0.0, g), Vec3::new(g, 0.0, g), Vec3::new(g, 0.0, -g), Vec3::new(-g, 0.0, -g)],
        normals: vec![Vec3::Y; 4],
        tangents: vec![Vec4::ZERO; 4],
        uv0: vec![Vec2::ZERO; 4],
        uv1: vec![],
        colors: vec![],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        material_ids: vec![1, 1],
    };
    s.add_world_mesh(ground);
    (s, half)
}

fn mb(b: usize) -> f64 {
    b as f64 / 1e6
}

/// Runs the benchmark (see the module docs for the parameters).
pub(super) fn bench_instances(
    instances: usize,
    triangles: usize,
    resolution: &str,
    spp: u32,
    repeats: usize,
    save: Option<&std::path::Path>,
) -> Result<(), Error> {
    let (w, h) = parse_wxh(resolution)?;
    let mesh = bumpy_sphere(triangles);
    let mesh_tris = mesh.triangle_count();
    // One copy of the mesh alone, for reference.
    let single = RenderScene::new(Scene { materials: vec![Material::default()], ..Scene::world(mesh.clone()) })?;
    let one = single.memory();
    let one_copy = one.mesh_bytes + one.world_bvh_bytes;

    let (scene, half) = scatter_scene(mesh, instances);
    let t0 = Instant::now();
    let rs = RenderScene::new(scene)?;
    let build = t0.elapsed().as_secs_f64();
    let m = rs.memory();
    println!(
        "## {instances} instances of a {mesh_tris}-triangle mesh ({} triangles seen by rays)",
        rs.triangle_count()
    );
    println!();
    println!("| item | MB |");
    println!("|---|---|");
    println!("| mesh data (each mesh once; includes the 2-triangle ground) | {:.3} |", mb(m.mesh_bytes));
    println!(
        "| instance records ({} × {} B) | {:.3} |",
        rs.scene().instances.len(),
        m.instance_bytes / rs.scene().instances.len().max(1),
        mb(m.instance_bytes)
    );
    println!("| mesh BVHs (BLAS, each mesh once) | {:.3} |", mb(m.blas_bytes));
    println!("| world BVH (meshes placed once: the ground) | {:.3} |", mb(m.world_bvh_bytes));
    println!(
        "| world-space positions and normals (meshes placed once by a transform) | {:.3} |",
        mb(m.world_attribute_bytes)
    );
    println!("| top level (TLAS nodes, leaves, per-instance transforms) | {:.3} |", mb(m.tlas_bytes));
    println!("| **total** | **{:.3}** |", mb(m.total()));
    println!("| one copy of the mesh (data + BVH) | {:.3} |", mb(one_copy));
    println!("| flattened scene (estimate: {instances} copies of data + BVH) | {:.1} |", mb(one_copy * instances));
    println!();
    let records = m.instance_bytes + m.tlas_bytes;
    println!(
        "total / one copy = {:.2} (one copy + {:.3} MB of instance records and top level = {:.0} B per instance); flattened / instanced = {:.0}×; build {:.2} s",
        m.total() as f64 / one_copy as f64,
        mb(records),
        records as f64 / instances.max(1) as f64,
        (one_copy * instances) as f64 / m.total() as f64,
        build
    );
    println!();

    // Render the scatter from above one corner.
    let eye = Vec3::new(-half * 0.9, 6.0, half * 0.9);
    let look = Vec3::new(-half * 0.3, 0.0, half * 0.3);
    let back = (eye - look).normalize();
    let right = Vec3::Y.cross(back).normalize();
    let up = back.cross(right);
    let to_world = glam::DAffine3::from_cols(right.as_dvec3(), up.as_dvec3(), back.as_dvec3(), eye.as_dvec3());
    let aspect = w as f64 / h as f64;
    let sensor = Sensor { width_mm: 36.0, height_mm: 36.0 / aspect, ..Sensor::default() };
    let rig = CameraRig { camera: Camera::Pinhole(PinholeCamera::new(sensor, 24.0)?), to_world };
    let settings = RenderSettings { width: w, height: h, spp, ..RenderSettings::default() };
    let r = render(&rs, &rig, &settings, &|_| true)?;
    let covered = r.image.rgba.iter().filter(|p| p[3] > 0.5).count() as f64 / r.image.rgba.len() as f64;
    println!(
        "render {w}x{h}, {spp} spp, {} threads: {:.2} s, {:.2} M camera rays/s, {:.0} % of pixels on geometry",
        rayon::current_num_threads(),
        r.seconds,
        r.camera_rays as f64 / r.seconds / 1e6,
        covered * 100.0
    );
    if let Some(path) = save {
        write_png(path, &r.image, 0.0, ToneMap::default())?;
        println!("wrote {}", path.display());
    }
    println!();

    // The demo: as built (its one mesh baked into the world BVH), flattened, and with its mesh
    // forced through the top level (a second, far-away instance makes it instanced).
    let (demo_scene, shot) = demo::demo_scene();
    let cam = demo_scene.cameras[0].clone();
    let to_world = glam::DAffine3::from_cols_array(&cam.to_world.to_cols_array().map(|v| v as f64));
    // The demo's shot is framed for a 50 mm lens.
    let _ = shot;
    let rig = CameraRig { camera: Camera::Pinhole(PinholeCamera::new(sensor, 50.0)?), to_world };
    let mut flat = demo_scene.clone();
    flat.flatten();
    let mut forced = demo_scene.clone();
    forced.add_instance(0, Affine3A::from_translation(Vec3::new(0.0, -1.0e4, 0.0)));
    let configs = [
        ("flattened", flat),
        ("instanced (as built: baked)", demo_scene),
        ("instanced, forced through the TLAS", forced),
    ];
    println!("## Built-in demo, {w}x{h}, {spp} spp, pinhole, fastest of {repeats}");
    println!();
    println!("| scene | seconds | ratio to flattened |");
    println!("|---|---|---|");
    let mut base = 0.0;
    for (name, s) in configs {
        let rs = RenderScene::new(s)?;
        let mut best = f64::INFINITY;
        for _ in 0..repeats.max(1) {
            best = best.min(render(&rs, &rig, &settings, &|_| true)?.seconds);
        }
        if base == 0.0 {
            base = best;
        }
        println!("| {name} | {best:.3} | {:.3} |", best / base);
    }
    Ok(())
}
