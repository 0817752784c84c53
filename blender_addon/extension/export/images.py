"""Blender images as petzval texture pixels: (H, W, 4) float32, image rows top first, linear
colour (byte images tagged sRGB decoded here)."""

from __future__ import annotations

import numpy as np

MISSING_TEXTURE = (1.0, 0.0, 1.0, 1.0)  # magenta: a missing image shows

LINEAR_SPACES = {
    "Linear Rec.709",
    "Linear",
    "Non-Color",
    "Raw",
    "Linear CIE-XYZ E",
    "Linear Rec.2020",
    "ACEScg",
    "ACES2065-1",
}


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((np.maximum(c, 0.04045) + 0.055) / 1.055) ** 2.4).astype(np.float32)


def srgb_byte_image(img) -> bool:
    """A byte image whose colours are sRGB-encoded (tagged sRGB, or a space we decode as sRGB)."""
    return not img.is_float and img.colorspace_settings.name not in LINEAR_SPACES


def image_pixels(img, notes, what: str, keep_srgb: bool = False):
    """(H, W, 4) float32 linear pixels of a Blender image, row 0 at the top; None if it has no
    pixels (missing file). Byte images tagged sRGB are decoded here (``Image.pixels`` gives the
    stored byte values / 255), unless ``keep_srgb`` (then they stay encoded, for a texture that
    petzval filters and then decodes as Cycles does); float images are already scene linear in
    Blender's memory."""
    try:
        w, h = img.size
    except Exception:
        w = h = 0
    if w == 0 or h == 0:
        notes.warn(f"{what}: image '{img.name}' has no pixels (missing file '{img.filepath}'?), shown magenta")
        return None
    c = img.channels
    buf = np.empty(w * h * c, dtype=np.float32)
    img.pixels.foreach_get(buf)
    px = buf.reshape(h, w, c)[::-1]
    if c == 4:
        out = np.array(px, dtype=np.float32)
    else:
        out = np.ones((h, w, 4), dtype=np.float32)
        if c >= 3:
            out[..., :3] = px[..., :3]
        else:
            out[..., :3] = px[..., :1]
        if c == 2:
            out[..., 3] = px[..., 1]
    if not img.is_float:
        cs = img.colorspace_settings.name
        if cs not in LINEAR_SPACES and cs != "sRGB":
            notes.warn(f"image '{img.name}': colour space '{cs}' decoded as sRGB")
        if cs not in LINEAR_SPACES and not keep_srgb:
            out[..., :3] = srgb_to_linear(out[..., :3])
    return np.ascontiguousarray(out)
