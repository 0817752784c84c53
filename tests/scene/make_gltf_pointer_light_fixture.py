"""Writes renderer/tests/data/gltf/animation/pointer_lights.glb with Blender's glTF exporter
(bpy 5.0.1, in the test venv): a point light's power (20 W at frame 10, 200 W at frame 40), a
sun's strength (1 → 4 W/m²), a spot's size and blend and the camera's focal length (35 → 50 mm)
animated, exported in Scene mode with "Export Pointer Animation" (KHR_animation_pointer), 30 fps.
renderer/tests/gltf.rs checks the values petzval reads at frames 10, 25 and 40 against the
Blender values set here. Usage:
.venv/bin/python tests/scene/make_gltf_pointer_light_fixture.py
"""

import math
from pathlib import Path

import bpy

OUT = Path(__file__).resolve().parents[2] / "renderer" / "tests" / "data" / "gltf" / "animation"


def keyed(data, path: str, frames_values) -> None:
    for frame, value in frames_values:
        setattr(data, path, value)
        data.keyframe_insert(path, frame=frame)


def main() -> None:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = 30
    scene.frame_start, scene.frame_end = 10, 40
    bpy.ops.mesh.primitive_plane_add(size=4.0)
    point = bpy.data.lights.new("Point", "POINT")
    scene.collection.objects.link(bpy.data.objects.new("Point", point))
    keyed(point, "energy", ((10, 20.0), (40, 200.0)))
    sun = bpy.data.lights.new("Sun", "SUN")
    scene.collection.objects.link(bpy.data.objects.new("Sun", sun))
    keyed(sun, "energy", ((10, 1.0), (40, 4.0)))
    spot = bpy.data.lights.new("Spot", "SPOT")
    scene.collection.objects.link(bpy.data.objects.new("Spot", spot))
    keyed(spot, "spot_size", ((10, math.radians(40.0)), (40, math.radians(80.0))))
    keyed(spot, "spot_blend", ((10, 0.0), (40, 0.5)))
    camera = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    scene.collection.objects.link(camera)
    camera.location = (0.0, -5.0, 2.0)
    keyed(camera.data, "lens", ((10, 35.0), (40, 50.0)))
    # linear keys, so the values between are known
    for action in bpy.data.actions:
        for layer in action.layers:
            for strip in layer.strips:
                for bag in strip.channelbags:
                    for fc in bag.fcurves:
                        for k in fc.keyframe_points:
                            k.interpolation = "LINEAR"
    OUT.mkdir(parents=True, exist_ok=True)
    bpy.ops.export_scene.gltf(
        filepath=str(OUT / "pointer_lights.glb"),
        export_format="GLB",
        export_cameras=True,
        export_lights=True,
        export_animations=True,
        export_animation_mode="SCENE",
        export_pointer_animation=True,
    )


if __name__ == "__main__":
    main()
