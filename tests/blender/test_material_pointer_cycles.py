"""Animated materials against Cycles through Blender's KHR_animation_pointer export: two planes
under a sun seen from above, one whose Principled Emission Color and Strength are keyframed
(frames 10 -> 40), one whose Base Color is (matte, no specular). Cycles renders Blender's scene
at frame 25; petzval renders the export (Scene mode, "Export Pointer Animation") at --frame 25
--fps 30. Each plane's mean colour must agree within MEAN_TOL.

The negative control is the same export with its material channels removed (what petzval read
before material pointers were supported: the materials' frame-10 values): it must miss by far
(session 39: emission 0.44 / 0.22 / 0 and paint 1.78 / 0.80 / 0.20 of Cycles per channel).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

try:
    import bpy
except Exception as e:  # ImportError, or a broken install
    pytest.skip(f"Blender's Python module cannot be imported ({type(e).__name__}: {e})", allow_module_level=True)

from renders import cache_key, cached_render, edit_glb, pinhole_glb_args, run_petzval
from test_cycles_match import MEAN_TOL

import blender_compare as B
import blender_scenes as S

SPP = 16
RESOLUTION = (96, 48)
CAMERA_NAME = "TopCam"
FRAME = 25
# (rows, columns) of each plane's middle in the image
WINDOWS = {"Glow": (slice(14, 34), slice(14, 34)), "Paint": (slice(14, 34), slice(62, 82))}


def _keyed(socket, frames_values) -> None:
    for frame, value in frames_values:
        socket.default_value = value
        socket.keyframe_insert("default_value", frame=frame)


def build_scene() -> None:
    """Resets Blender and builds the scene (linear keys at frames 10 and 40, 30 fps)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = 30
    scene.frame_start, scene.frame_end = 10, 40
    S.set_world_colour(bpy, scene, (0.0, 0.0, 0.0))
    inputs = {}
    for name, x in (("Glow", -1.1), ("Paint", 1.1)):
        bpy.ops.mesh.primitive_plane_add(size=2.0, location=(x, 0.0, 0.0))
        material = bpy.data.materials.new(name)
        bpy.context.object.data.materials.append(material)
        inputs[name] = material.node_tree.nodes["Principled BSDF"].inputs
        inputs[name]["Roughness"].default_value = 1.0
        inputs[name]["Specular IOR Level"].default_value = 0.0
    inputs["Glow"]["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    _keyed(inputs["Glow"]["Emission Color"], ((10, (1.0, 0.5, 0.0, 1.0)), (40, (0.0, 0.5, 1.0, 1.0))))
    _keyed(inputs["Glow"]["Emission Strength"], ((10, 0.5), (40, 4.0)))
    _keyed(inputs["Paint"]["Base Color"], ((10, (0.8, 0.2, 0.1, 1.0)), (40, (0.1, 0.3, 0.9, 1.0))))
    for action in bpy.data.actions:
        for layer in action.layers:
            for strip in layer.strips:
                for bag in strip.channelbags:
                    for fc in bag.fcurves:
                        for k in fc.keyframe_points:
                            k.interpolation = "LINEAR"
    sun = bpy.data.lights.new("Sun", "SUN")
    sun.energy, sun.angle = 3.0, 0.0
    scene.collection.objects.link(bpy.data.objects.new("Sun", sun))
    cam = bpy.data.objects.new(CAMERA_NAME, bpy.data.cameras.new(CAMERA_NAME))
    cam.data.lens, cam.data.sensor_width, cam.data.sensor_fit = 50.0, 36.0, "HORIZONTAL"
    cam.location = (0.0, 0.0, 6.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = RESOLUTION
    scene.render.resolution_percentage = 100


def _means(img: np.ndarray) -> dict[str, np.ndarray]:
    return {name: img[ys, xs].reshape(-1, 3).mean(axis=0) for name, (ys, xs) in WINDOWS.items()}


def _worst(pz: dict, cyc: dict) -> float:
    """The largest relative difference of a channel's mean, over both planes (channels Cycles
    renders above 10⁻³ only: the emission's blue is 0 at frame 10)."""
    return max(float(np.max(np.abs(pz[n] - cyc[n])[cyc[n] > 1e-3] / cyc[n][cyc[n] > 1e-3])) for n in WINDOWS)


@pytest.fixture(scope="module")
def pointer_run(blender_run):
    """The export, Cycles' render at FRAME (cached) and the petzval arguments; afterwards
    rebuilds the main scene, which the other modules' tests read from Blender."""
    try:
        yield _pointer_renders(blender_run)
    finally:
        S.build_scene(blender_run.workdir)


def _pointer_renders(blender_run):
    workdir = blender_run.workdir / "material_pointer"
    workdir.mkdir(parents=True, exist_ok=True)
    build_scene()
    glb = workdir / "material_pointer.glb"
    bpy.ops.export_scene.gltf(
        filepath=str(glb),
        export_format="GLB",
        export_cameras=True,
        export_lights=True,
        export_animations=True,
        export_animation_mode="SCENE",
        export_pointer_animation=True,
    )
    bpy.context.scene.frame_set(FRAME)
    cache_dir = blender_run.cache_dir.parent / f"cycles-material_pointer-{cache_key(bpy, Path(__file__).name)}"
    cache_dir.mkdir(parents=True, exist_ok=True)
    cfg = S.CyclesSettings(samples=SPP, seed=0)
    exr, _, _ = cached_render(bpy, cache_dir, f"cycles_f{FRAME}", lambda out: S.render_cycles(cfg, CAMERA_NAME, out))
    args = [*pinhole_glb_args(CAMERA_NAME, (0.0, 0.0, 0.0), RESOLUTION), "--frame", str(FRAME), "--fps", "30"]
    return blender_run, glb, args, _means(B.read_rgb(exr)), workdir


def test_animated_materials_match_cycles_at_the_frame(pointer_run, report):
    blender_run, glb, args, cyc, workdir = pointer_run
    out = workdir / "petzval.exr"
    _, stderr = run_petzval(blender_run.binary, glb, out, args, SPP, 0)
    assert "KHR_animation_pointer" not in stderr, stderr
    pz = _means(B.read_rgb(out))
    worst = _worst(pz, cyc)
    report.line(f"material pointers at frame {FRAME}: worst plane-channel mean {worst:.2e} from Cycles")
    assert worst <= MEAN_TOL, f"petzval {pz} against Cycles {cyc}"


def test_negative_control_without_the_material_channels(pointer_run, report):
    blender_run, glb, args, cyc, workdir = pointer_run

    def drop_material_channels(doc: dict) -> None:
        for anim in doc["animations"]:
            keep = [
                c
                for c in anim["channels"]
                if not c["target"]
                .get("extensions", {})
                .get("KHR_animation_pointer", {})
                .get("pointer", "")
                .startswith("/materials/")
            ]
            anim["channels"] = keep

    control = edit_glb(glb, workdir / "no_material_channels.glb", drop_material_channels)
    out = workdir / "petzval_control.exr"
    run_petzval(blender_run.binary, control, out, args, SPP, 0)
    worst = _worst(_means(B.read_rgb(out)), cyc)
    report.line(f"material pointers, control without the material channels: worst {worst:.2f} from Cycles")
    assert worst > 0.5, f"the control is within {worst:.2e} of Cycles: the test cannot fail"
