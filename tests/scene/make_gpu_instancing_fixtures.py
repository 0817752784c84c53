"""Writes renderer/tests/data/gltf/gpu_instancing/{nodes,instanced}.glb with Blender's glTF
exporter (bpy 5.0.1, in the test venv): one scene exported twice, without and with the
exporter's "GPU Instances" option (EXT_mesh_gpu_instancing).

The scene: an empty, rotated and moved, parenting seven linked duplicates of one cube (one
mesh), each with its own location, rotation and non-uniform scale, one of them mirrored
(negative scale); a plane of its own mesh; a camera and a sun. Usage:
.venv/bin/python tests/scene/make_gpu_instancing_fixtures.py
"""

import math
from pathlib import Path

import bpy

OUT = Path(__file__).resolve().parents[2] / "renderer" / "tests" / "data" / "gltf" / "gpu_instancing"


def build() -> None:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    empty = bpy.data.objects.new("Scatter", None)
    scene.collection.objects.link(empty)
    empty.location = (0.3, -0.2, 0.1)
    empty.rotation_euler = (0.0, 0.0, 0.4)
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    cube = bpy.context.active_object
    cube.data.name = "Cube"
    cubes = [cube] + [cube.copy() for _ in range(6)]
    for i, o in enumerate(cubes):
        if i:
            scene.collection.objects.link(o)
        o.name = f"Cube.{i}"
        o.parent = empty
        o.location = ((i % 4) * 1.2 - 1.8, (i // 4) * 1.5, 0.2 * i)
        o.rotation_euler = (0.3 * i, 0.1 * i, 0.7 * i)
        o.scale = (0.4 + 0.05 * i, 0.5, 0.45 - 0.03 * i)
    cubes[5].scale = (-0.5, 0.4, 0.6)
    bpy.ops.mesh.primitive_plane_add(size=20.0, location=(0.0, 0.0, -0.8))
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    camera.location = (0.0, -8.0, 3.0)
    camera.rotation_euler = (math.radians(72.0), 0.0, 0.0)
    scene.camera = camera
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    scene.collection.objects.link(sun)
    sun.data.energy = 3.0
    sun.rotation_euler = (0.5, 0.3, 0.0)


if __name__ == "__main__":
    build()
    OUT.mkdir(parents=True, exist_ok=True)
    for name, gpu in (("nodes", False), ("instanced", True)):
        bpy.ops.export_scene.gltf(
            filepath=str(OUT / f"{name}.glb"),
            export_format="GLB",
            export_cameras=True,
            export_lights=True,
            export_gpu_instances=gpu,
            export_apply=True,
        )
