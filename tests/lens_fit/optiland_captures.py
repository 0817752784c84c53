"""Photographs of point sources made with optiland (an independent forward model for petzval-fit).

The lens is optiland's Cooke triplet sample, written to Zemax with ``save_zemax_file``; that file
is petzval-fit's start lens. A capture is made here without any petzval code:

1. **Geometry** (optiland's paraxial data, at the primary wavelength 550 nm): the lens frame has
   its first vertex at z = 0, z towards the film, x right and y up looking from the camera at the
   scene (optiland's global frame, unchanged). With ``distances_from = "entrance_pupil"`` the
   source at ``source_m = (X, Y, Z)`` is at ``(1000 X, 1000 Y, z_EP − 1000 Z)`` mm, and the sensor
   plane is where the lens focused at ``focus_m`` puts it: the paraxial image of the axial object
   point ``focus_m`` in front of the entrance pupil, found with optiland's real-ray trace of a ray
   1e-6 mm off the axis (paraxial to ~1e-14). With ``"sensor"`` both distances are from the
   sensor plane (``OptilandCamera.placement`` solves for the pupil distance).
2. **Stop**: f/N sets the stop's radius to ``EFL / (2N)`` (the entrance-pupil radius) times the
   paraxial ratio (stop height / entrance-pupil height) of a collimated ray (optiland's trace).
   Every surface clips at its Zemax semi-diameter (optiland ``RadialAperture``), the stop at
   that radius.
3. **Rays**: a square grid over a disc on the entrance-pupil plane 1.3 × the paraxial pupil
   (checked: no ray of the disc's outer ring passes, so the whole beam is sampled), each ray
   carrying its solid angle ``dA cos θ / r²``; optiland traces them (real rays, 550 nm), they are
   carried on to the sensor plane and binned into the pixels they land in: the pixel-area
   integral of the irradiance, by hundreds of rays per pixel.
4. **Pixels**: a sensor point (qx, qy) mm is at full-sensor pixel coordinates ``(columns / 2 −
   qx / pitch, rows / 2 + qy / pitch)`` (x right, y down; the image is inverted on the sensor and
   the camera writes it upright: a source right of and above the axis images right of and above
   the centre); ``crop_origin_px`` is subtracted, pixel (i, j) covers [i, i + 1] × [j, j + 1].
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import optiland.backend as be
from optiland.fileio import save_zemax_file
from optiland.physical_apertures import RadialAperture
from optiland.rays import RealRays
from optiland.samples.objectives import CookeTriplet

WL_UM = 0.55
SENSOR = {"width_mm": 36.0, "height_mm": 24.0, "pixels": (6000, 4000)}
PITCH_MM = SENSOR["width_mm"] / SENSOR["pixels"][0]


@dataclass
class Shot:
    """One capture: the source (m), focus (m), f-number; distances from the entrance pupil, or
    with ``from_sensor`` from the sensor plane."""

    source_m: tuple[float, float, float]
    focus_m: float
    f_number: float
    from_sensor: bool = False


def _np(v) -> np.ndarray:
    return np.asarray(be.to_numpy(v), dtype=float)


class OptilandCamera:
    """optiland's Cooke triplet sample as a camera."""

    def __init__(self):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            self.optic = CookeTriplet()
            self.optic.updater.update_paraxial()
        surfaces = self.optic.surfaces.surfaces
        self.n = len(surfaces) - 2  # lens surfaces 1..n (0: object, n + 1: image)
        self.semi = [float(surfaces[k].semi_aperture) for k in range(self.n + 1)]
        self.stop = next(k for k in range(1, self.n + 1) if surfaces[k].is_stop)
        self.z = [float(_np(surfaces[k].geometry.cs.z)) for k in range(1, self.n + 1)]
        self.efl = float(self.optic.paraxial.f2())
        self.ep_z = float(self.optic.paraxial.EPL())
        for k in range(1, self.n + 1):
            surfaces[k].aperture = RadialAperture(r_max=self.semi[k])

    def radius(self, k: int) -> float:
        return float(self.optic.surfaces.surfaces[k].geometry.radius)

    def save_zemax(self, path: Path) -> None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            save_zemax_file(self.optic, str(path))

    def trace(self, p0: np.ndarray, d: np.ndarray, with_apertures: bool = True) -> tuple[np.ndarray, ...]:
        """Real rays (start points p0, directions d, lens frame mm) to the image surface: (x, y,
        z, L, M, N, transmitted)."""
        surfaces = self.optic.surfaces.surfaces
        saved = [s.aperture for s in surfaces]
        if not with_apertures:
            for s in surfaces:
                s.aperture = None
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        n = len(p0)
        rr = RealRays(
            p0[:, 0].copy(), p0[:, 1].copy(), p0[:, 2].copy(),
            d[:, 0].copy(), d[:, 1].copy(), d[:, 2].copy(),
            np.ones(n), np.full(n, WL_UM),
        )  # fmt: skip
        try:
            with warnings.catch_warnings(), np.errstate(all="ignore"):
                warnings.simplefilter("ignore")
                self.optic.surfaces.trace(rr)
        finally:
            for s, a in zip(surfaces, saved, strict=True):
                s.aperture = a
        out = [_np(v) for v in (rr.x, rr.y, rr.z, rr.L, rr.M, rr.N, rr.i)]
        ok = (out[6] > 0) & np.all(np.isfinite(np.column_stack(out[:6])), axis=1)
        return (*out[:6], ok)

    def image_distance(self, focus_mm: float) -> float:
        """Paraxial image distance from the last vertex of the axial point ``focus_mm`` in front
        of the entrance pupil (a real ray 1e-6 mm from the axis)."""
        zo = self.ep_z - focus_mm
        z0 = -5.0
        slope = 1e-6 / (z0 - zo)
        p0 = np.array([[0.0, 1e-6, z0]])
        _, y, z, _, m, nn, ok = self.trace(p0, np.array([[0.0, slope, 1.0]]), with_apertures=False)
        assert ok[0]
        return float(z[0] - y[0] / (m[0] / nn[0])) - self.z[-1]

    def placement(self, shot: Shot) -> tuple[float, float]:
        """(sensor plane z, origin of the shot's distances z). From the sensor, the focus distance
        D is the object's distance d from the entrance pupil plus the pupil-to-sensor length,
        which depends on d: d = D − (z_last + image_distance(d) − z_EP), iterated."""
        focus = shot.focus_m * 1e3
        if not shot.from_sensor:
            return self.z[-1] + self.image_distance(focus), self.ep_z
        d = focus
        for _ in range(100):
            nxt = focus - (self.z[-1] + self.image_distance(d) - self.ep_z)
            if abs(nxt - d) < 1e-10:
                break
            d = nxt
        film_z = self.z[-1] + self.image_distance(d)
        assert abs(d + film_z - self.ep_z - focus) < 1e-8
        return film_z, film_z

    def stop_radius(self, f_number: float) -> float:
        eps = 1e-6
        p0 = np.array([[0.0, eps, -5.0]])
        self.trace(p0, np.array([[0.0, 0.0, 1.0]]), with_apertures=False)
        y_stop = float(_np(self.optic.surfaces.surfaces[self.stop].y)[0])
        return self.efl / (2.0 * f_number) * abs(y_stop / eps)

    def render(self, shot: Shot, size: int, grid: int = 900, offset_px=(0.3, -0.2)) -> tuple[np.ndarray, list[int]]:
        """The image (size × size, row 0 at the top) and its crop origin on the full sensor."""
        surfaces = self.optic.surfaces.surfaces
        r_stop = self.stop_radius(shot.f_number)
        assert r_stop <= self.semi[self.stop] * (1 + 1e-9), f"f/{shot.f_number} is wider than the lens"
        surfaces[self.stop].aperture = RadialAperture(r_max=r_stop)
        try:
            film_z, z_origin = self.placement(shot)
            s = np.array([shot.source_m[0] * 1e3, shot.source_m[1] * 1e3, z_origin - shot.source_m[2] * 1e3])
            # the disc on the entrance-pupil plane, centred where the chief ray aims (paraxially)
            r_ep = self.efl / (2.0 * shot.f_number)
            radius = 1.3 * r_ep
            u = (np.arange(grid) + 0.5) / grid * 2.0 - 1.0
            gx, gy = np.meshgrid(u, u)
            inside = gx**2 + gy**2 <= 1.0
            gx, gy = gx[inside] * radius, gy[inside] * radius
            ring = np.hypot(gx, gy) > 0.97 * radius
            target = np.column_stack([gx, gy, np.full(gx.shape, self.ep_z)])
            dA = (2.0 * radius / grid) ** 2
            cols, rows, weights = [], [], []
            ring_passed = 0
            for lo in range(0, len(target), 400_000):
                t = target[lo : lo + 400_000]
                d = t - s
                r2 = np.sum(d * d, axis=1)
                w = dA * (d[:, 2] / np.sqrt(r2)) / r2
                z0 = -5.0
                p0 = s + d * ((z0 - s[2]) / d[:, 2])[:, None]
                x, y, z, dx, dy, dz, ok = self.trace(p0, d)
                ring_passed += int(np.count_nonzero(ok & ring[lo : lo + 400_000]))
                tt = (film_z - z[ok]) / dz[ok]
                qx, qy = x[ok] + dx[ok] * tt, y[ok] + dy[ok] * tt
                cols.append(SENSOR["pixels"][0] / 2.0 - qx / PITCH_MM)
                rows.append(SENSOR["pixels"][1] / 2.0 + qy / PITCH_MM)
                weights.append(w[ok])
            assert ring_passed == 0, f"{ring_passed} rays of the sampling disc's rim passed: widen it"
        finally:
            surfaces[self.stop].aperture = RadialAperture(r_max=self.semi[self.stop])
        col, row, w = np.concatenate(cols), np.concatenate(rows), np.concatenate(weights)
        cx, cy = np.average(col, weights=w), np.average(row, weights=w)
        origin = [math.floor(cx - size / 2 + offset_px[0]), math.floor(cy - size / 2 + offset_px[1])]
        img, _, _ = np.histogram2d(
            row - origin[1], col - origin[0], bins=[size, size], range=[[0, size], [0, size]], weights=w
        )
        return img, origin


def write_exr(path: Path, img: np.ndarray) -> None:
    """A linear RGB float EXR (the same value in R, G and B)."""
    import OpenEXR

    v = np.ascontiguousarray(img, dtype=np.float32)
    rgb = np.ascontiguousarray(np.stack([v, v, v], axis=-1))
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"RGB": rgb}) as f:
        f.write(str(path))


def read_exr(path: Path) -> np.ndarray:
    import OpenEXR

    with OpenEXR.File(str(path), separate_channels=True) as f:
        return np.asarray(f.channels()["R"].pixels, dtype=np.float64)


def manifest(start: str, free: list[dict], captures: list[dict]) -> str:
    """Manifest text (docs/lens-fit.md's keys)."""
    px = SENSOR["pixels"]
    out = [
        f'[lens]\nstart = "{start}"\n',
        f"[sensor]\nwidth_mm = {SENSOR['width_mm']}\nheight_mm = {SENSOR['height_mm']}\npixels = [{px[0]}, {px[1]}]\n",
    ]
    for f in free:
        out.append("[[free]]\n" + "".join(f"{k} = {_toml(v)}\n" for k, v in f.items()))
    for c in captures:
        out.append("[[capture]]\n" + "".join(f"{k} = {_toml(v)}\n" for k, v in c.items()))
    return "\n".join(out)


def _toml(v) -> str:
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    return repr(v)
