//! The integrator: ray casting against the scene ([`RenderScene`]: obvhs CWBVH, watertight
//! triangles, alpha cut-outs, robust ray offsets), the glTF metallic-roughness BSDF
//! ([`bsdf`]), light sampling ([`lights`]: punctual lights, emissive triangles, environment,
//! light-tree selection) and a unidirectional path tracer with next-event estimation
//! and MIS ([`PathTracer`]).

pub mod accel;
pub mod bsdf;
mod light_sampling;
pub mod lights;
mod packet;
pub mod path;
mod traverse;

pub use accel::{offset_ray_origin, BvhQuality, RenderScene, SurfaceHit};
pub use bsdf::{Bsdf, BsdfSample, Coat, SurfaceBsdf};
pub use light_sampling::spot_attenuation;
pub use lights::{LightSample, LightSelection};
pub use packet::PACKET;
pub use path::{angle_factor, scattering_material, LightStrategy, PathSample, PathTracer};

use glam::Vec3;
use std::time::Instant;

/// Closest-hit throughput on one thread (rays per second) for camera rays: a pinhole camera
/// outside the scene (bounds centre + 1.6 bounding radii along (0.35, 0.8, 0.6), looking down at
/// the centre with a 50° field of view) shoots one jittered ray
/// per pixel of a square image of `rays` pixels, in scanline order, through
/// [`RenderScene::intersect`] (full hit records). Rays are generated before timing.
pub fn primary_ray_throughput(scene: &RenderScene, rays: usize) -> f64 {
    primary_ray_throughput_in(scene, rays, false)
}

/// [`primary_ray_throughput`] with the same rays traced [`PACKET`] at a time (consecutive pixels
/// of a row) through [`RenderScene::intersect_packet`].
pub fn primary_ray_throughput_packets(scene: &RenderScene, rays: usize) -> f64 {
    primary_ray_throughput_in(scene, rays, true)
}

fn primary_ray_throughput_in(scene: &RenderScene, rays: usize, packets: bool) -> f64 {
    let (bmin, bmax) = scene.bounds();
    let center = 0.5 * (bmin + bmax);
    let radius = (0.5 * (bmax - bmin).length()).max(1e-3);
    let back = Vec3::new(0.35, 0.8, 0.6).normalize();
    let eye = center + back * (1.6 * radius);
    let right = Vec3::Y.cross(back).normalize();
    let up = back.cross(right);
    let half = (25.0f32).to_radians().tan();
    let side = (rays.max(1) as f64).sqrt().ceil() as usize;
    let mut state = 0x1234_5678u32;
    let mut next = || {
        state = crate::sampler::hash_u32(state.wrapping_add(0x9e37_79b9));
        (state >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    };
    let mut dirs: Vec<Vec3> = Vec::with_capacity(side * side);
    for y in 0..side {
        for x in 0..side {
            let sx = ((x as f32 + next()) / side as f32 * 2.0 - 1.0) * half;
            let sy = (1.0 - (y as f32 + next()) / side as f32 * 2.0) * half;
            dirs.push((right * sx + up * sy - back).normalize());
        }
    }
    let start = Instant::now();
    let mut hits = 0usize;
    if packets {
        let mut batch = [(eye, Vec3::Z, f32::INFINITY); PACKET];
        for chunk in dirs.chunks(PACKET) {
            for (b, &d) in batch.iter_mut().zip(chunk) {
                b.1 = d;
            }
            for h in scene.intersect_packet(&batch[..chunk.len()]).iter().flatten() {
                hits += (h.t > 0.0) as usize;
            }
        }
    } else {
        for &d in &dirs {
            if let Some(h) = scene.intersect(eye, d, f32::INFINITY) {
                hits += (h.t > 0.0) as usize;
            }
        }
    }
    let secs = start.elapsed().as_secs_f64();
    std::hint::black_box(hits);
    dirs.len() as f64 / secs.max(1e-9)
}
