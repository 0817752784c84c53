"""Skins and shape keys against Cycles through Blender's GLB export with its animation: a
smooth tube bent by a two-bone armature and an icosphere with two shape keys (one animated),
on a matte floor under a sun, rendered at frame 13 by Cycles and by `petzval render --frame 13`
(the joints' and the weights' channels evaluated at 13 / 24 s; renderer/src/scene/gltf/deform.rs).

Exported as a user would: the exporter's defaults (animation, skins and shape keys on, modifiers
not applied), so the tube arrives in its rest pose with a skin and the icosphere as morph
targets. The whole image is compared in 8×8 blocks (z-test, two seeds a side; the criteria of
test_cycles_match.py) and its mean. The negative control is the same file without its skin and
morph weights animated (the animations removed): the rest pose must fail the z-test by far.
The same scene exported to USD with its animation (a Skeleton, a SkelAnimation, BlendShapes)
and rendered at time code 13 is compared with the same Cycles images.
"""

from __future__ import annotations

import json
import math
import subprocess
from pathlib import Path

import numpy as np
import pytest

try:
    import bpy
except Exception as e:  # ImportError, or a broken install
    pytest.skip(f"Blender's Python module cannot be imported ({type(e).__name__}: {e})", allow_module_level=True)

from mathutils import Vector
from renders import edit_glb, pinhole_glb_args, run_petzval, scene_pairs
from test_cycles_match import MEAN_TOL, _block_verdict, _fmt_verdict, _glb_json, _passes

import blender_compare as B
import blender_scenes as S

SPP = 128
SEEDS = (0, 1)
RESOLUTION = (240, 160)
WORLD_RGB = (0.05, 0.05, 0.06)
CAMERA_NAME = "SkinCam"
FRAME = 13


def build_scene(tmpdir: Path) -> None:
    """Resets Blender and builds the scene at frame 13."""
    tmpdir.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps, scene.frame_start, scene.frame_end = 24, 1, 24
    S.set_world_colour(bpy, scene, WORLD_RGB)
    bpy.ops.mesh.primitive_plane_add(size=12.0)
    bpy.context.active_object.data.materials.append(S._principled(bpy, "Matte", base=(0.8, 0.8, 0.8)))
    # 1. A tube bent by a two-bone armature (weights blending over the joint).
    rig = bpy.data.objects.new("Rig", bpy.data.armatures.new("Rig"))
    scene.collection.objects.link(rig)
    rig.location = (0.6, 0.3, 0.0)
    bpy.context.view_layer.objects.active = rig
    bpy.ops.object.mode_set(mode="EDIT")
    root = rig.data.edit_bones.new("Root")
    root.head, root.tail = (0, 0, 0), (0, 0, 0.8)
    tip = rig.data.edit_bones.new("Tip")
    tip.head, tip.tail, tip.parent, tip.use_connect = (0, 0, 0.8), (0, 0, 1.6), root, True
    bpy.ops.object.mode_set(mode="OBJECT")
    bpy.ops.mesh.primitive_cylinder_add(vertices=32, radius=0.22, depth=1.6, location=(0.6, 0.3, 0.8))
    tube = bpy.context.active_object
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.mesh.subdivide(number_cuts=9)
    bpy.ops.object.mode_set(mode="OBJECT")
    bpy.ops.object.shade_smooth()
    tube.data.materials.append(S._principled(bpy, "Red", base=(0.70, 0.12, 0.08)))
    g_root, g_tip = tube.vertex_groups.new(name="Root"), tube.vertex_groups.new(name="Tip")
    for v in tube.data.vertices:
        w = min(1.0, max(0.0, (v.co.z + 0.8 - 0.6) / 0.4))
        if w < 1.0:
            g_root.add([v.index], 1.0 - w, "REPLACE")
        if w > 0.0:
            g_tip.add([v.index], w, "REPLACE")
    tube.parent = rig
    tube.matrix_parent_inverse = rig.matrix_world.inverted()
    tube.modifiers.new("Armature", "ARMATURE").object = rig
    for b in rig.pose.bones:
        b.rotation_mode = "XYZ"
    for frame, r0, r1 in ((1, 0.0, 0.0), (24, 0.5, -1.2)):
        rig.pose.bones["Root"].rotation_euler = (0.0, r0, 0.0)
        rig.pose.bones["Tip"].rotation_euler = (r1, 0.0, 0.0)
        for b in rig.pose.bones:
            b.keyframe_insert("rotation_euler", frame=frame)
    # 2. An icosphere with two shape keys, one animated.
    bpy.ops.object.select_all(action="DESELECT")
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=4, radius=0.45, location=(-0.9, 0.0, 0.5))
    blob = bpy.context.active_object
    bpy.ops.object.shade_smooth()
    blob.data.materials.append(S._principled(bpy, "Blue", base=(0.10, 0.20, 0.65)))
    blob.shape_key_add(name="Basis")
    push = blob.shape_key_add(name="Push")
    for i, v in enumerate(blob.data.vertices):
        if v.co.z > 0:
            push.data[i].co = v.co + Vector((0.25, 0.0, 0.5 * v.co.z))
    squash = blob.shape_key_add(name="Squash")
    for i, v in enumerate(blob.data.vertices):
        squash.data[i].co = Vector((1.3 * v.co.x, 1.3 * v.co.y, 0.75 * v.co.z))
    squash.value = 0.4
    for frame, value in ((1, 0.0), (24, 1.0)):
        push.value = value
        push.keyframe_insert("value", frame=frame)
    # 3. Light, camera, the frame.
    S._add_light(bpy, "SUN", "Sun", (0.0, 0.0, 5.0), 3.0, target=(1.5, 2.0, 0.0))
    cam = bpy.data.objects.new(CAMERA_NAME, bpy.data.cameras.new(CAMERA_NAME))
    scene.collection.objects.link(cam)
    cam.location, cam.rotation_euler = (0.0, -4.6, 2.0), (math.radians(72.0), 0.0, 0.0)
    cam.data.lens, cam.data.sensor_width = 35.0, 36.0
    cam.data.dof.use_dof = False
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = RESOLUTION
    scene.render.resolution_percentage = 100
    scene.frame_set(FRAME)


def export_animated(path: Path) -> Path:
    """The exporter's defaults (animation, skins, shape keys; modifiers not applied)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    bpy.ops.export_scene.gltf(
        filepath=str(path), export_format="GLB", export_cameras=True, export_lights=True,
        export_import_convert_lighting_mode="SPEC",
    )  # fmt: skip
    return path


def _args() -> list[str]:
    return [*pinhole_glb_args(CAMERA_NAME, WORLD_RGB, RESOLUTION), "--frame", str(FRAME)]


@pytest.fixture(scope="module")
def skin_run(blender_run):
    """The scene's export, Cycles' renders (cached) and petzval's; afterwards rebuilds the main
    scene, which the other modules' tests read from Blender."""
    key_files = ("test_skin_cycles.py", "blender_scenes.py")
    try:
        glb, cyc, pz, workdir = scene_pairs(
            blender_run, "skin", key_files, build_scene, CAMERA_NAME, _args(), SPP, SEEDS, export=export_animated
        )
        # the same scene through Blender's USD export with its animation (UsdSkel)
        usd = workdir / "skin.usdc"
        bpy.ops.wm.usd_export(filepath=str(usd), export_animation=True)
        yield glb, cyc, pz, usd
    finally:
        S.build_scene(blender_run.workdir)


def test_skinned_and_morphed_meshes_match_cycles(skin_run, report):
    glb, cyc, pz, _ = skin_run
    doc = _glb_json(glb)
    assert doc.get("skins") and any(p.get("targets") for m in doc["meshes"] for p in m["primitives"]), (
        "the export has no skin or no morph targets"
    )
    v = _block_verdict(B.compare_blocks(cyc[0], cyc[1], pz[0], pz[1]))
    ratio = B.mean_ratio((pz[0] + pz[1]) / 2, (cyc[0] + cyc[1]) / 2)
    report.line(
        f"skin + shape keys (glTF, frame {FRAME}) vs Cycles, {SPP} spp x seeds {len(SEEDS)}: {_fmt_verdict(v)}; "
        f"image mean petzval/Cycles R,G,B {ratio[0]:.4f} {ratio[1]:.4f} {ratio[2]:.4f}"
    )
    assert np.all(np.abs(ratio - 1) <= MEAN_TOL), f"image mean ratio {ratio}"
    assert _passes(v), f"blocks differ beyond noise: {_fmt_verdict(v)}"


def test_the_rest_pose_is_the_negative_control(skin_run, blender_run, report):
    glb, cyc, _, _ = skin_run
    rest = edit_glb(glb, glb.with_name("rest.glb"), lambda doc: doc.pop("animations", None))
    pz = []
    for seed in SEEDS:
        out = glb.with_name(f"rest_seed{seed}.exr")
        run_petzval(blender_run.binary, rest, out, _args(), SPP, seed)
        pz.append(B.read_rgb(out))
    v = _block_verdict(B.compare_blocks(cyc[0], cyc[1], pz[0], pz[1]))
    report.line(f"  negative control, the rest pose (animations removed): {_fmt_verdict(v)}")
    assert v["mean_z2"] > 20 * 1.5, f"the rest pose still passes: {_fmt_verdict(v)}"


def test_the_usd_export_matches_cycles(skin_run, blender_run, report):
    """The same scene through Blender's USD export with its animation: a Skeleton with a
    SkelAnimation and BlendShapes (usd/src/skel.rs), rendered at time code 13."""
    _, cyc, _, usd = skin_run
    info = subprocess.run(
        [str(blender_run.binary), "usd", "info", str(usd), "--json"], capture_output=True, text=True, check=True
    )
    (cam,) = [c["path"] for c in json.loads(info.stdout)["cameras"] if f"/{CAMERA_NAME}/" in c["path"] + "/"]
    args = _args()
    args[args.index("--camera") + 1] = cam
    for flag in ("--sensor-width", "--environment"):  # the stage's camera and dome light
        i = args.index(flag)
        del args[i : i + 2]
    pz = []
    for seed in SEEDS:
        out = usd.with_name(f"usd_seed{seed}.exr")
        run_petzval(blender_run.binary, usd, out, args, SPP, seed)
        pz.append(B.read_rgb(out))
    v = _block_verdict(B.compare_blocks(cyc[0], cyc[1], pz[0], pz[1]))
    ratio = B.mean_ratio((pz[0] + pz[1]) / 2, (cyc[0] + cyc[1]) / 2)
    report.line(
        f"  the same through USD (UsdSkel, time code {FRAME}): {_fmt_verdict(v)}; "
        f"image mean petzval/Cycles R,G,B {ratio[0]:.4f} {ratio[1]:.4f} {ratio[2]:.4f}"
    )
    assert np.all(np.abs(ratio - 1) <= MEAN_TOL), f"image mean ratio {ratio}"
    assert _passes(v), f"blocks differ beyond noise: {_fmt_verdict(v)}"
