"""Writes renderer/tests/data/gltf/skin/ with Blender's glTF exporter (bpy 5.0.1, in the test
venv), for renderer/tests/gltf.rs's skin and morph-target tests:

- `skinned.glb`: the scene below exported with its animation (the armature's action as joint
  channels, the shape key's as a `weights` channel);
- `pose_13.glb`: the scene at frame 13 exported without animation, with the exporter's "Use
  Current Frame" on and its armature rest position off, so the joints carry frame 13's pose and
  the mesh its shape-key values as `weights`;
- `frame_F.json`: Blender's own evaluated meshes at frames 1, 7, 13 and 24 (per object, the
  depsgraph's world-space vertex positions and vertex normals in glTF's y-up axes, rounded to
  10⁻⁶): the reference the loaded meshes are compared with. Both objects are smooth-shaded, so
  their vertex normals are the normals Cycles shades with.

The scene (24 fps, frames 1–24): a smooth tube bent by a two-bone armature (vertex weights
blending over the joint, the armature object moved off the origin), and an icosphere with two
shape keys, one animated from 0 to 1 and one held at 0.35. Usage:
.venv/bin/python tests/scene/make_gltf_skin_fixtures.py
"""

import json
import math
from pathlib import Path

import bpy
from mathutils import Vector

OUT = Path(__file__).resolve().parents[2] / "renderer" / "tests" / "data" / "gltf" / "skin"
FRAMES = (1, 7, 13, 24)


def build() -> None:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = 24
    scene.frame_start, scene.frame_end = 1, 24
    # 1. The armature: two connected bones along +z, the object moved off the origin.
    rig_data = bpy.data.armatures.new("Rig")
    rig = bpy.data.objects.new("Rig", rig_data)
    scene.collection.objects.link(rig)
    rig.location = (0.5, 0.2, 0.0)
    bpy.context.view_layer.objects.active = rig
    bpy.ops.object.mode_set(mode="EDIT")
    root = rig_data.edit_bones.new("Root")
    root.head, root.tail = (0, 0, 0), (0, 0, 1)
    tip = rig_data.edit_bones.new("Tip")
    tip.head, tip.tail = (0, 0, 1), (0, 0, 2)
    tip.parent, tip.use_connect = root, True
    bpy.ops.object.mode_set(mode="OBJECT")
    # 2. The tube, weighted to the bones (a blend over 0.6 m about the joint).
    bpy.ops.mesh.primitive_cylinder_add(vertices=12, radius=0.25, depth=2.0, location=(0.5, 0.2, 1.0))
    tube = bpy.context.active_object
    tube.name = "Tube"
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.mesh.subdivide(number_cuts=7)
    bpy.ops.object.mode_set(mode="OBJECT")
    bpy.ops.object.shade_smooth()
    g_root, g_tip = tube.vertex_groups.new(name="Root"), tube.vertex_groups.new(name="Tip")
    for v in tube.data.vertices:
        w = min(1.0, max(0.0, (v.co.z + 1.0 - 0.7) / 0.6))
        if w < 1.0:
            g_root.add([v.index], 1.0 - w, "REPLACE")
        if w > 0.0:
            g_tip.add([v.index], w, "REPLACE")
    tube.parent = rig
    tube.matrix_parent_inverse = rig.matrix_world.inverted()
    tube.modifiers.new("Armature", "ARMATURE").object = rig
    # 3. The pose's keys.
    bones = rig.pose.bones
    for b in bones:
        b.rotation_mode = "XYZ"
    for frame, r0, r1 in ((1, 0.0, 0.0), (12, 0.3, 0.9), (24, -0.2, 1.4)):
        bones["Root"].rotation_euler = (0.0, r0, 0.0)
        bones["Tip"].rotation_euler = (r1, 0.0, 0.0)
        bones["Root"].keyframe_insert("rotation_euler", frame=frame)
        bones["Tip"].keyframe_insert("rotation_euler", frame=frame)
    # 4. The shape-keyed icosphere.
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=2, radius=0.5, location=(-1.5, 0.0, 0.5))
    blob = bpy.context.active_object
    blob.name = "Blob"
    bpy.ops.object.shade_smooth()
    blob.shape_key_add(name="Basis")
    push = blob.shape_key_add(name="Push")
    for i, v in enumerate(blob.data.vertices):
        if v.co.z > 0:
            push.data[i].co = v.co + Vector((0.2, 0.0, 0.4 * v.co.z))
    squash = blob.shape_key_add(name="Squash")
    for i, v in enumerate(blob.data.vertices):
        squash.data[i].co = Vector((1.3 * v.co.x, 1.3 * v.co.y, 0.7 * v.co.z))
    squash.value = 0.35
    for frame, value in ((1, 0.0), (24, 1.0)):
        push.value = value
        push.keyframe_insert("value", frame=frame)
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    camera.location, camera.rotation_euler = (0.0, -7.0, 2.0), (math.radians(80.0), 0.0, 0.0)
    scene.camera = camera


def evaluated_meshes(y_up: bool) -> dict:
    """Per object, Blender's evaluated world-space vertex positions and normals (rounded to
    10⁻⁶), in glTF's y-up axes (x, z, −y), as the exporter converts them, or Blender's own."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    out = {}
    for name in ("Tube", "Blob"):
        ob = bpy.data.objects[name].evaluated_get(depsgraph)
        mesh = ob.to_mesh()
        to_normal = ob.matrix_world.to_3x3().inverted().transposed()
        rows = []
        for v in mesh.vertices:
            p, n = ob.matrix_world @ v.co, (to_normal @ v.normal).normalized()
            row = (p.x, p.z, -p.y, n.x, n.z, -n.y) if y_up else (*p, *n)
            rows.append([round(x, 6) for x in row])
        out[name] = rows
        ob.to_mesh_clear()
    return out


def evaluated(path: Path) -> None:
    path.write_text(json.dumps(evaluated_meshes(y_up=True), separators=(",", ":")) + "\n")


def export(path: Path, **kw) -> None:
    bpy.ops.export_scene.gltf(filepath=str(path), export_format="GLB", export_cameras=True, **kw)


if __name__ == "__main__":
    build()
    OUT.mkdir(parents=True, exist_ok=True)
    export(OUT / "skinned.glb", export_animations=True)
    for f in FRAMES:
        bpy.context.scene.frame_set(f)
        evaluated(OUT / f"frame_{f}.json")
    bpy.context.scene.frame_set(13)
    export(
        OUT / "pose_13.glb",
        export_animations=False,
        export_current_frame=True,
        export_rest_position_armature=False,
    )
