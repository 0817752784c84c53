"""Alpha cut-outs against Cycles through Blender's GLB export: a leaf, a quad whose Principled
Alpha comes from its image's alpha (a disc; 8-bit sRGB PNG, Linear), which Blender exports as
alphaMode BLEND, standing on a matte floor under a low sun; its shadow and its cut-out edge.
petzval takes a BLEND surface stochastically (a ray passes with probability 1 − alpha), Cycles
as a transparent mix: the same in expectation.

The whole image is compared in 8×8 blocks (z-test, two seeds a side; the criteria of
test_cycles_match.py) and its mean. The negative control is the same export with the leaf's
alpha mode set to OPAQUE: it must fail the z-test by far. (Session 33 first suspected a
difference in this leaf's shadow; it was the glossy floor's grazing difference of
test_normal_maps_cycles.py, and on a matte floor the leaf matches.)
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

try:
    import bpy
except Exception as e:  # ImportError, or a broken install
    pytest.skip(f"Blender's Python module cannot be imported ({type(e).__name__}: {e})", allow_module_level=True)

from renders import edit_glb, pinhole_glb_args, run_petzval, scene_pairs
from test_cycles_match import MEAN_TOL, _block_verdict, _fmt_verdict, _passes
from test_normal_maps_cycles import _image

import blender_compare as B
import blender_scenes as S

SPP = 128
SEEDS = (0, 1)
RESOLUTION = (240, 160)
WORLD_RGB = (0.05, 0.05, 0.06)
CAMERA_NAME = "LeafCam"


def build_scene(tmpdir: Path) -> None:
    """Resets Blender and builds the scene."""
    tmpdir.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    S.set_world_colour(bpy, scene, WORLD_RGB)
    n = 128
    y, x = np.mgrid[0:n, 0:n] / n
    disc = ((x - 0.5) ** 2 + (y - 0.5) ** 2 < 0.16).astype(float)
    leaf = _image("leaf", np.stack([0.2 + 0 * x, 0.6 + 0.3 * x, 0.2 + 0 * x, disc], -1), "sRGB", tmpdir)
    mat = bpy.data.materials.new("Leaf")
    nt = mat.node_tree
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = leaf
    nt.links.new(tex.outputs["Color"], nt.nodes["Principled BSDF"].inputs["Base Color"])
    nt.links.new(tex.outputs["Alpha"], nt.nodes["Principled BSDF"].inputs["Alpha"])
    floor = S._principled(bpy, "Matte", base=(0.8, 0.8, 0.8))
    bpy.ops.mesh.primitive_plane_add(size=12.0)
    bpy.context.active_object.data.materials.append(floor)
    bpy.ops.mesh.primitive_plane_add(
        size=1.2, location=(0.9, 0.4, 0.8), rotation=(math.radians(80.0), 0.0, math.radians(-20.0))
    )
    bpy.context.active_object.data.materials.append(mat)
    S._add_light(bpy, "SUN", "Sun", (0.0, 0.0, 5.0), 2.0, target=(2.0, 1.0, 4.2))
    cam = bpy.data.objects.new(CAMERA_NAME, bpy.data.cameras.new(CAMERA_NAME))
    scene.collection.objects.link(cam)
    cam.location, cam.rotation_euler = (0.3, -4.5, 2.6), (math.radians(62.0), 0.0, 0.0)
    cam.data.lens, cam.data.sensor_width = 35.0, 36.0
    cam.data.dof.use_dof = False
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = RESOLUTION
    scene.render.resolution_percentage = 100


def _args() -> list[str]:
    return pinhole_glb_args(CAMERA_NAME, WORLD_RGB, RESOLUTION)


@pytest.fixture(scope="module")
def leaf_run(blender_run):
    """The scene's export, Cycles' renders (cached) and petzval's; afterwards rebuilds the main
    scene, which the other modules' tests read from Blender."""
    key_files = ("test_alpha_cycles.py", "test_normal_maps_cycles.py", "blender_scenes.py")
    try:
        glb, cyc, pz, _ = scene_pairs(blender_run, "alpha", key_files, build_scene, CAMERA_NAME, _args(), SPP, SEEDS)
        yield glb, cyc, pz
    finally:
        S.build_scene(blender_run.workdir)


def test_alpha_cut_out_leaf_matches_cycles(leaf_run, report):
    glb, cyc, pz = leaf_run
    from test_cycles_match import _glb_json

    modes = [m.get("alphaMode") for m in _glb_json(glb)["materials"]]
    assert "BLEND" in modes, f"the leaf's alpha mode in the export: {modes}"
    v = _block_verdict(B.compare_blocks(cyc[0], cyc[1], pz[0], pz[1]))
    ratio = B.mean_ratio((pz[0] + pz[1]) / 2, (cyc[0] + cyc[1]) / 2)
    report.line(
        f"alpha cut-out leaf (glTF BLEND) vs Cycles, {SPP} spp x seeds {len(SEEDS)}: {_fmt_verdict(v)}; "
        f"image mean petzval/Cycles R,G,B {ratio[0]:.4f} {ratio[1]:.4f} {ratio[2]:.4f}"
    )
    assert np.all(np.abs(ratio - 1) <= MEAN_TOL), f"image mean ratio {ratio}"
    assert _passes(v), f"blocks differ beyond noise: {_fmt_verdict(v)}"


def test_an_opaque_leaf_is_the_negative_control(leaf_run, blender_run, report):
    glb, cyc, _ = leaf_run

    def opaque(doc):
        for m in doc["materials"]:
            if m.get("alphaMode") == "BLEND":
                m["alphaMode"] = "OPAQUE"

    solid = edit_glb(glb, glb.with_name("opaque.glb"), opaque)
    pz = []
    for seed in SEEDS:
        out = glb.with_name(f"opaque_seed{seed}.exr")
        run_petzval(blender_run.binary, solid, out, _args(), SPP, seed)
        pz.append(B.read_rgb(out))
    v = _block_verdict(B.compare_blocks(cyc[0], cyc[1], pz[0], pz[1]))
    report.line(f"  negative control, the leaf opaque: {_fmt_verdict(v)}")
    assert v["mean_z2"] > 20 * 1.5, f"an opaque leaf still passes: {_fmt_verdict(v)}"
