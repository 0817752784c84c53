//! Capture images as the fit sees them: linear, dark frame subtracted, one plane per channel
//! (one for a single wavelength, three for `rgb`), with a mask of the pixels that count.
//!
//! | step | what |
//! |---|---|
//! | read | EXR (`R`,`G`,`B` or `Y` channels, first layer) or floating-point TIFF (grey or RGB; linear values, no clipping level), 16-bit PNG or TIFF (values 0…65535), 8-bit PNG, TIFF or JPEG (0…255) |
//! | clip | pixels at or above `saturation` in any channel are masked (default: the integer format's maximum, 65535 or 255; 245 for JPEG, whose ringing keeps a clipped core a few levels below 255; none for EXR and float TIFF) |
//! | decode | `transfer = "srgb"`: the sRGB curve is undone on value / maximum (an 8-bit file left at the default transfer is read as linear, with a warning: [`transfer_warning`]) |
//! | dark | the dark frame (same size, and the same kind of file: 8-bit, 16-bit or floating point) is subtracted |
//! | hot pixels | a pixel over 8 noise σ above the largest of its 8 neighbours, which are themselves near the background, is masked, however bright (a point source's image spreads over several pixels) |
//!
//! Errors name the manifest, the capture and the field (`image`, `dark_frame`, `mask`,
//! `wavelength_nm`) as well as the file: `m.toml: capture[2] (p02.png).dark_frame: dark32.png: …`.
//! | mask | the manifest's mask (same size): zero = masked |
//! | mono | a single-wavelength capture of an RGB file uses the channels' mean |

use crate::error::{Error, Result};
use crate::manifest::{Capture, Transfer, Wavelength};
use std::path::Path;

/// The default clipping level of a lossy 8-bit file (JPEG): its ringing around a clipped core
/// keeps the plateau a few levels below 255 (249 to 254 at quality 95), where 255 would mask part of it or nothing.
pub const JPEG_SATURATION: f64 = 245.0;

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
    // 2. Linear values.
    let kind = raw.kind();
    let mut planes = raw.planes;
    if capture.transfer == Transfer::Srgb {
        let max = raw.max_value.unwrap_or(1.0);
        for p in &mut planes {
            for v in p.iter_mut() {
                *v = srgb_to_linear(*v / max) * max;
            }
        }
    }
    // 3. Dark frame.
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
        for (c, p) in planes.iter_mut().enumerate() {
            let d = &dark.planes[c.min(dark.planes.len() - 1)];
            for (v, dv) in p.iter_mut().zip(d) {
                *v -= dv;
            }
        }
    }
    // 4. The manifest's mask.
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
        for (k, v) in mask.iter_mut().enumerate() {
            *v &= m.planes.iter().any(|p| p[k] != 0.0);
        }
    }
    // 5. Channels the fit uses.
    let channels = match (capture.wavelength, planes.len()) {
        (Wavelength::Rgb, 3) => planes,
        (Wavelength::Rgb, _) => {
            return Err(capture_err(
                capture,
                "wavelength_nm",
                path,
                "wavelength_nm = \"rgb\" needs a colour image (R, G, B), this one has one channel",
            ))
        }
        (Wavelength::Mono(_), 1) => planes,
        (Wavelength::Mono(_), _) => {
            vec![(0..n).map(|k| planes.iter().map(|p| p[k]).sum::<f64>() / planes.len() as f64).collect()]
        }
    };
    for (c, p) in channels.iter().enumerate() {
        if let Some(k) = p.iter().position(|v| !v.is_finite()) {
            let (x, y) = (k % width, k / width);
            return Err(capture_err(capture, "image", path, format!("pixel ({x}, {y}) of channel {c} is not finite")));
        }
    }
    // 6. Hot pixels.
    let hot = reject_hot_pixels(&channels, width, height, &mut mask);
    Ok(CaptureImage { width, height, channels, mask, clipped, hot, eight_bit })
}

/// Masks isolated hot pixels: far above all 8 neighbours while those are at the background,
/// however bright (a hot pixel may outshine a faint spot's peak; a point source's image
/// spreads over several pixels, so its peak's neighbours stand above the background). Returns
/// how many were masked.
fn reject_hot_pixels(channels: &[Vec<f64>], width: usize, height: usize, mask: &mut [bool]) -> usize {
    let mut count = 0;
    for p in channels {
        // background level and noise from the image's lower half of values
        let mut sorted: Vec<f64> = p.clone();
        sorted.sort_by(|a, b| a.total_cmp(b));
        let median = sorted[sorted.len() / 2];
        let mad = {
            let mut dev: Vec<f64> = sorted.iter().map(|v| (v - median).abs()).collect();
            dev.sort_by(|a, b| a.total_cmp(b));
            dev[dev.len() / 2] * 1.4826
        };
        let sigma = mad.max(1e-12 * median.abs()).max(f64::MIN_POSITIVE);
        for y in 1..height.saturating_sub(1) {
            for x in 1..width.saturating_sub(1) {
                let k = y * width + x;
                let v = p[k];
                let mut neighbour_max = f64::NEG_INFINITY;
                for (dx, dy) in [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)] {
                    let kk = (y as i64 + dy) as usize * width + (x as i64 + dx) as usize;
                    neighbour_max = neighbour_max.max(p[kk]);
                }
                if v - neighbour_max > 8.0 * sigma && neighbour_max - median < 5.0 * sigma && mask[k] {
                    mask[k] = false;
                    count += 1;
                }
            }
        }
    }
    count
}
