"""Viewport preview: the 3D viewport's *Rendered* shading through ``petzval.render``.

The depsgraph is translated on ``view_update`` (any change), the view on ``view_draw``; a change
of either restarts a progressive render on a background thread at a fraction of the viewport's
resolution (``Scene.petzval.viewport_divisor``), whose newest pass ``view_draw`` shows. The
native render releases the GIL, so Blender stays responsive; a restart cancels the running
render through its progress callback (within one progress interval, 50 ms).

Film: Film > Transparent gives the preview the final render's transparent background
(``display_pixels``); without it the preview is drawn opaque.

Camera: looking through the scene camera, its Petzval lens and Blender camera settings (the
frame fitted to the viewport's aspect); in a free view, a pinhole with the viewport's focal
length on Blender's 72 mm viewport sensor and the view's clipping.
"""

from __future__ import annotations

import threading
import traceback

import numpy as np

from . import camera as camera_mod

# Blender's free 3D view: a 36 mm sensor at zoom 2, i.e. 72 mm across for the view's "lens".
VIEWPORT_SENSOR_MM = 72.0


def display_pixels(rgba, transparent: bool) -> np.ndarray:
    """The texture ``view_draw`` uploads: the pass flipped to bottom row first (OpenGL's order),
    float32. Without Film > Transparent every pixel is opaque; with it the pass's alpha is kept
    (the background is RGBA 0, premultiplied), so the viewport's own background shows through as
    in Cycles' Rendered shading."""
    img = np.array(rgba[::-1], dtype=np.float32)
    if not transparent:
        img[..., 3] = 1.0
    return img


def free_view_kwargs(
    view_matrix_inverted, lens_mm: float, clip_start: float, clip_end: float, natural_vignetting: bool = False
) -> dict:
    """``petzval.Camera`` arguments for a free (non-camera) perspective 3D view."""
    return {
        "camera_to_world": camera_mod.camera_to_world(view_matrix_inverted),
        "lens": "thin",
        "lens_model": "pinhole",
        "focal_length_mm": float(lens_mm),
        "sensor_width_mm": VIEWPORT_SENSOR_MM,
        "sensor_height_mm": VIEWPORT_SENSOR_MM,
        "sensor_fit": "auto",
        "fstop": None,
        "focus_distance_m": None,
        "clip_start_m": float(clip_start),
        "clip_end_m": float(clip_end),
        "natural_vignetting": bool(natural_vignetting),
    }


def free_ortho_view_kwargs(
    view_matrix_inverted, view_distance: float, lens_mm: float, clip_end: float, natural_vignetting: bool = False
) -> dict:
    """``petzval.Camera`` arguments for a free orthographic 3D view, as Blender frames it
    (``BKE_camera_params_from_view3d``): an Orthographic Scale of distance × 36 mm / lens at
    zoom 2, i.e. distance × 72 / lens across the larger side, and depth from −clip_end/2 to
    +clip_end/2 about the view point. Petzval clips from the window's own plane, so the window
    moves back by clip_end/2 along the view axis and keeps [0, clip_end]."""
    m = view_matrix_inverted.copy()
    # the view looks along its −Z axis: +Z points behind it
    m.translation = m.translation + m.col[2].xyz.normalized() * (0.5 * float(clip_end))
    return {
        "camera_to_world": camera_mod.camera_to_world(m),
        "lens": "thin",
        "lens_model": "auto",
        "focal_length_mm": float(lens_mm),
        "sensor_width_mm": VIEWPORT_SENSOR_MM,
        "sensor_height_mm": VIEWPORT_SENSOR_MM,
        "sensor_fit": "auto",
        "ortho_scale_m": float(view_distance) * VIEWPORT_SENSOR_MM / float(lens_mm),
        "fstop": None,
        "focus_distance_m": None,
        "clip_start_m": 0.0,
        "clip_end_m": float(clip_end),
        "natural_vignetting": bool(natural_vignetting),
    }


def view_key(kwargs: dict, width: int, height: int) -> tuple:
    """What identifies a view: a change restarts the preview."""
    items = []
    for k in sorted(kwargs):
        v = kwargs[k]
        items.append(
            (k, tuple(np.round(np.asarray(v, dtype=np.float64).ravel(), 9)) if isinstance(v, np.ndarray) else v)
        )
    return (width, height, tuple(items))


class PreviewRender:
    """One progressive render on a background thread; ``latest()`` gives its newest pass."""

    def __init__(self, petzval, scene, camera_kwargs: dict, render_kwargs: dict, width: int, height: int, spp: int):
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._rgba = None
        self.spp_done = 0
        self.spp = spp
        self.error: str | None = None
        self.finished = False
        self._thread = threading.Thread(
            target=self._run,
            args=(petzval, scene, dict(camera_kwargs), width, height, spp, dict(render_kwargs)),
            name="petzval-viewport",
            daemon=True,
        )
        self._thread.start()

    def _run(self, petzval, scene, camera_kw, width, height, spp, render_kw):
        def progress(fraction, spp_done, rgba):
            if rgba is not None:
                with self._lock:
                    self._rgba = rgba
                    self.spp_done = spp_done
            return not self._stop.is_set()

        try:
            cam = petzval.Camera(**camera_kw)
            out = petzval.render(
                scene, cam, width, height, spp=spp, progress=progress, progress_interval_s=0.05, **render_kw
            )
            with self._lock:
                self._rgba = out["rgba"]
                self.spp_done = out["spp"]
        except petzval.CancelledError:
            pass
        except Exception as e:  # shown in the viewport's status, never raised into Blender
            self.error = f"{type(e).__name__}: {e}"
            traceback.print_exc()
        finally:
            self.finished = True

    def latest(self):
        """The newest image (top row first, (H, W, 4) float32) or None."""
        with self._lock:
            return self._rgba

    def cancel(self, wait_s: float = 1.0) -> None:
        self._stop.set()
        self._thread.join(wait_s)
