//! Image error metrics: relative RMSE on linear radiance and LDR-FLIP, a perceptual difference
//! for images seen alternately (flipped between) on a display.
//!
//! FLIP follows P. Andersson, J. Nilsson, T. Akenine-Möller, M. Oskarsson, K. Åström and M. D.
//! Fairchild, "FLIP: A Difference Evaluator for Alternating Images", Proceedings of the ACM on
//! Computer Graphics and Interactive Techniques (HPG 2020) 3(2), and the steps of its reference
//! implementation (NVlabs/flip, `FLIP::image<float>::FLIP` in the C++ version): sRGB → YCxCz,
//! contrast-sensitivity filtering (separable Gaussians, the blue–yellow channel a sum of two),
//! clamp to the linear-RGB gamut, CIELab with the Hunt adjustment, HyAB distance raised to
//! q_c = 0.7 and compressed above p_c·c_max into [p_t, 1]; edge and point features from the
//! first and second derivatives of a Gaussian (σ = 0.5·w·ppd, w = 0.082) on the luminance;
//! error = colour^(1 − feature). Inputs are display-referred sRGB values in [0, 1] (use
//! [`tonemap_srgb`] for renders). 0 means identical, 1 the largest difference.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `pixels_per_degree` | f32: display resolution seen by the observer | px/degree | 67 (0.7 m from a 0.7 m wide 3840-pixel display, as the reference) |

use super::Image;
use crate::error::{Error, Result};

/// The reference implementation's default observer: 0.7 m from a 0.7 m wide 3840-pixel display.
pub const DEFAULT_PIXELS_PER_DEGREE: f32 = 67.0;

/// FLIP's constants (paper, section 4).
const GQC: f32 = 0.7;
const GPC: f32 = 0.4;
const GPT: f32 = 0.95;
const GW: f32 = 0.082;
const GQF: f32 = 0.5;
/// Contrast-sensitivity Gaussians (a, b) per YCxCz channel; the blue–yellow channel has two.
const A1: [f32; 3] = [1.0, 1.0, 34.1];
const B1: [f32; 3] = [0.0047, 0.0053, 0.04];
const A2Z: f32 = 13.5;
const B2Z: f32 = 0.025;
/// D65 white and its inverse.
const WHITE: [f32; 3] = [0.950_428_55, 1.0, 1.088_900_4];
const INV_WHITE: [f32; 3] = [1.052_156_9, 1.0, 0.918_357_7];

/// Pixels per degree of visual angle for an observer `distance_m` from a display `width_m`
/// wide showing `resolution_x` pixels across.
pub fn pixels_per_degree(distance_m: f32, resolution_x: f32, width_m: f32) -> f32 {
    distance_m * (resolution_x / width_m) * (std::f32::consts::PI / 180.0)
}

/// Linear radiance → display sRGB in [0, 1]: scaled by 2^`exposure_stops`, clamped, sRGB
/// transfer function (as the PNG preview with `--tonemap srgb`).
pub fn tonemap_srgb(image: &Image, exposure_stops: f32) -> Vec<[f32; 3]> {
    let scale = 2f32.powf(exposure_stops);
    image
        .rgba
        .iter()
        .map(|p| {
            let f = |c: f32| {
                let v = (c * scale).clamp(0.0, 1.0);
                if v.is_nan() {
                    0.0
                } else {
                    crate::scene::texture::linear_to_srgb(v)
                }
            };
            [f(p[0]), f(p[1]), f(p[2])]
        })
        .collect()
}

/// Relative RMSE of `test` against `reference` over R, G and B (linear values):
/// sqrt(mean((t − r)²)) / sqrt(mean(r²)).
pub fn relative_rmse(reference: &Image, test: &Image) -> Result<f64> {
    same_size(reference.width, reference.height, test.width, test.height)?;
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (r, t) in reference.rgba.iter().zip(&test.rgba) {
        for k in 0..3 {
            let (r, t) = (r[k] as f64, t[k] as f64);
            num += (t - r) * (t - r);
            den += r * r;
        }
    }
    if !(den > 0.0) || !num.is_finite() {
        return Err(Error::Metrics("relative RMSE: the reference image is black or not finite".into()));
    }
    Ok((num / den).sqrt())
}

fn same_size(w: u32, h: u32, w2: u32, h2: u32) -> Result<()> {
    if (w, h) != (w2, h2) {
        return Err(Error::Camera {
            field: "resolution".into(),
            message: format!("images of different sizes cannot be compared: {w}x{h} and {w2}x{h2}"),
        });
    }
    if w == 0 || h == 0 {
        return Err(Error::Camera { field: "resolution".into(), message: "empty image".into() });
    }
    Ok(())
}

#[inline]
fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

#[inline]
fn linear_rgb_to_xyz(c: [f32; 3]) -> [f32; 3] {
    let (r, g, b) = (c[0], c[1], c[2]);
    [
        (10135552.0 / 24577794.0) * r + (8788810.0 / 24577794.0) * g + (4435075.0 / 24577794.0) * b,
        (2613072.0 / 12288897.0) * r + (8788810.0 / 12288897.0) * g + (887015.0 / 12288897.0) * b,
        (1425312.0 / 73733382.0) * r + (8788810.0 / 73733382.0) * g + (70074185.0 / 73733382.0) * b,
    ]
}

#[inline]
fn xyz_to_linear_rgb(c: [f32; 3]) -> [f32; 3] {
    let (x, y, z) = (c[0], c[1], c[2]);
    [
        3.241_003_3 * x - 1.537_398_9 * y - 0.498_615_85 * z,
        -0.969_224_3 * x + 1.875_930_1 * y + 0.041_554_224 * z,
        0.055_639_423 * x - 0.204_011_2 * y + 1.057_148_9 * z,
    ]
}

#[inline]
fn xyz_to_ycxcz(c: [f32; 3]) -> [f32; 3] {
    let (x, y, z) = (c[0] * INV_WHITE[0], c[1] * INV_WHITE[1], c[2] * INV_WHITE[2]);
    [116.0 * y - 16.0, 500.0 * (x - y), 200.0 * (y - z)]
}

#[inline]
fn ycxcz_to_xyz(c: [f32; 3]) -> [f32; 3] {
    let y = (c[0] + 16.0) / 116.0;
    let x = y + c[1] / 500.0;
    let z = y - c[2] / 200.0;
    [x * WHITE[0], y * WHITE[1], z * WHITE[2]]
}

#[inline]
fn xyz_to_lab(c: [f32; 3]) -> [f32; 3] {
    let delta = 6.0f32 / 29.0;
    let delta3 = delta * delta * delta;
    let factor = 1.0 / (3.0 * delta * delta);
    let term = 4.0f32 / 29.0;
    let f = |v: f32| if v > delta3 { v.powf(1.0 / 3.0) } else { factor * v + term };
    let (x, y, z) = (f(c[0] * INV_WHITE[0]), f(c[1] * INV_WHITE[1]), f(c[2] * INV_WHITE[2]));
    [116.0 * y - 16.0, 500.0 * (x - y), 200.0 * (y - z)]
}

/// Lab with the Hunt adjustment (chroma scaled by 0.01·L).
#[inline]
fn hunt(lab: [f32; 3]) -> [f32; 3] {
    [lab[0], 0.01 * lab[0] * lab[1], 0.01 * lab[0] * lab[2]]
}

#[inline]
fn hyab(a: [f32; 3], b: [f32; 3]) -> f32 {
    (a[0] - b[0]).abs() + ((a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Gaussian in the paper's form a·sqrt(π/b)·exp(−π²x²/b).
#[inline]
fn gaussian_ab(x2: f32, a: f32, b: f32) -> f32 {
    let pi = std::f32::consts::PI;
    a * (pi / b).sqrt() * (-pi * pi * x2 / b).exp()
}

/// Square root of the weight of [`gaussian_ab`], for separating a sum of two Gaussians.
#[inline]
fn gaussian_ab_sqrt(x2: f32, a: f32, b: f32) -> f32 {
    let pi = std::f32::consts::PI;
    (a * (pi / b).sqrt()).sqrt() * (-pi * pi * x2 / b).exp()
}

/// Separable 1-D kernels of the contrast-sensitivity filters: per tap (Y, Cx) weights and the
/// two Cz components.
fn spatial_filters(ppd: f32) -> (Vec<[f32; 2]>, Vec<[f32; 2]>) {
    let pi2 = std::f32::consts::PI * std::f32::consts::PI;
    let max_b = B1.iter().copied().chain([1e-5, 1e-5, B2Z]).fold(0.0f32, f32::max);
    let radius = (3.0 * (max_b / (2.0 * pi2)).sqrt() * ppd).ceil() as i32;
    let dx = 1.0 / ppd;
    let (mut ycx, mut cz) = (Vec::new(), Vec::new());
    let (mut sum_ycx, mut sum_cz) = ([0.0f32; 2], [0.0f32; 2]);
    for i in -radius..=radius {
        let x = i as f32 * dx;
        let x2 = x * x;
        let a = [gaussian_ab(x2, A1[0], B1[0]), gaussian_ab(x2, A1[1], B1[1])];
        let b = [gaussian_ab_sqrt(x2, A1[2], B1[2]), gaussian_ab_sqrt(x2, A2Z, B2Z)];
        for k in 0..2 {
            sum_ycx[k] += a[k];
            sum_cz[k] += b[k];
        }
        ycx.push(a);
        cz.push(b);
    }
    let norm_cz = 1.0 / (sum_cz[0] * sum_cz[0] + sum_cz[1] * sum_cz[1]).sqrt();
    for w in &mut ycx {
        w[0] /= sum_ycx[0];
        w[1] /= sum_ycx[1];
    }
    for w in &mut cz {
        w[0] *= norm_cz;
        w[1] *= norm_cz;
    }
    (ycx, cz)
}

/// Separable 1-D edge/point kernel: per tap (Gaussian, first derivative, second derivative),
/// normalised so the Gaussian sums to 1 and the positive and negative lobes of the derivatives
/// to ±1.
fn feature_filter(ppd: f32) -> Vec<[f32; 3]> {
    let sd = 0.5 * GW * ppd;
    let radius = (3.0 * sd).ceil() as i32;
    let mut f = Vec::new();
    let (mut g_sum, mut dg_pos, mut dg_neg, mut ddg_pos, mut ddg_neg) = (0.0f32, 0.0f32, 0.0f32, 0.0f32, 0.0f32);
    for i in -radius..=radius {
        let x = i as f32;
        let g = (-(x * x) / (2.0 * sd * sd)).exp();
        g_sum += g;
        let dg = -x * g;
        if dg > 0.0 {
            dg_pos += dg;
        } else {
            dg_neg -= dg;
        }
        let ddg = (x * x / (sd * sd) - 1.0) * g;
        if ddg > 0.0 {
            ddg_pos += ddg;
        } else {
            ddg_neg -= ddg;
        }
        f.push([g, dg, ddg]);
    }
    for w in &mut f {
        w[0] /= g_sum;
        w[1] /= if w[1] > 0.0 { dg_pos } else { dg_neg };
        w[2] /= if w[2] > 0.0 { ddg_pos } else { ddg_neg };
    }
    f
}

/// Per-pixel LDR-FLIP error map (row-major, values in [0, 1]) of `test` against `reference`,
/// both display sRGB in [0, 1], `width` × `height`, for an observer at `ppd` pixels per degree.
pub fn flip_ldr(reference: &[[f32; 3]], test: &[[f32; 3]], width: usize, height: usize, ppd: f32) -> Result<Vec<f32>> {
    if reference.len() != width * height || test.len() != width * height {
        return Err(Error::Camera {
            field: "resolution".into(),
            message: format!("FLIP: {} and {} pixels given for a {width}x{height} image", reference.len(), test.len()),
        });
    }
    same_size(width as u32, height as u32, width as u32, height as u32)?;
    if !(ppd.is_finite() && ppd > 0.0) {
        return Err(Error::Camera {
            field: "pixels_per_degree".into(),
            message: format!("must be a positive number, got {ppd}"),
        });
    }
    let (w, h) = (width, height);
    let clampi = |v: isize, n: usize| v.clamp(0, n as isize - 1) as usize;
    // 1. sRGB → YCxCz (inputs clamped to [0, 1]; NaN as 0).
    let to_ycxcz = |img: &[[f32; 3]]| -> Vec<[f32; 3]> {
        img.iter()
            .map(|p| {
                let c = |v: f32| if v.is_nan() { 0.0 } else { srgb_to_linear(v.clamp(0.0, 1.0)) };
                xyz_to_ycxcz(linear_rgb_to_xyz([c(p[0]), c(p[1]), c(p[2])]))
            })
            .collect()
    };
    let images = [to_ycxcz(reference), to_ycxcz(test)];
    // 2. Colour pipeline: contrast-sensitivity filter (x, then y), clamp to the RGB gamut,
    //    Hunt-adjusted Lab, HyAB distance, compressed into [0, 1].
    let (f_ycx, f_cz) = spatial_filters(ppd);
    let r = (f_ycx.len() / 2) as isize;
    let mut lab_hunt: Vec<Vec<[f32; 3]>> = Vec::with_capacity(2);
    for img in &images {
        // horizontal: (Y, Cx, Cz_a, Cz_b)
        let mut tmp = vec![[0.0f32; 4]; w * h];
        for y in 0..h {
            for x in 0..w {
                let mut acc = [0.0f32; 4];
                for (k, (a, b)) in f_ycx.iter().zip(&f_cz).enumerate() {
                    let p = img[y * w + clampi(x as isize + k as isize - r, w)];
                    acc[0] += a[0] * p[0];
                    acc[1] += a[1] * p[1];
                    acc[2] += b[0] * p[2];
                    acc[3] += b[1] * p[2];
                }
                tmp[y * w + x] = acc;
            }
        }
        let mut out = vec![[0.0f32; 3]; w * h];
        for y in 0..h {
            for x in 0..w {
                let mut acc = [0.0f32; 4];
                for (k, (a, b)) in f_ycx.iter().zip(&f_cz).enumerate() {
                    let p = tmp[clampi(y as isize + k as isize - r, h) * w + x];
                    acc[0] += a[0] * p[0];
                    acc[1] += a[1] * p[1];
                    acc[2] += b[0] * p[2];
                    acc[3] += b[1] * p[3];
                }
                let rgb = xyz_to_linear_rgb(ycxcz_to_xyz([acc[0], acc[1], acc[2] + acc[3]])).map(|v| v.clamp(0.0, 1.0));
                out[y * w + x] = hunt(xyz_to_lab(linear_rgb_to_xyz(rgb)));
            }
        }
        lab_hunt.push(out);
    }
    let green = hunt(xyz_to_lab(linear_rgb_to_xyz([0.0, 1.0, 0.0])));
    let blue = hunt(xyz_to_lab(linear_rgb_to_xyz([0.0, 0.0, 1.0])));
    let cmax = hyab(green, blue).powf(GQC);
    let pccmax = GPC * cmax;
    let mut error: Vec<f32> = lab_hunt[0]
        .iter()
        .zip(&lab_hunt[1])
        .map(|(a, b)| {
            let d = hyab(*a, *b).powf(GQC);
            if d < pccmax {
                d * GPT / pccmax
            } else {
                GPT + (d - pccmax) / (cmax - pccmax) * (1.0 - GPT)
            }
        })
        .collect();
    // 3. Feature pipeline on the luminance normalised to [0, 1]: edges (first derivative) and
    //    points (second derivative), separable as in the reference.
    let ff = feature_filter(ppd);
    let rf = (ff.len() / 2) as isize;
    let mut features: Vec<Vec<[f32; 2]>> = Vec::with_capacity(2);
    for img in &images {
        let mut tmp = vec![[0.0f32; 3]; w * h]; // (dx, ddx, gaussian) along x
        for y in 0..h {
            for x in 0..w {
                let mut acc = [0.0f32; 3];
                for (k, f) in ff.iter().enumerate() {
                    let v = img[y * w + clampi(x as isize + k as isize - rf, w)][0] / 116.0 + 16.0 / 116.0;
                    acc[0] += f[1] * v;
                    acc[1] += f[2] * v;
                    acc[2] += f[0] * v;
                }
                tmp[y * w + x] = acc;
            }
        }
        let mut out = vec![[0.0f32; 2]; w * h]; // (edge, point)
        for y in 0..h {
            for x in 0..w {
                let (mut dx, mut ddx, mut dy, mut ddy) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
                for (k, f) in ff.iter().enumerate() {
                    let p = tmp[clampi(y as isize + k as isize - rf, h) * w + x];
                    dx += f[0] * p[0];
                    ddx += f[0] * p[1];
                    dy += f[1] * p[2];
                    ddy += f[2] * p[2];
                }
                out[y * w + x] = [(dx * dx + dy * dy).sqrt(), (ddx * ddx + ddy * ddy).sqrt()];
            }
        }
        features.push(out);
    }
    let norm = 1.0 / 2f32.sqrt();
    for (i, e) in error.iter_mut().enumerate() {
        let (a, b) = (features[0][i], features[1][i]);
        let fd = (norm * (a[0] - b[0]).abs().max((a[1] - b[1]).abs())).powf(GQF);
        *e = e.powf(1.0 - fd);
    }
    Ok(error)
}

/// Mean LDR-FLIP of two renders (tone-mapped with [`tonemap_srgb`] at `exposure_stops`) at
/// [`DEFAULT_PIXELS_PER_DEGREE`].
pub fn flip_mean(reference: &Image, test: &Image, exposure_stops: f32) -> Result<f64> {
    same_size(reference.width, reference.height, test.width, test.height)?;
    let map = flip_ldr(
        &tonemap_srgb(reference, exposure_stops),
        &tonemap_srgb(test, exposure_stops),
        reference.width as usize,
        reference.height as usize,
        DEFAULT_PIXELS_PER_DEGREE,
    )?;
    Ok(map.iter().map(|v| *v as f64).sum::<f64>() / map.len() as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A test card: smooth gradients, sharp edges and a few saturated patches.
    fn card(w: usize, h: usize) -> Vec<[f32; 3]> {
        let mut v = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let (u, t) = (x as f32 / w as f32, y as f32 / h as f32);
                let checker = if ((x / 12) + (y / 12)) % 2 == 0 { 0.8 } else { 0.2 };
                let patch = if (20..40).contains(&x) && (10..30).contains(&y) {
                    [0.9, 0.1, 0.1]
                } else {
                    [checker, checker * 0.9 + 0.05 * u, 0.5 * t + 0.2]
                };
                v.push(patch);
            }
        }
        v
    }

    fn rng(seed: &mut u64) -> f32 {
        *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (*seed >> 40) as f32 / (1u64 << 24) as f32
    }

    fn mean(v: &[f32]) -> f32 {
        v.iter().sum::<f32>() / v.len() as f32
    }

    #[test]
    fn identical_images_score_zero() {
        let (w, h) = (64, 48);
        let a = card(w, h);
        let e = flip_ldr(&a, &a, w, h, DEFAULT_PIXELS_PER_DEGREE).unwrap();
        assert!(e.iter().all(|v| *v == 0.0), "max {}", e.iter().cloned().fold(0.0, f32::max));
    }

    #[test]
    fn symmetric_and_in_unit_range() {
        let (w, h) = (64, 48);
        let a = card(w, h);
        let mut s = 7;
        let b: Vec<[f32; 3]> = a.iter().map(|p| p.map(|c| (c + 0.2 * (rng(&mut s) - 0.5)).clamp(0.0, 1.0))).collect();
        let ab = flip_ldr(&a, &b, w, h, DEFAULT_PIXELS_PER_DEGREE).unwrap();
        let ba = flip_ldr(&b, &a, w, h, DEFAULT_PIXELS_PER_DEGREE).unwrap();
        for (x, y) in ab.iter().zip(&ba) {
            assert!((x - y).abs() < 1e-5, "{x} vs {y}");
            assert!((0.0..=1.0).contains(x));
        }
        // black against white is the largest difference there is
        let black = vec![[0.0; 3]; w * h];
        let white = vec![[1.0; 3]; w * h];
        let e = mean(&flip_ldr(&black, &white, w, h, DEFAULT_PIXELS_PER_DEGREE).unwrap());
        assert!(e > 0.9, "{e}");
    }

    #[test]
    fn noise_scores_higher_than_slight_blur() {
        let (w, h) = (96, 64);
        let a = card(w, h);
        // 3×3 box blur
        let mut blur = a.clone();
        for y in 0..h {
            for x in 0..w {
                let mut acc = [0.0f32; 3];
                for dy in -1i32..=1 {
                    for dx in -1i32..=1 {
                        let p = a[(y as i32 + dy).clamp(0, h as i32 - 1) as usize * w
                            + (x as i32 + dx).clamp(0, w as i32 - 1) as usize];
                        for k in 0..3 {
                            acc[k] += p[k] / 9.0;
                        }
                    }
                }
                blur[y * w + x] = acc;
            }
        }
        let mut s = 3;
        let noise: Vec<[f32; 3]> = (0..w * h).map(|_| [rng(&mut s), rng(&mut s), rng(&mut s)]).collect();
        let e_blur = mean(&flip_ldr(&a, &blur, w, h, DEFAULT_PIXELS_PER_DEGREE).unwrap());
        let e_noise = mean(&flip_ldr(&a, &noise, w, h, DEFAULT_PIXELS_PER_DEGREE).unwrap());
        assert!(e_blur > 0.0 && e_noise > 3.0 * e_blur, "blur {e_blur}, noise {e_noise}");
        // more noise → more error
        let mut s = 11;
        let light: Vec<[f32; 3]> =
            a.iter().map(|p| p.map(|c| (c + 0.05 * (rng(&mut s) - 0.5)).clamp(0.0, 1.0))).collect();
        let heavy: Vec<[f32; 3]> =
            a.iter().map(|p| p.map(|c| (c + 0.4 * (rng(&mut s) - 0.5)).clamp(0.0, 1.0))).collect();
        let (el, eh) =
            (mean(&flip_ldr(&a, &light, w, h, 67.0).unwrap()), mean(&flip_ldr(&a, &heavy, w, h, 67.0).unwrap()));
        assert!(el < eh, "{el} {eh}");
    }

    #[test]
    fn bad_input_is_an_error() {
        let a = vec![[0.5f32; 3]; 12];
        assert!(flip_ldr(&a, &a, 4, 4, 67.0).is_err());
        assert!(flip_ldr(&a, &a, 4, 3, 0.0).is_err());
        assert!(flip_ldr(&a, &a, 4, 3, f32::NAN).is_err());
        let img = |w, h| Image {
            width: w,
            height: h,
            rgba: vec![[1.0; 4]; (w * h) as usize],
            depth: vec![],
            normal: vec![],
            albedo: vec![],
        };
        assert!(relative_rmse(&img(4, 3), &img(3, 4)).is_err());
        assert_eq!(relative_rmse(&img(4, 3), &img(4, 3)).unwrap(), 0.0);
        assert!(flip_mean(&img(4, 3), &img(2, 2), 0.0).is_err());
    }

    /// Mean FLIP values computed by the reference C++ implementation (NVlabs/flip through the
    /// `nv-flip` crate 0.1.2) for the same 8-bit images; ours agree per pixel within 2e-5.
    #[test]
    fn matches_the_reference_implementation() {
        let (w, h) = (160usize, 120usize);
        let mut a = vec![[0u8; 3]; w * h];
        for y in 0..h {
            for x in 0..w {
                let (u, t) = (x as f32 / w as f32, y as f32 / h as f32);
                let c = if ((x / 16) + (y / 10)) % 2 == 0 { 200.0 } else { 40.0 };
                a[y * w + x] =
                    [(c * (0.5 + 0.5 * u)) as u8, (255.0 * t) as u8, (c * 0.3 + 100.0 * (u * 7.0).sin().abs()) as u8];
            }
        }
        let shifted: Vec<[u8; 3]> = (0..w * h).map(|i| a[if i % w + 1 < w { i + 1 } else { i }]).collect();
        let cast: Vec<[u8; 3]> = a.iter().map(|p| [p[0].saturating_add(30), p[1], p[2].saturating_sub(20)]).collect();
        let tof = |v: &Vec<[u8; 3]>| v.iter().map(|p| p.map(|c| c as f32 / 255.0)).collect::<Vec<[f32; 3]>>();
        for (b, ppd, reference) in
            [(&shifted, 67.0, 0.098679), (&cast, 67.0, 0.318615), (&shifted, 30.0, 0.097797), (&cast, 30.0, 0.303949)]
        {
            let m = mean(&flip_ldr(&tof(&a), &tof(b), w, h, ppd).unwrap());
            assert!((m - reference).abs() < 2e-6, "ppd {ppd}: {m} vs the reference's {reference}");
        }
    }

    #[test]
    fn pixels_per_degree_matches_the_reference_default() {
        let ppd = pixels_per_degree(0.7, 3840.0, 0.7);
        assert!((ppd - 67.02).abs() < 0.01, "{ppd}");
    }
}
