"""Evaluated meshes as petzval per-corner buffers.

Meshes: one vertex per face corner (loop), so split normals and UV seams come out right with no
welding; triangles from ``loop_triangles``; UVs as (u, 1 - v); the colour attribute a material's
Color Attribute node reads, per corner, linear RGBA; the evaluated mesh (modifiers
applied) is converted once per evaluated data-block and added to the petzval scene once
(``Scene.add_mesh``); every further instance of it is a transform referencing it
(``Scene.add_instance``; see ``build`` in ``__init__``).
"""

from __future__ import annotations

import numpy as np


class MeshData:
    """Per-corner buffers of one evaluated mesh (petzval conventions, object space)."""

    __slots__ = ("colours", "normals", "positions", "slot_index", "triangles", "uvs")

    def __init__(self, positions, triangles, slot_index, normals, uvs, colours=None):
        self.positions = positions
        self.triangles = triangles
        self.slot_index = slot_index
        self.normals = normals
        self.uvs = uvs
        self.colours = colours


def corner_colours(mesh, name: str, warn) -> np.ndarray:
    """The colour attribute `name` ("" = the mesh's default colour attribute, as an unnamed
    Color Attribute node reads) per face corner, linear RGBA (nl, 4). Point, corner and face
    domains; a missing attribute reads as black, as Cycles reads it (`warn` says so)."""
    nl = len(mesh.loops)
    if not name:
        # the render colour attribute (Blender's "default" colour attribute)
        name = getattr(mesh.attributes, "default_color_name", "") or ""
        if not name:
            attrs = mesh.color_attributes
            k = attrs.render_color_index
            name = attrs[k].name if 0 <= k < len(attrs) else ""
    attr = mesh.attributes.get(name) if name else None
    if attr is None or attr.domain not in ("POINT", "CORNER", "FACE"):
        warn(f"mesh '{mesh.name}': colour attribute '{name or '(default)'}' "
             f"{'not found' if attr is None else f'on the {attr.domain} domain'} (black, as Cycles)")
        return np.zeros((nl, 4), dtype=np.float32)
    n = len(attr.data)
    buf = np.empty(n * 4, dtype=np.float32)
    if attr.data_type in ("FLOAT_COLOR", "BYTE_COLOR"):
        attr.data.foreach_get("color", buf)  # linear for both (BYTE_COLOR is stored as sRGB)
        values = buf.reshape(-1, 4)
    elif attr.data_type == "FLOAT_VECTOR":
        v = np.empty(n * 3, dtype=np.float32)
        attr.data.foreach_get("vector", v)
        values = np.concatenate([v.reshape(-1, 3), np.ones((n, 1), dtype=np.float32)], axis=1)
    elif attr.data_type == "FLOAT":
        v = np.empty(n, dtype=np.float32)
        attr.data.foreach_get("value", v)
        values = np.stack([v, v, v, np.ones(n, dtype=np.float32)], axis=1)
    else:
        warn(f"mesh '{mesh.name}': colour attribute '{name}' of type {attr.data_type} (black)")
        return np.zeros((nl, 4), dtype=np.float32)
    if attr.domain == "CORNER":
        return np.ascontiguousarray(values)
    if attr.domain == "POINT":
        vidx = np.empty(nl, dtype=np.int64)
        mesh.loops.foreach_get("vertex_index", vidx)
        return np.ascontiguousarray(values[vidx])
    starts = np.empty(len(mesh.polygons), dtype=np.int64)
    totals = np.empty(len(mesh.polygons), dtype=np.int64)
    mesh.polygons.foreach_get("loop_start", starts)
    mesh.polygons.foreach_get("loop_total", totals)
    face = np.repeat(np.arange(len(starts)), totals)
    return np.ascontiguousarray(values[face])


def mesh_data(mesh, colour_attribute: str | None = None, warn=print) -> MeshData | None:
    """One vertex per face corner; triangles from loop_triangles; corner normals; the active
    render UV map as (u, 1 - v); with `colour_attribute`, that colour attribute (see
    :func:`corner_colours`)."""
    mesh.calc_loop_triangles()
    nt = len(mesh.loop_triangles)
    if nt == 0:
        return None
    nl = len(mesh.loops)
    tris = np.empty(nt * 3, dtype=np.uint32)
    mesh.loop_triangles.foreach_get("loops", tris)
    slots = np.empty(nt, dtype=np.uint32)
    mesh.loop_triangles.foreach_get("material_index", slots)
    vidx = np.empty(nl, dtype=np.int64)
    mesh.loops.foreach_get("vertex_index", vidx)
    co = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", co)
    positions = np.ascontiguousarray(co.reshape(-1, 3)[vidx])
    normals = np.empty(nl * 3, dtype=np.float32)
    mesh.corner_normals.foreach_get("vector", normals)
    uvs = None
    layer = next((uv for uv in mesh.uv_layers if uv.active_render), None)
    if layer is not None:
        uvs = np.empty(nl * 2, dtype=np.float32)
        if hasattr(layer, "uv"):
            layer.uv.foreach_get("vector", uvs)
        else:
            layer.data.foreach_get("uv", uvs)
        uvs = uvs.reshape(-1, 2)
        uvs[:, 1] = 1.0 - uvs[:, 1]
    colours = None if colour_attribute is None else corner_colours(mesh, colour_attribute, warn)
    return MeshData(positions, tris.reshape(-1, 3), slots, normals.reshape(-1, 3), uvs, colours)
