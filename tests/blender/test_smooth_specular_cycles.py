"""Specular reflection off smooth-shaded low-poly meshes against Cycles: Cycles turns a shading
normal that would reflect the view below the geometric surface toward the geometric normal
(`ensure_valid_specular_reflection`, Blender's Bump Map Correction, on by default) wherever
the shading normal differs from the geometric one: on normal-mapped surfaces and on every
smooth-shaded mesh, whose interpolated normals lean away from their flat facets. Near a
low-poly silhouette the uncorrected reflection goes into the surface and is lost.

Scene: smooth-shaded low-poly spheres and a cylinder smoothed by angle (smooth sides, flat
caps) of two glossy dielectrics (roughness 0.1 and 0.08; dielectrics, because a metal's
Fresnel at grazing angles differs between Cycles' F82 model and the glTF export's Schlick by
design, see test_metals_cycles.py, and a polished metal's rims put that difference exactly
where this test looks), in a bright uniform world with a sun, over a matte floor; Blender's
GLB export rendered by both. The whole image is compared in 8×8 blocks (z-test, two seeds a
side; the criteria of test_cycles_match.py) and its mean. Before the correction: mean z² 137,
max |z| 108 (docs/cycles-comparison.md, "Smooth-shaded low-poly meshes").
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

from renders import pinhole_glb_args, scene_pairs
from test_cycles_match import MEAN_TOL, _block_verdict, _fmt_verdict, _passes

import blender_compare as B
import blender_scenes as S

SPP = 128
SEEDS = (0, 1)
RESOLUTION = (240, 160)
WORLD_RGB = (0.5, 0.55, 0.6)
CAMERA_NAME = "GlintCam"


def _glossy(name, base, roughness, metallic, specular=0.5):
    mat = S._principled(bpy, name, base=base, roughness=roughness)
    p = mat.node_tree.nodes.get("Principled BSDF")
    p.inputs["Metallic"].default_value = metallic
    p.inputs["Specular IOR Level"].default_value = specular
    return mat


def build_scene(tmpdir: Path) -> None:
    """Resets Blender and builds the scene."""
    tmpdir.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    S.set_world_colour(bpy, scene, WORLD_RGB)
    bpy.ops.mesh.primitive_plane_add(size=14.0)
    bpy.context.active_object.data.materials.append(S._principled(bpy, "Matte", base=(0.3, 0.3, 0.3)))
    porcelain = _glossy("Porcelain", (0.8, 0.8, 0.8), 0.1, 0.0)
    plastic = _glossy("Glossy", (0.05, 0.1, 0.4), 0.08, 0.0)
    for mat, loc, segments in ((porcelain, (-1.1, 0.0, 0.7), 10), (plastic, (0.3, 0.6, 0.7), 8)):
        bpy.ops.mesh.primitive_uv_sphere_add(segments=segments, ring_count=segments // 2, radius=0.7, location=loc)
        bpy.ops.object.shade_smooth()
        bpy.context.active_object.data.materials.append(mat)
    # smooth by angle (Blender's usual shading of a cylinder): smooth sides, flat caps
    bpy.ops.mesh.primitive_cylinder_add(vertices=8, radius=0.45, depth=1.6, location=(1.6, -0.2, 0.8))
    bpy.ops.object.shade_smooth_by_angle(angle=math.radians(30.0))
    bpy.context.active_object.data.materials.append(porcelain)
    S._add_light(bpy, "SUN", "Sun", (0.0, 0.0, 5.0), 2.0, target=(1.0, 2.0, 0.0))
    cam = bpy.data.objects.new(CAMERA_NAME, bpy.data.cameras.new(CAMERA_NAME))
    scene.collection.objects.link(cam)
    cam.location, cam.rotation_euler = (0.2, -6.0, 2.2), (math.radians(75.0), 0.0, 0.0)
    cam.data.lens, cam.data.sensor_width = 40.0, 36.0
    cam.data.dof.use_dof = False
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = RESOLUTION
    scene.render.resolution_percentage = 100


@pytest.fixture(scope="module")
def glint_run(blender_run):
    """The scene's export, Cycles' renders (cached) and petzval's; afterwards rebuilds the main
    scene, which the other modules' tests read from Blender."""
    key_files = ("test_smooth_specular_cycles.py", "blender_scenes.py")
    args = pinhole_glb_args(CAMERA_NAME, WORLD_RGB, RESOLUTION)
    try:
        glb, cyc, pz, _ = scene_pairs(
            blender_run, "smooth_specular", key_files, build_scene, CAMERA_NAME, args, SPP, SEEDS
        )
        yield glb, cyc, pz
    finally:
        S.build_scene(blender_run.workdir)


def test_smooth_low_poly_glossy_meshes_match_cycles(glint_run, report):
    _, cyc, pz = glint_run
    v = _block_verdict(B.compare_blocks(cyc[0], cyc[1], pz[0], pz[1]))
    ratio = B.mean_ratio((pz[0] + pz[1]) / 2, (cyc[0] + cyc[1]) / 2)
    report.line(
        f"smooth low-poly glossy meshes vs Cycles, {SPP} spp x seeds {len(SEEDS)}: {_fmt_verdict(v)}; "
        f"image mean petzval/Cycles R,G,B {ratio[0]:.4f} {ratio[1]:.4f} {ratio[2]:.4f}"
    )
    assert np.all(np.abs(ratio - 1) <= MEAN_TOL), f"image mean ratio {ratio}"
    assert _passes(v), f"blocks differ beyond noise: {_fmt_verdict(v)}"
