"""Evaluated meshes as petzval per-corner buffers.

Meshes: one vertex per face corner (loop), so split normals and UV seams come out right with no
welding; triangles from ``loop_triangles``; UVs as (u, 1 - v); the evaluated mesh (modifiers
applied) is converted once per evaluated data-block and added to the petzval scene once
(``Scene.add_mesh``); every further instance of it is a transform referencing it
(``Scene.add_instance``; see ``build`` in ``__init__``).
"""

from __future__ import annotations

import numpy as np


class MeshData:
    """Per-corner buffers of one evaluated mesh (petzval conventions, object space)."""

    __slots__ = ("normals", "positions", "slot_index", "triangles", "uvs")

    def __init__(self, positions, triangles, slot_index, normals, uvs):
        self.positions = positions
        self.triangles = triangles
        self.slot_index = slot_index
        self.normals = normals
        self.uvs = uvs


def mesh_data(mesh) -> MeshData | None:
    """One vertex per face corner; triangles from loop_triangles; corner normals; the active
    render UV map as (u, 1 - v)."""
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
    return MeshData(positions, tris.reshape(-1, 3), slots, normals.reshape(-1, 3), uvs)
