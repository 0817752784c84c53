//! `--lens-model auto`: the cheapest camera model whose image stays within an error budget
//! (pixels at the render's resolution) of the exact trace — model only what the scene needs.
//!
//! Candidates, cheapest first: pinhole, thin lens, thick lens, LRTF at 32³, 64³, 96³, 128³,
//! exact. For an ideal (thin) lens only pinhole and thin are candidates and the answer is
//! analytic: a pinhole when the circle of confusion over the scene's depth range is below the
//! budget.
//!
//! For a real lens every candidate is compared with the exact trace where it matters in the
//! image: for a grid of 7 × 5 film points, 512 rays each (the same Owen-scrambled Sobol lens
//! samples for every model) are followed to three surfaces — planes perpendicular to the axis
//! at the focus distance and at the scene's nearest depth, and infinity (directions) — and the
//! weighted centroid and RMS radius of where they land are compared. The error of a film point
//! is the largest, over the three surfaces, of |Δcentroid| + |ΔRMS radius| in pixels (the pixel
//! footprint at that depth, from the sensor width, the image width and the focal length). A
//! model meets the budget when the mean of that error over the film grid is within
//! `tolerance_px` and no film point exceeds 4 × `tolerance_px`. So a missing blur (pinhole), a missing
//! aberration or distortion (thin, thick) or a table's interpolation error (LRTF) all count,
//! at the resolution that will be rendered. The relative irradiance reaching each film point
//! (vignetting) must also agree within 2 % of the centre's, or the model is rejected.
//!
//! Among the models that meet the budget the cheapest in estimated camera-ray time wins. The
//! estimate is a fixed cost model (measured with `petzval bench lens` and `bench lens-models`,
//! see docs/speed-vs-error.md), not a timing, so the choice — and the image — is the same on
//! every run and thread count: exact 40 ns per surface, LRTF 30 ns plus its exact fallback
//! (2 % of an exact trace; batched lookups measured at 26–32 ns with 0.5–1.6 % of rays traced
//! exactly on double-gauss-50mm, nikon-normal-52mm and angenieux-double-gauss-100mm), thick
//! lens 60 ns, thin lens 50 ns, pinhole 30 ns, times the render's camera rays
//! (width × height × spp); an LRTF adds its bake (about five exact traces per table entry)
//! and is only baked when it can pay off. Baked tables are cached for the process.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `tolerance_px` | f64 | px | 0.25 |
//! | film grid × rays per point | — | — | 7 × 5 × 512 |
//! | vignetting agreement | relative irradiance | — | 0.02 |
//! | depth range without a scene | (near, far) | m | (0.3, ∞) |

use super::model::{build_model, cached_lrtf};
use super::spec::{CameraSpec, LensModel, SpecLens};
use super::Camera;
use crate::error::{Error, Result};
use glam::{DVec2, DVec3};

/// What `auto` needs to know about the shot.
#[derive(Debug, Clone)]
pub struct ShotContext {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Samples per pixel.
    pub spp: u32,
    /// Nearest and farthest scene depth seen by the camera (m); None = unknown.
    pub depth_range_m: Option<(f64, f64)>,
    /// Wavelengths matter (spectral rendering of a dispersive lens).
    pub spectral: bool,
}

impl Default for ShotContext {
    fn default() -> Self {
        ShotContext { width: 1920, height: 1280, spp: 64, depth_range_m: None, spectral: false }
    }
}

/// One candidate's measured error and estimated cost.
#[derive(Debug, Clone)]
pub struct CandidateReport {
    /// The model.
    pub model: LensModel,
    /// Largest error over the film grid (px); infinite when not applicable.
    pub max_error_px: f64,
    /// Mean error over the film grid (px).
    pub mean_error_px: f64,
    /// Largest relative-irradiance difference (vignetting) over the film grid.
    pub irradiance_error: f64,
    /// Nominal cost per camera ray (ns, one core; see the module docs).
    pub ns_per_ray: f64,
    /// Nominal set-up time (LRTF bake) in seconds of one core.
    pub setup_seconds: f64,
    /// Nominal camera-ray time of the render plus set-up (seconds of one core).
    pub estimated_seconds: f64,
    /// Within the budget.
    pub meets: bool,
    /// Why not, when it does not (or a remark).
    pub note: String,
}

/// The model chosen, why, and what was considered.
#[derive(Debug, Clone)]
pub struct ModelChoice {
    /// The model used.
    pub model: LensModel,
    /// One line: why.
    pub reason: String,
    /// Every candidate evaluated (empty when the model was given).
    pub candidates: Vec<CandidateReport>,
}

impl ModelChoice {
    /// A model the user asked for.
    pub fn fixed(model: LensModel) -> Self {
        ModelChoice { model, reason: "requested".into(), candidates: Vec::new() }
    }
}

const GRID: (usize, usize) = (7, 5);
const RAYS_PER_POINT: u32 = 512;
const IRRADIANCE_TOLERANCE: f64 = 0.02;
/// No film point may be off by more than this many budgets.
const MAX_OVER_MEAN_BUDGET: f64 = 4.0;
const DEFAULT_DEPTH_RANGE_M: (f64, f64) = (0.3, f64::INFINITY);

/// Picks the model for `spec` (whose model is `Auto`); returns the chosen camera when it was
/// built on the way.
pub(crate) fn choose_model(
    spec: &CameraSpec,
    lens: &SpecLens,
    shot: &ShotContext,
) -> Result<(ModelChoice, Option<Camera>)> {
    if shot.width == 0 || shot.height == 0 {
        return Err(Error::settings("resolution", "must be at least 1x1"));
    }
    match lens {
        SpecLens::Ideal => Ok((choose_ideal(spec, shot), None)),
        SpecLens::Real(_) => choose_real(spec, lens, shot),
    }
}

/// Pixel pitch (mm per pixel along the sensor width).
fn pixel_pitch_mm(spec: &CameraSpec, shot: &ShotContext) -> f64 {
    spec.sensor.width_mm / shot.width as f64
}

fn choose_ideal(spec: &CameraSpec, shot: &ShotContext) -> ModelChoice {
    if spec.orthographic_m_per_mm.is_some() {
        return ModelChoice {
            model: LensModel::Orthographic,
            reason: "orthographic camera: parallel rays, no lens".into(),
            candidates: Vec::new(),
        };
    }
    let Some(n) = spec.f_number.filter(|_| !spec.is_pinhole()) else {
        return ModelChoice {
            model: LensModel::Pinhole,
            reason: "pinhole camera: no lens to model".into(),
            candidates: Vec::new(),
        };
    };
    // Blender's thin lens: film at F, lens of focal length F·s/(F+s), aperture diameter F/N.
    let f = spec.focal_length_mm;
    let s = spec.focus_distance_m.map(|m| m * 1e3);
    let f_lens = s.map(|s| f * s / (f + s)).unwrap_or(f);
    let aperture = f / n;
    let coc_mm = |d_mm: f64| {
        let v = if d_mm.is_finite() { 1.0 / (1.0 / f_lens - 1.0 / d_mm) } else { f_lens };
        if v <= 0.0 {
            f64::INFINITY
        } else {
            aperture * (v - f).abs() / v
        }
    };
    let (near, far) = shot.depth_range_m.unwrap_or(DEFAULT_DEPTH_RANGE_M);
    let coc_px = coc_mm(near * 1e3).max(coc_mm(far * 1e3)) / pixel_pitch_mm(spec, shot);
    let depth = if far.is_finite() { format!("{near:.2}–{far:.2} m") } else { format!("{near:.2} m–∞") };
    if coc_px <= spec.tolerance_px {
        ModelChoice {
            model: LensModel::Pinhole,
            reason: format!(
                "pinhole: the largest circle of confusion over the scene's depths ({depth}) is {coc_px:.3} px ≤ {} px",
                spec.tolerance_px
            ),
            candidates: Vec::new(),
        }
    } else {
        ModelChoice { model: LensModel::Thin, reason: format!("thin lens: circles of confusion reach {coc_px:.1} px over {depth} (> {} px), and an ideal lens has no aberrations to model", spec.tolerance_px), candidates: Vec::new() }
    }
}

/// Where one model's rays from one film point land: per surface, weighted sums.
#[derive(Debug, Clone, Copy, Default)]
struct Landing {
    weight: f64,
    sum: [DVec3; 3],
    sum_sq: [f64; 3],
    w: [f64; 3],
}

impl Landing {
    fn add(&mut self, k: usize, p: DVec3, w: f64) {
        self.sum[k] += p * w;
        self.sum_sq[k] += p.length_squared() * w;
        self.w[k] += w;
    }

    /// Centroid and RMS radius on surface `k`.
    fn stats(&self, k: usize) -> Option<(DVec3, f64)> {
        (self.w[k] > 0.0).then(|| {
            let c = self.sum[k] / self.w[k];
            (c, (self.sum_sq[k] / self.w[k] - c.length_squared()).max(0.0).sqrt())
        })
    }
}

/// The surfaces rays are followed to: planes perpendicular to the axis at the focus distance
/// and at the nearest scene depth, and infinity.
struct Surfaces {
    focus_m: Option<f64>,
    near_m: f64,
}

impl Surfaces {
    /// Landing points of a camera-space ray: focus plane, near plane, infinity (direction
    /// slope). None where it does not reach that surface.
    fn land(&self, o: DVec3, d: DVec3) -> [Option<DVec3>; 3] {
        let at = |z: f64| (d.z < -1e-9).then(|| o + d * ((-z - o.z) / d.z));
        let inf = (d.z < -1e-9).then(|| DVec3::new(d.x / -d.z, d.y / -d.z, 0.0));
        [self.focus_m.and_then(at), at(self.near_m), inf]
    }
}

/// Follows `RAYS_PER_POINT` rays per film point through `camera` at `wavelength_nm`; returns the
/// landings per film point and the measured ns per ray.
fn measure(camera: &Camera, surfaces: &Surfaces, film_points: &[DVec2], wavelength_nm: f64) -> Vec<Landing> {
    let mut out = Vec::with_capacity(film_points.len());
    for (i, &film) in film_points.iter().enumerate() {
        let mut l = Landing::default();
        for s in 0..RAYS_PER_POINT {
            let seed = 0x5EED_0000 ^ i as u32;
            let u = DVec2::new(sobol_burley::sample(s, 0, seed) as f64, sobol_burley::sample(s, 1, seed) as f64);
            let Some(ray) = camera.generate_ray(film, u, wavelength_nm) else { continue };
            l.weight += ray.weight;
            for (k, p) in surfaces.land(ray.origin, ray.direction).into_iter().enumerate() {
                if let Some(p) = p {
                    l.add(k, p, ray.weight);
                }
            }
        }
        l.weight /= RAYS_PER_POINT as f64;
        out.push(l);
    }
    out
}

/// Nominal bake cost (ns of one core) of a table: about five exact traces per entry.
fn nominal_bake_ns(resolution: u32, wavelengths: usize, surfaces: usize) -> f64 {
    let n = resolution as f64;
    n * n * (n / 2.0 + 1.0) * wavelengths as f64 * 5.0 * LensModel::Exact.nominal_ns_per_ray(surfaces)
}

/// Errors of `model` against `exact` (pixels per film point, irradiance difference).
fn compare(model: &[Landing], exact: &[Landing], footprint: &dyn Fn(usize, DVec3) -> f64) -> (Vec<f64>, f64) {
    let mut errs = Vec::with_capacity(exact.len());
    let mut irr: f64 = 0.0;
    let centre_irradiance = exact.iter().map(|l| l.weight).fold(0.0, f64::max).max(1e-12);
    for (m, e) in model.iter().zip(exact) {
        irr = irr.max((m.weight - e.weight).abs() / centre_irradiance);
        let mut err: f64 = 0.0;
        for k in 0..3 {
            match (m.stats(k), e.stats(k)) {
                (Some((cm, rm)), Some((ce, re))) => {
                    err = err.max(((cm - ce).length() + (rm - re).abs()) / footprint(k, ce))
                }
                (None, None) => {}
                // Light in one model and none in the other: as wrong as it gets.
                _ => err = f64::INFINITY,
            }
        }
        errs.push(err);
    }
    (errs, irr)
}

fn choose_real(spec: &CameraSpec, lens: &SpecLens, shot: &ShotContext) -> Result<(ModelChoice, Option<Camera>)> {
    let SpecLens::Real(real) = lens else { return Err(Error::Internal("choose_real takes a real lens".into())) };
    // 1. The reference: the exact camera, and the surfaces rays are followed to.
    let exact = build_model(spec, lens, LensModel::Exact, None, shot.spectral)?;
    let Camera::Exact(exact_cam) = &exact else {
        return Err(Error::Internal("the exact model of a real lens is not an exact camera".into()));
    };
    let mut cameras: Vec<(LensModel, Camera)> = Vec::new();
    let (near, _far) = shot.depth_range_m.unwrap_or(DEFAULT_DEPTH_RANGE_M);
    let surfaces = Surfaces { focus_m: spec.focus_distance_m, near_m: near.max(1e-3) };
    let (gx, gy) = GRID;
    let film_points: Vec<DVec2> = (0..gy)
        .flat_map(|j| {
            (0..gx).map(move |i| {
                DVec2::new(0.03 + 0.94 * i as f64 / (gx - 1) as f64, 0.03 + 0.94 * j as f64 / (gy - 1) as f64)
            })
        })
        .collect();
    let wavelengths: Vec<f64> = if shot.spectral && real.has_dispersion() {
        real.wavelengths_nm().to_vec()
    } else {
        vec![real.primary_wavelength_nm()]
    };
    let primary = real.primary_wavelength_nm();
    let exact_landings: Vec<Vec<Landing>> =
        wavelengths.iter().map(|&w| measure(&exact, &surfaces, &film_points, w)).collect();
    let n_surfaces = real.surfaces().len();
    let exact_ns = LensModel::Exact.nominal_ns_per_ray(n_surfaces);
    let table_wavelengths = if real.has_dispersion() { real.wavelengths_nm().len().max(1) } else { 1 };
    // Pixel footprint: pitch / f per metre of distance (planes), pitch / f radians (infinity).
    let angle_per_px = pixel_pitch_mm(spec, shot) / real.paraxial().efl_mm;
    let footprint = move |k: usize, c: DVec3| if k == 2 { angle_per_px } else { angle_per_px * c.length().max(1e-6) };
    let camera_rays = shot.width as f64 * shot.height as f64 * shot.spp.max(1) as f64;
    // Seconds of one core (bake and render parallelise alike).
    let render_seconds = |ns: f64| camera_rays * ns * 1e-9;
    // 2. Candidates, cheapest first.
    let mut reports: Vec<CandidateReport> = Vec::new();
    let mut lrtf_met = false;
    for model in LensModel::AUTO_CANDIDATES {
        let mut report = CandidateReport {
            model,
            max_error_px: f64::INFINITY,
            mean_error_px: f64::INFINITY,
            irradiance_error: f64::INFINITY,
            ns_per_ray: f64::NAN,
            setup_seconds: 0.0,
            estimated_seconds: f64::INFINITY,
            meets: false,
            note: String::new(),
        };
        let mut setup = 0.0;
        if let LensModel::Lrtf { resolution } = model {
            if lrtf_met {
                continue;
            }
            if !real.is_rotationally_symmetric() {
                report.note = "not applicable: the lens is not rotationally symmetric".into();
                reports.push(report);
                continue;
            }
            // Bake only when the table can pay off.
            setup = nominal_bake_ns(resolution, table_wavelengths, n_surfaces) * 1e-9;
            if setup + render_seconds(model.nominal_ns_per_ray(n_surfaces)) >= render_seconds(exact_ns) {
                report.setup_seconds = setup;
                report.note = format!(
                    "not baked: its bake (est. {setup:.2} s) costs more than it saves on {:.2e} camera rays",
                    camera_rays
                );
                reports.push(report);
                continue;
            }
            if let Err(e) = cached_lrtf(real, resolution) {
                report.note = format!("not applicable: {e}");
                reports.push(report);
                continue;
            }
        }
        let camera = match build_model(spec, lens, model, Some(exact_cam), shot.spectral) {
            Ok(c) => c,
            Err(e) => {
                report.note = format!("not applicable: {e}");
                reports.push(report);
                continue;
            }
        };
        // 3. Error against the exact trace at every wavelength that matters.
        let mut errs = vec![0.0f64; film_points.len()];
        let mut irr: f64 = 0.0;
        for (wi, &w) in wavelengths.iter().enumerate() {
            // Pinhole, thin and thick lenses have no dispersion: they render every
            // wavelength like the primary one.
            let w_model = if matches!(model, LensModel::Lrtf { .. }) { w } else { primary };
            let l = measure(&camera, &surfaces, &film_points, w_model);
            let (e, i) = compare(&l, &exact_landings[wi], &footprint);
            for (a, b) in errs.iter_mut().zip(e) {
                *a = a.max(b);
            }
            irr = irr.max(i);
        }
        report.max_error_px = errs.iter().cloned().fold(0.0, f64::max);
        report.mean_error_px = errs.iter().sum::<f64>() / errs.len() as f64;
        report.irradiance_error = irr;
        report.ns_per_ray = model.nominal_ns_per_ray(n_surfaces);
        report.setup_seconds = setup;
        report.estimated_seconds = setup + render_seconds(report.ns_per_ray);
        report.meets = report.mean_error_px <= spec.tolerance_px
            && report.max_error_px <= MAX_OVER_MEAN_BUDGET * spec.tolerance_px
            && irr <= IRRADIANCE_TOLERANCE;
        if !report.meets {
            report.note = if report.mean_error_px > spec.tolerance_px {
                format!("mean error {:.3} px > {} px", report.mean_error_px, spec.tolerance_px)
            } else if report.max_error_px > MAX_OVER_MEAN_BUDGET * spec.tolerance_px {
                format!(
                    "largest error {:.3} px > {} × {} px",
                    report.max_error_px, MAX_OVER_MEAN_BUDGET, spec.tolerance_px
                )
            } else {
                format!("vignetting differs by {:.1} % (> {:.0} %)", irr * 100.0, IRRADIANCE_TOLERANCE * 100.0)
            };
        }
        if report.meets && matches!(model, LensModel::Lrtf { .. }) {
            lrtf_met = true;
        }
        if report.meets {
            cameras.push((model, camera));
        }
        reports.push(report);
    }
    let exact_report = CandidateReport {
        model: LensModel::Exact,
        max_error_px: 0.0,
        mean_error_px: 0.0,
        irradiance_error: 0.0,
        ns_per_ray: exact_ns,
        setup_seconds: 0.0,
        estimated_seconds: render_seconds(exact_ns),
        meets: true,
        note: String::new(),
    };
    reports.push(exact_report);
    // 4. The cheapest that meets the budget.
    let best = reports
        .iter()
        .filter(|r| r.meets)
        .min_by(|a, b| a.estimated_seconds.total_cmp(&b.estimated_seconds))
        .or(reports.last())
        .cloned()
        .ok_or_else(|| Error::Internal("no candidate model (exact is always one)".into()))?;
    let best_index = reports.iter().position(|r| r.model == best.model).unwrap_or(reports.len());
    let cheaper_failed: Vec<String> =
        reports[..best_index].iter().filter(|r| !r.meets).map(|r| format!("{} ({})", r.model, r.note)).collect();
    let reason = match best.model {
        LensModel::Exact => format!(
            "exact: nothing cheaper stays within {} px at {}x{}: {}",
            spec.tolerance_px,
            shot.width,
            shot.height,
            if cheaper_failed.is_empty() { "every faster model costs more here".to_string() } else { cheaper_failed.join("; ") }
        ),
        m => format!(
            "{m}: mean error {:.3} px ≤ {} px at {}x{} (largest {:.3} px), vignetting within {:.1} %, est. {:.2} core-s of camera rays vs {:.2} exact{}",
            best.mean_error_px,
            spec.tolerance_px,
            shot.width,
            shot.height,
            best.max_error_px,
            best.irradiance_error * 100.0,
            best.estimated_seconds,
            render_seconds(exact_ns),
            if cheaper_failed.is_empty() { String::new() } else { format!("; cheaper ones fail: {}", cheaper_failed.join("; ")) }
        ),
    };
    let camera = if best.model == LensModel::Exact {
        Some(exact)
    } else {
        cameras.into_iter().find(|(m, _)| *m == best.model).map(|(_, c)| c)
    };
    Ok((ModelChoice { model: best.model, reason, candidates: reports }, camera))
}
