"""Writes renderer/tests/data/gltf/animation/ with Blender's glTF exporter (bpy 5.0.1, in the
test venv): one animated scene exported with its animation (`animated.glb`: sampled at every
frame, LINEAR; `animated_cubic.glb`: the exporter's "Always Sample Animations" off, so Bezier
keys become CUBICSPLINE; `pointer.glb`: in one scene animation, with the camera's focal
length as a KHR_animation_pointer channel), and exported without animation at some frames (`frame_F.glb`, the
scene evaluated at frame F), which renderer/tests/gltf.rs compares node for node.

The scene (24 fps, frames 1–24): a cube moving, turning and scaling under a turning empty, a
camera flying (linear keys) and zooming, a point light moving. Usage:
.venv/bin/python tests/scene/make_gltf_animation_fixtures.py
"""

import math
from pathlib import Path

import bpy

OUT = Path(__file__).resolve().parents[2] / "renderer" / "tests" / "data" / "gltf" / "animation"
FRAMES = (1, 7, 13, 24)


def build() -> None:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = 24
    scene.frame_start, scene.frame_end = 1, 24
    pivot = bpy.data.objects.new("Pivot", None)
    scene.collection.objects.link(pivot)
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    cube = bpy.context.active_object
    cube.name = "Cube"
    cube.parent = pivot
    for frame, loc, rot, scale in (
        (1, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (1.0, 1.0, 1.0)),
        (12, (2.0, 1.0, 0.5), (0.4, 0.2, 1.6), (1.5, 0.7, 1.0)),
        (24, (-1.0, 3.0, 1.0), (1.2, -0.3, 3.0), (0.5, 0.5, 2.0)),
    ):
        cube.location, cube.rotation_euler, cube.scale = loc, rot, scale
        for path in ("location", "rotation_euler", "scale"):
            cube.keyframe_insert(path, frame=frame)
    for frame, angle in ((1, 0.0), (24, math.pi / 2)):
        pivot.rotation_euler = (0.0, 0.0, angle)
        pivot.keyframe_insert("rotation_euler", frame=frame)
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    camera.rotation_euler = (math.radians(70.0), 0.0, 0.0)
    for frame, loc in ((1, (0.0, -8.0, 3.0)), (24, (3.0, -6.0, 4.0))):
        camera.location = loc
        camera.keyframe_insert("location", frame=frame)
    for fc in camera.animation_data.action.layers[0].strips[0].channelbags[0].fcurves:
        for k in fc.keyframe_points:
            k.interpolation = "LINEAR"
    scene.camera = camera
    for frame, lens in ((1, 35.0), (24, 70.0)):
        camera.data.lens = lens
        camera.data.keyframe_insert("lens", frame=frame)
    light = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
    scene.collection.objects.link(light)
    for frame, loc in ((1, (1.0, -1.0, 3.0)), (24, (-2.0, 0.0, 4.0))):
        light.location = loc
        light.keyframe_insert("location", frame=frame)


def export(path: Path, **kw) -> None:
    bpy.ops.export_scene.gltf(
        filepath=str(path), export_format="GLB", export_cameras=True, export_lights=True, **kw
    )


if __name__ == "__main__":
    build()
    OUT.mkdir(parents=True, exist_ok=True)
    export(OUT / "animated.glb", export_animations=True)
    export(OUT / "animated_cubic.glb", export_animations=True, export_force_sampling=False)
    # the camera's focal length as a KHR_animation_pointer channel (no target node)
    export(OUT / "pointer.glb", export_animations=True, export_pointer_animation=True, export_animation_mode="SCENE")
    for f in FRAMES:
        bpy.context.scene.frame_set(f)
        export(OUT / f"frame_{f}.glb", export_animations=False, export_current_frame=True)
