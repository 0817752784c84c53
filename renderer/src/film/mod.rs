//! The film: per-pixel f32 accumulation of radiance, alpha and first-hit AOVs (depth, normal,
//! albedo), with the pixel filter applied by filter importance sampling (each sample's position
//! is drawn from the filter, as Cycles does), so a sample only touches its own pixel and the
//! image does not depend on the thread count.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `filter` | [`PixelFilter`] | — | Blackman–Harris spanning 3 px (Cycles' default `filter_width` 1.5, which Cycles doubles for this filter) |

pub mod metrics;
mod output;
mod window;

pub use output::{write_exr, write_exr_framed, write_png, ExrFrame, ExrLayers, Metadata, ToneMap};
pub use window::{PixelWindow, MAX_OVERSCAN_FRAMES};

use glam::{Vec2, Vec3};

/// The reconstruction filter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PixelFilter {
    /// Box of the given width in pixels.
    Box {
        /// Width in pixels.
        width_px: f32,
    },
    /// Blackman–Harris of the given total width (support) in pixels. Cycles' `filter_width`
    /// w corresponds to a support of 2w.
    BlackmanHarris {
        /// Total width (support) in pixels.
        width_px: f32,
    },
}

impl Default for PixelFilter {
    fn default() -> Self {
        PixelFilter::BlackmanHarris { width_px: 3.0 }
    }
}

/// Tabulated inverse CDF for filter importance sampling (separable filters).
#[derive(Debug, Clone)]
pub struct FilterSampler {
    inverse_cdf: Vec<f32>,
    width_px: f32,
    /// Per bin b of [0, 1] (`PDF_BINS` bins): how many knots of `inverse_cdf` are ≤ b / PDF_BINS,
    /// where [`FilterSampler::pdf_1d`]'s count of knots ≤ v starts for v in the bin.
    knots_below: Vec<u32>,
    /// Density (per px) of each segment between knots, as `pdf_1d` gives it.
    segment_pdf: Vec<f32>,
}

/// Bins of the lookup that finds a filter offset's segment without a binary search.
const PDF_BINS: usize = 1024;

impl FilterSampler {
    /// Tabulates the filter.
    pub fn new(filter: PixelFilter) -> Self {
        let (width, f): (f32, Box<dyn Fn(f32) -> f32>) = match filter {
            PixelFilter::Box { width_px } => (width_px, Box::new(|_| 1.0)),
            PixelFilter::BlackmanHarris { width_px } => (
                width_px,
                Box::new(|x: f32| {
                    // x in [0, 1] across the window
                    let t = 2.0 * std::f32::consts::PI * x;
                    0.35875 - 0.48829 * t.cos() + 0.14128 * (2.0 * t).cos() - 0.01168 * (3.0 * t).cos()
                }),
            ),
        };
        // 1. CDF over [0, 1] of the 1-D profile.
        let n = 1024;
        let mut cdf = vec![0.0f64; n + 1];
        for i in 0..n {
            let x = (i as f32 + 0.5) / n as f32;
            cdf[i + 1] = cdf[i] + f(x).max(0.0) as f64;
        }
        let total = cdf[n];
        // 2. Invert on a regular grid of probabilities.
        let m = 256;
        let mut inverse_cdf = Vec::with_capacity(m + 1);
        let mut j = 0;
        for k in 0..=m {
            let p = total * k as f64 / m as f64;
            while j < n && cdf[j + 1] < p {
                j += 1;
            }
            let seg = (cdf[j + 1] - cdf[j]).max(1e-300);
            let frac = ((p - cdf[j]) / seg).clamp(0.0, 1.0);
            inverse_cdf.push(((j as f64 + frac) / n as f64) as f32);
        }
        // 3. The density lookup: knots below each bin's start, and each segment's density.
        let knots_below =
            (0..PDF_BINS).map(|b| inverse_cdf.partition_point(|&a| a <= b as f32 / PDF_BINS as f32) as u32).collect();
        let segment_pdf = inverse_cdf
            .windows(2)
            .map(|k| {
                let dv = k[1] - k[0];
                if dv > 0.0 {
                    1.0 / ((inverse_cdf.len() - 1) as f32 * dv * width)
                } else {
                    0.0
                }
            })
            .collect();
        FilterSampler { inverse_cdf, width_px: width, knots_below, segment_pdf }
    }

    fn sample_1d(&self, u: f32) -> f32 {
        let m = (self.inverse_cdf.len() - 1) as f32;
        let x = (u.clamp(0.0, 1.0) * m).min(m - 1e-4);
        let i = x as usize;
        let f = x - i as f32;
        let v = self.inverse_cdf[i] * (1.0 - f) + self.inverse_cdf[i + 1] * f;
        (v - 0.5) * self.width_px
    }

    /// Density (per px) of the offsets [`FilterSampler::sample`] draws along one axis, at `x`
    /// (px from the centre); the filter is separable, so [`FilterSampler::pdf`] is the product
    /// of two.
    pub fn pdf_1d(&self, x: f32) -> f32 {
        let v = x / self.width_px + 0.5;
        let inv = &self.inverse_cdf;
        if !(v >= inv[0] && v <= inv[inv.len() - 1]) {
            return 0.0;
        }
        // the segment i with inv[i] <= v < inv[i+1] (each holds probability 1/m): the count of
        // knots ≤ v, from the count at v's bin start on
        let bin = ((v * PDF_BINS as f32) as usize).min(PDF_BINS - 1);
        let mut below = self.knots_below[bin] as usize;
        while below < inv.len() && inv[below] <= v {
            below += 1;
        }
        let i = below.clamp(1, inv.len() - 1) - 1;
        self.segment_pdf[i]
    }

    /// Density (per px²) with which [`FilterSampler::sample`] draws offset `off` (px from the
    /// pixel centre): the effective pixel filter, for splatting light-path samples.
    pub fn pdf(&self, off: Vec2) -> f32 {
        self.pdf_1d(off.x) * self.pdf_1d(off.y)
    }

    /// Half the filter's width (px): offsets beyond it have zero density.
    pub fn radius_px(&self) -> f32 {
        0.5 * self.width_px
    }

    /// Offset from the pixel centre (pixels) for a sample `u` in [0,1)².
    pub fn sample(&self, u: Vec2) -> Vec2 {
        Vec2::new(self.sample_1d(u.x), self.sample_1d(u.y))
    }
}

/// One pixel's sums.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PixelSums {
    /// Σ radiance.
    pub rgb: Vec3,
    /// Σ radiance of the class-A samples (see [`crate::render::adaptive_class_a`]; adaptive
    /// sampling's error estimate).
    pub rgb_class_a: Vec3,
    /// Σ alpha × camera-ray weight, over the samples the lens let through.
    pub alpha: f32,
    /// Σ camera-ray weight of those samples (alpha = `alpha / alpha_weight`).
    pub alpha_weight: f32,
    /// Σ first-hit depth over samples that hit (metres).
    pub depth: f32,
    /// Number of samples that hit.
    pub hits: u32,
    /// Σ first-hit normals.
    pub normal: Vec3,
    /// Σ first-hit albedo.
    pub albedo: Vec3,
    /// Samples taken.
    pub samples: u32,
    /// Samples dropped as NaN/inf.
    pub dropped: u32,
}

// The memory estimate of `limits` counts these bytes per pixel.
const _: () = assert!(std::mem::size_of::<PixelSums>() as u64 == crate::limits::PIXEL_SUMS_BYTES);

/// The film.
#[derive(Debug, Clone)]
pub struct Film {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Row-major pixel sums, row 0 at the top.
    pub pixels: Vec<PixelSums>,
    /// Light-path splats (radiance sums; empty when no light paths are traced).
    pub splat: Vec<Vec3>,
    /// Scale of `splat` in the image (1 / the light paths' sample count: the samples done, or
    /// under adaptive sampling the light paths traced in samples' worth).
    pub splat_scale: f32,
}

/// A finished image: per-pixel means.
#[derive(Debug, Clone)]
pub struct Image {
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
    /// RGBA, row-major, top row first. Alpha is coverage: the share of the light reaching the
    /// pixel through the lens that comes from geometry (camera rays weighted as their radiance
    /// is; samples blocked inside the lens do not count), so `rgb = α·surface + (1 − α)·env`.
    pub rgba: Vec<[f32; 4]>,
    /// Depth: the first hit's distance along the camera's view axis (metres; planar, as Cycles'
    /// Z pass); +inf where nothing was hit.
    pub depth: Vec<f32>,
    /// First-hit normal.
    pub normal: Vec<[f32; 3]>,
    /// First-hit albedo.
    pub albedo: Vec<[f32; 3]>,
}

impl Film {
    /// An empty film.
    pub fn new(width: u32, height: u32) -> Self {
        Film {
            width,
            height,
            pixels: vec![PixelSums::default(); (width as usize) * (height as usize)],
            splat: Vec::new(),
            splat_scale: 0.0,
        }
    }

    /// Per-pixel means.
    pub fn image(&self) -> Image {
        let n = self.pixels.len();
        let mut img = Image {
            width: self.width,
            height: self.height,
            rgba: Vec::with_capacity(n),
            depth: Vec::with_capacity(n),
            normal: Vec::with_capacity(n),
            albedo: Vec::with_capacity(n),
        };
        for (i, p) in self.pixels.iter().enumerate() {
            let s = p.samples.max(1) as f32;
            let c = p.rgb / s + self.splat.get(i).map_or(Vec3::ZERO, |&v| v * self.splat_scale);
            let alpha = if p.alpha_weight > 0.0 { (p.alpha / p.alpha_weight).clamp(0.0, 1.0) } else { 0.0 };
            img.rgba.push([c.x, c.y, c.z, alpha]);
            img.depth.push(if p.hits > 0 { p.depth / p.hits as f32 } else { f32::INFINITY });
            let nrm = if p.hits > 0 { p.normal.normalize_or_zero() } else { Vec3::ZERO };
            img.normal.push(nrm.to_array());
            img.albedo.push((if p.hits > 0 { p.albedo / p.hits as f32 } else { Vec3::ZERO }).to_array());
        }
        img
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blackman_harris_samples_follow_the_filter() {
        let fs = FilterSampler::new(PixelFilter::BlackmanHarris { width_px: 1.5 });
        let n = 100_000;
        let mut inside_half = 0;
        for i in 0..n {
            let x = fs.sample_1d((i as f32 + 0.5) / n as f32);
            assert!(x.abs() <= 0.75 + 1e-4);
            if x.abs() < 0.25 {
                inside_half += 1;
            }
        }
        // ∫ of the Blackman–Harris window over the central third is ≈ 0.722 of the total
        let frac = inside_half as f32 / n as f32;
        assert!(frac > 0.6 && frac < 0.8, "{frac}");
    }

    /// The binned lookup finds the segment a binary search finds, so the density is the same
    /// bit for bit: at offsets across and beyond the filter, and at every knot and its
    /// neighbours (where the segment changes).
    #[test]
    fn pdf_lookup_is_the_binary_search() {
        for filter in [
            PixelFilter::BlackmanHarris { width_px: 3.0 },
            PixelFilter::Box { width_px: 1.0 },
            PixelFilter::BlackmanHarris { width_px: 0.7 },
        ] {
            let fs = FilterSampler::new(filter);
            let searched = |x: f32| {
                let inv = &fs.inverse_cdf;
                let v = x / fs.width_px + 0.5;
                if !(v >= inv[0] && v <= inv[inv.len() - 1]) {
                    return 0.0;
                }
                let i = inv.partition_point(|&a| a <= v).clamp(1, inv.len() - 1) - 1;
                let dv = inv[i + 1] - inv[i];
                if dv > 0.0 {
                    1.0 / ((inv.len() - 1) as f32 * dv * fs.width_px)
                } else {
                    0.0
                }
            };
            let mut xs: Vec<f32> = (-4000..=4000).map(|k| k as f32 * 1e-3 * fs.width_px).collect();
            for &k in &fs.inverse_cdf {
                let x = (k - 0.5) * fs.width_px;
                xs.extend([x, f32::from_bits(x.to_bits() + 1), f32::from_bits(x.to_bits().wrapping_sub(1))]);
            }
            for x in xs {
                assert_eq!(fs.pdf_1d(x).to_bits(), searched(x).to_bits(), "{filter:?} at {x}");
            }
        }
    }
}
