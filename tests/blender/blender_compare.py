"""Image statistics for the Cycles comparison (numpy only; EXR files read with OpenEXR).

Conventions: images are float64 arrays (height, width, 3) of linear Rec.709 RGB, row 0 at the
top; image coordinates x to the right, y *up* (angles counter-clockwise as seen on screen).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

# Rec. 709 luminance weights.
LUM = np.array([0.2126, 0.7152, 0.0722])


def read_exr(path: Path) -> dict[str, np.ndarray]:
    """Every channel of a scanline EXR as a float64 (height, width) array, by channel name."""
    import OpenEXR

    with OpenEXR.File(str(path), separate_channels=True) as f:
        return {name: np.asarray(ch.pixels, dtype=np.float64) for name, ch in f.channels().items()}


def read_rgb(path: Path) -> np.ndarray:
    ch = read_exr(path)
    missing = [c for c in "RGB" if c not in ch]
    if missing:
        raise ValueError(f"{path}: no channel(s) {missing}; has {sorted(ch)}")
    return np.stack([ch["R"], ch["G"], ch["B"]], axis=-1)


def luminance(img: np.ndarray) -> np.ndarray:
    return img @ LUM


def block_sum(a: np.ndarray, b: int) -> np.ndarray:
    """Sums over b x b blocks of a (h, w[, ...]) array (h, w multiples of b)."""
    h, w = a.shape[:2]
    if h % b or w % b:
        raise ValueError(f"{h}x{w} is not a multiple of the block size {b}")
    return a.reshape(h // b, b, w // b, b, *a.shape[2:]).sum(axis=(1, 3))


@dataclass
class BlockComparison:
    """Block means of two renderers (each the average of two seeds) and their noise.

    For a renderer X rendered with seeds 0 and 1, the per-pixel variance of the two-seed average
    X̄ = (X0 + X1)/2 is estimated by (X0 − X1)²/4 (one degree of freedom per pixel); a block's
    variance is the sum over its pixels divided by n² (pixels are independent: both renderers
    importance-sample the pixel filter, so a sample lands in one pixel only). Then

        z_b = (P̄_b − C̄_b) / sqrt(var P̄_b + var C̄_b)

    is ~N(0, 1) per block when both converge to the same image. Blocks that are exactly constant
    in every render (the world seen directly) have no sampling variance at all; there the two
    renderers still differ by float32 rounding, so σ has a floor of 1e-5 of the block mean
    (:data:`FLOAT_FLOOR`), added in quadrature.
    """

    block: int
    mean_c: np.ndarray  # (by, bx) block means, Cycles
    mean_p: np.ndarray  # petzval
    sigma: np.ndarray  # std of (P̄_b − C̄_b)
    z: np.ndarray
    rel_noise_c: float  # median relative std of a Cycles block mean (two-seed average)
    rel_noise_p: float

    @property
    def diff(self) -> np.ndarray:
        return self.mean_p - self.mean_c

    def flagged(self, k_sigma: float, rel_tol: float, abs_tol: float) -> np.ndarray:
        """Blocks that differ by more than k·σ + rel_tol·|C̄| + abs_tol."""
        return np.abs(self.diff) > k_sigma * self.sigma + rel_tol * np.abs(self.mean_c) + abs_tol


FLOAT_FLOOR = 1e-5


def block_sigma(var_c: np.ndarray, var_p: np.ndarray, mean_c: np.ndarray) -> np.ndarray:
    """σ of a block difference: the two variances plus the float32 floor, in quadrature."""
    return np.sqrt(var_c + var_p + (FLOAT_FLOOR * mean_c) ** 2)


def z_scores(mean_p: np.ndarray, mean_c: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(sigma > 0, (mean_p - mean_c) / sigma, 0.0)


def compare_blocks(c0, c1, p0, p1, block: int = 8, channel=luminance) -> BlockComparison:
    c0, c1, p0, p1 = (channel(x) for x in (c0, c1, p0, p1))
    n = block * block
    cm = block_sum((c0 + c1) / 2, block) / n
    pm = block_sum((p0 + p1) / 2, block) / n
    vc = block_sum((c0 - c1) ** 2 / 4, block) / n**2
    vp = block_sum((p0 - p1) ** 2 / 4, block) / n**2
    sigma = block_sigma(vc, vp, cm)
    z = z_scores(pm, cm, sigma)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel_c = np.sqrt(vc) / np.abs(cm)
        rel_p = np.sqrt(vp) / np.abs(pm)
    return BlockComparison(
        block=block,
        mean_c=cm,
        mean_p=pm,
        sigma=sigma,
        z=z,
        rel_noise_c=float(np.nanmedian(rel_c)),
        rel_noise_p=float(np.nanmedian(rel_p)),
    )


def mean_ratio(p: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Per-channel ratio of image means."""
    return p.mean(axis=(0, 1)) / c.mean(axis=(0, 1))


# ------------------------------------------------------------------------------------------
# Bokeh (the image of a small emitter far out of focus)


@dataclass
class Bokeh:
    flux: float  # sum of the background-subtracted luminance
    cx: float  # centroid, pixels (x right from the left edge, y down from the top), pixel centres at +0.5
    cy: float
    r_gyration: float  # sqrt(E[r²]) about the centroid, pixels
    vertex_angle_deg: (
        float  # 6-fold (for N blades: N-fold) orientation: angle of a polygon vertex, CCW from +x, mod 360/N
    )
    harmonic: float  # relative strength of the N-fold harmonic (0 for a circle)


def measure_bokeh(img: np.ndarray, centre_xy: tuple[float, float], radius: float, blades: int) -> Bokeh:
    """Moments of the blob around `centre_xy` (pixels) within `radius`, background (the median
    of the ring radius..1.3 radius) subtracted. The N-fold orientation is the phase of
    Σ I·r²·exp(i N θ) / N (θ counter-clockwise with y up): for a regular N-gon its vertices lie
    where that harmonic peaks."""
    lum = luminance(img)
    h, w = lum.shape
    ys, xs = np.mgrid[0:h, 0:w]
    px, py = xs + 0.5, ys + 0.5
    cx, cy = centre_xy
    for _ in range(3):  # re-centre on the centroid
        r = np.hypot(px - cx, py - cy)
        ring = (r >= radius) & (r < 1.3 * radius)
        bg = float(np.median(lum[ring]))
        inside = r < radius
        wgt = np.where(inside, lum - bg, 0.0)
        flux = float(wgt.sum())
        cx, cy = float((wgt * px).sum() / flux), float((wgt * py).sum() / flux)
    dx, dy = px - cx, -(py - cy)
    r2 = dx * dx + dy * dy
    rg = math.sqrt(float((wgt * r2).sum()) / flux)
    theta = np.arctan2(dy, dx)
    hcoef = complex((wgt * r2 * np.exp(1j * blades * theta)).sum()) / float((wgt * r2).sum())
    ang = math.degrees(math.atan2(hcoef.imag, hcoef.real)) / blades % (360.0 / blades)
    return Bokeh(flux=flux, cx=cx, cy=cy, r_gyration=rg, vertex_angle_deg=ang, harmonic=abs(hcoef))


def angle_diff_mod(a: float, b: float, period: float) -> float:
    """a − b wrapped into [−period/2, period/2)."""
    return (a - b + period / 2) % period - period / 2


def polygon_r_gyration(circumradius: float, n: int) -> float:
    """sqrt(E[r²]) of a uniform regular n-gon of the given circumradius."""
    # E[r²] of a regular polygon = R²·(2 + cos(2π/n)) / 6 ... derived for the isosceles triangles
    # (apex at the centre) it is made of; n = 6 gives 5/12 R², n → ∞ gives R²/2.
    return circumradius * math.sqrt((2.0 + math.cos(2.0 * math.pi / n)) / 6.0)
