//! Multi-view accumulation: the image is the mean of N = `spp` pinhole views, each through one
//! point of the pupil, as a rasteriser would make depth of field by rendering the scene N times
//! from points of the lens and averaging.
//!
//! * **Views.** View n shares one lens sample `u_n` for every pixel ([`view_lens_sample`]: an
//!   Owen-scrambled Sobol sequence over the aperture indexed by the sample index, the same for
//!   every pixel, so any prefix of views is stratified and the image does not depend on the
//!   thread count). The per-pixel loop of [`crate::render`] is reused: the pixel's ray of view n
//!   is `generate_ray(film, u_n)`. For the thin lens (tilted and shifted sensors included) that
//!   is exactly the pinhole ray from the lens point of `u_n` through the pixel's point of sharp
//!   focus, and [`view_transform`] is the view's 4 × 4 view-projection matrix.
//! * **Shading, as cheap as a rasterised view.** Visibility along the view ray is exact (the
//!   primary ray is traced against the scene); the radiance at the hit is looked up in the
//!   depth-peeled [`Layers`] seen from the perspective centre: the hit is projected into the
//!   layer frame and, at the four texels around it (bilinear weights), the layer whose surface
//!   holds the hit gives the radiance: the hit lies within [`PLANE_TOLERANCE`] of the texel's
//!   tangent plane ([`Layers::planes`]; a plain depth match fails on planes seen at grazing
//!   angles, whose depth changes by tens of per cent per texel) and within [`DEPTH_TOLERANCE`]
//!   of its depth. A layer's radiance is that of its surface alone (its coverage of the texel
//!   does not enter: visibility is the view's own). The layers hold
//!   the radiance leaving the surface towards the *pupil centre*: it stands in for the radiance
//!   towards the view's pupil point (exact for diffuse surfaces; glossy highlights do not move
//!   across the pupil, an error of the order of the pupil's angle at the surface). When no layer
//!   matches (a surface disoccluded beyond the K layers, or outside the layer frame) the sample
//!   is path traced ([`PathTracer::trace_clipped`]) and counted in
//!   [`MultiviewStats::fallbacks`]. Misses show the environment.
//! * **Real lenses** (exact, LRTF, thick): views go through the real lens's entrance pupil with
//!   the same machinery: a fixed lens sample per view, and `generate_ray` does the distortion and
//!   the exact pupil. The thick lens gives true pinhole views (a fixed point on the principal
//!   planes). For the traced lens the pinhole view is an approximation, measured by
//!   [`pinhole_view_error`] (the rays `generate_ray` gives for a fixed sample) and
//!   [`traced_pinhole_view_error`] (the lens's own part: rays through one fixed entrance-pupil
//!   point). It breaks where (1) with aberrations the rays of one pupil point towards a pixel's
//!   focus point do not meet in one point (spherical aberration, coma, field curvature), (2) at
//!   wide angles the pupil moves and tilts with the field angle (pupil aberration), and (3) the
//!   exact camera samples the exit pupil's bounds for each film radius, rotated to the film
//!   point's azimuth, so a fixed sample is not a fixed entrance-pupil point across the frame.
//!   Measured over a 9 × 9 film grid at 960 px across 36 mm (tests/dof.rs): the lens's own part
//!   at 70 % of the pupil radius is up to 1.4 px for a double Gauss at f/2.8, 2.7 px for a
//!   Petzval at f/4, 1.6 px for a 22 mm wide angle at f/4; the sampler's rotation makes the
//!   fixed-sample rays up to 9 px from one pinhole view (the pupil point moves by up to 13 mm).
//!   The image stays a correct N-sample estimate per pixel (multi-view through the traced double
//!   Gauss agrees with Monte Carlo about as closely as on the thin lens); only the "one view = one
//!   pinhole" picture, which a rasteriser would need, breaks.
//!
//! The layers' texels are half a pixel, their radiance the mean over the texel, looked up
//! bilinearly: on the tests' tilted checkered ground the per-pixel relative RMSE against a
//! 1024-spp MC reference is 0.030 at 64 views (64-spp MC: 0.048). Their noise is seen coherently by every view (an in-focus
//! surface is looked up at the same texels by all views), so the layers' `spp` bounds the noise
//! of sharp regions. Cost: the layers (K × texels × their spp paths) dominate; each view costs
//! one primary ray per pixel, so the method pays off when the views outnumber the layers' spp.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `spp` (of [`RenderSettings`]) | u32: views N (lens samples shared by every pixel) | — | 64 |
//! | `seed` (of [`RenderSettings`]) | u32: scrambles the view sequence and the fallback paths | — | 0 |
//! | `layers` (of [`PreviewSettings`]) | [`crate::dof::LayerSettings`] | — | 4 layers, 4 spp per texel, 2 texels per pixel, margin 0.15 |
//! | [`PLANE_TOLERANCE`] | f64: distance of a hit from a layer texel's tangent plane, relative to its depth | — | 0.005 |
//! | [`DEPTH_TOLERANCE`] | f64: largest relative depth difference of a hit and a matching texel | — | 0.5 |

use super::layers::Layers;
use super::{make_layers, PreviewSettings};
use crate::camera::{Camera, CameraRay, ThinCamera};
use crate::error::{Error, Result};
use crate::integrator::path::base_color;
use crate::integrator::{PathSample, PathTracer, RenderScene};
use crate::render::{render_samples, CameraRig, PassObserver, Progress, RenderResult, RenderSettings, SampleShader};
use crate::sampler::PixelSampler;
use glam::{DAffine3, DMat4, DVec2, DVec3, DVec4, Vec3};
use std::sync::atomic::{AtomicU64, Ordering};

/// Largest distance of a hit from a layer texel's tangent plane, relative to the texel's depth,
/// for the texel to hold the hit's surface (a sphere of radius R bends away from its tangent
/// plane by s²/2R over a footprint s: far below this at texel footprints).
pub const PLANE_TOLERANCE: f64 = 0.005;

/// Largest relative difference of a hit's planar depth and a layer texel's: a sanity bound on
/// the tangent-plane match (a plane seen at a grazing angle α changes depth by δθ/α per texel
/// of angle δθ, so the bound is loose).
pub const DEPTH_TOLERANCE: f64 = 0.5;

/// The depth-only tolerance of texels whose surface could not be found again (the layers'
/// [`crate::dof::ibrt::SURFACE_JUMP`]).
const DEPTH_ONLY_TOLERANCE: f64 = 0.03;

/// Salt of the view sequence's scramble (so it differs from every pixel's own stream).
const VIEW_SALT: u32 = 0x5f1e_77a3;

/// The lens sample in [0, 1)² of view `s` under render seed `seed`: the same for every pixel
/// (an Owen-scrambled Sobol (0, 2)-sequence, stratified over any power-of-two prefix).
pub fn view_lens_sample(s: u32, seed: u32) -> DVec2 {
    let mut sampler = PixelSampler::new(0, 0, s, seed ^ VIEW_SALT);
    sampler.next_2d().as_dvec2()
}

/// What the shading did, over every camera sample of a multi-view render.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MultiviewStats {
    /// Camera samples shaded (rays the lens let through).
    pub samples: u64,
    /// Samples whose radiance came from the layers.
    pub layer_hits: u64,
    /// Samples that hit a surface no layer holds, path traced instead.
    pub fallbacks: u64,
    /// Samples that saw the environment.
    pub misses: u64,
}

impl MultiviewStats {
    /// Fallbacks as a fraction of the samples that hit a surface (0 when none did).
    pub fn fallback_fraction(&self) -> f64 {
        let hits = self.layer_hits + self.fallbacks;
        if hits == 0 {
            0.0
        } else {
            self.fallbacks as f64 / hits as f64
        }
    }
}

/// Renders `scene` through `rig` by multi-view accumulation (see the module docs), returning
/// the image (its `seconds` include making the layers) and the shading statistics.
pub fn render_multiview(
    scene: &RenderScene,
    rig: &CameraRig,
    settings: &RenderSettings,
    preview: &PreviewSettings,
    progress: Progress,
    on_pass: PassObserver,
) -> Result<(RenderResult, MultiviewStats)> {
    settings.validate()?;
    let start = std::time::Instant::now();
    let Some(layers) = make_layers(scene, rig, settings, preview, progress)? else {
        return Ok((super::cancelled(settings, start), MultiviewStats::default()));
    };
    let shader = MultiviewShader {
        layers: &layers,
        surfaces: &layers.planes,
        scene,
        tracer: PathTracer { max_depth: settings.max_depth, ..PathTracer::default() },
        to_camera: rig.to_world.inverse(),
        seed: settings.seed,
        counts: Default::default(),
    };
    // The views share their lens samples: no view may fall in the pupil's defensive disc.
    let rig = CameraRig { camera: rig.camera.for_shared_lens_samples(), to_world: rig.to_world };
    let mut result = render_samples(&rig, settings, progress, on_pass, &shader)?;
    result.seconds = start.elapsed().as_secs_f64();
    let [layer_hits, fallbacks, misses] = shader.counts.each_ref().map(|c| c.load(Ordering::Relaxed));
    let stats = MultiviewStats { samples: layer_hits + fallbacks + misses, layer_hits, fallbacks, misses };
    Ok((result, stats))
}

/// The multi-view shader: shared lens samples, exact visibility, radiance from the layers.
struct MultiviewShader<'a> {
    layers: &'a Layers,
    /// Per layer texel (the layers' index): its tangent plane n·x = d (camera space, unit n;
    /// NaN where the surface was not found again).
    surfaces: &'a [[f32; 4]],
    scene: &'a RenderScene,
    tracer: PathTracer,
    to_camera: DAffine3,
    seed: u32,
    /// Layer hits, fallbacks, misses.
    counts: [AtomicU64; 3],
}

impl MultiviewShader<'_> {
    /// The layers' radiance at camera-space point `p`: bilinear over the four texels around
    /// its projection, each taking the layer whose surface holds `p` (see the module docs);
    /// None when none does.
    fn lookup(&self, p: DVec3) -> Option<Vec3> {
        let frame = self.layers.frame;
        let (xy, z) = frame.project(p)?;
        let size = DVec2::new(frame.width as f64, frame.height as f64);
        if !(xy.x >= 0.0 && xy.y >= 0.0 && xy.x <= size.x && xy.y <= size.y) {
            return None;
        }
        let c = xy - DVec2::splat(0.5);
        let base = c.floor();
        let f = c - base;
        let (mut sum, mut weight) = (Vec3::ZERO, 0.0f32);
        for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            let w = (if dx == 0 { 1.0 - f.x } else { f.x }) * (if dy == 0 { 1.0 - f.y } else { f.y });
            let w = w as f32;
            if w <= 0.0 {
                continue;
            }
            let tx = (base.x as i64 + dx).clamp(0, frame.width as i64 - 1) as usize;
            let ty = (base.y as i64 + dy).clamp(0, frame.height as i64 - 1) as usize;
            // The layer whose surface holds the hit, nearest to its tangent plane.
            let mut best: Option<(usize, f64)> = None;
            for k in 0..self.layers.count {
                let i = self.layers.index(k, tx, ty);
                let zk = self.layers.depth_m[i] as f64;
                if !zk.is_finite() {
                    continue;
                }
                let depth_err = (zk / z - 1.0).abs();
                let [nx, ny, nz, offset] = self.surfaces[i].map(f64::from);
                let score = if !nx.is_finite() {
                    (depth_err <= DEPTH_ONLY_TOLERANCE).then_some(depth_err * PLANE_TOLERANCE)
                } else if depth_err <= DEPTH_TOLERANCE {
                    let d = ((DVec3::new(nx, ny, nz).dot(p) - offset) / zk).abs();
                    (d <= PLANE_TOLERANCE).then_some(d)
                } else {
                    None
                };
                if let Some(d) = score {
                    if best.is_none_or(|(_, b)| d < b) {
                        best = Some((i, d));
                    }
                }
            }
            if let Some((i, _)) = best {
                sum += self.layers.radiance[i] * w;
                weight += w;
            }
        }
        (weight > 0.0).then(|| sum / weight)
    }
}

impl SampleShader for MultiviewShader<'_> {
    fn lens_sample(&self, s: u32, _own: DVec2) -> DVec2 {
        view_lens_sample(s, self.seed)
    }

    fn shade(
        &self,
        _ray: &CameraRay,
        origin: Vec3,
        dir: Vec3,
        clip: (f32, f32),
        _film: &crate::bokeh::FilmSample,
        sampler: &mut PixelSampler,
    ) -> PathSample {
        let d = dir.normalize_or_zero();
        let (t_near, t_far) = (clip.0.max(0.0), clip.1);
        let start = origin + d * t_near;
        let found =
            if t_far > t_near && d != Vec3::ZERO { self.scene.intersect_seen(start, d, t_far - t_near) } else { None };
        let Some(hit) = found else {
            self.counts[2].fetch_add(1, Ordering::Relaxed);
            return PathSample::miss(crate::integrator::lights::camera_env_radiance(self.scene.scene(), d));
        };
        let p = self.to_camera.transform_point3(hit.position.as_dvec3());
        match self.lookup(p) {
            Some(radiance) => {
                self.counts[0].fetch_add(1, Ordering::Relaxed);
                let n = hit.shading_normal;
                PathSample {
                    radiance,
                    alpha: 1.0,
                    depth_m: hit.t + t_near,
                    normal: if n.dot(-d) >= 0.0 { n } else { -n },
                    albedo: base_color(self.scene, &hit),
                    dropped: false,
                }
            }
            None => {
                self.counts[1].fetch_add(1, Ordering::Relaxed);
                self.tracer.trace_clipped(self.scene, origin, dir, clip, sampler)
            }
        }
    }
}

// ------------------------------------------------------------------------------------------
// The rectifying view transform of a thin lens with a tilted / shifted sensor.

/// The lens point (mm, on the thin lens's plane z = 0) where `camera`'s rays of lens sample
/// `lens_u` leave: the point of view of that sample. (`generate_ray` returns None there when the
/// aperture's transmission is zero, e.g. outside an image mask.)
pub fn lens_point_mm(camera: &ThinCamera, lens_u: DVec2) -> DVec2 {
    camera.aperture().sample_unit(lens_u).0 * camera.aperture_radius_mm()
}

/// The view-projection matrix of the pinhole view of `camera` from lens point `lens_point_mm`
/// (mm, lens plane): the 4 × 4 projective matrix M_p that a rasteriser would use for this view.
///
/// For a camera-space point X (metres, homogeneous (X, 1)), M_p·(X, 1) = (u·w, v·w, 1, w):
/// * (u, v) is the image position (`generate_ray`'s `film`, [0, 1]² over the frame, (0, 0) at the
///   top left) whose ray through the lens point passes through X: X is projected from the lens
///   point p onto the plane of sharp focus (the Scheimpflug plane of the tilted sensor,
///   [`Camera::focus_plane`]; the plane at infinity when focused at infinity), and that point
///   maps to the sensor through the lens centre (a plane-to-plane homography). Both steps are
///   central projections, so their composition is one projective map. The view's frustum is the
///   general quadrilateral the sensor images onto the plane of focus, with apex p.
/// * w (metres) is the distance of X in front of the plane through p and the hinge line (where
///   the plane of focus meets the lens plane parallel to the sensor): the points of that plane
///   image at infinity. Untilted, it is the lens plane and w = −z, the planar depth.
/// * The third component after the division is ζ = 1/w (m⁻¹): inverse depth, decreasing along
///   every view ray, a reverse-Z depth with the far plane at infinity (a depth buffer with near
///   plane n stores n·ζ).
///
/// Homogeneous derivation (mm, lens frame; the sensor plane σ = (m, −m·c) with normal m through
/// the pivot c = (0, 0, F)): the thin lens maps film points P to object points Q = −P·f/(P.z − f),
/// the homography H = [−f·I, 0; ẑᵀ, −f], so the plane of focus is π = H⁻ᵀσ = (f·m, f·m_z − m·c,
/// −f·m·c) (f = the focused lens's focal length). The central projection from a point C onto a
/// plane Π is X ↦ (Π·C)·X − (Π·X)·C. Then M_p = K·G·proj(O → σ)·proj(p → π)·S with S metres → mm,
/// G the sensor frame (the sensor rotation's inverse about the pivot) and K the image
/// coordinates (size and shift), and M_p is scaled so that its last row is w.
///
/// Errors when the lens point is not finite or lies on the plane of focus (the view degenerates
/// to a point).
pub fn view_transform(camera: &ThinCamera, lens_point_mm: DVec2) -> Result<DMat4> {
    if !lens_point_mm.is_finite() {
        return Err(Error::settings("lens_point_mm", format!("{lens_point_mm} is not finite")));
    }
    let sensor = camera.sensor();
    let f = camera.lens_focal_length_mm();
    let m = sensor.normal();
    let pivot = DVec3::new(0.0, 0.0, camera.film_distance_mm());
    let e = m.dot(pivot);
    // 1. The planes: sensor σ and its conjugate, the plane of focus π.
    let sigma = DVec4::new(m.x, m.y, m.z, -e);
    let pi = DVec4::new(f * m.x, f * m.y, f * m.z - e, -f * e);
    let p = DVec4::new(lens_point_mm.x, lens_point_mm.y, 0.0, 1.0);
    let scale_pi = pi.length();
    if !(pi.dot(p).abs() > 1e-12 * scale_pi * p.length()) {
        return Err(Error::settings(
            "lens_point_mm",
            format!("{lens_point_mm} lies on the plane of sharp focus: the view degenerates"),
        ));
    }
    // 2. Central projections: from p onto π, then from the lens centre onto σ.
    let project = |c: DVec4, plane: DVec4| {
        DMat4::from_diagonal(DVec4::splat(plane.dot(c)))
            - DMat4::from_cols(c * plane.x, c * plane.y, c * plane.z, c * plane.w)
    };
    let to_focus = project(p, pi);
    let to_sensor = project(DVec4::W, sigma);
    // 3. Sensor frame: (−sx, −sy, 0) = Rᵀ (P − c) (see `Sensor::film_point`), then the image
    //    position u = 0.5 + (sx − shift_x)/W, v = 0.5 − (sy − shift_y)/H.
    let rt = sensor.rotation().transpose();
    let g = DMat4::from_cols(
        rt.x_axis.extend(0.0),
        rt.y_axis.extend(0.0),
        rt.z_axis.extend(0.0),
        (-(rt * pivot)).extend(1.0),
    );
    let (wd, ht, shift) = (sensor.width_mm, sensor.height_mm, sensor.shift_mm);
    let k = DMat4::from_cols(
        DVec4::new(-1.0 / wd, 0.0, 0.0, 0.0),
        DVec4::new(0.0, 1.0 / ht, 0.0, 0.0),
        DVec4::ZERO,
        DVec4::new(0.5 - shift.x / wd, 0.5 + shift.y / ht, 0.0, 1.0),
    );
    let metres = DMat4::from_diagonal(DVec4::new(1e3, 1e3, 1e3, 1.0));
    let mut mtx = k * g * to_sensor * to_focus * metres;
    // 4. Normalise the last row to w = ω̂·(X − p) (it vanishes at p), positive in front (−z).
    let omega = DVec3::new(mtx.x_axis.w, mtx.y_axis.w, mtx.z_axis.w);
    let len = omega.length();
    if !(len.is_finite() && len > 0.0 && mtx.is_finite()) {
        return Err(Error::settings("lens_point_mm", format!("no view from {lens_point_mm}: degenerate projection")));
    }
    let s = if omega.z > 0.0 { -1.0 / len } else { 1.0 / len };
    mtx *= s;
    // 5. Third row: ζ = 1/w.
    mtx.x_axis.z = 0.0;
    mtx.y_axis.z = 0.0;
    mtx.z_axis.z = 0.0;
    mtx.w_axis.z = 1.0;
    Ok(mtx)
}

/// The quadrilateral the sensor images onto the plane of sharp focus (camera space, metres):
/// the conjugates of the frame's corners, in the order of image positions (0, 0), (1, 0),
/// (1, 1), (0, 1) (top left first, clockwise as seen in the image). It is the same for every
/// view; with the view's point p as apex it bounds the view's frustum (a general, non-symmetric
/// pyramid under tilt and shift). Errors when focused at infinity (the quadrilateral lies at
/// infinity) or when a corner images behind the lens.
pub fn focus_quadrilateral(camera: &ThinCamera) -> Result<[DVec3; 4]> {
    let f = camera.lens_focal_length_mm();
    let corners = [DVec2::new(0.0, 0.0), DVec2::new(1.0, 0.0), DVec2::new(1.0, 1.0), DVec2::new(0.0, 1.0)];
    let mut out = [DVec3::ZERO; 4];
    for (o, c) in out.iter_mut().zip(corners) {
        let p = camera.sensor().film_point(c, camera.film_distance_mm());
        let den = p.z - f;
        if !(den > 1e-9 * f) {
            return Err(Error::settings(
                "focus_distance_m",
                format!("the frame's corner {c} images at or beyond infinity: no quadrilateral of focus"),
            ));
        }
        *o = -p * (f / den) * 1e-3;
    }
    Ok(out)
}

/// Applies a [`view_transform`] to camera-space point `x` (metres): image position (u, v) and
/// ζ = 1/w (m⁻¹); None where w ≤ 0 (behind the view or on its vanishing plane).
pub fn apply_view_transform(m: &DMat4, x: DVec3) -> Option<(DVec2, f64)> {
    let h = *m * x.extend(1.0);
    (h.w > 0.0 && h.is_finite()).then(|| (DVec2::new(h.x / h.w, h.y / h.w), h.z / h.w))
}

// ------------------------------------------------------------------------------------------
// How far a real lens's fixed-sample rays are from pinhole views.

/// The gap between `camera`'s rays of one fixed lens sample and an ideal pinhole view
/// (see [`pinhole_view_error`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PinholeViewError {
    /// The view's point (camera space x, y in mm): where the sample's rays leave the thin lens or
    /// the thick lens's front principal plane; for a traced lens, where the ray of the sample
    /// from the optical axis's film point crosses the paraxial entrance pupil's plane z = 0.
    pub pupil_point_mm: DVec2,
    /// Largest angle between a ray `generate_ray(film, u)` and the ideal ray from the pupil point
    /// through the film point's focus point, over the film grid (radians).
    pub max_angle_rad: f64,
    /// Mean of that angle over the film grid (radians).
    pub mean_angle_rad: f64,
    /// Largest distance between where a ray crosses the view point's plane and the view point (mm).
    pub max_pupil_shift_mm: f64,
    /// Film points compared (those whose ray of the sample and chief ray both exist).
    pub points: usize,
}

/// Compares `camera`'s rays of the fixed lens sample `lens_u` over a `grid` × `grid` lattice of
/// film points with the ideal pinhole view: rays from one pupil point through each film point's
/// point of sharp focus, taken where the film point's chief ray (lens sample at the pupil
/// centre) meets [`Camera::focus_plane`] (the thick-lens plane for real lenses, so field
/// curvature counts as error). Zero for the thin and thick models (their views are pinholes on
/// the lens / front principal plane); for a traced lens it measures
/// where the multi-view picture breaks (see the module docs). None when the camera has no plane
/// of focus (pinhole, focus at infinity), `grid < 2`, or no ray passes.
pub fn pinhole_view_error(camera: &Camera, lens_u: DVec2, grid: usize, wavelength_nm: f64) -> Option<PinholeViewError> {
    if grid < 2 || !lens_u.is_finite() {
        return None;
    }
    let plane = camera.focus_plane()?;
    // 1. The view point: where the rays leave the thin lens / the thick lens's front principal
    //    plane, or, for a traced lens, where the axis film point's ray crosses the paraxial
    //    entrance pupil's plane z = 0.
    let axis = camera.sensor().axis_film_coord();
    let axis_ray = camera.generate_ray(axis, lens_u, wavelength_nm)?;
    let plane_z = match camera {
        Camera::Thin(_) | Camera::Thick(_) | Camera::Pinhole(_) => axis_ray.origin.z,
        Camera::Exact(_) | Camera::Lrtf(_) => 0.0,
        Camera::Orthographic(_) => return None,
    };
    let crossing = |ray: &CameraRay| -> Option<DVec3> {
        (ray.direction.z.abs() > 1e-12).then(|| {
            let t = (plane_z - ray.origin.z) / ray.direction.z;
            ray.origin + ray.direction * t
        })
    };
    let view_point = crossing(&axis_ray)?;
    let pupil = view_point.truncate() * 1e3;
    let (mut max_angle, mut sum, mut max_shift, mut n) = (0.0f64, 0.0, 0.0f64, 0usize);
    for j in 0..grid {
        for i in 0..grid {
            let film = DVec2::new(i as f64 / (grid - 1) as f64, j as f64 / (grid - 1) as f64);
            let (Some(ray), Some(chief)) = (
                camera.generate_ray(film, lens_u, wavelength_nm),
                camera.generate_ray(film, DVec2::splat(0.5), wavelength_nm),
            ) else {
                continue;
            };
            let Some(t) = plane.intersect(chief.origin, chief.direction) else { continue };
            let focus = chief.origin + chief.direction * t;
            let ideal = (focus - view_point).normalize();
            let angle = angle_between(ideal, ray.direction);
            if !angle.is_finite() {
                continue;
            }
            if let Some(c) = crossing(&ray) {
                max_shift = max_shift.max((c - view_point).length() * 1e3);
            }
            max_angle = max_angle.max(angle);
            sum += angle;
            n += 1;
        }
    }
    (n > 0).then(|| PinholeViewError {
        pupil_point_mm: pupil,
        max_angle_rad: max_angle,
        mean_angle_rad: sum / n as f64,
        max_pupil_shift_mm: max_shift,
        points: n,
    })
}

/// The optical part of [`pinhole_view_error`] for a traced lens (exact or LRTF model, traced
/// exactly here), without the sampler's: for each film point of a `grid` × `grid` lattice the
/// ray through the fixed entrance-pupil point `pupil_point_mm` (camera space, on the paraxial
/// entrance pupil's plane z = 0) is found by Newton iteration on its aim at the rear element,
/// and compared with the ideal pinhole-view ray from that pupil point through the film point's
/// focus point (its chief ray, through the pupil centre, where it meets
/// [`Camera::focus_plane`]). What remains is the lens's: aberrations (the rays of one pupil
/// point towards a film point miss its focus point: spherical aberration, coma, field
/// curvature against the thick-lens plane) and the pupil's own aberration at wide angles.
/// `max_pupil_shift_mm` is the largest Newton residual at the pupil plane. None for other
/// models, `grid < 2`, or when no ray passes.
pub fn traced_pinhole_view_error(
    camera: &Camera,
    pupil_point_mm: DVec2,
    grid: usize,
    wavelength_nm: f64,
) -> Option<PinholeViewError> {
    let exact = match camera {
        Camera::Exact(c) => c,
        Camera::Lrtf(c) => c.exact(),
        _ => return None,
    };
    if grid < 2 || !pupil_point_mm.is_finite() {
        return None;
    }
    let plane = camera.focus_plane()?;
    let (mut max_angle, mut sum, mut max_residual, mut n) = (0.0f64, 0.0, 0.0f64, 0usize);
    let view_point = DVec3::new(pupil_point_mm.x, pupil_point_mm.y, 0.0) * 1e-3;
    for j in 0..grid {
        for i in 0..grid {
            let film = DVec2::new(i as f64 / (grid - 1) as f64, j as f64 / (grid - 1) as f64);
            let (Some((ray, residual)), Some((chief, _))) = (
                ray_through_pupil(exact, film, pupil_point_mm, wavelength_nm),
                ray_through_pupil(exact, film, DVec2::ZERO, wavelength_nm),
            ) else {
                continue;
            };
            let Some(t) = plane.intersect(chief.origin, chief.direction) else { continue };
            let focus = chief.origin + chief.direction * t;
            let angle = angle_between(focus - view_point, ray.direction);
            if !angle.is_finite() {
                continue;
            }
            max_angle = max_angle.max(angle);
            max_residual = max_residual.max(residual);
            sum += angle;
            n += 1;
        }
    }
    (n > 0).then(|| PinholeViewError {
        pupil_point_mm,
        max_angle_rad: max_angle,
        mean_angle_rad: sum / n as f64,
        max_pupil_shift_mm: max_residual,
        points: n,
    })
}

/// The ray (camera space, origin on the plane z = 0) from image position `film` through the
/// lens that crosses the entrance pupil's plane at `target_mm`, and the residual there (mm):
/// Newton iteration on the aim point at the rear element, from the pupil sampler's centre.
fn ray_through_pupil(
    camera: &crate::camera::ExactCamera,
    film: DVec2,
    target_mm: DVec2,
    wavelength_nm: f64,
) -> Option<(CameraRay, f64)> {
    use crate::optics::lens::{Ray, TraceDirection};
    let lens = camera.lens();
    let z_ep = lens.paraxial().entrance_pupil_z_mm;
    let p = camera.sensor().film_point(film, camera.film_z_mm());
    let rear = camera.pupil().rear_z_mm;
    let cross = |a: DVec2| -> Option<(DVec2, DVec3)> {
        let ray = Ray::new(p, DVec3::new(a.x, a.y, rear) - p);
        let out = lens.trace(&ray, wavelength_nm, TraceDirection::FilmToScene)?.ray;
        if out.direction.z.abs() < 1e-12 {
            return None;
        }
        let s = (z_ep - out.origin.z) / out.direction.z;
        Some(((out.origin + out.direction * s).truncate(), out.direction))
    };
    let mut aim = camera.pupil().sample(p.truncate(), DVec2::splat(0.5))?.point.truncate();
    let h = 1e-5;
    for _ in 0..40 {
        let (c, dir) = cross(aim)?;
        let r = c - target_mm;
        if r.length() < 1e-9 {
            let origin = DVec3::new(c.x, c.y, 0.0) * 1e-3;
            return Some((CameraRay { origin, direction: dir.normalize(), weight: 1.0 }, r.length()));
        }
        let (cx, _) = cross(aim + DVec2::new(h, 0.0))?;
        let (cy, _) = cross(aim + DVec2::new(0.0, h))?;
        let jac = glam::DMat2::from_cols((cx - c) / h, (cy - c) / h);
        if !(jac.determinant().abs() > 1e-12) {
            return None;
        }
        let step = jac.inverse() * r;
        // damped: at most 1 mm per step on the rear element
        aim -= step * (1.0f64).min(1.0 / step.length().max(1e-300));
    }
    None
}

/// The angle between two vectors, accurate near 0 (atan2 of the cross and dot products).
fn angle_between(a: DVec3, b: DVec3) -> f64 {
    a.cross(b).length().atan2(a.dot(b))
}
