//! Rendering: camera + scene → integrator → film. Pixels are rendered in parallel (rayon, rows
//! of tiles) in progressive passes; each pixel sample draws from its own Sobol stream, so the
//! image is identical for any thread count.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `width`, `height` | u32 | pixels | 960 × 640 |
//! | `spp` | u32, samples per pixel | — | 64 |
//! | `seed` | u32 | — | 0 |
//! | `max_depth` | u32, path vertices | — | 8 |
//! | `spectral` | bool: one wavelength per camera ray (lens dispersion) | — | false |
//! | `time_limit` | optional duration; stops after the pass that crosses it | s | none |
//! | `filter` | [`PixelFilter`] | px | Blackman–Harris spanning 3 px (Cycles' default) |
//! | `clip_start_m`, `clip_end_m` | f64: clipping planes perpendicular to the view axis (Cycles) | m | 0, ∞ |
//! | `crop` | optional `[x0, y0, x1, y1)` window of the frame to render (row 0 = top) | px | whole frame |
//! | `pixel_origin` | the frame's pixel (0, 0) in the numbering that seeds each pixel's samples (overscan) | px | (0, 0) |
//! | `adaptive_threshold` | f32: adaptive sampling's noise threshold, as Cycles' "Noise Threshold" (a pixel stops once its error estimate, over its 3×3 neighbourhood, is below it; see [`adaptive_converged`]); path tracing (`mc`) only | — | 0 (off: every pixel takes `spp`) |
//! | `adaptive_min_samples` | u32: samples every pixel takes before adaptive sampling may stop it | — | 0 (auto, as Cycles: max(4, ⌈16 / threshold^0.3⌉)) |
//! | `bokeh_paths` | f32: light paths from emitters through the lens per pixel per sample, combined with camera paths by MIS (see [`crate::bokeh`]; under adaptive sampling a pass traces only the share of them whose light lands in pixels still sampled); any model with a lens (thin, thick, exact, LRTF), not the pinhole | — | 0 (off; the CLI's and the Python module's auto gives 1 where it applies) |

use crate::bokeh::{BokehTracer, FilmSample, LightPathSettings};
use crate::camera::{Camera, CameraRay, CAMERA_BATCH};
use crate::error::{Error, Result};
use crate::film::{Film, FilterSampler, Image, PixelFilter};
use crate::integrator::{PathSample, PathTracer, RenderScene, SurfaceHit};
use crate::limits;
use crate::sampler::PixelSampler;
use crate::spectral;
use glam::{DAffine3, DVec2, Vec3};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// A camera placed in the world.
#[derive(Debug, Clone)]
pub struct CameraRig {
    /// The camera model.
    pub camera: Camera,
    /// Camera-to-world transform (rigid, metres; camera looks down −z).
    pub to_world: DAffine3,
}

/// Render settings.
#[derive(Debug, Clone)]
pub struct RenderSettings {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Samples per pixel.
    pub spp: u32,
    /// Seed.
    pub seed: u32,
    /// Maximum path depth.
    pub max_depth: u32,
    /// Trace one wavelength per camera ray.
    pub spectral: bool,
    /// Stop after the pass in which this much time has passed.
    pub time_limit: Option<Duration>,
    /// Pixel filter.
    pub filter: PixelFilter,
    /// Near clipping plane distance along the view axis.
    pub clip_start_m: f64,
    /// Far clipping plane distance along the view axis.
    pub clip_end_m: f64,
    /// Render only this window `[x0, y0, x1, y1)` of the frame; the image is the window's size.
    pub crop: Option<[u32; 4]>,
    /// Light paths from emissive triangles through the lens per pixel per sample (0 = none).
    pub bokeh_paths: f32,
    /// Adaptive sampling's noise threshold (Cycles' "Noise Threshold"); 0 turns it off.
    pub adaptive_threshold: f32,
    /// Samples every pixel takes before adaptive sampling may stop it (0: automatic).
    pub adaptive_min_samples: u32,
    /// Where this frame's pixel (0, 0) sits in the frame its pixels are numbered by (a frame
    /// extended for overscan starts left of and above the display frame): the pixels' sample
    /// sequences follow that numbering, so a pixel renders the same with and without overscan.
    pub pixel_origin: [i32; 2],
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            width: 960,
            height: 640,
            spp: 64,
            seed: 0,
            max_depth: 8,
            spectral: false,
            time_limit: None,
            filter: PixelFilter::default(),
            clip_start_m: 0.0,
            clip_end_m: f64::INFINITY,
            crop: None,
            bokeh_paths: 0.0,
            adaptive_threshold: 0.0,
            adaptive_min_samples: 0,
            pixel_origin: [0, 0],
        }
    }
}

impl RenderSettings {
    /// Checks the settings.
    pub fn validate(&self) -> Result<()> {
        let bad = |f: &str, m: String| Err(Error::settings(f, m));
        let side = limits::MAX_SIDE_PX;
        if self.width == 0 || self.height == 0 || self.width > side || self.height > side {
            return bad("resolution", format!("{}x{} is outside 1..16384 per side", self.width, self.height));
        }
        if (self.width as u64) * (self.height as u64) > limits::MAX_PIXELS {
            return bad("resolution", format!("{}x{} is more than 100 megapixels", self.width, self.height));
        }
        let [x0, y0, x1, y1] = self.crop.unwrap_or([0, 0, self.width, self.height]);
        let film_px = (x1.saturating_sub(x0) as u64) * (y1.saturating_sub(y0) as u64);
        let film_bytes = film_px * limits::FILM_BYTES_PER_PIXEL;
        if let Err(budget) = limits::check_memory(film_bytes) {
            return bad(
                "resolution",
                format!(
                    "{}x{} needs about {} for the film ({} bytes per pixel), {}",
                    self.width,
                    self.height,
                    limits::format_bytes(film_bytes),
                    limits::FILM_BYTES_PER_PIXEL,
                    limits::over_budget(budget)
                ),
            );
        }
        if self.spp == 0 || self.spp > limits::MAX_SPP {
            return bad("spp", format!("{} must be in 1..=1048576", self.spp));
        }
        if self.max_depth == 0 || self.max_depth > limits::MAX_DEPTH {
            return bad("max_depth", format!("{} must be in 1..=1024", self.max_depth));
        }
        if !(self.clip_start_m >= 0.0 && self.clip_start_m.is_finite())
            || self.clip_end_m.is_nan()
            || self.clip_end_m <= self.clip_start_m
        {
            return bad(
                "clip",
                format!("clip start {} and end {} must satisfy 0 ≤ start < end", self.clip_start_m, self.clip_end_m),
            );
        }
        if !(self.bokeh_paths.is_finite() && (0.0..=64.0).contains(&self.bokeh_paths)) {
            return bad(
                "bokeh_paths",
                format!("{} must be in 0..=64 light paths per pixel per sample", self.bokeh_paths),
            );
        }
        if !(self.adaptive_threshold.is_finite() && (0.0..=1.0).contains(&self.adaptive_threshold)) {
            return bad(
                "adaptive_threshold",
                format!("{} must be in 0..=1 (0 turns adaptive sampling off)", self.adaptive_threshold),
            );
        }
        if self.adaptive_min_samples > limits::MAX_SPP {
            return bad("adaptive_min_samples", format!("{} must be in 0..=1048576", self.adaptive_min_samples));
        }
        if let Some([x0, y0, x1, y1]) = self.crop {
            if !(x0 < x1 && y0 < y1 && x1 <= self.width && y1 <= self.height) {
                return bad(
                    "crop",
                    format!(
                        "window [{x0}, {y0}, {x1}, {y1}) is empty or outside the {}x{} frame",
                        self.width, self.height
                    ),
                );
            }
        }
        Ok(())
    }

    /// The samples every pixel takes before adaptive sampling may stop it: the setting, or
    /// when it is 0 Cycles' automatic choice, max(4, ⌈16 / threshold^0.3⌉) (threshold 0.1 → 32,
    /// 0.01 → 64, 0.001 → 128). None when adaptive sampling is off.
    pub fn adaptive_min_spp(&self) -> Option<u32> {
        if !(self.adaptive_threshold > 0.0) {
            return None;
        }
        Some(match self.adaptive_min_samples {
            0 => ((16.0 / self.adaptive_threshold.powf(0.3)).ceil() as u32).max(4),
            n => n,
        })
    }
}

/// Cycles' factor between the Noise Threshold a user sets and the one its test uses
/// (`Integrator::get_adaptive_sampling`: "arbitrary factor that makes the threshold more similar
/// to what it was before"); the automatic minimum is chosen from the unscaled threshold.
pub const ADAPTIVE_THRESHOLD_SCALE: f32 = 5.0;

/// Whether sample `index` of a pixel is in class A, the half of its samples that adaptive
/// sampling compares with the whole: Cycles' split (`sample_is_class_A`: the parity of the set
/// bits at odd positions, after Christensen et al. 2018, "Progressive Multi-Jittered Sample
/// Sequences", §10.2.1). Both halves of an Owen-scrambled Sobol prefix stay well stratified, so
/// their difference follows the estimate's error. Odd-numbered samples are no such half: with
/// them, pixels took several times more samples to pass the same threshold, for a lower error
/// than Cycles' at that threshold (docs/performance.md).
pub fn adaptive_class_a(index: u32) -> bool {
    (index & 0xaaaa_aaaa).count_ones() & 1 == 1
}

/// How many of the samples 0..`samples` are in class A ([`adaptive_class_a`]): half of each
/// aligned group of 4 (bit 1 flips the class, bit 0 does not), then the remainder's.
pub fn adaptive_class_a_count(samples: u32) -> u32 {
    let rest = samples % 4;
    let c = adaptive_class_a(samples - rest) as u32;
    (samples - rest) / 2
        + match rest {
            0 => 0,
            1 => c,
            2 => 2 * c,
            _ => 2 * c + (1 - c),
        }
}

/// Adaptive sampling's test of one pixel, as Cycles' (`film_adaptive_sampling_convergence_check`,
/// after Dammertz et al. 2010, "A hierarchical automatic stopping condition for Monte Carlo
/// global illumination", §2.1): `sum` is the sum of its `samples` samples (numbered from 0),
/// `sum_a` that of its class-A ones ([`adaptive_class_a`]); with I = r + g + b of the mean, the
/// error is |mean − mean of class A|₁ / (10⁻⁴ + √I below I = 1, else I) (Cycles' rule: brighter
/// pixels are highly exposed and need fewer samples), and the pixel passes when it is below
/// `threshold` (the test's threshold: the user's times [`ADAPTIVE_THRESHOLD_SCALE`], as Cycles').
pub fn adaptive_converged(sum: Vec3, sum_a: Vec3, samples: u32, threshold: f32) -> bool {
    // Cycles' 2·Σ_A / n is class A's mean when A holds exactly half; the exact count keeps a
    // noiseless pixel from being held back by a 1/n bias at other counts.
    let n_a = adaptive_class_a_count(samples);
    if samples < 2 || n_a == 0 {
        return false;
    }
    let (mean, half) = (sum / samples as f32, sum_a / n_a as f32);
    let difference = (mean - half).abs();
    let intensity = (mean.x + mean.y + mean.z).max(0.0);
    let normalize = if intensity < 1.0 { intensity.sqrt() } else { intensity };
    let error = (difference.x + difference.y + difference.z) / (1e-4 + normalize);
    error < threshold
}

/// Samples between adaptive sampling's tests (Cycles' `adaptive_step`).
pub const ADAPTIVE_STEP: u32 = 16;

/// The sample count after `done` at which adaptive sampling next tests its pixels, as Cycles
/// schedules it (`AdaptiveSampling::need_filter`): at multiples of [`ADAPTIVE_STEP`] that exceed
/// the minimum `min_spp` by at least 2 (the first at 16 for a minimum of 8, at 80 for 64). The
/// tests then always see a whole number of groups of 4 samples, which class A splits in half.
pub fn adaptive_next_check(done: u32, min_spp: u32) -> u32 {
    let first = (min_spp + 2).div_ceil(ADAPTIVE_STEP) * ADAPTIVE_STEP;
    first.max((done + 1).div_ceil(ADAPTIVE_STEP) * ADAPTIVE_STEP)
}

/// One adaptive-sampling step over the film: a pixel converges when every pixel of its 3×3
/// neighbourhood (clipped at the film's edges) has converged already or passes
/// [`adaptive_converged`] (Cycles' test, then its dilation of unconverged pixels by one in x and
/// y); a converged pixel stays converged.
fn adaptive_step(film: &Film, converged: &[bool], threshold: f32) -> Vec<bool> {
    let (w, h) = (film.width as usize, film.height as usize);
    let passes: Vec<bool> = film
        .pixels
        .par_iter()
        .zip(converged)
        .map(|(p, &c)| c || adaptive_converged(p.rgb, p.rgb_class_a, p.samples, threshold))
        .collect();
    (0..w * h)
        .into_par_iter()
        .map(|i| {
            let (x, y) = (i % w, i / w);
            converged[i]
                || (y.saturating_sub(1)..(y + 2).min(h))
                    .all(|yy| (x.saturating_sub(1)..(x + 2).min(w)).all(|xx| passes[yy * w + xx]))
        })
        .collect()
}

/// The share of the light-path splats so far (r + g + b) that lies in pixels not yet
/// `converged`; where nothing has landed yet, the share of those pixels.
fn light_share_open(splat: &[Vec3], converged: &[bool]) -> f64 {
    let (open, all) = splat.iter().zip(converged).fold((0f64, 0f64), |(open, all), (v, &c)| {
        let e = (v.x + v.y + v.z).max(0.0) as f64;
        (if c { open } else { open + e }, all + e)
    });
    if all > 0.0 {
        open / all
    } else {
        converged.iter().filter(|&&c| !c).count() as f64 / converged.len().max(1) as f64
    }
}

/// What a render produced.
#[derive(Debug, Clone)]
pub struct RenderResult {
    /// The image.
    pub image: Image,
    /// Samples per pixel completed in every pixel (with adaptive sampling: in every pixel still
    /// sampled at the end; `camera_rays` over the pixel count is the mean).
    pub spp_done: u32,
    /// False when stopped early (time limit or cancel); true when adaptive sampling found every
    /// pixel converged before `spp`.
    pub complete: bool,
    /// Wall time.
    pub seconds: f64,
    /// Camera rays generated (including blocked ones).
    pub camera_rays: u64,
    /// Bokeh light paths started (0 without them).
    pub light_paths: u64,
    /// Those of them that reached the window (added at least one splat).
    pub light_paths_landed: u64,
    /// Samples dropped as non-finite.
    pub dropped_samples: u64,
}

/// Progress: fraction done in [0, 1]; return false to cancel.
pub type Progress<'a> = &'a (dyn Fn(f32) -> bool + Sync);

/// Called after every finished pass with the image so far and the samples per pixel done
/// (progressive display). None: nobody watches, and no image is made between passes (with
/// adaptive sampling's many short passes, that conversion took up to a tenth of the render).
pub type PassObserver<'a> = Option<&'a (dyn Fn(&Image, u32) + Sync)>;

/// Renders `scene` through `rig`.
pub fn render(
    scene: &RenderScene,
    rig: &CameraRig,
    settings: &RenderSettings,
    progress: Progress,
) -> Result<RenderResult> {
    render_observed(scene, rig, settings, progress, None)
}

/// Renders `scene` through `rig`, showing every finished pass to `on_pass` (progressive display).
pub fn render_observed(
    scene: &RenderScene,
    rig: &CameraRig,
    settings: &RenderSettings,
    progress: Progress,
    on_pass: PassObserver,
) -> Result<RenderResult> {
    settings.validate()?;
    let tracer = PathTracer { max_depth: settings.max_depth, ..PathTracer::default() };
    let light = LightPathSettings {
        paths: settings.bokeh_paths,
        width: settings.width,
        height: settings.height,
        crop: settings.crop.unwrap_or([0, 0, settings.width, settings.height]),
        filter: settings.filter,
        spectral: settings.spectral,
        seed: settings.seed,
        clip_m: (settings.clip_start_m, settings.clip_end_m),
    };
    let bokeh = BokehTracer::new(scene, &rig.camera, rig.to_world, &light)?;
    render_samples(rig, settings, progress, on_pass, &PathShader { tracer, scene, bokeh })
}

/// What a render method does with each camera sample (Monte Carlo traces a path; the preview
/// methods of [`crate::dof`] look the ray up in layers or share lens samples between pixels).
pub(crate) trait SampleShader: Sync {
    /// The lens sample of sample index `s`, given the pixel's own Sobol lens sample `own`.
    fn lens_sample(&self, _s: u32, own: DVec2) -> DVec2 {
        own
    }

    /// Light paths traced alongside the camera samples (Monte Carlo with bokeh light paths).
    fn bokeh(&self) -> Option<&BokehTracer<'_>> {
        None
    }

    /// The radiance (and first-hit AOVs) along camera ray `ray` (camera space), whose world ray
    /// is `origin` + t·`dir` seen between `clip.0` and `clip.1`; `film` is the sample's film
    /// position, lens sample and filter offset, from which its density is found for weighting
    /// it against light paths where a light path could have made it.
    fn shade(
        &self,
        ray: &CameraRay,
        origin: Vec3,
        dir: Vec3,
        clip: (f32, f32),
        film: &FilmSample,
        sampler: &mut PixelSampler,
    ) -> PathSample;

    /// The scene whose first hits [`SampleShader::shade_from_hit`] takes: the render loop then
    /// finds a batch's first hits together ([`RenderScene::intersect_packet`]). None: `shade`.
    fn packet_scene(&self) -> Option<&RenderScene> {
        None
    }

    /// [`SampleShader::shade`] given the camera ray's first hit (what `intersect` gives for
    /// [`PathTracer::camera_query`]'s query).
    #[allow(clippy::too_many_arguments)]
    fn shade_from_hit(
        &self,
        ray: &CameraRay,
        origin: Vec3,
        dir: Vec3,
        clip: (f32, f32),
        film: &FilmSample,
        sampler: &mut PixelSampler,
        _first_hit: Option<SurfaceHit>,
    ) -> PathSample {
        self.shade(ray, origin, dir, clip, film, sampler)
    }
}

/// A camera ray in the world: origin, unit direction, clipping distances along it.
type WorldRay = (Vec3, Vec3, (f32, f32));

/// Monte Carlo: every camera ray is path traced.
struct PathShader<'a> {
    tracer: PathTracer,
    scene: &'a RenderScene,
    bokeh: Option<BokehTracer<'a>>,
}

impl SampleShader for PathShader<'_> {
    fn bokeh(&self) -> Option<&BokehTracer<'_>> {
        self.bokeh.as_ref()
    }

    fn shade(
        &self,
        _ray: &CameraRay,
        origin: Vec3,
        dir: Vec3,
        clip: (f32, f32),
        film: &FilmSample,
        sampler: &mut PixelSampler,
    ) -> PathSample {
        match &self.bokeh {
            None => self.tracer.trace_clipped(self.scene, origin, dir, clip, sampler),
            Some(b) => {
                let weight = |hit: &SurfaceHit, d: Vec3| b.camera_weight(film, origin, d, hit);
                self.tracer.trace_weighted(self.scene, origin, dir, clip, sampler, Some(&weight))
            }
        }
    }

    fn packet_scene(&self) -> Option<&RenderScene> {
        Some(self.scene)
    }

    fn shade_from_hit(
        &self,
        _ray: &CameraRay,
        origin: Vec3,
        dir: Vec3,
        clip: (f32, f32),
        film: &FilmSample,
        sampler: &mut PixelSampler,
        first_hit: Option<SurfaceHit>,
    ) -> PathSample {
        let weight =
            self.bokeh.as_ref().map(|b| move |hit: &SurfaceHit, d: Vec3| b.camera_weight(film, origin, d, hit));
        let direct = weight.as_ref().map(|w| w as &dyn Fn(&SurfaceHit, Vec3) -> f32);
        self.tracer.trace_weighted_from_hit(self.scene, origin, dir, clip, sampler, direct, first_hit)
    }
}

/// The progressive render loop shared by every method: pixel samples (filter offset, lens
/// sample, wavelength) → camera ray → `shader` → film.
pub(crate) fn render_samples(
    rig: &CameraRig,
    settings: &RenderSettings,
    progress: Progress,
    on_pass: PassObserver,
    shader: &dyn SampleShader,
) -> Result<RenderResult> {
    settings.validate()?;
    let start = Instant::now();
    let (w, h) = (settings.width, settings.height);
    let [x0, y0, x1, y1] = settings.crop.unwrap_or([0, 0, w, h]);
    let (cw, ch) = (x1 - x0, y1 - y0);
    let mut film = Film::new(cw, ch);
    let bokeh = shader.bokeh();
    if bokeh.is_some() {
        film.splat = vec![Vec3::ZERO; film.pixels.len()];
    }
    let (clip_near, clip_far) = (settings.clip_start_m, settings.clip_end_m);
    let filter = FilterSampler::new(settings.filter);
    let cancelled = AtomicBool::new(false);
    let camera_rays = AtomicU64::new(0);
    let dropped = AtomicU64::new(0);
    let wavelength_primary =
        rig.camera.real_lens().map_or(crate::optics::glass::WAVELENGTH_D_NM, |l| l.primary_wavelength_nm());
    // Adaptive sampling: pixels that have converged take no more samples (row-major flags).
    let adaptive_min = settings.adaptive_min_spp();
    let mut converged = vec![false; if adaptive_min.is_some() { film.pixels.len() } else { 0 }];
    let mut all_converged = false;
    // The light paths' sample count: a sample adds the part of its light paths traced (1 without
    // adaptive sampling, so then the count is `done`).
    let (mut light_samples, mut light_paths, mut light_paths_landed) = (0f64, 0u64, 0u64);
    // 1. Progressive passes: 1, 2, 4, ... samples, at most 16 spp per pass (with adaptive
    //    sampling, passes end where the tests are made: see `adaptive_next_check`).
    let mut done = 0u32;
    let mut pass_spp = 1u32;
    let total_work = settings.spp as f64 * ch as f64;
    let rows_done = AtomicU64::new(0);
    while done < settings.spp && !cancelled.load(Ordering::Relaxed) {
        let to_check = adaptive_min.map_or(u32::MAX, |m| adaptive_next_check(done, m) - done);
        let n = pass_spp.min(settings.spp - done).min(to_check);
        let range = done..done + n;
        let flags = &converged;
        film.pixels.par_chunks_mut(cw as usize).enumerate().for_each(|(row_index, row)| {
            if cancelled.load(Ordering::Relaxed) {
                return;
            }
            let y = row_index + y0 as usize;
            // The row's pixels still sampled (every one unless adaptive sampling stopped some).
            let active: Option<Vec<usize>> = (!flags.is_empty()).then(|| {
                let row_flags = &flags[row_index * row.len()..(row_index + 1) * row.len()];
                (0..row.len()).filter(|&c| !row_flags[c]).collect()
            });
            let columns = active.as_ref().map_or(row.len(), |a| a.len());
            // The row's samples, pixel by pixel, in batches of CAMERA_BATCH camera rays (the
            // LRTF model looks a batch up at once); each sample keeps its own sampler, so the
            // results are those of one sample at a time.
            let per_pixel = n as usize;
            let total = columns * per_pixel;
            for first in (0..total).step_by(CAMERA_BATCH) {
                // (pixel column, sample index) of each lane
                let lanes: [(usize, u32); CAMERA_BATCH] = std::array::from_fn(|i| {
                    let k = (first + i).min(total - 1);
                    let col = active.as_ref().map_or(k / per_pixel, |a| a[k / per_pixel]);
                    (col, range.start + (k % per_pixel) as u32)
                });
                let chunk = &lanes[..CAMERA_BATCH.min(total - first)];
                // 2. Camera samples: filter offset, lens point, wavelength.
                let mut samplers: [Option<PixelSampler>; CAMERA_BATCH] = std::array::from_fn(|_| None);
                let mut film_uv = [DVec2::ZERO; CAMERA_BATCH];
                let mut lens_u = [DVec2::ZERO; CAMERA_BATCH];
                let mut offsets = [glam::Vec2::ZERO; CAMERA_BATCH];
                let mut lambdas = [(wavelength_primary, Vec3::ONE); CAMERA_BATCH];
                for (i, &(col, s)) in chunk.iter().enumerate() {
                    let x = col + x0 as usize;
                    let [ox, oy] = settings.pixel_origin;
                    let (sx, sy) = ((x as i64 + ox as i64) as u32, (y as i64 + oy as i64) as u32);
                    let mut sampler = PixelSampler::new(sx, sy, s, settings.seed);
                    let off = filter.sample(sampler.next_2d());
                    film_uv[i] = DVec2::new(
                        (x as f64 + 0.5 + off.x as f64) / w as f64,
                        (y as f64 + 0.5 + off.y as f64) / h as f64,
                    );
                    lens_u[i] = shader.lens_sample(s, sampler.next_2d().as_dvec2());
                    let u_lambda = sampler.next_1d();
                    lambdas[i] = if settings.spectral {
                        let (l, wt) = spectral::sample_wavelength(u_lambda);
                        (l as f64, wt)
                    } else {
                        (wavelength_primary as f32 as f64, Vec3::ONE)
                    };
                    offsets[i] = off;
                    samplers[i] = Some(sampler);
                }
                let wavelengths: [f64; CAMERA_BATCH] = std::array::from_fn(|i| lambdas[i].0);
                let rays = rig.camera.generate_ray_batch(&film_uv, &lens_u, &wavelengths);
                // 3. World rays and clipping planes (along the view axis); the batch's first hits
                //    found together when the shader starts from them.
                let world: [Option<WorldRay>; CAMERA_BATCH] = std::array::from_fn(|i| {
                    let ray = rays[i].as_ref()?;
                    let o = rig.to_world.transform_point3(ray.origin).as_vec3();
                    let d = rig.to_world.transform_vector3(ray.direction).normalize().as_vec3();
                    let axial = (-ray.direction.z / ray.direction.length()).max(1e-6);
                    Some((o, d, ((clip_near / axial) as f32, (clip_far / axial) as f32)))
                });
                let first_hits = shader.packet_scene().map(|scene| {
                    let queries: [(Vec3, Vec3, f32); CAMERA_BATCH] = std::array::from_fn(|i| {
                        world[i]
                            .filter(|_| i < chunk.len())
                            .and_then(|(o, d, clip)| PathTracer::camera_query(o, d, clip))
                            .unwrap_or((Vec3::ZERO, Vec3::ZERO, 0.0))
                    });
                    scene.intersect_packet(&queries)
                });
                for (i, &(col, s)) in chunk.iter().enumerate() {
                    let (Some(mut sampler), px) = (samplers[i].take(), &mut row[col]) else { continue };
                    let lambda_weight = lambdas[i].1;
                    px.samples += 1;
                    let (Some(ray), Some((o, d, clip))) = (rays[i], world[i]) else {
                        continue;
                    };
                    // 4. The path.
                    let film_sample = FilmSample { film: film_uv[i], lens_u: lens_u[i], offset: offsets[i] };
                    let sample = match &first_hits {
                        Some(hits) => shader.shade_from_hit(&ray, o, d, clip, &film_sample, &mut sampler, hits[i]),
                        None => shader.shade(&ray, o, d, clip, &film_sample, &mut sampler),
                    };
                    let value = sample.radiance * lambda_weight * ray.weight as f32;
                    if !value.is_finite() || sample.dropped {
                        px.dropped += 1;
                        continue;
                    }
                    px.rgb += value;
                    if adaptive_class_a(s) {
                        px.rgb_class_a += value;
                    }
                    // Coverage over the light that reaches the film: a sample blocked by the
                    // lens carries no light and says nothing about coverage, and rays are
                    // weighted as their radiance is (so compositing with alpha is exact).
                    let w = ray.weight as f32;
                    px.alpha += sample.alpha * w;
                    px.alpha_weight += w;
                    if sample.depth_m.is_finite() {
                        // Z: the hit's distance along the camera's view axis (Cycles' Z pass).
                        let dir = ray.direction.normalize();
                        let z = -(ray.origin.z + dir.z * sample.depth_m as f64);
                        px.hits += 1;
                        px.depth += z as f32;
                        px.normal += sample.normal;
                        px.albedo += sample.albedo;
                    }
                }
            }
            camera_rays.fetch_add(columns as u64 * n as u64, Ordering::Relaxed);
            let r = rows_done.fetch_add(n as u64, Ordering::Relaxed) + n as u64;
            if !progress((r as f64 / total_work) as f32) {
                cancelled.store(true, Ordering::Relaxed);
            }
        });
        if !cancelled.load(Ordering::Relaxed) {
            // 4. The pass's light paths, splatted (the camera samples above weighted against them).
            if let Some(b) = bokeh {
                // With adaptive sampling, only part of each sample's light paths: the share of
                // the light on the film (the splats so far) that lands in pixels still sampled.
                // Light paths serve the whole window; once the pixels they reach have stopped,
                // tracing them all would make the render's cost follow its slowest pixel.
                let share = if converged.is_empty() { 1.0 } else { light_share_open(&film.splat, &converged) };
                let (traced, landed) = b.trace_pass(range.clone(), &mut film.splat, share);
                light_samples += traced as f64 / b.paths_per_sample() as f64 * n as f64;
                light_paths += traced * n as u64;
                light_paths_landed += landed;
            }
            done += n;
            film.splat_scale = 1.0 / light_samples as f32;
            if let Some(show) = on_pass {
                show(&film.image(), done);
            }
        }
        pass_spp = (pass_spp * 2).min(16);
        // 5. Adaptive sampling: stop the pixels whose 3×3 neighbourhood has converged.
        if let Some(min_spp) = adaptive_min {
            let at_check = done.checked_sub(1).is_some_and(|d| adaptive_next_check(d, min_spp) == done);
            if at_check && done < settings.spp && !cancelled.load(Ordering::Relaxed) {
                converged = adaptive_step(&film, &converged, settings.adaptive_threshold * ADAPTIVE_THRESHOLD_SCALE);
                if converged.iter().all(|&c| c) {
                    all_converged = true;
                    break;
                }
            }
        }
        if let Some(limit) = settings.time_limit {
            if start.elapsed() >= limit && done < settings.spp {
                break;
            }
        }
    }
    for p in &film.pixels {
        dropped.fetch_add(p.dropped as u64, Ordering::Relaxed);
    }
    Ok(RenderResult {
        image: film.image(),
        spp_done: done,
        complete: done == settings.spp || all_converged,
        seconds: start.elapsed().as_secs_f64(),
        camera_rays: camera_rays.load(Ordering::Relaxed),
        light_paths,
        light_paths_landed,
        dropped_samples: dropped.load(Ordering::Relaxed),
    })
}
