//! Capture images as the fit sees them: linear, dark frame subtracted, one plane per channel
//! (one for a single wavelength, three for `rgb`), with a mask of the pixels that count.
//!
//! | step | what |
//! |---|---|
//! | read | EXR (`R`,`G`,`B` or `Y` channels, first layer) or floating-point TIFF (grey or RGB; linear values, no clipping level), 16-bit PNG or TIFF (values 0…65535), 8-bit PNG, TIFF or JPEG (0…255) |
//! | clip | pixels at or above `saturation` in any channel are masked (default: the integer format's maximum, 65535 or 255; 245 for JPEG, whose ringing keeps a clipped core a few levels below 255; none for EXR and float TIFF) |
//! | decode | `transfer = "srgb"`: the sRGB curve is undone on value / maximum (an 8-bit file left at the default transfer is read as linear, with a warning: [`transfer_warning`]) |
//! | dark | the dark frame (same size, and the same kind of file: 8-bit, 16-bit or floating point) is decoded by the capture's `transfer`, as the capture is, and subtracted in linear light |
//! | mask | the manifest's mask (same size): zero = masked |
//! | mono | a single-wavelength capture of an RGB file uses the channels' mean |
//! | hot pixels | see below |
//!
//! Hot pixels. Each channel's background is its median and its noise σ the median absolute
//! deviation × 1.4826, at least one step of an integer file at the background (in linear
//! units: the quantisation of a clean 8-bit background leaves the deviation 0). A **lone
//! pixel** stands over 8 σ above the largest of its 8 neighbours, which are themselves within
//! 5 σ of the background (in any channel). A **spread spot** is an 8-connected region of at
//! least [`SPREAD_PIXELS`] pixels over the 10th percentile + [`SPREAD_SIGMA`] σ (the median +
//! 5 σ for normal noise; from the 10th percentile so that a defocused disc covering most of
//! the image, whose level is the median, counts), in any channel, the manifest's mask excluded
//! and clipped pixels included. Then:
//!
//! | case | lone pixels |
//! |---|---|
//! | the dark frame has a lone pixel at the same place (its own background and σ) | masked, however bright |
//! | the image holds a spread spot | masked, however bright: the spread spot is the source (a hot pixel may outshine a faint spot's peak) |
//! | no spread spot | the brightest (summed over the channels, not marked by the dark frame) is the spot, kept, with a warning ([`undersampled_warning`]: one pixel constrains the fit weakly); the others are masked |
//!
//! A lone pixel belongs to no region of its own channel (it stands out of a plateau too); one
//! that is part of a spread region in another channel is part of the spot, kept.
//! `hot` counts the masked pixels.
//!
//! Errors name the manifest, the capture and the field (`image`, `dark_frame`, `mask`,
//! `wavelength_nm`) as well as the file: `m.toml: capture[2] (p02.png).dark_frame: dark32.png: …`.

use crate::error::{Error, Result};
use crate::manifest::{Capture, Transfer, Wavelength};
use std::path::Path;

/// The default clipping level of a lossy 8-bit file (JPEG): its ringing around a clipped core
/// keeps the plateau a few levels below 255 (249 to 254 at quality 95), where 255 would mask part of it or nothing.
pub const JPEG_SATURATION: f64 = 245.0;

/// The least number of 8-connected pixels over the spread threshold ([`SPREAD_SIGMA`]) that
/// make a spread spot (a point source's image, not a lone hot pixel; see the module docs).
pub const SPREAD_PIXELS: usize = 2;

/// A spread spot's pixels stand this many noise σ over the image's 10th percentile: the
/// median + 5 σ for a background of normal noise, whose 10th percentile is 1.28 σ below its
/// median; and a defocused disc covering most of the image (its level the median) still counts.
pub const SPREAD_SIGMA: f64 = 6.3;

/// A loaded capture image.
#[derive(Debug, Clone, PartialEq)]
pub struct CaptureImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// One plane per channel (row-major, top row first), linear.
    pub channels: Vec<Vec<f64>>,
    /// Pixels that count.
    pub mask: Vec<bool>,
    /// Pixels masked as clipped.
    pub clipped: usize,
    /// Pixels masked as hot.
    pub hot: usize,
    /// The spot is this one pixel (x, y): a lone pixel kept because the image holds no spread
    /// spot (see the module docs); None for a spread spot.
    pub lone_spot: Option<(usize, usize)>,
    /// The file stores 8-bit integers (JPEG, 8-bit PNG or TIFF): almost always sRGB-encoded.
    pub eight_bit: bool,
}

/// Raw planes of an image file with the format's clipping level.
struct Raw {
    width: usize,
    height: usize,
    planes: Vec<Vec<f64>>,
    max_value: Option<f64>,
    eight_bit: bool,
    /// Lossy compression (JPEG).
    lossy: bool,
}

impl Raw {
    /// What kind of values the file holds, for messages.
    fn kind(&self) -> &'static str {
        match (self.max_value, self.eight_bit) {
            (None, _) => "floating point",
            (Some(_), true) => "8-bit",
            (Some(_), false) => "16-bit",
        }
    }

    /// The clipping level when the manifest gives none.
    fn default_saturation(&self) -> Option<f64> {
        if self.lossy && self.eight_bit {
            Some(JPEG_SATURATION)
        } else {
            self.max_value
        }
    }
}

/// An error of one of a capture's files: the manifest, the capture, the field and the file.
fn capture_err(capture: &Capture, field: &str, path: &Path, message: impl std::fmt::Display) -> Error {
    Error::manifest(&capture.manifest, format!("{}.{field}", capture.label), format!("{}: {message}", path.display()))
}

fn read_raw(path: &Path) -> std::result::Result<Raw, String> {
    if !path.exists() {
        return Err("no such file".into());
    }
    if path.is_dir() {
        return Err("is a folder, not an image".into());
    }
    let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    if ext == "exr" {
        let img = exr::prelude::read_first_flat_layer_from_file(path).map_err(|e| e.to_string())?;
        let layer = img.layer_data;
        let (width, height) = (layer.size.width(), layer.size.height());
        let find = |name: &str| {
            layer
                .channel_data
                .list
                .iter()
                .find(|c| c.name.to_string().eq_ignore_ascii_case(name))
                .map(|c| c.sample_data.values_as_f32().map(|v| v as f64).collect::<Vec<f64>>())
        };
        let planes = match (find("R"), find("G"), find("B"), find("Y")) {
            (Some(r), Some(g), Some(b), _) => vec![r, g, b],
            (_, _, _, Some(y)) => vec![y],
            _ => {
                let names: Vec<String> = layer.channel_data.list.iter().map(|c| c.name.to_string()).collect();
                return Err(format!(
                    "has neither R, G, B nor Y channels (its first layer has {}); write the capture's channels as R, G, B or Y",
                    names.join(", ")
                ));
            }
        };
        return Ok(Raw { width, height, planes, max_value: None, eight_bit: false, lossy: false });
    }
    if ext == "tif" || ext == "tiff" {
        if let Some(raw) = read_float_tiff(path)? {
            return Ok(raw);
        }
    }
    if std::fs::metadata(path).is_ok_and(|m| m.len() == 0) {
        return Err("is empty (0 bytes)".into());
    }
    let img = image::open(path).map_err(|e| e.to_string())?;
    let lossy = matches!(ext.as_str(), "jpg" | "jpeg" | "jpe" | "jfif");
    let (width, height) = (img.width() as usize, img.height() as usize);
    let eight_bit = matches!(
        img.color(),
        image::ColorType::L8 | image::ColorType::La8 | image::ColorType::Rgb8 | image::ColorType::Rgba8
    );
    let (planes, max_value) = match img {
        image::DynamicImage::ImageLuma8(b) => (vec![b.pixels().map(|p| p.0[0] as f64).collect()], 255.0),
        image::DynamicImage::ImageLuma16(b) => (vec![b.pixels().map(|p| p.0[0] as f64).collect()], 65535.0),
        image::DynamicImage::ImageRgb8(b) => {
            ((0..3).map(|c| b.pixels().map(|p| p.0[c] as f64).collect()).collect(), 255.0)
        }
        image::DynamicImage::ImageRgb16(b) => {
            ((0..3).map(|c| b.pixels().map(|p| p.0[c] as f64).collect()).collect(), 65535.0)
        }
        other => {
            let b = other.to_rgb16();
            ((0..3).map(|c| b.pixels().map(|p| p.0[c] as f64).collect()).collect(), 65535.0)
        }
    };
    Ok(Raw { width, height, planes, max_value: Some(max_value), eight_bit, lossy })
}

/// A warning for an 8-bit capture read as linear only because the manifest left `transfer` at
/// its default: such files (camera JPEGs, 8-bit PNG or TIFF) are almost always sRGB-encoded,
/// and read as linear their spots' wings come out far too bright.
pub fn transfer_warning(capture: &Capture, image: &CaptureImage) -> Option<String> {
    (image.eight_bit && !capture.transfer_given).then(|| {
        format!(
            "{}: an 8-bit image read as linear (the default transfer); camera JPEGs and 8-bit PNGs are sRGB-encoded: set transfer = \"srgb\" if this one is, or transfer = \"linear\" to say it is linear",
            capture.image.display()
        )
    })
}

/// A warning for a capture whose spot is a single pixel (kept as the spot, see the module
/// docs): undersampled, it constrains the fit weakly; and were it a hot pixel, only a dark
/// frame would tell.
pub fn undersampled_warning(capture: &Capture, image: &CaptureImage) -> Option<String> {
    image.lone_spot.map(|(x, y)| {
        format!(
            "{}: the spot is one pixel, ({x}, {y}), its 8 neighbours at the background: undersampled, it constrains the fit weakly{}",
            capture.image.display(),
            if capture.dark_frame.is_some() {
                ""
            } else {
                " (were it a hot pixel, a dark_frame would mask it)"
            }
        )
    })
}

/// A floating-point TIFF (16-, 32- or 64-bit samples; grey, grey + alpha, RGB or RGBA, alpha
/// dropped), read as linear values with no clipping level, as an EXR is; None for an integer
/// TIFF, which the `image` crate reads.
fn read_float_tiff(path: &Path) -> std::result::Result<Option<Raw>, String> {
    use tiff::decoder::{Decoder, DecodingResult};
    use tiff::ColorType;
    let file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let tiff_err = |e: tiff::TiffError| format!("TIFF: {e}");
    let mut decoder = Decoder::new(std::io::BufReader::new(file)).map_err(tiff_err)?;
    let (samples, keep) = match decoder.colortype().map_err(tiff_err)? {
        ColorType::Gray(_) => (1, 1),
        ColorType::GrayA(_) => (2, 1),
        ColorType::RGB(_) => (3, 3),
        ColorType::RGBA(_) => (4, 3),
        // other layouts: left to the image crate (which refuses what it cannot read)
        _ => return Ok(None),
    };
    let (w, h) = decoder.dimensions().map_err(tiff_err)?;
    let values: Vec<f64> = match decoder.read_image().map_err(tiff_err)? {
        DecodingResult::F32(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::F64(v) => v,
        DecodingResult::F16(v) => v.into_iter().map(|x| x.to_f64()).collect(),
        _ => return Ok(None),
    };
    let (width, height) = (w as usize, h as usize);
    if values.len() < width * height * samples {
        return Err(format!("TIFF: {} samples for {width}×{height}×{samples}", values.len()));
    }
    let planes = (0..keep).map(|c| (0..width * height).map(|k| values[k * samples + c]).collect()).collect();
    Ok(Some(Raw { width, height, planes, max_value: None, eight_bit: false, lossy: false }))
}

fn srgb_to_linear(v: f64) -> f64 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// Undoes the sRGB curve on value / `max` (1 for floating point) of every plane when
/// `transfer` says so; a linear file is left as it is.
fn decode(planes: &mut [Vec<f64>], transfer: Transfer, max: Option<f64>) {
    if transfer == Transfer::Srgb {
        let max = max.unwrap_or(1.0);
        for p in planes {
            for v in p.iter_mut() {
                *v = srgb_to_linear(*v / max) * max;
            }
        }
    }
}

/// The median of `values` (the upper one of an even count); 0 for none.
fn median(values: &[f64]) -> f64 {
    quantile(values, 0.5)
}

/// The value of rank ⌊q · count⌋ in `values` (q in [0, 1)); 0 for none.
fn quantile(values: &[f64], q: f64) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mut v = values.to_vec();
    let rank = ((q * v.len() as f64) as usize).min(v.len() - 1);
    *v.select_nth_unstable_by(rank, |a, b| a.total_cmp(b)).1
}

/// Per plane, the linear size of one step of an integer file at the plane's median (raw
/// values, before decoding): the least noise σ an integer background can have. 0 for
/// floating point.
fn quantisation_steps(raw: &Raw, transfer: Transfer) -> Vec<f64> {
    let Some(max) = raw.max_value else { return vec![0.0; raw.planes.len()] };
    raw.planes
        .iter()
        .map(|p| match transfer {
            Transfer::Linear => 1.0,
            Transfer::Srgb => {
                let r = median(p);
                max * (srgb_to_linear((r + 1.0) / max) - srgb_to_linear(r / max))
            }
        })
        .collect()
}

/// Loads a capture's image, dark frame and mask (see the module's table); errors name the
/// manifest, the capture, the field and the file.
pub fn load(capture: &Capture) -> Result<CaptureImage> {
    let path = &capture.image;
    let raw = read_raw(path).map_err(|m| capture_err(capture, "image", path, m))?;
    let (width, height, eight_bit) = (raw.width, raw.height, raw.eight_bit);
    let n = width * height;
    if n == 0 {
        return Err(capture_err(capture, "image", path, "is empty"));
    }
    // 1. Clipped pixels (before any decoding), in any channel.
    let saturation = capture.saturation.or(raw.default_saturation());
    let mut mask = vec![true; n];
    let mut clipped = 0;
    if let Some(s) = saturation {
        for (k, m) in mask.iter_mut().enumerate() {
            if raw.planes.iter().any(|p| p[k] >= s) {
                *m = false;
                clipped += 1;
            }
        }
    }
    // 2. Linear values (and the noise floor of an integer file, from its raw values).
    let kind = raw.kind();
    let steps = quantisation_steps(&raw, capture.transfer);
    let mut planes = raw.planes;
    decode(&mut planes, capture.transfer, raw.max_value);
    // 3. Dark frame: decoded as the capture is, subtracted in linear light; its lone pixels
    //    mark hot ones.
    let mut dark_hot = None;
    if let Some(dark_path) = &capture.dark_frame {
        let dark = read_raw(dark_path).map_err(|m| capture_err(capture, "dark_frame", dark_path, m))?;
        if (dark.width, dark.height) != (width, height) {
            return Err(capture_err(
                capture,
                "dark_frame",
                dark_path,
                format!("dark frame is {}×{}, the capture {}×{}", dark.width, dark.height, width, height),
            ));
        }
        // subtracted in the capture's units: an 8-bit dark under a 16-bit capture (or the
        // reverse, or integers under floating point) would be off by the ratio of the ranges
        if (dark.max_value, dark.eight_bit) != (raw.max_value, raw.eight_bit) {
            return Err(capture_err(
                capture,
                "dark_frame",
                dark_path,
                format!(
                    "dark frame is {}, the capture {}: it is subtracted in the capture's units, so it must be the same kind of file",
                    dark.kind(),
                    kind
                ),
            ));
        }
        let dark_steps = quantisation_steps(&dark, capture.transfer);
        let mut dark_planes = dark.planes;
        decode(&mut dark_planes, capture.transfer, dark.max_value);
        for (c, p) in planes.iter_mut().enumerate() {
            let d = &dark_planes[c.min(dark_planes.len() - 1)];
            for (v, dv) in p.iter_mut().zip(d) {
                *v -= dv;
            }
        }
        let mut marked = vec![false; n];
        for (d, step) in dark_planes.iter().zip(&dark_steps) {
            mark_lone(d, width, height, noise(d, *step), &vec![true; n], &mut marked);
        }
        dark_hot = Some(marked);
    }
    // 4. The manifest's mask.
    let mut allowed = vec![true; n];
    if let Some(mask_path) = &capture.mask {
        let m = read_raw(mask_path).map_err(|m| capture_err(capture, "mask", mask_path, m))?;
        if (m.width, m.height) != (width, height) {
            return Err(capture_err(
                capture,
                "mask",
                mask_path,
                format!("mask is {}×{}, the capture {}×{}", m.width, m.height, width, height),
            ));
        }
        for (k, a) in allowed.iter_mut().enumerate() {
            *a = m.planes.iter().any(|p| p[k] != 0.0);
        }
        for (v, a) in mask.iter_mut().zip(&allowed) {
            *v &= a;
        }
    }
    // 5. Channels the fit uses (a channels' mean steps by a fraction of a step).
    let (channels, steps) = match (capture.wavelength, planes.len()) {
        (Wavelength::Rgb, 3) => (planes, steps),
        (Wavelength::Rgb, _) => {
            return Err(capture_err(
                capture,
                "wavelength_nm",
                path,
                "wavelength_nm = \"rgb\" needs a colour image (R, G, B), this one has one channel",
            ))
        }
        (Wavelength::Mono(_), 1) => (planes, steps),
        (Wavelength::Mono(_), count) => {
            let mean = (0..n).map(|k| planes.iter().map(|p| p[k]).sum::<f64>() / count as f64).collect();
            (vec![mean], vec![steps.iter().sum::<f64>() / (count * count) as f64])
        }
    };
    for (c, p) in channels.iter().enumerate() {
        if let Some(k) = p.iter().position(|v| !v.is_finite()) {
            let (x, y) = (k % width, k / width);
            return Err(capture_err(capture, "image", path, format!("pixel ({x}, {y}) of channel {c} is not finite")));
        }
    }
    // 6. Hot pixels.
    let frame = Frame { width, height, allowed: &allowed, dark_hot: dark_hot.as_deref() };
    let (hot, lone_spot) = reject_hot_pixels(&channels, &steps, &frame, &mut mask);
    Ok(CaptureImage { width, height, channels, mask, clipped, hot, lone_spot, eight_bit })
}

/// The image's size and what the hot-pixel rule needs besides the values.
struct Frame<'a> {
    width: usize,
    height: usize,
    /// The manifest's mask (true: use the pixel).
    allowed: &'a [bool],
    /// Lone pixels of the dark frame, when there is one.
    dark_hot: Option<&'a [bool]>,
}

/// A plane's background (median) and noise σ (median absolute deviation × 1.4826, at least
/// `floor`, and above zero).
fn noise(p: &[f64], floor: f64) -> (f64, f64) {
    let background = median(p);
    let deviations: Vec<f64> = p.iter().map(|v| (v - background).abs()).collect();
    let sigma = (median(&deviations) * 1.4826).max(floor).max(1e-12 * background.abs()).max(f64::MIN_POSITIVE);
    (background, sigma)
}

/// Marks the lone pixels of plane `p` among the `usable` ones: over 8 σ above the largest of
/// their 8 neighbours, which are within 5 σ of the background (the image's edge is never lone).
fn mark_lone(
    p: &[f64],
    width: usize,
    height: usize,
    (background, sigma): (f64, f64),
    usable: &[bool],
    out: &mut [bool],
) {
    for y in 1..height.saturating_sub(1) {
        for x in 1..width.saturating_sub(1) {
            let k = y * width + x;
            let mut neighbour_max = f64::NEG_INFINITY;
            for (dx, dy) in NEIGHBOURS {
                let kk = (y as i64 + dy) as usize * width + (x as i64 + dx) as usize;
                neighbour_max = neighbour_max.max(p[kk]);
            }
            if usable[k] && p[k] - neighbour_max > 8.0 * sigma && neighbour_max - background < 5.0 * sigma {
                out[k] = true;
            }
        }
    }
}

/// The 8 neighbours' offsets.
const NEIGHBOURS: [(i64, i64); 8] = [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)];

/// Marks the pixels of plane `p`'s spread regions: 8-connected regions of at least
/// [`SPREAD_PIXELS`] `allowed` pixels over `threshold`.
fn mark_spread(p: &[f64], width: usize, height: usize, threshold: f64, allowed: &[bool], out: &mut [bool]) {
    let above = |k: usize| allowed[k] && p[k] > threshold;
    let mut seen = vec![false; p.len()];
    for start in 0..p.len() {
        if seen[start] || !above(start) {
            continue;
        }
        // flood fill one region
        let (mut region, mut stack) = (Vec::new(), vec![start]);
        seen[start] = true;
        while let Some(k) = stack.pop() {
            region.push(k);
            let (x, y) = ((k % width) as i64, (k / width) as i64);
            for (dx, dy) in NEIGHBOURS {
                let (nx, ny) = (x + dx, y + dy);
                if nx < 0 || ny < 0 || nx >= width as i64 || ny >= height as i64 {
                    continue;
                }
                let kk = ny as usize * width + nx as usize;
                if !seen[kk] && above(kk) {
                    seen[kk] = true;
                    stack.push(kk);
                }
            }
        }
        if region.len() >= SPREAD_PIXELS {
            for k in region {
                out[k] = true;
            }
        }
    }
}

/// Masks hot pixels by the module docs' rule; returns how many were masked, and the lone
/// pixel kept as the spot when the image holds no spread spot.
fn reject_hot_pixels(
    channels: &[Vec<f64>],
    steps: &[f64],
    frame: &Frame,
    mask: &mut [bool],
) -> (usize, Option<(usize, usize)>) {
    let (width, height, n) = (frame.width, frame.height, frame.width * frame.height);
    // 1. Lone pixels and spread regions, in any channel.
    let (mut lone, mut spread) = (vec![false; n], vec![false; n]);
    let mut excess = vec![0.0; n];
    for (p, step) in channels.iter().zip(steps) {
        let (background, sigma) = noise(p, *step);
        let mut lone_here = vec![false; n];
        mark_lone(p, width, height, (background, sigma), mask, &mut lone_here);
        // a lone pixel on a bright plateau (a disc) is no part of the plateau's region
        let region_pixel: Vec<bool> = frame.allowed.iter().zip(&lone_here).map(|(a, l)| *a && !l).collect();
        mark_spread(p, width, height, quantile(p, 0.1) + SPREAD_SIGMA * sigma, &region_pixel, &mut spread);
        for (l, h) in lone.iter_mut().zip(&lone_here) {
            *l |= h;
        }
        for (e, v) in excess.iter_mut().zip(p) {
            *e += v - background;
        }
    }
    // 2. Candidates: lone, not part of a spread region in another channel.
    let candidates: Vec<usize> = (0..n).filter(|&k| lone[k] && !spread[k]).collect();
    // 3. Without a spread spot, the brightest not marked by the dark frame is the spot.
    let marked = |k: usize| frame.dark_hot.is_some_and(|d| d[k]);
    let spot = if spread.iter().any(|s| *s) {
        None
    } else {
        candidates.iter().copied().filter(|&k| !marked(k)).max_by(|a, b| excess[*a].total_cmp(&excess[*b]))
    };
    // 4. The others are masked.
    let mut count = 0;
    for &k in &candidates {
        if Some(k) != spot {
            mask[k] = false;
            count += 1;
        }
    }
    (count, spot.map(|k| (k % width, k / width)))
}
