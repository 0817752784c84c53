//! Textures: RGBA f32 texels with glTF wrap modes and bilinear filtering. Texels are linear,
//! except where `srgb_encoded` keeps an 8-bit sRGB image's encoded values, decoded after
//! filtering, as Cycles does with byte images (filtering the encoded values brightens a texel
//! edge's blend, up to ~5 % on a checker). The add-on does that for Blender's images, and the
//! glTF and USD loaders for files Blender wrote; other glTF files' and USD stages' images are
//! decoded before filtering, as the glTF spec asks and USD's other renderers do.

use glam::{Vec2, Vec4};

/// glTF wrap mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wrap {
    /// Repeat.
    Repeat,
    /// Clamp to the edge texel.
    ClampToEdge,
    /// Mirrored repeat.
    MirroredRepeat,
}

/// A decoded texture (colour textures are sRGB-decoded to linear at load).
#[derive(Debug, Clone, PartialEq)]
pub struct Texture {
    /// Name or file (for reports).
    pub name: String,
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// Row-major texels, row 0 at the top (v = 0 in glTF).
    pub texels: Vec<Vec4>,
    /// Wrap in u.
    pub wrap_s: Wrap,
    /// Wrap in v.
    pub wrap_t: Wrap,
    /// Bilinear (true) or nearest (false) filtering.
    pub bilinear: bool,
    /// The RGB texels are sRGB-encoded: filtered, then decoded (alpha is linear).
    pub srgb_encoded: bool,
}

impl Texture {
    /// A 1×1 texture of one value (the visible fallback for a missing image is magenta).
    pub fn constant(name: &str, value: Vec4) -> Self {
        Texture {
            name: name.into(),
            width: 1,
            height: 1,
            texels: vec![value],
            wrap_s: Wrap::Repeat,
            wrap_t: Wrap::Repeat,
            bilinear: false,
            srgb_encoded: false,
        }
    }

    fn wrap(i: i64, n: u32, mode: Wrap) -> u32 {
        let n = n as i64;
        let i = match mode {
            Wrap::Repeat => i.rem_euclid(n),
            Wrap::ClampToEdge => i.clamp(0, n - 1),
            Wrap::MirroredRepeat => {
                let m = i.rem_euclid(2 * n);
                if m < n {
                    m
                } else {
                    2 * n - 1 - m
                }
            }
        };
        i as u32
    }

    fn texel(&self, x: i64, y: i64) -> Vec4 {
        let x = Self::wrap(x, self.width, self.wrap_s);
        let y = Self::wrap(y, self.height, self.wrap_t);
        self.texels[(y * self.width + x) as usize]
    }

    /// Samples at `uv` (glTF convention: (0,0) = top left of the image): linear RGBA.
    pub fn sample(&self, uv: Vec2) -> Vec4 {
        let v = self.filtered(uv);
        if self.srgb_encoded {
            Vec4::new(srgb_to_linear(v.x), srgb_to_linear(v.y), srgb_to_linear(v.z), v.w)
        } else {
            v
        }
    }

    /// The filtered texel value at `uv`, as stored.
    fn filtered(&self, uv: Vec2) -> Vec4 {
        if !uv.is_finite() {
            return self.texels[0];
        }
        let x = uv.x as f64 * self.width as f64 - 0.5;
        let y = uv.y as f64 * self.height as f64 - 0.5;
        if !self.bilinear {
            return self.texel((x + 0.5).floor() as i64, (y + 0.5).floor() as i64);
        }
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let a = self.texel(x0, y0).lerp(self.texel(x0 + 1, y0), fx);
        let b = self.texel(x0, y0 + 1).lerp(self.texel(x0 + 1, y0 + 1), fx);
        a.lerp(b, fy)
    }
}

/// sRGB transfer function to linear.
#[inline]
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear to the sRGB transfer function.
#[inline]
pub fn linear_to_srgb(c: f32) -> f32 {
    if c <= 0.0031308 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An 8-bit sRGB texture filtered bilinearly blends the encoded values and decodes the
    /// blend (as Cycles does with byte images): halfway between black and white is
    /// decode(0.5) = 0.214, not 0.5; its texel centres and alpha are unchanged.
    #[test]
    fn encoded_textures_are_filtered_then_decoded() {
        let mut t = Texture::constant("t", Vec4::ZERO);
        t.width = 2;
        t.texels = vec![Vec4::new(0.0, 0.0, 0.0, 0.0), Vec4::ONE];
        t.bilinear = true;
        t.wrap_s = Wrap::ClampToEdge;
        let linear = t.sample(Vec2::new(0.5, 0.5));
        assert!((linear - Vec4::splat(0.5)).abs().max_element() < 1e-6, "{linear}");
        t.srgb_encoded = true;
        let blend = t.sample(Vec2::new(0.5, 0.5));
        let half = srgb_to_linear(0.5);
        assert!((blend - Vec4::new(half, half, half, 0.5)).abs().max_element() < 1e-6, "{blend}");
        assert_eq!(t.sample(Vec2::new(0.75, 0.5)), Vec4::ONE);
    }
}
