//! The shot: the steps that need both a camera spec and the scene, so they sit above the
//! camera layer (which knows no scene) and the integrator — the depth probe that sizes the
//! depth of field `--lens-model auto` must honour, autofocus on the image centre, and
//! [`build_for_scene`], the camera builder with the scene's depth range.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | depth probe | 32 × 24 rays through a pinhole of the lens's focal length | — | — |
//! | autofocus | the distance along the view axis to the surface at the image centre | m | infinity when nothing is hit |

use crate::camera::{BuiltCamera, Camera, CameraSpec, PinholeCamera, Sensor, ShotContext, SpecLens};
use crate::error::Result;
use crate::integrator::RenderScene;
use glam::{DAffine3, DVec2, DVec3};

/// Nearest and farthest distance (m) at which the scene is seen through a pinhole of focal
/// length `focal_length_mm` on `sensor` (a 32 × 24 grid of rays from the camera origin); the far
/// end is infinite when some ray escapes. `None` when no ray hits anything. Used to size the
/// depth of field that `--lens-model auto` must honour.
pub fn scene_depth_range_m(
    scene: &RenderScene,
    to_world: &DAffine3,
    sensor: &Sensor,
    focal_length_mm: f64,
) -> Option<(f64, f64)> {
    let pinhole = PinholeCamera::new(*sensor, focal_length_mm).ok()?;
    let camera = Camera::Pinhole(pinhole);
    let (mut near, mut far, mut any) = (f64::INFINITY, 0.0f64, false);
    let (nx, ny) = (32, 24);
    for j in 0..ny {
        for i in 0..nx {
            let film = DVec2::new((i as f64 + 0.5) / nx as f64, (j as f64 + 0.5) / ny as f64);
            let Some(ray) = camera.generate_ray(film, DVec2::splat(0.5), crate::optics::glass::WAVELENGTH_D_NM) else {
                continue;
            };
            let o = to_world.transform_point3(ray.origin).as_vec3();
            let d = to_world.transform_vector3(ray.direction).normalize().as_vec3();
            match scene.intersect_seen(o, d, f32::INFINITY) {
                Some(hit) => {
                    // distance along the view axis (the depth a lens focuses by)
                    let z = hit.t as f64 * (-ray.direction.z);
                    near = near.min(z);
                    far = far.max(z);
                    any = true;
                }
                None => far = f64::INFINITY,
            }
        }
    }
    any.then_some((near, far))
}

/// Autofocus: the distance (m) to the surface the image centre sees (the camera's −z axis from
/// its origin); `None` (infinity) when nothing is there.
pub fn autofocus_m(scene: &RenderScene, to_world: &DAffine3) -> Option<f64> {
    autofocus_clipped_m(scene, to_world, (0.0, f64::INFINITY))
}

/// [`autofocus_m`] seeing only what lies between the clipping planes `clip_m` (start, end,
/// metres along the view axis), as the render does.
pub fn autofocus_clipped_m(scene: &RenderScene, to_world: &DAffine3, clip_m: (f64, f64)) -> Option<f64> {
    let o = to_world.translation.as_vec3();
    let d = to_world.transform_vector3(DVec3::NEG_Z).normalize().as_vec3();
    let near = clip_m.0.max(0.0);
    let t_max = if clip_m.1.is_finite() { (clip_m.1 - near).max(0.0) as f32 } else { f32::INFINITY };
    if !(t_max > 0.0) {
        return None;
    }
    scene.intersect_seen(o + d * near as f32, d, t_max).map(|h| h.t as f64 + near)
}

/// Builds the camera of `spec` for a shot of `scene` seen from `to_world` at `width` ×
/// `height` and `spp`: the depth range `auto` must honour is probed in the scene through a
/// pinhole of the lens's focal length. The lens is loaded once.
pub fn build_for_scene(
    spec: &CameraSpec,
    scene: &RenderScene,
    to_world: &DAffine3,
    width: u32,
    height: u32,
    spp: u32,
    spectral: bool,
) -> Result<BuiltCamera> {
    spec.validate()?;
    let lens = spec.load_lens()?;
    let probe_focal_mm = match &lens {
        SpecLens::Ideal => spec.focal_length_mm,
        SpecLens::Real(l) => l.paraxial().efl_mm,
    };
    let depth_range_m = scene_depth_range_m(scene, to_world, &spec.sensor, probe_focal_mm);
    spec.build_loaded(lens, &ShotContext { width, height, spp, depth_range_m, spectral })
}
