"""Builds a small Blender scene (ground, cube, smooth metal sphere, a cube rounded by a
Subdivision modifier, sun, point light, camera, a constant-colour world) and exports it with
Blender's own exporters as glTF (scene.glb, modifiers applied: the subdivided mesh) and USD
(scene.usdc, the world as a dome light; "Best Match" writes the rounded cube's cage with
subdivisionScheme = catmullClark, which the USD path subdivides itself). Run by tests/usd/test_blender_usd.py in a
separate process (bpy bundles its own pxr): `python blender_usd_scene.py OUT_DIR`.
"""

import math
import sys

import bpy

out = sys.argv[-1]
bpy.ops.wm.read_factory_settings(use_empty=True)
s = bpy.context.scene
s.render.resolution_x, s.render.resolution_y = 96, 64


def mat(name, color, rough, metal=0.0):
    m = bpy.data.materials.new(name)
    bsdf = m.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*color, 1)
    bsdf.inputs["Roughness"].default_value = rough
    bsdf.inputs["Metallic"].default_value = metal
    return m


bpy.ops.mesh.primitive_plane_add(size=10)
bpy.context.object.data.materials.append(mat("Ground", (0.5, 0.5, 0.5), 0.8))
bpy.ops.mesh.primitive_cube_add(size=1, location=(0, 0, 0.5), rotation=(0, 0, 0.4))
bpy.context.object.data.materials.append(mat("Red", (0.8, 0.1, 0.05), 0.4))
bpy.ops.mesh.primitive_uv_sphere_add(radius=0.4, location=(1.2, 0.3, 0.4))
bpy.ops.object.shade_smooth()
bpy.context.object.data.materials.append(mat("Gold", (0.9, 0.7, 0.3), 0.3, 1.0))
bpy.ops.mesh.primitive_cube_add(size=0.8, location=(0.2, -1.4, 0.4), rotation=(0, 0, -0.3))
bpy.ops.object.shade_smooth()
rounded = bpy.context.object.modifiers.new("Subdivision", "SUBSURF")
rounded.levels = rounded.render_levels = 2
bpy.context.object.data.materials.append(mat("Teal", (0.1, 0.6, 0.5), 0.5))


def add_object(name: str, data: bpy.types.ID) -> bpy.types.Object:
    o = bpy.data.objects.new(name, data)
    s.collection.objects.link(o)
    return o


sun = bpy.data.lights.new("Sun", "SUN")
sun.energy = 3.0
add_object("Sun", sun).rotation_euler = (0.6, 0.2, 0.3)
pt = bpy.data.lights.new("Pt", "POINT")
pt.energy = 300.0
pt.shadow_soft_size = 0.0
add_object("Pt", pt).location = (-1.5, -1.0, 2.0)
cam = bpy.data.cameras.new("Cam")
cam.lens = 40
o = add_object("Cam", cam)
o.location = (3.5, -4.5, 2.6)
o.rotation_euler = (math.radians(65), 0, math.radians(38))
s.camera = o
w = bpy.data.worlds.new("W")
s.world = w
w.node_tree.nodes["Background"].inputs[0].default_value = (0.3, 0.4, 0.5, 1)
w.node_tree.nodes["Background"].inputs[1].default_value = 1.0
bpy.ops.export_scene.gltf(filepath=out + "/scene.glb", export_lights=True, export_cameras=True, export_apply=True)
bpy.ops.wm.usd_export(filepath=out + "/scene.usdc")
