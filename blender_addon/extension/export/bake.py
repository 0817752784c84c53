"""Colour and value node chains evaluated here, as Cycles' SVM nodes compute them: constants
(a Mix Color of two colours, a Math node of two values) become a constant, and chains over one
image (an Image Texture through a ColorRamp, RGB Curves, Hue/Saturation/Value, Invert,
Bright/Contrast, Gamma, Mix Color, Math, Map Range, Clamp, RGB to BW, Separate Color) become a
new texture of that image's size, mapping and filtering, whose texels are the chain applied to
Cycles' lookups of the image at several points per texel (Cycles filters the image first, in
its stored values, and applies the chain after; the baked texture, filtered again, follows that
within its finer texels).

``evaluate(socket, kind)`` returns a ``Baked`` value or raises ``Unsupported`` naming the node
it cannot evaluate (procedural textures, coordinates, anything spatial).
"""

from __future__ import annotations

import contextlib

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
        if t == "HUE_SAT":
            return self._hue_saturation(node)
        if t == "CURVE_RGB":
            return self._rgb_curves(node)
        if t == "MAP_RANGE" and node.data_type == "FLOAT" and node.interpolation_type == "LINEAR":
            v = self._input(node, "Value", "float")
            f0, f1 = self._input(node, "From Min", "float"), self._input(node, "From Max", "float")
            t0, t1 = self._input(node, "To Min", "float"), self._input(node, "To Max", "float")
            with np.errstate(divide="ignore", invalid="ignore"):
                r = np.where(f1 != f0, t0 + (v - f0) / np.where(f1 != f0, f1 - f0, 1.0) * (t1 - t0), 0.0)
            return np.clip(r, np.minimum(t0, t1), np.maximum(t0, t1)) if node.clamp else r
        if t == "CLAMP":
            v = self._input(node, "Value", "float")
            lo, hi = self._input(node, "Min", "float"), self._input(node, "Max", "float")
            if node.clamp_type == "RANGE":
                lo, hi = np.minimum(lo, hi), np.maximum(lo, hi)
            return np.minimum(np.maximum(v, lo), hi)
        raise Unsupported(node.bl_label)

    def _hue_saturation(self, node) -> np.ndarray:
        """Cycles' `svm_node_hsv`: hue turned (+ 0.5 is no turn), saturation scaled and
        clamped, value scaled, mixed with the input by the factor, negatives clipped."""
        c = self._input(node, "Color", "color")
        hue = self._input(node, "Hue", "float")[..., 0]
        sat = self._input(node, "Saturation", "float")[..., 0]
        val = self._input(node, "Value", "float")[..., 0]
        fac = self._input(node, "Fac", "float")
        h, s, v = rgb_to_hsv(c)
        h = np.mod(h + hue + 0.5, 1.0)
        s = np.clip(s * sat, 0.0, 1.0)
        out = hsv_to_rgb(h, s, v * val)
        return np.maximum(fac * out + (1.0 - fac) * c, 0.0)

    def _rgb_curves(self, node) -> np.ndarray:
        """RGB Curves as Cycles bakes them: per channel its curve after the combined one, in a
        256-entry table over the curves' x range, looked up linearly (extrapolated beyond)."""
        mapping = node.mapping
        with contextlib.suppress(AttributeError, RuntimeError):
            mapping.initialize()
        curves = list(mapping.curves)
        lo = min([0.0, *(c.points[0].location[0] for c in curves if len(c.points))])
        hi = max([1.0, *(c.points[-1].location[0] for c in curves if len(c.points))])
        xs = lo + np.arange(RAMP_TABLE) / (RAMP_TABLE - 1) * (hi - lo)
        table = np.array(
            [[mapping.evaluate(curves[k], mapping.evaluate(curves[3], float(x))) for k in range(3)] for x in xs],
            np.float32,
        )
        c = self._input(node, "Color", "color")
        fac = self._input(node, "Fac", "float")
        f = (c - lo) / (hi - lo) * (RAMP_TABLE - 1)
        out = np.empty_like(c)
        for k in range(3):
            col = table[:, k]
            fk = f[..., k]
            i = np.clip(np.floor(fk).astype(np.int64), 0, RAMP_TABLE - 2)
            t = fk - i  # beyond the ends: the end segments extended
            out[..., k] = col[i] + (col[i + 1] - col[i]) * t
        return (1.0 - fac) * c + fac * out

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


def rgb_to_hsv(c: np.ndarray):
    """Cycles' `rgb_to_hsv` per texel: (h, s, v), h in [0, 1)."""
    r, g, b = c[..., 0], c[..., 1], c[..., 2]
    cmax = np.maximum(np.maximum(r, g), b)
    cmin = np.minimum(np.minimum(r, g), b)
    delta = cmax - cmin
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(cmax != 0.0, delta / np.where(cmax != 0.0, cmax, 1.0), 0.0)
        d = np.where(delta != 0.0, delta, 1.0)
        cr, cg, cb = (cmax - r) / d, (cmax - g) / d, (cmax - b) / d
    h = np.where(r == cmax, cb - cg, np.where(g == cmax, 2.0 + cr - cb, 4.0 + cg - cr)) / 6.0
    h = np.where(h < 0.0, h + 1.0, h)
    h = np.where(s != 0.0, h, 0.0)
    return h, s, cmax


def hsv_to_rgb(h, s, v) -> np.ndarray:
    """Cycles' `hsv_to_rgb` per texel."""
    h = np.where(h == 1.0, 0.0, h) * 6.0
    i = np.floor(h)
    f = h - i
    p, q, t = v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f))
    i = i.astype(np.int64)
    r = np.choose(np.clip(i, 0, 5), [v, q, p, p, t, v])
    g = np.choose(np.clip(i, 0, 5), [t, v, v, q, p, p])
    b = np.choose(np.clip(i, 0, 5), [p, p, t, v, v, q])
    grey = s == 0.0
    out = np.stack([np.where(grey, v, r), np.where(grey, v, g), np.where(grey, v, b)], axis=-1)
    return out.astype(np.float32)


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
