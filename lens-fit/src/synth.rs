//! Synthetic captures for tests and the benchmark: a point source rendered by our own tracer
//! (a denser ray pattern than a fit uses, its own density footprint), photon noise (normal
//! approximation, deterministic) on a dark level, written as EXR or 16-bit PNG with the
//! manifest that fits them.
//!
//! | option | what | default |
//! |---|---|---|
//! | `rays` | rays of the rendering | 120 000 |
//! | `peak_photons` | mean photons at the spot's peak | 20 000 |
//! | `dark` | dark level added (not subtracted) | 100 |
//! | `png16` | write 16-bit PNG (values clipped at 65535) instead of EXR | false |
//! | `hot_pixels` | (x, y, value) set after the noise | none |

use crate::error::{Error, Result};
use crate::forward::{land, splat, Aim, Frame, Geometry, Pattern};
use crate::manifest::{DistancesFrom, SensorSpec};
use crate::params::Model;
use glam::DVec2;
use std::path::{Path, PathBuf};

/// A deterministic photon count (normal approximation, Box–Muller on SplitMix64).
#[derive(Debug, Clone)]
pub struct Noise(pub u64);

impl Noise {
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// A photon count of mean `mean`.
    pub fn photons(&mut self, mean: f64) -> f64 {
        let (u1, u2) = (self.uniform().max(1e-300), self.uniform());
        let g = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
        (mean + g * mean.max(0.0).sqrt()).max(0.0)
    }
}

/// One capture to render.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shot {
    /// Source position (m, from the sensor).
    pub source_m: [f64; 3],
    /// Focus distance (m, from the sensor).
    pub focus_m: f64,
    /// Working f-number; 0 (or less): the stop fully open (the manifest's `"open"`).
    pub f_number: f64,
}

/// How to render (see the module's table).
#[derive(Debug, Clone, PartialEq)]
pub struct SynthOptions {
    /// Rays of the rendering.
    pub rays: usize,
    /// Mean photons at the peak.
    pub peak_photons: f64,
    /// Dark level.
    pub dark: f64,
    /// 16-bit PNG instead of EXR.
    pub png16: bool,
    /// Hot pixels (x, y, value), per capture.
    pub hot_pixels: Vec<(usize, usize, f64)>,
    /// Noise seed.
    pub seed: u64,
}

impl Default for SynthOptions {
    fn default() -> Self {
        SynthOptions {
            rays: 120_000,
            peak_photons: 20_000.0,
            dark: 100.0,
            png16: false,
            hot_pixels: Vec::new(),
            seed: 7,
        }
    }
}

/// Renders `truth` for each shot into `dir` (size × size crops around the spot) and writes
/// `manifest.toml` starting from the library lens `start` with the `[[free]]` tables `free`.
/// Returns the manifest's path; errors name what could not be rendered or written.
pub fn write_captures(
    dir: &Path,
    start: &str,
    truth: &Model,
    shots: &[Shot],
    free: &str,
    size: usize,
    options: &SynthOptions,
) -> Result<PathBuf> {
    let sensor = SensorSpec { width_mm: 36.0, height_mm: 24.0, pixels: [6000, 4000] };
    let lens = petzval_optics::Lens::new(
        truth.prescription.clone(),
        &petzval_optics::prescription::SourceMap::new("truth", vec![]),
        None,
    )?;
    let image_err = |path: PathBuf, message: String| Error::Image { path, message };
    let pattern = Pattern::spiral(options.rays);
    let mut manifest = format!(
        "[lens]\nstart = \"{start}\"\n\n[sensor]\nwidth_mm = 36.0\nheight_mm = 24.0\npixels = [6000, 4000]\n\n"
    );
    manifest.push_str(free);
    let mut noise = Noise(options.seed);
    for (i, s) in shots.iter().enumerate() {
        let l = if s.f_number > 0.0 {
            lens.stopped_down(s.f_number)?
        } else {
            lens.with_stop_semi_diameter(lens.max_stop_semi_diameter_mm())?
        };
        let f_number = if s.f_number > 0.0 { s.f_number.to_string() } else { "\"open\"".to_string() };
        let g = Geometry::new(&l, &truth.camera, s.source_m, s.focus_m, DistancesFrom::Sensor)?;
        let aim = Aim::find(&l, g.source_mm, 550.0).ok_or_else(|| {
            Error::manifest(
                dir.display().to_string(),
                format!("shot {}", i + 1),
                "the source is outside the lens's field",
            )
        })?;
        // where the spot lands on the full sensor: crop around it
        let full = Frame { sensor, crop_origin_px: [0, 0], width: 1, height: 1 };
        let landing = land(&l, &truth.camera, None, &g, &aim, &pattern, 550.0, &full);
        let w: f64 = landing.weights.iter().sum();
        let c = landing.positions_px.iter().zip(&landing.weights).fold(DVec2::ZERO, |a, (p, wt)| a + *p * *wt) / w;
        let origin = [(c.x - size as f64 / 2.0).round() as i64 + 1, (c.y - size as f64 / 2.0).round() as i64 - 1];
        let frame = Frame { sensor, crop_origin_px: origin, width: size, height: size };
        let landing = land(&l, &truth.camera, None, &g, &aim, &pattern, 550.0, &frame);
        let img = splat(&landing, DVec2::ZERO, 0.0, size, size);
        let peak = img.iter().copied().fold(0.0, f64::max);
        let mut values: Vec<f64> =
            img.iter().map(|v| noise.photons(options.dark + options.peak_photons * v / peak)).collect();
        for &(x, y, v) in &options.hot_pixels {
            values[y * size + x] = v;
        }
        let name = if options.png16 { format!("c{:02}.png", i + 1) } else { format!("c{:02}.exr", i + 1) };
        if options.png16 {
            let buf = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(size as u32, size as u32, |x, y| {
                image::Luma([values[y as usize * size + x as usize].round().clamp(0.0, 65535.0) as u16])
            });
            buf.save(dir.join(&name)).map_err(|e| image_err(dir.join(&name), e.to_string()))?;
        } else {
            exr::prelude::write_rgb_file(dir.join(&name), size, size, |x, y| {
                let v = values[y * size + x] as f32;
                (v, v, v)
            })
            .map_err(|e| image_err(dir.join(&name), e.to_string()))?;
        }
        manifest.push_str(&format!(
            "[[capture]]\nimage = \"{name}\"\ncrop_origin_px = [{}, {}]\nsource_m = [{}, {}, {}]\nfocus_m = {}\nf_number = {}\nwavelength_nm = 550\n\n",
            origin[0], origin[1], s.source_m[0], s.source_m[1], s.source_m[2], s.focus_m, f_number
        ));
    }
    let path = dir.join("manifest.toml");
    std::fs::write(&path, manifest).map_err(|e| Error::Io { path: path.clone(), source: e })?;
    Ok(path)
}
