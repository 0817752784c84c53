"""Writes usd/tests/data/subdiv/: Blender 5.0's USD export ("Best Match": the Subdivision
modifier's cage with its scheme, boundary rule and creases) of a few subdivided objects, and
`blender.json`, their meshes as Blender's Subdivision modifier evaluates them (render level 2,
limit surface, OpenSubdiv): per object, every face corner's world position and UV.

    .venv/bin/python tests/usd/make_subdiv_fixture.py usd/tests/data/subdiv
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import bpy


def subsurf(o: bpy.types.Object, boundary: str = "ALL", uv_smooth: str = "PRESERVE_BOUNDARIES") -> None:
    m = o.modifiers.new("Subdivision", "SUBSURF")
    m.levels = m.render_levels = 2
    m.boundary_smooth = boundary
    m.uv_smooth = uv_smooth


def add(op, name: str, location, **kw) -> bpy.types.Object:
    op(location=location, **kw)
    o = bpy.context.object
    o.name = name
    return o


def creases(o: bpy.types.Object, values: dict[int, float]) -> None:
    attr = o.data.attributes.new("crease_edge", "FLOAT", "EDGE")
    for edge, c in values.items():
        attr.data[edge].value = c


def main(out: Path) -> None:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    m = bpy.ops.mesh
    subsurf(add(m.primitive_cube_add, "Cube", (0, 0, 0)))
    subsurf(add(m.primitive_grid_add, "GridEdge", (3, 0, 0), x_subdivisions=4, y_subdivisions=3, size=2))
    subsurf(
        add(m.primitive_grid_add, "GridCorner", (6, 0, 0), x_subdivisions=4, y_subdivisions=3, size=2),
        boundary="PRESERVE_CORNERS",
    )
    # triangles and a pentagon
    subsurf(add(m.primitive_cone_add, "Cone", (0, 3, 0), vertices=5))
    # creases: infinitely sharp (1 → 10), semi-sharp ending after 2.5 and 0.625 levels
    o = add(m.primitive_cube_add, "Creased", (3, 3, 0))
    creases(o, {0: 1.0, 1: 0.5, 2: 0.25})
    subsurf(o)
    # a crease of sharpness 2 that ends exactly at the last level, and UVs smoothed everywhere
    o = add(m.primitive_cube_add, "Crease2", (6, 3, 0))
    creases(o, {0: math.sqrt(0.2), 5: math.sqrt(0.2)})
    subsurf(o, uv_smooth="SMOOTH_ALL")
    # an infinitely sharp crease on one edge only: its ends are darts
    o = add(m.primitive_cube_add, "Dart", (9, 3, 0))
    creases(o, {0: 1.0})
    subsurf(o)
    # UVs linear everywhere, on a cylinder (n-gon caps)
    subsurf(add(m.primitive_cylinder_add, "Cylinder", (0, 6, 0), vertices=7), uv_smooth="NONE")
    out.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.usd_export(filepath=str(out / "subd.usda"))
    dg = bpy.context.evaluated_depsgraph_get()
    result = {}
    for ob in bpy.data.objects:
        me = ob.evaluated_get(dg).to_mesh()
        uv = me.uv_layers.active.data
        result[ob.name] = {
            "corners": [
                [*(ob.matrix_world @ me.vertices[loop.vertex_index].co), *uv[loop.index].uv] for loop in me.loops
            ],
        }
    for o in result.values():
        o["corners"] = [[round(x, 7) for x in c] for c in o["corners"]]
    (out / "blender.json").write_text(json.dumps(result, separators=(",", ":")))


if __name__ == "__main__":
    main(Path(sys.argv[-1]))
