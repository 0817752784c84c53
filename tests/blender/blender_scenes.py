"""The Cycles comparison scene, built from code with Blender's Python module (bpy 5.0.1).

Everything is made in memory: no .blend assets. :func:`build_scene` resets Blender to an empty
factory state and builds

* a 6 m x 6 m ground plane with a checkerboard image texture (made here, 0.25 m tiles,
  'Closest' interpolation so neither renderer filters texels),
* four diffuse objects at different depths (spheres near, at and behind the focus distance, a
  cube, a large far sphere) and two small emissive spheres,
* a point light (radius 0), a spot light (hard edge: blend 0, radius 0) and a sun (angle 0), i.e.
  only punctual lights, which glTF's KHR_lights_punctual carries (Blender area lights do not
  export), plus the emissive meshes (KHR_materials_emissive_strength),
* a world of constant colour (glTF has no world: it is passed to petzval with --environment),
* three cameras: ``MainCam`` (50 mm, 36 mm sensor, f/2.8, focused at 1.5 m, 6 blades at 10 deg)
  for the whole-image comparison, and ``BokehCam`` (50 mm on a 9 mm sensor, i.e. a 4x crop of
  the same lens so the circles of confusion span many pixels, f/2.8, focused at 1.2 m) looking
  at two tiny emitters against the dark world, one far behind and one in front of the focus
  plane, for measuring the circle of confusion and the blade orientation; and ``OrthoCam``, an
  orthographic camera (Orthographic Scale 2.2 m, shifted) for test_ortho_cycles.py.

Materials are within what glTF round-trips and what both BSDFs agree on: Principled BSDF with
metallic 0, roughness 1 and **Specular IOR Level 0**, i.e. no specular layer at all, so Cycles'
Principled BSDF and petzval's glTF BSDF are both pure Lambertian base/pi (with the default
specular 0.5 the two specular layers and their energy compensation differ by design, which is
not what this test is about). Emitters: black base colour plus emission.

Every mesh is triangulated in Blender before rendering and export, so Cycles and the exported
glTF have the same triangles (Cycles would otherwise split quads itself).

What glTF cannot carry about the camera, and is therefore passed to ``petzval render`` from the
Blender camera data by :func:`petzval_camera_args`: the f-stop, the focus distance, the number of
blades and their rotation, and the sensor width (glTF only has yfov; with the sensor width the
focal length follows). The render resolution, samples, seed, thread count and bounce limit are
render settings, not scene data, and are passed explicitly too.

Also usable as a script (writes the GLB and the Cycles renders, prints the petzval commands)::

    .venv/bin/python tests/blender/blender_scenes.py OUTDIR
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

# Bump when anything here changes in a way that changes the images (part of the cache key,
# together with this file's text itself).
SCENE_VERSION = 1

RESOLUTION = (240, 160)  # both cameras render at this size (3:2 like the 36 x 24 frame)
WORLD_RGB = (0.05, 0.06, 0.08)

# Bounce limits. Cycles' max_bounces = B allows B bounces after the first hit, with emission
# found by the last bounce's BSDF ray still counted; petzval's --max-depth counts scattering
# events (1 = direct lighting only). So Cycles B <-> petzval B + 1.
CYCLES_MAX_BOUNCES = 6
PETZVAL_MAX_DEPTH = CYCLES_MAX_BOUNCES + 1


@dataclass(frozen=True)
class CameraSpec:
    name: str
    location: tuple[float, float, float]
    target: tuple[float, float, float]
    lens_mm: float
    sensor_mm: float
    fstop: float
    focus_m: float
    blades: int
    rotation_deg: float


def pinhole_camera(name: str, location, target, lens_mm: float) -> CameraSpec:
    """A 36 mm-wide camera rendered without depth of field (f/8, focused on `target`, no blades),
    as the material comparisons use it with :func:`pinhole_args`."""
    focus = math.dist(location, target)
    return CameraSpec(name, location, target, lens_mm, 36.0, 8.0, focus, 0, 0.0)


MAIN_CAM = CameraSpec(
    name="MainCam",
    location=(0.0, -1.6, 0.45),
    target=(0.0, 0.0, 0.12),
    lens_mm=50.0,
    sensor_mm=36.0,
    fstop=2.8,
    focus_m=1.5,
    blades=6,
    rotation_deg=10.0,
)

# BokehCam looks up into the dark world at two tiny emitters.
_BOKEH_LOC = (2.5, -1.0, 0.3)
_BOKEH_DIR = (0.0, 1.0, 0.5)
BOKEH_CAM = CameraSpec(
    name="BokehCam",
    location=_BOKEH_LOC,
    target=tuple(a + b for a, b in zip(_BOKEH_LOC, _BOKEH_DIR, strict=True)),
    lens_mm=50.0,
    sensor_mm=9.0,
    fstop=2.8,
    focus_m=1.2,
    blades=6,
    rotation_deg=10.0,
)


@dataclass(frozen=True)
class OrthoSpec:
    name: str
    location: tuple[float, float, float]
    target: tuple[float, float, float]
    ortho_scale: float  # Blender's Orthographic Scale (m across the larger image side, AUTO fit)
    shift: tuple[float, float]  # Blender's shift_x, shift_y (fractions of the fitted side)
    clip: tuple[float, float]


# OrthoCam looks down at the scene from the front right, shifted (glTF carries no shift: the
# comparison passes it as --shift-x/-y in mm of the 36 mm sensor width).
ORTHO_CAM = OrthoSpec(
    name="OrthoCam",
    location=(1.5, -3.0, 2.2),
    target=(0.0, 0.3, 0.1),
    ortho_scale=2.2,
    shift=(0.08, -0.05),
    clip=(0.5, 100.0),
)


@dataclass(frozen=True)
class BokehEmitter:
    name: str
    distance_m: float  # along the BokehCam view axis
    side_deg: float  # angle to the right (+) of the view axis, in the horizontal image direction
    radius_m: float
    strength: float


BOKEH_EMITTERS = (
    BokehEmitter("BokehFar", distance_m=12.0, side_deg=1.9, radius_m=0.025, strength=60.0),
    BokehEmitter("BokehNear", distance_m=0.6, side_deg=-1.9, radius_m=0.0015, strength=60.0),
)


@contextlib.contextmanager
def _quiet(log: Path):
    """Sends what Blender prints at the C level (render progress, exporter logging) to `log`
    instead of the terminal (file descriptors 1 and 2 redirected, then restored)."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, "ab") as f:
        try:
            os.dup2(f.fileno(), 1)
            os.dup2(f.fileno(), 2)
            yield
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)


def _import_bpy():
    import bpy  # imported lazily so the module is importable without Blender

    return bpy


def _look_at_quat(location, target):
    from mathutils import Vector

    d = Vector(target) - Vector(location)
    return d.to_track_quat("-Z", "Y")


def _camera_axes(spec: CameraSpec):
    """(forward, right, up) unit vectors of a camera spec, Blender world space."""
    from mathutils import Vector

    q = _look_at_quat(spec.location, spec.target)
    fwd = q @ Vector((0.0, 0.0, -1.0))
    right = q @ Vector((1.0, 0.0, 0.0))
    up = q @ Vector((0.0, 1.0, 0.0))
    return fwd, right, up


def bokeh_emitter_position(e: BokehEmitter):
    """World position of a BokehCam emitter: `distance_m` along the axis (camera-space depth),
    `side_deg` to the right."""
    from mathutils import Vector

    fwd, right, _ = _camera_axes(BOKEH_CAM)
    return Vector(BOKEH_CAM.location) + fwd * e.distance_m + right * (e.distance_m * math.tan(math.radians(e.side_deg)))


def _principled(bpy, name, base=(0.8, 0.8, 0.8), roughness=1.0, emission=None, strength=0.0, image=None):
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:  # Blender 5 creates the node tree; `use_nodes` is deprecated
        mat.use_nodes = True
    nt = mat.node_tree
    bsdf = nt.nodes.get("Principled BSDF")
    bsdf.inputs["Base Color"].default_value = (*base, 1.0)
    bsdf.inputs["Metallic"].default_value = 0.0
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Specular IOR Level"].default_value = 0.0  # pure Lambert on both sides
    if emission is not None:
        bsdf.inputs["Emission Color"].default_value = (*emission, 1.0)
        bsdf.inputs["Emission Strength"].default_value = strength
    if image is not None:
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = image
        tex.interpolation = "Closest"
        nt.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    return mat


def _checker_image(bpy, tmpdir: Path, n_tiles=24, px_per_tile=8, light=200, dark=60):
    """An sRGB 8-bit checkerboard PNG (saved to `tmpdir`, then packed into the .blend data)."""
    import numpy as np

    size = n_tiles * px_per_tile
    ij = np.indices((size, size)) // px_per_tile
    val = np.where((ij[0] + ij[1]) % 2 == 0, light, dark).astype(np.uint8)
    rgb = np.stack([val, val, (val.astype(np.int32) * 9 // 10).astype(np.uint8)], axis=-1)
    path = tmpdir / "checker.png"
    img = bpy.data.images.new("Checker", size, size, alpha=False)
    # bpy pixels are floats 0..1 (the byte values exactly), bottom row first
    rgba = np.concatenate([rgb, np.full((size, size, 1), 255, np.uint8)], axis=-1).astype(np.float32) / 255.0
    img.pixels.foreach_set(rgba.ravel())
    img.filepath_raw = str(path)
    img.file_format = "PNG"
    img.save()
    img.pack()
    img.colorspace_settings.name = "sRGB"
    return img


def _triangulate(bpy, obj):
    import bmesh

    bm = bmesh.new()
    bm.from_mesh(obj.data)
    bmesh.ops.triangulate(bm, faces=bm.faces[:])
    bm.to_mesh(obj.data)
    bm.free()


def _add_mesh(bpy, kind, name, location, material, size, smooth=True, rotation=(0, 0, 0)):
    ops = bpy.ops.mesh
    if kind == "uv_sphere":
        ops.primitive_uv_sphere_add(segments=48, ring_count=24, radius=size, location=location)
    elif kind == "ico_sphere":
        ops.primitive_ico_sphere_add(subdivisions=3, radius=size, location=location)
    elif kind == "cube":
        ops.primitive_cube_add(size=size, location=location, rotation=rotation)
    elif kind == "plane":
        ops.primitive_plane_add(size=size, location=location)
    else:
        raise ValueError(kind)
    obj = bpy.context.active_object
    obj.name = name
    obj.data.materials.append(material)
    if smooth:
        bpy.ops.object.shade_smooth()
    else:
        bpy.ops.object.shade_flat()
    _triangulate(bpy, obj)
    return obj


def _add_camera(bpy, spec: CameraSpec):
    cam_data = bpy.data.cameras.new(spec.name)
    cam_data.type = "PERSP"
    cam_data.lens = spec.lens_mm
    cam_data.sensor_width = spec.sensor_mm
    cam_data.sensor_fit = "AUTO"
    cam_data.clip_start = 0.01
    cam_data.clip_end = 1000.0
    cam_data.dof.use_dof = True
    cam_data.dof.aperture_fstop = spec.fstop
    cam_data.dof.focus_distance = spec.focus_m
    cam_data.dof.aperture_blades = spec.blades
    cam_data.dof.aperture_rotation = math.radians(spec.rotation_deg)
    cam_data.dof.aperture_ratio = 1.0
    return _place_camera(bpy, spec.name, cam_data, spec.location, spec.target)


def _place_camera(bpy, name, cam_data, location, target):
    """A camera object `name` of `cam_data` at `location`, looking at `target`."""
    obj = bpy.data.objects.new(name, cam_data)
    bpy.context.scene.collection.objects.link(obj)
    obj.location = location
    obj.rotation_mode = "QUATERNION"
    obj.rotation_quaternion = _look_at_quat(location, target)
    return obj


def _add_ortho_camera(bpy, spec: OrthoSpec):
    cam_data = bpy.data.cameras.new(spec.name)
    cam_data.type = "ORTHO"
    cam_data.ortho_scale = spec.ortho_scale
    cam_data.sensor_fit = "AUTO"
    cam_data.shift_x, cam_data.shift_y = spec.shift
    cam_data.clip_start, cam_data.clip_end = spec.clip
    cam_data.dof.use_dof = False
    return _place_camera(bpy, spec.name, cam_data, spec.location, spec.target)


def _add_light(bpy, kind, name, location, energy, target=None, spot_deg=None):
    data = bpy.data.lights.new(name, kind)
    data.energy = energy
    data.color = (1.0, 1.0, 1.0)
    if kind in ("POINT", "SPOT"):
        data.shadow_soft_size = 0.0  # a true point light (glTF lights are punctual)
        data.use_soft_falloff = False
    if kind == "SPOT":
        data.spot_size = math.radians(spot_deg)
        data.spot_blend = 0.0
        data.show_cone = False
    if kind == "SUN":
        data.angle = 0.0
    obj = bpy.data.objects.new(name, data)
    bpy.context.scene.collection.objects.link(obj)
    obj.location = location
    if target is not None:
        obj.rotation_mode = "QUATERNION"
        obj.rotation_quaternion = _look_at_quat(location, target)
    return obj


@dataclass
class BuiltScene:
    blender_version: str
    cameras: dict = field(default_factory=dict)  # name -> CameraSpec


def build_scene(tmpdir: Path) -> BuiltScene:
    """Resets Blender and builds the comparison scene (see the module docstring)."""
    bpy = _import_bpy()
    tmpdir.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene

    # World: constant colour, strength 1.
    set_world_colour(bpy, scene, WORLD_RGB)

    checker = _checker_image(bpy, tmpdir)
    m_ground = _principled(bpy, "Ground", image=checker)
    m_red = _principled(bpy, "Red", base=(0.70, 0.12, 0.08))
    m_green = _principled(bpy, "Green", base=(0.15, 0.55, 0.20))
    m_blue = _principled(bpy, "Blue", base=(0.10, 0.20, 0.65))
    m_white = _principled(bpy, "White", base=(0.80, 0.80, 0.78))
    m_warm = _principled(bpy, "EmitWarm", base=(0.0, 0.0, 0.0), emission=(1.0, 0.6, 0.3), strength=30.0)
    m_cool = _principled(bpy, "EmitCool", base=(0.0, 0.0, 0.0), emission=(0.4, 0.7, 1.0), strength=20.0)

    _add_mesh(bpy, "plane", "Ground", (0.0, 1.0, 0.0), m_ground, 6.0, smooth=False)
    _add_mesh(bpy, "uv_sphere", "NearSphere", (-0.28, -0.75, 0.12), m_red, 0.12)
    _add_mesh(bpy, "uv_sphere", "FocusSphere", (0.06, -0.12, 0.15), m_white, 0.15)
    _add_mesh(bpy, "cube", "Cube", (0.5, 0.9, 0.15), m_blue, 0.3, smooth=False, rotation=(0, 0, math.radians(30)))
    _add_mesh(bpy, "uv_sphere", "FarSphere", (-0.8, 2.6, 0.35), m_green, 0.35)
    _add_mesh(bpy, "ico_sphere", "EmitterNear", (0.32, -0.55, 0.04), m_warm, 0.04)
    _add_mesh(bpy, "ico_sphere", "EmitterFar", (0.15, 3.2, 0.5), m_cool, 0.06)
    for e in BOKEH_EMITTERS:
        m = _principled(bpy, f"{e.name}Mat", base=(0.0, 0.0, 0.0), emission=(1.0, 1.0, 1.0), strength=e.strength)
        _add_mesh(bpy, "ico_sphere", e.name, tuple(bokeh_emitter_position(e)), m, e.radius_m)

    _add_light(bpy, "POINT", "Key", (0.8, -0.6, 1.6), 60.0)
    _add_light(bpy, "SPOT", "Spot", (-1.0, 0.4, 1.5), 100.0, target=(-0.4, 1.4, 0.0), spot_deg=50.0)
    _add_light(bpy, "SUN", "Sun", (0.0, 0.0, 5.0), 0.8, target=(0.5, 0.3, 4.0))

    built = BuiltScene(blender_version=bpy.app.version_string)
    for spec in (MAIN_CAM, BOKEH_CAM):
        _add_camera(bpy, spec)
        built.cameras[spec.name] = spec
    _add_ortho_camera(bpy, ORTHO_CAM)
    scene.camera = bpy.data.objects[MAIN_CAM.name]
    scene.render.resolution_x, scene.render.resolution_y = RESOLUTION
    scene.render.resolution_percentage = 100
    scene.render.pixel_aspect_x = scene.render.pixel_aspect_y = 1.0
    return built


def export_glb(path: Path) -> Path:
    """Exports the current scene as GLB (cameras and punctual lights included, lighting mode
    SPEC: the exporter's default, physically based watts <-> candela/lux with 683 lm/W)."""
    bpy = _import_bpy()
    path.parent.mkdir(parents=True, exist_ok=True)
    with _quiet(path.parent / "blender.log"):
        _export(bpy, path)
    return path


def _export(bpy, path: Path) -> None:
    bpy.ops.export_scene.gltf(
        filepath=str(path),
        export_format="GLB",
        export_cameras=True,
        export_lights=True,
        export_import_convert_lighting_mode="SPEC",
        export_apply=True,
        export_yup=True,
        export_texcoords=True,
        export_normals=True,
        export_materials="EXPORT",
        export_image_format="AUTO",
        export_animations=False,
        use_selection=False,
    )


@dataclass(frozen=True)
class CyclesSettings:
    samples: int
    seed: int
    threads: int = 2
    max_bounces: int = CYCLES_MAX_BOUNCES


def configure_cycles(cfg: CyclesSettings, camera: str) -> None:
    """Cycles CPU set up to be comparable with petzval: no denoising, no adaptive sampling, no
    clamping, no glossy filter, no light threshold, Blackman-Harris 1.5 px, Standard view with no
    look, exposure 0, gamma 1, output OpenEXR float32 RGBA (linear Rec.709)."""
    bpy = _import_bpy()
    scene = bpy.context.scene
    scene.camera = bpy.data.objects[camera]
    r = scene.render
    r.engine = "CYCLES"
    r.threads_mode = "FIXED"
    r.threads = cfg.threads
    r.film_transparent = False
    r.use_persistent_data = False
    c = scene.cycles
    c.device = "CPU"
    c.samples = cfg.samples
    c.seed = cfg.seed
    c.use_animated_seed = False
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    c.blur_glossy = 0.0
    c.light_sampling_threshold = 0.0
    c.max_bounces = cfg.max_bounces
    c.diffuse_bounces = cfg.max_bounces
    c.glossy_bounces = cfg.max_bounces
    c.transmission_bounces = cfg.max_bounces
    c.volume_bounces = 0
    c.transparent_max_bounces = cfg.max_bounces
    c.pixel_filter_type = "BLACKMAN_HARRIS"
    c.filter_width = 1.5
    c.film_exposure = 1.0
    if hasattr(c, "use_guiding"):
        c.use_guiding = False
    linear_exr_output(scene)


def render_cycles(cfg: CyclesSettings, camera: str, out_exr: Path) -> float:
    """Renders `camera` with Cycles into `out_exr`; returns the wall time of the render call (s)."""
    bpy = _import_bpy()
    configure_cycles(cfg, camera)
    out_exr.parent.mkdir(parents=True, exist_ok=True)
    bpy.context.scene.render.filepath = str(out_exr)
    with _quiet(out_exr.parent / "blender.log"):
        t0 = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        dt = time.perf_counter() - t0
    if not out_exr.is_file():
        raise RuntimeError(f"Cycles did not write {out_exr}")
    return dt


def _num(x: float) -> str:
    """A Blender (float32) property as a short decimal string (7 significant digits)."""
    return f"{float(x):.7g}"


def petzval_direct_args(spec: CameraSpec) -> list[str]:
    """The Blender camera as `petzval render` options by petzval's documented conventions: what
    glTF cannot carry (f-stop, focus distance, blades and their rotation, sensor width spanning
    the larger image dimension as Blender's AUTO fit) taken over as they are, the focal length
    from the exported yfov with that sensor width, Cycles' filter_width, natural vignetting off
    (Cycles has none). Since petzval adopted Blender's conventions this is the Cycles-equivalent
    mapping itself."""
    return petzval_cycles_args(spec)


@dataclass(frozen=True)
class CyclesEquivalentLens:
    """The physical thin lens that forms exactly Cycles' image (see `cycles_equivalent`)."""

    focal_length_mm: float
    fstop: float
    focus_m: float
    rotation_deg: float
    filter_width_px: float


def cycles_equivalent(
    spec: CameraSpec, *, fstop_scale: float = 1.0, focus_m: float | None = None
) -> CyclesEquivalentLens:
    """Cycles' camera model as petzval's thin lens: since petzval follows Blender's conventions
    (the film stays at the focal length F and the lens focuses by its power, f = F·s/(F + s), with
    aperture diameter F/N; blade rotation puts an edge middle at the angle; --filter-width is
    Cycles' filter_width, the Blackman-Harris support being twice it), this is Blender's camera
    as it is. Cycles references: intern/cycles/kernel/camera/camera.h (thin lens),
    kernel regular_polygon_sample (blades), scene/film.cpp filter_table (width *= 2).

    `fstop_scale` and `focus_m` make deliberately wrong cameras for the negative controls (the
    Cycles camera with another f-stop or focus distance)."""
    bpy = _import_bpy()
    cam = bpy.data.objects[spec.name].data
    s_m = float(cam.dof.focus_distance) if focus_m is None else focus_m
    n = float(cam.dof.aperture_fstop) * fstop_scale
    rot = math.degrees(cam.dof.aperture_rotation)
    return CyclesEquivalentLens(float(cam.lens), n, s_m, rot, float(bpy.context.scene.cycles.filter_width))


def petzval_cycles_args(spec: CameraSpec, **kw) -> list[str]:
    """`petzval render` options for Blender's camera (see `cycles_equivalent`), with the
    negative controls' overrides."""
    bpy = _import_bpy()
    cam = bpy.data.objects[spec.name].data
    eq = cycles_equivalent(spec, **kw)
    return [
        "--camera", spec.name,
        "--lens", "thin",
        "--fstop", _num(eq.fstop),
        "--focus", _num(eq.focus_m),
        "--aperture", f"blades:{cam.dof.aperture_blades}:{_num(eq.rotation_deg)}",
        "--sensor-width", _num(cam.sensor_width),
        "--natural-vignetting", "off",
        "--filter-width", _num(eq.filter_width_px),
    ]


def pinhole_args(camera: CameraSpec, world_rgb, max_depth: int, resolution: tuple[int, int]) -> list[str]:
    """`petzval render` options for a Blender camera without depth of field as a pinhole: the
    focal length from the exported yfov and the sensor width, no natural vignetting (Cycles has
    none), Cycles' pixel filter, the world colour and the bounce limit."""
    bpy = _import_bpy()
    return [
        "--camera", camera.name,
        "--lens", "pinhole",
        "--sensor-width", _num(camera.sensor_mm),
        "--natural-vignetting", "off",
        "--filter-width", _num(bpy.context.scene.cycles.filter_width),
        "--environment", ",".join(_num(c) for c in world_rgb),
        "--max-depth", str(max_depth),
        "--resolution", "x".join(map(str, resolution)),
    ]  # fmt: skip


def world_rgb_arg() -> str:
    """Blender's world colour x strength, as petzval's --environment R,G,B."""
    bpy = _import_bpy()
    bg = bpy.context.scene.world.node_tree.nodes["Background"]
    col = bg.inputs["Color"].default_value
    s = bg.inputs["Strength"].default_value
    return ",".join(_num(col[i] * s) for i in range(3))


if __name__ == "__main__":
    import sys

    out = Path(sys.argv[1] if len(sys.argv) > 1 else "tests/out/blender-manual")
    built = build_scene(out)
    glb = export_glb(out / "scene.glb")
    print("blender", built.blender_version, "->", glb)
    for spec in built.cameras.values():
        t = render_cycles(CyclesSettings(samples=64, seed=0), spec.name, out / f"cycles_{spec.name}.exr")
        print(f"cycles {spec.name}: {t:.2f} s")
        print(
            "petzval render",
            glb,
            "-o",
            out / f"petzval_{spec.name}.exr",
            " ".join(petzval_cycles_args(spec)),
            "--environment",
            world_rgb_arg(),
            "--max-depth",
            PETZVAL_MAX_DEPTH,
            "--resolution",
            "x".join(map(str, RESOLUTION)),
        )


def linear_exr_output(scene) -> None:
    """Standard view transform (no look, exposure 0, gamma 1) and RGBA float32 EXR output: the
    pixels saved are the renderer's linear values, whichever engine made them."""
    vs = scene.view_settings
    vs.view_transform = "Standard"
    vs.look = "None"
    vs.exposure = 0.0
    vs.gamma = 1.0
    im = scene.render.image_settings
    if hasattr(im, "media_type"):
        im.media_type = "IMAGE"
    im.file_format = "OPEN_EXR"
    im.color_depth = "32"
    im.color_mode = "RGBA"
    im.exr_codec = "ZIP"


def set_world_colour(bpy, scene, rgb) -> None:
    """A new world of constant colour `rgb` (Background node, strength 1) for `scene`."""
    world = bpy.data.worlds.new("World")
    if world.node_tree is None:
        world.use_nodes = True
    bg = world.node_tree.nodes.get("Background")
    bg.inputs["Color"].default_value = (*rgb, 1.0)
    bg.inputs["Strength"].default_value = 1.0
    scene.world = world


def sphere_windows(camera: str, resolution: tuple[int, int], centres, radius: float) -> list[tuple[slice, slice]]:
    """Per sphere centre (world, in the built scene), the pixel rows and columns of a square of
    half side 0.6 radius about its projection through `camera` (inside the disc)."""
    bpy = _import_bpy()
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Vector

    bpy.context.view_layer.update()
    scene = bpy.context.scene
    cam = bpy.data.objects[camera]
    w, h = resolution
    out = []
    for centre in centres:
        c = world_to_camera_view(scene, cam, Vector(centre))
        e = world_to_camera_view(scene, cam, Vector(centre) + Vector((radius, 0.0, 0.0)))
        px, py = c.x * w, (1.0 - c.y) * h
        half = max(2, int(0.6 * abs(e.x - c.x) * w))
        out.append((slice(int(py) - half, int(py) + half), slice(int(px) - half, int(px) + half)))
    return out


def window_means(cyc, pz, windows) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per window: petzval's two-seed mean over Cycles' per channel, and the standard error of
    that ratio from the seed-to-seed differences."""
    out = []
    for rows, cols in windows:
        c = [img[rows, cols].reshape(-1, 3).mean(axis=0) for img in cyc]
        p = [img[rows, cols].reshape(-1, 3).mean(axis=0) for img in pz]
        cm, pm = (c[0] + c[1]) / 2, (p[0] + p[1]) / 2
        se = np.sqrt(((c[0] - c[1]) / 2) ** 2 / cm**2 + ((p[0] - p[1]) / 2) ** 2 / pm**2)
        out.append((pm / cm, se))
    return out


def assert_spheres_match(cyc, pz, windows, names, label: str, report, max_mean_z2, max_abs_z, mean_tol) -> None:
    """The verdict of a sphere scene against Cycles: the 8×8-block z-test of the whole image
    (mean z² ≤ `max_mean_z2`, max |z| ≤ `max_abs_z`) and each sphere's window mean (petzval over
    Cycles within `mean_tol` or four standard errors), reported as one line starting `label`."""
    import blender_compare as B

    z = B.compare_blocks(cyc[0], cyc[1], pz[0], pz[1]).z
    mean_z2, max_z = float(np.mean(z**2)), float(np.max(np.abs(z)))
    ratios = [(name, r, se) for name, (r, se) in zip(names, window_means(cyc, pz, windows), strict=True)]
    h, w = cyc[0].shape[:2]
    means = "; ".join(
        f"{n} " + " ".join(f"{x:.4f} ± {e:.4f}" for x, e in zip(r, se, strict=True)) for n, r, se in ratios
    )
    report.line(
        f"{label}, {w}x{h} x seeds {len(cyc)}: blocks mean z² {mean_z2:.3f} (≤ {max_mean_z2}), max |z| {max_z:.2f} "
        f"(≤ {max_abs_z}); sphere means petzval/Cycles {means}"
    )
    for name, r, se in ratios:
        assert np.all(np.abs(r - 1.0) <= np.maximum(mean_tol, 4 * se)), f"{name}: sphere mean ratio {r} ± {se}"
    assert mean_z2 <= max_mean_z2 and max_z <= max_abs_z, f"blocks: mean z² {mean_z2:.3f}, max |z| {max_z:.2f}"


def sphere_scene_renders(
    blender_run, name: str, key_files, build, camera: CameraSpec, world_rgb, resolution, spp: int, seeds, xs, radius
):
    """For a module fixture (`yield from`): a scene of spheres of `radius` centred at (x, 0, 0)
    for x in `xs`, built by `build` and rendered by `glb_pairs`, as (glb, Cycles images, petzval
    images, the spheres' windows); afterwards rebuilds the main scene, which the other modules'
    tests read from Blender."""
    try:
        glb, cyc, pz = glb_pairs(blender_run, name, key_files, build, camera, world_rgb, resolution, spp, seeds)
        yield glb, cyc, pz, sphere_windows(camera.name, resolution, [(x, 0.0, 0.0) for x in xs], radius)
    finally:
        build_scene(blender_run.workdir)


def glb_pairs(blender_run, name: str, key_files, build, camera: CameraSpec, world_rgb, resolution, spp: int, seeds):
    """Builds a scene with `build(workdir)`, exports it as GLB and renders it with Cycles (cached
    by `key_files`' text) and `petzval render` (pinhole args), once per seed: (glb, Cycles
    images, petzval images). The caller rebuilds the main scene afterwards."""
    from renders import cache_key, cached_render, run_petzval

    import blender_compare as B

    bpy = _import_bpy()
    workdir = blender_run.workdir / name
    cache_dir = blender_run.cache_dir.parent / f"cycles-{name}-{cache_key(bpy, *key_files)}"
    cache_dir.mkdir(parents=True, exist_ok=True)
    build(workdir)
    glb = export_glb(workdir / f"{name}.glb")
    args = pinhole_args(camera, world_rgb, PETZVAL_MAX_DEPTH, resolution)
    cyc, pz = [], []
    for seed in seeds:
        cfg = CyclesSettings(samples=spp, seed=seed)
        render = lambda out, cfg=cfg: render_cycles(cfg, camera.name, out)  # noqa: E731
        exr, _, _ = cached_render(bpy, cache_dir, f"cycles_spp{spp}_seed{seed}", render)
        cyc.append(B.read_rgb(exr))
        out = workdir / f"petzval_spp{spp}_seed{seed}.exr"
        run_petzval(blender_run.binary, glb, out, args, spp, seed)
        pz.append(B.read_rgb(out))
    return glb, cyc, pz


def spheres_on_floor(workdir: Path, world_rgb, materials, radius: float, light, camera: CameraSpec, resolution) -> None:
    """Resets Blender and builds a row of spheres of `radius` resting on a 20 m floor under a
    world of colour `world_rgb`: `materials()` (called after the reset) gives the floor's
    material and the spheres as (name, material, x), centred at (x, 0, 0); `light` is a point
    light's (location, watts); seen through `camera` without depth of field at `resolution`."""
    bpy = _import_bpy()
    workdir.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    floor, spheres = materials()
    set_world_colour(bpy, scene, world_rgb)
    _add_mesh(bpy, "plane", floor.name, (0.0, 0.0, -radius), floor, 20.0, smooth=False)
    for name, material, x in spheres:
        _add_mesh(bpy, "uv_sphere", name, (x, 0.0, 0.0), material, radius)
    _add_light(bpy, "POINT", "Key", light[0], light[1])
    cam = _add_camera(bpy, camera)
    cam.data.dof.use_dof = False
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = resolution
    scene.render.resolution_percentage = 100
