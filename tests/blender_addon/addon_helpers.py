"""Helpers of the add-on suite: resetting Blender with the add-on enabled, rendering through the
PETZVAL engine, the scenes specific to this suite (tilt-shift ground, depth target), and the
Cycles references shared with tests/blender (same scene module, same cache directory)."""

from __future__ import annotations

import hashlib
import json
import math
import subprocess
import time
from pathlib import Path

import blender_compare as B  # noqa: F401  (re-exported for the tests)
import blender_scenes as S
from blender_scenes import _quiet as quiet

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
OUT = REPO / "tests" / "out" / "blender_addon"
CYCLES_CACHE_ROOT = REPO / "tests" / "out" / "blender"
ADDON_MODULE = "bl_ext.user_default.petzval"


def bpy():
    import bpy as _bpy

    return _bpy


def ensure_enabled():
    """Enables the installed add-on if a factory reset disabled it; returns its module."""
    import addon_utils

    b = bpy()
    if ADDON_MODULE not in {a.module for a in b.context.preferences.addons}:
        mod = addon_utils.enable(ADDON_MODULE, default_set=True, handle_error=None)
        if mod is None:
            raise RuntimeError(f"could not enable {ADDON_MODULE}")
    import importlib

    return importlib.import_module(ADDON_MODULE)


def reset_blender():
    """An empty factory scene with the add-on enabled."""
    bpy().ops.wm.read_factory_settings(use_empty=True)
    return ensure_enabled()


def build_main_scene(workdir: Path):
    """tests/blender's comparison scene (MainCam, BokehCam, lights, checker ground)."""
    built = S.build_scene(workdir)
    ensure_enabled()
    return built


def configure_petzval(spp: int, seed: int = 0, max_bounces: int = S.CYCLES_MAX_BOUNCES, camera: str | None = None,
                      threads: int = 2) -> None:
    """PETZVAL engine with Cycles-comparable settings and EXR (RGBA float32) output."""
    b = bpy()
    scene = b.context.scene
    if camera is not None:
        scene.camera = b.data.objects[camera]
    r = scene.render
    r.engine = "PETZVAL"
    r.threads_mode = "FIXED"
    r.threads = threads
    r.film_transparent = False
    p = scene.petzval
    p.samples = spp
    p.seed = seed
    p.use_animated_seed = False
    p.max_bounces = max_bounces
    p.filter_width = 1.5
    p.natural_vignetting = False
    p.spectral = False
    S.linear_exr_output(scene)


def render_still(out_exr: Path) -> tuple[float, dict]:
    """F12 + save (``bpy.ops.render.render(write_still=True)``); returns (wall seconds, the
    engine's log entry for the render)."""
    b = bpy()
    mod = ensure_enabled()
    out_exr.parent.mkdir(parents=True, exist_ok=True)
    if out_exr.exists():
        out_exr.unlink()
    b.context.scene.render.filepath = str(out_exr)
    before = mod.engine.RENDER_LOG[-1] if mod.engine.RENDER_LOG else None
    with quiet(OUT / "blender.log"):
        t0 = time.perf_counter()
        b.ops.render.render(write_still=True)
        dt = time.perf_counter() - t0
    entry = mod.engine.RENDER_LOG[-1] if mod.engine.RENDER_LOG and mod.engine.RENDER_LOG[-1] is not before else {}
    if entry.get("error"):
        raise AssertionError(f"the Petzval render failed: {entry['error']}")
    if not out_exr.is_file():
        raise AssertionError(f"Blender did not write {out_exr}")
    return dt, entry


# ------------------------------------------------------------------------------------------
# Cycles references, shared with tests/blender (same key, same directory, same files)


def cycles_cache_dir() -> Path:
    """tests/blender's cache: keyed by blender_scenes.py and the Blender build (the same key as
    tests/blender/conftest.py, so either suite reuses the other's Cycles renders)."""
    b = bpy()
    h = hashlib.sha256()
    h.update((REPO / "tests" / "blender" / "blender_scenes.py").read_bytes())
    h.update(b.app.version_string.encode())
    h.update(b.app.build_hash if isinstance(b.app.build_hash, bytes) else str(b.app.build_hash).encode())
    return CYCLES_CACHE_ROOT / f"cycles-{h.hexdigest()[:16]}"


def cycles_reference(camera: str, seed: int, spp: int) -> Path:
    """A cached Cycles render of the comparison scene (rendered now when missing; the scene
    must be built). Leaves the scene's engine at Cycles: configure_petzval() switches back."""
    import os

    cache = cycles_cache_dir()
    cache.mkdir(parents=True, exist_ok=True)
    name = f"cycles_{camera}_spp{spp}_seed{seed}"
    exr, meta = cache / f"{name}.exr", cache / f"{name}.json"
    if exr.is_file() and meta.is_file() and not os.environ.get("PETZVAL_BLENDER_NO_CACHE"):
        return exr
    secs = S.render_cycles(S.CyclesSettings(samples=spp, seed=seed), camera, exr)
    meta.write_text(json.dumps({"seconds": secs, "blender": bpy().app.version_string}))
    return exr


# ------------------------------------------------------------------------------------------
# the glTF path: Blender's exporter + the petzval command line


def petzval_cli_render(glb: Path, args: list[str], out: Path, spp: int, seed: int, resolution, environment: str,
                       max_depth: int) -> Path:
    import petzval_cli

    w, h = resolution
    cmd = [str(petzval_cli.ensure_binary()), "render", str(glb), "-o", str(out), "--no-png", *args,
           "--environment", environment, "--max-depth", str(max_depth), "--resolution", f"{w}x{h}",
           "--spp", str(spp), "--seed", str(seed), "--threads", "2"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    if proc.returncode != 0 or not out.is_file():
        raise AssertionError(f"`{' '.join(cmd)}` exited {proc.returncode}:\n{proc.stderr[-3000:]}")
    return out


# ------------------------------------------------------------------------------------------
# scenes of this suite


def _emissive_checker_material(name: str, tiles: int, px_per_tile: int = 8, bright: float = 1.0):
    """An emission-only material whose emission is a sRGB 8-bit checkerboard image (Closest)."""
    import numpy as np

    b = bpy()
    size = tiles * px_per_tile
    ij = np.indices((size, size)) // px_per_tile
    val = np.where((ij[0] + ij[1]) % 2 == 0, 1.0, 0.08).astype(np.float32)
    img = b.data.images.new(f"{name}Checker", size, size, alpha=False)
    img.colorspace_settings.name = "sRGB"  # before the pixels: changing it regenerates a generated image
    rgba = np.stack([val, val, val, np.ones_like(val)], axis=-1)
    img.pixels.foreach_set(rgba.ravel())
    OUT.mkdir(parents=True, exist_ok=True)
    img.filepath_raw = str(OUT / f"{name}_checker.png")
    img.file_format = "PNG"
    img.save()
    img.pack()
    mat = b.data.materials.new(name)
    if mat.node_tree is None:
        mat.use_nodes = True
    nt = mat.node_tree
    bsdf = nt.nodes.get("Principled BSDF")
    bsdf.inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bsdf.inputs["Specular IOR Level"].default_value = 0.0
    bsdf.inputs["Emission Strength"].default_value = bright
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = img
    tex.interpolation = "Closest"
    nt.links.new(tex.outputs["Color"], bsdf.inputs["Emission Color"])
    return mat


def add_camera(name: str, location, rotation_euler, lens_mm=50.0, sensor_mm=36.0):
    b = bpy()
    data = b.data.cameras.new(name)
    data.lens = lens_mm
    data.sensor_width = sensor_mm
    data.sensor_fit = "AUTO"
    data.clip_start = 0.01
    data.clip_end = 1000.0
    obj = b.data.objects.new(name, data)
    b.context.scene.collection.objects.link(obj)
    obj.location = location
    obj.rotation_euler = rotation_euler
    b.context.scene.camera = obj
    return obj


def set_world_colour(rgb) -> None:
    b = bpy()
    S.set_world_colour(b, b.context.scene, rgb)


# Tilt-shift scene: a camera `TILT_HEIGHT_M` above an emissive checkerboard ground, pitched down
# by `TILT_PITCH_DEG`; its axis meets the ground `TILT_HEIGHT_M / sin(pitch)` away.
TILT_HEIGHT_M = 0.6
TILT_PITCH_DEG = 30.0
TILT_TILE_M = 0.05


def build_tilt_scene(resolution=(360, 240)):
    """Emissive checkerboard ground (no lights, black world: the only noise is the lens's), the
    camera looking down at it. Returns the camera object."""
    b = bpy()
    reset_blender()
    scene = b.context.scene
    set_world_colour((0.0, 0.0, 0.0))
    extent = 8.0
    tiles = round(extent / TILT_TILE_M)
    mat = _emissive_checker_material("Ground", tiles=tiles, px_per_tile=4)
    b.ops.mesh.primitive_plane_add(size=extent, location=(0.0, extent / 2 - 0.5, 0.0))
    ground = b.context.active_object
    ground.name = "Ground"
    ground.data.materials.append(mat)
    cam = add_camera("TiltCam", (0.0, 0.0, TILT_HEIGHT_M), (math.radians(90.0 - TILT_PITCH_DEG), 0.0, 0.0))
    scene.render.resolution_x, scene.render.resolution_y = resolution
    scene.render.resolution_percentage = 100
    return cam


# Lights-and-world scene: what tests/blender's glTF scene cannot carry (area lights, an
# environment texture with a Mapping rotation), for a direct add-on-vs-Cycles comparison.
LIGHTS_RESOLUTION = (160, 96)
LIGHTS_ENV_ROTATION_DEG = 40.0


def _principled_lambert(name, base):
    b = bpy()
    mat = b.data.materials.new(name)
    if mat.node_tree is None:
        mat.use_nodes = True
    bsdf = mat.node_tree.nodes.get("Principled BSDF")
    bsdf.inputs["Base Color"].default_value = (*base, 1.0)
    bsdf.inputs["Roughness"].default_value = 1.0
    bsdf.inputs["Specular IOR Level"].default_value = 0.0
    return mat


def _anisotropic_sphere(mat, small: bool) -> None:
    """The "aniso" variant's spheres: a brushed gold metal (Anisotropic 0.8, Rotation 0.1, the
    Tangent input unlinked: Cycles' default radial tangent about the object's Z axis) and a
    blue dielectric (Anisotropic 0.6, Specular IOR Level 0.8) whose tangent is a Tangent node's
    radial X."""
    p = mat.node_tree.nodes.get("Principled BSDF")
    if small:
        p.inputs["Base Color"].default_value = (1.0, 0.78, 0.34, 1.0)
        p.inputs["Metallic"].default_value = 1.0
        p.inputs["Roughness"].default_value = 0.3
        p.inputs["Anisotropic"].default_value = 0.8
        p.inputs["Anisotropic Rotation"].default_value = 0.1
    else:
        p.inputs["Base Color"].default_value = (0.1, 0.25, 0.6, 1.0)
        p.inputs["Roughness"].default_value = 0.25
        p.inputs["Specular IOR Level"].default_value = 0.8
        p.inputs["Anisotropic"].default_value = 0.6
        t = mat.node_tree.nodes.new("ShaderNodeTangent")
        t.direction_type = "RADIAL"
        t.axis = "X"
        mat.node_tree.links.new(t.outputs["Tangent"], p.inputs["Tangent"])


def _add_anisotropic_objects(b) -> None:
    """The "aniso" variant's cylinder with a Glossy BSDF (Anisotropy -0.6, along its UV map's
    tangent through a Tangent node; shaded smooth by angle) and a small sun whose highlights the
    lobes stretch."""
    b.ops.mesh.primitive_cylinder_add(vertices=48, radius=0.3, depth=0.9, location=(1.5, 1.2, 0.45))
    b.ops.object.shade_smooth_by_angle()  # smooth side, flat cap (a fully smooth cap rim: see docs)

    def glossy(nt):
        g = nt.nodes.new("ShaderNodeBsdfGlossy")
        g.inputs["Color"].default_value = (0.9, 0.9, 0.92, 1.0)
        g.inputs["Roughness"].default_value = 0.35
        g.inputs["Anisotropy"].default_value = -0.6
        t = nt.nodes.new("ShaderNodeTangent")
        t.direction_type = "UV_MAP"
        nt.links.new(t.outputs["Tangent"], g.inputs["Tangent"])
        return g

    b.context.active_object.data.materials.append(_node_material("BrushedCylinder", glossy))
    sun = b.data.lights.new("AnisoSun", "SUN")
    sun.energy = 3.0
    sun.angle = math.radians(2.0)
    obj = b.data.objects.new("AnisoSun", sun)
    b.context.scene.collection.objects.link(obj)
    obj.rotation_euler = (math.radians(35.0), 0.0, math.radians(30.0))


def _node_material(name, build):
    """A material whose Surface is the shader `build(node_tree)` returns (the default
    Principled BSDF removed)."""
    b = bpy()
    mat = b.data.materials.new(name)
    if mat.node_tree is None:
        mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.remove(nt.nodes.get("Principled BSDF"))
    out = build(nt)
    nt.links.new(out.outputs[0], nt.nodes.get("Material Output").inputs["Surface"])
    return mat


def _shader(nt, kind, **inputs):
    """A shader node of `kind` (ShaderNode… without the prefix) with its inputs set."""
    n = nt.nodes.new("ShaderNode" + kind)
    for k, v in inputs.items():
        n.inputs[k].default_value = v
    return n


def _combine(nt, kind, first, second, factor=None):
    """A Mix Shader (`factor`) or Add Shader joining two shader nodes."""
    n = nt.nodes.new("ShaderNode" + kind)
    shaders = [s for s in n.inputs if s.type == "SHADER"]
    if factor is not None:
        n.inputs[0].default_value = factor
    nt.links.new(first.outputs[0], shaders[0])
    nt.links.new(second.outputs[0], shaders[1])
    return n


def _diffuse_glossy_group(nt):
    """A group node whose node group mixes a Diffuse BSDF, coloured by the group's "Paint"
    input, with a golden Glossy BSDF by its "Shine" input, through a reroute; the group node
    sets Paint (0.7, 0.2, 0.15) and Shine 0.4."""
    b = bpy()
    group = b.data.node_groups.new("DiffuseGlossyGroup", "ShaderNodeTree")
    group.interface.new_socket("Paint", in_out="INPUT", socket_type="NodeSocketColor")
    group.interface.new_socket("Shine", in_out="INPUT", socket_type="NodeSocketFloat")
    group.interface.new_socket("Shader", in_out="OUTPUT", socket_type="NodeSocketShader")
    gin = group.nodes.new("NodeGroupInput")
    gout = group.nodes.new("NodeGroupOutput")
    diffuse = _shader(group, "BsdfDiffuse")
    glossy = _shader(group, "BsdfGlossy", Color=(0.9, 0.75, 0.4, 1.0), Roughness=0.25)
    mix = _combine(group, "MixShader", diffuse, glossy)
    reroute = group.nodes.new("NodeReroute")
    group.links.new(gin.outputs["Paint"], reroute.inputs[0])
    group.links.new(reroute.outputs[0], diffuse.inputs["Color"])
    group.links.new(gin.outputs["Shine"], mix.inputs[0])
    group.links.new(mix.outputs[0], gout.inputs["Shader"])
    node = nt.nodes.new("ShaderNodeGroup")
    node.node_tree = group
    node.inputs["Paint"].default_value = (0.7, 0.2, 0.15, 1.0)
    node.inputs["Shine"].default_value = 0.4
    return node


def _copper(nt):
    """A Metallic BSDF whose roughness is the checker through a ColorRamp (0.15 to 0.6) and a
    Map Range (to 0.1 … 0.7)."""
    metal = _shader(nt, "BsdfMetallic", **{"Base Color": (0.95, 0.64, 0.54, 1.0)})
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = _checker_image()
    ramp = nt.nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.elements[0].color = (0.15, 0.15, 0.15, 1.0)
    ramp.color_ramp.elements[1].color = (0.6, 0.6, 0.6, 1.0)
    nt.links.new(tex.outputs["Color"], ramp.inputs["Fac"])
    # and a Map Range from [0, 1] to [0.1, 0.7] (clamped)
    remap = nt.nodes.new("ShaderNodeMapRange")
    remap.inputs["To Min"].default_value = 0.1
    remap.inputs["To Max"].default_value = 0.7
    nt.links.new(ramp.outputs["Color"], remap.inputs["Value"])
    nt.links.new(remap.outputs["Result"], metal.inputs["Roughness"])
    return metal


def _leaf_green(nt):
    """A Diffuse BSDF whose colour is an RGB node through a Bright/Contrast and an RGB Curves
    node (a constant)."""
    diffuse = _shader(nt, "BsdfDiffuse")
    rgb = nt.nodes.new("ShaderNodeRGB")
    rgb.outputs[0].default_value = (0.2, 0.6, 0.2, 1.0)
    bc = _shader(nt, "BrightContrast", Bright=0.05, Contrast=0.2)
    nt.links.new(rgb.outputs[0], bc.inputs["Color"])
    # then RGB Curves lifting the combined curve's middle and lowering the red one's
    curves = nt.nodes.new("ShaderNodeRGBCurve")
    curves.mapping.curves[3].points.new(0.5, 0.65)
    curves.mapping.curves[0].points.new(0.5, 0.35)
    curves.mapping.update()
    nt.links.new(bc.outputs[0], curves.inputs["Color"])
    nt.links.new(curves.outputs[0], diffuse.inputs["Color"])
    return diffuse


def _tinted_checker_diffuse(nt):
    """A Diffuse BSDF whose colour is the checker multiplied by a pale blue (Mix Color,
    Multiply, factor 0.7), its hue turned, saturation raised and value lowered (Hue/Saturation/Value)."""
    diffuse = _shader(nt, "BsdfDiffuse")
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = _checker_image()
    mix = nt.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    mix.blend_type = "MULTIPLY"
    mix.inputs["Factor"].default_value = 0.7
    nt.links.new(tex.outputs["Color"], mix.inputs[6])  # A (colour)
    mix.inputs[7].default_value = (0.6, 0.8, 1.0, 1.0)  # B (colour)
    hsv = _shader(nt, "HueSaturation", Hue=0.6, Saturation=1.3, Value=0.9)
    nt.links.new(mix.outputs[2], hsv.inputs["Color"])  # Result (colour)
    nt.links.new(hsv.outputs[0], diffuse.inputs["Color"])
    return diffuse


def _masked_tiles(nt):
    """A Mix Shader of a white Diffuse and a grey, fairly smooth Glossy BSDF whose factor is the
    checker through RGB to BW (a mask: mostly glossy on its light squares)."""
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = _checker_image()
    bw = nt.nodes.new("ShaderNodeRGBToBW")
    nt.links.new(tex.outputs["Color"], bw.inputs["Color"])
    mix = _combine(
        nt,
        "MixShader",
        _shader(nt, "BsdfDiffuse", Color=(0.9, 0.9, 0.9, 1.0)),
        _shader(nt, "BsdfGlossy", Color=(0.8, 0.8, 0.8, 1.0), Roughness=0.2),
    )
    nt.links.new(bw.outputs[0], mix.inputs[0])
    return mix


def _varnish(nt):
    """The classic varnish: a blue Diffuse and a white, smooth Glossy BSDF mixed by a Layer
    Weight's Fresnel output (blend 0.3)."""
    layer = _shader(nt, "LayerWeight", Blend=0.3)
    mix = _combine(
        nt,
        "MixShader",
        _shader(nt, "BsdfDiffuse", Color=(0.3, 0.5, 0.8, 1.0)),
        _shader(nt, "BsdfGlossy", Color=(1.0, 1.0, 1.0, 1.0), Roughness=0.1),
    )
    nt.links.new(layer.outputs["Fresnel"], mix.inputs[0])
    return mix


def _add_shader_objects(b):
    """The "shaders" variant's materials: a tinted rough Glass BSDF on the small sphere, a Mix
    Shader of a red Diffuse and a golden Glossy BSDF inside a node group on the big one, a Metallic
    BSDF (F82, its default Edge Tint; roughness from the checker through a ColorRamp and a Map
    Range) on a cube, a leaf card mixing a green Diffuse (an RGB node through Bright/Contrast and
    RGB Curves) and a yellow-green Translucent BSDF with a Transparent BSDF, a small ball adding
    an orange Emission to a Diffuse coloured by the checker times a pale blue (Mix Color,
    Multiply, then Hue/Saturation/Value), a card mixing a Diffuse and a Glossy BSDF by the checker
    (a mask through RGB to BW), and a sphere mixing them by a Layer Weight's Fresnel."""
    spheres = [o for o in b.context.scene.objects if o.name.startswith("Sphere")]
    small, big = sorted(spheres, key=lambda o: o.dimensions.x)
    glass = _node_material(
        "TintedGlass", lambda nt: _shader(nt, "BsdfGlass", Color=(0.75, 0.9, 0.8, 1.0), Roughness=0.15, IOR=1.5)
    )
    mixed = _node_material("DiffuseGlossy", _diffuse_glossy_group)
    for obj, mat in ((small, glass), (big, mixed)):
        obj.data.materials.clear()
        obj.data.materials.append(mat)
    b.ops.mesh.primitive_cube_add(size=0.5, location=(-1.35, 2.4, 0.25))
    b.context.active_object.rotation_euler = (0.0, 0.0, math.radians(30.0))
    b.context.active_object.data.materials.append(_node_material("Copper", _copper))
    b.ops.mesh.primitive_plane_add(size=0.6, location=(1.25, 1.1, 0.45), rotation=(math.radians(90.0), 0.0, 0.0))
    b.context.active_object.data.materials.append(
        _node_material(
            "Leaf",
            lambda nt: _combine(
                nt,
                "MixShader",
                _shader(nt, "BsdfTransparent"),
                _combine(nt, "MixShader", _leaf_green(nt), _shader(nt, "BsdfTranslucent", Color=(0.5, 0.8, 0.2, 1.0))),
                factor=0.6,
            ),
        )
    )
    b.ops.mesh.primitive_plane_add(size=0.8, location=(-0.9, 3.2, 1.0), rotation=(math.radians(90.0), 0.0, 0.0))
    b.context.active_object.data.materials.append(_node_material("Tiles", _masked_tiles))
    b.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16, radius=0.35, location=(1.55, 2.9, 0.35))
    b.ops.object.shade_smooth()
    b.context.active_object.data.materials.append(_node_material("Varnish", _varnish))
    b.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12, radius=0.15, location=(0.05, 1.0, 0.15))
    b.ops.object.shade_smooth()
    b.context.active_object.data.materials.append(
        _node_material(
            "GlowBall",
            lambda nt: _combine(
                nt,
                "AddShader",
                _shader(nt, "Emission", Color=(1.0, 0.6, 0.3, 1.0), Strength=2.0),
                _tinted_checker_diffuse(nt),
            ),
        )
    )


def _checker_image():
    """An 8-bit sRGB 8 x 8 checker of dark red and light grey, saved as PNG and packed: a byte
    image, which Cycles filters in its encoded values and decodes afterwards."""
    import numpy as np

    b = bpy()
    n = 8
    img = b.data.images.new("Checker8", n, n, alpha=False, float_buffer=False)
    img.colorspace_settings.name = "sRGB"
    i, j = np.meshgrid(np.arange(n), np.arange(n))
    dark = ((i + j) % 2 == 0)[..., None]
    px = np.where(dark, np.array([0.35, 0.05, 0.05, 1.0]), np.array([0.9, 0.9, 0.85, 1.0])).astype(np.float32)
    img.pixels.foreach_set(px.ravel())
    return _save_packed(img, "checker8.png", "PNG")


def _environment_image():
    """A float equirectangular sky: a blue-to-white gradient with a small bright warm patch, saved
    and packed. With the Mapping node's 40° Z rotation the patch is seen 15° right of the view
    axis of LightsCam, just above the horizon; with the rotation the wrong way round it would be
    out of view."""
    import numpy as np

    b = bpy()
    w, h = 256, 128
    img = b.data.images.new("Sky", w, h, alpha=False, float_buffer=True)
    img.colorspace_settings.name = "Linear Rec.709"
    v = (np.arange(h)[::-1] + 0.5) / h  # 0 at the bottom row: Blender's pixel rows go bottom up
    u = (np.arange(w) + 0.5) / w
    uu, vv = np.meshgrid(u, v)
    sky = np.zeros((h, w, 4), np.float32)
    sky[..., 0] = 0.25 + 0.3 * vv
    sky[..., 1] = 0.35 + 0.3 * vv
    sky[..., 2] = 0.6 + 0.2 * vv
    sky[..., 3] = 1.0
    # Blender's equirectangular lookup (Cycles direction_to_equirectangular): u = 0.5 - atan2(y, x) / 2pi,
    # v = 0.5 + asin(z) / pi, of the direction rotated by the Mapping node: azimuth atan2(y, x) = 75°
    # (15° right of the camera's +y view) + 40° -> u = 0.5 - 115 / 360
    u0 = 0.5 - (75.0 + LIGHTS_ENV_ROTATION_DEG) / 360.0
    blob = ((uu - u0) ** 2 / 0.02**2 + (vv - 0.53) ** 2 / 0.025**2) < 1.0
    sky[blob, :3] = (20.0, 15.0, 10.0)
    img.pixels.foreach_set(sky[::-1].ravel())  # rows bottom-first for Blender
    return _save_packed(img, "sky.exr", "OPEN_EXR")


def _save_packed(img, file_name: str, file_format: str):
    """Saves a generated image under OUT and packs it into the .blend; returns it."""
    OUT.mkdir(parents=True, exist_ok=True)
    img.filepath_raw = str(OUT / file_name)
    img.file_format = file_format
    img.save()
    img.pack()
    return img


def _paint_sphere(b, obj, mat, small: bool) -> None:
    """Colours a sphere from its mesh (variant "paint"): small, the default colour attribute
    (float, per corner: red to green across x, blue with height) read by an unnamed Color
    Attribute node; big, a byte colour attribute "Tint" per point (orange to cyan with height,
    stored in sRGB) read by an Attribute node."""
    me = obj.data
    nt = mat.node_tree
    bsdf = nt.nodes.get("Principled BSDF")
    if small:
        attr = me.color_attributes.new("Paint", "FLOAT_COLOR", "CORNER")
        me.attributes.default_color_name = "Paint"
        for loop in me.loops:
            co = me.vertices[loop.vertex_index].co.normalized()
            u, h = 0.5 + 0.5 * co.x, 0.5 + 0.5 * co.z
            attr.data[loop.index].color = (0.9 * u, 0.9 * (1.0 - u), 0.1 + 0.7 * h, 1.0)
        node = nt.nodes.new("ShaderNodeVertexColor")
    else:
        attr = me.color_attributes.new("Tint", "BYTE_COLOR", "POINT")
        for v in me.vertices:
            h = 0.5 + 0.5 * v.co.normalized().z
            attr.data[v.index].color = (0.9 - 0.7 * h, 0.4 + 0.2 * h, 0.1 + 0.8 * h, 1.0)
        node = nt.nodes.new("ShaderNodeAttribute")
        node.attribute_type = "GEOMETRY"
        node.attribute_name = "Tint"
    nt.links.new(node.outputs["Color"], bsdf.inputs["Base Color"])


def build_lights_scene(variant: str):
    """Diffuse ground and spheres lit by a rectangular and a disc area light (``variant``
    "area", black world), by an environment texture rotated by a Mapping node ("world", no
    lights), or by three spot lights of Spot Blend 0, 0.3 and 1 ("spots", black world). The
    "texture" lights the ground, coloured by a coarse 8-bit checker with Linear interpolation, by
    a sun. "soft" has a point light of radius 0.4 m (Soft Falloff, Blender's default), a spot light of
    radius 0.3 m with Soft Falloff off (a sphere) and a sun 12° wide,
    whose soft shadows the add-on renders as Cycles does (black world). "hidden" has an area light
    in view facing the camera (Blender 5 hides lights from camera rays) and a cube whose Camera ray
    visibility is off, both lighting or shadowing the scene, lit also by a sun (black world).
    "terminator" has smooth-shaded low-poly meshes lit from the side by a sun: Suzanne with
    Blender's default Shadow Terminator Geometry Offset (0.1) and a 12 x 6 UV sphere with 0.
    "glass" makes the two spheres glass (Transmission Weight 1: clear IOR 1.45, and a tinted one
    of roughness 0.3) over the checker ground, lit by the environment texture. "coat" coats the
    two spheres (a red dielectric with an orange Specular Tint and Specular IOR Level 0.75 under
    a smooth coat of weight 1; a metal under a rougher, tinted coat of weight 0.6 and IOR 1.8)
    over the same ground and light. "paint" colours the two spheres from the meshes: the small
    one's Base Color from a Color Attribute node with no name (the default colour attribute, per
    corner, float), the big one's from an Attribute node naming a per-point byte colour
    attribute, over the same ground and light. "ortho" is "texture"
    seen through an orthographic camera (Orthographic Scale 3 m, VERTICAL fit, shifted, f/4 focused
    at 2.5 m). "shaders" has shader nodes other than the Principled BSDF over the same ground and
    light (see ``_add_shader_objects``), the ground's checker tiled, turned and shifted by a
    Mapping node."""
    b = bpy()
    reset_blender()
    scene = b.context.scene
    world = b.data.worlds.new("World")
    if world.node_tree is None:
        world.use_nodes = True
    nt = world.node_tree
    bg = nt.nodes.get("Background")
    bg.inputs["Strength"].default_value = (
        0.5 if variant in ("world", "glass", "coat", "paint", "shaders", "aniso") else 0.0
    )
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = _environment_image()
    mapping = nt.nodes.new("ShaderNodeMapping")
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(LIGHTS_ENV_ROTATION_DEG))
    coords = nt.nodes.new("ShaderNodeTexCoord")
    nt.links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
    nt.links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    scene.world = world

    b.ops.mesh.primitive_plane_add(size=8.0, location=(0.0, 2.0, 0.0))
    ground = _principled_lambert("Ground", (0.5, 0.5, 0.5))
    if variant in ("texture", "glass", "ortho", "coat", "paint", "shaders", "aniso"):
        # the ground's colour from a coarse 8-bit checker with Linear interpolation
        tex = ground.node_tree.nodes.new("ShaderNodeTexImage")
        tex.image = _checker_image()
        tex.interpolation = "Linear"
        bsdf = ground.node_tree.nodes.get("Principled BSDF")
        ground.node_tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
        if variant == "shaders":
            # the checker tiled, turned and shifted by a Mapping node on the UV map
            coords = ground.node_tree.nodes.new("ShaderNodeTexCoord")
            mapping = ground.node_tree.nodes.new("ShaderNodeMapping")
            mapping.inputs["Location"].default_value = (0.1, 0.25, 0.0)
            mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(25.0))
            mapping.inputs["Scale"].default_value = (2.0, 1.5, 1.0)
            ground.node_tree.links.new(coords.outputs["UV"], mapping.inputs["Vector"])
            ground.node_tree.links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
    if variant in ("texture", "ortho"):
        sun = b.data.lights.new("TexSun", "SUN")
        sun.energy = 2.0
        sun_obj = b.data.objects.new("TexSun", sun)
        scene.collection.objects.link(sun_obj)
        sun_obj.rotation_euler = (math.radians(20.0), 0.0, math.radians(10.0))
    b.context.active_object.data.materials.append(ground)
    for loc, r, col in (((-0.5, 1.5, 0.35), 0.35, (0.7, 0.2, 0.15)), ((0.6, 2.2, 0.5), 0.5, (0.2, 0.6, 0.3))):
        b.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16, radius=r, location=loc)
        b.ops.object.shade_smooth()
        mat = _principled_lambert("Sphere", col)
        if variant == "glass":
            p = mat.node_tree.nodes.get("Principled BSDF")
            p.inputs["Transmission Weight"].default_value = 1.0
            p.inputs["IOR"].default_value = 1.45
            p.inputs["Specular IOR Level"].default_value = 0.5
            rough = r < 0.4
            p.inputs["Roughness"].default_value = 0.3 if rough else 0.0
            p.inputs["Base Color"].default_value = (0.75, 0.9, 0.8, 1.0) if rough else (1.0, 1.0, 1.0, 1.0)
        if variant == "coat":
            p = mat.node_tree.nodes.get("Principled BSDF")
            small = r < 0.4
            p.inputs["Coat Weight"].default_value = 1.0 if small else 0.6
            p.inputs["Coat Roughness"].default_value = 0.05 if small else 0.25
            p.inputs["Coat IOR"].default_value = 1.5 if small else 1.8
            p.inputs["Coat Tint"].default_value = (1.0, 1.0, 1.0, 1.0) if small else (0.9, 0.6, 0.3, 1.0)
            p.inputs["Roughness"].default_value = 0.5 if small else 0.35
            p.inputs["Metallic"].default_value = 0.0 if small else 1.0
            if small:
                # a coloured Specular Tint on the dielectric layer under the coat
                p.inputs["Specular Tint"].default_value = (1.0, 0.55, 0.25, 1.0)
                p.inputs["Specular IOR Level"].default_value = 0.75
        if variant == "paint":
            _paint_sphere(b, b.context.active_object, mat, small=r < 0.4)
        if variant == "aniso":
            _anisotropic_sphere(mat, small=r < 0.4)
        b.context.active_object.data.materials.append(mat)
    if variant == "shaders":
        _add_shader_objects(b)
    if variant == "aniso":
        _add_anisotropic_objects(b)

    lights = (("Rect", "RECTANGLE", 1.0, 0.5, (0.8, 1.0, 2.6), 300.0, (1.0, 0.85, 0.7)),
              ("Disc", "DISK", 0.6, 0.6, (-1.2, 2.5, 2.4), 150.0, (0.7, 0.8, 1.0)))
    for name, shape, size, size_y, loc, power, colour in (lights if variant == "area" else ()):
        data = b.data.lights.new(name, "AREA")
        data.shape = shape
        data.size = size
        data.size_y = size_y
        data.energy = power
        data.color = colour
        obj = b.data.objects.new(name, data)
        scene.collection.objects.link(obj)
        obj.location = loc  # no rotation: emits down (-z)
    spots = (("Spot0", -1.3, 0.0), ("Spot03", 0.0, 0.3), ("Spot1", 1.3, 1.0))
    for name, x, blend in spots if variant == "spots" else ():
        data = b.data.lights.new(name, "SPOT")
        data.energy = 400.0
        data.spot_size = math.radians(60.0)
        data.spot_blend = blend
        data.shadow_soft_size = 0.0  # a true point: the add-on's spots are punctual
        obj = b.data.objects.new(name, data)
        scene.collection.objects.link(obj)
        obj.location = (x, 2.2, 2.2)  # no rotation: points down (-z)
    if variant in ("soft", "soft_point"):
        data = b.data.lights.new("SoftPoint", "POINT")
        data.energy = 250.0
        data.shadow_soft_size = 0.4
        obj = b.data.objects.new("SoftPoint", data)
        scene.collection.objects.link(obj)
        obj.location = (-0.9, 1.3, 1.5)
        # and a spot light emitting from a sphere (Soft Falloff off), close to the ground
        data = b.data.lights.new("SphereSpot", "SPOT")
        data.energy = 120.0
        data.spot_size = math.radians(70.0)
        data.spot_blend = 0.2
        data.shadow_soft_size = 0.3
        data.use_soft_falloff = False
        obj = b.data.objects.new("SphereSpot", data)
        scene.collection.objects.link(obj)
        obj.location = (1.0, 1.6, 0.9)
    if variant in ("soft", "soft_sun"):
        data = b.data.lights.new("WideSun", "SUN")
        data.energy = 1.5
        data.angle = math.radians(12.0)
        data.color = (0.8, 0.9, 1.0)
        obj = b.data.objects.new("WideSun", data)
        scene.collection.objects.link(obj)
        obj.rotation_euler = (math.radians(40.0), 0.0, math.radians(-35.0))
    if variant == "hidden":
        data = b.data.lights.new("FacingRect", "AREA")
        data.shape = "RECTANGLE"
        data.size = 1.2
        data.size_y = 0.6
        data.energy = 200.0
        obj = b.data.objects.new("FacingRect", data)
        scene.collection.objects.link(obj)
        obj.location = (0.3, 3.6, 1.1)
        obj.rotation_euler = (math.radians(-90.0), 0.0, 0.0)  # emits toward -y: at the camera
        assert not obj.visible_camera, "Blender 5 hides new lights from camera rays"
        data = b.data.lights.new("HiddenSun", "SUN")
        data.energy = 1.5
        obj = b.data.objects.new("HiddenSun", data)
        scene.collection.objects.link(obj)
        obj.rotation_euler = (math.radians(40.0), 0.0, math.radians(30.0))
        b.ops.mesh.primitive_cube_add(size=0.5, location=(-0.2, 0.9, 0.25))
        card = b.context.active_object
        card.data.materials.append(_principled_lambert("Card", (0.8, 0.8, 0.8)))
        card.visible_camera = False
    if variant == "terminator":
        data = b.data.lights.new("SideSun", "SUN")
        data.energy = 3.0
        obj = b.data.objects.new("SideSun", data)
        scene.collection.objects.link(obj)
        obj.rotation_euler = (math.radians(80.0), 0.0, math.radians(70.0))  # low, from the side
        b.ops.mesh.primitive_monkey_add(size=0.8, location=(-0.6, 0.6, 0.45))
        monkey = b.context.active_object
        b.ops.object.shade_smooth()
        monkey.data.materials.append(_principled_lambert("Monkey", (0.7, 0.7, 0.7)))
        assert abs(monkey.shadow_terminator_geometry_offset - 0.1) < 1e-6, "Blender's default offset"
        b.ops.mesh.primitive_uv_sphere_add(segments=12, ring_count=6, radius=0.4, location=(0.7, 0.8, 0.4))
        ball = b.context.active_object
        b.ops.object.shade_smooth()
        ball.data.materials.append(_principled_lambert("Ball", (0.6, 0.65, 0.7)))
        ball.shadow_terminator_geometry_offset = 0.0
    cam = add_camera("LightsCam", (0.0, -2.6, 0.9), (math.radians(80.0), 0.0, 0.0), lens_mm=28.0)
    cam.data.dof.use_dof = False
    if variant == "ortho":
        cam.data.type = "ORTHO"
        cam.data.ortho_scale = 3.0
        cam.data.sensor_fit = "VERTICAL"  # the image height spans the scale
        cam.data.shift_x, cam.data.shift_y = 0.06, 0.04
        # Cycles' orthographic depth of field: aperture radius 1/(2N) = 0.125 m, focused at 2.5 m
        cam.data.dof.use_dof = True
        cam.data.dof.aperture_fstop = 4.0
        cam.data.dof.focus_distance = 2.5
    scene.render.resolution_x, scene.render.resolution_y = LIGHTS_RESOLUTION
    scene.render.resolution_percentage = 100
    return cam


def lights_cycles_reference(variant: str, seed: int, spp: int) -> Path:
    """Cycles render of build_lights_scene(variant) (cached by this file's text and the Blender
    build; the scene must be built)."""
    import os

    b = bpy()
    h = hashlib.sha256()
    h.update(Path(__file__).read_bytes())
    h.update(b.app.version_string.encode())
    h.update(str(b.app.build_hash).encode())
    cache = OUT / f"cycles-{h.hexdigest()[:16]}"
    cache.mkdir(parents=True, exist_ok=True)
    exr = cache / f"cycles_lights_{variant}_spp{spp}_seed{seed}.exr"
    if exr.is_file() and not os.environ.get("PETZVAL_BLENDER_NO_CACHE"):
        return exr
    S.render_cycles(S.CyclesSettings(samples=spp, seed=seed), "LightsCam", exr)
    return exr
