//! Depth-of-field preview methods against Monte Carlo.

use glam::{DAffine3, DVec2, DVec3};
use petzval_renderer::dof::{self, LayerFrame, LayerSettings, Layers};
use petzval_renderer::integrator::RenderScene;
use petzval_renderer::render::{render, CameraRig, RenderSettings};
use petzval_renderer::scene::demo;
use petzval_renderer::{Camera, PinholeCamera, Sensor};

fn demo_pinhole() -> (RenderScene, CameraRig) {
    let (scene, _shot) = demo::demo_scene();
    let sc = scene.cameras[0].clone();
    let to_world = DAffine3::from_cols_array(&sc.to_world.to_cols_array().map(|v| v as f64));
    let camera = Camera::Pinhole(PinholeCamera::new(Sensor::default(), 50.0).unwrap());
    (RenderScene::new(scene).unwrap(), CameraRig { camera, to_world })
}

#[test]
fn debug_layers_pinhole() {
    let (rs, rig) = demo_pinhole();
    let st = RenderSettings { width: 60, height: 40, spp: 64, ..RenderSettings::default() };
    let mc = render(&rs, &rig, &st, &|_| true).unwrap().image;
    let frame = LayerFrame::covering(&rig.camera, 60, 40, 0.0, 1).unwrap();
    eprintln!("{frame:?}");
    let layers =
        Layers::trace(&rs, rig.to_world, frame, &LayerSettings { spp: 64, ..LayerSettings::default() }, 0.0, &|| true)
            .unwrap()
            .unwrap();
    for (x, y) in [(5usize, 30usize), (10, 35), (30, 20), (55, 30), (50, 15)] {
        let i = y * 60 + x;
        let ray = rig
            .camera
            .generate_ray(DVec2::new((x as f64 + 0.5) / 60.0, (y as f64 + 0.5) / 40.0), DVec2::splat(0.5), 550.0)
            .unwrap();
        let (xy, _) = frame.project(ray.direction * 10.0).unwrap();
        let li = layers.index(0, x, y);
        eprintln!(
            "px ({x},{y}) mc {:?} depth {} | layer texel {xy:?} depth {:?} rad {:?} | l1 {:?}",
            mc.rgba[i],
            mc.depth[i],
            layers.depth_m[li],
            layers.radiance[li],
            layers.depth_m[layers.index(1, x, y)]
        );
    }
    let _ = (dof::Method::Mc, DVec3::ZERO);
    let tracer = petzval_renderer::PathTracer::default();
    let (x, y) = (10usize, 35usize);
    let dir = frame.direction(DVec2::new(x as f64 + 0.5, y as f64 + 0.5));
    let d = rig.to_world.transform_vector3(dir).normalize().as_vec3();
    let o = rig.to_world.transform_point3(DVec3::ZERO).as_vec3();
    let t = rs.intersect(o, d, f32::INFINITY).unwrap().t;
    for clip in [(0.0f32, f32::INFINITY), (t * (1.0 - 1e-4), f32::INFINITY), (t * 0.99, f32::INFINITY)] {
        let mut sum = glam::Vec3::ZERO;
        for s in 0..256 {
            let mut sm = petzval_renderer::sampler::PixelSampler::new(x as u32, y as u32, s, 7);
            sum += tracer.trace_clipped(&rs, o, d, clip, &mut sm).radiance;
        }
        eprintln!("clip {clip:?} t {t}: {:?}", sum / 256.0);
    }
}
