//! The fit: the free parameters (scaled to [0, 1] within their bounds) and each capture's
//! sub-pixel position, found by a global NLopt stage (CRS2), a local one (BOBYQA) and a
//! Levenberg–Marquardt refinement of the residual vector; each capture's intensity scale and
//! background are solved in closed form at every evaluation (linear least squares).
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `time_limit_s` | f64: the whole fit | s | 60 |
//! | `rays` | traced rays per wavelength per capture (a grid's corners on the pupil disc) | — | 8 192 |
//! | `subsamples` | points per grid cell side, interpolated from the cell's traced corners, twice as many near a rim (`forward::Pattern::Grid`); 0 = a spiral of `rays` points, each traced | — | 2 |
//! | `footprint_px` | ray footprint on the sensor (0: from the ray density) | px | 0 |
//! | `global_share` | share of the time for the global stage (0 skips it) | — | 0.35 |
//! | `local_share` | share of the time for the local stage (0 skips it) | — | 0.3 |
//! | `global_rays` | rays per wavelength per capture in the global stage (0: `rays / 4`, at least 2048) | — | 0 |
//! | `global_footprint_px` | ray footprint of the global stage (0: as the fit's) | px | 0 |
//! | `local_rays` | rays per wavelength per capture in the local stage (0: `rays`) | — | 0 |
//! | `shift_steps` | Gauss–Newton steps on each capture's shift in every global/local evaluation (0: the centroid-matching shift) | — | 2 |
//! | `max_evaluations` | objective evaluations of the whole fit (0: no bound, the time limit alone) | — | 0 |
//! | `starts` | local (BOBYQA) starts from the global stage's best mutually distinct points | — | 3 |
//! | `stop` | a flag that, once set (by the command's interrupt handler), ends the fit at its next evaluation with the best point so far: no further stage, no new Jacobian for the uncertainties | — | none |
//! | `central_differences` | Levenberg–Marquardt's parameter Jacobian by central differences from the start (two evaluations per parameter: narrow valleys, e.g. several coupled radii, need them); false: forward differences until two poor steps, then central | bool | true |
//!
//! The whole fit keeps to `time_limit_s`: CRS2 35 %, BOBYQA 30 %, Levenberg–Marquardt computes
//! no Jacobian or step that would leave too little time before the limit for the uncertainty
//! stage's Jacobian (which it always computes, at the end point). `max_evaluations`
//! is split over the stages by the same shares; with it (and a time limit that is not reached)
//! a fit's end point does not depend on the machine's speed, load or thread count.
//!
//! Residuals: for every unmasked pixel k of capture c and channel, `(d_k − a·m_k − b) / ‖d − b‖`
//! with the capture's fitted scale a and background b, so each capture weighs the same. During
//! the global and local stages each capture's shift starts as the one that puts the model's
//! centroid on the measured one and takes `shift_steps` Gauss–Newton steps (`solve::
//! profiled_objective`; [`Problem::objective`] is the centroid-only form);
//! Levenberg–Marquardt then fits the shifts with the parameters.

use crate::captures::{self, CaptureImage};
use crate::correction::{Basis, Correction};
use crate::error::{Error, Result};
use crate::forward::{land, splat, Aim, Frame, Geometry, Landing, Pattern};
use crate::manifest::{Capture, FNumber, FreeParam, Manifest, Wavelength};
use crate::params::Model;
use glam::DVec2;
use petzval_optics::lrtf::{BakeOptions, LrtfTable};
use petzval_optics::prescription::SourceMap;
use petzval_optics::Lens;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// Fit settings (see the module's table).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitOptions {
    /// Wall-clock budget of the whole fit.
    pub time_limit_s: f64,
    /// Rays per wavelength per capture.
    pub rays: usize,
    /// Points per grid cell side (0: a spiral, every point traced).
    pub subsamples: usize,
    /// Ray footprint on the sensor.
    pub footprint_px: f64,
    /// Share of the time for the global stage.
    pub global_share: f64,
    /// Share of the time for the local stage (0 skips it).
    pub local_share: f64,
    /// Rays of the global stage (0: from `rays`).
    pub global_rays: usize,
    /// Ray footprint of the global stage (0: as the fit's).
    pub global_footprint_px: f64,
    /// Rays of the local stage (0: `rays`).
    pub local_rays: usize,
    /// Gauss–Newton steps on each capture's shift per global/local evaluation.
    pub shift_steps: usize,
    /// Objective evaluations of the whole fit, split over the stages by the time's shares
    /// (0: unbounded).
    pub max_evaluations: usize,
    /// Local starts from the global stage's best mutually distinct points.
    pub starts: usize,
    /// Levenberg–Marquardt's parameter Jacobian by central differences from the start (twice
    /// the cost); false: forward differences until they prove poor, then central.
    pub central_differences: bool,
    /// Set from outside (an interrupt) to end the fit early with the best point so far.
    pub stop: StopFlag,
}

/// A flag that asks a running fit to stop at its next evaluation (see [`FitOptions::stop`]).
#[derive(Debug, Clone, Copy, Default)]
pub struct StopFlag(Option<&'static AtomicBool>);

impl StopFlag {
    /// A stop flag watching `flag` (set it to request the stop).
    pub fn new(flag: &'static AtomicBool) -> StopFlag {
        StopFlag(Some(flag))
    }

    /// Whether the stop has been requested.
    pub fn requested(&self) -> bool {
        self.0.is_some_and(|f| f.load(Ordering::SeqCst))
    }
}

impl PartialEq for StopFlag {
    fn eq(&self, other: &StopFlag) -> bool {
        match (self.0, other.0) {
            (Some(a), Some(b)) => std::ptr::eq(a, b),
            (a, b) => a.is_none() && b.is_none(),
        }
    }
}

impl FitOptions {
    /// Rays per wavelength per capture of the global stage.
    pub fn global_rays(&self) -> usize {
        if self.global_rays > 0 {
            self.global_rays
        } else {
            (self.rays / 4).max(2048).min(self.rays)
        }
    }
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            time_limit_s: 60.0,
            rays: crate::forward::DEFAULT_RAYS,
            subsamples: crate::forward::DEFAULT_SUBSAMPLES,
            footprint_px: 0.0,
            global_share: 0.35,
            local_share: 0.3,
            global_rays: 0,
            global_footprint_px: 0.0,
            local_rays: 0,
            shift_steps: 2,
            max_evaluations: 0,
            starts: 3,
            central_differences: true,
            stop: StopFlag::default(),
        }
    }
}

/// One capture ready to fit.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// From the manifest.
    pub capture: Capture,
    /// The image.
    pub image: CaptureImage,
    /// Where it sits on the sensor.
    pub frame: Frame,
    /// Wavelength of each channel.
    pub wavelengths_nm: Vec<f64>,
    /// Sampling disc of each channel (fixed for the fit).
    pub aims: Vec<Aim>,
    /// ‖d − median‖ over the mask, per channel (the residual's normaliser).
    pub norms: Vec<f64>,
    /// Measured centroid (pixels).
    pub centroid_px: DVec2,
}

/// The fitting problem: the captures, the start model and the free parameters.
#[derive(Debug, Clone)]
pub struct Problem {
    /// The manifest's name (for messages).
    pub file: String,
    /// The start model.
    pub start: Model,
    /// Where the start lens came from (for rebuilding).
    pub source_label: String,
    /// Free parameters.
    pub free: Vec<FreeParam>,
    /// Captures.
    pub captures: Vec<Prepared>,
    /// The fixed pupil pattern.
    pub pattern: Pattern,
    /// Ray footprint.
    pub footprint_px: f64,
    /// The LRTF correction's normalisation (from the start lens and the sensor).
    pub basis: Basis,
    /// How `--lrtf` bakes the fitted table (from `[lens] table`, else 96³ over the sensor).
    pub table_options: BakeOptions,
}

/// What one evaluation gives for one capture.
#[derive(Debug, Clone, PartialEq)]
pub struct CaptureFit {
    /// Model images per channel, with the fitted scale and background applied.
    pub model: Vec<Vec<f64>>,
    /// Fitted scale per channel.
    pub scale: Vec<f64>,
    /// Fitted background per channel.
    pub background: Vec<f64>,
    /// ‖d − model‖ / ‖d − background‖ over the unmasked pixels (all channels).
    pub residual: f64,
}

/// Model parameters from the scaled vector (values in [0, 1] → bounds; integers rounded).
pub fn unscale(free: &[FreeParam], x: &[f64]) -> Vec<f64> {
    free.iter()
        .zip(x)
        .map(|(f, u)| {
            let v = f.min + u.clamp(0.0, 1.0) * (f.max - f.min);
            if f.param.is_integer() {
                v.round()
            } else {
                v
            }
        })
        .collect()
}

impl Problem {
    /// Loads every capture of a manifest and prepares the fit from its start lens.
    pub fn new(manifest: &Manifest, options: &FitOptions) -> Result<Problem> {
        let file = manifest.file.display().to_string();
        let lens = petzval_optics::load_lens(&manifest.start_lens).map_err(|e| match e {
            // a lens that is not found is the manifest's field; a broken lens file names itself
            petzval_optics::Error::UnknownLens(_) => Error::manifest(&file, "lens.start", e.to_string()),
            other => other.into(),
        })?;
        let mut start = Model::new(lens.prescription().clone());
        for (i, f) in manifest.free.iter().enumerate() {
            let field = format!("free[{}].param", i + 1);
            let v = start.get(&f.param).map_err(|m| Error::manifest(&file, &field, m))?;
            // an explicit start is checked with the manifest; the lens's own value here
            if f.start.is_none() && !(v >= f.min && v <= f.max) {
                return Err(Error::manifest(
                    &file,
                    &field,
                    format!(
                        "'{}' starts at the start lens's value {v}, outside the bounds [{}, {}]: widen them or give a `start` inside",
                        f.name, f.min, f.max
                    ),
                ));
            }
            let v = f.start.unwrap_or(v);
            start.set(&f.param, v).map_err(|m| Error::manifest(&file, &field, m))?;
        }
        let mut problem = Problem {
            file: file.clone(),
            start,
            source_label: lens.source_label().to_string(),
            free: manifest.free.clone(),
            captures: Vec::new(),
            pattern: Pattern::for_fit(options.rays, options.subsamples),
            footprint_px: options.footprint_px,
            basis: Basis::new(&lens, 0.5 * manifest.sensor.width_mm.hypot(manifest.sensor.height_mm)),
            table_options: BakeOptions {
                max_film_radius_mm: 0.5 * manifest.sensor.width_mm.hypot(manifest.sensor.height_mm) * 1.05,
                ..BakeOptions::default()
            },
        };
        if let Some(path) = &manifest.start_table {
            // the start table must be the start lens's; the output table keeps its sampling
            let table = LrtfTable::load(path, &lens)
                .map_err(|e| Error::manifest(&file, "lens.table", format!("{}: {e}", path.display())))?;
            let h = &table.header;
            problem.table_options = BakeOptions {
                resolution: h.resolution,
                max_film_radius_mm: h.max_film_radius_mm,
                min_film_distance_mm: None,
                wavelengths_nm: Some(h.wavelengths_nm.clone()),
            };
        }
        let start_lens = problem.build_lens(&problem.start)?;
        for c in &manifest.captures {
            let field = |k: &str| format!("{}.{k}", c.label);
            let image = captures::load(c)?;
            let (w, h) = (image.width as i64, image.height as i64);
            let [ox, oy] = c.crop_origin_px;
            let [sw, sh] = manifest.sensor.pixels.map(|p| p as i64);
            if ox < 0 || oy < 0 || ox + w > sw || oy + h > sh {
                return Err(Error::manifest(
                    &file,
                    field("crop_origin_px"),
                    format!("a {w}×{h} image at ({ox}, {oy}) does not fit on the {sw}×{sh} sensor"),
                ));
            }
            let frame = Frame {
                sensor: manifest.sensor,
                crop_origin_px: c.crop_origin_px,
                width: image.width,
                height: image.height,
            };
            let wavelengths_nm = match c.wavelength {
                Wavelength::Mono(w) => vec![w],
                Wavelength::Rgb => rgb_wavelengths(&start_lens),
            };
            let lens =
                capture_lens(&start_lens, c).map_err(|e| Error::manifest(&file, field("f_number"), e.to_string()))?;
            let g = Geometry::new(&lens, &problem.start.camera, c.source_m, c.focus_m, c.distances_from)
                .map_err(|e| Error::manifest(&file, field("focus_m"), e.to_string()))?;
            let mut aims = Vec::new();
            for &wl in &wavelengths_nm {
                let aim = Aim::find(&lens, g.source_mm, wl).ok_or_else(|| {
                    Error::manifest(
                        &file,
                        field("source_m"),
                        format!(
                            "no light from {:?} m passes '{}': the source is outside the lens's field",
                            c.source_m,
                            lens.name()
                        ),
                    )
                })?;
                aims.push(aim);
            }
            let norms = image
                .channels
                .iter()
                .map(|p| {
                    let mut v: Vec<f64> = p.iter().zip(&image.mask).filter(|(_, m)| **m).map(|(v, _)| *v).collect();
                    v.sort_by(|a, b| a.total_cmp(b));
                    let median = v.get(v.len() / 2).copied().unwrap_or(0.0);
                    v.iter().map(|x| (x - median).powi(2)).sum::<f64>().sqrt()
                })
                .collect::<Vec<f64>>();
            if norms.iter().any(|n| !(*n > 0.0)) || image.mask.iter().all(|m| !m) {
                return Err(Error::manifest(&file, field("image"), "the image has no signal in its unmasked pixels"));
            }
            // a one-pixel spot is its pixel's centre (the percentile threshold below would be
            // set by the noise, whose light would pull the centroid off it)
            let centroid_px = match image.lone_spot {
                Some((x, y)) => DVec2::new(x as f64 + 0.5, y as f64 + 0.5),
                None => centroid(&image.channels, &image.mask, image.width),
            };
            problem.captures.push(Prepared {
                capture: c.clone(),
                image,
                frame,
                wavelengths_nm,
                aims,
                norms,
                centroid_px,
            });
        }
        Ok(problem)
    }

    /// The model at parameter values `values` (in the free parameters' order).
    pub fn model_at(&self, values: &[f64]) -> std::result::Result<Model, String> {
        let mut m = self.start.clone();
        for (f, v) in self.free.iter().zip(values) {
            m.set(&f.param, *v)?;
        }
        Ok(m)
    }

    /// Builds the lens of a model.
    pub fn build_lens(&self, model: &Model) -> petzval_optics::Result<Lens> {
        Lens::new(model.prescription.clone(), &SourceMap::new(self.source_label.clone(), vec![]), None)
    }

    /// Bakes the film → scene LRTF table of a fitted model for `lens` (the fitted lens as written
    /// to its file, so the table's hash matches what the renderer loads), with the model's
    /// correction applied to every outgoing ray (see [`crate::correction`]).
    pub fn bake_lrtf(&self, lens: &Lens, model: &Model) -> Result<LrtfTable> {
        let correction = self.correction(model);
        let map = |r: &petzval_optics::Ray| correction.as_ref().map_or(Some(*r), |c| c.correct_outgoing(r));
        let map: &petzval_optics::lrtf::OutgoingMap<'_> = &map;
        Ok(LrtfTable::bake_mapped(lens, &self.table_options, correction.is_some().then_some(map), &|_| {})?)
    }

    /// The model's LRTF correction (None when it has none).
    pub fn correction(&self, model: &Model) -> Option<Correction> {
        model.has_correction().then_some(Correction { basis: self.basis, coefficients: model.correction })
    }

    /// Where each capture's rays land (per channel) for a model; `None` where the lens cannot
    /// be built or set as the capture asks.
    pub fn landings(&self, model: &Model) -> Option<Vec<Vec<Landing>>> {
        let lens = self.build_lens(model).ok()?;
        let correction = self.correction(model);
        // captures in parallel (each traces its rays in parallel too); collect keeps the order
        self.captures
            .par_iter()
            .map(|p| {
                let lens = capture_lens(&lens, &p.capture).ok()?;
                let g = Geometry::new(
                    &lens,
                    &model.camera,
                    p.capture.source_m,
                    p.capture.focus_m,
                    p.capture.distances_from,
                )
                .ok()?;
                Some(
                    p.wavelengths_nm
                        .iter()
                        .zip(&p.aims)
                        .map(|(wl, aim)| {
                            land(&lens, &model.camera, correction.as_ref(), &g, aim, &self.pattern, *wl, &p.frame)
                        })
                        .collect(),
                )
            })
            .collect()
    }

    /// The centroid-matching shift of each capture (model centroid onto the measured one).
    pub fn centroid_shifts(&self, landings: &[Vec<Landing>]) -> Vec<DVec2> {
        landings
            .iter()
            .zip(&self.captures)
            .map(|(l, p)| {
                let (mut s, mut w) = (DVec2::ZERO, 0.0);
                for ch in l {
                    for (q, wt) in ch.positions_px.iter().zip(&ch.weights) {
                        s += *q * *wt;
                        w += wt;
                    }
                }
                if w > 0.0 {
                    p.centroid_px - s / w
                } else {
                    DVec2::ZERO
                }
            })
            .collect()
    }

    /// One capture's model, fitted scale and background, and residual.
    pub fn fit_capture(&self, index: usize, landing: &[Landing], shift: DVec2) -> CaptureFit {
        let p = &self.captures[index];
        let (w, h) = (p.image.width, p.image.height);
        let mut out = CaptureFit { model: Vec::new(), scale: Vec::new(), background: Vec::new(), residual: 0.0 };
        let (mut num, mut den) = (0.0, 0.0);
        for (c, l) in landing.iter().enumerate() {
            let m = splat(l, shift, self.footprint_px, w, h);
            let d = &p.image.channels[c];
            // d ≈ a·m + b over the mask: 2×2 normal equations
            let (mut n, mut sm, mut sd, mut smm, mut smd) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for k in 0..w * h {
                if p.image.mask[k] {
                    n += 1.0;
                    sm += m[k];
                    sd += d[k];
                    smm += m[k] * m[k];
                    smd += m[k] * d[k];
                }
            }
            let det = n * smm - sm * sm;
            let (a, b) = if det.abs() > 1e-300 {
                ((n * smd - sm * sd) / det, (smm * sd - sm * smd) / det)
            } else {
                (0.0, sd / n)
            };
            let model: Vec<f64> = m.iter().map(|v| a * v + b).collect();
            for k in 0..w * h {
                if p.image.mask[k] {
                    num += (d[k] - model[k]).powi(2);
                    den += (d[k] - b).powi(2);
                }
            }
            out.model.push(model);
            out.scale.push(a);
            out.background.push(b);
        }
        out.residual = if den > 0.0 { (num / den).sqrt() } else { f64::INFINITY };
        out
    }

    /// The residual vector (see the module docs) for landings and shifts; a capture whose
    /// landing is missing counts as a model showing nothing.
    pub fn residual_vector(&self, landings: Option<&[Vec<Landing>]>, shifts: &[DVec2]) -> Vec<f64> {
        let mut r = Vec::new();
        for (i, p) in self.captures.iter().enumerate() {
            let n = p.image.width * p.image.height;
            match landings {
                Some(l) => {
                    let f = self.fit_capture(i, &l[i], shifts[i]);
                    for (c, model) in f.model.iter().enumerate() {
                        let d = &p.image.channels[c];
                        for k in 0..n {
                            if p.image.mask[k] {
                                r.push((d[k] - model[k]) / p.norms[c]);
                            }
                        }
                    }
                }
                None => {
                    for (c, d) in p.image.channels.iter().enumerate() {
                        let mean = d.iter().zip(&p.image.mask).filter(|(_, m)| **m).map(|(v, _)| *v).sum::<f64>()
                            / p.image.mask.iter().filter(|m| **m).count() as f64;
                        for (dk, _) in d.iter().zip(&p.image.mask).filter(|(_, m)| **m) {
                            r.push((dk - mean) / p.norms[c]);
                        }
                    }
                }
            }
        }
        r
    }

    /// The objective of the global and local stages: Σ r² with centroid-matched shifts.
    pub fn objective(&self, scaled: &[f64]) -> f64 {
        let values = unscale(&self.free, scaled);
        let Ok(model) = self.model_at(&values) else { return self.captures.len() as f64 * 4.0 };
        match self.landings(&model) {
            Some(l) => {
                let shifts = self.centroid_shifts(&l);
                self.residual_vector(Some(&l), &shifts).iter().map(|v| v * v).sum()
            }
            None => self.captures.len() as f64 * 4.0,
        }
    }
}

/// The lens as a capture sets it: stopped to its f-number, or fully open.
fn capture_lens(lens: &Lens, capture: &Capture) -> petzval_optics::Result<Lens> {
    match capture.f_number {
        FNumber::Stopped(n) => lens.stopped_down(n),
        FNumber::Open => lens.with_stop_semi_diameter(lens.max_stop_semi_diameter_mm()),
    }
}

/// R, G, B wavelengths: the lens's design wavelengths, longest first (C, d, F by default).
fn rgb_wavelengths(lens: &Lens) -> Vec<f64> {
    let mut w = lens.wavelengths_nm().to_vec();
    w.sort_by(|a, b| b.total_cmp(a));
    if w.len() >= 3 {
        vec![w[0], w[w.len() / 2], w[w.len() - 1]]
    } else {
        vec![656.2725, 587.5618, 486.1327]
    }
}

/// Light-weighted centroid (pixels, x right, y down) of the unmasked pixels that stand out of
/// the background: over the 10th percentile b by more than 2 % of (the 99.9th percentile − b),
/// weighted by their value over b. (Weighting every pixel above the median let the background's
/// noise pull the centroid towards the image centre, by ~0.1–1 px at 128² px; a threshold from
/// the median fails when a defocused disc covers most of the image.) A capture whose spot is one
/// pixel (`CaptureImage::lone_spot`) takes that pixel's centre instead.
fn centroid(channels: &[Vec<f64>], mask: &[bool], width: usize) -> DVec2 {
    let (mut s, mut w) = (DVec2::ZERO, 0.0);
    for p in channels {
        let mut v: Vec<f64> = p.iter().zip(mask).filter(|(_, m)| **m).map(|(v, _)| *v).collect();
        v.sort_by(|a, b| a.total_cmp(b));
        let quantile = |q: f64| v.get(((v.len() as f64 - 1.0) * q).round() as usize).copied().unwrap_or(0.0);
        let (background, peak) = (quantile(0.1), quantile(0.999));
        let threshold = background + 0.02 * (peak - background);
        for (k, val) in p.iter().enumerate() {
            if mask[k] && *val > threshold {
                let q = DVec2::new((k % width) as f64 + 0.5, (k / width) as f64 + 0.5);
                s += q * (val - background);
                w += val - background;
            }
        }
    }
    if w > 0.0 {
        s / w
    } else {
        DVec2::ZERO
    }
}

/// Wall-clock since `start`, in seconds.
pub fn elapsed_s(start: Instant) -> f64 {
    start.elapsed().as_secs_f64()
}
