//! Capture loading: an sRGB capture's dark frame decoded as the capture is, and the hot-pixel
//! rule (lone pixels masked beside a spread spot or where the dark frame marks them, a lone
//! pixel kept as the spot otherwise).

use petzval_fit::captures::{load, undersampled_warning, CaptureImage};
use petzval_fit::fit::{FitOptions, Problem};
use petzval_fit::Manifest;
use std::path::{Path, PathBuf};

/// One capture of `image` (40×32 px at the sensor's centre, the source in focus at 3 m, 550 nm)
/// with `extra` lines; parsed as `dir/m.toml`.
fn manifest(dir: &Path, image: &str, extra: &str) -> Manifest {
    let text = format!(
        r#"
[lens]
start = "double-gauss-50mm"

[sensor]
width_mm = 36.0
height_mm = 24.0
pixels = [6000, 4000]

[[free]]
param = "sensor.offset_mm"
min = -0.2
max = 0.2

[[capture]]
image = "{image}"
crop_origin_px = [2980, 1984]
source_m = [0.0, 0.0, 3.0]
focus_m = 3.0
f_number = 2.8
wavelength_nm = 550
{extra}"#
    );
    Manifest::parse(&text, &dir.join("m.toml")).unwrap()
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("petzval-fit-cap-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn load_one(dir: &Path, image: &str, extra: &str) -> CaptureImage {
    load(&manifest(dir, image, extra).captures[0]).unwrap()
}

/// sRGB → linear on 0…1.
fn srgb_to_linear(v: f64) -> f64 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

const W: u32 = 40;
const H: u32 = 32;

/// A 16-bit grey image: a background of 100 plus deterministic noise 0…15 (σ ≈ 4.6), a
/// Gaussian spot of `peak` and width `sigma_px` at `spot` (none for a peak of 0), and
/// `pixels` set to their values.
fn grey16(
    spot: (u32, u32),
    peak: f64,
    sigma_px: f64,
    pixels: &[(u32, u32, u16)],
    seed: u32,
) -> image::ImageBuffer<image::Luma<u16>, Vec<u16>> {
    let mut seed = seed;
    image::ImageBuffer::from_fn(W, H, |x, y| {
        seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        let noise = (seed >> 28) as f64;
        let r2 = (x as f64 - spot.0 as f64).powi(2) + (y as f64 - spot.1 as f64).powi(2);
        let v = 100.0 + noise + peak * (-r2 / (2.0 * sigma_px * sigma_px)).exp();
        let set = pixels.iter().find(|p| (p.0, p.1) == (x, y));
        image::Luma([set.map_or(v.round() as u16, |p| p.2)])
    })
}

fn at(x: u32, y: u32) -> usize {
    (y * W + x) as usize
}

/// An 8-bit sRGB capture's dark frame is decoded as the capture is and subtracted in linear
/// light: where the capture shows the dark frame's level the result is 0, and a spot pixel is
/// the difference of the decoded values (subtracting the undecoded dark frame left the
/// background at −34.6 and the spot 34.6 too low). With `transfer = "linear"` both are read
/// as they are.
#[test]
fn an_srgb_captures_dark_frame_is_decoded_as_the_capture() {
    let dir = temp_dir("srgbdark");
    // a dark pedestal of 40 (encoded), a 3×3 spot of 128 (encoded) over it
    let spot = |x: u32, y: u32| (19..=21).contains(&x) && (15..=17).contains(&y);
    image::GrayImage::from_fn(W, H, |x, y| image::Luma([if spot(x, y) { 128 } else { 40 }]))
        .save(dir.join("c.png"))
        .unwrap();
    image::GrayImage::from_pixel(W, H, image::Luma([40])).save(dir.join("d.png")).unwrap();
    let dark = "dark_frame = \"d.png\"\n";
    let c = load_one(&dir, "c.png", &format!("transfer = \"srgb\"\n{dark}"));
    let (lin40, lin128) = (255.0 * srgb_to_linear(40.0 / 255.0), 255.0 * srgb_to_linear(128.0 / 255.0));
    let background = c.channels[0][at(2, 2)];
    let peak = c.channels[0][at(20, 16)];
    assert!(background.abs() < 1e-9, "background {background}, expected 0 (undecoded: {})", lin40 - 40.0);
    assert!((peak - (lin128 - lin40)).abs() < 1e-9, "spot {peak}, expected {}", lin128 - lin40);
    // the undecoded subtraction is measurably off: the test tells them apart
    assert!((lin40 - 40.0).abs() > 30.0 && (peak - (lin128 - 40.0)).abs() > 30.0);
    let linear = load_one(&dir, "c.png", &format!("transfer = \"linear\"\n{dark}"));
    assert_eq!((linear.channels[0][at(2, 2)], linear.channels[0][at(20, 16)]), (0.0, 88.0));
    // a flat (spread) spot: no pixel masked as hot, no one-pixel spot
    assert_eq!((c.hot, c.lone_spot), (0, None));
    std::fs::remove_dir_all(&dir).ok();
}

/// A spot whose light falls in one pixel (its neighbours at the background) is the spot when
/// nothing else in the image is: kept (it was masked as hot and the fit saw background only),
/// reported as a one-pixel spot with a warning, and the fit's centroid is on it; the model,
/// shifted there, puts its light on it.
#[test]
fn a_one_pixel_spot_is_kept_and_the_fit_lands_on_it() {
    let dir = temp_dir("lone");
    let (sx, sy) = (27u32, 9u32);
    grey16((0, 0), 0.0, 1.0, &[(sx, sy, 20_000)], 777).save(dir.join("lone.png")).unwrap();
    let m = manifest(&dir, "lone.png", "");
    let c = load(&m.captures[0]).unwrap();
    assert!(c.mask[at(sx, sy)], "the one-pixel spot is kept");
    assert_eq!((c.hot, c.lone_spot), (0, Some((sx as usize, sy as usize))));
    let w = undersampled_warning(&m.captures[0], &c).expect("a warning for a one-pixel spot");
    assert!(w.contains("lone.png") && w.contains("one pixel") && w.contains("(27, 9)"), "{w}");
    assert!(w.contains("dark_frame"), "{w}");
    // the fit: centroid on the pixel's centre, the model's brightest pixel on it
    let problem = Problem::new(&m, &FitOptions::default()).unwrap();
    let p = &problem.captures[0];
    assert_eq!((p.centroid_px.x, p.centroid_px.y), (sx as f64 + 0.5, sy as f64 + 0.5));
    let landings = problem.landings(&problem.start).unwrap();
    let shifts = problem.centroid_shifts(&landings);
    let fit = problem.fit_capture(0, &landings[0], shifts[0]);
    assert!(fit.scale[0] > 0.0, "scale {}", fit.scale[0]);
    let brightest = (0..(W * H) as usize).max_by(|a, b| fit.model[0][*a].total_cmp(&fit.model[0][*b])).unwrap();
    let (bx, by) = ((brightest % W as usize) as i64, (brightest / W as usize) as i64);
    assert!((bx - sx as i64).abs() <= 1 && (by - sy as i64).abs() <= 1, "model peak at ({bx}, {by})");
    std::fs::remove_dir_all(&dir).ok();
}

/// A hot pixel a few pixels beside a faint spread spot (peak 3 000, σ 1.2 px; the hot pixel
/// 40 000 and 6 px from its centre, its neighbours at the background) is masked, the spot kept.
#[test]
fn a_hot_pixel_beside_a_spread_faint_spot_is_masked() {
    let dir = temp_dir("beside");
    let (sx, sy) = (18u32, 14u32);
    let (hx, hy) = (sx + 6, sy + 1);
    grey16((sx, sy), 3000.0, 1.2, &[(hx, hy, 40_000)], 4242).save(dir.join("beside.png")).unwrap();
    let c = load_one(&dir, "beside.png", "");
    assert!(!c.mask[at(hx, hy)], "the hot pixel is masked");
    assert_eq!((c.hot, c.lone_spot), (1, None));
    for dy in 0..5 {
        for dx in 0..5 {
            assert!(c.mask[at(sx + dx - 2, sy + dy - 2)], "spot pixel ({}, {}) kept", sx + dx - 2, sy + dy - 2);
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Several hot pixels and a spot. (a) Beside a spread spot, all four (8 000 to 60 000, over and
/// under the spot's peak) are masked. (b) With a one-pixel spot and a dark frame showing
/// three hot pixels (one brighter than the spot), those three are masked and the spot kept.
/// (c) The same without the dark frame: the brightest lone pixel is taken for the spot (the
/// documented limit: only a dark frame tells a hot pixel from a one-pixel spot), the others
/// masked.
#[test]
fn several_hot_pixels_and_a_spot() {
    let dir = temp_dir("several");
    // (a)
    let hot = [(4u32, 5u32, 30_000u16), (33, 6, 12_000), (7, 27, 60_000), (30, 25, 8_000)];
    grey16((20, 15), 15_000.0, 1.5, &hot, 99).save(dir.join("spread.png")).unwrap();
    let c = load_one(&dir, "spread.png", "");
    assert_eq!((c.hot, c.lone_spot), (4, None));
    assert!(hot.iter().all(|&(x, y, _)| !c.mask[at(x, y)]), "all four masked");
    assert!(c.mask[at(20, 15)] && c.mask[at(21, 15)], "the spot kept");
    // (b) dark frame: 100 + noise with three hot pixels at their dark-current levels
    let (sx, sy) = (21u32, 17u32);
    let dark_hot = [(6u32, 6u32, 20_000u16), (33, 8, 9_000), (10, 26, 25_000)];
    let lit: Vec<(u32, u32, u16)> = dark_hot.iter().map(|&(x, y, v)| (x, y, v * 2)).chain([(sx, sy, 20_000)]).collect();
    grey16((0, 0), 0.0, 1.0, &lit, 5).save(dir.join("lone.png")).unwrap();
    grey16((0, 0), 0.0, 1.0, &dark_hot, 6).save(dir.join("dark.png")).unwrap();
    let c = load_one(&dir, "lone.png", "dark_frame = \"dark.png\"\n");
    let (hot_value, spot_value) = (c.channels[0][at(10, 26)], c.channels[0][at(sx, sy)]);
    assert!(hot_value > spot_value, "a hot pixel outshines the spot after the dark frame: {hot_value} vs {spot_value}");
    assert_eq!((c.hot, c.lone_spot), (3, Some((sx as usize, sy as usize))));
    assert!(dark_hot.iter().all(|&(x, y, _)| !c.mask[at(x, y)]), "the dark frame's hot pixels masked");
    assert!(c.mask[at(sx, sy)], "the spot kept");
    // (c) without the dark frame the brightest (10, 26) is taken for the spot
    let c = load_one(&dir, "lone.png", "");
    assert_eq!((c.hot, c.lone_spot), (3, Some((10, 26))));
    assert!(!c.mask[at(sx, sy)] && c.mask[at(10, 26)]);
    std::fs::remove_dir_all(&dir).ok();
}

/// An 8-bit sRGB capture whose background is quantised (mostly 0, a few adjacent pairs at 1:
/// its median absolute deviation is 0) keeps a one-pixel spot: the noise σ is at least one
/// step of the file, so the pairs at one step are not a spread spot (with σ from the
/// deviation alone they were, and the spot was masked as hot).
#[test]
fn a_quantised_background_is_no_spread_spot() {
    let dir = temp_dir("quant");
    let (sx, sy) = (12u32, 18u32);
    image::GrayImage::from_fn(W, H, |x, y| {
        let pair = (x % 8 == 3 || x % 8 == 4) && y % 5 == 1;
        image::Luma([if (x, y) == (sx, sy) { 200 } else { pair as u8 }])
    })
    .save(dir.join("q.png"))
    .unwrap();
    let c = load_one(&dir, "q.png", "transfer = \"srgb\"\n");
    assert_eq!((c.hot, c.lone_spot), (0, Some((sx as usize, sy as usize))));
    assert!(c.mask[at(sx, sy)]);
    std::fs::remove_dir_all(&dir).ok();
}

/// A defocused disc covering most of the image (its level the image's median) is a spread spot:
/// a hot pixel inside it is masked, not taken for a one-pixel spot (with the spread threshold
/// from the median, nothing stood over it and the hot pixel became the spot).
#[test]
fn a_hot_pixel_in_a_disc_covering_most_of_the_image_is_masked() {
    let dir = temp_dir("disc");
    let (hx, hy) = (14u32, 12u32);
    let mut seed = 31u32;
    let img = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(W, H, |x, y| {
        seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        let noise = (seed >> 28) as u16;
        let inside = (x as f64 - 19.5).powi(2) + (y as f64 - 15.5).powi(2) < 18.0f64.powi(2);
        image::Luma([if (x, y) == (hx, hy) {
            40_000
        } else if inside {
            5000 + noise
        } else {
            100 + noise
        }])
    });
    img.save(dir.join("disc.png")).unwrap();
    let c = load_one(&dir, "disc.png", "");
    let inside = (0..W * H).filter(|k| c.channels[0][*k as usize] >= 5000.0).count();
    assert!(inside as f64 > 0.6 * (W * H) as f64, "the disc covers {inside} of {} pixels", W * H);
    assert_eq!((c.hot, c.lone_spot), (1, None));
    assert!(!c.mask[at(hx, hy)]);
    std::fs::remove_dir_all(&dir).ok();
}

/// An RGB capture whose spot spreads in red but falls in one pixel in green and blue keeps that
/// pixel (part of the red channel's spread spot); a hot pixel in all three channels elsewhere is
/// masked.
#[test]
fn a_spot_lone_in_one_channel_and_spread_in_another_is_kept() {
    let dir = temp_dir("chroma");
    let (sx, sy, hx, hy) = (20u32, 15u32, 6u32, 24u32);
    let mut seed = 8u32;
    let img = image::ImageBuffer::<image::Rgb<u16>, Vec<u16>>::from_fn(W, H, |x, y| {
        let mut px = [0u16; 3];
        for (c, v) in px.iter_mut().enumerate() {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let r2 = (x as f64 - sx as f64).powi(2) + (y as f64 - sy as f64).powi(2);
            let spot = match c {
                0 => 10_000.0 * (-r2 / (2.0 * 1.5f64.powi(2))).exp(),
                _ if (x, y) == (sx, sy) => 10_000.0,
                _ => 0.0,
            };
            *v = if (x, y) == (hx, hy) { 30_000 } else { (100.0 + (seed >> 28) as f64 + spot).round() as u16 };
        }
        image::Rgb(px)
    });
    img.save(dir.join("rgb.png")).unwrap();
    let m = manifest(&dir, "rgb.png", "").captures.remove(0);
    let capture = petzval_fit::Capture { wavelength: petzval_fit::manifest::Wavelength::Rgb, ..m };
    let c = load(&capture).unwrap();
    assert!(c.mask[at(sx, sy)], "the spot's centre kept");
    assert!(!c.mask[at(hx, hy)], "the hot pixel masked");
    assert_eq!((c.hot, c.lone_spot), (1, None));
    std::fs::remove_dir_all(&dir).ok();
}
