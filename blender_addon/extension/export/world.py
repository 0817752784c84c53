"""The Blender world as petzval's environment.

World: Background colour x strength, or an Environment Texture image (equirectangular, with a
Mapping node's Z rotation).
"""

from __future__ import annotations

from .images import MISSING_TEXTURE, image_pixels
from .nodes import node_tree_of, source, surface_shader, value


def add_world(pz, world, notes, materials) -> None:
    if world is None:
        pz.set_environment_color((0.0, 0.0, 0.0))
        return
    nt = node_tree_of(world)
    node = surface_shader(nt) if nt is not None else None
    if node is None:
        pz.set_environment_color(tuple(float(c) for c in world.color))
        return
    if node.type != "BACKGROUND":
        notes.warn(f"world '{world.name}': {node.bl_label} shader (the world's viewport colour used)")
        pz.set_environment_color(tuple(float(c) for c in world.color))
        return
    strength = float(value(node, "Strength", 1.0))
    if source(node.inputs.get("Strength")) is not None:
        notes.warn(f"world '{world.name}': strength from a node (its unlinked value used)")
    src = source(node.inputs.get("Color"))
    if src is None:
        col = value(node, "Color", (0.05, 0.05, 0.05, 1.0))
        pz.set_environment_color(tuple(float(c) * strength for c in col[:3]))
        return
    env, out = src
    if env.type == "TEX_ENVIRONMENT" and out.name == "Color" and env.image is not None:
        if env.projection != "EQUIRECTANGULAR":
            notes.warn(f"world '{world.name}': {env.projection.lower()} environment projection (equirectangular used)")
        rotation = 0.0
        vec = source(env.inputs.get("Vector"))
        if vec is not None:
            mapping = vec[0]
            if mapping.type == "MAPPING":
                rot = tuple(value(mapping, "Rotation", (0.0, 0.0, 0.0)))
                loc = tuple(value(mapping, "Location", (0.0, 0.0, 0.0)))
                scl = tuple(value(mapping, "Scale", (1.0, 1.0, 1.0)))
                # petzval's rotation_rad is a Texture-type Mapping Z rotation (the map turns by it);
                # Point/Vector/Normal types rotate the lookup direction instead: the opposite turn
                rotation = float(rot[2]) if mapping.vector_type == "TEXTURE" else -float(rot[2])
                if (
                    abs(rot[0]) > 1e-6
                    or abs(rot[1]) > 1e-6
                    or any(abs(x) > 1e-6 for x in loc)
                    or any(abs(s - 1) > 1e-6 for s in scl)
                ):
                    notes.warn(f"world '{world.name}': Mapping node other than a Z rotation (only its Z rotation used)")
            else:
                notes.warn(f"world '{world.name}': environment coordinates from a {mapping.bl_label} node (ignored)")
        px = image_pixels(env.image, notes, f"world '{world.name}'")
        if px is None:
            pz.set_environment_color(MISSING_TEXTURE[:3])
            return
        pz.set_environment_map(px, strength=strength, rotation_rad=rotation, name=env.image.name)
        return
    if env.type == "RGB":
        col = tuple(out.default_value)
        pz.set_environment_color(tuple(float(c) * strength for c in col[:3]))
        return
    notes.warn(f"world '{world.name}': background colour from a {env.bl_label} node (its unlinked value used)")
    col = value(node, "Color", (0.05, 0.05, 0.05, 1.0))
    pz.set_environment_color(tuple(float(c) * strength for c in col[:3]))
