"""The spot-light comparison scene (bpy 5.0.1), built from code like blender_scenes.py.

Two spot lights of 100 W and radius 0 light a grey floor and a grey sphere, direct lighting only
(Cycles max_bounces 0, petzval --max-depth 1), seen through a pinhole camera (no depth of field):

* ``SpotHard``: size 50°, blend 0 (a hard edge). Its cone edge crosses the floor and the sphere.
  Blender's exporter writes ``innerConeAngle = outerConeAngle`` for it; petzval renders that as
  a step at the outer cone, as Cycles does.
* ``SpotSoft``: size 50°, blend 0.2. Blender fades it with a smoothstep in cos θ over
  ``[cos θo, cos θo + (1 − cos θo)·blend]`` (θo = size/2: 25° to 22.3°); the exporter writes
  ``innerConeAngle = θo·(1 − blend)`` (20°) and petzval follows KHR_lights_punctual's squared
  ramp in cos θ from the outer to the inner cone. The two falloffs differ by design between
  20° and 25°; inside 20° and outside 25° both are exactly 1 and 0.

Plus a small emissive icosphere (320 triangles: the light tree has more than the two spots to
choose from) and a dim constant world, so that light selection also mixes lights at infinity.

:func:`pixel_masks` computes from the same geometry, analytically (camera rays against the floor
plane and the sphere), which pixels see the soft spot's transition zone (excluded from the
comparison) and which straddle the hard spot's edge (the band compared on its own).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import blender_scenes as S

RESOLUTION = (240, 160)
WORLD_RGB = (0.02, 0.025, 0.03)
CYCLES_MAX_BOUNCES = 0  # direct lighting only: both falloffs compared where light arrives first
PETZVAL_MAX_DEPTH = CYCLES_MAX_BOUNCES + 1

CAMERA = S.CameraSpec(
    name="SpotCam",
    location=(0.0, -1.9, 2.3),
    target=(0.0, 1.2, 0.2),
    lens_mm=30.0,
    sensor_mm=36.0,
    fstop=0.0,  # no depth of field
    focus_m=0.0,
    blades=0,
    rotation_deg=0.0,
)

SPHERE_CENTRE = (-0.35, 1.55, 0.35)
SPHERE_RADIUS = 0.35
EMITTER = ((0.1, 0.3, 0.12), 0.05, (1.0, 0.8, 0.6), 40.0)  # location, radius, colour, strength


@dataclass(frozen=True)
class SpotSpec:
    name: str
    location: tuple[float, float, float]
    target: tuple[float, float, float]
    size_deg: float
    blend: float
    watts: float = 100.0

    @property
    def outer(self) -> float:
        return math.radians(self.size_deg) / 2

    @property
    def gltf_inner(self) -> float:
        """innerConeAngle as Blender's exporter writes it."""
        return self.outer * (1.0 - self.blend)

    @property
    def blender_inner(self) -> float:
        """Angle at which Blender's smoothstep reaches 1: cos θ = cos θo + (1 − cos θo)·blend."""
        c = math.cos(self.outer)
        return math.acos(min(1.0, c + (1.0 - c) * self.blend))

    def axis(self) -> np.ndarray:
        d = np.subtract(self.target, self.location)
        return d / np.linalg.norm(d)


SPOT_HARD = SpotSpec("SpotHard", location=(-1.2, 0.7, 2.1), target=(-1.1, 1.3, 0.0), size_deg=50.0, blend=0.0)
SPOT_SOFT = SpotSpec("SpotSoft", location=(1.3, 0.7, 2.1), target=(1.2, 1.3, 0.0), size_deg=50.0, blend=0.2)
SPOTS = (SPOT_HARD, SPOT_SOFT)


def _add_spot(bpy, spec: SpotSpec):
    data = bpy.data.lights.new(spec.name, "SPOT")
    data.energy = spec.watts
    data.color = (1.0, 1.0, 1.0)
    data.shadow_soft_size = 0.0  # a true point source (glTF lights are punctual)
    data.use_soft_falloff = False
    data.spot_size = math.radians(spec.size_deg)
    data.spot_blend = spec.blend
    obj = bpy.data.objects.new(spec.name, data)
    bpy.context.scene.collection.objects.link(obj)
    obj.location = spec.location
    obj.rotation_mode = "QUATERNION"
    obj.rotation_quaternion = S._look_at_quat(spec.location, spec.target)
    return obj


def build_scene(tmpdir: Path) -> str:
    """Resets Blender and builds the spot scene (see the module docstring); returns the Blender
    version."""
    bpy = S._import_bpy()
    tmpdir.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    S.set_world_colour(bpy, scene, WORLD_RGB)
    grey = S._principled(bpy, "Grey", base=(0.5, 0.5, 0.5))
    loc, radius, colour, strength = EMITTER
    emit = S._principled(bpy, "Emit", base=(0.0, 0.0, 0.0), emission=colour, strength=strength)
    S._add_mesh(bpy, "plane", "Floor", (0.0, 1.0, 0.0), grey, 8.0, smooth=False)
    S._add_mesh(bpy, "uv_sphere", "Ball", SPHERE_CENTRE, grey, SPHERE_RADIUS)
    S._add_mesh(bpy, "ico_sphere", "Emitter", loc, emit, radius)
    for spec in SPOTS:
        _add_spot(bpy, spec)
    cam = S._add_camera(bpy, CAMERA)
    cam.data.dof.use_dof = False
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = RESOLUTION
    scene.render.resolution_percentage = 100
    scene.render.pixel_aspect_x = scene.render.pixel_aspect_y = 1.0
    # Cycles' settings (pixel filter, bounces) are part of the scene that petzval_args reads
    S.configure_cycles(S.CyclesSettings(samples=1, seed=0, max_bounces=CYCLES_MAX_BOUNCES), CAMERA.name)
    return bpy.app.version_string


def render_cycles(samples: int, seed: int, out_exr: Path) -> float:
    """Cycles as in blender_scenes.configure_cycles, direct lighting only; returns the wall time."""
    cfg = S.CyclesSettings(samples=samples, seed=seed, max_bounces=CYCLES_MAX_BOUNCES)
    return S.render_cycles(cfg, CAMERA.name, out_exr)


def petzval_args() -> list[str]:
    """`petzval render` options for SpotCam: a pinhole with the focal length from the exported
    yfov and the sensor width, no natural vignetting (Cycles has none), Cycles' pixel filter."""
    return S.pinhole_args(CAMERA, WORLD_RGB, PETZVAL_MAX_DEPTH, RESOLUTION)


# ------------------------------------------------------------------------------------------
# Geometry of the image: which pixels see what


def _camera_rays(sub: int, reach_px: float) -> np.ndarray:  # float32: (H, W, sub², 3) is large
    """Unit world directions (H, W, sub*sub, 3) from the camera through a sub x sub grid of
    points spanning ±reach_px around each pixel centre (Blender's AUTO fit: the sensor width
    spans the image width; film y up)."""
    w, h = RESOLUTION
    q = S._look_at_quat(CAMERA.location, CAMERA.target)
    m = np.array(q.to_matrix())  # camera → world (camera looks along −z, y up)
    pitch = CAMERA.sensor_mm / w
    offs = np.linspace(-reach_px, reach_px, sub) if sub > 1 else np.zeros(1)
    ox, oy = np.meshgrid(offs, offs)
    ix = np.arange(w)[None, :, None] + 0.5 + ox.ravel()[None, None, :]
    iy = np.arange(h)[:, None, None] + 0.5 + oy.ravel()[None, None, :]
    x, y = np.broadcast_arrays((ix - w / 2) * pitch, (h / 2 - iy) * pitch)
    d = np.stack([x, y, np.full_like(x, -CAMERA.lens_mm)], axis=-1)
    d = (d @ m.T).astype(np.float32)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def _first_hits(d: np.ndarray) -> np.ndarray:
    """World points where rays from the camera along `d` first meet the sphere or the floor
    (z = 0); NaN where they meet neither (the emitter is ignored: it hides nothing that
    matters)."""
    o = np.array(CAMERA.location)
    c = np.array(SPHERE_CENTRE)
    oc = o - c
    b = d @ oc
    disc = b * b - (oc @ oc - SPHERE_RADIUS**2)
    t_sphere = np.where(disc >= 0, -b - np.sqrt(np.maximum(disc, 0)), np.inf)
    t_sphere = np.where(t_sphere > 0, t_sphere, np.inf)
    down = d[..., 2] < 0
    t_floor = np.where(down, -o[2] / np.where(down, d[..., 2], -1.0), np.inf)
    p_floor = o + np.where(down, t_floor, 0.0)[..., None] * d
    on_floor = down & (np.abs(p_floor[..., 0]) <= 4.0) & (np.abs(p_floor[..., 1] - 1.0) <= 4.0)
    t = np.minimum(t_sphere, np.where(on_floor, t_floor, np.inf))
    hit = np.isfinite(t)
    p = o + np.where(hit, t, 0.0)[..., None] * d
    p[~hit] = np.nan
    return p


def spot_angles(p: np.ndarray, spec: SpotSpec) -> np.ndarray:
    """Angle (rad) between the spot's axis and the direction from the spot to points `p`."""
    v = p - np.array(spec.location)
    cos = (v @ spec.axis()) / np.linalg.norm(v, axis=-1)
    return np.arccos(np.clip(cos, -1.0, 1.0))


@dataclass
class PixelMasks:
    soft_transition: np.ndarray  # (H, W) bool: the footprint reaches the soft spot's fade zone
    hard_band: np.ndarray  # (H, W) bool: the footprint straddles the hard spot's edge
    soft_inner: np.ndarray  # (H, W) bool: all of the footprint inside both soft inner cones
    hard_inside: np.ndarray  # (H, W) bool: all of the footprint inside the hard cone


def pixel_masks(footprint_px: float = 2.5, sub: int = 9) -> PixelMasks:
    """Masks from the scene geometry, each pixel tested over a sub x sub grid spanning
    ±footprint_px (the Blackman–Harris filter of filter_width 1.5 reaches ±1.5 px; the rest is
    margin for the sphere's triangles against the exact sphere, ≤ 3 mm here against ~15 mm per
    pixel). Occlusion of the spots (the sphere's shadow) is not tested: a shadow only makes a
    masked pixel darker on both sides."""
    w, h = RESOLUTION
    rays = _camera_rays(sub, footprint_px)
    masks = PixelMasks(*(np.zeros((h, w), bool) for _ in range(4)))
    lo = min(SPOT_SOFT.gltf_inner, SPOT_SOFT.blender_inner)
    for row in range(h):  # a row at a time: (W, sub², 3) arrays
        p = _first_hits(rays[row])
        hit = np.isfinite(p[..., 0])
        with np.errstate(invalid="ignore"):
            a_soft = np.where(hit, spot_angles(p, SPOT_SOFT), np.nan)
            a_hard = np.where(hit, spot_angles(p, SPOT_HARD), np.nan)
            inner_s, outer_s = a_soft < lo, a_soft > SPOT_SOFT.outer
            fade = (a_soft >= lo) & (a_soft <= SPOT_SOFT.outer)
            # a footprint with points on both sides of the fade zone (across a silhouette) too
            masks.soft_transition[row] = np.any(fade, -1) | (np.any(inner_s, -1) & np.any(outer_s, -1))
            inside_h, outside_h = a_hard < SPOT_HARD.outer, a_hard >= SPOT_HARD.outer
            masks.hard_band[row] = np.any(inside_h, -1) & np.any(outside_h, -1)
            masks.soft_inner[row] = np.all(inner_s, -1)
            masks.hard_inside[row] = np.all(inside_h, -1)
    return masks


def hard_edge_side(footprint_px: float = 0.0) -> np.ndarray:
    """(H, W) bool: the pixel centre sees a point inside the hard spot's cone."""
    p = _first_hits(_camera_rays(1, footprint_px)[:, :, 0])
    with np.errstate(invalid="ignore"):
        return np.isfinite(p[..., 0]) & (spot_angles(p, SPOT_HARD) < SPOT_HARD.outer)
