//! Bokeh light paths: light traced from emissive triangles through the lens onto the film, and
//! combined with camera paths by multiple importance sampling, so that small bright emitters
//! seen out of focus (the demo's lamps, the lights of a night street) converge as fast as the
//! rest of the image. Camera paths find such an emitter only when a ray through the wide
//! aperture happens to hit it; a light path starts on the emitter and always lands somewhere in
//! its bokeh disc.
//!
//! One light path, scene → film:
//! 1. a point p on a disc about the camera origin (the entrance pupil, camera plane z = 0;
//!    radius 1.25 × the paraxial entrance pupil's, plus 0.5 mm),
//! 2. an emitter point y chosen from p by the light tree, as next-event estimation chooses one
//!    (selection × solid-angle pdf at p),
//! 3. the object-space ray y → p traced through the lens ([`Camera::connect`]) onto the
//!    sensor, the segment from y to where the ray enters the lens tested for occlusion,
//! 4. a splat into every pixel whose filter covers the film point, weighted by that pixel's
//!    filter density.
//!
//! Both strategies' densities are expressed in the ray (étendue) measure, which the lens
//! conserves: the camera's is pdf(film point) · pdf(rear-plane point) / (cosθ cosθ' / d²), the
//! light path's pdf(p on the disc) · pdf_ω(y from p) / cosθ_p. The balance heuristic weights
//! each strategy by its density times its sample count (K light paths per sample per pixel of
//! the whole image against one camera sample per pixel). Only emission that the camera ray hits
//! directly is shared between the strategies; a path the disc cannot produce (p outside it) is
//! left wholly to the camera, so the combination is unbiased whatever the disc's radius.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `bokeh_paths` | f32: light paths per pixel per sample (0 = off); exact and LRTF lens models | — | 0 |

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::film::{FilterSampler, PixelFilter};
use crate::integrator::{RenderScene, SurfaceHit};
use crate::optics::aperture::concentric_disk;
use crate::sampler::PixelSampler;
use crate::spectral;
use glam::{DAffine3, DVec2, DVec3, Vec2, Vec3};
use rayon::prelude::*;

/// The `auto` choice of light paths per pixel per sample: 1 where `camera` can trace light onto
/// its film (a real lens, exact or LRTF model) and `scene` has emissive triangles, else 0.
pub fn auto_paths(scene: &RenderScene, camera: &Camera) -> f32 {
    if camera.can_connect() && scene.has_emissive_triangles() {
        1.0
    } else {
        0.0
    }
}

/// Light paths traced per parallel task (a fixed split, so the image does not depend on the
/// thread count).
const CHUNK: u64 = 2048;
/// Tasks whose splats are gathered before they are added to the film, in task order.
const BATCH: u64 = 64;
/// The sampler row of light paths (camera samples use rows below the image height).
const LIGHT_ROW: u32 = 0xB0CE_0000;

/// What the light tracer takes from the render's settings.
#[derive(Debug, Clone, Copy)]
pub(crate) struct LightPathSettings {
    /// Light paths per pixel per sample (0 = none).
    pub paths: f32,
    /// The full frame (pixels).
    pub width: u32,
    /// The full frame (pixels).
    pub height: u32,
    /// The window rendered `[x0, y0, x1, y1)`.
    pub crop: [u32; 4],
    /// The pixel filter.
    pub filter: PixelFilter,
    /// One wavelength per path.
    pub spectral: bool,
    /// Seed.
    pub seed: u32,
    /// Clipping planes along the view axis (m).
    pub clip_m: (f64, f64),
}

/// The light tracer of one render (immutable once built).
pub(crate) struct BokehTracer<'a> {
    scene: &'a RenderScene,
    camera: &'a Camera,
    to_world: DAffine3,
    to_camera: DAffine3,
    /// The camera's viewing direction and origin (world).
    forward: Vec3,
    /// Radius of the disc light paths aim at (m) and its area density (mm⁻²).
    radius_m: f64,
    disc_pdf_mm2: f64,
    /// Light paths per sample per pixel over the whole window (K).
    paths_per_spp: u64,
    /// Area of one pixel on the sensor (mm²).
    px_area_mm2: f64,
    width: u32,
    height: u32,
    crop: [u32; 4],
    filter: FilterSampler,
    spectral: bool,
    primary_nm: f64,
    seed: u32,
    clip_m: (f64, f64),
}

impl<'a> BokehTracer<'a> {
    /// The tracer for `settings.bokeh_paths` > 0 and a scene with emissive triangles; None when
    /// there is nothing to trace. An error when light paths are asked for a camera model that
    /// cannot trace light onto its film.
    pub(crate) fn new(
        scene: &'a RenderScene,
        camera: &'a Camera,
        to_world: DAffine3,
        settings: &LightPathSettings,
    ) -> Result<Option<Self>> {
        if settings.paths <= 0.0 {
            return Ok(None);
        }
        let Some(ep_radius_m) = camera.entrance_pupil_radius_m().filter(|_| camera.can_connect()) else {
            return Err(Error::settings(
                "bokeh_paths",
                format!(
                    "light paths through the lens need the exact or LRTF lens model (a real lens); this camera is {}",
                    camera.model()
                ),
            ));
        };
        if !scene.has_emissive_triangles() {
            return Ok(None);
        }
        let (w, h) = (settings.width, settings.height);
        let crop = settings.crop;
        let window_px = (crop[2] - crop[0]) as f64 * (crop[3] - crop[1]) as f64;
        let radius_m = 1.25 * ep_radius_m + 0.5e-3;
        let radius_mm = radius_m * 1e3;
        let sensor = camera.sensor();
        Ok(Some(BokehTracer {
            scene,
            camera,
            to_world,
            to_camera: to_world.inverse(),
            forward: to_world.transform_vector3(DVec3::NEG_Z).normalize().as_vec3(),
            radius_m,
            disc_pdf_mm2: 1.0 / (std::f64::consts::PI * radius_mm * radius_mm),
            paths_per_spp: (settings.paths as f64 * window_px).ceil().max(1.0) as u64,
            px_area_mm2: sensor.width_mm / w as f64 * (sensor.height_mm / h as f64),
            width: w,
            height: h,
            crop,
            filter: FilterSampler::new(settings.filter),
            spectral: settings.spectral,
            primary_nm: camera.real_lens().map_or(crate::optics::glass::WAVELENGTH_D_NM, |l| l.primary_wavelength_nm()),
            seed: settings.seed ^ 0x5bd1_e995,
            clip_m: settings.clip_m,
        }))
    }

    /// The camera strategy's density (mm⁻², ray measure) for the camera sample at image
    /// position `film` with lens sample `lens_u`, whose filter offset was `off` (px).
    pub(crate) fn camera_density(&self, film: DVec2, lens_u: DVec2, off: Vec2) -> f64 {
        let f = self.filter.pdf(off) as f64 / self.px_area_mm2;
        self.camera.sample_density(film, lens_u).map_or(0.0, |d| f * d)
    }

    /// The camera path's weight for the emission it hits directly at `hit`, along the world ray
    /// `origin` + t·`dir` (unit), with its own density `camera_density`.
    pub(crate) fn camera_weight(&self, camera_density: f64, origin: Vec3, dir: Vec3, hit: &SurfaceHit) -> f32 {
        let light = self.light_density(origin, dir, hit);
        if camera_density + light > 0.0 {
            (camera_density / (camera_density + light)) as f32
        } else {
            1.0
        }
    }

    /// K times the light strategy's density (mm⁻² sr⁻¹, ray measure) for the ray `origin` +
    /// t·`dir` ending on the emitter at `hit` (0 when its line misses the disc).
    fn light_density(&self, origin: Vec3, dir: Vec3, hit: &SurfaceHit) -> f64 {
        // 1. Where the ray's line crosses the camera plane (it may be behind the ray's origin,
        //    inside the lens).
        let centre = self.to_world.translation.as_vec3();
        let cos_p = dir.dot(self.forward);
        if cos_p.abs() < 1e-6 {
            return 0.0;
        }
        let p = origin + dir * ((centre - origin).dot(self.forward) / cos_p);
        if (p - centre).length() as f64 > self.radius_m {
            return 0.0;
        }
        // 2. The light tree's choice of this emitter point from p.
        let dist = (hit.position - p).length();
        let pdf_w = self.scene.triangle_light_pdf_from(p, self.forward, hit, dir, dist) as f64;
        self.paths_per_spp as f64 * self.disc_pdf_mm2 * pdf_w / cos_p.abs() as f64
    }

    /// Traces the light paths of samples `spp` and adds their splats to `splat` (the window's
    /// pixels, row-major).
    pub(crate) fn trace_pass(&self, spp: std::ops::Range<u32>, splat: &mut [Vec3]) {
        let k = self.paths_per_spp;
        for s in spp {
            let mut start = 0;
            while start < k {
                let end = (start + CHUNK * BATCH).min(k);
                let chunks: Vec<u64> = (start..end).step_by(CHUNK as usize).collect();
                let parts: Vec<Vec<(u32, Vec3)>> = chunks
                    .par_iter()
                    .map(|&c0| {
                        let mut out = Vec::new();
                        for i in c0..(c0 + CHUNK).min(end) {
                            self.trace_one(i, s, &mut out);
                        }
                        out
                    })
                    .collect();
                for (px, v) in parts.into_iter().flatten() {
                    splat[px as usize] += v;
                }
                start = end;
            }
        }
    }

    /// Light path `i` of sample `s`: its splats (window pixel index, radiance) into `out`.
    fn trace_one(&self, i: u64, s: u32, out: &mut Vec<(u32, Vec3)>) {
        // 1. Samples: disc point, emitter (pick, point), wavelength.
        let mut sampler = PixelSampler::new(i as u32, LIGHT_ROW ^ (i >> 32) as u32, s, self.seed);
        let u_disc = sampler.next_2d();
        let u_pick = sampler.next_1d();
        let u_light = sampler.next_2d();
        let u_lambda = sampler.next_1d();
        let disc = concentric_disk(u_disc.as_dvec2()) * self.radius_m;
        let p_cam = DVec3::new(disc.x, disc.y, 0.0);
        let p_world = self.to_world.transform_point3(p_cam).as_vec3();
        // 2. An emitter point seen from p (punctual lights and the sky are not seen directly).
        let Some(ls) = self.scene.sample_light_at(p_world, self.forward, u_pick, u_light) else { return };
        let Some(y) = ls.target.filter(|_| !ls.delta) else { return };
        let (lambda, lambda_weight) =
            if self.spectral { spectral::sample_wavelength(u_lambda) } else { (self.primary_nm as f32, Vec3::ONE) };
        // 3. Through the lens onto the film; inside the clipping planes; unoccluded.
        let y_cam = self.to_camera.transform_point3(y.as_dvec3());
        let Some(conn) = self.camera.connect(y_cam, p_cam, lambda as f64) else { return };
        let axial = conn.entry_m.z - y_cam.z;
        if !(axial >= self.clip_m.0 && axial <= self.clip_m.1) {
            return;
        }
        let entry = self.to_world.transform_point3(conn.entry_m).as_vec3();
        if self.scene.occluded(y, entry - y, 1.0 - 1e-4) {
            return;
        }
        // 4. Density and value before the filter.
        let cos_p = (p_cam - y_cam).normalize().z.abs();
        if !(cos_p > 1e-9) {
            return;
        }
        let light_density = self.paths_per_spp as f64 * self.disc_pdf_mm2 * ls.pdf as f64 / cos_p;
        let base = ls.radiance * lambda_weight * conn.importance as f32;
        // 5. Splat into the window's pixels under the filter.
        let (fx, fy) = (conn.film.x * self.width as f64, conn.film.y * self.height as f64);
        let r = self.filter.radius_px() as f64;
        let [x0, y0, x1, y1] = self.crop;
        let ix0 = ((fx - r - 0.5).ceil().max(x0 as f64)) as i64;
        let ix1 = ((fx + r - 0.5).floor().min(x1 as f64 - 1.0)) as i64;
        let iy0 = ((fy - r - 0.5).ceil().max(y0 as f64)) as i64;
        let iy1 = ((fy + r - 0.5).floor().min(y1 as f64 - 1.0)) as i64;
        let cw = (x1 - x0) as i64;
        for iy in iy0..=iy1 {
            for ix in ix0..=ix1 {
                let off = Vec2::new((fx - (ix as f64 + 0.5)) as f32, (fy - (iy as f64 + 0.5)) as f32);
                let f = self.filter.pdf(off) as f64 / self.px_area_mm2;
                if !(f > 0.0) {
                    continue;
                }
                let v = base * (f / (light_density + f * conn.camera_density)) as f32;
                if v.is_finite() {
                    out.push((((iy - y0 as i64) * cw + (ix - x0 as i64)) as u32, v));
                }
            }
        }
    }
}
