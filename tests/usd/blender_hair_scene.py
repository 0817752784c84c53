"""Builds a hair scene in Blender 5.0 (a Curves object of 24 thick Catmull-Rom strands with
tapering radii and a diffuse red material, a camera, a uniform white world), exports it as USD
(`bpy.ops.wm.usd_export`: the strands as BasisCurves, widths = 2 × Blender's radius; the world
as a dome light) and renders it with Cycles ("3D Curves", 32 spp, 160 × 120) to cycles.exr. Run
by tests/usd/test_curves.py in its own process (bpy bundles its own pxr):
`python blender_hair_scene.py OUT_DIR`.
"""

import math
import sys

import bpy
import numpy as np


def add_hair_strands(radius_scale: float = 1.0):
    """The scene's hair: a Curves object of 24 strands, 5 points each, in a 4 × 6 grid swaying in
    x, radii tapering from 0.04 (× `radius_scale`), diffuse red (0.8, 0.2, 0.1); returns the
    object (also used by tests/blender_addon)."""
    cu = bpy.data.hair_curves.new("Hair")
    n, k = 24, 5
    cu.add_curves([k] * n)
    rng = np.random.default_rng(5)
    for i in range(n):
        x0, y0 = -0.75 + 0.3 * (i % 6) + rng.uniform(-0.05, 0.05), 0.3 * (i // 6) + rng.uniform(-0.05, 0.05)
        for j in range(k):
            p = cu.points[i * k + j]
            p.position = (x0 + 0.12 * math.sin(1.3 * j + i), y0, 0.25 * j)
            p.radius = (0.04 - 0.006 * j) * radius_scale
    m = bpy.data.materials.new("HairRed")
    bsdf = m.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.8, 0.2, 0.1, 1)
    bsdf.inputs["Roughness"].default_value = 1.0
    bsdf.inputs["Specular IOR Level"].default_value = 0.0
    cu.materials.append(m)
    hair = bpy.data.objects.new("Hair", cu)
    bpy.context.scene.collection.objects.link(hair)
    return hair


def main(out: str) -> None:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    s = bpy.context.scene
    s.render.resolution_x, s.render.resolution_y, s.render.resolution_percentage = 160, 120, 100
    s.render.engine = "CYCLES"
    s.cycles.samples, s.cycles.seed, s.cycles.use_denoising = 32, 1, False
    s.cycles.device = "CPU"
    s.cycles_curves.shape = "THICK"
    s.render.image_settings.file_format = "OPEN_EXR"
    s.view_settings.view_transform = "Standard"
    world = bpy.data.worlds.new("World")
    s.world = world
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    bg.inputs["Strength"].default_value = 1.0

    add_hair_strands()

    cam = bpy.data.cameras.new("Cam")
    cam.lens, cam.sensor_width = 35.0, 36.0
    co = bpy.data.objects.new("Cam", cam)
    s.collection.objects.link(co)
    co.location = (0.0, -4.0, 0.5)
    co.rotation_euler = (math.radians(90), 0.0, 0.0)
    s.camera = co

    bpy.ops.wm.usd_export(filepath=f"{out}/hair.usda")
    s.render.filepath = f"{out}/cycles.exr"
    bpy.ops.render.render(write_still=True)


if __name__ == "__main__":
    main(sys.argv[-1])
