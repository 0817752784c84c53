//! Output files: EXR (RGBA plus optional depth, normal and albedo channels, and metadata) with
//! the `exr` crate, and a PNG preview (exposure, sRGB or filmic tone mapping). Both are written
//! to a temporary name and renamed.

use super::Image;
use crate::error::{Error, Result};
use crate::scene::texture::linear_to_srgb;
use exr::prelude::*;
use petzval_optics::write_atomic;
use std::path::Path;

/// Which extra EXR channels to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ExrLayers {
    /// `Z` (depth in metres).
    pub depth: bool,
    /// `normal.X/Y/Z`.
    pub normal: bool,
    /// `albedo.R/G/B`.
    pub albedo: bool,
}

/// Render metadata stored in the EXR header (as `petzval/KEY` text attributes).
pub type Metadata = Vec<(String, String)>;

/// Tone mapping for the PNG preview.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ToneMap {
    /// Clamp and apply the sRGB transfer function ("Standard" in Blender).
    #[default]
    Srgb,
    /// A filmic curve (Narkowicz's ACES fit) before sRGB encoding.
    Filmic,
}

/// An EXR text attribute (or name) holding `s` as UTF-8, as OpenEXR's libraries read strings
/// (NULs, which end a string in the header, become '?').
fn text(s: &str) -> Text {
    let clean: String = s.chars().map(|c| if c == '\0' { '?' } else { c }).collect();
    Text::from_slice_unchecked(clean.as_bytes())
}

/// Where an EXR's pixels sit in its frame: the display window (the whole frame) and the data
/// window's top-left pixel, which is negative or beyond the frame for overscan; and the pixel
/// aspect ratio (OpenEXR's `pixelAspectRatio`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExrFrame {
    /// Frame (display window) width in pixels.
    pub display_width: u32,
    /// Frame (display window) height in pixels.
    pub display_height: u32,
    /// The image's first column in the frame.
    pub origin_x: i32,
    /// The image's first row in the frame (row 0 at the top).
    pub origin_y: i32,
    /// Width over height of one pixel.
    pub pixel_aspect: f32,
}

/// Writes `image` as an EXR file whose data window is the whole frame.
pub fn write_exr(path: &Path, image: &Image, layers: ExrLayers, metadata: &Metadata) -> Result<()> {
    let frame = ExrFrame {
        display_width: image.width,
        display_height: image.height,
        origin_x: 0,
        origin_y: 0,
        pixel_aspect: 1.0,
    };
    write_exr_framed(path, image, layers, metadata, &frame)
}

/// Writes `image` as an EXR file placed in `frame` (data window inside the display window for
/// a crop, reaching beyond it for overscan).
pub fn write_exr_framed(
    path: &Path,
    image: &Image,
    layers: ExrLayers,
    metadata: &Metadata,
    frame: &ExrFrame,
) -> Result<()> {
    let (w, h) = (image.width as usize, image.height as usize);
    let chan =
        |name: &str, f: &dyn Fn(usize) -> f32| AnyChannel::new(name, FlatSamples::F32((0..w * h).map(f).collect()));
    let mut channels: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
    for (k, name) in ["R", "G", "B", "A"].iter().enumerate() {
        channels.push(chan(name, &|i| image.rgba[i][k]));
    }
    if layers.depth {
        channels.push(chan("Z", &|i| image.depth[i]));
    }
    if layers.normal {
        for (k, name) in ["normal.X", "normal.Y", "normal.Z"].iter().enumerate() {
            channels.push(chan(name, &|i| image.normal[i][k]));
        }
    }
    if layers.albedo {
        for (k, name) in ["albedo.R", "albedo.G", "albedo.B"].iter().enumerate() {
            channels.push(chan(name, &|i| image.albedo[i][k]));
        }
    }
    let attributes = LayerAttributes { layer_position: Vec2(frame.origin_x, frame.origin_y), ..Default::default() };
    let layer = Layer::new((w, h), attributes, Encoding::SMALL_LOSSLESS, AnyChannels::sort(channels));
    let mut img = exr::image::Image::from_layer(layer);
    img.attributes.display_window =
        IntegerBounds::from_dimensions((frame.display_width as usize, frame.display_height as usize));
    img.attributes.pixel_aspect = frame.pixel_aspect;
    for (k, v) in metadata {
        img.attributes.other.insert(text(&format!("petzval/{k}")), AttributeValue::Text(text(v)));
    }
    let mut buf = std::io::Cursor::new(Vec::new());
    img.write().to_buffered(&mut buf).map_err(|e| Error::io(path, std::io::Error::other(e.to_string())))?;
    Ok(write_atomic(path, buf.get_ref())?)
}

/// Narkowicz's fit of the ACES filmic curve.
fn filmic(x: f32) -> f32 {
    let (a, b, c, d, e) = (2.51, 0.03, 2.43, 0.59, 0.14);
    ((x * (a * x + b)) / (x * (c * x + d) + e)).clamp(0.0, 1.0)
}

/// Writes an 8-bit sRGB PNG preview with `exposure_stops` and tone mapping.
pub fn write_png(path: &Path, image: &Image, exposure_stops: f32, tone: ToneMap) -> Result<()> {
    let scale = 2f32.powf(exposure_stops);
    let mut bytes = Vec::with_capacity(image.rgba.len() * 3);
    for p in &image.rgba {
        for c in &p[..3] {
            let v = (c * scale).max(0.0);
            let v = match tone {
                ToneMap::Srgb => v.min(1.0),
                ToneMap::Filmic => filmic(v),
            };
            bytes.push((linear_to_srgb(v) * 255.0 + 0.5).clamp(0.0, 255.0) as u8);
        }
    }
    let buf = image::RgbImage::from_raw(image.width, image.height, bytes)
        .ok_or_else(|| Error::io(path, std::io::Error::other("image size mismatch")))?;
    let mut out = std::io::Cursor::new(Vec::new());
    buf.write_to(&mut out, image::ImageFormat::Png)
        .map_err(|e| Error::io(path, std::io::Error::other(e.to_string())))?;
    Ok(write_atomic(path, out.get_ref())?)
}
