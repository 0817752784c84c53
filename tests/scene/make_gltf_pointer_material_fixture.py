"""Writes renderer/tests/data/gltf/animation/pointer_materials*.glb with Blender's glTF exporter
(bpy 5.0.1, in the test venv): three planes whose Principled BSDF inputs are keyframed (linear
keys at frames 10 and 40, 30 fps), exported in Scene mode with "Export Pointer Animation"
(KHR_animation_pointer channels on /materials/N/...):

- "Principled": Base Color, Alpha (0.6 -> 0.3, so the material is BLEND), Metallic, Roughness,
  Emission Color and Strength, IOR, Transmission Weight, Coat Weight and Roughness, Specular IOR
  Level (0.3 -> 0.9: above 0.5 the exporter moves it into specularColorFactor), Anisotropic and
  Anisotropic Rotation;
- "Glow": only Emission Strength animated (0.5 -> 3), its colour fixed;
- "Mapped": an image on Base Color through a Mapping node whose Location, Rotation and Scale
  are animated (KHR_texture_transform offset, rotation, scale).

Files:
- pointer_materials.glb: sampled every frame, LINEAR (the exporter's default);
- pointer_materials_step.glb: the same with the exporter's STEP sampling fallback;
- pointer_materials_frame_25.glb, pointer_materials_frame_40.glb: still exports at frames 25
  and 40 (the exporter's own conversion of that frame's values, e.g. the Mapping node into
  KHR_texture_transform and the Specular IOR Level above 0.5 into specularColorFactor);
- pointer_materials_blender.json: Blender's evaluated input values at frames 10, 25, 25.5 and
  40 (scene.frame_set, read back from the node sockets).

renderer/tests/gltf.rs checks what petzval loads at those frames against them. Usage:
.venv/bin/python tests/scene/make_gltf_pointer_material_fixture.py
"""

import json
from pathlib import Path

import bpy

OUT = Path(__file__).resolve().parents[2] / "renderer" / "tests" / "data" / "gltf" / "animation"

# Principled BSDF input -> (value at frame 10, value at frame 40)
PRINCIPLED = {
    "Base Color": ((0.8, 0.2, 0.1, 1.0), (0.1, 0.3, 0.9, 1.0)),
    "Alpha": (0.6, 0.3),
    "Metallic": (0.0, 1.0),
    "Roughness": (0.2, 0.8),
    "Emission Color": ((1.0, 0.5, 0.0, 1.0), (0.0, 0.5, 1.0, 1.0)),
    "Emission Strength": (0.5, 4.0),
    "IOR": (1.3, 1.8),
    "Transmission Weight": (0.0, 0.6),
    "Coat Weight": (0.0, 0.7),
    "Coat Roughness": (0.1, 0.5),
    "Specular IOR Level": (0.3, 0.9),
    "Anisotropic": (0.2, 0.8),
    "Anisotropic Rotation": (0.1, 0.4),
}
MAPPING = {
    "Location": ((0.0, 0.0, 0.0), (0.5, 0.25, 0.0)),
    "Rotation": ((0.0, 0.0, 0.0), (0.0, 0.0, 0.5)),
    "Scale": ((1.0, 1.0, 1.0), (2.0, 3.0, 1.0)),
}
FRAMES = (10, 25, 25.5, 40)


def keyed(socket, first_last) -> None:
    for frame, value in zip((10, 40), first_last, strict=True):
        socket.default_value = value
        socket.keyframe_insert("default_value", frame=frame)


def plane(name: str, x: float):
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(x, 0.0, 0.0))
    material = bpy.data.materials.new(name)
    bpy.context.object.data.materials.append(material)
    return material


def build() -> dict:
    """The scene; returns the sockets whose values are recorded, by material."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = 30
    scene.frame_start, scene.frame_end = 10, 40
    principled = plane("Principled", 0.0).node_tree.nodes["Principled BSDF"].inputs
    for name, values in PRINCIPLED.items():
        keyed(principled[name], values)
    glow = plane("Glow", 2.0).node_tree.nodes["Principled BSDF"].inputs
    glow["Emission Color"].default_value = (1.0, 0.5, 0.25, 1.0)
    keyed(glow["Emission Strength"], (0.5, 3.0))
    mapped = plane("Mapped", 4.0).node_tree
    image = bpy.data.images.new("grey", 4, 4)
    image.pixels = [0.5] * 64
    image.pack()
    texture = mapped.nodes.new("ShaderNodeTexImage")
    texture.image = image
    mapping = mapped.nodes.new("ShaderNodeMapping")
    uv = mapped.nodes.new("ShaderNodeTexCoord")
    mapped.links.new(uv.outputs["UV"], mapping.inputs["Vector"])
    mapped.links.new(mapping.outputs["Vector"], texture.inputs["Vector"])
    mapped.links.new(texture.outputs["Color"], mapped.nodes["Principled BSDF"].inputs["Base Color"])
    for name, values in MAPPING.items():
        keyed(mapping.inputs[name], values)
    # linear keys, so that the values between are known
    for action in bpy.data.actions:
        for layer in action.layers:
            for strip in layer.strips:
                for bag in strip.channelbags:
                    for fc in bag.fcurves:
                        for k in fc.keyframe_points:
                            k.interpolation = "LINEAR"
    camera = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    scene.collection.objects.link(camera)
    camera.location = (0.0, -5.0, 2.0)
    return {
        "Principled": {n: principled[n] for n in PRINCIPLED},
        "Glow": {n: glow[n] for n in ("Emission Color", "Emission Strength")},
        "Mapped": {n: mapping.inputs[n] for n in MAPPING},
    }


def evaluated(sockets: dict) -> dict:
    """Blender's values of the recorded sockets at each of FRAMES."""
    scene = bpy.context.scene
    out = {}
    for frame in FRAMES:
        scene.frame_set(int(frame), subframe=frame - int(frame))
        out[str(frame)] = {
            material: {
                name: (list(s.default_value) if hasattr(s.default_value, "__len__") else s.default_value)
                for name, s in inputs.items()
            }
            for material, inputs in sockets.items()
        }
    return out


def export(name: str, animated: bool, sampling: str = "LINEAR") -> None:
    bpy.ops.export_scene.gltf(
        filepath=str(OUT / name),
        export_format="GLB",
        export_cameras=True,
        export_animations=animated,
        export_animation_mode="SCENE",
        export_pointer_animation=animated,
        export_sampling_interpolation_fallback=sampling,
        # the still: the values at the scene's frame (by default the exporter writes frame 0's)
        export_current_frame=not animated,
    )


def main() -> None:
    sockets = build()
    OUT.mkdir(parents=True, exist_ok=True)
    values = evaluated(sockets)
    (OUT / "pointer_materials_blender.json").write_text(json.dumps(values, indent=1) + "\n")
    for frame in (25, 40):
        bpy.context.scene.frame_set(frame)
        export(f"pointer_materials_frame_{frame}.glb", False)
    export("pointer_materials.glb", True)
    export("pointer_materials_step.glb", True, "STEP")


if __name__ == "__main__":
    main()
