"""Blender's camera and render settings as arguments of ``petzval.Camera`` and ``petzval.render``.

What maps how (documented for users in the Camera panel's tooltips and the README):

* Thin lens (Blender camera): focal length ``cam.lens``, sensor width/height/fit, shift, clipping,
  and depth of field exactly as Cycles uses them. Depth of field off means a pinhole
  (``fstop=None``).
* Library lens or lens file: the lens brings its own focal length (Blender's Focal Length is not
  used) and its own widest f-number. Depth of field on: Blender's F-Stop stops it down and the
  focus distance (or focus object) focuses it. Depth of field off: a real lens cannot be a
  pinhole, so it renders wide open at its own f-number, still focused at the focus distance (or
  focus object) of the Depth of Field panel: the lens as it is, with its depth of field.
* Blender's aperture blades, rotation and ratio apply to every lens (0 blades: a circle); an
  aperture image in the Petzval panel replaces them.
* Sensor tilt (Scheimpflug) from ``Camera.petzval.tilt_x/tilt_y``.
"""

from __future__ import annotations

import math

import numpy as np

from . import properties

# Blender world (x, y, z), +z up -> glTF/petzval world (x, z, -y), +y up.
BLENDER_TO_GLTF = np.array(
    [[1.0, 0.0, 0.0, 0.0],
     [0.0, 0.0, 1.0, 0.0],
     [0.0, -1.0, 0.0, 0.0],
     [0.0, 0.0, 0.0, 1.0]]
)


class SettingsError(Exception):
    """A camera or render setting Petzval cannot use (message names the setting)."""


def to_gltf(matrix) -> np.ndarray:
    """A Blender object-to-world matrix (mathutils.Matrix) as object-to-world in petzval's axes."""
    return BLENDER_TO_GLTF @ np.array(matrix, dtype=np.float64)


def camera_to_world(matrix) -> np.ndarray:
    """The camera's matrix without scale (Blender ignores the camera object's scale)."""
    m = np.array(matrix, dtype=np.float64)
    for i in range(3):
        n = np.linalg.norm(m[:3, i])
        if n > 0:
            m[:3, i] /= n
    return BLENDER_TO_GLTF @ m


def frame_size(scene) -> tuple[int, int]:
    """Full frame in pixels, with the resolution percentage (as Blender: integer division)."""
    r = scene.render
    return r.resolution_x * r.resolution_percentage // 100, r.resolution_y * r.resolution_percentage // 100


def border_window(scene, width: int, height: int):
    """Blender's render border as (x0, y0, x1, y1) pixels of the full frame, row 0 at the
    BOTTOM (Blender's disprect: float * size truncated), or None without a border. The products
    are taken in single precision as Blender takes them: 0.9 * 120 is 107.99999 in double, 108
    in float32, and a double product would cut the last row."""
    r = scene.render

    def edge(border: float, size: int) -> int:
        return int(np.float32(border) * np.float32(size))

    if not r.use_border:
        return None
    x0, x1 = edge(r.border_min_x, width), edge(r.border_max_x, width)
    y0, y1 = edge(r.border_min_y, height), edge(r.border_max_y, height)
    if x1 - x0 < 1 or y1 - y0 < 1 or (x0, y0, x1, y1) == (0, 0, width, height):
        return None
    return x0, y0, x1, y1


def crop_top_first(window, height: int):
    """A bottom-first window as petzval's crop (x0, y0, x1, y1) with row 0 at the top."""
    x0, y0, x1, y1 = window
    return x0, height - y1, x1, height - y0


def focus_distance(cam_obj, depsgraph) -> float:
    """Blender's focus distance: the focus object's (or bone's) distance along the camera's view
    axis, as Cycles computes it, else ``dof.focus_distance``."""
    dof = cam_obj.data.dof
    target = dof.focus_object
    if target is None:
        return float(dof.focus_distance)
    target_eval = target.evaluated_get(depsgraph)
    m = np.array(target_eval.matrix_world, dtype=np.float64)
    pos = m[:3, 3]
    if target.type == "ARMATURE" and dof.focus_subtarget:
        bone = target_eval.pose.bones.get(dof.focus_subtarget)
        if bone is not None:
            pos = (m @ np.array([*bone.head, 1.0]))[:3]
    c = np.array(cam_obj.matrix_world, dtype=np.float64)
    view = c[:3, 2] / np.linalg.norm(c[:3, 2])
    return float(abs(np.dot(view, c[:3, 3] - pos)))


def lens_choice(cam) -> tuple[str, bool]:
    """(lens argument, is a real lens) from Camera.petzval."""
    import bpy

    p = cam.petzval
    if p.lens == properties.LENS_THIN:
        return "thin", False
    if p.lens == properties.LENS_PINHOLE:
        return "pinhole", False
    if p.lens == properties.LENS_FILE:
        if not p.lens_file.strip():
            raise SettingsError(f"camera '{cam.name}': Lens is 'Lens File' but no file is chosen")
        return bpy.path.abspath(p.lens_file), True
    return p.lens, True


def camera_kwargs(scene, cam_obj, depsgraph, notes) -> dict:
    """Keyword arguments of ``petzval.Camera`` for the camera (its Blender data, the Petzval
    lens settings and the scene's natural-vignetting switch)."""
    import bpy

    cam = cam_obj.data
    if cam.type not in ("PERSP", "ORTHO"):
        raise SettingsError(
            f"camera '{cam_obj.name}' is {cam.type.lower()}: Petzval renders perspective and orthographic cameras"
        )
    p = cam.petzval
    lens, real = lens_choice(cam)
    ortho = cam.type == "ORTHO"
    if ortho and real:
        raise SettingsError(
            f"camera '{cam_obj.name}' is orthographic: it has no lens, so Lens must be Thin Lens or Pinhole"
        )
    dof = cam.dof
    kw: dict = {
        "camera_to_world": camera_to_world(cam_obj.matrix_world),
        "lens": lens,
        "lens_model": p.lens_model.lower(),
        "tolerance_px": float(p.tolerance_px),
        "focal_length_mm": float(cam.lens),
        "sensor_width_mm": float(cam.sensor_width),
        "sensor_height_mm": float(cam.sensor_height),
        "sensor_fit": cam.sensor_fit.lower(),
        "shift_x": float(cam.shift_x),
        "shift_y": float(cam.shift_y),
        "tilt_x_deg": math.degrees(p.tilt_x),
        "tilt_y_deg": math.degrees(p.tilt_y),
        "clip_start_m": float(cam.clip_start),
        "clip_end_m": float(cam.clip_end),
        "aperture_blades": int(dof.aperture_blades) if dof.aperture_blades >= 3 else 0,
        "aperture_rotation_rad": float(dof.aperture_rotation),
        "aperture_ratio": float(dof.aperture_ratio),
        "natural_vignetting": bool(scene.petzval.natural_vignetting),
    }
    if ortho:
        # Cycles' orthographic depth of field: an aperture of radius 1/(2N) scene units
        kw["ortho_scale_m"] = float(cam.ortho_scale)
        kw["fstop"] = float(dof.aperture_fstop) if dof.use_dof and lens != "pinhole" else None
        kw["focus_distance_m"] = focus_distance(cam_obj, depsgraph) if kw["fstop"] is not None else None
    elif lens == "pinhole":
        kw["fstop"] = None
        kw["focus_distance_m"] = None
    elif not real:  # Blender's thin lens
        kw["fstop"] = float(dof.aperture_fstop) if dof.use_dof else None
        kw["focus_distance_m"] = focus_distance(cam_obj, depsgraph) if dof.use_dof else None
    else:
        kw["fstop"] = float(dof.aperture_fstop) if dof.use_dof else None
        kw["focus_distance_m"] = focus_distance(cam_obj, depsgraph)
        if not dof.use_dof:
            notes.note(
                "depth of field is off: the real lens renders wide open, focused at the Depth of Field panel's distance"
            )
    if kw["focus_distance_m"] is not None and kw["focus_distance_m"] <= 0:
        kw["focus_distance_m"] = None  # Blender's 0 focus distance: infinity
    if p.aperture_image.strip():
        kw["aperture_image"] = bpy.path.abspath(p.aperture_image)
    if scene.unit_settings.system != "NONE" and abs(scene.unit_settings.scale_length - 1.0) > 1e-6:
        notes.warn(f"unit scale {scene.unit_settings.scale_length:g} (Petzval takes Blender units as metres)")
    return kw


def render_kwargs(scene, frame: int) -> dict:
    """Keyword arguments of ``petzval.render``: sampling settings from Scene.petzval and the
    render settings."""
    s = scene.petzval
    r = scene.render
    seed = int(s.seed) + (int(frame) if s.use_animated_seed else 0)
    return {
        "spp": int(s.samples),
        "seed": seed,
        "max_depth": int(s.max_bounces) + 1,
        "filter_width_px": float(s.filter_width),
        "spectral": bool(s.spectral),
        "threads": int(r.threads) if r.threads_mode == "FIXED" else 0,
        # Cycles' noise threshold (off: every pixel takes every sample)
        "adaptive_threshold": float(s.adaptive_threshold) if s.use_adaptive_sampling else 0.0,
        "adaptive_min_samples": int(s.adaptive_min_samples),
    }
