"""Blender lights as petzval lights.

Lights: point and spot as punctual lights (intensity = power / 4 pi, as Blender's glTF exporter),
or discs/spheres with a radius; sun as a directional light with its angle; area lights as
one-sided emitting quads/discs with Cycles' radiance power / (area * pi), which as Cycles' lights
cast no shadow, are not there from behind and are hidden from camera rays unless the light's
Ray Visibility > Camera is on (off by default in Blender 5). Positions and directions in glTF axes
(Blender (x, y, z) -> (x, z, -y)).
"""

from __future__ import annotations

import math

import numpy as np

from ..camera import to_gltf
from .nodes import node_tree_of, value


def light_colour(light) -> np.ndarray:
    c = np.array(light.color, dtype=np.float64)
    if getattr(light, "use_temperature", False):
        c = c * np.array(light.temperature_color, dtype=np.float64)
    return c * (2.0 ** float(getattr(light, "exposure", 0.0)))


def _light_nodes_do_something(nt) -> bool:
    """True unless the light's node tree is Blender's default (a white Emission of strength 1
    into the Light Output)."""
    for node in nt.nodes:
        if node.type == "OUTPUT_LIGHT":
            continue
        if node.type != "EMISSION":
            return True
        col = value(node, "Color", (1.0, 1.0, 1.0, 1.0))
        if abs(value(node, "Strength", 1.0) - 1.0) > 1e-6 or any(abs(c - 1.0) > 1e-6 for c in col[:3]):
            return True
        if any(s.is_linked for s in node.inputs):
            return True
    return False


def add_light(pz, obj, matrix_world, notes, materials) -> None:
    light = obj.data
    m = to_gltf(matrix_world)
    pos = m[:3, 3]
    axis = -m[:3, 2]
    n = np.linalg.norm(axis)
    direction = axis / n if n > 0 else np.array([0.0, -1.0, 0.0])
    colour = light_colour(light)
    name = obj.name
    if not float(light.energy) >= 0.0:
        # petzval's lights only add light; Cycles' negative ones take it away
        notes.warn(f"light '{name}': negative power {float(light.energy):g} W (light skipped)")
        return
    lnt = node_tree_of(light) if hasattr(light, "node_tree") else None
    if lnt is not None and _light_nodes_do_something(lnt):
        notes.warn(f"light '{name}': light nodes")
    if not getattr(light, "use_shadow", True):
        notes.warn(f"light '{name}': Cast Shadow off (its light is shadowed)")
    if light.type in ("POINT", "SPOT"):
        intensity = colour * float(light.energy) / (4.0 * math.pi)
        radius = max(float(light.shadow_soft_size), 0.0)
        # Soft Falloff (the default): a disc facing each point; off: a sphere, as in Cycles
        sphere = not getattr(light, "use_soft_falloff", True)
        if light.type == "POINT":
            pz.add_point_light(tuple(pos), tuple(intensity), name=name, radius_m=radius, sphere=sphere)
        else:
            outer = float(light.spot_size) / 2.0
            inner = outer * (1.0 - float(light.spot_blend))
            if light.use_square:
                notes.warn(f"light '{name}': square spot (a round cone used)")
            # Spot Blend fades as in Cycles (a smoothstep in cos over (1 - cos outer)·blend)
            pz.add_spot_light(
                tuple(pos),
                tuple(direction),
                tuple(intensity),
                inner,
                outer,
                name=name,
                falloff="blender",
                radius_m=radius,
                sphere=sphere,
            )
    elif light.type == "SUN":
        angle = min(max(float(light.angle), 0.0), math.radians(179.0))
        pz.add_sun_light(tuple(direction), tuple(colour * float(light.energy)), name=name, angle_rad=angle)
    elif light.type == "AREA":
        add_area_light(pz, obj, m, colour, notes, materials)
    else:
        notes.warn(f"light '{name}': {light.type.lower()} lights")


def area_light_geometry(light):
    """Object-space vertices and triangles of an area light's shape (z = 0), its triangles
    facing -z (the direction the light emits to)."""
    sx = float(light.size)
    sy = float(light.size_y) if light.shape in ("RECTANGLE", "ELLIPSE") else sx
    if light.shape in ("SQUARE", "RECTANGLE"):
        v = np.array(
            [[-sx / 2, -sy / 2, 0], [sx / 2, -sy / 2, 0], [sx / 2, sy / 2, 0], [-sx / 2, sy / 2, 0]], dtype=np.float64
        )
        t = np.array([[0, 2, 1], [0, 3, 2]], dtype=np.uint32)
    else:
        k = 48
        a = np.linspace(0, 2 * math.pi, k, endpoint=False)
        # a polygon with the disc's area (so the emitted power is the disc's)
        r_scale = math.sqrt(math.pi / (k / 2 * math.sin(2 * math.pi / k)))
        rim = np.stack([sx / 2 * r_scale * np.cos(a), sy / 2 * r_scale * np.sin(a), np.zeros(k)], axis=1)
        v = np.vstack([[[0.0, 0.0, 0.0]], rim])
        t = np.array([[0, (i + 1) % k + 1, i + 1] for i in range(k)], dtype=np.uint32)
    return v, t


def add_area_light(pz, obj, m, colour, notes, materials) -> None:
    light = obj.data
    v, t = area_light_geometry(light)
    world = (m[:3, :3] @ v.T).T
    e1 = world[t[:, 1]] - world[t[:, 0]]
    e2 = world[t[:, 2]] - world[t[:, 0]]
    area = float(0.5 * np.linalg.norm(np.cross(e1, e2), axis=1).sum())
    if area <= 0:
        notes.warn(f"light '{obj.name}': area light of zero size")
        return
    if light.spread < math.pi - 1e-4:
        notes.warn(f"light '{obj.name}': area light spread below 180°")
    # Cycles: radiance = power / (area * pi) for a normalized light (one-sided, Lambertian); measured
    # in Cycles 5.0: a 1 m^2 light of 100 W seen head-on reads 31.83 = 100 / pi)
    power = float(light.energy)
    radiance = colour * power / ((area if light.normalize else 1.0) * math.pi)
    # a light's emitter, not geometry (as in Cycles): it casts no shadow, and from behind it is not there
    # Blender 5 hides lights from camera rays unless Ray Visibility > Camera is on
    mat = pz.add_material(f"{obj.name} (area light)", base_color=(0.0, 0.0, 0.0, 1.0), specular=0.0, roughness=1.0,
                          emission=tuple(radiance), double_sided=False, light_emitter=True,
                          visible_to_camera=bool(getattr(obj, "visible_camera", False)))
    normals = np.tile(np.array([[0.0, 0.0, -1.0]], dtype=np.float32), (len(v), 1))
    pz.add_mesh(v.astype(np.float32), t, material_ids=np.full(len(t), mat, dtype=np.uint32), normals=normals,
                transform=m, name=obj.name)
