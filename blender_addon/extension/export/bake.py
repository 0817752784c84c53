"""Colour and value node chains evaluated here, as Cycles' SVM nodes compute them: constants
(a Mix Color of two colours, a Math node of two values) become a constant, and chains over one
image (an Image Texture through a ColorRamp, Invert, Bright/Contrast, Gamma, Mix Color, Math,
RGB to BW, Separate Color) become a new texture of that image's size, mapping and filtering,
whose texels are the chain applied to Cycles' lookups of the image at several points per texel
(Cycles filters the image first, in its stored values, and applies the chain after; the baked
texture, filtered again, follows that within its finer texels).

``evaluate(socket, kind)`` returns a ``Baked`` value or raises ``Unsupported`` naming the node
it cannot evaluate (procedural textures, coordinates, anything spatial).
"""

from __future__ import annotations

import numpy as np

from .images import image_pixels, srgb_byte_image, srgb_to_linear
from .nodes import socket_value, source

# Blender's scene-linear Rec.709 luminance (Cycles' `linear_rgb_to_gray`)
LUMINANCE = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
RAMP_TABLE = 256  # Cycles' ramp table size


class Unsupported(Exception):
    """A node the evaluation cannot follow (its label is the message)."""


class Baked:
    """A value: `value` has a trailing axis of 3 (colour) or 1 (scalar), over an image's texels
    (H, W, C) or constant (C,); `tex_node` is the Image Texture it came from (None: constant)."""

    def __init__(self, value: np.ndarray, tex_node=None):
        self.value = value
        self.tex_node = tex_node

    @property
    def constant(self) -> bool:
        return self.tex_node is None


class Evaluator:
    """Evaluates sockets of one material (reading each image once)."""

    def __init__(self, notes, what: str):
        self.notes = notes
        self.what = what
        self.tex_node = None
        self.shape = None
        self._pixels: dict = {}

    def evaluate(self, socket, kind: str) -> Baked:
        """`socket`'s value as a colour (`kind` "color", 3 channels) or a scalar ("float"),
        non-negative and finite (what a material input takes; Cycles clamps colours it
        shades with to the same)."""
        v = self._socket(socket, kind)
        v = np.nan_to_num(np.maximum(v, 0.0), nan=0.0, posinf=0.0).astype(np.float32)
        return Baked(v, self.tex_node if v.ndim > 1 else None)

    # -- sockets and conversions

    def _socket(self, socket, kind: str) -> np.ndarray:
        src = source(socket)
        if src is None:
            v = socket_value(socket, 0.0)
            v = np.atleast_1d(np.asarray(v, dtype=np.float32))
            return self._convert(v[:3] if v.size >= 3 else v[:1], kind)
        node, out = src
        return self._convert(self._output(node, out), kind)

    def _input(self, node, key, kind: str) -> np.ndarray:
        """Input `key` (name or index) of `node`."""
        sock = node.inputs[key] if isinstance(key, int) else _enabled(node, key)
        return self._socket(sock, kind)

    @staticmethod
    def _convert(v: np.ndarray, kind: str) -> np.ndarray:
        c = v.shape[-1]
        if kind == "color":
            return v if c == 3 else np.repeat(v[..., :1], 3, axis=-1)
        return v if c == 1 else (v[..., :3] @ LUMINANCE)[..., None].astype(np.float32)

    # -- nodes

    def _output(self, node, out) -> np.ndarray:
        t = node.type
        if t == "TEX_IMAGE":
            px = self._image(node)
            return px[..., 3:4] if out.name == "Alpha" else px[..., :3]
        if t in ("RGB", "VALUE"):
            v = np.atleast_1d(np.asarray(tuple(out.default_value) if t == "RGB" else out.default_value, np.float32))
            return v[:3]
        if t == "MIX" and node.data_type in ("RGBA", "FLOAT"):
            kind = "color" if node.data_type == "RGBA" else "float"
            suffix = "Color" if kind == "color" else "Float"
            fac = self._input(node, "Factor_Float", "float")
            if node.clamp_factor:
                fac = np.clip(fac, 0.0, 1.0)
            a = self._input(node, "A_" + suffix, kind)
            b = self._input(node, "B_" + suffix, kind)
            blend = node.blend_type if kind == "color" else "MIX"
            r = _blend(blend, fac, a, b, node.bl_label)
            return np.clip(r, 0.0, 1.0) if node.clamp_result else r
        if t == "MIX_RGB":
            fac = np.clip(self._input(node, 0, "float"), 0.0, 1.0)
            a, b = self._input(node, 1, "color"), self._input(node, 2, "color")
            r = _blend(node.blend_type, fac, a, b, node.bl_label)
            return np.clip(r, 0.0, 1.0) if node.use_clamp else r
        if t == "INVERT":
            fac = self._input(node, "Fac", "float")
            c = self._input(node, "Color", "color")
            return c + (1.0 - 2.0 * c) * fac
        if t == "GAMMA":
            c = self._input(node, "Color", "color")
            g = self._input(node, "Gamma", "float")
            return np.where(c > 0.0, np.power(np.maximum(c, 0.0), g), c)
        if t == "BRIGHTCONTRAST":
            c = self._input(node, "Color", "color")
            bright = self._input(node, "Bright", "float")
            contrast = self._input(node, "Contrast", "float")
            return np.maximum((1.0 + contrast) * c + (bright - contrast * 0.5), 0.0)
        if t == "VALTORGB":
            return self._ramp(node, out)
        if t == "RGBTOBW":
            return self._input(node, "Color", "float")
        if t in ("SEPARATE_COLOR", "SEPRGB", "SEPARATE_RGB"):
            if getattr(node, "mode", "RGB") != "RGB":
                raise Unsupported(f"{node.bl_label} ({node.mode})")
            c = self._input(node, 0, "color")
            k = {"Red": 0, "R": 0, "Green": 1, "G": 1, "Blue": 2, "B": 2}[out.name]
            return c[..., k : k + 1]
        if t == "MATH":
            return self._math(node)
        raise Unsupported(node.bl_label)

    def _image(self, node) -> np.ndarray:
        """(…, 4) linear values of an Image Texture node (one image size per evaluation): its
        texels for Closest interpolation; else Cycles' lookup (bilinear, in the stored values,
        so before decoding an 8-bit sRGB image) at `upsampling(h, w)` points per texel and axis,
        so that the chain's result, filtered again where rendered, stays close to Cycles'
        chain applied after filtering."""
        img = node.image
        if img is None:
            raise Unsupported("Image Texture without an image")
        key = (img.name_full, node.interpolation, node.extension)
        if key not in self._pixels:
            encoded = srgb_byte_image(img)
            px = image_pixels(img, self.notes, self.what, keep_srgb=encoded)
            if px is None:
                raise Unsupported(f"image '{img.name}' without pixels")
            if node.interpolation != "Closest":
                k = upsampling(*px.shape[:2])
                px = bilinear_upsample(px, k, wrap=node.extension == "REPEAT")
            if encoded:
                px[..., :3] = srgb_to_linear(px[..., :3])
            self._pixels[key] = px
        px = self._pixels[key]
        if self.tex_node is None:
            self.tex_node, self.shape = node, px.shape
        elif px.shape != self.shape:
            raise Unsupported("Image Textures of different sizes")
        return px

    def _ramp(self, node, out) -> np.ndarray:
        """ColorRamp: Blender's ramp in a 256-entry table, looked up as Cycles does (linear
        between entries, or the entry below for Constant interpolation)."""
        ramp = node.color_ramp
        table = np.array([tuple(ramp.evaluate(i / (RAMP_TABLE - 1))) for i in range(RAMP_TABLE)], np.float32)
        f = np.clip(self._input(node, "Fac", "float")[..., 0], 0.0, 1.0) * (RAMP_TABLE - 1)
        i = np.clip(f.astype(np.int64), 0, RAMP_TABLE - 1)
        v = table[i]
        if ramp.interpolation != "CONSTANT":
            t = (f - i)[..., None]
            v = v + (table[np.minimum(i + 1, RAMP_TABLE - 1)] - v) * t
        return v[..., 3:4] if out.name == "Alpha" else v[..., :3]

    def _math(self, node) -> np.ndarray:
        op = node.operation
        a = self._input(node, 0, "float")
        b = self._input(node, 1, "float")
        with np.errstate(divide="ignore", invalid="ignore"):
            if op == "ADD":
                r = a + b
            elif op == "SUBTRACT":
                r = a - b
            elif op == "MULTIPLY":
                r = a * b
            elif op == "DIVIDE":
                r = np.where(b != 0.0, a / np.where(b != 0.0, b, 1.0), 0.0)
            elif op == "MULTIPLY_ADD":
                r = a * b + self._input(node, 2, "float")
            elif op == "POWER":
                r = np.where(a >= 0.0, np.power(np.maximum(a, 0.0), b), 0.0)
            elif op == "MINIMUM":
                r = np.minimum(a, b)
            elif op == "MAXIMUM":
                r = np.maximum(a, b)
            elif op == "ABSOLUTE":
                r = np.abs(a)
            else:
                raise Unsupported(f"Math ({op.replace('_', ' ').title()})")
        r = r.astype(np.float32)
        return np.clip(r, 0.0, 1.0) if node.use_clamp else r


def upsampling(h: int, w: int) -> int:
    """Points per texel and axis for a baked chain over an h × w image: 4 up to 512², 2 up to
    1024², else 1 (at most 4 M baked texels)."""
    for k in (4, 2):
        if h * w * k * k <= 4 * 1024 * 1024:
            return k
    return 1


def bilinear_upsample(px: np.ndarray, k: int, wrap: bool) -> np.ndarray:
    """Bilinear lookups (texel centres at (i + 0.5)/n, as Cycles) of `px` at k × k points per
    texel, at their centres; `wrap` repeats the image across its borders, else edges extend."""
    if k == 1:
        return px.copy()
    h, w = px.shape[:2]

    def axis(n):
        x = (np.arange(n * k) + 0.5) / k - 0.5
        i0 = np.floor(x).astype(np.int64)
        f = (x - i0).astype(np.float32)
        i1 = i0 + 1
        if wrap:
            i0, i1 = i0 % n, i1 % n
        else:
            i0, i1 = np.clip(i0, 0, n - 1), np.clip(i1, 0, n - 1)
        return i0, i1, f

    y0, y1, fy = axis(h)
    x0, x1, fx = axis(w)
    fy, fx = fy[:, None, None], fx[None, :, None]
    top = px[y0][:, x0] * (1.0 - fx) + px[y0][:, x1] * fx
    bottom = px[y1][:, x0] * (1.0 - fx) + px[y1][:, x1] * fx
    return (top * (1.0 - fy) + bottom * fy).astype(np.float32)


def _enabled(node, identifier):
    """The input of `node` with this identifier (the Mix node has one per data type)."""
    for s in node.inputs:
        if s.identifier == identifier:
            return s
    raise Unsupported(f"{node.bl_label} without input {identifier}")


def _blend(blend: str, t, a, b, label: str):
    """Cycles' `svm_mix` for the blend types it shares with Blender's Mix Color."""
    tm = 1.0 - t
    with np.errstate(divide="ignore", invalid="ignore"):
        if blend == "MIX":
            return tm * a + t * b
        if blend == "MULTIPLY":
            return a * (tm + t * b)
        if blend == "ADD":
            return a + t * b
        if blend == "SUBTRACT":
            return a - t * b
        if blend == "SCREEN":
            return 1.0 - (tm + t * (1.0 - b)) * (1.0 - a)
        if blend == "DIVIDE":
            return np.where(b != 0.0, tm * a + t * a / np.where(b != 0.0, b, 1.0), a)
        if blend == "DIFFERENCE":
            return tm * a + t * np.abs(a - b)
        if blend == "DARKEN":
            return tm * a + t * np.minimum(a, b)
        if blend == "LIGHTEN":
            return tm * a + t * np.maximum(a, b)
        if blend == "OVERLAY":
            low = a * (tm + 2.0 * t * b)
            high = 1.0 - (tm + 2.0 * t * (1.0 - b)) * (1.0 - a)
            return np.where(a < 0.5, low, high)
    raise Unsupported(f"{label} ({blend.title()})")
